"""What a run of a system says: its summary lines, its metrics and its plot, from named instances.

A system's :class:`Report` is a tuple of parts, each bound to the instance names of its definition
(``LatheCycle(seq="seq", x="x_axis", z="z_axis")``): the CLI's summary, a sweep's metrics and recorded
variables, and the plot in the machine plane all come from it. Nothing here recognises a system by the
columns of its result. A part reads the parameters the run actually used (``Result.parameters``: the
system's parameter sets with every ``--set`` applied), so a plot or a metric of a run with ``--set`` is
that run's.

Every summary line and metric is computed in one place, an accumulator (:meth:`Part.accumulator`,
:meth:`Report.accumulator`) that reads the rows of a run in chunks as they come and keeps only running
extremes, first and last values and counts -- never the trajectory -- so an eight-hour run is summarised in
the memory of a short one. The whole-trajectory methods (``summary(result, parameters)``,
``metrics(result, parameters)``) feed a finished Result to the same accumulator in one chunk.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..controllers.base import POSITION_LIMIT
from ..errors import SystemDefinitionError
from ..ports import to_float, to_int

Parameters = Mapping[str, Mapping[str, object]]      # instance -> parameter -> value

#: How many configured controllers :func:`configured` keeps (a run's report asks for one a few times).
_CONFIGURED_KEPT = 4
_configured_cache: dict[tuple[str, tuple[tuple[str, str], ...]], Any] = {}


def configured(kind: type[Any], values: Mapping[str, object]) -> Any:
    """A controller of class ``kind`` configured with a component's parameters ``values`` (the run's; its
    defaults for the rest): its ``meaning`` is what the run's program means (the part check, the plots and the
    thread judge read it, never the program). Kept for the next reader of the same parameters."""
    key = (kind.__qualname__, tuple(sorted((k, repr(v)) for k, v in values.items())))
    controller = _configured_cache.get(key)
    if controller is None or type(controller) is not kind:
        controller = kind(**values)
        if len(_configured_cache) >= _CONFIGURED_KEPT:
            _configured_cache.pop(next(iter(_configured_cache)))
        _configured_cache[key] = controller
    return controller


def start_parameters(components, start_values: Mapping[str, object]) -> dict[str, dict[str, object]]:
    """The parameters a run applies, known before it starts: each component's parameter set (``components``
    of a System) with the run's start values (``INSTANCE.VARIABLE`` -> value) on top -- what the run's
    Result.parameters will say, for an accumulator that must know them from the first row."""
    applied: dict[str, dict[str, object]] = {c.name: dict(c.parameters) for c in components}
    for qualified, value in start_values.items():
        instance, _, name = qualified.partition(".")
        applied.setdefault(instance, {})[name] = value
    return applied


class FirstTime:
    """The time of the first row at which a flag is set (NaN until it is), over chunks of rows."""

    def __init__(self) -> None:
        self.value = float("nan")

    def write(self, t: np.ndarray, flag: np.ndarray) -> None:
        if np.isnan(self.value) and flag.any():
            self.value = float(t[np.argmax(flag)])


class EndOfActivity:
    """The time the last active stretch ended (the row after its last active row), over chunks of rows;
    NaN when it never ran or still runs at the last row."""

    def __init__(self) -> None:
        self.ended = float("nan")        # the last active -> inactive transition seen so far
        self.active = False              # the last row seen

    def write(self, t: np.ndarray, active: np.ndarray) -> None:
        if not len(active):
            return
        before = np.concatenate(([self.active], active[:-1]))      # each row's predecessor
        stops = np.flatnonzero(before & ~active)
        if len(stops):
            self.ended = float(t[stops[-1]])
        self.active = bool(active[-1])

    @property
    def value(self) -> float:
        return float("nan") if self.active else self.ended


def _first_time(result, mask: np.ndarray) -> float:
    """:class:`FirstTime` over a whole trajectory."""
    first = FirstTime()
    first.write(result.time, mask)
    return first.value


def _ended(result, active: np.ndarray) -> float:
    """:class:`EndOfActivity` over a whole trajectory."""
    end = EndOfActivity()
    end.write(result.time, active)
    return end.value


def table_of(parameters: Mapping[str, object]) -> list[tuple[float, float, float]]:
    """An AreaLimiter's limit table ``(ref_max, lim_min, lim_max)`` from its parameters."""
    n = to_int(parameters.get("n_regions", 0))
    return [(to_float(parameters[f"region[{i}].ref_max"]), to_float(parameters[f"region[{i}].lim_min"]),
             to_float(parameters[f"region[{i}].lim_max"])) for i in range(1, n + 1)]


