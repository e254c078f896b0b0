/*
 * ncfmu: the numerics the native drive models share -- exact zero-order-hold discretisation (matrix
 * exponential by balancing, scaling and squaring of a Pade approximant, as scipy's expm does) and the
 * phase margin of a PI velocity/speed loop, and of a position loop around it (as control.margin gives
 * them) -- and the steps of a drive's digital loop, written once: sub-steps of a communication step, the
 * encoder, the torque limit with conditional integration, one sub-step of the current loop + mechanics
 * with Coulomb friction. Static inline functions, included by each drive's C file (servo_model.c,
 * spindle_model.c); each drive keeps the order of its Python stepper, operation for operation.
 */
#ifndef NCFMU_DRIVE_MATH_H
#define NCFMU_DRIVE_MATH_H

#include <math.h>
#include <string.h>

#include "model.h"                 /* Fmi2Log, FMI2_SAY: the drives' refusals (below) */

#ifndef PI
#define PI 3.14159265358979323846
#endif

/* ---- small dense linear algebra ---------------------------------------------------------------- */
#define NMAX 8

static inline void mat_mul(int n, const double a[NMAX][NMAX], const double b[NMAX][NMAX], double c[NMAX][NMAX])
{
    double t[NMAX][NMAX];
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) {
            double s = 0.0;
            for (int k = 0; k < n; k++) s += a[i][k] * b[k][j];
            t[i][j] = s;
        }
    memcpy(c, t, sizeof t);
}

/* Solve D X = N in place (N becomes X) by Gaussian elimination with partial pivoting. */
static inline int solve(int n, double d[NMAX][NMAX], double x[NMAX][NMAX])
{
    for (int col = 0; col < n; col++) {
        int p = col;
        for (int r = col + 1; r < n; r++)
            if (fabs(d[r][col]) > fabs(d[p][col])) p = r;
        if (d[p][col] == 0.0) return -1;
        if (p != col)
            for (int k = 0; k < n; k++) {
                double t = d[p][k]; d[p][k] = d[col][k]; d[col][k] = t;
                t = x[p][k]; x[p][k] = x[col][k]; x[col][k] = t;
            }
        for (int r = col + 1; r < n; r++) {
            double f = d[r][col] / d[col][col];
            if (f == 0.0) continue;
            for (int k = col; k < n; k++) d[r][k] -= f * d[col][k];
            for (int k = 0; k < n; k++) x[r][k] -= f * x[col][k];
        }
    }
    for (int col = n - 1; col >= 0; col--)
        for (int k = 0; k < n; k++) {
            double s = x[col][k];
            for (int j = col + 1; j < n; j++) s -= d[col][j] * x[j][k];
            x[col][k] = s / d[col][col];
        }
    return 0;
}

/* Balance m in place by a diagonal similarity of powers of two (Parlett-Reinsch, as LAPACK's gebal without
 * permutations): d[i] holds the scale, m becomes D^-1 m D. The closed loop's matrix mixes entries of 1e-3
 * and 1e7; unbalanced, its norm (not its eigenvalues) would set the number of squarings and cost accuracy. */
static inline void balance(int n, double m[NMAX][NMAX], double d[NMAX])
{
    for (int i = 0; i < n; i++) d[i] = 1.0;
    for (int sweep = 0, done = 0; !done && sweep < 100; sweep++) {
        done = 1;
        for (int i = 0; i < n; i++) {
            double c = 0.0, r = 0.0;
            for (int j = 0; j < n; j++)
                if (j != i) { c += fabs(m[j][i]); r += fabs(m[i][j]); }
            if (c == 0.0 || r == 0.0) continue;
            double f = 1.0, g = r / 2.0, total = c + r;
            while (c < g) { f *= 2.0; c *= 4.0; }
            g = r * 2.0;
            while (c >= g) { f /= 2.0; c /= 4.0; }
            if ((c + r) / f < 0.95 * total) {
                done = 0;
                d[i] *= f;
                for (int j = 0; j < n; j++) { m[i][j] /= f; m[j][i] *= f; }
            }
        }
    }
}

