/* Argument checks and the world's error message (checks.c). Each check sets the message
 * when it fails, naming the argument. */
#ifndef GC_CHECKS_H
#define GC_CHECKS_H

#include "base/small_dense.h"
#include "world.h"

/* The message gc_world_last_error returns; every error path sets one, naming the argument. */
void gc_world_set_error(const gcWorld *world, const char *fmt, ...);

/* A NULL pointer argument: sets "<name>: must not be NULL" and returns GC_ERR_INVALID_ARGUMENT. */
gcStatus gc_null_argument(const gcWorld *world, const char *name);

int gc_all_finite(const double *v, int n);
gcStatus gc_check_body(const gcWorld *world, int32_t body);       /* GC_ERR_UNKNOWN_ID */
gcStatus gc_check_finger(const gcWorld *world, int32_t finger);   /* GC_ERR_UNKNOWN_ID */
gcStatus gc_check_vec(const gcWorld *world, const double *v, int n, const char *name);
gcStatus gc_check_friction(const gcWorld *world, double mu_s, double mu_d, double viscosity);
/* Symmetric, positive definite, triangle inequality. */
int gc_inertia_is_physical(const gcMat3 *inertia);

#endif
