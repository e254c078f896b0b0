/*
 * ncfmu's Python FMUs: the FMU's binary (the "shim").
 *
 * It is the whole FMI 2.0 co-simulation interface of a controller FMU. It checks every call (the
 * instance handle, the FMI state machine of fmi2_machine.h, value references and their types, step
 * times), and drives the Python slave (fmi/adapter.py) through the calls listed in the contract
 * (fmi/contract.py, generated into ncfmu_contract.h; see docs/architecture.md). Each call returns its
 * status; the log messages it queued are taken after the call (when there are any: the shim reads the length
 * of the slave's pending_log) and sent to the host's logger: errors and warnings always, the rest only with
 * debug logging on. pythonfmu provides the Python slave API
 * (Fmi2Slave) and the packaging; its export library is not used.
 *
 * Hosts hold opaque handles, not addresses (fmi2_machine.h): a NULL, freed, made-up or foreign instance
 * or FMU-state handle is recognised and refused with fmi2Error (a second fmi2FreeInstance of the same
 * handle does nothing).
 *
 * Built per FMU by ncfmu.fmi.builder with -DNCFMU_GUID, -DNCFMU_MODULE (the model script's module in
 * resources/) and -DNCFMU_CLASS (its slave class, the model identifier).
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <math.h>
#include <pthread.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

/* The official FMI 2.0 headers (fmpy ships them; the builder passes -I<fmpy>/c-code), the state machine
 * shared with ncfmu's native FMUs, and the contract with the Python side. */
#include "fmi2Functions.h"
#include "fmi2_machine.h"
#include "ncfmu_contract.h"

#if !defined(NCFMU_GUID) || !defined(NCFMU_MODULE) || !defined(NCFMU_CLASS)
#error "the builder passes NCFMU_GUID, NCFMU_MODULE and NCFMU_CLASS"
#endif

/* ---- a Python runtime for native hosts ------------------------------------------------------------
 * In a Python host (fmpy, ncfmu) the interpreter is there. In a native host (fmusim, ecos, libcosim)
 * the shim loads a libpython with RTLD_GLOBAL, choosing, in this order:
 *   1. $NCFMU_LIBPYTHON (a path or a soname), and nothing else when it is set;
 *   2. the library recorded at build time in resources/ncfmu_python.txt (path, then its soname);
 * and starts the interpreter itself (then releases the GIL). It is never finalised: it lives until the
 * process ends (numpy's and scipy's clean-up at Py_Finalize crashed native hosts). If no runtime loads,
 * one message says so, and every instantiation fails (fmi2Instantiate returns NULL). */
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

/* ---- the Python C API, resolved at run time (the binary links no libpython) ------------------------- */
typedef struct _object PyObject;
typedef int PyGILState_STATE;
typedef long Py_ssize_t_;
static struct {
    PyGILState_STATE (*GILEnsure)(void);
    void (*GILRelease)(PyGILState_STATE);
    PyObject *(*DictGetItem)(PyObject *, PyObject *);
    PyObject *(*DictGetItemString)(PyObject *, const char *);
    int (*DictSetItem)(PyObject *, PyObject *, PyObject *);
    double (*FloatAs)(PyObject *);
    PyObject *(*FloatFrom)(double);
    long (*LongAs)(PyObject *);
    PyObject *(*LongFrom)(long);
    int (*IsTrue)(PyObject *);
    PyObject *(*BoolFrom)(long);
    PyObject *(*GetAttr)(PyObject *, PyObject *);
    PyObject *(*GetAttrString)(PyObject *, const char *);
    PyObject *(*CallMethod)(PyObject *, PyObject *, ...);
    PyObject *(*StrFrom)(const char *);
    PyObject *(*InternFrom)(const char *);
    const char *(*Utf8)(PyObject *);
    Py_ssize_t_ (*SeqSize)(PyObject *);
    PyObject *(*SeqGetItem)(PyObject *, Py_ssize_t_);
    int (*SeqContains)(PyObject *, PyObject *);
    PyObject *(*ListNew)(Py_ssize_t_);
    int (*ListSetItem)(PyObject *, Py_ssize_t_, PyObject *);
    int (*ListInsert)(PyObject *, Py_ssize_t_, PyObject *);
    Py_ssize_t_ (*ListSize)(PyObject *);
    PyObject *(*SysGet)(const char *);
    PyObject *(*Import)(const char *);
    PyObject *(*BytesFrom)(const char *, Py_ssize_t_);
    int (*BytesAs)(PyObject *, char **, Py_ssize_t_ *);
    PyObject *(*Occurred)(void);
    void (*Fetch)(PyObject **, PyObject **, PyObject **);
    PyObject *(*Str)(PyObject *);
    void (*Clear)(void);
    void (*IncRef)(PyObject *);
    void (*DecRef)(PyObject *);
    PyObject *None;
} py;

