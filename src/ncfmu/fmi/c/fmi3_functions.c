/*
 * ncfmu: the FMI 3.0 co-simulation layer of every ncfmu FMU, over the same model interface (fmi2_model.h)
 * as the FMI 2.0 layer (fmi2_functions.c), as the Reference-FMUs keep fmi3Functions.c beside fmi2Functions.c.
 *
 * Variables are Float64 (a port's Real), Int32 (Integer), Boolean and String; every other type's call is
 * refused naming the value reference. The instances, handles, state machine and checks are fmi2_machine.h's
 * (FMI 3.0 co-simulation without event mode has the same four states: instantiated, initialization mode,
 * step mode, terminated); model exchange, scheduled execution, event mode, clocks and configuration mode are
 * not offered (fmi3Error with a reason; an instantiation of them returns NULL). No call reaches fmi3Fatal on
 * bad input; errors and warnings reach the host's logMessage whatever the debug-logging setting.
 */
#define _GNU_SOURCE                     /* dladdr: the binary holds itself loaded while its instances live */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"
#include "fmi2_machine.h"
#include "fmi2_model.h"

/* ---- instances ----------------------------------------------------------------------------------- */
typedef struct {
    uintptr_t handle;
    void *model;
    int phase;                          /* the instance's phase when it was taken; -1: unknown (kept at restore) */
    double time;
} State;

typedef struct {
    int phase;
    double next_time;
    char name[128];
    Fmi2Log log;                        /* say: the host's logMessage */
    fmi3LogMessageCallback log_message;
    Model *model;                       /* NULL after a failed fmi3Reset: the instance can only be freed */
    State *states;
    size_t n_states, cap_states;
} Instance;

static void say3(const Fmi2Log *log, int status, const char *category, const char *text)
{
    const Instance *i = (const Instance *)((const char *)log - offsetof(Instance, log));
    i->log_message((fmi3InstanceEnvironment)log->env, (fmi3Status)status, category, text);
}

static Instance *checked(fmi3Instance c, const char *call, int phases)
{
    Instance *i = fmi2_instance_find((fmi2Component)c, 0);
    if (!i || !fmi2_allowed(&i->log, i->phase, call, phases)) return NULL;
    if (!i->model) {
        FMI2_SAY(&i->log, fmi3Error, "logStatusError", "%s: the instance has no model (its reset failed): free it",
                 call);
        return NULL;
    }
    return i;
}

const char *fmi3GetVersion(void) { return fmi3Version; }

