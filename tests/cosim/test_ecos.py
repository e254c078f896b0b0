"""ecos (pip ``ecospy``), another independent FMI/SSP host, runs our packed .ssp archives unchanged
from its command line, applies the systems' .ssv parameter set, and gives ncfmu's Jacobi trajectories.

ecos steps every FMU, then exchanges values (Jacobi), like libcosim; its CSV holds reals with six
decimals, so the comparison is to 2e-6 absolute (rounding is at most 5e-7) and exact for Integers and
Booleans. The CLI is run as README says (plus ``--csvConfig`` to pick the variables and ``-l debug`` for
the parameter-set log line), in a child process with its own working directory (it writes
``<cwd>/<ssp stem>.csv``), with no help from the environment; a non-zero exit fails the system's tests.
"""

from __future__ import annotations

import re
import signal
import subprocess
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT

from ncfmu.cosim import ecos
from ncfmu.cosim.ssp import PARAMETER_SET, read_ssp
from ncfmu.project import simulate

pytestmark = pytest.mark.slow        # whole systems in closed loop: not in the fast subset

STEP = 1e-3
TOL = 2e-6   # ecos writes reals with 6 decimals (std::to_string): 5e-7 rounding, nothing else allowed

#: system -> (stop time, variables compared at every common time point). The stop times cover real
#: motion and cost a few seconds each: lathe_taper rapids in, cuts pass 1 along the taper, retracts,
#: returns and starts pass 2 (11.8 s); grinder_feed rapids to 4.0, rough-grinds and enters the fine
#: feed at 4.2 (10.5 s).
CASES = {
    "lathe_taper": (12.0, ["x_axis.pos", "z_axis.pos", "x_axis.following_error", "seq.x_cmd", "seq.z_cmd",
                           "seq.x_vff", "seq.z_vff", "limiter.lim_cmd", "limiter.ref_cmd", "seq.subcycle",
                           "seq.pass_no", "seq.busy", "panel.start"]),
    "grinder_feed": (11.0, ["x_axis.pos", "x_axis.following_error", "feed.x_cmd", "feed.x_vff",
                            "feed.dwell_left", "feed.pc", "feed.busy", "panel.start"]),
    # the other systems, shorter: every .ssp runs in ecos with its parameters, as in ncfmu's Jacobi mode
    "lathe_roughing": (6.0, ["x_axis.pos", "z_axis.pos", "seq.x_cmd", "seq.z_cmd", "seq.subcycle",
                             "limiter.ref_cmd"]),
    "grinder_envelope": (6.0, ["x_axis.pos", "y_axis.pos", "feed.x_cmd", "feed.y_cmd", "limiter.ref_cmd"]),
    "mill_contour": (4.0, ["x_axis.pos", "y_axis.pos", "contour.x_cmd", "contour.y_cmd", "contour.x_vff"]),
}
#: How far each system's axes must travel in the compared window (mm): the runs are not standing still.
TRAVEL = {"lathe_taper": {"x_axis.pos": 1.5, "z_axis.pos": 40.0}, "grinder_feed": {"x_axis.pos": 4.1},
          "lathe_roughing": {"x_axis.pos": 1.4, "z_axis.pos": 20.0},
          "grinder_envelope": {"x_axis.pos": 140.0, "y_axis.pos": 390.0},
          "mill_contour": {"x_axis.pos": 9.0, "y_axis.pos": 9.0}}


@pytest.fixture(scope="session")
def ecos_exe(tmp_path_factory) -> Path:
    """The ecos CLI shipped in ecospy, copied and made executable (the wheel ships it without +x)."""
    try:
        return ecos.ecos_program(tmp_path_factory.mktemp("ecos_bin") / "ecos")
    except FileNotFoundError as err:
        pytest.fail(str(err))


