"""Closed loop through the built FMUs (fmpy master): the lathe systems of SPEC section 5."""

import numpy as np
import pytest

X0, Z0 = 30.0, 2.0
BAND = 0.005


def cuts(result):
    """Index ranges of every SC2 (cut) interval."""
    sub = result["seq.subcycle"]
    edges = np.flatnonzero(np.diff((sub == 2).astype(int)))
    starts, ends = edges[::2] + 1, edges[1::2] + 1
    return list(zip(starts, ends))


def test_roughing_cuts_every_pass_at_its_depth(lathe_roughing):
    r = lathe_roughing
    intervals = cuts(r)
    assert len(intervals) == 7
    expected = [X0 - (1.0 + n * 0.5) for n in range(1, 7)] + [X0 - (4.0 + 0.1)]
    assert expected[-1] == pytest.approx(25.9)
    for (a, b), x_target in zip(intervals, expected):
        x = r["x_axis.pos"][a:b]
        assert np.abs(x - x_target).max() <= 0.002, (x_target, np.abs(x - x_target).max())
        z_end = r["z_axis.pos"][b - 1]
        assert abs(z_end - (Z0 - 42.0)) <= BAND


def test_roughing_ends_at_the_start_point(lathe_roughing):
    r = lathe_roughing
    assert r["seq.done"][-1] and not r["seq.alarm"].any()
    assert abs(r["x_axis.pos"][-1] - X0) <= BAND and abs(r["z_axis.pos"][-1] - Z0) <= BAND
    # passes and blocks as the seed counts them
    assert r["seq.block_no"].max() == 2
    assert set(np.unique(r["seq.pass_no"][r["seq.block_no"] == 1])) >= {1, 2, 3, 4, 5, 6}


def test_no_motion_beyond_the_stock_outline_during_rapids(lathe_roughing):
    r = lathe_roughing
    sub = r["seq.subcycle"]
    # SC4 (return) runs at X0, clear of the stock (radius 29)
    sc4 = sub == 4
    assert r["x_axis.pos"][sc4].min() > 29.0


def test_taper_path_on_the_straight_line(lathe_taper):
    r = lathe_taper
    intervals = cuts(r)
    assert len(intervals) == 4
    for n, (a, b) in enumerate(intervals, start=1):
        sigma = 1.0 + n * 0.5
        x, z = r["x_axis.pos"][a:b], r["z_axis.pos"][a:b]
        p0, p1 = np.array([X0 - sigma, Z0]), np.array([X0 - sigma - 1.5, Z0 - 42.0])
        d = (p1 - p0) / np.linalg.norm(p1 - p0)
        normal = np.array([-d[1], d[0]])
        dist = (x - p0[0]) * normal[0] + (z - p0[1]) * normal[1]
        assert np.abs(dist).max() <= 0.002, (n, np.abs(dist).max())
        assert abs(x[-1] - p1[0]) <= BAND and abs(z[-1] - p1[1]) <= BAND
    assert abs(r["x_axis.pos"][-1] - X0) <= BAND and abs(r["z_axis.pos"][-1] - Z0) <= BAND


def test_feed_rate_during_the_cut(lathe_roughing):
    r = lathe_roughing
    a, b = cuts(r)[0]
    v = -r["z_axis.vel"][a:b]
    steady = v[(r.time[a:b] > r.time[a] + 0.5) & (r.time[a:b] < r.time[b - 1] - 0.5)]
    assert steady == pytest.approx(4.0, rel=0.01)


def test_default_programs_never_raise_the_limiter_alarm(lathe_roughing, lathe_taper):
    for r in (lathe_roughing, lathe_taper):
        assert not r["limiter.alarm"].any() and not r["seq.alarm"].any()
        assert r["limiter.blocked"].max() == 0


def test_cut_into_the_chuck_stops_before_it(project):
    """Zp = 50 would take the tool to Z = -48; the chuck zone starts at Z = -45."""
    from ncfmu.project import simulate
    r = simulate("lathe_roughing", stop_time=14.0, start_values={"seq.block[1].Zp": 50.0})
    assert r["limiter.alarm"].any() and r["seq.alarm"][-1]
    assert r["limiter.blocked"].max() == 2                     # Z- blocked, nothing else
    assert r["z_axis.pos"].min() > -45.0                       # the actual axis never enters
    assert r["limiter.ref_cmd"].min() > -45.0                  # nor does the command
    first = np.argmax(r["limiter.alarm"])
    assert r["z_axis.pos"][first] < -44.0                      # it got close: stopped by the limit, not early
    # the sequencer holds: no motion after the alarm has settled
    late = r.time > r.time[first] + 0.5
    assert np.ptp(r["z_axis.pos"][late]) < 1e-4 and np.ptp(r["seq.z_cmd"][late]) == 0.0
    assert not r["seq.busy"][-1]
