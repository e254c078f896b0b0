"""The served part check runs in a thread of its own (``ncfmu-part-check``), at most one hand-over of rows behind
the simulation thread, so that its work (shapely, ~1-17 ms a hand-over for the lathes) does not hold up the paced
clock; at --speed 0 every check is waited for (the run is deterministic). A crash's time, line and depth come
from the rows, not from when they were judged: at the halt, the records are the synchronous check's of every row
up to the halt. In process: a session that records rows and a part check that costs wall time."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
from test_serve_runner import POINTS, Session

from ncfmu.machining.removal import Crash
from ncfmu.serving import CRASH_CHECK, FAST_CHUNK, MAX_CHUNK_WALL, CrashWatch, Runner

COLUMNS = [("time", np.dtype(np.float64)), ("a.y", np.dtype(np.float64))]


class RowSession(Session):
    """The fake session with a recording: a row per step, handed to the sinks by flush() (and at a reset)."""

    def __init__(self, sinks: list, **kw) -> None:
        super().__init__(**kw)
        self.rows: list[tuple[float, float]] = []
        self.sinks = list(sinks)
        for sink in self.sinks:
            sink.open(COLUMNS)

    def advance(self, n: int) -> None:
        for _ in range(n):
            super().advance(1)
            self.rows.append((self.time, self.y))

    def flush(self) -> None:
        rows = np.array(self.rows, dtype=COLUMNS)
        self.rows.clear()
        for sink in self.sinks:
            sink.write(rows)
        rows[:] = (-1.0, -1.0)             # the session's window is reused: a sink must have copied what it keeps

    def reset(self, sinks=()) -> None:
        self.flush()
        for sink in self.sinks:
            sink.close(True, self.time, "reset")
        super().reset()
        self.sinks = list(sinks)
        for sink in self.sinks:
            sink.open(COLUMNS)


class Check:
    """A part check's accumulator: each write costs ``cost`` s of wall; from ``crash_at`` on the tool is in the
    stock, one crash whose depth grows with the rows judged (as the removal engine's does)."""

    def __init__(self, cost: float, crash_at: float) -> None:
        self.cost, self.crash_at = cost, crash_at
        self.crashes: list[Crash] = []
        self.threads: set[str] = set()
        self.times: list[float] = []

    def open(self, columns) -> None:
        assert [c for c, _ in columns] == ["time", "a.y"]

    def write(self, rows) -> None:
        self.threads.add(threading.current_thread().name)
        if self.cost:
            time.sleep(self.cost)
        for t in rows["time"]:
            assert t >= 0, "a row the session had reused"
            self.times.append(float(t))
            if t >= self.crash_at - 1e-12:
                depth = round(float(t) - self.crash_at, 9)
                if not self.crashes:
                    self.crashes.append(Crash(float(t), 4, "rapid into the stock", depth, (0.0, 0.0)))
                elif depth > self.crashes[0].depth_mm:
                    self.crashes[0] = Crash(self.crashes[0].t, 4, "rapid into the stock", depth, (0.0, 0.0))

    def close(self, complete, stopped_at=None, reason="") -> None:
        pass


class Report:
    parts: tuple = ()           # no part of ncfmu's: no program end to give a verdict at

    def __init__(self, cost: float = 0.0, crash_at: float = float("inf")) -> None:
        self.cost, self.crash_at = cost, crash_at
        self.made: list[Check] = []

    def accumulator(self, parameters) -> Check:
        self.made.append(Check(self.cost, self.crash_at))
        return self.made[-1]


@pytest.fixture(autouse=True)
def crashes_of_the_check(monkeypatch):
    import ncfmu.systems.part as part
    monkeypatch.setattr(part, "crashes_so_far", lambda acc: list(acc.crashes))


def served(report: Report, speed: float, seconds: float | None = None,
           until=None) -> tuple[Runner, RowSession, str]:
    """The runner after ``seconds`` or once ``until(runner)``, its session and its state then (before Stop)."""
    watch = CrashWatch(report, None)
    session = RowSession(watch.sinks([]))
    runner = Runner(session, POINTS, speed=speed, watch=watch)
    runner.start()
    end = time.perf_counter() + (seconds if seconds is not None else 30.0)
    while time.perf_counter() < end and not (until is not None and until(runner)):
        time.sleep(0.005)
    state = runner.state
    runner.stop("test over")
    runner.thread.join(5)
    assert not runner.thread.is_alive()
    watch.close()
    return runner, session, state


def test_a_slow_part_check_runs_beside_the_paced_clock():
    # 30 ms of checking per 50 ms hand-over: in the simulation thread, every hand-over would end 30 ms late
    report = Report(cost=0.030)
    runner, session, _ = served(report, speed=1.0, seconds=1.0)
    check = report.made[-1]
    assert check.threads == {"ncfmu-part-check"}
    assert session.time > 0.8 and len(check.times) > 0.7 / session.step_size       # it judged the rows ...
    assert runner.stats.overruns == 0 and runner.stats.max < 0.010                  # ... and the pace held


def test_at_speed_0_every_check_is_waited_for_and_the_halt_is_the_synchronous_one():
    halts = []
    for _ in range(2):
        report = Report(crash_at=0.1234)
        runner, session, state = served(report, speed=0.0, until=lambda r: r.state == "crashed")
        assert state == "crashed"
        halts.append((session.time, runner.crashes))
        # halted at the first hand-over after the crash: every row up to it judged, the depth theirs
        assert 0.1234 < session.time <= 0.1234 + CRASH_CHECK + FAST_CHUNK * session.step_size
        assert report.made[-1].times[-1] == session.time
        assert runner.crashes[0].depth_mm == pytest.approx(session.time - 0.1234, abs=1e-9)
    assert halts[0] == halts[1]                                   # deterministic


@pytest.mark.parametrize("speed", [1.0, 4.0])
def test_above_speed_0_the_halt_comes_at_most_a_hand_over_later_with_the_same_crash(speed):
    report = Report(cost=0.030, crash_at=0.3001)
    runner, session, state = served(report, speed=speed, until=lambda r: r.state == "crashed")
    assert state == "crashed"
    (crash,) = runner.crashes
    assert crash.t == pytest.approx(0.3001, abs=session.step_size) and crash.line == 4
    # the check is a hand-over behind: it judges the rows up to one hand-over while the next is simulated
    chunk = MAX_CHUNK_WALL * speed
    assert crash.t < session.time <= crash.t + 2 * (CRASH_CHECK + chunk)
    # the records at the halt are the synchronous check's of every row up to the halt
    oracle = Check(0.0, 0.3001)
    oracle.write(np.array([(t, 0.0) for t in report.made[-1].times], dtype=COLUMNS))
    assert report.made[-1].times[-1] == session.time
    assert runner.crashes == tuple(oracle.crashes)
    assert crash.depth_mm == pytest.approx(session.time - 0.3001, abs=1e-9)


def test_a_part_check_that_fails_fails_the_simulation():
    class Broken(Report):
        def accumulator(self, parameters):
            check = super().accumulator(parameters)

            def write(rows):
                raise ValueError("the part check broke")
            check.write = write                   # type: ignore[method-assign]
            return check
    runner, _, state = served(Broken(), speed=1.0, until=lambda r: r.state == "failed")
    assert state == "failed" and "the part check broke" in runner.reason


def test_a_verdict_at_each_program_end_across_hand_overs(monkeypatch):
    """A grinder's program ends when its RUN falls, a lathe's when its done rises -- also at a hand-over's
    first row (the edge from the row before); each end gives one verdict, the summary line as judged then."""
    import ncfmu.systems.part as part
    from ncfmu.systems.part import GrindPart, LathePart

    class Judged:
        def summary(self):
            return [f"  part: {len(seen)} rows judged"]

    seen: list[float] = []

    class Acc:
        crashes: list = []

        def open(self, columns): pass

        def write(self, rows):
            seen.extend(rows["time"])

        def close(self, *args): pass

    class Both:
        parts = (GrindPart(feed="feed", x="x_axis"), LathePart(seq="seq", x="x_axis", z="z_axis", limiter="lim"))

        def accumulator(self, parameters):
            return Acc()
    monkeypatch.setattr(part, "verdict_of", lambda acc: Judged())
    dtype = [("time", np.float64), ("feed.run", np.float64), ("seq.done", np.float64)]
    watch = CrashWatch(Both(), None)
    watch.wait_every_time = True
    acc = watch.accumulator

    def hand_over(*rows):
        watch.hand_over(acc, np.array(list(rows), dtype=dtype))
    try:
        hand_over((0.0, 0, 0), (0.1, 1, 0), (0.2, 1, 0))
        hand_over((0.3, 0, 0), (0.4, 0, 0))          # RUN falls at a hand-over's first row: a grinder's end
        hand_over((0.5, 1, 0), (0.6, 1, 1), (0.7, 0, 1))      # done rises at 0.6, RUN falls at 0.7: one verdict
        hand_over((0.8, 0, 1))                       # nothing ends: done stays, RUN stays down
        assert watch.verdicts() == [(0.3, "part: 5 rows judged"), (0.7, "part: 8 rows judged")]
        watch.new_accumulator()                      # a Reset: a new run, no verdict yet
        assert watch.verdicts() == []
    finally:
        watch.close()
