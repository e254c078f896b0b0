"""A lathe program as a Fanuc 0i-T programmer writes it (issue 32 s2), run by the CutSequencer with ideal axes and
a plain-Python spindle (first order toward the command): X as a diameter, U/W, a type II first block, tools and
their offsets, G28, G04, M00/M01, M08/M09, the spindle (S, M03/M04/M05, G96/G97, G50 S, G98/G99) and the
speed-arrival wait."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from lathe_oracle import spindle_run

from ncfmu.controllers import CutSequencer
from ncfmu.controllers.g7x import Tool
from ncfmu.controllers.lathe_program import Setup, parse, plan
from ncfmu.errors import ProgramError

#: A shaft as Fanuc's manuals write it (the README's example): O number, safety block, tool 1, G50 S, G96, G99,
#: G71/G70 with the type I profile in diameters, G28 U0 W0, M30.
SHAFT = (Path(__file__).resolve().parents[2] / "docs" / "examples" / "lathe_fanuc.nc").read_text()


@pytest.fixture(scope="module")
def shaft():
    seq = CutSequencer(program=SHAFT, x_start=30.0, z_start=2.0)
    return spindle_run(seq)


def test_the_fanuc_program_runs_to_its_end(shaft):
    assert shaft["done"][-1] and not shaft["alarm"].any()
    assert set(shaft["canned_cycle"]) == {0, 70, 71}
    # X as a diameter: X60. is the start point's radius 30, the profile's X28. radius 14
    g70 = shaft["canned_cycle"] == 70
    assert shaft["x_cmd"][g70].min() == pytest.approx(14.0, abs=1e-9)
    assert shaft["x_cmd"][shaft["canned_cycle"] == 71].min() == pytest.approx(14.0 + 0.2, abs=1e-6)   # U0.4 dia


def test_the_program_reports_tool_spindle_and_coolant(shaft):
    busy = shaft["busy"].astype(bool)
    assert set(shaft["tool"][busy]) == {1}
    cutting = shaft["canned_cycle"] > 0
    assert (shaft["spindle_dir"][cutting] == 1).all() and shaft["coolant"][cutting].all()
    assert shaft["spindle_dir"][-1] == 0 and not shaft["coolant"][-1] and shaft["s_cmd"][-1] == 0.0   # M05, M09


def test_g96_speed_is_the_surface_speed_at_the_tools_diameter_clamped_by_g50(shaft):
    cutting = (shaft["canned_cycle"] > 0) & (shaft["subcycle"] == 2)
    x, s = shaft["x_cmd"][cutting], shaft["s_cmd"][cutting]
    expected = np.minimum(2500.0, 1000.0 * 180.0 / (math.pi * 2.0 * x))
    assert np.allclose(s, expected, rtol=1e-9)
    assert s.min() < 1000.0 < s.max()        # 180 m/min: 955 rev/min at D 60, 2046 at D 28


def test_feed_per_revolution_follows_the_actual_spindle_speed(shaft):
    """G99 F0.25 mm/rev: the path speed is F x actual rev/min / 60 while cutting at a steady speed."""
    steady = ((shaft["canned_cycle"] == 71) & (shaft["subcycle"] == 2))
    v = np.hypot(shaft["x_vff"], shaft["z_vff"])[steady]
    expected = 0.25 * np.abs(shaft["speed"][steady]) / 60.0
    flat = (np.abs(np.diff(v, prepend=v[0])) < 1e-6) & (v > 0)      # moving, not accelerating
    assert flat.sum() > 1000
    assert np.allclose(v[flat], expected[flat], rtol=0.02)


def test_the_cut_waits_for_the_spindle_to_arrive():
    """A slow spindle (tau 1 s): the first cut begins only once the speed is within 5 % of the command."""
    seq = CutSequencer(program=SHAFT, x_start=30.0, z_start=2.0)
    run = spindle_run(seq, tau=1.0, limit=20_000)
    moving = np.hypot(run["x_vff"], run["z_vff"]) > 0
    cut = (run["canned_cycle"] == 71) & (run["subcycle"] == 2)
    first_cut = np.argmax(cut)
    first_motion = np.argmax(cut & moving)
    assert first_cut > 0 and first_motion > first_cut + 1000                 # stood still for more than 1 s
    assert abs(run["speed"][first_motion] - run["s_cmd"][first_motion]) <= 0.05 * run["s_cmd"][first_motion]
    assert abs(run["speed"][first_motion - 2] - run["s_cmd"][first_motion]) > 0.05 * run["s_cmd"][first_motion]


def test_a_spindle_that_never_arrives_is_an_alarm():
    seq = CutSequencer(program=SHAFT, x_start=30.0, z_start=2.0, spindle_timeout=0.5)
    run = spindle_run(seq, tau=1e9, limit=20_000)              # the spindle does not turn
    assert run["alarm"][-1] and not run["done"][-1]
    assert 0.5 < run["t"][-1] < 2.0


def test_a_tool_offset_moves_the_axes_not_the_program():
    text = "G21 G98\nT0202\nG00 X40. Z5.\nG01 W-10. F600\nU-4.\nM30\n"
    setup = Setup(tools=(Tool(), Tool(x_offset=1.5, z_offset=-2.0)))
    segs = plan(text, (30.0, 2.0), 50.0, setup)
    ends = [(round(s.element.end[1], 9), round(s.element.end[0], 9)) for s in segs]     # (x, z) of the axes
    # the offset taken up where T stands, then X40 (radius 20) Z5, W-10, U-4 (radius -2), each + (1.5, -2)
    assert ends == [(31.5, 0.0), (21.5, 3.0), (21.5, -7.0), (19.5, -7.0)]
    assert {s.modal.tool for s in segs} == {2}


def test_u_and_w_are_incremental_and_x_a_diameter():
    ops = parse("G00 X40. Z5.\nU-10. W-3.\nM30\n", (30.0, 2.0))
    assert [op.element.end for op in ops] == [(5.0, 20.0), (2.0, 15.0)]           # (z, x): U on the diameter
    radius = parse("G00 X40. Z5.\nU-10. W-3.\nM30\n", (30.0, 2.0), Setup(diameter=False))
    assert [op.element.end for op in radius] == [(5.0, 40.0), (2.0, 30.0)]


def test_type_two_first_block_with_z_or_w():
    """Fanuc's type II: the profile's first block names Z (or W0); a pocket is roughed, the part is not cut."""
    text = ("G21 G98\nG00 X60. Z2.\nG71 U1. R0.5\nG71 P10 Q20 U0.4 W0 F300\nN10 G00 X40. W0\nG01 Z-5.\nX30. Z-10.\n"
            "Z-15.\nX50. Z-20.\nN20 X60.\nM30\n")
    segs = plan(text, (30.0, 2.0), 50.0)
    assert min(min(s.element.start[1], s.element.end[1]) for s in segs if s.cycle == 71) == pytest.approx(15.2)
    behind = text.replace("N10 G00 X40. W0", "N10 G00 X40. Z0")           # the first block moves in Z too
    assert plan(behind, (30.0, 2.0), 50.0)


def test_dwell_and_stops():
    text = "G21 G98\nG00 X50.\nG04 P1500\nM00\nM01\nG00 X40.\nM30\n"

    def press_at(k, inputs):
        inputs["start"] = inputs["start"] or k == 4000

    run = spindle_run(CutSequencer(program=text, x_start=30.0, z_start=2.0), events=press_at)
    at_50 = np.flatnonzero(run["x_cmd"] == 25.0)
    leave = np.flatnonzero(run["x_cmd"] < 25.0)[0]
    # the dwell (1.5 s), then M00 waits for START at step 4000; M01 with the switch off does not stop
    assert 1.5 < run["t"][leave] - run["t"][at_50[0]]
    assert 4000 <= leave <= 4010 and run["done"][-1]
    with_switch = spindle_run(CutSequencer(program=text, x_start=30.0, z_start=2.0), limit=8000,
                              events=lambda k, i: (i.update(optional_stop=True), press_at(k, i)))
    assert not with_switch["done"][-1] and with_switch["x_cmd"][-1] == 25.0       # held at M01 after the START


def test_g28_returns_through_the_intermediate_point_to_the_reference():
    segs = plan("G21 G98\nG00 X40. Z-5.\nG28 U10.\nM30\n", (30.0, 2.0), 50.0, Setup(home=(100.0, 80.0)))
    ends = [s.element.end for s in segs]
    assert ends == [(-5.0, 20.0), (-5.0, 25.0), (-5.0, 80.0)]       # X only: via U10 (dia), then X home; Z stays
    both = plan("G21 G98\nG00 X40. Z-5.\nG28 U0 W0\nM30\n", (30.0, 2.0), 50.0, Setup(home=(100.0, 80.0)))
    assert [s.element.end for s in both] == [(-5.0, 20.0), (100.0, 80.0)]   # U0 W0: straight to the reference


@pytest.mark.parametrize("text, line, column, words", [
    ("O1\nG20\nM30\n", 2, 1, "inch units are not in the subset"),
    ("G96 S100 M03\nM30\n", 1, 1, "G96 needs the highest spindle speed first"),
    ("G99\nG01 X10. F0.2\nM30\n", 2, 1, "a feed per revolution (G99) with the spindle stopped"),
    ("T0909\nM30\n", 1, 1, "T<tool><offset>"),
    ("G50 X100. S2000\nM30\n", 1, 5, "setting the coordinate system is not in the subset"),
    ("G00 X10. / Z2.\nM30\n", 1, 10, "block delete '/' stands at the start of a block"),
])
def test_fanuc_refusals(text, line, column, words):
    with pytest.raises(ProgramError) as err:
        plan(text, (30.0, 2.0), 50.0)
    assert (err.value.line_no, err.value.column) == (line, column), str(err.value)
    assert words in str(err.value)


def test_g96_with_its_clamp_is_taken():
    """The refusal above can pass: with G50 S first, G96 is read (the spindle then at 2000 rev/min near the axis)."""
    segs = plan("G50 S2000\nG96 S100 M03\nG98 G01 X0.1 F100\nM30\n", (30.0, 2.0), 50.0)
    assert segs[-2].modal.rpm(0.05) == 2000.0 and segs[-1].modal.spindle == 0        # M30 stops the spindle


def test_a_state_in_a_feed_per_revolution_cut_restores_and_continues_identically():
    """Mid-G99 cut (the rate follows the spindle), in a dwell and waiting for the spindle: the FMU state's
    round trip (fmi/state.py, the controller's own check_state) is accepted and continues bit for bit."""
    from ncfmu.fmi import state

    parameters = {p.name: p.start for p in CutSequencer.ports("parameter")}
    parameters.update(program=SHAFT, x_start=30.0, z_start=2.0)
    for stop_at in (1500, 9000, 30_000):
        seq = CutSequencer.from_parameters(parameters)
        inputs = {p.name: p.start for p in CutSequencer.ports("input")}
        speed = 0.0
        outs = []
        for k in range(stop_at + 2000):
            if k == stop_at:
                blob = state.dumps(CutSequencer.MODEL_NAME, parameters, dict(inputs), seq)
                twin, _, _ = state.loads(blob, CutSequencer, CutSequencer.from_parameters)
                twin_inputs, twin_speed, twin_outs = dict(inputs), speed, []
            inputs["start"] = k == 0
            out = seq.step(k * 1e-3, 1e-3, inputs)
            outs.append((out["x_cmd"], out["z_cmd"], out["s_cmd"]))
            inputs["x_pos"], inputs["z_pos"] = out["x_cmd"], out["z_cmd"]
            speed += (out["s_cmd"] * out["spindle_dir"] - speed) * (1.0 - math.exp(-1e-3 / 0.05))
            inputs["spindle_speed"] = speed
        for k in range(stop_at, stop_at + 2000):
            twin_inputs["start"] = False
            out = twin.step(k * 1e-3, 1e-3, twin_inputs)
            twin_outs.append((out["x_cmd"], out["z_cmd"], out["s_cmd"]))
            twin_inputs["x_pos"], twin_inputs["z_pos"] = out["x_cmd"], out["z_cmd"]
            twin_speed += (out["s_cmd"] * out["spindle_dir"] - twin_speed) * (1.0 - math.exp(-1e-3 / 0.05))
            twin_inputs["spindle_speed"] = twin_speed
        assert twin_outs == outs[stop_at:], stop_at
