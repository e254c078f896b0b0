"""Where a run's recorded rows go: sinks the master streams chunks of rows into.

A run opens every sink once with its columns, writes the rows in chunks as the run goes (a numpy
structured array per chunk, rows in time order, the first chunk starting with the start row) and closes
the sinks once at the end, saying whether the run completed. What a sink holds is its own business: a
:class:`CsvSink` holds one chunk at most, so a run of any length streams to disk at flat memory; a
:class:`MemorySink` keeps everything (an in-memory :class:`~ncfmu.cosim.result.Result`).

Interrupted runs: a :class:`CsvSink` writes ``PATH.partial`` and renames it to ``PATH`` only when the run
completed. An interrupted run (Ctrl-C, SIGTERM, a deadline, an FMU error) leaves ``PATH.partial``: a valid CSV
in the same layout holding every row written so far (whole rows only); ``PATH`` itself is never written
half-way. :attr:`CsvSink.final_path` says which of the two holds the rows after :meth:`CsvSink.close`. A write
the machine refuses (a full disk, a file-size limit) is the same: ``PATH.partial`` is cut back to its last whole
row and :class:`RecordWriteError` says so; the run ends as interrupted.
"""

from __future__ import annotations

import io
import os
import shutil
from pathlib import Path
from typing import Protocol, runtime_checkable

import numpy as np

from ..errors import NcfmuError, SystemDefinitionError
from .result import Result, csv_header, csv_rows

#: The most a run may keep in memory: more is a mistake (stream it to a file instead).
MAX_RECORD_BYTES = 8 * 2 ** 30


@runtime_checkable
class RecordSink(Protocol):
    def open(self, columns: list[tuple[str, np.dtype]]) -> None:
        """Once, before the first row: ``("time", float64)`` first, then ``INSTANCE.VARIABLE`` columns with
        float64 (Real), int32 (Integer) or bool (Boolean)."""
        ...

    def write(self, rows: np.ndarray) -> None:
        """A chunk of rows as a numpy structured array with exactly those columns (rows in time order,
        the first chunk starts with the start time)."""
        ...

    def close(self, complete: bool, stopped_at: float | None = None, reason: str = "") -> None:
        """Once, at the end: ``complete`` False when the run was interrupted (Ctrl-C, SIGTERM, a deadline,
        an FMU error); ``stopped_at`` the time of the last row written."""
        ...


def too_big(rows: int, row_bytes: int, what: str) -> SystemDefinitionError | None:
    """The refusal for keeping ``rows`` rows of ``row_bytes`` bytes in memory, or None when it fits."""
    need = rows * row_bytes
    if need <= MAX_RECORD_BYTES:
        return None
    return SystemDefinitionError(
        f"{what}: keeping {rows} rows of {row_bytes} bytes in memory needs {need / 2 ** 30:.1f} GiB; an in-memory "
        f"result must stay under {MAX_RECORD_BYTES / 2 ** 30:g} GiB (rows x bytes per row): shorten the run, "
        "record fewer variables or a longer output interval, or stream the rows to a file instead of keeping them")


