"""The part drawn (``--drawing FILE.dxf``, :mod:`ncfmu.systems.drawing`): the DXF reader against hand-worked
geometry, its refusals, and the part check's judgement against a drawing -- the programmed part replaced, the
verdict from polygons -- without simulating; the closed-loop runs (marked slow) judge the README's Fanuc example
and a program without G71/G70 against drawings of them."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import ezdxf
import numpy as np
import pytest
from conftest import ROOT
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import Polygon, box

from ncfmu.errors import DrawingError
from ncfmu.machining import deviation
from ncfmu.systems import SYSTEMS, parameters
from ncfmu.systems.drawing import JOIN_TOLERANCE, lathe_part, read_drawing
from ncfmu.systems.part import ARC_SPACING, LathePart, MillPart, PartSettings

FANUC = (ROOT / "docs" / "examples" / "lathe_fanuc.nc").read_text()
#: The Fanuc example's finished profile (docs/examples/lathe_fanuc.nc, N10-N20) as the drawing's (X = Z, Y =
#: radius): the chamfer, the taper, the R4 fillet into the shoulder (centre Z -26 X 24), closed along the axis.
FANUC_BEFORE_ARC = [(0.0, 0.0), (0.0, 14.0), (-2.0, 16.0), (-12.0, 16.0), (-20.0, 20.0), (-26.0, 20.0)]
FANUC_AFTER_ARC = [(-30.0, 24.0), (-30.0, 27.0), (-40.0, 27.0), (-40.0, 0.0), (0.0, 0.0)]

#: A program without G71/G70 (as CAM writes them): two diameters turned with plain G01 moves, 1 mm deep each
#: from the 58 mm bar -- X 56 from Z 0 to Z -20, then X 54 from Z 0 to Z -10 (diameters; G99 F mm/rev).
PLAIN = """G21 G40 G99
T0101
G50 S2500
G97 S1500 M03
G00 X60. Z2.
G00 X56.
G01 Z-20. F0.3
G01 X60.
G00 Z2.
G00 X54.
G01 Z-10. F0.3
G01 X60.
G00 Z2.
M05
M30
"""
#: Its part: the bar of radius 29 with a step of radius 28 down to Z -20 and of 27 down to Z -10.
PLAIN_OUTLINE = [(0.0, 0.0), (0.0, 27.0), (-10.0, 27.0), (-10.0, 28.0), (-20.0, 28.0), (-20.0, 29.0),
                 (-30.0, 29.0), (-30.0, 0.0)]


def new_drawing(units: int | None = 4):
    doc = ezdxf.new() if units is None else ezdxf.new(units=units)
    return doc, doc.modelspace()


def polyline_lines(msp, points) -> None:
    for a, b in zip(points, points[1:]):
        msp.add_line(a, b)


def fanuc_dxf(path: Path, off: float = 0.0) -> Path:
    """The Fanuc example's part drawn, the taper's end and the Z -26 to -30 fillet's cylinder ``off`` mm (radius)
    higher when asked: the 40 mm diameter drawn as 40 + 2 * off."""
    doc, msp = new_drawing()
    before = [(z, x + off if z in (-20.0, -26.0) else x) for z, x in FANUC_BEFORE_ARC]
    polyline_lines(msp, before)
    # the fillet from (-26, 20) to (-30, 24) about (-26, 24): drawn counter-clockwise from 180 to 270 degrees
    if off:
        msp.add_line((-26.0, 20.0 + off), (-26.0, 20.0))
    msp.add_arc((-26.0, 24.0), 4.0, 180.0, 270.0)
    polyline_lines(msp, FANUC_AFTER_ARC)
    doc.saveas(path)
    return path


def lathe_setup(program: str, drawing=None):
    part = next(p for p in SYSTEMS["lathe_roughing"].report.parts if isinstance(p, LathePart))
    part = replace(part, settings=PartSettings(drawing=drawing))
    values = {"seq": {**parameters("lathe_roughing", "seq"), "program": program},
              "limiter": parameters("lathe_roughing", "limiter")}
    return part.setup(values)


# -- the reader -----------------------------------------------------------------------------------------------
def test_the_fanuc_example_drawn_is_its_programmed_part(tmp_path):
    drawing = read_drawing(fanuc_dxf(tmp_path / "fanuc.dxf"))
    assert len(drawing.handles) == 10
    # the half section's area by hand, the radius integrated over Z: chamfer, 32 mm, taper, 40 mm, the fillet
    # (its square under X 24 less the quarter disc about its centre), 54 mm
    area = 2 * (14 + 16) / 2 + 10 * 16 + 8 * (16 + 20) / 2 + 6 * 20 + (4 * 24 - 4 * math.pi) + 10 * 27
    assert drawing.outline.area == pytest.approx(area, rel=1e-5)
    # the same part as the part check reads from the program's G71/G70 profile
    programmed = lathe_setup(FANUC).programmed
    judged = lathe_setup(FANUC, drawing).programmed
    assert judged.symmetric_difference(programmed).area < 1e-6
    d = deviation(programmed, judged)
    assert d.left < 1e-6 and d.gouge < 1e-6


def test_arcs_are_chords_at_the_part_checks_spacing(tmp_path):
    doc, msp = new_drawing()
    msp.add_circle((5.0, 5.0), 3.0)
    doc.saveas(tmp_path / "disc.dxf")
    ring = np.array(read_drawing(tmp_path / "disc.dxf").outline.exterior.coords)
    chords = np.hypot(*np.diff(ring, axis=0).T)
    assert chords.max() <= ARC_SPACING + 1e-12
    assert np.hypot(ring[:, 0] - 5.0, ring[:, 1] - 5.0) == pytest.approx(3.0, abs=1e-12)


@settings(deadline=None, max_examples=30)     # each example writes and reads a DXF (40 ms)
@given(st.floats(-0.99, 0.99).filter(lambda b: abs(b) > 0.05), st.booleans())
def test_a_bulge_is_the_arc_it_says_whichever_way_the_polyline_runs(bulge, mirrored):
    # a slot: two half-lines joined by a bulged segment each end; the bulge b is tan(sweep / 4), the arc's
    # sagitta b * chord / 2 off the chord, on the right of travel for b > 0 (a counter-clockwise arc)
    import tempfile
    doc, msp = new_drawing()
    pl = msp.add_lwpolyline([(0.0, 0.0, 0.0), (10.0, 0.0, bulge), (10.0, 4.0, 0.0), (0.0, 4.0, bulge)],
                            format="xyb", close=True)
    if mirrored:                        # drawn with the extrusion -Z (a CAD's mirror): x runs along -X
        pl.dxf.extrusion = (0.0, 0.0, -1.0)
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "slot.dxf"
        doc.saveas(path)
        outline = read_drawing(path).outline
    theta = 4.0 * math.atan(abs(bulge))
    radius = 4.0 / (2.0 * math.sin(theta / 2.0))
    chord_error = ARC_SPACING ** 2 / (8.0 * radius)      # the chords' sagitta: how far inside the arc they cut
    sagitta = max(bulge * 4.0 / 2.0, 0.0)     # how far the ends bulge out (b < 0: in, the corners stay)
    x0, y0, x1, y1 = outline.bounds
    expected = (-10.0 - sagitta, sagitta) if mirrored else (-sagitta, 10.0 + sagitta)
    assert (x0, x1) == pytest.approx(expected, abs=chord_error + 1e-9)
    assert (y0, y1) == pytest.approx((0.0, 4.0), abs=1e-12)
    # the area: the rectangle plus (b > 0) or minus (b < 0) two circular segments of the bulge's arc
    segment = radius ** 2 / 2.0 * (theta - math.sin(theta))
    assert outline.area == pytest.approx(40.0 + math.copysign(2.0 * segment, bulge), rel=1e-4)


# -- the refusals: one line naming the file, the entity and the rule ----------------------------------------
def refusal(path: Path) -> str:
    with pytest.raises(DrawingError) as caught:
        read_drawing(path)
    text = str(caught.value)
    assert "\n" not in text and text.startswith(f"--drawing {path}: ")
    return text


def test_a_gap_in_the_outline_is_refused_saying_where(tmp_path):
    doc, msp = new_drawing()
    polyline_lines(msp, [(0.0, 0.0), (0.0, 10.0), (-20.0, 10.0), (-20.0, 0.0)])
    msp.add_line((-20.0, 0.0), (-0.05, 0.0))          # 0.05 mm short of closing at the origin
    doc.saveas(tmp_path / "gap.dxf")
    text = refusal(tmp_path / "gap.dxf")
    assert "not closed (a gap" in text
    assert "(-0.0500, 0.0000)" in text and "(0.0000, 0.0000)" in text and "0.0500 mm away" in text
    # within the join tolerance the ends are one point: the same outline closes
    doc, msp = new_drawing()
    polyline_lines(msp, [(0.0, 0.0), (0.0, 10.0), (-20.0, 10.0), (-20.0, 0.0), (-JOIN_TOLERANCE / 2, 0.0)])
    doc.saveas(tmp_path / "closed.dxf")
    assert read_drawing(tmp_path / "closed.dxf").outline.area == pytest.approx(200.0, abs=1e-3)


def test_inch_units_are_refused_unitless_and_mm_read(tmp_path):
    square = [(0.0, 0.0), (0.0, 1.0), (-2.0, 1.0), (-2.0, 0.0), (0.0, 0.0)]
    for units, ok in ((1, False), (0, True), (4, True), (6, False)):
        doc, msp = new_drawing(units)
        polyline_lines(msp, square)
        path = tmp_path / f"units{units}.dxf"
        doc.saveas(path)
        if ok:
            assert read_drawing(path).outline.area == pytest.approx(2.0)
        else:
            text = refusal(path)
            assert f"$INSUNITS = {units} ({'Inches' if units == 1 else 'Meters'})" in text and "in mm" in text


def test_a_spline_is_refused_by_its_handle(tmp_path):
    doc, msp = new_drawing()
    polyline_lines(msp, [(0.0, 0.0), (0.0, 10.0), (-20.0, 10.0), (-20.0, 0.0), (0.0, 0.0)])
    msp.add_text("SHAFT")                        # an annotation: passed over
    spline = msp.add_spline([(0.0, 10.0), (-5.0, 12.0), (-10.0, 10.0)])
    doc.saveas(tmp_path / "spline.dxf")
    text = refusal(tmp_path / "spline.dxf")
    assert f"SPLINE {spline.dxf.handle} cannot be read" in text


def test_two_outlines_side_by_side_are_refused_a_hole_is_a_hole(tmp_path):
    doc, msp = new_drawing()
    msp.add_lwpolyline([(0, 0), (10, 0), (10, 10), (0, 10)], close=True)
    msp.add_circle((30.0, 5.0), 2.0)
    doc.saveas(tmp_path / "two.dxf")
    assert "cannot tell which is the part" in refusal(tmp_path / "two.dxf")
    doc, msp = new_drawing()
    msp.add_lwpolyline([(0, 0), (10, 0), (10, 10), (0, 10)], close=True)
    msp.add_circle((5.0, 5.0), 2.0)
    doc.saveas(tmp_path / "holed.dxf")
    outline = read_drawing(tmp_path / "holed.dxf").outline
    assert len(outline.interiors) == 1 and outline.area == pytest.approx(100.0 - 4.0 * math.pi, rel=1e-4)


def test_a_branching_or_crossing_outline_and_a_lathe_section_below_the_axis_are_refused(tmp_path):
    doc, msp = new_drawing()
    polyline_lines(msp, [(0.0, 0.0), (0.0, 10.0), (-20.0, 10.0), (-20.0, 0.0), (0.0, 0.0)])
    msp.add_line((0.0, 10.0), (5.0, 15.0))
    doc.saveas(tmp_path / "branch.dxf")
    assert "the outline branches" in refusal(tmp_path / "branch.dxf")
    doc, msp = new_drawing()
    polyline_lines(msp, [(0.0, 0.0), (-20.0, 10.0), (-20.0, 0.0), (0.0, 10.0), (0.0, 0.0)])   # a bow tie
    doc.saveas(tmp_path / "bowtie.dxf")
    assert "must not cross or touch itself" in refusal(tmp_path / "bowtie.dxf")
    doc, msp = new_drawing()
    polyline_lines(msp, [(0.0, -10.0), (0.0, 10.0), (-20.0, 10.0), (-20.0, -10.0), (0.0, -10.0)])   # full section
    doc.saveas(tmp_path / "full.dxf")
    with pytest.raises(DrawingError, match="below the axis: a lathe's drawing is the upper half section"):
        lathe_part(read_drawing(tmp_path / "full.dxf"), box(-80.0, 0.0, 0.0, 29.0))


def test_the_cli_refuses_a_bad_drawing_in_one_line_with_exit_2_before_it_runs(tmp_path, capsys):
    from ncfmu.cli import main
    doc, msp = new_drawing(1)
    polyline_lines(msp, [(0.0, 0.0), (0.0, 1.0), (-2.0, 1.0), (-2.0, 0.0), (0.0, 0.0)])
    doc.saveas(tmp_path / "inch.dxf")
    doc, msp = new_drawing()
    polyline_lines(msp, [(0.0, -10.0), (0.0, 10.0), (-20.0, 10.0), (-20.0, -10.0), (0.0, -10.0)])
    doc.saveas(tmp_path / "full.dxf")                  # a full section: fine for a mill, not for a lathe
    out = tmp_path / "out"
    for argv, says in (
            (["run", "lathe_roughing", "--drawing", str(tmp_path / "inch.dxf")], "$INSUNITS = 1 (Inches)"),
            (["run", "lathe_roughing", "--drawing", str(tmp_path / "none.dxf")], "cannot be read"),
            (["run", "lathe_roughing", "--drawing", str(tmp_path / "full.dxf")], "below the axis"),
            (["serve", "lathe_roughing", "--drawing", str(tmp_path / "inch.dxf")], "$INSUNITS = 1 (Inches)")):
        assert main([*argv, "--out", str(out)]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and f"--drawing {tmp_path}" in err and says in err, err
        assert not out.exists() or not any(out.iterdir())      # refused before anything was written


# -- the judgement against the part drawn, without simulating ----------------------------------------------
def test_the_fanuc_example_drawn_a_tenth_off_is_a_tenth_out_where_it_is_off(tmp_path):
    made = lathe_setup(FANUC).programmed          # a part made exactly to the program
    drawn = lathe_setup(FANUC, read_drawing(fanuc_dxf(tmp_path / "off.dxf", off=0.1))).programmed
    d = deviation(made, drawn)
    assert d.left < 1e-6                                  # drawn larger: nothing left over, 0.1 missing
    assert d.gouge == pytest.approx(0.1, abs=1e-4)
    z, x = d.gouge_at
    assert -26.0 - 1e-6 <= z <= -20.0 + 1e-6 and x == pytest.approx(20.05, abs=0.051)


def test_a_program_without_g71_is_judged_against_the_drawing_at_its_cuts_lines(tmp_path):
    assert lathe_setup(PLAIN).programmed is None
    doc, msp = new_drawing()
    polyline_lines(msp, PLAIN_OUTLINE + [PLAIN_OUTLINE[0]])
    doc.saveas(tmp_path / "plain.dxf")
    setup = lathe_setup(PLAIN, read_drawing(tmp_path / "plain.dxf"))
    # the part drawn, and toward the chuck (Z < -30) the bar as held: the stock, 80 mm long from the face
    expected = Polygon(PLAIN_OUTLINE).union(box(-80.0, 0.0, -30.0, 29.0))
    assert setup.programmed.symmetric_difference(expected).area < 1e-9
    # where the part is off, the nearest cut names the line: the program's feed moves (G01), not its rapids
    assert sorted({line for _, line in setup.lines}) == [7, 8, 11, 12]


def test_a_mill_outline_drawn_replaces_the_contour(tmp_path):
    part = next(p for p in SYSTEMS["mill_contour"].report.parts if isinstance(p, MillPart))
    values = {"contour": parameters("mill_contour", "contour")}
    programmed = part.setup(values).programmed
    for off, gouge in ((0.0, 0.0), (0.1, 0.1)):
        doc, msp = new_drawing()
        # the default contour (0,0) (60,0) (60,40) (20,40) (0,20), its 60 mm edge drawn `off` further out
        msp.add_lwpolyline([(0, 0), (60 + off, 0), (60 + off, 40), (20, 40), (0, 20)], close=True)
        doc.saveas(tmp_path / "mill.dxf")
        drawing = read_drawing(tmp_path / "mill.dxf")
        setup = replace(part, settings=PartSettings(drawing=drawing)).setup(values)
        assert setup.programmed.equals(drawing.outline)
        d = deviation(programmed, setup.programmed)
        assert d.left < 1e-9 and d.gouge == pytest.approx(gouge, abs=1e-9)
        if gouge:
            assert d.gouge_at[0] == pytest.approx(60.05, abs=0.051) and 0.0 <= d.gouge_at[1] <= 40.0
        # the plate is the part drawn grown by the stock margin
        assert setup.removal.part(setup.anchor).bounds == pytest.approx((-5.0, -5.0, 65.0 + off, 45.0))


# -- closed loop through the FMUs ------------------------------------------------------------------------------
def plain_dxf(path: Path, off: float = 0.0) -> Path:
    """PLAIN's part drawn, its 56 mm diameter (radius 28, Z -10 to -20) ``off`` mm higher."""
    doc, msp = new_drawing()
    outline = [(z, x + off if x == 28.0 else x) for z, x in PLAIN_OUTLINE]
    polyline_lines(msp, outline + [outline[0]])
    doc.saveas(path)
    return path