class PartAccumulator:
    """A part's summary lines and metrics over the rows of a run fed in chunks (time order): running values
    only. This base tracks the part's alarm; a part's own accumulator adds what its lines need."""

    def __init__(self, part: Part) -> None:
        self.part = part
        self.alarmed = False

    def write(self, rows: np.ndarray) -> None:
        """One chunk (a structured array with ``time`` and at least the part's variables), never empty."""
        alarm = self.part.alarm
        if alarm is not None and not self.alarmed:
            self.alarmed = bool(rows[alarm].any())

    def summary(self) -> list[str]:
        return []

    def metrics(self) -> dict[str, float]:
        return {}

    def finished(self) -> bool | None:
        """Whether the part's cycle ran to its end in the rows so far; None for a part without a cycle."""
        return None


class Part:
    """One instance's (or a few instances') share of a report; every method has a neutral default."""

    def variables(self) -> tuple[str, ...]:
        """The recorded variables the part reads (a sweep records them by default)."""
        return ()

    def accumulator(self, parameters: Parameters) -> PartAccumulator:
        """The part's summary and metrics over rows fed in chunks, for a run with ``parameters``."""
        return PartAccumulator(self)

    def _fed(self, result, parameters: Parameters) -> PartAccumulator:
        acc = self.accumulator(parameters)
        if len(result.data):
            acc.write(result.data)
        return acc

    def summary(self, result, parameters: Parameters) -> list[str]:
        return self._fed(result, parameters).summary()

    def metrics(self, result, parameters: Parameters) -> dict[str, float]:
        return self._fed(result, parameters).metrics()

    @property
    def alarm(self) -> str | None:
        """The part's alarm output, if it has one."""
        return None

    @property
    def done(self) -> str | None:
        """The output that says the part's cycle is done (its accumulator's :meth:`PartAccumulator.finished` reads
        it; a run ends there, :func:`~ncfmu.systems.outcome.halted`); None: the part has no cycle."""
        return None

    def alarmed(self, result) -> bool:
        return self.alarm is not None and bool(result[self.alarm].any())

    def finished(self, result, parameters: Parameters | None = None) -> bool | None:
        """Whether the part's cycle ran to its end within the run; None for a part without a cycle (the
        accumulator's judgement over the whole trajectory)."""
        return self._fed(result, parameters or {}).finished()

    def draw(self, ax, result, parameters: Parameters) -> None:
        """Add to the machine-plane panel (path, envelope, contour)."""

    def draw_time(self, ax, result) -> None:
        """Mark on a panel over time what the part did when (a feed hold, an emergency return)."""


@dataclass(frozen=True)
class Axes(Part):
    """The servo axes: following errors."""

    names: tuple[str, ...]

    def variables(self) -> tuple[str, ...]:
        return tuple(f"{a}.{v}" for a in self.names for v in ("pos", "following_error"))

    def accumulator(self, parameters: Parameters) -> PartAccumulator:
        return _AxesAccumulator(self)


class _AxesAccumulator(PartAccumulator):
    part: Axes

    def __init__(self, part: Axes) -> None:
        super().__init__(part)
        self.largest = dict.fromkeys(part.names, 0.0)        # axis -> max |following error| so far

    def write(self, rows: np.ndarray) -> None:
        super().write(rows)
        for a in self.part.names:
            self.largest[a] = float(np.maximum(self.largest[a], np.abs(rows[f"{a}.following_error"]).max()))

    def summary(self) -> list[str]:
        return [f"  {a}: max |following error| {e * 1000:.2f} um" for a, e in self.largest.items()]

    def metrics(self) -> dict[str, float]:
        return {"max_following_error_mm": max(self.largest.values())} if self.largest else {}


@dataclass(frozen=True)
class Plane:
    """The machine plane of the plot: ``horizontal`` and ``vertical`` are axis instances."""

    horizontal: str
    vertical: str
    title: str
    xlabel: str
    ylabel: str
    path_label: str = "tool (actual)"
    equal_aspect: bool = False


