"""The OPC UA server in front of a :class:`~ncfmu.serving.runner.Runner` (:class:`LiveServer`: the address
space, the writes, the methods, the watchdog, the publishing) and :func:`serve`, which wires a system to it."""

from __future__ import annotations

import asyncio
import datetime
import gc
import logging
import math
import os
import signal
import sys
import time as _time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    from asyncua.common.node import Node
from ..errors import ConfigError
from .address_space import UNECE, UNECE_NAMESPACE, Point, WriteRefused, _unece_id, check_value, points_of
from .cnc_model import _Mirror, build_cnc_model
from .crash_watch import CrashWatch, crash_text
from .recording import Recorder
from .runner import ENDED_BADLY, Runner, _Command
from .security import APPLICATION_URI, Security, check_endpoint

log = logging.getLogger("ncfmu.serve")     # the name it had before the package was split

#: The OPC UA Severity of a crash event (1..1000; 801-1000 is "high" in Part 5).
CRASH_SEVERITY = 900

#: What the watchdog does with a lost client's forces: hold the machine (the default) or release them.
ON_LOST = ("hold", "release")
#: How long a client's write waits for the simulation thread to take it (the thread takes writes between
#: chunks, every few ms; longer means the simulation is stopped or failed).
WRITE_TIMEOUT = 2.0
#: The ``Simulation`` object's methods without an argument (:meth:`LiveServer.call`), as the address space names them
METHODS = ("Pause", "Resume", "Stop", "Reset")

DEFAULT_ENDPOINT = "opc.tcp://127.0.0.1:4840/ncfmu"

PRODUCT_URI = "urn:ncfmu"


@dataclass(eq=False)
class _Client:
    """A client's session as the watchdog sees it: when it was last heard (any request), whether it closed."""

    session: object
    heard: float

    @property
    def name(self) -> str:
        user = getattr(self.session, "user", None)
        who = getattr(user, "name", None)
        return f"{getattr(self.session, 'name', '?')}" + (f" (user {who})" if who else "")


async def _load(load, option: str, path: Path | None, what: str) -> None:
    """asyncua's certificate or key loader, its failure (no such file, not a certificate) one ConfigError."""
    try:
        await load(str(path))
    except OSError as err:
        raise ConfigError(option, str(path), f"cannot read it: {err.strerror or err}") from None
    except Exception as err:        # cryptography's parsers: ValueError, TypeError, UnsupportedAlgorithm ...
        raise ConfigError(option, str(path), f"not {what}: {type(err).__name__}") from None


def parameter_check(components: Mapping[str, str], session) -> Callable[[str, object], None]:
    """``check(INSTANCE.PARAMETER, value)``: the instance's model built anew, on a copy, from its present
    parameters and the new value (ConfigError: a rule of the model refuses it). A refused tunable then never
    reaches the FMU, which would apply it before refusing it."""
    from ..catalogue import models
    logic_of = {inst: models().get(model) for inst, model in components.items()}

    def check(name: str, value: object) -> None:
        instance, _, variable = name.partition(".")
        logic = logic_of.get(instance)
        if logic is None:
            return
        values = {p.name: session.value(f"{instance}.{p.name}") for p in logic.ports("parameter")}
        values[variable] = value
        logic.from_parameters(values)
    return check


