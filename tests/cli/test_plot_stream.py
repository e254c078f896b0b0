"""Plots of runs of any length in bounded memory (issue 37): ``--plot`` draws from the run's stream and ``ncfmu plot``
reads a CSV in chunks, both through a peak-detect decimation (:class:`ncfmu.cosim.record.DecimatingSink`) that keeps
every bucket's extremes and edges. Before, ``--plot`` held every row (about 4 MB per simulated second of a lathe
run: 641 MB peak for the 113 s Fanuc program here) and the replot read the whole file (685 MB for 200k rows)."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ncfmu.cosim.record import DecimatingSink
from ncfmu.exitcodes import EXIT_NOT_FINISHED, EXIT_OK

DTYPE = np.dtype([("time", np.float64), ("x", np.float64), ("alarm", np.bool_), ("line", np.int32)])


def _feed(data: np.ndarray, chunks: list[int], buckets: int) -> DecimatingSink:
    sink = DecimatingSink("test", buckets=buckets)
    sink.open([(n, DTYPE[n]) for n in DTYPE.names])
    at = 0
    for size in chunks:
        sink.write(data[at:at + size])
        at += size
    sink.write(data[at:])
    sink.close(True)
    return sink


def _per_bucket(values: np.ndarray, bucket: np.ndarray, how) -> np.ndarray:
    starts = np.flatnonzero(np.concatenate(([True], bucket[1:] != bucket[:-1])))
    return how.reduceat(values, starts)


def _steps(kept_index: np.ndarray, kept: np.ndarray, n: int) -> np.ndarray:
    """The kept values as a step curve at every row of the run (each held until the next kept row)."""
    return kept[np.searchsorted(kept_index, np.arange(n), side="right") - 1]


@settings(max_examples=60, deadline=None)
@given(n=st.integers(1, 3000), buckets=st.integers(1, 40), seed=st.integers(0, 2 ** 31),
       chunks=st.lists(st.integers(0, 700), max_size=8), flips=st.integers(1, 400))
def test_the_decimation_keeps_every_buckets_extremes_and_its_edges(n, buckets, seed, chunks, flips):
    rng = np.random.default_rng(seed)
    data = np.zeros(n, DTYPE)
    data["time"] = np.arange(n) * 1e-3
    data["x"] = np.cumsum(rng.normal(size=n))
    data["x"][rng.integers(n)] += 1e3 * rng.choice([-1, 1])           # a one-step spike somewhere
    data["alarm"] = rng.random(n) < 1 / flips
    data["line"] = np.cumsum(rng.random(n) < 1 / flips)
    sink = _feed(data, chunks, buckets)
    index, kept = sink.index, sink.data
    # bounded: at most `buckets` buckets of a power-of-two width, each keeping a few rows per column
    width = sink.width
    assert width & (width - 1) == 0 and (n - 1) // width < buckets
    assert len(kept) <= ((n - 1) // width + 1) * (2 + 5 * 3)
    # every row kept is a row of the run, in time order, the first and the last among them
    assert np.all(np.diff(index) > 0) and index[0] == 0 and index[-1] == n - 1
    assert np.array_equal(kept, data[index])
    # the min/max envelope per bucket is the raw trace's, exactly
    raw_bucket, kept_bucket = np.arange(n) // width, index // width
    for name in ("x", "alarm", "line"):
        raw, mine = data[name].astype(np.float64), kept[name].astype(np.float64)
        for how in (np.minimum, np.maximum):
            assert np.array_equal(_per_bucket(raw, raw_bucket, how), _per_bucket(mine, kept_bucket, how)), name
    # an alarm or a line number that changes at most twice in a bucket is exact as a step curve
    for name in ("alarm", "line"):
        raw = data[name]
        changes = np.concatenate(([0], np.diff(raw.astype(np.int64)) != 0))
        quiet = np.bincount(raw_bucket, weights=changes) <= 2
        steps = _steps(index, kept[name], n)
        assert np.array_equal(steps[quiet[raw_bucket]], raw[quiet[raw_bucket]]), name


def test_a_one_step_spike_of_a_long_run_survives():
    n = 1_000_001                                    # 1000 s at 1 ms
    data = np.zeros(n, DTYPE)
    data["time"] = np.arange(n) * 1e-3
    data["x"] = np.sin(data["time"])
    data["x"][654_321] = 7.5                         # one step
    data["alarm"][777_777] = True                    # an alarm for one step
    sink = _feed(data, [2600] * 384, 2048)
    kept = sink.data
    assert len(kept) < 2048 * 8
    assert kept["x"].max() == 7.5 and kept["time"][kept["x"].argmax()] == data["time"][654_321]
    [on] = np.flatnonzero(kept["alarm"])
    assert kept["time"][on] == data["time"][777_777] and not kept["alarm"][on + 1]


def test_a_short_run_is_kept_whole():
    data = np.zeros(2048, DTYPE)
    data["time"] = np.arange(2048) * 1e-3
    data["x"] = np.random.default_rng(0).normal(size=2048)
    sink = _feed(data, [100, 1000], 2048)
    assert sink.width == 1 and np.array_equal(sink.data, data)


def test_a_long_grinder_run_decimated_marks_the_feed_hold_as_before(ncfmu_run):
    """The hold's start and end rows are kept exactly: the legend's count and duration are the full run's."""
    import matplotlib.pyplot as plt

    from ncfmu.plots import result_figure
    from ncfmu.systems.report import columns_of
    held = ncfmu_run("grinder_feed", start_values={"panel.hold_at": 12.0, "panel.release_at": 15.0})
    sink = DecimatingSink("grinder_feed", buckets=256)
    sink.open(columns_of(held.data))
    for at in range(0, len(held.data), 2600):
        sink.write(held.data[at:at + 2600])
    shown = sink.result()
    assert sink.width >= 128 and len(shown.data) < len(held.data) / 10
    fig = result_figure(shown)
    labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert "feed hold: 1 time, 3 s" in labels
    plt.close(fig)