def _csv_config(system, compared: list[str]) -> tuple[str, list[str]]:
    """An ecos CSV config logging the compared variables and every non-String .ssv parameter."""
    logged: dict[str, list[str]] = {}
    for qualified in compared:
        inst, var = qualified.split(".", 1)
        logged.setdefault(inst, []).append(var)
    for comp in system.components:
        logged.setdefault(comp.name, []).extend(k for k, v in comp.parameters.items() if not isinstance(v, str))
    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             '<ecos:CsvConfig xmlns:ecos="https://github.com/Ecos-platform/ecos">', "  <ecos:components>"]
    for inst, names in logged.items():
        lines.append(f'    <ecos:component name="{inst}">')
        lines += [f'      <ecos:variable name="{n}"/>' for n in names]
        lines.append("    </ecos:component>")
    lines += ["  </ecos:components>", "</ecos:CsvConfig>", ""]
    return "\n".join(lines), [f"{i}.{n}" for i, ns in logged.items() for n in ns]


class EcosRun:
    def __init__(self, name: str, columns: dict[str, np.ndarray], log: str, wall: float):
        self.name, self.columns, self.log, self.wall = name, columns, log, wall

    def __getitem__(self, qualified: str) -> np.ndarray:
        return self.columns[qualified]


def run_ecos(exe: Path, name: str, stop_time: float, compared: list[str], workdir: Path) -> EcosRun:
    archive = ROOT / "ssp" / f"{name}.ssp"
    config, wanted = _csv_config(read_ssp(archive), compared)
    (workdir / "csv.xml").write_text(config)
    # ecos stops one step short of --stopTime: ask for half a step more.
    cmd = [str(exe), "simulate", "--path", str(archive), "--stopTime", repr(stop_time + STEP / 2),
           "--stepSize", repr(STEP), "--parameterSet", PARAMETER_SET, "--csvConfig", "csv.xml", "-l", "debug"]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=workdir, capture_output=True, text=True, timeout=600, env=ecos.environment())
    wall = time.perf_counter() - t0
    log = proc.stdout + proc.stderr
    rc = proc.returncode
    why = f"killed by {signal.Signals(-rc).name}" if rc < 0 else f"exit status {rc}"
    hint = " (ecos needs libtbb.so.12: pip's tbb wheel, a test extra)" if "libtbb" in log else ""
    assert rc == 0, f"ecos on {name}: {why}{hint}; its output ends:\n{log[-3000:]}"
    # ecos goes on (and may exit 0) when an FMU call fails: any warning, error or line that is not
    # ecos's own log (an FMU's or the C library's stderr) is a failure, and so is an FMU's own error or
    # warning (ecos logs those at debug level: "[debug] [<fmu>] fmi2Error ...").
    bad = [line for line in log.splitlines()
           if line.strip() and (not line.startswith("[") or any(f"] [{lvl}]" in line for lvl in
                                                                  ("warn", "warning", "error", "critical"))
                                or re.search(r"\] fmi2(Warning|Discard|Error|Fatal) ", line))]
    assert not bad, f"ecos on {name} reported {len(bad)} problem lines, the first:\n" + "\n".join(bad[:5])
    csv = workdir / f"{name}.csv"
    assert csv.is_file(), f"ecos wrote no {csv.name}; its output ends:\n{log[-3000:]}"
    with csv.open() as f:
        header = [h.strip() for h in f.readline().split(",")]
    data = np.loadtxt(csv, delimiter=",", skiprows=1, ndmin=2)
    assert data.shape[1] == len(header), "ecos CSV rows and header disagree"
    columns = {}
    for j, h in enumerate(header):
        if h in ("iterations", "time"):
            columns[h] = data[:, j]
        else:
            inst, var = h.rsplit("[", 1)[0].split("::", 1)   # "x_axis::pos[REAL]"
            columns[f"{inst}.{var}"] = data[:, j]
    missing = [q for q in wanted if q not in columns]
    assert not missing, f"ecos did not log {missing}"
    return EcosRun(name, columns, log, wall)


@pytest.fixture(scope="session")
def ecos_runs(project, ecos_exe, tmp_path_factory):
    """Both systems in ecos, two child processes at a time, each in its own working directory.

    ``ecos_runs(name)`` is that system's run; a failed run fails only the tests of its system.
    """
    def run(name):
        stop, compared = CASES[name]
        try:
            return name, run_ecos(ecos_exe, name, stop, compared, tmp_path_factory.mktemp(f"ecos_{name}"))
        except AssertionError as failure:
            return name, failure
    with ThreadPoolExecutor(max_workers=2) as pool:
        runs = dict(pool.map(run, CASES))

    def get(name: str) -> EcosRun:
        if isinstance(runs[name], AssertionError):
            raise runs[name]
        return runs[name]
    return get


