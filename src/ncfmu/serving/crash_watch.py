"""A served run's part check in a thread of its own (``ncfmu-part-check``): :class:`CrashWatch` is handed the
rows every :data:`CRASH_CHECK` s of simulated time and tells the crashes and the verdicts it found."""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable, Sequence

import numpy as np

#: How often (simulated s) a served run's part check is handed the rows so far: how late a crash is seen at most.
CRASH_CHECK = 0.05


def program_ends(report) -> list[tuple[str, bool]]:
    """Where a part check's program ends, as (column, True: its rising edge, False: its falling edge): a lathe's
    or mill's part check is judged when its cycle says done, a grinder's after each cycle (RUN falls)."""
    from ..systems.part import GrindPart, MachinedPart
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
        #: told each judged accumulator in the check's thread, which owns it (the web page's part section)
        self.on_judged: Callable[[object], None] | None = None
        self.accumulator = self.new_accumulator()

    def sinks(self, recording: Sequence) -> list:
        """A segment's sinks: the recording's (kept to ``--record``) and a new part check."""
        from ..cosim.record import SelectColumns
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
        from ..systems.part import crashes_so_far, verdict_of
        accumulator.write(rows)
        if accumulator is self.accumulator:
            if self.on_judged is not None:
                self.on_judged(accumulator)
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
