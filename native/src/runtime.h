/* The real-time runtime (docs/runtime.md): what the world API above it needs. The runtime
 * tells the world it owns the dynamic state by world->locked, never by a call. */
#ifndef GC_RUNTIME_H
#define GC_RUNTIME_H

#include "world_internal.h"

/* Stops the runtime if it runs (joining its threads) and frees it; for gc_world_destroy. */
void gc_runtime_free(gcWorld *world);
/* gc_world_push_finger_poses for the device threads (orientations NULL: positions only): the
 * same checks and effect, but no error message (the world's last error belongs to the API
 * thread). GC_ERR_NOT_RUNNING while stopped. */
gcStatus gc_runtime_push_input(gcWorld *world, const double *positions, const double *orientations, int count,
                               double t);

#endif
