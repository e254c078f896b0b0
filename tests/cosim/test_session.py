"""Sessions: a run stepped from outside (forced inputs, released, tunable parameters set, reset), its write log
replayed exactly through an input CSV, in the C loop and in the Python loop; branch logs stay in their branch."""

from pathlib import Path

import numpy as np
import pytest

from ncfmu.cosim.master import InputTable, Master, write_input_csv
from ncfmu.cosim.slave import Variable
from ncfmu.cosim.ssp import Component, Connection, System
from ncfmu.errors import ConfigError, SimulationError, SystemDefinitionError
from ncfmu.project import OpenSystem, simulate_branches

ROOT = Path(__file__).resolve().parents[2]
LATHE = ROOT / "ssp" / "lathe_taper.ssp"


def assert_identical(a, b):
    assert a.data.dtype == b.data.dtype and len(a.data) == len(b.data)
    for name in a.data.dtype.names:
        assert np.array_equal(a.data[name], b.data[name]), name


def served(archive, native):
    """A session on the lathe: the operator forces the sequencer's override (a connected input), presses the
    feed hold by forcing it and lets go, turns the panel's dial (a tunable parameter), and raises an M word on
    the panel's m_active (an input no connection drives), then releases everything."""
    with OpenSystem(archive) as opened:
        opened.master.native = native
        session = opened.master.open_session(stop_time=4.0, keep=True)
        assert session.time == 0.0 and session.step_size == 0.001 and session.stop_time == 4.0
        session.advance(500)
        session.force("seq.feed_override", 0.5)
        session.advance(300)
        assert session.value("seq.feed_override") == 0.5          # what the FMU was given at the last step
        session.force("panel.m_active", 3)
        session.advance(200)
        session.set_parameter("panel.override", 1.2)
        session.force("seq.feed_hold", True)
        assert session.forced() == {"seq.feed_override": 0.5, "panel.m_active": 3, "seq.feed_hold": True}
        session.advance(500)
        assert session.value("panel.override") == 1.2 and session.value("panel.feed_override") == 1.2
        session.release("seq.feed_hold")
        session.release("panel.m_active")
        session.advance(700)
        session.release("seq.feed_override")
        assert session.forced() == {} and session.value("panel.m_active") == 0
        session.advance(4000 - 2200)
        assert session.time == pytest.approx(4.0)
        result = session.close()
        writes = list(session.writes)
        assert opened.master.loop_used == ("c" if native else "python")
    return result, writes


@pytest.mark.parametrize("native", [True, False])
def test_a_served_session_replays_exactly_from_its_write_log(project, tmp_path, native):
    result, writes = served(LATHE, native)
    assert [(round(t, 9), name, value) for t, name, value in writes] == [
        (0.5, "seq.feed_override", 0.5), (0.8, "panel.m_active", 3), (1.0, "panel.override", 1.2),
        (1.0, "seq.feed_hold", True), (1.5, "seq.feed_hold", None), (1.5, "panel.m_active", None),
        (2.2, "seq.feed_override", None)]
    t = result.time
    assert result["panel.mfin"][(t > 0.8) & (t < 1.5)].any()                 # the M word was answered
    with OpenSystem(LATHE) as opened:
        plain = opened.run(stop_time=4.0)
    assert not np.array_equal(plain["x_axis.pos"], result["x_axis.pos"])    # the writes changed the run
    # the replay: the log as an input CSV, run straight through
    csv = write_input_csv(tmp_path / "session.csv", writes)
    assert csv.read_text().splitlines()[0] == ('"time","seq.feed_override","panel.m_active","panel.override",'
                                               '"seq.feed_hold"')
    with OpenSystem(LATHE) as opened:
        opened.master.native = native
        replay = opened.run(stop_time=4.0, inputs=InputTable.from_csv(csv))
    assert_identical(result, replay)
    assert result.parameters["panel"]["override"] == replay.parameters["panel"]["override"] == 1.2


def test_the_c_loop_and_the_python_loop_serve_the_same_session(project):
    c, _ = served(LATHE, True)
    python, _ = served(LATHE, False)
    assert_identical(c, python)


