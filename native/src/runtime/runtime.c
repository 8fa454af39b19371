/* The real-time runtime (docs/runtime.md: the thread layout of the source chapter, Harwin &
 * Barrow, "Multi-finger grasps in a dynamic environment").
 *
 * gc_world_start() hands the world's dynamic state to two threads:
 *   - the haptic loop (default 1 kHz, absolute deadlines on CLOCK_MONOTONIC, SCHED_FIFO when
 *     the OS allows): latest HIPs in, god-objects and finger springs (xFCA), the bodies it
 *     has adopted stepped at its rate, device forces out through the safety stage;
 *   - the object manager (default 500 Hz, normal priority): every other dynamic body, in
 *     steps of at most 2 ms; when a tick takes too long it falls behind real time instead
 *     of taking larger steps.
 * Each thread steps its own *shadow* of the world: a gcWorld whose state (bodies, fingers,
 * output arrays, contacts) is private to the thread and whose model (shapes, masses, friction,
 * finger parameters) is the world's, read-only. A mask (body_active)
 * tells the dynamics which bodies the shadow moves. Nothing is locked between the threads:
 * every channel is a triple buffer (latest value, wait-free on both sides, C11 atomics):
 *   input   push_hips() -> haptic       latest HIPs (producers serialise among themselves)
 *   devices each finger's device -> haptic  its latest sample, a triple buffer a finger
 *           (device_hub.c: device threads and push_device_hips write them, no lock)
 *   haptic  haptic -> object manager    finger springs, adoption wishes, handed-back bodies
 *   object  object manager -> haptic    its bodies, and the bodies it released
 *   display haptic -> gc_world_snapshot everything a display needs, one haptic tick's view
 *
 * Hand-over of a body between the threads is a two-phase protocol in which exactly one
 * thread steps the body at any time and its state moves with the ownership:
 *   haptic   OM --want--> REQ --sees 'released'--> HAP --no longer wanted--> RET --sees 'owned'--> OM
 *   object   OWN --sees 'want'--> RELEASED --sees 'not wanted' with the final state--> OWN
 * A thread gives a body away only after stepping it in that tick, and takes it only before
 * stepping, so with the manual clock (realtime = 0, gc_world_advance) and equal rates every
 * body is stepped exactly once per tick with the same inputs as gc_world_step: the runtime
 * reproduces a synchronous run bit for bit (tests/core/test_runtime.py). */
#define _GNU_SOURCE
#include "runtime_internal.h"
#include "tick_log.h"

/* ---- the runtime's memory ------------------------------------------------------------ */

/* calloc, remembering the block so that gc_world_start can lock it in RAM. */
static void *rt_calloc(gcRuntime *rt, size_t n, size_t size) {
    void *p = calloc(n, size);
    if (p && rt->num_regions < GC_MAX_REGIONS) {
        rt->region[rt->num_regions].p = p;
        rt->region[rt->num_regions].n = n * size;
        rt->num_regions++;
    }
    return p;
}

static void unlock_memory(gcRuntime *rt) {
#ifdef __linux__
    if (rt->locked_bytes) {
        for (int i = 0; i < rt->num_regions; ++i) munlock(rt->region[i].p, rt->region[i].n);
        /* A page shared with another locked block (another world's runtime) is unlocked
         * with it: the worst case is that page can be swapped out again. */
    }
#endif
    rt->locked_bytes = 0;
}

/* Locks the runtime's own blocks (shadows, messages, this struct) in RAM, which also
 * faults them in: the haptic loop never waits for a page of them to come back from swap.
 * Not the contact state (contacts.c) nor the world's hulls, which the runtime does not
 * allocate. Never the whole process (mlockall): this runs inside Blender. Refused (no
 * CAP_IPC_LOCK and RLIMIT_MEMLOCK too small) or over GC_LOCK_BUDGET: nothing is locked and
 * the note says why. */
