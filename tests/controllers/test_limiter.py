"""AreaLimiter logic at region boundaries, back-out, alarm; property tests with hypothesis."""

import math

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from ncfmu.controllers.limiter import LIM_MINUS, LIM_PLUS, REF_MINUS, REF_PLUS, AreaLimiter, find_region
from ncfmu.controllers.motion import LinearMove
from ncfmu.errors import ConfigError
from ncfmu.servo.axis import ServoAxis

DT = 1e-3
# the grinder_envelope system's table: reference Y (table), limited X (infeed)
GRINDER = [(200.0, -1e6, 250.0), (350.0, -1e6, 80.0), (800.0, -1e6, 180.0), (1000.0, -1e6, 60.0)]


class Drive:
    """Feeds the limiter with commands moving at given speeds, changed at once: the worst upstream, whose
    velocity steps the limiter must govern (no step beyond decel * dt reaches a servo); the axes follow the gated
    commands."""

    def __init__(self, table=GRINDER, ref=100.0, lim=0.0, **parameters):
        self.lim = make(table, ref=ref, lim=lim, **parameters)
        self.ref_cmd, self.lim_cmd = ref, lim
        self.t = 0.0
        self.out = dict(self.lim.outputs())

    def step(self, v_ref=0.0, v_lim=0.0):
        self.ref_cmd += v_ref * DT
        self.lim_cmd += v_lim * DT
        o = self.lim.step(self.t, DT, {"ref_cmd_in": self.ref_cmd, "lim_cmd_in": self.lim_cmd, "ref_vff_in": v_ref,
                                       "lim_vff_in": v_lim, "ref_pos": self.out["ref_cmd"],
                                       "lim_pos": self.out["lim_cmd"]})
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


def run_to_rest(d, limit=400, **v):
    """Step until both gated feed-forwards are 0; check that they never step by more than decel*dt."""
    trace = [d.out]
    for _ in range(limit):
        trace.append(d.step(**v))
        if trace[-1]["ref_vff"] == trace[-1]["lim_vff"] == 0.0:
            break
    assert_no_velocity_step(d.lim, trace)
    return trace[-1]


def assert_no_velocity_step(limiter, trace):
    for a, b in zip(trace, trace[1:]):
        for k in ("ref_vff", "lim_vff"):
            assert abs(b[k] - a[k]) <= limiter.decel * DT * (1 + 1e-9) + 1e-9, (k, a[k], b[k])


def test_limited_axis_motion_blocked_in_its_direction_only():
    d = Drive(GRINDER, ref=300.0, lim=70.0)       # headstock region: X <= 80
    while not d.step(v_lim=20.0)["alarm"]:
        assert d.t < 2
    o = d.out
    assert o["blocked"] == LIM_PLUS and o["region"] == 2
    assert 0 < o["lim_cmd"] - 80.0 <= 20.0 * 0.005 + 1e-9      # seen within one monitor period
    # a controlled stop, not a freeze: decelerates at decel, then holds
    o = run_to_rest(d, v_lim=20.0)
    assert 0 < o["lim_cmd"] - 80.0 <= d.lim.overshoot_bound(20.0, DT) and o["alarm"]
    held = o["lim_cmd"]
    for _ in range(20):
        o = d.step(v_lim=20.0)
        assert o["lim_cmd"] == held and o["lim_vff"] == 0.0 and o["alarm"]
    # the reference axis may still move within the region
    o = d.step(v_ref=10.0)
    assert o["ref_cmd"] > 300.0
    # back out: the opposite direction is followed at once (its velocity step governed: decel * dt a step, never
    # faster than the 20 mm/s asked), the alarm clears once inside
    d.hold_inputs_at_output()
    trace = [o, d.step(v_lim=-20.0)]
    assert trace[-1]["lim_cmd"] < held and trace[-1]["lim_vff"] == -d.lim.decel * DT
    for _ in range(60):                            # the controlled stop went ~0.4 mm past: 0.8 mm back
        trace.append(d.step(v_lim=-20.0))
    assert_no_velocity_step(d.lim, trace)
    o = trace[-1]
    assert not o["alarm"] and o["blocked"] == 0 and o["lim_cmd"] < 80.0
    assert max(abs(r["lim_vff"]) for r in trace) <= 20.0