static int py_load(void)
{
    static int ready = 0;
    if (ready) return ready > 0;
    void *h = RTLD_DEFAULT;
#define L(field, name) if (!(py.field = (__typeof__(py.field))dlsym(h, name))) { ready = -1; return 0; }
    L(GILEnsure, "PyGILState_Ensure") L(GILRelease, "PyGILState_Release") L(DictGetItem, "PyDict_GetItem")
    L(DictGetItemString, "PyDict_GetItemString")
    L(DictSetItem, "PyDict_SetItem") L(FloatAs, "PyFloat_AsDouble") L(FloatFrom, "PyFloat_FromDouble")
    L(LongAs, "PyLong_AsLong") L(LongFrom, "PyLong_FromLong") L(IsTrue, "PyObject_IsTrue")
    L(BoolFrom, "PyBool_FromLong") L(GetAttr, "PyObject_GetAttr") L(GetAttrString, "PyObject_GetAttrString")
    L(CallMethod, "PyObject_CallMethodObjArgs") L(StrFrom, "PyUnicode_FromString")
    L(InternFrom, "PyUnicode_InternFromString") L(Utf8, "PyUnicode_AsUTF8") L(SeqSize, "PySequence_Size")
    L(SeqGetItem, "PySequence_GetItem") L(SeqContains, "PySequence_Contains") L(ListNew, "PyList_New")
    L(ListSetItem, "PyList_SetItem") L(ListInsert, "PyList_Insert") L(ListSize, "PyList_Size") L(SysGet, "PySys_GetObject")
    L(Import, "PyImport_ImportModule") L(BytesFrom, "PyBytes_FromStringAndSize")
    L(BytesAs, "PyBytes_AsStringAndSize") L(Occurred, "PyErr_Occurred") L(Fetch, "PyErr_Fetch")
    L(Str, "PyObject_Str") L(Clear, "PyErr_Clear") L(IncRef, "Py_IncRef") L(DecRef, "Py_DecRef")
    L(None, "_Py_NoneStruct")
#undef L
    ready = 1;
    return 1;
}

static void py_drop(PyObject *o)
{
    if (o) py.DecRef(o);
}

/* The pending Python exception as text (and cleared). */
static void py_error_text(char *out, size_t size)
{
    PyObject *type = NULL, *value = NULL, *tb = NULL;
    py.Fetch(&type, &value, &tb);
    PyObject *s = value ? py.Str(value) : type ? py.Str(type) : NULL;
    const char *text = s ? py.Utf8(s) : NULL;
    snprintf(out, size, "%s", text ? text : "an exception without text");
    if (py.Occurred()) py.Clear();
    py_drop(s); py_drop(type); py_drop(value); py_drop(tb);
}

/* The contract's names, interned once (under the GIL). */
#define NAME_ENUM(m) N_##m,
enum { NCFMU_CONTRACT_NAMES(NAME_ENUM) N_COUNT };
#define NAME_TEXT(m) NCFMU_##m,
static const char *const name_text[N_COUNT] = { NCFMU_CONTRACT_NAMES(NAME_TEXT) };
static PyObject *names[N_COUNT];

static int names_ready(void)
{
    if (names[0]) return 1;
    for (int k = 0; k < N_COUNT; k++)
        if (!(names[k] = py.InternFrom(name_text[k]))) { py.Clear(); return 0; }
    return 1;
}

/* ---- instances and FMU states: opaque handles of fmi2_machine.h, never reused ---------------------- */

typedef struct {
    uintptr_t handle;
    PyObject *object;                     /* the adapter's state object */
    double time;                          /* where the instance was when the state was taken */
} State;

typedef struct Inst {
    int phase;
    double next_time;                     /* where the next step must start: start time, last step's end, restored */
    char name[128];
    Fmi2Log log;                          /* the host's logger; log.name points to name */
    char resources[4096];                 /* the resources folder, for fmi2Reset's new slave */
    int visible;
    int debug;                            /* debug logging on: info messages reach the logger too */
    unsigned categories;                  /* with debug on: which categories (bit k: FMI2_CATEGORIES[k]); all if 0 */
    PyObject *slave, *inputs;
    PyObject *pending;                    /* the slave's pending_log: fmi_take_log only when not empty */
    unsigned n;                           /* value references 0 .. n-1 */
    PyObject **port_name;                 /* by value reference: the variable's name (NULL: none) */
    unsigned char *type, *causality, *fixed;
    PyObject *strings;                    /* the last fmi2GetString's values, kept alive until the next */
    State *states;
    size_t n_states, cap_states;
} Inst;

static Inst *inst_find(fmi2Component c)
{
    return fmi2_instance_find(c, 0);
}

/* The instance behind ``c`` when ``call`` is allowed in its phase; else NULL (and fmi2Error). A NULL,
 * freed or made-up handle has no logger to tell: the call just returns fmi2Error. */
static Inst *checked(fmi2Component c, const char *call, int phases)
{
    Inst *i = inst_find(c);
    if (!i || !fmi2_allowed(&i->log, i->phase, call, phases)) return NULL;
    if (!i->slave) {                      /* a failed fmi2Reset: the instance can only be freed */
        FMI2_SAY(&i->log, fmi2Error, "logStatusError", "%s: the instance has no slave (its reset failed): "
                 "free it", call);
        return NULL;
    }
    return i;
}

