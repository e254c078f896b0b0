"""A user's FMU that dies takes nothing with it (issue 45): a foreign FMU runs in a process of its own
(:mod:`ncfmu.cosim.isolated`), and its crash -- SIGSEGV, abort(), exit(3), in fmi2DoStep, fmi2GetReal or
fmi3DoStep -- ends the run with a message naming the instance, the call and the simulated time, every whole row
before it on disk: ``ncfmu run`` exits 4 (not finished), a sweep's variant is ``failed`` and the sweep goes on, a
served run is faulted (Simulation.state) with its rows kept. The crashing FMUs are
tests/foreign/crashing_axis.c (``CrashingAxis``, ``CrashingAxis3``: PlantAxis with a bug).

Each crash runs in a subprocess: on a master that runs foreign FMUs in its own process, the crash kills it.
"""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from foreign_fmus import packed, with_plant

from ncfmu.errors import SimulationError
from ncfmu.project import OpenSystem

HERE = Path(__file__).resolve().parent
#: the CSV's output interval in the runs below, s (lathe_taper steps at 1 ms)
INTERVAL = 0.01


def _ncfmu(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "ncfmu.cli", *args], capture_output=True, text=True, timeout=300,
                          cwd=cwd)


def _times(csv_path: Path) -> np.ndarray:
    with open(csv_path, newline="") as f:
        rows = list(csv.reader(f))
    assert rows[0][0] == "time"
    return np.array([float(r[0]) for r in rows[1:]])


@pytest.fixture(scope="module")
def crashing_taper(foreign, project, tmp_path_factory) -> Path:
    """lathe_taper with its x axis the foreign CrashingAxis (z stays ncfmu's own ServoAxis)."""
    return packed(with_plant("lathe_taper", "CrashingAxis", axes=("x_axis",)), foreign,
                  tmp_path_factory.mktemp("crashing"))


@pytest.mark.parametrize("model, crash_in, how, at, call, ended, rows", [
    # fmi2DoStep of the step that starts at crash_at: the row at crash_at is whole (every FMU made that step)
    ("CrashingAxis", 0, 1, 1.0, "fmi2DoStep", "its process was killed by SIGSEGV", 101),
    ("CrashingAxis3", 0, 3, 0.75, "fmi3DoStep", "its process exited with status 3", 76),
    # fmi2GetReal after the step that reached crash_at: the row at crash_at is not whole, the rows before are
    ("CrashingAxis", 1, 2, 1.0, "fmi2GetReal", "its process was killed by SIGABRT", 100),
])
def test_a_crash_in_a_foreign_fmu_ends_ncfmu_run_with_exit_4_and_keeps_every_row_before(
        foreign, project, tmp_path, model, crash_in, how, at, call, ended, rows):
    out = tmp_path / "out"
    done = _ncfmu("run", "lathe_taper", "--replace", f"x_axis={foreign[model]}", "--out", str(out),
                  "--stop-time", "2", "--output-interval", str(INTERVAL), "--set", f"x_axis.crash_in={crash_in}",
                  "--set", f"x_axis.crash_how={how}", "--set", f"x_axis.crash_at={at}", cwd=tmp_path)
    assert done.returncode == 4, done.stderr
    partial = out / "lathe_taper.csv.partial"
    assert done.stderr.strip().splitlines()[-1] == (
        f"ncfmu run: x_axis: the FMU crashed in {call} at t = {at:g} s ({ended}): {rows} rows up to "
        f"t = {(rows - 1) * INTERVAL:.3f} s in {partial} (the run did not finish)")
    times = _times(partial)
    # every row up to the crash, on the output interval, none after it
    assert np.array_equal(np.round(times / INTERVAL).astype(int), np.arange(rows))
    assert not (out / "lathe_taper.csv").exists()


def test_a_sweep_variant_whose_fmu_crashes_is_failed_and_the_sweep_goes_on(crashing_taper, tmp_path):
    out = tmp_path / "sweep"
    done = _ncfmu("sweep", str(crashing_taper), "--vary", "x_axis.crash_at=100,0.25,200", "--stop-time", "0.5",
                  "--workers", "0", "--out", str(out), cwd=tmp_path)
    assert done.returncode == 4, done.stderr            # a variant not ok: not finished
    with open(out / "summary.csv", newline="") as f:
        rows = {r["x_axis.crash_at"]: r for r in csv.DictReader(f)}
    assert rows["0.25"]["status"] == "failed"
    assert rows["0.25"]["error"] == "x_axis: the FMU crashed in fmi2DoStep at t = 0.25 s (its process was killed " \
                                    "by SIGSEGV)"
    # the variants before and after it ran to their stop time (the taper cycle takes longer than 0.5 s), the one
    # after it in a new process, with the same rows (crash_at changes nothing before it comes)
    for after in ("100", "200"):
        assert rows[after]["status"] == "unfinished" and rows[after]["error"] == "cycle not finished by t = 0.5 s"
    before, after = ((out / "variants" / f"{rows[k]['key']}.csv").read_bytes() for k in ("100", "200"))
    assert before == after and _times(out / "variants" / f"{rows['200']['key']}.csv")[-1] == pytest.approx(0.5)


def test_a_served_run_whose_fmu_crashes_fails_with_the_crash_and_keeps_its_rows(crashing_taper, tmp_path):
    out = tmp_path / "served"
    done = subprocess.run([sys.executable, str(HERE / "crash_host.py"), str(crashing_taper), str(out), "0.2"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    served = json.loads(done.stdout.strip().splitlines()[-1])
    assert not served["timed_out"]
    assert served["state"] == "faulted"
    assert served["reason"] == "x_axis: the FMU crashed in fmi2DoStep at t = 0.2 s (its process was killed by SIGSEGV)"
    # every step before the crash recorded (the served CSV records every step), the session left unfinished
    times = _times(out / "lathe_taper.csv.partial")
    assert np.array_equal(np.round(times / 0.001).astype(int), np.arange(201))


def test_an_isolated_foreign_fmu_gives_bit_identical_results(foreign, project, tmp_path):
    from ncfmu.cosim.isolated import IsolatedSlave
    archive = packed(with_plant("lathe_taper", "PlantAxis"), foreign, tmp_path)
    runs = []
    for isolate in (True, False):
        with OpenSystem(archive, isolate=isolate) as opened:
            isolated_axes = [s.name for s in opened.slaves if isinstance(s, IsolatedSlave)]
            assert isolated_axes == (["x_axis", "z_axis"] if isolate else [])     # the controllers stay in process
            runs.append(opened.run(stop_time=0.5))
    isolated, in_process = runs
    assert isolated.names == in_process.names and len(isolated.time) == 501
    assert isolated.data.tobytes() == in_process.data.tobytes()
    assert np.ptp(isolated["x_axis.pos"]) > 0.1          # the axes moved: the comparison compares something


def test_an_fmu_error_crosses_the_process_as_it_reads_in_process(foreign, project, tmp_path):
    """A refusal the FMU reports (fmi2Error at initialisation, its log line) is the same SimulationError."""
    archive = packed(with_plant("lathe_taper", "PlantAxis"), foreign, tmp_path)
    said = []
    for isolate in (True, False):
        with OpenSystem(archive, isolate=isolate) as opened, pytest.raises(SimulationError) as err:
            opened.run(stop_time=0.01, start_values={"x_axis.vel_max": 0.0})
        said.append(str(err.value))
    assert said[0] == said[1] and "vel_max must be > 0" in said[0]
