"""A foreign FMU's variables share a value reference only as aliases (issue 45): a collision between variables of
different causality or type is refused at load, naming both; aliases load as FMI permits."""

from __future__ import annotations

import re
import zipfile

import pytest

from ncfmu.cosim.fmu import UnpackedFmu
from ncfmu.errors import SystemDefinitionError


def with_description(src, dst, change):
    """The FMU ``src`` with its modelDescription.xml changed by ``change`` (text -> text), at ``dst``."""
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "modelDescription.xml":
                changed = change(data.decode())
                assert changed != data.decode()
                data = changed.encode()
            zout.writestr(item, data)
    return dst


def described(tmp_path, version: str, variables: str, structure: str):
    """An FMU of only a modelDescription (loading reads no binary)."""
    token = "instantiationToken" if version == "3.0" else "guid"
    md = (f'<?xml version="1.0" encoding="UTF-8"?>\n<fmiModelDescription fmiVersion="{version}" modelName="Other" '
          f'{token}="{{00000000-0000-0000-0000-000000000000}}"><CoSimulation modelIdentifier="Other"/>'
          f'<ModelVariables>{variables}</ModelVariables><ModelStructure>{structure}</ModelStructure>'
          '</fmiModelDescription>')
    fmu = tmp_path / "Other.fmu"
    with zipfile.ZipFile(fmu, "w") as z:
        z.writestr("modelDescription.xml", md)
    return fmu


def real2(name: str, vr: int, causality: str, kind: str = "Real") -> str:
    extra = ' initial="calculated"' if causality in ("output", "local") else ""
    start = ' start="0"' if causality in ("input", "parameter") else ""
    variability = "fixed" if causality == "parameter" else "continuous" if kind == "Real" else "discrete"
    return (f'<ScalarVariable name="{name}" valueReference="{vr}" causality="{causality}" '
            f'variability="{variability}"{extra}><{kind}{start}/></ScalarVariable>')


def test_the_plant_whose_command_is_its_position_is_refused_naming_both(foreign, tmp_path):
    """The reported case: PlantAxis with pos_cmd (input) on pos's value reference loaded, ran and alarmed."""
    on_pos = 'name="pos_cmd" valueReference="2"'
    bad = with_description(foreign["PlantAxis"], tmp_path / "PlantAxis.fmu",
                           lambda xml: xml.replace('name="pos_cmd" valueReference="0"', on_pos))
    with pytest.raises(SystemDefinitionError) as err:
        UnpackedFmu(bad, tmp_path / "x")
    assert str(err.value).startswith("PlantAxis.fmu: variables pos_cmd (input Real) and pos (output Real) share "
                                     "value reference 2: only aliases may"), err.value
    assert set(UnpackedFmu(foreign["PlantAxis"], tmp_path / "y").variables) >= {"pos", "pos_cmd"}   # as built


@pytest.mark.parametrize("first, second, says", [
    (real2("gain", 0, "parameter"), real2("y", 0, "output"),
     "variables gain (parameter Real) and y (output Real) share value reference 0"),
    (real2("mode", 3, "input", "Integer"), real2("count", 3, "output", "Integer"),
     "variables mode (input Integer) and count (output Integer) share value reference 3"),
])
def test_fmi2_collisions_of_causality_are_refused(tmp_path, first, second, says):
    fmu = described(tmp_path, "2.0", first + second, '<Outputs><Unknown index="2" dependencies=""/></Outputs>')
    with pytest.raises(SystemDefinitionError, match=re.escape(says)):
        UnpackedFmu(fmu, tmp_path / "x")


def test_fmi2_aliases_and_value_references_of_other_types_load(tmp_path):
    """A local alias of an output and an output under two names are one value, as FMI 2.0 permits; a Boolean on a
    Real's value reference is another variable (FMI 2.0 keeps value references per base type)."""
    variables = (real2("pos", 0, "output") + real2("pos_alias", 0, "output") + real2("pos_local", 0, "local")
                 + real2("enable", 0, "input", "Boolean"))
    fmu = described(tmp_path, "2.0", variables,
                    '<Outputs><Unknown index="1" dependencies=""/><Unknown index="2" dependencies=""/></Outputs>')
    loaded = UnpackedFmu(fmu, tmp_path / "x")
    assert {n: v.vr for n, v in loaded.variables.items()} == {"pos": 0, "pos_alias": 0, "pos_local": 0, "enable": 0}


def test_fmi3_collisions_are_refused_and_declared_aliases_load(tmp_path):
    time = '<Float64 name="time" valueReference="9" causality="independent" variability="continuous"/>'
    clash = (time + '<Float64 name="pos_cmd" valueReference="0" causality="input" variability="continuous" start="0"/>'
             '<Float64 name="pos" valueReference="0" causality="output" variability="continuous"/>')
    with pytest.raises(SystemDefinitionError, match='"pos".* the same value reference as variable "pos_cmd"'):
        UnpackedFmu(described(tmp_path, "3.0", clash, '<Output valueReference="0"/>'), tmp_path / "x")
    types = (time + '<Float64 name="x" valueReference="0" causality="output" variability="continuous"/>'
             '<Int32 name="n" valueReference="0" causality="output" variability="discrete"/>')
    with pytest.raises(SystemDefinitionError, match='"n".* the same value reference as variable "x"'):
        UnpackedFmu(described(tmp_path, "3.0", types, '<Output valueReference="0"/>'), tmp_path / "z")
    alias = time + ('<Float64 name="pos" valueReference="0" causality="output" variability="continuous">'
                    '<Alias name="pos_alias"/></Float64>')
    loaded = UnpackedFmu(described(tmp_path, "3.0", alias, '<Output valueReference="0"/>'), tmp_path / "y")
    assert {n: v.vr for n, v in loaded.variables.items()} == {"pos": 0, "pos_alias": 0}
