"""Arcs, bounded corners, corner speed and part programs -- as properties and through the FMUs."""

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from physics import drive_contour

from ncfmu.checks import element_distance, path_distance
from ncfmu.controllers.contour import ContourInterpolator, program_path
from ncfmu.controllers.geometry import Arc, Line
from ncfmu.controllers.rs274 import parse
from ncfmu.errors import ProgramError

DT = 1e-3
SQRT2 = math.sqrt(2.0)

#: A part with a convex arc (G03, R 20), a concave arc (G02, R 20) and square corners, cut outside (G42).
PART = """%
(part: convex arc, concave arc, square corners)
G21 G17 G90
F300
G42 G01 X0 Y0          (lead-in: compensation starts)
X40
G03 X60 Y20 I0 J20     (convex, tangent to both neighbours)
G01 Y40
G02 X40 Y60 I0 J20     (concave)
G01 X0
Y0
G40 G01 X0 Y-10        (lead-out)
M30
%"""
CONVEX = {"line": 7, "center": (40.0, 20.0), "corner": None}
#: The concave arc starts at a square corner, (60, 40): cut outside, the block begins with the corner's arc.
CONCAVE = {"line": 9, "center": (60.0, 60.0), "corner": (60.0, 40.0)}


def on_arc(arc, segment, x, y, r=2.0):
    """Samples of the arc's block on the offset arc itself (past the arc around the corner before it)."""
    on = segment == arc["line"]
    if arc["corner"] is not None:
        on &= np.hypot(x - arc["corner"][0], y - arc["corner"][1]) > r + 0.002
    return on


def signed_offset(points, element):
    """Signed distance of points from an element's geometry, positive to the left of travel."""
    p = np.asarray(points, float)
    if isinstance(element, Line):
        (ux, uy), (ax, ay) = element.unit, element.start
        return ux * (p[:, 1] - ay) - uy * (p[:, 0] - ax)
    dist = np.hypot(p[:, 0] - element.center[0], p[:, 1] - element.center[1])
    return (element.radius - dist) if element.sweep > 0 else (dist - element.radius)


def sample(element, n=40):
    return [element.point(element.length * i / n) for i in range(n + 1)]


# -- geometry: random programs of lines and arcs ------------------------------------------------------
@st.composite
def star_programs(draw):
    """A closed contour around the origin (so it never crosses itself): vertices at rising angles, joined
    by lines, convex arcs (G03) or concave arcs (G02); cut with G41 (inside) or G42 (outside)."""
    n = draw(st.integers(3, 8))
    gaps = draw(st.lists(st.floats(0.6, 1.0), min_size=n, max_size=n))
    scale = 2 * math.pi / sum(gaps)
    angles = [scale * sum(gaps[:i]) for i in range(n)]
    radii = draw(st.lists(st.floats(30.0, 60.0), min_size=n, max_size=n))
    pts = [(r * math.cos(a), r * math.sin(a)) for r, a in zip(radii, angles)]
    kinds = draw(st.lists(st.sampled_from(["line", "convex", "concave"]), min_size=n, max_size=n))
    bulges = draw(st.lists(st.floats(0.05, 0.3), min_size=n, max_size=n))
    side = draw(st.sampled_from(["G41", "G42"]))
    feed = draw(st.sampled_from([600.0, 3000.0, 6000.0]))
    lines = ["G21 G17 G90", f"F{feed:g}", f"G0 X{pts[0][0] * 1.5:.12f} Y{pts[0][1] * 1.5:.12f}",
             f"{side} G1 X{pts[0][0]:.12f} Y{pts[0][1]:.12f}"]
    for k in range(n):
        (ax, ay), (bx, by) = pts[k], pts[(k + 1) % n]
        if kinds[k] == "line":
            lines.append(f"G1 X{bx:.12f} Y{by:.12f}")
            continue
        chord = math.hypot(bx - ax, by - ay)
        h = bulges[k] * chord                                  # sagitta
        radius = (chord * chord / 4 + h * h) / (2 * h)
        lx, ly = -(by - ay) / chord, (bx - ax) / chord         # left of the chord (inside the CCW contour)
        towards = 1.0 if kinds[k] == "convex" else -1.0        # convex: the centre lies inside
        cx, cy = (ax + bx) / 2 + towards * lx * (radius - h), (ay + by) / 2 + towards * ly * (radius - h)
        code = "G3" if kinds[k] == "convex" else "G2"
        lines.append(f"{code} X{bx:.12f} Y{by:.12f} I{cx - ax:.12f} J{cy - ay:.12f}")
    lines += [f"G40 G1 X{pts[0][0] * 1.5:.12f} Y{pts[0][1] * 1.5:.12f}", "M2"]
    r = draw(st.floats(0.05, 2.0))
    return "\n".join(lines), r, (1 if side == "G41" else -1)


