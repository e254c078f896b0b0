"""The panel any front end uses (a web page beside the OPC UA server): the runner's newest values without taking
them from the server (``Runner.latest``) and the server's writes and calls (``LiveServer.write``, ``call``,
``release``), the very code an OPC UA client's Write and method calls run -- in process, on the small session of
test_serve_runner (no FMUs)."""

from __future__ import annotations

import asyncio
import threading
import time

import pytest
from test_serve_gc import free_endpoint
from test_serve_runner import POINTS, Session

from ncfmu.serving import LiveServer, Point, Runner, WriteRefused

#: a fixed parameter: read once at the start, in no later snapshot
FIXED = Point("a.k", "a", "k", "Real", "parameter", "fixed", None, "", None, None)


def test_latest_shows_every_value_and_leaves_the_snapshot_to_the_server():
    session = Session(end_at=0.05)
    ended = threading.Event()
    runner = Runner(session, [*POINTS, FIXED], speed=0.0, on_state=ended.set)
    first = runner.latest()
    assert first.time == 0.0 and first.values == {"a.y": 0.0, "a.u": 1.0, "a.k": 1.0}
    assert runner.snapshot() is not None              # latest() took nothing from the server's reader
    runner.start()
    assert ended.wait(5)
    runner.thread.join(5)
    last = runner.latest()
    assert last.state == "stopped" and last.time == pytest.approx(0.05)
    assert last.values["a.y"] == pytest.approx(0.05)  # y integrates u = 1 for 0.05 s
    assert last.values["a.k"] == 1.0                  # the fixed parameter, as read at the start
    final = runner.snapshot()                          # the server still gets the final state
    assert final is not None and final.state == "stopped" and final.time == last.time
    assert runner.latest().time == last.time           # ... and latest() still shows it after that


def test_the_panel_writes_and_calls_as_an_opc_ua_client_does():
    session = Session()
    runner = Runner(session, POINTS, speed=1.0)
    server = LiveServer("panel", runner, free_endpoint())
    seen: dict = {}

    async def refused(act) -> tuple[str, str]:
        with pytest.raises(WriteRefused) as refusal:
            await act
        return refusal.value.status, str(refusal.value)

    async def press() -> None:
        await server.write("a.u", 0.5)                 # forced: applied before the next step, then published
        seen["forced"] = runner.latest().forced
        seen["bad writes"] = [await refused(server.write(name, value)) for name, value in (
            ("a.u", -1.0), ("a.y", 1.0), ("a.u", True), ("a.u.forced", 1), ("b.z", 1.0))]
        await server.call("Pause")
        paused = runner.latest()
        await asyncio.sleep(0.05)
        seen["paused"] = (paused.state, paused.time, runner.latest().time)
        await server.call("Resume")
        resumed, wall = runner.latest().time, time.perf_counter()
        await asyncio.sleep(0.05)
        seen["resumed"] = (runner.latest().time - resumed, time.perf_counter() - wall)
        await server.release("a.u")
        seen["released"] = runner.latest().forced
        await server.write("a.u.forced", True)          # held at its present value
        seen["held"] = runner.latest().forced
        await server.write("a.u.forced", False)
        seen["bad calls"] = [await refused(server.release("a.y")), await refused(server.call("Jump"))]
        await server.call("Stop")
        seen["stopped"] = runner.latest().state
        seen["after"] = await refused(server.call("Reset"))

    async def pressed() -> None:
        try:
            await press()
        finally:                                        # a failure too ends the serve (the test says what)
            server.stopped.set()

    def ready(endpoint: str) -> None:
        seen["task"] = asyncio.get_running_loop().create_task(pressed())
    asyncio.run(asyncio.wait_for(server.serve(ready), 30))
    assert seen["task"].exception() is None
    assert seen["forced"] == {"a.u": 0.5}
    assert seen["bad writes"] == [("BadOutOfRange", "a.u: a.u = -1.0: must be >= 0"),
                                  ("BadNotWritable", "a.y is an output: not writable"),
                                  ("BadTypeMismatch", "a.u = True: must be a Double"),
                                  ("BadTypeMismatch", "a.u.forced = 1: must be a Boolean"),
                                  ("BadNotWritable", "b.z: not writable")]
    state, at_pause, later = seen["paused"]
    assert state == "paused" and later == at_pause     # paused: simulated time stands
    simulated, wall = seen["resumed"]
    assert 0.02 <= simulated <= wall + 0.001            # resumed: paced on at speed 1, never ahead of the clock
    assert seen["released"] == {} and seen["held"] == {"a.u": 1.0}
    assert seen["bad calls"] == [("BadInvalidArgument", "Release('a.y'): not an input INSTANCE.VARIABLE"),
                                 ("BadMethodInvalid", "'Jump': not a method of Simulation (Pause, Resume, Stop, "
                                                      "Reset)")]
    assert seen["stopped"] == "stopped" and seen["after"] == ("BadInvalidState", "the simulation is stopped")
    # what reached the session: the force, the release, the hold at 1.0 and its release; nothing refused
    assert [w[1:] for w in session.writes] == [("a.u", 0.5), ("a.u", None), ("a.u", 1.0), ("a.u", None)]
