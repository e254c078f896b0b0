"""The material-removal engine on its own: chips, crashes and the part made, against hand-worked geometry."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import Polygon, box

from ncfmu.machining import MaterialRemoval, deviation, lathe_tool, mill_cutter
from ncfmu.machining.removal import RESOLUTION, TOUCH, Forbidden


def feed(m: MaterialRemoval, points, rapid, line=0, chunk=None, dt=1e-3, t0=0.0):
    """Feed a polyline, densified to rows 0.01 mm apart, in chunks of ``chunk`` rows."""
    rows = []
    for (a, b) in zip(points, points[1:]):
        n = max(2, int(math.dist(a, b) / 0.01))
        rows.append(np.linspace(a, b, n, endpoint=False))
    rows.append(np.array([points[-1]]))
    xy = np.concatenate(rows)
    t = t0 + dt * np.arange(len(xy))
    flags = np.full(len(xy), rapid)
    lines = np.full(len(xy), line)
    step = chunk or len(xy)
    for k in range(0, len(xy), step):
        s = slice(k, k + step)
        m.write(t[s], xy[s, 0], xy[s, 1], flags[s], lines[s])
    return t


def test_the_lathe_tool_has_its_programmed_point_at_its_lowest_and_leftmost():
    for r in (0.0, 0.4, 0.8):
        zmin, xmin = lathe_tool(r).min(axis=0)
        assert zmin == pytest.approx(0.0, abs=RESOLUTION) and xmin == pytest.approx(0.0, abs=RESOLUTION)
        assert lathe_tool(r).max(axis=0)[0] == pytest.approx(2 * r, abs=RESOLUTION)     # the blade: 2r wide
    # inscribed, its chords within RESOLUTION of the circle: short of the disc by less than perimeter x RESOLUTION
    assert 0 < math.pi * 4 - Polygon(mill_cutter(2.0)).area < 4 * math.pi * RESOLUTION


@pytest.mark.parametrize("chunk", [None, 37, 1000])
def test_a_turning_pass_takes_its_depth_over_its_length_whatever_the_chunks(chunk):
    # bar radius 29 from Z 0 to -80; a pass at X 28.5 from Z 2 to -40, in front of the face at rapid
    m = MaterialRemoval(box(-80, 0, 0, 29), lathe_tool(0.0), max_depth=1.0)
    feed(m, [(2.0, 30.0), (2.0, 28.5)], rapid=True, chunk=chunk)
    feed(m, [(2.0, 28.5), (-40.0, 28.5)], rapid=False, chunk=chunk, t0=10)
    feed(m, [(-40.0, 28.5), (-40.0, 30.0)], rapid=True, chunk=chunk, t0=20)
    assert m.crashes == []
    assert m.removed_area == pytest.approx(40 * 0.5, rel=1e-6)
    assert m.deepest_cut == pytest.approx(0.5, abs=RESOLUTION)
    assert m.stock.area == pytest.approx(80 * 29 - 20, rel=1e-9)


def test_a_rapid_into_the_stock_is_a_crash_named_by_its_line_time_and_depth():
    m = MaterialRemoval(box(-80, 0, 0, 29), lathe_tool(0.0))
    # rapid down at Z -20 from X 32 to X 24.2: the bar's top is at 29, so 4.8 mm deep; it is entered at X 29
    t = feed(m, [(-20.0, 32.0), (-20.0, 24.2)], rapid=True, line=7)
    assert len(m.crashes) == 1
    c = m.crashes[0]
    assert (c.line, c.what) == (7, "rapid into the stock")
    assert c.depth_mm == pytest.approx(4.8, abs=0.01)
    # when it went in: about the first row more than TOUCH below X 29 (0.01 mm, 1 ms per row; the chip is a
    # triangle whose sharp top is reached a row or two later)
    assert c.t == pytest.approx(t[0] + (32 - 29 + TOUCH) / 0.01 * 1e-3, abs=2.5e-3)
    assert c.at == pytest.approx((-20.0, 29.0), abs=0.021)


@pytest.mark.parametrize("r", [0.0, 0.4])
def test_a_rapid_plunge_in_x_alone_is_a_crash_also_for_a_point(r):
    m = MaterialRemoval(box(-80, 0, 0, 29), lathe_tool(r))
    feed(m, [(-20.0, 30.0), (-20.0, 27.0)], rapid=True, line=4)
    assert [(c.line, c.what) for c in m.crashes] == [(4, "rapid into the stock")]
    assert m.crashes[0].depth_mm == pytest.approx(2.0, abs=0.01)


def test_a_rapid_through_air_or_along_a_surface_it_cut_is_no_crash():
    m = MaterialRemoval(box(-80, 0, 0, 29), lathe_tool(0.0))
    feed(m, [(2.0, 28.5), (-40.0, 28.5)], rapid=False)
    feed(m, [(-40.0, 28.5), (-40.0, 28.5 + TOUCH / 2)], rapid=True, t0=10)       # settles up along its own wall
    feed(m, [(-40.0, 30.0), (2.0, 30.0), (2.0, 28.5)], rapid=True, t0=20)      # over the bar and in front of it
    assert m.crashes == []


def test_a_cut_deeper_than_max_depth_and_the_chuck_and_the_axis():
    chuck = Forbidden("tool into the chuck jaws", box(-120, 0, -45, 40))
    axis = Forbidden("tool across the spindle axis", box(-200, -100, 100, 0))

    def crashes(path, line):
        m = MaterialRemoval(box(-80, 0, 0, 29), lathe_tool(0.0), [chuck, axis], max_depth=2.0)
        feed(m, path, rapid=False, line=line)
        return [(c.line, c.what, round(c.depth_mm, 3)) for c in m.crashes]

    assert crashes([(2.0, 26.0), (-20.0, 26.0)], 3) == [(3, "cut deeper than the tool's max_depth 2 mm", 3.0)]
    assert crashes([(-20.0, 30.0), (-46.0, 30.0)], 4) == [(4, "tool into the chuck jaws", 1.0)]
    assert crashes([(2.0, 1.0), (2.0, -0.5)], 5) == [(5, "tool across the spindle axis", 0.5)]   # in front: air
    assert crashes([(2.0, 27.0), (-20.0, 27.0)], 6) == []                                        # 2 mm: allowed


def test_a_mill_cutter_around_a_square_leaves_the_square_and_the_deviation_names_excess_and_gouge():
    part = box(0, 0, 40, 30)
    m = MaterialRemoval(box(-5, -5, 45, 35), mill_cutter(2.0))
    # the cutter centre 2 mm outside the square, around it (corners rounded by arcs of radius 2)
    pts = []
    for (cx, cy), a0 in (((40, 0), -90), ((40, 30), 0), ((0, 30), 90), ((0, 0), 180)):
        pts += [(cx + 2 * math.cos(math.radians(a)), cy + 2 * math.sin(math.radians(a))) for a in range(a0, a0 + 91, 3)]
    pts.append(pts[0])
    feed(m, pts, rapid=False)
    made = m.part(part)
    d = deviation(made, part)
    assert d.left < 0.005 and d.gouge < 0.005
    # the same part against a drawing 0.1 mm larger on the right: a gouge of 0.1 there; 0.2 smaller at the top
    d = deviation(made, box(0, 0, 40.1, 29.8))
    assert d.gouge == pytest.approx(0.1, abs=0.003) and d.gouge_at[0] == pytest.approx(40.0, abs=0.01)
    assert d.left == pytest.approx(0.2, abs=0.003) and d.left_at[1] == pytest.approx(30.0, abs=0.01)


@settings(max_examples=25, deadline=None)
@given(st.floats(0.1, 3.0), st.floats(-30.0, -5.0), st.integers(40, 400))
def test_the_chip_is_the_depth_whatever_the_chunking(depth, z_end, chunk):
    m = MaterialRemoval(box(-80, 0, 0, 29), lathe_tool(0.4))
    feed(m, [(3.0, 29.0 - depth), (z_end, 29.0 - depth)], rapid=False, chunk=chunk)
    assert m.deepest_cut == pytest.approx(depth, abs=2 * RESOLUTION)
    top = max(x for z, x in m.stock.exterior.coords if z < z_end - 1)
    assert top == pytest.approx(29.0)
    # the band, less what the nose's rounding leaves in the corner at the end: at most r^2 (1 - pi/4)
    assert m.removed_area == pytest.approx(-z_end * depth, abs=0.4**2 * (1 - math.pi / 4) + 1e-3)


def test_recutting_the_same_surface_keeps_the_stock_small():
    m = MaterialRemoval(box(-80, 0, 0, 29), lathe_tool(0.4))
    feed(m, [(2.0, 28.0), (-40.0, 28.0)], rapid=False)
    size = len(m.stock.exterior.coords)
    for k in range(20):
        jitter = 1e-7 * (k % 3)
        feed(m, [(2.0, 28.0 + jitter), (-40.0, 28.0 + jitter)], rapid=False, t0=10 * (k + 1))
    assert isinstance(m.stock, Polygon) and len(m.stock.exterior.coords) <= size + 4


@pytest.mark.parametrize("chunk", [None, 50])
def test_a_crash_is_one_crash_per_move_whatever_the_chunks(chunk):
    m = MaterialRemoval(box(-80, 0, 0, 29), lathe_tool(0.0), max_depth=1.0)
    feed(m, [(2.0, 27.0), (-30.0, 27.0)], rapid=False, line=3, chunk=chunk)
    assert m.crash_count == 1 and m.crashes[0].depth_mm == pytest.approx(2.0, abs=RESOLUTION)


def test_a_live_server_reads_the_crashes_as_they_happen():
    """crashes_so_far: the hook ncfmu serve reads after every chunk (no verdict is judged)."""
    from ncfmu.systems import SYSTEMS, parameters
    from ncfmu.systems.part import crashes_so_far
    report = SYSTEMS["lathe_roughing"].report
    acc = report.accumulator({"seq": {**parameters("lathe_roughing", "seq"), "program": ""},
                              "limiter": parameters("lathe_roughing", "limiter")})
    names = report.record()
    dtype = [("time", float), *((n, bool if n.endswith(("rapid", "done", "alarm")) else
                                  np.int32 if n.endswith(("line", "subcycle", "blocked")) else float)
                                 for n in names)]
    acc.open([(n, np.dtype(t)) for n, t in dtype])
    rows = np.zeros(3, dtype=dtype)
    rows["time"] = [0.0, 0.001, 0.002]
    rows["x_axis.pos"], rows["z_axis.pos"] = [30.0, 27.0, 24.0], [-10.0, -10.0, -10.0]
    rows["seq.rapid"] = True
    acc.write(rows[:1])
    assert crashes_so_far(acc) == []
    acc.write(rows[1:])
    assert [c.what for c in crashes_so_far(acc)] == ["rapid into the stock"]


@pytest.mark.parametrize("chunk", [None, 37, 1000])
def test_a_cut_where_the_work_stands_is_a_crash_from_the_first_standing_row_inside(chunk):
    # a pass at X 28.5 from Z 2 to -40; the spindle stops (standing) from Z -20 on: what is cut from there on is
    # the crash, 0.5 mm deep, entered where the pass was at Z -20; before it the same pass cut at speed
    from ncfmu.machining.removal import STANDING
    m = MaterialRemoval(box(-80, 0, 0, 29), lathe_tool(0.0))
    xy = np.column_stack((np.linspace(2.0, -40.0, 4201), np.full(4201, 28.5)))
    t = 1e-3 * np.arange(len(xy))
    standing = xy[:, 0] <= -20.0
    step = chunk or len(xy)
    for k in range(0, len(xy), step):
        s = slice(k, k + step)
        m.write(t[s], xy[s, 0], xy[s, 1], np.zeros(len(xy[s]), bool), np.full(len(xy[s]), 5), standing[s])
    assert [(c.line, c.what) for c in m.crashes] == [(5, STANDING)]
    c = m.crashes[0]
    assert c.depth_mm == pytest.approx(0.5, abs=RESOLUTION)
    assert c.at[0] == pytest.approx(-20.0, abs=0.011)
    assert c.t == pytest.approx(float(t[np.argmax(standing)]), abs=0.0011)
    assert m.removed_area == pytest.approx(40 * 0.5, rel=1e-6)     # it still cut (the bar was pushed)
    # the same pass with the work turning throughout: no crash
    m = MaterialRemoval(box(-80, 0, 0, 29), lathe_tool(0.0))
    m.write(t, xy[:, 0], xy[:, 1], np.zeros(len(xy), bool), np.full(len(xy), 5), np.zeros(len(xy), bool))
    assert m.crashes == []
