"""Parameter sweeps on dask.distributed, with workers that need none of the client's files.

    from ncfmu.batch import sweep
    rows = sweep("lathe_roughing", {"seq.block[1].Xd": [0.4, 0.5, 0.6]}, out="sweep_xd", workers=2)

What goes where:

- The client reads the system's ``.ssp`` once and ships its bytes to the workers (scattered once, to
  every worker). A worker keeps them in its own cache (``<its temp dir>/ncfmu-sweep-<uid>/<digest>.ssp``,
  by content digest), opens the system once per process (FMUs instantiated once, ``fmi2Reset`` between
  variants) and sends back the variant's row (status, error, wall time, metrics). A worker needs ncfmu
  installed and nothing else: no path of the client's, no shared folder.
- Memory does not grow with a variant's length, on the worker or the client: the worker's run keeps no
  trajectory -- its rows stream into a CSV file and into the report's accumulator, which computes the metrics
  on the fly from every step. A worker on the client's machine (a local cluster's, a serial sweep) writes the
  file into ``out/variants/`` (``<key>-<pid>@<machine>.rows``) and the client renames it to ``<key>.csv``: no
  copy. Any other worker writes it in its own temp dir (``ncfmu-sweep-<uid>/rows/``); the client fetches it from that
  worker in chunks of ``FETCH_CHUNK`` bytes (through the cluster's own connection: no shared folder) and the
  worker deletes it (a file whose client went away before fetching it stays in that folder).
- The client alone writes ``out`` (but for those rows files): ``out/variants/<key>.csv`` (fmpy's CSV layout:
  ``time``, then one column per ``INSTANCE.VARIABLE``) and ``out/summary.csv``, each atomically (a temporary
  file, then a rename); an ``out/variants`` that takes no file is refused before any variant runs. A
  variant stopped by its timeout or an FMU error leaves the rows it recorded so far (a valid CSV, whole rows)
  as ``out/variants/<key>.csv.partial``, its row says how many (``rows``) and up to when (``sim_time``,
  with the metrics of those rows).
- Results that scale: ``record`` names the variables kept (default: the axes' positions and what the summary
  metrics read), ``output_interval`` keeps every k-th step.
- Nothing lost: a sweep into an existing ``out`` merges into its summary (rows of other variants are kept);
  a variant whose row and trajectory file (with the row count the summary says) are there is not run again;
  leftovers of an interrupted run (``*.part``, a worker's ``*.rows`` and ``*.rows.partial``) are removed, and
  the rows file of a worker killed mid-variant when the sweep ends; a variant without a row is run again.
  Values are canonical: ``8`` and ``8.0`` are one variant, duplicates are dropped.
- ``timeout`` (s) per variant: the worker's master stops at the deadline (checked every 64 steps), the
  variant is recorded as ``timeout`` and the worker goes on with the next one.
"""

from __future__ import annotations

import contextlib
import csv
import errno
import hashlib
import io
import itertools
import json
import logging
import math
import multiprocessing
import os
import signal
import sys
import tempfile
import threading
import time
import uuid
import xml.etree.ElementTree as ET
import zipfile
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .cosim.interrupts import Interrupted, handled_signals, held_interrupts, raise_pending
from .errors import NcfmuError, SimulationTimeout, SystemDefinitionError
from .files import atomic_file, machine_id, write_atomic, writer_id
from .systems.outcome import RAN, STATUSES

if TYPE_CHECKING:
    from .cosim.ssp import System
    from .project import OpenSystem

SUMMARY = "summary.csv"
# A variant's status, as ``ncfmu run`` judges a run (:mod:`ncfmu.systems.outcome`): ``ok`` (the work done, every
# cycle of the system's report finished, the part within tolerance), ``crashed`` (the part check saw a crash:
# the run ended there), ``out_of_tolerance``, ``unfinished`` (the stop-time limit reached with a cycle still
# running or never started -- the error column says ``cycle not finished by t = <stop> s`` --, an alarm, or the
# part not judged), ``failed`` (refused, or an FMU failed: the error says why), ``timeout``.
# (:data:`ncfmu.systems.outcome.STATUSES`). A variant of a status in ``RAN`` has its trajectory file written.

#: Bytes of a variant's trajectory file per message from a worker to the client.
FETCH_CHUNK = 2 ** 20
#: A running variant's rows file, ``<key>-<pid>@<machine>.rows`` (``.rows.partial`` while written,
#: :func:`~ncfmu.files.writer_id`): in ``DIR/variants`` for
#: a worker on the client's machine, until the client renames it to ``<key>.csv``; one left there by a worker killed
#: mid-variant is removed when its sweep ends, one of a sweep killed itself by the next; never taken for a result.
ROWS_SUFFIX = ".rows"

# -- the worker side -------------------------------------------------------------------------------
_OPEN: dict[str, OpenSystem] = {}      # per worker process: archive digest -> OpenSystem, FMUs instantiated once
#: Per remote worker process: the rows files each sweep (by its id) has yet to fetch, and the sweeps stopped --
#: whose variants still running finish after their client left: their rows are removed, never fetched.
_UNFETCHED: dict[str, set[str]] = {}
_STOPPED: set[str] = set()
_UNFETCHED_LOCK = threading.Lock()


