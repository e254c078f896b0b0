"""What a new user meets (issue 47): the plain install has what the README shows, ``--program FILE``, refusals in
a CNC's words, ``validate`` on the FMI 3.0 FMUs, a bare FMU's ``--set``, the kind of FMUs a build keeps."""

import io
import json
import re
from importlib.metadata import requires
from pathlib import Path

import pytest

from ncfmu.cli import main
from ncfmu.errors import NcfmuError, ProgramErrors
from ncfmu.exitcodes import EXIT_NOT_FINISHED

ROOT = Path(__file__).resolve().parents[2]

#: The mill's part as a Fanuc user hands it over: tape marks, a program number, both comment forms.
MILL_PART = """%
O2001 (SQUARE)
N10 G90 G17 G21 ; absolute, mm
N20 G01 X10. Y0 F300
N30 X10. Y10.
N40 M30
%
"""

#: A lathe part the same way.
LATHE_PART = """%
O1001 (FACE)
N10 G00 X60. Z2.
N20 G01 Z-5. F0.2 ; cut
N30 M30
%
"""

#: Two errors a Fanuc programmer makes: a code outside the subset and a comma word (direct drawing dimensions).
LATHE_ALARMS = """%
O1002
N10 G00 X60. Z2.
N30 G112
N40 G01 X50. Z-10.,A30.
N50 M30
%
"""


def test_the_plain_install_has_what_the_readme_shows():
    """dask (dask[distributed]) and tqdm for ``ncfmu sweep``, mypy (mypyc) for the compiled controllers: in the
    installed distribution's own requirements, not behind an extra the README never names."""
    plain = [r for r in requires("ncfmu") or [] if "extra ==" not in r]
    names = {re.match(r"[A-Za-z0-9_.\-]+(\[[^\]]*\])?", r).group(0).lower() for r in plain}
    assert {"dask[distributed]", "tqdm", "mypy"} <= names, sorted(names)
    import dask.distributed  # noqa: F401  (importable: the plain install brought it)


def _run_record(out: Path, system: str) -> dict:
    return json.loads((out / f"{system}.run.json").read_text())["parameters"]


def test_program_from_a_file_on_the_mill_with_tape_marks_and_a_program_number(project, tmp_path, capsys):
    part = tmp_path / "square.nc"
    part.write_text(MILL_PART)
    rc = main(["run", "mill_contour", "--program", str(part), "--stop-time", "0.05", "--no-part-check",
               "--out", str(tmp_path)])
    assert rc == EXIT_NOT_FINISHED, capsys.readouterr().err    # read and run: 0.05 s is short of the contour's end
    assert _run_record(tmp_path, "mill_contour")["contour"]["program"] == MILL_PART


def test_program_from_standard_input_on_the_lathe(project, tmp_path, capsys, monkeypatch):
    monkeypatch.setattr("sys.stdin", io.StringIO(LATHE_PART))
    rc = main(["run", "lathe_roughing", "--program", "-", "--stop-time", "0.05", "--no-part-check",
               "--out", str(tmp_path)])
    assert rc == EXIT_NOT_FINISHED, capsys.readouterr().err    # read and run: 0.05 s is short of its M30
    assert _run_record(tmp_path, "lathe_roughing")["seq"]["program"] == LATHE_PART


