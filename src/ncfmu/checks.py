"""Assertion helpers for closed-loop checks over a :class:`~ncfmu.cosim.result.Result`.

Each raises ``AssertionError`` with a message that says where and by how much a check failed::

    from ncfmu.checks import assert_reaches, assert_no_motion, assert_inside_envelope, assert_alarm
    assert_reaches(r, "x_axis.pos", 25.9, band=0.002, between=(80.0, 90.0))
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .controllers.geometry import Arc, Element, Line


def _window(result, between: tuple[float, float] | None) -> np.ndarray:
    t = result.time
    if between is None:
        return np.ones(len(t), dtype=bool)
    lo, hi = between
    mask = (t >= lo) & (t <= hi)
    if not mask.any():
        raise AssertionError(f"no samples between {lo} s and {hi} s (run covers {t[0]}..{t[-1]} s)")
    return mask


def assert_reaches(result, signal: str, value: float, band: float, between: tuple[float, float] | None = None,
                   at_end: bool = False) -> float:
    """``signal`` comes within ``band`` of ``value`` (at the end of the run with ``at_end``); returns the time."""
    y, t = np.asarray(result[signal], dtype=float), result.time
    if at_end:
        if abs(y[-1] - value) > band:
            raise AssertionError(f"{signal} ends at {y[-1]:.6g}, not within {band:g} of {value:g} "
                                 f"(off by {y[-1] - value:+.3g})")
        return float(t[-1])
    mask = _window(result, between) & (np.abs(y - value) <= band)
    if not mask.any():
        w = _window(result, between)
        closest = np.argmin(np.abs(y[w] - value))
        raise AssertionError(f"{signal} never within {band:g} of {value:g}"
                             f"{'' if between is None else f' between {between[0]} and {between[1]} s'}; "
                             f"closest {y[w][closest]:.6g} at t = {t[w][closest]:.4f} s")
    return float(t[np.argmax(mask)])


def assert_no_motion(result, signal: str, between: tuple[float, float], tolerance: float = 1e-4) -> None:
    """``signal`` stays within ``tolerance`` (peak to peak) during ``between`` (a dwell, a hold)."""
    y = np.asarray(result[signal], dtype=float)[_window(result, between)]
    if np.ptp(y) > tolerance:
        raise AssertionError(f"{signal} moved {np.ptp(y):.3g} between {between[0]} and {between[1]} s "
                             f"(allowed {tolerance:g}): from {y.min():.6g} to {y.max():.6g}")


def assert_inside_envelope(result, ref: str, lim: str, table: Sequence[tuple[float, float, float]],
                           tolerance: float = 0.0) -> None:
    """The point (``ref``, ``lim``) never leaves the stepped envelope.

    ``table`` rows are ``(ref_max, lim_min, lim_max)`` in increasing ``ref_max`` (the AreaLimiter's table):
    region i allows ``lim_min <= lim <= lim_max`` for ``ref_max[i-1] < ref <= ref_max[i]``.
    """
    r, l, t = np.asarray(result[ref], float), np.asarray(result[lim], float), result.time
    bounds = np.array([row[0] for row in table])
    lows, highs = np.array([row[1] for row in table]), np.array([row[2] for row in table])
    region = np.searchsorted(bounds, r, side="left")
    outside_table = region >= len(table)
    region = np.minimum(region, len(table) - 1)
    bad = outside_table | (l > highs[region] + tolerance) | (l < lows[region] - tolerance)
    if bad.any():
        i = int(np.argmax(bad))
        raise AssertionError(f"({ref}, {lim}) = ({r[i]:.6g}, {l[i]:.6g}) leaves the envelope at t = {t[i]:.4f} s "
                             f"({int(bad.sum())} samples outside)")


def element_distance(x: np.ndarray, y: np.ndarray, element: Element) -> np.ndarray:
    """Exact distance of each point (x, y) from a line segment or an arc."""
    px, py = np.asarray(x, float), np.asarray(y, float)
    if isinstance(element, Line):
        a, b = np.asarray(element.start), np.asarray(element.end)
        d = b - a
        s = np.clip(((px - a[0]) * d[0] + (py - a[1]) * d[1]) / (d @ d), 0.0, 1.0)
        return np.hypot(px - a[0] - s * d[0], py - a[1] - s * d[1])
    cx, cy = element.center
    # within the arc's angular range the nearest point is radial, else an end point
    turn = np.arctan2(py - cy, px - cx) - element.a0
    along = np.mod(turn if element.sweep > 0 else -turn, 2 * np.pi)
    radial = np.abs(np.hypot(px - cx, py - cy) - element.radius)
    (sx, sy), (ex, ey) = element.start, element.end
    ends = np.minimum(np.hypot(px - sx, py - sy), np.hypot(px - ex, py - ey))
    return np.where(along <= abs(element.sweep), radial, ends)


def path_distance(x: np.ndarray, y: np.ndarray, path: Sequence[Element] | Sequence[tuple[float, float]]) -> np.ndarray:
    """Distance of each point (x, y) from a path: lines and arcs (e.g. a contour's ``tool_path`` elements),
    or a polyline given as points."""
    elements: list[Element] = [e for e in path if isinstance(e, Line | Arc)]
    if len(elements) < len(path):                                   # a polyline's points
        points = [(float(p[0]), float(p[1])) for p in path if not isinstance(p, Line | Arc)]
        elements = [Line(a, b) for a, b in zip(points[:-1], points[1:])]
    best = np.full(np.shape(x), np.inf)
    for element in elements:
        best = np.minimum(best, element_distance(x, y, element))
    return best


def assert_on_path(result, x: str, y: str, path: Sequence[Element] | Sequence[tuple[float, float]],
                   tolerance: float, between: tuple[float, float] | None = None) -> float:
    """The point (``x``, ``y``) stays within ``tolerance`` of ``path`` (lines and arcs, or a polyline's points);
    returns the largest distance."""
    w = _window(result, between)
    dist = path_distance(result[x][w], result[y][w], path)
    worst = float(dist.max()) if len(dist) else 0.0
    if worst > tolerance:
        i = int(np.argmax(dist))
        raise AssertionError(f"({x}, {y}) is {worst * 1000:.1f} µm from the path at t = {result.time[w][i]:.4f} s "
                             f"(allowed {tolerance * 1000:.1f} µm)")
    return worst


def assert_alarm(result, signal: str, raised: bool = True, between: tuple[float, float] | None = None) -> None:
    """``signal`` (a Boolean or a nonzero Integer) is raised at least once -- or never, with ``raised=False``."""
    y = np.asarray(result[signal])[_window(result, between)]
    t = result.time[_window(result, between)]
    on = y.astype(bool)
    if raised and not on.any():
        raise AssertionError(f"{signal} was never raised" + ("" if between is None else f" between {between}"))
    if not raised and on.any():
        raise AssertionError(f"{signal} was raised at t = {t[np.argmax(on)]:.4f} s")
