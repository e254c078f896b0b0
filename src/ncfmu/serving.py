"""Live virtual commissioning: a system run in real time behind an OPC UA server (asyncua).

Two threads share the work, and neither waits on the other:

- the **simulation thread** owns the FMUs (every FMI call happens there). It paces simulated time to the
  wall clock (``speed`` 1 = real time, 0 = as fast as it can), runs the steps that are due in chunks, and
  between chunks applies the writes clients made (forcing an input, releasing it, a tunable parameter, Pause,
  Resume, Stop, Reset) and leaves a snapshot of the values for the server;
- the **server** (asyncua, on an asyncio loop in the main thread) publishes the newest snapshot every
  ``publish_interval`` (subscriptions then deliver data changes) and answers clients.

A write is checked on the server side first (type, NaN/inf, the port's min/max from the modelDescription:
OPC UA status Bad_TypeMismatch, Bad_OutOfRange, Bad_NotWritable, nothing changes), then handed to the
simulation thread, which applies it before the next step and answers with the session's verdict (a
controller's own rule, e.g. the panel's allowed values, is the session's ConfigError -> Bad_OutOfRange).

Address space (stable: PLC projects point at these names): namespace ``urn:ncfmu:<system>``; one Object per
component instance; one Variable per FMU variable, string NodeId ``<instance>.<variable>``, BrowseName the
variable's name, DataType Double/Int32/Boolean/String, its description, its unit as EngineeringUnits
(EUInformation); inputs also get ``<instance>.<variable>.forced`` (Boolean). The ``Simulation`` object holds
``time``, ``speed``, ``lag``, ``overruns``, ``state``, ``reason`` and the methods ``Pause``, ``Resume``,
``Stop``, ``Reset`` and ``Release(name)``.
"""

from __future__ import annotations

import asyncio
import ipaddress
import logging
import math
import os
import queue
import signal
import sys
import threading
import time as _time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING
from urllib.parse import urlparse

import numpy as np

if TYPE_CHECKING:
    from asyncua.common.node import Node
from .errors import ConfigError, NcfmuError, SimulationError

log = logging.getLogger("ncfmu.serve")

#: An overrun: the loop falls behind, a chunk's last step finishing more than this after its wall-clock due time
#: (counted once until a chunk is on time again).
OVERRUN_LAG = 0.010
#: The most wall time one chunk may take when catching up (the server gets the GIL in between anyway).
MAX_CHUNK_WALL = 0.020
#: The shortest wall time between chunks when paced: faster than real time, one wake-up runs several steps.
MIN_CHUNK_WALL = 0.001
#: Steps per chunk at ``speed`` 0 (as fast as possible, still handing back between chunks).
FAST_CHUNK = 50
#: How long a client's write waits for the simulation thread to take it (the thread takes writes between
#: chunks, every few ms; longer means the simulation is stopped or failed).
WRITE_TIMEOUT = 2.0

DEFAULT_ENDPOINT = "opc.tcp://127.0.0.1:4840/ncfmu"

#: UNECE codes (OPC UA EngineeringUnits, namespace below) of the units our FMUs declare.
UNECE_NAMESPACE = "http://www.opcfoundation.org/UA/units/un/cefact"
UNECE = {"mm": "MMT", "s": "SEC", "mm/s": "C16", "mm/s2": "M41", "1": "C62", "N.m": "NU", "1/s": "1/s",
         "kg.m2": "B32", "rad/s": "2A", "rev/min": "RPM"}


def _unece_id(code: str) -> int:
    """The UnitId of a UNECE common code (OPC UA Part 8: the code's characters packed into an Int32)."""
    if code == "1/s":
        return -1
    value = 0
    for ch in code:
        value = (value << 8) | ord(ch)
    return value


# -- the served variables -------------------------------------------------------------------------
@dataclass(frozen=True)
class Point:
    """One FMU variable as the server shows it."""

    name: str               # INSTANCE.VARIABLE, the NodeId's string
    instance: str
    variable: str
    type: str               # Real, Integer, Boolean, String (Enumeration served as Integer)
    causality: str
    variability: str
    unit: str | None
    description: str
    minimum: float | None
    maximum: float | None

    @property
    def writes(self) -> str | None:
        """``"input"`` (forcing), ``"parameter"`` (a tunable parameter) or None (read-only)."""
        if self.causality == "input":
            return "input"
        if self.causality == "parameter" and self.variability == "tunable":
            return "parameter"
        return None

    def rule(self) -> str:
        low = "" if self.minimum is None else f">= {self.minimum:g}"
        high = "" if self.maximum is None else f"<= {self.maximum:g}"
        return " and ".join(p for p in (low, high) if p) or "finite"


