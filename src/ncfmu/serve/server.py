"""Live virtual commissioning: a system run in real time behind an OPC UA server (asyncua).

Two threads share the work, and neither waits on the other:

- the **simulation thread** owns the FMUs (every FMI call happens there). It paces simulated time to the
  wall clock (``speed`` 1 = real time, 0 = as fast as it can), runs the steps that are due in chunks, and
  between chunks applies the writes clients made (forcing an input, releasing it, a tunable parameter, Pause,
  Resume, Stop, Reset) and leaves a snapshot of the values for the server;
- the **server** (asyncua, on an asyncio loop in the main thread) publishes the newest snapshot every
  ``publish_interval`` (subscriptions then deliver data changes) and answers clients.

Each node of a Write is checked on the server side first (type, NaN/inf, the port's min/max from the
modelDescription: OPC UA status Bad_TypeMismatch, Bad_OutOfRange, Bad_NotWritable, Bad_NodeIdUnknown; that node
changes nothing), then handed to the simulation thread, which applies it before the next step and answers with
the session's verdict (a tunable parameter is first checked by its model's own rules on a copy; a refusal is
Bad_OutOfRange and never reaches the FMU). Each node gets its own status, as OPC UA Part 4 asks.

Address space (stable: PLC projects point at these names): namespace ``urn:ncfmu:<system>``; one Object per
component instance; one Variable per FMU variable, string NodeId ``<instance>.<variable>``, BrowseName the
variable's name, DataType Double/Int32/Boolean/String, its description, its unit as EngineeringUnits
(EUInformation); inputs also get ``<instance>.<variable>.forced`` (Boolean). The ``Simulation`` object holds
``time``, ``speed``, ``lag``, ``overruns``, ``state``, ``reason``, ``forced`` (the forced inputs), ``verdict``
(the part check's summary line when the last program ended: a lathe's or mill's done, a grinder's cycle end) and the
methods ``Pause``, ``Resume``, ``Stop``, ``Reset`` and ``Release(name)``.

With a watchdog (``--watchdog S``), a client session that forced inputs is lost when it closes or is silent S s.
As a CNC that loses its PLC or HMI link stops, ``--on-lost hold`` (the default) puts the machine in feed hold:
each feed-hold input (:data:`FEED_HOLD_INPUT`) forced true, the simulation running on (a system without one
halts: a stop), the lost session's forces kept, ``Simulation.state`` ``held`` and ``Simulation.reason`` which
session was lost and what is held. Those inputs cannot be forced or released one by one meanwhile (Bad_InvalidState);
a client's ``Resume`` -- the cycle start after a feed hold -- releases them all and the machine moves on (Reset
starts again). ``--on-lost release`` lets the lost session's forces fall back at once instead.

A crash is published as it happens (a system with a part check: the lathes, the mill): the simulation thread
hands the recorded rows to the part check every :data:`CRASH_CHECK` s of simulated time; the check runs in a
third thread (``ncfmu-part-check``), at most one hand-over behind (at --speed 0 each is waited for); at the first
crash the simulation halts (above speed 0 up to one hand-over later; the crash's time, line and depth are those
of the rows up to the halt, as a synchronous check has them), as a machine's collision monitor stops it --
``Simulation.state`` ``crashed``, ``Simulation.reason`` and ``Simulation.crash`` the crash (time, program line,
what, how deep), ``Simulation.crashes`` how many -- and the ``Simulation`` object emits a ``CrashEventType``
event (Message the same text, Severity 900, and the fields ``SimulationTime``, ``Line``, ``What``, ``DepthMm``).
Reset starts again; Resume is refused.
"""

from __future__ import annotations

import asyncio
import datetime
import gc
import ipaddress
import logging
import math
import os
import queue
import signal
import sys
import threading
import time as _time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING
from urllib.parse import urlparse

import numpy as np

if TYPE_CHECKING:
    from asyncua.common.node import Node
from .errors import ConfigError, FmuCrashed, NcfmuError, SimulationError, TerminationRequested

log = logging.getLogger("ncfmu.serve")

#: The states a simulation ends in when it did not finish: ``failed`` (an FMU refused a call, the part check broke)
#: and ``faulted`` (a foreign FMU's process died: :class:`~ncfmu.errors.FmuCrashed`); the session's rows are kept.
ENDED_BADLY = ("failed", "faulted")

#: An overrun: the loop falls behind, a chunk's last step finishing more than this after its wall-clock due time
#: (counted once until a chunk is on time again).
OVERRUN_LAG = 0.010
#: The most wall time one chunk may take when catching up (the server gets the GIL in between anyway).
MAX_CHUNK_WALL = 0.020
#: The shortest wall time between chunks when paced: faster than real time, one wake-up runs several steps.
MIN_CHUNK_WALL = 0.001
#: Steps per chunk at ``speed`` 0 (as fast as possible, still handing back between chunks).
FAST_CHUNK = 50
#: How often (simulated s) a served run's part check is handed the rows so far: how late a crash is seen at most.
CRASH_CHECK = 0.05
#: The OPC UA Severity of a crash event (1..1000; 801-1000 is "high" in Part 5).
CRASH_SEVERITY = 900
#: The input that puts a channel in feed hold (our NC controllers' name for it; a foreign FMU may follow it): what
#: ``--on-lost hold`` forces true when a client that forced inputs is lost.
FEED_HOLD_INPUT = "feed_hold"
#: What the watchdog does with a lost client's forces: hold the machine (the default) or release them.
ON_LOST = ("hold", "release")
#: How long a client's write waits for the simulation thread to take it (the thread takes writes between
#: chunks, every few ms; longer means the simulation is stopped or failed).
WRITE_TIMEOUT = 2.0

DEFAULT_ENDPOINT = "opc.tcp://127.0.0.1:4840/ncfmu"
#: The server's ApplicationUri (OPC UA Part 4 7.2), also the URI its certificate carries (``--make-certificate``)
APPLICATION_URI = "urn:ncfmu:serve"
PRODUCT_URI = "urn:ncfmu"

#: UNECE codes (OPC UA EngineeringUnits, namespace below) of the units our FMUs declare.
UNECE_NAMESPACE = "http://www.opcfoundation.org/UA/units/un/cefact"
UNECE = {"mm": "MMT", "s": "SEC", "mm/s": "C16", "mm/s2": "M41", "1": "C62", "N.m": "NU", "1/s": "1/s",
         "kg.m2": "B32", "rad/s": "2A", "rev/min": "RPM"}


def _unece_id(code: str) -> int:
    """The UnitId of a UNECE common code (OPC UA Part 8: the code's characters packed into an Int32)."""
    if code == "1/s":
        return -1
    value = 0
    for ch in code:
        value = (value << 8) | ord(ch)
    return value


# -- the served variables -------------------------------------------------------------------------
@dataclass(frozen=True)
class Point:
    """One FMU variable as the server shows it."""

    name: str               # INSTANCE.VARIABLE, the NodeId's string
    instance: str
    variable: str
    type: str               # Real, Integer, Boolean, String (Enumeration served as Integer)
    causality: str
    variability: str
    unit: str | None
    description: str
    minimum: float | None
    maximum: float | None

    @property
    def writes(self) -> str | None:
        """``"input"`` (forcing), ``"parameter"`` (a tunable parameter) or None (read-only)."""
        if self.causality == "input":
            return "input"
        if self.causality == "parameter" and self.variability == "tunable":
            return "parameter"
        return None

    def rule(self) -> str:
        low = "" if self.minimum is None else f">= {self.minimum:g}"
        high = "" if self.maximum is None else f"<= {self.maximum:g}"
        return " and ".join(p for p in (low, high) if p) or "finite"


def points_of(slaves: Sequence) -> list[Point]:
    """Every variable of every FMU, in system order, as its modelDescription declares it."""
    return [Point(f"{s.name}.{v.name}", s.name, v.name, "Integer" if v.type == "Enumeration" else v.type,
                  v.causality, v.variability or "continuous", v.unit, v.description or "", v.min, v.max)
            for s in slaves for v in s.variables.values()]


class WriteRefused(NcfmuError):
    """A client's write that changes nothing; ``status`` is the OPC UA status code's name."""

    def __init__(self, status: str, message: str) -> None:
        super().__init__(message)
        self.status = status


def check_value(point: Point, value: object) -> object:
    """``value`` (already of the node's OPC UA type) checked against the port's rule, or :class:`WriteRefused`."""
    if point.writes is None:
        what = "an output" if point.causality == "output" else f"a {point.variability} {point.causality}"
        raise WriteRefused("BadNotWritable", f"{point.name} is {what}: not writable")
    if point.type == "Real":
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise WriteRefused("BadTypeMismatch", f"{point.name} = {value!r}: must be a Double")
        x = float(value)
        if not math.isfinite(x):
            raise WriteRefused("BadOutOfRange", f"{point.name} = {x!r}: must be finite")
        if (point.minimum is not None and x < point.minimum) or (point.maximum is not None and x > point.maximum):
            raise WriteRefused("BadOutOfRange", f"{point.name} = {x!r}: must be {point.rule()}")
        return x
    if point.type == "Integer":
        if isinstance(value, bool) or not isinstance(value, int):
            raise WriteRefused("BadTypeMismatch", f"{point.name} = {value!r}: must be an Int32")
        if (point.minimum is not None and value < point.minimum) or (point.maximum is not None
                                                                      and value > point.maximum):
            raise WriteRefused("BadOutOfRange", f"{point.name} = {value!r}: must be {point.rule()}")
        return int(value)
    if point.type == "Boolean":
        if not isinstance(value, bool):
            raise WriteRefused("BadTypeMismatch", f"{point.name} = {value!r}: must be a Boolean")
        return value
    if not isinstance(value, str):
        raise WriteRefused("BadTypeMismatch", f"{point.name} = {value!r}: must be a String")
    return value


# -- recording ------------------------------------------------------------------------------------------
class Recorder:
    """Where a served run's recording goes (``--out DIR``): ``DIR/<system>.csv`` (every output, or ``--record``)
    and ``DIR/session_inputs.csv`` (the writes that took effect, an input CSV ``ncfmu run --input`` replays).

    A Reset ends a recording segment (the session starts again from its start values): the segment before the
    k-th Reset is kept as ``<system>.segment<k>.csv`` and ``session_inputs.segment<k>.csv``; the two files
    without a number always hold the run since the last Reset.
    """

    def __init__(self, system: str, out: Path) -> None:
        self.system, self.out = system, Path(out)
        self.segments = 0
        self.files: list[Path] = []
        self.out.mkdir(parents=True, exist_ok=True)

    @property
    def trajectory(self) -> Path:
        return self.out / f"{self.system}.csv"

    def sinks(self) -> list:
        from .cosim.record import CsvSink
        return [CsvSink(self.trajectory)]

    def end_segment(self, writes: Sequence[tuple[float, str, object]], final: bool, start: float = 0.0) -> None:
        """After the session closed its sinks: name the segment's files and write its writes (a segment without
        writes: one row at its ``start`` time that changes nothing -- an input CSV with a header and no rows is
        refused by ``ncfmu run --input`` as a mistake)."""
        from .cosim.master import write_input_csv
        from .files import write_atomic

        def inputs(path: Path) -> Path:
            if writes:
                return write_input_csv(path, writes)
            write_atomic(path, f'"time"\n{float(start)!r}\n'.encode())
            return path
        if final:
            self.files.append(inputs(self.out / "session_inputs.csv"))
            for path in (self.trajectory, self.trajectory.with_name(self.trajectory.name + ".partial")):
                if path.exists():
                    self.files.append(path)
            return
        self.segments += 1
        k = self.segments
        if self.trajectory.exists():
            self.files.append(self.trajectory.replace(self.out / f"{self.system}.segment{k}.csv"))
        self.files.append(inputs(self.out / f"session_inputs.segment{k}.csv"))


