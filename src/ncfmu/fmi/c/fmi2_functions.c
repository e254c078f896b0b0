/*
 * ncfmu: the FMI 2.0 co-simulation layer of every ncfmu FMU, written once over the model interface
 * (model.h), as the Reference-FMUs' fmi2Functions.c is over their model.c.
 *
 * Behind it stands a native model (native_model.c with the model's equations: the ServoAxis) or the Python
 * runtime (python_model.c: the controller FMUs). This file holds FMI 2.0's functions; what it keeps and checks
 * (fmu_instance.h, shared with the FMI 3.0 layer) is: instances behind opaque
 * handles (fmi2_machine.h: a NULL, freed, made-up or foreign instance or FMU-state handle is refused with
 * fmi2Error, never dereferenced; a second fmi2FreeInstance does nothing), the state machine, value
 * references checked against the model's table (unknown, wrong type, an output, a fixed parameter after
 * initialisation, a value outside the port's rule, a String that is not UTF-8 text: fmi2Error naming the
 * variable, the value and the rule), step times and sizes, and the FMU states the host holds. No call
 * reaches fmi2Fatal on bad input. Errors and warnings reach the host's logger whatever the debug-logging
 * setting; the rest only with debug logging on, in the categories the host chose.
 */
#define _GNU_SOURCE                     /* dladdr: the binary holds itself loaded while its instances live */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "fmi2_machine.h"
#include "model.h"
#define FMU_FMI_MAJOR 2                 /* the FMI version its serialized states are sealed with */
#include "fmu_instance.h"

_Static_assert((int)fmi2OK == ModelOK && (int)fmi2Warning == ModelWarning && (int)fmi2Discard == ModelDiscard
               && (int)fmi2Error == ModelError && (int)fmi2Fatal == ModelFatal,
               "FMI 2.0's statuses are the model interface's numbers (fmu_instance.h returns them)");
_Static_assert(sizeof(fmi2Integer) == sizeof(int) && sizeof(fmi2Boolean) == sizeof(int)
               && sizeof(fmi2ValueReference) == sizeof(unsigned), "the model interface's types are FMI 2.0's");

static const char *const TYPE_NAMES[4] = {"Real", "Integer", "Boolean", "String"};

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

/* ---- instances ----------------------------------------------------------------------------------- */
fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String resources,
                              const fmi2CallbackFunctions *cb, fmi2Boolean visible, fmi2Boolean logging)
{
    char dir[4096];
    if (!fmi2_instantiate_ok(cb, name, type, guid, FMU_MODEL_GUID, FMU_MODEL_IDENTIFIER, resources, dir,
                             sizeof dir))
        return NULL;
    FmuInstance *i = calloc(1, sizeof *i);
    if (!i) return NULL;
    snprintf(i->name, sizeof i->name, "%s", name);
    i->log = (Fmi2Log){.logger = cb ? cb->logger : NULL, .env = cb ? cb->componentEnvironment : NULL, .name = i->name};
    i->log.debug = logging != fmi2False;
    return fmu_instance_start(i, "fmi2Instantiate", dir, visible != fmi2False);
}

void fmi2FreeInstance(fmi2Component c)
{
    void *self = fmu_instance_free(c);
    if (self) dlclose(self);            /* the last thing done (a tail call): it may unmap this library */
}

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String categories[])
{
    return fmu_set_debug_logging(c, "fmi2SetDebugLogging", on != fmi2False, n, categories);
}

/* ---- the state machine --------------------------------------------------------------------------- */
fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tol_defined, fmi2Real tol, fmi2Real start,
                               fmi2Boolean stop_defined, fmi2Real stop)
{
    FmuInstance *i = fmu_checked(c, "fmi2SetupExperiment", P_SETUP);
    return (fmi2Status)fmu_setup_experiment(i, "fmi2SetupExperiment", tol_defined != fmi2False, tol, start,
                                            stop_defined != fmi2False, stop);
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    return (fmi2Status)fmu_transition(c, "fmi2EnterInitializationMode", P_SETUP, P_INIT,
                                      fmu_model_enter_initialization);
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    return (fmi2Status)fmu_transition(c, "fmi2ExitInitializationMode", P_INIT, P_STEP, fmu_model_exit_initialization);
}

fmi2Status fmi2Terminate(fmi2Component c)
{
    return (fmi2Status)fmu_transition(c, "fmi2Terminate", P_STEP, P_TERMINATED, fmu_model_terminate);
}

fmi2Status fmi2Reset(fmi2Component c) { return (fmi2Status)fmu_reset(c, "fmi2Reset"); }

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean no_set_prior_state)
{
    (void)no_set_prior_state;
    FmuInstance *i;
    return (fmi2Status)fmu_do_step(c, "fmi2DoStep", t, h, &i);
}

fmi2Status fmi2CancelStep(fmi2Component c)
{
    FmuInstance *i = fmu_checked(c, "fmi2CancelStep", P_STEP);
    if (!i) return fmi2Error;
    FMI2_SAY(&i->log, fmi2Error, "logStatusError", "fmi2CancelStep: no step is pending (this FMU steps "
             "synchronously)");
    return fmi2Error;
}

