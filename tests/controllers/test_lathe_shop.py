"""A shop's lathe program beyond G71/G70 and threads (issue 46), as Fanuc's 0i-T manual defines it (plain-Python
planner, no FMU): M98/M99 subprograms (repeats, nesting, the return to the calling block, the text's lines),
G54..G59 work offsets, the G90/G94 single cycles, direct drawing dimensions (,C ,R A) -- and the refusals,
naming the line."""

from __future__ import annotations

import math
import re

import pytest
from hypothesis import given
from hypothesis import strategies as st

from ncfmu.controllers import lathe_program
from ncfmu.controllers.direct_dimensions import corner
from ncfmu.controllers.geometry import Arc, Line
from ncfmu.errors import ProgramError, ProgramErrors


def _plan(text: str, start: tuple[float, float] = (50.0, 5.0), setup: lathe_program.Setup | None = None):
    return lathe_program.plan(text, start, 100.0, setup)


def _ends(segs) -> list[tuple[int, float, float]]:
    """(line, X diameter, Z) at the end of each move."""
    return [(g.line, round(2 * g.element.end[1], 9), round(g.element.end[0], 9)) for g in segs]


#: Fanuc 0i-T: subprogram calls nest four levels deep.
MAX_NESTING = 4


def _refusals(text: str, setup: lathe_program.Setup | None = None) -> list[ProgramError]:
    with pytest.raises((ProgramError, ProgramErrors)) as info:
        _plan(text, setup=setup)
    err = info.value
    return err.errors if isinstance(err, ProgramErrors) else [err]


# -- M98 / M99 ---------------------------------------------------------------------------------------------
GROOVES = """O0001
G00 X40. Z2.
M98 P30100 (three times O0100)
G00 X50. Z5.
M30
O0100
G00 W-5.
G01 U-4. F60
G00 U4.
M99
"""


def test_m98_repeats_a_subprogram_and_returns_to_the_block_after_the_call() -> None:
    ends = _ends(_plan(GROOVES))
    # each run: W-5 at X40, down to X36 (U-4 on the diameter), back up; the shift accumulates (incremental W)
    expected = [(2, 40.0, 2.0)]
    for k in range(1, 4):
        expected += [(7, 40.0, 2.0 - 5 * k), (8, 36.0, 2.0 - 5 * k), (9, 40.0, 2.0 - 5 * k)]
    expected.append((4, 50.0, 5.0))        # the block after the call, after the third return
    assert ends == expected


def test_m98_p_l_form_and_p_alone_are_once_or_l_times() -> None:
    once = _ends(_plan(GROOVES.replace("M98 P30100", "M98 P100")))
    assert [e for e in once if e[0] == 8] == [(8, 36.0, -3.0)]
    twice = _ends(_plan(GROOVES.replace("M98 P30100", "M98 P0100 L2")))
    assert [e for e in twice if e[0] == 8] == [(8, 36.0, -3.0), (8, 36.0, -8.0)]


def _nested(depth: int) -> str:
    """The main program calling O1, O1 calling O2, ... O<depth>: each moves W-1 before its call."""
    subs = "".join(f"O{k}\nG01 W-1. F60\n" + (f"M98 P{k + 1}\n" if k < depth else "") + "M99\n"
                   for k in range(1, depth + 1))
    return f"G00 X40. Z2.\nM98 P1\nG00 X50.\nM30\n{subs}"


def test_calls_nest_four_deep_each_returning_to_its_caller() -> None:
    segs = _plan(_nested(MAX_NESTING))
    # the main's line 2 calls O1 (its W-1 on line 6), O1 calls O2 (line 9), ...: each subprogram's block reports
    # its own text line, 4 lines apart
    assert _ends(segs) == [(1, 40.0, 2.0)] + [(6 + 4 * k, 40.0, 1.0 - k) for k in range(4)] + [(3, 50.0, -2.0)]


