"""The contract between the Python FMUs' binary (fmi/c/python_model.c) and the Python slave (fmi/adapter.py):
written once in fmi/contract.py; these tests fail when the generated C header, the shim or the adapter
disagree with it."""

from __future__ import annotations

import inspect
import re
from pathlib import Path

import pytest

from ncfmu.fmi import contract
from ncfmu.fmi.adapter import ControllerSlave
from ncfmu.fmi.builder import C_LAYER, CONTRACT_HEADER, PYTHON_MODEL, fmi_headers

SHIM = PYTHON_MODEL.read_text()


def test_the_checked_in_header_is_what_the_table_generates():
    assert CONTRACT_HEADER.read_bytes() == contract.c_header().encode(), \
        "regenerate: python -c 'from ncfmu.fmi import contract; print(contract.c_header(), end=\"\")' > " \
        f"{CONTRACT_HEADER.relative_to(C_LAYER.parents[3])}"


def test_every_entry_exists_on_the_python_side_with_the_arguments_the_table_names():
    slave = ControllerSlave
    for e in contract.ENTRIES:
        if e.kind in ("dict", "list"):
            init = inspect.getsource(slave.__init__)
            assert re.search(rf"self\.{e.name}\b.*=", init), f"{e.name}: not an attribute the slave sets up"
            continue
        member = inspect.getattr_static(slave, e.name)
        assert isinstance(member, classmethod) == (e.on == "class"), e.name
        params = list(inspect.signature(getattr(slave, e.name)).parameters)
        if e.on == "slave":
            params = params[1:]                                      # self
        assert tuple(params) == e.args, f"{e.name}: {params} != {e.args}"


def test_the_shim_names_nothing_on_the_python_side_outside_the_table():
    # every Python name comes from the header's NCFMU_CONTRACT_NAMES; the only string lookup is the model
    # script's class, compiled in as NCFMU_CLASS
    assert re.findall(r"GetAttrString\(([^)]*)\)", SHIM.split("static int py_load")[1]) == ["module, NCFMU_CLASS"]
    assert set(re.findall(r"py\.GetAttr\(\s*[^,]+,\s*([^)]*)\)", SHIM)) == {"names[N_INPUTS]",
                                                                       "names[N_PENDING_LOG]", "names[N_OUT]"}
    calls = (re.findall(r"CallMethod\([^,]+,\s*names\[N_(\w+)\]", SHIM)
             + re.findall(r"call(?:_status)?\(m, [^,]+, N_(\w+)", SHIM))
    methods = {e.macro for e in contract.ENTRIES if e.kind == "method"}
    assert set(calls) == methods, "every method of the table is called, and nothing else"
    assert "_ncfmu_fast" not in SHIM and "step_failed" not in SHIM and "log_queue" not in SHIM


def test_status_values_are_fmi2s_and_the_adapter_returns_them():
    header = (fmi_headers() / "fmi2FunctionTypes.h").read_text()
    for name, value in contract.STATUS.items():
        assert re.search(rf"fmi2{name.capitalize()}\s*(?:=\s*{value})?\s*[,}}]", header) or value == 0, name
    enum = re.search(r"typedef enum \{\s*fmi2OK,\s*fmi2Warning,\s*fmi2Discard,\s*fmi2Error,\s*fmi2Fatal", header)
    assert enum, "fmi2Status is OK, Warning, Discard, Error, Fatal = 0..4"
    assert list(contract.STATUS.values()) == [0, 1, 2, 3, 4]


def test_the_ports_table_speaks_the_contracts_codes(fmus):
    import sys
    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "models"))
    from CutSequencer import CutSequencer
    slave = CutSequencer.fmi_instantiate("t", "", False)
    ports = slave.fmi_ports()
    assert {p[1] for p in ports} <= set(contract.TYPE.values())
    assert {p[2] for p in ports} <= set(contract.CAUSALITY.values())
    by_name = {p[4]: p for p in ports}
    assert by_name["x_cmd"][2] == contract.CAUSALITY["OUTPUT"] and by_name["x_cmd"][1] == contract.TYPE["Real"]
    # a step returns its status; a refused parameter is ERROR returned by the call, with the reason logged
    slave.parameters["block[1].Xd"] = -0.5
    assert slave.fmi_exit_initialization_mode() == contract.STATUS["ERROR"]
    assert slave.fmi_do_step(0.0, 1e-3) == contract.STATUS["ERROR"]
    log = slave.fmi_take_log()
    assert [s for s, _, _ in log] == [contract.STATUS["ERROR"]] * 2 and "block[1].Xd = -0.5" in log[0][2]
    assert slave.fmi_take_log() == []


def test_a_serialized_state_is_the_slaves_bytes_and_its_time(fmus):
    """The shim appends the state's time (contract.STATE_TRAILER) so a state restored from bytes goes on from it;
    a state whose trailer is gone is refused naming why, and one with an edited time goes on from that time."""
    from ncfmu.cosim.fmu import FmuSlave, UnpackedFmu
    from ncfmu.errors import SimulationError

    unpacked = UnpackedFmu(fmus["CutSequencer"])
    slave = FmuSlave(unpacked, "dut")
    slave.initialize(0.0, 1e6)
    for k in range(7):
        slave.do_step(k * 1e-3, 1e-3)
    blob = slave.serialize_state(slave.get_state())
    data, phase, time = contract.split_state(blob)
    assert data.startswith(b'{"format":"ncfmu-fmu-state"') and phase == contract.PHASE["STEP"] and time == 6e-3 + 1e-3
    with pytest.raises(SimulationError, match="dut: fmi2DeSerializeFMUstate returned fmi2Error"):
        slave.deserialize_state(data)                                 # no seal: refused (our error, not fmpy's)
    slave.set_state(slave.deserialize_state(contract.join_state(data, 0.5, model="CutSequencer")))
    slave.do_step(0.5, 1e-3)                                          # goes on from the state's time
    slave.terminate()
    unpacked.cleanup()
