"""OperatorPanel: the push buttons, the feed hold and the dial exactly at their times, also after long idle
stretches (an idle step publishes only MFIN, issue 50), after a retune and after a state restore."""

from __future__ import annotations

import copy

import pytest

from ncfmu.controllers import OperatorPanel
from ncfmu.fmi import state

DT = 1e-3
BUTTONS = ("start", "wear_start", "emergency", "feed_hold", "feed_override")


def run(panel, n, inputs=None, t0=0.0):
    """``n`` steps of 1 ms: the outputs after each."""
    inputs = inputs or OperatorPanel.default_inputs()
    return [dict(panel.step(t0 + k * DT, DT, inputs)) for k in range(n)]


def on_steps(trace, name):
    """The steps (1-based: step k ends at k ms) at which ``name`` is true."""
    return [k for k, o in enumerate(trace, start=1) if o[name]]


@pytest.mark.parametrize("repeat_every", [-1.0, 1.5])
def test_buttons_exact_at_their_times_after_idling(repeat_every):
    """Each push is a pulse of exactly 10 steps from its own millisecond, the hold from 0.7 s to 0.9 s, after
    idle stretches of up to 1 s between them; repeated every 1.5 s when so set."""
    panel = OperatorPanel(start_at=0.1, restart_at=1.234, wear_start_at=0.5, emergency_at=1.4, hold_at=0.7,
                          release_at=0.9, pulse=0.01, override=0.8, repeat_every=repeat_every)
    trace = run(panel, 3200)
    period = [0, 1500, 3000] if repeat_every > 0 else [0]
    every = lambda first, n: [p + k for p in period for k in range(first, first + n) if p + k <= 3200]  # noqa: E731
    assert on_steps(trace, "start") == sorted(every(100, 10) + every(1234, 10))
    assert on_steps(trace, "wear_start") == every(500, 10)
    assert on_steps(trace, "emergency") == every(1400, 10)
    assert on_steps(trace, "feed_hold") == every(700, 200)
    assert {o["feed_override"] for o in trace} == {0.8}


def test_a_retune_while_idle_acts_at_the_next_step():
    """The dial and the hold time changed during a quiet stretch: the dial at the next step, the hold at its new
    time to the millisecond."""
    panel = OperatorPanel(start_at=0.1)
    run(panel, 300)
    panel.retune(OperatorPanel.default_parameters() | {"start_at": 0.1, "override": 0.5, "hold_at": 0.4})
    trace = run(panel, 200, t0=0.3)
    assert trace[0]["feed_override"] == 0.5
    assert on_steps(trace, "feed_hold") == list(range(100, 201))      # from 0.4 s (step 400) on
    assert not any(o["start"] for o in trace)


def test_mfin_after_its_delay_while_the_buttons_are_idle():
    panel = OperatorPanel(start_at=-1.0, mfin_delay=0.05)
    trace = run(panel, 100, {"m_active": 3}) + run(panel, 5, {"m_active": 0})
    assert on_steps(trace, "mfin") == list(range(50, 101))


@pytest.mark.parametrize("how", ["serialized", "in memory"])
def test_a_state_restored_across_a_period_wrap_publishes_what_the_original_does(how):
    """Saved while the hold is on (0.999 s into a 1 s period, hold from 0.5 s), restored and stepped into the next
    period, where the hold is off until 0.5 s again: the restored panel publishes what the original does, step for
    step -- the state holds no quiet interval, the restored panel judges its buttons afresh."""
    parameters = OperatorPanel.default_parameters() | {"start_at": 0.1, "hold_at": 0.5, "repeat_every": 1.0}
    panel = OperatorPanel.from_parameters(parameters)
    inputs = OperatorPanel.default_inputs()
    assert run(panel, 999)[-1]["feed_hold"]
    if how == "serialized":
        blob = state.dumps("OperatorPanel", parameters, inputs, panel)
        assert b'"_quiet' not in blob and b'"_events' not in blob
        restored, _, _ = state.loads(blob, OperatorPanel, OperatorPanel.from_parameters)
    else:
        restored = copy.deepcopy(panel)
    original, again = run(panel, 700, t0=0.999), run(restored, 700, t0=0.999)
    assert [{k: o[k] for k in BUTTONS} for o in again] == [{k: o[k] for k in BUTTONS} for o in original]
    held = on_steps(original, "feed_hold")
    assert held[0] == 1 or held[0] > 400      # the wrap ends the hold (at step 1 or 2, by the clock's rounding)
    assert not original[100]["feed_hold"] and original[-1]["feed_hold"] and original[101]["start"]