@dataclass(frozen=True)
class LatheCycle(Part):
    """A CutSequencer driving a radius axis ``x`` and a length axis ``z``."""

    seq: str
    x: str
    z: str

    def variables(self) -> tuple[str, ...]:
        return (*(f"{self.seq}.{v}" for v in ("subcycle", "done", "alarm")), f"{self.x}.pos", f"{self.z}.pos")

    @property
    def alarm(self) -> str | None:
        return f"{self.seq}.alarm"

    @property
    def done(self) -> str | None:
        """The sequencer's ``done``: set when the last block (the registers' last pass) or the program (M30/M02)
        has finished."""
        return f"{self.seq}.done"

    def accumulator(self, parameters: Parameters) -> PartAccumulator:
        return _LatheAccumulator(self, self.x_written(parameters))

    def x_written(self, parameters: Parameters) -> str | None:
        """How the run's part program writes X: "diameter", "radius", "diameter and radius" (G7 and G8 both), or
        None for a run of the registers (radii): its G7/G8 words, else seq.x_diameter (the configured sequencer's
        ``meaning.x_written``). The axis and the summary's X are radii either way."""
        from ..controllers.sequencer import CutSequencer
        return configured(CutSequencer, parameters.get(self.seq, {})).meaning.x_written or None

    def draw(self, ax, result, parameters: Parameters) -> None:
        from ..controllers.sequencer import CutSequencer
        seq = parameters.get(self.seq, {})
        controller = configured(CutSequencer, seq)
        if controller.meaning.programmed:
            # a part program: the finished profile of each cycle and the planned passes, as the sequencer runs them
            from ..controllers.geometry import sample
            for k, seg in enumerate(controller.plan):     # the planned moves in the axes' coordinates
                ax.plot(*zip(*sample([seg.element], 0.2)), color="tab:green", lw=0.5, alpha=0.6,
                        label="planned moves" if k == 0 else None)
            profiles = {id(o.elements): o.elements for o in controller.meaning.outlines}
            for k, profile in enumerate(profiles.values()):
                ax.plot(*zip(*sample([p.element for p in profile], 0.2)), color="k", lw=1.5,
                        label="profile (finished part)" if k == 0 else None)
        elif "x_start" in seq and "block[1].Xf" in seq:
            stock = to_float(seq["x_start"]) - to_float(seq["block[1].Xf"])
            ax.axhline(stock, color="0.5", ls=":", lw=0.8, label=f"stock outline X = {stock:g}")
            x = result[f"{self.x}.pos"]
            ax.set_ylim(min(x.min(), stock) - 1, max(x.max(), to_float(seq["x_start"])) + 2)


class _LatheAccumulator(PartAccumulator):
    """Cuts are the stretches of sub-cycle 2 (SC2); a run that starts in SC2 has not started a cut there."""

    part: LatheCycle

    def __init__(self, part: LatheCycle, x_written: str | None = None) -> None:
        super().__init__(part)
        self.x_written = x_written             # how the part program writes X (None: a run of the registers)
        self.sub: int | None = None            # the sub-cycle of the last row seen
        self.cut_starts: list[float] = []      # X at the start of each cut (one value per cut, not per step)
        self.cut = False                       # any row in SC2
        self.x_cut = self.z_cut = math.inf     # smallest X and Z during the cuts
        self.done = FirstTime()
        self.x = self.z = math.nan             # the last row's tool position

    def write(self, rows: np.ndarray) -> None:
        super().write(rows)
        p = self.part
        sub, x, z = rows[f"{p.seq}.subcycle"], rows[f"{p.x}.pos"], rows[f"{p.z}.pos"]
        cut = sub == 2
        before = np.concatenate(([self.sub if self.sub is not None else 2], sub[:-1]))
        self.cut_starts += x[cut & (before != 2)].tolist()
        if cut.any():
            self.cut = True
            self.x_cut = float(np.minimum(self.x_cut, x[cut].min()))
            self.z_cut = float(np.minimum(self.z_cut, z[cut].min()))
        self.done.write(rows["time"], rows[p.done])
        self.sub, self.x, self.z = int(sub[-1]), float(x[-1]), float(z[-1])

    def summary(self) -> list[str]:
        lines = [f"  cuts (SC2): {len(self.cut_starts)}"]
        if self.cut:
            lines.append("  X at the start of each cut [mm]: " + ", ".join(f"{x:.4f}" for x in self.cut_starts))
            lines.append(f"  smallest X during the cuts: {self.x_cut:.4f} mm; Z reached {self.z_cut:.4f} mm")
        end = "not finished" if math.isnan(self.done.value) else f"{self.done.value:.3f} s"
        lines.append(f"  cycle done: {end}; tool at X {self.x:.4f}, Z {self.z:.4f} mm; "
                     f"alarm: {'yes' if self.alarmed else 'no'}")
        if self.x_written and "diameter" in self.x_written:
            smallest = f"smallest during the cuts {2 * self.x_cut:.4f} mm, " if self.cut else ""
            lines.append(f"  X above is a radius (the axis); the program writes X as a {self.x_written}; as a "
                         f"diameter: {smallest}tool at the end {2 * self.x:.4f} mm")
        elif self.x_written == "radius":
            lines.append("  X above is a radius, as the program writes it")
        return lines

    def metrics(self) -> dict[str, float]:
        return {"final_radius_mm": self.x_cut if self.cut else float("nan"),
                "cycle_time_s": self.done.value}

    def finished(self) -> bool | None:
        return not math.isnan(self.done.value)


