"""Defects a red-team review of the issue-11 change demonstrated on the plain controllers, each fixed and kept
here as a test (the scenario, then what must hold)."""

import math

import pytest

from ncfmu.controllers import Block, ContourInterpolator, CutSequencer, ProgrammableFeed
from ncfmu.controllers.limiter import AreaLimiter
from ncfmu.errors import ConfigError
from ncfmu.systems import parameters

#: Scenario values from the system definitions (the controllers' own defaults are neutral).
GRINDER_FEED, MILL = parameters("grinder_feed", "feed"), parameters("mill_contour", "contour")

DT = 1e-3
TABLE = [(200.0, -100.0, 250.0), (350.0, -100.0, 80.0)]


def ramp(p, v, target, vmax, accel=500.0):
    """An acceleration-limited upstream command toward ``target``."""
    d = target - p
    vt = math.copysign(min(vmax, math.sqrt(2 * accel * abs(d))), d) if abs(d) > 1e-12 else 0.0
    vn = min(max(vt, v - accel * DT), v + accel * DT)
    pn = p + 0.5 * (v + vn) * DT
    if (target - pn) * d <= 0 and abs(vn) <= accel * DT:
        pn, vn = target, 0.0
    return pn, vn


@pytest.mark.parametrize("predictive", [False, True])
def test_limiter_comes_back_onto_the_table(predictive):
    """The reference axis ran past the table's last boundary; backing it out must not be blocked too."""
    lim = AreaLimiter.with_table(TABLE, ref_start=300.0, lim_start=50.0, predictive=predictive)
    r, vr, out = 300.0, 0.0, dict(lim.outputs())
    for k in range(8000):
        r, vr = ramp(r, vr, 360.0 if k < 2000 else 300.0, 100.0)
        out = lim.step(k * DT, DT, {"ref_cmd_in": r, "lim_cmd_in": 50.0, "ref_vff_in": vr, "lim_vff_in": 0.0,
                                    "ref_pos": out["ref_cmd"], "lim_pos": 50.0})
    assert out["ref_cmd"] == 300.0 and not out["alarm"] and out["blocked"] == 0


def test_limiter_releases_a_back_out_that_stops_just_inside():
    lim = AreaLimiter.with_table(TABLE, ref_start=300.0, lim_start=0.0)
    x, vx, out = 0.0, 0.0, dict(lim.outputs())
    for k in range(12000):
        x, vx = ramp(x, vx, 100.0 if k < 2000 else 79.95, 100.0 if k < 2000 else 5.0)
        out = lim.step(k * DT, DT, {"ref_cmd_in": 300.0, "lim_cmd_in": x, "ref_vff_in": 0.0, "lim_vff_in": vx,
                                    "ref_pos": 300.0, "lim_pos": out["lim_cmd"]})
    assert out["lim_cmd"] == 79.95 and not out["alarm"] and out["blocked"] == 0


def test_predictive_limiter_needs_a_margin():
    with pytest.raises(ConfigError) as err:
        AreaLimiter.with_table(TABLE, predictive=True, margin=0.0)
    assert err.value.variable == "margin"
    AreaLimiter.with_table(TABLE, predictive=False, margin=0.0)        # without predictive it is unused


def test_sequencer_restart_clears_every_block_before_travelling_in_z():
    """Block 2 (own STP X 45, taper) stopped by an alarm at X 41.5: the approach travels in Z above X 45."""
    b1 = Block(Xf=1.0, Xd=0.5, Xp=0.0, Zp=40.0, N=2, feed=4.0, rapid=50.0)
    b2 = Block(Xf=1.0, Xd=0.5, Xp=3.0, Zp=30.0, N=2, feed=4.0, rapid=50.0, own_stp=True, x_stp=45.0, z_stp=-40.0)
    seq = CutSequencer.with_blocks([b1, b2], x_start=30.0, z_start=2.0)
    inputs = dict(CutSequencer.default_inputs(), x_pos=30.0, z_pos=2.0)
    k = 0

    def step(**kw):
        nonlocal k
        inputs.update(kw)
        out = dict(seq.step(k * DT, DT, inputs))
        k += 1
        inputs["x_pos"], inputs["z_pos"] = out["x_cmd"], out["z_cmd"]
        return out
    step(start=True)
    out = step(start=False)
    while not (out["block_no"] == 2 and out["subcycle"] == 2 and out["pass_no"] == 2 and out["z_cmd"] < -55.0):
        out = step()
    for _ in range(500):
        out = step(alarm_in=True)
    z_rest = out["z_cmd"]
    step(alarm_in=False, start=True)
    out = step(start=False)
    while out["subcycle"] != 1:
        out = step()
        if z_rest + 1e-9 < out["z_cmd"] < 2.0 - 1e-9:          # Z travelling back to STP (30, 2)
            assert out["x_cmd"] >= 45.0 - 1e-9