# -- the simulation thread ------------------------------------------------------------------------------
@dataclass
class _Command:
    what: str                       # force, release, set, pause, resume, stop, reset, hold
    name: str = ""
    value: object = None
    done: Callable[[str | None], None] | None = None    # called with None (applied) or the refusal's text


@dataclass
class Snapshot:
    """The values at one communication point, with the simulation's state as it was then."""

    time: float
    values: dict[str, object]
    forced: dict[str, object]
    state: str = "running"
    reason: str = ""
    lag: float = 0.0
    overruns: int = 0
    crashes: tuple = ()              # the part check's crash records so far (ncfmu.machining.Crash)
    verdicts: tuple = ()             # the part check's verdicts so far: (program end's time, summary line)


def program_ends(report) -> list[tuple[str, bool]]:
    """Where a part check's program ends, as (column, True: its rising edge, False: its falling edge): a lathe's
    or mill's part check is judged when its cycle says done, a grinder's after each cycle (RUN falls)."""
    from .systems.part import GrindPart, MachinedPart
    ends: list[tuple[str, bool]] = []
    for part in report.parts:
        if isinstance(part, MachinedPart):
            ends.append((part.done_column(), True))
        elif isinstance(part, GrindPart):
            ends.append((f"{part.feed}.run", False))
    return ends


def verdict_text(verdict) -> str:
    """A part check's verdict as ``Simulation.verdict`` and the printed line say it: its summary on one line."""
    return "; ".join(line.strip() for line in verdict.summary())


def crash_text(c) -> str:
    """One crash as ``Simulation.crash`` and the event's Message say it."""
    return f"crash at t = {c.t:.3f} s, line {c.line}: {c.what}, {c.depth_mm:.3g} mm deep"


class CrashWatch:
    """A served run's part check: its accumulator is one of the session's sinks (a new one after each Reset),
    and the crashes it saw so far are read after each hand-over of rows.

    The check's work (shapely: 1-17 ms a hand-over for the lathes, measured) runs in a thread of its own,
    ``ncfmu-part-check``, at most one hand-over behind: the simulation thread hands a copy of the rows over and
    goes on; the next hand-over first waits for the previous check. With :attr:`wait_every_time` (--speed 0)
    each hand-over waits for its own check too: the run is deterministic. What the check says comes from the
    rows, not from when it judged them."""

    def __init__(self, report, parameters, record: Sequence[str] | None = None) -> None:
        self.report, self.parameters = report, parameters
        self.record = list(record) if record else None       # --record: what the recording's sinks keep
        #: wait for each hand-over's check (--speed 0); else a check runs beside the next hand-over's steps
        self.wait_every_time = False
        #: a check finished since :meth:`crashes` was last read
        self.fresh = False
        self._jobs: queue.SimpleQueue[tuple[object, np.ndarray] | None] = queue.SimpleQueue()
        self._idle = threading.Event()
        self._idle.set()
        self._error: BaseException | None = None
        self._seen: list = []
        #: the verdicts given so far, at each program end (the part check's summary line then)
        self._verdicts: list[tuple[float, str]] = []
        self._ends = program_ends(report)
        self._flags: dict[str, bool] = {}          # each end column's value at the last row judged
        self._thread: threading.Thread | None = None
        self._closed = False
        self.accumulator = self.new_accumulator()

    def sinks(self, recording: Sequence) -> list:
        """A segment's sinks: the recording's (kept to ``--record``) and a new part check."""
        from .cosim.record import SelectColumns
        kept = list(recording) if self.record is None else [SelectColumns(k, self.record) for k in recording]
        return [*kept, self.new()]

    def new_accumulator(self):
        self._idle.wait()               # the previous segment's last check done: what it finds is not this one's
        self.accumulator = self.report.accumulator(self.parameters)
        self._seen, self.fresh = [], False
        self._verdicts, self._flags = [], {}
        return self.accumulator

    def new(self) -> _PartCheckSink:
        return _PartCheckSink(self, self.new_accumulator())

    def crashes(self) -> list:
        """The crashes of the rows judged so far (up to the last hand-over whose check finished)."""
        self.fresh = False
        return list(self._seen)

    def verdicts(self) -> list[tuple[float, str]]:
        """The verdicts of the programs that ended in the rows judged so far: (the end's time, the summary)."""
        return list(self._verdicts)

    def hand_over(self, accumulator, rows: np.ndarray) -> None:
        """Give ``rows`` (copied: the session reuses its window) to the check, after the previous check."""
        self.wait()
        rows = np.array(rows, copy=True)
        if self._closed:
            self._judge(accumulator, rows)
            return
        if self._thread is None:
            self._thread = threading.Thread(target=self._main, name="ncfmu-part-check", daemon=True)
            self._thread.start()
        self._idle.clear()
        self._jobs.put((accumulator, rows))
        if self.wait_every_time:
            self.wait()

    def wait(self) -> None:
        """Until the check handed over last is done; what it raised is raised here (the simulation fails)."""
        self._idle.wait()
        if self._error is not None:
            error, self._error = self._error, None
            raise error

    def close(self) -> None:
        """End the thread (the serve is over; what comes after is checked in the caller's thread)."""
        self._closed = True
        if self._thread is not None:
            self._jobs.put(None)
            self._thread.join()
            self._thread = None

    def _judge(self, accumulator, rows: np.ndarray) -> None:
        from .systems.part import crashes_so_far, verdict_of
        accumulator.write(rows)
        if accumulator is self.accumulator:
            self._seen = crashes_so_far(accumulator)
            ended = self._program_end(rows)
            if ended is not None:
                verdict = verdict_of(accumulator)
                if verdict is not None:
                    self._verdicts.append((ended, verdict_text(verdict)))
            self.fresh = True

    def _program_end(self, rows: np.ndarray) -> float | None:
        """The time of the last program end in ``rows`` (None: none ended there)."""
        end: float | None = None
        for column, rising in self._ends:
            if not len(rows) or column not in (rows.dtype.names or ()):
                continue
            flag = rows[column].astype(bool)
            before = np.concatenate(([self._flags.get(column, False)], flag[:-1]))
            edges = np.flatnonzero(flag & ~before if rising else ~flag & before)
            self._flags[column] = bool(flag[-1])
            if len(edges):
                t = float(rows["time"][edges[-1]])
                end = t if end is None else max(end, t)
        return end

    def _main(self) -> None:
        while True:
            job = self._jobs.get()
            if job is None:
                return
            try:
                self._judge(*job)
            except BaseException as err:      # raised in the simulation thread at its next hand-over
                self._error = err
            finally:
                self._idle.set()


class _PartCheckSink:
    """The part check's accumulator as a session sink whose ``write`` hands the rows to :class:`CrashWatch`'s
    thread; ``open`` and ``close`` happen once the check is idle."""

    def __init__(self, watch: CrashWatch, accumulator) -> None:
        self.watch, self.accumulator = watch, accumulator

    def open(self, columns: list[tuple[str, np.dtype]]) -> None:
        self.watch.wait()
        self.accumulator.open(columns)

    def write(self, rows: np.ndarray) -> None:
        self.watch.hand_over(self.accumulator, rows)

    def close(self, complete: bool, stopped_at: float | None = None, reason: str = "") -> None:
        self.watch.wait()
        self.accumulator.close(complete, stopped_at, reason)


class PaceStats:
    """The lag after every chunk, as a histogram (10 µs bins up to 1 s; bounded memory however long the run),
    its exact maximum, and the overruns."""

    BIN = 1e-5
    BINS = 100_000

    def __init__(self) -> None:
        self.counts = np.zeros(self.BINS + 1, dtype=np.int64)
        self.count = 0
        self.max = 0.0
        self.overruns = 0

    def add(self, lag: float) -> None:
        self.counts[min(max(int(lag / self.BIN), 0), self.BINS)] += 1
        self.count += 1
        self.max = max(self.max, lag)

    def percentile(self, q: float) -> float:
        """The lag that ``q`` percent of the chunks did not exceed (to the bin's upper edge, at most the max)."""
        if not self.count:
            return 0.0
        k = int(np.searchsorted(np.cumsum(self.counts), q / 100.0 * self.count, side="left"))
        return self.max if k >= self.BINS else min((k + 1) * self.BIN, self.max)     # the last bin: beyond 1 s

    def percentiles(self) -> tuple[float, float, float]:
        return self.percentile(50), self.percentile(99), self.max