/* ---- calls into the Python slave (the GIL held) ---------------------------------------------------- */
/* Send what the slave logged to the host: errors and warnings always, the rest with debug logging on. */
static void flush_log(Inst *i)
{
    if (!i->slave) return;
    Py_ssize_t_ pending = py.ListSize(i->pending);          /* a C call: nothing logged, nothing called */
    if (pending == 0) return;
    if (pending < 0) py.Clear();                             /* not a list: take the log anyway */
    PyObject *taken = py.CallMethod(i->slave, names[N_TAKE_LOG], NULL);
    Py_ssize_t_ n = taken ? py.SeqSize(taken) : 0;
    for (Py_ssize_t_ k = 0; k < n; k++) {
        PyObject *m = py.SeqGetItem(taken, k);
        PyObject *st = m ? py.SeqGetItem(m, 0) : NULL, *cat = m ? py.SeqGetItem(m, 1) : NULL;
        PyObject *text = m ? py.SeqGetItem(m, 2) : NULL;
        long status = st ? py.LongAs(st) : fmi2Error;
        const char *c_s = cat ? py.Utf8(cat) : NULL, *t_s = text ? py.Utf8(text) : NULL;
        int shown = status >= fmi2Warning;
        if (!shown && i->debug) {
            shown = i->categories == 0;
            for (unsigned b = 0; !shown && b < FMI2_N_CATEGORIES; b++)
                shown = (i->categories & (1u << b)) && c_s && !strcmp(c_s, FMI2_CATEGORIES[b]);
        }
        if (shown && t_s)
            FMI2_SAY(&i->log, status < fmi2OK || status > fmi2Fatal ? fmi2Error : (fmi2Status)status,
                     c_s ? c_s : "logAll", "%s", t_s);
        py_drop(st); py_drop(cat); py_drop(text); py_drop(m);
    }
    if (py.Occurred()) py.Clear();
    py_drop(taken);
}

/* slave.<entry>(a, b, c): a new reference, or NULL after logging the exception that escaped. */
static PyObject *call(Inst *i, const char *fmi_call, int entry, PyObject *a, PyObject *b, PyObject *c)
{
    PyObject *r = py.CallMethod(i->slave, names[entry], a, b, c, NULL);
    if (!r) {
        char text[512];
        py_error_text(text, sizeof text);
        FMI2_SAY(&i->log, fmi2Error, "logStatusError", "%s: the Python slave raised: %s", fmi_call, text);
    }
    return r;
}

/* A call that returns a status (the contract's STATUS). */
static fmi2Status call_status(Inst *i, const char *fmi_call, int entry, PyObject *a, PyObject *b, PyObject *c)
{
    PyObject *r = call(i, fmi_call, entry, a, b, c);
    long st = r ? py.LongAs(r) : NCFMU_STATUS_ERROR;
    if (py.Occurred()) { py.Clear(); st = NCFMU_STATUS_ERROR; }
    py_drop(r);
    if (st < NCFMU_STATUS_OK || st > NCFMU_STATUS_FATAL) st = NCFMU_STATUS_ERROR;
    return st == NCFMU_STATUS_FATAL ? fmi2Error : (fmi2Status)st;   /* nothing the slave says breaks the instance */
}

static fmi2Status simple_call(fmi2Component c, const char *fmi_call, int phases, int entry)
{
    Inst *i = checked(c, fmi_call, phases);
    if (!i) return fmi2Error;
    PyGILState_STATE g = py.GILEnsure();
    fmi2Status st = call_status(i, fmi_call, entry, NULL, NULL, NULL);
    flush_log(i);
    py.GILRelease(g);
    return st;
}

/* ---- making and dropping the Python slave -------------------------------------------------------- */
static void slave_drop(Inst *i)
{
    py_drop(i->slave); py_drop(i->inputs); py_drop(i->pending); py_drop(i->strings);
    for (unsigned k = 0; k < i->n; k++) py_drop(i->port_name[k]);
    free(i->port_name); free(i->type); free(i->causality); free(i->fixed);
    i->slave = i->inputs = i->pending = i->strings = NULL;
    i->port_name = NULL; i->type = i->causality = i->fixed = NULL;
    i->n = 0;
}

/* The slave class: the model script's module, imported once per process from the FMU's resources folder
 * (its folder goes on sys.path then, not again: a host that extracts the FMU anew per run adds no entry a run). */
static PyObject *slave_class(const Fmi2Log *log, const char *resources)
{
    PyObject *modules = py.SysGet("modules");                    /* borrowed */
    if (!modules || !py.DictGetItemString(modules, NCFMU_MODULE)) {
        PyObject *path = py.SysGet("path");                      /* borrowed */
        PyObject *dir = py.StrFrom(resources);
        if (path && dir && py.SeqContains(path, dir) == 0) py.ListInsert(path, 0, dir);
        py_drop(dir);
    }
    PyObject *module = py.Import(NCFMU_MODULE);   /* the import lock: another thread's import finishes first */
    PyObject *cls = module ? py.GetAttrString(module, NCFMU_CLASS) : NULL;
    py_drop(module);
    if (!cls) {
        char text[512];
        py_error_text(text, sizeof text);
        FMI2_SAY(log, fmi2Error, "logStatusError", "fmi2Instantiate: the model %s could not be loaded from %s: %s",
                 NCFMU_MODULE, resources, text);
    }
    return cls;
}

