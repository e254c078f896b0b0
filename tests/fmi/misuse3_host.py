"""An adversarial FMI 3.0 host (run as a script, in its own process, by test_fmi3_misuse.py): misuse_host.py's
cases ported to the FMI 3.0 layer (fmi/c/fmi3_functions.c), and the ones FMI 3.0 adds.

    python misuse3_host.py <fmu> <another FMU (its instance is the foreign handle)>

Calls the exported functions of the FMU's binary directly through ctypes, the way a careless or hostile host
would, and prints one line per case, flushed at once (so a crash names the case it died in):

    CASE <name> HELD|BROKEN <what happened>

then ``CASES <n> HELD <k>``. A case holds when the call returns what the FMI rules and our README say (NULL,
fmi3Error, fmi3OK; never fmi3Fatal), with a log line naming the reason where a logger was given, and nothing
crashes. FMI 3.0 passes Booleans as one byte: every argument is given as its ctypes type.
"""

from __future__ import annotations

import ctypes
import sys
import tempfile
from ctypes import (
    CFUNCTYPE,
    byref,
    c_bool,
    c_char_p,
    c_double,
    c_int,
    c_int32,
    c_size_t,
    c_uint32,
    c_uint64,
    c_void_p,
)
from pathlib import Path

from fmpy import extract, read_model_description
from misuse_report import announce, bad_instantiations, case, frees_do_nothing, refused_everywhere, summary, time_line

OK, ERROR, FATAL = 0, 3, 4
PLATFORM = "x86_64-linux"
LOGGER = CFUNCTYPE(None, c_void_p, c_int, c_char_p, c_char_p)
LOG: list[tuple[int, str, str]] = []
FATAL_LOGGED: list[str] = []                    # over the whole run: no message may be fmi3Fatal,
FMI2_NAMED: list[str] = []                      # nor name an FMI 2.0 call (the host called fmi3 ones)


def _log(env, status: int, category: bytes | None, message: bytes | None) -> None:
    text = (message or b"").decode(errors="replace")
    LOG.append((status, (category or b"").decode(errors="replace"), text))
    if status == FATAL:
        FATAL_LOGGED.append(text)
    if "fmi2" in text or "FMI 2.0" in text:
        FMI2_NAMED.append(text)


_logger = LOGGER(_log)
logger = ctypes.cast(_logger, c_void_p)


class Binary:
    """One FMU's extracted binary, its model description and its instantiation arguments."""

    def __init__(self, fmu: str) -> None:
        self.md = read_model_description(fmu)
        folder = Path(extract(fmu, tempfile.mkdtemp()))
        self.lib = ctypes.CDLL(str(folder / "binaries" / PLATFORM / f"{self.md.coSimulation.modelIdentifier}.so"))
        self.resources = (str(folder / "resources") + "/").encode()
        self.token = self.md.instantiationToken.encode()
        f = self.lib.fmi3InstantiateCoSimulation
        f.restype = c_void_p
        f.argtypes = [c_char_p, c_char_p, c_char_p, c_bool, c_bool, c_bool, c_bool, c_void_p, c_size_t, c_void_p,
                      c_void_p, c_void_p]
        for name in ("fmi3InstantiateModelExchange",):
            g = getattr(self.lib, name)
            g.restype = c_void_p
            g.argtypes = [c_char_p, c_char_p, c_char_p, c_bool, c_bool, c_void_p, c_void_p]
        g = self.lib.fmi3InstantiateScheduledExecution
        g.restype = c_void_p
        g.argtypes = [c_char_p, c_char_p, c_char_p, c_bool, c_bool, c_void_p, c_void_p, c_void_p, c_void_p, c_void_p]
        self.lib.fmi3FreeInstance.argtypes = [c_void_p]
        self.lib.fmi3FreeInstance.restype = None

    def make(self, name: bytes | None = b"dut", token: bytes | None | str = "own", res: bytes | None | str = "own",
             log: c_void_p | None = logger, event_mode: bool = False, logging: bool = False) -> int | None:
        return self.lib.fmi3InstantiateCoSimulation(name, self.token if token == "own" else token,
                                                    self.resources if res == "own" else res, False, logging,
                                                    event_mode, False, None, 0, None, log, None)

    def st(self, fn: str, *args) -> int:
        f = getattr(self.lib, fn)
        f.restype = c_int
        return f(*args)

    def ready(self, name: bytes = b"dut") -> c_void_p:
        c = self.make(name)
        assert c, LOG
        c = c_void_p(c)
        assert self.st("fmi3EnterInitializationMode", c, c_bool(False), c_double(0.0), c_double(0.0), c_bool(False),
                       c_double(0.0)) == OK, LOG
        assert self.st("fmi3ExitInitializationMode", c) == OK, LOG
        return c

    def free(self, c) -> None:
        self.lib.fmi3FreeInstance(c)