def test_nesting_five_deep_is_refused_at_the_call() -> None:
    text = _nested(MAX_NESTING + 1)
    [err] = _refusals(text)
    call = text.splitlines().index("M98 P5") + 1
    assert err.line_no == call and "nested 5 deep, at most 4" in str(err)


def test_a_call_to_a_program_not_held_is_refused_naming_the_line() -> None:
    errs = _refusals(GROOVES.replace("M98 P30100", "M98 P30200").replace("G00 X50. Z5.", "M98 P300"))
    assert [(e.line_no, "O0200" in str(e) or "O0300" in str(e)) for e in errs] == [(3, True), (4, True)]
    assert "holds" in str(errs[0]) or "hold" in str(errs[0])


def test_m99_p_in_the_main_program_jumps_forward_to_that_block() -> None:
    text = "G00 X40. Z2.\nM99 P30\nG00 X30.\nN30 G00 X45.\nM30\n"
    assert _ends(_plan(text)) == [(1, 40.0, 2.0), (4, 45.0, 2.0)]
    [back] = _refusals("N10 G00 X40. Z2.\nM99 P10\nM30\n")
    assert back.line_no == 2 and "endlessly" in str(back)


def test_subprogram_refusals_name_their_lines() -> None:
    text = GROOVES.replace("M99\n", "M30\n")
    errs = _refusals(text)
    assert errs[0].line_no == 10 and "a subprogram ends with M99" in str(errs[0])
    [after] = _refusals("G00 X40.\nM30\nG00 X30.\n")
    assert after.line_no == 3 and "a subprogram starts with O" in str(after)


# -- G54..G59 ----------------------------------------------------------------------------------------------
#: Work offsets (z, x radius): G54 shifts Z by -100, G55 by -150 and X by 2 (radius), the rest 0.
WORKS = ((-100.0, 0.0), (-150.0, 2.0), (0.0, 0.0), (0.0, 0.0), (0.0, 0.0), (7.0, -1.0))


def test_work_offsets_shift_the_axes_with_the_tool_offset_on_top() -> None:
    setup = lathe_program.Setup(works=WORKS, tools=(lathe_program.Tool(x_offset=0.5, z_offset=3.0),) * 8)
    text = "G00 X40. Z2.\nT0101\nG00 X40. Z2.\nG55\nG00 X40. Z2.\nG59 X30.\nG54 G01 Z-5. F60\nM30\n"
    # the tool starts at the axes' (x 50, z 5): under the power-on G54 that is the programmed Z 105
    ends = _ends(_plan(text, (50.0, 5.0), setup))
    assert ends == [(1, 40.0, -98.0),                   # G54: Z 2 - 100
                    (2, 41.0, -95.0),                   # T0101 taken up where it stands: + 0.5 radius, + 3
                    (4, 45.0, -145.0),                  # G55 taken up (line 3 is where the tool is: no move)
                    (6, 39.0, 12.0),                    # G59 taken up first (Z 2 + 7 + 3, X 20 - 1 + 0.5) ...
                    (6, 29.0, 12.0),                    # ... then X30 on the diameter: 15 - 1 + 0.5 = 14.5 radius
                    (7, 31.0, -95.0),                   # G54 taken up (X 15 + 0.5) ...
                    (7, 31.0, -102.0)]                  # ... then Z -5 - 100 + 3
    assert [g.feed for g in _plan(text, (50.0, 5.0), setup)][-2:] == [False, True]


def test_work_offset_refused_inside_a_profile() -> None:
    text = "G00 X40. Z2.\nG71 U1. R0.5\nG71 P10 Q20 U0.2 W0.1 F100\nN10 G00 X20.\nG55 G01 Z-10.\nN20 X40.\nM30\n"
    [err] = _refusals(text)
    assert err.line_no == 5 and "G55 inside the profile" in str(err)


