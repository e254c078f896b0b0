"""A suite of lathe programs written the way Fanuc manuals write them (issue 32, must show): O number, tool and
offset, G50 S / G96 / G99, G71/G70 (type I and II), chamfers, tapers, arcs by R and by I/K, U/W moves, G28, M30 --
each run by the CutSequencer with ideal axes and a plain-Python spindle, judged by the oracle from the profile's
geometry (tests/lathe_oracle.py): roughing never below the profile + allowance, G70 on the profile (3 um), feed =
F x actual rev/min / 60 (2 %), rev/min = min(G50 S, 1000 v / (pi D)) (the command exactly, the spindle 1 %).

Outside work, and one bore (inside work: G71 with U negative roughs outward from the drilled hole), judged as the
outside part it mirrors about the start point's X."""

from __future__ import annotations

import math

import numpy as np
import pytest
from lathe_oracle import POCKETS, SHAFT, Part, below_shifted_profile, build_part, distances, spindle_run

from ncfmu.controllers import CutSequencer


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


HALF_PI = math.pi / 2
#: (part, options): OD work, type I and II, chamfers, tapers, arcs by R and by I/K, U/W moves.
SUITE = {
    "shaft R": (SHAFT, {}),
    "shaft I/K": (SHAFT, {"arcs": "IK"}),
    "shaft U/W": (SHAFT, {"incremental": True}),
    "pockets type II": (POCKETS, {"w": 0.0, "depth": 1.25, "u": 0.3, "type2": True}),
    "pockets I/K U/W": (POCKETS, {"w": 0.0, "depth": 1.25, "u": 0.3, "type2": True, "arcs": "IK",
                                 "incremental": True}),
    "chamfer and steps": (build_part(30.0, 2.0, 10.0, [("z", 2.0), ("taper", 1.0, 1.0), ("z", 8.0), ("face", 6.0),
                                                       ("z", 10.0), ("face", 6.0), ("z", 5.0), ("face", 7.0)]), {}),
    "long taper": (build_part(30.0, 2.0, 12.0, [("z", 2.0), ("taper", 30.0, 10.0), ("z", 5.0), ("face", 8.0)]),
                   {"depth": 2.0, "s_max": 2000.0}),
    "ball end": (build_part(30.0, 2.0, 0.0, [("convex", 10.0, 0.0, HALF_PI), ("z", 15.0), ("face", 20.0)]),
                 {"depth": 2.0, "v": 150.0}),
    "fillets": (build_part(30.0, 2.0, 15.0, [("z", 5.0), ("concave", 3.0, -HALF_PI, -math.pi), ("z", 6.0),
                                             ("convex", 2.0, 0.0, HALF_PI), ("z", 6.0), ("face", 7.0)]),
                {"arcs": "IK", "u": 0.25, "w": 0.05}),
    "slow surface speed": (SHAFT, {"v": 90.0, "s_max": 1200.0, "f_rough": 0.3, "f_finish": 0.08}),
    # a bore from a drilled hole of 20 mm (X20.) to 38 mm at its mouth: a chamfer, a convex corner (a concave arc
    # of the mirrored part), a step, a taper, a face down to the hole -- roughed outward with U-0.4
    "bore (ID)": (build_part(10.0, 2.0, 1.0, [("z", 2.0), ("taper", 1.0, 1.0), ("z", 8.0),
                                             ("concave", 2.0, -HALF_PI, -math.pi), ("face", 1.0), ("z", 6.0),
                                             ("taper", 6.0, 2.0), ("z", 5.0), ("face", 3.0)]),
                  {"inside": True, "depth": 1.0, "u": 0.2, "w": 0.1, "arcs": "IK", "incremental": True}),
}


@pytest.mark.slow                  # ten whole programs: 10-15 s each on 2 loaded cores
@pytest.mark.parametrize("name", list(SUITE))
def test_a_fanuc_program_against_its_geometry(name):
    part, options = SUITE[name]
    o = 1001 + list(SUITE).index(name)
    text = fanuc(part, o, **options)
    assert text.startswith(f"%\nO{o}") and "T0101" in text and "G28 U0 W0" in text and "M30" in text
    run = spindle_run(CutSequencer(program=text, x_start=part.x0, z_start=part.z0))
    assert run["done"][-1] and not run["alarm"].any(), name
    u, w = options.get("u", 0.2), options.get("w", 0.1)
    g71 = run["canned_cycle"] == 71
    # a bore is judged as the outside part it mirrors (the oracle's geometry): X mirrored about the start point's
    x_part = 2 * part.x0 - run["x_cmd"] if options.get("inside") else run["x_cmd"]
    if options.get("inside"):       # the cuts go outward from the hole (above its X less U), the retracts
        cuts = g71 & (run["subcycle"] == 2)        # into it (air)
        assert run["x_cmd"][cuts].min() >= part.x0 - u - 1e-9 and run["x_cmd"][cuts].max() > part.x0 + 8.0
        assert run["x_cmd"][g71].min() < part.x0
    assert below_shifted_profile(part, u, w, run["z_cmd"][g71], x_part[g71], tol=0.002) <= 0.002
    g70 = (run["canned_cycle"] == 70) & (run["subcycle"] == 2)
    path, profile = np.column_stack([run["z_cmd"][g70], x_part[g70]]), part.points(0.01)
    assert distances(path, profile).max() <= 0.003 and distances(profile, path).max() <= 0.005
    # feed per revolution from the actual speed; the constant surface speed at the tool's diameter
    v = np.hypot(run["x_vff"], run["z_vff"])
    steady = (run["subcycle"] == 2) & (run["canned_cycle"] > 0) & (np.abs(np.diff(v, prepend=v[0])) < 1e-6) & (v > 0)
    f = np.where(run["canned_cycle"] == 71, options.get("f_rough", 0.25), options.get("f_finish", 0.1))
    assert np.abs(v[steady] / (f[steady] * np.abs(run["speed"][steady]) / 60.0) - 1.0).max() <= 0.02
    cutting = (run["subcycle"] == 2) & (run["canned_cycle"] > 0)
    with np.errstate(divide="ignore"):                 # at the axis (X 0) the surface speed asks for no end
        wanted = np.minimum(options.get("s_max", 2500.0),
                            1000.0 * options.get("v", 180.0) / (math.pi * 2 * run["x_cmd"]))
    assert np.allclose(run["s_cmd"][cutting], wanted[cutting], rtol=1e-12)
    assert np.abs(np.abs(run["speed"][steady]) / wanted[steady] - 1.0).max() <= 0.01
    # and at the end: at the machine reference, spindle and coolant off
    assert (run["x_cmd"][-1], run["z_cmd"][-1]) == (50.0, 50.0) and run["spindle_dir"][-1] == 0
