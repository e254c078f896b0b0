"""``ncfmu serve SYSTEM --web HOST:PORT``: a live page of the running machine, beside the OPC UA server.

The page (``static/``: plain HTML, JS and SVG, nothing from outside) shows a DRO, the program with its current
line, the cycle, alarms and crashes as they happen, the part section being cut (the part check's polygons) and
the panel's buttons. The server (aiohttp) runs on the OPC UA server's asyncio loop and never calls into the
simulation: once per frame (:data:`FRAME_RATE`) it reads the newest snapshot (:meth:`~ncfmu.serving.Runner.latest`,
which never waits for the simulation thread) and, from the part check's thread, the newest section of the stock;
it encodes what changed once and pushes it to every page as server-sent events; a page that cannot keep up gets
the whole state again instead of a queue that grows. The buttons are the OPC UA side's own requests
(:meth:`~ncfmu.serving.LiveServer.call`, ``write``, ``release``): the same checks, the same effects.
"""

from __future__ import annotations

import asyncio
import base64
import json
import logging
import math
import ssl
import tempfile
import time as _time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..errors import ConfigError
from ..serving.address_space import WriteRefused
from ..serving.crash_watch import crash_text
from ..serving.security import is_loopback_host

if TYPE_CHECKING:
    from aiohttp import web

    from ..serving import LiveServer, Security, Snapshot

log = logging.getLogger("ncfmu.serving.web")

#: Frames pushed to the pages per second (a browser draws 10-30 Hz; the OPC UA side publishes at 100 Hz).
FRAME_RATE = 20.0
#: The least wall time between two sections of the stock sent (the part check hands one over every 0.05 s of
#: simulated time; a polygon of a few hundred vertices is the largest thing a frame carries).
SECTION_INTERVAL = 0.2
#: Frames a page may have waiting before it is considered too slow (it then gets the whole state again).
BACKLOG = 4
#: The longest a page's stream stays silent (a comment line then): a page that left is found by the write.
HEARTBEAT = 1.0
#: How long the server waits for the pages' streams to end when it stops.
SHUTDOWN = 1.0
STATIC = Path(__file__).parent / "static"
#: What the page shows of a cycle controller, when the controller has it (in this order).
CONTROLLER_VALUES = ("line", "block_no", "segment", "canned_cycle", "subcycle", "pass_no", "tool", "busy", "done",
                     "alarm", "feed_hold", "feed_override", "s_cmd", "rapid")
#: The panel's buttons (each a ``data-action``) and the override dial's action.
ACTIONS = ("start", "hold", "release", "reset")
#: The least wall time a start press is held (and until the simulation made a step: the controller takes the
#: rising edge at its next step).
START_PULSE = 0.1


@dataclass(frozen=True)
class WebAddress:
    host: str
    port: int

    @property
    def loopback(self) -> bool:
        return is_loopback_host(self.host)


def parse_address(text: str) -> WebAddress:
    """``HOST:PORT`` (``[::1]:PORT`` for IPv6) as --web gives it, or ConfigError naming the rule."""
    host, colon, port = text.rpartition(":")
    host = host[1:-1] if host.startswith("[") and host.endswith("]") else host
    if not colon or not host or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise ConfigError("--web", text, "must be HOST:PORT with a port 0..65535 (e.g. 127.0.0.1:8080)")
    return WebAddress(host, int(port))


def check_address(address: WebAddress, security: Security) -> None:
    """The OPC UA side's rules off the loopback: users (HTTP Basic, never anonymous control from the network)
    and the certificate (HTTPS: no password in plain text), unless --allow-insecure."""
    if address.loopback:
        return
    where = f"{address.host}:{address.port}"
    if not security.users:
        raise ConfigError("--web", where, "serving the page beyond this machine needs --user NAME:PASSWORD (no "
                          "anonymous buttons from the network); bind 127.0.0.1 otherwise")
    if security.certificate is None and not security.allow_insecure:
        raise ConfigError("--web", where, "serving the page beyond this machine needs --certificate and "
                          "--private-key (HTTPS: no password in plain text), or --allow-insecure")


