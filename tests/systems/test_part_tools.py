"""The part check's verdict from the tool's real shape, the spindle, the pocket's side and the crash's N number
(issue 51): plain Python, the report's own accumulator fed rows made here (the tool's positions as a program
moves it, the sequencer's outputs), so each verdict is checked against hand-worked geometry.

The oracles are the programs' own numbers: a groove as wide as the blade and as deep as its X, a hole of the
drill's diameter, a pocket corner's material a round cutter cannot reach (r / sin(theta / 2) - r).
"""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest
import shapely
from physics import drive_contour
from shapely.geometry import LineString, Polygon

from ncfmu.controllers.contour import ContourInterpolator
from ncfmu.controllers.sequencer import CutSequencer
from ncfmu.errors import ConfigError
from ncfmu.machining.removal import STANDING
from ncfmu.systems.compose import points
from ncfmu.systems.part import LathePart, MillPart, PartVerdict

LATHE = LathePart(seq="seq", x="x_axis", z="z_axis", spindle="spindle")
MILL = MillPart(contour="contour", x="x_axis", y="y_axis")
#: The lathe systems' bar: 58 mm in diameter, its face at Z 0, 80 mm long.
BAR = {"stock_diameter": 58.0, "stock_length": 80.0, "stock_face_z": 0.0, "x_start": 31.0, "z_start": 2.0}
COLUMNS = ("time", "seq.rapid", "seq.line", "seq.done", "seq.tool", "x_axis.pos", "z_axis.pos", "spindle.speed",
           "seq.s_cmd", "seq.spindle_dir")


def lathe_rows(moves, start=(2.0, 31.0), rpm=600.0):
    """Rows of a lathe run: the tool's (z, x radius) moving straight from ``start`` through each move
    ``(z, x, rapid, line, tool)`` at 0.01 mm a row, the spindle at ``rpm`` (commanded and actual, M03 when > 0),
    ``done`` on the last row."""
    rows = []
    at = start
    for z, x, rapid, line, tool in moves:
        n = max(2, int(math.dist(at, (z, x)) / 0.01))
        zx = np.linspace(at, (z, x), n + 1)[1:]
        for pz, px in zx:
            rows.append((pz, px, rapid, line, tool))
        at = (z, x)
    out = np.zeros(len(rows), dtype=[(c, float) for c in COLUMNS])
    a = np.array(rows, float)
    out["time"] = 1e-3 * np.arange(len(rows))
    out["z_axis.pos"], out["x_axis.pos"] = a[:, 0], a[:, 1]
    out["seq.rapid"], out["seq.line"], out["seq.tool"] = a[:, 2], a[:, 3], a[:, 4]
    out["spindle.speed"] = out["seq.s_cmd"] = rpm
    out["seq.spindle_dir"] = 1.0 if rpm > 0 else 0.0
    out["seq.done"][-1] = 1.0
    return out


def lathe_check(program: str, moves, rpm=600.0, **tools):
    """The lathe part check's accumulator after the rows of ``moves`` (its verdict, and the stock left)."""
    parameters = {"seq": {**CutSequencer.default_parameters(), **BAR, "program": program, **tools}}
    acc = LATHE.accumulator(parameters)
    rows = lathe_rows(moves, rpm=rpm)
    for k in range(0, len(rows), 2000):          # in chunks, as a run streams them
        acc.write(rows[k:k + 2000])
    return acc


def groove_at(stock, x: float) -> list[tuple[float, float]]:
    """The Z intervals where the radius-``x`` line lies outside the stock (the grooves cut through it)."""
    line = LineString([(-79.0, x), (-0.01, x)])
    gaps = line.difference(stock)
    return sorted((g.bounds[0], g.bounds[2]) for g in shapely.get_parts(gaps) if g.length > 1e-6)


GROOVE = """%
O1000 (A GROOVE, 3 MM BLADE)
N10 G21 G97 S600 M03 T0101
N20 G00 X62. Z-10.
N30 G01 X40. F50.
N40 G00 X62.
N50 M30
%
"""


