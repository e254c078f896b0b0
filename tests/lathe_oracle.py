"""An oracle for lathe part programs, written from the geometry (not from the planner).

A turned part is a chain of pieces from its start (X ``a_x`` at the start point's Z) toward the chuck:
straight lines and arcs, every one monotone (Z falls, X never falls: Fanuc's type I). From it come the
program text (G8 radius or G7 diameter, arcs by I/K or R) and the checks of a tool path:

- roughing never below the profile shifted by the allowances (W in Z, U in X), at any Z;
- after roughing, the material left is that shifted profile: the tool reached every point of it;
- no pass deeper than U; SC1..SC4 in order on every pass;
- finishing follows the profile.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class Piece:
    start: tuple[float, float]          # (z, x)
    end: tuple[float, float]
    centre: tuple[float, float] | None = None   # arcs: (z, x); convex: centre below the surface
    convex: bool = False

    @property
    def radius(self) -> float:
        assert self.centre is not None
        return math.dist(self.start, self.centre)

    def x_low(self, z: float) -> float:
        """Lowest X of the piece at ``z`` (inside its Z range)."""
        (z0, x0), (z1, x1) = self.start, self.end
        if self.centre is None:
            if abs(z0 - z1) < 1e-12:
                return min(x0, x1)
            return x0 + (x1 - x0) * (z - z0) / (z1 - z0)
        cz, cx = self.centre
        h = math.sqrt(max(self.radius ** 2 - (z - cz) ** 2, 0.0))
        return cx + h if self.convex else cx - h

    def points(self, spacing: float) -> list[tuple[float, float]]:
        if self.centre is None:
            n = max(1, math.ceil(math.dist(self.start, self.end) / spacing))
            return [(self.start[0] + (self.end[0] - self.start[0]) * i / n,
                     self.start[1] + (self.end[1] - self.start[1]) * i / n) for i in range(n + 1)]
        cz, cx = self.centre
        a0 = math.atan2(self.start[1] - cx, self.start[0] - cz)
        a1 = math.atan2(self.end[1] - cx, self.end[0] - cz)
        if self.convex:       # counter-clockwise (G03): the angle rises
            a1 = a1 if a1 >= a0 else a1 + 2 * math.pi
        else:                 # clockwise (G02): the angle falls
            a1 = a1 if a1 <= a0 else a1 - 2 * math.pi
        n = max(1, math.ceil(abs(a1 - a0) * self.radius / spacing))
        return [(cz + self.radius * math.cos(a0 + (a1 - a0) * i / n),
                 cx + self.radius * math.sin(a0 + (a1 - a0) * i / n)) for i in range(n + 1)]


@dataclass
class Part:
    x0: float                   # cycle start point X (radius) and Z
    z0: float
    a_x: float                  # the profile starts at (a_x, z0)
    pieces: list[Piece] = field(default_factory=list)

    @property
    def end(self) -> tuple[float, float]:
        return self.pieces[-1].end

    def x_low(self, z: float) -> float:
        """The profile's lowest X at ``z`` (the lower end of a vertical face); z in [end Z, z0]."""
        return min(p.x_low(z) for p in self.pieces
                   if min(p.start[0], p.end[0]) - 1e-12 <= z <= max(p.start[0], p.end[0]) + 1e-12)

    def x_low_array(self, z: np.ndarray) -> np.ndarray:
        """:meth:`x_low` for an array of Z, each in [end Z, z0]."""
        out = np.full(len(z), np.inf)
        for p in self.pieces:
            (z0, x0), (z1, x1) = p.start, p.end
            inside = (z >= min(z0, z1) - 1e-12) & (z <= max(z0, z1) + 1e-12)
            zi = z[inside]
            if p.centre is None:
                v = np.full(len(zi), min(x0, x1)) if abs(z0 - z1) < 1e-12 else x0 + (x1 - x0) * (zi - z0) / (z1 - z0)
            else:
                h = np.sqrt(np.maximum(p.radius ** 2 - (zi - p.centre[0]) ** 2, 0.0))
                v = p.centre[1] + h if p.convex else p.centre[1] - h
            out[inside] = np.minimum(out[inside], v)
        return out

    def points(self, spacing: float) -> np.ndarray:
        return np.array([pt for p in self.pieces for pt in p.points(spacing)])

    def program(self, depth: float, retract: float, u: float, w: float, f_rough: float, f_finish: float,
                diameter: bool = False, arcs: str = "IK") -> str:
        k = 2.0 if diameter else 1.0

        def num(v: float) -> str:
            return f"{v:.6f}".rstrip("0").rstrip(".") if "." in f"{v:.6f}" else f"{v}"

        lines = ["%", "G18 G21 G90 " + ("G7" if diameter else "G8"),
                 f"G00 X{num(k * self.x0)} Z{num(self.z0)}",
                 f"G71 U{num(depth)} R{num(retract)}",
                 f"G71 P10 Q20 U{num(k * u)} W{num(w)} F{num(f_rough)}",
                 f"N10 G00 X{num(k * self.a_x)}"]
        for i, p in enumerate(self.pieces):
            n = "N20 " if i == len(self.pieces) - 1 else ""
            end = f"X{num(k * p.end[1])} Z{num(p.end[0])}"
            if p.centre is None:
                lines.append(f"{n}G01 {end}")
            elif arcs == "R":
                lines.append(f"{n}G0{3 if p.convex else 2} {end} R{num(p.radius)}")
            else:
                lines.append(f"{n}G0{3 if p.convex else 2} {end} I{num(p.centre[1] - p.start[1])} "
                             f"K{num(p.centre[0] - p.start[0])}")
        lines += [f"G70 P10 Q20 F{num(f_finish)}", "M30", "%"]
        return "\n".join(lines) + "\n"


