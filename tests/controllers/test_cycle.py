"""The NC cycle every controller shares (controllers/cycle.py), on the plain controllers.

A motion ends only at the controller's own command within ``inpos_band``; waiting longer than
``inpos_timeout`` is the in-position alarm, counted from the stop of *this* motion; an excess following error
stops the cycle, and START after it re-bases the command on where the axes stand (follow-up).
"""

from __future__ import annotations

import pytest

from ncfmu.controllers import ContourInterpolator, ProgrammableFeed
from ncfmu.controllers.cycle import ARRIVED, LATE, MOVING, WAITING, InPosition

DT = 1e-3


def test_in_position_needs_two_steps_the_band_and_the_servo():
    check = InPosition(band=0.005, timeout=0.01)
    assert check.judge(DT, False, True, [1.0], [1.0]) == MOVING
    assert check.judge(DT, True, True, [1.0], [1.0]) == WAITING          # the servo has not answered yet
    assert check.judge(DT, True, False, [1.0], [1.0]) == WAITING         # it says: not in position
    assert check.judge(DT, True, True, [1.006], [1.0]) == WAITING        # in position, but not at our command
    assert check.judge(DT, True, True, [1.004], [1.0]) == ARRIVED
    assert (check.steps, check.waited) == (0, 0.0)


def test_in_position_timeout_counts_from_the_stop():
    check = InPosition(band=0.005, timeout=0.0105)
    results = [check.judge(DT, True, True, [2.0], [1.0]) for _ in range(11)]
    assert results[:10] == [WAITING] * 10 and results[10] == LATE        # 11 ms waited > 10.5 ms
    assert check.waited == 0.0


# -- ProgrammableFeed -------------------------------------------------------------------------------
def run_feed(feed: ProgrammableFeed, steps: int, offset: float = 0.0, **inputs) -> list[dict]:
    """Step with an X axis that stands ``offset`` from the command (a servo that stopped short)."""
    state = {"start": False, "wear_start": False, "emergency": False, "mfin": False, "alarm_in": False,
             "feed_hold": False, "feed_override": 1.0, "x_pos": 0.0, "y_pos": 0.0, "x_in_position": True,
             "y_in_position": True, **inputs}
    out = []
    for k in range(steps):
        o = dict(feed.step(k * DT, DT, state))
        state["start"] = state["emergency"] = False
        state["x_pos"] = o["x_cmd"] + (offset if not o["run"] or o["x_vff"] == 0.0 else 0.0)
        out.append(o)
    return out


@pytest.mark.parametrize("band, ends", [(0.003, False), (0.005, True)])
def test_feed_word_ends_within_its_inpos_band(band, ends):
    """ProgrammableFeed's band is its port (it was a constant): an axis 4 um short ends a word only with a band
    of 5 um; with 3 um the word waits, and after inpos_timeout it is the in-position alarm."""
    feed = ProgrammableFeed(program="M0: X+D1F1; M1: END; M41: XF7S1; M42: END; M43: END", D1=1.0, F1=10.0,
                            inpos_band=band, inpos_timeout=0.5)
    out = run_feed(feed, 900, offset=0.004, start=True)
    done_at = next((k for k, o in enumerate(out) if o["pc"] == 1), None)
    if ends:
        assert done_at is not None and not any(o["alarm"] for o in out)
    else:
        assert done_at is None
        alarm_at = next(k for k, o in enumerate(out) if o["alarm"])
        stop = next(k for k, o in enumerate(out) if k > 10 and o["x_vff"] == 0.0 and o["x_cmd"] == 1.0)
        assert alarm_at - stop == pytest.approx(500, abs=2)                 # inpos_timeout after the stop
        assert any("in-position check" in text for _, text in feed.take_messages())


def test_the_wait_starts_afresh_with_each_motion():
    """EMB during a word's wait: the emergency return's own wait is counted from its own stop (a wait left over
    from the aborted word used to count too and raised the in-position alarm early)."""
    feed = ProgrammableFeed(program="M0: X+D1F1; M1: END; M41: XF7S1; M42: END; M43: END", D1=1.0, F1=10.0,
                            inpos_band=0.005, inpos_timeout=0.5)
    out = run_feed(feed, 520, offset=0.01, start=True)       # stops at 0.12 s, waits 0.4 s short of it: not late
    assert not out[-1]["alarm"] and out[-1]["pc"] == 0
    more = run_feed(feed, 800, offset=0.01, emergency=True, x_pos=out[-1]["x_cmd"] + 0.01)
    returned = next(k for k, o in enumerate(more) if o["emergency_active"] and o["x_vff"] == 0.0 and k > 5
                    and o["x_cmd"] == 0.0)
    late = next(k for k, o in enumerate(more) if o["alarm"])
    assert late - returned == pytest.approx(500, abs=2)       # the return's own 0.5 s, not 0.5 s - 0.4 s


# -- ContourInterpolator ----------------------------------------------------------------------------
def test_contour_excess_following_error_stops_and_start_follows_up():
    """A servo that stops following: the contour alarms when |command - actual| passes max_following_error, the
    command decelerates along the path (no jump), and START re-bases the command on where the axis stands."""
    contour = ContourInterpolator(y_start=0.0, feed=20.0, max_following_error=0.5)
    state = {"start": True, "feed_hold": False, "feed_override": 1.0, "x_pos": 0.0, "y_pos": 0.0,
             "x_in_position": True, "y_in_position": True}
    out = []
    for k in range(400):
        o = dict(contour.step(k * DT, DT, state))
        state["start"] = False
        out.append(o)                                          # the X axis never moves: it stays at 0
    alarm_at = next(k for k, o in enumerate(out) if o["alarm"])
    assert out[alarm_at - 1]["x_cmd"] <= 0.5 + 20.0 * DT and out[alarm_at]["x_cmd"] > 0.5 - 20.0 * DT
    accel = contour.accel
    vx = [o["x_vff"] for o in out]
    assert all(abs(b - a) <= accel * DT * (1 + 1e-9) + 1e-12 for a, b in zip(vx, vx[1:]))
    assert out[-1]["x_vff"] == 0.0 and not out[-1]["busy"]
    assert any("excess following error" in text for _, text in contour.take_messages())
    stopped = out[-1]["x_cmd"]
    state.update(start=True, x_pos=0.2)                         # the axis stands at 0.2 mm when START comes
    o = dict(contour.step(0.4, DT, state))
    assert not o["alarm"] and o["busy"]
    assert abs(o["x_cmd"] - 0.2) <= 0.001 < abs(stopped - 0.2)   # from where the axis stands, not the old command
    assert any("follow-up" in text for _, text in contour.take_messages())
