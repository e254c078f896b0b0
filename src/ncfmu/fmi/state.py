"""The serialized FMU state: plain data in a versioned format, tied to the FMU that wrote it.

``fmi2SerializeFMUstate`` bytes are one UTF-8 JSON document::

    {"format": "ncfmu-fmu-state", "version": 1, "model": "CutSequencer", "build": "<digest>",
     "parameters": {...}, "inputs": {...}, "logic": {<attribute>: <value>, ...} | null}

``build`` is the digest of the ncfmu copy the FMU carries (``resources/ncfmu_<digest>``), so a state
is accepted only by the same model of the same build. The FMU's binary appends the state's phase and time
(:mod:`.contract`) and seals the whole as every ncfmu FMU state is (:mod:`.sealed_state`: a format version, the
FMI version and the model that made it, a CRC-32): what reaches :func:`loads` passed the seal.

Values are JSON; what JSON cannot say is tagged:
``{"f": "nan"|"inf"|"-inf"}`` for non-finite floats, ``{"t": [...]}`` for tuples, ``{"d": [[k, v], ...]}``
for dicts whose keys are not all strings, ``{"a": [...], "dtype": ..., "shape": [...]}`` for numpy arrays
and ``{"o": "controllers.motion:LinearMove", "v": {...}}`` for objects of ncfmu's own classes.

Loading runs no code from the bytes: nothing is imported, no constructor, ``__reduce__`` or
``__setstate__`` is called. An object tag names a class by module and name inside the FMU's own
ncfmu package, among the modules already loaded; the object is created empty (``object.__new__``)
and its attributes filled with decoded plain data. The controller itself is rebuilt from the saved
parameters (its ``configure()`` checks them) before its dynamic attributes are restored; attributes
it lists in ``DERIVED`` (python-control models, rebuilt from the parameters) are not saved.

Restoring checks every value, not only the names (see "checking" below): the freshly built controller is
the template for the saved attributes, inputs and outputs keep their ports' types and rules, the
controller judges its own registers (``Controller.check_state``), and one step of a copy must run sanely.
Whatever breaks a rule, and whatever error decoding or checking meets, is a :class:`StateError` naming the
field; no other exception leaves :func:`loads`.
"""

from __future__ import annotations

import copy
import dataclasses
import json
import math
import sys
import types
import typing
from collections.abc import Callable, Mapping
from functools import cached_property
from typing import TYPE_CHECKING, Any

from ..controllers.base import POSITION_LIMIT, SPEED_LIMIT
from ..controllers.mypyc_compat import attributes, blank, blankable, set_attributes
from ..errors import ConfigError, NcfmuError
from ..ports import Port

if TYPE_CHECKING:
    from ..controllers.base import Controller

try:     # numpy is optional: the controller FMUs run on the standard library alone
    import numpy as np
    HAVE_NUMPY = True
except ImportError:  # pragma: no cover - exercised where numpy is absent
    HAVE_NUMPY = False
_NP_BOOL: tuple[type[np.bool_], ...] = (np.bool_,) if HAVE_NUMPY else ()
_NP_ARRAY: tuple[type[np.ndarray], ...] = (np.ndarray,) if HAVE_NUMPY else ()
_INTEGERS: tuple[type[int] | type[np.integer], ...] = (int, np.integer) if HAVE_NUMPY else (int,)
_FLOATS: tuple[type[float] | type[np.floating], ...] = (float, np.floating) if HAVE_NUMPY else (float,)

FORMAT = "ncfmu-fmu-state"
VERSION = 1
#: Numpy dtypes a state may hold (the servo's loop states and discretisations).
_DTYPES = {"float64", "int64", "bool"}
#: Bytes above this are refused before parsing: a state is a few kB to a few hundred kB.
MAX_STATE_BYTES = 16 * 1024 * 1024
_PACKAGE = __name__.rsplit(".", 2)[0]          # "ncfmu", or the FMU's copy "ncfmu_<digest>"


class StateError(NcfmuError, ValueError):
    """Bytes that are not a state of this FMU (garbage, another format or version, another model or build)."""


def build_digest(package: str = _PACKAGE) -> str:
    """The digest of the ncfmu copy this code runs from ("dev" outside a built FMU)."""
    prefix = "ncfmu_"
    return package[len(prefix):] if package.startswith(prefix) else "dev"


