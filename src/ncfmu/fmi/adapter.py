"""One generic adapter from a :class:`~ncfmu.controllers.base.Controller` to ``pythonfmu.Fmi2Slave``.

A model script in ``models/`` is three lines::

    @fmu_slave(CutSequencerLogic)
    class CutSequencer(Fmi2Slave):
        \"\"\"Lathe repetitive-cut sequencer.\"\"\"

The decorator returns a :class:`ControllerSlave` subclass that registers every port of the
controller (declared once, as data), builds and checks the controller at
``exitInitializationMode`` and steps it in ``doStep``. Messages the controller queues go to the FMU
log with their level.
"""

from __future__ import annotations

import copy
import ctypes
import operator
import sys
import types
from pathlib import Path

from pythonfmu import Boolean, Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real, String
from pythonfmu.default_experiment import DefaultExperiment
from pythonfmu.enums import Fmi2Status

from ..controllers.base import Controller
from ..errors import ConfigError
from ..ports import Port
from . import state as state_format

_TYPES = {"Real": Real, "Integer": Integer, "Boolean": Boolean, "String": String}
_CAUSALITY = {"parameter": Fmi2Causality.parameter, "input": Fmi2Causality.input, "output": Fmi2Causality.output}
_VARIABILITY = {"fixed": Fmi2Variability.fixed, "tunable": Fmi2Variability.tunable,
                "discrete": Fmi2Variability.discrete, "continuous": Fmi2Variability.continuous}
_LEVEL = {"info": Fmi2Status.ok, "warning": Fmi2Status.warning, "error": Fmi2Status.error}
_CONVERT = {"Real": float, "Integer": int, "Boolean": bool, "String": str}