def r6(v: float) -> float:
    return round(v, 6)


def build_part(x0: float, z0: float, a_x: float, specs: list[tuple]) -> Part:
    """A part from piece specifications, coordinates on a 1e-6 mm grid (so G7's doubled X halves back exactly):
    ``("z", length)``, ``("taper", dz, dx)``, ``("face", dx)``, ``("convex", r, a0, a1)`` (angles in
    [0, pi/2], a0 < a1), ``("concave", r, a0, a1)`` (angles in [-pi, -pi/2], a0 > a1)."""
    part = Part(x0, z0, a_x)
    z, x = z0, a_x
    for spec in specs:
        kind = spec[0]
        if kind in ("convex", "concave"):
            r, a0, a1 = spec[1:]
            cz, cx = r6(z - r * math.cos(a0)), r6(x - r * math.sin(a0))
            end = (r6(cz + r * math.cos(a1)), r6(cx + r * math.sin(a1)))
            piece = Piece((z, x), end, (cz, cx), kind == "convex")
        else:
            dz, dx = (spec[1], 0.0) if kind == "z" else (0.0, spec[1]) if kind == "face" else (spec[1], spec[2])
            end = (r6(z - dz), r6(x + dx))
            piece = Piece((z, x), end)
        part.pieces.append(piece)
        z, x = piece.end
    return part


# -- checks of a tool path ---------------------------------------------------------------------------
def densify(path: np.ndarray, spacing: float) -> np.ndarray:
    """The polyline ``path`` with points inserted so that no piece is longer than ``spacing``."""
    d = np.diff(path, axis=0)
    n = np.maximum(1, np.ceil(np.hypot(d[:, 0], d[:, 1]) / spacing).astype(int))
    k = np.repeat(np.arange(len(d)), n)
    frac = (np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)) / np.repeat(n, n)
    return np.vstack([path[k] + frac[:, None] * d[k], path[-1:]])