# -- G90 / G94 ---------------------------------------------------------------------------------------------
def _passes(segs, code: int) -> list[list[tuple[int, int, bool, float, float]]]:
    """Each pass of a single cycle: (sub-cycle, pass, feed, X diameter, Z) at each move's end."""
    out: dict[tuple[int, int], list] = {}
    for g in segs:
        if g.cycle == code:
            out.setdefault((g.line, g.pass_no), []).append(
                (g.subcycle, g.pass_no, g.feed, round(2 * g.element.end[1], 9), round(g.element.end[0], 9)))
    return list(out.values())


def test_g90_turns_in_four_moves_and_repeats_with_x_alone() -> None:
    text = "G00 X52. Z2.\nG90 X46. Z-30. F120\nX42.\nX38. R-1.\nG00 X60.\nM30\n"
    segs = _plan(text, (60.0, 10.0))
    passes = _passes(segs, 90)
    # SC1 X in at rapid, SC2 the cut to Z-30 at F, SC3 X out to the start point's X at F, SC4 Z back at rapid
    assert passes[0] == [(1, 1, False, 46.0, 2.0), (2, 1, True, 46.0, -30.0), (3, 1, True, 52.0, -30.0),
                         (4, 1, False, 52.0, 2.0)]
    assert passes[1] == [(1, 2, False, 42.0, 2.0), (2, 2, True, 42.0, -30.0), (3, 2, True, 52.0, -30.0),
                         (4, 2, False, 52.0, 2.0)]
    # R-1 (radius): the cut starts 1 mm (radius) below its end's X: a taper from X36 at Z2 to X38 at Z-30
    assert passes[2][:2] == [(1, 3, False, 36.0, 2.0), (2, 3, True, 38.0, -30.0)]
    cut = [g for g in segs if g.cycle == 90 and g.subcycle == 2]
    assert all(math.isclose(g.rate, 2.0) for g in cut)          # F120 mm/min
    assert segs[-1].cycle == 0 and 2 * segs[-1].element.end[1] == 60.0   # G00 ends the modal cycle


def test_g94_faces_in_four_moves_and_repeats_with_z_alone() -> None:
    text = "G00 X52. Z2.\nG94 X10. Z-1. F60\nZ-2.\nW-5. R-1.\nM30\n"
    passes = _passes(_plan(text, (60.0, 10.0)), 94)
    # SC1 Z in at rapid, SC2 the face cut in X at F, SC3 Z out to the start point's Z at F, SC4 X back at rapid
    assert passes[0] == [(1, 1, False, 52.0, -1.0), (2, 1, True, 10.0, -1.0), (3, 1, True, 10.0, 2.0),
                         (4, 1, False, 52.0, 2.0)]
    assert passes[1][1] == (2, 2, True, 10.0, -2.0)
    # W-5 from the start point (Z-3), R-1: the face starts at Z-4 at X52 and ends at Z-3 at X10
    assert passes[2][:2] == [(1, 3, False, 52.0, -4.0), (2, 3, True, 10.0, -3.0)]


def test_one_shot_blocks_after_a_modal_cycle_are_their_own() -> None:
    """G28 U0 W0, G04 U1.5, G71 U R after G90/G94/G92 passes: Fanuc's group 00 codes, not the cycle's next pass (their
    U and W are the return's intermediate point, the dwell's seconds, G71's depth of cut)."""
    home = lathe_program.Setup(home=(50.0, 40.0))
    for cycle in ("G90 X46. Z-30. F120", "G94 X20. Z-2. F120"):
        segs = _plan(f"G00 X52. Z2.\n{cycle}\nG04 U1.5\nG28 U0 W0\nM30\n", (60.0, 10.0), home)
        assert [g.dwell for g in segs if g.line == 3] == [1.5]
        assert _ends([g for g in segs if g.line == 4]) == [(4, 80.0, 50.0)]     # to the reference (X radius 40)
    segs = _plan("G97 S500 M03\nG00 X32. Z5.\nG92 X29. Z-20. F2.\nG28 U0 W0\nM30\n", (60.0, 10.0), home)
    assert segs[-1].line == 4 and segs[-1].cycle == 0 and _ends(segs[-1:]) == [(4, 80.0, 50.0)]
    # G71 after G90 passes: stock removal from where the passes left the tool
    text = ("G00 X52. Z2.\nG90 X46. Z-30. F600\nG71 U1.5 R0.5\nG71 P10 Q20 U0.4 W0.1 F300\nN10 G00 X30.\n"
            "G01 Z-20.\nN20 X52.\nM30\n")
    rough = [op for op in lathe_program.parse(text, (60.0, 10.0)) if isinstance(op, lathe_program.Rough)]
    assert [(op.line, op.depth, op.start) for op in rough] == [(4, 1.5, (2.0, 26.0))]