class ControllerSlave(Fmi2Slave):
    """pythonfmu slave around a controller class (set ``logic_class`` in a subclass)."""

    logic_class: type[Controller]
    _shim_present = False                 # set by __init__: the status shim turns refusals into fmi2Error
    _parked_refusal: str | None = None    # a refusal from a classmethod, for the next flag read
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
        self._init_refused = False
        self._call_refused = False        # the last FMU-state call was refused (read and cleared by the shim)
        self.step_failed = False          # a failed doStep: fmi2Error through the shim (not discard)
        resources = kwargs.get("resources")
        # pythonfmu 0.7 puts the FMU's resources folder on sys.path at every fmi2Instantiate and never takes it
        # out: one more entry per instance. Keep one (its builder removes exactly one after it built the
        # model description), drop the repeats: the entries stay bounded by the FMUs a process has loaded.
        if resources:
            repeats = [i for i, p in enumerate(sys.path) if p and Path(p) == Path(resources)][1:]
            for i in reversed(repeats):
                del sys.path[i]
        self._status_shim = bool(resources and sys.platform.startswith("linux")
                                 and Path(resources, "ncfmu_status_shim").is_file())
        type(self)._shim_present = self._status_shim
        for port in logic.PORTS:
            self._register(port)
        self._causality = {vr: (v.causality.name, type(v).__name__, v.name, v.variability.name)
                           for vr, v in self.vars.items()}
        self._fast_get: dict[tuple, object] = {}
        self._fast_set: dict[tuple, object] = {}
        # The status shim picks this instance up right after pythonfmu created it (fmi2Instantiate,
        # fmi2Reset) and then reads outputs and writes inputs straight from/into these dicts.
        fast = sys.modules.setdefault("_ncfmu_fast", types.ModuleType("_ncfmu_fast"))
        vars(fast)["last"] = self

    # -- fast paths for the calls a master makes every step ---------------------------------------
    # pythonfmu's generic get/set check every variable's type and call its getter one by one; a
    # master asks for the same value references every step, so a compiled accessor is cached per list.
    def _getter_for(self, vrs: list[int], kind: str):
        key = (kind, *vrs)
        fn = self._fast_get.get(key)
        if fn is None:
            info = [i for i in (self._causality.get(vr) for vr in vrs) if i is not None]
            if vrs and len(info) == len(vrs) and all(i[0] == "output" and i[1] == kind for i in info):
                pick = operator.itemgetter(*(i[2] for i in info))
                fn = (lambda: [pick(self.out)]) if len(vrs) == 1 else (lambda: list(pick(self.out)))
            else:
                fn = None
            self._fast_get[key] = fn
        return fn

    def _setter_for(self, vrs: list[int], kind: str):
        key = (kind, *vrs)
        fn = self._fast_set.get(key, False)
        if fn is False:
            info = [i for i in (self._causality.get(vr) for vr in vrs) if i is not None]
            if vrs and len(info) == len(vrs) and all(i[0] == "input" and i[1] == kind for i in info):
                names = tuple(i[2] for i in info)
                inputs = self.inputs

                def fn(values, names=names, inputs=inputs):
                    for name, value in zip(names, values):
                        inputs[name] = value
            else:
                fn = None
            self._fast_set[key] = fn
        return fn

    def get_real(self, vrs):
        fn = self._getter_for(vrs, "Real")
        return fn() if fn is not None else super().get_real(vrs)

    def get_integer(self, vrs):
        if len(vrs) == 1 and vrs[0] == INIT_REFUSED_VR:
            return [int(self._init_refused)]
        if len(vrs) == 1 and vrs[0] == CALL_REFUSED_VR:
            cls = type(self)
            parked, cls._parked_refusal = cls._parked_refusal, None
            if parked:
                self.log(f"{self.instance_name}: {parked}", Fmi2Status.error)
            refused, self._call_refused = self._call_refused or bool(parked), False
            return [int(refused)]
        fn = self._getter_for(vrs, "Integer")
        return fn() if fn is not None else super().get_integer(vrs)

    def get_boolean(self, vrs):
        fn = self._getter_for(vrs, "Boolean")
        return fn() if fn is not None else super().get_boolean(vrs)

    def set_real(self, vrs, values):
        fn = self._setter_for(vrs, "Real")
        return fn(values) if fn is not None else super().set_real(vrs, values)

    def set_integer(self, vrs, values):
        fn = self._setter_for(vrs, "Integer")
        return fn(values) if fn is not None else super().set_integer(vrs, values)

    def set_boolean(self, vrs, values):
        fn = self._setter_for(vrs, "Boolean")
        return fn(values) if fn is not None else super().set_boolean(vrs, values)

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

    # -- FMI life cycle -------------------------------------------------------------------------
    def exit_initialization_mode(self) -> None:
        try:
            self.logic = self.logic_class.from_parameters(self.parameters)
        except Exception as err:               # ConfigError names the rule; anything else is a value no rule foresaw
            text = str(err) if isinstance(err, ConfigError) else f"the parameters cannot be used: {err!r}"
            self.log(f"{self.instance_name}: parameter refused: {text}", Fmi2Status.error)
            if self._status_shim:
                self._init_refused = True      # the shim turns this into fmi2Error; the instance lives on
                return
            raise
        self.out = self.logic.outputs()
        self._flush()

    def _retune(self, name: str) -> bool:
        """Apply a tunable parameter set during the run; False (logged, flagged for the shim) if refused."""
        try:
            assert self.logic is not None                         # the setters call this during the run only
            self.logic.retune(self.parameters)
            return True
        except Exception as err:
            self.log(f"{self.instance_name}: tunable parameter refused, the old value kept: {err}", Fmi2Status.error)
            if not self._status_shim:
                raise
            self._call_refused = True                             # the shim returns fmi2Error
            return False

    # -- FMU state: the controller object holds every hidden state (registers, counters, program
    # counter, DDA, servo states, caches); a deep copy of it is the FMU state.
    def _get_fmu_state(self):
        return copy.deepcopy((self.logic, self.parameters, self.inputs))

    def _set_fmu_state(self, state) -> None:
        if not (isinstance(state, tuple) and len(state) == 3
                and (state[0] is None or isinstance(state[0], self.logic_class))):
            self._refuse_state_call("fmi2SetFMUstate", "not a state of this FMU (a refused or foreign state)")
            return
        logic, parameters, inputs = copy.deepcopy(state)      # the same state may be restored again
        # in place: the registered getters and setters hold these very dicts
        self.parameters.clear()
        self.parameters.update(parameters)
        self.inputs.clear()
        self.inputs.update(inputs)
        self.logic = logic
        self.out = logic.outputs() if logic is not None else self.out

    # Serialized: plain data in a versioned format tied to this model and build (fmi/state.py); no code
    # ever runs from the bytes a host hands us (pythonfmu's default is pickle). pythonfmu calls these two
    # on the class, not the instance; a refusal is therefore parked on the class and picked up by the
    # instance when the shim asks, right after the call, in the same thread.
    @classmethod
    def _fmu_state_to_bytes(cls, state) -> bytes:
        logic, parameters, inputs = state
        return state_format.dumps(cls.logic_class.MODEL_NAME, parameters, inputs, logic)

    @classmethod
    def _fmu_state_from_bytes(cls, data: bytes):
        try:
            return state_format.loads(data, cls.logic_class, cls.logic_class.from_parameters)
        except (state_format.StateError, ConfigError) as err:
            if not cls._shim_present:
                raise                            # pythonfmu alone: its fmi2Fatal is all it can say
            cls._parked_refusal = f"fmi2DeSerializeFMUstate refused: {err}"
            return None

    def _refuse_state_call(self, call: str, why: str) -> None:
        """Log why; the shim reads the flag after the call and returns fmi2Error (the instance lives on)."""
        self.log(f"{self.instance_name}: {call} refused: {why}", Fmi2Status.error)
        self._call_refused = True
        if not self._status_shim:
            raise state_format.StateError(why)

    def do_step(self, current_time: float, step_size: float) -> bool:
        if self.logic is None:
            self.log(f"{self.instance_name}: doStep refused: the parameters were refused at initialisation",
                     Fmi2Status.error)
            self.step_failed = True
            return False
        # Tools count time in integer nanoseconds (libcosim); their conversion to seconds can differ in
        # the last bit (1e6 ns -> 0.0010000000000000002 s). Whole nanoseconds make every tool's step equal.
        step_size = round(step_size * 1e9) * 1e-9
        try:
            self.logic.step(current_time, step_size, self.inputs)
        except Exception as err:                                  # a defect: say where, fail the step
            import traceback
            self.log(f"{self.instance_name}: doStep at t = {current_time:.6f} s failed: {err!r}\n"
                     f"{traceback.format_exc(limit=4)}", Fmi2Status.error)
            self.step_failed = True
            return False
        if self.logic.messages:
            self._flush()
        return True

    def _flush(self) -> None:
        assert self.logic is not None                             # called once the controller is built
        for level, text in self.logic.take_messages():
            self.log(f"{self.instance_name}: {text}", _LEVEL[level])


