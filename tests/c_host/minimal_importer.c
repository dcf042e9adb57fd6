/*
 * minimal_importer.c -- a host that is not a Python process: it loads an FMI 2.0 FMU's
 * binary with dlopen and runs it through the C API alone.  Used by the tests to check that
 * our FMUs run in a bare environment (no LD_PRELOAD, PYTHONHOME or PYTHONPATH: the FMU finds
 * its Python itself), and that their results in a host whose numerics we did not borrow
 * pass their references.
 *
 * Co-Simulation: instantiates, sets one real input, steps, reads one real output and frees.
 *
 * usage: minimal_importer UNZIPPED_DIR MODEL_IDENTIFIER GUID INPUT_VR INPUT_VALUE
 *                         OUTPUT_VR STEP N_STEPS
 * INPUT_VR "-" sets nothing.  The resource location is file://UNZIPPED_DIR/resources
 * unless the environment variable RESOURCE_URI gives another one.  INSTANCES=2 runs two
 * instances side by side in each thread (their outputs must agree: exit 6 if not);
 * STEP_THREADS=1 makes every step in a thread of its own (one instance called from
 * several threads in turn).
 * prints "t=<time> y=<output>" after every step and "freed" at the end, and the time the
 * stepping loop took as "loop_s=<seconds>" on stderr; exit 0 on success.
 *
 * Model Exchange (--me): the standard's calling sequence (FMI 2.0 section 3.2.3) around a
 * fixed-step classical Runge-Kutta integrator (RK4): instantiate as fmi2ModelExchange,
 * fmi2SetupExperiment, the start values, fmi2EnterInitializationMode, the inputs at the
 * start, fmi2ExitInitializationMode, the event iteration (fmi2NewDiscreteStates until no
 * new discrete states are needed), fmi2EnterContinuousTimeMode; then per RK4 stage
 * fmi2SetTime, the inputs, fmi2SetContinuousStates, fmi2GetDerivatives; after each step
 * fmi2GetEventIndicators - a sign change is located by bisection of the step (the step
 * redone shorter), the states set at its end - and fmi2CompletedIntegratorStep; at a state,
 * time (nextEventTime), input (a repeated CSV row) or step event fmi2EnterEventMode, the
 * new inputs, the event iteration, fmi2EnterContinuousTimeMode and the states read anew
 * when they changed; at the end fmi2Terminate and fmi2FreeInstance.
 *
 * usage: minimal_importer --me UNZIPPED_DIR MODEL_IDENTIFIER GUID NX NZ START OUTPUT_STEP
 *                         N_OUTPUT SUBSTEPS INPUT_CSV INPUT_VRS START_VALUES OUTPUTS OUTPUT_CSV
 * NX, NZ: the model description's numbers of states and event indicators.  INPUT_CSV: a
 * header, then rows "time,u1,u2,..." in the order of INPUT_VRS (comma-separated value
 * references, "-" for none); between rows an input is linear, a row repeated at the same
 * time is a discontinuity (the left value first).  START_VALUES: "rVR=VALUE" (Real) or
 * "iVR=VALUE" (Integer), comma-separated, "-" for none.  OUTPUTS: "name=VR" comma-separated.
 * Writes OUTPUT_CSV ("time" and the outputs' names; a row at every output point, START +
 * k * OUTPUT_STEP, read after the inputs of that time are set and any event there is
 * handled), each output step made of SUBSTEPS RK4 steps (shorter ones up to an event).
 * prints on stderr "me: rk4_steps=N state_events=N time_events=N input_events=N
 * step_events=N loop_s=S"; exit 0 on success.
 *
 * Co-Simulation driven by inputs (--cs): instantiate as fmi2CoSimulation, fmi2SetupExperiment
 * (stop time defined), the start values, fmi2EnterInitializationMode, the inputs at the start,
 * fmi2ExitInitializationMode, the outputs at the start; then per communication step the
 * inputs at its start (right values at a repeated row), fmi2DoStep and the outputs at its end
 * - the cross-check's sampling - and fmi2Terminate, fmi2FreeInstance.
 *
 * usage: minimal_importer --cs DIR MODEL GUID START STEP N_STEPS INPUT_CSV INPUT_VRS
 *                         START_VALUES OUTPUTS OUTPUT_CSV
 * (the arguments as for --me); writes a row at START and after every step; prints on stderr
 * "cs: steps=N loop_s=S".
 *
 * FMI 3.0 (--me3, --cs3, the arguments as for --me, --cs; GUID is the instantiation token):
 * the binary from binaries/x86_64-linux, resourcePath DIR/resources/;
 * fmi3InstantiateModelExchange or fmi3InstantiateCoSimulation (no event mode, no early
 * return, no intermediate update), the start values in Instantiated, then
 * fmi3EnterInitializationMode (tolerance undefined: RK4 has no error control; the start and
 * stop times), the inputs, fmi3ExitInitializationMode; Model Exchange: the event iteration
 * with fmi3UpdateDiscreteStates until no discrete state needs an update,
 * fmi3EnterContinuousTimeMode, the same RK4 loop over fmi3SetTime, fmi3SetFloat64,
 * fmi3SetContinuousStates, fmi3GetContinuousStateDerivatives, fmi3GetEventIndicators,
 * fmi3CompletedIntegratorStep, fmi3EnterEventMode; Co-Simulation: fmi3DoStep with its
 * out-arguments (the FMU asking for event handling, to terminate or returning early is an
 * error here: this host offers none of them; lastSuccessfulTime must be the step's end);
 * at the end fmi3Terminate and fmi3FreeInstance.
 */
