"""Stops, interlocks and restarts through the built FMUs: every reproduction of a reported defect, closed loop
(fmpy master) or stepped by hand. Each failed before its fix."""

import math

import numpy as np
import pytest
from fakes import unwired

from ncfmu.controllers.limiter import AreaLimiter
from ncfmu.project import simulate

DT = 1e-3
BAND = 0.005
GRINDER_TABLE = {"n_regions": 4, "region[1].ref_max": 200.0, "region[1].lim_min": -100.0, "region[1].lim_max": 250.0,
                 "region[2].ref_max": 350.0, "region[2].lim_min": -100.0, "region[2].lim_max": 80.0,
                 "region[3].ref_max": 800.0, "region[3].lim_min": -100.0, "region[3].lim_max": 180.0,
                 "region[4].ref_max": 1000.0, "region[4].lim_min": -100.0, "region[4].lim_max": 60.0}


def accelerations(r, name):
    return np.abs(np.diff(r[name])) / DT


# -- 1. the limiter never deadlocks (AreaLimiter FMU stepped by hand) -------------------------------
def step_limiter(runner, t, **inputs):
    runner.set(**inputs)
    runner.slave.do_step(t, DT)
    return {k: runner.get(k) for k in ("ref_cmd", "lim_cmd", "ref_vff", "lim_vff", "alarm", "blocked")}


def test_predictive_limiter_follows_a_fast_ramp_inside_the_envelope(fmus, fmu_runner):
    """Y held at 100 (X <= 250), X commanded 50 -> 240 mm in 1 s: stopped at 149.38 for ever before."""
    r = fmu_runner(fmus["AreaLimiter"]).start(predictive=True, use_actual=True, ref_start=100.0, lim_start=50.0,
                                              **GRINDER_TABLE)
    t, x, outs = 0.0, 50.0, []
    for _ in range(2000):
        v = 190.0 if x < 240.0 else 0.0
        x = min(x + 190.0 * DT, 240.0) if v else x
        o = step_limiter(r, t, ref_cmd_in=100.0, lim_cmd_in=x, ref_vff_in=0.0, lim_vff_in=v, ref_pos=100.0,
                         lim_pos=outs[-1]["lim_cmd"] if outs else 50.0)
        outs.append(o)
        t += DT
        assert o["lim_cmd"] <= 250.0
    assert outs[-1]["lim_cmd"] == 240.0 and not outs[-1]["alarm"] and outs[-1]["blocked"] == 0


def test_limiter_started_away_from_an_inside_command_arrives(fmus, fmu_runner):
    r = fmu_runner(fmus["AreaLimiter"]).start(predictive=True, ref_start=100.0, lim_start=0.0, **GRINDER_TABLE)
    t, outs = 0.0, []
    for _ in range(2000):
        outs.append(step_limiter(r, t, ref_cmd_in=100.0, lim_cmd_in=100.0, ref_vff_in=0.0, lim_vff_in=0.0,
                                 ref_pos=100.0, lim_pos=outs[-1]["lim_cmd"] if outs else 0.0))
        t += DT
    vff = np.array([o["lim_vff"] for o in outs])
    assert outs[-1]["lim_cmd"] == 100.0 and not outs[-1]["alarm"]
    assert np.abs(np.diff(vff)).max() <= 500.0 * DT * (1 + 1e-9)          # a rejoin, not a jump


def test_limiter_holds_absurd_inputs_with_an_alarm(fmus, fmu_runner):
    """ref_vff_in = 1e300 with a 1000 mm command jump went straight to the servo."""
    r = fmu_runner(fmus["AreaLimiter"]).start(ref_start=0.0, lim_start=0.0)
    t = 0.0
    for _ in range(10):
        step_limiter(r, t, ref_cmd_in=0.0, lim_cmd_in=0.0, ref_vff_in=0.0, lim_vff_in=0.0, ref_pos=0.0, lim_pos=0.0)
        t += DT
    for _ in range(20):
        o = step_limiter(r, t, ref_cmd_in=1000.0, lim_cmd_in=0.0, ref_vff_in=1e300, lim_vff_in=0.0, ref_pos=0.0,
                         lim_pos=0.0)
        t += DT
        assert o["alarm"] and abs(o["ref_cmd"]) < 1e-9 and o["ref_vff"] == 0.0
    assert sum(lvl == "error" for lvl, _ in r.slave.messages) == 1
    assert any("ref_vff_in" in msg for _, msg in r.slave.messages)


