/*
 * ncfmu: the FMI 2.0 co-simulation state machine, written once.
 *
 * Included by both of ncfmu's FMI layers: the Python FMUs' binary, status_shim.c (the
 * controller FMUs) and the native layer of the C FMUs (ServoAxis). It says which call is allowed in
 * which state, what a refused call returns (fmi2Error: the instance stays usable and freeable;
 * fmi2Fatal is kept for a broken instance, never for bad input), and checks what every FMU checks
 * the same way: experiment times, step sizes, UTF-8 strings. Cf. the Reference-FMUs' fmi2Functions.c.
 */
#ifndef NCFMU_FMI2_MACHINE_H
#define NCFMU_FMI2_MACHINE_H

#include <math.h>
#include "fmi2Functions.h"

/* The states of an instance (FMI 2.0 co-simulation, section 4.2.4), as bits so a call lists the
 * states it is allowed in. A refused call leaves the instance in its state (it stays usable), so the
 * standard's error state is never entered. */
enum { P_INSTANTIATED = 1, P_INIT = 2, P_STEP = 4, P_TERMINATED = 8 };

/* Which calls are allowed where. */
#define P_SETUP      P_INSTANTIATED                                   /* fmi2SetupExperiment, EnterInit */
#define P_SETTABLE   (P_INSTANTIATED | P_INIT | P_STEP)              /* fmi2Set* (inputs in step mode) */
#define P_GETTABLE   (P_INIT | P_STEP | P_TERMINATED)                /* fmi2Get* */
#define P_ANY        (P_INSTANTIATED | P_INIT | P_STEP | P_TERMINATED) /* Reset, FMU-state calls */

static inline const char *fmi2_phase_name(int phase)
{
    return phase == P_INSTANTIATED ? "instantiated" : phase == P_INIT ? "initialization mode"
         : phase == P_STEP ? "step mode" : phase == P_TERMINATED ? "terminated" : "unknown";
}

/* The host's logger, as an instance keeps it. */
typedef struct {
    fmi2CallbackLogger logger;
    fmi2ComponentEnvironment env;
    const char *name;
} Fmi2Log;

#define FMI2_SAY(log, status, category, ...) \
    do { if ((log) && (log)->logger) (log)->logger((log)->env, (log)->name, (status), (category), __VA_ARGS__); } while (0)

/* 1 when ``call`` is allowed in ``phase``; else logs why and returns 0 (the call returns fmi2Error). */
static inline int fmi2_allowed(const Fmi2Log *log, int phase, const char *call, int phases)
{
    if (phase & phases) return 1;
    FMI2_SAY(log, fmi2Error, "error", "%s: not allowed in the %s state (FMI 2.0 state machine)",
             call, fmi2_phase_name(phase));
    return 0;
}

static inline int fmi2_experiment_ok(const Fmi2Log *log, double start, int stop_defined, double stop)
{
    if (isfinite(start) && (!stop_defined || (isfinite(stop) && stop >= start))) return 1;
    FMI2_SAY(log, fmi2Error, "error", "fmi2SetupExperiment: startTime = %g, stopTime = %g: "
             "times must be finite and stopTime >= startTime", start, stop);
    return 0;
}

static inline int fmi2_step_ok(const Fmi2Log *log, double t, double h)
{
    if (isfinite(t) && isfinite(h) && h > 0.0) return 1;
    FMI2_SAY(log, fmi2Error, "error", "fmi2DoStep: currentCommunicationPoint = %g, communicationStepSize = %g: "
             "the step size must be finite and > 0, the time finite", t, h);
    return 0;
}

/* 1 when the step, counted in whole nanoseconds as ncfmu's FMUs count it, is at least 1 ns. */
static inline int fmi2_step_ns_ok(const Fmi2Log *log, double h)
{
    if (nearbyint(h * 1e9) > 0.0) return 1;
    FMI2_SAY(log, fmi2Error, "error", "fmi2DoStep: communicationStepSize = %g s: below 1 ns", h);
    return 0;
}

/* 1 when a step at ``t`` continues from ``next`` (where the last successful step ended, or the start time,
 * or the time of a restored state), as the Reference-FMUs require; within half a nanosecond (steps are
 * whole nanoseconds) and the rounding of the host's own time arithmetic. */
static inline int fmi2_continues_ok(const Fmi2Log *log, double next, double t)
{
    if (fabs(t - next) <= 0.5e-9 + 1e-12 * fabs(next)) return 1;
    FMI2_SAY(log, fmi2Error, "error", "fmi2DoStep: currentCommunicationPoint = %.16g s, expected %.16g s (where the "
             "last step ended): an FMU steps on from where it is, or from a state restored with fmi2SetFMUstate",
             t, next);
    return 0;
}

/* 1 when ``s`` is well-formed UTF-8 (no overlongs, no surrogates, at most U+10FFFF). */
static inline int fmi2_utf8_ok(const unsigned char *s)
{
    while (*s) {
        unsigned c = *s++;
        int more = c < 0x80 ? 0 : (c >> 5) == 6 ? 1 : (c >> 4) == 14 ? 2 : (c >> 3) == 30 ? 3 : -1;
        if (more < 0) return 0;
        unsigned cp = more == 0 ? c : more == 1 ? c & 0x1F : more == 2 ? c & 0x0F : c & 0x07;
        for (int k = 0; k < more; k++) {
            if ((*s & 0xC0) != 0x80) return 0;
            cp = (cp << 6) | (*s++ & 0x3F);
        }
        if ((more == 1 && cp < 0x80) || (more == 2 && cp < 0x800) || (more == 3 && cp < 0x10000)
            || cp > 0x10FFFF || (cp >= 0xD800 && cp <= 0xDFFF)) return 0;
    }
    return 1;
}

#endif