class MemorySink:
    """Keeps every chunk; :meth:`result` joins them into a :class:`Result` (refused past ``MAX_RECORD_BYTES``)."""

    def __init__(self, system: str = "") -> None:
        self.system = system
        self._chunks: list[np.ndarray] = []
        self._dtype: np.dtype | None = None
        self._bytes = 0
        self.complete: bool | None = None
        self.stopped_at: float | None = None
        self.reason = ""

    def open(self, columns: list[tuple[str, np.dtype]]) -> None:
        self._dtype = np.dtype([(name, dtype) for name, dtype in columns])
        self._chunks.clear()
        self._bytes = 0

    def write(self, rows: np.ndarray) -> None:
        self._bytes += rows.nbytes
        if self._bytes > MAX_RECORD_BYTES:
            assert self._dtype is not None
            err = too_big(self._bytes // self._dtype.itemsize, self._dtype.itemsize, "a memory sink")
            assert err is not None
            raise err
        self._chunks.append(rows.copy())

    def close(self, complete: bool, stopped_at: float | None = None, reason: str = "") -> None:
        self.complete, self.stopped_at, self.reason = complete, stopped_at, reason

    @property
    def data(self) -> np.ndarray:
        assert self._dtype is not None, "the sink was never opened"
        if len(self._chunks) != 1:
            self._chunks = [np.concatenate(self._chunks) if self._chunks else np.empty(0, self._dtype)]
        return self._chunks[0]

    def result(self) -> Result:
        return Result(self.data, self.system)


class RecordWriteError(NcfmuError):
    """The machine refused to take more rows (``ENOSPC``, ``EFBIG``, ...): the file keeps the whole rows written
    before; the message names the file and the reason (``errno``: the machine's error number)."""

    def __init__(self, path: Path, reason: str, errno: int | None) -> None:
        super().__init__(f"{path}: {reason}: no more rows could be written")
        self.path, self.reason, self.errno = path, reason, errno


class CsvSink:
    """fmpy's CSV layout, byte for byte what :meth:`Result.to_csv` writes, streamed chunk by chunk.

    The rows go to ``PATH.partial`` (unbuffered, a chunk in one write); :meth:`close` renames it to ``PATH`` when the
    run completed, and leaves it as ``PATH.partial`` (a valid CSV of every row written) when it did not.
    """

    #: Bytes a value of each column dtype takes in the CSV at most (a float's repr, a sign, the comma).
    WIDTH = {"f": 25, "i": 12, "b": 2}

    def __init__(self, path: Path | str, expected_rows: int | None = None, run: str = "") -> None:
        """``expected_rows``: when given, :meth:`open` refuses a run whose CSV could not fit in the free space of
        the folder (a stop time of a billion seconds is a mistake, not a run); ``run`` names it in the message."""
        self.path = Path(path)
        self.expected_rows = expected_rows
        self.run = run
        self.partial = self.path.with_name(self.path.name + ".partial")
        self.final_path: Path | None = None
        self.rows = 0
        self.stopped_at: float | None = None
        self._file: io.FileIO | None = None
        self._whole = 0
        self.failed: OSError | None = None

    def open(self, columns: list[tuple[str, np.dtype]]) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        if self.expected_rows is not None:
            row = sum(self.WIDTH.get(np.dtype(dtype).kind, 25) for _, dtype in columns)
            need = self.expected_rows * row
            free = shutil.disk_usage(self.path.parent).free
            if need > free:
                label = f"{self.run}: " if self.run else ""
                raise SystemDefinitionError(
                    f"{label}{self.expected_rows} rows of {len(columns)} columns: the CSV may need up to "
                    f"{need / 2 ** 30:.3g} GiB and {self.path.parent} has {free / 2 ** 30:.3g} GiB free: shorten the "
                    "run, record fewer variables or write fewer rows (a longer output interval)")
        # unbuffered: each chunk goes to the file at once, and a refused write leaves nothing pending in a buffer
        self._file = open(self.partial, "wb", buffering=0)
        self._whole = 0                       # the file's bytes up to the end of its last whole row
        self.failed = None
        self.rows = 0
        self._append(csv_header([name for name, _ in columns]))

    def write(self, rows: np.ndarray) -> None:
        assert self._file is not None, "write before open"
        if len(rows) and self.failed is None:
            # one write of whole rows: what is on disk always ends at a row boundary
            self._append(csv_rows(rows))
            self.rows += len(rows)
            self.stopped_at = float(rows["time"][-1])

    def _append(self, data: bytes) -> None:
        """Write all of ``data`` or nothing: a refused write (the disk full) cuts the file back to its last whole
        row and raises :class:`RecordWriteError`; the rows after it are not written (the run is over)."""
        assert self._file is not None
        view = memoryview(data)
        try:
            while view:
                done = self._file.write(view)
                view = view[done or 0:]
        except OSError as err:
            self.failed = err
            self._file.truncate(self._whole)  # the half-written chunk goes (cutting a file needs no room)
            raise RecordWriteError(self.partial, err.strerror or str(err), err.errno) from None
        self._whole += len(data)

    def close(self, complete: bool, stopped_at: float | None = None, reason: str = "") -> None:
        if self._file is None:
            return
        f, self._file = self._file, None
        synced: OSError | None = None
        try:
            os.fsync(f.fileno())
        except OSError as err:                # the disk could not take what it had accepted (delayed allocation)
            synced = err
        finally:
            f.close()
        if complete and self.failed is None and synced is None:
            self.partial.replace(self.path)
            self.final_path = self.path
            return
        self.final_path = self.partial
        if synced is not None and self.failed is None:
            self.failed = synced
            raise RecordWriteError(self.partial, synced.strerror or str(synced), synced.errno)


class SelectColumns:
    """A sink seen through a subset of the run's columns (``time`` and ``names``, in that order): when one run
    feeds sinks that need different columns (a CSV of what the user asked for, a summary of what it reads)."""

    def __init__(self, sink: RecordSink, names: list[str]) -> None:
        self.sink = sink
        self.names = ["time", *[n for n in dict.fromkeys(names) if n != "time"]]

    def open(self, columns: list[tuple[str, np.dtype]]) -> None:
        have = dict(columns)
        missing = [n for n in self.names if n not in have]
        if missing:
            raise SystemDefinitionError(f"record: the run does not record {', '.join(missing)}")
        self.sink.open([(n, have[n]) for n in self.names])

    def write(self, rows: np.ndarray) -> None:
        # a copy with exactly these fields (a multi-field view would keep the others' bytes as padding)
        part = np.empty(len(rows), dtype=[(n, rows.dtype[n]) for n in self.names])
        for n in self.names:
            part[n] = rows[n]
        self.sink.write(part)

    def close(self, complete: bool, stopped_at: float | None = None, reason: str = "") -> None:
        self.sink.close(complete, stopped_at, reason)


class EveryKth:
    """A sink that takes the start row and every ``k``-th row after it (an output interval of its own), while the
    run's other sinks see every step (a summary computed from every step, a CSV at 0.1 s)."""

    def __init__(self, sink: RecordSink, k: int) -> None:
        self.sink, self.k = sink, int(k)
        self._seen = 0                       # rows of the run before the present chunk

    def open(self, columns: list[tuple[str, np.dtype]]) -> None:
        self._seen = 0
        self.sink.open(columns)

    def write(self, rows: np.ndarray) -> None:
        first = (-self._seen) % self.k       # the chunk's first row whose run index is a multiple of k
        self._seen += len(rows)
        if first < len(rows):
            self.sink.write(rows[first::self.k])

    def close(self, complete: bool, stopped_at: float | None = None, reason: str = "") -> None:
        self.sink.close(complete, stopped_at, reason)


#: Time buckets a :class:`DecimatingSink` keeps at most: about two per pixel of a 10-inch figure at 100 dpi.
PLOT_BUCKETS = 2048


def peak_rows(index: np.ndarray, rows: np.ndarray, width: int) -> np.ndarray:
    """The positions in ``rows`` of the rows a peak-detect decimation keeps (ascending), in buckets of ``width``
    consecutive rows of the run (``index``: each row's index in the run, ascending; row ``i`` is in bucket
    ``i // width``): a bucket's first and last row and, per column, the first row of its smallest and of its
    largest value (an oscilloscope's peak detect: a one-step spike stays), its first NaN, the first row that differs
    from the bucket's first value and the row that starts its last constant stretch (a column that changes at most
    twice in a bucket, an alarm's edge or a hold's start and end, is exact as a step curve).

    Choosing again from rows chosen so (with the same or a doubled width) keeps every bucket's extremes: the
    smallest of a union is the smallest of one of its parts."""
    n = len(index)
    bucket = np.asarray(index) // width
    starts_mask = np.empty(n, bool)
    starts_mask[:1] = True
    np.not_equal(bucket[1:], bucket[:-1], out=starts_mask[1:])
    starts = np.flatnonzero(starts_mask)
    if len(starts) == n:                     # every row a bucket of its own: all are kept
        return np.arange(n)
    ends = np.append(starts[1:], n)          # exclusive
    seg = np.cumsum(starts_mask) - 1         # the bucket (counted in this call) of each row
    keep = np.zeros(n, bool)
    keep[starts] = True
    keep[ends - 1] = True

    def first_of_each(hit: np.ndarray) -> None:
        pos = np.flatnonzero(hit)
        if len(pos):
            s = seg[pos]
            keep[pos[np.concatenate(([True], s[1:] != s[:-1]))]] = True

    names = rows.dtype.names
    assert names is not None, "rows are a structured array"
    for name in names[1:]:                   # after time (ascending: its first and last row are kept)
        col = rows[name]
        if not _differs(col, col[:1]).any():
            continue                         # constant here: the first row has it all
        if col.dtype == np.bool_:
            col = col.view(np.uint8)
        if col.dtype.kind == "f":
            nan = np.isnan(col)
            if nan.any():
                first_of_each(nan)
            low, high = np.fmin.reduceat(col, starts), np.fmax.reduceat(col, starts)
        else:
            low, high = np.minimum.reduceat(col, starts), np.maximum.reduceat(col, starts)
        first_of_each(col == low[seg])
        first_of_each(col == high[seg])
        first_of_each(_differs(col, col[starts][seg]))
        # the last row that differs from the bucket's last value: the row after it starts the last stretch
        pos = np.flatnonzero(_differs(col, col[ends - 1][seg]))
        if len(pos):
            s = seg[pos]
            keep[pos[np.concatenate((s[1:] != s[:-1], [True]))] + 1] = True
    return np.flatnonzero(keep)


def _differs(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a != b`` where a NaN equals a NaN (a stretch of NaN is constant)."""
    out = a != b
    if a.dtype.kind == "f":
        out &= ~(np.isnan(a) & np.isnan(b))
    return out


class DecimatingSink:
    """What a figure can show of a run of any length, in memory bounded by ``buckets``: the rows
    :func:`peak_rows` keeps of buckets of ``width`` rows. ``width`` starts at 1 (a run of up to ``buckets`` rows is
    kept whole) and doubles whenever the run outgrows the buckets, choosing again from the rows kept (two adjacent
    buckets become one). Every row kept is a row of the run (its time and all its columns), so a path drawn in a
    machine plane goes through points the machine was at. :meth:`result` is a :class:`Result` of them."""

    def __init__(self, system: str = "", buckets: int = PLOT_BUCKETS) -> None:
        if buckets < 1:
            raise ValueError(f"buckets = {buckets}: must be >= 1")
        self.system, self.buckets = system, int(buckets)
        self.width = 1
        self.rows = 0                        # rows of the run seen
        self._parts: list[tuple[np.ndarray, np.ndarray]] = []     # (run index, rows) kept, in time order
        self._dtype: np.dtype | None = None
        self.complete: bool | None = None
        self.stopped_at: float | None = None

    def open(self, columns: list[tuple[str, np.dtype]]) -> None:
        self._dtype = np.dtype([(name, dtype) for name, dtype in columns])
        self._parts.clear()
        self.width, self.rows = 1, 0

    def write(self, rows: np.ndarray) -> None:
        if not len(rows):
            return
        index = np.arange(self.rows, self.rows + len(rows), dtype=np.int64)
        self.rows += len(rows)
        wider = False
        while (self.rows - 1) // self.width >= self.buckets:
            self.width *= 2
            wider = True
        if wider and self._parts:            # the kept rows into the wider buckets
            self._parts = [self._choose(*self._joined())]
        # the chunk's first bucket may have begun in the rows kept before: choose its rows again with the chunk's
        tail_index, tail_rows = np.empty(0, np.int64), rows[:0]
        if self._parts:
            last_index, last_rows = self._parts[-1]
            cut = int(np.searchsorted(last_index, index[0] // self.width * self.width))
            tail_index, tail_rows = last_index[cut:], last_rows[cut:]
            self._parts[-1] = (last_index[:cut], last_rows[:cut])
        self._parts.append(self._choose(np.concatenate((tail_index, index)), np.concatenate((tail_rows, rows))))

    def _choose(self, index: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        keep = peak_rows(index, rows, self.width)
        return index[keep], rows[keep]       # copies: nothing of the run's record window is held

    def _joined(self) -> tuple[np.ndarray, np.ndarray]:
        assert self._dtype is not None, "the sink was never opened"
        parts = [p for p in self._parts if len(p[0])]
        if not parts:
            return np.empty(0, np.int64), np.empty(0, self._dtype)
        return np.concatenate([i for i, _ in parts]), np.concatenate([r for _, r in parts])

    def close(self, complete: bool, stopped_at: float | None = None, reason: str = "") -> None:
        self.complete, self.stopped_at = complete, stopped_at

    @property
    def index(self) -> np.ndarray:
        """The run index of each row kept."""
        return self._joined()[0]

    @property
    def data(self) -> np.ndarray:
        """The rows kept, in time order."""
        return self._joined()[1]

    def result(self) -> Result:
        return Result(self.data, self.system)
