/* graspcore._core: the one CPython binding of the C core, for the stable ABI (3.11+).
 * Thin on purpose: argument conversion, status -> exception, GIL released while stepping,
 * zero-copy array views through the buffer protocol. Friendlier argument handling
 * (numpy conversion, keyword defaults) lives in graspcore/__init__.py. */
#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include <stdatomic.h>
#include <limits.h>
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

/* A warning status that still needs saying (a body stopped by the non-finite guard). */
static int warn_status(WorldObject *self, gcStatus st) {
    if (st != GC_WARN_STOPPED) return 0;
    return PyErr_WarnEx(PyExc_RuntimeWarning, gc_world_last_error(self->world), 1);
}

static int check_ready(WorldObject *self) {
    if (!self->world) {
        PyErr_SetString(PyExc_RuntimeError, "World is not initialised");
        return 0;
    }
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

static PyObject *tuple3(const double *v) { return Py_BuildValue("(ddd)", v[0], v[1], v[2]); }

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
    static char *kwlist[] = {"gravity", "gyroscopic", "max_bodies", "max_fingers", "max_parts",
                             "threads", "max_contacts", NULL}; /* threads, max_contacts: docs/solver.md */
    gcWorldDef def = gc_default_world_def();
    PyObject *gravity = NULL;
    int gyroscopic = 1;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "|Opiiiii", kwlist, &gravity, &gyroscopic, &def.max_bodies,
                                     &def.max_fingers, &def.max_parts, &def.threads, &def.max_contacts))
        return -1;
    if (gravity && !parse_vec(gravity, 3, "gravity", def.gravity)) return -1;
    def.gyroscopic = gyroscopic;
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

/* _add_body(parts, radii, mass, position, orientation, static, mu_s, mu_d, viscosity,
 *           inertia, center_of_mass, linear_velocity, angular_velocity,
 *           linear_damping, angular_damping)
 * parts: sequence of C-contiguous float64 buffers of shape (n, 3). */
static PyObject *World_add_body(PyObject *obj, PyObject *args) {
    WorldObject *self = (WorldObject *)obj;
    PyObject *parts, *radii, *position, *orientation, *inertia, *com, *lin, *ang;
    gcBodyDef def = gc_default_body_def();
    int is_static;
    if (!PyArg_ParseTuple(args, "OOdOOpdddOOOOdd", &parts, &radii, &def.mass, &position, &orientation,
                          &is_static, &def.mu_s, &def.mu_d, &def.viscosity, &inertia, &com, &lin, &ang,
                          &def.linear_damping, &def.angular_damping))
        return NULL;
    if (!check_ready(self)) return NULL;
    def.is_static = is_static;
    if (!parse_vec(position, 3, "position", def.position) ||
        !parse_vec(orientation, 4, "orientation", def.orientation) ||
        !parse_vec(lin, 3, "linear_velocity", def.linear_velocity) ||
        !parse_vec(ang, 3, "angular_velocity", def.angular_velocity))
        return NULL;
    if (inertia != Py_None) {
        if (!parse_vec(inertia, 9, "inertia", def.inertia)) return NULL;
        def.has_inertia = 1;
    }
    if (com != Py_None) {
        if (!parse_vec(com, 3, "center_of_mass", def.center_of_mass)) return NULL;
        def.has_center_of_mass = 1;
    }
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

/* points: None (a sphere finger) or a C-contiguous float64 buffer of xyz rows (a convex finger). */
static PyObject *World_add_finger(PyObject *obj, PyObject *args, PyObject *kwargs) {
    WorldObject *self = (WorldObject *)obj;
    static char *kwlist[] = {"radius",      "stiffness", "damping",  "position",    "points",
                             "orientation", "torsion",   "renderer", "cursor_mass", NULL};
    gcFingerDef def = gc_default_finger_def();
    PyObject *position = NULL, *points = NULL, *orientation = NULL;
    const char *renderer = NULL;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "|dddOOOdsd", kwlist, &def.radius, &def.stiffness, &def.damping,
                                     &position, &points, &orientation, &def.torsion, &renderer, &def.cursor_mass))
        return NULL;
    if (!check_ready(self)) return NULL;
    if (renderer && strcmp(renderer, "xfca") == 0)
        def.renderer = GC_RENDERER_XFCA;
    else if (renderer && strcmp(renderer, "cursor") == 0)
        def.renderer = GC_RENDERER_CURSOR;
    else if (renderer) {
        PyErr_Format(PyExc_ValueError, "renderer: must be 'xfca' or 'cursor' (got '%s')", renderer);
        return NULL;
    }
    if (position && !parse_vec(position, 3, "position", def.position)) return NULL;
    if (orientation && orientation != Py_None && !parse_vec(orientation, 4, "orientation", def.orientation))
        return NULL;
    Py_buffer b = {0};
    int has_points = points && points != Py_None;
    if (has_points) {
        if (PyObject_GetBuffer(points, &b, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0) return NULL;
        if (!b.format || strcmp(b.format, "d") != 0 || b.len % (3 * (Py_ssize_t)sizeof(double)) != 0 ||
            b.len / (Py_ssize_t)(3 * sizeof(double)) > (1 << 20)) {
            PyBuffer_Release(&b);
            PyErr_SetString(PyExc_ValueError, "points: must be a C-contiguous float64 array of xyz rows");
            return NULL;
        }
        def.points = b.buf;
        def.num_points = (int)(b.len / (Py_ssize_t)(3 * sizeof(double)));
    }
    int32_t id;
    gcStatus st = gc_world_add_finger(self->world, &def, &id);
    if (has_points) PyBuffer_Release(&b);
    return st < 0 ? raise_status(self, st) : PyLong_FromLong(id);
}

static PyObject *World_set_finger_pose(PyObject *obj, PyObject *args) {
    WorldObject *self = (WorldObject *)obj;
    int finger;
    PyObject *pos, *orient;
    double p[3], o[4];
    if (!PyArg_ParseTuple(args, "iOO", &finger, &pos, &orient) || !check_ready(self) ||
        !parse_vec(pos, 3, "position", p) || !parse_vec(orient, 4, "orientation", o))
        return NULL;
    gcStatus st = gc_world_set_finger_pose(self->world, finger, p, o);
    if (st < 0) return raise_status(self, st);
    Py_RETURN_NONE;
}

