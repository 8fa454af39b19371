/* graspcore._core: the one CPython binding of the C core, for the stable ABI (3.11+).
 * Thin on purpose: argument conversion, status -> exception, GIL released while stepping,
 * zero-copy array views through the buffer protocol. What repeats is written once as a table:
 * keyword parameters, stats and contact dicts (Field rows), accessors (X-macro rows), enum
 * names; docs/architecture.md "Binding" says how to add to each. Friendlier argument handling
 * (numpy conversion, inertia forms) lives in graspcore/__init__.py. */
#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include <stdatomic.h>
#include <limits.h>
#include <stddef.h>
#include <string.h>

#include "graspcore.h"

typedef struct {
    PyObject_HEAD
    gcWorld *world;
    atomic_int busy; /* set while a step runs without the GIL */
} WorldObject;

typedef struct {
    PyObject_HEAD
    PyObject *owner; /* keeps the world alive while the view exists */
    const double *data;
    Py_ssize_t shape[2];
    Py_ssize_t strides[2];
} ViewObject;

static PyObject *World_Type, *View_Type;

/* ---- helpers ------------------------------------------------------------------- */

/* The one map from the core's error statuses to Python exceptions. The message is always
 * the core's own (gc_world_last_error / gc_world_create_error), which names the argument. */
static PyObject *exception_for(gcStatus st) {
    static const struct { gcStatus status; PyObject **type; } table[] = {
        {GC_ERR_INVALID_ARGUMENT, &PyExc_ValueError}, {GC_ERR_DEGENERATE, &PyExc_ValueError},
        {GC_ERR_UNKNOWN_ID, &PyExc_ValueError},       {GC_ERR_CAPACITY, &PyExc_ValueError},
        {GC_ERR_NO_MEMORY, &PyExc_MemoryError},       {GC_ERR_BUSY, &PyExc_RuntimeError},
        {GC_ERR_NOT_RUNNING, &PyExc_RuntimeError},
    };
    for (size_t i = 0; i < sizeof table / sizeof table[0]; ++i)
        if (table[i].status == st) return *table[i].type;
    return PyExc_RuntimeError;
}

static PyObject *raise_message(gcStatus st, const char *msg) {
    PyErr_SetString(exception_for(st), msg && msg[0] ? msg : gc_status_string(st));
    return NULL;
}

static PyObject *raise_status(WorldObject *self, gcStatus st) {
    return raise_message(st, self->world ? gc_world_last_error(self->world) : "");
}

/* None, or the exception for an error status: the end of most calls. */
static PyObject *none_or_raise(WorldObject *self, gcStatus st) {
    if (st < 0) return raise_status(self, st);
    Py_RETURN_NONE;
}

/* A warning status that still needs saying (a body stopped by the non-finite guard). */
static int warn_status(WorldObject *self, gcStatus st) {
    if (st != GC_WARN_STOPPED) return 0;
    return PyErr_WarnEx(PyExc_RuntimeWarning, gc_world_last_error(self->world), 1);
}

/* The statement runs with the GIL released and the world marked busy (check_ready refuses). */
#define WITHOUT_GIL(self, ...)                                                                                   \
    do {                                                                                                         \
        atomic_store(&(self)->busy, 1);                                                                          \
        Py_BEGIN_ALLOW_THREADS                                                                                   \
        __VA_ARGS__;                                                                                             \
        Py_END_ALLOW_THREADS                                                                                     \
        atomic_store(&(self)->busy, 0);                                                                          \
    } while (0)

/* The world exists (a call the core serialises itself may come while another thread steps). */
static int check_world(WorldObject *self) {
    if (!self->world) {
        PyErr_SetString(PyExc_RuntimeError, "World is not initialised");
        return 0;
    }
    return 1;
}

/* The world exists and no step runs on another thread. */
static int check_ready(WorldObject *self) {
    if (!check_world(self)) return 0;
    if (atomic_load(&self->busy)) {
        PyErr_SetString(PyExc_RuntimeError, "World is stepping in another thread");
        return 0;
    }
    return 1;
}

/* Convert a sequence of n numbers; ValueError naming the argument on failure. */
static int parse_vec(PyObject *obj, int n, const char *name, double *out) {
    if (obj == NULL || !PySequence_Check(obj) || PySequence_Size(obj) != n) {
        PyErr_Clear();
        PyErr_Format(PyExc_ValueError, "%s: expected a sequence of %d numbers", name, n);
        return 0;
    }
    for (int i = 0; i < n; ++i) {
        PyObject *item = PySequence_GetItem(obj, i);
        if (!item) return 0;
        double v = PyFloat_AsDouble(item);
        Py_DECREF(item);
        if (v == -1.0 && PyErr_Occurred()) {
            PyErr_Clear();
            PyErr_Format(PyExc_ValueError, "%s: item %d is not a number", name, i);
            return 0;
        }
        out[i] = v;
    }
    return 1;
}

/* (v[0], ..., v[n-1]) as floats. */
static PyObject *tuple_of(const double *v, int n) {
    PyObject *t = PyTuple_New(n);
    for (int i = 0; t && i < n; ++i) {
        PyObject *item = PyFloat_FromDouble(v[i]);
        if (!item || PyTuple_SetItem(t, i, item) < 0) Py_CLEAR(t);
    }
    return t;
}

/* A C-contiguous float64 buffer of xyz rows (at most max_rows; at least one when nonempty): its
 * rows, or -1 with "<name>: must be a C-contiguous float64 array of xyz rows" (nothing held). */
