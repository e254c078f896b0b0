"""Sweeps into one DIR at once: the summary's merge where the folder cannot be locked, temporary files left by a
failed write (plain Python: no system runs)."""

from __future__ import annotations

import csv
import errno
import fcntl
import os
import subprocess
import sys
from pathlib import Path

import pytest

from ncfmu import files
from ncfmu.batch import _merge_summary, _remove_rows_files, _remove_temporary_files, _write_rows
from ncfmu.errors import NcfmuError
from ncfmu.files import machine_id


def _rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


@pytest.mark.parametrize("code", [errno.ENOLCK, errno.EBADF])
def test_a_summary_is_merged_where_the_folder_cannot_be_locked(tmp_path, monkeypatch, code):
    """The lock only keeps two sweeps' writes from interleaving: on a filesystem without ``flock`` (some NFS
    mounts: ENOLCK; EBADF where NFS emulates it with a byte-range lock) a sweep still writes its summary, merged
    into the rows another sweep wrote there: it failed with one line, for good, after its first variant ran."""
    summary = tmp_path / "summary.csv"
    summary.write_text("key,feed.D3,status,error,rows\nb,4.2,ok,,1001\n")

    def no_lock(fd: int, operation: int) -> None:
        raise OSError(code, os.strerror(code))

    monkeypatch.setattr(fcntl, "flock", no_lock)
    ours = {"a": {"key": "a", "feed.D3": 4.0, "status": "ok", "error": "", "rows": 1001}}
    _merge_summary(summary, ours, ["a"], {"a"}, ["feed.D3"])
    assert [(r["key"], r["feed.D3"], r["rows"]) for r in _rows(summary)] == [("a", "4.0", "1001"),
                                                                            ("b", "4.2", "1001")]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["summary.csv"]


def test_a_failed_atomic_write_leaves_no_temporary_file(tmp_path, monkeypatch):
    """A write that fails (a full disk) leaves the old file as it was and no ``NAME.<pid>.part``: with the pid in
    the name, each failed process would leave one more, for good, where no sweep's start looks (OUT of
    ``ncfmu run``, the pack's folder)."""
    target = tmp_path / "result.csv"
    target.write_bytes(b"old\n")

    def full(fd: int) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(files.os, "fsync", full)
    with pytest.raises(OSError, match="No space left"):
        files.write_atomic(target, b"new\n")
    assert target.read_bytes() == b"old\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["result.csv"]


def test_a_summary_saved_with_a_byte_order_mark_keeps_its_rows(tmp_path):
    """A summary saved by a spreadsheet ("CSV UTF-8": a BOM before ``key``) while sweeps run: its rows are the
    rows another sweep wrote -- read as rows without a key, the merge dropped every one of them (and a sweep's
    start ran their variants again)."""
    summary = tmp_path / "summary.csv"
    summary.write_bytes(b"\xef\xbb\xbfkey,feed.D3,status,error,rows\r\nb,4.2,ok,,1001\r\n")
    ours = {"a": {"key": "a", "feed.D3": 4.0, "status": "ok", "error": "", "rows": 1001}}
    _merge_summary(summary, ours, ["a"], {"a"}, ["feed.D3"])
    assert [(r["key"], r["feed.D3"], r["rows"]) for r in _rows(summary)] == [("a", "4.0", "1001"),
                                                                            ("b", "4.2", "1001")]


def test_a_fetch_that_breaks_off_leaves_no_temporary_file(tmp_path):
    """A remote worker's rows that end early (the worker lost mid-fetch): the sweep says so, and leaves no
    ``<key>.csv.<pid>.part`` in DIR/variants -- with the pid in the name, only a later sweep's start removed it."""
    (tmp_path / "variants").mkdir()
    trajectory = {"path": "/elsewhere/abc-1.rows", "size": 100, "complete": True}

    def read(path: str, offset: int, size: int) -> bytes:
        return b"time,x\n0,1\n" if offset == 0 else b""

    with pytest.raises(NcfmuError, match="the rows of variant abc ended at byte 11 of 100 on the worker"):
        _write_rows(tmp_path, "abc", trajectory, read)
    assert list((tmp_path / "variants").iterdir()) == []


def test_a_sweeps_start_leaves_another_machines_files_alone(tmp_path):
    """A sweep on another host sharing DIR (NFS) or in another container: its pids mean nothing here -- taken for
    ended processes', its running variant's rows were removed (that variant recorded ``failed``, for good) and its
    summary's temporary file too. Its files name their machine and are left to it; this machine's of an ended
    process are removed as before."""
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    pid = int(dead.stdout)
    variants = tmp_path / "variants"
    variants.mkdir()
    other = "0badcafe" if machine_id() != "0badcafe" else "0badcaff"
    theirs = [variants / f"539bf8893b-{pid}@{other}.rows.partial", tmp_path / f"summary.csv.{pid}@{other}.part"]
    ours = [variants / f"539bf8893b-{pid}@{machine_id()}.rows.partial",
            tmp_path / f"summary.csv.{pid}@{machine_id()}.part"]
    for path in [*theirs, *ours]:
        path.write_text("time,x\n0,")
    _remove_rows_files(variants)
    _remove_temporary_files(tmp_path)
    assert [path.exists() for path in theirs] == [True, True] and [path.exists() for path in ours] == [False, False]


def test_a_temporary_file_names_its_process_and_machine(tmp_path, monkeypatch):
    """What the file names carry is what a sweep's start reads back: ``<pid>@<machine>``."""
    seen = []
    monkeypatch.setattr(files.Path, "replace", lambda part, target: seen.append(part.name))
    files.write_atomic(tmp_path / "summary.csv", b"key\n")
    assert seen == [f"summary.csv.{os.getpid()}@{machine_id()}.part"]


def test_a_summary_row_with_more_fields_than_its_header_is_refused_naming_the_line(tmp_path):
    """A row edited by hand with a field too many (a comma in an error text, a column pasted): refused before any
    variant runs, naming the file and the line -- it was written back under a column with an empty name."""
    from ncfmu.batch import sweep
    summary = tmp_path / "summary.csv"
    edited = "key,feed.D3,status,error,rows\nb,4.2,ok,,1001\nc,4.4,ok,a, b,1001\n"
    summary.write_text(edited)
    with pytest.raises(NcfmuError, match=rf"{summary}: line 3 has 6 fields, its header 5: .*fix or remove the line"):
        sweep("grinder_feed", {"feed.D3": [4.0]}, tmp_path, workers=0, stop_time=0.01, progress=False)
    assert summary.read_text() == edited and not list(tmp_path.rglob("*.csv.*")) and not list(tmp_path.glob("v*/*"))
