"""What one can set in a system: every parameter and input of every instance, as ``ncfmu vars`` lists them.

For an instance of a model ncfmu defines, the facts come from the model's ports (unit, rule, description,
variability) and the system's parameter sets (the start value a run begins with); for another model (an
``.ssp`` of the user's), from its FMU's modelDescription. Inputs say which connection drives them: such an
input cannot be set (``--set`` is refused: set the source); a free input takes a start value or an input CSV.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import dataclass, replace

from ..cosim.ssp import System
from ..ports import Port
from .compose import MODELS
from .roles import identify


@dataclass(frozen=True)
class Settable:
    """One parameter or input of one instance."""

    name: str                   # INSTANCE.VARIABLE
    kind: str                   # "parameter, tunable", "parameter, fixed", "input"
    type: str                   # Real, Integer, Boolean, String
    unit: str
    start: str                  # the system's start value (after its parameter sets), as text
    rule: str
    description: str
    driven_by: str = ""         # for an input: the output a connection feeds it from, else ""


def text(value: object) -> str:
    """A start value as one would type it after ``--set NAME=``."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(int(value)) if value.is_integer() and abs(value) < 1e15 else repr(value)
    return str(value)


def _rule(port: Port) -> str:
    if port.type == "Boolean":
        return "true or false"
    if port.type == "String":
        return "text"
    return port.rule()


def _from_ports(inst: str, ports: tuple[Port, ...], values: dict[str, object]) -> list[Settable]:
    return [Settable(f"{inst}.{p.name}",
                     "input" if p.causality == "input" else
                     "parameter, tunable" if p.fmi_variability == "tunable" else "parameter, fixed",
                     p.type, p.unit or "", text(values.get(p.name, p.start)), _rule(p), p.description)
            for p in ports if p.causality in ("parameter", "input")]


def _from_model_description(inst: str, md_xml: bytes, values: dict[str, object]) -> list[Settable]:
    out = []
    root = ET.fromstring(md_xml)
    declared = {t.get("name"): t[0].get("unit", "") for t in root.iterfind("TypeDefinitions/SimpleType") if len(t)}
    if root.get("fmiVersion", "").startswith("3"):
        # FMI 3.0: the variable is its type's element (Float64, Int32, ...), with the attributes on it
        declared.update({t.get("name"): t.get("unit", "") for t in root.iterfind("TypeDefinitions/*")})
        variables = [(v, v) for v in root.iterfind("ModelVariables/*")]
    else:
        variables = [(sv, sv[0]) for sv in root.iter("ScalarVariable") if len(sv)]
    for sv, typed in variables:
        causality = sv.get("causality", "local")
        if causality not in ("parameter", "input"):
            continue
        name = sv.get("name", "")
        lo, hi = typed.get("min"), typed.get("max")
        rule = (f"must be in [{lo}, {hi}]" if lo and hi else f"must be >= {lo}" if lo else f"must be <= {hi}" if hi
                else "")
        kind = "input" if causality == "input" else f"parameter, {sv.get('variability', 'fixed')}"
        start = typed.get("start", "")
        if not start and typed.find("Start") is not None:            # FMI 3.0's String start
            start = typed.find("Start").get("value", "")             # type: ignore[union-attr]
        unit = typed.get("unit") or declared.get(typed.get("declaredType"), "")
        out.append(Settable(f"{inst}.{name}", kind, typed.tag, unit,
                            text(values[name]) if name in values else start, rule,
                            sv.get("description", "")))
    return out


def settable(system: System, model_description: Callable[[str], bytes] | None = None) -> list[Settable]:
    """Every parameter and input of ``system``, instance by instance in stepping order.

    ``model_description(instance)`` gives the modelDescription.xml of an instance's FMU (an .ssp's own): the FMU
    is then known by it (:func:`~ncfmu.systems.roles.identify`), never by its file name -- one of ncfmu's models
    is listed from its ports, any other FMU from its modelDescription. Without it the components are taken to be
    the models they name (a system ncfmu defines).
    """
    drivers = {(c.end_element, c.end_connector): f"{c.start_element}.{c.start_connector}"
               for c in system.connections}
    out: list[Settable] = []
    for comp in system.components:
        md = None if model_description is None else model_description(comp.name)
        logic = MODELS.get(comp.model if md is None else identify(md, comp.name).model)
        if logic is not None:
            rows = _from_ports(comp.name, logic.PORTS, comp.parameters)
        elif md is not None:
            rows = _from_model_description(comp.name, md, comp.parameters)
        else:
            continue
        for row in rows:
            inst, _, var = row.name.partition(".")
            source = drivers.get((inst, var), "") if row.kind == "input" else ""
            out.append(replace(row, driven_by=source) if source else row)
    return out
