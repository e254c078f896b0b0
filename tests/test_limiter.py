"""AreaLimiter logic at region boundaries, back-out, alarm; property tests with hypothesis."""

import math

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ncfmu.controllers.limiter import LIM_MINUS, LIM_PLUS, REF_MINUS, REF_PLUS, AreaLimiter, find_region
from ncfmu.errors import ConfigError
from ncfmu.servo.axis import ServoAxis

DT = 1e-3
# the grinder table of SPEC 5: reference Y (table), limited X (infeed)
GRINDER = [(200.0, -1e6, 250.0), (350.0, -1e6, 80.0), (800.0, -1e6, 180.0), (1000.0, -1e6, 60.0)]


class Drive:
    """Feeds the limiter with commands moving at given speeds; the axes follow the gated commands."""

    def __init__(self, table=GRINDER, ref=100.0, lim=0.0, **parameters):
        self.lim = make(table, ref=ref, lim=lim, **parameters)
        self.ref_cmd, self.lim_cmd = ref, lim
        self.t = 0.0
        self.out = dict(self.lim.outputs())

    def step(self, v_ref=0.0, v_lim=0.0):
        self.ref_cmd += v_ref * DT
        self.lim_cmd += v_lim * DT
        o = self.lim.step(self.t, DT, {"ref_cmd_in": self.ref_cmd, "lim_cmd_in": self.lim_cmd, "ref_vff_in": v_ref,
                                       "lim_vff_in": v_lim, "ref_pos": self.out["ref_cmd"], "lim_pos": self.out["lim_cmd"]})
        self.out = dict(o)
        self.t += DT
        return self.out

    def hold_inputs_at_output(self):
        self.ref_cmd, self.lim_cmd = self.out["ref_cmd"], self.out["lim_cmd"]


def make(table=GRINDER, ref=100.0, lim=0.0, **kw):
    return AreaLimiter.with_table(table, ref_start=ref, lim_start=lim, **kw)


def test_region_search_on_and_past_boundaries():
    b = [200.0, 350.0, 800.0, 1000.0]
    assert find_region(b, -5.0) == 1
    assert find_region(b, 200.0) == 1            # exactly on the boundary: still the lower region
    assert find_region(b, 200.0 + 1e-9) == 2     # just past it
    assert find_region(b, 1000.0) == 4
    assert find_region(b, 1000.1) == 0           # above the table


def test_limited_axis_motion_blocked_in_its_direction_only():
    d = Drive(GRINDER, ref=300.0, lim=70.0)       # headstock region: X <= 80
    while not d.step(v_lim=20.0)["alarm"]:
        assert d.t < 2
    o = d.out
    assert o["blocked"] == LIM_PLUS and o["region"] == 2
    overshoot = o["lim_cmd"] - 80.0
    assert 0 < overshoot <= 20.0 * 0.005 + 1e-9           # at most one monitor period of travel
    held = o["lim_cmd"]
    for _ in range(20):
        o = d.step(v_lim=20.0)
        assert o["lim_cmd"] == held and o["lim_vff"] == 0.0 and o["alarm"]
    # the reference axis may still move within the region
    o = d.step(v_ref=10.0)
    assert o["ref_cmd"] > 300.0
    # back out: the opposite direction passes at once, the alarm clears once inside
    d.hold_inputs_at_output()
    o = d.step(v_lim=-20.0)
    assert o["lim_cmd"] < held and o["lim_vff"] == -20.0
    for _ in range(20):
        o = d.step(v_lim=-20.0)
    assert not o["alarm"] and o["blocked"] == 0 and o["lim_cmd"] < 80.0


def test_reference_axis_motion_into_a_stricter_region_is_blocked():
    d = Drive(GRINDER, ref=150.0, lim=100.0)      # X = 100 allowed below Y 200, not in the headstock region
    while not d.step(v_ref=40.0)["alarm"]:
        assert d.t < 5
    o = d.out
    assert o["blocked"] == REF_PLUS                # the table axis carried the wheel in: block Y+
    assert 200.0 < o["ref_cmd"] <= 200.0 + 40.0 * 0.005 + 1e-9
    held = o["ref_cmd"]
    assert d.step(v_ref=40.0)["ref_cmd"] == held
    d.hold_inputs_at_output()
    for _ in range(10):
        o = d.step(v_ref=-40.0)                    # back out along Y
    assert o["ref_cmd"] < 200.0 and not o["alarm"]