def points_of(slaves: Sequence) -> list[Point]:
    """Every variable of every FMU, in system order, as its modelDescription declares it."""
    return [Point(f"{s.name}.{v.name}", s.name, v.name, "Integer" if v.type == "Enumeration" else v.type,
                  v.causality, v.variability or "continuous", v.unit, v.description or "", v.min, v.max)
            for s in slaves for v in s.variables.values()]


class WriteRefused(NcfmuError):
    """A client's write that changes nothing; ``status`` is the OPC UA status code's name."""

    def __init__(self, status: str, message: str) -> None:
        super().__init__(message)
        self.status = status


def check_value(point: Point, value: object) -> object:
    """``value`` (already of the node's OPC UA type) checked against the port's rule, or :class:`WriteRefused`."""
    if point.writes is None:
        what = "an output" if point.causality == "output" else f"a {point.variability} {point.causality}"
        raise WriteRefused("BadNotWritable", f"{point.name} is {what}: not writable")
    if point.type == "Real":
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise WriteRefused("BadTypeMismatch", f"{point.name} = {value!r}: must be a Double")
        x = float(value)
        if not math.isfinite(x):
            raise WriteRefused("BadOutOfRange", f"{point.name} = {x!r}: must be finite")
        if (point.minimum is not None and x < point.minimum) or (point.maximum is not None and x > point.maximum):
            raise WriteRefused("BadOutOfRange", f"{point.name} = {x!r}: must be {point.rule()}")
        return x
    if point.type == "Integer":
        if isinstance(value, bool) or not isinstance(value, int):
            raise WriteRefused("BadTypeMismatch", f"{point.name} = {value!r}: must be an Int32")
        if (point.minimum is not None and value < point.minimum) or (point.maximum is not None
                                                                      and value > point.maximum):
            raise WriteRefused("BadOutOfRange", f"{point.name} = {value!r}: must be {point.rule()}")
        return int(value)
    if point.type == "Boolean":
        if not isinstance(value, bool):
            raise WriteRefused("BadTypeMismatch", f"{point.name} = {value!r}: must be a Boolean")
        return value
    if not isinstance(value, str):
        raise WriteRefused("BadTypeMismatch", f"{point.name} = {value!r}: must be a String")
    return value


# -- recording ------------------------------------------------------------------------------------------
class Recorder:
    """Where a served run's recording goes (``--out DIR``): ``DIR/<system>.csv`` (every output, or ``--record``)
    and ``DIR/session_inputs.csv`` (the writes that took effect, an input CSV ``ncfmu run --input`` replays).

    A Reset ends a recording segment (the session starts again from its start values): the segment before the
    k-th Reset is kept as ``<system>.segment<k>.csv`` and ``session_inputs.segment<k>.csv``; the two files
    without a number always hold the run since the last Reset.
    """

    def __init__(self, system: str, out: Path) -> None:
        self.system, self.out = system, Path(out)
        self.segments = 0
        self.files: list[Path] = []
        self.out.mkdir(parents=True, exist_ok=True)

    @property
    def trajectory(self) -> Path:
        return self.out / f"{self.system}.csv"

    def sinks(self) -> list:
        from .cosim.record import CsvSink
        return [CsvSink(self.trajectory)]

    def end_segment(self, writes: Sequence[tuple[float, str, object]], final: bool) -> None:
        """After the session closed its sinks: name the segment's files and write its writes."""
        from .cosim.master import write_input_csv
        if final:
            self.files.append(write_input_csv(self.out / "session_inputs.csv", writes))
            for path in (self.trajectory, self.trajectory.with_name(self.trajectory.name + ".partial")):
                if path.exists():
                    self.files.append(path)
            return
        self.segments += 1
        k = self.segments
        if self.trajectory.exists():
            self.files.append(self.trajectory.replace(self.out / f"{self.system}.segment{k}.csv"))
        self.files.append(write_input_csv(self.out / f"session_inputs.segment{k}.csv", writes))


# -- the simulation thread ------------------------------------------------------------------------------
@dataclass
class _Command:
    what: str                       # force, release, set, pause, resume, stop, reset
    name: str = ""
    value: object = None
    done: Callable[[str | None], None] | None = None    # called with None (applied) or the refusal's text


