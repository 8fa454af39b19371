/* The real-time runtime (docs/runtime.md): what the world API above it needs. The runtime
 * tells the world it owns the dynamic state by world->locked, never by a call. */
#ifndef GC_RUNTIME_H
#define GC_RUNTIME_H

#include "world/world.h"

/* Stops the runtime if it runs (joining its threads) and frees it; for gc_world_destroy. */
void gc_runtime_free(gcWorld *world);

#endif
