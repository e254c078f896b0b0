/*
 * ncfmu: the FMI 2.0 co-simulation state machine, written once.
 *
 * Included by ncfmu's FMI layer (fmi2_functions.c, over the model interface model.h: the Python
 * runtime of the controller FMUs, or a native model such as the ServoAxis) and by the models. It says which call is allowed in
 * which state, what a refused call returns (fmi2Error: the instance stays usable and freeable;
 * fmi2Fatal is kept for a broken instance, never for bad input), and checks what every FMU checks
 * the same way: experiment times, step sizes, UTF-8 strings. Cf. the Reference-FMUs' fmi2Functions.c.
 */
#ifndef NCFMU_FMI2_MACHINE_H
#define NCFMU_FMI2_MACHINE_H

#include <dlfcn.h>
#include <math.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include "fmi2Functions.h"

/* The states of an instance (FMI 2.0 co-simulation, section 4.2.4), as bits so a call lists the
 * states it is allowed in. A refused call leaves the instance in its state (it stays usable), so the
 * standard's error state is never entered. */
enum { P_INSTANTIATED = 1, P_INIT = 2, P_STEP = 4, P_TERMINATED = 8 };

/* Which calls are allowed where. */
#define P_SETUP      P_INSTANTIATED                                   /* fmi2SetupExperiment, EnterInit */
#define P_SETTABLE   (P_INSTANTIATED | P_INIT | P_STEP)              /* fmi2Set* (inputs in step mode) */
#define P_GETTABLE   (P_INIT | P_STEP | P_TERMINATED)                /* fmi2Get* */
#define P_ANY        (P_INSTANTIATED | P_INIT | P_STEP | P_TERMINATED) /* Reset, FMU-state calls */

static inline const char *fmi2_phase_name(int phase)
{
    return phase == P_INSTANTIATED ? "instantiated" : phase == P_INIT ? "initialization mode"
         : phase == P_STEP ? "step mode" : phase == P_TERMINATED ? "terminated" : "unknown";
}

#if defined(__GNUC__)
#define FMI2_UNUSED __attribute__((unused))     /* a model's file includes this header and uses none of it */
#define FMI2_PRINTF(f, a) __attribute__((format(printf, f, a)))
#else
#define FMI2_UNUSED
#define FMI2_PRINTF(f, a)
#endif

/* The log categories of ncfmu's FMUs (their modelDescriptions list them). Errors and warnings reach the
 * host's logger whatever the debug-logging setting; the rest only with debug logging on, in the chosen
 * categories (all when none is named). */
static const char *const FMI2_CATEGORIES[] FMI2_UNUSED = {"logStatusWarning", "logStatusDiscard", "logStatusError",
                                              "logStatusFatal", "logAll"};
#define FMI2_N_CATEGORIES (sizeof FMI2_CATEGORIES / sizeof *FMI2_CATEGORIES)

/* The host's logger, as an instance keeps it, with the host's debug-logging choice. */
typedef struct Fmi2Log {
    fmi2CallbackLogger logger;          /* an FMI 2.0 host's logger */
    fmi2ComponentEnvironment env;
    const char *name;                   /* the instance's name */
    int debug;                          /* debug logging on: messages below fmi2Warning are shown too */
    unsigned categories;                /* with debug on: the categories shown (bit k: FMI2_CATEGORIES[k]); 0: all */
    /* another FMI version's logger (FMI 3.0's logMessage), called instead of ``logger`` when set */
    void (*say)(const struct Fmi2Log *log, int status, const char *category, const char *text);
} Fmi2Log;

/* 1 when a message of ``status`` in ``category`` is shown: errors and warnings always, the rest with debug
 * logging on, in the chosen categories. */
static inline int fmi2_shown(const Fmi2Log *log, int status, const char *category)
{
    if (status >= fmi2Warning) return 1;
    if (!log->debug) return 0;
    if (log->categories == 0) return 1;
    for (unsigned b = 0; b < FMI2_N_CATEGORIES; b++)
        if ((log->categories & (1u << b)) && category && !strcmp(category, FMI2_CATEGORIES[b])) return 1;
    return 0;
}

