/*
 * A minimal native FMI 3.0 co-simulation host (no Python in it), for tests/fmi/test_fmi3.py:
 *
 *     fmi3_host <binary.so> <instantiationToken> <resources path> <steps> <out vr> <in vr> <ramp per step>
 *
 * Instantiates the FMU, initialises it at t = 0, then per 1 ms step sets the input to ramp * (k + 1), steps,
 * and prints "OUT <k> <value of out vr>" every 100 steps; 0 when every call returned fmi3OK.
 */
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>

#include "fmi3Functions.h"

static void logger(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message)
{
    (void)env;
    printf("LOG %d %s %s\n", (int)status, category, message);
}

int main(int argc, char **argv)
{
    if (argc != 8) { fprintf(stderr, "usage: fmi3_host so token resources steps out-vr in-vr ramp\n"); return 64; }
    void *h = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (!h) { printf("DLOPEN %s\n", dlerror()); return 1; }
#define F(name) fmi3##name##TYPE *name = (fmi3##name##TYPE *)dlsym(h, "fmi3" #name); if (!name) return 2
    F(InstantiateCoSimulation); F(EnterInitializationMode); F(ExitInitializationMode); F(SetFloat64);
    F(DoStep); F(GetFloat64); F(Terminate); F(FreeInstance);
    fmi3Instance c = InstantiateCoSimulation("axis", argv[2], argv[3], fmi3False, fmi3False, fmi3False, fmi3False,
                                             NULL, 0, NULL, logger, NULL);
    if (!c) return 3;
    if (EnterInitializationMode(c, fmi3False, 0.0, 0.0, fmi3False, 0.0) != fmi3OK
        || ExitInitializationMode(c) != fmi3OK) return 4;
    int steps = atoi(argv[4]);
    fmi3ValueReference out = (fmi3ValueReference)atoi(argv[5]), in = (fmi3ValueReference)atoi(argv[6]);
    double ramp = atof(argv[7]);
    for (int k = 0; k < steps; k++) {
        double u = ramp * (k + 1), y = 0.0, last = 0.0;
        fmi3Boolean event = fmi3True, stop = fmi3True, early = fmi3True;
        if (SetFloat64(c, &in, 1, &u, 1) != fmi3OK) return 5;
        if (DoStep(c, k * 1e-3, 1e-3, fmi3True, &event, &stop, &early, &last) != fmi3OK || event || stop || early)
            return 6;
        if (GetFloat64(c, &out, 1, &y, 1) != fmi3OK) return 7;
        if ((k + 1) % 100 == 0) printf("OUT %d %.17g\n", k + 1, y);
    }
    if (Terminate(c) != fmi3OK) return 8;
    FreeInstance(c);
    dlclose(h);
    return 0;
}
