"""What a controller publishes stays its state's own while the step skips work it need not redo.

The sequencer and the limiter write their status outputs (sub-cycle, pass, block, flags; alarm, region, blocked)
into ``out`` only when the status changed, the cycle controllers read the positions a step judged once, and the
position guard keeps its last positions in place. None of that may let a restored state publish what its
registers do not say, nor leave a step's reading behind it.
"""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from ncfmu.controllers import CutSequencer
from ncfmu.controllers.base import POSITION_LIMIT, SPEED_LIMIT, PositionGuard
from ncfmu.controllers.limiter import AreaLimiter
from ncfmu.fmi import state

DT = 1e-3


def at_rest(cls):
    """A fresh controller stepped three times with its default inputs: at rest, where it started."""
    logic = cls()
    for k in range(3):
        logic.step(k * DT, DT, cls.default_inputs())
    return logic


@pytest.mark.parametrize("cls, output, value", [
    (CutSequencer, "pass_no", 7),
    (CutSequencer, "busy", True),
    (CutSequencer, "tool", 3),
    (AreaLimiter, "region", 2),
    (AreaLimiter, "alarm", True),
])
def test_a_state_publishing_a_status_its_registers_do_not_give_is_refused(cls, output, value):
    """A state whose ``_outputs`` says another status than its registers is refused, though the status the registers
    give is the one a fresh controller publishes (the cache of what was written describes the fresh controller's
    dict, not the restored one, so the check publishes the restored registers in full)."""
    logic = at_rest(cls)
    assert logic.outputs()[output] != value
    blob_ok = state.dumps(cls.MODEL_NAME, cls.default_parameters(), cls.default_inputs(), logic)
    assert state.loads(blob_ok, cls, cls.from_parameters)[0] is not None
    logic.outputs()[output] = value
    blob = state.dumps(cls.MODEL_NAME, cls.default_parameters(), cls.default_inputs(), logic)
    with pytest.raises(state.StateError, match="not what the state publishes"):
        state.loads(blob, cls, cls.from_parameters)


def test_a_restored_status_is_published_at_the_first_step():
    """A sequencer restored from a running state (pass 1 of block 1) into one at rest publishes the restored status
    at its first step, as the original does."""
    running = CutSequencer()
    inputs = dict(CutSequencer.default_inputs(), start=True)
    out = running.step(0.0, DT, inputs)
    inputs["start"] = False
    for k in range(1, 400):                    # the axes follow the command exactly
        inputs["x_pos"], inputs["z_pos"] = out["x_cmd"], out["z_cmd"]
        out = running.step(k * DT, DT, inputs)
    assert out["busy"] and out["pass_no"] >= 1
    blob = state.dumps("CutSequencer", CutSequencer.default_parameters(), inputs, running)
    restored, _, _ = state.loads(blob, CutSequencer, CutSequencer.from_parameters)
    inputs["x_pos"], inputs["z_pos"] = out["x_cmd"], out["z_cmd"]
    again, original = dict(restored.step(0.4, DT, inputs)), dict(running.step(0.4, DT, inputs))
    assert again == original and again["busy"] and again["pass_no"] == out["pass_no"]


def test_the_guard_keeps_its_last_positions_when_an_input_is_absurd():
    """An absurd input leaves the positions of the last sane step as they were: the next step's jump is judged
    against them, not against a position of the absurd step."""
    guard = PositionGuard(("x_pos", "z_pos"))
    assert guard.check({"x_pos": 1.0, "z_pos": 2.0}, DT) is None
    assert guard.check({"x_pos": 1.5, "z_pos": math.nan}, DT) == "input z_pos = nan: must be finite"
    assert guard.last == [1.0, 2.0]
    # 1.0 -> 3.5 in one step is 2500 mm/s: a jump against the last sane step (1.5 -> 3.5 would be 2000, allowed)
    assert guard.check({"x_pos": 3.5, "z_pos": 2.0}, DT) == (
        "input x_pos jumped 1.0 -> 3.5 in one step of 0.001 s: faster than 2000 mm/s, no axis moves so")
    assert guard.last == [3.5, 2.0]


