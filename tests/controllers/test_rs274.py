"""The RS274/NGC subset of part programs (ncfmu.controllers.rs274): words, modal state, arcs, errors."""

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ncfmu.controllers.contour import ContourInterpolator
from ncfmu.controllers.geometry import Arc, Line
from ncfmu.controllers.rs274 import ARC_RADIUS_TOLERANCE, COORDINATE_LIMIT, MAX_PROGRAM_CHARS, parse
from ncfmu.errors import ConfigError, ProgramError

O = (0.0, 0.0)


def refused(text, start=O):
    with pytest.raises(ProgramError) as info:
        parse(text, start)
    return info.value


def ends(moves):
    return [m.element.end for m in moves]


def test_words_modal_motion_and_feed_comments_percent_and_block_numbers():
    moves = parse("%\n(setup) N10 G17 G21 G90\nN20 G00 X5 Y5 ; rapid (to the start\nN30 G01 X15 F600\n"
                  "N40 Y10 (modal G01 and F)\nn50 x 20 y 20\nN60 g0 x25\nN70 M30\n%\n", O)
    assert ends(moves) == [(5.0, 5.0), (15.0, 5.0), (15.0, 10.0), (20.0, 20.0), (25.0, 20.0)]
    assert [m.rapid for m in moves] == [True, False, False, False, True]
    assert [m.feed for m in moves[1:4]] == pytest.approx([10.0] * 3)     # F600 mm/min = 10 mm/s, modal
    assert [m.line for m in moves] == [3, 4, 5, 6, 7]
    assert all(isinstance(m.element, Line) for m in moves)
    assert moves[0].element.start == O


@pytest.mark.parametrize("spelled", ["G1", "G01", "g1", "G 1", "G001", "G1.0", "G+1"])
def test_g1_is_g01(spelled):
    assert parse(f"{spelled} F60 X3 Y4\nM2", O) == parse("G01 F60 X3 Y4\nM2", O)


@pytest.mark.parametrize("end", ["M2", "M02", "m30", "M30 (end)", "N99 M2"])
def test_program_end_and_what_may_follow_it(end):
    assert len(parse(f"G1 F60 X1\n{end}\n\n%\n(comment)\n; note\n", O)) == 1
    err = refused(f"G1 F60 X1\n{end}\n  G1 X2\n")
    assert (err.line_no, err.column) == (3, 3)
    assert "text after the program end (line 2)" in str(err)


def test_move_on_the_m2_line_is_run():
    assert ends(parse("G1 F60 X1 M2", O)) == [(1.0, 0.0)]


def test_incremental_moves_and_arc_centres_relative_to_the_start():
    moves = parse("G91 G1 F60 X10 Y5\nX-3\nG3 Y10 I0 J5\nG90 G2 X8 Y7 I0 J-5\nG1 X0 Y0\nM2", (1.0, 2.0))
    # flat: pytest.approx compares flat sequences only (pytest >= 9.2 refuses nested ones)
    expected = [(11.0, 7.0), (8.0, 7.0), (8.0, 17.0), (8.0, 7.0), (0.0, 0.0)]
    assert [c for end in ends(moves) for c in end] == pytest.approx([c for end in expected for c in end])
    for arc, sweep in ((moves[2].element, math.pi), (moves[3].element, -math.pi)):
        assert isinstance(arc, Arc)
        assert arc.center == pytest.approx((8.0, 12.0)) and arc.radius == pytest.approx(5.0)
        assert arc.sweep == pytest.approx(sweep)


@pytest.mark.parametrize("block, sweep", [
    ("G3 X0 Y10 I-10", math.pi / 2), ("G2 X0 Y-10 I-10", -math.pi / 2), ("G3 X-10 Y0 I-10 J0", math.pi),
    ("G2 X0 Y10 I-10", -3 * math.pi / 2), ("G2 I-10", -2 * math.pi), ("G3 X10 Y0 I-10", 2 * math.pi),
    ("G03 X0 Y10 J0 I-10", math.pi / 2)])
