"""An adversarial FMI host (run as a script, in its own process, by test_shim_misuse.py).

    python misuse_host.py <fmu>

Calls the exported functions of the FMU's binary directly through ctypes, the way a careless or hostile
host would, and prints one line per case, flushed at once (so a crash names the case it died in):

    CASE <name> HELD|BROKEN <what happened>

then ``CASES <n> HELD <k>``. A case holds when the call returns what the FMI rules and our README say
(NULL, fmi2Error, fmi2OK), with a log line naming the reason where a logger was given, and nothing crashes.
"""

from __future__ import annotations

import ctypes
import sys
import tempfile
from ctypes import byref, c_char_p, c_double, c_int, c_size_t, c_uint, c_void_p
from pathlib import Path

from fmpy import extract, read_model_description
from fmpy.fmi2 import (
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
)
from fmpy.logging import addLoggerProxy
from misuse_report import announce, bad_instantiations, case, frees_do_nothing, refused_everywhere, summary, time_line

OK, ERROR = 0, 3
fmu_path = sys.argv[1]
md = read_model_description(fmu_path)
folder = Path(extract(fmu_path, tempfile.mkdtemp()))
model = md.coSimulation.modelIdentifier
lib = ctypes.CDLL(str(folder / "binaries" / "linux64" / f"{model}.so"))
RESOURCES = (folder / "resources").as_uri().encode()
GUID = md.guid.encode()
vr = {v.name: v.valueReference for v in md.modelVariables}

LOG: list[tuple[int, str]] = []


def _log(env, name, status, category, message):
    LOG.append((status, message.decode(errors="replace")))


libc = ctypes.CDLL(None)
libc.calloc.restype = c_void_p
libc.calloc.argtypes = [c_size_t, c_size_t]
libc.free.argtypes = [c_void_p]
callbacks = fmi2CallbackFunctions()
callbacks.logger = fmi2CallbackLoggerTYPE(_log)
callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(lambda n, s: libc.calloc(n, s))
callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(lambda p: libc.free(p))
addLoggerProxy(byref(callbacks))                  # formats the FMU's printf-style messages, as fmpy does
silent = fmi2CallbackFunctions()                  # a host that gives no logger at all

Instantiate = lib.fmi2Instantiate
Instantiate.restype = c_void_p
Instantiate.argtypes = [c_char_p, c_int, c_char_p, c_char_p, c_void_p, c_int, c_int]
for fn in ("fmi2FreeInstance",):
    getattr(lib, fn).argtypes = [c_void_p]
    getattr(lib, fn).restype = None

def make(name: bytes = b"dut", cb=callbacks, guid=GUID, res=RESOURCES, kind: int = 1):
    return Instantiate(name, kind, guid, res, byref(cb) if cb is not None else None, 0, 0)


def st(fn: str, *args) -> int:
    f = getattr(lib, fn)
    f.restype = c_int
    return f(*args)


def ready(name: bytes = b"dut"):
    c = make(name)
    assert c, LOG
    assert st("fmi2SetupExperiment", c_void_p(c), 0, c_double(0.0), c_double(0.0), 0, c_double(0.0)) == OK
    assert st("fmi2EnterInitializationMode", c_void_p(c)) == OK
    assert st("fmi2ExitInitializationMode", c_void_p(c)) == OK, LOG
    return c


# -- 1. fmi2Instantiate with bad arguments: NULL, one log line (when the host gave a logger), no crash -----
BAD_INSTANTIATIONS = {
    "null_instance_name": dict(name=None),
    "non_utf8_instance_name": dict(name=b"\xff\xfe"),
    "null_resource_location": dict(res=None),
    "nonexistent_resources": dict(res=b"file:///nonexistent"),
    "resources_not_a_file_uri": dict(res=b"http://example.invalid/resources"),
    "wrong_guid": dict(guid=b"{00000000-0000-0000-0000-000000000000}"),
    "null_guid": dict(guid=None),
    "model_exchange": dict(kind=0),
}
bad_instantiations(BAD_INSTANTIATIONS, make, {"cb": silent}, LOG, ERROR)
announce("instantiate_null_callbacks")
c = make(name=None, cb=None)
case("instantiate_null_callbacks", not c, repr(c))

