"""The part check's judgement of a lathe program's threads (G32, G92, G76), from the **actual** positions and the
spindle's encoder angle (``spindle.revolutions``), as the run streams.

Each pass of a thread (the sequencer's ``threading`` output rising: the k-th rise is the plan's k-th pass) is
collected from its marker until its Z comes to rest. With turns = revolutions x the spindle's direction and the
pass's helix z = c + s * lead * turns (s the sign of the cut's Z), per thread (its program line, the first of a
G92 run):

- the **full-lead length**: where the local lead |dz / dturns| lies within :data:`LEAD_RATIO` of the programmed
  lead (Fanuc's permissible lead error a); before it the **incomplete lead at the start**, after it the one at
  the end (mm of Z, the finishing pass's);
- the **lead** (mm) fitted over the full-lead length of the finishing pass and its error accumulated over that
  length (um);
- the **phase spread** (um): each pass's helix constant c (median over its full-lead length) less the Z shift
  its plan intends (G76's flank infeed: the pass's planned start Z less the first's), modulo the lead, the
  largest difference between passes; above the tolerance the thread is **cross-threaded**;
- the **minor diameter** (mm): twice the deepest pass's actual X over its full-lead length, less the tool offset
  (the programmed X is the plan's).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..controllers.g7x import Segment

#: The local lead within this fraction of the programmed lead is the full lead (Fanuc's a).
LEAD_RATIO = 0.02
#: A pass has come to rest when its Z moves less than this fraction of its thread speed.
REST_FRACTION = 0.01


@dataclass(frozen=True)
class PlannedPass:
    """A thread pass as the plan has it (axes' coordinates)."""

    group: int              # the thread it belongs to (index into the threads)
    line: int
    lead: float
    z_sign: float           # the cut's direction in Z
    spindle: int            # +1 M03, -1 M04
    z_start: float          # the planned start Z of the pass (its flank shift included)
    x_root: float           # the planned X at the cut's end (radius, axes)
    x_offset: float         # the tool's X offset (the axes stand at the programmed point + it)


@dataclass
class ThreadResult:
    """One thread's judgement (``threads`` in part.json)."""

    line: int
    lead_mm: float
    lead_error_um: float
    phase_spread_um: float
    minor_diameter_mm: float
    programmed_minor_diameter_mm: float
    incomplete_start_mm: float
    incomplete_end_mm: float
    passes: int
    cross_threaded: bool

    def as_json(self) -> dict[str, object]:
        def number(v: float) -> float | None:
            return None if math.isnan(v) else round(v, 6)

        return {"line": self.line, "lead_mm": number(self.lead_mm), "lead_error_um": number(self.lead_error_um),
                "phase_spread_um": number(self.phase_spread_um),
                "minor_diameter_mm": number(self.minor_diameter_mm),
                "incomplete_start_mm": number(self.incomplete_start_mm),
                "incomplete_end_mm": number(self.incomplete_end_mm)}

    def summary(self) -> str:
        state = "CROSS-THREADED" if self.cross_threaded else "in one groove"
        passes = f"{self.passes} pass" + ("es" if self.passes != 1 else "")
        return (f"  thread (line {self.line}): lead {self.lead_mm:.5f} mm (error {self.lead_error_um:+.2f} um over the "
                f"full lead), {passes} {state} (phase spread {self.phase_spread_um:.2f} um), minor "
                f"diameter {self.minor_diameter_mm:.4f} mm (programmed {self.programmed_minor_diameter_mm:.4f}), "
                f"incomplete lead {self.incomplete_start_mm:.3f} mm at the start, {self.incomplete_end_mm:.3f} mm at "
                "the end")


def planned_passes(segments: list[Any]) -> list[PlannedPass]:
    """The thread passes of a plan (:class:`ncfmu.controllers.g7x.Segment` s), grouped into threads: a G76 by
    its line, a G92 run from its first pass (pass 1), G32 passes with the same lead and start Z in a row."""
    out: list[PlannedPass] = []
    group = -1
    key: tuple[object, ...] = ()
    for g in segments:
        if not g.lead or g.continues:
            continue
        z0, z1 = g.element.start[0], g.element.end[0]
        new_key: tuple[object, ...] = ((76, g.line) if g.cycle == 76 else (92, g.lead) if g.cycle == 92 else
                                       (32, g.lead, round(z0, 6)))
        if new_key != key or (g.cycle == 92 and g.pass_no == 1):
            group += 1
            key = new_key
        out.append(PlannedPass(group, g.line, g.lead, 1.0 if z1 > z0 else -1.0, g.modal.spindle or 1, z0,
                               g.element.end[1], g.modal.offset[1]))
    return out


@dataclass
class _Pass:
    plan: PlannedPass
    turns: list[float] = field(default_factory=list)
    z: list[float] = field(default_factory=list)
    x: list[float] = field(default_factory=list)


class ThreadJudge:
    """Streams a run's rows; :meth:`results` judges each thread from the passes seen."""

    def __init__(self, passes: list[PlannedPass], threading: str, revolutions: str, x: str, z: str,
                 tolerance_mm: float) -> None:
        self.plan = passes
        self.columns = (threading, revolutions, x, z)
        self.tolerance = tolerance_mm
        self.seen: list[_Pass] = []
        self._active: _Pass | None = None
        self._was_threading = False
        self._tail = False

    def write(self, rows: np.ndarray) -> None:
        threading, revolutions, x, z = (rows[c] for c in self.columns)
        for i in range(len(threading)):
            on = bool(threading[i])
            if on and not self._was_threading and len(self.seen) < len(self.plan):
                self._active = _Pass(self.plan[len(self.seen)])
                self.seen.append(self._active)
                self._tail = False
            self._was_threading = on
            p = self._active
            if p is None:
                continue
            turns = float(revolutions[i]) * p.plan.spindle
            if not on:
                # after the command's end: until Z comes to rest (the incomplete lead at the end)
                if p.z and abs(float(z[i]) - p.z[-1]) <= REST_FRACTION * p.plan.lead * abs(turns - p.turns[-1]):
                    self._active = None
                    continue
            p.turns.append(turns)
            p.z.append(float(z[i]))
            p.x.append(float(x[i]))

    def results(self) -> list[ThreadResult]:
        out = []
        for group in sorted({p.plan.group for p in self.seen}):
            passes = [p for p in self.seen if p.plan.group == group and len(p.z) > 3]
            if passes:
                out.append(self._judge(passes))
        return out

    @staticmethod
    def _full(p: _Pass) -> tuple[np.ndarray, np.ndarray, np.ndarray, slice]:
        turns, z, x = np.array(p.turns), np.array(p.z), np.array(p.x)
        dt = np.diff(turns)
        ratio = np.abs(np.diff(z)) / (p.plan.lead * np.where(dt > 0, dt, np.inf))
        full = np.nonzero(np.abs(ratio - 1.0) <= LEAD_RATIO)[0]
        if len(full) < 2:
            return turns, z, x, slice(0, 0)
        return turns, z, x, slice(int(full[0]), int(full[-1]) + 2)

    def _judge(self, passes: list[_Pass]) -> ThreadResult:
        plan0 = passes[0].plan
        lead, s = plan0.lead, plan0.z_sign
        constants = []
        for p in passes:
            turns, z, _x, full = self._full(p)
            if full.stop - full.start < 2:
                constants.append(math.nan)
                continue
            c = float(np.median(z[full] - s * lead * turns[full])) - (p.plan.z_start - plan0.z_start)
            constants.append(c)
        c0 = constants[0]
        offsets = [(c - c0 + lead / 2) % lead - lead / 2 for c in constants if not math.isnan(c)]
        spread = (max(offsets) - min(offsets)) * 1000.0 if offsets else math.nan
        last = passes[-1]
        turns, z, x, full = self._full(last)
        if full.stop - full.start >= 2:
            slope = float(np.polyfit(turns[full], z[full], 1)[0])
            measured = abs(slope)
            span = float(turns[full][-1] - turns[full][0])
            lead_error = (measured - lead) * span * 1000.0
            start = abs(float(z[full.start] - z[0]))
            end = abs(float(z[-1] - z[full.stop - 1]))
            minor = 2.0 * (float(np.median(x[full])) - last.plan.x_offset)
        else:
            measured = lead_error = start = end = minor = math.nan
        deepest = min(p.plan.x_root for p in passes)
        return ThreadResult(plan0.line, measured, lead_error, spread, minor, 2.0 * (deepest - last.plan.x_offset),
                            start, end, len(passes), bool(spread > self.tolerance * 1000.0))


def thread_judge(plan: Sequence[Segment], seq: str, x: str, z: str, spindle: str,
                 tolerance_mm: float) -> ThreadJudge | None:
    """The judge of the threads in a configured sequencer's ``plan`` (its planned moves: the program as the
    sequencer reads it); None: no program, or one without threads."""
    passes = planned_passes(list(plan))
    if not passes:
        return None
    return ThreadJudge(passes, f"{seq}.threading", f"{spindle}.revolutions", f"{x}.pos", f"{z}.pos", tolerance_mm)
