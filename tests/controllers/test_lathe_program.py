"""Lathe part programs (G71 stock removal, G70 finishing) in the CutSequencer, with ideal servo feedback:
the tool path checked against the part's geometry (tests/lathe_oracle.py), and the parser's refusals."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from lathe_oracle import (
    POCKETS,
    SHAFT,
    SHAFT_DEPTH,
    SHAFT_RETRACT,
    SHAFT_U,
    SHAFT_W,
    below_shifted_profile,
    deepest_cut,
    distances,
    pass_changes,
    rapids_in_air,
    run_ideal,
    shifted_points,
)

from ncfmu.controllers import Block, CutSequencer
from ncfmu.controllers.lathe_program import parse, plan
from ncfmu.errors import ProgramError

EXAMPLE = Path(__file__).resolve().parents[2] / "docs" / "examples" / "lathe_shaft.ngc"
DEPTH, RETRACT, U, W = SHAFT_DEPTH, SHAFT_RETRACT, SHAFT_U, SHAFT_W


def program_run(text: str, **kw) -> dict[str, np.ndarray]:
    return run_ideal(CutSequencer(program=text, x_start=30.0, z_start=2.0), **kw)


@pytest.fixture(scope="module")
def shaft() -> dict[str, np.ndarray]:
    return program_run(EXAMPLE.read_text())


def test_example_roughing_never_below_profile_plus_allowance(shaft):
    g71 = shaft["canned_cycle"] == 71
    assert g71.sum() > 1000
    z, x = shaft["z_cmd"][g71], shaft["x_cmd"][g71]
    assert below_shifted_profile(SHAFT, U, W, z, x, tol=0.002) <= 0.002
    # the plainer form of the rule: at every Z the tool stays above the profile + U
    inside = (z <= SHAFT.z0) & (z >= SHAFT.end[0])
    assert all(xi >= SHAFT.x_low(min(zi + 0.002, SHAFT.z0)) + U - 0.002 for zi, xi in zip(z[inside], x[inside]))


def test_the_oracle_sees_a_gouge_and_a_step(shaft):
    """The checks can fail: the roughing path 5 um lower is below the profile + allowance; without the pass along
    the shifted profile the steps are left."""
    g71 = shaft["canned_cycle"] == 71
    z, x = shaft["z_cmd"][g71], shaft["x_cmd"][g71]
    assert below_shifted_profile(SHAFT, U, W, z, x - 0.005, tol=0.002) > 0.002
    passes = shaft["pass_no"][g71] < shaft["pass_no"][g71].max()
    left = distances(shifted_points(SHAFT, U, W, 0.02), np.column_stack([z[passes], x[passes]]))
    assert left.max() > 0.5                                        # the steps on the taper and the radius


def test_example_leaves_the_allowance_everywhere(shaft):
    """The tool reached every point of the profile shifted by (W, U): no steps left on the taper and the radius."""
    g71 = shaft["canned_cycle"] == 71
    path = np.column_stack([shaft["z_cmd"][g71], shaft["x_cmd"][g71]])
    target = shifted_points(SHAFT, U, W, 0.02)
    assert len(target) > 2000
    assert distances(target, path).max() <= 0.005
    # and the pass along it is on it: no detour, no spurious half circle where an allowance is given (the defect
    # LinuxCNC's G71 has), no arc other than the profile's own, shifted
    last = g71 & (shaft["subcycle"] == 2) & (shaft["pass_no"] == shaft["pass_no"][g71].max())
    along = np.column_stack([shaft["z_cmd"][last], shaft["x_cmd"][last]])
    assert distances(along, SHAFT.points(0.01) + np.array([W, U])).max() <= 0.005


def test_example_passes_sc1_to_sc4_no_deeper_than_u(shaft):
    g71 = shaft["canned_cycle"] == 71
    sub, pass_no = shaft["subcycle"][g71], shaft["pass_no"][g71]
    changes = pass_changes(sub, pass_no)
    assert changes[-1] == (0, 0)                                   # back to the start point after the last pass
    passes = changes[:-1]
    n = len(passes) // 4
    assert passes == [(k, s) for k in range(1, n + 1) for s in (1, 2, 3, 4)]
    # levels 28.5 .. 15.5 (1.5 apart) above the lowest point of the shifted profile, X 14.2; then the profile pass
    assert n == 11
    cut_x = [float(shaft["x_cmd"][g71][(sub == 2) & (pass_no == k)][0]) for k in range(1, n)]
    assert cut_x == pytest.approx([30.0 - 1.5 * k for k in range(1, n)], abs=1e-12)
    assert shaft["sigma_x"][g71][(sub == 2) & (pass_no == 3)][0] == pytest.approx(4.5)
    assert deepest_cut(30.0, shaft["z_cmd"][g71], shaft["x_cmd"][g71], sub, pass_no) <= DEPTH + 1e-6
    # SC3 retracts by R, straight up
    for k in range(1, n + 1):
        sc3 = (sub == 3) & (pass_no == k)
        xs, zs = shaft["x_cmd"][g71][sc3], shaft["z_cmd"][g71][sc3]
        end_cut = shaft["x_cmd"][g71][(sub == 2) & (pass_no == k)][-1]
        assert xs[-1] - end_cut == pytest.approx(RETRACT, abs=1e-9) and np.ptp(zs) < 1e-12


def test_example_finishing_follows_the_profile(shaft):
    g70 = (shaft["canned_cycle"] == 70) & (shaft["subcycle"] == 2)
    path = np.column_stack([shaft["z_cmd"][g70], shaft["x_cmd"][g70]])
    profile = SHAFT.points(0.01)
    assert distances(path, profile).max() <= 0.005                 # on the profile
    assert distances(profile[profile[:, 0] <= 2.0], path).max() <= 0.005   # and all of it
    assert shaft["x_cmd"][-1] == 30.0 and shaft["z_cmd"][-1] == 2.0


def test_line_and_canned_cycle_outputs(shaft):
    text = EXAMPLE.read_text().split("\n")
    line_of = {ln: text[ln - 1] for ln in set(shaft["line"].tolist()) if ln}
    # the passes report the G71 block; the pass along the profile and G70 the profile's blocks
    g71 = shaft["canned_cycle"] == 71
    assert "G71 P10" in line_of[int(shaft["line"][g71][0])]
    arc = [ln for ln, t in line_of.items() if "G02" in t]
    assert set(shaft["canned_cycle"][np.isin(shaft["line"], arc)]) == {70, 71}
    assert "G70" in line_of[int(shaft["line"][(shaft["canned_cycle"] == 70) & (shaft["subcycle"] == 4)][0])]
    assert shaft["line"][-1] == 0 and shaft["canned_cycle"][-1] == 0      # idle at the end
    assert set(np.unique(shaft["canned_cycle"])) == {0, 70, 71}


def test_command_never_jumps(shaft):
    """Arcs included: the command moves at most feed-limited distances per step, the feed-forward is consistent."""
    step = np.hypot(np.diff(shaft["x_cmd"]), np.diff(shaft["z_cmd"]))
    assert step.max() <= 50.0 * 1e-3 + 1e-9                         # the rapid rate, 50 mm/s
    vff = np.hypot(shaft["x_vff"], shaft["z_vff"])
    assert np.abs(np.diff(vff)).max() <= 500.0 * 1e-3 + 1e-9        # accel 500 mm/s2
    for axis in ("x_vff", "z_vff"):                                 # per axis too, on the radius as well
        assert np.abs(np.diff(shaft[axis])).max() <= 500.0 * 1e-3 + 1e-9
    assert np.isfinite(shaft["x_cmd"]).all() and np.isfinite(shaft["z_cmd"]).all()


def test_a_depth_of_cut_too_small_is_refused():
    with pytest.raises(ProgramError, match=r"line 7, column 1: more than 5000 passes of U0.001"):
        CutSequencer(program=EXAMPLE.read_text().replace("G71 U1.5", "G71 U0.001"))


def test_g7_program_and_its_g8_twin_give_the_same_path():
    g8 = SHAFT.program(DEPTH, RETRACT, U, W, 300, 180, diameter=False, arcs="R")
    g7 = SHAFT.program(DEPTH, RETRACT, U, W, 300, 180, diameter=True, arcs="R")
    assert "X60" in g7 and "U0.4" in g7
    # the same plan, number for number (the run through the FMUs compares the trajectories)
    assert plan(g8, (30.0, 2.0), 50.0) == plan(g7, (30.0, 2.0), 50.0)
    # and the I/K twin of the R program plans the same geometry
    ik = plan(SHAFT.program(DEPTH, RETRACT, U, W, 300, 180, arcs="IK"), (30.0, 2.0), 50.0)
    r = plan(g8, (30.0, 2.0), 50.0)
    assert len(ik) == len(r)
    for s, t in zip(ik, r):
        assert math.dist(s.element.start, t.element.start) < 1e-9 and math.dist(s.element.end, t.element.end) < 1e-9


def test_registers_unchanged_without_a_program():
    seq = CutSequencer.with_blocks([Block(N=2)])
    run = run_ideal(seq)
    assert not run["line"].any() and not run["canned_cycle"].any()
    assert seq.plan == []


def test_feed_hold_override_and_restart_in_a_program(shaft):
    text = EXAMPLE.read_text()

    def events(k, inputs):
        inputs["feed_hold"] = 3000 <= k < 4000          # hold during the first cut
        inputs["feed_override"] = 0.5 if 6000 <= k < 7000 else 1.0

    run = program_run(text, events=events)
    held = slice(3300, 4000)                            # decelerated within 4 mm/s / 500 mm/s2 = 8 ms
    assert np.ptp(run["z_cmd"][held]) == 0.0 and run["subcycle"][3500] == 2
    vz = np.abs(run["z_vff"][6100:7000][run["subcycle"][6100:7000] == 2])
    assert vz.max() == pytest.approx(2.5, abs=1e-9)    # F300 = 5 mm/s at 50 %
    assert run["t"][-1] > shaft["t"][-1] + 1.0
    # an alarm mid-cut stops the cycle; START re-bases on the axes, retracts X clear, and runs the program again
    seq = CutSequencer(program=text, x_start=30.0, z_start=2.0)

    def alarm(k, inputs):
        inputs["alarm_in"] = 5000 <= k < 5100
        inputs["start"] = inputs["start"] or k == 6000

    again = run_ideal(seq, events=alarm)
    assert again["alarm"][5050] and not again["busy"][5050]
    after = slice(6001, 6001 + 2000)
    x_alarm = again["x_cmd"][5200]
    assert again["x_cmd"][after].max() == pytest.approx(30.0) and again["x_cmd"][6001] >= x_alarm - 1e-12
    rest = again["canned_cycle"][6001:] == 71
    assert pass_changes(again["subcycle"][6001:][rest], again["pass_no"][6001:][rest])[:4] == [
        (1, 1), (1, 2), (1, 3), (1, 4)]
    assert again["done"][-1]


# -- the parser's refusals: each names the line and the column --------------------------------------------
HEAD = "G18 G21 G90 G8\nG00 X30 Z2\nG71 U1 R0.5\n"   # X as radius (G8; a diameter without it)
PROFILE = "N10 G00 X20\nG01 Z-10\nN20 X30\n"


@pytest.mark.parametrize("text, line, column, words", [
    (HEAD + "G71 P11 Q20 U0.2 W0.1 F300\n" + PROFILE + "M30\n", 4, 5, "P11: the profile's first block N11 is not"),
    (HEAD + "G71 P10 Q21 U0.2 W0.1 F300\n" + PROFILE + "M30\n", 4, 9, "Q21: the profile's last block N21"),
    ("G00 X30 Z2\nG71 U0 R0.5\nM30\n", 2, 5, "U0: the depth of cut must be > 0"),
    ("G00 X30 Z2\nG71 U1 R-0.5\nM30\n", 2, 8, "R-0.5: the retract must be >= 0"),
    # a profile rising from the start point is a bore: with a positive U (an outside allowance) it is refused
    (HEAD + "G71 P10 Q20 U0.4 F300\nN10 G00 X31\nG01 Z-10\nN20 X30\nM30\n", 4, 13, "an inside profile (boring"),
    (HEAD + "G71 P10 Q20 F300\nN10 G00 X20\nG01 Z-10\nN20 X31\nM30\n", 7, 1, "leaves the stock"),
    (HEAD + "G71 P10 Q20 W0.1 F300\nN10 G00 X20\nG01 Z-10\nX15 Z-15\nN20 X30\nM30\n", 4, 13,
     "W0.1: the profile has a pocket (X falls along -Z on line 7)"),
    (HEAD + "G71 P10 Q20 F300\nN10 G00 X20\nG01 Z-10\nG02 X25 Z-15 I0 K-3\nN20 X30\nM30\n", 7, 14,
     "do not define a circle"),
    (HEAD + "G71 P10 Q20 F300\nN10 G00 X20\nG01 Z-10\nG02 X25 Z-25 R2\nN20 X30\nM30\n", 7, 14,
     "R2 does not define a circle"),
    (HEAD + "G71 P10 Q20 F300\nN10 G00 X20\nG01 Z-10\nG01 Z-5\nN20 X30\nM30\n", 7, 1, "moves +Z"),
    (HEAD + "G71 P10 Q20 F300\nN10 G00 X20 Z3\nG01 Z-10\nN20 X30\nM30\n", 5, 1, "not in front of the start point's Z"),
    (HEAD + "G71 P10 Q20 U-0.2 F300\n" + PROFILE + "M30\n", 4, 13, "negative allowance"),
    ("G00 X30 Z2\nG71 P10 Q20 F300\n" + PROFILE + "M30\n", 2, 1, "needs G71's first block"),
    ("G17\nM30\n", 1, 1, "XZ plane"),
    ("G01 X10 Y2 F100\nM30\n", 1, 9, "no Y axis"),
    ("G41 G00 X30 Z2\nG01 X10 F100 T0101\nM30\n", 2, 14, "with G41 in force: cancel the tool-nose radius"),
    ("G01 G00 X10\nM30\n", 1, 5, "modal group motion"),
    ("G7 G8 X10\nM30\n", 1, 4, "modal group X mode"),
    ("G01 X10 Z1\nM30\n", 1, 1, "no feed"),
    ("G00 X10 U2\nM30\n", 1, 9, "X and U in one block"),
    ("G00 X10\n", 1, 1, "does not end with M02 or M30"),
    ("G00 X10\nM30\nG00 X5\n", 3, 1, "text after the program end"),
    ("G00 X#1\nM30\n", 1, 5, "parameters and expressions"),
    ("G00 X30 Z2\nG71 U1 R0.5\nG71 P10 Q20 F300 X5\n" + PROFILE + "M30\n", 3, 18, "G71 takes P, Q"),
    (HEAD + "G70 P10 Q20\n" + PROFILE.replace("G01", "G01 ") + "M30\n", 4, 1, "has no feed"),
    (HEAD + "G71 P10 Q20 F300\nN10 G00 X20\nG01 Z-10\nN20 X15\nM30\n", 7, 1, "a groove of no width"),
    (HEAD + "G71 P10 Q20 F300\nN10 G00 X20\nG01 Z-10\nX15\nX25\nN20 Z-20\nM30\n", 7, 1, "a groove of no width"),
    (HEAD + "G71 P10 Q20 F300\n" + PROFILE + "G00 X32\nG71 P10 Q20 F300\nM30\n", 9, 5,
     "was read from the start point X 30 Z 2, this G71 starts at X 32 Z 2"),
])
def test_refusals_name_line_and_column(text, line, column, words):
    with pytest.raises(ProgramError) as err:
        parse(text, (30.0, 2.0))
    assert (err.value.line_no, err.value.column) == (line, column), str(err.value)
    assert words in str(err.value)


def test_refusal_at_initialisation_names_the_program():
    with pytest.raises(ProgramError, match=r"program = .*line 2, column 5: U0"):
        CutSequencer(program="G00 X30 Z2\nG71 U0 R0.5\nM30\n")


def test_profile_after_m30_is_not_found_and_g70_reuses_g71_profile():
    ops = [o for o in parse(EXAMPLE.read_text(), (30.0, 2.0)) if type(o).__name__ != "State"]   # S800 M03: a State
    assert [type(o).__name__ for o in ops] == ["Rough", "Finish"]
    assert ops[0].profile is ops[1].profile
    assert ops[0].u == pytest.approx(0.2) and ops[0].w == pytest.approx(0.1) and ops[0].feed == pytest.approx(5.0)
    # G7: the second block's U is a diameter, the first block's U and R stay radius values
    g7 = parse(EXAMPLE.read_text().replace(" G97 S800 M03", "").replace("G8", "G7").replace("X14", "X28")
               .replace("X16", "X32").replace("X20", "X40").replace("X24", "X48").replace("X27", "X54")
               .replace("X30", "X60"),
               (30.0, 2.0))
    assert g7[0].u == pytest.approx(0.1) and g7[0].depth == 1.5 and g7[0].retract == 0.5


def test_moves_around_a_cycle_incremental_and_modes_restored():
    """Plain moves before and after G71 (G91 too): sub-cycle 0, canned cycle 0, their own line; the cycle starts
    where the tool stands and ends there; after the profile the modes in force before it hold again."""
    text = ("G18 G21 G8\nG00 X35 Z5\nG91 G00 X-5 Z-3\nG90\nG71 U1 R0.5\nG71 P1 Q2 U0.1 F300\n"
            "N1 G00 X20\nG01 Z-10 F100\nN2 X30\nX34 Z4\nG01 X33 Z3\nM30\n")
    segs = plan(text, (30.0, 2.0), 50.0)
    plain = [s for s in segs if s.cycle == 0]
    assert [(s.line, s.feed, s.subcycle) for s in plain] == [(2, False, 0), (3, False, 0), (10, False, 0),
                                                              (11, True, 0)]
    assert plain[1].element.end == (2.0, 30.0)                 # G91: X-5 Z-3 from X35 Z5, as (z, x)
    assert plain[2].element.start == (2.0, 30.0)               # after the cycle: from its start point, G00 again
    assert plain[3].rate == pytest.approx(5.0)                 # F300 (the profile's F100 was not executed)
    g71 = [s for s in segs if s.cycle == 71]
    assert g71[0].element.start == (2.0, 30.0) and g71[-1].element.end == (2.0, 30.0)
    assert {s.rate for s in g71 if s.feed} == {5.0}             # the cycle's F, not the profile's
    run = program_run(text)
    assert run["done"][-1] and not run["alarm"].any()
    assert (run["x_cmd"][-1], run["z_cmd"][-1]) == (33.0, 3.0)
    assert set(run["line"][run["canned_cycle"] == 0]) == {0, 2, 3, 10, 11}


@pytest.mark.parametrize("u", [pytest.param(0.0, marks=pytest.mark.slow), 0.3])
def test_pockets_roughed_without_cutting_below_profile_plus_allowance(u):
    assert min(p.end[1] for p in POCKETS.pieces) == pytest.approx(14.0)
    text = POCKETS.program(1.25, 0.4, u, 0.0, 600, 600, arcs="R")
    segs = plan(text, (30.0, 2.0), 50.0)
    assert rapids_in_air(segs, 30.0, 2.0) <= 1e-6                 # rapids only through air
    run = program_run(text, dt=2e-3)
    g71 = run["canned_cycle"] == 71
    z, x, sub, pass_no = run["z_cmd"][g71], run["x_cmd"][g71], run["subcycle"][g71], run["pass_no"][g71]
    assert below_shifted_profile(POCKETS, u, 0.0, z, x, tol=0.002) <= 0.002
    assert distances(shifted_points(POCKETS, u, 0.0, 0.02), np.column_stack([z, x])).max() <= 0.005
    changes = pass_changes(sub, pass_no)
    n = (len(changes) - 1) // 4
    assert changes == [(k, s) for k in range(1, n + 1) for s in (1, 2, 3, 4)] + [(0, 0)]
    assert deepest_cut(30.0, z, x, sub, pass_no) <= 1.25 + 1e-6
    # the pockets take passes of their own: more passes than levels
    levels = {round(float(v), 9) for v in run["sigma_x"][g71][sub == 2]}
    assert n > len(levels) + 1
    # the plunges into the pockets are at the feed, never deeper than U below what the cuts before left
    plunge = [s for s in segs if s.cycle == 71 and s.subcycle == 1 and s.feed]
    assert len(plunge) > 3 and all(s.rate == pytest.approx(10.0) for s in plunge)
    g70 = (run["canned_cycle"] == 70) & (run["subcycle"] == 2)
    path = np.column_stack([run["z_cmd"][g70], run["x_cmd"][g70]])
    assert distances(path, POCKETS.points(0.01)).max() <= 0.005
    assert distances(POCKETS.points(0.01), path).max() <= 0.005


def test_a_program_leaves_the_registers_unread():
    unread = CutSequencer.unread({"program": EXAMPLE.read_text()})
    assert "block[1].Xd" in unread and "block[2].Zp" in unread and "n_blocks" in unread
    assert "block[1].rapid" not in unread and "x_start" not in unread and "accel" not in unread
    assert not {k for k in CutSequencer.unread({"program": ""}) if k.startswith("block[1]")}
