/*
 * ncfmu's master loop in C: the fixed-step loop of ncfmu.cosim.master, over the FMUs' own FMI 2.0
 * functions, in the order of the master's algorithm (ncfmu.cosim.algorithm), which it is handed as its
 * schedule: the calls of one step as (what, slave) pairs, PLAN_GATHER, PLAN_STEP or PLAN_READ.
 *
 * It does exactly what the Python loop does, call for call: GATHER a slave's inputs from the
 * global output vectors (one per kind); STEP: send a kind only when its values changed since last sent,
 * then fmi2DoStep; READ its outputs into its slice of the global vector; after each step whose count is a
 * multiple of the output interval (in steps), copy the recorded prefix of every global vector into that
 * row of the record window (a bounded buffer: row r of the run goes to row r - row_base). The inputs'
 * gather indices say where each input reads from: its source's output, or a slot Python writes (an
 * input CSV, a forced value); Python changes them between calls, never during one. The plan (index arrays,
 * buffers, function pointers) is prepared by Python (ncfmu.cosim.native_loop); nothing is allocated
 * here. The first call returning more than fmi2Warning stops the loop; Python turns the report into
 * the same SimulationError as the Python loop raises.
 *
 * No FMI header: the function types are spelled out (fmi2Component is a void *, fmi2ValueReference an
 * unsigned int, fmi2Integer and fmi2Boolean are ints).
 */
#include <stddef.h>
#include <stdint.h>
#include <string.h>

typedef int (*set_real_fn)(void *, const unsigned int *, size_t, const double *);
typedef int (*set_int_fn)(void *, const unsigned int *, size_t, const int *);
typedef int (*get_real_fn)(void *, const unsigned int *, size_t, double *);
typedef int (*get_int_fn)(void *, const unsigned int *, size_t, int *);
typedef int (*do_step_fn)(void *, double, double, int);

enum { CALL_SET = 0, CALL_DO_STEP = 1, CALL_GET = 2 };
/* The calls of a schedule: ncfmu.cosim.algorithm's GATHER, STEP, READ. */
enum { PLAN_GATHER = 0, PLAN_STEP = 1, PLAN_READ = 2 };

typedef struct {
    void *function;             /* fmi2SetXxx (writes) or fmi2GetXxx (reads) */
    const unsigned int *vrs;
    size_t n;
    void *data;                 /* the slave's bound buffer: inputs to send, or its slice of the vector */
    const intptr_t *gather;     /* writes: the slot in the global vector of each input */
    const void *vector;         /* writes: the global output vector of this kind */
    void *sent;                 /* writes: the values last sent */
    int32_t *sent_valid;        /* writes: 0 until sent (Python clears it when the FMU may have changed) */
    int32_t is_real;            /* 8-byte doubles, else 4-byte ints */
    int32_t kind;               /* 0 Real, 1 Integer, 2 Boolean: for the error report */
} ncfmu_transfer;

typedef struct {
    void *component;
    void *do_step;
    ncfmu_transfer *writes;
    ncfmu_transfer *reads;
    int32_t n_writes;
    int32_t n_reads;
} ncfmu_slave;

typedef struct {
    char *table;                /* row r starts at table + r * bytes */
    const void *vector;
    size_t bytes;
} ncfmu_record;

typedef struct {
    int32_t status;
    int32_t slave;
    int32_t call;               /* CALL_SET, CALL_DO_STEP, CALL_GET */
    int32_t kind;
    int64_t step;
} ncfmu_failure;

/* gather, send and read_outputs stay functions of their own (gcc would inline them into the one loop): a
 * profile names the FMI calls each makes (bench/callgrind_step.py counts an FMU's Set and Get calls by them). */
#define NCFMU_OWN_FRAME __attribute__((noinline))

