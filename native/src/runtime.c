/* The real-time runtime (docs/runtime.md, DESIGN.md §2 "Threads").
 *
 * gc_world_start() hands the world's dynamic state to two threads:
 *   - the haptic loop (default 1 kHz, absolute deadlines on CLOCK_MONOTONIC, SCHED_FIFO when
 *     the OS allows): latest HIPs in, god-objects and finger springs (xFCA), the bodies it
 *     has adopted stepped at its rate, device forces out through the safety stage;
 *   - the object manager (default 500 Hz, normal priority): every other dynamic body, in
 *     steps of at most 2 ms; when a tick takes too long it falls behind real time instead
 *     of taking larger steps.
 * Each thread steps its own *shadow* of the world: a gcWorld whose body and finger arrays are
 * private to the thread and whose read-only parts (hulls) are shared. A mask (body_active)
 * tells the dynamics which bodies the shadow moves. Nothing is locked between the threads:
 * every channel is a triple buffer (latest value, wait-free on both sides, C11 atomics):
 *   input   push_hips() -> haptic       latest HIPs (producers serialise among themselves)
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
#define _GNU_SOURCE /* Linux: prctl, sched_setattr, mlock */

#include "runtime.h"

#include "contacts.h"
#include "hip_input.h"
#include "step.h"

#include <errno.h>
#include <pthread.h>
#include <sched.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#ifdef __linux__
#include <sys/mman.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>
#endif

#define NS_PER_S 1000000000LL
/* The object manager's step cap (DESIGN.md §2: the chapter's "0.002 ms" is a typo for 2 ms). */
#define GC_OBJECT_MAX_STEP 0.002
/* Period-error histogram of the haptic loop: 1 us bins, the last one collects the rest. */
#define GC_JITTER_BINS 20000
#define NEVER INT64_MIN
/* The haptic loop's wait (docs/runtime.md "Getting on time"): the scheduler time slice it
 * asks for at normal priority (Linux >= 6.12; the kernel's minimum), the stack it touches
 * before its first tick, and the most runtime memory it locks in RAM. */
#define GC_HAPTIC_SLICE_NS 100000
#define GC_HAPTIC_STACK_PREFAULT (64 * 1024)
#define GC_LOCK_BUDGET (64u << 20)
#define GC_MAX_REGIONS 96

/* ---- triple buffer: the latest value from one writer to one reader ------------------ */

/* Three slots of a message: the writer fills `back`, then swaps it with `middle`; the
 * reader swaps `front` with `middle` when `middle` holds something new. Neither side ever
 * waits, and the reader always holds a complete message. */
typedef struct gcTriple {
    _Atomic unsigned middle; /* slot index | GC_TRIPLE_FRESH while unread */
    unsigned back;           /* writer's slot */
    unsigned front;          /* reader's slot */
} gcTriple;
#define GC_TRIPLE_FRESH 4u

static void triple_reset(gcTriple *t) {
    t->back = 0;
    t->front = 1;
    atomic_store_explicit(&t->middle, 2u, memory_order_relaxed);
}

static void triple_publish(gcTriple *t) {
    t->back = atomic_exchange_explicit(&t->middle, t->back | GC_TRIPLE_FRESH, memory_order_acq_rel) & 3u;
}

/* The reader's slot, now holding the latest publication; *fresh = 1 when it is new. */
static unsigned triple_latest(gcTriple *t, int *fresh) {
    *fresh = 0;
    if (atomic_load_explicit(&t->middle, memory_order_relaxed) & GC_TRIPLE_FRESH) {
        t->front = atomic_exchange_explicit(&t->middle, t->front, memory_order_acq_rel) & 3u;
        *fresh = 1;
    }
    return t->front;
}

/* ---- messages --------------------------------------------------------------------- */

/* A body's dynamic state, exactly (no re-derivation), so that a hand-over changes no bit. */
typedef struct gcRtBody {
    gcBodyState state;
    double pose[7];          /* the world's pose view of the body */
} gcRtBody;

typedef struct gcInputMsg { /* push_hips -> haptic loop */
    int count;
    double t;                /* device time stamp */
    int64_t receipt_ns;      /* runtime clock when pushed: staleness */
    double *hips;            /* 3 per finger */
} gcInputMsg;

typedef struct gcHapticMsg { /* haptic loop -> object manager, every haptic tick */
    unsigned char *want;      /* per body: the haptic loop wants to step it (REQ or HAP) */
    unsigned char *has_state; /* per body: body[] is the haptic loop's state (HAP or RET) */
    gcRtBody *body;
    gcFinger *fingers;        /* after this tick's god-object update: the springs on bodies */
} gcHapticMsg;

typedef struct gcObjectMsg { /* object manager -> haptic loop, every object tick */
    double time;
    unsigned char *released; /* per body: handed to the haptic loop; body[] is its final state */
    gcRtBody *body;
} gcObjectMsg;

typedef struct gcDisplayMsg { /* haptic loop -> gc_world_snapshot, every haptic tick */
    uint64_t tick;
    double time, object_time;
    int64_t clock_ns;         /* runtime clock at publication: the reader-side watchdog */
    int forces_enabled;
    gcRtBody *body;
    unsigned char *adopted;
    double *hip, *god_object, *spring_force, *device_force; /* 3 per finger */
    int32_t *state, *contact_body;
} gcDisplayMsg;

enum { H_OM = 0, H_REQ, H_HAP, H_RET };   /* a body as the haptic loop sees it */
enum { O_OWN = 0, O_RELEASED };           /* a body as the object manager sees it */
enum { RT_STOPPED = 0, RT_RUNNING = 1 };

