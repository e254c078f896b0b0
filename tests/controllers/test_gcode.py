"""The one G-code front end (controllers/gcode.py): one reader and checker for the mill's and the lathe's
dialects, every reading error of a program at once, in line order, each with its line and column."""

from __future__ import annotations

import pytest

from ncfmu.controllers import lathe_program, rs274
from ncfmu.controllers.gcode import Block, read
from ncfmu.errors import ProgramError, ProgramErrors


def test_every_reading_error_at_once_in_line_order_lathe():
    text = ("G18 G21 G90\nG00 X30 Z2 Y1\nG01 G00 X10\nG5 P1\nN10 G01 Z-1 F100\nN10 X20\nG01 X#1\nM30\nG00 X5\n")
    with pytest.raises(ProgramErrors) as err:
        lathe_program.parse(text, (30.0, 2.0))
    found = [(e.line_no, e.column) for e in err.value.errors]
    assert found == [(2, 12), (3, 5), (4, 1), (6, 1), (7, 5), (9, 1)]
    assert (err.value.line_no, err.value.column) == (2, 12)
    reasons = [e.rule for e in err.value.errors]
    assert "no Y axis" in reasons[0] and "modal group motion" in reasons[1] and "G5 is not in the subset" in reasons[2]
    assert "N10 again: line 5" in reasons[3] and "parameters" in reasons[4] and "after the program end" in reasons[5]
    # one message, every error in it, each with its line and column
    assert str(err.value).count("line ") >= 6 and "line 9, column 1: text after the program end" in str(err.value)


def test_every_reading_error_at_once_in_line_order_mill():
    text = "G17 G21\nG1 F60 X1 Z2\nG18\nG01 X1 Y1 R3\n"
    with pytest.raises(ProgramErrors) as err:
        rs274.parse(text, (0.0, 0.0))
    assert [(e.line_no, e.column) for e in err.value.errors] == [(2, 11), (3, 1), (4, 11), (4, 1)]
    assert "does not end with M02 or M30" in err.value.errors[-1].rule


def test_one_error_is_a_plain_program_error():
    with pytest.raises(ProgramError) as err:
        rs274.parse("G1 F60 X1 A5\nM2", (0.0, 0.0))
    assert type(err.value) is ProgramError and "line 1, column 11: A5: word A is not in the subset" in str(err.value)


def test_one_reader_two_dialects():
    """The same words read the same way; what a dialect does not take it refuses with its own reason."""
    text = "N5 G01 X1.5 F60 (comment)\nM30\n"
    mill, lathe = read(text, rs274.MILL), read(text, lathe_program.LATHE)
    assert [(b.n, b.g, b.m, b.values) for b in mill] == [(b.n, b.g, b.m, b.values) for b in lathe]
    assert isinstance(mill[0], Block) and mill[0].values == {"X": 1.5, "F": 60.0} and mill[1].ends
    with pytest.raises(ProgramError, match="G18: only the XY plane"):
        read("G18\nM30\n", rs274.MILL)
    with pytest.raises(ProgramError, match="G17: a lathe works in the XZ plane"):
        read("G17\nM30\n", lathe_program.LATHE)
