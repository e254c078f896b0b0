"""What a configured controller publishes about its program (ncfmu.controllers.meaning): the lines and N numbers of
its elements, the outlines and regions its cycles define, the tools it uses with their table rows, the setup and
whether it drives the spindle -- read by the part check, the plots and the thread judge in place of the program."""

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ncfmu.controllers.contour import ContourInterpolator
from ncfmu.controllers.g7x import FAR
from ncfmu.controllers.geometry import Arc, Line
from ncfmu.controllers.sequencer import CutSequencer
from ncfmu.errors import ProgramError

# A shaft in two tools: the G71/G70 profile N10..N14 with tool 1 (row 1), a rough turn with tool 3 on row 2 (and
# the same station named again with row 4 later: the first row stands), radius X (G8) then diameter X (G7).
LATHE = """%
O0001
N1 G21 G99 G8
N2 T0101
N3 G97 S800 M03
N4 G00 X20. Z2.
N5 G71 U1. R0.5
N6 G71 P10 Q14 U0.2 W0.1 F0.2
N10 G00 X12.
N11 G01 Z-5.
N12 G03 X16. Z-9. R4.
N13 G01 Z-15.
N14 X20.
N15 G70 P10 Q14 F0.1
N16 G00 X30. Z5.
N17 T0302
N18 G7 G00 X44. Z1.
N19 G01 Z-4. F0.2
N20 T0304
N21 G00 X50.
N22 M05
N23 M30
%
"""
TOOLS = {"tool[1].x_offset": 1.5, "tool[1].z_offset": -2.0, "tool[1].nose_radius": 0.4, "tool[1].tip": 3,
         "tool[2].width": 3.0, "tool[2].nose_radius": 0.2, "tool[2].tip": 3, "tool[2].max_depth": 2.5,
         "tool[4].drill_diameter": 8.0}


def lathe(**values):
    return CutSequencer(program=LATHE, x_start=25.0, z_start=5.0, x_diameter=False, stock_diameter=44.0,
                        stock_length=60.0, stock_face_z=1.0, x_home=70.0, z_home=90.0, **TOOLS, **values).meaning


def test_a_lathe_programs_elements_carry_their_text_lines_and_n_numbers():
    m = lathe()
    assert m.dialect == "lathe" and m.programmed
    lines = [p.line for p in m.elements]
    assert lines == [6, 15, 17, 18, 20]          # the moves outside the cycles, in order (text lines: '%' is 1)
    assert [m.numbers[k] for k in lines] == [4, 16, 18, 19, 21]
    assert [p.n for p in m.elements] == [4, 16, 18, 19, 21]
    assert [p.rapid for p in m.elements] == [True, True, True, False, True]
    # G7 in force from N18: X44. is a radius of 22, the cut N19 runs along Z at it
    assert m.elements[3].element == Line((1.0, 22.0), (-4.0, 22.0))
    assert m.x_written == "diameter and radius"
    assert 2 not in m.numbers and m.numbers[3] == 1          # O0001 (line 2) has no N number
    assert m.rapid_lines == (6, 15, 17, 20)


def test_a_lathe_programs_profile_is_its_cycles_outline_and_region():
    m = lathe()
    # G71 and G70 share the profile N10..N14: two outlines (the cycles' lines and start point), one region
    assert [(o.line, o.start, o.inside) for o in m.outlines] == [(8, (2.0, 20.0), False), (14, (2.0, 20.0), False)]
    assert m.outlines[0].elements is m.outlines[1].elements
    profile = m.outlines[0].elements
    assert [(p.line, p.n) for p in profile] == [(10, 11), (11, 12), (12, 13), (13, 14)]
    assert isinstance(profile[1].element, Arc) and profile[1].element.end == pytest.approx((-9.0, 16.0))
    assert len(m.regions) == 1
    region = m.regions[0]
    assert region.line == 8 and region.edges is profile
    # the region: the profile from (Z 0, X 12) -- N10's X at N11's start -- to (Z -15, X 20), closed to the outside
    assert region.outline[0] == (2.0, 12.0) and region.outline[-2:] == ((-15.0, FAR), (2.0, FAR))
    assert region.outline[-3] == pytest.approx((-15.0, 20.0))
    # the arc is followed within 0.1 um: every point of its stretch lies on its circle
    arc = profile[1].element
    on_arc = [p for p in region.outline if -9.0 < p[0] < -5.0]
    assert len(on_arc) > 100
    assert all(math.isclose(math.dist(p, arc.center), 4.0, abs_tol=1e-9) for p in on_arc)


