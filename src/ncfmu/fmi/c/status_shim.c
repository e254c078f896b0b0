/*
 * ncfmu status shim: the FMU's binary in front of pythonfmu's export library.
 *
 * pythonfmu reports every Python exception as fmi2Fatal (the instance is gone). A parameter that
 * breaks a rule should be refused with fmi2Error (the importer may reset and try again). The
 * Python adapter therefore does not raise on a bad parameter when this shim is present; it logs the
 * reason and raises a flag that the shim reads after fmi2ExitInitializationMode through a reserved
 * Integer value reference, and turns into fmi2Error. Every other call is forwarded unchanged to
 * pythonfmu's library, loaded from next to this one (<modelIdentifier>.pythonfmu.so).
 *
 * Fast path: fmi2Get/Set{Real,Integer,Boolean} of plain inputs and outputs -- what a master calls
 * every step -- read and write the adapter's ``out`` and ``inputs`` dicts directly through the Python
 * C API instead of pythonfmu's generic path (method lookup by name, Python lists, log flushing).
 * The Python functions are looked up at run time; where they or the adapter are not found, or a value
 * reference is anything else, the call goes to pythonfmu unchanged. doStep and everything that may
 * log still go through pythonfmu.
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* The official FMI 2.0 headers (fmpy ships them; the builder passes -I<fmpy>/c-code), and the state
 * machine this shim shares with ncfmu's native FMUs. */
#include "fmi2Functions.h"
#include "fmi2_machine.h"

/* ---- the Python C API, resolved at run time ------------------------------------------------- */
typedef struct _object PyObject;
typedef int PyGILState_STATE;
typedef long Py_ssize_t_;
static struct {
    int ready;
    PyGILState_STATE (*GILEnsure)(void);
    void (*GILRelease)(PyGILState_STATE);
    PyObject *(*DictGetItem)(PyObject *, PyObject *);
    int (*DictSetItem)(PyObject *, PyObject *, PyObject *);
    int (*DictNext)(PyObject *, Py_ssize_t_ *, PyObject **, PyObject **);
    double (*FloatAs)(PyObject *);
    PyObject *(*FloatFrom)(double);
    long (*LongAs)(PyObject *);
    PyObject *(*LongFrom)(long);
    int (*IsTrue)(PyObject *);
    PyObject *(*BoolFrom)(long);
    PyObject *(*GetAttr)(PyObject *, const char *);
    PyObject *(*TupleGet)(PyObject *, Py_ssize_t_);
    PyObject *(*ImportAdd)(const char *);
    PyObject *(*CallMethod)(PyObject *, PyObject *, ...);
    PyObject *(*StrFrom)(const char *);
    Py_ssize_t_ (*Length)(PyObject *);
    PyObject *(*Occurred)(void);
    void (*Clear)(void);
    void (*IncRef)(PyObject *);
    void (*DecRef)(PyObject *);
    const char *(*Utf8)(PyObject *);
} py;

static int py_load(void)
{
    if (py.ready) return py.ready > 0;
    void *h = RTLD_DEFAULT;
#define L(field, name) if (!(py.field = (__typeof__(py.field))dlsym(h, name))) { py.ready = -1; return 0; }
    L(GILEnsure, "PyGILState_Ensure") L(GILRelease, "PyGILState_Release") L(DictGetItem, "PyDict_GetItem")
    L(DictSetItem, "PyDict_SetItem") L(DictNext, "PyDict_Next") L(FloatAs, "PyFloat_AsDouble")
    L(FloatFrom, "PyFloat_FromDouble") L(LongAs, "PyLong_AsLong") L(LongFrom, "PyLong_FromLong")
    L(IsTrue, "PyObject_IsTrue") L(BoolFrom, "PyBool_FromLong") L(GetAttr, "PyObject_GetAttrString")
    L(TupleGet, "PyTuple_GetItem") L(ImportAdd, "PyImport_AddModule") L(Occurred, "PyErr_Occurred")
    L(Clear, "PyErr_Clear") L(IncRef, "Py_IncRef") L(DecRef, "Py_DecRef") L(Utf8, "PyUnicode_AsUTF8")
    L(CallMethod, "PyObject_CallMethodObjArgs") L(StrFrom, "PyUnicode_FromString") L(Length, "PyObject_Length")
#undef L
    py.ready = 1;
    return 1;
}

/* ---- one record per instance: its FMI state, and the fast path to the adapter ---------------- */
typedef struct Inst {
    fmi2Component c;
    int phase;
    double last_time;                     /* end of the last successful doStep */
    char name[128];
    fmi2CallbackLogger logger;
    fmi2ComponentEnvironment env;
    struct Fast *fast;                    /* the fast path, once the adapter is found (NULL before) */
    void **states;                        /* the FMU states this instance handed out and not freed */
    size_t n_states, cap_states;
    struct Inst *next;
} Inst;
static Inst *inst_list = NULL;
/* Hosts such as ecos instantiate, step and free instances on several threads at once. */
static pthread_mutex_t inst_lock = PTHREAD_MUTEX_INITIALIZER;

static Inst *inst_find(fmi2Component c)
{
    pthread_mutex_lock(&inst_lock);
    Inst *found = NULL;
    for (Inst *i = inst_list; i; i = i->next)
        if (i->c == c) { found = i; break; }
    pthread_mutex_unlock(&inst_lock);
    return found;
}

static void fast_drop(fmi2Component c);

static void inst_drop(fmi2Component c)
{
    fast_drop(c);
    pthread_mutex_lock(&inst_lock);
    for (Inst **p = &inst_list; *p; p = &(*p)->next)
        if ((*p)->c == c) { Inst *i = *p; *p = i->next; free(i->states); free(i); break; }
    pthread_mutex_unlock(&inst_lock);
}

