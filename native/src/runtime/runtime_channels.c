/* The runtime's channels (runtime_internal.h): copies of body state into and out of the
 * shadows, the publications each thread makes every tick, push_hips and snapshots. */
#define _GNU_SOURCE
#include "runtime_internal.h"

static void body_save(const gcWorld *s, int32_t i, gcRuntimeBody *o) {
    const gcBody *b = &s->bodies[i];
    o->state = b->state;
    memcpy(o->pose, &s->pose_array[7 * i], sizeof o->pose);
}

void gc_runtime_body_load(gcWorld *s, int32_t i, const gcRuntimeBody *o) {
    gcBody *b = &s->bodies[i];
    b->state = o->state;
    memcpy(&s->pose_array[7 * i], o->pose, sizeof o->pose);
}

/* ---- publications ------------------------------------------------------------------- */

void gc_runtime_publish_to_object(gcRuntime *rt) {
    const gcWorld *hw = &rt->hap;
    gcHapticMsg *m = &rt->haptic_msg[rt->to_object.back];
    for (int32_t b = 0; b < hw->num_bodies; ++b) {
        unsigned char s = rt->hstate[b];
        m->want[b] = s == GC_HAPTIC_REQUESTED || s == GC_HAPTIC_OWNS;
        m->has_state[b] = s == GC_HAPTIC_OWNS || s == GC_HAPTIC_RETURNING;
        if (m->has_state[b]) body_save(hw, b, &m->body[b]);
    }
    memcpy(m->fingers, hw->fingers, (size_t)hw->num_fingers * sizeof *hw->fingers);
    rt->object_reads = gc_triple_publish_counted(&rt->to_object);
}

void gc_runtime_publish_to_haptic(gcRuntime *rt) {
    const gcWorld *ow = &rt->obj;
    /* A replay holds the result back until the tick the schedule delivers it at. */
    gcObjectMsg *m = rt->replaying ? &rt->replay_queue[rt->object_seq % GC_REPLAY_QUEUE]
                                      : &rt->object_msg[rt->to_haptic.back];
    m->seq = rt->object_seq;
    m->time = ow->time;
    for (int32_t b = 0; b < ow->num_bodies; ++b) {
        m->released[b] = rt->ostate[b] == GC_OBJECT_RELEASED;
        body_save(ow, b, &m->body[b]);
    }
    if (!rt->replaying) gc_triple_publish(&rt->to_haptic);
}

void gc_runtime_deliver_to_haptic(gcRuntime *rt, const gcObjectMsg *held) {
    gcObjectMsg *m = &rt->object_msg[rt->to_haptic.back];
    m->seq = held->seq;
    m->time = held->time;
    memcpy(m->released, held->released, (size_t)rt->obj.num_bodies);
    memcpy(m->body, held->body, (size_t)rt->obj.num_bodies * sizeof *m->body);
    gc_triple_publish(&rt->to_haptic);
}

void gc_runtime_publish_display(gcRuntime *rt, int64_t now, int forces_enabled) {
    const gcWorld *hw = &rt->hap;
    gcDisplayMsg *d = &rt->display_msg[rt->display.back];
    d->tick = rt->tick;
    d->time = hw->time;
    d->object_time = rt->object_time_seen;
    d->clock_ns = now;
    d->forces_enabled = forces_enabled;
    for (int32_t b = 0; b < hw->num_bodies; ++b) {
        body_save(hw, b, &d->body[b]);
        d->adopted[b] = rt->hstate[b] == GC_HAPTIC_OWNS;
    }
    for (int32_t i = 0; i < hw->num_fingers; ++i) {
        const gcFinger *f = &hw->fingers[i];
        memcpy(&d->hip[3 * i], &f->hip, 3 * sizeof(double));
        memcpy(&d->god_object[3 * i], &f->god_object, 3 * sizeof(double));
        memcpy(&d->spring_force[3 * i], &f->force, 3 * sizeof(double));
        memcpy(&d->device_force[3 * i], &rt->device_force[3 * i], 3 * sizeof(double));
        memcpy(&d->normal[3 * i], &f->normal, 3 * sizeof(double));
        memcpy(&d->patch[2 * GC_FINGER_PATCH_CORNERS * i], f->patch, sizeof f->patch);
        d->state[i] = (int32_t)f->state;
        d->contact_body[i] = f->contact_body;
    }
    gc_triple_publish(&rt->display);
}

