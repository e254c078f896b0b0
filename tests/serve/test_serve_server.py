"""``ncfmu serve`` started as a process, a real asyncua client as the PLC: address space, writes, control.

Each test starts a server process (a few seconds): all are ``slow`` but the command-line refusal."""

from __future__ import annotations

import asyncio
import math
import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest
from asyncua import Client, ua
from serve_plc import connect, run

from ncfmu.cli import main


# -- the address space --------------------------------------------------------------------------------------
@pytest.mark.slow
def test_units_descriptions_and_types_are_browsable(ncfmu_serve):
    served = ncfmu_serve("lathe_roughing", "--no-cnc", "--speed", "0")

    async def plc():
        async with connect(served) as p:
            objects = p.client.nodes.objects
            names = {(await c.read_browse_name()).Name for c in await objects.get_children()}
            assert {"panel", "seq", "limiter", "x_axis", "z_axis", "Simulation"} <= names
            pos = p.node("x_axis.pos")
            assert (await pos.read_browse_name()).Name == "pos"
            assert (await pos.read_data_type()) == ua.NodeId(ua.ObjectIds.Double)
            assert (await pos.read_description()).Text == "actual position (encoder)"
            eu = await (await pos.get_child(["0:EngineeringUnits"])).read_value()
            assert eu.DisplayName.Text == "mm" and eu.NamespaceUri == "http://www.opcfoundation.org/UA/units/un/cefact"
            assert eu.UnitId == int.from_bytes(b"MMT", "big")            # UNECE code MMT: millimetre
            assert not (await pos.get_access_level()) & {ua.AccessLevel.CurrentWrite}   # an output: read-only
            xd = p.node("seq.block[1].Xd")
            assert (await xd.read_browse_name()).Name == "block[1].Xd" and await xd.read_value() == 0.5
            assert (await p.node("seq.block[1].N").read_data_type()) == ua.NodeId(ua.ObjectIds.Int32)
            assert (await p.node("seq.start").read_data_type()) == ua.NodeId(ua.ObjectIds.Boolean)
            assert ua.AccessLevel.CurrentWrite in await p.node("seq.feed_hold").get_access_level()
            assert await p.read("seq.feed_hold.forced") is False
            assert (await p.node("panel.override").read_description()).Text == "feed override dial"
            for name in ("time", "speed", "lag", "overruns", "state", "reason"):
                await p.read(f"Simulation.{name}")
            assert await p.read("Simulation.speed") == 0.0
            assert await p.read("Simulation.state") == "running"
    run(plc())