/* ---- the fast path: the adapter and its ports by value reference --------------------- */
enum { K_NONE = 0, K_REAL = 1, K_INTEGER = 2, K_BOOLEAN = 3 };
enum { C_OTHER = 0, C_INPUT = 1, C_OUTPUT = 2 };
typedef struct Fast {
    PyObject *slave;          /* the ControllerSlave (a reference held) */
    PyObject *inputs;         /* slave.inputs: the same dict for the instance's life */
    PyObject *queue;          /* slave.log_queue: pythonfmu's log list, flushed by any pythonfmu call */
    unsigned n;
    PyObject **names;         /* by value reference: the port's name (borrowed from slave._causality) */
    unsigned char *kind, *causality, *fixed;
} Fast;

static Fast *fast_find(fmi2Component c)
{
    Inst *i = inst_find(c);
    return i ? i->fast : NULL;
}

static void fast_drop(fmi2Component c)
{
    Inst *i = inst_find(c);
    Fast *f = i ? i->fast : NULL;
    if (!f) return;
    i->fast = NULL;
    if (py_load()) {
        PyGILState_STATE g = py.GILEnsure();
        py.DecRef(f->slave);
        py.DecRef(f->inputs);
        py.DecRef(f->queue);
        py.GILRelease(g);
    }
    free(f->names); free(f->kind); free(f->causality); free(f->fixed); free(f);
}

/* The adapter puts itself in module _ncfmu_fast (attribute "last") when pythonfmu creates it. */
static void fast_register(fmi2Component c, fmi2String instance_name)
{
    Inst *inst = inst_find(c);
    if (!inst || !py_load()) return;
    fast_drop(c);
    PyGILState_STATE g = py.GILEnsure();
    PyObject *mod = py.ImportAdd("_ncfmu_fast");                  /* borrowed */
    PyObject *slave = mod ? py.GetAttr(mod, "last") : NULL;        /* new */
    PyObject *caus = NULL, *inputs = NULL, *name = NULL;
    Fast *f = NULL;
    if (!slave) goto done;
    name = py.GetAttr(slave, "instance_name");
    if (!name || !py.Utf8(name) || strcmp(py.Utf8(name), instance_name) != 0) goto done;
    caus = py.GetAttr(slave, "_causality");
    inputs = py.GetAttr(slave, "inputs");
    PyObject *queue = py.GetAttr(slave, "log_queue");
    if (!caus || !inputs || !queue) { if (queue) py.DecRef(queue); goto done; }
    unsigned n = 0;
    Py_ssize_t_ pos = 0;
    PyObject *k, *v;
    while (py.DictNext(caus, &pos, &k, &v)) {
        long vr = py.LongAs(k);
        if (vr >= 0 && (unsigned)vr + 1 > n) n = (unsigned)vr + 1;
    }
    f = calloc(1, sizeof *f);
    f->names = calloc(n ? n : 1, sizeof(PyObject *));
    f->kind = calloc(n ? n : 1, 1);
    f->causality = calloc(n ? n : 1, 1);
    f->fixed = calloc(n ? n : 1, 1);
    f->n = n;
    pos = 0;
    while (py.DictNext(caus, &pos, &k, &v)) {
        long vr = py.LongAs(k);
        const char *c_s = py.Utf8(py.TupleGet(v, 0)), *k_s = py.Utf8(py.TupleGet(v, 1));
        if (vr < 0 || !c_s || !k_s) continue;
        f->names[vr] = py.TupleGet(v, 2);
        PyObject *variability = py.TupleGet(v, 3);
        const char *var_s = variability ? py.Utf8(variability) : NULL;
        if (!variability && py.Occurred()) py.Clear();
        f->fixed[vr] = var_s && !strcmp(var_s, "fixed") && !strcmp(c_s, "parameter");
        f->causality[vr] = !strcmp(c_s, "input") ? C_INPUT : !strcmp(c_s, "output") ? C_OUTPUT : C_OTHER;
        f->kind[vr] = !strcmp(k_s, "Real") ? K_REAL : !strcmp(k_s, "Integer") ? K_INTEGER
                    : !strcmp(k_s, "Boolean") ? K_BOOLEAN : K_NONE;
    }
    f->slave = slave; slave = NULL;                                /* keeps the names alive too */
    f->inputs = inputs; inputs = NULL;
    f->queue = queue;
    inst->fast = f;
done:
    if (py.Occurred()) py.Clear();
    if (slave) py.DecRef(slave);
    if (inputs) py.DecRef(inputs);
    if (caus) py.DecRef(caus);
    if (name) py.DecRef(name);
    py.GILRelease(g);
}

/* Reads: every vr an output of ``kind``; returns 0 to fall back to pythonfmu. */
static int fast_get(Fast *f, const fmi2ValueReference vr[], size_t n, int kind, void *values)
{
    if (!f) return 0;
    for (size_t i = 0; i < n; i++)
        if (vr[i] >= f->n || f->kind[vr[i]] != kind || f->causality[vr[i]] != C_OUTPUT) return 0;
    PyGILState_STATE g = py.GILEnsure();
    int ok = 0;
    PyObject *out = py.GetAttr(f->slave, "out");
    if (out) {
        ok = 1;
        for (size_t i = 0; i < n && ok; i++) {
            PyObject *v = py.DictGetItem(out, f->names[vr[i]]);
            if (!v) { ok = 0; break; }
            if (kind == K_REAL) ((fmi2Real *)values)[i] = py.FloatAs(v);
            else if (kind == K_INTEGER) ((fmi2Integer *)values)[i] = (fmi2Integer)py.LongAs(v);
            else ((fmi2Boolean *)values)[i] = py.IsTrue(v) > 0;
        }
        py.DecRef(out);
    }
    if (py.Occurred()) { py.Clear(); ok = 0; }
    py.GILRelease(g);
    return ok;
}