dut, foreign_binary = Binary(sys.argv[1]), Binary(sys.argv[2])
md, lib, st = dut.md, dut.lib, dut.st
def refused(name: str, call, says: str | None = None) -> None:
    """``call()`` returns fmi3Error (not Fatal), with a log line saying ``says`` when given."""
    announce(name)
    LOG.clear()
    result = call()
    told = says is None or any(s == ERROR and says in m for s, _, m in LOG)
    case(name, result == ERROR and told, f"returned {result} {LOG[-2:]}")


def accepted(name: str, call) -> None:
    announce(name)
    LOG.clear()
    result = call()
    case(name, result == OK, f"returned {result} {LOG[-2:]}")


def variables(type_: str, *causalities: str, variability: str | None = None) -> list:
    return [v for v in md.modelVariables if v.type == type_ and v.causality in causalities and v.valueReference < 10**9
            and (variability is None or v.variability == variability)]


def enter(c, start: float = 0.0, stop_defined: bool = False, stop: float = 0.0) -> int:
    return st("fmi3EnterInitializationMode", c, c_bool(False), c_double(0.0), c_double(start), c_bool(stop_defined),
              c_double(stop))


# -- 1. instantiation with bad arguments: NULL, one error line (when the host gave a logger), no crash -------
BAD_INSTANTIATIONS = {
    "null_instance_name": dict(name=None),
    "non_utf8_instance_name": dict(name=b"\xff\xfe"),
    "null_resource_path": dict(res=None),
    "empty_resource_path": dict(res=b""),
    "nonexistent_resource_path": dict(res=b"/nonexistent/resources/"),
    "resource_path_given_as_a_uri": dict(res=b"file:///tmp/"),        # FMI 3.0: a path, not FMI 2.0's URI
    "resource_path_a_file": dict(res=b"/etc/passwd"),
    "resource_path_too_long": dict(res=b"/" + b"x" * 5000 + b"/"),
    "wrong_instantiation_token": dict(token=b"{00000000-0000-0000-0000-000000000000}"),
    "empty_instantiation_token": dict(token=b""),
    "null_instantiation_token": dict(token=None),
    "event_mode_asked": dict(event_mode=True),
}
announce("instantiate_long_name")
c = dut.make(name=b"n" * 5000, logging=True)
case("instantiate_long_name_and_debug_logging", bool(c) and st("fmi3Terminate", c_void_p(c)) == ERROR, "")
dut.free(c_void_p(c))
bad_instantiations(BAD_INSTANTIATIONS, dut.make, {"log": None}, LOG, ERROR)
announce("instantiate_model_exchange")
LOG.clear()
c = lib.fmi3InstantiateModelExchange(b"dut", dut.token, dut.resources, False, False, None, logger)
case("instantiate_model_exchange", not c and len(LOG) == 1 and LOG[0][0] == ERROR, f"{c!r} {LOG}")
announce("instantiate_scheduled_execution")
LOG.clear()
c = lib.fmi3InstantiateScheduledExecution(b"dut", dut.token, dut.resources, False, False, None, logger, None, None,
                                          None)
case("instantiate_scheduled_execution", not c and len(LOG) == 1 and LOG[0][0] == ERROR, f"{c!r} {LOG}")
for fn in ("fmi3InstantiateModelExchange", "fmi3InstantiateScheduledExecution"):
    announce(f"{fn}_all_null")
    args = [None] * (7 if fn.endswith("Exchange") else 10)
    args[3:5] = [False, False]
    case(f"{fn}_all_null", not getattr(lib, fn)(*args), "")

# -- 2. every exported function with a NULL, a freed, a made-up and another FMU's instance: fmi3Error --------
refs = (c_uint32 * 1)(0)
f64 = (c_double * 1)()
f64b = (c_double * 1)()
i32 = (c_int32 * 1)()
u64 = (c_uint64 * 1)()
u64b = (c_uint64 * 1)()
flags = (c_bool * 1)()
strs = (c_char_p * 1)(b"x")
sizes = (c_size_t * 1)(1)
binaries = (c_void_p * 1)()
state = c_void_p()
size = c_size_t()
blob = (ctypes.c_char * 64)()
b1, b2, b3, b4, b5 = (c_bool() for _ in range(5))
d1 = c_double()
N1 = c_size_t(1)