typedef struct gcRuntime {
    gcRuntimeDef def;
    int max_bodies, max_fingers;
    int64_t period_ns, object_period_ns, watchdog_ns, hip_timeout_ns, ramp_ns;
    double dt_haptic, dt_object;
    int object_substeps;

    /* Shadows: each thread's own copy of the world's dynamic state. */
    gcWorld hap, obj;
    unsigned char *hap_active, *obj_active;

    /* Haptic loop only. */
    unsigned char *hstate;
    double *last_touch;       /* haptic simulated time of the last touch of the body's chain */
    int32_t *chain;           /* gc_contacts_chain_of() scratch */
    double *device_force;     /* 3 per finger */
    gcHipFollow *follow;      /* per finger: walking towards the last pushed sample */
    double follow_prev_t;     /* time stamp of the last pushed sample taken */
    const gcHipTrack *track;  /* the world's scripted track (fixed while running), or NULL */
    double object_time_seen;
    int64_t prev_tick_ns, enabled_since_ns, last_input_ns;
    int was_stale;
    uint64_t tick;

    /* Object manager only. */
    unsigned char *ostate;

    /* Channels. */
    gcTriple input, to_object, to_haptic, display;
    gcInputMsg input_msg[3];
    gcHapticMsg haptic_msg[3];
    gcObjectMsg object_msg[3];
    gcDisplayMsg display_msg[3];
    pthread_mutex_t input_mutex; /* among push_hips callers only; the haptic loop never takes it */
    double input_last_t;

    /* Control (API callers; never taken by the loops). */
    pthread_mutex_t api_mutex;
    _Atomic int state;
    _Atomic int run;
    pthread_t haptic_thread, object_thread;
    int64_t start_ns, stop_ns;
    _Atomic int64_t manual_now_ns;
    double object_phase;      /* manual clock: object ticks due */
    _Atomic int64_t debug_stall_ns;
    int rt_priority;
    char priority_note[128];
    /* Set by the haptic thread before its first tick (its scheduling: rt_priority, thread_note);
     * gc_world_start waits for it. */
    _Atomic int haptic_ready;
    char thread_note[85];

    /* The runtime's own allocations, locked in RAM (mlock) while the threads run. */
    struct { void *p; size_t n; } region[GC_MAX_REGIONS];
    int num_regions;
    size_t locked_bytes;
    char memory_note[40];

    /* Statistics: written by one thread each, read by gc_world_stats. */
    _Atomic uint64_t haptic_ticks, object_ticks, overruns, late_periods, object_overruns;
    _Atomic uint64_t accepted_inputs, rejected_inputs, watchdog_trips, stale_inputs, nonfinite_forces;
    _Atomic uint64_t stopped_bodies;
    _Atomic int adopted, forces_enabled;
    _Atomic int64_t first_tick_ns, last_tick_ns, first_object_ns, last_object_ns, jitter_max_ns;
    _Atomic int64_t tick_sum_ns;
    _Atomic int64_t tick_max_ns, wake_max_ns; /* haptic tick's work; wake-up after its deadline */
    _Atomic uint64_t haptic_time_bits, object_time_bits, object_time0_bits;
    _Atomic uint32_t jitter_hist[GC_JITTER_BINS];
    uint32_t stats_hist[GC_JITTER_BINS]; /* gc_world_stats scratch, under api_mutex */
} gcRuntime;

/* ---- small helpers ------------------------------------------------------------------ */

static int64_t clock_now_ns(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * NS_PER_S + ts.tv_nsec;
}

static void sleep_until_ns(int64_t t) {
    struct timespec ts = {(time_t)(t / NS_PER_S), (long)(t % NS_PER_S)};
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, NULL) == EINTR) {
    }
}

static void count(_Atomic uint64_t *c) { atomic_fetch_add_explicit(c, 1, memory_order_relaxed); }

static void store_double(_Atomic uint64_t *slot, double v) {
    uint64_t bits;
    memcpy(&bits, &v, sizeof bits);
    atomic_store_explicit(slot, bits, memory_order_relaxed);
}

static double load_double(_Atomic uint64_t *slot) {
    uint64_t bits = atomic_load_explicit(slot, memory_order_relaxed);
    double v;
    memcpy(&v, &bits, sizeof v);
    return v;
}

static int64_t seconds_to_ns(double s) { return (int64_t)(s * 1e9 + 0.5); }

static void body_save(const gcWorld *s, int32_t i, gcRtBody *o) {
    const gcBody *b = &s->bodies[i];
    o->state = b->state;
    memcpy(o->pose, &s->pose_array[7 * i], sizeof o->pose);
}

static void body_load(gcWorld *s, int32_t i, const gcRtBody *o) {
    gcBody *b = &s->bodies[i];
    b->state = o->state;
    memcpy(&s->pose_array[7 * i], o->pose, sizeof o->pose);
}

/* Bodies the non-finite guard stopped in a shadow's step, for gc_world_stats. */
static void count_stopped(gcRuntime *rt, int stopped) {
    if (stopped) atomic_fetch_add_explicit(&rt->stopped_bodies, (uint64_t)stopped, memory_order_relaxed);
}

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

