"""The one module that talks to ``fmpy.fmi3``: an FMI 3.0 co-simulation FMU as a :class:`~ncfmu.cosim.slave.Slave`.

The master's buffers hold FMI 2.0 kinds (:data:`~ncfmu.cosim.fmu.FMI3_TYPES`: Float64 as Real, Int32 as Integer,
Boolean, String); each step sets and gets them through fmpy's wrappers (the Python loop: the C loop drives FMI 2.0
functions only). The error contract is :class:`~ncfmu.cosim.fmu.FmuSlave`'s: a refused value is ConfigError, a
failed call SimulationError naming the instance and the call, fmpy's exceptions never escape; an FMU that sets
terminateSimulation raises TerminationRequested (the run ends cleanly at the step before).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TypeVar

import numpy as np
from fmpy.fmi1 import FMICallException
from fmpy.fmi3 import FMU3Slave

from ..errors import SimulationError, SystemDefinitionError, TerminationRequested
from .fmu import UnpackedFmu, check_range, fmpy_slave, typed_value
from .slave import Variable

_T = TypeVar("_T")
_STATUS = {0: "ok", 1: "warning", 2: "discard", 3: "error", 4: "fatal"}
_SET = {"Real": "setFloat64", "Integer": "setInt32", "Boolean": "setBoolean", "String": "setString"}
_GET = {"Real": "getFloat64", "Integer": "getInt32", "Boolean": "getBoolean", "String": "getString"}


class Fmu3Slave:
    """One FMI 3.0 co-simulation instance driven through fmpy's :class:`fmpy.fmi3.FMU3Slave`."""

    def __init__(self, unpacked: UnpackedFmu, instance_name: str) -> None:
        self.name = instance_name
        self.unpacked = unpacked
        self.variables: dict[str, Variable] = unpacked.variables
        self.messages: list[tuple[str, str]] = []
        self._alive = False
        self.fmu = self._call("fmi3InstantiateCoSimulation", lambda: fmpy_slave(FMU3Slave, unpacked, instance_name))
        self._call("fmi3InstantiateCoSimulation", lambda: self.fmu.instantiate(loggingOn=True, logMessage=self._log))
        self._alive = True
        self._initialized = False
        self._reads: list[tuple[str, list[int], np.ndarray]] = []
        self._writes: list[tuple[str, list[int], np.ndarray]] = []

    def _log(self, env, status, category, message) -> None:
        text = message.decode("utf-8", "replace") if isinstance(message, bytes) else str(message)
        self.messages.append((_STATUS.get(status, str(status)), text))

    def _fail(self, what: str, status: int) -> SimulationError:
        """The one place a failed call's status becomes our exception."""
        if status >= 4:
            self._alive = False
        errors = [msg for lvl, msg in self.messages[-5:] if lvl in ("error", "fatal")]
        error = SimulationError(f"{self.name}: {what} returned fmi3{_STATUS.get(status, str(status)).capitalize()}"
                                + (f": {'; '.join(errors)}" if errors else ""))
        if errors and "Initialization" in what:
            error.refusal = "; ".join(errors)
        return error

    def _call(self, what: str, call: Callable[..., _T], *args: object) -> _T:
        try:
            return call(*args)
        except FMICallException as err:
            raise self._fail(what, int(getattr(err, "status", 3))) from None
        except Exception as err:           # fmpy's "Failed to instantiate FMU" is a plain Exception
            raise SimulationError(f"{self.name}: {what} failed: {err}") from None

    # -- set-up ---------------------------------------------------------------------------------
    def set_start(self, name: str, value: object) -> None:
        v = self.variables.get(name)
        if v is None:
            raise SystemDefinitionError(f"{self.name} has no variable {name!r}")
        typed = typed_value(f"{self.name}.{name}", v.type, value)
        if v.type in ("Real", "Integer"):
            check_range(f"{self.name}.{name}", v, typed)
        setter = getattr(self.fmu, _SET[v.type])
        self._call(f"fmi3S{_SET[v.type][1:]}({name} = {typed!r})", lambda: setter([v.vr], [typed]))

    def initialize(self, start_time: float, stop_time: float) -> None:
        self._initialized = True
        stop = stop_time if math.isfinite(stop_time) else None
        self._call("fmi3EnterInitializationMode",
                   lambda: self.fmu.enterInitializationMode(startTime=start_time, stopTime=stop))
        self._call("fmi3ExitInitializationMode", self.fmu.exitInitializationMode)

    def bind(self, kind: str, inputs: np.ndarray, input_vrs: list[int],
             outputs: np.ndarray, output_vrs: list[int]) -> None:
        if input_vrs:
            self._writes.append((kind, list(input_vrs), inputs))
        if output_vrs:
            self._reads.append((kind, list(output_vrs), outputs))

    # -- the loop -------------------------------------------------------------------------------
    def write_inputs(self) -> None:
        for kind, vrs, buffer in self._writes:
            values = [bool(x) for x in buffer] if kind == "Boolean" else buffer.tolist()
            self._call(f"fmi3S{_SET[kind][1:]}", getattr(self.fmu, _SET[kind]), vrs, values)

    def do_step(self, t: float, h: float) -> None:
        done = self._call(f"fmi3DoStep at t = {t:.6f} s", lambda: self.fmu.doStep(t, h, False))
        assert isinstance(done, tuple)
        _event, terminate, _early, last = done
        if terminate:
            raise TerminationRequested(self.name, t, "; ".join(m for _l, m in self.messages[-3:]), float(last))

    def read_outputs(self) -> None:
        for kind, vrs, buffer in self._reads:
            buffer[:] = self._call(f"fmi3G{_GET[kind][1:]}", getattr(self.fmu, _GET[kind]), vrs)

    def read_kind(self, kind: str) -> None:
        """Fill the bound outputs of ``kind`` alone (an isolated FMU's process names each call before it makes it)."""
        for bound, vrs, buffer in self._reads:
            if bound == kind:
                buffer[:] = self._call(f"fmi3G{_GET[kind][1:]}", getattr(self.fmu, _GET[kind]), vrs)

    def get(self, name: str) -> object:
        v = self.variables[name]
        value = self._call(f"fmi3Get{v.type}({name})", lambda: getattr(self.fmu, _GET[v.type])([v.vr])[0])
        return value.decode() if isinstance(value, bytes) else value

    def reset(self) -> None:
        self._call("fmi3Reset", self.fmu.reset)
        self._initialized = False
        self.messages.clear()
        self._reads.clear()
        self._writes.clear()

    def terminate(self) -> None:
        if self._alive:
            self._alive = False
            try:
                if self._initialized:       # fmi3Terminate is for an initialised instance
                    self.fmu.terminate()
            except FMICallException:
                pass              # freed all the same
            finally:
                self.fmu.freeInstance()
