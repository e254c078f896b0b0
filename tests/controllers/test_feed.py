"""ProgrammableFeed logic against the seed (JP S60-43522): parser, cycles, wear compensation, emergency."""

import math

import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from ncfmu.controllers.feed import ProgramError, ProgrammableFeed, parse_program
from ncfmu.errors import ConfigError
from ncfmu.servo.axis import ServoAxis
from ncfmu.systems import parameters

#: The grinder_feed settings and the seed's program, from the system definition.
GRINDER_FEED = parameters("grinder_feed", "feed")

DT = 1e-3
BAND = 0.005


class Grinder:
    """Feed logic + a ServoAxis (the same classes the FMUs run), stepped in plain Python."""

    def __init__(self, mfin_delay=0.5, **changes):
        self.feed = ProgrammableFeed(**{**GRINDER_FEED, **changes})
        self.axis = ServoAxis(pos_start=self.feed.x_origin)
        self.t = 0.0
        self.inputs = {"start": False, "wear_start": False, "emergency": False, "mfin": False, "alarm_in": False,
                       "x_pos": self.feed.x_origin, "y_pos": self.feed.y_origin, "x_in_position": True,
                       "feed_hold": False, "feed_override": 1.0,
                       "y_in_position": True}
        self.mfin_delay, self.m_for = mfin_delay, 0.0
        self.log = []

    def step(self, **buttons):
        self.inputs.update({"start": False, "wear_start": False, "emergency": False})
        self.inputs.update(buttons)
        o = dict(self.feed.step(self.t, DT, self.inputs))
        a = self.axis.step(self.t, DT, {"pos_cmd": o["x_cmd"], "vel_ff": o["x_vff"], "enable": True})
        self.inputs["x_pos"], self.inputs["x_in_position"] = a["pos"], a["in_position"]
        self.m_for = self.m_for + DT if o["m_active"] else 0.0
        self.inputs["mfin"] = bool(o["m_active"]) and self.m_for >= self.mfin_delay
        self.t += DT
        o["x"] = a["pos"]
        o["t"] = self.t
        self.log.append(o)
        return o

    def run_until(self, cond, limit=60.0):
        while self.t < limit:
            o = self.step()
            if cond(o):
                return o
        raise AssertionError("condition not reached")

    def finish(self):
        self.step()
        return self.run_until(lambda o: not o["run"] and not o["emergency_active"] and not o["busy"])


def test_seed_program_parses():
    p = parse_program(str(GRINDER_FEED["program"]))
    assert sorted(p) == [0, 1, 2, 3, 4, 5, 41, 42, 43, 44]
    assert (p[0].kind, p[0].axis, p[0].sign, p[0].d, p[0].f) == ("feed", "x", 1, 3, 7)
    assert p[41].kind == "return" and p[43].wear and p[3].kind == "dwell"


@pytest.mark.parametrize("text, where, reason", [
    ("M0: X+D3F7\nM1: Q7\nM2: END", "line 2", "unknown word 'Q7'"),
    ("M0: X+D3\nM1: END", "line 1", "missing rate"),
    ("M0: X+D3F7\nM0: END", "line 2", "address M0 given twice"),
    ("M0: X+D3F7\nM1: X+D9F7", "line 2", "settings are numbered 1..7"),
    ("M0: XD3F7", "line 1", "missing direction"),
    ("M0: X+D3F7S2", "line 1", "S2 is not supported"),
    ("X+D3F7", "line 1", "expected 'M<address>: <word>'"),
])
def test_parser_errors_name_line_column_and_reason(text, where, reason):
    with pytest.raises(ProgramError) as err:
        parse_program(text)
    assert where in str(err.value) and reason in str(err.value) and "column" in str(err.value)


@pytest.mark.parametrize("changes, variable, rule", [
    ({"program": "M0: X+D3F7; M41: XF7S1; M42: END; M43: END"}, "program", "runs past M0 without END"),
    ({"program": "M0: END; M41: END"}, "wear_address", "entry address M43 is missing"),
    ({"F7": 0.0}, "F7", "must be > 0: used by M0: X+D3F7"),
    ({"D3": 0.0}, "D3", "is not set (0): used by M0"),
    ({"T1": -1.0}, "T1", "must be >= 0"),
    ({"D2": math.nan}, "D2", "must be finite"),
])
def test_bad_settings_refused_naming_the_item(changes, variable, rule):
    with pytest.raises(ConfigError) as err:
        ProgrammableFeed(**{**GRINDER_FEED, **changes})
    assert err.value.variable == variable and rule in str(err.value)


def phase_of(o):
    return o["pc"]


