"""What ``LiveServer`` builds before the paced clock starts (the address space; with ``--cnc`` the OPC 40502
NodeSet import, ~5 s and many objects) lives for the whole serve: it is collected once and frozen before the
simulation thread starts, so that no full collection of it lands in the paced loop (bench/serve_lag.py saw one
~200 ms stall in every ``--cnc`` run, a generation-2 collection after the build)."""

from __future__ import annotations

import asyncio
import gc
import socket

from test_serve_runner import POINTS, Session

from ncfmu.serving import LiveServer, Runner


def free_endpoint() -> str:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    return f"opc.tcp://127.0.0.1:{port}/ncfmu"


def test_what_is_built_is_frozen_before_the_clock_starts():
    gc.unfreeze()
    runner = Runner(Session(), POINTS, speed=1.0)
    server = LiveServer("frozen", runner, free_endpoint())
    seen: dict[str, int] = {}
    start = runner.start

    def start_and_stop() -> None:
        seen["frozen"] = gc.get_freeze_count()
        start()
        runner.stop("test over")
    runner.start = start_and_stop           # type: ignore[method-assign]
    asyncio.run(asyncio.wait_for(server.serve(), 30))
    assert runner.state == "stopped" and runner.reason == "test over"
    # the server's own objects (the address space: thousands of nodes) are frozen when the clock starts ...
    assert seen["frozen"] > 10_000
    # ... and given back to the collector when the serve is over
    assert gc.get_freeze_count() == 0
