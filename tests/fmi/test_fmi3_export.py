"""FMI 3.0 co-simulation FMUs of every model (fmus/fmi3/<Model>.fmu), built from the same sources as the FMI 2.0
ones (fmi/c/fmi3_functions.c over the same model interface): fmpy's validation passes, and each runs through
fmpy bit for bit as its FMI 2.0 twin does -- with a system's parameters (Strings included) and its inputs
driven -- while its outputs move. Misuse of the FMI 3.0 layer is refused, never a crash (in a subprocess)."""

from __future__ import annotations

import re
import subprocess
import sys
import zipfile

import numpy as np
import pytest
from conftest import ROOT
from fmpy import read_model_description, simulate_fmu
from fmpy.validation import validate_fmu

from ncfmu.catalogue import models
from ncfmu.fmi.fmi3 import PLATFORM
from ncfmu.fmi.modeldesc import TIME_VR, TYPES
from ncfmu.systems import SYSTEMS, get_system

MODELS = sorted(models())


@pytest.fixture(scope="session")
def fmus3(project):
    return {p.stem: p for p in project["fmi3"]}


def parameters_of(model: str) -> dict[str, object]:
    """The first system component of ``model``: its parameter set (a real scenario, Strings included)."""
    for name in sorted(SYSTEMS):
        for component in get_system(name).components:
            if component.model == model and component.parameters:
                return dict(component.parameters)
    return {}


def driven_inputs(md) -> np.ndarray:
    """Every input driven for 0.3 s: Reals ramp (0.3 mm/ms), Booleans rise at 20 ms, Integers count."""
    inputs = [v for v in md.modelVariables if v.causality == "input"]
    t = np.arange(0.0, 0.3 + 1e-9, 1e-3)
    kinds = {"Real": float, "Float64": float, "Integer": np.int32, "Int32": np.int32, "Boolean": np.bool_}
    rows = np.zeros(len(t), dtype=[("time", float)] + [(v.name, kinds[v.type]) for v in inputs])
    rows["time"] = t
    for v in inputs:
        if v.type in ("Real", "Float64"):
            rows[v.name] = 0.3 * np.arange(len(t))
        elif v.type == "Boolean":
            rows[v.name] = t >= 0.02
        else:
            rows[v.name] = np.arange(len(t)) // 50
    return rows


@pytest.mark.parametrize("model", MODELS)
def test_fmi3_fmu_is_valid_and_typed_from_the_ports(fmus, fmus3, model):
    assert fmus3[model].parent.name == "fmi3" and fmus3[model].parent.parent == fmus[model].parent
    assert validate_fmu(str(fmus3[model])) == []
    md2, md3 = read_model_description(str(fmus[model])), read_model_description(str(fmus3[model]))
    assert md3.fmiVersion == "3.0" and md3.instantiationToken == md2.guid
    with zipfile.ZipFile(fmus3[model]) as z:
        assert f"binaries/{PLATFORM}/{model}.so" in z.namelist()
    by2 = {v.name: v for v in md2.modelVariables}
    for v in md3.modelVariables:
        if v.valueReference == TIME_VR:
            assert v.name == "time" and v.causality == "independent"
            continue
        twin = by2[v.name]
        assert (v.valueReference, v.causality, v.variability, v.type) == \
            (twin.valueReference, twin.causality, twin.variability, TYPES[twin.type])
        number = float if v.type in ("Float64", "Int32") else str
        assert (v.unit, v.min, v.max) == (twin.unit, twin.min, twin.max), v.name
        assert (v.start is None and twin.start is None) or number(v.start) == number(twin.start), v.name


@pytest.mark.parametrize("model", MODELS)
def test_fmi3_runs_bit_for_bit_as_fmi2_through_fmpy(fmus, fmus3, model):
    md = read_model_description(str(fmus[model]))
    inputs, start = driven_inputs(md), parameters_of(model)
    # No logger= for the FMI 2.0 run: fmpy's logger proxy (fmpy/logging) keeps the last logger it was given in one
    # global, which simulate_fmu's freed callback leaves dangling for every later FMU2Slave of the process.
    runs = [simulate_fmu(str(f), stop_time=0.3, output_interval=1e-3, start_values=start, input=inputs)
            for f in (fmus[model], fmus3[model])]
    assert runs[0].dtype.names == runs[1].dtype.names
    for name in runs[0].dtype.names:
        assert np.array_equal(runs[0][name], runs[1][name]), name
    moved = [n for n in runs[0].dtype.names[1:] if len(np.unique(runs[0][n])) > 1]
    assert moved, f"{model}: no output moved in the compared run"