def test_a_lathe_programs_tools_are_its_stations_with_the_rows_their_first_t_word_gives():
    m = lathe()
    uses = {u.station: (u.row, u.tool) for u in m.tools}
    assert sorted(uses) == [0, 1, 3]
    assert uses[0][0] == 0 and uses[0][1].x_offset == 0.0 and uses[0][1].insert_angle == 80.0
    row, tool = uses[1]
    assert row == 1 and (tool.x_offset, tool.z_offset, tool.nose_radius, tool.tip) == (1.5, -2.0, 0.4, 3)
    row, tool = uses[3]
    assert row == 2 and (tool.width, tool.nose_radius, tool.max_depth, tool.drill_diameter) == (3.0, 0.2, 2.5, 0.0)
    assert m.tool(3) is not None and m.tool(2) is None


def test_a_lathe_programs_setup_and_spindle():
    m = lathe(**{"work[2].x": 1.0, "work[2].z": -3.0})
    assert (m.stock.diameter, m.stock.length, m.stock.face_z) == (44.0, 60.0, 1.0)
    assert m.home == (90.0, 70.0) and m.start == (25.0, 5.0)
    assert m.works[1] == (-3.0, 1.0) and m.first_work == (0.0, 0.0)     # G54 at power-on: no G55 in it
    assert m.drives_spindle
    assert lathe_with_g55().first_work == (-3.0, 1.0)


def lathe_with_g55():
    return CutSequencer(program="G55\nG00 X10. Z0\nM30\n", **{"work[2].x": 1.0, "work[2].z": -3.0}).meaning


def test_the_registers_mean_each_blocks_deepest_pass_and_no_program():
    m = CutSequencer(x_start=20.0, z_start=0.0, n_blocks=2, **{
        "block[1].Xf": 1.0, "block[1].Xd": 0.5, "block[1].N": 3, "block[1].Zp": 30.0, "block[1].Xp": 0.0,
        "block[2].Xf": 0.5, "block[2].Xd": 1.0, "block[2].N": 2, "block[2].Zp": 10.0, "block[2].Xp": 2.0,
        "block[2].own_stp": True, "block[2].x_stp": 17.0, "block[2].z_stp": -2.0}).meaning
    assert m.dialect == "registers" and not m.programmed and not m.drives_spindle
    assert m.elements == () and m.numbers == {} and m.x_written == ""
    assert [(u.station, u.row) for u in m.tools] == [(0, 0)]
    # depth Xf + N Xd below the start point; the second block from its own start point, tapering by Xp
    assert [r.outline[:2] for r in m.regions] == [((0.0, 17.5), (-30.0, 17.5)), ((-2.0, 14.5), (-12.0, 12.5))]
    assert all(r.line == 0 and r.edges == () for r in m.regions)


def test_a_mill_programs_elements_contour_and_numbers():
    text = ("%\nN10 G17 G21 G90\nN20 G00 X-5 Y-5\nN30 G42 G01 X0 Y0 F600\nN40 X20\nN50 G03 X30 Y10 I0 J10\n"
            "N60 G01 Y20\nN70 X0\nN80 Y0\nN90 G40 G00 X-5 Y-5\nN100 M30\n%\n")
    m = ContourInterpolator(program=text, x_start=-5.0, y_start=-8.0, diameter_delta=-0.5, stock_margin=3.0,
                            pocket=True).meaning
    assert m.dialect == "mill" and m.programmed and not m.drives_spindle and m.tools == ()
    assert [(p.line, p.n, p.rapid) for p in m.elements] == [
        (3, 20, True), (4, 30, False), (5, 40, False), (6, 50, False), (7, 60, False), (8, 70, False),
        (9, 80, False), (10, 90, True)]
    assert m.rapid_lines == (3, 10)
    contour, = m.outlines
    assert [p.line for p in contour.elements] == [5, 6, 7, 8, 9]       # between the lead-in and the lead-out
    assert contour.elements[0].element.start == (0.0, 0.0) and contour.elements[-1].element.end == (0.0, 0.0)
    assert (m.cutter_radius, m.stock.margin, m.pocket) == (0.25, 3.0, True)
    assert m.start == (-5.0, -8.0) and m.regions == ()


