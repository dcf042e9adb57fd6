/*
 * lever_fmi3_shim.c -- the native entry of our FMI 3.0 FMUs (Co-Simulation and Model
 * Exchange in one file).
 *
 * It is a translation layer on the FMU's FMI 2.0 entry (lever_fmi2_shim.c, shipped next to
 * this file as "lever-fmi2-entry.so", which loads pythonfmu's library in turn): every guest
 * rule that entry keeps -- it finds a Python itself, checks the resources and the GUID (the
 * FMI 3 instantiation token), keeps one Python thread state per host thread, turns what
 * the Python model logs into the call's status, validates serialized states, refuses its
 * private channel references -- holds here too because every call goes through it.  What
 * this file adds is FMI 3.0's:
 *
 *   - the FMI 3.0 state machine (Instantiated, Initialization Mode, Event Mode,
 *     Continuous-Time Mode, Step Mode, Terminated; Configuration Mode is refused: the
 *     models have no structural parameters), checked before anything is forwarded, with
 *     FMI 3 names in every message (the inner layer's messages are translated);
 *   - the independent variable `time` and the event-indicator variables the FMI 3 model
 *     description declares, answered here (the indicators in either interface through the
 *     FMI 2 entry's leverGetEventIndicatorValues, which is not an FMI 2.0 function);
 *   - fmi3GetNumberOfVariableDependencies / fmi3GetVariableDependencies from the
 *     ModelStructure the build wrote into resources/lever_fmi3.cfg;
 *   - fmi3GetAdjointDerivative: the transpose product of the same partials that
 *     fmi3GetDirectionalDerivative multiplies (one directional derivative per known);
 *   - fmi3DoStep's out-arguments (eventHandlingNeeded, terminateSimulation, earlyReturn
 *     always false: events are handled inside the step; lastSuccessfulTime);
 *   - FMU states that carry the FMI 3 state with them (checked against the inner state's
 *     header on deserialization).
 *
 * Not offered: Scheduled Execution and clocks (the models have none), Float32/Int8.../
 * Binary variables (the models have none: such calls with values are refused),
 * fmi3EvaluateDiscreteStates, early return and intermediate update.
 *
 * Build (build/shim/compile.py): the same flags as the FMI 2 entry.
 */
#define _GNU_SOURCE /* dladdr */

#include <dlfcn.h>
#include <errno.h>
#include <limits.h>
#include <math.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ------------------------------------------------------------------------- */
/* FMI 3.0 declarations (standard ABI of fmi3PlatformTypes.h, fmi3FunctionTypes.h) */
/* ------------------------------------------------------------------------- */

typedef void *fmi3Instance;
typedef void *fmi3InstanceEnvironment;
typedef void *fmi3FMUState;
typedef uint32_t fmi3ValueReference;
typedef float fmi3Float32;
typedef double fmi3Float64;
typedef int8_t fmi3Int8;
typedef uint8_t fmi3UInt8;
typedef int16_t fmi3Int16;
typedef uint16_t fmi3UInt16;
typedef int32_t fmi3Int32;
typedef uint32_t fmi3UInt32;
typedef int64_t fmi3Int64;
typedef uint64_t fmi3UInt64;
typedef bool fmi3Boolean;
typedef char fmi3Char;
typedef const fmi3Char *fmi3String;
typedef uint8_t fmi3Byte;
typedef const fmi3Byte *fmi3Binary;
typedef bool fmi3Clock;

typedef enum { fmi3OK, fmi3Warning, fmi3Discard, fmi3Error, fmi3Fatal } fmi3Status;
typedef enum {
    fmi3Independent,
    fmi3Constant,
    fmi3Fixed,
    fmi3Tunable,
    fmi3Discrete,
    fmi3Dependent
} fmi3DependencyKind;
typedef enum { fmi3IntervalNotYetKnown, fmi3IntervalUnchanged, fmi3IntervalChanged } fmi3IntervalQualifier;

typedef void (*fmi3LogMessageCallback)(fmi3InstanceEnvironment, fmi3Status, fmi3String category,
                                       fmi3String message);
typedef void (*fmi3ClockUpdateCallback)(fmi3InstanceEnvironment);
typedef void (*fmi3IntermediateUpdateCallback)(fmi3InstanceEnvironment, fmi3Float64, fmi3Boolean, fmi3Boolean,
                                               fmi3Boolean, fmi3Boolean, fmi3Boolean *, fmi3Float64 *);
typedef void (*fmi3LockPreemptionCallback)(void);
typedef void (*fmi3UnlockPreemptionCallback)(void);

/* ------------------------------------------------------------------------- */
/* The FMI 2.0 entry underneath (lever_fmi2_abi.h: the FMI 2.0 ABI)            */
/* ------------------------------------------------------------------------- */

#include "lever_fmi2_abi.h"

/* What this layer calls of the FMI 2.0 entry (the function types fmi2XxxTYPE). */
#define INNER_FUNCTIONS(X)                                                                         \
    X(fmi2Instantiate)                                                                             \
    X(fmi2FreeInstance)                                                                            \
    X(fmi2SetDebugLogging)                                                                         \
    LEVER_FMI2_SETUP_VALUES_AND_STATES(X)                                                          \
    X(fmi2GetDirectionalDerivative)                                                                \
    X(fmi2GetRealOutputDerivatives)                                                                \
    X(fmi2DoStep)                                                                                  \
    X(fmi2GetRealStatus)                                                                           \
    LEVER_FMI2_ME_FUNCTIONS(X)                                                                     \
    X(leverGetEventIndicatorValues)

typedef struct {
#define INNER_MEMBER(name) name##TYPE *name;
    INNER_FUNCTIONS(INNER_MEMBER)
#undef INNER_MEMBER
} Inner;

#define INNER_LIBRARY_NAME "lever-fmi2-entry.so"
#define CONFIG_NAME "lever_fmi3.cfg" /* in resources/, written by build/fmi3.py */
#define CATEGORY "logStatusError"

#define EXPORT __attribute__((visibility("default")))

/* ------------------------------------------------------------------------- */
/* Loading the FMI 2.0 entry                                                  */
/* ------------------------------------------------------------------------- */

static Inner *g_inner;
static pthread_mutex_t g_inner_lock = PTHREAD_MUTEX_INITIALIZER;

EXPORT const char *fmi3GetVersion(void);

/* The FMI 2.0 entry next to this library, loaded once and never unloaded (its instances
 * and the Python interpreter live as long as the process).  NULL and a message in err. */
static Inner *inner_library(char *err, size_t errsize)
{
    Inner *api = __atomic_load_n(&g_inner, __ATOMIC_ACQUIRE);
    if (api) {
        return api;
    }
    pthread_mutex_lock(&g_inner_lock);
    if (g_inner) {
        pthread_mutex_unlock(&g_inner_lock);
        return g_inner;
    }
    Dl_info info;
    char path[PATH_MAX];
    if (!dladdr((void *)&fmi3GetVersion, &info) || !info.dli_fname) {
        snprintf(err, errsize, "cannot determine the directory of the FMU binary");
        pthread_mutex_unlock(&g_inner_lock);
        return NULL;
    }
    const char *slash = strrchr(info.dli_fname, '/');
    int dir = slash ? (int)(slash - info.dli_fname) + 1 : 0;
    snprintf(path, sizeof path, "%.*s%s", dir, info.dli_fname, INNER_LIBRARY_NAME);
    void *handle = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!handle) {
        const char *why = dlerror();
        snprintf(err, errsize, "cannot load %.900s: %.100s", path, why ? why : "unknown error");
        pthread_mutex_unlock(&g_inner_lock);
        return NULL;
    }
    api = calloc(1, sizeof *api);
    if (!api) {
        snprintf(err, errsize, "out of memory");
        pthread_mutex_unlock(&g_inner_lock);
        return NULL;
    }
#define INNER_RESOLVE(name)                                                                        \
    api->name = (name##TYPE *)lever_function(handle, path, #name, err, errsize);                   \
    if (!api->name) {                                                                              \
        free(api);                                                                                 \
        pthread_mutex_unlock(&g_inner_lock);                                                       \
        return NULL;                                                                               \
    }
    INNER_FUNCTIONS(INNER_RESOLVE)
#undef INNER_RESOLVE
    __atomic_store_n(&g_inner, api, __ATOMIC_RELEASE);
    pthread_mutex_unlock(&g_inner_lock);
    return api;
}