/* exp(M) by balancing, then scaling and squaring with the (8, 8) Pade approximant (|M|/2^s <= 0.5: error
 * below double rounding). */
static inline int expm(int n, const double m_in[NMAX][NMAX], double e[NMAX][NMAX])
{
    double m[NMAX][NMAX], d[NMAX];
    memcpy(m, m_in, sizeof m);
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++)
            if (!isfinite(m[i][j])) return -1;
    balance(n, m, d);
    double norm = 0.0;
    for (int i = 0; i < n; i++) {
        double row = 0.0;
        for (int j = 0; j < n; j++) row += fabs(m[i][j]);
        if (row > norm) norm = row;
    }
    if (!isfinite(norm)) return -1;
    int s = 0;
    while (norm > 0.5 && s < 1000) { norm *= 0.5; s++; }
    double scale = ldexp(1.0, -s);
    double a[NMAX][NMAX], p[NMAX][NMAX], num[NMAX][NMAX], den[NMAX][NMAX];
    memset(num, 0, sizeof num); memset(den, 0, sizeof den); memset(p, 0, sizeof p);
    for (int i = 0; i < n; i++) {
        for (int j = 0; j < n; j++) a[i][j] = m[i][j] * scale;
        p[i][i] = num[i][i] = den[i][i] = 1.0;
    }
    const int q = 8;
    double c = 1.0;
    for (int k = 1; k <= q; k++) {
        c *= (double)(q - k + 1) / (double)(k * (2 * q - k + 1));
        mat_mul(n, p, a, p);                       /* p = a^k */
        double sign = (k % 2) ? -1.0 : 1.0;
        for (int i = 0; i < n; i++)
            for (int j = 0; j < n; j++) {
                num[i][j] += c * p[i][j];
                den[i][j] += sign * c * p[i][j];
            }
    }
    if (solve(n, den, num) != 0) return -1;
    for (int k = 0; k < s; k++) mat_mul(n, num, num, num);
    for (int i = 0; i < n; i++)                       /* undo the balancing: e = D exp(B) D^-1 */
        for (int j = 0; j < n; j++) e[i][j] = num[i][j] * d[i] / d[j];
    return 0;
}

/* Zero-order hold of (A, B) (nx states, nu inputs) over h: Ad = e^{Ah}, Bd = int_0^h e^{As} ds B. */
static inline int zoh(int nx, int nu, const double *A, const double *B, double h, double *Ad, double *Bd)
{
    double m[NMAX][NMAX] = {{0}}, e[NMAX][NMAX];
    for (int i = 0; i < nx; i++) {
        for (int j = 0; j < nx; j++) m[i][j] = A[i * nx + j] * h;
        for (int j = 0; j < nu; j++) m[i][nx + j] = B[i * nu + j] * h;
    }
    if (expm(nx + nu, m, e) != 0) return -1;
    for (int i = 0; i < nx; i++) {
        for (int j = 0; j < nx; j++) Ad[i * nx + j] = e[i][j];
        for (int j = 0; j < nu; j++) Bd[i * nu + j] = e[i][nx + j];
    }
    return 0;
}

/* ---- design: the phase margin of a PI loop, and of the position loop around it ------------------ */
typedef struct { double kv, bw, a, tau; int position; } Loop;

