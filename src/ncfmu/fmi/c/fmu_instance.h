/*
 * ncfmu: an instance of an ncfmu FMU and the FMU states it hands out, written once for both FMI layers
 * (fmi2_functions.c, fmi3_functions.c): they differ in their types and names, not in what they keep or check.
 *
 * An instance is found through its opaque handle (fmi2_machine.h); a call is checked against the state
 * machine; value references against the model's table (model.h); FMU states are handles of the instance
 * that made them, any other is refused, never dereferenced. Statuses are model.h's ModelStatus, FMI's numbers
 * (OK 0, Warning 1, Discard 2, Error 3, Fatal 4: the same in FMI 2.0 and 3.0); every call names itself (``call``)
 * in what it logs.
 */
#ifndef NCFMU_FMU_INSTANCE_H
#define NCFMU_FMU_INSTANCE_H

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2_machine.h"
#include "model.h"

typedef struct {
    uintptr_t handle;
    void *model;                        /* the model's state */
    int phase;                          /* the instance's phase when it was taken: it comes back with the state */
    double time;                        /* where steps go on from it */
} FmuState;

typedef struct {
    int phase;
    double next_time;                   /* where the next step starts: start time, last step's end, restored */
    char name[128];
    Fmi2Log log;                        /* the host's logger; log.name points to name */
    void (*host_log)(void);             /* FMI 3.0: the host's logMessage (the layer's say hook casts it back) */
    Model *model;                       /* NULL after a failed reset: the instance can only be freed */
    FmuState *states;                   /* the FMU states this instance handed out and not freed */
    size_t n_states, cap_states;
} FmuInstance;

/* The instance behind ``c`` when ``call`` is allowed in its phase; else NULL (the call returns Error). A NULL,
 * freed, made-up or foreign handle has no logger to tell. */
static FMI2_UNUSED FmuInstance *fmu_checked(void *c, const char *call, int phases)
{
    FmuInstance *i = fmi2_instance_find((fmi2Component)c, 0);
    if (!i || !fmi2_allowed(&i->log, i->phase, call, phases)) return NULL;
    if (!i->model) {
        FMI2_SAY(&i->log, ModelError, "logStatusError", "%s: the instance has no model (its reset failed): free it",
                 call);
        return NULL;
    }
    return i;
}

/* The model of instance ``i`` (its name and log set by the layer) made and ``i`` registered: its handle, or
 * NULL (``i`` freed). */
static FMI2_UNUSED void *fmu_instance_start(FmuInstance *i, const char *call, const char *dir, int visible)
{
    i->phase = P_INSTANTIATED;
    i->model = fmu_model_new(call, i->name, dir, visible, &i->log);
    fmi2Component handle = i->model ? fmi2_instance_add(i) : NULL;
    if (i->model && !handle) {
        FMI2_SAY(&i->log, ModelError, "logStatusError", "%s: no new instance handle can be made", call);
        fmu_model_free(i->model);
    }
    if (!handle) free(i);
    return handle;
}

static FMI2_UNUSED void fmu_states_drop(FmuInstance *i)
{
    for (size_t k = 0; k < i->n_states; k++) fmu_model_state_free(i->model, i->states[k].model);
    free(i->states);
    i->states = NULL;
    i->n_states = i->cap_states = 0;
}

/* Frees the instance behind ``c`` (NULL, freed already, or not ours: nothing to do). Returns this library's
 * reference when it was the last instance: the caller dlcloses it as the very last thing it does (a tail call:
 * the library may be unmapped by it). */
static FMI2_UNUSED void *fmu_instance_free(void *c)
{
    FmuInstance *i = fmi2_instance_find((fmi2Component)c, 1);
    if (!i) return NULL;
    if (i->model) {
        fmu_states_drop(i);
        fmu_model_free(i->model);
    }
    free(i);
    return fmi2_library_release();
}

static FMI2_UNUSED int fmu_reset(void *c, const char *call)
{
    FmuInstance *i = fmu_checked(c, call, P_ANY);
    if (!i) return ModelError;
    if (fmu_model_reset(i->model, call) != 0) {
        fmu_states_drop(i);             /* logged; the instance can only be freed (every call refuses) */
        fmu_model_free(i->model);
        i->model = NULL;
        return ModelError;
    }
    i->phase = P_INSTANTIATED;
    i->next_time = 0.0;
    return ModelOK;
}

