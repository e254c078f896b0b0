/* Counts whole seconds and asks the host to end the simulation at end_at (like a model that detects the
 * end of its own experiment): the step that would pass end_at returns fmi2Discard with fmi2Terminated set,
 * and fmi2LastSuccessfulTime stays at the step's start.
 * Built with -DWHOLE_STEP (the "Stairs" FMUs), it ends as the Reference-FMUs' Stair does: the step that reaches
 * end_at is made whole (its outputs at the step's end, fmi2LastSuccessfulTime = the step's end) and then
 * returns fmi2Discard with fmi2Terminated -- fmpy and fmusim record that last point.
 *
 * Real vr: 0 end_at (parameter, s), 1 minutes (output, min: the time in minutes)
 * Integer vr: 0 counter (output)
 */
#include <math.h>

#include "model.h"

const unsigned N_REAL = 2, N_INTEGER = 1, N_BOOLEAN = 0, N_STRING = 0;

void model_defaults(Instance *m) {
    m->r[0] = 9.0;
    m->r[1] = 0.0;
    m->i[0] = 0;
}

int model_settable(char type, unsigned vr) { return type == 'r' && vr == 0 ? 1 : 0; }

const char *model_initialize(Instance *m) {
    if (!(m->r[0] > 0)) return "end_at must be > 0";
    m->r[1] = m->time / 60.0;
    return 0;
}

int model_step(Instance *m, double t, double h) {
#ifdef WHOLE_STEP
    if (t + h > m->r[0] - 1e-9) {
        m->i[0] = (int)floor(t + h + 1e-9);
        m->r[1] = (t + h) / 60.0;
        m->time = t + h;            /* the step is whole: the frame keeps the time of a step that said Discard */
        m->terminated = 1;
        if (m->logger) m->logger(m->environment, m->name, 0, "logEvents", "end of the experiment at %g s", t + h);
        return 2;                   /* fmi2Discard (FMI 3.0: terminateSimulation) */
    }
#endif
    if (t + h > m->r[0] + 1e-9) {
        m->terminated = 1;
        if (m->logger) m->logger(m->environment, m->name, 0, "logEvents", "end of the experiment at %g s", m->r[0]);
        return 2;                   /* fmi2Discard */
    }
    m->i[0] = (int)floor(t + h + 1e-9);
    m->r[1] = (t + h) / 60.0;
    return 0;
}
