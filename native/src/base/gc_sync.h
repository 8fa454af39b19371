/* The small helpers every threaded file shares (the runtime's loops, the device threads): the
 * monotonic clock, doubles in relaxed atomics, counters, and the triple buffer. Header only. */
#ifndef GC_SYNC_H
#define GC_SYNC_H

#include <errno.h>
#include <stdatomic.h>
#include <stdint.h>
#include <string.h>
#include <time.h>

#define GC_NS_PER_S 1000000000LL

static inline int64_t gc_clock_now_ns(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * GC_NS_PER_S + ts.tv_nsec;
}

static inline void gc_sleep_until_ns(int64_t t) {
    struct timespec ts = {(time_t)(t / GC_NS_PER_S), (long)(t % GC_NS_PER_S)};
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, NULL) == EINTR) {
    }
}

static inline int64_t gc_seconds_to_ns(double s) { return (int64_t)(s * 1e9 + 0.5); }

static inline void gc_atomic_increment(_Atomic uint64_t *c) { atomic_fetch_add_explicit(c, 1, memory_order_relaxed); }

/* A double in an atomic 64-bit slot (relaxed: the fences of a sequence lock order them). */
static inline void gc_atomic_store_double(_Atomic uint64_t *slot, double v) {
    uint64_t bits;
    memcpy(&bits, &v, sizeof bits);
    atomic_store_explicit(slot, bits, memory_order_relaxed);
}

static inline double gc_atomic_load_double(_Atomic uint64_t *slot) {
    uint64_t bits = atomic_load_explicit(slot, memory_order_relaxed);
    double v;
    memcpy(&v, &bits, sizeof v);
    return v;
}

/* A sequence-locked read: acquire, so that the sequence number read after it is not read before. */
static inline double gc_atomic_load_double_acquire(_Atomic uint64_t *slot) {
    uint64_t bits = atomic_load_explicit(slot, memory_order_acquire);
    double v;
    memcpy(&v, &bits, sizeof v);
    return v;
}

/* ---- triple buffer: the latest value from one writer to one reader ------------------ */

/* Three slots of a message: the writer fills `back`, then swaps it with `middle`; the
 * reader swaps `front` with `middle` when `middle` holds something new. Neither side ever
 * waits, and the reader always holds a complete message. */
typedef struct gcTriple {
    _Atomic uint64_t middle; /* slot index | GC_TRIPLE_FRESH while unread (| reads, counted) */
    unsigned back;           /* writer's slot */
    unsigned front;          /* reader's slot */
} gcTriple;
#define GC_TRIPLE_FRESH 4u

static inline void gc_triple_reset(gcTriple *t) {
    t->back = 0;
    t->front = 1;
    atomic_store_explicit(&t->middle, 2u, memory_order_relaxed);
}

static inline void gc_triple_publish(gcTriple *t) {
    t->back = (unsigned)(atomic_exchange_explicit(&t->middle, t->back | GC_TRIPLE_FRESH, memory_order_acq_rel) & 3u);
}

/* The reader's slot, now holding the latest publication; *fresh = 1 when it is new. */
static inline unsigned gc_triple_latest(gcTriple *t, int *fresh) {
    *fresh = 0;
    if (atomic_load_explicit(&t->middle, memory_order_relaxed) & GC_TRIPLE_FRESH) {
        t->front = (unsigned)(atomic_exchange_explicit(&t->middle, t->front, memory_order_acq_rel) & 3u);
        *fresh = 1;
    }
    return t->front;
}

/* The haptic -> object manager channel also counts the object manager's reads, in the bits
 * of `middle` above the slot and the fresh flag: every object tick adds one as it takes the
 * latest message, and every publication learns how many reads came before it. Recorded with
 * each haptic tick, that count says which haptic tick's message each object tick stepped from:
 * half of the hand-over schedule (docs/recording-format.md). A side retries its
 * compare-and-swap only when the other changed the word in between (once per object tick at
 * most), so neither waits on the other. Only the channel's two ends use these. */
#define GC_TRIPLE_COUNT 8u

/* gc_triple_publish, returning the reads made before this publication. */
static inline uint64_t gc_triple_publish_counted(gcTriple *t) {
    uint64_t old = atomic_load_explicit(&t->middle, memory_order_relaxed);
    while (!atomic_compare_exchange_weak_explicit(&t->middle, &old, t->back | GC_TRIPLE_FRESH | (old & ~(uint64_t)7),
                                                  memory_order_acq_rel, memory_order_relaxed)) {
    }
    t->back = (unsigned)(old & 3u);
    return old / GC_TRIPLE_COUNT;
}

/* gc_triple_latest, counting one read. */
static inline unsigned gc_triple_latest_counted(gcTriple *t, int *fresh) {
    uint64_t old = atomic_load_explicit(&t->middle, memory_order_relaxed), next;
    do {
        *fresh = (old & GC_TRIPLE_FRESH) != 0;
        next = (*fresh ? t->front : (old & 7u)) | ((old & ~(uint64_t)7) + GC_TRIPLE_COUNT);
    } while (!atomic_compare_exchange_weak_explicit(&t->middle, &old, next, memory_order_acq_rel,
                                                    memory_order_relaxed));
    if (*fresh) t->front = (unsigned)(old & 3u);
    return t->front;
}

#endif
