/* The runtime's ticks and the hand-over of bodies between its two loops
 * (runtime_internal.h; the protocol is described in runtime.c). */
#define _GNU_SOURCE
#include "runtime_internal.h"
#include "tick_log.h"

/* Bodies the non-finite guard stopped in a shadow's step, for gc_world_stats. */
static void count_stopped(gcRuntime *rt, int stopped) {
    if (stopped) atomic_fetch_add_explicit(&rt->stopped_bodies, (uint64_t)stopped, memory_order_relaxed);
}

/* ---- the haptic tick ---------------------------------------------------------------- */

/* Which chains the haptic loop wants, after this tick's god-object update: those touched by
 * a finger within release_delay, while they have at most max_adopted_bodies bodies. */
static void update_adoption(gcRuntime *rt) {
    gcWorld *hw = &rt->hap;
    const int cap = rt->def.max_adopted_bodies;
    const double now = hw->time;
    if (cap > 0) {
        for (int32_t fi = 0; fi < hw->num_fingers; ++fi) {
            const gcFinger *f = &hw->fingers[fi];
            for (int c = 0; c < f->num_contacts; ++c) {
                int32_t b = hw->model->parts[f->contacts[c].part].body;
                if (hw->model->bodies[b].is_static) continue;
                int n = gc_contacts_chain_of(hw, b, rt->chain, cap);
                if (n > cap) continue;
                for (int k = 0; k < n; ++k) rt->last_touch[rt->chain[k]] = now;
            }
        }
    }
    int adopted = 0;
    for (int32_t b = 0; b < hw->num_bodies; ++b) {
        if (hw->model->bodies[b].is_static) continue;
        int want = cap > 0 && now - rt->last_touch[b] <= rt->def.release_delay &&
                   gc_contacts_chain_of(hw, b, rt->chain, cap) <= cap;
        /* A request or a return runs to completion before the wish can change again. */
        if (rt->hstate[b] == GC_HAPTIC_OM_OWNS && want) {
            rt->hstate[b] = GC_HAPTIC_REQUESTED;
        } else if (rt->hstate[b] == GC_HAPTIC_OWNS && !want) {
            rt->hstate[b] = GC_HAPTIC_RETURNING; /* stepped this tick; the object manager continues from here */
            rt->hap_active[b] = 0;
        }
        adopted += rt->hstate[b] == GC_HAPTIC_OWNS;
    }
    atomic_store_explicit(&rt->adopted, adopted, memory_order_relaxed);
}

/* Device forces: the spring, ramped in, clamped, and zero while the watchdog holds them. */
static int update_safety(gcRuntime *rt, int64_t now) {
    const gcWorld *hw = &rt->hap;
    int64_t period = rt->prev_tick_ns == GC_NEVER_NS ? rt->period_ns : now - rt->prev_tick_ns;
    rt->prev_tick_ns = now;
    int ok = 1;
    if (period > rt->watchdog_ns) {
        ok = 0; /* the loop missed its deadlines: zero, then ramp in again */
        gc_atomic_increment(&rt->watchdog_trips);
    }
    int stale = rt->last_input_ns == GC_NEVER_NS || now - rt->last_input_ns > rt->hip_timeout_ns;
    if (stale) {
        ok = 0;
        if (!rt->was_stale) gc_atomic_increment(&rt->stale_inputs);
    }
    rt->was_stale = stale;
    double gain = gc_force_gate_gain(&rt->gate, ok, now);
    for (int32_t i = 0; i < hw->num_fingers; ++i) {
        double *out = &rt->device_force[3 * i];
        out[0] = hw->fingers[i].force.x, out[1] = hw->fingers[i].force.y, out[2] = hw->fingers[i].force.z;
    }
    int nonfinite = gc_force_gate_apply(gain, rt->def.max_force, rt->device_force, rt->device_force, hw->num_fingers);
    if (nonfinite) atomic_fetch_add_explicit(&rt->nonfinite_forces, (uint64_t)nonfinite, memory_order_relaxed);
    atomic_store_explicit(&rt->forces_enabled, ok, memory_order_relaxed);
    return ok;
}

/* The device slots (device_hub.c): each finger a device drives walks towards its device's
 * latest sample, at most GC_HIP_SOFT_START_SPEED from the first sample of a connection until
 * it is there; a sample with an orientation turns the finger to it over the same interval
 * (normalised lerp, as a pushed pose), one without leaves the orientation where it is. Returns 1 when a device sent something new. Pushed rows no longer move such a
 * finger (its device drives it whatever the caller pushes). */
