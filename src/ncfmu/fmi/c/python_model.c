/*
 * ncfmu's Python FMUs: the Python runtime as a model behind the model interface (model.h).
 *
 * The FMI layer (fmi2_functions.c, the same file the native FMUs are built from) checks every call: the
 * instance handle, the state machine, value references, their types and settability, String values,
 * step times. This file drives the Python slave (fmi/adapter.py) through the calls listed in the contract
 * (fmi/contract.py, generated into ncfmu_contract.h; see docs/architecture.md). Each call returns its
 * status; the log messages it queued are taken after the call (when there are any: the model reads the
 * length of the slave's pending_log) and sent to the host's logger: errors and warnings always, the rest only
 * with debug logging on. pythonfmu provides the Python slave API (Fmi2Slave) and the packaging; its export
 * library is not used.
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

/* The official FMI 2.0 headers (fmpy ships them; the builder passes -I<fmpy>/c-code), the model interface
 * and the contract with the Python side. */
#include "fmi2Functions.h"
#include "model.h"
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
    int (*DictNext)(PyObject *, Py_ssize_t_ *, PyObject **, PyObject **);
    int (*RichCompareBool)(PyObject *, PyObject *, int);
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
    PyObject *(*CallFunction)(PyObject *, ...);
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
    void (*Normalize)(PyObject **, PyObject **, PyObject **);
    int (*SetTraceback)(PyObject *, PyObject *);
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
    L(DictGetItemString, "PyDict_GetItemString") L(DictNext, "PyDict_Next")
    L(RichCompareBool, "PyObject_RichCompareBool")
    L(DictSetItem, "PyDict_SetItem") L(FloatAs, "PyFloat_AsDouble") L(FloatFrom, "PyFloat_FromDouble")
    L(LongAs, "PyLong_AsLong") L(LongFrom, "PyLong_FromLong") L(IsTrue, "PyObject_IsTrue")
    L(BoolFrom, "PyBool_FromLong") L(GetAttr, "PyObject_GetAttr") L(GetAttrString, "PyObject_GetAttrString")
    L(CallMethod, "PyObject_CallMethodObjArgs") L(CallFunction, "PyObject_CallFunctionObjArgs")
    L(StrFrom, "PyUnicode_FromString")
    L(InternFrom, "PyUnicode_InternFromString") L(Utf8, "PyUnicode_AsUTF8") L(SeqSize, "PySequence_Size")
    L(SeqGetItem, "PySequence_GetItem") L(SeqContains, "PySequence_Contains") L(ListNew, "PyList_New")
    L(ListSetItem, "PyList_SetItem") L(ListInsert, "PyList_Insert") L(ListSize, "PyList_Size") L(SysGet, "PySys_GetObject")
    L(Import, "PyImport_ImportModule") L(BytesFrom, "PyBytes_FromStringAndSize")
    L(BytesAs, "PyBytes_AsStringAndSize") L(Occurred, "PyErr_Occurred") L(Fetch, "PyErr_Fetch")
    L(Normalize, "PyErr_NormalizeException") L(SetTraceback, "PyException_SetTraceback")
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

const char FMU_MODEL_GUID[] = NCFMU_GUID;
const char FMU_MODEL_IDENTIFIER[] = NCFMU_CLASS;

/* ---- the model ----------------------------------------------------------------------------------- */
struct Model {
    const Fmi2Log *log;                   /* the instance's: the host's logger, its debug-logging choice */
    char name[128];
    char resources[4096];                 /* the resources folder, for fmu_model_reset's new slave */
    int visible;
    PyObject *slave, *inputs;
    PyObject *pending;                    /* the slave's pending_log: fmi_take_log only when not empty */
    unsigned n;                           /* value references 0 .. n-1 */
    VarInfo *vars;                        /* by value reference (name NULL: none) */
    PyObject **port_name;                 /* by value reference: the variable's name as a str */
    PyObject *strings;                    /* the last Get's strings, kept alive until the next */
    unsigned char *bytes;                 /* the last serialized state */
    /* The per-step boundary without Python objects (docs/architecture.md): the outputs as the slave's ``out``
     * held them after its last call, read by the fast fmi2Get* with no GIL (valid until the next call into
     * Python: only Python code changes ``out``); the inputs set by the fast fmi2Set*, written into the slave's
     * ``inputs`` before the next call into Python (only Python code reads them). By value reference. */
    unsigned *out_vrs, n_out;             /* the Real, Integer and Boolean outputs */
    /* ``out`` read in its own order (PyDict_Next, no lookups): the key met at each position last time (a
     * reference held, so the same address is the same string) and the output's vr there (UINT32_MAX: none);
     * a key not where it was makes the map anew. The value met there last time is held too: the same object (a
     * value is immutable) is the same value, not read again -- a status the controller did not write this step, a
     * bool, a small int. */
    PyObject **map_key, **map_value;
    unsigned *map_vr, n_map;
    double *out_real;
    int *out_int, out_valid;
    double *in_real;
    int *in_int;
    unsigned char *in_pending;            /* set and not yet handed over */
    /* What the inputs dict holds, as handed over last (known: 1), while only the controller's step has run since
     * (it reads the dict, never writes it): a value set again to the same bits is not written again. */
    double *handed_real;
    int *handed_int;
    unsigned char *handed_known;
    unsigned *pending_vrs, n_pending;
    /* The slave's fmi_stepper: the controller's step a DoStep calls directly (NULL: not taken since the last other
     * call into the slave, which may have rebound its controller; None: no controller, fmi_do_step says why). */
    PyObject *stepper;
    PyObject *out_dict;                   /* the slave's ``out`` (NULL: not taken since the last other call) */
};

