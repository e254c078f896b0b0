"""A shop's lathe program closed-loop (issue 46): three grooves made by one subprogram called three times with an
incremental shift (W), under G54 with a work offset, the bar's edge chamfered with ,C -- run on lathe_roughing
and judged by the part check against the part drawn (the program has no G71/G70 profile)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from drawings import outline_dxf
from shop_programs import PASSES

#: Diameters, G99 F mm/rev. The chamfer 1 x 45 degrees at the face (,C1 from the corner), turned with tool 1; the
#: grooves: 3 mm wide, 1 mm deep (radius), 6 mm apart, from Z-9 on, by a grooving blade 2 mm wide (tool 2, its
#: programmed point the corner toward the chuck: it spans Z..Z+2): a plunge 8 mm on from where the last groove
#: ended (W-8), then 1 mm along Z to the groove's width (W-1).
GROOVES = """G21 G40 G99
G54
T0101
G97 S1500 M03
G00 X60. Z2.
G00 X54. Z1.
G01 Z0. F0.2
X58. ,C1.
Z-3.
G00 X60. T0202
M98 P30100
G00 Z5.
M05
M30
O0100
G00 W-8.
G01 U-4. F0.1
W-1. F0.2
G00 U4.
M99
"""
#: The subprogram's groove cut (text line 18) and the chamfering block (line 8).
GROOVE_LINE, CHAMFER_LINE = 18, 8
#: The grooving blade (tool 2): its width, mm, and its tip (3: the programmed point on the chuck's side).
BLADE_WIDTH = 2.0
#: G54: the axes stand 5 mm (Z) and 0.5 mm (X, radius) off the part's programmed coordinates.
WORK_Z, WORK_X = 5.0, 0.5
#: The part drawn, (Z, radius): the 58 mm bar with the chamfer and the three grooves.
OUTLINE = [(0.0, 0.0), (0.0, 28.0), (-1.0, 29.0),
           (-9.0, 29.0), (-9.0, 28.0), (-12.0, 28.0), (-12.0, 29.0),
           (-18.0, 29.0), (-18.0, 28.0), (-21.0, 28.0), (-21.0, 29.0),
           (-27.0, 29.0), (-27.0, 28.0), (-30.0, 28.0), (-30.0, 29.0),
           (-40.0, 29.0), (-40.0, 0.0)]




@pytest.mark.slow
def test_grooves_by_a_subprogram_under_g54_with_a_chamfer_are_the_part_drawn(ncfmu_run, tmp_path):
    start = {"seq.program": GROOVES, "seq.work[1].z": WORK_Z, "seq.work[1].x": WORK_X,
             "seq.tool[2].width": BLADE_WIDTH, "seq.tool[2].tip": 3}
    right = outline_dxf(tmp_path / "grooves.dxf", OUTLINE)
    r = ncfmu_run("lathe_roughing", stop_time=9.0, start_values=start, drawing=right)
    assert r["seq.done"][-1], "the program did not finish in 9 s"
    x, z, line = r["x_axis.pos"], r["z_axis.pos"], r["seq.line"]
    # the subprogram's cut reports its own text line, three times: at the groove's bottom (radius 28) + the G54 X,
    # from each plunge (the groove's far wall + the blade's width) to the groove's end
    cutting = (line == GROOVE_LINE) & (np.abs(x - (28.0 + WORK_X)) < 0.01)
    assert cutting.sum() > 0
    ends = sorted({round(float(v) - WORK_Z) for v in z[cutting] if abs(v - round(v)) < 0.01 and
                   round(float(v) - WORK_Z) in (-11, -12, -20, -21, -29, -30)})
    assert ends == [-30, -29, -21, -20, -12, -11]
    p = r.part
    assert p.judged == "" and p.crashes == []
    assert p.max_left_mm < 0.01 and p.max_gouge_mm < 0.01 and p.within_tolerance is True
    # the grooves drawn 3 mm further toward the chuck: the part made is out of tolerance, at a groove's line
    shifted = [(z - 3.0 if -30.0 <= z <= -9.0 else z, x) for z, x in OUTLINE]
    off = ncfmu_run("lathe_roughing", stop_time=9.0, start_values=start,
                    drawing=outline_dxf(tmp_path / "off.dxf", shifted)).part
    assert off.within_tolerance is False and off.max_gouge_mm == pytest.approx(1.0, abs=0.01)
    assert GROOVE_LINE in (off.gouge_line, off.left_line)


#: PASSES (G94 facing, G90 turning under G54, judged by their own definition): the face pass to Z-2 and the
#: taper pass (text lines).
FACE_LINE, TAPER_LINE = 7, 10
#: G54 (z, x radius) and tool 1's offsets: the axes stand at the programmed point + both.
PASS_WORK = (-3.0, 0.5)
PASS_TOOL = (-1.0, 0.25)


@pytest.mark.slow
def test_g90_g94_passes_under_g54_are_judged_by_their_definition_at_the_offset_axes(ncfmu_run, tmp_path, capsys):
    from ncfmu.cli import main
    start = {"seq.program": PASSES, "seq.work[1].z": PASS_WORK[0], "seq.work[1].x": PASS_WORK[1],
             "seq.tool[1].z_offset": PASS_TOOL[0], "seq.tool[1].x_offset": PASS_TOOL[1]}
    r = ncfmu_run("lathe_roughing", stop_time=11.0, start_values=start)
    assert r["seq.done"][-1], "the program did not finish in 11 s (it does at 10.3 s)"
    dz, dx = PASS_WORK[0] + PASS_TOOL[0], PASS_WORK[1] + PASS_TOOL[1]
    x, z, line, sub = r["x_axis.pos"], r["z_axis.pos"], r["seq.line"], r["seq.subcycle"]
    # the face cut (SC2 of the pass to Z-2): at Z -2 + offsets, down to X40 (radius 20) + offsets
    face = (line == FACE_LINE) & (sub == 2)
    assert np.abs(z[face] - (-2.0 + dz)).max() < 0.002
    assert x[face].min() == pytest.approx(20.0 + dx, abs=0.002)
    # the taper cut (SC2, R-1): on the line from radius 24 at Z2 to 25 at Z-15, all shifted by the offsets
    taper = (line == TAPER_LINE) & (sub == 2)
    programmed = 24.0 + (2.0 - (z[taper] - dz)) / 17.0
    assert np.abs(x[taper] - dx - programmed).max() < 0.005
    assert z[taper].min() == pytest.approx(-15.0 + dz, abs=0.002)
    p = r.part
    assert p.judged == "" and p.crashes == []
    assert p.max_left_mm < 0.01 and p.max_gouge_mm < 0.01 and p.within_tolerance is True
    # what a user sees: part within, exit 0
    program = tmp_path / "passes.nc"
    program.write_text(PASSES)
    sets = [a for k, v in start.items() if k != "seq.program" for a in ("--set", f"{k}={v}")]
    assert main(["run", "lathe_roughing", "--program", str(program), *sets, "--out", str(tmp_path)]) == 0
    assert "  part: within 0.0100 mm" in capsys.readouterr().out


#: A G71/G70 profile with a corner radius (,R3 where the X40 cylinder meets the face up to X46) and a chamfer (,C1
#: on the X50 edge), roughed and finished with tool 1 under G54.
CORNERS = """G21 G40 G98
G54
T0101
G97 S1000 M03
G00 X60. Z2.
G71 U2. R0.5
G71 P10 Q20 U0.4 W0.1 F900
N10 G00 X40.
G01 Z-10. ,R3.
X50. ,C1.
Z-20.
N20 X60.
G70 P10 Q20 F300
G00 X64. Z5.
M05
M30
"""
ROUND_LINE, CHAMFER_BLOCK = 9, 10
#: The ,R3 corner's centre (z, x radius): 3 mm from the X40 cylinder (radius 20) and from the face at Z-10.
ROUND_CENTRE, ROUND_R = (-7.0, 23.0), 3.0


@pytest.mark.slow
def test_a_corner_radius_and_a_chamfer_on_the_profile_are_on_the_part(ncfmu_run):
    start = {"seq.program": CORNERS, "seq.work[1].z": PASS_WORK[0], "seq.work[1].x": PASS_WORK[1]}
    r = ncfmu_run("lathe_roughing", stop_time=18.0, start_values=start)
    assert r["seq.done"][-1], "the program did not finish in 18 s (it does at 17.6 s)"
    x, z, line, cycle = r["x_axis.pos"], r["z_axis.pos"], r["seq.line"], r["seq.canned_cycle"]
    # G70 along the ,R block: the axes' path round the corner is an arc of radius 3 about its centre (+ G54)
    cz, cx = ROUND_CENTRE[0] + PASS_WORK[0], ROUND_CENTRE[1] + PASS_WORK[1]
    finishing = (cycle == 70) & (line == ROUND_LINE)
    on_arc = finishing & (z < cz) & (x < cx)          # the quadrant the fillet sweeps (below its centre)
    assert on_arc.sum() > 20
    radius = np.hypot(z[on_arc] - cz, x[on_arc] - cx)
    assert np.abs(radius - ROUND_R).max() < 0.005
    # the chamfer: G70 on the ,C block runs along the 45-degree line from (Z-10, radius 24) to (Z-11, radius 25)
    chamfer = (cycle == 70) & (line == CHAMFER_BLOCK) & (x > 24.0 + PASS_WORK[1] + 0.01)
    assert chamfer.sum() > 5
    assert np.abs((x[chamfer] - PASS_WORK[1]) - (24.0 - (z[chamfer] - PASS_WORK[0] + 10.0))).max() < 0.005
    p = r.part
    assert p.judged == "" and p.crashes == []
    assert p.max_left_mm < 0.01 and p.max_gouge_mm < 0.01 and p.within_tolerance is True


#: The README's shop example: G54, T words, G94 facing, four G90 passes by a subprogram, G71/G70 with ,R and ,C.
SHOP = Path(__file__).resolve().parents[2] / "docs" / "examples" / "lathe_shop.nc"


def _programmed_radius(programmed, z: float) -> float:
    """The programmed part's radius at ``z``: the top of its section there."""
    from shapely.geometry import LineString
    return float(programmed.intersection(LineString([(z, 0.0), (z, 100.0)])).bounds[3])


