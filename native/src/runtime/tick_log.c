/* The per-tick log: one record per haptic tick in a fixed-size SPSC ring (docs/recording-format.md).
 *
 * The producer is the haptic loop (or gc_world_advance on the manual clock); the consumer is
 * whoever calls gc_world_drain_ticks (the recorder thread). The ring is sized at gc_world_start,
 * so the producer never allocates and never waits: a full ring drops the record and counts it. */
#define _POSIX_C_SOURCE 200809L /* clock_gettime */

#include "tick_log.h"

#include <pthread.h>
#include <stddef.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#ifdef __linux__
#include <sys/mman.h>
#include <sys/resource.h>
#endif

#include "world/body.h"
#include "base/gc_math.h"
#include "graspcore.h"

/* tick_fields' rows by name, in the table's order (checked below): fill_record places each field
 * at the offset the table gives it. */
enum {
    F_TICK, F_TIME, F_OBJECT_TIME, F_STATE_HASH, F_PERIOD_US, F_WORK_US, F_FLAGS, F_ADOPTED, F_LOG_US, F_HIP,
    F_GOD_OBJECT, F_FORCE, F_DEVICE_FORCE, F_NORMAL, F_POSE, F_VELOCITY, F_WRENCH, F_STATE, F_CONTACT, F_PARTS,
    F_ORIENTATION, F_PATCH, F_OBJECT_TICK, F_OBJECT_READS, F_COUNT
};
struct gcTickLog {
    int capacity;                 /* records, as asked by gc_world_set_tick_log */
    int num_bodies, num_fingers;  /* the layout the ring was sized for */
    size_t record_size;
    size_t offsets[F_COUNT];      /* of each field in a record of that layout (record_offsets) */
    unsigned char *records;       /* capacity * record_size */
    size_t locked_bytes;          /* of records, locked in RAM (mlock); 0 when not */
    _Atomic uint64_t head;        /* records written (producer) */
    _Atomic uint64_t tail;        /* records drained (consumer) */
    _Atomic uint64_t overflow;    /* records dropped on a full ring since the start */
    int64_t prev_now_ns;          /* producer: the previous tick's clock, for its period */
    float prev_log_us;            /* producer: what recording the previous tick cost (real time) */
    pthread_mutex_t drain_mutex;  /* among drain callers; the producer never takes it */
};

/* The record's fields in order (graspcore.h, docs/recording-format.md): what readers build
 * their layout from and the size is summed from; fill_record writes them in this order. */
static const gcTickField tick_fields[] = {
    {"tick", "<u8", 8, GC_TICK_ONCE, 1, 0},
    {"time", "<f8", 8, GC_TICK_ONCE, 1, 0},
    {"object_time", "<f8", 8, GC_TICK_ONCE, 1, 0},
    {"state_hash", "<u8", 8, GC_TICK_ONCE, 1, 0},
    {"period_us", "<f4", 4, GC_TICK_ONCE, 1, 0},
    {"work_us", "<f4", 4, GC_TICK_ONCE, 1, 0},
    {"flags", "<u4", 4, GC_TICK_ONCE, 1, 0},
    {"adopted", "<u4", 4, GC_TICK_ONCE, 1, 0},
    {"log_us", "<f4", 4, GC_TICK_ONCE, 1, 0},
    {"hip", "<f8", 8, GC_TICK_PER_FINGER, 3, 0},
    {"god_object", "<f8", 8, GC_TICK_PER_FINGER, 3, 0},
    {"force", "<f8", 8, GC_TICK_PER_FINGER, 3, 0},
    {"device_force", "<f8", 8, GC_TICK_PER_FINGER, 3, 0},
    {"normal", "<f8", 8, GC_TICK_PER_FINGER, 3, 0},
    {"pose", "<f8", 8, GC_TICK_PER_BODY, 7, 0},
    {"velocity", "<f8", 8, GC_TICK_PER_BODY, 6, 0},
    {"wrench", "<f8", 8, GC_TICK_PER_BODY, 6, 0},
    {"state", "<i4", 4, GC_TICK_PER_FINGER, 1, 0},
    {"contact", "<i4", 4, GC_TICK_PER_FINGER, 1, 0},
    {"parts", "<u4", 4, GC_TICK_PER_FINGER, 1, 0},
    {"orientation", "<f8", 8, GC_TICK_PER_FINGER, 4, 0},
    {"patch", "<f4", 4, GC_TICK_PER_FINGER, 2 * GC_FINGER_PATCH_CORNERS, 2},
    {"object_tick", "<u8", 8, GC_TICK_ONCE, 1, 0},  /* the hand-over schedule (docs/recording-format.md) */
    {"object_reads", "<u8", 8, GC_TICK_ONCE, 1, 0},
};
_Static_assert(sizeof tick_fields / sizeof tick_fields[0] == F_COUNT, "a row of tick_fields has no F_ name");