#include <dlfcn.h>
#include <math.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

/* The FMI 2.0 ABI, as the FMUs' own native entry declares it (build/shim; the compiler is
 * given that folder). */
#include "lever_fmi2_abi.h"

typedef fmi2InstantiateTYPE *InstantiateT;
typedef fmi2FreeInstanceTYPE *FreeInstanceT;
typedef fmi2SetupExperimentTYPE *SetupExperimentT;
typedef fmi2EnterInitializationModeTYPE *ModeT;        /* every f(instance) of both versions */
typedef fmi2GetRealTYPE *GetRealT;
typedef fmi2SetRealTYPE *SetRealT;
typedef fmi2DoStepTYPE *DoStepT;

static void logger(void *env, fmi2String instance, fmi2Status status, fmi2String category,
                   fmi2String message, ...) {
    (void)env;
    va_list args;
    va_start(args, message);
    fprintf(stderr, "[%d] %s (%s): ", (int)status, instance, category);
    vfprintf(stderr, message, args);
    fputc('\n', stderr);
    va_end(args);
}

static GetRealT get_real;
static DoStepT do_step;

/* One communication step of every instance (run in the caller's or a thread of its own). */
typedef struct {
    fmi2Component *c;
    int n;
    double t, h;
    fmi2ValueReference vr;
    fmi2Real y[2];
    fmi2Status status;
} Step;

static void *step_all(void *arg) {
    Step *s = arg;
    s->status = fmi2OK;
    for (int i = 0; i < s->n && s->status <= fmi2Warning; i++) {
        s->status = do_step(s->c[i], s->t, s->h, 1);
        if (s->status <= fmi2Warning) {
            s->status = get_real(s->c[i], &s->vr, 1, &s->y[i]);
        }
    }
    return NULL;
}

static void *symbol(void *lib, const char *name) {
    void *f = dlsym(lib, name);
    if (!f) {
        fprintf(stderr, "minimal_importer: %s not found: %s\n", name, dlerror());
        exit(3);
    }
    return f;
}

