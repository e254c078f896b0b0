"""ncfmu and plain fmpy in one process: fmpy's C proxy that formats log messages keeps one logger per process,
and ncfmu's slaves register theirs; an FMU the user runs through fmpy's default callbacks afterwards still has
its messages printed as fmpy prints them (they were dropped), and nothing calls a freed logger."""

from __future__ import annotations

import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave

from ncfmu.cosim.fmu import FmuSlave, UnpackedFmu


def test_a_plain_fmpy_instance_still_prints_its_refusal_after_an_ncfmu_slave(fmus, tmp_path, capfd):
    ours = FmuSlave(UnpackedFmu(fmus["OperatorPanel"]), "ours")       # registers ncfmu's logger with fmpy's proxy
    md = read_model_description(str(fmus["OperatorPanel"]))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    plain = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(fmus["OperatorPanel"]), str(tmp_path)),
                      modelIdentifier="OperatorPanel", instanceName="plain")
    plain.instantiate()
    try:
        plain.setupExperiment(startTime=0.0)
        plain.enterInitializationMode()
        plain.exitInitializationMode()
        with pytest.raises(FMICallException):
            plain.setReal([vr["repeat_every"]], [5e-324])
        out = capfd.readouterr().out
        assert "[ERROR]" in out and "repeat_every" in out
    finally:
        plain.terminate()
        plain.freeInstance()
        ours.terminate()
