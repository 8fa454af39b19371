/* The runtime's two loops: clocks, deadlines, scheduling and the statistics they keep
 * (runtime_internal.h, docs/runtime.md "Getting on time"). */
#define _GNU_SOURCE
#include "runtime_internal.h"

/* ---- threads ------------------------------------------------------------------------ */

void gc_runtime_record_period(gcRuntime *rt, int64_t period) {
    int64_t err = period - rt->period_ns;
    if (err < 0) err = -err;
    int64_t bin = err / 1000;
    if (bin >= GC_JITTER_BINS) bin = GC_JITTER_BINS - 1;
    atomic_fetch_add_explicit(&rt->jitter_hist[bin], 1, memory_order_relaxed);
    if (err > atomic_load_explicit(&rt->jitter_max_ns, memory_order_relaxed))
        atomic_store_explicit(&rt->jitter_max_ns, err, memory_order_relaxed);
    if (err > rt->period_ns) gc_atomic_increment(&rt->late_periods);
}

/* Next absolute deadline after a tick that ended at `end`: deadlines already missed are
 * skipped (counted as an overrun), never run back to back to catch up. */
static int64_t next_deadline(int64_t deadline, int64_t period, int64_t end, _Atomic uint64_t *overruns) {
    deadline += period;
    if (end > deadline) {
        gc_atomic_increment(overruns);
        deadline += ((end - deadline) / period + 1) * period;
    }
    return deadline;
}

static void record_max(_Atomic int64_t *slot, int64_t v) {
    if (v > atomic_load_explicit(slot, memory_order_relaxed)) atomic_store_explicit(slot, v, memory_order_relaxed);
}

#ifdef __linux__
/* struct sched_attr as the kernel reads it (SCHED_ATTR_SIZE_VER0); glibc 2.36 has no wrapper. */
typedef struct gcSchedAttr {
    uint32_t size, policy;
    uint64_t flags;
    int32_t nice;
    uint32_t priority;
    uint64_t runtime, deadline, period;
} gcSchedAttr;

/* At normal priority: ask for a GC_HAPTIC_SLICE_NS time slice. Since Linux 6.12 (EEVDF) a
 * waking task with a shorter slice than the running one preempts it sooner; the nice level
 * and so the thread's share of the CPU are unchanged, and no privilege is needed. Returns 1
 * when the kernel took it (read back; older kernels ignore the field). */
static int request_short_slice(void) {
    gcSchedAttr a;
    memset(&a, 0, sizeof a);
    if (syscall(SYS_sched_getattr, 0, &a, sizeof a, 0) != 0 || a.policy != SCHED_OTHER) return 0;
    a.size = sizeof a;
    a.flags &= 1; /* SCHED_FLAG_RESET_ON_FORK */
    a.runtime = GC_HAPTIC_SLICE_NS;
    a.deadline = a.period = 0;
    if (syscall(SYS_sched_setattr, 0, &a, 0) != 0) return 0;
    memset(&a, 0, sizeof a);
    return syscall(SYS_sched_getattr, 0, &a, sizeof a, 0) == 0 && a.runtime == GC_HAPTIC_SLICE_NS;
}
#endif

/* Touches the next GC_HAPTIC_STACK_PREFAULT bytes of stack below the caller's frame, so that
 * no tick faults a stack page in. */
__attribute__((noinline)) static void prefault_stack(void) {
    volatile unsigned char pad[GC_HAPTIC_STACK_PREFAULT];
    for (size_t i = 0; i < sizeof pad; i += 4096) pad[i] = 0;
    pad[sizeof pad - 1] = 0;
}

/* The haptic thread's own scheduling, before its first tick (docs/runtime.md "Getting on
 * time"): SCHED_FIFO when asked for and granted, else normal priority with a short time
 * slice; timer slack 1 ns (the kernel's default of 50 us for normal threads lets a wake-up
 * drift that late); its stack pre-faulted, and locked when the runtime's memory is.
 * Returns the locked stack window's start (or NULL). */
static void *haptic_thread_setup(gcRuntime *rt, size_t *stack_locked) {
    const int prio = rt->def.priority;
    int fifo = 0;
    char *note = rt->thread_note;
    const size_t cap = sizeof rt->thread_note;
    if (prio > 0) {
        struct sched_param sp;
        memset(&sp, 0, sizeof sp);
        sp.sched_priority = prio;
        int e = pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp);
        fifo = e == 0;
        if (fifo)
            snprintf(note, cap, "haptic loop at SCHED_FIFO %d", prio);
        else
            snprintf(note, cap, "SCHED_FIFO %d refused (%s): haptic loop at normal priority", prio,
                     e == EPERM ? "not permitted" : e == EINVAL ? "invalid" : "error");
    } else {
        snprintf(note, cap, "normal priority (priority=0)");
    }
    rt->rt_priority = fifo;
    void *window = NULL;
    *stack_locked = 0;
