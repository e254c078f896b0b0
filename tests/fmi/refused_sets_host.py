"""A refused set changes nothing, through the built FMU (run as a script, in its own process, by
test_refused_sets.py):

    python refused_sets_host.py <fmu> <examples>

A seeded hypothesis property in an fmpy host (FMU2Slave): two instances of the FMU, ``a`` and its twin ``b``,
step side by side in a small closed loop (tests/twins.py). Before some steps ``a`` is offered values for any of
its variables (parameters fixed or tunable, inputs, outputs; NaN, infinities, subnormals, the edges of each
rule). A value ``a`` refuses (fmi2Error) is never shown to ``b``; one ``a`` takes, ``b`` takes too. After each
offer and each step every variable of ``a`` reads bit-identical to ``b``'s, and their statuses agree.

Prints ``EXAMPLES <n> OFFERS <m> REFUSED <k>`` and exits 0 when the property held; a falsifying example
(hypothesis's report) and exit 1 when not. A crash is the process dying: the test sees it.
"""

from __future__ import annotations

import sys
import tempfile
from ctypes import byref
from pathlib import Path

from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave, defaultCallbacks, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE
from fmpy.logging import addLoggerProxy
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

sys.path.insert(0, str(Path(__file__).parents[1]))
from twins import LOOP_PARAMETERS, loop_inputs, offered_values, same_bits  # noqa: E402

STEPS = 120
DT = 1e-3
fmu_path, examples = sys.argv[1], int(sys.argv[2])
md = read_model_description(fmu_path)
folder = extract(fmu_path, tempfile.mkdtemp())
MODEL = md.coSimulation.modelIdentifier
VARS = [v for v in md.modelVariables if v.causality in ("parameter", "input", "output")]
BY_NAME = {v.name: v for v in VARS}
TUNABLE = [v for v in VARS if v.causality == "parameter" and v.variability == "tunable"]
PARAMETERS = [v for v in VARS if v.causality == "parameter"]
counts = {"examples": 0, "offers": 0, "refused": 0}
LOG: list[str] = []


def _log(env, name, status, category, message):
    LOG.append(message.decode("utf-8", "replace"))


callbacks = fmi2CallbackFunctions()
callbacks.logger = fmi2CallbackLoggerTYPE(_log)
callbacks.allocateMemory = defaultCallbacks.allocateMemory
callbacks.freeMemory = defaultCallbacks.freeMemory
addLoggerProxy(byref(callbacks))                  # formats the FMU's printf-style messages, as fmpy does


def _bound(text: str | None) -> float | None:
    return None if text is None else float(text)


def _start(v) -> object:
    return {"Real": float, "Integer": int, "Boolean": lambda s: s == "true", "String": str}[v.type](v.start or 0)


RELATED = tuple(float(_start(v)) for v in PARAMETERS if v.type in ("Real", "Integer"))


def call(fn, *args) -> tuple[int, object]:
    """(status, result) of one FMI call: fmpy raises on an error status, a host sees the status."""
    try:
        return 0, fn(*args)
    except FMICallException as err:
        return err.status, None


def set_value(fmu: FMU2Slave, v, value: object) -> int:
    setter = {"Real": fmu.setReal, "Integer": fmu.setInteger, "Boolean": fmu.setBoolean, "String": fmu.setString}
    return call(setter[v.type], [v.valueReference], [value])[0]


def read_all(fmu: FMU2Slave, causalities=("parameter", "input", "output")) -> dict[str, tuple[int, object]]:
    getter = {"Real": fmu.getReal, "Integer": fmu.getInteger, "Boolean": fmu.getBoolean, "String": fmu.getString}
    out = {}
    for v in VARS:
        if v.causality not in causalities:
            continue
        status, got = call(getter[v.type], [v.valueReference])
        value = got[0] if got is not None else None
        out[v.name] = (status, value.decode("utf-8", "replace") if isinstance(value, bytes) else value)
    return out


def offer() -> st.SearchStrategy:
    """One value for one variable; the tunable parameters (if any) are offered half the time."""
    pool = st.sampled_from(VARS)
    if TUNABLE:
        pool = st.one_of(st.sampled_from(TUNABLE), st.sampled_from(TUNABLE), st.sampled_from(PARAMETERS), pool)
    return pool.flatmap(lambda v: st.tuples(
        st.just(v.name), offered_values(v.type, _start(v), _bound(v.min), _bound(v.max), RELATED)))


def instance(name: str) -> FMU2Slave:
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=folder, modelIdentifier=MODEL, instanceName=name)
    fmu.instantiate(callbacks=callbacks)
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    for name, value in LOOP_PARAMETERS.get(MODEL, {}).items():
        assert set_value(fmu, BY_NAME[name], value) == 0
    fmu.exitInitializationMode()
    return fmu


#: The reported cases, tried first: a repeat period within the pulse, stored by configure() before it was refused.
REPORTED = {"OperatorPanel": [[(15, ("repeat_every", 5e-324))], [(40, ("repeat_every", 0.005))]]}


def with_reported(test):
    for offers in REPORTED.get(MODEL, []):
        test = example(offers=offers)(test)
    return test


@settings(max_examples=examples, derandomize=True, database=None, deadline=None,
          suppress_health_check=list(HealthCheck))
@given(offers=st.lists(st.tuples(st.integers(0, STEPS - 1), offer()), min_size=1, max_size=6))
@with_reported
def refused_sets_change_nothing(offers):
    counts["examples"] += 1
    a, b = instance("a"), instance("b")
    inputs = {v.name: _start(v) for v in VARS if v.causality == "input"}
    try:
        for k in range(STEPS):
            for _, (name, value) in (o for o in offers if o[0] == k):
                counts["offers"] += 1
                v = BY_NAME[name]
                del LOG[:]
                status = set_value(a, v, value)
                if status > 1:                       # refused (fmi2Error): b never sees it, the log says why
                    counts["refused"] += 1
                    assert LOG and ("refused" in LOG[-1] or "cannot" in LOG[-1]), f"{name} = {value!r}: {LOG}"
                else:
                    assert set_value(b, v, value) == status, f"{name} = {value!r}: a took it, its twin did not"
                seen_a, seen_b = read_all(a), read_all(b)
                assert same_bits(seen_a, seen_b), (
                    f"step {k}: after {name} = {value!r} (status {status}) a and its twin differ: "
                    + str({n: (seen_a[n], seen_b[n]) for n in seen_a if not same_bits(seen_a[n], seen_b[n])}))
            for name, value in inputs.items():
                assert set_value(a, BY_NAME[name], value) == set_value(b, BY_NAME[name], value)
            assert call(a.doStep, k * DT, DT)[0] == call(b.doStep, k * DT, DT)[0], f"step {k}: statuses differ"
            seen_a, seen_b = read_all(a, ("output",)), read_all(b, ("output",))
            assert same_bits(seen_a, seen_b), (
                f"step {k} differs: "
                + str({n: (seen_a[n], seen_b[n]) for n in seen_a if not same_bits(seen_a[n], seen_b[n])}))
            loop_inputs(MODEL, k + 1, inputs, {n: value for n, (_, value) in seen_a.items()})
        assert same_bits(read_all(a), read_all(b)), "the twins differ at the end"
    finally:
        for fmu in (a, b):
            call(fmu.terminate)
            fmu.freeInstance()


refused_sets_change_nothing()
print(f"EXAMPLES {counts['examples']} OFFERS {counts['offers']} REFUSED {counts['refused']}", flush=True)
