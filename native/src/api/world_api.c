/* World lifetime, bodies and fingers, argument validation, queries. */
#define _GNU_SOURCE /* device_hub.h: the monotonic clock (gc_sync.h) */
#include "world/world.h"
#include "runtime/hip_input.h"
#include "runtime/runtime.h"
#include "runtime/tick_log.h"
#include "devices/device_hub.h"
#include "dynamics/step.h"

#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

const char *gc_status_string(gcStatus status) {
    switch (status) {
    case GC_OK: return "ok";
    case GC_WARN_MAX_ITERATIONS: return "iteration cap reached";
    case GC_WARN_REJECTED: return "input rejected";
    case GC_WARN_STOPPED: return "body stopped (non-finite state)";
    case GC_ERR_INVALID_ARGUMENT: return "invalid argument";
    case GC_ERR_DEGENERATE: return "degenerate geometry";
    case GC_ERR_NO_MEMORY: return "out of memory";
    case GC_ERR_UNKNOWN_ID: return "unknown id";
    case GC_ERR_CAPACITY: return "capacity exhausted";
    case GC_ERR_BUSY: return "busy";
    case GC_ERR_NOT_RUNNING: return "runtime not running";
    }
    return "unknown status";
}

const char *gc_world_last_error(const gcWorld *world) { return world ? world->last_error : "no world"; }

gcWorldDef gc_default_world_def(void) {
    gcWorldDef def;
    memset(&def, 0, sizeof def);
    def.gravity[2] = -9.81;
    def.gyroscopic = 1;
    def.max_bodies = 256;
    def.max_fingers = 32;
    def.max_parts = 4096;
    def.threads = 1;
    def.max_contacts = GC_DEFAULT_MAX_CONTACTS;
    return def;
}

gcBodyDef gc_default_body_def(void) {
    gcBodyDef def;
    memset(&def, 0, sizeof def);
    def.orientation[0] = 1.0;
    def.mass = 1.0;
    def.mu_s = 0.8;
    def.mu_d = 0.6;
    return def;
}

gcFingerDef gc_default_finger_def(void) {
    gcFingerDef def;
    memset(&def, 0, sizeof def);
    def.radius = 0.008;
    def.stiffness = 1000.0;
    def.orientation[0] = 1.0;
    def.renderer = GC_RENDERER_XFCA;
    def.cursor_mass = 0.002;
    return def;
}


/* No world exists yet when gc_world_create fails: its message is kept per thread. */
static _Thread_local char create_error[256];

const char *gc_world_create_error(void) { return create_error; }

static gcStatus create_failed(gcStatus status, const char *fmt, ...) {
    va_list args;
    va_start(args, fmt);
    vsnprintf(create_error, sizeof create_error, fmt, args);
    va_end(args);
    return status;
}

/* The first argument of gcWorldDef that is out of range, named in the message. */
static gcStatus check_world_def(const gcWorldDef *def) {
    if (!gc_all_finite(def->gravity, 3))
        return create_failed(GC_ERR_INVALID_ARGUMENT, "gravity: must be 3 finite numbers (got %g, %g, %g)",
                             def->gravity[0], def->gravity[1], def->gravity[2]);
    if (def->max_bodies < 1 || def->max_bodies > (1 << 24))
        return create_failed(GC_ERR_INVALID_ARGUMENT, "max_bodies: must be in 1..%d (got %d)", 1 << 24,
                             def->max_bodies);
    if (def->max_fingers < 1 || def->max_fingers > (1 << 20))
        return create_failed(GC_ERR_INVALID_ARGUMENT, "max_fingers: must be in 1..%d (got %d)", 1 << 20,
                             def->max_fingers);
    if (def->max_parts < 1 || def->max_parts > (1 << 24))
        return create_failed(GC_ERR_INVALID_ARGUMENT, "max_parts: must be in 1..%d (got %d)", 1 << 24,
                             def->max_parts);
    if (def->threads < 0 || def->threads > GC_MAX_THREADS)
        return create_failed(GC_ERR_INVALID_ARGUMENT, "threads: must be in 1..%d, 0 for 1 (got %d)",
                             GC_MAX_THREADS, def->threads);
    if (def->max_contacts < 0 || def->max_contacts > GC_MAX_CONTACTS_LIMIT)
        return create_failed(GC_ERR_INVALID_ARGUMENT, "max_contacts: must be in 1..%d, 0 for the default (got %d)",
                             GC_MAX_CONTACTS_LIMIT, def->max_contacts);
    return GC_OK;
}