class FrontEnd(Protocol):
    """Another front end beside the OPC UA server (the live page): it serves the OPC UA server's ``serve``."""

    async def serve(self, ready: Callable[[str], None] | None) -> None: ...


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
                 security: Security | None = None, publish_interval: float = 0.010,
                 watchdog: float | None = None, cnc_components: Mapping[str, str] | None = None,
                 on_lost: str = "hold", on_verdict: Callable[[float, str], None] | None = None) -> None:
        self.system_name, self.runner, self.endpoint = system_name, runner, endpoint
        self.security = security or Security()
        self.publish_interval = publish_interval
        self.points = {p.name: p for p in runner.points}
        self.stopped = asyncio.Event()
        self._publishing = asyncio.Lock()
        if watchdog is not None and not (math.isfinite(watchdog) and watchdog > 0):
            raise ConfigError("--watchdog", watchdog, "must be a number of seconds > 0")
        if on_lost not in ON_LOST:
            raise ConfigError("--on-lost", on_lost, f"must be one of {', '.join(ON_LOST)}")
        #: with a watchdog: a client session that forced inputs is lost when it closes or is silent this long;
        #: then (``on_lost``) the machine is held until a client calls Resume, or its forces fall back
        self.watchdog, self.on_lost = watchdog, on_lost
        self._clients: dict[int, _Client] = {}       # id(asyncua session) -> what the watchdog knows of it
        self._owner: dict[str, _Client] = {}         # a forced input -> the session that forced it last
        self._held: set[str] = set()                 # what a hold keeps forced until Resume (--on-lost hold)
        #: told each part verdict as it is published (a program ended): its time and summary line
        self.on_verdict = on_verdict
        self.verdicts_published = 0
        #: with the OPC 40502 companion model: instance -> model of the served system's components
        self.cnc_components = cnc_components
        self._mirrors: list[_Mirror] = []
        self._mirrored: dict[int, object] = {}

    async def _build(self) -> None:
        from asyncua import Server, ua
        from asyncua.crypto.permission_rules import User, UserRole
        from asyncua.server.user_managers import UserManager

        self.ua = ua
        server = self.server = Server()
        sec = self.security
        if sec.users:
            class _Users(UserManager):
                def get_user(self, iserver, username=None, password=None, certificate=None):
                    if sec.admits(username, password):
                        return User(role=UserRole.User, name=username)
                    return None
            server = self.server = Server(user_manager=_Users())
        await server.init()
        server.set_endpoint(self.endpoint)
        server.set_server_name(f"ncfmu {self.system_name}")
        from ..version import __version__
        server.product_uri = PRODUCT_URI
        await server.set_application_uri(APPLICATION_URI)
        await server.set_build_info(PRODUCT_URI, "ncfmu", "ncfmu", __version__, __version__,
                                    datetime.datetime.now(datetime.UTC))
        if sec.certificate is not None:
            await _load(server.load_certificate, "--certificate", sec.certificate, "a certificate (DER or PEM)")
            await _load(server.load_private_key, "--private-key", sec.private_key, "a private key (DER or PEM)")
            policies = [ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt]
            if sec.allow_insecure:
                policies.append(ua.SecurityPolicyType.NoSecurity)
            server.set_security_policy(policies)
            if sec.trust is not None:
                from asyncua.crypto.truststore import TrustStore
                from asyncua.crypto.validator import CertificateValidator, CertificateValidatorOptions
                store = TrustStore([Path(sec.trust)], [])
                await store.load()
                options = CertificateValidatorOptions
                server.set_certificate_validator(CertificateValidator(
                    options.TIME_RANGE | options.URI | options.TRUSTED | options.PEER_CLIENT, store))
        else:
            # only what is served: asyncua offers the signing policies too, and warns that it cannot
            server.set_security_policy([ua.SecurityPolicyType.NoSecurity])
        # users, or anonymous clients: never both (asyncua otherwise offers user names, and warns that their
        # passwords would travel in plain text, where no user was asked for)
        server.set_identity_tokens([ua.UserNameIdentityToken] if sec.users else [ua.AnonymousIdentityToken])
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
                ("state", "running", ua.VariantType.String,
                 "running, paused, held (a client was lost: see reason), crashed, stopped, failed, or faulted (a "
                 "foreign FMU's process died)"),
                ("reason", "", ua.VariantType.String,
                 "why the simulation is held, crashed, stopped, failed or faulted"),
                ("forced", [], ua.VariantType.String,
                 "the inputs a client's value overrides now, INSTANCE.VARIABLE, in system order"),
                ("crashes", 0, ua.VariantType.Int32, "crashes the part check saw since the start (or the last Reset)"),
                ("crash", "", ua.VariantType.String,
                 "the last crash: time, program line, what and how deep (empty: none)"),
                ("verdict", "", ua.VariantType.String,
                 "the part check's verdict when the last program ended: its summary line (empty: none ended yet "
                 "since the start or the last Reset)")):
            node = await simobj.add_variable(self._nid(f"Simulation.{name}"), ua.QualifiedName(name, idx),
                                             ua.Variant(value, vt), varianttype=vt)
            await node.write_attribute(ua.AttributeIds.Description, ua.DataValue(ua.Variant(ua.LocalizedText(desc))))
            self.sim_nodes[name] = (node, vt)
        crash_type = await server.create_custom_event_type(
            idx, "CrashEventType", ua.ObjectIds.BaseEventType,
            [("SimulationTime", ua.VariantType.Double), ("Line", ua.VariantType.Int32),
             ("What", ua.VariantType.String), ("DepthMm", ua.VariantType.Double)])
        self._crash_events = await server.get_event_generator(crash_type, simobj.nodeid)
        self._crashes_published = 0
        for method in METHODS:
            await simobj.add_method(self._nid(f"Simulation.{method}"), ua.QualifiedName(method, idx),
                                    self._method(method), [], [])
        arg = ua.Argument(Name="name", DataType=ua.NodeId(ua.Int32(ua.ObjectIds.String)), ValueRank=-1,
                          Description=ua.LocalizedText("the input, INSTANCE.VARIABLE (e.g. feed.mfin)"))
        await simobj.add_method(self._nid("Simulation.Release"), ua.QualifiedName("Release", idx),
                                self._release_method, [arg], [])
        if self.cnc_components is not None:
            self._mirrors = await build_cnc_model(server, idx, self.system_name, self.cnc_components, self.points,
                                                  snap.values)
        service = server.iserver.attribute_service
        self._asyncua_write = service.write
        service.write = self._write      # type: ignore[method-assign]  # why: see _write
        if self.watchdog is not None:
            self._watch_sessions(server.iserver)

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

    # -- the panel: what any client may do -- an OPC UA client's request and any other front end's (a web page)
    # come here alike. Coroutines of the server's event loop (the one :meth:`serve` runs on); each returns once
    # the simulation thread applied it and the values are published (what a client reads next shows it), or
    # raises WriteRefused (the OPC UA status's name and why; nothing changed).
    async def write(self, name: str, value: object) -> None:
        """Write one served variable as an OPC UA client's Write of its node does: ``INSTANCE.VARIABLE`` an input
        (forced to ``value``) or a tunable parameter (set), ``INSTANCE.VARIABLE.forced`` True (the input held at
        its present value) or False (released); ``value`` checked as :func:`~ncfmu.serving.address_space.check_value`
        has it. No OPC UA session owns what it forces: the watchdog never releases it."""
        command = self._command(name, value)
        refusal = await self._submit(command)
        if refusal is not None:
            raise self._refused(command, refusal)
        if command.what in ("force", "release"):
            self._owner.pop(command.name, None)
        await self._publish_once()

    async def call(self, method: str) -> None:
        """``Simulation.Pause``, ``Resume``, ``Stop`` or ``Reset`` (``method`` one of :data:`METHODS`), as an OPC UA
        client's call does it."""
        if method not in METHODS:
            raise WriteRefused("BadMethodInvalid", f"{method!r}: not a method of Simulation ({', '.join(METHODS)})")
        what = method.lower()
        if what == "stop" and self.runner.state in ENDED_BADLY:
            self.stopped.set()
            return
        refusal = await self._submit(_Command(what))
        if refusal is not None:
            raise WriteRefused("BadInvalidState", refusal)
        if what == "reset":
            self._owner.clear()            # nothing is forced after a Reset
        if what in ("reset", "resume"):     # what a hold kept is released (Resume), or all is (Reset)
            for name in self._held:
                self._owner.pop(name, None)
            self._held.clear()
        await self._publish_once()

    async def release(self, name: str) -> None:
        """``Simulation.Release(name)``: the input ``name`` (INSTANCE.VARIABLE) falls back to what drives it, as an
        OPC UA client's call does it."""
        if not self._is_input(name):
            raise WriteRefused("BadInvalidArgument", f"Release({name!r}): not an input INSTANCE.VARIABLE")
        refusal = await self._submit(_Command("release", name))
        if refusal is not None:
            raise WriteRefused("BadInvalidState", refusal)
        self._owner.pop(name, None)
        await self._publish_once()

    def _is_input(self, name: str) -> bool:
        return name in self.points and self.points[name].causality == "input"

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
        if self.runner.state in ("stopped", *ENDED_BADLY):
            return f"the simulation is {self.runner.state}"
        self.runner.submit(command)
        try:
            return await asyncio.wait_for(future, WRITE_TIMEOUT)
        except TimeoutError:
            return "the simulation did not take the write in time"

    def _status(self, status: str, message: str):
        log.info("ncfmu serve: write refused (%s): %s", status, message)
        return self.ua.StatusCode(getattr(self.ua.StatusCodes, status))

    def _plan(self, wv, user) -> _Command | tuple[str, str]:
        """One WriteValue of our namespace: the command that applies it, or (status, why) refused."""
        ua = self.ua
        nid = wv.NodeId
        key = nid.Identifier
        forced = isinstance(key, str) and key.endswith(".forced") and key[:-7] in self.points
        p = self.points.get(key) if isinstance(key, str) else None
        if p is None and not forced:
            return "BadNotWritable", f"{key}: not writable"
        if wv.AttributeId != ua.AttributeIds.Value:
            return "BadNotWritable", f"{key}: only the Value attribute is writable"
        if getattr(user, "role", None) is not None and user.role.name == "Anonymous":
            return "BadUserAccessDenied", f"{key}: anonymous clients may not write"
        variant = wv.Value.Value if wv.Value is not None else None
        value = None if variant is None else variant.Value
        vt = None if variant is None else variant.VariantType
        if forced:
            if vt != ua.VariantType.Boolean:
                return "BadTypeMismatch", f"{key} = {value!r}: must be a Boolean"
        else:
            assert p is not None
            if p.writes and vt != self.vtype[p.type]:
                return "BadTypeMismatch", (f"{key} = {value!r} ({vt.name if vt else 'null'}): "
                                           f"must be a {self.vtype[p.type].name}")
        try:
            return self._command(key, value)
        except WriteRefused as err:
            return err.status, str(err)

    def _command(self, key: str, value: object) -> _Command:
        """The command that writes ``value`` to the served variable ``key`` (see :meth:`write`), or
        :class:`WriteRefused`."""
        if key.endswith(".forced") and key[:-7] in self.points:
            if not isinstance(value, bool):
                raise WriteRefused("BadTypeMismatch", f"{key} = {value!r}: must be a Boolean")
            name = key[:-7]
            # true: held at its present value; false: released
            return _Command("force", name, self._last.get(name)) if value else _Command("release", name)
        p = self.points.get(key)
        if p is None:
            raise WriteRefused("BadNotWritable", f"{key}: not writable")
        return _Command("force" if p.writes == "input" else "set", key, check_value(p, value))

    @staticmethod
    def _refused(command: _Command, refusal: str) -> WriteRefused:
        """The simulation thread's refusal of a write: the simulation's state (held, stopped ...), else the
        model's rule."""
        status = "BadOutOfRange" if "simulation" not in refusal else "BadInvalidState"
        return WriteRefused(status, f"{command.name}: {refusal}")

    async def _write(self, params, user=None) -> list:
        """The Write service (OPC UA Part 4 5.11.4): a StatusCode per WriteValue, the good ones applied in their
        order by the simulation thread (before the same step), the bad ones changing nothing. Installed in
        place of asyncua's attribute service's ``write``: its PreWrite callback can only refuse a request as a
        whole (a ServiceFault), and it would apply our values to the address space itself."""
        ua = self.ua
        results: list = [None] * len(params.NodesToWrite)
        planned: list[tuple[int, _Command]] = []
        theirs: list[int] = []
        for i, wv in enumerate(params.NodesToWrite):
            if wv.NodeId not in self.server.iserver.aspace:   # asyncua: BadUserAccessDenied unless an admin
                results[i] = self._status("BadNodeIdUnknown", f"{wv.NodeId.to_string()}: no such node")
                continue
            if wv.NodeId.NamespaceIndex != self.idx:
                theirs.append(i)
                continue
            plan = self._plan(wv, user)
            if isinstance(plan, tuple):
                results[i] = self._status(*plan)
            else:
                planned.append((i, plan))
        if planned:
            refusals = await asyncio.gather(*(self._submit(c) for _, c in planned))
            for (i, c), refusal in zip(planned, refusals):
                if refusal is None:
                    results[i] = ua.StatusCode()
                    self._owned(c, user)
                else:
                    refused = self._refused(c, refusal)
                    results[i] = self._status(refused.status, str(refused))
            await self._publish_once()
        if theirs:
            inner = ua.WriteParameters(NodesToWrite=[params.NodesToWrite[i] for i in theirs])
            for i, result in zip(theirs, await self._asyncua_write(inner, user=user)):
                results[i] = result
        return results

    def _call_result(self, status: str, message: str, arguments: Sequence[str] = ()):
        # asyncua answers a method's exception with Bad_UnexpectedError; a returned result is the call's own
        log.info("ncfmu serve: call refused (%s): %s", status, message)
        codes = self.ua.StatusCodes
        return self.ua.CallMethodResult(StatusCode=self.ua.StatusCode(getattr(codes, status)),
                                        InputArgumentResults=[self.ua.StatusCode(getattr(codes, a))
                                                              for a in arguments])

    def _method(self, method: str):
        async def call(parent, *args):
            if args:
                return self._call_result("BadTooManyArguments", f"{method} takes no argument",
                                         ["BadTooManyArguments"] * len(args))
            try:
                await self.call(method)
            except WriteRefused as refused:
                return self._call_result(refused.status, str(refused))
            return []
        return call

    async def _release_method(self, parent, *args):
        ua = self.ua
        if not args:
            return self._call_result("BadArgumentsMissing", "Release(name): the input's name is missing")
        first = args[0]
        text = first.Value if isinstance(first, ua.Variant) else first
        if isinstance(first, ua.Variant) and first.VariantType != ua.VariantType.String or not isinstance(text, str):
            verdict = "BadTypeMismatch"
        elif not self._is_input(text):
            verdict = "BadInvalidArgument"
        else:
            verdict = "Good"
        if len(args) > 1:
            return self._call_result("BadTooManyArguments", "Release takes one argument, the input's name",
                                     [verdict] + ["BadTooManyArguments"] * (len(args) - 1))
        if verdict == "BadTypeMismatch":
            return self._call_result(verdict, f"Release({text!r}): the name must be a String", [verdict])
        try:
            await self.release(text)
        except WriteRefused as refused:          # the argument is bad (no input) or Good (the simulation refused)
            return self._call_result(refused.status, str(refused), [verdict])
        return []

    # -- the watchdog -------------------------------------------------------------------------------------
    def _watch_sessions(self, iserver) -> None:
        """Know every client session and when it was last heard. asyncua tells neither (its own session timeout
        closes a silent session after minutes, and a session with subscriptions outlives its connection): its
        ``create_session`` and each session's ``touch`` (called on every request) are wrapped, here only."""
        create = iserver.create_session

        def create_session(*args, **kwargs):
            session = create(*args, **kwargs)
            client = self._clients[id(session)] = _Client(session, _time.monotonic())
            touch = session.touch

            def touched() -> None:
                touch()
                client.heard = _time.monotonic()
            session.touch = touched
            return session
        iserver.create_session = create_session

    def _owned(self, command: _Command, user) -> None:
        if command.what == "release":
            self._owner.pop(command.name, None)
            return
        if command.what != "force":
            return
        for client in self._clients.values():
            if getattr(client.session, "user", None) is user:
                self._owner[command.name] = client
                return
        self._owner.pop(command.name, None)

    async def _watch(self) -> None:
        """Every tenth of the watchdog's time: a closed or silent session's forced inputs are released (logged,
        and recorded as any release)."""
        from asyncua.server.internal_session import SessionState
        assert self.watchdog is not None
        while not self.stopped.is_set():
            now = _time.monotonic()
            for key, client in list(self._clients.items()):
                closed = getattr(client.session, "state", None) == SessionState.Closed
                silent = now - client.heard > self.watchdog
                if closed or silent:
                    names = [name for name, owner in self._owner.items() if owner is client]
                    why = "closed" if closed else f"silent for {self.watchdog:g} s"
                    if names and self.on_lost == "hold":
                        await self._hold(client, why, names)
                        names = []
                    for name in names:
                        refusal = await self._submit(_Command("release", name))
                        if self._owner.get(name) is client:
                            del self._owner[name]
                        if refusal is not None:
                            log.warning("ncfmu serve: watchdog: could not release %s: %s", name, refusal)
                    if names:
                        log.warning("ncfmu serve: watchdog: session %s %s at t = %.3f s: released %s",
                                    client.name, why, self._last.get("Simulation.time", 0.0), ", ".join(names))
                if closed:
                    del self._clients[key]
            try:
                await asyncio.wait_for(self.stopped.wait(), min(0.1, self.watchdog / 10))
            except TimeoutError:
                pass

    async def _hold(self, client: _Client, why: str, names: Sequence[str]) -> None:
        """``--on-lost hold``: the machine goes to feed hold (Simulation.state ``held``, Simulation.reason why),
        the lost session's forces kept; Simulation.Resume (a client's explicit act) releases both."""
        for name in names:
            if self._owner.get(name) is client:
                del self._owner[name]
        feed = self.runner.feed_holds
        reason = (f"client lost: session {client.name} {why}; "
                  + (f"feed hold on {', '.join(feed)}" if feed else "halted (no feed-hold input)")
                  + f", its forces kept ({', '.join(names)}); Resume releases them")
        refusal = await self._submit(_Command("hold", value=(reason, tuple(names))))
        if refusal is not None:
            log.warning("ncfmu serve: watchdog: could not hold the machine: %s", refusal)
            return
        self._held.update(names)
        self._held.update(feed)
        log.warning("ncfmu serve: watchdog: session %s %s at t = %.3f s: %s", client.name, why,
                    self._last.get("Simulation.time", 0.0), reason)

    # -- publishing ---------------------------------------------------------------------------------------
    async def _publish_once(self) -> None:
        # one publication at a time: an answer's own publication must not be overwritten by an older snapshot
        # the periodic one is still writing
        async with self._publishing:
            await self._publish_snapshot()

    async def _publish_snapshot(self) -> None:
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
            await self._sim_value("forced", [name for name in self.points if name in snap.forced])
            await self._publish_crashes(snap.crashes)
            await self._publish_verdicts(snap.verdicts)
            if self._mirrors:
                values = {**self._last, **snap.values}
                for k, m in enumerate(self._mirrors):
                    value = m.value(values)
                    if self._mirrored.get(k) != value:
                        self._mirrored[k] = value
                        await self.server.write_attribute_value(m.node.nodeid,      # type: ignore[attr-defined]
                                                                ua.DataValue(ua.Variant(value, m.vtype)))

    async def _publish_crashes(self, crashes: Sequence) -> None:
        """The crashes not yet published: each an event; then the count and the last one's text."""
        ua = self.ua
        if len(crashes) < self._crashes_published:           # a Reset: a new run
            self._crashes_published = 0
        for c in crashes[self._crashes_published:]:
            event = self._crash_events.event
            event.Message = ua.LocalizedText(crash_text(c))
            event.Severity = CRASH_SEVERITY
            event.SimulationTime, event.Line, event.What = float(c.t), int(c.line), c.what
            event.DepthMm = float(c.depth_mm)
            await self._crash_events.trigger()
        self._crashes_published = len(crashes)
        await self._sim_value("crashes", len(crashes))
        await self._sim_value("crash", crash_text(crashes[-1]) if crashes else "")

    async def _publish_verdicts(self, verdicts: Sequence[tuple[float, str]]) -> None:
        """The last program's verdict; each new one told to :attr:`on_verdict` (printed by the CLI)."""
        if len(verdicts) < self.verdicts_published:          # a Reset: a new run
            self.verdicts_published = 0
        for t, text in verdicts[self.verdicts_published:]:
            if self.on_verdict is not None:
                self.on_verdict(t, text)
        self.verdicts_published = len(verdicts)
        await self._sim_value("verdict", verdicts[-1][1] if verdicts else "")

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
            if self.runner.state not in ENDED_BADLY:
                loop.call_soon_threadsafe(self.stopped.set)
        self.runner.on_state = wake
        try:
            await self.server.start()
        except OSError as err:          # the port is taken, or the address is not this machine's
            said = os.strerror(err.errno).lower() if err.errno else str(err)
            raise ConfigError("--endpoint", self.endpoint, f"cannot listen there: {said}") from None
        watch: asyncio.Task | None = None
        # what was built (the address space; with --cnc the OPC 40502 NodeSet import: ~5 s, many objects) lives
        # for the whole serve: collected once and frozen here, before the clock starts, so that no full
        # collection walks it in the paced loop (the ~200 ms stall once seen with --cnc was not shown to be one)
        gc.collect()
        gc.freeze()
        try:
            self.runner.start()
            if self.watchdog is not None:
                watch = asyncio.create_task(self._watch())
            if ready is not None:
                ready(self.endpoint)
            while not self.stopped.is_set():
                await self._publish_once()
                try:
                    await asyncio.wait_for(self.stopped.wait(), self.publish_interval)
                except TimeoutError:
                    pass
            if self.runner.state in ("running", "paused", "held"):
                self.runner.stop("stopped by a signal")
            await asyncio.get_running_loop().run_in_executor(None, self.runner.thread.join, 5.0)
            await self._publish_once()
        finally:
            gc.unfreeze()
            if watch is not None:
                watch.cancel()
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


