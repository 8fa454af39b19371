/* Replaying a threaded session on the manual clock (docs/runtime.md "Replaying a recorded
 * schedule", docs/recording-format.md): its recorded HIPs, and the object manager's ticks run
 * and their results handed to the haptic loop at the ticks the recording says, so that each
 * tick's state is the recorded one bit for bit. The real threads interleave freely; what a
 * haptic tick computes depends only on the object result it took, and what an object tick
 * computes only on the haptic message it read, so this order reproduces theirs: before haptic
 * tick t, the object ticks that read a message older than t's (object_reads), their results
 * held in a queue until the tick that took them (object_tick). */
#define _GNU_SOURCE
#include "runtime_internal.h"
#include "tick_log.h"

void gc_runtime_replay_free(gcRuntime *rt) {
    if (!rt->replay_queue) return;
    for (int i = 0; i < GC_REPLAY_QUEUE; ++i) {
        free(rt->replay_queue[i].released);
        free(rt->replay_queue[i].body);
    }
    free(rt->replay_queue);
    rt->replay_queue = NULL;
}

/* Once per runtime, before the first replayed tick (never inside one). */
static int replay_queue_alloc(gcRuntime *rt) {
    if (rt->replay_queue) return 1;
    rt->replay_queue = calloc(GC_REPLAY_QUEUE, sizeof *rt->replay_queue);
    if (!rt->replay_queue) return 0;
    for (int i = 0; i < GC_REPLAY_QUEUE; ++i) {
        rt->replay_queue[i].released = calloc((size_t)rt->max_bodies, 1);
        rt->replay_queue[i].body = calloc((size_t)rt->max_bodies, sizeof(gcRuntimeBody));
        if (!rt->replay_queue[i].released || !rt->replay_queue[i].body) {
            gc_runtime_replay_free(rt);
            return 0;
        }
    }
    return 1;
}

/* The schedule at one tick, against where the replay is: NULL when it can be replayed, else why. */
static const char *schedule_fault(const gcRuntime *rt, uint64_t object_tick, uint64_t object_reads) {
    if (object_reads < rt->object_seq) return "object_reads goes back";
    if (object_tick < rt->object_seq_seen) return "object_tick goes back";
    if (object_tick > object_reads) return "object_tick is a result no object tick had made yet";
    if (object_reads - object_tick >= GC_REPLAY_QUEUE) return "more object results in flight than a replay holds";
    return NULL;
}

gcStatus gc_world_replay_ticks(gcWorld *w, const double *hips, const double *orientations, int num_fingers,
                               const uint64_t *object_ticks, const uint64_t *object_reads, int steps, void *records,
                               size_t size, int *done) {
    if (done) *done = 0;
    if (!w) return GC_ERR_INVALID_ARGUMENT;
    gcRuntime *rt = w->runtime;
    if (!gc_runtime_running(w) || rt->def.realtime) {
        gc_world_set_error(w, "replay_ticks: needs the runtime on the manual clock (start it with realtime=0)");
        return gc_runtime_running(w) ? GC_ERR_BUSY : GC_ERR_NOT_RUNNING;
    }
    if (steps < 0 || num_fingers != w->num_fingers || (steps > 0 && ((!hips && num_fingers > 0) || !object_ticks ||
                                                                     !object_reads))) {
        gc_world_set_error(w, "steps: %d steps of HIPs for %d fingers (the world has %d) and their schedule", steps,
                           num_fingers, (int)w->num_fingers);
        return GC_ERR_INVALID_ARGUMENT;
    }
    size_t record = gc_tick_record_size(w->num_bodies, w->num_fingers);
    if (records && size / record < (size_t)steps) {
        gc_world_set_error(w, "records: %zu bytes for %d records of %zu", size, steps, record);
        return GC_ERR_INVALID_ARGUMENT;
    }
    if (!replay_queue_alloc(rt)) {
        gc_world_set_error(w, "replay_ticks: out of memory");
        return GC_ERR_NO_MEMORY;
    }
    pthread_mutex_lock(&rt->api_mutex);
    gcStatus st = GC_OK;
    rt->replaying = 1;
    for (int k = 0; k < steps; ++k) {
        const char *fault = schedule_fault(rt, object_ticks[k], object_reads[k]);
        if (fault) {
            gc_world_set_error(w, "object_ticks, object_reads: at step %d (tick %llu): %s (object tick %llu, "
                               "reads %llu; replayed so far: %llu object ticks, result %llu held)",
                               k, (unsigned long long)(rt->tick + 1), fault, (unsigned long long)object_ticks[k],
                               (unsigned long long)object_reads[k], (unsigned long long)rt->object_seq,
                               (unsigned long long)rt->object_seq_seen);
            st = GC_ERR_INVALID_ARGUMENT;
            break;
        }
        /* The object ticks that took a message before this tick publishes its own. */
        while (rt->object_seq < object_reads[k]) gc_runtime_object_tick(rt);
        if (object_ticks[k] > rt->object_seq_seen)
            gc_runtime_deliver_to_haptic(rt, &rt->replay_queue[object_ticks[k] % GC_REPLAY_QUEUE]);
        rt->replay_hips = hips + 3 * (size_t)num_fingers * (size_t)k;
        rt->replay_orientations = orientations ? orientations + 4 * (size_t)num_fingers * (size_t)k : NULL;
        rt->replay_record = records ? (char *)records + record * (size_t)k : NULL;
        int64_t now = atomic_load_explicit(&rt->manual_now_ns, memory_order_relaxed) + rt->period_ns;
        atomic_store_explicit(&rt->manual_now_ns, now, memory_order_relaxed);
        gc_runtime_haptic_tick(rt, now);
        atomic_store_explicit(&rt->last_tick_ns, now, memory_order_relaxed);
        if (done) *done = k + 1;
    }
    rt->replaying = 0;
    rt->replay_hips = rt->replay_orientations = NULL;
    rt->replay_record = NULL;
    pthread_mutex_unlock(&rt->api_mutex);
    return st;
}
