/* Body-body contacts, collision chains and the contact solver (docs/solver.md): what the
 * layers above (the step, the runtime, the world API) may use. The contact system itself,
 * struct gcContactSystem, is private to the contact files (contacts_internal.h). */
#ifndef GC_CONTACTS_H
#define GC_CONTACTS_H

#include "world/body.h"

#include <stdint.h>

/* Storage and the thread pool, made once at world creation (sizes from gcWorldDef). */
gcStatus gc_contacts_create(gcWorld *world);
void gc_contacts_destroy(gcWorld *world);
/* Between gc_dynamics_velocities and gc_dynamics_positions: detect, build chains, solve
 * every chain (in parallel). Changes body velocities, and poses for the position correction. */
void gc_contacts_step(gcWorld *world, double dt);
/* Its two halves. */
void gc_contacts_detect(gcWorld *world);
void gc_contacts_solve(gcWorld *world, double dt);

/* For the runtime's shadow worlds. The collision chain of a body (the dynamic bodies that
 * must be stepped with it) written to out (up to capacity); returns how many there are (the
 * body alone before the first step). */
int gc_contacts_chain_of(const gcWorld *world, int32_t body, int32_t *out, int capacity);
/* The contact state that lives from one step to the next (manifolds: warm start and
 * friction anchors; the broad phase's order), so that dst steps on as src would. */
void gc_contacts_copy_state(gcWorld *dst, const gcWorld *src);
/* dst's contact state from two worlds that stepped disjoint bodies: each manifold from
 * `first` when from_first(ctx, body) says `first` stepped its dynamic body, else from
 * `second` (the broad-phase order too). */
void gc_contacts_merge(gcWorld *dst, const gcWorld *first, const gcWorld *second,
                       int (*from_first)(const void *ctx, int32_t body), const void *ctx);

#endif
