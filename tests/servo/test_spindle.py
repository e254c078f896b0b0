"""SpindleDrive: its python-control design, and the built FMU against the physics.

Ramps from the torque limit (acceleration = (torque_max - tau_coulomb) / J while it acts), the constant-power
range (t = J (w2^2 - w1^2) / (2 power_max)), settling from the designed closed loop (control.step_response),
coasting on friction, the speed-arrival signal, direction, limits and broken inputs, all through the FMU.
"""

from __future__ import annotations

import math

import control as ct
import numpy as np
import pytest

from ncfmu.errors import ConfigError
from ncfmu.servo.parameters import RAD_S_PER_RPM, SpindleParameters
from ncfmu.servo.spindle import SpindleDrive
from ncfmu.servo.spindle_model import MIN_PHASE_MARGIN, design, speed_loop, spindle_drive, spindle_plant

DT = 1e-3
#: the FMU's default parameters (J 0.2 kg.m2, torque_max 100 N.m, power_max 15 kW)
J, T_MAX, P_MAX = 0.2, 100.0, 15e3
#: the plant without friction or power limit: the ramps are the torque limit's alone
FRICTIONLESS = dict(b_visc=0.0, tau_coulomb=0.0, power_max=1e4)
#: the speed is the encoder's angle over a step: one count (2^20 per revolution) in 1 ms is 0.057 rev/min
RESOLUTION = 60.0 / (2 ** 20 * DT)


def run(runner, commands, direction=None, enable=None, start=0, load=None):
    """Step the FMU 1 ms per command (rev/min) from step ``start``; every output per step as arrays."""
    names = ("speed", "torque", "power", "revolutions", "at_speed", "limited")
    out = {k: [] for k in names}
    for i, cmd in enumerate(commands):
        runner.set(speed_cmd=float(cmd), direction=1 if direction is None else int(direction[i]),
                   enable=True if enable is None else bool(enable[i]),
                   load_torque=0.0 if load is None else float(load[i]))
        runner.slave.do_step((start + i) * DT, DT)
        for k in names:
            out[k].append(runner.get(k))
    return {k: np.array(v) for k, v in out.items()}


def overshoot(torque: float, p: SpindleParameters = SpindleParameters(b_visc=0.0)) -> float:
    """The most a ramp ending at ``torque`` may overshoot (rev/min) with anti-windup: the loop leaves the limit
    e = torque / Kp short of its command and closes that gap as the linear loop closes a step of e."""
    kp, _ = p.speed_gains
    return ct.step_info(ct.feedback(speed_loop(p), 1))["Overshoot"] / 100 * torque / kp / RAD_S_PER_RPM


def first(mask) -> int:
    """Index of the first true element (the test fails when there is none)."""
    hits = np.flatnonzero(mask)
    assert hits.size, "never"
    return int(hits[0])


# -- design (python-control) ----------------------------------------------------------------------
def test_the_default_design_meets_the_margin_rule_at_its_crossover():
    d = design()
    assert d.stable and d.phase_margin >= MIN_PHASE_MARGIN + 30          # 70.5 deg: well damped
    assert d.gain_margin == math.inf                                      # a third-order loop, phase > -180
    # the crossover is where it was put: speed_bandwidth (the PI zero and the current lag move it a little)
    assert d.crossover == pytest.approx(SpindleParameters().speed_bandwidth, rel=0.05)
    assert d.bandwidth > d.crossover
    # the loop is PI x current lag x inertia: three poles, one at the origin
    loop = speed_loop()
    assert len(loop.den[0][0]) - 1 == 3 and min(abs(ct.poles(loop))) < 1e-9


def test_the_closed_loop_is_the_loop_closed():
    """spindle_drive() (interconnected from the factories) has the poles of feedback(speed_loop), plus the
    angle's integrator; and spindle_plant() is its plant."""
    loop_poles = np.sort_complex(ct.poles(ct.feedback(speed_loop(), 1)))
    drive_poles = np.sort_complex(ct.poles(spindle_drive()))
    assert np.sum(np.abs(drive_poles) < 1e-9) == 1
    assert np.allclose(np.sort_complex(drive_poles[np.abs(drive_poles) > 1e-9]), loop_poles, rtol=1e-6)
    plant = spindle_plant()
    assert plant.state_labels == ["torque", "angle", "speed"] and plant.input_labels == ["torque_cmd",
                                                                                         "torque_friction"]
    torque_to_speed = ct.minreal(ct.tf(plant[2, 0]), verbose=False)         # the angle's integrator drops out
    assert ct.dcgain(torque_to_speed) == pytest.approx(1.0 / SpindleParameters().b_visc)


