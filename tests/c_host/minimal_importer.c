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
 */
#include <dlfcn.h>
#include <math.h>
#include <pthread.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

typedef void *fmi2Component;
typedef unsigned int fmi2ValueReference;
typedef double fmi2Real;
typedef int fmi2Boolean;
typedef const char *fmi2String;
typedef enum { fmi2OK, fmi2Warning, fmi2Discard, fmi2Error, fmi2Fatal, fmi2Pending } fmi2Status;
typedef enum { fmi2ModelExchange, fmi2CoSimulation } fmi2Type;
typedef struct {
    void (*logger)(void *, fmi2String, fmi2Status, fmi2String, fmi2String, ...);
    void *(*allocateMemory)(size_t, size_t);
    void (*freeMemory)(void *);
    void (*stepFinished)(void *, fmi2Status);
    void *componentEnvironment;
} fmi2CallbackFunctions;

typedef fmi2Component (*InstantiateT)(fmi2String, fmi2Type, fmi2String, fmi2String,
                                      const fmi2CallbackFunctions *, fmi2Boolean, fmi2Boolean);
typedef void (*FreeInstanceT)(fmi2Component);
typedef fmi2Status (*SetupExperimentT)(fmi2Component, fmi2Boolean, fmi2Real, fmi2Real, fmi2Boolean,
                                       fmi2Real);
typedef fmi2Status (*ModeT)(fmi2Component);
typedef fmi2Status (*GetRealT)(fmi2Component, const fmi2ValueReference[], size_t, fmi2Real[]);
typedef fmi2Status (*SetRealT)(fmi2Component, const fmi2ValueReference[], size_t, const fmi2Real[]);
typedef fmi2Status (*DoStepT)(fmi2Component, fmi2Real, fmi2Real, fmi2Boolean);

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

typedef int fmi2Integer;
typedef struct {
    fmi2Boolean newDiscreteStatesNeeded;
    fmi2Boolean terminateSimulation;
    fmi2Boolean nominalsOfContinuousStatesChanged;
    fmi2Boolean valuesOfContinuousStatesChanged;
    fmi2Boolean nextEventTimeDefined;
    fmi2Real nextEventTime;
} fmi2EventInfo;
typedef fmi2Status (*SetIntegerT)(fmi2Component, const fmi2ValueReference[], size_t, const fmi2Integer[]);
typedef fmi2Status (*NewDiscreteStatesT)(fmi2Component, fmi2EventInfo *);
typedef fmi2Status (*CompletedIntegratorStepT)(fmi2Component, fmi2Boolean, fmi2Boolean *, fmi2Boolean *);
typedef fmi2Status (*SetTimeT)(fmi2Component, fmi2Real);
typedef fmi2Status (*SetStatesT)(fmi2Component, const fmi2Real[], size_t);
typedef fmi2Status (*GetArrayT)(fmi2Component, fmi2Real[], size_t);

