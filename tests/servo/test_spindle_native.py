"""The native (C) SpindleDrive FMU against its executable specification, the Python stepper, and its design.

- through FMI it agrees with ``ncfmu.servo.spindle.SpindleDrive`` to 1e-9 on random command sequences with
  the torque, power and speed limits, Coulomb friction, encoder quantisation, reversals, enable off and
  broken commands;
- its phase-margin check agrees with python-control (``control.margin``) on random parameter sets;
- an FMU state taken mid-ramp and restored replays the same steps, bit for bit.
"""

from __future__ import annotations

import json
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
from ncfmu.servo.spindle import SpindleDrive
from ncfmu.servo.spindle_model import MIN_PHASE_MARGIN, SpindleParameters, design

OUTPUTS = ("speed", "torque", "power", "revolutions")


def commands(seed: int, n: int, standstill: bool):
    """Random speed commands (50..4000 rev/min, beyond the tests' speed_max 3000) held for random spells, in
    either direction, loads up to 120 N.m (beyond the default torque), a NaN now and then; with ``standstill``
    also M05 (direction 0) and enable-off spells."""
    rng = np.random.default_rng(seed)
    spells = rng.integers(20, 300, n)
    cmd = np.repeat(rng.uniform(50.0, 4000.0, n), spells)[:n]
    direction = np.repeat(rng.choice([-1, 0, 1, 1] if standstill else [-1, 1, 1], n), spells[::-1])[:n]
    enable = np.repeat(rng.random(n) > (0.2 if standstill else 0.0), spells)[:n]
    load = np.repeat(np.where(rng.random(n) < 0.3, rng.uniform(0.0, 120.0, n), 0.0), spells)[:n]
    bad = rng.random(n) < 0.01
    return np.where(bad, np.nan, cmd), direction, enable, load


def compare(fmus, fmu_runner, params, dt, cmd, direction, enable, load):
    """Step the FMU and the Python stepper side by side: (FMU outputs, stepper outputs) per step, and how often a
    limit acted. The Booleans must agree exactly."""
    spec = SpindleDrive(**params)
    runner = fmu_runner(fmus["SpindleDrive"]).start(**params)
    got, want = [], []
    limited = 0
    for i in range(len(cmd)):
        inputs = {"speed_cmd": float(cmd[i]), "direction": int(direction[i]), "enable": bool(enable[i]),
                  "load_torque": float(load[i])}
        runner.set(**inputs)
        runner.slave.do_step(i * dt, dt)
        out = spec.step(i * dt, dt, inputs)
        got.append([runner.get(k) for k in OUTPUTS])
        want.append([out[k] for k in OUTPUTS])
        limited += out["limited"]
    return np.array(got), np.array(want), limited


def count_effect(want, counts_per_rev: int, substep: float, dt: float, torque_max: float) -> np.ndarray:
    """What one encoder count read differently does to each output (speed, torque, power, revolutions): the
    speed one count over the step, the torque the speed loop's answer to one count over a sub-step (Kp q / h, at
    most the limit), the power their products, the angle one count."""
    q = 2 * np.pi / counts_per_rev
    h = dt / np.ceil(dt / substep - 1e-9)
    kp, _ = SpindleParameters().speed_gains
    speed, torque = q / dt * 60 / (2 * np.pi), min(kp * q / h, torque_max)
    power = (np.abs(want[:, 1]).max() * speed + torque * np.abs(want[:, 0]).max() + torque * speed) * 2 * np.pi / 6e4
    return np.array([speed, torque, power, 1.0 / counts_per_rev])


@settings(max_examples=16, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2 ** 31), torque_max=st.sampled_from([5.0, 100.0]), power_max=st.sampled_from([2.0, 15.0]),
       tau_coulomb=st.sampled_from([0.0, 1.0, 30.0]), counts_per_rev=st.sampled_from([4096, 2 ** 20]),
       substep=st.sampled_from([2.5e-4, 3e-4]), dt=st.sampled_from([1e-3, 4e-3]), standstill=st.booleans())
def test_the_fmu_agrees_with_the_python_stepper(fmus, fmu_runner, seed, torque_max, power_max, tau_coulomb,
                                                counts_per_rev, substep, dt, standstill):
    """To 1e-9 of each output's range, step by step -- but for an encoder count read on the other side.

    The C model's zero-order hold equals python-control's to a few units in the last place. The encoder rounds
    the angle to a count: where the two angles straddle a count's edge (a spindle standing under M05 creeps
    towards one; a turning one passes thousands a step), the last-place difference decides and the two read one
    count apart for a sub-step. Then the outputs differ by that count's effect (:func:`count_effect`), no more,
    and the two never drift apart: the angle agrees to one count on every step.
    """
    params = dict(torque_max=torque_max, power_max=power_max, tau_coulomb=tau_coulomb,
                  counts_per_rev=counts_per_rev, substep=substep, speed_max=3000.0)
    got, want, limited = compare(fmus, fmu_runner, params, dt, *commands(seed, 800, standstill))
    scale = np.maximum(np.abs(want).max(axis=0), 1e-9)
    exact = np.all(np.abs(got - want) <= 1e-9 * scale, axis=1)
    count = count_effect(want, counts_per_rev, substep, dt, torque_max)
    assert np.all(np.abs(got - want) <= 1e-9 * scale + count * (1 + 1e-9))
    assert exact.mean() >= 0.95, f"{exact.mean():.1%} of the steps agree to 1e-9"
    assert limited > 0                                            # the limits were exercised


