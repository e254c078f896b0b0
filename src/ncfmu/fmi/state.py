"""The serialized FMU state: plain data in a versioned format, tied to the FMU that wrote it.

``fmi2SerializeFMUstate`` bytes are one UTF-8 JSON document::

    {"format": "ncfmu-fmu-state", "version": 1, "model": "CutSequencer", "build": "<digest>",
     "parameters": {...}, "inputs": {...}, "logic": {<attribute>: <value>, ...} | null}

``build`` is the digest of the ncfmu copy the FMU carries (``resources/ncfmu_<digest>``), so a state
is accepted only by the same model of the same build. Values are JSON; what JSON cannot say is tagged:
``{"f": "nan"|"inf"|"-inf"}`` for non-finite floats, ``{"t": [...]}`` for tuples, ``{"d": [[k, v], ...]}``
for dicts whose keys are not all strings, ``{"a": [...], "dtype": ..., "shape": [...]}`` for numpy arrays
and ``{"o": "controllers.motion:LinearMove", "v": {...}}`` for objects of ncfmu's own classes.

Loading runs no code from the bytes: nothing is imported, no constructor, ``__reduce__`` or
``__setstate__`` is called. An object tag names a class by module and name inside the FMU's own
ncfmu package, among the modules already loaded; the object is created empty (``object.__new__``)
and its attributes filled with decoded plain data. The controller itself is rebuilt from the saved
parameters (its ``configure()`` checks them) before its dynamic attributes are restored; attributes
it lists in ``DERIVED`` (python-control models, rebuilt from the parameters) are not saved.
"""

from __future__ import annotations

import json
import math
import sys
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

from ..errors import NcfmuError

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
        attrs = {k: _encode(v, f"{where}.{k}") for k, v in vars(value).items() if k not in derived}
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
            if isinstance(key, (list, dict)):
                raise StateError(f"{where}: unhashable key")
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
        obj: object = object.__new__(_class(tree["o"]))
        vars(obj).update({str(k): _decode(v, f"{where}.{k}") for k, v in tree["v"].items()})
        return obj
    return {str(k): _decode(v, f"{where}[{k!r}]") for k, v in tree.items()}


def loads(data: bytes, logic_class: type[Controller], build_logic: Callable[[dict[str, object]], Controller]
          ) -> tuple[Controller | None, dict[str, object], dict[str, object]]:
    """Check ``data`` against this FMU and decode it: ``(logic, parameters, inputs)``.

    ``build_logic(parameters)`` rebuilds the controller from the saved parameters; its dynamic
    attributes are then restored from the state.

    Raises
    ------
    StateError
        for anything that is not a state of this model and build.
    """
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
    try:
        parameters, inputs = _decode(doc.get("parameters"), "parameters"), _decode(doc.get("inputs"), "inputs")
        saved = doc.get("logic")
        if (not isinstance(parameters, dict) or not isinstance(inputs, dict)
                or not isinstance(saved, (dict, type(None)))):
            raise StateError("parameters, inputs or logic missing")
        expected = set(logic_class.default_parameters()), set(logic_class.default_inputs())
        if set(parameters) != expected[0] or set(inputs) != expected[1]:
            raise StateError(f"parameters or inputs are not those of {model}")
        logic = None
        if saved is not None:
            logic = build_logic(parameters)
            attrs = {str(k): _decode(v, f"logic.{k}") for k, v in saved.items()}
            unknown = set(attrs) - set(vars(logic))
            if unknown:
                raise StateError(f"attributes {sorted(unknown)} are not state of {model}")
            vars(logic).update(attrs)
        return logic, parameters, inputs
    except RecursionError:
        raise StateError("nested too deeply to be a state") from None
