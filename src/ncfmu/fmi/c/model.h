/*
 * ncfmu: the model interface -- what ncfmu's one FMI layer (fmi2_functions.c) asks of a model, as the
 * Reference-FMUs keep model.c apart from fmi2Functions.c.
 *
 * Two kinds of model stand behind it:
 *   - a native model (the ServoAxis): native_model.c implements this interface over a table of variables
 *     generated from the model's Python ports (model_vars.h) and the model's equations, which its own C file
 *     gives through the three functions of section 2 below (model_init, model_step, model_restore);
 *   - a Python model (the controller FMUs): python_model.c, the Python runtime driving the Python slave
 *     through the contract (ncfmu_contract.h).
 *
 * The FMI layer holds everything FMI: instances and handles, the state machine (fmi2_machine.h), value
 * references checked against the model's table (unknown, wrong type, an output, a fixed parameter after
 * initialisation, a value outside the port's rule), step times, FMU-state handles. A model is asked only
 * what is its own: its variables' values, its steps, its states. Every call returns a ModelStatus, the
 * interface's own status type (as the Reference-FMUs' model.h has its Status): its numbers are FMI 2.0's and
 * FMI 3.0's statuses' alike, which each layer asserts and returns as its own; nothing a model says is ModelFatal.
 */
#ifndef NCFMU_MODEL_H
#define NCFMU_MODEL_H

#include <stddef.h>
#include "fmi2_machine.h"

/* ---- 1. what every model gives the FMI layer -------------------------------------------------------- */
typedef enum { ModelOK = 0, ModelWarning = 1, ModelDiscard = 2, ModelError = 3, ModelFatal = 4 } ModelStatus;
typedef enum { V_REAL = 0, V_INTEGER = 1, V_BOOLEAN = 2, V_STRING = 3 } VarType;
typedef enum { V_PARAMETER = 0, V_INPUT = 1, V_OUTPUT = 2, V_OTHER = 3 } VarCausality;

typedef struct {
    const char *name;       /* NULL: no variable has this value reference */
    VarType type;
    VarCausality causality;
    int tunable;            /* a parameter that may change in step mode */
    double start;
    int has_min, has_max, min_exclusive;
    double min, max;
    const char *rule;       /* the port's rule as text: "must be in (0, 10000]"; NULL: the model judges the value */
} VarInfo;

/* The build's GUID (the modelDescription's; FMI 3.0's instantiationToken) and the model identifier. */
extern const char FMU_MODEL_GUID[];
extern const char FMU_MODEL_IDENTIFIER[];

/* A model instance (the layer's Instance holds one). */
typedef struct Model Model;

/* What a Get/Set carries, by type: double (Real), int (Integer: fmi2Integer, fmi3Int32), int (Boolean, 0 or 1)
 * and const char * (String; a Get's strings stay valid until the next call on the instance). */

/* Every function that may log is given ``call``, the name of the call the host made (fmi2Instantiate,
 * fmi3InstantiateCoSimulation, fmi3DoStep, ...), and names it in what it logs. */

/* A new model for the instance ``name`` (resources: the FMU's resources folder, a path), logging to ``log``
 * (kept for the instance's life); NULL (logged) when it cannot be made. */
Model *fmu_model_new(const char *call, const char *name, const char *resources, int visible, const Fmi2Log *log);
void fmu_model_free(Model *m);

/* The variables, by value reference 0 .. *n - 1 (the table lives as long as the model, until fmu_model_reset). */
const VarInfo *fmu_model_variables(Model *m, unsigned *n);

/* Back to the state after fmu_model_new; not 0 (logged) when that fails (the instance can only be freed). */
int fmu_model_reset(Model *m, const char *call);

ModelStatus fmu_model_setup_experiment(Model *m, const char *call, int tolerance_defined, double tolerance, double start,
                                      int stop_defined, double stop);
ModelStatus fmu_model_enter_initialization(Model *m, const char *call);
/* ERROR (logged) when the parameters are refused: the instance stays in initialization mode. */
ModelStatus fmu_model_exit_initialization(Model *m, const char *call);
ModelStatus fmu_model_terminate(Model *m, const char *call);

/* One step from ``t`` by ``h`` (checked by the layer: finite, at least 1 ns, continuing); a failed step leaves
 * the model where it was. */
ModelStatus fmu_model_do_step(Model *m, const char *call, double t, double h);

/* Values of variables the layer checked (each vr a variable of ``type``; for a set, settable now; Strings
 * UTF-8 text; a value with a rule within it). A refused set changes nothing. */
ModelStatus fmu_model_get(Model *m, const char *call, const unsigned vr[], size_t n, VarType type, void *values);
ModelStatus fmu_model_set(Model *m, const char *call, const unsigned vr[], size_t n, VarType type, const void *values);

/* FMU states, opaque to the layer (it keeps them behind handles, with the instance's phase and time; a state
 * set that the model accepts brings its phase with it, as the Reference-FMUs' setFMUState does, in every phase
 * the instance is in).
 * ``call``: the name of the call the host made (fmi2SetFMUstate, fmi3SetFMUState, ...), for what is logged.
 * take: a new state of the model (NULL, logged, when none can be taken); restore: ``initialized`` says the
 * instance's parameters were accepted at fmi2ExitInitializationMode (a state with the same ones needs no new
 * judgement); ERROR (logged) when refused, the model unchanged. */
void *fmu_model_state_take(Model *m, const char *call);
ModelStatus fmu_model_state_restore(Model *m, const char *call, void *state, int initialized);
void fmu_model_state_free(Model *m, void *state);

/* Serialized: the model's own format, which carries the state's ``time`` and ``phase`` (one of P_*).
 * serialize: the bytes in a buffer of the model's (valid until the next call on the model), NULL (logged) when
 * it cannot; deserialize: a state (checked: bad bytes are refused, logged, NULL). */
const unsigned char *fmu_model_serialize(Model *m, const char *call, void *state, int phase, double time,
                                         size_t *size);
void *fmu_model_deserialize(Model *m, const char *call, const unsigned char *bytes, size_t size, int *phase,
                            double *time);

/* A parameter's value against its rule (vr ``v``'s table entry); 1 when it holds, else logs and returns 0. */
static inline int fmi2_value_ok(const Fmi2Log *log, const VarInfo *v, double x)
{
    if (v->causality != V_PARAMETER || v->type == V_BOOLEAN || v->type == V_STRING || !v->rule) return 1;
    const char *rule = NULL;
    if (!isfinite(x)) rule = "must be finite";
    else if ((v->has_min && (x < v->min || (v->min_exclusive && x == v->min))) || (v->has_max && x > v->max))
        rule = v->rule;
    if (!rule) return 1;
    FMI2_SAY(log, ModelError, "logStatusError", "%s = %.17g: %s", v->name, x, rule);
    return 0;
}

/* ---- 2. what a native model's C file gives native_model.c --------------------------------------------
 * Every variable lives in ``values[vr]`` (Integer and Boolean as exact doubles); the table of variables
 * (name, type, causality, start and the port's rule) is generated from the model's Python ports into
 * model_vars.h, so a parameter's rule is stated once. The model keeps whatever else it needs in its
 * ``ModelState`` (plain data: it is copied and serialized as bytes, and re-derived and checked by
 * model_restore when it comes back). */
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
