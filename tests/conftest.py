"""Session fixtures: the FMUs and SSP archives are built once per test run; each system runs once."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import settings

from ncfmu.systems import SYSTEMS

# Property tests are seeded: CI runs the same examples every time (a failure reproduces).
settings.register_profile("ncfmu", derandomize=True, print_blob=True)
settings.load_profile("ncfmu")

ROOT = Path(__file__).resolve().parents[1]


pytest_plugins = ["pytester"]


@pytest.fixture(scope="session")
def project(ncfmu_project):
    """Every FMU built (only what is stale) and every system packed, once: the plugin's fixture."""
    return ncfmu_project


@pytest.fixture(scope="session")
def fmus(project) -> dict[str, Path]:
    return {p.stem: p for p in project["fmus"]}


@pytest.fixture(scope="session", params=sorted(SYSTEMS))
def system(request) -> str:
    """Each system's name in turn (parametrised): for what holds for every system."""
    return request.param


# the default runs of single systems, by name (the plugin runs each once per session)
@pytest.fixture(scope="session")
def lathe_roughing(ncfmu_run):
    return ncfmu_run("lathe_roughing")


@pytest.fixture(scope="session")
def lathe_taper(ncfmu_run):
    return ncfmu_run("lathe_taper")


class FmuRunner:
    """One FMU instance stepped by hand through fmpy (for single-FMU tests)."""

    def __init__(self, fmu: Path, name: str = "dut"):
        from ncfmu.cosim.fmu import FmuSlave, UnpackedFmu
        self.unpacked = UnpackedFmu(fmu)
        self.slave = FmuSlave(self.unpacked, name)

    def start(self, **parameters):
        for k, v in parameters.items():
            self.slave.set_start(k, v)
        self.slave.initialize(0.0, 1e6)
        return self

    def set(self, **values):
        for k, v in values.items():
            self.slave.set_start(k, v)   # fmi2SetXxx: the same call for inputs during the run

    def get(self, name):
        return self.slave.get(name)

    def close(self):
        self.slave.terminate()
        self.unpacked.cleanup()


@pytest.fixture
def fmu_runner():
    opened = []

    def make(fmu: Path, name: str = "dut") -> FmuRunner:
        r = FmuRunner(fmu, name)
        opened.append(r)
        return r
    yield make
    for r in opened:
        r.close()


@pytest.fixture(scope="session")
def grinder_feed(ncfmu_run):
    return ncfmu_run("grinder_feed")


@pytest.fixture(scope="session")
def grinder_envelope(ncfmu_run):
    return ncfmu_run("grinder_envelope")


@pytest.fixture(scope="session")
def mill_contour(ncfmu_run):
    return ncfmu_run("mill_contour")


@pytest.fixture(scope="session")
def foreign(tmp_path_factory) -> dict[str, Path]:
    """The foreign FMUs of ``tests/foreign/`` (models written without ncfmu's code), compiled once per session."""
    import foreign_fmus
    return foreign_fmus.build(tmp_path_factory.mktemp("foreign"))
