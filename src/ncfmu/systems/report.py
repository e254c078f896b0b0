"""What a run of a system says: its summary lines, its metrics and its plot, from named instances.

A system's :class:`Report` is a tuple of parts, each bound to the instance names of its definition
(``LatheCycle(seq="seq", x="x_axis", z="z_axis")``): the CLI's summary, a sweep's metrics and recorded
variables, and the plot in the machine plane all come from it. Nothing here recognises a system by the
columns of its result. A part reads the parameters the run actually used (``Result.parameters``: the
system's parameter sets with every ``--set`` applied), so a plot or a metric of a run with ``--set`` is
that run's.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..controllers.base import POSITION_LIMIT
from ..ports import to_float, to_int

Parameters = Mapping[str, Mapping[str, object]]      # instance -> parameter -> value


def _first_time(result, mask: np.ndarray) -> float:
    return float(result.time[np.argmax(mask)]) if mask.any() else float("nan")


def _ended(result, active: np.ndarray) -> float:
    """Time the last active stretch ended; NaN when it never ran or still runs."""
    return float(result.time[np.flatnonzero(active)[-1] + 1]) if active.any() and not active[-1] else float("nan")


def table_of(parameters: Mapping[str, object]) -> list[tuple[float, float, float]]:
    """An AreaLimiter's limit table ``(ref_max, lim_min, lim_max)`` from its parameters."""
    n = to_int(parameters.get("n_regions", 0))
    return [(to_float(parameters[f"region[{i}].ref_max"]), to_float(parameters[f"region[{i}].lim_min"]),
             to_float(parameters[f"region[{i}].lim_max"])) for i in range(1, n + 1)]


class Part:
    """One instance's (or a few instances') share of a report; every method has a neutral default."""

    def variables(self) -> tuple[str, ...]:
        """The recorded variables the part reads (a sweep records them by default)."""
        return ()

    def summary(self, result, parameters: Parameters) -> list[str]:
        return []

    def metrics(self, result, parameters: Parameters) -> dict[str, float]:
        return {}

    @property
    def alarm(self) -> str | None:
        """The part's alarm output, if it has one."""
        return None

    def alarmed(self, result) -> bool:
        return self.alarm is not None and bool(result[self.alarm].any())

    def finished(self, result) -> bool | None:
        """Whether the part's cycle ran to its end within the run; None for a part without a cycle."""
        return None

    def draw(self, ax, result, parameters: Parameters) -> None:
        """Add to the machine-plane panel (path, envelope, contour)."""


@dataclass(frozen=True)
class Axes(Part):
    """The servo axes: following errors."""

    names: tuple[str, ...]

    def variables(self) -> tuple[str, ...]:
        return tuple(f"{a}.{v}" for a in self.names for v in ("pos", "following_error"))

    def summary(self, result, parameters: Parameters) -> list[str]:
        return [f"  {a}: max |following error| {abs(result[f'{a}.following_error']).max() * 1000:.2f} um"
                for a in self.names]

    def metrics(self, result, parameters: Parameters) -> dict[str, float]:
        if not self.names:
            return {}
        return {"max_following_error_mm": float(max(abs(result[f"{a}.following_error"]).max() for a in self.names))}


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
        return tuple(f"{self.seq}.{v}" for v in ("subcycle", "done", "alarm"))

    @property
    def alarm(self) -> str | None:
        return f"{self.seq}.alarm"

    def summary(self, result, parameters: Parameters) -> list[str]:
        sub, x, z = result[f"{self.seq}.subcycle"], result[f"{self.x}.pos"], result[f"{self.z}.pos"]
        cut = sub == 2
        starts = np.flatnonzero((sub[1:] == 2) & (sub[:-1] != 2)) + 1
        lines = [f"  cuts (SC2): {len(starts)}"]
        if cut.any():
            lines.append("  X at the start of each cut [mm]: " + ", ".join(f"{x[i]:.4f}" for i in starts))
            lines.append(f"  smallest X during the cuts: {x[cut].min():.4f} mm; Z reached {z[cut].min():.4f} mm")
        done = result[f"{self.seq}.done"]
        end = f"{result.time[done.argmax()]:.3f} s" if done.any() else "not finished"
        lines.append(f"  cycle done: {end}; tool at X {x[-1]:.4f}, Z {z[-1]:.4f} mm; "
                     f"alarm: {'yes' if self.alarmed(result) else 'no'}")
        return lines

    def finished(self, result) -> bool | None:
        return bool(result[f"{self.seq}.done"].any())

    def metrics(self, result, parameters: Parameters) -> dict[str, float]:
        cut = result[f"{self.seq}.subcycle"] == 2
        return {"final_radius_mm": float(result[f"{self.x}.pos"][cut].min()) if cut.any() else float("nan"),
                "cycle_time_s": _first_time(result, result[f"{self.seq}.done"])}

    def draw(self, ax, result, parameters: Parameters) -> None:
        seq = parameters.get(self.seq, {})
        if "x_start" in seq and "block[1].Xf" in seq:
            stock = to_float(seq["x_start"]) - to_float(seq["block[1].Xf"])
            ax.axhline(stock, color="0.5", ls=":", lw=0.8, label=f"stock outline X = {stock:g}")
            x = result[f"{self.x}.pos"]
            ax.set_ylim(min(x.min(), stock) - 1, max(x.max(), to_float(seq["x_start"])) + 2)


