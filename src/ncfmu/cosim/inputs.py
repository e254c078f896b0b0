"""Inputs over time: an input CSV read into an :class:`InputTable`, and a session's writes written back as one.

fmpy's layout (``time``, then ``INSTANCE.VARIABLE`` columns); a cell holds a value, is empty (no change at this
row) or says ``release`` (the connection drives the input again). The master applies a table (its schedule:
:meth:`~ncfmu.cosim.master.Master.prepare`); :func:`write_input_csv` turns a session's writes into a table that
replays it exactly.
"""

from __future__ import annotations

import csv
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import SystemDefinitionError
from ..ports import NUMBER_RULE, parse_real

__all__ = ["EMPTY", "RELEASE", "VALUE", "InputTable", "write_input_csv"]

#: An input CSV cell: a value, empty (no change at this row), or ``release`` (the connection drives it again).
VALUE, EMPTY, RELEASE = 1, 0, 2

#: How close to a communication point an input change counts as at it (s).
TIME_SLACK = 1e-12


@dataclass
class InputTable:
    """Changes over time (columns ``INSTANCE.VARIABLE``), applied before the first step at or after their time.

    A column may be an input no connection drives (its value from that row's time on, as fmpy reads an input
    CSV), an input a connection drives (forced to that value from that time), or a tunable parameter (set at
    that time). ``cells[name]`` says per row whether the cell holds a value (:data:`VALUE`), is empty
    (:data:`EMPTY`: no change at this row) or says ``release`` (:data:`RELEASE`: the connection, or the start
    value of an input no connection drives, drives it again); a column without ``cells`` holds values only.
    """

    time: np.ndarray
    columns: dict[str, np.ndarray] = field(default_factory=dict)
    cells: dict[str, np.ndarray] = field(default_factory=dict)

    def cell_kinds(self, name: str) -> np.ndarray:
        kinds = self.cells.get(name)
        return np.full(len(self.time), VALUE, dtype=np.int8) if kinds is None else kinds

    @classmethod
    def from_csv(cls, path) -> InputTable:
        """Read fmpy's CSV layout (``time``, then ``INSTANCE.VARIABLE`` columns; names may be quoted): numbers,
        empty cells (no change) and the word ``release``. Every mistake is a :class:`SystemDefinitionError`
        naming the file, the line and what is wrong."""
        try:
            with open(path, newline="") as f:
                lines = list(csv.reader(f))
        except (OSError, UnicodeDecodeError, csv.Error) as err:
            raise SystemDefinitionError(f"{path}: cannot read the input CSV: {err}") from None
        if not lines or not any(cell.strip() for cell in lines[0]):
            raise SystemDefinitionError(f"{path}: the input CSV is empty "
                                        "(expected a header time,INSTANCE.VARIABLE,...)")
        header = [h.strip() for h in lines[0]]
        if header[0] != "time":
            raise SystemDefinitionError(f"{path}: an input CSV needs a first column 'time'")
        seen = set()
        for name in header:
            if name in seen:
                raise SystemDefinitionError(f"{path}: line 1: column {name!r} twice")
            seen.add(name)
        rows = [(k, r) for k, r in enumerate(lines[1:], start=2) if any(cell.strip() for cell in r)]
        if not rows:
            raise SystemDefinitionError(f"{path}: the input CSV has a header and no rows")
        table = np.full((len(rows), len(header)), np.nan)
        kinds = np.full((len(rows), len(header)), VALUE, dtype=np.int8)
        for i, (k, row) in enumerate(rows):
            if len(row) != len(header):
                raise SystemDefinitionError(f"{path}: line {k}: {len(row)} values for {len(header)} columns")
            for j, raw in enumerate(row):
                cell = raw.strip()
                if j and not cell:
                    kinds[i, j] = EMPTY
                elif j and cell == "release":
                    kinds[i, j] = RELEASE
                else:
                    try:
                        table[i, j] = parse_real(cell)
                    except ValueError:
                        raise SystemDefinitionError(f"{path}: line {k}: {header[j]} = {raw!r}: not a number"
                                                    + ("" if j == 0 else ", empty (no change) or 'release'")
                                                    + ("" if cell.isascii() else f" ({NUMBER_RULE})")) from None
        t = table[:, 0]
        if not np.all(np.isfinite(t)):
            k = rows[int(np.flatnonzero(~np.isfinite(t))[0])][0]
            raise SystemDefinitionError(f"{path}: line {k}: time must be finite")
        if np.any(np.diff(t) < 0):
            raise SystemDefinitionError(f"{path}: the time column must not decrease")
        return cls(t, {n: table[:, j] for j, n in enumerate(header) if j > 0},
                   {n: kinds[:, j] for j, n in enumerate(header) if j > 0 and (kinds[:, j] != VALUE).any()})


def write_input_csv(path: Path | str, writes: Iterable[tuple[float, str, object]]) -> Path:
    """A session's write log as an input CSV that :meth:`InputTable.from_csv` reads back: fmpy's layout (``time``,
    then quoted names), one row per write (``None`` -> ``release``), every other cell empty (no change)."""
    writes = list(writes)
    names = list(dict.fromkeys(name for _, name, _ in writes))
    column = {name: j for j, name in enumerate(names)}
    lines = [",".join(f'"{n}"' for n in ["time", *names])]
    for t, name, value in writes:
        cells = [""] * len(names)
        if value is None:
            cells[column[name]] = "release"
        elif isinstance(value, (bool, np.bool_)):
            cells[column[name]] = "1" if value else "0"
        elif isinstance(value, (int, np.integer)):
            cells[column[name]] = str(int(value))
        else:
            cells[column[name]] = repr(float(value))     # type: ignore[arg-type]  # shortest round-trip form: read back exactly
        lines.append(",".join([repr(float(t)), *cells]))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    from ..files import write_atomic
    write_atomic(path, ("\n".join(lines) + "\n").encode())
    return path
