"""The simulation thread's pacing, overruns and failure, on a small in-process session (no FMUs, no server)."""

from __future__ import annotations

import logging
import math
import threading
import time

import pytest

from ncfmu.errors import ConfigError, SimulationError, TerminationRequested
from ncfmu.serving import PaceStats, Point, Runner
from ncfmu.serving.runner import _Command

POINTS = [Point("a.y", "a", "y", "Real", "output", "continuous", None, "", None, None),
          Point("a.u", "a", "u", "Real", "input", "continuous", None, "", None, None)]


class Session:
    """What the runner uses of ``Master.open_session``: steps cost ``cost`` s of wall each; y integrates u."""

    def __init__(self, cost: float = 0.0, fail_at: float = math.inf, h: float = 0.001,
                 end_at: float = math.inf) -> None:
        self.time, self.step_size, self.stop_time = 0.0, h, math.inf
        self.cost, self.fail_at, self.end_at = cost, fail_at, end_at
        self.failed: BaseException | None = None
        self.y, self.u, self.forced_u = 0.0, 1.0, None
        self.writes: list = []

    def advance(self, n: int) -> None:
        for _ in range(n):
            if self.time >= self.fail_at:
                raise SimulationError(f"a: fmi2DoStep at t = {self.time:.6f} s returned fmi2Error")
            if self.time >= self.end_at:        # as the master's session: it says it failed, the runner decides
                self.failed = TerminationRequested("a", self.time)
                raise self.failed
            if self.cost:
                end = time.perf_counter() + self.cost
                while time.perf_counter() < end:
                    pass
            u = self.u if self.forced_u is None else self.forced_u
            self.y += u * self.step_size
            self.time = round(self.time + self.step_size, 9)

    def outputs(self):
        return {"a.y": self.y}

    def value(self, name):
        return self.y if name == "a.y" else (self.u if self.forced_u is None else self.forced_u)

    def forced(self):
        return {} if self.forced_u is None else {"a.u": self.forced_u}

    def force(self, name, value):
        if value < 0:
            raise ConfigError(name, value, "must be >= 0")
        self.forced_u = value
        self.writes.append((self.time, name, value))

    def release(self, name):
        self.forced_u = None
        self.writes.append((self.time, name, None))

    def set_parameter(self, name, value):
        raise ConfigError(name, value, "not writable")

    def reset(self, sinks=()):
        self.time, self.y, self.forced_u, self.writes = 0.0, 0.0, None, []


def run_for(runner: Runner, seconds: float) -> None:
    runner.start()
    time.sleep(seconds)
    runner.stop("test over")
    runner.thread.join(5)
    assert not runner.thread.is_alive()


def test_real_time_pacing_follows_the_wall_clock():
    session = Session()
    runner = Runner(session, POINTS, speed=1.0)
    wall = time.perf_counter()
    run_for(runner, 0.5)
    wall = time.perf_counter() - wall
    assert session.time <= wall + session.step_size                # never ahead of the clock ...
    assert session.time >= wall - 0.1                             # ... and keeping up (the steps cost nothing)
    p50, p99, pmax = runner.stats.percentiles()
    assert 0 < p50 <= p99 <= pmax and runner.stats.count > 100    # each chunk ends after its due time


def test_twice_real_time():
    session = Session()
    runner = Runner(session, POINTS, speed=2.0)
    wall = time.perf_counter()
    run_for(runner, 0.5)
    wall = time.perf_counter() - wall
    assert 2 * wall - 0.2 <= session.time <= 2 * wall + session.step_size


def test_a_loop_that_cannot_keep_the_pace_counts_overruns_and_says_so_once(caplog):
    session = Session(cost=0.002)         # 2 ms of work per 1 ms step: it falls behind at once
    runner = Runner(session, POINTS, speed=1.0)
    with caplog.at_level(logging.WARNING, logger="ncfmu.serve"):
        run_for(runner, 0.6)
    # it fell behind once and never caught up (0.6 s of steps cost 1.2 s): one overrun, the lag growing
    assert runner.stats.overruns == 1 and runner.stats.max > 0.1 and runner.stats.count > 3
    said = [r for r in caplog.records if "cannot keep the pace" in r.getMessage()]
    assert len(said) == 1 and "--speed 1" in said[0].getMessage()
    assert session.time < 0.45                                    # it did fall behind: nothing was skipped


def test_writes_apply_between_chunks_and_refusals_come_back():
    session = Session()
    runner = Runner(session, POINTS, speed=0.0)
    answers: list = []
    done = threading.Event()

    def answer(refusal):
        answers.append(refusal)
        if len(answers) == 3:
            done.set()
    runner.start()
    for value in (0.5, -1.0):
        runner.submit(_Command("force", "a.u", value, answer))
    runner.submit(_Command("set", "a.y", 1.0, answer))
    assert done.wait(5)
    runner.stop()
    runner.thread.join(5)
    assert answers[0] is None and "must be >= 0" in answers[1] and "not writable" in answers[2]
    assert session.forced_u == 0.5 and [w[2] for w in session.writes] == [0.5]


