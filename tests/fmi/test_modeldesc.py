"""The one modelDescription writer: both FMI versions say the same facts of every port (plain Python, no build)."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import pytest

from ncfmu.catalogue import models
from ncfmu.errors import BuildError
from ncfmu.fmi.modeldesc import TIME_VR, TYPES, log_categories, model_description

GUID, VERSION = "{00000000-0000-0000-0000-000000000000}", "0.0.0+test"


def _sources(name: str) -> tuple[str, ...]:
    return ("native_model.c", f"{name}.c")


@pytest.mark.parametrize("model", sorted(models()))
def test_fmi2_and_fmi3_say_the_same_of_every_port(model):
    logic = models()[model]
    sources = _sources(model)
    root2 = ET.fromstring(model_description(logic, "2.0", GUID, VERSION, native_sources=sources))
    root3 = ET.fromstring(model_description(logic, "3.0", GUID, VERSION, native_sources=sources))
    assert (root2.get("guid"), root3.get("instantiationToken")) == (GUID, GUID)
    units2 = {u.get("name"): ET.tostring(u) for u in root2.iter("Unit")}
    units3 = {u.get("name"): ET.tostring(u) for u in root3.iter("Unit")}
    assert units3 == {**units2, "s": units3["s"]}, "FMI 3.0 adds the time's unit only"
    for root in (root2, root3):
        assert [c.get("name") for c in root.iter("Category")] == log_categories()
        exp = root.find("DefaultExperiment")
        assert exp is not None and float(exp.get("stopTime", "nan")) == logic.STOP_TIME
        assert float(exp.get("stepSize", "nan")) == logic.PERIOD
    vars2 = {sv.get("name"): sv for sv in root2.iter("ScalarVariable")}
    variables3 = root3.find("ModelVariables")
    assert variables3 is not None
    vars3 = {v.get("name"): v for v in variables3}
    assert vars3.pop("time").get("valueReference") == str(TIME_VR)
    assert list(vars2) == list(vars3) == [p.name for p in logic.PORTS]
    for vr, port in enumerate(logic.PORTS):
        sv, v3 = vars2[port.name], vars3[port.name]
        typed = sv[0]
        assert (sv.get("valueReference"), v3.get("valueReference")) == (str(vr), str(vr))
        assert (typed.tag, v3.tag) == (port.type, TYPES[port.type])
        for attribute in ("description", "causality", "variability"):
            assert sv.get(attribute) == v3.get(attribute), (port.name, attribute)
        assert typed.get("unit") == v3.get("unit")
        for bound in ("min", "max"):
            assert (typed.get(bound) is None) == (v3.get(bound) is None), (port.name, bound)
            if typed.get(bound) is not None:
                assert float(typed.get(bound, "nan")) == float(v3.get(bound, "nan"))
        start_node = v3.find("Start")
        start3 = start_node.get("value") if start_node is not None else v3.get("start")
        if port.type == "Real" and start3 is not None:
            assert float(typed.get("start", "nan")) == float(start3), port.name
        else:
            assert typed.get("start") == start3, port.name
    outputs = [str(vr) for vr, p in enumerate(logic.PORTS) if p.causality == "output"]
    assert [u.get("valueReference") for u in root3.iter("Output")] == outputs
    outputs2 = root2.find("ModelStructure/Outputs")
    assert [str(int(u.get("index", "0")) - 1) for u in (outputs2 if outputs2 is not None else [])] == outputs


def test_an_unknown_fmi_version_is_refused_by_name():
    logic = models()["OperatorPanel"]
    with pytest.raises(BuildError, match=r"fmi_version = '1\.0': must be one of 2\.0, 3\.0"):
        model_description(logic, "1.0", GUID, VERSION)


def test_pythonfmus_file_with_another_guid_is_refused():
    logic = models()["OperatorPanel"]
    theirs = model_description(logic, "2.0", GUID, VERSION, native_sources=())
    with pytest.raises(BuildError, match="pythonfmu's modelDescription has guid"):
        model_description(logic, "2.0", "{other}", VERSION, pythonfmu_xml=theirs)


def test_a_change_to_the_writer_rebuilds_every_fmu(monkeypatch, tmp_path):
    """The writer is part of what every FMU is made from: its digest (the FMU's version) changes with it."""
    from pathlib import Path

    from ncfmu.fmi import builder, modeldesc, native
    writer = Path(modeldesc.__file__).resolve()
    script = tmp_path / "Model.py"
    script.write_text("class Model: pass\n")
    before = builder.source_digest(script), [m.digest() for m in native.native_models()]
    read = Path.read_bytes
    monkeypatch.setattr(Path, "read_bytes", lambda p: read(p) + (b"#" if p.resolve() == writer else b""))
    after = builder.source_digest(script), [m.digest() for m in native.native_models()]
    assert after[0] != before[0] and all(a != b for a, b in zip(after[1], before[1], strict=True))