/* The trace of gc_world_step_hips_trace: these fields of the record, each one array over the ticks. */
static const int trace_fields[] = {F_TIME, F_CONTACT, F_STATE, F_FORCE, F_GOD_OBJECT, F_POSE};
enum { TRACE_COUNT = sizeof trace_fields / sizeof trace_fields[0] };

/* Bytes of field f in one record of nb bodies and nf fingers. */
static size_t field_bytes(const gcTickField *f, size_t nb, size_t nf) {
    size_t units = f->scope == GC_TICK_PER_FINGER ? nf : f->scope == GC_TICK_PER_BODY ? nb : 1;
    return (size_t)f->size * (size_t)f->count * units;
}

/* Where each field starts in one record of nb bodies and nf fingers. */
static void record_offsets(size_t nb, size_t nf, size_t off[F_COUNT]) {
    size_t at = 0;
    for (int i = 0; i < F_COUNT; ++i) {
        off[i] = at;
        at += field_bytes(&tick_fields[i], nb, nf);
    }
}

int gc_tick_record_fields(const gcTickField **fields) {
    if (fields) *fields = tick_fields;
    return (int)(sizeof tick_fields / sizeof tick_fields[0]);
}

size_t gc_tick_record_size(int num_bodies, int num_fingers) {
    if (num_bodies < 0 || num_fingers < 0) return 0;
    size_t size = 0;
    for (int i = 0; i < F_COUNT; ++i) size += field_bytes(&tick_fields[i], (size_t)num_bodies, (size_t)num_fingers);
    return size;
}

#define FNV_PRIME 1099511628211ull
#define FNV_PRIME4 (FNV_PRIME * FNV_PRIME * FNV_PRIME * FNV_PRIME)

/* FNV-1a over the state variables, in id order, eight bytes a step (the tail byte by byte):
 * each step is a bijection of h, so states differing in one word always hash apart; a
 * fifth of the cost of FNV-1a byte by byte (recordings hash every haptic tick). */
static uint64_t hash_bytes(uint64_t h, const void *data, size_t n) {
    const unsigned char *p = data;
    for (; n >= 8; p += 8, n -= 8) {
        uint64_t v;
        memcpy(&v, p, 8);
        h = (h ^ v) * FNV_PRIME;
    }
    for (; n > 0; ++p, --n) {
        h ^= *p;
        h *= FNV_PRIME;
    }
    return h;
}

/* hash_bytes of a 4-byte field (a part id, a finger state): byte by byte, but when its last
 * three bytes are zero, as for small ids and enums, each of their steps is (h ^ 0) * P, so
 * the four steps are ((h ^ byte 0) * P) * P^3 = (h ^ byte 0) * P^4 (mod 2^64): the same value
 * with a quarter of the dependent multiplies (the fingers' chain is serial). */
static uint64_t hash_4(uint64_t h, const void *data) {
    unsigned char b[4];
    memcpy(b, data, 4);
    if ((b[1] | b[2] | b[3]) == 0) return (h ^ b[0]) * FNV_PRIME4;
    return hash_bytes(h, b, 4);
}