def _tls(security: Security) -> ssl.SSLContext:
    """An HTTPS context from the OPC UA server's certificate (DER or PEM) and private key."""
    from cryptography import x509
    from cryptography.hazmat.primitives.serialization import Encoding
    assert security.certificate is not None and security.private_key is not None
    where = str(security.certificate)
    try:
        raw = Path(security.certificate).read_bytes()
    except OSError as err:
        raise ConfigError("--certificate", where, f"cannot read it: {err.strerror or err}") from None
    try:
        cert = x509.load_pem_x509_certificate(raw) if raw.lstrip().startswith(b"-----") else \
            x509.load_der_x509_certificate(raw)
    except ValueError as err:
        raise ConfigError("--certificate", where, f"not a certificate (DER or PEM): {err}") from None
    context = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
    with tempfile.TemporaryDirectory() as folder:      # ssl reads PEM files only
        pem = Path(folder) / "cert.pem"
        pem.write_bytes(cert.public_bytes(Encoding.PEM))
        try:
            context.load_cert_chain(str(pem), str(security.private_key))
        except (OSError, ssl.SSLError) as err:
            raise ConfigError("--private-key", str(security.private_key), f"cannot use it for HTTPS: {err}") from None
    return context


def _json_value(value: object) -> object:
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)          # JSON has no NaN or inf: the page shows the word
    return value


def _rings(geometry: Any) -> list[list[list[float]]]:
    """A (multi)polygon's rings, exterior and holes alike (the page fills them even-odd), to 1 µm."""
    import shapely
    rings: list[list[list[float]]] = []
    for part in shapely.get_parts(geometry):
        if part.geom_type == "Polygon" and not part.is_empty:
            for ring in (part.exterior, *part.interiors):
                rings.append([[round(float(u), 3), round(float(v), 3)] for u, v in ring.coords])
        elif part.geom_type in ("MultiPolygon", "GeometryCollection"):
            rings.extend(_rings(part))
    return rings


def _removal(accumulator: Any) -> tuple[Any, Any, Any] | None:
    """(the engine, the setup, the report's part) of a part check's accumulator that removes material, as
    ``crashes_so_far`` finds them; None: none (a grinder's judges sparks, not a section)."""
    for acc in getattr(accumulator, "parts", ()):
        setup = getattr(acc, "setup", None)
        if setup is not None and getattr(setup, "removal", None) is not None:
            return setup.removal, setup, acc.part
    return None


class _Page:
    """One connected page: the frames waiting for it; ``stale`` when it fell behind (the whole state next)."""

    def __init__(self) -> None:
        self.frames: asyncio.Queue[bytes | None] = asyncio.Queue(BACKLOG)
        self.stale = True

    def end(self) -> None:
        """The server stops: the stream ends (None)."""
        while not self.frames.empty():
            self.frames.get_nowait()
        self.frames.put_nowait(None)

    def push(self, frame: bytes) -> None:
        try:
            self.frames.put_nowait(frame)
        except asyncio.QueueFull:
            while not self.frames.empty():
                self.frames.get_nowait()
            self.stale = True