class Runner:
    """Paces a session in a worker thread (see the module's docstring)."""

    def __init__(self, session, points: Sequence[Point], speed: float = 1.0, recorder: Recorder | None = None,
                 on_state: Callable[[], None] | None = None,
                 check_parameter: Callable[[str, object], None] | None = None,
                 watch: CrashWatch | None = None) -> None:
        if not (math.isfinite(speed) and speed >= 0):
            raise ConfigError("--speed", speed, "must be a number >= 0 (0: as fast as possible)")
        self.session, self.speed, self.recorder = session, float(speed), recorder
        self.points = list(points)
        #: a tunable parameter's value checked by the model's own rules on a copy before the FMU sees it
        #: (ConfigError: refused, nothing applied, nothing recorded)
        self.check_parameter = check_parameter
        self.start_time = float(session.time)
        #: the writes of the segments before the last Reset (the session's own log restarts at a Reset)
        self.earlier_writes: list[tuple[float, str, object]] = []
        self.state, self.reason = "running", ""
        #: the feed-hold inputs (Boolean inputs named FEED_HOLD_INPUT): what a hold forces true while the
        #: simulation runs on; a system without one halts when held (a stop, as a machine without feed hold has)
        self.feed_holds = [p.name for p in self.points
                           if p.causality == "input" and p.type == "Boolean" and p.variable == FEED_HOLD_INPUT]
        #: held: the inputs kept forced until Resume (a lost client's forces and the feed holds)
        self.held: set[str] = set()
        #: the part check (None: the system has none), the crashes it saw and when it was last handed rows
        self.watch = watch
        if watch is not None:
            watch.wait_every_time = self.speed == 0      # as fast as possible: deterministic, as `ncfmu run`
        self.crashes: tuple = ()
        self.verdicts: tuple = ()            # the part check's verdicts at each program end (CrashWatch.verdicts)
        self._checked = float(session.time)
        self.stats = PaceStats()
        self.lag = 0.0
        self.started, self.wall = 0.0, 0.0      # perf_counter at the thread's start; its wall time to the end
        self.commands: queue.SimpleQueue[_Command] = queue.SimpleQueue()
        self._snapshot: Snapshot | None = None
        self._snapshot_lock = threading.Lock()
        self._want_snapshot = True
        self._stop = threading.Event()
        self._said_overrun = False
        self._on_state = on_state
        self.thread = threading.Thread(target=self._main, name="ncfmu-simulation", daemon=True)
        self._take_snapshot()
        assert self._snapshot is not None
        # fixed parameters (and the rest that no step changes): read once, published with the first snapshot
        for p in self.points:
            if p.name not in self._snapshot.values:
                self._snapshot.values[p.name] = session.value(p.name)

    # -- called from the server's thread -----------------------------------------------------------
    def start(self) -> None:
        self.thread.start()

    def submit(self, command: _Command) -> None:
        self.commands.put(command)

    def snapshot(self) -> Snapshot | None:
        """The newest snapshot (and ask for the next one)."""
        with self._snapshot_lock:
            snap, self._snapshot = self._snapshot, None
        self._want_snapshot = True
        return snap

    def stop(self, reason: str = "") -> None:
        self.submit(_Command("stop", value=reason))
        self._stop.set()

    # -- the thread ----------------------------------------------------------------------------------
    def _take_snapshot(self) -> None:
        s = self.session
        values = s.outputs()
        for p in self.points:
            if p.causality == "input" or p.writes == "parameter":
                values[p.name] = s.value(p.name)
        forced = dict(s.forced())
        values.update(forced)       # a forced input shows its forced value as soon as it is forced
        with self._snapshot_lock:
            self._snapshot = Snapshot(float(s.time), values, forced, self.state, self.reason, self.lag,
                                      self.stats.overruns, self.crashes, self.verdicts)
        self._want_snapshot = False

    def _apply(self, c: _Command) -> bool:
        """Apply one command; True when the pacing's origin must move (pause, reset)."""
        s = self.session
        rebase = False
        refusal: str | None = None
        try:
            if c.what in ("force", "release") and c.name in self.held:
                refusal = f"the simulation is held: {self.reason}"
            elif c.what == "force":
                s.force(c.name, c.value)
            elif c.what == "release":
                s.release(c.name)
            elif c.what == "hold":
                rebase = self._hold(*c.value)          # type: ignore[misc]
            elif c.what == "set":
                if self.check_parameter is not None:
                    self.check_parameter(c.name, c.value)
                s.set_parameter(c.name, c.value)
            elif c.what == "pause":
                if self.state == "running":
                    self.state = "paused"
                elif self.state == "held":
                    refusal = f"the simulation is held: {self.reason}"
            elif c.what == "resume":
                if self.state == "paused":
                    self.state, rebase = "running", True
                elif self.state == "held":           # a client acknowledges the lost one: what it held falls back
                    for name in sorted(self.held):
                        s.release(name)
                    self.held.clear()
                    self.state, self.reason, rebase = "running", "", True
                elif self.state != "running":
                    refusal = f"the simulation is {self.state}"
            elif c.what == "reset":
                if self.state in ("stopped", *ENDED_BADLY):
                    refusal = f"the simulation is {self.state}"
                else:
                    writes = list(s.writes)
                    rec = self.recorder
                    recording = rec.sinks() if rec is not None else []
                    s.reset(self.watch.sinks(recording) if self.watch is not None else recording)
                    self.earlier_writes += writes
                    if rec is not None:
                        rec.end_segment(writes, final=False, start=self.start_time)
                    if self.state in ("crashed", "held"):      # a new run: no crash yet, nothing forced
                        self.state, self.reason = "running", ""
                    self.held.clear()
                    self.crashes, self.verdicts, self._checked = (), (), float(s.time)
                    rebase = True
            elif c.what == "stop":
                self.state, self.reason = "stopped", str(c.value or "Stop called")
                self._stop.set()
        except (ConfigError, NcfmuError) as err:
            refusal = str(err)
        if c.done is not None:
            # the snapshot first: once a client has its answer, what it reads next shows the command's effect
            # (Simulation.state "paused" as soon as Pause returned)
            self._take_snapshot()
            c.done(refusal)
        else:
            self._want_snapshot = True
        return rebase

    def _hold(self, why: str, names: Sequence[str]) -> bool:
        """A client that forced ``names`` is lost (``--on-lost hold``): the machine goes to feed hold -- each
        feed-hold input forced true, the lost client's forces kept -- and stays there until a client calls
        Resume (or Reset). Without a feed-hold input the simulation halts. True when the pacing's origin must
        move (a paused simulation runs on held)."""
        s = self.session
        if self.state not in ("running", "paused", "held"):
            # crashed, stopped or failed: nothing moves anyway; its forces fall back as a release would have it
            for name in names:
                if name not in self.held:
                    s.release(name)
            return False
        for name in self.feed_holds:
            s.force(name, True)
        self.held.update(names)
        self.held.update(self.feed_holds)
        was = self.state
        if was != "held":
            self.state, self.reason = "held", why
        return was == "paused"

    def _stepping(self) -> bool:
        """Whether the simulation steps in its present state (held: on, with its feed held, if it has a feed
        hold; else it stands)."""
        return self.state == "running" or (self.state == "held" and bool(self.feed_holds))

    def _check_crashes(self, hand_over: bool) -> None:
        """Hand the rows so far to the part check (``hand_over``) and read what it found; at its first crash
        the simulation halts ("crashed"), with the crash's records those of every row up to the halt. A program
        that ended: its verdict joins :attr:`verdicts`."""
        s = self.session
        assert self.watch is not None
        if hand_over:
            self._checked = float(s.time)
            s.flush()
        crashes = self.watch.crashes()
        if len(crashes) > len(self.crashes):
            if self.state in ("running", "held"):
                # the check may be a hand-over behind: the rows simulated since are judged before the halt
                # (a crash goes deeper until it halts; its depth is the rows', as a synchronous check has it)
                s.flush()
                self.watch.wait()
                crashes = self.watch.crashes()
                self._checked = float(s.time)
                self.state, self.reason = "crashed", crash_text(crashes[len(self.crashes)])
                log.error("ncfmu serve: %s; the simulation halts (Reset starts again)", self.reason)
            self.crashes = tuple(crashes)
            self._take_snapshot()
        verdicts = self.watch.verdicts()
        if len(verdicts) > len(self.verdicts):       # a program ended: its verdict is published
            self.verdicts = tuple(verdicts)
            self._take_snapshot()

    def _main(self) -> None:
        s, h = self.session, self.session.step_size
        stop_time = s.stop_time
        wall0, sim0 = _time.perf_counter(), s.time
        self.started = wall0
        # the fewest steps worth waking up for: a chunk every MIN_CHUNK_WALL at least (1 step at real time)
        min_steps = max(1, int(MIN_CHUNK_WALL * self.speed / h + 1e-9)) if self.speed > 0 else 1
        behind = False
        try:
            while not self._stop.is_set():
                rebase = False
                while True:
                    try:
                        c = self.commands.get_nowait()
                    except queue.Empty:
                        break
                    rebase |= self._apply(c)
                if self._stop.is_set():
                    break
                if rebase:
                    wall0, sim0 = _time.perf_counter(), s.time
                if not self._stepping():
                    if self._want_snapshot:
                        self._take_snapshot()
                    try:
                        c = self.commands.get(timeout=0.005)
                    except queue.Empty:
                        continue
                    if self._apply(c):
                        wall0, sim0 = _time.perf_counter(), s.time
                    continue
                remaining = int(round((stop_time - s.time) / h)) if math.isfinite(stop_time) else 1 << 62
                if remaining <= 0:
                    self.state, self.reason = "stopped", f"stop time {stop_time:g} s reached"
                    break
                if self.speed > 0:
                    now = _time.perf_counter()
                    due = int(math.floor(((now - wall0) * self.speed - (s.time - sim0)) / h + 1e-9))
                    if due < min_steps:
                        # sleep until a chunk is due (at most 5 ms: commands are taken in between)
                        wait = (s.time + min_steps * h - sim0) / self.speed - (now - wall0)
                        try:
                            c = self.commands.get(timeout=min(max(wait, 0.0), 0.005))
                        except queue.Empty:
                            continue
                        if self._apply(c):
                            wall0, sim0 = _time.perf_counter(), s.time
                        continue
                    n = min(due, remaining, max(1, int(MAX_CHUNK_WALL * self.speed / h)))
                else:
                    n = min(FAST_CHUNK, remaining)
                s.advance(n)
                if self.watch is not None:
                    if s.time - self._checked >= CRASH_CHECK - 1e-9:
                        self._check_crashes(hand_over=True)
                    elif self.watch.fresh:        # the check of the last hand-over finished meanwhile
                        self._check_crashes(hand_over=False)
                if self.speed > 0:
                    lag = _time.perf_counter() - (wall0 + (s.time - sim0) / self.speed)
                    self.lag = lag
                    self.stats.add(lag)
                    if lag <= OVERRUN_LAG:
                        behind = False
                    elif not behind:            # one overrun per time it falls behind, however long it takes
                        behind = True           # to catch up again
                        self.stats.overruns += 1
                        if not self._said_overrun:
                            self._said_overrun = True
                            log.warning("ncfmu serve: cannot keep the pace at --speed %g: t = %.3f s finished "
                                        "%.1f ms late (overruns are counted in Simulation.overruns)",
                                        self.speed, s.time, lag * 1e3)
                else:
                    _time.sleep(0)          # hand the GIL to the server between chunks
                if self._want_snapshot:
                    self._take_snapshot()
        except TerminationRequested as ended:
            # an FMU asked to end (fmi2Discard + terminateSimulation): the run's clean end, as `ncfmu run` has it --
            # stopped, not failed, and the session closes complete (its CSV renamed, its summary written)
            s.failed = None
            self.state, self.reason = "stopped", str(ended)
            log.info("ncfmu serve: %s", ended)
        except FmuCrashed as err:    # a foreign FMU's process died (ncfmu.cosim.isolated): the server lives on
            self.state, self.reason = "faulted", str(err)
            log.error("ncfmu serve: the simulation faulted at t = %.3f s: %s", s.time, err)
        except SimulationError as err:
            self.state, self.reason = "failed", str(err)
            log.error("ncfmu serve: the simulation failed at t = %.3f s: %s", s.time, err)
        except Exception as err:     # anything else from an FMU call: the run has failed, the server lives on
            self.state, self.reason = "failed", f"{type(err).__name__}: {err}"
            log.exception("ncfmu serve: the simulation failed at t = %.3f s", s.time)
        finally:
            self.wall = _time.perf_counter() - self.started
            if self.state in ("running", "held"):
                self.state = "stopped"
            try:
                self._take_snapshot()
            except Exception:
                pass
            # answer every write still waiting: nothing applies them any more
            while True:
                try:
                    c = self.commands.get_nowait()
                except queue.Empty:
                    break
                if c.done is not None:
                    c.done(f"the simulation is {self.state}")
            if self._on_state is not None:
                self._on_state()


