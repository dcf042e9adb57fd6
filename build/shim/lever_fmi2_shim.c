/*
 * lever_fmi2_shim.c -- the native entry of our FMI 2.0 Co-Simulation FMUs, in front of
 * pythonfmu 0.7.0's export library (shipped next to this file as "pythonfmu-export.so").
 *
 * What it adds, so that the FMUs are usable guests of any FMI 2.0 host:
 *   1. It finds a Python itself (python_ready): the host's own interpreter if the host
 *      already runs one, else a CPython shared library loaded RTLD_GLOBAL (pythonfmu's
 *      library resolves its Python symbols against it) from, in this order:
 *        LEVER_FMU_LIBPYTHON (a path to libpython3.X.so; LEVER_FMU_PYTHONHOME optional),
 *        the interpreter the FMU was built with (resources/lever_shim.cfg) if present,
 *        `python3` on PATH, asked for its library and prefix.
 *      It sets the Python home to match the library (a PYTHONHOME of another Python in the
 *      environment would make Py_Initialize abort the host), initialises the interpreter
 *      once and never finalises it.  Nothing usable: fmi2Instantiate returns NULL and logs
 *      what it tried and how to fix it.
 *   2. The resource location is any RFC 8089 file URI (file:///p, file:/p,
 *      file://localhost/p, percent-encoded), checked and turned into a plain path before
 *      pythonfmu sees it; anything else is refused with a message.
 *   3. The FMI 2.0 Co-Simulation state machine (the standard's table of which function may
 *      be called in which state): calls in the wrong state get fmi2Error and reach nothing.
 *      A GUID other than the one the FMU was built with is refused.  The shim keeps the
 *      communication time, wraps FMU states (and their serialized bytes, in a header it
 *      validates before anything is forwarded) with the time and state they were taken
 *      in, so fmi2GetRealStatus(fmi2LastSuccessfulTime) is true after refusals and
 *      restores.  Strings that are not UTF-8 and too small buffers get fmi2Error.
 *      A refused call (fmi2Error) changes nothing: the instance stays in its state.
 *   3a. FMI 2.0 Model Exchange, which pythonfmu does not export: the ME functions and the
 *      ME state machine (instantiated, initialization, event mode, continuous-time mode,
 *      terminated) are implemented here, and fmi2GetDirectionalDerivative in both
 *      interfaces.  The model is reached through pythonfmu's fmi2GetReal/fmi2SetReal on
 *      value references of the shim's own "channel" (CHANNEL and above; see
 *      fmu_src/lever/fmus/me_channel.py), which a host's calls may not use.  One
 *      function that is not FMI 2.0's, leverGetEventIndicatorValues, gives the FMI 3.0 entry
 *      (lever_fmi3_shim.c) the event indicators in Co-Simulation too.
 *   4. One Python thread state per host thread: pythonfmu calls PyGILState_Ensure and
 *      Release around every call, which creates and destroys a thread state each time when
 *      the calling thread is unknown to Python.  The shim registers one thread state for
 *      such a thread on its first call and keeps it (released when the last instance is
 *      freed on that thread, or when the thread ends); threads Python knows are left alone.
 *   5. pythonfmu's own defects: the only non-OK status a Python slave can produce is an
 *      exception, which becomes fmi2Fatal *and* frees the Python instance while keeping a
 *      dangling pointer; with loggingOn=fmi2False it drops every message, errors included;
 *      do_step() returning False is reported as fmi2Discard.  Our Python slaves therefore
 *      never raise; they call self.log(msg, error) and return normally.  The shim turns the
 *      most severe status logged during a call into that call's return status, always
 *      delivers warnings and errors to the importer, and quarantines an instance after a
 *      fatal error.
 *
 * Build (build/shim/compile.py): cc -shared -fPIC -O2 -std=c99 -fvisibility=hidden
 *        -Wall -Wextra -Werror -Wl,-z,nodelete -o <modelIdentifier>.so lever_fmi2_shim.c
 *        -ldl -lpthread
 */
#define _GNU_SOURCE /* dladdr, RTLD_DEFAULT */

#include <dlfcn.h>
#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <math.h>
#include <pthread.h>
#include <spawn.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>
#include <wchar.h>

extern char **environ;

/* The FMI 2.0 declarations (fmi2TypesPlatform.h, fmi2FunctionTypes.h), shared with the FMI 3.0
 * entry and the C importer. */
#include "lever_fmi2_abi.h"

/* Every function the inner library must provide (all of them are exported by
 * pythonfmu 0.7.0).  fmi2GetTypesPlatform/fmi2GetVersion are answered by the
 * shim itself and are not needed from the inner library; the Model Exchange functions
 * (LEVER_FMI2_ME_FUNCTIONS), which pythonfmu lacks, are the shim's own. */
#define SHIM_INNER_FUNCTIONS(X)                                                                    \
    X(fmi2Instantiate)                                                                             \
    X(fmi2FreeInstance)                                                                            \
    LEVER_FMI2_SETUP_VALUES_AND_STATES(X)                                                          \
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
LEVER_FMI2_ME_FUNCTIONS(SHIM_DECLARE)

/* Not an FMI 2.0 function (lever_fmi2_abi.h): the event indicators for the FMI 3.0 entry. */
SHIM_DECLARE(leverGetEventIndicatorValues)

/* ------------------------------------------------------------------------- */
/* Small helpers                                                             */
/* ------------------------------------------------------------------------- */

#define INNER_LIBRARY_NAME "pythonfmu-export.so"
#define CONFIG_NAME "lever_shim.cfg" /* in resources/, written by compile.py */
#define SHIM_CATEGORY "logStatusError"
#define MAX_PYTHON_PATHS 8

/* Appends printf-formatted text to a bounded buffer (truncating, never overflowing). */
static void appendf(char *buf, size_t size, const char *fmt, ...) __attribute__((format(printf, 3, 4)));
static void appendf(char *buf, size_t size, const char *fmt, ...)
{
    size_t used = strlen(buf);
    if (used + 1 >= size) {
        return;
    }
    va_list args;
    va_start(args, fmt);
    vsnprintf(buf + used, size - used, fmt, args);
    va_end(args);
}

static char *copy_string(const char *text)
{
    size_t n = strlen(text) + 1;
    char *copy = malloc(n);
    if (copy) {
        memcpy(copy, text, n);
    }
    return copy;
}

static int is_file(const char *path)
{
    struct stat st;
    return stat(path, &st) == 0 && S_ISREG(st.st_mode);
}

static int is_directory(const char *path)
{
    struct stat st;
    return stat(path, &st) == 0 && S_ISDIR(st.st_mode);
}

/* The directory part of path (without the final '/'), in out (which may be path). */
static void dirname_of(const char *path, char *out, size_t size)
{
    if (out != path) {
        snprintf(out, size, "%s", path);
    }
    char *slash = strrchr(out, '/');
    if (slash && slash != out) {
        *slash = '\0';
    } else if (slash) {
        out[1] = '\0';
    }
}

/* ------------------------------------------------------------------------- */
/* Configuration: resources/lever_shim.cfg, and `python3 -c` answers          */
/* (lines "key=value"; '#' starts a comment line)                             */
/* ------------------------------------------------------------------------- */

typedef struct {
    char guid[256];
    char library[PATH_MAX];            /* python_library */
    char home[PATH_MAX];               /* python_home */
    char paths[MAX_PYTHON_PATHS][PATH_MAX]; /* python_path: added with site.addsitedir */
    int nPaths;
    int channel;                       /* channel=1: the model answers the channel (ours do) */
} Config;

static void config_line(Config *cfg, char *line)
{
    size_t n = strlen(line);
    while (n > 0 && (line[n - 1] == '\n' || line[n - 1] == '\r')) {
        line[--n] = '\0';
    }
    char *eq = strchr(line, '=');
    if (line[0] == '#' || !eq) {
        return;
    }
    *eq = '\0';
    const char *key = line, *value = eq + 1;
    if (strcmp(key, "guid") == 0) {
        snprintf(cfg->guid, sizeof cfg->guid, "%s", value);
    } else if (strcmp(key, "python_library") == 0) {
        snprintf(cfg->library, sizeof cfg->library, "%s", value);
    } else if (strcmp(key, "python_home") == 0) {
        snprintf(cfg->home, sizeof cfg->home, "%s", value);
    } else if (strcmp(key, "python_path") == 0 && cfg->nPaths < MAX_PYTHON_PATHS) {
        snprintf(cfg->paths[cfg->nPaths++], PATH_MAX, "%s", value);
    } else if (strcmp(key, "channel") == 0) {
        cfg->channel = strcmp(value, "1") == 0;
    }
}

static void config_read(Config *cfg, FILE *f)
{
    char line[PATH_MAX + 64];
    while (fgets(line, sizeof line, f)) {
        config_line(cfg, line);
    }
}

/* Asks `python3` on PATH (isolated from PYTHON* variables) for its shared library, its
 * prefix and, in a virtual environment, its site-packages.  0 on success. */
static const char PYTHON_QUERY[] =
    "import os, site, sys, sysconfig\n"
    "d = sysconfig.get_config_var('LIBDIR') or ''\n"
    "for n in (sysconfig.get_config_var('INSTSONAME'), sysconfig.get_config_var('LDLIBRARY')):\n"
    "    if n and '.so' in n and os.path.exists(os.path.join(d, n)):\n"
    "        print('python_library=' + os.path.join(d, n))\n"
    "        break\n"
    "print('python_home=' + sys.base_prefix)\n"
    "if sys.prefix != sys.base_prefix:\n"
    "    for p in site.getsitepackages():\n"
    "        print('python_path=' + p)\n";

static int query_python_on_path(Config *cfg, char *why, size_t whysize)
{
    int out[2];
    if (pipe(out) != 0) {
        snprintf(why, whysize, "pipe: %s", strerror(errno));
        return -1;
    }
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_adddup2(&actions, out[1], 1);
    posix_spawn_file_actions_addclose(&actions, out[0]);
    posix_spawn_file_actions_addclose(&actions, out[1]);
    posix_spawn_file_actions_addopen(&actions, 2, "/dev/null", O_WRONLY, 0);
    char *argv[] = {"python3", "-I", "-c", (char *)PYTHON_QUERY, NULL};
    pid_t pid;
    int rc = posix_spawnp(&pid, "python3", &actions, NULL, argv, environ);
    posix_spawn_file_actions_destroy(&actions);
    close(out[1]);
    if (rc != 0) {
        close(out[0]);
        snprintf(why, whysize, "no python3 on PATH (%s)", strerror(rc));
        return -1;
    }
    FILE *f = fdopen(out[0], "r");
    if (!f) {
        close(out[0]);
        waitpid(pid, NULL, 0);
        snprintf(why, whysize, "fdopen: %s", strerror(errno));
        return -1;
    }
    config_read(cfg, f);
    fclose(f);
    int status = 0;
    if (waitpid(pid, &status, 0) == pid && !(WIFEXITED(status) && WEXITSTATUS(status) == 0)) {
        snprintf(why, whysize, "python3 on PATH failed to answer");
        return -1;
    }
    if (!cfg->library[0]) {
        snprintf(why, whysize, "python3 on PATH (prefix %s) has no shared libpython",
                 cfg->home[0] ? cfg->home : "?");
        return -1;
    }
    return 0;
}

/* ------------------------------------------------------------------------- */
/* Python                                                                     */
/* ------------------------------------------------------------------------- */

typedef enum { PyGILState_LOCKED, PyGILState_UNLOCKED } PyGILState_STATE;

/* The few CPython functions the shim calls, resolved at run time. */
#define PYTHON_FUNCTIONS(X)                                                                        \
    X(int, Py_IsInitialized, (void))                                                               \
    X(void, Py_InitializeEx, (int))                                                                \
    X(const char *, Py_GetVersion, (void))                                                         \
    X(wchar_t *, Py_DecodeLocale, (const char *, size_t *))                                        \
    X(void, Py_SetPythonHome, (const wchar_t *))                                                   \
    X(int, PyRun_SimpleStringFlags, (const char *, void *))                                        \
    X(void *, PyEval_SaveThread, (void))                                                           \
    X(void, PyEval_RestoreThread, (void *))                                                        \
    X(PyGILState_STATE, PyGILState_Ensure, (void))                                                 \
    X(void *, PyGILState_GetThisThreadState, (void))                                               \
    X(void, PyThreadState_Clear, (void *))                                                         \
    X(void, PyThreadState_DeleteCurrent, (void))