def values_call(fn: str, array):
    return lambda c: st(fn, c, refs, N1, array, N1)


CALLS = {
    "fmi3SetDebugLogging": lambda c: st("fmi3SetDebugLogging", c, c_bool(True), c_size_t(0), None),
    "fmi3EnterInitializationMode": lambda c: st("fmi3EnterInitializationMode", c, c_bool(False), c_double(0),
                                                c_double(0), c_bool(False), c_double(0)),
    "fmi3ExitInitializationMode": lambda c: st("fmi3ExitInitializationMode", c),
    "fmi3EnterEventMode": lambda c: st("fmi3EnterEventMode", c),
    "fmi3EnterStepMode": lambda c: st("fmi3EnterStepMode", c),
    "fmi3EnterConfigurationMode": lambda c: st("fmi3EnterConfigurationMode", c),
    "fmi3ExitConfigurationMode": lambda c: st("fmi3ExitConfigurationMode", c),
    "fmi3EvaluateDiscreteStates": lambda c: st("fmi3EvaluateDiscreteStates", c),
    "fmi3EnterContinuousTimeMode": lambda c: st("fmi3EnterContinuousTimeMode", c),
    "fmi3Terminate": lambda c: st("fmi3Terminate", c),
    "fmi3Reset": lambda c: st("fmi3Reset", c),
    "fmi3GetFloat64": values_call("fmi3GetFloat64", f64),
    "fmi3GetInt32": values_call("fmi3GetInt32", i32),
    "fmi3GetBoolean": values_call("fmi3GetBoolean", flags),
    "fmi3GetString": values_call("fmi3GetString", strs),
    "fmi3SetFloat64": values_call("fmi3SetFloat64", f64),
    "fmi3SetInt32": values_call("fmi3SetInt32", i32),
    "fmi3SetBoolean": values_call("fmi3SetBoolean", flags),
    "fmi3SetString": values_call("fmi3SetString", strs),
    **{f"fmi3{io}{t}": values_call(f"fmi3{io}{t}", u64) for io in ("Get", "Set")
       for t in ("Float32", "Int8", "UInt8", "Int16", "UInt16", "UInt32", "Int64", "UInt64")},
    "fmi3GetBinary": lambda c: st("fmi3GetBinary", c, refs, N1, sizes, binaries, N1),
    "fmi3SetBinary": lambda c: st("fmi3SetBinary", c, refs, N1, sizes, binaries, N1),
    "fmi3GetClock": lambda c: st("fmi3GetClock", c, refs, N1, flags),
    "fmi3SetClock": lambda c: st("fmi3SetClock", c, refs, N1, flags),
    "fmi3GetNumberOfVariableDependencies": lambda c: st("fmi3GetNumberOfVariableDependencies", c, c_uint32(0),
                                                        byref(size)),
    "fmi3GetVariableDependencies": lambda c: st("fmi3GetVariableDependencies", c, c_uint32(0), sizes, refs, sizes,
                                                i32, N1),
    "fmi3GetFMUState": lambda c: st("fmi3GetFMUState", c, byref(state)),
    "fmi3SetFMUState": lambda c: st("fmi3SetFMUState", c, c_void_p(0x1234)),
    "fmi3FreeFMUState": lambda c: st("fmi3FreeFMUState", c, byref(c_void_p(0x1234))),
    "fmi3SerializedFMUStateSize": lambda c: st("fmi3SerializedFMUStateSize", c, c_void_p(0x1234), byref(size)),
    "fmi3SerializeFMUState": lambda c: st("fmi3SerializeFMUState", c, c_void_p(0x1234), blob, c_size_t(64)),
    "fmi3DeserializeFMUState": lambda c: st("fmi3DeserializeFMUState", c, blob, c_size_t(64), byref(state)),
    "fmi3GetDirectionalDerivative": lambda c: st("fmi3GetDirectionalDerivative", c, refs, N1, refs, N1, f64, N1,
                                                 f64b, N1),
    "fmi3GetAdjointDerivative": lambda c: st("fmi3GetAdjointDerivative", c, refs, N1, refs, N1, f64, N1, f64b, N1),
    "fmi3GetIntervalDecimal": lambda c: st("fmi3GetIntervalDecimal", c, refs, N1, f64, i32),
    "fmi3GetIntervalFraction": lambda c: st("fmi3GetIntervalFraction", c, refs, N1, u64, u64b, i32),
    "fmi3GetShiftDecimal": lambda c: st("fmi3GetShiftDecimal", c, refs, N1, f64),
    "fmi3GetShiftFraction": lambda c: st("fmi3GetShiftFraction", c, refs, N1, u64, u64b),
    "fmi3SetIntervalDecimal": lambda c: st("fmi3SetIntervalDecimal", c, refs, N1, f64),
    "fmi3SetIntervalFraction": lambda c: st("fmi3SetIntervalFraction", c, refs, N1, u64, u64b),
    "fmi3SetShiftDecimal": lambda c: st("fmi3SetShiftDecimal", c, refs, N1, f64),
    "fmi3SetShiftFraction": lambda c: st("fmi3SetShiftFraction", c, refs, N1, u64, u64b),
    "fmi3ActivateModelPartition": lambda c: st("fmi3ActivateModelPartition", c, c_uint32(0), c_double(0.0)),
    "fmi3UpdateDiscreteStates": lambda c: st("fmi3UpdateDiscreteStates", c, byref(b1), byref(b2), byref(b3),
                                             byref(b4), byref(b5), byref(d1)),
    "fmi3CompletedIntegratorStep": lambda c: st("fmi3CompletedIntegratorStep", c, c_bool(True), byref(b1),
                                                byref(b2)),
    "fmi3SetTime": lambda c: st("fmi3SetTime", c, c_double(0.0)),
    **{fn: (lambda name: lambda c: st(name, c, f64, N1))(fn) for fn in (
        "fmi3SetContinuousStates", "fmi3GetContinuousStateDerivatives", "fmi3GetEventIndicators",
        "fmi3GetContinuousStates", "fmi3GetNominalsOfContinuousStates")},
    "fmi3GetNumberOfEventIndicators": lambda c: st("fmi3GetNumberOfEventIndicators", c, byref(size)),
    "fmi3GetNumberOfContinuousStates": lambda c: st("fmi3GetNumberOfContinuousStates", c, byref(size)),
    "fmi3GetOutputDerivatives": lambda c: st("fmi3GetOutputDerivatives", c, refs, N1, i32, f64, N1),
    "fmi3DoStep": lambda c: st("fmi3DoStep", c, c_double(0.0), c_double(1e-3), c_bool(True), byref(b1), byref(b2),
                               byref(b3), byref(d1)),
}
print("CALLS", " ".join(sorted(CALLS)), flush=True)     # the test checks these are all the binary exports
other = dut.ready(b"bystander")                 # another instance: it must not be disturbed
freed = dut.make(b"freed")
dut.free(c_void_p(freed))
foreign = foreign_binary.ready(b"foreign")      # an instance of another FMU's binary
refused_everywhere(CALLS, (("null", None), ("freed", c_void_p(freed)), ("made_up", c_void_p(0x4E43100000000007)),
                           ("foreign", foreign)), "instance", ERROR)