@dataclass(frozen=True)
class FeedCycle(Part):
    """A ProgrammableFeed infeeding the axis ``x``."""

    feed: str
    x: str
    hold: str = ""      # the variable wired to the feed's feed_hold input (a panel's switch), marked in the plot

    def variables(self) -> tuple[str, ...]:
        return (*(f"{self.feed}.{v}" for v in ("pc", "run", "emergency_active", "alarm", "return_counter_x")),
                f"{self.x}.pos")

    @property
    def alarm(self) -> str | None:
        return f"{self.feed}.alarm"

    @property
    def done(self) -> str | None:
        """The feed's ``run`` (RUN): the cycle is done when RUN -- and the emergency return, if one ran -- fell
        after it ran (the program's END after the return)."""
        return f"{self.feed}.run"

    def accumulator(self, parameters: Parameters) -> PartAccumulator:
        from ..controllers.feed import ProgrammableFeed
        default = ProgrammableFeed.default_parameters()["wear_address"]
        return _FeedAccumulator(self, to_int(parameters.get(self.feed, {}).get("wear_address", default)))

    def draw_time(self, ax, result) -> None:
        """Shade the stretches of feed hold (while a cycle ran: it holds nothing else) and of the emergency
        return, with how many and how long in the legend; a variable not recorded marks nothing."""
        t = result.time
        run = result[f"{self.feed}.run"].astype(bool) if f"{self.feed}.run" in result else np.ones(len(t), bool)
        spans = []
        if self.hold and self.hold in result:
            spans.append(("feed hold", "tab:orange", result[self.hold].astype(bool) & run))
        if f"{self.feed}.emergency_active" in result:
            spans.append(("emergency return", "tab:red", result[f"{self.feed}.emergency_active"].astype(bool)))
        for what, colour, on in spans:
            if not on.any():
                continue
            starts = int(np.count_nonzero(on & ~np.concatenate(([False], on[:-1]))))
            # a row stands for the time to the next one (the last row for none)
            held = float(np.sum(np.diff(t)[on[:-1]]))
            ax.fill_between(t, 0, 1, where=on, step="post", color=colour, alpha=0.2, lw=0,
                            transform=ax.get_xaxis_transform(),
                            label=f"{what}: {starts} time{'s' if starts != 1 else ''}, {held:.3g} s")



class _FeedAccumulator(PartAccumulator):
    """The cycle is active while the feed runs or its emergency return does; it ended when the last active
    stretch did."""

    part: FeedCycle

    def __init__(self, part: FeedCycle, wear_address: int) -> None:
        super().__init__(part)
        self.deepest = -math.inf
        self.ended = EndOfActivity()
        self.x = self.counter = math.nan       # the last row's X and return counter
        # the cycles RUN ran (a soak's panel.repeat_every runs many): a stretch of RUN entered at the wear
        # address is a wear compensation (START2), any other a part (START1); a part stretch that ends without
        # the emergency return is a part completed
        self.wear_address = wear_address
        self.running = self.emergency = False  # RUN and the emergency return at the last row
        self.in_part = False                   # the present stretch of RUN is a part's
        self.parts = self.completed = self.wear_cycles = self.emergencies = 0

    def write(self, rows: np.ndarray) -> None:
        super().write(rows)
        p = self.part
        x = rows[f"{p.x}.pos"]
        self.deepest = float(np.maximum(self.deepest, x.max()))
        run, emergency = rows[p.done].astype(bool), rows[f"{p.feed}.emergency_active"].astype(bool)
        self.ended.write(rows["time"], run | emergency)
        self.x, self.counter = float(x[-1]), float(rows[f"{p.feed}.return_counter_x"][-1])
        self.emergencies += int(np.count_nonzero(emergency & ~np.concatenate(([self.emergency], emergency[:-1]))))
        before = np.concatenate(([self.running], run[:-1]))
        pc = rows[f"{p.feed}.pc"]
        for i in np.flatnonzero(run != before):          # the edges of RUN: a few per cycle
            if run[i]:
                self.in_part = int(pc[i]) != self.wear_address
                self.parts += self.in_part
                self.wear_cycles += not self.in_part
            elif self.in_part and not emergency[i]:
                self.completed += 1
        self.running, self.emergency = bool(run[-1]), bool(emergency[-1])

    def summary(self) -> list[str]:
        end = "not finished" if math.isnan(self.ended.value) else f"{self.ended.value:.3f} s"
        return [f"  deepest X: {self.deepest:.4f} mm; cycle ended: {end}; "
                f"X at the end {self.x:.4f} mm; return counter X {self.counter:.4f} mm",
                f"  cycles: {self.parts} parts started (START1), {self.completed} completed; "
                f"{self.wear_cycles} wear compensations (START2); {self.emergencies} emergency returns",
                f"  alarm: {'yes' if self.alarmed else 'no'}"]

    def metrics(self) -> dict[str, float]:
        return {"deepest_x_mm": self.deepest, "cycle_time_s": self.ended.value}

    def finished(self) -> bool | None:
        return not math.isnan(self.ended.value)


