// What the node-opcua scripts share: a session with the served system, the served namespace's index, and the
// answer printed as one JSON line ("RESULT {...}") for the Python test to judge.
"use strict";
const os = require("os");
const path = require("path");
// node-opcua's client and certificate manager, not the whole of node-opcua (its server too): half the load time
const { OPCUAClient, MessageSecurityMode, SecurityPolicy } = require("node-opcua-client");
const { OPCUACertificateManager } = require("node-opcua-certificate-manager");

async function withSession(work) {
    const [endpoint, namespaceUri, pki] = process.argv.slice(2);
    const client = OPCUAClient.create({
        applicationName: "ncfmu-test-node-opcua",
        endpointMustExist: false,
        securityMode: MessageSecurityMode.None,
        securityPolicy: SecurityPolicy.None,
        connectionStrategy: { maxRetry: 0 },       // a server that is not there fails the test, at once
        // the client's own certificate (made on first use, even for policy None) in the test's folder, not ~/.config
        clientCertificateManager: new OPCUACertificateManager({ rootFolder: pki || path.join(os.tmpdir(), "pki") }),
    });
    await client.connect(endpoint);
    let session;
    try {
        session = await client.createSession();
        const namespaces = await session.readNamespaceArray();
        const ns = namespaces.indexOf(namespaceUri);
        if (ns < 0) throw new Error(`namespace ${namespaceUri} not served: ${namespaces}`);
        const result = await work(session, ns, namespaces);
        console.log("RESULT " + JSON.stringify(result));
    } finally {
        if (session) await session.close();
        await client.disconnect();
    }
}

// node-opcua leaves timers running after the session closed: the process ends when the answer is out
function run(work) {
    withSession(work).then(() => process.exit(0), (err) => {
        console.error(err && err.stack ? err.stack : String(err));
        process.exit(1);
    });
}

module.exports = { run };