@pytest.mark.slow
def test_the_fanuc_example_run_is_judged_against_its_drawing(ncfmu_run, tmp_path):
    # the same run as tests/systems/test_fanuc_program_system.py's (the session shares it)
    right, off = fanuc_dxf(tmp_path / "fanuc.dxf"), fanuc_dxf(tmp_path / "off.dxf", off=0.1)
    start = {"seq.program": FANUC}
    p = ncfmu_run("lathe_roughing", stop_time=100.0, start_values=start, drawing=right).part
    assert p.crashes == [] and p.judged == ""
    assert p.max_left_mm < 0.01 and p.max_gouge_mm < 0.01 and p.within_tolerance is True
    p = ncfmu_run("lathe_roughing", stop_time=100.0, start_values=start, drawing=off).part
    assert p.within_tolerance is False and p.max_left_mm < 0.01
    assert p.max_gouge_mm == pytest.approx(0.1, abs=0.005)
    z, x = p.gouge_at
    assert -26.0 - 0.01 <= z <= -20.0 + 0.01 and x == pytest.approx(20.0, abs=0.01)   # the 40 mm diameter
    assert p.gouge_line == 16                                                         # N15 Z-26.


@pytest.mark.slow
def test_a_program_without_g71_gets_a_dimensional_verdict_with_a_drawing(ncfmu_run, tmp_path, capsys):
    from ncfmu.cli import main
    start = {"seq.program": PLAIN}
    r = ncfmu_run("lathe_roughing", stop_time=8.0, start_values=start)
    assert r.part.judged == "the program has no G71/G70 profile to judge against"
    assert r.part.within_tolerance is None
    # the tool went where the drawing says: radius 28 down to Z -20, 27 down to Z -10
    x, z, line = r["x_axis.pos"], r["z_axis.pos"], r["seq.line"]
    assert x[line == 7] == pytest.approx(28.0, abs=0.01) and z[line == 7].min() == pytest.approx(-20.0, abs=0.01)
    assert x[line == 11] == pytest.approx(27.0, abs=0.01) and z[line == 11].min() == pytest.approx(-10.0, abs=0.01)
    p = ncfmu_run("lathe_roughing", stop_time=8.0, start_values=start, drawing=plain_dxf(tmp_path / "p.dxf")).part
    assert p.judged == "" and p.crashes == []
    assert p.max_left_mm < 0.01 and p.max_gouge_mm < 0.01 and p.within_tolerance is True
    # drawn a tenth larger on the 56 mm diameter: out of tolerance there, by the tenth, on the line that cut it
    off = plain_dxf(tmp_path / "off.dxf", off=0.1)
    status = main(["run", "lathe_roughing", "--stop-time", "8", "--set", f"seq.program={PLAIN}",
                   "--drawing", str(off), "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert status == 3, out
    assert "  part: OUT OF TOLERANCE 0.0100 mm: left <= " in out and "(line 7)" in out
    written = json.loads((tmp_path / "lathe_roughing.part.json").read_text())
    assert written["max_gouge_mm"] == pytest.approx(0.1, abs=0.005) and written["within_tolerance"] is False
    assert -20.01 <= written["gouge_at"]["Z"] <= -9.99 and written["gouge_at"]["line"] == 7


def test_what_no_part_is_made_of_is_refused(tmp_path):
    for name, says in (("empty", "cannot be read"), ("nan", "LINE 2F has the coordinate nan"),
                       ("huge", "of arcs: more than 1000000 points")):
        doc, msp = new_drawing()
        if name == "nan":
            msp.add_line((0.0, 0.0), (math.nan, 1.0))
        elif name == "huge":                      # a 200 m circle: 31 million chords of 0.02 mm
            msp.add_circle((0.0, 0.0), 1e5)
        path = tmp_path / f"{name}.dxf"
        if name == "empty":
            path.write_text("")
        else:
            doc.saveas(path)
        assert says in refusal(path)