gcStatus gc_world_create(const gcWorldDef *def, gcWorld **out_world) {
    create_error[0] = 0;
    if (!out_world) return create_failed(GC_ERR_INVALID_ARGUMENT, "out_world: must not be NULL");
    *out_world = NULL;
    if (!def) return create_failed(GC_ERR_INVALID_ARGUMENT, "def: must not be NULL");
    gcStatus st = check_world_def(def);
    if (st) return st;
    gcWorld *w = calloc(1, sizeof *w);
    gcModel *m = calloc(1, sizeof *m);
    if (!w || !m) {
        free(w);
        free(m);
        return create_failed(GC_ERR_NO_MEMORY, "out of memory for the world");
    }
    w->def = *def;
    w->own_model = m;
    w->model = m;
    m->gravity = gc_v3(def->gravity[0], def->gravity[1], def->gravity[2]);
    m->parts = calloc((size_t)def->max_parts, sizeof *m->parts);
    m->bodies = calloc((size_t)def->max_bodies, sizeof *m->bodies);
    m->fingers = calloc((size_t)def->max_fingers, sizeof *m->fingers);
    m->finger_hulls = calloc((size_t)def->max_fingers, sizeof *m->finger_hulls);
    w->bodies = calloc((size_t)def->max_bodies, sizeof *w->bodies);
    w->fingers = calloc((size_t)def->max_fingers, sizeof *w->fingers);
    w->pose_array = calloc((size_t)def->max_bodies * 7, sizeof(double));
    w->god_object_array = calloc((size_t)def->max_fingers * 3, sizeof(double));
    w->force_array = calloc((size_t)def->max_fingers * 3, sizeof(double));
    w->hip_array = calloc((size_t)def->max_fingers * 3, sizeof(double));
    if (!m->parts || !m->bodies || !m->fingers || !m->finger_hulls || !w->bodies || !w->fingers || !w->pose_array ||
        !w->god_object_array || !w->force_array || !w->hip_array || !(w->hub = gc_device_hub_create(w))) {
        gc_world_destroy(w);
        return create_failed(GC_ERR_NO_MEMORY, "out of memory for the capacities (max_bodies %d, max_fingers %d, max_parts %d)",
                             def->max_bodies, def->max_fingers, def->max_parts);
    }
    gcStatus contacts_status = gc_contacts_create(w); /* contact storage and thread pool */
    if (contacts_status != GC_OK) {
        create_failed(contacts_status, "%s", w->last_error[0] ? w->last_error : "out of memory for the contacts");
        gc_world_destroy(w);
        return contacts_status;
    }
    *out_world = w;
    return GC_OK;
}

void gc_world_destroy(gcWorld *w) {
    if (!w) return;
    gc_device_threads_stop_all(w->hub); /* device threads read the runtime's ticks */
    gc_runtime_free(w); /* stops the runtime threads first */
    gc_tick_log_free(w);
    gc_device_hub_destroy(w->hub); /* the haptic loop wrote into it */
    gc_contacts_destroy(w); /* joins the contact thread pool */
    gc_hip_track_free(w->hip_track);
    gcModel *m = w->own_model;
    for (int i = 0; i < m->num_parts; ++i) gc_hull_free(&m->parts[i].hull);
    if (m->finger_hulls)
        for (int i = 0; i < w->num_fingers; ++i) gc_hull_free(&m->finger_hulls[i]);
    free(m->finger_hulls);
    free(m->parts);
    free(m->bodies);
    free(m->fingers);
    free(m);
    free(w->bodies);
    free(w->fingers);
    free(w->pose_array);
    free(w->god_object_array);
    free(w->force_array);
    free(w->hip_array);
    free(w);
}

int gc_world_body_count(const gcWorld *w) { return w ? w->num_bodies : 0; }
int gc_world_finger_count(const gcWorld *w) { return w ? w->num_fingers : 0; }
double gc_world_time(const gcWorld *w) { return w ? (w->shown ? w->shown->time : w->time) : 0.0; }

/* While the runtime runs it owns the dynamic state (it sets `locked`): mutating calls are refused. */
static gcStatus check_idle(const gcWorld *w) {
    if (!w) return GC_ERR_INVALID_ARGUMENT;
    if (w->locked) {
        gc_world_set_error(w, "the runtime is running: stop it first (World.stop / gc_world_stop)");
        return GC_ERR_BUSY;
    }
    return GC_OK;
}

/* A body definition's values and the world's room for its parts: checked before anything is built. */
static gcStatus check_body_def(gcWorld *w, const gcBodyDef *def, const gcPartDef *parts, int num_parts) {
    gcStatus st;
    if ((st = gc_check_vec(w, def->position, 3, "position")) ||
        (st = gc_check_vec(w, def->orientation, 4, "orientation")) ||
        (st = gc_check_vec(w, def->linear_velocity, 3, "linear_velocity")) ||
        (st = gc_check_vec(w, def->angular_velocity, 3, "angular_velocity")) ||
        (st = gc_check_friction(w, def->mu_s, def->mu_d, def->viscosity)))
        return st;
    double qn = sqrt(def->orientation[0] * def->orientation[0] + def->orientation[1] * def->orientation[1] +
                     def->orientation[2] * def->orientation[2] + def->orientation[3] * def->orientation[3]);
    if (!(qn > 1e-9)) {
        gc_world_set_error(w, "orientation: quaternion (w, x, y, z) must not be zero");
        return GC_ERR_INVALID_ARGUMENT;
    }
    if (!def->is_static && (!isfinite(def->mass) || !(def->mass > 0.0))) {
        gc_world_set_error(w, "mass: must be a finite number > 0 for a dynamic body (got %g)", def->mass);
        return GC_ERR_INVALID_ARGUMENT;
    }
    if (!isfinite(def->linear_damping) || def->linear_damping < 0 || !isfinite(def->angular_damping) ||
        def->angular_damping < 0) {
        gc_world_set_error(w, "linear_damping/angular_damping: must be finite and >= 0");
        return GC_ERR_INVALID_ARGUMENT;
    }
    if (!parts || num_parts < 1) {
        gc_world_set_error(w, "parts: a body needs at least one convex part");
        return GC_ERR_INVALID_ARGUMENT;
    }
    if (w->num_bodies >= w->def.max_bodies) {
        gc_world_set_error(w, "max_bodies: the world holds at most %d bodies", w->def.max_bodies);
        return GC_ERR_CAPACITY;
    }
    if (w->own_model->num_parts + num_parts > w->def.max_parts) {
        gc_world_set_error(w, "max_parts: the world holds at most %d convex parts", w->def.max_parts);
        return GC_ERR_CAPACITY;
    }
    return GC_OK;
}