# -- encoding -------------------------------------------------------------------------------------
def _encode(value: Any, where: str) -> Any:
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, _INTEGERS) and not isinstance(value, _NP_BOOL):
        return int(value)
    if isinstance(value, _FLOATS):
        x = float(value)
        return x if math.isfinite(x) else {"f": repr(x)}
    if isinstance(value, _NP_BOOL):
        return bool(value)
    if isinstance(value, list):
        return [_encode(v, f"{where}[{i}]") for i, v in enumerate(value)]
    if isinstance(value, tuple):
        return {"t": [_encode(v, f"{where}[{i}]") for i, v in enumerate(value)]}
    if isinstance(value, dict):
        if all(isinstance(k, str) for k in value):
            if any(k in ("f", "t", "d", "a", "o") for k in value) and len(value) <= 3:
                return {"d": [[k, _encode(v, f"{where}[{k!r}]")] for k, v in value.items()]}
            return {k: _encode(v, f"{where}[{k!r}]") for k, v in value.items()}
        return {"d": [[_encode(k, where), _encode(v, f"{where}[{k!r}]")] for k, v in value.items()]}
    if isinstance(value, _NP_ARRAY):
        if value.dtype.name not in _DTYPES:
            raise StateError(f"{where}: numpy dtype {value.dtype} cannot be saved")
        return {"a": [_encode(v, where) for v in value.ravel().tolist()], "dtype": value.dtype.name,
                "shape": list(value.shape)}
    cls = type(value)
    module = cls.__module__
    if module == _PACKAGE or module.startswith(_PACKAGE + "."):
        derived = set(getattr(cls, "DERIVED", ()))
        # sorted: a compiled controller lists its attributes in another order than the pure one's __dict__
        attrs = {k: _encode(v, f"{where}.{k}") for k, v in sorted(attributes(value).items()) if k not in derived}
        return {"o": f"{module[len(_PACKAGE) + 1:]}:{cls.__qualname__}", "v": attrs}
    raise StateError(f"{where}: a {cls.__module__}.{cls.__qualname__} cannot be saved")


def dumps(model: str, parameters: Mapping[str, object], inputs: Mapping[str, object], logic: object) -> bytes:
    """The state of one FMU instance as bytes (see the module docstring)."""
    doc = {"format": FORMAT, "version": VERSION, "model": model, "build": build_digest(),
           "parameters": _encode(dict(parameters), "parameters"), "inputs": _encode(dict(inputs), "inputs"),
           "logic": None if logic is None else _encode(logic, "logic")["v"]}
    return json.dumps(doc, separators=(",", ":"), allow_nan=False).encode("utf-8")


# -- decoding -------------------------------------------------------------------------------------
def _class(tag: str) -> type:
    rel, _, name = tag.partition(":")
    if not rel or not name or not all(part.isidentifier() for part in rel.split(".")) or not name.isidentifier():
        raise StateError(f"object tag {tag!r} is not 'module:Class'")
    module = sys.modules.get(f"{_PACKAGE}.{rel}")      # only modules already loaded: nothing is imported
    cls = getattr(module, name, None) if module is not None and not name.startswith("_") else None
    if module is None or not isinstance(cls, type) or cls.__module__ != module.__name__:
        raise StateError(f"object tag {tag!r} names no class of this FMU")
    # an empty object of a class with its own construction (an exception, a builtin subclass) is no state
    if not blankable(cls):
        raise StateError(f"object tag {tag!r} names a class whose objects are no state")
    return cls