@dataclass(frozen=True)
class Envelope(Part):
    """An AreaLimiter: reference axis ``ref`` (horizontal in the plane), limited axis ``lim`` (vertical)."""

    limiter: str
    ref: str
    lim: str
    region_names: tuple[str, ...] = ()

    def variables(self) -> tuple[str, ...]:
        return (f"{self.limiter}.alarm", f"{self.limiter}.blocked")

    @property
    def alarm(self) -> str | None:
        return f"{self.limiter}.alarm"

    def legend(self) -> tuple[str, ...]:
        """What each bit of the limiter's ``blocked`` mask stops (its port says: 1 ref+, 2 ref-, 4 lim+, 8 lim-),
        in the system's axis names."""
        return (f"{self.ref} +", f"{self.ref} -", f"{self.lim} +", f"{self.lim} -")

    def accumulator(self, parameters: Parameters) -> PartAccumulator:
        return _EnvelopeAccumulator(self, parameters)

    def summary(self, result, parameters: Parameters) -> list[str]:
        if not self.alarmed(result):
            return ["  area limiter: no violation"]
        mask = int(np.bitwise_or.reduce(np.asarray(result[f"{self.limiter}.blocked"], dtype=np.int64)))
        bits = ", ".join(f"{1 << i} {d}" for i, d in enumerate(self.legend()))
        stopped = [d for i, d in enumerate(self.legend()) if mask & (1 << i)]
        what = (f"blocked {' and '.join(stopped)}" if stopped
                else "no direction blocked (a fault: an absurd input, see the log)")
        first = _first_time(result, result[f"{self.limiter}.alarm"].astype(bool))
        return [f"  area limiter: ALARM from t = {first:.3f} s, {what} (blocked mask {mask}; bits {bits})"]

    def draw(self, ax, result, parameters: Parameters) -> None:
        """Shade what the table forbids, region by region, over the span the path covers (a bound beyond
        POSITION_LIMIT, e.g. the table's 1e6 for "no limit", is none)."""
        table = table_of(parameters.get(self.limiter, {}))
        ref, lim = result[f"{self.ref}.pos"], result[f"{self.lim}.pos"]
        inner = [b for b, _, _ in table if abs(b) < POSITION_LIMIT]
        left = min(ref.min(), *inner) - 20 if inner else ref.min() - 20
        right = max(ref.max(), *inner) + 20 if inner else ref.max() + 20
        finite = [v for _, lo, hi in table for v in (lo, hi) if abs(v) < POSITION_LIMIT]
        bottom, top = min(lim.min(), *finite) - 20, max(lim.max(), *finite) + 20
        edge = left
        # A region's name goes on its boundary, on the forbidden side; a boundary outside the view (the chuck's
        # X >= 40 above a lathe's work, whose cycle part has set the limits already) gets its name at the view's
        # edge nearest to it, with the bound: a label outside the axes would have tight_layout shrink the figure.
        view = (bottom, top) if ax.get_autoscaley_on() else ax.get_ylim()
        edge_of_view = ax.get_xaxis_transform()          # x in data, y in axes fractions
        for i, (ref_max, lo, hi) in enumerate(table):
            end = min(ref_max, right)
            if end <= edge:
                continue
            name = self.region_names[i] if i < len(self.region_names) else f"region {i + 1}"
            for low, high, bound, above in ((bottom, lo, lo, False), (hi, top, hi, True)):
                if low < high and abs(bound) < POSITION_LIMIT:
                    ax.fill_between([edge, end], low, high, color="tab:red", alpha=0.15, lw=0)
                    ax.hlines(bound, edge, end, color="tab:red", lw=1)
                    mid = (edge + end) / 2
                    if view[0] <= bound <= view[1]:
                        label = ax.text(mid, bound, name, ha="center", va="bottom" if above else "top", fontsize=8)
                    else:
                        over = bound > view[1]
                        label = ax.text(mid, 0.97 if over else 0.03, f"{name}: {self.lim} {'>' if above else '<'} "
                                        f"{bound:g} forbidden", transform=edge_of_view, ha="center",
                                        va="top" if over else "bottom", fontsize=8)
                    label.set_in_layout(False)
            edge = end
        ax.fill_between([], [], [], color="tab:red", alpha=0.15, label="forbidden by the limit table")


