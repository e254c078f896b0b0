"""Stops, interlocks and restarts on the plain controllers, as seeded hypothesis properties.

Feed holds, alarms, excess following errors, bad inputs and EMB strike at random instants in every
phase. Whatever strikes, a command never accelerates faster than the controller's ``accel`` (a stop
decelerates along the path), a restart after an alarm is safe (the lathe retracts X before Z moves;
the grinder returns to the feed origin before it feeds toward the work), and every M word waits for
its own MFIN.
"""

import math

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ncfmu.controllers import Block, ContourInterpolator, CutSequencer, OperatorPanel, ProgrammableFeed
from ncfmu.systems import parameters

#: Scenario values from the system definitions (the controllers' own defaults are neutral).
GRINDER_FEED, MILL = parameters("grinder_feed", "feed"), parameters("mill_contour", "contour")

DT = 1e-3
PROPERTY = settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def assert_within_accel(trace, accel, keys):
    for a, b in zip(trace, trace[1:]):
        for k in keys:
            assert abs(b[k] - a[k]) <= accel * DT * (1 + 1e-9) + 1e-12, (k, a[k], b[k])


# -- CutSequencer -----------------------------------------------------------------------------------
class Lathe:
    """The sequencer with axes that stand where commanded (or stick: an axis that stopped following)."""

    def __init__(self, seq):
        self.seq = seq
        self.inputs = {"start": False, "feed_hold": False, "feed_override": 1.0, "x_pos": seq.x_cmd,
                       "z_pos": seq.z_cmd, "x_in_position": True, "z_in_position": True, "alarm_in": False}
        self.stuck = False
        self.trace = []

    def step(self, **inputs):
        self.inputs.update(inputs)
        o = dict(self.seq.step(len(self.trace) * DT, DT, self.inputs))
        self.inputs["start"] = False
        if not self.stuck:
            self.inputs["x_pos"], self.inputs["z_pos"] = o["x_cmd"], o["z_cmd"]
        self.trace.append(o)
        return o


@pytest.mark.slow
@PROPERTY
@given(phase=st.integers(1, 4), pass_no=st.integers(1, 3), delay=st.integers(0, 400),
       event=st.sampled_from(["hold", "alarm_in", "following_error", "nan", "override"]),
       feed=st.floats(2.0, 40.0), rapid=st.floats(20.0, 100.0))
def test_property_sequencer_stops_within_accel_and_restarts_safely(phase, pass_no, delay, event, feed, rapid):
    seq = CutSequencer.with_blocks([Block(Xf=1.0, Xd=0.5, Zp=20.0, N=3, feed=feed, rapid=rapid)])
    lathe = Lathe(seq)
    lathe.step(start=True)
    while not (lathe.trace[-1]["subcycle"] == phase and lathe.trace[-1]["pass_no"] == pass_no):
        lathe.step()
        assert len(lathe.trace) < 200_000
    for _ in range(delay):
        lathe.step()
    if event == "hold":
        for _ in range(300):
            o = lathe.step(feed_hold=True)
        assert o["x_vff"] == o["z_vff"] == 0.0 or phase != 2      # a hold stops the cut (rapids go on)
        lathe.step(feed_hold=False)
    elif event == "override":
        lathe.step(feed_override=7.0)                                # clamped to 1.5 and said once
        for _ in range(200):
            lathe.step()
        lathe.step(feed_override=1.0)
        assert sum("feed_override" in m for _, m in seq.take_messages()) == 1
    else:
        if event == "alarm_in":
            lathe.step(alarm_in=True)
            lathe.step(alarm_in=False)
        elif event == "nan":
            lathe.step(z_pos=math.nan)
        else:                                                        # the axes stop following
            lathe.stuck = True
            before = (lathe.trace[-1]["subcycle"], lathe.trace[-1]["pass_no"])
            for _ in range(3000):
                if seq.alarm:
                    break
                lathe.step()
            else:
                # the command had (almost) arrived: no alarm, but no sub-cycle ends on a position not reached
                assert (lathe.trace[-1]["subcycle"], lathe.trace[-1]["pass_no"]) == before
                return
        while lathe.trace[-1]["x_vff"] or lathe.trace[-1]["z_vff"]:
            lathe.step()
            assert len(lathe.trace) < 200_000
        o = lathe.trace[-1]
        assert o["alarm"] and not o["busy"]
        # START after the alarm: follow-up on the actual position, X clear first, then Z
        x_rest, z_rest = lathe.inputs["x_pos"], lathe.inputs["z_pos"]
        lathe.stuck = False
        mark = len(lathe.trace)
        lathe.step(start=True)
        while lathe.trace[-1]["subcycle"] == 0 and lathe.trace[-1]["busy"]:
            lathe.step()
            assert len(lathe.trace) < 200_000
        approach = lathe.trace[mark:-1]
        clear = max(x_rest, seq.x_start)
        for r in approach:
            assert r["x_cmd"] >= x_rest - 1e-9                       # never toward the work on the way
            if abs(r["z_cmd"] - z_rest) > 1e-9:
                assert r["x_cmd"] >= clear - 1e-9                    # Z moves only once X is clear
        assert not lathe.trace[-1]["alarm"]
    while not lathe.trace[-1]["done"]:
        lathe.step()
        assert len(lathe.trace) < 200_000
    assert_within_accel(lathe.trace, seq.accel, ("x_vff", "z_vff"))
    final = lathe.trace[-1]
    assert (final["x_cmd"], final["z_cmd"]) == (seq.x_start, seq.z_start)


