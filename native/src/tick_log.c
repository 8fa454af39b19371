/* The per-tick log: one record per haptic tick in a fixed-size SPSC ring (docs/recording-format.md).
 *
 * The producer is the haptic loop (or gc_world_advance on the manual clock); the consumer is
 * whoever calls gc_world_drain_ticks (the recorder thread). The ring is sized at gc_world_start,
 * so the producer never allocates and never waits: a full ring drops the record and counts it. */
#define _POSIX_C_SOURCE 200809L /* clock_gettime */

#include "tick_log.h"

#include <pthread.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "body.h"
#include "gc_math.h"
#include "graspcore.h"

struct gcTickLog {
    int capacity;                 /* records, as asked by gc_world_set_tick_log */
    int num_bodies, num_fingers;  /* the layout the ring was sized for */
    size_t record_size;
    unsigned char *records;       /* capacity * record_size */
    _Atomic uint64_t head;        /* records written (producer) */
    _Atomic uint64_t tail;        /* records drained (consumer) */
    _Atomic uint64_t overflow;    /* records dropped on a full ring since the start */
    int64_t prev_now_ns;          /* producer: the previous tick's clock, for its period */
    float prev_log_us;            /* producer: what recording the previous tick cost (real time) */
    pthread_mutex_t drain_mutex;  /* among drain callers; the producer never takes it */
};

/* Field offsets inside a record (all little-endian; the f64 arrays first, then the i32). */
enum { REC_HEADER = 52 };

size_t gc_tick_record_size(int num_bodies, int num_fingers) {
    if (num_bodies < 0 || num_fingers < 0) return 0;
    return REC_HEADER + sizeof(double) * (15 * (size_t)num_fingers + 19 * (size_t)num_bodies) +
           sizeof(int32_t) * 2 * (size_t)num_fingers;
}

/* FNV-1a over the state variables, in id order, eight bytes a step (the tail byte by byte):
 * each step is a bijection of h, so states differing in one word always hash apart; a
 * fifth of the cost of FNV-1a byte by byte (recordings hash every haptic tick). */
static uint64_t hash_bytes(uint64_t h, const void *data, size_t n) {
    const unsigned char *p = data;
    for (; n >= 8; p += 8, n -= 8) {
        uint64_t v;
        memcpy(&v, p, 8);
        h = (h ^ v) * 1099511628211ull;
    }
    for (; n > 0; ++p, --n) {
        h ^= *p;
        h *= 1099511628211ull;
    }
    return h;
}

uint64_t gc_tick_state_hash(const gcWorld *w) {
    /* While the runtime runs, what the last snapshot showed (as the world's queries answer). */
    uint64_t h = 14695981039346656037ull;
    double time = w->shown ? w->shown->time : w->time;
    h = hash_bytes(h, &time, sizeof time);
    /* Bodies in four lanes (body i in lane i % 4): four independent multiply chains, folded in
     * lane order; a word that differs still changes its lane, and so the hash. */
    uint64_t lane[4] = {h, h + 1, h + 2, h + 3};
    for (int i = 0; i < w->num_bodies; ++i) {
        const gcBodyState *s = w->shown ? &w->shown->bodies[i] : &w->bodies[i].state;
        uint64_t l = lane[i & 3];
        l = hash_bytes(l, &s->com, sizeof s->com);
        l = hash_bytes(l, &s->q, sizeof s->q);
        l = hash_bytes(l, &s->v, sizeof s->v);
        l = hash_bytes(l, &s->w, sizeof s->w);
        lane[i & 3] = l;
    }
    h = hash_bytes(h, lane, sizeof lane);
    for (int i = 0; i < w->num_fingers; ++i) {
        const gcFinger *f = &w->fingers[i], *shown = w->shown ? &w->shown->fingers[i] : f;
        h = hash_bytes(h, &shown->hip, sizeof shown->hip);
        h = hash_bytes(h, &shown->force, sizeof shown->force);
        for (int c = 0; c < f->num_contacts; ++c) {
            const gcFingerContact *k = &f->contacts[c];
            h = hash_bytes(h, &k->part, sizeof k->part);
            h = hash_bytes(h, &k->state, sizeof k->state);
            h = hash_bytes(h, &k->go_local, sizeof k->go_local);
            h = hash_bytes(h, &k->normal_local, sizeof k->normal_local);
        }
    }
    return h;
}