/* One message, as text, to the host's logger when it is shown. */
static inline void fmi2_say_text(const Fmi2Log *log, int status, const char *category, const char *text)
{
    if (!log || !(log->logger || log->say) || !fmi2_shown(log, status, category)) return;
    if (log->say) log->say(log, status, category, text);
    else log->logger(log->env, log->name, (fmi2Status)status, category, "%s", text);
}

/* One message, formatted here (the host's logger gets plain text). */
static inline FMI2_PRINTF(4, 5) void fmi2_say(const Fmi2Log *log, int status, const char *category,
                                              const char *format, ...)
{
    if (!log || !(log->logger || log->say) || !fmi2_shown(log, status, category)) return;
    char small[1024], *text = small;
    va_list args;
    va_start(args, format);
    int n = vsnprintf(small, sizeof small, format, args);
    va_end(args);
    if (n >= (int)sizeof small && (text = malloc((size_t)n + 1)) != NULL) {
        va_start(args, format);
        vsnprintf(text, (size_t)n + 1, format, args);
        va_end(args);
    }
    fmi2_say_text(log, status, category, text ? text : small);
    if (text != small) free(text);
}

#define FMI2_SAY(log, status, category, ...) fmi2_say((log), (status), (category), __VA_ARGS__)

/* 1 when ``call`` is allowed in ``phase``; else logs why and returns 0 (the call returns fmi2Error). */
static inline int fmi2_allowed(const Fmi2Log *log, int phase, const char *call, int phases)
{
    if (phase & phases) return 1;
    FMI2_SAY(log, fmi2Error, "logStatusError", "%s: not allowed in the %s state (the FMI co-simulation state machine)",
             call, fmi2_phase_name(phase));
    return 0;
}

/* (``call``: the function the host called, named in the message -- fmi2SetupExperiment, fmi3DoStep, ...) */
static inline int fmi2_experiment_ok(const Fmi2Log *log, const char *call, double start, int stop_defined, double stop)
{
    if (isfinite(start) && (!stop_defined || (isfinite(stop) && stop >= start))) return 1;
    FMI2_SAY(log, fmi2Error, "logStatusError", "%s: startTime = %g, stopTime = %g: "
             "times must be finite and stopTime >= startTime", call, start, stop);
    return 0;
}

static inline int fmi2_step_ok(const Fmi2Log *log, const char *call, double t, double h)
{
    if (isfinite(t) && isfinite(h) && h > 0.0) return 1;
    FMI2_SAY(log, fmi2Error, "logStatusError", "%s: currentCommunicationPoint = %g, communicationStepSize = %g: "
             "the step size must be finite and > 0, the time finite", call, t, h);
    return 0;
}

/* 1 when the step, counted in whole nanoseconds as ncfmu's FMUs count it, is at least 1 ns. */
static inline int fmi2_step_ns_ok(const Fmi2Log *log, const char *call, double h)
{
    if (nearbyint(h * 1e9) > 0.0) return 1;
    FMI2_SAY(log, fmi2Error, "logStatusError", "%s: communicationStepSize = %g s: below 1 ns", call, h);
    return 0;
}

/* 1 when a step at ``t`` continues from ``next`` (where the last successful step ended, or the start time,
 * or the time of a restored state), as the Reference-FMUs require; within half a nanosecond (steps are
 * whole nanoseconds) and the rounding of the host's own time arithmetic. */
static inline int fmi2_continues_ok(const Fmi2Log *log, const char *call, double next, double t)
{
    if (fabs(t - next) <= 0.5e-9 + 1e-12 * fabs(next)) return 1;
    FMI2_SAY(log, fmi2Error, "logStatusError", "%s: currentCommunicationPoint = %.16g s, expected %.16g s (where the "
             "last step ended): an FMU steps on from where it is, or from a restored FMU state", call, t, next);
    return 0;
}

