"""Restoring a serialized Python FMU state: every value is checked, not only the names.

A state is restored only when every value it carries keeps the rule of its port or field (types, finite
positions within reach, objects of the classes a freshly built controller holds there, what configure()
derives equal to what it derives, no command that jumps); anything else is fmi2Error naming the field, and
the instance keeps its previous state. The states here are real ones, taken mid-cycle from closed-loop runs of
every system; the cases that broke are reproduced through the built FMUs, each in its own process, and a
seeded fuzz mutates values, types, lengths and nesting of real states -- in Python (``state.loads``) and
through the FMUs.
"""

from __future__ import annotations

import copy
import json
import math
import random
import re
import subprocess
import sys
import textwrap

import pytest

from ncfmu.controllers import AreaLimiter, CutSequencer, OperatorPanel, ProgrammableFeed
from ncfmu.controllers.base import SPEED_LIMIT
from ncfmu.controllers.contour import ContourInterpolator
from ncfmu.errors import ConfigError
from ncfmu.fmi import state
from ncfmu.fmi.contract import split_state
from ncfmu.fmi.sealed_state import unseal
from ncfmu.project import OpenSystem, system_archive

CLASSES = {c.MODEL_NAME: c for c in (CutSequencer, AreaLimiter, ProgrammableFeed, ContourInterpolator,
                                     OperatorPanel)}
DT = 1e-3

#: Closed-loop runs the states come from: (system, start values, times at which every Python FMU is saved). They
#: cover every Python model, cycles under way, feed hold, an emergency return and an envelope alarm.
RUNS = [
    ("lathe_taper", {}, (0.0, 0.05, 0.5, 2.0, 3.3337)),
    ("lathe_roughing", {"panel.hold_at": 1.0, "panel.release_at": 1.6}, (1.2, 2.5)),
    ("grinder_feed", {"panel.emergency_at": 3.0}, (2.0, 3.0045, 4.5)),
    ("grinder_envelope", {}, (1.0, 3.0, 6.5)),
    ("mill_contour", {"panel.hold_at": 2.0, "panel.release_at": 2.5}, (0.3, 2.2, 7.25)),
]
#: More times of the same runs for the slow tests (the whole cycles).
MORE_TIMES = {"lathe_taper": (5.0, 11.0, 20.0, 33.3, 49.0), "lathe_roughing": (7.0, 30.0, 60.0, 94.0),
              "grinder_feed": (6.0, 10.0, 20.0, 34.0), "grinder_envelope": (10.0, 15.5, 24.0),
              "mill_contour": (11.0, 20.0, 30.0, 41.0)}


def collect_states(system: str, start_values: dict, times, step: float | None = None, mode: str = "gauss-seidel"
                   ) -> list[tuple[str, str, float, bytes]]:
    """(system, instance, t, bytes) of every Python FMU of a closed-loop run of ``system`` at each time."""
    out = []
    times = sorted(times)
    with OpenSystem(system_archive(system), mode=mode) as opened:
        master = opened.master
        run = master.prepare(times[-1] + 0.01, step, start_values, None, 0.0)
        done = 0
        for t in times:
            k = int(round(t / run.h))
            run.steps(done, k)
            done = k
            for slave in opened.slaves:
                handle = slave.get_state()
                blob = slave.serialize_state(handle)
                slave.free_state(handle)
                if unseal(blob).payload.startswith(b"{"):   # the Python FMUs (the servo's format is its own)
                    out.append((system, slave.name, t, split_state(blob)[0]))   # the JSON, without the time
    return out


@pytest.fixture(scope="module")
def real_states(project):
    states = [s for system, values, times in RUNS for s in collect_states(system, values, times)]
    assert {json.loads(b)["model"] for *_, b in states} == set(CLASSES)
    return states


def as_dev(blob: bytes) -> bytes:
    """The same state, tagged for the ncfmu package this test runs (build "dev") instead of an FMU's copy."""
    doc = json.loads(blob)
    doc["build"] = state.build_digest()
    return json.dumps(doc, separators=(",", ":")).encode()


