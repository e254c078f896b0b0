"""The one module that talks to ``fmpy.fmi2``: an FMU as a :class:`~ncfmu.cosim.slave.Slave`.

The loop calls go straight to the FMU's C functions with ctypes arrays that share memory with
the master's numpy buffers: one ``fmi2SetXxx``/``fmi2GetXxx`` call per kind per step, nothing
allocated per step.
"""

from __future__ import annotations

import atexit
import ctypes
import hashlib
import itertools
import math
import shutil
import tempfile
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

import numpy as np
from fmpy import read_model_description
from fmpy.fmi1 import FMICallException, calloc, free, printLogMessage
from fmpy.fmi2 import (
    FMU2Slave,
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
)

from ..errors import ConfigError, SimulationError, SystemDefinitionError, TerminationRequested
from ..ports import NUMBER_RULE, Value, parse_text
from .native_loop import Fmi2Functions
from .slave import KINDS, Variable
from .ssp import MAX_UNPACKED, is_link
from .units import unit_from_fmpy, variable_unit
from .value_references import check_value_references

_T = TypeVar("_T")

_STATUS = {0: "ok", 1: "warning", 2: "discard", 3: "error", 4: "fatal", 5: "pending"}

# fmpy's C proxy that formats the variadic log message keeps ONE logger per process; so one logger
# routes every message by the componentEnvironment each slave registers (its own id).
_SINKS: dict[int, list[tuple[str, str]]] = {}
_IDS = itertools.count(1)


def _dispatch(env, instance, status, category, message) -> None:
    sink = _SINKS.get(env or 0)
    if sink is not None:
        sink.append((_STATUS.get(status, str(status)), message.decode("utf-8", "replace")))
    else:
        # not one of ours: an FMU the user runs through fmpy's default callbacks in the same process, whose
        # messages fmpy's proxy now routes here -- print them as fmpy's own default logger would
        printLogMessage(env, instance, status, category, message)


_LOGGER = fmi2CallbackLoggerTYPE(_dispatch)


INT32 = (-2 ** 31, 2 ** 31 - 1)

#: fmi2DoStep's noSetFMUStatePriorToCurrentPoint: fmi2False, because a branch run sets an FMU back to a saved
#: state before the current point (an FMU may drop that history after fmi2True).
NO_SET_FMU_STATE_PRIOR = 0


def typed_value(qualified: str, fmi_type: str, value: object) -> Value:
    """``value`` as an FMI ``fmi_type`` value, or :class:`ConfigError` -- never rounded, wrapped or guessed.

    A Real is returned as a float, an Integer or Enumeration as an int, a Boolean as a bool, a String as a str.
    """
    if fmi_type == "Real":
        if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
            raise ConfigError(qualified, value, NUMBER_RULE if isinstance(value, str) else "must be a number")
        return float(value)
    if fmi_type in ("Integer", "Enumeration"):
        if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
            whole = int(value)
        elif isinstance(value, (float, np.floating)) and math.isfinite(value) and float(value).is_integer():
            whole = int(value)
        else:
            digits = " in ASCII digits 0-9" if isinstance(value, str) else ""
            raise ConfigError(qualified, value, f"must be a whole number{digits}")
        if not INT32[0] <= whole <= INT32[1]:
            raise ConfigError(qualified, value, f"must be a whole number in {INT32[0]}..{INT32[1]} (fmi2Integer)")
        return whole
    if fmi_type == "Boolean":
        if isinstance(value, (bool, np.bool_)) or value in (0, 1):
            return bool(value)
        raise ConfigError(qualified, value, "must be true or false")
    if not isinstance(value, str):
        raise ConfigError(qualified, value, "must be text")
    return _utf8_text(qualified, value)


def _utf8_text(qualified: str, value: str) -> str:
    """A String as an FMU takes it: UTF-8 (a command line's undecodable byte arrives as a lone surrogate) without
    NUL (an fmi2String ends there: the rest would be lost without a word)."""
    try:
        value.encode("utf-8")
    except UnicodeEncodeError as err:
        bad = value[err.start]
        byte = value[err.start:err.start + 1].encode("utf-8", "surrogateescape") if "\udc80" <= bad <= "\udcff" else b""
        what = f"the byte 0x{byte[0]:02x}" if byte else f"the character U+{ord(bad):04X}"
        raise ConfigError(qualified, value, f"must be UTF-8 text ({what} at position {err.start} is not)") from None
    if "\x00" in value:
        raise ConfigError(qualified, value, f"must be text without NUL (one at position {value.index(chr(0))}: an "
                          "FMI String ends there)")
    return value


