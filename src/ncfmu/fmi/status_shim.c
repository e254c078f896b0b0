/*
 * ncfmu status shim: the FMU's binary in front of pythonfmu's export library.
 *
 * pythonfmu reports every Python exception as fmi2Fatal (the instance is gone). A parameter that
 * breaks a rule should be refused with fmi2Error (the importer may reset and try again). The
 * Python adapter therefore does not raise on a bad parameter when this shim is present; it logs the
 * reason and raises a flag that the shim reads after fmi2ExitInitializationMode through a reserved
 * Integer value reference, and turns into fmi2Error. Every other call is forwarded unchanged to
 * pythonfmu's library, loaded from next to this one (<modelIdentifier>.pythonfmu.so).
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef void *fmi2Component;
typedef void *fmi2ComponentEnvironment;
typedef void *fmi2FMUstate;
typedef unsigned int fmi2ValueReference;
typedef double fmi2Real;
typedef int fmi2Integer;
typedef int fmi2Boolean;
typedef char fmi2Char;
typedef const fmi2Char *fmi2String;
typedef char fmi2Byte;
typedef enum { fmi2OK, fmi2Warning, fmi2Discard, fmi2Error, fmi2Fatal, fmi2Pending } fmi2Status;
typedef enum { fmi2ModelExchange, fmi2CoSimulation } fmi2Type;
typedef enum { fmi2DoStepStatus, fmi2PendingStatus, fmi2LastSuccessfulTime, fmi2Terminated } fmi2StatusKind;
typedef struct fmi2CallbackFunctions fmi2CallbackFunctions;

/* Must match ncfmu.fmi.adapter.INIT_REFUSED_VR */
#define NCFMU_INIT_REFUSED_VR 2147483000u

static void *inner = NULL;

static void *sym(const char *name)
{
    if (!inner) {
        Dl_info info;
        char path[4096];
        if (!dladdr((void *)&sym, &info) || !info.dli_fname) return NULL;
        const char *dot = strrchr(info.dli_fname, '.');
        size_t stem = dot ? (size_t)(dot - info.dli_fname) : strlen(info.dli_fname);
        if (stem + 32 >= sizeof path) return NULL;
        memcpy(path, info.dli_fname, stem);
        strcpy(path + stem, ".pythonfmu.so");
        inner = dlopen(path, RTLD_NOW | RTLD_LOCAL | RTLD_DEEPBIND);
        if (!inner) {
            fprintf(stderr, "ncfmu status shim: cannot load %s: %s\n", path, dlerror());
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
FWD(fmi2Component, NULL, fmi2Instantiate, (fmi2String name, fmi2Type type, fmi2String guid, fmi2String res, const fmi2CallbackFunctions *cb, fmi2Boolean vis, fmi2Boolean log), (name, type, guid, res, cb, vis, log))
FWDV(fmi2FreeInstance, (fmi2Component c), (c))
FWD(fmi2Status, fmi2Fatal, fmi2SetupExperiment, (fmi2Component c, fmi2Boolean tol_def, fmi2Real tol, fmi2Real start, fmi2Boolean stop_def, fmi2Real stop), (c, tol_def, tol, start, stop_def, stop))
FWD(fmi2Status, fmi2Fatal, fmi2EnterInitializationMode, (fmi2Component c), (c))
FWD(fmi2Status, fmi2Fatal, fmi2Terminate, (fmi2Component c), (c))
FWD(fmi2Status, fmi2Fatal, fmi2Reset, (fmi2Component c), (c))
FWD(fmi2Status, fmi2Fatal, fmi2GetReal, (fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]), (c, vr, n, v))
FWD(fmi2Status, fmi2Fatal, fmi2GetInteger, (fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]), (c, vr, n, v))
FWD(fmi2Status, fmi2Fatal, fmi2GetBoolean, (fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]), (c, vr, n, v))
FWD(fmi2Status, fmi2Fatal, fmi2GetString, (fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[]), (c, vr, n, v))
FWD(fmi2Status, fmi2Fatal, fmi2SetReal, (fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real v[]), (c, vr, n, v))
FWD(fmi2Status, fmi2Fatal, fmi2SetInteger, (fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]), (c, vr, n, v))
FWD(fmi2Status, fmi2Fatal, fmi2SetBoolean, (fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[]), (c, vr, n, v))
FWD(fmi2Status, fmi2Fatal, fmi2SetString, (fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String v[]), (c, vr, n, v))
FWD(fmi2Status, fmi2Fatal, fmi2GetFMUstate, (fmi2Component c, fmi2FMUstate *s), (c, s))
FWD(fmi2Status, fmi2Fatal, fmi2SetFMUstate, (fmi2Component c, fmi2FMUstate s), (c, s))
FWD(fmi2Status, fmi2Fatal, fmi2FreeFMUstate, (fmi2Component c, fmi2FMUstate *s), (c, s))
FWD(fmi2Status, fmi2Fatal, fmi2SerializedFMUstateSize, (fmi2Component c, fmi2FMUstate s, size_t *size), (c, s, size))
FWD(fmi2Status, fmi2Fatal, fmi2SerializeFMUstate, (fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t size), (c, s, b, size))
FWD(fmi2Status, fmi2Fatal, fmi2DeSerializeFMUstate, (fmi2Component c, const fmi2Byte b[], size_t size, fmi2FMUstate *s), (c, b, size, s))
FWD(fmi2Status, fmi2Fatal, fmi2GetDirectionalDerivative, (fmi2Component c, const fmi2ValueReference u[], size_t nu, const fmi2ValueReference z[], size_t nz, const fmi2Real dv[], fmi2Real dz[]), (c, u, nu, z, nz, dv, dz))
FWD(fmi2Status, fmi2Fatal, fmi2SetRealInputDerivatives, (fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer order[], const fmi2Real v[]), (c, vr, n, order, v))
FWD(fmi2Status, fmi2Fatal, fmi2GetRealOutputDerivatives, (fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer order[], fmi2Real v[]), (c, vr, n, order, v))
FWD(fmi2Status, fmi2Fatal, fmi2DoStep, (fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean discard), (c, t, h, discard))
FWD(fmi2Status, fmi2Fatal, fmi2CancelStep, (fmi2Component c), (c))
FWD(fmi2Status, fmi2Fatal, fmi2GetStatus, (fmi2Component c, const fmi2StatusKind k, fmi2Status *v), (c, k, v))
FWD(fmi2Status, fmi2Fatal, fmi2GetRealStatus, (fmi2Component c, const fmi2StatusKind k, fmi2Real *v), (c, k, v))
FWD(fmi2Status, fmi2Fatal, fmi2GetIntegerStatus, (fmi2Component c, const fmi2StatusKind k, fmi2Integer *v), (c, k, v))
FWD(fmi2Status, fmi2Fatal, fmi2GetBooleanStatus, (fmi2Component c, const fmi2StatusKind k, fmi2Boolean *v), (c, k, v))
FWD(fmi2Status, fmi2Fatal, fmi2GetStringStatus, (fmi2Component c, const fmi2StatusKind k, fmi2String *v), (c, k, v))

fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
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
    return status;
}