# -- OPC UA for CNC Systems (OPC 40502) ----------------------------------------------------------------------
CNC_NAMESPACE = "http://opcfoundation.org/UA/CNC"
#: The OPC Foundation's published NodeSet of OPC 40502 v1.00 (OPC Foundation MIT License 1.00, in its header),
#: as node-opcua's npm package node-opcua-nodesets ships it.
CNC_NODESET = Path(__file__).parent / "data" / "Opc.Ua.CNC.NodeSet2.xml"
#: The models whose instances the companion model shows: an axis, a spindle, a channel (an NC cycle controller)
CNC_AXIS_MODELS = ("ServoAxis",)
CNC_SPINDLE_MODELS = ("SpindleDrive",)
# the enumerations' values (OPC 40502 6.x: CncAxisStatus, CncChannelProgramStatus, CncChannelStatus, ...)
AXIS_IN_POSITION, AXIS_MOVING = 0, 1
PROGRAM_STOPPED, PROGRAM_RUNNING, PROGRAM_WAITING, PROGRAM_INTERRUPTED, PROGRAM_CANCELED = 0, 1, 2, 3, 4
CHANNEL_RESET, CHANNEL_INTERRUPTED, CHANNEL_ACTIVE = 0, 1, 2
MODE_AUTOMATIC = 2
SPINDLE_STOPPED, SPINDLE_IN_TARGET, SPINDLE_ACCELERATING = 0, 1, 2
TURN_NONE, TURN_CW, TURN_CCW = 0, 1, 2


def cnc_types_xml(path: Path = CNC_NODESET) -> str:
    """The NodeSet's types only: the published file also holds example instances (``test`` under Objects, axes
    ``X``, ``Y``, ``Channel_1`` ... without a parent) that asyncua refuses and a client must not see. They are
    left out, with every reference to them."""
    import xml.etree.ElementTree as ET
    ua_ns = "http://opcfoundation.org/UA/2011/03/UANodeSet.xsd"
    ET.register_namespace("", ua_ns)
    root = ET.parse(path).getroot()

    def q(tag: str) -> str:
        return f"{{{ua_ns}}}{tag}"
    instances = {n.get("NodeId"): n for n in root if n.tag in (q("UAObject"), q("UAVariable"), q("UAMethod"))}

    def type_definition(n) -> str:
        for r in n.iter(q("Reference")):
            if r.get("ReferenceType") == "HasTypeDefinition":
                return r.text or ""
        return ""
    dropped: set[str | None] = set()
    changed = True
    while changed:
        changed = False
        for nid, n in instances.items():
            if nid in dropped:
                continue
            example = not n.get("ParentNodeId") and type_definition(n).startswith(("ns=1;", "i=61"))
            if example or n.get("ParentNodeId") in dropped:
                dropped.add(nid)
                changed = True
    for n in list(root):
        if n.get("NodeId") in dropped:
            root.remove(n)
            continue
        refs = n.find(q("References"))
        for r in list(refs) if refs is not None else ():
            if r.text in dropped:
                refs.remove(r)         # type: ignore[union-attr]
    return ET.tostring(root, encoding="unicode")


@dataclass
class _Mirror:
    """A node of the companion model that shows a function of the served values."""

    node: object
    vtype: object
    value: Callable[[Mapping[str, object]], object]


async def build_cnc_model(server, idx: int, system: str, components: Mapping[str, str],
                          points: Mapping[str, Point], values: Mapping[str, object] | None = None) -> list[_Mirror]:
    """The served system as an OPC 40502 ``CncInterfaceType`` object ``Objects/CncInterface`` (NodeIds
    ``ns=<idx>;s=Cnc...``): ``CncAxisList`` (an axis per servo axis: ``PosDirect``/``PosIndirect`` ``ActPos`` =
    the axis's ``pos``, ``CmdPos`` = its ``pos_cmd``, ``RemDist`` = CmdPos - ActPos, mm, with EngineeringUnits and
    EURange; ``ActStatus`` in position or moving; ``ActTorque`` within +-``torque_max``), ``CncChannelList`` (a
    channel per NC cycle controller: program status, the system's name as the active program, the block -- the
    part program's line where the controller says it, else its block number --, feed override % within its
    port's range, feed hold, mode automatic) and ``CncSpindleList`` (a spindle per spindle drive: speeds within
    +-``speed_max``, torque, power, status, turn direction). With one channel, each drive's ``ActChannel`` is
    it. What the served system has nothing for: a mandatory variable reads Bad_NotConnected (never the 0 or the
    empty value a client would take for known), an optional one is left out (:func:`_settle_unvalued`).
    ``values``: the served values at the start (the parameters' for the ranges). The mirrors that keep the
    model current."""
    from asyncua import ua

    from . import __version__
    from .catalogue import models
    from .controllers.cycle import CycleController
    await server.import_xml(xmlstring=cnc_types_xml())
    cnc = await server.get_namespace_index(CNC_NAMESPACE)
    start = dict(values or {})
    fed: set = set()            # the NodeIds of what ncfmu writes or mirrors

    def nid(name: str):
        return ua.NodeId(ua.String(name), ua.Int16(idx))

    def t(number: int):
        return ua.NodeId(ua.Int32(number), ua.Int16(cnc))
    async def add(parent, name: str, node_id: str, type_number: int):
        # asyncua instantiates a type's optional placeholders too (CncChannelType's <CncAxis>, <CncSpindle>):
        # a client would browse them as members, zero-filled; a placeholder is the type's, not an instance's
        obj = await parent.add_object(nid(node_id), ua.QualifiedName(name, idx), objecttype=t(type_number))
        for c in await obj.get_children():
            if (await c.read_browse_name()).Name.startswith("<"):
                await server.delete_nodes([c], recursive=True)
        return obj

    async def child(parent, path: str):
        # the NodeSet's own browse names, or OPC UA's (an AnalogUnitType's EURange is 0:EURange)
        node = parent
        for p in path.split("/"):
            try:
                node = await node.get_child([f"{cnc}:{p}"])
            except ua.UaStatusCodeError:
                node = await node.get_child([f"0:{p}"])
        return node

    async def put(parent, path: str, value) -> None:
        node = await child(parent, path)
        await node.write_value(value)
        fed.add(node.nodeid)

    def limit(name: str) -> float | None:
        v = start.get(name)
        return float(v) if isinstance(v, (int, float)) and math.isfinite(v) and v > 0 else None

    async def symmetric(parent, path: str, name: str, scale: float = 1.0) -> None:
        # a range ncfmu knows: +- a limit parameter of the component (speed_max, torque_max, power_max)
        v = limit(name)
        if v is not None:
            await put(parent, f"{path}/EURange", ua.Range(Low=-v * scale, High=v * scale))
    iface = await add(server.nodes.objects, "CncInterface", "Cnc", 1007)
    for name, value in (("VendorName", "ncfmu"), ("VendorRevision", __version__), ("Version", "1.00"),
                        ("CncTypeName", f"ncfmu {system}")):
        try:
            node = await iface.get_child([f"{cnc}:{name}"])
        except ua.UaStatusCodeError:             # an optional property: added
            node = await iface.add_property(nid(f"Cnc.{name}"), ua.QualifiedName(name, cnc), value)
        await node.write_value(ua.Variant(value, ua.VariantType.String))
        fed.add(node.nodeid)
    mirrors: list[_Mirror] = []
    D, I32, B, S, U32 = (ua.VariantType.Double, ua.VariantType.Int32, ua.VariantType.Boolean,
                         ua.VariantType.String, ua.VariantType.UInt32)

    async def mirror(parent, path: str, vtype, fn) -> None:
        node = await child(parent, path)
        mirrors.append(_Mirror(node, vtype, fn))
        fed.add(node.nodeid)

    def real(name: str) -> Callable[[Mapping[str, object]], float]:
        return lambda v: float(v.get(name) or 0.0)          # type: ignore[arg-type]
    logic = models()
    # CncPositionDataType: the class import_xml made from the NodeSet's definition
    position = ua.CncPositionDataType         # type: ignore[attr-defined]
    axis_list = await iface.get_child([f"{cnc}:CncAxisList"])
    spindle_list = await iface.get_child([f"{cnc}:CncSpindleList"])
    channel_list = await iface.get_child([f"{cnc}:CncChannelList"])
    channel_id = 0
    drives, channels = [], []
    for inst, model in components.items():
        if model in CNC_AXIS_MODELS:
            axis = await add(axis_list, inst, f"Cnc.{inst}", 1004)
            drives.append(axis)
            pos, cmd = f"{inst}.pos", f"{inst}.pos_cmd"
            low = points[cmd].minimum if cmd in points else None
            high = points[cmd].maximum if cmd in points else None
            eu = ua.EUInformation(NamespaceUri=UNECE_NAMESPACE, UnitId=_unece_id("MMT"),
                                  DisplayName=ua.LocalizedText("mm"), Description=ua.LocalizedText("millimetre"))
            span = ua.Range(Low=-math.inf if low is None else low, High=math.inf if high is None else high)
            for which in ("PosDirect", "PosIndirect"):
                await put(axis, f"{which}/EngineeringUnits", eu)
                await put(axis, f"{which}/EURange", span)
                # the position variable's own value, the structure of the three (what a client reads whole)
                await mirror(axis, which, ua.VariantType.ExtensionObject, lambda v, pos=pos, cmd=cmd: position(
                    ActPos=real(pos)(v), CmdPos=real(cmd)(v), RemDist=real(cmd)(v) - real(pos)(v)))
                await mirror(axis, f"{which}/ActPos", D, real(pos))
                await mirror(axis, f"{which}/CmdPos", D, real(cmd))
                await mirror(axis, f"{which}/RemDist", D,
                             lambda v, pos=pos, cmd=cmd: real(cmd)(v) - real(pos)(v))
            await mirror(axis, "ActStatus", I32, lambda v, inst=inst: AXIS_IN_POSITION
                         if v.get(f"{inst}.in_position") else AXIS_MOVING)
            await mirror(axis, "ActTorque", D, real(f"{inst}.torque"))
            await symmetric(axis, "ActTorque", f"{inst}.torque_max")
            await mirror(axis, "IsInactive", B, lambda v, inst=inst: not v.get(f"{inst}.enable", True))
            await put(axis, "IsReferenced", True)
            await put(axis, "IsRotational", False)         # a servo axis of ncfmu is linear, in mm
            await put(axis, "IsVirtual", False)
        elif model in CNC_SPINDLE_MODELS:
            spindle = await add(spindle_list, inst, f"Cnc.{inst}", 1005)
            drives.append(spindle)
            speed, cmd = f"{inst}.speed", f"{inst}.speed_cmd"
            await mirror(spindle, "ActSpeed", D, real(speed))
            await mirror(spindle, "CmdSpeed", D, real(cmd))
            for which in ("ActSpeed", "CmdSpeed"):      # rev/min, signed: as the NodeSet's min⁻¹
                await symmetric(spindle, which, f"{inst}.speed_max")
            await mirror(spindle, "ActTorque", D, real(f"{inst}.torque"))
            await symmetric(spindle, "ActTorque", f"{inst}.torque_max")
            await mirror(spindle, "ActPower", D, lambda v, inst=inst: 1e3 * real(f"{inst}.power")(v))   # kW -> W
            await symmetric(spindle, "ActPower", f"{inst}.power_max", 1e3)
            await mirror(spindle, "ActStatus", I32, lambda v, inst=inst, speed=speed: SPINDLE_STOPPED
                         if abs(real(speed)(v)) < 1e-9 else SPINDLE_IN_TARGET if v.get(f"{inst}.at_speed")
                         else SPINDLE_ACCELERATING)
            await mirror(spindle, "ActTurnDirection", I32, lambda v, speed=speed: TURN_NONE
                         if abs(real(speed)(v)) < 1e-9 else TURN_CW if real(speed)(v) > 0 else TURN_CCW)
            await mirror(spindle, "IsInactive", B, lambda v, inst=inst: not v.get(f"{inst}.enable", True))
            await put(spindle, "IsVirtual", False)
        elif model in logic and issubclass(logic[model], CycleController):
            channel_id += 1
            channel = await add(channel_list, inst, f"Cnc.{inst}", 1002)
            channels.append(channel)
            block = next((f"{inst}.{b}" for b in ("line", "block_no", "pc", "segment") if f"{inst}.{b}" in points),
                         None)

            def program_status(v, inst=inst) -> int:
                if v.get(f"{inst}.alarm"):
                    return PROGRAM_CANCELED
                if not v.get(f"{inst}.busy"):
                    return PROGRAM_STOPPED
                if v.get(f"{inst}.feed_hold"):
                    return PROGRAM_INTERRUPTED
                return PROGRAM_WAITING if v.get(f"{inst}.m_active") else PROGRAM_RUNNING
            await mirror(channel, "ActProgramStatus", I32, program_status)
            await mirror(channel, "ActStatus", I32, lambda v, st=program_status: CHANNEL_ACTIVE
                         if st(v) in (PROGRAM_RUNNING, PROGRAM_WAITING) else CHANNEL_INTERRUPTED
                         if st(v) == PROGRAM_INTERRUPTED else CHANNEL_RESET)
            await mirror(channel, "ActProgramBlock", S, lambda v, block=block: "" if block is None
                         else str(v.get(block, "")))
            override = points.get(f"{inst}.feed_override")
            for which in ("ActOverride", "CmdOverride"):
                await mirror(channel, which, D, lambda v, inst=inst: 100.0 * real(f"{inst}.feed_override")(v))
                if override is not None and override.minimum is not None and override.maximum is not None:
                    await put(channel, f"{which}/EURange", ua.Range(Low=100.0 * override.minimum,
                                                                    High=100.0 * override.maximum))
            await mirror(channel, "FeedHold", B, lambda v, inst=inst: bool(v.get(f"{inst}.feed_hold")))
            fixed: tuple[tuple[str, object, object], ...]
            fixed = (("ActProgramName", system, S), ("ActMainProgramName", system, S),
                     ("ActOperationMode", MODE_AUTOMATIC, I32), ("CmdOperationMode", MODE_AUTOMATIC, I32),
                     ("Id", channel_id, U32), ("BlockMode", False, B))      # no single-block mode in ncfmu
            for prop, fixed_value, vt in fixed:
                await put(channel, prop, ua.Variant(fixed_value, vt))
    if len(channels) == 1:                      # one channel: every drive is its
        for drive in drives:
            await put(drive, "ActChannel", ua.Variant(channels[0].nodeid, ua.VariantType.NodeId))
    await _settle_unvalued(server, iface, fed)
    return mirrors


