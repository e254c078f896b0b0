/*
 * ncfmu: the FMI 2.0 co-simulation layer of every ncfmu FMU, written once over the model interface
 * (fmi2_model.h), as the Reference-FMUs' fmi2Functions.c is over their model.c.
 *
 * Behind it stands a native model (native_model.c with the model's equations: the ServoAxis) or the Python
 * runtime (python_model.c: the controller FMUs). This file holds everything FMI: instances behind opaque
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
#include "fmi2_model.h"

/* ---- instances ----------------------------------------------------------------------------------- */
typedef struct {
    uintptr_t handle;
    void *model;                        /* the model's state */
    int phase;                          /* the instance's phase when it was taken; -1: unknown (kept at restore) */
    double time;                        /* where steps go on from it */
} State;

typedef struct {
    int phase;
    double next_time;                   /* where the next step starts: start time, last step's end, restored */
    char name[128];
    Fmi2Log log;                        /* the host's logger; log.name points to name */
    Model *model;                       /* NULL after a failed fmi2Reset: the instance can only be freed */
    State *states;                      /* the FMU states this instance handed out and not freed */
    size_t n_states, cap_states;
} Instance;

/* The instance behind ``c`` when ``call`` is allowed in its phase; else NULL (the call returns fmi2Error). A
 * NULL, freed, made-up or foreign handle has no logger to tell. */
static Instance *checked(fmi2Component c, const char *call, int phases)
{
    Instance *i = fmi2_instance_find(c, 0);
    if (!i || !fmi2_allowed(&i->log, i->phase, call, phases)) return NULL;
    if (!i->model) {
        FMI2_SAY(&i->log, fmi2Error, "logStatusError", "%s: the instance has no model (its reset failed): free it",
                 call);
        return NULL;
    }
    return i;
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String resources,
                              const fmi2CallbackFunctions *cb, fmi2Boolean visible, fmi2Boolean logging)
{
    char dir[4096];
    if (!fmi2_instantiate_ok(cb, name, type, guid, FMU_MODEL_GUID, FMU_MODEL_IDENTIFIER, resources, dir,
                             sizeof dir))
        return NULL;
    Instance *i = calloc(1, sizeof *i);
    if (!i) return NULL;
    snprintf(i->name, sizeof i->name, "%s", name);
    i->log = (Fmi2Log){.logger = cb ? cb->logger : NULL, .env = cb ? cb->componentEnvironment : NULL, .name = i->name};
    i->log.debug = logging != fmi2False;
    i->phase = P_INSTANTIATED;
    i->model = fmu_model_new(i->name, dir, visible != fmi2False, &i->log);
    fmi2Component handle = i->model ? fmi2_instance_add(i) : NULL;
    if (i->model && !handle) {
        FMI2_SAY(&i->log, fmi2Error, "logStatusError", "fmi2Instantiate: no new instance handle can be made");
        fmu_model_free(i->model);
    }
    if (!handle) free(i);
    return handle;
}

static void states_drop(Instance *i)
{
    for (size_t k = 0; k < i->n_states; k++) fmu_model_state_free(i->model, i->states[k].model);
    free(i->states);
    i->states = NULL;
    i->n_states = i->cap_states = 0;
}

void fmi2FreeInstance(fmi2Component c)
{
    Instance *i = fmi2_instance_find(c, 1);
    if (!i) return;                     /* NULL, freed already, or not ours: nothing to do */
    if (i->model) {
        states_drop(i);
        fmu_model_free(i->model);
    }
    free(i);
    void *self = fmi2_library_release();
    if (self) dlclose(self);            /* the last thing done (a tail call): it may unmap this library */
}

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String categories[])
{
    Instance *i = checked(c, "fmi2SetDebugLogging", P_ANY);
    if (!i) return fmi2Error;
    unsigned mask;
    if (!fmi2_categories_ok(&i->log, "fmi2SetDebugLogging", n, categories, &mask)) return fmi2Error;
    i->log.debug = on != fmi2False;
    i->log.categories = mask;
    return fmi2OK;
}