@dataclass
class Snapshot:
    """The values at one communication point, with the simulation's state as it was then."""

    time: float
    values: dict[str, object]
    forced: dict[str, object]
    state: str = "running"
    reason: str = ""
    lag: float = 0.0
    overruns: int = 0


class PaceStats:
    """The lag after every chunk, as a histogram (10 µs bins up to 1 s; bounded memory however long the run),
    its exact maximum, and the overruns."""

    BIN = 1e-5
    BINS = 100_000

    def __init__(self) -> None:
        self.counts = np.zeros(self.BINS + 1, dtype=np.int64)
        self.count = 0
        self.max = 0.0
        self.overruns = 0

    def add(self, lag: float) -> None:
        self.counts[min(max(int(lag / self.BIN), 0), self.BINS)] += 1
        self.count += 1
        self.max = max(self.max, lag)

    def percentile(self, q: float) -> float:
        """The lag that ``q`` percent of the chunks did not exceed (to the bin's upper edge, at most the max)."""
        if not self.count:
            return 0.0
        k = int(np.searchsorted(np.cumsum(self.counts), q / 100.0 * self.count, side="left"))
        return self.max if k >= self.BINS else min((k + 1) * self.BIN, self.max)     # the last bin: beyond 1 s

    def percentiles(self) -> tuple[float, float, float]:
        return self.percentile(50), self.percentile(99), self.max


