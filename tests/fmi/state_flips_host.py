"""Single-bit flips of one model's serialized FMU states, and its states carried across FMI versions, in this
process (tests/fmi/test_state_integrity.py runs it in a process of its own: a crash is a failure, not a lost run).

    python state_flips_host.py FMI2_FMU FMI3_FMU FLIPS SEED

For each FMI version: the instance runs 20 steps of 1 ms (inputs in mm ramp at 10 mm/s), its state is serialized,
and a reference is taken (that state restored, one step, the outputs). Then each of FLIPS seeded single-bit flips of
the bytes is deserialized and set: refused (Error), or accepted -- then one step from it, and its outputs compared
with the reference. At the end each version's state is deserialized into the other version's instance. Prints one
``RESULT <json>`` line and each good state as ``GOOD <FMI version> <hex>``; the FMUs' log goes to stdout as fmpy
prints it (``[ERROR] ...``).
"""

from __future__ import annotations

import json
import math
import random
import sys
import tempfile

from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave

DT = 1e-3
STEPS = 20
GETTERS = {"Real": "getReal", "Integer": "getInteger", "Float64": "getFloat64", "Int32": "getInt32",
           "Boolean": "getBoolean"}


class Host:
    """One started instance of an FMU, FMI 2.0 or 3.0, behind the same few calls."""

    def __init__(self, path: str, name: str) -> None:
        self.md = read_model_description(path)
        self.fmi3 = self.md.fmiVersion == "3.0"
        folder = extract(path, tempfile.mkdtemp())
        token = self.md.instantiationToken if self.fmi3 else self.md.guid
        cls = FMU3Slave if self.fmi3 else FMU2Slave
        self.fmu = cls(guid=token, unzipDirectory=folder, modelIdentifier=self.md.coSimulation.modelIdentifier,
                       instanceName=name)
        variables = [v for v in self.md.modelVariables if v.causality != "independent"]
        self.outputs = [v for v in variables if v.causality == "output" and v.type != "String"]
        self.ramped = [v for v in variables if v.causality == "input" and v.type in ("Real", "Float64")
                       and v.unit == "mm"]
        self.fmu.instantiate(loggingOn=True)
        if self.fmi3:
            self.fmu.enterInitializationMode(startTime=0.0)
        else:
            self.fmu.setupExperiment(startTime=0.0)
            self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()
        self.t = 0.0

    def step(self, t: float) -> None:
        self.fmu.doStep(t, DT)

    def run(self) -> None:
        for k in range(STEPS):
            if self.ramped:
                refs = [v.valueReference for v in self.ramped]
                (self.fmu.setFloat64 if self.fmi3 else self.fmu.setReal)(refs, [0.01 * k] * len(refs))
            self.step(self.t)
            self.t += DT

    def read(self) -> list[object]:
        return [getattr(self.fmu, GETTERS[v.type])([v.valueReference])[0] for v in self.outputs]

    def serialized(self) -> bytes:
        if self.fmi3:
            state = self.fmu.getFMUState()
            blob = bytes(self.fmu.serializeFMUState(state))
            self.fmu.freeFMUState(state)
        else:
            state = self.fmu.getFMUstate()
            blob = bytes(self.fmu.serializeFMUstate(state))
            self.fmu.freeFMUstate(state)
        return blob

    def restore(self, blob: bytes) -> None:
        """Deserialize and set ``blob``; FMICallException when refused."""
        if self.fmi3:
            state = self.fmu.deserializeFMUState(blob)
            try:
                self.fmu.setFMUState(state)
            finally:
                self.fmu.freeFMUState(state)
        else:
            state = self.fmu.deSerializeFMUstate(blob)
            try:
                self.fmu.setFMUstate(state)
            finally:
                self.fmu.freeFMUstate(state)

    def after_one_step(self, blob: bytes) -> list[object] | str:
        """The outputs one step after ``blob`` was restored (at the time the good state holds), or why not."""
        self.restore(blob)
        try:
            self.step(self.t)
        except FMICallException as err:
            return f"the step failed ({err})"
        return self.read()


def same(a: list[object], b: list[object]) -> bool:
    return all(x == y or (isinstance(x, float) and math.isnan(x) and math.isnan(y)) for x, y in zip(a, b))


def flips(host: Host, n: int, seed: int) -> dict[str, object]:
    good = host.serialized()
    print(f"GOOD {host.md.fmiVersion} {good.hex()}", flush=True)
    reference = host.after_one_step(good)
    rng = random.Random(seed)
    accepted, changed = 0, []
    for _ in range(n):
        at, bit = rng.randrange(len(good)), rng.randrange(8)
        blob = bytearray(good)
        blob[at] ^= 1 << bit
        try:
            after = host.after_one_step(bytes(blob))
        except FMICallException:
            continue                                    # refused: the instance kept its state
        accepted += 1
        if isinstance(after, str) or not same(after, reference):
            changed.append(f"byte {at} bit {bit}: {after}")
    assert host.after_one_step(good) == reference       # the instance is sound after it all
    print(f"FLIPPED {host.md.fmiVersion} accepted {accepted} of {n}", flush=True)
    return {"size": len(good), "flips": n, "accepted": accepted, "changed": changed[:10],
            "n_changed": len(changed)}


def main() -> None:
    paths, n, seed = sys.argv[1:3], int(sys.argv[3]), int(sys.argv[4])
    hosts = [Host(path, f"dut{k}") for k, path in enumerate(paths)]
    result: dict[str, object] = {}
    for host in hosts:
        host.run()
        result[host.md.fmiVersion] = flips(host, n, seed)
    for source, target in ((hosts[0], hosts[1]), (hosts[1], hosts[0])):
        print(f"CROSS {source.md.fmiVersion} -> {target.md.fmiVersion}", flush=True)
        try:
            target.restore(source.serialized())
            outcome = "OK"
        except FMICallException:
            outcome = "Error"
        print(f"CROSSED {outcome}", flush=True)
        result[f"{source.md.fmiVersion}->{target.md.fmiVersion}"] = outcome
    for host in hosts:
        host.fmu.terminate()
        host.fmu.freeInstance()
    print("RESULT", json.dumps(result), flush=True)


if __name__ == "__main__":
    main()