static int shadow_alloc(gcRuntime *rt, gcWorld *s, const gcWorld *w, unsigned char **active, int threads) {
    *s = *w; /* configuration and the shared read-only parts */
    s->contacts = NULL;
    s->def.threads = threads;
    s->bodies = rt_calloc(rt, (size_t)w->def.max_bodies, sizeof *s->bodies);
    s->fingers = rt_calloc(rt, (size_t)w->def.max_fingers, sizeof *s->fingers);
    s->pose_array = rt_calloc(rt, (size_t)w->def.max_bodies * 7, sizeof(double));
    s->god_object_array = rt_calloc(rt, (size_t)w->def.max_fingers * 3, sizeof(double));
    s->force_array = rt_calloc(rt, (size_t)w->def.max_fingers * 3, sizeof(double));
    s->hip_array = rt_calloc(rt, (size_t)w->def.max_fingers * 3, sizeof(double));
    *active = rt_calloc(rt, (size_t)w->def.max_bodies, 1);
    s->body_active = *active;
    s->runtime = NULL;
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

/* The world's dynamic state into a shadow, at start. */
static void shadow_load(gcWorld *s, const gcWorld *w) {
    s->gravity = w->gravity;
    s->time = w->time;
    s->num_bodies = w->num_bodies;
    s->num_fingers = w->num_fingers;
    s->num_parts = w->num_parts;
    s->parts = w->parts;
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
    shadow_free(&rt->hap);
    shadow_free(&rt->obj);
    free(rt->hap_active);
    free(rt->obj_active);
    free(rt->hstate);
    free(rt->last_touch);
    free(rt->chain);
    free(rt->device_force);
    free(rt->ostate);
    for (int i = 0; i < 3; ++i) {
        free(rt->input_msg[i].hips);
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
    int ok = shadow_alloc(rt, &rt->hap, w, &rt->hap_active, 1);
    ok &= shadow_alloc(rt, &rt->obj, w, &rt->obj_active, w->def.threads);
    rt->hstate = rt_calloc(rt, nb, 1);
    rt->last_touch = rt_calloc(rt, nb, sizeof(double));
    rt->chain = rt_calloc(rt, nb, sizeof(int32_t));
    rt->device_force = rt_calloc(rt, nf * 3, sizeof(double));
    rt->follow = rt_calloc(rt, nf, sizeof(gcHipFollow));
    rt->ostate = rt_calloc(rt, nb, 1);
    ok &= rt->hstate && rt->last_touch && rt->chain && rt->device_force && rt->follow && rt->ostate;
    for (int i = 0; i < 3; ++i) {
        gcInputMsg *in = &rt->input_msg[i];
        gcHapticMsg *h = &rt->haptic_msg[i];
        gcObjectMsg *o = &rt->object_msg[i];
        gcDisplayMsg *d = &rt->display_msg[i];
        in->hips = rt_calloc(rt, nf * 3, sizeof(double));
        h->want = rt_calloc(rt, nb, 1);
        h->has_state = rt_calloc(rt, nb, 1);
        h->body = rt_calloc(rt, nb, sizeof(gcRtBody));
        h->fingers = rt_calloc(rt, nf, sizeof(gcFinger));
        o->released = rt_calloc(rt, nb, 1);
        o->body = rt_calloc(rt, nb, sizeof(gcRtBody));
        d->body = rt_calloc(rt, nb, sizeof(gcRtBody));
        d->adopted = rt_calloc(rt, nb, 1);
        d->hip = rt_calloc(rt, nf * 3, sizeof(double));
        d->god_object = rt_calloc(rt, nf * 3, sizeof(double));
        d->spring_force = rt_calloc(rt, nf * 3, sizeof(double));
        d->device_force = rt_calloc(rt, nf * 3, sizeof(double));
        d->state = rt_calloc(rt, nf, sizeof(int32_t));
        d->contact_body = rt_calloc(rt, nf, sizeof(int32_t));
        ok &= in->hips && h->want && h->has_state && h->body && h->fingers && o->released && o->body && d->body &&
              d->adopted && d->hip && d->god_object && d->spring_force && d->device_force && d->state &&
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

/* ---- publications ------------------------------------------------------------------- */

static void publish_to_object(gcRuntime *rt) {
    const gcWorld *hw = &rt->hap;
    gcHapticMsg *m = &rt->haptic_msg[rt->to_object.back];
    for (int32_t b = 0; b < hw->num_bodies; ++b) {
        unsigned char s = rt->hstate[b];
        m->want[b] = s == H_REQ || s == H_HAP;
        m->has_state[b] = s == H_HAP || s == H_RET;
        if (m->has_state[b]) body_save(hw, b, &m->body[b]);
    }
    memcpy(m->fingers, hw->fingers, (size_t)hw->num_fingers * sizeof *hw->fingers);
    triple_publish(&rt->to_object);
}

static void publish_to_haptic(gcRuntime *rt) {
    const gcWorld *ow = &rt->obj;
    gcObjectMsg *m = &rt->object_msg[rt->to_haptic.back];
    m->time = ow->time;
    for (int32_t b = 0; b < ow->num_bodies; ++b) {
        m->released[b] = rt->ostate[b] == O_RELEASED;
        body_save(ow, b, &m->body[b]);
    }
    triple_publish(&rt->to_haptic);
}

static void publish_display(gcRuntime *rt, int64_t now, int forces_enabled) {
    const gcWorld *hw = &rt->hap;
    gcDisplayMsg *d = &rt->display_msg[rt->display.back];
    d->tick = rt->tick;
    d->time = hw->time;
    d->object_time = rt->object_time_seen;
    d->clock_ns = now;
    d->forces_enabled = forces_enabled;
    for (int32_t b = 0; b < hw->num_bodies; ++b) {
        body_save(hw, b, &d->body[b]);
        d->adopted[b] = rt->hstate[b] == H_HAP;
    }
    for (int32_t i = 0; i < hw->num_fingers; ++i) {
        const gcFinger *f = &hw->fingers[i];
        memcpy(&d->hip[3 * i], &f->hip, 3 * sizeof(double));
        memcpy(&d->god_object[3 * i], &f->god_object, 3 * sizeof(double));
        memcpy(&d->spring_force[3 * i], &f->force, 3 * sizeof(double));
        memcpy(&d->device_force[3 * i], &rt->device_force[3 * i], 3 * sizeof(double));
        d->state[i] = (int32_t)f->state;
        d->contact_body[i] = f->contact_body;
    }
    triple_publish(&rt->display);
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
                int32_t b = hw->parts[f->contacts[c].part].body;
                if (hw->bodies[b].is_static) continue;
                int n = gc_contacts_chain_of(hw, b, rt->chain, cap);
                if (n > cap) continue;
                for (int k = 0; k < n; ++k) rt->last_touch[rt->chain[k]] = now;
            }
        }
    }
    int adopted = 0;
    for (int32_t b = 0; b < hw->num_bodies; ++b) {
        if (hw->bodies[b].is_static) continue;
        int want = cap > 0 && now - rt->last_touch[b] <= rt->def.release_delay &&
                   gc_contacts_chain_of(hw, b, rt->chain, cap) <= cap;
        /* A request or a return runs to completion before the wish can change again. */
        if (rt->hstate[b] == H_OM && want) {
            rt->hstate[b] = H_REQ;
        } else if (rt->hstate[b] == H_HAP && !want) {
            rt->hstate[b] = H_RET; /* stepped this tick; the object manager continues from here */
            rt->hap_active[b] = 0;
        }
        adopted += rt->hstate[b] == H_HAP;
    }
    atomic_store_explicit(&rt->adopted, adopted, memory_order_relaxed);
}

/* Device forces: the spring, ramped in, clamped, and zero while the watchdog holds them. */
static int update_safety(gcRuntime *rt, int64_t now) {
    const gcWorld *hw = &rt->hap;
    int64_t period = rt->prev_tick_ns == NEVER ? rt->period_ns : now - rt->prev_tick_ns;
    rt->prev_tick_ns = now;
    int ok = 1;
    if (period > rt->watchdog_ns) {
        ok = 0; /* the loop missed its deadlines: zero, then ramp in again */
        count(&rt->watchdog_trips);
    }
    int stale = rt->last_input_ns == NEVER || now - rt->last_input_ns > rt->hip_timeout_ns;
    if (stale) {
        ok = 0;
        if (!rt->was_stale) count(&rt->stale_inputs);
    }
    rt->was_stale = stale;
    if (!ok)
        rt->enabled_since_ns = NEVER;
    else if (rt->enabled_since_ns == NEVER)
        rt->enabled_since_ns = now;
    double gain = 0.0;
    if (ok) gain = rt->ramp_ns > 0 ? fmin(1.0, (double)(now - rt->enabled_since_ns) / (double)rt->ramp_ns) : 1.0;
    for (int32_t i = 0; i < hw->num_fingers; ++i) {
        gcVec3 f = gc_scale(hw->fingers[i].force, gain);
        if (!gc_vec_finite(f)) {
            count(&rt->nonfinite_forces);
            f = gc_v3(0, 0, 0);
        }
        double norm = gc_len(f);
        if (norm > rt->def.max_force) f = gc_scale(f, rt->def.max_force / norm);
        double *out = &rt->device_force[3 * i];
        out[0] = f.x, out[1] = f.y, out[2] = f.z;
    }
    atomic_store_explicit(&rt->forces_enabled, ok, memory_order_relaxed);
    return ok;
}

static void haptic_tick(gcRuntime *rt, int64_t now) {
    gcWorld *hw = &rt->hap;
    const double dt = rt->dt_haptic;
    int fresh;

    /* 1. HIPs at this tick's end time: the scripted track, or the walk towards the latest
     *    pushed samples (validated by push_hips). */
    const gcInputMsg *in = &rt->input_msg[triple_latest(&rt->input, &fresh)];
    if (fresh) {
        double interval = isfinite(rt->follow_prev_t) ? in->t - rt->follow_prev_t : 0.0;
        rt->follow_prev_t = in->t;
        for (int i = 0; i < in->count; ++i)
            if (!gc_hip_track_drives(rt->track, i))
                gc_hip_follow_retarget(&rt->follow[i], hw->fingers[i].hip,
                                       gc_v3(in->hips[3 * i], in->hips[3 * i + 1], in->hips[3 * i + 2]), interval, dt);
        rt->last_input_ns = in->receipt_ns;
    }
    if (gc_hip_track_covers(rt->track, hw->num_fingers)) rt->last_input_ns = now; /* the track is never stale */
    const double t_next = (double)(rt->tick + 1) * dt;
    for (int i = 0; i < hw->num_fingers; ++i) {
        gcVec3 hip = gc_hip_track_drives(rt->track, i)
                         ? gc_hip_track_sample(rt->track, i, t_next)
                         : gc_hip_follow_advance(&rt->follow[i], hw->fingers[i].hip, dt, rt->def.max_hip_speed);
        hw->fingers[i].hip = hip;
        double *out = &hw->hip_array[3 * i];
        out[0] = hip.x, out[1] = hip.y, out[2] = hip.z;
    }

    /* 2. The object manager's bodies; bodies it released are adopted before stepping. */
    const gcObjectMsg *om = &rt->object_msg[triple_latest(&rt->to_haptic, &fresh)];
    if (fresh) {
        rt->object_time_seen = om->time;
        for (int32_t b = 0; b < hw->num_bodies; ++b) {
            if (hw->bodies[b].is_static) continue;
            switch (rt->hstate[b]) {
            case H_OM: body_load(hw, b, &om->body[b]); break;
            case H_REQ:
                body_load(hw, b, &om->body[b]);
                if (om->released[b]) {
                    rt->hstate[b] = H_HAP;
                    rt->hap_active[b] = 1;
                }
                break;
            case H_RET:
                if (!om->released[b]) {
                    body_load(hw, b, &om->body[b]);
                    rt->hstate[b] = H_OM;
                }
                break;
            default: break;
            }
        }
    }

    /* 3. As gc_world_step: god-objects and springs, then the bodies this loop owns. */
    count_stopped(rt, gc_step(hw, dt));
    rt->tick++;

    /* 4. Adoption wishes for the next ticks, device forces, publications. */
    update_adoption(rt);
    int ok = update_safety(rt, now);
    publish_to_object(rt);
    publish_display(rt, now, ok);
    store_double(&rt->haptic_time_bits, hw->time);
    count(&rt->haptic_ticks);
}

/* ---- the object tick ---------------------------------------------------------------- */

static void object_tick(gcRuntime *rt) {
    gcWorld *ow = &rt->obj;
    int fresh;
    const gcHapticMsg *h = &rt->haptic_msg[triple_latest(&rt->to_object, &fresh)];
    memcpy(ow->fingers, h->fingers, (size_t)ow->num_fingers * sizeof *ow->fingers);
    /* Bodies the haptic loop steps, where it has them now: obstacles for the contacts here. */
    for (int32_t b = 0; b < ow->num_bodies; ++b)
        if (rt->ostate[b] == O_RELEASED && h->has_state[b]) body_load(ow, b, &h->body[b]);
    for (int s = 0; s < rt->object_substeps; ++s) {
        count_stopped(rt, gc_step_bodies(ow, rt->dt_object));
        ow->time += rt->dt_object;
    }
    /* Hand-over after stepping: a released body was stepped this tick; a body taken back
     * was stepped by the haptic loop and moves from the next tick. */
    for (int32_t b = 0; b < ow->num_bodies; ++b) {
        if (ow->bodies[b].is_static) continue;
        if (rt->ostate[b] == O_OWN && h->want[b]) {
            rt->ostate[b] = O_RELEASED;
            rt->obj_active[b] = 0;
        } else if (rt->ostate[b] == O_RELEASED && !h->want[b] && h->has_state[b]) {
            body_load(ow, b, &h->body[b]);
            rt->ostate[b] = O_OWN;
            rt->obj_active[b] = 1;
        }
    }
    publish_to_haptic(rt);
    store_double(&rt->object_time_bits, ow->time);
    count(&rt->object_ticks);
}

/* ---- threads ------------------------------------------------------------------------ */

static void record_period(gcRuntime *rt, int64_t period) {
    int64_t err = period - rt->period_ns;
    if (err < 0) err = -err;
    int64_t bin = err / 1000;
    if (bin >= GC_JITTER_BINS) bin = GC_JITTER_BINS - 1;
    atomic_fetch_add_explicit(&rt->jitter_hist[bin], 1, memory_order_relaxed);
    if (err > atomic_load_explicit(&rt->jitter_max_ns, memory_order_relaxed))
        atomic_store_explicit(&rt->jitter_max_ns, err, memory_order_relaxed);
    if (err > rt->period_ns) count(&rt->late_periods);
}

/* Next absolute deadline after a tick that ended at `end`: deadlines already missed are
 * skipped (counted as an overrun), never run back to back to catch up. */
static int64_t next_deadline(int64_t deadline, int64_t period, int64_t end, _Atomic uint64_t *overruns) {
    deadline += period;
    if (end > deadline) {
        count(overruns);
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

static void *haptic_main(void *arg) {
    gcRuntime *rt = arg;
    size_t stack_locked;
    void *stack_window = haptic_thread_setup(rt, &stack_locked);
    atomic_store_explicit(&rt->haptic_ready, 1, memory_order_release);
    int64_t deadline = clock_now_ns() + rt->period_ns, prev_wake = NEVER;
    while (atomic_load_explicit(&rt->run, memory_order_acquire)) {
        int64_t stall = atomic_exchange_explicit(&rt->debug_stall_ns, 0, memory_order_relaxed);
        sleep_until_ns(deadline + stall);
        int64_t wake = clock_now_ns();
        record_max(&rt->wake_max_ns, wake - deadline);
        if (prev_wake == NEVER)
            atomic_store_explicit(&rt->first_tick_ns, wake, memory_order_relaxed);
        else
            record_period(rt, wake - prev_wake);
        prev_wake = wake;
        haptic_tick(rt, wake);
        int64_t end = clock_now_ns();
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

static void *object_main(void *arg) {
    gcRuntime *rt = arg;
#ifdef __linux__
    pthread_setname_np(pthread_self(), "gc-object");
#endif
    int64_t deadline = clock_now_ns() + rt->object_period_ns;
    int first = 1;
    while (atomic_load_explicit(&rt->run, memory_order_acquire)) {
        sleep_until_ns(deadline);
        int64_t wake = clock_now_ns();
        if (first) atomic_store_explicit(&rt->first_object_ns, wake, memory_order_relaxed);
        first = 0;
        object_tick(rt);
        int64_t end = clock_now_ns();
        atomic_store_explicit(&rt->last_object_ns, wake, memory_order_relaxed);
        deadline = next_deadline(deadline, rt->object_period_ns, end, &rt->object_overruns);
    }
    return NULL;
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

int gc_runtime_running(const gcWorld *w) {
    return w && w->runtime && atomic_load_explicit(&w->runtime->state, memory_order_acquire) == RT_RUNNING;
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
    atomic_store(&rt->first_tick_ns, NEVER);
    atomic_store(&rt->last_tick_ns, NEVER);
    atomic_store(&rt->first_object_ns, NEVER);
    atomic_store(&rt->last_object_ns, NEVER);
    atomic_store(&rt->jitter_max_ns, 0);
    atomic_store(&rt->tick_max_ns, 0);
    atomic_store(&rt->tick_sum_ns, 0);
    atomic_store(&rt->wake_max_ns, 0);
    for (int i = 0; i < GC_JITTER_BINS; ++i) atomic_store_explicit(&rt->jitter_hist[i], 0, memory_order_relaxed);
}

gcStatus gc_world_start(gcWorld *w, const gcRuntimeDef *def) {
    if (!w || !def) return GC_ERR_INVALID_ARGUMENT;
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
    rt->def = *def;
    rt->def.realtime = def->realtime != 0;
    rt->period_ns = seconds_to_ns(1.0 / def->haptic_rate);
    rt->object_period_ns = seconds_to_ns(1.0 / def->object_rate);
    rt->watchdog_ns = seconds_to_ns(def->watchdog_timeout);
    rt->hip_timeout_ns = seconds_to_ns(def->hip_timeout);
    rt->ramp_ns = seconds_to_ns(def->ramp_time);
    rt->dt_haptic = 1.0 / def->haptic_rate;
    double object_period = 1.0 / def->object_rate;
    rt->object_substeps = (int)ceil(object_period / GC_OBJECT_MAX_STEP - 1e-9);
    if (rt->object_substeps < 1) rt->object_substeps = 1;
    rt->dt_object = object_period / rt->object_substeps;

    /* Both shadows start from the world; every dynamic body belongs to the object manager. */
    shadow_load(&rt->hap, w);
    shadow_load(&rt->obj, w);
    for (int32_t b = 0; b < w->num_bodies; ++b) {
        rt->hstate[b] = H_OM;
        rt->ostate[b] = O_OWN;
        rt->hap_active[b] = 0;
        rt->obj_active[b] = 1;
        rt->last_touch[b] = -INFINITY;
    }
    memset(rt->device_force, 0, (size_t)rt->max_fingers * 3 * sizeof(double));
    rt->object_time_seen = w->time;
    rt->prev_tick_ns = rt->enabled_since_ns = rt->last_input_ns = NEVER;
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
    store_double(&rt->haptic_time_bits, w->time);
    store_double(&rt->object_time_bits, w->time);
    store_double(&rt->object_time0_bits, w->time);

    /* First publications, so that every reader starts from a complete message. */
    triple_reset(&rt->input);
    triple_reset(&rt->to_object);
    triple_reset(&rt->to_haptic);
    triple_reset(&rt->display);
    publish_to_object(rt);
    publish_to_haptic(rt);
    publish_display(rt, 0, 0);
    int fresh;
    (void)triple_latest(&rt->to_haptic, &fresh); /* the haptic shadow already holds these bodies */

    rt->rt_priority = 0;
    rt->start_ns = clock_now_ns();
    rt->stop_ns = NEVER;
    if (!rt->def.realtime) {
        snprintf(rt->priority_note, sizeof rt->priority_note, "manual clock (realtime=0): no threads");
        atomic_store_explicit(&rt->state, RT_RUNNING, memory_order_release);
        pthread_mutex_unlock(&rt->api_mutex);
        return GC_OK;
    }
    lock_memory(rt);
    atomic_store_explicit(&rt->haptic_ready, 0, memory_order_relaxed);
    atomic_store_explicit(&rt->run, 1, memory_order_release);
    atomic_store_explicit(&rt->state, RT_RUNNING, memory_order_release);
    int e = pthread_create(&rt->object_thread, NULL, object_main, rt);
    if (e == 0) {
        e = pthread_create(&rt->haptic_thread, NULL, haptic_main, rt);
        if (e != 0) {
            atomic_store_explicit(&rt->run, 0, memory_order_release);
            pthread_join(rt->object_thread, NULL);
        }
    }
    if (e != 0) {
        unlock_memory(rt);
        atomic_store_explicit(&rt->state, RT_STOPPED, memory_order_release);
        w->locked = 0;
        pthread_mutex_unlock(&rt->api_mutex);
        gc_world_set_error(w, "runtime: could not create its threads (error %d)", e);
        return GC_ERR_NO_MEMORY;
    }
    /* The haptic thread sets up its own scheduling before its first tick; wait for its note
     * (microseconds), so that stats() is complete as soon as start() returns. */
    while (!atomic_load_explicit(&rt->haptic_ready, memory_order_acquire)) {
        struct timespec ts = {0, 20000};
        nanosleep(&ts, NULL);
    }
    snprintf(rt->priority_note, sizeof rt->priority_note, "%s; %s", rt->thread_note, rt->memory_note);
    pthread_mutex_unlock(&rt->api_mutex);
    return GC_OK;
}

static int haptic_owns(const gcRuntime *rt, int32_t b) {
    return rt->ostate[b] == O_RELEASED && (rt->hstate[b] == H_HAP || rt->hstate[b] == H_RET);
}

static int haptic_owns_ctx(const void *rt, int32_t b) { return haptic_owns(rt, b); }

/* After the loops ended: each body from the thread that owned it last, fingers from the
 * haptic loop. */
static void merge_into_world(gcRuntime *rt, gcWorld *w) {
    const gcWorld *hw = &rt->hap, *ow = &rt->obj;
    for (int32_t b = 0; b < w->num_bodies; ++b) {
        if (w->bodies[b].is_static) continue;
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

gcStatus gc_world_stop(gcWorld *w) {
    if (!w) return GC_ERR_INVALID_ARGUMENT;
    gcRuntime *rt = w->runtime;
    if (!rt) return GC_OK;
    pthread_mutex_lock(&rt->api_mutex);
    if (atomic_load_explicit(&rt->state, memory_order_acquire) != RT_RUNNING) {
        pthread_mutex_unlock(&rt->api_mutex);
        return GC_OK;
    }
    if (rt->def.realtime) {
        atomic_store_explicit(&rt->run, 0, memory_order_release);
        pthread_join(rt->haptic_thread, NULL);
        pthread_join(rt->object_thread, NULL);
        unlock_memory(rt);
    }
    rt->stop_ns = clock_now_ns();
    merge_into_world(rt, w);
    atomic_store_explicit(&rt->state, RT_STOPPED, memory_order_release);
    w->locked = 0;
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
        int64_t period = rt->period_ns + (k == 0 ? seconds_to_ns(delay) : 0);
        int64_t now = atomic_load_explicit(&rt->manual_now_ns, memory_order_relaxed) + period;
        atomic_store_explicit(&rt->manual_now_ns, now, memory_order_relaxed);
        if (rt->tick == 0)
            atomic_store_explicit(&rt->first_tick_ns, now, memory_order_relaxed);
        else
            record_period(rt, period);
        haptic_tick(rt, now);
        atomic_store_explicit(&rt->last_tick_ns, now, memory_order_relaxed);
        /* The object manager's ticks fall on a fixed schedule of the haptic ticks. */
        rt->object_phase += rt->def.object_rate;
        if (rt->object_phase >= rt->def.haptic_rate) {
            rt->object_phase -= rt->def.haptic_rate;
            if (atomic_load_explicit(&rt->object_ticks, memory_order_relaxed) == 0)
                atomic_store_explicit(&rt->first_object_ns, now, memory_order_relaxed);
            object_tick(rt);
            atomic_store_explicit(&rt->last_object_ns, now, memory_order_relaxed);
        }
    }
    pthread_mutex_unlock(&rt->api_mutex);
    return GC_OK;
}

gcStatus gc_world_push_hips(gcWorld *w, const double *positions, int count_, double t) {
    if (!w || !positions) return GC_ERR_INVALID_ARGUMENT;
    gcRuntime *rt = w->runtime;
    if (!gc_runtime_running(w)) return GC_ERR_NOT_RUNNING;
    if (count_ < 1 || count_ > w->num_fingers) return GC_ERR_INVALID_ARGUMENT;
    int finite = isfinite(t);
    for (int i = 0; i < 3 * count_ && finite; ++i) finite = isfinite(positions[i]);
    if (!finite) {
        count(&rt->rejected_inputs);
        return GC_WARN_REJECTED;
    }
    pthread_mutex_lock(&rt->input_mutex);
    if (t < rt->input_last_t) { /* older than what the loop already has */
        pthread_mutex_unlock(&rt->input_mutex);
        count(&rt->rejected_inputs);
        return GC_WARN_REJECTED;
    }
    rt->input_last_t = t;
    gcInputMsg *m = &rt->input_msg[rt->input.back];
    m->count = count_;
    m->t = t;
    m->receipt_ns = rt->def.realtime ? clock_now_ns() : atomic_load_explicit(&rt->manual_now_ns, memory_order_relaxed);
    memcpy(m->hips, positions, 3 * (size_t)count_ * sizeof(double));
    triple_publish(&rt->input);
    pthread_mutex_unlock(&rt->input_mutex);
    count(&rt->accepted_inputs);
    return GC_OK;
}

static void put_body(const gcSnapshot *s, int32_t b, const double pose[7], gcVec3 force, gcVec3 torque, int adopted) {
    if (s->poses) memcpy(&s->poses[7 * b], pose, 7 * sizeof(double));
    if (s->residual_wrenches) {
        double *r = &s->residual_wrenches[6 * b];
        r[0] = force.x, r[1] = force.y, r[2] = force.z, r[3] = torque.x, r[4] = torque.y, r[5] = torque.z;
    }
    if (s->adopted) s->adopted[b] = (uint8_t)adopted;
}

static void put3(double *array, int32_t i, const double *v) {
    if (array) memcpy(&array[3 * i], v, 3 * sizeof(double));
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
        put_body(s, b, &w->pose_array[7 * b], w->bodies[b].state.residual_force, w->bodies[b].state.residual_torque, 0);
    for (int32_t i = 0; i < w->num_fingers; ++i) {
        const gcFinger *f = &w->fingers[i];
        put3(s->hips, i, &w->hip_array[3 * i]);
        put3(s->god_objects, i, &w->god_object_array[3 * i]);
        put3(s->spring_forces, i, &w->force_array[3 * i]);
        put3(s->forces, i, zero);
        if (s->finger_states) s->finger_states[i] = (int32_t)f->state;
        if (s->contact_bodies) s->contact_bodies[i] = f->contact_body;
    }
}

gcStatus gc_world_snapshot(gcWorld *w, gcSnapshot *s) {
    if (!w || !s) return GC_ERR_INVALID_ARGUMENT;
    gcRuntime *rt = w->runtime;
    if (!rt) {
        snapshot_from_world(w, s);
        return GC_OK;
    }
    pthread_mutex_lock(&rt->api_mutex);
    if (atomic_load_explicit(&rt->state, memory_order_acquire) != RT_RUNNING) {
        snapshot_from_world(w, s);
        pthread_mutex_unlock(&rt->api_mutex);
        return GC_OK;
    }
    int fresh;
    const gcDisplayMsg *d = &rt->display_msg[triple_latest(&rt->display, &fresh)];
    /* Reader-side watchdog: a loop that stalled cannot zero its own output. */
    int enabled = d->forces_enabled;
    if (rt->def.realtime && clock_now_ns() - d->clock_ns > rt->watchdog_ns) enabled = 0;
    static const double zero[3] = {0, 0, 0};
    s->time = d->time;
    s->object_time = d->object_time;
    s->tick = d->tick;
    s->forces_enabled = enabled;
    s->num_bodies = w->num_bodies;
    s->num_fingers = w->num_fingers;
    /* The world's queries and views answer from this snapshot while the runtime runs. */
    for (int32_t b = 0; b < w->num_bodies; ++b) {
        const gcRtBody *rb = &d->body[b];
        put_body(s, b, rb->pose, rb->state.residual_force, rb->state.residual_torque, d->adopted[b]);
        if (!w->bodies[b].is_static) body_load(w, b, rb);
    }
    for (int32_t i = 0; i < w->num_fingers; ++i) {
        put3(s->hips, i, &d->hip[3 * i]);
        put3(s->god_objects, i, &d->god_object[3 * i]);
        put3(s->spring_forces, i, &d->spring_force[3 * i]);
        put3(s->forces, i, enabled ? &d->device_force[3 * i] : zero);
        if (s->finger_states) s->finger_states[i] = d->state[i];
        if (s->contact_bodies) s->contact_bodies[i] = d->contact_body[i];
        gcFinger *f = &w->fingers[i];
        f->hip = gc_v3(d->hip[3 * i], d->hip[3 * i + 1], d->hip[3 * i + 2]);
        f->god_object = gc_v3(d->god_object[3 * i], d->god_object[3 * i + 1], d->god_object[3 * i + 2]);
        f->force = gc_v3(d->spring_force[3 * i], d->spring_force[3 * i + 1], d->spring_force[3 * i + 2]);
        f->state = (gcFingerState)d->state[i];
        f->contact_body = d->contact_body[i];
        memcpy(&w->hip_array[3 * i], &d->hip[3 * i], 3 * sizeof(double));
        memcpy(&w->god_object_array[3 * i], &d->god_object[3 * i], 3 * sizeof(double));
        memcpy(&w->force_array[3 * i], &d->spring_force[3 * i], 3 * sizeof(double));
    }
    w->time = d->time;
    pthread_mutex_unlock(&rt->api_mutex);
    return GC_OK;
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
    if (!w || !out) return GC_ERR_INVALID_ARGUMENT;
    memset(out, 0, sizeof *out);
    gcRuntime *rt = w->runtime;
    if (!rt) {
        snprintf(out->priority_note, sizeof out->priority_note, "never started");
        out->haptic_time = out->object_time = w->time;
        return GC_OK;
    }
    pthread_mutex_lock(&rt->api_mutex);
    int running = atomic_load_explicit(&rt->state, memory_order_acquire) == RT_RUNNING;
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
    out->rejected_inputs = atomic_load_explicit(&rt->rejected_inputs, memory_order_relaxed);
    out->watchdog_trips = atomic_load_explicit(&rt->watchdog_trips, memory_order_relaxed);
    out->stale_inputs = atomic_load_explicit(&rt->stale_inputs, memory_order_relaxed);
    out->nonfinite_forces = atomic_load_explicit(&rt->nonfinite_forces, memory_order_relaxed);
    out->stopped_bodies = atomic_load_explicit(&rt->stopped_bodies, memory_order_relaxed);
    out->adopted_bodies = atomic_load_explicit(&rt->adopted, memory_order_relaxed);
    out->forces_enabled = running && atomic_load_explicit(&rt->forces_enabled, memory_order_relaxed);
    out->haptic_time = load_double(&rt->haptic_time_bits);
    out->object_time = load_double(&rt->object_time_bits);

    /* Achieved rates over the run (on the manual clock, per simulated second). */
    int64_t t0 = atomic_load_explicit(&rt->first_tick_ns, memory_order_relaxed);
    int64_t t1 = atomic_load_explicit(&rt->last_tick_ns, memory_order_relaxed);
    if (out->haptic_ticks > 1 && t0 != NEVER && t1 > t0)
        out->haptic_rate = (double)(out->haptic_ticks - 1) * 1e9 / (double)(t1 - t0);
    t0 = atomic_load_explicit(&rt->first_object_ns, memory_order_relaxed);
    t1 = atomic_load_explicit(&rt->last_object_ns, memory_order_relaxed);
    if (out->object_ticks > 1 && t0 != NEVER && t1 > t0)
        out->object_rate = (double)(out->object_ticks - 1) * 1e9 / (double)(t1 - t0);
    double wall;
    if (rt->def.realtime)
        wall = (double)((running ? clock_now_ns() : rt->stop_ns) - rt->start_ns) * 1e-9;
    else
        wall = (double)atomic_load_explicit(&rt->manual_now_ns, memory_order_relaxed) * 1e-9;
    if (wall > 0.0) out->object_speed = (out->object_time - load_double(&rt->object_time0_bits)) / wall;

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
    if (!gc_runtime_running(w)) return GC_ERR_NOT_RUNNING;
    if (!isfinite(seconds) || seconds < 0.0 || seconds > 10.0) {
        gc_world_set_error(w, "seconds: must be in [0, 10] (got %g)", seconds);
        return GC_ERR_INVALID_ARGUMENT;
    }
    atomic_store_explicit(&w->runtime->debug_stall_ns, seconds_to_ns(seconds), memory_order_relaxed);
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