async def _settle_unvalued(server, iface, fed: set) -> None:
    """What the served system has nothing for, below ``iface`` (the variables not in ``fed``): an optional one
    (its instance declaration's ModellingRule) is deleted; a mandatory one reads Bad_NotConnected ("should
    receive its value from another variable, but has never been configured to do so"), the value Null -- never
    the Good 0, "" or Null that asyncua instantiated it with, which a client takes for known. The
    EngineeringUnits the NodeSet declares (N·m, %, min⁻¹ ...) stay: a unit is the type's, not a value."""
    from asyncua import ua
    from asyncua.common.ua_utils import get_node_supertypes
    optional = {ua.NodeId(ua.Int32(ua.ObjectIds.ModellingRule_Optional)),
                ua.NodeId(ua.Int32(ua.ObjectIds.ModellingRule_OptionalPlaceholder))}
    unknown = ua.DataValue(ua.Variant(), StatusCode=ua.StatusCode(ua.UInt32(ua.StatusCodes.BadNotConnected)))
    declared: dict = {}

    async def declarations(decl) -> dict:
        # as asyncua instantiates: the children of the type or declaration and of its supertypes, lowest first
        key = decl.nodeid
        if key not in declared:
            found: dict = {}
            for parent in await get_node_supertypes(decl, includeitself=True):
                for d in await parent.get_children_descriptions():
                    found.setdefault(d.BrowseName.Name, server.get_node(d.NodeId))
            declared[key] = found
        return declared[key]

    async def settle(node, decl) -> None:
        decls = await declarations(decl) if decl is not None else {}
        for child in await node.get_children():
            name = (await child.read_browse_name()).Name
            cls = await child.read_node_class()
            if cls not in (ua.NodeClass.Object, ua.NodeClass.Variable):
                continue
            d = decls.get(name)
            if d is None:                   # ncfmu's own (an axis, a spindle, a channel): from its type
                d = await child.read_type_definition()
                d = server.get_node(d) if d is not None else None
            if cls == ua.NodeClass.Variable and child.nodeid not in fed:
                if name == "EngineeringUnits" and (await child.read_value()) is not None:
                    continue
                rule = await d.get_referenced_nodes(refs=ua.ObjectIds.HasModellingRule) if d is not None else []
                if rule and rule[0].nodeid in optional:
                    await server.delete_nodes([child], recursive=True)
                    continue
                await server.write_attribute_value(child.nodeid, unknown)
            await settle(child, d)
    await settle(iface, server.get_node(await iface.read_type_definition()))


# -- the OPC UA server -----------------------------------------------------------------------------------
@dataclass(eq=False)
class _Client:
    """A client's session as the watchdog sees it: when it was last heard (any request), whether it closed."""

    session: object
    heard: float

    @property
    def name(self) -> str:
        user = getattr(self.session, "user", None)
        who = getattr(user, "name", None)
        return f"{getattr(self.session, 'name', '?')}" + (f" (user {who})" if who else "")


@dataclass
class Security:
    """Who may connect when the endpoint is not on the loopback interface."""

    users: dict[str, str] = field(default_factory=dict)     # name -> password
    certificate: Path | None = None                          # server certificate (DER or PEM)
    private_key: Path | None = None
    trust: Path | None = None                # folder of the client certificates (or their CAs) accepted
    allow_insecure: bool = False             # off the loopback: security policy None, any client certificate


def _is_loopback(endpoint: str) -> bool:
    host = urlparse(endpoint).hostname or ""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def check_endpoint(endpoint: str, security: Security) -> None:
    parsed = urlparse(endpoint)
    try:
        port = parsed.port
    except ValueError:
        raise ConfigError("--endpoint", endpoint, "the port must be a number 0..65535") from None
    if parsed.scheme != "opc.tcp" or not parsed.hostname or port is None:
        raise ConfigError("--endpoint", endpoint, "must be opc.tcp://HOST:PORT/PATH")
    if not _is_loopback(endpoint):
        if not security.users:
            raise ConfigError("--endpoint", endpoint, "serving beyond this machine needs --user NAME:PASSWORD "
                              "(no anonymous writes from the network); bind 127.0.0.1 otherwise")
        if security.certificate is None and not security.allow_insecure:
            raise ConfigError("--endpoint", endpoint, "serving beyond this machine needs --certificate and "
                              "--private-key (security policy Basic256Sha256, Sign & Encrypt: no password or write "
                              "in plain text; 'ncfmu serve --make-certificate DIR' makes them), or --allow-insecure")
        if security.trust is None and not security.allow_insecure:
            raise ConfigError("--endpoint", endpoint, "serving beyond this machine needs --trust DIR (the client "
                              "certificates accepted), or --allow-insecure")
    if (security.certificate is None) != (security.private_key is None):
        raise ConfigError("--certificate", str(security.certificate), "needs --private-key too (and vice versa)")
    if security.trust is not None:
        if security.certificate is None:
            raise ConfigError("--trust", str(security.trust), "needs --certificate: client certificates are only "
                              "presented on a signed and encrypted channel")
        if not Path(security.trust).is_dir():
            raise ConfigError("--trust", str(security.trust), "must be a folder of trusted certificates (DER or PEM)")


def make_certificate(folder: Path | str, hostname: str | None = None) -> tuple[Path, Path]:
    """A private key (``ncfmu-key.pem``) and a self-signed certificate (``ncfmu.der``, 5 years) in ``folder``,
    for ``ncfmu serve --certificate ncfmu.der --private-key ncfmu-key.pem``: ncfmu's application URI, the host's
    name, ``localhost`` and 127.0.0.1 as subject alternative names (OPC UA Part 6 6.2.2). Existing files are
    never overwritten."""
    import socket

    from asyncua.crypto import cert_gen
    from cryptography import x509
    from cryptography.hazmat.primitives.serialization import Encoding
    from cryptography.x509.oid import ExtendedKeyUsageOID

    from .files import write_atomic
    folder = Path(folder)
    key_path, cert_path = folder / "ncfmu-key.pem", folder / "ncfmu.der"
    for path in (key_path, cert_path):
        if path.exists():
            raise ConfigError("--make-certificate", str(folder), f"{path.name} exists there already (remove it "
                              "first: a key is never overwritten)")
    host = hostname or socket.gethostname()
    key = cert_gen.generate_private_key()
    names: list[x509.GeneralName] = [x509.UniformResourceIdentifier(APPLICATION_URI), x509.DNSName(host),
                                     x509.DNSName("localhost"), x509.IPAddress(ipaddress.ip_address("127.0.0.1"))]
    cert = cert_gen.generate_self_signed_app_certificate(
        key, f"ncfmu serve@{host}", {"organizationName": "ncfmu"}, names,
        extended=[ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH], days=5 * 365)
    folder.mkdir(parents=True, exist_ok=True)
    write_atomic(key_path, cert_gen.dump_private_key_as_pem(key))
    os.chmod(key_path, 0o600)
    write_atomic(cert_path, cert.public_bytes(Encoding.DER))
    return key_path, cert_path


async def _load(load, option: str, path: Path | None, what: str) -> None:
    """asyncua's certificate or key loader, its failure (no such file, not a certificate) one ConfigError."""
    try:
        await load(str(path))
    except OSError as err:
        raise ConfigError(option, str(path), f"cannot read it: {err.strerror or err}") from None
    except Exception as err:        # cryptography's parsers: ValueError, TypeError, UnsupportedAlgorithm ...
        raise ConfigError(option, str(path), f"not {what}: {type(err).__name__}") from None