def test_a_forced_hold_stops_the_feed_until_released(project):
    """Forcing a connected input overrides its connection from the next step; releasing hands it back."""
    with OpenSystem(LATHE) as opened:
        session = opened.master.open_session(stop_time=6.0, keep=True)
        session.advance(3000)                         # the cycle is feeding by now
        session.force("seq.feed_hold", True)
        session.advance(1500)
        held_at = session.value("z_axis.pos")
        session.advance(500)
        assert session.value("z_axis.pos") == pytest.approx(held_at, abs=1e-6)   # stopped, not crawling
        assert session.value("seq.feed_hold") is True and session.value("panel.feed_hold") is False
        session.release("seq.feed_hold")
        session.advance(1000)
        assert abs(session.value("z_axis.pos") - held_at) > 0.1                  # feeding again
        session.close()


def test_writes_are_checked_before_anything_changes(project):
    with OpenSystem(LATHE) as opened:
        session = opened.master.open_session(stop_time=1.0)
        session.advance(10)
        with pytest.raises(ConfigError, match=r"panel.override = 2.0: must be in \[0, 1.5\]"):
            session.set_parameter("panel.override", 2.0)
        with pytest.raises(ConfigError, match=r"panel.pulse = 0.5: not writable during a run \(a fixed parameter"):
            session.set_parameter("panel.pulse", 0.5)
        with pytest.raises(ConfigError, match=r"x_axis.pos = 1.0: not an input \(a output\)|not an input"):
            session.force("x_axis.pos", 1.0)
        with pytest.raises(ConfigError, match=r"seq.feed_hold = 2: must be true or false"):
            session.force("seq.feed_hold", 2)
        with pytest.raises(ConfigError, match=r"seq.feed_override = nan: must be finite"):
            session.force("seq.feed_override", float("nan"))
        with pytest.raises(ConfigError, match=r"panel.m_active = 2.5: must be a whole number"):
            session.force("panel.m_active", 2.5)
        assert session.forced() == {} and session.writes == []
        assert session.value("panel.override") == opened.system.components[0].parameters.get("override", 1.0)
        session.close()


def test_reset_starts_again_and_runs_the_same(project):
    with OpenSystem(LATHE) as opened:
        session = opened.master.open_session(stop_time=2.0, keep=True)
        session.advance(1000)
        session.force("seq.feed_override", 0.3)
        session.advance(1000)
        first_x = session.value("x_axis.pos")
        session.reset()
        assert session.time == 0.0 and session.forced() == {} and session.writes == []
        session.advance(1000)
        session.force("seq.feed_override", 0.3)
        session.advance(1000)
        assert session.value("x_axis.pos") == first_x
        again = session.close()
        with OpenSystem(LATHE) as other:
            straight = other.master.open_session(stop_time=2.0, keep=True)
            straight.advance(1000)
            straight.force("seq.feed_override", 0.3)
            straight.advance(1000)
            assert_identical(straight.close(), again)


def test_a_session_without_a_stop_time_runs_until_closed(project, tmp_path):
    import math

    from ncfmu.cosim.record import CsvSink
    sink = CsvSink(tmp_path / "live.csv")
    with OpenSystem(LATHE) as opened:
        with pytest.raises(SystemDefinitionError, match="keeps nothing in memory"):
            opened.master.open_session(stop_time=math.inf, keep=True)
        for s in opened.slaves:
            s.reset()
        session = opened.master.open_session(stop_time=math.inf, sinks=[sink], record=["x_axis.pos"],
                                             output_interval=0.01)
        session.advance(2345)
        result = session.close()
    assert result.end_time == pytest.approx(2.345) and len(result.data) == 0
    lines = (tmp_path / "live.csv").read_text().splitlines()
    assert lines[0] == '"time","x_axis.pos"' and len(lines) == 1 + 235      # 0, 0.01, ..., 2.34
    assert lines[-1].startswith("2.34")


def test_input_csv_cells_empty_release_and_parameters(project, tmp_path):
    csv = tmp_path / "in.csv"
    csv.write_text('"time","seq.feed_override","panel.override","panel.m_active"\n'
                   "0.0,,,\n0.5,0.25,,\n1.0,,1.4,5\n1.5,release,,release\n")
    table = InputTable.from_csv(csv)
    assert table.columns["seq.feed_override"][1] == 0.25
    with OpenSystem(LATHE) as opened:
        r = opened.run(stop_time=2.0, inputs=table)
    t = r.time
    assert np.all(r["panel.feed_override"][(t > 1.001) & (t <= 2.0)] == 1.4)   # the dial turned at 1 s
    assert r.parameters["panel"]["override"] == 1.4


