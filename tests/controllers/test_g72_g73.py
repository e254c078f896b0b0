"""G72 (stock removal in facing), G73 (pattern repeat) and G70 finishing them: the commanded path against each
cycle's definition (Fanuc 0i-T), and the programs refused naming the line."""

from __future__ import annotations

import pytest

from ncfmu.controllers import CutSequencer
from ncfmu.controllers.lathe_program import Finish, PlannedCycle, parse, plan
from ncfmu.errors import ProgramError

X0, Z0 = 30.0, 2.0          # the start point (radius, Z)

#: A face in radius values: from X30 at Z-6 down to X20, a shoulder forward to Z-2, the face down to the axis.
#: G72 W1.5 (depth of cut in Z) R0.5 (retract), allowances U0.2 (radius, G8) W0.1.
FACE = """G18 G21 G90 G8
G00 X30 Z2
G72 W1.5 R0.5
G72 P10 Q20 U0.2 W0.1 F300
N10 G00 Z-6
G01 X20
Z-2
N20 X0
G70 P10 Q20 F120
M30
"""


def ends(e) -> tuple[float, float, float, float]:
    return (*e.start, *e.end)


def flat(pairs) -> list:
    return [pytest.approx((*a, *b), abs=1e-9) for a, b in pairs]


def segments(text: str, cycle: int) -> list:
    return [g for g in plan(text, (X0, Z0), 50.0) if g.cycle == cycle]


def test_g72_passes_step_in_z_and_cut_along_x():
    rough = segments(FACE, 72)
    cuts = [g for g in rough if g.subcycle == 2]
    last = max(g.pass_no for g in rough)
    passes = [g for g in cuts if g.pass_no < last]
    # levels Z = 2 - 1.5 k while in front of the shifted profile's deepest Z (-6 + W0.1): 0.5, -1, -2.5, -4, -5.5
    assert [g.element.start[0] for g in passes] == pytest.approx([0.5, -1.0, -2.5, -4.0, -5.5], abs=1e-9)
    for g in passes:
        (zs, xs), (ze, _) = g.element.start, g.element.end
        assert zs == pytest.approx(ze, abs=1e-9) and xs == pytest.approx(X0, abs=1e-9) and g.feed   # along -X
    # each pass ends on the profile + allowance: in front of the face Z-1.9 at X0.2, behind it at X20.2
    assert [g.element.end[1] for g in passes] == pytest.approx([0.2, 0.2, 20.2, 20.2, 20.2], abs=1e-9)
    # SC3 retracts by R0.5 at 45 degrees (+Z, +X), SC4 returns in +X to the start point's X
    for k in range(1, last):
        sc2, sc3, sc4 = ([g for g in rough if g.pass_no == k and g.subcycle == s] for s in (2, 3, 4))
        (z, x) = sc2[-1].element.end
        assert sc3[0].element.start == pytest.approx((z, x), abs=1e-9)
        assert sc3[0].element.end == pytest.approx((z + 0.5, x + 0.5), abs=1e-9) and not sc3[0].feed
        assert sc4[-1].element.end == pytest.approx((z + 0.5, X0), abs=1e-9) and not sc4[-1].feed
    # the last pass runs along the profile shifted by (W0.1, U0.2), from the start point's X on: the allowance left
    final = [g.element for g in cuts if g.pass_no == last]
    assert [ends(e) for e in final] == flat([((-5.9, 30.0), (-5.9, 20.2)), ((-5.9, 20.2), (-1.9, 20.2)),
                                             ((-1.9, 20.2), (-1.9, 0.2))])
    assert rough[-1].element.end == pytest.approx((Z0, X0), abs=1e-9)          # back at the start point


def test_g72_in_diameters_is_the_same_path():
    """X and U in the X mode: G7's U0.4 is G8's U0.2."""
    twin = FACE.replace("G8", "G7").replace("U0.2", "U0.4").replace("X30", "X60").replace("X20", "X40")
    assert plan(twin, (X0, Z0), 50.0) == plan(FACE, (X0, Z0), 50.0)


def test_g70_finishes_the_g72_profile_and_leaves_the_face_in_z():
    g70 = segments(FACE, 70)
    assert g70[0].subcycle == 1 and g70[0].element.end == pytest.approx((-6.0, 30.0), abs=1e-9)   # Z only
    profile = [ends(g.element) for g in g70 if g.subcycle == 2]
    assert profile == flat([((-6, 30), (-6, 20)), ((-6, 20), (-2, 20)), ((-2, 20), (-2, 0))])
    assert all(g.rate == pytest.approx(2.0) for g in g70 if g.subcycle == 2)      # G70's F120 mm/min
    # SC3 off the face in +Z to the start point's Z, SC4 back out in +X: never along the finished face
    sc3, sc4 = [g for g in g70 if g.subcycle == 3], [g for g in g70 if g.subcycle == 4]
    assert sc3[0].element.start == pytest.approx((-2.0, 0.0)) and sc3[-1].element.end == pytest.approx((Z0, 0.0))
    assert sc4[-1].element.end == pytest.approx((Z0, X0))
    ops = parse(FACE, (X0, Z0))
    assert [op.code for op in ops if isinstance(op, PlannedCycle)] == [72, 70]