/* The experiment's times (checked) given to the model of ``i`` (already fmu_checked: NULL when refused). */
static FMI2_UNUSED int fmu_setup_experiment(FmuInstance *i, const char *call, int tol_defined, double tol,
                                            double start, int stop_defined, double stop)
{
    if (!i || !fmi2_experiment_ok(&i->log, call, start, stop_defined, stop)) return ModelError;
    int st = fmu_model_setup_experiment(i->model, call, tol_defined, tol, start, stop_defined, stop);
    if (st <= ModelWarning) i->next_time = start;
    return st;
}

/* ``call``, allowed in ``from``: the model does ``how``, and when it did, the instance is in ``to``. */
static FMI2_UNUSED int fmu_transition(void *c, const char *call, int from, int to, ModelStatus (*how)(Model *, const char *))
{
    FmuInstance *i = fmu_checked(c, call, from);
    if (!i) return ModelError;
    int st = how(i->model, call);
    if (st <= ModelWarning) i->phase = to;
    return st;
}

static FMI2_UNUSED int fmu_set_debug_logging(void *c, const char *call, int on, size_t n,
                                             const char *const categories[])
{
    FmuInstance *i = fmu_checked(c, call, P_ANY);
    if (!i) return ModelError;
    unsigned mask;
    if (!fmi2_categories_ok(&i->log, call, n, categories, &mask)) return ModelError;
    i->log.debug = on;
    i->log.categories = mask;
    return ModelOK;
}

/* A step from ``t`` by ``h``, checked (finite, >= 1 ns, continuing where the last one ended). */
static FMI2_UNUSED int fmu_do_step(void *c, const char *call, double t, double h, FmuInstance **out)
{
    FmuInstance *i = fmu_checked(c, call, P_STEP);
    *out = i;
    if (!i || !fmi2_step_ok(&i->log, call, t, h) || !fmi2_step_ns_ok(&i->log, call, h)
        || !fmi2_continues_ok(&i->log, call, i->next_time, t)) return ModelError;
    int st = fmu_model_do_step(i->model, call, t, h);
    if (st <= ModelWarning) i->next_time = t + h;   /* the host's own arithmetic: its next step starts there */
    return st;
}

/* What this FMU does not offer: refused with a reason, never Fatal. */
static FMI2_UNUSED int fmu_not_provided(void *c, const char *call, const char *why)
{
    FmuInstance *i = fmu_checked(c, call, P_ANY);
    if (!i) return ModelError;
    FMI2_SAY(&i->log, ModelError, "logStatusError", "%s: %s", call, why);
    return ModelError;
}

/* ---- variables ----------------------------------------------------------------------------------- */
/* 1 when every reference is a variable of ``type`` (and, for a set, settable now, its value within the rule, a
 * String UTF-8 text); else logs the first offender and returns 0. ``type_names``: the layer's names of the four
 * types, for the message. Reals and Integers come as double and int (both layers' types are those). */
static FMI2_UNUSED int fmu_refs_ok(FmuInstance *i, const char *call, const unsigned vr[], size_t n, VarType type,
                                   int set, const void *values, const char *const type_names[4])
{
    if (n > 0 && (!vr || !values)) {
        FMI2_SAY(&i->log, ModelError, "logStatusError", "%s: %zu values asked, but the %s array is NULL", call, n,
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
            FMI2_SAY(&i->log, ModelError, "logStatusError", "%s: value reference %u%s%s%s %s (a %s call)", call, r,
                     v ? " (" : "", v ? v->name : "", v ? ")" : "", why, type_names[type]);
            return 0;
        }
    }
    for (size_t k = 0; set && k < n; k++) {         /* sets are all-or-nothing: every value checked first */
        const VarInfo *v = &vars[vr[k]];
        if (type == V_STRING) {
            const char *s = ((const char *const *)values)[k];
            if (!s || !fmi2_utf8_ok((const unsigned char *)s)) {
                FMI2_SAY(&i->log, ModelError, "logStatusError", "%s: value reference %u (%s): %s", call, vr[k],
                         v->name, s ? "not valid UTF-8 text" : "a NULL string");
                return 0;
            }
        } else if (type == V_REAL ? !fmi2_value_ok(&i->log, v, ((const double *)values)[k])
                   : type == V_INTEGER ? !fmi2_value_ok(&i->log, v, (double)((const int *)values)[k]) : 0) {
            return 0;
        }
    }
    return 1;
}