static void lock_memory(gcRuntime *rt) {
    rt->locked_bytes = 0;
#ifdef __linux__
    size_t total = 0;
    for (int i = 0; i < rt->num_regions; ++i) total += rt->region[i].n;
    if (total > GC_LOCK_BUDGET) {
        snprintf(rt->memory_note, sizeof rt->memory_note, "memory not locked (over %u MiB)", GC_LOCK_BUDGET >> 20);
        return;
    }
    for (int i = 0; i < rt->num_regions; ++i) {
        if (mlock(rt->region[i].p, rt->region[i].n) != 0) {
            int e = errno;
            for (int k = 0; k < i; ++k) munlock(rt->region[k].p, rt->region[k].n);
            snprintf(rt->memory_note, sizeof rt->memory_note, "memory not locked (%s)",
                     e == EPERM ? "not permitted" : e == ENOMEM ? "RLIMIT_MEMLOCK" : "refused");
            return;
        }
    }
    rt->locked_bytes = total;
    snprintf(rt->memory_note, sizeof rt->memory_note, "%zu KiB locked", (total + 1023) >> 10);
#else
    snprintf(rt->memory_note, sizeof rt->memory_note, "memory not locked");
#endif
}

/* ---- shadows ------------------------------------------------------------------------ */

/* A shadow is a world of its own state (its arrays, its contacts, its thread count) over the
 * world's model, which it only reads: it holds no other pointer of the world's (not its
 * runtime, tick log, devices, track or shown view). */
static int shadow_alloc(gcRuntime *rt, gcWorld *s, const gcWorld *w, unsigned char **active, int threads) {
    memset(s, 0, sizeof *s);
    s->def = w->def;
    s->def.threads = threads;
    s->model = w->model;
    s->bodies = rt_calloc(rt, (size_t)w->def.max_bodies, sizeof *s->bodies);
    s->fingers = rt_calloc(rt, (size_t)w->def.max_fingers, sizeof *s->fingers);
    s->pose_array = rt_calloc(rt, (size_t)w->def.max_bodies * 7, sizeof(double));
    s->god_object_array = rt_calloc(rt, (size_t)w->def.max_fingers * 3, sizeof(double));
    s->force_array = rt_calloc(rt, (size_t)w->def.max_fingers * 3, sizeof(double));
    s->hip_array = rt_calloc(rt, (size_t)w->def.max_fingers * 3, sizeof(double));
    *active = rt_calloc(rt, (size_t)w->def.max_bodies, 1);
    s->body_active = *active;
    if (!(s->bodies && s->fingers && s->pose_array && s->god_object_array && s->force_array && s->hip_array &&
          *active))
        return 0;
    /* Its own contact state and pool; the haptic loop never hands work to other threads. */
    return gc_contacts_create(s) == GC_OK;
}

static void shadow_free(gcWorld *s) {
    gc_contacts_destroy(s);
    free(s->bodies);
    free(s->fingers);
    free(s->pose_array);
    free(s->god_object_array);
    free(s->force_array);
    free(s->hip_array);
}

/* The world's state into a shadow, at start: all of it, copied (the model is shared). */
static void shadow_load(gcWorld *s, const gcWorld *w) {
    s->time = w->time;
    s->num_bodies = w->num_bodies;
    s->num_fingers = w->num_fingers;
    memcpy(s->bodies, w->bodies, (size_t)w->num_bodies * sizeof *w->bodies);
    memcpy(s->fingers, w->fingers, (size_t)w->num_fingers * sizeof *w->fingers);
    memcpy(s->pose_array, w->pose_array, (size_t)w->num_bodies * 7 * sizeof(double));
    memcpy(s->god_object_array, w->god_object_array, (size_t)w->num_fingers * 3 * sizeof(double));
    memcpy(s->force_array, w->force_array, (size_t)w->num_fingers * 3 * sizeof(double));
    memcpy(s->hip_array, w->hip_array, (size_t)w->num_fingers * 3 * sizeof(double));
    gc_contacts_copy_state(s, w);
}

/* ---- allocation --------------------------------------------------------------------- */