/* The checks of fmi3InstantiateCoSimulation's arguments (FMI 3.0: the resources are a path, not a URI). */
static int instantiate_ok(const Fmi2Log *early, fmi3String name, fmi3String token, fmi3String resources,
                          char *dir, size_t dir_size)
{
    struct stat st;
    if (!name || !fmi2_utf8_ok((const unsigned char *)name)) {
        FMI2_SAY(early, fmi3Error, "logStatusError", "fmi3InstantiateCoSimulation: instanceName is %s",
                 name ? "not valid UTF-8 text" : "NULL");
        return 0;
    }
    if (!token || strcmp(token, FMU_MODEL_GUID) != 0) {
        FMI2_SAY(early, fmi3Error, "logStatusError", "fmi3InstantiateCoSimulation: instantiationToken %s is not "
                 "this FMU's (%s): the modelDescription and the binary are from different builds",
                 token ? token : "(NULL)", FMU_MODEL_GUID);
        return 0;
    }
    size_t n = resources ? strlen(resources) : 0;
    if (!resources || n == 0 || n >= dir_size) {
        FMI2_SAY(early, fmi3Error, "logStatusError", "fmi3InstantiateCoSimulation: resourcePath %s is not the path "
                 "of an existing folder (the FMU's resources)", resources ? resources : "(NULL)");
        return 0;
    }
    memcpy(dir, resources, n + 1);
    while (n > 1 && dir[n - 1] == '/') dir[--n] = 0;
    if (stat(dir, &st) != 0 || !S_ISDIR(st.st_mode)) {
        FMI2_SAY(early, fmi3Error, "logStatusError", "fmi3InstantiateCoSimulation: resourcePath %s is not the path "
                 "of an existing folder (the FMU's resources)", resources);
        return 0;
    }
    return 1;
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String name, fmi3String token, fmi3String resources, fmi3Boolean visible,
                                         fmi3Boolean logging, fmi3Boolean event_mode, fmi3Boolean early_return,
                                         const fmi3ValueReference required[], size_t n_required,
                                         fmi3InstanceEnvironment env, fmi3LogMessageCallback log_message,
                                         fmi3IntermediateUpdateCallback intermediate_update)
{
    (void)early_return; (void)required; (void)n_required; (void)intermediate_update;
    Instance *i = calloc(1, sizeof *i);
    if (!i) return NULL;
    i->log_message = log_message;
    i->log = (Fmi2Log){.env = env, .say = log_message ? say3 : NULL,
                       .name = name && fmi2_utf8_ok((const unsigned char *)name) ? name : ""};
    char dir[4096];
    if (!instantiate_ok(&i->log, name, token, resources, dir, sizeof dir)) { free(i); return NULL; }
    if (event_mode) {
        FMI2_SAY(&i->log, fmi3Error, "logStatusError", "fmi3InstantiateCoSimulation: event mode is not offered "
                 "(hasEventMode is false)");
        free(i);
        return NULL;
    }
    snprintf(i->name, sizeof i->name, "%s", name);
    i->log.name = i->name;
    i->log.debug = logging;
    i->phase = P_INSTANTIATED;
    i->model = fmu_model_new(i->name, dir, visible, &i->log);
    fmi2Component handle = i->model ? fmi2_instance_add(i) : NULL;
    if (i->model && !handle) {
        FMI2_SAY(&i->log, fmi3Error, "logStatusError", "fmi3InstantiateCoSimulation: no new instance handle can be "
                 "made");
        fmu_model_free(i->model);
    }
    if (!handle) free(i);
    return (fmi3Instance)handle;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String name, fmi3String token, fmi3String resources,
                                          fmi3Boolean visible, fmi3Boolean logging, fmi3InstanceEnvironment env,
                                          fmi3LogMessageCallback log_message)
{
    (void)name; (void)token; (void)resources; (void)visible; (void)logging;
    if (log_message) log_message(env, fmi3Error, "logStatusError", "fmi3InstantiateModelExchange: this FMU is for "
                                 "co-simulation only");
    return NULL;
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String name, fmi3String token, fmi3String resources,
                                               fmi3Boolean visible, fmi3Boolean logging,
                                               fmi3InstanceEnvironment env, fmi3LogMessageCallback log_message,
                                               fmi3ClockUpdateCallback clock_update,
                                               fmi3LockPreemptionCallback lock, fmi3UnlockPreemptionCallback unlock)
{
    (void)name; (void)token; (void)resources; (void)visible; (void)logging; (void)clock_update; (void)lock;
    (void)unlock;
    if (log_message) log_message(env, fmi3Error, "logStatusError", "fmi3InstantiateScheduledExecution: this FMU is "
                                 "for co-simulation only");
    return NULL;
}

static void states_drop(Instance *i)
{
    for (size_t k = 0; k < i->n_states; k++) fmu_model_state_free(i->model, i->states[k].model);
    free(i->states);
    i->states = NULL;
    i->n_states = i->cap_states = 0;
}

void fmi3FreeInstance(fmi3Instance c)
{
    Instance *i = fmi2_instance_find((fmi2Component)c, 1);
    if (!i) return;
    if (i->model) {
        states_drop(i);
        fmu_model_free(i->model);
    }
    free(i);
    void *self = fmi2_library_release();
    if (self) dlclose(self);            /* the last thing done (a tail call): it may unmap this library */
}

fmi3Status fmi3SetDebugLogging(fmi3Instance c, fmi3Boolean on, size_t n, const fmi3String categories[])
{
    Instance *i = checked(c, "fmi3SetDebugLogging", P_ANY);
    if (!i) return fmi3Error;
    unsigned mask;
    if (!fmi2_categories_ok(&i->log, "fmi3SetDebugLogging", n, categories, &mask)) return fmi3Error;
    i->log.debug = on;
    i->log.categories = mask;
    return fmi3OK;
}

