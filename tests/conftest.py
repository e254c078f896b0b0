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


# fmpy's logger proxy (fmpy.logging.addLoggerProxy, which formats an FMU's printf-style messages) keeps the last
# logger it was given in one process-wide global, and every FMU2Slave made with fmpy's default callbacks logs through
# it. A test that hands it a short-lived logger (its own callbacks, or simulate_fmu(logger=...)) leaves that global
# dangling when the logger is freed, and the next FMU that logs in this process calls freed memory (a segfault in
# whatever test comes next). After every test the global points back at a logger that lives as long as the process
# (given anew each time: the proxy ignores callbacks whose logger is already the proxy).
def _printer():
    import fmpy.fmi2 as fmi2
    return fmi2.fmi2CallbackLoggerTYPE(fmi2.printLogMessage)


_PRINTER = _printer()


@pytest.fixture(autouse=True)
def _logger_proxy_points_at_a_living_logger():
    yield
    from ctypes import byref

    import fmpy.fmi2 as fmi2
    from fmpy.logging import addLoggerProxy
    callbacks = fmi2.fmi2CallbackFunctions()
    callbacks.logger = _PRINTER
    addLoggerProxy(byref(callbacks))
