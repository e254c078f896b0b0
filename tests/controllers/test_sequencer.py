"""CutSequencer logic against the seed (US 4,017,723), without any FMU."""

import math

import pytest

from ncfmu.controllers import Block, CutSequencer
from ncfmu.errors import ConfigError
from ncfmu.systems import parameters

#: lathe_roughing's program (rough 6 passes, finish 1 pass), from its system definition.
ROUGHING = parameters("lathe_roughing", "seq")

DT = 1e-3


class PerfectAxes:
    """Servo stand-in for logic tests: the axes are where commanded, always in position."""

    def __init__(self, seq):
        self.seq = seq
        self.inputs = {"start": False, "feed_hold": False, "feed_override": 1.0, "x_pos": seq.x_cmd,
                       "z_pos": seq.z_cmd, "x_in_position": True, "z_in_position": True, "alarm_in": False}
        self.t = 0.0
        self.trace = []

    def step(self, **overrides):
        self.inputs.update(overrides)
        out = dict(self.seq.step(self.t, DT, self.inputs))
        self.inputs["x_pos"], self.inputs["z_pos"] = out["x_cmd"], out["z_cmd"]
        self.t += DT
        self.trace.append(out)
        return out

    def run_until(self, cond, limit=200_000, **overrides):
        for _ in range(limit):
            out = self.step(**overrides)
            if cond(out):
                return out
        raise AssertionError("condition not reached")

    def press_start(self):
        self.step(start=True)
        self.inputs["start"] = False


def run_cycle(seq):
    axes = PerfectAxes(seq)
    axes.press_start()
    axes.run_until(lambda o: o["done"])
    return axes


def cut_points(trace):
    """(pass, block, x at start of SC2, end point of SC2) for every cut."""
    out = []
    for prev, cur, nxt in zip(trace, trace[1:], trace[2:]):
        if cur["subcycle"] == 2 and prev["subcycle"] != 2:
            out.append(("start", cur["block_no"], cur["pass_no"], cur["x_cmd"], cur["z_cmd"], cur["sigma_x"]))
        if cur["subcycle"] == 2 and nxt["subcycle"] == 3:
            out.append(("end", cur["block_no"], cur["pass_no"], cur["x_cmd"], cur["z_cmd"], cur["sigma_x"]))
    return out


def test_subcycle_order_and_sigma_x():
    seq = CutSequencer.with_blocks([Block(Xf=1.0, Xd=0.5, Xp=0.0, Zp=42.0, N=3)], x_start=30.0, z_start=2.0)
    axes = run_cycle(seq)
    phases = [o["subcycle"] for o in axes.trace]
    changes = [p for i, p in enumerate(phases) if i == 0 or p != phases[i - 1]]
    assert changes == [1, 2, 3, 4] * 3 + [0]
    starts = [c for c in cut_points(axes.trace) if c[0] == "start"]
    # pass n moves ΣX = Xf + n·Xd and cuts at X0 - ΣX
    assert [c[5] for c in starts] == pytest.approx([1.5, 2.0, 2.5])
    assert [c[3] for c in starts] == pytest.approx([28.5, 28.0, 27.5], abs=1e-12)
    assert axes.trace[-1]["x_cmd"] == 30.0 and axes.trace[-1]["z_cmd"] == 2.0


def test_pass_counter_counts_down_at_sc3_to_sc4():
    seq = CutSequencer.with_blocks([Block(N=2)])
    axes = PerfectAxes(seq)
    axes.press_start()
    seen = []
    axes.run_until(lambda o: (seen.append((o["subcycle"], o["passes_left"])) or o["done"]))
    at = {}
    for sub, left in seen:
        at.setdefault(sub, set()).add(left)
    # N=2: passes_left is 2 during the first SC1..SC3, 1 from the first SC4, 0 from the second SC4
    first_sc4 = next(i for i, (s, _) in enumerate(seen) if s == 4)
    assert seen[first_sc4 - 1] == (3, 2) and seen[first_sc4] == (4, 1)
    assert seen[-2][1] == 0


def test_taper_end_points():
    seq = CutSequencer.with_blocks([Block(Xf=1.0, Xd=0.5, Xp=1.5, Zp=42.0, N=2)], x_start=30.0, z_start=2.0)
    axes = run_cycle(seq)
    cuts = cut_points(axes.trace)
    ends = [c for c in cuts if c[0] == "end"]
    assert [(c[3], c[4]) for c in ends] == [(pytest.approx(30 - 1.5 - 1.5), pytest.approx(-40.0)),
                                            (pytest.approx(30 - 2.0 - 1.5), pytest.approx(-40.0))]
    # during SC2 both axes move together on the straight line
    for o in axes.trace:
        if o["subcycle"] == 2 and o["pass_no"] == 1:
            frac = (2.0 - o["z_cmd"]) / 42.0
            assert o["x_cmd"] == pytest.approx(28.5 - 1.5 * frac, abs=1e-9)


def test_block_change_reloads_xf():
    seq = CutSequencer(**ROUGHING)
    axes = run_cycle(seq)
    starts = [c for c in cut_points(axes.trace) if c[0] == "start"]
    assert [(c[1], c[2]) for c in starts] == [(1, n) for n in range(1, 7)] + [(2, 1)]
    assert [c[3] for c in starts] == pytest.approx([28.5, 28.0, 27.5, 27.0, 26.5, 26.0, 25.9])