def _worker_folder() -> Path:
    """This process's own cache folder (in its own temp dir: nothing of the client's)."""
    folder = Path(tempfile.gettempdir()) / f"ncfmu-sweep-{os.getuid() if hasattr(os, 'getuid') else 'user'}"
    folder.mkdir(parents=True, exist_ok=True)
    return folder


def _cached_archive(digest: str, data: bytes) -> Path:
    """The archive in this process's own cache (written once per content digest, atomically)."""
    path = _worker_folder() / f"{digest}.ssp"
    if not path.is_file() or hashlib.sha256(path.read_bytes()).hexdigest() != digest:
        write_atomic(path, data)
    return path


def run_variant(ssp: bytes, digest: str, variant: Mapping[str, object], stop_time: float | None,
                record: Sequence[str] | None, every: int, timeout: float | None,
                rows_folder: str | None = None, sweep_id: str | None = None) -> dict:
    """Run one variant in this process; never raises.

    Returns ``{"row": {status, error, wall_time, rows, metrics...}, "trajectory": where its rows are or None}``:
    the rows stay in a file (``{"path", "size", "complete", "worker"}``) until the client takes them. The file
    is in ``rows_folder`` when given -- the sweep's own ``DIR/variants`` when this process runs on the client's
    machine: the client renames it (:func:`_write_rows`) --, else in this process's temp dir, where the client
    fetches it (:func:`read_rows`) and removes it (:func:`remove_rows`).
    """
    from .cosim.master import CHECK_INTERVAL
    from .cosim.record import CsvSink
    from .project import OpenSystem, recording
    from .systems.outcome import default_stop_time, ends_when_done, halted, outcome, watched
    t0 = time.perf_counter()
    row: dict[str, object] = {}
    opened = _OPEN.get(digest)
    csv = None
    metrics = None
    try:
        if opened is None:
            opened = _OPEN[digest] = OpenSystem(_cached_archive(digest, ssp))
        else:
            for slave in opened.slaves:
                slave.reset()
        folder = Path(rows_folder) if rows_folder is not None else _worker_folder() / "rows"
        csv = CsvSink(folder / f"{variant_key(variant)}-{writer_id()}{ROWS_SUFFIX}")
        # the metrics read every step of what the report needs; the file gets the kept columns (default: what the
        # report reads) every k-th row
        keep = list(record) if record is not None else opened.report().record()
        how = recording(opened, variant, csv, keep, every=every)
        metrics = how.summary
        assert metrics is not None
        deadline = None if timeout is None else time.perf_counter() + timeout
        # as ncfmu run: to where the work ends (stop_time, default RUN_LIMIT, the limit), a crash or an alarm
        if stop_time is None:
            stop_time = default_stop_time(opened.system.stop_time, ends_when_done(metrics))
        row_time = every * opened.system.step_size     # asked at whole rows, about every CHECK_INTERVAL s
        opened.run(stop_time=stop_time, start_values=dict(variant), deadline=deadline, keep=False,
                   until=lambda: halted(metrics), check_interval=row_time * max(1, round(CHECK_INTERVAL / row_time)),
                   watch=watched(metrics), **how.run_arguments())
        came_out = outcome(metrics)
        row.update(status=came_out.status, error=came_out.why)
    except SimulationTimeout as err:
        row.update(status="timeout", error=str(err))       # the instances are reset before the next variant
    except NcfmuError as err:
        row.update(status="failed", error=str(err))
        _discard(digest)               # an instance after fmi2Fatal is unusable: open afresh next time
    except Exception as err:           # a crash in one variant must not end the sweep
        row.update(status="failed", error=f"{type(err).__name__}: {err}")
        _discard(digest)
    trajectory = None
    if csv is not None and csv.final_path is not None and csv.rows:
        # the rows written (all of them, or up to where the run stopped) and the metrics of those rows
        trajectory = {"path": str(csv.final_path), "size": csv.final_path.stat().st_size,
                      "complete": row["status"] in RAN, "worker": _worker_address()}
        assert metrics is not None
        row.update(rows=csv.rows, **metrics.metrics())
    elif csv is not None and csv.final_path is not None:
        csv.final_path.unlink(missing_ok=True)              # a header without rows: nothing to fetch
    if trajectory is not None and sweep_id is not None:
        rows_file = str(trajectory["path"])
        with _UNFETCHED_LOCK:
            if sweep_id in _STOPPED:
                Path(rows_file).unlink(missing_ok=True)
            else:
                _UNFETCHED.setdefault(sweep_id, set()).add(rows_file)
    row["wall_time"] = round(time.perf_counter() - t0, 4)
    return {"row": row, "trajectory": trajectory}


def _worker_address() -> str | None:
    """The dask worker running this task, or None outside one (a serial sweep)."""
    try:
        from distributed import get_worker
        return get_worker().address
    except (ImportError, ValueError):
        return None


