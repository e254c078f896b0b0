"""Parameter sweeps on dask.distributed.

    from ncfmu.batch import sweep
    summary = sweep("lathe_roughing", {"seq.block[1].Xd": [0.4, 0.5, 0.6]}, out="sweep_xd", workers=2)

The cartesian product of the values runs on a dask LocalCluster of worker *processes* (pythonfmu
FMUs hold the GIL, threads would not run in parallel) or on an existing cluster (``scheduler``).
Each worker opens a system once -- its FMUs instantiated once -- and resets them (``fmi2Reset``)
between variants. Each variant writes ``DIR/variants/<key>.csv``; ``DIR/summary.csv`` has one row per
variant: the varied values, ``status`` (ok / failed), ``error`` and the system's summary metrics. A
failing variant is recorded and the others complete; running the same sweep again skips the variants
already in the summary.
"""

from __future__ import annotations

import csv
import hashlib
import itertools
import json
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np

from .checks import path_distance
from .errors import NcfmuError, SystemDefinitionError

SUMMARY = "summary.csv"

# -- metrics per system ----------------------------------------------------------------------------


def _first_time(result, mask) -> float:
    return float(result.time[np.argmax(mask)]) if mask.any() else float("nan")


def metrics(result, parameters: Mapping[str, object] | None = None) -> dict[str, float]:
    """Summary numbers of a run, by what the system contains."""
    out: dict[str, float] = {"sim_time": float(result.time[-1]), "wall_time": float(result.wall_time)}
    fe = [abs(result[f"{a}.following_error"]).max() for a in ("x_axis", "y_axis", "z_axis")
          if f"{a}.following_error" in result]
    if fe:
        out["max_following_error_mm"] = float(max(fe))
    if "seq.subcycle" in result:
        cut = result["seq.subcycle"] == 2
        out["final_radius_mm"] = float(result["x_axis.pos"][cut].min()) if cut.any() else float("nan")
        out["cycle_time_s"] = _first_time(result, result["seq.done"])
        out["alarms"] = int(result["seq.alarm"].any()) + int("limiter.alarm" in result and result["limiter.alarm"].any())
    if "feed.pc" in result:
        out["deepest_x_mm"] = float(result["x_axis.pos"].max())
        active = result["feed.run"] | result["feed.emergency_active"]
        out["cycle_time_s"] = float(result.time[np.flatnonzero(active)[-1] + 1]) if active.any() and not active[-1] \
            else float("nan")
        out["alarms"] = int(result["feed.alarm"].any()) + int("limiter.alarm" in result and result["limiter.alarm"].any())
    if "contour.segment" in result:
        from .controllers.contour import ContourInterpolator
        names = {p.name for p in ContourInterpolator.ports("parameter")}
        values = {k.split(".", 1)[1]: v for k, v in (parameters or {}).items()
                  if k.startswith("contour.") and k.split(".", 1)[1] in names}
        path = ContourInterpolator(**values).path
        on = result["contour.segment"] >= 1
        best = path_distance(result["x_axis.pos"][on], result["y_axis.pos"][on], path)
        out["max_contour_error_mm"] = float(best.max()) if len(best) else float("nan")
        out["cycle_time_s"] = _first_time(result, result["contour.done"])
        out["alarms"] = int(result["contour.alarm"].any())
    return out


# -- the worker side -------------------------------------------------------------------------------
_OPEN: dict[str, object] = {}      # per worker process: archive -> OpenSystem, FMUs instantiated once


def run_variant(archive: str, variant: Mapping[str, object], stop_time: float | None, out_csv: str) -> dict:
    """Run one variant in this process, reusing the opened system; never raises."""
    from .project import OpenSystem
    t0 = time.perf_counter()
    row: dict[str, object] = {}
    opened = _OPEN.get(archive)
    try:
        if opened is None:
            opened = _OPEN[archive] = OpenSystem(Path(archive))
        else:
            for slave in opened.slaves:
                slave.reset()
        base = {f"{c.name}.{k}": v for c in opened.system.components for k, v in c.parameters.items()}
        result = opened.run(stop_time=stop_time, start_values=dict(variant))
        result.to_csv(Path(out_csv))
        row.update(status="ok", error="")
        row.update(metrics(result, {**base, **variant}))
    except NcfmuError as err:
        row.update(status="failed", error=str(err))
        _discard(archive)              # an instance after fmi2Fatal is unusable: open afresh next time
    except Exception as err:           # a crash in one variant must not end the sweep
        row.update(status="failed", error=f"{type(err).__name__}: {err}")
        _discard(archive)
    row["wall_time"] = round(time.perf_counter() - t0, 4)
    return row