/* The checked input into the haptic loop's input channel (callers serialise on input_mutex). */
static gcStatus gc_runtime_push_input(gcWorld *w, const double *positions, const double *orientations,
                                      int count, double t) {
    gcRuntime *rt = w->runtime;
    int finite = isfinite(t);
    for (int i = 0; i < 3 * count && finite; ++i) finite = isfinite(positions[i]);
    for (int i = 0; orientations && i < count && finite; ++i) { /* finite and not zero */
        const double *q = &orientations[4 * i];
        double n2 = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3];
        finite = isfinite(q[0]) && isfinite(q[1]) && isfinite(q[2]) && isfinite(q[3]) && n2 > 1e-20 && isfinite(n2);
    }
    if (!finite) {
        gc_atomic_increment(&rt->rejected_inputs);
        return GC_WARN_REJECTED;
    }
    pthread_mutex_lock(&rt->input_mutex);
    if (t < rt->input_last_t) { /* older than what the loop already has */
        pthread_mutex_unlock(&rt->input_mutex);
        gc_atomic_increment(&rt->rejected_inputs);
        return GC_WARN_REJECTED;
    }
    rt->input_last_t = t;
    gcInputMsg *m = &rt->input_msg[rt->input.back];
    m->count = count;
    m->t = t;
    m->receipt_ns = rt->def.realtime ? gc_clock_now_ns() : atomic_load_explicit(&rt->manual_now_ns, memory_order_relaxed);
    memcpy(m->hips, positions, 3 * (size_t)count * sizeof(double));
    m->has_orientations = orientations != NULL;
    if (orientations) memcpy(m->orientations, orientations, 4 * (size_t)count * sizeof(double));
    gc_triple_publish(&rt->input);
    pthread_mutex_unlock(&rt->input_mutex);
    gc_atomic_increment(&rt->accepted_inputs);
    return GC_OK;
}

gcStatus gc_world_push_hips(gcWorld *w, const double *positions, int count, double t) {
    return gc_world_push_finger_poses(w, positions, NULL, count, t);
}

gcStatus gc_world_push_finger_poses(gcWorld *w, const double *positions, const double *orientations, int count,
                                    double t) {
    if (!w) return GC_ERR_INVALID_ARGUMENT;
    if (!positions) return gc_null_argument(w, "positions");
    if (!gc_runtime_running(w)) {
        gc_world_set_error(w, "push_hips: the runtime is not running (World.start / gc_world_start)");
        return GC_ERR_NOT_RUNNING;
    }
    if (count < 1 || count > w->num_fingers) {
        gc_world_set_error(w, "positions: %d rows given for %d fingers", count, w->num_fingers);
        return GC_ERR_INVALID_ARGUMENT;
    }
    return gc_runtime_push_input(w, positions, orientations, count, t);
}

/* Body b of a snapshot from its model and a copy of its state (the world's or the display
 * channel's). */
static void put_body(const gcSnapshot *s, const gcBodyModel *model, int32_t b, const double pose[7],
                     const gcBodyState *st, int adopted) {
    if (s->poses) memcpy(&s->poses[7 * b], pose, 7 * sizeof(double));
    if (s->residual_wrenches) {
        double *r = &s->residual_wrenches[6 * b];
        gcVec3 f = st->residual_force, t = st->residual_torque;
        r[0] = f.x, r[1] = f.y, r[2] = f.z, r[3] = t.x, r[4] = t.y, r[5] = t.z;
    }
    if (s->velocities) {
        double *v = &s->velocities[6 * b];
        gcVec3 lin = gc_body_origin_velocity(model, st);
        v[0] = lin.x, v[1] = lin.y, v[2] = lin.z, v[3] = st->w.x, v[4] = st->w.y, v[5] = st->w.z;
    }
    if (s->adopted) s->adopted[b] = (uint8_t)adopted;
}

static void put3(double *array, int32_t i, const double *v) {
    if (array) memcpy(&array[3 * i], v, 3 * sizeof(double));
}

static void put_patch(float *array, int32_t i, const float *patch) {
    if (array) memcpy(&array[2 * GC_FINGER_PATCH_CORNERS * i], patch, 2 * GC_FINGER_PATCH_CORNERS * sizeof(float));
}

