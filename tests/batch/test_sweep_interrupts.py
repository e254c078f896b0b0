"""``ncfmu sweep`` stopped by Ctrl-C or SIGTERM: what ran is kept and said, nothing is left, the rest runs next."""

from __future__ import annotations

import csv
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import psutil  # dask's own dependency
import pytest
from conftest import ROOT

from ncfmu.cli import main

pytestmark = pytest.mark.slow        # dask clusters and whole systems in closed loop

#: 16 lathe_taper variants of ~0.36 s of CPU each, run to the cycle's end (~47-61 s simulated)
VARY = ["--vary", "seq.block[1].Xd=0.3,0.35,0.4,0.45,0.5,0.55,0.6,0.65", "--vary", "seq.block[1].feed=3,4"]


def summary(out: Path) -> dict[str, dict[str, str]]:
    with open(out / "summary.csv", newline="") as f:
        return {r["key"]: r for r in csv.DictReader(f)}


def running_in_group(pgid: int, settle: float = 5.0) -> list[str]:
    """The processes of process group ``pgid`` still running (not an exited one its parent has yet to reap) once
    those already ending have ended: a worker or the forkserver may still be in its exit a few ms after the sweep
    (its command line already gone); one alive ``settle`` s later outlived it."""
    deadline = time.monotonic() + settle
    while True:
        running = []
        for proc in psutil.process_iter(["pid", "status", "cmdline"]):
            try:
                if os.getpgid(proc.pid) == pgid and proc.info["status"] != psutil.STATUS_ZOMBIE:
                    running.append(f"{proc.pid}: {' '.join(proc.info['cmdline'] or [])}")
            except (ProcessLookupError, psutil.NoSuchProcess):
                pass
        if not running or time.monotonic() > deadline:
            return running
        time.sleep(0.05)


def start_sweep(out: Path, workers: int) -> subprocess.Popen:
    """``ncfmu sweep`` of VARY into ``out``, in a process group of its own, as a terminal's job."""
    return subprocess.Popen(sweep_command(out, workers), cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)


def stop(proc: subprocess.Popen, signum: int, to_group: bool, timeout: float) -> str:
    """Send ``signum`` to the sweep (or its whole process group); its stderr once it ended."""
    if to_group:
        os.killpg(proc.pid, signum)
    else:
        proc.send_signal(signum)
    return proc.communicate(timeout=timeout)[1]


def sweep_command(out: Path, workers: int) -> list[str]:
    return [str(Path(sys.executable).with_name("ncfmu")), "sweep", "lathe_taper", *VARY, "--workers", str(workers),
            "--out", str(out)]