/* Get/Set of ``n`` values of ``type``. The model takes Booleans as int 0/1; ``bool_size`` is the layer's
 * Boolean (sizeof(int): FMI 2.0, passed through on a get; 1: FMI 3.0's bool, converted both ways). */
static FMI2_UNUSED int fmu_get_values(void *c, const char *call, const unsigned vr[], size_t n, void *values,
                                      VarType type, size_t bool_size, const char *const type_names[4])
{
    FmuInstance *i = fmu_checked(c, call, P_GETTABLE);
    if (!i || !fmu_refs_ok(i, call, vr, n, type, 0, values, type_names)) return ModelError;
    if (n == 0) return ModelOK;
    if (type != V_BOOLEAN || bool_size == sizeof(int)) return fmu_model_get(i->model, call, vr, n, type, values);
    int small[32], *flags = n <= 32 ? small : malloc(n * sizeof *flags);   /* (no allocation in a step's gets) */
    if (!flags) return ModelError;
    int st = fmu_model_get(i->model, call, vr, n, type, flags);
    for (size_t k = 0; st <= ModelWarning && k < n; k++) ((unsigned char *)values)[k] = flags[k] != 0;
    if (flags != small) free(flags);
    return st;
}

static FMI2_UNUSED int fmu_set_values(void *c, const char *call, const unsigned vr[], size_t n, const void *values,
                                      VarType type, size_t bool_size, const char *const type_names[4])
{
    FmuInstance *i = fmu_checked(c, call, P_SETTABLE);
    if (!i || !fmu_refs_ok(i, call, vr, n, type, 1, values, type_names)) return ModelError;
    if (n == 0) return ModelOK;
    if (type != V_BOOLEAN) return fmu_model_set(i->model, call, vr, n, type, values);
    int small[32], *flags = n <= 32 ? small : malloc(n * sizeof *flags);   /* (no allocation in a step's sets) */
    if (!flags) return ModelError;
    for (size_t k = 0; k < n; k++)                  /* 0 or 1 */
        flags[k] = bool_size == sizeof(int) ? ((const int *)values)[k] != 0 : ((const unsigned char *)values)[k] != 0;
    int st = fmu_model_set(i->model, call, vr, n, type, flags);
    if (flags != small) free(flags);
    return st;
}

/* ---- FMU states: handles of this instance; any other is refused, never dereferenced ---------------- */
static FMI2_UNUSED FmuState *fmu_state_find(FmuInstance *i, const char *call, void *s)
{
    for (size_t k = 0; s && k < i->n_states; k++)
        if (i->states[k].handle == (uintptr_t)s) return &i->states[k];
    FMI2_SAY(&i->log, ModelError, "logStatusError", "%s: %p is not a live FMU state of this instance (freed, of "
             "another instance or FMU, or never made)", call, s);
    return NULL;
}

/* ``model`` (just made) becomes one of this instance's live states; its handle, or NULL (``model`` freed). */
static FMI2_UNUSED void *fmu_state_add(FmuInstance *i, const char *call, void *model, int phase, double time)
{
    if (i->n_states == i->cap_states) {
        size_t cap = i->cap_states ? 2 * i->cap_states : 8;
        FmuState *grown = realloc(i->states, cap * sizeof *grown);
        if (!grown) { fmu_model_state_free(i->model, model); return NULL; }
        i->states = grown;
        i->cap_states = cap;
    }
    uintptr_t handle = fmi2_state_handle();
    if (!handle) {
        FMI2_SAY(&i->log, ModelError, "logStatusError", "%s: no new FMU-state handle can be made", call);
        fmu_model_state_free(i->model, model);
        return NULL;
    }
    i->states[i->n_states++] = (FmuState){handle, model, phase, time};
    return (void *)handle;
}