def compensated(program, r):
    moves = parse(program, (0.0, 0.0))
    try:
        path = program_path(moves, r, rapid_feed=50.0)
    except ProgramError:
        assume(False)          # the cutter does not fit this random part (an inside corner): not the property
    contour_lines = {m.line for m in moves if m.comp_before and m.comp_after}
    contour = {m.line: m.element for m in moves if m.line in contour_lines}
    return path, contour


@settings(max_examples=150, deadline=None)
@given(star_programs())
def test_property_compensated_path_keeps_r_on_the_requested_side(case):
    program, r, side = case
    path, contour = compensated(program, r)
    d = side * r
    elements = list(contour.values())
    for move in path:
        if move.label not in contour:
            continue                                            # lead-in, lead-out, positioning
        element, points = contour[move.label], sample(move.element)
        corner_arc = (isinstance(move.element, Arc) and math.isclose(move.element.radius, r, abs_tol=1e-12)
                      and min(math.dist(move.element.center, element.start),
                              math.dist(move.element.center, element.end)) < 1e-9)   # the closing corner
        if corner_arc:
            # an outside corner rounded around the programmed corner: exactly r from it
            assert abs(move.element.sweep) > 0
        else:
            # an offset piece: at d from its own programmed element (side included), within 1e-9
            assert np.abs(signed_offset(points, element) - d).max() < 1e-9
        # never closer than r to the contour (no gouge), never farther than r*sqrt(2) (corners)
        x, y = np.asarray(points).T
        dist = path_distance(x, y, elements)
        assert dist.min() >= r - 1e-9
        assert dist.max() <= r * SQRT2 + 1e-9


def run_program(program, feed_override=1.0, accel=500.0, hold=None, **parameters):
    c = ContourInterpolator(**{"program": program, "accel": accel, "x_start": 0.0, "y_start": 0.0, **parameters})
    return c, drive_contour(c, DT, hold=hold, feed_override=feed_override)


@pytest.mark.slow
@settings(max_examples=25, deadline=None)
@given(star_programs(), st.sampled_from([0.5, 1.0, 1.5]), st.sampled_from([200.0, 500.0, 2000.0]),
       st.floats(0.0, 3.0))
def test_property_interpolated_command_never_exceeds_accel(case, override, accel, hold_at):
    program, r, _ = case
    compensated(program, r)                                   # the same cases as the geometry property
    hold = (hold_at, hold_at + 0.5)                           # a feed hold somewhere on the path
    c, rows = run_program(program, feed_override=override, accel=accel, hold=hold, diameter_delta=2 * r)
    # held: at rest on the path within v / accel of the hold (the stop never asks for more than accel)
    rest = (np.arange(len(rows)) * DT >= hold[0] + 150.0 / accel + 0.01) & (np.arange(len(rows)) * DT < hold[1])
    if rest.any():
        assert np.ptp(rows[rest, 0]) == 0.0 and np.ptp(rows[rest, 1]) == 0.0
        assert path_distance(rows[rest, 0], rows[rest, 1], [m.element for m in c.tool_path]).max() <= c.dda_unit
    assert rows[-1, 5] == 1 and not rows[:, 6].any()          # done, no alarm
    vff = rows[:, 2:4]
    acc = np.diff(vff, axis=0) / DT
    assert np.abs(acc).max() <= accel * (1 + 1e-9)                   # every axis ...
    assert np.hypot(acc[:, 0], acc[:, 1]).max() <= accel * (1 + 1e-9)  # ... and the vector
    # the position follows the speed: no jump beyond the highest feed and the DDA's increments
    step = np.hypot(*np.diff(rows[:, :2], axis=0).T)
    assert step.max() <= 6000.0 / 60 * 1.5 * DT + 2 * c.dda_unit
    # the command ends where the program ends
    assert rows[-1, :2] == pytest.approx([c.tool_path[-1].element.end[0], c.tool_path[-1].element.end[1]], abs=1e-3)