#define CHECK(call)                                                                   \
    do {                                                                              \
        fmi2Status s_ = (call);                                                       \
        if (s_ > fmi2Warning) {                                                       \
            fprintf(stderr, "minimal_importer: %s returned status %d\n", #call, s_);  \
            fflush(stderr);                                                           \
            _exit(4); /* see the end of main */                                       \
        }                                                                             \
    } while (0)

/* ------------------------------------------------------------------------------------ */
/* Model Exchange                                                                        */
/* ------------------------------------------------------------------------------------ */

typedef fmi2SetIntegerTYPE *SetIntegerT;
typedef fmi2NewDiscreteStatesTYPE *NewDiscreteStatesT;
typedef fmi2CompletedIntegratorStepTYPE *CompletedIntegratorStepT;
typedef fmi2SetTimeTYPE *SetTimeT;
typedef fmi2SetContinuousStatesTYPE *SetStatesT;
typedef fmi2GetDerivativesTYPE *GetArrayT;              /* every f(instance, double[], n) of both versions */

/* FMI 3.0 (fmi3FunctionTypes.h): the functions whose signatures differ from FMI 2.0's; the
 * status enums agree from OK to Fatal, a value reference is a 32-bit unsigned int. */
typedef void (*Logger3T)(void *, int, const char *, const char *);
typedef void *(*InstantiateME3T)(const char *, const char *, const char *, bool, bool, void *, Logger3T);
typedef void *(*InstantiateCS3T)(const char *, const char *, const char *, bool, bool, bool, bool,
                                 const uint32_t[], size_t, void *, Logger3T, void *);
typedef fmi2Status (*EnterInit3T)(void *, bool, double, double, bool, double);
typedef fmi2Status (*GetFloat64T)(void *, const uint32_t[], size_t, double[], size_t);
typedef fmi2Status (*SetFloat64T)(void *, const uint32_t[], size_t, const double[], size_t);
typedef fmi2Status (*SetInt32T)(void *, const uint32_t[], size_t, const int32_t[], size_t);
typedef fmi2Status (*UpdateDiscreteStatesT)(void *, bool *, bool *, bool *, bool *, bool *, double *);
typedef fmi2Status (*CompletedIntegratorStep3T)(void *, bool, bool *, bool *);
typedef fmi2Status (*DoStep3T)(void *, double, double, bool, bool *, bool *, bool *, double *);

static void logger3(void *env, int status, const char *category, const char *message) {
    (void)env;
    fprintf(stderr, "[%d] (%s): %s\n", status, category ? category : "", message ? message : "");
}

/* The instance and what the loop needs of it. */
typedef struct {
    int v3; /* FMI 3.0 */
    fmi2Component c;
    SetFloat64T set_float64;
    UpdateDiscreteStatesT update_discrete_states;
    SetRealT set_real;
    SetTimeT set_time;
    SetStatesT set_states;
    GetArrayT get_derivatives, get_indicators, get_states;
    ModeT enter_event_mode, enter_continuous_time_mode;
    NewDiscreteStatesT new_discrete_states;
    size_t nx, nz, nu;
    fmi2ValueReference *u_vr;
    /* the inputs: rows of (time, u1..unu) */
    size_t rows;
    double *table;
    double *u; /* scratch: the inputs at a time */
    /* RK4 scratch */
    double *k1, *k2, *k3, *k4, *xs;
    long rk4_steps;
} Me;

static void die(const char *what) {
    fprintf(stderr, "minimal_importer: %s\n", what);
    fflush(stderr);
    _exit(4); /* see the end of main */
}

static void *alloc(size_t n) {
    void *p = calloc(n ? n : 1, sizeof(double));
    if (!p) die("out of memory");
    return p;
}

/* Reads the input CSV: a header, then numbers; exits on a malformed file. */
static void read_inputs(Me *m, const char *path) {
    FILE *f = fopen(path, "r");
    if (!f) die("cannot open the input CSV");
    char line[65536];
    if (!fgets(line, sizeof line, f)) die("the input CSV has no header");
    size_t capacity = 1024;
    m->table = malloc(capacity * (m->nu + 1) * sizeof(double));
    if (!m->table) die("out of memory");
    m->rows = 0;
    while (fgets(line, sizeof line, f)) {
        if (line[0] == '\n' || line[0] == '\0') continue;
        if (m->rows == capacity) {
            capacity *= 2;
            m->table = realloc(m->table, capacity * (m->nu + 1) * sizeof(double));
            if (!m->table) die("out of memory");
        }
        char *p = line;
        for (size_t j = 0; j <= m->nu; j++) {
            char *end;
            m->table[m->rows * (m->nu + 1) + j] = strtod(p, &end);
            if (end == p) die("the input CSV has a row with too few numbers");
            p = end;
            while (*p == ',' || *p == ' ') p++;
        }
        m->rows++;
    }
    fclose(f);
    if (m->nu > 0 && m->rows == 0) die("the input CSV has no rows");
}

#define ROW(m, i) ((m)->table + (size_t)(i) * ((m)->nu + 1))

/* The inputs at t, linear between rows; at a repeated time the left value (right = 0) or
 * the right one (right = 1); held beyond the first and last rows. */
static void inputs_at(Me *m, double t, int right) {
    if (m->nu == 0) return;
    size_t i = 0;
    if (right) {
        while (i + 1 < m->rows && ROW(m, i + 1)[0] <= t) i++;  /* the last row at or before t */
    } else {
        while (i + 1 < m->rows && ROW(m, i + 1)[0] < t) i++;   /* the last row before t */
    }
    const double *a = ROW(m, i);
    if (i + 1 >= m->rows || t <= a[0]) {
        memcpy(m->u, a + 1, m->nu * sizeof(double));
        return;
    }
    const double *b = ROW(m, i + 1);
    double s = b[0] > a[0] ? (t - a[0]) / (b[0] - a[0]) : 1.0;
    for (size_t j = 0; j < m->nu; j++) m->u[j] = a[j + 1] + s * (b[j + 1] - a[j + 1]);
}

/* The first input discontinuity (a repeated row) after t, or INFINITY-like 1e300. */
static double next_input_event(const Me *m, double t) {
    for (size_t i = 1; i < m->rows; i++) {
        if (ROW(m, i)[0] == ROW(m, i - 1)[0] && ROW(m, i)[0] > t) return ROW(m, i)[0];
    }
    return 1e300;
}

/* fmi2SetReal or fmi3SetFloat64 (every variable a scalar: as many values as references). */
static fmi2Status set_reals(Me *m, const fmi2ValueReference *vr, size_t n, const double *values) {
    return m->v3 ? m->set_float64(m->c, vr, n, values, n) : m->set_real(m->c, vr, n, values);
}

static void set_inputs(Me *m, double t, int right) {
    if (m->nu == 0) return;
    inputs_at(m, t, right);
    CHECK(set_reals(m, m->u_vr, m->nu, m->u));
}

/* dx/dt at (t, x) with the inputs of t: at a discontinuity the right values, or the left
 * ones (right = 0) where a step ends there. */
static void derivatives(Me *m, double t, const double *x, double *dx, int right) {
    CHECK(m->set_time(m->c, t));
    set_inputs(m, t, right);
    if (m->nx == 0) return;
    CHECK(m->set_states(m->c, x, m->nx));
    CHECK(m->get_derivatives(m->c, dx, m->nx));
}

/* One classical Runge-Kutta step of h from (t, x) into out. */
static void rk4(Me *m, double t, const double *x, double h, double *out) {
    size_t n = m->nx;
    m->rk4_steps++;
    derivatives(m, t, x, m->k1, 1);
    for (size_t i = 0; i < n; i++) m->xs[i] = x[i] + 0.5 * h * m->k1[i];
    derivatives(m, t + 0.5 * h, m->xs, m->k2, 1);
    for (size_t i = 0; i < n; i++) m->xs[i] = x[i] + 0.5 * h * m->k2[i];
    derivatives(m, t + 0.5 * h, m->xs, m->k3, 1);
    for (size_t i = 0; i < n; i++) m->xs[i] = x[i] + h * m->k3[i];
    derivatives(m, t + h, m->xs, m->k4, 0);
    for (size_t i = 0; i < n; i++) out[i] = x[i] + h / 6.0 * (m->k1[i] + 2.0 * m->k2[i] + 2.0 * m->k3[i] + m->k4[i]);
}

/* The instance at the end of a step, (t, x), with its event indicators in z. */
static void place(Me *m, double t, const double *x, double *z) {
    CHECK(m->set_time(m->c, t));
    set_inputs(m, t, 0);
    if (m->nx) CHECK(m->set_states(m->c, x, m->nx));
    if (m->nz) CHECK(m->get_indicators(m->c, z, m->nz));
}

/* An indicator crossed zero: from a nonzero sign to the other or to zero.  One that was
 * exactly zero (the point of an event just handled, or the start) takes its sign from the
 * next point, as CVODE's root finding does. */
static int crossed(const Me *m, const double *before, const double *after) {
    for (size_t i = 0; i < m->nz; i++) {
        if ((before[i] > 0.0 && after[i] <= 0.0) || (before[i] < 0.0 && after[i] >= 0.0)) return 1;
    }
    return 0;
}

/* The event iteration in event mode; the next time event in *next (1e300: none). */
static void event_iteration(Me *m, double *next) {
    fmi2EventInfo info;
    int rounds = 0;
    do {
        memset(&info, 0, sizeof info);
        if (m->v3) {
            bool update = false, end = false, nominals = false, values = false, defined = false;
            double when = 0.0;
            CHECK(m->update_discrete_states(m->c, &update, &end, &nominals, &values, &defined, &when));
            info.newDiscreteStatesNeeded = update, info.terminateSimulation = end;
            info.nominalsOfContinuousStatesChanged = nominals, info.valuesOfContinuousStatesChanged = values;
            info.nextEventTimeDefined = defined, info.nextEventTime = when;
        } else {
            CHECK(m->new_discrete_states(m->c, &info));
        }
        if (info.terminateSimulation) die("the FMU asked to terminate the simulation");
        if (++rounds > 1000) die("the event iteration did not converge in 1000 rounds");
    } while (info.newDiscreteStatesNeeded);
    *next = info.nextEventTimeDefined ? info.nextEventTime : 1e300;
}

/* An event at t: event mode, the inputs of t (right values), the iteration, continuous-time
 * mode; the states read anew, the indicators at the new point. */
static void handle_event(Me *m, double t, double *x, double *z, double *next) {
    CHECK(m->enter_event_mode(m->c));
    set_inputs(m, t, 1);
    event_iteration(m, next);
    CHECK(m->enter_continuous_time_mode(m->c));
    if (m->nx) CHECK(m->get_states(m->c, x, m->nx));
    if (m->nz) CHECK(m->get_indicators(m->c, z, m->nz));
}

/* The arguments both loops share: the input value references, the inputs' CSV, the outputs
 * ("name=VR"). */
typedef struct {
    char *names[256];
    fmi2ValueReference y_vr[256];
    size_t ny;
    double *y;
} Outputs;

static void parse_inputs(Me *m, char *vrs, const char *csv) {
    m->u_vr = calloc(64, sizeof *m->u_vr);
    if (!m->u_vr) die("out of memory");
    if (strcmp(vrs, "-") != 0) {
        for (char *p = vrs; *p && m->nu < 64;) {
            m->u_vr[m->nu++] = (fmi2ValueReference)strtoul(p, &p, 10);
            if (*p == ',') p++;
        }
    }
    read_inputs(m, csv);
    m->u = alloc(m->nu);
}

static void parse_outputs(Outputs *o, char *text) {
    o->ny = 0;
    for (char *p = text; *p && o->ny < 256;) {
        char *eq = strchr(p, '=');
        if (!eq) die("OUTPUTS: expected name=VR");
        *eq = '\0';
        o->names[o->ny] = p;
        o->y_vr[o->ny++] = (fmi2ValueReference)strtoul(eq + 1, &p, 10);
        if (*p == ',') p++;
    }
    o->y = alloc(o->ny);
}

/* What both loops call besides the Model Exchange functions. */
typedef struct {
    void *lib;
    FreeInstanceT free_instance;
    ModeT exit_init, terminate;
    GetRealT get_real;
    GetFloat64T get_float64;
    SetIntegerT set_integer;
    SetInt32T set_int32;
} Api;

static void *load(const char *dir, const char *model, int v3) {
    char path[4096];
    snprintf(path, sizeof path, "%s/binaries/%s/%s.so", dir, v3 ? "x86_64-linux" : "linux64", model);
    void *lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        fprintf(stderr, "minimal_importer: cannot load %s: %s\n", path, dlerror());
        exit(3);
    }
    return lib;
}

