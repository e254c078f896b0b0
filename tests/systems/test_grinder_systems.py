"""Closed loop through the built FMUs: grinder_feed and grinder_envelope."""

import numpy as np
import pytest

from ncfmu.project import simulate

pytestmark = pytest.mark.slow        # whole systems in closed loop: not in the fast subset

BAND = 0.005


# The cycle's depths, rates and spark-out, and the envelope, are physics.check_grinder_feed/_envelope, which
# test_interop runs on these same results and on libcosim's. Here: what only ncfmu's run records.


def test_normal_cycle_ends_idle_without_alarm(grinder_feed):
    assert not grinder_feed["feed.run"][-1] and not grinder_feed["feed.alarm"].any()


@pytest.mark.parametrize("strike, phase", [(3.0, "rough"), (20.0, "fine"), (31.0, "dwell"), (32.2, "return")])
def test_emergency_through_the_fmus(project, strike, phase):
    r = simulate("grinder_feed", stop_time=strike + 1.5, start_values={"panel.emergency_at": strike})
    after = r.time > strike
    assert r["feed.emergency_active"][after].any()
    assert r["x_axis.pos"][-1] == pytest.approx(0.0, abs=BAND)
    assert r["feed.return_counter_x"][-1] == pytest.approx(0.0, abs=1e-9)
    assert not r["feed.emergency_active"][-1] and not r["feed.run"][-1]
    assert np.ptp(r["x_axis.pos"][r.time > r.time[-1] - 0.2]) < 1e-3    # stopped at the origin


def test_wear_compensation_then_normal_cycle(project):
    # the wear cycle feeds D1 = 0.02 mm at F2 = 0.005 mm/s: 4 s; START1 after it
    r = simulate("grinder_feed", stop_time=39.0,
                 start_values={"panel.wear_start_at": 0.1, "panel.start_at": 5.0})
    x = r["x_axis.pos"]
    assert x.max() == pytest.approx(4.32, abs=BAND)
    assert x[-1] == pytest.approx(0.02, abs=BAND)
    assert r["feed.return_counter_x"][-1] == pytest.approx(0.0, abs=1e-9)


def test_m_word_waits_for_mfin_from_the_panel(project):
    program = "M0: X+D3F7; M1: M2; M2: X-D3F7; M3: END; M41: XF7S1; M42: END; M43: X+D1F2S4; M44: END"
    r = simulate("grinder_feed", stop_time=3.0, start_values={"feed.program": program, "panel.mfin_delay": 0.8})
    waiting = r["feed.m_active"] == 2
    t = r.time[waiting]
    assert t[-1] - t[0] == pytest.approx(0.8, abs=0.003)
    assert np.ptp(r["x_axis.pos"][waiting]) < 1e-3            # no motion while waiting
    assert r["x_axis.pos"][-1] == pytest.approx(0.0, abs=BAND)
    # EMB aborts the wait
    r = simulate("grinder_feed", stop_time=3.0, start_values={"feed.program": program, "panel.mfin_delay": 100.0,
                                                              "panel.emergency_at": 1.5})
    assert r["feed.m_active"][r.time < 1.5].max() == 2 and r["feed.m_active"][-1] == 0
    assert r["x_axis.pos"][-1] == pytest.approx(0.0, abs=BAND) and not r["feed.emergency_active"][-1]


def test_envelope_default_program_never_alarms(grinder_envelope):
    assert not grinder_envelope["limiter.alarm"].any() and not grinder_envelope["feed.alarm"].any()


def test_envelope_stops_a_program_entering_the_headstock_zone(project):
    """With X at 150 (work zone, X <= 180) the table is sent back to Y = 250 (headstock zone, X <= 80)."""
    program = "M0: Y+D1F7; M1: X+D2F7; M2: Y-D6F7; M3: END; M41: XF7S1; M42: YF7S1; M43: END; M45: END"
    r = simulate("grinder_envelope", stop_time=9.0, start_values={"feed.program": program, "feed.D6": 250.0})
    assert r["limiter.alarm"].any() and r["feed.alarm"].any()
    assert r["limiter.blocked"].max() == 2                    # Y- blocked (the table carried the wheel in)
    x, y = r["x_axis.pos"], r["y_axis.pos"]
    assert y[x > 80.0].min() > 350.0                          # never in the headstock zone with X > 80
    # EMB backs out: X retracts first, then Y returns to the origin
    r = simulate("grinder_envelope", stop_time=16.0, start_values={"feed.program": program, "feed.D6": 250.0,
                                                                   "panel.emergency_at": 9.0})
    assert r["x_axis.pos"][-1] == pytest.approx(0.0, abs=BAND) and r["y_axis.pos"][-1] == pytest.approx(100.0, abs=BAND)
    assert not r["limiter.alarm"][-1]
