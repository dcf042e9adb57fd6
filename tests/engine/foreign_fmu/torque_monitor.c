/* TorqueMonitor: a minimal FMI 2.0 co-simulation FMU in C, an FMU that is not ours
 * (tests/test_own_fmu.py builds it).  It observes a torque input and outputs the largest
 * magnitude seen (Real), a status text (String) and a level (Enumeration).  The outputs
 * are updated in fmi2DoStep from the input at the step's start: no direct feedthrough. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

enum { VR_LIMIT = 0, VR_TORQUE = 1, VR_PEAK = 2, VR_STATUS = 3, VR_LEVEL = 4 };
enum { LEVEL_NORMAL = 1, LEVEL_HIGH = 2 };

typedef struct {
    double limit, torque, peak, time;
    int level;
    fmi2CallbackLogger log;
    fmi2ComponentEnvironment env;
    char name[128];
} Monitor;

static const char *status_of(const Monitor *m) { return m->level == LEVEL_HIGH ? "over limit" : "ok"; }

static fmi2Status refuse(Monitor *m, const char *what) {
    if (m->log) m->log(m->env, m->name, fmi2Error, "error", "%s", what);
    return fmi2Error;
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }
fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cats[]) {
    (void)c; (void)on; (void)n; (void)cats; return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String resources,
                              const fmi2CallbackFunctions *callbacks, fmi2Boolean visible, fmi2Boolean logging) {
    (void)resources; (void)visible; (void)logging;
    if (type != fmi2CoSimulation || strcmp(guid, "{5b0f6c2e-1d7a-4c55-9a64-0c7e3f2b9d11}") != 0) return NULL;
    Monitor *m = calloc(1, sizeof *m);
    if (!m) return NULL;
    m->limit = 500.0;
    m->level = LEVEL_NORMAL;
    m->log = callbacks ? callbacks->logger : NULL;
    m->env = callbacks ? callbacks->componentEnvironment : NULL;
    strncpy(m->name, name ? name : "", sizeof m->name - 1);
    return m;
}

void fmi2FreeInstance(fmi2Component c) { free(c); }
fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolDefined, fmi2Real tol, fmi2Real start,
                               fmi2Boolean stopDefined, fmi2Real stop) {
    (void)tolDefined; (void)tol; (void)stopDefined; (void)stop;
    ((Monitor *)c)->time = start;
    return fmi2OK;
}
fmi2Status fmi2EnterInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2Terminate(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2Reset(fmi2Component c) {
    Monitor *m = c;
    m->limit = 500.0; m->torque = m->peak = m->time = 0.0; m->level = LEVEL_NORMAL;
    return fmi2OK;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real value[]) {
    Monitor *m = c;
    for (size_t i = 0; i < n; i++) {
        switch (vr[i]) {
        case VR_LIMIT: value[i] = m->limit; break;
        case VR_TORQUE: value[i] = m->torque; break;
        case VR_PEAK: value[i] = m->peak; break;
        default: return refuse(m, "fmi2GetReal: no Real variable with this value reference");
        }
    }
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real value[]) {
    Monitor *m = c;
    for (size_t i = 0; i < n; i++) {
        if (!isfinite(value[i])) return refuse(m, "fmi2SetReal: a value is not finite");
        switch (vr[i]) {
        case VR_LIMIT:
            if (value[i] < 0) return refuse(m, "variable 'limit' must be >= 0 N.m");
            m->limit = value[i];
            break;
        case VR_TORQUE: m->torque = value[i]; break;
        default: return refuse(m, "fmi2SetReal: no settable Real variable with this value reference");
        }
    }
    return fmi2OK;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer value[]) {
    Monitor *m = c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] != VR_LEVEL) return refuse(m, "fmi2GetInteger: no Integer/Enumeration variable with this value reference");
        value[i] = m->level;
    }
    return fmi2OK;
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String value[]) {
    Monitor *m = c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] != VR_STATUS) return refuse(m, "fmi2GetString: no String variable with this value reference");
        value[i] = status_of(m);
    }
    return fmi2OK;
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean value[]) {
    (void)vr; (void)value; return n ? refuse(c, "fmi2GetBoolean: the monitor has no Boolean variable") : fmi2OK;
}
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer value[]) {
    (void)vr; (void)value; return n ? refuse(c, "fmi2SetInteger: the monitor has no settable Integer variable") : fmi2OK;
}
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean value[]) {
    (void)vr; (void)value; return n ? refuse(c, "fmi2SetBoolean: the monitor has no Boolean variable") : fmi2OK;
}
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String value[]) {
    (void)vr; (void)value; return n ? refuse(c, "fmi2SetString: the monitor has no settable String variable") : fmi2OK;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSetPrior) {
    Monitor *m = c;
    (void)noSetPrior;
    if (!(h > 0) || !isfinite(h)) return refuse(m, "fmi2DoStep: the step must be finite and > 0 s");
    double magnitude = fabs(m->torque);
    if (magnitude > m->peak) m->peak = magnitude;
    m->level = m->peak >= m->limit ? LEVEL_HIGH : LEVEL_NORMAL;
    m->time = t + h;
    return fmi2OK;
}

/* FMU states: a copy of the numbers (masters roll back to them). */
typedef struct { double limit, torque, peak, time; int level; } State;