def test_an_fmu_error_fails_the_simulation_with_its_reason():
    session = Session(fail_at=0.05)
    seen = threading.Event()
    runner = Runner(session, POINTS, speed=0.0, on_state=seen.set)
    runner.start()
    assert seen.wait(5)
    runner.thread.join(5)
    assert runner.state == "failed" and "fmi2DoStep at t = 0.050000 s returned fmi2Error" in runner.reason
    snap = runner.snapshot()
    assert snap is not None and snap.state == "failed" and snap.time == pytest.approx(0.05)


def test_an_fmu_that_asks_to_end_stops_the_simulation_cleanly():
    # fmi2Discard + terminateSimulation is the end of the run, as `ncfmu run` has it: stopped (not failed), the
    # reason names the FMU, and the session may close complete (its CSV renamed, its summary written)
    session = Session(end_at=0.05)
    seen = threading.Event()
    runner = Runner(session, POINTS, speed=0.0, on_state=seen.set)
    runner.start()
    assert seen.wait(5)
    runner.thread.join(5)
    assert runner.state == "stopped" and runner.reason.startswith("a asked to end the simulation at t = 0.05 s")
    assert session.failed is None
    snap = runner.snapshot()
    assert snap is not None and snap.state == "stopped" and snap.time == pytest.approx(0.05)


def test_speed_must_be_a_number_not_below_zero():
    for bad in (-1.0, math.nan, math.inf):
        with pytest.raises(ConfigError, match="--speed"):
            Runner(Session(), POINTS, speed=bad)


def test_lag_percentiles_from_the_histogram():
    stats = PaceStats()
    for k in range(1, 1001):            # 0.1 ms .. 100 ms
        stats.add(k * 1e-4)
    p50, p99, pmax = stats.percentiles()
    assert p50 == pytest.approx(0.050, abs=2e-5) and p99 == pytest.approx(0.099, abs=2e-5) and pmax == 0.1
    stats.add(5.0)                      # beyond the last bin: counted there, the max exact
    assert stats.max == 5.0 and stats.percentile(100) == 5.0


def test_each_time_it_falls_behind_is_one_overrun():
    class Stalling(Session):
        stalls = [0.1, 0.3]                     # two stalls of 50 ms, caught up in between

        def advance(self, n):
            if self.stalls and self.time <= self.stalls[0] < self.time + n * self.step_size:
                self.stalls.pop(0)
                time.sleep(0.05)
            super().advance(n)
    session = Stalling()
    runner = Runner(session, POINTS, speed=1.0)
    run_for(runner, 0.6)
    late_chunks = int(runner.stats.counts[1001:].sum())            # chunks ending more than 10 ms late
    # each stall leaves several chunks late while it catches up; an overrun is the stall, not each chunk
    # (a loaded machine may add stalls of its own)
    assert 2 <= runner.stats.overruns < late_chunks and runner.stats.max >= 0.04


def _answered(runner: Runner, command: _Command) -> str | None:
    """Submit ``command`` and wait for the simulation thread's answer (None: applied)."""
    answers: list = []
    done = threading.Event()
    command.done = lambda refusal: (answers.append(refusal), done.set())
    runner.submit(command)
    assert done.wait(5)
    return answers[0]


def test_a_hold_without_a_feed_hold_input_halts_until_resume_releases_what_it_kept():
    # --on-lost hold on a system without a feed-hold input: a stop. The lost client's force stays, nothing
    # releases or re-forces it but Resume (the simulation's time stands meanwhile); Resume releases it, time runs
    session = Session()
    runner = Runner(session, POINTS, speed=0.0)
    assert runner.feed_holds == []
    runner.start()
    try:
        assert _answered(runner, _Command("force", "a.u", 0.5)) is None
        assert _answered(runner, _Command("hold", value=("client lost: session s silent for 1 s", ("a.u",)))) is None
        assert (runner.state, runner.reason) == ("held", "client lost: session s silent for 1 s")
        halted = session.time
        for refused in (_Command("release", "a.u"), _Command("force", "a.u", 2.0), _Command("pause")):
            assert _answered(runner, refused) == "the simulation is held: client lost: session s silent for 1 s"
        time.sleep(0.05)
        assert session.time == halted and session.forced_u == 0.5
        assert _answered(runner, _Command("resume")) is None
        assert (runner.state, runner.reason, session.forced_u) == ("running", "", None)
        deadline = time.monotonic() + 5
        while session.time <= halted:
            assert time.monotonic() < deadline, "the simulation did not run on after Resume"
            time.sleep(0.005)
    finally:
        runner.stop()
        runner.thread.join(5)
    assert [w[2] for w in session.writes] == [0.5, None]          # the force, Resume's release: nothing else
