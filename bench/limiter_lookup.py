"""Region lookup cost of the AreaLimiter: binary search (ncfmu) vs the seed's linear scan, side by side.

    python bench/limiter_lookup.py [--json FILE]

Prints ns per lookup at 10, 100, 1 000 and 10 000 regions (random positions over the table,
interleaved repetitions, medians) and the growth factor per 10x more regions: ~constant steps for
O(log n), ~10x for the linear scan.
"""

from __future__ import annotations

import argparse
import json
import random
import statistics
import time

from ncfmu.controllers.limiter import find_region


def linear_scan(boundaries, ref):
    """The seed's routine LVAS: read boundaries in order until the position is not larger."""
    for i, b in enumerate(boundaries):
        if ref <= b:
            return i + 1
    return 0


def measure(fn, boundaries, queries, repeats=7):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter_ns()
        for q in queries:
            fn(boundaries, q)
        times.append((time.perf_counter_ns() - t0) / len(queries))
    return statistics.median(times)


def main() -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", default=None)
    args = parser.parse_args()
    rng = random.Random(1)
    rows = {}
    for n in (10, 100, 1000, 10000):
        bounds = [float(i) for i in range(1, n + 1)]
        queries = [rng.uniform(0, n) for _ in range(2000 if n <= 1000 else 300)]
        assert all(find_region(bounds, q) == linear_scan(bounds, q) for q in queries[:200])
        b = measure(find_region, bounds, queries)
        s = measure(linear_scan, bounds, queries, repeats=3)
        rows[n] = {"binary_ns": b, "linear_ns": s, "speedup": s / b}
    print(f"{'regions':>8} {'binary ns':>10} {'linear ns':>12} {'linear/binary':>14}")
    for n, r in rows.items():
        print(f"{n:>8} {r['binary_ns']:>10.0f} {r['linear_ns']:>12.0f} {r['speedup']:>14.1f}")
    ns = list(rows)
    growth = [rows[b]["binary_ns"] / rows[a]["binary_ns"] for a, b in zip(ns, ns[1:])]
    print("binary search cost growth per 10x regions:", ", ".join(f"{g:.2f}x" for g in growth))
    out = {"limiter_lookup_ns": {str(n): r["binary_ns"] for n, r in rows.items()},
           "limiter_linear_scan_ns": {str(n): r["linear_ns"] for n, r in rows.items()}}
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=2)
    return out


if __name__ == "__main__":
    main()