frees_do_nothing(dut.free, c_void_p(freed))     # a second free of the same handle: nothing happens
announce("free_foreign")
dut.free(foreign)                               # not this binary's: nothing happens, the other FMU's lives on
case("free_foreign_instance", foreign_binary.st("fmi3DoStep", foreign, c_double(0.0), c_double(1e-3), c_bool(True),
                                                None, None, None, None) == OK, "")
foreign_binary.free(foreign)

# -- 3. the calls this FMU does not offer, on a live instance in step mode: fmi3Error naming why ----------------
c = dut.ready(b"not_provided")
VALUE_TYPES = {"fmi3GetFloat64", "fmi3GetInt32", "fmi3GetBoolean", "fmi3GetString", "fmi3SetFloat64", "fmi3SetInt32",
               "fmi3SetBoolean", "fmi3SetString"}
STATE_MACHINE = {"fmi3SetDebugLogging", "fmi3EnterInitializationMode", "fmi3ExitInitializationMode",
                 "fmi3Terminate", "fmi3Reset", "fmi3DoStep", "fmi3GetFMUState", "fmi3SetFMUState",
                 "fmi3FreeFMUState", "fmi3SerializedFMUStateSize", "fmi3SerializeFMUState",
                 "fmi3DeserializeFMUState"}