/* A new Python slave for ``i`` and its table of variables; 0 (logged) if it cannot be made. */
static int slave_make(Inst *i)
{
    const char *resources = i->resources;
    int visible = i->visible;
    PyObject *cls = slave_class(&i->log, resources);
    if (!cls) return 0;
    PyObject *n = py.StrFrom(i->name), *res = py.StrFrom(resources), *vis = py.BoolFrom(visible);
    PyObject *slave = (n && res && vis) ? py.CallMethod(cls, names[N_INSTANTIATE], n, res, vis, NULL) : NULL;
    py_drop(n); py_drop(res); py_drop(vis); py_drop(cls);
    PyObject *ports = slave ? py.CallMethod(slave, names[N_PORTS], NULL) : NULL;
    PyObject *inputs = slave ? py.GetAttr(slave, names[N_INPUTS]) : NULL;
    PyObject *pending = slave ? py.GetAttr(slave, names[N_PENDING_LOG]) : NULL;
    if (!slave || !ports || !inputs || !pending) {
        char text[512];
        py_error_text(text, sizeof text);
        FMI2_SAY(&i->log, fmi2Error, "logStatusError", "fmi2Instantiate: the slave %s could not be made: %s",
                 NCFMU_CLASS, text);
        py_drop(slave); py_drop(ports); py_drop(inputs); py_drop(pending);
        return 0;
    }
    Py_ssize_t_ count = py.SeqSize(ports);
    unsigned n_vr = 0;
    for (Py_ssize_t_ k = 0; k < count; k++) {
        PyObject *p = py.SeqGetItem(ports, k), *vr = p ? py.SeqGetItem(p, 0) : NULL;
        long v = vr ? py.LongAs(vr) : -1;
        if (v >= 0 && v < 1000000 && (unsigned)v + 1 > n_vr) n_vr = (unsigned)v + 1;
        py_drop(vr); py_drop(p);
    }
    i->n = n_vr;
    i->port_name = calloc(n_vr ? n_vr : 1, sizeof *i->port_name);
    i->type = calloc(n_vr ? n_vr : 1, 1);
    i->causality = calloc(n_vr ? n_vr : 1, 1);
    i->fixed = calloc(n_vr ? n_vr : 1, 1);
    for (Py_ssize_t_ k = 0; k < count && i->port_name && i->type && i->causality && i->fixed; k++) {
        PyObject *p = py.SeqGetItem(ports, k);
        PyObject *f[5] = {NULL, NULL, NULL, NULL, NULL};
        for (int j = 0; p && j < 5; j++) f[j] = py.SeqGetItem(p, j);
        long vr = f[0] ? py.LongAs(f[0]) : -1;
        if (vr >= 0 && (unsigned long)vr < n_vr && f[4] && !i->port_name[vr]) {
            i->type[vr] = (unsigned char)(f[1] ? py.LongAs(f[1]) : 0);
            i->causality[vr] = (unsigned char)(f[2] ? py.LongAs(f[2]) : 0);
            i->fixed[vr] = f[3] && py.IsTrue(f[3]) > 0;
            i->port_name[vr] = f[4];
            f[4] = NULL;                                          /* kept */
        }
        for (int j = 0; j < 5; j++) py_drop(f[j]);
        py_drop(p);
    }
    py_drop(ports);
    if (py.Occurred()) py.Clear();
    i->slave = slave;
    i->inputs = inputs;
    i->pending = pending;
    if (!i->port_name || !i->type || !i->causality || !i->fixed) { slave_drop(i); return 0; }
    return 1;
}

static int binary_ready(void)
{
    static pthread_mutex_t lock = PTHREAD_MUTEX_INITIALIZER;
    pthread_mutex_lock(&lock);
    Dl_info info;
    int ok = dladdr((void *)&binary_ready, &info) && info.dli_fname && python_runtime(info.dli_fname) && py_load();
    pthread_mutex_unlock(&lock);
    return ok;
}

/* ---- the FMI 2.0 interface ------------------------------------------------------------------------ */
const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String res,
                              const fmi2CallbackFunctions *cb, fmi2Boolean visible, fmi2Boolean logging)
{
    char dir[4096];
    if (!fmi2_instantiate_ok(cb, name, type, guid, NCFMU_GUID, NCFMU_CLASS, res, dir, sizeof dir)) return NULL;
    Fmi2Log early_log = {cb ? cb->logger : NULL, cb ? cb->componentEnvironment : NULL, name};
    const Fmi2Log *early = &early_log;
    if (!binary_ready()) {
        FMI2_SAY(early, fmi2Error, "logStatusError", "%s",
                 python_problem[0] ? python_problem : "ncfmu: the Python runtime's API could not be found");
        return NULL;
    }
    Inst *i = calloc(1, sizeof *i);
    if (!i) return NULL;
    snprintf(i->name, sizeof i->name, "%s", name);
    snprintf(i->resources, sizeof i->resources, "%s", dir);
    i->visible = visible != fmi2False;
    i->log = (Fmi2Log){early->logger, early->env, i->name};
    i->phase = P_INSTANTIATED;
    i->debug = logging != fmi2False;
    PyGILState_STATE g = py.GILEnsure();
    int made = names_ready() && slave_make(i);
    if (made) flush_log(i);
    py.GILRelease(g);
    fmi2Component handle = made ? fmi2_instance_add(i) : NULL;
    if (made && !handle) {
        FMI2_SAY(early, fmi2Error, "logStatusError", "fmi2Instantiate: no new instance handle can be made");
        g = py.GILEnsure();
        slave_drop(i);
        py.GILRelease(g);
    }
    if (!handle) free(i);
    return handle;
}

static void states_drop(Inst *i)
{
    for (size_t k = 0; k < i->n_states; k++) py_drop(i->states[k].object);
    free(i->states);
    i->states = NULL;
    i->n_states = i->cap_states = 0;
}

void fmi2FreeInstance(fmi2Component c)
{
    Inst *i = fmi2_instance_find(c, 1);
    if (!i) return;                       /* NULL, freed already, or not ours: nothing to do */
    PyGILState_STATE g = py.GILEnsure();
    flush_log(i);
    states_drop(i);
    slave_drop(i);
    py.GILRelease(g);
    free(i);
    void *self = fmi2_library_release();
    if (self) dlclose(self);              /* the last thing done (a tail call): it may unmap this library */
}