/* Writes: every vr an input of ``kind`` (tunable parameters go through pythonfmu: they retune). */
static int fast_set(Fast *f, const fmi2ValueReference vr[], size_t n, int kind, const void *values)
{
    if (!f) return 0;
    for (size_t i = 0; i < n; i++)
        if (vr[i] >= f->n || f->kind[vr[i]] != kind || f->causality[vr[i]] != C_INPUT) return 0;
    PyGILState_STATE g = py.GILEnsure();
    int ok = 1;
    for (size_t i = 0; i < n && ok; i++) {
        PyObject *v = kind == K_REAL ? py.FloatFrom(((const fmi2Real *)values)[i])
                    : kind == K_INTEGER ? py.LongFrom(((const fmi2Integer *)values)[i])
                    : py.BoolFrom(((const fmi2Boolean *)values)[i] != 0);
        if (!v || py.DictSetItem(f->inputs, f->names[vr[i]], v) != 0) ok = 0;
        if (v) py.DecRef(v);
    }
    if (py.Occurred()) { py.Clear(); ok = 0; }
    py.GILRelease(g);
    return ok;
}

/* doStep straight into the adapter: 1 done (status in *st), 0 fall back to pythonfmu. */
static PyObject *s_do_step = NULL, *s_failed = NULL;
static int fast_step(Fast *f, fmi2Real t, fmi2Real h, fmi2Status *st, int *flush)
{
    if (!f) return 0;
    PyGILState_STATE g = py.GILEnsure();
    if (!s_do_step) { s_do_step = py.StrFrom("do_step"); s_failed = py.StrFrom("step_failed"); }
    PyObject *pt = py.FloatFrom(t), *ph = py.FloatFrom(h);
    PyObject *r = (pt && ph) ? py.CallMethod(f->slave, s_do_step, pt, ph, NULL) : NULL;
    if (pt) py.DecRef(pt);
    if (ph) py.DecRef(ph);
    if (!r) {
        py.Clear();
        *st = fmi2Fatal;                      /* the adapter catches its own errors: this is not expected */
    } else {
        int good = py.IsTrue(r) > 0;
        py.DecRef(r);
        PyObject *failed = py.GetAttr(f->slave, "step_failed");
        *st = good ? fmi2OK : (failed && py.IsTrue(failed) > 0) ? fmi2Error : fmi2Discard;
        if (failed) py.DecRef(failed);
    }
    *flush = py.Length(f->queue) > 0;
    if (py.Occurred()) py.Clear();
    py.GILRelease(g);
    return 1;
}

/* ---- the FMI 2.0 co-simulation state machine, per instance -------------------------------------
 * pythonfmu checks no call against the state of the instance; the checks live here, in one place:
 * which call is allowed in which phase, a step size that is not a positive finite number, and the
 * time of the last successful step (fmi2LastSuccessfulTime). A refused call logs why (through the
 * host's logger) and returns fmi2Error; the instance stays usable (fmi2Reset) and freeable. */
/* 1 when ``call`` is allowed in the instance's phase (fmi2_machine.h); else logs and returns 0. */
static int allowed(Inst *i, const char *call, int phases)
{
    if (!i) return 0;                      /* NULL, freed, or not made here: never handed to pythonfmu */
    Fmi2Log log = {i->logger, i->env, i->name};
    return fmi2_allowed(&log, i->phase, call, phases);
}

static void inst_phase(fmi2Component c, int phase)
{
    Inst *i = inst_find(c);
    if (i) i->phase = phase;
}

/* Must match ncfmu.fmi.adapter.INIT_REFUSED_VR */
#define NCFMU_INIT_REFUSED_VR 2147483000u
/* Must match ncfmu.fmi.adapter.CALL_REFUSED_VR */
#define NCFMU_CALL_REFUSED_VR 2147483001u

/* ---- a Python runtime for native hosts ------------------------------------------------------------
 * pythonfmu's library does not link libpython: in a Python host the symbols are there, in a native
 * host (fmusim, ecos, libcosim) they are not. Before pythonfmu's library is loaded, the shim makes sure
 * a libpython is loaded with RTLD_GLOBAL, choosing, in this order:
 *   1. $NCFMU_LIBPYTHON (a path or a soname), and nothing else when it is set;
 *   2. the library recorded at build time in resources/ncfmu_python.txt (path, then its soname);
 * and starts the interpreter itself (then releases the GIL). pythonfmu then finds it initialised and
 * leaves it alone: it never runs Py_Finalize from a static destructor at process exit, where numpy's
 * and scipy's clean-up crashed native hosts (SIGSEGV/SIGABRT after the run). The interpreter lives
 * until the process ends. If no runtime loads, one message says so, once, and every instantiation
 * fails (fmi2Instantiate returns NULL). */
static char python_problem[1024] = "";