def dev_load(blob: bytes):
    model = re.search(rb'"model": ?"(\w+)"', blob)          # not json.loads: the bytes may be any mutation
    cls = CLASSES[model.group(1).decode()] if model else OperatorPanel
    return cls, state.loads(blob, cls, cls.from_parameters)


# -- the mutations ----------------------------------------------------------------------------------
TAGS = ["controllers.base:Controller", "errors:ConfigError", "controllers.motion:LinearMove", "controllers.feed:Word",
        "controllers.geometry:Line", "controllers.base:PositionGuard", "controllers.sequencer:Block",
        "controllers.limiter:AreaLimiter", "os:system", "controllers.base:OverrideDial"]


def _paths(tree, prefix=()):
    if prefix:
        yield prefix
    if isinstance(tree, dict):
        for k, v in tree.items():
            yield from _paths(v, (*prefix, k))
    elif isinstance(tree, list):
        for i, v in enumerate(tree):
            yield from _paths(v, (*prefix, i))


def _replacement(old, rng: random.Random):
    kind = rng.choice(["nan", "inf", "-inf", "huge", "far", "zero", "negative", "scale", "nudge", "int", "bool",
                       "str", "none", "list", "dict", "tuple", "object", "unhashable", "deep", "untuple"])
    number = isinstance(old, (int, float)) and not isinstance(old, bool)
    value = {
        "nan": {"f": "nan"}, "inf": {"f": "inf"}, "-inf": {"f": "-inf"}, "huge": 1e300, "far": 5000.0, "zero": 0.0,
        "negative": -1.0, "str": "x", "none": None, "bool": rng.random() < 0.5,
        "int": rng.choice([0, 1, -1, 7, 2 ** 31, 10 ** 30]),
        "scale": old * rng.uniform(0.5, 1.5) if number else 1.0,
        "nudge": old + rng.choice([1e-9, 1e-3, 1.0, 100.0]) * rng.choice([-1, 1]) if number else 0.5,
        "list": rng.choice([[], [old], [old, old]]), "dict": rng.choice([{}, {"x": 1}, {"x": old}]),
        "tuple": {"t": [old]} if not isinstance(old, list) else {"t": old},
        "object": {"o": rng.choice(TAGS), "v": rng.choice([{}, {"x": 1}, {"accel": old}])},
        "unhashable": {"d": [[{"t": [[1]]}, 1]]},
        "deep": None,
        "untuple": old["t"] if isinstance(old, dict) and "t" in old else [old],
    }[kind]
    if kind == "deep":
        value = old
        for _ in range(rng.choice([30, 600])):
            value = [value]
    return kind, value


def mutate(blob: bytes, rng: random.Random) -> tuple[bytes, str]:
    """One mutation of a value, type, length or nesting somewhere in a state; the bytes and what was done."""
    doc = json.loads(blob)
    section = rng.choice(["logic"] * 8 + ["inputs", "parameters"])
    paths = list(_paths(doc[section]))
    path = rng.choice(paths)
    parent = doc[section]
    for key in path[:-1]:
        parent = parent[key]
    key = path[-1]
    old = parent[key]
    where = ".".join([section, *map(str, path)])
    roll = rng.random()
    if roll < 0.08 and isinstance(parent, (list, dict)) and len(parent) > 1:       # a length change: drop
        del parent[key]
        what = f"{where}: dropped"
    elif roll < 0.16 and isinstance(parent, list):                                  # a length change: add
        parent.insert(key, copy.deepcopy(old))
        what = f"{where}: repeated"
    elif roll < 0.2 and isinstance(parent, dict):
        parent["zz"] = copy.deepcopy(old)
        what = f"{where}: a key 'zz' added beside it"
    else:
        kind, parent[key] = _replacement(old, rng)
        what = f"{where}: {kind} ({json.dumps(parent[key])[:60]})"
    return json.dumps(doc).encode(), what