# -- 2. stops decelerate within accel; the predictive limiter stops at the boundary --------------------
@pytest.fixture(scope="module")
def chuck_runs(project):
    """A cut lengthened into the chuck zone (Zp 50 -> Z -48, the zone starts at -45) at 40 mm/s."""
    long_fast = {"seq.block[1].Zp": 50.0, "seq.block[1].feed": 40.0}
    return {predictive: simulate("lathe_roughing", stop_time=4.0,
                                 start_values={**long_fast, "limiter.predictive": predictive})
            for predictive in (True, False)}


@pytest.mark.slow
def test_predictive_limiter_stops_the_cut_at_the_chuck_without_a_slam(chuck_runs):
    r = chuck_runs[True]
    z, zc = r["z_axis.pos"], r["limiter.ref_cmd"]
    assert r["limiter.alarm"].any() and r["seq.alarm"][-1]
    assert z.min() > -45.0 and zc.min() > -45.0                         # the actual axis never enters
    assert z.min() < -44.0                                              # stopped at the boundary, not early
    assert accelerations(r, "limiter.ref_vff").max() <= 500.0 * (1 + 1e-6)
    assert accelerations(r, "seq.z_vff").max() <= 500.0 * (1 + 1e-6)
    assert np.abs(r["z_axis.following_error"]).max() < 0.05             # no torque-limit braking


@pytest.mark.slow
def test_non_predictive_limiter_overshoot_within_its_documented_bound(chuck_runs):
    r = chuck_runs[False]
    bound = AreaLimiter().overshoot_bound(40.0, DT)
    assert r["limiter.alarm"].any() and r["seq.alarm"][-1]
    assert -45.0 - bound <= r["limiter.ref_cmd"].min() < -45.0
    assert -45.0 - bound <= r["z_axis.pos"].min()
    assert accelerations(r, "limiter.ref_vff").max() <= 500.0 * (1 + 1e-6)


# -- 3. a move held downstream never counts as done ------------------------------------------------
@pytest.mark.slow
def test_taper_pass_held_in_x_never_ends_short_with_the_alarm_unwired(project, tmp_path):
    """With limiter.alarm -> seq.alarm_in removed and X limited to >= 27.2 (a shoulder), the first
    taper pass (X 28.5 -> 27.0 over the cut) was held at X 27.2 while Z went on, and ended there: 'done',
    no alarm. Now the sequencer waits for its own end point and raises its in-position alarm."""
    r = simulate(unwired("lathe_taper", tmp_path), stop_time=20.0, start_values={"limiter.region[2].lim_min": 27.2})
    x, sub, t = r["x_axis.pos"], r["seq.subcycle"], r.time
    assert r["limiter.alarm"].any()
    assert x.min() >= 27.2 - 1e-6                                       # held by the limiter
    first_cut = np.flatnonzero(sub == 2)
    assert first_cut.size and not (sub[first_cut[0]:] == 3).any()     # the held cut never "ends"
    assert r["seq.alarm"][-1] and not r["seq.done"].any()
    alarm_at = t[np.argmax(r["seq.alarm"])]
    end_of_command = t[first_cut[0]] + 42.0 / 4.0                       # the cut's command ends ~10.5 s later
    assert end_of_command < alarm_at < end_of_command + 2.0 + 0.5       # inpos_timeout = 2 s after it


@pytest.mark.slow
def test_cut_held_at_the_chuck_never_ends_short_with_the_alarm_unwired(project, tmp_path):
    """The same with Z held at the chuck boundary (Zp 50): no sub-cycle after the held cut."""
    r = simulate(unwired("lathe_taper", tmp_path), stop_time=15.0, start_values={"seq.block[1].Zp": 50.0})
    cut = r["seq.subcycle"] == 2
    assert cut.any() and r["limiter.alarm"].any()
    # the sequencer's own alarm (excess following error) stops it; no sub-cycle after the held cut
    assert r["seq.alarm"][-1]
    first_hold = np.argmax(r["limiter.alarm"])
    assert not (r["seq.subcycle"][first_hold:] == 3).any()
    assert r["z_axis.pos"].min() > -45.0