fmi2Status fmi2Reset(fmi2Component c)
{
    Inst *i = checked(c, "fmi2Reset", P_ANY);
    if (!i) return fmi2Error;
    PyGILState_STATE g = py.GILEnsure();
    flush_log(i);
    slave_drop(i);
    int made = slave_make(i);
    if (made) flush_log(i);
    py.GILRelease(g);
    if (!made) return fmi2Error;          /* logged; the instance can only be freed (every call refuses) */
    i->phase = P_INSTANTIATED;
    i->next_time = 0.0;
    return fmi2OK;
}

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String categories[])
{
    Inst *i = checked(c, "fmi2SetDebugLogging", P_ANY);
    if (!i) return fmi2Error;
    unsigned mask;
    if (!fmi2_categories_ok(&i->log, n, categories, &mask)) return fmi2Error;
    i->debug = on != fmi2False;
    i->categories = mask;
    return fmi2OK;
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tol_def, fmi2Real tol, fmi2Real start,
                               fmi2Boolean stop_def, fmi2Real stop)
{
    Inst *i = checked(c, "fmi2SetupExperiment", P_SETUP);
    if (!i || !fmi2_experiment_ok(&i->log, start, stop_def, stop)) return fmi2Error;
    PyGILState_STATE g = py.GILEnsure();
    PyObject *a = py.FloatFrom(start), *b = stop_def ? py.FloatFrom(stop) : (py.IncRef(py.None), py.None);
    PyObject *t = tol_def ? py.FloatFrom(tol) : (py.IncRef(py.None), py.None);
    fmi2Status st = (a && b && t) ? call_status(i, "fmi2SetupExperiment", N_SETUP_EXPERIMENT, a, b, t) : fmi2Error;
    py_drop(a); py_drop(b); py_drop(t);
    flush_log(i);
    py.GILRelease(g);
    if (st <= fmi2Warning) i->next_time = start;
    return st;
}

static fmi2Status transition(fmi2Component c, const char *call, int from, int to, int entry)
{
    Inst *i = checked(c, call, from);
    if (!i) return fmi2Error;
    fmi2Status st = simple_call(c, call, from, entry);
    if (st <= fmi2Warning) i->phase = to;
    return st;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    return transition(c, "fmi2EnterInitializationMode", P_SETUP, P_INIT, N_ENTER_INITIALIZATION);
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    return transition(c, "fmi2ExitInitializationMode", P_INIT, P_STEP, N_EXIT_INITIALIZATION);
}

fmi2Status fmi2Terminate(fmi2Component c)
{
    return transition(c, "fmi2Terminate", P_STEP, P_TERMINATED, N_TERMINATE);
}

/* ---- values ---------------------------------------------------------------------------------------- */
static const char *type_name(int type)
{
    return type == NCFMU_TYPE_REAL ? "Real" : type == NCFMU_TYPE_INTEGER ? "Integer"
         : type == NCFMU_TYPE_BOOLEAN ? "Boolean" : "String";
}

/* The value references of a Get/Set: arrays given, every vr a variable of the call's type, and (for a set)
 * settable now. 1 when fine, else logs the first offender and returns 0. */
static int refs_ok(Inst *i, const char *call, const fmi2ValueReference vr[], size_t n, const void *v, int type,
                   int set)
{
    if (n > 0 && (!vr || !v)) {
        FMI2_SAY(&i->log, fmi2Error, "logStatusError", "%s: %zu values asked, but the %s array is NULL", call, n,
                 !vr ? "value reference" : "value");
        return 0;
    }
    for (size_t k = 0; k < n; k++) {
        unsigned r = vr[k];
        const char *why = NULL;
        if (r >= i->n || !i->port_name[r]) why = "is not a variable of this FMU";
        else if (i->type[r] != type) why = type == NCFMU_TYPE_STRING ? "is not a String variable"
                                                                     : "is not of this call's type";
        else if (set && i->causality[r] == NCFMU_CAUSALITY_OUTPUT) why = "is an output: it cannot be set";
        else if (set && i->causality[r] == NCFMU_CAUSALITY_PARAMETER && i->fixed[r] && i->phase == P_STEP)
            why = "is a fixed parameter: it cannot be set after initialisation";
        if (why) {
            FMI2_SAY(&i->log, fmi2Error, "logStatusError", "%s: value reference %u %s (a %s call)", call, r, why,
                     type_name(type));
            return 0;
        }
    }
    return 1;
}

static void value_out(PyObject *v, int type, void *values, size_t k)
{
    if (type == NCFMU_TYPE_REAL) ((fmi2Real *)values)[k] = py.FloatAs(v);
    else if (type == NCFMU_TYPE_INTEGER) ((fmi2Integer *)values)[k] = (fmi2Integer)py.LongAs(v);
    else if (type == NCFMU_TYPE_BOOLEAN) ((fmi2Boolean *)values)[k] = py.IsTrue(v) > 0;
    else ((fmi2String *)values)[k] = py.Utf8(v);
}

static PyObject *value_in(int type, const void *values, size_t k)
{
    if (type == NCFMU_TYPE_REAL) return py.FloatFrom(((const fmi2Real *)values)[k]);
    if (type == NCFMU_TYPE_INTEGER) return py.LongFrom(((const fmi2Integer *)values)[k]);
    if (type == NCFMU_TYPE_BOOLEAN) return py.BoolFrom(((const fmi2Boolean *)values)[k] != fmi2False);
    return py.StrFrom(((const fmi2String *)values)[k]);
}