def test_emb_during_the_stop_after_an_alarm_still_returns():
    f = ProgrammableFeed(**{**GRINDER_FEED, "F7": 100.0})
    inputs = dict(ProgrammableFeed.default_inputs())

    def step(k, **kw):
        inputs.update(kw)
        out = dict(f.step(k * DT, DT, inputs))
        inputs["x_pos"], inputs["y_pos"] = out["x_cmd"], out["y_cmd"]
        return out
    step(0, start=True)
    for k in range(1, 31):
        step(k, start=False)
    step(31, alarm_in=True)                               # the limiter stops the rapid approach
    step(32, emergency=True)                              # EMB while it still decelerates
    for k in range(33, 3033):
        out = step(k, emergency=False)
    assert out["x_cmd"] == pytest.approx(0.0, abs=1e-9) and out["return_counter_x"] == pytest.approx(0.0, abs=1e-9)


def test_restart_after_a_held_wear_feed_never_feeds_toward_the_work():
    f = ProgrammableFeed(**{**GRINDER_FEED, "F2": 0.05})
    inputs = dict(ProgrammableFeed.default_inputs())
    held, k = True, 0

    def step(**kw):
        nonlocal k
        inputs.update(kw)
        out = dict(f.step(k * DT, DT, inputs))
        k += 1
        inputs["x_pos"], inputs["y_pos"] = (0.0 if held else out["x_cmd"]), out["y_cmd"]
        return out
    step(wear_start=True)
    for _ in range(3000):
        out = step(wear_start=False)
    assert out["alarm"]                                   # the in-position check
    # the S4 feed that fell short was never counted: the wheel is at the feed origin (X 0), no return needed,
    # and no phantom "return" of +0.02 mm toward the work
    assert out["return_counter_x"] == 0.0
    held = False
    step(start=True)
    assert not any("returning to the origin" in m for _, m in f.take_messages())


def test_contour_end_not_reached_raises_the_in_position_alarm():
    c = ContourInterpolator(**{**MILL, "feed": 50.0, "approach_feed": 50.0})
    inputs = dict(ContourInterpolator.default_inputs(), x_pos=c.x_start, y_pos=c.y_start)
    for k in range(10000):
        inputs["start"] = k == 1
        out = c.step(k * DT, DT, inputs)
        inputs["x_pos"] = out["x_cmd"]
        inputs["y_pos"] = out["y_cmd"] - 0.1                 # Y lags 0.1 mm: short of the end point at the end
    assert out["alarm"] and not out["done"] and not out["busy"]
    assert any("in-position" in m for _, m in c.take_messages())


def test_mfin_stuck_high_is_said():
    program = "M0: M2; M1: END; M41: XF7S1; M42: END; M43: X+D1F2S4; M44: END"
    f = ProgrammableFeed(**{**GRINDER_FEED, "program": program})
    inputs = dict(ProgrammableFeed.default_inputs(), mfin=True)
    for k in range(2000):
        inputs["start"] = k == 1
        out = f.step(k * DT, DT, inputs)
    assert out["m_active"] == 0 and out["pc"] == 0         # the strobe waits for MFIN to drop
    said = [m for _, m in f.take_messages() if "waits for MFIN to drop" in m]
    assert len(said) == 1