/* ------------------------------------------------------------------------- */
/* resources/lever_fmi3.cfg: what the FMI 3 model description declares that    */
/* the FMI 2 entry does not know                                               */
/* ------------------------------------------------------------------------- */

typedef struct {
    fmi3ValueReference vr;
    int initial;      /* 1: an InitialUnknown's dependencies, 0: an Output's or derivative's */
    size_t n;
    fmi3ValueReference *on;
} Dependency;

typedef struct {
    fmi3ValueReference timeVr;          /* the independent variable */
    size_t nx, nz;                      /* continuous states, event indicators */
    fmi3ValueReference indicatorVr;     /* the first event indicator's; the others follow */
    Dependency *deps;
    size_t nDeps;
} Config;

static void free_config(Config *cfg)
{
    for (size_t i = 0; i < cfg->nDeps; i++) {
        free(cfg->deps[i].on);
    }
    free(cfg->deps);
    memset(cfg, 0, sizeof *cfg);
}

/* A line "run=<vr> <vr>..." or "init=<vr> <vr>...": the first is the unknown. */
static int config_dependency(Config *cfg, const char *text, int initial)
{
    fmi3ValueReference values[4096];
    size_t n = 0;
    const char *p = text;
    char *end;
    while (n < sizeof values / sizeof values[0]) {
        errno = 0;
        unsigned long v = strtoul(p, &end, 10);
        if (end == p) {
            break;
        }
        if (errno || v > UINT32_MAX) {
            return -1;
        }
        values[n++] = (fmi3ValueReference)v;
        p = end;
    }
    if (n == 0) {
        return -1;
    }
    Dependency *grown = realloc(cfg->deps, (cfg->nDeps + 1) * sizeof *grown);
    if (!grown) {
        return -1;
    }
    cfg->deps = grown;
    Dependency *d = &cfg->deps[cfg->nDeps];
    d->vr = values[0];
    d->initial = initial;
    d->n = n - 1;
    d->on = malloc((n > 1 ? n - 1 : 1) * sizeof *d->on);
    if (!d->on) {
        return -1;
    }
    memcpy(d->on, values + 1, (n - 1) * sizeof *d->on);
    cfg->nDeps++;
    return 0;
}

/* Reads the configuration of the FMU whose resources are at `resources`.  0 on success. */
static int read_config(const char *resources, Config *cfg, char *err, size_t errsize)
{
    char path[PATH_MAX + 32];
    size_t len = strlen(resources);
    snprintf(path, sizeof path, "%s%s%s", resources, len && resources[len - 1] == '/' ? "" : "/", CONFIG_NAME);
    memset(cfg, 0, sizeof *cfg);
    FILE *f = fopen(path, "r");
    if (!f) {
        snprintf(err, errsize, "cannot read %.800s (%.60s): is resourcePath this FMU's resources directory?", path,
                 strerror(errno));
        return -1;
    }
    char *line = NULL;
    size_t cap = 0;
    int ok = 1, have_time = 0;
    while (ok && getline(&line, &cap, f) > 0) {
        unsigned long a = 0, b = 0;
        if (line[0] == '#' || line[0] == '\n') {
            continue;
        } else if (sscanf(line, "time=%lu", &a) == 1) {
            cfg->timeVr = (fmi3ValueReference)a;
            have_time = 1;
        } else if (sscanf(line, "states=%lu", &a) == 1) {
            cfg->nx = a;
        } else if (sscanf(line, "event_indicators=%lu %lu", &a, &b) == 2) {
            cfg->nz = a;
            cfg->indicatorVr = (fmi3ValueReference)b;
        } else if (strncmp(line, "run=", 4) == 0) {
            ok = config_dependency(cfg, line + 4, 0) == 0;
        } else if (strncmp(line, "init=", 5) == 0) {
            ok = config_dependency(cfg, line + 5, 1) == 0;
        }
    }
    free(line);
    fclose(f);
    if (!ok || !have_time) {
        snprintf(err, errsize, "%.900s is malformed%s", path, have_time ? "" : " (no time=)");
        free_config(cfg);
        return -1;
    }
    return 0;
}

/* ------------------------------------------------------------------------- */
/* Instances                                                                  */
/* ------------------------------------------------------------------------- */

/* The FMI 3.0 states (bits, so that each function's allowed states are one mask). */
enum {
    S_INSTANTIATED = 1,
    S_INITIALIZATION = 2,
    S_EVENT = 4,
    S_CONTINUOUS = 8,
    S_STEP = 16,
    S_TERMINATED = 32,
};
#define S_ANY (S_INSTANTIATED | S_INITIALIZATION | S_EVENT | S_CONTINUOUS | S_STEP | S_TERMINATED)
#define S_RUNNING (S_EVENT | S_CONTINUOUS | S_STEP)

static const char *state_name(int state)
{
    switch (state) {
    case S_INSTANTIATED: return "Instantiated";
    case S_INITIALIZATION: return "Initialization Mode";
    case S_EVENT: return "Event Mode";
    case S_CONTINUOUS: return "Continuous-Time Mode";
    case S_STEP: return "Step Mode";
    case S_TERMINATED: return "Terminated";
    default: return "?";
    }
}

typedef struct {
    fmi2Component inner;
    Inner *api;
    int me;                 /* instantiated for Model Exchange */
    int state;
    int discarded;          /* Co-Simulation: the last step returned fmi3Discard */
    int eventModeUsed;
    double time;
    char *instanceName;
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback logMessage;
    Config cfg;
} Instance;

#define INST(i) ((Instance *)(i))

/* fmi2 names in the inner layer's messages, as this interface calls them. */
static const char *const RENAMED[][2] = {
    {"fmi2GetRealOutputDerivatives", "fmi3GetOutputDerivatives"},
    {"fmi2GetNominalsOfContinuousStates", "fmi3GetNominalsOfContinuousStates"},
    {"fmi2GetDirectionalDerivative", "fmi3GetDirectionalDerivative"},
    {"fmi2EnterInitializationMode", "fmi3EnterInitializationMode"},
    {"fmi2ExitInitializationMode", "fmi3ExitInitializationMode"},
    {"fmi2EnterContinuousTimeMode", "fmi3EnterContinuousTimeMode"},
    {"fmi2CompletedIntegratorStep", "fmi3CompletedIntegratorStep"},
    {"fmi2SerializedFMUstateSize", "fmi3SerializedFMUStateSize"},
    {"fmi2DeSerializeFMUstate", "fmi3DeserializeFMUState"},
    {"fmi2SetContinuousStates", "fmi3SetContinuousStates"},
    {"fmi2GetContinuousStates", "fmi3GetContinuousStates"},
    {"fmi2GetEventIndicators", "fmi3GetEventIndicators"},
    {"fmi2SerializeFMUstate", "fmi3SerializeFMUState"},
    {"fmi2NewDiscreteStates", "fmi3UpdateDiscreteStates"},
    {"fmi2SetupExperiment", "fmi3EnterInitializationMode"},
    {"fmi2GetDerivatives", "fmi3GetContinuousStateDerivatives"},
    {"fmi2EnterEventMode", "fmi3EnterEventMode"},
    {"fmi2FreeFMUstate", "fmi3FreeFMUState"},
    {"fmi2GetFMUstate", "fmi3GetFMUState"},
    {"fmi2SetFMUstate", "fmi3SetFMUState"},
    {"fmi2Instantiate", "fmi3Instantiate"},
    {"fmi2GetInteger", "fmi3GetInt32"},
    {"fmi2SetInteger", "fmi3SetInt32"},
    {"fmi2GetBoolean", "fmi3GetBoolean"},
    {"fmi2SetBoolean", "fmi3SetBoolean"},
    {"fmi2Terminate", "fmi3Terminate"},
    {"fmi2GetString", "fmi3GetString"},
    {"fmi2SetString", "fmi3SetString"},
    {"fmi2SetTime", "fmi3SetTime"},
    {"fmi2GetReal", "fmi3GetFloat64"},
    {"fmi2SetReal", "fmi3SetFloat64"},
    {"fmi2DoStep", "fmi3DoStep"},
    {"fmi2Reset", "fmi3Reset"},
    {"fmi2Error", "fmi3Error"},
};

