/* Every input copied to its output, per type; a Real gain with a range (min/max) applied on the way.
 *
 * Real vr: 0 gain (parameter, fixed, min 0.5, max 4), 1 time_in (input, declaredType Time: s),
 *          2 time_out (output), 3 length_in (input, mm), 4 length_out (output, mm)
 * Integer vr: 0 int_in (input), 1 int_out (output)
 * Boolean vr: 0 bool_in (input), 1 bool_out (output)
 * String vr: 0 label (parameter)
 */
#include <string.h>

#include "model.h"

const unsigned N_REAL = 5, N_INTEGER = 2, N_BOOLEAN = 2, N_STRING = 1;

void model_defaults(Instance *m) {
    for (int k = 0; k < MAX_VARS; k++) { m->r[k] = 0; m->i[k] = 0; m->b[k] = 0; }
    m->r[0] = 1.0;
    m->s[0] = strdup("feed");
}

int model_settable(char type, unsigned vr) {
    switch (type) {
        case 'r': return vr == 0 ? 1 : (vr == 1 || vr == 3) ? 2 : 0;
        case 'i': case 'b': return vr == 0 ? 2 : 0;
        default: return vr == 0 ? 1 : 0;
    }
}

static void copy(Instance *m) {
    m->r[2] = m->r[0] * m->r[1];
    m->r[4] = m->r[0] * m->r[3];
    m->i[1] = m->i[0];
    m->b[1] = m->b[0];
}

const char *model_initialize(Instance *m) {
    if (!(m->r[0] >= 0.5 && m->r[0] <= 4.0)) return "gain must be in [0.5, 4]";
    copy(m);
    return 0;
}

int model_step(Instance *m, double t, double h) {
    (void)t; (void)h;
    copy(m);
    return 0;
}
