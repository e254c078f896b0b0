"""A run stepped from outside (:class:`Session`): advance, read, force inputs, set tunable parameters, reset, close;
its recorded rows streamed into sinks (:mod:`.record`, the observers). Opened by
:meth:`~ncfmu.cosim.master.Master.open_session` over one :class:`~ncfmu.cosim.execution.Execution`."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from ..errors import ConfigError, SimulationError, SystemDefinitionError
from .execution import COLUMN_DTYPES, Execution, Owner, as_python, described
from .fmu import check_range, typed_value
from .record import RecordSink
from .result import Result
from .slave import KINDS, ReadableSlave, ResettableSlave

__all__ = ["Session"]


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

    def __init__(self, master: Owner, run: Execution, sinks: list[RecordSink], keep: bool,
                 prepare_again: Callable[[], Execution]) -> None:
        self.master, self.run, self.sinks, self.keep = master, run, sinks, keep
        self._prepare_again = prepare_again
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

    def flush(self) -> None:
        """Hand the rows recorded so far to the sinks now, not when the record window fills (a live server's part
        check reads them as they come); a session that keeps its rows hands them over when it closes."""
        self._usable()
        if not self.keep:
            self._flush()

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

    def run_to_stop(self, progress: Callable[[float], None] | None = None, deadline: float | None = None,
                    until: Callable[[], str] | None = None, check_every: int = 0,
                    watch: Sequence[str] = ()) -> str:
        """Run to the stop time; ``progress(fraction)`` is called as it goes, and past ``deadline`` (a
        ``time.perf_counter()`` value) the run stops with :class:`~ncfmu.errors.SimulationTimeout`.

        ``until`` (a session that keeps no rows): asked after the sinks got every row so far -- whenever the record
        window is full, and when one of the ``watch`` outputs (``INSTANCE.VARIABLE``) changed, looked at every
        ``check_every`` steps; its first non-empty answer ends the run there, and is returned ("": the run reached
        the stop time)."""
        if self.run.n_steps is None:
            raise SystemDefinitionError("run_to_stop(): this session has no stop time (advance it instead)")
        if until is not None and (self.keep or check_every < 1):
            raise SystemDefinitionError("run_to_stop(until=...): needs a session that keeps no rows (its sinks read "
                                        f"them) and check_every >= 1 step, got keep={self.keep}, "
                                        f"check_every={check_every}")
        slots = []
        for name in watch:
            kind = next((k for k in KINDS if name in self.run.record_names[k]), None)
            if kind is None:
                raise SystemDefinitionError(f"run_to_stop(watch=...): {name!r} is not an output of "
                                            f"{self.master.system.name}")
            slots.append((kind, self.run.record_names[kind].index(name)))
        self._advance(self.run.n_steps - self.run.step, progress, deadline, until, check_every, slots)
        return self.run.ended

    def _advance(self, n: int, progress: Callable[[float], None] | None = None,
                 deadline: float | None = None, until: Callable[[], str] | None = None,
                 check_every: int = 0, watch: Sequence[tuple[str, int]] = ()) -> None:
        self._usable()
        n = int(n)
        if n < 0:
            raise SystemDefinitionError(f"advance({n}): the number of steps must be >= 0")
        run = self.run
        if run.n_steps is not None and run.step + n > run.n_steps:
            raise SystemDefinitionError(f"advance({n}): {run.n_steps - run.step} steps are left before the stop "
                                        f"time {run.stop_time:g} s")
        try:
            self.wall_time += run.steps(run.step, run.step + n, progress, deadline, until, check_every, watch)
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
            return as_python(kind, run.values[kind][j])
        if v.causality == "input" and v.type in KINDS:
            b = run.bound.get(name)
            if b is not None:
                return as_python(v.type, b.in_buf[b.pos])
            if name in run.unbound:
                return run.unbound[name]
            start = run.start_values[slave.name].get(v.name, v.start)
            return None if start is None else as_python(v.type, start)
        if v.causality == "parameter":
            return run.start_values[slave.name].get(v.name, v.start)
        if not isinstance(slave, ReadableSlave):
            raise SystemDefinitionError(f"{name} is a {v.causality}: this slave cannot be read outside its outputs")
        return slave.get(v.name)

    def outputs(self) -> dict[str, object]:
        """Every output's present value."""
        run = self.run
        return {name: as_python(kind, run.values[kind][j])
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
        check_range(name, v, typed)
        try:
            self.run.apply("force", name, typed)
        except SimulationError as err:
            raise ConfigError(name, value, f"refused by {slave.name}: {err}") from None
        self.writes.append((self.time, name, typed))

    def release(self, name: str) -> None:
        """The connection (or the input CSV, or the start value) drives ``name`` again from the next step."""
        self._usable()
        self.master.variable(name)
        if name not in self.run.forced:
            return
        self.run.apply("release", name, None)
        self.writes.append((self.time, name, None))

    def set_parameter(self, name: str, value: object) -> None:
        """Set a tunable parameter before the next step. A fixed parameter or any other variable, a value of
        the wrong type or outside its range, or the FMU's refusal is :class:`ConfigError`; the old value stays."""
        self._usable()
        slave, v = self.master.variable(name)
        if v.causality != "parameter" or v.variability != "tunable":
            kind = described(v)
            raise ConfigError(name, value, f"not writable during a run ({kind}; only tunable parameters are)")
        typed = typed_value(name, v.type, value)
        if v.type in ("Real", "Integer"):
            check_range(name, v, typed)
        try:
            self.run.apply("param", name, typed)
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
        self.run = self._prepare_again()
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
