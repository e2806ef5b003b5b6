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
 *
 * Fast path (XpanelFast below).  Every fmi2 call that enters Python costs microseconds
 * (pythonfmu's wrapper takes the GIL and calls the slave's methods), several times a
 * step.  A slave may register, for its instance, a compiled step function (a numba cfunc
 * or xpanel_lti_step below), the value references of its per-step inputs and outputs
 * with the buffers that hold them, and two callbacks into Python: `load` (make the
 * buffers hold the state; returns 1 if compiled steps may run) and `sync` (hand the
 * buffers' state back to the Python objects).  Then fmi2SetReal of those inputs and
 * fmi2GetReal of those outputs are copies here, and fmi2DoStep calls the step function
 * without entering Python.  The step function returns 0 when it took the step, 2 when data
 * must be loaded first (`load` is called, the buffers stay current, and the step is tried
 * again: a wheel entering a rail element), anything else when Python must take it (nothing
 * changed): what it does not handle (a bad input, a failing step, ...).  Outputs that cost
 * something to evaluate (the track's sensors) may be registered as lazy: the first read of
 * them after a step calls the registered `lazy` function, which fills their buffer.
 * Before any other call is forwarded to Python, `sync` runs, so the slave always sees
 * the state the steps reached; the next fast step calls `load` again.
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <limits.h>
#include <pthread.h>
#include <stdint.h>
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


/* ---------------------------------------------------------------- fast path (see the top) */
typedef int (*XpanelStepF)(void *ctx, double t, double h);
typedef int (*XpanelCallF)(void);

typedef struct {                       /* as fmus/fast.py's ctypes structure, field by field */
    void *ctx;                         /* the step function's argument */
    XpanelStepF step;
    XpanelCallF load, sync;
    int64_t n_in, n_out;
    const uint32_t *in_vr, *out_vr;    /* fmi2SetReal of in_vr[k] writes in_buf[k] ... */
    double *in_buf;
    const double *out_buf;             /* ... fmi2GetReal of out_vr[k] reads out_buf[k] */
    int64_t *mode;                     /* 1: the buffers hold the state (fast steps), 0: Python does */
    XpanelStepF lazy;                  /* out_buf[n_eager:] are evaluated by lazy(ctx, 0, 0) when read */
    int64_t n_eager;                   /* (0 from lazy: done; else Python answers the read) */
} XpanelFast;

#define MAX_FAST 64
/* Slots never move: a thread stepping one instance reads its slot while another registers or drops
 * another instance (hosts such as libcosim step FMUs in parallel threads); changes are under `lock`. */
static struct { fmi2Component c; XpanelFast f; } fast_table[MAX_FAST];
static int n_fast = 0;                          /* slots in use, for a quick "none at all" */
static __thread fmi2Component serving = NULL;   /* the instance of the call being forwarded */

static XpanelFast *fast_of(fmi2Component c) {
    int i;
    if (!c) return NULL;               /* free slots hold NULL */
    for (i = 0; i < MAX_FAST; i++)
        if (fast_table[i].c == c) return &fast_table[i].f;
    return NULL;
}

static void fast_clear(int i) {                 /* under lock */
    fast_table[i].c = NULL;
    memset(&fast_table[i].f, 0, sizeof fast_table[i].f);
    n_fast--;
}

static void fast_drop(fmi2Component c) {
    int i;
    pthread_mutex_lock(&lock);
    for (i = 0; c && i < MAX_FAST; i++)
        if (fast_table[i].c == c) fast_clear(i);
    pthread_mutex_unlock(&lock);
}

/* Called by the slave's Python during a forwarded call: registers the fast path of the instance
 * being served (a copy of *spec; the buffers must live until it is dropped).  0 on success. */
int xpanel_fast_register(const XpanelFast *spec) {
    XpanelFast *f;
    int rc = 0;
    if (!serving || !spec || !spec->step || !spec->load || !spec->sync || !spec->mode) return -1;
    pthread_mutex_lock(&lock);
    f = fast_of(serving);
    if (!f) {
        int i;
        for (i = 0; i < MAX_FAST && fast_table[i].c; i++) {}
        if (i < MAX_FAST) {
            fast_table[i].f = *spec;
            fast_table[i].c = serving;
            n_fast++;
            f = &fast_table[i].f;
        }
    } else {
        *f = *spec;
    }
    if (!f) rc = -2;                   /* table full: this instance steps in Python */
    pthread_mutex_unlock(&lock);
    return rc;
}

/* Drops the registration whose `mode` flag is `mode` (the slave's Python object is going away:
 * fmi2Reset and fmi2FreeInstance make pythonfmu drop it, and its buffers and callbacks with it). */
int xpanel_fast_forget(const int64_t *mode) {
    int i;
    pthread_mutex_lock(&lock);
    for (i = 0; mode && i < MAX_FAST; i++)
        if (fast_table[i].c && fast_table[i].f.mode == mode) fast_clear(i);
    pthread_mutex_unlock(&lock);
    return 0;
}

/* before a call enters Python: the slave must see the state the fast steps reached */
static XpanelFast *enter(fmi2Component c) {
    XpanelFast *f = n_fast ? fast_of(c) : NULL;
    serving = c;
    if (f && *f->mode) f->sync();      /* sets *mode = 0 */
    return f;
}

static int index_of(const uint32_t *list, int64_t n, fmi2ValueReference vr) {
    int64_t k;
    for (k = 0; k < n; k++)
        if (list[k] == vr) return (int)k;
    return -1;
}

/* A linear discrete-time system as a step function (the vehicle's exact zoh step): ctx is
 * LtiStep.  y <- G [y | u | 1] (u = the inputs), then out = Y y + off + tco * t_end. */
typedef struct {
    int64_t ny, nz, nout;              /* len(y), len(z) = ny + nu + 1, len(out) */
    double *G, *z, *ynew, *Y, *off, *tco, *out;   /* G (ny, nz), Y (nout, ny), C order */
    double *u_in;                      /* the input buffer, copied into z[ny:ny+nu] */
    double h, rtol;                    /* the step the matrices are for, its tolerance */
    double *time;                      /* the slave's time, advanced */
    int64_t steps;                     /* steps taken (the slave reads and clears it) */
} LtiStep;

int xpanel_lti_step(void *ctx, double t, double h) {
    LtiStep *s = (LtiStep *)ctx;
    int64_t i, j, nu = s->nz - s->ny - 1;
    double d = h - s->h, acc;
    if (!(h > 0.0) || (d < 0 ? -d : d) > s->rtol * s->h) return 1;   /* another step: Python */
    for (i = 0; i < nu; i++)
        if (s->u_in[i] - s->u_in[i] != 0.0) return 1;                 /* NaN or inf: Python (nothing changed) */
    for (i = 0; i < nu; i++) s->z[s->ny + i] = s->u_in[i];
    for (i = 0; i < s->ny; i++) {
        acc = 0.0;
        for (j = 0; j < s->nz; j++) acc += s->G[i * s->nz + j] * s->z[j];
        s->ynew[i] = acc;
    }
    for (i = 0; i < s->ny; i++) s->z[i] = s->ynew[i];
    *s->time = t + h;
    s->steps++;
    for (i = 0; i < s->nout; i++) {
        acc = 0.0;
        for (j = 0; j < s->ny; j++) acc += s->Y[i * s->ny + j] * s->z[j];
        s->out[i] = acc + s->off[i] + s->tco[i] * *s->time;
    }
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
    enter(c);
    fast_drop(c);
    if (api.fmi2FreeInstance) api.fmi2FreeInstance(c);
    serving = NULL;
}

#define FORWARD(fn, params, args) \
    fmi2Status fn params { enter(c); return api.fn ? api.fn args : fmi2Error; }

FORWARD(fmi2SetDebugLogging, (fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cat[]),
        (c, on, n, cat))
FORWARD(fmi2SetupExperiment, (fmi2Component c, fmi2Boolean tol_on, fmi2Real tol, fmi2Real t0,
                              fmi2Boolean stop_on, fmi2Real t1), (c, tol_on, tol, t0, stop_on, t1))
FORWARD(fmi2EnterInitializationMode, (fmi2Component c), (c))
FORWARD(fmi2ExitInitializationMode, (fmi2Component c), (c))
FORWARD(fmi2Terminate, (fmi2Component c), (c))
fmi2Status fmi2Reset(fmi2Component c) {   /* pythonfmu makes a new Python object: its own registration */
    enter(c);
    fast_drop(c);
    return api.fmi2Reset ? api.fmi2Reset(c) : fmi2Error;
}
FORWARD(fmi2GetInteger, (fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]),
        (c, vr, n, v))
FORWARD(fmi2GetBoolean, (fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]),
        (c, vr, n, v))
