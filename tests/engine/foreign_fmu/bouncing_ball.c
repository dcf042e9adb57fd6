/* BouncingBall: a minimal FMI 2.0 Model Exchange FMU in C whose event update moves a
 * continuous state by a finite amount (tests/engine/test_me_events.py builds it).
 *
 * States h (height, m) and v (velocity, m/s): der(h) = v, der(v) = -g.  Event indicator
 * z = h; at its root with v < 0 fmi2NewDiscreteStates reverses the velocity, v := -e v,
 * sets h := 0 and counts the bounce.  A master that restarts its integrator from anything
 * but the states this update reports lets the ball fall through the floor. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

#define GUID "{8c4d2f9a-3e61-4b7d-a0c5-5f1e9b2d7a43}"

enum { VR_H = 0, VR_DER_H = 1, VR_V = 2, VR_DER_V = 3, VR_G = 4, VR_E = 5, VR_H0 = 6, VR_BOUNCES = 7 };

typedef struct {
    double h, v, g, e, h0, time;
    int bounces;
    fmi2CallbackLogger log;
    fmi2ComponentEnvironment env;
    char name[128];
} Ball;

static fmi2Status refuse(Ball *b, const char *what) {
    if (b->log) b->log(b->env, b->name, fmi2Error, "error", "%s", what);
    return fmi2Error;
}

static void defaults(Ball *b) {
    b->h0 = 1.0; b->h = 1.0; b->v = 0.0; b->g = 9.81; b->e = 0.7; b->time = 0.0; b->bounces = 0;
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }
fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cats[]) {
    (void)c; (void)on; (void)n; (void)cats; return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String resources,
                              const fmi2CallbackFunctions *callbacks, fmi2Boolean visible, fmi2Boolean logging) {
    (void)resources; (void)visible; (void)logging;
    if (type != fmi2ModelExchange || strcmp(guid, GUID) != 0) return NULL;
    Ball *b = calloc(1, sizeof *b);
    if (!b) return NULL;
    defaults(b);
    b->log = callbacks ? callbacks->logger : NULL;
    b->env = callbacks ? callbacks->componentEnvironment : NULL;
    strncpy(b->name, name ? name : "", sizeof b->name - 1);
    return b;
}

void fmi2FreeInstance(fmi2Component c) { free(c); }
fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolDefined, fmi2Real tol, fmi2Real start,
                               fmi2Boolean stopDefined, fmi2Real stop) {
    (void)tolDefined; (void)tol; (void)stopDefined; (void)stop;
    ((Ball *)c)->time = start;
    return fmi2OK;
}
fmi2Status fmi2EnterInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    Ball *b = c;
    b->h = b->h0;
    return fmi2OK;
}
fmi2Status fmi2Terminate(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2Reset(fmi2Component c) { defaults(c); return fmi2OK; }

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real value[]) {
    Ball *b = c;
    for (size_t i = 0; i < n; i++) {
        switch (vr[i]) {
        case VR_H: value[i] = b->h; break;
        case VR_DER_H: value[i] = b->v; break;
        case VR_V: value[i] = b->v; break;
        case VR_DER_V: value[i] = -b->g; break;
        case VR_G: value[i] = b->g; break;
        case VR_E: value[i] = b->e; break;
        case VR_H0: value[i] = b->h0; break;
        default: return refuse(b, "fmi2GetReal: no Real variable with this value reference");
        }
    }
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real value[]) {
    Ball *b = c;
    for (size_t i = 0; i < n; i++) {
        if (!isfinite(value[i])) return refuse(b, "fmi2SetReal: a value is not finite");
        switch (vr[i]) {
        case VR_G:
            if (!(value[i] > 0)) return refuse(b, "variable 'g' must be > 0 m/s2");
            b->g = value[i];
            break;
        case VR_E:
            if (!(value[i] >= 0 && value[i] <= 1)) return refuse(b, "variable 'e' must be in [0, 1]");
            b->e = value[i];
            break;
        case VR_H0:
            if (!(value[i] > 0)) return refuse(b, "variable 'h0' must be > 0 m");
            b->h0 = value[i];
            break;
        default: return refuse(b, "fmi2SetReal: no settable Real variable with this value reference");
        }
    }
    return fmi2OK;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer value[]) {
    Ball *b = c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] != VR_BOUNCES) return refuse(b, "fmi2GetInteger: no Integer variable with this value reference");
        value[i] = b->bounces;
    }
    return fmi2OK;
}
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean value[]) {
    (void)vr; (void)value; return n ? refuse(c, "fmi2GetBoolean: the ball has no Boolean variable") : fmi2OK;
}
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String value[]) {
    (void)vr; (void)value; return n ? refuse(c, "fmi2GetString: the ball has no String variable") : fmi2OK;
}
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer value[]) {
    (void)vr; (void)value; return n ? refuse(c, "fmi2SetInteger: the ball has no settable Integer variable") : fmi2OK;
}
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean value[]) {
    (void)vr; (void)value; return n ? refuse(c, "fmi2SetBoolean: the ball has no Boolean variable") : fmi2OK;
}
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String value[]) {
    (void)vr; (void)value; return n ? refuse(c, "fmi2SetString: the ball has no String variable") : fmi2OK;
}

/* -- Model Exchange ------------------------------------------------------------------------ */
fmi2Status fmi2SetTime(fmi2Component c, fmi2Real t) { ((Ball *)c)->time = t; return fmi2OK; }

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx) {
    Ball *b = c;
    if (nx != 2) return refuse(b, "fmi2SetContinuousStates: the ball has 2 states");
    b->h = x[0]; b->v = x[1];
    return fmi2OK;
}
fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
    Ball *b = c;
    if (nx != 2) return refuse(b, "fmi2GetContinuousStates: the ball has 2 states");
    x[0] = b->h; x[1] = b->v;
    return fmi2OK;
}
fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real dx[], size_t nx) {
    Ball *b = c;
    if (nx != 2) return refuse(b, "fmi2GetDerivatives: the ball has 2 states");
    dx[0] = b->v; dx[1] = -b->g;
    return fmi2OK;
}
fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real z[], size_t nz) {
    Ball *b = c;
    if (nz != 1) return refuse(b, "fmi2GetEventIndicators: the ball has 1 event indicator");
    z[0] = b->h;
    return fmi2OK;
}
fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
    (void)c; for (size_t i = 0; i < nx; i++) x[i] = 1.0; return fmi2OK;
}
fmi2Status fmi2EnterEventMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) { (void)c; return fmi2OK; }

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *info) {
    Ball *b = c;
    info->newDiscreteStatesNeeded = fmi2False;
    info->terminateSimulation = fmi2False;
    info->nominalsOfContinuousStatesChanged = fmi2False;
    info->valuesOfContinuousStatesChanged = fmi2False;
    info->nextEventTimeDefined = fmi2False;
    info->nextEventTime = 0.5;      /* not defined: a master must not take it for a time event */
    if (b->h <= 0.0 && b->v < 0.0) {        /* the bounce: a finite jump of v */
        b->h = 0.0;
        b->v = -b->e * b->v;
        b->bounces += 1;
        info->valuesOfContinuousStatesChanged = fmi2True;
    }
    return fmi2OK;
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetPrior, fmi2Boolean *enterEventMode,
                                       fmi2Boolean *terminate) {
    (void)c; (void)noSetPrior; *enterEventMode = fmi2False; *terminate = fmi2False; return fmi2OK;
}