# -- 5. ProgrammableFeed restart never plunges the wheel ---------------------------------------------
@pytest.mark.slow
def test_grinder_restart_after_an_alarm_returns_to_the_origin_first(project, tmp_path):
    """alarm_in at 3 s stops the rough grind near X 4.05; START again at 5 s."""
    csv_file = tmp_path / "alarm.csv"
    csv_file.write_text('"time","feed.alarm_in"\n0.0,0\n3.0,1\n3.1,0\n')
    r = simulate("grinder_feed", stop_time=42.0, input_csv=csv_file, start_values={"panel.restart_at": 5.0})
    t, x, rc = r.time, r["x_axis.pos"], r["feed.return_counter_x"]
    held = (t > 3.5) & (t < 5.0)
    assert r["feed.alarm"][held].all() and 4.0 < x[held].min() and np.ptp(x[held]) < 1e-3
    x_rest = x[held][-1]
    back = np.argmax((t > 5.0) & (np.abs(rc) < 1e-9))                  # at the feed origin again
    assert t[back] > 5.0 and x[back] == pytest.approx(0.0, abs=BAND)
    assert x[(t > 5.0) & (t < t[back])].max() <= x_rest + 1e-3          # nothing toward the work first
    # then the whole cycle from M0: rough, fine, spark-out, return
    after = t > t[back]
    assert x[after].max() == pytest.approx(4.3, abs=BAND)
    assert x[-1] == pytest.approx(0.0, abs=BAND) and not r["feed.alarm"][-1] and not r["feed.run"][-1]


# -- 6. the M/MFIN handshake --------------------------------------------------------------------------
def test_two_m_words_in_a_row_each_wait_for_their_own_mfin(project):
    program = "M0: M1; M1: M2; M2: X+D3F7; M3: X-D3F7; M4: END; M41: XF7S1; M42: END; M43: END"
    r = simulate("grinder_feed", stop_time=3.0, start_values={"feed.program": program, "panel.mfin_delay": 0.4})
    m, t = r["feed.m_active"], r.time
    changes = [(int(a), int(b)) for a, b in zip(m, m[1:]) if a != b]
    assert changes[:4] == [(0, 1), (1, 0), (0, 2), (2, 0)]
    for word in (1, 2):
        waited = t[m == word]
        assert waited[-1] - waited[0] == pytest.approx(0.4, abs=0.003)
    assert r["x_axis.pos"].max() == pytest.approx(4.0, abs=BAND) and r["x_axis.pos"][-1] == pytest.approx(0.0, abs=BAND)


# -- 7. dwell_left is exactly 0 after the spark-out ---------------------------------------------------
@pytest.mark.slow
def test_dwell_left_is_exactly_zero_after_the_dwell(grinder_feed):
    r = grinder_feed
    dwelling = r["feed.pc"] == 3
    assert r["feed.dwell_left"][dwelling].max() == pytest.approx(1.5, abs=2 * DT)
    assert (r["feed.dwell_left"][~dwelling] == 0.0).all()


# -- 8. one block series, two diameters; restart retracts X first --------------------------------------
@pytest.mark.slow
def test_stepped_shaft_from_one_block_series(project):
    r = simulate("lathe_roughing", stop_time=50.0, start_values={
        "seq.block[1].Xf": 1.0, "seq.block[1].Xd": 0.5, "seq.block[1].N": 2,
        "seq.block[2].own_stp": True, "seq.block[2].x_stp": 29.0, "seq.block[2].z_stp": 2.0,
        "seq.block[2].Xf": 1.0, "seq.block[2].Xd": 0.5, "seq.block[2].N": 2, "seq.block[2].Zp": 15.0,
        "seq.block[2].feed": 4.0})
    from physics import intervals
    cuts = intervals(r["seq.subcycle"], 2)
    assert len(cuts) == 4 and r["seq.done"][-1] and not r["seq.alarm"].any()
    ends = [(round(float(r["x_axis.pos"][b - 1]), 3), round(float(r["z_axis.pos"][b - 1]), 3)) for a, b in cuts]
    assert ends == [(28.5, -40.0), (28.0, -40.0), (27.5, -13.0), (27.0, -13.0)]
    assert r["x_axis.pos"][-1] == pytest.approx(29.0, abs=BAND) and r["z_axis.pos"][-1] == pytest.approx(2.0, abs=BAND)