def test_reference_axis_motion_into_a_stricter_region_is_blocked():
    d = Drive(GRINDER, ref=150.0, lim=100.0)      # X = 100 allowed below Y 200, not in the headstock region
    while not d.step(v_ref=40.0)["alarm"]:
        assert d.t < 5
    o = d.out
    assert o["blocked"] == REF_PLUS                # the table axis carried the wheel in: block Y+
    assert 200.0 < o["ref_cmd"] <= 200.0 + 40.0 * 0.005 + 1e-9
    o = run_to_rest(d, v_ref=40.0)
    assert o["ref_cmd"] <= 200.0 + d.lim.overshoot_bound(40.0, DT)
    held = o["ref_cmd"]
    assert d.step(v_ref=40.0)["ref_cmd"] == held
    d.hold_inputs_at_output()
    trace = [o]
    for _ in range(120):                           # back out along Y (the stop went ~1.8 mm past; the first
        trace.append(d.step(v_ref=-40.0))          # 80 ms accelerate the axis to the 40 mm/s asked: 1.6 mm)
    assert_no_velocity_step(d.lim, trace)
    o = trace[-1]
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


@pytest.mark.parametrize("v", [5.0, 50.0, 200.0])
def test_predictive_mode_stops_at_the_boundary(v):
    d = Drive(GRINDER, ref=300.0, lim=0.0, predictive=True)
    trace = [d.out]
    # the input reaches 120 mm; the gated axis accelerates to v at decel first (it trails the input by v**2 / 2a)
    for _ in range(int(120.0 / v / DT) + int(v / d.lim.decel / DT)):
        trace.append(d.step(v_lim=v))
        assert trace[-1]["lim_cmd"] < 80.0                   # never at or past the boundary
    assert_no_velocity_step(d.lim, trace)         # the input's own velocity step included
    o = trace[-1]
    assert 79.0 <= o["lim_cmd"] and o["lim_vff"] == 0.0             # stopped at the boundary, not early
    assert o["alarm"] and o["blocked"] == LIM_PLUS                   # the command asks to go on
    # the command comes back inside: followed again, alarm cleared
    while d.lim_cmd > 60.0 + 1e-9:
        o = d.step(v_lim=-min(100.0, (d.lim_cmd - 60.0) / DT))
    for _ in range(1000):
        o = d.step()
    assert o["lim_cmd"] == d.lim_cmd == pytest.approx(60.0) and not o["alarm"] and o["blocked"] == 0


def test_predictive_ramp_inside_the_envelope_is_followed():
    """Y held at 100 (X <= 250), X ramped 50 -> 240 mm in 1 s: never a deadlock."""
    d = Drive(GRINDER, ref=100.0, lim=50.0, predictive=True, use_actual=True)
    trace = [d.out]
    for _k in range(3000):
        v = 190.0 if d.lim_cmd < 240.0 else 0.0
        d.lim_cmd = min(d.lim_cmd + v * DT, 240.0) - v * DT
        trace.append(d.step(v_lim=v))
        assert trace[-1]["lim_cmd"] <= 250.0
    o = trace[-1]
    assert o["lim_cmd"] == 240.0 and not o["alarm"] and o["blocked"] == 0


@pytest.mark.parametrize("predictive", [False, True])
def test_start_away_from_an_inside_command_rejoins_without_a_jump(predictive):
    d = Drive(GRINDER, ref=100.0, lim=0.0, predictive=predictive)
    d.lim_cmd = 100.0
    trace = [d.out]
    for _ in range(2000):
        trace.append(d.step())
        assert trace[-1]["lim_cmd"] <= 100.0 + 1e-9
    assert_no_velocity_step(d.lim, trace)
    assert trace[-1]["lim_cmd"] == 100.0 and not trace[-1]["alarm"]


