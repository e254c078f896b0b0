"""Robust loading: bad archives and system definitions are refused with the names involved, before running."""

import zipfile

import pytest

from ncfmu.errors import SystemDefinitionError
from ncfmu.project import OpenSystem, system_archive


def rewrite(src, dst, change_ssd=None, drop=(), add=()):
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w") as zout:
        for item in zin.infolist():
            if item.filename in drop:
                continue
            data = zin.read(item.filename)
            if item.filename == "SystemStructure.ssd" and change_ssd:
                data = change_ssd(data.decode()).encode()
            zout.writestr(item.filename, data)
        for name, data in add:
            zout.writestr(name, data)
    return dst


@pytest.mark.parametrize("entry", ["../escaped.txt", "/tmp/absolute.txt", "resources/../../escaped.txt"])
def test_entry_escaping_the_extraction_folder_is_refused(project, tmp_path, entry):
    bad = rewrite(system_archive("lathe_taper"), tmp_path / "bad.ssp", add=[(entry, b"x")])
    with pytest.raises(SystemDefinitionError, match="outside the extraction folder"):
        OpenSystem(bad)
    assert not (tmp_path.parent / "escaped.txt").exists()


def test_missing_fmu_is_named(project, tmp_path):
    bad = rewrite(system_archive("lathe_taper"), tmp_path / "bad.ssp", drop={"resources/AreaLimiter.fmu"})
    with pytest.raises(SystemDefinitionError, match="FMU not found: .*AreaLimiter.fmu"):
        OpenSystem(bad)


def test_unknown_connector_is_named(project, tmp_path):
    bad = rewrite(system_archive("lathe_taper"), tmp_path / "bad.ssp",
                  change_ssd=lambda s: s.replace('startConnector="x_cmd"', 'startConnector="x_command"'))
    with pytest.raises(SystemDefinitionError, match="seq has no variable 'x_command'"):
        OpenSystem(bad)


def test_type_mismatch_is_named(project, tmp_path):
    bad = rewrite(system_archive("lathe_taper"), tmp_path / "bad.ssp",
                  change_ssd=lambda s: s.replace('startElement="panel" startConnector="start"',
                                                 'startElement="seq" startConnector="subcycle"'))
    with pytest.raises(SystemDefinitionError, match=r"seq.subcycle -> seq.start: type mismatch \(Integer -> Boolean\)"):
        OpenSystem(bad)


@pytest.mark.parametrize("version, kind, says", [
    ("3.0", "CoSimulation", "variable x is an FMI 3.0 Float32: not supported"),
    ("3.0", "ModelExchange", "a model-exchange-only FMU"),
    ("2.0", "ModelExchange", "a model-exchange-only FMU"),
])
def test_fmus_the_master_cannot_run_are_named(tmp_path, version, kind, says):
    """An SSP may reference an FMU the master cannot run (model exchange only; an FMI 3.0 type it does not run):
    a clear error, not a KeyError."""
    import zipfile

    from ncfmu.cosim.fmu import UnpackedFmu
    from ncfmu.errors import SystemDefinitionError
    variables = ('<ModelVariables><Float64 name="time" valueReference="1" causality="independent"/>'
                 '<Float32 name="x" valueReference="0" causality="output"/></ModelVariables>'
                 '<ModelStructure><Output valueReference="0"/></ModelStructure>' if version == "3.0" else
                 '<ModelVariables><ScalarVariable name="x" valueReference="0" causality="output" '
                 'variability="discrete"><Real/></ScalarVariable></ModelVariables>'
                 '<ModelStructure><Outputs><Unknown index="1"/></Outputs></ModelStructure>')
    md = (f'<?xml version="1.0" encoding="UTF-8"?>\n<fmiModelDescription fmiVersion="{version}" modelName="Other" '
          f'{"instantiationToken" if version == "3.0" else "guid"}="{{00000000-0000-0000-0000-000000000000}}">'
          f'<{kind} modelIdentifier="Other"/>{variables}</fmiModelDescription>')
    fmu = tmp_path / "Other.fmu"
    with zipfile.ZipFile(fmu, "w") as z:
        z.writestr("modelDescription.xml", md)
    with pytest.raises(SystemDefinitionError) as err:
        UnpackedFmu(fmu, tmp_path / "x")
    assert "Other.fmu" in str(err.value) and says in str(err.value)