/* ---- calls into the Python slave (the GIL held) ---------------------------------------------------- */
/* Send what the slave logged to the host (errors and warnings always, the rest with debug logging on:
 * fmi2_say_text); nothing is called when nothing was logged. */
static void flush_log(Model *m)
{
    if (!m->slave) return;
    Py_ssize_t_ pending = py.ListSize(m->pending);          /* a C call: nothing logged, nothing called */
    if (pending == 0) return;
    if (pending < 0) py.Clear();                             /* not a list: take the log anyway */
    m->out_valid = 0;                                        /* Python code runs */
    PyObject *taken = py.CallMethod(m->slave, names[N_TAKE_LOG], NULL);
    Py_ssize_t_ n = taken ? py.SeqSize(taken) : 0;
    for (Py_ssize_t_ k = 0; k < n; k++) {
        PyObject *msg = py.SeqGetItem(taken, k);
        PyObject *st = msg ? py.SeqGetItem(msg, 0) : NULL, *cat = msg ? py.SeqGetItem(msg, 1) : NULL;
        PyObject *text = msg ? py.SeqGetItem(msg, 2) : NULL;
        long status = st ? py.LongAs(st) : ModelError;
        const char *c_s = cat ? py.Utf8(cat) : NULL, *t_s = text ? py.Utf8(text) : NULL;
        if (t_s)
            fmi2_say_text(m->log, status < ModelOK || status > ModelFatal ? ModelError : (ModelStatus)status,
                          c_s ? c_s : "logAll", t_s);
        py_drop(st); py_drop(cat); py_drop(text); py_drop(msg);
    }
    if (py.Occurred()) py.Clear();
    py_drop(taken);
}

static PyObject *value_in(VarType type, const void *values, size_t k);
static void value_out(PyObject *v, VarType type, void *values, size_t k);

/* The inputs set since the last call into Python, written into the slave's inputs dict (in the order first set;
 * a value set twice is written once, the last); 0 with a Python exception pending if one could not be. */
static int hand_inputs(Model *m)
{
    int ok = 1;
    for (unsigned k = 0; k < m->n_pending; k++) {
        unsigned vr = m->pending_vrs[k];
        m->in_pending[vr] = 0;
        if (!ok) continue;
        VarType type = m->vars[vr].type;
        int real = type == V_REAL;
        if (m->handed_known[vr] && (real ? memcmp(&m->handed_real[vr], &m->in_real[vr], sizeof(double)) == 0
                                         : m->handed_int[vr] == m->in_int[vr]))
            continue;                                        /* the dict holds this very value */
        m->handed_known[vr] = 0;
        PyObject *v = real ? value_in(type, m->in_real, vr) : value_in(type, m->in_int, vr);
        if (!v || py.DictSetItem(m->inputs, m->port_name[vr], v) != 0) ok = 0;
        py_drop(v);
        if (!ok) continue;
        if (real) m->handed_real[vr] = m->in_real[vr];
        else m->handed_int[vr] = m->in_int[vr];
        m->handed_known[vr] = 1;
    }
    m->n_pending = 0;
    return ok;
}

static void map_drop(Model *m)
{
    for (unsigned k = 0; k < m->n_map; k++) { py_drop(m->map_key[k]); py_drop(m->map_value[k]); }
    free(m->map_key); free(m->map_value); free(m->map_vr);
    m->map_key = m->map_value = NULL; m->map_vr = NULL; m->n_map = 0;
}