def test_a_groove_plunged_and_retracted_along_the_same_path_is_no_crash_and_as_wide_as_the_blade():
    acc = lathe_check(GROOVE, [(-10.0, 31.0, 1, 3, 1), (-10.0, 20.0, 0, 4, 1), (-10.0, 31.0, 1, 5, 1)],
                      **{"tool[1].width": 3.0})
    v = acc.verdict()
    assert v.crashes == [] and v.crash_count == 0
    stock = acc.setup.removal.stock
    # the blade's corner toward the chuck is the programmed point (tip 0 as 3): the groove Z -10 .. -7, to X 20
    for x in (20.5, 25.0, 28.5):
        [(z0, z1)] = groove_at(stock, x)
        assert z0 == pytest.approx(-10.0, abs=0.002) and z1 == pytest.approx(-7.0, abs=0.002)
    assert groove_at(stock, 19.99) == []
    assert acc.setup.removal.deepest_cut == pytest.approx(9.0, abs=0.01)


def test_a_part_off_and_its_retract_are_no_crash_and_the_bar_is_cut_through():
    program = GROOVE.replace("Z-10.", "Z-40.").replace("X40.", "X0.")
    acc = lathe_check(program, [(-40.0, 31.0, 1, 3, 1), (-40.0, 0.0, 0, 4, 1), (-40.0, 31.0, 1, 5, 1)],
                      **{"tool[1].width": 4.0, "tool[1].nose_radius": 0.2})
    v = acc.verdict()
    assert v.crashes == []
    pieces = sorted(shapely.get_parts(acc.setup.removal.stock), key=lambda p: p.bounds[0])
    assert len(pieces) == 2                   # the chuck's end and the piece parted off
    # the cut as wide as the blade; at the axis the blade's rounded corners (0.2) leave their fillets
    [(z0, z1)] = groove_at(acc.setup.removal.stock, 10.0)
    assert (z0, z1) == (pytest.approx(-40.0, abs=0.002), pytest.approx(-36.0, abs=0.002))
    assert pieces[0].bounds[2] == pytest.approx(-39.8, abs=0.002)
    assert pieces[1].bounds[0] == pytest.approx(-36.2, abs=0.002)


def test_the_active_tool_cuts_a_turning_pass_with_t1_and_a_groove_with_t2():
    program = """%
O1001 (TURN WITH T1, GROOVE WITH T2)
N10 G21 G97 S600 M03 T0101
N20 G00 X56. Z2.
N30 G01 Z-30. F50.
N40 G00 X62.
N50 T0202
N60 G00 X62. Z-20.
N70 G01 X44. F50.
N80 G00 X62.
N90 M30
%
"""
    moves = [(2.0, 28.0, 1, 4, 1), (-30.0, 28.0, 0, 5, 1), (-30.0, 31.0, 1, 6, 1),
             (-20.0, 31.0, 1, 8, 2), (-20.0, 22.0, 0, 9, 2), (-20.0, 31.0, 1, 10, 2)]
    acc = lathe_check(program, moves, **{"tool[2].width": 2.5, "tool[2].tip": 4})
    assert acc.verdict().crashes == []
    # tip 4: the programmed point is the blade's corner toward the tailstock, the blade reaches 2.5 mm to -Z
    [(z0, z1)] = groove_at(acc.setup.removal.stock, 25.0)
    assert (z0, z1) == (pytest.approx(-22.5, abs=0.002), pytest.approx(-20.0, abs=0.002))
    # the turning pass (T1's 80-degree insert, no nose radius) left radius 28 up to its end at Z -30
    top = acc.setup.removal.stock.intersection(LineString([(-29.0, 27.0), (-29.0, 40.0)]))
    assert top.bounds[3] == pytest.approx(28.0, abs=0.002)


