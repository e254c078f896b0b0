"""The native (C) ServoAxis FMU against its executable specification, the Python stepper, and its design.

- the digital drive through FMI agrees with ``ncfmu.servo.axis.ServoAxis`` to 1e-9 on random command
  sequences with the torque and speed limits, Coulomb friction and encoder quantisation active;
- its margin check agrees with python-control (``control.margin``) on random parameter sets;
- friction never moves the axis, whatever ``tau_coulomb``.
(Without Python, in a C host: tests/fmi/test_native_hosts.py.)
"""

from __future__ import annotations

import re
import subprocess
import sys
import textwrap
import zipfile

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ncfmu.errors import ConfigError
from ncfmu.servo.axis import ServoAxis
from ncfmu.servo.model import MIN_PHASE_MARGIN, AxisParameters, design

DT = 1e-3


def commands(seed: int, n: int, v_max: float, jumps: bool):
    """A random velocity profile (and its integral), with occasional command jumps when ``jumps``."""
    rng = np.random.default_rng(seed)
    vel = np.clip(np.cumsum(rng.normal(0.0, v_max / 10, n)), -v_max, v_max)
    pos = np.cumsum(vel) * DT
    if jumps:
        pos = pos + np.where(rng.random(n) < 0.01, rng.normal(0.0, 5.0, n), 0.0).cumsum()
    return pos, vel


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2 ** 31), torque_max=st.sampled_from([0.5, 2.0, 12.0]),
       speed_max=st.sampled_from([300.0, 3000.0]), tau_coulomb=st.sampled_from([0.0, 0.1, 1.0]),
       counts_per_rev=st.sampled_from([1000, 2 ** 20]), jumps=st.booleans(), enable_off=st.booleans())
def test_digital_drive_agrees_with_the_python_stepper(fmus, fmu_runner, seed, torque_max, speed_max, tau_coulomb,
                                                      counts_per_rev, jumps, enable_off):
    params = dict(torque_max=torque_max, speed_max=speed_max, tau_coulomb=tau_coulomb,
                  counts_per_rev=counts_per_rev, pos_start=3.0)
    n = 600
    pos, vel = commands(seed, n, 200.0, jumps)
    pos = pos + 3.0
    spec = ServoAxis(**params)
    runner = fmu_runner(fmus["ServoAxis"]).start(**params)
    got, want = [], []
    limited = False
    for i in range(n):
        enable = not (enable_off and 200 <= i < 260)
        runner.set(pos_cmd=float(pos[i]), vel_ff=float(vel[i]), enable=enable)
        runner.slave.do_step(i * DT, DT)
        out = spec.step(i * DT, DT, {"pos_cmd": float(pos[i]), "vel_ff": float(vel[i]), "enable": enable})
        got.append([runner.get(k) for k in ("pos", "vel", "torque", "following_error")])
        want.append([out[k] for k in ("pos", "vel", "torque", "following_error")])
        assert runner.get("limited") == out["limited"] and runner.get("in_position") == out["in_position"], i
        limited |= out["limited"]
    got, want = np.array(got), np.array(want)
    scale = np.maximum(np.abs(want).max(axis=0), 1e-9)
    assert (np.abs(got - want).max(axis=0) / scale).max() <= 1e-9
    if torque_max == 0.5:
        assert limited                                 # the limits were exercised, not only the linear path


def test_ideal_mode_agrees_with_the_python_stepper(fmus, fmu_runner):
    pos, vel = commands(7, 800, 300.0, False)
    spec = ServoAxis(ideal=True)
    runner = fmu_runner(fmus["ServoAxis"]).start(ideal=True)
    got, want = [], []
    for i in range(len(pos)):
        runner.set(pos_cmd=float(pos[i]), vel_ff=float(vel[i]))
        runner.slave.do_step(i * DT, DT)
        out = spec.step(i * DT, DT, {"pos_cmd": float(pos[i]), "vel_ff": float(vel[i]), "enable": True})
        got.append([runner.get("pos"), runner.get("vel"), runner.get("torque")])
        want.append([out["pos"], out["vel"], out["torque"]])
    got, want = np.array(got), np.array(want)
    assert (np.abs(got - want).max(axis=0) / np.abs(want).max(axis=0)).max() <= 1e-9