output = variables("Float64", "output")[0].valueReference
for fn in sorted(set(CALLS) - VALUE_TYPES - STATE_MACHINE):
    refs[0] = output
    refused(f"live_{fn}_refused", lambda fn=fn: CALLS[fn](c), fn)      # the message names the call
    case(f"live_{fn}_keeps_the_instance",
         st("fmi3GetFloat64", c, refs, N1, f64, N1) == OK, "")
dut.free(c)

# -- 4. value references: wrong type, unknown, counts, NULL arrays, outputs, fixed parameters, rules, Strings ---
c = dut.ready(b"values")
real_in = (variables("Float64", "input") or variables("Float64", "parameter", variability="tunable"))[0]
int_any = (variables("Int32", "input", "parameter", "output"))[0]
bool_any = variables("Boolean", "input", "parameter", "output")[0]
fixed = variables("Float64", "parameter", variability="fixed")[0]
ruled = next(v for v in variables("Float64", "parameter") if v.min is not None or v.max is not None)  # (inputs: the
outside = float(ruled.min) - abs(float(ruled.min)) - 1.0 if ruled.min is not None else \
    float(ruled.max) + abs(float(ruled.max)) + 1.0                              # controller's rules)
string_vars = variables("String", "parameter")
not_string = min(v.valueReference for v in md.modelVariables if v.type != "String")


def with_ref(ref: int, fn: str, array, n: int = 1, n_values: int = 1):
    def call():
        refs[0] = ref
        return st(fn, c, refs, c_size_t(n), array, c_size_t(n_values))
    return call


for fn, array in (("fmi3GetString", strs), ("fmi3SetString", strs)):
    refused(f"{fn}_vr_not_string", with_ref(not_string, fn, array), f"value reference {not_string} ")
    refused(f"{fn}_vr_unknown", with_ref(99999, fn, array), "value reference 99999 ")
for fn, array, var in (("fmi3GetFloat64", f64, int_any), ("fmi3GetInt32", i32, real_in),
                       ("fmi3GetBoolean", flags, real_in), ("fmi3SetFloat64", f64, bool_any),
                       ("fmi3SetInt32", i32, real_in), ("fmi3SetBoolean", flags, int_any)):
    refused(f"{fn}_on_a_{var.type}", with_ref(var.valueReference, fn, array), "is not of this call's type")
refused("fmi3GetFloat64_vr_unknown", with_ref(99999, "fmi3GetFloat64", f64), "is not a variable of this FMU")
refused("fmi3GetFloat64_vr_max", with_ref(0xFFFFFFFF, "fmi3GetFloat64", f64), "is not a variable of this FMU")
announce("fmi3GetFloat64_the_time_variable")      # the declared independent variable: where the instance stands
refs[0], f64[0] = 10**9, -1.0
got = st("fmi3GetFloat64", c, refs, N1, f64, N1)
case("fmi3GetFloat64_the_time_variable", got == OK and f64[0] == 0.0, f"returned {got} {f64[0]} {LOG[-2:]}")
refused("fmi3GetUInt16_no_such_type", with_ref(output, "fmi3GetUInt16", u64), "is not a variable of this call's type")
refused("fmi3SetInt64_no_such_type", with_ref(real_in.valueReference, "fmi3SetInt64", u64),
        "is not a variable of this call's type")
refused("fmi3GetFloat64_two_values_for_one_ref", with_ref(output, "fmi3GetFloat64", f64, 1, 2), "scalar")
refused("fmi3SetFloat64_no_value_for_one_ref", with_ref(real_in.valueReference, "fmi3SetFloat64", f64, 1, 0),
        "scalar")
refused("fmi3GetFloat64_null_refs", lambda: st("fmi3GetFloat64", c, None, N1, f64, N1), "NULL")
refused("fmi3GetFloat64_null_values", lambda: st("fmi3GetFloat64", c, refs, N1, None, N1), "NULL")
refused("fmi3SetString_null_values", lambda: st("fmi3SetString", c, refs, N1, None, N1), "NULL")
accepted("fmi3GetFloat64_no_refs", lambda: st("fmi3GetFloat64", c, None, c_size_t(0), None, c_size_t(0)))
accepted("fmi3GetUInt8_no_refs", lambda: st("fmi3GetUInt8", c, None, c_size_t(0), None, c_size_t(0)))
refs[0] = output
f64[0] = 1.0
refused("fmi3SetFloat64_an_output", with_ref(output, "fmi3SetFloat64", f64), "is an output")
f64[0] = float(fixed.start) if fixed.start is not None else 0.0
refused("fmi3SetFloat64_a_fixed_parameter_in_step_mode", with_ref(fixed.valueReference, "fmi3SetFloat64", f64),
        "fixed parameter")
