"""The modelDescription.xml of every ncfmu FMU, FMI 2.0 or 3.0, written from the model's port table.

One writer, :func:`model_description`, the FMI version a parameter. What each version's file says comes from the
same places: the variables, their units, ranges, start values and variabilities from the controller's ports
(:class:`~ncfmu.ports.Port`, value reference = the port's index), the unit definitions from ``ports.UNITS``, the
log categories from the C layer's table (``fmi/c/fmi2_machine.h``), the default experiment from the controller's
``STOP_TIME`` and ``PERIOD``. The versions differ only in how they spell it:

- FMI 2.0: ``ScalarVariable`` with a typed child, ``ModelStructure/Outputs`` and ``InitialUnknowns`` by index.
  A Python FMU's file starts from pythonfmu's (which owns its GUID, generation time, author and the start values
  the slave registered); a native FMU's from :func:`_fmi2_skeleton`. Both are then completed the same way
  (:func:`_complete_fmi2`): units, ranges, descriptions, variabilities, capabilities, structure, experiment.
- FMI 3.0: typed variables (:data:`TYPES`), the independent variable ``time`` (:data:`TIME_VR`), the structure by
  value reference.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from ..errors import BuildError
from ..ports import DISPLAY_UNITS, UNITS, Port
from ..version import __version__

if TYPE_CHECKING:
    from ..controllers.base import Controller

__all__ = ["FMI_VERSIONS", "TIME_VR", "TYPES", "log_categories", "model_description"]

FMI_VERSIONS = ("2.0", "3.0")
#: The FMI 3.0 types of the ports' types.
TYPES = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean", "String": "String"}
#: FMI 3.0's independent variable's value reference (it must be declared); far above any port's (a port's index).
TIME_VR = 1_000_000_000
C_LAYER = Path(__file__).with_name("c")
#: The header whose table lists the log categories the FMI layer takes.
CATEGORIES_HEADER = C_LAYER / "fmi2_machine.h"
_BASE_UNIT_ORDER = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")


def log_categories() -> list[str]:
    """The log categories the SetDebugLogging calls take (FMI 2.0 and 3.0 alike): FMI2_CATEGORIES of the C layer,
    their one home."""
    table = re.search(r"FMI2_CATEGORIES\[\][^{]*\{([^}]*)\}", CATEGORIES_HEADER.read_text())
    if table is None:
        raise BuildError(f"{CATEGORIES_HEADER.name}: no FMI2_CATEGORIES table")
    return re.findall(r'"(\w+)"', table.group(1))


def model_description(logic: type[Controller], fmi_version: str, guid: str, version: str, *,
                      native_sources: Sequence[str] | None = None, pythonfmu_xml: bytes | None = None) -> bytes:
    """The modelDescription of ``logic``'s FMU in ``fmi_version`` ("2.0" or "3.0").

    ``guid`` is the FMI 2.0 GUID (FMI 3.0's instantiationToken), ``version`` the build's version. A native FMU
    names its C ``native_sources`` (FMI 2.0 lists them in ``SourceFiles``); a Python FMU's FMI 2.0 file is
    completed from ``pythonfmu_xml``, pythonfmu's own (which holds that GUID)."""
    if fmi_version == "3.0":
        return _fmi3(logic, guid, version, native=native_sources is not None)
    if fmi_version != "2.0":
        raise BuildError(f"fmi_version = {fmi_version!r}: must be one of {', '.join(FMI_VERSIONS)}")
    if pythonfmu_xml is not None:
        root = ET.fromstring(pythonfmu_xml)
        if root.get("guid") != guid:
            raise BuildError(f"{logic.MODEL_NAME}: pythonfmu's modelDescription has guid {root.get('guid')!r}, "
                             f"not {guid!r}")
    elif native_sources is not None:
        root = _fmi2_skeleton(logic, guid, native_sources)
    else:
        raise BuildError(f"{logic.MODEL_NAME}: an FMI 2.0 modelDescription starts from pythonfmu's or names the "
                         "native model's C sources")
    return _complete_fmi2(root, logic, version)


# -- what both versions say alike -----------------------------------------------------------------
def _unit_definitions(units: Iterable[str]) -> ET.Element:
    """``UnitDefinitions`` of ``units`` (sorted), each with its SI base and display units (``ports.UNITS``)."""
    defs = ET.Element("UnitDefinitions")
    for name in sorted(units):
        spec = dict(UNITS[name])
        unit = ET.SubElement(defs, "Unit", name=name)
        base = {k: str(spec[k]) for k in _BASE_UNIT_ORDER if k in spec}
        if "factor" in spec:
            base["factor"] = repr(spec["factor"])
        ET.SubElement(unit, "BaseUnit", base)
        for display, factor in DISPLAY_UNITS.get(name, []):
            ET.SubElement(unit, "DisplayUnit", name=display, factor=repr(factor))
    return defs


def _used_units(logic: type[Controller]) -> set[str]:
    return {p.unit for p in logic.PORTS if p.unit}


def _log_categories() -> ET.Element:
    categories = ET.Element("LogCategories")
    for name in log_categories():
        ET.SubElement(categories, "Category", name=name)
    return categories


def _type_attributes(port: Port, real: Callable[[float], str]) -> dict[str, str]:
    """A port's ``unit``, ``min`` and ``max`` in that order, a Real's bounds written by ``real``."""
    attributes = {}
    if port.type == "Real" and port.unit:
        attributes["unit"] = port.unit
    if port.type in ("Real", "Integer"):
        for name, bound in (("min", port.min), ("max", port.max)):
            if bound is not None:
                attributes[name] = real(bound) if port.type == "Real" else str(int(bound))
    return attributes


def _float(x: float) -> str:
    return repr(float(x))


def _as_written(x: float) -> str:
    """A bound as the port gives it: an int bound of a Real stays "0" (the FMI 2.0 files have always said so)."""
    return repr(float(x)) if isinstance(x, float) else str(x)


def _start(port: Port) -> str:
    start = port.default()
    if port.type == "Boolean":
        return "true" if start else "false"
    if port.type == "String":
        return str(start)
    return _float(float(start)) if port.type == "Real" else str(int(start))


def _experiment(logic: type[Controller]) -> dict[str, str]:
    return {"startTime": "0.0", "stopTime": _float(logic.STOP_TIME), "stepSize": _float(logic.PERIOD)}


# -- FMI 2.0 --------------------------------------------------------------------------------------
def _fmi2_skeleton(logic: type[Controller], guid: str, sources: Sequence[str]) -> ET.Element:
    """A native FMU's FMI 2.0 file before completion: its identity, sources, categories and variables."""
    name = logic.MODEL_NAME
    root = ET.Element("fmiModelDescription", fmiVersion="2.0", modelName=name, guid=guid,
                      generationTool=f"ncfmu {__version__} (native C)", variableNamingConvention="structured",
                      numberOfEventIndicators="0")
    cs = ET.SubElement(root, "CoSimulation", modelIdentifier=name, needsExecutionTool="false",
                       canHandleVariableCommunicationStepSize="true", canInterpolateInputs="false",
                       canBeInstantiatedOnlyOncePerProcess="false", canNotUseMemoryManagementFunctions="false",
                       canGetAndSetFMUstate="true", canSerializeFMUstate="true",
                       providesDirectionalDerivative="false")
    files = ET.SubElement(cs, "SourceFiles")
    for source in sources:
        ET.SubElement(files, "File", name=source)
    root.append(_log_categories())
    ET.SubElement(root, "DefaultExperiment")
    mv = ET.SubElement(root, "ModelVariables")
    for vr, p in enumerate(logic.PORTS):
        sv = ET.SubElement(mv, "ScalarVariable", name=p.name, valueReference=str(vr), causality=p.causality)
        typed = ET.SubElement(sv, p.type)
        if p.causality != "output":
            typed.set("start", _start(p))
    ET.SubElement(root, "ModelStructure")
    return root


def _complete_fmi2(root: ET.Element, logic: type[Controller], version: str) -> bytes:
    """The FMI 2.0 file ``root`` completed from ``logic``'s ports, as strict validation (``fmpy.validation``)
    and FMI tools want it."""
    root.set("version", version)
    root.set("description", logic.DESCRIPTION)
    ports = {p.name: p for p in logic.PORTS}
    cosim = root.find("CoSimulation")
    variables = root.find("ModelVariables")
    structure = root.find("ModelStructure")
    assert cosim is not None and variables is not None and structure is not None, \
        "pythonfmu and _fmi2_skeleton write CoSimulation, ModelVariables and ModelStructure"
    # The adapter's state hooks copy the whole controller: every hidden state round-trips.
    cosim.set("canGetAndSetFMUstate", "true")
    cosim.set("canSerializeFMUstate", "true")
    # The binary loads the Python runtime itself, as a library, in any host (fmi/c/python_model.c): no tool
    # has to run beside it.
    cosim.set("needsExecutionTool", "false")
    used = _used_units(logic)
    if used:
        # The schema's order: CoSimulation, UnitDefinitions, TypeDefinitions, LogCategories, ...
        root.insert(list(root).index(cosim) + 1, _unit_definitions(used))

    outputs_index = []
    for index, sv in enumerate(variables, start=1):
        port = ports[sv.get("name", "")]
        sv.set("description", port.description)
        sv.set("variability", port.fmi_variability)
        type_node = sv[0]
        for attribute, value in _type_attributes(port, _as_written).items():
            type_node.set(attribute, value)
        if port.causality == "output":
            outputs_index.append(index)
            type_node.attrib.pop("start", None)
            sv.attrib.pop("initial", None)

    for child in list(structure):
        structure.remove(child)
    if outputs_index:
        outs = ET.SubElement(structure, "Outputs")
        init = ET.SubElement(structure, "InitialUnknowns")
        for i in outputs_index:
            ET.SubElement(outs, "Unknown", index=str(i))
            ET.SubElement(init, "Unknown", index=str(i))

    experiment = root.find("DefaultExperiment")
    if experiment is None:
        experiment = ET.Element("DefaultExperiment")
        root.insert(list(root).index(variables), experiment)
    for attribute, value in _experiment(logic).items():
        experiment.set(attribute, value)
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


# -- FMI 3.0 --------------------------------------------------------------------------------------
def _fmi3(logic: type[Controller], guid: str, version: str, native: bool) -> bytes:
    root = ET.Element("fmiModelDescription", fmiVersion="3.0", modelName=logic.MODEL_NAME,
                      instantiationToken=guid, description=logic.DESCRIPTION, version=version,
                      generationTool=f"ncfmu {__version__}" + (" (native C)" if native else ""),
                      variableNamingConvention="structured")
    ET.SubElement(root, "CoSimulation", modelIdentifier=logic.MODEL_NAME, needsExecutionTool="false",
                  canBeInstantiatedOnlyOncePerProcess="false", canGetAndSetFMUState="true",
                  canSerializeFMUState="true", providesDirectionalDerivatives="false",
                  providesAdjointDerivatives="false", canHandleVariableCommunicationStepSize="true",
                  maxOutputDerivativeOrder="0", providesIntermediateUpdate="false",
                  canReturnEarlyAfterIntermediateUpdate="false", hasEventMode="false",
                  providesEvaluateDiscreteStates="false")
    root.append(_unit_definitions(_used_units(logic) | {"s"}))     # "s": the time's
    root.append(_log_categories())
    ET.SubElement(root, "DefaultExperiment", _experiment(logic))
    variables = ET.SubElement(root, "ModelVariables")
    ET.SubElement(variables, "Float64", name="time", valueReference=str(TIME_VR), causality="independent",
                  variability="continuous", unit="s", description="simulation time")
    outputs = []
    for vr, port in enumerate(logic.PORTS):
        var = ET.SubElement(variables, TYPES[port.type], name=port.name, valueReference=str(vr),
                            description=port.description, causality=port.causality,
                            variability=port.fmi_variability)
        for attribute, value in _type_attributes(port, _float).items():
            var.set(attribute, value)
        if port.causality == "output":
            outputs.append(vr)
        elif port.type == "String":
            ET.SubElement(var, "Start", value=_start(port))
        else:
            var.set("start", _start(port))
    structure = ET.SubElement(root, "ModelStructure")
    for vr in outputs:
        ET.SubElement(structure, "Output", valueReference=str(vr))
    for vr in outputs:
        ET.SubElement(structure, "InitialUnknown", valueReference=str(vr))
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)
