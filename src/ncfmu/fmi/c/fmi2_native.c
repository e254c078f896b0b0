/*
 * ncfmu: the FMI 2.0 co-simulation layer of the native FMUs (ServoAxis), table-driven.
 *
 * The model (fmi2_model.h) supplies its equations; the generated model_vars.h its variables. This
 * file holds everything FMI: instances, the state machine (fmi2_machine.h, shared with the status
 * shim of the Python FMUs), value references checked against the table (unknown, wrong type, an
 * output, a fixed parameter after initialisation, a value outside the port's rule: fmi2Error naming
 * the variable, the value and the rule), and the FMU state (plain data, serialized in a versioned
 * format checked against the model and its build). No call reaches fmi2Fatal on bad input.
 *
 * Hosts hold opaque handles, not addresses (fmi2_machine.h, as the Python FMUs' binary does): a NULL,
 * freed, made-up or foreign instance or FMU-state handle is refused with fmi2Error, never dereferenced.
 * Every message this layer and the model log is an error or a warning: each reaches the host's logger
 * whatever the debug-logging setting.
 */
#define _GNU_SOURCE                     /* dladdr: the binary holds itself loaded while its instances live */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "fmi2_machine.h"
#include "fmi2_model.h"
#define NCFMU_VAR_TABLE
#include "model_vars.h"

/* ---- instances -------------------------------------------------------------------------------- */
typedef struct State State;

typedef struct {
    int phase;
    double next_time;                   /* where the next step starts: start time, last step's end, restored */
    char name[128];
    Fmi2Log log;
    fmi2CallbackFunctions cb;
    double values[NVARS];
    ModelState *model;
    ModelState *before;                 /* the model before the step in progress: a failed step is undone */
    State *states;                      /* the FMU states this instance handed out and not freed */
} Instance;

#define STATE_MAGIC 0x4e43534du          /* "NCSM": a live state record (never trusted from bytes) */
struct State {
    uint32_t magic;
    uintptr_t handle;                   /* what the host holds */
    Instance *owner;
    State *next;
    int phase;
    double next_time;
    double values[NVARS];
    unsigned char model[];              /* model_state_size() bytes */
};

static void *mem_alloc(Instance *i, size_t n)
{
    void *p = i->cb.allocateMemory ? i->cb.allocateMemory(1, n) : calloc(1, n);
    if (p) memset(p, 0, n);
    return p;
}

static void mem_free(Instance *i, void *p)
{
    if (!p) return;
    if (i->cb.freeMemory) i->cb.freeMemory(p); else free(p);
}

#define LOG(i) (&(i)->log)

/* The instance behind a host's handle; NULL for a NULL, freed, made-up or foreign one. */
static Instance *instance_of(fmi2Component c)
{
    return fmi2_instance_find(c, 0);
}

static void set_defaults(Instance *i)
{
    for (unsigned vr = 0; vr < NVARS; vr++) i->values[vr] = MODEL_VARS[vr].start;
}

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String resources,
                              const fmi2CallbackFunctions *cb, fmi2Boolean visible, fmi2Boolean logging)
{
    (void)visible; (void)logging;
    char dir[4096];                     /* the model needs nothing from its resources; the location is checked */
    if (!fmi2_instantiate_ok(cb, name, type, guid, MODEL_GUID, MODEL_IDENTIFIER, resources, dir, sizeof dir))
        return NULL;
    Instance tmp = {0};
    if (cb) tmp.cb = *cb;               /* no callbacks: calloc/free, and nobody to log to */
    Instance *i = mem_alloc(&tmp, sizeof *i);
    if (!i) return NULL;
    *i = tmp;
    i->model = mem_alloc(i, model_state_size());
    i->before = mem_alloc(i, model_state_size());
    snprintf(i->name, sizeof i->name, "%s", name);
    i->log.logger = i->cb.logger;
    i->log.env = i->cb.componentEnvironment;
    i->log.name = i->name;
    i->phase = P_INSTANTIATED;
    set_defaults(i);
    fmi2Component handle = i->model && i->before ? fmi2_instance_add(i) : NULL;
    if (!handle) {
        FMI2_SAY(LOG(i), fmi2Error, "error", "fmi2Instantiate: out of memory or of instance handles");
        mem_free(i, i->model); mem_free(i, i->before); mem_free(i, i);
    }
    return handle;
}