def _discard(archive: str) -> None:
    opened = _OPEN.pop(archive, None)
    if opened is not None:
        try:
            opened.close()
        except Exception:
            pass


# -- the sweep -------------------------------------------------------------------------------------
def variant_key(variant: Mapping[str, object]) -> str:
    text = json.dumps({k: variant[k] for k in sorted(variant)}, sort_keys=True)
    return hashlib.sha1(text.encode()).hexdigest()[:10]


def product(vary: Mapping[str, Sequence[object]]) -> list[dict[str, object]]:
    names = list(vary)
    for name in names:
        if "." not in name:
            raise SystemDefinitionError(f"--vary {name!r}: expected INSTANCE.VARIABLE")
        if not vary[name]:
            raise SystemDefinitionError(f"--vary {name}: no values")
    return [dict(zip(names, values)) for values in itertools.product(*(vary[n] for n in names))]


def _read_summary(path: Path) -> list[dict[str, str]]:
    if not path.is_file():
        return []
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def _write_summary(path: Path, rows: list[dict[str, object]], varied: list[str]) -> None:
    columns = ["key", *varied, "status", "error"]
    for row in rows:
        for k in row:
            if k not in columns:
                columns.append(k)
    partial = path.with_suffix(".csv.part")
    with open(partial, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=columns)
        writer.writeheader()
        for row in rows:
            writer.writerow({k: row.get(k, "") for k in columns})
    partial.replace(path)


class Progress:
    """done / failed / remaining on one terminal line (silent when not on a terminal)."""

    def __init__(self, total: int, stream=sys.stderr) -> None:
        self.total, self.done, self.failed, self.stream = total, 0, 0, stream
        self.tty = hasattr(stream, "isatty") and stream.isatty()
        self.show()

    def update(self, ok: bool) -> None:
        self.done += ok
        self.failed += not ok
        self.show()

    def show(self) -> None:
        if not self.tty:
            return
        n = self.done + self.failed
        width = 30
        filled = int(width * n / self.total) if self.total else width
        self.stream.write(f"\r[{'#' * filled}{'.' * (width - filled)}] done {self.done}  failed {self.failed}  "
                          f"remaining {self.total - n} ")
        self.stream.flush()

    def close(self) -> None:
        if self.tty:
            self.stream.write("\n")


def sweep(system: str, vary: Mapping[str, Sequence[object]], out: Path, workers: int = 2,
          scheduler: str | None = None, stop_time: float | None = None, root: Path | None = None,
          progress: bool = True, on_done: Callable[[dict], None] | None = None) -> list[dict[str, object]]:
    """Run the cartesian product of ``vary`` on ``system``; return the summary rows.

    ``workers = 0`` runs the variants serially in this process (no dask).
    """
    from .project import system_archive
    out = Path(out)
    (out / "variants").mkdir(parents=True, exist_ok=True)
    archive = str(system_archive(system, root).resolve())
    variants = product(vary)
    varied = list(vary)
    summary_path = out / SUMMARY
    previous = {row["key"]: row for row in _read_summary(summary_path)}
    rows: dict[str, dict[str, object]] = {}
    todo = []
    for v in variants:
        key = variant_key(v)
        if key in previous:
            rows[key] = previous[key]
        else:
            todo.append((key, v))
    bar = Progress(len(todo)) if progress and todo else None

    def record(key, variant, row):
        rows[key] = {"key": key, **variant, **row}
        _write_summary(summary_path, [rows[k] for k in (variant_key(v) for v in variants) if k in rows], varied)
        if bar:
            bar.update(row["status"] == "ok")
        if on_done:
            on_done(rows[key])

    if todo and (workers == 0 and scheduler is None):
        for key, v in todo:
            record(key, v, run_variant(archive, v, stop_time, str(out / "variants" / f"{key}.csv")))
    elif todo:
        from dask.distributed import Client, LocalCluster, as_completed
        cluster = None
        if scheduler is None:
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                   dashboard_address=None)
            client = Client(cluster)
        else:
            client = Client(scheduler)
        try:
            futures = {client.submit(run_variant, archive, v, stop_time, str(out / "variants" / f"{key}.csv"),
                                     pure=False): (key, v) for key, v in todo}
            for future in as_completed(futures):
                key, v = futures[future]
                record(key, v, future.result())
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
    if bar:
        bar.close()
    return [rows[variant_key(v)] for v in variants]