def test_blocks_with_their_own_start_points_rough_a_stepped_shaft():
    """Two diameters of a stepped shaft from one block series: block 2 has its own STP."""
    seq = CutSequencer.with_blocks([
        Block(Xf=1.0, Xd=0.5, Zp=40.0, N=2, feed=4.0),                                   # radius 28.0 over 40 mm
        Block(Xf=1.0, Xd=0.5, Zp=15.0, N=2, feed=4.0, own_stp=True, x_stp=29.0, z_stp=2.0),  # 27.0 over 15 mm
    ], x_start=30.0, z_start=2.0)
    lathe = Lathe(seq)
    lathe.step(start=True)
    while not lathe.trace[-1]["done"]:
        lathe.step()
    cuts = [(r["block_no"], r["x_cmd"], r["z_cmd"]) for a, r, b in zip(lathe.trace, lathe.trace[1:], lathe.trace[2:])
            if r["subcycle"] == 2 and b["subcycle"] == 3]
    assert [(blk, round(x, 9), round(z, 9)) for blk, x, z in cuts] == [
        (1, 28.5, -38.0), (1, 28.0, -38.0), (2, 27.5, -13.0), (2, 27.0, -13.0)]
    # between the blocks: X down to the new STP only after Z got there (no diagonal)
    assert_within_accel(lathe.trace, seq.accel, ("x_vff", "z_vff"))


# -- ProgrammableFeed ---------------------------------------------------------------------------------
M_PROGRAM = ("M0: X+D3F7; M1: M1; M2: M2; M3: X+D2F1; M4: M3; M5: X+D5F2; M6: T1; M7: X-D4F7; M8: END; "
             "M41: XF7S1; M42: END; M43: X+D1F2S4; M44: END")


class Grinder:
    """The feed with an axis that stands where commanded and the real OperatorPanel answering M words."""

    def __init__(self, mfin_delay=0.05, **changes):
        self.feed = ProgrammableFeed(**{**GRINDER_FEED, **changes})
        self.panel = OperatorPanel(start_at=-1.0, mfin_delay=mfin_delay)
        self.inputs = {"start": False, "wear_start": False, "emergency": False, "mfin": False, "alarm_in": False,
                       "feed_hold": False, "feed_override": 1.0, "x_pos": 0.0, "y_pos": 0.0,
                       "x_in_position": True, "y_in_position": True}
        self.trace = []

    def step(self, **inputs):
        self.inputs.update(inputs)
        p = self.panel.step(0.0, DT, {"m_active": self.trace[-1]["m_active"] if self.trace else 0})
        self.inputs["mfin"] = p["mfin"]
        o = dict(self.feed.step(len(self.trace) * DT, DT, self.inputs))
        o["mfin"] = p["mfin"]
        for k in ("start", "wear_start", "emergency"):
            self.inputs[k] = False
        self.inputs["x_pos"], self.inputs["y_pos"] = o["x_cmd"], o["y_cmd"]
        self.trace.append(o)
        return o

    def idle(self):
        o = self.trace[-1]
        return not (o["run"] or o["busy"] or o["emergency_active"]) and o["x_vff"] == 0.0


def assert_own_mfin(trace):
    """m_active never changes from one M word to another without 0 between; each wait ends on a rising
    edge of MFIN that came after its strobe."""
    strobe_at = 0 if trace[0]["m_active"] else None
    for i in range(1, len(trace)):
        a, b = trace[i - 1]["m_active"], trace[i]["m_active"]
        assert not (a and b and a != b), (i, a, b)
        if b and not a:
            strobe_at = i
        if a and not b and trace[i]["pc"] == trace[i - 1]["pc"] + 1:   # answered (not aborted by EMB)
            assert trace[i]["mfin"] and not trace[i - 1]["mfin"] and i > strobe_at


@pytest.mark.slow
@PROPERTY
@given(pc=st.sampled_from([0, 1, 2, 3, 4, 5, 6, 7, 43]), delay=st.integers(0, 3000),
       event=st.sampled_from(["alarm_in", "emergency", "hold", "nan"]),
       restart=st.sampled_from(["start", "wear_start"]), mfin_delay=st.floats(0.0, 0.3))
