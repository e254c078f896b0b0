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
from lathe_oracle import (
    BORE,
    BORE_OPTIONS,
    HALF_PI,
    POCKETS,
    SHAFT,
    below_shifted_profile,
    build_part,
    distances,
    fanuc,
    spindle_run,
)

from ncfmu.controllers import CutSequencer

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
    # a bore from a drilled hole of 20 mm (X20.) to 38 mm at its mouth (lathe_oracle.BORE)
    "bore (ID)": (BORE, BORE_OPTIONS),
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