for label, value in (("nan", float("nan")), ("inf", float("inf")), ("outside_its_range", outside)):
    # Refused at the set (the native models) or, the Python models, when initialisation checks the parameters:
    # either way fmi3Error naming the parameter, never a model running with it.
    announce(f"fmi3SetFloat64_{label}_for_a_parameter")
    fresh = c_void_p(dut.make(b"ruled"))        # in Instantiated, where a fixed parameter is set
    f64[0] = value
    refs[0] = ruled.valueReference
    LOG.clear()
    result = st("fmi3SetFloat64", fresh, refs, N1, f64, N1)
    if result == OK:
        result = max(enter(fresh), st("fmi3ExitInitializationMode", fresh))
    named = any(s == ERROR and ruled.name in m for s, _, m in LOG)
    case(f"fmi3SetFloat64_{label}_for_a_parameter", result == ERROR and named, f"returned {result} {LOG[-2:]}")
    dut.free(fresh)
if string_vars:                                  # Strings: text must be UTF-8 (in Instantiated, where a set goes)
    fresh = c_void_p(dut.make(b"strings"))
    ref = string_vars[0].valueReference
    for label, text in (("non_utf8", b"\xff\xfe"), ("truncated_utf8", b"abc\xe2\x82"), ("overlong_utf8", b"\xc0\xaf"),
                        ("null_string", None)):
        strs[0] = text
        refused(f"fmi3SetString_{label}", lambda: (refs.__setitem__(0, ref),
                                                   st("fmi3SetString", fresh, refs, N1, strs, N1))[1],
                "UTF-8" if text is not None else "NULL")
    strs[0] = b"x"
    dut.free(fresh)
announce("values_instance_steps_on")
case("values_instance_steps_on", st("fmi3DoStep", c, c_double(0.0), c_double(1e-3), c_bool(True), None, None, None,
                                    None) == OK, "")
dut.free(c)

# -- 5. the state machine: each call outside the states FMI 3.0 allows it in --------------------------------
c = c_void_p(dut.make(b"machine"))
refs[0] = output


def step(c, t: float, h: float = 1e-3) -> int:
    return st("fmi3DoStep", c, c_double(t), c_double(h), c_bool(True), None, None, None, None)


refused("get_when_instantiated", lambda: st("fmi3GetFloat64", c, refs, N1, f64, N1), "not allowed")
refused("step_when_instantiated", lambda: step(c, 0.0), "not allowed")
refused("exit_initialization_when_instantiated", lambda: st("fmi3ExitInitializationMode", c), "not allowed")
refused("terminate_when_instantiated", lambda: st("fmi3Terminate", c), "not allowed")
refused("enter_initialization_stop_before_start", lambda: enter(c, 1.0, True, 0.5), "stopTime")
refused("enter_initialization_nan_start", lambda: enter(c, float("nan")), "finite")
accepted("enter_initialization", lambda: enter(c))
refused("enter_initialization_twice", lambda: enter(c), "not allowed")
refused("step_in_initialization_mode", lambda: step(c, 0.0), "not allowed")
accepted("exit_initialization", lambda: st("fmi3ExitInitializationMode", c))
refused("exit_initialization_twice", lambda: st("fmi3ExitInitializationMode", c), "not allowed")
accepted("step_in_step_mode", lambda: step(c, 0.0))
accepted("terminate", lambda: st("fmi3Terminate", c))
refused("step_when_terminated", lambda: step(c, 1e-3), "not allowed")
refused("set_when_terminated", with_ref(real_in.valueReference, "fmi3SetFloat64", f64), "not allowed")
accepted("get_when_terminated", lambda: st("fmi3GetFloat64", c, refs, N1, f64, N1))
refused("terminate_twice", lambda: st("fmi3Terminate", c), "not allowed")
accepted("reset_when_terminated", lambda: st("fmi3Reset", c))
refused("step_after_reset", lambda: step(c, 0.0), "not allowed")
accepted("initialise_again_after_reset", lambda: max(enter(c), st("fmi3ExitInitializationMode", c), step(c, 0.0)))
refused("set_debug_logging_unknown_category",
        lambda: st("fmi3SetDebugLogging", c, c_bool(True), N1, (c_char_p * 1)(b"noSuchCategory")), "noSuchCategory")
refused("set_debug_logging_null_categories", lambda: st("fmi3SetDebugLogging", c, c_bool(True), N1, None))
refused("set_debug_logging_a_null_category",
        lambda: st("fmi3SetDebugLogging", c, c_bool(True), N1, (c_char_p * 1)(None)))
