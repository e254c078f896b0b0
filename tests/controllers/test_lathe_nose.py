"""Tool-nose radius compensation G40/G41/G42 of the lathe dialect (issue 32): the nose circle of every commanded
point touches the programmed profile (3 um), never cuts into it, and the axes command the imaginary tool tip =
nose centre + the tip vector of Fanuc's imaginary tool-nose number.

The oracle is the profile's own geometry (the pieces the program is written from, :mod:`lathe_oracle`),
measured exactly (distance of a point from a line segment or an arc), not the planner's offset."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from lathe_oracle import SHAFT, Part, Piece, below_shifted_profile, build_part, densify

from ncfmu.controllers.g7x import Tool
from ncfmu.controllers.geometry import JOIN, Arc, CornerError, Line, arc_through, point_distance, sample
from ncfmu.controllers.lathe_program import Setup, parse, plan
from ncfmu.controllers.nose import TIP, Nose
from ncfmu.errors import ProgramError

R = 0.8
HALF_PI = math.pi / 2


def setup(r: float = R, tip: int = 3) -> Setup:
    return Setup(tools=(Tool(nose_radius=r, tip=tip),) + (Tool(),) * 7, home=(50.0, 50.0))


def element(p: Piece) -> Line | Arc:
    """The oracle's piece as an exact element (an arc: counter-clockwise when convex), through both its end points
    (the oracle's coordinates are on a 1e-6 mm grid: the centre is moved onto the chord's bisector, < 1e-5 mm)."""
    if p.centre is None:
        return Line(p.start, p.end)
    return arc_through(p.start, p.end, p.centre, p.convex, 1e-5)


def gap(points, pieces: list[Piece], r: float, tip: int) -> np.ndarray:
    """For each commanded point (z, x): the nose circle's distance from the profile (0: touching, < 0: cutting
    into it), the nose centre being the point less the tip vector."""
    vz, vx = TIP[tip]
    elements = [element(p) for p in pieces]
    return np.array([min(point_distance((z - vz * r, x - vx * r), e) for e in elements) - r for z, x in points])


def num(v: float) -> str:
    text = f"{v:.6f}".rstrip("0")
    return text if text != "-0." else "0."


def moves(pieces: list[Piece], first_n: int = 100) -> list[str]:
    """The pieces as G01/G02/G03 blocks, X on the diameter, arcs by R."""
    out = []
    for i, p in enumerate(pieces):
        end = f"X{num(2 * p.end[1])} Z{num(p.end[0])}"
        if p.centre is None:
            out.append(f"N{first_n + i} G01 {end}")
        else:
            out.append(f"N{first_n + i} G0{3 if p.convex else 2} {end} R{num(p.radius)}")
    return out


#: An OD profile with a chamfer, a taper, a concave and a convex arc, a face up to the stock (start X 30 radius).
OD = build_part(30.0, 2.0, 8.0, [("z", 2.0), ("taper", 2.0, 2.0), ("z", 8.0), ("concave", 4.0, -HALF_PI, -math.pi),
                                 ("taper", 8.0, 3.0), ("convex", 3.0, 0.0, HALF_PI), ("z", 5.0), ("face", 6.0)])


def od_program(side: str = "G42") -> str:
    z0, x0 = OD.pieces[0].start
    return "\n".join(["%", "O2001", "N1 G21 G40 G98", "N2 T0101", "N3 G00 X70. Z5.",
                      f"N4 {side} G00 X{num(2 * x0)} Z{num(z0)}", "N5 F120.", *moves(OD.pieces),
                      "N200 G40 G00 X70. Z5.", "N201 M30", "%"]) + "\n"


def profile_lines(text: str) -> set[int]:
    """The program lines (1-based) of the profile's blocks (N100..)."""
    return {i + 1 for i, t in enumerate(text.splitlines()) if t.startswith("N1") and len(t.split()[0]) == 4}


def test_g42_on_an_outside_profile_touches_it_everywhere_and_never_gouges():
    text = od_program()
    segs = plan(text, (35.0, 5.0), 100.0, setup())
    lines = profile_lines(text)
    on = [p for g in segs if g.line in lines for p in sample([g.element], 0.005)]
    assert len(on) > 1000
    touching = gap(on, OD.pieces, R, 3)
    assert np.abs(touching).max() <= 0.003
    every = [p for g in segs for p in sample([g.element], 0.005)]
    assert gap(every, OD.pieces, R, 3).min() >= -0.003               # start-up and cancel moves too
    # the compensated path's outside corners are arcs of the nose radius about the programmed corner
    corner = OD.pieces[0].end                                       # Z0 -> the chamfer: a turn to the right
    assert any(isinstance(g.element, Arc) and math.dist(g.element.center, (corner[0] - R, corner[1] - R)) < 1e-9
               for g in segs) is False                              # inside corner (turning right under G42)
    corner = OD.pieces[1].end                                       # the chamfer -> Z: turning left, outside
    assert any(isinstance(g.element, Arc) and abs(g.element.radius - R) < 1e-12
               and math.dist(g.element.center, (corner[0] - R, corner[1] - R)) < 1e-9 for g in segs)
    # start and end: programmed points, uncompensated (the imaginary tip there)
    assert segs[0].element.start == (5.0, 35.0) and segs[-1].element.end == (5.0, 35.0)