/* L_v(jw) = bw (1 + bw/(4 jw)) / ((jw + a)(tau jw + 1)); L_p = Kv/(jw) L_v/(1 + L_v). */
static inline void loop_at(const Loop *l, double w, double *re, double *im)
{
    /* complex arithmetic by hand: (x + iy) */
    double nr = l->bw, ni = -l->bw * l->bw / (4.0 * w);          /* bw (1 + bw/(4 i w)) */
    double d1r = l->a, d1i = w, d2r = 1.0, d2i = l->tau * w;       /* (i w + a)(tau i w + 1) */
    double dr = d1r * d2r - d1i * d2i, di = d1r * d2i + d1i * d2r;
    double dd = dr * dr + di * di;
    double lr = (nr * dr + ni * di) / dd, li = (ni * dr - nr * di) / dd;
    if (l->position) {
        double sr = 1.0 + lr, si = li, ss = sr * sr + si * si;   /* T = L / (1 + L) */
        double tr = (lr * sr + li * si) / ss, ti = (li * sr - lr * si) / ss;
        /* Kv / (i w) * T = Kv (ti - i tr) / w */
        lr = l->kv * ti / w;
        li = -l->kv * tr / w;
    }
    *re = lr; *im = li;
}

static inline double loop_log_gain(const Loop *l, double w)
{
    double re, im;
    loop_at(l, w, &re, &im);
    return log(hypot(re, im));
}

/* The phase margin as control.margin gives it: over the gain crossovers, PM = (phase mod 360) - 180,
 * the one of smallest magnitude. Crossovers found on a log grid and refined by bisection. */
static inline double phase_margin(const Loop *l)
{
    const int n = 4000;
    double w0 = 1e-3, w1 = 1e9;
    /* both loops are integrators at low frequency: start where the gain is above 1, so no crossover is missed */
    while (loop_log_gain(l, w0) <= 0.0 && w0 > 1e-12) w0 /= 10.0;
    double best = INFINITY;
    double wa = w0, ga = loop_log_gain(l, wa);
    for (int k = 1; k <= n; k++) {
        double wb = w0 * pow(w1 / w0, (double)k / n), gb = loop_log_gain(l, wb);
        if (isnan(gb)) continue;
        if ((ga > 0.0) != (gb > 0.0)) {
            double lo = wa, hi = wb, glo = ga;
            for (int it = 0; it < 200 && hi - lo > 1e-14 * hi; it++) {
                double mid = sqrt(lo * hi), gm = loop_log_gain(l, mid);
                if ((gm > 0.0) == (glo > 0.0)) { lo = mid; glo = gm; } else hi = mid;
            }
            double re, im;
            loop_at(l, sqrt(lo * hi), &re, &im);
            double phase = atan2(im, re) * 180.0 / PI;
            double pm = fmod(fmod(phase, 360.0) + 360.0, 360.0) - 180.0;
            if (fabs(pm) < fabs(best)) best = pm;
        }
        wa = wb; ga = gb;
    }
    return best;
}

/* ---- the digital loop's steps (ServoAxis._digital, SpindleDrive._digital) ------------------------ */
/* Sub-steps of ``substep`` s per communication step ``dt``; 0 when there would be more than DRIVE_MAX_SUBSTEPS
 * (the model refuses the step). */
#define DRIVE_MAX_SUBSTEPS 10000000
static inline int drive_substeps(double substep, double dt)
{
    double n = ceil(dt / substep - 1e-9);
    return n < 1.0 ? 1 : n > DRIVE_MAX_SUBSTEPS ? 0 : (int)n;
}

/* The encoder: ``x`` to whole counts of ``quantum``. */
static inline double drive_encoder(double x, double quantum) { return nearbyint(x / quantum) * quantum; }

/* The torque command ``t_cmd`` limited to +-``t_lim``, with conditional integration (no windup): the
 * integral ``*xi`` of the speed error ``e`` grows over ``h`` only while nothing limits -- neither the torque
 * nor (``held``) a limit before it, such as the commanded speed's; ``*limited`` is set when one did. */
static inline double drive_torque_limit(double t_cmd, double t_lim, int held, double e, double h, double *xi,
                                        int *limited)
{
    int torque_limited = fabs(t_cmd) > t_lim;
    if (torque_limited) t_cmd = copysign(t_lim, t_cmd);
    if (held || torque_limited) *limited = 1;
    else *xi += e * h;
    return t_cmd;
}

