"""``ncfmu serve`` with a third OPC UA stack as the client: node-opcua (Node.js), which ships the OPC 40502 CNC
types. Its version is pinned in one place, ``tests/serve/node/package.json`` with its ``package-lock.json``:
``npm ci`` installs exactly that once per test session into a cache folder (``~/.cache/ncfmu-node/<hash of the
lock file>``, or ``$NCFMU_NODE_CACHE``), reused while the lock file is unchanged. No node, npm or registry: the
tests fail saying so -- a second stack that is not there is a check not made, not one passed.

The scripts in ``tests/serve/node/`` make the requests and print what they got as one JSON line; the judging is
here. Each test starts a server process: ``slow``."""

from __future__ import annotations

import asyncio
import hashlib
import json
import os
import shutil
import subprocess
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import pytest
from serve_plc import connect, run

NODE_DIR = Path(__file__).parent / "node"
PINNED = json.loads((NODE_DIR / "package.json").read_text())["dependencies"]["node-opcua"]


@dataclass
class NodeOpcua:
    """node and the installed node-opcua: ``script(name, served)`` runs ``tests/serve/node/<name>`` against a
    served system and returns what it printed after ``RESULT``."""

    node: str
    modules: Path
    pki: Path

    def script(self, name: str, served, timeout: float = 180.0) -> dict:
        done = subprocess.run([self.node, str(NODE_DIR / name), served.endpoint, served.namespace, str(self.pki)],
                              capture_output=True, text=True, timeout=timeout,
                              env={**os.environ, "NODE_PATH": str(self.modules)})
        assert done.returncode == 0 and "RESULT " in done.stdout, (
            f"node {name} (node-opcua {PINNED}) failed, exit {done.returncode}:\n{done.stderr}\n{done.stdout}")
        return json.loads(done.stdout.rsplit("RESULT ", 1)[1].splitlines()[0])


@pytest.fixture(scope="session")
def node_opcua(tmp_path_factory) -> NodeOpcua:
    node, npm = shutil.which("node"), shutil.which("npm")
    if node is None or npm is None:
        pytest.fail("the node-opcua tests need Node.js: node and npm on the PATH (https://nodejs.org/, or the "
                    "distribution's nodejs and npm packages)", pytrace=False)
    files = [NODE_DIR / "package.json", NODE_DIR / "package-lock.json"]
    key = hashlib.sha256(b"".join(f.read_bytes() for f in files)).hexdigest()[:16]
    root = Path(os.environ.get("NCFMU_NODE_CACHE") or Path.home() / ".cache" / "ncfmu-node")
    cache = root / key
    if not (cache / "installed").exists():
        root.mkdir(parents=True, exist_ok=True)
        work = Path(tempfile.mkdtemp(prefix=f"{key}.", dir=root))    # installed aside, then renamed: atomic
        for f in files:
            shutil.copy(f, work / f.name)
        started = time.monotonic()
        try:
            done = subprocess.run([npm, "ci", "--no-audit", "--no-fund", "--ignore-scripts", "--loglevel=error"],
                                  cwd=work, capture_output=True, text=True, timeout=900)
        except subprocess.TimeoutExpired:
            shutil.rmtree(work, ignore_errors=True)
            pytest.fail(f"npm ci of node-opcua {PINNED} took more than 900 s (is the npm registry reachable?)",
                        pytrace=False)
        if done.returncode != 0:
            shutil.rmtree(work, ignore_errors=True)
            pytest.fail(f"npm ci of node-opcua {PINNED} (tests/serve/node/package-lock.json) failed, exit "
                        f"{done.returncode} -- is the npm registry reachable? {done.stderr.strip()[-2000:]}",
                        pytrace=False)
        (work / "installed").write_text(f"npm ci in {time.monotonic() - started:.1f} s\n")
        try:
            work.rename(cache)
        except OSError:                      # another session installed it meanwhile: theirs is as good
            shutil.rmtree(work, ignore_errors=True)
    return NodeOpcua(node, cache / "node_modules", tmp_path_factory.mktemp("node-opcua-pki"))


# -- a PLC's requests: Write results per node, unknown nodes, method arguments -----------------------------------
@pytest.mark.slow
def test_node_opcua_gets_a_result_per_node_and_per_argument(ncfmu_serve, node_opcua):
    served = ncfmu_serve("lathe_roughing", "--no-cnc", "--speed", "2")
    got = node_opcua.script("write_call.js", served)
    # (a) a batch [override 0.8, override 9.0]: the good one applied, the bad one says why
    assert got["batch"] == ["Good", "BadOutOfRange"]
    assert got["mixed"] == ["Good", "BadNodeIdUnknown", "BadNotWritable", "BadTypeMismatch", "Good"]
    assert got["after"]["override"] == {"status": "Good", "value": 0.8, "type": "Double"}
    assert got["after"]["mfin_delay"]["value"] == 0.25
    assert got["after"]["feed_hold_forced"]["value"] is False          # its Double write was refused
    # (b) a node that is not there, written alone and read
    assert got["unknownWrite"] == ["BadNodeIdUnknown"]
    assert got["unknownRead"]["status"] == "BadNodeIdUnknown"
    # (c) Simulation.Release with no, a Double and two arguments; then a good one
    assert got["calls"] == [
        {"status": "BadArgumentsMissing", "arguments": []},
        {"status": "BadTypeMismatch", "arguments": ["BadTypeMismatch"]},
        {"status": "BadTooManyArguments", "arguments": ["Good", "BadTooManyArguments"]},
        {"status": "Good", "arguments": ["Good"]},
    ]

    async def plc():             # asyncua sees the same: the dial's 0.8 reached the sequencer, the force released
        async with connect(served) as p:
            await p.wait_until("seq.feed_override", lambda v: v == 0.8, timeout=5)
            assert await p.read("seq.feed_override.forced") is False
            assert await p.read("Simulation.forced") == []
    run(plc())
    assert served.stop() == 0, served.output
    assert "Traceback" not in served.output