@pytest.mark.parametrize("tip", [1, 2, 3, 4, 5, 6, 7, 8, 0, 9])
def test_the_axes_command_the_nose_centre_plus_the_tip_vector(tip):
    """The same profile with every tip number: the commanded path is the nose centre's path (tip 0) moved by the
    tip vector, exactly."""
    text = od_program()
    centre = [g.element for g in plan(text, (35.0, 5.0), 100.0, setup(tip=0)) if g.line in profile_lines(text)]
    tipped = [g.element for g in plan(text, (35.0, 5.0), 100.0, setup(tip=tip)) if g.line in profile_lines(text)]
    vz, vx = TIP[tip]
    assert len(centre) == len(tipped)
    for c, t in zip(centre, tipped):
        for a, b in ((c.start, t.start), (c.end, t.end)):
            assert b[0] == pytest.approx(a[0] + vz * R, abs=1e-12) and b[1] == pytest.approx(a[1] + vx * R, abs=1e-12)


def test_fanuc_tip_table():
    """Tip 3 (OD turning tool toward the chuck): the tip at the nose's lowest X and lowest Z; tip 2 (boring bar):
    highest X, lowest Z; 5..8 the sides +Z, +X, -Z, -X; 0 and 9 the centre."""
    assert Nose(-1, 0.4, 3).tip_of((10.0, 20.0)) == (9.6, 19.6)
    assert Nose(1, 0.4, 2).tip_of((10.0, 20.0)) == (9.6, 20.4)
    assert [TIP[k] for k in (1, 4, 5, 6, 7, 8)] == [(1, 1), (1, -1), (1, 0), (0, 1), (-1, 0), (0, -1)]
    assert TIP[0] == TIP[9] == (0, 0)


def test_without_g41_g42_nothing_changes():
    """The same program with G40 in place of G42 runs the tool's tip on the profile (the nose radius unused)."""
    text = od_program("G40")
    segs = plan(text, (35.0, 5.0), 100.0, setup())
    on = [p for g in segs if g.line in profile_lines(text) for p in sample([g.element], 0.01)]
    assert max(min(point_distance(p, element(q)) for q in OD.pieces) for p in on) <= 1e-9


#: A bore (inside work, boring toward the chuck): X falls along -Z; the material is above the profile.
ID = [Piece((2.0, 14.0), (0.0, 14.0)), Piece((0.0, 14.0), (-2.0, 12.0)), Piece((-2.0, 12.0), (-10.0, 12.0)),
      Piece((-10.0, 12.0), (-13.0, 9.0), (-13.0, 12.0), convex=False),      # G02: a convex corner of the bore
      Piece((-13.0, 9.0), (-20.0, 9.0)), Piece((-20.0, 9.0), (-23.0, 6.0), (-20.0, 6.0), convex=True),  # concave
      Piece((-23.0, 6.0), (-30.0, 6.0)), Piece((-30.0, 6.0), (-30.0, 4.0))]


def test_g41_on_an_inside_profile_touches_it_everywhere_and_never_gouges():
    text = "\n".join(["%", "O2002", "N1 G21 G98 T0101 F100.", "N2 G00 X10. Z5.", "N3 G41 G00 X28. Z2.",
                      *moves(ID), "N200 G40 G00 X6. Z5.", "M30", "%"]) + "\n"
    segs = plan(text, (5.0, 5.0), 100.0, setup(0.4, 2))
    lines = profile_lines(text)
    on = [p for g in segs if g.line in lines for p in sample([g.element], 0.005)]
    assert np.abs(gap(on, ID, 0.4, 2)).max() <= 0.003
    every = [p for g in segs for p in sample([g.element], 0.005)]
    assert gap(every, ID, 0.4, 2).min() >= -0.003
    # the nose below the bore's wall (the air's side): along the first Z block its centre is at X 14 - 0.4
    first = next(g for g in segs if g.line == 6)                   # N100 G01 X28. Z0.
    assert first.element.start[1] - TIP[2][1] * 0.4 == pytest.approx(14.0 - 0.4, abs=1e-12)