def check_range(qualified: str, v: Variable, value: object) -> None:
    """The modelDescription's rule for a value given to ``v`` (type checked already): finite, within min/max."""
    if v.type == "Real" and not math.isfinite(float(value)):     # type: ignore[arg-type]
        raise ConfigError(qualified, value, "must be finite")
    if v.type in ("Real", "Integer"):
        x = float(value)                                          # type: ignore[arg-type]
        low, high = v.min, v.max
        if (low is not None and x < low) or (high is not None and x > high):
            rule = (f"must be in [{low:g}, {high:g}]" if low is not None and high is not None
                    else f"must be >= {low:g}" if low is not None else f"must be <= {high:g}")
            raise ConfigError(qualified, value, rule)


def safe_extract(archive: Path, target: Path) -> Path:
    """Unzip ``archive`` into ``target``, refusing entries that escape it (``../``, absolute paths) and symbolic
    links (zipfile would write a link as a file holding its target; no tool should find one there)."""
    target = Path(target).resolve()
    try:
        z = zipfile.ZipFile(archive)
    except (zipfile.BadZipFile, OSError) as err:
        raise SystemDefinitionError(f"{archive}: not an SSP archive (a zip file): {err}") from None
    with z:
        total = sum(info.file_size for info in z.infolist())
        if total > MAX_UNPACKED:
            raise SystemDefinitionError(f"{archive}: unpacks to more than {MAX_UNPACKED / 2 ** 30:g} GiB "
                                        f"({total / 2 ** 30:.1f} GiB): refused")
        for entry in z.infolist():
            name = entry.filename
            dest = (target / name).resolve()
            if name.startswith(("/", "\\")) or (dest != target and target not in dest.parents):
                raise SystemDefinitionError(f"{archive}: entry {name!r} would be written outside the extraction folder")
            if is_link(entry):
                raise SystemDefinitionError(f"{archive}: entry {name!r} is a symbolic link: refused (an archive "
                                            "carries its files themselves)")
        z.extractall(target)
    return target


_UNPACKED: dict[str, UnpackedFmu] = {}
_CACHE_ROOT: list[Path] = []


def unpacked_fmu(path: Path) -> UnpackedFmu:
    """The FMU at ``path`` unpacked once per process, keyed by its content.

    Every run of a system used to unpack its FMUs afresh and load their binaries from the new folder: each
    run left another copy of each shared library mapped (deleted) in the process and a few MB of memory.
    Keyed by content, a second run of the same FMU loads the very same library file, which the dynamic
    loader shares. The folder lives until the process exits.
    """
    if not Path(path).is_file():
        raise SystemDefinitionError(f"FMU not found: {path}")
    digest = hashlib.sha256(Path(path).read_bytes()).hexdigest()[:20]
    unpacked = _UNPACKED.get(digest)
    if unpacked is None:
        if not _CACHE_ROOT:
            _CACHE_ROOT.append(Path(tempfile.mkdtemp(prefix="ncfmu_fmus_")))
            atexit.register(shutil.rmtree, _CACHE_ROOT[0], True)
        unpacked = _UNPACKED[digest] = UnpackedFmu(path, _CACHE_ROOT[0] / digest)
    return unpacked


#: The FMI 3.0 types the master runs, as the FMI 2.0 kinds its buffers hold (the rest are refused, naming them)
FMI3_TYPES = {"Float64": "Real", "Int32": "Integer", "Boolean": "Boolean", "String": "String"}


def _supported_fmi3(fmu: str, v) -> None:
    """An FMI 3.0 variable the master can run, or SystemDefinitionError naming it and what is not supported."""
    if v.causality == "independent":
        return
    if v.type not in FMI3_TYPES:
        raise SystemDefinitionError(f"{fmu}: variable {v.name} is an FMI 3.0 {v.type}: not supported (ncfmu's master "
                                    f"runs {', '.join(FMI3_TYPES)} variables)")
    if getattr(v, "dimensions", None):
        raise SystemDefinitionError(f"{fmu}: variable {v.name} is an array: FMI 3.0 arrays are not supported")
    if getattr(v, "clocks", None) or getattr(v, "intervalVariability", None):
        raise SystemDefinitionError(f"{fmu}: variable {v.name} is clocked: FMI 3.0 clocks are not supported")