/* Every part's hull, built into the model's next free parts; a bad part leaves the world untouched. */
static gcStatus build_part_hulls(gcWorld *w, const gcPartDef *parts, int num_parts) {
    gcStatus st;
    int first = w->own_model->num_parts;
    for (int i = 0; i < num_parts; ++i) {
        const gcPartDef *pd = &parts[i];
        const char *what = num_parts > 1 ? "parts" : "points";
        if (!pd->points || pd->num_points < 1 || !isfinite(pd->radius) || pd->radius < 0 ||
            !gc_all_finite(pd->points, 3 * pd->num_points)) {
            st = GC_ERR_INVALID_ARGUMENT;
            gc_world_set_error(w, "%s: part %d must be finite xyz points with a radius >= 0", what, i);
        } else {
            st = gc_hull_build(pd->points, pd->num_points, pd->radius, 0.0, &w->own_model->parts[first + i].hull);
            if (st == GC_ERR_DEGENERATE)
                gc_world_set_error(w, "%s: part %d is a degenerate hull (coplanar, collinear or coincident points)",
                                   what, i);
            else if (st < 0)
                gc_world_set_error(w, "%s: part %d could not be built (%s)", what, i, gc_status_string(st));
        }
        if (st < 0) {
            for (int j = 0; j < i; ++j) gc_hull_free(&w->own_model->parts[first + j].hull);
            memset(&w->own_model->parts[first], 0, sizeof(gcPart) * (size_t)num_parts);
            return st;
        }
    }
    return GC_OK;
}

/* A body's centre of mass and inertia from its parts' hulls (uniform density over the union of
 * parts, overlaps counted twice) unless the definition gives them. */
static gcStatus body_mass_properties(gcWorld *w, const gcBodyDef *def, gcBodyModel *out) {
    gcBodyModel bm = *out;
    int first = bm.first_part, num_parts = bm.num_parts;
    gcStatus st = GC_OK;
    double volume = 0.0;
    gcVec3 centroid = gc_v3(0, 0, 0);
    for (int i = 0; i < num_parts; ++i) {
        const gcHull *h = &w->own_model->parts[first + i].hull;
        volume += h->volume;
        centroid = gc_madd(centroid, h->centroid, h->volume);
    }
    centroid = gc_scale(centroid, 1.0 / volume);
    bm.com_local = def->has_center_of_mass ? gc_v3(def->center_of_mass[0], def->center_of_mass[1],
                                                  def->center_of_mass[2])
                                          : centroid;
    if (def->has_center_of_mass && !gc_all_finite(def->center_of_mass, 3)) {
        st = GC_ERR_INVALID_ARGUMENT;
        gc_world_set_error(w, "center_of_mass: must be 3 finite numbers");
    }
    if (!bm.is_static) {
        bm.mass = def->mass;
        bm.inv_mass = 1.0 / def->mass;
        if (def->has_inertia) {
            memcpy(bm.inertia_local.m, def->inertia, sizeof bm.inertia_local.m);
        } else {
            double density = def->mass / volume;
            memset(&bm.inertia_local, 0, sizeof bm.inertia_local);
            for (int i = 0; i < num_parts; ++i) {
                const gcHull *h = &w->own_model->parts[first + i].hull;
                double m = density * h->volume;
                gcVec3 d = gc_sub(h->centroid, bm.com_local);
                double d2 = gc_len2(d);
                double dv[3] = {d.x, d.y, d.z};
                for (int r = 0; r < 3; ++r)
                    for (int c = 0; c < 3; ++c)
                        bm.inertia_local.m[r][c] += density * h->inertia_unit.m[r][c] +
                                                   m * ((r == c ? d2 : 0.0) - dv[r] * dv[c]);
            }
        }
        if (st == GC_OK && (!gc_inertia_is_physical(&bm.inertia_local) ||
                            !gc_invert_mat3(&bm.inertia_local, &bm.inv_inertia_local))) {
            st = GC_ERR_INVALID_ARGUMENT;
            gc_world_set_error(w, "inertia: must be symmetric positive definite and obey the triangle inequality");
        }
    }
    *out = bm;
    return st;
}

