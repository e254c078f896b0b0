/* The feed axis of plant_axis.c that crashes its host: a plant model from another tool with a bug in it.
 *
 * At the simulated time crash_at it dies in the call crash_in names (0: fmi2DoStep, the step that starts there;
 * 1: fmi2GetReal, once the FMU's time has reached it) the way crash_how names (1: SIGSEGV, a write through a
 * null pointer; 2: abort(); 3: exit(3)). Otherwise it is plant_axis.c's axis, variable for variable.
 *
 * Real vr: plant_axis.c's 0..9, 10 crash_at;  Integer vr: 0 crash_how, 1 crash_in;  Boolean vr: 0 in_position
 */
#include <stdlib.h>

/* plant_axis.c under other names; this file defines the model the frame calls */
#define N_REAL PLANT_N_REAL
#define N_INTEGER PLANT_N_INTEGER
#define N_BOOLEAN PLANT_N_BOOLEAN
#define N_STRING PLANT_N_STRING
#define model_defaults plant_defaults
#define model_settable plant_settable
#define model_initialize plant_initialize
#define model_step plant_step
#include "plant_axis.c"
#undef N_REAL
#undef N_INTEGER
#undef N_BOOLEAN
#undef N_STRING
#undef model_defaults
#undef model_settable
#undef model_initialize
#undef model_step

const unsigned N_REAL = 11, N_INTEGER = 2, N_BOOLEAN = 1, N_STRING = 0;

enum { CRASH_AT = 10 };
enum { CRASH_HOW, CRASH_IN };

void model_defaults(Instance *m) {
    plant_defaults(m);
    m->r[CRASH_AT] = 1.0;
    m->i[CRASH_HOW] = 1;
    m->i[CRASH_IN] = 0;
}

int model_settable(char type, unsigned vr) {
    if (type == 'i') return 1;
    if (type == 'r' && vr == CRASH_AT) return 1;
    return plant_settable(type, vr);
}

const char *model_initialize(Instance *m) {
    if (m->i[CRASH_HOW] < 1 || m->i[CRASH_HOW] > 3) return "crash_how must be 1, 2 or 3";
    if (m->i[CRASH_IN] < 0 || m->i[CRASH_IN] > 1) return "crash_in must be 0 or 1";
    return plant_initialize(m);
}

static void crash(Instance *m) {
    volatile int *volatile nowhere = NULL;   /* volatile: the write is made, through a null the compiler cannot see */
    switch (m->i[CRASH_HOW]) {
    case 1: *nowhere = 1; break;
    case 2: abort();
    default: exit(3);
    }
}

int model_step(Instance *m, double t, double h) {
    if (m->i[CRASH_IN] == 0 && t + 0.5 * h >= m->r[CRASH_AT]) crash(m);
    return plant_step(m, t, h);
}

void crash_in_get(Instance *m) {
    if (m->i[CRASH_IN] == 1 && m->time >= m->r[CRASH_AT]) crash(m);
}
