"""The co-simulation master: the execution of a system's slaves at a fixed communication step.

Split as libcosim splits it: the **algorithm** (:mod:`.algorithm`: Gauss-Seidel, the default, or Jacobi) says in
which order a step calls the slaves; the **execution** (:class:`Execution`, made by :meth:`Master.prepare`) is one
prepared run -- its value vectors, its step plan, its record window, its input schedule -- and its loop; the
**observers** are the recording sinks (:mod:`.record`) a :class:`~ncfmu.cosim.session.Session` feeds. Inputs over
time come from :mod:`.inputs`, Ctrl-C and SIGTERM from :mod:`.interrupts`.

All outputs of one kind of all components live in one numpy vector; each slave reads its outputs
straight into its slice and its inputs are gathered with one ``numpy.take`` per kind. Nothing is
allocated inside the loop. The master depends only on the :class:`~ncfmu.cosim.slave.Slave`
interface, so it is tested with a fake slave.

When every slave also offers its raw FMI functions (:class:`~ncfmu.cosim.native_loop.NativeSlave`: the
FMUs), the steps run in C (``loop.c``), call for call the same; Python acts only between chunks of
steps: at input changes, progress reports, deadline checks and when the record window is full.

A run is a :class:`~ncfmu.cosim.session.Session` (:meth:`Master.open_session`): advanced step by step, inputs
forced and released, tunable parameters set, its recorded rows streamed into sinks. Each forced input reads from a
slot of its own in the value vector instead of its source (the gather index changes; nothing runs per step).
:meth:`Master.run` is one session from start to stop. The rows go through a bounded record window: the whole run
when it is kept in memory, a chunk of rows otherwise (written to the sinks whenever it is full), so a run that
keeps nothing holds nothing that grows with the simulated time.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence

import numpy as np

from ..errors import SystemDefinitionError, TerminationRequested
from .algorithm import MODES, Algorithm, algorithm
from .connect import check_units
from .execution import COLUMN_DTYPES, BoundInput, Execution, article, described
from .fmu import check_range, typed_value
from .inputs import EMPTY, RELEASE, TIME_SLACK, InputTable, write_input_csv
from .interrupts import Interrupted, deferred_interrupts
from .native_loop import NativePlan, NativeSlave, library
from .record import MAX_RECORD_BYTES, RecordSink, too_big
from .result import Result
from .session import Session
from .slave import DTYPES, KINDS, Slave, StatefulSlave, Variable
from .ssp import System

__all__ = ["MAX_RECORD_BYTES", "MODES", "Execution", "InputTable", "Interrupted", "Master", "Session",
           "deferred_interrupts", "steps_per_row", "write_input_csv"]

#: The record window of a run that keeps nothing in memory: about this many bytes of rows.
WINDOW_BYTES = 2 ** 20

#: How often (s of simulated time) a run looks at its watched outputs (``Master.run``'s ``watch``: a done signal, an
#: alarm) to ask whether it should end: it stops at most this long after one changed (looked at between chunks of
#: steps, not in them).
CHECK_INTERVAL = 0.5

#: Steps a run counts at most (whole numbers in a double): a stop time beyond is a mistake, not a run.
MAX_STEPS = 2.0 ** 53


def steps_per_row(output_interval: float | None, h: float) -> int:
    """Steps between recorded rows for an output interval (None: every step); it must be a whole multiple of ``h``."""
    if output_interval is None:
        return 1
    ratio = float(output_interval) / h
    if not (math.isfinite(ratio) and ratio >= 1 - 1e-9 and abs(ratio - round(ratio)) <= 1e-9 * ratio):
        raise SystemDefinitionError(f"output interval {output_interval!r} s: must be a whole multiple of the "
                                    f"step {h:g} s")
    return int(round(ratio))



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


class Master:
    """Run a :class:`~ncfmu.cosim.ssp.System` whose components are given as slaves.

    Parameters
    ----------
    system : System
    slaves : sequence of Slave
        One per component, in the system's order, already instantiated.
    mode : {"gauss-seidel", "jacobi"} or Algorithm
        The stepping algorithm (:mod:`.algorithm`).
    native : bool
        Run the steps in C when every slave allows it (False: always the Python loop).
    """

    def __init__(self, system: System, slaves: Sequence[Slave], mode: str | Algorithm = "gauss-seidel",
                 native: bool = True) -> None:
        self.algorithm = algorithm(mode)
        self.mode = self.algorithm.name
        self.system, self.slaves, self.native = system, slaves, native
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
                                            f"{article(src.causality)}, not an output")
            if dst.causality != "input":
                raise SystemDefinitionError(f"connection {c}: {c.end_element}.{c.end_connector} is "
                                            f"{article(dst.causality)}, not an input")
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
            output_interval: float | None = None, sinks: Sequence[RecordSink] = (), keep: bool = True,
            until: Callable[[], str] | None = None, check_interval: float | None = None,
            watch: Sequence[str] = ()) -> Result:
        """Initialise every slave, step to ``stop_time`` and return the recorded outputs.

        ``record`` names the outputs recorded (default: every output), ``output_interval`` records every so
        many seconds (a whole multiple of the step: the start row and every k-th row). The rows go to every
        sink in ``sinks`` as the run goes; with ``keep`` False nothing is held in memory and the returned
        Result has no rows (only its span, messages and parameters). An interrupted run (an exception,
        Ctrl-C) closes the sinks as incomplete with every row of the finished chunks, then raises.
        ``deadline`` (a ``time.perf_counter()`` value): past it the run stops with :class:`SimulationTimeout`.
        ``until`` (with ``keep`` False): asked once the sinks have every row so far -- e.g. "is the work done?" --
        whenever the record window is full, and when one of the ``watch`` outputs (a done signal, an alarm) changed,
        looked at every ``check_interval`` s of simulated time (default ``CHECK_INTERVAL``); its first non-empty
        answer ends the run there, a complete run (``Result.ended_by`` says why).
        """
        if stop_time is not None and not math.isfinite(float(stop_time)):
            raise SystemDefinitionError(f"stop time = {stop_time!r}: a run needs a finite stop time "
                                        "(a session may run until closed)")
        session = self.open_session(stop_time, step_size, start_values, inputs, start_time, record,
                                    output_interval, sinks, keep=keep)
        try:
            every = 0
            if until is not None:
                every = max(1, int(round((CHECK_INTERVAL if check_interval is None else check_interval)
                                         / session.step_size)))
            work_ended = session.run_to_stop(progress, deadline, until, every, watch)
        except TerminationRequested as ended:
            # an FMU asked to end (fmi2Discard + terminateSimulation): the run ends cleanly at the last whole step
            # (the execution has made the step whole where the FMU had: Execution._end_where_asked)
            session.failed = None
            result = session.close(reason=str(ended))
            result.ended_by = str(ended)
            return result
        except BaseException as err:
            session.close(complete=False, reason=str(err) or type(err).__name__)
            raise
        if work_ended:
            result = session.close(reason=work_ended)
            result.ended_by = work_ended
            return result
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
        every = steps_per_row(output_interval, self.system.step_size if step_size is None else float(step_size))
        args = (stop_time, step_size, start_values, inputs, start_time, record, every, keep)
        return Session(self, self.prepare(*args), list(sinks), keep, lambda: self.prepare(*args))

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
        run = self.prepare(stop_time, step_size, start_values, inputs, start_time)
        assert run.n_steps is not None
        steps = (branch_time - start_time) / run.h      # nan or beyond the run (1e308 s) is refused, not rounded
        k = int(round(steps)) if 0 < steps < run.n_steps else 0
        if not 0 < k < run.n_steps:
            raise SystemDefinitionError(f"branch time {branch_time} s must lie inside the run "
                                        f"({start_time}..{start_time + run.n_steps * run.h} s)")
        wall = run.steps(0, k)
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
                run_wall = wall + run.steps(k, run.n_steps)
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

    # -- preparing an execution -----------------------------------------------------------------
    def prepare(self, stop_time: float | None = None, step_size: float | None = None,
                start_values: Mapping[str, object] | None = None, inputs: InputTable | None = None,
                start_time: float = 0.0, record: Sequence[str] | None = None, every: int = 1,
                keep: bool = True) -> Execution:
        """Initialise every slave and prepare one run of them: the checks of the span and of what is recorded,
        the start values, the input CSV's roles, the value vectors and the step plan, the record window, the
        input schedule and (when every slave allows it) the C loop's plan. Nothing has stepped yet."""
        h, stop, n_steps = self._span(stop_time, step_size, start_time, keep)
        by_kind, columns = self._recorded(record)
        capacity = self._window(by_kind, columns, h, stop, n_steps, every, keep)
        applied = self._start_values(start_values)
        ext, csv_forced = self._input_roles(inputs)
        for s in self.slaves:
            s.initialize(start_time, stop)
        values, slots, force_slot = self._vectors(ext)
        ext_slots = {q: (kind, slots[kind][q]) for q, kind in ext.items()}
        for q, (kind, slot) in ext_slots.items():
            # until its first row, an input the CSV drives keeps its start value
            slave, v = self.variable(q)
            start = applied[slave.name].get(v.name, v.start)
            values[kind][slot] = 0 if start is None else start
        plan, bindings, bound = self._bind(values, slots, ext, force_slot)

        n_rec = {k: len(by_kind[k]) for k in KINDS}
        rec = {k: np.empty((capacity, n_rec[k]), dtype=DTYPES[k]) for k in KINDS}
        for s in self.slaves:
            s.read_outputs()
        for k in KINDS:
            rec[k][0] = values[k][:n_rec[k]]
        run = Execution(self, self.algorithm, h, float(start_time), stop, n_steps, values, plan, by_kind, n_rec, rec,
                        every, capacity, columns, applied, bound, ext_slots, [])
        if inputs is not None:
            run.schedule = self._schedule(run, inputs, csv_forced)
        for _s, prepared in plan:
            for buf, take, idx in prepared:
                take(idx, out=buf)             # what each input is given at the first step (Session.value)
        natives = [s for s in self.slaves if isinstance(s, NativeSlave)]
        if self.native and len(natives) == len(self.slaves) and library() is not None and not self.conversions:
            records = [(rec[k], values[k][:n_rec[k]]) for k in KINDS if n_rec[k]]
            run.native = NativePlan(natives, bindings, values, records, run.start_time, h,
                                    self.algorithm.schedule(len(natives)), every)
        return run

    def _span(self, stop_time: float | None, step_size: float | None, start_time: float,
              keep: bool) -> tuple[float, float, int | None]:
        """The step, the stop time and the number of steps (None: no stop time), each checked."""
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
        return h, stop, n_steps

    def _recorded(self, record: Sequence[str] | None) -> tuple[dict[str, list[str]], list[tuple[str, str, int]]]:
        """Every output by kind (vector order), and the recorded columns: every output, or the ones named (in the
        order named) as ``(name, kind, index)``."""
        by_kind = {kind: [f"{s.name}.{v.name}" for s in self.slaves for v in s.variables.values()
                          if v.causality == "output" and v.type == kind] for kind in KINDS}
        position = {name: (kind, j) for kind in KINDS for j, name in enumerate(by_kind[kind])}
        names = [n for kind in KINDS for n in by_kind[kind]] if record is None else list(dict.fromkeys(record))
        for name in names:
            if name not in position:
                raise SystemDefinitionError(f"record {name!r}: not an output of {self.system.name} "
                                            "(outputs are INSTANCE.VARIABLE, e.g. x_axis.pos)")
        return by_kind, [(name, *position[name]) for name in names]

    @staticmethod
    def _window(by_kind: dict[str, list[str]], columns: list[tuple[str, str, int]], h: float, stop: float,
                n_steps: int | None, every: int, keep: bool) -> int:
        """Rows in the record window: the whole run when it is kept (refused when too big), else about
        ``WINDOW_BYTES``."""
        window_row = sum(len(by_kind[k]) * np.dtype(DTYPES[k]).itemsize for k in KINDS)
        if keep:
            assert n_steps is not None
            capacity = n_steps // every + 1
            kept_row = 8 + sum(COLUMN_DTYPES[kind].itemsize for _, kind, _ in columns)
            refusal = too_big(capacity, window_row + kept_row,
                              f"stop time {stop:g} s at a step of {h:g} s ({n_steps} steps, {capacity} rows)")
            if refusal is not None:
                raise refusal
            return capacity
        capacity = max(1, WINDOW_BYTES // max(window_row, 1))
        if n_steps is not None:
            capacity = min(capacity, n_steps // every + 1)
        return capacity

    def _start_values(self, start_values: Mapping[str, object] | None) -> dict[str, dict[str, object]]:
        """Set the system's parameter sets, then the caller's overrides; returns what was applied."""
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
        return applied

    def _input_roles(self, inputs: InputTable | None) -> tuple[dict[str, str], set[str]]:
        """The input CSV's columns: inputs no connection drives get a slot of their own (set from the CSV; returned
        with their kind), inputs a connection drives are forced (returned as a set), tunable parameters are set."""
        ext: dict[str, str] = {}
        csv_forced: set[str] = set()
        if inputs is None:
            return ext, csv_forced
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
                what = described(v)
                raise SystemDefinitionError(f"input CSV column {qualified!r} is {what}: only inputs and tunable "
                                            "parameters change during a run")
        return ext, csv_forced

    def _driven(self, s: Slave, v: Variable, ext: Mapping[str, str]) -> bool:
        """An input in the step plan: a connection or the input CSV drives it."""
        return (s.name, v.name) in self.sources or f"{s.name}.{v.name}" in ext

    def _vectors(self, ext: Mapping[str, str]) -> tuple[dict, dict, dict[str, int]]:
        """The global vectors: every output, then the CSV's inputs, then one force slot per input in the plan."""
        values, slots = {}, {}
        bound_inputs: dict[str, list[tuple[Slave, Variable]]] = {}
        for kind in KINDS:
            slots[kind] = _output_slots(self.slaves, kind, [q for q, t in ext.items() if t == kind])
            bound_inputs[kind] = [(s, v) for s in self.slaves for v in s.variables.values()
                                  if v.causality == "input" and v.type == kind and self._driven(s, v, ext)]
            values[kind] = np.zeros(len(slots[kind]) + len(bound_inputs[kind]), dtype=DTYPES[kind])
        force_slot = {f"{s.name}.{v.name}": len(slots[kind]) + j
                      for kind in KINDS for j, (s, v) in enumerate(bound_inputs[kind])}
        return values, slots, force_slot

    def _bind(self, values: dict, slots: dict, ext: Mapping[str, str],
              force_slot: Mapping[str, int]) -> tuple[list, list, dict[str, BoundInput]]:
        """Bind every slave's buffers (its outputs: its slice of the vectors; its inputs: a buffer gathered by
        index) and make the step plan: per slave, its gathers."""
        plan, bindings, bound = [], [], {}
        for s in self.slaves:
            gathers: list[tuple] = []
            kinds_bound = {}
            for kind in KINDS:
                outs = [v for v in s.variables.values() if v.causality == "output" and v.type == kind]
                first = slots[kind][f"{s.name}.{outs[0].name}"] if outs else 0
                out_view = values[kind][first:first + len(outs)]
                ins = [v for v in s.variables.values() if v.causality == "input" and v.type == kind
                       and self._driven(s, v, ext)]
                idx = np.array([slots[kind][self.sources.get((s.name, v.name), f"{s.name}.{v.name}")] for v in ins],
                               dtype=np.intp)
                in_buf = np.zeros(len(ins), dtype=DTYPES[kind])
                s.bind(kind, in_buf, [v.vr for v in ins], out_view, [v.vr for v in outs])
                kinds_bound[kind] = (in_buf, [v.vr for v in ins], idx, out_view, [v.vr for v in outs])
                for pos, v in enumerate(ins):
                    q = f"{s.name}.{v.name}"
                    bound[q] = BoundInput(kind, idx, pos, in_buf, int(idx[pos]), force_slot[q])
                if len(ins):
                    gathers.append((in_buf, self._gather(s, kind, ins, values[kind]), idx))
            plan.append((s, tuple(gathers)))
            bindings.append(kinds_bound)
        return plan, bindings, bound

    def _in_range(self, qualified: str, value: object) -> None:
        """A start value within its modelDescription's min/max, whichever FMU it is for (an FMU need not check)."""
        slave, v = self.variable(qualified)
        if v.type in ("Real", "Integer") and not isinstance(value, (bool, str)):
            check_range(qualified, v, typed_value(qualified, v.type, value))

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

    def _schedule(self, run: Execution, inputs: InputTable, forced: set[str]) -> list:
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
                check_range(q, v, typed)
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

    def _assemble(self, run: Execution, wall: float, applied: dict[str, dict[str, object]]) -> Result:
        data = run.rows(run.rows_done)
        messages = {s.name: list(s.messages) for s in self.slaves}
        return Result(data, self.system.name, wall, messages, parameters=applied,
                      models={c.name: c.model for c in self.system.components},
                      span=(run.start_time, run.time_of(run.step)))

    def terminate(self) -> None:
        for s in self.slaves:
            s.terminate()
