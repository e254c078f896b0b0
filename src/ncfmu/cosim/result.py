"""Simulation results: a numpy structured array with ``time`` and one field per ``INSTANCE.VARIABLE``."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..ports import NUMBER_RULE, parse_real


def csv_header(names) -> bytes:
    """The header line of fmpy's CSV layout: every name quoted."""
    return (",".join(f'"{n}"' for n in names) + "\n").encode()


def csv_rows(data: np.ndarray) -> bytes:
    """The rows of a structured array in fmpy's CSV layout, each ending in a newline (no header): floats in
    their shortest round-trip form, Booleans as 0/1. Column by column: fmpy formats value by value (~4x
    slower, longer than a lathe_roughing run itself)."""
    names = data.dtype.names
    assert names is not None, "a trajectory is a structured array"
    if not len(data):
        return b""
    columns = []
    for n in names:
        col = data[n]
        if col.dtype == np.bool_:
            col = col.astype(np.int8)
        columns.append(list(map(repr if col.dtype.kind == "f" else str, col.tolist())))
    return ("\n".join(map(",".join, zip(*columns))) + "\n").encode()


def csv_bytes(data: np.ndarray) -> bytes:
    """A structured array as CSV text in fmpy's layout (``"time","x_axis.pos",...``), byte for byte what
    :func:`fmpy.util.write_csv` writes and :func:`fmpy.util.read_csv` reads (header, then :func:`csv_rows`)."""
    names = data.dtype.names
    assert names is not None, "a trajectory is a structured array"
    return csv_header(names) + csv_rows(data)