static unsigned char *put(unsigned char *p, const void *v, size_t n) {
    memcpy(p, v, n);
    return p + n;
}

/* One record of world `w`: device forces given (NULL: the physics forces, no safety layer). */
static void fill_record(const gcWorld *w, const double *device_force, uint64_t tick, double object_time,
                        float period_us, float work_us, uint32_t flags, uint32_t adopted, float log_us,
                        unsigned char *out) {
    const int nb = w->num_bodies, nf = w->num_fingers;
    uint64_t hash = gc_tick_state_hash(w);
    unsigned char *p = out;
    p = put(p, &tick, 8);
    p = put(p, &w->time, 8);
    p = put(p, &object_time, 8);
    p = put(p, &hash, 8);
    p = put(p, &period_us, 4);
    p = put(p, &work_us, 4);
    p = put(p, &flags, 4);
    p = put(p, &adopted, 4);
    p = put(p, &log_us, 4);
    for (int i = 0; i < nf; ++i) p = put(p, &w->fingers[i].hip, 24);
    for (int i = 0; i < nf; ++i) p = put(p, &w->fingers[i].god_object, 24);
    for (int i = 0; i < nf; ++i) p = put(p, &w->fingers[i].force, 24);
    if (device_force)
        p = put(p, device_force, 24 * (size_t)nf);
    else
        for (int i = 0; i < nf; ++i) p = put(p, &w->fingers[i].force, 24);
    for (int i = 0; i < nf; ++i) { /* the first contact's plane normal, world (0 when free) */
        const gcFinger *f = &w->fingers[i];
        gcVec3 n = gc_v3(0, 0, 0);
        if (f->num_contacts > 0 && f->contacts[0].part >= 0) {
            const gcBody *b = &w->bodies[w->parts[f->contacts[0].part].body];
            n = gc_mat3_mul_vec(&b->state.R, f->contacts[0].normal_local);
        }
        p = put(p, &n, 24);
    }
    p = put(p, w->pose_array, 56 * (size_t)nb);
    for (int b = 0; b < nb; ++b) { /* of the body frame origin, as gc_world_body_velocity */
        const gcBody *body = &w->bodies[b];
        const gcBodyState *st = &body->state;
        gcVec3 v = gc_add(st->v, gc_cross(st->w, gc_mat3_mul_vec(&st->R, gc_neg(body->com_local))));
        p = put(p, &v, 24);
        p = put(p, &st->w, 24);
    }
    for (int b = 0; b < nb; ++b) {
        p = put(p, &w->bodies[b].state.residual_force, 24);
        p = put(p, &w->bodies[b].state.residual_torque, 24);
    }
    for (int i = 0; i < nf; ++i) {
        int32_t s = (int32_t)w->fingers[i].state;
        p = put(p, &s, 4);
    }
    for (int i = 0; i < nf; ++i) p = put(p, &w->fingers[i].contact_body, 4);
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
    fill_record(w, NULL, tick, w->time, 0.0f, 0.0f, 1u, 0u, 0.0f, out);
    return GC_OK;
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
        free(w->tick_log->records);
        w->tick_log->records = NULL;
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
    if (!log->records || size != log->record_size) {
        free(log->records);
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
    free(w->tick_log->records);
    free(w->tick_log);
    w->tick_log = NULL;
}

static int64_t monotonic_ns(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}

void gc_tick_log_push(gcTickLog *log, const gcWorld *hw, const double *device_force, uint64_t tick,
                      double object_time, int64_t now_ns, int realtime, int forces_enabled,
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
    fill_record(hw, device_force, tick, object_time, period_us, work_us, forces_enabled ? 1u : 0u,
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