class UnpackedFmu:
    """An FMU archive unpacked once and shared by all its instances (two servo axes, many variants)."""

    def __init__(self, path: Path, workdir: Path | None = None) -> None:
        """``path``: the FMU archive, or the folder it was unpacked to already (where an isolated FMU's process
        loads the master's copy from, :mod:`~ncfmu.cosim.isolated`)."""
        self.path = Path(path)
        self._tmp = None
        if self.path.is_dir():
            self.directory = self.path
        else:
            if not self.path.is_file():
                raise SystemDefinitionError(f"FMU not found: {self.path}")
            if workdir is None:
                self._tmp = tempfile.mkdtemp(prefix=f"ncfmu_{self.path.stem}_")
                workdir = Path(self._tmp)
            self.directory = safe_extract(self.path, Path(workdir))
        try:
            self.model_description = read_model_description(str(self.path))
        except Exception as err:                         # fmpy's own errors name the schema problem
            raise SystemDefinitionError(f"{self.path.name}: cannot read its modelDescription.xml: {err}") from None
        md = self.model_description
        if md.fmiVersion not in ("2.0", "3.0"):
            raise SystemDefinitionError(f"{self.path.name}: an FMI {md.fmiVersion} FMU; ncfmu's master runs FMI 2.0 "
                                        "and 3.0 co-simulation FMUs only")
        if md.coSimulation is None:
            raise SystemDefinitionError(f"{self.path.name}: a model-exchange-only FMU; ncfmu's master runs FMI 2.0 "
                                        "and 3.0 co-simulation FMUs only (no solver for model exchange)")
        self.fmi3 = md.fmiVersion == "3.0"
        check_value_references(self.path.name, md.modelVariables, self.fmi3)
        self.variables: dict[str, Variable] = {}
        for v in md.modelVariables:
            if self.fmi3:
                _supported_fmi3(self.path.name, v)
                if v.causality == "independent":
                    continue
            typ = FMI3_TYPES.get(v.type, v.type) if self.fmi3 else v.type
            start = v.start
            if start is not None:
                try:
                    start = parse_text(typ, str(start))
                except ValueError:
                    raise SystemDefinitionError(f"{self.path.name}: variable {v.name} has start {start!r}, not a "
                                                f"valid {v.type}") from None
            bounds = []
            for bound in (v.min, v.max):
                try:
                    bounds.append(None if bound is None else float(bound))
                except ValueError:
                    raise SystemDefinitionError(f"{self.path.name}: variable {v.name} has a range bound "
                                                f"{bound!r} that is not a number") from None
            unit = variable_unit(v)
            self.variables[v.name] = Variable(v.name, typ, v.causality, v.valueReference,
                                              unit, start, v.description or "",
                                              v.variability or "", bounds[0], bounds[1],
                                              None if unit is None else unit_from_fmpy(unit, md.unitDefinitions))

    def cleanup(self) -> None:
        if self._tmp:
            shutil.rmtree(self._tmp, ignore_errors=True)


def fmpy_slave(cls: Callable[..., _T], unpacked: UnpackedFmu, instance_name: str) -> _T:
    """fmpy's slave of class ``cls`` (FMU2Slave, FMU3Slave) for ``unpacked``: it loads the binary, and fmpy
    raises a plain Exception when it cannot (the caller's _call makes that a SimulationError)."""
    md = unpacked.model_description
    return cls(guid=md.guid, unzipDirectory=str(unpacked.directory), modelIdentifier=md.coSimulation.modelIdentifier,
               instanceName=instance_name)


