"""A refused change of parameters changes nothing (plain Python, every model).

``Controller.retune`` applies parameters changed during a run. A value a rule refuses raises ConfigError and
leaves the controller as it was: its state and its next steps bit-identical to a twin that never saw the value.
"""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from twins import loop_inputs, offered_values, same_bits

from ncfmu.catalogue import is_native, models
from ncfmu.controllers.panel import OperatorPanel
from ncfmu.errors import ConfigError
from ncfmu.fmi import state

DT = 1e-3
STEPS = 60


def test_a_refused_repeat_period_keeps_the_old_one_and_presses_nothing():
    """The reported case: repeat_every = 5e-324 is refused; the panel keeps -1 and presses no button."""
    parameters = OperatorPanel.default_parameters() | {"start_at": 0.0, "emergency_at": 0.0}
    panel, twin = OperatorPanel(**parameters), OperatorPanel(**parameters)
    inputs = OperatorPanel.default_inputs()
    for k in range(20):                                   # past the 10 ms pulses
        panel.step(k * DT, DT, inputs)
        twin.step(k * DT, DT, inputs)
    with pytest.raises(ConfigError, match="repeat_every = 5e-324"):
        panel.retune(parameters | {"repeat_every": 5e-324})
    assert panel.repeat_every == -1.0
    out = panel.step(20 * DT, DT, inputs)
    assert not out["start"] and not out["emergency"]
    assert same_bits(out, twin.step(20 * DT, DT, inputs))


def _offers(model: str) -> st.SearchStrategy:
    """Changes of one to three parameters of ``model``, each to a value a host may send, at a step of the run."""
    ports = models()[model].ports("parameter")
    related = tuple(float(p.start) for p in ports if p.type in ("Real", "Integer"))  # type: ignore[arg-type]
    one = st.sampled_from(ports).flatmap(
        lambda p: st.tuples(st.just(p.name), offered_values(p.type, p.start, p.min, p.max, related)))
    return st.tuples(st.integers(0, STEPS - 1), st.lists(one, min_size=1, max_size=3).map(dict))


def _step(logic, k: int, inputs: dict) -> object:
    try:
        return dict(logic.step(k * DT, DT, inputs))
    except Exception as err:                               # both twins must fail alike (none should)
        return repr(err)


# the drives step their loops in sub-steps and rebuild their discretisation at each change taken: slow
@pytest.mark.parametrize("model", [pytest.param(m, marks=pytest.mark.slow) if is_native(cls) else m
                                   for m, cls in models().items()])
@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_a_refused_retune_leaves_the_controller_as_its_twin(model, data):
    cls = models()[model]
    offers = sorted(data.draw(st.lists(_offers(model), min_size=1, max_size=4)), key=lambda o: o[0])
    parameters = cls.default_parameters()
    logic, twin = cls(**parameters), cls(**parameters)
    inputs = cls.default_inputs()
    refused = 0
    for k in range(STEPS):
        for _, change in (o for o in offers if o[0] == k):
            offered = parameters | change
            try:
                logic.retune(offered)
            except ConfigError:
                refused += 1
                assert state.dumps(model, parameters, inputs, logic) == state.dumps(model, parameters, inputs, twin)
                continue
            twin.retune(offered)                           # accepted: the twin takes it too
            parameters = offered
        out = _step(logic, k, inputs)
        assert same_bits(out, _step(twin, k, inputs)), f"step {k} differs after a refused change"
        if isinstance(out, dict):
            loop_inputs(model, k + 1, inputs, out)
    assert state.dumps(model, parameters, inputs, logic) == state.dumps(model, parameters, inputs, twin)

