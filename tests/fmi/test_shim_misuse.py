"""ncfmu's FMU binaries against a hostile host -- the Python FMUs' binary (the shim) and the native ServoAxis
alike: bad fmi2Instantiate arguments, NULL, freed, made-up and foreign components in every exported function,
String calls on variables that are not Strings, steps that go back in time or round to 0 ns. Each FMU's cases
run in one process of their own (tests/fmi/misuse_host.py): a crash is a failure that names the case it died in.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest
from misuse_report import exported_functions, run_host

from ncfmu.controllers import __name__ as _controllers  # noqa: F401 -- the package is importable

HOST = Path(__file__).with_name("misuse_host.py")
PYTHON_FMUS = ["AreaLimiter", "ContourInterpolator", "CutSequencer", "OperatorPanel", "ProgrammableFeed"]
ALL_FMUS = [*PYTHON_FMUS, "ServoAxis", "SpindleDrive"]
# Functions without a component (nothing to misuse) and the two the host calls in its own cases.
NO_COMPONENT = {"fmi2GetTypesPlatform", "fmi2GetVersion", "fmi2Instantiate", "fmi2FreeInstance"}

@pytest.mark.parametrize("model", ALL_FMUS)
def test_every_misuse_is_refused_and_nothing_crashes(fmus, model):
    n, held, covered = run_host(HOST, str(fmus[model]))
    print(f"{model}: {n} misuse cases tried, {held} held")
    assert n == held == 122
    # the NULL/freed/made-up component cases cover every function the binary exports
    assert covered == exported_functions(fmus[model], "linux64", "fmi2") - NO_COMPONENT


@pytest.fixture(scope="module")
def native_host(tmp_path_factory) -> Path:
    from ncfmu.fmi.builder import fmi_headers
    exe = tmp_path_factory.mktemp("host") / "fmi_host"
    host_c = Path(__file__).parents[1] / "native" / "fmi_host.c"
    subprocess.run(["cc", "-O1", "-Wall", f"-I{fmi_headers()}", "-o", str(exe), str(host_c), "-ldl", "-lpthread"],
                   check=True)
    return exe


@pytest.mark.slow                                      # compiles the host, a process per FMU
@pytest.mark.parametrize("model", ALL_FMUS)
def test_misuse_in_a_native_host_without_python(fmus, native_host, model, tmp_path):
    """The same refusals in a C host with an empty environment (where a Python FMU loads Python itself)."""
    from fmpy import extract, read_model_description
    md = read_model_description(str(fmus[model]))
    folder = Path(extract(str(fmus[model]), unzipdir=str(tmp_path)))
    binary = folder / "binaries" / "linux64" / f"{model}.so"
    proc = subprocess.run(["env", "-i", str(native_host), str(binary), md.guid, (folder / "resources").as_uri(), "0"],
                          capture_output=True, text=True, timeout=120)
    cases = re.findall(r"^CASE (\S+) (HELD|BROKEN)$", proc.stdout, re.MULTILINE)
    assert proc.returncode == 0, f"died after {cases[-1:]}: {proc.stderr[-2000:]}"
    assert [name for name, result in cases if result != "HELD"] == []
    assert re.search(r"^CASES 36 HELD 36$", proc.stdout, re.MULTILINE), proc.stdout[-500:]


FOREIGN = """
import ctypes, sys, tempfile
from ctypes import c_char_p, c_double, c_int, c_void_p
from pathlib import Path
from fmpy import extract, read_model_description
from fmpy.fmi2 import (fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE, fmi2CallbackFunctions,
                       fmi2CallbackLoggerTYPE)
libc = ctypes.CDLL(None)
libc.calloc.restype = c_void_p
libc.calloc.argtypes = [ctypes.c_size_t, ctypes.c_size_t]
libc.free.argtypes = [c_void_p]
callbacks = fmi2CallbackFunctions()
callbacks.logger = fmi2CallbackLoggerTYPE(lambda *a: None)
callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(lambda n, s: libc.calloc(n, s))
callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(lambda p: libc.free(p))
loaded = []
for path in sys.argv[1:]:
    md = read_model_description(path)
    folder = Path(extract(path, tempfile.mkdtemp()))
    lib = ctypes.CDLL(str(folder / "binaries" / "linux64" / f"{md.coSimulation.modelIdentifier}.so"))
    lib.fmi2Instantiate.restype = c_void_p
    lib.fmi2Instantiate.argtypes = [c_char_p, c_int, c_char_p, c_char_p, c_void_p, c_int, c_int]
    lib.fmi2FreeInstance.argtypes = [c_void_p]
    c = lib.fmi2Instantiate(b"dut", 1, md.guid.encode(), (folder / "resources").as_uri().encode(),
                            ctypes.byref(callbacks), 0, 0)
    assert c, path
    assert lib.fmi2SetupExperiment(c_void_p(c), 0, c_double(0.0), c_double(0.0), 0, c_double(0.0)) == 0
    assert lib.fmi2EnterInitializationMode(c_void_p(c)) == 0 and lib.fmi2ExitInitializationMode(c_void_p(c)) == 0
    loaded.append((lib, c))
(a, own_a), (b, own_b) = loaded
for lib, foreign in ((a, own_b), (b, own_a)):
    print("FOREIGN", lib.fmi2DoStep(c_void_p(foreign), c_double(0.0), c_double(1e-3), 0),
          lib.fmi2Reset(c_void_p(foreign)), lib.fmi2Terminate(c_void_p(foreign)), flush=True)
for lib, own in loaded:
    print("OWN", lib.fmi2DoStep(c_void_p(own), c_double(0.0), c_double(1e-3), 0), flush=True)
    lib.fmi2FreeInstance(c_void_p(own))