@pytest.mark.parametrize("inputs, named", [
    ({"ref_vff_in": 1e300}, "ref_vff_in"),
    ({"lim_cmd_in": 1000.0}, "lim_cmd_in"),
    ({"ref_cmd_in": 1e300}, "ref_cmd_in"),
    ({"lim_pos": -1e300}, "lim_pos"),
    ({"lim_cmd_in": math.inf}, "lim_cmd_in"),
])
def test_absurd_inputs_stop_both_axes_with_an_alarm(inputs, named):
    d = Drive(GRINDER, ref=300.0, lim=0.0)
    for _ in range(50):
        d.step(v_lim=10.0)
    base = {"ref_cmd_in": d.ref_cmd, "lim_cmd_in": d.lim_cmd, "ref_vff_in": 0.0, "lim_vff_in": 10.0,
            "ref_pos": d.out["ref_cmd"], "lim_pos": d.out["lim_cmd"]}
    trace = [d.out]
    for _ in range(100):
        trace.append(dict(d.lim.step(d.t, DT, {**base, **inputs})))
    assert_no_velocity_step(d.lim, trace)
    o = trace[-1]
    assert o["alarm"] and o["lim_vff"] == 0.0 and abs(o["lim_cmd"] - trace[0]["lim_cmd"]) < 0.2
    assert all(math.isfinite(r[k]) for r in trace for k in ("ref_cmd", "lim_cmd", "ref_vff", "lim_vff"))
    errors = [text for level, text in d.lim.take_messages() if level == "error"]
    assert len(errors) == 1 and named in errors[0]


@pytest.mark.parametrize("name, value, rule", [
    ("n_regions", 0, "must be in 1..32"),
    ("n_regions", 33, "must be in 1..32"),
    ("region[2].ref_max", 100.0, "boundaries must increase strictly"),
    ("region[1].lim_min", 300.0, "must be <= region[1].lim_max"),
    ("region[1].lim_max", math.inf, "must be finite"),
    ("monitor_period", 0.0, "must be > 0"),
    ("max_speed", -1.0, "must be > 0"),
    ("margin", -0.1, "must be >= 0"),
])
def test_bad_table_refused_naming_the_entry(name, value, rule):
    values = {"n_regions": 2, "region[1].ref_max": 200.0, "region[2].ref_max": 300.0, "region[1].lim_max": 100.0}
    values[name] = value
    with pytest.raises(ConfigError) as err:
        AreaLimiter(**values)
    assert err.value.variable == name and rule in str(err.value)


# -- properties (seeded: the hypothesis profile in conftest.py) ---------------------------------
# Derandomized (conftest.py), but Hypothesis (6.131+) also draws, now and then, constants it collects from every
# local module loaded so far, so the examples drawn depend on what ran before (a full run drew the two falsifying
# cases kept below as @example, a single-file run drew others). Hypothesis has no public setting for it; the
# found cases are pinned as examples, and any other draw must hold the property as well.


@st.composite
def tables(draw):
    """Stepped envelopes with upper AND lower limits per region; X = 0 is inside every region."""
    n = draw(st.integers(1, 6))
    widths = draw(st.lists(st.floats(20.0, 200.0), min_size=n, max_size=n))
    bounds, b = [], 0.0
    for w in widths:
        b += w
        bounds.append(b)
    highs = draw(st.lists(st.floats(5.0, 60.0), min_size=n, max_size=n))
    lows = draw(st.lists(st.floats(-60.0, -5.0), min_size=n, max_size=n))
    return [(bb, lo, hi) for bb, lo, hi in zip(bounds, lows, highs)]


# straight moves of the upstream controller: (d_ref, d_lim) in mm, speed mm/s; the signs drawn apart from the
# lengths, so that moves down (toward the lower limits) are as frequent as moves up
signed = st.builds(float.__mul__, st.sampled_from((-1.0, 1.0)), st.floats(0.0, 1.0))
moves = st.lists(st.tuples(signed.map(lambda f: 300.0 * f), signed.map(lambda f: 200.0 * f), st.floats(5.0, 200.0)),
                 min_size=1, max_size=4)


def envelope_ok(limiter, ref, lim, tol=0.0):
    r = find_region(limiter.ref_max, ref)
    return r > 0 and limiter.lim_min[r - 1] - tol <= lim <= limiter.lim_max[r - 1] + tol