def test_g90_alone_is_still_the_absolute_mode() -> None:
    text = "G18 G21 G90 G8\nG91 G00 X-5. Z-3.\nG90\nG00 X20. Z1.\nM30\n"
    assert _ends(_plan(text, (30.0, 5.0))) == [(2, 50.0, 2.0), (4, 40.0, 1.0)]


def test_single_cycle_refusals_name_their_lines() -> None:
    assert "X (or U) and Z (or W)" in str(_refusals("G00 X52. Z2.\nG90 X46. F100\nM30\n")[0])
    err = _refusals("G00 X52. Z2.\nG90 X46. Z-30. R4. F100\nM30\n")[0]     # the cut would start above S
    assert err.line_no == 2 and "R4" in str(err)
    err = _refusals("G00 X52. Z2.\nG42\nG90 X46. Z-30. F100\nM30\n")[0]
    assert err.line_no == 3 and "G40" in str(err)
    text = "G00 X52. Z2.\nG71 U1. R0.5\nG71 P10 Q20 U0.2 W0.1 F100\nN10 G00 X20.\nG94 X10. Z-10.\nN20 X40.\nM30\n"
    err = _refusals(text)[0]
    assert err.line_no == 5 and "inside a profile" in str(err)


# -- ,C ,R A -----------------------------------------------------------------------------------------------
def _points(segs, line: int | None = None) -> list[tuple[float, float]]:
    """(X diameter, Z) at each move's end (rounded to 1 nm)."""
    return [(round(2 * g.element.end[1], 6), round(g.element.end[0], 6)) for g in segs
            if line is None or g.line == line]


def test_chamfer_cuts_the_corner_c_from_it_along_each_move() -> None:
    # face down to X30 at Z0 with ,C2, then turn along Z: a 2 x 45 degree chamfer (Fanuc's C2)
    text = "G00 X20. Z1.\nG01 Z0. F60\nX30. ,C2.\nZ-20.\nM30\n"
    segs = _plan(text, (50.0, 5.0))
    assert _points(segs)[1:] == [(20.0, 0.0), (26.0, 0.0), (30.0, -2.0), (30.0, -20.0)]
    chamfer = segs[3]
    assert chamfer.line == 3 and chamfer.feed and math.isclose(chamfer.element.length, 2 * math.sqrt(2))


def test_corner_radius_is_tangent_to_both_moves() -> None:
    text = "G00 X20. Z1.\nG01 Z0. F60\nX30. ,R2.\nZ-20.\nM30\n"
    segs = _plan(text, (50.0, 5.0))
    arc = segs[3].element
    # a right angle: the arc's ends r from the corner (X30 Z0), its centre at X26 (radius 13) Z-2
    assert _points(segs)[1:] == [(20.0, 0.0), (26.0, 0.0), (30.0, -2.0), (30.0, -20.0)]
    assert segs[3].line == 3 and math.isclose(arc.radius, 2.0)
    assert math.isclose(arc.center[0], -2.0, abs_tol=1e-12) and math.isclose(arc.center[1], 13.0)
    assert math.isclose(arc.sweep, math.pi / 2)                 # up, then toward the chuck: a G03 turn
    # on a 45 degree corner the ends stand r tan(22.5 deg) from it
    text = "G00 X20. Z1.\nG01 Z0. F60\nX30. Z-5. ,R3.\nZ-20.\nM30\n"
    segs = _plan(text, (50.0, 5.0))
    t = 3 * math.tan(math.pi / 8)
    assert math.isclose(segs[4].element.start[0], -5.0 - t)     # the arc's end on the Z move
    assert math.isclose(segs[4].element.end[0], -20.0)


