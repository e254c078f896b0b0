"""Seeded properties of G71/G70 on random monotone profiles of lines and arcs (Fanuc's type I), random depth
of cut U, retract R and allowances, run by the CutSequencer with ideal servo feedback and checked against the
part's geometry (tests/lathe_oracle.py), not against the planner."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, reject, settings
from hypothesis import strategies as st
from lathe_oracle import (
    below_shifted_profile,
    build_part,
    deepest_cut,
    distances,
    pass_changes,
    rapids_in_air,
    run_ideal,
    shifted_points,
)

from ncfmu.controllers import CutSequencer
from ncfmu.controllers.lathe_program import plan
from ncfmu.errors import ProgramError

X0, Z0 = 30.0, 2.0


@st.composite
def arcs(draw, kind: str):
    r = draw(st.floats(0.5, 3.0))
    span = draw(st.floats(0.2, math.pi / 2))
    first = draw(st.floats(0.0, math.pi / 2 - span))
    if kind == "convex":                          # counter-clockwise within [0, pi/2]
        return ("convex", r, first, first + span)
    return ("concave", r, -math.pi / 2 - first, -math.pi / 2 - first - span)   # clockwise within [-pi, -pi/2]


PIECES = st.one_of(
    st.tuples(st.just("z"), st.floats(0.5, 6.0)),
    st.tuples(st.just("taper"), st.floats(0.5, 6.0), st.floats(0.2, 2.5)),
    st.tuples(st.just("face"), st.floats(0.3, 2.5)),
    arcs("convex"),
    arcs("concave"),
)


@pytest.mark.slow
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(a_x=st.floats(3.0, 10.0), specs=st.lists(PIECES, min_size=2, max_size=6),
       depth=st.floats(0.5, 3.0), retract=st.floats(0.0, 1.0), u=st.floats(0.0, 0.5), w=st.floats(0.0, 0.5),
       diameter=st.booleans(), arc_words=st.sampled_from(["IK", "R"]))
def test_random_monotone_profiles(a_x, specs, depth, retract, u, w, diameter, arc_words):
    depth, retract, u, w, a_x = (round(v, 3) for v in (depth, retract, u, w, a_x))
    part = build_part(X0, Z0, a_x, specs)
    assume(part.end[0] < Z0 - w - 0.1)
    text = part.program(depth, retract, u, w, 600, 600, diameter=diameter, arcs=arc_words)
    twin = part.program(depth, retract, u, w, 600, 600, diameter=not diameter, arcs=arc_words)
    assert plan(text, (X0, Z0), 50.0) == plan(twin, (X0, Z0), 50.0)        # G7 and G8: the same path
    assert rapids_in_air(plan(text, (X0, Z0), 50.0), X0, Z0) <= 1e-6        # rapids only through air
    run = run_ideal(CutSequencer(program=text, x_start=X0, z_start=Z0), dt=2e-3)
    assert not run["alarm"].any()
    g71 = run["canned_cycle"] == 71
    z, x, sub, pass_no = run["z_cmd"][g71], run["x_cmd"][g71], run["subcycle"][g71], run["pass_no"][g71]
    # never below the profile + allowance (shifted by W, U), at any Z
    assert below_shifted_profile(part, u, w, z, x, tol=0.002) <= 0.002
    # the material left is the allowance everywhere: the tool reached every point of the shifted profile
    assert distances(shifted_points(part, u, w, 0.02), np.column_stack([z, x])).max() <= 0.005
    # ... and the pass along it stays on it (no detour, no spurious half circle with an allowance)
    last = (sub == 2) & (pass_no == pass_no.max())
    assert distances(np.column_stack([z[last], x[last]]), part.points(0.01) + np.array([w, u])).max() <= 0.005
    # SC1..SC4 in order on every pass, then back to the start point; no cut deeper than U
    changes = pass_changes(sub, pass_no)
    n = (len(changes) - 1) // 4
    assert changes == [(k, s) for k in range(1, n + 1) for s in (1, 2, 3, 4)] + [(0, 0)]
    assert deepest_cut(X0, z, x, sub, pass_no) <= depth + 1e-6
    # G70 runs on the profile, all of it
    g70 = (run["canned_cycle"] == 70) & (run["subcycle"] == 2)
    path = np.column_stack([run["z_cmd"][g70], run["x_cmd"][g70]])
    profile = part.points(0.01)
    assert distances(path, profile).max() <= 0.005
    assert distances(profile, path).max() <= 0.005
    assert (run["x_cmd"][-1], run["z_cmd"][-1]) == (X0, Z0)


@pytest.mark.parametrize("kind", ["convex", "concave"])
def test_quarter_arcs_both_ways(kind):
    """A fillet of each kind, the full quarter circle, with both allowances."""
    spec = ("convex", 3.0, 0.0, math.pi / 2) if kind == "convex" else ("concave", 3.0, -math.pi / 2, -math.pi)
    part = build_part(X0, Z0, 10.0, [("z", 5.0), spec, ("z", 5.0), ("face", 30.0 - 13.0)])
    run = run_ideal(CutSequencer(program=part.program(1.0, 0.3, 0.25, 0.15, 600, 600), x_start=X0, z_start=Z0),
                    dt=2e-3)
    g71 = run["canned_cycle"] == 71
    z, x = run["z_cmd"][g71], run["x_cmd"][g71]
    assert below_shifted_profile(part, 0.25, 0.15, z, x, tol=0.002) <= 0.002
    assert distances(shifted_points(part, 0.25, 0.15, 0.01), np.column_stack([z, x])).max() <= 0.005


@st.composite
def falling_arcs(draw, kind: str):
    r = draw(st.floats(0.5, 3.0))
    span = draw(st.floats(0.2, math.pi / 2))
    first = draw(st.floats(0.0, math.pi / 2 - span))
    if kind == "convex":                          # counter-clockwise within [pi/2, pi]: X falls
        return ("convex", r, math.pi / 2 + first, math.pi / 2 + first + span)
    return ("concave", r, -first, -first - span)  # clockwise within [-pi/2, 0]: X falls


FALLING = st.one_of(
    st.tuples(st.just("taper"), st.floats(0.5, 6.0), st.floats(-4.0, -0.2)),
    st.tuples(st.just("face"), st.floats(-4.0, -0.3)),
    falling_arcs("convex"),
    falling_arcs("concave"),
)


@pytest.mark.slow
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(a_x=st.floats(8.0, 20.0), specs=st.lists(st.one_of(PIECES, FALLING), min_size=3, max_size=7),
       depth=st.floats(0.5, 3.0), retract=st.floats(0.0, 1.0), u=st.floats(0.0, 0.5))
def test_random_profiles_with_pockets(a_x, specs, depth, retract, u):
    """Type II: X may fall along -Z (pockets, undercuts); W is 0. Never below the profile + U, the allowance left
    everywhere, rapids only through air, SC1-SC4 per pass, no cut deeper than U, G70 on the profile."""
    depth, retract, u, a_x = (round(v, 3) for v in (depth, retract, u, a_x))
    part = build_part(X0, Z0, a_x, specs)
    xs = [x for p in part.pieces for x in (p.start[1], p.end[1])]
    assume(part.end[0] < Z0 - 0.1 and 0.5 <= min(xs) and max(xs) <= 29.0)
    text = part.program(depth, retract, u, 0.0, 600, 600)
    try:
        segments = plan(text, (X0, Z0), 50.0)
    except ProgramError as err:                  # a groove of no width is refused, naming its wall
        if "a groove of no width" not in str(err):
            raise
        reject()
    assert rapids_in_air(segments, X0, Z0) <= 1e-6
    run = run_ideal(CutSequencer(program=text, x_start=X0, z_start=Z0), dt=2e-3)
    assert not run["alarm"].any()
    g71 = run["canned_cycle"] == 71
    z, x, sub, pass_no = run["z_cmd"][g71], run["x_cmd"][g71], run["subcycle"][g71], run["pass_no"][g71]
    assert below_shifted_profile(part, u, 0.0, z, x, tol=0.002) <= 0.002
    assert distances(shifted_points(part, u, 0.0, 0.02), np.column_stack([z, x])).max() <= 0.005
    changes = pass_changes(sub, pass_no)
    n = (len(changes) - 1) // 4
    assert changes == [(k, s) for k in range(1, n + 1) for s in (1, 2, 3, 4)] + [(0, 0)]
    assert deepest_cut(X0, z, x, sub, pass_no) <= depth + 1e-6
    g70 = (run["canned_cycle"] == 70) & (run["subcycle"] == 2)
    path = np.column_stack([run["z_cmd"][g70], run["x_cmd"][g70]])
    assert distances(path, part.points(0.01)).max() <= 0.005
    assert distances(part.points(0.01), path).max() <= 0.005
