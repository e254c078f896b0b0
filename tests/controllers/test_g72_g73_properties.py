"""Seeded properties of G72 and G73 with G70 on random profiles of lines and arcs, checked on the commanded path
(the plan) against the profile's geometry (shapely), not against the planner: G72's rough passes never inside the
profile + allowance, its last pass on it, levels Δd apart, rapids only through air; G73's passes the profile
shifted, never inside the profile + allowance; G70 on the profile."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from lathe_oracle import densify, rapids_in_air
from shapely.geometry import LineString, Polygon

from ncfmu.controllers.g72_g73 import exchanged
from ncfmu.controllers.geometry import sample
from ncfmu.controllers.lathe_program import plan

X0, Z0 = 30.0, 2.0
FAR = 1e3
TOL = 1e-5          # mm: the chords of the profile's arcs sampled 5 um apart lie within 6 nm of them (r >= 0.5)


def num(v: float) -> str:
    return f"{v:.4f}"


def g72_profile(a: float, pieces: list[tuple]) -> tuple[list[str], list[tuple[float, float]]]:
    """The blocks (radius values) and the corner points of a G72 profile: first block Z-a, then the pieces, each
    moving toward the axis and toward +Z (faces, hubs, tapers, quarter arcs)."""
    z, x = -a, X0
    blocks, corners = [], [(z, x)]
    for kind, *v in pieces:
        if kind == "face":
            x -= v[0]
            blocks.append(f"G01 X{num(x)}")
        elif kind == "hub":
            z += v[0]
            blocks.append(f"G01 Z{num(z)}")
        elif kind == "taper":
            z, x = z + v[0], x - v[1]
            blocks.append(f"G01 X{num(x)} Z{num(z)}")
        else:                                   # a quarter circle of radius r: G02 bulging out, G03 in
            r = v[0]
            z, x = z + r, x - r
            blocks.append(f"{'G02' if kind == 'convex' else 'G03'} X{num(x)} Z{num(z)} R{num(r)}")
        corners.append((z, x))
    return blocks, corners


FACE_PIECES = st.one_of(
    st.tuples(st.just("face"), st.floats(0.5, 6.0)),
    st.tuples(st.just("hub"), st.floats(0.3, 3.0)),
    st.tuples(st.just("taper"), st.floats(0.2, 2.0), st.floats(0.5, 5.0)),
    st.tuples(st.sampled_from(["convex", "concave"]), st.floats(0.5, 2.5)),
)


def part_behind(points: list[tuple[float, float]]) -> Polygon:
    """The part (+ allowance) behind a G72 boundary: everything at -Z of it, below its first point's X."""
    (_, xa), (zb, _) = points[0], points[-1]
    return Polygon([*points, (zb, -FAR), (-FAR, -FAR), (-FAR, xa)])


def inside_by(poly: Polygon, segs) -> float:
    """How deep (mm) the moves' points (0.05 mm apart) reach into ``poly`` (<= 0: never inside)."""
    pts = np.concatenate([densify(np.array(sample([g.element], 0.05)), 0.05) for g in segs])
    inside = shapely.contains_xy(poly, pts[:, 0], pts[:, 1])
    if not inside.any():
        return 0.0
    return float(shapely.distance(poly.exterior, shapely.points(pts[inside])).max())


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(a=st.floats(2.0, 10.0), pieces=st.lists(FACE_PIECES, min_size=1, max_size=5), depth=st.floats(0.5, 3.0),
       retract=st.floats(0.0, 1.0), u=st.floats(0.0, 0.5), w=st.floats(0.0, 0.5), diameter=st.booleans())