class Upstream:
    """The controller upstream of the limiter: straight moves, acceleration-limited like every ncfmu controller.
    It ignores the limiter's alarm -- the worst case: the limiter alone keeps the axes inside."""

    def __init__(self, ref, lim, accel):
        self.move = LinearMove(accel)
        self.move.begin((ref, lim), (ref, lim), 1.0)

    def go(self, d_ref, d_lim, speed):
        r, l = self.move.position()
        self.move.begin((r, l), (r + d_ref, l + d_lim), speed)

    def steps(self, n):
        """``n`` steps of the present move, then its controlled stop (a new move starts from rest)."""
        yield from range(n)
        self.move.halt()
        while not self.move.done:
            yield None

    def inputs(self, o, actual=None):
        self.move.advance(DT, 1.0)
        (r, l), (vr, vl) = self.move.position(), self.move.velocity()
        ar, al = actual if actual else (o["ref_cmd"], o["lim_cmd"])
        return {"ref_cmd_in": r, "lim_cmd_in": l, "ref_vff_in": vr, "lim_vff_in": vl, "ref_pos": ar, "lim_pos": al}


@pytest.mark.slow
@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(table=tables(), program=moves)
def test_property_predictive_commanded_and_actual_never_cross(table, program):
    start = table[0][0] / 2
    limiter = make(table, ref=start, lim=0.0, predictive=True, use_actual=True)
    servo_r, servo_l = ServoAxis(pos_start=start), ServoAxis(pos_start=0.0)
    up = Upstream(start, 0.0, limiter.decel)
    o, t, trace = dict(limiter.outputs()), 0.0, []
    sr, sl = {"pos": start}, {"pos": 0.0}
    for d_ref, d_lim, speed in program:
        up.go(d_ref, d_lim, speed)
        for _ in up.steps(250):
            o = dict(limiter.step(t, DT, up.inputs(o, (sr["pos"], sl["pos"]))))
            sr = servo_r.step(t, DT, {"pos_cmd": o["ref_cmd"], "vel_ff": o["ref_vff"], "enable": True})
            sl = servo_l.step(t, DT, {"pos_cmd": o["lim_cmd"], "vel_ff": o["lim_vff"], "enable": True})
            t += DT
            trace.append(o)
            assert envelope_ok(limiter, o["ref_cmd"], o["lim_cmd"])
            assert envelope_ok(limiter, sr["pos"], sl["pos"])
    assert_no_velocity_step(limiter, trace)


@st.composite
def inside_tours(draw):
    """A table and a tour of points inside it, visited along L-paths that stay inside (X to the
    tightest range on the way, then Y, then X), at speeds with velocity steps, as the issue's ramp."""
    table = draw(tables())
    points = []
    for _ in range(draw(st.integers(1, 4))):
        j = draw(st.integers(0, len(table) - 1))
        lo_ref = table[j - 1][0] if j else table[0][0] - 200.0
        ref = draw(st.floats(lo_ref + 1.0, table[j][0] - 1.0))
        lim = draw(st.floats(table[j][1] + 1.0, table[j][2] - 1.0))
        points.append((ref, lim, draw(st.floats(5.0, 200.0))))
    return table, points