static PyObject *World_finger_pose(PyObject *obj, PyObject *args) {
    WorldObject *self = (WorldObject *)obj;
    int finger;
    double p[3], o[4];
    if (!PyArg_ParseTuple(args, "i", &finger) || !check_ready(self)) return NULL;
    gcStatus st = gc_world_finger_pose(self->world, finger, p, o);
    if (st < 0) return raise_status(self, st);
    return Py_BuildValue("((ddd)(dddd))", p[0], p[1], p[2], o[0], o[1], o[2], o[3]);
}

/* finger_contacts(finger) -> list of dicts, one per point of the finger's contact patch. */
static PyObject *World_finger_contacts(PyObject *obj, PyObject *args) {
    WorldObject *self = (WorldObject *)obj;
    int finger;
    if (!PyArg_ParseTuple(args, "i", &finger) || !check_ready(self)) return NULL;
    gcFingerContactPoint points[64];
    int n = 0;
    gcStatus st = gc_world_finger_contacts(self->world, finger, points, 64, &n);
    if (st < 0) return raise_status(self, st);
    if (n > 64) n = 64;
    static const char *states[] = {"free", "stick", "slip"};
    PyObject *list = PyList_New(n);
    if (!list) return NULL;
    for (int i = 0; i < n; ++i) {
        const gcFingerContactPoint *c = &points[i];
        PyObject *d = Py_BuildValue("{s:i,s:i,s:O,s:s,s:(ddd),s:(ddd),s:(ddd)}", "body", c->body, "sample",
                                    c->sample, "reversed", c->reversed ? Py_True : Py_False, "state",
                                    states[c->state >= 0 && c->state <= 2 ? c->state : 0],
                                    "point", c->point[0], c->point[1], c->point[2], "normal",
                                    c->normal[0], c->normal[1], c->normal[2], "force", c->force[0], c->force[1],
                                    c->force[2]);
        if (!d) {
            Py_DECREF(list);
            return NULL;
        }
        if (PyList_SetItem(list, i, d) < 0) {
            Py_DECREF(list);
            return NULL;
        }
    }
    return list;
}

static PyObject *World_set_hip(PyObject *obj, PyObject *args) {
    WorldObject *self = (WorldObject *)obj;
    int finger;
    PyObject *pos;
    double p[3];
    if (!PyArg_ParseTuple(args, "iO", &finger, &pos) || !check_ready(self) || !parse_vec(pos, 3, "position", p))
        return NULL;
    gcStatus st = gc_world_set_hip(self->world, finger, p);
    if (st < 0) return raise_status(self, st);
    Py_RETURN_NONE;
}