static FMI2_UNUSED int fmu_get_state(void *c, const char *call, void **s)
{
    FmuInstance *i = fmu_checked(c, call, P_ANY);
    if (!i) return ModelError;
    if (!s) {
        FMI2_SAY(&i->log, ModelError, "logStatusError", "%s: the FMU-state pointer is NULL", call);
        return ModelError;
    }
    FmuState *old = *s ? fmu_state_find(i, call, *s) : NULL;
    if (*s && !old) return ModelError;
    void *model = fmu_model_state_take(i->model, call);
    if (!model) return ModelError;
    if (old) {                          /* FMI: a given state is overwritten */
        fmu_model_state_free(i->model, old->model);
        *old = (FmuState){old->handle, model, i->phase, i->next_time};
        return ModelOK;
    }
    *s = fmu_state_add(i, call, model, i->phase, i->next_time);
    return *s ? ModelOK : ModelError;
}

static FMI2_UNUSED int fmu_set_state(void *c, const char *call, void *s)
{
    FmuInstance *i = fmu_checked(c, call, P_ANY);
    FmuState *state = i ? fmu_state_find(i, call, s) : NULL;
    if (!state) return ModelError;
    int st = fmu_model_state_restore(i->model, call, state->model, i->phase == P_STEP || i->phase == P_TERMINATED);
    if (st > ModelWarning) return st;
    i->phase = state->phase;            /* the state's phase comes with it (the Reference-FMUs' setFMUState) */
    i->next_time = state->time;         /* steps go on from the state's time */
    return st;
}

static FMI2_UNUSED int fmu_free_state(void *c, const char *call, void **s)
{
    FmuInstance *i = fmu_checked(c, call, P_ANY);
    if (!i) return ModelError;
    if (!s || !*s) return ModelOK;
    FmuState *state = fmu_state_find(i, call, *s);
    if (!state) return ModelError;
    fmu_model_state_free(i->model, state->model);
    *state = i->states[--i->n_states];
    *s = NULL;
    return ModelOK;
}

/* ---- serialized FMU states: the model's bytes, sealed ------------------------------------------------
 * Whatever a model serializes (native_model.c's plain data, python_model.c's JSON from fmi/state.py) leaves the
 * FMU sealed by this layer, and comes back only through the seal:
 *
 *   "ncfmu-st" | u32 seal format version | u32 FMI major version (2, 3) | model identifier [64], NUL-padded |
 *   u64 size of the model's bytes | the model's bytes | u32 CRC-32 of every byte before it
 *
 * integers little-endian; the CRC-32 is IEEE 802.3's (reflected polynomial 0xEDB88320, as zlib's crc32, which
 * src/ncfmu/fmi/sealed_state.py uses for the same format). The CRC finds every single-bit flip and every burst
 * of up to 32 bits; it is computed at serialization and deserialization only, never per step. A state is refused
 * (the call returns Error, naming why) when its seal format version, checksum, model or FMI version is not this
 * FMU's: a state made by the FMI 2.0 build of a model is not one of its FMI 3.0 build (their modelDescriptions,
 * state machines and calls differ), and they do not exchange states. */
#ifndef FMU_FMI_MAJOR
#error "the FMI layer defines FMU_FMI_MAJOR (2 or 3) before it includes fmu_instance.h"
#endif
#define FMU_SEAL_MAGIC "ncfmu-st"
#define FMU_SEAL_MAGIC_SIZE 8
#define FMU_SEAL_VERSION 1u
#define FMU_SEAL_MODEL_SIZE 64
#define FMU_SEAL_HEADER_SIZE (FMU_SEAL_MAGIC_SIZE + 4 + 4 + FMU_SEAL_MODEL_SIZE + 8)
#define FMU_SEAL_SIZE (FMU_SEAL_HEADER_SIZE + 4)        /* what the seal adds to the model's bytes */

static uint32_t fmu_crc_table[256];
static pthread_once_t fmu_crc_once = PTHREAD_ONCE_INIT;

static void fmu_crc_init(void)
{
    for (uint32_t n = 0; n < 256; n++) {
        uint32_t c = n;
        for (int k = 0; k < 8; k++) c = (c & 1u) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
        fmu_crc_table[n] = c;
    }
}