def distances(points: np.ndarray, path: np.ndarray) -> np.ndarray:
    """Distance of each point (m x 2, (z, x)) from the polyline ``path`` (n x 2), overestimated by at most
    0.5 um (the polyline is densified to 1 um)."""
    from scipy.spatial import cKDTree

    dist, _ = cKDTree(densify(path, 0.001)).query(points)
    return np.asarray(dist)


def below_shifted_profile(part: Part, u: float, w: float, z: np.ndarray, x: np.ndarray, tol: float) -> float:
    """How far the deepest tool point lies below the profile shifted by (W, U), within ``tol`` in Z (mm; <= 0:
    never below). Beyond the profile's shifted end the tool must not go at all (below the end's X)."""
    z, x = np.asarray(z, float), np.asarray(x, float)
    zb = part.end[0]
    worst = -math.inf
    beyond = z - w + tol < zb
    if beyond.any():
        past = beyond & (x < part.end[1] + u)
        worst = float((zb - (z[past] - w + tol)).max()) if past.any() else worst
    z, x = z[~beyond], x[~beyond]
    # the lowest profile within tol in Z (a wall there: its foot)
    lowest = np.full(len(z), np.inf)
    for zc in (z - w - tol, z - w, z - w + tol):
        lowest = np.minimum(lowest, part.x_low_array(np.clip(zc, zb, part.z0)))
    return max(worst, float((lowest + u - x).max())) if len(z) else worst


def shifted_points(part: Part, u: float, w: float, spacing: float) -> np.ndarray:
    """Points of the profile shifted by the allowances, from the start point's Z on."""
    pts = part.points(spacing) + np.array([w, u])
    return pts[pts[:, 0] < part.z0 - 1e-9]          # the stock lies behind the start point's Z


def pass_changes(sub: np.ndarray, pass_no: np.ndarray) -> list[tuple[int, int]]:
    """(pass, sub-cycle) at every change of either."""
    out: list[tuple[int, int]] = []
    for p, s in zip(pass_no, sub):
        if not out or out[-1] != (int(p), int(s)):
            out.append((int(p), int(s)))
    return out


def rapids_in_air(segments, x0: float, z0: float, spacing: float = 0.01) -> float:
    """How deep (mm) any rapid move of a plan goes into the material the cuts before it left (<= 0: never); the
    stock is X ``x0`` behind Z ``z0``, every feed move cuts down to where it passes."""
    from ncfmu.controllers.geometry import sample

    floor: dict[int, float] = {}
    worst = -math.inf
    for seg in segments:
        pts = densify(np.array(sample([seg.element], 0.01)), spacing / 2)
        for z, x in pts:
            b = round(z / spacing)
            top = floor.get(b, x0 if z < z0 - 1e-9 else -math.inf)
            if seg.feed:
                floor[b] = min(top, x)
            else:
                worst = max(worst, top - x)
    return worst


def deepest_cut(x0: float, z: np.ndarray, x: np.ndarray, sub: np.ndarray, pass_no: np.ndarray) -> float:
    """The largest depth of cut of any SC2: how far below everything cut before at that Z (the stock's X
    ``x0`` where nothing was) the tool goes, mm."""
    grid = np.round(np.arange(z.min(), z.max() + 0.01, 0.01), 6)
    floor = np.full(len(grid), x0)                    # lowest X cut so far at each Z
    deepest = 0.0
    for k in sorted(set(int(p) for p in pass_no[sub == 2])):
        sel = (sub == 2) & (pass_no == k)
        zs, xs = densify(np.column_stack([z[sel], x[sel]]), 0.002).T   # every bin the cut passes
        idx = np.clip(np.round((zs - grid[0]) / 0.01).astype(int), 0, len(grid) - 1)
        deepest = max(deepest, float((floor[idx] - xs).max()))
        np.minimum.at(floor, idx, xs)
    return deepest


# -- the controller with ideal servo feedback ----------------------------------------------------------
RECORD = ("x_cmd", "z_cmd", "x_vff", "z_vff", "subcycle", "pass_no", "sigma_x", "line", "canned_cycle", "busy",
          "done", "alarm")