def test_a_loop_without_phase_margin_is_refused_naming_speed_bandwidth():
    # tau_current 10 ms against a 300 rad/s crossover: the current loop's lag eats the margin
    with pytest.raises(ConfigError, match=r"speed_bandwidth = 300\.0: gives the speed loop a phase margin of "
                                          r"\d+\.\d deg \(< 30 deg\) with tau_current = 0\.01 s"):
        SpindleDrive(speed_bandwidth=300.0, tau_current=0.01)
    with pytest.raises(ConfigError, match=r"speed_bandwidth = 5000\.0: must be <= 0\.5 / substep = 2000"):
        SpindleDrive(speed_bandwidth=5000.0)


# -- through the FMU: the linear range -------------------------------------------------------------
def test_a_small_step_follows_the_designed_closed_loop(fmus, fmu_runner):
    """30 rev/min from rest (P kick 63 N.m: within the torque limit, so the loop stays linear): the FMU's speed
    is the continuous closed loop's (control.step_response of spindle_drive) to the sampling's effect, and it
    settles in the design's time."""
    step = 30.0
    n = 300
    out = run(fmu_runner(fmus["SpindleDrive"]).start(tau_coulomb=0.0), [step] * n)
    assert not out["limited"].any()
    t = np.arange(n + 1) * DT
    ref = ct.step_response(spindle_drive()[0, 0], T=t)                    # speed_cmd -> speed
    w_ref = np.asarray(ref.outputs).reshape(-1) * step             # rad/s per rad/s, so rev/min per rev/min
    # the FMU reports the mean speed over each step: the reference's, by the trapezoid rule
    mean_ref = (w_ref[:-1] + w_ref[1:]) / 2
    # a digital loop: the speed measured by backward difference over a 0.25 ms substep lags by half of it,
    # 1.25 % of a radian at the 100 rad/s crossover; 2 % of the step bounds what that moves the response
    assert np.abs(out["speed"] - mean_ref).max() <= 0.02 * step
    # settling into 2 % of the step: as the design's closed loop, to a sample
    info = ct.step_info(ct.feedback(speed_loop(), 1), T=t, SettlingTimeThreshold=0.02)
    outside = np.flatnonzero(np.abs(out["speed"] - step) > 0.02 * step)
    settled = (outside[-1] + 1) * DT
    assert settled == pytest.approx(info["SettlingTime"], abs=3 * DT)
    assert out["at_speed"][-1] and out["speed"][-1] == pytest.approx(step, abs=RESOLUTION)


# -- ramps: the torque and power limits -------------------------------------------------------------
def test_a_large_step_ramps_at_the_torque_limit_over_the_inertia(fmus, fmu_runner):
    """Frictionless, no power limit: 0 -> 2000 rev/min accelerates at torque_max / J = 500 rad/s^2 (4775
    rev/min/s), reaches 95 % in 0.95 * 2000 / 4775 s plus the current loop's lag, and stops without overshoot."""
    out = run(fmu_runner(fmus["SpindleDrive"]).start(**FRICTIONLESS), [2000.0] * 800)
    accel = T_MAX / J / RAD_S_PER_RPM                              # rev/min per second
    # the slope over 100 ms in the middle of the ramp (the current loop's lag long settled)
    assert out["limited"][50:300].all() and np.all(out["torque"][50:300] == pytest.approx(T_MAX, rel=1e-6))
    assert (out["speed"][250] - out["speed"][150]) / 0.1 == pytest.approx(accel, rel=1e-4)
    arrived = (first(out["speed"] >= 0.95 * 2000.0) + 1) * DT
    assert arrived == pytest.approx(0.95 * 2000.0 / accel + 1e-3, abs=1.5 * DT)     # + tau_current
    assert (first(out["at_speed"]) + 1) * DT == arrived                           # the 5 % band
    # anti-windup: the integral did not run up during the ramp, so no more overshoot than the linear loop's
    # from the limit (6.9 rev/min); a wound-up integral (0.4 s of the ramp's error) would carry it far beyond
    assert 0.0 < out["speed"].max() - 2000.0 <= overshoot(T_MAX) + RESOLUTION
    assert out["at_speed"][first(out["at_speed"]):].all()
    assert not out["limited"][-100:].any() and out["speed"][-1] == pytest.approx(2000.0, abs=RESOLUTION)


