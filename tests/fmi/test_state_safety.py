"""A safe FMU state: host bytes are data, never code; a wrong state is fmi2Error, not a crash.

Every case runs in its own process against the built FMU, so a crash is a failure, not a lost run.
"""

import re
import subprocess
import sys
import textwrap

import pytest

pytestmark = pytest.mark.slow        # a process per case: not in the fast subset

SCRIPT = textwrap.dedent('''
    import os, pickle, shutil, sys, tempfile
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave
    from fmpy.fmi1 import FMICallException

    fmu_path, case, marker = sys.argv[1], sys.argv[2], sys.argv[3]
    other_path = sys.argv[4] if len(sys.argv) > 4 else None

    def open_fmu(path, name):
        md = read_model_description(path)
        folder = extract(path, tempfile.mkdtemp())
        fmu = FMU2Slave(guid=md.guid, unzipDirectory=folder, modelIdentifier=md.coSimulation.modelIdentifier,
                        instanceName=name)
        fmu.instantiate(loggingOn=True)
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        return fmu, md

    fmu, md = open_fmu(fmu_path, "dut")
    t = 0.0
    for _ in range(50):
        fmu.doStep(t, 1e-3); t += 1e-3
    good = bytes(fmu.serializeFMUstate(fmu.getFMUstate()))

    class Exploit:
        def __reduce__(self):
            return (os.system, (f"touch {marker}",))

    if case == "garbage":
        blob = os.urandom(200)
    elif case == "pickle":
        blob = pickle.dumps(Exploit())
    elif case == "truncated":
        blob = good[: len(good) // 2]
    elif case == "empty":
        blob = b""
    elif case == "other_model":
        other, _ = open_fmu(other_path, "other")
        blob = bytes(other.serializeFMUstate(other.getFMUstate()))
    elif case in ("other_build", "nan_values", "object_tag"):         # the model's bytes edited, sealed again
        from ncfmu.fmi.sealed_state import seal, unseal
        inner = unseal(good)
        data = inner.payload
        if case == "other_build" and data.startswith(b"NCFMU-FMUSTATE-1"):      # the native format
            at = data.index(b"+", 17 + 32)                            # the build's digest after "0.1.0+"
            data = data[:at + 1] + bytes([data[at + 1] ^ 1]) + data[at + 2:]
        elif case == "other_build":
            data = data.replace(b'"build":"', b'"build":"x', 1)
        elif case == "nan_values":                                    # the native format's plain doubles
            import struct
            data = data[:-8] + struct.pack("d", float("nan"))
        else:
            data = data.replace(b'"logic":{', b'"logic":{"evil":{"o":"os:system","v":{}},', 1)
        assert data != inner.payload
        blob = seal(data, inner.model, inner.fmi)
    elif case == "good":
        blob = good
    try:
        state = fmu.deSerializeFMUstate(blob)
        fmu.setFMUstate(state)
        fmu.freeFMUstate(state)
        status = "OK"
    except FMICallException as err:
        status = {3: "Error", 4: "Fatal"}.get(err.status, str(err.status))
    # the instance lives on: it steps, and it is freed cleanly
    fmu.doStep(t, 1e-3)
    fmu.terminate()
    fmu.freeInstance()
    print("STATUS", status, "EXECUTED", os.path.exists(marker))
''')


