"""Every panel signal a system's controller can take is wired, and the grinder's feed hold and override act.

The wiring check is structural (every system, no run); the grinder runs check the physics of a held and an
overridden feed through the FMUs: a hold of ``release_at - hold_at`` seconds delays the cycle end by exactly
that (the feed decelerates and re-accelerates at the same ``accel``, so the ramps cancel), and an override
``o`` stretches every feed word from ``D/F + F/a`` (trapezoid: cruise plus one ramp's worth) to
``D/(o F) + o F/a``; the spark-out dwell and the M handshakes do not change.
"""

from __future__ import annotations

import pytest

from ncfmu.exitcodes import EXIT_NOT_FINISHED
from ncfmu.project import simulate
from ncfmu.systems import MODELS, SYSTEMS, get_system
from ncfmu.systems.report import _ended

ACCEL = 500.0      # ProgrammableFeed's accel (the grinder systems keep the default), mm/s^2


def _controller_of(system):
    """The component the panel's START drives: the system's controller."""
    starts = [c for c in system.connections if (c.start_element, c.start_connector) == ("panel", "start")]
    assert len(starts) == 1, starts
    return system.component(starts[0].end_element)


@pytest.mark.parametrize("name", sorted(SYSTEMS))
def test_every_panel_signal_the_controller_takes_is_connected(name):
    system = get_system(name)
    ctrl = _controller_of(system)
    panel = MODELS[system.component("panel").model]
    logic = MODELS[ctrl.model]
    wired = {(c.start_element, c.start_connector, c.end_element, c.end_connector) for c in system.connections}
    ctrl_inputs = {p.name for p in logic.ports("input")}
    ctrl_outputs = {p.name for p in logic.ports("output")}
    missing = [f"panel.{p.name} -> {ctrl.name}.{p.name}" for p in panel.ports("output")
               if p.name in ctrl_inputs and ("panel", p.name, ctrl.name, p.name) not in wired]
    missing += [f"{ctrl.name}.{p.name} -> panel.{p.name}" for p in panel.ports("input")
                if p.name in ctrl_outputs and (ctrl.name, p.name, "panel", p.name) not in wired]
    assert not missing, f"{name}: not connected: {missing}"
    # the check has teeth: every controller takes the panel's START, hold and override
    assert {"start", "feed_hold", "feed_override"} <= ctrl_inputs


def _cycle_end(result) -> float:
    return _ended(result, result["feed.run"] | result["feed.emergency_active"])


def _trapezoid(d: float, v: float, a: float = ACCEL) -> float:
    """Time of a move of ``d`` mm at ``v`` mm/s from rest to rest, accelerating at ``a`` (d >= v**2/a)."""
    assert d >= v * v / a
    return d / v + v / a


#: The feed words (distance mm, rate mm/s) of each grinder system's default program (ncfmu.systems.grinder):
#: grinder_feed: rapid D3 at F7, rough D2 at F1, fine D5 at F2, return D4 at F7;
#: grinder_envelope: Y D1 at F7, X D2 at F7, X D3 at F1, X D4 at F7, Y D1 at F7.
FEED_WORDS = {"grinder_feed": [(4.0, 10.0), (0.2, 0.02), (0.1, 0.005), (4.3, 10.0)],
              "grinder_envelope": [(400.0, 100.0), (150.0, 100.0), (20.0, 2.0), (170.0, 100.0), (400.0, 100.0)]}


@pytest.fixture(scope="module")
def nominal(project):
    return {name: simulate(name, stop_time=40.0) for name in FEED_WORDS}


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(FEED_WORDS))
def test_feed_hold_from_the_panel_delays_the_cycle_by_the_hold(nominal, name):
    base = _cycle_end(nominal[name])
    assert 5.0 < base < 40.0 - 3.0           # the hold lies inside a running cycle (a feed or a dwell)
    held = simulate(name, stop_time=40.0, start_values={"panel.hold_at": 5.0, "panel.release_at": 7.0})
    assert held["panel.feed_hold"].any()
    assert _cycle_end(held) == pytest.approx(base + 2.0, abs=0.001)        # one step of 1 ms
    # while held nothing moves on the infeed
    t = held.time
    x = held["x_axis.pos"][(t >= 5.3) & (t <= 7.0)]     # after the ramp down (<= 0.2 s)
    assert x.max() - x.min() < 1e-3


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(FEED_WORDS))
def test_feed_override_from_the_panel_stretches_every_feed_word(nominal, name):
    o = 0.5
    base = _cycle_end(nominal[name])
    expected = base + sum(_trapezoid(d, o * f) - _trapezoid(d, f) for d, f in FEED_WORDS[name])
    slow = simulate(name, stop_time=expected + 2.0, start_values={"panel.override": o})
    assert (slow["panel.feed_override"] == o).all()
    assert _cycle_end(slow) == pytest.approx(expected, abs=0.002)   # the end falls on a 1 ms step


