"""The part check's thread judgement (systems/threads.py) on synthetic runs (no FMU): one groove or
cross-threaded, the flank shift of G76 taken out, the lead error, the incomplete lead, part.json and the summary."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ncfmu.controllers import lathe_program
from ncfmu.systems.part import PartVerdict
from ncfmu.systems.threads import ThreadJudge, planned_passes

G92 = """G97 S600 M03
G00 X30. Z4.
G92 X28.4 Z-20. F1.5
X27.8
X27.6
G00 X40.
M30"""
G76 = """G97 S500 M03
G00 X32. Z5.
G76 P020060 Q100 R0.05
G76 X27.546 Z-30. P1227 Q400 F2.0
M30"""
DT, RPM = 1e-3, 600.0


def _rows(passes, lead, ramp=0.2, offsets=None, lead_scale=1.0):
    """A run's rows: per planned pass, the axes follow the spindle from the marker with a lead ramp over ``ramp``
    mm (linear in speed), shifted by ``offsets[k]`` mm; rest in between."""
    names = ("seq.threading", "spindle.revolutions", "x_axis.pos", "z_axis.pos")
    rows: list[tuple[float, float, float, float]] = []
    turns = 0.0
    step = RPM / 60.0 * DT
    for k, p in enumerate(passes):
        shift = offsets[k] if offsets else 0.0
        for _ in range(200):                                  # in between: rest, the spindle turning
            turns += step
            rows.append((0.0, turns, p.x_root + 1.0, p.z_start))
        n0 = math.ceil(turns)
        length = abs(p.z_start - (-20.0 if lead == 1.5 else -30.0))
        ramp_turns = 2 * ramp / lead
        turns = float(n0)
        travel = 0.0
        while travel < length:
            u = turns - n0
            # constant acceleration to the lead over ramp_turns, then the lead; the helix shifted by the ramp
            travel = (lead * u * u / (2 * ramp_turns) if u < ramp_turns else lead * (u - ramp_turns / 2)) * lead_scale
            rows.append((1.0, turns, p.x_root, p.z_start + p.z_sign * (travel - ramp) + shift))
            turns += step
        for _ in range(20):                                   # at rest at the end
            turns += step
            rows.append((0.0, turns, p.x_root, rows[-1][3]))
    table = np.array(rows, dtype=[(n, float) for n in names])
    return table


def _judge(text: str, **kw):
    passes = planned_passes(lathe_program.plan(text, (20.0, 10.0), 50.0))
    judge = ThreadJudge(passes, "seq.threading", "spindle.revolutions", "x_axis.pos", "z_axis.pos", 0.01)
    rows = _rows(passes, passes[0].lead, **kw)
    for chunk in np.array_split(rows, 7):                    # as the run streams
        judge.write(chunk)
    return passes, judge.results()


def test_g92_run_is_one_thread_in_one_groove():
    passes, (thread,) = _judge(G92)
    assert len(passes) == 3 and thread.line == 3 and thread.passes == 3
    assert thread.phase_spread_um < 0.01 and not thread.cross_threaded
    assert thread.lead_mm == pytest.approx(1.5, rel=1e-6) and abs(thread.lead_error_um) < 0.01
    assert thread.minor_diameter_mm == pytest.approx(27.6)
    assert thread.programmed_minor_diameter_mm == pytest.approx(27.6)
    # the ramp: the local lead reaches 98 % of the lead after 0.98^2 of its 0.2 mm
    assert thread.incomplete_start_mm == pytest.approx(0.98 ** 2 * 0.2, rel=0.03)


def test_a_pass_out_of_the_groove_is_cross_threaded_and_the_part_out_of_tolerance():
    _, (thread,) = _judge(G92, offsets=[0.0, 0.03, 0.0])
    assert thread.phase_spread_um == pytest.approx(30.0, abs=0.05) and thread.cross_threaded
    verdict = PartVerdict([], 0, 0.01, "the program has no G71/G70 profile to judge against", threads=[thread])
    assert verdict.within_tolerance is False
    (entry,) = verdict.as_json()["threads"]
    assert set(entry) == {"line", "lead_mm", "lead_error_um", "phase_spread_um", "minor_diameter_mm",
                          "incomplete_start_mm", "incomplete_end_mm"}
    assert entry["line"] == 3 and entry["phase_spread_um"] == pytest.approx(30.0, abs=0.05)
    assert "thread (line 3)" in verdict.summary()[-1] and "CROSS-THREADED" in verdict.summary()[-1]


def test_a_whole_lead_apart_is_the_same_groove():
    _, (thread,) = _judge(G92, offsets=[0.0, 1.5, -3.0])
    assert thread.phase_spread_um < 0.01


def test_g76_flank_infeed_is_taken_out_and_a_lead_error_is_measured():
    passes, (thread,) = _judge(G76)
    assert len({round(p.z_start, 6) for p in passes}) > 5                # the passes stand apart in Z (flank)
    assert thread.phase_spread_um < 0.01 and thread.passes == 10 and thread.line == 4
    assert thread.minor_diameter_mm == pytest.approx(27.546)
    _, (long,) = _judge(G76, lead_scale=1.0005)
    assert long.lead_mm == pytest.approx(2.001, rel=1e-6)
    turns = (5.0 + 30.0) / 2.0                                           # the finishing pass: Z 5 to -30
    assert long.lead_error_um == pytest.approx(1.0 * turns, rel=0.02)    # 1 um a turn over the full lead