def read_rows(path: str, offset: int, size: int) -> bytes:
    """Up to ``size`` bytes of a variant's rows file from ``offset`` (run where the file is)."""
    with open(path, "rb") as f:
        f.seek(offset)
        return f.read(size)


def remove_rows(path: str) -> None:
    Path(path).unlink(missing_ok=True)
    with _UNFETCHED_LOCK:
        for paths in _UNFETCHED.values():
            paths.discard(path)


def stop_sweep_rows(sweep_id: str) -> None:
    """Remove the rows files of the stopped sweep ``sweep_id`` no one will fetch (run on each remote worker by its
    client as it stops), and those of its variants that finish later."""
    with _UNFETCHED_LOCK:
        _STOPPED.add(sweep_id)
        paths = _UNFETCHED.pop(sweep_id, set())
    for path in paths:
        Path(path).unlink(missing_ok=True)


def _discard(digest: str) -> None:
    opened = _OPEN.pop(digest, None)
    if opened is not None:
        try:
            opened.close()
        except Exception:
            pass


# -- variants --------------------------------------------------------------------------------------
def canonical(value: object) -> object:
    """The value that identifies a variant: numbers as floats (``8`` and ``8.0`` are one), text as text."""
    if isinstance(value, bool) or isinstance(value, str):
        return value
    if isinstance(value, (int, float, np.integer, np.floating)):
        x = float(value)
        if not math.isfinite(x):
            raise SystemDefinitionError(f"sweep value {value!r}: must be finite")
        return x
    raise SystemDefinitionError(f"sweep value {value!r}: must be a number, true/false or text")


def variant_key(variant: Mapping[str, object]) -> str:
    text = json.dumps({k: canonical(variant[k]) for k in sorted(variant)}, sort_keys=True)
    return hashlib.sha1(text.encode()).hexdigest()[:10]


def product(vary: Mapping[str, Sequence[object]]) -> list[dict[str, object]]:
    """The cartesian product of ``vary``, each list first rid of duplicates (by canonical value)."""
    names = list(vary)
    unique: dict[str, list[object]] = {}
    for name in names:
        if "." not in name:
            raise SystemDefinitionError(f"--vary {name!r}: expected INSTANCE.VARIABLE")
        if not vary[name]:
            raise SystemDefinitionError(f"--vary {name}: no values")
        seen: dict[object, object] = {}
        for v in vary[name]:
            seen.setdefault(canonical(v), v)
        unique[name] = list(seen.values())
    return [dict(zip(names, values)) for values in itertools.product(*(unique[n] for n in names))]


# -- the client's files ----------------------------------------------------------------------------
def _read_summary(path: Path) -> list[dict[str, str]]:
    if not path.is_file():
        return []
    with open(path, newline="", encoding="utf-8-sig") as f:    # saved by a spreadsheet: a BOM before "key"
        reader = csv.DictReader(f)
        rows = []
        for row in reader:
            if None in row:            # csv's key for the fields past the header's: a row edited by hand
                fields = len(reader.fieldnames or []) + len(row[None])
                raise NcfmuError(f"{path}: line {reader.line_num} has {fields} fields, its header "
                                 f"{len(reader.fieldnames or [])}: edited by hand? fix or remove the line (a "
                                 "variant without its row is run again)")
            rows.append(row)
        return rows


def _write_summary(path: Path, rows: list[Mapping[str, object]], varied: list[str]) -> None:
    columns = ["key", *varied, "status", "error"]
    for row in rows:
        for k in row:
            if k not in columns:
                columns.append(k)
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=columns, lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: row.get(k, "") for k in columns})
    write_atomic(path, text.getvalue().encode())


def _merge_summary(path: Path, rows: Mapping[str, Mapping[str, object]], order: Sequence[str],
                   recorded: set[str], varied: list[str]) -> None:
    """Write ``path`` with the rows of ``recorded`` (this sweep's) merged into the summary there now: every row
    another sweep wrote there is kept, as it wrote it; ``rows`` of other keys (this sweep read them at its start)
    are kept where the file no longer has them. Under a lock of the folder, so that two sweeps' writes never
    interleave (where the system has ``flock``)."""
    with _folder_locked(path.parent):
        there = {r["key"]: r for r in _read_summary(path) if r.get("key")}
        # in this sweep's order (the file's at its start, then its variants'), then what another sweep added
        keys = [k for k in order if k in rows or k in there]
        ours = set(keys)
        keys += [k for k in there if k not in ours]
        _write_summary(path, [rows[k] if k in recorded or k not in there else there[k] for k in keys], varied)