class Runner:
    """Paces a session in a worker thread (see the module's docstring)."""

    def __init__(self, session, points: Sequence[Point], speed: float = 1.0, recorder: Recorder | None = None,
                 on_state: Callable[[], None] | None = None) -> None:
        if not (math.isfinite(speed) and speed >= 0):
            raise ConfigError("--speed", speed, "must be a number >= 0 (0: as fast as possible)")
        self.session, self.speed, self.recorder = session, float(speed), recorder
        self.points = list(points)
        self.state, self.reason = "running", ""
        self.stats = PaceStats()
        self.lag = 0.0
        self.started, self.wall = 0.0, 0.0      # perf_counter at the thread's start; its wall time to the end
        self.commands: queue.SimpleQueue[_Command] = queue.SimpleQueue()
        self._snapshot: Snapshot | None = None
        self._snapshot_lock = threading.Lock()
        self._want_snapshot = True
        self._stop = threading.Event()
        self._said_overrun = False
        self._on_state = on_state
        self.thread = threading.Thread(target=self._main, name="ncfmu-simulation", daemon=True)
        self._take_snapshot()
        assert self._snapshot is not None
        # fixed parameters (and the rest that no step changes): read once, published with the first snapshot
        for p in self.points:
            if p.name not in self._snapshot.values:
                self._snapshot.values[p.name] = session.value(p.name)

    # -- called from the server's thread -----------------------------------------------------------
    def start(self) -> None:
        self.thread.start()

    def submit(self, command: _Command) -> None:
        self.commands.put(command)

    def snapshot(self) -> Snapshot | None:
        """The newest snapshot (and ask for the next one)."""
        with self._snapshot_lock:
            snap, self._snapshot = self._snapshot, None
        self._want_snapshot = True
        return snap

    def stop(self, reason: str = "") -> None:
        self.submit(_Command("stop", value=reason))
        self._stop.set()

    # -- the thread ----------------------------------------------------------------------------------
    def _take_snapshot(self) -> None:
        s = self.session
        values = s.outputs()
        for p in self.points:
            if p.causality == "input" or p.writes == "parameter":
                values[p.name] = s.value(p.name)
        with self._snapshot_lock:
            self._snapshot = Snapshot(float(s.time), values, dict(s.forced()), self.state, self.reason, self.lag,
                                      self.stats.overruns)
        self._want_snapshot = False

    def _apply(self, c: _Command) -> bool:
        """Apply one command; True when the pacing's origin must move (pause, reset)."""
        s = self.session
        rebase = False
        refusal: str | None = None
        try:
            if c.what == "force":
                s.force(c.name, c.value)
            elif c.what == "release":
                s.release(c.name)
            elif c.what == "set":
                s.set_parameter(c.name, c.value)
            elif c.what == "pause":
                if self.state == "running":
                    self.state = "paused"
            elif c.what == "resume":
                if self.state == "paused":
                    self.state, rebase = "running", True
                elif self.state != "running":
                    refusal = f"the simulation is {self.state}"
            elif c.what == "reset":
                if self.state in ("stopped", "failed"):
                    refusal = f"the simulation is {self.state}"
                else:
                    writes = list(s.writes)
                    rec = self.recorder
                    s.reset(rec.sinks() if rec is not None else ())
                    if rec is not None:
                        rec.end_segment(writes, final=False)
                    rebase = True
            elif c.what == "stop":
                self.state, self.reason = "stopped", str(c.value or "Stop called")
                self._stop.set()
        except (ConfigError, NcfmuError) as err:
            refusal = str(err)
        if c.done is not None:
            c.done(refusal)
        self._want_snapshot = True
        return rebase

    def _main(self) -> None:
        s, h = self.session, self.session.step_size
        stop_time = s.stop_time
        wall0, sim0 = _time.perf_counter(), s.time
        self.started = wall0
        # the fewest steps worth waking up for: a chunk every MIN_CHUNK_WALL at least (1 step at real time)
        min_steps = max(1, int(MIN_CHUNK_WALL * self.speed / h + 1e-9)) if self.speed > 0 else 1
        behind = False
        try:
            while not self._stop.is_set():
                rebase = False
                while True:
                    try:
                        c = self.commands.get_nowait()
                    except queue.Empty:
                        break
                    rebase |= self._apply(c)
                if self._stop.is_set():
                    break
                if rebase:
                    wall0, sim0 = _time.perf_counter(), s.time
                if self.state != "running":
                    if self._want_snapshot:
                        self._take_snapshot()
                    try:
                        c = self.commands.get(timeout=0.005)
                    except queue.Empty:
                        continue
                    if self._apply(c):
                        wall0, sim0 = _time.perf_counter(), s.time
                    continue
                remaining = int(round((stop_time - s.time) / h)) if math.isfinite(stop_time) else 1 << 62
                if remaining <= 0:
                    self.state, self.reason = "stopped", f"stop time {stop_time:g} s reached"
                    break
                if self.speed > 0:
                    now = _time.perf_counter()
                    due = int(math.floor(((now - wall0) * self.speed - (s.time - sim0)) / h + 1e-9))
                    if due < min_steps:
                        # sleep until a chunk is due (at most 5 ms: commands are taken in between)
                        wait = (s.time + min_steps * h - sim0) / self.speed - (now - wall0)
                        try:
                            c = self.commands.get(timeout=min(max(wait, 0.0), 0.005))
                        except queue.Empty:
                            continue
                        if self._apply(c):
                            wall0, sim0 = _time.perf_counter(), s.time
                        continue
                    n = min(due, remaining, max(1, int(MAX_CHUNK_WALL * self.speed / h)))
                else:
                    n = min(FAST_CHUNK, remaining)
                s.advance(n)
                if self.speed > 0:
                    lag = _time.perf_counter() - (wall0 + (s.time - sim0) / self.speed)
                    self.lag = lag
                    self.stats.add(lag)
                    if lag <= OVERRUN_LAG:
                        behind = False
                    elif not behind:            # one overrun per time it falls behind, however long it takes
                        behind = True           # to catch up again
                        self.stats.overruns += 1
                        if not self._said_overrun:
                            self._said_overrun = True
                            log.warning("ncfmu serve: cannot keep the pace at --speed %g: t = %.3f s finished "
                                        "%.1f ms late (overruns are counted in Simulation.overruns)",
                                        self.speed, s.time, lag * 1e3)
                else:
                    _time.sleep(0)          # hand the GIL to the server between chunks
                if self._want_snapshot:
                    self._take_snapshot()
        except SimulationError as err:
            self.state, self.reason = "failed", str(err)
            log.error("ncfmu serve: the simulation failed at t = %.3f s: %s", s.time, err)
        except Exception as err:     # anything else from an FMU call: the run has failed, the server lives on
            self.state, self.reason = "failed", f"{type(err).__name__}: {err}"
            log.exception("ncfmu serve: the simulation failed at t = %.3f s", s.time)
        finally:
            self.wall = _time.perf_counter() - self.started
            if self.state == "running":
                self.state = "stopped"
            try:
                self._take_snapshot()
            except Exception:
                pass
            # answer every write still waiting: nothing applies them any more
            while True:
                try:
                    c = self.commands.get_nowait()
                except queue.Empty:
                    break
                if c.done is not None:
                    c.done(f"the simulation is {self.state}")
            if self._on_state is not None:
                self._on_state()


# -- the OPC UA server -----------------------------------------------------------------------------------
@dataclass
class Security:
    """Who may connect when the endpoint is not on the loopback interface."""

    users: dict[str, str] = field(default_factory=dict)     # name -> password
    certificate: Path | None = None                          # server certificate (DER or PEM)
    private_key: Path | None = None