def test_arc_sweep_sign_length_and_full_circles(block, sweep):
    [arc] = [m.element for m in parse(f"G1 F60\n{block}\nM2", (10.0, 0.0))]
    assert isinstance(arc, Arc)
    assert arc.center == pytest.approx(O, abs=1e-12) and arc.radius == pytest.approx(10.0)
    assert arc.sweep == pytest.approx(sweep)
    assert arc.length == pytest.approx(10.0 * abs(sweep))
    assert arc.start == pytest.approx((10.0, 0.0), abs=1e-12)


def test_arc_radii_within_the_tolerance_pass_exactly_through_start_and_end():
    d = 0.75 * ARC_RADIUS_TOLERANCE
    [arc] = [m.element for m in parse(f"G2 F60 X{10 + d} Y0 I5 J0\nM2", O)]
    assert arc.start == pytest.approx(O, abs=1e-12) and arc.end == pytest.approx((10 + d, 0.0), abs=1e-12)
    assert arc.center == pytest.approx((5 + d / 2, 0.0), abs=1e-12)     # moved onto the bisector (d/2 <= tol)


def test_a_short_chord_keeps_the_centre_and_ends_on_the_circle():
    # a nearly full circle whose end is 1.5 um inside: the bisector is ~radial, the centre would move far
    d = 0.75 * ARC_RADIUS_TOLERANCE
    arc, line = [m.element for m in parse(f"G2 F60 X{d} Y-0.0001 I5 J0\nG1 X20\nM2", O)]
    assert arc.center == (5.0, 0.0) and arc.radius == 5.0 and arc.sweep < -6.0
    assert math.dist(arc.end, (d, -0.0001)) <= d + 1e-12                  # ends on its circle, near X/Y
    assert line.start == arc.end                                         # where the next block starts
    err = refused(f"G2 F60 X{10 + 1.25 * ARC_RADIUS_TOLERANCE} Y0 I5 J0\nM2")
    assert (err.line_no, err.column) == (1, 20)
    assert "do not define a circle" in str(err) and "5.0000 mm to the start, 5.0025 mm to the end" in str(err)


def test_cutter_compensation_lead_in_and_lead_out():
    moves = parse("G1 F60 X5\nG41\nG1 X10\nX20\nG3 X30 Y10 I0 J10\nG40 G1 X40\n"
                  "G42 G0 Y0\nG1 X50\nG40 X60\nM2", O)
    assert [(m.comp_before, m.comp_after) for m in moves] == [
        (0, 0), (0, 1), (1, 1), (1, 1), (1, 0), (0, -1), (-1, -1), (-1, 0)]
    assert [m.line for m in moves] == [1, 3, 4, 5, 6, 7, 8, 9]