/* While the runtime runs, what the last snapshot showed (as the world's queries answer). */
static const gcBodyState *hashed_state(const gcWorld *w, int i) {
    return w->shown ? &w->shown->bodies[i] : &w->bodies[i].state;
}

/* Word j (0..12) of a body's hashed state: com, q, v, w (R between q and v is derived). */
static uint64_t state_word(const gcBodyState *s, int j) {
    size_t off = j < 3 ? offsetof(gcBodyState, com) + 8 * (size_t)j
                 : j < 7 ? offsetof(gcBodyState, q) + 8 * (size_t)(j - 3)
                 : j < 10 ? offsetof(gcBodyState, v) + 8 * (size_t)(j - 7)
                          : offsetof(gcBodyState, w) + 8 * (size_t)(j - 10);
    uint64_t v;
    memcpy(&v, (const unsigned char *)s + off, 8);
    return v;
}

/* The time and the bodies. Bodies in four lanes (body i in lane i % 4): four independent
 * multiply chains, folded in lane order; a word that differs still changes its lane, and so
 * the hash. Four bodies at a time, word by word, so that the four chains run side by side. */
static uint64_t hash_time_bodies(const gcWorld *w) {
    uint64_t h = 14695981039346656037ull;
    double time = w->shown ? w->shown->time : w->time;
    h = hash_bytes(h, &time, sizeof time);
    uint64_t l0 = h, l1 = h + 1, l2 = h + 2, l3 = h + 3;
    const int nb = w->num_bodies;
    int i = 0;
    for (; i + 4 <= nb; i += 4) {
        const gcBodyState *s0 = hashed_state(w, i), *s1 = hashed_state(w, i + 1);
        const gcBodyState *s2 = hashed_state(w, i + 2), *s3 = hashed_state(w, i + 3);
        for (int j = 0; j < 13; ++j) {
            l0 = (l0 ^ state_word(s0, j)) * FNV_PRIME;
            l1 = (l1 ^ state_word(s1, j)) * FNV_PRIME;
            l2 = (l2 ^ state_word(s2, j)) * FNV_PRIME;
            l3 = (l3 ^ state_word(s3, j)) * FNV_PRIME;
        }
    }
    uint64_t lane[4] = {l0, l1, l2, l3};
    for (; i < nb; ++i)
        for (int j = 0; j < 13; ++j) lane[i & 3] = (lane[i & 3] ^ state_word(hashed_state(w, i), j)) * FNV_PRIME;
    return hash_bytes(h, lane, sizeof lane);
}

/* Then each finger in id order (a serial chain): its HIP and force (as shown), its contacts. */
static uint64_t hash_finger(uint64_t h, const gcWorld *w, int i) {
    const gcFinger *f = &w->fingers[i], *shown = w->shown ? &w->shown->fingers[i] : f;
    const gcFingerModel *fm = &w->model->fingers[i];
    h = hash_bytes(h, &shown->hip, sizeof shown->hip);
    h = hash_bytes(h, &shown->force, sizeof shown->force);
    if (fm->num_vertices) h = hash_bytes(h, &f->q, sizeof f->q); /* a convex finger's orientation */
    if (fm->renderer == GC_RENDERER_CURSOR) { /* its own state (xFCA fingers hash as before) */
        h = hash_bytes(h, &f->cursor, sizeof f->cursor);
        h = hash_bytes(h, &f->cursor_velocity, sizeof f->cursor_velocity);
    }
    for (int c = 0; c < f->num_contacts; ++c) {
        const gcFingerContact *k = &f->contacts[c];
        if (fm->num_vertices) h = hash_4(h, &k->sample), h = hash_4(h, &k->reversed);
        h = hash_4(h, &k->part);
        h = hash_4(h, &k->state);
        h = hash_bytes(h, &k->go_local, sizeof k->go_local);
        h = hash_bytes(h, &k->normal_local, sizeof k->normal_local);
        if (fm->torsion > 0.0) h = hash_bytes(h, &k->twist_local, sizeof k->twist_local);
    }
    return h;
}

