"""The per-step boundary of a Python FMU's binary (fmi/c/python_model.c): values set to inputs are kept in C and
handed to the slave before its next call; the outputs are copied after each step and read without Python. What a
host sees must be what the slave holds: every call below is one that would tell a stale copy from the truth."""

from __future__ import annotations

import copy
import math
import subprocess
import sys

from ncfmu.controllers import AreaLimiter
from ncfmu.systems import parameters

LIMITER = parameters("lathe_roughing", "limiter")
OUTPUTS = [p.name for p in AreaLimiter.ports("output")]


def outputs(runner) -> dict:
    return {n: runner.get(n) for n in OUTPUTS}


def twin_outputs(twin_out: dict) -> dict:
    return {n: (float(v) if isinstance(v, float) else int(v) if not isinstance(v, bool) else v)
            for n, v in twin_out.items()}


def test_inputs_set_between_steps_reach_the_step_and_outputs_are_the_steps(fmus, fmu_runner):
    """The FMU against the plain controller, step by step, with inputs set several times between steps (the last
    value counts), some kinds left unset for steps, and reads of inputs (the slow path) between Set and step."""
    r = fmu_runner(fmus["AreaLimiter"]).start(**LIMITER)
    twin = AreaLimiter.from_parameters({**AreaLimiter.default_parameters(), **LIMITER})
    inputs = AreaLimiter.default_inputs()
    for k in range(400):
        t = k * 1e-3
        x = 5.0 * math.sin(2.0 * t) - 2.0
        if k % 3:                                   # some steps set nothing: the last values stay
            r.set(ref_cmd_in=x + 100.0)             # a value overwritten before the step never reaches it
            r.set(ref_cmd_in=x, lim_cmd_in=-x, ref_pos=x - 0.01, lim_pos=-x + 0.01)
            inputs.update(ref_cmd_in=x, lim_cmd_in=-x, ref_pos=x - 0.01, lim_pos=-x + 0.01)
            assert r.get("ref_cmd_in") == x         # read back before the step: handed over first
        r.slave.do_step(t, 1e-3)
        out = twin.step(t, 1e-3, dict(inputs))
        assert outputs(r) == twin_outputs(out), f"step {k}"


def test_outputs_after_a_restored_state_are_the_states(fmus, fmu_runner):
    """fmi2SetFMUstate changes the outputs without a step: a Get after it reads the restored ones, and an input set
    before a state is taken is in the state."""
    r = fmu_runner(fmus["AreaLimiter"]).start(**LIMITER)
    for k in range(50):
        r.set(ref_cmd_in=0.01 * k, ref_pos=0.01 * k)
        r.slave.do_step(k * 1e-3, 1e-3)
    r.set(ref_cmd_in=0.5, ref_pos=0.49)             # set, not yet stepped: part of the state taken now
    saved, state = outputs(r), r.slave.get_state()
    for k in range(50, 300):
        r.set(ref_cmd_in=-0.02 * k, ref_pos=-0.02 * k + 0.01)
        r.slave.do_step(k * 1e-3, 1e-3)
    assert outputs(r) != saved
    r.slave.set_state(state)
    assert outputs(r) == saved
    assert (r.get("ref_cmd_in"), r.get("ref_pos")) == (0.5, 0.49)
    r.slave.free_state(state)



