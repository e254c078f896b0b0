"""The example lathe part program (docs/examples/lathe_shaft.ngc) closed loop through the FMUs: lathe_roughing
with ``seq.program`` set, the tool path checked against the part's geometry (tests/lathe_oracle.py)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from lathe_oracle import (
    POCKETS,
    SHAFT,
    SHAFT_DEPTH,
    SHAFT_U,
    SHAFT_W,
    below_shifted_profile,
    deepest_cut,
    distances,
    pass_changes,
    shifted_points,
)

from ncfmu.controllers.lathe_program import parse

EXAMPLE = Path(__file__).resolve().parents[2] / "docs" / "examples" / "lathe_shaft.ngc"
STOP = 100.0

pytestmark = pytest.mark.slow


def shaft_part():
    return SHAFT, SHAFT_DEPTH, SHAFT_U, SHAFT_W


@pytest.fixture(scope="module")
def run(ncfmu_run):
    return ncfmu_run("lathe_roughing", stop_time=STOP, start_values={"seq.program": EXAMPLE.read_text()})


def test_cycle_finishes_clear_of_the_chuck(run, ncfmu_checks):
    assert run["seq.done"].any() and not run["seq.alarm"].any()
    ncfmu_checks.assert_alarm(run, "limiter.alarm", raised=False)
    assert run["x_axis.pos"][-1] == pytest.approx(30.0, abs=0.005)
    assert run["z_axis.pos"][-1] == pytest.approx(2.0, abs=0.005)


def test_roughing_against_the_geometry(run):
    part, depth, u, w = shaft_part()
    g71 = run["seq.canned_cycle"] == 71
    z, x = run["seq.z_cmd"][g71], run["seq.x_cmd"][g71]
    # the commanded tool point never below the profile + allowance, at any Z (2 um)
    assert below_shifted_profile(part, u, w, z, x, tol=0.002) <= 0.002
    # the actual tool point neither (the servos follow within microns)
    za, xa = run["z_axis.pos"][g71], run["x_axis.pos"][g71]
    assert below_shifted_profile(part, u, w, za, xa, tol=0.002) <= 0.002
    # after roughing the material left is the allowance everywhere (the actual tool reached all of it, 5 um)
    target = shifted_points(part, u, w, 0.02)
    assert distances(target, np.column_stack([za, xa])).max() <= 0.005
    # SC1..SC4 on every pass, in order; no cut deeper than U
    sub, pass_no = run["seq.subcycle"][g71], run["seq.pass_no"][g71]
    changes = pass_changes(sub, pass_no)
    n = (len(changes) - 1) // 4
    assert n == 11 and changes == [(k, s) for k in range(1, n + 1) for s in (1, 2, 3, 4)] + [(0, 0)]
    assert deepest_cut(30.0, z, x, sub, pass_no) <= depth + 1e-6


def test_finishing_follows_the_profile(run):
    part = shaft_part()[0]
    g70 = (run["seq.canned_cycle"] == 70) & (run["seq.subcycle"] == 2)
    profile = part.points(0.01)
    commanded = np.column_stack([run["seq.z_cmd"][g70], run["seq.x_cmd"][g70]])
    actual = np.column_stack([run["z_axis.pos"][g70], run["x_axis.pos"][g70]])
    assert distances(commanded, profile).max() <= 0.005 and distances(profile, commanded).max() <= 0.005
    assert distances(actual, profile).max() <= 0.010 and distances(profile, actual).max() <= 0.010


def test_line_output_walks_the_program(run):
    lines = EXAMPLE.read_text().split("\n")
    seen = [int(v) for v in np.unique(run["seq.line"]) if v]
    ops = [o for o in parse(EXAMPLE.read_text(), (30.0, 2.0)) if type(o).__name__ != "State"]   # S800 M03
    assert {ops[0].line, ops[1].line} <= set(seen)
    assert all(lines[k - 1].strip() for k in seen)          # only lines holding blocks
    assert set(np.unique(run["seq.canned_cycle"])) == {0, 70, 71}


def test_g7_twin_gives_the_same_path(run, ncfmu_run):
    part, depth, u, w = shaft_part()
    # the example starts the spindle (S800 M03 on its first line): so does its twin
    g7 = part.program(depth, 0.5, u, w, 300, 180, diameter=True, arcs="R").replace("G90 G7\n", "G90 G7 G97 S800 M03\n")
    twin = ncfmu_run("lathe_roughing", stop_time=STOP, start_values={"seq.program": g7})
    assert np.array_equal(twin["seq.x_cmd"], run["seq.x_cmd"]) and np.array_equal(twin["seq.z_cmd"], run["seq.z_cmd"])
    assert np.array_equal(twin["x_axis.pos"], run["x_axis.pos"])


def test_a_refused_program_fails_initialisation(ncfmu_project):
    from ncfmu.errors import NcfmuError
    from ncfmu.project import simulate

    bad = EXAMPLE.read_text().replace("G71 U1.5 R0.5", "G71 U0 R0.5")
    with pytest.raises(NcfmuError, match=r"program: line 6: U0: the depth of cut must be > 0"):
        simulate("lathe_roughing", stop_time=0.01, start_values={"seq.program": bad})


def test_state_mid_program_continues_bit_identically(ncfmu_project):
    """An FMU state saved on the pass along the shifted profile (its radius: an arc move, the plan, the program
    counter) restores and runs on bit for bit."""
    from ncfmu.project import simulate, simulate_branches

    values = {"seq.program": EXAMPLE.read_text()}
    straight = simulate("lathe_roughing", stop_time=69.0, start_values=values)
    at = 66.5
    k = int(np.searchsorted(straight.time, at))
    assert straight["seq.canned_cycle"][k] == 71 and straight["seq.subcycle"][k] == 2
    assert "G02" in EXAMPLE.read_text().split("\n")[int(straight["seq.line"][k]) - 1]
    (branch,) = simulate_branches("lathe_roughing", at, [{}], stop_time=69.0, start_values=values)
    for variable in straight.names:
        assert np.array_equal(branch[variable], straight[variable]), variable


def test_limiter_stops_a_program_that_runs_into_the_chuck(ncfmu_run):
    """A profile down to Z -50: the first pass runs into the chuck zone; the limiter stops the axes at its
    boundary (Z -45) and its alarm stops the sequencer, as for the registers."""
    text = ("G18 G21 G8\nG00 X30 Z2\nG71 U2 R0.5\nG71 P10 Q20 U0.2 W0 F600\n"
            "N10 G00 X20\nG01 Z-50\nN20 X30\nG70 P10 Q20\nM30\n")
    r = ncfmu_run("lathe_roughing", stop_time=12.0, start_values={"seq.program": text})
    assert r["limiter.alarm"].any() and r["seq.alarm"][-1] and not r["seq.busy"][-1]
    z = r["z_axis.pos"]
    assert -46.0 < z.min() <= -44.9
    k = int(np.argmax(r["seq.alarm"]))
    assert r["seq.canned_cycle"][k - 1] == 71 and r["seq.subcycle"][k - 1] == 2 and r["seq.pass_no"][k - 1] == 1
    assert r["seq.line"][-1] == 0 and r["seq.canned_cycle"][-1] == 0
    assert np.abs(r["z_axis.vel"][-100:]).max() < 1e-6                 # at rest


def test_hold_and_restart_through_the_panel(project, tmp_path):
    """The panel holds the first cut of the example and releases it; an alarm stops the cut; START again re-bases
    on the axes, retracts X clear before Z moves, and runs the program from its start."""
    from fakes import unwired  # lathe_roughing with seq.alarm_in free for an input CSV

    from ncfmu.project import simulate

    csv_file = tmp_path / "alarm.csv"
    csv_file.write_text('"time","seq.alarm_in"\n0.0,0\n5.0,1\n5.1,0\n')
    r = simulate(unwired("lathe_roughing", tmp_path), stop_time=9.0, input_csv=csv_file, start_values={
        "seq.program": EXAMPLE.read_text(), "panel.hold_at": 2.0, "panel.release_at": 3.0, "panel.restart_at": 6.0})
    t, x, z = r.time, r["x_axis.pos"], r["z_axis.pos"]
    held = (t > 2.1) & (t < 3.0)
    assert np.ptp(z[held]) < 1e-4 and r["seq.subcycle"][held].min() == 2 and r["seq.busy"][held].all()
    assert np.ptp(z[(t > 3.2) & (t < 3.5)]) > 1.0                      # released: cutting on
    stopped = (t > 5.5) & (t < 6.0)
    assert r["seq.alarm"][stopped].all() and r["seq.line"][stopped].max() == 0
    x_rest, z_rest = x[stopped][-1], z[stopped][-1]
    assert z_rest < -10.0 and x_rest < 29.0
    approach = (t > 6.0) & (r["seq.subcycle"] == 0) & r["seq.busy"].astype(bool)
    moving_z = approach & (np.abs(z - z_rest) > 0.01)
    assert moving_z.any() and (x[moving_z] > 30.0 - 0.01).all()        # Z travels only with X clear
    again = (t > 6.0) & (r["seq.canned_cycle"] == 71)
    assert again.any() and r["seq.pass_no"][again][0] == 1 and r["seq.line"][again][0] == 7
    assert not r["seq.alarm"][t > 6.1].any()


def test_pocket_example_through_the_fmus(ncfmu_run):
    """docs/examples/lathe_pockets.ngc (G7, two grooves): the actual tool never below the profile + U, the
    allowance left everywhere, SC1-SC4 per pass, G70 on the profile (actual axes within 10 um)."""
    text = (EXAMPLE.parent / "lathe_pockets.ngc").read_text()
    r = ncfmu_run("lathe_roughing", stop_time=120.0, start_values={"seq.program": text})      # about 104 s
    assert r["seq.done"].any() and not r["seq.alarm"].any()
    u = 0.3
    g71 = r["seq.canned_cycle"] == 71
    z, x = r["z_axis.pos"][g71], r["x_axis.pos"][g71]
    assert below_shifted_profile(POCKETS, u, 0.0, r["seq.z_cmd"][g71], r["seq.x_cmd"][g71], tol=0.002) <= 0.002
    assert below_shifted_profile(POCKETS, u, 0.0, z, x, tol=0.002) <= 0.002
    assert distances(shifted_points(POCKETS, u, 0.0, 0.02), np.column_stack([z, x])).max() <= 0.005
    sub, pass_no = r["seq.subcycle"][g71], r["seq.pass_no"][g71]
    changes = pass_changes(sub, pass_no)
    n = (len(changes) - 1) // 4
    # levels 28.75 .. 22.5 over everything (6); 21.25 behind the collar (1); 20, 18.75, 17.5 in both grooves (6);
    # 16.25, 15 in the square groove (2); the pass along the shifted profile (1)
    assert n == 16 and changes == [(k, s) for k in range(1, n + 1) for s in (1, 2, 3, 4)] + [(0, 0)]
    g70 = (r["seq.canned_cycle"] == 70) & (r["seq.subcycle"] == 2)
    actual = np.column_stack([r["z_axis.pos"][g70], r["x_axis.pos"][g70]])
    assert distances(actual, POCKETS.points(0.01)).max() <= 0.010
    assert distances(POCKETS.points(0.01), actual).max() <= 0.010