static int take_device_samples(gcRuntime *rt) {
    gcWorld *hw = &rt->hap;
    int took = 0;
    for (int i = 0; i < hw->num_fingers; ++i) {
        gcDeviceSample s;
        gcRuntimeDeviceFinger *df = &rt->device_finger[i];
        if (gc_hip_track_drives(rt->track, i) || !gc_device_hub_latest_hip(rt->hub, i, &s)) {
            df->serial = 0;
            continue;
        }
        if (s.serial == df->serial) continue;
        if (!df->serial || s.episode != df->episode) df->soft_start = 1;
        double interval = df->serial ? s.t - df->t : 0.0;
        gc_hip_follow_retarget(&rt->follow[i], hw->fingers[i].hip, gc_v3(s.hip[0], s.hip[1], s.hip[2]), interval,
                               rt->dt_haptic);
        if (s.has_q) /* as a pushed pose's: over the same interval as its position */
            gc_hip_follow_turn_to(&rt->follow[i], hw->fingers[i].q, (gcQuat){s.q[0], s.q[1], s.q[2], s.q[3]});
        df->serial = s.serial, df->t = s.t, df->episode = s.episode;
        took = 1;
    }
    return took;
}

/* Step 1 of the haptic tick: the newest pushed samples retargeted, device samples taken, a
 * replay's recorded poses set; when the input was last fresh. */
static void take_hip_inputs(gcRuntime *rt, int64_t now) {
    gcWorld *hw = &rt->hap;
    const double dt = rt->dt_haptic;
    int fresh;
    const gcInputMsg *in = &rt->input_msg[gc_triple_latest(&rt->input, &fresh)];
    if (fresh) {
        double interval = isfinite(rt->follow_prev_t) ? in->t - rt->follow_prev_t : 0.0;
        rt->follow_prev_t = in->t;
        for (int i = 0; i < in->count; ++i)
            if (!gc_hip_track_drives(rt->track, i) && !rt->device_finger[i].serial) {
                gc_hip_follow_retarget(&rt->follow[i], hw->fingers[i].hip,
                                       gc_v3(in->hips[3 * i], in->hips[3 * i + 1], in->hips[3 * i + 2]), interval, dt);
                const double *q = &in->orientations[4 * i];
                if (in->has_orientations)
                    gc_hip_follow_turn_to(&rt->follow[i], hw->fingers[i].q, (gcQuat){q[0], q[1], q[2], q[3]});
            }
        rt->last_input_ns = in->receipt_ns;
    }
    if (take_device_samples(rt)) rt->last_input_ns = now;
    if (gc_hip_track_covers(rt->track, hw->num_fingers)) rt->last_input_ns = now; /* the track is never stale */
    for (int i = 0; i < hw->num_fingers && rt->replay_hips; ++i) { /* a replay: the recorded pose */
        gcFinger *f = &hw->fingers[i];
        const double *p = &rt->replay_hips[3 * i], *q = rt->replay_orientations ? &rt->replay_orientations[4 * i] : NULL;
        f->hip = gc_v3(p[0], p[1], p[2]);
        if (q && memcmp(q, &f->q, sizeof f->q) != 0) { /* as recorded: already normalised once */
            f->q = (gcQuat){q[0], q[1], q[2], q[3]};
            f->R = gc_quat_to_mat3(f->q);
        }
        memcpy(&hw->hip_array[3 * i], p, 3 * sizeof(double));
    }
}

/* Step 1, live: every finger's HIP (and orientation) at the tick's end time t_next, from the
 * scripted track or the bounded-speed walk (slower while a device's soft start lasts). */