/* A copy of text with the inner layer's function names renamed (malloc'ed, or NULL). */
static char *renamed(const char *text)
{
    size_t n = strlen(text), cap = n + 64, k = 0;
    char *out = malloc(cap);
    if (!out) {
        return NULL;
    }
    for (size_t i = 0; i < n;) {
        const char *to = NULL;
        size_t from = 0;
        if (text[i] == 'f' && strncmp(text + i, "fmi2", 4) == 0) {
            for (size_t r = 0; r < sizeof RENAMED / sizeof RENAMED[0]; r++) {
                size_t m = strlen(RENAMED[r][0]);
                if (m > from && strncmp(text + i, RENAMED[r][0], m) == 0) {
                    to = RENAMED[r][1];
                    from = m;
                }
            }
        }
        const char *piece = to ? to : text + i;
        size_t m = to ? strlen(to) : 1;
        if (k + m + 1 > cap) {
            cap = 2 * cap + m;
            char *grown = realloc(out, cap);
            if (!grown) {
                free(out);
                return NULL;
            }
            out = grown;
        }
        memcpy(out + k, piece, m);
        k += m;
        i += to ? from : 1;
    }
    out[k] = '\0';
    return out;
}

static void deliver(Instance *s, fmi3Status status, const char *category, const char *message)
{
    if (!s->logMessage) {
        return;
    }
    char *text = renamed(message);
    s->logMessage(s->env, status, category ? category : "", text ? text : message);
    free(text);
}

/* The logger the FMI 2 entry calls (it filters by the importer's logging settings,
 * which fmi3SetDebugLogging hands on to it, and passes the message as a "%s" argument). */
static void relay(void *env, fmi2String instanceName, fmi2Status status, fmi2String category,
                  fmi2String format, ...)
{
    (void)instanceName;
    Instance *s = env;
    if (!s || !format) {
        return;
    }
    va_list args, again;
    va_start(args, format);
    va_copy(again, args);
    int n = vsnprintf(NULL, 0, format, args);
    va_end(args);
    char *message = n >= 0 ? malloc((size_t)n + 1) : NULL;
    if (message) {
        vsnprintf(message, (size_t)n + 1, format, again);
    }
    va_end(again);
    fmi3Status mapped = (unsigned)status <= (unsigned)fmi2Fatal ? (fmi3Status)status : fmi3Error;
    deliver(s, mapped, category, message ? message : format);
    free(message);
}

/* Messages of this layer; returns fmi3Error. */
static fmi3Status fail(Instance *s, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static fmi3Status fail(Instance *s, const char *fmt, ...)
{
    char buffer[2048];
    va_list args;
    va_start(args, fmt);
    vsnprintf(buffer, sizeof buffer, fmt, args);
    va_end(args);
    if (s && s->logMessage) {
        s->logMessage(s->env, fmi3Error, CATEGORY, buffer);
    }
    return fmi3Error;
}

/* Prologue: 1 if the call may proceed in the instance's state. */
static int begin(Instance *s, const char *function, int allowed, int me_allowed)
{
    if (!s) {
        return 0;
    }
    int mask = s->me ? me_allowed : allowed;
    if (mask == 0) {
        fail(s, "%s is not offered to this instance: it was instantiated for %s%s", function,
             s->me ? "Model Exchange" : "Co-Simulation",
             s->me ? " (FMU states and output derivatives are Co-Simulation's)" : " (this is a Model Exchange function)");
        return 0;
    }
    if (!(s->state & mask)) {
        char where[256] = "";
        size_t k = 0;
        for (int bit = S_INSTANTIATED; bit <= S_TERMINATED; bit <<= 1) {
            if (mask & bit) {
                k += (size_t)snprintf(where + k, k < sizeof where ? sizeof where - k : 0, "%s'%s'", k ? ", " : "",
                                      state_name(bit));
            }
        }
        fail(s, "%s is not allowed in %s; it is allowed in %s (FMI 3.0 %s state machine)", function,
             state_name(s->state), where, s->me ? "Model Exchange" : "Co-Simulation");
        return 0;
    }
    return 1;
}

#define BEGIN(name, instance, cs_mask, me_mask)                                                    \
    Instance *s = INST(instance);                                                                  \
    if (!begin(s, #name, (cs_mask), (me_mask))) return fmi3Error

static fmi3Status status3(fmi2Status status)
{
    return (unsigned)status <= (unsigned)fmi2Fatal ? (fmi3Status)status : fmi3Error;
}

static int succeeded(fmi3Status status) { return status == fmi3OK || status == fmi3Warning; }

/* 0 (and an error logged) unless n values were given for n value references. */
static int scalar_counts(Instance *s, const char *function, const void *vr, size_t nvr, const void *values,
                         size_t nValues)
{
    if (nValues != nvr) {
        fail(s, "%s: %zu values for %zu value references; every variable of this FMU is a scalar, "
                "nothing was done", function, nValues, nvr);
        return 0;
    }
    if (nvr > 0 && (!vr || !values)) {
        fail(s, "%s: the %s array is NULL", function, vr ? "values" : "value reference");
        return 0;
    }
    return 1;
}

static int is_indicator(const Instance *s, fmi3ValueReference vr)
{
    return s->cfg.nz && vr >= s->cfg.indicatorVr && vr - s->cfg.indicatorVr < s->cfg.nz;
}

/* A variable this layer declares (time, an event indicator) rather than the model. */
static int is_own(const Instance *s, fmi3ValueReference vr) { return vr == s->cfg.timeVr || is_indicator(s, vr); }

/* ------------------------------------------------------------------------- */
/* Instantiation                                                              */
/* ------------------------------------------------------------------------- */

EXPORT const char *fmi3GetVersion(void) { return "3.0"; }

/* resourcePath (a directory, FMI 3.0) as the file URI the FMI 2 entry takes. */
static char *file_uri(const char *path)
{
    size_t n = strlen(path);
    char *uri = malloc(3 * n + 16);
    if (!uri) {
        return NULL;
    }
    size_t k = (size_t)sprintf(uri, "file://");
    for (size_t i = 0; i < n; i++) {
        unsigned char c = (unsigned char)path[i];
        if ((c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || strchr("/-._~", c)) {
            uri[k++] = (char)c;
        } else {
            k += (size_t)sprintf(uri + k, "%%%02X", c);
        }
    }
    uri[k] = '\0';
    return uri;
}

static Instance *instantiate(fmi3String instanceName, fmi3String token, fmi3String resourcePath, fmi3Boolean visible,
                             fmi3Boolean loggingOn, fmi3InstanceEnvironment env, fmi3LogMessageCallback logMessage,
                             int me)
{
    Instance *s = calloc(1, sizeof *s);
    if (!s) {
        return NULL;
    }
    s->env = env;
    s->logMessage = logMessage;
    s->me = me;
    s->state = S_INSTANTIATED;
    s->instanceName = strdup(instanceName ? instanceName : "");
    const char *function = me ? "fmi3InstantiateModelExchange" : "fmi3InstantiateCoSimulation";
    char err[1200];
    if (!s->instanceName) {
        free(s);
        return NULL;
    }
    if (!token || !resourcePath) {
        fail(s, "%s: %s is NULL (this FMU needs its resources)", function, token ? "resourcePath" : "instantiationToken");
    } else if (read_config(resourcePath, &s->cfg, err, sizeof err) != 0) {
        fail(s, "%s: %s", function, err);
    } else if (!(s->api = inner_library(err, sizeof err))) {
        fail(s, "%s: %s", function, err);
    } else {
        char *uri = file_uri(resourcePath);
        if (!uri) {
            fail(s, "%s: out of memory", function);
        } else {
            fmi2CallbackFunctions callbacks = {relay, NULL, NULL, NULL, s};
            /* The FMI 2 entry checks the token (its GUID), finds Python, and logs why not. */
            s->inner = s->api->fmi2Instantiate(s->instanceName, me ? fmi2ModelExchange : fmi2CoSimulation, token,
                                               uri, &callbacks, visible, loggingOn);
            free(uri);
        }
    }
    if (!s->inner) {
        free_config(&s->cfg);
        free(s->instanceName);
        free(s);
        return NULL;
    }
    return s;
}

EXPORT fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                                 fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                                 fmi3InstanceEnvironment instanceEnvironment,
                                                 fmi3LogMessageCallback logMessage)
{
    return instantiate(instanceName, instantiationToken, resourcePath, visible, loggingOn, instanceEnvironment,
                       logMessage, 1);
}

EXPORT fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                                fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                                fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                                const fmi3ValueReference requiredIntermediateVariables[],
                                                size_t nRequiredIntermediateVariables,
                                                fmi3InstanceEnvironment instanceEnvironment,
                                                fmi3LogMessageCallback logMessage,
                                                fmi3IntermediateUpdateCallback intermediateUpdate)
{
    /* Steps never return early and there is no intermediate update: both are only offers. */
    (void)earlyReturnAllowed;
    (void)requiredIntermediateVariables;
    (void)intermediateUpdate;
    if (nRequiredIntermediateVariables > 0) {
        if (logMessage) {
            logMessage(instanceEnvironment, fmi3Error, CATEGORY,
                       "fmi3InstantiateCoSimulation: this FMU offers no intermediate update "
                       "(providesIntermediateUpdate=\"false\"): no variable can be required for it");
        }
        return NULL;
    }
    Instance *s = instantiate(instanceName, instantiationToken, resourcePath, visible, loggingOn,
                              instanceEnvironment, logMessage, 0);
    if (s) {
        s->eventModeUsed = eventModeUsed;
    }
    return s;
}

EXPORT fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                                      fmi3String resourcePath, fmi3Boolean visible,
                                                      fmi3Boolean loggingOn,
                                                      fmi3InstanceEnvironment instanceEnvironment,
                                                      fmi3LogMessageCallback logMessage,
                                                      fmi3ClockUpdateCallback clockUpdate,
                                                      fmi3LockPreemptionCallback lockPreemption,
                                                      fmi3UnlockPreemptionCallback unlockPreemption)
{
    (void)instanceName, (void)instantiationToken, (void)resourcePath, (void)visible, (void)loggingOn;
    (void)clockUpdate, (void)lockPreemption, (void)unlockPreemption;
    if (logMessage) {
        logMessage(instanceEnvironment, fmi3Error, CATEGORY,
                   "fmi3InstantiateScheduledExecution: this FMU offers Co-Simulation and Model Exchange only "
                   "(its model description has no ScheduledExecution element)");
    }
    return NULL;
}

EXPORT void fmi3FreeInstance(fmi3Instance instance)
{
    Instance *s = INST(instance);
    if (!s) {
        return;
    }
    s->api->fmi2FreeInstance(s->inner);
    free_config(&s->cfg);
    free(s->instanceName);
    free(s);
}

EXPORT fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                                      const fmi3String categories[])
{
    BEGIN(fmi3SetDebugLogging, instance, S_ANY, S_ANY);
    return status3(s->api->fmi2SetDebugLogging(s->inner, loggingOn, nCategories, categories));
}

