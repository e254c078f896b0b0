"""Peak memory of a sweep of long variants, client and workers: ``python bench/sweep_memory.py [--json FILE]``.

A sweep of ``--variants`` variants (``feed.D3`` varied) of ``--system`` (grinder_feed), each ``--durations``
seconds of simulated time (default 600, 1800 and 3600: 10 min, 30 min, 1 h), on a real dask LocalCluster of
``--workers`` worker processes (one thread each), recorded at ``--output-interval`` (0.1 s; the metrics still
read every 1 ms step). Each duration runs in a fresh process (peak RSS only grows), which starts its own
cluster, runs the sweep through it and then reads every worker's peak RSS (``getrusage`` ``ru_maxrss``, in the
worker) and its own. Printed: wall time, client and worker peak RSS, and their growth from the shortest to the
longest duration -- flat memory means the growth stays a few MB while the variants get 6x longer.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def peak_rss_mb() -> float:
    """This process's peak resident set size in MB (Linux reports ru_maxrss in KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def one(system: str, duration: float, variants: int, workers: int, output_interval: float) -> dict:
    from dask.distributed import Client, LocalCluster

    from ncfmu.batch import sweep
    from ncfmu.project import system_archive
    system_archive(system)                       # build what is stale before the clock starts
    values = [round(4.0 - 0.2 * i, 3) for i in range(variants)]
    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            Client(cluster) as client, tempfile.TemporaryDirectory() as tmp:
        before = {"client": peak_rss_mb(), "workers": list(client.run(peak_rss_mb).values())}
        t0 = time.perf_counter()
        rows = sweep(system, {"feed.D3": values}, Path(tmp), scheduler=cluster.scheduler_address,
                     stop_time=duration, output_interval=output_interval, progress=False)
        wall = time.perf_counter() - t0
        workers_peak = list(client.run(peak_rss_mb).values())
        files = sorted((Path(tmp) / "variants").glob("*.csv"))
        size = sum(f.stat().st_size for f in files)
    bad = [r for r in rows if r["status"] != "ok"]
    if bad:
        raise SystemExit(f"variants failed: {bad}")
    return {"duration_s": duration, "variants": variants, "workers": workers, "wall_s": round(wall, 2),
            "steps_per_variant": int(round(duration / 1e-3)),
            "rows_per_variant": int(rows[0]["rows"]), "csv_mb_per_variant": round(size / len(files) / 2 ** 20, 2),
            "client_peak_mb": round(peak_rss_mb(), 1), "client_before_mb": round(before["client"], 1),
            "worker_peak_mb": [round(w, 1) for w in workers_peak],
            "worker_before_mb": [round(w, 1) for w in before["workers"]],
            "deepest_x_mm": [float(r["deepest_x_mm"]) for r in rows]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--system", default="grinder_feed")
    ap.add_argument("--durations", type=float, nargs="+", default=[600.0, 1800.0, 3600.0])
    ap.add_argument("--variants", type=int, default=4)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--output-interval", type=float, default=0.1)
    ap.add_argument("--json", type=Path)
    ap.add_argument("--one", type=float, help=argparse.SUPPRESS)       # one duration, in this process
    args = ap.parse_args()
    if args.one is not None:
        print(json.dumps(one(args.system, args.one, args.variants, args.workers, args.output_interval)))
        return
    results = []
    for duration in args.durations:
        out = subprocess.run([sys.executable, __file__, "--one", str(duration), "--system", args.system,
                              "--variants", str(args.variants), "--workers", str(args.workers),
                              "--output-interval", str(args.output_interval)],
                             capture_output=True, text=True, check=True)
        r = json.loads(out.stdout.strip().splitlines()[-1])
        results.append(r)
        print(f"{duration / 60:6.1f} min x {r['variants']} variants on {r['workers']} workers: "
              f"wall {r['wall_s']:7.1f} s "
              f"({r['wall_s'] * r['workers'] / r['variants'] / r['steps_per_variant'] * 1e6:.1f} us a step per "
              f"worker); client peak {r['client_peak_mb']:.0f} MB; worker peaks "
              f"{', '.join(f'{w:.0f}' for w in r['worker_peak_mb'])} MB; {r['rows_per_variant']} rows, "
              f"{r['csv_mb_per_variant']:.1f} MB CSV a variant", flush=True)
    first, last = results[0], results[-1]
    growth = {"client_mb": round(last["client_peak_mb"] - first["client_peak_mb"], 1),
              "worker_mb": round(max(last["worker_peak_mb"]) - max(first["worker_peak_mb"]), 1)}
    print(f"growth {first['duration_s'] / 60:g} min -> {last['duration_s'] / 60:g} min variants: "
          f"client {growth['client_mb']:+.1f} MB, largest worker {growth['worker_mb']:+.1f} MB")
    if args.json:
        args.json.write_text(json.dumps({"runs": results, "growth": growth}, indent=2) + "\n")


if __name__ == "__main__":
    main()