gcStatus gc_world_add_body(gcWorld *w, const gcBodyDef *def, const gcPartDef *parts, int num_parts,
                           int32_t *out_body) {
    if (!w) return GC_ERR_INVALID_ARGUMENT;
    if (!def) return gc_null_argument(w, "def");
    if (!out_body) return gc_null_argument(w, "out_body");
    gcStatus st;
    if ((st = check_idle(w)) || (st = check_body_def(w, def, parts, num_parts)) ||
        (st = build_part_hulls(w, parts, num_parts)))
        return st;
    int first = w->own_model->num_parts;
    gcBodyModel bm;
    memset(&bm, 0, sizeof bm);
    gcBody b;
    memset(&b, 0, sizeof b);
    bm.is_static = def->is_static != 0;
    bm.first_part = first;
    bm.num_parts = num_parts;
    st = body_mass_properties(w, def, &bm);
    if (st < 0) {
        for (int i = 0; i < num_parts; ++i) gc_hull_free(&w->own_model->parts[first + i].hull);
        return st;
    }
    bm.mu_s = def->mu_s;
    bm.mu_d = def->mu_d;
    bm.viscosity = def->viscosity;
    bm.linear_damping = def->linear_damping;
    bm.angular_damping = def->angular_damping;
    b.state.q = gc_quat_normalize((gcQuat){def->orientation[0], def->orientation[1], def->orientation[2],
                                     def->orientation[3]});
    b.state.R = gc_quat_to_mat3(b.state.q);
    b.state.com = gc_add(gc_v3(def->position[0], def->position[1], def->position[2]),
                   gc_mat3_mul_vec(&b.state.R, bm.com_local));
    if (!bm.is_static) {
        b.state.w = gc_v3(def->angular_velocity[0], def->angular_velocity[1], def->angular_velocity[2]);
        b.state.v = gc_add(gc_v3(def->linear_velocity[0], def->linear_velocity[1], def->linear_velocity[2]),
                     gc_cross(b.state.w, gc_mat3_mul_vec(&b.state.R, bm.com_local))); /* origin -> COM */
    }
    int32_t id = w->num_bodies;
    for (int i = 0; i < num_parts; ++i) w->own_model->parts[first + i].body = id;
    w->own_model->bodies[id] = bm;
    w->bodies[id] = b;
    w->num_bodies++;
    w->own_model->num_parts += num_parts;
    gc_body_refresh_derived(w, id);
    *out_body = id;
    return GC_OK;
}

/* A finger's orientation: finite, not zero, normalised. */
static gcStatus finger_orientation(gcWorld *w, const double o[4], gcQuat *out) {
    gcStatus st = gc_check_vec(w, o, 4, "orientation");
    if (st) return st;
    double n2 = o[0] * o[0] + o[1] * o[1] + o[2] * o[2] + o[3] * o[3];
    if (!(n2 > 1e-20) || !isfinite(n2)) {
        gc_world_set_error(w, "orientation: must be a non-zero quaternion (w, x, y, z)");
        return GC_ERR_INVALID_ARGUMENT;
    }
    gcQuat q = {o[0], o[1], o[2], o[3]};
    *out = gc_quat_normalize(q);
    return GC_OK;
}

