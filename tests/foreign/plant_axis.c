/* A feed axis as a plant model: a velocity loop (first-order lag, time constant tau_vel, speed limit
 * vel_max) closed by a proportional position loop with velocity feed-forward:
 *
 *     vel_cmd = Kv (pos_cmd - pos) + vel_ff,   d vel / dt = (sat(vel_cmd) - vel) / tau_vel,   d pos / dt = vel
 *
 * integrated exactly over sub-steps of at most 0.1 ms. Unit-agnostic: SCALE is the length of the model's
 * length unit in millimetres' terms (1 for mm, 1e-3 for m); the defaults follow it.
 *
 * Real vr: 0 pos_cmd, 1 vel_ff (inputs); 2 pos, 3 vel, 4 following_error (outputs);
 *          5 Kv, 6 tau_vel, 7 vel_max, 8 inpos_band, 9 pos_start (parameters)
 * Boolean vr: 0 in_position (output)
 */
#include <math.h>

#include "model.h"

#ifndef SCALE
#define SCALE 1.0
#endif

const unsigned N_REAL = 10, N_INTEGER = 0, N_BOOLEAN = 1, N_STRING = 0;

enum { POS_CMD, VEL_FF, POS, VEL, FOLLOWING_ERROR, KV, TAU_VEL, VEL_MAX, INPOS_BAND, POS_START };
enum { IN_POSITION };

void model_defaults(Instance *m) {
    for (int k = 0; k < MAX_VARS; k++) { m->r[k] = 0; m->b[k] = 0; }
    m->r[KV] = 40.0;
    m->r[TAU_VEL] = 0.002;
    m->r[VEL_MAX] = 500.0 * SCALE;
    m->r[INPOS_BAND] = 0.005 * SCALE;
    m->r[POS_START] = 0.0;
}

int model_settable(char type, unsigned vr) {
    if (type == 'r') return vr <= VEL_FF ? 2 : vr >= KV ? 1 : 0;
    return 0;
}

static void outputs(Instance *m) {
    m->r[FOLLOWING_ERROR] = m->r[POS_CMD] - m->r[POS];
    m->b[IN_POSITION] = fabs(m->r[FOLLOWING_ERROR]) <= m->r[INPOS_BAND];
}

const char *model_initialize(Instance *m) {
    if (!(m->r[KV] > 0)) return "Kv must be > 0";
    if (!(m->r[TAU_VEL] > 0)) return "tau_vel must be > 0";
    if (!(m->r[VEL_MAX] > 0)) return "vel_max must be > 0";
    m->r[POS] = m->r[POS_START];
    if (m->r[POS_CMD] == 0.0) m->r[POS_CMD] = m->r[POS_START];
    m->r[VEL] = 0;
    outputs(m);
    return 0;
}

int model_step(Instance *m, double t, double h) {
    (void)t;
    int n = (int)ceil(h / 1e-4 - 1e-9);
    if (n < 1) n = 1;
    double dt = h / n, decay = exp(-dt / m->r[TAU_VEL]);
    for (int k = 0; k < n; k++) {
        double cmd = m->r[KV] * (m->r[POS_CMD] - m->r[POS]) + m->r[VEL_FF];
        if (cmd > m->r[VEL_MAX]) cmd = m->r[VEL_MAX];
        if (cmd < -m->r[VEL_MAX]) cmd = -m->r[VEL_MAX];
        double v0 = m->r[VEL], v1 = cmd + (v0 - cmd) * decay;
        /* exact position increment of the lag's response over dt */
        m->r[POS] += cmd * dt + (v0 - cmd) * m->r[TAU_VEL] * (1 - decay);
        m->r[VEL] = v1;
    }
    outputs(m);
    return 0;
}