/* ---- the state machine --------------------------------------------------------------------------- */
fmi3Status fmi3EnterInitializationMode(fmi3Instance c, fmi3Boolean tol_defined, fmi3Float64 tol, fmi3Float64 start,
                                       fmi3Boolean stop_defined, fmi3Float64 stop)
{
    Instance *i = checked(c, "fmi3EnterInitializationMode", P_SETUP);
    if (!i || !fmi2_experiment_ok(&i->log, "fmi3EnterInitializationMode", start, stop_defined, stop)) return fmi3Error;
    fmi3Status st = (fmi3Status)fmu_model_setup_experiment(i->model, tol_defined, tol, start, stop_defined, stop);
    if (st > fmi3Warning) return st;
    i->next_time = start;
    st = (fmi3Status)fmu_model_enter_initialization(i->model);
    if (st <= fmi3Warning) i->phase = P_INIT;
    return st;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance c)
{
    Instance *i = checked(c, "fmi3ExitInitializationMode", P_INIT);
    if (!i) return fmi3Error;
    fmi3Status st = (fmi3Status)fmu_model_exit_initialization(i->model);
    if (st <= fmi3Warning) i->phase = P_STEP;
    return st;
}

fmi3Status fmi3Terminate(fmi3Instance c)
{
    Instance *i = checked(c, "fmi3Terminate", P_STEP);
    if (!i) return fmi3Error;
    fmi3Status st = (fmi3Status)fmu_model_terminate(i->model);
    if (st <= fmi3Warning) i->phase = P_TERMINATED;
    return st;
}

fmi3Status fmi3Reset(fmi3Instance c)
{
    Instance *i = checked(c, "fmi3Reset", P_ANY);
    if (!i) return fmi3Error;
    if (fmu_model_reset(i->model) != 0) {
        states_drop(i);
        fmu_model_free(i->model);
        i->model = NULL;
        return fmi3Error;
    }
    i->phase = P_INSTANTIATED;
    i->next_time = 0.0;
    return fmi3OK;
}

fmi3Status fmi3DoStep(fmi3Instance c, fmi3Float64 t, fmi3Float64 h, fmi3Boolean no_set_prior_state,
                      fmi3Boolean *event_handling_needed, fmi3Boolean *terminate_simulation, fmi3Boolean *early_return,
                      fmi3Float64 *last_successful_time)
{
    (void)no_set_prior_state;
    Instance *i = checked(c, "fmi3DoStep", P_STEP);
    if (!i || !fmi2_step_ok(&i->log, "fmi3DoStep", t, h) || !fmi2_step_ns_ok(&i->log, "fmi3DoStep", h)
        || !fmi2_continues_ok(&i->log, "fmi3DoStep", i->next_time, t)) return fmi3Error;
    fmi3Status st = (fmi3Status)fmu_model_do_step(i->model, t, h);
    if (st <= fmi3Warning) i->next_time = t + h;
    if (event_handling_needed) *event_handling_needed = fmi3False;
    if (terminate_simulation) *terminate_simulation = fmi3False;
    if (early_return) *early_return = fmi3False;
    if (last_successful_time) *last_successful_time = i->next_time;
    return st;
}

/* ---- variables ----------------------------------------------------------------------------------- */
static const char *type_name(VarType t)
{
    return t == V_REAL ? "Float64" : t == V_INTEGER ? "Int32" : t == V_BOOLEAN ? "Boolean" : "String";
}

/* As fmi2_functions.c: every reference a variable of ``type`` (settable now, its value within the rule, a String
 * UTF-8 text); one value per reference (every variable is a scalar). */