/* The ZOH map of the plant (3 states: torque, position, speed; 2 inputs: torque command, friction) for a
 * sub-step ``h``, kept in ``Ad``/``Bd`` while ``*cached_h`` is ``h``. 0 when fine. */
static inline int drive_plant_map(const double Ap[3][3], const double Bp[3][2], double h, double *cached_h,
                                  double Ad[3][3], double Bd[3][2])
{
    if (*cached_h == h) return 0;
    if (zoh(3, 2, &Ap[0][0], &Bp[0][0], h, &Ad[0][0], &Bd[0][0]) != 0) return -1;
    *cached_h = h;
    return 0;
}

/* One sub-step ``h`` of the plant under ``t_cmd`` with Coulomb friction ``tc`` (0: none): the friction
 * opposes the motion, or holds the load while the drive's torque is below it (stick); it only brakes --
 * where the speed would change sign, the axis stops where uniform deceleration takes it. */
static inline void drive_plant_step(const double ad[3][3], const double bd[3][2], double tc, double t_cmd, double h,
                                    double *torque, double *pos, double *vel)
{
    double tq = *torque, x = *pos, v = *vel, t_fr;
    if (tc == 0.0) t_fr = 0.0;
    else if (v != 0.0) t_fr = copysign(tc, v);
    else t_fr = fmin(fmax(tq, -tc), tc);
    double torque_n = ad[0][0] * tq + ad[0][1] * x + ad[0][2] * v + bd[0][0] * t_cmd + bd[0][1] * t_fr;
    double pos_n = ad[1][0] * tq + ad[1][1] * x + ad[1][2] * v + bd[1][0] * t_cmd + bd[1][1] * t_fr;
    double vel_n = ad[2][0] * tq + ad[2][1] * x + ad[2][2] * v + bd[2][0] * t_cmd + bd[2][1] * t_fr;
    if (t_fr != 0.0) {
        if (v == 0.0 && fabs(torque_n) <= tc) {
            pos_n = x; vel_n = 0.0;                                 /* stick */
        } else if (v * vel_n < 0.0) {
            double s_stop = v / (v - vel_n);
            pos_n = x + 0.5 * v * s_stop * h;
            vel_n = 0.0;
        }
    }
    *torque = torque_n; *pos = pos_n; *vel = vel_n;
}

/* ---- the drives' refusals, in the same words ------------------------------------------------------ */
/* 1 when a communication step ``dt`` takes at most DRIVE_MAX_SUBSTEPS sub-steps; else logs and returns 0. */
static inline int drive_substeps_ok(const Fmi2Log *log, double substep, double dt)
{
    if (drive_substeps(substep, dt) != 0) return 1;
    FMI2_SAY(log, ModelError, "logStatusError", "communicationStepSize = %g s: more than %d sub-steps of "
             "substep = %g s in one step; take shorter steps", dt, DRIVE_MAX_SUBSTEPS, substep);
    return 0;
}

/* 1 when the ``n`` dynamic values of a state record are finite and within 1e12; else logs the first other one
 * (``what``: the drive, "axis" or "spindle") and returns 0. */
static inline int drive_state_finite(const Fmi2Log *log, const char *what, const double *v, size_t n)
{
    for (size_t k = 0; k < n; k++)
        if (!isfinite(v[k]) || fabs(v[k]) > 1e12) {
            FMI2_SAY(log, ModelError, "logStatusError", "FMU state: the %s state holds %g, not a finite %s value", what,
                     v[k], what);
            return 0;
        }
    return 1;
}

/* 1 when a state record's flags are 0 or 1; else logs and returns 0. */
static inline int drive_state_flags(const Fmi2Log *log, const char *what, int limited, int fault)
{
    if ((limited == 0 || limited == 1) && (fault == 0 || fault == 1)) return 1;
    FMI2_SAY(log, ModelError, "logStatusError", "FMU state: a flag of the %s state is neither 0 nor 1", what);
    return 0;
}

#endif
