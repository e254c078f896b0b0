"""pytest plugin (entry point ``pytest11``): fixtures for users' closed-loop checks.

Fixtures
--------
ncfmu_project
    Session: builds what is missing or stale (FMUs in fmus/, systems in ssp/) once; the artefact paths.
ncfmu_run
    Session: ``ncfmu_run(system, stop_time=None, start_values=None, input_csv=None, mode="gauss-seidel")``
    runs a system closed loop through the FMUs and returns the Result; identical calls share one run.
ncfmu_checks
    The :mod:`ncfmu.checks` module (``assert_reaches``, ``assert_no_motion``, ``assert_inside_envelope``,
    ``assert_alarm``).

Example::

    def test_finish_pass(ncfmu_run, ncfmu_checks):
        r = ncfmu_run("lathe_roughing")
        ncfmu_checks.assert_reaches(r, "x_axis.pos", 25.9, band=0.002)
"""

from __future__ import annotations

import json

import pytest


@pytest.fixture(scope="session")
def ncfmu_project():
    from ncfmu.project import build
    return build(only_stale=True)


@pytest.fixture(scope="session")
def ncfmu_run(ncfmu_project):
    from ncfmu.project import simulate
    cache: dict[str, object] = {}

    def run(system: str = "lathe_roughing", stop_time: float | None = None, start_values: dict | None = None,
            input_csv=None, mode: str = "gauss-seidel"):
        key = json.dumps([system, stop_time, sorted((start_values or {}).items()), str(input_csv), mode],
                         default=str)
        if key not in cache:
            cache[key] = simulate(system, stop_time=stop_time, start_values=start_values, input_csv=input_csv,
                                  mode=mode)
        return cache[key]
    return run


@pytest.fixture(scope="session")
def ncfmu_checks():
    from ncfmu import checks
    return checks
