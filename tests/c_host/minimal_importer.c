/*
 * minimal_importer.c -- a host that is not a Python process: it loads an FMI 2.0
 * co-simulation FMU's binary with dlopen, instantiates it, sets one real input,
 * steps, reads one real output and frees the instance.  Used by the tests to check
 * the host set-up the README documents for pythonfmu FMUs (libpython loaded into
 * the host, PYTHONHOME and PYTHONPATH naming an interpreter with the FMU's
 * requirements).
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
 */
#include <dlfcn.h>
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

int main(int argc, char **argv) {
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
