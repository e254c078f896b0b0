"""The live page's server without a browser or a served system: its address rules, and how frames are made and
handed to pages (decimated, the whole state to a page that fell behind) from snapshots, never from the
simulation."""

from __future__ import annotations

import asyncio
import json
import subprocess
import sys

import pytest

from ncfmu.errors import ConfigError
from ncfmu.serve import Point, Security, Snapshot
from ncfmu.web import BACKLOG, WebFront, _Page, check_address, parse_address

POINTS = [Point("x_axis.pos", "x_axis", "pos", "Real", "output", "continuous", "mm", "actual position", None, None),
          Point("x_axis.pos_cmd", "x_axis", "pos_cmd", "Real", "input", "continuous", "mm", "", None, None),
          Point("seq.feed_hold", "seq", "feed_hold", "Boolean", "input", "discrete", None, "", None, None),
          Point("seq.feed_override", "seq", "feed_override", "Real", "input", "discrete", "1", "", 0.0, 1.5),
          Point("seq.program", "seq", "program", "String", "parameter", "fixed", None, "", None, None)]


class Live:
    """What the page reads of the OPC UA side: its points and listeners (no server, no simulation)."""

    system_name = "fake"

    def __init__(self) -> None:
        self.points = {p.name: p for p in POINTS}
        self.listeners: list = []


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
    assert live.listeners == [front.take]
    assert front.machine["axes"] == ["x_axis"] and front.machine["controllers"][0]["program"] == "seq.program"
    # the first snapshot is the only one with the fixed parameters: a later one must not hide them
    front.take(Snapshot(0.0, {"x_axis.pos": 1.0, "seq.program": "G00 X1\nM30"}, {}))
    front.take(Snapshot(0.01, {"x_axis.pos": 1.5, "seq.feed_hold": False}, {}))
    delta, whole = front._frame()
    assert decode(delta)["values"] == {"x_axis.pos": 1.5, "seq.program": "G00 X1\nM30", "seq.feed_hold": False}
    assert front._frame() is None                            # nothing new: nothing sent
    front.take(Snapshot(0.02, {"x_axis.pos": 1.5, "seq.feed_hold": True}, {"seq.feed_hold": True}, "running"))
    delta, whole = front._frame()
    d, w = decode(delta), decode(whole)
    assert d["values"] == {"seq.feed_hold": True} and d["forced"] == ["seq.feed_hold"] and d["time"] == 0.02
    assert w["values"]["seq.program"] == "G00 X1\nM30" and w["values"]["x_axis.pos"] == 1.5
    front.take(Snapshot(0.03, {"x_axis.pos": float("nan")}, {}))
    assert decode(front._frame()[0])["values"] == {"x_axis.pos": "nan"}      # JSON has no NaN: the word


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
