"""Where the CPU of bench/run.py's 2-worker sweep goes: ``python bench/sweep_cpu.py [--stop S] [--json FILE]``.

The same 16-variant lathe_taper sweep as ``run.py``'s ``sweep_speedup`` (whole cycles, 50 s; ``--stop 6`` for a
quick look), serially in this process and then on a 2-worker LocalCluster, with CPU seconds (user + sys, psutil)
accounted

- per process: the client (this process; its threads split into the main thread -- results, CSV writing -- and
  the event loop thread, which runs the in-process scheduler and the client's comms), each nanny, each worker,
  and what the children left behind (``RUSAGE_CHILDREN`` after shutdown: CPU of processes already gone);
- per phase: cluster start (up to ``local_cluster`` returning), first results (up to each worker's first result:
  the scatter, the worker's imports and its opening of the system), steady state (first to last result), the
  end (last result to ``sweep`` returning: client and cluster close).

Wall-clock ratios on a shared machine are noisy; CPU seconds are not (much): work per variant (serial CPU / 16)
against the CPU a worker spends per variant in the steady state says how much slower a worker steps beside the
others, and the CPU of everything that is not a worker says what the second core loses to the machinery.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

import psutil

HERE = Path(__file__).resolve().parent
VARY = {"seq.block[1].Xd": [0.3, 0.35, 0.4, 0.45, 0.5, 0.55, 0.6, 0.65], "seq.block[1].feed": [3.0, 4.0]}


def cpu(p: psutil.Process) -> float:
    t = p.cpu_times()
    return t.user + t.system


def thread_cpu() -> dict[int, float]:
    return {t.id: t.user_time + t.system_time for t in psutil.Process().threads()}


def serial(stop: float, vary: dict | None = None) -> dict:
    from ncfmu.batch import sweep
    me = psutil.Process()
    marks: list[tuple[float, float]] = []
    with tempfile.TemporaryDirectory() as tmp:
        c0, t0 = cpu(me), time.perf_counter()
        sweep("lathe_taper", vary or VARY, Path(tmp) / "serial", workers=0, stop_time=stop, progress=False,
              on_done=lambda row: marks.append((cpu(me), time.perf_counter())))
        c1, t1 = cpu(me), time.perf_counter()
    per = [b[0] - a[0] for a, b in zip(marks, marks[1:])]
    return {"wall_s": t1 - t0, "cpu_s": c1 - c0, "first_variant_cpu_s": marks[0][0] - c0,
            "cpu_per_variant_s": statistics.median(per), "cpu_per_variant_mean_s": sum(per) / len(per),
            "wall_per_variant_s": statistics.median(b[1] - a[1] for a, b in zip(marks, marks[1:]))}


class Accounting:
    """Snapshots of every process of the cluster, taken at the sweep's events (in the client's main thread)."""

    def __init__(self) -> None:
        self.me = psutil.Process()
        self.cluster = None
        self.snaps: list[dict] = []
        self.main_tid = threading.get_native_id()

    def roles(self) -> dict[int, str]:
        """pid -> role: client, forkserver (the workers' parent, up from an earlier sweep too), nanny-i, worker-i."""
        out = {self.me.pid: "client"}
        workers = [] if self.cluster is None else self.cluster.scheduler.workers.values()
        pids = {ws.pid: i for i, ws in enumerate(sorted(workers, key=lambda w: w.address))}
        for child in self.me.children(recursive=True):
            try:
                if child.pid in pids:
                    out[child.pid] = f"worker-{pids[child.pid]}"
                elif "multiprocessing.forkserver" in " ".join(child.cmdline()):
                    out[child.pid] = "forkserver"        # the workers' parent: it imported once, then forked each
                elif child.ppid() == self.me.pid and any(c.pid in pids for c in child.children()):
                    out[child.pid] = f"nanny-{pids[next(c.pid for c in child.children() if c.pid in pids)]}"
                else:
                    out[child.pid] = f"other-{child.pid}"
            except psutil.NoSuchProcess:
                pass
        return out

    def done_by(self) -> dict[str, int]:
        """Worker role -> number of variants it finished (from the in-process scheduler's task states)."""
        if self.cluster is None:
            return {}
        workers = sorted(self.cluster.scheduler.workers.values(), key=lambda w: w.address)
        index = {w.address: i for i, w in enumerate(workers)}
        counts = {f"worker-{i}": 0 for i in index.values()}
        for ts in list(self.cluster.scheduler.tasks.values()):
            if str(ts.key).startswith("run_variant") and ts.state == "memory":
                for ws in ts.who_has or ():
                    counts[f"worker-{index[ws.address]}"] += 1
        return counts

    def snap(self, event: str) -> None:
        procs: dict[str, float] = {}
        for pid, role in self.roles().items():
            try:
                proc = psutil.Process(pid)
                procs[role] = cpu(proc)
                if role.startswith("worker"):       # its busiest thread runs the variants; the rest is dask's
                    busiest = max(t.user_time + t.system_time for t in proc.threads())
                    procs[role + "/task-thread"] = busiest
                    procs[role + "/other-threads"] = procs[role] - busiest
            except psutil.NoSuchProcess:
                pass
        threads = thread_cpu()
        main = threads.pop(self.main_tid, 0.0)
        ru = resource.getrusage(resource.RUSAGE_CHILDREN)
        self.snaps.append({"event": event, "t": time.perf_counter(), "cpu": procs, "client_main": main,
                           "client_threads": sum(threads.values()), "children_gone": ru.ru_utime + ru.ru_stime,
                           "done": self.done_by()})


def parallel(stop: float, workers: int) -> dict:
    import ncfmu.batch as batch
    acc = Accounting()
    make = batch.local_cluster

    def local_cluster(n: int):
        acc.cluster = make(n)
        acc.snap("cluster up")
        return acc.cluster
    batch.local_cluster = local_cluster
    try:
        with tempfile.TemporaryDirectory() as tmp:
            acc.snap("start")
            batch.sweep("lathe_taper", VARY, Path(tmp) / "dask", workers=workers, stop_time=stop, progress=False,
                        on_done=lambda row: acc.snap("result"))
            acc.cluster = None
            acc.snap("end")
    finally:
        batch.local_cluster = make
    return analyse(acc.snaps)


def analyse(snaps: list[dict]) -> dict:
    start, up, end = snaps[0], snaps[1], snaps[-1]
    results = [s for s in snaps if s["event"] == "result"]
    roles = sorted({r for s in snaps for r in s["cpu"]})
    workers = [r for r in roles if r.startswith("worker") and "/" not in r]
    last = results[-1]

    def delta(a: dict, b: dict, role: str) -> float:
        return b["cpu"].get(role, 0.0) - a["cpu"].get(role, 0.0)
    out: dict = {"wall_s": end["t"] - start["t"], "cluster_start_wall_s": up["t"] - start["t"],
                 "first_result_wall_s": results[0]["t"] - up["t"], "end_wall_s": end["t"] - last["t"]}
    # per process, whole run up to the last result (the workers are gone after it), and the end phase; a process
    # there before the sweep (the client, a forkserver an earlier sweep started) from the start
    out["cpu_by_process_s"] = {r: delta(start, last, r) for r in roles}
    out["client_main_thread_s"] = last["client_main"] - start["client_main"]
    out["client_other_threads_s"] = last["client_threads"] - start["client_threads"]
    out["end_client_cpu_s"] = end["cpu"]["client"] - last["cpu"]["client"]
    out["end_children_gone_cpu_s"] = end["children_gone"] - last["children_gone"]
    # phases: cluster start, first result of each worker, steady (each worker: its first to its last result)
    out["phase_cluster_start_cpu_s"] = {r: delta(start, up, r) for r in up["cpu"]}
    steady = {}
    for w in workers:
        own = [s for s in results if s["done"].get(w, 0) > 0]
        own = [s for i, s in enumerate(own) if i == 0 or s["done"][w] != own[i - 1]["done"][w]]
        first, final = own[0], own[-1]
        n = final["done"][w] - first["done"][w]
        steady[w] = {"first_result_cpu_s": first["cpu"][w], "first_done": first["done"][w],
                     "steady_task_thread_cpu_per_variant_s": (final["cpu"][w + "/task-thread"] -
                                                              first["cpu"][w + "/task-thread"]) / n if n else None,
                     "variants": final["done"][w], "steady_variants": n,
                     "steady_cpu_per_variant_s": (final["cpu"][w] - first["cpu"][w]) / n if n else None,
                     "steady_wall_per_variant_s": (final["t"] - first["t"]) / n if n else None}
    out["workers"] = steady
    # steady state of the whole cluster: from the later of the workers' first results to the earlier last one
    a = max((next(s for s in results if s["done"].get(w, 0) > 0) for w in workers), key=lambda s: s["t"])
    b = results[-2] if len(results) > 2 else results[-1]
    span = b["t"] - a["t"]
    out["steady_window_wall_s"] = span
    out["steady_cpu_per_wall_s"] = {r: delta(a, b, r) / span for r in roles} if span > 0 else {}
    out["steady_client_main_per_wall"] = (b["client_main"] - a["client_main"]) / span if span > 0 else None
    out["steady_client_threads_per_wall"] = (b["client_threads"] - a["client_threads"]) / span if span > 0 else None
    return out


def report(s: dict, p: dict) -> None:
    print(f"serial: {s['wall_s']:.2f} s wall, {s['cpu_s']:.2f} s CPU; first variant {s['first_variant_cpu_s']:.2f} s "
          f"CPU (opens the system), then {s['cpu_per_variant_s']:.3f} s CPU a variant (median; mean "
          f"{s['cpu_per_variant_mean_s']:.3f})")
    print(f"2 workers: {p['wall_s']:.2f} s wall (cluster up {p['cluster_start_wall_s']:.2f} s, first result "
          f"{p['first_result_wall_s']:.2f} s later, end {p['end_wall_s']:.2f} s); "
          f"wall ratio {s['wall_s'] / p['wall_s']:.2f}")
    print("  CPU s by process up to the last result:",
          ", ".join(f"{r} {v:.2f}" for r, v in p["cpu_by_process_s"].items()))
    print(f"  client: main thread {p['client_main_thread_s']:.2f} s, other threads (event loop: scheduler + comms) "
          f"{p['client_other_threads_s']:.2f} s; end phase: client {p['end_client_cpu_s']:.2f} s, children gone "
          f"{p['end_children_gone_cpu_s']:.2f} s")
    print("  cluster start CPU s:", ", ".join(f"{r} {v:.2f}" for r, v in p["phase_cluster_start_cpu_s"].items()))
    for w, d in p["workers"].items():
        per = d["steady_cpu_per_variant_s"]
        print(f"  {w}: {d['variants']} variants; CPU at its first result {d['first_result_cpu_s']:.2f} s; steady "
              f"{per:.3f} s CPU a variant ({100 * (per / s['cpu_per_variant_s'] - 1):+.1f} % vs serial; its task "
              f"thread {d['steady_task_thread_cpu_per_variant_s']:.3f} s), "
              f"{d['steady_wall_per_variant_s']:.3f} s wall")
    print(f"  steady state ({p['steady_window_wall_s']:.1f} s): CPU s per wall s:",
          ", ".join(f"{r} {v:.3f}" for r, v in p["steady_cpu_per_wall_s"].items()),
          f"(client main {p['steady_client_main_per_wall']:.3f}, other threads "
          f"{p['steady_client_threads_per_wall']:.3f})")


def pair(stop: float) -> dict:
    """Two serial sweeps of 8 variants each (feed 3 and 4) in two processes at once, no dask: what two busy cores
    cost a variant by themselves (shared caches, memory, the host under the VM)."""
    import subprocess
    with tempfile.TemporaryDirectory() as tmp:
        procs = [subprocess.Popen([sys.executable, __file__, "--half", str(i), "--stop", str(stop), "--json",
                                   f"{tmp}/{i}.json"], stdout=subprocess.DEVNULL) for i in (0, 1)]
        for proc in procs:
            proc.wait()
        halves = [json.loads(Path(f"{tmp}/{i}.json").read_text()) for i in (0, 1)]
    return {"halves": halves, "cpu_per_variant_mean_s": sum(h["cpu_per_variant_mean_s"] for h in halves) / 2,
            "wall_s": max(h["wall_s"] for h in halves)}


def main() -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--stop", type=float, default=50.0, help="simulated seconds a variant (run.py: 50)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--json", default=None)
    parser.add_argument("--config", action="append", default=[], metavar="KEY=VALUE",
                        help="a dask config value for the 2-worker run's cluster (e.g. "
                             "distributed.worker.multiprocessing-method=spawn)")
    parser.add_argument("--pair", action="store_true", help="also two serial halves side by side, no dask")
    parser.add_argument("--again", action="store_true",
                        help="a second 2-worker sweep in the same process after the first (its forkserver is up)")
    parser.add_argument("--half", type=int, default=None, help=argparse.SUPPRESS)
    parser.add_argument("--parallel-only", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.parallel_only:
        import yaml

        import ncfmu.batch
        # over the cluster's own settings too (batch.LOCAL_CLUSTER_CONFIG), which local_cluster sets over the client's
        settings = (c.split("=", 1) for c in args.config)
        ncfmu.batch.LOCAL_CLUSTER_CONFIG.update({k: yaml.safe_load(v) for k, v in settings})
        p = parallel(args.stop, args.workers)
        if args.again:
            p["again"] = parallel(args.stop, args.workers)
        Path(args.json).write_text(json.dumps(p))
        return p
    if args.half is not None:
        half = serial(args.stop, {"seq.block[1].Xd": VARY["seq.block[1].Xd"],
                                  "seq.block[1].feed": [VARY["seq.block[1].feed"][args.half]]})
        Path(args.json).write_text(json.dumps(half))
        return half
    from ncfmu.project import build
    build(HERE.parent)
    s = serial(args.stop)
    # the 2-worker sweep in a process of its own, as `ncfmu sweep` runs it: this one has opened the system for the
    # serial run, and a worker forked from it (batch.LOCAL_CLUSTER_CONFIG) would start with that system open
    import subprocess
    with tempfile.TemporaryDirectory() as tmp:
        subprocess.run([sys.executable, __file__, "--parallel-only", "--stop", str(args.stop), "--workers",
                        str(args.workers), "--json", f"{tmp}/p.json", *(f"--config={c}" for c in args.config),
                        *(["--again"] if args.again else [])],
                       check=True, stdout=subprocess.DEVNULL)
        p = json.loads(Path(f"{tmp}/p.json").read_text())
    out = {"config": args.config, "load_avg": os.getloadavg(), "stop_time_s": args.stop, "serial": s, "parallel": p}
    report(s, p)
    if "again" in p:
        print("the same sweep again, in the same process:")
        report(s, p["again"])
    if args.pair:
        out["pair"] = two = pair(args.stop)
        extra = 100 * (two["cpu_per_variant_mean_s"] / s["cpu_per_variant_mean_s"] - 1)
        print(f"two serial halves side by side (no dask): {two['wall_s']:.2f} s wall, "
              f"{two['cpu_per_variant_mean_s']:.3f} s CPU a variant (mean; serial alone "
              f"{s['cpu_per_variant_mean_s']:.3f} s: {extra:+.1f} %)")
        print(f"two plain processes' wall / the 2-worker sweep's: {two['wall_s'] / p['wall_s']:.3f}"
              + (f" (again: {two['wall_s'] / p['again']['wall_s']:.3f})" if "again" in p else ""))
    print(f"load average {os.getloadavg()[0]:.2f}")
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=2))
    return out


if __name__ == "__main__":
    sys.exit(0 if main() else 1)