static void runtime_free_memory(gcRuntime *rt) {
    gc_runtime_replay_free(rt);
    shadow_free(&rt->hap);
    shadow_free(&rt->obj);
    free(rt->hap_active);
    free(rt->obj_active);
    free(rt->hstate);
    free(rt->last_touch);
    free(rt->chain);
    free(rt->device_force);
    free(rt->follow);
    free(rt->device_finger);
    free(rt->shown.bodies);
    free(rt->shown.fingers);
    free(rt->ostate);
    for (int i = 0; i < 3; ++i) {
        free(rt->input_msg[i].hips);
        free(rt->input_msg[i].orientations);
        free(rt->haptic_msg[i].want);
        free(rt->haptic_msg[i].has_state);
        free(rt->haptic_msg[i].body);
        free(rt->haptic_msg[i].fingers);
        free(rt->object_msg[i].released);
        free(rt->object_msg[i].body);
        gcDisplayMsg *d = &rt->display_msg[i];
        free(d->body);
        free(d->adopted);
        free(d->hip);
        free(d->god_object);
        free(d->spring_force);
        free(d->device_force);
        free(d->normal);
        free(d->patch);
        free(d->state);
        free(d->contact_body);
    }
    free(rt);
}

/* Everything is sized by the world's capacities once, on the first start, and reused: a
 * start/stop cycle allocates nothing but its two threads. */
static gcRuntime *runtime_alloc(const gcWorld *w) {
    gcRuntime *rt = calloc(1, sizeof *rt);
    if (!rt) return NULL;
    rt->region[0].p = rt;
    rt->region[0].n = sizeof *rt;
    rt->num_regions = 1;
    size_t nb = (size_t)w->def.max_bodies, nf = (size_t)w->def.max_fingers;
    rt->max_bodies = w->def.max_bodies;
    rt->max_fingers = w->def.max_fingers;
    rt->hub = w->hub;
    int ok = shadow_alloc(rt, &rt->hap, w, &rt->hap_active, 1);
    ok &= shadow_alloc(rt, &rt->obj, w, &rt->obj_active, w->def.threads);
    rt->hstate = rt_calloc(rt, nb, 1);
    rt->last_touch = rt_calloc(rt, nb, sizeof(double));
    rt->chain = rt_calloc(rt, nb, sizeof(int32_t));
    rt->device_force = rt_calloc(rt, nf * 3, sizeof(double));
    rt->follow = rt_calloc(rt, nf, sizeof(gcHipFollow));
    rt->device_finger = rt_calloc(rt, nf, sizeof(gcRuntimeDeviceFinger));
    rt->shown.bodies = rt_calloc(rt, nb, sizeof(gcBodyState));
    rt->shown.fingers = rt_calloc(rt, nf, sizeof(gcFinger));
    rt->ostate = rt_calloc(rt, nb, 1);
    ok &= rt->hstate && rt->last_touch && rt->chain && rt->device_force && rt->follow && rt->device_finger && rt->ostate &&
          rt->shown.bodies && rt->shown.fingers;
    for (int i = 0; i < 3; ++i) {
        gcInputMsg *in = &rt->input_msg[i];
        gcHapticMsg *h = &rt->haptic_msg[i];
        gcObjectMsg *o = &rt->object_msg[i];
        gcDisplayMsg *d = &rt->display_msg[i];
        in->hips = rt_calloc(rt, nf * 3, sizeof(double));
        in->orientations = rt_calloc(rt, nf * 4, sizeof(double));
        h->want = rt_calloc(rt, nb, 1);
        h->has_state = rt_calloc(rt, nb, 1);
        h->body = rt_calloc(rt, nb, sizeof(gcRuntimeBody));
        h->fingers = rt_calloc(rt, nf, sizeof(gcFinger));
        o->released = rt_calloc(rt, nb, 1);
        o->body = rt_calloc(rt, nb, sizeof(gcRuntimeBody));
        d->body = rt_calloc(rt, nb, sizeof(gcRuntimeBody));
        d->adopted = rt_calloc(rt, nb, 1);
        d->hip = rt_calloc(rt, nf * 3, sizeof(double));
        d->god_object = rt_calloc(rt, nf * 3, sizeof(double));
        d->spring_force = rt_calloc(rt, nf * 3, sizeof(double));
        d->device_force = rt_calloc(rt, nf * 3, sizeof(double));
        d->normal = rt_calloc(rt, nf * 3, sizeof(double));
        d->patch = rt_calloc(rt, nf * 2 * GC_FINGER_PATCH_CORNERS, sizeof(float));
        d->state = rt_calloc(rt, nf, sizeof(int32_t));
        d->contact_body = rt_calloc(rt, nf, sizeof(int32_t));
        ok &= in->hips && in->orientations && h->want && h->has_state && h->body && h->fingers && o->released && o->body && d->body &&
              d->adopted && d->hip && d->god_object && d->spring_force && d->device_force && d->normal && d->patch && d->state &&
              d->contact_body;
    }
    if (!ok) {
        runtime_free_memory(rt);
        return NULL;
    }
    if (pthread_mutex_init(&rt->input_mutex, NULL) != 0) {
        runtime_free_memory(rt);
        return NULL;
    }
    if (pthread_mutex_init(&rt->api_mutex, NULL) != 0) {
        pthread_mutex_destroy(&rt->input_mutex);
        runtime_free_memory(rt);
        return NULL;
    }
    return rt;
}

