/* A small FMI 2.0 co-simulation frame for the test suite's foreign FMUs.
 *
 * Written for the tests on the FMI 2.0 headers that come with fmpy, independently of ncfmu's own C code:
 * these FMUs stand for models someone else wrote. A model file defines the variable counts (N_REAL,
 * N_INTEGER, N_BOOLEAN, N_STRING), the causality of each (model_settable), its defaults and its step.
 * A variable's value reference is its index among the variables of its type.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "model.h"

#ifdef GET_HOOK
void GET_HOOK(Instance *m);
#endif

typedef enum { INSTANTIATED, INITIALIZATION, STEPPING, TERMINATED, FAILED } Phase;

static void say(Instance *m, fmi2Status status, const char *category, const char *text) {
    if (m->logger) m->logger(m->environment, m->name, status, category, "%s", text);
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String resources,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible, fmi2Boolean logging) {
    (void)resources; (void)visible; (void)logging;
    if (!name || type != fmi2CoSimulation || !guid || strcmp(guid, MODEL_GUID) != 0) return NULL;
    Instance *m = calloc(1, sizeof(Instance));
    if (!m) return NULL;
    m->name = strdup(name);
    m->logger = functions ? (Logger)functions->logger : NULL;
    m->environment = functions ? functions->componentEnvironment : NULL;
    model_defaults(m);
    m->phase = INSTANTIATED;
    return m;
}

void fmi2FreeInstance(fmi2Component c) {
    Instance *m = c;
    if (!m) return;
    for (int i = 0; i < N_STRING; i++) free(m->s[i]);
    free(m->name);
    free(m);
}

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cats[]) {
    (void)c; (void)on; (void)n; (void)cats;
    return fmi2OK;
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tol_defined, fmi2Real tol, fmi2Real start,
                               fmi2Boolean stop_defined, fmi2Real stop) {
    Instance *m = c;
    (void)tol_defined; (void)tol; (void)stop_defined; (void)stop;
    if (!m || m->phase != INSTANTIATED) return fmi2Error;
    m->time = start;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    Instance *m = c;
    if (!m || m->phase != INSTANTIATED) return fmi2Error;
    m->phase = INITIALIZATION;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    Instance *m = c;
    if (!m || m->phase != INITIALIZATION) return fmi2Error;
    const char *why = model_initialize(m);
    if (why) { say(m, fmi2Error, "logStatusError", why); m->phase = FAILED; return fmi2Error; }
    m->phase = STEPPING;
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c) {
    Instance *m = c;
    if (!m) return fmi2Error;
    m->phase = TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c) {
    Instance *m = c;
    if (!m) return fmi2Error;
    for (int i = 0; i < N_STRING; i++) { free(m->s[i]); m->s[i] = NULL; }
    model_defaults(m);
    m->terminated = 0;
    m->time = 0;
    m->phase = INSTANTIATED;
    return fmi2OK;
}

/* -- getters and setters ------------------------------------------------------------------------- */
#define CHECK_VRS(count)                                                                              \
    for (size_t k = 0; k < nvr; k++)                                                                  \
        if (vr[k] >= (count)) { say(m, fmi2Error, "logStatusError", "unknown value reference"); return fmi2Error; }

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
    Instance *m = c;
    if (!m) return fmi2Error;
#ifdef GET_HOOK
    GET_HOOK(m);                  /* a model that misbehaves when read (the crashing test models) */
#endif
    CHECK_VRS(N_REAL)
    for (size_t k = 0; k < nvr; k++) value[k] = m->r[vr[k]];
    return fmi2OK;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[]) {
    Instance *m = c;
    if (!m) return fmi2Error;
    CHECK_VRS(N_INTEGER)
    for (size_t k = 0; k < nvr; k++) value[k] = m->i[vr[k]];
    return fmi2OK;
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[]) {
    Instance *m = c;
    if (!m) return fmi2Error;
    CHECK_VRS(N_BOOLEAN)
    for (size_t k = 0; k < nvr; k++) value[k] = m->b[vr[k]];
    return fmi2OK;
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
    Instance *m = c;
    if (!m) return fmi2Error;
    CHECK_VRS(N_STRING)
    for (size_t k = 0; k < nvr; k++) value[k] = m->s[vr[k]] ? m->s[vr[k]] : "";
    return fmi2OK;
}

