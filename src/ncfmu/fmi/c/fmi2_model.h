/*
 * ncfmu: what a native model gives the native FMI layer (fmi2_native.c), as the Reference-FMUs keep
 * model.c apart from fmi2Functions.c.
 *
 * Every variable lives in ``values[vr]`` (Integer and Boolean as exact doubles); the table of
 * variables (name, type, causality, start and the port's rule) is generated from the model's Python
 * ports into model_vars.h, so a parameter's rule is stated once. The model keeps whatever else it
 * needs in its ``ModelState`` (plain data: it is copied and serialized as bytes, and re-derived and
 * checked by model_restore when it comes back).
 */
#ifndef NCFMU_FMI2_MODEL_H
#define NCFMU_FMI2_MODEL_H

#include <stddef.h>
#include "fmi2_machine.h"

typedef enum { V_REAL = 0, V_INTEGER = 1, V_BOOLEAN = 2 } VarType;
typedef enum { V_PARAMETER = 0, V_INPUT = 1, V_OUTPUT = 2 } VarCausality;

typedef struct {
    const char *name;
    VarType type;
    VarCausality causality;
    int tunable;            /* a parameter that may change in step mode (none of the servo's) */
    double start;
    int has_min, has_max, min_exclusive;
    double min, max;
    const char *rule;       /* the port's rule as text: "must be in (0, 10000]" */
} VarInfo;

typedef struct ModelState ModelState;

/* Size of the model's state record. */
size_t model_state_size(void);

/* Check the parameters against each other (a single value's range is checked by the FMI layer when
 * it is set), derive what the model needs, and put the model in its initial state with its outputs
 * set. 0 when fine; else logs (naming the parameter, its value and the rule) and returns -1. */
int model_init(double *values, ModelState *m, const Fmi2Log *log);

/* Advance from ``t`` by ``h`` > 0 s: read the inputs from ``values``, write the outputs. 0 when fine. */
int model_step(double *values, ModelState *m, double t, double h, const Fmi2Log *log);

/* After a state record came back (fmi2SetFMUstate, fmi2DeSerializeFMUstate): derive again what is
 * derived from the parameters and check the dynamic state is sane; ``judged``: the parameters are ones
 * model_init already accepted (their checks may be skipped). 0 when fine, else logs and -1. */
int model_restore(double *values, ModelState *m, int judged, const Fmi2Log *log);

#endif
