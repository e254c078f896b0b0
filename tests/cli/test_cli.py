"""The ncfmu command line."""

import csv

import pytest

from ncfmu.cli import main
from ncfmu.exitcodes import EXIT_NOT_FINISHED


def test_run_writes_fmpy_csv_and_summary(project, tmp_path, capsys):
    rc = main(["run", "lathe_taper", "--stop-time", "1.0", "--set", "seq.block[1].Xd=0.25", "--out", str(tmp_path)])
    assert rc == EXIT_NOT_FINISHED
    out = capsys.readouterr().out
    assert "simulated/wall-clock ratio" in out
    with open(tmp_path / "lathe_taper.csv") as f:
        header = next(csv.reader(f))
    assert header[0] == "time" and "x_axis.pos" in header and "seq.subcycle" in header


def test_indexed_set_takes_effect(project, tmp_path):
    from ncfmu.project import simulate
    r = simulate("lathe_taper", stop_time=0.6, start_values={"seq.block[1].Xd": 0.25})
    assert r["seq.sigma_x"].max() == 1.25


def test_unknown_system_instance_variable_are_clear_errors(project, tmp_path, capsys):
    assert main(["run", "lathe_nope", "--out", str(tmp_path)]) == 2
    assert "unknown system 'lathe_nope'" in capsys.readouterr().err
    assert main(["run", "lathe_taper", "--set", "sq.x_start=1", "--out", str(tmp_path)]) == 2
    assert "unknown instance 'sq'" in capsys.readouterr().err
    assert main(["run", "lathe_taper", "--set", "seq.nope=1", "--out", str(tmp_path)]) == 2
    assert "seq has no variable 'nope'" in capsys.readouterr().err


def test_validate_reports_nothing(project, capsys):
    assert main(["validate"]) == 0
    assert "all FMUs and SSPs valid" in capsys.readouterr().out


def test_input_csv_drives_an_unconnected_input(project, tmp_path):
    """An fmpy-style input CSV sets the panel's m_active at 0.2 s: MFIN answers 0.5 s (mfin_delay) later."""
    from ncfmu.project import simulate
    csv_file = tmp_path / "inputs.csv"
    csv_file.write_text('"time","panel.m_active"\n0.0,0\n0.2,3\n')
    r = simulate("lathe_taper", stop_time=1.0, input_csv=csv_file)
    t, mfin = r.time, r["panel.mfin"]
    assert not mfin[t < 0.699].any() and mfin[t > 0.701].all()


@pytest.mark.slow
def test_run_changes_no_file_of_the_checkout(project, tmp_path):
    """A run builds what is missing and nothing else; the checkout (sources, generated SSP and docs,
    built FMUs and archives) is byte-for-byte and timestamp-for-timestamp as before."""
    import os
    import shutil
    import subprocess
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    skip = {".git", "__pycache__", ".pytest_cache", ".hypothesis", ".ruff_cache", ".mypy_cache"}

    def snapshot():
        files = {}
        for dirpath, dirnames, filenames in os.walk(root):
            dirnames[:] = [d for d in dirnames if d not in skip]
            for name in filenames:
                st = os.stat(os.path.join(dirpath, name))
                files[os.path.join(dirpath, name)] = (st.st_size, st.st_mtime_ns)
        return files

    before = snapshot()
    done = subprocess.run([shutil.which("ncfmu"), "run", "mill_contour", "--stop-time", "0.5", "--out", str(tmp_path)],
                          cwd=root, capture_output=True, text=True, timeout=300)
    assert done.returncode == EXIT_NOT_FINISHED, done.stderr
    after = snapshot()
    changed = sorted(p for p in before.keys() | after.keys() if before.get(p) != after.get(p))
    assert changed == []


def test_plot_of_a_csv_without_the_plane_columns_draws_what_it_has(project, tmp_path, capsys):
    """A sweep trajectory recorded with --record x_axis.pos has no Z column: the plot draws X over time and
    leaves the X-Z plane out (it crashed with a KeyError traceback)."""
    import numpy as np

    from ncfmu.cosim.result import Result
    data = np.zeros(50, dtype=[("time", float), ("x_axis.pos", float)])
    data["time"], data["x_axis.pos"] = np.arange(50) * 1e-3, np.linspace(30.0, 29.0, 50)
    Result(data).to_csv(tmp_path / "traj.csv")
    assert main(["plot", str(tmp_path / "traj.csv"), "--system", "lathe_taper", "--png",
                 str(tmp_path / "traj.png")]) == 0, capsys.readouterr().err
    assert (tmp_path / "traj.png").read_bytes()[:4] == b"\x89PNG"


def test_a_run_reads_its_ssp_once(project, tmp_path, monkeypatch):
    """One ``ncfmu run`` of an .ssp opens the archive once: the run, its summary and its warnings of settings that
    reach nothing all use the system as the run read it."""
    import ncfmu.cosim.ssp as ssp
    import ncfmu.project as project_module
    reads = []
    real = ssp.read_ssp

    def counted(*args, **kwargs):
        reads.append(args[0])
        return real(*args, **kwargs)
    monkeypatch.setattr(ssp, "read_ssp", counted)
    monkeypatch.setattr(project_module, "read_ssp", counted)
    from conftest import ROOT
    archive = ROOT / "ssp" / "lathe_taper.ssp"
    assert main(["run", str(archive), "--stop-time", "0.2", "--out", str(tmp_path)]) == EXIT_NOT_FINISHED
    assert len(reads) == 1
