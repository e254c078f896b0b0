/* A small FMI 3.0 co-simulation frame for the test suite's foreign FMUs, on the FMI 3.0 headers that come with
 * fmpy, independent of ncfmu's own C code. It runs the same model files as frame2.c (model.h); value references
 * are per type: Float64 1.., Int32 101.., Boolean 201.., String 301.. (index = vr - base). The functions a
 * co-simulation host does not need here are in stubs3.c (they return fmi3Error).
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"
#include "model.h"

enum { INSTANTIATED, INITIALIZATION, STEPPING, TERMINATED, FAILED };
enum { FLOAT64 = 1, INT32 = 101, BOOLEAN = 201, STRING = 301 };

typedef struct {
    Instance m;
    fmi3LogMessageCallback log;
    fmi3InstanceEnvironment env;
} Instance3;

static void say(Instance3 *x, fmi3Status status, const char *text) {
    if (x->log) x->log(x->env, status, "logStatusError", text);
}

/* model.h's logger (for models that log): formatted here */
static void model_log(void *env, const char *instance, int status, const char *category, const char *fmt, ...) {
    (void)instance; (void)category;
    Instance3 *x = env;
    char text[512];
    va_list args;
    va_start(args, fmt);
    vsnprintf(text, sizeof text, fmt, args);
    va_end(args);
    if (x->log) x->log(x->env, (fmi3Status)status, "logEvents", text);
}

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance c, fmi3Boolean on, size_t n, const fmi3String cats[]) {
    (void)c; (void)on; (void)n; (void)cats;
    return fmi3OK;
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String name, fmi3String token, fmi3String resources,
                                         fmi3Boolean visible, fmi3Boolean logging, fmi3Boolean event_mode,
                                         fmi3Boolean early_return, const fmi3ValueReference required[],
                                         size_t n_required, fmi3InstanceEnvironment env,
                                         fmi3LogMessageCallback log, fmi3IntermediateUpdateCallback update) {
    (void)resources; (void)visible; (void)logging; (void)early_return; (void)required; (void)n_required;
    (void)update;
    if (!name || !token || strcmp(token, MODEL_GUID) != 0 || event_mode) return NULL;
    Instance3 *x = calloc(1, sizeof(Instance3));
    if (!x) return NULL;
    x->m.name = strdup(name);
    x->m.logger = (Logger)model_log;
    x->m.environment = x;
    x->log = log;
    x->env = env;
    model_defaults(&x->m);
    x->m.phase = INSTANTIATED;
    return x;
}

void fmi3FreeInstance(fmi3Instance c) {
    Instance3 *x = c;
    if (!x) return;
    for (int i = 0; i < MAX_VARS; i++) free(x->m.s[i]);
    free(x->m.name);
    free(x);
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance c, fmi3Boolean tol_defined, fmi3Float64 tol, fmi3Float64 start,
                                       fmi3Boolean stop_defined, fmi3Float64 stop) {
    Instance3 *x = c;
    (void)tol_defined; (void)tol; (void)stop_defined; (void)stop;
    if (!x || x->m.phase != INSTANTIATED) return fmi3Error;
    x->m.time = start;
    x->m.phase = INITIALIZATION;
    return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance c) {
    Instance3 *x = c;
    if (!x || x->m.phase != INITIALIZATION) return fmi3Error;
    const char *why = model_initialize(&x->m);
    if (why) { say(x, fmi3Error, why); x->m.phase = FAILED; return fmi3Error; }
    x->m.phase = STEPPING;
    return fmi3OK;
}

fmi3Status fmi3EnterStepMode(fmi3Instance c) { return c ? fmi3OK : fmi3Error; }

fmi3Status fmi3Terminate(fmi3Instance c) {
    Instance3 *x = c;
    if (!x) return fmi3Error;
    x->m.phase = TERMINATED;
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance c) {
    Instance3 *x = c;
    if (!x) return fmi3Error;
    for (int i = 0; i < MAX_VARS; i++) { free(x->m.s[i]); x->m.s[i] = NULL; }
    model_defaults(&x->m);
    x->m.terminated = 0;
    x->m.time = 0;
    x->m.phase = INSTANTIATED;
    return fmi3OK;
}