def test_lower_limit_and_leaving_the_table():
    d = Drive([(100.0, 10.0, 50.0)], ref=50.0, lim=20.0)
    while not d.step(v_lim=-30.0)["alarm"]:
        pass
    assert d.out["blocked"] == LIM_MINUS and d.out["lim_cmd"] < 10.0
    d2 = Drive([(100.0, 10.0, 50.0)], ref=90.0, lim=20.0)
    while not d2.step(v_ref=30.0)["alarm"]:
        pass
    assert d2.out["blocked"] == REF_PLUS and d2.out["region"] == 0


def test_predictive_mode_stops_inside():
    for v in (5.0, 50.0, 200.0):
        d = Drive(GRINDER, ref=300.0, lim=75.0, predictive=True)
        for _ in range(3000):
            o = d.step(v_lim=v)
            assert o["lim_cmd"] <= 80.0
        assert o["alarm"] and o["blocked"] == LIM_PLUS


@pytest.mark.parametrize("name, value, rule", [
    ("n_regions", 0, "must be in 1..32"),
    ("n_regions", 33, "must be in 1..32"),
    ("region[2].ref_max", 100.0, "boundaries must increase strictly"),
    ("region[1].lim_min", 300.0, "must be <= region[1].lim_max"),
    ("region[1].lim_max", math.inf, "must be finite"),
    ("monitor_period", 0.0, "must be > 0"),
])
def test_bad_table_refused_naming_the_entry(name, value, rule):
    values = {"n_regions": 2, "region[1].ref_max": 200.0, "region[2].ref_max": 300.0, "region[1].lim_max": 100.0}
    values[name] = value
    with pytest.raises(ConfigError) as err:
        AreaLimiter(**values)
    assert err.value.variable == name and rule in str(err.value)


def test_nan_input_holds_and_alarms():
    d = Drive(GRINDER, ref=300.0, lim=0.0)
    d.step(v_lim=10.0)
    before = dict(d.out)
    o = d.lim.step(1.0, DT, {"ref_cmd_in": math.nan, "lim_cmd_in": 5.0, "ref_vff_in": 0.0, "lim_vff_in": 0.0,
                             "ref_pos": 300.0, "lim_pos": 0.0})
    assert o["alarm"] and o["ref_cmd"] == before["ref_cmd"] and o["lim_cmd"] == before["lim_cmd"]


# -- properties ---------------------------------------------------------------------------------
@st.composite
def tables(draw):
    n = draw(st.integers(1, 6))
    widths = draw(st.lists(st.floats(20.0, 200.0), min_size=n, max_size=n))
    bounds, b = [], 0.0
    for w in widths:
        b += w
        bounds.append(b)
    highs = draw(st.lists(st.floats(40.0, 150.0), min_size=n, max_size=n))
    return [(bb, -1e6, h) for bb, h in zip(bounds, highs)]


moves = st.lists(st.tuples(st.sampled_from([-1, 0, 1]), st.sampled_from([-1, 0, 1]),
                           st.floats(5.0, 60.0), st.integers(20, 400)), min_size=1, max_size=8)