def g70_program(part: Part) -> str:
    return "\n".join(["%", "O2003", "N1 G21 G40 G99", "N2 T0101", "N3 G50 S2500.", "N4 G96 S180. M03",
                      f"N5 G42 G00 X{num(2 * part.x0)} Z{num(part.z0)} M08", "N6 G71 U1.5 R0.5",
                      "N7 G71 P10 Q20 U0.4 W0.1 F0.25", f"N10 G00 X{num(2 * part.a_x)}",
                      *[("N20 " if i == len(part.pieces) - 1 else "") + t.split(" ", 1)[1]
                        for i, t in enumerate(moves(part.pieces))],
                      "N21 G70 P10 Q20 F0.1", "N22 G40 G00 X70. Z5.", "N23 G28 U0 W0 M09", "N24 M05", "N25 M30",
                      "%"]) + "\n"


def test_g70_under_g42_finishes_with_the_nose_on_the_profile_and_g71_roughs_uncompensated():
    text = g70_program(SHAFT)
    assert "N20 G01 X60. Z-40." in text
    segs = plan(text, (SHAFT.x0, SHAFT.z0), 100.0, setup())
    g70 = [p for g in segs if g.cycle == 70 and g.subcycle == 2 for p in sample([g.element], 0.005)]
    assert np.abs(gap(g70, SHAFT.pieces, R, 3)).max() <= 0.003
    whole = [p for g in segs if g.cycle == 70 for p in sample([g.element], 0.005)]
    assert gap(whole, SHAFT.pieces, R, 3).min() >= -0.003
    # G71: the tool's tip on the profile shifted by the allowances, as without compensation (Fanuc's G71)
    plain = plan(text.replace("G42", "G40"), (SHAFT.x0, SHAFT.z0), 100.0, setup())
    assert [g.element for g in segs if g.cycle == 71] == [g.element for g in plain if g.cycle == 71]
    rough = np.array([p for g in segs if g.cycle == 71 and g.feed for p in sample([g.element], 0.01)])
    assert below_shifted_profile(SHAFT, 0.2, 0.1, rough[:, 0], rough[:, 1], tol=0.002) <= 0.002


# -- refusals -----------------------------------------------------------------------------------------
def refused(text: str, s: Setup | None = None, start=(35.0, 5.0)) -> ProgramError:
    with pytest.raises(ProgramError) as err:
        parse(text, start, s or setup())
    return err.value


def test_an_arc_smaller_than_the_nose_on_its_concave_side_is_refused():
    text = ("N1 G98 T0101 F100\nN2 G42 G00 X20 Z2\nN3 G01 Z-10\nN4 G02 X21 Z-10.5 R0.5\nN5 G01 X40\n"
            "N6 G40 G00 X70 Z5\nM30\n")
    err = refused(text)
    assert (err.line_no, err.column) == (4, 1)
    assert "G42, nose radius 0.8 mm" in str(err) and "arc of radius 0.5 mm" in str(err) and "does not fit" in str(err)
    assert parse(text, (35.0, 5.0), setup(0.4))                    # a smaller nose fits


def test_a_groove_narrower_than_the_nose_is_refused():
    text = ("N1 G98 T0101 F100\nN2 G42 G00 X30 Z2\nN3 G01 Z-10\nN4 X20\nN5 Z-11\nN6 X30\nN7 Z-20\n"
            "N8 G40 G00 X70 Z5\nM30\n")
    err = refused(text)
    # the groove's floor (1 mm) is shorter than the nose's diameter: its offset between the walls' offsets runs
    # backwards (the nose would cut both walls)
    assert (err.line_no, err.column) == (5, 1) and "run backwards" in str(err) and "G42, nose radius 0.8" in str(err)
    assert parse(text, (35.0, 5.0), setup(0.4))                    # 1 mm wide: a 0.8 mm nose fits