def test_coulomb_and_viscous_friction_take_their_share_of_the_torque(fmus, fmu_runner):
    """tau_coulomb 5 N.m: the ramp is (torque_max - 5) / J; viscous 0.05 N.m.s/rad: at a steady 1000 rev/min the
    motor gives tau_coulomb + b * w."""
    tc, b = 5.0, 0.05
    out = run(fmu_runner(fmus["SpindleDrive"]).start(tau_coulomb=tc, b_visc=0.0, power_max=1e4), [2000.0] * 300)
    accel = (T_MAX - tc) / J / RAD_S_PER_RPM
    assert (out["speed"][250] - out["speed"][150]) / 0.1 == pytest.approx(accel, rel=1e-4)
    out = run(fmu_runner(fmus["SpindleDrive"]).start(tau_coulomb=tc, b_visc=b, power_max=1e4), [1000.0] * 1000)
    w = 1000.0 * RAD_S_PER_RPM
    assert out["torque"][-100:].mean() == pytest.approx(tc + b * w, rel=2e-3)
    assert out["speed"][-1] == pytest.approx(1000.0, abs=RESOLUTION)


def test_above_the_base_speed_the_ramp_is_limited_by_power(fmus, fmu_runner):
    """15 kW, 100 N.m: base speed 1432 rev/min. Frictionless, 0 -> 4000 rev/min: the power stays at 15 kW above
    it and the time from 2000 to 3500 rev/min is J (w2^2 - w1^2) / (2 P)."""
    out = run(fmu_runner(fmus["SpindleDrive"]).start(b_visc=0.0, tau_coulomb=0.0), [4000.0] * 2000)
    w1, w2 = 2000.0 * RAD_S_PER_RPM, 3500.0 * RAD_S_PER_RPM
    t1, t2 = first(out["speed"] >= 2000.0), first(out["speed"] >= 3500.0)
    assert (t2 - t1) * DT == pytest.approx(J * (w2 ** 2 - w1 ** 2) / (2 * P_MAX), abs=2 * DT)
    assert np.all(out["power"][t1:t2] == pytest.approx(P_MAX / 1e3, rel=2e-3))
    assert out["speed"].max() - 4000.0 <= overshoot(P_MAX / (4000.0 * RAD_S_PER_RPM)) + RESOLUTION
    assert out["speed"][-1] == pytest.approx(4000.0, abs=RESOLUTION)


# -- load -----------------------------------------------------------------------------------------------------
def test_a_cutting_torque_dips_the_speed_as_the_designed_loop_answers_it(fmus, fmu_runner):
    """30 N.m of load at a steady 1000 rev/min: the speed dips as the closed loop's answer to a load step
    (control.step_response of spindle_drive's torque_load input: 10.9 rev/min at 19 ms), the integral brings it
    back, and the motor then gives the load on top of its friction."""
    n0, n1 = 600, 400
    load = np.array([0.0] * n0 + [30.0] * n1)
    out = run(fmu_runner(fmus["SpindleDrive"]).start(), [1000.0] * (n0 + n1), load=load)
    t = np.arange(n1 + 1) * DT
    ref = ct.step_response(spindle_drive(load_input=True)[0, 1], T=t)        # torque_load -> speed
    w_ref = np.asarray(ref.outputs).reshape(-1) * 30.0 / RAD_S_PER_RPM
    dip = 1000.0 + (w_ref[:-1] + w_ref[1:]) / 2                              # mean over each step
    # the digital loop (sampling, encoder) moves the answer by 3 % of the dip at most
    assert np.abs(out["speed"][n0:] - dip).max() <= 0.03 * abs(w_ref.min()) + RESOLUTION
    assert out["speed"][n0:].min() == pytest.approx(1000.0 + w_ref.min(), rel=5e-4)
    assert out["speed"][-1] == pytest.approx(1000.0, abs=RESOLUTION)
    torque_before = out["torque"][n0 - 100:n0].mean()
    assert out["torque"][-50:].mean() - torque_before == pytest.approx(30.0, rel=1e-3)