def test_program_on_a_system_without_one_is_refused(project, tmp_path, capsys):
    part = tmp_path / "p.nc"
    part.write_text(LATHE_PART)
    assert main(["run", str(ROOT / "fmus" / "ServoAxis.fmu"), "--program", str(part), "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"--program {part}:" in err and "has no program parameter" in err
    assert main(["run", "lathe_taper", "--program", str(tmp_path / "missing.nc"), "--out", str(tmp_path)]) == 2
    assert "missing.nc: cannot read it" in capsys.readouterr().err


def test_program_alarms_in_a_cncs_words_every_one_at_once(project, tmp_path, capsys, monkeypatch):
    """One line: each error by its line and block number, the G code named as Fanuc names it, the comma word as
    direct drawing dimensions the lathe does not take; no FMI call or status (the FMU's log keeps those)."""
    monkeypatch.setattr("sys.stdin", io.StringIO(LATHE_ALARMS))
    assert main(["run", "lathe_roughing", "--program", "-", "--stop-time", "0.05", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert "line 4 (N30): G112: not in the subset (polar interpolation)" in err
    # (,C and ,R are taken on the lathe since issue 46; ,A -- the angle written as a comma word -- is not)
    assert "line 5 (N40): ,A: not in the subset (angle by direct drawing dimensions)" in err
    assert "fmi2" not in err and "fmi3" not in err and "unexpected character" not in err
    from ncfmu.project import simulate
    with pytest.raises(NcfmuError) as raised:     # the API's exception keeps the call and status
        simulate("lathe_roughing", stop_time=0.05, start_values={"seq.program": LATHE_ALARMS})
    assert "fmi2ExitInitializationMode returned fmi2Error" in str(raised.value)


def test_program_errors_name_the_block_number():
    from ncfmu.controllers import rs274
    with pytest.raises(ProgramErrors) as raised:
        rs274.parse("%\nO7\nN10 G01 X1 Y0 F60\nN20 G112\nG01 X2 Y0,R1.\nM30\n", (0.0, 0.0))
    assert raised.value.cnc_words() == ("line 4 (N20): G112: not in the subset (polar interpolation); "
                                        "line 5: ,R: not in the subset (corner radius by direct drawing dimensions)")


def test_validate_checks_the_fmi3_fmus_too(project, capsys, monkeypatch):
    import fmpy.validation
    real = fmpy.validation.validate_fmu
    seen: list[str] = []

    def validate_fmu(filename, *args, **kwargs):
        seen.append(filename)
        return real(filename, *args, **kwargs)
    monkeypatch.setattr(fmpy.validation, "validate_fmu", validate_fmu)
    assert main(["validate"]) == 0, capsys.readouterr().out
    out = capsys.readouterr().out
    fmi3 = sorted(str(p) for p in (ROOT / "fmus" / "fmi3").glob("*.fmu"))
    assert fmi3 and set(fmi3) <= set(seen)
    assert f"{len(fmi3)} FMI 3.0 FMUs" in out and "all FMUs and SSPs valid" in out


def test_a_bare_fmus_input_it_reads_itself_warns_nothing(project, tmp_path, capsys):
    """The servo axis run alone moves to the commanded 5 mm: setting pos_cmd does something, so no warning."""
    rc = main(["run", str(ROOT / "fmus" / "fmi3" / "ServoAxis.fmu"), "--set", "ServoAxis.pos_cmd=5",
               "--stop-time", "0.5", "--out", str(tmp_path)])
    out = capsys.readouterr().out
    warnings = [line for line in out.splitlines() if "[warning]" in line]
    assert rc == 0 and not [w for w in warnings if "pos_cmd" in w], out      # (free inputs are named, rightly)
    import csv
    with open(tmp_path / "ServoAxis.csv") as f:
        rows = list(csv.DictReader(f))
    assert float(rows[-1]["ServoAxis.pos"]) == pytest.approx(5.0, abs=0.05)


def test_unreached_in_a_system_of_one_instance_and_in_a_loop():
    from ncfmu.systems import get_system
    from ncfmu.systems.reach import unreached
    alone = get_system("lathe_taper")
    alone.components, alone.connections = [c for c in alone.components if c.name == "x_axis"], []
    assert unreached(alone, {"x_axis.pos_cmd": 5.0}) == {}
    assert "panel.emergency_at" in unreached(get_system("lathe_taper"), {"panel.emergency_at": 12.0})


def test_a_build_keeps_the_kind_asked_for(tmp_path, monkeypatch):
    """``build --pure`` is not undone by the next run: a build not told which kind keeps the recorded one;
    ``--compiled`` (or ``build`` without --pure) switches back."""
    import ncfmu.project as project_module
    from ncfmu.fmi.builder import KIND_FILE

    class Stop(NcfmuError):
        pass
    asked: list[bool] = []

    def build_all(models, dest, only_stale=False, pure=False):
        asked.append(pure)
        raise Stop("recorded")
    monkeypatch.setattr(project_module, "build_all", build_all)
    (tmp_path / "fmus").mkdir()
    with pytest.raises(Stop):
        project_module.build(tmp_path)                  # nothing recorded: compiled, the default
    (tmp_path / "fmus" / KIND_FILE).write_text("pure\n")
    with pytest.raises(Stop):
        project_module.build(tmp_path)                  # what `ncfmu run` does: keeps pure
    kind = (tmp_path / "fmus" / KIND_FILE).read_text
    assert main(["--root", str(tmp_path), "run", "lathe_taper", "--compiled", "--out", str(tmp_path / "o")]) == 2
    assert kind() == "compiled\n"
    assert main(["--root", str(tmp_path), "sweep", "lathe_taper", "--vary", "seq.block[1].Xd=0.4", "--pure",
                 "--out", str(tmp_path / "o")]) == 2
    assert kind() == "pure\n"
    with pytest.raises(Stop):
        project_module.build(tmp_path)                  # pure again, as the sweep asked
    assert main(["--root", str(tmp_path), "build"]) == 2
    assert kind() == "compiled\n"
    assert asked == [False, True, False, True, True, False]


def test_the_mill_reads_tape_marks_a_program_number_and_both_comment_forms():
    from ncfmu.controllers import rs274
    moves = rs274.parse(MILL_PART, (0.0, 0.0))
    assert [(m.element.end, m.line) for m in moves] == [((10.0, 0.0), 4), ((10.0, 10.0), 5)]


def test_program_for_every_variant_of_a_sweep(project, tmp_path, capsys):
    import csv
    part = tmp_path / "square.nc"
    part.write_text(MILL_PART)
    rc = main(["sweep", "mill_contour", "--program", str(part), "--vary", "contour.diameter_delta=0.4,0.8",
               "--workers", "0", "--stop-time", "0.05", "--out", str(tmp_path / "sw")])
    out = capsys.readouterr().out
    assert rc == EXIT_NOT_FINISHED, out        # 0.05 s: the cycle is running, not refused
    with open(tmp_path / "sw" / "summary.csv") as f:
        rows = list(csv.DictReader(f))
    assert [r["status"] for r in rows] == ["unfinished", "unfinished"]
    # the program is one value every variant shares (as --set): a program the reader refuses fails every variant,
    # naming its line
    bad = tmp_path / "bad.nc"
    bad.write_text(MILL_PART.replace("G01 X10.", "G112 X10."))
    rc = main(["sweep", "mill_contour", "--program", str(bad), "--vary", "contour.diameter_delta=0.4,0.8",
               "--workers", "0", "--stop-time", "0.05", "--out", str(tmp_path / "bad")])
    with open(tmp_path / "bad" / "summary.csv") as f:
        rows = list(csv.DictReader(f))
    assert rc == EXIT_NOT_FINISHED and [r["status"] for r in rows] == ["failed", "failed"]
    assert all("G112" in r["error"] for r in rows), rows
