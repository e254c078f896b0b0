"""Soak: a grinder shift streamed to disk at flat memory. ``python bench/soak.py [--hours 1 4 8] [--json FILE]``.

The scenario (defined once, here and in the README): ``grinder_feed`` with the panel's button schedule
repeated every 80 s -- wear-compensation start (START2) at 0.1 s, a part at 5 s, another at 45 s -- so the wheel
grinds two parts per period and compensates its wear before every other part, for hours::

    ncfmu run grinder_feed --stop-time 28800 --output-interval 0.1 --set panel.repeat_every=80 \\
        --set panel.wear_start_at=0.1 --set panel.start_at=5 --set panel.restart_at=45

Printed:

- per simulated duration: the peak RSS of the ``ncfmu run`` process (``os.wait4``'s ru_maxrss of that child),
  its wall time, the microseconds per 1 ms step, and the CSV's size (and per simulated hour); the growth of the
  peak RSS from the shortest to the longest duration (goal < 20 MB from 1 h to 8 h).
- streaming vs in memory on a short run (``--short`` s, interleaved A, B, A, B, medians): today's way (the
  whole run in memory, then ``Result.to_csv`` and the summary from the trajectory) against ``ncfmu run``'s
  (the rows streamed through a CsvSink, the summary from the report's accumulator), per step, with the same
  every-step CSV. Goal: streaming < 5 % slower.
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

SYSTEM = "grinder_feed"
SCENARIO = ["--set", "panel.repeat_every=80", "--set", "panel.wear_start_at=0.1", "--set", "panel.start_at=5",
            "--set", "panel.restart_at=45"]
START_VALUES = {"panel.repeat_every": 80.0, "panel.wear_start_at": 0.1, "panel.start_at": 5.0,
                "panel.restart_at": 45.0}


def soak(hours: float, out: Path) -> dict:
    """One ``ncfmu run`` of ``hours`` simulated, recorded at 0.1 s: its peak RSS, wall time and output size."""
    ncfmu = Path(sys.executable).with_name("ncfmu")
    stop = hours * 3600.0
    t0 = time.perf_counter()
    proc = subprocess.Popen([str(ncfmu), "run", SYSTEM, "--stop-time", repr(stop), "--output-interval", "0.1",
                             *SCENARIO, "--out", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    # wait4 gives this child's own rusage (getrusage(RUSAGE_CHILDREN) would be the max over all children)
    stdout = proc.stdout.read() if proc.stdout else b""
    stderr = proc.stderr.read() if proc.stderr else b""
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"ncfmu run failed ({proc.returncode}): {stderr.decode()[-2000:]}")
    csv = out / f"{SYSTEM}.csv"
    size = csv.stat().st_size
    steps = int(round(stop / 0.001))
    summary = stdout.decode().splitlines()
    # the loop's own wall time, from the summary's first line ("simulated T s in W s wall"): without start-up
    loop_wall = float(re.search(r" in ([0-9.]+) s wall", summary[0]).group(1))  # type: ignore[union-attr]
    return {"hours": hours, "peak_rss_mb": usage.ru_maxrss / 1024, "wall_s": wall, "loop_wall_s": loop_wall,
            "us_per_step": loop_wall / steps * 1e6,
            "csv_mb": size / 2 ** 20, "csv_mb_per_hour": size / 2 ** 20 / hours, "summary": summary}


def short_side_by_side(seconds: float, repeats: int, out: Path) -> dict:
    """Today's in-memory run + CSV + summary against the streamed run, interleaved, in this process."""
    from ncfmu.cosim.record import CsvSink
    from ncfmu.project import OpenSystem, system_archive
    from ncfmu.systems import report_for, run_parameters

    archive = system_archive(SYSTEM)
    steps = int(round(seconds / 0.001))

    def in_memory() -> float:
        with OpenSystem(archive) as opened:
            t0 = time.perf_counter()
            r = opened.run(stop_time=seconds, start_values=START_VALUES)
            r.to_csv(out / "memory.csv")
            report_for(SYSTEM).summary(r, run_parameters(r))
            return time.perf_counter() - t0

    def streamed() -> float:
        with OpenSystem(archive) as opened:
            parameters = {c.name: dict(c.parameters) for c in opened.system.components}
            for q, v in START_VALUES.items():
                inst, _, var = q.partition(".")
                parameters[inst][var] = v
            acc = report_for(SYSTEM).accumulator(parameters)
            t0 = time.perf_counter()
            opened.run(stop_time=seconds, start_values=START_VALUES, sinks=[CsvSink(out / "streamed.csv"), acc],
                       keep=False)
            acc.summary()
            return time.perf_counter() - t0

    a, b = [], []
    for _ in range(repeats):
        a.append(in_memory())
        b.append(streamed())
    same = (out / "memory.csv").read_bytes() == (out / "streamed.csv").read_bytes()
    ma, mb = statistics.median(a), statistics.median(b)
    return {"seconds": seconds, "in_memory_us_per_step": ma / steps * 1e6, "streamed_us_per_step": mb / steps * 1e6,
            "streamed_slower_pct": (mb / ma - 1) * 100, "identical_csv": same, "in_memory_runs": a,
            "streamed_runs": b}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hours", type=float, nargs="+", default=[1.0, 4.0, 8.0])
    parser.add_argument("--short", type=float, default=60.0, help="simulated seconds of the side-by-side run "
                        "(0: none)")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    results: dict = {"soak": [], "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}
    # build first: a run that (re)builds FMUs or docs imports python-control and matplotlib (~250 MB) before it
    # steps, which is start-up, not what the run holds
    subprocess.run([str(Path(sys.executable).with_name("ncfmu")), "build"], check=True, capture_output=True)
    # The soaks first, while this process is small: Linux counts the RSS a child had between fork and exec (a
    # copy of this process) in its ru_maxrss, so after the in-process side-by-side (~300 MB) every child would
    # report at least that.
    with tempfile.TemporaryDirectory(prefix="ncfmu_soak_") as tmp:
        for hours in args.hours:
            row = soak(hours, Path(tmp))
            results["soak"].append(row)
            print(f"{hours:g} h simulated: peak RSS {row['peak_rss_mb']:.1f} MB, wall {row['wall_s']:.0f} s "
                  f"(steps {row['loop_wall_s']:.0f} s, {row['us_per_step']:.1f} us/step), CSV {row['csv_mb']:.0f} MB "
                  f"({row['csv_mb_per_hour']:.1f} MB per simulated hour)", flush=True)
            for line in row["summary"][:3]:
                print(f"    {line}")
    with tempfile.TemporaryDirectory(prefix="ncfmu_soak_") as tmp:
        side = short_side_by_side(args.short, args.repeats, Path(tmp)) if args.short > 0 else None
        results["side_by_side"] = side
        if side is not None:
            print(f"short run ({args.short:g} s, {args.repeats} interleaved pairs, medians): in memory "
                  f"{side['in_memory_us_per_step']:.1f} us/step, streamed {side['streamed_us_per_step']:.1f} us/step: "
                  f"streaming {side['streamed_slower_pct']:+.1f} % (goal < +5 %); CSV identical: "
                  f"{side['identical_csv']}", flush=True)
    rows = results["soak"]
    if len(rows) > 1:
        growth = rows[-1]["peak_rss_mb"] - rows[0]["peak_rss_mb"]
        results["rss_growth_mb"] = growth
        print(f"peak RSS growth {rows[0]['hours']:g} h -> {rows[-1]['hours']:g} h: {growth:+.1f} MB (goal < 20 MB)")
    if args.json:
        args.json.write_text(json.dumps(results, indent=1) + "\n")


if __name__ == "__main__":
    main()
