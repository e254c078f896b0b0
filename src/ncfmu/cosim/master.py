"""The co-simulation master: fixed communication step, Gauss-Seidel (default) or Jacobi.

- **Gauss-Seidel**: the components are stepped in system order (panel -> controller -> servos);
  each takes its inputs from the newest outputs, so a controller's command reaches the servo in
  the same step, and the servo's answer reaches the controller in the next.
- **Jacobi**: every component takes its inputs from the outputs of the previous communication
  point, then all step (what libcosim's fixed-step algorithm does).

All outputs of one kind of all components live in one numpy vector; each slave reads its outputs
straight into its slice and its inputs are gathered with one ``numpy.take`` per kind. Nothing is
allocated inside the loop. The master depends only on the :class:`~ncfmu.cosim.slave.Slave`
interface, so it is tested with a fake slave.

When every slave also offers its raw FMI functions (:class:`~ncfmu.cosim.native_loop.NativeSlave`: the
FMUs), the steps run in C (``loop.c``), call for call the same; Python acts only between chunks of
steps: at input changes, progress reports, deadline checks and when the record window is full.

A run is a :class:`Session` (:meth:`Master.open_session`): advanced step by step, inputs forced and
released, tunable parameters set, its recorded rows streamed into sinks (:mod:`ncfmu.cosim.record`).
Each forced input reads from a slot of its own in the value vector instead of its source (the gather
index changes; nothing runs per step). :meth:`Master.run` is one session from start to stop.
The rows go through a bounded record window: the whole run when it is kept in memory, a chunk of rows
otherwise (written to the sinks whenever it is full), so a run that keeps nothing holds nothing that
grows with the simulated time.
"""

from __future__ import annotations

import csv
import math
import signal
import threading
import time as _time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import ConfigError, SimulationError, SimulationTimeout, SystemDefinitionError, TerminationRequested
from ..ports import NUMBER_RULE, parse_real
from .connect import check_units
from .fmu import check_range, typed_value
from .native_loop import NativePlan, NativeSlave, library
from .record import MAX_RECORD_BYTES, RecordSink, too_big
from .result import Result
from .slave import DTYPES, KINDS, ReadableSlave, ResettableSlave, Slave, StatefulSlave, Variable
from .ssp import System

__all__ = ["MAX_RECORD_BYTES", "InputTable", "Interrupted", "Master", "Session", "deferred_interrupts", "steps_per_row",
           "write_input_csv"]

MODES = ("gauss-seidel", "jacobi")

#: Steps run before the loop hands back to Python (10 s simulated at 1 ms; ~0.3 s of lathe_taper in C).
NATIVE_CHUNK = 10_000

#: The record window of a run that keeps nothing in memory: about this many bytes of rows.
WINDOW_BYTES = 2 ** 20

#: The dtype of a recorded column of each kind (Booleans as bool, as fmpy's results)
COLUMN_DTYPES: dict[str, np.dtype] = {"Real": np.dtype(np.float64), "Integer": np.dtype(np.int32),
                                     "Boolean": np.dtype(np.bool_)}

#: An input CSV cell: a value, empty (no change at this row), or ``release`` (the connection drives it again).
VALUE, EMPTY, RELEASE = 1, 0, 2

#: How close to a communication point an input change counts as at it (s).
TIME_SLACK = 1e-12


@dataclass
class InputTable:
    """Changes over time (columns ``INSTANCE.VARIABLE``), applied before the first step at or after their time.

    A column may be an input no connection drives (its value from that row's time on, as fmpy reads an input
    CSV), an input a connection drives (forced to that value from that time), or a tunable parameter (set at
    that time). ``cells[name]`` says per row whether the cell holds a value (:data:`VALUE`), is empty
    (:data:`EMPTY`: no change at this row) or says ``release`` (:data:`RELEASE`: the connection, or the start
    value of an input no connection drives, drives it again); a column without ``cells`` holds values only.
    """

    time: np.ndarray
    columns: dict[str, np.ndarray] = field(default_factory=dict)
    cells: dict[str, np.ndarray] = field(default_factory=dict)

    def cell_kinds(self, name: str) -> np.ndarray:
        kinds = self.cells.get(name)
        return np.full(len(self.time), VALUE, dtype=np.int8) if kinds is None else kinds

    @classmethod
    def from_csv(cls, path) -> InputTable:
        """Read fmpy's CSV layout (``time``, then ``INSTANCE.VARIABLE`` columns; names may be quoted): numbers,
        empty cells (no change) and the word ``release``. Every mistake is a :class:`SystemDefinitionError`
        naming the file, the line and what is wrong."""
        try:
            with open(path, newline="") as f:
                lines = list(csv.reader(f))
        except (OSError, UnicodeDecodeError, csv.Error) as err:
            raise SystemDefinitionError(f"{path}: cannot read the input CSV: {err}") from None
        if not lines or not any(cell.strip() for cell in lines[0]):
            raise SystemDefinitionError(f"{path}: the input CSV is empty "
                                        "(expected a header time,INSTANCE.VARIABLE,...)")
        header = [h.strip() for h in lines[0]]
        if header[0] != "time":
            raise SystemDefinitionError(f"{path}: an input CSV needs a first column 'time'")
        seen = set()
        for name in header:
            if name in seen:
                raise SystemDefinitionError(f"{path}: line 1: column {name!r} twice")
            seen.add(name)
        rows = [(k, r) for k, r in enumerate(lines[1:], start=2) if any(cell.strip() for cell in r)]
        if not rows:
            raise SystemDefinitionError(f"{path}: the input CSV has a header and no rows")
        table = np.full((len(rows), len(header)), np.nan)
        kinds = np.full((len(rows), len(header)), VALUE, dtype=np.int8)
        for i, (k, row) in enumerate(rows):
            if len(row) != len(header):
                raise SystemDefinitionError(f"{path}: line {k}: {len(row)} values for {len(header)} columns")
            for j, raw in enumerate(row):
                cell = raw.strip()
                if j and not cell:
                    kinds[i, j] = EMPTY
                elif j and cell == "release":
                    kinds[i, j] = RELEASE
                else:
                    try:
                        table[i, j] = parse_real(cell)
                    except ValueError:
                        raise SystemDefinitionError(f"{path}: line {k}: {header[j]} = {raw!r}: not a number"
                                                    + ("" if j == 0 else ", empty (no change) or 'release'")
                                                    + ("" if cell.isascii() else f" ({NUMBER_RULE})")) from None
        t = table[:, 0]
        if not np.all(np.isfinite(t)):
            k = rows[int(np.flatnonzero(~np.isfinite(t))[0])][0]
            raise SystemDefinitionError(f"{path}: line {k}: time must be finite")
        if np.any(np.diff(t) < 0):
            raise SystemDefinitionError(f"{path}: the time column must not decrease")
        return cls(t, {n: table[:, j] for j, n in enumerate(header) if j > 0},
                   {n: kinds[:, j] for j, n in enumerate(header) if j > 0 and (kinds[:, j] != VALUE).any()})