def test_feed_rate_override_and_hold():
    def cut_time(**overrides):
        seq = CutSequencer.with_blocks([Block(Xf=1.0, Xd=0.5, N=1, Zp=42.0, feed=4.0)], x_start=30.0, z_start=2.0)
        axes = PerfectAxes(seq)
        axes.press_start()
        axes.run_until(lambda o: o["subcycle"] == 2)
        n = 0
        while axes.step(**overrides)["subcycle"] == 2:
            n += 1
        return n * DT

    nominal = cut_time()
    assert nominal == pytest.approx(42.0 / 4.0, abs=0.02)
    assert cut_time(feed_override=0.5) == pytest.approx(42.0 / 2.0, abs=0.02)
    # hold: decelerate to rest, no motion while held, resume on the path
    seq = CutSequencer.with_blocks([Block(Xf=1.0, Xd=0.5, N=1, Zp=42.0)], x_start=30.0, z_start=2.0)
    axes = PerfectAxes(seq)
    axes.press_start()
    axes.run_until(lambda o: o["subcycle"] == 2 and o["z_cmd"] < -10)
    for _ in range(50):
        axes.step(feed_hold=True)
    held = axes.step(feed_hold=True)
    for _ in range(100):
        o = axes.step(feed_hold=True)
        assert o["z_cmd"] == held["z_cmd"] and o["z_vff"] == 0.0
    o = axes.run_until(lambda o: o["subcycle"] == 3, feed_hold=False)
    assert (o["x_cmd"], o["z_cmd"]) == (pytest.approx(28.5), pytest.approx(-40.0))   # the cut was completed


def test_commands_never_jump():
    seq = CutSequencer(**ROUGHING)
    axes = run_cycle(seq)
    for a, b in zip(axes.trace, axes.trace[1:]):
        for axis in "xz":
            dv = abs(b[f"{axis}_vff"] - a[f"{axis}_vff"])
            assert dv <= seq.accel * DT * 1.000001
            assert abs(b[f"{axis}_cmd"] - a[f"{axis}_cmd"]) <= 50.0 * DT * 1.000001


def assert_controlled_stop(seq, trace, axis="z"):
    """From the alarm on: the command decelerates within accel to rest, along the path, and stays there."""
    v0 = abs(trace[0][f"{axis}_vff"])
    for a, b in zip(trace, trace[1:]):
        for ax in "xz":
            assert abs(b[f"{ax}_vff"] - a[f"{ax}_vff"]) <= seq.accel * DT * 1.000001
            assert math.isfinite(b[f"{ax}_cmd"])
    assert trace[-1]["x_vff"] == trace[-1]["z_vff"] == 0.0
    travel = abs(trace[-1][f"{axis}_cmd"] - trace[0][f"{axis}_cmd"])
    assert travel <= v0 * v0 / (2 * seq.accel) + v0 * DT + 1e-9


def test_alarm_in_decelerates_along_the_path_and_latches():
    seq = CutSequencer.with_blocks([Block(feed=40.0)])
    axes = PerfectAxes(seq)
    axes.press_start()
    before = axes.run_until(lambda o: o["subcycle"] == 2 and o["z_cmd"] < -5)
    trace = [before]
    o = axes.step(alarm_in=True)
    assert o["alarm"] and not o["busy"]
    assert o["z_vff"] < 0 and o["x_cmd"] == before["x_cmd"]         # still moving: no velocity step
    trace.append(o)
    for _ in range(200):
        trace.append(axes.step(alarm_in=False))
    assert_controlled_stop(seq, trace)
    assert trace[-1]["alarm"] and trace[-1]["z_cmd"] < before["z_cmd"] - 1.0   # 40 mm/s: 1.6 mm to stop
    assert any("alarm_in" in text for _, text in seq.take_messages())


@pytest.mark.parametrize("bad", [math.nan, math.inf, 1e300])
def test_absurd_position_raises_alarm_and_stops_under_control(bad):
    seq = CutSequencer(**ROUGHING)
    axes = PerfectAxes(seq)
    axes.press_start()
    before = axes.run_until(lambda o: o["subcycle"] == 2 and o["z_cmd"] < -1)
    seq.step(axes.t, DT, {**axes.inputs, "x_pos": bad})
    trace = [before, dict(seq.outputs())]
    assert trace[-1]["alarm"]
    axes.t += DT
    for _ in range(50):
        trace.append(axes.step())
    assert_controlled_stop(seq, trace)
    assert any("x_pos" in text for _, text in seq.take_messages())


@pytest.mark.parametrize("name, value, rule", [
    ("block[1].Xd", 0.0, "must be > 0"),
    ("block[1].Xd", -0.5, "must be > 0"),
    ("block[2].N", 0, "must be in 1..10000"),
    ("block[1].Zp", 0.0, "must be > 0"),
    ("block[1].feed", 0.0, "must be > 0"),
    ("block[1].Xf", math.nan, "must be finite"),
    ("n_blocks", 0, "must be in 1..8"),
    ("n_blocks", 9, "must be in 1..8"),
])
def test_bad_registers_are_refused_naming_the_variable(name, value, rule):
    with pytest.raises(ConfigError) as err:
        CutSequencer(**{name: value})
    assert err.value.variable == name
    assert name in str(err.value) and rule in str(err.value)
