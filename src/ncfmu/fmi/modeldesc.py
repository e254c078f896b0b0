"""Post-processing of pythonfmu's modelDescription.xml so that it passes strict validation.

pythonfmu writes names, causalities and start values. From the controller's port table this adds
what FMI tools and ``fmpy.validation.validate_fmu`` need: ``UnitDefinitions`` (with display units),
``unit``/``min``/``max``/``description`` on every variable, ``variability`` on every parameter and
non-Real, ``ModelStructure/InitialUnknowns`` for the outputs, and a ``DefaultExperiment``.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

from ..controllers.base import Controller
from ..ports import DISPLAY_UNITS, UNITS

_BASE_UNIT_ORDER = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")


def _fmt(x: float) -> str:
    return repr(float(x)) if isinstance(x, float) else str(x)


def enrich(xml_text: bytes, logic: type[Controller], version: str) -> bytes:
    """Return the modelDescription ``xml_text`` completed from ``logic``'s ports."""
    root = ET.fromstring(xml_text)
    root.set("version", version)
    root.set("description", logic.DESCRIPTION)
    ports = {p.name: p for p in logic.PORTS}
    # The adapter's state hooks copy the whole controller: every hidden state round-trips.
    cosim = root.find("CoSimulation")
    variables = root.find("ModelVariables")
    structure = root.find("ModelStructure")
    assert cosim is not None and variables is not None and structure is not None, \
        "pythonfmu and fmi.native write CoSimulation, ModelVariables and ModelStructure"
    cosim.set("canGetAndSetFMUstate", "true")
    cosim.set("canSerializeFMUstate", "true")
    # The binary loads the Python runtime itself, as a library, in any host (fmi/c/python_model.c): no tool
    # has to run beside it.
    cosim.set("needsExecutionTool", "false")

    used_units = sorted({p.unit for p in logic.PORTS if p.unit})
    if used_units:
        defs = ET.Element("UnitDefinitions")
        for name in used_units:
            spec = dict(UNITS[name])
            unit = ET.SubElement(defs, "Unit", name=name)
            base = {k: str(spec[k]) for k in _BASE_UNIT_ORDER if k in spec}
            if "factor" in spec:
                base["factor"] = repr(spec["factor"])
            ET.SubElement(unit, "BaseUnit", base)
            for display, factor in DISPLAY_UNITS.get(name, []):
                ET.SubElement(unit, "DisplayUnit", name=display, factor=repr(factor))
        # The schema's order: CoSimulation, UnitDefinitions, TypeDefinitions, LogCategories, ...
        root.insert(list(root).index(cosim) + 1, defs)

    outputs_index = []
    for index, sv in enumerate(variables, start=1):
        port = ports[sv.get("name", "")]
        sv.set("description", port.description)
        sv.set("variability", port.fmi_variability)
        type_node = sv[0]
        if port.type == "Real" and port.unit:
            type_node.set("unit", port.unit)
        if port.type in ("Real", "Integer"):
            if port.min is not None:
                type_node.set("min", _fmt(port.min) if port.type == "Real" else str(int(port.min)))
            if port.max is not None:
                type_node.set("max", _fmt(port.max) if port.type == "Real" else str(int(port.max)))
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
    experiment.set("startTime", "0.0")
    experiment.set("stopTime", _fmt(float(logic.STOP_TIME)))
    experiment.set("stepSize", _fmt(float(logic.PERIOD)))
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)
