"""What a component of a system is, from its FMU's modelDescription and its connections -- never its file name.

:func:`identify` says which model of ncfmu's catalogue an FMU is: its ``modelName`` is the model's and its variables
are exactly the model's ports (name, causality, type, in value-reference order). Any other FMU is foreign and known by
its modelName, GUID and generation tool (:class:`Identity`). :func:`axes` finds a system's axes by their role: a
component whose output feeds a position input (``*_pos``, in mm) of one of ncfmu's controllers.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass

from ..cosim.ssp import System
from ..errors import SystemDefinitionError
from .compose import MODELS


@dataclass(frozen=True)
class Identity:
    """An FMU as its modelDescription names it; ``model`` is the catalogue's model it is, else ""."""

    model_name: str
    guid: str
    generation_tool: str
    model: str = ""

    def __str__(self) -> str:
        if self.model:
            return self.model
        return f"{self.model_name} (foreign: GUID {self.guid}, {self.generation_tool or 'no generation tool'})"


def identify(md_xml: bytes, where: str = "") -> Identity:
    """The identity of the FMU whose modelDescription.xml is ``md_xml``."""
    try:
        root = ET.fromstring(md_xml)
    except ET.ParseError as err:
        raise SystemDefinitionError(f"{where}: modelDescription.xml is not well-formed XML: {err}") from None
    name = root.get("modelName", "")
    ident = Identity(name, root.get("guid", root.get("instantiationToken", "")), root.get("generationTool", ""))
    logic = MODELS.get(name)
    if logic is None or root.get("fmiVersion") != "2.0":
        return ident
    variables = [(sv.get("name"), sv.get("causality", "local"), sv[0].tag if len(sv) else "")
                 for sv in root.iter("ScalarVariable")]
    ports = [(p.name, p.causality, p.type) for p in logic.PORTS]
    return Identity(ident.model_name, ident.guid, ident.generation_tool, name if variables == ports else "")


def position_inputs(model: str) -> set[str]:
    """The position inputs of a controller of the catalogue: inputs in mm whose name ends in ``_pos``."""
    logic = MODELS.get(model)
    if logic is None:
        return set()
    return {p.name for p in logic.PORTS if p.causality == "input" and p.unit == "mm" and p.name.endswith("_pos")}


def axes(system: System, models: Mapping[str, str]) -> list[str]:
    """The instances of ``system`` that are axes by their role (``models``: instance -> catalogue model or "")."""
    found = []
    for c in system.connections:
        if c.end_connector in position_inputs(models.get(c.end_element, "")) and c.start_element not in found:
            found.append(c.start_element)
    order = [comp.name for comp in system.components]
    return sorted(found, key=order.index)