def test_g72_rough_passes_leave_the_allowance_and_g70_runs_the_profile(a, pieces, depth, retract, u, w, diameter):
    depth, retract, u, w, a = (round(v, 3) for v in (depth, retract, u, w, a))
    blocks, corners = g72_profile(a, pieces)
    (zb, xb) = corners[-1]
    assume(zb <= Z0 - 0.1 and 0.0 <= xb and xb + u < X0 - 0.1 and -a + w < Z0 - 0.1)
    scale = 2.0 if diameter else 1.0
    body = "\n".join(f"N{10 + k} {b}" for k, b in enumerate(blocks[:-1])) + f"\nN99 {blocks[-1]}"
    if diameter:                                  # X and R written in diameters / radius as the X mode says
        body = "\n".join(_diameters(line) for line in body.splitlines())
    text = (f"G18 G21 G90 {'G7' if diameter else 'G8'}\nG00 X{num(X0 * scale)} Z{num(Z0)}\n"
            f"G72 W{num(depth)} R{num(retract)}\nG72 P9 Q99 U{num(u * scale)} W{num(w)} F300\n"
            f"N9 G00 Z{num(-a)}\n{body}\nG70 P9 Q99\nM30\n")
    segments = plan(text, (X0, Z0), 50.0)
    g72 = [g for g in segments if g.cycle == 72]
    profile = sample([g.element for g in segments if g.cycle == 70 and g.subcycle == 2], 0.005)
    boundary = [(z + w, x + u) for z, x in profile]
    # never inside the profile shifted by the allowances
    assert inside_by(part_behind(boundary), [g for g in g72 if g.feed]) <= TOL
    # rapids only through air: seen with Z and X exchanged, G72's stock is G71's
    assert rapids_in_air([type(g)(exchanged(g.element), *_rest(g)) for g in g72], Z0, X0, spacing=0.05) <= 1e-6
    # the levels: Δd apart from the start point's Z, along -X from the start point's X
    last = max(g.pass_no for g in g72)
    levels = [g for g in g72 if g.subcycle == 2 and g.pass_no < last]
    for g in levels:
        assert g.element.start[0] == pytest.approx(g.element.end[0], abs=1e-9)
        assert g.element.start[1] == pytest.approx(X0, abs=1e-9) and g.element.end[1] < X0
    zs = sorted({round(g.element.start[0], 9) for g in levels}, reverse=True)
    assert zs == pytest.approx([Z0 - k * depth for k in range(1, len(zs) + 1)], abs=1e-9)
    # the last pass runs on the shifted profile below the start point's X: the allowance left everywhere
    on = np.array([p for p in boundary if p[1] < X0 - TOL])
    final = LineString(sample([g.element for g in g72 if g.subcycle == 2 and g.pass_no == last], 0.005))
    assert shapely.distance(final, shapely.points(on)).max() <= 1e-5      # chords of 5 um on arcs
    assert (zs[-1] if zs else Z0) - on[:, 0].min() <= depth + 1e-9         # the last pass takes at most Δd
    # G70 runs the profile as programmed: its corners, in order
    g70 = [g for g in segments if g.cycle == 70 and g.subcycle == 2]
    assert [g.element.end for g in g70] == [pytest.approx(c, abs=2e-4) for c in corners[1:]]
    assert segments[-1].element.end == pytest.approx((Z0, X0))


def _diameters(line: str) -> str:
    words = line.split()
    return " ".join(f"X{num(2 * float(w[1:]))}" if w.startswith("X") else w for w in words)


def _rest(g) -> tuple:
    return (g.rate, g.feed, g.subcycle, g.pass_no, g.sigma_x, g.line, g.cycle)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(xa=st.floats(3.0, 15.0), steps=st.lists(st.tuples(st.floats(0.5, 5.0), st.floats(-4.0, 6.0)), min_size=1,
                                                 max_size=5),
       di=st.floats(0.0, 5.0), dk=st.floats(0.0, 3.0), d=st.integers(2, 6), u=st.floats(0.0, 0.5),
       w=st.floats(0.0, 0.5))
def test_g73_passes_are_the_profile_shifted_never_inside_the_allowance(xa, steps, di, dk, d, u, w):
    """A profile toward the chuck, X free (tapers up and down: pockets): every pass the profile shifted by (W +
    Δk (d-k)/(d-1), U + Δi (d-k)/(d-1)); W0 and Δk0 where X falls (a Z shift would move a pocket's wall into the
    part: refused)."""
    xa, di, dk, u, w = (round(v, 3) for v in (xa, di, dk, u, w))
    z, x = 1.0, xa
    corners = [(z, x)]
    for dz, dx in steps:
        z, x = z - round(dz, 3), min(max(x + round(dx, 3), 0.5), 28.0)
        corners.append((z, x))
    falls = any(b[1] < a[1] for a, b in zip(corners, corners[1:]))
    if falls:
        w, dk = 0.0, 0.0
    body = "\n".join(f"G01 X{num(x)} Z{num(z)}" for z, x in corners[1:-1])
    text = (f"G18 G21 G90 G8\nG00 X{num(X0)} Z{num(Z0)}\nG73 U{num(di)} W{num(dk)} R{d}\n"
            f"G73 P9 Q99 U{num(u)} W{num(w)} F300\nN9 G00 X{num(xa)} Z1\n" + (body + "\n" if body else "")
            + f"N99 G01 X{num(corners[-1][1])} Z{num(corners[-1][0])}\nG70 P9 Q99\nM30\n")
    segments = plan(text, (X0, Z0), 50.0)
    g73 = [g for g in segments if g.cycle == 73]
    assert sorted({g.pass_no for g in g73} - {0}) == list(range(1, d + 1))
    part = Polygon([*corners, (corners[-1][0], -FAR), (FAR, -FAR), (FAR, corners[0][1])])
    allowance = Polygon([(cz + w, cx + u) for cz, cx in corners]
                        + [(corners[-1][0] + w, -FAR), (FAR, -FAR), (FAR, corners[0][1] + u)])
    for k in range(1, d + 1):
        f = (d - k) / (d - 1)
        dz, dx = w + dk * f, u + di * f
        cut = [g for g in g73 if g.pass_no == k and g.subcycle == 2]
        assert [g.element.end for g in cut] == [pytest.approx((cz + dz, cx + dx), abs=1e-9) for cz, cx in corners[1:]]
        assert cut[0].element.start == pytest.approx((corners[0][0] + dz, corners[0][1] + dx), abs=1e-9)
    assert inside_by(allowance.intersection(part), [g for g in g73 if g.feed and g.subcycle == 2]) <= TOL
    g70 = [g for g in segments if g.cycle == 70 and g.subcycle == 2]
    assert [g.element.end for g in g70] == [pytest.approx(c, abs=1e-9) for c in corners[1:]]
    assert not math.isnan(np.array([g.element.end for g in segments]).sum())
