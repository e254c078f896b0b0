/*
 * ncfmu ServoAxis: the equations of one feed axis, in C (the FMI plumbing is fmi2_functions.c over
 * native_model.c; this file gives the three functions of model.h, section 2).
 *
 * The executable specification is the Python stepper ncfmu.servo.axis.ServoAxis, and the design is
 * python-control's (ncfmu.servo.model): this file computes the same continuous models from the
 * parameters -- the closed loop of servo_axis() and the drive plant of drive_plant() -- discretises
 * them exactly (zero-order hold, drive_math.h: matrix exponential by scaling and squaring of a Pade
 * approximant, as scipy's expm does) and steps them as the Python stepper does, operation for
 * operation. Tests hold the two to 1e-9, and the margins computed here to control.margin.
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "model.h"
#include "model_vars.h"
#include "drive_math.h"

#define MIN_PHASE_MARGIN 30.0

struct ModelState {
    /* derived from the parameters (model_derive) */
    double kp, ki, rad_per_mm, t_per_acc, v_max, quantum;
    double A[4][4], B[4][3];             /* servo_axis(): states integral, torque, pos, vel */
    double Ap[3][3], Bp[3][2];           /* drive_plant(): states torque, pos, vel; inputs torque_cmd, friction */
    double ideal_dt, F[4][4], G[4][4];   /* the ideal step map for one communication step (cached) */
    double plant_h, Ad[3][3], Bd[3][2];  /* the plant's ZOH map for one sub-step (cached) */
    /* the dynamic state */
    double x[4];                         /* integral, torque, pos, vel */
    double p_meas, p_last, pos_cmd, cmd_prev, vel_ff, vff_prev;
    int limited, fault;
};

size_t model_state_size(void) { return sizeof(struct ModelState); }

/* ---- the models, from the parameters ----------------------------------------------------------- */
#define P(vr) (values[vr])

static void derive(const double *values, struct ModelState *m)
{
    double J = P(VR_J), pitch = P(VR_pitch), b = P(VR_b_visc), tau = P(VR_tau_current);
    double bw = P(VR_vel_bandwidth), kv = P(VR_Kv), kff = P(VR_kff);
    m->rad_per_mm = 2.0 * PI / pitch;
    m->t_per_acc = J * m->rad_per_mm;
    m->kp = J * m->rad_per_mm * bw;
    m->ki = m->kp * bw / 4.0;
    m->v_max = P(VR_speed_max) * pitch / 60.0;
    m->quantum = pitch / P(VR_counts_per_rev);
    double ka = P(VR_kaff) * m->t_per_acc, jk = J * m->rad_per_mm;
    /* servo_axis(): integral' = vel_cmd - vel, torque' = (torque_cmd - torque)/tau,
     * pos' = vel, vel' = torque/(J k) - b/J vel, with vel_cmd = Kv (pos_cmd - pos) + kff vel_ff and
     * torque_cmd = Kp (vel_cmd - vel) + Ki integral + Ka acc_ff. */
    double A[4][4] = {{0.0, 0.0, -kv, -1.0},
                      {m->ki / tau, -1.0 / tau, -m->kp * kv / tau, -m->kp / tau},
                      {0.0, 0.0, 0.0, 1.0},
                      {0.0, 1.0 / jk, 0.0, -b / J}};
    double B[4][3] = {{kv, kff, 0.0},
                      {m->kp * kv / tau, m->kp * kff / tau, ka / tau},
                      {0.0, 0.0, 0.0},
                      {0.0, 0.0, 0.0}};
    double Ap[3][3] = {{-1.0 / tau, 0.0, 0.0}, {0.0, 0.0, 1.0}, {1.0 / jk, 0.0, -b / J}};
    double Bp[3][2] = {{1.0 / tau, 0.0}, {0.0, 0.0}, {0.0, -1.0 / jk}};
    memcpy(m->A, A, sizeof A); memcpy(m->B, B, sizeof B);
    memcpy(m->Ap, Ap, sizeof Ap); memcpy(m->Bp, Bp, sizeof Bp);
    m->ideal_dt = m->plant_h = 0.0;      /* caches empty */
}

/* ---- design: margins of the two loops (ncfmu.servo.model.design) ------------------------------- */
/* Routh-Hurwitz for the closed loop tau s^4 + (1 + tau a) s^3 + (a + bw) s^2 + (bw^2/4 + Kv bw) s
 * + Kv bw^2/4 (the characteristic polynomial of servo_axis()). */
static int stable(const Loop *l)
{
    double a4 = l->tau, a3 = 1.0 + l->tau * l->a, a2 = l->a + l->bw, a1 = l->bw * l->bw / 4.0 + l->kv * l->bw;
    double a0 = l->kv * l->bw * l->bw / 4.0;
    return a4 > 0 && a3 > 0 && a2 > 0 && a1 > 0 && a0 > 0 && a3 * a2 > a4 * a1
        && a3 * a2 * a1 > a4 * a1 * a1 + a3 * a3 * a0;
}

