"""``ncfmu serve --web``: the live page in a real headless browser (Debian's chromium, driven by selenium).

One served lathe (seed cycle, --speed 2) is watched by two browsers at once; a second one, whose program rapids
into the bar, is started with the page's own button and crashes. What the page shows is read from its
``data-var`` elements; what the machine does is read back over OPC UA, the other way into the same session."""

from __future__ import annotations

import asyncio
import inspect
import json
import socket
import time
import urllib.error
import urllib.request
from collections.abc import Callable

import pytest
from asyncua import Client, ua
from web_browser import browser

from ncfmu.pytest_plugin import ServedSystem

pytestmark = pytest.mark.slow

#: Rapids into the bar (radius 29) at Z -10 down to X 24.2 on its line 4 (tests/serve/test_serve_crash.py's).
RAPID_INTO_STOCK = "G18 G21 G90 G8\nG00 X30 Z2\nG00 Z-10\nG00 X24.2\nG00 X30\nG00 Z2\nM30\n"


def opcua(served: ServedSystem, *names: str) -> list:
    """The values of ``names`` read over OPC UA: the same session, the other way in."""
    async def read() -> list:
        async with Client(served.endpoint, timeout=10) as client:
            idx = await client.get_namespace_index(served.namespace)
            return [await client.get_node(ua.NodeId(n, idx)).read_value() for n in names]
    return asyncio.run(read())


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def page_url(served: ServedSystem) -> str:
    line = next(line for line in served.lines if "the live page at " in line)
    return line.split("the live page at ", 1)[1].strip()


def text(driver, name: str) -> str:
    """The element's text, as the page wrote it (not as CSS renders it: the state is shown in capitals)."""
    return driver.find_element("css selector", f'[data-var="{name}"]').get_attribute("textContent")


def wait_for(what: Callable[[], object], timeout: float = 20.0, poll: float = 0.05):
    end = time.monotonic() + timeout
    while True:
        value = what()
        if value:
            return value
        if time.monotonic() > end:
            raise AssertionError(f"not within {timeout} s: {inspect.getsource(what).strip()}")
        time.sleep(poll)


def press(driver, action: str) -> None:
    driver.find_element("css selector", f'button[data-action="{action}"]').click()


def errors(driver) -> list[dict]:
    return [e for e in driver.get_log("browser") if e["level"] == "SEVERE"]


def post(url: str, body: object, headers: dict | None = None) -> tuple[int, dict]:
    request = urllib.request.Request(url, data=json.dumps(body).encode(), method="POST",
                                     headers={"Content-Type": "application/json", **(headers or {})})
    try:
        with urllib.request.urlopen(request, timeout=10) as answer:
            return answer.status, json.loads(answer.read())
    except urllib.error.HTTPError as err:
        return err.code, json.loads(err.read())


@pytest.fixture(scope="module")
def served(ncfmu_project):
    s = ServedSystem("lathe_roughing", ("--no-cnc", "--speed", "2", "--web", f"127.0.0.1:{free_port()}"))
    yield s
    assert s.stop(30) == 0


def test_two_browsers_watch_hold_and_release_the_same_machine(served):
    url = page_url(served)
    with browser() as a, browser() as b:
        a.get(url)
        b.get(url)
        for d in (a, b):
            wait_for(lambda d=d: text(d, "Simulation.state") == "running")
            assert d.find_element("css selector", "#system").text == "ncfmu lathe_roughing"
            for action in ("start", "hold", "release", "reset"):
                assert d.find_element("css selector", f'[data-action="{action}"]').is_displayed()
        # values change while the cycle runs (the panel starts it at t = 0.1 s)
        first = text(a, "Simulation.time"), text(a, "z_axis.pos")
        wait_for(lambda: (text(a, "Simulation.time"), text(a, "z_axis.pos")) != first and
                 text(a, "seq.busy") == "on", timeout=10)
        wait_for(lambda: float(text(a, "z_axis.pos")) != float(first[1]), timeout=10)

        press(a, "hold")                         # browser A holds the feed ...
        for d in (a, b):                         # ... both see it forced
            wait_for(lambda d=d: text(d, "Simulation.forced") == "seq.feed_hold" and text(d, "seq.feed_hold") == "on")
            assert "forced" in d.find_element("css selector", '[data-var="seq.feed_hold"]').get_attribute("class")
        t_hold = float(text(a, "Simulation.time"))
        wait_for(lambda: float(text(a, "Simulation.time")) > t_hold + 1.0)       # the axes come to rest
        held = [(text(a, f"{axis}.pos"), text(b, f"{axis}.pos")) for axis in ("x_axis", "z_axis")]
        t_held = float(text(a, "Simulation.time"))
        wait_for(lambda: float(text(a, "Simulation.time")) > t_held + 1.0)       # 1 s on: neither moves by a µm
        for axis, (in_a, in_b) in zip(("x_axis", "z_axis"), held):
            assert text(a, f"{axis}.pos") == in_a, f"{axis} moved under feed hold"
            assert in_a == in_b == text(b, f"{axis}.pos"), "the two browsers see different machines"
        # the same machine over OPC UA: held by the page's button
        forced, hold, z = opcua(served, "Simulation.forced", "seq.feed_hold", "z_axis.pos")
        assert forced == ["seq.feed_hold"] and hold is True
        assert f"{z:.3f}" == held[1][0]

        press(b, "release")                      # browser B releases: the axes move again, both see it
        for d in (a, b):
            wait_for(lambda d=d: text(d, "Simulation.forced") == "" and text(d, "seq.feed_hold") == "off")
        wait_for(lambda: (text(a, "x_axis.pos"), text(a, "z_axis.pos")) != held_positions(held), timeout=10)
        assert errors(a) == [] and errors(b) == []