def test_a_drill_on_the_axis_makes_a_hole_of_its_diameter_and_crosses_no_axis():
    program = """%
O1002 (DRILL 10)
N10 G21 G97 S600 M03 T0303
N20 G00 X0. Z2.
N30 G01 Z-20. F30.
N40 G00 Z2.
N50 M30
%
"""
    acc = lathe_check(program, [(2.0, 0.0, 1, 3, 3), (-20.0, 0.0, 0, 4, 3), (2.0, 0.0, 1, 5, 3)],
                      **{"tool[3].drill_diameter": 10.0})
    assert acc.verdict().crashes == []
    stock = acc.setup.removal.stock
    # the hole: radius 5 down to Z -20 (the drill's point below it), the bar untouched outside it
    wall = stock.intersection(LineString([(-10.0, 0.0), (-10.0, 29.0)]))
    assert wall.bounds[1] == pytest.approx(5.0, abs=0.002) and wall.bounds[3] == pytest.approx(29.0, abs=1e-9)
    # its 118-degree point: the hole's bottom at Z -20 on the axis, rising along the cone to the full diameter
    for rho in (0.01, 2.5, 4.99):
        bottom = stock.intersection(LineString([(-30.0, rho), (0.0, rho)]))
        assert bottom.bounds[2] == pytest.approx(-20.0 + rho / math.tan(math.radians(59.0)), abs=0.002)


def test_the_insert_shapes_have_their_programmed_point_where_the_tip_says():
    from ncfmu.machining import grooving_insert, placed, turning_insert
    r = 0.4
    for tip in (1, 2, 3, 4):
        outline = placed(turning_insert(r), tip, r)
        # the imaginary tip: the extreme point of the tool along both axes, toward the work
        fz, fx = {1: (-1, -1), 2: (1, -1), 3: (1, 1), 4: (-1, 1)}[tip]
        assert (fz * outline[:, 0]).min() == pytest.approx(0.0, abs=1e-9)
        assert (fx * outline[:, 1]).min() == pytest.approx(0.0, abs=1e-9)
    # an 80-degree insert on a square holder: its side edge along X, its end edge rising 10 degrees from Z
    sharp = Polygon(turning_insert(0.0))
    assert sharp.contains(shapely.Point(5.0, 5.0 * math.tan(math.radians(10.0)) + 0.01))
    assert not sharp.contains(shapely.Point(5.0, 5.0 * math.tan(math.radians(10.0)) - 0.01))
    assert sharp.contains(shapely.Point(0.01, 10.0)) and not sharp.contains(shapely.Point(-0.01, 10.0))
    assert Polygon(grooving_insert(3.0, 0.2)).bounds == pytest.approx((0.0, 0.0, 3.0, 100.0))


@pytest.mark.parametrize("name, value, rule", [
    ("tool[2].width", -0.5, ">= 0"), ("tool[2].drill_diameter", math.inf, "finite"),
    ("tool[2].insert_angle", 95.0, "(0, 90]"), ("tool[2].insert_angle", 0.0, "(0, 90]"),
])
def test_the_tool_table_shapes_refuse_bad_values_naming_them(name, value, rule):
    with pytest.raises(ConfigError, match=rf"{re.escape(name)}.*{re.escape(rule)}"):
        CutSequencer(**{name: value})


def test_a_row_is_one_tool_and_a_blade_has_corners_of_at_most_half_its_width():
    with pytest.raises(ConfigError, match=r"tool\[4\]\.drill_diameter.*one tool"):
        CutSequencer(**{"tool[4].width": 3.0, "tool[4].drill_diameter": 8.0})
    with pytest.raises(ConfigError, match=r"tool\[4\]\.nose_radius.*half"):
        CutSequencer(**{"tool[4].width": 1.0, "tool[4].nose_radius": 0.8})