@pytest.mark.slow
def test_lathe_restart_after_an_alarm_retracts_x_before_z_moves(project, tmp_path):
    csv_file = tmp_path / "alarm.csv"
    csv_file.write_text('"time","seq.alarm_in"\n0.0,0\n3.0,1\n3.1,0\n')
    r = simulate(unwired("lathe_roughing", tmp_path), stop_time=9.0, input_csv=csv_file,
                 start_values={"panel.restart_at": 4.0})
    t, x, z = r.time, r["x_axis.pos"], r["z_axis.pos"]
    stopped = (t > 3.5) & (t < 4.0)
    assert r["seq.alarm"][stopped].all() and r["seq.subcycle"][t < 3.0][-1] == 2     # stopped in the cut
    x_rest, z_rest = x[stopped][-1], z[stopped][-1]
    assert z_rest < 0.0 and x_rest < 29.0
    approach = (t > 4.0) & (r["seq.subcycle"] == 0) & r["seq.busy"].astype(bool)
    moving_z = approach & (np.abs(z - z_rest) > 0.01)
    assert moving_z.any() and (x[moving_z] > 30.0 - 0.01).all()           # Z travels only with X clear
    assert math.isclose(r["seq.z_cmd"][approach][-1], 2.0, abs_tol=1e-9)
    assert r["seq.subcycle"][t > 8.0].max() >= 1 and not r["seq.alarm"][t > 4.1].any()


# -- 4. absurd positions and out-of-range overrides in every controller FMU ----------------------------
@pytest.mark.parametrize("model, start, axis_inputs", [
    ("ProgrammableFeed", "start", {"x_pos": 0.0, "y_pos": 0.0}),
    ("ContourInterpolator", "start", {"x_pos": 0.0, "y_pos": -10.0}),
    ("CutSequencer", "start", {"x_pos": 10.0, "z_pos": 0.0}),                # its start point as the FMU starts
])
@pytest.mark.parametrize("bad", [1e300, -1e300, "jump"])
def test_absurd_position_input_alarms_and_stops_under_control(fmus, fmu_runner, model, start, axis_inputs, bad):
    r = fmu_runner(fmus[model]).start()
    axes = sorted(axis_inputs)
    r.set(**{start: True}, **axis_inputs)
    t = 0.0
    for _ in range(200):
        r.slave.do_step(t, DT)
        t += DT
        r.set(**{a: r.get(a.replace("_pos", "_cmd")) for a in axes})
    assert not r.get("alarm")
    first = axes[0]
    value = r.get(first.replace("_pos", "_cmd")) + 1000.0 if bad == "jump" else bad
    r.set(**{first: value})
    vffs = []
    for _ in range(100):
        r.slave.do_step(t, DT)
        t += DT
        vffs.append([r.get(a.replace("_pos", "_vff")) for a in axes])
        assert all(math.isfinite(r.get(a.replace("_pos", "_cmd"))) for a in axes)
    assert r.get("alarm")
    assert vffs[-1] == [0.0, 0.0]
    errors = [msg for lvl, msg in r.slave.messages if lvl == "error"]
    assert len(errors) == 1 and first in errors[0]


def test_override_out_of_range_is_clamped_and_said_once(fmus, fmu_runner):
    r = fmu_runner(fmus["ContourInterpolator"]).start()
    r.set(start=True, x_pos=0.0, y_pos=-10.0, feed_override=5.0)
    t = 0.0
    for _ in range(1000):
        r.slave.do_step(t, DT)
        t += DT
        r.set(x_pos=r.get("x_cmd"), y_pos=r.get("y_cmd"))
    speed = math.hypot(r.get("x_vff"), r.get("y_vff"))
    assert speed == pytest.approx(5.0 * 1.5)                  # clamped to 150 %
    warnings = [msg for lvl, msg in r.slave.messages if "feed_override" in msg]
    assert len(warnings) == 1 and "clamped to 1.5" in warnings[0]
