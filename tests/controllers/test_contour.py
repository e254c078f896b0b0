"""ContourInterpolator against the seed (GB 1,175,423): offset corners, DDA, vector feed; through the FMUs."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from physics import contour_error

from ncfmu.controllers.contour import ContourInterpolator, point_contour
from ncfmu.controllers.geometry import Arc, CornerError, Line, compensate
from ncfmu.errors import ConfigError
from ncfmu.systems import parameters
from ncfmu.systems.mill import CONTOUR

#: mill_contour's point path and correction, from its system definition.
MILL = parameters("mill_contour", "contour")

DT = 1e-3
MILL_PATH = CONTOUR


def line_distance(p, a, b):
    """Signed distance of p from the line a->b (positive to the left of travel)."""
    ux, uy = b[0] - a[0], b[1] - a[1]
    length = math.hypot(ux, uy)
    return (ux * (p[1] - a[1]) - uy * (p[0] - a[0])) / length


def segment_distance(p, a, b):
    ax, ay = b[0] - a[0], b[1] - a[1]
    t = max(0.0, min(1.0, ((p[0] - a[0]) * ax + (p[1] - a[1]) * ay) / (ax * ax + ay * ay)))
    return math.hypot(p[0] - a[0] - t * ax, p[1] - a[1] - t * ay)


def offset_lines(points, r, closed):
    """The compensated pieces of a point path; every piece must be a line (corners of at most 90 degrees)."""
    pieces = compensate(point_contour(points, closed), r, closed)
    assert all(isinstance(e, Line) for e, _ in pieces)
    return pieces


@pytest.mark.parametrize("r", [0.2, -0.2, 1.5])
@pytest.mark.parametrize("closed", [True, False])
def test_corners_at_the_correction_from_both_neighbouring_segments(r, closed):
    pts = MILL_PATH if closed else MILL_PATH[:-1]
    pieces = offset_lines(pts, r, closed)
    assert len(pieces) == (5 if closed else 4)
    for piece, k in pieces:
        a, b = MILL_PATH[k], MILL_PATH[k + 1]
        assert line_distance(piece.start, a, b) == pytest.approx(r, abs=1e-9)
        assert line_distance(piece.end, a, b) == pytest.approx(r, abs=1e-9)
    # consecutive pieces meet: the corner is the intersection of both offsets (the seed's corner)
    ends = [(pieces[i][0].end, pieces[(i + 1) % len(pieces)][0].start) for i in range(len(pieces) - (not closed))]
    for end, start in ends:
        assert math.dist(end, start) < 1e-12


def test_convex_and_concave_corners():
    # (20,40) -> (0,20): the corner at (0,20) is convex; a notch makes a concave one
    notch = [(0.0, 0.0), (30.0, 0.0), (30.0, 10.0), (40.0, 10.0), (40.0, 0.0), (60.0, 0.0), (60.0, 30.0), (0.0, 30.0)]
    for r in (0.5, -0.5):
        for piece, k in offset_lines(notch, r, True):
            a, b = notch[k], notch[(k + 1) % len(notch)]
            assert line_distance(piece.start, a, b) == pytest.approx(r, abs=1e-9)
            assert line_distance(piece.end, a, b) == pytest.approx(r, abs=1e-9)


def test_a_reversal_is_rounded_around_its_tip_and_a_fold_is_reported():
    # the path turns back on itself: the cutter goes around the tip on a half circle of radius r
    pieces = compensate(point_contour([(0, 0), (10, 0), (0, 0.0)], False), 0.1, False)
    (first, _), (tip, k), (back, _) = pieces
    assert isinstance(tip, Arc) and k == 1 and tip.center == (10.0, 0.0) and tip.radius == pytest.approx(0.1)
    assert abs(tip.sweep) == pytest.approx(math.pi) and tip.point(tip.length / 2) == pytest.approx((10.1, 0.0))
    assert first.end == pytest.approx((10.0, 0.1)) and back.start == pytest.approx((10.0, -0.1))
    with pytest.raises(CornerError) as err:                 # 0.5 mm step, 2 mm tool change: segment 2 folds
        compensate(point_contour([(0, 0), (10, 0), (10, 0.5), (0, 0.5)], False), 1.0, False)
    assert err.value.index == 1 and "run backwards" in err.value.reason
    c = ContourInterpolator(n_points=4, closed=False, diameter_delta=2.0, side=1,
                            **{"point[1].x": 0, "point[1].y": 0, "point[2].x": 10, "point[2].y": 0,
                               "point[3].x": 10, "point[3].y": 0.5, "point[4].x": 0, "point[4].y": 0.5})
    assert c.outputs()["alarm"] and any("segment 2" in m for _, m in c.take_messages())
    o = c.step(0.0, DT, {"start": True, "feed_hold": False, "feed_override": 1.0, "x_pos": 0.0, "y_pos": -10.0,
                         "x_in_position": True, "y_in_position": True})
    assert not o["busy"] and o["alarm"]


@pytest.mark.parametrize("values, variable, rule", [
    ({"n_points": 1}, "n_points", "must be in 2..64"),
    ({"point[2].x": 0.0, "point[2].y": 0.0}, "point[2]", "repeats point[1]"),
    ({"feed": 0.0}, "feed", "must be > 0"),
    ({"side": 0}, "side", "must be one of -1, +1"),
    ({"point[3].y": math.inf}, "point[3].y", "must be finite"),
])
def test_bad_input_refused(values, variable, rule):
    with pytest.raises(ConfigError) as err:
        ContourInterpolator(**{**MILL, **values})
    assert err.value.variable == variable and rule in str(err.value)


def iterative_dda(span, n):
    """The seed's interpolator literally: N iterative additions with carry, accumulator preset to N/2."""
    acc, pulses, out = n // 2, 0, []
    for _ in range(n):
        acc += abs(span)
        if acc >= n:
            acc -= n
            pulses += 1
        out.append(pulses)
    return out


