"""The part check judges a G74 drilled hole and a G75 groove (issue 46): each cycle's region, cut away by its
definition (``removed()``), is part of the programmed part -- so a hole drilled to depth with the drill of
``tool[k].drill_diameter`` is no gouge, a groove by the blade of ``tool[k].width`` no gouge -- and a hole or groove
made deeper than the program says is out of tolerance at the cycle's line.

Plain Python first (the report's accumulator fed the rows of the tool moving along the planned path, the oracle the
program's own numbers), then closed loop on lathe_roughing (slow)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely
from drawings import outline_dxf
from shapely.geometry import LineString

from ncfmu.controllers import lathe_program
from ncfmu.controllers.g7x import Tool
from ncfmu.controllers.peck_cycles import DRILL_POINT
from ncfmu.controllers.sequencer import CutSequencer
from ncfmu.systems.part import LathePart

LATHE = LathePart(seq="seq", x="x_axis", z="z_axis", spindle="spindle")
#: The lathe systems' bar: 58 mm in diameter, its face at Z 0, 80 mm long; the start point X30 (radius) Z2.
BAR = {"stock_diameter": 58.0, "stock_length": 80.0, "stock_face_z": 0.0, "x_start": 30.0, "z_start": 2.0}
COLUMNS = ("time", "seq.rapid", "seq.line", "seq.done", "seq.tool", "x_axis.pos", "z_axis.pos", "spindle.speed",
           "seq.s_cmd", "seq.spindle_dir")
#: Tool 2 a grooving blade 3 mm wide (its corner toward the chuck programmed), tool 3 a drill of 10 mm.
TOOLS = {"tool[2].width": 3.0, "tool[2].tip": 3, "tool[3].drill_diameter": 10.0}
SETUP = lathe_program.Setup(tools=(Tool(), Tool(width=3.0, tip=3), Tool(drill_diameter=10.0)) + (Tool(),) * 5)
#: A hole 10 mm in diameter to Z-12 (its point's tip), pecked 4 mm at a time from Z2 (line 5); a groove Z -12 .. -7
#: down to X54 (radius 27: 2 mm into the 29 mm bar) by the 3 mm blade stepping 2 mm, pecking 1 mm (line 9).
PROGRAM = """G21 G98 G97 S1200 M03
T0303
G00 X0. Z2.
G74 R0.5
G74 Z-12. Q4000 F300.
G00 X60.
T0202
G00 Z-10.
G75 R0.3
G75 X54. Z-12. P1000 Q2000 F240.
G00 X62.
M05
M30
"""
DRILL_LINE, GROOVE_LINE = 5, 10
#: The drill's point: its cone's length along Z (the hole's full diameter starts this far above its tip).
CONE = 5.0 / math.tan(math.radians(DRILL_POINT / 2.0))


def rows_of(program: str) -> np.ndarray:
    """Rows of a lathe run: the tool (programmed point, no offsets) along every planned move of ``program`` at
    0.01 mm a row, the spindle at its S, ``done`` on the last row."""
    rows = []
    for g in lathe_program.plan(program, (BAR["x_start"], BAR["z_start"]), 50.0, SETUP):
        e = g.element
        n = max(2, int(e.length / 0.01))
        (z0, x0), (z1, x1) = e.start, e.end
        for t in np.linspace(0.0, 1.0, n + 1)[1:]:
            rows.append((z0 + t * (z1 - z0), x0 + t * (x1 - x0), not g.feed, g.line, g.modal.tool,
                         g.modal.rpm(x0)))
    out = np.zeros(len(rows), dtype=[(c, float) for c in COLUMNS])
    a = np.array(rows, float)
    out["time"] = 1e-3 * np.arange(len(rows))
    out["z_axis.pos"], out["x_axis.pos"] = a[:, 0], a[:, 1]
    out["seq.rapid"], out["seq.line"], out["seq.tool"] = a[:, 2], a[:, 3], a[:, 4]
    out["spindle.speed"] = out["seq.s_cmd"] = a[:, 5]
    out["seq.spindle_dir"] = (a[:, 5] > 0).astype(float)
    out["seq.done"][-1] = 1.0
    return out


def judged(made_by: str, program: str = PROGRAM):
    """The part check's verdict of a run of ``program`` whose tool moved as ``made_by`` plans it."""
    acc = LATHE.accumulator({"seq": {**CutSequencer.default_parameters(), **BAR, "program": program, **TOOLS}})
    rows = rows_of(made_by)
    for k in range(0, len(rows), 5000):
        acc.write(rows[k:k + 5000])
    return acc.verdict()