/* The same refusals, in the same order, with the same words as LoopDesign.refusal. */
static int design_ok(const double *values, const Fmi2Log *log)
{
    Loop l = {P(VR_Kv), P(VR_vel_bandwidth), P(VR_b_visc) / P(VR_J), P(VR_tau_current), 0};
    double pm_v = phase_margin(&l);
    l.position = 1;
    double pm_p = phase_margin(&l);
    if (!(pm_v >= MIN_PHASE_MARGIN)) {
        FMI2_SAY(log, ModelError, "logStatusError", "vel_bandwidth = %.17g: gives the velocity loop a phase margin of %.1f "
                 "deg (< %g deg) with tau_current = %g s; lower vel_bandwidth", P(VR_vel_bandwidth), pm_v,
                 MIN_PHASE_MARGIN, P(VR_tau_current));
        return 0;
    }
    if (!(pm_p >= MIN_PHASE_MARGIN)) {
        FMI2_SAY(log, ModelError, "logStatusError", "Kv = %.17g: gives the position loop a phase margin of %.1f deg (< %g "
                 "deg) with vel_bandwidth = %g rad/s; lower Kv", P(VR_Kv), pm_p, MIN_PHASE_MARGIN,
                 P(VR_vel_bandwidth));
        return 0;
    }
    if (!stable(&l)) {
        FMI2_SAY(log, ModelError, "logStatusError", "Kv = %.17g: the closed loop is unstable; lower Kv or vel_bandwidth",
                 P(VR_Kv));
        return 0;
    }
    return 1;
}

/* Cross-parameter rules. Each parameter's own range is its port's, checked by the FMI layer whenever a value
 * comes in (fmi2Set*, a deserialized state), so every value seen here already keeps it. */
static int parameters_ok(const double *values, const Fmi2Log *log)
{
    /* The velocity loop is sampled every substep: a crossover above 0.5 rad per sample is no design. */
    if (!(P(VR_vel_bandwidth) * P(VR_substep) <= 0.5)) {
        FMI2_SAY(log, ModelError, "logStatusError", "vel_bandwidth = %.17g: must be <= 0.5 / substep = %g rad/s (the "
                 "velocity loop is sampled every substep = %g s)", P(VR_vel_bandwidth), 0.5 / P(VR_substep),
                 P(VR_substep));
        return 0;
    }
    return design_ok(values, log);
}

/* ---- stepping (ServoAxis.step / _digital, operation for operation) ----------------------------- */
static double quantise(const double *values, const struct ModelState *m, double pos)
{
    return P(VR_ideal) != 0.0 ? pos : drive_encoder(pos, m->quantum);
}

/* Sub-steps per communication step; 0 when there would be too many (refused by model_step). */
static int substeps(const double *values, double dt) { return drive_substeps(P(VR_substep), dt); }

static void publish(double *values, const struct ModelState *m, double pos, double vel, double torque)
{
    double fe = m->pos_cmd - pos;
    values[VR_pos] = pos;
    values[VR_vel] = vel;
    values[VR_following_error] = fe;
    values[VR_in_position] = fabs(fe) <= P(VR_inpos_band);
    values[VR_torque] = torque;
    values[VR_limited] = m->limited;
}

static int ideal_matrices(const double *values, struct ModelState *m, double dt)
{
    if (m->ideal_dt == dt) return 0;
    int n = substeps(values, dt);
    double ad[4][4], bd[4][3];
    if (zoh(4, 3, &m->A[0][0], &m->B[0][0], dt / n, &ad[0][0], &bd[0][0]) != 0) return -1;
    double f[4][4] = {{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}, {0, 0, 0, 1}}, g[4][4] = {{0}};
    for (int i = 0; i < n; i++) {
        double w = (double)(i + 1) / n;
        double u[3][4] = {{1 - w, w, 0.0, 0.0}, {0.0, 0.0, 1 - w, w}, {0.0, 0.0, -1.0 / dt, 1.0 / dt}};
        double f2[4][4], g2[4][4];
        for (int r = 0; r < 4; r++)
            for (int c = 0; c < 4; c++) {
                double sf = 0.0, sg = 0.0;
                for (int k = 0; k < 4; k++) { sf += ad[r][k] * f[k][c]; sg += ad[r][k] * g[k][c]; }
                for (int k = 0; k < 3; k++) sg += bd[r][k] * u[k][c];
                f2[r][c] = sf; g2[r][c] = sg;
            }
        memcpy(f, f2, sizeof f); memcpy(g, g2, sizeof g);
    }
    memcpy(m->F, f, sizeof f); memcpy(m->G, g, sizeof g);
    m->ideal_dt = dt;
    return 0;
}

