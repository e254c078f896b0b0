"""G74 (face peck drilling, face grooving) and G75 (grooving) as Fanuc's 0i-T manual defines their moves (plain-Python
planner, no FMU): the pecks (how many, each Q or P deep, the retracts e, the last to the end point), the steps across
X (G74) or Z (G75), the relief at the bottom, the return to the start point, the region each cuts away by its
definition -- a hypothesis property over the numbers -- and the refusals, naming the line."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ncfmu.controllers import lathe_program
from ncfmu.controllers.g7x import PeckCycle, Tool
from ncfmu.controllers.peck_cycles import DRILL_POINT, plan_pecks
from ncfmu.errors import ProgramError, ProgramErrors

#: The tool table: row 1 a turning insert, row 2 a grooving blade 3 mm wide (tip 3: its corner toward the chuck
#: programmed), row 3 a drill of 10 mm.
TOOLS = (Tool(), Tool(width=3.0, tip=3), Tool(drill_diameter=10.0)) + (Tool(),) * 5
SETUP = lathe_program.Setup(tools=TOOLS)
RAPID = 50.0

#: A hole 10 mm in diameter, 20 mm deep from the face (Z0), pecked 5 mm at a time from Z2, retract 0.5 mm.
DRILL = """G21 G98 G97 S600 M03 T0303
G00 X0. Z2.
G74 R0.5
G74 Z-20. Q5000 F30.
G00 Z5.
M30"""
#: A groove 3 + 8 mm wide (Z -18 .. -7) down to X40 from X62, pecked 3 mm (radius) at a time, stepped 2.5 mm.
GROOVE = """G21 G98 G97 S600 M03 T0202
G00 X62. Z-10.
G75 R0.5
G75 X40. Z-18. P3000 Q2500 F50.
G00 X70.
M30"""


def _cycle(text: str, start=(31.0, 2.0), setup=SETUP) -> PeckCycle:
    [op] = [op for op in lathe_program.parse(text, start, setup) if isinstance(op, PeckCycle)]
    return op


def _refusal(text: str, setup=SETUP) -> ProgramError:
    with pytest.raises((ProgramError, ProgramErrors)) as info:
        lathe_program.parse(text, (31.0, 2.0), setup)
    err = info.value
    return err.errors[0] if isinstance(err, ProgramErrors) else err


def test_g74_on_the_axis_pecks_q_deep_each_retracts_e_and_returns_to_the_start_point():
    op = _cycle(DRILL)
    segs = op.segments
    assert all(g.cycle == 74 and g.line == 4 for g in segs)
    assert all(g.element.start[1] == 0.0 and g.element.end[1] == 0.0 for g in segs)     # on the axis all along
    pecks = [g for g in segs if g.feed]
    # from Z2: 5 mm a peck to Z -3, -8, -13, -18, then the last 2 mm to the end Z -20
    assert [g.element.end[0] for g in pecks] == pytest.approx([-3.0, -8.0, -13.0, -18.0, -20.0])
    assert all(g.rate == pytest.approx(30.0 / 60.0) and g.subcycle == 2 for g in pecks)
    # each peck after the first feeds back through the retract e and then 5 mm (the last 2 mm) of new depth
    assert [g.element.start[0] - g.element.end[0] for g in pecks] == pytest.approx([5.0, 5.5, 5.5, 5.5, 2.5])
    retracts = [g for g in segs if g.subcycle == 3]
    assert len(retracts) == 4 and not any(g.feed for g in retracts)
    assert all(g.element.end[0] - g.element.start[0] == pytest.approx(0.5) for g in retracts)
    # from the bottom straight out to the start point at rapid, where the tool stands after the cycle
    assert segs[-1].element.start == (-20.0, 0.0) and segs[-1].element.end == (2.0, 0.0) and not segs[-1].feed
    assert op.end == (2.0, 0.0)
    # the plan (with the rapid rate) continues from the start point: the next G00 Z5. starts at Z2 on the axis
    plan = lathe_program.plan(DRILL, (31.0, 2.0), RAPID, SETUP)
    after = plan[plan.index(next(g for g in plan if g.line == 5))]
    assert after.element.start == (2.0, 0.0) and after.element.end == (5.0, 0.0)
    assert all(g.rate == RAPID for g in plan if g.cycle == 74 and not g.feed)


def test_g74_steps_p_across_x_to_the_end_x_with_the_relief_after_the_first_plunge():
    # a face groove from X40 to X60 (radius 20 .. 30), 6 mm deep from Z1: steps of 2 mm (P2000, radius), pecks of
    # 2 mm (Q2000), retract 0.4, relief 0.3 in -X (against the steps) at the bottom of every plunge but the first
    op = _cycle("G21 G98 T0101\nG00 X40. Z1.\nG74 R0.4\nG74 X60. Z-5. P2000 Q2000 R0.3 F60.\nM30")
    segs = op.segments
    plunges = [g.element.start[1] for g in segs if g.subcycle == 2 and g.element.start[0] == 1.0]
    assert plunges == pytest.approx([20.0, 22.0, 24.0, 26.0, 28.0, 30.0])
    for j, x in enumerate(plunges, 1):
        mine = [g for g in segs if g.pass_no == j]
        ends = [g.element.end[0] for g in mine if g.feed]
        assert ends == pytest.approx([-1.0, -3.0, -5.0]) and all(g.element.end[1] == x for g in mine if g.feed)
        relief = [g for g in mine if g.subcycle == 4 and g.element.start == (-5.0, x)]
        assert relief[0].element.end == ((-5.0, x - 0.3) if j > 1 else (1.0, x))
    assert all(g.element.end[1] <= 30.0 and g.element.end[0] >= -5.0 for g in segs)
    assert segs[-1].element.end == (1.0, 20.0)
    # the steps between the plunges: at rapid, at the start point's Z, from the relieved X to the next plunge's
    steps = [g for g in segs if g.subcycle == 1]
    assert [g.element.end for g in steps] == [(1.0, x) for x in plunges[1:]]
    assert [g.element.start[1] for g in steps] == pytest.approx([20.0] + [x - 0.3 for x in plunges[1:-1]])


def test_g75_pecks_p_in_x_and_steps_q_along_z_and_cuts_a_groove_of_the_blade_and_the_steps():
    op = _cycle(GROOVE)
    segs = op.segments
    # from X62 (radius 31): pecks of 3 mm to radius 28, 25, 22 and the last to 20; steps of 2.5 mm along -Z from
    # Z-10 to the end Z-18: plunges at -10, -12.5, -15, -17.5 and the last at -18
    plunges = sorted({g.element.end[0] for g in segs if g.feed}, reverse=True)
    assert plunges == pytest.approx([-10.0, -12.5, -15.0, -17.5, -18.0])
    for j, z in enumerate(plunges, 1):
        pecks = [g for g in segs if g.feed and g.pass_no == j]
        assert [g.element.end for g in pecks] == [(z, 28.0), (z, 25.0), (z, 22.0), (z, 20.0)]
        retracts = [g for g in segs if g.subcycle == 3 and g.pass_no == j]
        assert [g.element.end[1] - g.element.start[1] for g in retracts] == pytest.approx([0.5] * 3)
        assert all(g.rate == pytest.approx(50.0 / 60.0) for g in pecks)
    assert segs[-1].element.end == (-10.0, 31.0) == op.end
    # the blade (3 mm along +Z from its programmed corner) makes the groove Z -18 .. -7, down to radius 20
    zs = [p[0] for p in op.removed()]
    xs = [p[1] for p in op.removed()]
    assert (min(zs), max(zs), min(xs)) == (-18.0, -7.0, 20.0) and max(xs) >= 1e4


def test_g74_with_a_drill_removes_the_hole_with_its_point():
    (z0, x0), (z1, x1), *_ = _cycle(DRILL).removed()
    cone = 5.0 / math.tan(math.radians(DRILL_POINT / 2.0))
    assert (z0, x0) == (-20.0, 0.0) and (z1, x1) == pytest.approx((-20.0 + cone, 5.0))


def test_g74_g75_without_x_or_z_keep_the_start_points_and_work_in_incremental_words():
    # G75 with U and W: from X62 Z-10 down 22 mm on the diameter, 0 along Z: one plunge
    op = _cycle("G21 G98 T0202\nG00 X62. Z-10.\nG75 R1.\nG75 U-22. P4000 F50.\nM30")
    assert {g.element.end[0] for g in op.segments} == {-10.0}
    assert [g.element.end[1] for g in op.segments if g.feed] == pytest.approx([27.0, 23.0, 20.0])
    op = _cycle("G21 G98 T0303\nG00 X0. Z2.\nG74 R0.\nG74 W-7. Q7000 F30.\nM30")
    assert [g.element.end for g in op.segments] == [(-5.0, 0.0), (2.0, 0.0)]


@settings(max_examples=80)
@given(depth=st.floats(0.1, 20.0), span=st.floats(0.0, 10.0), peck=st.floats(0.5, 10.0),
       step=st.floats(0.5, 5.0), retract=st.floats(0.0, 2.0), relief=st.floats(0.0, 0.5),
       code=st.sampled_from((74, 75)), down=st.booleans())
def test_no_commanded_point_passes_the_end_point_and_no_peck_is_deeper_than_asked(depth, span, peck, step, retract,
                                                                                   relief, code, down):
    peck = min(peck, depth)
    span = 0.0 if span < 0.1 else span
    a = 0 if code == 74 else 1
    s = (2.0, 30.0)
    d = -1.0 if down else 1.0
    end = [0.0, 0.0]
    end[a], end[1 - a] = s[a] - depth, s[1 - a] + d * span
    relief = min(relief, step, span)
    segs = plan_pecks(code, s, (end[0], end[1]), peck, step if span else 0.0, retract, relief, 1.0, 1)
    lo, hi = sorted((s[1 - a], end[1 - a]))
    deepest: dict[float, float] = {}            # plunge's place across -> the deepest reached there (along a)
    for g in segs:
        for p in (g.element.start, g.element.end):
            assert p[a] >= end[a] - 1e-9                                    # never beyond the end along the pecks
            assert lo - 1e-9 <= p[1 - a] <= hi + 1e-9               # never beyond the end (nor the start) across
        if g.feed:
            across, before = g.element.end[1 - a], deepest.get(g.element.end[1 - a], s[a])
            assert g.element.start[1 - a] == across                          # a peck runs along its axis only
            assert before - g.element.end[a] <= peck + 1e-9                  # at most one peck of new depth
            deepest[across] = min(before, g.element.end[a])
    assert all(v == pytest.approx(end[a], abs=1e-12) for v in deepest.values())   # every plunge to the end
    assert max(deepest) == pytest.approx(hi) and min(deepest) == pytest.approx(lo)   # to the end across
    assert sorted(deepest) == sorted(set(deepest))
    if span:
        gaps = sorted(deepest)
        assert all(b - a_ <= step + 1e-9 for a_, b in zip(gaps, gaps[1:]))     # steps of at most P (Q)
    assert segs[-1].element.end == s                                        # back at the start point


@pytest.mark.parametrize("program, line, fragment", [
    (DRILL.replace("Q5000", "Q5000."), 4, "Q5000.: the peck in Z is a whole number of um >= 0 without a decimal"),
    (GROOVE.replace("P3000", "P3.5"), 4, "P3.5: the peck in X"),
    (DRILL.replace("Q5000", "Q0"), 4, "Q0: a peck of 0 um"),
    (DRILL.replace("Q5000", "Q30000"), 4, "Q30000: a peck of 30 mm is longer than the cut (22 mm"),
    (GROOVE.replace("P3000", "P0"), 4, "P0: a peck of 0 um"),
    (GROOVE.replace("Q2500", "Q0"), 4, "Q0: a step of 0 um never reaches the end Z"),
    (GROOVE.replace("Q2500", "Q3500"), 4, "Q3500: steps of 3.5 mm in Z wider than the blade (tool[2].width 3)"),
    (DRILL.replace("Z-20. Q5000", "X10. Z-20. P1000 Q5000"), 4, "G74 of a tool on the spindle axis steps across X"),
    (DRILL.replace("G00 X0.", "G00 X20."), 4, "a drill drills on the spindle axis, start G74 at X0"),
    (DRILL.replace("T0303", "T0101"), 4, "the active offset's row (tool[1]) is no drill: set tool[1].drill_diameter"),
    (GROOVE.replace("T0202", "T0303"), 4, "G75 with a drill (tool[3].drill_diameter 10)"),
    (DRILL.replace("G74 R0.5\n", ""), 3, "G74 X Z P Q R F needs G74's first block (G74 R<retract, mm>)"),
    (DRILL.replace("F30.", "R0.2 F30."), 4, "R0.2: a relief at the bottom is made on the plunges after the first"),
    (DRILL.replace("G74 R0.5", "G74 R0.5 F30."), 3, "G74's first block gives the retract R (mm, after each peck)"),
    (DRILL.replace("G74 Z-20.", "G74 G01 Z-20."), 4, "G01 in a G74 block: give it a block of its own"),
    (GROOVE.replace("G75 X40. Z-18.", "G75 Z-18."), 4, "G75 gives the end X the pecks reach (X or U)"),
    (DRILL.replace("G74 Z-20.", "G74 Z2."), 4, "G74: the end point's Z is the start point's"),
    # a drill's hole opens toward the tailstock (+Z): drilling away from the face starts inside the part
    (DRILL.replace("G74 Z-20.", "G74 Z10."), 4, "a drill drills toward the chuck (-Z)"),
    # a groove's width is the blade's: a row without one (a turning insert) has no groove to cut by definition
    (GROOVE.replace("T0202", "T0101"), 4, "the active offset's row (tool[1]) is no grooving blade: set tool[1].width"),
    (GROOVE.replace(" T0202", ""), 4, "give a grooving blade's offset first (T, its row's tool[k].width)"),
    # an outside blade (tip 3) pecking away from the axis: its groove's region would open upward from X70, missing
    # the band from X62 it cuts, and the blade's body stands in the part
    (GROOVE.replace("G75 X40.", "G75 X70."), 4, "tool[2].tip 3 is an outside blade: its pecks run toward the axis"),
    ("G21 G98 T0101\nG00 X60. Z2.\nG71 U1. R0.5\nG71 P10 Q20 U0.2 W0.1 F100.\nN10 G00 X40.\nG75 X30. Z-10. P1000\n"
     "N20 G01 Z-20.\nM30", 6, "G75 (a peck cycle) inside a profile"),
])
def test_refusals_name_the_line_and_the_rule(program, line, fragment):
    err = _refusal(program)
    assert err.line_no == line and fragment in err.reason, err.reason


def test_g75_region_puts_the_blade_where_its_tip_says_with_its_rounded_corners():
    from ncfmu.controllers.peck_cycles import region
    # tip 4: the programmed corner toward the tailstock, the blade 3 mm toward -Z: the groove Z -21 .. -10
    left = region(75, (-10.0, 31.0), (-18.0, 20.0), Tool(width=3.0, tip=4, nose_radius=0.5))
    zs, xs = [p[0] for p in left], [p[1] for p in left]
    assert (min(zs), max(zs), min(xs)) == pytest.approx((-21.0, -10.0, 20.0))
    # the bottom corners are the blade's: the corner's point on its bisector r (1 - 1/sqrt 2) in from each side
    corner = min(left, key=lambda p: math.dist(p, (-21.0, 20.0)))
    assert math.dist(corner, (-21.0, 20.0)) == pytest.approx(0.5 * (math.sqrt(2.0) - 1.0), abs=1e-3)
    # tip 2 (inside work, a bore's groove from the hole's radius 10 out to 12): it opens toward the axis
    inside = region(75, (-10.0, 10.0), (-14.0, 12.0), Tool(width=3.0, tip=2))
    assert max(p[1] for p in inside) == 12.0 and min(p[1] for p in inside) <= -1e4
    assert (min(p[0] for p in inside), max(p[0] for p in inside)) == (-14.0, -7.0)