uint64_t gc_tick_state_hash(const gcWorld *w) {
    uint64_t h = hash_time_bodies(w);
    for (int i = 0; i < w->num_fingers; ++i) h = hash_finger(h, w, i);
    return h;
}

/* One record of world `w`: device forces given (NULL: the physics forces, no safety layer).
 * The layout is docs/recording-format.md's, field by field; the state hash is
 * gc_tick_state_hash's, computed here finger by finger beside the fingers' fields so that its
 * dependent multiply chain overlaps the copies. */
static void fill_record(const size_t off[F_COUNT], const gcWorld *w, const double *device_force, uint64_t tick,
                        double object_time, gcTickSchedule schedule, float period_us, float work_us, uint32_t flags, uint32_t adopted,
                        float log_us, unsigned char *out) {
    const size_t nb = (size_t)w->num_bodies, nf = (size_t)w->num_fingers;
    unsigned char *hip = out + off[F_HIP], *go = out + off[F_GOD_OBJECT], *force = out + off[F_FORCE];
    unsigned char *dev = out + off[F_DEVICE_FORCE], *normal = out + off[F_NORMAL], *pose = out + off[F_POSE];
    unsigned char *vel = out + off[F_VELOCITY], *wrench = out + off[F_WRENCH], *state = out + off[F_STATE];
    unsigned char *contact = out + off[F_CONTACT], *parts = out + off[F_PARTS];
    unsigned char *orientation = out + off[F_ORIENTATION], *patch = out + off[F_PATCH];
    uint64_t hash = hash_time_bodies(w);
    memcpy(out + off[F_TICK], &tick, 8);
    memcpy(out + off[F_TIME], &w->time, 8);
    memcpy(out + off[F_OBJECT_TIME], &object_time, 8);
    memcpy(out + off[F_PERIOD_US], &period_us, 4);
    memcpy(out + off[F_WORK_US], &work_us, 4);
    memcpy(out + off[F_FLAGS], &flags, 4);
    memcpy(out + off[F_ADOPTED], &adopted, 4);
    memcpy(out + off[F_LOG_US], &log_us, 4);
    for (size_t i = 0; i < nf; ++i) {
        const gcFinger *f = &w->fingers[i];
        hash = hash_finger(hash, w, (int)i);
        memcpy(hip + 24 * i, &f->hip, 24);
        memcpy(go + 24 * i, &f->god_object, 24);
        memcpy(force + 24 * i, &f->force, 24);
        memcpy(dev + 24 * i, device_force ? (const void *)&device_force[3 * i] : (const void *)&f->force, 24);
        memcpy(normal + 24 * i, &f->normal, 24);
        int32_t s = (int32_t)f->state;
        memcpy(state + 4 * i, &s, 4);
        memcpy(contact + 4 * i, &f->contact_body, 4);
        /* The convex parts touched, by index in their body: a change is a change of part. */
        uint32_t mask = 0;
        for (int c = 0; c < f->num_contacts; ++c) {
            int32_t k = f->contacts[c].part - w->model->bodies[w->model->parts[f->contacts[c].part].body].first_part;
            mask |= 1u << (k < 31 ? k : 31);
        }
        memcpy(parts + 4 * i, &mask, 4);
        double q[4] = {f->q.w, f->q.x, f->q.y, f->q.z};
        memcpy(orientation + 32 * i, q, 32);
        memcpy(patch + sizeof f->patch * i, f->patch, sizeof f->patch);
    }
    memcpy(pose, w->pose_array, 56 * nb);
    for (size_t b = 0; b < nb; ++b) { /* of the body frame origin, as gc_world_body_velocity */
        const gcBodyState *st = &w->bodies[b].state;
        gcVec3 v = gc_body_origin_velocity(&w->model->bodies[b], st);
        memcpy(vel + 48 * b, &v, 24);
        memcpy(vel + 48 * b + 24, &st->w, 24);
        memcpy(wrench + 48 * b, &st->residual_force, 24);
        memcpy(wrench + 48 * b + 24, &st->residual_torque, 24);
    }
    memcpy(out + off[F_OBJECT_TICK], &schedule.object_tick, 8);
    memcpy(out + off[F_OBJECT_READS], &schedule.object_reads, 8);
    memcpy(out + off[F_STATE_HASH], &hash, 8);
}