@contextlib.contextmanager
def _folder_locked(folder: Path) -> Iterator[None]:
    """Hold an exclusive ``flock`` of ``folder`` (a lock of the directory itself: no lock file left in it). Where
    there is none (Windows; a filesystem that refuses it, as some NFS mounts do with ENOLCK), nothing is held: the
    lock only keeps two sweeps' writes into one folder from interleaving -- a sweep alone there must not fail for
    it (a lost row is run again by the next sweep)."""
    if sys.platform == "win32":
        yield
        return
    import fcntl
    fd = os.open(folder, os.O_RDONLY)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
        except OSError as err:
            # NFS emulates it with a byte-range lock, which a folder opened to read cannot take: EBADF
            if err.errno not in (errno.ENOLCK, errno.EOPNOTSUPP, errno.ENOSYS, errno.EINVAL, errno.EBADF):
                raise
        yield
    finally:
        os.close(fd)                                    # the lock goes with it


def _complete(path: Path, rows: str) -> bool:
    """The trajectory file is there with the number of rows its summary row says (header + rows lines)."""
    try:
        expected = int(rows)
        with open(path, "rb") as f:
            return sum(1 for _ in f) == expected + 1
    except (OSError, ValueError):
        return False


def output_names(archive: Path, system: System | None = None) -> list[str]:
    """``INSTANCE.VARIABLE`` of every output in the archive (read from the SSD -- or ``system``, the archive's as
    read already -- and the FMUs' modelDescriptions)."""
    from .cosim.ssp import read_ssp
    system = system or read_ssp(archive)
    names = []
    with zipfile.ZipFile(archive) as z:
        for comp in system.components:
            with zipfile.ZipFile(z.open(comp.source)) as fmu:
                root = ET.fromstring(fmu.read("modelDescription.xml"))
            names += [f"{comp.name}.{sv.get('name')}" for sv in root.iter("ScalarVariable")
                      if sv.get("causality") == "output"]
    return names


def _write_rows(out: Path, key: str, trajectory: Mapping[str, Any],
                read: Callable[[str, int, int], bytes]) -> None:
    """Put a variant's rows where they belong, atomically: ``out/variants/<key>.csv`` for a run that completed,
    ``<key>.csv.partial`` for one that stopped early (the other name removed, so a variant has one file).

    A rows file the worker wrote into ``out/variants`` itself (a worker on this machine) is renamed there, after
    its bytes are on disk: no copy. Any other is copied from where the worker left it, chunk by chunk
    (``read(path, offset, size)``)."""
    final = out / "variants" / (f"{key}.csv" if trajectory["complete"] else f"{key}.csv.partial")
    other = out / "variants" / (f"{key}.csv.partial" if trajectory["complete"] else f"{key}.csv")
    path, size = str(trajectory["path"]), int(trajectory["size"])
    if Path(path).parent == (out / "variants").resolve():
        with open(path, "rb") as rows:
            os.fsync(rows.fileno())
        os.replace(path, final)
        other.unlink(missing_ok=True)
        return
    with atomic_file(final) as f:
        offset = 0
        while offset < size:
            chunk = read(path, offset, min(FETCH_CHUNK, size - offset))
            if not chunk:
                raise NcfmuError(f"the rows of variant {key} ended at byte {offset} of {size} on the worker")
            f.write(chunk)
            offset += len(chunk)
    other.unlink(missing_ok=True)


def _remove_rows_files(folder: Path) -> None:
    """Remove the rows files (``*.rows``, ``*.rows.partial``) in ``folder`` of workers that no longer run: those
    of another sweep's workers still running (a second sweep into the same ``out``) are theirs to rename."""
    for leftover in [*folder.glob(f"*{ROWS_SUFFIX}"), *folder.glob(f"*{ROWS_SUFFIX}.partial")]:
        if not _writer_running(leftover):
            leftover.unlink(missing_ok=True)


def _remove_temporary_files(folder: Path) -> None:
    """Remove the temporary files (``NAME.<pid>.part``, :func:`~ncfmu.files.write_atomic`'s) in ``folder`` of
    processes that no longer run -- an interrupted write, never trusted; another sweep's still running (into the
    same ``out``) are its own to rename."""
    for leftover in folder.glob("*.part"):
        if not _writer_running(leftover):
            leftover.unlink(missing_ok=True)


def _writer_running(path: Path) -> bool:
    """Whether the process that writes ``path`` -- a rows file (``<key>-<writer>.rows``: a worker on this machine)
    or a temporary file (``NAME.<writer>.part``), ``<writer>`` :func:`~ncfmu.files.writer_id`'s ``<pid>@<machine>``
    -- is one other than this one and still running. A process of another machine (a host sharing ``out`` over
    NFS, another container) counts as running: its pid means nothing here -- taken for a dead one's, its rows were
    removed while it wrote them. Asked of the system on POSIX only (``os.kill(pid, 0)`` would end it on Windows,
    where a file another process has open cannot be removed anyway)."""
    if path.name.endswith(".part"):
        writer = path.name[:-len(".part")].rpartition(".")[2]
    else:
        writer = path.name.split(".", 1)[0].rpartition("-")[2]
    pid, _, machine = writer.partition("@")
    if machine and machine != machine_id():
        return os.name == "posix"
    if os.name != "posix" or not pid.isdigit() or int(pid) == os.getpid():
        return False
    try:
        os.kill(int(pid), 0)
    except (ProcessLookupError, OverflowError):
        return False
    except PermissionError:          # another user's process: running
        pass
    return True