def test_the_sequencer_runs_g72_and_reports_it():
    from lathe_oracle import run_ideal
    run = run_ideal(CutSequencer(program=FACE, x_start=X0, z_start=Z0, x_diameter=False), dt=2e-3)
    assert run["done"][-1] and not run["alarm"].any()
    assert set(run["canned_cycle"]) == {0, 70, 72}
    g72 = run["canned_cycle"] == 72
    assert run["z_cmd"][g72].min() == pytest.approx(-5.9, abs=1e-9)           # never deeper than the allowance
    assert set(run["pass_no"][g72 & (run["subcycle"] == 2)]) == {1, 2, 3, 4, 5, 6}


#: A pattern in radius values: the start point X30 Z2, the profile from X10 Z1: Z-5, a taper to X20 Z-10, Z-15,
#: out to X30. G73 U3 (escape X, radius) W1 (escape Z) R3 (passes), allowances U0.4 (radius, G8) W0.1.
PATTERN = """G18 G21 G90 G8
G00 X30 Z2
G73 U3 W1 R3
G73 P10 Q20 U0.4 W0.1 F300
N10 G00 X10 Z1
G01 Z-5
X20 Z-10
Z-15
N20 X30
G70 P10 Q20
M30
"""
PROFILE = [((1, 10), (-5, 10)), ((-5, 10), (-10, 20)), ((-10, 20), (-15, 20)), ((-15, 20), (-15, 30))]


def test_g73_runs_the_profile_shifted_d_times_evenly_down_to_the_allowance():
    g73 = segments(PATTERN, 73)
    (op,) = [op for op in parse(PATTERN, (X0, Z0)) if isinstance(op, PlannedCycle)]
    # the first pass off by (Δk + W, Δi + U) = (1.1, 3.4), the last by the allowance (0.1, 0.4), even steps
    assert [c for shift in op.shifts for c in shift] == pytest.approx([1.1, 3.4, 0.6, 1.9, 0.1, 0.4], abs=1e-12)
    assert sorted({g.pass_no for g in g73} - {0}) == [1, 2, 3]
    for k, (dz, dx) in enumerate(op.shifts, 1):
        passing = [g for g in g73 if g.pass_no == k]
        sc1 = [g for g in passing if g.subcycle == 1]
        assert sc1[0].element.start == pytest.approx((Z0, X0))
        assert sc1[-1].element.end == pytest.approx((1 + dz, 10 + dx))
        assert not sc1[-1].feed                                                    # the G00 of N10
        cut = [ends(g.element) for g in passing if g.subcycle == 2]
        assert cut == flat([((a[0] + dz, a[1] + dx), (b[0] + dz, b[1] + dx)) for a, b in PROFILE])
        assert all(g.feed and g.rate == pytest.approx(5.0) for g in passing if g.subcycle == 2)   # F300 mm/min
    assert g73[-1].element.end == pytest.approx((Z0, X0))


def test_g70_finishes_the_g73_profile():
    g70 = segments(PATTERN, 70)
    cut = [ends(g.element) for g in g70 if g.subcycle == 2]
    assert cut == flat(PROFILE)
    assert [(type(op), getattr(op, "code", 70)) for op in parse(PATTERN, (X0, Z0))
            if isinstance(op, (PlannedCycle, Finish))] == [(PlannedCycle, 73), (Finish, 70)]


def test_g73_with_one_pass_and_no_escape_cuts_on_the_allowance():
    one = PATTERN.replace("G73 U3 W1 R3", "G73 U0 W0 R1")
    cut = [g for g in segments(one, 73) if g.subcycle == 2]
    assert {g.pass_no for g in cut} == {1}
    assert cut[0].element.start == pytest.approx((1.1, 10.4))


def refused(text: str) -> ProgramError:
    with pytest.raises(ProgramError) as err:
        parse(text, (X0, Z0))
    return err.value


@pytest.mark.parametrize("first, why", [("N10 G00 X28 Z-6", "in Z only"), ("N10 G00 X28", "in Z only"),
                                        ("N10 G00 Z4", "in Z only")])
def test_g72s_first_block_moves_in_z_only_toward_the_chuck(first, why):
    err = refused(FACE.replace("N10 G00 Z-6", first))
    assert (err.line_no, why in str(err)) == (5, True)


@pytest.mark.parametrize("block, line, why", [
    ("Z-2\nZ-3", 8, "moves -Z here"),              # the shoulder turns back toward the chuck
    ("Z-2\nX25", 8, "moves +X here"),              # rises again on the way to the axis
    ("G02 X20 Z-2 R2", 7, "moves +X here"),         # a half circle: X leaves and comes back
    ("G02 X16 Z-5 R-3", 7, "moves -Z here"),        # more than half a circle: it passes behind its start's Z
])
def test_a_g72_profile_that_is_not_monotonic_is_refused_naming_its_line(block, line, why):
    err = refused(FACE.replace("Z-2\nN20 X0", f"{block}\nN20 G01 X0"))
    assert (err.line_no, why in str(err)) == (line, True)


