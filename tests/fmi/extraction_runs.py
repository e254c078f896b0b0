"""``fmpy.simulate_fmu`` of one FMU again and again in this process; prints what stays behind.

    python extraction_runs.py <fmu> <warm-up runs> <runs>

Run by test_memory_extractions.py in a fresh process. fmpy extracts the FMU to a new folder at every call and
deletes it afterwards, as a test bench or a batch of fmpy simulations does. Prints
``GROWTH <RSS KiB> <mappings of deleted files> <sys.path entries>`` over the runs after the warm-up.
"""

from __future__ import annotations

import gc
import sys

from fmpy import simulate_fmu


def rss_kib() -> int:
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith("VmRSS:"))


def deleted_maps() -> int:
    with open("/proc/self/maps") as f:
        return sum(1 for line in f if line.rstrip().endswith("(deleted)"))


def run(fmu: str) -> None:
    simulate_fmu(fmu, stop_time=0.01, output_interval=1e-3, logger=lambda *args: None)


fmu_path, warm, runs = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
for _ in range(warm):
    run(fmu_path)
gc.collect()
rss, maps, path = rss_kib(), deleted_maps(), len(sys.path)
for _ in range(runs):
    run(fmu_path)
gc.collect()
print("GROWTH", rss_kib() - rss, deleted_maps() - maps, len(sys.path) - path, flush=True)