static Py_ssize_t xyz_rows(PyObject *obj, Py_buffer *b, const char *name, int nonempty, Py_ssize_t max_rows) {
    if (PyObject_GetBuffer(obj, b, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0) return -1;
    const Py_ssize_t row = 3 * (Py_ssize_t)sizeof(double);
    if (!b->format || strcmp(b->format, "d") != 0 || b->len % row != 0 || (nonempty && b->len == 0) ||
        b->len / row > max_rows) {
        PyBuffer_Release(b);
        PyErr_Format(PyExc_ValueError, "%s: must be a C-contiguous float64 array of xyz rows", name);
        return -1;
    }
    return b->len / row;
}

/* ---- Names the core's enums go by in Python (exported as FINGER_STATES etc.) ------- */

static const char *const finger_state_names[] = {
    [GC_FINGER_FREE] = "free", [GC_FINGER_STICK] = "stick", [GC_FINGER_SLIP] = "slip"};
static const char *const renderer_names[] = {[GC_RENDERER_XFCA] = "xfca", [GC_RENDERER_CURSOR] = "cursor"};
static const char *const serial_state_names[] = {[GC_SERIAL_WAITING] = "waiting", [GC_SERIAL_STREAMING] = "streaming",
                                                 [GC_SERIAL_LOST] = "lost", [GC_SERIAL_HANGUP] = "hangup"};
static const char *const serial_event_names[] = {
    "?", [GC_SERIAL_EV_CONNECTED] = "connected", [GC_SERIAL_EV_LOST] = "lost",
    [GC_SERIAL_EV_RECOVERED] = "recovered", [GC_SERIAL_EV_ENABLED] = "enabled", [GC_SERIAL_EV_ESTOP] = "estop",
    [GC_SERIAL_EV_STALL] = "stall", [GC_SERIAL_EV_DROPPED] = "dropped", [GC_SERIAL_EV_FOREIGN] = "foreign"};
#define COUNT_OF(a) ((int)(sizeof(a) / sizeof((a)[0])))

/* names[i], or names[fallback] for a value outside the table (never an out-of-bounds read). */
static const char *enum_name(const char *const *names, int count, int i, int fallback) {
    return i >= 0 && i < count && names[i] ? names[i] : names[fallback];
}

/* ---- Fields: the keyword arguments of World(), add_finger, _add_body, start and
 * attach_serial; the dicts of stats(), serial_stats(), contacts(), finger_contacts() and
 * grasp_quality(); one table row each ----------------------------------------------------------
 * A row names a field of a core struct and how Python sees it. parse_params reads a call's
 * positional and keyword arguments into the definition the core's gc_default_*_def filled;
 * fields_dict turns a struct into a dict: the results, and the definitions' defaults exported
 * as WORLD_DEFAULTS, BODY_DEFAULTS, ... so Python never types a default twice. Adding a
 * parameter or a result's entry is one row (docs/architecture.md). */
typedef enum FieldKind {
    FIELD_DOUBLE,  /* double, from any real number */
    FIELD_INT,     /* int, from an integer in C int range */
    FIELD_BOOL,    /* int 0/1, from any object's truth */
    FIELD_U64,     /* uint64_t (a counter: out only) */
    FIELD_VEC,     /* double[n], from a sequence of n numbers */
    FIELD_OPT_VEC, /* as FIELD_VEC, or None for the default; the int at `flag` (if any) is set when given */
    FIELD_TEXT,    /* char[n], from a str shorter than n bytes */
    FIELD_ENUM,    /* an int-sized enum, from its name (names, n of them) */
    FIELD_COUNTS,  /* uint64_t[n], as a dict of counters by names[i] (out only) */
    FIELD_OBJECT,  /* not a field: the argument itself, left to the caller (a buffer, a descriptor) */
} FieldKind;

typedef struct Field {
    const char *name;         /* the Python keyword or key, and the name an error message starts with */
    FieldKind kind;
    size_t offset;            /* of the field in the struct */
    int n;                    /* VEC, OPT_VEC: numbers; TEXT: bytes of the array; ENUM, COUNTS: names */
    size_t flag;              /* OPT_VEC: offset of the int set to 1 when given; 0: none */
    const char *const *names; /* ENUM: by value; COUNTS: of the counters */
} Field;

#define FIELD(type, field, kind) {#field, FIELD_##kind, offsetof(type, field), 0, 0, NULL}
#define FIELD_N(type, field, kind, n) {#field, FIELD_##kind, offsetof(type, field), n, 0, NULL}
#define FIELD_TEXT(type, field) {#field, FIELD_TEXT, offsetof(type, field), sizeof(((type *)0)->field), 0, NULL}
#define FIELD_NAMED(type, field, kind, names) {#field, FIELD_##kind, offsetof(type, field), COUNT_OF(names), 0, names}
#define FIELD_ARGUMENT(name) {name, FIELD_OBJECT, 0, 0, 0, NULL}
enum { MAX_FIELDS = 40, MAX_VEC = 16 }; /* rows of a table, numbers of a VEC (checked at import: add_tables) */
_Static_assert(sizeof(gcFingerRenderer) == sizeof(int) && sizeof(int32_t) == sizeof(int), "INT and ENUM read an int");

static const char *const frame_error_names[] = {"cobs", "short", "crc", "version", "type", "length", "overflow",
                                                "range"}; /* gcSerialStats.frame_errors */

static const Field world_params[] = {
    FIELD_N(gcWorldDef, gravity, VEC, 3),
    FIELD(gcWorldDef, gyroscopic, BOOL),
    FIELD(gcWorldDef, max_bodies, INT),
    FIELD(gcWorldDef, max_fingers, INT),
    FIELD(gcWorldDef, max_parts, INT),
    FIELD(gcWorldDef, threads, INT), /* threads, max_contacts: docs/solver.md */
    FIELD(gcWorldDef, max_contacts, INT),
};

/* _add_body(parts, radii, **params); parts: C-contiguous float64 buffers of shape (n, 3). */
static const Field body_params[] = {
    FIELD_ARGUMENT("parts"),
    FIELD_ARGUMENT("radii"),
    FIELD(gcBodyDef, mass, DOUBLE),
    FIELD_N(gcBodyDef, position, VEC, 3),
    FIELD_N(gcBodyDef, orientation, VEC, 4),
    {"static", FIELD_BOOL, offsetof(gcBodyDef, is_static), 0, 0, NULL},
    FIELD(gcBodyDef, mu_s, DOUBLE),
    FIELD(gcBodyDef, mu_d, DOUBLE),
    FIELD(gcBodyDef, viscosity, DOUBLE),
    {"inertia", FIELD_OPT_VEC, offsetof(gcBodyDef, inertia), 9, offsetof(gcBodyDef, has_inertia), NULL},
    {"center_of_mass", FIELD_OPT_VEC, offsetof(gcBodyDef, center_of_mass), 3,
     offsetof(gcBodyDef, has_center_of_mass), NULL},
    FIELD_N(gcBodyDef, linear_velocity, VEC, 3),
    FIELD_N(gcBodyDef, angular_velocity, VEC, 3),
    FIELD(gcBodyDef, linear_damping, DOUBLE),
    FIELD(gcBodyDef, angular_damping, DOUBLE),
};

/* add_finger's arguments, in their positional order. points: None (a sphere finger) or a
 * C-contiguous float64 buffer of xyz rows (a convex finger). */
static const Field finger_params[] = {
    FIELD(gcFingerDef, radius, DOUBLE),
    FIELD(gcFingerDef, stiffness, DOUBLE),
    FIELD(gcFingerDef, damping, DOUBLE),
    FIELD_N(gcFingerDef, position, VEC, 3),
    FIELD_ARGUMENT("points"),
    FIELD_N(gcFingerDef, orientation, OPT_VEC, 4),
    FIELD(gcFingerDef, torsion, DOUBLE),
    FIELD_NAMED(gcFingerDef, renderer, ENUM, renderer_names),
    FIELD(gcFingerDef, cursor_mass, DOUBLE),
};

/* start(*, **params) */
static const Field runtime_params[] = {
    FIELD(gcRuntimeDef, haptic_rate, DOUBLE),
    FIELD(gcRuntimeDef, object_rate, DOUBLE),
    FIELD(gcRuntimeDef, max_adopted_bodies, INT),
    FIELD(gcRuntimeDef, max_force, DOUBLE),
    FIELD(gcRuntimeDef, ramp_time, DOUBLE),
    FIELD(gcRuntimeDef, watchdog_timeout, DOUBLE),
    FIELD(gcRuntimeDef, hip_timeout, DOUBLE),
    FIELD(gcRuntimeDef, release_delay, DOUBLE),
    FIELD(gcRuntimeDef, realtime, BOOL),
    FIELD(gcRuntimeDef, priority, INT),
    FIELD(gcRuntimeDef, max_hip_speed, DOUBLE),
};

/* attach_serial(fd, *, **params) */
static const Field serial_params[] = {
    FIELD_ARGUMENT("fd"),
    FIELD(gcSerialDef, finger_offset, INT),
    FIELD(gcSerialDef, num_fingers, INT),
    FIELD_N(gcSerialDef, transform, OPT_VEC, 16), /* row-major 4x4, device metres -> world */
    FIELD(gcSerialDef, force_ttl, DOUBLE),
    FIELD(gcSerialDef, lost_timeout, DOUBLE),
    FIELD(gcSerialDef, max_force, DOUBLE),
    FIELD(gcSerialDef, ramp_time, DOUBLE),
    FIELD(gcSerialDef, max_position, DOUBLE),
    FIELD(gcSerialDef, stall_timeout, DOUBLE),
    FIELD(gcSerialDef, priority, INT),
    FIELD_TEXT(gcSerialDef, udp_host),
    FIELD(gcSerialDef, udp_port, INT),
};

/* stats(): rates, jitter, overruns, adoption, inputs, safety (docs/runtime.md). */
static const Field runtime_stats_fields[] = {
    FIELD(gcRuntimeStats, running, BOOL),
    FIELD(gcRuntimeStats, realtime, BOOL),
    FIELD(gcRuntimeStats, rt_priority, BOOL),
    FIELD_TEXT(gcRuntimeStats, priority_note),
    FIELD(gcRuntimeStats, haptic_rate, DOUBLE),
    FIELD(gcRuntimeStats, object_rate, DOUBLE),
    FIELD(gcRuntimeStats, object_speed, DOUBLE),
    FIELD(gcRuntimeStats, haptic_ticks, U64),
    FIELD(gcRuntimeStats, object_ticks, U64),
    FIELD(gcRuntimeStats, jitter_p50_us, DOUBLE),
    FIELD(gcRuntimeStats, jitter_p99_us, DOUBLE),
    FIELD(gcRuntimeStats, jitter_max_us, DOUBLE),
    FIELD(gcRuntimeStats, tick_max_us, DOUBLE),
    FIELD(gcRuntimeStats, tick_mean_us, DOUBLE),
    FIELD(gcRuntimeStats, wake_max_us, DOUBLE),
    FIELD(gcRuntimeStats, overruns, U64),
    FIELD(gcRuntimeStats, late_periods, U64),
    FIELD(gcRuntimeStats, object_overruns, U64),
    FIELD(gcRuntimeStats, adopted_bodies, INT),
    FIELD(gcRuntimeStats, accepted_inputs, U64),
    FIELD(gcRuntimeStats, rejected_inputs, U64),
    FIELD(gcRuntimeStats, watchdog_trips, U64),
    FIELD(gcRuntimeStats, stale_inputs, U64),
    FIELD(gcRuntimeStats, nonfinite_forces, U64),
    FIELD(gcRuntimeStats, stopped_bodies, U64),
    FIELD(gcRuntimeStats, forces_enabled, BOOL),
    FIELD(gcRuntimeStats, haptic_time, DOUBLE),
    FIELD(gcRuntimeStats, object_time, DOUBLE),
};

/* serial_stats(device): state, rate, drops, latency (docs/devices.md). */
static const Field serial_stats_fields[] = {
    FIELD_NAMED(gcSerialStats, state, ENUM, serial_state_names),
    FIELD(gcSerialStats, enabled, BOOL),
    FIELD(gcSerialStats, device_fingers, INT),
    FIELD(gcSerialStats, renders_forces, BOOL),
    FIELD(gcSerialStats, units, INT),
    FIELD(gcSerialStats, device_rate, DOUBLE),
    FIELD(gcSerialStats, device_force_max, DOUBLE),
    FIELD(gcSerialStats, device_ttl_max, DOUBLE),
    FIELD_TEXT(gcSerialStats, name),
    FIELD(gcSerialStats, pose_rate, DOUBLE),
    FIELD(gcSerialStats, last_pose_age, DOUBLE),
    FIELD(gcSerialStats, poses, U64),
    FIELD(gcSerialStats, forces_sent, U64),
    FIELD(gcSerialStats, heartbeats, U64),
    FIELD(gcSerialStats, dropped, U64),
    FIELD_NAMED(gcSerialStats, frame_errors, COUNTS, frame_error_names),
    FIELD(gcSerialStats, sequence_gaps, U64),
    FIELD(gcSerialStats, disconnects, U64),
    FIELD(gcSerialStats, estops, U64),
    FIELD(gcSerialStats, stall_zeroes, U64),
    FIELD(gcSerialStats, write_errors, U64),
    FIELD(gcSerialStats, push_rejected, U64),
    FIELD(gcSerialStats, latency_p50_us, DOUBLE),
    FIELD(gcSerialStats, latency_p99_us, DOUBLE),
    FIELD(gcSerialStats, latency_max_us, DOUBLE),
    FIELD(gcSerialStats, gain, DOUBLE),
    FIELD(gcSerialStats, rt_priority, BOOL),
    FIELD(gcSerialStats, late_poses, U64),
    FIELD(gcSerialStats, duplicate_poses, U64),
    FIELD(gcSerialStats, foreign_datagrams, U64),
    FIELD_TEXT(gcSerialStats, peer),
    FIELD(gcSerialStats, sends_orientations, BOOL),
    FIELD(gcSerialStats, oriented_poses, U64),
};

/* finger_contacts(finger): one dict per point of the patch (docs/api.md). */
static const Field finger_contact_fields[] = {
    FIELD(gcFingerContactPoint, body, INT),
    FIELD(gcFingerContactPoint, sample, INT),
    FIELD(gcFingerContactPoint, reversed, BOOL),
    FIELD_NAMED(gcFingerContactPoint, state, ENUM, finger_state_names),
    FIELD_N(gcFingerContactPoint, point, VEC, 3),
    FIELD_N(gcFingerContactPoint, normal, VEC, 3),
    FIELD_N(gcFingerContactPoint, force, VEC, 3),
};

/* contacts(): one dict per body-body contact point of the last step. */
static const Field contact_fields[] = {
    FIELD(gcContactPoint, body_a, INT),
    FIELD(gcContactPoint, body_b, INT),
    FIELD_N(gcContactPoint, point, VEC, 3),
    FIELD_N(gcContactPoint, normal, VEC, 3),
    FIELD(gcContactPoint, separation, DOUBLE),
    FIELD(gcContactPoint, normal_impulse, DOUBLE),
    FIELD_N(gcContactPoint, friction_impulse, VEC, 3),
    FIELD(gcContactPoint, sticking, BOOL),
};

/* _grasp_quality(...) -> dict; _grasp_quality_batch fills gcGraspQuality records, which
 * graspcore reads through GRASP_QUALITY_FIELDS (the same rows as a layout). */
static const Field grasp_quality_fields[] = {
    FIELD(gcGraspQuality, force_closure, BOOL),
    FIELD(gcGraspQuality, force_only_closure, BOOL),
    FIELD(gcGraspQuality, torque_closure, BOOL),
    FIELD(gcGraspQuality, epsilon, DOUBLE),
    FIELD(gcGraspQuality, volume, DOUBLE),
    FIELD_N(gcGraspQuality, weakest, VEC, 6),
    FIELD(gcGraspQuality, rank, INT),
    FIELD(gcGraspQuality, facets, INT),
};

/* A TypeError naming the parameter, what it wants and what it got; 0. */
static int wrong_type(const char *name, const char *want, PyObject *value) {
    PyObject *got = PyType_GetName(Py_TYPE(value));
    if (got) {
        PyErr_Format(PyExc_TypeError, "%s: must be %s, not %U", name, want, got);
        Py_DECREF(got);
    }
    return 0;
}

/* After a failed conversion: a TypeError said again naming the parameter (another error, an
 * overflow say, is left as it is); 0. */
static int conversion_failed(const char *name, const char *want, PyObject *value) {
    if (!PyErr_ExceptionMatches(PyExc_TypeError)) return 0;
    PyErr_Clear();
    return wrong_type(name, want, value);
}

/* A FIELD_ENUM given by name: its value, or -1 with "<name>: must be 'a' or 'b' (got 'c')". */
static int enum_value(const Field *p, const char *s) {
    for (int i = 0; i < p->n; ++i)
        if (p->names[i] && strcmp(s, p->names[i]) == 0) return i;
    char choices[256] = "";
    for (int i = 0; i < p->n; ++i) {
        if (!p->names[i]) continue;
        size_t used = strlen(choices);
        const char *sep = used == 0 ? "" : i + 1 < p->n ? ", " : " or ";
        PyOS_snprintf(choices + used, sizeof choices - used, "%s'%s'", sep, p->names[i]);
    }
    PyErr_Format(PyExc_ValueError, "%s: must be %s (got '%s')", p->name, choices, s);
    return -1;
}

/* One argument into its field; 0 with a Python error naming the parameter. */
static int set_field(const Field *p, PyObject *value, void *def) {
    char *field = (char *)def + p->offset;
    switch (p->kind) {
    case FIELD_DOUBLE: {
        double v = PyFloat_AsDouble(value);
        if (v == -1.0 && PyErr_Occurred()) return conversion_failed(p->name, "a real number", value);
        memcpy(field, &v, sizeof v);
        return 1;
    }
    case FIELD_INT: {
        int overflow = 0;
        long v = PyLong_AsLongAndOverflow(value, &overflow);
        if (v == -1 && PyErr_Occurred()) return conversion_failed(p->name, "an integer", value);
        if (overflow || v < INT_MIN || v > INT_MAX) {
            PyErr_Format(PyExc_OverflowError, "%s: outside the range of a C int", p->name);
            return 0;
        }
        int i = (int)v;
        memcpy(field, &i, sizeof i);
        return 1;
    }
    case FIELD_BOOL: {
        int truth = PyObject_IsTrue(value);
        if (truth < 0) return 0;
        memcpy(field, &truth, sizeof truth);
        return 1;
    }
    case FIELD_OPT_VEC:
        if (value == Py_None) return 1;
        if (p->flag) {
            int one = 1;
            memcpy((char *)def + p->flag, &one, sizeof one);
        }
        /* fall through */
    case FIELD_VEC: {
        double v[MAX_VEC];
        if (!parse_vec(value, p->n, p->name, v)) return 0;
        memcpy(field, v, sizeof(double) * (size_t)p->n);
        return 1;
    }
    case FIELD_TEXT:
    case FIELD_ENUM: {
        Py_ssize_t len;
        if (!PyUnicode_Check(value)) return wrong_type(p->name, "a str", value);
        const char *s = PyUnicode_AsUTF8AndSize(value, &len);
        if (!s) return 0;
        if ((size_t)len != strlen(s)) {
            PyErr_Format(PyExc_ValueError, "%s: contains a NUL character", p->name);
            return 0;
        }
        if (p->kind == FIELD_ENUM) {
            int v = enum_value(p, s);
            if (v < 0) return 0;
            memcpy(field, &v, sizeof v);
        } else if (len >= p->n) {
            PyErr_Format(PyExc_ValueError, "%s: longer than %d bytes", p->name, p->n - 1);
            return 0;
        } else {
            memcpy(field, s, (size_t)len + 1);
        }
        return 1;
    }
    case FIELD_U64:
    case FIELD_COUNTS:
    case FIELD_OBJECT: return 1;
    }
    return 1;
}

/* A call's arguments into def (filled with the core's defaults by the caller): positional ones
 * (at most max_positional) in the table's order, then keywords. given[i] is the object for
 * params[i] or NULL (the caller reads its FIELD_OBJECT rows there). 0 with an error set. */
static int parse_params(const char *func, PyObject *args, PyObject *kwargs, const Field *params, int count,
                        int max_positional, void *def, PyObject **given) {
    Py_ssize_t nargs = PyTuple_Size(args);
    if (nargs > max_positional) {
        PyErr_Format(PyExc_TypeError, "%s() takes at most %d positional argument%s (%zd given)", func,
                     max_positional, max_positional == 1 ? "" : "s", nargs);
        return 0;
    }
    for (int i = 0; i < count; ++i) given[i] = i < nargs ? PyTuple_GetItem(args, i) : NULL;
    Py_ssize_t pos = 0;
    PyObject *key, *value;
    while (kwargs && PyDict_Next(kwargs, &pos, &key, &value)) {
        const char *name = PyUnicode_Check(key) ? PyUnicode_AsUTF8AndSize(key, NULL) : NULL;
        if (!name) {
            PyErr_Clear();
            PyErr_Format(PyExc_TypeError, "%s() keywords must be strings", func);
            return 0;
        }
        int i = 0;
        while (i < count && strcmp(params[i].name, name) != 0) ++i;
        if (i == count) {
            PyErr_Format(PyExc_TypeError, "%s() got an unexpected keyword argument '%s'", func, name);
            return 0;
        }
        if (given[i]) {
            PyErr_Format(PyExc_TypeError, "%s() got multiple values for argument '%s'", func, name);
            return 0;
        }
        given[i] = value;
    }
    for (int i = 0; i < count; ++i)
        if (given[i] && !set_field(&params[i], given[i], def)) return 0;
    return 1;
}

/* One field of a struct as a Python object (a new reference; NULL with an error set). */
static PyObject *field_value(const Field *p, const void *data) {
    const char *field = (const char *)data + p->offset;
    double x[MAX_VEC];
    uint64_t u[MAX_VEC];
    int k;
    switch (p->kind) {
    case FIELD_DOUBLE: memcpy(x, field, sizeof x[0]); return PyFloat_FromDouble(x[0]);
    case FIELD_INT: memcpy(&k, field, sizeof k); return PyLong_FromLong(k);
    case FIELD_BOOL: memcpy(&k, field, sizeof k); return PyBool_FromLong(k);
    case FIELD_U64: memcpy(u, field, sizeof u[0]); return PyLong_FromUnsignedLongLong(u[0]);
    case FIELD_OPT_VEC:
        if (p->flag && (memcpy(&k, (const char *)data + p->flag, sizeof k), !k)) Py_RETURN_NONE;
        /* fall through */
    case FIELD_VEC: memcpy(x, field, sizeof(double) * (size_t)p->n); return tuple_of(x, p->n);
    case FIELD_TEXT: {
        Py_ssize_t len = 0;
        while (len + 1 < p->n && field[len]) ++len; /* NUL-terminated within the array */
        return PyUnicode_FromStringAndSize(field, len);
    }
    case FIELD_ENUM: memcpy(&k, field, sizeof k); return PyUnicode_FromString(enum_name(p->names, p->n, k, 0));
    case FIELD_COUNTS: {
        memcpy(u, field, sizeof(uint64_t) * (size_t)p->n);
        PyObject *d = PyDict_New();
        for (int i = 0; d && i < p->n; ++i) {
            PyObject *v = PyLong_FromUnsignedLongLong(u[i]);
            if (!v || PyDict_SetItemString(d, p->names[i], v) < 0) Py_CLEAR(d);
            Py_XDECREF(v);
        }
        return d;
    }
    case FIELD_OBJECT: break;
    }
    Py_RETURN_NONE;
}

/* A struct as a dict, one key per row (FIELD_OBJECT rows left out). */
static PyObject *fields_dict(const Field *fields, int count, const void *data) {
    PyObject *d = PyDict_New();
    for (int i = 0; d && i < count; ++i) {
        if (fields[i].kind == FIELD_OBJECT) continue;
        PyObject *v = field_value(&fields[i], data);
        if (!v || PyDict_SetItemString(d, fields[i].name, v) < 0) Py_CLEAR(d);
        Py_XDECREF(v);
    }
    return d;
}

/* A table as a layout for numpy: ((name, kind, byte offset, count), ...), kind "double", "int"
 * (int32), "bool" (an int32 0/1) or "u64"; count 1 but for a VEC. */
static PyObject *fields_layout(const Field *fields, int count) {
    static const char *const kinds[] = {[FIELD_DOUBLE] = "double", [FIELD_INT] = "int", [FIELD_BOOL] = "bool",
                                        [FIELD_U64] = "u64", [FIELD_VEC] = "double"};
    PyObject *t = PyTuple_New(count);
    for (int i = 0; t && i < count; ++i) {
        const Field *f = &fields[i];
        if ((size_t)f->kind >= sizeof kinds / sizeof kinds[0] || !kinds[f->kind]) {
            PyErr_Format(PyExc_SystemError, "%s: no numpy layout for its kind", f->name);
            Py_CLEAR(t);
            break;
        }
        PyObject *row = Py_BuildValue("(ssni)", f->name, kinds[f->kind], (Py_ssize_t)f->offset,
                                      f->kind == FIELD_VEC ? f->n : 1);
        if (!row || PyTuple_SetItem(t, i, row) < 0) Py_CLEAR(t);
    }
    return t;
}

/* n structs of item_size bytes as a list of dicts. */
static PyObject *fields_list(const Field *fields, int count, const void *items, size_t item_size, int n) {
    PyObject *list = PyList_New(n);
    for (int i = 0; list && i < n; ++i) {
        PyObject *d = fields_dict(fields, count, (const char *)items + item_size * (size_t)i);
        if (!d || PyList_SetItem(list, i, d) < 0) Py_CLEAR(list);
    }
    return list;
}

/* ---- View: a read-only (rows, cols) float64 buffer into world storage ------------- */

static int View_getbuffer(PyObject *obj, Py_buffer *view, int flags) {
    ViewObject *self = (ViewObject *)obj;
    if (flags & PyBUF_WRITABLE) {
        PyErr_SetString(PyExc_BufferError, "graspcore views are read-only");
        view->obj = NULL;
        return -1;
    }
    view->buf = (void *)self->data;
    view->obj = obj;
    Py_INCREF(obj);
    view->len = self->shape[0] * self->shape[1] * (Py_ssize_t)sizeof(double);
    view->readonly = 1;
    view->itemsize = sizeof(double);
    view->format = (flags & PyBUF_FORMAT) ? "d" : NULL;
    view->ndim = 2;
    view->shape = (flags & PyBUF_ND) ? self->shape : NULL;
    view->strides = (flags & PyBUF_STRIDES) == PyBUF_STRIDES ? self->strides : NULL;
    view->suboffsets = NULL;
    view->internal = NULL;
    return 0;
}

static void View_releasebuffer(PyObject *obj, Py_buffer *view) { (void)obj, (void)view; }

static void View_dealloc(PyObject *obj) {
    ViewObject *self = (ViewObject *)obj;
    PyTypeObject *tp = Py_TYPE(obj);
    Py_XDECREF(self->owner);
    freefunc tp_free = (freefunc)PyType_GetSlot(tp, Py_tp_free);
    tp_free(obj);
    Py_DECREF(tp);
}

static PyType_Slot View_slots[] = {
    {Py_tp_dealloc, View_dealloc},
    {Py_bf_getbuffer, View_getbuffer},
    {Py_bf_releasebuffer, View_releasebuffer},
    {Py_tp_doc, "Read-only float64 view of world state (use numpy.asarray)."},
    {0, NULL},
};
static PyType_Spec View_spec = {"graspcore._core.View", sizeof(ViewObject), 0, Py_TPFLAGS_DEFAULT, View_slots};

/* ---- World ------------------------------------------------------------------------ */

static int World_init(PyObject *obj, PyObject *args, PyObject *kwargs) {
    WorldObject *self = (WorldObject *)obj;
    gcWorldDef def = gc_default_world_def();
    PyObject *given[MAX_FIELDS];
    if (!parse_params("World", args, kwargs, world_params, COUNT_OF(world_params), COUNT_OF(world_params), &def,
                      given))
        return -1;
    if (self->world) {
        PyErr_SetString(PyExc_RuntimeError, "World is already initialised");
        return -1;
    }
    gcStatus st = gc_world_create(&def, &self->world);
    if (st != GC_OK) {
        raise_message(st, gc_world_create_error());
        return -1;
    }
    return 0;
}

static void World_dealloc(PyObject *obj) {
    WorldObject *self = (WorldObject *)obj;
    PyTypeObject *tp = Py_TYPE(obj);
    gc_world_destroy(self->world);
    self->world = NULL;
    freefunc tp_free = (freefunc)PyType_GetSlot(tp, Py_tp_free);
    tp_free(obj);
    Py_DECREF(tp);
}

/* _add_body(parts, radii, **body_params): the parts' points stay the caller's (zero-copy). */
static PyObject *World_add_body(PyObject *obj, PyObject *args, PyObject *kwargs) {
    WorldObject *self = (WorldObject *)obj;
    gcBodyDef def = gc_default_body_def();
    PyObject *given[MAX_FIELDS];
    if (!parse_params("_add_body", args, kwargs, body_params, COUNT_OF(body_params), 2, &def, given)) return NULL;
    PyObject *parts = given[0], *radii = given[1];
    if (!parts || !radii) {
        PyErr_SetString(PyExc_TypeError, "_add_body() needs parts and radii");
        return NULL;
    }
    if (!check_ready(self)) return NULL;
    Py_ssize_t n = PySequence_Size(parts);
    if (n < 1 || n > 65536 || PySequence_Size(radii) != n) {
        PyErr_Clear();
        PyErr_SetString(PyExc_ValueError, "parts: expected 1..65536 point arrays with one radius each");
        return NULL;
    }
    gcPartDef *pdefs = PyMem_Calloc((size_t)n, sizeof *pdefs);
    Py_buffer *bufs = PyMem_Calloc((size_t)n, sizeof *bufs);
    int got = 0;
    PyObject *result = NULL;
    if (!pdefs || !bufs) {
        PyErr_NoMemory();
        goto done;
    }
    for (; got < n; ++got) {
        PyObject *item = PySequence_GetItem(parts, got);
        if (!item) goto done;
        int rc = PyObject_GetBuffer(item, &bufs[got], PyBUF_C_CONTIGUOUS | PyBUF_FORMAT);
        Py_DECREF(item);
        if (rc < 0) goto done;
        Py_buffer *b = &bufs[got];
        if (!b->format || strcmp(b->format, "d") != 0 || b->len % (3 * (Py_ssize_t)sizeof(double)) != 0 ||
            b->len / (Py_ssize_t)(3 * sizeof(double)) > (1 << 28)) {
            PyErr_Format(PyExc_ValueError, "points: part %d must be float64 xyz rows", got);
            PyBuffer_Release(b);
            goto done;
        }
        pdefs[got].points = b->buf;
        pdefs[got].num_points = (int)(b->len / (Py_ssize_t)(3 * sizeof(double)));
        PyObject *r = PySequence_GetItem(radii, got);
        if (!r) {
            PyBuffer_Release(b);
            goto done;
        }
        pdefs[got].radius = PyFloat_AsDouble(r);
        Py_DECREF(r);
        if (PyErr_Occurred()) {
            PyBuffer_Release(b);
            goto done;
        }
    }
    int32_t id = -1;
    gcStatus st = gc_world_add_body(self->world, &def, pdefs, (int)n, &id);
    result = st < 0 ? raise_status(self, st) : PyLong_FromLong(id);
done:
    for (int i = 0; i < got; ++i) PyBuffer_Release(&bufs[i]);
    PyMem_Free(pdefs);
    PyMem_Free(bufs);
    return result;
}

static PyObject *World_add_finger(PyObject *obj, PyObject *args, PyObject *kwargs) {
    WorldObject *self = (WorldObject *)obj;
    gcFingerDef def = gc_default_finger_def();
    PyObject *given[MAX_FIELDS];
    if (!parse_params("add_finger", args, kwargs, finger_params, COUNT_OF(finger_params), COUNT_OF(finger_params),
                      &def, given) ||
        !check_ready(self))
        return NULL;
    PyObject *points = given[4];
    Py_buffer b = {0};
    int has_points = points && points != Py_None;
    if (has_points) {
        Py_ssize_t rows = xyz_rows(points, &b, "points", 0, 1 << 20);
        if (rows < 0) return NULL;
        def.points = b.buf;
        def.num_points = (int)rows;
    }
    int32_t id;
    gcStatus st = gc_world_add_finger(self->world, &def, &id);
    if (has_points) PyBuffer_Release(&b);
    return st < 0 ? raise_status(self, st) : PyLong_FromLong(id);
}

/* ---- Accessors: queries and setters of one body or finger, and the world's numbers -------
 * One row each: the Python name, the core call, the shape of its arguments or result, the
 * docstring. A shape's one function (query_*, set_*, below) parses the id, checks the world,
 * calls the core and maps its status; the rows expand into the World_<name> methods and their
 * World_methods entries. Adding an accessor of a shape that exists is one row; a new shape is
 * one function (docs/architecture.md). */

#define ID_QUERIES(X)                                                                                            \
    X(body_pose, gc_world_body_pose, POSE, "body_pose(body) -> ((x, y, z), (w, x, y, z))")                      \
    X(body_velocity, gc_world_body_velocity, PAIR, "body_velocity(body) -> (linear, angular), world frame")     \
    X(body_mass, gc_world_body_mass, MASS, "body_mass(body) -> (mass, center_of_mass, inertia 3x3)")            \
    X(residual_wrench, gc_world_residual_wrench, PAIR,                                                           \
      "residual_wrench(body) -> (force, torque about the centre of mass)")                                       \
    X(body_chain, gc_world_body_chain, OPTIONAL_ID,                                                              \
      "body_chain(body) -> index of the body's collision chain (last step), None for a static body")            \
    X(finger_pose, gc_world_finger_pose, POSE, "finger_pose(finger) -> ((x, y, z), (w, x, y, z))")              \
    X(finger_force, gc_world_finger_force, VEC, "finger_force(finger) -> force rendered to the device, N")      \
    X(finger_torque, gc_world_finger_torque, VEC,                                                                \
      "finger_torque(finger) -> a convex finger's contact torque about its HIP, N m (0 for a sphere)")          \
    X(god_object, gc_world_god_object, VEC, "god_object(finger) -> world position")                             \
    X(finger_state, gc_world_finger_state, STATE, "finger_state(finger) -> 'free' | 'stick' | 'slip'")          \
    X(finger_contact, gc_world_finger_state, CONTACT, "finger_contact(finger) -> body id or None")

/* Setters: name, core call, shape, the names of its two arguments (for errors), docstring. */
#define ID_SETTERS(X)                                                                                            \
    X(set_hip, gc_world_set_hip, VEC, "position", NULL,                                                          \
      "set_hip(finger, (x, y, z)): the device (haptic interface) point.")                                        \
    X(set_finger_pose, gc_world_set_finger_pose, POSE, "position", "orientation",                               \
      "set_finger_pose(finger, (x, y, z), (w, x, y, z)): the whole HIP (a convex finger turns with it).")        \
    X(set_body_velocity, gc_world_set_body_velocity, PAIR, "linear", "angular",                                 \
      "set_body_velocity(body, linear, angular): world frame, of the body origin's COM.")                      \
    X(set_body_pose, gc_world_set_body_pose, POSE, "position", "orientation",                                   \
      "set_body_pose(body, position, orientation_wxyz)")                                                         \
    X(set_body_friction, gc_world_set_body_friction, FRICTION, NULL, NULL,                                      \
      "set_body_friction(body, mu_s, mu_d, viscosity)")

/* Numbers of the whole world: name, core call, Python type, the guard (ready: not while a step
 * runs; world: any time, the core serialises it), docstring. NUMBERS are methods, PROPERTIES
 * read-only attributes. */
#define WORLD_NUMBERS(X)                                                                                         \
    X(state_hash, gc_world_state_hash, U64, ready, "64-bit hash of the full dynamic state.")                    \
    X(chain_count, gc_world_chain_count, INT, ready, "chain_count() -> number of collision chains, last step")  \
    X(stopped_bodies, gc_world_stopped_bodies, I64, ready,                                                       \
      "stopped_bodies() -> bodies stopped since creation because their state would have become non-finite")     \
    X(contact_overflow, gc_world_contact_overflow, I64, ready,                                                   \
      "contact_overflow() -> contact pairs dropped since creation for want of max_contacts")                    \
    X(tick_log_overflow, gc_world_tick_log_overflow, U64, world,                                                 \
      "tick_log_overflow() -> ticks dropped on a full tick log since the last start().")

#define WORLD_PROPERTIES(X)                                                                                      \
    X(time, gc_world_time, DOUBLE, ready, "Simulated time, s")                                                   \
    X(body_count, gc_world_body_count, INT, ready, "Number of bodies")                                           \
    X(finger_count, gc_world_finger_count, INT, ready, "Number of fingers")                                      \
    X(running, gc_world_running, BOOL, world, "True between start() and stop()")

/* The shapes. A pair's two arrays are 3 and 3 (PAIR) or 3 and 4 numbers (POSE). */
typedef gcStatus (*QueryVec)(const gcWorld *, int32_t, double[3]);
typedef gcStatus (*QueryTwo)(const gcWorld *, int32_t, double *, double *);
typedef gcStatus (*QueryMass)(const gcWorld *, int32_t, double *, double[3], double[9]);
typedef gcStatus (*QueryOptionalId)(const gcWorld *, int32_t, int32_t *);
typedef gcStatus (*QueryState)(const gcWorld *, int32_t, gcFingerState *, int32_t *);
typedef gcStatus (*SetVec)(gcWorld *, int32_t, const double[3]);
typedef gcStatus (*SetTwo)(gcWorld *, int32_t, const double *, const double *);
typedef gcStatus (*SetFriction)(gcWorld *, int32_t, double, double, double);

/* The id argument of a query, and the world ready for it. */
static int parse_id(WorldObject *self, PyObject *args, int *id) {
    return PyArg_ParseTuple(args, "i", id) && check_ready(self);
}

static PyObject *query_VEC(WorldObject *self, PyObject *args, QueryVec query) {
    int id;
    double v[3];
    if (!parse_id(self, args, &id)) return NULL;
    gcStatus st = query(self->world, id, v);
    return st < 0 ? raise_status(self, st) : tuple_of(v, 3);
}

static PyObject *query_two(WorldObject *self, PyObject *args, QueryTwo query, int n) {
    int id;
    double a[3], b[4];
    if (!parse_id(self, args, &id)) return NULL;
    gcStatus st = query(self->world, id, a, b);
    return st < 0 ? raise_status(self, st) : Py_BuildValue("(NN)", tuple_of(a, 3), tuple_of(b, n));
}
#define query_PAIR(self, args, query) query_two(self, args, query, 3)
#define query_POSE(self, args, query) query_two(self, args, query, 4)

static PyObject *query_MASS(WorldObject *self, PyObject *args, QueryMass query) {
    int id;
    double m, c[3], I[9];
    if (!parse_id(self, args, &id)) return NULL;
    gcStatus st = query(self->world, id, &m, c, I);
    if (st < 0) return raise_status(self, st);
    return Py_BuildValue("(d(ddd)((ddd)(ddd)(ddd)))", m, c[0], c[1], c[2], I[0], I[1], I[2], I[3], I[4], I[5], I[6],
                         I[7], I[8]);
}

/* An id or None (a negative id: a free finger's body, a static body's chain). */
static PyObject *optional_id(int32_t id) {
    if (id < 0) Py_RETURN_NONE;
    return PyLong_FromLong(id);
}

static PyObject *query_OPTIONAL_ID(WorldObject *self, PyObject *args, QueryOptionalId query) {
    int id;
    int32_t out;
    if (!parse_id(self, args, &id)) return NULL;
    gcStatus st = query(self->world, id, &out);
    return st < 0 ? raise_status(self, st) : optional_id(out);
}

/* A finger's state by name (STATE) or the body it touches (CONTACT), from one core call. */
static PyObject *query_state(WorldObject *self, PyObject *args, QueryState query, int want_body) {
    int id;
    gcFingerState state;
    int32_t body;
    if (!parse_id(self, args, &id)) return NULL;
    gcStatus st = query(self->world, id, &state, &body);
    if (st < 0) return raise_status(self, st);
    if (want_body) return optional_id(body);
    return PyUnicode_FromString(enum_name(finger_state_names, COUNT_OF(finger_state_names), (int)state, 0));
}
#define query_STATE(self, args, query) query_state(self, args, query, 0)
#define query_CONTACT(self, args, query) query_state(self, args, query, 1)

static PyObject *set_VEC(WorldObject *self, PyObject *args, SetVec set, const char *name, const char *unused) {
    int id;
    PyObject *a;
    double v[3];
    if (!PyArg_ParseTuple(args, "iO", &id, &a) || !check_ready(self) || !parse_vec(a, 3, name, v)) return NULL;
    return none_or_raise(self, set(self->world, id, v));
}

static PyObject *set_two(WorldObject *self, PyObject *args, SetTwo set, const char *name_a, const char *name_b,
                         int n) {
    int id;
    PyObject *a, *b;
    double u[3], v[4];
    if (!PyArg_ParseTuple(args, "iOO", &id, &a, &b) || !check_ready(self) || !parse_vec(a, 3, name_a, u) ||
        !parse_vec(b, n, name_b, v))
        return NULL;
    return none_or_raise(self, set(self->world, id, u, v));
}
#define set_PAIR(self, args, set, name_a, name_b) set_two(self, args, set, name_a, name_b, 3)
#define set_POSE(self, args, set, name_a, name_b) set_two(self, args, set, name_a, name_b, 4)

static PyObject *set_FRICTION(WorldObject *self, PyObject *args, SetFriction set, const char *unused_a,
                              const char *unused_b) {
    int id;
    double mu_s, mu_d, viscosity;
    if (!PyArg_ParseTuple(args, "iddd", &id, &mu_s, &mu_d, &viscosity) || !check_ready(self)) return NULL;
    return none_or_raise(self, set(self->world, id, mu_s, mu_d, viscosity));
}

#define NUMBER_U64(v) PyLong_FromUnsignedLongLong(v)
#define NUMBER_I64(v) PyLong_FromLongLong((long long)(v))
#define NUMBER_INT(v) PyLong_FromLong(v)
#define NUMBER_DOUBLE(v) PyFloat_FromDouble(v)
#define NUMBER_BOOL(v) PyBool_FromLong(v)

/* The rows, expanded into methods. */
#define QUERY_METHOD(name, call, shape, doc)                                                                     \
    static PyObject *World_##name(PyObject *obj, PyObject *args) {                                               \
        return query_##shape((WorldObject *)obj, args, call);                                                    \
    }