def test_a_load_beyond_the_motor_stalls_the_spindle_and_never_turns_it(fmus, fmu_runner):
    """150 N.m of load against 100 N.m of motor torque: the spindle stands (the load holds it as friction
    does); with the load gone it turns up to speed."""
    load = np.array([150.0] * 500 + [0.0] * 500)
    out = run(fmu_runner(fmus["SpindleDrive"]).start(), [1000.0] * 1000, load=load)
    assert np.all(out["speed"][:500] == 0.0) and np.all(out["revolutions"][:500] == 0.0)
    assert np.all(out["torque"][20:500] == pytest.approx(T_MAX, rel=1e-6)) and out["limited"][:500].all()
    assert out["speed"][-1] == pytest.approx(1000.0, abs=RESOLUTION) and out["at_speed"][-1]


# -- stop, reverse, coast ---------------------------------------------------------------------------
def test_m04_turns_the_other_way_and_m05_brakes_to_a_standstill(fmus, fmu_runner):
    """direction -1 (M04): the same ramp, negative; the revolutions count down. direction 0 (M05): braking at the
    torque limit, then standing (Coulomb friction holds it)."""
    n = 1500
    direction = np.array([-1] * 700 + [0] * 800)
    out = run(fmu_runner(fmus["SpindleDrive"]).start(**FRICTIONLESS | {"tau_coulomb": 1.0}), [1000.0] * n,
              direction=direction)
    assert out["speed"][600] == pytest.approx(-1000.0, abs=RESOLUTION) and out["at_speed"][600]
    assert np.all(np.diff(out["revolutions"][:700]) <= 0) and out["revolutions"][600] < -5.0
    decel = (T_MAX + 1.0) / J / RAD_S_PER_RPM                       # the motor and the friction both brake
    assert (out["speed"][800] - out["speed"][750]) / 0.05 == pytest.approx(decel, rel=1e-3)
    halved = first(out["speed"][700:] >= -500.0) + 1                  # steps after M05
    assert halved * DT == pytest.approx(500.0 / decel + 1e-3, abs=1.5 * DT)   # + tau_current
    # the last rev/min on the linear loop, then the friction holds it: standing, not creeping
    assert np.all(out["speed"][-200:] == 0.0) and out["at_speed"][-1]
    assert np.ptp(out["revolutions"][-200:]) == 0.0


def test_without_enable_the_spindle_coasts_on_its_friction(fmus, fmu_runner):
    """enable false at 1500 rev/min: no motor torque; Coulomb friction 20 N.m alone stops J = 0.2 kg.m2 in
    J w / tau_coulomb = 1.57 s, and it stays stopped."""
    n = 2400
    enable = np.array([True] * 600 + [False] * (n - 600))
    out = run(fmu_runner(fmus["SpindleDrive"]).start(b_visc=0.0, tau_coulomb=20.0, power_max=1e4), [1500.0] * n,
              enable=enable)
    assert np.all(out["torque"][610:] == pytest.approx(0.0, abs=1e-3))
    w0 = out["speed"][599] * RAD_S_PER_RPM
    stopped = first(out["speed"][600:] == 0.0) + 600
    assert (stopped - 600) * DT == pytest.approx(J * w0 / 20.0, abs=3 * DT)
    assert not out["at_speed"][-1] and np.all(out["speed"][stopped:] == 0.0)


# -- the speed-arrival signal and the limits ---------------------------------------------------------
def test_at_speed_follows_the_band_of_each_new_command(fmus, fmu_runner):
    """at_speed drops when the command changes, and rises where |speed - command| <= 5 % of it (or 10 rev/min)."""
    commands = [1000.0] * 600 + [1200.0] * 600 + [0.0] * 600
    out = run(fmu_runner(fmus["SpindleDrive"]).start(), commands)
    cmd = np.array(commands)
    band = np.maximum(0.05 * np.abs(cmd), 10.0)
    assert np.array_equal(out["at_speed"], np.abs(out["speed"] - cmd) <= band)
    for k in (600, 1200):
        assert not out["at_speed"][k] and out["at_speed"][k + 500]


