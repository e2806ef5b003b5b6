/* FMI 2.0 co-simulation shim: makes a pythonfmu FMU loadable by a host without Python.
 *
 * pythonfmu's C wrapper (libpythonfmu-export.so) calls the Python C API but is not linked
 * with libpython: it only loads in a process that already has Python's symbols (a
 * Python host such as FMPy).  fmus.build puts this shim in its place as
 * binaries/<platform>/<modelIdentifier>.so and the wrapper next to it as
 * <modelIdentifier>_pythonfmu.so.  At the first fmi2Instantiate the shim
 *
 *   1. reads resources/xpanel_python.cfg (written at build time: the Python that built the
 *      FMU: its executable, its libpython, the folders with numpy and scipy);
 *   2. finds Python's C API: in the process already (a Python host), else by dlopen()ing
 *      with RTLD_GLOBAL, in this order, $XPANEL_FMU_LIBPYTHON, the recorded libpython,
 *      the recorded library's file name on the loader's search path;
 *   3. if Python is not initialised, initialises it as that Python would start
 *      (program name = $XPANEL_FMU_PYTHON or the recorded executable, so that its venv and
 *      site-packages are found; no signal handlers), adds the recorded folders to sys.path
 *      if missing, and releases the GIL (the wrapper takes it with PyGILState_Ensure);
 *   4. dlopen()s the wrapper and forwards every fmi2 function to it.
 *
 * Python is never finalised and no library is ever unloaded (the host may exit while
 * instances live; extension modules cannot be unloaded safely).  pythonfmu's wrapper
 * finalises the interpreter only when it initialised it itself, which it no longer does;
 * its exit-time use-after-free is avoided by release_wrapper_state (see there).
 * fmi2GetTypesPlatform and fmi2GetVersion answer without loading anything.  Errors go to
 * the host's logger callback (with a NULL callback: stderr).
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <limits.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <wchar.h>

#include "fmi2Functions.h"

#define CONFIG_FILE "xpanel_python.cfg"
#define WRAPPER_SUFFIX "_pythonfmu.so"
#define MAX_PATHS 16
#define MAX_LINE 4096
#define MAX_MESSAGE 8192

/* ---------------------------------------------------------------- the wrapper's API */
#define CS_FUNCTIONS(X) \
    X(fmi2SetDebugLogging) X(fmi2Instantiate) X(fmi2FreeInstance) X(fmi2SetupExperiment) \
    X(fmi2EnterInitializationMode) X(fmi2ExitInitializationMode) X(fmi2Terminate) X(fmi2Reset) \
    X(fmi2GetReal) X(fmi2GetInteger) X(fmi2GetBoolean) X(fmi2GetString) \
    X(fmi2SetReal) X(fmi2SetInteger) X(fmi2SetBoolean) X(fmi2SetString) \
    X(fmi2GetFMUstate) X(fmi2SetFMUstate) X(fmi2FreeFMUstate) X(fmi2SerializedFMUstateSize) \
    X(fmi2SerializeFMUstate) X(fmi2DeSerializeFMUstate) X(fmi2GetDirectionalDerivative) \
    X(fmi2SetRealInputDerivatives) X(fmi2GetRealOutputDerivatives) X(fmi2DoStep) X(fmi2CancelStep) \
    X(fmi2GetStatus) X(fmi2GetRealStatus) X(fmi2GetIntegerStatus) X(fmi2GetBooleanStatus) \
    X(fmi2GetStringStatus)

#define MEMBER(name) name##TYPE *name;
static struct { CS_FUNCTIONS(MEMBER) } api;
#undef MEMBER

/* Python C API functions the shim calls (stable since Python 3.2; Py_SetProgramName is
 * deprecated since 3.11 and optional here) */
typedef int (*IsInitializedF)(void);
typedef void (*InitializeExF)(int);
typedef void (*SetProgramNameF)(const wchar_t *);
typedef wchar_t *(*DecodeLocaleF)(const char *, size_t *);
typedef int (*RunSimpleStringF)(const char *);
typedef void *(*SaveThreadF)(void);
typedef void (*FinalizeF)(void);

static pthread_mutex_t lock = PTHREAD_MUTEX_INITIALIZER;
static int loaded = 0;                 /* 1: api filled */
static char failure[MAX_MESSAGE];      /* why loading failed (reported at every instantiate) */
static FinalizeF wrapper_finalize = NULL;

typedef struct {
    char executable[PATH_MAX];
    char libpython[PATH_MAX];
    char paths[MAX_PATHS][PATH_MAX];
    int n_paths;
    char fmu[256];                     /* "the track FMU" */
} Config;