int gc_tick_trace_fields(const char *const **names) {
    static const char *trace_names[TRACE_COUNT];
    for (int i = 0; i < TRACE_COUNT; ++i) trace_names[i] = tick_fields[trace_fields[i]].name;
    if (names) *names = trace_names;
    return TRACE_COUNT;
}

size_t gc_tick_trace_size(int num_bodies, int num_fingers) {
    if (num_bodies < 0 || num_fingers < 0) return 0;
    size_t size = 0;
    for (int i = 0; i < TRACE_COUNT; ++i)
        size += field_bytes(&tick_fields[trace_fields[i]], (size_t)num_bodies, (size_t)num_fingers);
    return size;
}

/* Tick k of `total` into the trace: each trace field one array over the ticks, in trace_fields'
 * order, tick k's values at k times the field's bytes in a record. */
void gc_tick_trace_fill(const gcWorld *w, void *out, size_t k, size_t total) {
    const size_t nb = (size_t)w->num_bodies, nf = (size_t)w->num_fingers;
    unsigned char *at[F_COUNT] = {0}, *base = out;
    for (int i = 0; i < TRACE_COUNT; ++i) {
        size_t bytes = field_bytes(&tick_fields[trace_fields[i]], nb, nf);
        at[trace_fields[i]] = base + bytes * k;
        base += bytes * total;
    }
    memcpy(at[F_TIME], &w->time, 8);
    for (size_t i = 0; i < nf; ++i) {
        const gcFinger *f = &w->fingers[i];
        int32_t s = (int32_t)f->state;
        memcpy(at[F_CONTACT] + 4 * i, &f->contact_body, 4);
        memcpy(at[F_STATE] + 4 * i, &s, 4);
        memcpy(at[F_FORCE] + 24 * i, &f->force, 24);
        memcpy(at[F_GOD_OBJECT] + 24 * i, &f->god_object, 24);
    }
    memcpy(at[F_POSE], w->pose_array, 56 * nb);
}

gcStatus gc_world_tick_record(gcWorld *w, uint64_t tick, void *out, size_t size) {
    if (!w || !out) return GC_ERR_INVALID_ARGUMENT;
    if (w->locked) {
        gc_world_set_error(w, "tick_record: the runtime is running (its ticks are in the tick log)");
        return GC_ERR_BUSY;
    }
    size_t need = gc_tick_record_size(w->num_bodies, w->num_fingers);
    if (size < need) {
        gc_world_set_error(w, "tick_record: buffer of %zu bytes, a record needs %zu", size, need);
        return GC_ERR_INVALID_ARGUMENT;
    }
    size_t off[F_COUNT];
    record_offsets((size_t)w->num_bodies, (size_t)w->num_fingers, off);
    fill_record(off, w, NULL, tick, w->time, (gcTickSchedule){0, 0}, 0.0f, 0.0f, 1u, 0u, 0.0f, out);
    return GC_OK;
}

/* The ring is written every tick and read by the recorder, megabytes cycled every couple of
 * seconds: lock it in RAM so that memory pressure never swaps a page out from under the
 * haptic loop (memset at allocation has faulted every page in). Only when it leaves at least
 * half of RLIMIT_MEMLOCK to the runtime's own blocks, locked after it (runtime.c); refused or
 * too large, the ring is simply not locked. */