/* The CRC-32 of ``n`` bytes (zlib's crc32(bytes)). */
static FMI2_UNUSED uint32_t fmu_crc32(const unsigned char *bytes, size_t n)
{
    pthread_once(&fmu_crc_once, fmu_crc_init);
    uint32_t c = 0xFFFFFFFFu;
    for (size_t k = 0; k < n; k++) c = fmu_crc_table[(c ^ bytes[k]) & 0xFFu] ^ (c >> 8);
    return c ^ 0xFFFFFFFFu;
}

static void fmu_put_le(unsigned char *at, uint64_t x, int bytes)
{
    for (int k = 0; k < bytes; k++) at[k] = (unsigned char)(x >> (8 * k));
}

static uint64_t fmu_get_le(const unsigned char *at, int bytes)
{
    uint64_t x = 0;
    for (int k = 0; k < bytes; k++) x |= (uint64_t)at[k] << (8 * k);
    return x;
}

/* The seal's header of this FMU for ``payload`` bytes of the model's. */
static void fmu_seal_header(unsigned char *h, uint64_t payload)
{
    memset(h, 0, FMU_SEAL_HEADER_SIZE);
    memcpy(h, FMU_SEAL_MAGIC, FMU_SEAL_MAGIC_SIZE);
    fmu_put_le(h + 8, FMU_SEAL_VERSION, 4);
    fmu_put_le(h + 12, FMU_FMI_MAJOR, 4);
    snprintf((char *)h + 16, FMU_SEAL_MODEL_SIZE, "%s", FMU_MODEL_IDENTIFIER);
    fmu_put_le(h + 16 + FMU_SEAL_MODEL_SIZE, payload, 8);
}

/* The model's bytes of a sealed state, or NULL with ``why`` (text for the log, in ``buf``) when the seal is not
 * this FMU's: too short, not sealed, another seal format, its size, its checksum, another model, another FMI
 * version -- checked in this order (the magic and the format version say how to read the rest). */
static const unsigned char *fmu_unseal(const unsigned char *b, size_t size, size_t *payload, char *buf,
                                       size_t buf_size)
{
    if (size < FMU_SEAL_SIZE) {
        snprintf(buf, buf_size, "too short to be an FMU state of this FMU (a sealed state has at least %d bytes)",
                 FMU_SEAL_SIZE);
        return NULL;
    }
    if (memcmp(b, FMU_SEAL_MAGIC, FMU_SEAL_MAGIC_SIZE) != 0) {
        snprintf(buf, buf_size, "not an ncfmu FMU state (no \"" FMU_SEAL_MAGIC "\" seal)");
        return NULL;
    }
    uint64_t version = fmu_get_le(b + 8, 4), fmi = fmu_get_le(b + 12, 4);
    uint64_t n = fmu_get_le(b + 16 + FMU_SEAL_MODEL_SIZE, 8);
    if (version != FMU_SEAL_VERSION) {
        snprintf(buf, buf_size, "seal format version %llu; this FMU reads version %u", (unsigned long long)version,
                 FMU_SEAL_VERSION);
        return NULL;
    }
    if (n != size - FMU_SEAL_SIZE) {
        snprintf(buf, buf_size, "its seal holds %llu bytes of state, the bytes given %zu", (unsigned long long)n,
                 size - FMU_SEAL_SIZE);
        return NULL;
    }
    uint32_t stored = (uint32_t)fmu_get_le(b + size - 4, 4), computed = fmu_crc32(b, size - 4);
    if (stored != computed) {
        snprintf(buf, buf_size, "checksum mismatch (CRC-32 %08x stored, %08x computed): the bytes were changed "
                 "after they were serialized", stored, computed);
        return NULL;
    }
    const char *model = (const char *)b + 16;
    size_t len = strnlen(model, FMU_SEAL_MODEL_SIZE);
    int named = len > 0 && len < FMU_SEAL_MODEL_SIZE;
    for (size_t k = 0; k < len && named; k++)
        named = (model[k] >= 'A' && model[k] <= 'Z') || (model[k] >= 'a' && model[k] <= 'z')
                || (model[k] >= '0' && model[k] <= '9') || model[k] == '_';
    if (!named || strcmp(model, FMU_MODEL_IDENTIFIER) != 0) {
        snprintf(buf, buf_size, "a state of model %.*s, not of this %s FMU", named ? (int)len : 18,
                 named ? model : "(not a model name)", FMU_MODEL_IDENTIFIER);
        return NULL;
    }
    if (fmi != FMU_FMI_MAJOR) {
        snprintf(buf, buf_size, "a state of the FMI %llu.0 build of %s; this is its FMI %d.0 build (states do not "
                 "cross FMI versions)", (unsigned long long)fmi, FMU_MODEL_IDENTIFIER, FMU_FMI_MAJOR);
        return NULL;
    }
    *payload = (size_t)n;
    return b + FMU_SEAL_HEADER_SIZE;
}