class _EnvelopeAccumulator(PartAccumulator):
    """The limiter's line is worded by :meth:`Envelope.summary` (one home for it) from the rows that witness
    every state the limiter was in: the first row of each (alarm, blocked mask) pair it showed, and the last
    row -- a few dozen rows at most (the mask has four bits), however long the run. Whatever the line reads
    of those columns that depends only on which states occurred, when each first occurred and how the run
    ended (any, max, OR of the masks, the first alarm's time, the last value) is the same on the witness
    rows as on the whole trajectory."""

    part: Envelope

    def __init__(self, part: Envelope, parameters: Parameters) -> None:
        super().__init__(part)
        self.parameters = parameters
        self.firsts: dict[int, np.ndarray] = {}      # (alarm, mask) state -> the row where it first occurred
        self.last: np.ndarray | None = None

    def write(self, rows: np.ndarray) -> None:
        super().write(rows)
        alarm, blocked = self.part.alarm, f"{self.part.limiter}.blocked"
        assert alarm is not None
        chunk = rows[["time", alarm, blocked]]
        # one integer per (alarm, mask) pair: the mask is an int32, the alarm a Boolean
        states = (chunk[alarm] != 0).astype(np.int64) << 32 | (chunk[blocked].astype(np.int64) & 0xFFFFFFFF)
        values, first = np.unique(states, return_index=True)
        for state, i in zip(values.tolist(), first.tolist()):
            if state not in self.firsts:
                self.firsts[state] = chunk[i:i + 1].copy()
        self.last = chunk[-1:].copy()

    def summary(self) -> list[str]:
        if self.last is None:
            return []
        from ..cosim.result import Result
        witness = np.concatenate(sorted(self.firsts.values(), key=lambda r: float(r["time"][0])))
        if witness["time"][-1] != self.last["time"][0]:
            witness = np.concatenate([witness, self.last])
        return self.part.summary(Result(witness), self.parameters)


@dataclass(frozen=True)
class ContourCycle(Part):
    """A ContourInterpolator on the axes ``x`` and ``y``: the programmed and the corrected contour."""

    contour: str
    x: str
    y: str

    def variables(self) -> tuple[str, ...]:
        return (*(f"{self.contour}.{v}" for v in ("segment", "done", "alarm")), f"{self.x}.pos", f"{self.y}.pos")

    @property
    def alarm(self) -> str | None:
        return f"{self.contour}.alarm"

    @property
    def done(self) -> str | None:
        """The interpolator's ``done``: set at the contour's end (the last segment or program line finished)."""
        return f"{self.contour}.done"

    def interpolator(self, parameters: Parameters):
        """The interpolator the run used (its tool path and contour), from the run's parameters."""
        from ..controllers.contour import ContourInterpolator
        return configured(ContourInterpolator, parameters.get(self.contour, {}))

    def accumulator(self, parameters: Parameters) -> PartAccumulator:
        return _ContourAccumulator(self, parameters)

    def draw(self, ax, result, parameters: Parameters) -> None:
        from ..controllers.geometry import sample
        c = self.interpolator(parameters)
        prog = np.array(sample(c.contour, 0.2))
        cor = np.array(sample([m.element for m in c.tool_path], 0.05))
        x, y = result[f"{self.x}.pos"], result[f"{self.y}.pos"]
        ax.plot(prog[:, 0], prog[:, 1], "k-", lw=1.0, label="programmed contour")
        ax.plot(cor[:, 0], cor[:, 1], "g--", lw=1.0, label=f"corrected ({c.diameter_delta:+g} mm diameter)")
        # the correction is a fraction of a millimetre: zoom on the corner farthest from the origin
        cx, cy = max((e.start for e in c.contour), key=lambda p: p[0] + p[1])
        zoom = ax.inset_axes([1.05, 0.05, 0.6, 0.9])
        zoom.plot(prog[:, 0], prog[:, 1], "k-", lw=1.0)
        zoom.plot(cor[:, 0], cor[:, 1], "g--", lw=1.0)
        zoom.plot(x, y, lw=0.8, color="tab:blue")
        span = max(1.0, 1.5 * abs(c.diameter_delta))
        zoom.set_xlim(cx - span, cx + 0.6 * span)
        zoom.set_ylim(cy - span, cy + 0.6 * span)
        zoom.set_aspect("equal")
        zoom.set_title(f"corner ({cx:g}, {cy:g}) [mm]", fontsize=8)
        zoom.grid(True, alpha=0.3)