ID_QUERIES(QUERY_METHOD)
#define SETTER_METHOD(name, call, shape, arg_a, arg_b, doc)                                                      \
    static PyObject *World_##name(PyObject *obj, PyObject *args) {                                               \
        return set_##shape((WorldObject *)obj, args, call, arg_a, arg_b);                                        \
    }
ID_SETTERS(SETTER_METHOD)
#define NUMBER_FUNCTION(function, second, call, type, guard)                                                     \
    static PyObject *function(PyObject *obj, second) {                                                           \
        WorldObject *self = (WorldObject *)obj;                                                                  \
        return check_##guard(self) ? NUMBER_##type(call(self->world)) : NULL;                                    \
    }
#define NUMBER_METHOD(name, call, type, guard, doc)                                                              \
    NUMBER_FUNCTION(World_##name, PyObject *unused, call, type, guard)
WORLD_NUMBERS(NUMBER_METHOD)
#define PROPERTY_GETTER(name, call, type, guard, doc)                                                            \
    NUMBER_FUNCTION(World_get_##name, void *closure, call, type, guard)
WORLD_PROPERTIES(PROPERTY_GETTER)

/* finger_contacts(finger) -> list of dicts, one per point of the finger's contact patch. */
static PyObject *World_finger_contacts(PyObject *obj, PyObject *args) {
    WorldObject *self = (WorldObject *)obj;
    int finger;
    if (!PyArg_ParseTuple(args, "i", &finger) || !check_ready(self)) return NULL;
    gcFingerContactPoint points[64];
    int n = 0;
    gcStatus st = gc_world_finger_contacts(self->world, finger, points, 64, &n);
    if (st < 0) return raise_status(self, st);
    return fields_list(finger_contact_fields, COUNT_OF(finger_contact_fields), points, sizeof points[0],
                       n < 64 ? n : 64);
}

static PyObject *World_set_hips(PyObject *obj, PyObject *arg) {
    WorldObject *self = (WorldObject *)obj;
    if (!check_ready(self)) return NULL;
    Py_buffer b;
    Py_ssize_t rows = xyz_rows(arg, &b, "positions", 0, INT_MAX);
    if (rows < 0) return NULL;
    gcStatus st = gc_world_set_hips(self->world, b.buf, (int)rows);
    PyBuffer_Release(&b);
    return none_or_raise(self, st);
}

static PyObject *World_set_gravity(PyObject *obj, PyObject *arg) {
    WorldObject *self = (WorldObject *)obj;
    double g[3];
    if (!check_ready(self) || !parse_vec(arg, 3, "gravity", g)) return NULL;
    return none_or_raise(self, gc_world_set_gravity(self->world, g));
}

/* step(dt, steps=1): the GIL is released while the core runs. */
static PyObject *World_step(PyObject *obj, PyObject *args, PyObject *kwargs) {
    WorldObject *self = (WorldObject *)obj;
    static char *kwlist[] = {"dt", "steps", NULL};
    double dt;
    int steps = 1;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "d|i", kwlist, &dt, &steps) || !check_ready(self)) return NULL;
    if (steps < 1) {
        PyErr_SetString(PyExc_ValueError, "steps: must be >= 1");
        return NULL;
    }
    gcStatus st = GC_OK, warned = GC_OK; /* a stop in any of the steps is said once */
    WITHOUT_GIL(self, {
        for (int i = 0; i < steps && st >= 0; ++i) {
            st = gc_world_step(self->world, dt);
            if (st == GC_WARN_STOPPED) warned = st;
        }
    });
    if (st < 0) return raise_status(self, st);
    if (warn_status(self, warned) < 0) return NULL;
    Py_RETURN_NONE;
}