gcStatus gc_world_add_finger(gcWorld *w, const gcFingerDef *def, int32_t *out_finger) {
    if (!w) return GC_ERR_INVALID_ARGUMENT;
    if (!def) return gc_null_argument(w, "def");
    if (!out_finger) return gc_null_argument(w, "out_finger");
    gcStatus st;
    if ((st = check_idle(w)) || (st = gc_check_vec(w, def->position, 3, "position"))) return st;
    if (!isfinite(def->radius) || def->radius < 0) {
        gc_world_set_error(w, "radius: must be a finite number >= 0 (got %g)", def->radius);
        return GC_ERR_INVALID_ARGUMENT;
    }
    if (!isfinite(def->stiffness) || !(def->stiffness > 0)) {
        gc_world_set_error(w, "stiffness: must be a finite number > 0 (got %g)", def->stiffness);
        return GC_ERR_INVALID_ARGUMENT;
    }
    if (!isfinite(def->damping) || def->damping < 0) {
        gc_world_set_error(w, "damping: must be a finite number >= 0 (got %g)", def->damping);
        return GC_ERR_INVALID_ARGUMENT;
    }
    if (!isfinite(def->torsion) || def->torsion < 0 || (def->torsion > 0 && (def->points || def->num_points))) {
        gc_world_set_error(w, "torsion: must be a finite number >= 0, and 0 for a convex finger (got %g)", def->torsion);
        return GC_ERR_INVALID_ARGUMENT;
    }
    if (def->renderer != GC_RENDERER_XFCA && def->renderer != GC_RENDERER_CURSOR) {
        gc_world_set_error(w, "renderer: must be GC_RENDERER_XFCA or GC_RENDERER_CURSOR (got %d)", (int)def->renderer);
        return GC_ERR_INVALID_ARGUMENT;
    }
    if (!isfinite(def->cursor_mass) || def->cursor_mass < 0) {
        gc_world_set_error(w, "cursor_mass: must be a finite number >= 0 (got %g)", def->cursor_mass);
        return GC_ERR_INVALID_ARGUMENT;
    }
    /* The cursor is one point mass on a sphere finger's spring: a convex finger's patch and a
     * soft fingertip's twist are xFCA god-objects' (docs/physics.md "Renderers and finger shapes"). */
    if (def->renderer == GC_RENDERER_CURSOR && (def->points || def->num_points || def->torsion > 0)) {
        gc_world_set_error(w, "renderer: the cursor renderer takes a sphere finger without torsion (got %s)",
                           def->torsion > 0 ? "torsion > 0" : "points: a convex finger");
        return GC_ERR_INVALID_ARGUMENT;
    }
    if (w->num_fingers >= w->def.max_fingers) {
        gc_world_set_error(w, "max_fingers: the world holds at most %d fingers", w->def.max_fingers);
        return GC_ERR_CAPACITY;
    }
    gcQuat q;
    if ((st = finger_orientation(w, def->orientation, &q))) return st;
    gcHull hull;
    memset(&hull, 0, sizeof hull);
    if (def->num_points != 0 || def->points) {
        if (!def->points) return gc_null_argument(w, "points");
        if (def->num_points < 4) {
            gc_world_set_error(w, "points: a convex finger needs at least 4 points that are not coplanar (got %d)",
                               def->num_points);
            return GC_ERR_INVALID_ARGUMENT;
        }
        if ((st = gc_check_vec(w, def->points, 3 * def->num_points, "points"))) return st;
        st = gc_hull_build(def->points, def->num_points, def->radius, 0.0, &hull);
        if (st != GC_OK) {
            gc_world_set_error(w, "points: their convex hull is degenerate (coplanar, collinear or coincident points)");
            gc_hull_free(&hull);
            return st < 0 ? st : GC_ERR_DEGENERATE;
        }
        if (hull.num_vertices > GC_MAX_FINGER_VERTICES) {
            gc_world_set_error(w, "points: their hull has %d vertices, a convex finger takes at most %d (decimate the mesh)",
                               hull.num_vertices, GC_MAX_FINGER_VERTICES);
            gc_hull_free(&hull);
            return GC_ERR_INVALID_ARGUMENT;
        }
    }
    int32_t id = w->num_fingers;
    gcFingerModel *fm = &w->own_model->fingers[id];
    memset(fm, 0, sizeof *fm);
    fm->num_vertices = hull.num_vertices;
    for (int i = 0; i < hull.num_vertices; ++i) fm->vertices[i] = hull.vertices[i];
    w->own_model->finger_hulls[id] = hull; /* freed with the world */
    fm->radius = def->radius;
    fm->torsion = def->torsion;
    fm->stiffness = def->stiffness;
    fm->damping = def->damping;
    fm->renderer = def->renderer;
    fm->cursor_mass = def->cursor_mass;
    gcFinger *f = &w->fingers[id];
    memset(f, 0, sizeof *f);
    f->q = f->q_prev = q;
    f->R = f->R_prev = gc_quat_to_mat3(q);
    f->hip = f->hip_prev = f->god_object = gc_v3(def->position[0], def->position[1], def->position[2]);
    f->cursor = f->hip;
    f->contact_body = -1;
    f->state = GC_FINGER_FREE;
    memcpy(&w->hip_array[3 * id], def->position, 3 * sizeof(double));
    memcpy(&w->god_object_array[3 * id], def->position, 3 * sizeof(double));
    w->num_fingers++;
    *out_finger = id;
    return GC_OK;
}

gcStatus gc_world_set_gravity(gcWorld *w, const double g[3]) {
    gcStatus st = check_idle(w);
    if (st || (st = gc_check_vec(w, g, 3, "gravity"))) return st;
    w->own_model->gravity = gc_v3(g[0], g[1], g[2]);
    return GC_OK;
}

gcStatus gc_world_set_hip(gcWorld *w, int32_t finger, const double p[3]) {
    gcStatus st;
    if ((st = check_idle(w)) || (st = gc_check_finger(w, finger)) || (st = gc_check_vec(w, p, 3, "position"))) return st;
    w->fingers[finger].hip = gc_v3(p[0], p[1], p[2]);
    memcpy(&w->hip_array[3 * finger], p, 3 * sizeof(double));
    return GC_OK;
}

gcStatus gc_world_set_finger_pose(gcWorld *w, int32_t finger, const double p[3], const double o[4]) {
    gcStatus st;
    gcQuat q;
    if ((st = check_idle(w)) || (st = gc_check_finger(w, finger)) || (st = gc_check_vec(w, p, 3, "position")) ||
        (st = gc_check_vec(w, o, 4, "orientation")) || (st = finger_orientation(w, o, &q)))
        return st;
    gcFinger *f = &w->fingers[finger];
    f->hip = gc_v3(p[0], p[1], p[2]);
    f->q = q;
    f->R = gc_quat_to_mat3(q);
    memcpy(&w->hip_array[3 * finger], p, 3 * sizeof(double));
    return GC_OK;
}