# -- memory: a subprocess measures its own peak RSS -------------------------------------------------------
_PEAK = """
import resource, sys
from ncfmu.cli import main
status = main(sys.argv[1:])
print("PEAK_KB", resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, "STATUS", status)
"""


def _peak_mb(args: list[str], cwd, status: int = 0) -> float:
    proc = subprocess.run([sys.executable, "-c", _PEAK, *args], capture_output=True, text=True, cwd=cwd,
                          timeout=600)
    line = proc.stdout.strip().splitlines()[-1]
    assert line.startswith("PEAK_KB") and line.endswith(f"STATUS {status}"), proc.stdout[-500:] + proc.stderr[-1000:]
    return int(line.split()[1]) / 1024


@pytest.mark.slow
def test_plot_of_a_run_holds_no_more_for_a_longer_run(project, tmp_path):
    """Before: every row kept (grinder_feed: 93.6 MB at 10 s, 153.5 MB at 40 s: 2 MB per simulated second);
    now 92.8 and 93.7 MB."""
    from conftest import ROOT
    peaks = {}
    for stop in (10, 40):
        out = tmp_path / f"t{stop}"
        peaks[stop] = _peak_mb(["--root", str(ROOT), "run", "grinder_feed", "--stop-time", str(stop),
                                "--set", "panel.repeat_every=40", "--out", str(out), "--plot"], tmp_path,
                                # a repeating panel runs to the limit: at 10 s its first part is not finished
                                EXIT_NOT_FINISHED if stop == 10 else EXIT_OK)
        assert (out / "grinder_feed.png").stat().st_size > 10_000
    print("peak RSS [MB] by stop time:", peaks)
    assert peaks[40] - peaks[10] < 8, peaks


def _write_lathe_csv(path, n: int) -> None:
    """A lathe_roughing CSV of ``n`` rows (the system plot's columns), written in chunks."""
    from ncfmu.cosim.result import csv_header, csv_rows
    from ncfmu.systems import report_for
    names = report_for("lathe_roughing").record()
    dtype = np.dtype([("time", np.float64), *[(name, np.float64) for name in names]])
    with open(path, "wb") as f:
        f.write(csv_header(dtype.names))
        for at in range(0, n, 50_000):
            k = np.arange(at, min(n, at + 50_000))
            rows = np.zeros(len(k), dtype)
            rows["time"] = k * 1e-3
            rows["x_axis.pos"] = 25 + 5 * np.sin(k * 1e-4)
            rows["z_axis.pos"] = 2 - 40 * (k % 10_000) / 10_000
            rows["x_axis.following_error"] = 1e-3 * np.cos(k * 3e-3)
            rows["seq.line"] = (k // 1000) % 20          # the same lines over and over (as a soak)
            f.write(csv_rows(rows))


@pytest.mark.slow
def test_the_replot_of_a_200k_row_csv_is_bounded(tmp_path):
    """Before: the whole file as lists of strings (here 124 MB for 50k rows, 334 MB for 200k; 685 MB for 200k
    rows of a lathe run's 51 columns); now chunks: 128 and 129 MB."""
    peaks = {}
    for n in (50_000, 200_000):
        csv = tmp_path / f"n{n}" / "lathe_roughing.csv"
        csv.parent.mkdir()
        _write_lathe_csv(csv, n)
        peaks[n] = _peak_mb(["plot", str(csv)], tmp_path)
        assert csv.with_suffix(".png").stat().st_size > 10_000
    print("peak RSS [MB] by rows:", peaks)
    assert peaks[200_000] - peaks[50_000] < 8, peaks


def test_the_replot_reads_what_from_csv_reads(tmp_path):
    """The streamed reader is Result.from_csv's, chunk by chunk: the same columns, dtypes and values."""
    from ncfmu.cosim.result import Result
    from ncfmu.plots import read_plot_csv
    csv = tmp_path / "r.csv"
    lines = ['"time","a","flag"'] + [f"{k * 0.01!r},{float(np.sin(k))!r},{'True' if k % 7 else 'False'}"
                                     for k in range(500)]
    csv.write_text("\n".join(lines) + "\n")
    whole = Result.from_csv(csv)
    for chunk in (1, 7, 1000):
        streamed = read_plot_csv(csv, chunk_rows=chunk)
        assert streamed.data.dtype == whole.data.dtype and np.array_equal(streamed.data, whole.data)
    bad = tmp_path / "bad.csv"
    bad.write_text('"time","flag"\n0,True\n1,False\n2,3\n')
    from ncfmu.errors import SystemDefinitionError
    with pytest.raises(SystemDefinitionError, match=r"line 4: flag = '3': not True/False as in the lines before"):
        read_plot_csv(bad, chunk_rows=2)
    with pytest.raises(SystemDefinitionError) as whole_file:
        Result.from_csv(bad)
    with pytest.raises(SystemDefinitionError, match=r"line 2: flag = 'True': not a number or True/False") as read:
        read_plot_csv(bad)
    assert str(read.value) == str(whole_file.value)
