"""Lathe programs that must be refused (issue 32, section 3: found by a red team): arcs leaving the stock between
their end points, an allowance that leaves nothing to rough, duplicate block numbers; and planning bounded."""

from __future__ import annotations

import pytest

from ncfmu.controllers.g7x import MAX_SEGMENTS
from ncfmu.controllers.lathe_program import parse, plan
from ncfmu.errors import ProgramError

HEAD = "G18 G21 G90 G8\nG00 X30 Z2\nG71 U1 R0.5\nG71 P10 Q20 F300\n"


def refused(text: str) -> ProgramError:
    with pytest.raises(ProgramError) as err:
        parse(text, (30.0, 2.0))
    return err.value


def test_an_arc_dipping_below_the_spindle_axis_is_refused():
    # G02 from X2 Z0 to X2 Z-10 about Z-5: a half circle of radius 5 whose lowest point is X -3
    err = refused(HEAD + "N10 G00 X2\nG01 Z0\nG02 X2 Z-10 I0 K-5\nN20 G01 X30\nM30\n")
    assert (err.line_no, err.column) == (7, 1)
    assert "crosses the spindle axis" in str(err) and "X -3" in str(err)


def test_an_arc_bulging_above_the_start_point_is_refused():
    # G03 from X26 to X26 about Z-5 from the start point X30: its highest point is X31
    err = refused(HEAD + "N10 G00 X26\nG01 Z0\nG03 X26 Z-10 I0 K-5\nN20 G01 X30\nM30\n")
    assert (err.line_no, err.column) == (7, 1)
    assert "leaves the stock: X 31 above the start point's X 30" in str(err)


def test_an_arc_inside_the_stock_still_runs():
    """The check can pass: the same half circle lifted clear of the axis and below the start point runs."""
    ops = parse(HEAD + "N10 G00 X8\nG01 Z0\nG02 X8 Z-10 I0 K-5\nN20 G01 X30\nM30\n", (30.0, 2.0))
    assert [type(op).__name__ for op in ops] == ["Rough"]


def test_an_allowance_that_leaves_nothing_to_rough_is_refused():
    text = HEAD.replace("G71 P10 Q20 F300", "G71 P10 Q20 U20 F300") + "N10 G00 X14\nG01 Z-20\nN20 X30\nM30\n"
    err = refused(text)
    assert (err.line_no, err.column) == (4, 13)
    assert "U20" in str(err) and "nothing to rough" in str(err)
    # an allowance that leaves something (the boundary 1 mm below the start point's X) runs
    assert parse(text.replace("U20", "U15"), (30.0, 2.0))


def test_duplicate_block_numbers_are_refused_naming_both_lines():
    err = refused(HEAD + "N10 G00 X20\nN20 G01 Z-10\nN20 X30\nM30\n")
    assert (err.line_no, err.column) == (7, 1)
    assert "N20" in str(err) and "line 6" in str(err)


# -- planning is bounded ------------------------------------------------------------------------------------
def pocket_profile(u: float) -> str:
    """The red team's ~300-byte pocket profile: four grooves between radii and tapers, X as radius."""
    return (f"G18 G21 G90 G8\nG00 X30 Z2\nG71 U{u} R0.2\nG71 P10 Q20 U0.1 W0 F300\nN10 G00 X20\nG01 Z-2\n"
            "X6 Z-4\nZ-8\nG02 X10 Z-12 R4\nG01 X4 Z-14\nZ-18\nG02 X8 Z-22 R4\nG01 X2 Z-24\nZ-28\nX18 Z-30\n"
            "X3 Z-33\nZ-36\nG02 X7 Z-40 R4\nG01 X22 Z-42\nZ-44\nN20 X30\nG70 P10 Q20 F180\nM30\n")


def v_pockets(n: int, u: float) -> str:
    """``n`` V-shaped pockets 20 mm deep side by side (about 1 KB for 50)."""
    lines = ["G18 G21 G90 G8", "G00 X30 Z2", f"G71 U{u} R0.2", "G71 P10 Q20 U0.05 W0 F300", "N10 G00 X25", "G01 Z-1"]
    z = -1.0
    for _ in range(n):
        lines += [f"X5 Z{z - 1:g}", f"X25 Z{z - 2:g}"]
        z -= 2
    return "\n".join([*lines, f"Z{z - 1:g}", "N20 X30", "G70 P10 Q20 F180", "M30", ""])


def test_the_pocket_profile_plans_its_passes():
    """The red team's worst accepted program (12.8 s of CPU before): planned, every pass above the profile."""
    segments = plan(pocket_profile(0.05), (30.0, 2.0), 50.0)
    assert 5000 < len(segments) <= MAX_SEGMENTS
    rough = [s for s in segments if s.cycle == 71]
    assert min(min(s.element.start[1], s.element.end[1]) for s in rough) == pytest.approx(2.0 + 0.1)


def test_fifty_v_pockets_are_refused_by_the_move_count():
    with pytest.raises(ProgramError, match=rf"line 4, column 1: more than {MAX_SEGMENTS} moves: \d+ passes of U0.01"):
        plan(v_pockets(50, 0.01), (30.0, 2.0), 50.0)
    assert len(v_pockets(50, 0.01)) <= 1024


# -- inside work (boring): the profile rises from the start point's X, U is negative ------------------------
BORE = "G18 G21 G90 G8\nG00 X10 Z2\nG71 U1 R0.5\nG71 P10 Q20 U{u} F300\nN10 G00 X18\nG01 Z-10\n{mid}N20 G01 X10\nM30\n"


def test_an_inside_profile_roughs_outward_with_a_negative_u():
    from ncfmu.controllers.g7x import Rough

    (rough,) = parse(BORE.format(u=-0.2, mid="X14 Z-14\nZ-20\n"), (10.0, 2.0))
    assert isinstance(rough, Rough) and rough.profile.inside and rough.u == -0.2
    cuts = [g for g in plan(BORE.format(u=-0.2, mid="X14 Z-14\nZ-20\n"), (10.0, 2.0), 100.0) if g.subcycle == 2]
    levels = [g.element.start[1] for g in cuts if g.pass_no < cuts[-1].pass_no]
    assert levels == [11.0, 12.0, 13.0, 14.0, 15.0, 16.0, 17.0]     # outward from X 10 by U1, below 18 - 0.2


def test_an_inside_profile_with_a_positive_u_is_refused():
    err = refused_at(BORE.format(u=0.2, mid=""), (10.0, 2.0))
    assert (err.line_no, err.column) == (4, 13) and "an inside profile" in str(err) and "U <= 0" in str(err)


def test_an_inside_profile_below_the_bore_s_start_x_is_refused():
    # the bore's profile dips to X 8 under the drilled hole's X 10: it leaves the stock
    err = refused_at(BORE.format(u=-0.2, mid="X8 Z-12\nZ-20\n"), (10.0, 2.0))
    assert (err.line_no, err.column) == (7, 1)
    assert "leaves the stock: X 8 below the start point's X 10" in str(err) and "above the bore's start X" in str(err)


def test_an_inside_allowance_that_leaves_nothing_to_rough_is_refused():
    err = refused_at(BORE.format(u=-20, mid=""), (10.0, 2.0))
    assert err.line_no == 4 and "nowhere above the start point's X 10" in str(err)


def refused_at(text: str, start: tuple[float, float]) -> ProgramError:
    with pytest.raises(ProgramError) as err:
        parse(text, start)
    return err.value