static FMI2_UNUSED int fmu_state_size(void *c, const char *call, void *s, size_t *size)
{
    FmuInstance *i = fmu_checked(c, call, P_ANY);
    FmuState *state = i ? fmu_state_find(i, call, s) : NULL;
    if (!state) return ModelError;
    if (!size) {
        FMI2_SAY(&i->log, ModelError, "logStatusError", "%s: the size pointer is NULL", call);
        return ModelError;
    }
    size_t payload = 0;
    if (!fmu_model_serialize(i->model, call, state->model, state->phase, state->time, &payload)) return ModelError;
    *size = payload + FMU_SEAL_SIZE;
    return ModelOK;
}

static FMI2_UNUSED int fmu_serialize(void *c, const char *call, void *s, unsigned char b[], size_t size)
{
    FmuInstance *i = fmu_checked(c, call, P_ANY);
    FmuState *state = i ? fmu_state_find(i, call, s) : NULL;
    if (!state) return ModelError;
    size_t payload = 0;
    const unsigned char *bytes = fmu_model_serialize(i->model, call, state->model, state->phase, state->time,
                                                     &payload);
    if (!bytes) return ModelError;
    size_t needed = payload + FMU_SEAL_SIZE;
    if (!b || size < needed) {
        FMI2_SAY(&i->log, ModelError, "logStatusError", "%s: %s (%zu bytes given, %zu needed)", call,
                 !b ? "the buffer is NULL" : "the buffer is too small", size, needed);
        return ModelError;
    }
    fmu_seal_header(b, payload);
    memcpy(b + FMU_SEAL_HEADER_SIZE, bytes, payload);
    fmu_put_le(b + needed - 4, fmu_crc32(b, needed - 4), 4);
    return ModelOK;
}

static FMI2_UNUSED int fmu_deserialize(void *c, const char *call, const unsigned char b[], size_t size, void **s)
{
    FmuInstance *i = fmu_checked(c, call, P_ANY);
    if (!i) return ModelError;
    if (!s || (size && !b)) {
        FMI2_SAY(&i->log, ModelError, "logStatusError", "%s: the %s is NULL", call,
                 !s ? "FMU-state pointer" : "byte array");
        return ModelError;
    }
    char why[256];
    size_t payload = 0;
    const unsigned char *bytes = fmu_unseal(b, size, &payload, why, sizeof why);
    if (!bytes) {
        FMI2_SAY(&i->log, ModelError, "logStatusError", "%s: %zu bytes refused: %s", call, size, why);
        *s = NULL;
        return ModelError;
    }
    int phase = -1;
    double time = 0.0;
    void *model = fmu_model_deserialize(i->model, call, bytes, payload, &phase, &time);
    if (!model) { *s = NULL; return ModelError; }   /* refused: the reason is in the log */
    if (phase != P_INSTANTIATED && phase != P_INIT && phase != P_STEP && phase != P_TERMINATED) {
        FMI2_SAY(&i->log, ModelError, "logStatusError", "%s: the state's phase (%d) is not one a state is taken in",
                 call, phase);            /* the models check it; this keeps a model's slip from the machine */
        fmu_model_state_free(i->model, model);
        *s = NULL;
        return ModelError;
    }
    *s = fmu_state_add(i, call, model, phase, time);
    return *s ? ModelOK : ModelError;
}

#endif