# -- the spindle ----------------------------------------------------------------------------------------------
NO_M03 = """%
O1003 (A CUT WITHOUT THE SPINDLE)
N10 G21 G98
N20 G00 X56. Z2.
N30 G01 Z-20. F300.
N40 G00 X62.
N50 M30
%
"""


def test_a_cut_while_the_spindle_never_started_is_a_crash_named_by_its_line_and_n_number():
    acc = lathe_check(NO_M03, [(2.0, 28.0, 1, 4, 0), (-20.0, 28.0, 0, 5, 0), (-20.0, 31.0, 1, 6, 0)], rpm=0.0)
    v = acc.verdict()
    assert [(c.line, c.what) for c in v.crashes] == [(5, STANDING)]
    assert v.crashes[0].depth_mm == pytest.approx(1.0, abs=0.002)
    summary = v.summary()
    assert summary[0].startswith("  part: CRASH at t = ") and "line 5 (N30): cut with the spindle stopped" in summary[0]
    assert not any("within" in line for line in summary)
    assert v.within_tolerance is False
    assert json.loads(json.dumps(v.as_json()))["crashes"][0]["n"] == 30


def test_the_same_cut_with_the_spindle_turning_is_no_crash():
    acc = lathe_check(NO_M03, [(2.0, 28.0, 1, 4, 0), (-20.0, 28.0, 0, 5, 0), (-20.0, 31.0, 1, 6, 0)], rpm=600.0)
    assert acc.verdict().crashes == []


def test_a_crashed_part_of_the_right_shape_is_never_within():
    v = PartVerdict([], 1, 0.01, "", max_left_mm=0.001, max_gouge_mm=0.002)
    assert not any("within" in line for line in v.summary())
    assert v.within_tolerance is False


# -- the mill's pocket ----------------------------------------------------------------------------------------
#: A counter-clockwise triangle: its corners' angles 90, 45, 45 degrees.
TRIANGLE = [(0.0, 0.0), (40.0, 0.0), (0.0, 40.0), (0.0, 0.0)]
POCKET = dict(closed=True, diameter_delta=0.6, side=1, feed=50.0, approach_feed=50.0, x_start=10.0, y_start=10.0,
              **points(TRIANGLE))


def mill_check(values: dict):
    c = ContourInterpolator(**values)
    path = drive_contour(c)
    assert path[-1, 5] == 1 and path[:, 6].max() == 0          # done, no alarm
    rows = np.zeros(len(path), dtype=[(n, float) for n in ("time", "contour.segment", "contour.done",
                                                            "x_axis.pos", "y_axis.pos")])
    rows["time"] = 1e-3 * np.arange(len(path))
    rows["x_axis.pos"], rows["y_axis.pos"] = path[:, 0], path[:, 1]
    rows["contour.segment"], rows["contour.done"] = path[:, 4], path[:, 5]
    acc = MILL.accumulator({"contour": values})
    acc.write(rows)
    return acc.verdict()


def test_a_pocket_milled_from_inside_is_no_gouge_and_leaves_its_corners():
    v = mill_check({**POCKET, "pocket": True})
    assert v.crashes == [] and v.judged == ""
    assert v.max_gouge_mm < 0.005
    # what a cutter of radius 0.3 cannot reach: the 45-degree corners -- on their bisector, the cutter's edge
    # r / sin(22.5 deg) - r from the corner, r (1 - sin(22.5 deg)) from either wall
    r = 0.3
    assert v.max_left_mm == pytest.approx(r * (1.0 - math.sin(math.radians(22.5))), abs=0.003)
    assert v.within_tolerance is False


def test_a_pocket_with_the_compensation_on_the_wrong_side_gouges_a_cutter_diameter():
    v = mill_check({**POCKET, "pocket": True, "side": -1})
    assert v.crash_count >= 1 and all("gouge" in c.what for c in v.crashes)
    # the cutter (0.6 across) runs outside the wall, in the plate: at least its diameter deep along the edges
    assert v.max_gouge_mm >= 0.6 - 0.005
    assert v.within_tolerance is False
