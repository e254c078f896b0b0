"""The FMI 3.0 layer (fmi/c/fmi3_functions.c) against a hostile host, as test_shim_misuse.py holds the FMI 2.0
layer: bad instantiations (name, instantiationToken, resource path, event mode, model exchange, scheduled
execution), NULL, freed, made-up and another FMU's instances in every exported function, the calls not offered
(event mode, clocks, model exchange, derivatives) on a live instance, wrong types and value references, values
outside a parameter's rule, non-UTF-8 Strings, calls in the wrong state, steps that leave the time line or round
to 0 ns, FMU states NULL/foreign/freed, serialized bytes that are not a state of this FMU. Each FMU's cases run
in one process of their own (tests/fmi/misuse3_host.py): a crash is a failure that names the case it died in."""

from __future__ import annotations

from pathlib import Path

import pytest
from fmpy import read_model_description
from misuse_report import exported_functions, run_host

from ncfmu.catalogue import models
from ncfmu.fmi.fmi3 import PLATFORM

HOST = Path(__file__).with_name("misuse3_host.py")
MODELS = sorted(models())
# Functions without an instance (nothing to misuse) and the one the host calls in its own cases.
NO_INSTANCE = {"fmi3GetVersion", "fmi3InstantiateCoSimulation", "fmi3InstantiateModelExchange",
               "fmi3InstantiateScheduledExecution", "fmi3FreeInstance"}
#: the cases every FMU runs; an FMU with a String parameter runs the four non-UTF-8/NULL String sets too
CASES, STRING_CASES = 508, 4


@pytest.fixture(scope="module")
def fmus3(project):
    return {p.stem: p for p in project["fmi3"]}


@pytest.mark.parametrize("model", MODELS)
def test_every_fmi3_misuse_is_refused_and_nothing_crashes(fmus3, model):
    foreign = "ServoAxis" if model == "AreaLimiter" else "AreaLimiter"     # its instance: the foreign handle
    n, held, covered = run_host(HOST, str(fmus3[model]), str(fmus3[foreign]))
    print(f"{model}: {n} FMI 3.0 misuse cases tried, {held} held")
    has_strings = any(v.type == "String" for v in read_model_description(str(fmus3[model])).modelVariables)
    assert n == held == CASES + (STRING_CASES if has_strings else 0)
    # the NULL/freed/made-up/foreign instance cases cover every function the binary exports
    assert covered == exported_functions(fmus3[model], PLATFORM, "fmi3") - NO_INSTANCE
