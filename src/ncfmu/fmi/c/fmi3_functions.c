/*
 * ncfmu: the FMI 3.0 co-simulation layer of every ncfmu FMU, over the same model interface (model.h)
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
#include "model.h"
#define FMU_FMI_MAJOR 3                 /* the FMI version its serialized states are sealed with */
#include "fmu_instance.h"

_Static_assert((int)fmi3OK == ModelOK && (int)fmi3Warning == ModelWarning && (int)fmi3Discard == ModelDiscard
               && (int)fmi3Error == ModelError && (int)fmi3Fatal == ModelFatal,
               "FMI 3.0's statuses are the model interface's numbers (fmu_instance.h returns them)");
_Static_assert(sizeof(fmi3Int32) == sizeof(int) && sizeof(fmi3Boolean) == 1
               && sizeof(fmi3ValueReference) == sizeof(unsigned), "the model interface carries Integers as int");

static const char *const TYPE_NAMES[4] = {"Float64", "Int32", "Boolean", "String"};

/* ---- instances ----------------------------------------------------------------------------------- */
static void say3(const Fmi2Log *log, int status, const char *category, const char *text)
{
    const FmuInstance *i = (const FmuInstance *)((const char *)log - offsetof(FmuInstance, log));
    ((fmi3LogMessageCallback)i->host_log)((fmi3InstanceEnvironment)log->env, (fmi3Status)status, category, text);
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
    FmuInstance *i = calloc(1, sizeof *i);
    if (!i) return NULL;
    i->host_log = (void (*)(void))log_message;
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
    return (fmi3Instance)fmu_instance_start(i, "fmi3InstantiateCoSimulation", dir, visible);
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

void fmi3FreeInstance(fmi3Instance c)
{
    void *self = fmu_instance_free(c);
    if (self) dlclose(self);            /* the last thing done (a tail call): it may unmap this library */
}

fmi3Status fmi3SetDebugLogging(fmi3Instance c, fmi3Boolean on, size_t n, const fmi3String categories[])
{
    return (fmi3Status)fmu_set_debug_logging(c, "fmi3SetDebugLogging", on, n, categories);
}

/* ---- the state machine --------------------------------------------------------------------------- */
/* FMI 3.0's fmi3EnterInitializationMode is FMI 2.0's fmi2SetupExperiment and fmi2EnterInitializationMode. */
fmi3Status fmi3EnterInitializationMode(fmi3Instance c, fmi3Boolean tol_defined, fmi3Float64 tol, fmi3Float64 start,
                                       fmi3Boolean stop_defined, fmi3Float64 stop)
{
    FmuInstance *i = fmu_checked(c, "fmi3EnterInitializationMode", P_SETUP);
    int st = fmu_setup_experiment(i, "fmi3EnterInitializationMode", tol_defined, tol, start, stop_defined, stop);
    return (fmi3Status)(st > ModelWarning ? st : fmu_transition(c, "fmi3EnterInitializationMode", P_SETUP, P_INIT,
                                                               fmu_model_enter_initialization));
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance c)
{
    return (fmi3Status)fmu_transition(c, "fmi3ExitInitializationMode", P_INIT, P_STEP, fmu_model_exit_initialization);
}

fmi3Status fmi3Terminate(fmi3Instance c)
{
    return (fmi3Status)fmu_transition(c, "fmi3Terminate", P_STEP, P_TERMINATED, fmu_model_terminate);
}

fmi3Status fmi3Reset(fmi3Instance c) { return (fmi3Status)fmu_reset(c, "fmi3Reset"); }

fmi3Status fmi3DoStep(fmi3Instance c, fmi3Float64 t, fmi3Float64 h, fmi3Boolean no_set_prior_state,
                      fmi3Boolean *event_handling_needed, fmi3Boolean *terminate_simulation, fmi3Boolean *early_return,
                      fmi3Float64 *last_successful_time)
{
    (void)no_set_prior_state;
    FmuInstance *i;
    fmi3Status st = (fmi3Status)fmu_do_step(c, "fmi3DoStep", t, h, &i);
    if (!i) return st;
    if (event_handling_needed) *event_handling_needed = fmi3False;
    if (terminate_simulation) *terminate_simulation = fmi3False;
    if (early_return) *early_return = fmi3False;
    if (last_successful_time) *last_successful_time = i->next_time;
    return st;
}

/* ---- variables (fmu_instance.h); FMI 3.0 counts the values too: one per reference (every variable is a scalar) */
static int counts_ok(fmi3Instance c, const char *call, size_t n, size_t n_values, int phases)
{
    if (n_values == n) return 1;
    FmuInstance *i = fmu_checked(c, call, phases);
    if (i) FMI2_SAY(&i->log, fmi3Error, "logStatusError", "%s: %zu values for %zu value references (every variable "
                    "of this FMU is a scalar)", call, n_values, n);
    return 0;
}

#define GETTER(name, ctype, type) \
    fmi3Status name(fmi3Instance c, const fmi3ValueReference vr[], size_t n, ctype v[], size_t nv) \
    { \
        if (!counts_ok(c, #name, n, nv, P_GETTABLE)) return fmi3Error; \
        return (fmi3Status)fmu_get_values(c, #name, vr, n, v, type, sizeof(fmi3Boolean), TYPE_NAMES); \
    }
#define SETTER(name, ctype, type) \
    fmi3Status name(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const ctype v[], size_t nv) \
    { \
        if (!counts_ok(c, #name, n, nv, P_SETTABLE)) return fmi3Error; \
        return (fmi3Status)fmu_set_values(c, #name, vr, n, v, type, sizeof(fmi3Boolean), TYPE_NAMES); \
    }
#ifndef NCFMU_TIME_VR
#error "NCFMU_TIME_VR: the value reference of the independent variable 'time' (TIME_VR in fmi/fmi3.py)"
#endif

/* Float64 reads the declared independent variable too: FMI 3.0 lets a host get it (fmusim records it); its
 * value is where the instance stands (the start time, the last step's end, a restored state's time). */
fmi3Status fmi3GetFloat64(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3Float64 v[], size_t nv)
{
    if (!counts_ok(c, "fmi3GetFloat64", n, nv, P_GETTABLE)) return fmi3Error;
    size_t k = 0;
    while (vr && v && k < n && vr[k] != NCFMU_TIME_VR) k++;
    if (!vr || !v || k == n)
        return (fmi3Status)fmu_get_values(c, "fmi3GetFloat64", vr, n, v, V_REAL, sizeof(fmi3Boolean), TYPE_NAMES);
    FmuInstance *i = fmu_checked(c, "fmi3GetFloat64", P_GETTABLE);
    if (!i) return fmi3Error;
    fmi3Status worst = fmi3OK;
    for (k = 0; k < n; k++) {
        if (vr[k] == NCFMU_TIME_VR) {
            v[k] = i->next_time;
            continue;
        }
        fmi3Status st = (fmi3Status)fmu_get_values(c, "fmi3GetFloat64", &vr[k], 1, &v[k], V_REAL,
                                                   sizeof(fmi3Boolean), TYPE_NAMES);
        if (st >= fmi3Error) return st;
        if (st > worst) worst = st;
    }
    return worst;
}
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
    FmuInstance *i = fmu_checked(c, call, phases);
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

/* ---- FMU states (fmu_instance.h) ---------------------------------------------------------------- */
fmi3Status fmi3GetFMUState(fmi3Instance c, fmi3FMUState *s)
{
    return (fmi3Status)fmu_get_state(c, "fmi3GetFMUState", s);
}

fmi3Status fmi3SetFMUState(fmi3Instance c, fmi3FMUState s)
{
    return (fmi3Status)fmu_set_state(c, "fmi3SetFMUState", s);
}

fmi3Status fmi3FreeFMUState(fmi3Instance c, fmi3FMUState *s)
{
    return (fmi3Status)fmu_free_state(c, "fmi3FreeFMUState", s);
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance c, fmi3FMUState s, size_t *size)
{
    return (fmi3Status)fmu_state_size(c, "fmi3SerializedFMUStateSize", s, size);
}

fmi3Status fmi3SerializeFMUState(fmi3Instance c, fmi3FMUState s, fmi3Byte b[], size_t size)
{
    return (fmi3Status)fmu_serialize(c, "fmi3SerializeFMUState", s, b, size);
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance c, const fmi3Byte b[], size_t size, fmi3FMUState *s)
{
    return (fmi3Status)fmu_deserialize(c, "fmi3DeserializeFMUState", b, size, s);
}

/* ---- what this FMU does not offer: refused with a reason, never Fatal (fmu_instance.h) ---------- */
#define not_provided(c, call, why) ((fmi3Status)fmu_not_provided((c), (call), (why)))
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
