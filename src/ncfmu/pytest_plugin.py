"""pytest plugin (entry point ``pytest11``): fixtures for users' closed-loop checks.

Fixtures
--------
ncfmu_project
    Session: builds what is missing or stale (FMUs in fmus/, systems in ssp/) once; the artefact paths.
ncfmu_run
    Session: ``ncfmu_run(system, stop_time=None, start_values=None, input_csv=None, mode="gauss-seidel",
    tolerance=0.01, nose_radius=None, max_depth=None, drawing=None)`` runs a system closed loop through the FMUs
    and returns the Result; identical calls share one run. ``result.part`` is the part check's verdict of a lathe
    or mill run (``within_tolerance``, ``crashes``, ``max_left_mm``, ``max_gouge_mm``, ...; judged on first use
    with the call's tolerance and tool -- None: the tool table's -- and against the part drawn in ``drawing``, a
    DXF file's path, in place of the programmed part), None for a system without one.
ncfmu_checks
    The :mod:`ncfmu.checks` module (``assert_reaches``, ``assert_no_motion``, ``assert_inside_envelope``,
    ``assert_alarm``).
ncfmu_serve
    ``ncfmu_serve(system, *options)`` starts ``ncfmu serve SYSTEM *options`` as a process on a free port of
    127.0.0.1 and returns a :class:`ServedSystem` (``endpoint``, ``namespace``, ``stop()``): the test plays
    the PLC with an OPC UA client (asyncua). Every server still running is stopped after the test.

Example::

    def test_finish_pass(ncfmu_run, ncfmu_checks):
        r = ncfmu_run("lathe_roughing")
        ncfmu_checks.assert_reaches(r, "x_axis.pos", 25.9, band=0.002)
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import threading
from pathlib import Path

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
            input_csv=None, mode: str = "gauss-seidel", tolerance: float = 0.01, nose_radius: float | None = None,
            max_depth: float | None = None, drawing=None):
        from ncfmu.systems.part import PartSettings
        key = json.dumps([system, stop_time, sorted((start_values or {}).items()), str(input_csv), mode],
                         default=str)
        if key not in cache:
            cache[key] = simulate(system, stop_time=stop_time, start_values=start_values, input_csv=input_csv,
                                  mode=mode)
        result = cache[key]
        part_drawn = None
        if drawing is not None:
            from ncfmu.systems.drawing import read_drawing
            part_drawn = read_drawing(drawing)
        settings = PartSettings(tolerance, nose_radius, max_depth, part_drawn)
        result.part = PartView(result, settings)  # type: ignore[attr-defined]
        return result
    return run


class PartView:
    """``result.part``: the part check's verdict (:class:`ncfmu.systems.part.PartVerdict`) of a run, judged on
    first use; ``bool(result.part)`` is False for a system without a part check."""

    def __init__(self, result, settings) -> None:
        self._result, self._settings = result, settings
        self._verdict: object = None
        self._judged = False

    def verdict(self):
        if not self._judged:
            from ncfmu.systems import report_of, run_parameters
            from ncfmu.systems.part import verdict_of_result, with_part_settings
            report = with_part_settings(report_of(self._result), self._settings)
            self._verdict = verdict_of_result(report, self._result, run_parameters(self._result))
            self._judged = True
        return self._verdict

    def __bool__(self) -> bool:
        return self.verdict() is not None

    def __getattr__(self, name: str):
        if name.startswith("_"):
            raise AttributeError(name)
        verdict = self.verdict()
        if verdict is None:
            raise AttributeError(f"{self._result.system}: no part check (not a lathe, grinder or mill)")
        return getattr(verdict, name)


@pytest.fixture(scope="session")
def ncfmu_checks():
    from ncfmu import checks
    return checks


class ServedSystem:
    """An ``ncfmu serve`` process: its endpoint, OPC UA namespace, output so far, and how to stop it."""

    def __init__(self, system: str, options: tuple[str, ...], cwd: Path | None = None, timeout: float = 120.0):
        with socket.socket() as probe:          # a free port (the server binds it a moment later)
            probe.bind(("127.0.0.1", 0))
            port = probe.getsockname()[1]
        self.system = system
        self.endpoint = f"opc.tcp://127.0.0.1:{port}/ncfmu"
        self.namespace = f"urn:ncfmu:{Path(system).stem}"
        self.lines: list[str] = []
        self.process = subprocess.Popen(
            [sys.executable, "-m", "ncfmu.cli", "serve", system, "--endpoint", self.endpoint, *options],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=cwd,
            env={**os.environ, "PYTHONUNBUFFERED": "1"})
        self._ready = threading.Event()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        if not self._ready.wait(timeout) or self.process.poll() is not None:
            output = self.output
            self.kill()
            raise RuntimeError(f"ncfmu serve {system} did not come up:\n{output}")

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            self.lines.append(line.rstrip("\n"))
            if " at opc.tcp://" in line:
                self._ready.set()
        self._ready.set()

    @property
    def output(self) -> str:
        return "\n".join(self.lines)

    def stop(self, timeout: float = 60.0) -> int:
        """SIGTERM (what Ctrl-C does) and wait: the exit status."""
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
        return self.wait(timeout)

    def wait(self, timeout: float = 60.0) -> int:
        rc = self.process.wait(timeout)
        self._reader.join(5)
        return rc

    def kill(self) -> None:
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait(10)


@pytest.fixture
def ncfmu_serve(ncfmu_project):
    served: list[ServedSystem] = []

    def start(system: str = "lathe_roughing", *options: str) -> ServedSystem:
        s = ServedSystem(system, tuple(str(o) for o in options))
        served.append(s)
        return s
    yield start
    for s in served:
        try:
            s.stop(30)
        except subprocess.TimeoutExpired:
            s.kill()