static void advance_hips(gcRuntime *rt, double t_next) {
    gcWorld *hw = &rt->hap;
    const double dt = rt->dt_haptic;
    for (int i = 0; i < hw->num_fingers && !rt->replay_hips; ++i) {
        const int scripted = gc_hip_track_drives(rt->track, i);
        gcRuntimeDeviceFinger *df = &rt->device_finger[i];
        double max_speed = rt->def.max_hip_speed;
        if (df->soft_start)
            max_speed = max_speed > 0 ? fmin(max_speed, GC_HIP_SOFT_START_SPEED) : GC_HIP_SOFT_START_SPEED;
        gcHipFollow walk; /* before this tick's step: the same walk without the soft speed */
        if (df->soft_start) walk = rt->follow[i];
        gcVec3 hip = scripted ? gc_hip_track_sample(rt->track, i, t_next)
                              : gc_hip_follow_advance(&rt->follow[i], hw->fingers[i].hip, dt, max_speed);
        if (df->soft_start && !scripted) { /* over once the soft speed no longer holds the walk back and
                                               * the HIP is within a soft step of the device's latest sample:
                                               * a sample after a long silence is walked over a long segment,
                                               * slower than the soft speed, but the next one may ask for the
                                               * rest of the way in a tick */
            gcVec3 unheld = gc_hip_follow_advance(&walk, hw->fingers[i].hip, dt, rt->def.max_hip_speed);
            if (unheld.x == hip.x && unheld.y == hip.y && unheld.z == hip.z &&
                gc_len(gc_sub(rt->follow[i].to, hip)) <= GC_HIP_SOFT_START_SPEED * dt)
                df->soft_start = 0;
        }
        hw->fingers[i].hip = hip;
        gcQuat q; /* the track's or the walk's orientation: normalised as gc_world_set_finger_pose does */
        if (scripted ? gc_hip_track_orientation(rt->track, i, t_next, &q)
                     : gc_hip_follow_orientation(&rt->follow[i], &q)) {
            hw->fingers[i].q = gc_quat_normalize(q);
            hw->fingers[i].R = gc_quat_to_mat3(hw->fingers[i].q);
        }
        double *out = &hw->hip_array[3 * i];
        out[0] = hip.x, out[1] = hip.y, out[2] = hip.z;
    }

}

/* Step 2: the object manager's newest bodies loaded; bodies it released adopted. */
static void take_object_bodies(gcRuntime *rt) {
    gcWorld *hw = &rt->hap;
    int fresh;
    const gcObjectMsg *om = &rt->object_msg[gc_triple_latest(&rt->to_haptic, &fresh)];
    if (fresh) {
        rt->object_time_seen = om->time;
        rt->object_seq_seen = om->seq;
        for (int32_t b = 0; b < hw->num_bodies; ++b) {
            if (hw->model->bodies[b].is_static) continue;
            switch (rt->hstate[b]) {
            case GC_HAPTIC_OM_OWNS: gc_runtime_body_load(hw, b, &om->body[b]); break;
            case GC_HAPTIC_REQUESTED:
                gc_runtime_body_load(hw, b, &om->body[b]);
                if (om->released[b]) {
                    rt->hstate[b] = GC_HAPTIC_OWNS;
                    rt->hap_active[b] = 1;
                }
                break;
            case GC_HAPTIC_RETURNING:
                if (!om->released[b]) {
                    gc_runtime_body_load(hw, b, &om->body[b]);
                    rt->hstate[b] = GC_HAPTIC_OM_OWNS;
                }
                break;
            default: break;
            }
        }
    }

}

void gc_runtime_haptic_tick(gcRuntime *rt, int64_t now) {
    gcWorld *hw = &rt->hap;
    const double dt = rt->dt_haptic;
    if (rt->tick_log) gc_tick_log_prefetch(rt->tick_log); /* its misses overlap steps 1-4 */

    /* 1. HIPs at this tick's end time: the scripted track, or the walk towards the latest
     *    pushed samples (validated by push_hips). */
    take_hip_inputs(rt, now);
    advance_hips(rt, (double)(rt->tick + 1) * dt);

    /* 2. The object manager's bodies; bodies it released are adopted before stepping. */
    take_object_bodies(rt);

    /* 3. As gc_world_step: god-objects and springs, then the bodies this loop owns. */
    count_stopped(rt, gc_step(hw, dt));
    rt->tick++;

    /* 4. Adoption wishes for the next ticks, device forces, publications. */
    update_adoption(rt);
    int ok = update_safety(rt, now);
    gc_device_hub_tick(rt->hub, hw, rt->device_force, ok, now);
    gc_runtime_publish_to_object(rt);
    gc_runtime_publish_display(rt, now, ok);
    gcTickSchedule schedule = {rt->object_seq_seen, rt->object_reads};
    if (rt->replay_record)
        gc_tick_record_fill(hw, rt->device_force, rt->tick, rt->object_time_seen, schedule, ok,
                            atomic_load_explicit(&rt->adopted, memory_order_relaxed), rt->replay_record);
    else if (rt->tick_log) /* fingers a serial device drives: what their device was actually sent */
        gc_tick_log_push(rt->tick_log, hw, gc_device_hub_recorded_forces(rt->hub, rt->device_force, hw->num_fingers),
                         rt->tick, rt->object_time_seen, schedule, now, rt->def.realtime, ok,
                         atomic_load_explicit(&rt->adopted, memory_order_relaxed));
    gc_atomic_store_double(&rt->haptic_time_bits, hw->time);
    gc_atomic_increment(&rt->haptic_ticks);
}