/* ---- public API --------------------------------------------------------------------- */

gcRuntimeDef gc_default_runtime_def(void) {
    gcRuntimeDef def;
    memset(&def, 0, sizeof def);
    def.haptic_rate = 1000.0;
    def.object_rate = 500.0;
    def.max_adopted_bodies = 3;
    def.release_delay = 0.05;
    def.max_force = 10.0;
    def.ramp_time = 0.5;
    def.watchdog_timeout = 0.005;
    def.hip_timeout = 0.1;
    def.realtime = 1;
    def.priority = 80;
    def.max_hip_speed = 0.0;
    return def;
}


int gc_world_running(const gcWorld *w) { return gc_runtime_running(w); }

static gcStatus check_def(const gcWorld *w, const gcRuntimeDef *d) {
    const char *bad = NULL;
    if (!isfinite(d->haptic_rate) || d->haptic_rate < 10.0 || d->haptic_rate > 20000.0)
        bad = "haptic_rate: must be in [10, 20000] Hz";
    else if (!isfinite(d->object_rate) || !(d->object_rate > 0.0) || d->object_rate > d->haptic_rate)
        bad = "object_rate: must be > 0 and <= haptic_rate";
    else if (d->max_adopted_bodies < 0)
        bad = "max_adopted_bodies: must be >= 0";
    else if (!isfinite(d->release_delay) || d->release_delay < 0.0)
        bad = "release_delay: must be a finite number >= 0";
    else if (!isfinite(d->max_force) || d->max_force < 0.0)
        bad = "max_force: must be a finite number >= 0";
    else if (!isfinite(d->ramp_time) || d->ramp_time < 0.0)
        bad = "ramp_time: must be a finite number >= 0";
    else if (!isfinite(d->watchdog_timeout) || !(d->watchdog_timeout > 1.0 / d->haptic_rate))
        bad = "watchdog_timeout: must be longer than one haptic period";
    else if (!isfinite(d->hip_timeout) || !(d->hip_timeout > 0.0))
        bad = "hip_timeout: must be a finite number > 0";
    else if (!isfinite(d->max_hip_speed) || d->max_hip_speed < 0.0)
        bad = "max_hip_speed: must be a finite number >= 0 (0 = unbounded)";
    else if (d->priority < 0 || d->priority > 99)
        bad = "priority: must be 0 (normal) or a SCHED_FIFO priority 1..99";
    if (bad) {
        gc_world_set_error(w, "%s", bad);
        return GC_ERR_INVALID_ARGUMENT;
    }
    return GC_OK;
}

