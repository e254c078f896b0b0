"""A report's summary and metrics computed on the fly, chunk by chunk, equal those of the whole trajectory.

The oracle below is the whole-trajectory computation written straight over the arrays of a finished run (as the
report computed it before it streamed). Every quantity is a first or last value, an extreme, a count or a
point-by-point distance, so chunking changes no floating-point operation: the comparison is exact (``==``,
NaN equal to NaN), not within a tolerance.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ncfmu.checks import path_distance
from ncfmu.cosim.result import Result
from ncfmu.systems import report_of as _report_of
from ncfmu.systems import run_parameters
from ncfmu.systems.part import without_part_check
from ncfmu.systems.report import Axes, ContourCycle, Envelope, FeedCycle, LatheCycle, columns_of

# (system, stop time, start values): the three default runs, and runs that raise alarms / end in an emergency
RUNS = {
    "lathe_roughing": ("lathe_roughing", None, {}),
    "grinder_feed": ("grinder_feed", None, {}),
    "mill_contour": ("mill_contour", None, {}),
    "grinder_envelope": ("grinder_envelope", None, {}),
    "lathe_alarm": ("lathe_roughing", 14.0, {"seq.block[1].Zp": 50.0}),       # the tool runs into the chuck zone
    "grinder_emergency": ("grinder_feed", 13.5, {"panel.emergency_at": 12.0}),  # emergency return mid-cycle
    # a soak: wear compensation at 0.1 s and parts at 5 and 45 s of every 80 s (README), cut off mid-part
    "grinder_soak": ("grinder_feed", 170.0, {"panel.repeat_every": 80.0, "panel.wear_start_at": 0.1,
                                             "panel.start_at": 5.0, "panel.restart_at": 45.0}),
}


@pytest.fixture(scope="module")
def runs(ncfmu_run):
    cache = {}

    def get(name):
        if name not in cache:
            system, stop, values = RUNS[name]
            cache[name] = ncfmu_run(system, stop_time=stop, start_values=values or None)
        return cache[name]
    return get


def report_of(result):
    """The run's report without its part check: the part check's geometry is judged to its stated resolution,
    not bit for bit across chunkings (tests/systems/test_part_check.py streams it)."""
    return without_part_check(_report_of(result))


# -- the oracle: whole trajectories ----------------------------------------------------------------
def _first(t, flag):
    return float(t[np.argmax(flag)]) if flag.any() else float("nan")


def _finished(t, s):
    return "not finished" if math.isnan(s) else f"{s:.3f} s"


def oracle(report, data, parameters) -> tuple[list[str], dict[str, float]]:
    t = data["time"]
    lines: list[str] = []
    metrics: dict[str, float] = {"sim_time": float(t[-1])}
    alarms, finished = 0, True
    for p in report.parts:
        alarmed = p.alarm is not None and bool(data[p.alarm].any())
        alarms += alarmed
        yes = "yes" if alarmed else "no"
        if isinstance(p, Axes):
            lines += [f"  {a}: max |following error| {abs(data[f'{a}.following_error']).max() * 1000:.2f} um"
                      for a in p.names]
            metrics["max_following_error_mm"] = float(max(abs(data[f"{a}.following_error"]).max() for a in p.names))
        elif isinstance(p, LatheCycle):
            sub, x, z = data[f"{p.seq}.subcycle"], data[f"{p.x}.pos"], data[f"{p.z}.pos"]
            cut = sub == 2
            starts = np.flatnonzero((sub[1:] == 2) & (sub[:-1] != 2)) + 1
            lines.append(f"  cuts (SC2): {len(starts)}")
            if cut.any():
                lines.append("  X at the start of each cut [mm]: " + ", ".join(f"{x[i]:.4f}" for i in starts))
                lines.append(f"  smallest X during the cuts: {x[cut].min():.4f} mm; Z reached {z[cut].min():.4f} mm")
            done = _first(t, data[f"{p.seq}.done"])
            lines.append(f"  cycle done: {_finished(t, done)}; tool at X {x[-1]:.4f}, Z {z[-1]:.4f} mm; alarm: {yes}")
            metrics["final_radius_mm"] = float(x[cut].min()) if cut.any() else float("nan")
            metrics["cycle_time_s"] = done
            finished &= not math.isnan(done)
        elif isinstance(p, FeedCycle):
            x = data[f"{p.x}.pos"]
            active = data[f"{p.feed}.run"] | data[f"{p.feed}.emergency_active"]
            end = (float(t[np.flatnonzero(active)[-1] + 1]) if active.any() and not active[-1] else float("nan"))
            run, emergency = data[f"{p.feed}.run"].astype(bool), data[f"{p.feed}.emergency_active"].astype(bool)
            rises = np.flatnonzero(run & ~np.concatenate(([False], run[:-1])))
            falls = np.flatnonzero(~run & np.concatenate(([False], run[:-1])))
            wear = int(parameters.get(p.feed, {}).get("wear_address", 43))
            part_rises = [i for i in rises if data[f"{p.feed}.pc"][i] != wear]
            # a part completed: its stretch of RUN ended (the next fall after its rise) without the emergency
            completed = sum(1 for i in part_rises for f in falls[falls > i][:1] if not emergency[f])
            emergencies = int(np.count_nonzero(emergency & ~np.concatenate(([False], emergency[:-1]))))
            lines += [f"  deepest X: {x.max():.4f} mm; cycle ended: {_finished(t, end)}; X at the end {x[-1]:.4f} mm; "
                      f"return counter X {data[f'{p.feed}.return_counter_x'][-1]:.4f} mm",
                      f"  cycles: {len(part_rises)} parts started (START1), {completed} completed; "
                      f"{len(rises) - len(part_rises)} wear compensations (START2); {emergencies} emergency returns",
                      f"  alarm: {yes}"]
            metrics["deepest_x_mm"] = float(x.max())
            metrics["cycle_time_s"] = end
            finished &= not math.isnan(end)
        elif isinstance(p, Envelope):
            # its line is worded in one place, over whatever rows it is given: here the whole trajectory (the
            # accumulator gives it the rows that witness each state the limiter was in)
            lines += p.summary(Result(data), parameters)
        elif isinstance(p, ContourCycle):
            done = _first(t, data[f"{p.contour}.done"])
            lines.append(f"  contour done: {_finished(t, done)}; last segment (point path) or program line: "
                         f"{int(data[f'{p.contour}.segment'][-1])}; alarm: {yes}")
            path = [move.element for move in p.interpolator(parameters).tool_path]
            on = data[f"{p.contour}.segment"] >= 1
            best = path_distance(data[f"{p.x}.pos"][on], data[f"{p.y}.pos"][on], path)
            metrics["max_contour_error_mm"] = float(best.max()) if len(best) else float("nan")
            metrics["cycle_time_s"] = done
            finished &= not math.isnan(done)
        else:
            raise AssertionError(f"no oracle for {type(p).__name__}")
    metrics["alarms"] = alarms
    metrics["finished"] = finished          # not a metric of the report: compared with the accumulator's finished()
    return lines, metrics


# -- feeding in chunks -----------------------------------------------------------------------------
def chunks(n: int, rng: np.random.Generator, largest: int) -> list[slice]:
    """Random chunk boundaries over n rows: sizes 0 (an empty write) to ``largest``, many of 1 and 2."""
    out, i = [], 0
    while i < n:
        size = int(rng.choice([0, 1, 2, rng.integers(1, largest + 1)]))
        out.append(slice(i, min(n, i + size)))
        i += size
    return out


def streamed(report, data, parameters, rng, largest=5000, wall_time=0.0):
    acc = report.accumulator(parameters)
    acc.open(columns_of(data))
    for part in chunks(len(data), rng, largest):
        acc.write(data[part])
    acc.close(True, float(data["time"][-1]))
    return acc.summary(), {**acc.metrics(wall_time=wall_time), "finished": acc.finished()}


def same(a: dict[str, float], b: dict[str, float]) -> bool:
    """Exactly equal, NaN equal to NaN."""
    return a.keys() == b.keys() and all(a[k] == b[k] or (math.isnan(a[k]) and math.isnan(b[k])) for k in a)


@pytest.mark.slow
@pytest.mark.parametrize("name", list(RUNS))
def test_streamed_summary_and_metrics_equal_the_whole_trajectorys(runs, name):
    r = runs(name)
    report, parameters = report_of(r), run_parameters(r)
    lines, metrics = oracle(report, r.data, parameters)
    metrics["wall_time"] = r.wall_time
    # the whole-trajectory API (one chunk) ...
    assert report.summary(r, parameters) == lines
    assert same({**report.metrics(r, parameters), "finished": metrics["finished"]}, metrics)
    # ... and chunks of random sizes, three seeds
    for seed in range(3):
        got_lines, got = streamed(report, r.data, parameters, np.random.default_rng(seed), wall_time=r.wall_time)
        assert got_lines == lines, f"seed {seed}"
        assert same(got, metrics), f"seed {seed}: {got} != {metrics}"


def test_the_runs_cover_what_the_lines_say(runs):
    """The comparison above is not vacuous: the runs finish and do not finish, alarm and do not."""
    _, normal = oracle(report_of(runs("grinder_feed")), runs("grinder_feed").data, {})
    _, alarm = oracle(report_of(runs("lathe_alarm")), runs("lathe_alarm").data, run_parameters(runs("lathe_alarm")))
    _, emergency = oracle(report_of(runs("grinder_emergency")), runs("grinder_emergency").data, {})
    assert normal["alarms"] == 0 and normal["cycle_time_s"] > 30 and normal["finished"]
    assert alarm["alarms"] == 2 and math.isnan(alarm["cycle_time_s"])       # limiter and sequencer
    assert not alarm["finished"]
    assert 12.0 < emergency["cycle_time_s"] < 13.5                          # the emergency return ended


@settings(max_examples=40, deadline=None)
@given(name=st.sampled_from(["lathe_alarm", "grinder_emergency", "mill_contour"]),
       cut=st.floats(0.0, 1.0), seed=st.integers(0, 2**32 - 1))
def test_an_interrupted_runs_rows_summarise_as_that_prefix(runs, name, cut, seed):
    """A run stopped anywhere (Ctrl-C, a deadline): what the accumulator says of the rows written so far is
    what the whole-trajectory computation says of that prefix -- mid-cut, mid-return, before the start."""
    r = runs(name)
    report, parameters = report_of(r), run_parameters(r)
    data = r.data[: 1 + int(cut * (len(r.data) - 1))]
    lines, metrics = oracle(report, data, parameters)
    metrics["wall_time"] = 0.0
    got_lines, got = streamed(report, data, parameters, np.random.default_rng(seed), largest=800)
    assert got_lines == lines
    assert same(got, metrics)


def test_the_accumulator_refuses_rows_without_what_it_reads():
    from ncfmu.errors import SystemDefinitionError
    from ncfmu.systems import SYSTEMS
    acc = SYSTEMS["grinder_feed"].report.accumulator({})
    with pytest.raises(SystemDefinitionError, match="feed.return_counter_x"):
        acc.open([("time", np.dtype(float)), ("x_axis.pos", np.dtype(float))])


@pytest.mark.parametrize("system", ["lathe_alarm", "grinder_envelope", "mill_contour"])
def test_any_rows_stream_as_they_summarise_whole(runs, system):
    """Arbitrary rows in the columns (and types) of a real run -- flags switching on and off in stretches,
    several active stretches, a run that starts in SC2 or ends active, alarms raised and cleared -- give the
    same lines and metrics chunked as whole (seeded: the same rows every time)."""
    real = runs(system)
    report, parameters = report_of(real), run_parameters(real)
    columns = ["time", *report.record()]
    dtypes = {n: real.data.dtype[n] for n in columns}
    rng = np.random.default_rng(1234)
    for _ in range(60):
        n = int(rng.integers(1, 400))
        data = np.zeros(n, dtype=[(c, dtypes[c]) for c in columns])
        data["time"] = np.arange(n) * 1e-3
        for c in columns[1:]:
            kind = dtypes[c].kind
            stretch = np.repeat(np.arange(n), rng.integers(1, 40, n))[:n] if rng.random() < 0.7 else np.arange(n)
            if kind == "b":
                data[c] = (rng.random(n) < rng.random())[stretch]
            elif kind == "i":
                data[c] = rng.integers(0, 5, n)[stretch]
            else:
                data[c] = rng.normal(0.0, 30.0, n)[stretch]
        lines, metrics = oracle(report, data, parameters)
        metrics["wall_time"] = 0.0
        got_lines, got = streamed(report, data, parameters, rng, largest=50)
        assert got_lines == lines
        assert same(got, metrics)


def test_the_soak_summary_counts_its_parts_and_wear_cycles(runs):
    """Before: a soak's summary said only how its last cycle ended ("not finished"), not how many ran."""
    from ncfmu.systems import report_of
    soak = runs("grinder_soak")
    lines = report_of(soak).summary(soak, run_parameters(soak))
    # parts start at 5, 45, 85, 125 and 165 s (the last one still grinding at 170 s); wear at 0.1, 80.1, 160.1 s
    assert ("  cycles: 5 parts started (START1), 4 completed; 3 wear compensations (START2); 0 emergency returns"
            in lines)
    emergency = runs("grinder_emergency")
    assert ("  cycles: 1 parts started (START1), 0 completed; 0 wear compensations (START2); 1 emergency returns"
            in report_of(emergency).summary(emergency, run_parameters(emergency)))