static void report(const fmi2CallbackFunctions *cb, fmi2String name, fmi2Status status, const char *msg) {
    if (cb && cb->logger)
        cb->logger(cb->componentEnvironment, name, status, status == fmi2Warning ? "logStatusWarning"
                   : "logStatusError", "%s", msg);
    else
        fprintf(stderr, "%s: %s\n", name ? name : "FMU", msg);
}

/* dir of this shared object, "binaries/<platform>" */
static int own_path(char *out, size_t size) {
    Dl_info info;
    if (!dladdr((void *)&report, &info) || !info.dli_fname) return -1;
    if (!realpath(info.dli_fname, out)) {   /* out has PATH_MAX bytes */
        if (strlen(info.dli_fname) >= size) return -1;
        strcpy(out, info.dli_fname);
    }
    return 0;
}

static void strip(char *s) {
    size_t n = strlen(s);
    while (n && (s[n - 1] == '\n' || s[n - 1] == '\r' || s[n - 1] == ' ')) s[--n] = '\0';
}

static int read_config(const char *file, Config *cfg) {
    char line[MAX_LINE];
    FILE *f = fopen(file, "r");
    memset(cfg, 0, sizeof *cfg);
    strcpy(cfg->fmu, "this FMU");
    if (!f) return -1;
    while (fgets(line, sizeof line, f)) {
        char *eq = strchr(line, '=');
        strip(line);
        if (line[0] == '#' || !eq) continue;
        *eq = '\0';
        if (strlen(eq + 1) >= PATH_MAX) continue;
        if (strcmp(line, "executable") == 0) strcpy(cfg->executable, eq + 1);
        else if (strcmp(line, "libpython") == 0) strcpy(cfg->libpython, eq + 1);
        else if (strcmp(line, "path") == 0 && cfg->n_paths < MAX_PATHS) strcpy(cfg->paths[cfg->n_paths++], eq + 1);
        else if (strcmp(line, "fmu") == 0 && strlen(eq + 1) < sizeof cfg->fmu) strcpy(cfg->fmu, eq + 1);
    }
    fclose(f);
    return 0;
}

/* a Python bytes literal of s, every byte escaped: safe for any path */
static void py_literal(char *out, const char *s) {
    out += sprintf(out, "b'");
    for (; *s; s++) out += sprintf(out, "\\x%02x", (unsigned char)*s);
    sprintf(out, "'.decode('utf-8', 'surrogateescape')");
}

static void *python_symbol(void *lib, const char *name) {
    return lib ? dlsym(lib, name) : dlsym(RTLD_DEFAULT, name);
}

