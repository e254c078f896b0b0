"""The part check's cost and memory. ``python bench/part_check.py [--pairs 3] [--hours 0.25 1] [--json FILE]``.

- **Cost**: ``ncfmu run lathe_roughing`` with the part check (the default) and with ``--no-part-check``, side by
  side in one invocation, interleaved (on off, off on, on off, ...), each a fresh process; printed: the wall time of
  each process and of its simulation (the summary's "in ... s wall"), the medians and the ratio on / off. Goal:
  the part check adds < 20 % to the run's wall time.
- **Cost in process** (the same on a loaded machine): one run of lathe_roughing kept in memory, its rows fed
  to the report's accumulator in chunks of 10 000 rows (as ``ncfmu run`` streams them) with and without the part
  check, interleaved, ``--pairs`` times each; the difference of the medians (the end's verdict included) against
  the run's own wall time.
- **Soak**: lathe_roughing cutting part after part (the panel's START repeated every 100 s; the first cycle cuts
  the bar, the later ones cut air along the part they made -- every rapid still checked against the stock) for
  each of ``--hours`` of simulated time with the part check on, recorded at 0.1 s: the peak RSS of each
  ``ncfmu run`` process (``os.wait4``'s ru_maxrss) and the growth from the shortest to the longest run. Goal: flat
  (the stock, the forbidden regions and at most 100 crash records are all the check keeps).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

SYSTEM = "lathe_roughing"
SOAK = ["--set", "panel.repeat_every=100", "--output-interval", "0.1"]


def run(args: list[str], out: Path) -> dict[str, float]:
    """One ``ncfmu run`` process: its wall time, the simulation's wall time (from the summary) and peak RSS."""
    cmd = [sys.executable, "-m", "ncfmu.cli", "run", SYSTEM, "--out", str(out), *args]
    start = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    stdout = proc.stdout.read() if proc.stdout else ""
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - start
    if os.waitstatus_to_exitcode(status) not in (0, 3):
        raise SystemExit(f"{' '.join(cmd)} failed:\n{stdout}")
    sim = re.search(r"simulated ([0-9.]+) s in ([0-9.]+) s wall", stdout)
    part = next((line.strip() for line in stdout.splitlines() if line.strip().startswith("part:")), "")
    return {"wall_s": wall, "run_wall_s": float(sim.group(2)) if sim else float("nan"),
            "peak_rss_mb": usage.ru_maxrss / 1024, "part": part}  # type: ignore[dict-item]


def cost(pairs: int, out: Path) -> dict[str, object]:
    run([], out)                                   # builds what is stale, warms the caches
    on: list[dict[str, float]] = []
    off: list[dict[str, float]] = []
    for k in range(pairs):          # A B, B A, A B, ...: neither side always runs second
        for side in ((0, 1) if k % 2 == 0 else (1, 0)):
            if side == 0:
                on.append(run([], out))
            else:
                off.append(run(["--no-part-check"], out))
        print(f"pair {k + 1}: on {on[-1]['wall_s']:.2f} s (run {on[-1]['run_wall_s']:.2f} s), "
              f"off {off[-1]['wall_s']:.2f} s (run {off[-1]['run_wall_s']:.2f} s)", flush=True)
    med = {side: {key: statistics.median(r[key] for r in rows) for key in ("wall_s", "run_wall_s")}
           for side, rows in (("on", on), ("off", off))}
    ratio = med["on"]["wall_s"] / med["off"]["wall_s"]
    ratio_run = med["on"]["run_wall_s"] / med["off"]["run_wall_s"]
    print(f"median wall: on {med['on']['wall_s']:.2f} s, off {med['off']['wall_s']:.2f} s: ratio {ratio:.3f} "
          f"({(ratio - 1) * 100:+.1f} %); the simulation alone {ratio_run:.3f} ({(ratio_run - 1) * 100:+.1f} %); "
          f"goal < +20 %: {'met' if ratio < 1.2 else 'NOT met'}")
    print(f"  {on[-1]['part']}")
    return {"pairs": pairs, "on": on, "off": off, "median": med, "ratio_wall": ratio, "ratio_run": ratio_run}


def in_process(pairs: int) -> dict[str, object]:
    from ncfmu.project import simulate
    from ncfmu.systems import report_of, run_parameters
    from ncfmu.systems.part import without_part_check
    from ncfmu.systems.report import columns_of
    r = simulate(SYSTEM)
    on_report = report_of(r)
    off_report = without_part_check(on_report)
    parameters = run_parameters(r)

    def feed(report) -> float:
        start = time.perf_counter()
        acc = report.accumulator(parameters)
        acc.open(columns_of(r.data))
        for k in range(0, len(r.data), 10_000):
            acc.write(r.data[k:k + 10_000])
        acc.close(True, float(r.time[-1]))
        acc.summary()
        return time.perf_counter() - start

    on, off = [], []
    for k in range(pairs):
        for side in ((0, 1) if k % 2 == 0 else (1, 0)):
            (on if side == 0 else off).append(feed(on_report if side == 0 else off_report))
    added = statistics.median(on) - statistics.median(off)
    print(f"in process: the summary with the part check {statistics.median(on):.3f} s, without "
          f"{statistics.median(off):.3f} s: the part check adds {added:.3f} s to a run of {r.wall_time:.2f} s wall "
          f"({added / r.wall_time * 100:+.1f} %)", flush=True)
    return {"on_s": on, "off_s": off, "added_s": added, "run_wall_s": r.wall_time,
            "added_fraction": added / r.wall_time}


def soak(hours: list[float], out: Path) -> dict[str, object]:
    rows = []
    for h in hours:
        r = run(["--stop-time", f"{h * 3600:g}", *SOAK], out)
        r["hours"] = h
        rows.append(r)
        print(f"soak {h:g} h simulated: peak RSS {r['peak_rss_mb']:.1f} MB, wall {r['wall_s']:.1f} s; {r['part']}",
              flush=True)
    growth = rows[-1]["peak_rss_mb"] - rows[0]["peak_rss_mb"]
    print(f"peak RSS growth from {hours[0]:g} h to {hours[-1]:g} h: {growth:+.1f} MB")
    return {"runs": rows, "growth_mb": growth}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pairs", type=int, default=4, help="interleaved on/off pairs (default 4)")
    parser.add_argument("--hours", type=float, nargs="*", default=[], help="soak durations, simulated hours")
    parser.add_argument("--json", type=Path, default=None, help="also write the numbers here")
    args = parser.parse_args()
    results: dict[str, object] = {}
    with tempfile.TemporaryDirectory() as tmp:
        if args.pairs:
            results["in_process"] = in_process(max(args.pairs, 5))
            results["cost"] = cost(args.pairs, Path(tmp))
        if args.hours:
            results["soak"] = soak(sorted(args.hours), Path(tmp))
    if args.json:
        args.json.write_text(json.dumps(results, indent=1) + "\n")


if __name__ == "__main__":
    main()