/* _view(kind): 0 body poses (n,7), 1 god-objects, 2 finger forces, 3 HIPs (n,3). */
static PyObject *World_view(PyObject *obj, PyObject *arg) {
    WorldObject *self = (WorldObject *)obj;
    long kind = PyLong_AsLong(arg);
    if (kind == -1 && PyErr_Occurred()) return NULL;
    if (!check_ready(self)) return NULL;
    const double *data;
    Py_ssize_t rows, cols = 3;
    switch (kind) {
    case 0: data = gc_world_body_pose_array(self->world), rows = gc_world_body_count(self->world), cols = 7; break;
    case 1: data = gc_world_god_object_array(self->world), rows = gc_world_finger_count(self->world); break;
    case 2: data = gc_world_finger_force_array(self->world), rows = gc_world_finger_count(self->world); break;
    case 3: data = gc_world_hip_array(self->world), rows = gc_world_finger_count(self->world); break;
    default: PyErr_SetString(PyExc_ValueError, "kind: must be 0..3"); return NULL;
    }
    allocfunc tp_alloc = (allocfunc)PyType_GetSlot((PyTypeObject *)View_Type, Py_tp_alloc);
    ViewObject *view = (ViewObject *)tp_alloc((PyTypeObject *)View_Type, 0);
    if (!view) return NULL;
    view->owner = Py_NewRef(obj);
    view->data = data;
    view->shape[0] = rows;
    view->shape[1] = cols;
    view->strides[0] = cols * (Py_ssize_t)sizeof(double);
    view->strides[1] = sizeof(double);
    return (PyObject *)view;
}

/* ---- Body-body contacts and collision chains (contacts.c, chains.c) ---------------- */

/* contacts() -> list of dicts, one per contact point of the last step. */
static PyObject *World_contacts(PyObject *obj, PyObject *unused) {
    WorldObject *self = (WorldObject *)obj;
    if (!check_ready(self)) return NULL;
    int n = gc_world_contacts(self->world, NULL, 0);
    gcContactPoint *points = PyMem_Malloc(sizeof(gcContactPoint) * (size_t)(n > 0 ? n : 1));
    if (!points) return PyErr_NoMemory();
    n = gc_world_contacts(self->world, points, n);
    PyObject *list = fields_list(contact_fields, COUNT_OF(contact_fields), points, sizeof points[0], n);
    PyMem_Free(points);
    return list;
}

/* ---- Runtime: haptic loop and object manager threads (runtime*.c, docs/runtime.md) ----
 * push_hips, _snapshot and stats may run while another thread is inside advance/stop: the
 * core serialises them itself. */