/* ---- the state machine --------------------------------------------------------------------------- */
fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tol_defined, fmi2Real tol, fmi2Real start,
                               fmi2Boolean stop_defined, fmi2Real stop)
{
    Instance *i = checked(c, "fmi2SetupExperiment", P_SETUP);
    if (!i || !fmi2_experiment_ok(&i->log, "fmi2SetupExperiment", start, stop_defined, stop)) return fmi2Error;
    fmi2Status st = fmu_model_setup_experiment(i->model, tol_defined != fmi2False, tol, start,
                                               stop_defined != fmi2False, stop);
    if (st <= fmi2Warning) i->next_time = start;
    return st;
}

static fmi2Status transition(fmi2Component c, const char *call, int from, int to, fmi2Status (*how)(Model *))
{
    Instance *i = checked(c, call, from);
    if (!i) return fmi2Error;
    fmi2Status st = how(i->model);
    if (st <= fmi2Warning) i->phase = to;
    return st;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    return transition(c, "fmi2EnterInitializationMode", P_SETUP, P_INIT, fmu_model_enter_initialization);
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    return transition(c, "fmi2ExitInitializationMode", P_INIT, P_STEP, fmu_model_exit_initialization);
}

fmi2Status fmi2Terminate(fmi2Component c)
{
    return transition(c, "fmi2Terminate", P_STEP, P_TERMINATED, fmu_model_terminate);
}

fmi2Status fmi2Reset(fmi2Component c)
{
    Instance *i = checked(c, "fmi2Reset", P_ANY);
    if (!i) return fmi2Error;
    if (fmu_model_reset(i->model) != 0) {
        states_drop(i);                 /* logged; the instance can only be freed (every call refuses) */
        fmu_model_free(i->model);
        i->model = NULL;
        return fmi2Error;
    }
    i->phase = P_INSTANTIATED;
    i->next_time = 0.0;
    return fmi2OK;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean no_set_prior_state)
{
    (void)no_set_prior_state;
    Instance *i = checked(c, "fmi2DoStep", P_STEP);
    if (!i || !fmi2_step_ok(&i->log, "fmi2DoStep", t, h) || !fmi2_step_ns_ok(&i->log, "fmi2DoStep", h)
        || !fmi2_continues_ok(&i->log, "fmi2DoStep", i->next_time, t)) return fmi2Error;
    fmi2Status st = fmu_model_do_step(i->model, t, h);
    if (st <= fmi2Warning) i->next_time = t + h;   /* the host's own arithmetic: its next step starts there */
    return st;
}

fmi2Status fmi2CancelStep(fmi2Component c)
{
    Instance *i = checked(c, "fmi2CancelStep", P_STEP);
    if (!i) return fmi2Error;
    FMI2_SAY(&i->log, fmi2Error, "logStatusError", "fmi2CancelStep: no step is pending (this FMU steps "
             "synchronously)");
    return fmi2Error;
}

/* ---- variables ----------------------------------------------------------------------------------- */
static const char *type_name(VarType t)
{
    return t == V_REAL ? "Real" : t == V_INTEGER ? "Integer" : t == V_BOOLEAN ? "Boolean" : "String";
}

/* 1 when every reference is a variable of ``type`` (and, for a set, settable now, its value within the rule);
 * else logs the first offender and returns 0. */
