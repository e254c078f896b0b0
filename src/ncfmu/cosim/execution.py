"""One prepared run of a master's slaves (libcosim's ``execution``): its value vectors, step plan, record window
and input schedule, made once by :meth:`~ncfmu.cosim.master.Master.prepare`, and the loop that steps it.

The loop runs the steps in chunks that end where Python must act before the next step; each chunk runs in C
(``loop.c``) when every slave allows it, else in Python; both follow the schedule of the master's
:mod:`algorithm <.algorithm>`, so both make the same calls. Writes between steps (an input CSV's cells, a
session's force, release and parameter) go through :meth:`Execution.apply`.
"""

from __future__ import annotations

import time as _time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from ..errors import SimulationError, SimulationTimeout, TerminationRequested
from .algorithm import Algorithm
from .interrupts import raise_pending
from .native_loop import NativePlan
from .slave import KINDS, Slave, Variable
from .ssp import System
from .units import Conversion

__all__ = ["COLUMN_DTYPES", "NATIVE_CHUNK", "Execution", "Owner"]

#: Steps run before the loop hands back to Python (10 s simulated at 1 ms; ~0.3 s of lathe_taper in C).
NATIVE_CHUNK = 10_000

#: How near an FMU's last successful time must be to a step's end for the step to count as whole, s (the FMI
#: layer's rule for a step that continues from the last one's end).
STEP_END_SLACK = 0.5e-9

#: The dtype of a recorded column of each kind (Booleans as bool, as fmpy's results)
COLUMN_DTYPES: dict[str, np.dtype] = {"Real": np.dtype(np.float64), "Integer": np.dtype(np.int32),
                                     "Boolean": np.dtype(np.bool_)}


@dataclass
class BoundInput:
    """An input in the gather plan: read from ``source`` (a connection's output, or an input-CSV slot), or
    from ``force_slot`` while forced."""

    kind: str
    idx: np.ndarray          # the gather indices of its slave and kind (shared with the C loop)
    pos: int
    in_buf: np.ndarray
    source: int
    force_slot: int


class Owner(Protocol):
    """The master an execution belongs to (:class:`~ncfmu.cosim.master.Master`), as the execution and its session
    use it: the layer below the master names what it asks of it, and never imports it."""

    #: which loop the last run stepped in: "c" or "python"
    loop_used: str

    @property
    def system(self) -> System: ...

    @property
    def slaves(self) -> Sequence[Slave]: ...

    @property
    def conversions(self) -> Mapping[tuple[str, str], Conversion]: ...

    def variable(self, qualified: str) -> tuple[Slave, Variable]: ...