static int refs_ok(Instance *i, const char *call, const fmi3ValueReference vr[], size_t n, VarType type, int set,
                   const void *values, size_t n_values)
{
    if (n > 0 && (!vr || !values)) {
        FMI2_SAY(&i->log, fmi3Error, "logStatusError", "%s: %zu values asked, but the %s array is NULL", call, n,
                 !vr ? "value reference" : "value");
        return 0;
    }
    if (n_values != n) {
        FMI2_SAY(&i->log, fmi3Error, "logStatusError", "%s: %zu values for %zu value references (every variable of "
                 "this FMU is a scalar)", call, n_values, n);
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
            FMI2_SAY(&i->log, fmi3Error, "logStatusError", "%s: value reference %u%s%s%s %s (a %s call)", call, r,
                     v ? " (" : "", v ? v->name : "", v ? ")" : "", why, type_name(type));
            return 0;
        }
    }
    for (size_t k = 0; set && k < n; k++) {
        const VarInfo *v = &vars[vr[k]];
        if (type == V_STRING) {
            fmi3String s = ((const fmi3String *)values)[k];
            if (!s || !fmi2_utf8_ok((const unsigned char *)s)) {
                FMI2_SAY(&i->log, fmi3Error, "logStatusError", "%s: value reference %u (%s): %s", call, vr[k],
                         v->name, s ? "not valid UTF-8 text" : "a NULL string");
                return 0;
            }
        } else if (type == V_REAL ? !fmi2_value_ok(&i->log, v, ((const fmi3Float64 *)values)[k])
                   : type == V_INTEGER ? !fmi2_value_ok(&i->log, v, (double)((const fmi3Int32 *)values)[k]) : 0) {
            return 0;
        }
    }
    return 1;
}

static fmi3Status get_values(fmi3Instance c, const char *call, const fmi3ValueReference vr[], size_t n,
                             void *values, size_t n_values, VarType type)
{
    Instance *i = checked(c, call, P_GETTABLE);
    if (!i || !refs_ok(i, call, vr, n, type, 0, values, n_values)) return fmi3Error;
    if (n == 0) return fmi3OK;
    if (type != V_BOOLEAN) return (fmi3Status)fmu_model_get(i->model, vr, n, type, values);
    int small[32], *flags = n <= 32 ? small : malloc(n * sizeof *flags);   /* (no allocation in a step's gets) */
    if (!flags) return fmi3Error;
    fmi3Status st = (fmi3Status)fmu_model_get(i->model, vr, n, type, flags);
    for (size_t k = 0; st <= fmi3Warning && k < n; k++) ((fmi3Boolean *)values)[k] = flags[k] != 0;
    if (flags != small) free(flags);
    return st;
}

static fmi3Status set_values(fmi3Instance c, const char *call, const fmi3ValueReference vr[], size_t n,
                             const void *values, size_t n_values, VarType type)
{
    Instance *i = checked(c, call, P_SETTABLE);
    if (!i || !refs_ok(i, call, vr, n, type, 1, values, n_values)) return fmi3Error;
    if (n == 0) return fmi3OK;
    if (type != V_BOOLEAN) return (fmi3Status)fmu_model_set(i->model, vr, n, type, values);
    int small[32], *flags = n <= 32 ? small : malloc(n * sizeof *flags);
    if (!flags) return fmi3Error;
    for (size_t k = 0; k < n; k++) flags[k] = ((const fmi3Boolean *)values)[k] ? 1 : 0;
    fmi3Status st = (fmi3Status)fmu_model_set(i->model, vr, n, type, flags);
    if (flags != small) free(flags);
    return st;
}

_Static_assert(sizeof(fmi3Int32) == sizeof(int), "the model interface carries Integers as int");