@dataclass(frozen=True)
class FeedCycle(Part):
    """A ProgrammableFeed infeeding the axis ``x``."""

    feed: str
    x: str

    def variables(self) -> tuple[str, ...]:
        return tuple(f"{self.feed}.{v}" for v in ("pc", "run", "emergency_active", "alarm", "return_counter_x"))

    @property
    def alarm(self) -> str | None:
        return f"{self.feed}.alarm"

    def _active(self, result) -> np.ndarray:
        return result[f"{self.feed}.run"] | result[f"{self.feed}.emergency_active"]

    def summary(self, result, parameters: Parameters) -> list[str]:
        x, end = result[f"{self.x}.pos"], _ended(result, self._active(result))
        return [f"  deepest X: {x.max():.4f} mm; cycle ended: {'not finished' if np.isnan(end) else f'{end:.3f} s'}; "
                f"X at the end {x[-1]:.4f} mm; return counter X {result[f'{self.feed}.return_counter_x'][-1]:.4f} mm",
                f"  alarm: {'yes' if self.alarmed(result) else 'no'}"]

    def finished(self, result) -> bool | None:
        return not np.isnan(_ended(result, self._active(result)))

    def metrics(self, result, parameters: Parameters) -> dict[str, float]:
        return {"deepest_x_mm": float(result[f"{self.x}.pos"].max()),
                "cycle_time_s": _ended(result, self._active(result))}


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


@dataclass(frozen=True)
class ContourCycle(Part):
    """A ContourInterpolator on the axes ``x`` and ``y``: the programmed and the corrected contour."""

    contour: str
    x: str
    y: str

    def variables(self) -> tuple[str, ...]:
        return tuple(f"{self.contour}.{v}" for v in ("segment", "done", "alarm"))

    @property
    def alarm(self) -> str | None:
        return f"{self.contour}.alarm"

    def interpolator(self, parameters: Parameters):
        """The interpolator the run used (its tool path and contour), from the run's parameters."""
        from ..controllers.contour import ContourInterpolator
        return ContourInterpolator(**parameters.get(self.contour, {}))

    def summary(self, result, parameters: Parameters) -> list[str]:
        done = result[f"{self.contour}.done"]
        end = f"{result.time[done.argmax()]:.3f} s" if done.any() else "not finished"
        return [f"  contour done: {end}; last segment (point path) or program line: "
                f"{int(result[f'{self.contour}.segment'][-1])}; alarm: {'yes' if self.alarmed(result) else 'no'}"]

    def finished(self, result) -> bool | None:
        return bool(result[f"{self.contour}.done"].any())

    def metrics(self, result, parameters: Parameters) -> dict[str, float]:
        from ..checks import path_distance
        path = [move.element for move in self.interpolator(parameters).tool_path]
        on = result[f"{self.contour}.segment"] >= 1
        best = path_distance(result[f"{self.x}.pos"][on], result[f"{self.y}.pos"][on], path)
        return {"max_contour_error_mm": float(best.max()) if len(best) else float("nan"),
                "cycle_time_s": _first_time(result, result[f"{self.contour}.done"])}

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


@dataclass(frozen=True)
class Report:
    """A system's summary, metrics, default record and plot: its parts in order, and its machine plane."""

    parts: tuple[Part, ...]
    plane: Plane | None = None

    @property
    def axes(self) -> tuple[str, ...]:
        return next((p.names for p in self.parts if isinstance(p, Axes)), ())

    def record(self) -> list[str]:
        """What a sweep keeps per variant by default: the axes' positions and what the metrics read."""
        axes_first = sorted(self.parts, key=lambda p: not isinstance(p, Axes))
        return list(dict.fromkeys(v for p in axes_first for v in p.variables()))

    def summary(self, result, parameters: Parameters) -> list[str]:
        return [line for p in self.parts for line in p.summary(result, parameters)]

    def finished(self, result) -> bool:
        """False when a cycle of the report's parts was still running, or never ran, at the end of the run."""
        return all(p.finished(result) is not False for p in self.parts)

    def metrics(self, result, parameters: Parameters) -> dict[str, float]:
        out = {"sim_time": float(result.time[-1]), "wall_time": float(result.wall_time)}
        for p in self.parts:
            out.update(p.metrics(result, parameters))
        if any(p.alarm is not None for p in self.parts):
            out["alarms"] = sum(p.alarmed(result) for p in self.parts)
        return out

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
