"""The small slave interface the master depends on: its call order, its error contract, its capabilities.

Call order, for every slave (the master keeps to it; ``tests/fakes.py`` has a fake slave that checks it)::

    s = make_slave(...)                # instantiated; s.variables known, s.messages empty
    s.set_start(name, value) ...       # parameters and start values (before initialisation)
    s.initialize(start_time, stop)     # setupExperiment + enter/exit initialisation mode
    s.bind(kind, inputs, outputs)      # once per kind ("Real", "Integer", "Boolean"): the master hands
                                       #   numpy buffers: inputs to write, outputs to fill
    loop:
        s.write_inputs()               # push the bound input buffers into the slave
        s.do_step(t, h)                # t continues from the last step's end (or a restored state's time)
        s.read_outputs()               # fill the bound output buffers
        s.set_start(name, value)       # between steps: a tunable parameter or an input not bound
    s.terminate()                      # and free

Error contract (libcosim's ``slave.hpp`` in Python): a value the slave refuses (a start value, a tunable
parameter during the run) raises :class:`~ncfmu.errors.ConfigError` naming the variable, the value and the rule,
and the slave is unchanged; a call the slave fails (an FMU's fmi2Error or fmi2Fatal) raises
:class:`~ncfmu.errors.SimulationError` naming the instance, the call and the time, and the run ends there; nothing
else escapes. An FMU that asks to end the simulation raises the SimulationError
:class:`~ncfmu.errors.TerminationRequested` from ``do_step`` (with how far it got): the run ends cleanly at the
step's start, or at its end when the FMU made the step whole before it asked (the step then done for the other
slaves and recorded, as fmpy and fmusim record that point); ``forget_sent_inputs()`` of a native slave makes its
next ``write_inputs`` send every input again (the C loop had set them). What the
slave said (its FMU's log) is in ``messages``, ``(level, text)`` pairs in order, kept until
:meth:`ResettableSlave.reset`.

Optional capabilities, each a protocol the master checks with ``isinstance`` before it relies on it:

- :class:`StatefulSlave` -- ``get_state()`` / ``set_state(state)`` / ``free_state(state)`` between steps (FMUs with
  canGetAndSetFMUstate): branching; after ``set_state`` the master reads the outputs again;
- :class:`ResettableSlave` -- ``reset()`` back to the instantiated state (fmi2Reset): sweeps and a session's Reset;
- :class:`ReadableSlave` -- ``get(name)`` of any variable: a session's value of a variable it does not bind;
- :class:`~ncfmu.cosim.native_loop.NativeSlave` -- ``fmi2_functions()`` hands the component and the FMI function
  addresses (the C loop then sets the inputs itself), ``fmi2_failure(what, status)`` the error a failed call
  raises. The C loop runs only when every slave offers it; a fake slave keeps the Python loop.

Buffers are float64 for Real and int32 for Integer and Boolean (FMI's fmi2Boolean is an int).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from .units import Unit

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
    unit_definition: Unit | None = None   # the unit with its SI exponents, factor and offset, where defined


class Slave(Protocol):
    name: str
    variables: dict[str, Variable]
    #: what the slave said, ``(level, text)`` in order (level: ok/info, warning, error, fatal)
    messages: list[tuple[str, str]]

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


@runtime_checkable
class ResettableSlave(Slave, Protocol):
    """A slave that goes back to its instantiated state (fmi2Reset): start values and initialisation again."""

    def reset(self) -> None: ...


@runtime_checkable
class ReadableSlave(Slave, Protocol):
    """A slave whose any variable can be read by name (not only the bound outputs)."""

    def get(self, name: str) -> object: ...