def envelope_ok(limiter, ref, lim, tol=0.0):
    r = find_region(limiter.ref_max, ref)
    return r > 0 and lim <= limiter.lim_max[r - 1] + tol


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(table=tables(), program=moves)
def test_property_predictive_commanded_and_actual_stay_inside(table, program):
    limiter = make(table, ref=table[0][0] / 2, lim=0.0, predictive=True, use_actual=True)
    servo_r, servo_l = ServoAxis(pos_start=table[0][0] / 2), ServoAxis(pos_start=0.0)
    ref_cmd, lim_cmd, t = table[0][0] / 2, 0.0, 0.0
    for dr, dl, speed, steps in program:
        for _ in range(steps):
            # the controller: a straight move, frozen once the limiter raises its alarm (like the sequencer)
            if not limiter.alarm:
                ref_cmd += dr * speed * DT
                lim_cmd += dl * speed * DT
            o = limiter.step(t, DT, {"ref_cmd_in": ref_cmd, "lim_cmd_in": lim_cmd,
                                     "ref_vff_in": 0.0 if limiter.alarm else dr * speed,
                                     "lim_vff_in": 0.0 if limiter.alarm else dl * speed,
                                     "ref_pos": servo_r.x[2], "lim_pos": servo_l.x[2]})
            sr = servo_r.step(t, DT, {"pos_cmd": o["ref_cmd"], "vel_ff": o["ref_vff"], "enable": True})
            sl = servo_l.step(t, DT, {"pos_cmd": o["lim_cmd"], "vel_ff": o["lim_vff"], "enable": True})
            t += DT
            ref_ok = ref_cmd <= table[-1][0]
            assert envelope_ok(limiter, o["ref_cmd"], o["lim_cmd"])
            assert envelope_ok(limiter, sr["pos"], sl["pos"])
        # the operator backs out: inputs follow the gated commands, then move the opposite way
        ref_cmd, lim_cmd = o["ref_cmd"], o["lim_cmd"]
        if limiter.blocked:
            blocked = limiter.blocked
            back_r = -1 if blocked & REF_PLUS else (1 if blocked & REF_MINUS else 0)
            back_l = -1 if blocked & LIM_PLUS else (1 if blocked & LIM_MINUS else 0)
            # the inputs held where the gate holds them, the operator backs out at 20 mm/s -- far enough
            # that a restart at the speed it was blocked at (<= 60 mm/s) could still stop inside
            ref_cmd, lim_cmd = o["ref_cmd"], o["lim_cmd"]
            room = 60.0 * limiter.monitor_period + 60.0 ** 2 / (2 * limiter.decel) + 0.2
            for _ in range(int(room / 20.0 / DT)):
                ref_cmd += back_r * 20.0 * DT
                lim_cmd += back_l * 20.0 * DT
                o = limiter.step(t, DT, {"ref_cmd_in": ref_cmd, "lim_cmd_in": lim_cmd, "ref_vff_in": back_r * 20.0,
                                         "lim_vff_in": back_l * 20.0, "ref_pos": o["ref_cmd"],
                                         "lim_pos": o["lim_cmd"]})
                assert (o["ref_cmd"], o["lim_cmd"]) == (ref_cmd, lim_cmd)     # followed at once
                t += DT
            assert not o["alarm"]


@settings(max_examples=40, deadline=None)
@given(table=tables(), program=moves)
def test_property_overshoot_bounded_by_one_monitor_period(table, program):
    limiter = make(table, ref=table[0][0] / 2, lim=0.0)
    ref_cmd, lim_cmd, t = table[0][0] / 2, 0.0, 0.0
    fastest = 0.0
    for dr, dl, speed, steps in program:
        fastest = max(fastest, speed)   # an overshoot made at this speed persists into later moves
        for _ in range(steps):
            if not limiter.alarm:
                ref_cmd += dr * speed * DT
                lim_cmd += dl * speed * DT
            o = limiter.step(t, DT, {"ref_cmd_in": ref_cmd, "lim_cmd_in": lim_cmd, "ref_vff_in": dr * speed,
                                     "lim_vff_in": dl * speed, "ref_pos": 0.0, "lim_pos": 0.0})
            t += DT
            # one monitor period (plus the step in which the alarm reaches the controller) of travel
            travel = fastest * (limiter.monitor_period + DT) + 1e-9
            r = find_region(limiter.ref_max, o["ref_cmd"])
            if r == 0:
                assert o["ref_cmd"] <= table[-1][0] + travel
            else:
                lim_allowed = limiter.lim_max[r - 1]
                ok = o["lim_cmd"] <= lim_allowed + travel
                # or the reference axis just stepped into a stricter region by at most one period
                stepped = find_region(limiter.ref_max, o["ref_cmd"] - travel) != r
                assert ok or stepped
        ref_cmd, lim_cmd = o["ref_cmd"], o["lim_cmd"]