def _check_writable(folder: Path, out: Path) -> None:
    """Refuse, before any variant runs, a ``folder`` (``out/variants``) that takes no new file: its variants would
    each be recorded ``failed`` -- and a failed variant counts as done, never run again."""
    probe = folder / f"write-check-{writer_id()}{ROWS_SUFFIX}.partial"      # if left, removed as a rows file is
    try:
        with open(probe, "wb"):
            pass
        probe.unlink()
    except OSError as err:
        raise NcfmuError(f"--out {out}: cannot write the variants' rows in {folder}: {err.strerror or err}") from None


class SweepStopped(Interrupted):
    """A sweep stopped by Ctrl-C or SIGTERM (``signum``): ``done`` of its ``total`` variants have their row in
    ``summary`` and their whole file; the same sweep again runs the rest."""

    def __init__(self, signum: int, done: int, total: int, summary: Path) -> None:
        super().__init__(signum)
        self.done, self.total, self.summary = done, total, summary


class Progress:
    """A tqdm bar with done / failed / timeout and an ETA, on a terminal only."""

    def __init__(self, total: int, stream=None) -> None:
        stream = sys.stderr if stream is None else stream      # the stderr of now, not of import time
        self.bar = None
        self.counts = {s: 0 for s in STATUSES}
        if total and hasattr(stream, "isatty") and stream.isatty():
            from tqdm import tqdm
            self.bar = tqdm(total=total, file=stream, unit="variant", dynamic_ncols=True)

    def update(self, status: str) -> None:
        self.counts[status] = self.counts.get(status, 0) + 1
        if self.bar is not None:
            self.bar.set_postfix(done=self.counts["ok"],
                                 rejected=self.counts["crashed"] + self.counts["out_of_tolerance"],
                                 unfinished=self.counts["unfinished"], failed=self.counts["failed"],
                                 timeout=self.counts["timeout"], refresh=False)
            self.bar.update(1)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def _scheduler_address(scheduler_file: str) -> str:
    """The address a running scheduler wrote to its scheduler file (JSON with an ``address``).

    Read here rather than by dask's ``Client(scheduler_file=...)``, which waits for a missing file for ever.
    """
    path = Path(scheduler_file)
    if not path.exists():
        raise NcfmuError(f"--scheduler-file {path}: no such file (start the scheduler first: dask scheduler "
                         f"--scheduler-file {path})")
    try:
        address = json.loads(path.read_text())["address"]
    except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError) as err:
        raise NcfmuError(f"--scheduler-file {path}: not a dask scheduler file (JSON with the scheduler's "
                         f"'address'): {type(err).__name__}: {err}") from None
    if not isinstance(address, str):
        raise NcfmuError(f"--scheduler-file {path}: address {address!r} is not text")
    return address


def _connect(scheduler: str | None, scheduler_file: str | None, connect_timeout: float):
    """A client of a running scheduler that has a worker, or one line saying why not within ``connect_timeout``."""
    from dask.distributed import Client
    option = f"--scheduler {scheduler}" if scheduler_file is None else f"--scheduler-file {scheduler_file}"
    address = scheduler if scheduler_file is None else _scheduler_address(scheduler_file)
    # dask's Client(timeout=) bounds the TCP connect, not the handshake: a port that accepts and never answers
    # (a stopped scheduler) held it for minutes. The client is made in a daemon thread, waited for here.
    made: list = []

    def connect() -> None:
        try:
            made.append(Client(address, timeout=connect_timeout))
        except Exception as err:                        # handed to the caller's thread below
            made.append(err)
    thread = threading.Thread(target=connect, name="ncfmu-connect", daemon=True)
    thread.start()
    thread.join(connect_timeout + 1.0)
    client = made[0] if made else TimeoutError()
    if isinstance(client, (OSError, TimeoutError)):
        raise NcfmuError(f"{option}: no dask scheduler answered within {connect_timeout:g} s at {address} "
                         "(--connect-timeout S waits longer)")
    if isinstance(client, (ValueError, TypeError)):    # an address dask cannot use (an unknown scheme, tls:// bare)
        raise NcfmuError(f"{option}: {address}: {client}")
    if isinstance(client, Exception):
        raise NcfmuError(f"{option}: cannot connect to {address}: {type(client).__name__}: {client}")
    try:
        client.wait_for_workers(1, timeout=connect_timeout)
    except (OSError, TimeoutError):
        client.close()
        raise NcfmuError(f"{option}: the scheduler at {address} has no worker (waited {connect_timeout:g} s, "
                         "--connect-timeout): start one with dask worker") from None
    return client


