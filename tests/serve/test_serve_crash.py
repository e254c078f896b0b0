"""``ncfmu serve`` publishes a crash as it happens: an OPC UA event from the Simulation object, the nodes
``Simulation.crashes`` and ``Simulation.crash``, and the state ``crashed`` (the simulation halts; Reset starts
again). A real asyncua client subscribes to the events; the oracle is the served run's own recording (where the
tool was on which line), not the part check."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest
from asyncua import ua
from serve_plc import connect, run

from ncfmu.cosim.result import Result
from ncfmu.machining.removal import TOUCH
from ncfmu.serving import CRASH_CHECK, CRASH_SEVERITY, MAX_CHUNK_WALL

pytestmark = pytest.mark.slow

#: Rapids into the bar (radius 29) at Z -10 down to X 24.2 on its line 4 (tests/systems/test_part_check.py's).
RAPID_INTO_STOCK = "G18 G21 G90 G8\nG00 X30 Z2\nG00 Z-10\nG00 X24.2\nG00 X30\nG00 Z2\nM30\n"


class Events:
    def __init__(self) -> None:
        self.seen: list = []

    def event_notification(self, event) -> None:
        self.seen.append(event)


@pytest.mark.parametrize("speed", [0.0, 2.0])
def test_a_crash_is_an_event_a_node_and_the_state_crashed(ncfmu_serve, tmp_path, speed):
    """At --speed 0 each part check is waited for; above, the check runs beside the simulation, a hand-over of
    rows behind: the halt may come a hand-over later, the crash (time, line, depth) is the same rows'."""
    out = tmp_path / "served"
    served = ncfmu_serve("lathe_roughing", "--no-cnc", "--speed", str(speed), "--out", out,
                         "--set", "panel.start_at=-1", "--set", f"seq.program={RAPID_INTO_STOCK}")
    events = Events()

    async def plc():
        async with connect(served) as p:
            sim = p.node("Simulation")
            crash_type = await p.client.nodes.base_event_type.get_child([f"{p.idx}:CrashEventType"])
            sub = await p.client.create_subscription(20, events)
            await sub.subscribe_events(sim, crash_type)
            assert await p.read("Simulation.crashes") == 0 and await p.read("Simulation.crash") == ""
            await p.write("seq.start", True)                  # START: the program runs into the bar
            await p.wait_until("Simulation.state", lambda s: s == "crashed", timeout=60)
            halted = await p.time()
            await asyncio.sleep(0.3)
            assert await p.time() == halted                   # it halted
            text = await p.read("Simulation.crash")
            assert await p.read("Simulation.crashes") == 1
            assert await p.read("Simulation.reason") == text
            end = asyncio.get_running_loop().time() + 10
            while not events.seen and asyncio.get_running_loop().time() < end:
                await asyncio.sleep(0.02)
            with pytest.raises(ua.UaStatusCodeError):        # a crashed run is not resumed ...
                await p.call("Resume")
            await p.call("Reset")                             # ... it starts again
            await p.wait_until("Simulation.state", lambda s: s == "running", timeout=10)
            assert await p.read("Simulation.crashes") == 0 and await p.read("Simulation.crash") == ""
            await sub.delete()
            await p.call("Stop")
            return halted, text
    halted, text = run(plc())
    assert len(events.seen) == 1
    e = events.seen[0]
    assert (e.Line, e.What) == (4, "rapid into the stock")
    assert e.Message.Text == text and e.Severity == CRASH_SEVERITY
    assert text == f"crash at t = {e.SimulationTime:.3f} s, line 4: rapid into the stock, {e.DepthMm:.3g} mm deep"
    # the oracle: the served run's recording up to the crash (the segment before the Reset)
    r = Result.from_csv(out / "lathe_roughing.segment1.csv")
    line, x = r["seq.line"], r["x_axis.pos"]
    first = (line == 4) & (x < 29.0 - TOUCH)
    assert first.any()
    assert e.SimulationTime == pytest.approx(float(r.time[np.argmax(first)]), abs=0.003)
    # seen as it happened: halted within a check interval (and one chunk of steps) of the crash; above speed 0
    # the check is a hand-over behind: two intervals, each with a chunk of steps (at most MAX_CHUNK_WALL's)
    if speed == 0:
        assert e.SimulationTime < halted <= e.SimulationTime + 2 * CRASH_CHECK + 0.01
    else:
        assert e.SimulationTime < halted <= e.SimulationTime + 2 * (CRASH_CHECK + MAX_CHUNK_WALL * speed)
    assert r.time[-1] == pytest.approx(halted, abs=0.002)
    # how deep: as far as the tool went into the bar before the halt -- short of the 4.8 mm the line asks for
    assert e.DepthMm == pytest.approx(29.0 - float(x.min()), abs=0.002)
    assert 0.0 < e.DepthMm < 4.8
