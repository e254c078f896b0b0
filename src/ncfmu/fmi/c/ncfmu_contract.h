/* Generated from src/ncfmu/fmi/contract.py by ncfmu.fmi.contract.c_header(): do not edit.
 * The contract between this shim and the Python slave (fmi/adapter.py); see docs/architecture.md. */
#ifndef NCFMU_CONTRACT_H
#define NCFMU_CONTRACT_H

/* class.fmi_instantiate(instance_name, resources, visible) [method] -> a new slave; an exception means the instantiation failed (its text is logged) */
#define NCFMU_INSTANTIATE "fmi_instantiate"
/* slave.fmi_ports() [method] -> tuple of (vr, TYPE_*, CAUSALITY_*, fixed, name) per variable; called once per slave */
#define NCFMU_PORTS "fmi_ports"
/* slave.fmi_setup_experiment(start_time, stop_time, tolerance) [method] -> status; stop_time and tolerance are None when undefined */
#define NCFMU_SETUP_EXPERIMENT "fmi_setup_experiment"
/* slave.fmi_enter_initialization_mode() [method] -> status */
#define NCFMU_ENTER_INITIALIZATION "fmi_enter_initialization_mode"
/* slave.fmi_exit_initialization_mode() [method] -> status: ERROR when the parameters are refused (the instance lives on: fmi2Reset) */
#define NCFMU_EXIT_INITIALIZATION "fmi_exit_initialization_mode"
/* slave.fmi_do_step(current_time, step_size) [method] -> status: OK, DISCARD, or ERROR (the step failed; the reason is in the log) */
#define NCFMU_DO_STEP "fmi_do_step"
/* slave.fmi_stepper() [method] -> the controller's step_then_count_messages(current_time, step_size, inputs) -> the number of messages it queued (an int), or None while there is no controller: the shim's DoStep calls it with the slave's inputs dict and a step of whole nanoseconds, no Python frame between (fmi_do_step when None); taken anew after any other call into the slave (it may rebind its controller) */
#define NCFMU_STEPPER "fmi_stepper"
/* slave.fmi_step_report(current_time, error) [method] -> status: after a stepper call that raised (error: the exception, its traceback set; ERROR) or queued messages (error None; OK): logs them as fmi_do_step does */
#define NCFMU_STEP_REPORT "fmi_step_report"
/* slave.fmi_terminate() [method] -> status */
#define NCFMU_TERMINATE "fmi_terminate"
/* slave.fmi_get(vrs) [method] -> list of values, one per vr (the shim checked each vr's type before) */
#define NCFMU_GET "fmi_get"
/* slave.fmi_set(vrs, values) [method] -> status: ERROR when a value is refused (the old value stays) */
#define NCFMU_SET "fmi_set"
/* slave.fmi_get_state() [method] -> an opaque state object the shim holds */
#define NCFMU_GET_STATE "fmi_get_state"
/* slave.fmi_set_state(state, call) [method] -> status: ERROR when refused (the instance keeps its state; the refusal names ``call``, the host's call) */
#define NCFMU_SET_STATE "fmi_set_state"
/* slave.fmi_serialize(state) [method] -> bytes */
#define NCFMU_SERIALIZE "fmi_serialize"
/* slave.fmi_deserialize(data, call) [method] -> a state object, or None when the bytes are refused (the reason is in the log, naming ``call``) */
#define NCFMU_DESERIALIZE "fmi_deserialize"
/* slave.fmi_take_log() [method] -> list of (status, category, text) logged since the last call; the queue is emptied */
#define NCFMU_TAKE_LOG "fmi_take_log"
/* slave.pending_log [list] -> what is logged and not yet taken (the same list for the slave's life): the shim calls fmi_take_log only when it is not empty */
#define NCFMU_PENDING_LOG "pending_log"
/* slave.out [dict] -> outputs by name: the shim copies the Real/Integer/Boolean ones after fmi_do_step (and at a Get after any other call: the adapter may rebind it), and its fast fmi2Get* read the copy without Python */
#define NCFMU_OUT "out"
/* slave.inputs [dict] -> inputs by name (the same dict for the slave's life): the shim's fast fmi2Set* keep the values in C and write them into this dict before its next call into the slave, which reads them only then */
#define NCFMU_INPUTS "inputs"

/* Every name above, for the shim's table of interned names: X(MACRO_SUFFIX). */
#define NCFMU_CONTRACT_NAMES(X) X(INSTANTIATE) X(PORTS) X(SETUP_EXPERIMENT) X(ENTER_INITIALIZATION) X(EXIT_INITIALIZATION) X(DO_STEP) X(STEPPER) X(STEP_REPORT) X(TERMINATE) X(GET) X(SET) X(GET_STATE) X(SET_STATE) X(SERIALIZE) X(DESERIALIZE) X(TAKE_LOG) X(PENDING_LOG) X(OUT) X(INPUTS)

#define NCFMU_STATE_TRAILER "ncfmu-t2"  /* then the phase, an int32, and the time, a double */
#define NCFMU_STATE_TRAILER_SIZE 20

#define NCFMU_STATUS_OK 0
#define NCFMU_STATUS_WARNING 1
#define NCFMU_STATUS_DISCARD 2
#define NCFMU_STATUS_ERROR 3
#define NCFMU_STATUS_FATAL 4

#define NCFMU_TYPE_REAL 1
#define NCFMU_TYPE_INTEGER 2
#define NCFMU_TYPE_BOOLEAN 3
#define NCFMU_TYPE_STRING 4

#define NCFMU_CAUSALITY_OTHER 0
#define NCFMU_CAUSALITY_INPUT 1
#define NCFMU_CAUSALITY_OUTPUT 2
#define NCFMU_CAUSALITY_PARAMETER 3

#define NCFMU_PHASE_INSTANTIATED 1
#define NCFMU_PHASE_INIT 2
#define NCFMU_PHASE_STEP 4
#define NCFMU_PHASE_TERMINATED 8

#endif