#: How a LocalCluster's nannies start their workers: forked from this process's forkserver where the platform has
#: one (not Windows), else spawned (dask's default). Never forked from the client itself: a sweep is often started
#: from a process that holds open FMUs, their loaded binaries and threads (a pytest session, a notebook), and a
#: fork would copy those mid-use into every worker. The forkserver is a fresh interpreter with none of that: it
#: imports :data:`WORKER_MODULES` once (~0.5 s CPU, once per process) and forks each worker from there, so a worker
#: starts with them imported: at its first result it has spent ~0.7 s CPU, spawned ~1.1 s (distributed and ncfmu
#: imported again in each), and a later sweep of the process starts its cluster in ~0.15 s (bench/README.md,
#: "the sweep on 2 workers").
WORKER_START = "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "spawn"
#: dask settings of the LocalCluster a sweep starts (an existing cluster keeps its own), measured with
#: bench/sweep_cpu.py (bench/README.md, "the sweep on 2 workers"): the workers started as :data:`WORKER_START`
#: says; the statistical profiler (a thread sampling the task thread's stack every 10 ms, for the dashboard nobody
#: opens) off; the event-loop health tick every 1 s instead of 20 ms and the system monitor (psutil samples for
#: the dashboard) every 10 s instead of 0.5 s, in each worker and in the client's scheduler.
LOCAL_CLUSTER_CONFIG: dict[str, object] = {"distributed.worker.multiprocessing-method": WORKER_START,
                                           "distributed.worker.profile.enabled": False,
                                           "distributed.admin.tick.interval": "1s",
                                           "distributed.admin.system-monitor.interval": "10s"}
#: What a LocalCluster's worker imports before its first variant, in the forkserver: dask's worker (distributed,
#: which imports the packages dask's own preload list names) and what ``run_variant`` imports (the co-simulation
#: with fmpy and numpy, the project's opening of a system, the outcome of a run). Nothing is opened there: a
#: system's FMUs are instantiated in each worker (their files and binaries are that worker's own).
WORKER_MODULES = ("distributed", "ncfmu.batch", "ncfmu.project", "ncfmu.cosim.master", "ncfmu.cosim.record",
                  "ncfmu.systems.outcome")


def start_worker_forkserver() -> None:
    """Start this process's forkserver, importing :data:`WORKER_MODULES`, if workers are forked from one.

    Once per process: it lives on and forks the workers of every later LocalCluster of this process, which then
    start with nothing to import. A sweep calls it first thing, so that the forkserver's imports run on the other
    core beside the client's own work before its cluster starts (reading the archive, importing distributed)."""
    if LOCAL_CLUSTER_CONFIG.get("distributed.worker.multiprocessing-method") != "forkserver":
        return
    from multiprocessing import forkserver
    # the preload is read when the server starts; dask sets its own list on the context later, at its first
    # worker, which a running server does not read again
    multiprocessing.get_context("forkserver").set_forkserver_preload(list(WORKER_MODULES))
    # Started with Ctrl-C and SIGTERM ignored, which an exec keeps and Python then leaves so: the forkserver gives its
    # children the dispositions it started with, so the workers ignore the Ctrl-C a terminal sends to the whole
    # process group (else each printed a KeyboardInterrupt traceback and died mid-variant) and the SIGTERM a service
    # manager sends to all of it (else each died mid-variant, its rows file left, and dask logged the loss and
    # restarted it); the client closes them (its nannies ask them to, then kill them), and the forkserver ends with
    # the client. (Outside the main thread, where no handler can be set, it starts as it would.)
    with handled_signals((signal.SIGINT, signal.SIGTERM), signal.SIG_IGN):
        forkserver.ensure_running()


class _WorkerClosing(logging.Filter):
    """Drops what dask logs when a worker is closed in the middle of its work, and only while it closes: a task
    cancelled with it ("Async instruction for <Task ... execute(...)> ended with CancelledError") and a heartbeat
    cut off by the closing of its own connections ("Failed to communicate with scheduler during heartbeat.", an
    ERROR with three tracebacks; dask's race, seen at the end of ~1 in 25 sweeps). A sweep's LocalCluster closes
    mid-variant when the sweep was stopped (Ctrl-C, SIGTERM), and the sweep says so itself, in one line."""

    def __init__(self, worker: Any) -> None:
        super().__init__()
        self.worker = worker

    def filter(self, record: logging.LogRecord) -> bool:
        from distributed.core import Status
        if self.worker.status not in (Status.closing, Status.closed):
            return True
        message = record.getMessage()
        return not (message.startswith("Failed to communicate with scheduler during heartbeat")
                    or (message.startswith("Async instruction for ") and message.endswith("with CancelledError")))


def dask_setup(worker: Any) -> None:
    """dask's preload hook, in each worker of a sweep's LocalCluster (``preload=["ncfmu.batch"]``) as it starts."""
    for name in ("distributed.worker", "distributed.worker.state_machine"):
        logging.getLogger(name).addFilter(_WorkerClosing(worker))


