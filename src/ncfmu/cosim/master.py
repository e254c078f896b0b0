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
steps: at input-CSV changes, progress reports and deadline checks.
"""

from __future__ import annotations

import math
import time as _time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from ..errors import SimulationTimeout, SystemDefinitionError
from .native_loop import NativePlan, NativeSlave, library
from .result import Result
from .slave import DTYPES, KINDS, Slave, StatefulSlave
from .ssp import System

MODES = ("gauss-seidel", "jacobi")


#: Steps run before the loop hands back to Python (10 s simulated at 1 ms; ~0.3 s of lathe_taper in C).
NATIVE_CHUNK = 10_000

#: The most a run may record in memory: a stop time that needs more is a mistake, not a run.
MAX_RECORD_BYTES = 8 * 2 ** 30


@dataclass
class _Run:
    """Everything one run needs inside the loop, prepared once."""

    h: float
    n_steps: int
    times: np.ndarray
    values: dict
    plan: list
    ext_updates: list
    input_times: np.ndarray
    record_names: dict
    n_rec: dict
    rec: dict
    start_values: dict      # instance -> variable -> value: the system's parameter sets with the caller's applied
    native: NativePlan | None = None


@dataclass
class InputTable:
    """Piecewise-constant input changes over time (columns ``INSTANCE.VARIABLE``)."""

    time: np.ndarray
    columns: dict[str, np.ndarray] = field(default_factory=dict)

    @classmethod
    def from_csv(cls, path) -> InputTable:
        """Read fmpy's CSV layout (``time``, then ``INSTANCE.VARIABLE`` columns, numbers; names may be quoted).
        Every mistake is a :class:`SystemDefinitionError` naming the file, the line and what is wrong."""
        import csv
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
        table = np.empty((len(rows), len(header)))
        for i, (k, row) in enumerate(rows):
            if len(row) != len(header):
                raise SystemDefinitionError(f"{path}: line {k}: {len(row)} values for {len(header)} columns")
            for j, cell in enumerate(row):
                try:
                    table[i, j] = float(cell)
                except ValueError:
                    raise SystemDefinitionError(f"{path}: line {k}: {header[j]} = {cell!r}: not a number") from None
        t = table[:, 0]
        if not np.all(np.isfinite(t)):
            k = rows[int(np.flatnonzero(~np.isfinite(t))[0])][0]
            raise SystemDefinitionError(f"{path}: line {k}: time must be finite")
        if np.any(np.diff(t) < 0):
            raise SystemDefinitionError(f"{path}: the time column must not decrease")
        return cls(t, {n: table[:, j] for j, n in enumerate(header) if j > 0})


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

    # -- the run --------------------------------------------------------------------------------
    def run(self, stop_time: float | None = None, step_size: float | None = None,
            start_values: Mapping[str, object] | None = None, inputs: InputTable | None = None,
            start_time: float = 0.0, progress: Callable[[float], None] | None = None,
            deadline: float | None = None) -> Result:
        """Initialise every slave, step to ``stop_time`` and return the recorded outputs.

        ``deadline`` (a ``time.perf_counter()`` value): past it the run stops with :class:`SimulationTimeout`.
        """
        run = self._prepare(stop_time, step_size, start_values, inputs, start_time)
        wall = self._loop(run, 0, run.n_steps, progress, deadline)
        return self._assemble(run, run.rec, wall, run.start_values)

    def run_branches(self, branch_time: float, variants: Sequence[Mapping[str, object]],
                     stop_time: float | None = None, step_size: float | None = None,
                     start_values: Mapping[str, object] | None = None, inputs: InputTable | None = None,
                     start_time: float = 0.0) -> list[Result]:
        """Simulate to ``branch_time`` once, save every FMU's state, then run each variant from it.

        A variant sets tunable parameters or inputs (``INSTANCE.VARIABLE`` -> value) at the branch
        point, e.g. ``{"panel.emergency_at": 12.5}``. Each result covers the whole run.
        """
        stateful = [self._stateful(s) for s in self.slaves]
        run = self._prepare(stop_time, step_size, start_values, inputs, start_time)
        steps = (branch_time - start_time) / run.h      # nan or beyond the run (1e308 s) is refused, not rounded
        k = int(round(steps)) if 0 < steps < run.n_steps else 0
        if not 0 < k < run.n_steps:
            raise SystemDefinitionError(f"branch time {branch_time} s must lie inside the run "
                                        f"({start_time}..{start_time + run.n_steps * run.h} s)")
        wall = self._loop(run, 0, k)
        states = [holder.get_state() for holder in stateful]
        prefix = {kind: run.rec[kind][:k + 1].copy() for kind in KINDS}
        vector = {kind: run.values[kind].copy() for kind in KINDS}
        results = []
        try:
            for variant in variants:
                for holder, state in zip(stateful, states):
                    holder.set_state(state)
                for kind in KINDS:
                    run.values[kind][:] = vector[kind]
                    run.rec[kind][:k + 1] = prefix[kind]
                applied = {inst: dict(values) for inst, values in run.start_values.items()}
                for qualified, value in variant.items():
                    slave, v = self.variable(qualified)
                    slave.set_start(v.name, value)
                    applied[slave.name][v.name] = value
                for s in self.slaves:
                    s.read_outputs()
                results.append(self._assemble(run, run.rec, wall + self._loop(run, k, run.n_steps), applied))
        finally:
            for holder, state in zip(stateful, states):
                holder.free_state(state)
        return results

    @staticmethod
    def _stateful(slave: Slave) -> StatefulSlave:
        if not isinstance(slave, StatefulSlave):
            raise SystemDefinitionError(f"{slave.name} cannot save and restore its state: no branching")
        return slave

    def _prepare(self, stop_time, step_size, start_values, inputs, start_time) -> _Run:
        stop = self.system.stop_time if stop_time is None else float(stop_time)
        h = self.system.step_size if step_size is None else float(step_size)
        if not (math.isfinite(h) and h > 0):
            raise SystemDefinitionError(f"step size = {h!r}: must be > 0")
        if not (math.isfinite(stop) and stop > start_time):
            raise SystemDefinitionError(f"stop time = {stop!r}: must be after the start time {start_time}")
        steps = (stop - start_time) / h       # judged before rounding: 1e308 s at 1 ms is inf steps
        recorded = sum(len(s.variables) for s in self.slaves) + 1
        if (steps + 1) * recorded * 8 > MAX_RECORD_BYTES:
            raise SystemDefinitionError(f"stop time {stop:g} s at a step of {h:g} s is {steps:.6g} steps: recording "
                                        f"them needs more than {MAX_RECORD_BYTES / 2 ** 30:g} GiB; shorten the run")
        n_steps = int(round(steps))
        if n_steps < 1:
            raise SystemDefinitionError(f"stop time {stop:g} s is shorter than one step ({h:g} s) after the start "
                                        f"time {start_time:g} s: nothing would run")

        # Start values: the system's parameter sets, then the caller's overrides.
        applied: dict[str, dict[str, object]] = {s.name: {} for s in self.slaves}
        for comp in self.system.components:
            for name, value in comp.parameters.items():
                self.by_name[comp.name].set_start(name, value)
                applied[comp.name][name] = value
        for qualified, value in (start_values or {}).items():
            slave, v = self.variable(qualified)
            for c in self.system.connections:
                if c.end_element == slave.name and c.end_connector == v.name:
                    raise SystemDefinitionError(f"{qualified} is driven by the connection {c}: a start value would be "
                                                f"overwritten every step (set {c.start_element}.{c.start_connector} "
                                                "instead)")
            slave.set_start(v.name, value)
            applied[slave.name][v.name] = value

        ext = {}
        if inputs is not None:
            for qualified in inputs.columns:
                slave, v = self.variable(qualified)
                if v.causality != "input":
                    raise SystemDefinitionError(f"input CSV column {qualified!r} is {_a(v.causality)}, not an input")
                if any(c.end_element == slave.name and c.end_connector == v.name for c in self.system.connections):
                    raise SystemDefinitionError(f"input CSV column {qualified!r} is driven by a connection already")
                ext[qualified] = v.type

        for s in self.slaves:
            s.initialize(start_time, stop)

        # Global output vectors and the gather plan.
        values, slots, record_names = {}, {}, {}
        for kind in KINDS:
            slots[kind] = _output_slots(self.slaves, kind, [q for q, t in ext.items() if t == kind])
            values[kind] = np.zeros(len(slots[kind]), dtype=DTYPES[kind])
            record_names[kind] = [q for q in slots[kind] if q not in ext]
        sources = {(c.end_element, c.end_connector): f"{c.start_element}.{c.start_connector}"
                   for c in self.system.connections}
        plan, bindings = [], []
        for s in self.slaves:
            gathers, bound = [], {}
            for kind in KINDS:
                outs = [v for v in s.variables.values() if v.causality == "output" and v.type == kind]
                first = slots[kind][f"{s.name}.{outs[0].name}"] if outs else 0
                out_view = values[kind][first:first + len(outs)]
                ins = [v for v in s.variables.values() if v.causality == "input" and v.type == kind
                       and ((s.name, v.name) in sources or f"{s.name}.{v.name}" in ext)]
                idx = np.array([slots[kind][sources.get((s.name, v.name), f"{s.name}.{v.name}")] for v in ins],
                               dtype=np.intp)
                in_buf = np.zeros(len(ins), dtype=DTYPES[kind])
                s.bind(kind, in_buf, [v.vr for v in ins], out_view, [v.vr for v in outs])
                bound[kind] = (in_buf, [v.vr for v in ins], idx, out_view, [v.vr for v in outs])
                if len(ins):
                    gathers.append((in_buf, values[kind].take, idx))
            plan.append((s, tuple(gathers)))
            bindings.append(bound)

        ext_updates = []
        if inputs is not None:
            for q, kind in ext.items():
                ext_updates.append((values[kind], slots[kind][q], inputs.columns[q].astype(DTYPES[kind])))

        n_rec = {k: len(record_names[k]) for k in KINDS}
        rec = {k: np.empty((n_steps + 1, n_rec[k]), dtype=DTYPES[k]) for k in KINDS}
        for s in self.slaves:
            s.read_outputs()
        for k in KINDS:
            rec[k][0] = values[k][:n_rec[k]]
        times = start_time + h * np.arange(n_steps + 1)
        input_times = inputs.time if inputs is not None else np.empty(0)
        run = _Run(h, n_steps, times, values, plan, ext_updates, input_times, record_names, n_rec, rec, applied)
        natives = [s for s in self.slaves if isinstance(s, NativeSlave)]
        if self.native and len(natives) == len(self.slaves) and library() is not None:
            records = [(rec[k], values[k][:n_rec[k]]) for k in KINDS if n_rec[k]]
            run.native = NativePlan(natives, bindings, values, records, times, h, self.mode == "jacobi")
        return run

    def _loop(self, run: _Run, first: int, last: int, progress=None, deadline: float | None = None) -> float:
        """Steps ``first`` .. ``last - 1``; returns the wall time.

        The steps run in chunks that end where Python must act before the next step (an input change, a
        progress report, a deadline check every 64 steps, and every ``NATIVE_CHUNK`` steps so that Ctrl-C is
        seen); each chunk runs in C when every slave allows it, else in Python. Both make the same calls.
        """
        input_times, ext_updates, times = run.input_times, run.ext_updates, run.times
        next_change = (int(np.searchsorted(input_times, times[first] + 1e-12, side="right")) - 1
                       if len(input_times) else 0)
        if len(input_times) and next_change >= 0:
            for arr, slot, col in ext_updates:
                arr[slot] = col[next_change]
        next_change = max(next_change + 1, 0)
        # the first step at which each input change applies: input <= t + 1e-12
        change_steps = np.searchsorted(times + 1e-12, input_times, side="left") if len(input_times) else None
        report_every = max(1, run.n_steps // 100)
        self.loop_used = "python" if run.native is None else "c"
        advance: Callable[[int, int], None]
        if run.native is not None:
            run.native.forget_sent()     # start values or a restored state may have changed the FMUs' inputs
            advance = run.native.run
        else:
            advance = self._python_steps(run)
        wall0 = _time.perf_counter()
        i = first
        while i < last:
            while next_change < len(input_times) and input_times[next_change] <= times[i] + 1e-12:
                for arr, slot, col in ext_updates:
                    arr[slot] = col[next_change]
                next_change += 1
            end = min(last, i + NATIVE_CHUNK)
            if change_steps is not None and next_change < len(input_times):
                end = min(end, int(change_steps[next_change]))
            if progress is not None:
                end = min(end, (i + report_every) // report_every * report_every)   # the next row to report
            if deadline is not None:
                end = min(end, (i + 64) // 64 * 64)
            advance(i, end)
            i = row = end
            if progress is not None and row % report_every == 0:
                progress(row / run.n_steps)
            if deadline is not None and row % 64 == 0 and _time.perf_counter() > deadline:
                raise SimulationTimeout(f"stopped at t = {float(times[row - 1]) + run.h:.3f} s of "
                                        f"{float(times[-1]):.3f} s: over the time allowed "
                                        f"({_time.perf_counter() - wall0:.1f} s of wall time)")
        return _time.perf_counter() - wall0

    def _python_steps(self, run: _Run) -> Callable[[int, int], None]:
        """The Python loop: ``advance(first, end)`` steps ``first`` .. ``end - 1`` and records each row."""
        values, plan, rec, n_rec, h = run.values, run.plan, run.rec, run.n_rec, run.h
        times = run.times.tolist()
        # the rows to record and the slices of the output vectors they copy, prepared once
        record = [(rec[k], values[k][:n_rec[k]]) for k in KINDS if n_rec[k]]
        jacobi = self.mode == "jacobi"

        def advance(first: int, end: int) -> None:
            for i in range(first, end):
                t = times[i]
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
                row = i + 1
                for table, vector in record:
                    table[row] = vector
        return advance

    def _assemble(self, run: _Run, rec, wall: float, applied: dict[str, dict[str, object]]) -> Result:
        dtype: list[tuple[str, type[np.generic]]] = [("time", np.float64)]
        for k in KINDS:
            dtype += [(q, np.float64 if k == "Real" else (np.bool_ if k == "Boolean" else np.int32))
                      for q in run.record_names[k]]
        data = np.empty(run.n_steps + 1, dtype=dtype)
        data["time"] = run.times
        for k in KINDS:
            for j, q in enumerate(run.record_names[k]):
                data[q] = rec[k][:, j]
        messages = {s.name: list(getattr(s, "messages", [])) for s in self.slaves}
        return Result(data, self.system.name, wall, messages, parameters=applied,
                      models={c.name: c.model for c in self.system.components})

    def terminate(self) -> None:
        for s in self.slaves:
            s.terminate()