/* Find Python's C API, initialise the interpreter if needed; 0 on success, else message in failure */
static int load_python(const Config *cfg) {
    void *lib = NULL;
    char tried[MAX_MESSAGE] = "";
    const char *candidates[3];
    int i, n = 0;
    IsInitializedF is_initialized = (IsInitializedF)dlsym(RTLD_DEFAULT, "Py_IsInitialized");

    if (!is_initialized) {                     /* no Python in the process yet */
        const char *env = getenv("XPANEL_FMU_LIBPYTHON");
        const char *base = strrchr(cfg->libpython, '/');
        if (env && *env) candidates[n++] = env;
        if (cfg->libpython[0]) candidates[n++] = cfg->libpython;
        if (base) candidates[n++] = base + 1; /* by file name on the loader's search path */
        for (i = 0; i < n && !lib; i++) {
            lib = dlopen(candidates[i], RTLD_NOW | RTLD_GLOBAL);
            if (!lib) {
                size_t used = strlen(tried);
                snprintf(tried + used, sizeof tried - used, "%s%s", used ? "; " : "", dlerror());
            }
        }
        if (!lib) {
            snprintf(failure, sizeof failure,
                     "%s needs the Python it was built with (%s, numpy, scipy) and could not load its "
                     "library: %s. Set XPANEL_FMU_LIBPYTHON to a libpython%s and XPANEL_FMU_PYTHON to "
                     "that Python's executable, or rebuild the FMU with that Python (turnout build-fmus)",
                     cfg->fmu, cfg->executable[0] ? cfg->executable : "unknown", n ? tried : "none recorded",
                     " of the same version");
            return -1;
        }
        is_initialized = (IsInitializedF)dlsym(lib, "Py_IsInitialized");
        if (!is_initialized) {
            snprintf(failure, sizeof failure, "%s: %s is not a Python library (no Py_IsInitialized)",
                     cfg->fmu, candidates[i - 1]);
            return -1;
        }
    }
    if (!is_initialized()) {
        InitializeExF initialize = (InitializeExF)python_symbol(lib, "Py_InitializeEx");
        SetProgramNameF set_program = (SetProgramNameF)python_symbol(lib, "Py_SetProgramName");
        DecodeLocaleF decode = (DecodeLocaleF)python_symbol(lib, "Py_DecodeLocale");
        RunSimpleStringF run = (RunSimpleStringF)python_symbol(lib, "PyRun_SimpleString");
        SaveThreadF save_thread = (SaveThreadF)python_symbol(lib, "PyEval_SaveThread");
        const char *env = getenv("XPANEL_FMU_PYTHON");
        const char *executable = env && *env ? env : cfg->executable;
        static char code[MAX_PATHS * PATH_MAX * 5 + 1024];
        char *p = code;

        if (!initialize || !decode || !run || !save_thread) {
            snprintf(failure, sizeof failure, "%s: the Python library lacks Py_InitializeEx, "
                     "Py_DecodeLocale, PyRun_SimpleString or PyEval_SaveThread", cfg->fmu);
            return -1;
        }
        if (set_program && executable[0]) {
            static wchar_t *program = NULL;    /* must outlive the interpreter */
            program = decode(executable, NULL);
            if (program) set_program(program);
        }
        initialize(0);                         /* 0: leave the host's signal handlers alone */
        /* the recorded folders (numpy, scipy, site-packages) if the start did not find them */
        p += sprintf(p, "import sys, site\nif not hasattr(sys, 'argv'):\n    sys.argv = ['']\n"
                        "for _d in [");
        for (i = 0; i < cfg->n_paths; i++) {
            py_literal(p, cfg->paths[i]);
            p += strlen(p);
            *p++ = ',';
        }
        sprintf(p, "]:\n    if _d not in sys.path:\n        site.addsitedir(_d)\ndel _d\n");
        if (run(code) != 0) {
            snprintf(failure, sizeof failure, "%s: setting up sys.path of the embedded Python failed",
                     cfg->fmu);
            return -1;
        }
        save_thread();                         /* release the GIL; never taken back: never finalised */
    }
    return 0;
}

/* pythonfmu 0.7's wrapper keeps its interpreter state in a static std::shared_ptr and
 * also releases it in finalizePythonInterpreter, a library destructor that runs after the
 * static destructors at exit: it then decrements the use count inside the block the
 * shared_ptr destructor has freed, a write into freed heap memory that glibc detects later
 * ("free(): corrupted unsorted chunks", in scipy's libgfortran destructor).  Calling it
 * once before the static destructors releases the state cleanly and leaves a null pointer
 * to both destructors.  (Python stays initialised: the state's destructor finalises
 * Python only when the wrapper initialised it, never after this shim did.) */
static void release_wrapper_state(void) {
    if (wrapper_finalize) wrapper_finalize();
}

static int load(const fmi2CallbackFunctions *cb, fmi2String name) {
    char self[PATH_MAX], file[PATH_MAX + 64];
    char *slash, *dot;
    Config cfg;
    void *wrapper;

    if (own_path(self, sizeof self) != 0) {
        snprintf(failure, sizeof failure, "FMU shim: cannot locate its own shared library (dladdr)");
        return -1;
    }
    slash = strrchr(self, '/');
    *slash = '\0';                             /* self = .../binaries/<platform> */
    snprintf(file, sizeof file, "%s/../../resources/" CONFIG_FILE, self);
    if (read_config(file, &cfg) != 0)
        report(cb, name, fmi2Warning, "FMU shim: resources/" CONFIG_FILE
               " not found: using the Python found on the loader's search path");
    if (load_python(&cfg) != 0) return -1;

    *slash = '/';
    dot = strrchr(slash, '.');
    if (dot) *dot = '\0';
    snprintf(file, sizeof file, "%s" WRAPPER_SUFFIX, self);
    wrapper = dlopen(file, RTLD_NOW | RTLD_LOCAL);
    if (!wrapper) {
        snprintf(failure, sizeof failure, "%s: cannot load pythonfmu's wrapper: %s", cfg.fmu, dlerror());
        return -1;
    }
#define FIND(fn) api.fn = (fn##TYPE *)dlsym(wrapper, #fn);
    CS_FUNCTIONS(FIND)
#undef FIND
    if (!api.fmi2Instantiate || !api.fmi2DoStep) {
        snprintf(failure, sizeof failure, "%s: %s lacks fmi2Instantiate or fmi2DoStep", cfg.fmu, file);
        return -1;
    }
    /* registered after the wrapper's static constructors: runs before its static destructors */
    wrapper_finalize = (FinalizeF)dlsym(wrapper, "finalizePythonInterpreter");
    if (wrapper_finalize) atexit(release_wrapper_state);
    return 0;
}

