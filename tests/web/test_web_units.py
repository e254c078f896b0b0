"""The live page's server without a browser or a served system: its address rules, and how frames are made and
handed to pages (decimated, the whole state to a page that fell behind) from snapshots, never from the
simulation."""

from __future__ import annotations

import asyncio
import json
import subprocess
import sys

import pytest
from hypothesis import given
from hypothesis import strategies as st

from ncfmu.errors import ConfigError
from ncfmu.serving import Point, Security, Snapshot, WriteRefused
from ncfmu.web import BACKLOG, START_PULSE, WebFront, _Page, check_address, parse_address

POINTS = [Point("x_axis.pos", "x_axis", "pos", "Real", "output", "continuous", "mm", "actual position", None, None),
          Point("x_axis.pos_cmd", "x_axis", "pos_cmd", "Real", "input", "continuous", "mm", "", None, None),
          Point("seq.feed_hold", "seq", "feed_hold", "Boolean", "input", "discrete", None, "", None, None),
          Point("seq.feed_override", "seq", "feed_override", "Real", "input", "discrete", "1", "", 0.0, 1.5),
          Point("seq.program", "seq", "program", "String", "parameter", "fixed", None, "", None, None)]


class Runner:
    """The simulation thread as the page reads it: its newest snapshot (``latest``), set by the test."""

    def __init__(self) -> None:
        self.snap = Snapshot(0.0, {}, {})
        self.state, self.feed_holds = "running", ["seq.feed_hold"]

    def latest(self) -> Snapshot:
        return self.snap


class Live:
    """What the page reads of the OPC UA side: its points and the runner (no server, no simulation)."""

    system_name = "fake"

    def __init__(self) -> None:
        self.points = {p.name: p for p in POINTS}
        self.runner = Runner()


def test_addresses():
    assert parse_address("127.0.0.1:8080").loopback and parse_address("localhost:0").port == 0
    assert parse_address("[::1]:9000").host == "::1" and parse_address("[::1]:9000").loopback
    assert not parse_address("0.0.0.0:8080").loopback
    for bad in ("8080", "127.0.0.1:", "127.0.0.1:http", "127.0.0.1:70000", ":8080"):
        with pytest.raises(ConfigError, match=r"--web = .*must be HOST:PORT"):
            parse_address(bad)


def test_off_the_loopback_the_page_needs_users_and_https():
    wide = parse_address("0.0.0.0:8080")
    check_address(parse_address("127.0.0.1:8080"), Security())
    with pytest.raises(ConfigError, match="needs --user NAME:PASSWORD"):
        check_address(wide, Security())
    with pytest.raises(ConfigError, match="needs --certificate and --private-key"):
        check_address(wide, Security(users={"op": "pw"}))
    check_address(wide, Security(users={"op": "pw"}, allow_insecure=True))