static void save(const Monitor *m, State *s) {
    s->limit = m->limit; s->torque = m->torque; s->peak = m->peak; s->time = m->time; s->level = m->level;
}
static void load(Monitor *m, const State *s) {
    m->limit = s->limit; m->torque = s->torque; m->peak = s->peak; m->time = s->time; m->level = s->level;
}
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s) {
    State *state = *s ? (State *)*s : malloc(sizeof *state);
    if (!state) return refuse(c, "fmi2GetFMUstate: out of memory");
    save(c, state);
    *s = state;
    return fmi2OK;
}
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) {
    if (!s) return refuse(c, "fmi2SetFMUstate: no state");
    load(c, s);
    return fmi2OK;
}
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s) {
    (void)c; free(*s); *s = NULL; return fmi2OK;
}
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *n) {
    (void)c; (void)s; *n = sizeof(State); return fmi2OK;
}
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n) {
    if (n < sizeof(State)) return refuse(c, "fmi2SerializeFMUstate: buffer too small");
    memcpy(b, s, sizeof(State));
    return fmi2OK;
}
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate *s) {
    if (n != sizeof(State)) return refuse(c, "fmi2DeSerializeFMUstate: not a TorqueMonitor state");
    State *state = malloc(sizeof *state);
    if (!state) return refuse(c, "fmi2DeSerializeFMUstate: out of memory");
    memcpy(state, b, sizeof *state);
    *s = state;
    return fmi2OK;
}

/* What the monitor does not offer: its capability flags say so; these answer an error. */
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                        const fmi2ValueReference z[], size_t nz, const fmi2Real du[], fmi2Real dz[]) {
    (void)u; (void)nu; (void)z; (void)nz; (void)du; (void)dz; return refuse(c, "no directional derivatives");
}
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    (void)vr; (void)n; (void)order; (void)value; return refuse(c, "no input derivatives");
}
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                        const fmi2Integer order[], fmi2Real value[]) {
    (void)vr; (void)n; (void)order; (void)value; return refuse(c, "no output derivatives");
}
fmi2Status fmi2CancelStep(fmi2Component c) { (void)c; return fmi2Error; }
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind k, fmi2Status *v) {
    (void)k; (void)v; return refuse(c, "fmi2GetStatus: steps are never asynchronous");
}
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind k, fmi2Real *v) {
    if (k == fmi2LastSuccessfulTime) { *v = ((Monitor *)c)->time; return fmi2OK; }
    return refuse(c, "fmi2GetRealStatus: only fmi2LastSuccessfulTime");
}
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind k, fmi2Integer *v) {
    (void)k; (void)v; return refuse(c, "fmi2GetIntegerStatus: none");
}
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind k, fmi2Boolean *v) {
    (void)k; (void)v; return refuse(c, "fmi2GetBooleanStatus: none");
}
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind k, fmi2String *v) {
    (void)k; (void)v; return refuse(c, "fmi2GetStringStatus: none");
}
