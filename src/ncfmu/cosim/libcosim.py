"""Run an .ssp archive in libcosim (package ``libcosimpy``), the independent FMI tool, into a Result.

libcosim reads the SSP itself (components, connections, .ssv parameter bindings, the OSP
fixed-step annotation) and steps all FMUs, then exchanges values (Jacobi). Its time-series observer
records Real and Integer variables; Booleans are not sampled, so they are absent from the Result.
Times are in nanoseconds inside libcosim.

libcosim runs in a child process (``python -m ncfmu.cosim.libcosim``): it is an independent FMI
host, and two hosts loading pythonfmu binaries into one interpreter interfere with each other.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from ..errors import SimulationError
from .result import Result

NS = 1_000_000_000


def run_ssp(archive: Path, stop_time: float, step_size: float = 1e-3, timeout: float = 1800.0) -> Result:
    """Simulate ``archive`` with libcosim (in a child process) from 0 to ``stop_time``; return its trajectories."""
    with tempfile.TemporaryDirectory(prefix="ncfmu_libcosim_") as tmp:
        out = Path(tmp) / "result.npz"
        proc = subprocess.run([sys.executable, "-m", "ncfmu.cosim.libcosim", str(Path(archive).resolve()),
                               repr(float(stop_time)), repr(float(step_size)), str(out)],
                              capture_output=True, text=True, timeout=timeout)
        if proc.returncode != 0 or not out.is_file():
            raise SimulationError(f"libcosim failed on {archive} (exit {proc.returncode}): "
                                  f"{(proc.stderr or proc.stdout).strip()[-2000:]}")
        with np.load(out) as z:
            return Result(z["data"], Path(archive).stem, float(z["wall"]))


def _run_here(archive: Path, stop_time: float, step_size: float = 1e-3, outputs_only: bool = True) -> Result:
    """The libcosim run itself, in this process."""
    from libcosimpy.CosimEnums import CosimVariableCausality, CosimVariableType
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver

    log_output_level(CosimLogLevel.WARNING)
    step_ns = int(round(step_size * NS))
    n_steps = int(round(stop_time / step_size))
    try:
        execution = CosimExecution.from_ssp_file(str(Path(archive).resolve()), step_size=step_ns)
    except AssertionError as err:
        raise SimulationError(f"libcosim could not load {archive}: {err}") from None
    observer = CosimObserver.create_time_series(buffer_size=n_steps + 2)
    execution.add_observer(observer)
    kinds = {CosimVariableType.REAL.value: ("Real", CosimVariableType.REAL, np.float64),
             CosimVariableType.INTEGER.value: ("Integer", CosimVariableType.INTEGER, np.int32)}
    watched = []
    for info in sorted(execution.slave_infos(), key=lambda s: s.index):
        instance = info.name.decode()
        for v in execution.slave_variables(info.index):
            if v.type not in kinds:
                continue
            if outputs_only and v.causality != CosimVariableCausality.OUTPUT.value:
                continue
            spec = kinds[v.type]
            observer.start_time_series(info.index, v.reference, spec[1])
            watched.append((f"{instance}.{v.name.decode()}", info.index, v.reference, spec))
    wall0 = time.perf_counter()
    if not execution.simulate_until(n_steps * step_ns):
        raise SimulationError(f"libcosim stopped before {stop_time} s simulating {archive}")
    wall = time.perf_counter() - wall0
    data = np.empty(n_steps + 1, dtype=[("time", np.float64)] + [(q, k[2]) for q, _, _, k in watched])
    data["time"] = np.arange(n_steps + 1) * step_size
    chunk = 4096
    for qualified, index, ref, (kind, _, dtype) in watched:
        fetch = observer.time_series_real_samples if kind == "Real" else observer.time_series_integer_samples
        values, got = np.empty(n_steps + 1, dtype=dtype), 0
        while got < n_steps + 1:
            times, steps, samples = fetch(index, ref, from_step=got, sample_count=min(chunk, n_steps + 1 - got))
            if not steps:
                raise SimulationError(f"libcosim returned no samples of {qualified} from step {got}")
            values[steps[0]:steps[0] + len(samples)] = samples
            got = steps[0] + len(samples)
        data[qualified] = values
    return Result(data, Path(archive).stem, wall)


if __name__ == "__main__":
    archive_arg, stop_arg, step_arg, out_arg = sys.argv[1:5]
    result = _run_here(Path(archive_arg), float(stop_arg), float(step_arg))
    np.savez(out_arg, data=result.data, wall=result.wall_time)
