"""The served system as OPC UA for CNC Systems (OPC 40502): the NodeSet's types and a ``CncInterface`` object
whose axes, spindles and channels mirror the served values (:func:`build_cnc_model`)."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path

from .address_space import UNECE_NAMESPACE, Point, _unece_id

CNC_NAMESPACE = "http://opcfoundation.org/UA/CNC"
#: The OPC Foundation's published NodeSet of OPC 40502 v1.00 (OPC Foundation MIT License 1.00, in its header),
#: as node-opcua's npm package node-opcua-nodesets ships it.
CNC_NODESET = Path(__file__).parents[1] / "data" / "Opc.Ua.CNC.NodeSet2.xml"
#: The models whose instances the companion model shows: an axis, a spindle, a channel (an NC cycle controller)
CNC_AXIS_MODELS = ("ServoAxis",)
CNC_SPINDLE_MODELS = ("SpindleDrive",)
# the enumerations' values (OPC 40502 6.x: CncAxisStatus, CncChannelProgramStatus, CncChannelStatus, ...)
AXIS_IN_POSITION, AXIS_MOVING = 0, 1
PROGRAM_STOPPED, PROGRAM_RUNNING, PROGRAM_WAITING, PROGRAM_INTERRUPTED, PROGRAM_CANCELED = 0, 1, 2, 3, 4
CHANNEL_RESET, CHANNEL_INTERRUPTED, CHANNEL_ACTIVE = 0, 1, 2
MODE_AUTOMATIC = 2
SPINDLE_STOPPED, SPINDLE_IN_TARGET, SPINDLE_ACCELERATING = 0, 1, 2
TURN_NONE, TURN_CW, TURN_CCW = 0, 1, 2


def cnc_types_xml(path: Path = CNC_NODESET) -> str:
    """The NodeSet's types only: the published file also holds example instances (``test`` under Objects, axes
    ``X``, ``Y``, ``Channel_1`` ... without a parent) that asyncua refuses and a client must not see. They are
    left out, with every reference to them."""
    import xml.etree.ElementTree as ET
    ua_ns = "http://opcfoundation.org/UA/2011/03/UANodeSet.xsd"
    ET.register_namespace("", ua_ns)
    root = ET.parse(path).getroot()

    def q(tag: str) -> str:
        return f"{{{ua_ns}}}{tag}"
    instances = {n.get("NodeId"): n for n in root if n.tag in (q("UAObject"), q("UAVariable"), q("UAMethod"))}

    def type_definition(n) -> str:
        for r in n.iter(q("Reference")):
            if r.get("ReferenceType") == "HasTypeDefinition":
                return r.text or ""
        return ""
    dropped: set[str | None] = set()
    changed = True
    while changed:
        changed = False
        for nid, n in instances.items():
            if nid in dropped:
                continue
            example = not n.get("ParentNodeId") and type_definition(n).startswith(("ns=1;", "i=61"))
            if example or n.get("ParentNodeId") in dropped:
                dropped.add(nid)
                changed = True
    for n in list(root):
        if n.get("NodeId") in dropped:
            root.remove(n)
            continue
        refs = n.find(q("References"))
        for r in list(refs) if refs is not None else ():
            if r.text in dropped:
                refs.remove(r)         # type: ignore[union-attr]
    return ET.tostring(root, encoding="unicode")


@dataclass
class _Mirror:
    """A node of the companion model that shows a function of the served values."""

    node: object
    vtype: object
    value: Callable[[Mapping[str, object]], object]


async def build_cnc_model(server, idx: int, system: str, components: Mapping[str, str],
                          points: Mapping[str, Point], values: Mapping[str, object] | None = None) -> list[_Mirror]:
    """The served system as an OPC 40502 ``CncInterfaceType`` object ``Objects/CncInterface`` (NodeIds
    ``ns=<idx>;s=Cnc...``): ``CncAxisList`` (an axis per servo axis: ``PosDirect``/``PosIndirect`` ``ActPos`` =
    the axis's ``pos``, ``CmdPos`` = its ``pos_cmd``, ``RemDist`` = CmdPos - ActPos, mm, with EngineeringUnits and
    EURange; ``ActStatus`` in position or moving; ``ActTorque`` within +-``torque_max``), ``CncChannelList`` (a
    channel per NC cycle controller: program status, the system's name as the active program, the block -- the
    part program's line where the controller says it, else its block number --, feed override % within its
    port's range, feed hold, mode automatic) and ``CncSpindleList`` (a spindle per spindle drive: speeds within
    +-``speed_max``, torque, power, status, turn direction). With one channel, each drive's ``ActChannel`` is
    it. What the served system has nothing for: a mandatory variable reads Bad_NotConnected (never the 0 or the
    empty value a client would take for known), an optional one is left out (:func:`_settle_unvalued`).
    ``values``: the served values at the start (the parameters' for the ranges). The mirrors that keep the
    model current."""
    from asyncua import ua

    from ..catalogue import models
    from ..controllers.cycle import CycleController
    from ..version import __version__
    await server.import_xml(xmlstring=cnc_types_xml())
    cnc = await server.get_namespace_index(CNC_NAMESPACE)
    start = dict(values or {})
    fed: set = set()            # the NodeIds of what ncfmu writes or mirrors

    def nid(name: str):
        return ua.NodeId(ua.String(name), ua.Int16(idx))

    def t(number: int):
        return ua.NodeId(ua.Int32(number), ua.Int16(cnc))
    async def add(parent, name: str, node_id: str, type_number: int):
        # asyncua instantiates a type's optional placeholders too (CncChannelType's <CncAxis>, <CncSpindle>):
        # a client would browse them as members, zero-filled; a placeholder is the type's, not an instance's
        obj = await parent.add_object(nid(node_id), ua.QualifiedName(name, idx), objecttype=t(type_number))
        for c in await obj.get_children():
            if (await c.read_browse_name()).Name.startswith("<"):
                await server.delete_nodes([c], recursive=True)
        return obj

    async def child(parent, path: str):
        # the NodeSet's own browse names, or OPC UA's (an AnalogUnitType's EURange is 0:EURange)
        node = parent
        for p in path.split("/"):
            try:
                node = await node.get_child([f"{cnc}:{p}"])
            except ua.UaStatusCodeError:
                node = await node.get_child([f"0:{p}"])
        return node

    async def put(parent, path: str, value) -> None:
        node = await child(parent, path)
        await node.write_value(value)
        fed.add(node.nodeid)

    def limit(name: str) -> float | None:
        v = start.get(name)
        return float(v) if isinstance(v, (int, float)) and math.isfinite(v) and v > 0 else None

    async def symmetric(parent, path: str, name: str, scale: float = 1.0) -> None:
        # a range ncfmu knows: +- a limit parameter of the component (speed_max, torque_max, power_max)
        v = limit(name)
        if v is not None:
            await put(parent, f"{path}/EURange", ua.Range(Low=-v * scale, High=v * scale))
    iface = await add(server.nodes.objects, "CncInterface", "Cnc", 1007)
    for name, value in (("VendorName", "ncfmu"), ("VendorRevision", __version__), ("Version", "1.00"),
                        ("CncTypeName", f"ncfmu {system}")):
        try:
            node = await iface.get_child([f"{cnc}:{name}"])
        except ua.UaStatusCodeError:             # an optional property: added
            node = await iface.add_property(nid(f"Cnc.{name}"), ua.QualifiedName(name, cnc), value)
        await node.write_value(ua.Variant(value, ua.VariantType.String))
        fed.add(node.nodeid)
    mirrors: list[_Mirror] = []
    D, I32, B, S, U32 = (ua.VariantType.Double, ua.VariantType.Int32, ua.VariantType.Boolean,
                         ua.VariantType.String, ua.VariantType.UInt32)

    async def mirror(parent, path: str, vtype, fn) -> None:
        node = await child(parent, path)
        mirrors.append(_Mirror(node, vtype, fn))
        fed.add(node.nodeid)

    def real(name: str) -> Callable[[Mapping[str, object]], float]:
        return lambda v: float(v.get(name) or 0.0)          # type: ignore[arg-type]
    logic = models()
    # CncPositionDataType: the class import_xml made from the NodeSet's definition
    position = ua.CncPositionDataType         # type: ignore[attr-defined]
    axis_list = await iface.get_child([f"{cnc}:CncAxisList"])
    spindle_list = await iface.get_child([f"{cnc}:CncSpindleList"])
    channel_list = await iface.get_child([f"{cnc}:CncChannelList"])
    channel_id = 0
    drives, channels = [], []
    for inst, model in components.items():
        if model in CNC_AXIS_MODELS:
            axis = await add(axis_list, inst, f"Cnc.{inst}", 1004)
            drives.append(axis)
            pos, cmd = f"{inst}.pos", f"{inst}.pos_cmd"
            low = points[cmd].minimum if cmd in points else None
            high = points[cmd].maximum if cmd in points else None
            eu = ua.EUInformation(NamespaceUri=UNECE_NAMESPACE, UnitId=_unece_id("MMT"),
                                  DisplayName=ua.LocalizedText("mm"), Description=ua.LocalizedText("millimetre"))
            span = ua.Range(Low=-math.inf if low is None else low, High=math.inf if high is None else high)
            for which in ("PosDirect", "PosIndirect"):
                await put(axis, f"{which}/EngineeringUnits", eu)
                await put(axis, f"{which}/EURange", span)
                # the position variable's own value, the structure of the three (what a client reads whole)
                await mirror(axis, which, ua.VariantType.ExtensionObject, lambda v, pos=pos, cmd=cmd: position(
                    ActPos=real(pos)(v), CmdPos=real(cmd)(v), RemDist=real(cmd)(v) - real(pos)(v)))
                await mirror(axis, f"{which}/ActPos", D, real(pos))
                await mirror(axis, f"{which}/CmdPos", D, real(cmd))
                await mirror(axis, f"{which}/RemDist", D,
                             lambda v, pos=pos, cmd=cmd: real(cmd)(v) - real(pos)(v))
            await mirror(axis, "ActStatus", I32, lambda v, inst=inst: AXIS_IN_POSITION
                         if v.get(f"{inst}.in_position") else AXIS_MOVING)
            await mirror(axis, "ActTorque", D, real(f"{inst}.torque"))
            await symmetric(axis, "ActTorque", f"{inst}.torque_max")
            await mirror(axis, "IsInactive", B, lambda v, inst=inst: not v.get(f"{inst}.enable", True))
            await put(axis, "IsReferenced", True)
            await put(axis, "IsRotational", False)         # a servo axis of ncfmu is linear, in mm
            await put(axis, "IsVirtual", False)
        elif model in CNC_SPINDLE_MODELS:
            spindle = await add(spindle_list, inst, f"Cnc.{inst}", 1005)
            drives.append(spindle)
            speed, cmd = f"{inst}.speed", f"{inst}.speed_cmd"
            await mirror(spindle, "ActSpeed", D, real(speed))
            await mirror(spindle, "CmdSpeed", D, real(cmd))
            for which in ("ActSpeed", "CmdSpeed"):      # rev/min, signed: as the NodeSet's min⁻¹
                await symmetric(spindle, which, f"{inst}.speed_max")
            await mirror(spindle, "ActTorque", D, real(f"{inst}.torque"))
            await symmetric(spindle, "ActTorque", f"{inst}.torque_max")
            await mirror(spindle, "ActPower", D, lambda v, inst=inst: 1e3 * real(f"{inst}.power")(v))   # kW -> W
            await symmetric(spindle, "ActPower", f"{inst}.power_max", 1e3)
            await mirror(spindle, "ActStatus", I32, lambda v, inst=inst, speed=speed: SPINDLE_STOPPED
                         if abs(real(speed)(v)) < 1e-9 else SPINDLE_IN_TARGET if v.get(f"{inst}.at_speed")
                         else SPINDLE_ACCELERATING)
            await mirror(spindle, "ActTurnDirection", I32, lambda v, speed=speed: TURN_NONE
                         if abs(real(speed)(v)) < 1e-9 else TURN_CW if real(speed)(v) > 0 else TURN_CCW)
            await mirror(spindle, "IsInactive", B, lambda v, inst=inst: not v.get(f"{inst}.enable", True))
            await put(spindle, "IsVirtual", False)
        elif model in logic and issubclass(logic[model], CycleController):
            channel_id += 1
            channel = await add(channel_list, inst, f"Cnc.{inst}", 1002)
            channels.append(channel)
            block = next((f"{inst}.{b}" for b in ("line", "block_no", "pc", "segment") if f"{inst}.{b}" in points),
                         None)

            def program_status(v, inst=inst) -> int:
                if v.get(f"{inst}.alarm"):
                    return PROGRAM_CANCELED
                if not v.get(f"{inst}.busy"):
                    return PROGRAM_STOPPED
                if v.get(f"{inst}.feed_hold"):
                    return PROGRAM_INTERRUPTED
                return PROGRAM_WAITING if v.get(f"{inst}.m_active") else PROGRAM_RUNNING
            await mirror(channel, "ActProgramStatus", I32, program_status)
            await mirror(channel, "ActStatus", I32, lambda v, st=program_status: CHANNEL_ACTIVE
                         if st(v) in (PROGRAM_RUNNING, PROGRAM_WAITING) else CHANNEL_INTERRUPTED
                         if st(v) == PROGRAM_INTERRUPTED else CHANNEL_RESET)
            await mirror(channel, "ActProgramBlock", S, lambda v, block=block: "" if block is None
                         else str(v.get(block, "")))
            override = points.get(f"{inst}.feed_override")
            for which in ("ActOverride", "CmdOverride"):
                await mirror(channel, which, D, lambda v, inst=inst: 100.0 * real(f"{inst}.feed_override")(v))
                if override is not None and override.minimum is not None and override.maximum is not None:
                    await put(channel, f"{which}/EURange", ua.Range(Low=100.0 * override.minimum,
                                                                    High=100.0 * override.maximum))
            await mirror(channel, "FeedHold", B, lambda v, inst=inst: bool(v.get(f"{inst}.feed_hold")))
            fixed: tuple[tuple[str, object, object], ...]
            fixed = (("ActProgramName", system, S), ("ActMainProgramName", system, S),
                     ("ActOperationMode", MODE_AUTOMATIC, I32), ("CmdOperationMode", MODE_AUTOMATIC, I32),
                     ("Id", channel_id, U32), ("BlockMode", False, B))      # no single-block mode in ncfmu
            for prop, fixed_value, vt in fixed:
                await put(channel, prop, ua.Variant(fixed_value, vt))
    if len(channels) == 1:                      # one channel: every drive is its
        for drive in drives:
            await put(drive, "ActChannel", ua.Variant(channels[0].nodeid, ua.VariantType.NodeId))
    await _settle_unvalued(server, iface, fed)
    return mirrors


async def _settle_unvalued(server, iface, fed: set) -> None:
    """What the served system has nothing for, below ``iface`` (the variables not in ``fed``): an optional one
    (its instance declaration's ModellingRule) is deleted; a mandatory one reads Bad_NotConnected ("should
    receive its value from another variable, but has never been configured to do so"), the value Null -- never
    the Good 0, "" or Null that asyncua instantiated it with, which a client takes for known. The
    EngineeringUnits the NodeSet declares (N·m, %, min⁻¹ ...) stay: a unit is the type's, not a value."""
    from asyncua import ua
    from asyncua.common.ua_utils import get_node_supertypes
    optional = {ua.NodeId(ua.Int32(ua.ObjectIds.ModellingRule_Optional)),
                ua.NodeId(ua.Int32(ua.ObjectIds.ModellingRule_OptionalPlaceholder))}
    unknown = ua.DataValue(ua.Variant(), StatusCode=ua.StatusCode(ua.UInt32(ua.StatusCodes.BadNotConnected)))
    declared: dict = {}

    async def declarations(decl) -> dict:
        # as asyncua instantiates: the children of the type or declaration and of its supertypes, lowest first
        key = decl.nodeid
        if key not in declared:
            found: dict = {}
            for parent in await get_node_supertypes(decl, includeitself=True):
                for d in await parent.get_children_descriptions():
                    found.setdefault(d.BrowseName.Name, server.get_node(d.NodeId))
            declared[key] = found
        return declared[key]

    async def settle(node, decl) -> None:
        decls = await declarations(decl) if decl is not None else {}
        for child in await node.get_children():
            name = (await child.read_browse_name()).Name
            cls = await child.read_node_class()
            if cls not in (ua.NodeClass.Object, ua.NodeClass.Variable):
                continue
            d = decls.get(name)
            if d is None:                   # ncfmu's own (an axis, a spindle, a channel): from its type
                d = await child.read_type_definition()
                d = server.get_node(d) if d is not None else None
            if cls == ua.NodeClass.Variable and child.nodeid not in fed:
                if name == "EngineeringUnits" and (await child.read_value()) is not None:
                    continue
                rule = await d.get_referenced_nodes(refs=ua.ObjectIds.HasModellingRule) if d is not None else []
                if rule and rule[0].nodeid in optional:
                    await server.delete_nodes([child], recursive=True)
                    continue
                await server.write_attribute_value(child.nodeid, unknown)
            await settle(child, d)
    await settle(iface, server.get_node(await iface.read_type_definition()))