#define SYMBOL(m, name) symbol(lib, (m)->v3 ? "fmi3" name : "fmi2" name)

static void common_api(Me *m, Api *api, void *lib) {
    api->lib = lib;
    api->free_instance = (FreeInstanceT)SYMBOL(m, "FreeInstance");
    api->exit_init = (ModeT)SYMBOL(m, "ExitInitializationMode");
    api->terminate = (ModeT)SYMBOL(m, "Terminate");
    if (m->v3) {
        api->get_float64 = (GetFloat64T)symbol(lib, "fmi3GetFloat64");
        api->set_int32 = (SetInt32T)symbol(lib, "fmi3SetInt32");
        m->set_float64 = (SetFloat64T)symbol(lib, "fmi3SetFloat64");
    } else {
        api->get_real = (GetRealT)symbol(lib, "fmi2GetReal");
        api->set_integer = (SetIntegerT)symbol(lib, "fmi2SetInteger");
        m->set_real = (SetRealT)symbol(lib, "fmi2SetReal");
    }
}

static fmi2Status get_reals(const Me *m, const Api *api, Outputs *o) {
    return m->v3 ? api->get_float64(m->c, o->y_vr, o->ny, o->y, o->ny) : api->get_real(m->c, o->y_vr, o->ny, o->y);
}

