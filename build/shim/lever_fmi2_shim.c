/*
 * lever_fmi2_shim.c -- FMI 2.0 Co-Simulation shim in front of pythonfmu 0.7.0.
 *
 * pythonfmu's native export library (shipped next to this file in the FMU as
 * "pythonfmu-export.so") has three defects we work around here:
 *   1. The only non-OK status a Python slave can produce is an exception, which
 *      becomes fmi2Fatal *and* frees the Python instance while keeping a
 *      dangling pointer: any later call, fmi2FreeInstance included, is a
 *      use-after-free.
 *   2. With loggingOn=fmi2False it drops every message, errors included.
 *   3. do_step() returning False is reported as fmi2Discard.
 * Our Python slaves therefore never raise; they call self.log(msg, error) and
 * return normally.  This shim turns the most severe status logged during a call
 * into that call's return status, always delivers warnings/errors to the
 * importer, and quarantines an instance after a fatal error.
 *
 * Build: cc -shared -fPIC -O2 -std=c99 -fvisibility=hidden -Wall -Wextra -Werror
 *        -o <modelIdentifier>.so lever_fmi2_shim.c -ldl
 */
#define _GNU_SOURCE /* dladdr */

#include <dlfcn.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ------------------------------------------------------------------------- */
/* Minimal FMI 2.0 declarations (standard ABI of fmi2TypesPlatform.h,          */
/* fmi2FunctionTypes.h and fmi2Functions.h).                                   */
/* ------------------------------------------------------------------------- */

typedef void *fmi2Component;
typedef void *fmi2ComponentEnvironment;
typedef void *fmi2FMUstate;
typedef unsigned int fmi2ValueReference;
typedef double fmi2Real;
typedef int fmi2Integer;
typedef int fmi2Boolean;
typedef char fmi2Char;
typedef const fmi2Char *fmi2String;
typedef char fmi2Byte;

#define fmi2True 1
#define fmi2False 0

typedef enum { fmi2OK, fmi2Warning, fmi2Discard, fmi2Error, fmi2Fatal, fmi2Pending } fmi2Status;
typedef enum { fmi2ModelExchange, fmi2CoSimulation } fmi2Type;
typedef enum {
    fmi2DoStepStatus,
    fmi2PendingStatus,
    fmi2LastSuccessfulTime,
    fmi2Terminated
} fmi2StatusKind;

typedef void (*fmi2CallbackLogger)(fmi2ComponentEnvironment, fmi2String instanceName,
                                   fmi2Status, fmi2String category, fmi2String message, ...);
typedef void *(*fmi2CallbackAllocateMemory)(size_t, size_t);
typedef void (*fmi2CallbackFreeMemory)(void *);
typedef void (*fmi2StepFinished)(fmi2ComponentEnvironment, fmi2Status);

typedef struct {
    fmi2CallbackLogger logger;
    fmi2CallbackAllocateMemory allocateMemory;
    fmi2CallbackFreeMemory freeMemory;
    fmi2StepFinished stepFinished;
    fmi2ComponentEnvironment componentEnvironment;
} fmi2CallbackFunctions;

/* Function types, as in fmi2FunctionTypes.h. */
typedef const char *fmi2GetTypesPlatformTYPE(void);
typedef const char *fmi2GetVersionTYPE(void);
typedef fmi2Status fmi2SetDebugLoggingTYPE(fmi2Component, fmi2Boolean, size_t, const fmi2String[]);
typedef fmi2Component fmi2InstantiateTYPE(fmi2String, fmi2Type, fmi2String, fmi2String,
                                          const fmi2CallbackFunctions *, fmi2Boolean, fmi2Boolean);
typedef void fmi2FreeInstanceTYPE(fmi2Component);
typedef fmi2Status fmi2SetupExperimentTYPE(fmi2Component, fmi2Boolean, fmi2Real, fmi2Real,
                                           fmi2Boolean, fmi2Real);