gcStatus gc_world_set_hips(gcWorld *w, const double *p, int count) {
    gcStatus idle = check_idle(w);
    if (idle) return idle;
    if (count < 0 || count > w->num_fingers) {
        gc_world_set_error(w, "positions: %d rows given for %d fingers", count, w->num_fingers);
        return GC_ERR_INVALID_ARGUMENT;
    }
    gcStatus st = gc_check_vec(w, p, 3 * count, "positions");
    if (st) return st;
    for (int i = 0; i < count; ++i) w->fingers[i].hip = gc_v3(p[3 * i], p[3 * i + 1], p[3 * i + 2]);
    memcpy(w->hip_array, p, 3 * (size_t)count * sizeof(double));
    return GC_OK;
}

gcStatus gc_world_set_body_velocity(gcWorld *w, int32_t body, const double lin[3], const double ang[3]) {
    gcStatus st;
    if ((st = check_idle(w)) || (st = gc_check_body(w, body)) || (st = gc_check_vec(w, lin, 3, "linear")) ||
        (st = gc_check_vec(w, ang, 3, "angular")))
        return st;
    gcBody *b = &w->bodies[body];
    const gcBodyModel *m = &w->model->bodies[body];
    if (m->is_static) {
        gc_world_set_error(w, "body: %d is static and cannot be given a velocity", (int)body);
        return GC_ERR_INVALID_ARGUMENT;
    }
    /* Given for the body frame origin, like body_velocity reports it; stored at the COM. */
    b->state.w = gc_v3(ang[0], ang[1], ang[2]);
    gcVec3 origin_to_com = gc_mat3_mul_vec(&b->state.R, m->com_local);
    b->state.v = gc_add(gc_v3(lin[0], lin[1], lin[2]), gc_cross(b->state.w, origin_to_com));
    return GC_OK;
}

gcStatus gc_world_set_body_pose(gcWorld *w, int32_t body, const double pos[3], const double quat[4]) {
    gcStatus st;
    if ((st = check_idle(w)) || (st = gc_check_body(w, body)) || (st = gc_check_vec(w, pos, 3, "position")) ||
        (st = gc_check_vec(w, quat, 4, "orientation")))
        return st;
    double qn = sqrt(quat[0] * quat[0] + quat[1] * quat[1] + quat[2] * quat[2] + quat[3] * quat[3]);
    if (!(qn > 1e-9)) {
        gc_world_set_error(w, "orientation: quaternion (w, x, y, z) must not be zero");
        return GC_ERR_INVALID_ARGUMENT;
    }
    gcBody *b = &w->bodies[body];
    b->state.q = gc_quat_normalize((gcQuat){quat[0], quat[1], quat[2], quat[3]});
    b->state.R = gc_quat_to_mat3(b->state.q);
    gcVec3 origin_to_com = gc_mat3_mul_vec(&b->state.R, w->model->bodies[body].com_local);
    b->state.com = gc_add(gc_v3(pos[0], pos[1], pos[2]), origin_to_com);
    gc_body_refresh_derived(w, body);
    return GC_OK;
}

gcStatus gc_world_set_body_friction(gcWorld *w, int32_t body, double mu_s, double mu_d, double viscosity) {
    gcStatus st;
    if ((st = check_idle(w)) || (st = gc_check_body(w, body)) || (st = gc_check_friction(w, mu_s, mu_d, viscosity))) return st;
    w->own_model->bodies[body].mu_s = mu_s;
    w->own_model->bodies[body].mu_d = mu_d;
    w->own_model->bodies[body].viscosity = viscosity;
    return GC_OK;
}

gcStatus gc_world_step(gcWorld *w, double dt) {
    gcStatus idle = check_idle(w);
    if (idle) return idle;
    if (!isfinite(dt) || !(dt > 0.0) || dt > 1.0) {
        gc_world_set_error(w, "dt: must be a finite step in (0, 1] seconds (got %g)", dt);
        return GC_ERR_INVALID_ARGUMENT;
    }
    if (gc_step(w, dt)) {
        gc_world_set_error(w, "body %d%s: its state would have become non-finite at t = %g s; "
                           "stopped at its pose before the step",
                           (int)w->first_stopped_body, w->step_stopped_bodies > 1 ? " and others" : "", w->time);
        return GC_WARN_STOPPED;
    }
    return GC_OK;
}

gcStatus gc_world_step_hips(gcWorld *w, const double *hips, int num_fingers, int steps, double dt,
                            uint64_t first_tick, void *records, size_t size, int *done) {
    if (done) *done = 0;
    gcStatus idle = check_idle(w);
    if (idle) return idle;
    if (steps < 0 || (steps > 0 && (!hips && num_fingers > 0))) {
        gc_world_set_error(w, "steps: %d steps of HIPs (need >= 0 and the HIPs)", steps);
        return GC_ERR_INVALID_ARGUMENT;
    }
    size_t record = gc_tick_record_size(w->num_bodies, w->num_fingers);
    if (records && size / record < (size_t)steps) {
        gc_world_set_error(w, "records: %zu bytes for %d records of %zu", size, steps, record);
        return GC_ERR_INVALID_ARGUMENT;
    }
    gcStatus warned = GC_OK;
    for (int k = 0; k < steps; ++k) {
        gcStatus st = num_fingers > 0 ? gc_world_set_hips(w, hips + 3 * (size_t)num_fingers * (size_t)k, num_fingers)
                                       : GC_OK;
        if (st >= 0) st = gc_world_step(w, dt);
        if (st == GC_WARN_STOPPED) warned = st;
        if (st >= 0 && records)
            st = gc_world_tick_record(w, first_tick + (uint64_t)k, (char *)records + record * (size_t)k, record);
        if (st < 0) return st;
        if (done) *done = k + 1;
    }
    return warned;
}

