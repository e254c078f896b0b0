"""One generic adapter from a :class:`~ncfmu.controllers.base.Controller` to ``pythonfmu.Fmi2Slave``.

A model script in ``models/`` is three lines::

    @fmu_slave(CutSequencerLogic)
    class CutSequencer(Fmi2Slave):
        \"\"\"Lathe repetitive-cut sequencer.\"\"\"

The decorator returns a :class:`ControllerSlave` subclass that registers every port of the
controller (declared once, as data), builds and checks the controller at
``exitInitializationMode`` and steps it in ``doStep``. Messages the controller queues go to the FMU
log with their level.

The FMU's binary (``fmi/c/python_model.c``) calls the ``fmi_*`` methods of :class:`ControllerSlave` and nothing
else: the contract is the table in :mod:`ncfmu.fmi.contract`, described in ``docs/architecture.md``.
"""

from __future__ import annotations

import copy
import traceback
from collections.abc import Callable, Mapping

from pythonfmu import Boolean, Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real, String
from pythonfmu.default_experiment import DefaultExperiment
from pythonfmu.enums import Fmi2Status

from ..controllers.base import Controller
from ..errors import ConfigError
from ..ports import Port
from . import state as state_format
from .contract import CAUSALITY, STATUS, TYPE

_TYPES = {"Real": Real, "Integer": Integer, "Boolean": Boolean, "String": String}
_CAUSALITY = {"parameter": Fmi2Causality.parameter, "input": Fmi2Causality.input, "output": Fmi2Causality.output}
_VARIABILITY = {"fixed": Fmi2Variability.fixed, "tunable": Fmi2Variability.tunable,
                "discrete": Fmi2Variability.discrete, "continuous": Fmi2Variability.continuous}
_LEVEL = {"info": Fmi2Status.ok, "warning": Fmi2Status.warning, "error": Fmi2Status.error}
_CONVERT = {"Real": float, "Integer": int, "Boolean": bool, "String": str}