def _crash_watch(opened, start_values: Mapping[str, object], recorder: Recorder | None,
                 record: Sequence[str] | None, drawing=None) -> tuple[CrashWatch | None, list, list[str] | None]:
    """The served run's part check (None: the system has none; with ``drawing``, judged against the part drawn),
    the session's sinks and what it records: with ``--record``, also what the part check reads (the CSV keeps to
    ``--record``)."""
    from ..systems.part import PartSettings, part_check_only, with_part_settings
    from ..systems.report import start_parameters
    report = part_check_only(opened.report())
    if report is not None and drawing is not None:
        report = with_part_settings(report, PartSettings(drawing=drawing))
    recording = list(recorder.sinks()) if recorder is not None else []
    columns = list(record) if record else None
    if report is None:
        return None, recording, columns
    watch = CrashWatch(report, start_parameters(opened.system.components, start_values), columns)
    if columns is not None:
        columns = list(dict.fromkeys([*columns, *report.record()]))
    return watch, watch.sinks(recording), columns


def serve(system: str = "lathe_roughing", endpoint: str = DEFAULT_ENDPOINT, speed: float = 1.0,
          start_values: Mapping[str, object] | None = None, stop_time: float | None = None,
          step_size: float | None = None, record: Sequence[str] | None = None, out: Path | str | None = None,
          security: Security | None = None, root: Path | None = None,
          ready: Callable[[str], None] | None = None, watchdog: float | None = None,
          cnc: bool = True, on_lost: str = "hold",
          on_verdict: Callable[[float, str], None] | None = None, drawing=None,
          front: Callable[[LiveServer, CrashWatch | None], FrontEnd] | None = None) -> ServeSummary:
    """Run ``system`` (a name or an .ssp path) paced to the wall clock behind an OPC UA server at ``endpoint``
    until stopped (Ctrl-C, SIGTERM, the ``Stop`` method, ``stop_time``); with ``out``, write the recorded
    trajectory ``OUT/<system>.csv`` and the session's writes ``OUT/session_inputs.csv`` (an input CSV that
    ``ncfmu run --input`` replays). ``ready(endpoint)`` is called once clients can connect. With ``watchdog``
    (s), a client session that forced inputs is lost when it closes or is silent that long: ``on_lost`` "hold"
    puts the machine in feed hold (state ``held``) until a client calls Resume, "release" lets its forces fall
    back. ``on_verdict(time, line)`` is told the part check's verdict each time a program ends (also
    ``Simulation.verdict``). With ``cnc`` (the default), the system is also served as an OPC 40502 (OPC UA for
    CNC Systems) ``CncInterface`` object (about 1 s more to start). With ``drawing`` (a
    :class:`~ncfmu.systems.drawing.Drawing`), the part check judges against the part drawn. With ``front``
    (``front(server, part check)``, e.g. the live page's :class:`ncfmu.web.WebFront`), another front end serves
    on the same loop, around the OPC UA server."""
    from ..project import OpenSystem, system_archive
    security = security or Security()
    check_endpoint(endpoint, security)
    if stop_time is not None and not (math.isfinite(stop_time) and stop_time > 0):
        raise ConfigError("--stop-time", stop_time, "must be a number > 0")
    if watchdog is not None and not (math.isfinite(watchdog) and watchdog > 0):
        raise ConfigError("--watchdog", watchdog, "must be a number of seconds > 0")
    if on_lost not in ON_LOST:
        raise ConfigError("--on-lost", on_lost, f"must be one of {', '.join(ON_LOST)}")
    _quiet_asyncua()
    sys.setswitchinterval(0.001)    # the server and the simulation thread share the GIL: hand it over often
    archive = system_archive(system, root)
    files: list[Path] = []
    with OpenSystem(archive) as opened:
        recorder = Recorder(opened.system.name, Path(out)) if out is not None else None
        watch, sinks, columns = _crash_watch(opened, start_values or {}, recorder, record, drawing)
        session = opened.open_session(
            stop_time=math.inf if stop_time is None else stop_time, step_size=step_size,
            start_values=dict(start_values or {}), record=columns, sinks=sinks)
        components = {c.name: c.model for c in opened.system.components}
        runner = Runner(session, points_of(opened.slaves), speed, recorder,
                        check_parameter=parameter_check(components, session), watch=watch)
        server = LiveServer(opened.system.name, runner, endpoint, security, watchdog=watchdog,
                            cnc_components=components if cnc else None, on_lost=on_lost, on_verdict=on_verdict)
        try:
            asyncio.run(server.serve(ready) if front is None else front(server, watch).serve(ready))
        finally:
            writes = list(session.writes)
            end = float(session.time)
            # a served run ends by being stopped: its recording is complete unless the simulation failed
            session.close(complete=runner.state not in ENDED_BADLY, reason=runner.reason)
            if watch is not None:
                watch.close()
                # the rows after the last hand-over (judged at the close): a program that ended there is told too
                if len(watch.verdicts()) > server.verdicts_published and on_verdict is not None:
                    for t, text in watch.verdicts()[server.verdicts_published:]:
                        on_verdict(t, text)
            if recorder is not None:
                recorder.end_segment(writes, final=True, start=runner.start_time)
                files = recorder.files
            writes = runner.earlier_writes + writes          # the summary counts every segment's
        p50, p99, pmax = runner.stats.percentiles()
        return ServeSummary(opened.system.name, end, runner.state, runner.reason,
                            runner.stats.overruns, p50, p99, pmax, files, writes, runner.wall)