def write_input_csv(path: Path | str, writes: Iterable[tuple[float, str, object]]) -> Path:
    """A session's write log as an input CSV that :meth:`InputTable.from_csv` reads back: fmpy's layout (``time``,
    then quoted names), one row per write (``None`` -> ``release``), every other cell empty (no change)."""
    writes = list(writes)
    names = list(dict.fromkeys(name for _, name, _ in writes))
    column = {name: j for j, name in enumerate(names)}
    lines = [",".join(f'"{n}"' for n in ["time", *names])]
    for t, name, value in writes:
        cells = [""] * len(names)
        if value is None:
            cells[column[name]] = "release"
        elif isinstance(value, (bool, np.bool_)):
            cells[column[name]] = "1" if value else "0"
        elif isinstance(value, (int, np.integer)):
            cells[column[name]] = str(int(value))
        else:
            cells[column[name]] = repr(float(value))     # type: ignore[arg-type]  # shortest round-trip form: read back exactly
        lines.append(",".join([repr(float(t)), *cells]))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    from ..files import write_atomic
    write_atomic(path, ("\n".join(lines) + "\n").encode())
    return path


@dataclass
class _BoundInput:
    """An input in the gather plan: read from ``source`` (a connection's output, or an input-CSV slot), or
    from ``force_slot`` while forced."""

    kind: str
    idx: np.ndarray          # the gather indices of its slave and kind (shared with the C loop)
    pos: int
    in_buf: np.ndarray
    source: int
    force_slot: int


@dataclass
class _Run:
    """Everything one run needs inside the loop, prepared once."""

    h: float
    start_time: float
    stop_time: float          # math.inf: until closed
    n_steps: int | None       # None: no stop time
    values: dict
    plan: list
    record_names: dict        # kind -> every output of that kind, in vector order
    n_rec: dict
    rec: dict                 # kind -> the record window: row r holds the run's row row_base + r
    every: int                # record every ``every``-th step (and the start)
    capacity: int             # rows in the window
    columns: list[tuple[str, str, int]]   # (name, kind, index in record_names[kind]): what the rows carry
    start_values: dict        # instance -> variable -> value: the system's parameter sets with the caller's applied
    bound: dict               # INSTANCE.VARIABLE -> _BoundInput
    ext: dict                 # INSTANCE.VARIABLE -> (kind, slot): inputs no connection drives, set by the CSV
    schedule: list            # (first step, [actions]) of the input CSV, in time order
    native: NativePlan | None = None
    row_base: int = 0
    step: int = 0             # steps done
    next_change: int = 0
    forced: dict = field(default_factory=dict)
    unbound: dict = field(default_factory=dict)   # inputs outside the plan: the value last set
    flush: Callable[[], None] | None = None

    def time_of(self, step: int) -> float:
        """The communication point after ``step`` steps: computed as both loops compute it."""
        return self.start_time + self.h * step

    @property
    def rows_done(self) -> int:
        """Rows of the window that hold finished steps."""
        return self.step // self.every - self.row_base + 1

    def rows(self, count: int) -> np.ndarray:
        """The first ``count`` rows of the window as a structured array of the recorded columns."""
        dtype = [("time", np.float64)] + [(name, COLUMN_DTYPES[kind]) for name, kind, _ in self.columns]
        data = np.empty(count, dtype=dtype)
        data["time"] = self.start_time + self.h * ((self.row_base + np.arange(count)) * self.every)
        for name, kind, j in self.columns:
            data[name] = self.rec[kind][:count, j]
        return data


def steps_per_row(output_interval: float | None, h: float) -> int:
    """Steps between recorded rows for an output interval (None: every step); it must be a whole multiple of ``h``."""
    if output_interval is None:
        return 1
    ratio = float(output_interval) / h
    if not (math.isfinite(ratio) and ratio >= 1 - 1e-9 and abs(ratio - round(ratio)) <= 1e-9 * ratio):
        raise SystemDefinitionError(f"output interval {output_interval!r} s: must be a whole multiple of the "
                                    f"step {h:g} s")
    return int(round(ratio))


#: Signals noted inside :func:`deferred_interrupts`, raised by the loop between chunks of steps.
_PENDING: list[int] = []


class Interrupted(KeyboardInterrupt):
    """Ctrl-C or SIGTERM during a run, raised between chunks of steps (``signum`` says which)."""

    def __init__(self, signum: int) -> None:
        self.signum = signum
        super().__init__(signal.Signals(signum).name)