@pytest.mark.slow
@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(tour=inside_tours(), lim_start=st.floats(-5.0, 5.0))
def test_property_predictive_follows_every_inside_command(tour, lim_start):
    table, points = tour
    start = table[0][0] / 2
    limiter = make(table, ref=start, lim=lim_start, predictive=True)
    ref, lim = start, 0.0          # the first command is away from where the limiter starts: a rejoin
    t, o = 0.0, dict(limiter.outputs())

    def hold(r, l, vr=0.0, vl=0.0):
        nonlocal t, o
        o = dict(limiter.step(t, DT, {"ref_cmd_in": r, "lim_cmd_in": l, "ref_vff_in": vr, "lim_vff_in": vl,
                                      "ref_pos": o["ref_cmd"], "lim_pos": o["lim_cmd"]}))
        t += DT
        assert envelope_ok(limiter, o["ref_cmd"], o["lim_cmd"])

    def travel(axis, target, speed):
        nonlocal ref, lim
        while True:
            here = ref if axis == 0 else lim
            step = min(speed * DT, abs(target - here))
            v = math.copysign(speed, target - here) if step > 0 else 0.0
            here += math.copysign(step, target - here)
            ref, lim = (here, lim) if axis == 0 else (ref, here)
            hold(ref, lim, v if axis == 0 else 0.0, v if axis == 1 else 0.0)
            if step < speed * DT:
                return

    for p_ref, p_lim, speed in points:
        r1, r2 = sorted((find_region(limiter.ref_max, ref), find_region(limiter.ref_max, p_ref)))
        safe_hi = min(limiter.lim_max[r1 - 1:r2]) - 1.0
        safe_lo = max(limiter.lim_min[r1 - 1:r2]) + 1.0
        travel(1, min(max(lim, safe_lo), safe_hi), speed)
        travel(0, p_ref, speed)
        travel(1, p_lim, speed)
        for _ in range(1500):                      # a rejoin after a 200 mm/s velocity step: < 1.2 s
            hold(ref, lim)
        assert (o["ref_cmd"], o["lim_cmd"]) == (ref, lim), (o, ref, lim, limiter.take_messages())
        assert not o["alarm"] and o["blocked"] == 0


# The two cases the full CI run found (2026-12-02), as focused tests and as explicit examples of the property.
# Case 1: six regions of lim -5..5; lim +200 at 25 mm/s (blocked at lim_max 5), then -200 at 59 mm/s: the
# back-out rejoined its input by outrunning it (85.5 mm/s) and so passed lim_min by 4.14 mm, more than
# overshoot_bound(59) = 3.84 mm.
SIX_NARROW = [(20.0 * k, -5.0, 5.0) for k in range(1, 7)]
BACK_OUT = [(0.0, 200.0, 25.0), (0.0, -200.0, 59.0)]
# Case 2: a straight move of 4.00500000617548 mm at 59 mm/s ends (LinearMove snaps its last 1e-12 mm) with its
# feed-forward stepping 0.5000000690 -> 0: decel * dt + 6.9e-8, which the limiter passed on to the servo.
SNAPPED_END = [(0.0, 4.00500000617548, 59.0)]


def run_upstream(table, program):
    """The property's loop: the upstream controller's moves (each 250 steps, then its stop) through the limiter."""
    limiter = make(table, ref=table[0][0] / 2, lim=0.0)
    up = Upstream(table[0][0] / 2, 0.0, limiter.decel)
    o, t, trace = dict(limiter.outputs()), 0.0, []
    for d_ref, d_lim, speed in program:
        up.go(d_ref, d_lim, speed)
        for _ in up.steps(250):
            o = dict(limiter.step(t, DT, up.inputs(o)))
            t += DT
            trace.append(o)
    return limiter, trace


def test_back_out_after_a_block_never_outruns_its_input():
    limiter, trace = run_upstream(SIX_NARROW, BACK_OUT)
    assert any(o["blocked"] & LIM_PLUS for o in trace) and any(o["blocked"] & LIM_MINUS for o in trace)
    assert max(abs(o["lim_vff"]) for o in trace) <= 59.0      # never faster than the program asked
    lowest = min(o["lim_cmd"] for o in trace)
    assert -5.0 - limiter.overshoot_bound(59.0, DT) <= lowest < -5.0
    assert_no_velocity_step(limiter, trace)