#: Reserved Integer value reference: 1 when exitInitializationMode refused the parameters. The FMU's
#: status shim (builder.status_shim) reads it and returns fmi2Error instead of pythonfmu's fmi2Fatal.
INIT_REFUSED_VR = 2147483000
#: Reserved Integer value reference: 1 once when the last FMU-state call was refused (read clears it).
CALL_REFUSED_VR = 2147483001


def fmu_slave(logic_class: type[Controller]):
    """Class decorator for a thin model script: make the class a :class:`ControllerSlave` of ``logic_class``.

    It also works around a defect of pythonfmu 0.7's native loader: on every ``fmi2Instantiate`` it
    re-executes the model script and then releases one reference to the module's globals that it
    never owned (``PyModule_GetDict`` returns a borrowed reference). After a few instantiations of
    the same FMU in one process -- two servo axes, a sweep -- the module's namespace would be freed
    under it (a crash, or "Failed to instantiate"). The script runs this decorator once per
    instantiation, so each run takes one reference of its own to give pythonfmu's release. The
    references are owned by nobody (``Py_IncRef``), not kept in a list inside the namespace: such a
    list, freed while the interpreter tears the module down, released them all at once and freed the
    namespace while it was being cleared (heap corruption at exit, seen intermittently). Over-counting
    by one (the first import) only keeps the namespace to the end of the process.
    """

    def decorate(cls: type) -> type:
        module_globals = sys.modules[cls.__module__].__dict__
        ctypes.pythonapi.Py_IncRef(ctypes.py_object(module_globals))
        namespace = {k: v for k, v in vars(cls).items() if k not in ("__dict__", "__weakref__")}
        namespace["logic_class"] = logic_class
        return type(cls.__name__, (ControllerSlave,), namespace)

    return decorate