/* "rVR=VALUE" (Real) or "iVR=VALUE" (Integer) start values, comma-separated ("-": none). */
static void set_start_values(Me *m, const Api *api, char *spec) {
    if (strcmp(spec, "-") == 0) return;
    for (char *p = spec; *p;) {
        char kind = *p++;
        fmi2ValueReference vr = (fmi2ValueReference)strtoul(p, &p, 10);
        if (*p++ != '=') die("START_VALUES: expected rVR=VALUE or iVR=VALUE");
        double value = strtod(p, &p);
        if (kind == 'r') {
            CHECK(set_reals(m, &vr, 1, &value));
        } else if (kind == 'i') {
            fmi2Integer i = (fmi2Integer)value;
            CHECK(m->v3 ? api->set_int32(m->c, &vr, 1, &i, 1) : api->set_integer(m->c, &vr, 1, &i));
        } else {
            die("START_VALUES: a value is r (Real) or i (Integer)");
        }
        if (*p == ',') p++;
    }
}

/* Instantiated (for Model Exchange or Co-Simulation), its start values set, in initialization
 * mode at `start` (stop time `stop`). */
static void instantiate_and_enter(Me *m, const Api *api, int me, const char *dir, const char *guid, char *start_values,
                                  double start, double stop) {
    void *lib = api->lib;
    if (m->v3) {
        char resources[4096];
        snprintf(resources, sizeof resources, "%s/resources/", dir);
        if (me) {
            m->c = ((InstantiateME3T)symbol(lib, "fmi3InstantiateModelExchange"))("me-host", guid, resources, false,
                                                                                  false, NULL, logger3);
        } else {
            m->c = ((InstantiateCS3T)symbol(lib, "fmi3InstantiateCoSimulation"))(
                "cs-host", guid, resources, false, false, false, false, NULL, 0, NULL, logger3, NULL);
        }
        if (!m->c) die(me ? "fmi3InstantiateModelExchange failed" : "fmi3InstantiateCoSimulation failed");
        set_start_values(m, api, start_values);
        CHECK(((EnterInit3T)symbol(lib, "fmi3EnterInitializationMode"))(m->c, false, 0.0, start, true, stop));
    } else {
        char uri[4096];
        snprintf(uri, sizeof uri, "file://%s/resources", dir);
        static fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
        m->c = ((InstantiateT)symbol(lib, "fmi2Instantiate"))(me ? "me-host" : "cs-host",
                                                             me ? fmi2ModelExchange : fmi2CoSimulation, guid, uri,
                                                             &callbacks, 0, 0);
        if (!m->c) die(me ? "fmi2Instantiate (fmi2ModelExchange) failed" : "fmi2Instantiate (fmi2CoSimulation) failed");
        CHECK(((SetupExperimentT)symbol(lib, "fmi2SetupExperiment"))(m->c, 0, 0.0, start, !me, stop));
        set_start_values(m, api, start_values);
        CHECK(((ModeT)symbol(lib, "fmi2EnterInitializationMode"))(m->c));
    }
}

static FILE *open_output(const char *path, const Outputs *o) {
    FILE *out = fopen(path, "w");
    if (!out) die("cannot write the output CSV");
    fprintf(out, "time");
    for (size_t j = 0; j < o->ny; j++) fprintf(out, ",%s", o->names[j]);
    fprintf(out, "\n");
    return out;
}

static void write_row(FILE *out, double t, const Outputs *o) {
    fprintf(out, "%.17g", t);
    for (size_t j = 0; j < o->ny; j++) fprintf(out, ",%.17g", o->y[j]);
    fprintf(out, "\n");
}

