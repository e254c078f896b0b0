"""``Master.run(until=...)``: a run that ends where its work ends, asked between chunks of steps, never in them.

``until`` is asked once the sinks have every row so far: when the record window is full, and -- looked at every
``check_interval`` s -- when a watched output changed. Its answer ends the run there: a complete run, its rows up
to that step, ``Result.ended_by`` its reason. The fake chain: a.y = b.y + 1, b.y = a.y + 10 (k = 0: both stay 0).
"""

from __future__ import annotations

import pytest
from fakes import chain

from ncfmu.cosim import master as master_module
from ncfmu.errors import SystemDefinitionError


class Rows:
    """A sink that keeps the times of its rows and how it was closed."""

    def __init__(self) -> None:
        self.times: list[float] = []
        self.closed: tuple[bool, float | None, str] | None = None

    def open(self, columns) -> None:
        pass

    def write(self, rows) -> None:
        self.times += rows["time"].tolist()

    def close(self, complete: bool, stopped_at: float | None = None, reason: str = "") -> None:
        self.closed = (complete, stopped_at, reason)


def test_a_run_ends_at_the_first_look_after_its_work_is_done():
    m, _log = chain("gauss-seidel")
    rows, asked = Rows(), []

    def until() -> str:
        asked.append(rows.times[-1])             # every row so far is in the sink when it is asked
        return "done" if rows.times[-1] >= 0.25 - 1e-12 else ""
    result = m.run(stop_time=1.0, step_size=0.001, keep=False, sinks=[rows], until=until, check_interval=0.1,
                   watch=["a.y"])
    assert asked == pytest.approx([0.1, 0.2, 0.3])            # a.y changes every step: looked at every 0.1 s
    assert result.ended_by == "done" and result.end_time == pytest.approx(0.3)
    assert rows.times[-1] == pytest.approx(0.3) and len(rows.times) == 301
    assert rows.closed == (True, pytest.approx(0.3), "done")


def test_nothing_watched_changed_no_look_before_the_window_is_full(monkeypatch):
    m, _log = chain("gauss-seidel")
    for component in m.system.components:
        component.parameters["k"] = 0.0       # a.y and b.y stay 0
    rows, asked = Rows(), []

    def until() -> str:
        asked.append(rows.times[-1])
        return ""
    result = m.run(stop_time=1.0, step_size=0.001, keep=False, sinks=[rows], until=until, check_interval=0.1,
                   watch=["a.y"])
    assert asked == [] and result.ended_by == "" and rows.times[-1] == pytest.approx(1.0)
    # a window of 250 rows (2 Real outputs of 8 bytes): asked at each handover (where a crash is seen)
    monkeypatch.setattr(master_module, "WINDOW_BYTES", 8 * 2 * 250)
    m, _log = chain("gauss-seidel")
    for component in m.system.components:
        component.parameters["k"] = 0.0
    rows, asked = Rows(), []
    m.run(stop_time=1.0, step_size=0.001, keep=False, sinks=[rows], until=until, check_interval=0.1, watch=["a.y"])
    assert asked == pytest.approx([0.249, 0.499, 0.749, 0.999])


def test_until_needs_a_run_that_keeps_no_rows_and_a_watched_output():
    m, _log = chain("gauss-seidel")
    with pytest.raises(SystemDefinitionError, match="keeps no rows"):
        m.run(stop_time=0.01, step_size=0.001, keep=True, until=lambda: "")
    m, _log = chain("gauss-seidel")
    with pytest.raises(SystemDefinitionError, match="'a.k' is not an output"):
        m.run(stop_time=0.01, step_size=0.001, keep=False, sinks=[Rows()], until=lambda: "", watch=["a.k"])