/* 1 when ``s`` is well-formed UTF-8 (no overlongs, no surrogates, at most U+10FFFF). */
static inline int fmi2_utf8_ok(const unsigned char *s)
{
    while (*s) {
        unsigned c = *s++;
        int more = c < 0x80 ? 0 : (c >> 5) == 6 ? 1 : (c >> 4) == 14 ? 2 : (c >> 3) == 30 ? 3 : -1;
        if (more < 0) return 0;
        unsigned cp = more == 0 ? c : more == 1 ? c & 0x1F : more == 2 ? c & 0x0F : c & 0x07;
        for (int k = 0; k < more; k++) {
            if ((*s & 0xC0) != 0x80) return 0;
            cp = (cp << 6) | (*s++ & 0x3F);
        }
        if ((more == 1 && cp < 0x80) || (more == 2 && cp < 0x800) || (more == 3 && cp < 0x10000)
            || cp > 0x10FFFF || (cp >= 0xD800 && cp <= 0xDFFF)) return 0;
    }
    return 1;
}

/* ---- opaque handles ------------------------------------------------------------------------------
 * A host holds handles, not addresses: an instance or an FMU state is a number never handed out twice in a
 * process, so a NULL, freed, made-up or foreign handle is recognised and refused with fmi2Error instead of
 * being dereferenced. A handle is never a valid address either ("NC" in the top bits makes it non-canonical
 * on 64-bit machines): a host that dereferences one faults at once instead of corrupting memory. The bits
 * below name the binary (12 bits mixed from where it was loaded: two FMUs in one process differ but for a
 * 1 in 4096 chance) and count up; when the count (2^32) runs out no new handle is made (the call fails)
 * rather than an old one reused.
 *
 * The binary keeps itself loaded exactly while instances made through it live: the first live instance
 * takes a reference to the library (dlopen of its own file, RTLD_NOLOAD), the last fmi2FreeInstance drops
 * it. So a host that closes the library while an instance lives on (ecos) keeps the instance and the
 * count, and a host that extracts the FMU anew for every run (fmpy.simulate_fmu) unloads each copy when it
 * is done with it (-z nodelete kept every copy mapped for the life of the process). A library loaded
 * again starts a new count under new binary bits (its load time is mixed in), so a handle of an earlier
 * load is refused as another binary's. */
#define FMI2_HANDLE_NC       ((uint64_t)0x4E43u << 48)
#define FMI2_HANDLE_INSTANCE ((uint64_t)0x1u << 44)
#define FMI2_HANDLE_STATE    ((uint64_t)0x2u << 44)

typedef struct { _Atomic uintptr_t handle; void *_Atomic object; } Fmi2Entry;

/* The live instances of this binary (hosts such as ecos instantiate, step and free on several threads).
 * Changed under ``lock`` only; every call of an instance looks its handle up, so the lookup takes no lock: a
 * sequence lock (``seq`` odd while the table changes; a lookup that saw it change looks again under the lock).
 * A table outgrown stays allocated (a lookup may still be reading it): a few entries, once per doubling. */
static struct {
    pthread_mutex_t lock;
    Fmi2Entry *_Atomic live;
    _Atomic size_t n;
    size_t cap;
    uint32_t made;
    uint64_t binary;                    /* the 12 bits naming this load of the binary, + 1 (0: not yet) */
    void *self;                         /* the reference to this library held while instances live */
    atomic_uint seq;
} fmi2_handles FMI2_UNUSED = {PTHREAD_MUTEX_INITIALIZER, NULL, 0, 0, 0, 0, NULL, 0};

/* A change of the live table begins / ends (called with the lock held). */
static inline void fmi2_table_change(void)
{
    atomic_fetch_add_explicit(&fmi2_handles.seq, 1, memory_order_relaxed);
    atomic_thread_fence(memory_order_release);
}

static inline void fmi2_table_changed(void)
{
    atomic_fetch_add_explicit(&fmi2_handles.seq, 1, memory_order_release);
}

