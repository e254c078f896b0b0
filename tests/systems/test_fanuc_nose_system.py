"""Tool-nose radius compensation closed loop (issue 32): docs/examples/lathe_fanuc_nose.nc (the Fanuc shaft with G42
before G71/G70, G40 on the way out) through the FMUs in lathe_roughing, tool 1 an OD turning tool of nose radius
0.8 mm, imaginary tip 3. From the ACTUAL axis positions (the imaginary tip) less the tip vector: the nose circle
touches the profile while G70 finishes and never cuts into it anywhere; G71 roughs the uncompensated profile shifted
by the allowances, as Fanuc's G71 does (its tip never below profile + allowance)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from lathe_oracle import SHAFT, below_shifted_profile, densify, distances

EXAMPLE = Path(__file__).resolve().parents[2] / "docs" / "examples" / "lathe_fanuc_nose.nc"
R, TIP = 0.8, (-1.0, -1.0)         # tip 3: the imaginary tip at (z - r, x - r) from the nose centre

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def run(ncfmu_run):
    return ncfmu_run("lathe_roughing", stop_time=100.0,
                     start_values={"seq.program": EXAMPLE.read_text(), "seq.tool[1].nose_radius": R,
                                   "seq.tool[1].tip": 3})


def nose_gap(run, sel, which: str) -> np.ndarray:
    """The nose circle's distance from the profile (< 0: into the part) at each selected sample."""
    z, x = (run["z_axis.pos"], run["x_axis.pos"]) if which == "actual" else (run["seq.z_cmd"], run["seq.x_cmd"])
    centre = np.column_stack([z[sel] - TIP[0] * R, x[sel] - TIP[1] * R])
    return distances(centre, densify(SHAFT.points(0.001), 0.001)) - R


def test_the_program_runs_to_the_end(run, ncfmu_checks):
    assert run["seq.done"][-1] and not run["seq.alarm"].any()
    ncfmu_checks.assert_alarm(run, "limiter.alarm", raised=False)
    assert run["x_axis.pos"][-1] == pytest.approx(50.0, abs=0.005)


def test_g70_the_nose_circle_on_the_profile_commanded_and_actual(run):
    g70 = (run["seq.canned_cycle"] == 70) & (run["seq.subcycle"] == 2)
    assert g70.sum() > 1000
    commanded = nose_gap(run, g70, "commanded")
    actual = nose_gap(run, g70, "actual")
    print(f"G70 nose gap commanded {commanded.min():.2e}..{commanded.max():.2e}, "
          f"actual {actual.min():.2e}..{actual.max():.2e} mm")
    assert np.abs(commanded).max() <= 0.003
    assert actual.min() >= -0.003 and actual.max() <= 0.010


def test_the_nose_never_cuts_into_the_part(run):
    everywhere = np.ones(len(run["seq.canned_cycle"]), bool)
    assert nose_gap(run, everywhere, "actual").min() >= -0.003


def test_g71_roughs_the_uncompensated_shifted_profile(run):
    g71 = run["seq.canned_cycle"] == 71
    assert below_shifted_profile(SHAFT, 0.2, 0.1, run["z_axis.pos"][g71], run["x_axis.pos"][g71], tol=0.002) <= 0.002