def position_commands(cls) -> list[str]:
    return [p.name for p in cls.ports("output") if p.unit == "mm" and p.name.endswith("_cmd")]


def sane_steps(cls, logic, inputs, reference: dict, steps: int = 5) -> str | None:
    """Step a restored controller: outputs of their port types, finite, no position command jumping (from the
    unmutated state's outputs first, then step to step) beyond ``SPEED_LIMIT * dt`` -- except onto the actual
    position (a follow-up). Returns what is wrong, else None."""
    prev = dict(logic.outputs())
    for name in position_commands(cls):
        if abs(prev[name] - reference[name]) > SPEED_LIMIT * DT + 1e-9:
            return f"restored {name} = {prev[name]!r}, the state's own is {reference[name]!r}"
    for k in range(steps):
        out = dict(logic.step(10.0 + k * DT, DT, inputs))
        for port in cls.ports("output"):
            value = out[port.name]
            kind = {"Real": float, "Integer": int, "Boolean": bool}[port.type]
            if type(value) is not kind or (kind is float and not math.isfinite(value)):
                return f"step {k}: output {port.name} = {value!r}"
        for name in position_commands(cls):
            if abs(out[name] - prev[name]) > SPEED_LIMIT * DT + 1e-9 and out[name] != inputs[name[:-4] + "_pos"]:
                return f"step {k}: {name} jumped {prev[name]!r} -> {out[name]!r}"
        prev = out
    return None


def fuzz_in_python(blobs: list[bytes], per_state: int, seed: int) -> dict[str, int]:
    """Mutate each state ``per_state`` times; each must be refused (StateError/ConfigError) or step sanely."""
    rng = random.Random(seed)
    counts = {"cases": 0, "refused": 0, "accepted": 0}
    for blob in blobs:
        blob = as_dev(blob)
        reference = dict(dev_load(blob)[1][0].outputs())
        for _ in range(per_state):
            bad, what = mutate(blob, rng)
            counts["cases"] += 1
            try:
                cls, (logic, parameters, inputs) = dev_load(bad)
            except (state.StateError, ConfigError):
                counts["refused"] += 1
                continue
            except Exception as err:                                       # noqa: BLE001 -- the defect sought
                pytest.fail(f"{what}: {type(err).__name__} escaped loads: {err}")
            counts["accepted"] += 1
            wrong = sane_steps(cls, logic, inputs, reference) if logic is not None else None
            assert wrong is None, f"{what}: accepted, then {wrong}"
    return counts


# -- pure Python: real states -----------------------------------------------------------------------
def test_real_states_restore_exactly(real_states):
    """Every real state of every model is accepted and restores to the very same state (re-saved identically)."""
    for system, instance, t, blob in real_states:
        blob = as_dev(blob)
        cls, (logic, parameters, inputs) = dev_load(blob)
        again = state.dumps(cls.MODEL_NAME, parameters, inputs, logic)
        assert json.loads(again) == json.loads(blob), (system, instance, t)


@pytest.mark.slow
@pytest.mark.parametrize("step, mode", [(0.5e-3, "gauss-seidel"), (2e-3, "gauss-seidel"), (1e-3, "jacobi")])
def test_real_states_of_other_steps_and_the_jacobi_mode_restore(project, step, mode):
    """The rules hold for real states whatever the host's step and master algorithm (inputs one step older)."""
    states = [s for system, values, times in RUNS for s in collect_states(system, values, times, step, mode)]
    for *_, blob in states:
        dev_load(as_dev(blob))                       # raises StateError naming the field if a rule is too strict
    python_fmus = {"lathe_taper": 3, "lathe_roughing": 3, "grinder_feed": 2, "grinder_envelope": 3, "mill_contour": 2}
    assert len(states) == sum(python_fmus[system] * len(times) for system, _, times in RUNS)