static double seconds_since(const struct timespec *began) {
    struct timespec now;
    clock_gettime(CLOCK_MONOTONIC, &now);
    return (double)(now.tv_sec - began->tv_sec) + 1e-9 * (now.tv_nsec - began->tv_nsec);
}

/* Co-Simulation driven by inputs (--cs, --cs3). */
static int cs_main(int argc, char **argv, int v3) {
    if (argc != 13) {
        fprintf(stderr, "usage: %s %s DIR MODEL GUID START STEP N_STEPS INPUT_CSV INPUT_VRS START_VALUES OUTPUTS "
                        "OUTPUT_CSV\n", argv[0], argv[1]);
        return 2;
    }
    const char *dir = argv[2], *model = argv[3], *guid = argv[4];
    Me m;
    memset(&m, 0, sizeof m);
    m.v3 = v3;
    double start = strtod(argv[5], NULL), h = strtod(argv[6], NULL);
    long n = strtol(argv[7], NULL, 10);
    if (!(h > 0.0) || n < 1) die("bad STEP or N_STEPS");
    parse_inputs(&m, argv[9], argv[8]);
    Outputs o;
    parse_outputs(&o, argv[11]);
    Api api;
    void *lib = load(dir, model, v3);
    common_api(&m, &api, lib);
    DoStepT step2 = v3 ? NULL : (DoStepT)symbol(lib, "fmi2DoStep");
    DoStep3T step3 = v3 ? (DoStep3T)symbol(lib, "fmi3DoStep") : NULL;

    instantiate_and_enter(&m, &api, 0, dir, guid, argv[10], start, start + (double)n * h);
    set_inputs(&m, start, 1);
    CHECK(api.exit_init(m.c));
    FILE *out = open_output(argv[12], &o);
    CHECK(get_reals(&m, &api, &o));
    write_row(out, start, &o);
    struct timespec began;
    clock_gettime(CLOCK_MONOTONIC, &began);
    for (long k = 0; k < n; k++) {
        double t = start + (double)k * h, t_next = start + (double)(k + 1) * h;
        set_inputs(&m, t, 1);
        if (v3) {
            bool event = true, end = true, early = true;
            double reached = -1.0;
            CHECK(step3(m.c, t, t_next - t, true, &event, &end, &early, &reached));
            if (event || end || early) die("fmi3DoStep asked for event handling, to terminate or returned early");
            if (reached != t_next) die("fmi3DoStep's lastSuccessfulTime is not the step's end");
        } else {
            CHECK(step2(m.c, t, t_next - t, 1));
        }
        CHECK(get_reals(&m, &api, &o));
        write_row(out, t_next, &o);
    }
    double loop = seconds_since(&began);
    fclose(out);
    CHECK(api.terminate(m.c));
    api.free_instance(m.c);
    fprintf(stderr, "cs: steps=%ld loop_s=%.6f\n", n, loop);
    printf("freed\n");
    fflush(stdout);
    fflush(stderr);
    _exit(0); /* see the end of main */
}