/* The instance and what the loop needs of it. */
typedef struct {
    fmi2Component c;
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

static void set_inputs(Me *m, double t, int right) {
    if (m->nu == 0) return;
    inputs_at(m, t, right);
    CHECK(m->set_real(m->c, m->u_vr, m->nu, m->u));
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
        CHECK(m->new_discrete_states(m->c, &info));
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

static int me_main(int argc, char **argv) {
    if (argc != 16) {
        fprintf(stderr, "usage: %s --me DIR MODEL GUID NX NZ START OUTPUT_STEP N_OUTPUT SUBSTEPS INPUT_CSV "
                        "INPUT_VRS START_VALUES OUTPUTS OUTPUT_CSV\n", argv[0]);
        return 2;
    }
    const char *dir = argv[2], *model = argv[3], *guid = argv[4];
    Me m;
    memset(&m, 0, sizeof m);
    m.nx = (size_t)strtoul(argv[5], NULL, 10);
    m.nz = (size_t)strtoul(argv[6], NULL, 10);
    double start = strtod(argv[7], NULL), output_step = strtod(argv[8], NULL);
    long n_output = strtol(argv[9], NULL, 10), substeps = strtol(argv[10], NULL, 10);
    if (!(output_step > 0.0) || n_output < 1 || substeps < 1) die("bad OUTPUT_STEP, N_OUTPUT or SUBSTEPS");

    /* the input value references */
    m.u_vr = calloc(64, sizeof *m.u_vr);
    if (!m.u_vr) die("out of memory");
    if (strcmp(argv[12], "-") != 0) {
        for (char *p = argv[12]; *p && m.nu < 64;) {
            m.u_vr[m.nu++] = (fmi2ValueReference)strtoul(p, &p, 10);
            if (*p == ',') p++;
        }
    }
    /* the outputs: name=vr */
    char *names[256];
    fmi2ValueReference y_vr[256];
    size_t ny = 0;
    for (char *p = argv[14]; *p && ny < 256;) {
        char *eq = strchr(p, '=');
        if (!eq) die("OUTPUTS: expected name=VR");
        *eq = '\0';
        names[ny] = p;
        y_vr[ny++] = (fmi2ValueReference)strtoul(eq + 1, &p, 10);
        if (*p == ',') p++;
    }
    read_inputs(&m, argv[11]);
    m.u = alloc(m.nu);

    char path[4096], uri[4096];
    snprintf(path, sizeof path, "%s/binaries/linux64/%s.so", dir, model);
    snprintf(uri, sizeof uri, "file://%s/resources", dir);
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
    GetRealT get = (GetRealT)symbol(lib, "fmi2GetReal");
    SetIntegerT set_integer = (SetIntegerT)symbol(lib, "fmi2SetInteger");
    CompletedIntegratorStepT completed = (CompletedIntegratorStepT)symbol(lib, "fmi2CompletedIntegratorStep");
    m.set_real = (SetRealT)symbol(lib, "fmi2SetReal");
    m.set_time = (SetTimeT)symbol(lib, "fmi2SetTime");
    m.set_states = (SetStatesT)symbol(lib, "fmi2SetContinuousStates");
    m.get_derivatives = (GetArrayT)symbol(lib, "fmi2GetDerivatives");
    m.get_indicators = (GetArrayT)symbol(lib, "fmi2GetEventIndicators");
    m.get_states = (GetArrayT)symbol(lib, "fmi2GetContinuousStates");
    m.enter_event_mode = (ModeT)symbol(lib, "fmi2EnterEventMode");
    m.enter_continuous_time_mode = (ModeT)symbol(lib, "fmi2EnterContinuousTimeMode");
    m.new_discrete_states = (NewDiscreteStatesT)symbol(lib, "fmi2NewDiscreteStates");

    fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
    m.c = instantiate("me-host", fmi2ModelExchange, guid, uri, &callbacks, 0, 0);
    if (!m.c) die("fmi2Instantiate (fmi2ModelExchange) failed");
    CHECK(setup(m.c, 0, 0.0, start, 0, 0.0));
    if (strcmp(argv[13], "-") != 0) {
        for (char *p = argv[13]; *p;) {
            char kind = *p++;
            fmi2ValueReference vr = (fmi2ValueReference)strtoul(p, &p, 10);
            if (*p++ != '=') die("START_VALUES: expected rVR=VALUE or iVR=VALUE");
            double value = strtod(p, &p);
            if (kind == 'r') {
                CHECK(m.set_real(m.c, &vr, 1, &value));
            } else if (kind == 'i') {
                fmi2Integer i = (fmi2Integer)value;
                CHECK(set_integer(m.c, &vr, 1, &i));
            } else {
                die("START_VALUES: a value is r (Real) or i (Integer)");
            }
            if (*p == ',') p++;
        }
    }
    CHECK(enter(m.c));
    set_inputs(&m, start, 1);
    CHECK(exit_init(m.c));
    double next_time_event;
    event_iteration(&m, &next_time_event);
    CHECK(m.enter_continuous_time_mode(m.c));

    double *x = alloc(m.nx), *x_new = alloc(m.nx), *z = alloc(m.nz), *z_new = alloc(m.nz), *x0 = alloc(m.nx);
    m.k1 = alloc(m.nx), m.k2 = alloc(m.nx), m.k3 = alloc(m.nx), m.k4 = alloc(m.nx), m.xs = alloc(m.nx);
    if (m.nx) CHECK(m.get_states(m.c, x, m.nx));
    if (m.nz) CHECK(m.get_indicators(m.c, z, m.nz));

    FILE *out = fopen(argv[15], "w");
    if (!out) die("cannot write the output CSV");
    fprintf(out, "time");
    for (size_t j = 0; j < ny; j++) fprintf(out, ",%s", names[j]);
    fprintf(out, "\n");
    fmi2Real *y = (fmi2Real *)alloc(ny);
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
            CHECK(completed(m.c, 1, &step_event, &stop));
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
        CHECK(get(m.c, y_vr, ny, y));
        fprintf(out, "%.17g", t);
        for (size_t j = 0; j < ny; j++) fprintf(out, ",%.17g", y[j]);
        fprintf(out, "\n");
    }
    clock_gettime(CLOCK_MONOTONIC, &ended);
    fclose(out);
    CHECK(terminate(m.c));
    free_instance(m.c);
    fprintf(stderr, "me: rk4_steps=%ld state_events=%ld time_events=%ld input_events=%ld step_events=%ld "
                    "loop_s=%.6f\n", m.rk4_steps, state_events, time_events, input_events, step_events,
            (double)(ended.tv_sec - began.tv_sec) + 1e-9 * (ended.tv_nsec - began.tv_nsec));
    printf("freed\n");
    fflush(stdout);
    fflush(stderr);
    _exit(0); /* see the end of main */
}

int main(int argc, char **argv) {
    if (argc > 1 && strcmp(argv[1], "--me") == 0) {
        return me_main(argc, argv);
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