#ifdef __linux__
    pthread_setname_np(pthread_self(), "gc-haptic"); /* as top -H, perf and ftrace show it */
    prctl(PR_SET_TIMERSLACK, 1UL, 0UL, 0UL, 0UL); /* 0 would mean "back to the default" */
    if (!fifo) {
        size_t n = strlen(note);
        snprintf(note + n, cap - n, "%s", request_short_slice() ? ", 0.1 ms slice" : ", default slice");
    }
#endif
    prefault_stack();
#ifdef __linux__
    if (rt->locked_bytes) {
        const uintptr_t page = 4096;
        char probe;
        uintptr_t top = ((uintptr_t)&probe & ~(page - 1)) + page;
        window = (void *)(top - GC_HAPTIC_STACK_PREFAULT - page);
        if (mlock(window, GC_HAPTIC_STACK_PREFAULT + page) == 0)
            *stack_locked = GC_HAPTIC_STACK_PREFAULT + page;
        else
            window = NULL;
    }
#endif
    return window;
}

void *gc_runtime_haptic_main(void *arg) {
    gcRuntime *rt = arg;
    size_t stack_locked;
    void *stack_window = haptic_thread_setup(rt, &stack_locked);
    atomic_store_explicit(&rt->haptic_ready, 1, memory_order_release);
    int64_t deadline = gc_clock_now_ns() + rt->period_ns, prev_wake = GC_NEVER_NS;
    while (atomic_load_explicit(&rt->run, memory_order_acquire)) {
        int64_t stall = atomic_exchange_explicit(&rt->debug_stall_ns, 0, memory_order_relaxed);
        gc_sleep_until_ns(deadline + stall);
        int64_t wake = gc_clock_now_ns();
        record_max(&rt->wake_max_ns, wake - deadline);
        if (prev_wake == GC_NEVER_NS)
            atomic_store_explicit(&rt->first_tick_ns, wake, memory_order_relaxed);
        else
            gc_runtime_record_period(rt, wake - prev_wake);
        prev_wake = wake;
        gc_runtime_haptic_tick(rt, wake);
        int64_t end = gc_clock_now_ns();
        record_max(&rt->tick_max_ns, end - wake);
        atomic_fetch_add_explicit(&rt->tick_sum_ns, end - wake, memory_order_relaxed);
        atomic_store_explicit(&rt->last_tick_ns, wake, memory_order_relaxed);
        deadline = next_deadline(deadline, rt->period_ns, end, &rt->overruns);
    }
#ifdef __linux__
    if (stack_window) munlock(stack_window, stack_locked);
#else
    (void)stack_window;
#endif
    return NULL;
}

void *gc_runtime_object_main(void *arg) {
    gcRuntime *rt = arg; /* named "gc-object" by gc_world_start, before it returns */
    int64_t deadline = gc_clock_now_ns() + rt->object_period_ns;
    int first = 1;
    while (atomic_load_explicit(&rt->run, memory_order_acquire)) {
        gc_sleep_until_ns(deadline);
        int64_t wake = gc_clock_now_ns();
        if (first) atomic_store_explicit(&rt->first_object_ns, wake, memory_order_relaxed);
        first = 0;
        gc_runtime_object_tick(rt);
        int64_t end = gc_clock_now_ns();
        atomic_store_explicit(&rt->last_object_ns, wake, memory_order_relaxed);
        deadline = next_deadline(deadline, rt->object_period_ns, end, &rt->object_overruns);
    }
    return NULL;
}

static double percentile_us(const uint32_t *hist, uint64_t total, double q) {
    if (total == 0) return 0.0;
    uint64_t target = (uint64_t)ceil(q * (double)total), sum = 0;
    if (target < 1) target = 1;
    for (int i = 0; i < GC_JITTER_BINS; ++i) {
        sum += hist[i];
        if (sum >= target) return (double)(i + 1); /* upper edge of the 1 us bin */
    }
    return (double)GC_JITTER_BINS;
}

