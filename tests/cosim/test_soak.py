"""The soak scenario: the panel repeats its button schedule (``repeat_every``), so one grinder run grinds part
after part for hours with wear compensation between them (bench/soak.py, README "Long runs")."""

import numpy as np
import pytest

from ncfmu.controllers.panel import OperatorPanel
from ncfmu.errors import ConfigError

SOAK = {"panel.repeat_every": 80.0, "panel.wear_start_at": 0.1, "panel.start_at": 5.0, "panel.restart_at": 45.0}


def rising_edges(panel, name, seconds, dt=0.001):
    edges, before = [], False
    for k in range(int(round(seconds / dt))):
        now = panel.step(k * dt, dt, {"m_active": 0})[name]
        if now and not before:
            edges.append(round((k + 1) * dt, 6))
        before = now
    return edges


def test_the_button_schedule_repeats_every_period():
    panel = OperatorPanel(repeat_every=80.0, wear_start_at=0.1, start_at=5.0, restart_at=45.0)
    panel.reset()
    assert rising_edges(panel, "start", 250.0) == [5.0, 45.0, 85.0, 125.0, 165.0, 205.0, 245.0]
    panel.reset()
    assert rising_edges(panel, "wear_start", 250.0) == [0.1, 80.1, 160.1, 240.1]


def test_without_a_period_every_button_is_pressed_once():
    panel = OperatorPanel(start_at=5.0)
    panel.reset()
    assert rising_edges(panel, "start", 100.0) == [5.0]


@pytest.mark.parametrize("period", [0.0, 0.005])
def test_a_period_not_longer_than_a_pulse_is_refused(period):
    with pytest.raises(ConfigError, match=r"repeat_every = .*: must be negative \(once\) or longer than the pulse"):
        OperatorPanel(repeat_every=period)


@pytest.mark.slow
def test_the_grinder_grinds_part_after_part_with_wear_compensation(project):
    """Three periods: six parts, each ground 0.02 mm deeper than the one before the last wear compensation
    (START2 moves the feed origin by the wear amount), the wheel back at the origin between parts."""
    from ncfmu.project import simulate
    r = simulate("grinder_feed", stop_time=240.0, start_values=SOAK, record=["x_axis.pos", "feed.busy"],
                 output_interval=0.01)
    t, x = r.time, r["x_axis.pos"]
    deepest = [float(x[(t >= a) & (t < a + 40.0)].max()) for a in np.arange(0.0, 240.0, 40.0)]
    # every period: the wear cycle, then two parts; the wear offset grows by 0.02 mm a period
    assert deepest == pytest.approx([4.32, 4.32, 4.34, 4.34, 4.36, 4.36], abs=2e-3)
    for start in (40.0, 80.0, 120.0, 160.0, 200.0):       # between parts the wheel stands clear of the work
        assert x[np.searchsorted(t, start - 0.5)] < 0.1