/* The map of ``out``'s positions to outputs, made anew; 0 if ``out`` lacks an output (or is no dict). */
static int map_make(Model *m, PyObject *out)
{
    map_drop(m);
    Py_ssize_t_ pos = 0, count = 0;
    PyObject *key, *value;
    while (py.DictNext(out, &pos, &key, &value)) count++;
    if (count == 0 && m->n_out) return 0;
    m->map_key = calloc(count ? (size_t)count : 1, sizeof *m->map_key);
    m->map_value = calloc(count ? (size_t)count : 1, sizeof *m->map_value);
    m->map_vr = calloc(count ? (size_t)count : 1, sizeof *m->map_vr);
    if (!m->map_key || !m->map_value || !m->map_vr) { map_drop(m); return 0; }
    unsigned found = 0;
    pos = 0;
    while (py.DictNext(out, &pos, &key, &value) && m->n_map < (unsigned)count) {
        unsigned at = UINT32_MAX;
        for (unsigned k = 0; k < m->n_out && at == UINT32_MAX; k++)
            if (py.RichCompareBool(key, m->port_name[m->out_vrs[k]], 2 /* Py_EQ */) == 1) at = m->out_vrs[k];
        if (py.Occurred()) py.Clear();
        if (at != UINT32_MAX) found++;
        py.IncRef(key);
        m->map_key[m->n_map] = key;
        m->map_vr[m->n_map++] = at;
    }
    if (found != m->n_out) { map_drop(m); return 0; }
    return 1;
}

/* Every Real, Integer and Boolean output from the slave's ``out`` into the model's copy; 0 (the copy invalid, no
 * exception left pending) if one cannot be read: the Get then reads ``out`` itself and says why. */
static int take_outputs(Model *m)
{
    m->out_valid = 0;
    if (!m->out_dict) m->out_dict = py.GetAttr(m->slave, names[N_OUT]);
    PyObject *out = m->out_dict;
    int ok = out != NULL;
    for (int attempt = 0; ok && attempt < 2; attempt++) {
        Py_ssize_t_ pos = 0;
        PyObject *key, *v;
        unsigned k = 0;
        int same = m->n_map > 0 || m->n_out == 0;
        while (same && py.DictNext(out, &pos, &key, &v)) {
            if (k >= m->n_map || m->map_key[k] != key) { same = 0; break; }
            unsigned vr = m->map_vr[k];
            PyObject **held = &m->map_value[k++];
            if (vr == UINT32_MAX || v == *held) continue;    /* not an output; the very value read before */
            VarType type = m->vars[vr].type;
            if (type == V_REAL) value_out(v, type, m->out_real, vr);
            else value_out(v, type, m->out_int, vr);
            if (py.Occurred()) continue;                     /* not a value of its type: the Get says which */
            py.IncRef(v);
            py_drop(*held);
            *held = v;
        }
        if (same && k == m->n_map) break;                  /* every output read */
        ok = attempt == 0 && map_make(m, out);               /* a new dict, or keys changed: map it, read again */
    }
    if (py.Occurred()) { py.Clear(); ok = 0; }
    m->out_valid = ok;
    return ok;
}

/* The inputs set since the last call handed to the slave, before a call into it; 0 (logged) if they could not be. */
static int inputs_handed(Model *m, const char *fmi_call)
{
    if (m->n_pending == 0 || hand_inputs(m)) return 1;
    char text[512];
    py_error_text(text, sizeof text);
    FMI2_SAY(m->log, ModelError, "logStatusError", "%s: the inputs set before could not be handed to the Python "
             "slave: %s", fmi_call, text);
    return 0;
}

/* Python code other than the controller's step is about to run: the slave may rebind its controller and ``out`` and
 * write its inputs dict (a restored state, a reset), so what the shim holds of them is taken anew. */
static void held_forget(Model *m)
{
    py_drop(m->stepper); py_drop(m->out_dict);
    m->stepper = m->out_dict = NULL;
    if (m->handed_known) memset(m->handed_known, 0, m->n ? m->n : 1);
}

/* slave.<entry>(a, b, c): a new reference, or NULL after logging the exception that escaped. */
static PyObject *call(Model *m, const char *fmi_call, int entry, PyObject *a, PyObject *b, PyObject *c)
{
    m->out_valid = 0;                                        /* Python code runs: ``out`` may change */
    if (entry != N_STEP_REPORT && entry != N_STEPPER && entry != N_GET)   /* ... and its controller, ``out``, inputs */
        held_forget(m);
    if (!inputs_handed(m, fmi_call)) return NULL;
    PyObject *r = py.CallMethod(m->slave, names[entry], a, b, c, NULL);
    if (!r) {
        char text[512];
        py_error_text(text, sizeof text);
        FMI2_SAY(m->log, ModelError, "logStatusError", "%s: the Python slave raised: %s", fmi_call, text);
    }
    return r;
}