static PyObject *World_set_hips(PyObject *obj, PyObject *arg) {
    WorldObject *self = (WorldObject *)obj;
    if (!check_ready(self)) return NULL;
    Py_buffer b;
    if (PyObject_GetBuffer(arg, &b, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0) return NULL;
    PyObject *result = NULL;
    if (!b.format || strcmp(b.format, "d") != 0 || b.len % (3 * (Py_ssize_t)sizeof(double)) != 0) {
        PyErr_SetString(PyExc_ValueError, "positions: must be a C-contiguous float64 array of xyz rows");
    } else {
        gcStatus st = gc_world_set_hips(self->world, b.buf, (int)(b.len / (Py_ssize_t)(3 * sizeof(double))));
        if (st < 0)
            raise_status(self, st);
        else
            result = Py_NewRef(Py_None);
    }
    PyBuffer_Release(&b);
    return result;
}

static PyObject *World_set_gravity(PyObject *obj, PyObject *arg) {
    WorldObject *self = (WorldObject *)obj;
    double g[3];
    if (!check_ready(self) || !parse_vec(arg, 3, "gravity", g)) return NULL;
    gcStatus st = gc_world_set_gravity(self->world, g);
    if (st < 0) return raise_status(self, st);
    Py_RETURN_NONE;
}

static PyObject *World_set_body_velocity(PyObject *obj, PyObject *args) {
    WorldObject *self = (WorldObject *)obj;
    int body;
    PyObject *lin, *ang;
    double l[3], a[3];
    if (!PyArg_ParseTuple(args, "iOO", &body, &lin, &ang) || !check_ready(self) ||
        !parse_vec(lin, 3, "linear", l) || !parse_vec(ang, 3, "angular", a))
        return NULL;
    gcStatus st = gc_world_set_body_velocity(self->world, body, l, a);
    if (st < 0) return raise_status(self, st);
    Py_RETURN_NONE;
}

static PyObject *World_set_body_pose(PyObject *obj, PyObject *args) {
    WorldObject *self = (WorldObject *)obj;
    int body;
    PyObject *pos, *quat;
    double p[3], q[4];
    if (!PyArg_ParseTuple(args, "iOO", &body, &pos, &quat) || !check_ready(self) ||
        !parse_vec(pos, 3, "position", p) || !parse_vec(quat, 4, "orientation", q))
        return NULL;
    gcStatus st = gc_world_set_body_pose(self->world, body, p, q);
    if (st < 0) return raise_status(self, st);
    Py_RETURN_NONE;
}

static PyObject *World_set_body_friction(PyObject *obj, PyObject *args) {
    WorldObject *self = (WorldObject *)obj;
    int body;
    double mu_s, mu_d, viscosity;
    if (!PyArg_ParseTuple(args, "iddd", &body, &mu_s, &mu_d, &viscosity) || !check_ready(self)) return NULL;
    gcStatus st = gc_world_set_body_friction(self->world, body, mu_s, mu_d, viscosity);
    if (st < 0) return raise_status(self, st);
    Py_RETURN_NONE;
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
    atomic_store(&self->busy, 1);
    Py_BEGIN_ALLOW_THREADS
    for (int i = 0; i < steps && st >= 0; ++i) {
        st = gc_world_step(self->world, dt);
        if (st == GC_WARN_STOPPED) warned = st;
    }
    Py_END_ALLOW_THREADS
    atomic_store(&self->busy, 0);
    if (st < 0) return raise_status(self, st);
    if (warn_status(self, warned) < 0) return NULL;
    Py_RETURN_NONE;
}

static PyObject *World_body_pose(PyObject *obj, PyObject *args) {
    WorldObject *self = (WorldObject *)obj;
    int body;
    double p[3], q[4];
    if (!PyArg_ParseTuple(args, "i", &body) || !check_ready(self)) return NULL;
    gcStatus st = gc_world_body_pose(self->world, body, p, q);
    if (st < 0) return raise_status(self, st);
    return Py_BuildValue("((ddd)(dddd))", p[0], p[1], p[2], q[0], q[1], q[2], q[3]);
}

static PyObject *World_body_velocity(PyObject *obj, PyObject *args) {
    WorldObject *self = (WorldObject *)obj;
    int body;
    double l[3], a[3];
    if (!PyArg_ParseTuple(args, "i", &body) || !check_ready(self)) return NULL;
    gcStatus st = gc_world_body_velocity(self->world, body, l, a);
    if (st < 0) return raise_status(self, st);
    return Py_BuildValue("((ddd)(ddd))", l[0], l[1], l[2], a[0], a[1], a[2]);
}

static PyObject *World_body_mass(PyObject *obj, PyObject *args) {
    WorldObject *self = (WorldObject *)obj;
    int body;
    double m, c[3], I[9];
    if (!PyArg_ParseTuple(args, "i", &body) || !check_ready(self)) return NULL;
    gcStatus st = gc_world_body_mass(self->world, body, &m, c, I);
    if (st < 0) return raise_status(self, st);
    return Py_BuildValue("(d(ddd)((ddd)(ddd)(ddd)))", m, c[0], c[1], c[2], I[0], I[1], I[2], I[3], I[4], I[5], I[6],
                         I[7], I[8]);
}

static PyObject *World_residual_wrench(PyObject *obj, PyObject *args) {
    WorldObject *self = (WorldObject *)obj;
    int body;
    double f[3], t[3];
    if (!PyArg_ParseTuple(args, "i", &body) || !check_ready(self)) return NULL;
    gcStatus st = gc_world_residual_wrench(self->world, body, f, t);
    if (st < 0) return raise_status(self, st);
    return Py_BuildValue("((ddd)(ddd))", f[0], f[1], f[2], t[0], t[1], t[2]);
}

typedef gcStatus (*FingerVecQuery)(const gcWorld *, int32_t, double[3]);

static PyObject *finger_vec(WorldObject *self, PyObject *args, FingerVecQuery query) {
    int finger;
    double v[3];
    if (!PyArg_ParseTuple(args, "i", &finger) || !check_ready(self)) return NULL;
    gcStatus st = query(self->world, finger, v);
    if (st < 0) return raise_status(self, st);
    return tuple3(v);
}

static PyObject *World_finger_force(PyObject *obj, PyObject *args) {
    return finger_vec((WorldObject *)obj, args, gc_world_finger_force);
}

static PyObject *World_finger_torque(PyObject *obj, PyObject *args) {
    return finger_vec((WorldObject *)obj, args, gc_world_finger_torque);
}

static PyObject *World_god_object(PyObject *obj, PyObject *args) {
    return finger_vec((WorldObject *)obj, args, gc_world_god_object);
}

static PyObject *finger_state_query(WorldObject *self, PyObject *args, int want_body) {
    int finger;
    gcFingerState state;
    int32_t body;
    if (!PyArg_ParseTuple(args, "i", &finger) || !check_ready(self)) return NULL;
    gcStatus st = gc_world_finger_state(self->world, finger, &state, &body);
    if (st < 0) return raise_status(self, st);
    if (want_body) {
        if (body < 0) Py_RETURN_NONE;
        return PyLong_FromLong(body);
    }
    static const char *names[] = {"free", "stick", "slip"};
    return PyUnicode_FromString(names[state]);
}

static PyObject *World_finger_state(PyObject *obj, PyObject *args) {
    return finger_state_query((WorldObject *)obj, args, 0);
}

static PyObject *World_finger_contact(PyObject *obj, PyObject *args) {
    return finger_state_query((WorldObject *)obj, args, 1);
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

static PyObject *World_state_hash(PyObject *obj, PyObject *unused) {
    WorldObject *self = (WorldObject *)obj;
    if (!check_ready(self)) return NULL;
    return PyLong_FromUnsignedLongLong(gc_world_state_hash(self->world));
}

/* ---- Body-body contacts and collision chains (contacts.c, chains.c) ---------------- */

/* contacts() -> list of dicts, one per contact point of the last step. */
static PyObject *World_contacts(PyObject *obj, PyObject *unused) {
    WorldObject *self = (WorldObject *)obj;
    if (!check_ready(self)) return NULL;
    int n = gc_world_contacts(self->world, NULL, 0);
    gcContactPoint *pts = PyMem_Malloc(sizeof(gcContactPoint) * (size_t)(n > 0 ? n : 1));
    if (!pts) return PyErr_NoMemory();
    n = gc_world_contacts(self->world, pts, n);
    PyObject *list = PyList_New(n);
    for (int i = 0; list && i < n; ++i) {
        const gcContactPoint *p = &pts[i];
        PyObject *item = Py_BuildValue(
            "{s:i,s:i,s:(ddd),s:(ddd),s:d,s:d,s:(ddd),s:O}", "body_a", (int)p->body_a, "body_b", (int)p->body_b,
            "point", p->point[0], p->point[1], p->point[2], "normal", p->normal[0], p->normal[1], p->normal[2],
            "separation", p->separation, "normal_impulse", p->normal_impulse, "friction_impulse",
            p->friction_impulse[0], p->friction_impulse[1], p->friction_impulse[2], "sticking",
            p->sticking ? Py_True : Py_False);
        if (!item) {
            Py_CLEAR(list);
            break;
        }
        PyList_SetItem(list, i, item);
    }
    PyMem_Free(pts);
    return list;
}

static PyObject *World_chain_count(PyObject *obj, PyObject *unused) {
    WorldObject *self = (WorldObject *)obj;
    if (!check_ready(self)) return NULL;
    return PyLong_FromLong(gc_world_chain_count(self->world));
}

static PyObject *World_body_chain(PyObject *obj, PyObject *args) {
    WorldObject *self = (WorldObject *)obj;
    int body;
    if (!PyArg_ParseTuple(args, "i", &body) || !check_ready(self)) return NULL;
    int32_t chain;
    gcStatus st = gc_world_body_chain(self->world, body, &chain);
    if (st != GC_OK) return raise_status(self, st);
    if (chain < 0) Py_RETURN_NONE;
    return PyLong_FromLong(chain);
}

static PyObject *World_stopped_bodies(PyObject *obj, PyObject *unused) {
    WorldObject *self = (WorldObject *)obj;
    if (!check_ready(self)) return NULL;
    return PyLong_FromLongLong((long long)gc_world_stopped_bodies(self->world));
}

static PyObject *World_contact_overflow(PyObject *obj, PyObject *unused) {
    WorldObject *self = (WorldObject *)obj;
    if (!check_ready(self)) return NULL;
    return PyLong_FromLongLong((long long)gc_world_contact_overflow(self->world));
}

static PyObject *World_get_time(PyObject *obj, void *closure) {
    WorldObject *self = (WorldObject *)obj;
    if (!check_ready(self)) return NULL;
    return PyFloat_FromDouble(gc_world_time(self->world));
}

static PyObject *World_get_body_count(PyObject *obj, void *closure) {
    WorldObject *self = (WorldObject *)obj;
    if (!check_ready(self)) return NULL;
    return PyLong_FromLong(gc_world_body_count(self->world));
}

static PyObject *World_get_finger_count(PyObject *obj, void *closure) {
    WorldObject *self = (WorldObject *)obj;
    if (!check_ready(self)) return NULL;
    return PyLong_FromLong(gc_world_finger_count(self->world));
}

/* ---- Runtime: haptic loop and object manager threads (runtime*.c, docs/runtime.md) ----
 * push_hips, _snapshot and stats may run while another thread is inside advance/stop: the
 * core serialises them itself. */

static int check_world(WorldObject *self) {
    if (!self->world) {
        PyErr_SetString(PyExc_RuntimeError, "World is not initialised");
        return 0;
    }
    return 1;
}

static PyObject *World_start(PyObject *obj, PyObject *args, PyObject *kwargs) {
    WorldObject *self = (WorldObject *)obj;
    static char *kwlist[] = {"haptic_rate", "object_rate", "max_adopted_bodies", "max_force", "ramp_time",
                             "watchdog_timeout", "hip_timeout", "release_delay", "realtime", "priority",
                             "max_hip_speed", NULL};
    gcRuntimeDef def = gc_default_runtime_def();
    int realtime = def.realtime;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "|$ddidddddpid", kwlist, &def.haptic_rate, &def.object_rate,
                                     &def.max_adopted_bodies, &def.max_force, &def.ramp_time,
                                     &def.watchdog_timeout, &def.hip_timeout, &def.release_delay, &realtime,
                                     &def.priority, &def.max_hip_speed) ||
        !check_ready(self))
        return NULL;
    def.realtime = realtime;
    gcStatus st = gc_world_start(self->world, &def);
    if (st < 0) return raise_status(self, st);
    Py_RETURN_NONE;
}