@dataclass
class Execution:
    """Everything one run needs inside the loop, prepared once (:meth:`~ncfmu.cosim.master.Master.prepare`)."""

    master: Owner
    algorithm: Algorithm
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
    bound: dict               # INSTANCE.VARIABLE -> BoundInput
    ext: dict                 # INSTANCE.VARIABLE -> (kind, slot): inputs no connection drives, set by the CSV
    schedule: list            # (first step, [actions]) of the input CSV, in time order
    native: NativePlan | None = None
    row_base: int = 0
    step: int = 0             # steps done
    next_change: int = 0
    forced: dict = field(default_factory=dict)
    unbound: dict = field(default_factory=dict)   # inputs outside the plan: the value last set
    flush: Callable[[], None] | None = None
    ended: str = ""           # why the run ended before its stop time (a check's answer), "" while it runs

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

    # -- writes between steps -------------------------------------------------------------------
    def apply(self, action: str, name: str, value) -> None:
        """One write between steps: a CSV row's cell or a session's force/release/parameter."""
        slave, v = self.master.variable(name)
        if action == "ext":
            kind, slot = self.ext[name]
            self.values[kind][slot] = value
        elif action == "force":
            b = self.bound.get(name)
            if b is None:
                slave.set_start(v.name, value)          # an input outside the plan keeps what it is set to
                self.unbound[name] = value
            else:
                conv = self.master.conversions.get((slave.name, v.name))
                # the slot is gathered like the connection's source: in the source's unit
                self.values[b.kind][b.force_slot] = value if conv is None else (value - conv.offset) / conv.gain
                b.idx[b.pos] = b.force_slot
            self.forced[name] = value
        elif action == "ext_release":
            kind, slot = self.ext[name]
            start = self.start_values[slave.name].get(v.name, v.start)
            self.values[kind][slot] = 0 if start is None else start
        elif action == "release":
            self.forced.pop(name, None)
            b = self.bound.get(name)
            start = self.start_values[slave.name].get(v.name, v.start)
            if b is not None:
                b.idx[b.pos] = b.source
            elif start is not None:
                slave.set_start(v.name, start)
                self.unbound[name] = start
        else:                                           # a tunable parameter
            slave.set_start(v.name, value)
            self.start_values[slave.name][v.name] = value

    # -- the loop -------------------------------------------------------------------------------
    def steps(self, first: int, last: int, progress: Callable[[float], None] | None = None,
              deadline: float | None = None, until: Callable[[], str] | None = None, check_every: int = 0,
              watch: Sequence[tuple[str, int]] = ()) -> float:
        """Steps ``first`` .. ``last - 1``; returns the wall time.

        The steps run in chunks that end where Python must act before the next step (an input change, a
        progress report, a deadline check every 64 steps, a full record window, a check of ``until`` every
        ``check_every`` steps, and every ``NATIVE_CHUNK`` steps so that Ctrl-C is seen); each chunk runs in C when
        every slave allows it, else in Python. Both make the same calls.

        ``until``: asked whenever the record window was handed to the sinks because it was full, and -- every
        ``check_every`` steps -- when one of the ``watch`` outputs (``(kind, index)`` in the value vectors: a done
        signal, an alarm) changed since the last look: then the window is handed over first, so ``until`` reads
        every row so far. A non-empty answer ends the run there (:attr:`ended` says why). Looked at between chunks,
        never inside the loop, and the window handed over early only when a watched output changed: the steps cost
        what they cost without it (a window handed over every ``check_every`` steps cost the lathe 10 %).
        """
        schedule, every = self.schedule, self.every
        report_every = max(1, (self.n_steps or 1) // 100)
        self.master.loop_used = "python" if self.native is None else "c"
        advance: Callable[[int, int, int], None]
        if self.native is not None:
            self.native.forget_sent()     # start values, a restored state or a direct set may have changed inputs
            advance = self.native.run
        else:
            advance = self._python_steps()
        wall0 = _time.perf_counter()
        watched = [(self.values[kind], j) for kind, j in watch]
        seen = [vector[j] for vector, j in watched]
        i = first
        try:
            while i < last:
                while self.next_change < len(schedule) and schedule[self.next_change][0] <= i:
                    for action, name, value in schedule[self.next_change][1]:
                        self.apply(action, name, value)
                    self.next_change += 1
                if i // every + 1 - self.row_base >= self.capacity:
                    assert self.flush is not None, "the record window is full and nothing takes its rows"
                    self.flush()
                    if until is not None and i > first:
                        self.ended = until()
                        if self.ended:
                            break
                end = min(last, i + NATIVE_CHUNK, (self.row_base + self.capacity) * every - 1)
                if self.next_change < len(schedule):
                    end = min(end, schedule[self.next_change][0])
                if progress is not None:
                    end = min(end, (i + report_every) // report_every * report_every)   # the next row to report
                if deadline is not None:
                    end = min(end, (i + 64) // 64 * 64)
                if until is not None:
                    end = min(end, (i + check_every) // check_every * check_every)
                advance(i, end, self.row_base)
                i = self.step = end
                raise_pending()
                if progress is not None and end % report_every == 0 and self.n_steps:
                    progress(end / self.n_steps)
                if deadline is not None and end % 64 == 0 and _time.perf_counter() > deadline:
                    stop = f" of {self.time_of(self.n_steps):.3f} s" if self.n_steps is not None else ""
                    raise SimulationTimeout(f"stopped at t = {self.time_of(end):.3f} s{stop}: over the time allowed "
                                            f"({_time.perf_counter() - wall0:.1f} s of wall time)")
                if until is not None and end % check_every == 0 and end < last:
                    now = [vector[j] for vector, j in watched]
                    if now != seen:
                        seen = now
                        assert self.flush is not None, "a check of the rows needs the rows handed to the sinks"
                        self.flush()
                        self.ended = until()
                        if self.ended:
                            break
        except SimulationError as err:
            failed = getattr(self.native, "failed_step", None)
            if failed is not None and i <= failed:
                self.step = failed          # the C loop says how far it got: those rows are whole
            if isinstance(err, TerminationRequested):
                raise self._end_where_asked(err) from None
            raise
        return _time.perf_counter() - wall0

    def _end_where_asked(self, ended: TerminationRequested) -> TerminationRequested:
        """Where the run ends when an FMU asks in step ``self.step``: at the step's start, or -- when the FMU made
        the step whole before it asked (its last successful time is the step's end, as the Reference-FMUs' Stair
        and fmpy's and fmusim's record of it have it) -- at its end, the step done for the FMUs after it and
        recorded."""
        i = self.step
        end = self.time_of(i + 1)
        if ended.last_time is None or not abs(ended.last_time - end) <= STEP_END_SLACK:
            return ended.at(self.time_of(i))
        self._finish_step(i, ended.instance)
        return ended.at(end)

    def _finish_step(self, i: int, asked: str) -> None:
        """The rest of step ``i`` after the slave ``asked`` made it whole and asked to end, by the master's
        algorithm (the same calls its loops make), then its row."""
        t, h, plan = self.time_of(i), self.h, self.plan
        if self.native is not None:             # the C loop set the inputs: Python sends every one again
            for s, _gathers in plan:
                s.forget_sent_inputs()
        k = next(n for n, (s, _gathers) in enumerate(plan) if s.name == asked)
        self.algorithm.rest_of_step(plan, k)(t, h)
        done = i + 1
        if done % self.every == 0:
            if done // self.every - self.row_base >= self.capacity:
                assert self.flush is not None, "the record window is full and nothing takes its rows"
                self.flush()
            row = done // self.every - self.row_base
            for kind in KINDS:
                if self.n_rec[kind]:
                    self.rec[kind][row] = self.values[kind][:self.n_rec[kind]]
        self.step = done

    def _python_steps(self) -> Callable[[int, int, int], None]:
        """The Python loop: ``advance(first, end, row_base)`` steps ``first`` .. ``end - 1`` and records the rows."""
        rec, n_rec, h, start, every = self.rec, self.n_rec, self.h, self.start_time, self.every
        # the rows to record and the slices of the output vectors they copy, prepared once
        record = [(rec[k], self.values[k][:n_rec[k]]) for k in KINDS if n_rec[k]]
        step = self.algorithm.stepper(self.plan)

        def advance(first: int, end: int, row_base: int) -> None:
            for i in range(first, end):
                step(start + h * i, h)
                done = i + 1
                if done % every == 0:
                    row = done // every - row_base
                    for table, vector in record:
                        table[row] = vector
                self.step = done
        return advance


# -- what the master and a session say of variables -------------------------------------------------
def article(causality: str) -> str:
    """``an output``, ``a parameter``: a causality with its article, for messages."""
    return f"{'an' if causality[:1] in 'aeiou' else 'a'} {causality}"


def described(v: Variable) -> str:
    """``a fixed parameter``, ``an output``: what a variable is, with its article, for messages."""
    return f"a {v.variability} parameter" if v.causality == "parameter" and v.variability else article(v.causality)


def as_python(kind: str, value) -> object:
    if kind == "Real":
        return float(value)
    if kind == "Boolean":
        return bool(value)
    return int(value)