/* ------------------------------------------------------------------- fmi2 functions */
const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
    int ok;
    pthread_mutex_lock(&lock);
    if (!loaded && !failure[0]) loaded = load(functions, instanceName) == 0;
    ok = loaded;
    pthread_mutex_unlock(&lock);
    if (!ok) {
        report(functions, instanceName, fmi2Error, failure);
        return NULL;
    }
    return api.fmi2Instantiate(instanceName, fmuType, fmuGUID, fmuResourceLocation, functions, visible,
                               loggingOn);
}

void fmi2FreeInstance(fmi2Component c) {
    if (api.fmi2FreeInstance) api.fmi2FreeInstance(c);
}

#define FORWARD(fn, params, args) \
    fmi2Status fn params { return api.fn ? api.fn args : fmi2Error; }

FORWARD(fmi2SetDebugLogging, (fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cat[]),
        (c, on, n, cat))
FORWARD(fmi2SetupExperiment, (fmi2Component c, fmi2Boolean tol_on, fmi2Real tol, fmi2Real t0,
                              fmi2Boolean stop_on, fmi2Real t1), (c, tol_on, tol, t0, stop_on, t1))
FORWARD(fmi2EnterInitializationMode, (fmi2Component c), (c))
FORWARD(fmi2ExitInitializationMode, (fmi2Component c), (c))
FORWARD(fmi2Terminate, (fmi2Component c), (c))
FORWARD(fmi2Reset, (fmi2Component c), (c))
FORWARD(fmi2GetReal, (fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]), (c, vr, n, v))
FORWARD(fmi2GetInteger, (fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]),
        (c, vr, n, v))
FORWARD(fmi2GetBoolean, (fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]),
        (c, vr, n, v))
FORWARD(fmi2GetString, (fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[]),
        (c, vr, n, v))
FORWARD(fmi2SetReal, (fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real v[]),
        (c, vr, n, v))
FORWARD(fmi2SetInteger, (fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]),
        (c, vr, n, v))
FORWARD(fmi2SetBoolean, (fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[]),
        (c, vr, n, v))
FORWARD(fmi2SetString, (fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String v[]),
        (c, vr, n, v))
FORWARD(fmi2GetFMUstate, (fmi2Component c, fmi2FMUstate *s), (c, s))
FORWARD(fmi2SetFMUstate, (fmi2Component c, fmi2FMUstate s), (c, s))
FORWARD(fmi2FreeFMUstate, (fmi2Component c, fmi2FMUstate *s), (c, s))
FORWARD(fmi2SerializedFMUstateSize, (fmi2Component c, fmi2FMUstate s, size_t *size), (c, s, size))
FORWARD(fmi2SerializeFMUstate, (fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t size), (c, s, b, size))
FORWARD(fmi2DeSerializeFMUstate, (fmi2Component c, const fmi2Byte b[], size_t size, fmi2FMUstate *s),
        (c, b, size, s))
FORWARD(fmi2GetDirectionalDerivative, (fmi2Component c, const fmi2ValueReference vu[], size_t nu,
                                       const fmi2ValueReference vk[], size_t nk, const fmi2Real dk[],
                                       fmi2Real du[]), (c, vu, nu, vk, nk, dk, du))
FORWARD(fmi2SetRealInputDerivatives, (fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                      const fmi2Integer order[], const fmi2Real v[]), (c, vr, n, order, v))
FORWARD(fmi2GetRealOutputDerivatives, (fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                       const fmi2Integer order[], fmi2Real v[]), (c, vr, n, order, v))
FORWARD(fmi2DoStep, (fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean no_prior), (c, t, h, no_prior))
FORWARD(fmi2CancelStep, (fmi2Component c), (c))
FORWARD(fmi2GetStatus, (fmi2Component c, const fmi2StatusKind s, fmi2Status *v), (c, s, v))
FORWARD(fmi2GetRealStatus, (fmi2Component c, const fmi2StatusKind s, fmi2Real *v), (c, s, v))
FORWARD(fmi2GetIntegerStatus, (fmi2Component c, const fmi2StatusKind s, fmi2Integer *v), (c, s, v))
FORWARD(fmi2GetBooleanStatus, (fmi2Component c, const fmi2StatusKind s, fmi2Boolean *v), (c, s, v))
FORWARD(fmi2GetStringStatus, (fmi2Component c, const fmi2StatusKind s, fmi2String *v), (c, s, v))