/* A call that returns a status (the contract's STATUS). */
static ModelStatus call_status(Model *m, const char *fmi_call, int entry, PyObject *a, PyObject *b, PyObject *c)
{
    PyObject *r = call(m, fmi_call, entry, a, b, c);
    long st = r ? py.LongAs(r) : NCFMU_STATUS_ERROR;
    if (py.Occurred()) { py.Clear(); st = NCFMU_STATUS_ERROR; }
    py_drop(r);
    if (st < NCFMU_STATUS_OK || st > NCFMU_STATUS_FATAL) st = NCFMU_STATUS_ERROR;
    return st == NCFMU_STATUS_FATAL ? ModelError : (ModelStatus)st;   /* nothing the slave says breaks the instance */
}

static ModelStatus simple_call(Model *m, const char *fmi_call, int entry)
{
    PyGILState_STATE g = py.GILEnsure();
    ModelStatus st = call_status(m, fmi_call, entry, NULL, NULL, NULL);
    flush_log(m);
    py.GILRelease(g);
    return st;
}

/* ---- making and dropping the Python slave -------------------------------------------------------- */
static void slave_drop(Model *m)
{
    held_forget(m);
    py_drop(m->slave); py_drop(m->inputs); py_drop(m->pending); py_drop(m->strings);
    for (unsigned k = 0; m->port_name && k < m->n; k++) py_drop(m->port_name[k]);
    free(m->port_name); free(m->vars);
    free(m->out_vrs); free(m->out_real); free(m->out_int); free(m->in_real); free(m->in_int); free(m->in_pending);
    free(m->pending_vrs); free(m->handed_real); free(m->handed_int); free(m->handed_known);
    map_drop(m);
    m->slave = m->inputs = m->pending = m->strings = NULL;
    m->port_name = NULL; m->vars = NULL;
    m->out_vrs = m->pending_vrs = NULL; m->out_real = m->in_real = NULL; m->out_int = m->in_int = NULL;
    m->in_pending = NULL;
    m->handed_real = NULL; m->handed_int = NULL; m->handed_known = NULL;
    m->n = m->n_out = m->n_pending = 0;
    m->out_valid = 0;
}

/* The slave class: the model script's module, imported once per process from the FMU's resources folder
 * (its folder goes on sys.path then, not again: a host that extracts the FMU anew per run adds no entry a run). */
static PyObject *slave_class(const Fmi2Log *log, const char *fmi_call, const char *resources)
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
        FMI2_SAY(log, ModelError, "logStatusError", "%s: the model %s could not be loaded from %s: %s", fmi_call,
                 NCFMU_MODULE, resources, text);
    }
    return cls;
}

/* The contract's codes -> the model interface's. */
static VarType var_type(long code)
{
    return code == NCFMU_TYPE_INTEGER ? V_INTEGER : code == NCFMU_TYPE_BOOLEAN ? V_BOOLEAN
         : code == NCFMU_TYPE_STRING ? V_STRING : V_REAL;
}

static VarCausality var_causality(long code)
{
    return code == NCFMU_CAUSALITY_PARAMETER ? V_PARAMETER : code == NCFMU_CAUSALITY_INPUT ? V_INPUT
         : code == NCFMU_CAUSALITY_OUTPUT ? V_OUTPUT : V_OTHER;
}