static int settable(Instance *m, char type, fmi2ValueReference vr) {
    int how = model_settable(type, vr);       /* 0: not settable, 1: parameter (before stepping), 2: input */
    if (how == 2) return 1;
    if (how == 1 && (m->phase == INSTANTIATED || m->phase == INITIALIZATION)) return 1;
    say(m, fmi2Error, "logStatusError", how == 1 ? "a fixed parameter cannot be set now" : "not settable");
    return 0;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
    Instance *m = c;
    if (!m) return fmi2Error;
    CHECK_VRS(N_REAL)
    for (size_t k = 0; k < nvr; k++) if (!settable(m, 'r', vr[k])) return fmi2Error;
    for (size_t k = 0; k < nvr; k++) m->r[vr[k]] = value[k];
    return fmi2OK;
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[]) {
    Instance *m = c;
    if (!m) return fmi2Error;
    CHECK_VRS(N_INTEGER)
    for (size_t k = 0; k < nvr; k++) if (!settable(m, 'i', vr[k])) return fmi2Error;
    for (size_t k = 0; k < nvr; k++) m->i[vr[k]] = value[k];
    return fmi2OK;
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[]) {
    Instance *m = c;
    if (!m) return fmi2Error;
    CHECK_VRS(N_BOOLEAN)
    for (size_t k = 0; k < nvr; k++) if (!settable(m, 'b', vr[k])) return fmi2Error;
    for (size_t k = 0; k < nvr; k++) m->b[vr[k]] = value[k] ? 1 : 0;
    return fmi2OK;
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[]) {
    Instance *m = c;
    if (!m) return fmi2Error;
    CHECK_VRS(N_STRING)
    for (size_t k = 0; k < nvr; k++) if (!settable(m, 's', vr[k])) return fmi2Error;
    for (size_t k = 0; k < nvr; k++) { free(m->s[vr[k]]); m->s[vr[k]] = strdup(value[k] ? value[k] : ""); }
    return fmi2OK;
}

/* -- stepping ------------------------------------------------------------------------------------ */
fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean no_prior) {
    Instance *m = c;
    (void)no_prior;
    if (!m || m->phase != STEPPING || !(h > 0)) return fmi2Error;
    if (fabs(t - m->time) > 1e-9 * (1 + fabs(t))) { say(m, fmi2Error, "logStatusError", "time does not continue"); return fmi2Error; }
    fmi2Status status = (fmi2Status)model_step(m, t, h);
    if (status == fmi2OK || status == fmi2Warning) m->time = t + h;
    return status;
}

fmi2Status fmi2CancelStep(fmi2Component c) { (void)c; return fmi2Error; }

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value) {
    (void)c; (void)s; (void)value; return fmi2Discard;
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
    Instance *m = c;
    if (!m || s != fmi2LastSuccessfulTime) return fmi2Discard;
    *value = m->time;
    return fmi2OK;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value) {
    (void)c; (void)s; (void)value; return fmi2Discard;
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) {
    Instance *m = c;
    if (!m || s != fmi2Terminated) return fmi2Discard;
    *value = m->terminated ? fmi2True : fmi2False;
    return fmi2OK;
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value) {
    (void)c; (void)s; (void)value; return fmi2Discard;
}

/* -- not provided (the modelDescriptions say so) -------------------------------------------------- */
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s) { (void)c; (void)s; return fmi2Error; }
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) { (void)c; (void)s; return fmi2Error; }
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s) { (void)c; (void)s; return fmi2Error; }
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *n) {
    (void)c; (void)s; (void)n; return fmi2Error;
}
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n) {
    (void)c; (void)s; (void)b; (void)n; return fmi2Error;
}
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate *s) {
    (void)c; (void)b; (void)n; (void)s; return fmi2Error;
}
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                        const fmi2ValueReference z[], size_t nz, const fmi2Real dz[],
                                        fmi2Real du[]) {
    (void)c; (void)u; (void)nu; (void)z; (void)nz; (void)dz; (void)du; return fmi2Error;
}
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    (void)c; (void)vr; (void)n; (void)order; (void)value; return fmi2Error;
}
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                        const fmi2Integer order[], fmi2Real value[]) {
    (void)c; (void)vr; (void)n; (void)order; (void)value; return fmi2Error;
}