static int me_main(int argc, char **argv, int v3) {
    if (argc != 16) {
        fprintf(stderr, "usage: %s %s DIR MODEL GUID NX NZ START OUTPUT_STEP N_OUTPUT SUBSTEPS INPUT_CSV "
                        "INPUT_VRS START_VALUES OUTPUTS OUTPUT_CSV\n", argv[0], argv[1]);
        return 2;
    }
    const char *dir = argv[2], *guid = argv[4];
    Me m;
    memset(&m, 0, sizeof m);
    m.v3 = v3;
    m.nx = (size_t)strtoul(argv[5], NULL, 10);
    m.nz = (size_t)strtoul(argv[6], NULL, 10);
    double start = strtod(argv[7], NULL), output_step = strtod(argv[8], NULL);
    long n_output = strtol(argv[9], NULL, 10), substeps = strtol(argv[10], NULL, 10);
    if (!(output_step > 0.0) || n_output < 1 || substeps < 1) die("bad OUTPUT_STEP, N_OUTPUT or SUBSTEPS");
    parse_inputs(&m, argv[12], argv[11]);
    Outputs o;
    parse_outputs(&o, argv[14]);

    Api api;
    void *lib = load(dir, argv[3], v3);
    common_api(&m, &api, lib);
    m.set_time = (SetTimeT)SYMBOL(&m, "SetTime");
    m.set_states = (SetStatesT)SYMBOL(&m, "SetContinuousStates");
    m.get_derivatives = (GetArrayT)symbol(lib, v3 ? "fmi3GetContinuousStateDerivatives" : "fmi2GetDerivatives");
    m.get_indicators = (GetArrayT)SYMBOL(&m, "GetEventIndicators");
    m.get_states = (GetArrayT)SYMBOL(&m, "GetContinuousStates");
    m.enter_event_mode = (ModeT)SYMBOL(&m, "EnterEventMode");
    m.enter_continuous_time_mode = (ModeT)SYMBOL(&m, "EnterContinuousTimeMode");
    CompletedIntegratorStepT completed = NULL;
    CompletedIntegratorStep3T completed3 = NULL;
    if (v3) {
        m.update_discrete_states = (UpdateDiscreteStatesT)symbol(lib, "fmi3UpdateDiscreteStates");
        completed3 = (CompletedIntegratorStep3T)symbol(lib, "fmi3CompletedIntegratorStep");
    } else {
        m.new_discrete_states = (NewDiscreteStatesT)symbol(lib, "fmi2NewDiscreteStates");
        completed = (CompletedIntegratorStepT)symbol(lib, "fmi2CompletedIntegratorStep");
    }
    instantiate_and_enter(&m, &api, 1, dir, guid, argv[13], start, start + (double)n_output * output_step);
    set_inputs(&m, start, 1);
    CHECK(api.exit_init(m.c));
    double next_time_event;
    event_iteration(&m, &next_time_event);
    CHECK(m.enter_continuous_time_mode(m.c));

    double *x = alloc(m.nx), *x_new = alloc(m.nx), *z = alloc(m.nz), *z_new = alloc(m.nz), *x0 = alloc(m.nx);
    m.k1 = alloc(m.nx), m.k2 = alloc(m.nx), m.k3 = alloc(m.nx), m.k4 = alloc(m.nx), m.xs = alloc(m.nx);
    if (m.nx) CHECK(m.get_states(m.c, x, m.nx));
    if (m.nz) CHECK(m.get_indicators(m.c, z, m.nz));

    FILE *out = open_output(argv[15], &o);
    long state_events = 0, time_events = 0, input_events = 0, step_events = 0;

    struct timespec began, ended;
    clock_gettime(CLOCK_MONOTONIC, &began);
    double t = start;
    for (long k = 0; k <= n_output; k++) {
        double target = start + (double)k * output_step;
        double h_max = output_step / (double)substeps;
        /* integrate to the output point, stopping at every event on the way */
        while (t < target) {
            double h = target - t < h_max * (1.0 + 1e-9) ? target - t : h_max;
            double input_event = next_input_event(&m, t);
            int stop_at = 0; /* 1: an input event ends this step, 2: a time event */
            if (input_event <= t + h) {
                h = input_event - t;
                stop_at = 1;
            }
            if (next_time_event <= t + h) {
                h = next_time_event - t;
                stop_at = 2;
            }
            rk4(&m, t, x, h, x_new);
            place(&m, t + h, x_new, z_new);
            double t_new = t + h;
            if (m.nz && crossed(&m, z, z_new)) {
                /* bisection: the shortest step after which an indicator has crossed */
                double low = 0.0, high = h;
                memcpy(x0, x, m.nx * sizeof *x);
                while (high - low > 1e-12 * (1.0 + fabs(t))) {
                    double mid = 0.5 * (low + high);
                    rk4(&m, t, x0, mid, x_new);
                    place(&m, t + mid, x_new, z_new);
                    if (crossed(&m, z, z_new)) high = mid;
                    else low = mid;
                }
                rk4(&m, t, x0, high, x_new);
                place(&m, t + high, x_new, z_new);
                t_new = t + high;
                stop_at = 3;
            }
            t = t_new;
            if (t > target - 1e-9 * output_step && stop_at != 3) t = target; /* no sliver left */
            fmi2Boolean step_event = 0, stop = 0;
            if (v3) {
                bool enter_event = false, end = false;
                CHECK(completed3(m.c, true, &enter_event, &end));
                step_event = enter_event, stop = end;
            } else {
                CHECK(completed(m.c, 1, &step_event, &stop));
            }
            if (stop) die("the FMU asked to terminate the simulation");
            memcpy(x, x_new, m.nx * sizeof *x);
            memcpy(z, z_new, m.nz * sizeof *z);
            if (stop_at || step_event) {
                state_events += stop_at == 3;
                time_events += stop_at == 2;
                input_events += stop_at == 1;
                step_events += step_event && !stop_at;
                handle_event(&m, t, x, z, &next_time_event);
            }
        }
        /* the output point: its inputs (right values) set, then the outputs read */
        CHECK(m.set_time(m.c, t));
        set_inputs(&m, t, 1);
        if (m.nx) CHECK(m.set_states(m.c, x, m.nx));
        CHECK(get_reals(&m, &api, &o));
        write_row(out, t, &o);
    }
    clock_gettime(CLOCK_MONOTONIC, &ended);
    fclose(out);
    CHECK(api.terminate(m.c));
    api.free_instance(m.c);
    fprintf(stderr, "me: rk4_steps=%ld state_events=%ld time_events=%ld input_events=%ld step_events=%ld "
                    "loop_s=%.6f\n", m.rk4_steps, state_events, time_events, input_events, step_events,
            (double)(ended.tv_sec - began.tv_sec) + 1e-9 * (ended.tv_nsec - began.tv_nsec));
    printf("freed\n");
    fflush(stdout);
    fflush(stderr);
    _exit(0); /* see the end of main */
}