gcStatus gc_world_step_hips_trace(gcWorld *w, const double *hips, int num_fingers, int steps, double dt,
                                  int first, int total, void *traces, size_t size, int *done) {
    if (done) *done = 0;
    gcStatus idle = check_idle(w);
    if (idle) return idle;
    size_t trace = gc_tick_trace_size(w->num_bodies, w->num_fingers);
    if (steps < 0 || (steps > 0 && (!hips && num_fingers > 0))) {
        gc_world_set_error(w, "steps: %d steps of HIPs (need >= 0 and the HIPs)", steps);
        return GC_ERR_INVALID_ARGUMENT;
    }
    if (first < 0 || total < 0 || steps > total - first) {
        gc_world_set_error(w, "first, total: steps %d to %d of %d ticks", first, first + steps, total);
        return GC_ERR_INVALID_ARGUMENT;
    }
    if (!traces || size / trace < (size_t)total) {
        gc_world_set_error(w, "traces: %zu bytes for %d ticks of %zu", traces ? size : 0, total, trace);
        return GC_ERR_INVALID_ARGUMENT;
    }
    gcStatus warned = GC_OK;
    for (int k = 0; k < steps; ++k) { /* as gc_world_step_hips, the trace for the record */
        gcStatus st = num_fingers > 0 ? gc_world_set_hips(w, hips + 3 * (size_t)num_fingers * (size_t)k, num_fingers)
                                       : GC_OK;
        if (st >= 0) st = gc_world_step(w, dt);
        if (st == GC_WARN_STOPPED) warned = st;
        if (st < 0) return st;
        gc_tick_trace_fill(w, traces, (size_t)first + (size_t)k, (size_t)total);
        if (done) *done = k + 1;
    }
    return warned;
}

int64_t gc_world_stopped_bodies(const gcWorld *w) { return w ? w->stopped_bodies : 0; }

/* While the runtime runs, queries answer from its last snapshot (world->shown). */
static const gcBodyState *shown_body(const gcWorld *w, int32_t body) {
    return w->shown ? &w->shown->bodies[body] : &w->bodies[body].state;
}

static const gcFinger *shown_finger(const gcWorld *w, int32_t finger) {
    return w->shown ? &w->shown->fingers[finger] : &w->fingers[finger];
}

static void put3(double out[3], gcVec3 v) {
    out[0] = v.x, out[1] = v.y, out[2] = v.z;
}

gcStatus gc_world_body_pose(const gcWorld *w, int32_t body, double pos[3], double quat[4]) {
    gcStatus st = gc_check_body(w, body);
    if (st) return st;
    if (!pos) return gc_null_argument(w, "position");
    if (!quat) return gc_null_argument(w, "orientation");
    memcpy(pos, &w->pose_array[7 * body], 3 * sizeof(double));
    memcpy(quat, &w->pose_array[7 * body + 3], 4 * sizeof(double));
    return GC_OK;
}

gcStatus gc_world_body_velocity(const gcWorld *w, int32_t body, double lin[3], double ang[3]) {
    gcStatus st = gc_check_body(w, body);
    if (st) return st;
    if (!lin) return gc_null_argument(w, "linear");
    if (!ang) return gc_null_argument(w, "angular");
    const gcBodyState *s = shown_body(w, body);
    /* Report the velocity of the body frame origin, consistent with body_pose. */
    put3(lin, gc_body_origin_velocity(&w->model->bodies[body], s));
    put3(ang, s->w);
    return GC_OK;
}

gcStatus gc_world_body_mass(const gcWorld *w, int32_t body, double *mass, double com[3], double inertia[9]) {
    gcStatus st = gc_check_body(w, body);
    if (st) return st;
    if (!mass) return gc_null_argument(w, "mass");
    if (!com) return gc_null_argument(w, "center_of_mass");
    if (!inertia) return gc_null_argument(w, "inertia");
    const gcBodyModel *b = &w->model->bodies[body];
    *mass = b->is_static ? INFINITY : b->mass;
    put3(com, b->com_local);
    memcpy(inertia, b->inertia_local.m, 9 * sizeof(double));
    return GC_OK;
}

gcStatus gc_world_residual_wrench(const gcWorld *w, int32_t body, double force[3], double torque[3]) {
    gcStatus st = gc_check_body(w, body);
    if (st) return st;
    if (!force) return gc_null_argument(w, "force");
    if (!torque) return gc_null_argument(w, "torque");
    put3(force, shown_body(w, body)->residual_force);
    put3(torque, shown_body(w, body)->residual_torque);
    return GC_OK;
}