static int refs_ok(Instance *i, const char *call, const fmi2ValueReference vr[], size_t n, VarType type, int set,
                   const void *values)
{
    if (n > 0 && (!vr || !values)) {
        FMI2_SAY(&i->log, fmi2Error, "logStatusError", "%s: %zu values asked, but the %s array is NULL", call, n,
                 !vr ? "value reference" : "value");
        return 0;
    }
    unsigned count;
    const VarInfo *vars = fmu_model_variables(i->model, &count);
    for (size_t k = 0; k < n; k++) {
        const char *why = NULL;
        unsigned r = vr[k];
        const VarInfo *v = r < count && vars[r].name ? &vars[r] : NULL;
        if (!v) why = "is not a variable of this FMU";
        else if (v->type != type) why = "is not of this call's type";
        else if (set && v->causality == V_OUTPUT) why = "is an output: it cannot be set";
        else if (set && v->causality == V_PARAMETER && !v->tunable && i->phase == P_STEP)
            why = "is a fixed parameter: it cannot be set after initialisation";
        if (why) {
            FMI2_SAY(&i->log, fmi2Error, "logStatusError", "%s: value reference %u%s%s%s %s (a %s call)", call, r,
                     v ? " (" : "", v ? v->name : "", v ? ")" : "", why, type_name(type));
            return 0;
        }
    }
    for (size_t k = 0; set && k < n; k++) {         /* sets are all-or-nothing: every value checked first */
        const VarInfo *v = &vars[vr[k]];
        if (type == V_STRING) {
            fmi2String s = ((const fmi2String *)values)[k];
            if (!s || !fmi2_utf8_ok((const unsigned char *)s)) {
                FMI2_SAY(&i->log, fmi2Error, "logStatusError", "%s: value reference %u (%s): %s", call, vr[k],
                         v->name, s ? "not valid UTF-8 text" : "a NULL string");
                return 0;
            }
        } else if (type == V_REAL ? !fmi2_value_ok(&i->log, v, ((const fmi2Real *)values)[k])
                   : type == V_INTEGER ? !fmi2_value_ok(&i->log, v, (double)((const fmi2Integer *)values)[k]) : 0) {
            return 0;
        }
    }
    return 1;
}

static fmi2Status get_values(fmi2Component c, const char *call, const fmi2ValueReference vr[], size_t n,
                             void *values, VarType type)
{
    Instance *i = checked(c, call, P_GETTABLE);
    if (!i || !refs_ok(i, call, vr, n, type, 0, values)) return fmi2Error;
    return n == 0 ? fmi2OK : fmu_model_get(i->model, vr, n, type, values);
}

static fmi2Status set_values(fmi2Component c, const char *call, const fmi2ValueReference vr[], size_t n,
                             const void *values, VarType type)
{
    Instance *i = checked(c, call, P_SETTABLE);
    if (!i || !refs_ok(i, call, vr, n, type, 1, values)) return fmi2Error;
    if (n == 0) return fmi2OK;
    if (type != V_BOOLEAN) return fmu_model_set(i->model, vr, n, type, values);
    int small[32], *flags = n <= 32 ? small : malloc(n * sizeof *flags);   /* (no allocation in a step's sets) */
    if (!flags) return fmi2Error;
    for (size_t k = 0; k < n; k++) flags[k] = ((const fmi2Boolean *)values)[k] != fmi2False;   /* 0 or 1 */
    fmi2Status st = fmu_model_set(i->model, vr, n, type, flags);
    if (flags != small) free(flags);
    return st;
}

