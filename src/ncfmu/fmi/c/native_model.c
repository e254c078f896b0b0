/*
 * ncfmu: a native model behind the model interface (model.h, section 1), table-driven.
 *
 * The model's C file gives its equations (model.h, section 2: model_init, model_step, model_restore
 * over ``values[vr]`` and its ModelState); the generated model_vars.h its variables, from the model's Python
 * ports. This file keeps the values, undoes a failed step, and makes, checks and serializes the FMU states
 * (plain data, in a versioned format checked against the model and its build).
 */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2_machine.h"
#include "model.h"
#define NCFMU_VAR_TABLE
#include "model_vars.h"

const char FMU_MODEL_GUID[] = MODEL_GUID;
const char FMU_MODEL_IDENTIFIER[] = MODEL_IDENTIFIER;

struct Model {
    const Fmi2Log *log;
    double values[NVARS];
    ModelState *state;
    ModelState *before;                 /* the model before the step in progress: a failed step is undone */
    unsigned char *bytes;               /* the last serialized state */
    int initializing;                   /* in initialization mode: the outputs follow the parameters */
};

typedef struct {                        /* an FMU state: the values and the model's state record */
    double values[NVARS];
    int initializing;
    unsigned char model[];              /* model_state_size() bytes */
} Snapshot;

static void set_defaults(Model *m)
{
    for (unsigned vr = 0; vr < NVARS; vr++) m->values[vr] = MODEL_VARS[vr].start;
    memset(m->state, 0, model_state_size());
    m->initializing = 0;
}

Model *fmu_model_new(const char *call, const char *name, const char *resources, int visible, const Fmi2Log *log)
{
    (void)name; (void)resources; (void)visible;    /* the model needs nothing from its resources */
    Model *m = calloc(1, sizeof *m);
    if (m) {
        m->log = log;
        m->state = calloc(1, model_state_size());
        m->before = calloc(1, model_state_size());
    }
    if (!m || !m->state || !m->before) {
        FMI2_SAY(log, ModelError, "logStatusError", "%s: out of memory", call);
        if (m) { free(m->state); free(m->before); free(m); }
        return NULL;
    }
    set_defaults(m);
    return m;
}

void fmu_model_free(Model *m)
{
    free(m->state);
    free(m->before);
    free(m->bytes);
    free(m);
}

const VarInfo *fmu_model_variables(Model *m, unsigned *n)
{
    (void)m;
    *n = NVARS;
    return MODEL_VARS;
}

int fmu_model_reset(Model *m, const char *call)
{
    (void)call;
    set_defaults(m);
    return 0;
}

ModelStatus fmu_model_setup_experiment(Model *m, const char *call, int tolerance_defined, double tolerance, double start,
                                      int stop_defined, double stop)
{
    (void)m; (void)tolerance_defined; (void)tolerance; (void)start; (void)stop_defined; (void)stop;
    return ModelOK;
}

ModelStatus fmu_model_enter_initialization(Model *m, const char *call)
{
    (void)call;
    /* Outputs are initial unknowns: compute them now when the parameters allow (quietly; the parameters may
     * still change, and are judged at fmi2ExitInitializationMode). */
    model_init(m->values, m->state, NULL);
    m->initializing = 1;
    return ModelOK;
}

ModelStatus fmu_model_exit_initialization(Model *m, const char *call)
{
    (void)call;
    if (model_init(m->values, m->state, m->log) != 0) return ModelError;     /* stays in init: fix and retry */
    m->initializing = 0;
    return ModelOK;
}

ModelStatus fmu_model_terminate(Model *m, const char *call)
{
    (void)call;
    (void)m;
    return ModelOK;
}

ModelStatus fmu_model_do_step(Model *m, const char *call, double t, double h)
{
    (void)call;
    /* Tools count time in integer nanoseconds (libcosim) and their conversion to seconds differs in the
     * last bit from step to step; whole nanoseconds make every tool's step equal (as the Python FMUs'
     * adapter does), so the same SSP gives the same trajectories in every host. */
    double step = nearbyint(h * 1e9) * 1e-9;
    double outputs[NVARS];
    memcpy(outputs, m->values, sizeof outputs);
    memcpy(m->before, m->state, model_state_size());
    if (model_step(m->values, m->state, t, step, m->log) != 0) {
        memcpy(m->state, m->before, model_state_size());    /* the instance stays where it was */
        memcpy(m->values, outputs, sizeof outputs);
        return ModelError;
    }
    return ModelOK;
}

ModelStatus fmu_model_get(Model *m, const char *call, const unsigned vr[], size_t n, VarType type, void *values)
{
    (void)call;
    for (size_t k = 0; k < n; k++) {
        double x = m->values[vr[k]];
        if (type == V_REAL) ((double *)values)[k] = x;
        else if (type == V_INTEGER) ((int *)values)[k] = (int)x;
        else ((int *)values)[k] = x != 0.0;
    }
    return ModelOK;
}

