"""Every model ncfmu builds, found once, from the code itself.

A model is a :class:`~ncfmu.controllers.base.Controller` subclass with a ``MODEL_NAME`` in this package: the
plain-Python controllers of :mod:`ncfmu.controllers`, each built into a Python FMU from its model script
``models/<MODEL_NAME>.py``, and the drives' Python steppers (:mod:`ncfmu.servo.axis`, :mod:`ncfmu.servo.spindle`),
the executable specifications of the native ServoAxis and SpindleDrive FMUs built from their C sources
(``NATIVE_SOURCE``). The systems' component
checks, the builders, the documentation and the command line ask :func:`models`; nothing else lists them.
Adding a model is its controller (a module of ``controllers/``), its model script and its tests.
"""

from __future__ import annotations

import functools
import importlib
import pkgutil

from . import controllers
from .controllers.base import Controller


@functools.cache
def models() -> dict[str, type[Controller]]:
    """Model name -> its logic class, in name order (every controller module is imported to find them)."""
    for info in pkgutil.iter_modules(controllers.__path__):
        importlib.import_module(f"{controllers.__name__}.{info.name}")
    importlib.import_module(f"{__package__}.servo.axis")
    importlib.import_module(f"{__package__}.servo.spindle")
    found: dict[str, type[Controller]] = {}
    stack: list[type[Controller]] = [Controller]
    while stack:
        for sub in stack.pop().__subclasses__():
            stack.append(sub)
            # only this package's own models (a test's fake controller is not one)
            if sub.MODEL_NAME and sub.__module__.startswith(f"{__package__}."):
                if sub.MODEL_NAME in found and found[sub.MODEL_NAME] is not sub:
                    raise TypeError(f"two models named {sub.MODEL_NAME}: {found[sub.MODEL_NAME]} and {sub}")
                found[sub.MODEL_NAME] = sub
    return dict(sorted(found.items()))


def is_native(logic: type[Controller]) -> bool:
    """Built from C sources (no Python at run time), not from a pythonfmu model script."""
    return bool(logic.NATIVE_SOURCE)


def python_models() -> list[str]:
    return [name for name, logic in models().items() if not is_native(logic)]


def native_models() -> list[str]:
    return [name for name, logic in models().items() if is_native(logic)]