MISUSE = r"""
import ctypes, sys, tempfile
from ctypes import byref, c_bool, c_char_p, c_double, c_size_t, c_uint, c_void_p
from pathlib import Path
from fmpy import extract, read_model_description
md = read_model_description(sys.argv[1])
folder = Path(extract(sys.argv[1], tempfile.mkdtemp()))
model = md.coSimulation.modelIdentifier
lib = ctypes.CDLL(str(folder / "binaries" / "x86_64-linux" / f"{model}.so"))
LOG = []
LOGGER = ctypes.CFUNCTYPE(None, c_void_p, ctypes.c_int, c_char_p, c_char_p)(
    lambda env, status, category, message: LOG.append((status, category.decode(), message.decode())))
inst = lib.fmi3InstantiateCoSimulation
inst.restype = c_void_p
inst.argtypes = [c_char_p, c_char_p, c_char_p, c_bool, c_bool, c_bool, c_bool, c_void_p, c_size_t, c_void_p,
                 c_void_p, c_void_p]
logger = ctypes.cast(LOGGER, c_void_p)
resources = (str(folder / "resources") + "/").encode()
def make(name=b"x", token=md.instantiationToken.encode(), res=resources):
    return inst(name, token, res, False, False, False, False, None, 0, None, logger, None)
for fn in ("fmi3EnterInitializationMode", "fmi3DoStep", "fmi3GetFloat64", "fmi3FreeInstance"):
    getattr(lib, fn).argtypes = None
print("BAD_TOKEN", make(token=b"{nope}") is None, flush=True)
print("NULL_NAME", make(name=None) is None, flush=True)
print("NO_FOLDER", make(res=b"/nonexistent/") is None, flush=True)
c = c_void_p(make())
made_up = c_void_p(0x4E43100000000007)
vr = (c_uint * 1)(0)
out = (c_double * 1)()
print("MADE_UP", lib.fmi3DoStep(made_up, c_double(0.0), c_double(1e-3), True, None, None, None, None),
      lib.fmi3GetFloat64(made_up, vr, c_size_t(1), out, c_size_t(1)), flush=True)
print("EARLY_STEP", lib.fmi3DoStep(c, c_double(0.0), c_double(1e-3), True, None, None, None, None), flush=True)
print("INIT", lib.fmi3EnterInitializationMode(c, False, c_double(0.0), c_double(0.0), False, c_double(0.0)),
      lib.fmi3ExitInitializationMode(c), flush=True)
ints = (ctypes.c_uint16 * 1)()
print("WRONG_TYPE", lib.fmi3GetUInt16(c, vr, c_size_t(1), ints, c_size_t(1)), flush=True)
print("COUNT", lib.fmi3GetFloat64(c, vr, c_size_t(1), out, c_size_t(2)), flush=True)
print("UNKNOWN_VR", lib.fmi3GetFloat64(c, (c_uint * 1)(99999), c_size_t(1), out, c_size_t(1)), flush=True)
print("BACK_IN_TIME", lib.fmi3DoStep(c, c_double(-1.0), c_double(1e-3), True, None, None, None, None), flush=True)
print("ME", lib.fmi3EnterContinuousTimeMode(c), lib.fmi3EnterEventMode(c), flush=True)
last = c_double()
print("STEP", lib.fmi3DoStep(c, c_double(0.0), c_double(1e-3), True, None, None, None, byref(last)), last.value,
      flush=True)
lib.fmi3FreeInstance(c)
lib.fmi3FreeInstance(c)                       # twice: nothing happens
print("ERRORS_LOGGED", sum(1 for s, cat, m in LOG if s == 3 and cat == "logStatusError"), flush=True)
"""