/* the index of vr among the variables of a type, or -1 */
static int index_of(fmi3ValueReference vr, unsigned base, unsigned count) {
    return vr >= base && vr < base + count ? (int)(vr - base) : -1;
}

static int may_set(Instance3 *x, char type, int k) {
    int how = model_settable(type, (unsigned)k);
    if (how == 2 || (how == 1 && (x->m.phase == INSTANTIATED || x->m.phase == INITIALIZATION))) return 1;
    say(x, fmi3Error, how == 1 ? "a fixed parameter cannot be set now" : "not settable");
    return 0;
}

#define ACCESS(Name, CType, base, count, field, type, get_expr, set_expr)                                       \
    fmi3Status fmi3Get##Name(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, CType values[],         \
                             size_t n) {                                                                      \
        Instance3 *x = c;                                                                                     \
        if (!x || n != nvr) return fmi3Error;                                                                 \
        for (size_t j = 0; j < nvr; j++) {                                                                    \
            int k = index_of(vr[j], base, count);                                                             \
            if (k < 0) { say(x, fmi3Error, "unknown value reference"); return fmi3Error; }                    \
            values[j] = get_expr;                                                                             \
        }                                                                                                     \
        return fmi3OK;                                                                                        \
    }                                                                                                         \
    fmi3Status fmi3Set##Name(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const CType values[],   \
                             size_t n) {                                                                      \
        Instance3 *x = c;                                                                                     \
        if (!x || n != nvr) return fmi3Error;                                                                 \
        for (size_t j = 0; j < nvr; j++) {                                                                    \
            int k = index_of(vr[j], base, count);                                                             \
            if (k < 0) { say(x, fmi3Error, "unknown value reference"); return fmi3Error; }                    \
            if (!may_set(x, type, k)) return fmi3Error;                                                       \
        }                                                                                                     \
        for (size_t j = 0; j < nvr; j++) {                                                                    \
            int k = index_of(vr[j], base, count);                                                             \
            set_expr;                                                                                         \
        }                                                                                                     \
        return fmi3OK;                                                                                        \
    }

ACCESS(Float64, fmi3Float64, FLOAT64, N_REAL, r, 'r', x->m.r[k], x->m.r[k] = values[j])
ACCESS(Int32, fmi3Int32, INT32, N_INTEGER, i, 'i', x->m.i[k], x->m.i[k] = values[j])
ACCESS(Boolean, fmi3Boolean, BOOLEAN, N_BOOLEAN, b, 'b', x->m.b[k] != 0, x->m.b[k] = values[j] ? 1 : 0)
ACCESS(String, fmi3String, STRING, N_STRING, s, 's', x->m.s[k] ? x->m.s[k] : "",
       (free(x->m.s[k]), x->m.s[k] = strdup(values[j] ? values[j] : "")))

fmi3Status fmi3DoStep(fmi3Instance c, fmi3Float64 t, fmi3Float64 h, fmi3Boolean no_prior, fmi3Boolean *event,
                      fmi3Boolean *terminate, fmi3Boolean *early, fmi3Float64 *last) {
    Instance3 *x = c;
    (void)no_prior;
    if (!x || x->m.phase != STEPPING || !(h > 0)) return fmi3Error;
    if (fabs(t - x->m.time) > 1e-9 * (1 + fabs(t))) { say(x, fmi3Error, "time does not continue"); return fmi3Error; }
    int status = model_step(&x->m, t, h);
    *event = fmi3False;
    *early = fmi3False;
    *terminate = x->m.terminated ? fmi3True : fmi3False;
    if (status == 0) x->m.time = t + h;
    *last = x->m.time;
    /* FMI 3.0 asks to end with terminateSimulation and fmi3OK; lastSuccessfulTime says how far the FMU got */
    return status == 2 && x->m.terminated ? fmi3OK : (fmi3Status)status;
}