def run_ideal(seq, dt: float = 1e-3, limit: int = 1_000_000, events=None) -> dict[str, np.ndarray]:
    """Press START and step the sequencer until done (the axes stand where commanded, always in position; the
    spindle turns at the speed commanded). ``events(k, inputs)`` may change the inputs before step ``k``. Returns
    every output per step, and ``t``."""
    inputs = {"start": True, "feed_hold": False, "feed_override": 1.0, "x_pos": seq.x_cmd, "z_pos": seq.z_cmd,
              "x_in_position": True, "z_in_position": True, "alarm_in": False, "spindle_speed": 0.0}
    rows = []
    for k in range(limit):
        if events is not None:
            events(k, inputs)
        out = seq.step(k * dt, dt, inputs)
        inputs["start"] = False
        inputs["x_pos"], inputs["z_pos"] = out["x_cmd"], out["z_cmd"]
        inputs["spindle_speed"] = out["s_cmd"] * out["spindle_dir"]
        rows.append(tuple(out[name] for name in RECORD))
        if out["done"]:
            break
    else:
        raise AssertionError("the cycle did not finish")
    cols = {name: np.array([r[i] for r in rows]) for i, name in enumerate(RECORD)}
    cols["t"] = np.arange(1, len(rows) + 1) * dt
    return cols


#: The example part program's part (docs/examples/lathe_shaft.ngc), from its drawing: a chamfer, a taper, a
#: radius R4 into a shoulder, and a face up to the start point's X. Start point X 30, Z 2.
SHAFT = build_part(30.0, 2.0, 14.0, [("z", 2.0), ("taper", 2.0, 2.0), ("z", 10.0), ("taper", 8.0, 4.0), ("z", 6.0),
                                     ("concave", 4.0, -math.pi / 2, -math.pi), ("face", 3.0), ("z", 10.0),
                                     ("face", 3.0)])
#: The example's G71 words: depth of cut U, retract R, allowances U (radius) and W.
SHAFT_DEPTH, SHAFT_RETRACT, SHAFT_U, SHAFT_W = 1.5, 0.5, 0.2, 0.1

#: The pocket example's part (docs/examples/lathe_pockets.ngc, written there in diameters): a collar, a square
#: groove, a taper back up, a convex radius falling into a second groove, a concave radius out of it, a shoulder.
POCKETS = build_part(30.0, 2.0, 22.0, [("z", 5.0), ("face", -8.0), ("z", 6.0), ("taper", 4.0, 6.0), ("z", 3.0),
                                       ("convex", 3.0, math.pi / 2, math.pi), ("z", 4.0),
                                       ("concave", 2.5, -math.pi / 2, -math.pi), ("z", 3.0), ("face", 30.0 - 22.5)])


#: What :func:`spindle_run` records of the sequencer (and the spindle's speed).
HALF_PI = math.pi / 2
# a bore from a drilled hole of 20 mm (X20.) to 38 mm at its mouth, given as the outside part it mirrors about the
# start point's X: a chamfer, a convex corner (a concave arc of the mirrored part), a step, a taper, a face down
# to the hole -- roughed outward with U-0.4 (the Fanuc suite's, and the part check's bore)
BORE = build_part(10.0, 2.0, 1.0, [("z", 2.0), ("taper", 1.0, 1.0), ("z", 8.0), ("concave", 2.0, -HALF_PI, -math.pi),
                                   ("face", 1.0), ("z", 6.0), ("taper", 6.0, 2.0), ("z", 5.0), ("face", 3.0)])
BORE_OPTIONS = {"inside": True, "depth": 1.0, "u": 0.2, "w": 0.1, "arcs": "IK", "incremental": True}


OUT = ("x_cmd", "z_cmd", "x_vff", "z_vff", "subcycle", "line", "canned_cycle", "busy", "done", "alarm", "tool",
       "s_cmd", "spindle_dir", "coolant")