def parameter_check(components: Mapping[str, str], session) -> Callable[[str, object], None]:
    """``check(INSTANCE.PARAMETER, value)``: the instance's model built anew, on a copy, from its present
    parameters and the new value (ConfigError: a rule of the model refuses it). A refused tunable then never
    reaches the FMU, which would apply it before refusing it."""
    from .catalogue import models
    logic_of = {inst: models().get(model) for inst, model in components.items()}

    def check(name: str, value: object) -> None:
        instance, _, variable = name.partition(".")
        logic = logic_of.get(instance)
        if logic is None:
            return
        values = {p.name: session.value(f"{instance}.{p.name}") for p in logic.ports("parameter")}
        values[variable] = value
        logic.from_parameters(values)
    return check


@dataclass
class ServeSummary:
    system: str
    time: float
    state: str
    reason: str
    overruns: int
    lag_p50: float
    lag_p99: float
    lag_max: float
    files: list[Path]
    writes: list[tuple[float, str, object]]
    wall: float = 0.0            # wall time of the simulation thread, s


class LiveServer:
    """An OPC UA server in front of a :class:`Runner`."""

    def __init__(self, system_name: str, runner: Runner, endpoint: str = DEFAULT_ENDPOINT,
                 security: Security | None = None, publish_interval: float = 0.010,
                 watchdog: float | None = None, cnc_components: Mapping[str, str] | None = None,
                 on_lost: str = "hold", on_verdict: Callable[[float, str], None] | None = None) -> None:
        self.system_name, self.runner, self.endpoint = system_name, runner, endpoint
        self.security = security or Security()
        self.publish_interval = publish_interval
        self.points = {p.name: p for p in runner.points}
        self.stopped = asyncio.Event()
        self._publishing = asyncio.Lock()
        if watchdog is not None and not (math.isfinite(watchdog) and watchdog > 0):
            raise ConfigError("--watchdog", watchdog, "must be a number of seconds > 0")
        if on_lost not in ON_LOST:
            raise ConfigError("--on-lost", on_lost, f"must be one of {', '.join(ON_LOST)}")
        #: with a watchdog: a client session that forced inputs is lost when it closes or is silent this long;
        #: then (``on_lost``) the machine is held until a client calls Resume, or its forces fall back
        self.watchdog, self.on_lost = watchdog, on_lost
        self._clients: dict[int, _Client] = {}       # id(asyncua session) -> what the watchdog knows of it
        self._owner: dict[str, _Client] = {}         # a forced input -> the session that forced it last
        self._held: set[str] = set()                 # what a hold keeps forced until Resume (--on-lost hold)
        #: told each part verdict as it is published (a program ended): its time and summary line
        self.on_verdict = on_verdict
        self.verdicts_published = 0
        #: with the OPC 40502 companion model: instance -> model of the served system's components
        self.cnc_components = cnc_components
        self._mirrors: list[_Mirror] = []
        self._mirrored: dict[int, object] = {}

    async def _build(self) -> None:
        from asyncua import Server, ua
        from asyncua.crypto.permission_rules import User, UserRole
        from asyncua.server.user_managers import UserManager

        self.ua = ua
        server = self.server = Server()
        sec = self.security
        if sec.users:
            users = dict(sec.users)

            class _Users(UserManager):
                def get_user(self, iserver, username=None, password=None, certificate=None):
                    if username is not None and users.get(username) == password:
                        return User(role=UserRole.User, name=username)
                    return None
            server = self.server = Server(user_manager=_Users())
        await server.init()
        server.set_endpoint(self.endpoint)
        server.set_server_name(f"ncfmu {self.system_name}")
        from . import __version__
        server.product_uri = PRODUCT_URI
        await server.set_application_uri(APPLICATION_URI)
        await server.set_build_info(PRODUCT_URI, "ncfmu", "ncfmu", __version__, __version__,
                                    datetime.datetime.now(datetime.UTC))
        if sec.certificate is not None:
            await _load(server.load_certificate, "--certificate", sec.certificate, "a certificate (DER or PEM)")
            await _load(server.load_private_key, "--private-key", sec.private_key, "a private key (DER or PEM)")
            policies = [ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt]
            if sec.allow_insecure:
                policies.append(ua.SecurityPolicyType.NoSecurity)
            server.set_security_policy(policies)
            if sec.trust is not None:
                from asyncua.crypto.truststore import TrustStore
                from asyncua.crypto.validator import CertificateValidator, CertificateValidatorOptions
                store = TrustStore([Path(sec.trust)], [])
                await store.load()
                options = CertificateValidatorOptions
                server.set_certificate_validator(CertificateValidator(
                    options.TIME_RANGE | options.URI | options.TRUSTED | options.PEER_CLIENT, store))
        else:
            # only what is served: asyncua offers the signing policies too, and warns that it cannot
            server.set_security_policy([ua.SecurityPolicyType.NoSecurity])
        # users, or anonymous clients: never both (asyncua otherwise offers user names, and warns that their
        # passwords would travel in plain text, where no user was asked for)
        server.set_identity_tokens([ua.UserNameIdentityToken] if sec.users else [ua.AnonymousIdentityToken])
        idx = self.idx = await server.register_namespace(f"urn:ncfmu:{self.system_name}")
        vtype = {"Real": ua.VariantType.Double, "Integer": ua.VariantType.Int32,
                 "Boolean": ua.VariantType.Boolean, "String": ua.VariantType.String}
        self.vtype = vtype
        snap = self.runner.snapshot()
        assert snap is not None, "the runner takes its first snapshot when made"
        objects = server.nodes.objects
        instances: dict[str, Node] = {}
        self.nodes: dict[str, Node] = {}
        self._last: dict[str, object] = {}
        for p in self.runner.points:
            obj = instances.get(p.instance)
            if obj is None:
                obj = instances[p.instance] = await objects.add_object(self._nid(p.instance),
                                                                       ua.QualifiedName(p.instance, idx))
            value = snap.values.get(p.name)
            if value is None:
                value = self._initial(p)
            node = await obj.add_variable(self._nid(p.name), ua.QualifiedName(p.variable, idx),
                                          ua.Variant(self._cast(p, value), vtype[p.type]), varianttype=vtype[p.type])
            if p.description:
                await node.write_attribute(ua.AttributeIds.Description,
                                           ua.DataValue(ua.Variant(ua.LocalizedText(p.description))))
            if p.unit:
                code = UNECE.get(p.unit)
                eu = ua.EUInformation(NamespaceUri=UNECE_NAMESPACE, UnitId=_unece_id(code) if code else -1,
                                      DisplayName=ua.LocalizedText(p.unit), Description=ua.LocalizedText(p.unit))
                await node.add_property(self._nid(f"{p.name}.EngineeringUnits"),
                                        ua.QualifiedName("EngineeringUnits", 0), eu)
            if p.writes:
                await node.set_writable()
            self.nodes[p.name] = node
            self._last[p.name] = value
            if p.causality == "input":
                forced = await node.add_variable(self._nid(f"{p.name}.forced"), ua.QualifiedName("forced", idx),
                                                 False, varianttype=ua.VariantType.Boolean)
                await forced.write_attribute(ua.AttributeIds.Description, ua.DataValue(ua.Variant(ua.LocalizedText(
                    "true while a client's value overrides what drives this input; write false to release"))))
                await forced.set_writable()
                self.nodes[f"{p.name}.forced"] = forced
                self._last[f"{p.name}.forced"] = False
        simobj = await objects.add_object(self._nid("Simulation"), ua.QualifiedName("Simulation", idx))
        self.sim_nodes = {}
        for name, value, vt, desc in (
                ("time", float(snap.time), ua.VariantType.Double, "simulated time, s"),
                ("speed", self.runner.speed, ua.VariantType.Double,
                 "simulated seconds per wall-clock second (0: as fast as possible)"),
                ("lag", 0.0, ua.VariantType.Double, "wall clock minus the paced simulated time, s"),
                ("overruns", 0, ua.VariantType.Int32, "times the simulation fell more than 10 ms behind the clock"),
                ("state", "running", ua.VariantType.String,
                 "running, paused, held (a client was lost: see reason), crashed, stopped, failed, or faulted (a "
                 "foreign FMU's process died)"),
                ("reason", "", ua.VariantType.String,
                 "why the simulation is held, crashed, stopped, failed or faulted"),
                ("forced", [], ua.VariantType.String,
                 "the inputs a client's value overrides now, INSTANCE.VARIABLE, in system order"),
                ("crashes", 0, ua.VariantType.Int32, "crashes the part check saw since the start (or the last Reset)"),
                ("crash", "", ua.VariantType.String,
                 "the last crash: time, program line, what and how deep (empty: none)"),
                ("verdict", "", ua.VariantType.String,
                 "the part check's verdict when the last program ended: its summary line (empty: none ended yet "
                 "since the start or the last Reset)")):
            node = await simobj.add_variable(self._nid(f"Simulation.{name}"), ua.QualifiedName(name, idx),
                                             ua.Variant(value, vt), varianttype=vt)
            await node.write_attribute(ua.AttributeIds.Description, ua.DataValue(ua.Variant(ua.LocalizedText(desc))))
            self.sim_nodes[name] = (node, vt)
        crash_type = await server.create_custom_event_type(
            idx, "CrashEventType", ua.ObjectIds.BaseEventType,
            [("SimulationTime", ua.VariantType.Double), ("Line", ua.VariantType.Int32),
             ("What", ua.VariantType.String), ("DepthMm", ua.VariantType.Double)])
        self._crash_events = await server.get_event_generator(crash_type, simobj.nodeid)
        self._crashes_published = 0
        for method in ("Pause", "Resume", "Stop", "Reset"):
            await simobj.add_method(self._nid(f"Simulation.{method}"), ua.QualifiedName(method, idx),
                                    self._method(method.lower()), [], [])
        arg = ua.Argument(Name="name", DataType=ua.NodeId(ua.Int32(ua.ObjectIds.String)), ValueRank=-1,
                          Description=ua.LocalizedText("the input, INSTANCE.VARIABLE (e.g. feed.mfin)"))
        await simobj.add_method(self._nid("Simulation.Release"), ua.QualifiedName("Release", idx),
                                self._release_method, [arg], [])
        if self.cnc_components is not None:
            self._mirrors = await build_cnc_model(server, idx, self.system_name, self.cnc_components, self.points,
                                                  snap.values)
        service = server.iserver.attribute_service
        self._asyncua_write = service.write
        service.write = self._write      # type: ignore[method-assign]  # why: see _write
        if self.watchdog is not None:
            self._watch_sessions(server.iserver)

    def _nid(self, name: str):
        return self.ua.NodeId(self.ua.String(name), self.ua.Int16(self.idx))

    @staticmethod
    def _initial(p: Point) -> object:
        return {"Real": 0.0, "Integer": 0, "Boolean": False, "String": ""}[p.type]

    @staticmethod
    def _cast(p: Point, value: object) -> object:
        if p.type == "Real":
            return float(value)   # type: ignore[arg-type]
        if p.type == "Integer":
            return int(value)     # type: ignore[call-overload]
        if p.type == "Boolean":
            return bool(value)
        return "" if value is None else str(value)

    # -- writes ------------------------------------------------------------------------------------------
    async def _submit(self, command: _Command) -> str | None:
        loop = asyncio.get_running_loop()
        future: asyncio.Future[str | None] = loop.create_future()

        def done(refusal: str | None) -> None:
            def settle() -> None:
                if not future.done():
                    future.set_result(refusal)
            loop.call_soon_threadsafe(settle)
        command.done = done
        if self.runner.state in ("stopped", *ENDED_BADLY):
            return f"the simulation is {self.runner.state}"
        self.runner.submit(command)
        try:
            return await asyncio.wait_for(future, WRITE_TIMEOUT)
        except TimeoutError:
            return "the simulation did not take the write in time"

    def _status(self, status: str, message: str):
        log.info("ncfmu serve: write refused (%s): %s", status, message)
        return self.ua.StatusCode(getattr(self.ua.StatusCodes, status))

    def _plan(self, wv, user) -> _Command | tuple[str, str]:
        """One WriteValue of our namespace: the command that applies it, or (status, why) refused."""
        ua = self.ua
        nid = wv.NodeId
        key = nid.Identifier
        forced = isinstance(key, str) and key.endswith(".forced") and key[:-7] in self.points
        p = self.points.get(key) if isinstance(key, str) else None
        if p is None and not forced:
            return "BadNotWritable", f"{key}: not writable"
        if wv.AttributeId != ua.AttributeIds.Value:
            return "BadNotWritable", f"{key}: only the Value attribute is writable"
        if getattr(user, "role", None) is not None and user.role.name == "Anonymous":
            return "BadUserAccessDenied", f"{key}: anonymous clients may not write"
        variant = wv.Value.Value if wv.Value is not None else None
        value = None if variant is None else variant.Value
        vt = None if variant is None else variant.VariantType
        if forced:
            if vt != ua.VariantType.Boolean:
                return "BadTypeMismatch", f"{key} = {value!r}: must be a Boolean"
            name = key[:-7]
            # true: held at its present value; false: released
            return _Command("force", name, self._last.get(name)) if value else _Command("release", name)
        assert p is not None
        if p.writes and vt != self.vtype[p.type]:
            return "BadTypeMismatch", (f"{key} = {value!r} ({vt.name if vt else 'null'}): "
                                       f"must be a {self.vtype[p.type].name}")
        try:
            checked = check_value(p, value)
        except WriteRefused as err:
            return err.status, str(err)
        return _Command("force" if p.writes == "input" else "set", key, checked)

    async def _write(self, params, user=None) -> list:
        """The Write service (OPC UA Part 4 5.11.4): a StatusCode per WriteValue, the good ones applied in their
        order by the simulation thread (before the same step), the bad ones changing nothing. Installed in
        place of asyncua's attribute service's ``write``: its PreWrite callback can only refuse a request as a
        whole (a ServiceFault), and it would apply our values to the address space itself."""
        ua = self.ua
        results: list = [None] * len(params.NodesToWrite)
        planned: list[tuple[int, _Command]] = []
        theirs: list[int] = []
        for i, wv in enumerate(params.NodesToWrite):
            if wv.NodeId not in self.server.iserver.aspace:   # asyncua: BadUserAccessDenied unless an admin
                results[i] = self._status("BadNodeIdUnknown", f"{wv.NodeId.to_string()}: no such node")
                continue
            if wv.NodeId.NamespaceIndex != self.idx:
                theirs.append(i)
                continue
            plan = self._plan(wv, user)
            if isinstance(plan, tuple):
                results[i] = self._status(*plan)
            else:
                planned.append((i, plan))
        if planned:
            refusals = await asyncio.gather(*(self._submit(c) for _, c in planned))
            for (i, c), refusal in zip(planned, refusals):
                if refusal is None:
                    results[i] = ua.StatusCode()
                    self._owned(c, user)
                else:
                    status = "BadOutOfRange" if "simulation" not in refusal else "BadInvalidState"
                    results[i] = self._status(status, f"{c.name}: {refusal}")
            await self._publish_once()
        if theirs:
            inner = ua.WriteParameters(NodesToWrite=[params.NodesToWrite[i] for i in theirs])
            for i, result in zip(theirs, await self._asyncua_write(inner, user=user)):
                results[i] = result
        return results

    def _call_result(self, status: str, message: str, arguments: Sequence[str] = ()):
        # asyncua answers a method's exception with Bad_UnexpectedError; a returned result is the call's own
        log.info("ncfmu serve: call refused (%s): %s", status, message)
        codes = self.ua.StatusCodes
        return self.ua.CallMethodResult(StatusCode=self.ua.StatusCode(getattr(codes, status)),
                                        InputArgumentResults=[self.ua.StatusCode(getattr(codes, a))
                                                              for a in arguments])

    def _method(self, what: str):
        async def call(parent, *args):
            if args:
                return self._call_result("BadTooManyArguments", f"{what.capitalize()} takes no argument",
                                         ["BadTooManyArguments"] * len(args))
            if what == "stop" and self.runner.state in ENDED_BADLY:
                self.stopped.set()
                return []
            refusal = await self._submit(_Command(what))
            if refusal is not None:
                return self._call_result("BadInvalidState", refusal)
            if what == "reset":
                self._owner.clear()            # nothing is forced after a Reset
            if what in ("reset", "resume"):     # what a hold kept is released (Resume), or all is (Reset)
                for name in self._held:
                    self._owner.pop(name, None)
                self._held.clear()
            await self._publish_once()
            return []
        return call

    async def _release_method(self, parent, *args):
        ua = self.ua
        if not args:
            return self._call_result("BadArgumentsMissing", "Release(name): the input's name is missing")
        first = args[0]
        text = first.Value if isinstance(first, ua.Variant) else first
        if isinstance(first, ua.Variant) and first.VariantType != ua.VariantType.String or not isinstance(text, str):
            verdict = "BadTypeMismatch"
        elif text not in self.points or self.points[text].causality != "input":
            verdict = "BadInvalidArgument"
        else:
            verdict = "Good"
        if len(args) > 1:
            return self._call_result("BadTooManyArguments", "Release takes one argument, the input's name",
                                     [verdict] + ["BadTooManyArguments"] * (len(args) - 1))
        if verdict == "BadTypeMismatch":
            return self._call_result(verdict, f"Release({text!r}): the name must be a String", [verdict])
        if verdict == "BadInvalidArgument":
            return self._call_result(verdict, f"Release({text!r}): not an input INSTANCE.VARIABLE", [verdict])
        refusal = await self._submit(_Command("release", text))
        if refusal is not None:
            return self._call_result("BadInvalidState", refusal, ["Good"])
        self._owner.pop(text, None)
        await self._publish_once()
        return []

    # -- the watchdog -------------------------------------------------------------------------------------
    def _watch_sessions(self, iserver) -> None:
        """Know every client session and when it was last heard. asyncua tells neither (its own session timeout
        closes a silent session after minutes, and a session with subscriptions outlives its connection): its
        ``create_session`` and each session's ``touch`` (called on every request) are wrapped, here only."""
        create = iserver.create_session

        def create_session(*args, **kwargs):
            session = create(*args, **kwargs)
            client = self._clients[id(session)] = _Client(session, _time.monotonic())
            touch = session.touch

            def touched() -> None:
                touch()
                client.heard = _time.monotonic()
            session.touch = touched
            return session
        iserver.create_session = create_session

    def _owned(self, command: _Command, user) -> None:
        if command.what == "release":
            self._owner.pop(command.name, None)
            return
        if command.what != "force":
            return
        for client in self._clients.values():
            if getattr(client.session, "user", None) is user:
                self._owner[command.name] = client
                return
        self._owner.pop(command.name, None)

    async def _watch(self) -> None:
        """Every tenth of the watchdog's time: a closed or silent session's forced inputs are released (logged,
        and recorded as any release)."""
        from asyncua.server.internal_session import SessionState
        assert self.watchdog is not None
        while not self.stopped.is_set():
            now = _time.monotonic()
            for key, client in list(self._clients.items()):
                closed = getattr(client.session, "state", None) == SessionState.Closed
                silent = now - client.heard > self.watchdog
                if closed or silent:
                    names = [name for name, owner in self._owner.items() if owner is client]
                    why = "closed" if closed else f"silent for {self.watchdog:g} s"
                    if names and self.on_lost == "hold":
                        await self._hold(client, why, names)
                        names = []
                    for name in names:
                        refusal = await self._submit(_Command("release", name))
                        if self._owner.get(name) is client:
                            del self._owner[name]
                        if refusal is not None:
                            log.warning("ncfmu serve: watchdog: could not release %s: %s", name, refusal)
                    if names:
                        log.warning("ncfmu serve: watchdog: session %s %s at t = %.3f s: released %s",
                                    client.name, why, self._last.get("Simulation.time", 0.0), ", ".join(names))
                if closed:
                    del self._clients[key]
            try:
                await asyncio.wait_for(self.stopped.wait(), min(0.1, self.watchdog / 10))
            except TimeoutError:
                pass

    async def _hold(self, client: _Client, why: str, names: Sequence[str]) -> None:
        """``--on-lost hold``: the machine goes to feed hold (Simulation.state ``held``, Simulation.reason why),
        the lost session's forces kept; Simulation.Resume (a client's explicit act) releases both."""
        for name in names:
            if self._owner.get(name) is client:
                del self._owner[name]
        feed = self.runner.feed_holds
        reason = (f"client lost: session {client.name} {why}; "
                  + (f"feed hold on {', '.join(feed)}" if feed else "halted (no feed-hold input)")
                  + f", its forces kept ({', '.join(names)}); Resume releases them")
        refusal = await self._submit(_Command("hold", value=(reason, tuple(names))))
        if refusal is not None:
            log.warning("ncfmu serve: watchdog: could not hold the machine: %s", refusal)
            return
        self._held.update(names)
        self._held.update(feed)
        log.warning("ncfmu serve: watchdog: session %s %s at t = %.3f s: %s", client.name, why,
                    self._last.get("Simulation.time", 0.0), reason)

    # -- publishing ---------------------------------------------------------------------------------------
    async def _publish_once(self) -> None:
        # one publication at a time: an answer's own publication must not be overwritten by an older snapshot
        # the periodic one is still writing
        async with self._publishing:
            await self._publish_snapshot()

    async def _publish_snapshot(self) -> None:
        ua = self.ua
        snap = self.runner.snapshot()
        if snap is not None:
            stamp = None
            for name, value in snap.values.items():
                if self._last.get(name) != value and name in self.nodes:
                    self._last[name] = value
                    p = self.points[name]
                    await self.server.write_attribute_value(
                        self.nodes[name].nodeid, ua.DataValue(ua.Variant(self._cast(p, value), self.vtype[p.type]),
                                                              SourceTimestamp=stamp))
            for name, p in self.points.items():
                if p.causality == "input":
                    forced = name in snap.forced
                    key = f"{name}.forced"
                    if self._last.get(key) != forced:
                        self._last[key] = forced
                        await self.server.write_attribute_value(
                            self.nodes[key].nodeid, ua.DataValue(ua.Variant(forced, ua.VariantType.Boolean)))
            await self._sim_value("time", float(snap.time))
            await self._sim_value("lag", float(snap.lag))
            await self._sim_value("overruns", int(snap.overruns))
            await self._sim_value("state", snap.state)
            await self._sim_value("reason", snap.reason)
            await self._sim_value("forced", [name for name in self.points if name in snap.forced])
            await self._publish_crashes(snap.crashes)
            await self._publish_verdicts(snap.verdicts)
            if self._mirrors:
                values = {**self._last, **snap.values}
                for k, m in enumerate(self._mirrors):
                    value = m.value(values)
                    if self._mirrored.get(k) != value:
                        self._mirrored[k] = value
                        await self.server.write_attribute_value(m.node.nodeid,      # type: ignore[attr-defined]
                                                                ua.DataValue(ua.Variant(value, m.vtype)))

    async def _publish_crashes(self, crashes: Sequence) -> None:
        """The crashes not yet published: each an event; then the count and the last one's text."""
        ua = self.ua
        if len(crashes) < self._crashes_published:           # a Reset: a new run
            self._crashes_published = 0
        for c in crashes[self._crashes_published:]:
            event = self._crash_events.event
            event.Message = ua.LocalizedText(crash_text(c))
            event.Severity = CRASH_SEVERITY
            event.SimulationTime, event.Line, event.What = float(c.t), int(c.line), c.what
            event.DepthMm = float(c.depth_mm)
            await self._crash_events.trigger()
        self._crashes_published = len(crashes)
        await self._sim_value("crashes", len(crashes))
        await self._sim_value("crash", crash_text(crashes[-1]) if crashes else "")

    async def _publish_verdicts(self, verdicts: Sequence[tuple[float, str]]) -> None:
        """The last program's verdict; each new one told to :attr:`on_verdict` (printed by the CLI)."""
        if len(verdicts) < self.verdicts_published:          # a Reset: a new run
            self.verdicts_published = 0
        for t, text in verdicts[self.verdicts_published:]:
            if self.on_verdict is not None:
                self.on_verdict(t, text)
        self.verdicts_published = len(verdicts)
        await self._sim_value("verdict", verdicts[-1][1] if verdicts else "")

    async def _sim_value(self, name: str, value: object) -> None:
        if self._last.get(f"Simulation.{name}") == value:
            return
        self._last[f"Simulation.{name}"] = value
        node, vt = self.sim_nodes[name]
        await self.server.write_attribute_value(node.nodeid, self.ua.DataValue(self.ua.Variant(value, vt)))

    async def serve(self, ready: Callable[[str], None] | None = None) -> None:
        await self._build()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            try:
                loop.add_signal_handler(sig, self.stopped.set)
            except (NotImplementedError, RuntimeError, ValueError):   # not the main thread, or Windows
                pass
        def wake() -> None:
            # stopped (Stop, the stop time): the server ends too; failed: it stays up so that clients see the
            # state and the reason, until Stop, Ctrl-C or SIGTERM
            if self.runner.state not in ENDED_BADLY:
                loop.call_soon_threadsafe(self.stopped.set)
        self.runner._on_state = wake
        try:
            await self.server.start()
        except OSError as err:          # the port is taken, or the address is not this machine's
            said = os.strerror(err.errno).lower() if err.errno else str(err)
            raise ConfigError("--endpoint", self.endpoint, f"cannot listen there: {said}") from None
        watch: asyncio.Task | None = None
        # what was built (the address space; with --cnc the OPC 40502 NodeSet import: ~5 s, many objects) lives
        # for the whole serve: collected once and frozen here, before the clock starts, so that no full
        # collection walks it in the paced loop (the ~200 ms stall once seen with --cnc was not shown to be one)
        gc.collect()
        gc.freeze()
        try:
            self.runner.start()
            if self.watchdog is not None:
                watch = asyncio.create_task(self._watch())
            if ready is not None:
                ready(self.endpoint)
            while not self.stopped.is_set():
                await self._publish_once()
                try:
                    await asyncio.wait_for(self.stopped.wait(), self.publish_interval)
                except TimeoutError:
                    pass
            if self.runner.state in ("running", "paused", "held"):
                self.runner.stop("stopped by a signal")
            await asyncio.get_running_loop().run_in_executor(None, self.runner.thread.join, 5.0)
            await self._publish_once()
        finally:
            gc.unfreeze()
            if watch is not None:
                watch.cancel()
            if self.runner.thread.is_alive():      # the server failed: the FMUs must not step on while closed
                self.runner.stop("the server stopped")
                await asyncio.get_running_loop().run_in_executor(None, self.runner.thread.join, 5.0)
            await self.server.stop()