gcStatus gc_world_stats(gcWorld *w, gcRuntimeStats *out) {
    if (!w) return GC_ERR_INVALID_ARGUMENT;
    if (!out) return gc_null_argument(w, "stats");
    memset(out, 0, sizeof *out);
    gcRuntime *rt = w->runtime;
    if (!rt) {
        snprintf(out->priority_note, sizeof out->priority_note, "never started");
        out->haptic_time = out->object_time = w->time;
        return GC_OK;
    }
    pthread_mutex_lock(&rt->api_mutex);
    int running = atomic_load_explicit(&rt->state, memory_order_acquire) == GC_RUNTIME_RUNNING;
    out->running = running;
    out->realtime = rt->def.realtime;
    out->rt_priority = rt->rt_priority;
    snprintf(out->priority_note, sizeof out->priority_note, "%s", rt->priority_note);
    out->haptic_ticks = atomic_load_explicit(&rt->haptic_ticks, memory_order_relaxed);
    out->object_ticks = atomic_load_explicit(&rt->object_ticks, memory_order_relaxed);
    out->overruns = atomic_load_explicit(&rt->overruns, memory_order_relaxed);
    out->late_periods = atomic_load_explicit(&rt->late_periods, memory_order_relaxed);
    out->object_overruns = atomic_load_explicit(&rt->object_overruns, memory_order_relaxed);
    out->accepted_inputs = atomic_load_explicit(&rt->accepted_inputs, memory_order_relaxed);
    out->rejected_inputs = atomic_load_explicit(&rt->rejected_inputs, memory_order_relaxed) +
                           atomic_load_explicit(&w->hub->rejected_inputs, memory_order_relaxed);
    out->watchdog_trips = atomic_load_explicit(&rt->watchdog_trips, memory_order_relaxed);
    out->stale_inputs = atomic_load_explicit(&rt->stale_inputs, memory_order_relaxed);
    out->nonfinite_forces = atomic_load_explicit(&rt->nonfinite_forces, memory_order_relaxed);
    out->stopped_bodies = atomic_load_explicit(&rt->stopped_bodies, memory_order_relaxed);
    out->adopted_bodies = atomic_load_explicit(&rt->adopted, memory_order_relaxed);
    out->forces_enabled = running && atomic_load_explicit(&rt->forces_enabled, memory_order_relaxed);
    out->haptic_time = gc_atomic_load_double(&rt->haptic_time_bits);
    out->object_time = gc_atomic_load_double(&rt->object_time_bits);

    /* Achieved rates over the run (on the manual clock, per simulated second). */
    int64_t t0 = atomic_load_explicit(&rt->first_tick_ns, memory_order_relaxed);
    int64_t t1 = atomic_load_explicit(&rt->last_tick_ns, memory_order_relaxed);
    if (out->haptic_ticks > 1 && t0 != GC_NEVER_NS && t1 > t0)
        out->haptic_rate = (double)(out->haptic_ticks - 1) * 1e9 / (double)(t1 - t0);
    t0 = atomic_load_explicit(&rt->first_object_ns, memory_order_relaxed);
    t1 = atomic_load_explicit(&rt->last_object_ns, memory_order_relaxed);
    if (out->object_ticks > 1 && t0 != GC_NEVER_NS && t1 > t0)
        out->object_rate = (double)(out->object_ticks - 1) * 1e9 / (double)(t1 - t0);
    double wall;
    if (rt->def.realtime)
        wall = (double)((running ? gc_clock_now_ns() : rt->stop_ns) - rt->start_ns) * 1e-9;
    else
        wall = (double)atomic_load_explicit(&rt->manual_now_ns, memory_order_relaxed) * 1e-9;
    if (wall > 0.0) out->object_speed = (out->object_time - gc_atomic_load_double(&rt->object_time0_bits)) / wall;

    uint32_t *hist = rt->stats_hist;
    uint64_t total = 0;
    for (int i = 0; i < GC_JITTER_BINS; ++i) {
        hist[i] = atomic_load_explicit(&rt->jitter_hist[i], memory_order_relaxed);
        total += hist[i];
    }
    out->jitter_max_us = (double)atomic_load_explicit(&rt->jitter_max_ns, memory_order_relaxed) * 1e-3;
    out->tick_max_us = (double)atomic_load_explicit(&rt->tick_max_ns, memory_order_relaxed) * 1e-3;
    uint64_t ticks_done = atomic_load_explicit(&rt->haptic_ticks, memory_order_relaxed);
    out->tick_mean_us = ticks_done ? (double)atomic_load_explicit(&rt->tick_sum_ns, memory_order_relaxed) * 1e-3 / (double)ticks_done : 0.0;
    out->wake_max_us = (double)atomic_load_explicit(&rt->wake_max_ns, memory_order_relaxed) * 1e-3;
    out->jitter_p50_us = fmin(percentile_us(hist, total, 0.50), out->jitter_max_us);
    out->jitter_p99_us = fmin(percentile_us(hist, total, 0.99), out->jitter_max_us);
    pthread_mutex_unlock(&rt->api_mutex);
    return GC_OK;
}

gcStatus gc_world_debug_stall(gcWorld *w, double seconds) {
    if (!w) return GC_ERR_INVALID_ARGUMENT;
    if (!gc_runtime_running(w)) {
        gc_world_set_error(w, "debug_stall: the runtime is not running");
        return GC_ERR_NOT_RUNNING;
    }
    if (!isfinite(seconds) || seconds < 0.0 || seconds > 10.0) {
        gc_world_set_error(w, "seconds: must be in [0, 10] (got %g)", seconds);
        return GC_ERR_INVALID_ARGUMENT;
    }
    atomic_store_explicit(&w->runtime->debug_stall_ns, gc_seconds_to_ns(seconds), memory_order_relaxed);
    return GC_OK;
}

