"""Peak memory of a sweep of long variants, client and workers: ``python bench/sweep_memory.py [--json FILE]``.

A sweep of ``--variants`` variants (``feed.D3`` varied) of ``--system`` (grinder_feed), each ``--durations``
seconds of simulated time (default 600, 1800 and 3600: 10 min, 30 min, 1 h), on a real dask LocalCluster of
``--workers`` worker processes (one thread each), recorded at ``--output-interval`` (0.1 s; the metrics still
read every 1 ms step). Each duration runs in a fresh process (peak RSS only grows), which starts its own
cluster, runs the sweep through it and then reads every worker's peak RSS (``getrusage`` ``ru_maxrss``, in the
worker) and its own. Printed: wall time, client and worker peak RSS, and their growth from the shortest to the
longest duration -- flat memory means the growth stays a few MB while the variants get 6x longer.

``--soak``: each variant is the README's soak, the grinder grinding part after part (the panel's
``repeat_every`` 80 s: wear compensation at 0.1 s, a part at 5 s and at 45 s of every period), given to the
sweep as single-valued varied values.

Step cost (``--step-cost S``, default 300): one variant of S simulated seconds run in this process by the
streaming worker function and by the pre-streaming one, interleaved five times, medians: the cluster's start-up
and the client's bookkeeping, which differ between the two sweeps above, are not in it.

Side by side (``--in-memory-durations``, default 600 and 1800): the same sweep as the workers ran variants
before they streamed -- the whole run kept in memory (every output, every step), the kept columns formatted
as CSV bytes on the worker and sent back in the answer, written by the client.
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


def in_memory_variant(ssp: bytes, digest: str, variant: dict, stop_time: float, every: int) -> dict:
    """A variant as sweep workers ran it before they streamed (kept here as the baseline)."""
    import time as _time

    from ncfmu.batch import _OPEN, _cached_archive
    from ncfmu.cosim.result import csv_bytes
    from ncfmu.project import OpenSystem
    from ncfmu.systems import report_of
    t0 = _time.perf_counter()
    opened = _OPEN.get(digest)
    if opened is None:
        opened = _OPEN[digest] = OpenSystem(_cached_archive(digest, ssp))
    else:
        for slave in opened.slaves:
            slave.reset()
    result = opened.run(stop_time=stop_time, start_values=dict(variant))
    report = report_of(result)
    kept = result.data[["time", *report.record()]][::every]
    row = {"status": "ok", "rows": len(kept), **report.metrics(result, result.parameters),
           "wall_time": _time.perf_counter() - t0}
    return {"row": row, "trajectory": csv_bytes(kept)}


#: The README's soak: the grinder's button schedule repeated every 80 s.
SOAK = {"panel.repeat_every": [80.0], "panel.wear_start_at": [0.1], "panel.start_at": [5.0],
        "panel.restart_at": [45.0]}


def one(system: str, duration: float, variants: int, workers: int, output_interval: float,
        in_memory: bool = False, soak: bool = False) -> dict:
    from dask.distributed import Client

    from ncfmu.batch import local_cluster, sweep
    from ncfmu.project import system_archive
    system_archive(system)                       # build what is stale before the clock starts
    values = [round(4.0 - 0.2 * i, 3) for i in range(variants)]
    with local_cluster(workers) as cluster, \
            Client(cluster) as client, tempfile.TemporaryDirectory() as tmp:
        before = {"client": peak_rss_mb(), "workers": list(client.run(peak_rss_mb).values())}
        t0 = time.perf_counter()
        vary = {"feed.D3": values, **(SOAK if soak else {})}
        if in_memory:
            rows = in_memory_sweep(client, system, vary, Path(tmp), duration, output_interval)
        else:
            rows = sweep(system, vary, Path(tmp), scheduler=cluster.scheduler_address,
                         stop_time=duration, output_interval=output_interval, progress=False)
        wall = time.perf_counter() - t0
        workers_peak = list(client.run(peak_rss_mb).values())
        files = sorted((Path(tmp) / "variants").glob("*.csv"))
        size = sum(f.stat().st_size for f in files)
    bad = [r for r in rows if r["status"] != "ok"]
    if bad:
        raise SystemExit(f"variants failed: {bad}")
    return {"mode": "in memory (before)" if in_memory else "streamed", "soak": soak, "duration_s": duration,
            "variants": variants, "workers": workers, "wall_s": round(wall, 2),
            "steps_per_variant": int(round(duration / 1e-3)),
            "rows_per_variant": int(rows[0]["rows"]), "csv_mb_per_variant": round(size / len(files) / 2 ** 20, 2),
            "client_peak_mb": round(peak_rss_mb(), 1), "client_before_mb": round(before["client"], 1),
            "worker_peak_mb": [round(w, 1) for w in workers_peak],
            "worker_before_mb": [round(w, 1) for w in before["workers"]],
            "deepest_x_mm": [float(r["deepest_x_mm"]) for r in rows],
            "cycle_time_s": [float(r["cycle_time_s"]) for r in rows]}


def in_memory_sweep(client, system: str, vary: dict[str, list[float]], out: Path, duration: float,
                    output_interval: float) -> list[dict]:
    import hashlib

    from dask.distributed import as_completed

    from ncfmu.files import write_atomic
    from ncfmu.project import system_archive
    data = system_archive(system).read_bytes()
    digest = hashlib.sha256(data).hexdigest()
    shipped = client.scatter(data, broadcast=True, hash=False)
    (out / "variants").mkdir(parents=True, exist_ok=True)
    every = int(round(output_interval / 1e-3))
    from ncfmu.batch import product, variant_key
    futures = {client.submit(in_memory_variant, shipped, digest, v, duration, every, pure=False): variant_key(v)
               for v in product(vary)}
    rows = []
    for future in as_completed(futures):
        answer = future.result()
        write_atomic(out / "variants" / f"{futures[future]}.csv", answer["trajectory"])
        rows.append(answer["row"])
        del answer
        future.release()
    return rows


def step_cost(system: str, duration: float, output_interval: float, soak: bool, repeats: int = 5) -> dict:
    import hashlib
    import statistics

    from ncfmu.batch import product, remove_rows, run_variant
    from ncfmu.project import system_archive
    data = system_archive(system).read_bytes()
    digest = hashlib.sha256(data).hexdigest()
    variant = product({"feed.D3": [4.0], **(SOAK if soak else {})})[0]
    every = int(round(output_interval / 1e-3))
    in_memory_variant(data, digest, variant, 1.0, every)             # the system opened once, as on a worker
    streamed, kept = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        answer = run_variant(data, digest, variant, duration, None, every, None)
        streamed.append(time.perf_counter() - t0)
        remove_rows(answer["trajectory"]["path"])
        t0 = time.perf_counter()
        in_memory_variant(data, digest, variant, duration, every)
        kept.append(time.perf_counter() - t0)
    steps = duration / 1e-3
    s, k = statistics.median(streamed), statistics.median(kept)
    return {"duration_s": duration, "streamed_us_per_step": round(s / steps * 1e6, 2),
            "in_memory_us_per_step": round(k / steps * 1e6, 2), "streamed_over_in_memory": round(s / k, 3)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--system", default="grinder_feed")
    ap.add_argument("--durations", type=float, nargs="+", default=[600.0, 1800.0, 3600.0])
    ap.add_argument("--variants", type=int, default=4)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--output-interval", type=float, default=0.1)
    ap.add_argument("--soak", action="store_true", help="each variant a soak: part after part, wear compensation")
    ap.add_argument("--in-memory-durations", type=float, nargs="*", default=[600.0, 1800.0])
    ap.add_argument("--step-cost", type=float, default=300.0, metavar="S")
    ap.add_argument("--json", type=Path)
    ap.add_argument("--one", type=float, help=argparse.SUPPRESS)       # one duration, in this process
    ap.add_argument("--in-memory", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.one is not None:
        print(json.dumps(one(args.system, args.one, args.variants, args.workers, args.output_interval,
                             args.in_memory, args.soak)))
        return
    results, baseline = [], []
    runs = [(d, False) for d in args.durations] + [(d, True) for d in args.in_memory_durations]
    for duration, in_memory in runs:
        out = subprocess.run([sys.executable, __file__, "--one", str(duration), "--system", args.system,
                              "--variants", str(args.variants), "--workers", str(args.workers),
                              "--output-interval", str(args.output_interval), *(["--in-memory"] * in_memory),
                              *(["--soak"] * args.soak)],
                             capture_output=True, text=True, check=True)
        r = json.loads(out.stdout.strip().splitlines()[-1])
        (baseline if in_memory else results).append(r)
        print(f"{r['mode']:>18}: {duration / 60:5.1f} min x {r['variants']} variants on {r['workers']} workers: "
              f"wall {r['wall_s']:7.1f} s "
              f"({r['wall_s'] * r['workers'] / r['variants'] / r['steps_per_variant'] * 1e6:.1f} us a step per "
              f"worker); client peak {r['client_peak_mb']:.0f} MB; worker peaks "
              f"{', '.join(f'{w:.0f}' for w in r['worker_peak_mb'])} MB; {r['rows_per_variant']} rows, "
              f"{r['csv_mb_per_variant']:.1f} MB CSV a variant", flush=True)
    first, last = results[0], results[-1]
    growth = {"client_mb": round(last["client_peak_mb"] - first["client_peak_mb"], 1),
              "worker_mb": round(max(last["worker_peak_mb"]) - max(first["worker_peak_mb"]), 1)}
    print(f"streamed growth {first['duration_s'] / 60:g} min -> {last['duration_s'] / 60:g} min variants: "
          f"client {growth['client_mb']:+.1f} MB, largest worker {growth['worker_mb']:+.1f} MB")
    if len(baseline) > 1:
        b0, b1 = baseline[0], baseline[-1]
        print(f"in memory (before) growth {b0['duration_s'] / 60:g} min -> {b1['duration_s'] / 60:g} min variants: "
              f"client {b1['client_peak_mb'] - b0['client_peak_mb']:+.1f} MB, largest worker "
              f"{max(b1['worker_peak_mb']) - max(b0['worker_peak_mb']):+.1f} MB")
    cost = None
    if args.step_cost:
        cost = step_cost(args.system, args.step_cost, args.output_interval, args.soak)
        print(f"step cost, one process, {args.step_cost:g} s variants, medians of 5 interleaved: streamed "
              f"{cost['streamed_us_per_step']} us, in memory {cost['in_memory_us_per_step']} us "
              f"(ratio {cost['streamed_over_in_memory']})")
    if args.json:
        args.json.write_text(json.dumps({"runs": results, "in_memory_runs": baseline, "growth": growth,
                                         "step_cost": cost}, indent=2) + "\n")


if __name__ == "__main__":
    main()