# -- an HMI that speaks OPC 40502 --------------------------------------------------------------------------------
@pytest.mark.slow
def test_node_opcua_reads_the_cnc_companion_model_typed(ncfmu_serve, node_opcua):
    """Browsed by the CNC types' names from node-opcua's own copy of the NodeSet: each axis's ActPos -- alone and
    in its CncPositionDataType structure -- is the axis's position output as asyncua reads it at the same paused
    time; every variable's value has its DataType's built-in type; no placeholder (``<CncAxis>``) is shown as if
    it were an axis, no position that is not known as if it were 0."""
    served = ncfmu_serve("lathe_roughing", "--speed", "2", "--cnc")

    async def paused():
        async with connect(served) as p:
            await p.wait_until("seq.busy", lambda v: v is True, timeout=30)
            await p.wait_until("x_axis.pos", lambda x: x < 29.0, timeout=30)     # moving in
            await p.call("Pause")
            await asyncio.sleep(0.1)                                             # a publication after the pause
            names = ("Simulation.time", "x_axis.pos", "x_axis.pos_cmd", "z_axis.pos", "z_axis.pos_cmd", "seq.line",
                     "spindle.speed")
            return {n: await p.read(n) for n in names}
    before = run(paused())
    got = node_opcua.script("cnc.js", served)
    after = run(paused())
    assert after == before                            # still paused: both clients saw the same instant

    assert got["iface"] == {"type": "CncInterfaceType", "ns": True}
    assert got["lists"] == {"CncAxisList": "CncAxisListType", "CncChannelList": "CncChannelListType",
                            "CncSpindleList": "CncSpindleListType"}
    assert set(got["axes"]) == {"x_axis", "z_axis"}
    assert before["x_axis.pos"] < 29.0
    for name, axis in got["axes"].items():
        assert axis["type"] == "CncAxisType"
        pos, cmd = before[f"{name}.pos"], before[f"{name}.pos_cmd"]
        for which in ("PosDirect", "PosIndirect"):
            p = axis[which]
            assert (p["ActPos"], p["CmdPos"]) == (pos, cmd), (name, which)
            assert p["RemDist"] == pytest.approx(cmd - pos, abs=1e-12)
            assert (p["dataType"], p["variant"]) == ("CncPositionDataType", "ExtensionObject")
            assert p["whole"] == {"ActPos": pos, "CmdPos": cmd, "RemDist": p["RemDist"]}, (name, which)
            assert p["unit"] == {"unitId": int.from_bytes(b"MMT", "big"), "displayName": "mm",
                                 "namespaceUri": "http://www.opcfoundation.org/UA/units/un/cefact"}
    assert list(got["channels"]) == ["seq"]
    seq = got["channels"]["seq"]
    assert seq["type"] == "CncChannelType"
    assert (seq["ActProgramStatus"], seq["status"]) == (1, "Running")
    assert (seq["statusType"], seq["statusVariant"]) == ("CncChannelProgramStatus", "Int32")
    assert seq["ActProgramName"] == "lathe_roughing" and seq["ActProgramBlock"] == str(before["seq.line"])
    assert seq["ActOverride"] == 100.0
    assert got["spindles"] == {"spindle": {"type": "CncSpindleType", "ActSpeed": before["spindle.speed"]}}
    variables = got["variables"]
    assert len(variables) > 100
    placeholders = sorted({v["path"].split(">")[0] + ">" for v in variables if "<" in v["path"]})
    assert placeholders == [], placeholders
    # a position has a value only where it is known: the axes' (checked above); the channel's tool centre point
    # (12 coordinates) and the spindle's angle, the structures and their parts, say Bad_NotConnected -- they read
    # 0 as if known
    positions = {v["path"]: v for v in variables if v["dataType"] == "CncPositionDataType"}
    known = {f"CncInterface/CncAxisList/{a}/{p}" for a in ("x_axis", "z_axis") for p in ("PosDirect", "PosIndirect")}
    assert {p for p, v in positions.items() if v["status"] == "Good"} == known
    assert len(positions) == len(known) + 12 + 1, sorted(positions)
    unknown = [v for v in variables if v["path"] in set(positions) - known
               or v["path"].rsplit("/", 1)[0] in set(positions) - known
               and v["path"].rsplit("/", 1)[1] in ("ActPos", "CmdPos", "RemDist")]
    assert len(unknown) == 4 * 13
    assert {(v["status"], v["variant"]) for v in unknown} == {("BadNotConnected", "Null")}, unknown
    variables = [v for v in variables if v not in unknown]
    # every value there is of its DataType's built-in type; what the system has nothing for says so -- Null only
    # with Bad_NotConnected, never Good (a client would take it for known)
    mistyped = [v for v in variables if not (v["status"] == "Good" and v["variant"] == v["builtIn"]
                                             or v["status"] == "BadNotConnected" and v["variant"] == "Null")]
    assert mistyped == [], mistyped
    assert served.stop() == 0, served.output
    assert "Traceback" not in served.output