class _ContourAccumulator(PartAccumulator):
    """The contour error is the largest distance of the axes' position from the corrected tool path while
    the interpolator is on the contour (segment >= 1): point by point, so chunk by chunk."""

    part: ContourCycle

    def __init__(self, part: ContourCycle, parameters: Parameters) -> None:
        super().__init__(part)
        self.path = [move.element for move in part.interpolator(parameters).tool_path]
        self.on = False                     # any row on the contour
        self.error = -math.inf              # largest distance from the path so far
        self.done = FirstTime()
        self.segment = 0                    # the last row's segment

    def write(self, rows: np.ndarray) -> None:
        from ..checks import path_distance
        super().write(rows)
        p = self.part
        segment = rows[f"{p.contour}.segment"]
        on = segment >= 1
        if on.any():
            self.on = True
            best = path_distance(rows[f"{p.x}.pos"][on], rows[f"{p.y}.pos"][on], self.path)
            self.error = float(np.maximum(self.error, best.max()))
        self.done.write(rows["time"], rows[p.done])
        self.segment = int(segment[-1])

    def summary(self) -> list[str]:
        end = "not finished" if math.isnan(self.done.value) else f"{self.done.value:.3f} s"
        return [f"  contour done: {end}; last segment (point path) or program line: "
                f"{self.segment}; alarm: {'yes' if self.alarmed else 'no'}"]

    def metrics(self) -> dict[str, float]:
        return {"max_contour_error_mm": self.error if self.on else float("nan"), "cycle_time_s": self.done.value}

    def finished(self) -> bool | None:
        return not math.isnan(self.done.value)


class ReportAccumulator:
    """A report's summary and metrics computed as a run goes: a recording sink (``open(columns)``,
    ``write(rows)`` chunk by chunk, ``close(...)``) that keeps running values only, so its memory does not
    grow with the simulated time. The rows must carry every column of :meth:`Report.record`; a run may
    record them at its output interval, and then the metrics are those of the recorded rows.

    The parts' accumulators are made when the run opens its sinks, i.e. after the master checked every start
    value: a bad one is named by the master's rule, not by a controller built here from the parameters."""

    def __init__(self, report: Report, parameters: Parameters) -> None:
        self.report = report
        self.parameters = parameters
        self.parts: list[PartAccumulator] = []
        self.rows = 0                           # rows written so far
        self.start_time = self.last_time = math.nan
        self.complete: bool | None = None       # None while open; then what close() said
        self.stopped_at: float | None = None
        self.reason = ""
        self._opened_at: float | None = None
        self._wall_time = math.nan

    def open(self, columns: Sequence[tuple[str, np.dtype]]) -> None:
        have = {name for name, _ in columns}
        missing = [n for n in self.report.record() if n not in have]
        if missing:
            raise SystemDefinitionError(f"the run's summary needs {', '.join(missing)} recorded; record them "
                                        f"(--record) or leave the record at its default")
        self.parts = [p.accumulator(self.parameters) for p in self.report.parts]
        self._opened_at = time.perf_counter()

    def write(self, rows: np.ndarray) -> None:
        if not len(rows):
            return
        if not self.rows:
            self.start_time = float(rows["time"][0])
        self.rows += len(rows)
        self.last_time = float(rows["time"][-1])
        for acc in self.parts:
            acc.write(rows)

    def close(self, complete: bool, stopped_at: float | None = None, reason: str = "") -> None:
        self.complete, self.stopped_at, self.reason = complete, stopped_at, reason
        if self._opened_at is not None:
            self._wall_time = time.perf_counter() - self._opened_at

    def summary(self) -> list[str]:
        return [line for acc in self.parts for line in acc.summary()]

    def finished(self) -> bool:
        """False when a part's cycle was still running, or never ran, at the last row so far."""
        return all(acc.finished() is not False for acc in self.parts)

    def metrics(self, wall_time: float | None = None) -> dict[str, float]:
        """``sim_time`` (the last row's time), ``wall_time`` (given, else from open to close), each part's
        metrics and, when a part has an alarm, ``alarms`` (how many parts raised theirs)."""
        out = {"sim_time": self.last_time, "wall_time": self._wall_time if wall_time is None else float(wall_time)}
        for acc in self.parts:
            out.update(acc.metrics())
        if any(p.alarm is not None for p in self.report.parts):
            out["alarms"] = sum(acc.alarmed for acc in self.parts)
        return out


