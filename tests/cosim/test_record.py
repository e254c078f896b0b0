"""Streaming a run's rows into sinks: the streamed CSV is byte for byte the in-memory run's CSV, chunk size and
output interval change no value, an interrupted run leaves a valid prefix under ``.partial`` and says where it
stopped, and only what is kept in memory is refused for its size."""

import resource
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from fmpy.util import read_csv

from ncfmu.cli import main
from ncfmu.cosim import master as master_module
from ncfmu.cosim.record import CsvSink, MemorySink
from ncfmu.cosim.result import csv_bytes
from ncfmu.errors import SimulationTimeout, SystemDefinitionError
from ncfmu.exitcodes import EXIT_NOT_FINISHED
from ncfmu.project import OpenSystem, simulate

ROOT = Path(__file__).resolve().parents[2]


def in_memory_csv(system, stop_time, record=None, every=1, **kwargs):
    """Today's way: the whole run in memory, then the columns and rows picked (as the sweeps do)."""
    r = simulate(system, stop_time=stop_time, **kwargs)
    data = r.data if record is None else r.data[["time", *record]]
    return csv_bytes(data[::every]), r


@pytest.mark.parametrize("system, stop, extra, record, every", [
    pytest.param("lathe_roughing", 12.0, [], None, 1, marks=pytest.mark.slow),
    pytest.param("grinder_feed", 35.0, ["--set", "panel.emergency_at=20"], None, 1, marks=pytest.mark.slow),
    ("mill_contour", 9.0, ["--output-interval", "0.007"], ["x_axis.pos", "y_axis.pos", "contour.segment",
                                                           "contour.alarm"], 7),
])
def test_the_streamed_csv_is_the_in_memory_csv_byte_for_byte(project, tmp_path, monkeypatch, capsys,
                                                             system, stop, extra, record, every):
    monkeypatch.setattr(master_module, "WINDOW_BYTES", 40_000)      # many chunks: the joints are tested
    args = ["run", system, "--stop-time", str(stop), "--out", str(tmp_path), *extra]
    if record:
        args += ["--record", *record]
    # none finishes its work: the lathe and the mill stop at the limit, the grinder's EMB aborts its only part
    assert main(args) == EXIT_NOT_FINISHED
    printed = capsys.readouterr().out
    start_values = {"panel.emergency_at": 20} if "--set" in extra else None
    streamed = (tmp_path / f"{system}.csv").read_bytes()
    # the grinder's run ended where its work did (the emergency return's end), within a second; the others at the
    # limit's last row: in memory to there
    end = float(streamed.rsplit(b"\n", 2)[-2].split(b",")[0])
    if system == "grinder_feed":
        ended = float(printed.split("cycle ended: ")[1].split(" s")[0])
        assert 20.0 < ended < end <= ended + 1.0
    else:
        assert end == pytest.approx(int(round(stop / 0.001)) // every * every * 0.001)
    expected, result = in_memory_csv(system, round(end, 9), record, every, start_values=start_values)
    assert streamed == expected
    assert not (tmp_path / f"{system}.csv.partial").exists()
    # the summary computed as the run went is the one from the whole trajectory
    from ncfmu.cli import _summary
    # (less the lines naming the files it wrote: the CSV and the part check's record)
    # and the lines of how the run ended and came out: the in-memory run knows neither)
    summary = [line for line in printed.splitlines()[1:] if not line.startswith(("  results:", "  part check:",
                                                                                  "  ended:"))
               and "(exit status" not in line]
    assert summary == _summary(result).splitlines()[1:]
    if every > 1:
        assert len(read_csv(str(tmp_path / f"{system}.csv"))) == int(stop / 0.001) // every + 1


@pytest.mark.parametrize("native", [True, False])
def test_chunks_and_the_output_interval_change_no_value(project, monkeypatch, native):
    """A run streamed through a window of a few rows into a MemorySink equals the run kept in memory."""
    archive = ROOT / "ssp" / "lathe_taper.ssp"
    record = ["x_axis.pos", "seq.subcycle", "limiter.alarm", "z_axis.pos"]
    with OpenSystem(archive) as opened:
        opened.master.native = native
        kept = opened.run(stop_time=2.0, record=record, output_interval=0.003)
    assert kept.names == record and len(kept.data) == 2000 // 3 + 1
    assert kept.data.dtype["seq.subcycle"] == np.int32 and kept.data.dtype["limiter.alarm"] == np.bool_
    monkeypatch.setattr(master_module, "WINDOW_BYTES", 3000)       # ~5 rows of every output per chunk
    sink = MemorySink()
    with OpenSystem(archive) as opened:
        opened.master.native = native
        streamed = opened.run(stop_time=2.0, record=record, output_interval=0.003, sinks=[sink], keep=False)
    assert len(streamed.data) == 0 and streamed.end_time == pytest.approx(2.0)
    assert sink.complete is True and sink.stopped_at == pytest.approx(1.998)
    assert sink.data.dtype == kept.data.dtype and np.array_equal(sink.data, kept.data)
    # the values are the full run's every third row
    with OpenSystem(archive) as opened:
        full = opened.run(stop_time=2.0)
    for name in record:
        assert np.array_equal(kept[name], full[name][::3]), name
    assert np.array_equal(kept.time, full.time[::3])


def test_a_deadline_leaves_a_valid_prefix_under_partial(project, tmp_path, monkeypatch):
    monkeypatch.setattr(master_module, "WINDOW_BYTES", 50_000)
    path = tmp_path / "taper.csv"
    sink = CsvSink(path)
    with OpenSystem(ROOT / "ssp" / "lathe_taper.ssp") as opened, pytest.raises(SimulationTimeout):
        opened.run(stop_time=50.0, sinks=[sink], keep=False, deadline=time.perf_counter() + 0.5)
    assert not path.exists() and sink.final_path == path.with_name("taper.csv.partial")
    text = sink.final_path.read_bytes()
    assert text.endswith(b"\n") and sink.rows > 100
    assert len(text.splitlines()) == sink.rows + 1
    assert float(text.splitlines()[-1].split(b",")[0]) == sink.stopped_at
    # every row written is the run's, whole: the same bytes as a run that stops there
    assert csv_bytes(simulate("lathe_taper", stop_time=sink.stopped_at).data) == text


@pytest.mark.slow
@pytest.mark.parametrize("signum, status, says", [(signal.SIGTERM, 143, "terminated (SIGTERM)"),
                                                  (signal.SIGINT, 130, "interrupted")])
def test_ctrl_c_and_sigterm_leave_a_valid_prefix_and_say_where(project, tmp_path, signum, status, says):
    ncfmu = Path(sys.executable).with_name("ncfmu")
    proc = subprocess.Popen([str(ncfmu), "run", "lathe_taper", "--stop-time", "10000", "--out", str(tmp_path)],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    partial = tmp_path / "lathe_taper.csv.partial"
    deadline = time.time() + 120
    while time.time() < deadline and (not partial.exists() or partial.stat().st_size < 2_000_000):
        time.sleep(0.2)
    proc.send_signal(signum)
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == status, err
    assert not (tmp_path / "lathe_taper.csv").exists()
    assert says in err and str(partial) in err and "rows up to t = " in err
    data = read_csv(str(partial))
    stopped = float(err.split("rows up to t = ")[1].split(" s")[0])
    assert data["time"][-1] == pytest.approx(stopped, abs=5e-4) and len(data) > 1000
    head = simulate("lathe_taper", stop_time=float(data["time"][-1]))
    assert csv_bytes(head.data) == partial.read_bytes()


def test_only_what_is_kept_in_memory_is_refused(project):
    with pytest.raises(SystemDefinitionError, match=r"must stay under 8 GiB \(rows x bytes per row\)"):
        simulate("lathe_taper", stop_time=100000)
    with OpenSystem(ROOT / "ssp" / "lathe_taper.ssp") as opened:
        session = opened.master.open_session(stop_time=100000)          # keeps nothing: no refusal
        session.advance(10)
        assert session.close().end_time == pytest.approx(0.01)


def test_a_csv_that_cannot_fit_on_the_disk_is_refused_before_the_run(project, tmp_path):
    """Streaming lifts the memory limit, not every limit: a billion seconds would not fit on any disk."""
    assert main(["run", "lathe_taper", "--stop-time", "0.1", "--out", str(tmp_path)]) == EXIT_NOT_FINISHED  # fits
    with pytest.raises(SystemDefinitionError, match=r"stop time 1e\+09 s at a step of 0.001 s: 1000000000001 rows "
                                                    r"of \d+ columns: the CSV may need up to .* GiB"):
        simulate("lathe_taper", stop_time=1e9, keep=False,
                 sinks=[CsvSink(tmp_path / "huge.csv", expected_rows=10 ** 12 + 1,
                                run="stop time 1e+09 s at a step of 0.001 s")])
    assert not (tmp_path / "huge.csv").exists() and not (tmp_path / "huge.csv.partial").exists()


#: A run whose folder fills up: a 64 MB tmpfs in a mount namespace of its own (no root needed, nothing left
#: mounted), filled by another writer once the run has written its first rows. $1 the mount point, $2 a folder
#: outside it that keeps what the test reads, $3 the ncfmu console script.
FILLS_UP = r'''
mount -t tmpfs -o size=64m tmpfs "$1" || exit 97
"$3" run lathe_taper --stop-time 40 --out "$1" 2> "$2/stderr" & pid=$!
while kill -0 $pid 2>/dev/null && [ "$(stat -c %s "$1/lathe_taper.csv.partial" 2>/dev/null || echo 0)" -lt 300000 ]
do sleep 0.02; done
dd if=/dev/zero of="$1/filler" bs=64k 2>/dev/null
wait $pid; echo $? > "$2/status"
cp "$1/lathe_taper.csv.partial" "$2/"
ls "$1" > "$2/listing"
'''


def _run_until_the_disk_is_full(tmp_path: Path) -> tuple[int, str, Path, Path]:
    """``ncfmu run`` into a folder that fills up during the run: (exit status, stderr, the folder it wrote to,
    a copy of what it left). A real ENOSPC where the machine allows a mount namespace; else the write refused by
    a file-size limit (EFBIG, RLIMIT_FSIZE) -- the same kind of refusal, at the same place."""
    ncfmu = Path(sys.executable).with_name("ncfmu")
    full, kept = tmp_path / "full", tmp_path / "kept"
    full.mkdir()
    kept.mkdir()
    if shutil.which("unshare"):
        proc = subprocess.run(["unshare", "-rm", "sh", "-c", FILLS_UP, "sh", str(full), str(kept), str(ncfmu)],
                              cwd=ROOT, capture_output=True, text=True, timeout=300)
        if proc.returncode == 0:
            status = int((kept / "status").read_text())
            return status, (kept / "stderr").read_text(), full, kept / "lathe_taper.csv.partial"
        assert proc.returncode == 97 or "unshare" in proc.stderr, proc.stderr    # no namespaces here: the limit

    def limit_file_size():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)          # a refused write, not a killed process
        resource.setrlimit(resource.RLIMIT_FSIZE, (3_000_000, 3_000_000))

    proc = subprocess.run([str(ncfmu), "run", "lathe_taper", "--stop-time", "40", "--out", str(full)], cwd=ROOT,
                          capture_output=True, text=True, timeout=300, preexec_fn=limit_file_size)
    return proc.returncode, proc.stderr, full, full / "lathe_taper.csv.partial"


@pytest.mark.slow
def test_a_full_disk_keeps_whole_rows_and_says_where(project, tmp_path):
    """The disk fills during ``ncfmu run``: the CSV keeps whole rows only (a prefix of the run, byte for byte)
    and one line says why, the file and how many rows it holds -- as Ctrl-C does."""
    status, err, folder, partial = _run_until_the_disk_is_full(tmp_path)
    lines = err.strip().splitlines()
    assert status == 2 and len(lines) == 1 and "Traceback" not in err, err
    line = lines[0]
    assert line.startswith("ncfmu run: writing the rows failed (No space left on device") or \
        line.startswith("ncfmu run: writing the rows failed (File too large"), line
    assert "rows up to t = " in line and f"in {folder / 'lathe_taper.csv.partial'} (the run did not finish)" in line
    text = partial.read_bytes()
    rows = int(line.split("): ")[1].split(" rows")[0])
    assert text.endswith(b"\n") and len(text.splitlines()) == rows + 1 and rows > 100, (rows, text[-200:])
    stopped = float(line.split("rows up to t = ")[1].split(" s")[0])
    data = read_csv(str(partial))
    assert data["time"][-1] == pytest.approx(stopped, abs=5e-4)
    assert csv_bytes(simulate("lathe_taper", stop_time=float(data["time"][-1])).data) == text


def test_rows_the_disk_cannot_sync_stay_partial_and_say_so(tmp_path, monkeypatch):
    """fsync at the end can still fail (a disk that accepted the writes and cannot store them): the file stays
    ``.partial`` and the error names it -- a run never claims a CSV it could not store."""
    import errno
    import os

    from ncfmu.cosim import record
    sink = CsvSink(tmp_path / "run.csv")
    sink.open([("time", np.dtype(np.float64)), ("x", np.dtype(np.float64))])
    sink.write(np.array([(0.0, 1.0), (0.001, 2.0)], dtype=[("time", np.float64), ("x", np.float64)]))

    def no_room(fd):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    monkeypatch.setattr(record.os, "fsync", no_room)
    with pytest.raises(record.RecordWriteError, match=r"run.csv.partial: No space left on device"):
        sink.close(complete=True)
    assert sink.final_path == tmp_path / "run.csv.partial" and not (tmp_path / "run.csv").exists()
    assert sink.final_path.read_bytes() == b'"time","x"\n0.0,1.0\n0.001,2.0\n'
