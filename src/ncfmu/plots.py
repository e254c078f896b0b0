"""Plots of runs and sweeps (matplotlib, written as PNG).

- :func:`plot_result`: axis positions and commands, following errors, and the tool path in the machine
  plane the system's report names, with its envelope or contour (lathe X-Z with the chuck zone, grinder
  Y-X with its four regions, mill X-Y with the programmed and the corrected contour).
- :func:`plot_sweep`: a sweep's summary metrics against the varied value.
"""

from __future__ import annotations

import csv
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