# -- 2. every exported function with a NULL, a freed, and a made-up component: fmi2Error, no crash ---------
refs = (c_uint * 1)(0)
reals = (c_double * 1)()
ints = (c_int * 1)()
strs = (c_char_p * 1)(b"x")
orders = (c_int * 1)(1)
state = c_void_p()
size = c_size_t()
status_out = c_int()
real_out = c_double()
blob = (ctypes.c_char * 64)()
CALLS = {
    "fmi2SetDebugLogging": lambda c: st("fmi2SetDebugLogging", c, 1, c_size_t(0), None),
    "fmi2SetupExperiment": lambda c: st("fmi2SetupExperiment", c, 0, c_double(0), c_double(0), 0, c_double(0)),
    "fmi2EnterInitializationMode": lambda c: st("fmi2EnterInitializationMode", c),
    "fmi2ExitInitializationMode": lambda c: st("fmi2ExitInitializationMode", c),
    "fmi2Terminate": lambda c: st("fmi2Terminate", c),
    "fmi2Reset": lambda c: st("fmi2Reset", c),
    "fmi2GetReal": lambda c: st("fmi2GetReal", c, refs, c_size_t(1), reals),
    "fmi2GetInteger": lambda c: st("fmi2GetInteger", c, refs, c_size_t(1), ints),
    "fmi2GetBoolean": lambda c: st("fmi2GetBoolean", c, refs, c_size_t(1), ints),
    "fmi2GetString": lambda c: st("fmi2GetString", c, refs, c_size_t(1), strs),
    "fmi2SetReal": lambda c: st("fmi2SetReal", c, refs, c_size_t(1), reals),
    "fmi2SetInteger": lambda c: st("fmi2SetInteger", c, refs, c_size_t(1), ints),
    "fmi2SetBoolean": lambda c: st("fmi2SetBoolean", c, refs, c_size_t(1), ints),
    "fmi2SetString": lambda c: st("fmi2SetString", c, refs, c_size_t(1), strs),
    "fmi2GetFMUstate": lambda c: st("fmi2GetFMUstate", c, byref(state)),
    "fmi2SetFMUstate": lambda c: st("fmi2SetFMUstate", c, c_void_p(0x1234)),
    "fmi2FreeFMUstate": lambda c: st("fmi2FreeFMUstate", c, byref(c_void_p(0x1234))),
    "fmi2SerializedFMUstateSize": lambda c: st("fmi2SerializedFMUstateSize", c, c_void_p(0x1234), byref(size)),
    "fmi2SerializeFMUstate": lambda c: st("fmi2SerializeFMUstate", c, c_void_p(0x1234), blob, c_size_t(64)),
    "fmi2DeSerializeFMUstate": lambda c: st("fmi2DeSerializeFMUstate", c, blob, c_size_t(64), byref(state)),
    "fmi2GetDirectionalDerivative": lambda c: st("fmi2GetDirectionalDerivative", c, refs, c_size_t(1), refs,
                                                 c_size_t(1), reals, reals),
    "fmi2SetRealInputDerivatives": lambda c: st("fmi2SetRealInputDerivatives", c, refs, c_size_t(1), orders, reals),
    "fmi2GetRealOutputDerivatives": lambda c: st("fmi2GetRealOutputDerivatives", c, refs, c_size_t(1), orders,
                                                 reals),
    "fmi2DoStep": lambda c: st("fmi2DoStep", c, c_double(0.0), c_double(1e-3), 0),
    "fmi2CancelStep": lambda c: st("fmi2CancelStep", c),
    "fmi2GetStatus": lambda c: st("fmi2GetStatus", c, 0, byref(status_out)),
    "fmi2GetRealStatus": lambda c: st("fmi2GetRealStatus", c, 2, byref(real_out)),
    "fmi2GetIntegerStatus": lambda c: st("fmi2GetIntegerStatus", c, 0, byref(status_out)),
    "fmi2GetBooleanStatus": lambda c: st("fmi2GetBooleanStatus", c, 0, byref(status_out)),
    "fmi2GetStringStatus": lambda c: st("fmi2GetStringStatus", c, 0, byref(c_char_p())),
}
print("CALLS", " ".join(sorted(CALLS)), flush=True)     # the test checks these are all the binary exports
other = ready(b"bystander")                     # another instance: it must not be disturbed
freed = make(b"freed")
lib.fmi2FreeInstance(c_void_p(freed))
refused_everywhere(CALLS, (("null", None), ("freed", c_void_p(freed)), ("made_up", c_void_p(0xDEADBEE0))),
                   "component", ERROR)
