"""Threads closed loop in lathe_roughing (stock 30 mm): an M30x2 cut by G76 whose Z follows the actual spindle
through its encoder (spindle.revolutions -> seq.revolutions). Judged here from the actual positions and the
spindle's angle, independently of the part check (whose threads[] is checked against the same numbers):
every pass in one groove, the lead, the bottom, and the incomplete lead at the start as the system's design
predicts it -- also with a spindle whose speed dips between passes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ncfmu.controllers.limiter import AreaLimiter
from ncfmu.systems.threads import LEAD_RATIO

pytestmark = pytest.mark.slow

LEAD, HEIGHT, ROOT_RADIUS, FLANK = 2.0, 1.227, 27.546 / 2, math.tan(math.radians(30.0))
M30 = """G97 S{s} M03
G00 X32. Z5.
G76 P020060 Q100 R0.05
G76 X27.546 Z-30. P1227 Q400 F2.0
G00 X60. Z2.
M30"""
#: the G76 passes' depths (tests/controllers/test_thread_cycles.py checks them against Fanuc's definition)
DEPTHS = [0.4, 0.4 * math.sqrt(2), 0.4 * math.sqrt(3), 0.8, 0.9, 1.0, 1.1, 1.177, 1.227, 1.227]


def _run(ncfmu_run, s: int, stop: float, input_csv=None):
    return ncfmu_run("lathe_roughing", stop_time=stop, input_csv=input_csv,
                     start_values={"seq.program": M30.format(s=s), "seq.stock_diameter": 30.0})


@pytest.fixture(scope="module")
def s500(ncfmu_run):
    return _run(ncfmu_run, 500, 34.0)


@pytest.fixture(scope="module")
def s1200(ncfmu_run):
    return _run(ncfmu_run, 1200, 22.0)


def _passes(run):
    """Per pass (a rise of seq.threading): the spindle's turns, the actual Z and X while it follows the spindle."""
    on = np.asarray(run["seq.threading"], dtype=bool)
    edges = np.flatnonzero(np.diff(on.astype(int))) + 1
    starts, ends = edges[::2], edges[1::2]
    turns, z, x = (np.asarray(run[k], dtype=float) for k in ("spindle.revolutions", "z_axis.pos", "x_axis.pos"))
    return [(turns[a:b], z[a:b], x[a:b]) for a, b in zip(starts, ends)]


def _full_lead(turns, z):
    """Where the local lead is the programmed one (within LEAD_RATIO): the full-lead part of a pass."""
    ratio = np.abs(np.diff(z)) / (LEAD * np.diff(turns))
    full = np.flatnonzero(np.abs(ratio - 1.0) <= LEAD_RATIO)
    return slice(full[0], full[-1] + 1)


def _helix_offsets(run):
    """Each pass's helix z = c - lead*turns: c less the flank infeed its depth intends, relative to the first's
    (um, modulo the lead)."""
    cs = []
    for (turns, z, _x), depth in zip(_passes(run), DEPTHS):
        full = _full_lead(turns, z)
        c = np.median(z[full] + LEAD * turns[full]) - (HEIGHT - depth) * FLANK
        cs.append(c)
    return np.array([((c - cs[0] + LEAD / 2) % LEAD - LEAD / 2) * 1000.0 for c in cs])


def test_every_pass_lands_in_the_groove_of_the_first(s500):
    assert s500["seq.done"][-1] and not s500["seq.alarm"].any()
    assert len(_passes(s500)) == 10
    on = np.asarray(s500["seq.threading"], dtype=bool)
    assert set(np.unique(s500["seq.canned_cycle"][on])) == {76}
    offsets = _helix_offsets(s500)
    assert np.abs(offsets).max() <= 2.0, offsets
    (thread,) = s500.part.threads
    assert thread.line == 4 and thread.passes == 10 and not thread.cross_threaded
    assert thread.phase_spread_um <= 2.0


def test_lead_exact_and_the_bottom_at_the_root(s500):
    turns, z, x = _passes(s500)[-1]
    full = _full_lead(turns, z)
    lead = -np.polyfit(turns[full], z[full], 1)[0]
    assert lead == pytest.approx(LEAD, rel=1e-3)
    assert abs(z[full][0] - z[full][-1]) > 30.0                     # over the thread's length
    assert np.abs(x[full] - ROOT_RADIUS).max() <= 0.005            # the bottom at radius 13.773
    (thread,) = s500.part.threads
    assert thread.lead_mm == pytest.approx(LEAD, rel=1e-3)
    assert thread.minor_diameter_mm == pytest.approx(27.546, abs=0.010)


def _incomplete_start(run) -> float:
    turns, z, _x = _passes(run)[-1]
    return abs(z[_full_lead(turns, z).start] - z[0])


def _predicted_incomplete_start(run, s: float) -> float:
    """The design's prediction. The sequencer commands Z from the spindle with a velocity step (no feed-forward);
    the area limiter between it and the servos passes no velocity step: it brings Z up to the thread's speed
    v = lead * S / 60 at its decel (and then trails by that ramp's length), and the servo follows the limiter's
    ramp with its feed-forward. The local lead reaches (1 - a) of the lead where the ramp's speed reaches it:
    after (1 - a)^2 v^2 / (2 decel) of Z."""
    decel = float(run.parameters.get("limiter", {}).get("decel", AreaLimiter.default_parameters()["decel"]))
    v = LEAD * s / 60.0
    return (1.0 - LEAD_RATIO) ** 2 * v * v / (2.0 * decel)


def test_incomplete_lead_at_the_start_as_the_design_predicts_and_longer_at_higher_speed(s500, s1200):
    slow, fast = _incomplete_start(s500), _incomplete_start(s1200)
    assert slow == pytest.approx(_predicted_incomplete_start(s500, 500.0), rel=0.2)
    assert fast == pytest.approx(_predicted_incomplete_start(s1200, 1200.0), rel=0.2)
    assert fast > 2.0 * slow
    assert np.abs(_helix_offsets(s1200)).max() <= 2.0
    (thread,) = s1200.part.threads
    assert thread.incomplete_start_mm == pytest.approx(fast, rel=1e-6)
    assert thread.incomplete_end_mm > thread.incomplete_start_mm * 0.5


def test_a_spindle_speed_dip_between_passes_still_one_groove(ncfmu_run, s500, tmp_path):
    """A load torque step (40 N.m) after the first pass: the spindle dips and falls behind in angle, so a pass
    started by time would land elsewhere; started at the marker, every pass is in the first's groove."""
    csv_file = tmp_path / "load.csv"
    csv_file.write_text("time,spindle.load_torque\n0,0\n3.2,0\n3.201,40\n34,40\n")
    dipped = _run(ncfmu_run, 500, 34.0, csv_file)
    assert dipped["seq.done"][-1] and not dipped["seq.alarm"].any()
    t = np.asarray(dipped["time"])
    after = (t > 3.2) & (t < 3.6)
    assert np.abs(dipped["spindle.speed"][after]).min() < 0.98 * 500.0              # the dip
    late = t > 5.0
    lost = np.abs(np.asarray(s500["spindle.revolutions"])[late] - np.asarray(dipped["spindle.revolutions"])[late])
    assert lost.min() * LEAD > 0.005                 # a start by time would be this far (mm) out of the groove
    assert np.abs(_helix_offsets(dipped)).max() <= 2.0
    (thread,) = dipped.part.threads
    assert not thread.cross_threaded and thread.phase_spread_um <= 2.0
