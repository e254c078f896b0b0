"""A shop's lathe program closed-loop (issue 46): three grooves made by one subprogram called three times with an
incremental shift (W), under G54 with a work offset, the bar's edge chamfered with ,C -- run on lathe_roughing
and judged by the part check against the part drawn (the program has no G71/G70 profile)."""

from __future__ import annotations

import ezdxf
import numpy as np
import pytest

#: Diameters, G99 F mm/rev. The chamfer 1 x 45 degrees at the face (,C1 from the corner), turned with tool 1; the
#: grooves: 3 mm wide, 1 mm deep (radius), 6 mm apart, from Z-9 on, by a grooving blade 2 mm wide (tool 2, its
#: programmed point the corner toward the chuck: it spans Z..Z+2): a plunge 8 mm on from where the last groove
#: ended (W-8), then 1 mm along Z to the groove's width (W-1).
GROOVES = """G21 G40 G99
G54
T0101
G97 S1500 M03
G00 X60. Z2.
G00 X54. Z1.
G01 Z0. F0.2
X58. ,C1.
Z-3.
G00 X60. T0202
M98 P30100
G00 Z5.
M05
M30
O0100
G00 W-8.
G01 U-4. F0.1
W-1. F0.2
G00 U4.
M99
"""
#: The subprogram's groove cut (text line 18) and the chamfering block (line 8).
GROOVE_LINE, CHAMFER_LINE = 18, 8
#: The grooving blade (tool 2): its width, mm, and its tip (3: the programmed point on the chuck's side).
BLADE_WIDTH = 2.0
#: G54: the axes stand 5 mm (Z) and 0.5 mm (X, radius) off the part's programmed coordinates.
WORK_Z, WORK_X = 5.0, 0.5
#: The part drawn, (Z, radius): the 58 mm bar with the chamfer and the three grooves.
OUTLINE = [(0.0, 0.0), (0.0, 28.0), (-1.0, 29.0),
           (-9.0, 29.0), (-9.0, 28.0), (-12.0, 28.0), (-12.0, 29.0),
           (-18.0, 29.0), (-18.0, 28.0), (-21.0, 28.0), (-21.0, 29.0),
           (-27.0, 29.0), (-27.0, 28.0), (-30.0, 28.0), (-30.0, 29.0),
           (-40.0, 29.0), (-40.0, 0.0)]


def _drawing(path, outline):
    doc = ezdxf.new(units=4)
    msp = doc.modelspace()
    for a, b in zip(outline, outline[1:] + outline[:1]):
        msp.add_line(a, b)
    doc.saveas(path)
    return path


@pytest.mark.slow
def test_grooves_by_a_subprogram_under_g54_with_a_chamfer_are_the_part_drawn(ncfmu_run, tmp_path):
    start = {"seq.program": GROOVES, "seq.work[1].z": WORK_Z, "seq.work[1].x": WORK_X,
             "seq.tool[2].width": BLADE_WIDTH, "seq.tool[2].tip": 3}
    right = _drawing(tmp_path / "grooves.dxf", OUTLINE)
    r = ncfmu_run("lathe_roughing", stop_time=9.0, start_values=start, drawing=right)
    assert r["seq.done"][-1], "the program did not finish in 9 s"
    x, z, line = r["x_axis.pos"], r["z_axis.pos"], r["seq.line"]
    # the subprogram's cut reports its own text line, three times: at the groove's bottom (radius 28) + the G54 X,
    # from each plunge (the groove's far wall + the blade's width) to the groove's end
    cutting = (line == GROOVE_LINE) & (np.abs(x - (28.0 + WORK_X)) < 0.01)
    assert cutting.sum() > 0
    ends = sorted({round(float(v) - WORK_Z) for v in z[cutting] if abs(v - round(v)) < 0.01 and
                   round(float(v) - WORK_Z) in (-11, -12, -20, -21, -29, -30)})
    assert ends == [-30, -29, -21, -20, -12, -11]
    p = r.part
    assert p.judged == "" and p.crashes == []
    assert p.max_left_mm < 0.01 and p.max_gouge_mm < 0.01 and p.within_tolerance is True
    # the grooves drawn 3 mm further toward the chuck: the part made is out of tolerance, at a groove's line
    shifted = [(z - 3.0 if -30.0 <= z <= -9.0 else z, x) for z, x in OUTLINE]
    off = ncfmu_run("lathe_roughing", stop_time=9.0, start_values=start,
                    drawing=_drawing(tmp_path / "off.dxf", shifted)).part
    assert off.within_tolerance is False and off.max_gouge_mm == pytest.approx(1.0, abs=0.01)
    assert GROOVE_LINE in (off.gouge_line, off.left_line)