frees_do_nothing(lib.fmi2FreeInstance, c_void_p(freed))      # a second free of the same handle: nothing happens
announce("bystander_after_misuse")
out = (c_double * 1)()
real_outputs = [v.valueReference for v in md.modelVariables if v.causality == "output" and v.type == "Real"]
refs[0] = real_outputs[0]
steps = [st("fmi2DoStep", c_void_p(other), c_double(k * 1e-3), c_double(1e-3), 0) for k in range(5)]
got = st("fmi2GetReal", c_void_p(other), refs, c_size_t(1), out)
case("bystander_instance_unharmed", steps == [OK] * 5 and got == OK and out[0] == out[0], f"{steps} {got}")

# -- 3. String calls with value references that are not String variables: fmi2Error naming the vr ----------
c = ready(b"strings")
not_string = min(v.valueReference for v in md.modelVariables if v.type != "String")    # 0 but in the contour
for fn, ref in ((f, r) for f in ("fmi2GetString", "fmi2SetString") for r in (not_string, 99999)):
    announce(f"{fn}_{ref}")
    LOG.clear()
    refs[0] = ref
    result = st(fn, c_void_p(c), refs, c_size_t(1), strs)
    named = any(f"value reference {ref} " in m for _, m in LOG)
    case(f"{fn}_vr_{'not_string' if ref == not_string else ref}", result == ERROR and named, f"returned {result} {LOG}")
lib.fmi2FreeInstance(c_void_p(c))


# -- 4. doStep: no going back in time, no step below 1 ns; a restored state's time is where steps go on ----
def step(c, t: float, h: float = 1e-3) -> int:
    return st("fmi2DoStep", c_void_p(c), c_double(t), c_double(h), 0)


c = ready(b"time")
time_line(lambda t, h=1e-3: step(c, t, h), lambda says: any(says in m for _, m in LOG), LOG.clear, OK, ERROR)
announce("restore_then_continue")
saved = c_void_p()
took = st("fmi2GetFMUstate", c_void_p(c), byref(saved))           # at t = 3 ms
later = [step(c, 3e-3), step(c, 4e-3)]
back = st("fmi2SetFMUstate", c_void_p(c), saved)
case("restored_state_continues_from_its_time", [took, *later, back, step(c, 3e-3)] == [OK] * 5,
     f"{took} {later} {back}")
announce("restore_then_old_time")
case("restored_state_refuses_the_time_before_it", (st("fmi2SetFMUstate", c_void_p(c), saved), step(c, 5e-3)) ==
     (OK, ERROR), "")
announce("deserialized_state_continues_from_its_time")
st("fmi2SerializedFMUstateSize", c_void_p(c), saved, byref(size))
buffer = (ctypes.c_char * size.value)()
serialized = st("fmi2SerializeFMUstate", c_void_p(c), saved, buffer, size)
other_instance = ready(b"other_time")
restored = c_void_p()
loaded = st("fmi2DeSerializeFMUstate", c_void_p(other_instance), buffer, size, byref(restored))
set_ = st("fmi2SetFMUstate", c_void_p(other_instance), restored)
case("deserialized_state_continues_from_its_time",
     [serialized, loaded, set_, step(other_instance, 3e-3), step(other_instance, 4e-3)] == [OK] * 5, "")
announce("state_set_on_a_fresh_instance")
# FMI 2.0 allows fmi2SetFMUstate in every state, and the state brings its own (the Reference-FMUs' setFMUState):
# restored, the never-initialised instance is in step mode at the state's time
fresh, fresh_state = make(b"fresh"), c_void_p()
got = [st("fmi2DeSerializeFMUstate", c_void_p(fresh), buffer, size, byref(fresh_state)),
       st("fmi2SetFMUstate", c_void_p(fresh), fresh_state)]
case("state_set_on_a_fresh_instance_steps_on", got == [OK, OK] and step(fresh, 3e-3) == OK and step(fresh, 4e-3) == OK,
     f"{got} {LOG[-2:]}")
lib.fmi2FreeInstance(c_void_p(fresh))
lib.fmi2FreeInstance(c_void_p(other_instance))
lib.fmi2FreeInstance(c_void_p(c))
lib.fmi2FreeInstance(c_void_p(other))

summary()