def test_property_feed_never_feeds_toward_the_work_before_the_origin(pc, delay, event, restart, mfin_delay):
    g = Grinder(mfin_delay=mfin_delay, program=M_PROGRAM, F1=0.5, F2=0.2, T1=0.3)
    g.step(**{"wear_start" if pc == 43 else "start": True})
    while g.trace[-1]["pc"] != pc:
        g.step()
        assert len(g.trace) < 100_000
    for _ in range(delay):
        g.step()
    if event == "hold":
        for _ in range(500):
            o = g.step(feed_hold=True)
        assert o["x_vff"] == 0.0
        g.step(feed_hold=False)
    elif event == "alarm_in":
        g.step(alarm_in=True)
        g.step(alarm_in=False)
    elif event == "emergency":
        g.step(emergency=True)
    else:
        g.step(x_pos=math.nan)
    while not g.idle():
        g.step()
        assert len(g.trace) < 200_000
    # a start from wherever the wheel rests: nothing toward the work (+X) until it is at the feed origin
    x_rest, rc = g.trace[-1]["x_cmd"], g.trace[-1]["return_counter_x"]
    origin = x_rest - rc
    mark = len(g.trace)
    g.step(**{restart: True})
    if abs(rc) > 1e-9:
        while abs(g.trace[-1]["return_counter_x"]) > 1e-9 and len(g.trace) - mark < 10_000:
            assert g.trace[-1]["x_cmd"] <= max(x_rest, origin) + 1e-9
            g.step()
        assert abs(g.trace[-1]["return_counter_x"]) <= 1e-9
    while not g.idle() or len(g.trace) - mark < 5:
        g.step()
        assert len(g.trace) < 400_000
    assert not g.trace[-1]["alarm"]
    assert_within_accel(g.trace, g.feed.accel, ("x_vff",))
    assert_own_mfin(g.trace)
    assert g.trace[-1]["dwell_left"] == 0.0


# -- ContourInterpolator ------------------------------------------------------------------------------
@pytest.mark.slow
@PROPERTY
@given(at=st.integers(50, 30000), event=st.sampled_from(["hold", "nan", "jump", "override"]),
       feed=st.floats(2.0, 30.0))
def test_property_contour_stops_along_the_path_within_accel(at, event, feed):
    c = ContourInterpolator(**{**MILL, "feed": feed, "approach_feed": feed})
    inputs = {"start": True, "feed_hold": False, "feed_override": 1.0, "x_pos": c.x_start, "y_pos": c.y_start,
              "x_in_position": True, "y_in_position": True}
    trace = []
    for k in range(at + 400):
        if k == at:
            if event == "hold":
                inputs["feed_hold"] = True
            elif event == "nan":
                inputs["x_pos"] = math.nan
            elif event == "jump":
                inputs["y_pos"] += 1000.0
            else:
                inputs["feed_override"] = -3.0
        o = dict(c.step(k * DT, DT, inputs))
        inputs["start"] = False
        if not (event in ("nan", "jump") and k == at):
            inputs["x_pos"], inputs["y_pos"] = o["x_cmd"], o["y_cmd"]
        trace.append(o)
        assert math.isfinite(o["x_cmd"]) and math.isfinite(o["y_cmd"])
    speeds = [{"v": math.hypot(o["x_vff"], o["y_vff"])} for o in trace]
    assert_within_accel(speeds, c.accel, ("v",))
    if c.busy or c.alarm:
        assert speeds[-1]["v"] == 0.0                              # at rest on the path
    if event in ("nan", "jump") and at < len(trace) and trace[at]["busy"] is False:
        assert trace[-1]["alarm"]


def test_feed_excess_following_error_stops_the_feed():
    """The wheel head stops following during the rapid approach (a jammed slide): alarm, controlled stop."""
    g = Grinder()
    g.step(start=True)
    for _ in range(100):
        g.step()
    stuck = g.inputs["x_pos"]
    while not g.trace[-1]["alarm"]:
        o = g.feed.step(0.0, DT, {**g.inputs, "x_pos": stuck})
        g.trace.append(dict(o, mfin=False))
        assert len(g.trace) < 2000
    assert g.trace[-1]["x_cmd"] - stuck > 2.0
    assert any("following error" in m for _, m in g.feed.take_messages())
    while g.trace[-1]["x_vff"]:
        g.trace.append(dict(g.feed.step(0.0, DT, {**g.inputs, "x_pos": stuck}), mfin=False))
    assert_within_accel(g.trace, g.feed.accel, ("x_vff",))


def test_m_words_in_a_row_each_wait_for_their_own_mfin():
    """M1 then M2 at once: M2 must not complete on M1's MFIN."""
    g = Grinder(mfin_delay=0.2, program="M0: M1; M1: M2; M2: END; M41: END; M43: END")
    g.step(start=True)
    while g.trace[-1]["run"] or len(g.trace) < 3:
        g.step()
    m = [o["m_active"] for o in g.trace]
    assert 1 in m and 2 in m
    first_2 = m.index(2)
    assert m[first_2 - 1] == 0                                   # 1 -> 0 -> 2
    waits = {k: sum(1 for v in m if v == k) * DT for k in (1, 2)}
    assert abs(waits[1] - 0.2) <= 2 * DT and abs(waits[2] - 0.2) <= 2 * DT
    assert_own_mfin(g.trace)
