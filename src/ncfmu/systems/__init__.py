"""The systems ncfmu ships, each defined once: components, parameters, connections, and its report.

A system is data: :func:`get_system` gives its :class:`~ncfmu.cosim.ssp.System` (written to
``ssp/<system>/`` as SSP 1.0), :func:`report_for` its :class:`~ncfmu.systems.report.Report` (summary
lines, metrics, default record, plot). The family modules (``lathe``, ``grinder``, ``mill``) keep a
system's definition and its report side by side. Components are listed in Gauss-Seidel order (operator
panel, controller, servos); connector types and units come from the controllers' port tables.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

from ..cosim.ssp import System
from ..errors import SystemDefinitionError
from . import grinder, lathe, mill
from .compose import MODELS
from .grinder import GRINDER_TABLE
from .lathe import CHUCK_TABLE
from .report import Report, generic_report

__all__ = ["CHUCK_TABLE", "GRINDER_TABLE", "MODELS", "SYSTEMS", "Definition", "get_system", "parameters",
           "report_for", "report_of", "run_parameters"]


@dataclass(frozen=True)
class Definition:
    """One system: how to build it and what its runs report."""

    build: Callable[[], System]
    report: Report


SYSTEMS: dict[str, Definition] = {
    "mill_contour": Definition(mill.mill_contour, mill.REPORT),
    "lathe_roughing": Definition(lathe.lathe_roughing, lathe.REPORT),
    "lathe_taper": Definition(lathe.lathe_taper, lathe.REPORT),
    "grinder_feed": Definition(grinder.grinder_feed, grinder.FEED_REPORT),
    "grinder_envelope": Definition(grinder.grinder_envelope, grinder.ENVELOPE_REPORT),
}


def get_system(name: str) -> System:
    try:
        return SYSTEMS[name].build()
    except KeyError:
        raise SystemDefinitionError(f"unknown system {name!r}; known systems: {', '.join(SYSTEMS)}") from None


def parameters(name: str, instance: str) -> dict[str, object]:
    """The parameters system ``name`` gives its instance ``instance`` (e.g. for a controller in a test)."""
    return dict(get_system(name).component(instance).parameters)


def report_for(name: str, models: Mapping[str, str] | None = None, axes: Sequence[str] | None = None) -> Report:
    """The report of system ``name``.

    ``models`` (instance -> the model its FMU is, :mod:`~ncfmu.systems.roles`), when given, must match the
    definition of that name -- but for its axes, which may be any plant (a user's axis in place of ServoAxis); an
    .ssp of another make (renamed instances, other controllers) gets the generic report of its axes: ``axes``
    (found by their role, :func:`~ncfmu.systems.roles.axes`), else its ServoAxis instances.
    """
    definition = SYSTEMS.get(name)
    if definition is not None:
        own = {c.name: c.model for c in definition.build().components}
        its_axes = set(definition.report.axes)
        if models is None or (own.keys() == dict(models).keys()
                              and all(models[i] == m or i in its_axes for i, m in own.items())):
            return definition.report
    if axes is None:
        axes = [inst for inst, model in (models or {}).items() if model == "ServoAxis"]
    return generic_report(axes)


def report_of(result) -> Report:
    """The report of a run: by the system it names and the instances it ran."""
    return report_for(result.system, result.models or None)


def run_parameters(result) -> dict[str, dict[str, object]]:
    """The parameters a run used; for a result read back from a CSV (which has none), its system's."""
    if result.parameters:
        return result.parameters
    if result.system in SYSTEMS:
        return {c.name: dict(c.parameters) for c in get_system(result.system).components}
    return {}