/* A new handle of ``kind``; 0 when the count ran out. Called with fmi2_handles.lock held. */
static inline uintptr_t fmi2_handle_locked(uint64_t kind)
{
    if (sizeof(uintptr_t) < 8 || fmi2_handles.made == UINT32_MAX) return 0;
    if (!fmi2_handles.binary) {         /* where and when this binary was loaded, mixed */
        struct timespec now = {0, 0};
        clock_gettime(CLOCK_MONOTONIC, &now);
        uint64_t binary = (uint64_t)(uintptr_t)&fmi2_handles ^ ((uint64_t)now.tv_sec * 1000000000u + (uint64_t)now.tv_nsec);
        binary = (binary ^ (binary >> 30)) * 0xBF58476D1CE4E5B9ull;  /* (splitmix64's finaliser) */
        binary = (binary ^ (binary >> 27)) * 0x94D049BB133111EBull;
        fmi2_handles.binary = ((binary ^ (binary >> 31)) & 0xFFFu) + 1;
    }
    return (uintptr_t)(FMI2_HANDLE_NC | kind | (fmi2_handles.binary - 1) << 32 | ++fmi2_handles.made);
}

#ifdef _GNU_SOURCE
/* A reference to this library (the file ``fmi2_handles`` lives in), taken while it is loaded: NULL when
 * none can be taken (then the library's lifetime is the host's alone). Called with the lock held. */
static inline void fmi2_library_hold_locked(void)
{
    Dl_info info;
    if (!fmi2_handles.self && dladdr((void *)&fmi2_handles, &info) && info.dli_fname)
        fmi2_handles.self = dlopen(info.dli_fname, RTLD_NOW | RTLD_NOLOAD);
}

/* After an instance was freed: this library's reference when no instance lives any more (the caller drops
 * it with dlclose as the very last thing it does, a tail call: the library may be unmapped by it), else NULL. */
static inline void *fmi2_library_release(void)
{
    pthread_mutex_lock(&fmi2_handles.lock);
    void *self = atomic_load_explicit(&fmi2_handles.n, memory_order_relaxed) == 0 ? fmi2_handles.self : NULL;
    if (self) fmi2_handles.self = NULL;
    pthread_mutex_unlock(&fmi2_handles.lock);
    return self;
}
#else
#define fmi2_library_hold_locked() ((void)0)
#define fmi2_library_release() ((void *)0)
#endif

/* A new FMU-state handle; 0 when none can be made. */
static inline uintptr_t fmi2_state_handle(void)
{
    pthread_mutex_lock(&fmi2_handles.lock);
    uintptr_t h = fmi2_handle_locked(FMI2_HANDLE_STATE);
    pthread_mutex_unlock(&fmi2_handles.lock);
    return h;
}

/* Registers ``object`` as a live instance; its handle, or NULL when none can be made. */
static inline fmi2Component fmi2_instance_add(void *object)
{
    pthread_mutex_lock(&fmi2_handles.lock);
    uintptr_t h = 0;
    size_t n = atomic_load_explicit(&fmi2_handles.n, memory_order_relaxed);
    Fmi2Entry *live = atomic_load_explicit(&fmi2_handles.live, memory_order_relaxed);
    if (n == fmi2_handles.cap) {
        size_t cap = fmi2_handles.cap ? 2 * fmi2_handles.cap : 8;
        Fmi2Entry *grown = calloc(cap, sizeof *grown);      /* the old table is not freed: see fmi2_handles */
        if (grown) {
            for (size_t k = 0; k < n; k++) {
                atomic_init(&grown[k].handle, atomic_load_explicit(&live[k].handle, memory_order_relaxed));
                atomic_init(&grown[k].object, atomic_load_explicit(&live[k].object, memory_order_relaxed));
            }
            atomic_store_explicit(&fmi2_handles.live, grown, memory_order_release);
            live = grown;
            fmi2_handles.cap = cap;
        }
    }
    if (n < fmi2_handles.cap && (h = fmi2_handle_locked(FMI2_HANDLE_INSTANCE)) != 0) {
        fmi2_table_change();
        atomic_store_explicit(&live[n].handle, h, memory_order_relaxed);
        atomic_store_explicit(&live[n].object, object, memory_order_relaxed);
        atomic_store_explicit(&fmi2_handles.n, n + 1, memory_order_release);   /* after the table: see _seen */
        fmi2_table_changed();
        fmi2_library_hold_locked();
    }
    pthread_mutex_unlock(&fmi2_handles.lock);
    return (fmi2Component)h;
}