static NCFMU_OWN_FRAME void gather(const ncfmu_slave *s)
{
    for (int32_t k = 0; k < s->n_writes; k++) {
        const ncfmu_transfer *w = &s->writes[k];
        if (w->is_real) {
            const double *v = (const double *)w->vector;
            double *d = (double *)w->data;
            for (size_t j = 0; j < w->n; j++) d[j] = v[w->gather[j]];
        } else {
            const int *v = (const int *)w->vector;
            int *d = (int *)w->data;
            for (size_t j = 0; j < w->n; j++) d[j] = v[w->gather[j]];
        }
    }
}

/* An FMU input keeps its value until set again: a kind is sent only when its values changed. */
static NCFMU_OWN_FRAME int send(const ncfmu_slave *s, ncfmu_failure *fail)
{
    for (int32_t k = 0; k < s->n_writes; k++) {
        const ncfmu_transfer *w = &s->writes[k];
        size_t size = w->is_real ? sizeof(double) : sizeof(int);
        if (*w->sent_valid && memcmp(w->sent, w->data, w->n * size) == 0) continue;
        int status = w->is_real ? ((set_real_fn)w->function)(s->component, w->vrs, w->n, (const double *)w->data)
                                : ((set_int_fn)w->function)(s->component, w->vrs, w->n, (const int *)w->data);
        if (status > 1) {
            fail->status = status;
            fail->call = CALL_SET;
            fail->kind = w->kind;
            return 0;
        }
        memcpy(w->sent, w->data, w->n * size);
        *w->sent_valid = 1;
    }
    return 1;
}

static NCFMU_OWN_FRAME int read_outputs(const ncfmu_slave *s, ncfmu_failure *fail)
{
    for (int32_t k = 0; k < s->n_reads; k++) {
        const ncfmu_transfer *r = &s->reads[k];
        int status = r->is_real ? ((get_real_fn)r->function)(s->component, r->vrs, r->n, (double *)r->data)
                                : ((get_int_fn)r->function)(s->component, r->vrs, r->n, (int *)r->data);
        if (status > 1) {
            fail->status = status;
            fail->call = CALL_GET;
            fail->kind = r->kind;
            return 0;
        }
    }
    return 1;
}

static int do_step(const ncfmu_slave *s, double t, double h, ncfmu_failure *fail)
{
    /* noSetFMUStatePriorToCurrentPoint = fmi2False: branch runs restore states saved earlier (as fmu.py) */
    int status = ((do_step_fn)s->do_step)(s->component, t, h, 0);
    if (status > 1) {
        fail->status = status;
        fail->call = CALL_DO_STEP;
        fail->kind = -1;
        return 0;
    }
    return 1;
}

/* Steps first .. last - 1: step i runs from start + h * i (the Python loop's time, the same operations;
 * compiled without FMA contraction) and, when (i + 1) is a multiple of every, is recorded in row
 * (i + 1) / every - row_base of the window. Python keeps the rows of a call inside the window.
 * Returns 0, or the failing call's status (details in *fail). */
int ncfmu_loop(const ncfmu_slave *slaves, const int32_t *schedule, int32_t n_calls, double start, double h,
               int64_t first, int64_t last, const ncfmu_record *records, int32_t n_records, int64_t every,
               int64_t row_base, ncfmu_failure *fail)
{
    for (int64_t i = first; i < last; i++) {
        double t = start + h * (double)i;
        fail->step = i;
        for (int32_t c = 0; c < n_calls; c++) {
            int32_t what = schedule[2 * c], s = schedule[2 * c + 1];
            fail->slave = s;
            if (what == PLAN_GATHER) gather(&slaves[s]);
            else if (what == PLAN_STEP) {
                if (!send(&slaves[s], fail) || !do_step(&slaves[s], t, h, fail)) return fail->status;
            } else if (!read_outputs(&slaves[s], fail)) return fail->status;
        }
        if ((i + 1) % every) continue;
        size_t row = (size_t)((i + 1) / every - row_base);
        for (int32_t r = 0; r < n_records; r++)
            memcpy(records[r].table + row * records[r].bytes, records[r].vector, records[r].bytes);
    }
    return 0;
}
