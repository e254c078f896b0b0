"""Summary lines say what they mean: the area limiter's blocked mask with its legend, what validate checked."""

from __future__ import annotations

import re

import pytest

from ncfmu.cli import main
from ncfmu.exitcodes import EXIT_NOT_FINISHED
from ncfmu.systems import SYSTEMS, get_system


def _line(out: str, start: str) -> str:
    return next(line.strip() for line in out.splitlines() if line.strip().startswith(start))


@pytest.mark.slow
def test_the_lathe_limiter_alarm_names_the_blocked_direction_and_the_bits(project, capsys, tmp_path):
    # a cut lengthened into the chuck zone (Z <= -45) at 40 mm/s: Z- is blocked at the boundary
    assert main(["run", "lathe_roughing", "--stop-time", "4", "--set", "seq.block[1].Zp=50", "--set",
                 "seq.block[1].feed=40", "--out", str(tmp_path)]) == EXIT_NOT_FINISHED
    line = _line(capsys.readouterr().out, "area limiter:")
    m = re.fullmatch(r"area limiter: ALARM from t = (\d+\.\d{3}) s, blocked z_axis - \(blocked mask 2; bits "
                     r"1 z_axis \+, 2 z_axis -, 4 x_axis \+, 8 x_axis -\)", line)
    assert m, line
    # START at 0.1 s; the infeed X 30 -> 28.5 at accel 500 is a triangle, 2*sqrt(1.5/500) s; then the cut from
    # Z 2 reaches the boundary Z -45 after 47 mm at 40 mm/s plus half a ramp (40/500/2 s)
    assert float(m[1]) == pytest.approx(0.1 + 2 * (1.5 / 500) ** 0.5 + 47 / 40 + 40 / 500 / 2, abs=0.02)


@pytest.mark.slow
def test_the_grinder_limiter_alarm_names_its_own_axes(project, capsys, tmp_path):
    """The table sent back into the headstock zone with the wheel in: Y- (the reference, the table) blocked."""
    program = "M0: Y+D1F7; M1: X+D2F7; M2: Y-D6F7; M3: END; M41: XF7S1; M42: YF7S1; M43: END; M45: END"
    assert main(["run", "grinder_envelope", "--stop-time", "9", "--set", f"feed.program={program}",
                 "--set", "feed.D6=250", "--out", str(tmp_path)]) == EXIT_NOT_FINISHED
    line = _line(capsys.readouterr().out, "area limiter:")
    assert re.fullmatch(r"area limiter: ALARM from t = \d+\.\d{3} s, blocked y_axis - \(blocked mask 2; bits "
                        r"1 y_axis \+, 2 y_axis -, 4 x_axis \+, 8 x_axis -\)", line), line


@pytest.mark.slow                       # fmpy validates every FMU again (test_cli's fast check does it once)
def test_validate_says_what_it_checked(project, capsys):
    assert main(["validate"]) == 0
    out = capsys.readouterr().out.splitlines()
    n_fmus = len(project["fmus"])
    # one .ssv per component that sets parameters (the lathes' spindle drives run on their defaults)
    n_ssv = sum(1 for name in SYSTEMS for c in get_system(name).components if c.parameters)
    assert n_fmus == 7 and len(SYSTEMS) == 5
    assert out[0].startswith(f"checked {n_fmus} FMUs (") and "with fmpy.validation: modelDescription.xml against " \
        "the FMI 2.0 schema" in out[0]
    assert out[1].startswith(f"checked {n_fmus} FMI 3.0 FMUs (") and "against the FMI 3.0 schema" in out[1]
    assert out[2].startswith(f"checked {len(SYSTEMS)} systems (")
    assert "SystemStructure.ssd against the SSP 1.0 schema" in out[2]
    assert f"their {n_ssv} .ssv parameter sets against the SSP 1.0 parameter-values schema" in out[2]
    assert out[-1] == "all FMUs and SSPs valid"


@pytest.mark.slow                       # opens the system twice (the master's own test covers connections fast)
def test_an_input_csv_column_that_is_an_output_is_said_in_good_grammar(project, capsys, tmp_path):
    csv_file = tmp_path / "inputs.csv"
    csv_file.write_text('"time","x_axis.pos"\n0.0,1\n')
    assert main(["run", "lathe_taper", "--stop-time", "0.1", "--input", str(csv_file), "--out", str(tmp_path)]) == 2
    assert capsys.readouterr().err == ("ncfmu run: input CSV column 'x_axis.pos' is an output: only inputs and tunable "
                                         "parameters change during a run\n")
    csv_file.write_text('"time","seq.accel"\n0.0,100\n')
    assert main(["run", "lathe_taper", "--stop-time", "0.1", "--input", str(csv_file), "--out", str(tmp_path)]) == 2
    assert capsys.readouterr().err == ("ncfmu run: input CSV column 'seq.accel' is a fixed parameter: only inputs and "
                                       "tunable parameters change during a run\n")


@pytest.mark.slow
def test_a_program_in_diameters_gets_its_x_as_diameters_too(project, capsys, tmp_path):
    """Before: a program written in diameters (G7) got its summary in radii with no word that they were."""
    from conftest import ROOT
    pockets = (ROOT / "docs" / "examples" / "lathe_pockets.ngc").read_text()     # G7: X as diameter, X60 Z2
    assert main(["run", "lathe_roughing", "--stop-time", "3", "--set", f"seq.program={pockets}",
                 "--out", str(tmp_path)]) == EXIT_NOT_FINISHED
    out = capsys.readouterr().out
    smallest = float(re.search(r"smallest X during the cuts: (\d+\.\d{4}) mm", out)[1])
    end = re.search(r"tool at X (\d+\.\d{4}),", out)[1]
    line = _line(out, "X above is a radius")
    m = re.fullmatch(r"X above is a radius \(the axis\); the program writes X as a diameter; as a diameter: "
                     r"smallest during the cuts (\d+\.\d{4}) mm, tool at the end (\d+\.\d{4}) mm", line)
    assert m, line
    assert float(m[1]) == pytest.approx(2 * smallest, abs=2e-4) and float(m[2]) == pytest.approx(2 * float(end),
                                                                                                 abs=2e-4)
    assert 55.0 < float(m[1]) < 60.0           # the first passes of the 60 mm bar, at most 2 x 1.25 mm deep


@pytest.mark.slow
def test_a_program_in_radii_and_a_register_run_say_so(project, capsys, tmp_path):
    from conftest import ROOT
    shaft = (ROOT / "docs" / "examples" / "lathe_shaft.ngc").read_text()         # G8: X as radius
    assert main(["run", "lathe_roughing", "--stop-time", "1", "--set", f"seq.program={shaft}",
                 "--out", str(tmp_path)]) == EXIT_NOT_FINISHED
    assert _line(capsys.readouterr().out, "X above") == "X above is a radius, as the program writes it"
    assert main(["run", "lathe_roughing", "--stop-time", "1", "--out", str(tmp_path)]) == EXIT_NOT_FINISHED
    assert "X above" not in capsys.readouterr().out                   # the registers: radii, no program