/* The instance behind ``c`` in the live table as it stands, without the lock: 1 with *found (NULL: not live) when
 * the table did not change while it was read, else 0 (look again under the lock). */
static inline int fmi2_instance_seen(fmi2Component c, void **found)
{
    unsigned before = atomic_load_explicit(&fmi2_handles.seq, memory_order_acquire);
    if (before & 1) return 0;
    /* the count before the table, each acquired (the count is stored with release after a grown table is): a
     * count read is never that of a table grown after the table read, so the entries read are within it */
    size_t n = atomic_load_explicit(&fmi2_handles.n, memory_order_acquire);
    Fmi2Entry *live = atomic_load_explicit(&fmi2_handles.live, memory_order_acquire);
    void *object = NULL;
    for (size_t k = 0; k < n; k++)
        if (atomic_load_explicit(&live[k].handle, memory_order_relaxed) == (uintptr_t)c) {
            object = atomic_load_explicit(&live[k].object, memory_order_relaxed);
            break;
        }
    atomic_thread_fence(memory_order_acquire);
    if (atomic_load_explicit(&fmi2_handles.seq, memory_order_relaxed) != before) return 0;
    *found = object;
    return 1;
}

/* The instance behind ``c``, or NULL (NULL, freed, made-up or another binary's handle). With ``remove``,
 * it is no longer live: the handle is refused from now on. */
static inline void *fmi2_instance_find(fmi2Component c, int remove)
{
    if (!c) return NULL;
    void *found = NULL;
    if (!remove && fmi2_instance_seen(c, &found)) return found;
    pthread_mutex_lock(&fmi2_handles.lock);
    Fmi2Entry *live = atomic_load_explicit(&fmi2_handles.live, memory_order_relaxed);
    size_t n = atomic_load_explicit(&fmi2_handles.n, memory_order_relaxed);
    for (size_t k = 0; k < n; k++) {
        if (atomic_load_explicit(&live[k].handle, memory_order_relaxed) != (uintptr_t)c) continue;
        found = atomic_load_explicit(&live[k].object, memory_order_relaxed);
        if (remove) {
            fmi2_table_change();
            atomic_store_explicit(&live[k].handle, atomic_load_explicit(&live[n - 1].handle, memory_order_relaxed),
                                  memory_order_relaxed);
            atomic_store_explicit(&live[k].object, atomic_load_explicit(&live[n - 1].object, memory_order_relaxed),
                                  memory_order_relaxed);
            atomic_store_explicit(&fmi2_handles.n, n - 1, memory_order_release);
            fmi2_table_changed();
        }
        break;
    }
    pthread_mutex_unlock(&fmi2_handles.lock);
    return found;
}

/* ---- fmi2Instantiate's arguments ---------------------------------------------------------------- */
/* ``file:`` URI -> path (percent-decoded, no trailing slash); 0 when it is not a file URI or too long. */
static inline int fmi2_uri_path(const char *uri, char *out, size_t size)
{
    const char *p;
    if (!strncmp(uri, "file:///", 8)) p = uri + 7;
    else if (!strncmp(uri, "file://localhost/", 17)) p = uri + 16;
    else if (!strncmp(uri, "file:/", 6)) p = uri + 5;
    else return 0;
    size_t n = 0;
    for (; *p && n + 1 < size; p++) {
        int hi, lo;
        if (*p == '%' && sscanf(p + 1, "%1x%1x", &hi, &lo) == 2) {
            if (hi == 0 && lo == 0) return 0;
            out[n++] = (char)(hi * 16 + lo);
            p += 2;
        } else {
            out[n++] = *p;
        }
    }
    if (*p) return 0;                                             /* too long */
    while (n > 1 && out[n - 1] == '/') n--;
    out[n] = 0;
    return 1;
}

