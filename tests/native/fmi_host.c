/*
 * A minimal native FMI 2.0 co-simulation host, for the tests: no Python in it.
 *
 *   fmi_host <binary.so> <guid> <resources-uri> <instances> <steps> <out-vr> [<in-vr>=<value> ...]
 *
 * Each input is "<vr>=<value>" (held) or "<vr>+=<slope>" (a ramp: slope x step number).
 * A negative <instances> instantiates that many on as many threads at once (a host such as ecos does).
 * Instantiates <instances> instances, sets the Real inputs, steps each <steps> times by 1 ms, prints
 * "OUT <k> <value>" for the Real output <out-vr> of every instance, frees them, exits 0. The FMU's log
 * goes to stdout as "LOG <status> <message>"; "STEPPING <s>" is the wall time of the stepping loop (set the
 * inputs, doStep, get the output, every step: what a master does). Exit codes: 1 cannot load, 2 instantiation failed,
 * 3 initialisation failed, 4 a step failed.
 *
 *   fmi_host <binary.so> <guid> <resources-uri> 0
 *
 * instead tries host misuse without Python in the host (bad fmi2Instantiate arguments, NULL, freed and made-up
 * components, a double free) and prints "CASE <name> HELD|BROKEN" per case, then "CASES <n> HELD <k>".
 */
#include <dlfcn.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include "fmi2Functions.h"

static int logged = 0;                  /* log lines so far */

static void logger(fmi2ComponentEnvironment e, fmi2String n, fmi2Status s, fmi2String c, fmi2String m, ...)
{
    (void)e; (void)n; (void)c;
    logged++;
    va_list ap;
    va_start(ap, m);
    printf("LOG %d ", (int)s);
    vprintf(m, ap);
    printf("\n");
    va_end(ap);
}

typedef struct {
    fmi2InstantiateTYPE *instantiate;
    const char *guid, *uri;
    fmi2CallbackFunctions *cb;
    pthread_barrier_t *go;
    char name[16];
    fmi2Component c;
} Start;

static void *start_on_thread(void *arg)
{
    Start *s = arg;
    pthread_barrier_wait(s->go);
    s->c = s->instantiate(s->name, fmi2CoSimulation, s->guid, s->uri, s->cb, fmi2False, fmi2True);
    return NULL;
}

static int cases = 0, held = 0;

static void report(const char *name, int ok)
{
    cases++;
    held += ok;
    printf("CASE %s %s\n", name, ok ? "HELD" : "BROKEN");
    fflush(stdout);
}

static int misuse(void *h, const char *guid, const char *uri)
{
#define G(name) fmi2##name##TYPE *name = (fmi2##name##TYPE *)dlsym(h, "fmi2" #name)
    G(Instantiate); G(FreeInstance); G(Reset); G(SetDebugLogging); G(GetString); G(SetString); G(DoStep);
    G(Terminate); G(SetupExperiment); G(EnterInitializationMode); G(ExitInitializationMode); G(GetReal);
    G(CancelStep); G(GetFMUstate);
    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    struct { const char *name, *instance, *guid, *uri; fmi2Type type; } bad[] = {
        {"null_instance_name", NULL, guid, uri, fmi2CoSimulation},
        {"non_utf8_instance_name", "\xff\xfe", guid, uri, fmi2CoSimulation},
        {"null_resource_location", "x", guid, NULL, fmi2CoSimulation},
        {"nonexistent_resources", "x", guid, "file:///nonexistent", fmi2CoSimulation},
        {"wrong_guid", "x", "{not-this-fmu}", uri, fmi2CoSimulation},
        {"null_guid", "x", NULL, uri, fmi2CoSimulation},
        {"model_exchange", "x", guid, uri, fmi2ModelExchange},
    };
    for (size_t k = 0; k < sizeof bad / sizeof *bad; k++) {
        int before = logged;
        fmi2Component c = Instantiate(bad[k].instance, bad[k].type, bad[k].guid, bad[k].uri, &cb, fmi2False, fmi2False);
        report(bad[k].name, c == NULL && logged == before + 1);
    }
    fmi2ValueReference vr = 0;
    fmi2String text = "x";
    fmi2Real real;
    fmi2FMUstate state = NULL;
    fmi2Component freed = Instantiate("freed", fmi2CoSimulation, guid, uri, &cb, fmi2False, fmi2False);
    fmi2Component alive = Instantiate("alive", fmi2CoSimulation, guid, uri, &cb, fmi2False, fmi2False);
    report("good_instantiations", freed && alive);
    if (!freed || !alive) return 2;
    FreeInstance(freed);
    fmi2Component wrong[3] = {NULL, freed, (fmi2Component)(intptr_t)0xDEADBEE0};
    for (int w = 0; w < 3; w++) {
        fmi2Component c = wrong[w];
        report("reset", Reset(c) == fmi2Error);
        report("set_debug_logging", SetDebugLogging(c, fmi2True, 0, NULL) == fmi2Error);
        report("get_string", GetString(c, &vr, 1, &text) == fmi2Error);
        report("set_string", SetString(c, &vr, 1, &text) == fmi2Error);
        report("do_step", DoStep(c, 0.0, 1e-3, fmi2True) == fmi2Error);
        report("terminate", Terminate(c) == fmi2Error);
        report("cancel_step", CancelStep(c) == fmi2Error);
        report("get_fmu_state", GetFMUstate(c, &state) == fmi2Error);
        report("get_real", GetReal(c, &vr, 1, &real) == fmi2Error);
    }
    FreeInstance(freed);                                 /* a double free: nothing happens */
    FreeInstance(NULL);
    SetupExperiment(alive, fmi2False, 0.0, 0.0, fmi2False, 0.0);
    int ok = EnterInitializationMode(alive) == fmi2OK && ExitInitializationMode(alive) == fmi2OK;
    for (int i = 0; i < 5; i++) ok = ok && DoStep(alive, i * 1e-3, 1e-3, fmi2True) == fmi2OK;
    report("other_instance_unharmed", ok);
    Terminate(alive);
    FreeInstance(alive);
    printf("CASES %d HELD %d\n", cases, held);
    return 0;
}

