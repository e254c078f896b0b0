"""Line ends of a program (issue 45): LF, CR LF, CR, NEL, U+2028 and U+2029 read alike in both G-code dialects
(gcode.program_lines), with the same line numbers in errors; what str.splitlines also splits at (VT, FF, FS, GS,
RS) is refused, naming the character, its line and its column."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ncfmu.controllers import lathe_program, rs274
from ncfmu.controllers.feed import parse_program
from ncfmu.controllers.gcode import LINE_END, NOT_LINE_ENDS, program_lines
from ncfmu.controllers.lathe_program import Setup
from ncfmu.errors import ProgramError, ProgramErrors

EXAMPLES = Path(__file__).resolve().parents[2] / "docs" / "examples"
ENDS = ("\n", "\r\n", "\r", "\x85", "\u2028", "\u2029")
MILL = (EXAMPLES / "arc_part.ngc").read_text()
LATHE = (EXAMPLES / "lathe_fanuc.nc").read_text()
#: Programs with errors on several lines (every reading error is reported, each with its line and column).
MILL_WRONG = "%\n(wrong)\nG21 G17 G90\nF300\nG01 X10 Q4\n\nG01 Y10\nX20 #1\nM2\n%\n"
LATHE_WRONG = "%\nO0001\nN1 G21 G99\n\nN2 G00 X60. Z2. Y1\n(comment)\nN3 G01 Z-5. F0.2 =\nN4 M30\n%\n"
PROGRAMS = {"mill": (MILL, lambda text: rs274.parse(text, (0.0, -10.0))),
            "lathe": (LATHE, lambda text: lathe_program.parse(text, (30.0, 2.0), Setup(home=(50.0, 100.0)))),
            "mill_wrong": (MILL_WRONG, lambda text: rs274.parse(text, (0.0, 0.0))),
            "lathe_wrong": (LATHE_WRONG, lambda text: lathe_program.parse(text, (30.0, 2.0)))}


def outcome(parse, text: str):
    """What a program reads as: its operations, or every error's line, column and reason."""
    try:
        return "read", parse(text)
    except ProgramErrors as err:
        return "refused", [(e.line_no, e.column, e.rule) for e in err.errors]
    except ProgramError as err:
        return "refused", [(err.line_no, err.column, err.rule)]


def joined(lines: list[str], ends: list[str]) -> str:
    """``lines`` joined by ``ends``; a CR that an LF would follow at once (the next line empty) makes that LF a CR LF
    (CR then LF is one line end, whoever meant what)."""
    out = [lines[0]]
    for k, (end, line) in enumerate(zip(ends, lines[1:])):
        if end == "\n" and out[-1].endswith("\r") and lines[k] == "":
            end = "\r\n"
        out += [end, line]
    return "".join(out)


@pytest.mark.parametrize("name", sorted(PROGRAMS))
@settings(max_examples=25, deadline=None)
@given(data=st.data())
def test_any_mix_of_line_ends_reads_the_same(name, data):
    text, parse = PROGRAMS[name]
    lines = text.split("\n")
    ends = data.draw(st.lists(st.sampled_from(ENDS), min_size=len(lines) - 1, max_size=len(lines) - 1))
    expected = outcome(parse, text)
    assert expected[0] == ("refused" if name.endswith("wrong") else "read")
    assert outcome(parse, joined(lines, ends)) == expected


@pytest.mark.parametrize("end", ENDS)
def test_each_line_end_alone_reads_as_lf(end):
    """The reported case: a CR-only program read as one line ("line 1 ... unexpected character '%'")."""
    for text, parse in PROGRAMS.values():
        assert outcome(parse, text.replace("\n", end)) == outcome(parse, text)
    refused = outcome(PROGRAMS["mill_wrong"][1], MILL_WRONG.replace("\n", end))
    assert [(n, c) for n, c, _ in refused[1]] == [(5, 9), (8, 5)]
    refused = outcome(PROGRAMS["lathe_wrong"][1], LATHE_WRONG.replace("\n", end))
    assert [(n, c) for n, c, _ in refused[1]] == [(5, 17), (7, 18)]


def test_a_cr_lf_is_one_line_end_and_a_lf_cr_two():
    assert program_lines("a\r\nb\n\rc") == ["a", "b", "", "c"]
    assert LINE_END.split("x\u2028\u2029y") == ["x", "", "y"]


@pytest.mark.parametrize("char", sorted(NOT_LINE_ENDS))
def test_what_splitlines_also_splits_at_is_refused_naming_it(char):
    for text, parse in PROGRAMS.values():
        lines = text.split("\n")
        lines[2] = lines[2][:3] + char + lines[2][3:]                  # line 3, column 4
        with pytest.raises(ProgramError) as err:
            parse("\r\n".join(lines))
        assert (err.value.line_no, err.value.column) == (3, 4)
        assert f"{NOT_LINE_ENDS[char]} is neither a line end" in str(err.value)


def test_the_feed_program_reads_the_same_line_ends():
    text = "M0: X+D3F7\nM1: X-D2F1\n\nM2: END"
    expected = parse_program(text)
    for end in ENDS:
        assert parse_program(text.replace("\n", end)) == expected
    with pytest.raises(ProgramError, match="line 2, column 3: a form feed"):
        parse_program("M0: X+D3F7\nM1\x0c: END")