static void reset_stats(gcRuntime *rt) {
    _Atomic uint64_t *counters[] = {&rt->haptic_ticks,    &rt->object_ticks,    &rt->overruns,
                                    &rt->late_periods,    &rt->object_overruns, &rt->accepted_inputs,
                                    &rt->rejected_inputs, &rt->watchdog_trips,  &rt->stale_inputs,
                                    &rt->nonfinite_forces, &rt->stopped_bodies};
    for (size_t i = 0; i < sizeof counters / sizeof counters[0]; ++i) atomic_store(counters[i], 0);
    atomic_store(&rt->adopted, 0);
    atomic_store(&rt->forces_enabled, 0);
    atomic_store(&rt->first_tick_ns, GC_NEVER_NS);
    atomic_store(&rt->last_tick_ns, GC_NEVER_NS);
    atomic_store(&rt->first_object_ns, GC_NEVER_NS);
    atomic_store(&rt->last_object_ns, GC_NEVER_NS);
    atomic_store(&rt->jitter_max_ns, 0);
    atomic_store(&rt->tick_max_ns, 0);
    atomic_store(&rt->tick_sum_ns, 0);
    atomic_store(&rt->wake_max_ns, 0);
    for (int i = 0; i < GC_JITTER_BINS; ++i) atomic_store_explicit(&rt->jitter_hist[i], 0, memory_order_relaxed);
}

/* The runtime loaded for a session from the world and def: rates, both shadows, every body with
 * the object manager, the gate, the HIP followers, zeroed statistics. */
static void load_session(gcWorld *w, gcRuntime *rt, const gcRuntimeDef *def) {
    rt->def = *def;
    rt->def.realtime = def->realtime != 0;
    rt->period_ns = gc_seconds_to_ns(1.0 / def->haptic_rate);
    rt->object_period_ns = gc_seconds_to_ns(1.0 / def->object_rate);
    rt->watchdog_ns = gc_seconds_to_ns(def->watchdog_timeout);
    rt->hip_timeout_ns = gc_seconds_to_ns(def->hip_timeout);
    rt->ramp_ns = gc_seconds_to_ns(def->ramp_time);
    rt->dt_haptic = 1.0 / def->haptic_rate;
    double object_period = 1.0 / def->object_rate;
    rt->object_substeps = (int)ceil(object_period / GC_OBJECT_MAX_STEP - 1e-9);
    if (rt->object_substeps < 1) rt->object_substeps = 1;
    rt->dt_object = object_period / rt->object_substeps;

    /* Both shadows start from the world; every dynamic body belongs to the object manager. */
    shadow_load(&rt->hap, w);
    shadow_load(&rt->obj, w);
    for (int32_t b = 0; b < w->num_bodies; ++b) {
        rt->hstate[b] = GC_HAPTIC_OM_OWNS;
        rt->ostate[b] = GC_OBJECT_OWNS;
        rt->hap_active[b] = 0;
        rt->obj_active[b] = 1;
        rt->last_touch[b] = -INFINITY;
    }
    memset(rt->device_force, 0, (size_t)rt->max_fingers * 3 * sizeof(double));
    rt->object_time_seen = w->time;
    rt->object_seq = rt->object_seq_seen = rt->object_reads = 0;
    rt->replaying = 0;
    rt->prev_tick_ns = rt->last_input_ns = GC_NEVER_NS;
    gc_force_gate_init(&rt->gate, rt->ramp_ns, 1);
    rt->hub->ramp_ns = rt->ramp_ns; /* devices read elsewhere ramp in as long (gc_world_device_forces) */
    memset(rt->device_finger, 0, (size_t)rt->max_fingers * sizeof *rt->device_finger);
    rt->was_stale = 1;
    rt->tick = 0;
    rt->object_phase = 0.0;
    rt->input_last_t = -INFINITY;
    rt->follow_prev_t = -INFINITY;
    rt->track = w->hip_track;
    for (int i = 0; i < w->num_fingers; ++i) /* standing still where they are */
        gc_hip_follow_retarget(&rt->follow[i], w->fingers[i].hip, w->fingers[i].hip, 0.0, rt->dt_haptic);
    atomic_store(&rt->manual_now_ns, 0);
    atomic_store(&rt->debug_stall_ns, 0);
    reset_stats(rt);
    atomic_store(&w->hub->rejected_inputs, 0);
}

/* The haptic and object threads of a realtime session, started once the runtime is loaded; the
 * world unlocked again when they cannot be made. */
