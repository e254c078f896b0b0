"""What a foreign FMU's own process costs a step (issue 45): one slave, bound as the master binds it, stepped
``--steps`` times (write_inputs, do_step, read_outputs) in process and isolated, interleaved repetitions, best of
``--repeats``, in us a step.

    python bench/isolation.py [--steps 20000] [--repeats 3] [--system-stop 2]

Then the same for a whole system: lathe_taper with both axes the foreign PlantAxis (``OpenSystem(isolate=...)``,
the Python loop either way: the C loop runs only when every slave is in process), us a 1 ms step.

The FMU is the test suite's foreign PlantAxis (tests/foreign/plant_axis.c, 2 Real inputs, 3 Real and 1 Boolean
outputs, sub-steps of 0.1 ms: ten a 1 ms step), compiled here.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from foreign_fmus import FOREIGN, build_one, packed, with_plant  # noqa: E402

from ncfmu.cosim.fmu import UnpackedFmu  # noqa: E402
from ncfmu.cosim.instances import make_slave  # noqa: E402
from ncfmu.cosim.isolated import isolated_slave  # noqa: E402
from ncfmu.project import OpenSystem  # noqa: E402


def steps_per_second(slave, steps: int, h: float = 1e-3) -> float:
    """us a step of ``steps`` steps of ``slave`` (initialised and bound here)."""
    real_in, real_out = np.zeros(2), np.zeros(3)
    bool_in, bool_out = np.zeros(0, np.int32), np.zeros(1, np.int32)
    slave.initialize(0.0, steps * h)
    slave.bind("Real", real_in, [0, 1], real_out, [2, 3, 4])
    slave.bind("Boolean", bool_in, [], bool_out, [0])
    t0 = time.perf_counter()
    for i in range(steps):
        real_in[0] = 10.0 * i * h             # a ramp at 10 mm/s
        real_in[1] = 10.0
        slave.write_inputs()
        slave.do_step(i * h, h)
        slave.read_outputs()
    wall = time.perf_counter() - t0
    assert abs(real_out[0] - 10.0 * steps * h) < 0.01, real_out     # it followed the ramp
    return wall / steps * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=20000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--system-stop", type=float, default=2.0)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        plant = build_one(FOREIGN["PlantAxis"], Path(tmp))
        unpacked = UnpackedFmu(plant)
        times: dict[str, list[float]] = {"in_process": [], "isolated": []}
        for _ in range(args.repeats):
            for how in times:
                slave = make_slave(unpacked, "x_axis") if how == "in_process" else isolated_slave(unpacked, "x_axis")
                try:
                    times[how].append(steps_per_second(slave, args.steps))
                finally:
                    slave.terminate()
        best = {how: min(values) for how, values in times.items()}
        archive = packed(with_plant("lathe_taper", "PlantAxis"), {"PlantAxis": plant}, Path(tmp))
        system: dict[str, list[float]] = {"in_process": [], "isolated": []}
        for _ in range(args.repeats):
            for how in system:
                with OpenSystem(archive, isolate=how == "isolated") as opened:
                    result = opened.run(stop_time=args.system_stop)
                    system[how].append(result.wall_time / round(args.system_stop / 1e-3) * 1e6)
        system_best = {how: min(values) for how, values in system.items()}
        print(json.dumps({"load_average": os.getloadavg(), "steps": args.steps, "us_per_step": times,
                          "best_us_per_step": best,
                          "isolation_cost_us_per_step": best["isolated"] - best["in_process"],
                          "lathe_taper_two_plant_axes_us_per_step": system, "lathe_taper_best": system_best},
                         indent=1))
        unpacked.cleanup()


if __name__ == "__main__":
    main()