def _decode(tree: Any, where: str) -> Any:
    if tree is None or isinstance(tree, (bool, int, float, str)):
        return tree
    if isinstance(tree, list):
        return [_decode(v, where) for v in tree]
    if not isinstance(tree, dict):
        raise StateError(f"{where}: unexpected {type(tree).__name__}")
    if len(tree) == 1 and "f" in tree:
        if tree["f"] not in ("nan", "inf", "-inf"):
            raise StateError(f"{where}: {tree['f']!r} is not a non-finite float")
        return float(tree["f"])
    if len(tree) == 1 and "t" in tree and isinstance(tree["t"], list):
        return tuple(_decode(v, where) for v in tree["t"])
    if len(tree) == 1 and "d" in tree and isinstance(tree["d"], list):
        out = {}
        for pair in tree["d"]:
            if not (isinstance(pair, list) and len(pair) == 2):
                raise StateError(f"{where}: a dict entry is not a [key, value] pair")
            key = _decode(pair[0], where)
            try:
                hash(key)
            except TypeError:
                raise StateError(f"{where}: a dict key {key!r} is unhashable") from None
            out[key] = _decode(pair[1], where)
        return out
    if set(tree) == {"a", "dtype", "shape"}:
        if not HAVE_NUMPY:
            raise StateError(f"{where}: a numpy array, and numpy is not available here")
        if tree["dtype"] not in _DTYPES or not isinstance(tree["a"], list) or not isinstance(tree["shape"], list):
            raise StateError(f"{where}: malformed array")
        try:
            return np.array([_decode(v, where) for v in tree["a"]], dtype=tree["dtype"]).reshape(tree["shape"])
        except (TypeError, ValueError) as err:
            raise StateError(f"{where}: malformed array: {err}") from None
    if set(tree) == {"o", "v"} and isinstance(tree["o"], str) and isinstance(tree["v"], dict):
        cls = _class(tree["o"])
        obj = blank(cls)
        for k, v in tree["v"].items():
            value = _decode(v, f"{where}.{k}")
            try:
                set_attributes(obj, {str(k): value})
            except AttributeError:                    # a compiled (native) class has its fields only
                raise StateError(f"{where}: {str(k)!r} is no attribute of a {cls.__name__}") from None
            except TypeError:                         # ... each of its declared type
                raise StateError(f"{where}.{k} = {_text(value)}: a {_kind(value)}, not what a {cls.__name__} "
                                 "holds there") from None
        return obj
    return {str(k): _decode(v, f"{where}[{k!r}]") for k, v in tree.items()}