static gcStatus start_threads(gcWorld *w, gcRuntime *rt) {
    lock_memory(rt);
    atomic_store_explicit(&rt->haptic_ready, 0, memory_order_relaxed);
    atomic_store_explicit(&rt->run, 1, memory_order_release);
    atomic_store_explicit(&rt->state, GC_RUNTIME_RUNNING, memory_order_release);
    int e = pthread_create(&rt->object_thread, NULL, gc_runtime_object_main, rt);
    if (e == 0) {
#ifdef __linux__
        pthread_setname_np(rt->object_thread, "gc-object"); /* as top -H, perf and ftrace show it */
#endif
        e = pthread_create(&rt->haptic_thread, NULL, gc_runtime_haptic_main, rt);
        if (e != 0) {
            atomic_store_explicit(&rt->run, 0, memory_order_release);
            pthread_join(rt->object_thread, NULL);
        }
    }
    if (e != 0) {
        unlock_memory(rt);
        atomic_store_explicit(&rt->state, GC_RUNTIME_STOPPED, memory_order_release);
        w->locked = 0;
        w->shown = NULL;
        gc_world_set_error(w, "runtime: could not create its threads (error %d)", e);
        return GC_ERR_NO_MEMORY;
    }
    /* The haptic thread sets up its own scheduling before its first tick; wait for its note
     * (microseconds), so that stats() is complete as soon as start() returns. */
    while (!atomic_load_explicit(&rt->haptic_ready, memory_order_acquire)) {
        struct timespec ts = {0, 20000};
        nanosleep(&ts, NULL);
    }
    return GC_OK;
}

gcStatus gc_world_start(gcWorld *w, const gcRuntimeDef *def) {
    if (!w) return GC_ERR_INVALID_ARGUMENT;
    if (!def) return gc_null_argument(w, "def");
    if (gc_runtime_running(w)) {
        gc_world_set_error(w, "the runtime is already running");
        return GC_ERR_BUSY;
    }
    gcStatus st = check_def(w, def);
    if (st) return st;
    if (!w->runtime && !(w->runtime = runtime_alloc(w))) {
        gc_world_set_error(w, "runtime: out of memory");
        return GC_ERR_NO_MEMORY;
    }
    gcRuntime *rt = w->runtime;
    pthread_mutex_lock(&rt->api_mutex);
    w->locked = 1;
    /* Until the first snapshot the world's queries show the state it started from. */
    rt->shown.time = w->time;
    for (int32_t b = 0; b < w->num_bodies; ++b) rt->shown.bodies[b] = w->bodies[b].state;
    memcpy(rt->shown.fingers, w->fingers, (size_t)w->num_fingers * sizeof *w->fingers);
    w->shown = &rt->shown;
    load_session(w, rt, def);
    rt->tick_log = gc_tick_log_begin(w, &st);
    if (st) { /* the world as it was: unlocked, its own state shown */
        w->locked = 0;
        w->shown = NULL;
        pthread_mutex_unlock(&rt->api_mutex);
        return st;
    }
    gc_atomic_store_double(&rt->haptic_time_bits, w->time);
    gc_atomic_store_double(&rt->object_time_bits, w->time);
    gc_atomic_store_double(&rt->object_time0_bits, w->time);

    /* First publications, so that every reader starts from a complete message. */
    gc_triple_reset(&rt->input);
    gc_triple_reset(&rt->to_object);
    gc_triple_reset(&rt->to_haptic);
    gc_triple_reset(&rt->display);
    gc_runtime_publish_to_object(rt);
    gc_runtime_publish_to_haptic(rt);
    gc_runtime_publish_display(rt, 0, 0);
    int fresh;
    (void)gc_triple_latest(&rt->to_haptic, &fresh); /* the haptic shadow already holds these bodies */

    rt->rt_priority = 0;
    rt->start_ns = gc_clock_now_ns();
    rt->stop_ns = GC_NEVER_NS;
    if (!rt->def.realtime) {
        snprintf(rt->priority_note, sizeof rt->priority_note, "manual clock (realtime=0): no threads");
        atomic_store_explicit(&rt->state, GC_RUNTIME_RUNNING, memory_order_release);
        pthread_mutex_unlock(&rt->api_mutex);
        return GC_OK;
    }
    if ((st = start_threads(w, rt)) != GC_OK) {
        pthread_mutex_unlock(&rt->api_mutex);
        return st;
    }
    snprintf(rt->priority_note, sizeof rt->priority_note, "%s; %s", rt->thread_note, rt->memory_note);
    pthread_mutex_unlock(&rt->api_mutex);
    return GC_OK;
}