static PyObject *World_start(PyObject *obj, PyObject *args, PyObject *kwargs) {
    WorldObject *self = (WorldObject *)obj;
    gcRuntimeDef def = gc_default_runtime_def();
    PyObject *given[MAX_FIELDS];
    if (!parse_params("start", args, kwargs, runtime_params, COUNT_OF(runtime_params), 0, &def, given) ||
        !check_ready(self))
        return NULL;
    return none_or_raise(self, gc_world_start(self->world, &def));
}

/* stop(): joins the threads with the GIL released (the loops never need it). */
static PyObject *World_stop(PyObject *obj, PyObject *unused) {
    WorldObject *self = (WorldObject *)obj;
    if (!check_ready(self)) return NULL;
    gcStatus st;
    WITHOUT_GIL(self, st = gc_world_stop(self->world));
    return none_or_raise(self, st);
}

/* advance(ticks, delay=0.0): manual clock only; the GIL is released meanwhile. */
static PyObject *World_advance(PyObject *obj, PyObject *args, PyObject *kwargs) {
    WorldObject *self = (WorldObject *)obj;
    static char *kwlist[] = {"ticks", "delay", NULL};
    int ticks;
    double delay = 0.0;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "i|d", kwlist, &ticks, &delay) || !check_ready(self)) return NULL;
    gcStatus st;
    WITHOUT_GIL(self, st = gc_world_advance(self->world, ticks, delay));
    return none_or_raise(self, st);
}

/* _set_hip_track(times float64 (n,), positions float64 (n, m, 3), scripted bytes (m) or None
 * [, orientations float64 (n, m, 4) or None]). */