def columns_of(data: np.ndarray) -> list[tuple[str, np.dtype]]:
    """A structured array's columns as a recording sink's ``open`` takes them."""
    assert data.dtype.names is not None, "a trajectory is a structured array"
    return [(n, data.dtype[n]) for n in data.dtype.names]


@dataclass(frozen=True)
class Report:
    """A system's summary, metrics, default record and plot: its parts in order, and its machine plane."""

    parts: tuple[Part, ...]
    plane: Plane | None = None
    #: the parameter (INSTANCE.VARIABLE) that, when > 0, starts the cycle again and again (a soak's
    #: ``panel.repeat_every``): such a run is never done, it runs to its stop time
    repeats: str = ""

    def done_signals(self) -> tuple[str, ...]:
        """The outputs that say this system's work is done (every part's with a cycle); (): none, the run goes to
        its stop time."""
        return tuple(p.done for p in self.parts if p.done is not None)

    def ends_when_done(self, parameters: Parameters) -> bool:
        """A run with ``parameters`` ends where its work ends: the system has a done signal and does not repeat."""
        if not self.done_signals():
            return False
        instance, _, name = self.repeats.partition(".")
        period = parameters.get(instance, {}).get(name) if self.repeats else None
        return period is None or not to_float(period) > 0

    @property
    def axes(self) -> tuple[str, ...]:
        return next((p.names for p in self.parts if isinstance(p, Axes)), ())

    def record(self) -> list[str]:
        """What a sweep keeps per variant by default: the axes' positions and what the metrics read."""
        axes_first = sorted(self.parts, key=lambda p: not isinstance(p, Axes))
        return list(dict.fromkeys(v for p in axes_first for v in p.variables()))

    def accumulator(self, parameters: Parameters) -> ReportAccumulator:
        """The summary and metrics of a run with ``parameters``, fed as it goes (a recording sink)."""
        return ReportAccumulator(self, parameters)

    def _fed(self, result, parameters: Parameters) -> ReportAccumulator:
        acc = self.accumulator(parameters)
        acc.open(columns_of(result.data))
        acc.write(result.data)
        acc.close(True, float(result.time[-1]) if len(result.data) else None)
        return acc

    def summary(self, result, parameters: Parameters) -> list[str]:
        return self._fed(result, parameters).summary()

    def finished(self, result, parameters: Parameters | None = None) -> bool:
        """False when a cycle of the report's parts was still running, or never ran, at the end of the run."""
        return all(p.finished(result, parameters) is not False for p in self.parts)

    def metrics(self, result, parameters: Parameters) -> dict[str, float]:
        return self._fed(result, parameters).metrics(wall_time=result.wall_time)

    def draw_time(self, ax, result) -> None:
        """Mark on a panel over time what the parts did when (see :meth:`Part.draw_time`)."""
        for p in self.parts:
            p.draw_time(ax, result)

    def draw_plane(self, ax, result, parameters: Parameters) -> None:
        assert self.plane is not None
        pl = self.plane
        for p in self.parts:
            p.draw(ax, result, parameters)
        ax.plot(result[f"{pl.horizontal}.pos"], result[f"{pl.vertical}.pos"], lw=0.8, color="tab:blue",
                label=pl.path_label)
        if pl.equal_aspect:
            ax.set_aspect("equal")
        ax.set(title=pl.title, xlabel=pl.xlabel, ylabel=pl.ylabel)
        ax.legend(loc="best", fontsize=8)
        ax.grid(True, alpha=0.3)


def generic_report(axes: Sequence[str]) -> Report:
    """The report of a system ncfmu does not define (an .ssp of the user's): its servo axes only."""
    return Report((Axes(tuple(axes)),))