class Result:
    """Trajectories of one run.

    ``result["x_axis.pos"]`` is a numpy array over ``result.time``; ``result.data`` is the
    structured array (fmpy's layout); :meth:`to_csv` writes fmpy's CSV layout. ``parameters``
    (instance -> variable -> value) are the start values the run applied: the system's parameter sets
    with the caller's on top (the rest were the FMUs' defaults); a branch's also hold the tunable parameters
    and inputs set at its branch point. ``models`` maps instance -> FMU model.
    A result read from a CSV has neither. A run that kept no trajectory in memory (its rows went to sinks)
    has zero rows; ``span`` then says which simulated time it covered (:attr:`start_time`, :attr:`end_time`).
    """

    def __init__(self, data: np.ndarray, system: str = "", wall_time: float = 0.0,
                 messages: dict[str, list[tuple[str, str]]] | None = None,
                 parameters: dict[str, dict[str, object]] | None = None,
                 models: dict[str, str] | None = None, span: tuple[float, float] | None = None) -> None:
        self.data = data
        self.span = span
        self.system = system
        self.wall_time = wall_time
        self.messages = messages or {}
        self.parameters = parameters or {}
        self.models = models or {}
        #: the master's warning lines about the system (units, connections, free inputs), one per problem
        self.warnings: list[str] = []
        #: why the run ended before its stop time when an FMU asked it to (else "")
        self.ended_by = ""

    @property
    def time(self) -> np.ndarray:
        return self.data["time"]

    @property
    def _fields(self) -> tuple[str, ...]:
        """``time`` and the recorded ``INSTANCE.VARIABLE`` names: the structured array's fields."""
        fields = self.data.dtype.names
        assert fields is not None, "a result is a structured array"
        return fields

    @property
    def names(self) -> list[str]:
        return list(self._fields[1:])

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self.data[name]
        except (KeyError, ValueError):
            raise KeyError(f"no recorded variable {name!r}; recorded: {', '.join(self.names[:12])}...") from None

    def __contains__(self, name: str) -> bool:
        return name in self._fields

    @property
    def start_time(self) -> float:
        return float(self.time[0]) if len(self.data) else (self.span[0] if self.span else 0.0)

    @property
    def end_time(self) -> float:
        """The last simulated time: the last row's, or the span's end when no rows were kept."""
        if self.span is not None:
            return self.span[1]
        return float(self.time[-1]) if len(self.data) else 0.0

    @property
    def realtime_factor(self) -> float:
        """Simulated seconds per wall-clock second."""
        span = self.end_time - self.start_time
        return span / self.wall_time if self.wall_time > 0 else float("inf")

    def to_csv(self, path: Path) -> Path:
        """Write fmpy's CSV layout (see :func:`csv_bytes`; Booleans as 0/1, which fmpy's read_csv parses)."""
        from ..files import write_atomic
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        write_atomic(path, csv_bytes(self.data))
        return path

    @classmethod
    def from_csv(cls, path: Path) -> Result:
        """Read fmpy's CSV layout: ``time``, then one column per variable.

        Numbers are read as float64; a column of True/False (how :func:`fmpy.util.write_csv` writes Booleans,
        which fmpy's own ``read_csv`` cannot read back) as Booleans. Every mistake is a
        :class:`~ncfmu.errors.SystemDefinitionError` naming the file, the line and the column.
        """
        import csv

        from ..errors import SystemDefinitionError
        path = Path(path)
        try:
            with open(path, newline="", encoding="utf-8-sig") as f:    # a BOM (Excel's "CSV UTF-8") is not a name
                lines = list(csv.reader(f))
        except (OSError, UnicodeDecodeError, csv.Error) as err:
            raise SystemDefinitionError(f"{path}: cannot read the result CSV: {err}") from None
        if not lines or not any(cell.strip() for cell in lines[0]):
            raise SystemDefinitionError(f"{path}: the result CSV is empty (expected a header time,NAME,...)")
        header = [h.strip() for h in lines[0]]
        if header[0] != "time":
            raise SystemDefinitionError(f"{path}: a result CSV needs a first column 'time', not {header[0]!r}")
        for j, name in enumerate(header):
            if name in header[:j]:
                raise SystemDefinitionError(f"{path}: line 1: column {name!r} twice")
        rows = [(k, row) for k, row in enumerate(lines[1:], start=2) if any(cell.strip() for cell in row)]
        if not rows:
            raise SystemDefinitionError(f"{path}: the result CSV has a header and no rows")
        for k, row in rows:
            if len(row) != len(header):
                raise SystemDefinitionError(f"{path}: line {k}: {len(row)} values for {len(header)} columns")
        columns: dict[str, np.ndarray] = {}
        for j, name in enumerate(header):
            cells = [row[j].strip() for _, row in rows]
            words = {c.lower() for c in cells}
            columns[name] = csv_column(path, name, rows, cells, j > 0 and words <= {"true", "false"})
        bad_time = np.flatnonzero(~np.isfinite(columns["time"]))
        if bad_time.size:
            raise SystemDefinitionError(f"{path}: line {rows[int(bad_time[0])][0]}: time must be finite")
        data = np.empty(len(rows), dtype=[(name, columns[name].dtype) for name in header])
        for name in header:
            data[name] = columns[name]
        return cls(data)


def csv_column(path: object, name: str, rows: list, cells: list[str], boolean: bool) -> np.ndarray:
    """One column of a result CSV from its cells (``rows``: the (line number, row) each came from): True/False
    as Booleans when ``boolean``, else ASCII decimal numbers -- a cell that is neither named with its line."""
    from ..errors import SystemDefinitionError
    if boolean:
        return np.array([c == "true" for c in map(str.lower, cells)])
    try:
        # numpy's conversion, like float(), takes any Unicode digit and '_': only plain ASCII goes through
        joined = "".join(cells)
        if not joined.isascii() or "_" in joined:
            raise ValueError("not ASCII decimal")
        return np.array(cells).astype(np.float64)
    except ValueError:
        for (k, _), cell in zip(rows, cells):
            try:
                parse_real(cell)
            except ValueError:
                rule = "" if cell.isascii() else f" ({NUMBER_RULE})"
                raise SystemDefinitionError(f"{path}: line {k}: {name} = {cell!r}: not a number or "
                                            f"True/False{rule}") from None
        raise