gcStatus gc_world_stop(gcWorld *w) {
    if (!w) return GC_ERR_INVALID_ARGUMENT;
    gcRuntime *rt = w->runtime;
    if (!rt) return GC_OK;
    pthread_mutex_lock(&rt->api_mutex);
    if (atomic_load_explicit(&rt->state, memory_order_acquire) != GC_RUNTIME_RUNNING) {
        pthread_mutex_unlock(&rt->api_mutex);
        return GC_OK;
    }
    if (rt->def.realtime) {
        atomic_store_explicit(&rt->run, 0, memory_order_release);
        pthread_join(rt->haptic_thread, NULL);
        pthread_join(rt->object_thread, NULL);
        unlock_memory(rt);
    }
    rt->stop_ns = gc_clock_now_ns();
    gc_runtime_merge_into_world(rt, w);
    atomic_store_explicit(&rt->state, GC_RUNTIME_STOPPED, memory_order_release);
    w->locked = 0;
    w->shown = NULL;
    pthread_mutex_unlock(&rt->api_mutex);
    return GC_OK;
}

gcStatus gc_world_advance(gcWorld *w, int ticks, double delay) {
    if (!w) return GC_ERR_INVALID_ARGUMENT;
    gcRuntime *rt = w->runtime;
    if (!gc_runtime_running(w)) {
        gc_world_set_error(w, "advance: the runtime is not running (start it with realtime=0)");
        return GC_ERR_NOT_RUNNING;
    }
    if (rt->def.realtime) {
        gc_world_set_error(w, "advance: the runtime runs on the real-time clock; start it with realtime=0");
        return GC_ERR_BUSY;
    }
    if (ticks < 0) {
        gc_world_set_error(w, "ticks: must be >= 0 (got %d)", ticks);
        return GC_ERR_INVALID_ARGUMENT;
    }
    if (!isfinite(delay) || delay < 0.0 || delay > 3600.0) {
        gc_world_set_error(w, "delay: must be a finite number of seconds in [0, 3600] (got %g)", delay);
        return GC_ERR_INVALID_ARGUMENT;
    }
    pthread_mutex_lock(&rt->api_mutex);
    for (int k = 0; k < ticks; ++k) {
        int64_t period = rt->period_ns + (k == 0 ? gc_seconds_to_ns(delay) : 0);
        int64_t now = atomic_load_explicit(&rt->manual_now_ns, memory_order_relaxed) + period;
        atomic_store_explicit(&rt->manual_now_ns, now, memory_order_relaxed);
        if (rt->tick == 0)
            atomic_store_explicit(&rt->first_tick_ns, now, memory_order_relaxed);
        else
            gc_runtime_record_period(rt, period);
        gc_runtime_haptic_tick(rt, now);
        atomic_store_explicit(&rt->last_tick_ns, now, memory_order_relaxed);
        /* The object manager's ticks fall on a fixed schedule of the haptic ticks. */
        rt->object_phase += rt->def.object_rate;
        if (rt->object_phase >= rt->def.haptic_rate) {
            rt->object_phase -= rt->def.haptic_rate;
            if (atomic_load_explicit(&rt->object_ticks, memory_order_relaxed) == 0)
                atomic_store_explicit(&rt->first_object_ns, now, memory_order_relaxed);
            gc_runtime_object_tick(rt);
            atomic_store_explicit(&rt->last_object_ns, now, memory_order_relaxed);
        }
    }
    pthread_mutex_unlock(&rt->api_mutex);
    return GC_OK;
}

void gc_runtime_free(gcWorld *w) {
    if (!w || !w->runtime) return;
    gc_world_stop(w);
    pthread_mutex_destroy(&w->runtime->api_mutex);
    pthread_mutex_destroy(&w->runtime->input_mutex);
    runtime_free_memory(w->runtime);
    w->runtime = NULL;
}