def test_a_drilled_hole_and_a_groove_are_the_programmed_part_and_no_gouge():
    v = judged(PROGRAM)
    assert v.judged == "" and v.crashes == []
    assert v.max_gouge_mm < 0.01 and v.max_left_mm < 0.01 and v.within_tolerance is True
    part = v.programmed
    # the hole: the drill's diameter from the face down to its cone, whose tip is at the G74's Z on the axis
    wall = part.intersection(LineString([(-5.0, 0.0), (-5.0, 29.0)]))
    assert wall.bounds[1] == pytest.approx(5.0, abs=1e-6)
    for rho in (0.01, 2.5, 4.99):
        bottom = part.intersection(LineString([(-40.0, rho), (0.0, rho)]))
        assert bottom.bounds[2] == pytest.approx(-12.0 + rho * CONE / 5.0, abs=0.005)
    # the groove: Z -12 .. -7 (the plunges at Z-10 and Z-12, the blade 3 mm wide toward +Z), down to radius 27
    gaps = LineString([(-40.0, 28.0), (-0.5, 28.0)]).difference(part)
    assert [(g.bounds[0], g.bounds[2]) for g in shapely.get_parts(gaps)] == [(-12.0, -7.0)]
    assert part.intersection(LineString([(-10.0, 0.0), (-10.0, 29.0)])).bounds[3] == pytest.approx(27.0)


def test_a_hole_drilled_1_mm_deeper_than_programmed_is_out_of_tolerance_at_the_g74():
    v = judged(PROGRAM.replace("G74 Z-12.", "G74 Z-13."))
    # the made cone 1 mm below the programmed one: 1 mm along Z is sin(59 deg) across the cone's face
    assert v.within_tolerance is False
    assert v.max_gouge_mm == pytest.approx(math.sin(math.radians(DRILL_POINT / 2.0)), abs=0.005)
    assert v.gouge_line == DRILL_LINE


def test_a_groove_cut_1_mm_deeper_than_programmed_is_out_of_tolerance_at_the_g75():
    v = judged(PROGRAM.replace("G75 X54.", "G75 X52."))
    assert v.within_tolerance is False and v.max_gouge_mm == pytest.approx(1.0, abs=0.005)
    assert v.gouge_line == GROOVE_LINE


# -- closed loop on lathe_roughing ---------------------------------------------------------------------------------
#: The part drawn, (Z, radius): the 58 mm bar, the hole (10 mm, its 118-degree point's tip at Z-12) and the groove.
OUTLINE = [(0.0, 5.0), (0.0, 29.0), (-7.0, 29.0), (-7.0, 27.0), (-12.0, 27.0), (-12.0, 29.0), (-40.0, 29.0),
           (-40.0, 0.0), (-12.0, 0.0), (-12.0 + CONE, 5.0)]




@pytest.mark.slow
def test_closed_loop_a_hole_by_g74_and_a_groove_by_g75_are_judged_to_depth(ncfmu_run, tmp_path):
    start = {"seq.program": PROGRAM, **{f"seq.{k}": v for k, v in TOOLS.items()}}
    r = ncfmu_run("lathe_roughing", stop_time=12.0, start_values=start)
    assert r["seq.done"][-1], "the program did not finish in 12 s"
    x, z, line, cycle = r["x_axis.pos"], r["z_axis.pos"], r["seq.line"], r["seq.canned_cycle"]
    drilling = line == DRILL_LINE
    assert set(cycle[drilling]) == {74} and np.abs(x[drilling]).max() < 0.01       # on the axis all along
    assert z[drilling].min() == pytest.approx(-12.0, abs=0.01)                      # to depth, not beyond
    assert x[line == GROOVE_LINE].min() == pytest.approx(27.0, abs=0.01)
    p = r.part
    assert p.judged == "" and p.crashes == []
    assert p.max_left_mm < 0.01 and p.max_gouge_mm < 0.01 and p.within_tolerance is True
    # the part drawn with the hole 1 mm shallower: the hole drilled is 1 mm too deep, out of tolerance at the G74
    shallow = [(zz + 1.0 if zz < 0.0 and xx < 5.0 + 1e-9 and zz > -40.0 else zz, xx) for zz, xx in OUTLINE]
    off = ncfmu_run("lathe_roughing", stop_time=12.0, start_values=start,
                    drawing=outline_dxf(tmp_path / "shallow.dxf", shallow)).part
    assert off.within_tolerance is False and off.gouge_line == DRILL_LINE
    assert off.max_gouge_mm == pytest.approx(math.sin(math.radians(DRILL_POINT / 2.0)), abs=0.01)
    # the part drawn with the groove 1 mm shallower (radius 28): out of tolerance at the G75
    groove = [(zz, 28.0 if xx == 27.0 else xx) for zz, xx in OUTLINE]
    off = ncfmu_run("lathe_roughing", stop_time=12.0, start_values=start,
                    drawing=outline_dxf(tmp_path / "groove.dxf", groove)).part
    assert off.within_tolerance is False and off.gouge_line == GROOVE_LINE
    assert off.max_gouge_mm == pytest.approx(1.0, abs=0.01)
