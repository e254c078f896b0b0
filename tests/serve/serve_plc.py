"""What the served-system tests share: an asyncua client playing the PLC against ``ncfmu serve``."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable

import numpy as np
from asyncua import Client, ua

from ncfmu.cli import main
from ncfmu.cosim.result import Result
from ncfmu.exitcodes import EXIT_NOT_FINISHED, EXIT_OK

VARIANT = {bool: ua.VariantType.Boolean, int: ua.VariantType.Int32, float: ua.VariantType.Double,
           str: ua.VariantType.String}


class Plc:
    """A connected client: read, write (forcing), call the Simulation's methods, wait for conditions."""

    def __init__(self, client: Client, idx: int) -> None:
        self.client, self.idx = client, idx

    def node(self, name: str):
        return self.client.get_node(ua.NodeId(name, self.idx))

    async def read(self, name: str):
        return await self.node(name).read_value()

    async def write(self, name: str, value, vtype: ua.VariantType | None = None) -> None:
        await self.node(name).write_value(ua.DataValue(ua.Variant(value, vtype or VARIANT[type(value)])))

    async def call(self, method: str, *args: str) -> None:
        await self.node("Simulation").call_method(ua.NodeId(f"Simulation.{method}", self.idx),
                                                  *(ua.Variant(a, ua.VariantType.String) for a in args))

    async def time(self) -> float:
        return await self.read("Simulation.time")

    async def wait_until(self, name: str, test: Callable[[object], bool], timeout: float = 60.0,
                         poll: float = 0.005):
        """Poll ``name`` until ``test(value)``; the value. Fails after ``timeout`` s of wall time."""
        end = time.monotonic() + timeout
        while True:
            value = await self.read(name)
            if test(value):
                return value
            if time.monotonic() > end:
                raise AssertionError(f"{name} = {value!r}: the condition did not hold within {timeout} s")
            await asyncio.sleep(poll)


class connect:
    """``async with connect(served) as plc``: a client of a served system (optionally as a user)."""

    def __init__(self, served, user: str | None = None, password: str | None = None, endpoint: str | None = None):
        self.client = Client(endpoint or served.endpoint, timeout=10)
        if user is not None:
            self.client.set_user(user)
            self.client.set_password(password or "")
        self.namespace = served.namespace

    async def __aenter__(self) -> Plc:
        await self.client.connect()
        return Plc(self.client, await self.client.get_namespace_index(self.namespace))

    async def __aexit__(self, *exc) -> None:
        await self.client.disconnect()


def run(coro):
    return asyncio.run(coro)


def replay(system: str, served_csv, inputs_csv, tmp_path, *sets: str) -> Result:
    """``ncfmu run SYSTEM --input inputs_csv`` to the served run's last row; the result read back."""
    recorded = Result.from_csv(served_csv)
    out = tmp_path / "replay"
    args = ["run", system, "--stop-time", repr(float(recorded.time[-1])), "--input", str(inputs_csv),
            "--out", str(out)]
    for s in sets:
        args += ["--set", s]
    # 0 when the served run's work was done by its last row, 4 (not finished) when it was stopped before: the
    # replay follows the input's timeline to that row either way, and the trajectories are compared
    assert main(args) in (EXIT_OK, EXIT_NOT_FINISHED)
    return Result.from_csv(out / f"{system}.csv")


def assert_same_trajectory(served: Result, replayed: Result) -> None:
    assert served.data.dtype.names == replayed.data.dtype.names
    assert len(served.time) == len(replayed.time)
    for name in served.data.dtype.names:
        assert np.array_equal(served[name], replayed[name]), name
