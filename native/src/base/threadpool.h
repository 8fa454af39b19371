/* A fixed pool of worker threads, created once with the world: the source chapter solves
 * each collision chain independently, in parallel on pre-created threads (docs/solver.md).
 * Private to the core. */
#ifndef GC_THREADPOOL_H
#define GC_THREADPOOL_H

#include "graspcore.h"

/* task(ctx, index) for index in [0, count); any thread may run any index. */
typedef void (*gcTaskFn)(void *ctx, int index);

typedef struct gcPool gcPool;

/* threads = total threads working on a run, the caller included: threads - 1 workers are
 * started here (none for 1). Workers sleep on a condition variable between runs. */
gcStatus gc_pool_create(int threads, gcPool **out_pool);
void gc_pool_destroy(gcPool *pool);

/* Runs task(ctx, i) for every i in [0, count) and returns when all are done. The caller
 * works too. With a NULL pool, one thread, count <= 1, or while another thread is already
 * running a job on this pool, everything runs inline on the caller (same results: tasks
 * must not depend on which thread runs them). */
void gc_pool_run(gcPool *pool, gcTaskFn task, void *ctx, int count);

#endif
