"""ServoAxis: python-control model, the built FMU against control.forced_response, and physics."""

import math

import control as ct
import numpy as np
import pytest

from ncfmu.servo.axis import ServoAxis
from ncfmu.servo.model import discretize, servo_axis

DT = 1e-3


def run_fmu(runner, n, pos_cmd, vel_ff, **params):
    r = runner.start(**params)
    out = {k: [] for k in ("pos", "vel", "following_error", "torque")}
    for i in range(n):
        r.set(pos_cmd=float(pos_cmd[i]), vel_ff=float(vel_ff[i]))
        r.slave.do_step(i * DT, DT)
        for k in out:
            out[k].append(r.get(k))
    return {k: np.array(v) for k, v in out.items()}


def test_closed_loop_is_stable_and_well_damped():
    poles = np.linalg.eigvals(servo_axis().A)
    assert np.all(poles.real < 0)
    zeta = -poles.real / np.abs(poles)
    assert zeta.min() > 0.7


def test_ideal_fmu_reproduces_forced_response_of_constant_input(fmus, fmu_runner):
    """Constant inputs: the continuous model's forced_response is exact; the FMU must agree."""
    n = 300
    cmd = np.full(n, 1.0)
    out = run_fmu(fmu_runner(fmus["ServoAxis"]), n, cmd, np.zeros(n), ideal=True, pos_start=0.0)
    # the FMU moves the command from its previous value (pos_start) to 1.0 over the first step
    # (fine interpolation), then holds it: compare from the second step on against the response
    # to the constant input started from the state the FMU had after one step.
    sys = servo_axis()
    t = np.arange(n) * DT
    x1 = ServoAxis(ideal=True, pos_start=0.0)
    x1.step(0.0, DT, {"pos_cmd": 1.0, "vel_ff": 0.0, "enable": True})
    resp = ct.forced_response(sys, T=t, U=np.vstack([np.ones(n), np.zeros(n), np.zeros(n)]), X0=x1.x)
    for k, name in enumerate(sys.output_labels):
        ref = resp.outputs[k][: n - 1]      # y[k]: k steps after the state X0 the FMU had after one step
        got = out[name][: n - 1]
        scale = max(np.abs(ref).max(), 1e-12)
        assert np.abs(got - ref).max() / scale <= 1e-9, name


def test_ideal_fmu_reproduces_forced_response_of_zoh_model(fmus, fmu_runner):
    """Arbitrary inputs: the exact ZOH model at the sub-step, fed the fine-interpolated command."""
    n, sub = 400, 10
    rng = np.random.default_rng(3)
    vel = np.cumsum(rng.normal(0, 20, n)) * 0.1
    cmd = np.cumsum(vel) * DT
    out = run_fmu(fmu_runner(fmus["ServoAxis"]), n, cmd, vel, ideal=True)
    sysd = discretize(servo_axis(), DT / sub)
    prev_c, prev_v = np.concatenate([[0.0], cmd[:-1]]), np.concatenate([[0.0], vel[:-1]])
    w = (np.arange(sub) + 1) / sub
    u_pos = (prev_c[:, None] * (1 - w) + cmd[:, None] * w).ravel()
    u_vel = (prev_v[:, None] * (1 - w) + vel[:, None] * w).ravel()
    u_acc = np.repeat((vel - prev_v) / DT, sub)
    t = np.arange(n * sub) * DT / sub
    resp = ct.forced_response(sysd, T=t, U=np.vstack([u_pos, u_vel, u_acc]))
    pos_ref = resp.outputs[0][sub - 1::sub]
    # forced_response's y[k] is after k steps from x0; the FMU reports the state after its step
    x = np.zeros(4)
    A, B = np.asarray(sysd.A), np.asarray(sysd.B)
    states = []
    U = np.vstack([u_pos, u_vel, u_acc])
    for k in range(n * sub):
        x = A @ x + B @ U[:, k]
        if k % sub == sub - 1:
            states.append(x.copy())
    pos_ref = np.array(states)[:, 2]
    assert np.abs(out["pos"] - pos_ref).max() / np.abs(pos_ref).max() <= 1e-9
    # and the same discretised model through control.forced_response, one sub-step later
    assert np.abs(resp.outputs[0][sub::sub] - pos_ref[:-1]).max() / np.abs(pos_ref).max() <= 1e-9


def ramp_error(kff, kaff, v=20.0, n=1500):
    axis = ServoAxis(kff=kff, kaff=kaff, ideal=True)
    fe = []
    for i in range(n):
        fe.append(axis.step(i * DT, DT, {"pos_cmd": v * (i + 1) * DT, "vel_ff": v, "enable": True})["following_error"])
    return np.array(fe)


def test_following_error_on_a_ramp():
    v, kv = 20.0, 30.0
    fe = ramp_error(0.0, 0.0, v)
    # type-1 loop: e = v / Kv; the command is held at its end-of-sub-step value, which leads the
    # continuous ramp by half a sub-step (h = 0.1 ms): e = v / Kv - v * h / 2, exactly
    assert fe[-1] == pytest.approx(v / kv - v * 1e-4 / 2, rel=1e-6)
    fe_ff = ramp_error(1.0, 1.0, v)
    # full feed-forward: nothing left but the half sub-step lead of the held command
    assert fe_ff[-1] == pytest.approx(-v * 1e-4 / 2, abs=1e-9)
    assert abs(fe_ff[200:]).max() < 0.01 * v / kv            # after the velocity step has settled


def test_step_settles_into_the_in_position_band():
    axis = ServoAxis(ideal=False)
    t_in = None
    for i in range(1000):
        o = axis.step(i * DT, DT, {"pos_cmd": 1.0, "vel_ff": 0.0, "enable": True})
        if o["in_position"] and t_in is None:
            t_in = (i + 1) * DT
    assert t_in is not None and t_in < 0.3                  # ~5 time constants of the Kv loop
    assert abs(o["pos"] - 1.0) < 1e-3 * 0.005 + 2 * 10 / 2 ** 20


def test_speed_never_exceeds_the_limit():
    axis = ServoAxis(speed_max=600.0)                       # 600 rpm * 10 mm = 100 mm/s
    v_max = 600.0 * 10.0 / 60.0
    vel, limited = [], False
    for i in range(1500):
        o = axis.step(i * DT, DT, {"pos_cmd": 100.0, "vel_ff": 0.0, "enable": True})
        vel.append(axis.x[3])
        limited |= o["limited"]
    assert limited
    assert max(vel) <= v_max
    assert max(vel) > 0.95 * v_max                          # the limit is reached, not avoided
    assert axis.x[2] == pytest.approx(100.0, abs=0.005)


def test_nan_command_is_held():
    axis = ServoAxis()
    axis.step(0.0, DT, {"pos_cmd": 0.5, "vel_ff": 0.0, "enable": True})
    o = axis.step(DT, DT, {"pos_cmd": math.nan, "vel_ff": 0.0, "enable": True})
    assert math.isfinite(o["pos"]) and axis.pos_cmd == 0.5
    assert any("pos_cmd" in t for _, t in axis.take_messages())