@pytest.mark.parametrize("model", ["CutSequencer", "ServoAxis"])
def test_fmi3_misuse_is_refused_not_a_crash(fmus3, model):
    proc = subprocess.run([sys.executable, "-c", MISUSE, str(fmus3[model])], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    seen = dict(re.findall(r"^(\w+) (.*)$", proc.stdout, re.MULTILINE))
    assert seen["BAD_TOKEN"] == seen["NULL_NAME"] == seen["NO_FOLDER"] == "True"
    assert seen["MADE_UP"] == "3 3" and seen["EARLY_STEP"] == "3" and seen["INIT"] == "0 0"
    assert seen["WRONG_TYPE"] == seen["COUNT"] == seen["UNKNOWN_VR"] == seen["BACK_IN_TIME"] == "3"
    assert seen["ME"] == "3 3" and seen["STEP"] == "0 0.001"
    assert int(seen["ERRORS_LOGGED"]) >= 10


def test_the_native_servo_runs_in_a_native_fmi3_host_without_python(fmus, fmus3, tmp_path):
    """ServoAxis's FMI 3.0 FMU in a C host (tests/native/fmi3_host.c) with an empty environment: no Python
    anywhere; the axis follows a ramp command exactly as its FMI 2.0 twin does through fmpy."""
    from fmpy import extract

    from ncfmu.fmi.builder import fmi_headers
    host = tmp_path / "fmi3_host"
    source = ROOT / "tests" / "native" / "fmi3_host.c"
    subprocess.run(["cc", "-O1", "-Wall", f"-I{fmi_headers()}", "-o", str(host), str(source), "-ldl"], check=True)
    md = read_model_description(str(fmus3["ServoAxis"]))
    folder = extract(str(fmus3["ServoAxis"]), unzipdir=str(tmp_path / "fmu"))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    proc = subprocess.run(["env", "-i", str(host), f"{folder}/binaries/{PLATFORM}/ServoAxis.so",
                           md.instantiationToken, f"{folder}/resources/", "300", str(vr["pos"]),
                           str(vr["pos_cmd"]), "0.01"], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, (proc.returncode, proc.stdout[-1000:], proc.stderr[-1000:])
    native = [float(x) for x in re.findall(r"^OUT \d+ (\S+)$", proc.stdout, re.MULTILINE)]
    t = np.arange(0.0, 0.3 + 1e-9, 1e-3)
    ramp = np.zeros(len(t), dtype=[("time", float), ("pos_cmd", float)])
    ramp["time"], ramp["pos_cmd"] = t, 0.01 * (np.arange(len(t)) + 1)
    twin = simulate_fmu(str(fmus["ServoAxis"]), stop_time=0.3, output_interval=1e-3, input=ramp, output=["pos"])
    assert len(native) == 3 and native[-1] > 1.0                   # it moved: 2.99 mm commanded by 0.3 s
    assert native == [float(twin["pos"][k]) for k in (100, 200, 300)]


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(SYSTEMS))
def test_every_system_from_fmi3_fmus_equals_its_fmi2_run(project, fmus3, name, tmp_path):
    """The system's .ssp packed with the FMI 3.0 twins (fmus/fmi3/) instead of the FMI 2.0 FMUs runs in ncfmu's
    master bit for bit as the shipped .ssp: every recorded variable, every step, while the machine moves."""
    from ncfmu.cosim.ssp import pack
    from ncfmu.project import simulate
    archive = pack(ROOT / "ssp" / name, fmus3[MODELS[0]].parent, tmp_path / f"{name}.ssp")
    runs = [simulate(str(a), stop_time=1.5) for a in (ROOT / "ssp" / f"{name}.ssp", archive)]
    assert runs[0].names == runs[1].names
    for variable in runs[0].names:
        assert np.array_equal(runs[0][variable], runs[1][variable]), variable
    assert sum(len(np.unique(runs[0][v])) > 1 for v in runs[0].names) >= 5


@pytest.mark.parametrize("model", MODELS)
def test_a_host_reads_the_independent_variable(fmus3, model, tmp_path):
    # found with the Reference-FMUs' fmusim (FMI 3 mode), which records the declared independent variable: every
    # FMU refused fmi3GetFloat64 of 'time'. Its value is where the instance stands, mixed with other variables too.
    from fmpy import extract
    from fmpy.fmi3 import FMU3Slave
    md = read_model_description(str(fmus3[model]))
    output = next(v for v in md.modelVariables if v.causality == "output" and v.type == "Float64")
    fmu = FMU3Slave(guid=md.guid, unzipDirectory=extract(str(fmus3[model]), str(tmp_path / "x")),
                    modelIdentifier=md.coSimulation.modelIdentifier, instanceName="dut")
    fmu.instantiate()
    try:
        fmu.enterInitializationMode(startTime=0.5)
        assert fmu.getFloat64([TIME_VR]) == [0.5]
        fmu.exitInitializationMode()
        for t in (0.5, 0.51):
            fmu.doStep(t, 0.01, True)
        both = fmu.getFloat64([output.valueReference, TIME_VR, output.valueReference])
        assert both[1] == 0.51 + 0.01 and both[0] == both[2] == fmu.getFloat64([output.valueReference])[0]
        fmu.terminate()
    finally:
        fmu.freeInstance()
