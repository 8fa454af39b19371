/* Small inline vector, matrix and quaternion helpers shared by the core.
 * Private: not part of the public header. Doubles everywhere (SI units). */
#ifndef GC_MATH_H
#define GC_MATH_H

#include <math.h>

typedef struct gcVec3 { double x, y, z; } gcVec3;
/* Row-major 3x3: m[row][col]. */
typedef struct gcMat3 { double m[3][3]; } gcMat3;
/* Unit quaternion, scalar first (w, x, y, z) as in the public API. */
typedef struct gcQuat { double w, x, y, z; } gcQuat;
/* Rigid transform: world = R * local + p. */
typedef struct gcTransform { gcVec3 p; gcMat3 R; } gcTransform;

/* max/min for values known not to be NaN (libm's fmax/fmin are calls, not instructions). */
static inline double gc_max(double a, double b) { return a > b ? a : b; }
static inline double gc_min(double a, double b) { return a < b ? a : b; }
static inline gcVec3 gc_v3(double x, double y, double z) { gcVec3 v = {x, y, z}; return v; }
static inline gcVec3 gc_add(gcVec3 a, gcVec3 b) { return gc_v3(a.x + b.x, a.y + b.y, a.z + b.z); }
static inline gcVec3 gc_sub(gcVec3 a, gcVec3 b) { return gc_v3(a.x - b.x, a.y - b.y, a.z - b.z); }
static inline gcVec3 gc_scale(gcVec3 a, double s) { return gc_v3(a.x * s, a.y * s, a.z * s); }
static inline gcVec3 gc_neg(gcVec3 a) { return gc_v3(-a.x, -a.y, -a.z); }
static inline gcVec3 gc_madd(gcVec3 a, gcVec3 b, double s) { return gc_v3(a.x + b.x * s, a.y + b.y * s, a.z + b.z * s); }
static inline double gc_dot(gcVec3 a, gcVec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
static inline gcVec3 gc_cross(gcVec3 a, gcVec3 b) {
    return gc_v3(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}
static inline double gc_len2(gcVec3 a) { return gc_dot(a, a); }
static inline double gc_len(gcVec3 a) { return sqrt(gc_dot(a, a)); }
static inline gcVec3 gc_normalize(gcVec3 a) {
    double l = gc_len(a);
    return l > 0.0 ? gc_scale(a, 1.0 / l) : gc_v3(0.0, 0.0, 0.0);
}
static inline int gc_vec_finite(gcVec3 a) { return isfinite(a.x) && isfinite(a.y) && isfinite(a.z); }

/* Closed boxes: touching counts as overlapping. */
static inline int gc_aabb_overlap(gcVec3 amin, gcVec3 amax, gcVec3 bmin, gcVec3 bmax) {
    return amin.x <= bmax.x && bmin.x <= amax.x && amin.y <= bmax.y && bmin.y <= amax.y && amin.z <= bmax.z &&
           bmin.z <= amax.z;
}
static inline gcMat3 gc_mat3_identity(void) {
    gcMat3 r = {{{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}};
    return r;
}
static inline gcVec3 gc_mat3_mul_vec(const gcMat3 *a, gcVec3 v) {
    return gc_v3(a->m[0][0] * v.x + a->m[0][1] * v.y + a->m[0][2] * v.z,
                 a->m[1][0] * v.x + a->m[1][1] * v.y + a->m[1][2] * v.z,
                 a->m[2][0] * v.x + a->m[2][1] * v.y + a->m[2][2] * v.z);
}
/* R^T v: world direction into the local frame. */
static inline gcVec3 gc_mat3_tmul_vec(const gcMat3 *a, gcVec3 v) {
    return gc_v3(a->m[0][0] * v.x + a->m[1][0] * v.y + a->m[2][0] * v.z,
                 a->m[0][1] * v.x + a->m[1][1] * v.y + a->m[2][1] * v.z,
                 a->m[0][2] * v.x + a->m[1][2] * v.y + a->m[2][2] * v.z);
}
static inline gcMat3 gc_mat3_mul(const gcMat3 *a, const gcMat3 *b) {
    gcMat3 r;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            r.m[i][j] = a->m[i][0] * b->m[0][j] + a->m[i][1] * b->m[1][j] + a->m[i][2] * b->m[2][j];
    return r;
}
static inline gcMat3 gc_mat3_transpose(const gcMat3 *a) {
    gcMat3 r;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) r.m[i][j] = a->m[j][i];
    return r;
}

static inline gcTransform gc_transform_identity(void) {
    gcTransform t;
    t.p = gc_v3(0, 0, 0);
    t.R = gc_mat3_identity();
    return t;
}
static inline gcVec3 gc_transform_point(const gcTransform *t, gcVec3 local) {
    return gc_add(gc_mat3_mul_vec(&t->R, local), t->p);
}
static inline gcVec3 gc_inv_transform_point(const gcTransform *t, gcVec3 world) {
    return gc_mat3_tmul_vec(&t->R, gc_sub(world, t->p));
}

static inline gcQuat gc_quat_normalize(gcQuat q) {
    double l = sqrt(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z);
    gcQuat r = {q.w / l, q.x / l, q.y / l, q.z / l};
    return r;
}
static inline gcQuat gc_quat_mul(gcQuat a, gcQuat b) {
    gcQuat r = {a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z,
                a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y,
                a.w * b.y - a.x * b.z + a.y * b.w + a.z * b.x,
                a.w * b.z + a.x * b.y - a.y * b.x + a.z * b.w};
    return r;
}
/* Rotation by the rotation vector v (axis times angle): exp of the world-frame update. */
static inline gcQuat gc_quat_from_rotation_vector(gcVec3 v) {
    double angle = gc_len(v);
    if (angle < 1e-12) {
        gcQuat q = {1.0, 0.5 * v.x, 0.5 * v.y, 0.5 * v.z};
        return gc_quat_normalize(q);
    }
    double s = sin(0.5 * angle) / angle;
    gcQuat q = {cos(0.5 * angle), v.x * s, v.y * s, v.z * s};
    return q;
}

/* The unit quaternion of a rotation matrix (Shepperd: from the largest of w^2, x^2, y^2, z^2,
 * never dividing by a small number). */
static inline gcQuat gc_mat3_to_quat(const gcMat3 *r) {
    const double (*m)[3] = r->m, t = m[0][0] + m[1][1] + m[2][2];
    gcQuat q;
    if (t >= m[0][0] && t >= m[1][1] && t >= m[2][2]) {
        double s = 2.0 * sqrt(1.0 + t);
        q = (gcQuat){s / 4, (m[2][1] - m[1][2]) / s, (m[0][2] - m[2][0]) / s, (m[1][0] - m[0][1]) / s};
    } else if (m[0][0] >= m[1][1] && m[0][0] >= m[2][2]) {
        double s = 2.0 * sqrt(1.0 + 2 * m[0][0] - t);
        q = (gcQuat){(m[2][1] - m[1][2]) / s, s / 4, (m[0][1] + m[1][0]) / s, (m[0][2] + m[2][0]) / s};
    } else if (m[1][1] >= m[2][2]) {
        double s = 2.0 * sqrt(1.0 + 2 * m[1][1] - t);
        q = (gcQuat){(m[0][2] - m[2][0]) / s, (m[0][1] + m[1][0]) / s, s / 4, (m[1][2] + m[2][1]) / s};
    } else {
        double s = 2.0 * sqrt(1.0 + 2 * m[2][2] - t);
        q = (gcQuat){(m[1][0] - m[0][1]) / s, (m[0][2] + m[2][0]) / s, (m[1][2] + m[2][1]) / s, s / 4};
    }
    return gc_quat_normalize(q);
}

static inline gcMat3 gc_quat_to_mat3(gcQuat q) {
    double w = q.w, x = q.x, y = q.y, z = q.z;
    gcMat3 r = {{{1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)},
                 {2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)},
                 {2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)}}};
    return r;
}

#endif