def test_the_cli_refuses_an_open_page_in_one_line():
    """Before anything is built: exit status 2 and one line naming the option, the value and the rule."""
    done = subprocess.run([sys.executable, "-m", "ncfmu.cli", "serve", "lathe_taper", "--web", "0.0.0.0:8080"],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2
    said = done.stderr.strip().splitlines()
    assert len(said) == 1 and "--web = '0.0.0.0:8080'" in said[0] and "needs --user" in said[0], done.stderr


def decode(frame: bytes) -> dict:
    assert frame.startswith(b"data: ") and frame.endswith(b"\n\n")
    return json.loads(frame[6:])


def test_frames_carry_what_changed_and_the_whole_state_to_a_new_page():
    live = Live()
    front = WebFront(live, parse_address("127.0.0.1:0"), Security())        # type: ignore[arg-type]
    assert front.machine["axes"] == ["x_axis"] and front.machine["controllers"][0]["program"] == "seq.program"
    live.runner.snap = Snapshot(0.01, {"x_axis.pos": 1.5, "seq.program": "G00 X1\nM30", "seq.feed_hold": False}, {})
    delta = front._frame()
    assert decode(delta)["values"] == {"x_axis.pos": 1.5, "seq.program": "G00 X1\nM30", "seq.feed_hold": False}
    assert front._frame() is None                            # nothing new: nothing sent
    live.runner.snap = Snapshot(0.02, {"x_axis.pos": 1.5, "seq.program": "G00 X1\nM30", "seq.feed_hold": True},
                                {"seq.feed_hold": True}, "running")
    d, w = decode(front._frame()), decode(front._whole())
    assert d["values"] == {"seq.feed_hold": True} and d["forced"] == ["seq.feed_hold"] and d["time"] == 0.02
    assert w["values"]["seq.program"] == "G00 X1\nM30" and w["values"]["x_axis.pos"] == 1.5
    live.runner.snap = Snapshot(0.03, {"x_axis.pos": float("nan")}, {})
    assert decode(front._frame())["values"] == {"x_axis.pos": "nan"}      # JSON has no NaN: the word


def test_a_page_that_falls_behind_gets_the_whole_state_not_a_growing_queue():
    async def main() -> None:
        page = _Page()
        page.stale = False
        for k in range(BACKLOG):
            page.push(b"%d" % k)
        assert not page.stale and page.frames.qsize() == BACKLOG
        page.push(b"one too many")
        assert page.stale and page.frames.empty()      # the broadcaster sends it the whole state next
        page.end()
        assert await page.frames.get() is None          # the server stops: its stream ends
    asyncio.run(main())


@given(st.lists(st.tuples(st.floats(allow_nan=False, allow_infinity=False, width=32), st.booleans(), st.booleans()),
                min_size=1, max_size=12),
       st.integers(0, 11))
def test_a_page_that_joins_late_and_applies_deltas_sees_what_one_there_from_the_start_sees(steps, joins):
    """However the snapshots come (each frame decimates those since the last), the whole state a page gets when
    it joins plus every delta after it is the same as the deltas from the start: one machine for every page."""
    live = Live()
    front = WebFront(live, parse_address("127.0.0.1:0"), Security())        # type: ignore[arg-type]
    first: dict = {}
    late: dict | None = None
    for k, (x, hold, skip_frame) in enumerate(steps):
        forced = {"seq.feed_hold": True} if hold else {}
        live.runner.snap = Snapshot(0.01 * k, {"x_axis.pos": x, "seq.feed_hold": hold}, forced)
        if skip_frame and k != len(steps) - 1:            # a frame takes every snapshot since the last one
            continue
        frame = front._frame()
        if frame is None:
            continue
        delta, whole = decode(frame), decode(front._whole())
        merge(first, delta)
        if late is None and k >= joins:
            late = whole
        elif late is not None:
            merge(late, delta)
    assert late is None or late == first
    assert first["values"]["x_axis.pos"] == steps[-1][0] and first["forced"] == (["seq.feed_hold"] if steps[-1][1]
                                                                                 else [])


def merge(state: dict, delta: dict) -> None:
    """What the page's apply() does with a frame."""
    state.setdefault("values", {}).update(delta.get("values", {}))
    state.update({k: v for k, v in delta.items() if k != "values"})


class Commands(Live):
    """A LiveServer's commands, recorded: what each button asks of the OPC UA side's own implementation."""

    def __init__(self) -> None:
        super().__init__()
        self.points["seq.start"] = Point("seq.start", "seq", "start", "Boolean", "input", "discrete", None, "",
                                         None, None)
        self.said: list[tuple] = []

    async def call(self, method: str) -> None:
        self.said.append(("call", method))

    async def write(self, name: str, value: object) -> None:
        self.said.append(("write", name, value))
        if value == 9.0:
            raise WriteRefused("BadOutOfRange", f"{name} = 9.0: must be <= 1.5")

    async def release(self, name: str) -> None:
        self.said.append(("release", name))


async def steps(runner: Runner, step: float = 0.001) -> None:
    """The simulation stepping (the snapshot's time moves on every 10 ms of wall time)."""
    while True:
        await asyncio.sleep(0.01)
        runner.snap = Snapshot(runner.snap.time + step, runner.snap.values, runner.snap.forced)


def test_the_buttons_are_the_opc_ua_sides_commands_and_users_are_asked_for():
    from aiohttp import encode_basic_auth
    from aiohttp.test_utils import TestClient, TestServer
    live = Commands()
    front = WebFront(live, parse_address("127.0.0.1:0"), Security(users={"op": "secret"}))  # type: ignore[arg-type]

    async def main() -> None:
        simulation = asyncio.create_task(steps(live.runner))
        async with TestClient(TestServer(front._app(), host="127.0.0.1")) as client:
            front.address = parse_address(f"127.0.0.1:{client.port}")
            assert (await client.get("/")).status == 401
            wrong = {"Authorization": encode_basic_auth("op", "wrong")}
            assert (await client.get("/", headers=wrong)).status == 401
            auth = {"Authorization": encode_basic_auth("op", "secret")}
            page = await client.get("/", headers=auth)
            assert page.status == 200 and "default-src 'self'" in page.headers["Content-Security-Policy"]
            assert 'data-action="hold"' in await page.text()
            for action in ("hold", "release", "reset", "start"):
                assert (await client.post(f"/api/action/{action}", json={}, headers=auth)).status == 200
            refused = await client.post("/api/action/override", json={"value": 9.0}, headers=auth)
            said = (await refused.json())["error"]
            assert refused.status == 409 and said == "seq.feed_override = 9.0: must be <= 1.5"
            assert (await client.get("/static/..%2fserve%2f__init__.py", headers=auth)).status == 404
        simulation.cancel()
    asyncio.run(main())
    assert live.said == [("write", "seq.feed_hold", True), ("release", "seq.feed_hold"), ("call", "Reset"),
                         ("write", "seq.start", True), ("release", "seq.start"),
                         ("write", "seq.feed_override", 9.0)]


def _requests(front: WebFront, bind: str, requests: list[tuple[str, str, dict[str, str], object]]) -> list[int]:
    """Each (method, path, headers, json body) against ``front`` served on ``bind``'s host: the statuses."""
    from aiohttp.test_utils import TestClient, TestServer

    async def main() -> list[int]:
        async with TestClient(TestServer(front._app(), host="127.0.0.1")) as client:
            front.address = parse_address(bind.replace(":0", f":{client.port}"))
            port = client.port
            statuses = []
            for method, path, headers, body in requests:
                headers = {k: v.replace("PORT", str(port)) for k, v in headers.items()}
                said = await client.request(method, path, headers=headers, json=body)
                statuses.append(said.status)
            return statuses
    return asyncio.run(main())


def test_a_page_served_on_every_interface_is_reached_by_the_machines_own_name():
    """Bound to 0.0.0.0 the page is reached as http://192.168.1.5:PORT or http://plant-pc:PORT (the users are
    asked for there); a POST from another site is still refused by its Origin."""
    from aiohttp import encode_basic_auth
    live = Commands()
    front = WebFront(live, parse_address("0.0.0.0:0"), Security(users={"op": "secret"},  # type: ignore[arg-type]
                                                                allow_insecure=True))
    auth = {"Authorization": encode_basic_auth("op", "secret")}
    statuses = _requests(front, "0.0.0.0:0", [
        ("GET", "/", {**auth, "Host": "192.168.1.5:PORT"}, None),
        ("GET", "/", {**auth, "Host": "plant-pc:PORT"}, None),
        ("POST", "/api/action/hold", {**auth, "Host": "plant-pc:PORT", "Origin": "http://plant-pc:PORT"}, {}),
        ("POST", "/api/action/hold", {**auth, "Host": "plant-pc:PORT", "Origin": "http://evil.example"}, {}),
        ("GET", "/", {"Host": "plant-pc:PORT"}, None)])
    assert statuses == [200, 200, 200, 403, 401]
    assert live.said == [("write", "seq.feed_hold", True)]


def test_an_override_too_large_for_a_double_is_refused_naming_it():
    """{"value": 1e400} parses as inf and 10**400 as an int no float holds: both refused (409) with the rule,
    never a server error."""
    front = WebFront(Live(), parse_address("127.0.0.1:0"), Security())  # type: ignore[arg-type]
    live = front.live

    async def write(name: str, value: object) -> None:
        from ncfmu.serving.address_space import check_value
        check_value(live.points[name], value)
    live.write = write  # type: ignore[attr-defined]
    front.machine["controllers"] = [{"name": "seq"}]
    from aiohttp.test_utils import TestClient, TestServer

    async def main() -> list[tuple[int, str]]:
        async with TestClient(TestServer(front._app(), host="127.0.0.1")) as client:
            front.address = parse_address(f"127.0.0.1:{client.port}")
            said = []
            for body in ('{"value": 1e400}', '{"value": 1' + "0" * 400 + "}", '{"value": NaN}'):
                r = await client.post("/api/action/override", data=body,
                                      headers={"Content-Type": "application/json"})
                said.append((r.status, (await r.json())["error"]))
            return said
    said = asyncio.run(main())
    assert [s for s, _ in said] == [409, 409, 409], said
    assert all(text.startswith("seq.feed_override = ") for _, text in said), said


def test_on_port_80_the_browser_names_the_host_without_the_port():
    """http://localhost/ sends ``Host: localhost`` (the scheme's own port is left out): still this server."""
    front = WebFront(Commands(), parse_address("127.0.0.1:80"), Security())  # type: ignore[arg-type]
    statuses = _requests(front, "127.0.0.1:80", [
        ("GET", "/", {"Host": "localhost"}, None), ("GET", "/", {"Host": "127.0.0.1"}, None),
        ("GET", "/", {"Host": "localhost:80"}, None), ("GET", "/", {"Host": "evil.example"}, None),
        ("POST", "/api/action/hold", {"Host": "localhost", "Origin": "http://localhost"}, {})])
    assert statuses == [200, 200, 200, 421, 200]


def test_an_override_on_a_system_without_a_cycle_controller_is_refused_not_ignored():
    live = Commands()
    front = WebFront(live, parse_address("127.0.0.1:0"), Security())  # type: ignore[arg-type]
    front.machine["controllers"] = []
    said = asyncio.run(front.act("override", 0.5))
    assert said == "the system has no feed-override input" and live.said == []


def test_a_malformed_override_body_is_a_clear_400_never_a_server_error():
    """Bad JSON, JSON nested deeper than the parser recurses (4 kB of brackets), no value: 400 with the rule;
    a body beyond the 4 kB limit: 413."""
    live = Commands()
    front = WebFront(live, parse_address("127.0.0.1:0"), Security())  # type: ignore[arg-type]
    from aiohttp.test_utils import TestClient, TestServer

    async def main() -> list[int]:
        async with TestClient(TestServer(front._app(), host="127.0.0.1")) as client:
            front.address = parse_address(f"127.0.0.1:{client.port}")
            statuses = []
            for body in ("{", "[" * 2000 + "]" * 2000, '{"val": 1}', "\xff", " " * 5000):
                said = await client.post("/api/action/override", data=body.encode("latin-1"),
                                         headers={"Content-Type": "application/json"})
                statuses.append(said.status)
            return statuses
    assert asyncio.run(main()) == [400, 400, 400, 400, 413]
    assert live.said == []


def test_a_start_press_lasts_until_the_simulation_made_a_step():
    """At a slow --speed (0.005: a 1 ms step takes 0.2 s of wall time) a press released after a fixed wall time
    falls between two steps and the controller never sees it: the press is held until the simulated time moved
    on (or the simulation stopped running)."""
    live = Commands()
    front = WebFront(live, parse_address("127.0.0.1:0"), Security())  # type: ignore[arg-type]

    async def main() -> list[list[tuple]]:
        seen = []
        press = asyncio.create_task(front.act("start"))
        await asyncio.sleep(3 * START_PULSE)
        seen.append(list(live.said))
        live.runner.snap = Snapshot(0.001, {}, {})          # the next step
        assert await asyncio.wait_for(press, 1.0) is None
        seen.append(list(live.said))
        live.said.clear()
        press = asyncio.create_task(front.act("start"))
        await asyncio.sleep(3 * START_PULSE)
        live.runner.state = "stopped"                         # no step is coming: the press ends
        assert await asyncio.wait_for(press, 1.0) is None
        seen.append(list(live.said))
        return seen
    press, step, stopped = asyncio.run(main())
    assert press == [("write", "seq.start", True)]
    assert step == stopped == [("write", "seq.start", True), ("release", "seq.start")]


def test_an_unreadable_certificate_for_https_is_one_config_error(tmp_path):
    """``--certificate`` missing or not a certificate: ConfigError naming it (the CLI's one line, exit 2), as
    the OPC UA side says it -- never cryptography's ValueError or a FileNotFoundError's traceback."""
    from ncfmu.web import _tls
    garbage = tmp_path / "server.der"
    garbage.write_bytes(b"not a certificate")
    with pytest.raises(ConfigError, match=r"--certificate = .*server.der.*not a certificate"):
        _tls(Security(users={"op": "secret"}, certificate=garbage, private_key=garbage))
    with pytest.raises(ConfigError, match=r"--certificate = .*missing.der.*cannot read it"):
        _tls(Security(users={"op": "secret"}, certificate=tmp_path / "missing.der", private_key=garbage))