@pytest.mark.slow
def test_normal_cycle_rates_dwell_and_return():
    g = Grinder()
    g.step(start=True)
    o = g.finish()
    log = g.log
    by_pc = {pc: [r for r in log if r["pc"] == pc] for pc in range(6)}
    # rapid approach ends at 4.0, rough to 4.2, fine to 4.3
    assert by_pc[1][0]["x"] == pytest.approx(4.0, abs=BAND)
    assert by_pc[2][0]["x"] == pytest.approx(4.2, abs=BAND)
    assert by_pc[3][0]["x"] == pytest.approx(4.3, abs=BAND)

    def rate(rows):
        mid = rows[len(rows) // 4: 3 * len(rows) // 4]
        return (mid[-1]["x"] - mid[0]["x"]) / (mid[-1]["t"] - mid[0]["t"])
    assert rate(by_pc[1]) == pytest.approx(0.02, rel=0.02)
    assert rate(by_pc[2]) == pytest.approx(0.005, rel=0.02)
    dwell = by_pc[3]
    assert dwell[-1]["t"] - dwell[0]["t"] == pytest.approx(1.5, abs=2 * DT)
    assert max(r["x"] for r in dwell) - min(r["x"] for r in dwell) < 1e-4       # spark-out: no motion
    assert o["x"] == pytest.approx(0.0, abs=BAND) and o["return_counter_x"] == pytest.approx(0.0, abs=1e-12)


@pytest.mark.slow
def test_wear_compensation_moves_the_origin():
    g = Grinder()
    g.step(wear_start=True)
    o = g.finish()
    assert o["x"] == pytest.approx(0.02, abs=BAND) and o["return_counter_x"] == 0.0   # S4: not counted
    g.step(start=True)
    o = g.finish()
    assert max(r["x"] for r in g.log) == pytest.approx(4.32, abs=BAND)
    assert o["x"] == pytest.approx(0.02, abs=BAND) and o["return_counter_x"] == pytest.approx(0.0, abs=1e-9)


def test_m_word_waits_for_mfin_and_emb_aborts_the_wait():
    program = "M0: X+D3F7; M1: M2; M2: X-D3F7; M3: END; M41: XF7S1; M42: END; M43: X+D1F2S4; M44: END"
    g = Grinder(program=program, mfin_delay=0.5)
    g.step(start=True)
    g.run_until(lambda o: o["m_active"] == 2)
    t0 = g.t
    o = g.run_until(lambda o: o["m_active"] == 0)
    assert g.t - t0 == pytest.approx(0.5, abs=3 * DT)
    g.finish()
    g2 = Grinder(program=program, mfin_delay=100.0)
    g2.step(start=True)
    g2.run_until(lambda o: o["m_active"] == 2)
    o = g2.step(emergency=True)
    assert o["m_active"] == 0 and o["emergency_active"]
    o = g2.finish()
    assert o["x"] == pytest.approx(0.0, abs=BAND)


PHASES = {  # (cycle, program counter) of every phase of the seed's program, and an M wait
    "approach": ("start", 0), "rough": ("start", 1), "fine": ("start", 2), "dwell": ("start", 3),
    "return": ("start", 4), "wear": ("wear_start", 43), "m_wait": ("start", 1),
}
#: The seed's program with an auxiliary function (M2, answered after 0.5 s) after the approach.
M_PROGRAM = "M0: X+D3F7; M1: M2; M2: X+D2F1; M3: X-D4F7; M4: END; M41: XF7S1; M42: END; M43: X+D1F2S4; M44: END"


def grinder_for(phase):
    return Grinder(program=M_PROGRAM, D4=4.2) if phase == "m_wait" else Grinder()


_DURATIONS: dict = {}


def phase_window(phase):
    """(entry time, duration) of ``phase`` in its cycle started at t = 0."""
    button, pc = PHASES[phase]
    key = (button, phase == "m_wait")
    if key not in _DURATIONS:
        g = grinder_for(phase)
        g.step(**{button: True})
        g.finish()
        spans = {}
        for r in g.log:
            spans.setdefault(r["pc"], [r["t"], r["t"]])[1] = r["t"]
        _DURATIONS[key] = {k: (a, b - a) for k, (a, b) in spans.items()}
    return _DURATIONS[key][pc]


def _every_phase(test):
    for phase in sorted(PHASES):
        test = example(phase=phase, fraction=0.5, worn=False)(test)
    return test


@pytest.mark.slow
@settings(max_examples=20, deadline=None)
@given(phase=st.sampled_from(sorted(PHASES)), fraction=st.floats(0.0, 1.0), worn=st.booleans())
@_every_phase
def test_property_emergency_at_any_instant_returns_to_the_feed_origin(phase, fraction, worn):
    g = grinder_for(phase)
    if worn and phase != "wear":
        g.step(wear_start=True)
        g.finish()
    button, pc = PHASES[phase]
    entry, duration = phase_window(phase)
    t0 = g.t
    g.step(**{button: True})
    while g.t - t0 < entry + fraction * duration:
        g.step()
    if phase == "m_wait":
        # struck while waiting for MFIN (the strobe rises the step after the M word is read)
        assert g.log[-1]["pc"] == 1 and (g.log[-1]["m_active"] == 2 or fraction < 0.01 or fraction > 0.99)
    g.step(emergency=True)
    returning = g.run_until(lambda o: o["pc"] == 41 and o["emergency_active"])
    # the feed origin as the seed's return counter defines it: here minus what was counted
    origin = returning["x_cmd"] - returning["return_counter_x"]
    if phase != "wear":
        assert origin == pytest.approx(0.02 if worn else 0.0, abs=1e-9)
    else:   # the part of the S4 move done before EMB is not counted: the origin moved with it
        assert 0.0 <= origin <= 0.02 + 1e-9
    o = g.finish()
    assert o["x"] == pytest.approx(origin, abs=BAND)
    assert o["return_counter_x"] == pytest.approx(0.0, abs=1e-9)
    after = [g.step() for _ in range(200)]                  # and stops there
    assert len({r["x_cmd"] for r in after}) == 1
    assert all(abs(r["x"] - origin) <= BAND for r in after)
    # never a velocity jump to the servo
    for a, b in zip(g.log, g.log[1:]):
        assert abs(b["x_vff"] - a["x_vff"]) <= 500.0 * DT * 1.000001


def test_a_program_address_in_other_digits_is_refused():
    """``M٥:`` was read as address M5 (the regex's \\d takes any Unicode digit): addresses are ASCII digits."""
    with pytest.raises(ProgramError, match=r"line 1, column 1: expected 'M<address>: <word>'"):
        ProgrammableFeed(**(ProgrammableFeed.default_parameters() | {"program": "M\u0665: X+D3F7; M6: END"}))