/* ------------------------------------------------------------------------- */
/* Modes                                                                      */
/* ------------------------------------------------------------------------- */

EXPORT fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance)
{
    BEGIN(fmi3EnterConfigurationMode, instance, S_INSTANTIATED | S_STEP | S_EVENT, S_INSTANTIATED | S_EVENT);
    return fail(s, "fmi3EnterConfigurationMode: this FMU has no structural parameters, so there is nothing to "
                   "configure; the instance stays in %s", state_name(s->state));
}

EXPORT fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance)
{
    BEGIN(fmi3ExitConfigurationMode, instance, 0, 0);
    return fmi3Error; /* never in Configuration Mode: begin() refused it */
}

EXPORT fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined,
                                              fmi3Float64 tolerance, fmi3Float64 startTime,
                                              fmi3Boolean stopTimeDefined, fmi3Float64 stopTime)
{
    BEGIN(fmi3EnterInitializationMode, instance, S_INSTANTIATED, S_INSTANTIATED);
    fmi3Status status = status3(s->api->fmi2SetupExperiment(s->inner, toleranceDefined, tolerance, startTime,
                                                            stopTimeDefined, stopTime));
    if (!succeeded(status)) {
        return status;
    }
    fmi3Status entered = status3(s->api->fmi2EnterInitializationMode(s->inner));
    if (succeeded(entered)) {
        s->state = S_INITIALIZATION;
        s->time = startTime;
    }
    return entered > status ? entered : status;
}

EXPORT fmi3Status fmi3ExitInitializationMode(fmi3Instance instance)
{
    BEGIN(fmi3ExitInitializationMode, instance, S_INITIALIZATION, S_INITIALIZATION);
    fmi3Status status = status3(s->api->fmi2ExitInitializationMode(s->inner));
    if (succeeded(status)) {
        s->state = (s->me || s->eventModeUsed) ? S_EVENT : S_STEP;
    }
    return status;
}

EXPORT fmi3Status fmi3EnterEventMode(fmi3Instance instance)
{
    BEGIN(fmi3EnterEventMode, instance, S_STEP, S_CONTINUOUS);
    if (!s->me && !s->eventModeUsed) {
        return fail(s, "fmi3EnterEventMode: this instance was instantiated with eventModeUsed = false "
                       "(the FMU handles its events inside fmi3DoStep)");
    }
    fmi3Status status = s->me ? status3(s->api->fmi2EnterEventMode(s->inner)) : fmi3OK;
    if (succeeded(status)) {
        s->state = S_EVENT;
    }
    return status;
}

EXPORT fmi3Status fmi3EnterStepMode(fmi3Instance instance)
{
    BEGIN(fmi3EnterStepMode, instance, S_EVENT, 0);
    s->state = S_STEP;
    return fmi3OK;
}

EXPORT fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance)
{
    BEGIN(fmi3EnterContinuousTimeMode, instance, 0, S_EVENT);
    fmi3Status status = status3(s->api->fmi2EnterContinuousTimeMode(s->inner));
    if (succeeded(status)) {
        s->state = S_CONTINUOUS;
    }
    return status;
}

EXPORT fmi3Status fmi3Terminate(fmi3Instance instance)
{
    BEGIN(fmi3Terminate, instance, S_STEP | S_EVENT, S_EVENT | S_CONTINUOUS);
    fmi3Status status = status3(s->api->fmi2Terminate(s->inner));
    if (succeeded(status)) {
        s->state = S_TERMINATED;
    }
    return status;
}

EXPORT fmi3Status fmi3Reset(fmi3Instance instance)
{
    BEGIN(fmi3Reset, instance, S_ANY, S_ANY);
    fmi3Status status = status3(s->api->fmi2Reset(s->inner));
    if (succeeded(status)) {
        s->state = S_INSTANTIATED;
        s->time = 0.0;
        s->discarded = 0;
    }
    return status;
}

/* ------------------------------------------------------------------------- */
/* Variables                                                                  */
/* ------------------------------------------------------------------------- */

#define GETTABLE S_ANY
#define SETTABLE (S_INSTANTIATED | S_INITIALIZATION | S_EVENT | S_CONTINUOUS | S_STEP)

/* Reads the variables this layer declares into value[] (the others are left alone).  An
 * event indicator is a local variable like any other to a Co-Simulation importer (FMI 3.0
 * ignores only the <EventIndicator> elements there): the physics' indicator at the current
 * state and inputs, with the modes the co-simulation edition is in.  It is calculated, so it
 * has no value before Initialization Mode (Instantiated offers start values only). */
static fmi3Status own_values(Instance *s, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 value[])
{
    fmi2Real *indicators = NULL;
    fmi3Status status = fmi3OK;
    for (size_t i = 0; i < nvr && succeeded(status); i++) {
        if (vr[i] == s->cfg.timeVr) {
            value[i] = s->time;
        } else if (is_indicator(s, vr[i])) {
            if (s->state == S_INSTANTIATED) {
                status = fail(s, "fmi3GetFloat64: value reference %u is an event indicator, calculated by the model: "
                                 "it has a value from fmi3EnterInitializationMode on, and no start value to give in "
                                 "Instantiated", vr[i]);
            } else {
                if (!indicators) {
                    indicators = malloc(s->cfg.nz * sizeof *indicators);
                    status = indicators
                                 ? status3(s->api->leverGetEventIndicatorValues(s->inner, indicators, s->cfg.nz))
                                 : fail(s, "fmi3GetFloat64: out of memory");
                }
                if (succeeded(status)) {
                    value[i] = indicators[vr[i] - s->cfg.indicatorVr];
                }
            }
        }
    }
    free(indicators);
    return status;
}

