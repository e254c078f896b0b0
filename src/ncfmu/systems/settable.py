"""What one can set in a system, and read from it: every parameter, input and output of every instance, as
``ncfmu vars`` lists them. A parameter the system's parameter set leaves unread (a table row beyond its count, a
setting its program names nowhere) is marked unused, with why.

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
    """One parameter, input or output of one instance."""

    name: str                   # INSTANCE.VARIABLE
    kind: str                   # "parameter, tunable", "parameter, fixed" (", unused"), "input", "output"
    type: str                   # Real, Integer, Boolean, String
    unit: str
    start: str                  # the system's start value (after its parameter sets), as text
    rule: str
    description: str
    driven_by: str = ""         # for an input: the output a connection feeds it from; for an output: "feeds ..."


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


def _outputs_from_ports(inst: str, ports: tuple[Port, ...]) -> list[Settable]:
    return [Settable(f"{inst}.{p.name}", "output", p.type, p.unit or "", "-", "-", p.description)
            for p in ports if p.causality == "output"]


def _unused(rows: list[Settable], unread: dict[str, str]) -> list[Settable]:
    """The rows of parameters the system's values leave unread, marked so, with why first in the description."""
    out = []
    for row in rows:
        why = unread.get(row.name.partition(".")[2])
        out.append(replace(row, kind=f"{row.kind}, unused", description=f"unused: {why}; {row.description}")
                   if why else row)
    return out


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
        if causality == "output":
            out.append(Settable(f"{inst}.{sv.get('name', '')}", "output", typed.tag,
                                typed.get("unit") or declared.get(typed.get("declaredType"), "") or "", "-", "-",
                                sv.get("description", "")))
            continue
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


def settable(system: System, model_description: Callable[[str], bytes] | None = None,
             outputs: bool = False) -> list[Settable]:
    """Every parameter and input of ``system`` (with ``outputs``, every output too, after its instance's
    parameters and inputs), instance by instance in stepping order. A parameter that the system's values leave
    unread is marked ``unused`` (``Controller.unread``: a table row beyond its count, ...).

    ``model_description(instance)`` gives the modelDescription.xml of an instance's FMU (an .ssp's own): the FMU
    is then known by it (:func:`~ncfmu.systems.roles.identify`), never by its file name -- one of ncfmu's models
    is listed from its ports, any other FMU from its modelDescription. Without it the components are taken to be
    the models they name (a system ncfmu defines).
    """
    drivers = {(c.end_element, c.end_connector): f"{c.start_element}.{c.start_connector}"
               for c in system.connections}
    fed: dict[tuple[str, str], list[str]] = {}
    for c in system.connections:
        fed.setdefault((c.start_element, c.start_connector), []).append(f"{c.end_element}.{c.end_connector}")
    out: list[Settable] = []
    for comp in system.components:
        md = None if model_description is None else model_description(comp.name)
        logic = MODELS.get(comp.model if md is None else identify(md, comp.name).model)
        if logic is not None:
            rows = _from_ports(comp.name, logic.PORTS, comp.parameters)
            rows = _unused(rows, logic.unread({**logic.default_parameters(), **comp.parameters}))
            rows += _outputs_from_ports(comp.name, logic.PORTS) if outputs else []
        elif md is not None:
            rows = [r for r in _from_model_description(comp.name, md, comp.parameters)
                    if outputs or r.kind != "output"]
        else:
            continue
        for row in rows:
            inst, _, var = row.name.partition(".")
            if row.kind == "output":
                source = f"feeds {', '.join(fed[inst, var])}" if (inst, var) in fed else ""
            else:
                source = drivers.get((inst, var), "") if row.kind == "input" else ""
            out.append(replace(row, driven_by=source) if source else row)
    return out
