"""G72/G73 profiles are the programmed part as G71's are (the part check subtracts each cycle's removed() from
the stock), and a G72 face finished by G70 closed loop on lathe_roughing, judged by the part check."""

from __future__ import annotations

from pathlib import Path

import pytest
from drawings import outline_dxf
from shapely.geometry import Point

from ncfmu.systems.part import LathePart

EXAMPLE = Path(__file__).resolve().parents[2] / "docs" / "examples" / "lathe_face_g72.nc"
#: The example's text lines: the shoulder's face (X44 at Z-4), the hub (Z-1), the taper, the front face.
FACE_LINE, HUB_LINE, TAPER_LINE, FRONT_LINE = 11, 12, 13, 14
BAR = {"stock_diameter": 58.0, "stock_length": 80.0, "stock_face_z": 0.0, "x_start": 30.0, "z_start": 2.0}

#: G73 on the same bar (radius values): the profile from X10 Z1 along Z-5, a taper to X20 Z-10, Z-15, out.
PATTERN = """G18 G21 G90 G8 G98
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


def test_the_g72_profile_is_the_programmed_part():
    s = LathePart(seq="seq", x="x_axis", z="z_axis").setup({"seq": {"program": EXAMPLE.read_text(), **BAR}})
    assert s.why_not == ""
    part = s.programmed
    # in front of the profile is cut away: the shoulder's step, the hub's taper; behind it the bar stays
    for z, x in ((-2.0, 25.0), (-0.3, 15.0), (-3.9, 28.9), (-0.95, 21.9)):
        assert not part.contains(Point(z, x)), (z, x)
    for z, x in ((-4.1, 25.0), (-0.5, 15.0), (-2.0, 21.9), (-10.0, 28.9)):
        assert part.contains(Point(z, x)), (z, x)
    assert part.area == pytest.approx(80 * 29 - (4 * (29 - 22) + 1 * 12 / 2), abs=1e-6)
    assert sorted({line for _, line in s.lines}) == [FACE_LINE, HUB_LINE, TAPER_LINE, FRONT_LINE]


def test_the_g73_profile_is_the_programmed_part():
    s = LathePart(seq="seq", x="x_axis", z="z_axis").setup({"seq": {"program": PATTERN, **BAR, "x_diameter": False}})
    assert s.why_not == ""
    # above the profile between its ends' Z is cut away: X10 in front of Z-5, the taper, X20 to Z-15
    for z, x in ((-2.0, 10.5), (-7.5, 15.5), (-12.0, 20.5)):
        assert not s.programmed.contains(Point(z, x)), (z, x)
    for z, x in ((-2.0, 9.5), (-7.5, 14.5), (-12.0, 19.5), (-20.0, 28.0)):
        assert s.programmed.contains(Point(z, x)), (z, x)
    assert sorted({line for _, line in s.lines}) == [6, 7, 8, 9]


@pytest.mark.slow
def test_a_g72_face_finished_by_g70_is_the_programmed_part_closed_loop(ncfmu_run):
    r = ncfmu_run("lathe_roughing", stop_time=60.0, start_values={"seq.program": EXAMPLE.read_text()})
    assert r["seq.done"][-1] and not r["seq.alarm"].any()
    assert {72, 70} <= set(r["seq.canned_cycle"])
    p = r.part
    assert p.judged == "" and p.crashes == []
    assert p.max_left_mm < 0.01 and p.max_gouge_mm < 0.01 and p.within_tolerance is True


@pytest.mark.slow
def test_the_face_drawn_a_tenth_deeper_is_out_of_tolerance_at_its_line(ncfmu_run, tmp_path):
    """The same run judged against a drawing whose shoulder face lies 0.1 mm deeper (Z-4.1): 0.1 mm left on that
    face, named by the profile's block that cut it (the run is the one above: ncfmu_run keeps it)."""
    right = outline_dxf(tmp_path / "right.dxf", OUTLINE)
    p = ncfmu_run("lathe_roughing", stop_time=60.0, start_values={"seq.program": EXAMPLE.read_text()},
                  drawing=right).part
    assert p.crashes == [] and p.within_tolerance is True                  # the drawing of the program: in
    deeper = [(-4.1 if z == -4.0 else z, x) for z, x in OUTLINE]
    off = ncfmu_run("lathe_roughing", stop_time=60.0, start_values={"seq.program": EXAMPLE.read_text()},
                    drawing=outline_dxf(tmp_path / "deeper.dxf", deeper)).part
    assert off.within_tolerance is False and off.max_left_mm == pytest.approx(0.1, abs=0.01)
    assert off.left_line == FACE_LINE and off.max_gouge_mm < 0.01


#: The example's part as drawn, (Z, radius): the front face to X10, the taper to the hub (X22, Z-1), the hub to the
#: shoulder's face at Z-4, the bar (radius 29) to its end at Z-80.
OUTLINE = [(0.0, 0.0), (0.0, 10.0), (-1.0, 22.0), (-4.0, 22.0), (-4.0, 29.0), (-80.0, 29.0), (-80.0, 0.0)]