def _is_loopback(endpoint: str) -> bool:
    host = urlparse(endpoint).hostname or ""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def check_endpoint(endpoint: str, security: Security) -> None:
    parsed = urlparse(endpoint)
    if parsed.scheme != "opc.tcp" or not parsed.hostname or parsed.port is None:
        raise ConfigError("--endpoint", endpoint, "must be opc.tcp://HOST:PORT/PATH")
    if not _is_loopback(endpoint) and not security.users:
        raise ConfigError("--endpoint", endpoint, "serving beyond this machine needs --user NAME:PASSWORD "
                          "(no anonymous writes from the network); bind 127.0.0.1 otherwise")
    if (security.certificate is None) != (security.private_key is None):
        raise ConfigError("--certificate", str(security.certificate), "needs --private-key too (and vice versa)")


@dataclass
class ServeSummary:
    system: str
    time: float
    state: str
    reason: str
    overruns: int
    lag_p50: float
    lag_p99: float
    lag_max: float
    files: list[Path]
    writes: list[tuple[float, str, object]]
    wall: float = 0.0            # wall time of the simulation thread, s


class LiveServer:
    """An OPC UA server in front of a :class:`Runner`."""

    def __init__(self, system_name: str, runner: Runner, endpoint: str = DEFAULT_ENDPOINT,
                 security: Security | None = None, publish_interval: float = 0.010) -> None:
        self.system_name, self.runner, self.endpoint = system_name, runner, endpoint
        self.security = security or Security()
        self.publish_interval = publish_interval
        self.points = {p.name: p for p in runner.points}
        self.stopped = asyncio.Event()

    async def _build(self) -> None:
        from asyncua import Server, ua
        from asyncua.crypto.permission_rules import User, UserRole
        from asyncua.server.user_managers import UserManager

        self.ua = ua
        server = self.server = Server()
        sec = self.security
        if sec.users:
            users = dict(sec.users)

            class _Users(UserManager):
                def get_user(self, iserver, username=None, password=None, certificate=None):
                    if username is not None and users.get(username) == password:
                        return User(role=UserRole.User, name=username)
                    return None
            server = self.server = Server(user_manager=_Users())
        await server.init()
        server.set_endpoint(self.endpoint)
        server.set_server_name(f"ncfmu {self.system_name}")
        if sec.certificate is not None:
            await server.load_certificate(str(sec.certificate))
            await server.load_private_key(str(sec.private_key))
            server.set_security_policy([ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt])
        if sec.users:
            server.set_security_IDs(["Username"])
        idx = self.idx = await server.register_namespace(f"urn:ncfmu:{self.system_name}")
        vtype = {"Real": ua.VariantType.Double, "Integer": ua.VariantType.Int32,
                 "Boolean": ua.VariantType.Boolean, "String": ua.VariantType.String}
        self.vtype = vtype
        snap = self.runner.snapshot()
        assert snap is not None, "the runner takes its first snapshot when made"
        objects = server.nodes.objects
        instances: dict[str, Node] = {}
        self.nodes: dict[str, Node] = {}
        self._last: dict[str, object] = {}
        for p in self.runner.points:
            obj = instances.get(p.instance)
            if obj is None:
                obj = instances[p.instance] = await objects.add_object(self._nid(p.instance),
                                                                       ua.QualifiedName(p.instance, idx))
            value = snap.values.get(p.name)
            if value is None:
                value = self._initial(p)
            node = await obj.add_variable(self._nid(p.name), ua.QualifiedName(p.variable, idx),
                                          ua.Variant(self._cast(p, value), vtype[p.type]), varianttype=vtype[p.type])
            if p.description:
                await node.write_attribute(ua.AttributeIds.Description,
                                           ua.DataValue(ua.Variant(ua.LocalizedText(p.description))))
            if p.unit:
                code = UNECE.get(p.unit)
                eu = ua.EUInformation(NamespaceUri=UNECE_NAMESPACE, UnitId=_unece_id(code) if code else -1,
                                      DisplayName=ua.LocalizedText(p.unit), Description=ua.LocalizedText(p.unit))
                await node.add_property(self._nid(f"{p.name}.EngineeringUnits"),
                                        ua.QualifiedName("EngineeringUnits", 0), eu)
            if p.writes:
                await node.set_writable()
            self.nodes[p.name] = node
            self._last[p.name] = value
            if p.causality == "input":
                forced = await node.add_variable(self._nid(f"{p.name}.forced"), ua.QualifiedName("forced", idx),
                                                 False, varianttype=ua.VariantType.Boolean)
                await forced.write_attribute(ua.AttributeIds.Description, ua.DataValue(ua.Variant(ua.LocalizedText(
                    "true while a client's value overrides what drives this input; write false to release"))))
                await forced.set_writable()
                self.nodes[f"{p.name}.forced"] = forced
                self._last[f"{p.name}.forced"] = False
        simobj = await objects.add_object(self._nid("Simulation"), ua.QualifiedName("Simulation", idx))
        self.sim_nodes = {}
        for name, value, vt, desc in (
                ("time", float(snap.time), ua.VariantType.Double, "simulated time, s"),
                ("speed", self.runner.speed, ua.VariantType.Double,
                 "simulated seconds per wall-clock second (0: as fast as possible)"),
                ("lag", 0.0, ua.VariantType.Double, "wall clock minus the paced simulated time, s"),
                ("overruns", 0, ua.VariantType.Int32, "times the simulation fell more than 10 ms behind the clock"),
                ("state", "running", ua.VariantType.String, "running, paused, stopped or failed"),
                ("reason", "", ua.VariantType.String, "why the simulation stopped or failed")):
            node = await simobj.add_variable(self._nid(f"Simulation.{name}"), ua.QualifiedName(name, idx),
                                             ua.Variant(value, vt), varianttype=vt)
            await node.write_attribute(ua.AttributeIds.Description, ua.DataValue(ua.Variant(ua.LocalizedText(desc))))
            self.sim_nodes[name] = (node, vt)
        for method in ("Pause", "Resume", "Stop", "Reset"):
            await simobj.add_method(self._nid(f"Simulation.{method}"), ua.QualifiedName(method, idx),
                                    self._method(method.lower()), [], [])
        arg = ua.Argument(Name="name", DataType=ua.NodeId(ua.Int32(ua.ObjectIds.String)), ValueRank=-1,
                          Description=ua.LocalizedText("the input, INSTANCE.VARIABLE (e.g. feed.mfin)"))
        await simobj.add_method(self._nid("Simulation.Release"), ua.QualifiedName("Release", idx),
                                self._release_method, [arg], [])
        from asyncua.common.callback import CallbackType
        server.iserver.subscribe_server_callback(CallbackType.PreWrite, self._pre_write)  # type: ignore[arg-type]

    def _nid(self, name: str):
        return self.ua.NodeId(self.ua.String(name), self.ua.Int16(self.idx))

    @staticmethod
    def _initial(p: Point) -> object:
        return {"Real": 0.0, "Integer": 0, "Boolean": False, "String": ""}[p.type]

    @staticmethod
    def _cast(p: Point, value: object) -> object:
        if p.type == "Real":
            return float(value)   # type: ignore[arg-type]
        if p.type == "Integer":
            return int(value)     # type: ignore[call-overload]
        if p.type == "Boolean":
            return bool(value)
        return "" if value is None else str(value)

    # -- writes ------------------------------------------------------------------------------------------
    async def _submit(self, command: _Command) -> str | None:
        loop = asyncio.get_running_loop()
        future: asyncio.Future[str | None] = loop.create_future()

        def done(refusal: str | None) -> None:
            def settle() -> None:
                if not future.done():
                    future.set_result(refusal)
            loop.call_soon_threadsafe(settle)
        command.done = done
        if self.runner.state in ("stopped", "failed"):
            return f"the simulation is {self.runner.state}"
        self.runner.submit(command)
        try:
            return await asyncio.wait_for(future, WRITE_TIMEOUT)
        except TimeoutError:
            return "the simulation did not take the write in time"

    def _refuse(self, status: str, message: str):
        log.info("ncfmu serve: write refused (%s): %s", status, message)
        return self.ua.UaStatusCodeError(getattr(self.ua.StatusCodes, status))

    async def _pre_write(self, event, dispatcher) -> None:
        """Every client write, before asyncua applies it: checked as a whole (a refused value refuses the
        request: nothing changes), then applied by the simulation thread, which answers."""
        ua = self.ua
        planned: list[tuple[str, str, object]] = []
        for wv in event.request_params.NodesToWrite:
            nid = wv.NodeId
            if nid.NamespaceIndex != self.idx:
                continue
            key = nid.Identifier
            if wv.AttributeId != ua.AttributeIds.Value:
                raise self._refuse("BadNotWritable", f"{key}: only the Value attribute is writable")
            if getattr(event.user, "role", None) is not None and event.user.role.name == "Anonymous":
                raise self._refuse("BadUserAccessDenied", f"{key}: anonymous clients may not write")
            variant = wv.Value.Value
            value = None if variant is None else variant.Value
            vt = None if variant is None else variant.VariantType
            if isinstance(key, str) and key.endswith(".forced") and key[:-7] in self.points:
                if vt != ua.VariantType.Boolean:
                    raise self._refuse("BadTypeMismatch", f"{key} = {value!r}: must be a Boolean")
                planned.append(("force_here" if value else "release", key[:-7], None))
                continue
            p = self.points.get(key) if isinstance(key, str) else None
            if p is None:
                raise self._refuse("BadNotWritable", f"{key}: not writable")
            if p.writes and vt != self.vtype[p.type]:
                raise self._refuse("BadTypeMismatch", f"{key} = {value!r} ({vt.name if vt else 'null'}): "
                                   f"must be a {self.vtype[p.type].name}")
            try:
                checked = check_value(p, value)
            except WriteRefused as err:
                raise self._refuse(err.status, str(err)) from None
            planned.append(("force" if p.writes == "input" else "set", key, checked))
        for what, name, value in planned:
            if what == "force_here":
                what, value = "force", self._last.get(name)      # held at its present value
            refusal = await self._submit(_Command(what, name, value))
            if refusal is not None:
                raise self._refuse("BadOutOfRange" if "simulation" not in refusal else "BadInvalidState", refusal)

    def _method(self, what: str):
        async def call(parent, *args):
            if what == "stop" and self.runner.state == "failed":
                self.stopped.set()
                return []
            refusal = await self._submit(_Command(what))
            if refusal is not None:
                return self._method_refusal("BadInvalidState", refusal)
            return []
        return call

    def _method_refusal(self, status: str, message: str):
        # asyncua answers a method's exception with Bad_UnexpectedError; a returned StatusCode is the call's own
        log.info("ncfmu serve: call refused (%s): %s", status, message)
        return self.ua.StatusCode(getattr(self.ua.StatusCodes, status))

    async def _release_method(self, parent, name):
        ua = self.ua
        text = name.Value if isinstance(name, ua.Variant) else name
        if not isinstance(text, str) or text not in self.points or self.points[text].causality != "input":
            return self._method_refusal("BadInvalidArgument", f"Release({text!r}): not an input INSTANCE.VARIABLE")
        refusal = await self._submit(_Command("release", text))
        if refusal is not None:
            return self._method_refusal("BadInvalidState", refusal)
        return []

    # -- publishing ---------------------------------------------------------------------------------------
    async def _publish_once(self) -> None:
        ua = self.ua
        snap = self.runner.snapshot()
        if snap is not None:
            stamp = None
            for name, value in snap.values.items():
                if self._last.get(name) != value and name in self.nodes:
                    self._last[name] = value
                    p = self.points[name]
                    await self.server.write_attribute_value(
                        self.nodes[name].nodeid, ua.DataValue(ua.Variant(self._cast(p, value), self.vtype[p.type]),
                                                              SourceTimestamp=stamp))
            for name, p in self.points.items():
                if p.causality == "input":
                    forced = name in snap.forced
                    key = f"{name}.forced"
                    if self._last.get(key) != forced:
                        self._last[key] = forced
                        await self.server.write_attribute_value(
                            self.nodes[key].nodeid, ua.DataValue(ua.Variant(forced, ua.VariantType.Boolean)))
            await self._sim_value("time", float(snap.time))
            await self._sim_value("lag", float(snap.lag))
            await self._sim_value("overruns", int(snap.overruns))
            await self._sim_value("state", snap.state)
            await self._sim_value("reason", snap.reason)

    async def _sim_value(self, name: str, value: object) -> None:
        if self._last.get(f"Simulation.{name}") == value:
            return
        self._last[f"Simulation.{name}"] = value
        node, vt = self.sim_nodes[name]
        await self.server.write_attribute_value(node.nodeid, self.ua.DataValue(self.ua.Variant(value, vt)))

    async def serve(self, ready: Callable[[str], None] | None = None) -> None:
        await self._build()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            try:
                loop.add_signal_handler(sig, self.stopped.set)
            except (NotImplementedError, RuntimeError, ValueError):   # not the main thread, or Windows
                pass
        def wake() -> None:
            # stopped (Stop, the stop time): the server ends too; failed: it stays up so that clients see the
            # state and the reason, until Stop, Ctrl-C or SIGTERM
            if self.runner.state != "failed":
                loop.call_soon_threadsafe(self.stopped.set)
        self.runner._on_state = wake
        try:
            await self.server.start()
        except OSError as err:          # the port is taken, or the address is not this machine's
            said = os.strerror(err.errno).lower() if err.errno else str(err)
            raise ConfigError("--endpoint", self.endpoint, f"cannot listen there: {said}") from None
        try:
            self.runner.start()
            if ready is not None:
                ready(self.endpoint)
            while not self.stopped.is_set():
                await self._publish_once()
                try:
                    await asyncio.wait_for(self.stopped.wait(), self.publish_interval)
                except TimeoutError:
                    pass
            if self.runner.state == "running" or self.runner.state == "paused":
                self.runner.stop("stopped by a signal")
            await asyncio.get_running_loop().run_in_executor(None, self.runner.thread.join, 5.0)
            await self._publish_once()
        finally:
            if self.runner.thread.is_alive():      # the server failed: the FMUs must not step on while closed
                self.runner.stop("the server stopped")
                await asyncio.get_running_loop().run_in_executor(None, self.runner.thread.join, 5.0)
            await self.server.stop()