typedef fmi2Status fmi2EnterInitializationModeTYPE(fmi2Component);
typedef fmi2Status fmi2ExitInitializationModeTYPE(fmi2Component);
typedef fmi2Status fmi2TerminateTYPE(fmi2Component);
typedef fmi2Status fmi2ResetTYPE(fmi2Component);
typedef fmi2Status fmi2GetRealTYPE(fmi2Component, const fmi2ValueReference[], size_t, fmi2Real[]);
typedef fmi2Status fmi2GetIntegerTYPE(fmi2Component, const fmi2ValueReference[], size_t, fmi2Integer[]);
typedef fmi2Status fmi2GetBooleanTYPE(fmi2Component, const fmi2ValueReference[], size_t, fmi2Boolean[]);
typedef fmi2Status fmi2GetStringTYPE(fmi2Component, const fmi2ValueReference[], size_t, fmi2String[]);
typedef fmi2Status fmi2SetRealTYPE(fmi2Component, const fmi2ValueReference[], size_t, const fmi2Real[]);
typedef fmi2Status fmi2SetIntegerTYPE(fmi2Component, const fmi2ValueReference[], size_t,
                                      const fmi2Integer[]);
typedef fmi2Status fmi2SetBooleanTYPE(fmi2Component, const fmi2ValueReference[], size_t,
                                      const fmi2Boolean[]);
typedef fmi2Status fmi2SetStringTYPE(fmi2Component, const fmi2ValueReference[], size_t,
                                     const fmi2String[]);
typedef fmi2Status fmi2GetFMUstateTYPE(fmi2Component, fmi2FMUstate *);
typedef fmi2Status fmi2SetFMUstateTYPE(fmi2Component, fmi2FMUstate);
typedef fmi2Status fmi2FreeFMUstateTYPE(fmi2Component, fmi2FMUstate *);
typedef fmi2Status fmi2SerializedFMUstateSizeTYPE(fmi2Component, fmi2FMUstate, size_t *);
typedef fmi2Status fmi2SerializeFMUstateTYPE(fmi2Component, fmi2FMUstate, fmi2Byte[], size_t);
typedef fmi2Status fmi2DeSerializeFMUstateTYPE(fmi2Component, const fmi2Byte[], size_t, fmi2FMUstate *);
typedef fmi2Status fmi2GetDirectionalDerivativeTYPE(fmi2Component, const fmi2ValueReference[], size_t,
                                                    const fmi2ValueReference[], size_t,
                                                    const fmi2Real[], fmi2Real[]);
typedef fmi2Status fmi2SetRealInputDerivativesTYPE(fmi2Component, const fmi2ValueReference[], size_t,
                                                   const fmi2Integer[], const fmi2Real[]);
typedef fmi2Status fmi2GetRealOutputDerivativesTYPE(fmi2Component, const fmi2ValueReference[], size_t,
                                                    const fmi2Integer[], fmi2Real[]);
typedef fmi2Status fmi2DoStepTYPE(fmi2Component, fmi2Real, fmi2Real, fmi2Boolean);
typedef fmi2Status fmi2CancelStepTYPE(fmi2Component);
typedef fmi2Status fmi2GetStatusTYPE(fmi2Component, const fmi2StatusKind, fmi2Status *);
typedef fmi2Status fmi2GetRealStatusTYPE(fmi2Component, const fmi2StatusKind, fmi2Real *);
typedef fmi2Status fmi2GetIntegerStatusTYPE(fmi2Component, const fmi2StatusKind, fmi2Integer *);
typedef fmi2Status fmi2GetBooleanStatusTYPE(fmi2Component, const fmi2StatusKind, fmi2Boolean *);
typedef fmi2Status fmi2GetStringStatusTYPE(fmi2Component, const fmi2StatusKind, fmi2String *);

/* Every function the inner library must provide (all of them are exported by
 * pythonfmu 0.7.0).  fmi2GetTypesPlatform/fmi2GetVersion are answered by the
 * shim itself and are not needed from the inner library. */
