"""The sequencer's thread passes in plain Python (an ideal spindle and ideal axes, no FMU): the start at the
one-revolution marker (+ thread_shift), Z from the actual spindle angle, feed override ignored, feed hold at the
thread block's end, and a bad encoder angle as an alarm."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ncfmu.controllers.sequencer import CutSequencer

PROGRAM = """G97 S600 M03
G00 X30. Z4.
G92 X27.6 Z-10. F1.5
G00 X40.
M30"""
DT = 1e-3
RPM = 600.0


def _machine(program: str = PROGRAM, **parameters):
    seq = CutSequencer(program=program, x_start=20.0, z_start=10.0, **parameters)
    seq.reset()
    return seq


def _run(seq, steps: int, turns_at=lambda t: RPM / 60.0 * t, override=1.0, hold=lambda t: False):
    """Steps with the axes where the command was (ideal servos); rows of (t, turns, outputs)."""
    inputs = dict(start=False, feed_hold=False, feed_override=override, alarm_in=False, x_pos=20.0, z_pos=10.0,
                  x_in_position=True, z_in_position=True, spindle_speed=RPM, revolutions=0.0, optional_stop=False,
                  block_delete=False)
    rows = []
    for k in range(steps):
        t = k * DT
        inputs["start"] = 5 <= k < 10
        inputs["feed_hold"] = hold(t)
        inputs["revolutions"] = turns_at(t)
        out = dict(seq.step(t, DT, inputs))
        inputs["x_pos"], inputs["z_pos"] = out["x_cmd"], out["z_cmd"]
        rows.append((t, inputs["revolutions"], out))
    return rows


def _threading(rows):
    return [(t, turns, out) for t, turns, out in rows if out["threading"]]


@pytest.mark.parametrize("shift", [0.0, 120.0])
def test_the_cut_starts_at_the_marker_and_z_follows_the_spindle(shift):
    rows = _run(_machine(thread_shift=shift), 4000)
    cut = _threading(rows)
    assert cut and all(out["canned_cycle"] == 92 for _, _, out in cut)
    t0, turns0, first = cut[0]
    marker = math.floor(turns0 - shift / 360.0) + shift / 360.0      # the marker (+ shift) passed in this step
    assert 0.0 <= turns0 - marker <= RPM / 60.0 * DT + 1e-12
    before = [turns for t, turns, out in rows if t < t0 and out["line"] == 3 and out["subcycle"] == 2]
    assert before and max(before) < marker                        # waited at the start for it
    for _, turns, out in cut:
        assert out["z_cmd"] == pytest.approx(4.0 - 1.5 * (turns - marker), abs=1e-9)
        assert out["x_cmd"] == pytest.approx(13.8) and out["z_vff"] == 0.0
    assert cut[-1][2]["z_cmd"] > -10.0 and any(out["z_cmd"] == pytest.approx(-10.0) for _, _, out in rows)


def test_feed_override_does_not_change_the_thread():
    full = _threading(_run(_machine(), 4000))
    half = _threading(_run(_machine(), 4000, override=0.5))
    assert len(full) == len(half)
    assert all(a[2]["z_cmd"] == b[2]["z_cmd"] for a, b in zip(full, half))


def test_feed_hold_during_the_thread_takes_effect_at_its_end():
    reference = _run(_machine(), 4000)
    start = _threading(reference)[0][0]
    rows = _run(_machine(), 4000, hold=lambda t: start + 0.2 <= t < start + 3.0)
    cut = _threading(rows)
    assert [out["z_cmd"] for _, _, out in cut] == [out["z_cmd"] for _, _, out in _threading(reference)]
    end = cut[-1][0]
    held = [out for t, _, out in rows if end + 0.05 < t < start + 3.0]
    assert held and all(out["subcycle"] == 3 and out["x_cmd"] == pytest.approx(13.8) for out in held)   # SC3 held
    assert any(out["x_cmd"] > 14.0 for t, _, out in rows if t > start + 3.0)                          # released


def test_feed_hold_before_the_marker_holds_the_start():
    rows = _run(_machine(), 3000, hold=lambda t: t < 1.5)
    cut = _threading(rows)
    assert cut and cut[0][0] >= 1.5


@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_a_bad_encoder_angle_is_an_alarm_and_never_a_command(bad):
    reference = _threading(_run(_machine(), 4000))
    t_bad = reference[10][0]
    rows = _run(_machine(), 2000, turns_at=lambda t: bad if t >= t_bad else RPM / 60.0 * t)
    after = [out for t, _, out in rows if t >= t_bad]
    assert after[0]["alarm"] and not after[-1]["busy"]
    assert all(math.isfinite(out["z_cmd"]) and math.isfinite(out["x_cmd"]) for out in after)


def test_a_spindle_turning_backwards_during_the_thread_is_an_alarm():
    reference = _threading(_run(_machine(), 4000))
    t_back = reference[10][0]
    rows = _run(_machine(), 2000, turns_at=lambda t: RPM / 60.0 * (t if t < t_back else 2 * t_back - t))
    assert any(out["alarm"] for t, _, out in rows if t >= t_back)


def test_a_state_taken_mid_thread_restores_and_a_forged_one_is_refused():
    import copy
    seq = _machine()
    inputs = dict(start=False, feed_hold=False, feed_override=1.0, alarm_in=False, x_pos=20.0, z_pos=10.0,
                  x_in_position=True, z_in_position=True, spindle_speed=RPM, revolutions=0.0, optional_stop=False,
                  block_delete=False)
    for k in range(600):
        inputs["start"] = 5 <= k < 10
        inputs["revolutions"] = RPM / 60.0 * k * DT
        out = seq.step(k * DT, DT, inputs)
        inputs["x_pos"], inputs["z_pos"] = out["x_cmd"], out["z_cmd"]
    assert out["threading"]
    restored = copy.deepcopy(seq)
    assert restored.check_state(inputs) is None and restored.threading
    forged = copy.deepcopy(seq)
    forged.thread_rev0 = math.nan
    assert "thread_rev0" in (forged.check_state(inputs) or "")


def _servo_thread(rpm: float):
    """A G92 pass driving two ServoAxis models (ideal, Python) directly, no limiter between: (turns, z, z_cmd)
    while the pass follows the spindle."""
    from ncfmu.servo.axis import ServoAxis
    program = PROGRAM.replace("S600", f"S{rpm:g}")
    seq = _machine(program)
    axes = {"x": ServoAxis(pos_start=20.0, ideal=True), "z": ServoAxis(pos_start=10.0, ideal=True)}
    for axis in axes.values():
        axis.reset()
    inputs = dict(start=False, feed_hold=False, feed_override=1.0, alarm_in=False, x_pos=20.0, z_pos=10.0,
                  x_in_position=True, z_in_position=True, spindle_speed=rpm, revolutions=0.0, optional_stop=False,
                  block_delete=False)
    rows = []
    for k in range(3000):
        t = k * DT
        inputs["start"] = 5 <= k < 10
        inputs["revolutions"] = rpm / 60.0 * t
        out = seq.step(t, DT, inputs)
        assert not out["alarm"]
        for name, axis in axes.items():
            moved = axis.step(t, DT, {"pos_cmd": out[f"{name}_cmd"], "vel_ff": out[f"{name}_vff"], "enable": True})
            inputs[f"{name}_pos"], inputs[f"{name}_in_position"] = moved["pos"], moved["in_position"]
        if out["threading"]:
            rows.append((inputs["revolutions"], inputs["z_pos"], out["z_cmd"]))
    return (np.array(c) for c in zip(*rows))


def test_without_the_limiter_the_servo_lag_is_uncompensated_and_sets_the_incomplete_lead():
    """Z commanded from the spindle with no feed-forward: the position loop lags v/Kv (the servo's design, Kv =
    30/s), and the local lead reaches (1 - a) of the lead after Fanuc's incomplete thread
    delta1 = (v/Kv) (ln(1/a) - 1) of Z -- longer at the higher speed."""
    kv, lead, a = 30.0, 1.5, 0.02
    starts = []
    for rpm in (600.0, 1200.0):
        turns, z, z_cmd = _servo_thread(rpm)
        v = lead * rpm / 60.0
        assert np.median((z - z_cmd)[len(z) // 2:]) == pytest.approx(v / kv, rel=0.01)
        ratio = np.abs(np.diff(z)) / (lead * np.diff(turns))
        full = np.flatnonzero(np.abs(ratio - 1.0) <= a)[0]
        starts.append(abs(z[full] - z[0]))
        assert starts[-1] == pytest.approx(v / kv * (math.log(1 / a) - 1.0), rel=0.05)
    assert starts[1] > 1.9 * starts[0]
