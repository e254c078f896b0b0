/*
 * ncfmu SpindleDrive: the equations of a lathe spindle drive, in C (the FMI plumbing is fmi2_functions.c over
 * native_model.c; this file gives the three functions of model.h, section 2).
 *
 * The executable specification is the Python stepper ncfmu.servo.spindle.SpindleDrive, and the design is
 * python-control's (ncfmu.servo.spindle_model): this file computes the same continuous plant from the
 * parameters -- spindle_plant(): current loop + mechanics -- discretises it exactly (zero-order hold,
 * drive_math.h) and steps the digital speed loop as the Python stepper does, operation for operation.
 * Tests hold the two to 1e-9, and the phase margin computed here to control.margin.
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "model.h"
#include "model_vars.h"
#include "drive_math.h"

#define MIN_PHASE_MARGIN 30.0
#define RAD_S_PER_RPM (2.0 * PI / 60.0)

struct ModelState {
    /* derived from the parameters (model_derive) */
    double kp, ki, quantum, power_max;
    double Ap[3][3], Bp[3][2];           /* spindle_plant(): states torque, angle, speed; inputs torque_cmd, friction */
    double plant_h, Ad[3][3], Bd[3][2];  /* the plant's ZOH map for one sub-step (cached) */
    /* the dynamic state */
    double x[4];                         /* integral, torque, angle, speed */
    double a_meas, a_last, command, load;
    int limited, fault;
};

size_t model_state_size(void) { return sizeof(struct ModelState); }

#define P(vr) (values[vr])

/* ---- the model, from the parameters -------------------------------------------------------------- */
static void derive(const double *values, struct ModelState *m)
{
    double J = P(VR_J), b = P(VR_b_visc), tau = P(VR_tau_current), bw = P(VR_speed_bandwidth);
    m->kp = J * bw;
    m->ki = m->kp * bw / 4.0;
    m->quantum = 2.0 * PI / P(VR_counts_per_rev);
    m->power_max = P(VR_power_max) * 1e3;
    /* spindle_plant(): torque' = (torque_cmd - torque)/tau, angle' = speed, speed' = (torque - friction)/J - b/J speed */
    double Ap[3][3] = {{-1.0 / tau, 0.0, 0.0}, {0.0, 0.0, 1.0}, {1.0 / J, 0.0, -b / J}};
    double Bp[3][2] = {{1.0 / tau, 0.0}, {0.0, 0.0}, {0.0, -1.0 / J}};
    memcpy(m->Ap, Ap, sizeof Ap); memcpy(m->Bp, Bp, sizeof Bp);
    m->plant_h = 0.0;                    /* cache empty */
}

/* Routh-Hurwitz for the closed speed loop tau s^3 + (1 + tau a) s^2 + (a + bw) s + bw^2/4. */
static int stable(const Loop *l)
{
    double a3 = l->tau, a2 = 1.0 + l->tau * l->a, a1 = l->a + l->bw, a0 = l->bw * l->bw / 4.0;
    return a3 > 0 && a2 > 0 && a1 > 0 && a0 > 0 && a2 * a1 > a3 * a0;
}

/* Cross-parameter rules, with the words of SpindleDrive.configure and SpindleDesign.refusal. Each parameter's
 * own range is its port's, checked by the FMI layer whenever a value comes in. */
static int parameters_ok(const double *values, const Fmi2Log *log)
{
    if (!(P(VR_speed_bandwidth) * P(VR_substep) <= 0.5)) {
        FMI2_SAY(log, ModelError, "logStatusError", "speed_bandwidth = %.17g: must be <= 0.5 / substep = %g rad/s (the "
                 "speed loop is sampled every substep = %g s)", P(VR_speed_bandwidth), 0.5 / P(VR_substep),
                 P(VR_substep));
        return 0;
    }
    Loop l = {0.0, P(VR_speed_bandwidth), P(VR_b_visc) / P(VR_J), P(VR_tau_current), 0};
    double pm = phase_margin(&l);
    if (!(pm >= MIN_PHASE_MARGIN)) {
        FMI2_SAY(log, ModelError, "logStatusError", "speed_bandwidth = %.17g: gives the speed loop a phase margin of %.1f "
                 "deg (< %g deg) with tau_current = %g s; lower speed_bandwidth", P(VR_speed_bandwidth), pm,
                 MIN_PHASE_MARGIN, P(VR_tau_current));
        return 0;
    }
    if (!stable(&l)) {
        FMI2_SAY(log, ModelError, "logStatusError", "speed_bandwidth = %.17g: the speed loop is unstable; lower "
                 "speed_bandwidth", P(VR_speed_bandwidth));
        return 0;
    }
    return 1;
}

/* ---- stepping (SpindleDrive.step / _digital, operation for operation) ---------------------------- */
/* Sub-steps per communication step; 0 when there would be too many (refused by model_step). */
static int substeps(const double *values, double dt) { return drive_substeps(P(VR_substep), dt); }

/* The commanded speed as the drive takes it (rev/min, limited to speed_max); *limited: it was. */
static double setpoint(const double *values, const struct ModelState *m, int *limited)
{
    double s_max = P(VR_speed_max);
    *limited = fabs(m->command) > s_max;
    return *limited ? copysign(s_max, m->command) : m->command;
}

