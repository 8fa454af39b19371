/* The runtime's private layout, shared by its files only (docs/architecture.md), bottom up:
 * runtime_channels.c   the triple-buffer channels between the threads and the API (body
 *                      state copies, publications, push_hips, snapshots);
 * runtime_handover.c   the haptic and object ticks, adoption and hand-over of bodies, the
 *                      device-force safety stage, the final merge into the world;
 * runtime_threads.c    the two loops, their clocks, deadlines and scheduling, statistics;
 * runtime.c            memory, shadows, start / stop / advance.
 * Each file is built with _GNU_SOURCE first (Linux: prctl, sched_setattr, mlock). */
#ifndef GC_RUNTIME_INTERNAL_H
#define GC_RUNTIME_INTERNAL_H

#include "runtime.h"

#include "contacts/contacts.h"
#include "hip_input.h"
#include "devices/device_hub.h"
#include "devices/force_gate.h"
#include "base/gc_sync.h"
#include "dynamics/step.h"

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

/* The object manager's step cap: 2 ms (the source chapter's "0.002 ms" is a typo;
 * docs/runtime.md). */
#define GC_OBJECT_MAX_STEP 0.002
/* Period-error histogram of the haptic loop: 1 us bins, the last one collects the rest. */
#define GC_JITTER_BINS 20000
#define GC_NEVER_NS INT64_MIN
/* The haptic loop's wait (docs/runtime.md "Getting on time"): the scheduler time slice it
 * asks for at normal priority (Linux >= 6.12; the kernel's minimum), the stack it touches
 * before its first tick, and the most runtime memory it locks in RAM. */
#define GC_HAPTIC_SLICE_NS 100000
#define GC_HAPTIC_STACK_PREFAULT (64 * 1024)
#define GC_LOCK_BUDGET (64u << 20)
#define GC_MAX_REGIONS 96
/* Object results in flight at once when a schedule is replayed (runtime_replay.c): more than
 * two needs the object manager to finish two ticks inside one haptic tick's work. */
#define GC_REPLAY_QUEUE 16

/* ---- messages --------------------------------------------------------------------- */

/* A body's dynamic state, exactly (no re-derivation), so that a hand-over changes no bit. */
typedef struct gcRuntimeBody {
    gcBodyState state;
    double pose[7];          /* the world's pose view of the body */
} gcRuntimeBody;

typedef struct gcInputMsg { /* push_hips -> haptic loop */
    int count;
    double t;                /* device time stamp */
    int64_t receipt_ns;      /* runtime clock when pushed: staleness */
    double *hips;            /* 3 per finger */
    int has_orientations;    /* the push carried orientations (gc_world_push_finger_poses) */
    double *orientations;    /* 4 per finger (w x y z), as pushed */
} gcInputMsg;

typedef struct gcRuntimeDeviceFinger { /* the haptic loop's view of a finger's device slot */
    uint64_t serial;          /* of the last sample taken (0: none this session) */
    double t;                 /* its time stamp */
    uint32_t episode;         /* its device's connection */
    int soft_start;           /* walking to the device at GC_HIP_SOFT_START_SPEED */
} gcRuntimeDeviceFinger;

typedef struct gcHapticMsg { /* haptic loop -> object manager, every haptic tick */
    unsigned char *want;      /* per body: the haptic loop wants to step it (REQ or HAP) */
    unsigned char *has_state; /* per body: body[] is the haptic loop's state (HAP or RET) */
    gcRuntimeBody *body;
    gcFinger *fingers;        /* after this tick's god-object update: the springs on bodies */
} gcHapticMsg;

typedef struct gcObjectMsg { /* object manager -> haptic loop, every object tick */
    uint64_t seq;            /* the object tick that published it (0: gc_world_start) */
    double time;
    unsigned char *released; /* per body: handed to the haptic loop; body[] is its final state */
    gcRuntimeBody *body;
} gcObjectMsg;

typedef struct gcDisplayMsg { /* haptic loop -> gc_world_snapshot, every haptic tick */
    uint64_t tick;
    double time, object_time;
    int64_t clock_ns;         /* runtime clock at publication: the reader-side watchdog */
    int forces_enabled;
    gcRuntimeBody *body;
    unsigned char *adopted;
    double *hip, *god_object, *spring_force, *device_force, *normal; /* 3 per finger */
    float *patch;                   /* 2 GC_FINGER_PATCH_CORNERS per finger: gcFinger.patch */
    int32_t *state, *contact_body;
} gcDisplayMsg;

