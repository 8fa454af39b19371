/* The bottom layer: what every file above may ask of a body or of the world's error slot.
 * Validation of arguments (with the message naming the argument), a body's derived state
 * (rotation, pose view, bounds) and its effective mass for this step. */
#include "body.h"

#include <stdarg.h>
#include <stdio.h>
#include <string.h>

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

/* Inverse of a symmetric positive-definite 3x3 (inertia); 0 when singular. */
int gc_invert_mat3(const gcMat3 *a, gcMat3 *out) {
    const double(*m)[3] = a->m;
    double c00 = m[1][1] * m[2][2] - m[1][2] * m[2][1];
    double c01 = m[1][2] * m[2][0] - m[1][0] * m[2][2];
    double c02 = m[1][0] * m[2][1] - m[1][1] * m[2][0];
    double det = m[0][0] * c00 + m[0][1] * c01 + m[0][2] * c02;
    if (!(fabs(det) > 0.0) || !isfinite(det)) return 0;
    double inv = 1.0 / det;
    out->m[0][0] = c00 * inv;
    out->m[0][1] = (m[0][2] * m[2][1] - m[0][1] * m[2][2]) * inv;
    out->m[0][2] = (m[0][1] * m[1][2] - m[0][2] * m[1][1]) * inv;
    out->m[1][0] = c01 * inv;
    out->m[1][1] = (m[0][0] * m[2][2] - m[0][2] * m[2][0]) * inv;
    out->m[1][2] = (m[0][2] * m[1][0] - m[0][0] * m[1][2]) * inv;
    out->m[2][0] = c02 * inv;
    out->m[2][1] = (m[0][1] * m[2][0] - m[0][0] * m[2][1]) * inv;
    out->m[2][2] = (m[0][0] * m[1][1] - m[0][1] * m[1][0]) * inv;
    return 1;
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

void gc_body_refresh_derived(gcWorld *w, int32_t id) {
    gcBody *b = &w->bodies[id];
    b->state.q = gc_quat_normalize(b->state.q);
    b->state.R = gc_quat_to_mat3(b->state.q);
    gcTransform frame = gc_body_transform(b);
    gcVec3 origin = frame.p;
    double *pose = &w->pose_array[7 * id];
    pose[0] = origin.x, pose[1] = origin.y, pose[2] = origin.z;
    pose[3] = b->state.q.w, pose[4] = b->state.q.x, pose[5] = b->state.q.y, pose[6] = b->state.q.z;
    /* World AABB of all parts: each part's local box turned into world axes (centre
     * transformed, half extents through |R|), grown by the part's radius. */
    gcVec3 lo = gc_v3(INFINITY, INFINITY, INFINITY), hi = gc_neg(lo);
    for (int p = b->first_part; p < b->first_part + b->num_parts; ++p) {
        const gcHull *h = &w->parts[p].hull;
        gcVec3 centre = gc_transform_point(&frame, gc_scale(gc_add(h->aabb_min, h->aabb_max), 0.5));
        gcVec3 half = gc_scale(gc_sub(h->aabb_max, h->aabb_min), 0.5);
        double e[3];
        for (int i = 0; i < 3; ++i)
            e[i] = fabs(b->state.R.m[i][0]) * half.x + fabs(b->state.R.m[i][1]) * half.y + fabs(b->state.R.m[i][2]) * half.z + h->radius;
        lo = gc_v3(gc_min(lo.x, centre.x - e[0]), gc_min(lo.y, centre.y - e[1]), gc_min(lo.z, centre.z - e[2]));
        hi = gc_v3(gc_max(hi.x, centre.x + e[0]), gc_max(hi.y, centre.y + e[1]), gc_max(hi.z, centre.z + e[2]));
    }
    b->state.aabb_min = lo;
    b->state.aabb_max = hi;
}

/* Cholesky factor of a 6x6 symmetric positive-definite matrix (lower); 0 on failure. */
int gc_cholesky6(const double A[6][6], double L[6][6]) {
    memset(L, 0, sizeof(double) * 36);
    for (int i = 0; i < 6; ++i) {
        for (int j = 0; j <= i; ++j) {
            double s = A[i][j];
            for (int k = 0; k < j; ++k) s -= L[i][k] * L[j][k];
            if (i == j) {
                if (!(s > 0.0)) return 0;
                L[i][i] = sqrt(s);
            } else {
                L[i][j] = s / L[j][j];
            }
        }
    }
    return 1;
}

void gc_cholesky_solve6(const double L[6][6], const double b[6], double x[6]) {
    double y[6];
    for (int i = 0; i < 6; ++i) {
        double s = b[i];
        for (int k = 0; k < i; ++k) s -= L[i][k] * y[k];
        y[i] = s / L[i][i];
    }
    for (int i = 5; i >= 0; --i) {
        double s = y[i];
        for (int k = i + 1; k < 6; ++k) s -= L[k][i] * x[k];
        x[i] = s / L[i][i];
    }
}

/* R A R^T: a body-frame tensor in world axes. */
gcMat3 gc_to_world(const gcMat3 *R, const gcMat3 *A) {
    gcMat3 RA = gc_mat3_mul(R, A);
    gcMat3 Rt = gc_mat3_transpose(R);
    return gc_mat3_mul(&RA, &Rt);
}

void gc_body_inverse_effective_mass(const gcBody *b, double M[36]) {
    memset(M, 0, 36 * sizeof(double));
    if (b->is_static || !b->effective_mass_valid) return;
    if (!b->coupled) {
        gcMat3 inv_inertia_world = gc_to_world(&b->inertia_rotation, &b->inv_inertia_local);
        for (int i = 0; i < 3; ++i) {
            M[6 * i + i] = b->inv_mass;
            for (int j = 0; j < 3; ++j) M[6 * (3 + i) + 3 + j] = inv_inertia_world.m[i][j];
        }
        return;
    }
    for (int j = 0; j < 6; ++j) {
        double e[6] = {0, 0, 0, 0, 0, 0}, col[6];
        e[j] = 1.0;
        gc_cholesky_solve6(b->effective_mass_factor, e, col);
        for (int r = 0; r < 6; ++r) M[6 * r + j] = col[r];
    }
}

