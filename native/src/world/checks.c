/* Argument checks and the world's error message: every error path of the core sets a
 * message that names the argument at fault (docs/architecture.md "Errors"). */
#include "checks.h"

#include <stdarg.h>
#include <stdio.h>

void gc_world_set_error(const gcWorld *world, const char *fmt, ...) {
    /* The error buffer is diagnostic state, not simulation state: writable from const queries. */
    gcWorld *w = (gcWorld *)world;
    va_list args;
    va_start(args, fmt);
    vsnprintf(w->last_error, sizeof w->last_error, fmt, args);
    va_end(args);
}

gcStatus gc_null_argument(const gcWorld *w, const char *name) {
    gc_world_set_error(w, "%s: must not be NULL", name);
    return GC_ERR_INVALID_ARGUMENT;
}

int gc_all_finite(const double *v, int n) {
    for (int i = 0; i < n; ++i)
        if (!isfinite(v[i])) return 0;
    return 1;
}

gcStatus gc_check_body(const gcWorld *w, int32_t body) {
    if (!w) return GC_ERR_INVALID_ARGUMENT;
    if (body < 0 || body >= w->num_bodies) {
        gc_world_set_error(w, "body: unknown id %d", (int)body);
        return GC_ERR_UNKNOWN_ID;
    }
    return GC_OK;
}

gcStatus gc_check_finger(const gcWorld *w, int32_t finger) {
    if (!w) return GC_ERR_INVALID_ARGUMENT;
    if (finger < 0 || finger >= w->num_fingers) {
        gc_world_set_error(w, "finger: unknown id %d", (int)finger);
        return GC_ERR_UNKNOWN_ID;
    }
    return GC_OK;
}

gcStatus gc_check_vec(const gcWorld *w, const double *v, int n, const char *name) {
    if (!v || !gc_all_finite(v, n)) {
        gc_world_set_error(w, "%s: must be %d finite numbers", name, n);
        return GC_ERR_INVALID_ARGUMENT;
    }
    return GC_OK;
}

gcStatus gc_check_friction(const gcWorld *w, double mu_s, double mu_d, double viscosity) {
    if (!isfinite(mu_s) || mu_s < 0.0) {
        gc_world_set_error(w, "mu_s: must be a finite number >= 0 (got %g)", mu_s);
        return GC_ERR_INVALID_ARGUMENT;
    }
    if (!isfinite(mu_d) || mu_d < 0.0 || mu_d > mu_s) {
        gc_world_set_error(w, "mu_d: must be finite, >= 0 and <= mu_s (got %g, mu_s %g)", mu_d, mu_s);
        return GC_ERR_INVALID_ARGUMENT;
    }
    if (!isfinite(viscosity) || viscosity < 0.0) {
        gc_world_set_error(w, "viscosity: must be a finite number >= 0 (got %g)", viscosity);
        return GC_ERR_INVALID_ARGUMENT;
    }
    return GC_OK;
}

/* Inertia of the principal minors must be positive and obey the triangle inequality. */
int gc_inertia_is_physical(const gcMat3 *I) {
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            if (!isfinite(I->m[i][j]) || fabs(I->m[i][j] - I->m[j][i]) > 1e-9 * (fabs(I->m[i][j]) + 1e-30))
                return 0;
    double a = I->m[0][0], b = I->m[1][1], c = I->m[2][2];
    if (!(a > 0 && b > 0 && c > 0)) return 0;
    double tol = 1e-9 * (a + b + c);
    if (a + b < c - tol || a + c < b - tol || b + c < a - tol) return 0;
    /* Positive definite: leading minors. */
    double m2 = a * b - I->m[0][1] * I->m[1][0];
    gcMat3 inv;
    return m2 > 0 && gc_invert_mat3(I, &inv);
}
