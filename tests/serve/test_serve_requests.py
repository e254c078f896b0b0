"""What a PLC or HMI asks of ``ncfmu serve`` beyond one good write: a result per node of a Write, per-argument
results of a Call, states and files that say what happened -- with asyncua's client and with open62541 (o6).

Each test starts a server process (a few seconds): ``slow`` but the command-line refusals."""

from __future__ import annotations

import asyncio
import json
import subprocess
import sys
import textwrap
import time

import pytest
from asyncua import ua
from serve_plc import assert_same_trajectory, connect, replay, run

from ncfmu.cli import main
from ncfmu.cosim.result import Result


def _dv(value, vtype):
    return ua.DataValue(ua.Variant(value, vtype))


D = ua.VariantType.Double


# -- Write: one StatusCode per node ------------------------------------------------------------------------
@pytest.mark.slow
def test_a_batch_write_applies_its_good_values_and_answers_each_node(ncfmu_serve):
    """OPC UA Part 4 5.11.4: each WriteValue gets its own StatusCode and the good ones are applied -- a bad value
    in a batch is not a ServiceFault for all of it."""
    served = ncfmu_serve("lathe_roughing", "--no-cnc", "--speed", "2")

    async def plc():
        async with connect(served) as p:
            ids = [p.node(n).nodeid for n in ("panel.override", "panel.override")]
            results = await p.client.uaclient.write_attributes(ids, [_dv(0.8, D), _dv(9.0, D)])
            assert [r.value for r in results] == [ua.StatusCodes.Good, ua.StatusCodes.BadOutOfRange]
            assert await p.wait_until("panel.feed_override", lambda v: v == 0.8, timeout=5) == 0.8
            names = ["seq.feed_override", "seq.no_such_input", "x_axis.pos", "seq.feed_hold", "panel.mfin_delay"]
            values = [_dv(0.5, D), _dv(1.0, D), _dv(1.0, D), _dv(1.0, D), _dv(0.25, D)]
            results = await p.client.uaclient.write_attributes([p.node(n).nodeid for n in names], values)
            assert [r.value for r in results] == [ua.StatusCodes.Good, ua.StatusCodes.BadNodeIdUnknown,
                                                  ua.StatusCodes.BadNotWritable, ua.StatusCodes.BadTypeMismatch,
                                                  ua.StatusCodes.Good]
            await p.wait_until("seq.feed_override", lambda v: v == 0.5, timeout=5)
            assert await p.read("seq.feed_override.forced") is True and await p.read("panel.mfin_delay") == 0.25
            assert await p.read("seq.feed_hold.forced") is False
            # a node of another namespace that does not exist either
            results = await p.client.uaclient.write_attributes([ua.NodeId("nothing", p.idx + 7)], [_dv(1.0, D)])
            assert [r.value for r in results] == [ua.StatusCodes.BadNodeIdUnknown]
            # one write to an unknown node alone: its own status, not a refusal of the request
            with pytest.raises(ua.UaStatusCodeError) as err:
                await p.write("seq.no_such_input", 1.0)
            assert err.value.code == ua.StatusCodes.BadNodeIdUnknown
    run(plc())
    assert served.stop() == 0, served.output
    assert "Traceback" not in served.output


#: The open62541 client (PyPI o6) in a process of its own: o6 without a licence runs in its "script mode", which
#: ends the process after 10 minutes -- never the test run's.
O6_CLIENT = textwrap.dedent("""
    import asyncio, json, sys
    import o6
    endpoint, idx = sys.argv[1], int(sys.argv[2])
    async def main():
        client = o6.Client(endpoint)
        await client.connect(createDefaultSubscription=False)
        try:
            node = lambda name: f"ns={idx};s={name}"
            codes = await client.write([node("panel.override"), node("panel.override"), node("seq.nothing")],
                                       [0.8, 9.0, 1.0])
            release = node("Simulation.Release")
            calls = [await client.call(node("Simulation"), release, args)
                     for args in ([], ["seq.feed_hold", "seq.start"], ["seq.feed_hold"])]
            override = await client.read(node("panel.override"))
            return {"codes": [c.name for c in codes], "calls": [c[0].name for c in calls], "override": override}
        finally:
            await client.disconnect()
    print("RESULT " + json.dumps(asyncio.run(main())))
""")


O6_READ = textwrap.dedent("""
    import asyncio, json, sys
    import o6
    async def main():
        client = o6.Client(sys.argv[1])
        await client.connect(createDefaultSubscription=False)
        try:
            return [await client.read(node) for node in sys.argv[2:]]
        finally:
            await client.disconnect()
    print("RESULT " + json.dumps(asyncio.run(main())))
""")