def test_a_command_beyond_speed_max_is_limited_to_it(fmus, fmu_runner):
    out = run(fmu_runner(fmus["SpindleDrive"]).start(speed_max=1200.0), [3000.0] * 800)
    assert out["speed"].max() <= 1200.0 + overshoot(T_MAX, SpindleParameters()) + RESOLUTION
    assert out["speed"][-1] == pytest.approx(1200.0, abs=RESOLUTION)
    assert out["limited"].all()                              # the speed limit acts on every step
    assert out["at_speed"][-1]                               # arrival at the speed the drive can give


def test_a_broken_command_is_held_not_acted_on(fmus, fmu_runner):
    """NaN speed, a direction of 2, a negative load: the last good inputs are held, and the FMU says why once a
    spell."""
    r = fmu_runner(fmus["SpindleDrive"]).start()
    run(r, [800.0] * 500)
    before = len(r.slave.messages)
    out = run(r, [float("nan")] * 100, start=500)
    assert np.all(out["speed"] == pytest.approx(800.0, abs=0.5))
    run(r, [800.0] * 10, start=600)                          # a good command ends the spell
    out = run(r, [800.0] * 100, direction=[2] * 100, start=610)
    assert np.all(out["speed"] == pytest.approx(800.0, abs=0.5))
    run(r, [800.0] * 10, start=710)
    out = run(r, [800.0] * 100, load=[-5.0] * 100, start=720)              # a load cannot drive the spindle
    assert np.all(out["speed"] == pytest.approx(800.0, abs=0.5))
    said = [text for _, text in r.slave.messages[before:]]
    assert len(said) == 3, said
    assert "input speed_cmd = nan: must be finite; holding the last command" in said[0]
    assert "input direction = 2: must be -1, 0 or 1; holding the last command" in said[1]
    assert "input load_torque = -5: must be finite and >= 0; holding the last command" in said[2]


# -- in a system, under the master ---------------------------------------------------------------------
def test_two_spindles_in_a_system_run_the_same_in_the_c_and_the_python_loop(fmus, tmp_path):
    """A system of two SpindleDrives, the follower commanded with the leader's actual speed (a Real connection),
    the leader by an input table (its Integer direction too): both loops record the same values, and the
    follower tracks the leader through a reversal."""
    from ncfmu.cosim.master import InputTable
    from ncfmu.cosim.ssp import Connection, System, pack, write_system
    from ncfmu.project import OpenSystem
    from ncfmu.systems.compose import component

    system = System("spindles", [component("leader", "SpindleDrive"), component("follower", "SpindleDrive")],
                    [Connection("leader", "speed", "follower", "speed_cmd")], stop_time=2.0)
    archive = pack(write_system(system, tmp_path), fmus["SpindleDrive"].parent, tmp_path / "spindles.ssp")
    table = InputTable(np.array([0.0, 1.0]), {"leader.speed_cmd": np.array([1200.0, 1200.0]),
                                              "leader.direction": np.array([1.0, -1.0])})
    runs = []
    for native in (False, True):
        with OpenSystem(archive) as opened:
            opened.master.native = native
            runs.append(opened.run(inputs=table))
            assert opened.master.loop_used == ("c" if native else "python")
    python, c = runs
    for name in python.data.dtype.names:
        assert np.array_equal(python.data[name], c.data[name]), name
    t, lead, follow = python["time"], python["leader.speed"], python["follower.speed"]
    assert lead[np.searchsorted(t, 0.9)] == pytest.approx(1200.0, abs=RESOLUTION)
    assert lead[-1] == pytest.approx(-1200.0, abs=RESOLUTION)
    # the follower lags a step behind (it reads the leader's speed of the step before), and its own loop
    assert follow[np.searchsorted(t, 0.9)] == pytest.approx(1200.0, abs=1.0)
    assert follow[-1] == pytest.approx(-1200.0, abs=1.0) and python["follower.at_speed"][-1]