static int all_of(Inst *i, const fmi2ValueReference vr[], size_t n, int causality)
{
    for (size_t k = 0; k < n; k++)
        if (i->causality[vr[k]] != causality) return 0;
    return 1;
}

static fmi2Status get_values(fmi2Component c, const char *fmi_call, const fmi2ValueReference vr[], size_t n,
                             void *values, int type)
{
    Inst *i = checked(c, fmi_call, P_GETTABLE);
    if (!i || !refs_ok(i, fmi_call, vr, n, values, type, 0)) return fmi2Error;
    if (n == 0) return fmi2OK;
    PyGILState_STATE g = py.GILEnsure();
    fmi2Status st = fmi2OK;
    if (type != NCFMU_TYPE_STRING && all_of(i, vr, n, NCFMU_CAUSALITY_OUTPUT)) {
        /* the master's every-step call: straight from the outputs dict */
        PyObject *out = py.GetAttr(i->slave, names[N_OUT]);
        for (size_t k = 0; out && k < n; k++) {
            PyObject *v = py.DictGetItem(out, i->port_name[vr[k]]);         /* borrowed */
            if (!v) { st = fmi2Error; break; }
            value_out(v, type, values, k);
        }
        if (!out) st = fmi2Error;
        py_drop(out);
    } else {
        PyObject *list = py.ListNew((Py_ssize_t_)n);
        for (size_t k = 0; list && k < n; k++) py.ListSetItem(list, (Py_ssize_t_)k, py.LongFrom((long)vr[k]));
        PyObject *got = list ? call(i, fmi_call, N_GET, list, NULL, NULL) : NULL;
        py_drop(list);
        if (!got || py.SeqSize(got) != (Py_ssize_t_)n) st = fmi2Error;
        for (size_t k = 0; st == fmi2OK && k < n; k++) {
            PyObject *v = py.SeqGetItem(got, (Py_ssize_t_)k);
            if (!v) { st = fmi2Error; break; }
            value_out(v, type, values, k);
            py_drop(v);                   /* a string stays alive in ``got``, kept below */
        }
        if (type == NCFMU_TYPE_STRING && st == fmi2OK) { py_drop(i->strings); i->strings = got; got = NULL; }
        py_drop(got);
    }
    if (py.Occurred()) {
        char text[512];
        py_error_text(text, sizeof text);
        FMI2_SAY(&i->log, fmi2Error, "logStatusError", "%s: a value could not be read as %s: %s", fmi_call,
                 type_name(type), text);
        st = fmi2Error;
    }
    flush_log(i);
    py.GILRelease(g);
    return st;
}

static fmi2Status set_values(fmi2Component c, const char *fmi_call, const fmi2ValueReference vr[], size_t n,
                             const void *values, int type)
{
    Inst *i = checked(c, fmi_call, P_SETTABLE);
    if (!i || !refs_ok(i, fmi_call, vr, n, values, type, 1)) return fmi2Error;
    for (size_t k = 0; type == NCFMU_TYPE_STRING && k < n; k++) {
        fmi2String s = ((const fmi2String *)values)[k];
        if (!s || !fmi2_utf8_ok((const unsigned char *)s)) {
            FMI2_SAY(&i->log, fmi2Error, "logStatusError", "%s: value reference %u: %s", fmi_call, vr[k],
                     s ? "not valid UTF-8 text" : "a NULL string");
            return fmi2Error;
        }
    }
    if (n == 0) return fmi2OK;
    PyGILState_STATE g = py.GILEnsure();
    fmi2Status st = fmi2OK;
    if (type != NCFMU_TYPE_STRING && all_of(i, vr, n, NCFMU_CAUSALITY_INPUT)) {
        /* the master's every-step call: straight into the inputs dict */
        for (size_t k = 0; k < n && st == fmi2OK; k++) {
            PyObject *v = value_in(type, values, k);
            if (!v || py.DictSetItem(i->inputs, i->port_name[vr[k]], v) != 0) st = fmi2Error;
            py_drop(v);
        }
    } else {
        PyObject *refs = py.ListNew((Py_ssize_t_)n), *vals = py.ListNew((Py_ssize_t_)n);
        for (size_t k = 0; refs && vals && k < n; k++) {
            py.ListSetItem(refs, (Py_ssize_t_)k, py.LongFrom((long)vr[k]));
            py.ListSetItem(vals, (Py_ssize_t_)k, value_in(type, values, k));
        }
        st = refs && vals ? call_status(i, fmi_call, N_SET, refs, vals, NULL) : fmi2Error;
        py_drop(refs); py_drop(vals);
    }
    if (py.Occurred()) py.Clear();
    flush_log(i);
    py.GILRelease(g);
    return st;
}

