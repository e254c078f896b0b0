"""The served variables' write rules and the endpoint rules, without a server; then the certificate policy and
the Python API against a served process (slow)."""

from __future__ import annotations

import asyncio
import math
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from ncfmu.errors import ConfigError
from ncfmu.serving import Point, Security, WriteRefused, check_endpoint, check_value
from ncfmu.serving.address_space import _unece_id

OVERRIDE = Point("panel.override", "panel", "override", "Real", "parameter", "tunable", "1", "feed override dial",
                 0.0, 1.5)
HOLD = Point("seq.feed_hold", "seq", "feed_hold", "Boolean", "input", "discrete", None, "", None, None)
N = Point("seq.block[1].N", "seq", "block[1].N", "Integer", "parameter", "tunable", None, "", 1.0, 10000.0)
POS = Point("x_axis.pos", "x_axis", "pos", "Real", "output", "continuous", "mm", "", None, None)
FIXED = Point("seq.block[1].Xd", "seq", "block[1].Xd", "Real", "parameter", "fixed", "mm", "", 0.0, None)


def status(point, value):
    with pytest.raises(WriteRefused) as err:
        check_value(point, value)
    return err.value.status


@given(st.floats(allow_nan=True, allow_infinity=True))
def test_a_double_is_taken_exactly_when_finite_and_inside_the_rule(x):
    if math.isfinite(x) and 0.0 <= x <= 1.5:
        assert check_value(OVERRIDE, x) == x
    else:
        assert status(OVERRIDE, x) == "BadOutOfRange"


@given(st.integers(-2 ** 31, 2 ** 31 - 1))
def test_an_int32_is_taken_inside_its_range(n):
    if 1 <= n <= 10000:
        assert check_value(N, n) == n
    else:
        assert status(N, n) == "BadOutOfRange"


@pytest.mark.parametrize("point, value, expected", [
    (OVERRIDE, True, "BadTypeMismatch"), (OVERRIDE, "0.5", "BadTypeMismatch"), (OVERRIDE, None, "BadTypeMismatch"),
    (HOLD, 1, "BadTypeMismatch"), (HOLD, 1.0, "BadTypeMismatch"),
    (N, 2.0, "BadTypeMismatch"), (N, True, "BadTypeMismatch"),
    (POS, 1.0, "BadNotWritable"), (FIXED, 0.4, "BadNotWritable"),
])
def test_wrong_types_and_read_only_variables(point, value, expected):
    assert status(point, value) == expected


def test_booleans_pass_as_they_are():
    assert check_value(HOLD, True) is True and check_value(HOLD, False) is False


@pytest.mark.parametrize("endpoint", ["opc.tcp://127.0.0.1:4840/ncfmu", "opc.tcp://localhost:4840/",
                                      "opc.tcp://127.0.0.2:4840/ncfmu", "opc.tcp://[::1]:4840/ncfmu"])
def test_the_loopback_needs_no_user(endpoint):
    check_endpoint(endpoint, Security())


@pytest.mark.parametrize("endpoint", ["opc.tcp://0.0.0.0:4840/ncfmu", "opc.tcp://192.168.1.5:4840/ncfmu",
                                      "opc.tcp://plc-net.example:4840/ncfmu"])
def test_any_other_address_needs_a_user_a_certificate_and_a_trust_list(endpoint, tmp_path):
    with pytest.raises(ConfigError, match="needs --user NAME:PASSWORD"):
        check_endpoint(endpoint, Security())
    users = {"plc": "secret"}
    with pytest.raises(ConfigError, match="needs --certificate and --private-key"):   # no policy None
        check_endpoint(endpoint, Security(users=users))
    with pytest.raises(ConfigError, match="needs --trust DIR"):
        check_endpoint(endpoint, Security(users, Path("c.der"), Path("k.pem")))
    check_endpoint(endpoint, Security(users, Path("c.der"), Path("k.pem"), tmp_path))
    check_endpoint(endpoint, Security(users, allow_insecure=True))          # said explicitly


@pytest.mark.parametrize("endpoint", ["http://127.0.0.1:4840/", "opc.tcp://127.0.0.1/ncfmu", "127.0.0.1:4840"])
def test_an_endpoint_is_opc_tcp_host_and_port(endpoint):
    with pytest.raises(ConfigError, match="must be opc.tcp://HOST:PORT/PATH"):
        check_endpoint(endpoint, Security())


def test_a_certificate_needs_its_key():
    with pytest.raises(ConfigError, match="needs --private-key"):
        check_endpoint("opc.tcp://127.0.0.1:4840/", Security(certificate=Path("cert.der")))


def test_unit_ids_are_the_unece_codes_packed():
    assert _unece_id("MMT") == 0x4D4D54 and _unece_id("SEC") == 0x534543


