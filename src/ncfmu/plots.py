"""Plots of a run (matplotlib): axis positions, following errors and the tool path."""

from __future__ import annotations

from pathlib import Path


def plot_result(result, path: Path) -> Path:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    axes = [a for a in ("x_axis", "z_axis", "y_axis") if f"{a}.pos" in result]
    fig, (ax_pos, ax_err, ax_path) = plt.subplots(3, 1, figsize=(9, 10))
    t = result.time
    for a in axes:
        ax_pos.plot(t, result[f"{a}.pos"], label=f"{a}.pos")
        ax_err.plot(t, result[f"{a}.following_error"] * 1000, label=f"{a}.following_error")
    ax_pos.set(title=f"{result.system}: axis positions", xlabel="time [s]", ylabel="position [mm]")
    ax_err.set(title="following error", xlabel="time [s]", ylabel="error [µm]")
    if len(axes) >= 2:
        a, b = axes[1], axes[0]
        ax_path.plot(result[f"{a}.pos"], result[f"{b}.pos"], lw=0.8)
        ax_path.set(title="tool path", xlabel=f"{a.split('_')[0].upper()} [mm]", ylabel=f"{b.split('_')[0].upper()} [mm]")
    for ax in (ax_pos, ax_err):
        ax.legend(loc="best")
        ax.grid(True, alpha=0.3)
    ax_path.grid(True, alpha=0.3)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