FORWARD(fmi2GetString, (fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[]),
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
FORWARD(fmi2CancelStep, (fmi2Component c), (c))
FORWARD(fmi2GetStatus, (fmi2Component c, const fmi2StatusKind s, fmi2Status *v), (c, s, v))
FORWARD(fmi2GetRealStatus, (fmi2Component c, const fmi2StatusKind s, fmi2Real *v), (c, s, v))
FORWARD(fmi2GetIntegerStatus, (fmi2Component c, const fmi2StatusKind s, fmi2Integer *v), (c, s, v))
FORWARD(fmi2GetBooleanStatus, (fmi2Component c, const fmi2StatusKind s, fmi2Boolean *v), (c, s, v))
FORWARD(fmi2GetStringStatus, (fmi2Component c, const fmi2StatusKind s, fmi2String *v), (c, s, v))

/* fmi2GetReal, fmi2SetReal, fmi2DoStep: the fast path when registered (see the top) */
fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]) {
    XpanelFast *f = n_fast ? fast_of(c) : NULL;
    if (f && *f->mode) {
        size_t k;
        int j, evaluated = 0;
        for (k = 0; k < n; k++) {
            if ((j = index_of(f->out_vr, f->n_out, vr[k])) < 0) break;
            if (j >= f->n_eager && !evaluated) {
                if (!f->lazy || f->lazy(f->ctx, 0.0, 0.0) != 0) break;
                evaluated = 1;
            }
            v[k] = f->out_buf[j];
        }
        if (k == n) return fmi2OK;
    }
    enter(c);
    return api.fmi2GetReal ? api.fmi2GetReal(c, vr, n, v) : fmi2Error;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real v[]) {
    XpanelFast *f = n_fast ? fast_of(c) : NULL;
    if (f) {                           /* the inputs' buffers are the slave's own input arrays */
        size_t k;
        for (k = 0; k < n; k++)
            if (index_of(f->in_vr, f->n_in, vr[k]) < 0) break;
        if (k == n) {
            for (k = 0; k < n; k++) f->in_buf[index_of(f->in_vr, f->n_in, vr[k])] = v[k];
            return fmi2OK;
        }
    }
    enter(c);
    return api.fmi2SetReal ? api.fmi2SetReal(c, vr, n, v) : fmi2Error;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean no_prior) {
    XpanelFast *f = n_fast ? fast_of(c) : NULL;
    serving = c;                       /* `load` may register again (new buffers) */
    if (f && (*f->mode || f->load() == 1)) {
        int r = 1, tries = 0;
        f = fast_of(c);
        if (f) r = f->step(f->ctx, t, h);
        /* 2: data to load first (the buffers stay current: load only loads them) */
        while (r == 2 && tries++ < 16 && f->load() == 1 && (f = fast_of(c)) != NULL)
            r = f->step(f->ctx, t, h);
        if (r == 0) return fmi2OK;
    }
    enter(c);                          /* Python takes the step (after sync) */
    return api.fmi2DoStep ? api.fmi2DoStep(c, t, h, no_prior) : fmi2Error;
}