class _SaidByUs(logging.Filter):
    """asyncua logs, as errors, what ncfmu says itself: every refused request ("sending service fault
    response": a refused write is ours to report, at info, naming the variable and the rule, and a client
    flooding bad writes must not flood the log) and a port it cannot bind, with a traceback (ours is one
    line naming the endpoint)."""

    SAID = ("sending service fault response", "%s error starting server")

    def filter(self, record: logging.LogRecord) -> bool:
        return not str(record.msg).startswith(self.SAID)


def _quiet_asyncua() -> None:
    # asyncua logs every request at INFO: a write flood would cost the server more in logging than in writing
    for name in ("asyncua", "asyncua.server", "asyncua.server.uaprocessor"):
        logging.getLogger(name).setLevel(logging.WARNING)
    for name in ("asyncua.server.uaprocessor", "asyncua.server.server"):
        logger = logging.getLogger(name)
        if not any(isinstance(f, _SaidByUs) for f in logger.filters):
            logger.addFilter(_SaidByUs())


def _crash_watch(opened, start_values: Mapping[str, object], recorder: Recorder | None,
                 record: Sequence[str] | None, drawing=None) -> tuple[CrashWatch | None, list, list[str] | None]:
    """The served run's part check (None: the system has none; with ``drawing``, judged against the part drawn),
    the session's sinks and what it records: with ``--record``, also what the part check reads (the CSV keeps to
    ``--record``)."""
    from .systems.part import PartSettings, part_check_only, with_part_settings
    from .systems.report import start_parameters
    report = part_check_only(opened.report())
    if report is not None and drawing is not None:
        report = with_part_settings(report, PartSettings(drawing=drawing))
    recording = list(recorder.sinks()) if recorder is not None else []
    columns = list(record) if record else None
    if report is None:
        return None, recording, columns
    watch = CrashWatch(report, start_parameters(opened.system.components, start_values), columns)
    if columns is not None:
        columns = list(dict.fromkeys([*columns, *report.record()]))
    return watch, watch.sinks(recording), columns