/* ---- the object tick ---------------------------------------------------------------- */

void gc_runtime_object_tick(gcRuntime *rt) {
    gcWorld *ow = &rt->obj;
    int fresh;
    const gcHapticMsg *h = &rt->haptic_msg[gc_triple_latest_counted(&rt->to_object, &fresh)];
    rt->object_seq++;
    memcpy(ow->fingers, h->fingers, (size_t)ow->num_fingers * sizeof *ow->fingers);
    /* Bodies the haptic loop steps, where it has them now: obstacles for the contacts here. */
    for (int32_t b = 0; b < ow->num_bodies; ++b)
        if (rt->ostate[b] == GC_OBJECT_RELEASED && h->has_state[b]) gc_runtime_body_load(ow, b, &h->body[b]);
    for (int s = 0; s < rt->object_substeps; ++s) {
        count_stopped(rt, gc_step_bodies(ow, rt->dt_object));
        ow->time += rt->dt_object;
    }
    /* Hand-over after stepping: a released body was stepped this tick; a body taken back
     * was stepped by the haptic loop and moves from the next tick. */
    for (int32_t b = 0; b < ow->num_bodies; ++b) {
        if (ow->model->bodies[b].is_static) continue;
        if (rt->ostate[b] == GC_OBJECT_OWNS && h->want[b]) {
            rt->ostate[b] = GC_OBJECT_RELEASED;
            rt->obj_active[b] = 0;
        } else if (rt->ostate[b] == GC_OBJECT_RELEASED && !h->want[b] && h->has_state[b]) {
            gc_runtime_body_load(ow, b, &h->body[b]);
            rt->ostate[b] = GC_OBJECT_OWNS;
            rt->obj_active[b] = 1;
        }
    }
    gc_runtime_publish_to_haptic(rt);
    gc_atomic_store_double(&rt->object_time_bits, ow->time);
    gc_atomic_increment(&rt->object_ticks);
}

static int haptic_owns(const gcRuntime *rt, int32_t b) {
    return rt->ostate[b] == GC_OBJECT_RELEASED &&
           (rt->hstate[b] == GC_HAPTIC_OWNS || rt->hstate[b] == GC_HAPTIC_RETURNING);
}

static int haptic_owns_ctx(const void *rt, int32_t b) { return haptic_owns(rt, b); }

/* After the loops ended: each body from the thread that owned it last, fingers from the
 * haptic loop. */
void gc_runtime_merge_into_world(gcRuntime *rt, gcWorld *w) {
    const gcWorld *hw = &rt->hap, *ow = &rt->obj;
    for (int32_t b = 0; b < w->num_bodies; ++b) {
        if (w->model->bodies[b].is_static) continue;
        const gcWorld *src = haptic_owns(rt, b) ? hw : ow;
        w->bodies[b] = src->bodies[b];
        memcpy(&w->pose_array[7 * b], &src->pose_array[7 * b], 7 * sizeof(double));
    }
    memcpy(w->fingers, hw->fingers, (size_t)w->num_fingers * sizeof *w->fingers);
    memcpy(w->god_object_array, hw->god_object_array, (size_t)w->num_fingers * 3 * sizeof(double));
    memcpy(w->force_array, hw->force_array, (size_t)w->num_fingers * 3 * sizeof(double));
    memcpy(w->hip_array, hw->hip_array, (size_t)w->num_fingers * 3 * sizeof(double));
    w->time = hw->time;
    w->stopped_bodies += (int64_t)atomic_load_explicit(&rt->stopped_bodies, memory_order_relaxed);
    gc_contacts_merge(w, &rt->hap, &rt->obj, haptic_owns_ctx, rt);
}