@pytest.mark.parametrize("text, line, column, reason", [
    ("G1 F60 X1 Z5\nM2", 1, 11, "Z5: only the XY plane is in the subset (no Z)"),
    ("G2 F60 X10 R5\nM2", 1, 12, "R5: R-format arcs are not in the subset"),
    ("G41 D1\nM2", 1, 5, "D1: the offset is diameter_delta / 2"),
    ("G1 F60 A5\nM2", 1, 8, "A5: word A is not in the subset"),
    ("G1 F60 X1\nG20\nM2", 2, 1, "G20: inch units are not in the subset: write the program in mm (G21)"),
    ("G1 F60 X1\nN5 G18 X2\nM2", 2, 4, "G18: only the XY plane (G17) is in the subset"),
    ("G04 P1\nM2", 1, 1, "G04 is not in the subset (G00-G03"),
    ("G41.1 X1\nM2", 1, 1, "G41.1 is not in the subset"),
    ("G1 F60 X1\nM03 S1000\nM2", 2, 1, "M03 is not in the subset (M02, M30)"),
    ("#1 = 5\nM2", 1, 1, "parameters and expressions are not in the subset"),
    ("G1 F60 X[1+2]\nM2", 1, 8, "parameters and expressions are not in the subset"),
    ("G1 F60 X#1\nM2", 1, 8, "parameters and expressions are not in the subset"),
    ("/G1 F60 X1\nM2", 1, 1, "block delete '/' is not in the subset"),
    ("G1 F60 X\nM2", 1, 8, "word X needs a number"),
    ("G1 F60 X1 (open\nM2", 1, 11, "comment not closed with ')'"),
    ("G1 F60 X1 (a (b) c)\nM2", 1, 14, "'(' inside a comment: comments do not nest"),
    ("G1 F60 X1 )\nM2", 1, 11, "unexpected character ')'"),
    ("G1 N10 F60 X1\nM2", 1, 4, "the block number N must be the first word"),
    ("G1 X1 Y2 X3 F60\nM2", 1, 10, "X given twice in one block (first at column 4)"),
    ("G1 G2 X1\nM2", 1, 4, "G01 and G2 in one block: both belong to the modal group motion (G00-G03)"),
    ("G90 G91 X1\nM2", 1, 5, "G90 and G91 in one block: both belong to the modal group distance mode"),
    ("G41 G42 X1\nM2", 1, 5, "G41 and G42 in one block: both belong to the modal group cutter compensation"),
    ("G1 F0 X1\nM2", 1, 4, "F0: the feed must be > 0 mm/min"),
    ("G1 X1\nM2", 1, 1, "G01 with no feed: give F (mm/min) first"),
    ("G0 X1\nG2 I1\nM2", 2, 1, "G02 with no feed"),
    ("X1 Y1\nM2", 1, 1, "a move with no motion mode"),
    ("G1 F60 X1 I1\nM2", 1, 11, "I and J belong to G02/G03 arcs"),
    ("G0 X1 J1\nM2", 1, 7, "I and J belong to G02/G03 arcs"),
    ("G2 F60 X10\nM2", 1, 1, "G02 needs the centre as I and/or J"),
    ("G1 F60\nG3 X1 Y1\nM2", 2, 1, "G03 needs the centre as I and/or J"),
    ("G2 F60 X10 I0 J0\nM2", 1, 12, "I0 J0: the centre is the start point, no circle"),
    ("G1 F60\nG41 G2 X10 I5\nM2", 2, 5, "an arc cannot start cutter compensation: program a straight lead-in"),
    ("G1 F60\nG41 X10\nX20\nG40 G3 X30 I5\nM2", 4, 5, "an arc cannot end cutter compensation"),
    ("G1 F60\nG41 X10\nG42 X20\nG40 X30\nM2", 3, 1, "G42: cutter compensation is already on (G41)"),
    ("G1 F60\nG42\nG41 X10\nG40 X30\nM2", 3, 1, "G41: cutter compensation is already on (G42)"),
    ("G1 F60\nG41 X10\nX20\nM2", 4, 1, "cutter compensation is still on at the program end"),
    ("G1 F60\nG41\nN9 M30", 3, 4, "cutter compensation is still on at the program end"),
    ("G1 F60 X10\n", 1, 1, "the program does not end with M02 or M30"),
    ("G1 F60 X10\nX20\n(the end)", 3, 1, "the program does not end with M02 or M30"),
    ("", 1, 1, "the program does not end with M02 or M30"),
    ("%\nG17 G21 G1 F60\nM30\n%", 3, 1, "the program has no moves"),
    ("G1 F60 X10\nX10\nM2\nG1 X20", 4, 1, "text after the program end (line 3)"),
    (f"G1 F60 X{COORDINATE_LIMIT + 0.5}\nM2", 1, 8, "X100000.5: beyond 100000 mm"),
    (f"G2 F60 I-{COORDINATE_LIMIT + 1:.0f}\nM2", 1, 8, "I-100001: beyond 100000 mm"),
])
def test_refused_with_line_column_and_reason(text, line, column, reason):
    err = refused(text)
    assert isinstance(err, ConfigError)
    assert (err.line_no, err.column) == (line, column)
    assert f"line {line}, column {column}: {reason}" in str(err)


