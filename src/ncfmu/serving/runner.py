"""The simulation thread: :class:`Runner` paces a session to the wall clock, applies the clients' commands
between chunks and leaves a :class:`Snapshot` of the values for the server (see :mod:`ncfmu.serving`). It knows
nothing of OPC UA."""

from __future__ import annotations

import logging
import math
import queue
import threading
import time as _time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from ..errors import ConfigError, FmuCrashed, NcfmuError, SimulationError, TerminationRequested
from .address_space import Point
from .crash_watch import CRASH_CHECK, CrashWatch, crash_text
from .recording import Recorder

log = logging.getLogger("ncfmu.serve")     # the name it had before the package was split

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

#: The input that puts a channel in feed hold (our NC controllers' name for it; a foreign FMU may follow it): what
#: ``--on-lost hold`` forces true when a client that forced inputs is lost.
FEED_HOLD_INPUT = "feed_hold"


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
    """Paces a session in a worker thread (see the package's docstring, :mod:`ncfmu.serving`)."""

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
        self._snapshot: Snapshot | None = None       # the newest one, until snapshot() takes it
        self._latest: Snapshot                        # the newest one, for latest()
        self._snapshot_lock = threading.Lock()
        self._want_snapshot = True
        self._stop = threading.Event()
        self._said_overrun = False
        #: called from the simulation thread when it ends (the server then stops, unless the run failed)
        self.on_state = on_state
        self.thread = threading.Thread(target=self._main, name="ncfmu-simulation", daemon=True)
        self._take_snapshot()
        assert self._snapshot is not None
        # fixed parameters (and the rest that no step changes): read once, published with the first snapshot
        for p in self.points:
            if p.name not in self._snapshot.values:
                self._snapshot.values[p.name] = session.value(p.name)
        #: the first snapshot's values: what latest() shows of a variable no later snapshot holds (a fixed one)
        self._first_values: dict[str, object] = dict(self._snapshot.values)

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

    def latest(self) -> Snapshot:
        """The newest snapshot, every variable's value in it (the fixed parameters' as read at the start), without
        taking it from :meth:`snapshot`'s one reader (the OPC UA server); for any other reader (a web page), from
        any thread, as often as it likes (and ask for the next one). The simulation thread is never waited for."""
        with self._snapshot_lock:
            snap = self._latest
        self._want_snapshot = True
        return replace(snap, values={**self._first_values, **snap.values})

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
            self._snapshot = self._latest = Snapshot(float(s.time), values, forced, self.state, self.reason,
                                                     self.lag, self.stats.overruns, self.crashes, self.verdicts)
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
            if self.on_state is not None:
                self.on_state()