"""


@pytest.mark.parametrize("pair", [("ServoAxis", "CutSequencer"), ("AreaLimiter", "CutSequencer")])
def test_a_component_of_another_fmu_is_refused(fmus, pair):
    """A host that mixes up two FMUs' components (each the first instance of its binary): each binary refuses
    the other's handle (fmi2Error, no crash) and its own instance is untouched."""
    proc = subprocess.run([sys.executable, "-c", FOREIGN, *(str(fmus[m]) for m in pair)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert re.findall(r"^(FOREIGN|OWN) (.*)$", proc.stdout, re.MULTILINE) == \
        [("FOREIGN", "3 3 3"), ("FOREIGN", "3 3 3"), ("OWN", "0"), ("OWN", "0")]


RELOADED = """
import _ctypes, ctypes, sys, tempfile
from ctypes import c_char_p, c_double, c_int, c_void_p
from pathlib import Path
from fmpy import extract, read_model_description
md = read_model_description(sys.argv[1])
folder = Path(extract(sys.argv[1], tempfile.mkdtemp()))
binary = str(folder / "binaries" / "linux64" / f"{md.coSimulation.modelIdentifier}.so")

def instance(name):
    lib = ctypes.CDLL(binary)
    lib.fmi2Instantiate.restype = c_void_p
    lib.fmi2Instantiate.argtypes = [c_char_p, c_int, c_char_p, c_char_p, c_void_p, c_int, c_int]
    c = lib.fmi2Instantiate(name, 1, md.guid.encode(), (folder / "resources").as_uri().encode(), None, 0, 0)
    return lib, c_void_p(c)

lib, first = instance(b"first")
_ctypes.dlclose(lib._handle)                     # the host lets go of the library: the instance lives on
lib, second = instance(b"second")
print("HANDLES", first.value != second.value, flush=True)
for c in (first, second):
    print("SETUP", lib.fmi2SetupExperiment(c, 0, c_double(0.0), c_double(0.0), 0, c_double(0.0)),
          lib.fmi2EnterInitializationMode(c), lib.fmi2ExitInitializationMode(c), flush=True)
for c in (first, second):
    print("STEP", lib.fmi2DoStep(c, c_double(0.0), c_double(1e-3), 0), flush=True)
free = lib.fmi2FreeInstance
free.argtypes = [c_void_p]
_ctypes.dlclose(lib._handle)                     # the host lets go of the second copy too: both instances live on

def mapped():
    return sum(binary in line for line in open("/proc/self/maps"))

print("MAPPED", mapped() > 0, flush=True)
free(first)
print("MAPPED", mapped() > 0, flush=True)
free(second)                                     # the last instance: the library goes, no crash on the way out
print("MAPPED", mapped() > 0, flush=True)
"""


@pytest.mark.parametrize("model", ["ServoAxis", "CutSequencer"])
def test_instances_stay_apart_when_the_host_reopens_the_library(fmus, model):
    """ecos opens an FMU's library once per component and closes the first copy while its instance lives:
    the binary holds itself loaded while an instance lives, so the second instance gets a handle of its own;
    when the host has let go of every copy, the instances are still freed through the function pointers it
    kept, and the library is unloaded with the last one (no -z nodelete: nothing stays mapped)."""
    proc = subprocess.run([sys.executable, "-c", RELOADED, str(fmus[model])], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert re.findall(r"^(HANDLES|SETUP|STEP|MAPPED) (.*)$", proc.stdout, re.MULTILINE) == \
        [("HANDLES", "True"), ("SETUP", "0 0 0"), ("SETUP", "0 0 0"), ("STEP", "0"), ("STEP", "0"),
         ("MAPPED", "True"), ("MAPPED", "True"), ("MAPPED", "False")]


CONTINUITY = """
import sys, tempfile
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave
from hypothesis import given, settings, strategies as st

md = read_model_description(sys.argv[1])
fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(sys.argv[1], tempfile.mkdtemp()),
                modelIdentifier=md.coSimulation.modelIdentifier, instanceName="dut")
fmu.instantiate()
fmu.setupExperiment(startTime=0.0)
fmu.enterInitializationMode()
fmu.exitInitializationMode()
now = [0.0]

def step(t, h):
    try:
        fmu.doStep(t, h)
        return True
    except FMICallException:
        return False

@settings(derandomize=True, max_examples=150, deadline=None)
@given(h_ns=st.integers(1, 5_000_000), off_ns=st.floats(-3.0, 3.0).filter(lambda x: abs(abs(x) - 0.5) > 0.05))
def steps_continue_from_where_the_last_ended(h_ns, off_ns):
    h = h_ns * 1e-9
    accepted = step(now[0] + off_ns * 1e-9, h)
    assert accepted == (abs(off_ns) < 0.5), (now[0], h, off_ns)
    if accepted:
        now[0] += off_ns * 1e-9 + h
    assert step(now[0], h)                      # a refused step changed nothing: the instance steps on
    now[0] += h

steps_continue_from_where_the_last_ended()
print("HELD", now[0], flush=True)
"""


@pytest.mark.parametrize("model", ["ServoAxis", "CutSequencer"])
def test_a_step_must_continue_from_where_the_last_ended(fmus, model):
    """Any step size from 1 ns to 5 ms, any offset of the next step's time: within half a nanosecond of where the
    last step ended it is taken, further off it is refused and the instance steps on as if it had not been asked."""
    proc = subprocess.run([sys.executable, "-c", CONTINUITY, str(fmus[model])], capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "HELD" in proc.stdout