class ControllerSlave(Fmi2Slave):
    """pythonfmu slave around a controller class (set ``logic_class`` in a subclass).

    The FMU's binary (``fmi/c/python_model.c``) drives it through the ``fmi_*`` methods below,
    and only those: the contract is the table in :mod:`ncfmu.fmi.contract`. Each returns its status
    (:data:`~ncfmu.fmi.contract.STATUS`) and never raises; what it has to say goes to the log queue,
    which the shim takes after every call (:meth:`fmi_take_log`).
    """

    logic_class: type[Controller]
    author = "ncfmu"
    license = "MIT"

    def __init__(self, **kwargs) -> None:
        super().__init__(**kwargs)
        logic = self.logic_class
        self.modelName = logic.MODEL_NAME
        self.description = logic.DESCRIPTION
        self.default_experiment = DefaultExperiment(start_time=0.0, stop_time=logic.STOP_TIME, step_size=logic.PERIOD)
        self.parameters: dict[str, object] = logic.default_parameters()
        self.inputs: dict[str, object] = logic.default_inputs()
        self.out: dict[str, object] = {p.name: p.default() for p in logic.ports("output")}
        self.logic: Controller | None = None
        self._refused = False             # a value fmi_set was given was refused (the old value kept)
        # What is logged and not yet taken: pythonfmu's queue (Fmi2Slave.log appends to it), the same list for the
        # slave's life; the shim reads its length after every call and calls fmi_take_log only when it is not empty.
        self.pending_log: list = self.log_queue
        for port in logic.PORTS:
            self._register(port)

    # -- the shim's entry points (ncfmu.fmi.contract.ENTRIES) -------------------------------------
    @classmethod
    def fmi_instantiate(cls, instance_name: str, resources: str, visible: bool) -> ControllerSlave:
        return cls(instance_name=instance_name, resources=resources, visible=bool(visible))

    def fmi_ports(self) -> tuple[tuple[int, int, int, bool, str], ...]:
        return tuple((vr, TYPE[type(v).__name__], CAUSALITY.get(v.causality.name.upper(), CAUSALITY["OTHER"]),
                      v.variability.name == "fixed", v.name) for vr, v in self.vars.items())

    def fmi_setup_experiment(self, start_time: float, stop_time: float | None, tolerance: float | None) -> int:
        return STATUS["OK"]

    def fmi_enter_initialization_mode(self) -> int:
        return STATUS["OK"]

    def fmi_exit_initialization_mode(self) -> int:
        try:
            self.logic = self.logic_class.from_parameters(self.parameters)
        except Exception as err:               # ConfigError names the rule; anything else is a value no rule foresaw
            text = err.in_words() if isinstance(err, ConfigError) else f"the parameters cannot be used: {err!r}"
            self.log(f"{self.instance_name}: parameter refused: {text}", Fmi2Status.error)
            return STATUS["ERROR"]             # the instance lives on: the host may reset and try again
        self.out = self.logic.outputs()
        self._flush()
        return STATUS["OK"]

    def fmi_do_step(self, current_time: float, step_size: float) -> int:
        if self.logic is None:
            self.log(f"{self.instance_name}: doStep refused: the parameters were refused at initialisation",
                     Fmi2Status.error)
            return STATUS["ERROR"]
        # Tools count time in integer nanoseconds (libcosim); their conversion to seconds can differ in
        # the last bit (1e6 ns -> 0.0010000000000000002 s). Whole nanoseconds make every tool's step equal.
        # (The shim's DoStep rounds so too before it calls fmi_stepper's step, as native_model.c does.)
        step_size = round(step_size * 1e9) * 1e-9
        try:
            queued = self.logic.step_then_count_messages(current_time, step_size, self.inputs)
        except Exception as err:                                  # a defect: say where, fail the step
            return self.fmi_step_report(current_time, err)
        return self.fmi_step_report(current_time, None) if queued else STATUS["OK"]

    def fmi_stepper(self) -> Callable[[float, float, Mapping[str, object]], int] | None:
        return None if self.logic is None else self.logic.step_then_count_messages

    def fmi_step_report(self, current_time: float, error: BaseException | None) -> int:
        if error is not None:
            trace = "".join(traceback.format_exception(type(error), error, error.__traceback__, limit=4))
            self.log(f"{self.instance_name}: doStep at t = {current_time:.6f} s failed: {error!r}\n{trace}",
                     Fmi2Status.error)
            return STATUS["ERROR"]
        if self.logic is not None:
            self._flush()
        return STATUS["OK"]

    def do_step(self, current_time: float, step_size: float) -> bool:
        """pythonfmu's abstract step (Fmi2Slave is an ABC); the shim calls :meth:`fmi_do_step`."""
        return self.fmi_do_step(current_time, step_size) == STATUS["OK"]

    def fmi_terminate(self) -> int:
        return STATUS["OK"]

    def fmi_get(self, vrs: list[int]) -> list[object]:
        return [self.vars[vr].getter() for vr in vrs]

    def fmi_set(self, vrs: list[int], values: list[object]) -> int:
        self._refused = False
        for vr, value in zip(vrs, values):
            self.vars[vr].setter(value)
        return STATUS["ERROR"] if self._refused else STATUS["OK"]

    # FMU state: the controller object holds every hidden state (registers, counters, program counter,
    # DDA, servo states, caches); a deep copy of it is the FMU state.
    def fmi_get_state(self) -> tuple:
        return copy.deepcopy((self.logic, self.parameters, self.inputs))

    def fmi_set_state(self, state: object, call: str) -> int:
        if not (isinstance(state, tuple) and len(state) == 3
                and (state[0] is None or isinstance(state[0], self.logic_class))):
            return self._refuse(call, "not a state of this FMU")
        if state[0] is None and self.logic is not None:
            return self._refuse(call, "a state taken before initialisation holds no controller: it "
                                "cannot be set into an initialised instance, which keeps its state (a reset "
                                "returns an instance to before initialisation)")
        logic, parameters, inputs = copy.deepcopy(state)      # the same state may be restored again
        # in place: the registered getters and setters hold these very dicts
        self.parameters.clear()
        self.parameters.update(parameters)
        self.inputs.clear()
        self.inputs.update(inputs)
        self.logic = logic
        self.out = logic.outputs() if logic is not None else self.out
        return STATUS["OK"]

    # Serialized: plain data in a versioned format tied to this model and build (fmi/state.py); no code
    # ever runs from the bytes a host hands us (pythonfmu's default is pickle).
    def fmi_serialize(self, state: tuple) -> bytes:
        logic, parameters, inputs = state
        return state_format.dumps(self.logic_class.MODEL_NAME, parameters, inputs, logic)

    def fmi_deserialize(self, data: bytes, call: str) -> tuple | None:
        try:
            return state_format.loads(data, self.logic_class, self.logic_class.from_parameters)
        except Exception as err:   # StateError names what is wrong; anything else is bytes no rule foresaw
            text = str(err) if isinstance(err, (state_format.StateError, ConfigError)) else repr(err)
            self._refuse(call, text)
            return None

    def fmi_take_log(self) -> list[tuple[int, str, str]]:
        queue = self.pending_log              # pythonfmu's Fmi2Slave.log appends LogMsg(status, category, msg)
        taken = [(int(m.status), str(m.category), str(m.msg)) for m in queue]
        queue.clear()                         # in place: the shim holds this list
        return taken

    def _refuse(self, call: str, why: str) -> int:
        self.log(f"{self.instance_name}: {call} refused: {why}", Fmi2Status.error)
        return STATUS["ERROR"]

    def _register(self, port: Port) -> None:
        store = {"parameter": self.parameters, "input": self.inputs}.get(port.causality)
        name, convert = port.name, _CONVERT[port.type]
        if store is None:
            getter = lambda: self.out[name]            # noqa: E731 -- looked up each call: self.out is rebound
            setter = None
        elif port.fmi_variability == "tunable":
            getter = lambda: store[name]               # noqa: E731

            def setter(value, store=store, name=name, convert=convert):
                old, store[name] = store[name], convert(value)
                if self.logic is not None and not self._retune(name):   # a tunable parameter set during the run
                    store[name] = old                                    # refused: the old value stays
        else:
            getter = lambda: store[name]               # noqa: E731

            def setter(value, store=store, name=name, convert=convert):
                store[name] = convert(value)
        var = _TYPES[port.type](name, causality=_CAUSALITY[port.causality],
                                variability=_VARIABILITY[port.fmi_variability],
                                description=port.description, getter=getter, setter=setter)
        self.register_variable(var, nested=False)

    def _retune(self, name: str) -> bool:
        """Apply a tunable parameter set during the run; False (logged, flagged for the shim) if refused."""
        try:
            assert self.logic is not None                         # the setters call this during the run only
            self.logic.retune(self.parameters)
            return True
        except Exception as err:
            self.log(f"{self.instance_name}: tunable parameter refused, the old value kept: {err}", Fmi2Status.error)
            self._refused = True                                  # fmi_set returns ERROR
            return False

    def _flush(self) -> None:
        assert self.logic is not None                             # called once the controller is built
        for level, text in self.logic.take_messages():
            self.log(f"{self.instance_name}: {text}", _LEVEL[level])


def fmu_slave(logic_class: type[Controller]):
    """Class decorator for a thin model script: make the class a :class:`ControllerSlave` of ``logic_class``."""

    def decorate(cls: type) -> type:
        namespace = {k: v for k, v in vars(cls).items() if k not in ("__dict__", "__weakref__")}
        namespace["logic_class"] = logic_class
        return type(cls.__name__, (ControllerSlave,), namespace)

    return decorate