static PyObject *World_set_hip_track(PyObject *obj, PyObject *args) {
    WorldObject *self = (WorldObject *)obj;
    PyObject *times_obj, *pos_obj, *scripted_obj, *quat_obj = Py_None;
    int num_fingers;
    if (!PyArg_ParseTuple(args, "OOiO|O", &times_obj, &pos_obj, &num_fingers, &scripted_obj, &quat_obj) ||
        !check_ready(self))
        return NULL;
    Py_buffer t, p, m = {0}, q = {0};
    if (PyObject_GetBuffer(times_obj, &t, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0) return NULL;
    if (PyObject_GetBuffer(pos_obj, &p, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0) {
        PyBuffer_Release(&t);
        return NULL;
    }
    int has_mask = scripted_obj != Py_None;
    if (has_mask && PyObject_GetBuffer(scripted_obj, &m, PyBUF_C_CONTIGUOUS) < 0) {
        PyBuffer_Release(&t);
        PyBuffer_Release(&p);
        return NULL;
    }
    int has_quat = quat_obj != Py_None;
    if (has_quat && PyObject_GetBuffer(quat_obj, &q, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0) {
        if (has_mask) PyBuffer_Release(&m);
        PyBuffer_Release(&t);
        PyBuffer_Release(&p);
        return NULL;
    }
    PyObject *result = NULL;
    Py_ssize_t n = t.len / (Py_ssize_t)sizeof(double);
    if (!t.format || strcmp(t.format, "d") != 0 || !p.format || strcmp(p.format, "d") != 0)
        PyErr_SetString(PyExc_ValueError, "set_hip_track: times and positions must be float64 arrays");
    else if (num_fingers < 1 || p.len != n * num_fingers * 3 * (Py_ssize_t)sizeof(double))
        PyErr_Format(PyExc_ValueError, "set_hip_track: positions must hold %zd x %d xyz rows", n, num_fingers);
    else if (has_mask && m.len != num_fingers)
        PyErr_Format(PyExc_ValueError, "set_hip_track: scripted must have %d entries", num_fingers);
    else if (has_quat && (!q.format || strcmp(q.format, "d") != 0 ||
                          q.len != n * num_fingers * 4 * (Py_ssize_t)sizeof(double)))
        PyErr_Format(PyExc_ValueError, "set_hip_track: orientations must be float64 and hold %zd x %d wxyz rows", n,
                     num_fingers);
    else {
        gcStatus st = gc_world_set_hip_track(self->world, t.buf, p.buf, (int)n, num_fingers,
                                             has_mask ? (const unsigned char *)m.buf : NULL);
        if (st >= 0 && has_quat && n > 0) st = gc_world_set_hip_track_orientations(self->world, q.buf);
        if (st < 0) {
            if (n > 0) gc_world_set_hip_track(self->world, NULL, NULL, 0, 1, NULL); /* none half set */
            raise_status(self, st);
        } else
            result = Py_NewRef(Py_None);
    }
    if (has_quat) PyBuffer_Release(&q);
    if (has_mask) PyBuffer_Release(&m);
    PyBuffer_Release(&p);
    PyBuffer_Release(&t);
    return result;
}

/* Quaternions (w, x, y, z), one a row of `rows` (float64, C-contiguous) into q: 0 with
 * ValueError otherwise (q released). */
static int wxyz_rows(PyObject *obj, Py_buffer *q, Py_ssize_t rows) {
    if (PyObject_GetBuffer(obj, q, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0) return 0;
    if (!q->format || strcmp(q->format, "d") != 0 || q->len != rows * 4 * (Py_ssize_t)sizeof(double)) {
        PyBuffer_Release(q);
        PyErr_Format(PyExc_ValueError, "orientations: must be a C-contiguous float64 array of %zd wxyz rows", rows);
        return 0;
    }
    return 1;
}

/* _push_hips(positions float64 (n, 3), t[, orientations float64 (n, 4) or None]). */
static PyObject *World_push_hips(PyObject *obj, PyObject *args) {
    WorldObject *self = (WorldObject *)obj;
    PyObject *positions, *quat_obj = Py_None;
    double t;
    if (!PyArg_ParseTuple(args, "Od|O", &positions, &t, &quat_obj) || !check_world(self)) return NULL;
    Py_buffer b, q = {0};
    Py_ssize_t rows = xyz_rows(positions, &b, "positions", 1, INT_MAX / 4);
    if (rows < 0) return NULL;
    int has_quat = quat_obj != Py_None;
    if (has_quat && !wxyz_rows(quat_obj, &q, rows)) {
        PyBuffer_Release(&b);
        return NULL;
    }
    PyObject *result = NULL;
    gcStatus st = gc_world_push_finger_poses(self->world, b.buf, has_quat ? q.buf : NULL, (int)rows, t);
    if (st < 0)
        raise_status(self, st);
    else
        result = PyBool_FromLong(st == GC_OK);
    if (has_quat) PyBuffer_Release(&q);
    PyBuffer_Release(&b);
    return result;
}

/* _snapshot() -> (time, object_time, tick, forces_enabled, n_bodies, n_fingers, poses,
 * wrenches, adopted, god_objects, hips, forces, spring_forces, states, contact_bodies,
 * normals, velocities, patches), arrays as bytearrays (float64, uint8, int32; patches float32) for
 * numpy.frombuffer. */
static PyObject *World_snapshot(PyObject *obj, PyObject *unused) {
    WorldObject *self = (WorldObject *)obj;
    if (!check_world(self)) return NULL;
    if (!gc_world_running(self->world) && !check_ready(self)) return NULL;
    int nb = gc_world_body_count(self->world), nf = gc_world_finger_count(self->world);
    enum { N_ARRAYS = 12 };
    Py_ssize_t sizes[N_ARRAYS] = {nb * 7 * 8, nb * 6 * 8, nb,     nf * 3 * 8, nf * 3 * 8, nf * 3 * 8,
                                  nf * 3 * 8, nf * 4,     nf * 4, nf * 3 * 8, nb * 6 * 8,
                                  nf * 2 * GC_FINGER_PATCH_CORNERS * 4};
    PyObject *arrays[N_ARRAYS] = {NULL};
    for (int i = 0; i < N_ARRAYS; ++i) {
        arrays[i] = PyByteArray_FromStringAndSize(NULL, sizes[i]);
        if (!arrays[i]) {
            for (int j = 0; j < i; ++j) Py_DECREF(arrays[j]);
            return NULL;
        }
    }
    gcSnapshot snap;
    memset(&snap, 0, sizeof snap);
    snap.poses = (double *)PyByteArray_AsString(arrays[0]);
    snap.residual_wrenches = (double *)PyByteArray_AsString(arrays[1]);
    snap.adopted = (uint8_t *)PyByteArray_AsString(arrays[2]);
    snap.god_objects = (double *)PyByteArray_AsString(arrays[3]);
    snap.hips = (double *)PyByteArray_AsString(arrays[4]);
    snap.forces = (double *)PyByteArray_AsString(arrays[5]);
    snap.spring_forces = (double *)PyByteArray_AsString(arrays[6]);
    snap.finger_states = (int32_t *)PyByteArray_AsString(arrays[7]);
    snap.contact_bodies = (int32_t *)PyByteArray_AsString(arrays[8]);
    snap.normals = (double *)PyByteArray_AsString(arrays[9]);
    snap.velocities = (double *)PyByteArray_AsString(arrays[10]);
    snap.patches = (float *)PyByteArray_AsString(arrays[11]);
    gcStatus st = gc_world_snapshot(self->world, &snap);
    if (st < 0) {
        for (int i = 0; i < N_ARRAYS; ++i) Py_DECREF(arrays[i]);
        return raise_status(self, st);
    }
    return Py_BuildValue("(ddKiiiNNNNNNNNNNNN)", snap.time, snap.object_time, (unsigned long long)snap.tick,
                         snap.forces_enabled, nb, nf, arrays[0], arrays[1], arrays[2], arrays[3], arrays[4],
                         arrays[5], arrays[6], arrays[7], arrays[8], arrays[9], arrays[10], arrays[11]);
}

static PyObject *World_stats(PyObject *obj, PyObject *unused) {
    WorldObject *self = (WorldObject *)obj;
    if (!check_world(self)) return NULL;
    gcRuntimeStats s;
    gcStatus st = gc_world_stats(self->world, &s);
    if (st < 0) return raise_status(self, st);
    return fields_dict(runtime_stats_fields, COUNT_OF(runtime_stats_fields), &s);
}

static PyObject *World_debug_stall(PyObject *obj, PyObject *arg) {
    WorldObject *self = (WorldObject *)obj;
    double seconds = PyFloat_AsDouble(arg);
    if ((seconds == -1.0 && PyErr_Occurred()) || !check_world(self)) return NULL;
    return none_or_raise(self, gc_world_debug_stall(self->world, seconds));
}

/* ---- Tick log (tick_log.c, docs/recording-format.md) --------------------------------- */

/* A writable, C-contiguous buffer of at least `need` bytes (the caller releases it). */
static int writable_buffer(PyObject *arg, Py_buffer *b, size_t need, const char *what) {
    if (PyObject_GetBuffer(arg, b, PyBUF_WRITABLE | PyBUF_C_CONTIGUOUS) < 0) return 0;
    if ((size_t)b->len < need) {
        PyErr_Format(PyExc_ValueError, "%s: buffer of %zd bytes, need at least %zu", what, b->len, need);
        PyBuffer_Release(b);
        return 0;
    }
    return 1;
}

static PyObject *World_tick_record(PyObject *obj, PyObject *args) {
    WorldObject *self = (WorldObject *)obj;
    PyObject *out;
    unsigned long long tick;
    if (!check_ready(self) || !PyArg_ParseTuple(args, "OK", &out, &tick)) return NULL;
    Py_buffer b;
    size_t need = gc_tick_record_size(gc_world_body_count(self->world), gc_world_finger_count(self->world));
    if (!writable_buffer(out, &b, need, "tick_record")) return NULL;
    gcStatus st = gc_world_tick_record(self->world, tick, b.buf, (size_t)b.len);
    PyBuffer_Release(&b);
    return none_or_raise(self, st);
}

static PyObject *World_step_hips(PyObject *obj, PyObject *args) {
    WorldObject *self = (WorldObject *)obj;
    PyObject *hips_obj, *out;
    int steps, fingers;
    double dt;
    unsigned long long first_tick;
    if (!PyArg_ParseTuple(args, "OiidOK", &hips_obj, &steps, &fingers, &dt, &out, &first_tick) || !check_ready(self))
        return NULL;
    if (steps < 0 || fingers < 0) {
        PyErr_SetString(PyExc_ValueError, "hips: expected (steps, fingers, 3)");
        return NULL;
    }
    Py_buffer h, b;
    if (PyObject_GetBuffer(hips_obj, &h, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0) return NULL;
    if (!h.format || strcmp(h.format, "d") != 0 ||
        (size_t)h.len < (size_t)steps * (size_t)fingers * 3 * sizeof(double)) {
        PyBuffer_Release(&h);
        PyErr_SetString(PyExc_ValueError, "hips: must be a C-contiguous float64 array of (steps, fingers, 3)");
        return NULL;
    }
    size_t record = gc_tick_record_size(gc_world_body_count(self->world), gc_world_finger_count(self->world));
    int records = out != Py_None;       /* None: the steps alone (benchmarks) */
    if (records && !writable_buffer(out, &b, record * (size_t)steps, "out")) {
        PyBuffer_Release(&h);
        return NULL;
    }
    gcStatus st;
    WITHOUT_GIL(self, {
        st = gc_world_step_hips(self->world, h.buf, fingers, steps, dt, first_tick, records ? b.buf : NULL,
                                records ? (size_t)b.len : 0, NULL);
    });
    if (records) PyBuffer_Release(&b);
    PyBuffer_Release(&h);
    if (st < 0) return raise_status(self, st);
    if (warn_status(self, st) < 0) return NULL;
    Py_RETURN_NONE;
}

/* ---- replay of a recorded hand-over schedule (docs/runtime.md), a block of its own ----
 * _replay_ticks(hips float64 (steps, fingers, 3), orientations float64 (steps, fingers, 4) or
 * None, object_ticks uint64 (steps,), object_reads uint64 (steps,), steps, fingers, out or None):
 * gc_world_replay_ticks with the GIL released. The Python wrapper checks shapes and dtypes. */
static int replay_buffer(PyObject *arg, Py_buffer *b, size_t need, const char *format, const char *what) {
    if (PyObject_GetBuffer(arg, b, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0) return 0;
    /* uint64: numpy says 'L' where unsigned long is 8 bytes, 'Q' elsewhere */
    int same = b->format && (strcmp(b->format, format) == 0 ||
                             (strcmp(format, "Q") == 0 && strcmp(b->format, "L") == 0 && b->itemsize == 8));
    if (!same || (size_t)b->len < need) {
        PyBuffer_Release(b);
        PyErr_Format(PyExc_ValueError, "%s: must be a C-contiguous array of %zu bytes of format '%s'", what, need,
                     format);
        return 0;
    }
    return 1;
}

static PyObject *World_replay_ticks(PyObject *obj, PyObject *args) {
    WorldObject *self = (WorldObject *)obj;
    PyObject *hips_obj, *quat_obj, *ticks_obj, *reads_obj, *out;
    int steps, fingers;
    if (!PyArg_ParseTuple(args, "OOOOiiO", &hips_obj, &quat_obj, &ticks_obj, &reads_obj, &steps, &fingers, &out) ||
        !check_ready(self))
        return NULL;
    if (steps < 0 || fingers < 0) {
        PyErr_SetString(PyExc_ValueError, "hips: expected (steps, fingers, 3)");
        return NULL;
    }
    size_t n = (size_t)steps, nf = (size_t)fingers;
    Py_buffer h, q, t, r, b;
    int quats = quat_obj != Py_None, records = out != Py_None;
    if (!replay_buffer(hips_obj, &h, n * nf * 3 * sizeof(double), "d", "hips")) return NULL;
    if (quats && !replay_buffer(quat_obj, &q, n * nf * 4 * sizeof(double), "d", "orientations")) goto fail_h;
    if (!replay_buffer(ticks_obj, &t, n * sizeof(uint64_t), "Q", "object_ticks")) goto fail_q;
    if (!replay_buffer(reads_obj, &r, n * sizeof(uint64_t), "Q", "object_reads")) goto fail_t;
    size_t record = gc_tick_record_size(gc_world_body_count(self->world), gc_world_finger_count(self->world));
    if (records && !writable_buffer(out, &b, record * n, "out")) goto fail_r;
    gcStatus st;
    atomic_store(&self->busy, 1);
    Py_BEGIN_ALLOW_THREADS
    st = gc_world_replay_ticks(self->world, h.buf, quats ? q.buf : NULL, fingers, t.buf, r.buf, steps,
                               records ? b.buf : NULL, records ? (size_t)b.len : 0, NULL);
    Py_END_ALLOW_THREADS
    atomic_store(&self->busy, 0);
    if (records) PyBuffer_Release(&b);
    PyBuffer_Release(&r);
    PyBuffer_Release(&t);
    if (quats) PyBuffer_Release(&q);
    PyBuffer_Release(&h);
    if (st < 0) return raise_status(self, st);
    Py_RETURN_NONE;
fail_r:
    PyBuffer_Release(&r);
fail_t:
    PyBuffer_Release(&t);
fail_q:
    if (quats) PyBuffer_Release(&q);
fail_h:
    PyBuffer_Release(&h);
    return NULL;
}
/* ---- end of the replay block ---- */

/* ---- step_hips with a short trace per step (docs/api.md), a block of its own ----
 * _step_hips_trace(hips float64 (steps, fingers, 3), steps, fingers, dt, out, first, total): the
 * GIL released. */
static PyObject *World_step_hips_trace(PyObject *obj, PyObject *args) {
    WorldObject *self = (WorldObject *)obj;
    PyObject *hips_obj, *out;
    int steps, fingers, first, total;
    double dt;
    if (!PyArg_ParseTuple(args, "OiidOii", &hips_obj, &steps, &fingers, &dt, &out, &first, &total) ||
        !check_ready(self))
        return NULL;
    if (steps < 0 || fingers < 0) {
        PyErr_SetString(PyExc_ValueError, "hips: expected (steps, fingers, 3)");
        return NULL;
    }
    Py_buffer h, b;
    if (!replay_buffer(hips_obj, &h, (size_t)steps * (size_t)fingers * 3 * sizeof(double), "d", "hips")) return NULL;
    size_t trace = gc_tick_trace_size(gc_world_body_count(self->world), gc_world_finger_count(self->world));
    if (total < 0 || !writable_buffer(out, &b, trace * (size_t)total, "out")) {
        PyBuffer_Release(&h);
        return NULL;
    }
    gcStatus st;
    atomic_store(&self->busy, 1);
    Py_BEGIN_ALLOW_THREADS
    st = gc_world_step_hips_trace(self->world, h.buf, fingers, steps, dt, first, total, b.buf, (size_t)b.len, NULL);
    Py_END_ALLOW_THREADS
    atomic_store(&self->busy, 0);
    PyBuffer_Release(&b);
    PyBuffer_Release(&h);
    if (st < 0) return raise_status(self, st);
    if (warn_status(self, st) < 0) return NULL;
    Py_RETURN_NONE;
}

static PyObject *tick_trace_size(PyObject *mod, PyObject *args) {
    int nb, nf;
    if (!PyArg_ParseTuple(args, "ii", &nb, &nf)) return NULL;
    return PyLong_FromSize_t(gc_tick_trace_size(nb, nf));
}
/* ---- end of the trace block ---- */

static PyObject *World_set_tick_log(PyObject *obj, PyObject *arg) {
    WorldObject *self = (WorldObject *)obj;
    if (!check_ready(self)) return NULL;
    int capacity = PyLong_AsLong(arg);
    if (capacity == -1 && PyErr_Occurred()) return NULL;
    return none_or_raise(self, gc_world_set_tick_log(self->world, capacity));
}

/* The tick log is safe from any thread at any time (tick_log.c): check_world, not check_ready,
 * so a recorder thread drains while another thread steps, advances or stops the world. */
static PyObject *World_drain_ticks(PyObject *obj, PyObject *arg) {
    WorldObject *self = (WorldObject *)obj;
    if (!check_world(self)) return NULL;
    Py_buffer b;
    if (!writable_buffer(arg, &b, 0, "drain_ticks")) return NULL;
    int n;
    Py_BEGIN_ALLOW_THREADS
    n = gc_world_drain_ticks(self->world, b.buf, (size_t)b.len, 1 << 30);
    Py_END_ALLOW_THREADS
    PyBuffer_Release(&b);
    if (n < 0) return raise_status(self, (gcStatus)n);
    return PyLong_FromLong(n);
}

static PyObject *module_tick_record_size(PyObject *mod, PyObject *args) {
    int nb, nf;
    if (!PyArg_ParseTuple(args, "ii", &nb, &nf)) return NULL;
    if (nb < 0 || nf < 0) {
        PyErr_SetString(PyExc_ValueError, "tick_record_size: counts must be >= 0");
        return NULL;
    }
    return PyLong_FromSize_t(gc_tick_record_size(nb, nf));
}

/* ---- grasp quality (docs/api.md "Grasp quality") ---- */

/* One workspace kept between calls (its storage grows to the largest grasp seen); a call that
 * finds it in use on another thread (the GIL is released while it works) makes its own. */
static gcGraspWorkspace *cached_workspace;
static atomic_int cached_workspace_busy;

static gcGraspWorkspace *workspace_take(void) {
    if (atomic_exchange(&cached_workspace_busy, 1) == 0) {
        if (!cached_workspace) cached_workspace = gc_grasp_workspace_create();
        if (cached_workspace) return cached_workspace;
        atomic_store(&cached_workspace_busy, 0);
    }
    gcGraspWorkspace *ws = gc_grasp_workspace_create();
    if (!ws) PyErr_NoMemory();
    return ws;
}

static void workspace_give(gcGraspWorkspace *ws) {
    if (ws && ws == cached_workspace)
        atomic_store(&cached_workspace_busy, 0);
    else
        gc_grasp_workspace_destroy(ws);
}

/* Up to 8 C-contiguous buffers of a grasp call: each of format fmt[i] ('d' float64, 'i' int32)
 * and, when count[i] >= 0, exactly that many items. 1 on success (release with release_all). */
typedef struct GraspBuffers {
    Py_buffer b[8];
    int n;
} GraspBuffers;

static void release_all(GraspBuffers *g) {
    for (int i = 0; i < g->n; ++i) PyBuffer_Release(&g->b[i]);
    g->n = 0;
}

static int take_buffer(GraspBuffers *g, PyObject *arg, char fmt, Py_ssize_t count, const char *name, int writable) {
    Py_buffer *b = &g->b[g->n];
    if (PyObject_GetBuffer(arg, b, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0)) < 0)
        return 0;
    Py_ssize_t size = fmt == 'd' ? (Py_ssize_t)sizeof(double) : (Py_ssize_t)sizeof(int32_t);
    int ok = writable ? 1 : (b->format && b->format[0] == fmt && b->format[1] == '\0' && b->itemsize == size);
    if (ok && count >= 0) ok = b->len == count * size;
    if (!ok) {
        PyErr_Format(PyExc_ValueError, "%s: expected a C-contiguous %s array of %zd items", name,
                     fmt == 'd' ? "float64" : "int32", count);
        PyBuffer_Release(b);
        return 0;
    }
    ++g->n;
    return 1;
}

/* The options of a grasp call (gcGraspDef) over the core's defaults. */
static gcGraspDef grasp_def(int edges, int volume, int reuse) {
    gcGraspDef def = gc_default_grasp_def();
    def.edges = edges;
    def.volume = volume;
    def.reuse = reuse;
    return def;
}

/* Soft contacts (gcGraspDef.torsion): an optional trailing argument of the three grasp calls, None
 * or a float64 buffer of one rho per contact row; 1 on success. */
static int take_torsion(GraspBuffers *g, PyObject *to, Py_ssize_t rows, gcGraspDef *def) {
    if (!to || to == Py_None) return 1;
    if (!take_buffer(g, to, 'd', rows, "torsion", 0)) return 0;
    def->torsion = g->b[g->n - 1].buf;
    return 1;
}

/* _grasp_quality(points, normals, mu, center, radius, edges, volume, reuse[, torsion]): float64
 * buffers of 3n, 3n, n, 3 (torsion n); volume and reuse bools (gcGraspDef.volume, .reuse). */
static PyObject *module_grasp_quality(PyObject *mod, PyObject *args) {
    PyObject *po, *no, *mo, *co, *to = NULL;
    double radius;
    int edges, volume, reuse;
    if (!PyArg_ParseTuple(args, "OOOOdipp|O", &po, &no, &mo, &co, &radius, &edges, &volume, &reuse, &to))
        return NULL;
    gcGraspDef def = grasp_def(edges, volume, reuse);
    GraspBuffers g = {.n = 0};
    PyObject *result = NULL;
    if (take_buffer(&g, mo, 'd', -1, "mu", 0)) {
        Py_ssize_t n = g.b[0].len / (Py_ssize_t)sizeof(double);
        if (n > INT_MAX / 3) {
            PyErr_SetString(PyExc_ValueError, "points: too many contacts");
        } else if (take_buffer(&g, po, 'd', 3 * n, "points", 0) && take_buffer(&g, no, 'd', 3 * n, "normals", 0) &&
                   take_buffer(&g, co, 'd', 3, "center", 0) && take_torsion(&g, to, n, &def)) {
            gcGraspWorkspace *ws = workspace_take();
            if (ws) {
                gcGraspQuality q;
                gcStatus st;
                Py_BEGIN_ALLOW_THREADS
                st = gc_grasp_quality(ws, &def, g.b[1].buf, g.b[2].buf, g.b[0].buf, (int)n, g.b[3].buf, radius, &q);
                Py_END_ALLOW_THREADS
                result = st < 0 ? raise_message(st, gc_grasp_workspace_error(ws))
                                : fields_dict(grasp_quality_fields, COUNT_OF(grasp_quality_fields), &q);
                workspace_give(ws);
            }
        }
    }
    release_all(&g);
    return result;
}

/* _grasp_quality_batch(points, normals, mu, counts (int32), centers, radii, edges, volume, reuse, out
 * [, torsion]): out a writable buffer of len(counts) * GRASP_QUALITY_SIZE bytes, filled with
 * gcGraspQuality records. */
static PyObject *module_grasp_quality_batch(PyObject *mod, PyObject *args) {
    PyObject *po, *no, *mo, *ko, *co, *ro, *oo, *to = NULL;
    int edges, volume, reuse;
    if (!PyArg_ParseTuple(args, "OOOOOOippO|O", &po, &no, &mo, &ko, &co, &ro, &edges, &volume, &reuse, &oo, &to))
        return NULL;
    gcGraspDef def = grasp_def(edges, volume, reuse);
    GraspBuffers g = {.n = 0};
    PyObject *result = NULL;
    if (take_buffer(&g, mo, 'd', -1, "mu", 0) && take_buffer(&g, ko, 'i', -1, "counts", 0)) {
        Py_ssize_t rows = g.b[0].len / (Py_ssize_t)sizeof(double);
        Py_ssize_t sets = g.b[1].len / (Py_ssize_t)sizeof(int32_t);
        if (rows > INT_MAX / 3 || sets > INT_MAX / 3) {
            PyErr_SetString(PyExc_ValueError, "counts: too many contact sets");
        } else if (take_buffer(&g, po, 'd', 3 * rows, "points", 0) &&
                   take_buffer(&g, no, 'd', 3 * rows, "normals", 0) &&
                   take_buffer(&g, co, 'd', 3 * sets, "centers", 0) && take_buffer(&g, ro, 'd', sets, "radii", 0) &&
                   take_buffer(&g, oo, 'd', -1, "out", 1) && take_torsion(&g, to, rows, &def)) {
            const int32_t *counts = g.b[1].buf;
            long long total = 0;
            for (Py_ssize_t s = 0; s < sets; ++s) total += counts[s] > 0 ? counts[s] : 0;
            if (g.b[6].len != sets * (Py_ssize_t)sizeof(gcGraspQuality)) {
                PyErr_SetString(PyExc_ValueError, "out: wrong size");
            } else if (total != rows) {
                PyErr_Format(PyExc_ValueError, "counts: they add up to %lld contacts, points has %zd rows", total,
                             rows);
            } else {
                gcGraspWorkspace *ws = workspace_take();
                if (ws) {
                    gcStatus st;
                    Py_BEGIN_ALLOW_THREADS
                    st = gc_grasp_quality_batch(ws, &def, g.b[2].buf, g.b[3].buf, g.b[0].buf, counts, (int)sets,
                                                g.b[4].buf, g.b[5].buf, g.b[6].buf);
                    Py_END_ALLOW_THREADS
                    result = st < 0 ? raise_message(st, gc_grasp_workspace_error(ws)) : Py_NewRef(Py_None);
                    workspace_give(ws);
                }
            }
        }
    }
    release_all(&g);
    return result;
}

/* _grasp_mu_min(points, normals, center, radius, edges, mu_max, reuse[, torsion]) -> float. */
static PyObject *module_grasp_mu_min(PyObject *mod, PyObject *args) {
    PyObject *po, *no, *co, *to = NULL;
    double radius, mu_max;
    int edges, reuse;
    if (!PyArg_ParseTuple(args, "OOOdidp|O", &po, &no, &co, &radius, &edges, &mu_max, &reuse, &to)) return NULL;
    gcGraspDef def = grasp_def(edges, gc_default_grasp_def().volume, reuse);
    GraspBuffers g = {.n = 0};
    PyObject *result = NULL;
    if (take_buffer(&g, po, 'd', -1, "points", 0)) {
        Py_ssize_t n = g.b[0].len / (Py_ssize_t)(3 * sizeof(double));
        if (n > INT_MAX / 3 || g.b[0].len % (Py_ssize_t)(3 * sizeof(double)) != 0) {
            PyErr_SetString(PyExc_ValueError, "points: expected xyz rows");
        } else if (take_buffer(&g, no, 'd', 3 * n, "normals", 0) && take_buffer(&g, co, 'd', 3, "center", 0) &&
                   take_torsion(&g, to, n, &def)) {
            gcGraspWorkspace *ws = workspace_take();
            if (ws) {
                double mu = 0.0;
                gcStatus st;
                Py_BEGIN_ALLOW_THREADS
                st = gc_grasp_mu_min(ws, &def, g.b[0].buf, g.b[1].buf, (int)n, g.b[2].buf, radius, mu_max, &mu);
                Py_END_ALLOW_THREADS
                result = st < 0 ? raise_message(st, gc_grasp_workspace_error(ws)) : PyFloat_FromDouble(mu);
                workspace_give(ws);
            }
        }
    }
    release_all(&g);
    return result;
}

/* ---- serial devices ---- */

static PyObject *World_attach_serial(PyObject *obj, PyObject *args, PyObject *kwargs) {
    WorldObject *self = (WorldObject *)obj;
    static const Field fd_param = {"fd", FIELD_INT, 0, 0, 0, NULL};
    gcSerialDef def = gc_default_serial_def();
    PyObject *given[MAX_FIELDS];
    int fd;
    if (!parse_params("attach_serial", args, kwargs, serial_params, COUNT_OF(serial_params), 1, &def, given))
        return NULL;
    if (!given[0]) {
        PyErr_SetString(PyExc_TypeError, "attach_serial() missing required argument 'fd'");
        return NULL;
    }
    if (!set_field(&fd_param, given[0], &fd) || !check_world(self)) return NULL;
    int32_t id;
    gcStatus st = gc_world_attach_serial(self->world, fd, &def, &id);
    if (st < 0) return raise_status(self, st);
    return PyLong_FromLong(id);
}

static int serial_id(WorldObject *self, PyObject *args, int32_t *id, int *flag) {
    int ok = flag ? PyArg_ParseTuple(args, "ip", id, flag) : PyArg_ParseTuple(args, "i", id);
    return ok && check_world(self);
}

static PyObject *serial_result(WorldObject *self, int32_t id, gcStatus st) {
    if (st == GC_ERR_UNKNOWN_ID) {
        PyErr_Format(PyExc_ValueError, "device %d: no such serial device", (int)id);
        return NULL;
    }
    return none_or_raise(self, st);
}

/* detach_serial(device): joins the device's thread with the GIL released. */
static PyObject *World_detach_serial(PyObject *obj, PyObject *args) {
    WorldObject *self = (WorldObject *)obj;
    int32_t id;
    if (!serial_id(self, args, &id, NULL)) return NULL;
    gcStatus st;
    Py_BEGIN_ALLOW_THREADS
    st = gc_world_detach_serial(self->world, id);
    Py_END_ALLOW_THREADS
    return serial_result(self, id, st);
}

static PyObject *World_serial_enable(PyObject *obj, PyObject *args) {
    WorldObject *self = (WorldObject *)obj;
    int32_t id;
    int on;
    if (!serial_id(self, args, &id, &on)) return NULL;
    return serial_result(self, id, gc_world_serial_enable(self->world, id, on));
}

static PyObject *World_serial_estop(PyObject *obj, PyObject *args) {
    WorldObject *self = (WorldObject *)obj;
    int32_t id;
    if (!serial_id(self, args, &id, NULL)) return NULL;
    return serial_result(self, id, gc_world_serial_estop(self->world, id));
}

static PyObject *World_serial_stats(PyObject *obj, PyObject *args) {
    WorldObject *self = (WorldObject *)obj;
    int32_t id;
    if (!serial_id(self, args, &id, NULL)) return NULL;
    gcSerialStats s;
    gcStatus st = gc_world_serial_stats(self->world, id, &s);
    if (st < 0) return serial_result(self, id, st);
    return fields_dict(serial_stats_fields, COUNT_OF(serial_stats_fields), &s);
}

/* A device read in Python: (finger_offset, float64 buffer of xyz rows) handed to the core;
 * True if taken, False if rejected (counted). */
typedef gcStatus (*DeviceRows)(gcWorld *, int, int, const double *);

static PyObject *device_rows(WorldObject *self, int offset, PyObject *rows_obj, DeviceRows call,
                             const char *rows_name, const char *not_running) {
    Py_buffer b;
    Py_ssize_t rows = xyz_rows(rows_obj, &b, rows_name, 1, INT_MAX);
    if (rows < 0) return NULL;
    gcStatus st = call(self->world, offset, (int)rows, b.buf);
    PyBuffer_Release(&b);
    if (st == GC_ERR_NOT_RUNNING && not_running) {
        PyErr_SetString(PyExc_RuntimeError, not_running);
        return NULL;
    }
    if (st < 0) return raise_status(self, st);
    return PyBool_FromLong(st == GC_OK);
}

/* push_device_hips(finger_offset, positions[, orientations float64 (n, 4) or None]): HIPs, and
 * convex fingers' orientations, from a device read in Python. */
static PyObject *World_push_device_hips(PyObject *obj, PyObject *args) {
    WorldObject *self = (WorldObject *)obj;
    int offset;
    PyObject *rows_obj, *quat_obj = Py_None;
    if (!PyArg_ParseTuple(args, "iO|O", &offset, &rows_obj, &quat_obj) || !check_world(self)) return NULL;
    if (quat_obj == Py_None) return device_rows(self, offset, rows_obj, gc_world_push_device_hips, "positions",
                                                "push_device_hips: the runtime is not running (World.start)");
    Py_buffer b, q;
    Py_ssize_t rows = xyz_rows(rows_obj, &b, "positions", 1, INT_MAX / 4);
    if (rows < 0) return NULL;
    if (!wxyz_rows(quat_obj, &q, rows)) {
        PyBuffer_Release(&b);
        return NULL;
    }
    gcStatus st = gc_world_push_device_poses(self->world, offset, (int)rows, b.buf, q.buf);
    PyBuffer_Release(&q);
    PyBuffer_Release(&b);
    if (st == GC_ERR_NOT_RUNNING) {
        PyErr_SetString(PyExc_RuntimeError, "push_device_hips: the runtime is not running (World.start)");
        return NULL;
    }
    if (st < 0) return raise_status(self, st);
    return PyBool_FromLong(st == GC_OK);
}

/* device_forces_sent(finger_offset, forces): what that device was sent, for the record. */
static PyObject *World_device_forces_sent(PyObject *obj, PyObject *args) {
    WorldObject *self = (WorldObject *)obj;
    int offset;
    PyObject *rows_obj;
    if (!PyArg_ParseTuple(args, "iO", &offset, &rows_obj) || !check_world(self)) return NULL;
    return device_rows(self, offset, rows_obj, gc_world_device_forces_sent, "forces", NULL);
}

/* ---- devices read in Python: their forces from the haptic tick, through the one gate ---- */
/* device_forces(finger_offset, out: writable float64 (n, 3), enable) -> None: out filled. */
static PyObject *World_device_forces(PyObject *obj, PyObject *args) {
    WorldObject *self = (WorldObject *)obj;
    int offset, enable;
    PyObject *target;
    if (!PyArg_ParseTuple(args, "iOp", &offset, &target, &enable) || !check_world(self)) return NULL;
    Py_buffer b;
    if (PyObject_GetBuffer(target, &b, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | PyBUF_WRITABLE) < 0) return NULL;
    PyObject *result = NULL;
    if (!b.format || strcmp(b.format, "d") != 0 || b.len % (3 * (Py_ssize_t)sizeof(double)) != 0 || b.len == 0) {
        PyErr_SetString(PyExc_ValueError, "out: must be a writable C-contiguous float64 array of xyz rows");
    } else {
        gcStatus st = gc_world_device_forces(self->world, offset, (int)(b.len / (Py_ssize_t)(3 * sizeof(double))),
                                             enable, b.buf);
        if (st == GC_ERR_NOT_RUNNING)
            PyErr_SetString(PyExc_RuntimeError, "device_forces: the runtime is not running (World.start)");
        else if (st < 0)
            raise_status(self, st);
        else
            result = Py_NewRef(Py_None);
    }
    PyBuffer_Release(&b);
    return result;
}
/* ---- end of devices read in Python ---- */

/* serial_events(device) -> [(time, name, value, session_time)], popped oldest first. */
static PyObject *World_serial_events(PyObject *obj, PyObject *args) {
    WorldObject *self = (WorldObject *)obj;
    int32_t id;
    if (!serial_id(self, args, &id, NULL)) return NULL;
    gcSerialStats probe;
    if (gc_world_serial_stats(self->world, id, &probe) < 0) return serial_result(self, id, GC_ERR_UNKNOWN_ID);
    PyObject *list = PyList_New(0);
    gcSerialEvent ev[64];
    int n;
    while (list && (n = gc_world_serial_events(self->world, id, ev, 64)) > 0) {
        for (int i = 0; i < n; ++i) {
            const char *name = enum_name(serial_event_names, COUNT_OF(serial_event_names), (int)ev[i].code, 0);
            PyObject *item = Py_BuildValue("(dsid)", ev[i].time, name, (int)ev[i].value, ev[i].session_time);
            if (!item || PyList_Append(list, item) < 0) {
                Py_XDECREF(item);
                Py_DECREF(list);
                return NULL;
            }
            Py_DECREF(item);
        }
    }
    return list;
}

#define QUERY_ENTRY(name, call, shape, doc) {#name, World_##name, METH_VARARGS, doc},
#define SETTER_ENTRY(name, call, shape, arg_a, arg_b, doc) {#name, World_##name, METH_VARARGS, doc},
#define NUMBER_ENTRY(name, call, type, guard, doc) {#name, World_##name, METH_NOARGS, doc},
#define PROPERTY_ENTRY(name, call, type, guard, doc) {#name, World_get_##name, NULL, doc, NULL},

static PyMethodDef World_methods[] = {
    {"_add_body", (PyCFunction)(void (*)(void))World_add_body, METH_VARARGS | METH_KEYWORDS,
     "Low-level add_body(parts, radii, **BODY_DEFAULTS); use World.add_body."},
    {"add_finger", (PyCFunction)(void (*)(void))World_add_finger, METH_VARARGS | METH_KEYWORDS,
     "add_finger(radius, stiffness, damping, position=(0,0,0), points=None, orientation=(1,0,0,0), torsion=0, "
     "renderer='xfca', cursor_mass) -> finger id; points: a convex finger's (n, 3) float64 points in its frame "
     "(None: a sphere); torsion: a soft sphere fingertip's patch radius, m; renderer 'cursor': sphere fingers "
     "without torsion only; defaults: FINGER_DEFAULTS"},
    ID_QUERIES(QUERY_ENTRY)
    ID_SETTERS(SETTER_ENTRY)
    WORLD_NUMBERS(NUMBER_ENTRY)
    {"finger_contacts", World_finger_contacts, METH_VARARGS,
     "finger_contacts(finger) -> [{body, sample, reversed, state, point, normal, force}] per contact point (first 64)"},
    {"set_hips", World_set_hips, METH_O, "set_hips(array (n, 3) float64): HIPs of fingers 0..n-1."},
    {"set_gravity", World_set_gravity, METH_O, "set_gravity((gx, gy, gz))"},
    {"step", (PyCFunction)(void (*)(void))World_step, METH_VARARGS | METH_KEYWORDS,
     "step(dt, steps=1): advance the world; the GIL is released meanwhile."},
    {"_view", World_view, METH_O, "Zero-copy buffer view of world arrays."},
    {"contacts", World_contacts, METH_NOARGS,
     "contacts() -> list of dicts (body_a, body_b, point, normal, separation, normal_impulse, "
     "friction_impulse, sticking), one per body-body contact point of the last step."},
    /* Runtime (docs/runtime.md). */
    {"start", (PyCFunction)(void (*)(void))World_start, METH_VARARGS | METH_KEYWORDS,
     "start(*, haptic_rate, object_rate, max_adopted_bodies, max_force, ramp_time, watchdog_timeout,\n"
     "      hip_timeout, release_delay, realtime, priority, max_hip_speed); defaults: RUNTIME_DEFAULTS\n"
     "Run the world on a haptic loop and an object manager thread (docs/runtime.md)."},
    {"stop", World_stop, METH_NOARGS, "stop(): join the runtime threads; the world steps synchronously again."},
    {"advance", (PyCFunction)(void (*)(void))World_advance, METH_VARARGS | METH_KEYWORDS,
     "advance(ticks, delay=0.0): manual clock (start(realtime=False)) only: run ticks haptic ticks."},
    {"_set_hip_track", World_set_hip_track, METH_VARARGS, "Low-level set_hip_track; use World.set_hip_track."},
    {"_push_hips", World_push_hips, METH_VARARGS, "Low-level push_hips; use World.push_hips."},
    {"_snapshot", World_snapshot, METH_NOARGS, "Low-level snapshot; use World.snapshot."},
    {"stats", World_stats, METH_NOARGS, "stats() -> dict: rates, jitter, overruns, adoption, inputs, safety."},
    {"_tick_record", World_tick_record, METH_VARARGS, "Low-level tick_record(buffer, tick); see graspcore.tick_log."},
    {"_step_hips", World_step_hips, METH_VARARGS, "Low-level step_hips; use World.step_hips."},
    {"_replay_ticks", World_replay_ticks, METH_VARARGS, "Low-level replay_ticks; use World.replay_ticks."},
    {"_step_hips_trace", World_step_hips_trace, METH_VARARGS, "Low-level step_hips_trace; use World.step_hips_trace."},
    {"_set_tick_log", World_set_tick_log, METH_O, "Low-level set_tick_log(capacity)."},
    {"_drain_ticks", World_drain_ticks, METH_O, "Low-level drain_ticks(buffer) -> records copied."},
    {"_debug_stall", World_debug_stall, METH_O, "Test hook: stall the haptic loop this many seconds once."},
    {"attach_serial", (PyCFunction)(void (*)(void))World_attach_serial, METH_VARARGS | METH_KEYWORDS,
     "attach_serial(fd, *, finger_offset, num_fingers, transform (row-major 4x4, device metres -> world; None: "
     "identity), force_ttl, lost_timeout, max_force, ramp_time, max_position, stall_timeout, priority, udp_host, "
     "udp_port); defaults: SERIAL_DEFAULTS "
     "-> device id: a C thread speaks the Grasp Lab serial protocol on fd (docs/protocol.md); with udp_port, fd is "
     "a bound UDP socket and frames go to udp_host:udp_port until the device's hello pins its address."},
    {"detach_serial", World_detach_serial, METH_VARARGS, "detach_serial(device): stop its thread (fd stays open)."},
    {"serial_enable", World_serial_enable, METH_VARARGS, "serial_enable(device, on): forces to the device on/off."},
    {"serial_estop", World_serial_estop, METH_VARARGS, "serial_estop(device): forces off, latched until enabled."},
    {"serial_stats", World_serial_stats, METH_VARARGS, "serial_stats(device) -> dict: state, rate, drops, latency."},
    {"push_device_hips", World_push_device_hips, METH_VARARGS,
     "push_device_hips(finger_offset, array (n, 3) float64[, orientations (n, 4) float64 w x y z]): HIPs from a "
     "device read in Python (SpaceMouse, glove), merged with the serial devices' fingers; orientations (unit) turn "
     "convex fingers too. False: a NaN/Inf position or a non-unit quaternion, nothing taken (rejected_inputs)."},
    {"device_forces_sent", World_device_forces_sent, METH_VARARGS,
     "device_forces_sent(finger_offset, array (n, 3) float64): what a device read in Python was sent (scene axes), "
     "recorded as those fingers' device force until the next call."},
    {"device_forces", World_device_forces, METH_VARARGS,
     "device_forces(finger_offset, out (n, 3) float64, enable): the forces of fingers a device read in Python drives "
     "(push_device_hips), from the latest haptic tick through the same gate as a serial device's (enable, ramp, "
     "stall); recorded as sent until device_forces_sent."},
    {"serial_events", World_serial_events, METH_VARARGS, "serial_events(device) -> [(time, event, value, session_time)] safety events: monotonic and session clock."},
    {NULL, NULL, 0, NULL},
};

static PyGetSetDef World_getset[] = {
    WORLD_PROPERTIES(PROPERTY_ENTRY)
    {NULL, NULL, NULL, NULL, NULL},
};

static PyType_Slot World_slots[] = {
    {Py_tp_init, World_init},
    {Py_tp_dealloc, World_dealloc},
    {Py_tp_methods, World_methods},
    {Py_tp_getset, World_getset},
    {Py_tp_doc, "A grasp world: rigid bodies touched by god-object fingers."},
    {0, NULL},
};
static PyType_Spec World_spec = {"graspcore._core.World", sizeof(WorldObject), 0,
                                 Py_TPFLAGS_DEFAULT | Py_TPFLAGS_BASETYPE, World_slots};

/* The core's defaults (gc_default_*_def), the one place they are written: graspcore's Python
 * signatures and the add-on take theirs from these. Every table is checked against the
 * binding's limits here, at import. */
static int add_tables(PyObject *m) {
    gcWorldDef world = gc_default_world_def();
    gcBodyDef body = gc_default_body_def();
    gcFingerDef finger = gc_default_finger_def();
    gcRuntimeDef runtime = gc_default_runtime_def();
    gcSerialDef serial = gc_default_serial_def();
    const struct { const char *name; const Field *fields; int count; const void *defaults; } tables[] = {
        {"WORLD_DEFAULTS", world_params, COUNT_OF(world_params), &world},
        {"BODY_DEFAULTS", body_params, COUNT_OF(body_params), &body},
        {"FINGER_DEFAULTS", finger_params, COUNT_OF(finger_params), &finger},
        {"RUNTIME_DEFAULTS", runtime_params, COUNT_OF(runtime_params), &runtime},
        {"SERIAL_DEFAULTS", serial_params, COUNT_OF(serial_params), &serial},
        {"stats", runtime_stats_fields, COUNT_OF(runtime_stats_fields), NULL},
        {"serial_stats", serial_stats_fields, COUNT_OF(serial_stats_fields), NULL},
        {"finger_contacts", finger_contact_fields, COUNT_OF(finger_contact_fields), NULL},
        {"contacts", contact_fields, COUNT_OF(contact_fields), NULL},
        {"grasp_quality", grasp_quality_fields, COUNT_OF(grasp_quality_fields), NULL},
    };
    PyObject *layout = fields_layout(grasp_quality_fields, COUNT_OF(grasp_quality_fields));
    int r = layout ? PyModule_AddObjectRef(m, "GRASP_QUALITY_FIELDS", layout) : -1;
    Py_XDECREF(layout);
    if (r < 0) return -1;
    for (int i = 0; i < COUNT_OF(tables); ++i) {
        int fits = tables[i].count <= MAX_FIELDS;
        for (int j = 0; j < tables[i].count; ++j) {
            const Field *f = &tables[i].fields[j];
            int arrays = f->kind == FIELD_VEC || f->kind == FIELD_OPT_VEC || f->kind == FIELD_COUNTS;
            fits = fits && (!arrays || f->n <= MAX_VEC);
        }
        if (!fits) {
            PyErr_Format(PyExc_SystemError, "graspcore: the table of %s exceeds MAX_FIELDS or MAX_VEC", tables[i].name);
            return -1;
        }
        if (!tables[i].defaults) continue;
        PyObject *d = fields_dict(tables[i].fields, tables[i].count, tables[i].defaults);
        r = d ? PyModule_AddObjectRef(m, tables[i].name, d) : -1;
        Py_XDECREF(d);
        if (r < 0) return -1;
    }
    return 0;
}

/* The tick record's layout (gc_tick_record_fields): ((name, numpy type, "once" | "finger" |
 * "body", shape), ...) in record order, shape the values' per finger/body (or once): () for
 * one, (count,) or (rows, columns); graspcore.tick_dtype is built from it. */
static int add_tick_fields(PyObject *m) {
    static const char *const scopes[] = {[GC_TICK_ONCE] = "once", [GC_TICK_PER_FINGER] = "finger",
                                         [GC_TICK_PER_BODY] = "body"};
    const gcTickField *fields;
    int n = gc_tick_record_fields(&fields);
    PyObject *t = PyTuple_New(n);
    for (int i = 0; t && i < n; ++i) {
        const gcTickField *f = &fields[i];
        PyObject *shape = f->count == 1 ? PyTuple_New(0)
                          : f->columns > 0 ? Py_BuildValue("(ii)", f->count / f->columns, f->columns)
                                           : Py_BuildValue("(i)", f->count);
        PyObject *row = shape ? Py_BuildValue("(sssN)", f->name, f->type,
                                              enum_name(scopes, COUNT_OF(scopes), (int)f->scope, 0), shape)
                              : NULL;
        if (!row || PyTuple_SetItem(t, i, row) < 0) Py_CLEAR(t);
    }
    int r = t ? PyModule_AddObjectRef(m, "TICK_FIELDS", t) : -1;
    Py_XDECREF(t);
    if (r < 0) return r;
    const char *const *names;
    int nt = gc_tick_trace_fields(&names);
    PyObject *trace = PyTuple_New(nt);
    for (int i = 0; trace && i < nt; ++i) {
        PyObject *name = PyUnicode_FromString(names[i]);
        if (!name || PyTuple_SetItem(trace, i, name) < 0) Py_CLEAR(trace);
    }
    r = trace ? PyModule_AddObjectRef(m, "TICK_TRACE_FIELDS", trace) : -1;
    Py_XDECREF(trace);
    return r;
}

/* A tuple of an enum's names, indexed by its values. */
static int add_names(PyObject *m, const char *name, const char *const *names, int count) {
    PyObject *t = PyTuple_New(count);
    for (int i = 0; t && i < count; ++i) {
        PyObject *item = PyUnicode_FromString(names[i]);
        if (!item || PyTuple_SetItem(t, i, item) < 0) Py_CLEAR(t);
    }
    int r = t ? PyModule_AddObjectRef(m, name, t) : -1;
    Py_XDECREF(t);
    return r;
}

static int module_exec(PyObject *m) {
    if (add_tables(m) < 0 || add_tick_fields(m) < 0 ||
        add_names(m, "FINGER_STATES", finger_state_names, COUNT_OF(finger_state_names)) < 0 ||
        add_names(m, "RENDERERS", renderer_names, COUNT_OF(renderer_names)) < 0 ||
        add_names(m, "SERIAL_STATES", serial_state_names, COUNT_OF(serial_state_names)) < 0 ||
        add_names(m, "SERIAL_EVENTS", serial_event_names, COUNT_OF(serial_event_names)) < 0)
        return -1;
    gcGraspDef grasp = gc_default_grasp_def();
    if (PyModule_AddIntConstant(m, "GRASP_QUALITY_SIZE", (long)sizeof(gcGraspQuality)) < 0 ||
        PyModule_AddIntConstant(m, "GRASP_DEFAULT_EDGES", grasp.edges) < 0 ||
        PyModule_AddIntConstant(m, "TICK_FORCES_ENABLED", GC_TICK_FORCES_ENABLED) < 0)
        return -1;
    /* Area contacts (docs/recording-format.md `patch`): corners per finger in records and snapshots. */
    if (PyModule_AddIntConstant(m, "FINGER_PATCH_CORNERS", GC_FINGER_PATCH_CORNERS) < 0) return -1;
    World_Type = PyType_FromSpec(&World_spec);
    if (!World_Type || PyModule_AddObjectRef(m, "World", World_Type) < 0) return -1;
    View_Type = PyType_FromSpec(&View_spec);
    if (!View_Type || PyModule_AddObjectRef(m, "View", View_Type) < 0) return -1;
    return 0;
}

static PyMethodDef module_methods[] = {
    {"tick_record_size", module_tick_record_size, METH_VARARGS,
     "tick_record_size(num_bodies, num_fingers) -> bytes of one tick log record."},
    {"tick_trace_size", tick_trace_size, METH_VARARGS,
     "tick_trace_size(num_bodies, num_fingers) -> bytes of one step_hips_trace trace."},
    {"_grasp_quality", module_grasp_quality, METH_VARARGS, "Low-level grasp_quality; use graspcore.grasp_quality."},
    {"_grasp_quality_batch", module_grasp_quality_batch, METH_VARARGS,
     "Low-level grasp_quality_batch; use graspcore.grasp_quality_batch."},
    {"_grasp_mu_min", module_grasp_mu_min, METH_VARARGS, "Low-level grasp_mu_min; use graspcore.grasp_mu_min."},
    {NULL, NULL, 0, NULL},
};

static PyModuleDef_Slot module_slots[] = {{Py_mod_exec, module_exec}, {0, NULL}};

static struct PyModuleDef module_def = {
    PyModuleDef_HEAD_INIT, "graspcore._core", "C core of graspcore (stable ABI).", 0, module_methods, module_slots,
    NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__core(void); /* the one exported symbol */

PyMODINIT_FUNC PyInit__core(void) { return PyModuleDef_Init(&module_def); }