int main(int argc, char **argv) {
    if (argc > 1 && (strcmp(argv[1], "--me") == 0 || strcmp(argv[1], "--me3") == 0)) {
        return me_main(argc, argv, strcmp(argv[1], "--me3") == 0);
    }
    if (argc > 1 && (strcmp(argv[1], "--cs") == 0 || strcmp(argv[1], "--cs3") == 0)) {
        return cs_main(argc, argv, strcmp(argv[1], "--cs3") == 0);
    }
    if (argc != 9) {
        fprintf(stderr, "usage: %s DIR MODEL_IDENTIFIER GUID INPUT_VR INPUT_VALUE OUTPUT_VR STEP N\n",
                argv[0]);
        return 2;
    }
    const char *dir = argv[1], *model = argv[2], *guid = argv[3];
    int set_input = strcmp(argv[4], "-") != 0;
    fmi2ValueReference in_vr = (fmi2ValueReference)strtoul(argv[4], NULL, 10);
    fmi2Real in_value = strtod(argv[5], NULL);
    fmi2ValueReference out_vr = (fmi2ValueReference)strtoul(argv[6], NULL, 10);
    fmi2Real h = strtod(argv[7], NULL);
    long n = strtol(argv[8], NULL, 10);

    char path[4096], uri[4096];
    snprintf(path, sizeof path, "%s/binaries/linux64/%s.so", dir, model);
    const char *given_uri = getenv("RESOURCE_URI");
    snprintf(uri, sizeof uri, "%s", given_uri ? given_uri : "");
    if (!given_uri) {
        snprintf(uri, sizeof uri, "file://%s/resources", dir);
    }
    void *lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        fprintf(stderr, "minimal_importer: cannot load %s: %s\n", path, dlerror());
        return 3;
    }
    InstantiateT instantiate = (InstantiateT)symbol(lib, "fmi2Instantiate");
    FreeInstanceT free_instance = (FreeInstanceT)symbol(lib, "fmi2FreeInstance");
    SetupExperimentT setup = (SetupExperimentT)symbol(lib, "fmi2SetupExperiment");
    ModeT enter = (ModeT)symbol(lib, "fmi2EnterInitializationMode");
    ModeT exit_init = (ModeT)symbol(lib, "fmi2ExitInitializationMode");
    ModeT terminate = (ModeT)symbol(lib, "fmi2Terminate");
    get_real = (GetRealT)symbol(lib, "fmi2GetReal");
    SetRealT set_real = (SetRealT)symbol(lib, "fmi2SetReal");
    do_step = (DoStepT)symbol(lib, "fmi2DoStep");
    const char *instances_setting = getenv("INSTANCES");
    int instances = instances_setting && strcmp(instances_setting, "2") == 0 ? 2 : 1;
    int step_threads = getenv("STEP_THREADS") != NULL;

    fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
    fmi2Component cs[2];
    for (int i = 0; i < instances; i++) {
        fmi2Component c = cs[i] = instantiate(i ? "host2" : "host", fmi2CoSimulation, guid, uri, &callbacks, 0, 0);
        if (!c) {
            fprintf(stderr, "minimal_importer: fmi2Instantiate failed\n");
            fflush(stderr);
            _exit(5); /* see the end of main */
        }
        CHECK(setup(c, 0, 0.0, 0.0, 0, 0.0));
        CHECK(enter(c));
        if (set_input) {
            CHECK(set_real(c, &in_vr, 1, &in_value));
        }
        CHECK(exit_init(c));
    }
    struct timespec began, ended;
    clock_gettime(CLOCK_MONOTONIC, &began);
    for (long k = 0; k < n; ++k) {
        Step step = {cs, instances, k * h, h, out_vr, {0, 0}, fmi2OK};
        if (step_threads) {
            pthread_t thread;
            if (pthread_create(&thread, NULL, step_all, &step) != 0 || pthread_join(thread, NULL) != 0) {
                fprintf(stderr, "minimal_importer: cannot run a step thread\n");
                _exit(3);
            }
        } else {
            step_all(&step);
        }
        CHECK(step.status);
        if (instances == 2 && step.y[0] != step.y[1]) {
            fprintf(stderr, "minimal_importer: the instances differ at step %ld\n", k);
            _exit(6);
        }
        printf("t=%.17g y=%.17g\n", (k + 1) * h, step.y[0]);
    }
    clock_gettime(CLOCK_MONOTONIC, &ended);
    fprintf(stderr, "loop_s=%.6f\n", (double)(ended.tv_sec - began.tv_sec) + 1e-9 * (ended.tv_nsec - began.tv_nsec));
    for (int i = 0; i < instances; i++) {
        CHECK(terminate(cs[i]));
        free_instance(cs[i]);
    }
    printf("freed\n");
    /* Leave without running the libraries' exit-time destructors: pythonfmu 0.7
     * finalises its embedded interpreter in a static destructor, which corrupts the
     * heap at process exit (seen with numpy loaded: "free(): corrupted unsorted
     * chunks").  Our Python tools leave the same way (harness/cli/, tests/conftest.py).
     * The library is not unloaded either: an embedded interpreter cannot be. */
    fflush(stdout);
    fflush(stderr);
    _exit(0);
}