# -- settings that reach nothing are said -----------------------------------------------------------
def _panel_trace(parameters: dict, m_active: int = 0, seconds: float = 1.0) -> dict[str, list]:
    from ncfmu.controllers import OperatorPanel
    panel = OperatorPanel(**parameters)
    trace: dict[str, list] = {p.name: [] for p in OperatorPanel.ports("output")}
    dt = 1e-3
    for k in range(int(round(seconds / dt))):
        out = panel.step(k * dt, dt, {"m_active": m_active})
        for name, value in out.items():
            trace[name].append(value)
    return trace


#: For each panel parameter (and its input): a base setting and a change that must show within 1 s.
PANEL_CHANGES = {
    "start_at": ({}, {"start_at": 0.5}), "restart_at": ({}, {"restart_at": 0.3}),
    "wear_start_at": ({}, {"wear_start_at": 0.2}), "emergency_at": ({}, {"emergency_at": 0.2}),
    "hold_at": ({}, {"hold_at": 0.2}), "release_at": ({"hold_at": 0.2}, {"release_at": 0.4}),
    "pulse": ({"wear_start_at": 0.3, "emergency_at": 0.6}, {"pulse": 0.05}),
    "mfin_delay": ({}, {"mfin_delay": 0.2}), "override": ({}, {"override": 0.5}),
}


@pytest.mark.parametrize("name", sorted(PANEL_CHANGES))
def test_panel_acts_on_says_which_outputs_a_parameter_changes(name):
    """ACTS_ON is the panel's behaviour: the outputs a change of the parameter moves are exactly those named."""
    from ncfmu.controllers import OperatorPanel
    base, change = PANEL_CHANGES[name]
    m = 3 if name == "mfin_delay" else 0
    a, b = _panel_trace(base, m), _panel_trace({**base, **change}, m)
    moved = {out for out in a if a[out] != b[out]}
    assert moved == set(OperatorPanel.ACTS_ON[name]), (name, moved)


def test_panel_m_active_acts_on_mfin_only():
    from ncfmu.controllers import OperatorPanel
    a, b = _panel_trace({}, 0), _panel_trace({}, 4)
    assert {out for out in a if a[out] != b[out]} == set(OperatorPanel.ACTS_ON["m_active"]) == {"mfin"}


def test_every_panel_parameter_has_its_outputs_named():
    from ncfmu.controllers import OperatorPanel
    assert set(OperatorPanel.ACTS_ON) == {p.name for p in OperatorPanel.ports() if p.causality != "output"}


def _warnings(out: str) -> list[str]:
    """The warnings about settings (an FMU's own warnings, e.g. EMB's, are not the point here)."""
    return [line.strip() for line in out.splitlines() if line.strip().startswith("[warning] --")]


def test_run_warns_of_settings_that_reach_no_connected_port(project, capsys, tmp_path):
    from ncfmu.cli import main
    rc = main(["run", "lathe_taper", "--stop-time", "0.2", "--out", str(tmp_path),
               "--set", "panel.emergency_at=0.1", "--set", "panel.override=0.5", "--set", "panel.pulse=0.02",
               "--set", "seq.block[2].Xd=0.2", "--set", "seq.block[1].Xd=0.4", "--set", "limiter.region[3].lim_min=1"])
    assert rc == EXIT_NOT_FINISHED
    assert _warnings(capsys.readouterr().out) == [
        "[warning] --set panel.emergency_at=0.1: panel.emergency_at acts only on panel.emergency, which no "
        "connection of lathe_taper reads: it changes nothing in this system",
        "[warning] --set seq.block[2].Xd=0.2: seq reads block[1..1] only (n_blocks = 1): seq.block[2].Xd changes "
        "nothing",
        "[warning] --set limiter.region[3].lim_min=1: limiter reads region[1..2] only (n_regions = 2): "
        "limiter.region[3].lim_min changes nothing"]
    # override and pulse reach the sequencer (feed_override, start) in the lathe: no warning for them


