"""The command line's own mistakes: one line ``ncfmu <command>: <what is wrong>``, exit 2, never a traceback, the
usage block or a hang. Each case runs the console script in a process of its own, with a timeout: a hang fails."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import ROOT

NCFMU = str(Path(sys.executable).parent / "ncfmu")
SWEEP = ["sweep", "lathe_taper", "--vary", "seq.block[1].Xd=0.4", "--stop-time", "0.05"]


def ncfmu(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([NCFMU, *args], capture_output=True, text=True, timeout=timeout, cwd=ROOT)


def refused(proc: subprocess.CompletedProcess, command: str, *says: str) -> str:
    """The one line of stderr, after checking exit status 2, no traceback and the ``ncfmu <command>: `` prefix."""
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert proc.returncode == 2, (proc.returncode, proc.stderr[-1500:])
    assert len(lines) == 1, proc.stderr[-1500:]
    assert "Traceback" not in proc.stderr and "usage:" not in proc.stderr, proc.stderr[-1500:]
    prefix = f"ncfmu {command}: " if command else "ncfmu: "
    assert lines[0].startswith(prefix), lines[0]
    for text in says:
        assert text in lines[0], lines[0]
    return lines[0]


# -- argparse's own errors: one line, the command named ----------------------------------------------------
@pytest.mark.parametrize("args, command, says", [
    (["run", "--step", "-1e-3"], "run", ["--step -0.001: must be > 0"]),
    (["run", "--step", "-0.001"], "run", ["--step -0.001: must be > 0"]),
    (["run", "--step", "0"], "run", ["--step 0.0: must be > 0"]),
    (["run", "--stop-time", "-5"], "run", ["--stop-time -5.0: must be > 0"]),
    (["run", "--stop-time", "nan"], "run", ["--stop-time nan: must be > 0 and finite"]),
    (["run", "--stop-time", "inf"], "run", ["--stop-time inf: must be > 0 and finite"]),
    (["run", "--branch-at", "-1e-3", "--branch-set", "panel.start_at=1"], "run", ["--branch-at -0.001: must be > 0"]),
    (["run", "--set"], "run", ["argument --set: expected one argument"]),
    (["run", "--mode", "nosuch"], "run", ["argument --mode: invalid choice: 'nosuch'"]),
    (["run", "--step", "fast"], "run", ["argument --step: 'fast': must be a number in ASCII decimal"]),
    (["validate", "extra"], "validate", ["unrecognized arguments: extra"]),
    (["run", "lathe_taper", "extra"], "run", ["unrecognized arguments: extra"]),
    (["sweep", "lathe_taper", "--out", "x"], "sweep", ["the following arguments are required: --vary"]),
    ([*SWEEP, "--out", "x", "--workers", "two"], "sweep",
     ["argument --workers: 'two': must be a whole number in ASCII digits 0-9"]),
    ([*SWEEP, "--out", "x", "--workers", "1", "--scheduler", "tcp://127.0.0.1:1"], "sweep",
     ["argument --scheduler: not allowed with argument --workers"]),
    ([*SWEEP, "--out", "x", "--connect-timeout", "-1"], "sweep", ["--connect-timeout -1.0: must be > 0"]),
    ([], "", ["the following arguments are required: command"]),
    (["nosuch"], "", ["argument command: invalid choice: 'nosuch'"]),
])
def test_argument_errors_are_one_line_naming_the_command(tmp_path, args, command, says):
    refused(ncfmu(*args), command, *says)


def test_help_still_prints_the_usage(tmp_path):
    proc = ncfmu("run", "--help")
    assert proc.returncode == 0 and "usage: ncfmu run" in proc.stdout and "--stop-time" in proc.stdout


# -- run: times and the output folder ----------------------------------------------------------------------
@pytest.mark.slow
@pytest.mark.parametrize("args, says", [
    (["--stop-time", "1e308"], ["stop time 1e+308 s at a step of 0.001 s", "shorten the run"]),
    (["--step", "1e-300", "--stop-time", "1"], ["stop time 1 s at a step of 1e-300 s", "shorten the run"]),
    (["--branch-at", "1e308", "--branch-set", "panel.start_at=1"], ["branch time 1e+308 s must lie inside the run"]),
])
def test_a_run_too_long_to_record_is_one_line(project, tmp_path, args, says):
    refused(ncfmu("run", "lathe_roughing", "--out", str(tmp_path), *args), "run", *says)


@pytest.mark.slow
def test_out_naming_a_file_or_an_impossible_folder_is_refused_before_the_run(project, tmp_path):
    existing = tmp_path / "results.csv"
    existing.write_text("keep me\n")
    dangling = tmp_path / "latest"                    # a link to a folder since removed (or on a share not mounted)
    dangling.symlink_to(tmp_path / "runs" / "2026-12-04")
    for out, says in ((existing, "is a file, not a folder"), (existing / "sub", "cannot make the folder"),
                      (Path("/proc/ncfmu-no-such/out"), "cannot make the folder"),
                      (dangling, f"a symbolic link to {tmp_path / 'runs' / '2026-12-04'}, which does not exist")):
        proc = ncfmu("run", "lathe_taper", "--out", str(out))
        refused(proc, "run", f"--out {out}", says)
        assert proc.stdout == ""                      # refused before the 50 s run, not after it
    assert existing.read_text() == "keep me\n"


# -- sweep: the output folder and the cluster connection ----------------------------------------------------
@pytest.mark.slow
def test_sweep_out_naming_a_file_is_refused(project, tmp_path):
    existing = tmp_path / "results.csv"
    existing.write_text("keep me\n")
    refused(ncfmu(*SWEEP, "--workers", "0", "--out", str(existing)), "sweep", f"--out {existing}",
            "is a file, not a folder")
    assert existing.read_text() == "keep me\n"


@pytest.mark.slow
def test_sweep_with_negative_workers_is_refused_at_once(project, tmp_path):
    refused(ncfmu(*SWEEP, "--workers", "-1", "--out", str(tmp_path / "o"), timeout=20), "sweep",
            "--workers -1: must be >= 0")


@pytest.mark.slow
@pytest.mark.parametrize("timeout_args, within", [([], 5.0), (["--connect-timeout", "1"], 1.0)])
def test_sweep_to_a_scheduler_nobody_runs_ends_within_the_connect_timeout(project, tmp_path, timeout_args, within):
    """Nothing listens on port 1: refused once the connect timeout (default 5 s) has passed, not after dask's 30 s."""
    proc = ncfmu(*SWEEP, "--scheduler", "tcp://127.0.0.1:1", *timeout_args, "--out", str(tmp_path / "o"),
                 timeout=25)
    refused(proc, "sweep", "--scheduler tcp://127.0.0.1:1", f"no dask scheduler answered within {within:g} s")