EXPORT fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                 fmi3Float64 value[], size_t nValues)
{
    BEGIN(fmi3GetFloat64, instance, GETTABLE, GETTABLE);
    if (!scalar_counts(s, "fmi3GetFloat64", vr, nvr, value, nValues)) return fmi3Error;
    size_t own = 0;
    for (size_t i = 0; i < nvr; i++) {
        own += (size_t)is_own(s, vr[i]);
    }
    if (own == 0) { /* the usual case: the model's variables only */
        return status3(s->api->fmi2GetReal(s->inner, vr, nvr, value));
    }
    /* Both kinds: the model's through the inner layer, into a scratch array first so that a
     * refusal leaves value[] as it was. */
    fmi3Float64 *scratch = malloc(nvr * sizeof *scratch);
    fmi2ValueReference *model = malloc((nvr - own + 1) * sizeof *model);
    fmi2Real *got = malloc((nvr - own + 1) * sizeof *got);
    fmi3Status status = fmi3OK;
    if (!scratch || !model || !got) {
        status = fail(s, "fmi3GetFloat64: out of memory");
    }
    size_t k = 0;
    for (size_t i = 0; succeeded(status) && i < nvr; i++) {
        if (!is_own(s, vr[i])) {
            model[k++] = vr[i];
        }
    }
    if (succeeded(status) && k > 0) {
        status = status3(s->api->fmi2GetReal(s->inner, model, k, got));
    }
    if (succeeded(status)) {
        fmi3Status mine = own_values(s, vr, nvr, scratch);
        status = mine > status ? mine : status;
    }
    if (succeeded(status)) {
        for (size_t i = 0, j = 0; i < nvr; i++) {
            value[i] = is_own(s, vr[i]) ? scratch[i] : got[j++];
        }
    }
    free(scratch);
    free(model);
    free(got);
    return status;
}

EXPORT fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                 const fmi3Float64 value[], size_t nValues)
{
    BEGIN(fmi3SetFloat64, instance, SETTABLE, SETTABLE);
    if (!scalar_counts(s, "fmi3SetFloat64", vr, nvr, value, nValues)) return fmi3Error;
    for (size_t i = 0; i < nvr; i++) {
        if (is_own(s, vr[i])) {
            return fail(s, "fmi3SetFloat64: value reference %u is %s, which cannot be set%s; nothing was set", vr[i],
                        vr[i] == s->cfg.timeVr ? "the independent variable time" : "an event indicator",
                        vr[i] == s->cfg.timeVr ? " (fmi3EnterInitializationMode, fmi3SetTime, fmi3DoStep move it)"
                                               : "");
        }
    }
    return status3(s->api->fmi2SetReal(s->inner, vr, nvr, value));
}