@pytest.mark.parametrize("predictive", [False, True])
def test_an_input_velocity_step_beyond_decel_is_not_passed(predictive):
    """The input's own feed-forward steps by decel * dt + 6.9e-8 (an interpolator's rounding) at the end of a
    move: the gated output does not, and still ends exactly where the input does."""
    lim = make([(100.0, -60.0, 60.0)], ref=10.0, lim=0.0, predictive=predictive)
    a_dt, eps = lim.decel * DT, 6.9e-8
    vs = [k * a_dt for k in range(1, 119)] + [59.0 + eps] * 20 + [59.0 + eps - k * a_dt for k in range(1, 118)]
    vs.append(0.0)
    assert abs(vs[-2] - vs[-1]) == pytest.approx(a_dt + eps, abs=1e-12)
    x, v_old, trace, xs = 0.0, 0.0, [dict(lim.outputs())], []
    for k, v in enumerate(vs + [0.0] * 5):
        x += 0.5 * (v_old + v) * DT              # trapezoidal, as the interpolators integrate
        v_old = v
        xs.append(x)
        trace.append(dict(lim.step(k * DT, DT, {"ref_cmd_in": 10.0, "lim_cmd_in": x, "ref_vff_in": 0.0,
                                                 "lim_vff_in": v, "ref_pos": 10.0, "lim_pos": trace[-1]["lim_cmd"]})))
    assert_no_velocity_step(lim, trace)
    assert trace[-1]["lim_cmd"] == x and trace[-1]["lim_vff"] == 0.0 and not trace[-1]["alarm"]
    # the rounding is governed away, not a lag: the output never leaves the input by more than a micrometre
    assert max(abs(o["lim_cmd"] - c) for o, c in zip(trace[1:], xs)) < 1e-6


@pytest.mark.slow
@settings(max_examples=200, deadline=None)
@given(table=tables(), program=moves)
# found by hypothesis: Z moving down carries X (above region 1's limit) back into region 1 by 0.05 mm
@example(table=[(20.0, -10.0, 20.0), (40.0, -10.0, 23.0), (60.0, -10.0, 20.0)],
         program=[(5.0, 10.0, 45.0), (6.0, 14.0, 59.0), (-1.0, 1.0, 8.0)])
@example(table=SIX_NARROW, program=BACK_OUT)              # found by the full CI run: case 1 above
@example(table=SIX_NARROW, program=SNAPPED_END)           # found by the full CI run: case 2 above
def test_property_overshoot_within_the_documented_bound(table, program):
    start = table[0][0] / 2
    limiter = make(table, ref=start, lim=0.0)
    up = Upstream(start, 0.0, limiter.decel)
    o, t, trace, fastest = dict(limiter.outputs()), 0.0, [], 0.0
    for d_ref, d_lim, speed in program:
        up.go(d_ref, d_lim, speed)
        fastest = max(fastest, speed)    # an overshoot made at this speed persists into later moves
        for _ in up.steps(250):
            o = dict(limiter.step(t, DT, up.inputs(o)))
            t += DT
            trace.append(o)
            bound = limiter.overshoot_bound(fastest, DT)
            r = find_region(limiter.ref_max, o["ref_cmd"])
            if r == 0:
                assert o["ref_cmd"] <= table[-1][0] + bound
            else:
                ok = limiter.lim_min[r - 1] - bound <= o["lim_cmd"] <= limiter.lim_max[r - 1] + bound
                # or the reference axis carried it into a stricter region, up or down, by at most the bound
                stepped = {find_region(limiter.ref_max, o["ref_cmd"] + s * bound) for s in (-1, 1)} != {r}
                assert ok or stepped
    assert_no_velocity_step(limiter, trace)


@st.composite
def lower_limit_cases(draw):
    """A table, a point inside region j at a distance above that region's lower limit, and a downward speed."""
    table = draw(tables())
    j = draw(st.integers(0, len(table) - 1))
    lo_ref = table[j - 1][0] if j else table[0][0] - 200.0
    ref = draw(st.floats(lo_ref + 5.0, table[j][0] - 5.0))
    speed = draw(st.floats(5.0, 200.0))
    lim = table[j][1] + speed * draw(st.floats(0.01, 0.3))         # reaches the lower limit in 10..300 ms
    return table, ref, min(lim, table[j][2] - 1.0), speed