def o6_read(endpoint: str, *nodes: str) -> list:
    """The values of ``nodes`` (NodeId strings) as open62541's client reads them."""
    done = subprocess.run([sys.executable, "-c", O6_READ, endpoint, *nodes], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.rsplit("RESULT ", 1)[1])


@pytest.mark.slow
def test_open62541_gets_a_result_per_node_and_per_argument(ncfmu_serve):
    """The same with a second stack: open62541's client (PyPI o6)."""
    served = ncfmu_serve("lathe_roughing", "--no-cnc", "--speed", "2")

    async def namespace():
        async with connect(served) as p:
            return p.idx
    done = subprocess.run([sys.executable, "-c", O6_CLIENT, served.endpoint, str(run(namespace()))],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    got = json.loads(done.stdout.rsplit("RESULT ", 1)[1])
    plain = lambda name: name.replace("_", "").upper()            # noqa: E731  o6 says BAD_OUT_OF_RANGE
    assert [plain(c) for c in got["codes"]] == ["GOOD", "BADOUTOFRANGE", "BADNODEIDUNKNOWN"]
    assert [plain(c) for c in got["calls"]] == ["BADARGUMENTSMISSING", "BADTOOMANYARGUMENTS", "GOOD"]
    assert got["override"] == 0.8
    assert served.stop() == 0, served.output
    assert "Traceback" not in served.output


# -- Call: argument errors -----------------------------------------------------------------------------------
@pytest.mark.slow
def test_method_argument_errors_have_their_own_status_and_per_argument_results(ncfmu_serve):
    served = ncfmu_serve("lathe_roughing", "--no-cnc", "--speed", "2")

    async def plc():
        async with connect(served) as p:
            def request(method, *args):
                return ua.CallMethodRequest(ObjectId=p.node("Simulation").nodeid,
                                            MethodId=p.node(f"Simulation.{method}").nodeid, InputArguments=list(args))
            s = lambda v: ua.Variant(v, ua.VariantType.String)          # noqa: E731
            results = await p.client.uaclient.call([
                request("Release"),                                            # no argument
                request("Release", ua.Variant(1.0, D)),                        # a Double for the String
                request("Release", s("seq.feed_hold"), s("seq.start")),        # one too many
                request("Pause", s("now")),                                    # Pause takes none
                request("Release", s("x_axis.pos")),                           # not an input
                request("Release", s("seq.feed_hold")),                        # good (nothing forced: no change)
            ])
            got = [(r.StatusCode.value, [a.value for a in r.InputArgumentResults]) for r in results]
            good, mismatch = ua.StatusCodes.Good, ua.StatusCodes.BadTypeMismatch
            assert got == [(ua.StatusCodes.BadArgumentsMissing, []),
                           (ua.StatusCodes.BadTypeMismatch, [mismatch]),
                           (ua.StatusCodes.BadTooManyArguments, [good, ua.StatusCodes.BadTooManyArguments]),
                           (ua.StatusCodes.BadTooManyArguments, [ua.StatusCodes.BadTooManyArguments]),
                           (ua.StatusCodes.BadInvalidArgument, [ua.StatusCodes.BadInvalidArgument]),
                           (good, [good])]
            assert await p.read("Simulation.state") == "running"         # the refused Pause changed nothing
    run(plc())
    assert served.stop() == 0, served.output
    assert "Traceback" not in served.output and "BadUnexpectedError" not in served.output


# -- the Simulation's state, the writes' count across a Reset ----------------------------------------------------
@pytest.mark.slow
def test_the_state_reads_paused_once_pause_returned_and_a_reset_keeps_the_write_count(ncfmu_serve, tmp_path):
    served = ncfmu_serve("lathe_roughing", "--no-cnc", "--speed", "1", "--out", tmp_path / "served")

    async def plc():
        async with connect(served) as p:
            for _ in range(5):
                await p.call("Pause")
                assert await p.read("Simulation.state") == "paused"
                await p.call("Resume")
                assert await p.read("Simulation.state") == "running"
            await p.write("panel.override", 0.5)
            await p.write("seq.feed_hold", True)
            await p.call("Reset")
            await p.write("panel.override", 0.75)
            await p.call("Stop")
    run(plc())
    assert served.wait(30) == 0, served.output
    assert "; 3 writes" in served.output, served.output            # 2 before the Reset, 1 after


# -- replay: a session without writes, a refused tunable --------------------------------------------------------
@pytest.mark.slow
def test_a_session_without_writes_replays(ncfmu_serve, tmp_path):
    out = tmp_path / "served"
    served = ncfmu_serve("lathe_taper", "--no-cnc", "--speed", "0", "--stop-time", "1.5", "--out", out)
    assert served.wait(60) == 0, served.output
    assert_same_trajectory(Result.from_csv(out / "lathe_taper.csv"),
                           replay("lathe_taper", out / "lathe_taper.csv", out / "session_inputs.csv", tmp_path))
    # no warning about a setup the user did not make (no --user: no password to transfer in plain text)
    assert "plaintext" not in served.output and "Endpoints other than open" not in served.output, served.output


@pytest.mark.slow
def test_a_refused_tunable_write_leaves_the_run_and_its_replay_identical(ncfmu_serve, tmp_path):
    """OperatorPanel's repeat_every must be negative or longer than a pulse: 5e-324 passes the port's range and
    is refused by the panel's own rule. Refused, it must change nothing -- START pressed once at 0 s, never
    again (a panel left with the refused period would press it at every step) -- and the replay of the recorded
    writes gives the recorded run bit for bit."""
    out = tmp_path / "served"
    sets = ["panel.start_at=0"]
    served = ncfmu_serve("lathe_roughing", "--no-cnc", "--speed", "4", "--out", out, "--set", sets[0])

    async def plc():
        async with connect(served) as p:
            await p.wait_until("Simulation.time", lambda t: t > 1.0)
            with pytest.raises(ua.UaStatusCodeError) as err:
                await p.write("panel.repeat_every", 5e-324)
            assert err.value.code == ua.StatusCodes.BadOutOfRange
            assert await p.read("panel.repeat_every") == -1.0
            await p.write("panel.override", 0.5)                   # a good write beside it
            t = await p.time()
            await p.wait_until("Simulation.time", lambda now: now > t + 1.0)
            assert await p.read("panel.start") is False
            await p.call("Stop")
    run(plc())
    assert served.wait(60) == 0, served.output
    r = Result.from_csv(out / "lathe_roughing.csv")
    assert r["panel.start"][0] and not r["panel.start"][r.time >= 1.0].any()
    writes = (out / "session_inputs.csv").read_text()
    assert "repeat_every" not in writes and "panel.override" in writes
    assert_same_trajectory(r, replay("lathe_roughing", out / "lathe_roughing.csv", out / "session_inputs.csv",
                                     tmp_path, *sets))


# -- the command line: one line and exit 2, never a traceback -----------------------------------------------------
def test_a_port_out_of_range_and_a_certificate_that_is_none_are_one_line(project, capsys, tmp_path):
    assert main(["serve", "grinder_feed", "--endpoint", "opc.tcp://127.0.0.1:99999/ncfmu"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("ncfmu serve: --endpoint = 'opc.tcp://127.0.0.1:99999/ncfmu': ") and "port" in err, err
    assert err.count("\n") == 1
    bad = tmp_path / "passwd"
    bad.write_text("root:x:0:0:root:/root:/bin/bash\n")
    assert main(["serve", "grinder_feed", "--certificate", str(bad), "--private-key", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"ncfmu serve: --certificate = '{bad}': ") and err.count("\n") == 1, err
    assert main(["serve", "grinder_feed", "--certificate", str(tmp_path / "none.der"), "--private-key",
                 str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("ncfmu serve: --certificate = ") and err.count("\n") == 1, err


def test_on_lost_needs_a_watchdog_and_is_hold_or_release(capsys):
    assert main(["serve", "grinder_feed", "--on-lost", "release"]) == 2
    err = capsys.readouterr().err
    assert err == "ncfmu serve: --on-lost release: needs --watchdog S (what tells that a client is lost)\n", err
    with pytest.raises(SystemExit) as exit_:
        main(["serve", "grinder_feed", "--watchdog", "1", "--on-lost", "ignore"])
    assert exit_.value.code == 2 and "--on-lost: invalid choice: 'ignore'" in capsys.readouterr().err


# -- forces a PLC can live with: Simulation.forced and the watchdog -----------------------------------------------
#: A PLC that forces an input (subscribed, as PLCs are: asyncua keeps a session with subscriptions past its
#: connection), says so, then reads the time every 0.2 s until killed -- or, with "close", disconnects properly.
FORCING_PLC = textwrap.dedent("""
    import asyncio, sys
    from asyncua import Client, ua
    async def main():
        c = Client(sys.argv[1], timeout=10)
        await c.connect()
        idx = await c.get_namespace_index(sys.argv[2])
        class H:
            def datachange_notification(self, node, val, data): pass
        sub = await c.create_subscription(100, H())
        await sub.subscribe_data_change(c.get_node(ua.NodeId("x_axis.pos", idx)))
        await c.get_node(ua.NodeId(sys.argv[3], idx)).write_value(ua.DataValue(ua.Variant(True,
                                                                                          ua.VariantType.Boolean)))
        print("forced", flush=True)
        if sys.argv[4] == "close":
            await c.disconnect()
            return
        while True:
            await c.get_node(ua.NodeId("Simulation.time", idx)).read_value()
            await asyncio.sleep(0.2)
    asyncio.run(main())
""")


@pytest.mark.slow
def test_the_watchdog_releases_what_a_dead_or_closed_session_forced(ncfmu_serve, tmp_path):
    """``--on-lost release``: a lost session's forces fall back (the HMI's feed hold is lifted)."""
    out = tmp_path / "served"
    served = ncfmu_serve("lathe_roughing", "--no-cnc", "--speed", "1", "--watchdog", "1.0", "--on-lost", "release",
                         "--out", out)

    def plc(node: str, how: str) -> subprocess.Popen:
        proc = subprocess.Popen([sys.executable, "-c", FORCING_PLC, served.endpoint, served.namespace, node, how],
                                stdout=subprocess.PIPE, text=True)
        assert proc.stdout is not None and proc.stdout.readline().strip() == "forced"
        return proc
    crashed = plc("seq.feed_hold", "live")

    async def watch():
        async with connect(served) as p:
            async def heartbeat():                                  # a PLC's cycle: heard every 0.2 s
                while True:
                    await p.time()
                    await asyncio.sleep(0.2)
            beat = asyncio.create_task(heartbeat())
            await p.write("seq.feed_override", 0.5)                 # ours: we stay alive, it stays forced
            assert await p.wait_until("Simulation.forced", lambda v: v == ["seq.feed_hold", "seq.feed_override"],
                                      timeout=5)
            await asyncio.sleep(2.0)                                # alive (heard every 0.2 s): still forced
            assert await p.read("Simulation.forced") == ["seq.feed_hold", "seq.feed_override"]
            crashed.kill()                                          # no goodbye, its session lives on
            crashed.wait(10)
            killed = time.monotonic()
            assert await p.read("seq.feed_hold.forced") is True
            # released after the watchdog's 1 s of silence (counted from its last request, which a loaded
            # machine may have delayed: no lower bound here -- alive, it kept its force for 2 s above)
            await p.wait_until("seq.feed_hold.forced", lambda v: v is False, timeout=10)
            assert time.monotonic() - killed < 5.0
            assert await p.read("Simulation.forced") == ["seq.feed_override"]
            assert await p.read("seq.feed_override") == 0.5
            # a session that closes properly: its forces fall back at once
            loop = asyncio.get_running_loop()
            closing = await loop.run_in_executor(None, plc, "seq.start", "close")
            await loop.run_in_executor(None, closing.wait, 10)
            await p.wait_until("seq.start.forced", lambda v: v is False, timeout=1.0)
            assert await p.read("Simulation.forced") == ["seq.feed_override"]
            beat.cancel()
            await p.call("Stop")
    try:
        run(watch())
    finally:
        if crashed.poll() is None:
            crashed.kill()
    assert served.wait(30) == 0, served.output
    assert "watchdog: session" in served.output and "silent for 1 s" in served.output and "closed" in served.output
    writes = (out / "session_inputs.csv").read_text().splitlines()
    header = writes[0].split(",")
    hold = header.index('"seq.feed_hold"')
    assert [row.split(",")[hold] for row in writes[1:] if row.split(",")[hold]] == ["1", "release"]


def _forcing_plc(served, node: str) -> subprocess.Popen:
    """An HMI process that forced ``node`` true and lives (subscribed) until killed."""
    proc = subprocess.Popen([sys.executable, "-c", FORCING_PLC, served.endpoint, served.namespace, node, "live"],
                            stdout=subprocess.PIPE, text=True)
    assert proc.stdout is not None and proc.stdout.readline().strip() == "forced"
    return proc


@pytest.mark.slow
def test_a_lost_hmi_leaves_the_machine_in_feed_hold_until_a_client_resumes(ncfmu_serve, tmp_path):
    """``--on-lost hold`` (the default): a CNC that loses its HMI stops. The HMI's feed hold stays, the state
    says why, the held inputs cannot be released one by one; a new client's Resume releases them and the axes
    move on."""
    out = tmp_path / "served"
    served = ncfmu_serve("lathe_roughing", "--no-cnc", "--speed", "1", "--watchdog", "1.0", "--out", out)
    axes = ("x_axis.pos", "z_axis.pos")

    async def positions(p) -> list[float]:
        return [await p.read(a) for a in axes]

    async def operator():
        loop = asyncio.get_running_loop()
        async with connect(served) as p:
            await p.wait_until("seq.busy", lambda v: v is True, timeout=30)         # the cycle runs (START 0.1 s)
            hmi = await loop.run_in_executor(None, _forcing_plc, served, "seq.feed_hold")
            try:
                assert await p.read("seq.feed_hold") is True
                hmi.kill()                                  # the HMI dies with its feed hold on
                await loop.run_in_executor(None, hmi.wait, 10)
            finally:
                if hmi.poll() is None:
                    hmi.kill()
            killed = time.monotonic()
            await p.wait_until("Simulation.state", lambda s: s == "held", timeout=10)
            assert time.monotonic() - killed < 5.0
            reason = await p.read("Simulation.reason")
            assert reason.startswith("client lost: session ") and "silent for 1 s" in reason, reason
            assert "feed hold on seq.feed_hold" in reason and "Resume" in reason, reason
            assert await p.read("Simulation.forced") == ["seq.feed_hold"]
            # held: the simulation runs on (the spindle turns, time goes on), the axes stay put (from 0.5 s
            # after the hold was seen: at rest then, the feed hold's deceleration long over)
            held = await p.time()
            await p.wait_until("Simulation.time", lambda t: t > held + 0.5, timeout=20)
            t0, at = await p.time(), await positions(p)
            await p.wait_until("Simulation.time", lambda t: t > t0 + 1.0, timeout=20)
            assert await positions(p) == pytest.approx(at, abs=1e-3)
            assert await p.read("Simulation.state") == "held"
            # a held input is released by Resume only (not by Release, nor by writing it)
            for attempt in (p.call("Release", "seq.feed_hold"), p.write("seq.feed_hold", False),
                            p.write("seq.feed_hold.forced", False), p.call("Pause")):
                with pytest.raises(ua.UaStatusCodeError) as err:
                    await attempt
                assert err.value.code == ua.StatusCodes.BadInvalidState
            assert await p.read("seq.feed_hold.forced") is True
            await p.call("Resume")                           # the new client acknowledges: cycle start
            assert await p.read("Simulation.state") == "running" and await p.read("Simulation.reason") == ""
            assert await p.read("Simulation.forced") == [] and await p.read("seq.feed_hold.forced") is False
            await p.wait_until("seq.feed_hold", lambda v: v is False, timeout=5)     # the panel's again, off
            end = time.monotonic() + 10
            while max(abs(a - b) for a, b in zip(await positions(p), at)) < 0.1:    # the axes move again
                assert time.monotonic() < end, "the axes did not move after Resume"
                await asyncio.sleep(0.05)
            await p.call("Stop")
    run(operator())
    assert served.wait(30) == 0, served.output
    assert "watchdog: session" in served.output and "client lost" in served.output
    writes = (out / "session_inputs.csv").read_text().splitlines()
    hold = writes[0].split(",").index('"seq.feed_hold"')
    # the HMI's force, the hold's (the same value: true), Resume's release
    assert [row.split(",")[hold] for row in writes[1:] if row.split(",")[hold]] == ["1", "1", "release"]


# -- security: certificates, a trust list, who the server says it is ---------------------------------------------
def _client_certificate(folder, name: str):
    """A client's key and self-signed certificate (application URI urn:ncfmu-test:NAME), as a PLC or UaExpert has."""
    from asyncua.crypto import cert_gen
    from cryptography import x509
    from cryptography.hazmat.primitives.serialization import Encoding
    from cryptography.x509.oid import ExtendedKeyUsageOID
    key = cert_gen.generate_private_key()
    uri = f"urn:ncfmu-test:{name}"
    cert = cert_gen.generate_self_signed_app_certificate(
        key, name, {}, [x509.UniformResourceIdentifier(uri), x509.DNSName("localhost")],
        extended=[ExtendedKeyUsageOID.CLIENT_AUTH])
    (folder / f"{name}-key.pem").write_bytes(cert_gen.dump_private_key_as_pem(key))
    (folder / f"{name}.der").write_bytes(cert.public_bytes(Encoding.DER))
    return folder / f"{name}.der", folder / f"{name}-key.pem", uri


@pytest.mark.slow
def test_a_trust_list_rejects_an_unknown_client_certificate_and_accepts_a_trusted_one(ncfmu_serve, tmp_path,
                                                                                       capsys):
    from asyncua import Client
    from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256
    from cryptography import x509
    server_dir, trusted_dir, clients = tmp_path / "server", tmp_path / "trusted", tmp_path / "clients"
    trusted_dir.mkdir()
    clients.mkdir()
    assert main(["serve", "--make-certificate", str(server_dir)]) == 0
    assert "application URI urn:ncfmu:serve" in capsys.readouterr().out
    server_cert = server_dir / "ncfmu.der"
    cert = x509.load_der_x509_certificate(server_cert.read_bytes())
    san = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert san.get_values_for_type(x509.UniformResourceIdentifier) == ["urn:ncfmu:serve"]
    assert main(["serve", "--make-certificate", str(server_dir)]) == 2          # a key is never overwritten
    assert "exists there already" in capsys.readouterr().err
    plc = _client_certificate(clients, "plc")
    stranger = _client_certificate(clients, "stranger")
    (trusted_dir / "plc.der").write_bytes(plc[0].read_bytes())
    served = ncfmu_serve("grinder_feed", "--no-cnc", "--speed", "1", "--certificate", server_cert,
                         "--private-key", server_dir / "ncfmu-key.pem", "--trust", trusted_dir)

    async def session(client_cert, key, uri):
        c = Client(served.endpoint, timeout=5)
        c.application_uri = uri
        await c.set_security(SecurityPolicyBasic256Sha256, certificate=str(client_cert), private_key=str(key),
                             server_certificate=str(server_cert))
        async with c:
            idx = await c.get_namespace_index(served.namespace)
            build = await c.nodes.server.get_child(["0:ServerStatus", "0:BuildInfo"])
            info = {n: await (await build.get_child([f"0:{n}"])).read_value()
                    for n in ("ProductName", "ManufacturerName", "SoftwareVersion", "ProductUri")}
            return await c.get_node(ua.NodeId("Simulation.state", idx)).read_value(), info
    state, info = run(session(*plc))
    import ncfmu
    assert state == "running"
    assert info == {"ProductName": "ncfmu", "ManufacturerName": "ncfmu", "SoftwareVersion": ncfmu.__version__,
                    "ProductUri": "urn:ncfmu"}
    with pytest.raises(ua.UaStatusCodeError) as refused:
        run(session(*stranger))
    assert refused.value.code == ua.StatusCodes.BadCertificateUntrusted
    assert served.stop() == 0, served.output


def test_off_the_loopback_no_security_policy_none_unless_allowed(project, capsys, tmp_path):
    anywhere = "opc.tcp://0.0.0.0:48499/ncfmu"
    assert main(["serve", "grinder_feed", "--endpoint", anywhere, "--user", "plc:secret"]) == 2
    err = capsys.readouterr().err
    assert "needs --certificate and --private-key" in err and "--allow-insecure" in err and err.count("\n") == 1
    assert main(["serve", "grinder_feed", "--endpoint", anywhere, "--user", "plc:secret", "--certificate", "c.der",
                 "--private-key", "k.pem"]) == 2
    assert "needs --trust DIR" in capsys.readouterr().err
    assert main(["serve", "grinder_feed", "--trust", str(tmp_path)]) == 2
    assert "--trust" in capsys.readouterr().err


# -- OPC UA for CNC Systems (OPC 40502) --------------------------------------------------------------------------
@pytest.mark.slow
def test_the_cnc_companion_model_shows_each_axis_position_and_the_channel(ncfmu_serve):
    """An HMI that speaks OPC 40502 and not ncfmu: Objects/CncInterface (a CncInterfaceType), its CncAxisList
    with one CncAxisType per servo axis whose ActPos is the axis's position output, its CncChannelList with the
    sequencer's program status, block and override."""
    served = ncfmu_serve("lathe_roughing", "--speed", "2", "--cnc")

    async def hmi():
        async with connect(served) as p:
            c = p.client
            cnc = await c.get_namespace_index("http://opcfoundation.org/UA/CNC")
            await p.wait_until("seq.busy", lambda v: v is True, timeout=30)
            await p.wait_until("x_axis.pos", lambda x: x < 29.0, timeout=30)     # moving in
            await p.call("Pause")
            await asyncio.sleep(0.1)
            iface = await c.nodes.objects.get_child([f"{p.idx}:CncInterface"])
            assert (await iface.read_type_definition()) == ua.NodeId(1007, cnc)          # CncInterfaceType
            assert await (await iface.get_child([f"{cnc}:VendorName"])).read_value() == "ncfmu"
            axes = await (await iface.get_child([f"{cnc}:CncAxisList"])).get_children()
            names = {}
            for axis in axes:
                name = (await axis.read_browse_name()).Name
                assert (await axis.read_type_definition()) == ua.NodeId(1004, cnc)       # CncAxisType
                pos = await axis.get_child([f"{cnc}:PosDirect"])
                names[name] = await (await pos.get_child([f"{cnc}:ActPos"])).read_value()
                assert names[name] == await p.read(f"{name}.pos")
                cmd = await (await pos.get_child([f"{cnc}:CmdPos"])).read_value()
                assert cmd == await p.read(f"{name}.pos_cmd")
                rem = await (await pos.get_child([f"{cnc}:RemDist"])).read_value()
                assert rem == pytest.approx(cmd - names[name], abs=1e-12)
                eu = await (await pos.get_child([f"{cnc}:EngineeringUnits"])).read_value()
                assert eu.DisplayName.Text == "mm" and eu.UnitId == int.from_bytes(b"MMT", "big")
                await (await pos.get_child([f"{cnc}:EURange"])).read_value()
            assert set(names) == {"x_axis", "z_axis"}
            assert names["x_axis"] < 29.0
            channels = await (await iface.get_child([f"{cnc}:CncChannelList"])).get_children()
            assert [(await ch.read_browse_name()).Name for ch in channels] == ["seq"]
            ch = channels[0]
            read = lambda name: ch.get_child([f"{cnc}:{name}"])                   # noqa: E731
            assert await (await read("ActProgramStatus")).read_value() == 1          # Running
            assert await (await read("ActProgramName")).read_value() == "lathe_roughing"
            assert await (await read("ActProgramBlock")).read_value() == str(await p.read("seq.line"))
            assert await (await read("ActOverride")).read_value() == 100.0
            assert await (await read("ActOperationMode")).read_value() == 2          # Automatic
            # the lathe's spindle drive (a register cycle commands no speed: the spindle stands)
            spindles = await (await iface.get_child([f"{cnc}:CncSpindleList"])).get_children()
            assert [(await sp.read_browse_name()).Name for sp in spindles] == ["spindle"]
            act_speed = await (await spindles[0].get_child([f"{cnc}:ActSpeed"])).read_value()
            assert act_speed == await p.read("spindle.speed")
            # the second stack reads the same typed nodes (paused: nothing moves meanwhile)
            loop = asyncio.get_running_loop()
            ids = [(await axis.get_child([f"{cnc}:PosDirect", f"{cnc}:ActPos"])).nodeid.to_string() for axis in axes]
            read_by_o6 = await loop.run_in_executor(None, lambda: o6_read(served.endpoint, *ids))
            assert sorted(read_by_o6) == sorted(names.values())
            await p.call("Resume")
            await p.write("seq.feed_hold", True)
            await p.wait_until("seq.feed_hold.forced", lambda v: v is True, timeout=5)
            await asyncio.sleep(0.1)
            assert await (await read("ActProgramStatus")).read_value() == 3          # Interrupted
            assert await (await read("FeedHold")).read_value() is True
    run(hmi())
    assert served.stop() == 0, served.output


async def _cnc_variables(c, iface) -> dict[str, ua.DataValue]:
    """Every Variable under the CncInterface object (through its objects and variables), path -> DataValue."""
    found: dict[str, ua.DataValue] = {}

    async def walk(node, path: str) -> None:
        for child in await node.get_children():
            name = (await child.read_browse_name()).Name
            cls = await child.read_node_class()
            here = f"{path}/{name}"
            if cls == ua.NodeClass.Variable:
                read = ua.ReadValueId(NodeId=child.nodeid, AttributeId=ua.AttributeIds.Value)
                (found[here],) = await c.uaclient.read(ua.ReadParameters(NodesToRead=[read]))
            if cls in (ua.NodeClass.Object, ua.NodeClass.Variable):
                await walk(child, here)
    await walk(iface, "CncInterface")
    return found


#: What ncfmu feeds of the companion model (build_cnc_model's docstring), relative to each object; every other
#: variable there is one it has nothing for: a mandatory one says Bad_NotConnected, an optional one is not there.
FED_AXIS = {"ActStatus", "IsReferenced", "IsRotational", "IsVirtual", "IsInactive", "ActChannel",
            "ActTorque", "ActTorque/EngineeringUnits", "ActTorque/EURange",
            *(f"{w}{p}" for w in ("PosDirect", "PosIndirect")
              for p in ("", "/ActPos", "/CmdPos", "/RemDist", "/EngineeringUnits", "/EURange"))}
FED_SPINDLE = {"ActStatus", "ActTurnDirection", "IsInactive", "IsVirtual", "ActChannel",
               *(f"{v}{p}" for v in ("ActSpeed", "CmdSpeed", "ActTorque", "ActPower")
                 for p in ("", "/EngineeringUnits", "/EURange"))}
FED_CHANNEL = {"ActProgramStatus", "ActStatus", "ActProgramBlock", "FeedHold", "ActProgramName",
               "ActMainProgramName", "ActOperationMode", "CmdOperationMode", "Id", "BlockMode",
               *(f"{v}{p}" for v in ("ActOverride", "CmdOverride") for p in ("", "/EngineeringUnits", "/EURange"))}
FED_INTERFACE = {"VendorName", "VendorRevision", "Version", "CncTypeName"}


def _fed(path: str) -> bool:
    if path.endswith("/EngineeringUnits"):
        return True             # a unit is the NodeSet's (N·m, W, %, min⁻¹, mm/min: ncfmu's ports' units)
    parts = path.split("/")[1:]
    if len(parts) == 1:
        return parts[0] in FED_INTERFACE
    rest = "/".join(parts[2:])
    fed = {"CncAxisList": FED_AXIS, "CncSpindleList": FED_SPINDLE, "CncChannelList": FED_CHANNEL}[parts[0]]
    return rest in fed


@pytest.mark.slow
def test_no_cnc_companion_variable_reads_good_without_a_value(ncfmu_serve):
    """A client reading the companion model sees a value or a status that says why there is none: Good with a
    Null value (an EURange, an EngineeringUnits, a G-function list asyncua left empty) is neither. What ncfmu does
    not feed is Bad_NotConnected, never the 0 asyncua fills a Double with (ActLoad, ActPower, ZeroOffset, a
    spindle override of 0 %: an HMI shows them as measured); what it feeds reads Good; the ranges are the ports'."""
    served = ncfmu_serve("lathe_roughing", "--speed", "2", "--cnc")

    async def hmi():
        async with connect(served) as p:
            await p.wait_until("seq.busy", lambda v: v is True, timeout=30)
            iface = await p.client.nodes.objects.get_child([f"{p.idx}:CncInterface"])
            return await _cnc_variables(p.client, iface), await p.read("spindle.speed_max"), \
                await p.read("x_axis.torque_max")
    found, speed_max, torque_max = run(hmi())
    assert len(found) > 100
    empty = sorted(path for path, dv in found.items() if dv.StatusCode.is_good() and dv.Value.Value is None)
    assert empty == [], empty
    good = {path for path, dv in found.items() if dv.StatusCode.is_good()}
    assert sorted(p for p in good if not _fed(p)) == []
    assert sorted(p for p in found if _fed(p) and p not in good and not p.endswith("/EngineeringUnits")) == []
    bad = {dv.StatusCode.value for path, dv in found.items() if path not in good}
    assert bad == {ua.StatusCodes.BadNotConnected}
    # the mandatory variables ncfmu has nothing for are there, saying so; the optional ones are not
    for path in ("CncAxisList/x_axis/ActLoad", "CncAxisList/x_axis/ZeroOffset", "CncSpindleList/spindle/ActOverride",
                 "CncChannelList/seq/ActFeedrate", "CncChannelList/seq/PosTcpBcsX/ActPos"):
        assert f"CncInterface/{path}" in found and f"CncInterface/{path}" not in good, path
    for path in ("Fix", "CncChannelList/seq/ActProgramLine", "CncChannelList/seq/ActMainProgramFileOffset"):
        assert f"CncInterface/{path}" not in found, path
    rng = {path: found[f"CncInterface/{path}/EURange"].Value.Value for path in (
        "CncChannelList/seq/ActOverride", "CncSpindleList/spindle/CmdSpeed", "CncAxisList/x_axis/ActTorque")}
    assert (rng["CncChannelList/seq/ActOverride"].Low, rng["CncChannelList/seq/ActOverride"].High) == (0.0, 150.0)
    assert (rng["CncSpindleList/spindle/CmdSpeed"].Low, rng["CncSpindleList/spindle/CmdSpeed"].High) == \
        (-speed_max, speed_max)
    assert (rng["CncAxisList/x_axis/ActTorque"].Low, rng["CncAxisList/x_axis/ActTorque"].High) == \
        (-torque_max, torque_max)
    assert served.stop() == 0, served.output