/* The types whose FMI 2.0 values are the same C type: passed through as they are. */
#define PASSED_THROUGH(type, ctype, type2)                                                         \
    EXPORT fmi3Status fmi3Get##type(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, \
                                    ctype value[], size_t nValues)                                 \
    {                                                                                              \
        BEGIN(fmi3Get##type, instance, GETTABLE, GETTABLE);                                        \
        if (!scalar_counts(s, "fmi3Get" #type, vr, nvr, value, nValues)) return fmi3Error;         \
        return status3(s->api->fmi2Get##type2(s->inner, vr, nvr, value));                          \
    }                                                                                              \
    EXPORT fmi3Status fmi3Set##type(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, \
                                    const ctype value[], size_t nValues)                           \
    {                                                                                              \
        BEGIN(fmi3Set##type, instance, SETTABLE, SETTABLE);                                        \
        if (!scalar_counts(s, "fmi3Set" #type, vr, nvr, value, nValues)) return fmi3Error;         \
        return status3(s->api->fmi2Set##type2(s->inner, vr, nvr, value));                          \
    }

PASSED_THROUGH(Int32, fmi3Int32, Integer)
PASSED_THROUGH(String, fmi3String, String)

EXPORT fmi3Status fmi3GetBoolean(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                 fmi3Boolean value[], size_t nValues)
{
    BEGIN(fmi3GetBoolean, instance, GETTABLE, GETTABLE);
    if (!scalar_counts(s, "fmi3GetBoolean", vr, nvr, value, nValues)) return fmi3Error;
    fmi2Boolean *wide = malloc((nvr ? nvr : 1) * sizeof *wide);
    if (!wide) return fail(s, "fmi3GetBoolean: out of memory");
    fmi3Status status = status3(s->api->fmi2GetBoolean(s->inner, vr, nvr, wide));
    for (size_t i = 0; succeeded(status) && i < nvr; i++) {
        value[i] = wide[i] != 0;
    }
    free(wide);
    return status;
}

EXPORT fmi3Status fmi3SetBoolean(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                 const fmi3Boolean value[], size_t nValues)
{
    BEGIN(fmi3SetBoolean, instance, SETTABLE, SETTABLE);
    if (!scalar_counts(s, "fmi3SetBoolean", vr, nvr, value, nValues)) return fmi3Error;
    fmi2Boolean *wide = malloc((nvr ? nvr : 1) * sizeof *wide);
    if (!wide) return fail(s, "fmi3SetBoolean: out of memory");
    for (size_t i = 0; i < nvr; i++) {
        wide[i] = value[i] ? 1 : 0;
    }
    fmi3Status status = status3(s->api->fmi2SetBoolean(s->inner, vr, nvr, wide));
    free(wide);
    return status;
}

/* The types no variable of these FMUs has: nothing to get or set. */
static fmi3Status no_such_type(Instance *s, const char *function, const char *type, const fmi3ValueReference vr[],
                               size_t nvr)
{
    if (nvr == 0) {
        return fmi3OK;
    }
    return fail(s, "%s: value reference %u is no %s variable: this FMU's variables are Float64, Int32, Boolean "
                   "and String", function, vr ? vr[0] : 0u, type);
}

#define NO_SUCH_TYPE(type, ctype, mask)                                                            \
    EXPORT fmi3Status fmi3Get##type(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, \
                                    ctype value[], size_t nValues)                                 \
    {                                                                                              \
        BEGIN(fmi3Get##type, instance, GETTABLE, GETTABLE);                                        \
        (void)value, (void)nValues;                                                                \
        return no_such_type(s, "fmi3Get" #type, #type, vr, nvr);                                   \
    }                                                                                              \
    EXPORT fmi3Status fmi3Set##type(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, \
                                    const ctype value[], size_t nValues)                           \
    {                                                                                              \
        BEGIN(fmi3Set##type, instance, mask, mask);                                                \
        (void)value, (void)nValues;                                                                \
        return no_such_type(s, "fmi3Set" #type, #type, vr, nvr);                                   \
    }

NO_SUCH_TYPE(Float32, fmi3Float32, SETTABLE)
NO_SUCH_TYPE(Int8, fmi3Int8, SETTABLE)
NO_SUCH_TYPE(UInt8, fmi3UInt8, SETTABLE)
NO_SUCH_TYPE(Int16, fmi3Int16, SETTABLE)
NO_SUCH_TYPE(UInt16, fmi3UInt16, SETTABLE)
NO_SUCH_TYPE(UInt32, fmi3UInt32, SETTABLE)
NO_SUCH_TYPE(Int64, fmi3Int64, SETTABLE)
NO_SUCH_TYPE(UInt64, fmi3UInt64, SETTABLE)

EXPORT fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                size_t valueSizes[], fmi3Binary value[], size_t nValues)
{
    BEGIN(fmi3GetBinary, instance, GETTABLE, GETTABLE);
    (void)valueSizes, (void)value, (void)nValues;
    return no_such_type(s, "fmi3GetBinary", "Binary", vr, nvr);
}

EXPORT fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                const size_t valueSizes[], const fmi3Binary value[], size_t nValues)
{
    BEGIN(fmi3SetBinary, instance, SETTABLE, SETTABLE);
    (void)valueSizes, (void)value, (void)nValues;
    return no_such_type(s, "fmi3SetBinary", "Binary", vr, nvr);
}

/* ------------------------------------------------------------------------- */
/* Clocks: none                                                               */
/* ------------------------------------------------------------------------- */

static fmi3Status no_clocks(Instance *s, const char *function, size_t nvr)
{
    if (nvr == 0) {
        return fmi3OK;
    }
    return fail(s, "%s: this FMU has no clocks", function);
}

#define CLOCK_FUNCTION(name, ...)                                                                  \
    EXPORT fmi3Status name(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, __VA_ARGS__) \
    {                                                                                              \
        BEGIN(name, instance, S_ANY, S_ANY);                                                       \
        (void)vr;                                                                                  \
        return no_clocks(s, #name, nvr);                                                           \
    }

CLOCK_FUNCTION(fmi3GetClock, __attribute__((unused)) fmi3Clock values[])
CLOCK_FUNCTION(fmi3SetClock, __attribute__((unused)) const fmi3Clock values[])
CLOCK_FUNCTION(fmi3GetIntervalDecimal, __attribute__((unused)) fmi3Float64 intervals[], __attribute__((unused)) fmi3IntervalQualifier qualifiers[])
CLOCK_FUNCTION(fmi3GetIntervalFraction, __attribute__((unused)) fmi3UInt64 counters[], __attribute__((unused)) fmi3UInt64 resolutions[], __attribute__((unused)) fmi3IntervalQualifier qualifiers[])
CLOCK_FUNCTION(fmi3GetShiftDecimal, __attribute__((unused)) fmi3Float64 shifts[])
CLOCK_FUNCTION(fmi3GetShiftFraction, __attribute__((unused)) fmi3UInt64 counters[], __attribute__((unused)) fmi3UInt64 resolutions[])
CLOCK_FUNCTION(fmi3SetIntervalDecimal, __attribute__((unused)) const fmi3Float64 intervals[])
CLOCK_FUNCTION(fmi3SetIntervalFraction, __attribute__((unused)) const fmi3UInt64 counters[], __attribute__((unused)) const fmi3UInt64 resolutions[])
CLOCK_FUNCTION(fmi3SetShiftDecimal, __attribute__((unused)) const fmi3Float64 shifts[])
CLOCK_FUNCTION(fmi3SetShiftFraction, __attribute__((unused)) const fmi3UInt64 counters[], __attribute__((unused)) const fmi3UInt64 resolutions[])

EXPORT fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                             fmi3Float64 activationTime)
{
    BEGIN(fmi3ActivateModelPartition, instance, 0, 0);
    (void)clockReference, (void)activationTime;
    return fmi3Error;
}

EXPORT fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance)
{
    BEGIN(fmi3EvaluateDiscreteStates, instance, S_EVENT | S_STEP, S_EVENT | S_CONTINUOUS);
    return fail(s, "fmi3EvaluateDiscreteStates: not offered (providesEvaluateDiscreteStates=\"false\")");
}

/* ------------------------------------------------------------------------- */
/* Dependencies                                                               */
/* ------------------------------------------------------------------------- */

/* The declared dependencies of `dependent` in the instance's current mode: the initial
 * unknowns' in Instantiated and Initialization Mode, else the outputs' and derivatives'. */
static const Dependency *dependency_of(Instance *s, const char *function, fmi3ValueReference dependent)
{
    int initial = (s->state & (S_INSTANTIATED | S_INITIALIZATION)) != 0;
    const Dependency *fallback = NULL;
    for (size_t i = 0; i < s->cfg.nDeps; i++) {
        const Dependency *d = &s->cfg.deps[i];
        if (d->vr == dependent && d->initial == initial) {
            return d;
        }
        if (d->vr == dependent) {
            fallback = d;
        }
    }
    if (fallback && !initial) {
        return fallback; /* an initial unknown only (a state): its dependencies as declared */
    }
    if (fallback) {
        fail(s, "%s: value reference %u is no initial unknown (in %s only initial unknowns have dependencies)",
             function, dependent, state_name(s->state));
        return NULL;
    }
    fail(s, "%s: value reference %u is no output, continuous state derivative or initial unknown of this FMU",
         function, dependent);
    return NULL;
}

EXPORT fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance, fmi3ValueReference valueReference,
                                                      size_t *nDependencies)
{
    BEGIN(fmi3GetNumberOfVariableDependencies, instance, S_ANY, S_ANY);
    if (!nDependencies) {
        return fail(s, "fmi3GetNumberOfVariableDependencies: nDependencies is NULL");
    }
    const Dependency *d = dependency_of(s, "fmi3GetNumberOfVariableDependencies", valueReference);
    if (!d) {
        return fmi3Error;
    }
    *nDependencies = d->n;
    return fmi3OK;
}

EXPORT fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                              size_t elementIndicesOfDependent[], fmi3ValueReference independents[],
                                              size_t elementIndicesOfIndependents[],
                                              fmi3DependencyKind dependencyKinds[], size_t nDependencies)
{
    BEGIN(fmi3GetVariableDependencies, instance, S_ANY, S_ANY);
    const Dependency *d = dependency_of(s, "fmi3GetVariableDependencies", dependent);
    if (!d) {
        return fmi3Error;
    }
    if (nDependencies != d->n) {
        return fail(s, "fmi3GetVariableDependencies: value reference %u has %zu dependencies, %zu were asked for "
                       "(fmi3GetNumberOfVariableDependencies)", dependent, d->n, nDependencies);
    }
    if (d->n && (!elementIndicesOfDependent || !independents || !elementIndicesOfIndependents || !dependencyKinds)) {
        return fail(s, "fmi3GetVariableDependencies: an array is NULL");
    }
    for (size_t i = 0; i < d->n; i++) {
        elementIndicesOfDependent[i] = 0; /* scalars */
        elementIndicesOfIndependents[i] = 0;
        independents[i] = d->on[i];
        dependencyKinds[i] = fmi3Dependent;
    }
    return fmi3OK;
}

/* ------------------------------------------------------------------------- */
/* Derivatives                                                                */
/* ------------------------------------------------------------------------- */

#define DERIVABLE (S_INITIALIZATION | S_EVENT | S_CONTINUOUS | S_STEP | S_TERMINATED)

static int derivative_arrays(Instance *s, const char *function, const fmi3ValueReference unknowns[],
                             size_t nUnknowns, const fmi3ValueReference knowns[], size_t nKnowns,
                             const fmi3Float64 seed[], size_t nSeed, size_t seedsExpected, fmi3Float64 sensitivity[],
                             size_t nSensitivity, size_t sensitivitiesExpected)
{
    if (nSeed != seedsExpected || nSensitivity != sensitivitiesExpected) {
        fail(s, "%s: %zu seeds and %zu sensitivities for %zu unknowns and %zu knowns (scalars: %zu and %zu "
                "expected); nothing was computed", function, nSeed, nSensitivity, nUnknowns, nKnowns, seedsExpected,
             sensitivitiesExpected);
        return 0;
    }
    if ((nUnknowns && !unknowns) || (nKnowns && !knowns) || (nSeed && !seed) || (nSensitivity && !sensitivity)) {
        fail(s, "%s: an array is NULL", function);
        return 0;
    }
    for (size_t i = 0; i < nSeed; i++) {
        if (!isfinite(seed[i])) {
            fail(s, "%s: seed[%zu] = %g is not finite; nothing was computed", function, i, seed[i]);
            return 0;
        }
    }
    return 1;
}

EXPORT fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[],
                                               size_t nUnknowns, const fmi3ValueReference knowns[], size_t nKnowns,
                                               const fmi3Float64 seed[], size_t nSeed, fmi3Float64 sensitivity[],
                                               size_t nSensitivity)
{
    BEGIN(fmi3GetDirectionalDerivative, instance, DERIVABLE, DERIVABLE);
    if (!derivative_arrays(s, "fmi3GetDirectionalDerivative", unknowns, nUnknowns, knowns, nKnowns, seed, nSeed,
                           nKnowns, sensitivity, nSensitivity, nUnknowns)) {
        return fmi3Error;
    }
    return status3(s->api->fmi2GetDirectionalDerivative(s->inner, unknowns, nUnknowns, knowns, nKnowns, seed,
                                                        sensitivity));
}

/* sensitivity = J^T seed, J = d unknowns / d knowns: one directional derivative per known
 * (J's column), so the same partials as fmi3GetDirectionalDerivative. */
EXPORT fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[],
                                           size_t nUnknowns, const fmi3ValueReference knowns[], size_t nKnowns,
                                           const fmi3Float64 seed[], size_t nSeed, fmi3Float64 sensitivity[],
                                           size_t nSensitivity)
{
    BEGIN(fmi3GetAdjointDerivative, instance, DERIVABLE, DERIVABLE);
    if (!derivative_arrays(s, "fmi3GetAdjointDerivative", unknowns, nUnknowns, knowns, nKnowns, seed, nSeed,
                           nUnknowns, sensitivity, nSensitivity, nKnowns)) {
        return fmi3Error;
    }
    fmi3Float64 *column = malloc((nUnknowns ? nUnknowns : 1) * sizeof *column);
    fmi3Float64 *result = malloc((nKnowns ? nKnowns : 1) * sizeof *result);
    fmi3Status status = column && result ? fmi3OK : fail(s, "fmi3GetAdjointDerivative: out of memory");
    const fmi2Real one = 1.0;
    for (size_t j = 0; succeeded(status) && j < nKnowns; j++) {
        fmi3Status got = status3(s->api->fmi2GetDirectionalDerivative(s->inner, unknowns, nUnknowns, &knowns[j], 1,
                                                                      &one, column));
        status = got > status ? got : status;
        double sum = 0.0;
        for (size_t i = 0; i < nUnknowns; i++) {
            sum += seed[i] * column[i];
        }
        result[j] = sum;
    }
    if (succeeded(status)) {
        memcpy(sensitivity, result, nKnowns * sizeof *result);
    }
    free(column);
    free(result);
    return status;
}

EXPORT fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                           const fmi3Int32 order[], fmi3Float64 values[], size_t nValues)
{
    BEGIN(fmi3GetOutputDerivatives, instance, S_STEP | S_EVENT | S_TERMINATED, 0);
    if (!scalar_counts(s, "fmi3GetOutputDerivatives", vr, nvr, values, nValues)) return fmi3Error;
    if (nvr && !order) return fail(s, "fmi3GetOutputDerivatives: order is NULL");
    return status3(s->api->fmi2GetRealOutputDerivatives(s->inner, vr, nvr, order, values));
}

/* ------------------------------------------------------------------------- */
/* Co-Simulation                                                              */
/* ------------------------------------------------------------------------- */

EXPORT fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                             fmi3Float64 communicationStepSize, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                             fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation,
                             fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime)
{
    BEGIN(fmi3DoStep, instance, S_STEP, 0);
    if (!eventHandlingNeeded || !terminateSimulation || !earlyReturn || !lastSuccessfulTime) {
        return fail(s, "fmi3DoStep: an out-argument (eventHandlingNeeded, terminateSimulation, earlyReturn, "
                       "lastSuccessfulTime) is NULL; no step was taken");
    }
    if (s->discarded) {
        return fail(s, "fmi3DoStep: the last step was discarded (lastSuccessfulTime %.17g s); restore a state "
                       "(fmi3SetFMUState) or terminate", s->time);
    }
    fmi3Status status = status3(s->api->fmi2DoStep(s->inner, currentCommunicationPoint, communicationStepSize,
                                                   noSetFMUStatePriorToCurrentPoint));
    if (succeeded(status)) {
        s->time = currentCommunicationPoint + communicationStepSize;
    } else if (status == fmi3Discard) {
        fmi2Real reached = s->time;
        if (s->api->fmi2GetRealStatus(s->inner, fmi2LastSuccessfulTime, &reached) == fmi2OK) {
            s->time = reached;
        }
        s->discarded = 1;
    }
    /* Events are located and handled inside the step, the simulation never asks to end and
     * steps never return early.  On fmi3Error nothing changed: the time is the step's start. */
    *eventHandlingNeeded = false;
    *terminateSimulation = false;
    *earlyReturn = false;
    *lastSuccessfulTime = s->time;
    return status;
}