@settings(max_examples=100, deadline=None)
@given(case=lower_limit_cases(), predictive=st.booleans())
def test_property_lower_limit_stops_the_limited_axis_and_blocks_only_lim_minus(case, predictive):
    """The limited axis sent down through its region's lim_min: it stops at it (predictive) or within the
    overshoot bound past it, only lim- is blocked, the reference axis still moves, and a move up backs out."""
    table, ref, lim, speed = case
    d = Drive(table, ref=ref, lim=lim, predictive=predictive)
    low = d.lim.lim_min[find_region(d.lim.ref_max, ref) - 1]
    bound = 0.0 if predictive else d.lim.overshoot_bound(speed, DT)
    trace = [d.out]
    for _ in range(2000):
        trace.append(d.step(v_lim=-speed))
        o = trace[-1]
        assert o["lim_cmd"] >= low - bound and o["ref_cmd"] == ref
        if o["alarm"] and o["lim_vff"] == 0.0:
            break
    assert_no_velocity_step(d.lim, trace)          # the input's own velocity step included
    assert o["alarm"] and o["blocked"] == LIM_MINUS and o["lim_vff"] == 0.0
    if predictive:
        assert low <= o["lim_cmd"] <= low + 1.0                       # at the boundary, not early
    else:
        assert low - bound <= o["lim_cmd"] < low                      # seen after the fact, stopped within the bound
    held = o["lim_cmd"]
    for _ in range(20):                                               # the command goes on down: held
        o = d.step(v_lim=-speed)
        assert o["lim_cmd"] == held and o["lim_vff"] == 0.0 and o["blocked"] == LIM_MINUS
    # only lim- is blocked: the reference axis follows its command within the region, passed as it is (ramped
    # at decel to 10 mm/s, down through -10 mm/s and back to rest)
    a_dt = d.lim.decel * DT
    for k in [*range(1, 21), *range(19, -21, -1), *range(-19, 1)]:
        o = d.step(v_ref=k * a_dt)
        assert o["ref_cmd"] == d.ref_cmd and o["lim_cmd"] == held and o["blocked"] == LIM_MINUS
    # back out upward: followed at once (its velocity step governed), released once inside
    d.hold_inputs_at_output()
    trace = [o, d.step(v_lim=speed)]
    assert trace[-1]["lim_cmd"] > held and trace[-1]["lim_vff"] == a_dt
    for _ in range(1000):
        if not trace[-1]["alarm"]:
            break
        trace.append(d.step(v_lim=speed))
    assert_no_velocity_step(d.lim, trace)
    o = trace[-1]
    assert not o["alarm"] and o["blocked"] == 0 and o["lim_cmd"] >= low


# -- the cached region (issue 50): a step inside the region it was in skips the binary search -----------------
class Uncached(AreaLimiter):
    """The limiter judging as before its region was cached: every lookup a binary search (its cache holds an
    empty interval that no position is in). Before the cache existed this is the limiter itself."""

    def _enter(self, r):
        self._reg, self._reg_lo, self._reg_hi, self._reg_min, self._reg_max = r, math.inf, -math.inf, 0.0, 0.0

    def _region(self, ref):
        return find_region(self.ref_max, ref)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(table=tables(), program=moves, predictive=st.booleans(), use_actual=st.booleans())
def test_property_the_cached_region_gives_the_uncached_run_bit_for_bit(table, program, predictive, use_actual):
    """Tours across the regions of a stepped table (and off its end): the limiter with its region cached gives
    every output and every message of one that searches the table at every lookup, to the last bit."""
    start = table[0][0] / 2
    cached = make(table, ref=start, lim=0.0, predictive=predictive, use_actual=use_actual)
    uncached = Uncached.with_table(table, ref_start=start, lim_start=0.0, predictive=predictive,
                                   use_actual=use_actual)
    up = Upstream(start, 0.0, cached.decel)
    o, t, regions = dict(cached.outputs()), 0.0, set()
    for d_ref, d_lim, speed in program:
        up.go(d_ref, d_lim, speed)
        for _ in up.steps(150):
            inputs = up.inputs(o)
            o = dict(cached.step(t, DT, inputs))
            assert uncached.step(t, DT, inputs) == o, f"t = {t:.3f} s"
            regions.add(o["region"])
            t += DT
    assert cached.take_messages() == uncached.take_messages()