def local_cluster(workers: int):
    """A dask LocalCluster of ``workers`` single-threaded processes on this machine, with no dashboard.

    dask's scheduler serves HTTP (health, metrics) even with the dashboard off, on port 8787 unless told
    otherwise: a second cluster on the machine (two sweeps, a test run beside a notebook) then warns "Port 8787
    is already in use". Ours listens on a free port of the loopback instead.

    Each worker gets this process's environment as it is now (the nanny sets it in the worker): a forkserver's
    children inherit the environment it was started with, maybe by an earlier sweep."""
    import dask
    from dask.distributed import LocalCluster
    start_worker_forkserver()
    with dask.config.set(LOCAL_CLUSTER_CONFIG):        # read by the scheduler, the nannies and (through them) workers
        return LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                            scheduler_kwargs={"dashboard_address": "127.0.0.1:0"}, env=dict(os.environ),
                            preload=[__name__])


def _run_on_dask(todo, data: bytes, digest: str, args: tuple, workers: int, scheduler: str | None,
                 scheduler_file: str | None, connect_timeout: float, record_result: Callable,
                 fixed: Mapping[str, object], rows_folder: str) -> None:
    from dask.distributed import Client, as_completed
    cluster = client = None
    sweep_id = uuid.uuid4().hex
    try:
        if scheduler is not None or scheduler_file is not None:
            client = _connect(scheduler, scheduler_file, connect_timeout)
        else:
            # a cluster cut off while it starts can be closed by no one (dask's own exit hook fails on it, with a
            # traceback, and its workers start after all): a Ctrl-C or SIGTERM waits for it, then stops the sweep
            with held_interrupts():
                cluster = local_cluster(workers)
                client = Client(cluster)
        with held_interrupts():         # cut off, dask's scheduler logged the half-made copies (an ERROR, a WARNING)
            shipped = client.scatter(data, broadcast=True, hash=False)     # once to every worker
        # a local cluster's workers write their rows into DIR/variants, where the client renames them; a remote
        # one's, in its own folder, known by this sweep's id
        local = {"sweep_id": sweep_id} if cluster is None else {"rows_folder": rows_folder}
        futures = {client.submit(run_variant, shipped, digest, {**fixed, **v}, *args, **local, pure=False):
                   (key, v) for key, v in todo}
        for future in as_completed(futures):
            key, v = futures[future]
            answer = future.result()
            if cluster is not None:
                record_result(key, v, answer)      # renamed in DIR/variants: nothing to fetch or remove
                continue
            worker = (answer["trajectory"] or {}).get("worker")

            def read(path: str, offset: int, size: int, worker=worker) -> bytes:
                # on the worker's own connection (Client.run), not as a task: the worker's thread may be
                # running the next variant already
                return client.run(read_rows, path, offset, size, workers=[worker])[worker]

            def remove(path: str, worker=worker) -> None:
                client.run(remove_rows, path, workers=[worker])
            record_result(key, v, answer, read, remove)
    except KeyboardInterrupt:
        if client is not None and cluster is None:
            try:        # the variants running go on to their end on the remote workers: their rows, removed
                client.run(stop_sweep_rows, sweep_id)
            except Exception:
                pass    # a worker gone: its files went with it, or its temp dir keeps them
        raise
    finally:
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()