/* ------------------------------------------------------------------------- */
/* Model Exchange and Event Mode                                              */
/* ------------------------------------------------------------------------- */

EXPORT fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                           fmi3Boolean *terminateSimulation,
                                           fmi3Boolean *nominalsOfContinuousStatesChanged,
                                           fmi3Boolean *valuesOfContinuousStatesChanged,
                                           fmi3Boolean *nextEventTimeDefined, fmi3Float64 *nextEventTime)
{
    BEGIN(fmi3UpdateDiscreteStates, instance, S_EVENT, S_EVENT);
    if (!discreteStatesNeedUpdate || !terminateSimulation || !nominalsOfContinuousStatesChanged ||
        !valuesOfContinuousStatesChanged || !nextEventTimeDefined || !nextEventTime) {
        return fail(s, "fmi3UpdateDiscreteStates: an out-argument is NULL; nothing was updated");
    }
    fmi2EventInfo info = {0, 0, 0, 0, 0, 0.0};
    fmi3Status status = fmi3OK;
    if (s->me) {
        status = status3(s->api->fmi2NewDiscreteStates(s->inner, &info));
        if (!succeeded(status)) {
            return status;
        }
    } /* Co-Simulation's Event Mode: the step handled every event already */
    *discreteStatesNeedUpdate = info.newDiscreteStatesNeeded != 0;
    *terminateSimulation = info.terminateSimulation != 0;
    *nominalsOfContinuousStatesChanged = info.nominalsOfContinuousStatesChanged != 0;
    *valuesOfContinuousStatesChanged = info.valuesOfContinuousStatesChanged != 0;
    *nextEventTimeDefined = info.nextEventTimeDefined != 0;
    *nextEventTime = info.nextEventTimeDefined ? info.nextEventTime : 0.0;
    return status;
}

EXPORT fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                              fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation)
{
    BEGIN(fmi3CompletedIntegratorStep, instance, 0, S_CONTINUOUS);
    if (!enterEventMode || !terminateSimulation) {
        return fail(s, "fmi3CompletedIntegratorStep: %s is NULL", enterEventMode ? "terminateSimulation" : "enterEventMode");
    }
    fmi2Boolean enter = 0, end = 0;
    fmi3Status status = status3(s->api->fmi2CompletedIntegratorStep(s->inner, noSetFMUStatePriorToCurrentPoint,
                                                                    &enter, &end));
    if (succeeded(status)) {
        *enterEventMode = enter != 0;
        *terminateSimulation = end != 0;
    }
    return status;
}

EXPORT fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time)
{
    BEGIN(fmi3SetTime, instance, 0, S_EVENT | S_CONTINUOUS);
    fmi3Status status = status3(s->api->fmi2SetTime(s->inner, time));
    if (succeeded(status)) {
        s->time = time;
    }
    return status;
}

EXPORT fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 x[], size_t nx)
{
    BEGIN(fmi3SetContinuousStates, instance, 0, S_CONTINUOUS);
    return status3(s->api->fmi2SetContinuousStates(s->inner, x, nx));
}

EXPORT fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[], size_t nx)
{
    BEGIN(fmi3GetContinuousStateDerivatives, instance, 0, S_EVENT | S_CONTINUOUS | S_TERMINATED);
    return status3(s->api->fmi2GetDerivatives(s->inner, derivatives, nx));
}

EXPORT fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[], size_t nz)
{
    BEGIN(fmi3GetEventIndicators, instance, 0, S_INITIALIZATION | S_EVENT | S_CONTINUOUS | S_TERMINATED);
    return status3(s->api->fmi2GetEventIndicators(s->inner, eventIndicators, nz));
}

EXPORT fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 x[], size_t nx)
{
    BEGIN(fmi3GetContinuousStates, instance, 0, S_INITIALIZATION | S_EVENT | S_CONTINUOUS | S_TERMINATED);
    return status3(s->api->fmi2GetContinuousStates(s->inner, x, nx));
}

EXPORT fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[], size_t nx)
{
    BEGIN(fmi3GetNominalsOfContinuousStates, instance, 0, S_INSTANTIATED | S_EVENT | S_CONTINUOUS | S_TERMINATED);
    return status3(s->api->fmi2GetNominalsOfContinuousStates(s->inner, nominals, nx));
}

EXPORT fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators)
{
    BEGIN(fmi3GetNumberOfEventIndicators, instance, 0, S_ANY);
    if (!nEventIndicators) return fail(s, "fmi3GetNumberOfEventIndicators: nEventIndicators is NULL");
    *nEventIndicators = s->cfg.nz;
    return fmi3OK;
}

EXPORT fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates)
{
    BEGIN(fmi3GetNumberOfContinuousStates, instance, 0, S_ANY);
    if (!nContinuousStates) return fail(s, "fmi3GetNumberOfContinuousStates: nContinuousStates is NULL");
    *nContinuousStates = s->cfg.nx;
    return fmi3OK;
}

/* ------------------------------------------------------------------------- */
/* FMU states (Co-Simulation)                                                 */
/* ------------------------------------------------------------------------- */

