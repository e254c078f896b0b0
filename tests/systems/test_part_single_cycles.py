"""The part check judges a part turned and faced by G90/G94 passes with no G71/G70 profile and no drawing: each
pass cuts away, by its definition, the quadrilateral its four moves enclose (start point, the cut's start with R's
taper, the cut's end, straight out) -- the shared convention's ``removed()`` on the op. Plain Python: the report's
own accumulator fed the rows of the planned path (the axes exactly on it), so the verdict's numbers are the
program's own."""

from __future__ import annotations

import pytest
from shapely.geometry import Polygon
from shop_programs import PASSES
from test_part_tools import BAR, LATHE, lathe_check

from ncfmu.controllers import lathe_program
from ncfmu.controllers.sequencer import CutSequencer

#: G54 shifts the axes 3 mm toward the chuck and 0.5 mm (radius) up from the part's coordinates.
WORK_Z, WORK_X = -3.0, 0.5
#: PASSES' two G94 and two G90 passes (text lines).
FACE_LINES, TURN_LINES = (6, 7), (9, 10)


def _parse(text: str):
    setup = lathe_program.Setup(works=((WORK_Z, WORK_X),) + ((0.0, 0.0),) * 5)
    return lathe_program.parse(text, (BAR["x_start"], BAR["z_start"]), setup)


def _flat(points) -> list[float]:
    return [c for p in points for c in p]


def test_each_pass_removes_the_quadrilateral_its_moves_enclose() -> None:
    passes = [op for op in _parse(PASSES) if isinstance(op, lathe_program.SingleCycle)]
    assert [(op.line, op.code) for op in passes] == [(6, 94), (7, 94), (9, 90), (10, 90)]
    # (z, x radius) in the program's coordinates: the start point, in, along the cut, out
    assert _flat(passes[1].removed()) == pytest.approx(_flat(((2.0, 32.0), (-2.0, 32.0), (-2.0, 20.0), (2.0, 20.0))))
    assert _flat(passes[3].removed()) == pytest.approx(_flat(((2.0, 30.0), (2.0, 24.0), (-15.0, 25.0), (-15.0, 30.0))))


def _rows_of(text: str):
    """The planned path as the moves of test_part_tools.lathe_rows (the axes exactly on it: work offset in)."""
    setup = lathe_program.Setup(works=((WORK_Z, WORK_X),) + ((0.0, 0.0),) * 5)
    segs = lathe_program.plan(text, (BAR["x_start"], BAR["z_start"]), 50.0, setup)
    return [(g.element.end[0], g.element.end[1], float(not g.feed), g.line, float(g.modal.tool)) for g in segs]


def _judge(text: str, path: str | None = None):
    works = {"work[1].z": WORK_Z, "work[1].x": WORK_X}
    return lathe_check(text, _rows_of(path or text), **works).verdict()


def test_a_part_of_g90_g94_passes_under_g54_is_judged_without_a_drawing() -> None:
    v = _judge(PASSES)
    assert v.judged == "" and v.crashes == []
    assert v.max_left_mm < 1e-3 and v.max_gouge_mm < 1e-3 and v.within_tolerance is True
    # the programmed part: the bar faced to Z-2 down to radius 20, turned to the taper from radius 24 (Z2) to 25
    # (Z-15), the shoulder at Z-15 -- in the program's coordinates (the G54 shift is the axes')
    setup = LATHE.setup({"seq": {**CutSequencer.default_parameters(), **BAR, "program": PASSES,
                                 "work[1].z": WORK_Z, "work[1].x": WORK_X}})
    expected = Polygon([(-80.0, 0.0), (-80.0, 29.0), (-15.0, 29.0), (-15.0, 25.0), (-2.0, 24.0 + 4.0 / 17.0),
                        (-2.0, 20.0), (0.0, 20.0), (0.0, 0.0)])
    assert setup.programmed.symmetric_difference(expected).area < 1e-6


def test_a_pass_the_axes_did_not_make_is_material_left_at_its_line() -> None:
    # the axes stop 0.3 mm (radius) short on the taper pass: the part is 0.3 mm too large there, named by line 10
    short = PASSES.replace("X50. R-1.", "X50.6 R-1.")
    v = _judge(PASSES, path=short)
    assert v.within_tolerance is False and v.max_left_mm == pytest.approx(0.3, abs=1e-3)
    assert v.left_line == TURN_LINES[1]
    # and a face pass 0.5 mm too deep: a gouge at a facing line
    deep = PASSES.replace("Z-2.\n", "Z-2.5\n")
    v = _judge(PASSES, path=deep)
    assert v.max_gouge_mm == pytest.approx(0.5, abs=1e-3) and v.gouge_line in FACE_LINES