class FmuSlave:
    """One FMU instance driven through fmpy's :class:`fmpy.fmi2.FMU2Slave`."""

    def __init__(self, unpacked: UnpackedFmu, instance_name: str, logging_on: bool = False) -> None:
        self.name = instance_name
        self.unpacked = unpacked
        self.variables = unpacked.variables
        self.messages: list[tuple[str, str]] = []
        self._alive = False
        self.fmu = self._call("fmi2Instantiate", lambda: fmpy_slave(FMU2Slave, unpacked, instance_name))
        self._env = next(_IDS)
        _SINKS[self._env] = self.messages
        self._callbacks = fmi2CallbackFunctions()
        self._callbacks.logger = _LOGGER
        self._callbacks.componentEnvironment = self._env
        self._callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        self._callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        try:
            from fmpy.logging import addLoggerProxy  # formats the variadic message in C
            addLoggerProxy(ctypes.byref(self._callbacks))
        except Exception:  # pragma: no cover - older fmpy without the proxy: messages stay unformatted
            pass
        try:
            self._call("fmi2Instantiate", lambda: self.fmu.instantiate(callbacks=self._callbacks, loggingOn=True))
        except SimulationError:
            _SINKS.pop(self._env, None)
            raise
        self._component = self.fmu.component
        self._dll = self.fmu.dll
        self._reads: list[tuple] = []
        self._writes: list[tuple] = []
        self._sent: list[bytes | None] = []
        self._raw: ctypes.CDLL | None = None   # our own handle of the FMU library (see bind)
        self._raw_component: ctypes.c_void_p | None = None
        self._raw_step: Callable[..., int] | None = None
        self._step = self._dll.fmi2DoStep
        self._alive = True
        self._initialized = False      # set by initialize (even when it fails part-way), cleared by reset

    def _fail(self, what: str, status: int, time: float | None = None, reason: str | None = None) -> SimulationError:
        """The one place a failed call's status becomes our exception (every route to the FMU comes here);
        ``reason``: what fmpy said when a call failed without a status (an instantiation that returned NULL, a
        binary that cannot be loaded)."""
        if reason is not None:
            errors = [msg for lvl, msg in self.messages[-5:] if lvl == "error"]
            return SimulationError(f"{self.name}: {what} failed: {reason}" + "".join(f"; {m}" for m in errors))
        if status == 2 and time is not None and self._asks_to_terminate():
            detail = [msg for _lvl, msg in self.messages[-3:]]
            return TerminationRequested(self.name, time, "; ".join(detail), self._last_successful_time())
        if status >= 4:
            self._alive = False   # after fmi2Fatal the FMI standard allows no further call, not even freeing
        recent = self.messages[-5:]
        # our own error lines name the variable and the rule; pythonfmu's "Fatal py exception" adds nothing then
        errors = [msg for lvl, msg in recent if lvl == "error"]
        said = "; ".join(errors) if errors else "; ".join(f"[{lvl}] {msg}" for lvl, msg in recent
                                                              if lvl in ("fatal", "warning"))
        error = SimulationError(f"{self.name}: {what} returned fmi2{_STATUS.get(status, str(status)).capitalize()}"
                                + (f": {said}" if said else ""))
        if errors and "Initialization" in what:
            error.refusal = "; ".join(errors)
        return error

    def _asks_to_terminate(self) -> bool:
        """After fmi2Discard from fmi2DoStep: fmi2GetBooleanStatus(fmi2Terminated) says whether the FMU asks to end
        the simulation (an FMU that cannot say does not)."""
        try:
            return bool(self.fmu.getBooleanStatus(3))      # 3: fmi2Terminated
        except Exception:          # fmi2Discard or fmi2Error: the FMU cannot say, so it does not ask
            return False

    def _last_successful_time(self) -> float | None:
        """After fmi2Discard: fmi2GetRealStatus(fmi2LastSuccessfulTime), how far the FMU got (None: it cannot say)."""
        try:
            return float(self.fmu.getRealStatus(2))        # 2: fmi2LastSuccessfulTime
        except Exception:          # fmi2Discard or fmi2Error: the FMU cannot say
            return None

    def _call(self, what: str, call: Callable[[], _T]) -> _T:
        """A call through fmpy's wrappers: fmpy's FMICallException becomes our SimulationError (the contract)."""
        try:
            return call()
        except FMICallException as err:
            raise self._fail(what, int(getattr(err, "status", 3))) from None
        except Exception as err:
            if type(err) is not Exception:     # ours or Python's (a bug): not fmpy's plain Exception
                raise
            raise self._fail(what, 3, reason=str(err)) from None

    def fmi2_failure(self, what: str, status: int) -> SimulationError:
        """The error for ``what`` returning ``status`` (for the C loop, which calls the functions directly)."""
        time = None
        if what.startswith("fmi2DoStep at t = "):
            time = float(what.removeprefix("fmi2DoStep at t = ").split()[0])
        return self._fail(what, status, time)

    def fmi2_functions(self) -> Fmi2Functions:
        """The component and the addresses of the loop's FMI functions, for the C loop
        (:mod:`~ncfmu.cosim.native_loop`), which sets the inputs from now on."""
        self.forget_sent_inputs()

        def address(name: str) -> int:
            value = ctypes.cast(getattr(self._dll, name), ctypes.c_void_p).value
            assert value is not None
            return value

        return Fmi2Functions(self._component, address("fmi2DoStep"),
                             {kind: address(f"fmi2Set{kind}") for kind in KINDS},
                             {kind: address(f"fmi2Get{kind}") for kind in KINDS})

    def forget_sent_inputs(self) -> None:
        """Inputs were set behind this slave's back (the C loop): the next :meth:`write_inputs` sends every one."""
        self._sent = [None] * len(self._writes)

    def _check(self, what: str, status: int) -> None:
        if status > 1:
            raise self._fail(what, status)

    # -- set-up ---------------------------------------------------------------------------------
    def set_start(self, name: str, value: object) -> None:
        self._sent = [None] * len(self._writes)        # an input may have been set directly
        v = self.variables.get(name)
        if v is None:
            raise SystemDefinitionError(f"{self.name} has no variable {name!r}")
        typed = typed_value(f"{self.name}.{name}", v.type, value)
        vr = (ctypes.c_uint * 1)(v.vr)
        # typed_value returned a float for a Real, an int for an Integer, a str for a String
        if v.type == "Real":
            assert isinstance(typed, float)
            status = self._dll.fmi2SetReal(self._component, vr, 1, (ctypes.c_double * 1)(typed))
        elif v.type in ("Integer", "Enumeration"):
            assert isinstance(typed, int)
            status = self._dll.fmi2SetInteger(self._component, vr, 1, (ctypes.c_int * 1)(typed))
        elif v.type == "Boolean":
            status = self._dll.fmi2SetBoolean(self._component, vr, 1, (ctypes.c_int * 1)(1 if typed else 0))
        else:
            assert isinstance(typed, str)
            status = self._dll.fmi2SetString(self._component, vr, 1, (ctypes.c_char_p * 1)(typed.encode()))
        self._check(f"setting {name} = {typed!r}", status)

    def initialize(self, start_time: float, stop_time: float) -> None:
        self._initialized = True
        for what, call in (("fmi2SetupExperiment", lambda: self._dll.fmi2SetupExperiment(
                                self._component, 0, 0.0, start_time, int(math.isfinite(stop_time)),
                                stop_time if math.isfinite(stop_time) else 0.0)),
                           ("fmi2EnterInitializationMode",
                            lambda: self._dll.fmi2EnterInitializationMode(self._component)),
                           ("fmi2ExitInitializationMode",
                            lambda: self._dll.fmi2ExitInitializationMode(self._component))):
            self._check(what, call())

    def bind(self, kind: str, inputs: np.ndarray, input_vrs: list[int],
             outputs: np.ndarray, output_vrs: list[int]) -> None:
        # The loop calls go through a handle of our own without argtypes: every argument is a ready
        # ctypes object, and ctypes' per-call argument conversion (~0.4 µs a call) is skipped.
        if self._raw is None:
            self._raw = ctypes.CDLL(self._dll._name)
            self._raw_component = ctypes.c_void_p(self._component)
            step = self._raw.fmi2DoStep
            step.restype = ctypes.c_int
            self._raw_step = step
            self._t, self._h = ctypes.c_double(), ctypes.c_double()
            self._no_set_prior = ctypes.c_int(NO_SET_FMU_STATE_PRIOR)
        setter = getattr(self._raw, f"fmi2Set{kind}")
        getter = getattr(self._raw, f"fmi2Get{kind}")
        setter.restype = getter.restype = ctypes.c_int
        ptr = ctypes.POINTER(ctypes.c_double if kind == "Real" else ctypes.c_int)
        if input_vrs:
            vrs = (ctypes.c_uint * len(input_vrs))(*input_vrs)
            self._writes.append((setter, vrs, ctypes.c_size_t(len(input_vrs)), inputs.ctypes.data_as(ptr), kind,
                                 inputs))
            self._sent.append(None)
        if output_vrs:
            vrs = (ctypes.c_uint * len(output_vrs))(*output_vrs)
            self._reads.append((getter, vrs, ctypes.c_size_t(len(output_vrs)), outputs.ctypes.data_as(ptr), kind,
                                outputs))

    # -- the loop -------------------------------------------------------------------------------
    def _transfer(self, calls: list[tuple], what: str) -> None:
        component = self._raw_component
        for function, vrs, n, data, kind, _keep in calls:
            status = function(component, vrs, n, data)
            if status > 1:
                raise self._fail(f"fmi2{what}{kind}", status)

    def write_inputs(self) -> None:
        # An FMU input keeps its value until set again: send a kind only when its values changed
        # (buttons, in-position flags and integers rarely do). Cleared whenever the FMU's inputs may
        # have changed behind our back (initialisation, reset, state restore).
        component, sent = self._raw_component, self._sent
        for i, (function, vrs, n, data, kind, buffer) in enumerate(self._writes):
            now = buffer.tobytes()
            if sent[i] == now:
                continue
            status = function(component, vrs, n, data)
            if status > 1:
                raise self._fail(f"fmi2Set{kind}", status)
            sent[i] = now

    def do_step(self, t: float, h: float) -> None:
        raw = self._raw_step
        if raw is not None:
            self._t.value, self._h.value = t, h
            status = raw(self._raw_component, self._t, self._h, self._no_set_prior)
        else:
            status = self._step(self._component, t, h, NO_SET_FMU_STATE_PRIOR)
        if status > 1:
            raise self._fail(f"fmi2DoStep at t = {t:.6f} s", status, t)

    def read_outputs(self) -> None:
        self._transfer(self._reads, "Get")

    def read_kind(self, kind: str) -> None:
        """Fill the bound outputs of ``kind`` alone (an isolated FMU's process names each call before it makes it)."""
        self._transfer([call for call in self._reads if call[4] == kind], "Get")

    def get(self, name: str) -> object:
        """Read one variable (for checks outside the loop)."""
        v = self.variables[name]
        if v.type == "Real":
            return self._call(f"fmi2GetReal({name})", lambda: self.fmu.getReal([v.vr])[0])
        if v.type in ("Integer", "Enumeration"):
            return self._call(f"fmi2GetInteger({name})", lambda: self.fmu.getInteger([v.vr])[0])
        if v.type == "Boolean":
            return self._call(f"fmi2GetBoolean({name})", lambda: self.fmu.getBoolean([v.vr])[0])
        value = self._call(f"fmi2GetString({name})", lambda: self.fmu.getString([v.vr])[0])
        return value.decode() if isinstance(value, bytes) else value

    # -- FMU state ------------------------------------------------------------------------------
    def get_state(self):
        """fmi2GetFMUstate: an opaque handle (free it with :meth:`free_state`)."""
        return self._call("fmi2GetFMUstate", self.fmu.getFMUstate)

    def set_state(self, state) -> None:
        self._call("fmi2SetFMUstate", lambda: self.fmu.setFMUstate(state))
        self._sent = [None] * len(self._writes)

    def free_state(self, state) -> None:
        self._call("fmi2FreeFMUstate", lambda: self.fmu.freeFMUstate(state))

    def serialize_state(self, state) -> bytes:
        return bytes(self._call("fmi2SerializeFMUstate", lambda: self.fmu.serializeFMUstate(state)))

    def deserialize_state(self, data: bytes):
        return self._call("fmi2DeSerializeFMUstate", lambda: self.fmu.deSerializeFMUstate(bytes(data)))

    def reset(self) -> None:
        """fmi2Reset: back to the instantiated state (for batch runs); bindings and the log of the run before
        are dropped (a run's messages are its own)."""
        self._check("fmi2Reset", self._dll.fmi2Reset(self._component))
        self._initialized = False
        self.messages.clear()
        self._reads.clear()
        self._writes.clear()
        self._sent.clear()

    def terminate(self) -> None:
        try:
            if self._alive:
                self._alive = False
                try:
                    if self._initialized:   # fmi2Terminate is for an initialised instance (FMI 2.0 state machine)
                        self._dll.fmi2Terminate(self._component)
                finally:
                    self.fmu.freeInstance()
        finally:
            _SINKS.pop(self._env, None)     # after the last call: what fmi2Terminate logs is still this slave's