@pytest.mark.slow
def test_sweep_with_a_scheduler_file_that_does_not_exist_is_refused_at_once(project, tmp_path):
    """dask waits for the file to appear, for ever: a file that is not there is refused before that."""
    missing = tmp_path / "nonexistent.json"
    proc = ncfmu(*SWEEP, "--scheduler-file", str(missing), "--out", str(tmp_path / "o"), timeout=20)
    refused(proc, "sweep", f"--scheduler-file {missing}", "no such file")


@pytest.mark.slow
@pytest.mark.parametrize("content, says", [
    (json.dumps({"address": "tcp://127.0.0.1:1"}), "no dask scheduler answered within 1 s"),
    ("this is not json", "not a dask scheduler file"),
    (json.dumps({"id": "x"}), "not a dask scheduler file"),
])
def test_sweep_with_a_scheduler_file_nobody_answers_is_one_line(project, tmp_path, content, says):
    sched = tmp_path / "scheduler.json"
    sched.write_text(content)
    proc = ncfmu(*SWEEP, "--scheduler-file", str(sched), "--connect-timeout", "1", "--out", str(tmp_path / "o"),
                 timeout=25)
    refused(proc, "sweep", f"--scheduler-file {sched}", says)


@pytest.mark.slow
def test_sweep_to_a_real_scheduler_without_a_worker_is_one_line(project, tmp_path):
    """A running ``dask scheduler`` with no worker would take the variants and wait for ever."""
    import time
    sched = tmp_path / "scheduler.json"
    proc = subprocess.Popen([str(Path(sys.executable).parent / "dask"), "scheduler", "--scheduler-file", str(sched),
                             "--port", "0", "--dashboard-address", "127.0.0.1:0"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=tmp_path)
    try:
        deadline = time.monotonic() + 60
        while not sched.exists() and time.monotonic() < deadline:
            time.sleep(0.1)
        assert sched.exists(), "the dask scheduler did not start"
        address = json.loads(sched.read_text())["address"]
        refused(ncfmu(*SWEEP, "--scheduler-file", str(sched), "--connect-timeout", "1", "--out",
                      str(tmp_path / "o"), timeout=25),
                "sweep", f"--scheduler-file {sched}", f"the scheduler at {address} has no worker")
    finally:
        proc.terminate()
        proc.wait(timeout=30)