static void lock_records(gcTickLog *log, size_t bytes) {
    log->locked_bytes = 0;
#ifdef __linux__
    struct rlimit lim;
    if (getrlimit(RLIMIT_MEMLOCK, &lim) != 0) return;
    if (lim.rlim_cur != RLIM_INFINITY && bytes > lim.rlim_cur / 2) return;
    if (mlock(log->records, bytes) == 0) log->locked_bytes = bytes;
#else
    (void)bytes;
#endif
}

static void free_records(gcTickLog *log) {
#ifdef __linux__
    if (log->locked_bytes) munlock(log->records, log->locked_bytes);
#endif
    log->locked_bytes = 0;
    free(log->records);
    log->records = NULL;
}

gcStatus gc_world_set_tick_log(gcWorld *w, int capacity) {
    if (!w) return GC_ERR_INVALID_ARGUMENT;
    if (w->locked) {
        gc_world_set_error(w, "set_tick_log: the runtime is running: stop it first");
        return GC_ERR_BUSY;
    }
    if (capacity < 0 || capacity > (1 << 22)) {
        gc_world_set_error(w, "capacity: must be 0 (off) to %d records (got %d)", 1 << 22, capacity);
        return GC_ERR_INVALID_ARGUMENT;
    }
    if (capacity == 0) {
        gc_tick_log_free(w);
        return GC_OK;
    }
    if (!w->tick_log) {
        gcTickLog *log = calloc(1, sizeof *log);
        if (!log) return GC_ERR_NO_MEMORY;
        pthread_mutex_init(&log->drain_mutex, NULL);
        w->tick_log = log;
    }
    if (w->tick_log->capacity != capacity) {
        free_records(w->tick_log);
        w->tick_log->record_size = 0;
        w->tick_log->capacity = capacity;
    }
    return GC_OK;
}

gcTickLog *gc_tick_log_begin(gcWorld *w, gcStatus *status) {
    gcTickLog *log = w->tick_log;
    *status = GC_OK;
    if (!log) return NULL;
    pthread_mutex_lock(&log->drain_mutex); /* a drain from another thread waits for the new ring */
    size_t size = gc_tick_record_size(w->num_bodies, w->num_fingers);
    record_offsets((size_t)w->num_bodies, (size_t)w->num_fingers, log->offsets); /* once: the haptic tick reads them */
    if (!log->records || size != log->record_size) {
        free_records(log);
        log->records = malloc((size_t)log->capacity * size);
        log->record_size = log->records ? size : 0;
        if (!log->records) {
            gc_world_set_error(w, "tick log: out of memory for %d records of %zu bytes", log->capacity, size);
            *status = GC_ERR_NO_MEMORY;
            pthread_mutex_unlock(&log->drain_mutex);
            return NULL;
        }
        /* Touch every page now: the haptic loop must not take page faults on its first lap. */
        memset(log->records, 0, (size_t)log->capacity * size);
        lock_records(log, (size_t)log->capacity * size);
    }
    log->num_bodies = w->num_bodies;
    log->num_fingers = w->num_fingers;
    atomic_store(&log->head, 0);
    atomic_store(&log->tail, 0);
    atomic_store(&log->overflow, 0);
    log->prev_now_ns = INT64_MIN;
    log->prev_log_us = 0.0f;
    pthread_mutex_unlock(&log->drain_mutex);
    return log;
}

void gc_tick_log_free(gcWorld *w) {
    if (!w->tick_log) return;
    pthread_mutex_destroy(&w->tick_log->drain_mutex);
    free_records(w->tick_log);
    free(w->tick_log);
    w->tick_log = NULL;
}

static int64_t monotonic_ns(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}

