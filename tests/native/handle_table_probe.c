/* A lookup of fmi2_machine.h's live table (fmi2_instance_find without the lock) interrupted, at one of its loads of
 * the table, by an fmi2Instantiate of another thread that outgrows the table: the interruption is made
 * deterministic by running the other thread's change from within the load (atomic_load_explicit wrapped). Built
 * with AddressSanitizer: a read beyond a table ends the process with its report.
 *
 * usage: handle_table_probe live|n   (the load before which the table changes)
 *        handle_table_probe threads   (lookups on two threads while two others instantiate and free: a live handle
 *                                      always finds its instance, a made-up one none) */
#include <stdatomic.h>
#include <stdio.h>
#include <string.h>
#include <unistd.h>

static const volatile void *probe_at;       /* the address whose next load lets the other thread change the table */
static void probe_change(void);

static inline void probe_before_load(const volatile void *p)
{
    if (probe_at && p == probe_at) { probe_at = NULL; probe_change(); }
}

#undef atomic_load_explicit
#define atomic_load_explicit(p, order) (probe_before_load(p), __atomic_load_n((p), (order)))

#include "fmi2_machine.h"

static int objects[64];

static void probe_change(void)
{
    if (!fmi2_instance_add(&objects[63])) { fprintf(stderr, "no handle\n"); _exit(3); }
}

enum { KEPT = 4, CHURN = 40, ROUNDS = 300, LOOKUPS = 100000 };
static fmi2Component kept[KEPT];
static atomic_int churning, wrong;

static void *churn(void *arg)
{
    fmi2Component made[CHURN];
    for (int r = 0; r < ROUNDS; r++) {
        for (int k = 0; k < CHURN; k++) made[k] = fmi2_instance_add(arg);
        for (int k = 0; k < CHURN; k++)
            if (fmi2_instance_find(made[k], 1) != arg) atomic_fetch_add(&wrong, 1);
    }
    atomic_fetch_sub(&churning, 1);
    return NULL;
}

static void *look_up(void *arg)
{
    (void)arg;
    for (int k = 0; k < LOOKUPS || atomic_load(&churning) > 0; k++) {
        if (fmi2_instance_find(kept[k % KEPT], 0) != &objects[k % KEPT]) atomic_fetch_add(&wrong, 1);
        if (fmi2_instance_find((fmi2Component)(uintptr_t)0x1234, 0)) atomic_fetch_add(&wrong, 1);
    }
    return NULL;
}

static int threads(void)
{
    for (int k = 0; k < KEPT; k++) kept[k] = fmi2_instance_add(&objects[k]);
    atomic_store(&churning, 2);
    pthread_t t[4];
    pthread_create(&t[0], NULL, churn, &objects[40]);
    pthread_create(&t[1], NULL, churn, &objects[41]);
    pthread_create(&t[2], NULL, look_up, NULL);
    pthread_create(&t[3], NULL, look_up, NULL);
    for (int k = 0; k < 4; k++) pthread_join(t[k], NULL);
    printf("%d wrong lookups\n", atomic_load(&wrong));
    return 0;
}

int main(int argc, char **argv)
{
    if (argc != 2) return 2;
    if (strcmp(argv[1], "threads") == 0) return threads();
    size_t cap;
    for (int k = 0;; k++) {                      /* fill the table to its capacity: the next add outgrows it */
        pthread_mutex_lock(&fmi2_handles.lock);
        int full = fmi2_handles.cap && __atomic_load_n(&fmi2_handles.n, __ATOMIC_RELAXED) == fmi2_handles.cap;
        cap = fmi2_handles.cap;
        pthread_mutex_unlock(&fmi2_handles.lock);
        if (full) break;
        if (!fmi2_instance_add(&objects[k])) return 3;
    }
    probe_at = strcmp(argv[1], "live") == 0 ? (const volatile void *)&fmi2_handles.live
                                             : (const volatile void *)&fmi2_handles.n;
    /* a handle that is not live: the lookup reads every entry */
    void *found = fmi2_instance_find((fmi2Component)(uintptr_t)0x1234, 0);
    if (probe_at) { fprintf(stderr, "the lookup did not load %s\n", argv[1]); return 4; }
    if (found) { fprintf(stderr, "a made-up handle found an instance\n"); return 5; }
    printf("table of %zu outgrown during a lookup: no read beyond it\n", cap);
    return 0;
}