/* The checks every ncfmu FMU makes of fmi2Instantiate's arguments: the instance name is UTF-8 text, a
 * co-simulation instance is asked, the GUID is this build's (``own_guid``), the resources location is a
 * file: URI of an existing folder (its path goes to ``dir``). 1 when all hold; else one log line (to
 * the host's logger, if it gave one) and 0: fmi2Instantiate returns NULL. */
static inline int fmi2_instantiate_ok(const fmi2CallbackFunctions *cb, fmi2String name, fmi2Type type,
                                      fmi2String guid, const char *own_guid, const char *model, fmi2String res,
                                      char *dir, size_t dir_size)
{
    int name_ok = name && fmi2_utf8_ok((const unsigned char *)name);
    Fmi2Log early_log = {.logger = cb ? cb->logger : NULL, .env = cb ? cb->componentEnvironment : NULL,
                         .name = name_ok ? name : ""};
    const Fmi2Log *early = &early_log;
    struct stat st;
    if (!name_ok) {
        FMI2_SAY(early, fmi2Error, "logStatusError", "fmi2Instantiate: instanceName is %s",
                 name ? "not valid UTF-8 text" : "NULL");
        return 0;
    }
    if (type != fmi2CoSimulation) {
        FMI2_SAY(early, fmi2Error, "logStatusError", "fmi2Instantiate: %s is a co-simulation FMU (fmuType = %d "
                 "asked, fmi2CoSimulation = %d)", model, (int)type, (int)fmi2CoSimulation);
        return 0;
    }
    if (!guid || strcmp(guid, own_guid) != 0) {
        FMI2_SAY(early, fmi2Error, "logStatusError", "fmi2Instantiate: GUID %s is not this FMU's (%s): the "
                 "modelDescription and the binary are from different builds", guid ? guid : "(NULL)", own_guid);
        return 0;
    }
    if (!res || !fmi2_uri_path(res, dir, dir_size) || stat(dir, &st) != 0 || !S_ISDIR(st.st_mode)) {
        FMI2_SAY(early, fmi2Error, "logStatusError", "fmi2Instantiate: fmuResourceLocation %s is not a file: URI "
                 "of an existing folder (the FMU's resources)", res ? res : "(NULL)");
        return 0;
    }
    return 1;
}

/* ---- fmi2SetDebugLogging ---------------------------------------------------------------------------- */
/* The categories named, as bits (bit k: FMI2_CATEGORIES[k]) in ``mask``; 0 (logged) for an unknown one. */
static inline int fmi2_categories_ok(const Fmi2Log *log, const char *call, size_t n, const fmi2String categories[],
                                     unsigned *mask)
{
    *mask = 0;
    if (n > 0 && !categories) {
        FMI2_SAY(log, fmi2Error, "logStatusError", "%s: %zu categories, but the array is NULL", call, n);
        return 0;
    }
    for (size_t k = 0; k < n; k++) {
        unsigned b = 0;
        while (b < FMI2_N_CATEGORIES && !(categories[k] && !strcmp(categories[k], FMI2_CATEGORIES[b]))) b++;
        if (b == FMI2_N_CATEGORIES) {
            FMI2_SAY(log, fmi2Error, "logStatusError", "%s: %s is not a log category of this "
                     "FMU (logStatusWarning, logStatusDiscard, logStatusError, logStatusFatal, logAll)", call,
                     categories[k] && fmi2_utf8_ok((const unsigned char *)categories[k]) ? categories[k] : "(not text)");
            return 0;
        }
        *mask |= 1u << b;
    }
    return 1;
}

#endif
