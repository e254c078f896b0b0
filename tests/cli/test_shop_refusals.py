"""The refusals issue 46 names, through the FMU and the command line (the planner's own tests are in
tests/controllers/test_lathe_shop.py): subprogram calls nested 5 deep, an M98 to a program the text does not hold,
,C on an arc -- the CutSequencer refuses the program at initialisation (fmi2Error, the API's NcfmuError) naming the
line, and ``ncfmu run`` says so on one line with exit status 2."""

from __future__ import annotations

import pytest

from ncfmu.cli import main
from ncfmu.errors import NcfmuError


def _nested(depth: int) -> str:
    """The main program calling O1, O1 calling O2, ... O<depth>: each cuts W-1 before its call."""
    subs = "".join(f"O{k}\nG01 W-1. F60\n" + (f"M98 P{k + 1}\n" if k < depth else "") + "M99\n"
                   for k in range(1, depth + 1))
    return f"G00 X60. Z2.\nM98 P1\nG00 X62.\nM30\n{subs}"


NESTED_5 = _nested(5)
REFUSED = [
    # the call that would open the fifth level: O4's M98 P5
    (NESTED_5, NESTED_5.splitlines().index("M98 P5") + 1, "M98 P5: subprogram calls nested 5 deep, at most 4"),
    ("G00 X60. Z2.\nM98 P30200\nG00 X62.\nM30\nO0100\nG00 W-1.\nM99\n", 2,
     "P30200: M98 calls O0200, which the program does not hold"),
    ("G00 X20. Z1.\nG01 Z0. F60\nG02 X30. Z-5. R5. ,C1.\nZ-20.\nM30\n", 3, ",C1 on an arc"),
]


@pytest.mark.parametrize("program, line, says", REFUSED, ids=["nesting 5 deep", "M98 to O0200 not held",
                                                              ",C on an arc"])
def test_the_fmu_and_the_cli_refuse_naming_the_line(project, tmp_path, capsys, program, line, says):
    from ncfmu.project import simulate
    with pytest.raises(NcfmuError) as raised:
        simulate("lathe_roughing", stop_time=0.01, start_values={"seq.program": program})
    assert "fmi2ExitInitializationMode returned fmi2Error" in str(raised.value)
    assert f"seq: parameter refused: program: line {line}: {says}" in str(raised.value)
    path = tmp_path / "refused.nc"
    path.write_text(program)
    assert main(["run", "lathe_roughing", "--program", str(path), "--stop-time", "0.05", "--out",
                 str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err and "fmi2" not in err, err
    assert err.startswith("ncfmu run: seq: parameter refused: ") and f"line {line}: {says}" in err, err


@pytest.mark.parametrize("program", [_nested(4), REFUSED[1][0].replace("P30200", "P30100")],
                         ids=["nesting 4 deep", "M98 to O0100 held"])
def test_what_the_rule_allows_initialises(project, program):
    from ncfmu.project import simulate
    r = simulate("lathe_roughing", stop_time=0.05, start_values={"seq.program": program})
    assert len(r.time) > 0 and not r["seq.alarm"].any()
