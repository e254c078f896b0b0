"""Physics checks of each system over a Result, shared by ncfmu's master and libcosim runs.

They use Real and Integer signals only (libcosim's time-series observer samples no Booleans).
"""

from __future__ import annotations

import numpy as np
import pytest

from ncfmu.checks import assert_inside_envelope, assert_no_motion, assert_reaches, path_distance

BAND = 0.005
X0, Z0 = 30.0, 2.0


def intervals(values: np.ndarray, what: int) -> list[tuple[int, int]]:
    """[start, end) index ranges where ``values == what``."""
    on = np.concatenate([[0], (values == what).astype(int), [0]])
    edges = np.flatnonzero(np.diff(on))
    return list(zip(edges[::2], edges[1::2]))


def check_lathe_roughing(r) -> None:
    cuts = intervals(r["seq.subcycle"], 2)
    assert len(cuts) == 7
    expected = [X0 - (1.0 + n * 0.5) for n in range(1, 7)] + [X0 - (4.0 + 0.1)]
    for (a, b), x_target in zip(cuts, expected):
        x = r["x_axis.pos"][a:b]
        assert np.abs(x - x_target).max() <= 0.002, (x_target, np.abs(x - x_target).max())
        assert abs(r["z_axis.pos"][b - 1] - (Z0 - 42.0)) <= BAND
    assert expected[-1] == pytest.approx(25.9)
    assert_reaches(r, "x_axis.pos", X0, BAND, at_end=True)
    assert_reaches(r, "z_axis.pos", Z0, BAND, at_end=True)
    assert r["seq.subcycle"][-1] == 0 and r["seq.block_no"].max() == 2
    assert r["limiter.blocked"].max() == 0
    assert r["x_axis.pos"][r["seq.subcycle"] == 4].min() > 29.0      # returns clear of the stock


def check_lathe_taper(r) -> None:
    cuts = intervals(r["seq.subcycle"], 2)
    assert len(cuts) == 4
    for n, (a, b) in enumerate(cuts, start=1):
        sigma = 1.0 + n * 0.5
        x, z = r["x_axis.pos"][a:b], r["z_axis.pos"][a:b]
        p0, p1 = np.array([X0 - sigma, Z0]), np.array([X0 - sigma - 1.5, Z0 - 42.0])
        d = (p1 - p0) / np.linalg.norm(p1 - p0)
        dist = (x - p0[0]) * -d[1] + (z - p0[1]) * d[0]
        assert np.abs(dist).max() <= 0.002, (n, np.abs(dist).max())
        assert abs(x[-1] - p1[0]) <= BAND and abs(z[-1] - p1[1]) <= BAND
    assert abs(r["x_axis.pos"][-1] - X0) <= BAND and abs(r["z_axis.pos"][-1] - Z0) <= BAND
    assert r["limiter.blocked"].max() == 0


def check_grinder_feed(r) -> None:
    x, t, pc = r["x_axis.pos"], r.time, r["feed.pc"]
    span = {k: intervals(pc, k)[0] for k in range(1, 6)}
    assert x[span[1][0]] == pytest.approx(4.0, abs=BAND)
    assert x[span[2][0]] == pytest.approx(4.2, abs=BAND)
    assert x[span[3][0]] == pytest.approx(4.3, abs=BAND)
    for k, rate in ((1, 0.02), (2, 0.005)):
        a, b = span[k]
        a, b = a + (b - a) // 4, b - (b - a) // 4
        assert (x[b] - x[a]) / (t[b] - t[a]) == pytest.approx(rate, rel=0.02)
    a, b = span[3]
    assert t[b] - t[a] == pytest.approx(1.5, abs=0.003)
    assert_no_motion(r, "x_axis.pos", (t[a], t[b - 1]))                 # spark-out
    assert x[-1] == pytest.approx(0.0, abs=BAND) and r["feed.return_counter_x"][-1] == 0.0
    assert pc[-1] == 5


def check_grinder_envelope(r) -> None:
    assert r["limiter.blocked"].max() == 0
    x, y = r["x_axis.pos"], r["y_axis.pos"]
    assert x.max() == pytest.approx(170.0, abs=BAND)
    assert x[-1] == pytest.approx(0.0, abs=BAND) and y[-1] == pytest.approx(100.0, abs=BAND)
    # the actual wheel position never leaves the envelope
    from ncfmu.systems import GRINDER_TABLE
    assert_inside_envelope(r, "y_axis.pos", "x_axis.pos", GRINDER_TABLE)


def contour_error(r, path) -> np.ndarray:
    on = r["contour.segment"] >= 1
    return path_distance(r["x_axis.pos"][on], r["y_axis.pos"][on], path)


def check_mill_contour(r) -> None:
    from ncfmu.controllers.contour import ContourInterpolator
    from ncfmu.systems import parameters
    c = ContourInterpolator(**parameters("mill_contour", "contour"))
    assert contour_error(r, [m.element for m in c.tool_path]).max() <= 0.050
    assert r["x_axis.pos"].max() == pytest.approx(60.2, abs=BAND)
    assert r["y_axis.pos"].max() == pytest.approx(40.2, abs=BAND)
    assert r["x_axis.pos"][-1] == pytest.approx(-0.2, abs=BAND) and r["y_axis.pos"][-1] == pytest.approx(-0.2, abs=BAND)


CHECKS = {"lathe_roughing": check_lathe_roughing, "lathe_taper": check_lathe_taper,
          "grinder_feed": check_grinder_feed, "grinder_envelope": check_grinder_envelope,
          "mill_contour": check_mill_contour}


def drive_contour(c, dt=1e-3, hold=None, feed_override=1.0, steps=400_000) -> np.ndarray:
    """Run a ContourInterpolator with perfect servos (its command fed back as the position) from a start until
    done or alarm; rows of (x_cmd, y_cmd, x_vff, y_vff, segment, done, alarm). ``hold``: (from, to) in s."""
    inputs = dict(c.default_inputs(), start=True, x_pos=c.x_start, y_pos=c.y_start, feed_override=feed_override)
    rows = []
    for k in range(steps):
        inputs["feed_hold"] = hold is not None and hold[0] <= k * dt < hold[1]
        o = c.step(k * dt, dt, inputs)
        inputs["start"] = False
        inputs["x_pos"], inputs["y_pos"] = o["x_cmd"], o["y_cmd"]
        rows.append((o["x_cmd"], o["y_cmd"], o["x_vff"], o["y_vff"], o["segment"], o["done"], o["alarm"]))
        if o["done"] or o["alarm"]:
            break
    return np.array(rows, float)
