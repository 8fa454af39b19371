/* The real-time runtime (runtime.c, docs/runtime.md): what world.c needs to know of it. */
#ifndef GC_RUNTIME_H
#define GC_RUNTIME_H

#include "world_internal.h"

/* 1 from gc_world_start to gc_world_stop: the runtime owns the world's dynamic state, so
 * the world's mutating calls answer GC_ERR_BUSY. */
int gc_runtime_running(const gcWorld *world);
/* Stops the runtime if it runs (joining its threads) and frees it; for gc_world_destroy. */
void gc_runtime_free(gcWorld *world);

#endif