def test_run_warns_per_system_and_the_count_as_the_run_sets_it(project, capsys, tmp_path):
    from ncfmu.cli import main
    # the grinder reads the panel's override and hold now, and its emergency: no warning
    assert main(["run", "grinder_feed", "--stop-time", "0.2", "--out", str(tmp_path), "--set", "panel.override=0.5",
                 "--set", "panel.hold_at=0.1", "--set", "panel.emergency_at=0.15"]) == EXIT_NOT_FINISHED
    assert _warnings(capsys.readouterr().out) == []
    # a second block is read once n_blocks says so
    assert main(["run", "lathe_taper", "--stop-time", "0.2", "--out", str(tmp_path), "--set", "seq.n_blocks=2",
                 "--set", "seq.block[2].Xd=0.2", "--set", "seq.block[2].N=1", "--set", "seq.block[2].Zp=42",
                 "--set", "seq.block[2].Xf=4", "--set", "seq.block[2].feed=2", "--set", "seq.block[2].rapid=50"]) \
        == EXIT_NOT_FINISHED
    assert _warnings(capsys.readouterr().out) == []
    # the mill has no EMB and no M words: the panel's MFIN delay reaches nothing
    assert main(["run", "mill_contour", "--stop-time", "0.2", "--out", str(tmp_path),
                 "--set", "panel.mfin_delay=1"]) == EXIT_NOT_FINISHED
    assert _warnings(capsys.readouterr().out) == [
        "[warning] --set panel.mfin_delay=1: panel.mfin_delay acts only on panel.mfin, which no connection of "
        "mill_contour reads: it changes nothing in this system"]


def test_sweep_warns_of_a_varied_setting_that_reaches_nothing(project, capsys, tmp_path):
    from ncfmu.cli import main
    main(["sweep", "lathe_taper", "--vary", "panel.wear_start_at=0.1,0.15", "--vary", "seq.block[1].Xd=0.4,0.5",
          "--stop-time", "0.2", "--workers", "0", "--out", str(tmp_path)])
    assert _warnings(capsys.readouterr().out) == [
        "[warning] --vary panel.wear_start_at=0.1,0.15: panel.wear_start_at acts only on panel.wear_start, which no "
        "connection of lathe_taper reads: it changes nothing in this system"]


def test_branches_warn_of_their_settings_once(project, capsys, tmp_path):
    from ncfmu.cli import main
    assert main(["run", "lathe_taper", "--branch-at", "0.5", "--branch-set", "panel.emergency_at=1,2",
                 "--set", "seq.block[2].Xd=0.3", "--stop-time", "1", "--out", str(tmp_path)]) == 0
    assert _warnings(capsys.readouterr().out) == [
        "[warning] --set seq.block[2].Xd=0.3: seq reads block[1..1] only (n_blocks = 1): seq.block[2].Xd changes "
        "nothing",
        "[warning] --branch-set panel.emergency_at=1,2: panel.emergency_at acts only on panel.emergency, which no "
        "connection of lathe_taper reads: it changes nothing in this system"]


def test_a_count_that_is_no_number_leaves_the_warnings_alone(project, capsys, tmp_path):
    """The variant with n_blocks = 'two' fails (its own error); the warning rule does not crash on it."""
    from ncfmu.cli import main
    assert main(["sweep", "lathe_taper", "--vary", "seq.n_blocks=two,1", "--vary", "seq.block[2].Xd=0.2",
                 "--stop-time", "0.1", "--workers", "0", "--out", str(tmp_path)]) == EXIT_NOT_FINISHED
    out = capsys.readouterr().out
    assert "failed: seq.n_blocks=two, seq.block[2].Xd=0.2" in out
    assert _warnings(out) == ["[warning] --vary seq.block[2].Xd=0.2: seq reads block[1..1] only (n_blocks = 1): "
                              "seq.block[2].Xd changes nothing"]


