"""The client plays the PLC: it answers the grinder's M words, strikes EMB, starts and feed-holds the lathe; every
served session's recorded writes, replayed by ``ncfmu run --input``, give the recorded trajectory exactly."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest
from serve_plc import assert_same_trajectory, connect, replay, run

from ncfmu.cosim.result import Result
from ncfmu.project import simulate

BAND = 0.002     # mm: what the systems' own tests allow for a position reached

#: The seed's grinding cycle with an M word before the rough feed, before the fine feed and after the
#: spark-out: each waits for the auxiliary device's MFIN.
M_PROGRAM = ("M0: X+D3F7; M1: M1; M2: X+D2F1; M3: M2; M4: X+D5F2; M5: T1; M6: M3; M7: X-D4F7; M8: END; "
             "M41: XF7S1; M42: END; M43: X+D1F2S4; M44: END")


def motion_segments(t, m):
    """Durations with m_active == 0 between M words (what the cycle does while nobody waits for MFIN)."""
    waiting = m != 0
    edges = np.flatnonzero(np.diff(waiting.astype(int)))
    # the first edge is the first M word's rise; then fall, rise, fall, rise ...
    falls, rises = edges[1::2], edges[2::2]
    return [t[r] - t[f] for f, r in zip(falls, rises)]


@pytest.mark.slow
def test_grinder_plc_answers_every_m_word_and_the_cycle_completes(ncfmu_serve, tmp_path):
    out = tmp_path / "served"
    sets = [f"feed.program={M_PROGRAM}", "panel.start_at=-1"]
    served = ncfmu_serve("grinder_feed", "--no-cnc", "--speed", "0", "--out", out,
                         *(x for s in sets for x in ("--set", s)))

    async def plc():
        async with connect(served) as p:
            await p.write("feed.mfin", False)        # the PLC owns MFIN from now on: the panel's never arrives
            await p.wait_until("feed.mfin.forced", lambda v: v is True, timeout=10)
            await p.write("feed.start", True)        # cycle start, a pulse
            await p.wait_until("feed.busy", lambda v: v is True, timeout=10)
            await p.write("feed.start", False)
            answered = []
            for _ in range(3):
                m = await p.wait_until("feed.m_active", lambda v: v != 0, timeout=30)
                await p.write("feed.mfin", True)                             # rising edge: M word done
                await p.wait_until("feed.m_active", lambda v: v == 0, timeout=30)
                await p.write("feed.mfin", False)                            # dropped when m_active drops
                answered.append(m)
            await p.wait_until("feed.busy", lambda v: v is False, timeout=60)
            t_end = await p.time()
            await p.wait_until("Simulation.time", lambda t: t > t_end + 0.5)
            await p.call("Stop")
            return answered
    assert run(plc()) == [1, 2, 3]
    assert served.wait(60) == 0, served.output
    r = Result.from_csv(out / "grinder_feed.csv")
    x, m, t = r["x_axis.pos"], r["feed.m_active"], r.time
    assert x.max() == pytest.approx(4.3, abs=BAND)                       # rough to 4.2, fine to 4.3
    assert x[-1] == pytest.approx(0.0, abs=BAND) and not r["feed.alarm"].any() and not r["feed.busy"][-1]
    assert [int(v) for v in dict.fromkeys(m[m != 0])] == [1, 2, 3]
    # as in the scripted run (the panel answering after 0.3 s): the same motions between the M words
    scripted = simulate("grinder_feed", stop_time=40.0,
                        start_values={"feed.program": M_PROGRAM, "panel.mfin_delay": 0.3})
    assert scripted["x_axis.pos"].max() == pytest.approx(x.max(), abs=1e-4)
    ours, theirs = motion_segments(t, m), motion_segments(scripted.time, scripted["feed.m_active"])
    assert len(ours) == len(theirs) == 2
    assert ours == pytest.approx(theirs, abs=0.003)
    # the replay
    assert_same_trajectory(r, replay("grinder_feed", out / "grinder_feed.csv", out / "session_inputs.csv",
                                     tmp_path, *sets))


@pytest.mark.slow
def test_grinder_emb_from_the_client_returns_the_wheel_to_the_feed_origin(ncfmu_serve, tmp_path):
    out = tmp_path / "served"
    served = ncfmu_serve("grinder_feed", "--no-cnc", "--speed", "4", "--out", out)

    async def plc():
        async with connect(served) as p:
            await p.wait_until("x_axis.pos", lambda x: x > 4.1, timeout=60)   # mid rough feed
            await p.write("feed.emergency", True)
            await p.wait_until("feed.emergency_active", lambda v: v is True, timeout=10)
            await p.call("Release", "feed.emergency")                           # the panel's EMB (off) again
            await p.wait_until("feed.emergency_active", lambda v: v is False, timeout=60)
            t = await p.time()
            await p.wait_until("Simulation.time", lambda now: now > t + 0.5)
            await p.call("Stop")
    run(plc())
    assert served.wait(60) == 0, served.output
    r = Result.from_csv(out / "grinder_feed.csv")
    x = r["x_axis.pos"]
    struck = np.flatnonzero(r["feed.emergency_active"])[0]
    assert 4.1 < x[struck] < 4.2                                       # struck during the rough feed
    assert x.max() < 4.2                                               # the cycle went no deeper
    assert x[-1] == pytest.approx(0.0, abs=BAND)                       # back at the feed origin
    assert r["feed.return_counter_x"][-1] == pytest.approx(0.0, abs=BAND)
    assert abs(r["x_axis.vel"][-1]) < 1e-3
    assert_same_trajectory(r, replay("grinder_feed", out / "grinder_feed.csv", out / "session_inputs.csv", tmp_path))


@pytest.mark.slow
def test_lathe_started_feed_held_mid_cut_and_released_by_the_client(ncfmu_serve, tmp_path):
    out = tmp_path / "served"
    sets = ["panel.start_at=-1"]
    served = ncfmu_serve("lathe_roughing", "--no-cnc", "--speed", "0", "--out", out, "--set", sets[0])

    async def plc():
        async with connect(served) as p:
            await asyncio.sleep(0.2)
            assert await p.read("seq.busy") is False                           # nobody pressed START
            await p.write("seq.start", True)
            await p.wait_until("seq.busy", lambda v: v is True, timeout=10)
            await p.call("Release", "seq.start")
            # the second pass's cut (SC2): Z well inside the cut
            await p.wait_until("seq.pass_no", lambda v: v == 2, timeout=60)
            await p.wait_until("seq.subcycle", lambda v: v == 2, timeout=60)
            await p.wait_until("z_axis.pos", lambda z: z < -20.0, timeout=60)
            await p.write("seq.feed_hold", True)
            await p.wait_until("z_axis.vel", lambda v: abs(v) < 1e-6, timeout=30)
            t_stop = await p.time()
            await p.wait_until("Simulation.time", lambda t: t > t_stop + 0.5)   # the servo settles
            t_hold, cmd_hold = await p.time(), await p.read("seq.z_cmd")
            await p.wait_until("Simulation.time", lambda t: t > t_hold + 2.0)   # held for 2 s
            assert await p.read("seq.z_cmd") == cmd_hold and await p.read("z_axis.in_position") is True
            assert await p.read("seq.subcycle") == 2 and await p.read("seq.busy") is True
            await p.call("Release", "seq.feed_hold")
            await p.wait_until("seq.done", lambda v: v is True, timeout=120)
            t = await p.time()
            await p.wait_until("Simulation.time", lambda now: now > t + 0.5)
            await p.call("Stop")
            return t_hold
    t_hold = run(plc())
    assert served.wait(60) == 0, served.output
    r = Result.from_csv(out / "lathe_roughing.csv")
    t, z, x = r.time, r["z_axis.pos"], r["x_axis.pos"]
    held = (t > t_hold) & (t < t_hold + 2.0)
    # the command stands still; the axis stays in position at it (the servo's last encoder counts of settling)
    assert np.ptp(r["seq.z_cmd"][held]) == 0.0 and np.ptp(r["limiter.ref_cmd"][held]) == 0.0
    assert r["z_axis.in_position"][held].all() and (r["seq.subcycle"][held] == 2).all()
    assert -30.0 < z[held][0] < -20.0                                 # mid-cut (the cut runs to Z -42)
    assert x.min() == pytest.approx(25.9, abs=BAND)                   # the finish pass's radius, as scripted
    assert r["seq.done"][-1] and not r["seq.alarm"].any() and not r["limiter.alarm"].any()
    assert_same_trajectory(r, replay("lathe_roughing", out / "lathe_roughing.csv", out / "session_inputs.csv",
                                     tmp_path, *sets))
