/* Worker pool for the contact phases (narrow phase per pair, solver per chain).
 *
 * One job at a time: the caller publishes (task, ctx, count), opens the job, bumps a
 * generation counter and wakes the workers; everyone, the caller included, takes indices
 * from an atomic counter until none are left. The caller then closes the job and waits only
 * for the workers that joined it (they are finishing their last task): a worker that wakes
 * late, after the job closed, never touches it, so a descheduled worker never delays the
 * caller. Workers sleep on a condition variable between jobs.
 * Which thread runs which index is not deterministic, so tasks write only to storage owned
 * by their index: results do not depend on the thread count (docs/solver.md). */
#define _POSIX_C_SOURCE 200809L
#include "threadpool.h"

#include <pthread.h>
#include <stdatomic.h>
#include <stdlib.h>

#define GC_POOL_MAX_THREADS 64

struct gcPool {
    int threads;                /* including the caller */
    int num_workers;
    pthread_t workers[GC_POOL_MAX_THREADS];
    pthread_mutex_t mutex;      /* guards generation, quit, open, busy_workers */
    pthread_cond_t wake;        /* workers wait for a new generation */
    pthread_cond_t done;        /* the caller waits for busy_workers == 0 */
    pthread_mutex_t submit;     /* one job at a time; trylock, else run inline */
    unsigned long generation;
    int quit;
    int open;                   /* the current job still accepts workers */
    int busy_workers;           /* workers inside the current job */
    /* The current job. */
    gcTaskFn task;
    void *ctx;
    int count;
    atomic_int next;
};

static void drain(gcPool *p) {
    for (;;) {
        int i = atomic_fetch_add_explicit(&p->next, 1, memory_order_relaxed);
        if (i >= p->count) break;
        p->task(p->ctx, i);
    }
}

static void *worker_main(void *arg) {
    gcPool *p = arg;
    unsigned long seen = 0;
    pthread_mutex_lock(&p->mutex);
    for (;;) {
        while (!p->quit && p->generation == seen) pthread_cond_wait(&p->wake, &p->mutex);
        if (p->quit) break;
        seen = p->generation;
        if (!p->open) continue; /* woke after the job closed: nothing to do */
        p->busy_workers++;
        pthread_mutex_unlock(&p->mutex);
        drain(p);
        pthread_mutex_lock(&p->mutex);
        if (--p->busy_workers == 0) pthread_cond_signal(&p->done);
    }
    pthread_mutex_unlock(&p->mutex);
    return NULL;
}

gcStatus gc_pool_create(int threads, gcPool **out_pool) {
    if (!out_pool || threads < 1 || threads > GC_POOL_MAX_THREADS) return GC_ERR_INVALID_ARGUMENT;
    *out_pool = NULL;
    gcPool *p = calloc(1, sizeof *p);
    if (!p) return GC_ERR_NO_MEMORY;
    p->threads = threads;
    if (pthread_mutex_init(&p->mutex, NULL)) goto fail_mutex;
    if (pthread_mutex_init(&p->submit, NULL)) goto fail_submit;
    if (pthread_cond_init(&p->wake, NULL)) goto fail_wake;
    if (pthread_cond_init(&p->done, NULL)) goto fail_done;
    atomic_init(&p->next, 0);
    for (int i = 0; i < threads - 1; ++i) {
        if (pthread_create(&p->workers[i], NULL, worker_main, p)) {
            gc_pool_destroy(p);
            return GC_ERR_NO_MEMORY;
        }
        p->num_workers++;
    }
    *out_pool = p;
    return GC_OK;
fail_done:
    pthread_cond_destroy(&p->wake);
fail_wake:
    pthread_mutex_destroy(&p->submit);
fail_submit:
    pthread_mutex_destroy(&p->mutex);
fail_mutex:
    free(p);
    return GC_ERR_NO_MEMORY;
}

void gc_pool_destroy(gcPool *p) {
    if (!p) return;
    pthread_mutex_lock(&p->mutex);
    p->quit = 1;
    pthread_cond_broadcast(&p->wake);
    pthread_mutex_unlock(&p->mutex);
    for (int i = 0; i < p->num_workers; ++i) pthread_join(p->workers[i], NULL);
    pthread_cond_destroy(&p->done);
    pthread_cond_destroy(&p->wake);
    pthread_mutex_destroy(&p->submit);
    pthread_mutex_destroy(&p->mutex);
    free(p);
}


void gc_pool_run(gcPool *p, gcTaskFn task, void *ctx, int count) {
    if (count <= 0) return;
    if (!p || p->num_workers == 0 || count == 1 || pthread_mutex_trylock(&p->submit) != 0) {
        for (int i = 0; i < count; ++i) task(ctx, i);
        return;
    }
    pthread_mutex_lock(&p->mutex);
    p->task = task;
    p->ctx = ctx;
    p->count = count;
    atomic_store_explicit(&p->next, 0, memory_order_relaxed);
    p->busy_workers = 0;
    p->open = 1;
    p->generation++;
    pthread_cond_broadcast(&p->wake);
    pthread_mutex_unlock(&p->mutex);
    drain(p);
    pthread_mutex_lock(&p->mutex);
    p->open = 0;
    while (p->busy_workers > 0) pthread_cond_wait(&p->done, &p->mutex);
    pthread_mutex_unlock(&p->mutex);
    pthread_mutex_unlock(&p->submit);
}
