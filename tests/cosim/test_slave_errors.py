"""The slave error contract (cosim/slave.py): nothing but ConfigError and SimulationError escapes a slave --
fmpy's exceptions (FMICallException, and the plain Exception its wrappers raise when an instantiation returns
NULL or the binary cannot be loaded) become SimulationError naming the instance and what failed, for FMI 2.0
(FmuSlave) and FMI 3.0 (Fmu3Slave) alike."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from ncfmu.cosim.fmu import UnpackedFmu
from ncfmu.cosim.instances import make_slave
from ncfmu.errors import SimulationError


@pytest.fixture(scope="module")
def fmus3(project):
    return {p.stem: p for p in project["fmi3"]}


def _unpacked(fmu: Path, broken: str) -> UnpackedFmu:
    unpacked = UnpackedFmu(fmu)
    if broken == "no_resources":                  # the binary refuses the instantiation (returns NULL)
        shutil.rmtree(unpacked.directory / "resources")
    else:                                         # no binary to load
        for binary in (unpacked.directory / "binaries").rglob("*.so"):
            binary.unlink()
    return unpacked


@pytest.mark.parametrize("broken", ["no_resources", "no_binary"])
@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("model", ["CutSequencer", "ServoAxis"])
def test_a_failed_instantiation_is_a_simulation_error_naming_the_instance(fmus, fmus3, model, version, broken):
    unpacked = _unpacked((fmus if version == 2 else fmus3)[model], broken)
    try:
        with pytest.raises(SimulationError, match=r"^dut: fmi[23]Instantiate"):
            make_slave(unpacked, "dut")
    finally:
        unpacked.cleanup()
