"""What the controllers need to run the same compiled with mypyc (``fmi/builder.py``'s ``COMPILED``) as from source.

``mypyc_attr``: mypyc reads ``@mypyc_attr(...)`` at compile time (it resolves the name to
``mypy_extensions.mypyc_attr``); at run time the decorator does nothing. An FMU runs on the standard library
alone, where ``mypy_extensions`` may be absent: then the no-op below stands in for it.

Two kinds of class are compiled (bench/README.md has what each costs):

- the controllers (``Controller`` and every subclass in the runtime) are **native classes**:
  ``@mypyc_attr(allow_interpreted_subclasses=True, serializable=True)`` -- their attributes are C fields, no
  ``__dict__``; ``serializable`` gives them the pickle protocol's ``__getstate__``, so ``copy.deepcopy`` (the
  FMU states, ``Controller.retune``) copies every attribute. An interpreted subclass of a native class keeps its
  own attributes in a ``__dict__`` that deepcopy would drop: hence *every* controller of the runtime is compiled
  with its base (a test holds the list to the runtime's subclasses);
- so are the objects a controller steps every step (``LinearMove``, ``ElementMove``, ``PositionGuard``,
  ``OverrideDial``, ``Button``, ``InPosition``): fmi/state.py's loader creates one empty with :func:`blank` (the
  class's allocator, no code of the class runs) and fills its typed fields;
- the records inside a controller's state (the dataclasses: ``Block``, ``Word``, the planner's) are
  ``native_class=False``: compiled methods, a ``__dict__`` kept, created empty with ``object.__new__`` as from
  source.

:func:`attributes` and :func:`set_attributes` read and fill an object's attributes for both kinds, so
fmi/state.py and ``Controller.check_state`` hold one format for the pure and the compiled runtime.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from mypy_extensions import mypyc_attr
else:
    try:
        from mypy_extensions import mypyc_attr
    except ImportError:                     # an FMU's host without mypy: the decorator is only read by mypyc
        def mypyc_attr(*attrs: str, **kwattrs: object):
            return lambda cls: cls

__all__ = ["attributes", "blank", "blankable", "mypyc_attr", "set_attributes"]


def attributes(obj: object) -> dict[str, Any]:
    """The attributes that hold a value, by name (a new dict): an object's ``__dict__``, or for an object of a
    native class (no ``__dict__``) what its ``__getstate__`` gives -- mypyc's ``serializable``: every
    attribute that is set."""
    if hasattr(obj, "__dict__"):
        return dict(vars(obj))
    state = obj.__getstate__()
    if not isinstance(state, dict):         # a native class compiled without serializable=True
        raise TypeError(f"a {type(obj).__qualname__} gives no attributes (a native class must be serializable)")
    return state


def set_attributes(obj: object, values: Mapping[str, Any]) -> None:
    """Set each attribute: into the ``__dict__`` as is (no descriptor runs), or on a native class through its
    typed fields (a value of another type is a TypeError, an unknown name an AttributeError)."""
    if hasattr(obj, "__dict__"):
        vars(obj).update(values)
        return
    for name, value in values.items():
        setattr(obj, name, value)


def blankable(cls: type[Any]) -> bool:
    """Whether :func:`blank` can make an object of ``cls``: a plain class (``object.__new__``) or a native one
    (instances without ``__dict__``, serializable); not a class with its own construction (an exception, a
    builtin's subclass). (ncfmu's classes define no ``__new__``.)"""
    if issubclass(cls, BaseException):
        return False
    return cls.__new__ is object.__new__ or (cls.__dictoffset__ == 0 and cls.__getstate__ is not object.__getstate__)


def blank(cls: type[Any]) -> object:
    """An object of a :func:`blankable` ``cls`` with no attribute set, made without running any code of the
    class: ``object.__new__`` for a plain class; for a native class its allocator, which only sets up the C
    fields."""
    if not blankable(cls):
        raise TypeError(f"a {cls.__qualname__} is made by its own construction, not blank")
    allocate: Any = cls.__new__
    return allocate(cls)