class WebFront:
    """The page's server in front of a :class:`~ncfmu.serving.LiveServer` (see the module's docstring)."""

    def __init__(self, live: LiveServer, address: WebAddress, security: Security, watch: Any = None,
                 rate: float = FRAME_RATE, listening: Callable[[str], None] | None = None) -> None:
        self.live, self.address, self.security, self.watch = live, address, security, watch
        #: told the page's URL once it listens
        self.listening = listening
        self.interval = 1.0 / rate
        self.points = live.points
        self._values: dict[str, object] = {}         # what the pages were last sent
        self._frame_state: dict[str, object] = {}
        self._section: dict[str, object] | None = None      # the newest stock section (from the check thread)
        self._section_sent: dict[str, object] | None = None
        self._section_at = 0.0
        self._section_crashes = 0
        self._pages: list[_Page] = []
        self._runner: web.AppRunner | None = None
        self._task: asyncio.Task | None = None
        self.url = ""
        self.machine = self._describe()
        if watch is not None:
            watch.on_judged = self.judged

    # -- what the page is told once -------------------------------------------------------------------
    def _describe(self) -> dict[str, object]:
        names = self.points
        instances = list(dict.fromkeys(p.instance for p in names.values()))

        def has(inst: str, *variables: str) -> bool:
            return all(f"{inst}.{v}" in names for v in variables)
        axes = [i for i in instances if has(i, "pos", "pos_cmd")]
        spindles = [i for i in instances if has(i, "speed", "speed_cmd")]
        # a cycle controller takes the panel's feed hold and override as inputs (the panel has them as outputs)
        controllers = [i for i in instances if all(names.get(f"{i}.{v}") is not None and
                                                   names[f"{i}.{v}"].causality == "input"
                                                   for v in ("feed_override", "feed_hold"))]
        machine: dict[str, object] = {
            "system": self.live.system_name,
            "points": {n: {"unit": p.unit or "", "type": p.type, "causality": p.causality,
                           "description": p.description, "min": p.minimum, "max": p.maximum}
                       for n, p in names.items()},
            "axes": axes, "spindles": spindles,
            "controllers": [{"name": c, "values": [v for v in CONTROLLER_VALUES if has(c, v)],
                             "program": f"{c}.program" if has(c, "program") else None,
                             "line": next((f"{c}.{v}" for v in ("line", "segment") if has(c, v)), None)}
                            for c in controllers],
            "actions": list(ACTIONS), "rate": 1.0 / self.interval, "section": None,
        }
        found = _removal(self.watch.accumulator) if self.watch is not None else None
        if found is not None:
            removal, setup, part = found
            u, v = part.plane_columns()
            tool = next((f"{c}.tool" for c in controllers if has(c, "tool")), None)
            machine["section"] = {
                "u": u, "v": v, "axes": list(getattr(part, "axes", ("u", "v"))),
                "lathe": hasattr(part, "seq"),
                "stock": _rings(removal.initial),
                "programmed": _rings(setup.programmed) if setup.programmed is not None else [],
                "tool": tool,
                "tools": {"0": removal.default.outline.round(3).tolist(),
                          **{str(k): c.outline.round(3).tolist() for k, c in removal.tools.items()}},
            }
        return machine

    # -- fed by the OPC UA side and the part check ------------------------------------------------------
    def judged(self, accumulator: Any) -> None:
        """The part check judged rows (its own thread, which owns the accumulator): the stock as it is now, at
        most every SECTION_INTERVAL (a Reset's first check always: the page must see the new bar)."""
        found = _removal(accumulator)
        if found is None:
            return
        removal = found[0]
        now = _time.monotonic()
        # a new bar (a Reset) and a new crash are sent at once: the simulation may halt before the next
        new = removal.stock is removal.initial or len(removal.crashes) != self._section_crashes
        if not new and now - self._section_at < SECTION_INTERVAL:
            return
        self._section_crashes = len(removal.crashes)
        self._section_at = now
        self._section = {"stock": _rings(removal.stock), "crashes": [c.as_dict() for c in removal.crashes]}

    # -- the frames ------------------------------------------------------------------------------------------
    def _state(self, snap: Snapshot) -> dict[str, object]:
        return {"time": snap.time, "state": snap.state, "reason": snap.reason, "lag": snap.lag,
                "overruns": snap.overruns, "forced": [n for n in self.points if n in snap.forced],
                "crashes": [{"t": c.t, "line": c.line, "what": c.what, "depth_mm": c.depth_mm,
                             "text": crash_text(c)} for c in snap.crashes],
                "verdict": snap.verdicts[-1][1] if snap.verdicts else ""}

    def _frame(self) -> bytes | None:
        """What changed since the last frame, encoded once for every page; None: nothing did."""
        snap = self.live.runner.latest()
        changed: dict[str, object] = {}
        state: dict[str, object] = {}
        for name, value in snap.values.items():
            value = _json_value(value)
            if self._values.get(name, changed) != value:
                self._values[name] = changed[name] = value
        for key, value in self._state(snap).items():
            if self._frame_state.get(key) != value:
                self._frame_state[key] = state[key] = value
        section = self._section
        if section is not None and section is not self._section_sent:
            self._section_sent = state["section"] = section
        if not changed and not state:
            return None
        return _event({**state, "values": changed})

    def _whole(self) -> bytes:
        """The whole state as the last frame left it (for a page that joined or fell behind: encoded only then)."""
        whole = {**self._frame_state, "values": self._values}
        if self._section_sent is not None:
            whole["section"] = self._section_sent
        return _event(whole)

    async def _broadcast(self) -> None:
        while True:
            await asyncio.sleep(self.interval)
            if not self._pages:
                continue
            try:
                delta = self._frame()
                whole = self._whole() if any(p.stale for p in self._pages) else None
            except Exception:          # a frame that cannot be made must not end the pages' updates for good
                log.exception("ncfmu serve --web: a frame failed")
                continue
            for page in self._pages:
                if page.stale:
                    assert whole is not None
                    page.stale = False
                    page.push(whole)
                elif delta is not None:
                    page.push(delta)

    # -- the panel -----------------------------------------------------------------------------------------------
    async def act(self, what: str, value: object = None) -> str | None:
        """A button: the OPC UA side's own request for it; None (done) or the refusal's text."""
        try:
            return await self._act(what, value)
        except WriteRefused as refused:
            return str(refused)

    async def _act(self, what: str, value: object) -> str | None:
        live = self.live
        runner = live.runner
        controllers = [c["name"] for c in self.machine["controllers"]]        # type: ignore[attr-defined]
        if what == "reset":
            await live.call("Reset")
            return None
        if what in ("start", "release") and runner.state in ("held", "paused"):
            await live.call("Resume")          # the cycle start after a (watchdog's) hold or a pause
            return None
        if what == "hold":
            for name in runner.feed_holds:
                await live.write(name, True)
            return None if runner.feed_holds else "the system has no feed-hold input"
        if what == "release":
            for name in runner.feed_holds:
                await live.release(name)
            return None
        if what == "start":
            starts = [f"{c}.start" for c in controllers if f"{c}.start" in self.points]
            if not starts:
                return "the system has no start input"
            for name in starts:
                await live.write(name, True)
            # the controller takes the rising edge at its next step: the press lasts until the simulation made
            # one (at a slow --speed a step takes longer than START_PULSE of wall time), or stopped running
            pressed_at = runner.latest().time
            await asyncio.sleep(START_PULSE)
            while runner.state == "running" and runner.latest().time <= pressed_at:
                await asyncio.sleep(START_PULSE / 4)
            for name in starts:
                await live.release(name)
            return None
        if what == "override":
            if not controllers:
                return "the system has no feed-override input"
            for c in controllers:
                await live.write(f"{c}.feed_override", value)
            return None
        return f"{what!r}: not one of {', '.join((*ACTIONS, 'override'))}"

    # -- HTTP -------------------------------------------------------------------------------------------------
    def _app(self) -> web.Application:
        from aiohttp import web
        app = web.Application(middlewares=[self._guard()], client_max_size=4096)
        app.router.add_get("/", self._index)
        app.router.add_get("/static/{name}", self._static)
        app.router.add_get("/api/machine", self._machine)
        app.router.add_get("/api/events", self._events)
        app.router.add_post("/api/action/{what}", self._action)
        return app

    @property
    def _allowed_hosts(self) -> set[str]:
        """The Host a browser may name us by (the port is the one bound once listening)."""
        port = self.address.port
        hosts = {self.address.host, "localhost", "127.0.0.1", "[::1]"} if self.address.loopback \
            else {self.address.host}
        named = {f"{h}:{port}" for h in hosts} | {f"[{self.address.host}]:{port}"}
        # a browser leaves the scheme's own port out of Host and Origin (the loopback is served by HTTP)
        bare = {h if ":" not in h or h.startswith("[") else f"[{h}]" for h in hosts}
        return named | bare if port == 80 else named

    def _guard(self):
        from aiohttp import web

        @web.middleware
        async def guard(request: web.Request, handler):
            # a page from another site must not reach the buttons through the browser: on the loopback (no users
            # asked for) the Host a browser sends must be ours (DNS rebinding); beyond it the machine has names
            # and addresses we cannot list (0.0.0.0 is bound) and the users are asked for, so any Host is served;
            # the Origin of a POST must be ours, or the very Host it came by
            ours = self._allowed_hosts if self.address.loopback else {request.host}
            if request.host not in ours:
                return web.json_response({"error": f"Host {request.host!r}: not this server"}, status=421)
            if request.method == "POST":
                origin = request.headers.get("Origin")
                if origin is not None and origin.split("://", 1)[-1] not in ours:
                    return web.json_response({"error": f"Origin {origin!r}: not this page"}, status=403)
            if self.security.users:
                said = request.headers.get("Authorization", "")
                ok = False
                if said.startswith("Basic "):
                    try:
                        name, _, password = base64.b64decode(said[6:]).decode().partition(":")
                    except ValueError:
                        name, password = "", ""
                    ok = self.security.admits(name, password)
                if not ok:
                    return web.json_response({"error": "a user of --user is asked for"}, status=401,
                                             headers={"WWW-Authenticate": 'Basic realm="ncfmu"'})
            return await handler(request)
        return guard

    async def _index(self, request: web.Request) -> web.StreamResponse:
        from aiohttp import web
        return web.FileResponse(STATIC / "index.html", headers=_NO_OUTSIDE)

    async def _static(self, request: web.Request) -> web.StreamResponse:
        from aiohttp import web
        name = request.match_info["name"]
        path = STATIC / name
        if "/" in name or name.startswith(".") or not path.is_file():
            raise web.HTTPNotFound(text=f"{name}: no such file")
        return web.FileResponse(path, headers=_NO_OUTSIDE)

    async def _machine(self, request: web.Request) -> web.StreamResponse:
        from aiohttp import web
        return web.json_response(self.machine)

    async def _events(self, request: web.Request) -> web.StreamResponse:
        from aiohttp import web
        response = web.StreamResponse(headers={"Content-Type": "text/event-stream", "Cache-Control": "no-cache"})
        await response.prepare(request)
        page = _Page()
        self._pages.append(page)
        try:
            while True:
                try:
                    frame = await asyncio.wait_for(page.frames.get(), HEARTBEAT)
                except TimeoutError:
                    frame = b": still here\n\n"
                if frame is None:
                    break
                await response.write(frame)
        except (ConnectionResetError, asyncio.CancelledError):
            pass
        finally:
            self._pages.remove(page)
        return response

    async def _action(self, request: web.Request) -> web.StreamResponse:
        from aiohttp import web
        what = request.match_info["what"]
        value: object = None
        if what == "override":
            try:
                body = await request.json()
            except (ValueError, RecursionError):      # 4 kB of brackets nest deeper than the parser recurses
                body = None
            if not isinstance(body, dict) or "value" not in body:
                return web.json_response({"error": 'override: the body must be {"value": NUMBER}'}, status=400)
            value = body["value"]
        elif what not in ACTIONS:
            return web.json_response({"error": f"{what!r}: not one of {', '.join((*ACTIONS, 'override'))}"},
                                     status=404)
        refusal = await self.act(what, value)
        if refusal is not None:
            return web.json_response({"error": refusal}, status=409)
        return web.json_response({"done": what})

    # -- life ---------------------------------------------------------------------------------------------------
    async def start(self) -> str:
        """Listen; the page's URL. ConfigError when the address cannot be bound."""
        from aiohttp import web
        context = _tls(self.security) if self.security.certificate is not None and not self.address.loopback \
            else None
        runner = self._runner = web.AppRunner(self._app(), access_log=None, handle_signals=False,
                                               shutdown_timeout=SHUTDOWN)
        await runner.setup()
        site = web.TCPSite(runner, self.address.host, self.address.port, ssl_context=context)
        try:
            await site.start()
        except OSError as err:
            await runner.cleanup()
            said = err.strerror.lower() if err.strerror else str(err)
            raise ConfigError("--web", f"{self.address.host}:{self.address.port}",
                              f"cannot listen there: {said}") from None
        port = int(runner.addresses[0][1]) if runner.addresses else self.address.port     # the one bound for 0
        host = f"[{self.address.host}]" if ":" in self.address.host else self.address.host
        self.url = f"{'https' if context else 'http'}://{host}:{port}/"
        self.address = WebAddress(self.address.host, port)
        self._task = asyncio.create_task(self._broadcast())
        return self.url

    async def serve(self, ready: Callable[[str], None] | None = None) -> None:
        """The OPC UA server's ``serve`` with the page beside it on the same loop: the page listens first
        (:attr:`listening` is told its URL), then the OPC UA server (``ready(endpoint)``)."""
        url = await self.start()
        if self.listening is not None:
            self.listening(url)
        try:
            await self.live.serve(ready)
        finally:
            await self.close()

    async def close(self) -> None:
        if self._task is not None:
            self._task.cancel()
        for page in self._pages:
            page.end()
        if self._runner is not None:
            await self._runner.cleanup()


def _event(data: object) -> bytes:
    """One server-sent event of ``data`` as JSON."""
    return b"data: " + json.dumps(data, separators=(",", ":")).encode() + b"\n\n"


#: Every page and file says where it may load from: here only (the page works on a plant network).
_NO_OUTSIDE = {"Content-Security-Policy": "default-src 'self'; img-src 'self' data:; style-src 'self'",
               "Cache-Control": "no-cache"}


