"""A system's connectors and connections checked against its FMUs, with the unit conversions they need.

Every SSD connector must name a variable of its component's FMU with the same causality (its ``kind``), type and a
unit of the same quantity. Every connection between two Reals with units converts from the source's unit to the
destination's (mm to m, min to s), is refused when the units are of different quantities (naming both ends), and
passes values unconverted with a warning when one end has no unit.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from ..errors import SystemDefinitionError
from .slave import Slave, Variable
from .ssp import System
from .units import Conversion, Unit, conversion

#: SSD connector kinds and the FMI causalities they stand for
KIND_CAUSALITY = {"input": ("input",), "output": ("output",), "parameter": ("parameter",),
                  "calculatedParameter": ("calculatedParameter",), "inout": ("input", "output")}

#: the FMI types an SSD connector type stands for (FMI 3.0's for the SSP 1.0 names too)
CONNECTOR_TYPES = {"Real": ("Real", "Float64", "Float32"), "Integer": ("Integer", "Int32", "Int64", "Int16", "Int8",
                                                                       "UInt32", "UInt16", "UInt8", "UInt64"),
                   "Boolean": ("Boolean",), "String": ("String",), "Enumeration": ("Enumeration",),
                   "Binary": ("Binary",)}

REAL_TYPES = ("Real", "Float64", "Float32")


@dataclass
class Checked:
    """What the checks found: the conversions (by the input they feed) and the warning lines."""

    conversions: dict[tuple[str, str], Conversion] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)


def unit_of(v: Variable, connector_unit: str | None, units: Mapping[str, Unit]) -> Unit | None:
    """A variable's unit: its FMU's (with the modelDescription's definition, else the SSD's), else its connector's."""
    name = v.unit or connector_unit
    if not name:
        return None
    if name == v.unit and v.unit_definition is not None and v.unit_definition.exponents is not None:
        return v.unit_definition
    return units.get(name) or Unit(name)


def _connector_units(system: System) -> dict[tuple[str, str], str | None]:
    return {(comp.name, name): unit for comp in system.components for name, _kind, _type, unit in comp.connectors}


def check_connectors(system: System, slaves: Mapping[str, Slave]) -> None:
    """Every SSD connector against its FMU: the variable exists, with the connector's causality, type and unit."""
    for comp in system.components:
        slave = slaves[comp.name]
        for name, kind, typ, unit in comp.connectors:
            where = f"{system.name}: connector {comp.name}.{name}"
            v = slave.variables.get(name)
            if v is None:
                raise SystemDefinitionError(f"{where}: {comp.name}'s FMU has no variable {name!r}")
            if kind not in KIND_CAUSALITY:
                raise SystemDefinitionError(f"{where}: kind {kind!r} is not an SSP connector kind "
                                            f"({', '.join(KIND_CAUSALITY)})")
            if v.causality not in KIND_CAUSALITY[kind]:
                raise SystemDefinitionError(f"{where}: declared {kind}, but the FMU's {name} is {v.causality}")
            if v.type not in CONNECTOR_TYPES.get(typ, (typ,)):
                raise SystemDefinitionError(f"{where}: declared {typ}, but the FMU's {name} is {v.type}")
            if unit and v.unit and v.type in REAL_TYPES:
                fmu_unit = unit_of(v, None, system.units)
                declared = system.units.get(unit) or Unit(unit)
                if fmu_unit is not None and conversion(declared, fmu_unit) is None:
                    raise SystemDefinitionError(f"{where}: declared in {unit} ({declared.dimension()}), but the FMU's "
                                                f"{name} is in {v.unit} ({fmu_unit.dimension()}): not the same "
                                                "quantity")


def check_units(system: System, slaves: Mapping[str, Slave]) -> Checked:
    """The connectors checked (:func:`check_connectors`), then every connection's units: the conversions and
    warnings. The connections' ends exist and their types agree (the master checked that first)."""
    check_connectors(system, slaves)
    declared = _connector_units(system)
    checked = Checked()
    for c in system.connections:
        src = slaves[c.start_element].variables[c.start_connector]
        dst = slaves[c.end_element].variables[c.end_connector]
        if src.type not in REAL_TYPES:
            continue
        su = unit_of(src, declared.get((c.start_element, c.start_connector)), system.units)
        du = unit_of(dst, declared.get((c.end_element, c.end_connector)), system.units)
        if su is None and du is None:
            continue
        if su is None or du is None:
            has, lacks = (c.end_connector, c.start_connector) if su is None else (c.start_connector, c.end_connector)
            owner, other = ((c.end_element, c.start_element) if su is None else (c.start_element, c.end_element))
            unit = (du if su is None else su)
            assert unit is not None
            checked.warnings.append(f"connection {c}: {owner}.{has} is in {unit.name}, {other}.{lacks} has no unit: "
                                    "values pass unconverted")
            continue
        conv = conversion(su, du)
        if conv is None:
            raise SystemDefinitionError(f"connection {c}: {c.start_element}.{c.start_connector} is in {su.name} "
                                        f"({su.dimension()}), {c.end_element}.{c.end_connector} in {du.name} "
                                        f"({du.dimension()}): not the same quantity, refused")
        if not conv.identity:
            checked.conversions[(c.end_element, c.end_connector)] = conv
    return checked


def free_inputs(system: System, slaves: Mapping[str, Slave], given: set[str]) -> list[str]:
    """Warning lines naming every input nothing drives and that has no value given (``given``: the qualified
    names the system's parameter sets, the run's start values or its input CSV set)."""
    driven = {(c.end_element, c.end_connector) for c in system.connections}
    lines = []
    for comp in system.components:
        for v in slaves[comp.name].variables.values():
            q = f"{comp.name}.{v.name}"
            if v.causality == "input" and (comp.name, v.name) not in driven and q not in given \
                    and v.name not in comp.parameters:
                value = "true" if v.start is True else "false" if v.start is False else repr(v.start)
                start = "no start value" if v.start is None else f"its FMU's start value {value}"
                lines.append(f"{q}: an input that no connection drives and no start value is given for: it keeps "
                             f"{start}")
    return lines