@pytest.mark.parametrize("text, says", [
    ('time,panel.override\n0,release\n', "a parameter cannot be released"),
    ('time,panel.pulse\n0,0.5\n', "a fixed parameter: only inputs and tunable parameters change"),
    ('time,x_axis.pos\n0,1\n', "is an output"),
    ('time,seq.feed_override\n0,maybe\n', r"not a number, empty \(no change\) or 'release'"),
    ('time,panel.override\n0,7\n', r"panel.override = 7.0: must be in \[0, 1.5\]"),
])
def test_bad_input_csv_cells_are_named(project, tmp_path, text, says):
    csv = tmp_path / "in.csv"
    csv.write_text(text)
    with OpenSystem(LATHE) as opened, pytest.raises((SystemDefinitionError, ConfigError), match=says):
        opened.run(stop_time=0.1, inputs=InputTable.from_csv(csv))


class Refusing:
    """A fake slave whose tunable parameter refuses negative values, as an FMU does (fmi2Error + a log line)."""

    def __init__(self, name):
        self.name = name
        self.variables = {"u": Variable("u", "Real", "input", 0), "y": Variable("y", "Real", "output", 1),
                          "gain": Variable("gain", "Real", "parameter", 2, variability="tunable", start=1.0)}
        self.gain, self.u, self.initialised = 1.0, 0.0, False
        self.messages: list[tuple[str, str]] = []

    def set_start(self, name, value):
        if name == "gain" and value < 0:
            raise SimulationError(f"{self.name}: setting gain returned fmi2Error: gain = {value}: must be >= 0")
        setattr(self, name, value)

    def initialize(self, t0, stop):
        self.initialised = True

    def bind(self, kind, inputs, input_vrs, outputs, output_vrs):
        if kind == "Real":
            self.inbuf, self.outbuf = inputs, outputs

    def write_inputs(self):
        self.u = float(self.inbuf[0]) if len(self.inbuf) else self.u

    def do_step(self, t, h):
        self.y = self.gain * (self.u + 1.0)

    def read_outputs(self):
        self.outbuf[0] = getattr(self, "y", 0.0)

    def terminate(self):
        pass


def test_the_fmus_refusal_of_a_parameter_is_a_config_error_and_the_old_value_stays():
    a, b = Refusing("a"), Refusing("b")
    system = System("pair", [Component("a", "R"), Component("b", "R")], [Connection("a", "y", "b", "u")],
                    stop_time=1.0)
    session = Master(system, [a, b]).open_session(stop_time=0.01, keep=True)
    session.advance(2)
    with pytest.raises(ConfigError, match=r"a.gain = -2.0: refused by a: .*gain = -2.0: must be >= 0"):
        session.set_parameter("a.gain", -2.0)
    assert session.value("a.gain") == 1.0 and a.gain == 1.0 and session.writes == []
    session.set_parameter("a.gain", 3.0)
    session.force("b.u", 10.0)
    session.advance(1)
    assert session.value("a.y") == 3.0 and session.value("b.y") == 11.0
    r = session.close()
    assert list(r["b.y"]) == [0.0, 2.0, 2.0, 11.0]


def emb_times(result):
    """The times of the feed's EMB warnings (``feed: t = 2.9990 s: EMB: ...``)."""
    import re
    return [float(re.search(r"t = ([0-9.]+) s", text).group(1)) for level, text in result.messages["feed"]
            if "EMB" in text and level == "warning"]


@pytest.mark.slow
def test_branch_logs_hold_their_own_branch_only(project):
    """EMB at 12, 21, 31 s from one state at 10 s: each branch says its own EMB warning, once."""
    results = simulate_branches("grinder_feed", 10.0, [{"panel.emergency_at": t} for t in (12.0, 21.0, 31.0)],
                                stop_time=33.0)
    for strike, r in zip((12.0, 21.0, 31.0), results):
        assert emb_times(r) == [pytest.approx(strike - 0.001)]      # said in the step that ends at the strike


def test_branch_logs_do_not_leak_into_the_next_branch(project):
    """A short version of the issue's command: EMB at 3 and 4.5 s from one state at 2 s."""
    results = simulate_branches("grinder_feed", 2.0, [{"panel.emergency_at": 3.0}, {"panel.emergency_at": 4.5}],
                                stop_time=6.0)
    assert [emb_times(r) for r in results] == [[pytest.approx(2.999)], [pytest.approx(4.499)]]
