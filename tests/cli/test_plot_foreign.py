"""``ncfmu plot`` of CSVs ncfmu did not write: what fmpy's ``write_csv`` writes (Booleans as True/False) for a
single FMU, drawn as signals over time without asking for ``--system``; a known system's CSV still gets its
system plot, also when fmpy wrote it."""

from __future__ import annotations

import fmpy
import numpy as np
import pytest
from conftest import ROOT
from fmpy.util import write_csv

from ncfmu import plots
from ncfmu.cli import main
from ncfmu.cosim.result import Result


@pytest.fixture(scope="module")
def servo_step(project):
    """fmpy itself simulates the ServoAxis FMU alone: a 1 mm position step, recorded every 1 ms for 0.3 s."""
    return fmpy.simulate_fmu(str(ROOT / "fmus" / "ServoAxis.fmu"), stop_time=0.3, step_size=1e-3,
                             output_interval=1e-3, start_values={"pos_cmd": 1.0})


@pytest.fixture(scope="module")
def taper_1s(project):
    """ncfmu runs lathe_taper for 1 s (shared by the tests of a known system's CSV)."""
    from ncfmu.project import simulate
    return simulate("lathe_taper", stop_time=1.0)


def test_fmpy_csv_of_a_single_fmu_reads_back_exactly(servo_step, tmp_path):
    csv = tmp_path / "servo.csv"
    write_csv(csv, servo_step)
    assert "True" in csv.read_text() or "False" in csv.read_text()          # what fmpy's own read_csv cannot read
    result = Result.from_csv(csv)
    assert result.names == list(servo_step.dtype.names[1:])
    for name in ("time", "pos", "vel", "following_error", "torque"):
        assert np.array_equal(result.data[name], servo_step[name]), name
    for name in ("in_position", "limited"):
        assert result.data[name].dtype == np.bool_ and np.array_equal(result.data[name], servo_step[name]), name
    # the physics is what was recorded: the axis reaches the 1 mm command and reports in position
    assert result["pos"][-1] == pytest.approx(1.0, abs=0.01) and result["in_position"][-1]


def test_plot_of_a_single_fmus_fmpy_csv_draws_its_signals(servo_step, tmp_path, capsys, monkeypatch):
    csv = tmp_path / "servo.csv"
    write_csv(csv, servo_step)
    calls = []
    monkeypatch.setattr(plots, "plot_signals", lambda r, p, _f=plots.plot_signals: calls.append(r) or _f(r, p))
    assert main(["plot", str(csv)]) == 0, capsys.readouterr().err
    png = tmp_path / "servo.png"
    assert capsys.readouterr().out.strip() == str(png)
    assert png.read_bytes()[:4] == b"\x89PNG"
    assert len(calls) == 1
    panels = plots.signal_panels(calls[0])
    # each changing number in a panel of its own, in the file's order; the Booleans together on one
    assert panels.numbers == ["pos", "vel", "following_error", "torque"]
    assert panels.booleans == ["in_position", "limited"]
    assert panels.constant == {}


def test_a_known_systems_csv_written_by_fmpy_gets_the_system_plot(taper_1s, tmp_path, capsys, monkeypatch):
    run = taper_1s
    assert run.data["seq.busy"].dtype == np.bool_
    csv = tmp_path / "lathe_taper.csv"
    write_csv(csv, run.data)
    assert ",True," in csv.read_text() or ",True\n" in csv.read_text()
    drawn = []
    monkeypatch.setattr(plots, "plot_result", lambda r, p, _f=plots.plot_result: drawn.append(r) or _f(r, p))
    assert main(["plot", str(csv)]) == 0, capsys.readouterr().err
    assert [r.system for r in drawn] == ["lathe_taper"]
    assert np.array_equal(drawn[0]["x_axis.pos"], run["x_axis.pos"])
    assert (tmp_path / "lathe_taper.png").read_bytes()[:4] == b"\x89PNG"


def test_a_csv_named_after_a_system_but_without_its_axes_is_drawn_as_signals(servo_step, tmp_path, capsys,
                                                                             monkeypatch):
    """A single FMU's CSV saved as lathe_taper.csv: the lathe plot would be empty, the signals are drawn."""
    csv = tmp_path / "lathe_taper.csv"
    write_csv(csv, servo_step)
    calls = []
    monkeypatch.setattr(plots, "plot_signals", lambda r, p, _f=plots.plot_signals: calls.append(r) or _f(r, p))
    assert main(["plot", str(csv)]) == 0, capsys.readouterr().err
    assert len(calls) == 1


def test_constant_signals_are_listed_not_drawn(tmp_path):
    data = np.zeros(20, dtype=[("time", float), ("x_cmd", float), ("x_vff", float), ("block_no", float),
                               ("alarm", bool)])
    data["time"] = np.arange(20) * 0.01
    data["x_cmd"] = np.linspace(30.0, 29.0, 20)
    data["block_no"] = 1.0
    panels = plots.signal_panels(Result(data))
    assert panels.numbers == ["x_cmd"]
    assert panels.constant == {"x_vff": 0.0, "block_no": 1.0}
    assert panels.booleans == ["alarm"]


@pytest.mark.parametrize("text, says", [
    ("", "empty"),
    ('"time","pos"\n', "no rows"),
    ('"pos","time"\n1,0\n', "first column 'time'"),
    ('"time","pos"\n0,1\n0.1,abc\n', "line 3: pos = 'abc': not a number or True/False"),
    ('"time","pos"\n0,1\n0.1\n', "line 3: 1 values for 2 columns"),
    ('"time","pos","pos"\n0,1,1\n', "column 'pos' twice"),
    ('"time","pos"\nnan,1\n', "line 2: time must be finite"),
])
def test_a_bad_result_csv_is_one_line(tmp_path, capsys, text, says):
    csv = tmp_path / "bad.csv"
    csv.write_text(text)
    assert main(["plot", str(csv)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("ncfmu plot: ") and "\n" not in err and says in err, err


def test_ncfmus_own_csv_reads_back_as_fmpy_reads_it(taper_1s, tmp_path):
    """Our CSV (Booleans as 0/1) reads back number for number, and as fmpy's read_csv reads it."""
    from fmpy.util import read_csv
    run = taper_1s
    csv = run.to_csv(tmp_path / "lathe_taper.csv")
    ours, theirs = Result.from_csv(csv).data, read_csv(str(csv))
    assert ours.dtype.names == run.data.dtype.names == theirs.dtype.names
    for name in run.data.dtype.names:
        assert np.array_equal(ours[name], run.data[name].astype(np.float64)), name
        assert np.array_equal(ours[name], theirs[name]), name
