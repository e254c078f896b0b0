"""Small builders the system definitions are written with: typed components, wiring, flattened tables."""

from __future__ import annotations

from collections.abc import Sequence

from ..catalogue import models
from ..controllers.base import Controller
from ..cosim.ssp import Component, Connection
from ..errors import ConfigError, SystemDefinitionError

#: The operator panel's parameter that repeats its buttons (a soak): a system with it > 0 is never done
#: (:attr:`~ncfmu.systems.report.Report.repeats`).
REPEATS = "panel.repeat_every"

#: Model name -> its logic class (the catalogue: every model ncfmu builds).
MODELS: dict[str, type[Controller]] = models()


def component(name: str, model: str, **parameters: object) -> Component:
    """An instance of ``model`` with parameters checked against its ports (name, type and rule)."""
    logic = MODELS[model]
    ports = {p.name: p for p in logic.ports("parameter")}
    typed: dict[str, object] = {}
    for key, value in parameters.items():
        if key not in ports:
            raise SystemDefinitionError(f"{model} has no parameter {key!r}")
        try:
            typed[key] = ports[key].check(value)
        except ConfigError as err:
            raise SystemDefinitionError(f"{name}: {err}") from None
    connectors: list[tuple[str, str, str, str | None]] = [
        (p.name, p.causality, p.type, p.unit) for p in logic.PORTS if p.causality in ("input", "output")]
    return Component(name, model, typed, connectors)


def wire(*pairs: str) -> list[Connection]:
    """``"seq.x_cmd -> x_axis.pos_cmd"`` -> connections."""
    out = []
    for pair in pairs:
        src, dst = (s.strip() for s in pair.split("->"))
        (a, b), (c, d) = src.split(".", 1), dst.split(".", 1)
        out.append(Connection(a, b, c, d))
    return out


def blocks(*rows: dict) -> dict[str, object]:
    """CutSequencer blocks as its flat parameters ``n_blocks``, ``block[k].<register>``."""
    flat: dict[str, object] = {"n_blocks": len(rows)}
    for k, b in enumerate(rows, start=1):
        for key, value in b.items():
            flat[f"block[{k}].{key}"] = value
    return flat


def table(rows: Sequence[tuple[float, float, float]]) -> dict[str, object]:
    """An AreaLimiter table ``(ref_max, lim_min, lim_max)`` as its flat parameters."""
    flat: dict[str, object] = {"n_regions": len(rows)}
    for i, (ref_max, lo, hi) in enumerate(rows, start=1):
        flat[f"region[{i}].ref_max"], flat[f"region[{i}].lim_min"], flat[f"region[{i}].lim_max"] = ref_max, lo, hi
    return flat


def points(path: Sequence[tuple[float, float]]) -> dict[str, object]:
    """A ContourInterpolator point path as its flat parameters ``n_points``, ``point[i].x/y``."""
    flat: dict[str, object] = {"n_points": len(path)}
    for i, (x, y) in enumerate(path, start=1):
        flat[f"point[{i}].x"], flat[f"point[{i}].y"] = x, y
    return flat