ModelStatus fmu_model_set(Model *m, const char *call, const unsigned vr[], size_t n, VarType type,
                         const void *values)
{
    (void)call;
    int parameter = 0;
    for (size_t k = 0; k < n; k++) {
        m->values[vr[k]] = type == V_REAL ? ((const double *)values)[k] : (double)((const int *)values)[k];
        parameter |= MODEL_VARS[vr[k]].causality == V_PARAMETER;
    }
    /* A parameter set in initialization mode: the initial outputs (initial unknowns) follow it, when the
     * parameters allow (quietly: they are judged at fmi2ExitInitializationMode). */
    if (parameter && m->initializing) model_init(m->values, m->state, NULL);
    return ModelOK;
}

/* ---- FMU states -------------------------------------------------------------------------------------- */
static size_t snapshot_bytes(void) { return sizeof(Snapshot) + model_state_size(); }

void *fmu_model_state_take(Model *m, const char *call)
{
    Snapshot *s = calloc(1, snapshot_bytes());
    if (!s) {
        FMI2_SAY(m->log, ModelError, "logStatusError", "%s: out of memory", call);
        return NULL;
    }
    memcpy(s->values, m->values, sizeof s->values);
    memcpy(s->model, m->state, model_state_size());
    s->initializing = m->initializing;
    return s;
}

void fmu_model_state_free(Model *m, void *state)
{
    (void)m;
    free(state);
}

static int params_equal(const double *a, const double *b)
{
    for (unsigned vr = 0; vr < NVARS; vr++)
        if (MODEL_VARS[vr].causality == V_PARAMETER && memcmp(&a[vr], &b[vr], sizeof a[vr]) != 0) return 0;
    return 1;
}

/* A state record into the model; a record that does not pass model_restore leaves the model as it was. */
ModelStatus fmu_model_state_restore(Model *m, const char *call, void *state, int initialized)
{
    const Snapshot *s = state;
    double values[NVARS];
    memcpy(values, m->values, sizeof values);
    memcpy(m->before, m->state, model_state_size());
    /* The parameters were judged when this instance left initialization mode: a state with the same ones
     * needs no new judgement (the design check costs ~0.4 ms; a restore should cost a copy). */
    int judged = initialized && params_equal(values, s->values);
    memcpy(m->values, s->values, sizeof values);
    memcpy(m->state, s->model, model_state_size());
    if (model_restore(m->values, m->state, judged, m->log) != 0) {
        memcpy(m->values, values, sizeof values);
        memcpy(m->state, m->before, model_state_size());
        FMI2_SAY(m->log, ModelError, "logStatusError", "%s: the state was refused; the instance is unchanged", call);
        return ModelError;
    }
    m->initializing = s->initializing;
    return ModelOK;
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

const unsigned char *fmu_model_serialize(Model *m, const char *call, void *state, int phase, double time,
                                         size_t *size)
{
    const Snapshot *s = state;
    if (!m->bytes && !(m->bytes = malloc(ser_size()))) {
        FMI2_SAY(m->log, ModelError, "logStatusError", "%s: out of memory", call);
        return NULL;
    }
    SerHeader h;
    ser_header(&h);
    h.phase = phase;
    h.time = time;
    memcpy(m->bytes, &h, sizeof h);
    memcpy(m->bytes + sizeof h, s->values, NVARS * sizeof(double));
    memcpy(m->bytes + sizeof h + NVARS * sizeof(double), s->model, model_state_size());
    *size = ser_size();
    return m->bytes;
}

void *fmu_model_deserialize(Model *m, const char *call, const unsigned char *bytes, size_t size, int *phase,
                            double *time)
{
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
    Snapshot *s = NULL;
    if (!why && !(s = calloc(1, snapshot_bytes()))) why = "out of memory";
    if (!why) {
        memcpy(s->values, bytes + sizeof h, NVARS * sizeof(double));
        memcpy(s->model, bytes + sizeof h + NVARS * sizeof(double), model_state_size());
        s->initializing = h.phase == P_INIT;
        for (unsigned vr = 0; vr < NVARS && !why; vr++) {
            double x = s->values[vr];
            const VarInfo *v = &MODEL_VARS[vr];
            if (v->type == V_BOOLEAN && x != 0.0 && x != 1.0) why = "a Boolean that is neither 0 nor 1";
            else if (v->type == V_INTEGER && !(isfinite(x) && x == (double)(int32_t)x)) why = "an Integer out of range";
            else if (!fmi2_value_ok(m->log, v, x)) why = "a parameter outside its rule";
        }
    }
    if (!why) {
        /* Check the model's part now, on a scratch copy, so a bad state is refused here. */
        double values[NVARS];
        memcpy(values, s->values, sizeof values);
        ModelState *scratch = calloc(1, model_state_size());
        if (!scratch || (memcpy(scratch, s->model, model_state_size()), model_restore(values, scratch, 0, m->log) != 0))
            why = "the model's state is not consistent";
        free(scratch);
    }
    if (why) {
        free(s);
        FMI2_SAY(m->log, ModelError, "logStatusError", "%s: %zu bytes refused: %s", call, size, why);
        return NULL;
    }
    *phase = h.phase;
    *time = h.time;
    return s;
}