def test_angle_a_fixes_the_other_coordinate() -> None:
    # A150: toward the chuck and up at 30 degrees: from X20 Z0 to X30 (radius +5) over Z -5/tan(30)
    segs = _plan("G00 X20. Z0.\nG01 X30. A150. F60\nG01 Z-20. A180.\nM30\n", (50.0, 5.0))
    x, z = _points(segs, 2)[0]
    assert x == 30.0 and math.isclose(z, -5.0 / math.tan(math.radians(30.0)), abs_tol=1e-6)
    assert _points(segs, 3) == [(30.0, -20.0)]


def test_direct_dimension_refusals_name_their_lines() -> None:
    [arc] = _refusals("G00 X20. Z1.\nG01 Z0. F60\nG02 X30. Z-5. R5. ,C1.\nZ-20.\nM30\n")
    assert arc.line_no == 3 and ",C1 on an arc" in str(arc)
    [to_arc] = _refusals("G00 X20. Z1.\nG01 Z0. F60\nX30. ,C1.\nG02 X40. Z-5. R5.\nM30\n")
    assert to_arc.line_no == 3 and "the next block (line 4) is an arc" in str(to_arc)
    [big] = _refusals("G00 X20. Z1.\nG01 Z0. F60\nX30. ,C6.\nZ-20.\nM30\n")     # the X move is 5 mm (radius)
    assert big.line_no == 3 and "larger than this move" in str(big)
    [big_r] = _refusals("G00 X20. Z1.\nG01 Z0. F60\nX30. ,R3.\nZ-2.\nM30\n")    # the Z move is 2 mm
    assert big_r.line_no == 3 and "larger than the next move" in str(big_r)
    [none] = _refusals("G00 X20. Z1.\nG01 Z0. F60\nX30. ,C1.\nM30\n")
    assert none.line_no == 3 and "no move" in str(none)
    [angle] = _refusals("G00 X20. Z1.\nG01 X30. Z-3. A150. F60\nM30\n")
    assert angle.line_no == 2 and "one of them" in str(angle)
    [thread] = _refusals("G97 S500 M03\nG00 X32. Z5.\nG92 X29. Z-20. F2. ,C1.\nM30\n")
    assert thread.line_no == 3 and "belong to G01 moves" in str(thread)


def test_chamfer_inside_a_g71_profile() -> None:
    text = ("G00 X42. Z2.\nG71 U1. R0.5\nG71 P10 Q20 U0. W0. F100\nN10 G00 X30.\nG01 Z-10. ,C1.\n"
            "X40.\nN20 Z-20.\nM30\n")
    profile = [op for op in lathe_program.parse(text, (50.0, 5.0)) if isinstance(op, lathe_program.Rough)][0].profile
    ends = [(round(2 * m.element.end[1], 6), round(m.element.end[0], 6), m.line) for m in profile.blocks]
    assert ends == [(30.0, -9.0, 5), (32.0, -10.0, 5), (40.0, -10.0, 6), (40.0, -20.0, 7)]


@given(st.floats(0.0, 2 * math.pi), st.floats(0.05, 3.0), st.floats(2.0, 20.0), st.floats(2.0, 20.0),
       st.floats(0.01, 1.0), st.sampled_from([",C", ",R"]))