def test_a_restored_state_replays_the_same_steps(fmus, fmu_runner):
    r = fmu_runner(fmus["SpindleDrive"]).start()
    for i in range(150):                                          # mid-ramp: the torque limit acts
        r.set(speed_cmd=2500.0)
        r.slave.do_step(i * 1e-3, 1e-3)
    state = r.slave.get_state()
    runs = []
    for _ in range(2):
        r.slave.set_state(state)
        trace = []
        for i in range(150, 400):
            r.set(speed_cmd=2500.0 if i < 300 else -800.0)
            r.slave.do_step(i * 1e-3, 1e-3)
            trace.append([r.get(k) for k in (*OUTPUTS, "limited", "at_speed")])
        runs.append(trace)
    r.slave.free_state(state)
    assert runs[0] == runs[1] and runs[0][0][-2]                  # limited: it was ramping


# -- design -----------------------------------------------------------------------------------------
def native_verdict(fmu, values: dict[str, float]) -> tuple[str, str]:
    """(status of fmi2ExitInitializationMode, the log) of the native FMU with ``values``, in a process of its own."""
    script = textwrap.dedent('''
        import json, sys
        from fmpy import extract, read_model_description
        from fmpy.fmi2 import FMU2Slave
        from fmpy.fmi1 import FMICallException
        md = read_model_description(sys.argv[1])
        vr = {v.name: v.valueReference for v in md.modelVariables}
        fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(sys.argv[1]), modelIdentifier="SpindleDrive",
                        instanceName="s")
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
    proc = subprocess.run([sys.executable, "-c", script, str(fmu), json.dumps(values)], capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr[-2000:]
    status = re.search(r"^STATUS (\w+)", proc.stdout, re.M).group(1)
    return status, proc.stdout


@pytest.mark.slow
@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(bw=st.floats(0.0, 4.0).map(lambda e: 10 ** e), tau=st.floats(1e-5, 0.02), b=st.floats(0.0, 5.0),
       j=st.floats(1e-3, 5.0))
def test_margin_check_agrees_with_python_control(fmus, bw, tau, b, j):
    values = dict(speed_bandwidth=bw, tau_current=tau, b_visc=b, J=j, substep=min(2.5e-4, 0.5 / bw))
    p = SpindleParameters(speed_bandwidth=bw, tau_current=tau, b_visc=b, J=j)
    d = design(p)
    near = abs(d.phase_margin - MIN_PHASE_MARGIN) < 0.05
    status, log = native_verdict(fmus["SpindleDrive"], values)
    refusal = d.refusal(p)
    if not near:
        assert status == ("Error" if refusal else "OK"), (d, log)
    if refusal and status == "Error":
        said = re.search(r"phase margin of (-?[\d.]+) deg", log)
        if said:
            assert abs(float(said.group(1)) - d.phase_margin) <= 0.051, (log, d)
        assert "speed_bandwidth = " in log
    if refusal:
        with pytest.raises(ConfigError):
            SpindleDrive(**values)
    else:
        SpindleDrive(**values)


def test_a_refused_design_names_speed_bandwidth_in_the_fmu_too(fmus):
    status, log = native_verdict(fmus["SpindleDrive"], {"speed_bandwidth": 300.0, "tau_current": 0.01})
    assert status == "Error"
    assert re.search(r"speed_bandwidth = 300: gives the speed loop a phase margin of \d+\.\d deg \(< 30 deg\) "
                     r"with tau_current = 0\.01 s; lower speed_bandwidth", log), log
    status, log = native_verdict(fmus["SpindleDrive"], {"speed_bandwidth": 5000.0})
    assert status == "Error" and "speed_bandwidth = 5000: must be <= 0.5 / substep = 2000 rad/s" in log, log


def test_documentation_carries_the_design_and_the_sources(fmus):
    with zipfile.ZipFile(fmus["SpindleDrive"]) as z:
        page = z.read("documentation/index.html").decode()
        names = z.namelist()
    d = design()
    assert f"{d.phase_margin:.1f} deg" in page and "Runtime requirements" in page
    assert "4727 rev/min/s" in page and "1432 rev/min" in page        # (100 - 1) N.m / 0.2 kg.m2; 15 kW / 100 N.m
    # the model's own sources beside the FMI layer's (which the ServoAxis's tests name)
    assert {"sources/spindle_model.c", "sources/drive_math.h", "sources/model_vars.h",
            "sources/buildDescription.xml"} <= set(names)
    assert "spindle_model.c" in page
    assert "bode.png" in page and "documentation/bode.png" in names
