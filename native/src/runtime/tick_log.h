/* The per-tick log (tick_log.c, docs/recording-format.md): a fixed-size single-producer,
 * single-consumer ring of tick records that the haptic loop fills at the end of every tick
 * and a recorder drains. What runtime.c and world.c need of it. */
#ifndef GC_TICK_LOG_H
#define GC_TICK_LOG_H

#include "world/world.h"

typedef struct gcTickLog gcTickLog;

/* The threaded runtime's hand-over schedule at a haptic tick (docs/recording-format.md): the
 * object manager tick whose result the haptic loop holds, and how many object ticks had read
 * the haptic loop's messages before this tick published its own. 0 and 0 outside the runtime. */
typedef struct gcTickSchedule {
    uint64_t object_tick, object_reads;
} gcTickSchedule;

/* gc_world_state_hash (world_api.c): the bit-exact state hash, here because every recorded
 * tick carries it. */
uint64_t gc_tick_state_hash(const gcWorld *world);
/* gc_world_start: (re)size the world's ring for its current bodies and fingers and empty it.
 * Returns the ring (NULL when the log is off) or sets *status on failure. */
gcTickLog *gc_tick_log_begin(gcWorld *world, gcStatus *status);
/* gc_world_destroy. */
void gc_tick_log_free(gcWorld *world);
/* The haptic loop, at the start of a tick: fetch the ring slot gc_tick_log_push will fill,
 * so that its cache misses overlap the tick's work instead of stalling the push. */
void gc_tick_log_prefetch(const gcTickLog *log);
/* The haptic loop, once a tick: one record of the shadow world `hw` and the device forces.
 * Never blocks, never allocates; a full ring drops the record and counts it. */
void gc_tick_log_push(gcTickLog *log, const gcWorld *hw, const double *device_force, uint64_t tick,
                      double object_time, gcTickSchedule schedule, int64_t now_ns, int realtime, int forces_enabled,
                      int adopted);
/* A stepped world's trace (gc_world_step_hips_trace) as tick k of `total` in the fields of out. */
void gc_tick_trace_fill(const gcWorld *w, void *out, size_t k, size_t total);
/* A replayed haptic tick (runtime_replay.c): its record straight into `out`, no ring, no clock. */
void gc_tick_record_fill(const gcWorld *hw, const double *device_force, uint64_t tick, double object_time,
                         gcTickSchedule schedule, int forces_enabled, int adopted, void *out);

#endif
