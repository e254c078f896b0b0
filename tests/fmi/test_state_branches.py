"""Honest FMU state: every hidden state round-trips through fmi2Get/SetFMUstate and serialisation."""

import numpy as np
import pytest

from ncfmu.cli import main
from ncfmu.project import OpenSystem, simulate, simulate_branches, system_archive

BRANCH = {"lathe_taper": 12.3456, "grinder_feed": 10.5, "grinder_envelope": 6.789, "mill_contour": 17.25}


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(BRANCH))
def test_restored_state_continues_bit_identically(project, name):
    """Branch twice from a mid-run state with no change: both equal the straight run, bit for bit."""
    stop = BRANCH[name] + 3.0
    straight = simulate(name, stop_time=stop)
    first, second = simulate_branches(name, BRANCH[name], [{}, {}], stop_time=stop)
    for branch in (first, second):
        assert branch.names == straight.names
        for variable in straight.names:
            assert np.array_equal(branch[variable], straight[variable]), variable


@pytest.mark.parametrize("name", ["lathe_taper", "grinder_feed", "mill_contour"])     # every model among them
def test_serialised_state_round_trips(project, name):
    """Save a system mid-run as bytes, run on, load the bytes, run again: the same outputs."""
    with OpenSystem(system_archive(name)) as opened:
        master = opened.master
        run = master.prepare(3.0, None, None, None, 0.0)
        run.steps(0, 1500)
        blobs = [s.serialize_state(st) for s, st in ((s, s.get_state()) for s in opened.slaves)]
        assert all(len(b) > 100 for b in blobs)
        run.steps(1500, 3000)
        once = {k: v[1500:].copy() for k, v in run.rec.items()}
        assert any(np.ptp(v) > 0 for v in once.values())     # it moved on: the restore has something to undo
        for s, blob in zip(opened.slaves, blobs):
            s.set_state(s.deserialize_state(blob))
        for s in opened.slaves:
            s.read_outputs()
        run.steps(1500, 3000)
        for k in once:
            assert np.array_equal(run.rec[k][1500:], once[k])


@pytest.mark.slow
def test_emergency_at_different_instants_from_one_state(project, tmp_path, capsys):
    """The use case: grind to 10 s once, then strike EMB at 12, 21 and 31 s."""
    results = simulate_branches("grinder_feed", 10.0, [{"panel.emergency_at": t} for t in (12.0, 21.0, 31.0)],
                                stop_time=33.0)
    for strike, r in zip((12.0, 21.0, 31.0), results):
        x = r["x_axis.pos"]
        assert np.array_equal(r["x_axis.pos"][r.time <= 10.0], results[0]["x_axis.pos"][r.time <= 10.0])
        assert r["feed.emergency_active"][(r.time > strike) & (r.time < strike + 0.05)].all()
        assert abs(x[-1]) <= 0.005 and not r["feed.emergency_active"][-1]
    # deeper strikes leave from deeper positions
    at = [r["x_axis.pos"][np.searchsorted(r.time, s)] for s, r in zip((12.0, 21.0, 31.0), results)]
    assert at[0] < at[1] < at[2]
    assert main(["run", "grinder_feed", "--branch-at", "10", "--branch-set", "panel.emergency_at=12,21",
                 "--stop-time", "23", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "branch 0 from t = 10.0 s (panel.emergency_at=12)" in out
    assert (tmp_path / "grinder_feed_branch1.csv").is_file()
