"""Plots of runs and sweeps (matplotlib, written as PNG).

- :func:`plot_result`: axis positions and commands, following errors, and the tool path in the machine
  plane with the system's envelope (lathe X-Z with the chuck zone, grinder Y-X with its four regions,
  mill X-Y with the programmed and the corrected contour).
- :func:`plot_sweep`: a sweep's summary metrics against the varied value.
"""

from __future__ import annotations

import csv
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from .ports import to_float, to_int


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _system_parameters(system: str) -> dict[str, dict[str, object]]:
    from .systems import SYSTEMS, get_system
    if system not in SYSTEMS:
        return {}
    return {c.name: dict(c.parameters) for c in get_system(system).components}


def _table(params: Mapping[str, object]) -> list[tuple[float, float, float]]:
    n = to_int(params.get("n_regions", 0))
    return [(to_float(params[f"region[{i}].ref_max"]), to_float(params[f"region[{i}].lim_min"]),
             to_float(params[f"region[{i}].lim_max"])) for i in range(1, n + 1)]


def _commands(result, axis: str) -> str | None:
    for src in ("limiter", "seq", "feed", "contour"):
        port = "lim_cmd" if src == "limiter" and axis == "x" else "ref_cmd" if src == "limiter" else axis + "_cmd"
        name = f"{src}.{port}"
        if name in result:
            return name
    return None


def plot_result(result, path: Path, system: str | None = None,
                start_values: Mapping[str, object] | None = None) -> Path:
    """Plot a run; ``start_values`` (``INSTANCE.VARIABLE``: value, e.g. ``--set``) override the system's
    parameters, so the envelope or the contour drawn is the one that ran."""
    plt = _plt()
    system = system or result.system
    params = _system_parameters(system)
    for name, value in (start_values or {}).items():
        instance, _, variable = name.partition(".")
        if instance in params:
            params[instance][variable] = value
    axes = [a for a in ("x_axis", "z_axis", "y_axis") if f"{a}.pos" in result]
    has_plane = len(axes) >= 2
    fig, panels = plt.subplots(3 if has_plane else 2, 1, figsize=(10, 12 if has_plane else 8))
    ax_pos, ax_err = panels[0], panels[1]
    t = result.time
    for a in axes:
        line, = ax_pos.plot(t, result[f"{a}.pos"], label=f"{a}.pos (actual)")
        if f"{a}.pos" in result and f"{a}.following_error" in result:
            ax_pos.plot(t, result[f"{a}.pos"] + result[f"{a}.following_error"], "--", lw=0.8,
                        color=line.get_color(), label=f"{a} command")
        ax_err.plot(t, result[f"{a}.following_error"] * 1000, label=f"{a}")
    ax_pos.set(title=f"{system}: axis positions", xlabel="time [s]", ylabel="position [mm]")
    ax_err.set(title="following error (command - actual)", xlabel="time [s]", ylabel="error [µm]")
    for ax in (ax_pos, ax_err):
        ax.legend(loc="best", fontsize=8)
        ax.grid(True, alpha=0.3)
    if has_plane:
        _plane(panels[2], result, system, params)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def _plane(ax, result, system: str, params: dict) -> None:
    if "z_axis.pos" in result:                                   # lathe: Z horizontal, X (radius) vertical
        z, x = result["z_axis.pos"], result["x_axis.pos"]
        ax.plot(z, x, lw=0.8, label="tool (actual)")
        table = _table(params.get("limiter", {}))
        if table:
            left = min(z.min(), table[0][0]) - 5
            ax.fill_between([left, table[0][0]], table[0][1], 0, color="tab:red", alpha=0.2,
                            label=f"forbidden: X < {table[0][1]:g} for Z <= {table[0][0]:g} (chuck)")
            ax.axvline(table[0][0], color="tab:red", lw=0.8)
        seq = params.get("seq", {})
        if seq:
            stock = float(seq.get("x_start", 30.0)) - float(seq.get("block[1].Xf", 1.0))
            ax.axhline(stock, color="0.5", ls=":", lw=0.8, label=f"stock outline X = {stock:g}")
        ax.set(title="tool path in the X-Z plane", xlabel="Z [mm]", ylabel="X (radius) [mm]")
        ax.set_ylim(min(x.min(), 20) - 1, max(x.max(), 30) + 2)
    elif "contour.segment" in result:                            # mill: X-Y
        from .controllers.contour import ContourInterpolator
        comp = params.get("contour", {})
        c = ContourInterpolator(**comp) if comp else None
        if c is not None:
            from .controllers.geometry import sample
            prog = np.array(sample(c.contour, 0.2))
            ax.plot(prog[:, 0], prog[:, 1], "k-", lw=1.0, label="programmed contour")
            cor = np.array(sample([m.element for m in c.tool_path], 0.05))
            ax.plot(cor[:, 0], cor[:, 1], "g--", lw=1.0, label=f"corrected ({c.diameter_delta:+g} mm diameter)")
        ax.plot(result["x_axis.pos"], result["y_axis.pos"], lw=0.6, color="tab:blue", label="cutter centre (actual)")
        ax.set_aspect("equal")
        ax.set(title="contour in the X-Y plane", xlabel="X [mm]", ylabel="Y [mm]")
        if c is not None:
            # the correction is a fraction of a millimetre: zoom on the corner farthest from the origin
            cx, cy = max((e.start for e in c.contour), key=lambda p: p[0] + p[1])
            zoom = ax.inset_axes([1.05, 0.05, 0.6, 0.9])
            zoom.plot(prog[:, 0], prog[:, 1], "k-", lw=1.0)
            zoom.plot(cor[:, 0], cor[:, 1], "g--", lw=1.0)
            zoom.plot(result["x_axis.pos"], result["y_axis.pos"], lw=0.8, color="tab:blue")
            span = max(1.0, 1.5 * abs(c.diameter_delta))
            zoom.set_xlim(cx - span, cx + 0.6 * span)
            zoom.set_ylim(cy - span, cy + 0.6 * span)
            zoom.set_aspect("equal")
            zoom.set_title(f"corner ({cx:g}, {cy:g}) [mm]", fontsize=8)
            zoom.grid(True, alpha=0.3)
    else:                                                        # grinder envelope: Y (table) horizontal
        y, x = result["y_axis.pos"], result["x_axis.pos"]
        table = _table(params.get("limiter", {}))
        if table:
            names = ["dresser", "headstock", "work", "tailstock"]
            left = min(y.min(), 0.0)
            top = max(max(h for _, _, h in table), x.max()) + 50
            for i, (ref_max, _lo, hi) in enumerate(table):
                ax.fill_between([left, ref_max], hi, top, color="tab:red", alpha=0.15,
                                label="forbidden" if i == 0 else None)
                ax.hlines(hi, left, ref_max, color="tab:red", lw=1)
                ax.text((left + ref_max) / 2, hi + 5, names[i] if i < len(names) else f"region {i + 1}",
                        ha="center", fontsize=8)
                left = ref_max
        ax.plot(y, x, lw=1.0, label="wheel (actual)")
        ax.set(title="wheel path in the Y-X plane with the limit envelope", xlabel="Y (table) [mm]",
               ylabel="X (infeed) [mm]")
    ax.legend(loc="best", fontsize=8)
    ax.grid(True, alpha=0.3)


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