#define SHIM_INNER_FUNCTIONS(X)                                                                    \
    X(fmi2Instantiate)                                                                             \
    X(fmi2FreeInstance)                                                                            \
    X(fmi2SetupExperiment)                                                                         \
    X(fmi2EnterInitializationMode)                                                                 \
    X(fmi2ExitInitializationMode)                                                                  \
    X(fmi2Terminate)                                                                               \
    X(fmi2Reset)                                                                                   \
    X(fmi2GetReal)                                                                                 \
    X(fmi2GetInteger)                                                                              \
    X(fmi2GetBoolean)                                                                              \
    X(fmi2GetString)                                                                               \
    X(fmi2SetReal)                                                                                 \
    X(fmi2SetInteger)                                                                              \
    X(fmi2SetBoolean)                                                                              \
    X(fmi2SetString)                                                                               \
    X(fmi2GetFMUstate)                                                                             \
    X(fmi2SetFMUstate)                                                                             \
    X(fmi2FreeFMUstate)                                                                            \
    X(fmi2SerializedFMUstateSize)                                                                  \
    X(fmi2SerializeFMUstate)                                                                       \
    X(fmi2DeSerializeFMUstate)                                                                     \
    X(fmi2GetDirectionalDerivative)                                                                \
    X(fmi2SetRealInputDerivatives)                                                                 \
    X(fmi2GetRealOutputDerivatives)                                                                \
    X(fmi2DoStep)                                                                                  \
    X(fmi2CancelStep)                                                                              \
    X(fmi2GetStatus)                                                                               \
    X(fmi2GetRealStatus)                                                                           \
    X(fmi2GetIntegerStatus)                                                                        \
    X(fmi2GetBooleanStatus)                                                                        \
    X(fmi2GetStringStatus)

/* Exported declarations: declaring through the TYPE typedefs makes the compiler
 * check each definition below against the standard signature. */
#define SHIM_EXPORT __attribute__((visibility("default")))
#define SHIM_DECLARE(name) SHIM_EXPORT name##TYPE name;
SHIM_DECLARE(fmi2GetTypesPlatform)
SHIM_DECLARE(fmi2GetVersion)
SHIM_DECLARE(fmi2SetDebugLogging)
SHIM_INNER_FUNCTIONS(SHIM_DECLARE)

/* ------------------------------------------------------------------------- */
/* Inner library                                                              */
/* ------------------------------------------------------------------------- */

#define INNER_LIBRARY_NAME "pythonfmu-export.so"
#define SHIM_CATEGORY "logStatusError"

typedef struct {
#define SHIM_API_MEMBER(name) name##TYPE *name;
    SHIM_INNER_FUNCTIONS(SHIM_API_MEMBER)
#undef SHIM_API_MEMBER
} InnerApi;

/* Published once with an atomic compare-and-swap so that concurrent first
 * instantiations (importers may instantiate from several threads) are safe
 * without pulling in pthreads.  The inner library is never unloaded: leaked
 * (dead) inner instances live in it, and pythonfmu pins itself anyway. */
static InnerApi *g_api;

/* Loads the inner library on first use.  On failure returns NULL and leaves a
 * description in err. */
static InnerApi *inner_api(char *err, size_t errsize)
{
    InnerApi *api = __atomic_load_n(&g_api, __ATOMIC_ACQUIRE);
    if (api) {
        return api;
    }

    /* The inner library sits next to this file; dladdr on one of our own
     * functions yields our path regardless of how the importer found us. */
    Dl_info info;
    if (!dladdr((void *)&fmi2Instantiate, &info) || !info.dli_fname) {
        snprintf(err, errsize, "cannot determine the directory of the FMU binary");
        return NULL;
    }
    const char *slash = strrchr(info.dli_fname, '/');
    size_t dirlen = slash ? (size_t)(slash - info.dli_fname) + 1 : 0;
    size_t pathsize = dirlen + sizeof INNER_LIBRARY_NAME;
    char *path = malloc(pathsize);
    if (!path) {
        snprintf(err, errsize, "out of memory");
        return NULL;
    }
    memcpy(path, info.dli_fname, dirlen);
    memcpy(path + dirlen, INNER_LIBRARY_NAME, sizeof INNER_LIBRARY_NAME);

    void *handle = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!handle) {
        const char *why = dlerror();
        snprintf(err, errsize, "cannot load %s: %s", path, why ? why : "unknown error");
        free(path);
        return NULL;
    }

    api = calloc(1, sizeof *api);
    if (!api) {
        snprintf(err, errsize, "out of memory");
        dlclose(handle);
        free(path);
        return NULL;
    }
