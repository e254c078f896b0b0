"""The small slave interface the master depends on.

Call order, for every slave (the master keeps to it; a fake slave can check it)::

    s = make_slave(...)                # instantiated; s.variables known
    s.set_start(name, value) ...       # parameters and start values (before initialisation)
    s.initialize(start_time, stop)     # setupExperiment + enter/exit initialisation mode
    s.bind(kind, inputs, outputs)      # once per kind ("Real", "Integer", "Boolean"): the master hands
                                       #   numpy buffers: inputs to write, outputs to fill
    loop:
        s.write_inputs()               # push the bound input buffers into the slave
        s.do_step(t, h)
        s.read_outputs()               # fill the bound output buffers
    s.terminate()                      # and free

Optional, for branching (FMUs with canGetAndSetFMUstate): ``get_state()`` / ``set_state(state)`` /
``free_state(state)`` between steps; after ``set_state`` the master reads the outputs again.

Optional, for the master's C loop (:class:`~ncfmu.cosim.native_loop.NativeSlave`, the FMUs):
``fmi2_functions()`` hands the component and the FMI function addresses (the loop then sets the inputs
itself), ``fmi2_failure(what, status)`` the error a failed call raises. The C loop runs only when every
slave offers both; a fake slave keeps the Python loop.

Buffers are float64 for Real and int32 for Integer and Boolean (FMI's fmi2Boolean is an int).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

KINDS = ("Real", "Integer", "Boolean")
DTYPES = {"Real": np.float64, "Integer": np.int32, "Boolean": np.int32}


@dataclass(frozen=True)
class Variable:
    """What the master needs to know of one FMU variable."""

    name: str
    type: str                 # Real, Integer, Boolean, String
    causality: str            # parameter, input, output, local, ...
    vr: int
    unit: str | None = None
    start: object = None
    description: str = ""
    variability: str = ""     # fixed, tunable, discrete, continuous ("" when the slave does not say)
    min: float | None = None  # the modelDescription's range (Real and Integer)
    max: float | None = None


class Slave(Protocol):
    name: str
    variables: dict[str, Variable]

    def set_start(self, name: str, value: object) -> None: ...
    def initialize(self, start_time: float, stop_time: float) -> None: ...
    def bind(self, kind: str, inputs: np.ndarray, input_vrs: list[int],
             outputs: np.ndarray, output_vrs: list[int]) -> None: ...
    def write_inputs(self) -> None: ...
    def do_step(self, t: float, h: float) -> None: ...
    def read_outputs(self) -> None: ...
    def terminate(self) -> None: ...


@runtime_checkable
class StatefulSlave(Slave, Protocol):
    """A slave that saves and restores its state (FMUs with canGetAndSetFMUstate): what branching needs."""

    def get_state(self) -> object: ...
    def set_state(self, state: object) -> None: ...
    def free_state(self, state: object) -> None: ...
