"""The drives' open loops in the frequency domain -- the servo axis's velocity and position loops, the spindle's
speed loop: the band that matters and the margins (python-control), and their Bode plots for the FMU documentation.
Design, not run time: the native FMUs never run this."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def _pyplot():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


# -- the servo axis's loops ------------------------------------------------------------------------
@dataclass(frozen=True)
class LoopMargins:
    """One open loop's margins as python-control's ``margin`` gives them (gain margin as a factor, inf when the
    phase never reaches -180 deg; frequencies in rad/s, NaN where there is no such crossing)."""

    name: str
    gain_margin: float
    phase_margin: float
    phase_crossover: float          # where the phase is -180 deg: the gain margin is read there
    gain_crossover: float           # where the gain is 1: the phase margin is read there

    def gain_margin_text(self) -> str:
        if not np.isfinite(self.gain_margin):
            return "GM infinite (the phase never reaches -180 deg)"
        return f"GM {20 * np.log10(self.gain_margin):.1f} dB at {self.phase_crossover:.0f} rad/s"

    def phase_margin_text(self) -> str:
        return f"PM {self.phase_margin:.1f} deg at {self.gain_crossover:.1f} rad/s"


@dataclass(frozen=True)
class Bode:
    """What the servo axis's Bode plot shows: the band (rad/s) and each loop's margins."""

    band: tuple[float, float]
    loops: tuple[LoopMargins, ...]


def bode_design(p=None) -> Bode:
    """The band that matters for the axis ``p`` (default: the ServoAxis's defaults) -- a decade below the
    position loop's closed-loop bandwidth to a decade above the current loop's (1/tau_current) -- and the
    margins of the open velocity and position loops (:mod:`ncfmu.servo.model`)."""
    import control as ct

    from .model import AxisParameters, design, position_loop, velocity_loop
    p = AxisParameters() if p is None else p
    d = design(p)
    low = (d.position_bandwidth if np.isfinite(d.position_bandwidth) else d.position_crossover) / 10.0
    band = (low, 10.0 / p.tau_current)
    loops = []
    for loop in (velocity_loop(p), position_loop(p)):
        gm, pm, w180, wc = (float(v) for v in ct.margin(loop))
        loops.append(LoopMargins(loop.name, gm, pm, w180, wc))
    return Bode(band, tuple(loops))


#: a margin's label stays readable where it crosses a curve
_ON_WHITE = {"boxstyle": "square,pad=0.15", "facecolor": "white", "edgecolor": "none", "alpha": 0.85}


def _draw_loop(ax_mag, ax_ph, loop, margins: LoopMargins, colour: str, w: np.ndarray) -> None:
    """One open loop's magnitude and phase over ``w``, its gain and phase margins drawn where they are read."""
    import control as ct
    response = ct.frequency_response(loop, w)
    h = np.asarray(response.complex).reshape(-1)
    mag_db, phase = 20 * np.log10(np.abs(h)), np.degrees(np.unwrap(np.angle(h)))
    # unwrap starts where numpy's angle does; a loop with an integrator starts near -90 deg
    phase -= 360.0 * np.round((phase[0] + 90.0) / 360.0)
    label = f"{loop.name}: {margins.phase_margin_text()}; {margins.gain_margin_text()}"
    ax_mag.semilogx(w, mag_db, color=colour, label=label)
    ax_ph.semilogx(w, phase, color=colour)
    wc = margins.gain_crossover
    ax_mag.axvline(wc, color=colour, ls=":", lw=0.8)
    ax_ph.axvline(wc, color=colour, ls=":", lw=0.8)
    ax_ph.vlines(wc, -180.0, -180.0 + margins.phase_margin, color=colour, lw=2.5)
    ax_ph.annotate(f"PM {margins.phase_margin:.1f}°", (wc, -180.0 + margins.phase_margin / 2), xytext=(6, 0),
                   textcoords="offset points", color=colour, fontsize=8, va="center", bbox=_ON_WHITE)
    if np.isfinite(margins.gain_margin):
        w180, gm_db = margins.phase_crossover, 20 * np.log10(margins.gain_margin)
        ax_mag.axvline(w180, color=colour, ls="--", lw=0.8)
        ax_ph.axvline(w180, color=colour, ls="--", lw=0.8)
        ax_mag.vlines(w180, -gm_db, 0.0, color=colour, lw=2.5)
        ax_mag.annotate(f"GM {gm_db:.1f} dB", (w180, -gm_db / 2), xytext=(6, 0), textcoords="offset points",
                        color=colour, fontsize=8, va="center", bbox=_ON_WHITE)


def _finish(fig, ax_mag, ax_ph, tau_current: float, band: tuple[float, float], title: str) -> None:
    """The axes' grid, the 0 dB and -180 deg lines, the current loop's corner 1/tau_current, labels."""
    for ax in (ax_mag, ax_ph):
        ax.axvline(1.0 / tau_current, color="0.4", ls="-.", lw=0.8)
        ax.grid(True, which="both", alpha=0.3)
    ax_mag.axhline(0.0, color="k", lw=0.8)
    ax_ph.axhline(-180.0, color="k", lw=0.8)
    ax_mag.text(1.0 / tau_current, 0.97, " current loop 1/tau", transform=ax_mag.get_xaxis_transform(),
                fontsize=8, color="0.4", va="top")
    ax_mag.set(ylabel="magnitude [dB]", title=title)
    ax_ph.set(ylabel="phase [deg]", xlabel="frequency [rad/s]", xlim=band)
    ax_ph.set_yticks(np.arange(-270, -44, 45))
    ax_mag.legend(fontsize=8, loc="lower left")
    fig.tight_layout()


def bode_figure(p=None):
    """The Bode plot of the open velocity and position loops over :func:`bode_design`'s band: magnitude in
    dB, phase in degrees, each loop's gain and phase margin drawn where they are read (an infinite gain margin
    is said in words), the current loop's corner 1/tau_current marked. Returns ``(figure, Bode)``."""
    from .model import AxisParameters, position_loop, velocity_loop
    plt = _pyplot()
    p = AxisParameters() if p is None else p
    info = bode_design(p)
    w = np.logspace(np.log10(info.band[0]), np.log10(info.band[1]), 1000)
    fig, (ax_mag, ax_ph) = plt.subplots(2, 1, figsize=(8, 7), sharex=True)
    for loop, margins, colour in zip((velocity_loop(p), position_loop(p)), info.loops, ("C0", "C1")):
        _draw_loop(ax_mag, ax_ph, loop, margins, colour, w)
    _finish(fig, ax_mag, ax_ph, p.tau_current, info.band, "ServoAxis open loops (default parameters)")
    return fig, info


# -- the spindle's speed loop ----------------------------------------------------------------------
def spindle_bode_design(p=None) -> Bode:
    """The band that matters for the spindle ``p`` (default: the SpindleDrive's defaults) -- a decade below the
    PI zero (speed_bandwidth / 4) to a decade above the current loop's corner -- and the speed loop's margins
    (:mod:`ncfmu.servo.spindle_model`)."""
    import control as ct

    from .spindle_model import SpindleParameters, speed_loop
    p = SpindleParameters() if p is None else p
    loop = speed_loop(p)
    gm, pm, w180, wc = (float(v) for v in ct.margin(loop))
    return Bode((p.speed_bandwidth / 40.0, 10.0 / p.tau_current), (LoopMargins(loop.name, gm, pm, w180, wc),))


def spindle_bode_figure(p=None):
    """The Bode plot of the spindle's open speed loop over :func:`spindle_bode_design`'s band, drawn as
    :func:`bode_figure` draws the feed axis's loops. Returns ``(figure, Bode)``."""
    from .spindle_model import SpindleParameters, speed_loop
    plt = _pyplot()
    p = SpindleParameters() if p is None else p
    info = spindle_bode_design(p)
    w = np.logspace(np.log10(info.band[0]), np.log10(info.band[1]), 1000)
    fig, (ax_mag, ax_ph) = plt.subplots(2, 1, figsize=(8, 7), sharex=True)
    _draw_loop(ax_mag, ax_ph, speed_loop(p), info.loops[0], "C0", w)
    _finish(fig, ax_mag, ax_ph, p.tau_current, info.band, "SpindleDrive open speed loop (default parameters)")
    return fig, info
