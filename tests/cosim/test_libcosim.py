"""Every system runs unchanged in libcosim (the independent FMI tool) and gives our trajectories."""

from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest
from conftest import ROOT
from physics import CHECKS

from ncfmu.cosim.libcosim import run_ssp
from ncfmu.systems import SYSTEMS, get_system

pytestmark = pytest.mark.slow        # whole systems in closed loop: not in the fast subset


@pytest.fixture(scope="session")
def libcosim_runs(project):
    """Every system's whole cycle in libcosim, two child processes at a time."""
    def run(name):
        return name, run_ssp(ROOT / "ssp" / f"{name}.ssp", get_system(name).stop_time)
    with ThreadPoolExecutor(max_workers=2) as pool:
        return dict(pool.map(run, SYSTEMS))


def test_libcosim_run_passes_the_physics_checks(libcosim_runs, system):
    CHECKS[system](libcosim_runs[system])


def test_our_gauss_seidel_run_passes_the_same_checks(ncfmu_run, system):
    CHECKS[system](ncfmu_run(system))


def test_jacobi_mode_reproduces_libcosim(libcosim_runs, ncfmu_run, system):
    theirs = libcosim_runs[system]
    ours = ncfmu_run(system, mode="jacobi")
    assert len(theirs.names) >= 10
    for variable in theirs.names:
        a, b = theirs[variable].astype(float), ours[variable].astype(float)
        assert np.abs(a - b).max() <= 1e-9, variable