def test_program_length_and_coordinate_limits():
    body = "G1 F60 X1\nM2\n"
    assert len(parse(body + ";" + "x" * (MAX_PROGRAM_CHARS - len(body) - 1), O)) == 1
    err = refused(body + ";" + "x" * (MAX_PROGRAM_CHARS - len(body)))
    assert (err.line_no, err.column) == (1, 1) and f"longer than {MAX_PROGRAM_CHARS} characters" in str(err)
    assert ends(parse(f"G1 F60 X{COORDINATE_LIMIT:g} Y-{COORDINATE_LIMIT:g}\nM2", O)) == [(1e5, -1e5)]


def test_contour_interpolator_refuses_a_bad_program_at_construction():
    with pytest.raises(ProgramError) as info:
        ContourInterpolator(program="G1 X10\nM2")
    assert "line 1, column 1: G01 with no feed" in str(info.value)
    with pytest.raises(ProgramError, match=r"line 2, column 4: Z5"):
        ContourInterpolator(program="G1 F60 X10\nG1 Z5\nM2")
    ok = ContourInterpolator(program="G1 F600 X10\nG3 X0 Y10 I-5 J5\nM2", x_start=0.0, y_start=0.0)
    assert [type(e).__name__ for e in ok.contour] == ["Line", "Arc"]


# -- defects: these fail on the parser as written (except the M, X and I controls of the large numbers) --
@pytest.mark.parametrize("between", ["G40\nG42", "G40\nG41", "G40 X30\nG42"])
def test_compensation_change_without_a_lead_out_move_is_refused(between):
    """G40 with no move does not end compensation; a new G41/G42 must be refused, not switch silently."""
    text = f"G1 F60 X10\nG41 X20\nX30\n{between}\nG1 X40 Y10\nX50\nG40 X60\nM2"
    err = refused(text)
    assert (err.line_no, err.column) == (5, 1) and "already on" in str(err)


@pytest.mark.parametrize("word", ["G", "F", "M", "X", "I"])
def test_numbers_too_large_for_a_float_are_refused_as_program_errors(word):
    err = refused(f"G3 J1 {word}{'9' * 400}\nM2")
    assert (err.line_no, err.column) == (1, 7)


def test_incremental_moves_beyond_the_coordinate_limit_are_refused():
    err = refused(f"G91 G1 F60 X{COORDINATE_LIMIT:g}\nX{COORDINATE_LIMIT:g}\nM2")
    assert (err.line_no, err.column) == (2, 1) and "beyond" in str(err)


@pytest.mark.parametrize("text, line, column", [
    ("G90 G01 X10\nM2", 1, 5),                 # no feed: the G01, not the G90
    ("G17 G02 F60 X10\nM2", 1, 5),             # no I/J: the G02, not the G17
    ("G1 F60 X1 J2 I3\nM2", 1, 11),            # I/J with G01: the first of them
    ("Y5 X10\nM2", 1, 1),                      # no motion mode: the first coordinate
    ("G1 F60 X1\nM2\n(c) G1 X2", 3, 5),        # after the end: the text, not the comment before it
])
def test_the_column_names_the_offending_word(text, line, column):
    err = refused(text)
    assert (err.line_no, err.column) == (line, column)


def test_what_ends_a_line():
    """NEL (and CR, U+2028, U+2029: tests/controllers/test_line_ends.py) ends a line as LF does; a form feed is no
    line end and no blank, even inside a comment: refused, where it stands (issue 45)."""
    err = refused("G1 F60 X1 (page\x0cbreak)\nM2")
    assert (err.line_no, err.column) == (1, 16) and "a form feed (U+000C)" in str(err)
    assert refused("G1 F60 X1\x85Y2\nG1 Z1\nM2").line_no == 3


