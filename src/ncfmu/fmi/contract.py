"""The contract between a Python FMU's C binary (``fmi/c/python_model.c``) and its Python slave (``fmi/adapter.py``).

Written once, here. The C side reads it from ``fmi/c/ncfmu_contract.h``, generated from this table by
:func:`c_header` (checked in; ``tests/fmi/test_contract.py`` fails when the header, the table or the
adapter disagree). ``docs/architecture.md`` describes the protocol around it.

The shim names nothing on the Python side but what this table lists: every call it makes (the
adapter's method, its arguments, what it returns) and the two dicts it reads and writes directly
for speed. Every ``fmi_*`` call returns its status as an int (:data:`STATUS`); none raises (the
adapter catches and logs), and the shim turns an exception that escapes anyway into fmi2Error with
the exception's text. Log messages are handed over by :data:`TAKE_LOG` after every call that logged
something (the shim reads the length of ``pending_log``, a C call, and calls into Python only when it is not
zero); the shim sends errors and warnings to the host's logger always, the rest only with debug logging on.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Entry:
    """One name the shim uses on the Python side."""

    macro: str                  # the C macro's suffix: NCFMU_<macro> is the Python name as a string
    name: str                   # the Python name
    on: str                     # "class" (the slave class) or "slave" (an instance)
    kind: str                   # "method", "dict" (an attribute the shim reads or writes item by item) or "list"
                                #   (an attribute whose length the shim reads)
    args: tuple[str, ...]       # the method's parameters (names as in the adapter), in order
    returns: str                # the return convention


#: Every entry point the shim calls, and every attribute it touches.
ENTRIES: tuple[Entry, ...] = (
    Entry("INSTANTIATE", "fmi_instantiate", "class", "method", ("instance_name", "resources", "visible"),
          "a new slave; an exception means the instantiation failed (its text is logged)"),
    Entry("PORTS", "fmi_ports", "slave", "method", (),
          "tuple of (vr, TYPE_*, CAUSALITY_*, fixed, name) per variable; called once per slave"),
    Entry("SETUP_EXPERIMENT", "fmi_setup_experiment", "slave", "method", ("start_time", "stop_time", "tolerance"),
          "status; stop_time and tolerance are None when undefined"),
    Entry("ENTER_INITIALIZATION", "fmi_enter_initialization_mode", "slave", "method", (), "status"),
    Entry("EXIT_INITIALIZATION", "fmi_exit_initialization_mode", "slave", "method", (),
          "status: ERROR when the parameters are refused (the instance lives on: fmi2Reset)"),
    Entry("DO_STEP", "fmi_do_step", "slave", "method", ("current_time", "step_size"),
          "status: OK, DISCARD, or ERROR (the step failed; the reason is in the log)"),
    Entry("STEPPER", "fmi_stepper", "slave", "method", (),
          "the controller's step_then_count_messages(current_time, step_size, inputs) -> the number of messages it "
          "queued (an int), or None while there is no controller: the shim's DoStep calls it with the slave's "
          "inputs dict and a step of whole nanoseconds, no Python frame between (fmi_do_step when None); "
          "taken anew after any other call into the slave (it may rebind its controller)"),
    Entry("STEP_REPORT", "fmi_step_report", "slave", "method", ("current_time", "error"),
          "status: after a stepper call that raised (error: the exception, its traceback set; ERROR) or queued "
          "messages (error None; OK): logs them as fmi_do_step does"),
    Entry("TERMINATE", "fmi_terminate", "slave", "method", (), "status"),
    Entry("GET", "fmi_get", "slave", "method", ("vrs",),
          "list of values, one per vr (the shim checked each vr's type before)"),
    Entry("SET", "fmi_set", "slave", "method", ("vrs", "values"),
          "status: ERROR when a value is refused (the old value stays)"),
    Entry("GET_STATE", "fmi_get_state", "slave", "method", (), "an opaque state object the shim holds"),
    Entry("SET_STATE", "fmi_set_state", "slave", "method", ("state", "call"),
          "status: ERROR when refused (the instance keeps its state; the refusal names ``call``, the host's call)"),
    Entry("SERIALIZE", "fmi_serialize", "slave", "method", ("state",), "bytes"),
    Entry("DESERIALIZE", "fmi_deserialize", "slave", "method", ("data", "call"),
          "a state object, or None when the bytes are refused (the reason is in the log, naming ``call``)"),
    Entry("TAKE_LOG", "fmi_take_log", "slave", "method", (),
          "list of (status, category, text) logged since the last call; the queue is emptied"),
    Entry("PENDING_LOG", "pending_log", "slave", "list", (),
          "what is logged and not yet taken (the same list for the slave's life): the shim calls fmi_take_log "
          "only when it is not empty"),
    Entry("OUT", "out", "slave", "dict", (),
          "outputs by name: the shim copies the Real/Integer/Boolean ones after fmi_do_step (and at a Get after any "
          "other call: the adapter may rebind it), and its fast fmi2Get* read the copy without Python"),
    Entry("INPUTS", "inputs", "slave", "dict", (),
          "inputs by name (the same dict for the slave's life): the shim's fast fmi2Set* keep the values in C and "
          "write them into this dict before its next call into the slave, which reads them only then"),
)

#: fmi2Status as the ``fmi_*`` calls return it.
STATUS = {"OK": 0, "WARNING": 1, "DISCARD": 2, "ERROR": 3, "FATAL": 4}
#: A variable's type in :data:`ENTRIES` PORTS.
TYPE = {"Real": 1, "Integer": 2, "Boolean": 3, "String": 4}
#: A variable's causality in PORTS (anything else -- local, independent -- is OTHER).
CAUSALITY = {"OTHER": 0, "INPUT": 1, "OUTPUT": 2, "PARAMETER": 3}

#: What the shim appends to the slave's serialized state: these 8 bytes, the state's phase (a native int32, one of
#: :data:`PHASE`) and its time (a native double), so that a state restored from bytes is in the phase it was taken
#: in and continues from its own time. The slave never sees them.
STATE_TRAILER = b"ncfmu-t2"
STATE_TRAILER_SIZE = len(STATE_TRAILER) + 4 + 8
#: The FMI layer's phases (fmi2_machine.h's P_*; python_model.c asserts they are the same).
PHASE = {"INSTANTIATED": 1, "INIT": 2, "STEP": 4, "TERMINATED": 8}

HEADER_NAME = "ncfmu_contract.h"


def split_state(serialized: bytes) -> tuple[bytes, int, float]:
    """An FMU's serialized state -> (the slave's bytes, the state's phase, its time); ValueError when its seal
    (:mod:`ncfmu.fmi.sealed_state`) does not hold or the trailer is missing."""
    import struct

    from .sealed_state import unseal
    inner = unseal(serialized).payload
    data, trailer = inner[:-STATE_TRAILER_SIZE], inner[-STATE_TRAILER_SIZE:]
    if len(inner) < STATE_TRAILER_SIZE or not trailer.startswith(STATE_TRAILER):
        raise ValueError("not a state serialized by an ncfmu Python FMU (no trailer)")
    phase, time = struct.unpack("=id", trailer[len(STATE_TRAILER):])
    return data, phase, time


def join_state(data: bytes, time: float, phase: int = PHASE["STEP"], *, model: str, fmi: int = 2) -> bytes:
    """The inverse of :func:`split_state`, sealed as the FMI ``fmi`` build of ``model`` seals it (for tests that
    edit a state's bytes)."""
    import struct

    from .sealed_state import seal
    return seal(bytes(data) + STATE_TRAILER + struct.pack("=id", phase, time), model, fmi)


def entry(macro: str) -> Entry:
    return next(e for e in ENTRIES if e.macro == macro)


def c_header() -> str:
    """The C header the shim includes: the table above as macros (generated; do not edit the header)."""
    lines = ["/* Generated from src/ncfmu/fmi/contract.py by ncfmu.fmi.contract.c_header(): do not edit.",
             " * The contract between this shim and the Python slave (fmi/adapter.py); see docs/architecture.md. */",
             "#ifndef NCFMU_CONTRACT_H", "#define NCFMU_CONTRACT_H", ""]
    for e in ENTRIES:
        signature = f"({', '.join(e.args)})" if e.kind == "method" else ""
        lines.append(f"/* {e.on}.{e.name}{signature} [{e.kind}] -> {e.returns} */")
        lines.append(f'#define NCFMU_{e.macro} "{e.name}"')
    lines.append("")
    lines.append("/* Every name above, for the shim's table of interned names: X(MACRO_SUFFIX). */")
    lines.append("#define NCFMU_CONTRACT_NAMES(X) " + " ".join(f"X({e.macro})" for e in ENTRIES))
    lines.append("")
    lines.append(f'#define NCFMU_STATE_TRAILER "{STATE_TRAILER.decode()}"  /* then the phase, an int32, and the time, '
                 'a double */')
    lines.append(f"#define NCFMU_STATE_TRAILER_SIZE {STATE_TRAILER_SIZE}")
    lines.append("")
    for group, table in (("STATUS", STATUS), ("TYPE", TYPE), ("CAUSALITY", CAUSALITY), ("PHASE", PHASE)):
        for name, value in table.items():
            lines.append(f"#define NCFMU_{group}_{name.upper()} {value}")
        lines.append("")
    lines.append("#endif")
    return "\n".join(lines) + "\n"