refused("set_debug_logging_non_utf8_category",
        lambda: st("fmi3SetDebugLogging", c, c_bool(True), N1, (c_char_p * 1)(b"\xff\xfe")))
accepted("set_debug_logging_known_category",
         lambda: st("fmi3SetDebugLogging", c, c_bool(True), N1, (c_char_p * 1)(b"logStatusError")))
dut.free(c)

# -- 6. doStep: no going back in time, no step below 1 ns; a restored state's time is where steps go on ---------
c = dut.ready(b"time")
time_line(lambda t, h=1e-3: step(c, t, h), lambda says: any(says in m for _, _, m in LOG), LOG.clear, OK, ERROR, {
    "step_of_0_s": (lambda: step(c, 2e-3, 0.0), ERROR, "> 0"),
    "step_negative": (lambda: step(c, 2e-3, -1e-3), ERROR, "> 0"),
    "step_of_nan_s": (lambda: step(c, 2e-3, float("nan")), ERROR, "finite"),
    "step_of_inf_s": (lambda: step(c, 2e-3, float("inf")), ERROR, "finite"),
    "step_at_nan_time": (lambda: step(c, float("nan")), ERROR, "finite")})
announce("step_reports_its_end")
last, flags3 = c_double(-1.0), [c_bool(True), c_bool(True), c_bool(True)]
got = st("fmi3DoStep", c, c_double(3e-3), c_double(1e-3), c_bool(True), *(byref(f) for f in flags3), byref(last))
case("step_reports_its_end_and_no_event", got == OK and abs(last.value - 4e-3) < 1e-15
     and not any(f.value for f in flags3), f"{got} {last.value} {[f.value for f in flags3]}")
announce("restore_then_continue")
saved = c_void_p()
took = st("fmi3GetFMUState", c, byref(saved))                       # at t = 4 ms
later = [step(c, 4e-3), step(c, 5e-3)]
back = st("fmi3SetFMUState", c, saved)
case("restored_state_continues_from_its_time", [took, *later, back, step(c, 4e-3)] == [OK] * 5,
     f"{took} {later} {back}")
announce("restore_then_old_time")
case("restored_state_refuses_the_time_before_it", (st("fmi3SetFMUState", c, saved), step(c, 6e-3)) == (OK, ERROR),
     "")
announce("deserialized_state_continues_from_its_time")
st("fmi3SerializedFMUStateSize", c, saved, byref(size))
good = (ctypes.c_char * size.value)()
serialized = st("fmi3SerializeFMUState", c, saved, good, size)
other_instance = dut.ready(b"other_time")
restored = c_void_p()
loaded = st("fmi3DeserializeFMUState", other_instance, good, size, byref(restored))
set_ = st("fmi3SetFMUState", other_instance, restored)
case("deserialized_state_continues_from_its_time",
     [serialized, loaded, set_, step(other_instance, 4e-3), step(other_instance, 5e-3)] == [OK] * 5,
     f"{serialized} {loaded} {set_} {LOG[-2:]}")

# -- 7. FMU states: NULL, foreign, freed, made up; serialized bytes that are not a state of this FMU ----------------
refused("get_state_null_pointer", lambda: st("fmi3GetFMUState", c, None), "NULL")
refused("get_state_made_up_to_overwrite", lambda: st("fmi3GetFMUState", c, byref(c_void_p(0x1234))), "not a live")
refused("set_state_null", lambda: st("fmi3SetFMUState", c, None), "not a live")
refused("set_state_of_another_instance", lambda: st("fmi3SetFMUState", c, restored), "not a live")
refused("size_state_of_another_instance", lambda: st("fmi3SerializedFMUStateSize", c, restored, byref(size)),
        "not a live")
refused("size_null_pointer", lambda: st("fmi3SerializedFMUStateSize", c, saved, None), "NULL")
refused("serialize_buffer_too_small", lambda: st("fmi3SerializeFMUState", c, saved, blob, c_size_t(1)), "too small")
refused("serialize_null_buffer", lambda: st("fmi3SerializeFMUState", c, saved, None, size), "NULL")
refused("deserialize_null_state_pointer", lambda: st("fmi3DeserializeFMUState", c, good, size, None), "NULL")
refused("deserialize_null_bytes", lambda: st("fmi3DeserializeFMUState", c, None, size, byref(state)), "NULL")
refused("deserialize_no_bytes", lambda: st("fmi3DeserializeFMUState", c, good, c_size_t(0), byref(state)))
refused("deserialize_garbage", lambda: st("fmi3DeserializeFMUState", c, (ctypes.c_char * 64)(*b"\xa5" * 64),
                                          c_size_t(64), byref(state)))
