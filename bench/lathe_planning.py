"""Planning time of lathe part programs: the red team's worst programs (issue 32) and how the cost grows.

    python bench/lathe_planning.py [--json FILE]

Prints, for each program, its size, the moves planned (or the refusal) and the CPU time of
``lathe_program.plan`` (median of interleaved repetitions), then the pocket profile at falling depths of cut:
the time per planned move should stay about flat (cost that grows with the moves made, not with their square).
"""

from __future__ import annotations

import argparse
import json
import statistics
import time

from ncfmu.controllers.lathe_program import plan
from ncfmu.errors import ProgramError


def pocket_profile(u: float) -> str:
    """The red team's ~300-byte pocket profile (12.8 s of CPU at U0.05 before the planner was bounded)."""
    return (f"G18 G21 G90 G8\nG00 X30 Z2\nG71 U{u} R0.2\nG71 P10 Q20 U0.1 W0 F300\nN10 G00 X20\nG01 Z-2\n"
            "X6 Z-4\nZ-8\nG02 X10 Z-12 R4\nG01 X4 Z-14\nZ-18\nG02 X8 Z-22 R4\nG01 X2 Z-24\nZ-28\nX18 Z-30\n"
            "X3 Z-33\nZ-36\nG02 X7 Z-40 R4\nG01 X22 Z-42\nZ-44\nN20 X30\nG70 P10 Q20 F180\nM30\n")


def v_pockets(n: int, u: float) -> str:
    """``n`` V-shaped pockets 20 mm deep side by side (54.9 s of CPU for 50 at U0.01 before, then refused)."""
    lines = ["G18 G21 G90 G8", "G00 X30 Z2", f"G71 U{u} R0.2", "G71 P10 Q20 U0.05 W0 F300", "N10 G00 X25", "G01 Z-1"]
    z = -1.0
    for _ in range(n):
        lines += [f"X5 Z{z - 1:g}", f"X25 Z{z - 2:g}"]
        z -= 2
    return "\n".join([*lines, f"Z{z - 1:g}", "N20 X30", "G70 P10 Q20 F180", "M30", ""])


def plan_once(text: str) -> tuple[float, str]:
    t0 = time.process_time()
    try:
        what = f"{len(plan(text, (30.0, 2.0), 50.0))} moves"
    except ProgramError as err:
        what = "refused: " + str(err).split(": ", 2)[-1][:60]
    return time.process_time() - t0, what


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", help="write the results to this file")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    programs = {
        "pocket profile U0.05": pocket_profile(0.05),
        "50 V-pockets U0.01": v_pockets(50, 0.01),
        **{f"pocket profile U{u:g}": pocket_profile(u) for u in (0.4, 0.2, 0.1)},
    }
    times: dict[str, list[float]] = {name: [] for name in programs}
    what: dict[str, str] = {}
    for _ in range(args.repeats):                      # interleaved: each round plans every program once
        for name, text in programs.items():
            t, what[name] = plan_once(text)
            times[name].append(t)
    results = {}
    print(f"{'program':28s} {'bytes':>6s} {'CPU s':>8s} {'us/move':>8s}  result")
    for name, text in programs.items():
        t = statistics.median(times[name])
        moves = int(what[name].split()[0]) if what[name].endswith("moves") else 0
        per = f"{1e6 * t / moves:8.1f}" if moves else f"{'':8s}"
        print(f"{name:28s} {len(text):6d} {t:8.3f} {per}  {what[name]}")
        results[name] = {"bytes": len(text), "cpu_s": t, "result": what[name]}
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=1)


if __name__ == "__main__":
    main()