typedef struct {
#define PY_MEMBER(ret, name, args) ret(*name) args;
    PYTHON_FUNCTIONS(PY_MEMBER)
#undef PY_MEMBER
} PythonApi;

static PythonApi g_py;
static int g_python_ready; /* written under g_python_lock, read atomically */
static pthread_mutex_t g_python_lock = PTHREAD_MUTEX_INITIALIZER;

/* Resolves every function from handle (RTLD_DEFAULT: whatever the process has). */
static int python_resolve(void *handle, PythonApi *api, char *why, size_t whysize)
{
#define PY_RESOLVE(ret, name, args)                                                                \
    api->name = (ret(*) args)dlsym(handle, #name);                                                 \
    if (!api->name) {                                                                              \
        snprintf(why, whysize, "it lacks %s", #name);                                              \
        return -1;                                                                                 \
    }
    PYTHON_FUNCTIONS(PY_RESOLVE)
#undef PY_RESOLVE
    return 0;
}

/* "3.11" of Py_GetVersion(), checked to be 3.9 or later. */
static int python_version(const PythonApi *api, char *version, size_t size, char *why, size_t whysize)
{
    int major = 0, minor = 0;
    if (sscanf(api->Py_GetVersion(), "%d.%d", &major, &minor) != 2) {
        snprintf(why, whysize, "unreadable version %.40s", api->Py_GetVersion());
        return -1;
    }
    if (major != 3 || minor < 9) {
        snprintf(why, whysize, "it is Python %d.%d, 3.9 or later is needed", major, minor);
        return -1;
    }
    snprintf(version, size, "%d.%d", major, minor);
    return 0;
}

/* The prefix holding lib/pythonX.Y/encodings (what Py_Initialize needs first) for the
 * library at lib_path: its directory's parent (<prefix>/lib/libpython...) or grandparent
 * (<prefix>/lib/<multiarch>/libpython...).  Empty if neither. */
static void home_of_library(const char *lib_path, const char *version, char *home, size_t size)
{
    char real[PATH_MAX], dir[PATH_MAX], probe[PATH_MAX + 64];
    home[0] = '\0';
    if (!realpath(lib_path, real)) {
        return;
    }
    dirname_of(real, dir, sizeof dir);
    for (int up = 0; up < 2; up++) {
        dirname_of(dir, dir, sizeof dir);
        snprintf(probe, sizeof probe, "%s/lib/python%s/encodings/__init__.py", dir, version);
        if (is_file(probe)) {
            snprintf(home, size, "%s", dir);
            return;
        }
    }
}

/* The code that adds a directory to sys.path; the path travels hex-encoded so that no
 * character in it can break the Python source. */
static int python_add_site_dir(const char *dir)
{
    size_t n = strlen(dir);
    size_t size = 2 * n + 200;
    char *code = malloc(size);
    if (!code) {
        return -1;
    }
    int k = snprintf(code, size, "import os, site\nsite.addsitedir(os.fsdecode(bytes.fromhex('");
    for (size_t i = 0; i < n; i++) {
        k += snprintf(code + k, size - (size_t)k, "%02x", (unsigned char)dir[i]);
    }
    snprintf(code + k, size - (size_t)k, "')))\n");
    int rc = g_py.PyRun_SimpleStringFlags(code, NULL);
    free(code);
    return rc;
}

/* Loads the library of one candidate, initialises its interpreter with the matching home
 * and the extra site directories.  0 on success; on failure why says what went wrong
 * and nothing irreversible was done (the interpreter was not initialised). */
static int python_try(const char *library, const char *home_hint, const Config *extra, char *why,
                      size_t whysize)
{
    if (!is_file(library)) {
        snprintf(why, whysize, "no such file");
        return -1;
    }
    void *handle = dlopen(library, RTLD_NOW | RTLD_GLOBAL);
    if (!handle) {
        const char *e = dlerror();
        snprintf(why, whysize, "cannot load it: %s", e ? e : "unknown error");
        return -1;
    }
    PythonApi api;
    char version[16];
    if (python_resolve(handle, &api, why, whysize) != 0 ||
        python_version(&api, version, sizeof version, why, whysize) != 0) {
        dlclose(handle);
        return -1;
    }
    if (api.Py_IsInitialized()) { /* someone in this process already runs it */
        g_py = api;
        return 0;
    }
    char home[PATH_MAX], probe[PATH_MAX + 64];
    if (home_hint && home_hint[0]) {
        snprintf(home, sizeof home, "%s", home_hint);
    } else {
        home_of_library(library, version, home, sizeof home);
    }
    snprintf(probe, sizeof probe, "%s/lib/python%s/encodings/__init__.py", home, version);
    if (!home[0] || !is_file(probe)) {
        /* Py_Initialize would abort the process without its standard library. */
        snprintf(why, whysize, "the standard library of Python %s is not at %s/lib/python%s "
                 "(set LEVER_FMU_PYTHONHOME to its prefix)", version, home[0] ? home : "<unknown prefix>",
                 version);
        return -1;
    }
    /* Py_SetPythonHome keeps the pointer: the string must live for ever. */
    wchar_t *whome = api.Py_DecodeLocale(home, NULL);
    if (!whome) {
        snprintf(why, whysize, "cannot decode the path %s", home);
        return -1;
    }
    g_py = api;
    api.Py_SetPythonHome(whome);
    /* UTF-8 mode: an embedded interpreter does not coerce the C locale hosts usually run
     * in, and would decode paths as ASCII. */
    int *utf8_mode = (int *)dlsym(handle, "Py_UTF8Mode");
    if (utf8_mode) {
        *utf8_mode = 1;
    }
    api.Py_InitializeEx(0); /* 0: the host's signal handlers stay the host's */
    for (int i = 0; extra && i < extra->nPaths; i++) {
        python_add_site_dir(extra->paths[i]);
    }
    /* Release the interpreter lock; this thread keeps its (main) thread state. */
    api.PyEval_SaveThread();
    return 0;
}

/* Makes sure a usable Python runs in this process; see the comment at the top of this
 * file for the order of places.  0 on success, else a message in err. */
static int python_ready(const Config *built, char *err, size_t errsize)
{
    if (__atomic_load_n(&g_python_ready, __ATOMIC_ACQUIRE)) {
        return 0;
    }
    pthread_mutex_lock(&g_python_lock);
    int rc = -1;
    /* Static, under the lock: host threads may have small stacks. */
    static char why[PATH_MAX + 256];
    static Config found;
    why[0] = err[0] = '\0';
    if (g_python_ready) {
        rc = 0;
        goto done;
    }

    /* The host already runs Python (fmpy, libcosimpy, ...), or loaded its library. */
    PythonApi host;
    if (python_resolve(RTLD_DEFAULT, &host, why, sizeof why) == 0) {
        Dl_info info;
        memset(&info, 0, sizeof info);
        if (host.Py_IsInitialized()) {
            g_py = host;
            rc = 0;
            goto done;
        }
        if (dladdr((void *)host.Py_IsInitialized, &info) && info.dli_fname &&
            python_try(info.dli_fname, getenv("LEVER_FMU_PYTHONHOME"), NULL, why, sizeof why) == 0) {
            rc = 0;
            goto done;
        }
        appendf(err, errsize, "the Python library already in this process (%s): %s; ",
                info.dli_fname ? info.dli_fname : "?", why);
    }

    const char *explicit_library = getenv("LEVER_FMU_LIBPYTHON");
    if (explicit_library && explicit_library[0]) {
        /* An explicit setting is final: falling back would hide its mistake. */
        if (python_try(explicit_library, getenv("LEVER_FMU_PYTHONHOME"), NULL, why, sizeof why) == 0) {
            rc = 0;
        } else {
            appendf(err, errsize, "LEVER_FMU_LIBPYTHON=%s: %s", explicit_library, why);
        }
        goto done;
    }
    if (built->library[0]) {
        if (python_try(built->library, built->home, built, why, sizeof why) == 0) {
            rc = 0;
            goto done;
        }
        appendf(err, errsize, "the Python this FMU was built with (%s): %s; ", built->library, why);
    }
    memset(&found, 0, sizeof found);
    if (query_python_on_path(&found, why, sizeof why) == 0 &&
        python_try(found.library, found.home, &found, why, sizeof why) == 0) {
        rc = 0;
        goto done;
    }
    appendf(err, errsize, "python3 on PATH%s%s: %s. ", found.library[0] ? " " : "", found.library, why);
    appendf(err, errsize, "Fix: set LEVER_FMU_LIBPYTHON to a CPython 3.9+ shared library "
                          "(libpython3.X.so, e.g. Debian's package libpython3.11), or put a python3 "
                          "that has one on PATH");
done:
    if (rc == 0) {
        __atomic_store_n(&g_python_ready, 1, __ATOMIC_RELEASE);
    }
    pthread_mutex_unlock(&g_python_lock);
    return rc;
}

/* ------------------------------------------------------------------------- */
/* One Python thread state per host thread                                    */
/* ------------------------------------------------------------------------- */

static __thread int t_thread_known;  /* this thread has a thread state (ours or Python's) */
static __thread void *t_kept_state;   /* the one we registered, if any */
static pthread_key_t g_thread_key;     /* its destructor releases it when the thread ends */
static pthread_once_t g_thread_key_once = PTHREAD_ONCE_INIT;
static int g_live_instances;

static void release_thread_state(void *state)
{
    /* After the host's Py_Finalize the state is gone with the interpreter.  Not
     * PyGILState_Release: at thread exit the C library may already have cleared Python's
     * thread-specific slot, which that function insists on. */
    if (state && g_py.Py_IsInitialized()) {
        g_py.PyEval_RestoreThread(state);
        g_py.PyThreadState_Clear(state);
        g_py.PyThreadState_DeleteCurrent(); /* also unregisters it and drops the lock */
    }
}

static void make_thread_key(void) { pthread_key_create(&g_thread_key, release_thread_state); }

/* On a thread's first call: register a thread state with the GIL-state machinery and
 * keep it, so that pythonfmu's PyGILState_Ensure finds it instead of making one. */
static void keep_thread_state(void)
{
    t_thread_known = 1;
    if (g_py.PyGILState_GetThisThreadState()) {
        return; /* Python's own thread, or the one that initialised the interpreter */
    }
    pthread_once(&g_thread_key_once, make_thread_key);
    g_py.PyGILState_Ensure(); /* creates the thread state, counter 1, lock held */
    t_kept_state = g_py.PyEval_SaveThread();
    pthread_setspecific(g_thread_key, t_kept_state);
}

static inline void thread_state_ready(void)
{
    if (__builtin_expect(!t_thread_known, 0)) {
        keep_thread_state();
    }
}

/* ------------------------------------------------------------------------- */
/* Inner library                                                              */
/* ------------------------------------------------------------------------- */

typedef struct {
#define SHIM_API_MEMBER(name) name##TYPE *name;
    SHIM_INNER_FUNCTIONS(SHIM_API_MEMBER)
#undef SHIM_API_MEMBER
} InnerApi;

/* Published once with an atomic compare-and-swap so that concurrent first
 * instantiations (importers may instantiate from several threads) are safe.  The inner
 * library is never unloaded: leaked (dead) inner instances live in it, and pythonfmu
 * pins itself anyway. */
static InnerApi *g_api;

/* pythonfmu 0.7 keeps its PyState in a static shared_ptr that the C++ runtime destroys at
 * exit, after which the library's ELF destructor (finalizePythonInterpreter) assigns to that
 * destroyed shared_ptr: a use after free that now and then corrupts the heap as the host
 * exits ("corrupted double-linked list").  Releasing the PyState first, from an exit handler
 * registered after the inner library's static constructors (so it runs before their
 * destructors), leaves both later steps an empty pointer.  Registered from this library, the
 * handler also runs if the host unloads it; the inner library then makes a new PyState on its
 * next instantiation. */
typedef void InnerFinalizeFn(void);
static InnerFinalizeFn *g_inner_finalize;

static void release_inner_python_state(void)
{
    InnerFinalizeFn *finalize = __atomic_exchange_n(&g_inner_finalize, NULL, __ATOMIC_ACQ_REL);
    if (finalize) {
        finalize();
    }
}

/* The directory of this library, with a trailing '/'. */
static int own_directory(char *dir, size_t size)
{
    Dl_info info;
    if (!dladdr((void *)&fmi2Instantiate, &info) || !info.dli_fname) {
        return -1;
    }
    const char *slash = strrchr(info.dli_fname, '/');
    size_t n = slash ? (size_t)(slash - info.dli_fname) + 1 : 0;
    if (n + 1 > size) {
        return -1;
    }
    memcpy(dir, info.dli_fname, n);
    dir[n] = '\0';
    return 0;
}

/* Loads the inner library on first use.  On failure returns NULL and leaves a
 * description in err. */
static InnerApi *inner_api(char *err, size_t errsize)
{
    InnerApi *api = __atomic_load_n(&g_api, __ATOMIC_ACQUIRE);
    if (api) {
        return api;
    }
    char path[PATH_MAX];
    if (own_directory(path, sizeof path - sizeof INNER_LIBRARY_NAME) != 0) {
        snprintf(err, errsize, "cannot determine the directory of the FMU binary");
        return NULL;
    }
    strcat(path, INNER_LIBRARY_NAME);

    void *handle = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!handle) {
        const char *why = dlerror();
        snprintf(err, errsize, "cannot load %s: %s", path, why ? why : "unknown error");
        return NULL;
    }
    api = calloc(1, sizeof *api);
    if (!api) {
        snprintf(err, errsize, "out of memory");
        dlclose(handle);
        return NULL;
    }
#define SHIM_RESOLVE(name)                                                                         \
    api->name = (name##TYPE *)lever_function(handle, path, #name, err, errsize);                   \
    if (!api->name) {                                                                              \
        free(api);                                                                                 \
        dlclose(handle);                                                                           \
        return NULL;                                                                               \
    }
    SHIM_INNER_FUNCTIONS(SHIM_RESOLVE)
#undef SHIM_RESOLVE

    InnerApi *expected = NULL;
    if (!__atomic_compare_exchange_n(&g_api, &expected, api, 0, __ATOMIC_ACQ_REL,
                                     __ATOMIC_ACQUIRE)) {
        /* Another thread won the race; drop our duplicate reference. */
        free(api);
        dlclose(handle);
        api = expected;
    } else {
        InnerFinalizeFn *finalize = (InnerFinalizeFn *)dlsym(handle, "finalizePythonInterpreter");
        if (finalize) {
            __atomic_store_n(&g_inner_finalize, finalize, __ATOMIC_RELEASE);
            atexit(release_inner_python_state);
        }
    }
    return api;
}

/* ------------------------------------------------------------------------- */
/* Resource location: RFC 8089 file URIs                                      */
/* ------------------------------------------------------------------------- */

static int hex_value(char c)
{
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    return -1;
}

/* The local directory a file URI names, percent-decoded, without a trailing '/'.
 * 0 on success, else a message in err. */
static int resource_directory(const char *uri, char *path, size_t size, char *err, size_t errsize)
{
    if (!uri[0]) {
        snprintf(err, errsize, "fmuResourceLocation is empty; a file URI is needed "
                               "(file:///path/to/unzipped/resources)");
        return -1;
    }
    if (strncasecmp(uri, "file:", 5) != 0) {
        snprintf(err, errsize, "fmuResourceLocation '%.200s' is not a file URI "
                               "(file:///path, file:/path or file://localhost/path)", uri);
        return -1;
    }
    const char *p = uri + 5;
    if (p[0] == '/' && p[1] == '/') { /* an authority: empty or localhost */
        const char *end = strchr(p + 2, '/');
        size_t n = end ? (size_t)(end - (p + 2)) : strlen(p + 2);
        if (!(n == 0 || (n == 9 && strncasecmp(p + 2, "localhost", 9) == 0)) || !end) {
            snprintf(err, errsize, "fmuResourceLocation '%.200s' names a host other than "
                                   "localhost or no path; only local files can be used", uri);
            return -1;
        }
        p = end;
    }
    if (p[0] != '/') {
        snprintf(err, errsize, "fmuResourceLocation '%.200s' has no absolute path", uri);
        return -1;
    }
    size_t k = 0;
    for (; *p && *p != '?' && *p != '#'; p++) {
        char c = *p;
        if (c == '%') {
            int hi = hex_value(p[1]), lo = hi < 0 ? -1 : hex_value(p[2]);
            if (hi < 0 || lo < 0 || (hi == 0 && lo == 0)) {
                snprintf(err, errsize, "fmuResourceLocation '%.200s' has a malformed "
                                       "percent-encoding", uri);
                return -1;
            }
            c = (char)(hi * 16 + lo);
            p += 2;
        }
        if (k + 1 >= size) {
            snprintf(err, errsize, "fmuResourceLocation is longer than %zu bytes", size);
            return -1;
        }
        path[k++] = c;
    }
    if (*p) {
        snprintf(err, errsize, "fmuResourceLocation '%.200s' has a query or fragment", uri);
        return -1;
    }
    while (k > 1 && path[k - 1] == '/') {
        k--;
    }
    path[k] = '\0';
    if (strstr(path, "%20")) {
        /* pythonfmu turns "%20" into a space once more. */
        snprintf(err, errsize, "the resource directory %.200s contains \"%%20\", which pythonfmu "
                               "misreads", path);
        return -1;
    }
    if (!is_directory(path)) {
        snprintf(err, errsize, "fmuResourceLocation '%.200s': %.200s is not a directory", uri, path);
        return -1;
    }
    return 0;
}

/* ------------------------------------------------------------------------- */
/* Instances                                                                  */
/* ------------------------------------------------------------------------- */

/* The FMI 2.0 Co-Simulation states (stepInProgress and stepCanceled never occur: steps
 * are synchronous) and Model Exchange's event and continuous-time modes.  Bits, so that
 * each function's allowed states are one mask. */
typedef enum {
    ST_INSTANTIATED = 1,
    ST_INITIALIZATION = 2,
    ST_STEP_COMPLETE = 4,
    ST_STEP_FAILED = 8,
    ST_TERMINATED = 16,
    ST_EVENT_MODE = 32,
    ST_CONTINUOUS_TIME = 64,
} ShimStateBit;

static const char *state_name(int state)
{
    switch (state) {
    case ST_INSTANTIATED: return "instantiated";
    case ST_INITIALIZATION: return "initialization mode";
    case ST_STEP_COMPLETE: return "step complete";
    case ST_STEP_FAILED: return "step failed";
    case ST_TERMINATED: return "terminated";
    case ST_EVENT_MODE: return "event mode";
    case ST_CONTINUOUS_TIME: return "continuous-time mode";
    default: return "?";
    }
}

#define ANY_STATE (ST_INSTANTIATED | ST_INITIALIZATION | ST_STEP_COMPLETE | ST_STEP_FAILED | ST_TERMINATED | \
                   ST_EVENT_MODE | ST_CONTINUOUS_TIME)
#define INITIALIZED (ST_STEP_COMPLETE | ST_STEP_FAILED | ST_TERMINATED)
/* The standard's table (FMI 2.0, section 4.2.4), Co-Simulation columns, with one
 * leniency: the getters also work in 'instantiated' (they return the start values), as
 * importers, ours included, read them before initialisation; reading changes nothing. */
#define MASK_fmi2SetupExperiment ST_INSTANTIATED
#define MASK_fmi2EnterInitializationMode ST_INSTANTIATED
#define MASK_fmi2ExitInitializationMode ST_INITIALIZATION
#define MASK_fmi2Terminate (ST_STEP_COMPLETE | ST_STEP_FAILED)
#define MASK_fmi2Reset ANY_STATE
#define MASK_fmi2GetReal ANY_STATE
#define MASK_fmi2GetInteger MASK_fmi2GetReal
#define MASK_fmi2GetBoolean MASK_fmi2GetReal
#define MASK_fmi2GetString MASK_fmi2GetReal
#define MASK_fmi2SetReal (ST_INSTANTIATED | ST_INITIALIZATION | ST_STEP_COMPLETE)
#define MASK_fmi2SetInteger MASK_fmi2SetReal
#define MASK_fmi2SetBoolean MASK_fmi2SetReal
#define MASK_fmi2SetString MASK_fmi2SetReal
#define MASK_fmi2GetFMUstate ANY_STATE
#define MASK_fmi2SetFMUstate ANY_STATE
#define MASK_fmi2FreeFMUstate ANY_STATE
#define MASK_fmi2SerializedFMUstateSize ANY_STATE
#define MASK_fmi2SerializeFMUstate ANY_STATE
#define MASK_fmi2DeSerializeFMUstate ANY_STATE
#define MASK_fmi2GetDirectionalDerivative (ST_INITIALIZATION | INITIALIZED)
#define MASK_fmi2SetRealInputDerivatives (ST_INSTANTIATED | ST_INITIALIZATION | ST_STEP_COMPLETE)
#define MASK_fmi2GetRealOutputDerivatives INITIALIZED
#define MASK_fmi2DoStep ST_STEP_COMPLETE
#define MASK_fmi2CancelStep 0 /* only while an asynchronous step runs: never */
#define MASK_fmi2GetStatus INITIALIZED
#define MASK_fmi2GetRealStatus INITIALIZED
#define MASK_fmi2GetIntegerStatus INITIALIZED
#define MASK_fmi2GetBooleanStatus INITIALIZED
#define MASK_fmi2GetStringStatus INITIALIZED
/* Model Exchange functions: none in Co-Simulation. */
#define MASK_fmi2EnterEventMode 0
#define MASK_fmi2NewDiscreteStates 0
#define MASK_fmi2EnterContinuousTimeMode 0
#define MASK_fmi2CompletedIntegratorStep 0
#define MASK_fmi2SetTime 0
#define MASK_fmi2SetContinuousStates 0
#define MASK_fmi2GetDerivatives 0
#define MASK_fmi2GetEventIndicators 0
#define MASK_fmi2GetContinuousStates 0
#define MASK_fmi2GetNominalsOfContinuousStates 0

/* The standard's table (FMI 2.0, section 3.2.3), Model Exchange columns, with the same
 * leniency for the getters.  The FMU state functions are not offered in Model Exchange
 * (canGetAndSetFMUstate="false" there): the discrete modes are the physics' own. */
#define ME_RUNNING (ST_EVENT_MODE | ST_CONTINUOUS_TIME)
#define MEMASK_fmi2SetupExperiment ST_INSTANTIATED
#define MEMASK_fmi2EnterInitializationMode ST_INSTANTIATED
#define MEMASK_fmi2ExitInitializationMode ST_INITIALIZATION
#define MEMASK_fmi2Terminate ME_RUNNING
#define MEMASK_fmi2Reset ANY_STATE
#define MEMASK_fmi2GetReal ANY_STATE
#define MEMASK_fmi2GetInteger ANY_STATE
#define MEMASK_fmi2GetBoolean ANY_STATE
#define MEMASK_fmi2GetString ANY_STATE
#define MEMASK_fmi2SetReal (ST_INSTANTIATED | ST_INITIALIZATION | ME_RUNNING)
#define MEMASK_fmi2SetInteger (ST_INSTANTIATED | ST_INITIALIZATION | ST_EVENT_MODE)
#define MEMASK_fmi2SetBoolean MEMASK_fmi2SetInteger
#define MEMASK_fmi2SetString MEMASK_fmi2SetInteger
#define MEMASK_fmi2GetFMUstate 0
#define MEMASK_fmi2SetFMUstate 0
#define MEMASK_fmi2FreeFMUstate 0
#define MEMASK_fmi2SerializedFMUstateSize 0
#define MEMASK_fmi2SerializeFMUstate 0
#define MEMASK_fmi2DeSerializeFMUstate 0
#define MEMASK_fmi2GetDirectionalDerivative (ST_INITIALIZATION | ME_RUNNING | ST_TERMINATED)
#define MEMASK_fmi2SetRealInputDerivatives 0
#define MEMASK_fmi2GetRealOutputDerivatives 0
#define MEMASK_fmi2DoStep 0
#define MEMASK_fmi2CancelStep 0
#define MEMASK_fmi2GetStatus 0
#define MEMASK_fmi2GetRealStatus 0
#define MEMASK_fmi2GetIntegerStatus 0
#define MEMASK_fmi2GetBooleanStatus 0
#define MEMASK_fmi2GetStringStatus 0
#define MEMASK_fmi2EnterEventMode ME_RUNNING
#define MEMASK_fmi2NewDiscreteStates ST_EVENT_MODE
#define MEMASK_fmi2EnterContinuousTimeMode ST_EVENT_MODE
#define MEMASK_fmi2CompletedIntegratorStep ST_CONTINUOUS_TIME
#define MEMASK_fmi2SetTime ME_RUNNING
#define MEMASK_fmi2SetContinuousStates ST_CONTINUOUS_TIME
#define MEMASK_fmi2GetDerivatives (ME_RUNNING | ST_TERMINATED)
#define MEMASK_fmi2GetEventIndicators (ST_INITIALIZATION | ME_RUNNING | ST_TERMINATED)
#define MEMASK_fmi2GetContinuousStates MEMASK_fmi2GetEventIndicators
/* Co-Simulation: wherever its variables have values (FMI 3.0: Initialization Mode on). */
#define MASK_leverGetEventIndicatorValues (ST_INITIALIZATION | INITIALIZED)
#define MEMASK_leverGetEventIndicatorValues MEMASK_fmi2GetEventIndicators
#define MEMASK_fmi2GetNominalsOfContinuousStates (ST_INSTANTIATED | ME_RUNNING | ST_TERMINATED)

/* The channel to the model (fmu_src/lever/fmus/me_channel.py): value references
 * CHANNEL + (kind << CHANNEL_SHIFT) + index. */
#define CHANNEL 0x40000000u
#define CHANNEL_SHIFT 20
#define CHANNEL_INDEX_MAX ((1u << CHANNEL_SHIFT) - 1u)
enum { CH_CONTROL, CH_STATES, CH_DERIVATIVES, CH_INDICATORS, CH_NOMINALS, CH_SEEDS, CH_DIRECTIONAL,
       CH_EVENT_INFO, CH_OUTPUT_RATES, CH_INPUT_TABLE, CH_STATE_OUTPUT_TABLE, CH_OUTPUT_TABLE };
enum { CONTROL_INTERFACE = 0, CONTROL_TIME = 1, CONTROL_COMMAND = 2, CONTROL_POINT = 3, CONTROL_SYNC = 4 };
enum { SIZE_STATES = 0, SIZE_INDICATORS = 1, SIZE_DEFERRED_INPUTS = 2, SIZE_STATE_OUTPUTS = 3, SIZE_OUTPUTS = 4 };
#define COMMAND_NEW_DISCRETE_STATES 2.0
#define EVENT_INFO_FIELDS 6

/* An inner (pythonfmu) instance with the callbacks handed to it.  pythonfmu keeps a
 * *pointer* to the callbacks, so they live here, at a stable address, as long as the inner
 * instance does.  A freed instance's inner instance is reset and kept for the next
 * fmi2Instantiate of the same resources (see the pool below). */
typedef struct Slot {
    fmi2Component inner;
    fmi2CallbackFunctions own; /* componentEnvironment: the Shim using the slot, or NULL */
    char *resources;
    fmi2Boolean visible;
    struct Slot *next;
} Slot;

typedef struct {
    fmi2Component inner;
    fmi2CallbackFunctions importer; /* the importer's callbacks (copied) */
    Slot *slot;
    char *instanceName;
    fmi2Boolean loggingOn;  /* the importer's wish; the inner one is always on */
    size_t nCategories;     /* 0 = all categories */
    char **categories;
    fmi2Status worst;       /* most severe status logged during the current call */
    int dead;               /* inner instance returned fmi2Fatal: never touch it again */
    const char *deadIn;     /* the function that returned fmi2Fatal */
    int state;              /* ShimStateBit */
    fmi2Real time;          /* the current communication point (Model Exchange: fmi2SetTime's) */
    int me;                 /* instantiated as fmi2ModelExchange */
    int channel;            /* the model answers the channel (the configuration's channel=1) */
    size_t nx, nz;          /* Model Exchange: continuous states, event indicators */
    int nzKnown;            /* nz was read (Model Exchange: at instantiation; else on first use) */
    /* The point block shared with the Python slave (POINT_* below), and the inputs it may
     * hold: value reference and closed range of each, in the block's order. */
    fmi2Real *point;
    size_t ninputs;
    fmi2ValueReference *inputVr;
    fmi2Real *inputRange; /* low, high of each input */
    /* Outputs that are states (value reference, state index): read from the block's states
     * while statesKnown - in Continuous-Time Mode, the states set since it was entered,
     * which nothing but fmi2SetContinuousStates changes there. */
    size_t nstateOutputs;
    fmi2ValueReference *stateOutputVr;
    size_t *stateOutputIndex;
    int statesKnown;
    /* Co-Simulation: the outputs the model leaves in the block after a step (value
     * references, in the block's order), answered from there until any other call */
    size_t noutputs;
    fmi2ValueReference *outputVr;
} Shim;

/* The point block: fmi2SetTime, fmi2SetContinuousStates and, while the model runs (Model
 * Exchange's event and continuous-time modes, Co-Simulation's step complete), fmi2SetReal
 * of inputs the model applies without judgement (the model names them and their closed
 * ranges at instantiation) are checked here and written to a block of doubles the Python
 * slave reads (its address handed over with CONTROL_POINT); the model takes them at its
 * next fmi2GetReal, fmi2SetReal or fmi2DoStep, the way every channel call reaches it, and
 * a call that reaches the model any other way is preceded by a sync (me_sync).  A value the check
 * refuses (out of range, NaN, not such an input) goes to the model, which says why.  An
 * integrator's right-hand side then calls into Python only to read: the time, the states
 * and the coupled inputs it sets cost no call there.  In Co-Simulation the model also
 * leaves its outputs there at the end of each step: a read of those alone is answered
 * from the block until the next call of any other kind (outputs_answer).
 * [0]: what is pending (POINT_TIME | POINT_STATES | POINT_INPUTS), [1]: the time,
 * [2 .. 2+max(nx,1)): the states, then the inputs' values, then their pending flags, then
 * whether the outputs are the model's (1.0) and the outputs. */
#define POINT_TIME 1
#define POINT_STATES 2
#define POINT_INPUTS 4
#define POINT_HEADER 2
/* where the inputs' values begin, and the block's size */
#define POINT_INPUTS_AT(s) (POINT_HEADER + ((s)->nx ? (s)->nx : 1))
#define POINT_OUTPUTS_AT(s) (POINT_INPUTS_AT(s) + 2 * (s)->ninputs)
#define POINT_SIZE(s) (POINT_OUTPUTS_AT(s) + 1 + (s)->noutputs)
/* what the host set and the model has not taken yet */
#define POINT_PENDING(s, what) ((s)->point[0] = (fmi2Real)((int)(s)->point[0] | (what)))

/* What fmi2GetFMUstate hands out: the inner state and where the instance was. */
#define STATE_MAGIC 0x4c565253u /* "LVRS" */
typedef struct {
    unsigned magic;
    int state;
    fmi2Real time;
    fmi2FMUstate inner;
} ShimFMUstate;

/* The header in front of the inner library's serialized bytes. */
#define SERIAL_MAGIC "LVRSHIM"  /* 8 bytes with its NUL */
#define SERIAL_VERSION 1u
#define SERIAL_HEADER 32       /* magic[8] version:u32 state:u32 time:f64 length:u64 */
/* The line in front of the model's bytes on deserialization: state bit, time's bits (hex). */
#define SERIAL_FRAME_LINE "lever-shim-frame"

static void free_categories(Shim *s)
{
    for (size_t i = 0; i < s->nCategories; i++) {
        free(s->categories[i]);
    }
    free(s->categories);
    s->categories = NULL;
    s->nCategories = 0;
}

/* The pool of reset inner instances.  pythonfmu 0.7's instantiation leaks about 1.4 KB of
 * Python objects every time (it inserts the resources path into sys.path again, and the
 * search for the slave class keeps the MRO list, the reprs of its classes and their UTF-8
 * bytes), while fmi2Reset of an inner instance only makes a fresh Python slave.  So a freed
 * inner instance is reset and kept, and the next fmi2Instantiate of the same resources takes
 * it: a host that instantiates and frees in a loop (an optimisation, a Monte Carlo study)
 * stays flat.  At most POOL_MAX are kept; beyond that they are freed. */
#define POOL_MAX 16
static Slot *g_pool;
static int g_pooled;
static pthread_mutex_t g_pool_lock = PTHREAD_MUTEX_INITIALIZER;

static void *shim_calloc(size_t n, size_t size) { return calloc(n, size); }

/* A kept inner instance for these resources, taken out of the pool, or NULL. */
static Slot *pool_take(const char *resources, fmi2Boolean visible)
{
    pthread_mutex_lock(&g_pool_lock);
    Slot **link = &g_pool, *slot = NULL;
    for (; *link; link = &(*link)->next) {
        if ((*link)->visible == visible && strcmp((*link)->resources, resources) == 0) {
            slot = *link;
            *link = slot->next;
            slot->next = NULL;
            g_pooled--;
            break;
        }
    }
    pthread_mutex_unlock(&g_pool_lock);
    return slot;
}

/* Keeps a reset inner instance; 0 if the pool is full (the caller frees it). */
static int pool_keep(Slot *slot)
{
    int kept = 0;
    pthread_mutex_lock(&g_pool_lock);
    if (g_pooled < POOL_MAX) {
        slot->own.componentEnvironment = NULL; /* nothing of it may reach a freed Shim */
        slot->next = g_pool;
        g_pool = slot;
        g_pooled++;
        kept = 1;
    }
    pthread_mutex_unlock(&g_pool_lock);
    return kept;
}

static void free_slot(Slot *slot)
{
    if (slot) {
        free(slot->resources);
        free(slot);
    }
}

static void free_shim(Shim *s)
{
    free(s->point);
    free(s->inputVr);
    free(s->inputRange);
    free(s->stateOutputVr);
    free(s->stateOutputIndex);
    free(s->outputVr);
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

/* Messages originating in the shim itself; returns fmi2Error. */
static fmi2Status shim_error(Shim *s, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static fmi2Status shim_error(Shim *s, const char *fmt, ...)
{
    char buffer[4096];
    va_list args;
    va_start(args, fmt);
    vsnprintf(buffer, sizeof buffer, fmt, args);
    va_end(args);
    shim_record(s, fmi2Error, SHIM_CATEGORY, buffer);
    return fmi2Error;
}

/* The refusal of a call made in a state the standard does not allow it in. */
static void shim_refuse_state(Shim *s, const char *function, int allowed)
{
    char where[256] = "";
    if (allowed == ST_INSTANTIATED) {
        appendf(where, sizeof where, "only in the instantiated phase (after fmi2Instantiate or fmi2Reset)");
    } else if (allowed == ST_INITIALIZATION) {
        appendf(where, sizeof where, "only in the initialisation phase (after fmi2EnterInitializationMode)");
    } else if (allowed == 0 && !s->me && strcmp(function, "fmi2CancelStep") != 0) {
        shim_error(s, "%s is a Model Exchange function: this instance was instantiated for Co-Simulation "
                      "(fmi2CoSimulation)", function);
        return;
    } else if (allowed == 0 && s->me) {
        shim_error(s, "%s is not offered by this FMU's Model Exchange interface (this instance was "
                      "instantiated as fmi2ModelExchange; %s)", function,
                   strstr(function, "FMUstate") ? "the FMU state functions are Co-Simulation's only"
                                                : "it is a Co-Simulation function");
        return;
    } else if (allowed == 0) {
        appendf(where, sizeof where, "only while an asynchronous step runs, and steps are synchronous");
    } else {
        appendf(where, sizeof where, "in the states");
        for (int bit = ST_INSTANTIATED; bit <= ST_CONTINUOUS_TIME; bit <<= 1) {
            if (allowed & bit) {
                appendf(where, sizeof where, " '%s'", state_name(bit));
            }
        }
    }
    int early = (s->state & (ST_INSTANTIATED | ST_INITIALIZATION)) &&
                (allowed & (INITIALIZED | ME_RUNNING)) && !(allowed & s->state);
    shim_error(s, "%s is not allowed in state '%s'; it is allowed %s (FMI 2.0 %s "
                  "state machine)%s",
               function, state_name(s->state), where, s->me ? "Model Exchange" : "Co-Simulation",
               early ? "; initialise the instance first (fmi2SetupExperiment, "
                       "fmi2EnterInitializationMode, fmi2ExitInitializationMode)" : "");
}

/* Prologue of every call: 1 if the inner library may be called in this state. */
static int shim_begin(Shim *s, const char *function, int allowed)
{
    if (!s) {
        return 0;
    }
    s->worst = fmi2OK;
    if (s->dead) {
        shim_error(s, "instance is unusable after a fatal error in %s", s->deadIn);
        return 0;
    }
    if (!(s->state & allowed)) {
        shim_refuse_state(s, function, allowed);
        return 0;
    }
    if (s->noutputs && s->point && strcmp(function, "fmi2GetReal") != 0) {
        s->point[POINT_OUTPUTS_AT(s)] = 0.0; /* any call but a read may change the outputs */
    }
    thread_state_ready();
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

static int succeeded(fmi2Status status) { return status == fmi2OK || status == fmi2Warning; }

#define SHIM(c) ((Shim *)(c))
#define BEGIN(name, c)                                                                             \
    if (!shim_begin(SHIM(c), #name, SHIM(c) && SHIM(c)->me ? MEMASK_##name : MASK_##name)) return fmi2Error

/* Forward a call with arguments after the component. */
#define FORWARD(name, c, ...)                                                                      \
    do {                                                                                           \
        BEGIN(name, c);                                                                            \
        SYNC(c);                                                                                   \
        return shim_end(SHIM(c), #name, g_api->name(SHIM(c)->inner, __VA_ARGS__));                 \
    } while (0)

/* The pending time and states taken by the model before this call (me_sync). */
#define SYNC(c)                                                                                    \
    do {                                                                                           \
        fmi2Status synced_ = me_sync(SHIM(c));                                                     \
        if (!succeeded(synced_)) return synced_;                                                   \
    } while (0)

/* ------------------------------------------------------------------------- */
/* The channel to the model (Model Exchange, directional derivatives)          */
/* ------------------------------------------------------------------------- */

/* Value references of the channel for `kind`: indices from `index`, or 0..n-1 when NULL. */
static fmi2ValueReference *channel_refs(Shim *s, const char *function, unsigned kind,
                                        const fmi2ValueReference *index, size_t n)
{
    fmi2ValueReference *vrs = malloc((n ? n : 1) * sizeof *vrs);
    if (!vrs) {
        shim_error(s, "%s: out of memory", function);
        return NULL;
    }
    for (size_t i = 0; i < n; i++) {
        vrs[i] = CHANNEL + (kind << CHANNEL_SHIFT) + (index ? index[i] : (fmi2ValueReference)i);
    }
    return vrs;
}

/* Sets n values on the channel; the status as shim_end makes it. */
static fmi2Status channel_set(Shim *s, const char *function, unsigned kind,
                              const fmi2ValueReference *index, size_t n, const fmi2Real *values)
{
    fmi2ValueReference *vrs = channel_refs(s, function, kind, index, n);
    if (!vrs) {
        return fmi2Error;
    }
    fmi2Status status = shim_end(s, function, g_api->fmi2SetReal(s->inner, vrs, n, values));
    free(vrs);
    return status;
}

/* Reads n values from the channel into out, which is written only when the call succeeds. */
static fmi2Status channel_get(Shim *s, const char *function, unsigned kind,
                              const fmi2ValueReference *index, size_t n, fmi2Real *out)
{
    fmi2ValueReference *vrs = channel_refs(s, function, kind, index, n);
    fmi2Real *values = malloc((n ? n : 1) * sizeof *values);
    if (!vrs || !values) {
        free(vrs);
        free(values);
        return vrs ? shim_error(s, "%s: out of memory", function) : fmi2Error;
    }
    fmi2Status status = shim_end(s, function, g_api->fmi2GetReal(s->inner, vrs, n, values));
    if (succeeded(status)) {
        memcpy(out, values, n * sizeof *values);
    }
    free(vrs);
    free(values);
    return status;
}

/* A host's value references never reach the channel: 0 (and an error logged) if one would. */
static int host_references(Shim *s, const char *function, const fmi2ValueReference vr[], size_t nvr)
{
    if (nvr > 0 && !vr) {
        shim_error(s, "%s: the value reference array is NULL with %zu values", function, nvr);
        return 0;
    }
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] >= CHANNEL) {
            shim_error(s, "%s: value reference %u is no variable of this FMU; nothing of this call was "
                          "applied", function, vr[i]);
            return 0;
        }
    }
    return 1;
}

/* The size a Model Exchange array argument must have. */
static int me_array(Shim *s, const char *function, const void *array, size_t n, size_t expected,
                    const char *what)
{
    if (n != expected) {
        shim_error(s, "%s: %zu %s given, this model has %zu; nothing was done", function, n, what,
                   expected);
        return 0;
    }
    if (n > 0 && !array) {
        shim_error(s, "%s: the array of %s is NULL", function, what);
        return 0;
    }
    return 1;
}

static fmi2Status point_connect(Shim *s);

/* Gives a fresh Co-Simulation slave its point block: a host's fmi2SetReal of inputs in
 * range then stays here until the model's next fmi2GetReal, fmi2SetReal or fmi2DoStep
 * takes it (a master sets a shaft's torque, then reads or steps it), one call into Python
 * fewer each.  The block's layout follows the model's states, as in Model Exchange. */
static fmi2Status cs_connect(Shim *s)
{
    fmi2ValueReference size = SIZE_STATES;
    fmi2Real n = 0.0;
    fmi2Status status = channel_get(s, "fmi2Instantiate", CH_CONTROL, &size, 1, &n);
    if (!succeeded(status)) {
        return status;
    }
    if (!(n >= 0.0 && n < 1e6)) {
        return shim_error(s, "fmi2Instantiate: the model reports %g states", n);
    }
    s->nx = (size_t)n;
    return point_connect(s);
}

/* Tells a fresh Python slave that it runs as Model Exchange and reads its sizes. */
static fmi2Status me_connect(Shim *s)
{
    fmi2ValueReference control = CONTROL_INTERFACE;
    fmi2Real one = 1.0;
    fmi2Status status = channel_set(s, "fmi2Instantiate", CH_CONTROL, &control, 1, &one);
    if (!succeeded(status)) {
        return status;
    }
    fmi2ValueReference sizes[2] = {SIZE_STATES, SIZE_INDICATORS};
    fmi2Real n[2] = {0.0, 0.0};
    status = channel_get(s, "fmi2Instantiate", CH_CONTROL, sizes, 2, n);
    if (succeeded(status)) {
        if (!(n[0] >= 0.0 && n[0] < 1e6 && n[1] >= 0.0 && n[1] < 1e6)) {
            return shim_error(s, "fmi2Instantiate: the model reports %g states and %g event indicators",
                              n[0], n[1]);
        }
        s->nx = (size_t)n[0];
        s->nz = (size_t)n[1];
        s->nzKnown = 1;
        status = point_connect(s);
    }
    return status;
}

/* A table the model gives at instantiation: its number of rows (at most `most`), then
 * `width` values a row, in *table (malloc'd; the caller frees it) and *rows. */
static fmi2Status read_table(Shim *s, fmi2ValueReference size, unsigned kind, size_t width, fmi2Real most,
                             const char *what, fmi2Real **table, size_t *rows)
{
    fmi2Real m = 0.0;
    *table = NULL;
    *rows = 0;
    fmi2Status status = channel_get(s, "fmi2Instantiate", CH_CONTROL, &size, 1, &m);
    if (!succeeded(status)) {
        return status;
    }
    if (!(m >= 0.0 && m <= most)) {
        return shim_error(s, "fmi2Instantiate: the model reports %g %s", m, what);
    }
    size_t n = (size_t)m;
    *table = malloc((width * n + 1) * sizeof **table);
    if (!*table) {
        return shim_error(s, "fmi2Instantiate: out of memory");
    }
    status = n ? channel_get(s, "fmi2Instantiate", kind, NULL, width * n, *table) : fmi2OK;
    if (succeeded(status)) {
        *rows = n;
    }
    return status;
}

/* The inputs the model lets the point block hold (value reference, low, high), read once
 * per instance. */
static fmi2Status read_deferred_inputs(Shim *s)
{
    fmi2Real *table;
    size_t n;
    fmi2Status status = read_table(s, SIZE_DEFERRED_INPUTS, CH_INPUT_TABLE, 3, 1e4, "inputs to keep", &table, &n);
    free(s->inputVr); /* read again for the fresh slave of an fmi2Reset */
    free(s->inputRange);
    s->ninputs = 0;
    s->inputVr = malloc((n + 1) * sizeof *s->inputVr);
    s->inputRange = malloc((2 * n + 1) * sizeof *s->inputRange);
    if (succeeded(status) && (!s->inputVr || !s->inputRange)) {
        status = shim_error(s, "fmi2Instantiate: out of memory");
    }
    if (succeeded(status)) {
        for (size_t i = 0; i < n; i++) {
            s->inputVr[i] = (fmi2ValueReference)table[3 * i];
            s->inputRange[2 * i] = table[3 * i + 1];
            s->inputRange[2 * i + 1] = table[3 * i + 2];
        }
        s->ninputs = n;
    }
    free(table);
    return status;
}

/* The outputs that are states (value reference, state index), read once per instance. */
static fmi2Status read_state_outputs(Shim *s)
{
    fmi2Real *table;
    size_t n;
    fmi2Status status = read_table(s, SIZE_STATE_OUTPUTS, CH_STATE_OUTPUT_TABLE, 2, (fmi2Real)s->nx,
                                   "outputs that are states", &table, &n);
    free(s->stateOutputVr);
    free(s->stateOutputIndex);
    s->nstateOutputs = 0;
    s->stateOutputVr = malloc((n + 1) * sizeof *s->stateOutputVr);
    s->stateOutputIndex = malloc((n + 1) * sizeof *s->stateOutputIndex);
    if (succeeded(status) && (!s->stateOutputVr || !s->stateOutputIndex)) {
        status = shim_error(s, "fmi2Instantiate: out of memory");
    }
    for (size_t i = 0; succeeded(status) && i < n; i++) {
        if (!(table[2 * i + 1] >= 0.0 && table[2 * i + 1] < (fmi2Real)s->nx)) {
            status = shim_error(s, "fmi2Instantiate: the model reports state %g of %zu", table[2 * i + 1], s->nx);
        } else {
            s->stateOutputVr[i] = (fmi2ValueReference)table[2 * i];
            s->stateOutputIndex[i] = (size_t)table[2 * i + 1];
        }
    }
    if (succeeded(status)) {
        s->nstateOutputs = n;
    }
    free(table);
    return status;
}

/* The outputs the model leaves in the point block after a Co-Simulation step, read once
 * per instance (in Model Exchange the block keeps their place, unused). */
static fmi2Status read_block_outputs(Shim *s)
{
    fmi2Real *table;
    size_t n;
    fmi2Status status = read_table(s, SIZE_OUTPUTS, CH_OUTPUT_TABLE, 1, 1e4, "outputs", &table, &n);
    free(s->outputVr);
    s->noutputs = 0;
    s->outputVr = malloc((n + 1) * sizeof *s->outputVr);
    if (succeeded(status) && !s->outputVr) {
        status = shim_error(s, "fmi2Instantiate: out of memory");
    }
    if (succeeded(status)) {
        for (size_t i = 0; i < n; i++) {
            s->outputVr[i] = (fmi2ValueReference)table[i];
        }
        s->noutputs = n;
    }
    free(table);
    return status;
}

/* fmi2GetReal answered from the outputs the model left in the point block at the end of
 * the step (Co-Simulation): 1 if they are still the model's and every value reference is
 * one of them, 0 to ask the model. */
static int outputs_answer(Shim *s, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    if (s->me || !s->point || !s->noutputs || s->state != ST_STEP_COMPLETE || nvr == 0 || !value) {
        return 0;
    }
    const fmi2Real *block = s->point + POINT_OUTPUTS_AT(s);
    if (block[0] != 1.0) {
        return 0;
    }
    for (size_t i = 0; i < nvr; i++) { /* a miss: the model's read writes every value */
        size_t k = 0;
        while (k < s->noutputs && s->outputVr[k] != vr[i]) k++;
        if (k == s->noutputs) {
            return 0;
        }
        value[i] = block[1 + k];
    }
    return 1;
}

/* fmi2GetReal answered from the point block: 1 if every value reference is an output that
 * is a state and the block's states are the model's (statesKnown), 0 to ask the model. */
static int point_answers(Shim *s, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    if (!s->statesKnown || s->state != ST_CONTINUOUS_TIME || nvr == 0 || !value) {
        return 0;
    }
    const fmi2Real *x = s->point + POINT_HEADER;
    for (size_t i = 0; i < nvr; i++) { /* a miss: the model's read writes every value */
        size_t k = 0;
        while (k < s->nstateOutputs && s->stateOutputVr[k] != vr[i]) k++;
        if (k == s->nstateOutputs) {
            return 0;
        }
        value[i] = x[s->stateOutputIndex[k]];
    }
    return 1;
}

/* Makes the point block (nothing pending) and hands it to the Python slave: at instantiation
 * and after every fmi2Reset, whose fresh slave gets a block of its own. */
static fmi2Status point_connect(Shim *s)
{
    s->statesKnown = 0;
    fmi2Status status = read_deferred_inputs(s);
    if (succeeded(status)) {
        status = read_state_outputs(s);
    }
    if (succeeded(status)) {
        status = read_block_outputs(s);
    }
    if (!succeeded(status)) {
        return status;
    }
    s->point = calloc(POINT_SIZE(s), sizeof *s->point);
    if (!s->point) {
        return shim_error(s, "fmi2Instantiate: out of memory");
    }
    s->point[1] = s->time;
    fmi2ValueReference control = CONTROL_POINT;
    /* an address of a 64-bit process is below 2^53: a double holds it exactly */
    fmi2Real address = (fmi2Real)(uintptr_t)s->point;
    status = channel_set(s, "fmi2Instantiate", CH_CONTROL, &control, 1, &address);
    if (!succeeded(status)) {
        free(s->point);
        s->point = NULL;
        s->ninputs = 0;
    }
    return status;
}

/* fmi2SetReal kept in the point block: 1 if every value is an input the block holds and in
 * its range (then written, pending), 0 to send the call to the model. */
static int point_keeps(Shim *s, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[])
{
    if (!s->point || !s->ninputs || !(s->state & (s->me ? ME_RUNNING : ST_STEP_COMPLETE)) || nvr == 0 || !value) {
        return 0;
    }
    size_t slot[16];
    if (nvr > sizeof slot / sizeof slot[0]) {
        return 0;
    }
    for (size_t i = 0; i < nvr; i++) {
        size_t k = 0;
        while (k < s->ninputs && s->inputVr[k] != vr[i]) k++;
        /* NaN fails both comparisons */
        if (k == s->ninputs || !(s->inputRange[2 * k] <= value[i] && value[i] <= s->inputRange[2 * k + 1])) {
            return 0;
        }
        slot[i] = k;
    }
    fmi2Real *values = s->point + POINT_INPUTS_AT(s);
    fmi2Real *pending = values + s->ninputs;
    for (size_t i = 0; i < nvr; i++) {
        values[slot[i]] = value[i];
        pending[slot[i]] = 1.0;
    }
    POINT_PENDING(s, POINT_INPUTS);
    return 1;
}

/* Before a call that reaches the model other than by fmi2GetReal/fmi2SetReal: the time and
 * states the host set since the model last saw them, taken in one call. */
static fmi2Status me_sync(Shim *s)
{
    if (!s->point || s->point[0] == 0.0) {
        return fmi2OK;
    }
    fmi2ValueReference control = CONTROL_SYNC;
    fmi2Real nothing = 0.0;
    return channel_set(s, "the time and states set before this call", CH_CONTROL, &control, 1, &nothing);
}

/* ------------------------------------------------------------------------- */
/* FMI 2.0 API                                                                */
/* ------------------------------------------------------------------------- */

const char *fmi2GetTypesPlatform(void) { return "default"; }

const char *fmi2GetVersion(void) { return "2.0"; }

/* Reads resources/lever_shim.cfg.  0 on success, else a message in err. */
static int read_config(const char *resources, Config *cfg, char *err, size_t errsize)
{
    char path[PATH_MAX + 32];
    snprintf(path, sizeof path, "%s/%s", resources, CONFIG_NAME);
    memset(cfg, 0, sizeof *cfg);
    FILE *f = fopen(path, "r");
    if (!f) {
        snprintf(err, errsize, "cannot read %s (%s): is fmuResourceLocation this FMU's resources "
                               "directory?", path, strerror(errno));
        return -1;
    }
    config_read(cfg, f);
    fclose(f);
    if (!cfg->guid[0]) {
        snprintf(err, errsize, "%s names no guid", path);
        return -1;
    }
    return 0;
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
    s->state = ST_INSTANTIATED;

    /* Large, so static (host threads may have small stacks), under this lock. */
    static char resources[PATH_MAX];
    static Config cfg;
    static char err[8192];
    static pthread_mutex_t lock = PTHREAD_MUTEX_INITIALIZER;
    pthread_mutex_lock(&lock);
    int ok = 0;
    if (!fmuGUID || !fmuResourceLocation) {
        shim_error(s, "fmi2Instantiate: %s is NULL", fmuGUID ? "fmuResourceLocation" : "fmuGUID");
    } else if (fmuType != fmi2CoSimulation && fmuType != fmi2ModelExchange) {
        shim_error(s, "fmi2Instantiate: fmuType %d is neither fmi2ModelExchange (0) nor fmi2CoSimulation (1)",
                   (int)fmuType);
    } else if (resource_directory(fmuResourceLocation, resources, sizeof resources, err, sizeof err) ||
               read_config(resources, &cfg, err, sizeof err)) {
        shim_error(s, "fmi2Instantiate: %s", err);
    } else if (strcmp(fmuGUID, cfg.guid) != 0) {
        shim_error(s, "fmi2Instantiate: fmuGUID '%.100s' is not this FMU's GUID '%s' "
                      "(modelDescription.xml of another FMU or build?)", fmuGUID, cfg.guid);
    } else if (python_ready(&cfg, err, sizeof err) != 0) {
        shim_error(s, "fmi2Instantiate: no usable Python for this FMU. Tried: %s", err);
    } else if (!inner_api(err, sizeof err)) {
        shim_error(s, "fmi2Instantiate: %s", err);
    } else {
        ok = 1;
        s->channel = cfg.channel;
    }
    if (!ok) {
        pthread_mutex_unlock(&lock);
        free_shim(s);
        return NULL;
    }
    thread_state_ready();
    Slot *slot = pool_take(resources, visible);
    if (slot) {
        slot->own.componentEnvironment = s;
    } else {
        slot = calloc(1, sizeof *slot);
        if (slot) {
            slot->resources = copy_string(resources);
        }
        if (!slot || !slot->resources) {
            pthread_mutex_unlock(&lock);
            free_slot(slot);
            shim_error(s, "fmi2Instantiate: out of memory");
            free_shim(s);
            return NULL;
        }
        slot->visible = visible;
        slot->own.logger = shim_logger;
        /* pythonfmu 0.7 allocates with new/delete; these are never called, but a kept
         * instance must not point at an importer's functions that may be gone. */
        slot->own.allocateMemory = shim_calloc;
        slot->own.freeMemory = free;
        slot->own.stepFinished = NULL; /* asynchronous doStep is not supported */
        slot->own.componentEnvironment = s; /* the inner instantiate may log already */
        /* loggingOn is always true for the inner library: with it off, pythonfmu
         * suppresses errors too.  The shim filters instead. */
        /* pythonfmu knows Co-Simulation only; Model Exchange is the shim's, over the channel. */
        slot->inner = g_api->fmi2Instantiate(s->instanceName, fmi2CoSimulation, fmuGUID, resources, &slot->own,
                                             visible, fmi2True);
        if (!slot->inner) {
            pthread_mutex_unlock(&lock);
            free_slot(slot);
            free_shim(s);
            return NULL;
        }
    }
    pthread_mutex_unlock(&lock);
    s->slot = slot;
    s->inner = slot->inner;
    __atomic_add_fetch(&g_live_instances, 1, __ATOMIC_ACQ_REL);
    if (fmuType == fmi2ModelExchange) {
        s->me = 1;
        if (!succeeded(me_connect(s))) {
            shim_error(s, "fmi2Instantiate: the model cannot run as Model Exchange");
            fmi2FreeInstance(s);
            return NULL;
        }
    } else if (s->channel && !succeeded(cs_connect(s))) {
        shim_error(s, "fmi2Instantiate: the model gives no point block for its inputs");
        fmi2FreeInstance(s);
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
        thread_state_ready();
        /* Reset drops the model (a fresh Python slave takes its place) and the instance is
         * kept for the next fmi2Instantiate; a fatal reset leaves it dead (and leaked). */
        fmi2Status reset = g_api->fmi2Reset(s->inner);
        if (reset == fmi2Fatal) {
            s->slot->own.componentEnvironment = NULL;
        } else if (reset != fmi2OK || !pool_keep(s->slot)) {
            g_api->fmi2FreeInstance(s->inner);
            free_slot(s->slot);
        }
    } else {
        s->slot->own.componentEnvironment = NULL; /* leaked with the dead inner instance */
    }
    free_shim(s);
    if (__atomic_sub_fetch(&g_live_instances, 1, __ATOMIC_ACQ_REL) == 0 && t_kept_state) {
        /* The last instance: this thread's kept state goes (others' when they end). */
        pthread_setspecific(g_thread_key, NULL);
        release_thread_state(t_kept_state);
        t_kept_state = NULL;
        t_thread_known = 0;
    }
}

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[])
{
    Shim *s = SHIM(c);
    if (!shim_begin(s, "fmi2SetDebugLogging", ANY_STATE)) {
        return fmi2Error;
    }
    if (nCategories > 0 && !categories) {
        return shim_error(s, "fmi2SetDebugLogging: categories is NULL");
    }
    /* Copy first so a failure leaves the previous settings intact; the
     * caller's strings may not outlive this call. */
    char **copies = NULL;
    if (nCategories > 0) {
        copies = calloc(nCategories, sizeof *copies);
        if (!copies) {
            return shim_error(s, "fmi2SetDebugLogging: out of memory");
        }
        for (size_t i = 0; i < nCategories; i++) {
            copies[i] = copy_string(categories[i] ? categories[i] : "");
            if (!copies[i]) {
                for (size_t j = 0; j < i; j++) {
                    free(copies[j]);
                }
                free(copies);
                return shim_error(s, "fmi2SetDebugLogging: out of memory");
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
    BEGIN(fmi2SetupExperiment, c);
    Shim *s = SHIM(c);
    if (!isfinite(startTime)) {
        return shim_error(s, "fmi2SetupExperiment: the start time (startTime = %g) is not finite; "
                             "nothing was set", startTime);
    }
    fmi2Status status = shim_end(s, "fmi2SetupExperiment",
                                 g_api->fmi2SetupExperiment(s->inner, toleranceDefined, tolerance,
                                                            startTime, stopTimeDefined, stopTime));
    if (succeeded(status)) {
        s->time = startTime;
    }
    return status;
}

/* A call that moves the instance to state `to` when it succeeds. */
#define TRANSITION(name, c, to)                                                                    \
    do {                                                                                           \
        BEGIN(name, c);                                                                            \
        SYNC(c);                                                                                   \
        fmi2Status status_ = shim_end(SHIM(c), #name, g_api->name(SHIM(c)->inner));                \
        if (succeeded(status_)) SHIM(c)->state = (to);                                             \
        return status_;                                                                            \
    } while (0)

fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    TRANSITION(fmi2EnterInitializationMode, c, ST_INITIALIZATION);
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    /* Model Exchange continues in event mode, Co-Simulation in step complete. */
    TRANSITION(fmi2ExitInitializationMode, c, SHIM(c)->me ? ST_EVENT_MODE : ST_STEP_COMPLETE);
}

fmi2Status fmi2Terminate(fmi2Component c) { TRANSITION(fmi2Terminate, c, ST_TERMINATED); }

fmi2Status fmi2Reset(fmi2Component c)
{
    BEGIN(fmi2Reset, c);
    Shim *s = SHIM(c);
    fmi2Status status = shim_end(s, "fmi2Reset", g_api->fmi2Reset(s->inner));
    if (succeeded(status)) {
        s->state = ST_INSTANTIATED;
        s->time = 0.0;
        /* the point block belonged to the slave reset: a new one for the new slave, made only
         * if it is connected (until then the time and states reach it by the channel) */
        free(s->point);
        s->point = NULL;
        s->statesKnown = 0;
        /* a fresh Python slave: told again that it runs as Model Exchange, or given its
         * point block */
        fmi2Status connected = s->me ? me_connect(s) : s->channel ? cs_connect(s) : fmi2OK;
        status = connected > status ? connected : status;
    }
    return status;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    BEGIN(fmi2GetReal, c);
    if (!host_references(SHIM(c), "fmi2GetReal", vr, nvr)) return fmi2Error;
    if (point_answers(SHIM(c), vr, nvr, value)) return fmi2OK;
    if (outputs_answer(SHIM(c), vr, nvr, value)) return fmi2OK;
    return shim_end(SHIM(c), "fmi2GetReal", g_api->fmi2GetReal(SHIM(c)->inner, vr, nvr, value));
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
    BEGIN(fmi2SetReal, c);
    if (!host_references(SHIM(c), "fmi2SetReal", vr, nvr)) return fmi2Error;
    if (point_keeps(SHIM(c), vr, nvr, value)) return fmi2OK;
    SHIM(c)->statesKnown = 0;
    return shim_end(SHIM(c), "fmi2SetReal", g_api->fmi2SetReal(SHIM(c)->inner, vr, nvr, value));
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

/* Offset of the first byte of text that is not well-formed UTF-8 (RFC 3629: no overlong
 * forms, no surrogates, nothing above U+10FFFF), or -1 if all of it is. */
static long utf8_error(const char *text)
{
    const unsigned char *p = (const unsigned char *)text, *start = p;
    while (*p) {
        unsigned c = *p;
        int n = c < 0x80 ? 0 : (c & 0xe0) == 0xc0 ? 1 : (c & 0xf0) == 0xe0 ? 2 : (c & 0xf8) == 0xf0 ? 3 : -1;
        if (n < 0 || (n == 1 && c < 0xc2) || (n == 3 && c > 0xf4)) {
            return (long)(p - start);
        }
        for (int i = 1; i <= n; i++) {
            if ((p[i] & 0xc0) != 0x80) {
                return (long)(p - start);
            }
        }
        if ((n == 2 && c == 0xe0 && p[1] < 0xa0) || (n == 2 && c == 0xed && p[1] >= 0xa0) ||
            (n == 3 && c == 0xf0 && p[1] < 0x90) || (n == 3 && c == 0xf4 && p[1] >= 0x90)) {
            return (long)(p - start);
        }
        p += n + 1;
    }
    return -1;
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         const fmi2String value[])
{
    BEGIN(fmi2SetString, c);
    Shim *s = SHIM(c);
    if (nvr > 0 && (!vr || !value)) {
        return shim_error(s, "fmi2SetString: vr or value is NULL");
    }
    /* pythonfmu cannot take text that is not UTF-8 (its exception would be fatal). */
    for (size_t i = 0; i < nvr; i++) {
        if (!value[i]) {
            return shim_error(s, "fmi2SetString: value[%zu] (vr %u) is NULL; nothing was set", i, vr[i]);
        }
        long bad = utf8_error(value[i]);
        if (bad >= 0) {
            return shim_error(s, "fmi2SetString: value[%zu] (vr %u) is not UTF-8 (byte %ld); "
                                 "nothing was set", i, vr[i], bad);
        }
    }
    SYNC(c);
    return shim_end(s, "fmi2SetString", g_api->fmi2SetString(s->inner, vr, nvr, value));
}

/* ---- FMU states -------------------------------------------------------- */

static ShimFMUstate *fmu_state_of(Shim *s, const char *function, fmi2FMUstate state)
{
    ShimFMUstate *w = (ShimFMUstate *)state;
    if (!w || w->magic != STATE_MAGIC) {
        shim_error(s, "%s: not an FMU state of this FMU (NULL, freed or foreign)", function);
        return NULL;
    }
    return w;
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    BEGIN(fmi2GetFMUstate, c);
    SYNC(c); /* the state holds the inputs set since the model last took them */
    Shim *s = SHIM(c);
    if (!state) {
        return shim_error(s, "fmi2GetFMUstate: state is NULL");
    }
    /* An existing state of ours is overwritten in place (FMI 2.0 allows reusing it). */
    ShimFMUstate *w = *state ? fmu_state_of(s, "fmi2GetFMUstate", *state) : calloc(1, sizeof *w);
    if (!w) {
        return *state ? fmi2Error : shim_error(s, "fmi2GetFMUstate: out of memory");
    }
    fmi2FMUstate inner = w->inner;
    fmi2Status status = shim_end(s, "fmi2GetFMUstate", g_api->fmi2GetFMUstate(s->inner, &inner));
    if (!succeeded(status)) {
        if (!*state) {
            free(w);
        }
        return status;
    }
    w->magic = STATE_MAGIC;
    w->inner = inner;
    w->state = s->state;
    w->time = s->time;
    *state = w;
    return status;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state)
{
    BEGIN(fmi2SetFMUstate, c);
    SYNC(c); /* inputs set before are taken, then the restored state's replace them */
    Shim *s = SHIM(c);
    ShimFMUstate *w = fmu_state_of(s, "fmi2SetFMUstate", state);
    if (!w) {
        return fmi2Error;
    }
    fmi2Status status = shim_end(s, "fmi2SetFMUstate", g_api->fmi2SetFMUstate(s->inner, w->inner));
    if (succeeded(status)) {
        s->state = w->state;
        s->time = w->time;
    }
    return status;
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    BEGIN(fmi2FreeFMUstate, c);
    Shim *s = SHIM(c);
    if (!state || !*state) {
        return fmi2OK; /* freeing nothing is allowed */
    }
    ShimFMUstate *w = fmu_state_of(s, "fmi2FreeFMUstate", *state);
    if (!w) {
        return fmi2Error;
    }
    fmi2Status status = shim_end(s, "fmi2FreeFMUstate", g_api->fmi2FreeFMUstate(s->inner, &w->inner));
    w->magic = 0;
    free(w);
    *state = NULL;
    return status;
}

static fmi2Status inner_serialized_size(Shim *s, const char *function, ShimFMUstate *w, size_t *size)
{
    *size = 0;
    fmi2Status status = shim_end(s, function, g_api->fmi2SerializedFMUstateSize(s->inner, w->inner, size));
    if (succeeded(status) && *size > SIZE_MAX - SERIAL_HEADER) {
        return shim_error(s, "%s: the state is too large", function);
    }
    return status;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t *size)
{
    BEGIN(fmi2SerializedFMUstateSize, c);
    Shim *s = SHIM(c);
    ShimFMUstate *w = fmu_state_of(s, "fmi2SerializedFMUstateSize", state);
    if (!w || !size) {
        return w ? shim_error(s, "fmi2SerializedFMUstateSize: size is NULL") : fmi2Error;
    }
    size_t inner = 0;
    fmi2Status status = inner_serialized_size(s, "fmi2SerializedFMUstateSize", w, &inner);
    if (succeeded(status)) {
        *size = SERIAL_HEADER + inner;
    }
    return status;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[], size_t size)
{
    BEGIN(fmi2SerializeFMUstate, c);
    Shim *s = SHIM(c);
    ShimFMUstate *w = fmu_state_of(s, "fmi2SerializeFMUstate", state);
    if (!w) {
        return fmi2Error;
    }
    size_t inner = 0;
    fmi2Status status = inner_serialized_size(s, "fmi2SerializeFMUstate", w, &inner);
    if (!succeeded(status)) {
        return status;
    }
    if (!bytes || size < SERIAL_HEADER + inner) {
        return shim_error(s, "fmi2SerializeFMUstate: the buffer holds %zu bytes, the state needs %zu "
                             "(fmi2SerializedFMUstateSize); nothing was written",
                          bytes ? size : 0, SERIAL_HEADER + inner);
    }
    uint32_t version = SERIAL_VERSION, st = (uint32_t)w->state;
    uint64_t length = inner;
    memcpy(bytes, SERIAL_MAGIC, 8);
    memcpy(bytes + 8, &version, 4);
    memcpy(bytes + 12, &st, 4);
    memcpy(bytes + 16, &w->time, 8);
    memcpy(bytes + 24, &length, 8);
    /* The inner library writes exactly as many bytes as it is told. */
    return shim_end(s, "fmi2SerializeFMUstate",
                    g_api->fmi2SerializeFMUstate(s->inner, w->inner, bytes + SERIAL_HEADER, inner));
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size,
                                   fmi2FMUstate *state)
{
    BEGIN(fmi2DeSerializeFMUstate, c);
    Shim *s = SHIM(c);
    if (!state || (!bytes && size)) {
        return shim_error(s, "fmi2DeSerializeFMUstate: %s is NULL", state ? "bytes" : "state");
    }
    /* The whole header is checked before anything reaches the inner library. */
    if (size < SERIAL_HEADER || memcmp(bytes, SERIAL_MAGIC, 8) != 0) {
        return shim_error(s, "fmi2DeSerializeFMUstate: these %zu bytes are not a serialized state of this FMU: "
                             "they do not decode (no '%s' header), so there is nothing for "
                             "fmi2SetFMUstate to restore", size, SERIAL_MAGIC);
    }
    uint32_t version, st;
    fmi2Real time;
    uint64_t length;
    memcpy(&version, bytes + 8, 4);
    memcpy(&st, bytes + 12, 4);
    memcpy(&time, bytes + 16, 8);
    memcpy(&length, bytes + 24, 8);
    if (version != SERIAL_VERSION) {
        return shim_error(s, "fmi2DeSerializeFMUstate: format version %u, this FMU reads %u", version,
                          SERIAL_VERSION);
    }
    if (!(st & ANY_STATE) || (st & (st - 1)) || !isfinite(time)) {
        return shim_error(s, "fmi2DeSerializeFMUstate: malformed header (state %u, time %g)", st, time);
    }
    /* Our models never end a step with fmi2Discard, so no instance of theirs is ever in
     * 'step failed' to save a state there: such a header is crafted or damaged, and the
     * instance restored from it could take no further step. */
    if (st == ST_STEP_FAILED) {
        return shim_error(s, "fmi2DeSerializeFMUstate: the header says the state was saved in 'step failed', "
                             "which this FMU never enters (a step either completes or is refused with fmi2Error): "
                             "a crafted or damaged state, not restored (the instance would be left where no "
                             "step is allowed)");
    }
    if (length != size - SERIAL_HEADER) {
        return shim_error(s, "fmi2DeSerializeFMUstate: the header announces %llu bytes of state, "
                             "%zu follow: the state is %s", (unsigned long long)length, size - SERIAL_HEADER,
                          length > size - SERIAL_HEADER ? "truncated" : "padded (bytes appended)");
    }
    /* The header's state and time go to the model with its bytes, on a line of their own
     * in front: fmi2SetFMUstate refuses the state unless the model's part agrees with them
     * (a state whose parts disagree would leave the instance contradicting itself). */
    char frame[96];
    uint64_t time_bits; /* the time's bits in hex: exact, and no locale's decimal comma */
    memcpy(&time_bits, &time, sizeof time_bits);
    int framed = snprintf(frame, sizeof frame, "%s %u %016llx\n", SERIAL_FRAME_LINE, st,
                          (unsigned long long)time_bits);
    ShimFMUstate *w = calloc(1, sizeof *w);
    fmi2Byte *inner_bytes = malloc((size_t)framed + (size_t)length);
    if (!w || !inner_bytes || framed <= 0 || (size_t)framed >= sizeof frame) {
        free(w);
        free(inner_bytes);
        return shim_error(s, "fmi2DeSerializeFMUstate: out of memory");
    }
    memcpy(inner_bytes, frame, (size_t)framed);
    memcpy(inner_bytes + framed, bytes + SERIAL_HEADER, (size_t)length);
    fmi2FMUstate inner = NULL;
    fmi2Status status = shim_end(s, "fmi2DeSerializeFMUstate",
                                 g_api->fmi2DeSerializeFMUstate(s->inner, inner_bytes,
                                                                (size_t)framed + (size_t)length, &inner));
    free(inner_bytes);
    if (!succeeded(status)) {
        free(w);
        return status;
    }
    w->magic = STATE_MAGIC;
    w->inner = inner;
    w->state = (int)st;
    w->time = time;
    *state = w;
    return status;
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown[],
                                        size_t nUnknown, const fmi2ValueReference vKnown[],
                                        size_t nKnown, const fmi2Real dvKnown[],
                                        fmi2Real dvUnknown[])
{
    BEGIN(fmi2GetDirectionalDerivative, c);
    Shim *s = SHIM(c);
    const char *function = "fmi2GetDirectionalDerivative";
    if ((nUnknown > 0 && (!vUnknown || !dvUnknown)) || (nKnown > 0 && (!vKnown || !dvKnown))) {
        return shim_error(s, "%s: an array is NULL (%zu unknowns, %zu knowns)", function, nUnknown, nKnown);
    }
    for (size_t i = 0; i < nUnknown + nKnown; i++) {
        fmi2ValueReference vr = i < nUnknown ? vUnknown[i] : vKnown[i - nUnknown];
        if (vr > CHANNEL_INDEX_MAX) {
            return shim_error(s, "%s: value reference %u is no variable of this FMU", function, vr);
        }
    }
    for (size_t i = 0; i < nKnown; i++) {
        if (!isfinite(dvKnown[i])) {
            return shim_error(s, "%s: seed dvKnown[%zu] = %g (value reference %u) is not finite; nothing was "
                                 "computed", function, i, dvKnown[i], vKnown[i]);
        }
    }
    fmi2Status status = channel_set(s, function, CH_SEEDS, vKnown, nKnown, dvKnown);
    if (!succeeded(status)) {
        return status;
    }
    fmi2Status got = channel_get(s, function, CH_DIRECTIONAL, vUnknown, nUnknown, dvUnknown);
    return got > status ? got : status;
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[])
{
    FORWARD(fmi2SetRealInputDerivatives, c, vr, nvr, order, value);
}

/* First derivatives only (the model's rates along its own motion, inputs held: the
 * partials of the directional derivative seeded with the state derivatives).  The FMI 2.0
 * description does not declare them (maxOutputDerivativeOrder 0, so FMI 2 masters are
 * unchanged); the FMI 3 entry (lever_fmi3_shim.c) offers them as fmi3GetOutputDerivatives. */
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[])
{
    BEGIN(fmi2GetRealOutputDerivatives, c);
    Shim *s = SHIM(c);
    const char *function = "fmi2GetRealOutputDerivatives";
    if (nvr > 0 && (!vr || !order || !value)) {
        return shim_error(s, "%s: an array is NULL (%zu values)", function, nvr);
    }
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] > CHANNEL_INDEX_MAX) {
            return shim_error(s, "%s: value reference %u is no variable of this FMU", function, vr[i]);
        }
        if (order[i] != 1) {
            return shim_error(s, "%s: order[%zu] = %d (value reference %u): this FMU gives first derivatives "
                                 "only; nothing was computed", function, i, order[i], vr[i]);
        }
    }
    return nvr ? channel_get(s, function, CH_OUTPUT_RATES, vr, nvr, value) : fmi2OK;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint,
                      fmi2Real communicationStepSize, fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    BEGIN(fmi2DoStep, c);
    Shim *s = SHIM(c);
    fmi2Status status = shim_end(s, "fmi2DoStep",
                                 g_api->fmi2DoStep(s->inner, currentCommunicationPoint,
                                                   communicationStepSize,
                                                   noSetFMUStatePriorToCurrentPoint));
    if (succeeded(status)) {
        s->time = currentCommunicationPoint + communicationStepSize;
    } else if (status == fmi2Discard) {
        s->state = ST_STEP_FAILED;
    }
    /* fmi2Error: the step was refused and nothing changed. */
    return status;
}

fmi2Status fmi2CancelStep(fmi2Component c)
{
    BEGIN(fmi2CancelStep, c); /* no asynchronous step ever runs: always refused */
    return fmi2Error;
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind kind, fmi2Status *value)
{
    BEGIN(fmi2GetStatus, c);
    return shim_error(SHIM(c), "fmi2GetStatus(%d): steps are synchronous, no step is pending",
                      (int)kind);
    (void)value;
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind kind, fmi2Real *value)
{
    BEGIN(fmi2GetRealStatus, c);
    Shim *s = SHIM(c);
    if (kind != fmi2LastSuccessfulTime) {
        return shim_error(s, "fmi2GetRealStatus: status kind %d has no real value", (int)kind);
    }
    if (!value) {
        return shim_error(s, "fmi2GetRealStatus: value is NULL");
    }
    *value = s->time;
    return fmi2OK;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind kind, fmi2Integer *value)
{
    BEGIN(fmi2GetIntegerStatus, c);
    (void)value;
    return shim_error(SHIM(c), "fmi2GetIntegerStatus: status kind %d has no integer value", (int)kind);
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind kind, fmi2Boolean *value)
{
    BEGIN(fmi2GetBooleanStatus, c);
    Shim *s = SHIM(c);
    if (kind != fmi2Terminated) {
        return shim_error(s, "fmi2GetBooleanStatus: status kind %d has no boolean value", (int)kind);
    }
    if (!value) {
        return shim_error(s, "fmi2GetBooleanStatus: value is NULL");
    }
    *value = fmi2False; /* our slaves never ask to end the simulation */
    return fmi2OK;
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind kind, fmi2String *value)
{
    BEGIN(fmi2GetStringStatus, c);
    (void)value;
    return shim_error(SHIM(c), "fmi2GetStringStatus: status kind %d has no string value", (int)kind);
}

/* ------------------------------------------------------------------------- */
/* FMI 2.0 Model Exchange                                                     */
/* ------------------------------------------------------------------------- */

fmi2Status fmi2EnterEventMode(fmi2Component c)
{
    BEGIN(fmi2EnterEventMode, c);
    SHIM(c)->state = ST_EVENT_MODE;
    SHIM(c)->statesKnown = 0; /* an event may move the states */
    return fmi2OK;
}

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *info)
{
    BEGIN(fmi2NewDiscreteStates, c);
    Shim *s = SHIM(c);
    if (!info) {
        return shim_error(s, "fmi2NewDiscreteStates: fmi2EventInfo is NULL");
    }
    fmi2ValueReference command = CONTROL_COMMAND;
    fmi2Real code = COMMAND_NEW_DISCRETE_STATES;
    fmi2Status status = channel_set(s, "fmi2NewDiscreteStates", CH_CONTROL, &command, 1, &code);
    if (!succeeded(status)) {
        return status;
    }
    fmi2Real fields[EVENT_INFO_FIELDS];
    fmi2Status got = channel_get(s, "fmi2NewDiscreteStates", CH_EVENT_INFO, NULL, EVENT_INFO_FIELDS, fields);
    if (!succeeded(got)) {
        return got;
    }
    info->newDiscreteStatesNeeded = fields[0] != 0.0;
    info->terminateSimulation = fields[1] != 0.0;
    info->nominalsOfContinuousStatesChanged = fields[2] != 0.0;
    info->valuesOfContinuousStatesChanged = fields[3] != 0.0;
    info->nextEventTimeDefined = fields[4] != 0.0;
    info->nextEventTime = fields[5];
    return got > status ? got : status;
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c)
{
    BEGIN(fmi2EnterContinuousTimeMode, c);
    SHIM(c)->state = ST_CONTINUOUS_TIME;
    SHIM(c)->statesKnown = 0; /* known again once the host sets them */
    return fmi2OK;
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation)
{
    BEGIN(fmi2CompletedIntegratorStep, c);
    (void)noSetFMUStatePriorToCurrentPoint;
    if (!enterEventMode || !terminateSimulation) {
        return shim_error(SHIM(c), "fmi2CompletedIntegratorStep: %s is NULL",
                          enterEventMode ? "terminateSimulation" : "enterEventMode");
    }
    /* no step events: the models' events are state and time events */
    *enterEventMode = fmi2False;
    *terminateSimulation = fmi2False;
    return fmi2OK;
}

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time)
{
    BEGIN(fmi2SetTime, c);
    Shim *s = SHIM(c);
    if (!isfinite(time)) {
        return shim_error(s, "fmi2SetTime: time %g is not finite; the time stays %.17g s", time, s->time);
    }
    if (s->point) {
        s->time = s->point[1] = time;
        POINT_PENDING(s, POINT_TIME);
        return fmi2OK;
    }
    fmi2ValueReference control = CONTROL_TIME;
    fmi2Status status = channel_set(s, "fmi2SetTime", CH_CONTROL, &control, 1, &time);
    if (succeeded(status)) {
        s->time = time;
    }
    return status;
}

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx)
{
    BEGIN(fmi2SetContinuousStates, c);
    Shim *s = SHIM(c);
    if (!me_array(s, "fmi2SetContinuousStates", x, nx, s->nx, "states")) {
        return fmi2Error;
    }
    for (size_t i = 0; i < nx; i++) {
        if (!isfinite(x[i])) {
            return shim_error(s, "fmi2SetContinuousStates: x[%zu] = %g is not finite; no state was set", i, x[i]);
        }
    }
    if (s->point) {
        if (nx) {
            memcpy(s->point + POINT_HEADER, x, nx * sizeof *x);
        }
        POINT_PENDING(s, POINT_STATES);
        s->statesKnown = 1;
        return fmi2OK;
    }
    return channel_set(s, "fmi2SetContinuousStates", CH_STATES, NULL, nx, x);
}