def sweep(system: str, vary: Mapping[str, Sequence[object]], out: Path, workers: int = 2,
          scheduler: str | None = None, scheduler_file: str | None = None, stop_time: float | None = None,
          root: Path | None = None, record: Sequence[str] | None = None, output_interval: float | None = None,
          timeout: float | None = None, progress: bool = True,
          on_done: Callable[[dict], None] | None = None, connect_timeout: float = 5.0,
          fixed: Mapping[str, object] | None = None) -> list[dict[str, object]]:
    """Run the cartesian product of ``vary`` on ``system`` (a name or an ``.ssp`` path); return its summary rows.

    ``fixed`` (``--set``): the start values every variant shares (``INSTANCE.VARIABLE`` -> value); they are part of
    each variant's key (a sweep into the same ``out`` with other ``fixed`` values runs its variants again), not
    columns of the summary.

    ``workers = 0`` runs the variants serially in this process (no dask); ``scheduler`` (an address) or
    ``scheduler_file`` runs them on an existing dask cluster, else on a LocalCluster of ``workers`` processes.
    An existing cluster must answer, with at least one worker, within ``connect_timeout`` seconds.
    """
    from .cosim.master import steps_per_row
    from .cosim.ssp import read_ssp
    from .project import system_archive
    out = Path(out)
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 0:
        raise NcfmuError(f"--workers {workers!r}: must be >= 0 (0: serial, no dask)")
    if not (math.isfinite(connect_timeout) and connect_timeout > 0):
        raise NcfmuError(f"--connect-timeout {connect_timeout!r}: must be a number of seconds > 0")
    if scheduler_file is not None:
        _scheduler_address(scheduler_file)              # refused now, not after the archive is built and read
    if timeout is not None and not (math.isfinite(timeout) and timeout > 0):
        raise SystemDefinitionError(f"--timeout {timeout!r}: must be a number of seconds > 0")
    if workers > 0 and scheduler is None and scheduler_file is None:
        start_worker_forkserver()       # its imports beside this process's work: the archive, dask's import
    archive = system_archive(system, root).resolve()
    data = archive.read_bytes()
    digest = hashlib.sha256(data).hexdigest()
    read = read_ssp(archive)                             # read once: the step and the outputs
    step = read.step_size
    try:
        every = steps_per_row(output_interval, step)         # the master's rule, said as the option
    except SystemDefinitionError:
        raise SystemDefinitionError(f"--output-interval {output_interval!r}: must be a whole multiple of the "
                                    f"system's step {step:g} s") from None
    if record is not None:
        known = set(output_names(archive, read))
        unknown = [n for n in record if n not in known]
        if unknown:
            raise SystemDefinitionError(f"--record {unknown[0]!r}: not an output of {archive.name} "
                                        f"(outputs are INSTANCE.VARIABLE, e.g. x_axis.pos)")
        record = list(dict.fromkeys(record))
    variants = product(vary)
    varied = list(vary)
    fixed = dict(fixed or {})
    both = [name for name in fixed if name in vary]
    if both:
        raise SystemDefinitionError(f"--set {both[0]} and --vary {both[0]}: a variable is either shared by every "
                                    "variant (--set) or varied (--vary), not both")
    for name, value in fixed.items():
        if "." not in name:
            raise SystemDefinitionError(f"--set {name!r}: expected INSTANCE.VARIABLE")
        canonical(value)

    def key_of(variant: Mapping[str, object]) -> str:
        return variant_key({**fixed, **variant})

    (out / "variants").mkdir(parents=True, exist_ok=True)
    variants_folder = out / "variants"
    _remove_temporary_files(out)
    _remove_temporary_files(variants_folder)
    _remove_rows_files(variants_folder)                 # an interrupted sweep's workers': never taken for a result
    summary_path = out / SUMMARY
    rows: dict[str, dict[str, object]] = {r["key"]: dict(r) for r in _read_summary(summary_path) if r.get("key")}
    order = list(rows)
    todo = []
    for v in variants:
        key = key_of(v)
        old = rows.get(key)
        done = old is not None and old.get("status") in STATUSES and (
            old["status"] not in RAN or _complete(out / "variants" / f"{key}.csv", str(old.get("rows", ""))))
        if not done:
            todo.append((key, v))
        if key not in rows:
            order.append(key)
    if todo:
        _check_writable(variants_folder, out)
    bar = Progress(len(todo)) if progress else None

    # The summary is rewritten at most once a second and at the end (also when interrupted): a variant whose
    # row did not make it is simply run again next time; its trajectory file is replaced atomically. Each write
    # merges this sweep's new rows into the summary as it is then (another sweep into ``out`` may have added
    # some since this one read it).
    last_write, dirty = [0.0], [False]
    recorded: set[str] = set()

    def flush_summary(force: bool = False) -> None:
        if dirty[0] and (force or time.monotonic() - last_write[0] >= 1.0):
            _merge_summary(summary_path, rows, order, recorded, varied)
            last_write[0], dirty[0] = time.monotonic(), False

    def record_result(key: str, variant: Mapping[str, object], answer: dict,
                      read: Callable[[str, int, int], bytes] = read_rows,
                      remove: Callable[[str], None] = remove_rows) -> None:
        row, trajectory = answer["row"], answer["trajectory"]
        # a Ctrl-C waits for the variant's record (a remote one's fetch: a second and more for a long one): cut
        # off, it left a .part in DIR/variants, a file without its row, or the rows file on the worker for good
        with held_interrupts():
            if trajectory is not None:
                try:
                    _write_rows(out, key, trajectory, read)
                finally:
                    remove(str(trajectory["path"]))
            rows[key] = {"key": key, **variant, **row}
            recorded.add(key)
            dirty[0] = True
            flush_summary()
        if bar:
            bar.update(row["status"])
        if on_done:
            on_done(rows[key])

    args = (stop_time, record, every, timeout)
    rows_folder = str(variants_folder.resolve())       # where a worker on this machine writes a variant's rows
    stopped: int | None = None
    try:
        if todo and workers == 0 and scheduler is None and scheduler_file is None:
            for key, v in todo:
                raise_pending()                         # a Ctrl-C noted between two variants
                record_result(key, v, run_variant(data, digest, {**fixed, **v}, *args, rows_folder=rows_folder))
        elif todo:
            _run_on_dask(todo, data, digest, args, workers, scheduler, scheduler_file, connect_timeout,
                         record_result, fixed, rows_folder)
    except KeyboardInterrupt as err:
        stopped = err.signum if isinstance(err, Interrupted) else signal.SIGINT
    finally:
        flush_summary(force=True)
        # every worker of this sweep has ended (its cluster closed): a rows file still here is the one of a worker
        # killed mid-variant (dask ran the variant again elsewhere), or of this sweep interrupted
        _remove_rows_files(variants_folder)
        if bar:
            bar.close()
    if stopped is not None:
        left = {key for key, _ in todo} - recorded     # a row read at the start may be of a damaged file
        raise SweepStopped(stopped, len(variants) - len(left), len(variants), summary_path) from None
    return [rows[key_of(v)] for v in variants]