#define GETTER(name, ctype, type) \
    fmi2Status name(fmi2Component c, const fmi2ValueReference vr[], size_t n, ctype v[]) \
    { return get_values(c, #name, vr, n, v, type); }
#define SETTER(name, ctype, type) \
    fmi2Status name(fmi2Component c, const fmi2ValueReference vr[], size_t n, const ctype v[]) \
    { return set_values(c, #name, vr, n, v, type); }
GETTER(fmi2GetReal, fmi2Real, NCFMU_TYPE_REAL)
GETTER(fmi2GetInteger, fmi2Integer, NCFMU_TYPE_INTEGER)
GETTER(fmi2GetBoolean, fmi2Boolean, NCFMU_TYPE_BOOLEAN)
GETTER(fmi2GetString, fmi2String, NCFMU_TYPE_STRING)
SETTER(fmi2SetReal, fmi2Real, NCFMU_TYPE_REAL)
SETTER(fmi2SetInteger, fmi2Integer, NCFMU_TYPE_INTEGER)
SETTER(fmi2SetBoolean, fmi2Boolean, NCFMU_TYPE_BOOLEAN)
SETTER(fmi2SetString, fmi2String, NCFMU_TYPE_STRING)

/* ---- stepping ------------------------------------------------------------------------------------- */
fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean no_set_prior_state)
{
    (void)no_set_prior_state;
    Inst *i = checked(c, "fmi2DoStep", P_STEP);
    if (!i || !fmi2_step_ok(&i->log, t, h) || !fmi2_step_ns_ok(&i->log, h)
        || !fmi2_continues_ok(&i->log, i->next_time, t)) return fmi2Error;
    PyGILState_STATE g = py.GILEnsure();
    PyObject *a = py.FloatFrom(t), *b = py.FloatFrom(h);
    fmi2Status st = (a && b) ? call_status(i, "fmi2DoStep", N_DO_STEP, a, b, NULL) : fmi2Error;
    py_drop(a); py_drop(b);
    flush_log(i);
    py.GILRelease(g);
    if (st <= fmi2Warning) i->next_time = t + h;
    return st;
}

fmi2Status fmi2CancelStep(fmi2Component c)
{
    Inst *i = checked(c, "fmi2CancelStep", P_STEP);
    if (!i) return fmi2Error;
    FMI2_SAY(&i->log, fmi2Error, "logStatusError", "fmi2CancelStep: no step is pending (this FMU steps synchronously)");
    return fmi2Error;
}

static fmi2Status not_provided(fmi2Component c, const char *call, const char *why)
{
    Inst *i = checked(c, call, P_ANY);
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

/* Status queries: only fmi2LastSuccessfulTime means something (no asynchronous steps). */
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind k, fmi2Real *v)
{
    Inst *i = checked(c, "fmi2GetRealStatus", P_ANY);
    if (!i || !v) return fmi2Error;
    if (k == fmi2LastSuccessfulTime) { *v = i->next_time; return fmi2OK; }
    FMI2_SAY(&i->log, fmi2Discard, "logStatusDiscard", "fmi2GetRealStatus: only fmi2LastSuccessfulTime is "
             "available (no asynchronous steps)");
    return fmi2Discard;
}

#define STATUS_QUERY(name, ctype)                                                                   \
    fmi2Status name(fmi2Component c, const fmi2StatusKind k, ctype *v)                               \
    {                                                                                                \
        (void)k;                                                                                     \
        Inst *i = checked(c, #name, P_ANY);                                                          \
        if (!i || !v) return fmi2Error;                                                              \
        FMI2_SAY(&i->log, fmi2Discard, "logStatusDiscard", #name ": nothing to report (no asynchronous steps)"); \
        return fmi2Discard;                                                                          \
    }
STATUS_QUERY(fmi2GetStatus, fmi2Status)
STATUS_QUERY(fmi2GetIntegerStatus, fmi2Integer)
STATUS_QUERY(fmi2GetBooleanStatus, fmi2Boolean)
STATUS_QUERY(fmi2GetStringStatus, fmi2String)

/* ---- FMU states: handles of this instance; any other is refused, never dereferenced ------------------ */
static State *state_find(Inst *i, const char *call, fmi2FMUstate s)
{
    for (size_t k = 0; k < i->n_states; k++)
        if (i->states[k].handle == (uintptr_t)s) return &i->states[k];
    FMI2_SAY(&i->log, fmi2Error, "logStatusError", "%s: %p is not a live FMU state of this instance (freed, of "
             "another instance or FMU, or never made)", call, s);
    return NULL;
}

static fmi2FMUstate state_add(Inst *i, PyObject *object, double time)
{
    if (i->n_states == i->cap_states) {
        size_t cap = i->cap_states ? 2 * i->cap_states : 8;
        State *grown = realloc(i->states, cap * sizeof *grown);
        if (!grown) { py_drop(object); return NULL; }
        i->states = grown;
        i->cap_states = cap;
    }
    uintptr_t handle = fmi2_state_handle();
    if (!handle) {
        FMI2_SAY(&i->log, fmi2Error, "logStatusError", "no new FMU-state handle can be made");
        py_drop(object);
        return NULL;
    }
    i->states[i->n_states++] = (State){handle, object, time};
    return (fmi2FMUstate)handle;
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s)
{
    Inst *i = checked(c, "fmi2GetFMUstate", P_ANY);
    if (!i) return fmi2Error;
    if (!s) {
        FMI2_SAY(&i->log, fmi2Error, "logStatusError", "fmi2GetFMUstate: the FMUstate pointer is NULL");
        return fmi2Error;
    }
    State *old = *s ? state_find(i, "fmi2GetFMUstate", *s) : NULL;
    if (*s && !old) return fmi2Error;
    PyGILState_STATE g = py.GILEnsure();
    PyObject *object = call(i, "fmi2GetFMUstate", N_GET_STATE, NULL, NULL, NULL);
    if (object && old) {                  /* FMI: a given state is overwritten */
        py_drop(old->object);
        old->object = object;
        old->time = i->next_time;
    } else if (object) {
        *s = state_add(i, object, i->next_time);
    }
    flush_log(i);
    py.GILRelease(g);
    return object && *s ? fmi2OK : fmi2Error;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s)
{
    Inst *i = checked(c, "fmi2SetFMUstate", P_ANY);
    State *state = i ? state_find(i, "fmi2SetFMUstate", s) : NULL;
    if (!state) return fmi2Error;
    PyGILState_STATE g = py.GILEnsure();
    fmi2Status st = call_status(i, "fmi2SetFMUstate", N_SET_STATE, state->object, NULL, NULL);
    flush_log(i);
    py.GILRelease(g);
    if (st <= fmi2Warning) i->next_time = state->time;      /* steps go on from the state's time */
    return st;
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s)
{
    Inst *i = checked(c, "fmi2FreeFMUstate", P_ANY);
    if (!i) return fmi2Error;
    if (!s || !*s) return fmi2OK;
    State *state = state_find(i, "fmi2FreeFMUstate", *s);
    if (!state) return fmi2Error;
    PyGILState_STATE g = py.GILEnsure();
    py_drop(state->object);
    py.GILRelease(g);
    *state = i->states[--i->n_states];
    *s = NULL;
    return fmi2OK;
}

/* The serialized state: the Python side's bytes, then STATE_TRAILER and the state's time, so that a state
 * restored from bytes continues from its own time. */
#define TRAILER_SIZE NCFMU_STATE_TRAILER_SIZE
#define STATE_TRAILER NCFMU_STATE_TRAILER
_Static_assert(sizeof NCFMU_STATE_TRAILER - 1 + sizeof(double) == NCFMU_STATE_TRAILER_SIZE, "trailer: 8 bytes + a double");

static PyObject *serialized(Inst *i, const char *fmi_call, fmi2FMUstate s)
{
    State *state = state_find(i, fmi_call, s);
    return state ? call(i, fmi_call, N_SERIALIZE, state->object, NULL, NULL) : NULL;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *size)
{
    Inst *i = checked(c, "fmi2SerializedFMUstateSize", P_ANY);
    if (!i || !size) return fmi2Error;
    PyGILState_STATE g = py.GILEnsure();
    PyObject *bytes = serialized(i, "fmi2SerializedFMUstateSize", s);
    char *data = NULL;
    Py_ssize_t_ n = 0;
    int ok = bytes && py.BytesAs(bytes, &data, &n) == 0;
    if (ok) *size = (size_t)n + TRAILER_SIZE;
    if (py.Occurred()) py.Clear();
    py_drop(bytes);
    flush_log(i);
    py.GILRelease(g);
    return ok ? fmi2OK : fmi2Error;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t size)
{
    Inst *i = checked(c, "fmi2SerializeFMUstate", P_ANY);
    if (!i) return fmi2Error;
    PyGILState_STATE g = py.GILEnsure();
    PyObject *bytes = serialized(i, "fmi2SerializeFMUstate", s);
    char *data = NULL;
    Py_ssize_t_ n = 0;
    fmi2Status st = fmi2Error;
    if (bytes && py.BytesAs(bytes, &data, &n) == 0) {
        size_t needed = (size_t)n + TRAILER_SIZE;
        if (!b || size < needed) {
            FMI2_SAY(&i->log, fmi2Error, "logStatusError", "fmi2SerializeFMUstate: %s (%zu bytes given, %zu needed)",
                     !b ? "the buffer is NULL" : "the buffer is too small", size, needed);
        } else {
            double time = state_find(i, "fmi2SerializeFMUstate", s)->time;
            memcpy(b, data, (size_t)n);
            memcpy(b + n, STATE_TRAILER, sizeof STATE_TRAILER - 1);
            memcpy(b + n + sizeof STATE_TRAILER - 1, &time, sizeof time);
            st = fmi2OK;
        }
    }
    if (py.Occurred()) py.Clear();
    py_drop(bytes);
    flush_log(i);
    py.GILRelease(g);
    return st;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t size, fmi2FMUstate *s)
{
    Inst *i = checked(c, "fmi2DeSerializeFMUstate", P_ANY);
    if (!i) return fmi2Error;
    if (!s || (size && !b)) {
        FMI2_SAY(&i->log, fmi2Error, "logStatusError", "fmi2DeSerializeFMUstate: the %s is NULL",
                 !s ? "FMUstate pointer" : "byte array");
        return fmi2Error;
    }
    if (size < TRAILER_SIZE || memcmp(b + size - TRAILER_SIZE, STATE_TRAILER, sizeof STATE_TRAILER - 1) != 0) {
        FMI2_SAY(&i->log, fmi2Error, "logStatusError", "fmi2DeSerializeFMUstate refused: %zu bytes that are not a "
                 "state this FMU serialized (no time trailer)", size);
        return fmi2Error;
    }
    double time;
    memcpy(&time, b + size - sizeof time, sizeof time);
    if (!isfinite(time)) {
        FMI2_SAY(&i->log, fmi2Error, "logStatusError", "fmi2DeSerializeFMUstate refused: the state's time is %g", time);
        return fmi2Error;
    }
    PyGILState_STATE g = py.GILEnsure();
    PyObject *bytes = py.BytesFrom((const char *)b, (Py_ssize_t_)(size - TRAILER_SIZE));
    PyObject *object = bytes ? call(i, "fmi2DeSerializeFMUstate", N_DESERIALIZE, bytes, NULL, NULL) : NULL;
    py_drop(bytes);
    fmi2Status st = fmi2Error;
    if (object && object != py.None) {
        *s = state_add(i, object, time);
        st = *s ? fmi2OK : fmi2Error;
    } else {
        py_drop(object);                  /* None: refused, the reason is in the log */
    }
    if (py.Occurred()) py.Clear();
    flush_log(i);
    py.GILRelease(g);
    return st;
}
