// An HMI that speaks OPC 40502 (OPC UA for CNC Systems) and knows nothing of ncfmu, with node-opcua: the CNC
// types by name from the NodeSet node-opcua ships (node-opcua-nodesets), the served CncInterface browsed, every
// variable under it read with its DataType resolved to a built-in type, the positions read as the structure
// CncPositionDataType and as its parts, an enumeration named by its DataType's EnumDefinition.
"use strict";
const fs = require("fs");
const { AttributeIds, BrowseDirection, DataType, NodeClass, makeBrowsePath } = require("node-opcua-client");
const { nodesets } = require("node-opcua-nodesets");
const { run } = require("./common");

const CNC = "http://opcfoundation.org/UA/CNC";

// the published NodeSet's types and data types: BrowseName -> "i=N" (namespace 1 of the file)
function cncTypes() {
    const xml = fs.readFileSync(nodesets.cnc, "utf8");
    const types = {};
    for (const m of xml.matchAll(/<UA(?:ObjectType|VariableType|DataType) NodeId="ns=1;(i=\d+)" BrowseName="1:(\w+)"/g)) {
        types[m[2]] = m[1];
    }
    return types;
}

run(async (session, ns, namespaces) => {
    const cnc = namespaces.indexOf(CNC);
    if (cnc < 0) throw new Error(`${CNC} not served`);
    const types = cncTypes();
    const byId = Object.fromEntries(Object.entries(types).map(([name, id]) => [`ns=${cnc};${id}`, name]));
    const typeName = (nodeId) => byId[nodeId.toString()] || nodeId.toString();

    async function children(nodeId) {
        const r = await session.browse({ nodeId, browseDirection: BrowseDirection.Forward, includeSubtypes: true,
                                         referenceTypeId: "HierarchicalReferences", nodeClassMask: 0, resultMask: 63 });
        if (!r.statusCode.isGood()) throw new Error(`browse ${nodeId}: ${r.statusCode.name}`);
        return r.references.map((ref) => ({ name: ref.browseName.name, ns: ref.browseName.namespaceIndex,
                                            nodeId: ref.nodeId, nodeClass: ref.nodeClass,
                                            type: typeName(ref.typeDefinition) }));
    }
    async function child(nodeId, ...path) {
        const r = await session.translateBrowsePath(makeBrowsePath(nodeId, path.map((p) => `/${cnc}:${p}`).join("")));
        if (!r.statusCode.isGood()) throw new Error(`${path.join("/")}: ${r.statusCode.name}`);
        return r.targets[0].targetId;
    }
    const num = (x) => (Number.isFinite(x) ? x : String(x));       // JSON has no Infinity
    async function read(nodeId) {
        const [dv, dataType] = await session.read([{ nodeId, attributeId: AttributeIds.Value },
                                                   { nodeId, attributeId: AttributeIds.DataType }]);
        return { status: dv.statusCode.name, variant: DataType[dv.value.dataType], value: dv.value.value,
                 dataType: typeName(dataType.value.value) };
    }
    // every variable under the interface, level by level (one Browse, one Read per level): the Variant's type
    // against the built-in type its DataType comes down to
    const variables = [];
    async function walk(root, path) {
        let level = [{ nodeId: root, path }];
        while (level.length) {
            const found = await session.browse(level.map((n) => ({
                nodeId: n.nodeId, browseDirection: BrowseDirection.Forward, includeSubtypes: true,
                referenceTypeId: "HierarchicalReferences", nodeClassMask: 0, resultMask: 63 })));
            const next = [];
            found.forEach((r, k) => {
                if (!r.statusCode.isGood() || (r.continuationPoint && r.continuationPoint.length)) {
                    throw new Error(`browse ${level[k].path}: ${r.statusCode.name}, continuation point ${r.continuationPoint}`);
                }
                for (const ref of r.references) {
                    if (ref.nodeClass === NodeClass.Method) continue;
                    const n = { nodeId: ref.nodeId, path: `${level[k].path}/${ref.browseName.name}` };
                    if (ref.nodeClass === NodeClass.Variable) variables.push(n);
                    next.push(n);
                }
            });
            level = next;
        }
        for (let k = 0; k < variables.length; k += 100) {
            const part = variables.slice(k, k + 100);
            const got = await session.read(part.flatMap((v) => [{ nodeId: v.nodeId, attributeId: AttributeIds.Value },
                                                                { nodeId: v.nodeId, attributeId: AttributeIds.DataType }]));
            part.forEach((v, j) => {
                v.status = got[2 * j].statusCode.name;
                v.variant = DataType[got[2 * j].value.dataType];
                v.dataTypeId = got[2 * j + 1].value.value;
            });
        }
        const builtIn = {};
        for (const v of variables) {
            const key = v.dataTypeId.toString();
            if (!(key in builtIn)) builtIn[key] = DataType[await session.getBuiltInDataType(v.nodeId)];
            v.builtIn = builtIn[key];
            v.dataType = typeName(v.dataTypeId);
            delete v.nodeId;
            delete v.dataTypeId;
        }
    }

    const objects = await children("ns=0;i=85");
    const ifaceRef = objects.find((o) => o.name === "CncInterface");
    if (!ifaceRef) throw new Error(`no CncInterface under Objects: ${objects.map((o) => o.name)}`);
    const iface = ifaceRef.nodeId;
    await walk(iface, "CncInterface");
    const lists = {};
    for (const c of await children(iface)) {
        if (c.name.endsWith("List")) lists[c.name] = { type: c.type, members: await children(c.nodeId) };
    }
    const axes = {};
    for (const a of lists.CncAxisList.members) {
        const pos = {};
        for (const which of ["PosDirect", "PosIndirect"]) {
            const node = await child(a.nodeId, which);
            const whole = await read(node);
            const part = async (name) => (await read(await child(node, name))).value;
            const eu = (await read(await child(node, "EngineeringUnits"))).value;
            const range = (await read(await child(node, "EURange"))).value;
            pos[which] = {
                dataType: whole.dataType, variant: whole.variant,
                // the structure as node-opcua decodes it with the DataTypeDefinition the server gives
                whole: whole.value && { ActPos: whole.value.actPos, CmdPos: whole.value.cmdPos,
                                        RemDist: whole.value.remDist },
                ActPos: await part("ActPos"), CmdPos: await part("CmdPos"), RemDist: await part("RemDist"),
                unit: { unitId: eu.unitId, displayName: eu.displayName.text, namespaceUri: eu.namespaceUri },
                range: { low: num(range.low), high: num(range.high) },
            };
        }
        axes[a.name] = { type: a.type, ...pos };
    }
    const channels = {};
    for (const ch of lists.CncChannelList.members) {
        const status = await read(await child(ch.nodeId, "ActProgramStatus"));
        // the enumeration's value named by its DataType's definition (an EnumDefinition), as the server gives it
        const definition = (await session.read({ nodeId: await child(ch.nodeId, "ActProgramStatus"),
                                                 attributeId: AttributeIds.DataType })).value.value;
        const fields = (await session.read({ nodeId: definition, attributeId: AttributeIds.DataTypeDefinition }))
            .value.value.fields;
        const int64 = (x) => (Array.isArray(x) ? x[0] * 2 ** 32 + x[1] : Number(x));    // node-opcua: [high, low]
        const names = Object.fromEntries(fields.map((f) => [int64(f.value), f.name]));
        const value = async (name) => (await read(await child(ch.nodeId, name))).value;
        channels[ch.name] = { type: ch.type, ActProgramStatus: status.value, status: names[status.value],
                              statusType: status.dataType, statusVariant: status.variant,
                              ActProgramName: await value("ActProgramName"),
                              ActProgramBlock: await value("ActProgramBlock"), ActOverride: await value("ActOverride") };
    }
    const spindles = {};
    for (const sp of lists.CncSpindleList.members) {
        spindles[sp.name] = { type: sp.type, ActSpeed: (await read(await child(sp.nodeId, "ActSpeed"))).value };
    }
    return { iface: { type: ifaceRef.type, ns: ifaceRef.ns === ns },
             lists: Object.fromEntries(Object.entries(lists).map(([k, v]) => [k, v.type])),
             axes, channels, spindles, variables };
});