# -- design ------------------------------------------------------------------------------------
def native_verdict(fmu, values: dict[str, float]) -> tuple[str, str]:
    """(status of fmi2ExitInitializationMode, the log) of the native FMU with ``values``."""
    script = textwrap.dedent('''
        import json, sys
        from fmpy import extract, read_model_description
        from fmpy.fmi2 import FMU2Slave
        from fmpy.fmi1 import FMICallException
        md = read_model_description(sys.argv[1])
        vr = {v.name: v.valueReference for v in md.modelVariables}
        fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(sys.argv[1]), modelIdentifier="ServoAxis",
                        instanceName="a")
        fmu.instantiate(loggingOn=True)       # fmpy prints the FMU's log
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        values = json.loads(sys.argv[2])
        fmu.setReal([vr[k] for k in values], list(values.values()))
        try:
            fmu.exitInitializationMode()
            print("STATUS OK")
        except FMICallException as e:
            print("STATUS", {3: "Error", 4: "Fatal"}.get(e.status, e.status))
        fmu.freeInstance()
    ''')
    import json
    proc = subprocess.run([sys.executable, "-c", script, str(fmu), json.dumps(values)], capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr[-2000:]
    status = re.search(r"^STATUS (\w+)", proc.stdout, re.M).group(1)
    return status, proc.stdout


@pytest.mark.slow
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(kv=st.floats(-2.5, 3.2).map(lambda e: 10 ** e), bw=st.floats(-2.3, 3.65).map(lambda e: 10 ** e),
       tau=st.floats(1e-5, 2e-3), b=st.floats(0.0, 0.05), j=st.floats(1e-4, 0.05))
def test_margin_check_agrees_with_python_control(fmus, kv, bw, tau, b, j):
    values = dict(Kv=kv, vel_bandwidth=bw, tau_current=tau, b_visc=b, J=j, substep=1e-4)
    if bw * 1e-4 > 0.5:
        values["substep"] = 0.5 / bw
    p = AxisParameters(Kv=kv, vel_bandwidth=bw, tau_current=tau, b_visc=b, J=j)
    d = design(p)
    near = min(abs(d.velocity_margin - MIN_PHASE_MARGIN), abs(d.position_margin - MIN_PHASE_MARGIN)) < 0.05
    status, log = native_verdict(fmus["ServoAxis"], values)
    refusal = d.refusal(p)
    if not near:
        assert status == ("Error" if refusal else "OK"), (d, log)
    if refusal and status == "Error":
        said = re.search(r"phase margin of (-?[\d.]+) deg", log)
        expected = d.velocity_margin if refusal[0] == "vel_bandwidth" else d.position_margin
        if said:
            assert abs(float(said.group(1)) - expected) <= 0.051, (log, d)
        assert f"{refusal[0]} = " in log
    with pytest.raises(ConfigError) if refusal else _nothing():
        ServoAxis(**values)


class _nothing:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


def test_documentation_carries_the_design_and_the_runtime_needs(fmus):
    with zipfile.ZipFile(fmus["ServoAxis"]) as z:
        page = z.read("documentation/index.html").decode()
        names = z.namelist()
    d = design(AxisParameters())
    assert f"{d.velocity_margin:.1f} deg" in page and f"{d.position_margin:.1f} deg" in page
    assert "bode.png" in page and "documentation/bode.png" in names
    assert "Runtime requirements" in page
    assert {"sources/fmi2_functions.c", "sources/native_model.c", "sources/servo_model.c", "sources/model_vars.h",
            "sources/buildDescription.xml"} <= set(names)


# -- friction --------------------------------------------------------------------------------------
@pytest.mark.parametrize("tau_coulomb", [1e3, 1e9])
def test_friction_never_moves_the_axis(fmus, fmu_runner, tau_coulomb):
    """Huge Coulomb friction: the axis sticks (the motor torque never exceeds it); never a jump."""
    runner = fmu_runner(fmus["ServoAxis"]).start(tau_coulomb=tau_coulomb, pos_start=5.0)
    for i in range(300):
        runner.set(pos_cmd=5.0 + 0.05 * i, vel_ff=50.0)
        runner.slave.do_step(i * DT, DT)
        assert runner.get("pos") == 5.0


def test_friction_only_brakes_a_moving_axis():
    """Friction raised on a moving axis (Python stepper, the FMU's specification): it stops without
    going back, and no further than its speed takes it in one sub-step."""
    axis = ServoAxis()
    for i in range(200):
        out = axis.step(i * DT, DT, {"pos_cmd": 0.05 * i, "vel_ff": 50.0, "enable": True})
    before, v = out["pos"], out["vel"]
    axis.tau_coulomb = 1e9
    out = axis.step(0.2, DT, {"pos_cmd": 10.0, "vel_ff": 50.0, "enable": True})
    assert before <= out["pos"] <= before + abs(v) * DT + 2 * axis.quantum
    assert axis.x[3] == 0.0