@pytest.mark.parametrize("workers, signum, to_group, status, says", [
    (2, signal.SIGTERM, False, 143, "terminated (SIGTERM)"),     # a service manager's stop, to the sweep's pid
    (2, signal.SIGINT, True, 130, "interrupted"),                # Ctrl-C at a terminal: the whole process group
    (2, signal.SIGTERM, True, 143, "terminated (SIGTERM)"),      # systemd's stop (KillMode=control-group): all
    (0, signal.SIGTERM, False, 143, "terminated (SIGTERM)"),
    (0, signal.SIGINT, True, 130, "interrupted"),
])
def test_a_stopped_sweep_keeps_what_ran_says_so_and_the_same_command_runs_the_rest(
        project, tmp_path, workers, signum, to_group, status, says):
    out = tmp_path / "sw"
    proc = start_sweep(out, workers)
    deadline = time.time() + 120
    while time.time() < deadline and len(list((out / "variants").glob("*.csv"))) < 3:
        time.sleep(0.02)
    stderr = stop(proc, signum, to_group, timeout=120)
    assert proc.returncode == status, stderr
    done = summary(out)
    assert 3 <= len(done) < 16
    assert stderr.splitlines() == [f"ncfmu sweep: {says}: {len(done)} of 16 variants done, in "
                                   f"{out / 'summary.csv'}; the same command runs the rest"], stderr
    # every variant that finished has its row and its whole file, and nothing else is in DIR
    for key, row in done.items():
        assert row["status"] == "ok"
        lines = (out / "variants" / f"{key}.csv").read_bytes().count(b"\n")
        assert lines == int(row["rows"]) + 1
    assert sorted(p.name for p in (out / "variants").iterdir()) == sorted(f"{k}.csv" for k in done)
    assert sorted(p.name for p in out.iterdir()) == ["summary.csv", "variants"]
    assert running_in_group(proc.pid) == []         # no worker, nanny or forkserver outlived the sweep
    # the same command again: only the rest runs, and the sweep is whole
    again = subprocess.run(sweep_command(out, workers), cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert again.returncode == 0, again.stderr
    whole = summary(out)
    assert len(whole) == 16 and all(r["status"] == "ok" for r in whole.values())
    assert all(whole[k] == row for k, row in done.items())               # the first run's rows, as they were
    assert len(list((out / "variants").iterdir())) == 16


@pytest.mark.parametrize("signum, to_group, status", [(signal.SIGINT, True, 130), (signal.SIGTERM, False, 143)])
def test_a_sweep_stopped_while_its_cluster_starts_says_one_line_and_leaves_nothing(
        project, tmp_path, signum, to_group, status):
    """The signal while dask starts the workers (the forkserver has forked one): the cluster, half made, is
    closed all the same -- else dask's exit hook failed on it, a traceback, and each worker starting one more."""
    out = tmp_path / "sw"
    proc = start_sweep(out, 2)
    sweeper = psutil.Process(proc.pid)
    deadline = time.time() + 60

    def forking() -> bool:
        try:
            return any("forkserver" in " ".join(p.cmdline()) and p.children() for p in sweeper.children())
        except psutil.Error:
            return False
    while time.time() < deadline and not forking():
        time.sleep(0.005)
    assert not list((out / "variants").glob("*.csv")), "a variant finished before the cluster started"
    stderr = stop(proc, signum, to_group, timeout=60)
    assert proc.returncode == status, stderr
    says = "terminated (SIGTERM)" if signum == signal.SIGTERM else "interrupted"
    assert stderr.splitlines() == [f"ncfmu sweep: {says}: 0 of 16 variants done; the same command runs them"], stderr
    assert list((out / "variants").iterdir()) == [] and not (out / "summary.csv").exists()
    assert running_in_group(proc.pid) == []


def test_a_sweep_stopped_while_its_system_is_built_says_one_line(project, tmp_path, monkeypatch, capsys):
    """A SIGTERM while the system's archive is built or read (its FMUs compiled: minutes, when stale) ends the
    sweep as any other: one line, exit 143, not an Interrupted traceback and exit 1."""
    from ncfmu import project as project_module
    built = project_module.system_archive

    def building(*args, **kwargs):
        os.kill(os.getpid(), signal.SIGTERM)
        return built(*args, **kwargs)
    monkeypatch.setattr(project_module, "system_archive", building)
    scheduler_file = tmp_path / "scheduler.json"        # never reached: no cluster is started here
    scheduler_file.write_text('{"address": "tcp://127.0.0.1:9"}')
    with pytest.raises(SystemExit) as ended:
        main(["sweep", "lathe_taper", *VARY, "--scheduler-file", str(scheduler_file), "--out", str(tmp_path / "sw")])
    assert ended.value.code == 143
    assert capsys.readouterr().err.splitlines() == [
        "ncfmu sweep: terminated (SIGTERM) before any variant ran; the same command runs them"]
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL             # the handler of before, back


def test_a_sweep_stopped_while_it_fetches_a_variants_rows_keeps_that_variant_whole(project, tmp_path, monkeypatch):
    """The client of a remote cluster fetches each variant's rows in chunks (a second and more for a long one):
    a Ctrl-C then waits for the variant to be recorded -- its file whole, its row written, the worker's copy
    removed -- instead of leaving a .csv.part in DIR/variants (or, cut off in the removal, the worker's copy). The
    rows of a variant the worker runs to its end after the client stopped are removed too, not left for good."""
    from dask.distributed import LocalCluster

    from ncfmu import batch
    from ncfmu.batch import SweepStopped, sweep
    from ncfmu.cosim.interrupts import raised_interrupts
    monkeypatch.setattr(batch, "FETCH_CHUNK", 4096)     # ~60 chunks a variant
    fetched = batch.read_rows

    def interrupted_fetch(path: str, offset: int, size: int) -> bytes:
        if offset == 4096:                                # the second chunk: mid-fetch
            os.kill(os.getpid(), signal.SIGINT)
        return fetched(path, offset, size)
    monkeypatch.setattr(batch, "read_rows", interrupted_fetch)
    (tmp_path / "worker").mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "worker"))   # the worker's rows, where this test sees
    out = tmp_path / "sw"
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None,
                      scheduler_kwargs={"dashboard_address": "127.0.0.1:0"}) as cluster:
        with pytest.raises(SweepStopped) as stopped, raised_interrupts():
            sweep("grinder_feed", {"feed.D3": [4.0, 3.0]}, out, scheduler=cluster.scheduler_address, stop_time=3.0,
                  progress=False)
    assert (stopped.value.done, stopped.value.total) == (1, 2)
    (row,) = summary(out).values()
    assert row["status"] == "unfinished" and int(row["rows"]) == 3001     # 3 s of the 32.5 s cycle, every 1 ms
    assert (out / "variants" / f"{row['key']}.csv").read_bytes().count(b"\n") == 3001 + 1
    assert sorted(p.name for p in (out / "variants").iterdir()) == [f"{row['key']}.csv"]
    assert list((tmp_path / "worker").rglob("*.ssp"))                # the worker's folder is the one looked in
    # its copy removed; and the other variant's, which the worker ran to its end after the client stopped
    assert not list((tmp_path / "worker").rglob(f"*{batch.ROWS_SUFFIX}*"))