def test_between_steps_the_actual_positions_are_read_from_the_inputs():
    """Within a step the cycle controller reads the positions it judged; after the step, :meth:`actual` reads the
    inputs it is given."""
    seq = CutSequencer()
    inputs = CutSequencer.default_inputs()
    seq.step(0.0, DT, inputs)
    assert seq.actual({"x_pos": 5.0, "z_pos": 6.0}) == [5.0, 6.0]


@pytest.mark.parametrize("names, last, why", [
    (("z_pos", "x_pos"), [0.0, 10.0], r"not the position inputs \('x_pos', 'z_pos'\)"),
    (("x_pos", "x_pos"), [10.0, 10.0], r"judges an input twice"),
])
def test_a_state_whose_guard_judges_other_inputs_than_the_axes_is_refused(names, last, why):
    """Within a step the actual positions are those the position guard judged: a state whose guard judges the axes
    in another order (Z read as X) or one axis twice (Z not judged at all) is refused. Restored, the swapped one
    makes the sequencer at rest (X 10, Z 0 mm, standing at its command) see X at 0 mm: an excess-following-error
    alarm of 10 mm at its first step."""
    logic = at_rest(CutSequencer)
    inputs = CutSequencer.default_inputs()
    logic.positions.names, logic.positions.last = names, last
    blob = state.dumps("CutSequencer", CutSequencer.default_parameters(), inputs, logic)
    with pytest.raises(state.StateError, match=r"positions\.names = .*" + why):
        state.loads(blob, CutSequencer, CutSequencer.from_parameters)


POSITION = st.one_of(st.floats(-2.0, 2.0), st.floats(-2.0, 2.0).map(lambda x: x * 1e4), st.integers(-2, 2),
                     st.booleans(), st.sampled_from([math.nan, math.inf, -math.inf, 1e300]))


@given(st.lists(st.tuples(POSITION, POSITION), min_size=1, max_size=6))
def test_the_guard_judges_each_step_against_the_last_sane_one(steps):
    """Judged in place, the guard says what its rules say: a position not finite or beyond any machine is absurd
    (the positions of the last sane step kept), else a position more than SPEED_LIMIT * dt from the last sane step's
    is a jump (the first such axis named); the sane step's positions, as floats, are the next step's last."""
    guard = PositionGuard(("x_pos", "z_pos"))
    last: list[float] | None = None
    for x, z in steps:
        said = guard.check({"x_pos": x, "z_pos": z}, DT)
        absurd = [n for n, v in (("x_pos", x), ("z_pos", z)) if not (math.isfinite(v) and abs(v) <= POSITION_LIMIT)]
        if absurd:
            assert said is not None and said.startswith(f"input {absurd[0]} = {(x, z)[absurd[0] == 'z_pos']!r}: ")
            assert guard.last == last
            continue
        now = [float(x), float(z)]
        jumped = [i for i in (0, 1) if last is not None and abs(now[i] - last[i]) > SPEED_LIMIT * DT + 1e-9]
        if jumped:
            i = jumped[0]
            assert said == (f"input {('x_pos', 'z_pos')[i]} jumped {last[i]!r} -> {now[i]!r} in one step of 0.001 "
                            f"s: faster than {SPEED_LIMIT:g} mm/s, no axis moves so")
        else:
            assert said is None
        assert guard.last == now and all(type(v) is float for v in guard.last)
        last = now


def test_a_state_whose_limiter_guard_judges_one_input_twice_is_refused():
    """The limiter's feedback guard judges ref_pos and lim_pos: a state whose guard judges ref_pos twice (lim_pos not
    judged at all) is refused."""
    logic = at_rest(AreaLimiter)
    logic._feedback.names = ("ref_pos", "ref_pos")
    blob = state.dumps("AreaLimiter", AreaLimiter.default_parameters(), AreaLimiter.default_inputs(), logic)
    with pytest.raises(state.StateError, match=r"_feedback\.names = \('ref_pos', 'ref_pos'\): .*twice"):
        state.loads(blob, AreaLimiter, AreaLimiter.from_parameters)
