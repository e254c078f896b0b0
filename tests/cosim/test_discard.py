"""An FMU that asks to end the simulation (fmi2Discard + fmi2Terminated) ends the run cleanly at that time."""

from __future__ import annotations

import numpy as np
import pytest
from fmpy import simulate_fmu
from foreign_fmus import packed

from ncfmu.cli import main
from ncfmu.cosim.ssp import Component, Connection, System
from ncfmu.errors import SimulationError
from ncfmu.project import OpenSystem


def _clock(end_at: float, model: str = "Countdown") -> System:
    return System("clock", [Component("count", model, {"end_at": end_at}), Component("feed", "Feedthrough")],
                  [Connection("count", "minutes", "feed", "time_in"), Connection("count", "counter", "feed", "int_in")],
                  20.0, 0.01)


@pytest.mark.parametrize("native", [True, False])
def test_the_run_ends_where_the_fmu_asks_as_fmpy_does(foreign, project, tmp_path, native):
    with OpenSystem(packed(_clock(9.0), foreign, tmp_path)) as opened:
        opened.master.native = native
        run = opened.run()
    assert run.end_time == pytest.approx(9.0) and run.time[-1] == pytest.approx(9.0)   # fmpy's last row: 9.0
    assert run["count.counter"][-1] == 9 and run["feed.int_out"][-1] == 9
    assert run.ended_by.startswith("count asked to end the simulation at t = 9 s")


@pytest.mark.parametrize("native", [True, False])
def test_a_step_made_whole_before_the_fmu_asks_is_recorded_as_fmpy_does(foreign, project, tmp_path, native):
    # The Reference-FMUs' Stair ends this way: the step that reaches the end is whole (fmi2LastSuccessfulTime at
    # its end), then fmi2Discard + fmi2Terminated. fmpy (and fmusim) record that last point; so does the master,
    # with the rest of the step done for the FMUs after it (the Feedthrough sees the last count).
    reference = simulate_fmu(str(foreign["Stairs"]), stop_time=20.0, output_interval=0.01)
    assert reference["time"][-1] == pytest.approx(9.0) and reference["counter"][-1] == 9
    with OpenSystem(packed(_clock(9.0, "Stairs"), foreign, tmp_path)) as opened:
        opened.master.native = native
        run = opened.run()
    assert len(run.time) == len(reference)
    assert np.array_equal(run["count.counter"], reference["counter"])
    # minutes = (t + h) / 60 with the host's t: fmpy and the master make the time grid by different sums
    assert np.abs(run["count.minutes"] - reference["minutes"]).max() < 1e-14
    assert run.end_time == pytest.approx(9.0) and run.time[-1] == pytest.approx(9.0)
    assert run["feed.int_out"][-1] == 9
    assert run.ended_by.startswith("count asked to end the simulation at t = 9 s")


def test_an_fmi3_step_made_whole_before_the_fmu_asks_is_recorded(foreign, project, tmp_path):
    reference = simulate_fmu(str(foreign["Stairs3"]), stop_time=20.0, output_interval=0.01)
    assert reference["time"][-1] == pytest.approx(9.0) and reference["counter"][-1] == 9
    system = System("stairs3", [Component("count", "Stairs3", {"end_at": 9.0})], [], 20.0, 0.01)
    with OpenSystem(packed(system, foreign, tmp_path)) as opened:
        run = opened.run()
    assert np.array_equal(run["count.counter"], reference["counter"])
    assert run.end_time == pytest.approx(9.0)
    assert run.ended_by.startswith("count asked to end the simulation at t = 9 s")


def test_the_summary_names_the_fmu_that_asked_and_the_exit_status_is_0(foreign, project, tmp_path, capsys):
    archive = packed(_clock(4.5), foreign, tmp_path)
    assert main(["run", str(archive), "--out", str(tmp_path / "out")]) == 0
    out = capsys.readouterr().out
    assert "system clock: simulated 4.500 s" in out
    assert "  ended: count asked to end the simulation at t = 4.5 s (fmi2Discard with terminateSimulation)" in out
    assert (tmp_path / "out" / "clock.csv").read_text().splitlines()[-1].startswith("4.5,")


def test_fmpy_errors_do_not_escape_a_slave(foreign, project, tmp_path):
    # the error contract: get_state of an FMU that cannot save its state is our SimulationError, not fmpy's
    with OpenSystem(packed(_clock(9.0), foreign, tmp_path)) as opened:
        opened.run(stop_time=0.1)
        with pytest.raises(SimulationError, match=r"count: fmi2GetFMUstate returned fmi2Error"):
            opened.slaves[0].get_state()