void fmi2FreeInstance(fmi2Component c)
{
    Instance *i = fmi2_instance_find(c, 1);
    if (!i) return;                     /* NULL, freed already, or not ours: nothing to do */
    for (State *s = i->states, *next; s; s = next) {
        next = s->next;
        s->magic = 0;
        mem_free(i, s);
    }
    mem_free(i, i->model);
    mem_free(i, i->before);
    fmi2CallbackFreeMemory free_memory = i->cb.freeMemory;
    if (free_memory) free_memory(i); else free(i);
    void *self = fmi2_library_release();
    if (self) dlclose(self);            /* the last thing done (a tail call): it may unmap this library */
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

/* Only the categories are checked: this FMU logs errors and warnings only, and those always. */
fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String categories[])
{
    Instance *i = instance_of(c);
    unsigned mask;
    (void)on;
    return i && fmi2_categories_ok(LOG(i), n, categories, &mask) ? fmi2OK : fmi2Error;
}

/* ---- the state machine ------------------------------------------------------------------------ */
#define ALLOWED(i, call, phases) \
    do { if (!(i)) return fmi2Error; if (!fmi2_allowed(LOG(i), (i)->phase, call, phases)) return fmi2Error; } while (0)

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tol_defined, fmi2Real tol, fmi2Real start,
                               fmi2Boolean stop_defined, fmi2Real stop)
{
    Instance *i = instance_of(c);
    (void)tol_defined; (void)tol;
    ALLOWED(i, "fmi2SetupExperiment", P_SETUP);
    if (!fmi2_experiment_ok(LOG(i), start, stop_defined, stop)) return fmi2Error;
    i->next_time = start;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    Instance *i = instance_of(c);
    ALLOWED(i, "fmi2EnterInitializationMode", P_SETUP);
    /* Outputs are initial unknowns: compute them now when the parameters allow (quietly; the
     * parameters may still change, and are judged at fmi2ExitInitializationMode). */
    model_init(i->values, i->model, NULL);
    i->phase = P_INIT;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    Instance *i = instance_of(c);
    ALLOWED(i, "fmi2ExitInitializationMode", P_INIT);
    if (model_init(i->values, i->model, LOG(i)) != 0) return fmi2Error;   /* stays in init: fix and retry */
    i->phase = P_STEP;
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c)
{
    Instance *i = instance_of(c);
    ALLOWED(i, "fmi2Terminate", P_STEP);
    i->phase = P_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c)
{
    Instance *i = instance_of(c);
    ALLOWED(i, "fmi2Reset", P_ANY);
    set_defaults(i);
    memset(i->model, 0, model_state_size());
    i->phase = P_INSTANTIATED;
    i->next_time = 0.0;
    return fmi2OK;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean no_set_prior_state)
{
    Instance *i = instance_of(c);
    (void)no_set_prior_state;
    ALLOWED(i, "fmi2DoStep", P_STEP);
    if (!fmi2_step_ok(LOG(i), t, h) || !fmi2_step_ns_ok(LOG(i), h) || !fmi2_continues_ok(LOG(i), i->next_time, t))
        return fmi2Error;
    /* Tools count time in integer nanoseconds (libcosim) and their conversion to seconds differs in the
     * last bit from step to step; whole nanoseconds make every tool's step equal (as the Python FMUs'
     * adapter does), so the same SSP gives the same trajectories in every host. */
    double step = nearbyint(h * 1e9) * 1e-9;
    double outputs[NVARS];
    memcpy(outputs, i->values, sizeof outputs);
    memcpy(i->before, i->model, model_state_size());
    if (model_step(i->values, i->model, t, step, LOG(i)) != 0) {
        memcpy(i->model, i->before, model_state_size());   /* the instance stays where it was */
        memcpy(i->values, outputs, sizeof outputs);
        return fmi2Error;
    }
    i->next_time = t + h;               /* the host's own arithmetic: its next step starts there */
    return fmi2OK;
}