static int python_runtime(const char *fmu_binary)
{
    static int state = 0;                  /* 0 not tried, 1 ready, -1 failed */
    if (state) return state > 0;
    int (*is_init)(void) = (int (*)(void))dlsym(RTLD_DEFAULT, "Py_IsInitialized");
    if (is_init) { state = 1; return 1; }  /* a Python host: its interpreter */
    char recorded[3][1024] = {"", "", ""}, path[4096], tried[2048] = "";
    const char *env = getenv("NCFMU_LIBPYTHON");
    /* resources/ncfmu_python.txt, next to binaries/<platform>/ */
    snprintf(path, sizeof path, "%s", fmu_binary);
    for (int up = 0; up < 3; up++) { char *slash = strrchr(path, '/'); if (slash) *slash = 0; }
    size_t used = strlen(path);
    if (used + 32 < sizeof path) {
        strcat(path, "/resources/ncfmu_python.txt");
        FILE *f = fopen(path, "r");
        if (f) {
            for (int k = 0; k < 3 && fgets(recorded[k], sizeof recorded[k], f); k++)
                recorded[k][strcspn(recorded[k], "\r\n")] = 0;
            fclose(f);
        }
    }
    const char *candidates[3] = {env, env ? NULL : recorded[0], env ? NULL : recorded[1]};
    void *lib = NULL;
    for (int k = 0; k < 3 && !lib; k++) {
        if (!candidates[k] || !candidates[k][0]) continue;
        lib = dlopen(candidates[k], RTLD_NOW | RTLD_GLOBAL);
        size_t n = strlen(tried);
        snprintf(tried + n, sizeof tried - n, "%s%s", n ? ", " : "", candidates[k]);
    }
    if (!lib) {
        snprintf(python_problem, sizeof python_problem, "ncfmu: this FMU runs Python code and needs a Python "
                 "runtime (libpython); none could be loaded (tried: %s). Install that Python with its shared "
                 "library, or set NCFMU_LIBPYTHON to the path of a libpython3.x.so of the same version.",
                 tried[0] ? tried : "nothing: no NCFMU_LIBPYTHON and no resources/ncfmu_python.txt");
        fprintf(stderr, "%s\n", python_problem);
        state = -1;
        return 0;
    }
    is_init = (int (*)(void))dlsym(lib, "Py_IsInitialized");
    void (*init_ex)(int) = (void (*)(int))dlsym(lib, "Py_InitializeEx");
    void *(*save_thread)(void) = (void *(*)(void))dlsym(lib, "PyEval_SaveThread");
    if (!is_init || !init_ex || !save_thread) {
        snprintf(python_problem, sizeof python_problem, "ncfmu: %s is not a Python runtime library", tried);
        fprintf(stderr, "%s\n", python_problem);
        state = -1;
        return 0;
    }
    if (!is_init()) {
        /* The interpreter's home is the one recorded at build time (line 3 of ncfmu_python.txt): left to
         * itself, an embedded Python looks for "python3" on PATH and may take another installation's
         * standard library. $PYTHONHOME, when the host sets it, still wins. */
        void (*set_home)(const wchar_t *) = (void (*)(const wchar_t *))dlsym(lib, "Py_SetPythonHome");
        wchar_t *(*decode)(const char *, size_t *) = (wchar_t *(*)(const char *, size_t *))dlsym(lib, "Py_DecodeLocale");
        if (!getenv("PYTHONHOME") && !env && recorded[2][0] && set_home && decode) {
            wchar_t *home = decode(recorded[2], NULL);   /* kept for the interpreter's life, as the API asks */
            if (home) set_home(home);
        }
        init_ex(0);                         /* 0: leave the host's signal handlers alone */
        save_thread();                      /* release the GIL: every call takes it with PyGILState_Ensure */
    }
    state = 1;
    return 1;
}

static void *inner = NULL;
static void *sym(const char *name);
static void *sym_locked(const char *name, int *failed);

/* pythonfmu 0.7 defect: its global std::shared_ptr<PyState> is released twice at process exit -- by its
 * static destructor, then again by its __attribute__((destructor)) finalizePythonInterpreter, which
 * reads the freed control block (valgrind: "Invalid read ... finalizePythonInterpreter", then
 * "free(): corrupted unsorted chunks", rc 134, in about 1 run of 3 of a native host). Calling that
 * function first, from an exit handler registered after pythonfmu's library is loaded (so it runs
 * before pythonfmu's static destructors), releases the state once and leaves both later releases
 * nothing to do. */