def test_compensation_words_out_of_place_are_refused():
    err = refused("N1 G98 T0101 F100\nN2 G42 G00 X30 Z2\nN3 G01 Z-10 T0202\nM30\n")
    assert (err.line_no, err.column) == (3, 13) and "cancel the tool-nose radius compensation (G40)" in str(err)
    err = refused("N1 G98 T0101 F100\nN2 G42 G00 X30 Z2\nN3 G01 Z-10\nN4 G28 U0 W0\nM30\n")
    assert (err.line_no, err.column) == (4, 4) and "G28 with G42 in force" in str(err)
    err = refused("N1 G98 T0101 F100\nN2 G00 X60 Z0\nN3 G42 G02 X50 Z-5 R5\nN4 G01 Z-10\nM30\n")
    assert err.line_no == 3 and "start-up" in str(err)
    err = refused("N1 G98 T0101 F100\nN2 G42 G00 X30 Z2\nN3 G01 Z-10\nN4 G41 G01 X40\nN5 Z-20\nM30\n")
    assert err.line_no == 4 and "change sides through G40" in str(err)
    err = refused(g70_program(SHAFT).replace("G42", "G41"), start=(SHAFT.x0, SHAFT.z0))
    assert (err.line_no, err.column) == (20, 5) and "G70 with G41 on an outside profile" in str(err)
    err = refused(g70_program(SHAFT).replace("N10 G00", "N10 G42 G00"), start=(SHAFT.x0, SHAFT.z0))
    assert err.line_no == 10 and "G42 inside the profile" in str(err)


# -- the offset geometry as a property -------------------------------------------------------------
SPEC = st.one_of(st.tuples(st.just("z"), st.floats(2.0, 8.0)),
                 st.tuples(st.just("taper"), st.floats(2.0, 8.0), st.floats(0.5, 4.0)),
                 st.tuples(st.just("face"), st.floats(2.0, 5.0)),
                 st.tuples(st.just("convex"), st.floats(2.0, 6.0), st.just(0.0), st.floats(0.3, HALF_PI)),
                 st.tuples(st.just("concave"), st.floats(2.5, 6.0), st.just(-HALF_PI), st.floats(-math.pi, -1.8)))


@settings(max_examples=60, deadline=None)
@given(specs=st.lists(SPEC, min_size=2, max_size=7), r=st.floats(0.2, 1.2), tip=st.integers(0, 9))
def test_the_offset_is_at_the_nose_radius_from_a_monotone_profile_everywhere(specs, r, tip):
    """Random monotone outside profiles of lines and arcs (X rising toward the chuck), each line at least 2 mm,
    each concave arc of radius > 2 mm: G42's commanded path, less the tip vector, lies at the nose radius from
    the profile everywhere (1e-6 mm) and nowhere nearer: the nose touches the profile and never gouges it."""
    part = build_part(100.0, 0.0, 5.0, specs)
    try:
        pieces = Nose(-1, r, tip).path([element(p) for p in part.pieces])
    except CornerError as err:          # only where a piece is too short for the corners on both its ends
        short = part.pieces[err.index]
        assert math.dist(short.start, short.end) < 4 * r, (err, specs, r)
        return
    points = densify(np.array([p for e, _ in pieces for p in sample([e], 0.05)]), 0.05)
    g = gap(points, part.pieces, r, tip)
    assert np.abs(g).max() <= 1e-6
    # the path is continuous (nearly tangent junctions are joined within geometry.JOIN) in the profile's order
    for (a, i), (b, j) in zip(pieces, pieces[1:]):
        assert math.dist(a.end, b.start) <= JOIN and i <= j


def test_g70_under_g41_on_a_bore_finishes_with_the_nose_on_the_profile():
    """Inside work: the bore of the Fanuc suite (roughed outward with U-0.4), finished under G41 by a boring bar
    (tip 2, nose 0.4): the nose circle on the bore's profile (3 um), never into the wall; G42 there is refused."""
    from lathe_oracle import fanuc
    from test_fanuc_suite import SUITE

    part, options = SUITE["bore (ID)"]
    text = fanuc(part, 2004, **options).replace("N5 G00", "N5 G41 G00").replace("N22 G28", "N215 G40 G00 X10. Z5.\n"
                                                                                           "N22 G28")
    x0 = part.x0
    bore = [Piece((p.start[0], 2 * x0 - p.start[1]), (p.end[0], 2 * x0 - p.end[1]),
                  None if p.centre is None else (p.centre[0], 2 * x0 - p.centre[1]), not p.convex)
            for p in part.pieces]
    segs = plan(text, (x0, part.z0), 100.0, setup(0.4, 2))
    g70 = [p for g in segs if g.cycle == 70 and g.subcycle == 2 for p in sample([g.element], 0.005)]
    assert len(g70) > 500 and np.abs(gap(g70, bore, 0.4, 2)).max() <= 0.003
    whole = [p for g in segs if g.cycle == 70 for p in sample([g.element], 0.005)]
    assert gap(whole, bore, 0.4, 2).min() >= -0.003
    with pytest.raises(ProgramError) as err:
        parse(text.replace("G41", "G42"), (x0, part.z0), setup(0.4, 2))
    assert "G70 with G42 on an inside profile" in str(err.value)