fmi2Status fmi2CancelStep(fmi2Component c)
{
    Instance *i = instance_of(c);
    ALLOWED(i, "fmi2CancelStep", P_STEP);
    FMI2_SAY(LOG(i), fmi2Error, "error", "fmi2CancelStep: steps are synchronous, there is nothing to cancel");
    return fmi2Error;
}

/* ---- variables -------------------------------------------------------------------------------- */
static const char *type_name(VarType t)
{
    return t == V_REAL ? "Real" : t == V_INTEGER ? "Integer" : "Boolean";
}

/* 1 when every reference is a variable of ``type`` (and, for a set, settable now); else logs the first
 * offender and returns 0. */
static int refs_ok(Instance *i, const char *call, const fmi2ValueReference vr[], size_t n, VarType type, int set,
                   const void *values)
{
    if (n > 0 && (!vr || !values)) {
        FMI2_SAY(LOG(i), fmi2Error, "error", "%s: %zu values asked, but the %s array is NULL", call, n,
                 !vr ? "value reference" : "value");
        return 0;
    }
    for (size_t k = 0; k < n; k++) {
        const char *why = NULL;
        unsigned r = vr[k];
        if (r >= NVARS) why = "is not a variable of this FMU";
        else if (MODEL_VARS[r].type != type) why = "is not of this call's type";
        else if (set && MODEL_VARS[r].causality == V_OUTPUT) why = "is an output: it cannot be set";
        else if (set && MODEL_VARS[r].causality == V_PARAMETER && !MODEL_VARS[r].tunable && i->phase == P_STEP)
            why = "is a fixed parameter: it cannot be set after initialisation";
        if (why) {
            FMI2_SAY(LOG(i), fmi2Error, "error", "%s: value reference %u%s%s%s %s (%s call)", call, r,
                     r < NVARS ? " (" : "", r < NVARS ? MODEL_VARS[r].name : "", r < NVARS ? ")" : "", why,
                     type_name(type));
            return 0;
        }
    }
    return 1;
}

/* A parameter's value against its port's rule. */
static int value_ok(Instance *i, unsigned vr, double x)
{
    const VarInfo *v = &MODEL_VARS[vr];
    if (v->causality != V_PARAMETER || v->type == V_BOOLEAN) return 1;
    const char *rule = NULL;
    if (!isfinite(x)) rule = "must be finite";
    else if ((v->has_min && (x < v->min || (v->min_exclusive && x == v->min))) || (v->has_max && x > v->max))
        rule = v->rule;
    if (!rule) return 1;
    FMI2_SAY(LOG(i), fmi2Error, "error", "%s = %.17g: %s", v->name, x, rule);
    return 0;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[])
{
    Instance *i = instance_of(c);
    ALLOWED(i, "fmi2GetReal", P_GETTABLE);
    if (!refs_ok(i, "fmi2GetReal", vr, n, V_REAL, 0, v)) return fmi2Error;
    for (size_t k = 0; k < n; k++) v[k] = i->values[vr[k]];
    return fmi2OK;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[])
{
    Instance *i = instance_of(c);
    ALLOWED(i, "fmi2GetInteger", P_GETTABLE);
    if (!refs_ok(i, "fmi2GetInteger", vr, n, V_INTEGER, 0, v)) return fmi2Error;
    for (size_t k = 0; k < n; k++) v[k] = (fmi2Integer)i->values[vr[k]];
    return fmi2OK;
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[])
{
    Instance *i = instance_of(c);
    ALLOWED(i, "fmi2GetBoolean", P_GETTABLE);
    if (!refs_ok(i, "fmi2GetBoolean", vr, n, V_BOOLEAN, 0, v)) return fmi2Error;
    for (size_t k = 0; k < n; k++) v[k] = i->values[vr[k]] != 0.0 ? fmi2True : fmi2False;
    return fmi2OK;
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[])
{
    Instance *i = instance_of(c);
    (void)v;
    ALLOWED(i, "fmi2GetString", P_GETTABLE);
    if (n == 0) return fmi2OK;
    FMI2_SAY(LOG(i), fmi2Error, "error", "fmi2GetString: value reference %u is not a variable of this FMU "
             "(it has no String variables)", vr ? vr[0] : 0u);
    return fmi2Error;
}