# -- against a served process ---------------------------------------------------------------------------------
@pytest.mark.slow
def test_basic256sha256_with_a_user(ncfmu_serve, tmp_path):
    from asyncua import Client, ua
    from asyncua.crypto.cert_gen import setup_self_signed_certificate
    from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256
    from cryptography.x509.oid import ExtendedKeyUsageOID

    async def certificates():
        for who, use in (("server", ExtendedKeyUsageOID.SERVER_AUTH), ("client", ExtendedKeyUsageOID.CLIENT_AUTH)):
            await setup_self_signed_certificate(tmp_path / f"{who}.pem", tmp_path / f"{who}.der",
                                                f"urn:ncfmu:test:{who}", "localhost", [use], {"commonName": who})
    asyncio.run(certificates())
    served = ncfmu_serve("grinder_feed", "--no-cnc", "--speed", "1", "--user", "plc:secret",
                         "--certificate", tmp_path / "server.der", "--private-key", tmp_path / "server.pem")

    async def plain():
        c = Client(served.endpoint, timeout=5)
        c.set_user("plc")
        c.set_password("secret")
        await c.connect()            # no NoSecurity endpoint: refused

    async def secure():
        c = Client(served.endpoint, timeout=10)
        c.set_user("plc")
        c.set_password("secret")
        await c.set_security(SecurityPolicyBasic256Sha256, str(tmp_path / "client.der"),
                             str(tmp_path / "client.pem"), mode=ua.MessageSecurityMode.SignAndEncrypt)
        async with c:
            idx = await c.get_namespace_index("urn:ncfmu:grinder_feed")
            await c.get_node(ua.NodeId("panel.override", idx)).write_value(
                ua.DataValue(ua.Variant(0.5, ua.VariantType.Double)))
            for _ in range(200):
                if await c.get_node(ua.NodeId("panel.feed_override", idx)).read_value() == 0.5:
                    return True
                await asyncio.sleep(0.01)
            return False
    async def endpoints():
        return await Client(served.endpoint, timeout=5).connect_and_get_server_endpoints()
    offered = asyncio.run(endpoints())
    assert offered and all(e.SecurityPolicyUri.endswith("#Basic256Sha256")
                           and e.SecurityMode == ua.MessageSecurityMode.SignAndEncrypt for e in offered)
    assert {t.TokenType for e in offered for t in e.UserIdentityTokens} == {ua.UserTokenType.UserName}
    with pytest.raises(Exception):       # noqa: B017  asyncua raises what the refused handshake gives
        asyncio.run(plain())
    assert asyncio.run(secure())


@pytest.mark.slow
def test_the_python_api_serves_and_returns_a_summary(project, tmp_path):
    import socket
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    script = (f"import ncfmu; s = ncfmu.serve('lathe_taper', endpoint='opc.tcp://127.0.0.1:{port}/ncfmu', "
              f"speed=0, stop_time=1.5, out={str(tmp_path)!r}, record=['x_axis.pos', 'seq.subcycle'], cnc=False); "
              "print(s.state, s.time, s.overruns, "
              "[p.name for p in s.files])")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split()[:3] == ["stopped", "1.5", "0"]
    assert "'session_inputs.csv'" in done.stdout and "'lathe_taper.csv'" in done.stdout
    lines = (tmp_path / "lathe_taper.csv").read_text().splitlines()
    assert lines[0] == '"time","x_axis.pos","seq.subcycle"' and len(lines) == 1 + 1501    # 0 .. 1.5 s at 1 ms
    assert (tmp_path / "session_inputs.csv").read_text() == '"time"\n0.0\n'   # no writes: a row changing nothing


@pytest.mark.slow
def test_a_port_in_use_is_one_line_and_status_2(project, capsys):
    import socket

    from ncfmu.cli import main
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        assert main(["serve", "lathe_taper", "--endpoint", f"opc.tcp://127.0.0.1:{port}/ncfmu"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1] == (f"ncfmu serve: --endpoint = 'opc.tcp://127.0.0.1:{port}/ncfmu': cannot listen there: "
                       "address already in use"), err


def test_a_user_is_admitted_by_name_and_password_only_both_right():
    """The one credential check of the OPC UA server and the web page (``Security.admits``): both words right, of
    one user; a wrong password, another user's, an unknown name, an empty or missing word are refused."""
    sec = Security(users={"plc": "s3cret", "hmi": "other"})
    assert sec.admits("plc", "s3cret") and sec.admits("hmi", "other")
    for name, password in (("plc", "other"), ("hmi", "s3cret"), ("plc", "s3cre"), ("plc", "s3cret "),
                           ("nobody", "s3cret"), ("", ""), (None, "s3cret"), ("plc", None), (None, None)):
        assert not sec.admits(name, password), (name, password)
    assert not Security().admits("", "")           # no users: nobody is admitted by name
