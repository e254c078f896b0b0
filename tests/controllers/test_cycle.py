"""The NC cycle every controller shares (controllers/cycle.py), on the plain controllers.

A motion ends only at the controller's own command within ``inpos_band``; waiting longer than
``inpos_timeout`` is the in-position alarm, counted from the stop of *this* motion; an excess following error
stops the cycle, and START after it re-bases the command on where the axes stand (follow-up). The order of a
step is the skeleton's (``CycleController.step``) for every cycle controller: the tests below run each of
them -- CutSequencer, ProgrammableFeed, ContourInterpolator -- through the same scenarios.
"""

from __future__ import annotations

import pytest

from ncfmu.controllers import Block, ContourInterpolator, CutSequencer, ProgrammableFeed
from ncfmu.controllers.cycle import ARRIVED, LATE, MOVING, WAITING, CycleController, InPosition

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


# -- every cycle controller, one skeleton -----------------------------------------------------------------
FEED_PROGRAM = "M0: X+D1F1; M1: END; M41: XF7S1; M42: END; M43: END"


def lathe(**parameters) -> CutSequencer:
    """SC1 first: X infeeds 10 -> 8.5 at the rapid rate, Z stands."""
    return CutSequencer.with_blocks([Block(Xf=1.0, Xd=0.5, Zp=20.0, N=1, feed=20.0, rapid=50.0)], **parameters)


def grinder(**parameters) -> ProgrammableFeed:
    """One feed word: X 0 -> 5 at 20 mm/s."""
    return ProgrammableFeed(program=FEED_PROGRAM, D1=5.0, F1=20.0, **parameters)


def mill(**parameters) -> ContourInterpolator:
    """One line: X 0 -> 10 at 20 mm/s, from where the command stands."""
    return ContourInterpolator(y_start=0.0, feed=20.0, **parameters)


CYCLES = {"CutSequencer": lathe, "ProgrammableFeed": grinder, "ContourInterpolator": mill}


class Axes:
    """Servo axes that follow the command, but X ``x_off`` mm off it (a servo that stops short) or, ``stuck``, X
    stands where it is (a slide that stopped following)."""

    def __init__(self, controller: CycleController, x_off: float = 0.0, stuck: bool = False):
        self.c, self.x_off, self.stuck = controller, x_off, stuck
        out = controller.outputs()
        self.inputs: dict[str, object] = {p.name: p.start for p in controller.ports("input")}
        for a in controller.AXES:
            self.inputs[f"{a}_pos"] = out[f"{a}_cmd"]
        self.trace: list[dict] = []

    def step(self, **inputs) -> dict:
        self.inputs.update(inputs)
        o = dict(self.c.step(len(self.trace) * DT, DT, self.inputs))
        for button in ("start", "wear_start", "emergency"):
            self.inputs[button] = False
        for a in self.c.AXES:
            if not (self.stuck and a == "x"):
                self.inputs[f"{a}_pos"] = o[f"{a}_cmd"] + (self.x_off if a == "x" else 0.0)
        self.trace.append(o)
        return o

    def messages(self, text: str) -> list[str]:
        return [m for _, m in self.c.messages if text in m]


def busy(o: dict) -> bool:
    return bool(o["busy"] or o.get("run"))


@pytest.mark.parametrize("name", CYCLES)
def test_the_skeleton_owns_the_order_of_a_step(name):
    cls = type(CYCLES[name]())
    assert issubclass(cls, CycleController) and "step" not in vars(cls)


@pytest.mark.parametrize("name", CYCLES)
def test_excess_following_error_stops_under_control_and_start_follows_up(name):
    """A slide that stops following: the alarm when |command - actual| passes max_following_error (said once), the
    command decelerates within accel (no jump) and START re-bases the command on where the axis stands."""
    c = CYCLES[name](max_following_error=0.5)
    axes = Axes(c, stuck=True)
    x0 = axes.inputs["x_pos"]
    axes.step(start=True)
    for _ in range(600):
        axes.step()
    alarm_at = next(k for k, o in enumerate(axes.trace) if o["alarm"])
    # a step judges the command the step before published against the position the servo answers with
    assert abs(axes.trace[alarm_at - 2]["x_cmd"] - x0) <= 0.5 < abs(axes.trace[alarm_at - 1]["x_cmd"] - x0)
    vx = [o["x_vff"] for o in axes.trace]
    assert all(abs(b - a) <= c.accel * DT * (1 + 1e-9) + 1e-12 for a, b in zip(vx, vx[1:]))
    last = axes.trace[-1]
    assert last["alarm"] and not busy(last) and last["x_vff"] == 0.0
    assert len(axes.messages("excess following error")) == 1
    stopped = last["x_cmd"]
    axes.inputs["x_pos"] = x0 + 0.2 * (1 if stopped > x0 else -1)     # where the slide stands at START
    o = axes.step(start=True)
    assert not o["alarm"] and busy(o)
    assert abs(o["x_cmd"] - axes.inputs["x_pos"]) <= 0.01 < abs(stopped - axes.inputs["x_pos"])
    assert len(axes.messages("follow-up: command re-based")) == len(axes.messages("alarm cleared by start")) == 1