def _tour(limiters, up, t, d_ref, d_lim, speed, n):
    """``n`` steps of one move fed to every limiter (the same inputs): the first one's outputs, which the others'
    must equal at every step."""
    up.go(d_ref, d_lim, speed)
    o, seen = dict(limiters[0].outputs()), []
    for _ in up.steps(n):
        inputs = up.inputs(o)
        o = dict(limiters[0].step(t, DT, inputs))
        for other in limiters[1:]:
            assert other.step(t, DT, inputs) == o, f"t = {t:.3f} s"
        seen.append(o["region"])
        t += DT
    return seen


@pytest.mark.parametrize("predictive", [True, False])
def test_crossing_down_into_a_stricter_region_as_uncached(predictive):
    """Down from the grinder's region 3 (X <= 180) into region 2 (X <= 80) while X rises from 0 to 150: the
    predictive governor must take region 2's range as soon as the reference axis's stopping reach enters it (its
    cached region 3 no longer holds the reach), then hold the reference axis at the boundary; the same outputs as
    the limiter searching every step, and the region output 3, then 2 only where it is allowed."""
    cached = make(GRINDER, ref=500.0, lim=0.0, predictive=predictive)
    uncached = Uncached.with_table(GRINDER, ref_start=500.0, lim_start=0.0, predictive=predictive)
    up = Upstream(500.0, 0.0, cached.decel)
    seen = _tour([cached, uncached], up, 0.0, -200.0, 150.0, 100.0, 3000)
    out = cached.outputs()
    if predictive:          # Z held a margin above the boundary, X where it was asked to go: region 2 never entered
        assert set(seen) == {3} and 350.0 < out["ref_cmd"] < 350.0 + cached.margin + 1e-3
        assert out["lim_cmd"] == 150.0 and out["blocked"] == REF_MINUS and out["alarm"]
    else:                   # seen at the monitor tick after the crossing (X 112.56 > 80), both directions stopped
        assert seen.index(2) == 1975 and set(seen[1975:]) == {2} and set(seen[:1975]) == {3}
        assert out["blocked"] == REF_MINUS | LIM_PLUS and out["alarm"]


def test_a_state_restored_in_another_region_steps_as_the_original():
    """A limiter saved in region 3 (it started in region 1) and restored -- from the serialized state (a fresh
    limiter filled with the saved registers) and from an in-memory copy (fmi2GetFMUstate) -- steps as the original
    while all cross back down to region 1; the serialized state carries the registers only (the cached region is
    derived from the table, not saved)."""
    import copy

    from ncfmu.fmi import state

    parameters = {"n_regions": len(GRINDER), "ref_start": 100.0, "lim_start": 0.0, "predictive": True,
                  "use_actual": True}
    for i, (b, lo, hi) in enumerate(GRINDER, start=1):
        parameters[f"region[{i}].ref_max"], parameters[f"region[{i}].lim_min"] = b, lo
        parameters[f"region[{i}].lim_max"] = hi
    limiter = AreaLimiter(**parameters)
    up = Upstream(100.0, 0.0, limiter.decel)
    o, t = dict(limiter.outputs()), 0.0
    up.go(400.0, 0.0, 200.0)
    for _ in up.steps(2200):
        o = dict(limiter.step(t, DT, up.inputs(o)))
        t += DT
    assert o["region"] == 3 and abs(o["ref_cmd"] - 500.0) < 1e-6 and o["blocked"] == 0
    blob = state.dumps("AreaLimiter", AreaLimiter.default_parameters() | parameters,
                       AreaLimiter.default_inputs(), limiter)
    assert b'"_reg' not in blob            # no attribute _reg, _reg_lo, ... saved
    restored, _, _ = state.loads(blob, AreaLimiter, AreaLimiter.from_parameters)
    assert restored is not None
    in_memory = copy.deepcopy(limiter)
    # down across 350 and 200 into region 1, the limited axis up toward region 2's stricter 80 mm (governed)
    seen = _tour([limiter, restored, in_memory], up, t, -380.0, 120.0, 150.0, 3000)
    assert seen[0] == 3 and seen[-1] == 1 and 2 in seen
    assert restored.take_messages() == in_memory.take_messages()
