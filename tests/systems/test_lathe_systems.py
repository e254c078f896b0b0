"""Closed loop through the built FMUs (fmpy master): the lathe systems."""

import numpy as np
import pytest

pytestmark = pytest.mark.slow        # whole systems in closed loop: not in the fast subset

# The cut depths, the taper line, the end point, the two blocks and nothing blocked are
# physics.check_lathe_roughing/_taper, which test_interop runs on these same results and on libcosim's.
# Here: what only ncfmu's run records.


def test_roughing_ends_done_counting_passes_as_the_seed(lathe_roughing):
    r = lathe_roughing
    assert r["seq.done"][-1] and not r["seq.alarm"].any()
    assert set(np.unique(r["seq.pass_no"][r["seq.block_no"] == 1])) >= {1, 2, 3, 4, 5, 6}


def test_feed_rate_during_the_cut(lathe_roughing):
    from physics import intervals
    r = lathe_roughing
    a, b = intervals(r["seq.subcycle"], 2)[0]
    v = -r["z_axis.vel"][a:b]
    steady = v[(r.time[a:b] > r.time[a] + 0.5) & (r.time[a:b] < r.time[b - 1] - 0.5)]
    assert steady == pytest.approx(4.0, rel=0.01)


def test_default_programs_never_raise_the_limiter_alarm(lathe_roughing, lathe_taper):
    for r in (lathe_roughing, lathe_taper):
        assert not r["limiter.alarm"].any() and not r["seq.alarm"].any()


def test_cut_into_the_chuck_stops_before_it(project):
    """Zp = 50 would take the tool to Z = -48; the chuck zone starts at Z = -45."""
    from ncfmu.project import simulate
    r = simulate("lathe_roughing", stop_time=14.0, start_values={"seq.block[1].Zp": 50.0})
    assert r["limiter.alarm"].any() and r["seq.alarm"][-1]
    assert r["limiter.blocked"].max() == 2                     # Z- blocked, nothing else
    assert r["z_axis.pos"].min() > -45.0                       # the actual axis never enters
    assert r["limiter.ref_cmd"].min() > -45.0                  # nor does the command
    first = np.argmax(r["limiter.alarm"])
    assert r["z_axis.pos"][first] < -44.0                      # it got close: stopped by the limit, not early
    # the sequencer holds: no motion after the alarm has settled
    late = r.time > r.time[first] + 0.5
    assert np.ptp(r["z_axis.pos"][late]) < 1e-4 and np.ptp(r["seq.z_cmd"][late]) == 0.0
    assert not r["seq.busy"][-1]
