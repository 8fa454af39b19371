/* The bottom layer (body.c): argument checks, the world's error message, a body's derived
 * state and its effective mass. Nothing here calls a file above it. */
#ifndef GC_BODY_H
#define GC_BODY_H

#include "world_internal.h"

/* The message gc_world_last_error returns; every error path sets one, naming the argument. */
void gc_world_set_error(const gcWorld *world, const char *fmt, ...);

/* A NULL pointer argument: sets "<name>: must not be NULL" and returns GC_ERR_INVALID_ARGUMENT. */
gcStatus gc_null_argument(const gcWorld *world, const char *name);

/* Checks that set the message when they fail. */
int gc_all_finite(const double *v, int n);
gcStatus gc_check_body(const gcWorld *world, int32_t body);       /* GC_ERR_UNKNOWN_ID */
gcStatus gc_check_finger(const gcWorld *world, int32_t finger);   /* GC_ERR_UNKNOWN_ID */
gcStatus gc_check_vec(const gcWorld *world, const double *v, int n, const char *name);
gcStatus gc_check_friction(const gcWorld *world, double mu_s, double mu_d, double viscosity);
/* Symmetric, positive definite, triangle inequality. */
int gc_inertia_is_physical(const gcMat3 *inertia);
/* Inverse of a 3x3; 0 when singular or not finite. */
int gc_invert_mat3(const gcMat3 *a, gcMat3 *out);

/* After the pose changed: normalised q, R, the pose view, the world AABB. */
void gc_body_refresh_derived(gcWorld *world, int32_t body);

/* 6x6 Cholesky factor (lower; 0 when not positive definite) and its solve. */
int gc_cholesky6(const double A[6][6], double L[6][6]);
void gc_cholesky_solve6(const double L[6][6], const double b[6], double x[6]);
/* R A R^T: a body-frame tensor in world axes. */
gcMat3 gc_to_world(const gcMat3 *R, const gcMat3 *A);

/* The body's (effective mass)^-1 for this step as a row-major 6x6, (linear, angular) world
 * frame, zero for a static or immovable body. A world impulse p at r from the COM changes
 * the twist by M [p; r x p], so contacts see the finger springs as mass. Valid between
 * gc_dynamics_velocities and gc_dynamics_positions. */
void gc_body_inverse_effective_mass(const gcBody *body, double M[36]);

/* Velocity of the body frame origin (world), as gc_world_body_velocity reports it, from
 * a body's model and a state of it (the world's, a shadow's or a channel's copy). */
static inline gcVec3 gc_body_origin_velocity(const gcBody *body, const gcBodyState *state) {
    return gc_add(state->v, gc_cross(state->w, gc_mat3_mul_vec(&state->R, gc_neg(body->com_local))));
}

#endif