#define GETTER(name, ctype, type) \
    fmi3Status name(fmi3Instance c, const fmi3ValueReference vr[], size_t n, ctype v[], size_t nv) \
    { return get_values(c, #name, vr, n, v, nv, type); }
#define SETTER(name, ctype, type) \
    fmi3Status name(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const ctype v[], size_t nv) \
    { return set_values(c, #name, vr, n, v, nv, type); }
GETTER(fmi3GetFloat64, fmi3Float64, V_REAL)
GETTER(fmi3GetInt32, fmi3Int32, V_INTEGER)
GETTER(fmi3GetBoolean, fmi3Boolean, V_BOOLEAN)
GETTER(fmi3GetString, fmi3String, V_STRING)
SETTER(fmi3SetFloat64, fmi3Float64, V_REAL)
SETTER(fmi3SetInt32, fmi3Int32, V_INTEGER)
SETTER(fmi3SetBoolean, fmi3Boolean, V_BOOLEAN)
SETTER(fmi3SetString, fmi3String, V_STRING)

/* The types no variable of this FMU has: a call with value references names the first; none is fine. */
static fmi3Status no_such_type(fmi3Instance c, const char *call, const fmi3ValueReference vr[], size_t n, int phases)
{
    Instance *i = checked(c, call, phases);
    if (!i) return fmi3Error;
    if (n == 0) return fmi3OK;
    FMI2_SAY(&i->log, fmi3Error, "logStatusError", "%s: value reference %u is not a variable of this call's type "
             "(this FMU has Float64, Int32, Boolean and String variables)", call, vr ? vr[0] : 0u);
    return fmi3Error;
}

#define NO_GETTER(name, ctype) \
    fmi3Status name(fmi3Instance c, const fmi3ValueReference vr[], size_t n, ctype v[], size_t nv) \
    { (void)v; (void)nv; return no_such_type(c, #name, vr, n, P_GETTABLE); }
#define NO_SETTER(name, ctype) \
    fmi3Status name(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const ctype v[], size_t nv) \
    { (void)v; (void)nv; return no_such_type(c, #name, vr, n, P_SETTABLE); }
NO_GETTER(fmi3GetFloat32, fmi3Float32)
NO_GETTER(fmi3GetInt8, fmi3Int8)
NO_GETTER(fmi3GetUInt8, fmi3UInt8)
NO_GETTER(fmi3GetInt16, fmi3Int16)
NO_GETTER(fmi3GetUInt16, fmi3UInt16)
NO_GETTER(fmi3GetUInt32, fmi3UInt32)
NO_GETTER(fmi3GetInt64, fmi3Int64)
NO_GETTER(fmi3GetUInt64, fmi3UInt64)
NO_SETTER(fmi3SetFloat32, fmi3Float32)
NO_SETTER(fmi3SetInt8, fmi3Int8)
NO_SETTER(fmi3SetUInt8, fmi3UInt8)
NO_SETTER(fmi3SetInt16, fmi3Int16)
NO_SETTER(fmi3SetUInt16, fmi3UInt16)
NO_SETTER(fmi3SetUInt32, fmi3UInt32)
NO_SETTER(fmi3SetInt64, fmi3Int64)
NO_SETTER(fmi3SetUInt64, fmi3UInt64)

fmi3Status fmi3GetBinary(fmi3Instance c, const fmi3ValueReference vr[], size_t n, size_t sizes[], fmi3Binary v[],
                         size_t nv)
{
    (void)sizes; (void)v; (void)nv;
    return no_such_type(c, "fmi3GetBinary", vr, n, P_GETTABLE);
}

fmi3Status fmi3SetBinary(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const size_t sizes[],
                         const fmi3Binary v[], size_t nv)
{
    (void)sizes; (void)v; (void)nv;
    return no_such_type(c, "fmi3SetBinary", vr, n, P_SETTABLE);
}

fmi3Status fmi3GetClock(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3Clock v[])
{
    (void)v;
    return no_such_type(c, "fmi3GetClock", vr, n, P_ANY);
}

fmi3Status fmi3SetClock(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3Clock v[])
{
    (void)v;
    return no_such_type(c, "fmi3SetClock", vr, n, P_ANY);
}

/* ---- FMU states (as fmi2_functions.c) ------------------------------------------------------------- */
static State *state_find(Instance *i, const char *call, fmi3FMUState s)
{
    for (size_t k = 0; s && k < i->n_states; k++)
        if (i->states[k].handle == (uintptr_t)s) return &i->states[k];
    FMI2_SAY(&i->log, fmi3Error, "logStatusError", "%s: %p is not a live FMU state of this instance (freed, of "
             "another instance or FMU, or never made)", call, s);
    return NULL;
}

static fmi3FMUState state_add(Instance *i, const char *call, void *model, int phase, double time)
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
        FMI2_SAY(&i->log, fmi3Error, "logStatusError", "%s: no new FMU-state handle can be made", call);
        fmu_model_state_free(i->model, model);
        return NULL;
    }
    i->states[i->n_states++] = (State){handle, model, phase, time};
    return (fmi3FMUState)handle;
}

fmi3Status fmi3GetFMUState(fmi3Instance c, fmi3FMUState *s)
{
    Instance *i = checked(c, "fmi3GetFMUState", P_ANY);
    if (!i) return fmi3Error;
    if (!s) {
        FMI2_SAY(&i->log, fmi3Error, "logStatusError", "fmi3GetFMUState: the FMUState pointer is NULL");
        return fmi3Error;
    }
    State *old = *s ? state_find(i, "fmi3GetFMUState", *s) : NULL;
    if (*s && !old) return fmi3Error;
    void *model = fmu_model_state_take(i->model);
    if (!model) return fmi3Error;
    if (old) {
        fmu_model_state_free(i->model, old->model);
        *old = (State){old->handle, model, i->phase, i->next_time};
        return fmi3OK;
    }
    *s = state_add(i, "fmi3GetFMUState", model, i->phase, i->next_time);
    return *s ? fmi3OK : fmi3Error;
}

fmi3Status fmi3SetFMUState(fmi3Instance c, fmi3FMUState s)
{
    Instance *i = checked(c, "fmi3SetFMUState", P_ANY);
    State *state = i ? state_find(i, "fmi3SetFMUState", s) : NULL;
    if (!state) return fmi3Error;
    fmi3Status st = (fmi3Status)fmu_model_state_restore(i->model, state->model,
                                                        i->phase == P_STEP || i->phase == P_TERMINATED);
    if (st > fmi3Warning) return st;
    if (state->phase >= 0) i->phase = state->phase;
    i->next_time = state->time;
    return st;
}

fmi3Status fmi3FreeFMUState(fmi3Instance c, fmi3FMUState *s)
{
    Instance *i = checked(c, "fmi3FreeFMUState", P_ANY);
    if (!i) return fmi3Error;
    if (!s || !*s) return fmi3OK;
    State *state = state_find(i, "fmi3FreeFMUState", *s);
    if (!state) return fmi3Error;
    fmu_model_state_free(i->model, state->model);
    *state = i->states[--i->n_states];
    *s = NULL;
    return fmi3OK;
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance c, fmi3FMUState s, size_t *size)
{
    Instance *i = checked(c, "fmi3SerializedFMUStateSize", P_ANY);
    State *state = i ? state_find(i, "fmi3SerializedFMUStateSize", s) : NULL;
    if (!state) return fmi3Error;
    if (!size) {
        FMI2_SAY(&i->log, fmi3Error, "logStatusError", "fmi3SerializedFMUStateSize: the size pointer is NULL");
        return fmi3Error;
    }
    return fmu_model_serialize(i->model, state->model, state->phase, state->time, size) ? fmi3OK : fmi3Error;
}

fmi3Status fmi3SerializeFMUState(fmi3Instance c, fmi3FMUState s, fmi3Byte b[], size_t size)
{
    Instance *i = checked(c, "fmi3SerializeFMUState", P_ANY);
    State *state = i ? state_find(i, "fmi3SerializeFMUState", s) : NULL;
    if (!state) return fmi3Error;
    size_t needed = 0;
    const unsigned char *bytes = fmu_model_serialize(i->model, state->model, state->phase, state->time, &needed);
    if (!bytes) return fmi3Error;
    if (!b || size < needed) {
        FMI2_SAY(&i->log, fmi3Error, "logStatusError", "fmi3SerializeFMUState: %s (%zu bytes given, %zu needed)",
                 !b ? "the buffer is NULL" : "the buffer is too small", size, needed);
        return fmi3Error;
    }
    memcpy(b, bytes, needed);
    return fmi3OK;
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance c, const fmi3Byte b[], size_t size, fmi3FMUState *s)
{
    Instance *i = checked(c, "fmi3DeserializeFMUState", P_ANY);
    if (!i) return fmi3Error;
    if (!s || (size && !b)) {
        FMI2_SAY(&i->log, fmi3Error, "logStatusError", "fmi3DeserializeFMUState: the %s is NULL",
                 !s ? "FMUState pointer" : "byte array");
        return fmi3Error;
    }
    int phase = -1;
    double time = 0.0;
    void *model = fmu_model_deserialize(i->model, (const unsigned char *)b, size, &phase, &time);
    if (!model) { *s = NULL; return fmi3Error; }
    *s = state_add(i, "fmi3DeserializeFMUState", model, phase, time);
    return *s ? fmi3OK : fmi3Error;
}

/* ---- what this FMU does not offer: refused with a reason, never Fatal ----------------------------- */
static fmi3Status not_provided(fmi3Instance c, const char *call, const char *why)
{
    Instance *i = checked(c, call, P_ANY);
    if (!i) return fmi3Error;
    FMI2_SAY(&i->log, fmi3Error, "logStatusError", "%s: %s", call, why);
    return fmi3Error;
}

#define CS_ONLY "not provided (a co-simulation FMU without event mode)"
#define NO_CLOCKS "not provided (this FMU has no clocks)"

fmi3Status fmi3EnterEventMode(fmi3Instance c) { return not_provided(c, "fmi3EnterEventMode", CS_ONLY); }
fmi3Status fmi3EnterStepMode(fmi3Instance c) { return not_provided(c, "fmi3EnterStepMode", CS_ONLY); }
fmi3Status fmi3EnterConfigurationMode(fmi3Instance c)
{
    return not_provided(c, "fmi3EnterConfigurationMode", "not provided (this FMU has no structural parameters)");
}
fmi3Status fmi3ExitConfigurationMode(fmi3Instance c)
{
    return not_provided(c, "fmi3ExitConfigurationMode", "not provided (this FMU has no structural parameters)");
}
fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance c) { return not_provided(c, "fmi3EvaluateDiscreteStates", CS_ONLY); }
fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance c)
{
    return not_provided(c, "fmi3EnterContinuousTimeMode", CS_ONLY);
}

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance c, fmi3ValueReference vr, size_t *n)
{
    (void)vr; (void)n;
    return not_provided(c, "fmi3GetNumberOfVariableDependencies", "not provided (no dependencies are declared)");
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance c, fmi3ValueReference dependent, size_t element_dependent[],
                                       fmi3ValueReference independents[], size_t element_independents[],
                                       fmi3DependencyKind kinds[], size_t n)
{
    (void)dependent; (void)element_dependent; (void)independents; (void)element_independents; (void)kinds; (void)n;
    return not_provided(c, "fmi3GetVariableDependencies", "not provided (no dependencies are declared)");
}

#define DERIVATIVE(name, why)                                                                                  \
    fmi3Status name(fmi3Instance c, const fmi3ValueReference unknowns[], size_t n_unknowns,                     \
                    const fmi3ValueReference knowns[], size_t n_knowns, const fmi3Float64 seed[], size_t n_seed, \
                    fmi3Float64 sensitivity[], size_t n_sensitivity)                                           \
    {                                                                                                          \
        (void)unknowns; (void)n_unknowns; (void)knowns; (void)n_knowns; (void)seed; (void)n_seed;              \
        (void)sensitivity; (void)n_sensitivity;                                                                \
        return not_provided(c, #name, why);                                                                    \
    }
DERIVATIVE(fmi3GetDirectionalDerivative, "not provided (providesDirectionalDerivatives is false)")
DERIVATIVE(fmi3GetAdjointDerivative, "not provided (providesAdjointDerivatives is false)")

fmi3Status fmi3GetIntervalDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3Float64 intervals[],
                                  fmi3IntervalQualifier qualifiers[])
{
    (void)vr; (void)n; (void)intervals; (void)qualifiers;
    return not_provided(c, "fmi3GetIntervalDecimal", NO_CLOCKS);
}

fmi3Status fmi3GetIntervalFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3UInt64 counters[],
                                   fmi3UInt64 resolutions[], fmi3IntervalQualifier qualifiers[])
{
    (void)vr; (void)n; (void)counters; (void)resolutions; (void)qualifiers;
    return not_provided(c, "fmi3GetIntervalFraction", NO_CLOCKS);
}

fmi3Status fmi3GetShiftDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3Float64 shifts[])
{
    (void)vr; (void)n; (void)shifts;
    return not_provided(c, "fmi3GetShiftDecimal", NO_CLOCKS);
}

fmi3Status fmi3GetShiftFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3UInt64 counters[],
                                fmi3UInt64 resolutions[])
{
    (void)vr; (void)n; (void)counters; (void)resolutions;
    return not_provided(c, "fmi3GetShiftFraction", NO_CLOCKS);
}