/* A body as the haptic loop sees it: the object manager's, requested, the haptic loop's, being
 * returned. */
enum { GC_HAPTIC_OM_OWNS = 0, GC_HAPTIC_REQUESTED, GC_HAPTIC_OWNS, GC_HAPTIC_RETURNING };
enum { GC_OBJECT_OWNS = 0, GC_OBJECT_RELEASED }; /* a body as the object manager sees it */
enum { GC_RUNTIME_STOPPED = 0, GC_RUNTIME_RUNNING = 1 };

typedef struct gcRuntime {
    gcRuntimeDef def;
    int max_bodies, max_fingers;
    int64_t period_ns, object_period_ns, watchdog_ns, hip_timeout_ns, ramp_ns;
    double dt_haptic, dt_object;
    int object_substeps;

    /* Shadows: each thread's own copy of the world's dynamic state. */
    gcWorld hap, obj;
    unsigned char *hap_active, *obj_active;

    struct gcDeviceHub *hub; /* the world's devices: HIP slots read, forces fed every haptic tick */

    /* Haptic loop only. */
    unsigned char *hstate;
    double *last_touch;       /* haptic simulated time of the last touch of the body's chain */
    int32_t *chain;           /* gc_contacts_chain_of() scratch */
    double *device_force;     /* 3 per finger */
    struct gcTickLog *tick_log; /* the world's, sized by gc_world_start; NULL when off */
    gcHipFollow *follow;      /* per finger: walking towards the last pushed sample */
    gcRuntimeDeviceFinger *device_finger; /* per finger: its device slot as taken */
    gcForceGate gate;         /* the safety stage's (always enabled: ready = watchdog and input) */
    gcShown shown;            /* the last snapshot, for the world's queries (world->shown) */
    double follow_prev_t;     /* time stamp of the last pushed sample taken */
    const gcHipTrack *track;  /* the world's scripted track (fixed while running), or NULL */
    double object_time_seen;
    uint64_t object_seq_seen;  /* the object tick whose message the loop holds (the schedule) */
    uint64_t object_reads;     /* object ticks that read a message before this tick's (the schedule) */
    int64_t prev_tick_ns, last_input_ns;
    int was_stale;
    uint64_t tick;

    /* Object manager only. */
    unsigned char *ostate;
    uint64_t object_seq;      /* object ticks run since the start */

    /* Replaying a recorded schedule (runtime_replay.c), manual clock only; NULL otherwise. */
    const double *replay_hips;        /* this tick's HIPs, 3 per finger */
    const double *replay_orientations; /* this tick's orientations, 4 per finger, or NULL */
    void *replay_record;              /* this tick's record goes here instead of the tick log */
    int replaying;                    /* object results go to replay_queue, not to the haptic loop */
    gcObjectMsg *replay_queue;        /* GC_REPLAY_QUEUE results made, not yet delivered: seq % size */

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

static inline int gc_runtime_running(const gcWorld *w) {
    return w && w->runtime && atomic_load_explicit(&w->runtime->state, memory_order_acquire) == GC_RUNTIME_RUNNING;
}

/* A body's state from a channel message into a shadow (channels). */
void gc_runtime_body_load(gcWorld *s, int32_t i, const gcRuntimeBody *o);
/* The haptic loop's message to the object manager. */
void gc_runtime_publish_to_object(gcRuntime *rt);
/* The object manager's message to the haptic loop. */
void gc_runtime_publish_to_haptic(gcRuntime *rt);
/* A result a replay held back, published to the haptic loop now (runtime_replay.c). */
void gc_runtime_deliver_to_haptic(gcRuntime *rt, const gcObjectMsg *held);
/* The haptic loop's view for gc_world_snapshot. */
void gc_runtime_publish_display(gcRuntime *rt, int64_t now, int forces_enabled);
/* One haptic tick at clock time now (handover). */
void gc_runtime_haptic_tick(gcRuntime *rt, int64_t now);
/* One object tick (handover). */
void gc_runtime_object_tick(gcRuntime *rt);
/* After the loops ended: each body from the thread that owned it last (handover). */
void gc_runtime_merge_into_world(gcRuntime *rt, gcWorld *w);
/* A haptic period into the jitter statistics (threads). */
void gc_runtime_record_period(gcRuntime *rt, int64_t period);
/* The replay queue's memory, freed with the runtime (replay). */
void gc_runtime_replay_free(gcRuntime *rt);
/* The threads' bodies (threads). */
void *gc_runtime_haptic_main(void *arg);
void *gc_runtime_object_main(void *arg);

#endif