refused("deserialize_truncated", lambda: st("fmi3DeserializeFMUState", c, good, c_size_t(size.value // 2),
                                            byref(state)))
flipped = (ctypes.c_char * size.value).from_buffer_copy(bytes(good))
flipped[0] = bytes([flipped[0][0] ^ 0xFF])
refused("deserialize_first_byte_flipped", lambda: st("fmi3DeserializeFMUState", c, flipped, size, byref(state)))
longer = (ctypes.c_char * (size.value + 8)).from_buffer_copy(bytes(good) + b"\0" * 8)
refused("deserialize_trailing_bytes", lambda: st("fmi3DeserializeFMUState", c, longer, c_size_t(size.value + 8),
                                                 byref(state)))
foreign_c = foreign_binary.ready(b"foreign_state")
fsaved, fsize = c_void_p(), c_size_t()
foreign_binary.st("fmi3GetFMUState", foreign_c, byref(fsaved))
foreign_binary.st("fmi3SerializedFMUStateSize", foreign_c, fsaved, byref(fsize))
fbytes = (ctypes.c_char * fsize.value)()
foreign_binary.st("fmi3SerializeFMUState", foreign_c, fsaved, fbytes, fsize)
refused("set_state_of_another_fmu", lambda: st("fmi3SetFMUState", c, fsaved), "not a live")
refused("deserialize_another_fmus_state", lambda: st("fmi3DeserializeFMUState", c, fbytes, fsize, byref(state)))
foreign_binary.st("fmi3FreeFMUState", foreign_c, byref(fsaved))
foreign_binary.free(foreign_c)
accepted("free_state_null_pointer", lambda: st("fmi3FreeFMUState", c, None))
accepted("free_state_pointing_to_null", lambda: st("fmi3FreeFMUState", c, byref(c_void_p())))
refused("free_state_of_another_instance", lambda: st("fmi3FreeFMUState", c, byref(c_void_p(restored.value))),
        "not a live")
kept = c_void_p(saved.value)
accepted("free_state", lambda: st("fmi3FreeFMUState", c, byref(saved)))
case("free_state_clears_the_pointer", saved.value is None, repr(saved.value))
refused("free_state_twice", lambda: st("fmi3FreeFMUState", c, byref(c_void_p(kept.value))), "not a live")
refused("set_freed_state", lambda: st("fmi3SetFMUState", c, kept), "not a live")
refused("serialize_freed_state", lambda: st("fmi3SerializeFMUState", c, kept, good, size), "not a live")
announce("state_set_on_a_fresh_instance")
fresh = c_void_p(dut.make(b"fresh"))             # never initialised: a state of a stepping one, set on it
fresh_state = c_void_p()
got = [st("fmi3DeserializeFMUState", fresh, good, size, byref(fresh_state)), st("fmi3SetFMUState", fresh, fresh_state)]
# FMI 3.0 allows fmi3SetFMUState in every state, and the state brings its own (the Reference-FMUs' setFMUState
# copies the instance's state with the model's): restored, the fresh instance is in step mode at the state's time
case("state_set_on_a_fresh_instance_steps_on", got == [OK, OK] and step(fresh, 4e-3) == OK
     and step(fresh, 5e-3) == OK, f"{got} {LOG[-2:]}")
dut.free(fresh)
announce("state_instance_steps_on")
case("state_instance_steps_on", step(c, 4e-3) == OK, f"{LOG[-2:]}")
dut.free(other_instance)
dut.free(c)

# -- 8. the bystander instance was not disturbed by any of it -------------------------------------------------
announce("bystander_after_misuse")
refs[0] = output
steps = [step(other, k * 1e-3) for k in range(5)]
got = st("fmi3GetFloat64", other, refs, N1, f64, N1)
case("bystander_instance_unharmed", steps == [OK] * 5 and got == OK and f64[0] == f64[0], f"{steps} {got}")
dut.free(other)

case("no_message_was_fatal", not FATAL_LOGGED, repr(FATAL_LOGGED[:3]))
case("no_message_names_fmi2", not FMI2_NAMED, f"{len(FMI2_NAMED)}: {sorted(set(FMI2_NAMED))}")
summary()