void gc_tick_log_prefetch(const gcTickLog *log) {
    /* The slot the coming push fills: a ring laps in seconds, so its lines are in no cache
     * of this core; fetched now, they arrive while the tick computes (a full ring: a slot the
     * recorder may be reading, fetched for nothing, harmlessly). With write intent where the
     * target has PREFETCHW, else a plain T0 prefetch (the line still arrives exclusive when no
     * other core holds it). Not the world's state: the tick reads it itself just before the
     * push (the display publication), and prefetching it too measured no better. */
    uint64_t head = atomic_load_explicit(&log->head, memory_order_relaxed);
    const unsigned char *slot = log->records + (head % (uint64_t)log->capacity) * log->record_size;
    const uintptr_t end = (uintptr_t)slot + log->record_size;
    for (uintptr_t a = (uintptr_t)slot & ~(uintptr_t)63; a < end; a += 64)
        __builtin_prefetch((const void *)a, 1, 3);
}

void gc_tick_record_fill(const gcWorld *hw, const double *device_force, uint64_t tick, double object_time,
                         gcTickSchedule schedule, int forces_enabled, int adopted, void *out) {
    size_t off[F_COUNT];
    record_offsets((size_t)hw->num_bodies, (size_t)hw->num_fingers, off);
    fill_record(off, hw, device_force, tick, object_time, schedule, 0.0f, 0.0f, forces_enabled ? (uint32_t)GC_TICK_FORCES_ENABLED : 0u,
                (uint32_t)adopted, 0.0f, out);
}

void gc_tick_log_push(gcTickLog *log, const gcWorld *hw, const double *device_force, uint64_t tick,
                      double object_time, gcTickSchedule schedule, int64_t now_ns, int realtime, int forces_enabled,
                      int adopted) {
    float period_us = log->prev_now_ns == INT64_MIN ? 0.0f : (float)((now_ns - log->prev_now_ns) * 1e-3);
    log->prev_now_ns = now_ns;
    int64_t t0 = monotonic_ns();
    /* From the wake-up to here: this tick's work (real-time clock only). */
    float work_us = realtime ? (float)((t0 - now_ns) * 1e-3) : 0.0f;
    uint64_t head = atomic_load_explicit(&log->head, memory_order_relaxed);
    uint64_t tail = atomic_load_explicit(&log->tail, memory_order_acquire);
    if (head - tail >= (uint64_t)log->capacity) {
        atomic_fetch_add_explicit(&log->overflow, 1, memory_order_relaxed);
        return;
    }
    unsigned char *slot = log->records + (head % (uint64_t)log->capacity) * log->record_size;
    fill_record(log->offsets, hw, device_force, tick, object_time, schedule, period_us, work_us, forces_enabled ? (uint32_t)GC_TICK_FORCES_ENABLED : 0u,
                (uint32_t)adopted, log->prev_log_us, slot);
    atomic_store_explicit(&log->head, head + 1, memory_order_release);
    log->prev_log_us = (float)((monotonic_ns() - t0) * 1e-3);
}

int gc_world_drain_ticks(gcWorld *w, void *out, size_t size, int max_records) {
    if (!w || !out || max_records < 0) return GC_ERR_INVALID_ARGUMENT;
    gcTickLog *log = w->tick_log;
    if (!log || !log->records) return 0;
    pthread_mutex_lock(&log->drain_mutex);
    uint64_t tail = atomic_load_explicit(&log->tail, memory_order_relaxed);
    uint64_t head = atomic_load_explicit(&log->head, memory_order_acquire);
    uint64_t n = head - tail;
    uint64_t room = size / log->record_size;
    if (n > room) n = room;
    if (n > (uint64_t)max_records) n = (uint64_t)max_records;
    unsigned char *dst = out;
    for (uint64_t k = 0; k < n; ++k)
        memcpy(dst + k * log->record_size,
               log->records + ((tail + k) % (uint64_t)log->capacity) * log->record_size, log->record_size);
    atomic_store_explicit(&log->tail, tail + n, memory_order_release);
    pthread_mutex_unlock(&log->drain_mutex);
    return (int)n;
}

uint64_t gc_world_tick_log_overflow(const gcWorld *w) {
    return w && w->tick_log ? atomic_load_explicit(&w->tick_log->overflow, memory_order_relaxed) : 0;
}
