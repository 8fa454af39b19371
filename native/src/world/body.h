/* A body's derived state and its effective mass (body.c); with them, the layers below that
 * every file above includes through this header: the argument checks and error message
 * (checks.h) and the small dense solves (small_dense.h). */
#ifndef GC_BODY_H
#define GC_BODY_H

#include "checks.h"
#include "base/small_dense.h"
#include "world.h"

/* After the pose changed: normalised q, R, the pose view, the world AABB. */
void gc_body_refresh_derived(gcWorld *world, int32_t body);

/* The body's (effective mass)^-1 for this step as a row-major 6x6, (linear, angular) world
 * frame, zero for a static or immovable body. A world impulse p at r from the COM changes
 * the twist by M [p; r x p], so contacts see the finger springs as mass. Valid between
 * gc_dynamics_velocities and gc_dynamics_positions. */
void gc_body_inverse_effective_mass(const gcBodyModel *model, const gcBody *body, double M[36]);

/* Velocity of the body frame origin (world), as gc_world_body_velocity reports it, from
 * a body's model and a state of it (the world's, a shadow's or a channel's copy). */
static inline gcVec3 gc_body_origin_velocity(const gcBodyModel *model, const gcBodyState *state) {
    return gc_add(state->v, gc_cross(state->w, gc_mat3_mul_vec(&state->R, gc_neg(model->com_local))));
}

#endif