@pytest.mark.parametrize("r", ["R0", "R2.5", "R-1"])
def test_g73_takes_a_whole_number_of_passes(r):
    err = refused(PATTERN.replace("R3", r))
    assert err.line_no == 3 and "number of passes, a whole number >= 1" in str(err)


def test_g73_one_pass_with_an_escape_is_refused():
    err = refused(PATTERN.replace("R3", "R1"))
    assert err.line_no == 3 and "give R >= 2" in str(err)


def test_g73_with_a_z_shift_on_a_pocket_is_refused():
    err = refused(PATTERN.replace("Z-15\n", "Z-12\nX15 Z-13\nZ-15\n"))
    assert err.line_no == 4 and "pocket (X falls along -Z on line 9)" in str(err)


def test_g72_g73_without_their_first_block_or_under_g42_are_refused():
    err = refused(FACE.replace("G72 W1.5 R0.5\n", ""))
    assert err.line_no == 3 and "G72's first block (G72 W<depth> R<retract>)" in str(err)
    err = refused(PATTERN.replace("G00 X30 Z2\n", "G00 X30 Z2\nG42 G01 X30 Z2.5 F100\nG00 X30 Z2\n"))
    assert err.line_no == 6 and "G40" in str(err)


@pytest.mark.parametrize("cycle", ["G90 X25 Z-6 F300\nX20", "G94 X10 Z1 F300\nZ0.5"])
@pytest.mark.parametrize("program", [FACE, PATTERN])
def test_g72_g73_right_after_modal_single_cycle_passes_are_their_own_blocks(cycle, program):
    # G72/G73 are Fanuc's group 00: their U/W never make the next pass of a modal G90/G94 (as G71's don't)
    after = program.replace("G00 X30 Z2\n", f"G00 X30 Z2\n{cycle}\n", 1)
    code = 72 if "G72" in program else 73
    ops = parse(after, (X0, Z0))
    (cycle_op,) = [op for op in ops if isinstance(op, PlannedCycle) and op.code == code]
    (alone,) = [op for op in parse(program, (X0, Z0)) if isinstance(op, PlannedCycle) and op.code == code]
    assert [(g.element, g.feed, g.subcycle, g.pass_no) for g in cycle_op.segments] == \
        [(g.element, g.feed, g.subcycle, g.pass_no) for g in alone.segments]


def test_a_g73_profile_above_the_start_points_x_is_refused_naming_its_line():
    # each pass returns to the start point's Z at its X (SC4): a collar of the part higher than that is in the way
    err = refused(PATTERN.replace("X20 Z-10", "X35 Z-10"))
    assert err.line_no == 7 and "above the start point's X 30" in str(err), str(err)


def test_g73_returns_over_the_highest_point_of_each_shifted_pass():
    # a collar (X29, radius) below the start point's X30 but ending lower (X25): the first pass is shifted 3.4 up
    # (the blank's surface there at X32.4); the return to the start point's Z passes above it, not through it
    text = (PATTERN.replace("G73 U3 W1 R3", "G73 U3 W0 R3").replace("U0.4 W0.1", "U0.4 W0")
            .replace("X20 Z-10\nZ-15\nN20 X30", "X29 Z-8\nX20 Z-12\nZ-15\nN20 X25"))
    (op,) = [op for op in parse(text, (X0, Z0)) if isinstance(op, PlannedCycle)]
    for k, (_, dx) in enumerate(op.shifts, 1):
        returns = [g.element for g in op.segments if g.pass_no == k and g.subcycle == 4]
        assert returns and all(min(e.start[1], e.end[1]) >= 29 + dx - 1e-9 for e in returns), (k, returns)
    assert op.segments[-1].element.end == pytest.approx((Z0, X0))


def test_g72s_last_pass_leaves_a_face_inside_the_stock_at_45_degrees_too():
    # the front face at Z-3 (allowance W0.1: Z-2.9), inside a bar: the pass along the profile ends on it at X0.2, in the
    # material its clearance angle leaves; straight off in +Z the insert's end edge drags across it at rapid (the
    # part check: 'rapid into the stock', 0.087 mm), so it leaves as the rough passes do: by R in +Z and +X
    rough = segments(FACE.replace("N10 G00 Z-6\nG01 X20\nZ-2", "N10 G00 Z-6\nG01 X20\nZ-3"), 72)
    last = max(g.pass_no for g in rough)
    sc2, sc3, sc4 = ([g for g in rough if g.pass_no == last and g.subcycle == s] for s in (2, 3, 4))
    (z, x) = sc2[-1].element.end
    assert (z, x) == pytest.approx((-2.9, 0.2), abs=1e-9)
    assert sc3[0].element.end == pytest.approx((z + 0.5, x + 0.5), abs=1e-9) and not sc3[0].feed
    assert sc4[-1].element.start == sc3[-1].element.end and sc4[-1].element.end[1] == pytest.approx(X0)