@pytest.fixture(scope="session")
def jacobi_runs(project):
    """ncfmu's own master, Jacobi mode, on the same packed archives and windows."""
    return {name: simulate(str(ROOT / "ssp" / f"{name}.ssp"), stop_time=stop, mode="jacobi")
            for name, (stop, _) in CASES.items()}


@pytest.mark.parametrize("name", sorted(CASES))
def test_ecos_reproduces_our_jacobi_run(ecos_runs, jacobi_runs, name):
    theirs, ours = ecos_runs(name), jacobi_runs[name]
    stop, compared = CASES[name]
    n = int(round(stop / STEP))
    assert len(theirs["iterations"]) == n + 1, "ecos did not run the whole window"
    assert len(ours.time) == n + 1
    assert np.array_equal(theirs["iterations"], np.arange(n + 1))
    assert np.abs(theirs["time"] - ours.time).max() <= 1e-9
    for q in compared:
        a, b = theirs[q], ours[q].astype(float)
        if ours.data.dtype[q] == np.float64:
            err = np.abs(a - b)
            assert err.max() <= TOL, f"{q}: off by {err.max():.3g} at t = {ours.time[err.argmax()]:.3f} s"
        else:
            wrong = np.flatnonzero(a != b)
            assert not len(wrong), f"{q}: {a[wrong[0]]} in ecos, {b[wrong[0]]} here at t = {ours.time[wrong[0]]:.3f} s"
    for q, least in TRAVEL[name].items():
        assert np.ptp(ours[q]) >= least, f"{q} travels only {np.ptp(ours[q]):.3f} mm: no real motion compared"


@pytest.mark.parametrize("name", sorted(CASES))
def test_ecos_applies_the_parameter_set_to_every_component(ecos_runs, name):
    system = read_ssp(ROOT / "ssp" / f"{name}.ssp")
    bound = [c for c in system.components if c.parameters]
    assert len(bound) >= 3
    run = ecos_runs(name)
    assert f"Parameterset '{PARAMETER_SET}' applied to {len(bound)} instances" in run.log
    for comp in bound:
        for k, v in comp.parameters.items():
            if isinstance(v, str):
                continue
            logged = run[f"{comp.name}.{k}"]
            want = float(v)
            assert np.abs(logged - want).max() <= TOL * max(1.0, abs(want)), (comp.name, k, v, logged[0])


def test_lathe_taper_parameters_differ_from_the_fmu_defaults(ecos_runs):
    """In lathe_taper the .ssv values that differ from the FMU defaults are what ecos ran with.

    (grinder_feed's set equals its FMUs' defaults, so there only ecos's log line tells it was applied.)
    """
    from fmpy import read_model_description
    system = read_ssp(ROOT / "ssp" / "lathe_taper.ssp")
    run = ecos_runs("lathe_taper")
    differing = []
    for comp in system.components:
        md = read_model_description(str(ROOT / "fmus" / f"{comp.model}.fmu"))
        defaults = {v.name: v.start for v in md.modelVariables}
        for k, v in comp.parameters.items():
            if isinstance(v, str):
                continue
            default = {"true": 1.0, "false": 0.0}.get(defaults[k], defaults[k])
            if float(default) != float(v):
                differing.append(f"{comp.name}.{k}")
                assert run[f"{comp.name}.{k}"][0] == pytest.approx(float(v), abs=TOL), (comp.name, k)
    # the start positions, the taper and the pass count at least
    assert {"x_axis.pos_start", "z_axis.pos_start", "seq.block[1].Xp", "seq.block[1].N"} <= set(differing)
    assert run["x_axis.pos"][0] == pytest.approx(30.0, abs=TOL) and run["z_axis.pos"][0] == pytest.approx(2.0, abs=TOL)
