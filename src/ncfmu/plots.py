"""Plots of runs and sweeps (matplotlib, written as PNG).

- :func:`plot_result`: axis positions and commands, following errors, and the tool path in the machine
  plane the system's report names, with its envelope or contour (lathe X-Z with the chuck zone, grinder
  Y-X with its four regions, mill X-Y with the programmed and the corrected contour).
- :func:`plot_sweep`: a sweep's summary metrics against the varied value.
- :func:`plot_signals`: a result of no known system (a single FMU's, a CSV fmpy wrote): its signals over time.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def plot_result(result, path: Path) -> Path:
    """Plot a run: positions, following errors and, for a system with a machine plane, the path in it with
    the envelope or the contour of the parameters the run used (see :func:`ncfmu.systems.run_parameters`)."""
    from .systems import report_of, run_parameters
    plt = _plt()
    report = report_of(result)
    axes = [a for a in report.axes if f"{a}.pos" in result]
    # the plane needs both of its axes' positions (a sweep's --record may have kept fewer)
    has_plane = report.plane is not None and all(f"{a}.pos" in result for a in (report.plane.horizontal,
                                                                                  report.plane.vertical))
    fig, panels = plt.subplots(3 if has_plane else 2, 1, figsize=(10, 12 if has_plane else 8))
    ax_pos, ax_err = panels[0], panels[1]
    t = result.time
    for a in axes:
        line, = ax_pos.plot(t, result[f"{a}.pos"], label=f"{a}.pos (actual)")
        if f"{a}.following_error" in result:
            ax_pos.plot(t, result[f"{a}.pos"] + result[f"{a}.following_error"], "--", lw=0.8,
                        color=line.get_color(), label=f"{a} command")
            ax_err.plot(t, result[f"{a}.following_error"] * 1000, label=f"{a}")
    ax_pos.set(title=f"{result.system}: axis positions", xlabel="time [s]", ylabel="position [mm]")
    ax_err.set(title="following error (command - actual)", xlabel="time [s]", ylabel="error [µm]")
    for ax in (ax_pos, ax_err):
        ax.legend(loc="best", fontsize=8)
        ax.grid(True, alpha=0.3)
    if has_plane:
        report.draw_plane(panels[2], result, run_parameters(result))
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def plot_sweep(summary_csv: Path, path: Path) -> Path:
    """Each numeric metric of a sweep's summary against the first varied parameter."""
    plt = _plt()
    with open(summary_csv, newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        raise ValueError(f"{summary_csv} has no rows")
    columns = list(rows[0])
    varied = columns[1:columns.index("status")]
    metrics = [c for c in columns[columns.index("error") + 1:] if c not in ("wall_time", "sim_time")]
    ok = [r for r in rows if r["status"] == "ok"]

    def finite(metric):
        try:
            return any(np.isfinite(float(r[metric])) for r in ok)
        except ValueError:
            return False
    metrics = [m for m in metrics if finite(m)]
    x_name = varied[0]
    fig, axes = plt.subplots(len(metrics), 1, figsize=(8, 2.6 * max(1, len(metrics))), squeeze=False)
    for ax, metric in zip(axes[:, 0], metrics):
        groups: dict[str, list[tuple[float, float]]] = {}
        for r in ok:
            label = ", ".join(f"{v}={r[v]}" for v in varied[1:]) or metric
            try:
                groups.setdefault(label, []).append((float(r[x_name]), float(r[metric])))
            except ValueError:
                continue
        for label, pts in groups.items():
            pts.sort()
            ax.plot([p[0] for p in pts], [p[1] for p in pts], "o-", label=label)
        failed = [float(r[x_name]) for r in rows if r["status"] != "ok"]
        for xf in failed:
            ax.axvline(xf, color="tab:red", ls=":", lw=1)
        ax.set(xlabel=x_name, ylabel=metric)
        ax.grid(True, alpha=0.3)
        if len(groups) > 1:
            ax.legend(fontsize=7)
    axes[0, 0].set_title(f"sweep {Path(summary_csv).parent.name}: {len(ok)} ok, {len(rows) - len(ok)} failed "
                         "(red: failed variants)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return Path(path)


# -- a result of no known system: a single FMU's, or a CSV another tool wrote --------------------------
#: changing numeric signals drawn at most; the title says how many more the file has
MAX_SIGNAL_PANELS = 24


@dataclass
class SignalPanels:
    """How :func:`plot_signals` lays out a result."""

    numbers: list[str]                  # numbers that change: a panel each, in the file's order
    booleans: list[str]                 # Booleans: together on one panel, as logic traces
    constant: dict[str, float]          # numbers that never change: listed with their value, not drawn


def signal_panels(result) -> SignalPanels:
    panels = SignalPanels([], [], {})
    for name in result.names:
        column = result[name]
        if column.dtype == np.bool_:
            panels.booleans.append(name)
        elif np.array_equal(column, np.full_like(column, column[0]), equal_nan=True):
            panels.constant[name] = float(column[0])
        else:
            panels.numbers.append(name)
    return panels


def plot_signals(result, path: Path) -> Path:
    """Every recorded signal over time, for a result that names no system ncfmu knows (a single FMU run by
    fmpy, another tool's CSV): each changing number on a panel of its own (whole-numbered ones as steps), the
    Booleans as logic traces on one panel, the constant numbers listed with their values."""
    import textwrap
    plt = _plt()
    panels = signal_panels(result)
    drawn = panels.numbers[:MAX_SIGNAL_PANELS]
    rows = max(1, len(drawn) + bool(panels.booleans))
    logic_height = 0.45 * len(panels.booleans) + 0.6
    heights = [1.0] * len(drawn) + ([logic_height / 1.9] if panels.booleans else [])
    listed = ", ".join(f"{name} = {value:g}" for name, value in panels.constant.items())
    note = textwrap.fill(f"constant over the run: {listed}", 140) if listed else ""
    note_height = 0.2 + 0.16 * (note.count("\n") + 1) if note else 0.0          # inches under the panels
    height = 1.9 * sum(heights or [1.0]) + 1.0 + note_height
    fig, axes = plt.subplots(rows, 1, figsize=(10, height), sharex=True, squeeze=False,
                             gridspec_kw={"height_ratios": heights or [1.0]})
    t = result.time
    for ax, name in zip(axes[:, 0], drawn):
        values = result[name]
        whole = bool(np.all(np.isfinite(values) & (values == np.round(values))))
        ax.plot(t, values, lw=1.0, drawstyle="steps-post" if whole else "default")
        ax.set_title(name, loc="left", fontsize=9)
        ax.grid(True, alpha=0.3)
    if panels.booleans:
        ax = axes[len(drawn), 0]
        for i, name in enumerate(panels.booleans):
            color = f"C{i % 10}"
            ax.fill_between(t, i, i + 0.7 * result[name], step="post", alpha=0.4, color=color, lw=0)
            ax.step(t, i + 0.7 * result[name], where="post", lw=1.0, color=color)
        ax.set_yticks([i + 0.35 for i in range(len(panels.booleans))], panels.booleans, fontsize=8)
        ax.set_ylim(-0.2, len(panels.booleans))
        ax.set_title("Booleans (raised: true)", loc="left", fontsize=9)
        ax.grid(True, axis="x", alpha=0.3)
    axes[-1, 0].set_xlabel("time [s]")
    title = f"{result.system or 'result'}: recorded signals over {t[0]:g}..{t[-1]:g} s"
    if len(panels.numbers) > len(drawn):
        title += f" (the first {len(drawn)} of {len(panels.numbers)} changing numbers)"
    fig.suptitle(title)
    if note:
        fig.text(0.01, 0.1 / height, note, fontsize=8, va="bottom")
    fig.tight_layout(rect=(0, note_height / height, 1, 1))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