# -- checking: a decoded state against a controller freshly built from its parameters -----------------
# The fresh controller is the template: the saved state must hold the same attributes, those configure()
# derives from the parameters identical to the fresh ones, the others of the same types and structure,
# recursively (objects of the same classes, dicts with the same keys, fixed-length lists as long). Where
# the fresh controller holds nothing to compare with (None, an empty list), a value must be plain data or
# objects of ncfmu's dataclasses whose fields have their declared types; what it means is the controller's
# to judge (``Controller.check_state``).
def _text(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _kind(value: Any) -> str:
    return type(value).__name__


def _cached(cls: type) -> set[str]:
    """Names of the class's cached properties: an object may hold their values (computed) or not yet."""
    return {k for c in cls.__mro__ for k, v in vars(c).items() if isinstance(v, cached_property)}


def _identical(a: Any, b: Any) -> bool:
    """Equal values of the same types, recursively (``1 == 1.0 == True`` is not enough; NaN equals NaN)."""
    if type(a) is not type(b):
        return False
    if isinstance(a, float):
        return a == b or (math.isnan(a) and math.isnan(b))
    if a is None or isinstance(a, (bool, int, str)):
        return bool(a == b)
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(_identical(x, y) for x, y in zip(a, b))
    if isinstance(a, dict):
        return ({(type(k), k) for k in a} == {(type(k), k) for k in b}
                and all(_identical(a[k], b[k]) for k in a))
    if isinstance(a, _NP_ARRAY):
        return a.dtype == b.dtype and a.shape == b.shape and bool(np.array_equal(a, b, equal_nan=True))
    va, vb = attributes(a), attributes(b)
    cached = _cached(type(a))
    if any(k not in cached for k in va.keys() ^ vb.keys()):
        return False
    fields = [k for k in va if k in vb and k not in cached]
    if not all(_identical(va[k], vb[k]) for k in fields):
        return False
    # a cached value is what its property computes from the fields (checked equal just above)
    return all(_identical(getattr(a, k), getattr(b, k)) for k in cached if k in va or k in vb)


def _number(value: Any, template: float, where: str) -> None:
    if math.isnan(value):
        raise StateError(f"{where} = nan: must be finite")
    if math.isinf(value) and math.isfinite(template):
        raise StateError(f"{where} = {value!r}: must be finite")


def _conform(value: Any, template: Any, where: str) -> None:
    """``value`` has the type and the structure of ``template`` (see above), else StateError naming it."""
    if template is None or (isinstance(template, (list, tuple)) and not template):
        if template is not None and type(value) is not type(template):
            raise StateError(f"{where}: a {_kind(value)}, not a {_kind(template)}")
        _plain(value, where)
        return
    if type(value) is not type(template):
        raise StateError(f"{where} = {_text(value)}: a {_kind(value)}, not a {_kind(template)}")
    if isinstance(value, float):
        _number(value, template, where)
    elif isinstance(value, (list, tuple)):
        if len(value) != len(template):
            raise StateError(f"{where}: {len(value)} items, not {len(template)}")
        for i, (v, t) in enumerate(zip(value, template)):
            _conform(v, t, f"{where}[{i}]")
    elif isinstance(value, dict):
        if {(type(k), k) for k in value} != {(type(k), k) for k in template}:
            raise StateError(f"{where}: keys {_text(list(value))}, not {_text(list(template))}")
        for k, t in template.items():
            _conform(value[k], t, f"{where}[{k!r}]")
    elif isinstance(value, _NP_ARRAY):
        if value.dtype != template.dtype or value.shape != template.shape:
            raise StateError(f"{where}: a {value.dtype} array of shape {value.shape}, not {template.dtype} "
                             f"{template.shape}")
        if value.dtype.kind == "f" and not np.isfinite(value).all():
            raise StateError(f"{where}: must be finite")
    elif not isinstance(value, (bool, int, str)):
        va, vt = attributes(value), attributes(template)
        cached = _cached(type(value))
        if {k for k in va if k not in cached} != {k for k in vt if k not in cached}:
            raise StateError(f"{where}: attributes {sorted(va)}, not those of a {_kind(template)} {sorted(vt)}")
        for k, t in vt.items():
            if k in va and k not in cached:
                _conform(va[k], t, f"{where}.{k}")
        _cached_values(value, where)


def _cached_values(obj: Any, where: str) -> None:
    """A cached property's saved value is the one it computes from the object's fields."""
    cached = _cached(type(obj))
    for k in cached & set(vars(obj)) if cached else ():       # (a compiled controller has none, and no __dict__)
        saved = vars(obj).pop(k)
        if not _identical(saved, getattr(obj, k)):
            raise StateError(f"{where}.{k} = {_text(saved)}: not what the fields give ({_text(getattr(obj, k))})")


def _plain(value: Any, where: str) -> None:
    """Where the fresh controller holds nothing to compare with: plain data (no NaN), or objects of ncfmu's
    dataclasses with exactly their fields, each of its declared type."""
    if value is None or isinstance(value, (bool, int, str)):
        return
    if isinstance(value, float):
        if math.isnan(value):
            raise StateError(f"{where} = nan: must be a number")
    elif isinstance(value, (list, tuple)):
        for i, v in enumerate(value):
            _plain(v, f"{where}[{i}]")
    elif isinstance(value, dict):
        for k, v in value.items():
            _plain(k, f"{where} key")
            _plain(v, f"{where}[{k!r}]")
    elif dataclasses.is_dataclass(value) and not isinstance(value, type):
        cls = type(value)
        names = [f.name for f in dataclasses.fields(cls)]
        extra = set(vars(value)) - set(names) - _cached(cls)
        if extra or not all(n in vars(value) for n in names):
            raise StateError(f"{where}: attributes {sorted(vars(value))}, not the fields of a {cls.__name__} "
                             f"{names}")
        hints = typing.get_type_hints(cls)
        for n in names:
            _typed(vars(value)[n], hints[n], f"{where}.{n}")
        _cached_values(value, where)
    else:
        raise StateError(f"{where}: a {_kind(value)} is not state here")


def _typed(value: Any, hint: Any, where: str) -> None:
    """``value`` of the declared type ``hint`` (the types ncfmu's dataclasses use)."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        for option in args:
            try:
                _typed(value, option, where)
                return
            except StateError:
                pass
        raise StateError(f"{where} = {_text(value)}: a {_kind(value)}, not a {hint}")
    if origin is tuple:
        if type(value) is not tuple:
            raise StateError(f"{where} = {_text(value)}: a {_kind(value)}, not a tuple")
        items = args[:1] * len(value) if len(args) == 2 and args[1] is Ellipsis else args
        if len(items) != len(value):
            raise StateError(f"{where}: {len(value)} items, not {len(items)}")
        for i, (v, h) in enumerate(zip(value, items)):
            _typed(v, h, f"{where}[{i}]")
        return
    if hint is type(None):
        if value is not None:
            raise StateError(f"{where} = {_text(value)}: must be None")
        return
    if not isinstance(hint, type) or type(value) is not hint:
        raise StateError(f"{where} = {_text(value)}: a {_kind(value)}, not a {getattr(hint, '__name__', hint)}")
    if isinstance(value, float) and not math.isfinite(value):
        raise StateError(f"{where} = {value!r}: must be finite")
    if dataclasses.is_dataclass(value):
        _plain(value, where)


def _port_value(port: Port, value: Any, where: str) -> None:
    """A value of the port's FMI type (a Real a finite float, an Integer an int, a Boolean a bool)."""
    want = {"Real": float, "Integer": int, "Boolean": bool, "String": str}[port.type]
    if type(value) is not want:
        raise StateError(f"{where} = {_text(value)}: a {_kind(value)}, not a {port.type}")
    if isinstance(value, float) and not math.isfinite(value):
        raise StateError(f"{where} = {value!r}: must be finite")
    if isinstance(value, int) and not -2 ** 31 <= value < 2 ** 31:
        raise StateError(f"{where} = {_text(value)}: beyond the range of an fmi2Integer")


def _check_inputs(logic_class: type[Controller], inputs: dict[str, object]) -> None:
    """Every input of its port's type and rule; positions within reach."""
    for port in logic_class.ports("input"):
        value: Any = inputs[port.name]
        if port.type == "Boolean" and type(value) is int and value in (0, 1):
            continue                                   # the FMI Boolean a host wrote as 0/1
        _port_value(port, value, f"inputs.{port.name}")
        if port.min is not None or port.max is not None or port.allowed is not None:
            try:
                port.check(value)
            except ConfigError as err:
                raise StateError(f"inputs.{err}") from None
        if port.unit == "mm" and abs(value) > POSITION_LIMIT:
            raise StateError(f"inputs.{port.name} = {value!r}: beyond {POSITION_LIMIT:g} mm, no axis is that long")
        if port.unit == "mm/s" and abs(value) > SPEED_LIMIT:
            raise StateError(f"inputs.{port.name} = {value!r}: faster than {SPEED_LIMIT:g} mm/s, no axis moves so")


def _check_outputs(logic_class: type[Controller], outputs: Any, where: str) -> None:
    ports = logic_class.ports("output")
    if not isinstance(outputs, dict) or set(outputs) != {p.name for p in ports}:
        raise StateError(f"{where}: not the outputs of {logic_class.MODEL_NAME}")
    for port in ports:
        _port_value(port, outputs[port.name], f"{where}[{port.name!r}]")
        if port.unit == "mm" and abs(outputs[port.name]) > POSITION_LIMIT:
            raise StateError(f"{where}[{port.name!r}] = {outputs[port.name]!r}: beyond {POSITION_LIMIT:g} mm")
        if port.unit == "mm/s" and abs(outputs[port.name]) > SPEED_LIMIT:
            raise StateError(f"{where}[{port.name!r}] = {outputs[port.name]!r}: faster than {SPEED_LIMIT:g} mm/s")


def _configured(logic_class: type[Controller], parameters: Mapping[str, object]) -> set[str]:
    """The attributes configure() derives from the parameters (before reset() adds the dynamic ones)."""
    probe: Any = blank(logic_class)
    probe.messages = []
    probe.configure(logic_class.check_parameters(parameters))
    return set(attributes(probe)) - {"messages"}


def _dry_step(logic: Controller, inputs: dict[str, object]) -> None:
    """One step of a copy, on the state's own inputs: it runs, its outputs are of their port types, finite, and
    no position command moves faster than any axis (``SPEED_LIMIT``) -- unless onto the axis's actual position
    (a follow-up re-bases the command there)."""
    dry = copy.deepcopy(logic)
    before = dict(dry.outputs())
    dt = type(logic).PERIOD
    try:
        after = dry.step(0.0, dt, dict(inputs))
    except Exception as err:
        raise StateError(f"logic: a step from this state fails ({type(err).__name__}: {err})") from None
    _check_outputs(type(logic), after, "logic: a step from this state gives the output")
    for name, value in after.items():
        actual = inputs.get(name[:-len("_cmd")] + "_pos")
        if name.endswith("_cmd") and abs(value - before[name]) > SPEED_LIMIT * dt + 1e-9 and value != actual:  # type: ignore[operator]
            raise StateError(f"logic: a step from this state moves {name} {before[name]!r} -> {value!r} in {dt:g} s: "
                             f"faster than {SPEED_LIMIT:g} mm/s, no axis moves so")


def _restore_logic(logic: Controller, saved: Mapping[str, Any], parameters: Mapping[str, object],
                   inputs: dict[str, object]) -> None:
    """Fill the freshly built ``logic`` with the saved attributes, each checked against its fresh value."""
    cls = type(logic)
    model = cls.MODEL_NAME
    attrs = {str(k): _decode(v, f"logic.{k}") for k, v in saved.items()}
    fresh = attributes(logic)
    expected = set(fresh) - set(getattr(cls, "DERIVED", ()))
    if set(attrs) != expected:
        unknown, missing = sorted(set(attrs) - expected), sorted(expected - set(attrs))
        raise StateError(f"logic: attributes {unknown} are not state of {model}" if unknown else
                         f"logic: attributes {missing} of {model} are missing")
    configured = _configured(cls, parameters)
    for name, value in attrs.items():
        if name in configured:
            if not _identical(value, fresh[name]):
                raise StateError(f"logic.{name} = {_text(value)}: not {_text(fresh[name])}, what the parameters give")
        else:
            _conform(value, fresh[name], f"logic.{name}")
    _check_outputs(cls, attrs.get("_outputs"), "logic._outputs")
    set_attributes(logic, attrs)
    why = logic.check_state(inputs)
    if why:
        raise StateError(f"logic.{why}")
    _dry_step(logic, inputs)


def loads(data: bytes, logic_class: type[Controller], build_logic: Callable[[dict[str, object]], Controller]
          ) -> tuple[Controller | None, dict[str, object], dict[str, object]]:
    """Check ``data`` against this FMU and decode it: ``(logic, parameters, inputs)``.

    ``build_logic(parameters)`` rebuilds the controller from the saved parameters; its dynamic
    attributes are then restored from the state, each checked (see "checking" above, and the
    controller's own ``check_state``), and one step of a copy must run sanely.

    Raises
    ------
    StateError
        for anything that is not a state of this model and build, or a value it carries that breaks its
        rule (the message names the field); ConfigError for a saved parameter that breaks its port's rule.
        No other exception leaves this function.
    """
    try:
        return _loads(data, logic_class, build_logic)
    except (StateError, ConfigError):
        raise
    except RecursionError:
        raise StateError("nested too deeply to be a state") from None
    except Exception as err:             # a value no rule above foresaw: refused, never passed to the host
        raise StateError(f"not a usable state ({type(err).__name__}: {_text(str(err))})") from None


def _loads(data: bytes, logic_class: type[Controller], build_logic: Callable[[dict[str, object]], Controller]
           ) -> tuple[Controller | None, dict[str, object], dict[str, object]]:
    if len(data) > MAX_STATE_BYTES:
        raise StateError(f"{len(data)} bytes: larger than any state ({MAX_STATE_BYTES} bytes)")
    try:
        doc = json.loads(bytes(data).decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError):
        raise StateError(f"not an ncfmu FMU state ({len(data)} bytes that are not its JSON format)") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise StateError("not an ncfmu FMU state (no 'format': 'ncfmu-fmu-state')")
    if doc.get("version") != VERSION:
        raise StateError(f"state format version {doc.get('version')!r}; this FMU reads version {VERSION}")
    model = logic_class.MODEL_NAME
    if doc.get("model") != model:
        raise StateError(f"a state of {doc.get('model')!r}, not of this {model!r} FMU")
    if doc.get("build") != build_digest():
        raise StateError(f"a state of build {doc.get('build')!r}; this FMU is build {build_digest()!r}")
    parameters, inputs = _decode(doc.get("parameters"), "parameters"), _decode(doc.get("inputs"), "inputs")
    saved = doc.get("logic")
    if not isinstance(parameters, dict) or not isinstance(inputs, dict) or not isinstance(saved, (dict, type(None))):
        raise StateError("parameters, inputs or logic missing")
    if set(parameters) != set(logic_class.default_parameters()) or set(inputs) != set(logic_class.default_inputs()):
        raise StateError(f"parameters or inputs are not those of {model}")
    for port in logic_class.ports("parameter"):
        if port.type == "Boolean" and type(parameters[port.name]) is int and parameters[port.name] in (0, 1):
            continue
        want = {"Real": (float, int), "Integer": (int,), "Boolean": (bool,), "String": (str,)}[port.type]
        if type(parameters[port.name]) not in want:
            raise StateError(f"parameters.{port.name} = {_text(parameters[port.name])}: a "
                             f"{_kind(parameters[port.name])}, not a {port.type}")
    _check_inputs(logic_class, inputs)
    if saved is None:                     # saved before exitInitializationMode: checked when it is left
        return None, parameters, inputs
    logic = build_logic(parameters)
    parameters = logic_class.check_parameters(parameters)          # each as its port's type (as the FMU holds it)
    _restore_logic(logic, saved, parameters, inputs)
    return logic, parameters, inputs