fmi3Status fmi3SetIntervalDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t n,
                                  const fmi3Float64 intervals[])
{
    (void)vr; (void)n; (void)intervals;
    return not_provided(c, "fmi3SetIntervalDecimal", NO_CLOCKS);
}

fmi3Status fmi3SetIntervalFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t n,
                                   const fmi3UInt64 counters[], const fmi3UInt64 resolutions[])
{
    (void)vr; (void)n; (void)counters; (void)resolutions;
    return not_provided(c, "fmi3SetIntervalFraction", NO_CLOCKS);
}

fmi3Status fmi3SetShiftDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3Float64 shifts[])
{
    (void)vr; (void)n; (void)shifts;
    return not_provided(c, "fmi3SetShiftDecimal", NO_CLOCKS);
}

fmi3Status fmi3SetShiftFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3UInt64 counters[],
                                const fmi3UInt64 resolutions[])
{
    (void)vr; (void)n; (void)counters; (void)resolutions;
    return not_provided(c, "fmi3SetShiftFraction", NO_CLOCKS);
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance c, fmi3Boolean *need_update, fmi3Boolean *terminate,
                                    fmi3Boolean *nominals_changed, fmi3Boolean *values_changed,
                                    fmi3Boolean *next_event_defined, fmi3Float64 *next_event)
{
    (void)need_update; (void)terminate; (void)nominals_changed; (void)values_changed; (void)next_event_defined;
    (void)next_event;
    return not_provided(c, "fmi3UpdateDiscreteStates", CS_ONLY);
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance c, fmi3Boolean no_set_prior, fmi3Boolean *enter_event_mode,
                                       fmi3Boolean *terminate)
{
    (void)no_set_prior; (void)enter_event_mode; (void)terminate;
    return not_provided(c, "fmi3CompletedIntegratorStep", CS_ONLY);
}