@pytest.mark.parametrize("span", [0, 1, 7, 200, 1023, 1024, 4999])
def test_closed_form_dda_equals_iterative_additions(span):
    n = 1 << max(1, span).bit_length()
    half = n >> 1
    assert [(half + k * span) // n for k in range(1, n + 1)] == iterative_dda(span, n)


def run_contour(override=1.0, hold=None, **changes):
    c = ContourInterpolator(**{**MILL, **changes})
    inp = {"start": True, "feed_hold": False, "feed_override": override, "x_pos": c.x_start, "y_pos": c.y_start,
           "x_in_position": True, "y_in_position": True}
    t, log = 0.0, []
    while t < 200:
        inp["feed_hold"] = hold is not None and hold[0] <= t < hold[1]
        o = dict(c.step(t, DT, inp))
        inp["start"] = False
        inp["x_pos"], inp["y_pos"] = o["x_cmd"], o["y_cmd"]
        t += DT
        o["t"] = t
        log.append(o)
        if o["done"]:
            break
    return c, log


def test_dda_points_on_the_corrected_segments_within_one_unit():
    c, log = run_contour()
    lines = {m.label: m.element for m in c.tool_path}
    assert sorted(lines) == [1, 2, 3, 4, 5] and all(isinstance(e, Line) for e in lines.values())
    for o in log:
        k = o["segment"]
        if k == 0:
            continue
        a, b = lines[k].start, lines[k].end
        assert segment_distance((o["x_cmd"], o["y_cmd"]), a, b) <= c.dda_unit * 1.0000001


@pytest.mark.parametrize("override", [1.0, 0.5, 1.5])
def test_vector_speed_is_feed_times_override(override):
    c, log = run_contour(override=override)
    for move in c.tool_path:
        k = move.label
        rows = [o for o in log if o["segment"] == k]
        if k in (1, len(c.tool_path)):
            continue      # the first and last segments include the start and the final stop
        duration = rows[-1]["t"] - rows[0]["t"] + DT
        # exact stop at both corners: the start and the stop each cost feed / (2 accel) of time
        assert move.element.length / duration == pytest.approx(5.0 * override, rel=0.01)


def test_hold_stops_on_the_path_and_resumes():
    c, log = run_contour(hold=(10.0, 12.0))
    held = [o for o in log if 10.5 <= o["t"] < 12.0]
    assert len({(o["x_cmd"], o["y_cmd"]) for o in held}) == 1
    assert log[-1]["done"]
    _, plain = run_contour()
    assert log[-1]["t"] - plain[-1]["t"] == pytest.approx(2.0, abs=0.05)


@st.composite
def convex_polygons(draw):
    n = draw(st.integers(3, 10))
    # gaps between the vertices' angles on a circle: every interior angle < 180 degrees
    gaps = draw(st.lists(st.floats(0.8, 1.0), min_size=n, max_size=n))
    scale = 2 * math.pi / sum(gaps)
    phase = draw(st.floats(0.0, 2 * math.pi))
    angles = [phase + scale * sum(gaps[:i]) for i in range(n)]
    radius = draw(st.floats(20.0, 100.0))
    return [(radius * math.cos(a), radius * math.sin(a)) for a in angles]


@settings(max_examples=100, deadline=None)
@given(poly=convex_polygons(), r=st.floats(-2.0, 2.0).filter(lambda r: abs(r) > 1e-3))
def test_property_corrected_polygon_is_the_offset_polygon(poly, r):
    pieces = compensate(point_contour(poly, True), r, True)
    n = len(poly)
    for piece, k in pieces:
        a, b = poly[k], poly[(k + 1) % n]
        if isinstance(piece, Arc):
            # a corner sharper than 90 degrees (outside): rounded around the programmed corner at distance r
            assert piece.center in (a, b) and piece.radius == pytest.approx(abs(r), abs=1e-12)
            continue
        # parallel to the programmed edge, in the same direction ...
        u = (b[0] - a[0], b[1] - a[1])
        v = (piece.end[0] - piece.start[0], piece.end[1] - piece.start[1])
        cross = (u[0] * v[1] - u[1] * v[0]) / (math.hypot(*u) * math.hypot(*v))
        assert abs(cross) < 1e-9 and u[0] * v[0] + u[1] * v[1] > 0
        # ... at the correction distance
        assert line_distance(piece.start, a, b) == pytest.approx(r, abs=1e-9)
        assert line_distance(piece.end, a, b) == pytest.approx(r, abs=1e-9)
    # the pieces join up into one closed path
    for (p, _), (q, _) in zip(pieces, pieces[1:] + pieces[:1]):
        assert math.dist(p.end, q.start) < 1e-9


# -- through the FMUs (the contour check itself is physics.check_mill_contour, run in test_interop) ----
@pytest.mark.slow
def test_mill_contour_finishes_without_alarm(mill_contour):
    assert mill_contour["contour.done"][-1] and not mill_contour["contour.alarm"].any()


@pytest.mark.slow
def test_override_half_doubles_the_contour_time(mill_contour, project):
    from ncfmu.project import simulate
    slow = simulate("mill_contour", stop_time=85.0, start_values={"panel.override": 0.5})

    def contour_time(r):
        on = (r["contour.segment"] >= 1) & r["contour.busy"]
        return r.time[on][-1] - r.time[on][0]
    assert contour_time(slow) == pytest.approx(2 * contour_time(mill_contour), rel=0.01)


@pytest.mark.slow
def test_hold_stops_and_resumes_on_the_path(project):
    from ncfmu.project import simulate
    r = simulate("mill_contour", stop_time=45.0, start_values={"panel.hold_at": 15.0, "panel.release_at": 17.0})
    c = ContourInterpolator(**MILL)
    assert contour_error(r, [m.element for m in c.tool_path]).max() <= 0.050
    held = (r.time > 15.3) & (r.time < 17.0)
    assert np.ptp(r["x_axis.pos"][held]) < 1e-3 and np.ptp(r["y_axis.pos"][held]) < 1e-3
    assert r["contour.done"][-1]