class _SaidByUs(logging.Filter):
    """asyncua logs, as errors, what ncfmu says itself: every refused request ("sending service fault
    response": a refused write is ours to report, at info, naming the variable and the rule, and a client
    flooding bad writes must not flood the log) and a port it cannot bind, with a traceback (ours is one
    line naming the endpoint)."""

    SAID = ("sending service fault response", "%s error starting server")

    def filter(self, record: logging.LogRecord) -> bool:
        return not str(record.msg).startswith(self.SAID)


def _quiet_asyncua() -> None:
    # asyncua logs every request at INFO: a write flood would cost the server more in logging than in writing
    for name in ("asyncua", "asyncua.server", "asyncua.server.uaprocessor"):
        logging.getLogger(name).setLevel(logging.WARNING)
    for name in ("asyncua.server.uaprocessor", "asyncua.server.server"):
        logger = logging.getLogger(name)
        if not any(isinstance(f, _SaidByUs) for f in logger.filters):
            logger.addFilter(_SaidByUs())


def serve(system: str = "lathe_roughing", endpoint: str = DEFAULT_ENDPOINT, speed: float = 1.0,
          start_values: Mapping[str, object] | None = None, stop_time: float | None = None,
          step_size: float | None = None, record: Sequence[str] | None = None, out: Path | str | None = None,
          security: Security | None = None, root: Path | None = None,
          ready: Callable[[str], None] | None = None) -> ServeSummary:
    """Run ``system`` (a name or an .ssp path) paced to the wall clock behind an OPC UA server at ``endpoint``
    until stopped (Ctrl-C, SIGTERM, the ``Stop`` method, ``stop_time``); with ``out``, write the recorded
    trajectory ``OUT/<system>.csv`` and the session's writes ``OUT/session_inputs.csv`` (an input CSV that
    ``ncfmu run --input`` replays). ``ready(endpoint)`` is called once clients can connect."""
    from .project import OpenSystem, system_archive
    security = security or Security()
    check_endpoint(endpoint, security)
    if stop_time is not None and not (math.isfinite(stop_time) and stop_time > 0):
        raise ConfigError("--stop-time", stop_time, "must be a number > 0")
    _quiet_asyncua()
    sys.setswitchinterval(0.001)    # the server and the simulation thread share the GIL: hand it over often
    archive = system_archive(system, root)
    files: list[Path] = []
    with OpenSystem(archive) as opened:
        recorder = Recorder(opened.system.name, Path(out)) if out is not None else None
        session = opened.open_session(
            stop_time=math.inf if stop_time is None else stop_time, step_size=step_size,
            start_values=dict(start_values or {}), record=list(record) if record else None,
            sinks=recorder.sinks() if recorder else ())
        runner = Runner(session, points_of(opened.slaves), speed, recorder)
        server = LiveServer(opened.system.name, runner, endpoint, security)
        try:
            asyncio.run(server.serve(ready))
        finally:
            writes = list(session.writes)
            end = float(session.time)
            # a served run ends by being stopped: its recording is complete unless the simulation failed
            session.close(complete=runner.state != "failed", reason=runner.reason)
            if recorder is not None:
                recorder.end_segment(writes, final=True)
                files = recorder.files
        p50, p99, pmax = runner.stats.percentiles()
        return ServeSummary(opened.system.name, end, runner.state, runner.reason,
                            runner.stats.overruns, p50, p99, pmax, files, writes, runner.wall)