def run_case(fmu, case, tmp_path, other=None):
    marker = tmp_path / "code_ran_from_state_bytes"
    args = [sys.executable, "-c", SCRIPT, str(fmu), case, str(marker)] + ([str(other)] if other else [])
    proc = subprocess.run(args, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, (proc.returncode, proc.stderr[-2000:])     # no crash
    line = [ln for ln in proc.stdout.splitlines() if ln.startswith("STATUS")][-1]
    return line.split()[1], line.split()[3] == "True", proc.stdout + proc.stderr


@pytest.mark.parametrize("case", ["garbage", "pickle", "truncated", "empty", "other_model", "other_build",
                                  "object_tag"])
def test_bad_state_bytes_are_an_error_and_run_no_code(fmus, tmp_path, case):
    status, executed, log = run_case(fmus["CutSequencer"], case, tmp_path, other=fmus["ServoAxis"])
    assert status == "Error", log
    assert not executed
    # refused by the seal (fmu_instance.h: "<call>: <n> bytes refused: ...") or by the slave ("<call> refused: ...")
    assert re.search(r"fmi2DeSerializeFMUstate(: \d+ bytes)? refused", log), log


@pytest.mark.parametrize("case", ["garbage", "pickle", "truncated", "empty", "other_model", "other_build",
                                  "nan_values"])
def test_native_servo_refuses_bad_state_bytes(fmus, tmp_path, case):
    status, executed, log = run_case(fmus["ServoAxis"], case, tmp_path, other=fmus["CutSequencer"])
    assert status == "Error", log
    assert not executed
    assert re.search(r"fmi2DeSerializeFMUstate: \d+ bytes refused", log), log


def test_a_good_state_round_trips_in_a_fresh_process(fmus, tmp_path):
    for model in ("CutSequencer", "ServoAxis", "ProgrammableFeed"):
        status, executed, log = run_case(fmus[model], "good", tmp_path)
        assert status == "OK", log


#: What the subprocess scripts below share: the FMU (argv[1]) unpacked, its value references, a factory for
#: instances and ``status(call, ...)`` -> "OK" / "Error" / "Fatal" / ...
PREAMBLE = textwrap.dedent('''
    import ctypes, math, sys, tempfile
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave, fmi2LastSuccessfulTime
    from fmpy.fmi1 import FMICallException

    path, case = sys.argv[1], sys.argv[2]
    md = read_model_description(path)
    folder = extract(path, tempfile.mkdtemp())
    vr = {v.name: v.valueReference for v in md.modelVariables}

    def make(name="dut"):
        fmu = FMU2Slave(guid=md.guid, unzipDirectory=folder, modelIdentifier=md.coSimulation.modelIdentifier,
                        instanceName=name)
        fmu.instantiate(loggingOn=True)
        return fmu

    def status(call, *args):
        try:
            call(*args)
            return "OK"
        except FMICallException as err:
            return {1: "Warning", 2: "Discard", 3: "Error", 4: "Fatal"}.get(err.status, str(err.status))
''')


FREED = PREAMBLE + textwrap.dedent('''
    def started(name):
        fmu = make(name)
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        return fmu

    a, b = started("a"), started("b")
    a.doStep(0.0, 1e-3)
    state = a.getFMUstate()
    freed = ctypes.c_void_p(state.value)                   # the pointer, kept (fmpy zeroes its own on free)
    a.freeFMUstate(state)
    of_b = b.getFMUstate()
    results = [status(a.setFMUstate, freed), status(a.serializeFMUstate, freed), status(a.freeFMUstate, freed),
               status(a.setFMUstate, of_b)]
    live = a.getFMUstate()                                 # the instance lives on, and its own states work
    results.append(status(a.setFMUstate, live))
    a.freeFMUstate(live)
    b.freeFMUstate(of_b)
    a.doStep(1e-3, 1e-3)
    for fmu in (a, b):
        fmu.terminate()
        fmu.freeInstance()
    print("RESULT", *results)
''')


@pytest.mark.parametrize("model", ["CutSequencer", "ServoAxis"])
def test_a_freed_or_foreign_state_is_an_error(fmus, model):
    """A state used after fmi2FreeFMUstate, or another instance's, is refused (never dereferenced)."""
    proc = subprocess.run([sys.executable, "-c", FREED, str(fmus[model]), "freed"], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    result = [ln.split()[1:] for ln in proc.stdout.splitlines() if ln.startswith("RESULT")][-1]
    assert result == ["Error", "Error", "Error", "Error", "OK"], proc.stdout[-2000:]
    assert "is not a live FMU state of this instance" in proc.stdout


MACHINE = PREAMBLE + textwrap.dedent('''
    fmu = make()
    fmu.setupExperiment(startTime=0.0)
    if case == "step_in_init":
        fmu.enterInitializationMode()
        result = status(fmu.doStep, 0.0, 1e-3)
        fmu.exitInitializationMode()
    else:
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        for k in range(10):
            fmu.doStep(k * 1e-3, 1e-3)
        if case in ("h_zero", "h_negative", "h_nan", "t_nan", "h_inf"):
            t, h = {"h_zero": (0.01, 0.0), "h_negative": (0.01, -1e-3), "h_nan": (0.01, math.nan),
                    "t_nan": (math.nan, 1e-3), "h_inf": (0.01, math.inf)}[case]
            result = status(fmu.doStep, t, h)
            assert status(fmu.doStep, 0.01, 1e-3) == "OK"          # the instance steps on
        elif case == "exit_init_twice":
            result = status(fmu.exitInitializationMode)
        elif case == "set_after_terminate":
            fmu.terminate()
            result = status(fmu.setReal, [vr["x_pos"]], [1.0])
        elif case == "step_after_terminate":
            fmu.terminate()
            result = status(fmu.doStep, 0.01, 1e-3)
            fmu.reset()                                              # and back to life
            fmu.setupExperiment(startTime=0.0)
            fmu.enterInitializationMode(); fmu.exitInitializationMode()
            assert status(fmu.doStep, 0.0, 1e-3) == "OK"
        elif case == "last_successful_time":
            value = ctypes.c_double(-1.0)
            fmu.fmi2GetRealStatus(fmu.component, fmi2LastSuccessfulTime, ctypes.byref(value))
            result = "OK" if abs(value.value - 0.01) < 1e-12 else f"wrong {value.value}"
    try:
        fmu.terminate()
    except FMICallException:
        pass
    fmu.freeInstance()
    again = make("again")                                            # the process is sound after it all
    again.freeInstance()
    print("RESULT", result)
''')


@pytest.mark.parametrize("case, expected", [
    ("h_zero", "Error"), ("h_negative", "Error"), ("h_nan", "Error"), ("t_nan", "Error"), ("h_inf", "Error"),
    ("step_in_init", "Error"), ("exit_init_twice", "Error"), ("set_after_terminate", "Error"),
    ("step_after_terminate", "Error"), ("last_successful_time", "OK"),
])
def test_fmi_state_machine_is_enforced(fmus, case, expected):
    proc = subprocess.run([sys.executable, "-c", MACHINE, str(fmus["CutSequencer"]), case],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    result = [ln.split(" ", 1)[1] for ln in proc.stdout.splitlines() if ln.startswith("RESULT")][-1]
    assert result == expected, proc.stdout[-2000:]
    if expected == "Error":
        assert "must be finite and > 0" in proc.stdout or "not allowed in the" in proc.stdout


BAD_CALLS = PREAMBLE + textwrap.dedent('''
    fmu = make()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    fmu.doStep(0.0, 1e-3)

    calls = {
        "unknown_vr_get": lambda: fmu.getReal([123456]),
        "unknown_vr_set": lambda: fmu.setReal([123456], [1.0]),
        "set_output": lambda: fmu.setBoolean([vr["start"]], [True]),
        "wrong_type": lambda: fmu.getReal([vr["start"]]),
        "fixed_after_init": lambda: fmu.setReal([vr["pulse"]], [0.5]),
        "tunable_out_of_range": lambda: fmu.setReal([vr["override"]], [5.0]),
    }
    result = status(calls[case])
    kept = fmu.getReal([vr["override"]])[0]
    assert status(fmu.doStep, 1e-3, 1e-3) == "OK"                   # the instance lives on
    fmu.terminate()
    fmu.freeInstance()
    print("RESULT", result, kept)
''')


@pytest.mark.parametrize("case, says", [
    ("unknown_vr_get", "is not a variable of this FMU"), ("unknown_vr_set", "is not a variable of this FMU"),
    ("set_output", "is an output"), ("wrong_type", "is not of this call's type"),
    ("fixed_after_init", "fixed parameter"), ("tunable_out_of_range", "override = 5.0: must be in [0, 1.5]"),
])
def test_bad_calls_are_an_error_not_fatal(fmus, case, says):
    proc = subprocess.run([sys.executable, "-c", BAD_CALLS, str(fmus["OperatorPanel"]), case],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    result = [ln.split()[1:] for ln in proc.stdout.splitlines() if ln.startswith("RESULT")][-1]
    assert result[0] == "Error" and says in proc.stdout, proc.stdout[-2000:]
    assert float(result[1]) == 1.0                                    # a refused tunable keeps its old value


BAD_INIT = PREAMBLE + textwrap.dedent('''
    fmu = make()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()

    if case == "huge_bandwidth":            # refused when set: outside the port's range
        result = status(fmu.setReal, [vr["vel_bandwidth"]], [1e300])
    elif case == "huge_inertia":
        result = status(fmu.setReal, [vr["J"]], [1e300])
    elif case == "tiny_substep":
        result = status(fmu.setReal, [vr["substep"]], [1e-12])
    elif case == "low_position_margin":     # each value in range, the design refused at exit
        fmu.setReal([vr["Kv"]], [1000.0])
        result = status(fmu.exitInitializationMode)
    elif case == "low_velocity_margin":
        fmu.setReal([vr["vel_bandwidth"], vr["substep"]], [3000.0, 1e-5])
        result = status(fmu.exitInitializationMode)
    elif case == "bad_utf8":
        refs = (ctypes.c_uint * 1)(vr["program"])
        text = (ctypes.c_char_p * 1)(b"M0: X+D3F7\\xff\\xfe; M1: END")
        result = status(fmu.fmi2SetString, fmu.component, refs, 1, text)
    fmu.reset()                                                      # usable again after the error
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    assert status(fmu.doStep, 0.0, 1e-3) == "OK"
    fmu.terminate()
    fmu.freeInstance()
    print("RESULT", result)
''')


@pytest.mark.parametrize("model, case, says", [
    ("ServoAxis", "huge_bandwidth", "vel_bandwidth = 1.0000000000000001e+300: must be in (0, 100000]"),
    ("ServoAxis", "huge_inertia", "J = 1.0000000000000001e+300: must be in [1e-07, 10]"),
    ("ServoAxis", "tiny_substep", "substep = 9.9999999999999998e-13: must be in [1e-06, 0.01]"),
    ("ServoAxis", "low_position_margin", "Kv = 1000: gives the position loop a phase margin of 8.9 deg (< 30 deg)"),
    ("ServoAxis", "low_velocity_margin", "vel_bandwidth = 3000: gives the velocity loop a phase margin of 23.7 deg"),
    ("ProgrammableFeed", "bad_utf8", "not valid UTF-8"),
])
def test_bad_parameter_values_are_an_error_not_fatal(fmus, model, case, says):
    proc = subprocess.run([sys.executable, "-c", BAD_INIT, str(fmus[model]), case],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    result = [ln.split()[1] for ln in proc.stdout.splitlines() if ln.startswith("RESULT")][-1]
    assert result == "Error" and says in proc.stdout, proc.stdout[-3000:]


NO_COMPILER = textwrap.dedent('''
    import os, sys, tempfile
    from pathlib import Path
    from ncfmu.errors import BuildError
    from ncfmu.fmi.builder import build_fmu

    os.environ["PATH"] = ""                                          # no cc, gcc or clang to be found
    dest = Path(tempfile.mkdtemp())
    try:
        build_fmu(Path(sys.argv[1]), dest)
    except BuildError as err:
        print("REFUSED", err)
    print("LEFT", sorted(p.name for p in dest.iterdir()))
''')


def test_no_c_compiler_is_a_build_error_never_an_fmu_without_the_shim(project):
    """A Python FMU's binary is the shim: without a compiler there is no FMU (never pythonfmu's library alone,
    which would check nothing the FMUs promise)."""
    from ncfmu.project import project_root
    script = project_root() / "models" / "OperatorPanel.py"
    proc = subprocess.run([sys.executable, "-c", NO_COMPILER, str(script)], capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "REFUSED no C compiler (cc, gcc or clang) found" in proc.stdout
    assert "LEFT []" in proc.stdout


HOST_MISUSE = PREAMBLE + textwrap.dedent('''
    fmu = make()
    refs = (ctypes.c_uint * 1)(vr[md.modelVariables[-1].name] if case == "get_before_init" else 0)
    if case == "get_before_init":                          # fmi2GetReal is not allowed before initialisation
        out = (ctypes.c_double * 1)()
        real_out = [v for v in md.modelVariables if v.causality == "output" and v.type == "Real"][0]
        refs[0] = real_out.valueReference
        print("RESULT", status(fmu.fmi2GetReal, fmu.component, refs, 1, out))
        sys.exit()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    if case == "init_outputs":                             # outputs follow a parameter set in initialization mode
        fmu.setReal([vr["pos_start"]], [5.0])
        print("RESULT", fmu.getReal([vr["pos"]])[0])
        sys.exit()
    if case == "big_step":
        fmu.setReal([vr["substep"]], [1e-6])
    fmu.exitInitializationMode()
    real_in = [v for v in md.modelVariables if v.causality == "input" and v.type == "Real"][0]
    refs[0] = real_in.valueReference
    if case == "null_values":
        result = status(fmu.fmi2SetReal, fmu.component, refs, 1, None)
    elif case == "null_refs":
        result = status(fmu.fmi2GetReal, fmu.component, None, 1, (ctypes.c_double * 1)())
    elif case == "big_step":                               # 3e9 sub-steps in one step
        result = status(fmu.doStep, 0.0, 3000.0)
    elif case in ("serialize_short", "serialize_long"):
        state = fmu.getFMUstate()
        size = ctypes.c_size_t()
        fmu.fmi2SerializedFMUstateSize(fmu.component, state, ctypes.byref(size))
        n = 16 if case == "serialize_short" else size.value + 2 ** 20
        buffer = (ctypes.c_char * n)()
        result = status(fmu.fmi2SerializeFMUstate, fmu.component, state, buffer, n)
        if result == "OK":                                 # the exact state, whatever the buffer's size
            blob = bytes(buffer[:size.value])
            assert bytes(fmu.serializeFMUstate(state)) == blob
        fmu.freeFMUstate(state)
    fmu.doStep(0.0, 1e-3)                                  # the instance lives on
    fmu.terminate()
    fmu.freeInstance()
    print("RESULT", result)
''')


@pytest.mark.parametrize("model", ["CutSequencer", "ServoAxis"])
@pytest.mark.parametrize("case, expected", [
    ("null_values", "Error"), ("null_refs", "Error"), ("get_before_init", "Error"), ("serialize_short", "Error"),
    ("serialize_long", "OK"),
])
def test_host_misuse_is_an_error_not_a_crash(fmus, model, case, expected):
    proc = subprocess.run([sys.executable, "-c", HOST_MISUSE, str(fmus[model]), case], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, (proc.returncode, proc.stderr[-2000:])
    result = [ln.split()[1] for ln in proc.stdout.splitlines() if ln.startswith("RESULT")][-1]
    assert result == expected, proc.stdout[-2000:]


@pytest.mark.parametrize("case, expected", [("big_step", "Error"), ("init_outputs", "5.0")])
def test_native_servo_refuses_a_runaway_step_and_shows_its_initial_outputs(fmus, case, expected):
    proc = subprocess.run([sys.executable, "-c", HOST_MISUSE, str(fmus["ServoAxis"]), case], capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, (proc.returncode, proc.stderr[-2000:])
    result = [ln.split()[1] for ln in proc.stdout.splitlines() if ln.startswith("RESULT")][-1]
    assert result == expected, proc.stdout[-2000:]


BEFORE_INIT = PREAMBLE + textwrap.dedent('''
    a, twin = make("a"), make("twin")
    taken = a.getFMUstate()                                # a state taken before initialisation ...
    blob = bytes(a.serializeFMUstate(taken))
    for fmu in (a, twin):                                  # ... set into the instance once it steps
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
    outputs = [v.valueReference for v in md.modelVariables if v.causality == "output" and v.type == "Real"]
    for k in range(20):
        a.doStep(k * 1e-3, 1e-3); twin.doStep(k * 1e-3, 1e-3)
    state = a.deSerializeFMUstate(blob) if case == "serialized" else taken
    results = [status(a.setFMUstate, state)]
    for k in range(20, 40):                                 # the instance keeps its state: it steps as its twin
        results.append(status(a.doStep, k * 1e-3, 1e-3))
        twin.doStep(k * 1e-3, 1e-3)
    same = a.getReal(outputs) == twin.getReal(outputs)
    fresh = make("fresh")                                  # before initialisation the same state is a state
    results.append(status(fresh.setFMUstate, fresh.deSerializeFMUstate(blob)))
    for fmu in (a, twin):
        fmu.terminate()
    for fmu in (a, twin, fresh):
        fmu.freeInstance()
    print("RESULT", results[0], sorted(set(results[1:-1])), results[-1], "SAME", same)
''')


@pytest.mark.parametrize("model", ["CutSequencer", "OperatorPanel", "ProgrammableFeed"])
@pytest.mark.parametrize("case", ["handle", "serialized"])
def test_a_state_taken_before_initialisation_is_refused_in_a_stepping_instance(fmus, model, case):
    """A Python FMU's state from before fmi2ExitInitializationMode holds no controller: set into an instance that
    steps, it is refused naming why, and the instance steps on from its own state (bit-identical to a twin).
    (The native ServoAxis keeps its FMI phase in its state: such a state returns it to before initialisation.)"""
    proc = subprocess.run([sys.executable, "-c", BEFORE_INIT, str(fmus[model]), case], capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    result = [ln.split(" ", 1)[1] for ln in proc.stdout.splitlines() if ln.startswith("RESULT")][-1]
    assert result == "Error ['OK'] OK SAME True", proc.stdout[-2000:]
    assert re.search(r"fmi2SetFMUstate.*before initiali[sz]ation", proc.stdout), proc.stdout[-2000:]