def test_a_restored_state_steps_on_from_the_state_with_its_inputs(fmus, fmu_runner):
    """DoStep calls the controller's step directly and keeps what it handed over: after fmi2SetFMUstate the restored
    controller steps (not the one before it), its outputs are read, and an input set to the value it had just before
    the restore reaches the step although the shim handed that very value over already (the state's dict held
    another)."""
    r = fmu_runner(fmus["AreaLimiter"]).start(**LIMITER)
    twin = AreaLimiter.from_parameters({**AreaLimiter.default_parameters(), **LIMITER})
    inputs = AreaLimiter.default_inputs()

    def step(k: int, x: float) -> None:
        r.set(ref_cmd_in=x, ref_pos=x - 0.01)
        inputs.update(ref_cmd_in=x, ref_pos=x - 0.01)
        r.slave.do_step(k * 1e-3, 1e-3)
        assert outputs(r) == twin_outputs(twin.step(k * 1e-3, 1e-3, dict(inputs))), f"step {k}"

    for k in range(40):
        step(k, 0.01 * k)
    state, at_state = r.slave.get_state(), copy.deepcopy((twin, inputs))
    for k in range(40, 140):                         # away: ref 0.39 -> -0.60
        step(k, 0.39 - 0.01 * (k - 39))
    away = outputs(r)
    r.slave.set_state(state)
    twin, inputs = at_state
    assert outputs(r) != away
    for k in range(40, 60):                          # first the value handed over last, then back up
        step(k, 0.39 - 0.01 * 100 if k == 40 else 0.39 + 0.002 * (k - 40))
    r.slave.free_state(state)


# A host in its own process (a defect in the step's error path may crash it): the FMU's own copy of the controller
# is given a step that raises; the binary fails that DoStep with fmi2Error, the slave logs where, and the instance
# goes on (reset, initialised again, its own step).
FAILING_STEP_HOST = r"""
import importlib, sys, tempfile
from ctypes import byref
import fmpy.fmi2 as fmi2
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.logging import addLoggerProxy
from ncfmu.fmi.builder import vendored_package

fmu = sys.argv[1]
md = read_model_description(fmu)
def said(env, name, status, category, message):
    print("LOG", status, message.decode().replace("\n", " | "), flush=True)
callbacks = fmi2.fmi2CallbackFunctions()
callbacks.logger = fmi2.fmi2CallbackLoggerTYPE(said)
callbacks.allocateMemory, callbacks.freeMemory = fmi2.defaultCallbacks.allocateMemory, fmi2.defaultCallbacks.freeMemory
addLoggerProxy(byref(callbacks))
slave = fmi2.FMU2Slave(guid=md.guid, unzipDirectory=extract(fmu, tempfile.mkdtemp()),
                       modelIdentifier=md.coSimulation.modelIdentifier, instanceName="dut")
slave.instantiate(callbacks=callbacks)
limiter = importlib.import_module(f"{vendored_package(fmu)}.controllers.limiter").AreaLimiter  # the FMU's own copy
working = limiter.step_then_count_messages
def broken_step(self, t, dt, inputs):
    raise ZeroDivisionError("a defect in the step")
limiter.step_then_count_messages = broken_step
ref_cmd = next(v.valueReference for v in md.modelVariables if v.name == "ref_cmd")
for attempt in ("broken", "working"):
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    try:
        slave.doStep(0.0, 1e-3)
        slave.doStep(1e-3, 1e-3)
        print("STEPPED", attempt, slave.getReal([ref_cmd]), flush=True)
    except FMICallException as err:
        print("FAILED", attempt, err, flush=True)
    slave.reset()
    limiter.step_then_count_messages = working
slave.freeInstance()
print("END", flush=True)
"""


def test_a_step_that_raises_fails_the_dostep_and_the_log_says_where(fmus):
    proc = subprocess.run([sys.executable, "-c", FAILING_STEP_HOST, str(fmus["AreaLimiter"])],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-3000:]
    lines = proc.stdout.splitlines()
    failed = [line for line in lines if line.startswith("FAILED")]
    assert failed and failed[0].startswith("FAILED broken") and "fmi2DoStep" in failed[0], lines
    errors = [line for line in lines if line.startswith("LOG 3 ")]
    assert len(errors) == 1, lines
    assert errors[0].startswith("LOG 3 dut: doStep at t = 0.000000 s failed: ZeroDivisionError('a defect in the step')")
    assert "Traceback" in errors[0] and "in broken_step" in errors[0], errors[0]
    assert lines[-2].startswith("STEPPED working [") and lines[-1] == "END", lines