def spindle_run(seq, dt: float = 1e-3, limit: int = 600_000, tau: float = 0.05, events=None):
    """START, then step until done: ideal axes, a spindle reaching its command with time constant ``tau``."""
    inputs = {"start": True, "feed_hold": False, "feed_override": 1.0, "x_pos": seq.x_cmd, "z_pos": seq.z_cmd,
              "x_in_position": True, "z_in_position": True, "alarm_in": False, "spindle_speed": 0.0,
              "optional_stop": False}
    rows, speed = [], 0.0
    for k in range(limit):
        if events is not None:
            events(k, inputs)
        out = seq.step(k * dt, dt, inputs)
        inputs["start"] = False
        inputs["x_pos"], inputs["z_pos"] = out["x_cmd"], out["z_cmd"]
        target = out["s_cmd"] * out["spindle_dir"]
        speed += (target - speed) * (1.0 - math.exp(-dt / tau))
        inputs["spindle_speed"] = speed
        rows.append((*(out[n] for n in OUT), speed))
        if out["done"] or out["alarm"]:
            break
    cols = {n: np.array([r[i] for r in rows]) for i, n in enumerate((*OUT, "speed"))}
    cols["t"] = np.arange(1, len(rows) + 1) * dt
    return cols


# -- programs in Fanuc's form ---------------------------------------------------------------------
def num(v: float) -> str:
    """A Fanuc number: always with its decimal point (X60. Z-2.5)."""
    text = f"{v:.6f}".rstrip("0")
    return text if text != "-0." else "0."


def fanuc(part: Part, o: int, *, depth: float = 1.5, retract: float = 0.5, u: float = 0.2, w: float = 0.1,
          f_rough: float = 0.25, f_finish: float = 0.1, v: float = 180.0, s_max: float = 2500.0, arcs: str = "R",
          incremental: bool = False, type2: bool = False, inside: bool = False) -> str:
    """The program of ``part`` in Fanuc's form, X on the diameter; ``incremental``: the profile in U/W.
    ``inside``: ``part`` is a bore mirrored about the start point's X (an outside profile below it): the program
    is the bore's -- X mirrored back, G02 and G03 swapped, U negative (Fanuc's sign of an inside allowance)."""
    sign = -1.0 if inside else 1.0

    def x(v: float) -> str:                     # a radius of the (mirrored) part as the program's diameter
        return num(2 * (2 * part.x0 - v if inside else v))

    def g(convex: bool) -> str:
        return "G03" if convex != inside else "G02"

    lines = ["%", f"O{o:04d} (PART {o})", "N1 G21 G40 G99", "N2 T0101", f"N3 G50 S{num(s_max)}",
             f"N4 G96 S{num(v)} M03", f"N5 G00 X{x(part.x0)} Z{num(part.z0)} M08",
             f"N6 G71 U{num(depth)} R{num(retract)}",
             f"N7 G71 P10 Q20 U{num(sign * 2 * u)} W{num(w)} F{num(f_rough)}",
             f"N10 G00 X{x(part.a_x)}" + (" W0" if type2 else "")]
    for i, p in enumerate(part.pieces):
        n = "N20 " if i == len(part.pieces) - 1 else ""
        if incremental:
            end = f"U{num(sign * 2 * (p.end[1] - p.start[1]))} W{num(p.end[0] - p.start[0])}"
        else:
            end = f"X{x(p.end[1])} Z{num(p.end[0])}"
        if p.centre is None:
            lines.append(f"{n}G01 {end}")
        elif arcs == "R":
            lines.append(f"{n}{g(p.convex)} {end} R{num(p.radius)}")
        else:
            lines.append(f"{n}{g(p.convex)} {end} I{num(sign * (p.centre[1] - p.start[1]))} "
                         f"K{num(p.centre[0] - p.start[0])}")
    lines += [f"N21 G70 P10 Q20 F{num(f_finish)}", "N22 G28 U0 W0 M09", "N23 M05", "N24 M30", "%"]
    return "\n".join(lines) + "\n"