/* A new Python slave for ``m`` and its table of variables; 0 (logged) if it cannot be made. */
static int slave_make(Model *m, const char *fmi_call)
{
    PyObject *cls = slave_class(m->log, fmi_call, m->resources);
    if (!cls) return 0;
    PyObject *n = py.StrFrom(m->name), *res = py.StrFrom(m->resources), *vis = py.BoolFrom(m->visible);
    PyObject *slave = (n && res && vis) ? py.CallMethod(cls, names[N_INSTANTIATE], n, res, vis, NULL) : NULL;
    py_drop(n); py_drop(res); py_drop(vis); py_drop(cls);
    PyObject *ports = slave ? py.CallMethod(slave, names[N_PORTS], NULL) : NULL;
    PyObject *inputs = slave ? py.GetAttr(slave, names[N_INPUTS]) : NULL;
    PyObject *pending = slave ? py.GetAttr(slave, names[N_PENDING_LOG]) : NULL;
    if (!slave || !ports || !inputs || !pending) {
        char text[512];
        py_error_text(text, sizeof text);
        FMI2_SAY(m->log, ModelError, "logStatusError", "%s: the slave %s could not be made: %s", fmi_call,
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
    m->n = n_vr;
    m->port_name = calloc(n_vr ? n_vr : 1, sizeof *m->port_name);
    m->vars = calloc(n_vr ? n_vr : 1, sizeof *m->vars);
    for (Py_ssize_t_ k = 0; k < count && m->port_name && m->vars; k++) {
        PyObject *p = py.SeqGetItem(ports, k);
        PyObject *f[5] = {NULL, NULL, NULL, NULL, NULL};
        for (int j = 0; p && j < 5; j++) f[j] = py.SeqGetItem(p, j);
        long vr = f[0] ? py.LongAs(f[0]) : -1;
        const char *name = f[4] ? py.Utf8(f[4]) : NULL;
        if (vr >= 0 && (unsigned long)vr < n_vr && name && !m->port_name[vr]) {
            VarInfo *v = &m->vars[vr];
            v->name = name;                                       /* lives as long as port_name[vr] */
            v->type = var_type(f[1] ? py.LongAs(f[1]) : 0);
            v->causality = var_causality(f[2] ? py.LongAs(f[2]) : 0);
            v->tunable = !(f[3] && py.IsTrue(f[3]) > 0);
            v->rule = NULL;                                       /* the Python side judges every value */
            m->port_name[vr] = f[4];
            f[4] = NULL;                                          /* kept */
        }
        for (int j = 0; j < 5; j++) py_drop(f[j]);
        py_drop(p);
    }
    py_drop(ports);
    if (py.Occurred()) py.Clear();
    m->slave = slave;
    m->inputs = inputs;
    m->pending = pending;
    if (!m->port_name || !m->vars) { slave_drop(m); return 0; }
    size_t size = n_vr ? n_vr : 1;
    m->out_vrs = calloc(size, sizeof *m->out_vrs);
    m->pending_vrs = calloc(size, sizeof *m->pending_vrs);
    m->out_real = calloc(size, sizeof *m->out_real);
    m->in_real = calloc(size, sizeof *m->in_real);
    m->out_int = calloc(size, sizeof *m->out_int);
    m->in_int = calloc(size, sizeof *m->in_int);
    m->in_pending = calloc(size, 1);
    m->handed_real = calloc(size, sizeof *m->handed_real);
    m->handed_int = calloc(size, sizeof *m->handed_int);
    m->handed_known = calloc(size, 1);
    if (!m->out_vrs || !m->pending_vrs || !m->out_real || !m->in_real || !m->out_int || !m->in_int || !m->in_pending
        || !m->handed_real || !m->handed_int || !m->handed_known) {
        slave_drop(m);
        return 0;
    }
    for (unsigned vr = 0; vr < n_vr; vr++)
        if (m->vars[vr].name && m->vars[vr].causality == V_OUTPUT && m->vars[vr].type != V_STRING)
            m->out_vrs[m->n_out++] = vr;
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

/* ---- the model interface ------------------------------------------------------------------------- */
Model *fmu_model_new(const char *fmi_call, const char *name, const char *resources, int visible,
                     const Fmi2Log *log)
{
    if (!binary_ready()) {
        FMI2_SAY(log, ModelError, "logStatusError", "%s",
                 python_problem[0] ? python_problem : "ncfmu: the Python runtime's API could not be found");
        return NULL;
    }
    Model *m = calloc(1, sizeof *m);
    if (!m) return NULL;
    m->log = log;
    snprintf(m->name, sizeof m->name, "%s", name);
    snprintf(m->resources, sizeof m->resources, "%s", resources);
    m->visible = visible;
    PyGILState_STATE g = py.GILEnsure();
    int made = names_ready() && slave_make(m, fmi_call);
    if (made) flush_log(m);
    py.GILRelease(g);
    if (!made) { free(m); return NULL; }
    return m;
}

void fmu_model_free(Model *m)
{
    PyGILState_STATE g = py.GILEnsure();
    flush_log(m);
    slave_drop(m);
    py.GILRelease(g);
    free(m->bytes);
    free(m);
}

const VarInfo *fmu_model_variables(Model *m, unsigned *n)
{
    *n = m->n;
    return m->vars;
}

int fmu_model_reset(Model *m, const char *fmi_call)
{
    PyGILState_STATE g = py.GILEnsure();
    flush_log(m);
    slave_drop(m);
    int made = slave_make(m, fmi_call);
    if (made) flush_log(m);
    py.GILRelease(g);
    return made ? 0 : -1;
}

ModelStatus fmu_model_setup_experiment(Model *m, const char *fmi_call, int tolerance_defined, double tolerance,
                                      double start, int stop_defined, double stop)
{
    PyGILState_STATE g = py.GILEnsure();
    PyObject *a = py.FloatFrom(start), *b = stop_defined ? py.FloatFrom(stop) : (py.IncRef(py.None), py.None);
    PyObject *t = tolerance_defined ? py.FloatFrom(tolerance) : (py.IncRef(py.None), py.None);
    ModelStatus st = (a && b && t) ? call_status(m, fmi_call, N_SETUP_EXPERIMENT, a, b, t) : ModelError;
    py_drop(a); py_drop(b); py_drop(t);
    flush_log(m);
    py.GILRelease(g);
    return st;
}

ModelStatus fmu_model_enter_initialization(Model *m, const char *fmi_call)
{
    return simple_call(m, fmi_call, N_ENTER_INITIALIZATION);
}

ModelStatus fmu_model_exit_initialization(Model *m, const char *fmi_call)
{
    return simple_call(m, fmi_call, N_EXIT_INITIALIZATION);
}

ModelStatus fmu_model_terminate(Model *m, const char *fmi_call)
{
    return simple_call(m, fmi_call, N_TERMINATE);
}

/* A step through the slave's stepper: the controller's compiled step called from here with the inputs dict (no
 * interpreted frame, no method lookup); a step that raised or queued messages is reported to the slave, which logs
 * it as fmi_do_step does. */
static ModelStatus stepper_step(Model *m, const char *fmi_call, PyObject *t, PyObject *h)
{
    m->out_valid = 0;
    if (!inputs_handed(m, fmi_call)) return ModelError;
    PyObject *r = py.CallFunction(m->stepper, t, h, m->inputs, NULL);
    long queued = r ? py.LongAs(r) : -1;
    py_drop(r);
    if (queued == 0) return ModelOK;
    PyObject *type = NULL, *error = NULL, *trace = NULL;
    if (py.Occurred()) {                                     /* the step raised: the slave says where */
        py.Fetch(&type, &error, &trace);
        py.Normalize(&type, &error, &trace);
        if (error && trace) py.SetTraceback(error, trace);
    }
    ModelStatus st = call_status(m, fmi_call, N_STEP_REPORT, t, error ? error : py.None, NULL);
    py_drop(type); py_drop(error); py_drop(trace);
    return st;
}

/* The slave's stepper, taken when not held; 1 if there is one (a controller), 0 for fmi_do_step. */
static int stepper_taken(Model *m, const char *fmi_call)
{
    if (!m->stepper && !(m->stepper = call(m, fmi_call, N_STEPPER, NULL, NULL, NULL))) py.Clear();
    return m->stepper && m->stepper != py.None;
}

ModelStatus fmu_model_do_step(Model *m, const char *fmi_call, double t, double h)
{
    PyGILState_STATE g = py.GILEnsure();
    /* Whole nanoseconds, as fmi_do_step and native_model.c round the step (a tool's seconds differ in the last bit):
     * Python's round(h * 1e9) * 1e-9 for every finite h */
    double whole = nearbyint(h * 1e9) * 1e-9;
    int direct = isfinite(whole) && stepper_taken(m, fmi_call);
    PyObject *a = py.FloatFrom(t), *b = py.FloatFrom(direct ? whole : h);
    ModelStatus st = !(a && b) ? ModelError
                  : direct ? stepper_step(m, fmi_call, a, b) : call_status(m, fmi_call, N_DO_STEP, a, b, NULL);
    py_drop(a); py_drop(b);
    flush_log(m);
    take_outputs(m);                      /* the step's outputs, for the Gets that follow (no GIL there) */
    py.GILRelease(g);
    return st;
}

/* ---- values ---------------------------------------------------------------------------------------- */
static const char *type_name(VarType type)
{
    return type == V_REAL ? "Real" : type == V_INTEGER ? "Integer" : type == V_BOOLEAN ? "Boolean" : "String";
}

static void value_out(PyObject *v, VarType type, void *values, size_t k)
{
    if (type == V_REAL) ((double *)values)[k] = py.FloatAs(v);
    else if (type == V_INTEGER) ((int *)values)[k] = (int)py.LongAs(v);
    else if (type == V_BOOLEAN) ((int *)values)[k] = py.IsTrue(v) > 0;
    else ((const char **)values)[k] = py.Utf8(v);
}

static PyObject *value_in(VarType type, const void *values, size_t k)
{
    if (type == V_REAL) return py.FloatFrom(((const double *)values)[k]);
    if (type == V_INTEGER) return py.LongFrom(((const int *)values)[k]);
    if (type == V_BOOLEAN) return py.BoolFrom(((const int *)values)[k] != 0);
    return py.StrFrom(((const char *const *)values)[k]);
}

static int all_of(Model *m, const unsigned vr[], size_t n, VarCausality causality)
{
    for (size_t k = 0; k < n; k++)
        if (m->vars[vr[k]].causality != causality) return 0;
    return 1;
}

/* The leading references of ``vr`` that are Real, Integer or Boolean outputs, copied from the model's copy of
 * ``out`` (taken): how many (one pass, no Python). */
static inline size_t outputs_copied(const Model *m, const unsigned vr[], size_t n, VarType type, void *values)
{
    const VarInfo *vars = m->vars;
    size_t k = 0;
    if (type == V_REAL)
        for (double *to = values; k < n && vars[vr[k]].causality == V_OUTPUT; k++) to[k] = m->out_real[vr[k]];
    else
        for (int *to = values; k < n && vars[vr[k]].causality == V_OUTPUT; k++) to[k] = m->out_int[vr[k]];
    return k;
}

ModelStatus fmu_model_get(Model *m, const char *fmi_call, const unsigned vr[], size_t n, VarType type, void *values)
{
    /* the master's every-step call: the outputs taken after the step (a reference that is not an output leaves the
     * copy, and the call reads them all below) */
    if (type != V_STRING && m->out_valid && outputs_copied(m, vr, n, type, values) == n) return ModelOK;
    int outputs = type != V_STRING && all_of(m, vr, n, V_OUTPUT);
    PyGILState_STATE g = py.GILEnsure();
    ModelStatus st = ModelOK;
    if (outputs && take_outputs(m)) {
        outputs_copied(m, vr, n, type, values);
    } else if (outputs) {
        /* an output that cannot be read as its type: read ``out`` itself, to say which and why */
        PyObject *out = py.GetAttr(m->slave, names[N_OUT]);
        for (size_t k = 0; out && k < n; k++) {
            PyObject *v = py.DictGetItem(out, m->port_name[vr[k]]);         /* borrowed */
            if (!v) { st = ModelError; break; }
            value_out(v, type, values, k);
        }
        if (!out) st = ModelError;
        py_drop(out);
    } else {
        PyObject *list = py.ListNew((Py_ssize_t_)n);
        for (size_t k = 0; list && k < n; k++) py.ListSetItem(list, (Py_ssize_t_)k, py.LongFrom((long)vr[k]));
        PyObject *got = list ? call(m, fmi_call, N_GET, list, NULL, NULL) : NULL;
        py_drop(list);
        if (!got || py.SeqSize(got) != (Py_ssize_t_)n) st = ModelError;
        for (size_t k = 0; st == ModelOK && k < n; k++) {
            PyObject *v = py.SeqGetItem(got, (Py_ssize_t_)k);
            if (!v) { st = ModelError; break; }
            value_out(v, type, values, k);
            py_drop(v);                   /* a string stays alive in ``got``, kept below */
        }
        if (type == V_STRING && st == ModelOK) { py_drop(m->strings); m->strings = got; got = NULL; }
        py_drop(got);
    }
    if (py.Occurred()) {
        char text[512];
        py_error_text(text, sizeof text);
        FMI2_SAY(m->log, ModelError, "logStatusError", "%s: a value could not be read as %s: %s", fmi_call,
                 type_name(type), text);
        st = ModelError;
    }
    flush_log(m);
    py.GILRelease(g);
    return st;
}

ModelStatus fmu_model_set(Model *m, const char *fmi_call, const unsigned vr[], size_t n, VarType type,
                         const void *values)
{
    if (type != V_STRING && all_of(m, vr, n, V_INPUT)) {
        /* the master's every-step call: kept here, handed to the slave's inputs dict before its next call */
        for (size_t k = 0; k < n; k++) {
            unsigned r = vr[k];
            if (type == V_REAL) m->in_real[r] = ((const double *)values)[k];
            else if (type == V_INTEGER) m->in_int[r] = ((const int *)values)[k];
            else m->in_int[r] = ((const int *)values)[k] != 0;
            if (!m->in_pending[r]) { m->in_pending[r] = 1; m->pending_vrs[m->n_pending++] = r; }
        }
        return ModelOK;
    }
    PyGILState_STATE g = py.GILEnsure();
    ModelStatus st = ModelOK;
    {
        PyObject *refs = py.ListNew((Py_ssize_t_)n), *vals = py.ListNew((Py_ssize_t_)n);
        for (size_t k = 0; refs && vals && k < n; k++) {
            py.ListSetItem(refs, (Py_ssize_t_)k, py.LongFrom((long)vr[k]));
            py.ListSetItem(vals, (Py_ssize_t_)k, value_in(type, values, k));
        }
        st = refs && vals ? call_status(m, fmi_call, N_SET, refs, vals, NULL) : ModelError;
        py_drop(refs); py_drop(vals);
    }
    if (py.Occurred()) py.Clear();
    flush_log(m);
    py.GILRelease(g);
    return st;
}

/* ---- FMU states: the adapter's state objects ------------------------------------------------------- */
void *fmu_model_state_take(Model *m, const char *fmi_call)
{
    PyGILState_STATE g = py.GILEnsure();
    PyObject *object = call(m, fmi_call, N_GET_STATE, NULL, NULL, NULL);
    flush_log(m);
    py.GILRelease(g);
    return object;
}

ModelStatus fmu_model_state_restore(Model *m, const char *fmi_call, void *state, int initialized)
{
    (void)initialized;                    /* the adapter judges a state's parameters itself */
    PyGILState_STATE g = py.GILEnsure();
    PyObject *name = py.StrFrom(fmi_call);  /* the adapter names the call in what it refuses */
    ModelStatus st = name ? call_status(m, fmi_call, N_SET_STATE, state, name, NULL) : ModelError;
    py_drop(name);
    if (py.Occurred()) py.Clear();
    flush_log(m);
    py.GILRelease(g);
    return st;
}

void fmu_model_state_free(Model *m, void *state)
{
    (void)m;
    PyGILState_STATE g = py.GILEnsure();
    py_drop(state);
    py.GILRelease(g);
}

/* The serialized state: the Python side's bytes, then STATE_TRAILER, the state's phase (an int32: the layer's
 * P_*) and its time (a double), so that a state restored from bytes is where it was taken: in its phase, going
 * on from its time. */
#define TRAILER_SIZE NCFMU_STATE_TRAILER_SIZE
#define STATE_TRAILER NCFMU_STATE_TRAILER
#define MAGIC_SIZE (sizeof STATE_TRAILER - 1)
_Static_assert(MAGIC_SIZE + sizeof(int32_t) + sizeof(double) == NCFMU_STATE_TRAILER_SIZE,
               "trailer: 8 bytes, an int32 and a double");
_Static_assert(NCFMU_PHASE_INSTANTIATED == P_INSTANTIATED && NCFMU_PHASE_INIT == P_INIT && NCFMU_PHASE_STEP == P_STEP
               && NCFMU_PHASE_TERMINATED == P_TERMINATED, "the contract's phases are the layer's");

const unsigned char *fmu_model_serialize(Model *m, const char *fmi_call, void *state, int phase, double time,
                                         size_t *size)
{
    PyGILState_STATE g = py.GILEnsure();
    PyObject *bytes = call(m, fmi_call, N_SERIALIZE, state, NULL, NULL);
    char *data = NULL;
    Py_ssize_t_ n = 0;
    unsigned char *out = NULL;
    int32_t phase32 = phase;
    if (bytes && py.BytesAs(bytes, &data, &n) == 0 && (out = realloc(m->bytes, (size_t)n + TRAILER_SIZE))) {
        m->bytes = out;
        memcpy(out, data, (size_t)n);
        memcpy(out + n, STATE_TRAILER, MAGIC_SIZE);
        memcpy(out + n + MAGIC_SIZE, &phase32, sizeof phase32);
        memcpy(out + n + MAGIC_SIZE + sizeof phase32, &time, sizeof time);
        *size = (size_t)n + TRAILER_SIZE;
    }
    if (py.Occurred()) py.Clear();
    py_drop(bytes);
    flush_log(m);
    py.GILRelease(g);
    return out;
}

void *fmu_model_deserialize(Model *m, const char *fmi_call, const unsigned char *b, size_t size, int *phase,
                            double *time)
{
    if (size < TRAILER_SIZE || memcmp(b + size - TRAILER_SIZE, STATE_TRAILER, MAGIC_SIZE) != 0) {
        FMI2_SAY(m->log, ModelError, "logStatusError", "%s refused: %zu bytes that are not a state this FMU "
                 "serialized (no " STATE_TRAILER " trailer)", fmi_call, size);
        return NULL;
    }
    int32_t phase32;
    memcpy(&phase32, b + size - TRAILER_SIZE + MAGIC_SIZE, sizeof phase32);
    memcpy(time, b + size - sizeof *time, sizeof *time);
    if (!isfinite(*time) || !(phase32 == P_INSTANTIATED || phase32 == P_INIT || phase32 == P_STEP
                              || phase32 == P_TERMINATED)) {
        FMI2_SAY(m->log, ModelError, "logStatusError", "%s refused: the state's %s is %g", fmi_call,
                 isfinite(*time) ? "phase" : "time", isfinite(*time) ? (double)phase32 : *time);
        return NULL;
    }
    *phase = phase32;
    PyGILState_STATE g = py.GILEnsure();
    PyObject *bytes = py.BytesFrom((const char *)b, (Py_ssize_t_)(size - TRAILER_SIZE));
    PyObject *name = py.StrFrom(fmi_call);
    PyObject *object = bytes && name ? call(m, fmi_call, N_DESERIALIZE, bytes, name, NULL) : NULL;
    py_drop(bytes);
    py_drop(name);
    if (object == py.None) { py_drop(object); object = NULL; }    /* refused: the reason is in the log */
    if (py.Occurred()) py.Clear();
    flush_log(m);
    py.GILRelease(g);
    return object;
}
