"""Sweeps that scale out: workers that share no files with the client, nothing lost, timeouts."""

from __future__ import annotations

import csv
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT

from ncfmu.batch import sweep
from ncfmu.cli import main
from ncfmu.cosim.result import Result, csv_bytes
from ncfmu.exitcodes import EXIT_NOT_FINISHED
from ncfmu.project import simulate
from ncfmu.systems import report_of

pytestmark = pytest.mark.slow        # whole systems in closed loop: not in the fast subset

D3 = {"feed.D3": [4.0, 3.0, 3.5]}


def summary(out: Path) -> list[dict[str, str]]:
    with open(out / "summary.csv", newline="") as f:
        return list(csv.DictReader(f))


def by_d3(out: Path) -> dict[float, dict[str, str]]:
    return {float(r["feed.D3"]): r for r in summary(out)}


# -- a real dask scheduler and worker, in processes and folders of their own ---------------------------
@pytest.fixture
def dask_cluster(tmp_path):
    """``dask scheduler`` and ``dask worker`` started by hand, each in a working directory of its own (the
    worker's temp dir too), as another user on another machine would: they see none of the client's files."""
    sched_dir, worker_dir = tmp_path / "scheduler", tmp_path / "worker"
    for d in (sched_dir, worker_dir, worker_dir / "tmp"):
        d.mkdir()
    scheduler_file = sched_dir / "scheduler.json"
    env = {k: v for k, v in os.environ.items() if not k.startswith("NCFMU")}
    bin_dir = Path(sys.executable).parent
    procs = [subprocess.Popen([str(bin_dir / "dask"), "scheduler", "--scheduler-file", str(scheduler_file),
                               "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                               "--dashboard-address", "127.0.0.1:0"], cwd=sched_dir, env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    deadline = time.time() + 60
    while not scheduler_file.exists() and time.time() < deadline:
        time.sleep(0.2)
    assert scheduler_file.exists(), "the dask scheduler did not start"
    procs.append(subprocess.Popen([str(bin_dir / "dask"), "worker", "--scheduler-file", str(scheduler_file),
                                   "--nworkers", "1", "--nthreads", "1", "--local-directory", str(worker_dir),
                                   "--no-dashboard"], cwd=worker_dir, env={**env, "TMPDIR": str(worker_dir / "tmp")},
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
    from dask.distributed import Client
    with Client(scheduler_file=str(scheduler_file), timeout=60) as client:
        client.wait_for_workers(1, timeout=60)
    yield scheduler_file, worker_dir
    for p in procs:
        p.terminate()
    for p in procs:
        p.wait(timeout=30)


def test_a_sweep_through_a_hand_started_scheduler_and_worker(project, tmp_path, dask_cluster, monkeypatch):
    """The worker shares no folder with the client: the rows come over the cluster's connection, in chunks."""
    from ncfmu import batch
    monkeypatch.setattr(batch, "FETCH_CHUNK", 4096)     # the client side fetches: ~60 chunks a variant
    scheduler_file, worker_dir = dask_cluster
    client_dir = tmp_path / "client"
    client_dir.mkdir()
    archive = client_dir / "grinder.ssp"                    # the client's own copy, by path
    archive.write_bytes((ROOT / "ssp" / "grinder_feed.ssp").read_bytes())
    out = client_dir / "out"
    # 3 s of a 32.5 s cycle: both variants run to the stop time unfinished, and the sweep says so (exit 1)
    assert main(["sweep", str(archive), "--vary", "feed.D3=4.0,3.0", "--stop-time", "3", "--scheduler-file",
                 str(scheduler_file), "--out", str(out)]) == EXIT_NOT_FINISHED
    rows = summary(out)
    assert [r["status"] for r in rows] == ["unfinished", "unfinished"]
    deepest = {float(r["feed.D3"]): float(r["deepest_x_mm"]) for r in rows}
    assert deepest[4.0] - deepest[3.0] == pytest.approx(1.0, abs=0.003)   # the physics came back
    for r in rows:                                           # the trajectories came back, the client wrote them
        traj = Result.from_csv(out / "variants" / f"{r['key']}.csv")
        assert len(traj.time) == int(r["rows"]) == 3001 and "x_axis.pos" in traj.names
        assert (out / "variants" / f"{r['key']}.csv").stat().st_size > 50 * 4096
    whole = simulate("grinder_feed", stop_time=3.0, start_values={"feed.D3": 4.0})      # byte for byte
    key = next(r["key"] for r in rows if float(r["feed.D3"]) == 4.0)
    assert (out / "variants" / f"{key}.csv").read_bytes() == csv_bytes(whole.data[["time", *report_of(whole).record()]])
    assert sorted(p.name for p in (out / "variants").iterdir()) == sorted(f"{r['key']}.csv" for r in rows)
    # the worker got the system by value: its own cache holds the archive, by content digest
    cached = list((worker_dir / "tmp").glob("ncfmu-sweep-*/*.ssp"))
    assert len(cached) == 1 and cached[0].read_bytes() == archive.read_bytes()
    assert not list(worker_dir.rglob("summary.csv")) and not list(worker_dir.rglob("*.csv"))


# -- nothing lost --------------------------------------------------------------------------------------
def test_a_second_sweep_merges_into_the_summary(project, tmp_path):
    sweep("grinder_feed", {"feed.D3": [4.0, 3.0]}, tmp_path, workers=0, stop_time=2.0, progress=False)
    calls = []
    sweep("grinder_feed", {"feed.D3": [3.0, 3.5, 2.5]}, tmp_path, workers=0, stop_time=2.0, progress=False,
          on_done=calls.append)
    assert sorted(float(c["feed.D3"]) for c in calls) == [2.5, 3.5]           # 3.0 was done already
    assert sorted(by_d3(tmp_path)) == [2.5, 3.0, 3.5, 4.0]                     # no row dropped
    assert len(list((tmp_path / "variants").glob("*.csv"))) == 4


def test_an_interrupted_sweep_resumes_without_trusting_partial_files(project, tmp_path):
    sweep("grinder_feed", D3, tmp_path, workers=0, stop_time=2.0, progress=False)
    rows = by_d3(tmp_path)
    truncated = tmp_path / "variants" / f"{rows[3.0]['key']}.csv"
    lines = truncated.read_text().splitlines(keepends=True)
    truncated.write_text("".join(lines[: len(lines) // 2]))                   # killed while writing (not ours)
    (tmp_path / "variants" / "abc.csv.part").write_text("time,x\n0,")           # a temp file left behind
    # the rows of a killed local worker, complete and not: in DIR/variants, never renamed to a result
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    pid = int(dead.stdout)                                                      # a process that has ended
    killed = [tmp_path / "variants" / f"{rows[3.5]['key']}-{pid}.rows", tmp_path / "variants" / f"x-{pid}.rows.partial"]
    for path in killed:
        path.write_text("time,x_axis.pos\n0,0\n")
    calls = []
    again = sweep("grinder_feed", D3, tmp_path, workers=0, stop_time=2.0, progress=False, on_done=calls.append)
    assert [float(c["feed.D3"]) for c in calls] == [3.0]                        # only the damaged one re-ran
    assert [r["status"] for r in again] == ["unfinished"] * 3                  # 2 s of the cycle
    assert len(truncated.read_text().splitlines()) == int(by_d3(tmp_path)[3.0]["rows"]) + 1 == 2002
    assert not list(tmp_path.rglob("*.part")) and not any(path.exists() for path in killed)
    assert sorted(p.name for p in (tmp_path / "variants").iterdir()) == sorted(f"{r['key']}.csv" for r in again)


def test_a_worker_killed_mid_variant_leaves_nothing_in_dir(project, tmp_path):
    """A local cluster's worker SIGKILLed while it writes a variant's rows into DIR/variants: dask runs the variant
    again on the other worker and the sweep completes -- with the killed worker's rows file gone from DIR, not
    left there beside the results until some later sweep into DIR."""
    import signal
    import threading
    killed: list[int] = []
    finished = threading.Event()

    def kill_the_first_writer() -> None:
        while not finished.is_set() and not killed:
            for rows in (tmp_path / "variants").glob("*.rows.partial"):
                if rows.stat().st_size > 100_000:           # mid-variant: ~1/20 of its rows written
                    pid = int(rows.name.split(".")[0].rsplit("-", 1)[1].partition("@")[0])   # <key>-<pid>@<machine>
                    os.kill(pid, signal.SIGKILL)               # a worker process of the cluster, not this one
                    killed.append(pid)
                    break
            time.sleep(0.01)
    watcher = threading.Thread(target=kill_the_first_writer, daemon=True)
    watcher.start()
    try:       # a feed 100x slower: the cycle never ends, the variant runs to the limit (~0.6 s of CPU)
        rows = sweep("grinder_feed", {"feed.F1": [0.0002]}, tmp_path, workers=2, stop_time=200.0,
                     output_interval=0.01, progress=False)
    finally:
        finished.set()
        watcher.join()
    assert len(killed) == 1
    assert rows[0]["status"] == "unfinished" and int(rows[0]["rows"]) == 20001       # run again, to the end
    assert sorted(p.name for p in (tmp_path / "variants").iterdir()) == [f"{rows[0]['key']}.csv"]
    assert len((tmp_path / "variants" / f"{rows[0]['key']}.csv").read_text().splitlines()) == 20002


def test_a_variants_folder_that_refuses_files_stops_the_sweep_and_fails_no_variant(project, tmp_path, monkeypatch,
                                                                                    capsys):
    """DIR/variants not writable (another user's folder, a read-only share): one line naming the folder, exit 2,
    before any variant runs -- not every variant recorded as ``failed`` (a failed variant counts as done: the
    next sweep, the folder fixed, would never run it)."""
    import builtins
    import errno
    out = tmp_path / "sw"
    variants = out / "variants"
    variants.mkdir(parents=True)
    variants.chmod(0o555)
    real_open = builtins.open

    def refused(file, mode="r", *args, **kwargs):     # as the system refuses anyone but root (this may be root)
        if isinstance(file, (str, os.PathLike)) and set(mode) & set("wax+") and \
                Path(file).resolve().parent == variants.resolve():
            raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(file))
        return real_open(file, mode, *args, **kwargs)
    monkeypatch.setattr(builtins, "open", refused)
    try:
        status = main(["sweep", "grinder_feed", "--vary", "feed.D3=4.0", "--workers", "0", "--stop-time", "1",
                       "--out", str(out)])
    finally:
        monkeypatch.undo()
        variants.chmod(0o755)
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert status == 2 and len(lines) == 1 and str(variants) in lines[0] and "Permission denied" in lines[0], lines
    assert not (out / "summary.csv").exists() and list(variants.iterdir()) == []
    calls = []           # the folder fixed: the variant runs
    sweep("grinder_feed", {"feed.D3": [4.0]}, out, workers=0, stop_time=1.0, progress=False, on_done=calls.append)
    assert [c["status"] for c in calls] == ["unfinished"] and int(calls[0]["rows"]) == 1001


def test_a_second_sweep_into_the_same_dir_leaves_the_running_ones_rows_alone(project, tmp_path):
    """A second sweep into a DIR while a first one runs there (README: a second sweep merges into it): its start
    and end remove the rows files of dead workers only -- not the one the first sweep's worker is writing, whose
    variant was recorded ``failed`` (FileNotFoundError at its rename), for good: a failed variant is done."""
    out, variants = tmp_path / "sw", tmp_path / "sw" / "variants"
    # the first: a feed 100x slower, the cycle never ends: ~2.5 s of CPU to its 600 s limit
    first = subprocess.Popen([sys.executable, "-m", "ncfmu.cli", "sweep", "grinder_feed", "--vary", "feed.F1=0.0002",
                              "--workers", "0", "--stop-time", "600", "--output-interval", "0.01", "--out", str(out)],
                             stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 120
        while not list(variants.glob("*.rows.partial")) and first.poll() is None and time.monotonic() < deadline:
            time.sleep(0.02)
        second = sweep("grinder_feed", {"feed.D3": [4.0]}, out, workers=0, stop_time=1.0, progress=False)
        running = first.poll() is None
    finally:
        said = first.communicate(timeout=300)[0]
    assert running, "the first sweep ended before the second one: nothing was tested"
    assert second[0]["status"] == "unfinished" and (variants / f"{second[0]['key']}.csv").is_file()
    assert first.returncode == EXIT_NOT_FINISHED and "1 unfinished, 0 failed" in said, said
    rows = {r["key"]: r for r in summary(out)}
    # both sweeps' rows: the first's last write, a second after the second's, merged into what it found
    assert sorted(rows) == sorted([second[0]["key"], *(k for k, r in rows.items() if r["feed.F1"] == "0.0002")])
    assert rows[second[0]["key"]]["feed.D3"] == "4.0" and rows[second[0]["key"]]["status"] == "unfinished"
    row = next(r for r in rows.values() if r["feed.F1"] == "0.0002")
    assert row["status"] == "unfinished" and int(row["rows"]) == 60001
    assert len((variants / f"{row['key']}.csv").read_text().splitlines()) == 60002
    assert not list(variants.glob("*.rows*")) and not list(out.rglob("*.part"))


def test_a_sweeps_start_removes_only_the_temporary_files_of_processes_that_ended(project, tmp_path):
    """A temporary file (``NAME.<pid>.part``: a summary or a fetched trajectory being written) is another
    sweep's to rename while its process runs -- removing it made that sweep fail at its rename -- and a leftover
    once the process ended."""
    alive = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    variants = tmp_path / "variants"
    variants.mkdir()
    try:
        theirs = [tmp_path / f"summary.csv.{alive.pid}.part", variants / f"abc.csv.{alive.pid}.part"]
        left = [tmp_path / f"summary.csv.{int(dead.stdout)}.part", variants / f"abc.csv.{int(dead.stdout)}.part",
                variants / "abc.csv.part"]                  # a pid that ended; a name from before pids
        for path in theirs + left:
            path.write_text("time,x\n0,")
        sweep("grinder_feed", {"feed.D3": [4.0]}, tmp_path, workers=0, stop_time=0.5, progress=False)
        assert all(path.exists() for path in theirs) and not any(path.exists() for path in left)
    finally:
        alive.kill()
        alive.wait()


def test_duplicates_and_equal_numbers_are_one_variant(project, tmp_path):
    rows = sweep("grinder_feed", {"feed.D3": [4, 4.0, 3.5, 4, 3.50]}, tmp_path, workers=0, stop_time=1.0,
                 progress=False)
    assert len(rows) == 2 and len(summary(tmp_path)) == 2
    calls = []
    sweep("grinder_feed", {"feed.D3": [4.0, 3.5]}, tmp_path, workers=0, stop_time=1.0, progress=False,
          on_done=calls.append)
    assert calls == []                                                          # 4 and 4.0: the same variant


def test_record_and_output_interval_keep_what_is_asked(project, tmp_path):
    rows = sweep("grinder_feed", {"feed.D3": [4.0]}, tmp_path, workers=0, stop_time=2.0, progress=False,
                 record=["x_axis.pos", "feed.x_cmd"], output_interval=0.01)
    traj = Result.from_csv(tmp_path / "variants" / f"{rows[0]['key']}.csv")
    assert traj.names == ["x_axis.pos", "feed.x_cmd"]
    assert np.allclose(np.diff(traj.time), 0.01) and len(traj.time) == 201
    # the default: the axis position and what the metrics read, every step
    rows = sweep("grinder_feed", {"feed.D3": [3.0]}, tmp_path / "default", workers=0, stop_time=2.0,
                 progress=False)
    traj = Result.from_csv(tmp_path / "default" / "variants" / f"{rows[0]['key']}.csv")
    assert {"x_axis.pos", "x_axis.following_error", "feed.pc", "feed.alarm"} <= set(traj.names)
    assert len(traj.names) < 12 and len(traj.time) == 2001


@pytest.mark.parametrize("args, says", [
    (["--record", "x_axis.nope"], "--record 'x_axis.nope': not an output"),
    (["--output-interval", "0.0015"], "--output-interval 0.0015: must be a whole multiple"),
    (["--timeout", "-1"], "--timeout -1.0: must be a number > 0"),
])
def test_bad_sweep_options_are_one_line_and_exit_2(project, tmp_path, args, says):
    proc = subprocess.run([sys.executable, "-m", "ncfmu.cli", "sweep", "grinder_feed", "--vary", "feed.D3=4.0",
                           "--workers", "0", "--out", str(tmp_path), *args], capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 2, proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and says in lines[0], proc.stderr


# -- timeouts ------------------------------------------------------------------------------------------
@pytest.fixture
def servo_only(project, tmp_path):
    """A system of one native servo axis and nothing else: a sub-step of 1 µs makes a variant ~10x slower."""
    from ncfmu.cosim.ssp import System, pack, write_system
    from ncfmu.systems.compose import component
    system = System("servo_only", [component("x_axis", "ServoAxis", pos_start=0.0)], [], stop_time=20.0)
    folder = write_system(system, tmp_path / "systems")
    return pack(folder, ROOT / "fmus", tmp_path / "servo_only.ssp")


def test_a_variant_over_its_timeout_is_recorded_and_the_sweep_goes_on(servo_only, tmp_path):
    # how long a plain variant takes here, now (the second: the system already open), and a slow one: the
    # timeout sits between them, in the geometric middle (the slow one costs ~5x)
    probe = sweep(str(servo_only), {"x_axis.substep": [1.5e-4, 1e-4, 1e-6]}, tmp_path / "probe", workers=0,
                  progress=False)
    plain, slow = float(probe[1]["wall_time"]), float(probe[2]["wall_time"])
    assert slow > 3 * plain, (plain, slow)
    rows = sweep(str(servo_only), {"x_axis.substep": [1e-4, 1e-6, 2e-4]}, tmp_path / "out", workers=1,
                 progress=False, timeout=(plain * slow) ** 0.5)
    assert [r["status"] for r in rows] == ["ok", "timeout", "ok"], rows
    assert "over the time allowed" in rows[1]["error"]
    assert not (tmp_path / "out" / "variants" / f"{rows[1]['key']}.csv").exists()
    # the worker was usable after the timeout: the variant after it ran to the end
    assert float(rows[2]["sim_time"]) == pytest.approx(20.0)


@pytest.mark.slow
def test_a_local_cluster_leaves_port_8787_alone():
    """dask's scheduler serves HTTP even with the dashboard off, on 8787 unless told otherwise: with that port
    taken (another cluster, a notebook) every sweep warned 'Port 8787 is already in use'. Ours uses a free port
    of the loopback."""
    import socket
    import warnings

    from ncfmu.batch import local_cluster
    holder = socket.socket()
    try:
        holder.bind(("0.0.0.0", 8787))          # taken now, by this test or by someone else already
        holder.listen()
    except OSError:
        pass
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            with local_cluster(1) as cluster:
                http = cluster.scheduler.http_server
                assert (http.address, http.port != 8787) == ("127.0.0.1", True)
    finally:
        holder.close()
    assert not [w for w in caught if "already in use" in str(w.message)]


@pytest.mark.slow
def test_a_local_cluster_spends_nothing_on_the_dashboard_it_does_not_serve():
    """A sweep's worker ran dask's statistical profiler (a thread sampling the variant's stack every 10 ms), its
    event-loop tick every 20 ms and its system monitor every 0.5 s, all for a dashboard that is off: ~4 % of a
    core beside each worker (bench/sweep_cpu.py). The local cluster's scheduler and workers run with them off or
    slow; the client's own dask settings are left as they were."""
    import dask
    from dask.distributed import Client

    from ncfmu.batch import local_cluster

    def settings() -> tuple:
        return (dask.config.get("distributed.worker.profile.enabled"),
                dask.config.get("distributed.admin.tick.interval"),
                dask.config.get("distributed.admin.system-monitor.interval"))
    before = settings()
    with local_cluster(1) as cluster, Client(cluster) as client:
        on_worker = next(iter(client.run(settings).values()))
        callbacks = cluster.scheduler.periodic_callbacks      # the scheduler, in this process
        scheduler = (callbacks["tick"].callback_time, callbacks["monitor"].callback_time)
    assert on_worker == (False, "1s", "10s")
    assert scheduler == (1000.0, 10000.0)             # ms
    assert settings() == before