def test_a_point_paths_segments_are_numbered_and_are_the_contour():
    m = ContourInterpolator(n_points=4, closed=True, **{
        "point[1].x": 0.0, "point[1].y": 0.0, "point[2].x": 10.0, "point[2].y": 0.0,
        "point[3].x": 10.0, "point[3].y": 5.0, "point[4].x": 0.0, "point[4].y": 0.0}).meaning
    assert m.dialect == "points" and not m.programmed
    assert [p.line for p in m.elements] == [1, 2, 3] and m.rapid_lines == ()
    assert m.outlines[0].elements == m.elements


def test_a_program_that_does_not_read_is_refused_by_the_controller_not_published():
    with pytest.raises(ProgramError):
        CutSequencer(program="G00 X10. Z0\nG05\nM30\n")


def test_the_meaning_is_no_state_of_an_fmu_and_a_copy_shares_it():
    import copy
    seq = CutSequencer(program=LATHE, x_start=25.0, z_start=5.0, x_diameter=False)
    assert "meaning" in CutSequencer.DERIVED and "meaning" in ContourInterpolator.DERIVED
    assert copy.deepcopy(seq).meaning is seq.meaning


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.booleans(), st.integers(1, 40), st.integers(-30, 0), st.booleans()),
                min_size=1, max_size=12),
       st.lists(st.integers(1, 9999), min_size=12, max_size=12, unique=True))
def test_every_move_of_a_program_is_published_once_with_its_line_and_n_number(moves, numbers):
    """Each block (a comment line or none between them, N given or not) is one element at its text line, with the
    N number written on it, rapid as its G00 -- whatever the moves."""
    text, expected, here = ["G21 G8 G98 F100"], [], (0.0, 10.0)     # X radius, mm/min: the start is Z 0, X 10
    written: dict[int, int] = {}                  # text line -> the N number written on it
    for k, (rapid, x, z, numbered) in enumerate(moves):
        if k % 3 == 1:
            text.append("(a comment line)")
        n = numbers[k] if numbered else None
        text.append(f"{f'N{n} ' if n else ''}G0{0 if rapid else 1} X{x} Z{z}")
        if n:
            written[len(text)] = n
        if (z, float(x)) != here:                 # a block that stays where the tool is makes no element
            expected.append((len(text), n, rapid))
            here = (z, float(x))
    text.append("M30")
    m = CutSequencer(program="\n".join(text), x_start=10.0, z_start=0.0).meaning
    assert [(p.line, p.n, p.rapid) for p in m.elements] == expected
    assert m.numbers == written
    if expected:
        assert m.elements[-1].element.end == pytest.approx(here)



def test_the_first_work_offset_is_the_first_the_program_runs_not_one_in_a_subprogram_never_called():
    # the CNC's memory holds O2000 beside the called O1000: its G55 never runs, the axes stand in G54 all along
    text = "G00 X10. Z0\nM98 P1000\nM30\nO1000\nG00 X12.\nM99\nO2000\nG55\nG00 X14.\nM99\n"
    values = {"work[2].x": 1.0, "work[2].z": -3.0, "work[3].x": 2.0, "work[3].z": -4.0}
    assert CutSequencer(program=text, **values).meaning.first_work == (0.0, 0.0)
    called = text.replace("M98 P1000", "M98 P2000").replace("O1000\nG00 X12.", "O1000\nG56\nG00 X12.")
    assert CutSequencer(program=called, **values).meaning.first_work == (-3.0, 1.0)   # O2000's G55 runs first