def test_a_state_saved_after_a_tunable_parameter_changed_restores():
    """A host may set a tunable parameter and save the state before the next step: the outputs still show the
    old dial, the parameters and what configure() derives the new one -- a real state, restored."""
    panel = OperatorPanel()
    inputs = OperatorPanel.default_inputs()
    for k in range(50):
        panel.step(k * DT, DT, inputs)
    parameters = OperatorPanel.default_parameters() | {"override": 0.5, "start_at": 0.02}
    panel.retune(parameters)
    blob = state.dumps("OperatorPanel", parameters, inputs, panel)
    logic, restored, _ = state.loads(blob, OperatorPanel, OperatorPanel.from_parameters)
    assert restored["override"] == 0.5 and logic.override == 0.5 and logic.outputs()["feed_override"] == 1.0
    assert logic.step(0.05, DT, inputs)["feed_override"] == 0.5


def test_fuzzed_states_are_refused_or_run_sanely(real_states):
    """Seeded fuzz in Python over real states of every model: nothing but StateError/ConfigError leaves loads,
    and an accepted state steps with finite outputs and no jump."""
    counts = fuzz_in_python([b for *_, b in real_states], per_state=25, seed=2026)
    print("state fuzz (Python):", counts)
    assert counts["cases"] == 25 * len(real_states)
    assert counts["refused"] > counts["cases"] // 2          # most mutations break a rule


# -- the reported cases, one by one (Python) ---------------------------------------------------------------
def _edited(blob: bytes, edit) -> bytes:
    doc = json.loads(as_dev(blob))
    edit(doc["logic"])
    return json.dumps(doc).encode()


def _first(real_states, model: str, busy: bool = True) -> bytes:
    for *_, blob in real_states:
        doc = json.loads(blob)
        if doc["model"] == model and (not busy or doc["logic"].get("busy", True)):
            return blob
    raise AssertionError(f"no real state of {model}")