@pytest.mark.slow
def test_the_shop_example_runs_to_a_part_within_tolerance(project, tmp_path, capsys):
    from ncfmu.cli import main
    from ncfmu.controllers.sequencer import CutSequencer
    from ncfmu.systems.lathe import STOCK, X_START, Z_START
    from ncfmu.systems.part import LathePart
    assert main(["run", "lathe_roughing", "--program", str(SHOP), "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "  part: within 0.0100 mm" in out and "ended: done" in out
    # judged without a drawing: the programmed part is the profile's (the ,R2 fillet, the ,C1 chamfer, X48 to
    # Z-25) and, beyond it, the G90 passes' (X50 to Z-30) and the G94 face's (Z-1), each by its definition
    seq = {**CutSequencer.default_parameters(), **STOCK, "x_start": X_START, "z_start": Z_START,
           "program": SHOP.read_text()}
    programmed = LathePart(seq="seq", x="x_axis", z="z_axis").setup({"seq": seq}).programmed
    assert _programmed_radius(programmed, -3.0) == pytest.approx(20.0)
    assert _programmed_radius(programmed, -7.0) == pytest.approx(22.0 - 3.0 ** 0.5, abs=0.002)   # the fillet
    assert _programmed_radius(programmed, -8.5) == pytest.approx(23.5)                          # the chamfer
    assert _programmed_radius(programmed, -20.0) == pytest.approx(24.0)
    assert _programmed_radius(programmed, -27.5) == pytest.approx(25.0)                         # the G90 passes
    assert _programmed_radius(programmed, -35.0) == pytest.approx(29.0)                         # the bar
    assert programmed.bounds[2] == pytest.approx(-1.0)                                          # faced 1 mm