int main(int argc, char **argv)
{
    if (argc == 5 && atoi(argv[4]) == 0) {
        void *lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
        if (!lib) { printf("DLOPEN %s\n", dlerror()); return 1; }
        return misuse(lib, argv[2], argv[3]);
    }
    if (argc < 7) { fprintf(stderr, "usage: fmi_host so guid uri instances steps out-vr [vr=value ...]\n"); return 64; }
    void *h = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (!h) { printf("DLOPEN %s\n", dlerror()); return 1; }
#define F(name) fmi2##name##TYPE *name = (fmi2##name##TYPE *)dlsym(h, "fmi2" #name)
    F(Instantiate); F(SetupExperiment); F(EnterInitializationMode); F(ExitInitializationMode); F(SetReal);
    F(DoStep); F(GetReal); F(Terminate); F(FreeInstance);
    int count = atoi(argv[4]), steps = atoi(argv[5]), threaded = count < 0;
    if (threaded) count = -count;
    fmi2ValueReference out = (fmi2ValueReference)atoi(argv[6]);
    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    fmi2Component c[16];
    if (count < 1 || count > 16) return 64;
    Start starts[16];
    pthread_t threads[16];
    pthread_barrier_t go;
    pthread_barrier_init(&go, NULL, (unsigned)count);
    for (int k = 0; k < count; k++) {
        starts[k] = (Start){Instantiate, argv[2], argv[3], &cb, &go, "", NULL};
        snprintf(starts[k].name, sizeof starts[k].name, "i%d", k);
        if (threaded) pthread_create(&threads[k], NULL, start_on_thread, &starts[k]);
    }
    for (int k = 0; k < count; k++) {
        if (threaded) pthread_join(threads[k], NULL);
        else starts[k].c = Instantiate(starts[k].name, fmi2CoSimulation, argv[2], argv[3], &cb, fmi2False, fmi2True);
    }
    for (int k = 0; k < count; k++) {
        c[k] = starts[k].c;
        if (!c[k]) return 2;
        SetupExperiment(c[k], fmi2False, 0.0, 0.0, fmi2False, 0.0);
        if (EnterInitializationMode(c[k]) != fmi2OK || ExitInitializationMode(c[k]) != fmi2OK) return 3;
    }
    struct timespec t0, t1;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    for (int i = 0; i < steps; i++)
        for (int k = 0; k < count; k++) {
            for (int a = 7; a < argc; a++) {
                fmi2ValueReference vr = (fmi2ValueReference)atoi(argv[a]);
                const char *eq = argv[a];
                while (*eq && *eq != '=') eq++;
                int ramp = eq > argv[a] && eq[-1] == '+';
                double v = ramp ? atof(eq + 1) * (i + 1) : atof(eq + 1);
                SetReal(c[k], &vr, 1, &v);
            }
            if (DoStep(c[k], i * 1e-3, 1e-3, fmi2True) != fmi2OK) return 4;
            double seen;
            GetReal(c[k], &out, 1, &seen);
        }
    clock_gettime(CLOCK_MONOTONIC, &t1);
    printf("STEPPING %.9f\n", (double)(t1.tv_sec - t0.tv_sec) + 1e-9 * (double)(t1.tv_nsec - t0.tv_nsec));
    for (int k = 0; k < count; k++) {
        double v = 0.0;
        GetReal(c[k], &out, 1, &v);
        printf("OUT %d %.9f\n", k, v);
        Terminate(c[k]);
        FreeInstance(c[k]);
    }
    return 0;
}
