"""The part check on inside work (a bore), closed loop through lathe_roughing: the Fanuc suite's bore program
(tests/lathe_oracle.py's BORE: a 20 mm drilled hole bored to 38 mm at its mouth, G71 U-0.4 W0.1 then G70).

The stock is a tube: the bar with the drilled hole, whose radius is the bore cycle's start point's X (X20.: 10
mm). Each verdict against an oracle of its own: the profile's geometry (the allowance, the depth of cut, the
hole) and the trajectory (where the axes stood on which line), never the material-removal engine.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from lathe_oracle import BORE, BORE_OPTIONS, SHAFT, fanuc

from ncfmu.cli import main
from ncfmu.exitcodes import EXIT_PART_REJECTED
from ncfmu.machining.removal import TOUCH
from ncfmu.systems.part import LathePart

PROGRAM = fanuc(BORE, 1011, **BORE_OPTIONS)
#: The drilled hole's radius: the start point's X (the program's X20.) -- the part the oracle mirrors about.
HOLE = BORE.x0
#: The G71's line in the program file (N7 G71 P10 Q20 ...; seq.line counts the file's lines from 1).
G71_LINE = PROGRAM.splitlines().index(next(t for t in PROGRAM.splitlines() if t.startswith("N7 G71"))) + 1
#: The bore's cylinders (radii): where G71 alone leaves its allowance, U/2 below each.
CYLINDERS = sorted({2 * BORE.x0 - p.start[1] for p in BORE.pieces if p.centre is None and p.start[1] == p.end[1]})
STOP = 45.0                         # the cycle ends at t = 42.3 s (G28 included)


def bore_run(ncfmu_run, program: str = PROGRAM, stop: float = STOP, **settings):
    return ncfmu_run("lathe_roughing", stop_time=stop, start_values={"seq.program": program}, **settings)


@pytest.mark.slow
def test_the_bore_is_judged_against_its_profile_within_a_hundredth(ncfmu_run):
    assert "U-0.4" in PROGRAM and HOLE == 10.0 and CYLINDERS == [13.0, 15.0, 18.0, 19.0]
    r = bore_run(ncfmu_run)
    assert r["seq.done"][-1]
    p = r.part
    # judged as a bore: no rapid "into the stock" where the retracts go into the hole, no cut across the axis
    assert p.crashes == [] and p.judged == ""
    assert p.max_left_mm < 0.01 and p.max_gouge_mm < 0.01 and p.within_tolerance is True
    # the stock is the tube: the part made and the programmed part both stand on the hole's wall, and the G70
    # pass (the axes' actual positions) ran along the bore's profile, mirrored from the oracle's part
    assert p.made.bounds[1] == pytest.approx(HOLE, abs=1e-9) and p.programmed.bounds[1] == pytest.approx(HOLE)
    g70 = r["seq.canned_cycle"] == 70
    x = r["x_axis.pos"][g70]
    assert x.min() >= HOLE - 0.5 - 1e-6 and x.max() == pytest.approx(2 * HOLE - BORE.a_x, abs=0.01)
    # the programmed part: the tube less the bore, as the oracle's geometry says (area of the removed region)
    pts = BORE.points(0.01)
    zs, xs = pts[:, 0], 2 * HOLE - pts[:, 1]
    inside = zs <= 0.0                               # the profile starts in front of the face (Z 2): air there
    removed = np.trapezoid(xs[inside] - HOLE, -zs[inside])
    tube = (29.0 - HOLE) * 80.0
    assert p.programmed.area == pytest.approx(tube - removed, abs=0.01)


@pytest.mark.slow
def test_a_bore_roughed_by_g71_alone_leaves_the_allowance(ncfmu_run):
    # no G70, W 0: U -0.4 (0.2 on the radius) is left below every one of the bore's cylinders
    text = fanuc(BORE, 1011, **{**BORE_OPTIONS, "w": 0.0}).replace("N21 G70 P10 Q20 F0.1\n", "")
    assert "G70" not in text and "U-0.4 W0." in text
    r = bore_run(ncfmu_run, text, stop=31.0)
    assert r["seq.done"][-1]
    p = r.part
    assert p.crashes == [] and p.judged == ""
    assert p.max_left_mm == pytest.approx(0.2, abs=0.005)
    assert p.max_gouge_mm < 0.005
    # where: on the inside of one of the cylinders that reach into the stock (Z < 0), 0.2 below it
    assert min(abs(p.left_at[1] + 0.2 - x) for x in CYLINDERS) < 0.005
    assert p.left_line > 0 and p.within_tolerance is False


@pytest.mark.slow
def test_a_rapid_into_the_bores_wall_is_a_crash_named_by_its_line(ncfmu_run, tmp_path, capsys):
    # before the cycle: into the hole at rapid (air), then out to X30. (radius 15): 5 mm into the tube's wall
    text = PROGRAM.replace("N6 G71", "N51 G00 Z-5.\nN52 G00 X30.\nN53 G00 X20.\nN54 G00 Z2.\nN6 G71")
    wrong = text.splitlines().index("N52 G00 X30.") + 1
    r = bore_run(ncfmu_run, text, stop=2.0)
    x, line = r["x_axis.pos"], r["seq.line"]
    assert r["seq.rapid"][line == wrong].all()
    crashes = r.part.crashes
    assert [(c.line, c.what) for c in crashes] == [(wrong, "rapid into the stock")]     # Z-5. in the hole: air
    assert crashes[0].depth_mm == pytest.approx(x[line == wrong].max() - HOLE, abs=0.002)
    assert crashes[0].depth_mm == pytest.approx(5.0, abs=0.01)
    assert crashes[0].t == pytest.approx(float(r.time[np.argmax((line == wrong) & (x > HOLE + TOUCH))]), abs=0.003)
    assert r.part.within_tolerance is False
    code = main(["run", "lathe_roughing", "--stop-time", "2", "--set", f"seq.program={text}", "--out",
                 str(tmp_path)])
    assert code == EXIT_PART_REJECTED
    out = capsys.readouterr().out
    assert f"  part: CRASH at t = {crashes[0].t:.3f} s, line {wrong} (N52): rapid into the stock, 5" in out
    written = json.loads((tmp_path / "lathe_roughing.part.json").read_text())
    assert written["within_tolerance"] is False and written["crashes"][0]["line"] == wrong
    # without a --stop-time the crash halts the machine: the run ends as soon as the rows reach the part check (a
    # record window, a few seconds), long before the program would have
    assert main(["run", "lathe_roughing", "--set", f"seq.program={text}", "--out", str(tmp_path)]) \
        == EXIT_PART_REJECTED
    out = capsys.readouterr().out
    assert f"  ended: crash at t = {crashes[0].t:.3f} s" in out
    last = float((tmp_path / "lathe_roughing.csv").read_text().rstrip("\n").rsplit("\n", 1)[1].split(",")[0])
    assert crashes[0].t < last < 10.0


@pytest.mark.slow
def test_the_boring_bar_may_cross_the_axis_only_as_far_as_the_hole(ncfmu_run):
    # the bar (a hole's radius below the tip) in the hole: down to X-2. (tip at radius -1) it reaches 1 mm into
    # the far wall
    text = PROGRAM.replace("N6 G71", "N51 G00 Z-5.\nN52 G00 X-2.\nN53 G00 X20.\nN54 G00 Z2.\nN6 G71")
    wrong = text.splitlines().index("N52 G00 X-2.") + 1
    r = bore_run(ncfmu_run, text, stop=2.0)
    far = [c for c in r.part.crashes if c.what == "boring bar into the far wall of the bore"]
    assert far and far[0].line == wrong
    assert far[0].depth_mm == pytest.approx(-r["x_axis.pos"].min(), abs=0.002)
    assert not [c for c in r.part.crashes if c.what == "rapid into the stock"]


@pytest.mark.slow
def test_passes_deeper_than_the_boring_tool_may_take_are_crashes(ncfmu_run):
    # G71 U1.: the roughing passes go outward from the hole 1 mm at a time (X 11, 12, ...); a tool that may take
    # 0.8 mm is overloaded on each full pass, one that may take 1.1 mm never (the same run, judged twice)
    crashes = bore_run(ncfmu_run, max_depth=0.8).part.crashes
    assert crashes and {c.line for c in crashes} == {G71_LINE}
    assert [c.depth_mm for c in crashes] == pytest.approx([1.0] * len(crashes), abs=0.002)
    assert [round(c.at[1], 3) for c in crashes] == [HOLE + k for k in range(1, len(crashes) + 1)]
    assert len(crashes) >= 7                   # up to X 17: the passes below the mouth's chamfer
    assert bore_run(ncfmu_run, max_depth=1.1).part.crashes == []


@pytest.mark.slow
def test_a_boring_bar_with_a_nose_under_g41_leaves_only_the_inside_corner_it_cannot_reach(ncfmu_run):
    # tip 2, nose 0.4 (the mirrored tool: its nose circle's centre at the tip + (r, -r)), G70 under G41: the nose
    # follows the profile; at the bore's bottom the face meets the cylinder X 13 in a sharp inside corner (Z-28.,
    # the part's material on three quarters), where a nose of radius r leaves r (1 - 1/sqrt 2) on the bisector
    r_nose = 0.4
    text = PROGRAM.replace("N5 G00", "N5 G41 G00").replace("N22 G28", "N215 G40 G00 X10. Z5.\nN22 G28")
    r = ncfmu_run("lathe_roughing", stop_time=STOP, start_values={
        "seq.program": text, "seq.tool[1].nose_radius": r_nose, "seq.tool[1].tip": 2})
    assert r["seq.done"][-1]
    p = r.part
    assert p.crashes == [] and p.judged == ""
    corner = r_nose * (1.0 - 2 ** -0.5)
    assert p.max_left_mm == pytest.approx(corner, abs=0.005)
    assert p.left_at == pytest.approx((-28.0 + corner, 13.0 - corner), abs=0.005)
    assert p.max_gouge_mm < 0.01 and p.within_tolerance is False


BAR = {"stock_diameter": 58.0, "stock_length": 80.0}


def test_the_stock_of_a_bore_is_a_tube_from_its_start_x_and_what_is_not_judged():
    part = LathePart(seq="seq", x="x_axis", z="z_axis")
    s = part.setup({"seq": {"program": PROGRAM, **BAR}})
    assert s.why_not == "" and s.programmed.bounds == pytest.approx((-80.0, HOLE, 0.0, 29.0))
    assert s.removal.stock.bounds == pytest.approx((-80.0, HOLE, 0.0, 29.0))
    assert [f.what for f in s.removal.forbidden] == ["boring bar into the far wall of the bore"]
    # the tool mirrored: the (point) tip on top, the bar a hole's radius below it
    tool = s.removal.cutter(0).outline
    assert tool[:, 1].max() == 0.0 and tool[:, 1].min() == pytest.approx(-HOLE)
    # a bore from X0 has no hole; a program with a bore and an outside profile is not judged (one kind at a time)
    zero = part.setup({"seq": {"program": PROGRAM.replace("N5 G00 X20.", "N5 G00 X0."), **BAR}})
    assert zero.programmed is None and zero.why_not.startswith("the bore's cycle starts at X 0 (radius)")
    shaft = fanuc(SHAFT, 1001).split("N5 ")[1].split("N22 ")[0]
    for n in ("10", "20", "6", "7", "21"):
        shaft = shaft.replace(f"N{n} ", f"N1{n} ")
    mixed = PROGRAM.replace("N22 G28", "N105 " + shaft.replace("P10 Q20", "P110 Q120") + "N22 G28")
    assert mixed.count("G71 P") == 2
    both = part.setup({"seq": {"program": mixed, **BAR}})
    assert both.programmed is None and "both inside and outside" in both.why_not