/* Partials of der(h) = v and der(v) = -g with respect to the states h and v. */
static double partial(fmi2ValueReference unknown, fmi2ValueReference known) {
    return unknown == VR_DER_H && known == VR_V ? 1.0 : 0.0;
}
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference unknowns[], size_t nu,
                                        const fmi2ValueReference knowns[], size_t nk, const fmi2Real dk[],
                                        fmi2Real du[]) {
    for (size_t i = 0; i < nu; i++) {
        if (unknowns[i] != VR_DER_H && unknowns[i] != VR_DER_V && unknowns[i] != VR_H && unknowns[i] != VR_V)
            return refuse(c, "fmi2GetDirectionalDerivative: unknowns are the states and derivatives");
        du[i] = 0.0;
        for (size_t j = 0; j < nk; j++)
            du[i] += (unknowns[i] == knowns[j] ? 1.0 : partial(unknowns[i], knowns[j])) * dk[j];
    }
    return fmi2OK;
}

/* What the ball does not offer: its capability flags say so; these answer an error. */
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s) { (void)s; return refuse(c, "no FMU states"); }
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) { (void)s; return refuse(c, "no FMU states"); }
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s) { (void)s; return refuse(c, "no FMU states"); }
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *n) {
    (void)s; (void)n; return refuse(c, "no FMU states");
}
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n) {
    (void)s; (void)b; (void)n; return refuse(c, "no FMU states");
}
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate *s) {
    (void)b; (void)n; (void)s; return refuse(c, "no FMU states");
}
