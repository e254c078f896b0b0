// A PLC's requests with node-opcua: a batch Write with one bad value, a Write and a Read of a node that is not
// there, Simulation.Release with no, a wrong-typed and too many arguments. Each answer's StatusCode by name.
"use strict";
const { AttributeIds, DataType } = require("node-opcua-client");
const { run } = require("./common");

run(async (session, ns) => {
    const id = (name) => `ns=${ns};s=${name}`;
    const value = (dataType, v) => ({ value: { dataType, value: v } });
    const write = async (...items) => (await session.write(items.map(([name, dataType, v]) => ({
        nodeId: id(name), attributeId: AttributeIds.Value, value: value(dataType, v) })))).map((s) => s.name);
    const read = async (name) => {
        const dv = await session.read({ nodeId: id(name), attributeId: AttributeIds.Value });
        return { status: dv.statusCode.name, value: dv.value.value, type: DataType[dv.value.dataType] };
    };
    const batch = await write(["panel.override", DataType.Double, 0.8], ["panel.override", DataType.Double, 9.0]);
    const mixed = await write(["seq.feed_override", DataType.Double, 0.5], ["seq.no_such_input", DataType.Double, 1.0],
                              ["x_axis.pos", DataType.Double, 1.0], ["seq.feed_hold", DataType.Double, 1.0],
                              ["panel.mfin_delay", DataType.Double, 0.25]);
    const unknownWrite = await write(["seq.no_such_input", DataType.Double, 1.0]);
    const unknownRead = await read("seq.no_such_input");
    const release = (...args) => ({ objectId: id("Simulation"), methodId: id("Simulation.Release"),
                                    inputArguments: args });
    const calls = (await session.call([
        release(),
        release({ dataType: DataType.Double, value: 1.0 }),
        release({ dataType: DataType.String, value: "seq.feed_hold" }, { dataType: DataType.String, value: "seq.start" }),
        release({ dataType: DataType.String, value: "seq.feed_override" }),     // forced above: released
    ])).map((r) => ({ status: r.statusCode.name, arguments: (r.inputArgumentResults || []).map((s) => s.name) }));
    return { batch, mixed, unknownWrite, unknownRead, calls,
             after: { override: await read("panel.override"), mfin_delay: await read("panel.mfin_delay"),
                      feed_hold_forced: await read("seq.feed_hold.forced") } };
});