def held_positions(held: list[tuple[str, str]]) -> tuple[str, str]:
    return held[0][0], held[1][0]


def test_the_override_dial_and_refusals(served):
    """The dial forces the controller's override as an OPC UA write would, checked by the port's rule."""
    url = page_url(served)
    status, said = post(url + "api/action/override", {"value": 0.5})
    assert status == 200, said
    value, forced = opcua(served, "seq.feed_override", "Simulation.forced")
    assert value == 0.5 and "seq.feed_override" in forced
    status, said = post(url + "api/action/override", {"value": "fast"})
    assert status == 409 and "seq.feed_override = 'fast': must be a Double" in said["error"]
    status, said = post(url + "api/action/override", {"value": float("nan")})
    assert status == 409 and "seq.feed_override = nan: must be finite" in said["error"]
    status, said = post(url + "api/action/fly", {})
    assert status == 404 and "'fly': not one of start, hold, release, reset, override" in said["error"]
    # a page of another site cannot press the buttons through a browser (its Origin), nor reach the server
    # under another name (DNS rebinding: its Host)
    status, said = post(url + "api/action/reset", {}, {"Origin": "http://evil.example"})
    assert status == 403 and said["error"] == "Origin 'http://evil.example': not this page"
    status, said = post(url + "api/action/reset", {}, {"Host": "evil.example"})
    assert status == 421 and said["error"] == "Host 'evil.example': not this server"
    status, said = post(url + "api/action/release", {})
    assert status == 200


def test_a_crash_appears_on_the_page(ncfmu_project):
    served = ServedSystem("lathe_roughing", ("--no-cnc", "--speed", "4", "--web", f"127.0.0.1:{free_port()}",
                                             "--set", "panel.start_at=-1", "--set", f"seq.program={RAPID_INTO_STOCK}"))
    try:
        with browser() as d:
            d.get(page_url(served))
            wait_for(lambda: text(d, "Simulation.state") == "running")
            program = d.find_elements("css selector", "#program li")
            assert [li.text for li in program[:3]] == ["G18 G21 G90 G8", "G00 X30 Z2", "G00 Z-10"]
            time.sleep(0.3)
            assert text(d, "seq.busy") == "off"          # nothing starts it but the page's button
            press(d, "start")
            wait_for(lambda: text(d, "Simulation.state") == "crashed", timeout=30)
            crash = text(d, "Simulation.crash")
            assert crash.startswith("crash at t = ") and ", line 4: " in crash, crash
            assert text(d, "Simulation.crashes") == "1"
            events = [e.text for e in d.find_elements("css selector", "#events li")]
            assert any(crash in e for e in events), events
            # the crash is drawn where it happened
            wait_for(lambda: d.find_elements("css selector", '[data-section="crashes"] circle'))
            # the program line the controller is on is the one marked (it halted there: the page stands still)
            line = text(d, "seq.line")
            assert int(line) >= 4
            assert [li.get_attribute("data-line") for li in d.find_elements("css selector", "#program li.current")] \
                == [line]
            press(d, "reset")                           # Reset starts again: no crash, running
            wait_for(lambda: text(d, "Simulation.state") == "running" and text(d, "Simulation.crashes") == "0")
            assert errors(d) == []
    finally:
        assert served.stop(30) == 0