/* A parameter set in initialization mode: the initial outputs (initial unknowns) follow it, when the
 * parameters allow (quietly: they are judged at fmi2ExitInitializationMode). */
static void parameters_changed(Instance *i, const fmi2ValueReference vr[], size_t n)
{
    if (i->phase != P_INIT) return;
    for (size_t k = 0; k < n; k++)
        if (MODEL_VARS[vr[k]].causality == V_PARAMETER) { model_init(i->values, i->model, NULL); return; }
}

/* Sets are all-or-nothing: every value is checked before any is stored. */
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real v[])
{
    Instance *i = instance_of(c);
    ALLOWED(i, "fmi2SetReal", P_SETTABLE);
    if (!refs_ok(i, "fmi2SetReal", vr, n, V_REAL, 1, v)) return fmi2Error;
    for (size_t k = 0; k < n; k++)
        if (!value_ok(i, vr[k], v[k])) return fmi2Error;
    for (size_t k = 0; k < n; k++) i->values[vr[k]] = v[k];
    parameters_changed(i, vr, n);
    return fmi2OK;
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[])
{
    Instance *i = instance_of(c);
    ALLOWED(i, "fmi2SetInteger", P_SETTABLE);
    if (!refs_ok(i, "fmi2SetInteger", vr, n, V_INTEGER, 1, v)) return fmi2Error;
    for (size_t k = 0; k < n; k++)
        if (!value_ok(i, vr[k], (double)v[k])) return fmi2Error;
    for (size_t k = 0; k < n; k++) i->values[vr[k]] = (double)v[k];
    parameters_changed(i, vr, n);
    return fmi2OK;
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[])
{
    Instance *i = instance_of(c);
    ALLOWED(i, "fmi2SetBoolean", P_SETTABLE);
    if (!refs_ok(i, "fmi2SetBoolean", vr, n, V_BOOLEAN, 1, v)) return fmi2Error;
    for (size_t k = 0; k < n; k++) i->values[vr[k]] = v[k] ? 1.0 : 0.0;
    parameters_changed(i, vr, n);
    return fmi2OK;
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String v[])
{
    Instance *i = instance_of(c);
    (void)v;
    ALLOWED(i, "fmi2SetString", P_SETTABLE);
    if (n == 0) return fmi2OK;
    FMI2_SAY(LOG(i), fmi2Error, "error", "fmi2SetString: value reference %u is not a variable of this FMU "
             "(it has no String variables)", vr ? vr[0] : 0u);
    return fmi2Error;
}

/* ---- FMU state -------------------------------------------------------------------------------- */
static size_t state_bytes(void) { return sizeof(State) + model_state_size(); }

/* The state behind handle ``s`` if this instance handed it out and it is not freed; else NULL. */
static State *live_state(Instance *i, fmi2FMUstate s)
{
    for (State *k = i->states; s && k; k = k->next)
        if (k->handle == (uintptr_t)s) return k;
    return NULL;
}

/* ``s`` (just made) becomes one of this instance's live states; 0 (and ``s`` freed) when no handle is left. */
static int state_add(Instance *i, State *s, const char *call)
{
    s->handle = fmi2_state_handle();
    if (!s->handle) {
        FMI2_SAY(LOG(i), fmi2Error, "error", "%s: no new FMU-state handle can be made", call);
        mem_free(i, s);
        return 0;
    }
    s->magic = STATE_MAGIC;
    s->owner = i;
    s->next = i->states;
    i->states = s;
    return 1;
}

