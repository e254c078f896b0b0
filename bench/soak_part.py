"""Soak with the part check on, RSS sampled over the run. ``python bench/soak_part.py [--hours 4]
[--system grinder_feed|lathe_roughing] [--every 5] [--json FILE]``.

One ``ncfmu run`` process of ``--hours`` of simulated time with the part check on (the default), recorded at
0.1 s, its resident set size read from ``/proc/<pid>/status`` (VmRSS) every ``--every`` s of wall time:

- ``grinder_feed``: bench/soak.py's shift (START2 at 0.1 s, parts at 5 s and 45 s, every 80 s): two parts and
  one wear compensation per period, every part's size judged (the verdict keeps up to 1000 cycle records, the
  count and the worst go on);
- ``lathe_roughing``: part after part (START every 100 s): the first cycle cuts the bar, the later ones cut
  air along the part they made, every move still swept against the stock.

Printed and written: the samples (wall s, RSS MB), the RSS at a quarter, half and the end of the run, the growth
from a quarter to the end and the slope of a least-squares line over the second half (MB per wall minute and
per simulated hour), the part line of the summary and the verdict's counts. Goal: flat -- the growth from a
quarter to the end within a few MB (allocator noise), no trend.
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

SCENARIOS = {
    "grinder_feed": ["--set", "panel.repeat_every=80", "--set", "panel.wear_start_at=0.1", "--set",
                     "panel.start_at=5", "--set", "panel.restart_at=45"],
    "lathe_roughing": ["--set", "panel.repeat_every=100"],
}


def rss_mb(pid: int) -> float | None:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    except OSError:
        return None
    return None


def slope(points: list[tuple[float, float]]) -> float:
    n = len(points)
    if n < 2:
        return float("nan")
    mx = sum(p[0] for p in points) / n
    my = sum(p[1] for p in points) / n
    sxx = sum((p[0] - mx) ** 2 for p in points)
    return sum((p[0] - mx) * (p[1] - my) for p in points) / sxx if sxx else float("nan")


def soak(system: str, hours: float, every: float, out: Path) -> dict[str, object]:
    ncfmu = Path(sys.executable).with_name("ncfmu")
    cmd = [str(ncfmu), "run", system, "--stop-time", repr(hours * 3600.0), "--output-interval", "0.1",
           *SCENARIOS[system], "--out", str(out)]
    t0 = time.perf_counter()
    log = (out / "stdout.txt").open("wb")
    proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT)
    samples: list[tuple[float, float]] = []
    while proc.poll() is None:
        r = rss_mb(proc.pid)
        if r is not None:
            samples.append((time.perf_counter() - t0, r))
        time.sleep(every)
    wall = time.perf_counter() - t0
    log.close()
    stdout = (out / "stdout.txt").read_text()
    if proc.returncode not in (0, 3):
        raise SystemExit(f"{' '.join(cmd)} failed ({proc.returncode}):\n{stdout[-3000:]}")
    part_json = json.loads((out / f"{system}.part.json").read_text())
    sim = re.search(r"simulated ([0-9.]+) s in ([0-9.]+) s wall", stdout)

    def at(fraction: float) -> float:
        return min(samples, key=lambda s: abs(s[0] - fraction * wall))[1]

    second_half = [s for s in samples if s[0] >= wall / 2]
    per_wall_s = slope(second_half)
    result = {
        "system": system, "hours_simulated": hours, "scenario": SCENARIOS[system], "wall_s": wall,
        "rtf": float(sim.group(1)) / float(sim.group(2)) if sim else None, "exit_status": proc.returncode,
        "rss_mb_quarter": at(0.25), "rss_mb_half": at(0.5), "rss_mb_end": samples[-1][1],
        "rss_mb_max": max(s[1] for s in samples), "growth_quarter_to_end_mb": samples[-1][1] - at(0.25),
        "slope_second_half_mb_per_wall_min": per_wall_s * 60,
        "slope_second_half_mb_per_sim_hour": per_wall_s * wall / hours,
        "part_lines": [line.strip() for line in stdout.splitlines() if line.strip().startswith("part:")],
        "verdict": {k: part_json.get(k) for k in ("crash_count", "within_tolerance", "max_left_mm", "max_gouge_mm",
                                                   "cycles_judged", "cycles_aborted", "cycles_kept",
                                                   "worst_error_mm", "worst_cycle")},
        "samples": [[round(t, 1), round(r, 2)] for t, r in samples],
    }
    print(f"{system}: {hours:g} h simulated in {wall:.0f} s wall (RTF {result['rtf']:.1f}); RSS at 1/4 "
          f"{result['rss_mb_quarter']:.1f} MB, 1/2 {result['rss_mb_half']:.1f} MB, end {result['rss_mb_end']:.1f} MB "
          f"(max {result['rss_mb_max']:.1f}); growth 1/4 -> end {result['growth_quarter_to_end_mb']:+.2f} MB; "
          f"second-half slope {result['slope_second_half_mb_per_sim_hour']:+.3f} MB per simulated hour")
    for line in result["part_lines"]:
        print(f"  {line}")
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--system", choices=sorted(SCENARIOS), default="grinder_feed")
    parser.add_argument("--hours", type=float, default=4.0, help="simulated hours (default 4)")
    parser.add_argument("--every", type=float, default=5.0, help="RSS sample period, wall s (default 5)")
    parser.add_argument("--json", type=Path, default=None, help="also write the numbers here")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        result = soak(args.system, args.hours, args.every, Path(tmp))
    if args.json:
        args.json.write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