/* stop(): joins the threads with the GIL released (the loops never need it). */
static PyObject *World_stop(PyObject *obj, PyObject *unused) {
    WorldObject *self = (WorldObject *)obj;
    if (!check_ready(self)) return NULL;
    gcStatus st;
    atomic_store(&self->busy, 1);
    Py_BEGIN_ALLOW_THREADS
    st = gc_world_stop(self->world);
    Py_END_ALLOW_THREADS
    atomic_store(&self->busy, 0);
    if (st < 0) return raise_status(self, st);
    Py_RETURN_NONE;
}

/* advance(ticks, delay=0.0): manual clock only; the GIL is released meanwhile. */
static PyObject *World_advance(PyObject *obj, PyObject *args, PyObject *kwargs) {
    WorldObject *self = (WorldObject *)obj;
    static char *kwlist[] = {"ticks", "delay", NULL};
    int ticks;
    double delay = 0.0;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "i|d", kwlist, &ticks, &delay) || !check_ready(self)) return NULL;
    gcStatus st;
    atomic_store(&self->busy, 1);
    Py_BEGIN_ALLOW_THREADS
    st = gc_world_advance(self->world, ticks, delay);
    Py_END_ALLOW_THREADS
    atomic_store(&self->busy, 0);
    if (st < 0) return raise_status(self, st);
    Py_RETURN_NONE;
}

/* _push_hips(float64 buffer of xyz rows, t) -> True if taken, False if rejected (counted). */
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