@pytest.mark.parametrize("name", CYCLES)
def test_late_arrival_is_an_alarm_latched_like_every_other(name):
    """X stops 0.05 mm short of the command (beyond inpos_band): the motion never ends, and inpos_timeout after the
    command stopped the in-position alarm is raised the one way every alarm is -- latched, said once with its
    time and what follows, the cycle stopped."""
    c = CYCLES[name](inpos_timeout=0.2)
    axes = Axes(c, x_off=0.05)
    axes.step(start=True)
    for _ in range(1500):
        axes.step()
    late = [m for m in axes.messages("in-position check")]
    assert len(late) == 1 and late[0].startswith("t = ") and "after it stopped" in late[0]
    assert late[0].endswith(c.STOP_SAYS)
    alarm_at = next(k for k, o in enumerate(axes.trace) if o["alarm"])
    stop = next(k for k, o in enumerate(axes.trace) if k > 5 and o["x_vff"] == 0.0)
    assert alarm_at - stop == pytest.approx(200, abs=2)
    assert not busy(axes.trace[-1]) and axes.trace[-1]["alarm"]


@pytest.mark.parametrize("name", CYCLES)
@pytest.mark.parametrize("band, ends", [(0.003, False), (0.005, True)])
def test_a_motion_ends_only_within_inpos_band_of_the_own_command(name, band, ends):
    c = CYCLES[name](inpos_band=band, inpos_timeout=0.5)
    axes = Axes(c, x_off=0.004)
    axes.step(start=True)
    first = c.command_point()
    for _ in range(700):
        axes.step()
        if c.command_point() != first and axes.trace[-1]["x_vff"] == 0.0:
            break                                   # the first motion has stopped
    stop = len(axes.trace)
    for _ in range(100):
        axes.step()
    moved_on = any(o["x_vff"] != 0.0 or o["y_vff" if "y_vff" in o else "z_vff"] != 0.0 for o in axes.trace[stop:])
    finished = any(o.get("done") or (o.get("pc", 0) == 1) for o in axes.trace[stop:])
    assert (moved_on or finished) == ends
    assert not any(o["alarm"] for o in axes.trace)


@pytest.mark.parametrize("name", CYCLES)
def test_a_bad_input_stops_and_takes_no_start_in_its_step(name):
    """A NaN position mid-motion: the alarm, a controlled stop; a START in that very step is not taken, a START
    while the motion still decelerates is ignored and said, a START at rest runs again."""
    c = CYCLES[name]()
    axes = Axes(c)
    axes.step(start=True)
    for _ in range(100):
        axes.step()
    x = axes.inputs["x_pos"]
    o = axes.step(start=True, x_pos=float("nan"))
    assert o["alarm"] and not busy(o) and o["x_vff"] != 0.0          # decelerating, not jumping to rest
    axes.inputs["x_pos"] = x
    axes.step()                                                       # START released
    o = axes.step(start=True)
    assert o["alarm"] and not busy(o)
    assert len(axes.messages("start ignored")) == 1 and axes.messages("still decelerating")
    while axes.trace[-1]["x_vff"] != 0.0:
        axes.step()
        assert len(axes.trace) < 5000
    o = axes.step(start=True)
    assert not o["alarm"] and busy(o)


@pytest.mark.parametrize("name, at_rest_too", [("CutSequencer", True), ("ProgrammableFeed", False),
                                                ("ContourInterpolator", False)])
def test_the_following_error_policy(name, at_rest_too):
    """The one policy that differs (CycleController.watching_following_error says why): the lathe judges the
    following error at rest too, the grinder and the mill only while they run a cycle."""
    c = CYCLES[name](max_following_error=0.5)
    axes = Axes(c)
    axes.step()
    o = axes.step(x_pos=axes.inputs["x_pos"] + 0.6)                # pushed off the command, at rest
    assert o["alarm"] == at_rest_too and not busy(o)
