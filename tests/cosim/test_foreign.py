"""A user's plant in place of ours: foreign FMUs (tests/foreign/, C on fmpy's FMI headers) through the master."""

from __future__ import annotations

import numpy as np
import pytest
from fmpy import simulate_fmu
from fmpy.validation import validate_fmu
from foreign_fmus import FOREIGN, packed, with_plant

from ncfmu.project import simulate


@pytest.mark.parametrize("name", sorted(FOREIGN))
def test_every_foreign_fmu_passes_fmpy_validation(foreign, name):
    assert validate_fmu(str(foreign[name])) == []


def test_the_foreign_axis_follows_a_ramp_by_its_own_physics(foreign):
    # a ramp at 10 mm/s with velocity feed-forward: the command is held over each step while the axis moves on,
    # so the loop balances the error over the step to zero and it reads -v h / 2 = -0.005 mm at the step's end;
    # without feed-forward a P position loop adds v / Kv = 10 / 40 = 0.25 mm
    t = np.arange(0, 2.0 + 1e-9, 1e-3)
    for vff, expected in ((10.0, -0.005), (0.0, 0.245)):
        signals = np.array([(ti, 10.0 * ti, vff) for ti in t], dtype=[("time", float), ("pos_cmd", float),
                                                                        ("vel_ff", float)])
        r = simulate_fmu(str(foreign["PlantAxis"]), stop_time=2.0, output_interval=1e-3, input=signals)
        assert r["following_error"][-1] == pytest.approx(expected, abs=1e-3)


def test_the_foreign_axis_in_mm_runs_the_lathe_taper_cycle(foreign, project, tmp_path):
    run = simulate(str(packed(with_plant("lathe_taper", "PlantAxis"), foreign, tmp_path)))
    assert run["seq.done"][-1] and not run["seq.alarm"].any()
    assert run["seq.pass_no"].max() == 4
    assert np.abs(run["x_axis.following_error"]).max() < 0.1


def test_fmpy_ends_the_countdown_where_it_asks(foreign):
    # the reference behaviour the master is held to: fmi2Discard + fmi2Terminated ends the run at that time
    r = simulate_fmu(str(foreign["Countdown"]), stop_time=20.0, output_interval=0.01)
    assert r["time"][-1] == pytest.approx(9.0) and r["counter"][-1] == 9