def serve(system: str = "lathe_roughing", endpoint: str = DEFAULT_ENDPOINT, speed: float = 1.0,
          start_values: Mapping[str, object] | None = None, stop_time: float | None = None,
          step_size: float | None = None, record: Sequence[str] | None = None, out: Path | str | None = None,
          security: Security | None = None, root: Path | None = None,
          ready: Callable[[str], None] | None = None, watchdog: float | None = None,
          cnc: bool = True, on_lost: str = "hold",
          on_verdict: Callable[[float, str], None] | None = None, drawing=None) -> ServeSummary:
    """Run ``system`` (a name or an .ssp path) paced to the wall clock behind an OPC UA server at ``endpoint``
    until stopped (Ctrl-C, SIGTERM, the ``Stop`` method, ``stop_time``); with ``out``, write the recorded
    trajectory ``OUT/<system>.csv`` and the session's writes ``OUT/session_inputs.csv`` (an input CSV that
    ``ncfmu run --input`` replays). ``ready(endpoint)`` is called once clients can connect. With ``watchdog``
    (s), a client session that forced inputs is lost when it closes or is silent that long: ``on_lost`` "hold"
    puts the machine in feed hold (state ``held``) until a client calls Resume, "release" lets its forces fall
    back. ``on_verdict(time, line)`` is told the part check's verdict each time a program ends (also
    ``Simulation.verdict``). With ``cnc`` (the default), the system is also served as an OPC 40502 (OPC UA for
    CNC Systems) ``CncInterface`` object (about 1 s more to start). With ``drawing`` (a
    :class:`~ncfmu.systems.drawing.Drawing`), the part check judges against the part drawn."""
    from .project import OpenSystem, system_archive
    security = security or Security()
    check_endpoint(endpoint, security)
    if stop_time is not None and not (math.isfinite(stop_time) and stop_time > 0):
        raise ConfigError("--stop-time", stop_time, "must be a number > 0")
    if watchdog is not None and not (math.isfinite(watchdog) and watchdog > 0):
        raise ConfigError("--watchdog", watchdog, "must be a number of seconds > 0")
    if on_lost not in ON_LOST:
        raise ConfigError("--on-lost", on_lost, f"must be one of {', '.join(ON_LOST)}")
    _quiet_asyncua()
    sys.setswitchinterval(0.001)    # the server and the simulation thread share the GIL: hand it over often
    archive = system_archive(system, root)
    files: list[Path] = []
    with OpenSystem(archive) as opened:
        recorder = Recorder(opened.system.name, Path(out)) if out is not None else None
        watch, sinks, columns = _crash_watch(opened, start_values or {}, recorder, record, drawing)
        session = opened.open_session(
            stop_time=math.inf if stop_time is None else stop_time, step_size=step_size,
            start_values=dict(start_values or {}), record=columns, sinks=sinks)
        components = {c.name: c.model for c in opened.system.components}
        runner = Runner(session, points_of(opened.slaves), speed, recorder,
                        check_parameter=parameter_check(components, session), watch=watch)
        server = LiveServer(opened.system.name, runner, endpoint, security, watchdog=watchdog,
                            cnc_components=components if cnc else None, on_lost=on_lost, on_verdict=on_verdict)
        try:
            asyncio.run(server.serve(ready))
        finally:
            writes = list(session.writes)
            end = float(session.time)
            # a served run ends by being stopped: its recording is complete unless the simulation failed
            session.close(complete=runner.state not in ENDED_BADLY, reason=runner.reason)
            if watch is not None:
                watch.close()
                # the rows after the last hand-over (judged at the close): a program that ended there is told too
                if len(watch.verdicts()) > server.verdicts_published and on_verdict is not None:
                    for t, text in watch.verdicts()[server.verdicts_published:]:
                        on_verdict(t, text)
            if recorder is not None:
                recorder.end_segment(writes, final=True, start=runner.start_time)
                files = recorder.files
            writes = runner.earlier_writes + writes          # the summary counts every segment's
        p50, p99, pmax = runner.stats.percentiles()
        return ServeSummary(opened.system.name, end, runner.state, runner.reason,
                            runner.stats.overruns, p50, p99, pmax, files, writes, runner.wall)
