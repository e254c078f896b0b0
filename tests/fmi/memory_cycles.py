"""Instantiate / step / get-set-serialize state / free cycles of one FMU in this process; prints the RSS.

    python memory_cycles.py <fmu> <warm-up cycles> <cycles>

Run by test_memory_cycles.py in a fresh process. Prints ``RSS <after warm-up> <after the cycles>`` in KiB.
"""

from __future__ import annotations

import gc
import sys
import tempfile

import fmpy.fmi2 as fmi2
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave


def rss_kib() -> int:
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith("VmRSS:"))


fmu_path, warm, cycles = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
md = read_model_description(fmu_path)
folder = extract(fmu_path, tempfile.mkdtemp())
fmu = FMU2Slave(guid=md.guid, unzipDirectory=folder, modelIdentifier=md.coSimulation.modelIdentifier,
                instanceName="cycle")
inputs = [v.valueReference for v in md.modelVariables if v.causality == "input" and v.type == "Real"]
outputs = [v.valueReference for v in md.modelVariables if v.causality == "output" and v.type == "Real"]


silent = fmi2.fmi2CallbackFunctions()           # the controllers' alarms (inputs held at 0) are not printed
silent.logger = fmi2.fmi2CallbackLoggerTYPE(lambda *args: None)
silent.allocateMemory = fmi2.defaultCallbacks.allocateMemory
silent.freeMemory = fmi2.defaultCallbacks.freeMemory


def cycle() -> None:
    fmu.instantiate(callbacks=silent)
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    t = 0.0
    for _ in range(10):
        fmu.setReal(inputs, [0.0] * len(inputs))
        fmu.doStep(t, 1e-3)
        fmu.getReal(outputs)
        t += 1e-3
    state = fmu.getFMUstate()
    blob = fmu.serializeFMUstate(state)
    fmu.freeFMUstate(state)
    state = fmu.deSerializeFMUstate(blob)
    fmu.setFMUstate(state)
    fmu.freeFMUstate(state)
    fmu.doStep(t, 1e-3)
    fmu.terminate()
    fmu.fmi2FreeInstance(fmu.component)           # the library stays loaded, as a host that re-instantiates keeps it


for _ in range(warm):
    cycle()
gc.collect()
before = rss_kib()
for _ in range(cycles):
    cycle()
gc.collect()
print("RSS", before, rss_kib(), flush=True)