#define SHIM_RESOLVE(name)                                                                         \
    api->name = (name##TYPE *)dlsym(handle, #name);                                                \
    if (!api->name) {                                                                              \
        snprintf(err, errsize, "%s does not export %s", path, #name);                             \
        free(api);                                                                                 \
        dlclose(handle);                                                                           \
        free(path);                                                                                \
        return NULL;                                                                               \
    }
    SHIM_INNER_FUNCTIONS(SHIM_RESOLVE)
#undef SHIM_RESOLVE
    free(path);

    InnerApi *expected = NULL;
    if (!__atomic_compare_exchange_n(&g_api, &expected, api, 0, __ATOMIC_ACQ_REL,
                                     __ATOMIC_ACQUIRE)) {
        /* Another thread won the race; drop our duplicate reference. */
        free(api);
        dlclose(handle);
        api = expected;
    }
    return api;
}

/* ------------------------------------------------------------------------- */
/* Instances                                                                  */
/* ------------------------------------------------------------------------- */

typedef struct {
    fmi2Component inner;
    fmi2CallbackFunctions importer; /* the importer's callbacks (copied) */
    /* Callbacks handed to the inner library.  pythonfmu keeps a *pointer* to
     * this struct, so it lives here, at a stable address. */
    fmi2CallbackFunctions own;
    char *instanceName;
    fmi2Boolean loggingOn;  /* the importer's wish; the inner one is always on */
    size_t nCategories;     /* 0 = all categories */
    char **categories;
    fmi2Status worst;       /* most severe status logged during the current call */
    int dead;               /* inner instance returned fmi2Fatal: never touch it again */
    const char *deadIn;     /* the function that returned fmi2Fatal */
} Shim;

static void free_categories(Shim *s)
{
    for (size_t i = 0; i < s->nCategories; i++) {
        free(s->categories[i]);
    }
    free(s->categories);
    s->categories = NULL;
    s->nCategories = 0;
}

static void free_shim(Shim *s)
{
    free_categories(s);
    free(s->instanceName);
    free(s);
}

static int category_enabled(const Shim *s, fmi2String category)
{
    if (s->nCategories == 0) {
        return 1;
    }
    if (!category) {
        return 0;
    }
    for (size_t i = 0; i < s->nCategories; i++) {
        if (strcmp(s->categories[i], category) == 0) {
            return 1;
        }
    }
    return 0;
}

/* Records the status and forwards the message to the importer: warnings and
 * worse always, fmi2OK messages only if the importer enabled that logging. */
static void shim_record(Shim *s, fmi2Status status, fmi2String category, fmi2String message)
{
    if ((unsigned)status > (unsigned)fmi2Fatal) {
        status = fmi2Error; /* nonsense from Python: treat it as an error */
    }
    if (status > s->worst) {
        s->worst = status;
    }
    if (!s->importer.logger) {
        return;
    }
    if (status == fmi2OK && !(s->loggingOn && category_enabled(s, category))) {
        return;
    }
    /* pythonfmu passes Python text as the printf format; pass it as an argument
     * instead so a '%' in a message cannot make the importer read garbage. */
    s->importer.logger(s->importer.componentEnvironment, s->instanceName, status,
                       category ? category : "", "%s", message ? message : "");
}

/* The logger the inner library sees.  componentEnvironment is our Shim.
 * pythonfmu never passes format arguments, so the variadic part is ignored. */
static void shim_logger(fmi2ComponentEnvironment env, fmi2String instanceName, fmi2Status status,
                        fmi2String category, fmi2String message, ...)
{
    (void)instanceName;
    if (env) {
        shim_record((Shim *)env, status, category, message);
    }
}

/* Messages originating in the shim itself. */
static void shim_error(Shim *s, const char *fmt, const char *arg)
{
    char buffer[2048]; /* room for an err[1024] plus prefix */
    snprintf(buffer, sizeof buffer, fmt, arg);
    shim_record(s, fmi2Error, SHIM_CATEGORY, buffer);
}

/* Prologue of every forwarded call: 1 if the inner library may be called. */
static int shim_begin(Shim *s)
{
    if (!s) {
        return 0;
    }
    s->worst = fmi2OK;
    if (s->dead) {
        shim_error(s, "instance is unusable after a fatal error in %s", s->deadIn);
        return 0;
    }
    return 1;
}

/* Epilogue: the call's status is the worse of what the inner library returned
 * and what was logged during the call. */
static fmi2Status shim_end(Shim *s, const char *function, fmi2Status status)
{
    if (status == fmi2Fatal) {
        /* pythonfmu has freed the Python object but still points at it. */
        s->dead = 1;
        s->deadIn = function;
    }
    return status > s->worst ? status : s->worst;
}

#define SHIM(c) ((Shim *)(c))

/* Forward a call with arguments after the component. */
#define FORWARD(name, c, ...)                                                                      \
    do {                                                                                           \
        if (!shim_begin(SHIM(c))) return fmi2Error;                                                \
        return shim_end(SHIM(c), #name, g_api->name(SHIM(c)->inner, __VA_ARGS__));                 \
    } while (0)

/* Forward a call whose only argument is the component. */
#define FORWARD0(name, c)                                                                          \
    do {                                                                                           \
        if (!shim_begin(SHIM(c))) return fmi2Error;                                                \
        return shim_end(SHIM(c), #name, g_api->name(SHIM(c)->inner));                              \
    } while (0)

/* ------------------------------------------------------------------------- */
/* FMI 2.0 API                                                                */
/* ------------------------------------------------------------------------- */

const char *fmi2GetTypesPlatform(void) { return "default"; }

const char *fmi2GetVersion(void) { return "2.0"; }

static char *copy_string(const char *text)
{
    size_t n = strlen(text) + 1;
    char *copy = malloc(n);
    if (copy) {
        memcpy(copy, text, n);
    }
    return copy;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible,
                              fmi2Boolean loggingOn)
{
    if (!functions) {
        return NULL;
    }
    /* The struct must exist before the inner instantiate: it may log already. */
    Shim *s = calloc(1, sizeof *s);
    if (!s) {
        return NULL;
    }
    s->importer = *functions;
    s->loggingOn = loggingOn;
    s->instanceName = copy_string(instanceName ? instanceName : "");
    if (!s->instanceName) {
        free_shim(s);
        return NULL;
    }
    s->own.logger = shim_logger;
    s->own.allocateMemory = functions->allocateMemory;
    s->own.freeMemory = functions->freeMemory;
    s->own.stepFinished = NULL; /* asynchronous doStep is not supported */
    s->own.componentEnvironment = s;

    /* pythonfmu builds std::strings from these; NULL would crash it. */
    if (!fmuGUID || !fmuResourceLocation) {
        shim_error(s, "fmi2Instantiate: %s is NULL", fmuGUID ? "fmuResourceLocation" : "fmuGUID");
        free_shim(s);
        return NULL;
    }
    if (fmuType != fmi2CoSimulation) {
        shim_error(s, "fmi2Instantiate: %s", "this FMU supports Co-Simulation only");
        free_shim(s);
        return NULL;
    }

    char err[1024];
    if (!inner_api(err, sizeof err)) {
        shim_error(s, "fmi2Instantiate: %s", err);
        free_shim(s);
        return NULL;
    }

    /* loggingOn is always true for the inner library: with it off, pythonfmu
     * suppresses errors too.  The shim filters instead. */
    s->inner = g_api->fmi2Instantiate(s->instanceName, fmuType, fmuGUID, fmuResourceLocation,
                                      &s->own, visible, fmi2True);
    if (!s->inner) {
        free_shim(s);
        return NULL;
    }
    return s;
}

void fmi2FreeInstance(fmi2Component c)
{
    Shim *s = SHIM(c);
    if (!s) {
        return;
    }
    /* A dead inner instance is leaked on purpose: freeing it would decref the
     * already freed Python object a second time. */
    if (!s->dead) {
        s->worst = fmi2OK;
        g_api->fmi2FreeInstance(s->inner);
    }
    free_shim(s);
}

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[])
{
    Shim *s = SHIM(c);
    if (!shim_begin(s)) {
        return fmi2Error;
    }
    if (nCategories > 0 && !categories) {
        shim_error(s, "fmi2SetDebugLogging: %s", "categories is NULL");
        return fmi2Error;
    }
    /* Copy first so a failure leaves the previous settings intact; the
     * caller's strings may not outlive this call. */
    char **copies = NULL;
    if (nCategories > 0) {
        copies = calloc(nCategories, sizeof *copies);
        if (!copies) {
            shim_error(s, "fmi2SetDebugLogging: %s", "out of memory");
            return fmi2Error;
        }
        for (size_t i = 0; i < nCategories; i++) {
            copies[i] = copy_string(categories[i] ? categories[i] : "");
            if (!copies[i]) {
                for (size_t j = 0; j < i; j++) {
                    free(copies[j]);
                }
                free(copies);
                shim_error(s, "fmi2SetDebugLogging: %s", "out of memory");
                return fmi2Error;
            }
        }
    }
    free_categories(s);
    s->categories = copies;
    s->nCategories = nCategories;
    s->loggingOn = loggingOn;
    /* The inner library keeps logging everything; it is not told. */
    return fmi2OK;
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    FORWARD(fmi2SetupExperiment, c, toleranceDefined, tolerance, startTime, stopTimeDefined,
            stopTime);
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) { FORWARD0(fmi2EnterInitializationMode, c); }

fmi2Status fmi2ExitInitializationMode(fmi2Component c) { FORWARD0(fmi2ExitInitializationMode, c); }

fmi2Status fmi2Terminate(fmi2Component c) { FORWARD0(fmi2Terminate, c); }

fmi2Status fmi2Reset(fmi2Component c) { FORWARD0(fmi2Reset, c); }

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    FORWARD(fmi2GetReal, c, vr, nvr, value);
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Integer value[])
{
    FORWARD(fmi2GetInteger, c, vr, nvr, value);
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Boolean value[])
{
    FORWARD(fmi2GetBoolean, c, vr, nvr, value);
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         fmi2String value[])
{
    FORWARD(fmi2GetString, c, vr, nvr, value);
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                       const fmi2Real value[])
{
    FORWARD(fmi2SetReal, c, vr, nvr, value);
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Integer value[])
{
    FORWARD(fmi2SetInteger, c, vr, nvr, value);
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Boolean value[])
{
    FORWARD(fmi2SetBoolean, c, vr, nvr, value);
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         const fmi2String value[])
{
    FORWARD(fmi2SetString, c, vr, nvr, value);
}

/* FMU states are opaque: the inner library's pointers pass through unchanged. */
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    FORWARD(fmi2GetFMUstate, c, state);
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state)
{
    FORWARD(fmi2SetFMUstate, c, state);
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    FORWARD(fmi2FreeFMUstate, c, state);
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t *size)
{
    FORWARD(fmi2SerializedFMUstateSize, c, state, size);
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[], size_t size)
{
    FORWARD(fmi2SerializeFMUstate, c, state, bytes, size);
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size,
                                   fmi2FMUstate *state)
{
    FORWARD(fmi2DeSerializeFMUstate, c, bytes, size, state);
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown[],
                                        size_t nUnknown, const fmi2ValueReference vKnown[],
                                        size_t nKnown, const fmi2Real dvKnown[],
                                        fmi2Real dvUnknown[])
{
    FORWARD(fmi2GetDirectionalDerivative, c, vUnknown, nUnknown, vKnown, nKnown, dvKnown,
            dvUnknown);
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[])
{
    FORWARD(fmi2SetRealInputDerivatives, c, vr, nvr, order, value);
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[])
{
    FORWARD(fmi2GetRealOutputDerivatives, c, vr, nvr, order, value);
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint,
                      fmi2Real communicationStepSize, fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    FORWARD(fmi2DoStep, c, currentCommunicationPoint, communicationStepSize,
            noSetFMUStatePriorToCurrentPoint);
}

fmi2Status fmi2CancelStep(fmi2Component c) { FORWARD0(fmi2CancelStep, c); }

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value)
{
    FORWARD(fmi2GetStatus, c, s, value);
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value)
{
    FORWARD(fmi2GetRealStatus, c, s, value);
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value)
{
    FORWARD(fmi2GetIntegerStatus, c, s, value);
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value)
{
    FORWARD(fmi2GetBooleanStatus, c, s, value);
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value)
{
    FORWARD(fmi2GetStringStatus, c, s, value);
}