@pytest.mark.slow
def test_subscription_delivers_x_axis_pos_changes(ncfmu_serve):
    """grinder_feed at real time: the wheel roughs from X 4.0 to 4.2 at 0.02 mm/s for 10 s; a 10 ms subscription
    sees it move every publication."""
    served = ncfmu_serve("grinder_feed", "--no-cnc", "--speed", "1")

    class Handler:
        def __init__(self):
            self.values = []

        def datachange_notification(self, node, val, data):
            self.values.append((time.monotonic(), val))

    async def plc():
        async with connect(served) as p:
            await p.wait_until("x_axis.pos", lambda x: x > 4.0 + 1e-4)
            handler = Handler()
            sub = await p.client.create_subscription(10, handler)
            await sub.subscribe_data_change(p.node("x_axis.pos"))
            await asyncio.sleep(1.5)
            await sub.delete()
            return handler.values
    values = run(plc())
    assert len(values) >= 30, f"only {len(values)} data changes in 1.5 s at a 10 ms publishing interval"
    xs = [v for _t, v in values]
    assert len(set(xs)) >= 30 and xs == sorted(xs)            # feeding in: X only grows
    assert xs[-1] - xs[0] == pytest.approx(0.02 * (values[-1][0] - values[0][0]), rel=0.2)   # at 0.02 mm/s
    gaps = [b[0] - a[0] for a, b in zip(values, values[1:])]
    assert sorted(gaps)[len(gaps) // 2] < 0.05       # delivered at the interval asked for, not in bursts


# -- writes ----------------------------------------------------------------------------------------------------
BAD_WRITES = [
    # node, value, variant type, status
    ("x_axis.pos", 1.0, ua.VariantType.Double, "BadNotWritable"),            # an output
    ("seq.block[1].Xd", 0.4, ua.VariantType.Double, "BadNotWritable"),       # a fixed parameter
    ("Simulation.time", 3.0, ua.VariantType.Double, "BadNotWritable"),
    ("seq.feed_hold", 1.0, ua.VariantType.Double, "BadTypeMismatch"),        # a Boolean input
    ("panel.override", 1, ua.VariantType.Int32, "BadTypeMismatch"),          # a Double parameter
    ("panel.override", "0.5", ua.VariantType.String, "BadTypeMismatch"),
    ("seq.feed_override", math.nan, ua.VariantType.Double, "BadOutOfRange"),
    ("seq.feed_override", math.inf, ua.VariantType.Double, "BadOutOfRange"),
    ("panel.override", 2.0, ua.VariantType.Double, "BadOutOfRange"),         # the port's rule: 0..1.5
    ("panel.override", -0.1, ua.VariantType.Double, "BadOutOfRange"),
    ("panel.mfin_delay", -1.0, ua.VariantType.Double, "BadOutOfRange"),      # >= 0
]


@pytest.mark.slow
def test_bad_writes_get_the_status_that_says_why_and_change_nothing(ncfmu_serve):
    served = ncfmu_serve("lathe_roughing", "--no-cnc", "--speed", "2")

    async def plc():
        async with connect(served) as p:
            before = {n: await p.read(n) for n in ("seq.feed_hold", "panel.override", "seq.feed_override",
                                                   "panel.mfin_delay", "seq.block[1].Xd")}
            for name, value, vtype, status in BAD_WRITES:
                with pytest.raises(ua.UaStatusCodeError) as err:
                    await p.write(name, value, vtype)
                assert err.value.code == getattr(ua.StatusCodes, status), (name, value, err.value)
            await asyncio.sleep(0.1)           # two publications: a write that slipped through would show
            for name, value in before.items():
                assert await p.read(name) == value, name
            for name in ("seq.feed_hold", "seq.feed_override"):
                assert await p.read(f"{name}.forced") is False
            t0 = await p.time()
            await asyncio.sleep(0.2)
            assert await p.time() > t0 + 0.2       # the simulation went on
            # and a good write of the same node takes effect
            await p.write("panel.override", 0.5)
            assert await p.wait_until("seq.feed_override", lambda v: v == 0.5, timeout=5)
    run(plc())


@pytest.mark.slow
def test_forcing_a_connected_input_and_releasing_it(ncfmu_serve):
    """seq.feed_override is driven by the panel's dial (1.0): forced to 0.25 it holds, released it follows again."""
    served = ncfmu_serve("lathe_roughing", "--no-cnc", "--speed", "2")

    async def plc():
        async with connect(served) as p:
            assert await p.read("seq.feed_override") == 1.0
            await p.write("seq.feed_override", 0.25)
            await p.wait_until("seq.feed_override.forced", lambda v: v is True, timeout=5)
            assert await p.read("seq.feed_override") == 0.25
            await asyncio.sleep(0.2)
            assert await p.read("seq.feed_override") == 0.25
            await p.call("Release", "seq.feed_override")
            await p.wait_until("seq.feed_override", lambda v: v == 1.0, timeout=5)
            assert await p.read("seq.feed_override.forced") is False
            # the .forced node: true holds the present value, false releases
            await p.write("seq.feed_override.forced", True)
            await p.wait_until("seq.feed_override.forced", lambda v: v is True, timeout=5)
            await p.write("panel.override", 0.5)          # the source moves; the forced input does not
            await p.wait_until("panel.feed_override", lambda v: v == 0.5, timeout=5)
            assert await p.read("seq.feed_override") == 1.0
            await p.write("seq.feed_override.forced", False)
            await p.wait_until("seq.feed_override", lambda v: v == 0.5, timeout=5)
            with pytest.raises(ua.UaStatusCodeError) as err:
                await p.call("Release", "x_axis.pos")
            assert err.value.code == ua.StatusCodes.BadInvalidArgument
    run(plc())


# -- the Simulation object --------------------------------------------------------------------------------------
@pytest.mark.slow
def test_pause_resume_reset_stop(ncfmu_serve, tmp_path):
    out = tmp_path / "served"
    served = ncfmu_serve("lathe_roughing", "--no-cnc", "--speed", "1", "--out", out)

    async def plc():
        async with connect(served) as p:
            await p.wait_until("Simulation.time", lambda t: t >= 0.5)
            await p.call("Pause")
            await p.wait_until("Simulation.state", lambda s: s == "paused", timeout=5)
            t_paused = await p.time()
            x_paused = await p.read("x_axis.pos")
            await asyncio.sleep(0.5)
            assert await p.time() == t_paused and await p.read("x_axis.pos") == x_paused
            wall = time.monotonic()
            await p.call("Resume")
            await p.wait_until("Simulation.time", lambda t: t >= t_paused + 0.5)
            assert await p.read("Simulation.state") == "running"
            # paced from where it paused: no jump to make up for the pause
            assert time.monotonic() - wall >= 0.45
            await p.write("seq.feed_override", 0.5)
            await p.wait_until("seq.feed_override.forced", lambda v: v is True, timeout=5)
            t_before = await p.time()
            await p.call("Reset")
            t_after = await p.wait_until("Simulation.time", lambda t: t < t_before, timeout=5)
            assert t_after < 0.2
            assert await p.wait_until("seq.feed_override.forced", lambda v: v is False, timeout=5) is False
            assert await p.read("seq.feed_override") == 1.0
            await p.wait_until("Simulation.time", lambda t: t >= 0.3)
            await p.call("Stop")
    run(plc())
    assert served.wait(30) == 0, served.output
    assert "stopped at t = " in served.output and "(Stop called)" in served.output
    # the Reset ended a recording segment: its trajectory and its writes are kept under their own names
    before = (out / "lathe_roughing.segment1.csv").read_text().splitlines()
    assert before[1].startswith("0.0,") and float(before[-1].split(",")[0]) > 1.0
    writes = (out / "session_inputs.segment1.csv").read_text().splitlines()
    assert writes[0] == '"time","seq.feed_override"' and writes[1].endswith(",0.5") and len(writes) == 2
    after = (out / "lathe_roughing.csv").read_text().splitlines()
    assert after[1].startswith("0.0,") and 0.3 <= float(after[-1].split(",")[0]) < 5.0
    assert (out / "session_inputs.csv").read_text() == '"time"\n0.0\n'     # no writes since the Reset



@pytest.mark.slow
def test_stop_time_and_sigterm_exit_zero(ncfmu_serve):
    served = ncfmu_serve("lathe_taper", "--no-cnc", "--speed", "0", "--stop-time", "2")
    assert served.wait(60) == 0, served.output
    assert "stopped at t = 2.000 s (stop time 2 s reached)" in served.output
    served = ncfmu_serve("lathe_taper", "--no-cnc", "--speed", "1")
    time.sleep(0.5)
    assert served.stop() == 0, served.output
    assert "stopped at t = " in served.output


# -- clients that misbehave, and several at once ------------------------------------------------------------------
ROGUE = textwrap.dedent("""
    import asyncio, sys
    from asyncua import Client, ua
    async def main():
        c = Client(sys.argv[1], timeout=10)
        await c.connect()
        idx = await c.get_namespace_index(sys.argv[2])
        class H:
            def datachange_notification(self, node, val, data): pass
        sub = await c.create_subscription(10, H())
        await sub.subscribe_data_change(c.get_node(ua.NodeId("x_axis.pos", idx)))
        node = c.get_node(ua.NodeId("panel.override", idx))
        print("flooding", flush=True)
        while True:                     # a flood of writes, until killed
            for v in (0.9, 1.0):
                await node.write_value(ua.DataValue(ua.Variant(v, ua.VariantType.Double)))
    asyncio.run(main())
""")


@pytest.mark.slow
def test_a_hung_client_and_a_flooding_client_killed_mid_session_do_not_stall_the_simulation(ncfmu_serve):
    served = ncfmu_serve("lathe_roughing", "--no-cnc", "--speed", "1")
    import socket
    hung = socket.create_connection(("127.0.0.1", int(served.endpoint.rsplit(":", 1)[1].split("/")[0])))
    hung.sendall(b"HELF\x40\x00\x00")      # the start of a Hello, then nothing: a client that hangs
    rogue = subprocess.Popen([sys.executable, "-c", ROGUE, served.endpoint, served.namespace],
                             stdout=subprocess.PIPE, text=True)
    try:
        assert rogue.stdout is not None and rogue.stdout.readline().strip() == "flooding"

        async def watch(seconds):
            async with connect(served) as p:
                t0, w0 = await p.time(), time.monotonic()
                await asyncio.sleep(seconds)
                return (await p.time() - t0) / (time.monotonic() - w0), await p.read("Simulation.overruns")
        # paced as the clock goes: a stalled or starved loop would fall far behind (a loaded machine may stall a
        # process for a few 100 ms now and then; the loop catches up after)
        pace, _ = run(watch(2.0))
        assert 0.8 <= pace <= 1.05                              # the flood does not stall the pacing
        os.kill(rogue.pid, signal.SIGKILL)                      # no goodbye: the connection just dies
        rogue.wait(10)
        pace, _ = run(watch(2.0))
        assert 0.8 <= pace <= 1.05
    finally:
        hung.close()
        if rogue.poll() is None:
            rogue.kill()
            rogue.wait()
    assert served.stop() == 0, served.output


@pytest.mark.slow
def test_three_clients_at_once(ncfmu_serve):
    served = ncfmu_serve("grinder_feed", "--no-cnc", "--speed", "2")

    async def client(k: int):
        async with connect(served) as p:
            seen = []
            for _ in range(20):
                seen.append(await p.time())
                await asyncio.sleep(0.02)
            if k == 0:
                await p.write("panel.override", 0.75)
            # every client sees the others' writes
            await p.wait_until("panel.feed_override", lambda v: v == 0.75, timeout=10)
            return seen

    async def all_three():
        return await asyncio.gather(*(client(k) for k in range(3)))
    for seen in run(all_three()):
        assert seen == sorted(seen) and seen[-1] > seen[0]


# -- security ----------------------------------------------------------------------------------------------------
def test_another_address_than_the_loopback_needs_a_user(project, capsys):
    assert main(["serve", "grinder_feed", "--endpoint", "opc.tcp://0.0.0.0:48499/ncfmu"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("ncfmu serve: --endpoint = 'opc.tcp://0.0.0.0:48499/ncfmu': serving beyond this machine "
                          "needs --user"), err
    assert main(["serve", "grinder_feed", "--user", "plc"]) == 2
    assert "--user 'plc': expected NAME:PASSWORD" in capsys.readouterr().err


@pytest.mark.slow
def test_with_users_only_users_connect_and_write(ncfmu_serve):
    served = ncfmu_serve("grinder_feed", "--no-cnc", "--speed", "1", "--user", "plc:secret")

    async def anonymous():
        c = Client(served.endpoint, timeout=5)
        with pytest.raises(Exception):       # noqa: B017  asyncua raises the server's refusal as it comes
            await c.connect()
            await c.get_node(ua.NodeId("Simulation.time", 2)).read_value()

    async def wrong_password():
        async with connect(served, "plc", "guess") as p:
            await p.time()

    async def user():
        async with connect(served, "plc", "secret") as p:
            await p.write("panel.override", 0.5)
            return await p.wait_until("panel.feed_override", lambda v: v == 0.5, timeout=5)
    async def endpoints():
        return await Client(served.endpoint, timeout=5).connect_and_get_server_endpoints()
    offered = run(endpoints())
    assert {t.TokenType for e in offered for t in e.UserIdentityTokens} == {ua.UserTokenType.UserName}
    run(anonymous())
    with pytest.raises(ua.UaStatusCodeError):
        run(wrong_password())
    assert run(user()) == 0.5
