/* What a foreign test model gives the frame (frame2.c): its variables and three functions. */
#ifndef FOREIGN_MODEL_H
#define FOREIGN_MODEL_H

#include <stddef.h>

#define MAX_VARS 32

typedef void (*Logger)(void *environment, const char *instance, int status, const char *category,
                       const char *message, ...);

typedef struct {
    char *name;
    Logger logger;
    void *environment;
    int phase;
    double time;
    int terminated;                 /* the model asks the host to end the simulation */
    double r[MAX_VARS];
    int i[MAX_VARS];
    int b[MAX_VARS];
    char *s[MAX_VARS];
    double x[MAX_VARS];             /* the model's own states */
} Instance;

extern const unsigned N_REAL, N_INTEGER, N_BOOLEAN, N_STRING;

/* defaults of every variable and state (at instantiation and fmi2Reset) */
void model_defaults(Instance *m);
/* 0: not settable, 1: a parameter (before stepping), 2: an input; type is 'r', 'i', 'b' or 's' */
int model_settable(char type, unsigned vr);
/* at fmi2ExitInitializationMode: NULL, or why the parameters are refused */
const char *model_initialize(Instance *m);
/* one communication step: an fmi2Status (0 OK, 2 Discard, 3 Error) */
int model_step(Instance *m, double t, double h);

#endif