fmi3Status fmi3SetTime(fmi3Instance c, fmi3Float64 time)
{
    (void)time;
    return not_provided(c, "fmi3SetTime", CS_ONLY);
}

#define ME_ARRAY(name, ctype)                                        \
    fmi3Status name(fmi3Instance c, ctype values[], size_t n)         \
    {                                                                \
        (void)values; (void)n;                                       \
        return not_provided(c, #name, CS_ONLY);                      \
    }
ME_ARRAY(fmi3SetContinuousStates, const fmi3Float64)
ME_ARRAY(fmi3GetContinuousStateDerivatives, fmi3Float64)
ME_ARRAY(fmi3GetEventIndicators, fmi3Float64)
ME_ARRAY(fmi3GetContinuousStates, fmi3Float64)
ME_ARRAY(fmi3GetNominalsOfContinuousStates, fmi3Float64)

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance c, size_t *n)
{
    (void)n;
    return not_provided(c, "fmi3GetNumberOfEventIndicators", CS_ONLY);
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance c, size_t *n)
{
    (void)n;
    return not_provided(c, "fmi3GetNumberOfContinuousStates", CS_ONLY);
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3Int32 orders[],
                                    fmi3Float64 values[], size_t nv)
{
    (void)vr; (void)n; (void)orders; (void)values; (void)nv;
    return not_provided(c, "fmi3GetOutputDerivatives", "not provided (maxOutputDerivativeOrder is 0)");
}

fmi3Status fmi3ActivateModelPartition(fmi3Instance c, fmi3ValueReference clock, fmi3Float64 time)
{
    (void)clock; (void)time;
    return not_provided(c, "fmi3ActivateModelPartition", NO_CLOCKS);
}