def test_settings_a_program_leaves_unread_are_warned(project, capsys, tmp_path):
    from ncfmu.cli import main
    # the seed's program names D1..D5, F1, F2, F7 and T1: D6, F3, T2 are switches nothing reads
    assert main(["run", "grinder_feed", "--stop-time", "0.2", "--out", str(tmp_path), "--set", "feed.D6=1",
                 "--set", "feed.F3=1", "--set", "feed.T2=3", "--set", "feed.T1=2", "--set", "feed.D3=3.5"]) \
        == EXIT_NOT_FINISHED
    assert _warnings(capsys.readouterr().out) == [
        "[warning] --set feed.D6=1: feed reads D1, D2, D3, D4, D5 only (the D settings its program names): "
        "feed.D6 changes nothing",
        "[warning] --set feed.F3=1: feed reads F1, F2, F7 only (the F settings its program names): feed.F3 changes "
        "nothing",
        "[warning] --set feed.T2=3: feed reads T1 only (the T settings its program names): feed.T2 changes nothing"]
    # a program of the run's own that names T2 reads it
    program = "M0: X+D3F7; M1: T2; M2: X-D3F7; M3: END; M41: XF7S1; M42: END; M43: END"
    assert main(["run", "grinder_feed", "--stop-time", "0.2", "--out", str(tmp_path), "--set",
                 f"feed.program={program}", "--set", "feed.T2=3"]) == EXIT_NOT_FINISHED
    assert _warnings(capsys.readouterr().out) == []
    # a part program replaces the contour's point path: its points, side and feed are read no more
    assert main(["run", "mill_contour", "--stop-time", "0.2", "--out", str(tmp_path), "--set",
                 "contour.program=G01 X5 Y-10 F300\nM02", "--set", "contour.side=1", "--set", "contour.point[2].x=50",
                 "--set", "contour.diameter_delta=0.2"]) == EXIT_NOT_FINISHED
    assert _warnings(capsys.readouterr().out) == [
        "[warning] --set contour.side=1: contour runs its program (program is set), not the point path: "
        "contour.side changes nothing",
        "[warning] --set contour.point[2].x=50: contour runs its program (program is set), not the point path: "
        "contour.point[2].x changes nothing"]


# -- unread is the controllers' behaviour -----------------------------------------------------------------
SHORT_PROGRAM = "M0: X+D1F1; M1: T1; M2: X-D1F1; M3: END; M41: XF7S1; M42: END; M43: END"


def _feed_trace(**changes) -> list[tuple]:
    """A short cycle of the plain ProgrammableFeed with an axis that stands where commanded."""
    from ncfmu.controllers import ProgrammableFeed
    feed = ProgrammableFeed(**{"program": SHORT_PROGRAM, "D1": 0.5, "F1": 5.0, "T1": 0.2, **changes})
    inputs = {"start": False, "wear_start": False, "emergency": False, "mfin": False, "alarm_in": False,
              "feed_hold": False, "feed_override": 1.0, "x_pos": 0.0, "y_pos": 0.0, "x_in_position": True,
              "y_in_position": True}
    trace = []
    for k in range(700):
        inputs["start"] = k == 1
        out = feed.step(k * 1e-3, 1e-3, inputs)
        inputs["x_pos"] = out["x_cmd"]
        trace.append((out["x_cmd"], out["x_vff"], out["pc"], out["run"]))
    assert not trace[-1][3] and trace[300][0] > 0          # the cycle ran and ended inside the trace
    return trace


def test_feed_unread_names_exactly_the_switches_the_cycle_does_not_read():
    from ncfmu.controllers import ProgrammableFeed
    params = {**ProgrammableFeed.default_parameters(), "program": SHORT_PROGRAM, "D1": 0.5, "F1": 5.0, "T1": 0.2}
    unread = set(ProgrammableFeed.unread(params))
    assert unread == {f"{letter}{k}" for letter in "DFT" for k in range(1, 8)} - {"D1", "F1", "T1", "F7"}
    base = _feed_trace()
    for name in sorted(unread):
        assert _feed_trace(**{name: 0.3}) == base, name                 # changes nothing
    for name, value in (("D1", 0.4), ("F1", 4.0), ("T1", 0.1)):
        assert _feed_trace(**{name: value}) != base, name               # the rule has teeth
    # F7 is read by the emergency return (M41), which this cycle does not strike: read, not warned


def test_contour_unread_is_the_point_path_when_a_program_runs():
    from ncfmu.controllers import ContourInterpolator
    from ncfmu.systems import parameters
    program = {"program": "G01 X5 Y-10 F300\nG01 X5 Y0\nM02"}
    params = {**parameters("mill_contour", "contour"), **program}
    unread = ContourInterpolator.unread(params)
    points = {p.name for p in ContourInterpolator.ports("parameter") if p.name.startswith("point[")}
    assert set(unread) == points | {"n_points", "closed", "side", "feed"}

    def path(**changes):
        return [(m.element, m.feed) for m in ContourInterpolator(**{**params, **changes}).tool_path]
    base = path()
    for name, value in (("side", 1), ("feed", 2.0), ("closed", False), ("point[2].x", 50.0), ("n_points", 5)):
        assert path(**{name: value}) == base, name
    assert path(x_start=1.0) != base                   # the program starts where the tool stands: read
    # without a program the point path runs: only the points beyond n_points (6) go unread
    assert set(ContourInterpolator.unread(parameters("mill_contour", "contour"))) == \
        {name for name in points if int(name[6:name.index("]")]) > 6}