/* ---- variables ----------------------------------------------------------------------------------- */
#define GETTER(name, ctype, type) \
    fmi2Status name(fmi2Component c, const fmi2ValueReference vr[], size_t n, ctype v[]) \
    { return (fmi2Status)fmu_get_values(c, #name, vr, n, v, type, sizeof(fmi2Boolean), TYPE_NAMES); }
#define SETTER(name, ctype, type) \
    fmi2Status name(fmi2Component c, const fmi2ValueReference vr[], size_t n, const ctype v[]) \
    { return (fmi2Status)fmu_set_values(c, #name, vr, n, v, type, sizeof(fmi2Boolean), TYPE_NAMES); }
GETTER(fmi2GetReal, fmi2Real, V_REAL)
GETTER(fmi2GetInteger, fmi2Integer, V_INTEGER)
GETTER(fmi2GetBoolean, fmi2Boolean, V_BOOLEAN)
GETTER(fmi2GetString, fmi2String, V_STRING)
SETTER(fmi2SetReal, fmi2Real, V_REAL)
SETTER(fmi2SetInteger, fmi2Integer, V_INTEGER)
SETTER(fmi2SetBoolean, fmi2Boolean, V_BOOLEAN)
SETTER(fmi2SetString, fmi2String, V_STRING)

/* ---- FMU states (fmu_instance.h) ---------------------------------------------------------------- */
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s)
{
    return (fmi2Status)fmu_get_state(c, "fmi2GetFMUstate", s);
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s)
{
    return (fmi2Status)fmu_set_state(c, "fmi2SetFMUstate", s);
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s)
{
    return (fmi2Status)fmu_free_state(c, "fmi2FreeFMUstate", s);
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *size)
{
    return (fmi2Status)fmu_state_size(c, "fmi2SerializedFMUstateSize", s, size);
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t size)
{
    return (fmi2Status)fmu_serialize(c, "fmi2SerializeFMUstate", s, (unsigned char *)b, size);
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t size, fmi2FMUstate *s)
{
    return (fmi2Status)fmu_deserialize(c, "fmi2DeSerializeFMUstate", (const unsigned char *)b, size, s);
}

/* ---- what this FMU does not offer: refused with a reason, never Fatal ----------------------------- */
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                        const fmi2ValueReference z[], size_t nz, const fmi2Real dv[], fmi2Real dz[])
{
    (void)u; (void)nu; (void)z; (void)nz; (void)dv; (void)dz;
    return (fmi2Status)fmu_not_provided(c, "fmi2GetDirectionalDerivative", "not provided (providesDirectionalDerivative is false)");
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                       const fmi2Integer order[], const fmi2Real v[])
{
    (void)vr; (void)n; (void)order; (void)v;
    return (fmi2Status)fmu_not_provided(c, "fmi2SetRealInputDerivatives", "not provided (canInterpolateInputs is false)");
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                        const fmi2Integer order[], fmi2Real v[])
{
    (void)vr; (void)n; (void)order; (void)v;
    return (fmi2Status)fmu_not_provided(c, "fmi2GetRealOutputDerivatives", "not provided (maxOutputDerivativeOrder is 0)");
}

/* Status queries: steps are synchronous, so only fmi2LastSuccessfulTime and fmi2Terminated mean something. */
static fmi2Status no_status(FmuInstance *i, const char *call)
{
    FMI2_SAY(&i->log, fmi2Discard, "logStatusDiscard", "%s: nothing to report (no asynchronous steps)", call);
    return fmi2Discard;
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind k, fmi2Real *v)
{
    FmuInstance *i = fmu_checked(c, "fmi2GetRealStatus", P_ANY);
    if (!i || !v) return fmi2Error;
    if (k == fmi2LastSuccessfulTime) { *v = i->next_time; return fmi2OK; }
    return no_status(i, "fmi2GetRealStatus");
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind k, fmi2Boolean *v)
{
    FmuInstance *i = fmu_checked(c, "fmi2GetBooleanStatus", P_ANY);
    if (!i || !v) return fmi2Error;
    if (k == fmi2Terminated) { *v = fmi2False; return fmi2OK; }    /* the FMU never asks to end the run */
    return no_status(i, "fmi2GetBooleanStatus");
}

#define NO_STATUS(name, ctype)                                                      \
    fmi2Status name(fmi2Component c, const fmi2StatusKind k, ctype *v)              \
    {                                                                               \
        (void)k;                                                                    \
        FmuInstance *i = fmu_checked(c, #name, P_ANY);                                     \
        if (!i || !v) return fmi2Error;                                             \
        return no_status(i, #name);                                                 \
    }
NO_STATUS(fmi2GetStatus, fmi2Status)
NO_STATUS(fmi2GetIntegerStatus, fmi2Integer)
NO_STATUS(fmi2GetStringStatus, fmi2String)
