"""The per-step boundary of a Python FMU's binary (fmi/c/python_model.c): values set to inputs are kept in C and
handed to the slave before its next call; the outputs are copied after each step and read without Python. What a
host sees must be what the slave holds: every call below is one that would tell a stale copy from the truth."""

from __future__ import annotations

import math

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