/* What fmi3GetFMUState hands out: the inner state and this layer's state and time. */
#define STATE_MAGIC 0x4c563353u /* "LV3S" */
typedef struct {
    unsigned magic;
    int state;
    int discarded;
    double time;
    fmi2FMUstate inner;
} State;

/* The header in front of the inner entry's serialized bytes. */
#define SERIAL_MAGIC "LVRFMI3" /* 8 bytes with its NUL */
#define SERIAL_VERSION 1u
#define SERIAL_HEADER 32 /* magic[8] version:u32 state:u32 discarded:u32 reserved:u32 time:f64 */
/* The FMI 2 entry's own header (lever_fmi2_shim.c): its state bit at 12, its time at 16. */
#define INNER_HEADER 32
enum { INNER_INSTANTIATED = 1, INNER_INITIALIZATION = 2, INNER_STEP_COMPLETE = 4, INNER_STEP_FAILED = 8,
       INNER_TERMINATED = 16 };

#define STATEFUL S_ANY

static State *state_of(Instance *s, const char *function, fmi3FMUState state)
{
    State *w = state;
    if (!w || w->magic != STATE_MAGIC) {
        fail(s, "%s: not an FMU state of this FMU (NULL, freed or foreign)", function);
        return NULL;
    }
    return w;
}

EXPORT fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *state)
{
    BEGIN(fmi3GetFMUState, instance, STATEFUL, 0);
    if (!state) return fail(s, "fmi3GetFMUState: state is NULL");
    State *w = *state ? state_of(s, "fmi3GetFMUState", *state) : calloc(1, sizeof *w);
    if (!w) return *state ? fmi3Error : fail(s, "fmi3GetFMUState: out of memory");
    fmi2FMUstate inner = w->inner;
    fmi3Status status = status3(s->api->fmi2GetFMUstate(s->inner, &inner));
    if (!succeeded(status)) {
        if (!*state) free(w);
        return status;
    }
    w->magic = STATE_MAGIC;
    w->inner = inner;
    w->state = s->state;
    w->discarded = s->discarded;
    w->time = s->time;
    *state = w;
    return status;
}

EXPORT fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState state)
{
    BEGIN(fmi3SetFMUState, instance, STATEFUL, 0);
    State *w = state_of(s, "fmi3SetFMUState", state);
    if (!w) return fmi3Error;
    fmi3Status status = status3(s->api->fmi2SetFMUstate(s->inner, w->inner));
    if (succeeded(status)) {
        s->state = w->state;
        s->discarded = w->discarded;
        s->time = w->time;
    }
    return status;
}

EXPORT fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *state)
{
    BEGIN(fmi3FreeFMUState, instance, STATEFUL, 0);
    if (!state || !*state) return fmi3OK; /* freeing nothing is allowed */
    State *w = state_of(s, "fmi3FreeFMUState", *state);
    if (!w) return fmi3Error;
    fmi3Status status = status3(s->api->fmi2FreeFMUstate(s->inner, &w->inner));
    w->magic = 0;
    free(w);
    *state = NULL;
    return status;
}

EXPORT fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState state, size_t *size)
{
    BEGIN(fmi3SerializedFMUStateSize, instance, STATEFUL, 0);
    State *w = state_of(s, "fmi3SerializedFMUStateSize", state);
    if (!w) return fmi3Error;
    if (!size) return fail(s, "fmi3SerializedFMUStateSize: size is NULL");
    size_t inner = 0;
    fmi3Status status = status3(s->api->fmi2SerializedFMUstateSize(s->inner, w->inner, &inner));
    if (succeeded(status)) {
        if (inner > SIZE_MAX - SERIAL_HEADER) return fail(s, "fmi3SerializedFMUStateSize: the state is too large");
        *size = SERIAL_HEADER + inner;
    }
    return status;
}

EXPORT fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState state, fmi3Byte serializedState[],
                                        size_t size)
{
    BEGIN(fmi3SerializeFMUState, instance, STATEFUL, 0);
    State *w = state_of(s, "fmi3SerializeFMUState", state);
    if (!w) return fmi3Error;
    size_t inner = 0;
    fmi3Status status = status3(s->api->fmi2SerializedFMUstateSize(s->inner, w->inner, &inner));
    if (!succeeded(status)) return status;
    if (!serializedState || inner > SIZE_MAX - SERIAL_HEADER || size != SERIAL_HEADER + inner) {
        return fail(s, "fmi3SerializeFMUState: the buffer holds %zu bytes, the state has %zu "
                       "(fmi3SerializedFMUStateSize); nothing was written", serializedState ? size : 0,
                    SERIAL_HEADER + inner);
    }
    uint32_t version = SERIAL_VERSION, st = (uint32_t)w->state, discarded = (uint32_t)w->discarded, reserved = 0;
    memcpy(serializedState, SERIAL_MAGIC, 8);
    memcpy(serializedState + 8, &version, 4);
    memcpy(serializedState + 12, &st, 4);
    memcpy(serializedState + 16, &discarded, 4);
    memcpy(serializedState + 20, &reserved, 4);
    memcpy(serializedState + 24, &w->time, 8);
    return status3(s->api->fmi2SerializeFMUstate(s->inner, w->inner, (fmi2Byte *)serializedState + SERIAL_HEADER,
                                                 inner));
}

/* The FMI 3 state the inner entry's state bit stands for (0: none). */
static int state_from_inner(uint32_t inner, int eventModeUsed, int *discarded)
{
    *discarded = inner == INNER_STEP_FAILED;
    switch (inner) {
    case INNER_INSTANTIATED: return S_INSTANTIATED;
    case INNER_INITIALIZATION: return S_INITIALIZATION;
    case INNER_STEP_COMPLETE: return eventModeUsed ? (S_STEP | S_EVENT) : S_STEP;
    case INNER_STEP_FAILED: return S_STEP;
    case INNER_TERMINATED: return S_TERMINATED;
    default: return 0;
    }
}

EXPORT fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[], size_t size,
                                          fmi3FMUState *state)
{
    BEGIN(fmi3DeserializeFMUState, instance, STATEFUL, 0);
    if (!state || (!serializedState && size)) {
        return fail(s, "fmi3DeserializeFMUState: %s is NULL", state ? "serializedState" : "state");
    }
    if (size < SERIAL_HEADER + INNER_HEADER || memcmp(serializedState, SERIAL_MAGIC, 8) != 0) {
        return fail(s, "fmi3DeserializeFMUState: these %zu bytes are not a serialized FMI 3 state of this FMU "
                       "(no '%s' header)", size, SERIAL_MAGIC);
    }
    uint32_t version, st, discarded, inner_state;
    double time, inner_time;
    memcpy(&version, serializedState + 8, 4);
    memcpy(&st, serializedState + 12, 4);
    memcpy(&discarded, serializedState + 16, 4);
    memcpy(&time, serializedState + 24, 8);
    memcpy(&inner_state, serializedState + SERIAL_HEADER + 12, 4);
    memcpy(&inner_time, serializedState + SERIAL_HEADER + 16, 8);
    if (version != SERIAL_VERSION) {
        return fail(s, "fmi3DeserializeFMUState: format version %u, this FMU reads %u", version, SERIAL_VERSION);
    }
    int inner_discarded = 0;
    int expected = state_from_inner(inner_state, 1, &inner_discarded);
    if (!(st & S_ANY) || (st & (st - 1)) || !(expected & (int)st) || discarded != (uint32_t)inner_discarded ||
        !isfinite(time) || memcmp(&time, &inner_time, sizeof time) != 0) {
        return fail(s, "fmi3DeserializeFMUState: the header (state %u, time %g) does not agree with the state it "
                       "carries (state bit %u, time %g): the bytes are damaged", st, time, inner_state, inner_time);
    }
    State *w = calloc(1, sizeof *w);
    if (!w) return fail(s, "fmi3DeserializeFMUState: out of memory");
    fmi2FMUstate inner = NULL;
    fmi3Status status = status3(s->api->fmi2DeSerializeFMUstate(
        s->inner, (const fmi2Byte *)serializedState + SERIAL_HEADER, size - SERIAL_HEADER, &inner));
    if (!succeeded(status)) {
        free(w);
        return status;
    }
    w->magic = STATE_MAGIC;
    w->inner = inner;
    w->state = (int)st;
    w->discarded = (int)discarded;
    w->time = time;
    *state = w;
    return status;
}
