"""How a run of a system came out -- done, crashed, out of tolerance, not finished -- and when it should end.

One home for what ``ncfmu run``'s exit status and a sweep variant's status say, from the run's summary as it went
(a :class:`~ncfmu.systems.report.ReportAccumulator`, the part check's verdict in it):

- :func:`halted`: asked as the run goes (``Master.run``'s ``until``: when the rows reach the sinks, and within
  ``CHECK_INTERVAL`` of simulated time after a :func:`watched` output -- a done signal, an alarm -- changed):
  the run ends when the part check saw a crash, when an alarm halted the machine, or when every cycle of the
  system is done (its report's done signals, :meth:`~ncfmu.systems.report.Report.done_signals`) -- unless the
  system repeats its cycle (a soak), or has no done signal (a bare FMU): then it runs to its stop time.
- :func:`outcome`: at the end, the status and exit status (:mod:`ncfmu.exitcodes`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..exitcodes import EXIT_NOT_FINISHED, EXIT_OK, EXIT_PART_REJECTED
from .part import crashes_so_far, verdict_of
from .report import ReportAccumulator

#: The limit of a run that ends where its work ends, s of simulated time (``--stop-time``'s default for a system
#: with a done signal): longer than any program a test or a sweep runs; the run stops where the work does.
RUN_LIMIT = 3600.0

#: A run's status (and a sweep variant's), and the exit status it gives; a sweep's variant may also have
#: ``failed`` (refused, or an FMU failed) or ``timeout`` (over its wall time)
OK, CRASHED, OUT_OF_TOLERANCE, UNFINISHED = "ok", "crashed", "out_of_tolerance", "unfinished"
FAILED, TIMEOUT = "failed", "timeout"
EXIT_OF = {OK: EXIT_OK, CRASHED: EXIT_PART_REJECTED, OUT_OF_TOLERANCE: EXIT_PART_REJECTED,
           UNFINISHED: EXIT_NOT_FINISHED, FAILED: EXIT_NOT_FINISHED, TIMEOUT: EXIT_NOT_FINISHED}
#: The statuses of a run that ran to its end (its work done, a crash, an alarm or the stop time)
RAN = (OK, CRASHED, OUT_OF_TOLERANCE, UNFINISHED)
STATUSES = (*RAN, FAILED, TIMEOUT)


def ends_when_done(accumulator: ReportAccumulator) -> bool:
    """The run the accumulator summarises ends where its work ends (a done signal, no repeat)."""
    return accumulator.report.ends_when_done(accumulator.parameters)


def default_stop_time(system_stop_time: float, to_done: bool) -> float:
    """The stop time of a run given none: for a run that ends where its work ends, the limit RUN_LIMIT (or the
    system's own stop time when longer); for one without a done signal, the system's stop time."""
    return max(RUN_LIMIT, system_stop_time) if to_done else system_stop_time


def watched(accumulator: ReportAccumulator) -> list[str]:
    """The outputs whose change makes a run look at :func:`halted` at once (``Master.run``'s ``watch``): the done
    signals of a run that :func:`ends_when_done`, and every alarm. (A crash is seen as the rows reach the part
    check: whenever the record window is full -- every few seconds of simulated time --, or at one of these.)"""
    report = accumulator.report
    done = list(report.done_signals()) if ends_when_done(accumulator) else []
    return list(dict.fromkeys([*done, *(p.alarm for p in report.parts if p.alarm is not None)]))


def halted(accumulator: ReportAccumulator, at_done: bool = True) -> str:
    """Why the run should end now, from the rows fed so far ("": go on): a crash, an alarm, or -- for a system that
    :func:`ends_when_done`, unless ``at_done`` is false (a replay follows its input's timeline) -- the work done."""
    crashes = crashes_so_far(accumulator)
    if crashes:
        return f"crash at t = {crashes[0].t:.3f} s"
    alarmed = _alarmed(accumulator)
    if alarmed:
        return f"alarm ({alarmed})"
    if at_done and ends_when_done(accumulator) and accumulator.finished():
        return f"done (seen at t = {accumulator.last_time:.3f} s)"
    return ""


def _alarmed(accumulator: ReportAccumulator) -> str:
    """The first part's alarm output that was raised in the rows so far ("": none)."""
    return next((acc.part.alarm or "" for acc in accumulator.parts if acc.alarmed), "")


@dataclass(frozen=True)
class Outcome:
    """A run's status (``ok``, ``crashed``, ``out_of_tolerance``, ``unfinished``), why (empty when ok) and its exit
    status."""

    status: str
    why: str

    @property
    def exit_status(self) -> int:
        return EXIT_OF[self.status]


def outcome(accumulator: ReportAccumulator) -> Outcome:
    """How the run summarised by ``accumulator`` came out."""
    verdict = verdict_of(accumulator)
    end = accumulator.last_time
    if verdict is not None and verdict.crashed:
        crash = verdict.crashes[0] if verdict.crashes else None
        return Outcome(CRASHED, f"crash at t = {crash.t:.3f} s, line {crash.line}: {crash.what}" if crash
                       else f"{verdict.crash_count} crashes")
    alarmed = _alarmed(accumulator)
    if alarmed:
        return Outcome(UNFINISHED, f"alarm ({alarmed}) by t = {end:g} s")
    if not accumulator.finished():
        return Outcome(UNFINISHED, f"cycle not finished by t = {end:g} s")
    if verdict is None:
        return Outcome(OK, "")
    within = verdict.within_tolerance
    if within is None:
        return Outcome(UNFINISHED, f"part not judged: {verdict.judged}")
    if not within:
        worst = max(verdict.max_left_mm, verdict.max_gouge_mm)
        return Outcome(OUT_OF_TOLERANCE, f"part out of tolerance {verdict.tolerance_mm:g} mm: "
                       f"{'left' if verdict.max_left_mm >= verdict.max_gouge_mm else 'gouge'} "
                       f"{worst if math.isfinite(worst) else math.nan:.4f} mm")
    return Outcome(OK, "")