#define GETTER(name, ctype, type) \
    fmi2Status name(fmi2Component c, const fmi2ValueReference vr[], size_t n, ctype v[]) \
    { return get_values(c, #name, vr, n, v, type); }
#define SETTER(name, ctype, type) \
    fmi2Status name(fmi2Component c, const fmi2ValueReference vr[], size_t n, const ctype v[]) \
    { return set_values(c, #name, vr, n, v, type); }
GETTER(fmi2GetReal, fmi2Real, V_REAL)
GETTER(fmi2GetInteger, fmi2Integer, V_INTEGER)
GETTER(fmi2GetBoolean, fmi2Boolean, V_BOOLEAN)
GETTER(fmi2GetString, fmi2String, V_STRING)
SETTER(fmi2SetReal, fmi2Real, V_REAL)
SETTER(fmi2SetInteger, fmi2Integer, V_INTEGER)
SETTER(fmi2SetBoolean, fmi2Boolean, V_BOOLEAN)
SETTER(fmi2SetString, fmi2String, V_STRING)

/* ---- FMU states: handles of this instance; any other is refused, never dereferenced ---------------- */
static State *state_find(Instance *i, const char *call, fmi2FMUstate s)
{
    for (size_t k = 0; s && k < i->n_states; k++)
        if (i->states[k].handle == (uintptr_t)s) return &i->states[k];
    FMI2_SAY(&i->log, fmi2Error, "logStatusError", "%s: %p is not a live FMU state of this instance (freed, of "
             "another instance or FMU, or never made)", call, s);
    return NULL;
}

/* ``model`` (just made) becomes one of this instance's live states; its handle, or NULL (``model`` freed). */
static fmi2FMUstate state_add(Instance *i, const char *call, void *model, int phase, double time)
{
    if (i->n_states == i->cap_states) {
        size_t cap = i->cap_states ? 2 * i->cap_states : 8;
        State *grown = realloc(i->states, cap * sizeof *grown);
        if (!grown) { fmu_model_state_free(i->model, model); return NULL; }
        i->states = grown;
        i->cap_states = cap;
    }
    uintptr_t handle = fmi2_state_handle();
    if (!handle) {
        FMI2_SAY(&i->log, fmi2Error, "logStatusError", "%s: no new FMU-state handle can be made", call);
        fmu_model_state_free(i->model, model);
        return NULL;
    }
    i->states[i->n_states++] = (State){handle, model, phase, time};
    return (fmi2FMUstate)handle;
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s)
{
    Instance *i = checked(c, "fmi2GetFMUstate", P_ANY);
    if (!i) return fmi2Error;
    if (!s) {
        FMI2_SAY(&i->log, fmi2Error, "logStatusError", "fmi2GetFMUstate: the FMUstate pointer is NULL");
        return fmi2Error;
    }
    State *old = *s ? state_find(i, "fmi2GetFMUstate", *s) : NULL;
    if (*s && !old) return fmi2Error;
    void *model = fmu_model_state_take(i->model);
    if (!model) return fmi2Error;
    if (old) {                          /* FMI: a given state is overwritten */
        fmu_model_state_free(i->model, old->model);
        *old = (State){old->handle, model, i->phase, i->next_time};
        return fmi2OK;
    }
    *s = state_add(i, "fmi2GetFMUstate", model, i->phase, i->next_time);
    return *s ? fmi2OK : fmi2Error;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s)
{
    Instance *i = checked(c, "fmi2SetFMUstate", P_ANY);
    State *state = i ? state_find(i, "fmi2SetFMUstate", s) : NULL;
    if (!state) return fmi2Error;
    fmi2Status st = fmu_model_state_restore(i->model, state->model, i->phase == P_STEP || i->phase == P_TERMINATED);
    if (st > fmi2Warning) return st;
    if (state->phase >= 0) i->phase = state->phase;
    i->next_time = state->time;         /* steps go on from the state's time */
    return st;
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s)
{
    Instance *i = checked(c, "fmi2FreeFMUstate", P_ANY);
    if (!i) return fmi2Error;
    if (!s || !*s) return fmi2OK;
    State *state = state_find(i, "fmi2FreeFMUstate", *s);
    if (!state) return fmi2Error;
    fmu_model_state_free(i->model, state->model);
    *state = i->states[--i->n_states];
    *s = NULL;
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *size)
{
    Instance *i = checked(c, "fmi2SerializedFMUstateSize", P_ANY);
    State *state = i ? state_find(i, "fmi2SerializedFMUstateSize", s) : NULL;
    if (!state) return fmi2Error;
    if (!size) {
        FMI2_SAY(&i->log, fmi2Error, "logStatusError", "fmi2SerializedFMUstateSize: the size pointer is NULL");
        return fmi2Error;
    }
    return fmu_model_serialize(i->model, state->model, state->phase, state->time, size) ? fmi2OK : fmi2Error;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t size)
{
    Instance *i = checked(c, "fmi2SerializeFMUstate", P_ANY);
    State *state = i ? state_find(i, "fmi2SerializeFMUstate", s) : NULL;
    if (!state) return fmi2Error;
    size_t needed = 0;
    const unsigned char *bytes = fmu_model_serialize(i->model, state->model, state->phase, state->time, &needed);
    if (!bytes) return fmi2Error;
    if (!b || size < needed) {
        FMI2_SAY(&i->log, fmi2Error, "logStatusError", "fmi2SerializeFMUstate: %s (%zu bytes given, %zu needed)",
                 !b ? "the buffer is NULL" : "the buffer is too small", size, needed);
        return fmi2Error;
    }
    memcpy(b, bytes, needed);
    return fmi2OK;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t size, fmi2FMUstate *s)
{
    Instance *i = checked(c, "fmi2DeSerializeFMUstate", P_ANY);
    if (!i) return fmi2Error;
    if (!s || (size && !b)) {
        FMI2_SAY(&i->log, fmi2Error, "logStatusError", "fmi2DeSerializeFMUstate: the %s is NULL",
                 !s ? "FMUstate pointer" : "byte array");
        return fmi2Error;
    }
    int phase = -1;
    double time = 0.0;
    void *model = fmu_model_deserialize(i->model, (const unsigned char *)b, size, &phase, &time);
    if (!model) { *s = NULL; return fmi2Error; }   /* refused: the reason is in the log */
    *s = state_add(i, "fmi2DeSerializeFMUstate", model, phase, time);
    return *s ? fmi2OK : fmi2Error;
}

/* ---- what this FMU does not offer: refused with a reason, never Fatal ----------------------------- */
static fmi2Status not_provided(fmi2Component c, const char *call, const char *why)
{
    Instance *i = checked(c, call, P_ANY);
    if (!i) return fmi2Error;
    FMI2_SAY(&i->log, fmi2Error, "logStatusError", "%s: %s", call, why);
    return fmi2Error;
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                        const fmi2ValueReference z[], size_t nz, const fmi2Real dv[], fmi2Real dz[])
{
    (void)u; (void)nu; (void)z; (void)nz; (void)dv; (void)dz;
    return not_provided(c, "fmi2GetDirectionalDerivative", "not provided (providesDirectionalDerivative is false)");
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                       const fmi2Integer order[], const fmi2Real v[])
{
    (void)vr; (void)n; (void)order; (void)v;
    return not_provided(c, "fmi2SetRealInputDerivatives", "not provided (canInterpolateInputs is false)");
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                        const fmi2Integer order[], fmi2Real v[])
{
    (void)vr; (void)n; (void)order; (void)v;
    return not_provided(c, "fmi2GetRealOutputDerivatives", "not provided (maxOutputDerivativeOrder is 0)");
}

/* Status queries: steps are synchronous, so only fmi2LastSuccessfulTime and fmi2Terminated mean something. */
static fmi2Status no_status(Instance *i, const char *call)
{
    FMI2_SAY(&i->log, fmi2Discard, "logStatusDiscard", "%s: nothing to report (no asynchronous steps)", call);
    return fmi2Discard;
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind k, fmi2Real *v)
{
    Instance *i = checked(c, "fmi2GetRealStatus", P_ANY);
    if (!i || !v) return fmi2Error;
    if (k == fmi2LastSuccessfulTime) { *v = i->next_time; return fmi2OK; }
    return no_status(i, "fmi2GetRealStatus");
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind k, fmi2Boolean *v)
{
    Instance *i = checked(c, "fmi2GetBooleanStatus", P_ANY);
    if (!i || !v) return fmi2Error;
    if (k == fmi2Terminated) { *v = fmi2False; return fmi2OK; }    /* the FMU never asks to end the run */
    return no_status(i, "fmi2GetBooleanStatus");
}

#define NO_STATUS(name, ctype)                                                      \
    fmi2Status name(fmi2Component c, const fmi2StatusKind k, ctype *v)              \
    {                                                                               \
        (void)k;                                                                    \
        Instance *i = checked(c, #name, P_ANY);                                     \
        if (!i || !v) return fmi2Error;                                             \
        return no_status(i, #name);                                                 \
    }
NO_STATUS(fmi2GetStatus, fmi2Status)
NO_STATUS(fmi2GetIntegerStatus, fmi2Integer)
NO_STATUS(fmi2GetStringStatus, fmi2String)