static void digital(const double *values, struct ModelState *m, double dt, int enabled)
{
    int n = substeps(values, dt), ideal = P(VR_ideal) != 0.0;
    double h = dt / n;
    double xi = m->x[0], torque = m->x[1], pos = m->x[2], vel = m->x[3];
    double kv = P(VR_Kv), kff = P(VR_kff), kp = m->kp, ki = m->ki;
    double v_max = m->v_max, t_max = P(VR_torque_max), tc = P(VR_tau_coulomb), q = m->quantum;
    double cmd0 = m->cmd_prev, d_cmd = (m->pos_cmd - m->cmd_prev) / n;
    double vff0 = m->vff_prev, d_vff = (m->vel_ff - m->vff_prev) / n;
    double t_ff = P(VR_kaff) * m->t_per_acc * (m->vel_ff - m->vff_prev) / dt;
    double p_meas = m->p_last;
    int limited = 0;
    for (int i = 0; i < n; i++) {
        double pos_cmd = cmd0 + d_cmd * (i + 1), vel_ff = vff0 + d_vff * (i + 1), t_cmd;
        double p_prev = p_meas;
        p_meas = ideal ? pos : drive_encoder(pos, q);
        if (enabled) {
            double v_meas = ideal ? vel : (p_meas - p_prev) / h;
            double v_cmd = kv * (pos_cmd - p_meas) + kff * vel_ff;
            int speed_limited = !ideal && fabs(v_cmd) > v_max;
            if (speed_limited) v_cmd = copysign(v_max, v_cmd);
            double e = v_cmd - v_meas;
            t_cmd = drive_torque_limit(kp * e + ki * xi + t_ff, ideal ? INFINITY : t_max, speed_limited, e, h, &xi,
                                       &limited);
        } else {
            t_cmd = 0.0;
            xi = 0.0;
        }
        drive_plant_step(m->Ad, m->Bd, ideal ? 0.0 : tc, t_cmd, h, &torque, &pos, &vel);   /* ideal: no friction */
    }
    m->x[0] = xi; m->x[1] = torque; m->x[2] = pos; m->x[3] = vel;
    m->p_last = p_meas;
    m->p_meas = ideal ? pos : drive_encoder(pos, q);
    m->limited = limited;
}

/* ---- the model interface ----------------------------------------------------------------------- */
int model_init(double *values, ModelState *m, const Fmi2Log *log)
{
    if (!parameters_ok(values, log)) return -1;
    memset(m, 0, sizeof *m);
    derive(values, m);
    double p0 = P(VR_pos_start);
    m->x[2] = p0;
    m->p_meas = m->p_last = quantise(values, m, p0);
    m->pos_cmd = m->cmd_prev = p0;
    publish(values, m, p0, 0.0, 0.0);
    return 0;
}

int model_step(double *values, ModelState *m, double t, double dt, const Fmi2Log *log)
{
    if (!drive_substeps_ok(log, P(VR_substep), dt)) return -1;
    double cmd = P(VR_pos_cmd), vff = P(VR_vel_ff);
    int bad = !isfinite(cmd) || !isfinite(vff);
    if (bad && !m->fault)   /* never act on a NaN: hold the last good command, say why once */
        FMI2_SAY(log, ModelWarning, "logStatusWarning", "t = %.4f s: %s = %g is not finite; holding the last command", t,
                 !isfinite(cmd) ? "pos_cmd" : "vel_ff", !isfinite(cmd) ? cmd : vff);
    m->fault = bad;
    m->cmd_prev = m->pos_cmd;
    m->vff_prev = m->vel_ff;
    if (!bad) { m->pos_cmd = cmd; m->vel_ff = vff; }
    double p0 = m->p_meas;
    int enabled = P(VR_enable) != 0.0, ideal = P(VR_ideal) != 0.0;
    if (ideal && enabled) {
        if (ideal_matrices(values, m, dt) != 0) goto numeric;
        double u[4] = {m->cmd_prev, m->pos_cmd, m->vff_prev, m->vel_ff}, x[4];
        for (int r = 0; r < 4; r++) {
            double s = 0.0, g = 0.0;
            for (int k = 0; k < 4; k++) s += m->F[r][k] * m->x[k];
            for (int k = 0; k < 4; k++) g += m->G[r][k] * u[k];
            x[r] = s + g;
        }
        memcpy(m->x, x, sizeof x);
        m->p_meas = m->x[2];
        m->limited = 0;
    } else {
        if (drive_plant_map(m->Ap, m->Bp, dt / substeps(values, dt), &m->plant_h, m->Ad, m->Bd) != 0) goto numeric;
        digital(values, m, dt, enabled);
    }
    double vel = ideal ? m->x[3] : (m->p_meas - p0) / dt;
    if (!isfinite(m->p_meas) || !isfinite(vel) || !isfinite(m->x[1])) goto numeric;
    publish(values, m, m->p_meas, vel, m->x[1]);
    return 0;
numeric:
    FMI2_SAY(log, ModelError, "logStatusError", "t = %.4f s: the axis model left the finite numbers (step %g s)", t, dt);
    return -1;
}

int model_restore(double *values, ModelState *m, int judged, const Fmi2Log *log)
{
    if (!judged && !parameters_ok(values, log)) return -1;
    derive(values, m);                       /* never trust derived data from a state record */
    double dyn[] = {m->x[0], m->x[1], m->x[2], m->x[3], m->p_meas, m->p_last, m->pos_cmd, m->cmd_prev,
                    m->vel_ff, m->vff_prev};
    if (!drive_state_finite(log, "axis", dyn, sizeof dyn / sizeof dyn[0])) return -1;
    if (!drive_state_flags(log, "axis", m->limited, m->fault)) return -1;
    return 0;
}