/* Stopped: the world's own state; nothing is rendered to a device. */
static void snapshot_from_world(const gcWorld *w, gcSnapshot *s) {
    static const double zero[3] = {0, 0, 0};
    s->time = s->object_time = w->time;
    s->tick = 0;
    s->forces_enabled = 0;
    s->num_bodies = w->num_bodies;
    s->num_fingers = w->num_fingers;
    for (int32_t b = 0; b < w->num_bodies; ++b)
        put_body(s, &w->model->bodies[b], b, &w->pose_array[7 * b], &w->bodies[b].state, 0);
    for (int32_t i = 0; i < w->num_fingers; ++i) {
        const gcFinger *f = &w->fingers[i];
        put3(s->hips, i, &w->hip_array[3 * i]);
        put3(s->god_objects, i, &w->god_object_array[3 * i]);
        put3(s->spring_forces, i, &w->force_array[3 * i]);
        put3(s->forces, i, zero);
        put3(s->normals, i, (const double *)&f->normal);
        put_patch(s->patches, i, f->patch);
        if (s->finger_states) s->finger_states[i] = (int32_t)f->state;
        if (s->contact_bodies) s->contact_bodies[i] = f->contact_body;
    }
}

gcStatus gc_world_snapshot(gcWorld *w, gcSnapshot *s) {
    if (!w) return GC_ERR_INVALID_ARGUMENT;
    if (!s) return gc_null_argument(w, "snapshot");
    gcRuntime *rt = w->runtime;
    if (!rt) {
        snapshot_from_world(w, s);
        return GC_OK;
    }
    pthread_mutex_lock(&rt->api_mutex);
    if (atomic_load_explicit(&rt->state, memory_order_acquire) != GC_RUNTIME_RUNNING) {
        snapshot_from_world(w, s);
        pthread_mutex_unlock(&rt->api_mutex);
        return GC_OK;
    }
    int fresh;
    const gcDisplayMsg *d = &rt->display_msg[gc_triple_latest(&rt->display, &fresh)];
    /* Reader-side watchdog: a loop that stalled cannot zero its own output. */
    int enabled = d->forces_enabled;
    if (rt->def.realtime && gc_clock_now_ns() - d->clock_ns > rt->watchdog_ns) enabled = 0;
    static const double zero[3] = {0, 0, 0};
    s->time = d->time;
    s->object_time = d->object_time;
    s->tick = d->tick;
    s->forces_enabled = enabled;
    s->num_bodies = w->num_bodies;
    s->num_fingers = w->num_fingers;
    /* The world's queries and views answer from this snapshot while the runtime runs. */
    for (int32_t b = 0; b < w->num_bodies; ++b) {
        const gcRuntimeBody *rb = &d->body[b];
        put_body(s, &w->model->bodies[b], b, rb->pose, &rb->state, d->adopted[b]);
        if (!w->model->bodies[b].is_static) {
            rt->shown.bodies[b] = rb->state;
            memcpy(&w->pose_array[7 * b], rb->pose, sizeof rb->pose); /* the pose view */
        }
    }
    for (int32_t i = 0; i < w->num_fingers; ++i) {
        put3(s->hips, i, &d->hip[3 * i]);
        put3(s->god_objects, i, &d->god_object[3 * i]);
        put3(s->spring_forces, i, &d->spring_force[3 * i]);
        put3(s->forces, i, enabled ? &d->device_force[3 * i] : zero);
        put3(s->normals, i, &d->normal[3 * i]);
        put_patch(s->patches, i, &d->patch[2 * GC_FINGER_PATCH_CORNERS * i]);
        if (s->finger_states) s->finger_states[i] = d->state[i];
        if (s->contact_bodies) s->contact_bodies[i] = d->contact_body[i];
        gcFinger *f = &rt->shown.fingers[i];
        f->hip = gc_v3(d->hip[3 * i], d->hip[3 * i + 1], d->hip[3 * i + 2]);
        f->god_object = gc_v3(d->god_object[3 * i], d->god_object[3 * i + 1], d->god_object[3 * i + 2]);
        f->force = gc_v3(d->spring_force[3 * i], d->spring_force[3 * i + 1], d->spring_force[3 * i + 2]);
        f->state = (gcFingerState)d->state[i];
        f->contact_body = d->contact_body[i];
        memcpy(&w->hip_array[3 * i], &d->hip[3 * i], 3 * sizeof(double));
        memcpy(&w->god_object_array[3 * i], &d->god_object[3 * i], 3 * sizeof(double));
        memcpy(&w->force_array[3 * i], &d->spring_force[3 * i], 3 * sizeof(double));
    }
    rt->shown.time = d->time;
    pthread_mutex_unlock(&rt->api_mutex);
    return GC_OK;
}