/* The Model Exchange getters of one array. */
#define ME_GETTER(name, kind, count, what)                                                         \
    fmi2Status name(fmi2Component c, fmi2Real out[], size_t n)                                     \
    {                                                                                              \
        BEGIN(name, c);                                                                            \
        Shim *s = SHIM(c);                                                                         \
        if (!me_array(s, #name, out, n, s->count, what)) return fmi2Error;                         \
        return n ? channel_get(s, #name, kind, NULL, n, out) : fmi2OK;                             \
    }

ME_GETTER(fmi2GetDerivatives, CH_DERIVATIVES, nx, "derivatives")
ME_GETTER(fmi2GetEventIndicators, CH_INDICATORS, nz, "event indicators")
ME_GETTER(fmi2GetContinuousStates, CH_STATES, nx, "states")
ME_GETTER(fmi2GetNominalsOfContinuousStates, CH_NOMINALS, nx, "nominals")

fmi2Status leverGetEventIndicatorValues(fmi2Component c, fmi2Real out[], size_t n)
{
    /* Named after the call it serves, as the FMI 3.0 entry renames it: fmi3GetFloat64. */
    static const char function[] = "fmi2GetReal of the event indicators";
    Shim *s = SHIM(c);
    if (!shim_begin(s, function, s && s->me ? MEMASK_leverGetEventIndicatorValues
                                            : MASK_leverGetEventIndicatorValues)) return fmi2Error;
    if (!s->nzKnown) {
        fmi2ValueReference size = SIZE_INDICATORS;
        fmi2Real nz = 0.0;
        fmi2Status status = channel_get(s, function, CH_CONTROL, &size, 1, &nz);
        if (!succeeded(status)) {
            return status;
        }
        if (!(nz >= 0.0 && nz < 1e6)) {
            return shim_error(s, "%s: the model reports %g event indicators", function, nz);
        }
        s->nz = (size_t)nz;
        s->nzKnown = 1;
    }
    if (!me_array(s, function, out, n, s->nz, "event indicators")) return fmi2Error;
    return n ? channel_get(s, function, CH_INDICATORS, NULL, n, out) : fmi2OK;
}