/* _push_hips(positions float64 (n, 3), t[, orientations float64 (n, 4) or None]). */
static PyObject *World_push_hips(PyObject *obj, PyObject *args) {
    WorldObject *self = (WorldObject *)obj;
    PyObject *positions, *quat_obj = Py_None;
    double t;
    if (!PyArg_ParseTuple(args, "Od|O", &positions, &t, &quat_obj) || !check_world(self)) return NULL;
    Py_buffer b, q = {0};
    if (PyObject_GetBuffer(positions, &b, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0) return NULL;
    int has_quat = quat_obj != Py_None;
    if (has_quat && PyObject_GetBuffer(quat_obj, &q, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0) {
        PyBuffer_Release(&b);
        return NULL;
    }
    PyObject *result = NULL;
    int rows = (int)(b.len / (Py_ssize_t)(3 * sizeof(double)));
    if (!b.format || strcmp(b.format, "d") != 0 || b.len % (3 * (Py_ssize_t)sizeof(double)) != 0 || b.len == 0) {
        PyErr_SetString(PyExc_ValueError, "positions: must be a C-contiguous float64 array of xyz rows");
    } else if (has_quat && (!q.format || strcmp(q.format, "d") != 0 || q.len != rows * 4 * (Py_ssize_t)sizeof(double))) {
        PyErr_Format(PyExc_ValueError, "orientations: must be a C-contiguous float64 array of %d wxyz rows", rows);
    } else {
        gcStatus st = gc_world_push_finger_poses(self->world, b.buf, has_quat ? q.buf : NULL, rows, t);
        if (st < 0)
            raise_status(self, st);
        else
            result = PyBool_FromLong(st == GC_OK);
    }
    if (has_quat) PyBuffer_Release(&q);
    PyBuffer_Release(&b);
    return result;
}

/* _snapshot() -> (time, object_time, tick, forces_enabled, n_bodies, n_fingers, poses,
 * wrenches, adopted, god_objects, hips, forces, spring_forces, states, contact_bodies,
 * normals, velocities), arrays as bytearrays (float64, uint8 or int32) for numpy.frombuffer. */
static PyObject *World_snapshot(PyObject *obj, PyObject *unused) {
    WorldObject *self = (WorldObject *)obj;
    if (!check_world(self)) return NULL;
    if (!gc_world_running(self->world) && !check_ready(self)) return NULL;
    int nb = gc_world_body_count(self->world), nf = gc_world_finger_count(self->world);
    enum { N_ARRAYS = 11 };
    Py_ssize_t sizes[N_ARRAYS] = {nb * 7 * 8, nb * 6 * 8, nb,     nf * 3 * 8, nf * 3 * 8, nf * 3 * 8,
                                  nf * 3 * 8, nf * 4,     nf * 4, nf * 3 * 8, nb * 6 * 8};
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
    gcStatus st = gc_world_snapshot(self->world, &snap);
    if (st < 0) {
        for (int i = 0; i < N_ARRAYS; ++i) Py_DECREF(arrays[i]);
        return raise_status(self, st);
    }
    return Py_BuildValue("(ddKiiiNNNNNNNNNNN)", snap.time, snap.object_time, (unsigned long long)snap.tick,
                         snap.forces_enabled, nb, nf, arrays[0], arrays[1], arrays[2], arrays[3], arrays[4],
                         arrays[5], arrays[6], arrays[7], arrays[8], arrays[9], arrays[10]);
}

static PyObject *World_stats(PyObject *obj, PyObject *unused) {
    WorldObject *self = (WorldObject *)obj;
    if (!check_world(self)) return NULL;
    gcRuntimeStats s;
    gcStatus st = gc_world_stats(self->world, &s);
    if (st < 0) return raise_status(self, st);
    return Py_BuildValue(
        "{s:N,s:N,s:N,s:s,s:d,s:d,s:d,s:K,s:K,s:d,s:d,s:d,s:d,s:d,s:d,s:K,s:K,s:K,s:i,s:K,s:K,s:K,s:K,s:K,s:K,s:N,s:d,s:d}",
        "running", PyBool_FromLong(s.running), "realtime", PyBool_FromLong(s.realtime), "rt_priority",
        PyBool_FromLong(s.rt_priority), "priority_note", s.priority_note, "haptic_rate", s.haptic_rate,
        "object_rate", s.object_rate, "object_speed", s.object_speed, "haptic_ticks",
        (unsigned long long)s.haptic_ticks, "object_ticks", (unsigned long long)s.object_ticks, "jitter_p50_us",
        s.jitter_p50_us, "jitter_p99_us", s.jitter_p99_us, "jitter_max_us", s.jitter_max_us, "tick_max_us", s.tick_max_us, "tick_mean_us", s.tick_mean_us, "wake_max_us", s.wake_max_us, "overruns",
        (unsigned long long)s.overruns, "late_periods", (unsigned long long)s.late_periods, "object_overruns",
        (unsigned long long)s.object_overruns, "adopted_bodies", s.adopted_bodies, "accepted_inputs",
        (unsigned long long)s.accepted_inputs, "rejected_inputs", (unsigned long long)s.rejected_inputs,
        "watchdog_trips", (unsigned long long)s.watchdog_trips, "stale_inputs", (unsigned long long)s.stale_inputs,
        "nonfinite_forces", (unsigned long long)s.nonfinite_forces, "stopped_bodies",
        (unsigned long long)s.stopped_bodies, "forces_enabled",
        PyBool_FromLong(s.forces_enabled), "haptic_time", s.haptic_time, "object_time", s.object_time);
}

static PyObject *World_debug_stall(PyObject *obj, PyObject *arg) {
    WorldObject *self = (WorldObject *)obj;
    double seconds = PyFloat_AsDouble(arg);
    if ((seconds == -1.0 && PyErr_Occurred()) || !check_world(self)) return NULL;
    gcStatus st = gc_world_debug_stall(self->world, seconds);
    if (st < 0) return raise_status(self, st);
    Py_RETURN_NONE;
}

static PyObject *World_get_running(PyObject *obj, void *closure) {
    WorldObject *self = (WorldObject *)obj;
    if (!check_world(self)) return NULL;
    return PyBool_FromLong(gc_world_running(self->world));
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
    if (st < 0) return raise_status(self, st);
    Py_RETURN_NONE;
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
    atomic_store(&self->busy, 1);
    Py_BEGIN_ALLOW_THREADS
    st = gc_world_step_hips(self->world, h.buf, fingers, steps, dt, first_tick, records ? b.buf : NULL,
                            records ? (size_t)b.len : 0, NULL);
    Py_END_ALLOW_THREADS
    atomic_store(&self->busy, 0);
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
    gcStatus st = gc_world_set_tick_log(self->world, capacity);
    if (st < 0) return raise_status(self, st);
    Py_RETURN_NONE;
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

static PyObject *World_tick_log_overflow(PyObject *obj, PyObject *unused) {
    WorldObject *self = (WorldObject *)obj;
    if (!check_world(self)) return NULL;
    return PyLong_FromUnsignedLongLong(gc_world_tick_log_overflow(self->world));
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

static PyObject *grasp_quality_dict(const gcGraspQuality *q) {
    return Py_BuildValue("{s:O,s:O,s:O,s:d,s:d,s:(dddddd),s:i,s:i}", "force_closure",
                         q->force_closure ? Py_True : Py_False, "force_only_closure",
                         q->force_only_closure ? Py_True : Py_False, "torque_closure",
                         q->torque_closure ? Py_True : Py_False, "epsilon", q->epsilon, "volume", q->volume, "weakest",
                         q->weakest[0], q->weakest[1], q->weakest[2], q->weakest[3], q->weakest[4], q->weakest[5],
                         "rank", (int)q->rank, "facets", (int)q->facets);
}

/* _grasp_quality(points, normals, mu, center, radius, edges, volume, reuse): float64 buffers of 3n,
 * 3n, n, 3; volume and reuse bools (gcGraspDef.volume, .reuse). */
static PyObject *module_grasp_quality(PyObject *mod, PyObject *args) {
    PyObject *po, *no, *mo, *co;
    double radius;
    int edges, volume, reuse;
    if (!PyArg_ParseTuple(args, "OOOOdipp", &po, &no, &mo, &co, &radius, &edges, &volume, &reuse)) return NULL;
    GraspBuffers g = {.n = 0};
    PyObject *result = NULL;
    if (take_buffer(&g, mo, 'd', -1, "mu", 0)) {
        Py_ssize_t n = g.b[0].len / (Py_ssize_t)sizeof(double);
        if (n > INT_MAX / 3) {
            PyErr_SetString(PyExc_ValueError, "points: too many contacts");
        } else if (take_buffer(&g, po, 'd', 3 * n, "points", 0) && take_buffer(&g, no, 'd', 3 * n, "normals", 0) &&
                   take_buffer(&g, co, 'd', 3, "center", 0)) {
            gcGraspWorkspace *ws = workspace_take();
            if (ws) {
                gcGraspDef def = gc_default_grasp_def();
                def.edges = edges;
                def.volume = volume;
                def.reuse = reuse;
                gcGraspQuality q;
                gcStatus st;
                Py_BEGIN_ALLOW_THREADS
                st = gc_grasp_quality(ws, &def, g.b[1].buf, g.b[2].buf, g.b[0].buf, (int)n, g.b[3].buf, radius, &q);
                Py_END_ALLOW_THREADS
                result = st < 0 ? raise_message(st, gc_grasp_workspace_error(ws)) : grasp_quality_dict(&q);
                workspace_give(ws);
            }
        }
    }
    release_all(&g);
    return result;
}

/* _grasp_quality_batch(points, normals, mu, counts (int32), centers, radii, edges, volume, reuse, out):
 * out a writable buffer of len(counts) * GRASP_QUALITY_SIZE bytes, filled with gcGraspQuality records. */
static PyObject *module_grasp_quality_batch(PyObject *mod, PyObject *args) {
    PyObject *po, *no, *mo, *ko, *co, *ro, *oo;
    int edges, volume, reuse;
    if (!PyArg_ParseTuple(args, "OOOOOOippO", &po, &no, &mo, &ko, &co, &ro, &edges, &volume, &reuse, &oo))
        return NULL;
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
                   take_buffer(&g, oo, 'd', -1, "out", 1)) {
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
                    gcGraspDef def = gc_default_grasp_def();
                    def.edges = edges;
                    def.volume = volume;
                    def.reuse = reuse;
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

/* _grasp_mu_min(points, normals, center, radius, edges, mu_max, reuse) -> float. */
static PyObject *module_grasp_mu_min(PyObject *mod, PyObject *args) {
    PyObject *po, *no, *co;
    double radius, mu_max;
    int edges, reuse;
    if (!PyArg_ParseTuple(args, "OOOdidp", &po, &no, &co, &radius, &edges, &mu_max, &reuse)) return NULL;
    GraspBuffers g = {.n = 0};
    PyObject *result = NULL;
    if (take_buffer(&g, po, 'd', -1, "points", 0)) {
        Py_ssize_t n = g.b[0].len / (Py_ssize_t)(3 * sizeof(double));
        if (n > INT_MAX / 3 || g.b[0].len % (Py_ssize_t)(3 * sizeof(double)) != 0) {
            PyErr_SetString(PyExc_ValueError, "points: expected xyz rows");
        } else if (take_buffer(&g, no, 'd', 3 * n, "normals", 0) && take_buffer(&g, co, 'd', 3, "center", 0)) {
            gcGraspWorkspace *ws = workspace_take();
            if (ws) {
                gcGraspDef def = gc_default_grasp_def();
                def.edges = edges;
                def.reuse = reuse;
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
    static char *kwlist[] = {"fd", "finger_offset", "num_fingers", "transform", "force_ttl", "lost_timeout",
                             "max_force", "ramp_time", "max_position", "stall_timeout", "priority", "udp_host",
                             "udp_port", NULL};
    gcSerialDef def = gc_default_serial_def();
    int fd;
    PyObject *transform = Py_None;
    const char *udp_host = "";
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "i|$iiOddddddisi", kwlist, &fd, &def.finger_offset,
                                     &def.num_fingers, &transform, &def.force_ttl, &def.lost_timeout, &def.max_force,
                                     &def.ramp_time, &def.max_position, &def.stall_timeout, &def.priority, &udp_host,
                                     &def.udp_port) ||
        !check_world(self))
        return NULL;
    if (strlen(udp_host) >= sizeof def.udp_host) {
        PyErr_SetString(PyExc_ValueError, "udp_host: longer than 63 bytes");
        return NULL;
    }
    strcpy(def.udp_host, udp_host);
    if (transform != Py_None && !parse_vec(transform, 16, "transform (16 numbers, row-major 4x4)", def.transform))
        return NULL;
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
    if (st < 0) return raise_status(self, st);
    Py_RETURN_NONE;
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

/* d[key] = v, taking v's reference; -1 (error set) when v is NULL or the insert fails. */
static int set_stolen(PyObject *d, const char *key, PyObject *v) {
    int r = v ? PyDict_SetItemString(d, key, v) : -1;
    Py_XDECREF(v);
    return r;
}

static PyObject *World_serial_stats(PyObject *obj, PyObject *args) {
    WorldObject *self = (WorldObject *)obj;
    int32_t id;
    if (!serial_id(self, args, &id, NULL)) return NULL;
    gcSerialStats s;
    gcStatus st = gc_world_serial_stats(self->world, id, &s);
    if (st < 0) return serial_result(self, id, st);
    static const char *states[] = {"waiting", "streaming", "lost", "hangup"};
    PyObject *errors = Py_BuildValue("{s:K,s:K,s:K,s:K,s:K,s:K,s:K,s:K}", "cobs", s.frame_errors[0], "short",
                                     s.frame_errors[1], "crc", s.frame_errors[2], "version", s.frame_errors[3],
                                     "type", s.frame_errors[4], "length", s.frame_errors[5], "overflow",
                                     s.frame_errors[6], "range", s.frame_errors[7]);
    if (!errors) return NULL;
    PyObject *out = Py_BuildValue(
        "{s:s,s:N,s:i,s:N,s:i,s:d,s:d,s:d,s:s,s:d,s:d,s:K,s:K,s:K,s:K,s:N,s:K,s:K,s:K,s:K,s:K,s:K,s:d,s:d,s:d,s:d,s:N}",
        "state", states[s.state & 3], "enabled", PyBool_FromLong(s.enabled), "device_fingers", s.device_fingers,
        "renders_forces", PyBool_FromLong(s.renders_forces), "units", s.units, "device_rate", s.device_rate,
        "device_force_max", s.device_force_max, "device_ttl_max", s.device_ttl_max, "name", s.name, "pose_rate",
        s.pose_rate, "last_pose_age", s.last_pose_age, "poses", (unsigned long long)s.poses, "forces_sent",
        (unsigned long long)s.forces_sent, "heartbeats", (unsigned long long)s.heartbeats, "dropped",
        (unsigned long long)s.dropped, "frame_errors", errors, "sequence_gaps", (unsigned long long)s.sequence_gaps,
        "disconnects", (unsigned long long)s.disconnects, "estops", (unsigned long long)s.estops, "stall_zeroes",
        (unsigned long long)s.stall_zeroes, "write_errors", (unsigned long long)s.write_errors, "push_rejected",
        (unsigned long long)s.push_rejected, "latency_p50_us", s.latency_p50_us, "latency_p99_us", s.latency_p99_us,
        "latency_max_us", s.latency_max_us, "gain", s.gain, "rt_priority", PyBool_FromLong(s.rt_priority));
    if (out && (set_stolen(out, "late_poses", PyLong_FromUnsignedLongLong(s.late_poses)) < 0 ||
                set_stolen(out, "duplicate_poses", PyLong_FromUnsignedLongLong(s.duplicate_poses)) < 0 ||
                set_stolen(out, "foreign_datagrams", PyLong_FromUnsignedLongLong(s.foreign_datagrams)) < 0 ||
                set_stolen(out, "peer", PyUnicode_FromString(s.peer)) < 0)) {
        Py_DECREF(out);
        return NULL;
    }
    return out;
}

/* push_device_hips(finger_offset, float64 buffer of xyz rows) -> True if taken, False if rejected. */
static PyObject *World_push_device_hips(PyObject *obj, PyObject *args) {
    WorldObject *self = (WorldObject *)obj;
    int offset;
    PyObject *positions;
    if (!PyArg_ParseTuple(args, "iO", &offset, &positions) || !check_world(self)) return NULL;
    Py_buffer b;
    if (PyObject_GetBuffer(positions, &b, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0) return NULL;
    PyObject *result = NULL;
    if (!b.format || strcmp(b.format, "d") != 0 || b.len % (3 * (Py_ssize_t)sizeof(double)) != 0 || b.len == 0) {
        PyErr_SetString(PyExc_ValueError, "positions: must be a C-contiguous float64 array of xyz rows");
    } else {
        gcStatus st = gc_world_push_device_hips(self->world, offset, (int)(b.len / (Py_ssize_t)(3 * sizeof(double))),
                                                b.buf);
        if (st == GC_ERR_NOT_RUNNING)
            PyErr_SetString(PyExc_RuntimeError, "push_device_hips: the runtime is not running (World.start)");
        else if (st < 0)
            raise_status(self, st);
        else
            result = PyBool_FromLong(st == GC_OK);
    }
    PyBuffer_Release(&b);
    return result;
}

/* device_forces_sent(finger_offset, float64 buffer of xyz rows) -> True if stored, False if rejected. */
static PyObject *World_device_forces_sent(PyObject *obj, PyObject *args) {
    WorldObject *self = (WorldObject *)obj;
    int offset;
    PyObject *forces;
    if (!PyArg_ParseTuple(args, "iO", &offset, &forces) || !check_world(self)) return NULL;
    Py_buffer b;
    if (PyObject_GetBuffer(forces, &b, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0) return NULL;
    PyObject *result = NULL;
    if (!b.format || strcmp(b.format, "d") != 0 || b.len % (3 * (Py_ssize_t)sizeof(double)) != 0 || b.len == 0) {
        PyErr_SetString(PyExc_ValueError, "forces: must be a C-contiguous float64 array of xyz rows");
    } else {
        gcStatus st = gc_world_device_forces_sent(self->world, offset, (int)(b.len / (Py_ssize_t)(3 * sizeof(double))),
                                                  b.buf);
        if (st < 0)
            raise_status(self, st);
        else
            result = PyBool_FromLong(st == GC_OK);
    }
    PyBuffer_Release(&b);
    return result;
}

/* serial_events(device) -> [(time, name, value, session_time)], popped oldest first. */
static PyObject *World_serial_events(PyObject *obj, PyObject *args) {
    WorldObject *self = (WorldObject *)obj;
    int32_t id;
    if (!serial_id(self, args, &id, NULL)) return NULL;
    gcSerialStats probe;
    if (gc_world_serial_stats(self->world, id, &probe) < 0) return serial_result(self, id, GC_ERR_UNKNOWN_ID);
    static const char *names[] = {"?", "connected", "lost", "recovered", "enabled", "estop", "stall", "dropped",
                                  "foreign"};
    PyObject *list = PyList_New(0);
    gcSerialEvent ev[64];
    int n;
    while (list && (n = gc_world_serial_events(self->world, id, ev, 64)) > 0) {
        for (int i = 0; i < n; ++i) {
            PyObject *item = Py_BuildValue("(dsid)", ev[i].time, names[ev[i].code >= 1 && ev[i].code <= 8 ? ev[i].code : 0], (int)ev[i].value,
                                           ev[i].session_time);
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

static PyMethodDef World_methods[] = {
    {"_add_body", World_add_body, METH_VARARGS, "Low-level add_body; use World.add_body."},
    {"add_finger", (PyCFunction)(void (*)(void))World_add_finger, METH_VARARGS | METH_KEYWORDS,
     "add_finger(radius, stiffness, damping, position=(0,0,0), points=None, orientation=(1,0,0,0), torsion=0, "
     "renderer='xfca', cursor_mass) -> finger id; points: a convex finger's (n, 3) float64 points in its frame "
     "(None: a sphere); torsion: a soft sphere fingertip's patch radius, m; renderer 'cursor': sphere fingers "
     "without torsion only; defaults: FINGER_DEFAULTS"},
    {"set_finger_pose", World_set_finger_pose, METH_VARARGS,
     "set_finger_pose(finger, (x, y, z), (w, x, y, z)): the whole HIP (a convex finger turns with it)."},
    {"finger_pose", World_finger_pose, METH_VARARGS, "finger_pose(finger) -> ((x, y, z), (w, x, y, z))"},
    {"finger_torque", World_finger_torque, METH_VARARGS,
     "finger_torque(finger) -> a convex finger's contact torque about its HIP, N m (0 for a sphere)"},
    {"finger_contacts", World_finger_contacts, METH_VARARGS,
     "finger_contacts(finger) -> [{body, sample, reversed, state, point, normal, force}] per contact point (first 64)"},
    {"set_hip", World_set_hip, METH_VARARGS, "set_hip(finger, (x, y, z)): the device (haptic interface) point."},
    {"set_hips", World_set_hips, METH_O, "set_hips(array (n, 3) float64): HIPs of fingers 0..n-1."},
    {"set_gravity", World_set_gravity, METH_O, "set_gravity((gx, gy, gz))"},
    {"set_body_velocity", World_set_body_velocity, METH_VARARGS,
     "set_body_velocity(body, linear, angular): world frame, of the body origin's COM."},
    {"set_body_pose", World_set_body_pose, METH_VARARGS, "set_body_pose(body, position, orientation_wxyz)"},
    {"set_body_friction", World_set_body_friction, METH_VARARGS, "set_body_friction(body, mu_s, mu_d, viscosity)"},
    {"step", (PyCFunction)(void (*)(void))World_step, METH_VARARGS | METH_KEYWORDS,
     "step(dt, steps=1): advance the world; the GIL is released meanwhile."},
    {"body_pose", World_body_pose, METH_VARARGS, "body_pose(body) -> ((x, y, z), (w, x, y, z))"},
    {"body_velocity", World_body_velocity, METH_VARARGS, "body_velocity(body) -> (linear, angular), world frame"},
    {"body_mass", World_body_mass, METH_VARARGS, "body_mass(body) -> (mass, center_of_mass, inertia 3x3)"},
    {"residual_wrench", World_residual_wrench, METH_VARARGS,
     "residual_wrench(body) -> (force, torque about the centre of mass)"},
    {"finger_force", World_finger_force, METH_VARARGS, "finger_force(finger) -> force rendered to the device, N"},
    {"god_object", World_god_object, METH_VARARGS, "god_object(finger) -> world position"},
    {"finger_state", World_finger_state, METH_VARARGS, "finger_state(finger) -> 'free' | 'stick' | 'slip'"},
    {"finger_contact", World_finger_contact, METH_VARARGS, "finger_contact(finger) -> body id or None"},
    {"_view", World_view, METH_O, "Zero-copy buffer view of world arrays."},
    {"state_hash", World_state_hash, METH_NOARGS, "64-bit hash of the full dynamic state."},
    {"contacts", World_contacts, METH_NOARGS,
     "contacts() -> list of dicts (body_a, body_b, point, normal, separation, normal_impulse, "
     "friction_impulse, sticking), one per body-body contact point of the last step."},
    {"chain_count", World_chain_count, METH_NOARGS, "chain_count() -> number of collision chains, last step"},
    {"body_chain", World_body_chain, METH_VARARGS,
     "body_chain(body) -> index of the body's collision chain (last step), None for a static body"},
    {"stopped_bodies", World_stopped_bodies, METH_NOARGS,
     "stopped_bodies() -> bodies stopped since creation because their state would have become non-finite"},
    {"contact_overflow", World_contact_overflow, METH_NOARGS,
     "contact_overflow() -> contact pairs dropped since creation for want of max_contacts"},
    /* Runtime (docs/runtime.md). */
    {"start", (PyCFunction)(void (*)(void))World_start, METH_VARARGS | METH_KEYWORDS,
     "start(*, haptic_rate=1000, object_rate=500, max_adopted_bodies=3, max_force=10, ramp_time=0.5,\n"
     "      watchdog_timeout=0.005, hip_timeout=0.1, release_delay=0.05, realtime=True, priority=80,\n"
     "      max_hip_speed=0.0)\n"
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
    {"tick_log_overflow", World_tick_log_overflow, METH_NOARGS,
     "tick_log_overflow() -> ticks dropped on a full tick log since the last start()."},
    {"_debug_stall", World_debug_stall, METH_O, "Test hook: stall the haptic loop this many seconds once."},
    {"attach_serial", (PyCFunction)(void (*)(void))World_attach_serial, METH_VARARGS | METH_KEYWORDS,
     "attach_serial(fd, *, finger_offset=0, num_fingers=1, transform=None (row-major 4x4, device metres -> world), "
     "force_ttl=0.02, lost_timeout=0.1, max_force=10.0, ramp_time=0.5, max_position=10.0, stall_timeout=0.005, "
     "priority=70, udp_host='', udp_port=0) "
     "-> device id: a C thread speaks the Grasp Lab serial protocol on fd (docs/protocol.md); with udp_port, fd is "
     "a bound UDP socket and frames go to udp_host:udp_port until the device's hello pins its address."},
    {"detach_serial", World_detach_serial, METH_VARARGS, "detach_serial(device): stop its thread (fd stays open)."},
    {"serial_enable", World_serial_enable, METH_VARARGS, "serial_enable(device, on): forces to the device on/off."},
    {"serial_estop", World_serial_estop, METH_VARARGS, "serial_estop(device): forces off, latched until enabled."},
    {"serial_stats", World_serial_stats, METH_VARARGS, "serial_stats(device) -> dict: state, rate, drops, latency."},
    {"push_device_hips", World_push_device_hips, METH_VARARGS,
     "push_device_hips(finger_offset, array (n, 3) float64): HIPs from a device read in Python (SpaceMouse, glove), "
     "merged with the serial devices' fingers."},
    {"device_forces_sent", World_device_forces_sent, METH_VARARGS,
     "device_forces_sent(finger_offset, array (n, 3) float64): what a device read in Python was sent (scene axes), "
     "recorded as those fingers' device force until the next call."},
    {"serial_events", World_serial_events, METH_VARARGS, "serial_events(device) -> [(time, event, value, session_time)] safety events: monotonic and session clock."},
    {NULL, NULL, 0, NULL},
};

static PyGetSetDef World_getset[] = {
    {"time", World_get_time, NULL, "Simulated time, s", NULL},
    {"body_count", World_get_body_count, NULL, "Number of bodies", NULL},
    {"finger_count", World_get_finger_count, NULL, "Number of fingers", NULL},
    {"running", World_get_running, NULL, "True between start() and stop()", NULL},
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

/* The core's defaults (gc_default_body_def, gc_default_finger_def), the one place they are
 * written: graspcore's Python signatures take theirs from these. */
static int add_defaults(PyObject *m) {
    gcBodyDef b = gc_default_body_def();
    gcFingerDef f = gc_default_finger_def();
    PyObject *body = Py_BuildValue("{s:d,s:d,s:d,s:d,s:d,s:d}", "mass", b.mass, "mu_s", b.mu_s, "mu_d", b.mu_d,
                                   "viscosity", b.viscosity, "linear_damping", b.linear_damping,
                                   "angular_damping", b.angular_damping);
    PyObject *finger = Py_BuildValue("{s:d,s:d,s:d,s:s,s:d}", "radius", f.radius, "stiffness", f.stiffness, "damping",
                                     f.damping, "renderer", "xfca", "cursor_mass", f.cursor_mass);
    int ok = body && finger && PyModule_AddObjectRef(m, "BODY_DEFAULTS", body) == 0 &&
             PyModule_AddObjectRef(m, "FINGER_DEFAULTS", finger) == 0;
    Py_XDECREF(body);
    Py_XDECREF(finger);
    return ok ? 0 : -1;
}

static int module_exec(PyObject *m) {
    if (add_defaults(m) < 0) return -1;
    gcGraspDef grasp = gc_default_grasp_def();
    if (PyModule_AddIntConstant(m, "GRASP_QUALITY_SIZE", (long)sizeof(gcGraspQuality)) < 0 ||
        PyModule_AddIntConstant(m, "GRASP_DEFAULT_EDGES", grasp.edges) < 0)
        return -1;
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