def test_arc_runs_at_the_programmed_feed_on_r_plus_or_minus_r():
    c, rows = run_program(PART, diameter_delta=4.0, x_start=0.0, y_start=-10.0)
    assert rows[-1, 5] == 1
    for arc, radius in ((CONVEX, 22.0), (CONCAVE, 18.0)):      # G42 on a CCW part: convex R + r, concave R - r
        on = on_arc(arc, rows[:, 4], rows[:, 0], rows[:, 1])
        dist = np.hypot(rows[on, 0] - arc["center"][0], rows[on, 1] - arc["center"][1])
        assert np.abs(dist - radius).max() <= 0.5e-3 * SQRT2 + 1e-12   # half an increment per axis
        speed = np.hypot(rows[on, 2], rows[on, 3])
        middle = speed[len(speed) // 5: -len(speed) // 5]
        assert middle == pytest.approx(5.0, rel=1e-9)


# -- through the FMUs ----------------------------------------------------------------------------------
def arc_part_run(project, side):
    from ncfmu.project import simulate
    program = PART if side == "G42" else PART.replace("G42", "G41")
    return simulate("mill_contour", stop_time=75.0, start_values={"contour.program": program,
                                                                  "contour.diameter_delta": 4.0})


@pytest.mark.slow
@pytest.mark.parametrize("side, convex_r, concave_r", [("G42", 22.0, 18.0), ("G41", 18.0, 22.0)])
def test_fmu_arc_part_cut_at_r_plus_minus_r_at_the_feed(project, side, convex_r, concave_r):
    r = arc_part_run(project, side)
    assert r["contour.done"][-1] and not r["contour.alarm"].any()
    for arc, radius in ((CONVEX, convex_r), (CONCAVE, concave_r)):
        on = on_arc(arc, r["contour.segment"], r["contour.x_cmd"], r["contour.y_cmd"]) & r["contour.busy"]
        cx, cy = arc["center"]
        commanded = np.hypot(r["contour.x_cmd"][on] - cx, r["contour.y_cmd"][on] - cy)
        actual = np.hypot(r["x_axis.pos"][on] - cx, r["y_axis.pos"][on] - cy)
        assert np.abs(commanded - radius).max() <= 0.002
        assert np.abs(actual - radius).max() <= 0.010
        # the vector feed, commanded and actual, in the arc's middle part: F300 = 5 mm/s
        t = r.time[on]
        middle = on & (r.time > t[0] + 0.2 * (t[-1] - t[0])) & (r.time < t[-1] - 0.2 * (t[-1] - t[0]))
        assert np.hypot(r["contour.x_vff"][middle], r["contour.y_vff"][middle]) == pytest.approx(5.0, rel=0.01)
        assert np.hypot(r["x_axis.vel"][middle], r["y_axis.vel"][middle]) == pytest.approx(5.0, rel=0.01)


@pytest.mark.slow
def test_fmu_sharp_outside_corner_stays_within_r_sqrt2(project):
    """A 175 degree turn cut outside with r = 2 mm: the seed's intersection would put the corner 46 mm out."""
    from ncfmu.project import simulate
    tip = (40.0 + 40.0 * math.cos(math.radians(175)), 40.0 * math.sin(math.radians(175)))
    points = [(0.0, 0.0), (40.0, 0.0), tip]
    values = {"contour.n_points": 3, "contour.closed": False, "contour.diameter_delta": 4.0, "contour.side": -1}
    for i, (x, y) in enumerate(points, start=1):
        values[f"contour.point[{i}].x"], values[f"contour.point[{i}].y"] = x, y
    r = simulate("mill_contour", stop_time=30.0, start_values=values)
    assert r["contour.done"][-1] and not r["contour.alarm"].any()
    contour = [Line(points[0], points[1]), Line(points[1], points[2])]
    on = r["contour.segment"] >= 1
    commanded = path_distance(r["contour.x_cmd"][on], r["contour.y_cmd"][on], contour)
    actual = path_distance(r["x_axis.pos"][on], r["y_axis.pos"][on], contour)
    assert commanded.max() <= 2.0 * SQRT2 and actual.max() <= 2.0 * SQRT2
    # around the tip the cutter centre keeps r: it is rounded, not extended
    near_tip = on & (np.hypot(r["x_axis.pos"] - 40.0, r["y_axis.pos"]) < 3.0)
    tip_dist = element_distance(r["x_axis.pos"][near_tip], r["y_axis.pos"][near_tip], contour[0])
    assert near_tip.any() and np.abs(np.minimum(tip_dist, 2.0 + 0.01) - 2.0).max() <= 0.010


@pytest.mark.slow
def test_fmu_default_path_at_80_mm_s_within_accel_and_no_gouge(project):
    from ncfmu.project import simulate
    r = simulate("mill_contour", stop_time=6.0, start_values={"contour.feed": 80.0, "contour.approach_feed": 80.0})
    assert r["contour.done"][-1] and not r["contour.alarm"].any()
    accel = 500.0
    on = r["contour.segment"] >= 1
    for axis, a in (("x", "x_axis"), ("y", "y_axis")):
        commanded = np.diff(r[f"contour.{axis}_vff"]) / np.diff(r.time)
        actual = np.diff(r[f"{a}.vel"]) / np.diff(r.time)
        assert np.abs(commanded).max() <= accel * (1 + 1e-9)
        assert np.abs(actual).max() <= 1.5 * accel
    mill = [(0.0, 0.0), (60.0, 0.0), (60.0, 40.0), (20.0, 40.0), (0.0, 20.0), (0.0, 0.0)]
    dist = path_distance(r["x_axis.pos"][on], r["y_axis.pos"][on], mill)
    assert dist.min() >= 0.2 - 0.005