def test_corner_geometry_for_any_turn(heading, turn_size, len1, len2, fraction, word) -> None:
    """Any corner turning by 0.05..3 rad either way: a chamfer's ends c from the virtual corner along both moves;
    a radius tangent to both (its centre r from both lines, its ends on them), the path continuous."""
    for sign in (1.0, -1.0):
        turn = sign * turn_size
        b = (1.0, 2.0)
        u1 = (math.cos(heading), math.sin(heading))
        u2 = (math.cos(heading + turn), math.sin(heading + turn))
        first = Line((b[0] - len1 * u1[0], b[1] - len1 * u1[1]), b)
        second = Line(b, (b[0] + len2 * u2[0], b[1] + len2 * u2[1]))
        reach = min(len1, len2) * fraction      # how far from the corner the corner's ends may come
        size = reach if word == ",C" else reach / math.tan(turn_size / 2)
        before, middle, after = corner(first, second, word, size)
        assert math.dist(middle.start, b) == pytest.approx(reach, abs=1e-9)
        assert math.dist(middle.end, b) == pytest.approx(reach, abs=1e-9)
        assert before is None or math.dist(before.end, middle.start) < 1e-9
        assert after is None or math.dist(after.start, middle.end) < 1e-9
        if word == ",R":
            assert isinstance(middle, Arc) and middle.radius == pytest.approx(size)
            for p, u in ((middle.start, u1), (middle.end, u2)):     # the radius to each end is normal to its move
                r = (p[0] - middle.center[0], p[1] - middle.center[1])
                assert abs(r[0] * u[0] + r[1] * u[1]) < 1e-7 * max(1.0, size)
            assert middle.sweep == pytest.approx(turn)


# -- the README's dialect table ------------------------------------------------------------------------------
def _dialect_table() -> list[str]:
    """The first cells of the README's Fanuc 0i-T table (the words as a programmer writes them)."""
    from pathlib import Path
    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text()
    section = readme.split("## Lathe part programs: the Fanuc 0i-T dialect", 1)[1].split("\n## ", 1)[0]
    table = section.split("| word | meaning | what we do |", 1)[1].split("\n\n", 1)[0]
    return [row.split("|")[1] for row in table.splitlines() if row.startswith("| ") and "---" not in row]


def test_the_readme_table_lists_every_word_the_lathe_takes() -> None:
    """Every G and M code and every address letter the reader takes has a row whose first cell writes it."""
    cells = _dialect_table()
    g: set[int] = set()
    m: set[int] = set()
    letters: set[str] = set()
    for cell in cells:
        for token in re.findall(r"`([^`]*)`", cell):
            g |= {int(n) for n in re.findall(r"\bG(\d+)", token)}
            m |= {int(n) for n in re.findall(r"\bM(\d+)", token)}
            letters |= set(re.findall(r"(,[A-Z]|(?<![A-Z,])[A-Z])(?=[-\d.]|\b)", token))
        for a, b in re.findall(r"`G(\d+)` \.\. `G(\d+)`", cell):      # G54 .. G59
            g |= set(range(int(a), int(b) + 1))
    assert set(lathe_program.LATHE.groups) - g == set()
    assert set(lathe_program.LATHE.m_codes) - m == set()
    taken = set(re.findall(r",?[A-Z]", lathe_program.LATHE.letter_list))      # "G, M, ..., A, ,C, ,R"
    assert {",C", ",R", "G", "A"} <= taken
    assert taken - letters == set()


@pytest.mark.parametrize("block, word", [("G90 X-10. Z-30. F100", "X-10"),      # the cut's end below the axis
                                         ("G90 X10. Z-30. R-8. F100", "R-8"),  # the taper's start below it
                                         ("G90 U-62. W-32. F100", "U-62")])
def test_a_g90_pass_across_the_spindle_axis_is_refused(block: str, word: str) -> None:
    # an OD/ID turning pass runs along Z at its X: below the axis the tool's far side is in the part (as a G71
    # profile crossing the axis is refused); a facing G94 may end past the centre
    err = _refusals(f"G00 X52. Z2.\n{block}\nM30\n")[0]
    assert err.line_no == 2 and word in str(err) and "spindle axis" in str(err), str(err)