CASES = {
    # name: (model, edit of the saved logic, the message naming the field)
    "unhashable_key": ("CutSequencer", lambda lg: lg.__setitem__("messages", {"d": [[{"t": [[1]]}, 1]]}),
                       "unhashable"),
    "exception_object": ("CutSequencer", lambda lg: lg.__setitem__("messages", {"o": "errors:ConfigError", "v": {}}),
                         "errors:ConfigError"),
    "outputs_text": ("CutSequencer", lambda lg: lg.__setitem__("_outputs", "x"), "logic._outputs"),
    "controller_object": ("CutSequencer", lambda lg: lg.__setitem__(
        "messages", {"o": "controllers.base:Controller", "v": {"x": 1}}), "logic.messages"),
    "output_text": ("CutSequencer", lambda lg: lg["_outputs"].__setitem__("x_cmd", "x"), "logic._outputs['x_cmd']"),
    "limiter_nan": ("AreaLimiter", lambda lg: lg.__setitem__("pos", [{"f": "nan"}, {"f": "nan"}]),
                    "logic.pos[0] = nan: must be finite"),
    "dda_unit_zero": ("ContourInterpolator", lambda lg: lg.__setitem__("dda_unit", 0.0), "logic.dda_unit = 0.0"),
    "x_cmd_far": ("CutSequencer", lambda lg: lg.__setitem__("x_cmd", 5000.0), "logic.x_cmd"),
    # the input names a step reads are configured: a state that swaps them would read Z's position as X's
    "input_names_swapped": ("CutSequencer", lambda lg: lg.__setitem__("_pos_inputs", {"t": ["z_pos", "x_pos"]}),
                            "logic._pos_inputs = ('z_pos', 'x_pos'): not ('x_pos', 'z_pos'), what the parameters give"),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_reported_case_is_refused_naming_the_field(real_states, case):
    model, edit, says = CASES[case]
    with pytest.raises(state.StateError, match=None) as err:
        dev_load(_edited(_first(real_states, model), edit))
    assert says in str(err.value), str(err.value)


def test_nesting_too_deep_for_the_decoder_is_refused(real_states):
    """A state nested deeper than Python recurses (json itself, then the decoder) is a StateError."""
    blob = as_dev(_first(real_states, "OperatorPanel", busy=False))
    for depth in (900, 100_000):
        deep = blob.replace(b'"messages":[]', b'"messages":' + b"[" * depth + b"]" * depth, 1)
        with pytest.raises(state.StateError):
            dev_load(deep)


# -- through the built FMUs, each in its own process --------------------------------------------------
HOST = textwrap.dedent('''
    import json, math, sys, tempfile
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave
    from fmpy.fmi1 import FMICallException
    from ncfmu.fmi.contract import join_state

    jobs_file, speed_limit = sys.argv[1], float(sys.argv[2])
    dt, t = 1e-3, [0.0]

    def status(call, *args):
        try:
            return "OK", call(*args)
        except FMICallException as err:
            return {1: "Warning", 2: "Discard", 3: "Error", 4: "Fatal"}.get(err.status, str(err.status)), None

    def run(path, bases, cases):
        md = read_model_description(path)
        folder = extract(path, tempfile.mkdtemp())
        outs = [v for v in md.modelVariables if v.causality == "output"]
        pos_in = {v.name: v.valueReference for v in md.modelVariables if v.name.endswith("_pos")}
        cmds = [v for v in outs if v.name.endswith("_cmd") and v.unit == "mm"]
        counts = {"cases": 0, "OK": 0, "Error": 0, "Fatal": 0, "leaked": 0, "not_kept": 0, "bad_output": 0,
                  "step_error": 0}
        said = []

        def read(fmu):
            values = {}
            for v in outs:
                get = {"Real": fmu.getReal, "Integer": fmu.getInteger, "Boolean": fmu.getBoolean}[v.type]
                values[v.name] = get([v.valueReference])[0]
            return values

        def started():
            fmu = FMU2Slave(guid=md.guid, unzipDirectory=folder, modelIdentifier=md.coSimulation.modelIdentifier,
                            instanceName="dut")
            fmu.instantiate(loggingOn=True)
            fmu.setupExperiment(startTime=0.0)
            fmu.enterInitializationMode()
            fmu.exitInitializationMode()
            return fmu

        def restore(fmu, blob):
            # the JSON with the shim's time trailer, sealed: the state continues at this host's next step
            st = fmu.deSerializeFMUstate(join_state(blob.encode(), t[0] + dt, model=md.coSimulation.modelIdentifier))
            fmu.setFMUstate(st)
            fmu.freeFMUstate(st)

        def wrong_outputs(values, before, actual):
            for v in outs:
                x = values[v.name]
                if v.type == "Real" and not math.isfinite(x):
                    return f"{v.name} = {x!r}"
            for v in cmds:
                step = abs(values[v.name] - before[v.name])
                if step > speed_limit * dt + 1e-9 and values[v.name] != actual.get(v.name[:-4] + "_pos"):
                    return f"{v.name} jumped {before[v.name]!r} -> {values[v.name]!r}"
            return None

        fmu = started()
        for base, blob, what in [(b, b, "a real state") for b in bases] + [(bases[i], b, w) for i, b, w in cases]:
            counts["cases"] += 1
            try:
                restore(fmu, base)
                reference = read(fmu)
                result, _ = status(restore, fmu, blob)
                counts[result] = counts.get(result, 0) + 1
                print("CASE", result, what, flush=True)
                values = read(fmu)
                if result != "OK" and values != reference:
                    counts["not_kept"] += 1
                    said.append(f"{what}: refused, and the instance did not keep its state")
                if result == "Fatal":
                    said.append(f"{what}: Fatal")
                    fmu = started()
                    continue
                before = values
                wrong = wrong_outputs(values, reference, {})
                for k in range(5):
                    t[0] += dt
                    step, _ = status(fmu.doStep, t[0], dt)
                    if step != "OK":
                        counts["step_error" if step == "Error" else step] = counts.get(step, 0) + 1
                        said.append(f"{what}: doStep {step}")
                        if step == "Fatal":
                            fmu = started()
                        break
                    values = read(fmu)
                    actual = {n: fmu.getReal([r])[0] for n, r in pos_in.items()}
                    wrong = wrong or wrong_outputs(values, before, actual)
                    before = values
                if wrong:
                    counts["bad_output"] += 1
                    said.append(f"{what}: {wrong}")
            except Exception as err:               # a Python exception leaking out of the FMU into this host
                counts["leaked"] += 1
                said.append(f"{what}: leaked {type(err).__name__}: {err}")
                fmu = started()
        fmu.terminate()
        fmu.freeInstance()
        return counts, said

    for model, path, bases, cases in json.load(open(jobs_file)):
        counts, said = run(path, bases, cases)
        print("COUNTS", model, json.dumps(counts), flush=True)
        for line in said[:20]:
            print("SAID", model, line)
''')


def run_host(jobs: list[tuple[str, object, list[bytes], list[tuple[int, bytes, str]]]], tmp_path
             ) -> tuple[dict[str, dict], str]:
    # One process for every job ``(model, fmu, bases, cases)``: each real state in ``bases`` restored as is,
    # then each case ``(i, bytes, what)`` restored over ``bases[i]`` and stepped. Counts by model and outcome,
    # and the log. A crash fails the test; a Python traceback on stderr too (an exception the FMU let out).
    data = tmp_path / "jobs.json"
    data.write_text(json.dumps([[model, str(fmu), [b.decode() for b in bases],
                                 [[i, b.decode(), w] for i, b, w in cases]] for model, fmu, bases, cases in jobs]))
    proc = subprocess.run([sys.executable, "-c", HOST, str(data), str(SPEED_LIMIT)],
                          capture_output=True, text=True, timeout=1800)
    assert proc.returncode == 0, (proc.returncode, proc.stdout[-2000:], proc.stderr[-3000:])   # no crash
    assert "Traceback" not in proc.stderr and "Exception ignored" not in proc.stderr, proc.stderr[-3000:]
    counts = {ln.split()[1]: json.loads(ln.split(" ", 2)[2]) for ln in proc.stdout.splitlines()
              if ln.startswith("COUNTS")}
    assert set(counts) == {job[0] for job in jobs}, proc.stdout[-3000:]
    return counts, proc.stdout + proc.stderr


def test_reported_cases_through_the_fmus(fmus, real_states, tmp_path):
    # Each case as a host meets it (one process, each FMU in turn): deserialize + set is fmi2Error with one log
    # line naming the field, the instance keeps its state and steps on with sane outputs; nothing Fatal, nothing
    # leaked.
    jobs = []
    for model in sorted({m for m, *_ in CASES.values()}):
        good = _first(real_states, model)
        cases = []
        for name in sorted(n for n, (m, *_) in CASES.items() if m == model):
            doc = json.loads(good)
            CASES[name][1](doc["logic"])
            cases.append((0, json.dumps(doc).encode(), name))
        jobs.append((model, fmus[model], [good], cases))
    counts, log = run_host(jobs, tmp_path)
    for model, _, _, cases in jobs:
        assert counts[model] == {"cases": 1 + len(cases), "OK": 1, "Error": len(cases), "Fatal": 0, "leaked": 0,
                                 "not_kept": 0, "bad_output": 0, "step_error": 0}, log
    names = sorted(CASES)
    said: list[str] = []                                   # the log lines of each case, up to its CASE line
    for line in log.splitlines():
        if line.startswith("CASE Error"):
            refused = [ln for ln in said if "fmi2DeSerializeFMUstate refused" in ln]
            name = line.split()[2]
            assert len(refused) == 1 and CASES[name][2] in refused[0], (name, said)
            names.remove(name)
        said = [] if line.startswith("CASE") else [*said, line]
    assert names == []


def _fuzz_through_fmus(fmus, real_states, tmp_path, per_model: int, seed: int) -> dict[str, dict]:
    rng = random.Random(seed)
    by_model: dict[str, list[bytes]] = {}
    for *_, blob in real_states:
        by_model.setdefault(json.loads(blob)["model"], []).append(blob)
    jobs = []
    for model, blobs in sorted(by_model.items()):
        cases = []
        for _ in range(per_model):
            i = rng.randrange(len(blobs))
            cases.append((i, *mutate(blobs[i], rng)))
        jobs.append((model, fmus[model], blobs, cases))
    results, log = run_host(jobs, tmp_path)
    real_ok = log.count("CASE OK a real state")
    assert real_ok == len(real_states), log[-4000:]                    # every real state restores
    for model, _, blobs, _ in jobs:
        counts = results[model]
        assert counts["cases"] == per_model + len(blobs)
        assert (counts["Fatal"], counts["leaked"], counts["not_kept"], counts["bad_output"], counts["step_error"]) == \
            (0, 0, 0, 0, 0), (model, [ln for ln in log.splitlines() if ln.startswith("SAID")])
        assert counts["Error"] > per_model // 2, (model, counts)        # most mutations break a rule
    print("state fuzz (through the FMUs):", results)
    return results


def test_fuzzed_states_through_the_fmus(fmus, real_states, tmp_path):
    """The seeded fuzz as a host meets it: 20 mutated real states per Python FMU, in one process."""
    _fuzz_through_fmus(fmus, real_states, tmp_path, per_model=20, seed=11)


@pytest.mark.slow
def test_fuzzed_states_through_the_fmus_at_length(fmus, real_states, tmp_path):
    _fuzz_through_fmus(fmus, real_states, tmp_path, per_model=400, seed=12)


@pytest.mark.slow
def test_fuzzed_states_in_python_at_length(project):
    """The Python fuzz over states of whole cycles (more times of the same runs): 200 mutations a state."""
    states = [s for system, values, times in RUNS for s in collect_states(system, values, times + MORE_TIMES[system])]
    counts = fuzz_in_python([b for *_, b in states], per_state=200, seed=7)
    print("state fuzz (Python, at length):", counts)
    assert counts["cases"] == 200 * len(states)


# -- real states through the FMUs: restored, they continue bit for bit -------------------------------------
def _continue_identically(system: str, start_values: dict, times) -> int:
    """Save every FMU of a running system as bytes at each time, run on, restore the bytes, run again: the same
    records, bit for bit. Returns how many FMU states were restored."""
    restored = 0
    with OpenSystem(system_archive(system)) as opened:
        master = opened.master
        run = master.prepare(max(times) + 0.5, None, start_values, None, 0.0)
        done = 0
        for t in sorted(times):
            k = max(int(round(t / run.h)), done)          # the FMUs step on from where they are
            run.steps(done, k)
            handles = [s.get_state() for s in opened.slaves]
            blobs = [s.serialize_state(h) for s, h in zip(opened.slaves, handles)]
            for s, h in zip(opened.slaves, handles):
                s.free_state(h)
            run.steps(k, k + 300)
            once = {name: v[k:k + 300].copy() for name, v in run.rec.items()}
            for s, blob in zip(opened.slaves, blobs):
                s.set_state(s.deserialize_state(blob))
            for s in opened.slaves:
                s.read_outputs()
            run.steps(k, k + 300)
            for name in once:
                assert (run.rec[name][k:k + 300] == once[name]).all(), (system, t, name)
            restored += len(blobs)
            done = k + 300
    return restored


@pytest.mark.parametrize("system, start_values, times", [RUNS[0], RUNS[2]], ids=["lathe_taper", "grinder_feed"])
def test_real_states_continue_bit_identically(project, system, start_values, times):
    slaves = {"lathe_taper": 6, "grinder_feed": 3}[system]    # the Python FMUs, the servo axes, the spindle
    assert _continue_identically(system, start_values, times) == slaves * len(times)


@pytest.mark.slow
@pytest.mark.parametrize("run", RUNS, ids=[r[0] for r in RUNS])
def test_real_states_of_whole_cycles_continue_bit_identically(project, run):
    system, start_values, times = run
    assert _continue_identically(system, start_values, tuple(sorted(set(times) | set(MORE_TIMES[system])))) > 0