static void publish(double *values, const struct ModelState *m, double w_mean, double torque)
{
    int clamped;
    double speed = w_mean / RAD_S_PER_RPM, set = setpoint(values, m, &clamped);
    double band = fmax(P(VR_at_speed_band) * fabs(set), P(VR_at_speed_min));
    values[VR_speed] = speed;
    values[VR_at_speed] = fabs(speed - set) <= band;
    values[VR_torque] = torque;
    values[VR_power] = torque * w_mean * 1e-3;
    values[VR_limited] = m->limited;
    values[VR_revolutions] = m->a_meas / (2.0 * PI);
}

static void digital(const double *values, struct ModelState *m, double dt, int enabled)
{
    int n = substeps(values, dt), limited;
    double h = dt / n;
    double xi = m->x[0], torque = m->x[1], angle = m->x[2], speed = m->x[3];
    double kp = m->kp, ki = m->ki, t_max = P(VR_torque_max), p_max = m->power_max;
    double tc = P(VR_tau_coulomb) + m->load;   /* the load opposes the rotation as Coulomb friction does */
    double q = m->quantum;
    double w_set = setpoint(values, m, &limited) * RAD_S_PER_RPM;
    double a_meas = m->a_last;
    for (int i = 0; i < n; i++) {
        double a_prev = a_meas, t_cmd;
        a_meas = drive_encoder(angle, q);
        if (enabled) {
            double w_meas = (a_meas - a_prev) / h;
            double e = w_set - w_meas;
            double t_lim = w_meas == 0.0 ? t_max : fmin(t_max, p_max / fabs(w_meas));   /* torque and power */
            t_cmd = drive_torque_limit(kp * e + ki * xi, t_lim, 0, e, h, &xi, &limited);
        } else {
            t_cmd = 0.0;
            xi = 0.0;
        }
        drive_plant_step(m->Ad, m->Bd, tc, t_cmd, h, &torque, &angle, &speed);
    }
    m->x[0] = xi; m->x[1] = torque; m->x[2] = angle; m->x[3] = speed;
    m->a_last = a_meas;
    m->a_meas = drive_encoder(angle, q);
    m->limited = limited;
}

/* ---- the model interface ----------------------------------------------------------------------- */
int model_init(double *values, ModelState *m, const Fmi2Log *log)
{
    if (!parameters_ok(values, log)) return -1;
    memset(m, 0, sizeof *m);
    derive(values, m);
    publish(values, m, 0.0, 0.0);
    return 0;
}

int model_step(double *values, ModelState *m, double t, double dt, const Fmi2Log *log)
{
    if (!drive_substeps_ok(log, P(VR_substep), dt)) return -1;
    double cmd = P(VR_speed_cmd), dir = P(VR_direction), load = P(VR_load_torque);
    int bad_cmd = !isfinite(cmd), bad_dir = dir != -1.0 && dir != 0.0 && dir != 1.0;
    int bad_load = !(load >= 0.0 && isfinite(load)), bad = bad_cmd || bad_dir || bad_load;
    if (bad && !m->fault) {   /* never act on a broken command: hold the last good one, say why once */
        if (bad_cmd)
            FMI2_SAY(log, ModelWarning, "logStatusWarning", "t = %.4f s: input speed_cmd = %g: must be finite; holding the "
                     "last command", t, cmd);
        else if (bad_dir)
            FMI2_SAY(log, ModelWarning, "logStatusWarning", "t = %.4f s: input direction = %.0f: must be -1, 0 or 1; holding "
                     "the last command", t, dir);
        else
            FMI2_SAY(log, ModelWarning, "logStatusWarning", "t = %.4f s: input load_torque = %g: must be finite and >= 0; "
                     "holding the last command", t, load);
    }
    m->fault = bad;
    if (!bad) { m->command = dir * cmd; m->load = load; }
    double a0 = m->a_meas;
    if (drive_plant_map(m->Ap, m->Bp, dt / substeps(values, dt), &m->plant_h, m->Ad, m->Bd) != 0) goto numeric;
    digital(values, m, dt, P(VR_enable) != 0.0);
    double w_mean = (m->a_meas - a0) / dt;
    if (!isfinite(m->a_meas) || !isfinite(w_mean) || !isfinite(m->x[1])) goto numeric;
    publish(values, m, w_mean, m->x[1]);
    return 0;
numeric:
    FMI2_SAY(log, ModelError, "logStatusError", "t = %.4f s: the spindle model left the finite numbers (step %g s)", t, dt);
    return -1;
}

int model_restore(double *values, ModelState *m, int judged, const Fmi2Log *log)
{
    if (!judged && !parameters_ok(values, log)) return -1;
    derive(values, m);                       /* never trust derived data from a state record */
    double dyn[] = {m->x[0], m->x[1], m->x[2], m->x[3], m->a_meas, m->a_last, m->command, m->load};
    if (!drive_state_finite(log, "spindle", dyn, sizeof dyn / sizeof dyn[0])) return -1;
    if (!(m->load >= 0.0)) {
        FMI2_SAY(log, ModelError, "logStatusError", "FMU state: the spindle state holds a load torque of %g, not >= 0", m->load);
        return -1;
    }
    if (!drive_state_flags(log, "spindle", m->limited, m->fault)) return -1;
    return 0;
}