gcStatus gc_world_finger_force(const gcWorld *w, int32_t finger, double force[3]) {
    gcStatus st = gc_check_finger(w, finger);
    if (st) return st;
    if (!force) return gc_null_argument(w, "force");
    put3(force, shown_finger(w, finger)->force);
    return GC_OK;
}

/* The contact patch and its torque are not in the runtime's snapshots: refused while it runs
 * rather than answered from the state the world had at gc_world_start. */
static gcStatus check_patch_readable(const gcWorld *w, const char *what) {
    if (w->locked) {
        gc_world_set_error(w, "%s: the runtime's snapshots do not carry a finger's contact patch; stop the runtime "
                              "first (World.stop / gc_world_stop)", what);
        return GC_ERR_BUSY;
    }
    return GC_OK;
}

gcStatus gc_world_finger_torque(const gcWorld *w, int32_t finger, double torque[3]) {
    gcStatus st = gc_check_finger(w, finger);
    if (st || (st = check_patch_readable(w, "finger_torque"))) return st;
    if (!torque) return gc_null_argument(w, "torque");
    put3(torque, shown_finger(w, finger)->torque);
    return GC_OK;
}

gcStatus gc_world_finger_pose(const gcWorld *w, int32_t finger, double pos[3], double orientation[4]) {
    gcStatus st = gc_check_finger(w, finger);
    if (st) return st;
    if (!pos) return gc_null_argument(w, "position");
    if (!orientation) return gc_null_argument(w, "orientation");
    const gcFinger *f = shown_finger(w, finger);
    put3(pos, f->hip);
    orientation[0] = f->q.w, orientation[1] = f->q.x, orientation[2] = f->q.y, orientation[3] = f->q.z;
    return GC_OK;
}

gcStatus gc_world_finger_contacts(const gcWorld *w, int32_t finger, gcFingerContactPoint *out, int capacity,
                                  int *out_count) {
    gcStatus st = gc_check_finger(w, finger);
    if (st || (st = check_patch_readable(w, "finger_contacts"))) return st;
    if (!out_count) return gc_null_argument(w, "out_count");
    if (capacity < 0 || (capacity > 0 && !out)) {
        gc_world_set_error(w, "out: %d entries asked for and %s", capacity, out ? "a negative capacity" : "no array");
        return GC_ERR_INVALID_ARGUMENT;
    }
    const gcFinger *f = &w->fingers[finger];
    const gcFingerModel *fm = &w->model->fingers[finger];
    for (int i = 0; i < f->num_contacts && i < capacity && out; ++i) {
        const gcFingerContact *c = &f->contacts[i];
        int32_t body = w->model->parts[c->part].body;
        const gcBodyModel *b = &w->model->bodies[body];
        gcBodyState state = w->bodies[body].state;
        gcTransform fr = gc_body_transform(b, &state);
        gcVec3 anchor, anchor_velocity, point;
        gc_finger_contact_ends(fm, f, c, &fr, &anchor, &anchor_velocity, &point);
        gcFingerContactPoint *o = &out[i];
        memset(o, 0, sizeof *o);
        o->body = body;
        o->sample = c->sample;
        o->reversed = c->reversed;
        o->state = c->state;
        put3(o->point, point);
        put3(o->normal, gc_finger_point_normal(f, c, &fr.R));
        /* The spring and damper as the body receives them (dynamics.c), weighted by the contact's
         * share (a seam's blend, the cursor's part of its constraint), on the state shown. */
        double k = fm->stiffness * c->share, damping = fm->damping * c->share;
        gcVec3 force = gc_scale(gc_sub(point, anchor), k);
        if (damping > 0.0 && !b->is_static) {
            gcVec3 v_point = gc_add(state.v, gc_cross(state.w, gc_sub(point, state.com)));
            force = gc_madd(force, gc_sub(v_point, anchor_velocity), damping);
        } else if (damping > 0.0) {
            force = gc_madd(force, anchor_velocity, -damping);
        }
        put3(o->force, force);
    }
    *out_count = f->num_contacts;
    return GC_OK;
}

gcStatus gc_world_god_object(const gcWorld *w, int32_t finger, double pos[3]) {
    gcStatus st = gc_check_finger(w, finger);
    if (st) return st;
    if (!pos) return gc_null_argument(w, "position");
    put3(pos, shown_finger(w, finger)->god_object);
    return GC_OK;
}

gcStatus gc_world_finger_state(const gcWorld *w, int32_t finger, gcFingerState *state, int32_t *contact_body) {
    gcStatus st = gc_check_finger(w, finger);
    if (st) return st;
    if (!state) return gc_null_argument(w, "state");
    if (!contact_body) return gc_null_argument(w, "contact_body");
    *state = shown_finger(w, finger)->state;
    *contact_body = shown_finger(w, finger)->contact_body;
    return GC_OK;
}

const double *gc_world_body_pose_array(const gcWorld *w) { return w->pose_array; }
const double *gc_world_god_object_array(const gcWorld *w) { return w->god_object_array; }
const double *gc_world_finger_force_array(const gcWorld *w) { return w->force_array; }
const double *gc_world_hip_array(const gcWorld *w) { return w->hip_array; }

uint64_t gc_world_state_hash(const gcWorld *w) { return gc_tick_state_hash(w); }