@contextmanager
def deferred_interrupts(signums: Sequence[int] = (signal.SIGINT, signal.SIGTERM)) -> Iterator[None]:
    """Inside: Ctrl-C and SIGTERM are noted and raised as :class:`Interrupted` by the master between chunks of
    steps, never inside an FMU's own Python code (a pythonfmu FMU runs in this interpreter and turns an
    exception raised in its step into fmi2Fatal). Only in the main thread; elsewhere nothing changes."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {signum: signal.signal(signum, lambda received, frame: _PENDING.append(received))
                for signum in signums}
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        _PENDING.clear()


def _output_slots(slaves, kind, ext_names):
    """Slot in the global vector of ``kind`` for every output of that kind, then for the CSV inputs."""
    slots: dict[str, int] = {}
    for s in slaves:
        for v in s.variables.values():
            if v.causality == "output" and v.type == kind:
                slots[f"{s.name}.{v.name}"] = len(slots)
    for name in ext_names:
        slots[name] = len(slots)
    return slots


def _a(causality: str) -> str:
    """``an output``, ``a parameter``: a causality with its article, for messages."""
    return f"{'an' if causality[:1] in 'aeiou' else 'a'} {causality}"


def _described(v: Variable) -> str:
    """``a fixed parameter``, ``an output``: what a variable is, with its article, for messages."""
    return f"a {v.variability} parameter" if v.causality == "parameter" and v.variability else _a(v.causality)


def _as_python(kind: str, value) -> object:
    if kind == "Real":
        return float(value)
    if kind == "Boolean":
        return bool(value)
    return int(value)


#: The modelDescription's rule for a value written during a run (one home: the slave's module)
_check_range = check_range


#: Steps a run counts at most (whole numbers in a double): a stop time beyond is a mistake, not a run.
MAX_STEPS = 2.0 ** 53


class Master:
    """Run a :class:`~ncfmu.cosim.ssp.System` whose components are given as slaves.

    Parameters
    ----------
    system : System
    slaves : sequence of Slave
        One per component, in the system's order, already instantiated.
    mode : {"gauss-seidel", "jacobi"}
    native : bool
        Run the steps in C when every slave allows it (False: always the Python loop).
    """

    def __init__(self, system: System, slaves: Sequence[Slave], mode: str = "gauss-seidel",
                 native: bool = True) -> None:
        if mode not in MODES:
            raise SystemDefinitionError(f"mode = {mode!r}: must be one of {', '.join(MODES)}")
        self.system, self.slaves, self.mode, self.native = system, slaves, mode, native
        #: which loop the last run stepped in: "c" or "python"
        self.loop_used = ""
        self.by_name = {s.name: s for s in slaves}
        self.check_connections()
        checked = check_units(system, self.by_name)
        #: input (instance, variable) -> the unit conversion its connection applies; the warnings of the checks
        self.conversions, self.warnings = checked.conversions, checked.warnings
        self.sources = {(c.end_element, c.end_connector): f"{c.start_element}.{c.start_connector}"
                        for c in system.connections}

    # -- checks before anything runs ------------------------------------------------------------
    def check_connections(self) -> None:
        seen_inputs: dict[tuple[str, str], str] = {}
        for c in self.system.connections:
            for inst in (c.start_element, c.end_element):
                if inst not in self.by_name:
                    raise SystemDefinitionError(f"connection {c}: no component {inst!r} in {self.system.name}")
            src = self.by_name[c.start_element].variables.get(c.start_connector)
            dst = self.by_name[c.end_element].variables.get(c.end_connector)
            if src is None:
                raise SystemDefinitionError(f"connection {c}: {c.start_element} has no variable {c.start_connector!r}")
            if dst is None:
                raise SystemDefinitionError(f"connection {c}: {c.end_element} has no variable {c.end_connector!r}")
            if src.causality != "output":
                raise SystemDefinitionError(f"connection {c}: {c.start_element}.{c.start_connector} is "
                                            f"{_a(src.causality)}, not an output")
            if dst.causality != "input":
                raise SystemDefinitionError(f"connection {c}: {c.end_element}.{c.end_connector} is "
                                            f"{_a(dst.causality)}, not an input")
            if src.type != dst.type or src.type not in KINDS:
                raise SystemDefinitionError(f"connection {c}: type mismatch ({src.type} -> {dst.type})")
            key = (c.end_element, c.end_connector)
            if key in seen_inputs:
                raise SystemDefinitionError(f"connection {c}: input already driven by {seen_inputs[key]}")
            seen_inputs[key] = str(c)

    def variable(self, qualified: str):
        inst, _, var = qualified.partition(".")
        slave = self.by_name.get(inst)
        if slave is None:
            raise SystemDefinitionError(f"unknown instance {inst!r} in {qualified!r}; instances: "
                                        f"{', '.join(self.by_name)}")
        v = slave.variables.get(var)
        if v is None:
            raise SystemDefinitionError(f"{inst} has no variable {var!r}")
        return slave, v

    def outputs(self) -> list[str]:
        """``INSTANCE.VARIABLE`` of every output, in the order a run records them by default."""
        return [f"{s.name}.{v.name}" for kind in KINDS for s in self.slaves for v in s.variables.values()
                if v.causality == "output" and v.type == kind]

    # -- runs and sessions ----------------------------------------------------------------------
    def run(self, stop_time: float | None = None, step_size: float | None = None,
            start_values: Mapping[str, object] | None = None, inputs: InputTable | None = None,
            start_time: float = 0.0, progress: Callable[[float], None] | None = None,
            deadline: float | None = None, record: Sequence[str] | None = None,
            output_interval: float | None = None, sinks: Sequence[RecordSink] = (), keep: bool = True) -> Result:
        """Initialise every slave, step to ``stop_time`` and return the recorded outputs.

        ``record`` names the outputs recorded (default: every output), ``output_interval`` records every so
        many seconds (a whole multiple of the step: the start row and every k-th row). The rows go to every
        sink in ``sinks`` as the run goes; with ``keep`` False nothing is held in memory and the returned
        Result has no rows (only its span, messages and parameters). An interrupted run (an exception,
        Ctrl-C) closes the sinks as incomplete with every row of the finished chunks, then raises.
        ``deadline`` (a ``time.perf_counter()`` value): past it the run stops with :class:`SimulationTimeout`.
        """
        if stop_time is not None and not math.isfinite(float(stop_time)):
            raise SystemDefinitionError(f"stop time = {stop_time!r}: a run needs a finite stop time "
                                        "(a session may run until closed)")
        session = self.open_session(stop_time, step_size, start_values, inputs, start_time, record,
                                    output_interval, sinks, keep=keep)
        try:
            assert session.run.n_steps is not None
            session._advance(session.run.n_steps, progress, deadline)
        except TerminationRequested as ended:
            # an FMU asked to end (fmi2Discard + terminateSimulation): the run ends cleanly at the last whole step
            session.failed = None
            result = session.close(reason=str(ended))
            result.ended_by = str(ended)
            return result
        except BaseException as err:
            session.close(complete=False, reason=str(err) or type(err).__name__)
            raise
        return session.close()

    def open_session(self, stop_time: float | None = None, step_size: float | None = None,
                     start_values: Mapping[str, object] | None = None, inputs: InputTable | None = None,
                     start_time: float = 0.0, record: Sequence[str] | None = None,
                     output_interval: float | None = None, sinks: Sequence[RecordSink] = (),
                     keep: bool = False) -> Session:
        """Initialise every slave and return a :class:`Session` at ``start_time``.

        ``stop_time`` None: the system's; ``math.inf``: until closed. ``keep``: hold the recorded rows in memory
        for the Result :meth:`Session.close` returns (needs a finite stop time).
        """
        every = self._every(output_interval, step_size)
        run = self._prepare(stop_time, step_size, start_values, inputs, start_time, record, every, keep)
        return Session(self, run, list(sinks), keep, (stop_time, step_size, start_values, inputs, start_time,
                                                      record, every))

    def _every(self, output_interval: float | None, step_size: float | None) -> int:
        return steps_per_row(output_interval, self.system.step_size if step_size is None else float(step_size))

    def run_branches(self, branch_time: float, variants: Sequence[Mapping[str, object]],
                     stop_time: float | None = None, step_size: float | None = None,
                     start_values: Mapping[str, object] | None = None, inputs: InputTable | None = None,
                     start_time: float = 0.0) -> list[Result]:
        """Simulate to ``branch_time`` once, save every FMU's state, then run each variant from it.

        A variant sets tunable parameters or inputs (``INSTANCE.VARIABLE`` -> value) at the branch
        point, e.g. ``{"panel.emergency_at": 12.5}``. Each result covers the whole run, and its messages are
        the shared prefix's and its own (never another branch's).
        """
        stateful = [self._stateful(s) for s in self.slaves]
        run = self._prepare(stop_time, step_size, start_values, inputs, start_time)
        assert run.n_steps is not None
        steps = (branch_time - start_time) / run.h      # nan or beyond the run (1e308 s) is refused, not rounded
        k = int(round(steps)) if 0 < steps < run.n_steps else 0
        if not 0 < k < run.n_steps:
            raise SystemDefinitionError(f"branch time {branch_time} s must lie inside the run "
                                        f"({start_time}..{start_time + run.n_steps * run.h} s)")
        wall = self._loop(run, 0, k)
        states = [holder.get_state() for holder in stateful]
        prefix = {kind: run.rec[kind][:k + 1].copy() for kind in KINDS}
        vector = {kind: run.values[kind].copy() for kind in KINDS}
        # the log lines each slave had at the branch point: a branch's result carries these and its own only
        logs = [s.messages for s in self.slaves]
        marks = [len(log) for log in logs]
        next_change = run.next_change
        results = []
        try:
            for variant in variants:
                for holder, state in zip(stateful, states):
                    holder.set_state(state)
                for log, mark in zip(logs, marks):
                    del log[mark:]
                for kind in KINDS:
                    run.values[kind][:] = vector[kind]
                    run.rec[kind][:k + 1] = prefix[kind]
                run.step, run.next_change = k, next_change
                applied = {inst: dict(values) for inst, values in run.start_values.items()}
                for qualified, value in variant.items():
                    slave, v = self.variable(qualified)
                    slave.set_start(v.name, value)
                    applied[slave.name][v.name] = value
                for s in self.slaves:
                    s.read_outputs()
                run_wall = wall + self._loop(run, k, run.n_steps)
                results.append(self._assemble(run, run_wall, applied))
        finally:
            for holder, state in zip(stateful, states):
                holder.free_state(state)
        return results

    @staticmethod
    def _stateful(slave: Slave) -> StatefulSlave:
        if not isinstance(slave, StatefulSlave):
            raise SystemDefinitionError(f"{slave.name} cannot save and restore its state: no branching")
        return slave

    def _prepare(self, stop_time, step_size, start_values, inputs, start_time, record=None, every: int = 1,
                 keep: bool = True) -> _Run:
        stop = self.system.stop_time if stop_time is None else float(stop_time)
        h = self.system.step_size if step_size is None else float(step_size)
        if not (math.isfinite(h) and h > 0):
            raise SystemDefinitionError(f"step size = {h!r}: must be > 0")
        if not (stop > start_time and not math.isnan(stop)):
            raise SystemDefinitionError(f"stop time = {stop!r}: must be after the start time {start_time}")
        n_steps: int | None = None
        if math.isfinite(stop):
            steps = (stop - start_time) / h       # judged before rounding: 1e308 s at 1 ms is inf steps
            if not steps < MAX_STEPS:
                raise SystemDefinitionError(f"stop time {stop:g} s at a step of {h:g} s is {steps:.6g} steps: more "
                                            f"than a run counts ({MAX_STEPS:.0e}); shorten the run")
            n_steps = int(round(steps))
            if n_steps < 1:
                raise SystemDefinitionError(f"stop time {stop:g} s is shorter than one step ({h:g} s) after the "
                                            f"start time {start_time:g} s: nothing would run")
        elif keep:
            raise SystemDefinitionError("a session without a stop time keeps nothing in memory (keep=False): "
                                        "give it sinks for its rows")

        # What is recorded: every output, or the ones named (in the order named).
        by_kind = {kind: [f"{s.name}.{v.name}" for s in self.slaves for v in s.variables.values()
                          if v.causality == "output" and v.type == kind] for kind in KINDS}
        position = {name: (kind, j) for kind in KINDS for j, name in enumerate(by_kind[kind])}
        names = [n for kind in KINDS for n in by_kind[kind]] if record is None else list(dict.fromkeys(record))
        for name in names:
            if name not in position:
                raise SystemDefinitionError(f"record {name!r}: not an output of {self.system.name} "
                                            "(outputs are INSTANCE.VARIABLE, e.g. x_axis.pos)")
        columns: list[tuple[str, str, int]] = [(name, *position[name]) for name in names]
        window_row = sum(len(by_kind[k]) * np.dtype(DTYPES[k]).itemsize for k in KINDS)
        if keep:
            assert n_steps is not None
            capacity = n_steps // every + 1
            kept_row = 8 + sum(COLUMN_DTYPES[kind].itemsize for _, kind, _ in columns)
            refusal = too_big(capacity, window_row + kept_row,
                              f"stop time {stop:g} s at a step of {h:g} s ({n_steps} steps, {capacity} rows)")
            if refusal is not None:
                raise refusal
        else:
            capacity = max(1, WINDOW_BYTES // max(window_row, 1))
            if n_steps is not None:
                capacity = min(capacity, n_steps // every + 1)

        # Start values: the system's parameter sets, then the caller's overrides.
        applied: dict[str, dict[str, object]] = {s.name: {} for s in self.slaves}
        for comp in self.system.components:
            for name, value in comp.parameters.items():
                self._in_range(f"{comp.name}.{name}", value)
                self.by_name[comp.name].set_start(name, value)
                applied[comp.name][name] = value
        for qualified, value in (start_values or {}).items():
            slave, v = self.variable(qualified)
            self._in_range(qualified, value)
            if (slave.name, v.name) in self.sources:
                c = self.sources[(slave.name, v.name)]
                raise SystemDefinitionError(f"{qualified} is driven by the connection {c} -> {qualified}: a start "
                                            f"value would be overwritten every step (set {c} instead)")
            slave.set_start(v.name, value)
            applied[slave.name][v.name] = value

        # The input CSV: inputs no connection drives get a slot of their own (set from the CSV), inputs a
        # connection drives are forced, tunable parameters are set.
        ext: dict[str, str] = {}
        csv_forced: set[str] = set()
        if inputs is not None:
            for qualified in inputs.columns:
                slave, v = self.variable(qualified)
                kinds = inputs.cell_kinds(qualified)
                if v.causality == "input" and v.type in KINDS:
                    if (slave.name, v.name) in self.sources:
                        csv_forced.add(qualified)
                    else:
                        ext[qualified] = v.type
                elif v.causality == "parameter" and v.variability == "tunable":
                    if (kinds == RELEASE).any():
                        raise SystemDefinitionError(f"input CSV column {qualified!r}: a parameter cannot be "
                                                    "released ('release' is for inputs)")
                else:
                    what = _described(v)
                    raise SystemDefinitionError(f"input CSV column {qualified!r} is {what}: only inputs and tunable "
                                                "parameters change during a run")

        for s in self.slaves:
            s.initialize(start_time, stop)

        # Global vectors: every output, then the CSV's inputs, then one force slot per input in the plan.
        values, slots, record_names = {}, {}, {}
        bound_inputs: dict[str, list[tuple[Slave, Variable]]] = {}
        for kind in KINDS:
            slots[kind] = _output_slots(self.slaves, kind, [q for q, t in ext.items() if t == kind])
            record_names[kind] = by_kind[kind]
            bound_inputs[kind] = [(s, v) for s in self.slaves for v in s.variables.values()
                                  if v.causality == "input" and v.type == kind
                                  and ((s.name, v.name) in self.sources or f"{s.name}.{v.name}" in ext)]
            values[kind] = np.zeros(len(slots[kind]) + len(bound_inputs[kind]), dtype=DTYPES[kind])
        force_slot = {f"{s.name}.{v.name}": len(slots[kind]) + j
                      for kind in KINDS for j, (s, v) in enumerate(bound_inputs[kind])}
        ext_slots = {q: (kind, slots[kind][q]) for q, kind in ext.items()}
        for q, (kind, slot) in ext_slots.items():
            # until its first row, an input the CSV drives keeps its start value
            slave, v = self.variable(q)
            start = applied[slave.name].get(v.name, v.start)
            values[kind][slot] = 0 if start is None else start

        plan, bindings, bound = [], [], {}
        for s in self.slaves:
            gathers: list[tuple] = []
            kinds_bound = {}
            for kind in KINDS:
                outs = [v for v in s.variables.values() if v.causality == "output" and v.type == kind]
                first = slots[kind][f"{s.name}.{outs[0].name}"] if outs else 0
                out_view = values[kind][first:first + len(outs)]
                ins = [v for v in s.variables.values() if v.causality == "input" and v.type == kind
                       and ((s.name, v.name) in self.sources or f"{s.name}.{v.name}" in ext)]
                idx = np.array([slots[kind][self.sources.get((s.name, v.name), f"{s.name}.{v.name}")] for v in ins],
                               dtype=np.intp)
                in_buf = np.zeros(len(ins), dtype=DTYPES[kind])
                s.bind(kind, in_buf, [v.vr for v in ins], out_view, [v.vr for v in outs])
                kinds_bound[kind] = (in_buf, [v.vr for v in ins], idx, out_view, [v.vr for v in outs])
                for pos, v in enumerate(ins):
                    q = f"{s.name}.{v.name}"
                    bound[q] = _BoundInput(kind, idx, pos, in_buf, int(idx[pos]), force_slot[q])
                if len(ins):
                    gathers.append((in_buf, self._gather(s, kind, ins, values[kind]), idx))
            plan.append((s, tuple(gathers)))
            bindings.append(kinds_bound)

        n_rec = {k: len(record_names[k]) for k in KINDS}
        rec = {k: np.empty((capacity, n_rec[k]), dtype=DTYPES[k]) for k in KINDS}
        for s in self.slaves:
            s.read_outputs()
        for k in KINDS:
            rec[k][0] = values[k][:n_rec[k]]
        run = _Run(h, float(start_time), stop, n_steps, values, plan, record_names, n_rec, rec, every, capacity,
                   columns, applied, bound, ext_slots, [])
        if inputs is not None:
            run.schedule = self._schedule(run, inputs, csv_forced)
        for _s, prepared in plan:
            for buf, take, idx in prepared:
                take(idx, out=buf)             # what each input is given at the first step (Session.value)
        natives = [s for s in self.slaves if isinstance(s, NativeSlave)]
        if self.native and len(natives) == len(self.slaves) and library() is not None and not self.conversions:
            records = [(rec[k], values[k][:n_rec[k]]) for k in KINDS if n_rec[k]]
            run.native = NativePlan(natives, bindings, values, records, run.start_time, h,
                                    self.mode == "jacobi", every)
        return run

    def _in_range(self, qualified: str, value: object) -> None:
        """A start value within its modelDescription's min/max, whichever FMU it is for (an FMU need not check)."""
        slave, v = self.variable(qualified)
        if v.type in ("Real", "Integer") and not isinstance(value, (bool, str)):
            _check_range(qualified, v, typed_value(qualified, v.type, value))

    def _gather(self, s: Slave, kind: str, ins: list[Variable], vector: np.ndarray) -> Callable:
        """``take(idx, out)`` for a slave's inputs of ``kind``: the vector's values, converted to the inputs' units
        where a connection converts (then the Python loop runs: the C loop gathers without converting)."""
        convs = [self.conversions.get((s.name, v.name)) for v in ins]
        if not any(convs):
            return vector.take
        gain = np.array([1.0 if c is None else c.gain for c in convs])
        offset = np.array([0.0 if c is None else c.offset for c in convs])

        def take(idx: np.ndarray, out: np.ndarray) -> None:
            vector.take(idx, out=out)
            out *= gain
            out += offset
        return take

    def _schedule(self, run: _Run, inputs: InputTable, forced: set[str]) -> list:
        """The CSV's changes as (first step they apply to, actions) in time order: a change at time tc applies
        from the first step whose start time t satisfies t + 1e-12 >= tc."""
        steps: dict[int, list] = {}
        for i, tc in enumerate(inputs.time.tolist()):
            actions: list[tuple[str, str, object]] = []
            for q, col in inputs.columns.items():
                kind = inputs.cell_kinds(q)[i]
                if kind == EMPTY:
                    continue
                slave, v = self.variable(q)
                if kind == RELEASE:
                    # an input no connection drives goes back to its start value, any other to its connection
                    actions.append(("ext_release" if q in run.ext else "release", q, None))
                    continue
                value = col[i]
                if q in run.ext:
                    # an input no connection drives: as fmpy's input CSV (the value converted to the kind)
                    actions.append(("ext", q, np.asarray(value).astype(DTYPES[v.type])))
                    continue
                typed = typed_value(q, v.type, float(value) if v.type == "Real" else value)
                _check_range(q, v, typed)
                actions.append(("force" if q in forced else "param", q, typed))
            if not actions:
                continue
            step = max(0, math.ceil((tc - TIME_SLACK - run.start_time) / run.h))
            while step > 0 and run.time_of(step - 1) + TIME_SLACK >= tc:
                step -= 1
            while run.time_of(step) + TIME_SLACK < tc:
                step += 1
            steps.setdefault(step, []).extend(actions)
        return sorted(steps.items())

    def _apply(self, run: _Run, action: str, name: str, value) -> None:
        """One write between steps: a CSV row's cell or a session's force/release/parameter."""
        slave, v = self.variable(name)
        if action == "ext":
            kind, slot = run.ext[name]
            run.values[kind][slot] = value
        elif action == "force":
            b = run.bound.get(name)
            if b is None:
                slave.set_start(v.name, value)          # an input outside the plan keeps what it is set to
                run.unbound[name] = value
            else:
                conv = self.conversions.get((slave.name, v.name))
                # the slot is gathered like the connection's source: in the source's unit
                run.values[b.kind][b.force_slot] = value if conv is None else (value - conv.offset) / conv.gain
                b.idx[b.pos] = b.force_slot
            run.forced[name] = value
        elif action == "ext_release":
            kind, slot = run.ext[name]
            start = run.start_values[slave.name].get(v.name, v.start)
            run.values[kind][slot] = 0 if start is None else start
        elif action == "release":
            run.forced.pop(name, None)
            b = run.bound.get(name)
            start = run.start_values[slave.name].get(v.name, v.start)
            if b is not None:
                b.idx[b.pos] = b.source
            elif start is not None:
                slave.set_start(v.name, start)
                run.unbound[name] = start
        else:                                           # a tunable parameter
            slave.set_start(v.name, value)
            run.start_values[slave.name][v.name] = value

    def _loop(self, run: _Run, first: int, last: int, progress=None, deadline: float | None = None) -> float:
        """Steps ``first`` .. ``last - 1``; returns the wall time.

        The steps run in chunks that end where Python must act before the next step (an input change, a
        progress report, a deadline check every 64 steps, a full record window, and every ``NATIVE_CHUNK``
        steps so that Ctrl-C is seen); each chunk runs in C when every slave allows it, else in Python. Both
        make the same calls.
        """
        schedule, every = run.schedule, run.every
        report_every = max(1, (run.n_steps or 1) // 100)
        self.loop_used = "python" if run.native is None else "c"
        advance: Callable[[int, int, int], None]
        if run.native is not None:
            run.native.forget_sent()     # start values, a restored state or a direct set may have changed inputs
            advance = run.native.run
        else:
            advance = self._python_steps(run)
        wall0 = _time.perf_counter()
        i = first
        try:
            while i < last:
                while run.next_change < len(schedule) and schedule[run.next_change][0] <= i:
                    for action, name, value in schedule[run.next_change][1]:
                        self._apply(run, action, name, value)
                    run.next_change += 1
                if i // every + 1 - run.row_base >= run.capacity:
                    assert run.flush is not None, "the record window is full and nothing takes its rows"
                    run.flush()
                end = min(last, i + NATIVE_CHUNK, (run.row_base + run.capacity) * every - 1)
                if run.next_change < len(schedule):
                    end = min(end, schedule[run.next_change][0])
                if progress is not None:
                    end = min(end, (i + report_every) // report_every * report_every)   # the next row to report
                if deadline is not None:
                    end = min(end, (i + 64) // 64 * 64)
                advance(i, end, run.row_base)
                i = run.step = end
                if _PENDING:
                    raise Interrupted(_PENDING[0])
                if progress is not None and end % report_every == 0 and run.n_steps:
                    progress(end / run.n_steps)
                if deadline is not None and end % 64 == 0 and _time.perf_counter() > deadline:
                    stop = f" of {run.time_of(run.n_steps):.3f} s" if run.n_steps is not None else ""
                    raise SimulationTimeout(f"stopped at t = {run.time_of(end):.3f} s{stop}: over the time allowed "
                                            f"({_time.perf_counter() - wall0:.1f} s of wall time)")
        except SimulationError:
            failed = getattr(run.native, "failed_step", None)
            if failed is not None and i <= failed:
                run.step = failed          # the C loop says how far it got: those rows are whole
            raise
        return _time.perf_counter() - wall0

    def _python_steps(self, run: _Run) -> Callable[[int, int, int], None]:
        """The Python loop: ``advance(first, end, row_base)`` steps ``first`` .. ``end - 1`` and records the rows."""
        values, plan, rec, n_rec, h, start, every = (run.values, run.plan, run.rec, run.n_rec, run.h,
                                                     run.start_time, run.every)
        # the rows to record and the slices of the output vectors they copy, prepared once
        record = [(rec[k], values[k][:n_rec[k]]) for k in KINDS if n_rec[k]]
        jacobi = self.mode == "jacobi"

        def advance(first: int, end: int, row_base: int) -> None:
            for i in range(first, end):
                t = start + h * i
                if jacobi:
                    for _s, gathers in plan:
                        for buf, take, idx in gathers:
                            take(idx, out=buf)
                    for s, _ in plan:
                        s.write_inputs()
                        s.do_step(t, h)
                    for s, _ in plan:
                        s.read_outputs()
                else:
                    for s, gathers in plan:
                        for buf, take, idx in gathers:
                            take(idx, out=buf)
                        s.write_inputs()
                        s.do_step(t, h)
                        s.read_outputs()
                done = i + 1
                if done % every == 0:
                    row = done // every - row_base
                    for table, vector in record:
                        table[row] = vector
                run.step = done
        return advance

    def _assemble(self, run: _Run, wall: float, applied: dict[str, dict[str, object]]) -> Result:
        data = run.rows(run.rows_done)
        messages = {s.name: list(s.messages) for s in self.slaves}
        return Result(data, self.system.name, wall, messages, parameters=applied,
                      models={c.name: c.model for c in self.system.components},
                      span=(run.start_time, run.time_of(run.step)))

    def terminate(self) -> None:
        for s in self.slaves:
            s.terminate()


class Session:
    """A run stepped from outside: advance, read, force inputs, set tunable parameters, reset, close.

    Opened by :meth:`Master.open_session`. Writes (force, release, set_parameter) take effect from the next
    step; :attr:`writes` logs each one as ``(time, name, value or None for a release)`` at the communication
    point before the step it first applied to, which :func:`write_input_csv` turns into an input CSV that
    replays the session exactly (``Master.run(inputs=InputTable.from_csv(...))``).

    :meth:`reset` ends the recording: the sinks are closed (complete, reason ``reset``) and the session
    starts again at its start time recording into the sinks given to ``reset`` (none by default), with
    :attr:`writes` emptied.

    Details the agreed interface left open: ``open_session(stop_time=None)`` is the system's stop time and
    ``math.inf`` runs until closed (then ``keep`` must be False: ``keep=True`` holds the rows for the Result);
    :meth:`close` always returns a Result (rows only when kept); releasing what is not forced does nothing and
    is not logged; an input nothing drives (no connection, no input-CSV column) is forced by setting it in the
    FMU directly and released by setting its start value again; a forced value is checked against the
    modelDescription's type and min/max (a list of allowed values is not in a modelDescription: the FMU refuses
    such a value at its next step, a SimulationError).
    """

    def __init__(self, master: Master, run: _Run, sinks: list[RecordSink], keep: bool,
                 args: tuple[float | None, float | None, Mapping[str, object] | None, InputTable | None, float,
                             Sequence[str] | None, int]) -> None:
        self.master, self.run, self.sinks, self.keep = master, run, sinks, keep
        self._args = args
        self.writes: list[tuple[float, str, object]] = []
        self.wall_time = 0.0
        self.closed = False
        self.failed: BaseException | None = None
        self._open_sinks()

    # -- the recording --------------------------------------------------------------------------
    def _open_sinks(self) -> None:
        run = self.run
        run.flush = self._flush
        columns: list[tuple[str, np.dtype]] = [("time", np.dtype(np.float64))]
        columns += [(name, COLUMN_DTYPES[kind]) for name, kind, _ in run.columns]
        for sink in self.sinks:
            sink.open(columns)

    def _flush(self) -> None:
        """Hand the window's finished rows to the sinks and start the window after them."""
        run = self.run
        count = run.rows_done
        if count > 0 and self.sinks:
            rows = run.rows(count)
            for sink in self.sinks:
                sink.write(rows)
        run.row_base += count

    @property
    def time(self) -> float:
        return self.run.time_of(self.run.step)

    @property
    def step_size(self) -> float:
        return self.run.h

    @property
    def stop_time(self) -> float:
        return self.run.stop_time

    def forced(self) -> dict[str, object]:
        """What is forced now: name -> value."""
        return dict(self.run.forced)

    # -- stepping -------------------------------------------------------------------------------
    def _usable(self) -> None:
        if self.closed:
            raise SimulationError("the session is closed")
        if self.failed is not None:
            raise SimulationError(f"the session failed: {self.failed}")

    def advance(self, n: int = 1) -> None:
        """Run ``n`` communication steps and feed the sinks; an FMU error raises :class:`SimulationError` and
        leaves the session failed (close it)."""
        self._advance(n)

    def _advance(self, n: int, progress=None, deadline: float | None = None) -> None:
        self._usable()
        n = int(n)
        if n < 0:
            raise SystemDefinitionError(f"advance({n}): the number of steps must be >= 0")
        run = self.run
        if run.n_steps is not None and run.step + n > run.n_steps:
            raise SystemDefinitionError(f"advance({n}): {run.n_steps - run.step} steps are left before the stop "
                                        f"time {run.stop_time:g} s")
        try:
            self.wall_time += self.master._loop(run, run.step, run.step + n, progress, deadline)
        except BaseException as err:
            self.failed = err
            raise

    # -- reading --------------------------------------------------------------------------------
    def value(self, name: str) -> object:
        """The present value of ``INSTANCE.VARIABLE``: an output as last read, an input as last given to the
        FMU, a parameter as applied."""
        slave, v = self.master.variable(name)
        run = self.run
        if v.causality == "output" and v.type in KINDS:
            kind = v.type
            j = run.record_names[kind].index(name)
            return _as_python(kind, run.values[kind][j])
        if v.causality == "input" and v.type in KINDS:
            b = run.bound.get(name)
            if b is not None:
                return _as_python(v.type, b.in_buf[b.pos])
            if name in run.unbound:
                return run.unbound[name]
            start = run.start_values[slave.name].get(v.name, v.start)
            return None if start is None else _as_python(v.type, start)
        if v.causality == "parameter":
            return run.start_values[slave.name].get(v.name, v.start)
        if not isinstance(slave, ReadableSlave):
            raise SystemDefinitionError(f"{name} is a {v.causality}: this slave cannot be read outside its outputs")
        return slave.get(v.name)

    def outputs(self) -> dict[str, object]:
        """Every output's present value."""
        run = self.run
        return {name: _as_python(kind, run.values[kind][j])
                for kind in KINDS for j, name in enumerate(run.record_names[kind])}

    # -- writing --------------------------------------------------------------------------------
    def force(self, name: str, value: object) -> None:
        """``name`` (an input, also one a connection or the input CSV drives) takes ``value`` from the next step
        on, until released. A value of the wrong type or outside the port's range is :class:`ConfigError`."""
        self._usable()
        slave, v = self.master.variable(name)
        if v.causality != "input" or v.type not in KINDS:
            raise ConfigError(name, value, f"not an input (a {v.causality}): only inputs can be forced")
        typed = typed_value(name, v.type, value)
        _check_range(name, v, typed)
        try:
            self.master._apply(self.run, "force", name, typed)
        except SimulationError as err:
            raise ConfigError(name, value, f"refused by {slave.name}: {err}") from None
        self.writes.append((self.time, name, typed))

    def release(self, name: str) -> None:
        """The connection (or the input CSV, or the start value) drives ``name`` again from the next step."""
        self._usable()
        self.master.variable(name)
        if name not in self.run.forced:
            return
        self.master._apply(self.run, "release", name, None)
        self.writes.append((self.time, name, None))

    def set_parameter(self, name: str, value: object) -> None:
        """Set a tunable parameter before the next step. A fixed parameter or any other variable, a value of
        the wrong type or outside its range, or the FMU's refusal is :class:`ConfigError`; the old value stays."""
        self._usable()
        slave, v = self.master.variable(name)
        if v.causality != "parameter" or v.variability != "tunable":
            kind = _described(v)
            raise ConfigError(name, value, f"not writable during a run ({kind}; only tunable parameters are)")
        typed = typed_value(name, v.type, value)
        if v.type in ("Real", "Integer"):
            _check_range(name, v, typed)
        try:
            self.master._apply(self.run, "param", name, typed)
        except SimulationError as err:
            raise ConfigError(name, value, f"refused by {slave.name}: {err}") from None
        self.writes.append((self.time, name, typed))

    # -- reset and close ------------------------------------------------------------------------
    def _close_sinks(self, complete: bool, reason: str) -> None:
        run = self.run
        if not self.keep:
            self._flush()
        elif self.sinks:
            rows = run.rows(run.rows_done)
            for sink in self.sinks:
                sink.write(rows)
        last_row = (run.step // run.every) * run.every
        stopped_at = run.time_of(last_row)
        for sink in self.sinks:
            sink.close(complete, stopped_at, reason)

    def reset(self, sinks: Sequence[RecordSink] = ()) -> None:
        """Back to the start: every slave reset (fmi2Reset), start values applied again, initialised again,
        nothing forced, :attr:`writes` emptied, time = start time. The present sinks are closed first (a
        completed segment, reason ``reset``); the rows from here on go to ``sinks``."""
        if self.closed:
            raise SimulationError("the session is closed")
        self._close_sinks(True, f"reset at t = {self.time:g} s")
        for s in self.master.slaves:
            if not isinstance(s, ResettableSlave):
                raise SimulationError(f"{s.name} cannot be reset")
            s.reset()
        self.sinks = list(sinks)
        self.failed = None
        self.writes = []
        self.wall_time = 0.0
        stop, step, start_values, inputs, start_time, record, every = self._args
        self.run = self.master._prepare(stop, step, start_values, inputs, start_time, record, every, self.keep)
        self._open_sinks()

    def close(self, complete: bool = True, stopped_at: float | None = None, reason: str = "") -> Result:
        """Write the last rows, close the sinks and return the Result: the rows when the session kept them,
        else none (its span, messages and parameters only). ``stopped_at`` is taken from the last row."""
        if self.closed:
            raise SimulationError("the session is closed already")
        if self.failed is not None and complete:
            complete, reason = False, reason or str(self.failed)
        self.closed = True
        self._close_sinks(complete, reason)
        run = self.run
        messages = {s.name: list(s.messages) for s in self.master.slaves}
        models = {c.name: c.model for c in self.master.system.components}
        span = (run.start_time, self.time)
        if self.keep:
            data = run.rows(run.rows_done)
        else:
            data = run.rows(0)
        return Result(data, self.master.system.name, self.wall_time, messages,
                      parameters={inst: dict(values) for inst, values in run.start_values.items()},
                      models=models, span=span)