def test_only_ascii_digits_are_numbers():
    err = refused("G1 F60 X\u0661\u0660\nM2")                  # Arabic-Indic "10"
    assert (err.line_no, err.column) == (1, 8)


# -- properties -----------------------------------------------------------------------------------------
coord = st.floats(-1000.0, 1000.0, allow_nan=False)
offset = st.floats(0.01, 500.0).flatmap(lambda r: st.sampled_from([r, -r]))
block = st.one_of(st.tuples(st.just(1), coord, coord),
                  st.tuples(st.sampled_from([2, 3]), st.tuples(offset, offset), st.floats(-math.pi, math.pi)))


@settings(max_examples=200, deadline=None, derandomize=True)
@given(start=st.tuples(coord, coord), blocks=st.lists(block, min_size=1, max_size=12),
       incremental=st.booleans())
def test_property_valid_programs_join_end_to_start_and_reach_the_programmed_points(start, blocks, incremental):
    start = (float(f"{start[0]:.6f}"), float(f"{start[1]:.6f}"))
    x, y = start
    lines, expected = ["G91" if incremental else "G90", "F1200"], []
    for g, a, b in blocks:
        if g == 1:
            tx, ty = float(f"{a:.6f}"), float(f"{b:.6f}")
            extra = ""
        else:
            i, j = (float(f"{v:.6f}") for v in a)
            radius = math.hypot(i, j)
            tx = float(f"{x + i + radius * math.cos(b):.6f}")
            ty = float(f"{y + j + radius * math.sin(b):.6f}")
            extra = f" I{i:.6f} J{j:.6f}"
        wx, wy = (tx - x, ty - y) if incremental else (tx, ty)
        wx, wy = float(f"{wx:.6f}"), float(f"{wy:.6f}")
        tx, ty = (x + wx, y + wy) if incremental else (wx, wy)
        lines.append(f"G{g:02d} X{wx:.6f} Y{wy:.6f}{extra}")
        if g != 1 or (tx, ty) != (x, y):
            expected.append(((tx, ty), g))
        x, y = tx, ty
    text = "\n".join(lines + ["M30"])
    if not expected:                                   # every block a zero-length line
        with pytest.raises(ProgramError, match="the program has no moves"):
            parse(text, start)
        return
    moves = parse(text, start)
    assert len(moves) == len(expected)
    previous, arcs_so_far = start, 0
    for move, (end, g) in zip(moves, expected):
        assert isinstance(move.element, Line if g == 1 else Arc)
        assert move.element.start == pytest.approx(previous, abs=1e-9)
        # an arc ends on its circle: within the radius tolerance of its programmed end (G91: of each end before)
        arcs_so_far += g != 1
        assert move.element.end == pytest.approx(end, abs=1e-9 + arcs_so_far * ARC_RADIUS_TOLERANCE)
        if g != 1:
            assert (move.element.sweep > 0) == (g == 3)
        previous = move.element.end


TOKENS = ["G0", "G1", "G2", "G3", "G17", "G21", "G40", "G41", "G42", "G90", "G91", "X5", "Y-3", "x2.5", "I2",
          "J-2", "I0", "F600", "F", "M2", "M30", "N1", "Z1", "(c)", "(", ")", ";x", "%", "#1", "[", "\n", "\n", " "]


@settings(max_examples=400, deadline=None, derandomize=True)
@given(text=st.one_of(st.text(max_size=60),
                      st.text(alphabet="GMXYIJFNRZgx0123456789.+- ()%;#[]/\n\t", max_size=80),
                      st.lists(st.sampled_from(TOKENS), max_size=40).map(" ".join)))
def test_property_garbage_parses_or_raises_program_error(text):
    try:
        moves = parse(text, O)
    except ProgramError as err:
        assert err.line_no >= 1 and err.column >= 1
    else:
        assert moves