static void capture(Instance *i, State *s)
{
    s->phase = i->phase;
    s->next_time = i->next_time;
    memcpy(s->values, i->values, sizeof s->values);
    memcpy(s->model, i->model, model_state_size());
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *out)
{
    Instance *i = instance_of(c);
    ALLOWED(i, "fmi2GetFMUstate", P_ANY);
    if (!out) {
        FMI2_SAY(LOG(i), fmi2Error, "error", "fmi2GetFMUstate: the FMUstate pointer is NULL");
        return fmi2Error;
    }
    State *s = *out ? live_state(i, *out) : NULL;       /* FMI: a given state is overwritten */
    if (*out && !s) {
        FMI2_SAY(LOG(i), fmi2Error, "error", "fmi2GetFMUstate: %p is not a live FMU state of this instance "
                 "(freed, of another instance or FMU, or never made)", *out);
        return fmi2Error;
    }
    if (!s) {
        s = mem_alloc(i, state_bytes());
        if (!s) {
            FMI2_SAY(LOG(i), fmi2Error, "error", "fmi2GetFMUstate: out of memory");
            return fmi2Error;
        }
        if (!state_add(i, s, "fmi2GetFMUstate")) return fmi2Error;
    }
    capture(i, s);
    *out = (fmi2FMUstate)s->handle;
    return fmi2OK;
}

static int params_equal(const double *a, const double *b)
{
    for (unsigned vr = 0; vr < NVARS; vr++)
        if (MODEL_VARS[vr].causality == V_PARAMETER && memcmp(&a[vr], &b[vr], sizeof a[vr]) != 0) return 0;
    return 1;
}

/* Put a state record into the instance; a record that does not pass model_restore leaves the
 * instance as it was. */
static fmi2Status restore(Instance *i, const State *s, const char *call)
{
    double values[NVARS];
    memcpy(values, i->values, sizeof values);
    unsigned char *saved = mem_alloc(i, model_state_size());
    if (!saved) return fmi2Error;
    memcpy(saved, i->model, model_state_size());
    /* The parameters were judged when this instance left initialization mode: a state with the same ones
     * needs no new judgement (the design check costs ~0.4 ms; a restore should cost a copy). */
    int judged = (i->phase == P_STEP || i->phase == P_TERMINATED) && params_equal(values, s->values);
    memcpy(i->values, s->values, sizeof values);
    memcpy(i->model, s->model, model_state_size());
    if (model_restore(i->values, i->model, judged, LOG(i)) != 0) {
        memcpy(i->values, values, sizeof values);
        memcpy(i->model, saved, model_state_size());
        mem_free(i, saved);
        FMI2_SAY(LOG(i), fmi2Error, "error", "%s: the state was refused; the instance is unchanged", call);
        return fmi2Error;
    }
    mem_free(i, saved);
    i->phase = s->phase;
    i->next_time = s->next_time;        /* steps go on from the state's time */
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state)
{
    Instance *i = instance_of(c);
    ALLOWED(i, "fmi2SetFMUstate", P_ANY);
    State *s = live_state(i, state);
    if (!s) {
        FMI2_SAY(LOG(i), fmi2Error, "error", "fmi2SetFMUstate: %p is not a live FMU state of this instance "
                 "(freed, of another instance or FMU, or never made)", state);
        return fmi2Error;
    }
    return restore(i, s, "fmi2SetFMUstate");
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    Instance *i = instance_of(c);
    if (!i) return fmi2Error;
    if (!state || !*state) return fmi2OK;
    for (State **p = &i->states; *p; p = &(*p)->next) {
        if ((*p)->handle == (uintptr_t)*state) {
            State *s = *p;
            *p = s->next;
            s->magic = 0;
            mem_free(i, s);
            *state = NULL;
            return fmi2OK;
        }
    }
    FMI2_SAY(LOG(i), fmi2Error, "error", "fmi2FreeFMUstate: %p is not a live FMU state of this instance "
             "(freed twice?)", *state);
    return fmi2Error;
}