static void (*pythonfmu_release)(void) = NULL;
static void release_pythonfmu_state(void)
{
    if (pythonfmu_release) pythonfmu_release();
}
#define INNER_(ret, name, params) static ret(*inner_##name) params = NULL; \
    if (!inner_##name) inner_##name = (ret(*) params)sym(#name);

static pthread_mutex_t load_lock = PTHREAD_MUTEX_INITIALIZER;

static void *sym(const char *name)
{
    static int inner_failed = 0;           /* say a load failure once, not on every call */
    /* Hosts instantiate on several threads: the runtime and pythonfmu's library are loaded once, under a lock. */
    pthread_mutex_lock(&load_lock);
    void *loaded = sym_locked(name, &inner_failed);
    pthread_mutex_unlock(&load_lock);
    return loaded;
}

static void *sym_locked(const char *name, int *failed)
{
    if (!inner) {
        Dl_info info;
        char path[4096];
        if (*failed) return NULL;
        if (!dladdr((void *)&sym, &info) || !info.dli_fname) return NULL;
        if (!python_runtime(info.dli_fname)) { *failed = 1; return NULL; }
        const char *dot = strrchr(info.dli_fname, '.');
        size_t stem = dot ? (size_t)(dot - info.dli_fname) : strlen(info.dli_fname);
        if (stem + 32 >= sizeof path) return NULL;
        memcpy(path, info.dli_fname, stem);
        strcpy(path + stem, ".pythonfmu.so");
        inner = dlopen(path, RTLD_NOW | RTLD_LOCAL | RTLD_DEEPBIND);
        if (inner) {
            pythonfmu_release = (void (*)(void))dlsym(inner, "finalizePythonInterpreter");
            if (pythonfmu_release) atexit(release_pythonfmu_state);
        }
        if (!inner) {
            snprintf(python_problem, sizeof python_problem, "ncfmu status shim: cannot load %s: %s", path, dlerror());
            fprintf(stderr, "%s\n", python_problem);
            *failed = 1;
            return NULL;
        }
    }
    return dlsym(inner, name);
}

#define FWD(ret, fail, name, params, args)                       \
    ret name params                                              \
    {                                                            \
        static ret(*f) params = NULL;                            \
        if (!f) f = (ret(*) params)sym(#name);                   \
        if (!f) return fail;                                     \
        return f args;                                           \
    }
#define FWDV(name, params, args)                                 \
    void name params                                             \
    {                                                            \
        static void(*f) params = NULL;                           \
        if (!f) f = (void(*) params)sym(#name);                  \
        if (f) f args;                                           \
    }

FWD(const char *, "cs", fmi2GetTypesPlatform, (void), ())
FWD(const char *, "2.0", fmi2GetVersion, (void), ())
FWD(fmi2Status, fmi2Fatal, fmi2SetDebugLogging, (fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cats[]), (c, on, n, cats))
FWD(fmi2Status, fmi2Fatal, fmi2GetString, (fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[]), (c, vr, n, v))
FWD(fmi2Status, fmi2Fatal, fmi2GetDirectionalDerivative, (fmi2Component c, const fmi2ValueReference u[], size_t nu, const fmi2ValueReference z[], size_t nz, const fmi2Real dv[], fmi2Real dz[]), (c, u, nu, z, nz, dv, dz))
FWD(fmi2Status, fmi2Fatal, fmi2SetRealInputDerivatives, (fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer order[], const fmi2Real v[]), (c, vr, n, order, v))
FWD(fmi2Status, fmi2Fatal, fmi2GetRealOutputDerivatives, (fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer order[], fmi2Real v[]), (c, vr, n, order, v))
FWD(fmi2Status, fmi2Fatal, fmi2CancelStep, (fmi2Component c), (c))
FWD(fmi2Status, fmi2Fatal, fmi2GetStatus, (fmi2Component c, const fmi2StatusKind k, fmi2Status *v), (c, k, v))
FWD(fmi2Status, fmi2Fatal, fmi2GetIntegerStatus, (fmi2Component c, const fmi2StatusKind k, fmi2Integer *v), (c, k, v))
FWD(fmi2Status, fmi2Fatal, fmi2GetBooleanStatus, (fmi2Component c, const fmi2StatusKind k, fmi2Boolean *v), (c, k, v))
FWD(fmi2Status, fmi2Fatal, fmi2GetStringStatus, (fmi2Component c, const fmi2StatusKind k, fmi2String *v), (c, k, v))

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tol_def, fmi2Real tol, fmi2Real start,
                               fmi2Boolean stop_def, fmi2Real stop)
{
    INNER_(fmi2Status, fmi2SetupExperiment, (fmi2Component, fmi2Boolean, fmi2Real, fmi2Real, fmi2Boolean, fmi2Real))
    Inst *i = inst_find(c);
    if (!allowed(i, "fmi2SetupExperiment", P_SETUP)) return fmi2Error;
    Fmi2Log log = {i ? i->logger : NULL, i ? i->env : NULL, i ? i->name : ""};
    if (!fmi2_experiment_ok(&log, start, stop_def, stop)) return fmi2Error;
    if (i) i->last_time = start;
    return inner_fmi2SetupExperiment ? inner_fmi2SetupExperiment(c, tol_def, tol, start, stop_def, stop) : fmi2Fatal;
}

/* A state transition: allowed from ``from``, forwarded, and in ``to`` when pythonfmu agrees. */
static fmi2Status transition(fmi2Component c, const char *call, int from, int to, fmi2Status (*inner_call)(fmi2Component))
{
    Inst *i = inst_find(c);
    if (!allowed(i, call, from)) return fmi2Error;
    fmi2Status s = inner_call ? inner_call(c) : fmi2Fatal;
    if (s <= fmi2Warning) i->phase = to;
    return s;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    INNER_(fmi2Status, fmi2EnterInitializationMode, (fmi2Component))
    return transition(c, "fmi2EnterInitializationMode", P_SETUP, P_INIT, inner_fmi2EnterInitializationMode);
}

fmi2Status fmi2Terminate(fmi2Component c)
{
    INNER_(fmi2Status, fmi2Terminate, (fmi2Component))
    return transition(c, "fmi2Terminate", P_STEP, P_TERMINATED, inner_fmi2Terminate);
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind k, fmi2Real *v)
{
    Inst *i = inst_find(c);
    if (i && k == fmi2LastSuccessfulTime && v) { *v = i->last_time; return fmi2OK; }
    if (i && i->logger)
        i->logger(i->env, i->name, fmi2Discard, "warning", "fmi2GetRealStatus: only fmi2LastSuccessfulTime is "
                  "available (no asynchronous steps)");
    return fmi2Discard;
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String v[])
{
    INNER_(fmi2Status, fmi2SetString, (fmi2Component, const fmi2ValueReference[], size_t, const fmi2String[]))
    if (!allowed(inst_find(c), "fmi2SetString", P_SETTABLE)) return fmi2Error;
    for (size_t k = 0; k < n; k++) {
        if (!v || !v[k] || !fmi2_utf8_ok((const unsigned char *)v[k])) {
            Inst *i = inst_find(c);
            if (i && i->logger)
                i->logger(i->env, i->name, fmi2Error, "error", "fmi2SetString: value reference %u: %s",
                          vr ? vr[k] : 0u, v && v[k] ? "not valid UTF-8 text" : "a NULL string");
            return fmi2Error;
        }
    }
    return inner_fmi2SetString ? inner_fmi2SetString(c, vr, n, v) : fmi2Fatal;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    if (!allowed(inst_find(c), "fmi2ExitInitializationMode", P_INIT)) return fmi2Error;
    static fmi2Status (*exit_init)(fmi2Component) = NULL;
    static fmi2Status (*get_integer)(fmi2Component, const fmi2ValueReference[], size_t, fmi2Integer[]) = NULL;
    if (!exit_init) exit_init = (fmi2Status(*)(fmi2Component))sym("fmi2ExitInitializationMode");
    if (!get_integer)
        get_integer = (fmi2Status(*)(fmi2Component, const fmi2ValueReference[], size_t, fmi2Integer[]))sym("fmi2GetInteger");
    if (!exit_init || !get_integer) return fmi2Fatal;
    fmi2Status status = exit_init(c);
    if (status > fmi2Warning) return status;
    fmi2ValueReference vr = NCFMU_INIT_REFUSED_VR;
    fmi2Integer refused = 0;
    if (get_integer(c, &vr, 1, &refused) == fmi2OK && refused) return fmi2Error;
    inst_phase(c, P_STEP);
    return status;
}

/* FMU-state calls the adapter may refuse (garbage bytes, a state of another FMU): it logs why and
 * raises a flag, read (and cleared) here through a reserved value reference, that becomes fmi2Error.
 * A refused deserialisation frees the empty state pythonfmu made, so the host gets nothing to misuse. */
static int call_refused(fmi2Component c)
{
    static fmi2Status (*get_integer)(fmi2Component, const fmi2ValueReference[], size_t, fmi2Integer[]) = NULL;
    if (!get_integer)
        get_integer = (fmi2Status(*)(fmi2Component, const fmi2ValueReference[], size_t, fmi2Integer[]))sym("fmi2GetInteger");
    fmi2ValueReference vr = NCFMU_CALL_REFUSED_VR;
    fmi2Integer refused = 0;
    return get_integer && get_integer(c, &vr, 1, &refused) == fmi2OK && refused;
}

/* ---- FMU states: only the live ones of this instance reach pythonfmu ------------------------------
 * pythonfmu dereferences whatever pointer it is given: a freed state, one of another instance, or a
 * made-up pointer crashed the host. The shim keeps the states each instance handed out and not yet
 * freed, and refuses any other with fmi2Error (the pointer is never dereferenced). */
static int state_index(Inst *i, void *s)
{
    for (size_t k = 0; i && k < i->n_states; k++)
        if (i->states[k] == s) return (int)k;
    return -1;
}

static void state_add(Inst *i, void *s)
{
    if (!i || !s || state_index(i, s) >= 0) return;
    if (i->n_states == i->cap_states) {
        size_t cap = i->cap_states ? 2 * i->cap_states : 8;
        void **grown = realloc(i->states, cap * sizeof *grown);
        if (!grown) return;
        i->states = grown;
        i->cap_states = cap;
    }
    i->states[i->n_states++] = s;
}

static int state_live(Inst *i, const char *call, void *s)
{
    if (state_index(i, s) >= 0) return 1;
    if (i->logger)
        i->logger(i->env, i->name, fmi2Error, "error", "%s: %p is not a live FMU state of this instance "
                  "(freed, of another instance or FMU, or never made)", call, s);
    return 0;
}

/* A call on the state ``s``: a known instance, and one of its live states. */
static int state_call_ok(Inst *i, const char *call, void *s)
{
    return allowed(i, call, P_ANY) && state_live(i, call, s);
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s)
{
    INNER_(fmi2Status, fmi2GetFMUstate, (fmi2Component, fmi2FMUstate *))
    INNER_(fmi2Status, fmi2FreeFMUstate, (fmi2Component, fmi2FMUstate *))
    Inst *i = inst_find(c);
    if (!allowed(i, "fmi2GetFMUstate", P_ANY) || !s) return fmi2Error;
    if (*s && !state_live(i, "fmi2GetFMUstate", *s)) return fmi2Error;
    if (*s) {                              /* FMI: a given state is overwritten -- pythonfmu makes a new one */
        int k = state_index(i, *s);
        if (k >= 0) i->states[k] = i->states[--i->n_states];
        if (inner_fmi2FreeFMUstate) inner_fmi2FreeFMUstate(c, s);
        *s = NULL;
    }
    fmi2Status st = inner_fmi2GetFMUstate ? inner_fmi2GetFMUstate(c, s) : fmi2Fatal;
    if (st <= fmi2Warning) state_add(i, *s);
    return st;
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s)
{
    INNER_(fmi2Status, fmi2FreeFMUstate, (fmi2Component, fmi2FMUstate *))
    Inst *i = inst_find(c);
    if (!allowed(i, "fmi2FreeFMUstate", P_ANY)) return fmi2Error;
    if (!s || !*s) return fmi2OK;
    if (!state_live(i, "fmi2FreeFMUstate", *s)) return fmi2Error;
    int k = state_index(i, *s);
    if (k >= 0) i->states[k] = i->states[--i->n_states];
    return inner_fmi2FreeFMUstate ? inner_fmi2FreeFMUstate(c, s) : fmi2Fatal;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *size)
{
    INNER_(fmi2Status, fmi2SerializedFMUstateSize, (fmi2Component, fmi2FMUstate, size_t *))
    Inst *i = inst_find(c);
    if (!state_call_ok(i, "fmi2SerializedFMUstateSize", s) || !size) return fmi2Error;
    return inner_fmi2SerializedFMUstateSize ? inner_fmi2SerializedFMUstateSize(c, s, size) : fmi2Fatal;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t size)
{
    INNER_(fmi2Status, fmi2SerializeFMUstate, (fmi2Component, fmi2FMUstate, fmi2Byte[], size_t))
    INNER_(fmi2Status, fmi2SerializedFMUstateSize, (fmi2Component, fmi2FMUstate, size_t *))
    Inst *i = inst_find(c);
    if (!state_call_ok(i, "fmi2SerializeFMUstate", s)) return fmi2Error;
    /* pythonfmu copies ``size`` bytes out of its state, whatever its length: only the exact size passes. */
    size_t needed = 0;
    if (!inner_fmi2SerializedFMUstateSize || inner_fmi2SerializedFMUstateSize(c, s, &needed) > fmi2Warning)
        return fmi2Error;
    if (!b || size < needed) {
        if (i->logger)
            i->logger(i->env, i->name, fmi2Error, "error", "fmi2SerializeFMUstate: %s (%zu bytes given, %zu needed)",
                      !b ? "the buffer is NULL" : "the buffer is too small", size, needed);
        return fmi2Error;
    }
    return inner_fmi2SerializeFMUstate ? inner_fmi2SerializeFMUstate(c, s, b, needed) : fmi2Fatal;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s)
{
    if (!state_call_ok(inst_find(c), "fmi2SetFMUstate", s)) return fmi2Error;
    static fmi2Status (*f)(fmi2Component, fmi2FMUstate) = NULL;
    if (!f) f = (fmi2Status(*)(fmi2Component, fmi2FMUstate))sym("fmi2SetFMUstate");
    if (!f) return fmi2Fatal;
    fmi2Status status = f(c, s);
    if (status <= fmi2Warning && call_refused(c)) return fmi2Error;
    return status;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t size, fmi2FMUstate *s)
{
    static fmi2Status (*f)(fmi2Component, const fmi2Byte[], size_t, fmi2FMUstate *) = NULL;
    static fmi2Status (*free_state)(fmi2Component, fmi2FMUstate *) = NULL;
    if (!f) f = (fmi2Status(*)(fmi2Component, const fmi2Byte[], size_t, fmi2FMUstate *))sym("fmi2DeSerializeFMUstate");
    if (!free_state) free_state = (fmi2Status(*)(fmi2Component, fmi2FMUstate *))sym("fmi2FreeFMUstate");
    if (!allowed(inst_find(c), "fmi2DeSerializeFMUstate", P_ANY) || !s || (size && !b)) return fmi2Error;
    if (!f) return fmi2Fatal;
    fmi2Status status = f(c, b, size, s);
    if (status <= fmi2Warning && call_refused(c)) {
        if (free_state && *s) free_state(c, s);
        *s = NULL;
        return fmi2Error;
    }
    if (status <= fmi2Warning) state_add(inst_find(c), *s);
    return status;
}

/* ---- the wrapped calls --------------------------------------------------------------------------- */
#define INNER(ret, name, params) static ret(*inner_##name) params = NULL; \
    if (!inner_##name) inner_##name = (ret(*) params)sym(#name);

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String res,
                              const fmi2CallbackFunctions *cb, fmi2Boolean vis, fmi2Boolean log)
{
    INNER(fmi2Component, fmi2Instantiate, (fmi2String, fmi2Type, fmi2String, fmi2String,
                                           const fmi2CallbackFunctions *, fmi2Boolean, fmi2Boolean))
    if (!inner_fmi2Instantiate) {
        if (cb && cb->logger)               /* the host's log says why, too */
            cb->logger(cb->componentEnvironment, name ? name : "", fmi2Error, "error", "%s",
                       python_problem[0] ? python_problem : "ncfmu: pythonfmu's library could not be loaded");
        return NULL;
    }
    /* The adapter announces itself in one global (_ncfmu_fast.last): instantiations are serialised so that
     * each instance's fast path binds to its own adapter, whatever threads the host uses. */
    static pthread_mutex_t instantiate_lock = PTHREAD_MUTEX_INITIALIZER;
    pthread_mutex_lock(&instantiate_lock);
    fmi2Component c = inner_fmi2Instantiate(name, type, guid, res, cb, vis, log);
    if (c) {
        Inst *i = calloc(1, sizeof *i);
        if (i) {
            i->c = c;
            i->phase = P_INSTANTIATED;
            snprintf(i->name, sizeof i->name, "%s", name ? name : "");
            i->logger = cb ? cb->logger : NULL;
            i->env = cb ? cb->componentEnvironment : NULL;
            pthread_mutex_lock(&inst_lock);
            i->next = inst_list;
            inst_list = i;
            pthread_mutex_unlock(&inst_lock);
        }
    }
    if (c && name) fast_register(c, name);
    pthread_mutex_unlock(&instantiate_lock);
    return c;
}

void fmi2FreeInstance(fmi2Component c)
{
    INNER(void, fmi2FreeInstance, (fmi2Component))
    inst_drop(c);                                  /* and its fast path */
    if (inner_fmi2FreeInstance) inner_fmi2FreeInstance(c);
}

fmi2Status fmi2Reset(fmi2Component c)
{
    INNER(fmi2Status, fmi2Reset, (fmi2Component))
    if (!inner_fmi2Reset) return fmi2Fatal;
    Fast *f = fast_find(c);
    char name[512] = "";
    if (f && py_load()) {                          /* pythonfmu creates a new adapter on reset */
        PyGILState_STATE g = py.GILEnsure();
        PyObject *n = py.GetAttr(f->slave, "instance_name");
        if (n && py.Utf8(n)) snprintf(name, sizeof name, "%s", py.Utf8(n));
        if (n) py.DecRef(n);
        if (py.Occurred()) py.Clear();
        py.GILRelease(g);
    }
    fast_drop(c);
    fmi2Status s = inner_fmi2Reset(c);
    if (s <= fmi2Warning && name[0]) fast_register(c, name);
    if (s <= fmi2Warning) inst_phase(c, P_INSTANTIATED);
    return s;
}

/* The value references of a Get/Set: known, of the call's type, and (for a set) settable now. 1 when
 * fine (or not checkable: no record), else logs the first offender and returns 0. */
static const char *kind_name(int kind)
{
    return kind == K_REAL ? "Real" : kind == K_INTEGER ? "Integer" : kind == K_BOOLEAN ? "Boolean" : "String";
}

static int check_refs(Inst *i, const char *call, const fmi2ValueReference vr[], size_t n, int kind, int set)
{
    Fast *f = i ? i->fast : NULL;
    if (!f) return 1;
    for (size_t k = 0; k < n; k++) {
        unsigned r = vr[k];
        const char *why = NULL;
        if (!set && kind == K_INTEGER && (r == NCFMU_INIT_REFUSED_VR || r == NCFMU_CALL_REFUSED_VR)) continue;
        if (r >= f->n || !f->names[r]) why = "is not a variable of this FMU";
        else if (f->kind[r] != kind) why = "is not of this call's type";
        else if (set && f->causality[r] == C_OUTPUT) why = "is an output: it cannot be set";
        else if (set && f->fixed[r] && i && i->phase == P_STEP)
            why = "is a fixed parameter: it cannot be set after initialisation";
        if (why) {
            if (i && i->logger)
                i->logger(i->env, i->name, fmi2Error, "error", "%s: value reference %u %s (%s call)", call, r, why,
                          kind_name(kind));
            return 0;
        }
    }
    return 1;
}

/* n values asked: both arrays must be there. */
static int arrays_ok(Inst *i, const char *call, const fmi2ValueReference vr[], size_t n, const void *v)
{
    if (n == 0 || (vr && v)) return 1;
    if (i && i->logger)
        i->logger(i->env, i->name, fmi2Error, "error", "%s: %zu values asked, but the %s array is NULL", call, n,
                  !vr ? "value reference" : "value");
    return 0;
}

#define GETTER(name, type, kind)                                                                  \
    fmi2Status name(fmi2Component c, const fmi2ValueReference vr[], size_t n, type v[])           \
    {                                                                                             \
        INNER(fmi2Status, name, (fmi2Component, const fmi2ValueReference[], size_t, type[]))      \
        Inst *i = inst_find(c);                                                                   \
        if (!allowed(i, #name, P_GETTABLE) || !arrays_ok(i, #name, vr, n, v)) return fmi2Error;   \
        if (fast_get(i ? i->fast : NULL, vr, n, kind, v)) return fmi2OK;                          \
        if (!check_refs(i, #name, vr, n, kind, 0)) return fmi2Error;                              \
        return inner_##name ? inner_##name(c, vr, n, v) : fmi2Fatal;                              \
    }
#define SETTER(name, type, kind)                                                                  \
    fmi2Status name(fmi2Component c, const fmi2ValueReference vr[], size_t n, const type v[])     \
    {                                                                                             \
        INNER(fmi2Status, name, (fmi2Component, const fmi2ValueReference[], size_t, const type[]))\
        Inst *i = inst_find(c);                                                                   \
        if (!allowed(i, #name, P_SETTABLE) || !arrays_ok(i, #name, vr, n, v)) return fmi2Error;   \
        if (fast_set(i ? i->fast : NULL, vr, n, kind, v)) return fmi2OK;                          \
        if (!check_refs(i, #name, vr, n, kind, 1)) return fmi2Error;                              \
        fmi2Status st = inner_##name ? inner_##name(c, vr, n, v) : fmi2Fatal;                     \
        if (st <= fmi2Warning && n > 0 && call_refused(c)) return fmi2Error;                      \
        return st;                                                                                \
    }
GETTER(fmi2GetReal, fmi2Real, K_REAL)
GETTER(fmi2GetInteger, fmi2Integer, K_INTEGER)
GETTER(fmi2GetBoolean, fmi2Boolean, K_BOOLEAN)
SETTER(fmi2SetReal, fmi2Real, K_REAL)
SETTER(fmi2SetInteger, fmi2Integer, K_INTEGER)
SETTER(fmi2SetBoolean, fmi2Boolean, K_BOOLEAN)

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean discard)
{
    INNER(fmi2Status, fmi2DoStep, (fmi2Component, fmi2Real, fmi2Real, fmi2Boolean))
    INNER(fmi2Status, fmi2SetReal, (fmi2Component, const fmi2ValueReference[], size_t, const fmi2Real[]))
    fmi2Status st;
    int flush = 0;
    Inst *i = inst_find(c);
    if (!allowed(i, "fmi2DoStep", P_STEP)) return fmi2Error;
    Fmi2Log log = {i ? i->logger : NULL, i ? i->env : NULL, i ? i->name : ""};
    if (!fmi2_step_ok(&log, t, h)) return fmi2Error;
    if (fast_step(i ? i->fast : NULL, t, h, &st, &flush)) {
        if (flush && inner_fmi2SetReal) inner_fmi2SetReal(c, NULL, 0, NULL);   /* pythonfmu flushes the log */
    } else {
        st = inner_fmi2DoStep ? inner_fmi2DoStep(c, t, h, discard) : fmi2Fatal;
    }
    if (i && st <= fmi2Warning) i->last_time = t + h;
    return st;
}
