"""Where a served run's recording goes (``--out DIR``): :class:`Recorder`."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path


class Recorder:
    """Where a served run's recording goes (``--out DIR``): ``DIR/<system>.csv`` (every output, or ``--record``)
    and ``DIR/session_inputs.csv`` (the writes that took effect, an input CSV ``ncfmu run --input`` replays).

    A Reset ends a recording segment (the session starts again from its start values): the segment before the
    k-th Reset is kept as ``<system>.segment<k>.csv`` and ``session_inputs.segment<k>.csv``; the two files
    without a number always hold the run since the last Reset.
    """

    def __init__(self, system: str, out: Path) -> None:
        self.system, self.out = system, Path(out)
        self.segments = 0
        self.files: list[Path] = []
        self.out.mkdir(parents=True, exist_ok=True)

    @property
    def trajectory(self) -> Path:
        return self.out / f"{self.system}.csv"

    def sinks(self) -> list:
        from ..cosim.record import CsvSink
        return [CsvSink(self.trajectory)]

    def end_segment(self, writes: Sequence[tuple[float, str, object]], final: bool, start: float = 0.0) -> None:
        """After the session closed its sinks: name the segment's files and write its writes (a segment without
        writes: one row at its ``start`` time that changes nothing -- an input CSV with a header and no rows is
        refused by ``ncfmu run --input`` as a mistake)."""
        from ..cosim.master import write_input_csv
        from ..files import write_atomic

        def inputs(path: Path) -> Path:
            if writes:
                return write_input_csv(path, writes)
            write_atomic(path, f'"time"\n{float(start)!r}\n'.encode())
            return path
        if final:
            self.files.append(inputs(self.out / "session_inputs.csv"))
            for path in (self.trajectory, self.trajectory.with_name(self.trajectory.name + ".partial")):
                if path.exists():
                    self.files.append(path)
            return
        self.segments += 1
        k = self.segments
        if self.trajectory.exists():
            self.files.append(self.trajectory.replace(self.out / f"{self.system}.segment{k}.csv"))
        self.files.append(inputs(self.out / f"session_inputs.segment{k}.csv"))