/* The serialized form: a header that names the format, the model and its build, then the plain data.
 *   "NCFMU-FMUSTATE-1\0" | model identifier [32] | build [64] | u32 nvars | u32 model bytes |
 *   i32 phase | f64 time (where its steps go on) | f64 values[nvars] | model state bytes        */
#define SER_MAGIC "NCFMU-FMUSTATE-1"
typedef struct {
    char magic[17];
    char model[32];
    char build[64];
    uint32_t nvars, model_bytes;
    int32_t phase;
    double time;
} SerHeader;

static size_t ser_size(void) { return sizeof(SerHeader) + NVARS * sizeof(double) + model_state_size(); }

static void ser_header(SerHeader *h)
{
    memset(h, 0, sizeof *h);
    memcpy(h->magic, SER_MAGIC, sizeof SER_MAGIC);
    snprintf(h->model, sizeof h->model, "%s", MODEL_IDENTIFIER);
    snprintf(h->build, sizeof h->build, "%s", MODEL_BUILD);
    h->nvars = NVARS;
    h->model_bytes = (uint32_t)model_state_size();
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t *size)
{
    Instance *i = instance_of(c);
    ALLOWED(i, "fmi2SerializedFMUstateSize", P_ANY);
    if (!size || !live_state(i, state)) {
        FMI2_SAY(LOG(i), fmi2Error, "error", "fmi2SerializedFMUstateSize: %p is not a live FMU state of this "
                 "instance", state);
        return fmi2Error;
    }
    *size = ser_size();
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[], size_t size)
{
    Instance *i = instance_of(c);
    ALLOWED(i, "fmi2SerializeFMUstate", P_ANY);
    State *s = live_state(i, state);
    if (!s || !bytes || size < ser_size()) {
        FMI2_SAY(LOG(i), fmi2Error, "error", "fmi2SerializeFMUstate: %s", !s ? "not a live FMU state of this "
                 "instance" : "the buffer is smaller than fmi2SerializedFMUstateSize said");
        return fmi2Error;
    }
    SerHeader h;
    ser_header(&h);
    h.phase = s->phase;
    h.time = s->next_time;
    memcpy(bytes, &h, sizeof h);
    memcpy(bytes + sizeof h, s->values, NVARS * sizeof(double));
    memcpy(bytes + sizeof h + NVARS * sizeof(double), s->model, model_state_size());
    return fmi2OK;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size, fmi2FMUstate *out)
{
    Instance *i = instance_of(c);
    ALLOWED(i, "fmi2DeSerializeFMUstate", P_ANY);
    if (!out) return fmi2Error;
    const char *why = NULL;
    SerHeader h, want;
    ser_header(&want);
    if (!bytes || size < sizeof h) why = "too short to be an FMU state";
    else {
        memcpy(&h, bytes, sizeof h);
        if (memcmp(h.magic, want.magic, sizeof h.magic) != 0) why = "not an ncfmu FMU state (format " SER_MAGIC ")";
        else if (memcmp(h.model, want.model, sizeof h.model) != 0) why = "a state of another model";
        else if (memcmp(h.build, want.build, sizeof h.build) != 0) why = "a state of another build of this model";
        else if (h.nvars != want.nvars || h.model_bytes != want.model_bytes || size != ser_size())
            why = "its size does not match this build";
        else if (!(h.phase == P_INSTANTIATED || h.phase == P_INIT || h.phase == P_STEP || h.phase == P_TERMINATED)
                 || !isfinite(h.time))
            why = "its FMI state is not one a state is taken in";
    }
    State *s = NULL;
    if (!why) {
        s = mem_alloc(i, state_bytes());
        if (!s) why = "out of memory";
    }
    if (!why) {
        memcpy(s->values, bytes + sizeof h, NVARS * sizeof(double));
        memcpy(s->model, bytes + sizeof h + NVARS * sizeof(double), model_state_size());
        s->phase = h.phase;
        s->next_time = h.time;
        for (unsigned vr = 0; vr < NVARS && !why; vr++) {
            double x = s->values[vr];
            const VarInfo *v = &MODEL_VARS[vr];
            if (v->type == V_BOOLEAN && x != 0.0 && x != 1.0) why = "a Boolean that is neither 0 nor 1";
            else if (v->type == V_INTEGER && !(isfinite(x) && x == (double)(int32_t)x)) why = "an Integer out of range";
            else if (v->causality == V_PARAMETER && !value_ok(i, vr, x)) why = "a parameter outside its rule";
        }
    }
    if (why) {
        if (s) mem_free(i, s);
        FMI2_SAY(LOG(i), fmi2Error, "error", "fmi2DeSerializeFMUstate: %zu bytes refused: %s", size, why);
        *out = NULL;
        return fmi2Error;
    }
    /* Check the model's part now, on a scratch instance copy, so a bad state is refused here. */
    double values[NVARS];
    memcpy(values, s->values, sizeof values);
    ModelState *scratch = mem_alloc(i, model_state_size());
    int bad = !scratch;
    if (scratch) {
        memcpy(scratch, s->model, model_state_size());
        bad = model_restore(values, scratch, 0, LOG(i)) != 0;
        mem_free(i, scratch);
    }
    if (bad) {
        mem_free(i, s);
        FMI2_SAY(LOG(i), fmi2Error, "error", "fmi2DeSerializeFMUstate: %zu bytes refused: the model's state "
                 "is not consistent", size);
        *out = NULL;
        return fmi2Error;
    }
    if (!state_add(i, s, "fmi2DeSerializeFMUstate")) { *out = NULL; return fmi2Error; }
    *out = (fmi2FMUstate)s->handle;
    return fmi2OK;
}

