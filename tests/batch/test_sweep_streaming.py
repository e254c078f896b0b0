"""Sweep workers stream: no trajectory in memory or in a message, the rows fetched in chunks, prefixes kept."""

from __future__ import annotations

import csv
import pickle
from pathlib import Path

import pytest

from ncfmu import batch
from ncfmu.batch import run_variant, sweep
from ncfmu.cosim.result import csv_bytes
from ncfmu.project import simulate, system_archive
from ncfmu.systems import report_of

pytestmark = pytest.mark.slow        # whole systems in closed loop: not in the fast subset


def summary(out: Path) -> dict[str, dict[str, str]]:
    with open(out / "summary.csv", newline="") as f:
        return {r["key"]: r for r in csv.DictReader(f)}


def in_memory(system: str, variant: dict, stop_time: float, record: list[str] | None = None, every: int = 1):
    """What a sweep wrote before it streamed: the whole run in memory, its columns picked, every k-th row."""
    r = simulate(system, stop_time=stop_time, start_values=variant)
    keep = record if record is not None else report_of(r).record()
    return r, csv_bytes(r.data[["time", *keep]][::every])


def test_a_dask_sweeps_files_and_metrics_are_the_in_memory_runs(project, tmp_path, monkeypatch):
    """On a real 2-worker LocalCluster: each variant's file is byte for byte the in-memory run's CSV, its
    metrics those of the whole trajectory; the workers wrote the rows into DIR/variants, where the client renamed
    them: it fetched nothing over the cluster's connection, and no rows file is left anywhere."""
    from distributed import Client
    fetches = []
    run = Client.run
    monkeypatch.setattr(Client, "run", lambda self, *a, **k: fetches.append(a) or run(self, *a, **k))
    vary = {"feed.D3": [4.0, 3.5]}
    rows = sweep("grinder_feed", vary, tmp_path, workers=2, stop_time=3.0, progress=False,
                 record=["x_axis.pos", "feed.pc", "feed.alarm"], output_interval=0.005)
    # 3 s of a 32 s grinding cycle: the variants ran to their stop time with the cycle still running
    assert [r["status"] for r in rows] == ["unfinished", "unfinished"]
    written = summary(tmp_path)
    for row in rows:
        variant = {"feed.D3": row["feed.D3"]}
        r, expected = in_memory("grinder_feed", variant, 3.0, ["x_axis.pos", "feed.pc", "feed.alarm"], every=5)
        got = (tmp_path / "variants" / f"{row['key']}.csv").read_bytes()
        assert len(got) > 10_000 and got == expected
        assert int(row["rows"]) == 601
        metrics = report_of(r).metrics(r, r.parameters)
        for name in ("sim_time", "deepest_x_mm", "cycle_time_s", "max_following_error_mm", "alarms"):
            assert written[row["key"]][name] == str(metrics[name]), name        # every step, not every 5th
    assert not list(Path(batch._worker_folder(), "rows").glob(f"*{row['key']}*")) and fetches == []
    assert sorted(p.name for p in (tmp_path / "variants").iterdir()) == sorted(f"{r['key']}.csv" for r in rows)


def test_a_serial_sweep_renames_its_rows_into_place(project, tmp_path, monkeypatch):
    """workers=0: the rows are written into DIR/variants and renamed there, never read back and copied; the
    file is the in-memory run's, byte for byte."""
    monkeypatch.setattr(batch, "read_rows", lambda *a: pytest.fail(f"the rows were copied: read_rows{a}"))
    rows = sweep("grinder_feed", {"feed.D3": [4.0]}, tmp_path, workers=0, stop_time=1.0, progress=False)
    _, expected = in_memory("grinder_feed", {"feed.D3": 4.0}, 1.0)
    assert (tmp_path / "variants" / f"{rows[0]['key']}.csv").read_bytes() == expected
    assert [p.name for p in (tmp_path / "variants").iterdir()] == [f"{rows[0]['key']}.csv"]


def test_what_a_worker_answers_does_not_grow_with_the_variant(project, tmp_path):
    """The answer a worker sends (its row and where its rows are) is the same size for 1 s and 20 s of
    simulated time; the rows stay in the worker's file until fetched."""
    data = system_archive("grinder_feed").read_bytes()
    import hashlib
    digest = hashlib.sha256(data).hexdigest()
    sizes = []
    for stop in (1.0, 20.0):
        answer = run_variant(data, digest, {"feed.D3": 4.0}, stop, None, 1, None)
        assert answer["row"]["status"] == "unfinished" and answer["row"]["rows"] == int(stop * 1000) + 1
        sizes.append(len(pickle.dumps(answer)))
        path = Path(answer["trajectory"]["path"])
        assert path.stat().st_size == answer["trajectory"]["size"] > 1000 * stop * 20   # >= 20 bytes a row
        batch.remove_rows(str(path))
        assert not path.exists()
    assert sizes[1] <= sizes[0] + 64 and sizes[1] < 4096


def test_a_timed_out_variant_leaves_the_rows_it_recorded(project, tmp_path):
    """A deadline mid-run: ``<key>.csv.partial`` is a byte prefix of the whole run's file (whole rows), the row
    says how many rows and up to when, with the metrics of those rows; ``<key>.csv`` is not written."""
    # a panel that repeats its cycle: never done, the run would go on to the 3000 s
    rows = sweep("grinder_feed", {"feed.D3": [4.0], "panel.repeat_every": [80.0]}, tmp_path, workers=0,
                 stop_time=3000.0, progress=False, timeout=3.0)
    row = rows[0]
    assert row["status"] == "timeout" and "over the time allowed" in row["error"]
    assert not (tmp_path / "variants" / f"{row['key']}.csv").exists()
    prefix = (tmp_path / "variants" / f"{row['key']}.csv.partial").read_bytes()
    n, stopped = int(row["rows"]), float(row["sim_time"])
    assert 1000 < n < 3_000_000 and stopped == pytest.approx((n - 1) * 1e-3)
    r, whole = in_memory("grinder_feed", {"feed.D3": 4.0, "panel.repeat_every": 80.0}, stopped)
    assert prefix == whole and len(prefix.splitlines()) == n + 1
    assert float(row["deepest_x_mm"]) == float(r["x_axis.pos"].max())
    # its row lost (an interrupted sweep), the variant runs again, to the end: the whole file replaces the prefix
    (tmp_path / "summary.csv").unlink()
    again = sweep("grinder_feed", {"feed.D3": [4.0], "panel.repeat_every": [80.0]}, tmp_path, workers=0,
                  stop_time=5.0, progress=False)
    assert again[0]["status"] == "unfinished" and (tmp_path / "variants" / f"{row['key']}.csv").is_file()
    assert not list((tmp_path / "variants").glob("*.partial"))