/* ---- what this FMU does not offer: refused with a reason, never Fatal --------------------------- */
static fmi2Status not_offered(fmi2Component c, const char *call, const char *why)
{
    Instance *i = instance_of(c);       /* NULL for a bad handle: nobody to tell */
    if (i) FMI2_SAY(LOG(i), fmi2Error, "error", "%s: %s", call, why);
    return fmi2Error;
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                        const fmi2ValueReference z[], size_t nz, const fmi2Real dv[], fmi2Real dz[])
{
    (void)u; (void)nu; (void)z; (void)nz; (void)dv; (void)dz;
    return not_offered(c, "fmi2GetDirectionalDerivative", "not provided (providesDirectionalDerivative=false)");
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                       const fmi2Integer order[], const fmi2Real v[])
{
    (void)vr; (void)n; (void)order; (void)v;
    return not_offered(c, "fmi2SetRealInputDerivatives", "not supported (canInterpolateInputs=false)");
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                        const fmi2Integer order[], fmi2Real v[])
{
    (void)vr; (void)n; (void)order; (void)v;
    return not_offered(c, "fmi2GetRealOutputDerivatives", "not supported (maxOutputDerivativeOrder=0)");
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind k, fmi2Real *v)
{
    Instance *i = instance_of(c);
    if (i && k == fmi2LastSuccessfulTime && v) { *v = i->next_time; return fmi2OK; }
    return not_offered(c, "fmi2GetRealStatus", "only fmi2LastSuccessfulTime is available");
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind k, fmi2Boolean *v)
{
    Instance *i = instance_of(c);
    if (i && k == fmi2Terminated && v) { *v = fmi2False; return fmi2OK; }
    return not_offered(c, "fmi2GetBooleanStatus", "only fmi2Terminated is available");
}

/* Steps are synchronous: there is no pending step whose status could be asked. */
#define NO_STATUS(name, type)                                                              \
    fmi2Status name(fmi2Component c, const fmi2StatusKind k, type *v)                      \
    {                                                                                      \
        (void)k; (void)v;                                                                  \
        return not_offered(c, #name, "steps are synchronous: there is no such status");    \
    }
NO_STATUS(fmi2GetStatus, fmi2Status)
NO_STATUS(fmi2GetIntegerStatus, fmi2Integer)
NO_STATUS(fmi2GetStringStatus, fmi2String)
