/* Geometry module tests: analytic answers, random-hull fuzzing with brute-force
 * checks, and the regression corpus native/tests/corpus/geometry_cases.txt
 * (run from the repository root). */
#include "geometry/geometry.h"
#include "gc_test.h"

#include <float.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

static const double kPi = 3.14159265358979323846;

/* ------------------------------------------------------------------ helpers */

static uint64_t rng_state;
static void rng_seed(uint64_t s) { rng_state = s * 0x9E3779B97F4A7C15ull + 1; }
static double rng_uniform(void) { /* splitmix64 -> [0, 1) */
    uint64_t z = (rng_state += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    z ^= z >> 31;
    return (double)(z >> 11) * (1.0 / 9007199254740992.0);
}
static double rng_range(double lo, double hi) { return lo + (hi - lo) * rng_uniform(); }

static gcQuat quat_axis_angle(gcVec3 axis, double angle) {
    gcVec3 u = gc_normalize(axis);
    double s = sin(angle / 2);
    gcQuat q = {cos(angle / 2), u.x * s, u.y * s, u.z * s};
    return q;
}
static gcTransform make_tf(double x, double y, double z, gcQuat q) {
    gcTransform t;
    t.p = gc_v3(x, y, z);
    t.R = gc_quat_to_mat3(gc_quat_normalize(q));
    return t;
}
static gcQuat quat_identity(void) { gcQuat q = {1, 0, 0, 0}; return q; }
static gcQuat random_quat(void) {
    gcQuat q = {rng_range(-1, 1), rng_range(-1, 1), rng_range(-1, 1), rng_range(-1, 1)};
    if (q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z < 1e-6) q.w = 1;
    return gc_quat_normalize(q);
}

static gcStatus make_box(double hx, double hy, double hz, double radius, gcHull *h) {
    double p[24];
    for (int i = 0; i < 8; ++i) {
        p[3 * i] = (i & 1) ? hx : -hx;
        p[3 * i + 1] = (i & 2) ? hy : -hy;
        p[3 * i + 2] = (i & 4) ? hz : -hz;
    }
    return gc_hull_build(p, 8, radius, 0.0, h);
}

static double brute_support_value(const gcHull *h, gcVec3 d) {
    double best = -DBL_MAX;
    for (int i = 0; i < h->num_vertices; ++i) best = fmax(best, gc_dot(h->vertices[i], d));
    return best;
}

/* World-frame support value h(d) of the inflated shape. */
static double world_support(const gcHull *h, const gcTransform *t, gcVec3 d) {
    gcVec3 dl = gc_mat3_tmul_vec(&t->R, d);
    return brute_support_value(h, dl) + gc_dot(d, t->p) + h->radius * gc_len(d);
}

/* Signed distance of a world point to the shape's inflated surface. */
static double world_sd(const gcHull *h, const gcTransform *t, gcVec3 p) {
    double sd = 0;
    gcVec3 sp, n;
    gc_point_query(h, gc_inv_transform_point(t, p), &sd, &sp, &n);
    return sd;
}

static int contact_finite(const gcContact *c) {
    return isfinite(c->distance) && gc_vec_finite(c->normal) && gc_vec_finite(c->point_a) &&
           gc_vec_finite(c->point_b);
}

static int contact_identical(const gcContact *x, const gcContact *y) {
    return x->distance == y->distance && x->normal.x == y->normal.x && x->normal.y == y->normal.y &&
           x->normal.z == y->normal.z && x->point_a.x == y->point_a.x && x->point_a.y == y->point_a.y &&
           x->point_a.z == y->point_a.z && x->point_b.x == y->point_b.x && x->point_b.y == y->point_b.y &&
           x->point_b.z == y->point_b.z && x->iterations == y->iterations;
}

static int hull_is_consistent(const gcHull *h, double tol) {
    /* every vertex below every plane, every triangle's winding matches its normal */
    for (int f = 0; f < h->num_planes; ++f) {
        for (int i = 0; i < h->num_vertices; ++i)
            if (gc_dot(h->plane_normals[f], h->vertices[i]) - h->plane_offsets[f] > tol) return 0;
        gcVec3 a = h->vertices[h->triangles[3 * f]], b = h->vertices[h->triangles[3 * f + 1]],
               c = h->vertices[h->triangles[3 * f + 2]];
        if (gc_dot(gc_cross(gc_sub(b, a), gc_sub(c, a)), h->plane_normals[f]) <= 0) return 0;
    }
    /* Euler: closed triangulated sphere */
    return h->num_vertices - 3 * h->num_triangles / 2 + h->num_triangles == 2;
}

/* ------------------------------------------------------------ hull building */

static void test_cube_hull(void) {
    double pts[3 * 40];
    int n = 0;
    for (int i = 0; i < 8; ++i) {
        pts[3 * n] = (i & 1) ? 1 : -1;
        pts[3 * n + 1] = (i & 2) ? 1 : -1;
        pts[3 * n + 2] = (i & 4) ? 1 : -1;
        ++n;
    }
    for (int i = 0; i < 8; ++i) { memcpy(&pts[3 * n], &pts[3 * i], 3 * sizeof(double)); ++n; } /* duplicates */
    rng_seed(1);
    for (int i = 0; i < 16; ++i, ++n)
        for (int k = 0; k < 3; ++k) pts[3 * n + k] = rng_range(-0.99, 0.99); /* interior */
    pts[3 * n] = 1; pts[3 * n + 1] = 0; pts[3 * n + 2] = 0; ++n;    /* on a face */
    pts[3 * n] = 1; pts[3 * n + 1] = 1; pts[3 * n + 2] = 0.3; ++n;  /* on an edge */
    gcHull h;
    gcStatus st = gc_hull_build(pts, n, 0.0, 0.0, &h);
    GC_CHECK(st == GC_OK, "cube status %d", st);
    GC_CHECK(h.num_vertices == 8, "cube vertices %d", h.num_vertices);
    GC_CHECK(h.num_triangles == 12, "cube triangles %d", h.num_triangles);
    GC_CHECK_NEAR(h.volume, 8.0, 1e-12, "cube volume");
    GC_CHECK_NEAR(gc_len(h.centroid), 0.0, 1e-12, "cube centroid");
    double m = 8.0, ixx = m * (4.0 + 4.0) / 12.0;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) GC_CHECK_NEAR(h.inertia_unit.m[i][j], i == j ? ixx : 0.0, 1e-12, "cube inertia");
    GC_CHECK_NEAR(h.min_width, 2.0, 1e-12, "cube min_width");
    GC_CHECK_NEAR(h.aabb_min.x, -1, 0, "aabb");
    GC_CHECK_NEAR(h.aabb_max.z, 1, 0, "aabb");
    GC_CHECK(hull_is_consistent(&h, 1e-12), "cube hull consistent");
    gc_hull_free(&h);
    GC_CHECK(h.vertices == NULL && h.num_vertices == 0, "free zeroes");
    gc_hull_free(&h); /* twice is fine */
    gc_hull_free(NULL);
}

static void test_box_mass(void) {
    /* 1 x 2 x 3 box centred at (5, -3, 2) */
    double a = 1, b = 2, c = 3, pts[24];
    for (int i = 0; i < 8; ++i) {
        pts[3 * i] = 5 + ((i & 1) ? a / 2 : -a / 2);
        pts[3 * i + 1] = -3 + ((i & 2) ? b / 2 : -b / 2);
        pts[3 * i + 2] = 2 + ((i & 4) ? c / 2 : -c / 2);
    }
    gcHull h;
    GC_CHECK(gc_hull_build(pts, 8, 0, 0, &h) == GC_OK, "box build");
    double m = a * b * c;
    GC_CHECK_NEAR(h.volume, m, 1e-12, "box volume");
    GC_CHECK_NEAR(h.centroid.x, 5, 1e-12, "box cx");
    GC_CHECK_NEAR(h.centroid.y, -3, 1e-12, "box cy");
    GC_CHECK_NEAR(h.centroid.z, 2, 1e-12, "box cz");
    GC_CHECK_NEAR(h.inertia_unit.m[0][0], m * (b * b + c * c) / 12, 1e-11, "box Ixx");
    GC_CHECK_NEAR(h.inertia_unit.m[1][1], m * (a * a + c * c) / 12, 1e-11, "box Iyy");
    GC_CHECK_NEAR(h.inertia_unit.m[2][2], m * (a * a + b * b) / 12, 1e-11, "box Izz");
    GC_CHECK_NEAR(h.inertia_unit.m[0][1], 0, 1e-11, "box Ixy");
    GC_CHECK_NEAR(h.inertia_unit.m[1][2], 0, 1e-11, "box Iyz");
    GC_CHECK_NEAR(h.min_width, 1.0, 1e-12, "box min_width");
    gc_hull_free(&h);

    /* rotated box: inertia = R I R^T */
    gcMat3 R = gc_quat_to_mat3(gc_quat_normalize((gcQuat){0.9, 0.2, -0.3, 0.4}));
    double rp[24];
    for (int i = 0; i < 8; ++i) {
        gcVec3 v = gc_v3((i & 1) ? a / 2 : -a / 2, (i & 2) ? b / 2 : -b / 2, (i & 4) ? c / 2 : -c / 2);
        v = gc_mat3_mul_vec(&R, v);
        rp[3 * i] = v.x; rp[3 * i + 1] = v.y; rp[3 * i + 2] = v.z;
    }
    GC_CHECK(gc_hull_build(rp, 8, 0, 0, &h) == GC_OK, "rotated box build");
    gcMat3 I0 = {{{m * (b * b + c * c) / 12, 0, 0}, {0, m * (a * a + c * c) / 12, 0}, {0, 0, m * (a * a + b * b) / 12}}};
    gcMat3 RT = gc_mat3_transpose(&R), tmp = gc_mat3_mul(&R, &I0), Iw = gc_mat3_mul(&tmp, &RT);
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) GC_CHECK_NEAR(h.inertia_unit.m[i][j], Iw.m[i][j], 1e-11, "rotated box inertia");
    GC_CHECK_NEAR(h.min_width, 1.0, 1e-12, "rotated box min_width");
    gc_hull_free(&h);
}

static void test_tetra_mass(void) {
    double pts[] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1};
    gcHull h;
    GC_CHECK(gc_hull_build(pts, 4, 0, 0, &h) == GC_OK, "tetra build");
    GC_CHECK_NEAR(h.volume, 1.0 / 6.0, 1e-14, "tetra volume");
    GC_CHECK_NEAR(h.centroid.x, 0.25, 1e-14, "tetra centroid");
    GC_CHECK_NEAR(h.centroid.z, 0.25, 1e-14, "tetra centroid");
    /* covariance about the centroid: C_xx = 1/160, C_xy = -1/480 */
    GC_CHECK_NEAR(h.inertia_unit.m[0][0], 2.0 / 160.0, 1e-14, "tetra Ixx");
    GC_CHECK_NEAR(h.inertia_unit.m[0][1], 1.0 / 480.0, 1e-14, "tetra Ixy");
    GC_CHECK_NEAR(h.inertia_unit.m[1][2], 1.0 / 480.0, 1e-14, "tetra Iyz");
    GC_CHECK_NEAR(h.min_width, 1.0 / sqrt(3.0), 1e-14, "tetra min_width");
    gc_hull_free(&h);
}

/* Numerical inertia of a capsule by midpoint integration on a grid. */
static void test_sphere_capsule_mass(void) {
    double c[3] = {0.5, -1, 2};
    gcHull h;
    GC_CHECK(gc_hull_build(c, 1, 0.3, 0, &h) == GC_OK, "sphere build");
    double v = 4.0 / 3.0 * kPi * 0.027;
    GC_CHECK(h.num_vertices == 1 && h.num_triangles == 0, "sphere shape");
    GC_CHECK_NEAR(h.volume, v, 1e-15, "sphere volume");
    GC_CHECK_NEAR(h.inertia_unit.m[1][1], 0.4 * v * 0.09, 1e-15, "sphere inertia");
    GC_CHECK_NEAR(h.inertia_unit.m[0][1], 0, 0, "sphere inertia offdiag");
    GC_CHECK_NEAR(h.centroid.z, 2, 0, "sphere centroid");
    GC_CHECK_NEAR(h.min_width, 0.6, 1e-15, "sphere min_width");
    gc_hull_free(&h);

    /* capsule along a tilted axis */
    double r = 0.25, L = 1.0;
    gcVec3 u = gc_normalize(gc_v3(1, 2, 2));
    double seg[6] = {-u.x * L / 2, -u.y * L / 2, -u.z * L / 2, u.x * L / 2, u.y * L / 2, u.z * L / 2};
    GC_CHECK(gc_hull_build(seg, 2, r, 0, &h) == GC_OK, "capsule build");
    GC_CHECK(h.num_vertices == 2, "capsule vertices");
    double vol = kPi * r * r * L + 4.0 / 3.0 * kPi * r * r * r;
    GC_CHECK_NEAR(h.volume, vol, 1e-14, "capsule volume");
    /* grid integration in the capsule's own frame (axis z) */
    int N = 160;
    double half_z = L / 2 + r, izz = 0, ixx = 0, cell = 0, vsum = 0;
    for (int i = 0; i < N; ++i)
        for (int j = 0; j < N; ++j)
            for (int k = 0; k < N; ++k) {
                double x = -r + (i + 0.5) * 2 * r / N, y = -r + (j + 0.5) * 2 * r / N;
                double z = -half_z + (k + 0.5) * 2 * half_z / N;
                double zc = fmin(fmax(z, -L / 2), L / 2);
                if (x * x + y * y + (z - zc) * (z - zc) > r * r) continue;
                izz += x * x + y * y;
                ixx += y * y + z * z;
                vsum += 1;
            }
    cell = (2 * r / N) * (2 * r / N) * (2 * half_z / N);
    GC_CHECK_NEAR(vsum * cell, vol, 2e-3 * vol, "capsule grid volume");
    /* tensor along u: I = I_perp (1 - uu^T) + I_axis uu^T */
    double I_axis = 0, I_perp = 0;
    double uu[3] = {u.x, u.y, u.z};
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) {
            I_axis += uu[i] * h.inertia_unit.m[i][j] * uu[j];
        }
    gcVec3 e = gc_normalize(gc_cross(u, gc_v3(1, 0, 0)));
    double ee[3] = {e.x, e.y, e.z};
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) I_perp += ee[i] * h.inertia_unit.m[i][j] * ee[j];
    GC_CHECK_NEAR(I_perp, ixx * cell, 3e-3 * ixx * cell, "capsule transverse inertia");
    GC_CHECK_NEAR(I_axis, izz * cell, 3e-3 * izz * cell, "capsule axial inertia");
    gc_hull_free(&h);
}

static void test_degenerate_inputs(void) {
    gcHull h;
    double coplanar[] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0, 0.5, 0.5, 1e-14};
    GC_CHECK(gc_hull_build(coplanar, 5, 0, 0, &h) == GC_ERR_DEGENERATE, "coplanar");
    GC_CHECK(gc_hull_build(coplanar, 5, 0.1, 0, &h) == GC_ERR_DEGENERATE, "coplanar with radius");
    double collinear[] = {0, 0, 0, 1, 1, 1, 2, 2, 2, 0.5, 0.5, 0.5};
    GC_CHECK(gc_hull_build(collinear, 4, 0, 0, &h) == GC_ERR_DEGENERATE, "collinear");
    GC_CHECK(gc_hull_build(collinear, 4, 0.1, 0, &h) == GC_OK && h.num_vertices == 2, "collinear + radius = capsule");
    GC_CHECK_NEAR(gc_len(gc_sub(h.vertices[1], h.vertices[0])), 2 * sqrt(3.0), 1e-14, "capsule from extremes");
    gc_hull_free(&h);
    double coincident[] = {1, 2, 3, 1, 2, 3, 1, 2, 3, 1, 2, 3, 1, 2, 3};
    GC_CHECK(gc_hull_build(coincident, 5, 0, 0, &h) == GC_ERR_DEGENERATE, "coincident");
    GC_CHECK(gc_hull_build(coincident, 5, 0.5, 0, &h) == GC_OK && h.num_vertices == 1, "coincident + radius = sphere");
    gc_hull_free(&h);
    GC_CHECK(gc_hull_build(coincident, 1, 0, 0, &h) == GC_ERR_DEGENERATE, "point without radius");
    GC_CHECK(gc_hull_build(collinear, 2, 0, 0, &h) == GC_ERR_DEGENERATE, "segment without radius");
    GC_CHECK(gc_hull_build(collinear, 3, 0, 0, &h) == GC_ERR_DEGENERATE, "three collinear");
    double tri[] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    GC_CHECK(gc_hull_build(tri, 3, 0, 0, &h) == GC_ERR_DEGENERATE, "triangle");
    double bad[] = {0, 0, 0, 1, 0, 0, 0, NAN, 0, 0, 0, 1};
    GC_CHECK(gc_hull_build(bad, 4, 0, 0, &h) == GC_ERR_INVALID_ARGUMENT, "NaN point");
    bad[7] = INFINITY;
    GC_CHECK(gc_hull_build(bad, 4, 0, 0, &h) == GC_ERR_INVALID_ARGUMENT, "Inf point");
    GC_CHECK(gc_hull_build(tri, 3, -1, 0, &h) == GC_ERR_INVALID_ARGUMENT, "negative radius");
    GC_CHECK(gc_hull_build(tri, 3, NAN, 0, &h) == GC_ERR_INVALID_ARGUMENT, "NaN radius");
    GC_CHECK(gc_hull_build(NULL, 3, 0, 0, &h) == GC_ERR_INVALID_ARGUMENT, "NULL points");
    GC_CHECK(gc_hull_build(tri, 0, 0, 0, &h) == GC_ERR_INVALID_ARGUMENT, "no points");
    GC_CHECK(gc_hull_build(tri, 3, 0, 0, NULL) == GC_ERR_INVALID_ARGUMENT, "NULL out");
    GC_CHECK(h.vertices == NULL, "failed build leaves an empty hull");
    /* very flat but valid: 1 x 1 x 1e-6 plate */
    double flat[] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0, 0, 0, 1e-6, 1, 0, 1e-6, 0, 1, 1e-6, 1, 1, 1e-6};
    GC_CHECK(gc_hull_build(flat, 8, 0, 0, &h) == GC_OK && h.num_vertices == 8, "thin plate");
    GC_CHECK_NEAR(h.volume, 1e-6, 1e-18, "thin plate volume");
    GC_CHECK_NEAR(h.min_width, 1e-6, 1e-16, "thin plate min_width");
    gc_hull_free(&h);
    /* explicit tolerance merges the plate's thickness away */
    GC_CHECK(gc_hull_build(flat, 8, 0, 1e-3, &h) == GC_ERR_DEGENERATE, "plate below tolerance");
    /* far from the origin */
    double far[24];
    for (int i = 0; i < 8; ++i) {
        far[3 * i] = 1e6 + ((i & 1) ? 0.01 : 0);
        far[3 * i + 1] = -1e6 + ((i & 2) ? 0.02 : 0);
        far[3 * i + 2] = 1e6 + ((i & 4) ? 0.03 : 0);
    }
    GC_CHECK(gc_hull_build(far, 8, 0, 0, &h) == GC_OK && h.num_vertices == 8, "far box");
    GC_CHECK_NEAR(h.volume, 6e-6, 1e-12, "far box volume");
    gc_hull_free(&h);
}

static void random_sphere_points(double *pts, int n, double noise) {
    for (int i = 0; i < n; ++i) {
        gcVec3 v;
        do v = gc_v3(rng_range(-1, 1), rng_range(-1, 1), rng_range(-1, 1));
        while (gc_len2(v) > 1 || gc_len2(v) < 1e-3);
        v = gc_scale(gc_normalize(v), 1.0 + noise * rng_range(-1, 1));
        pts[3 * i] = v.x; pts[3 * i + 1] = v.y; pts[3 * i + 2] = v.z;
    }
}

static void test_large_hull_support(void) {
    rng_seed(7);
    int n = 2000;
    double *pts = (double *)malloc(sizeof(double) * 3 * n);
    random_sphere_points(pts, n, 0.0);
    gcHull h;
    GC_CHECK(gc_hull_build(pts, n, 0, 0, &h) == GC_OK, "sphere cloud build");
    GC_CHECK(h.num_vertices == n, "all points on the sphere are vertices: %d", h.num_vertices);
    GC_CHECK(h.adjacency != NULL, "adjacency built");
    GC_CHECK(hull_is_consistent(&h, 1e-9), "sphere cloud consistent");
    GC_CHECK_NEAR(h.volume, 4.0 / 3.0 * kPi, 0.05, "sphere cloud volume");
    int bad = 0;
    for (int k = 0; k < 2000; ++k) {
        gcVec3 d = gc_v3(rng_range(-1, 1), rng_range(-1, 1), rng_range(-1, 1));
        double got = gc_dot(gc_hull_support(&h, d), d);
        if (got < brute_support_value(&h, d) - 1e-12) ++bad;
    }
    GC_CHECK(bad == 0, "hill climbing support %d misses", bad);
    gc_hull_free(&h);
    /* noisy cloud with many interior points and near-coplanar ones */
    random_sphere_points(pts, n, 1e-9);
    for (int i = 0; i < n / 2; ++i) pts[3 * i] *= 0.5;
    GC_CHECK(gc_hull_build(pts, n, 0, 0, &h) == GC_OK, "noisy cloud build");
    GC_CHECK(hull_is_consistent(&h, 1e-8), "noisy cloud consistent");
    gc_hull_free(&h);
    free(pts);
}

/* ------------------------------------------------------------- point query */

static void check_pq(const gcHull *h, gcVec3 p, double sd_exp, gcVec3 n_exp, const char *what) {
    double sd = NAN;
    gcVec3 sp, n;
    gcStatus st = gc_point_query(h, p, &sd, &sp, &n);
    GC_CHECK(st == GC_OK, "%s: status %d", what, st);
    GC_CHECK_NEAR(sd, sd_exp, 1e-12, what);
    GC_CHECK(gc_len(gc_sub(n, n_exp)) < 1e-9, "%s: normal (%g %g %g)", what, n.x, n.y, n.z);
    /* the surface point is where p ends up when moved by -sd along the normal */
    GC_CHECK(gc_len(gc_sub(gc_madd(sp, n, sd), p)) < 1e-12, "%s: surface point", what);
}

static void test_point_query(void) {
    gcHull box, rbox, sph, cap;
    make_box(1, 2, 3, 0, &box);
    make_box(1, 2, 3, 0.5, &rbox);
    double c[3] = {0, 0, 0}, seg[6] = {0, 0, -1, 0, 0, 1};
    gc_hull_build(c, 1, 2, 0, &sph);
    gc_hull_build(seg, 2, 0.5, 0, &cap);
    double s2 = sqrt(0.5), s3 = sqrt(1.0 / 3.0);
    check_pq(&box, gc_v3(3, 0.5, -1), 2, gc_v3(1, 0, 0), "face +x");
    check_pq(&box, gc_v3(0.2, -0.3, -4), 1, gc_v3(0, 0, -1), "face -z");
    check_pq(&box, gc_v3(2, 3, 0), sqrt(2.0), gc_v3(s2, s2, 0), "edge");
    check_pq(&box, gc_v3(-2, -3, 4), sqrt(3.0), gc_v3(-s3, -s3, s3), "vertex");
    check_pq(&box, gc_v3(0.9, 0, 0), -0.1, gc_v3(1, 0, 0), "inside near +x");
    check_pq(&box, gc_v3(0.1, 0.3, -2.95), -0.05, gc_v3(0, 0, -1), "inside near -z");
    check_pq(&box, gc_v3(1, 0.5, 0.5), 0, gc_v3(1, 0, 0), "on face");
    {
        double sd;
        gcVec3 sp, n;
        GC_CHECK(gc_point_query(&box, gc_v3(1, 2, 0), &sd, &sp, &n) == GC_OK, "on edge status");
        GC_CHECK_NEAR(sd, 0, 1e-15, "on edge distance");
        GC_CHECK(fabs(gc_len(n) - 1) < 1e-12 && n.z == 0 && (n.x == 1 || n.y == 1), "on edge normal is a face normal");
        GC_CHECK(gc_point_query(&box, gc_v3(1, 2, 3), &sd, &sp, &n) == GC_OK, "on vertex");
        GC_CHECK_NEAR(sd, 0, 1e-15, "on vertex distance");
        GC_CHECK(fabs(gc_len(n) - 1) < 1e-12, "on vertex normal unit");
        GC_CHECK(gc_point_query(&box, gc_v3(0, 0, 0), &sd, &sp, &n) == GC_OK, "centre");
        GC_CHECK_NEAR(sd, -1, 1e-15, "centre: least-penetrated face is x");
        GC_CHECK(gc_point_query(&box, gc_v3(NAN, 0, 0), &sd, &sp, &n) == GC_ERR_INVALID_ARGUMENT, "NaN point");
        GC_CHECK(gc_point_query(&box, gc_v3(1 + 1e-15, 0.3, 0.2), &sd, &sp, &n) == GC_OK, "just outside");
        GC_CHECK(gc_len(gc_sub(n, gc_v3(1, 0, 0))) < 1e-12, "just outside: face normal");
    }
    check_pq(&rbox, gc_v3(3, 0.5, -1), 1.5, gc_v3(1, 0, 0), "rounded face");
    check_pq(&rbox, gc_v3(2, 3, 0), sqrt(2.0) - 0.5, gc_v3(s2, s2, 0), "rounded edge");
    check_pq(&rbox, gc_v3(1.2, 2.2, 3.2), sqrt(0.12) - 0.5, gc_v3(s3, s3, s3), "inside rounded vertex");
    check_pq(&rbox, gc_v3(0.5, 0, 0), -1.0, gc_v3(1, 0, 0), "inside rounded box");
    check_pq(&sph, gc_v3(3, 4, 0), 3, gc_v3(0.6, 0.8, 0), "sphere");
    check_pq(&sph, gc_v3(0, 0, 1), -1, gc_v3(0, 0, 1), "inside sphere");
    check_pq(&cap, gc_v3(2, 0, 0.5), 1.5, gc_v3(1, 0, 0), "capsule side");
    check_pq(&cap, gc_v3(0, 0, 3), 1.5, gc_v3(0, 0, 1), "capsule cap");
    check_pq(&cap, gc_v3(0, 0.25, -0.3), -0.25, gc_v3(0, 1, 0), "inside capsule");
    {
        double sd;
        gcVec3 sp, n;
        GC_CHECK(gc_point_query(&sph, gc_v3(0, 0, 0), &sd, &sp, &n) == GC_OK, "sphere centre");
        GC_CHECK(sd == -2 && fabs(gc_len(n) - 1) < 1e-15, "sphere centre: finite unit normal");
        GC_CHECK(gc_point_query(&cap, gc_v3(0, 0, 0.3), &sd, &sp, &n) == GC_OK, "capsule axis");
        GC_CHECK(fabs(sd + 0.5) < 1e-15 && fabs(gc_len(n) - 1) < 1e-15 && fabs(n.z) < 1e-15, "capsule axis normal");
    }
    gc_hull_free(&box);
    gc_hull_free(&rbox);
    gc_hull_free(&sph);
    gc_hull_free(&cap);
}

/* --------------------------------------------------------------- collisions */

static void check_contact(const gcHull *a, const gcTransform *ta, const gcHull *b, const gcTransform *tb,
                          double dist, gcVec3 normal, double tol, const char *what) {
    gcContact c;
    gcStatus st = gc_collide(a, ta, b, tb, &c);
    GC_CHECK(st == GC_OK, "%s: status %d", what, st);
    GC_CHECK(contact_finite(&c), "%s: finite", what);
    GC_CHECK_NEAR(c.distance, dist, tol, what);
    GC_CHECK(gc_len(gc_sub(c.normal, normal)) < 1e-6, "%s: normal (%.9g %.9g %.9g)", what, c.normal.x,
             c.normal.y, c.normal.z);
    /* points on the surfaces, and separated by the distance along the normal */
    GC_CHECK(fabs(world_sd(a, ta, c.point_a)) < 1e-8, "%s: point_a on A (%g)", what, world_sd(a, ta, c.point_a));
    GC_CHECK(fabs(world_sd(b, tb, c.point_b)) < 1e-8, "%s: point_b on B (%g)", what, world_sd(b, tb, c.point_b));
    GC_CHECK_NEAR(gc_dot(gc_sub(c.point_b, c.point_a), c.normal), c.distance, 1e-8, "witness gap along normal");
    /* symmetry: swapping A and B flips the normal, keeps the distance */
    gcContact s;
    gc_collide(b, tb, a, ta, &s);
    GC_CHECK_NEAR(s.distance, c.distance, tol, "swapped distance");
}

static void test_box_box(void) {
    gcHull box, thin;
    make_box(1, 1, 1, 0, &box);
    make_box(0.5, 0.5, 0.5, 0, &thin);
    gcQuat I = quat_identity();
    gcTransform ta = make_tf(0, 0, 0, I);
    gcTransform tb = make_tf(2.5, 0.3, -0.2, I);
    check_contact(&box, &ta, &box, &tb, 0.5, gc_v3(1, 0, 0), 1e-10, "boxes apart x");
    tb = make_tf(0.3, -0.2, -2.2, I);
    check_contact(&box, &ta, &box, &tb, 0.2, gc_v3(0, 0, -1), 1e-10, "boxes apart -z");
    tb = make_tf(1.9, 0.3, -0.2, I);
    check_contact(&box, &ta, &box, &tb, -0.1, gc_v3(1, 0, 0), 1e-9, "boxes penetrating x");
    tb = make_tf(0.2, 0.9, 0.1, I);
    check_contact(&box, &ta, &thin, &tb, -0.6, gc_v3(0, 1, 0), 1e-9, "small box sunk into y face");
    /* B rotated 45 degrees about z: its edge faces A's +x face */
    gcQuat q45 = quat_axis_angle(gc_v3(0, 0, 1), kPi / 4);
    tb = make_tf(1 + sqrt(2.0) + 0.25, 0.1, 0.2, q45);
    check_contact(&box, &ta, &box, &tb, 0.25, gc_v3(1, 0, 0), 1e-10, "rotated box apart");
    tb = make_tf(1 + sqrt(2.0) - 0.25, 0.1, 0.2, q45);
    check_contact(&box, &ta, &box, &tb, -0.25, gc_v3(1, 0, 0), 1e-9, "rotated box penetrating");
    /* vertex-vertex along the diagonal: both rotated so a corner points at the other */
    tb = make_tf(3, 3, 3, I);
    check_contact(&box, &ta, &box, &tb, sqrt(3.0), gc_v3(sqrt(1 / 3.0), sqrt(1 / 3.0), sqrt(1 / 3.0)), 1e-10,
                  "corner to corner");
    /* both rotated by the same random rotation: face-face in a rotated frame */
    gcQuat qr = gc_quat_normalize((gcQuat){0.3, -0.5, 0.7, 0.2});
    gcMat3 R = gc_quat_to_mat3(qr);
    gcVec3 off = gc_mat3_mul_vec(&R, gc_v3(0, 2.05, 0.4));
    ta = make_tf(1, 2, 3, qr);
    tb = make_tf(1 + off.x, 2 + off.y, 3 + off.z, qr);
    check_contact(&box, &ta, &box, &tb, 0.05, gc_mat3_mul_vec(&R, gc_v3(0, 1, 0)), 1e-10, "rotated pair apart");
    off = gc_mat3_mul_vec(&R, gc_v3(0, 1.95, 0.4));
    tb = make_tf(1 + off.x, 2 + off.y, 3 + off.z, qr);
    check_contact(&box, &ta, &box, &tb, -0.05, gc_mat3_mul_vec(&R, gc_v3(0, 1, 0)), 1e-9, "rotated pair penetrating");
    /* gjk_distance */
    ta = make_tf(0, 0, 0, I);
    tb = make_tf(0, 0, 3, I);
    double d;
    gcVec3 pa, pb;
    GC_CHECK(gc_gjk_distance(&box, &ta, &box, &tb, &d, &pa, &pb) == GC_OK, "gjk status");
    GC_CHECK_NEAR(d, 1, 1e-12, "gjk distance");
    GC_CHECK_NEAR(pa.z, 1, 1e-12, "gjk witness a");
    GC_CHECK_NEAR(pb.z, 2, 1e-12, "gjk witness b");
    tb = make_tf(0, 0, 1.5, I);
    GC_CHECK(gc_gjk_distance(&box, &ta, &box, &tb, &d, &pa, &pb) == GC_OK && d == 0, "gjk overlap");
    gc_hull_free(&box);
    gc_hull_free(&thin);
}

static void test_spheres_capsules(void) {
    gcHull box, sph, sph2, cap, cap2, rbox;
    make_box(1, 1, 1, 0, &box);
    make_box(1, 1, 1, 0.1, &rbox);
    double c[3] = {0, 0, 0}, seg[6] = {-0.5, 0, 0, 0.5, 0, 0};
    gc_hull_build(c, 1, 0.5, 0, &sph);
    gc_hull_build(c, 1, 0.25, 0, &sph2);
    gc_hull_build(seg, 2, 0.2, 0, &cap);
    gc_hull_build(seg, 2, 0.1, 0, &cap2);
    gcQuat I = quat_identity();
    gcTransform ta = make_tf(0, 0, 0, I), tb;
    double s2 = sqrt(0.5);
    tb = make_tf(2, 0.2, 0.3, I);
    check_contact(&box, &ta, &sph, &tb, 0.5, gc_v3(1, 0, 0), 1e-12, "box-sphere face");
    tb = make_tf(2, 2, 0.3, I);
    check_contact(&box, &ta, &sph, &tb, sqrt(2.0) - 0.5, gc_v3(s2, s2, 0), 1e-12, "box-sphere edge");
    tb = make_tf(0.8, 0.1, 0.2, I);
    check_contact(&box, &ta, &sph, &tb, -0.7, gc_v3(1, 0, 0), 1e-12, "sphere centre inside box");
    check_contact(&sph, &tb, &box, &ta, -0.7, gc_v3(-1, 0, 0), 1e-12, "sphere centre inside box (A = sphere)");
    tb = make_tf(2.2, 0, 0, I);
    check_contact(&rbox, &ta, &sph, &tb, 0.6, gc_v3(1, 0, 0), 1e-12, "rounded box - sphere");
    tb = make_tf(0.3, 0.4, 0, I);
    check_contact(&sph, &ta, &sph2, &tb, 0.5 - 0.75, gc_v3(0.6, 0.8, 0), 1e-12, "sphere-sphere overlap");
    tb = make_tf(3, 4, 0, I);
    check_contact(&sph, &ta, &sph2, &tb, 5 - 0.75, gc_v3(0.6, 0.8, 0), 1e-12, "sphere-sphere apart");
    {
        gcContact ct;
        GC_CHECK(gc_collide(&sph, &ta, &sph2, &ta, &ct) == GC_OK, "coincident spheres");
        GC_CHECK(contact_finite(&ct) && fabs(gc_len(ct.normal) - 1) < 1e-15, "coincident spheres: unit normal");
        GC_CHECK_NEAR(ct.distance, -0.75, 1e-15, "coincident spheres depth");
    }
    /* capsule lying on the box's top face, slightly above / into it */
    tb = make_tf(0.1, 0.2, 1.3, I);
    check_contact(&box, &ta, &cap, &tb, 0.1, gc_v3(0, 0, 1), 1e-10, "capsule above box");
    tb = make_tf(0.1, 0.2, 1.1, I);
    check_contact(&box, &ta, &cap, &tb, -0.1, gc_v3(0, 0, 1), 1e-9, "capsule touching into box");
    tb = make_tf(0.1, 0.2, 0.9, I);
    check_contact(&box, &ta, &cap, &tb, -0.3, gc_v3(0, 0, 1), 1e-9, "capsule core inside box");
    /* crossed capsules */
    gcQuat qz = quat_axis_angle(gc_v3(0, 0, 1), kPi / 2);
    tb = make_tf(0, 0, 0.5, qz);
    check_contact(&cap, &ta, &cap2, &tb, 0.2, gc_v3(0, 0, 1), 1e-12, "crossed capsules apart");
    tb = make_tf(0, 0, 0.1, qz);
    check_contact(&cap, &ta, &cap2, &tb, -0.2, gc_v3(0, 0, 1), 1e-12, "crossed capsules overlap");
    tb = make_tf(0, 0, 0, qz);
    {
        gcContact ct;
        GC_CHECK(gc_collide(&cap, &ta, &cap2, &tb, &ct) == GC_OK, "crossing cores");
        GC_CHECK_NEAR(ct.distance, -0.3, 1e-12, "crossing cores depth");
        GC_CHECK(fabs(fabs(ct.normal.z) - 1) < 1e-12, "crossing cores normal along z");
    }
    tb = make_tf(0.5, 0.4, 0, I);
    check_contact(&cap, &ta, &cap2, &tb, 0.1, gc_v3(0, 1, 0), 1e-12, "parallel capsules");
    tb = make_tf(1.5, 0, 0, I);
    check_contact(&cap, &ta, &cap2, &tb, 0.2, gc_v3(1, 0, 0), 1e-12, "collinear capsules");
    tb = make_tf(2, 0, 0, I);
    check_contact(&sph, &tb, &cap, &ta, 0.8, gc_v3(-1, 0, 0), 1e-12, "sphere-capsule");
    gc_hull_free(&box);
    gc_hull_free(&rbox);
    gc_hull_free(&sph);
    gc_hull_free(&sph2);
    gc_hull_free(&cap);
    gc_hull_free(&cap2);
}

/* gc_penetration: analytic pairs (boxes, rounded boxes, spheres, capsules) and its
 * argument checks; the fuzz and corpus runs compare it with gc_collide on every pair. */
static void test_penetration(void) {
    gcHull box, rbox, sph, cap;
    make_box(1, 1, 1, 0, &box);
    make_box(1, 1, 1, 0.1, &rbox);
    double c[3] = {0, 0, 0}, seg[6] = {-0.5, 0, 0, 0.5, 0, 0};
    gc_hull_build(c, 1, 0.5, 0, &sph);
    gc_hull_build(seg, 2, 0.2, 0, &cap);
    gcQuat I = quat_identity();
    gcTransform ta = make_tf(0, 0, 0, I), tb;
    gcContact p, q;
    int sep = -1;
    /* apart along x by 0.5: separated, lower bound <= 0.5 along a separating axis */
    tb = make_tf(2.5, 0.3, -0.2, I);
    GC_CHECK(gc_penetration(&box, &ta, &box, &tb, &p, &sep) == GC_OK && sep == 1, "boxes apart: separated");
    GC_CHECK(p.distance > 0 && p.distance <= 0.5 + 1e-12, "boxes apart: lower bound %g", p.distance);
    GC_CHECK(fabs(gc_len(p.normal) - 1) < 1e-12 && p.normal.x > 0, "boxes apart: axis (%g %g %g)", p.normal.x,
             p.normal.y, p.normal.z);
    /* penetrating: identical to gc_collide */
    tb = make_tf(1.9, 0.3, -0.2, I);
    GC_CHECK(gc_penetration(&box, &ta, &box, &tb, &p, &sep) == GC_OK && sep == 0, "boxes overlap: not separated");
    gc_collide(&box, &ta, &box, &tb, &q);
    GC_CHECK(contact_identical(&p, &q), "boxes overlap: same contact as gc_collide");
    GC_CHECK_NEAR(p.distance, -0.1, 1e-9, "boxes overlap depth");
    /* rounded boxes whose cores are 0.15 apart: margins 0.2 overlap them */
    tb = make_tf(2.15, 0.1, 0.0, I);
    GC_CHECK(gc_penetration(&rbox, &ta, &rbox, &tb, &p, &sep) == GC_OK && sep == 0, "rounded boxes: touching");
    gc_collide(&rbox, &ta, &rbox, &tb, &q);
    GC_CHECK(contact_identical(&p, &q), "rounded boxes: same contact as gc_collide");
    GC_CHECK_NEAR(p.distance, -0.05, 1e-9, "rounded boxes depth");
    tb = make_tf(2.25, 0.1, 0.0, I);
    GC_CHECK(gc_penetration(&rbox, &ta, &rbox, &tb, &p, &sep) == GC_OK && sep == 1, "rounded boxes: apart");
    GC_CHECK(p.distance > 0 && p.distance <= 0.05 + 1e-12, "rounded boxes apart: bound %g", p.distance);
    /* closed-form shapes go through gc_collide */
    tb = make_tf(0, 0, 1.6, I);
    GC_CHECK(gc_penetration(&box, &ta, &sph, &tb, &p, &sep) == GC_OK && sep == 1, "sphere apart");
    GC_CHECK_NEAR(p.distance, 0.1, 1e-12, "sphere distance");
    tb = make_tf(0, 0, 1.4, I);
    GC_CHECK(gc_penetration(&box, &ta, &sph, &tb, &p, &sep) == GC_OK && sep == 0, "sphere overlap");
    GC_CHECK_NEAR(p.distance, -0.1, 1e-12, "sphere depth");
    tb = make_tf(0, 0.3, 0, I);
    GC_CHECK(gc_penetration(&cap, &ta, &cap, &tb, &p, &sep) == GC_OK && sep == 0, "capsules overlap");
    GC_CHECK_NEAR(p.distance, 0.3 - 0.4, 1e-12, "capsules: parallel axes 0.3 apart, radii 0.2 + 0.2");
    tb = make_tf(0, 0.5, 0, I);
    GC_CHECK(gc_penetration(&cap, &ta, &cap, &tb, &p, &sep) == GC_OK && sep == 1, "capsules apart");
    GC_CHECK_NEAR(p.distance, 0.5 - 0.4, 1e-12, "capsules distance");
    /* invalid arguments */
    gcTransform bad = ta;
    bad.p.x = NAN;
    GC_CHECK(gc_penetration(&box, &ta, &box, &ta, &p, NULL) == GC_ERR_INVALID_ARGUMENT, "NULL separated");
    GC_CHECK(gc_penetration(&box, &ta, &box, &bad, &p, &sep) == GC_ERR_INVALID_ARGUMENT, "NaN transform");
    GC_CHECK(gc_penetration(&box, &ta, &box, &ta, NULL, &sep) == GC_ERR_INVALID_ARGUMENT, "NULL out");
    gc_hull_free(&box);
    gc_hull_free(&rbox);
    gc_hull_free(&sph);
    gc_hull_free(&cap);
}

static void test_invalid_queries(void) {
    gcHull box, empty;
    make_box(1, 1, 1, 0, &box);
    memset(&empty, 0, sizeof(empty));
    gcTransform t = gc_transform_identity(), bad = t;
    bad.p.x = NAN;
    gcContact c;
    GC_CHECK(gc_collide(&box, &t, &empty, &t, &c) == GC_ERR_INVALID_ARGUMENT, "empty hull");
    GC_CHECK(gc_collide(&box, &t, &box, &bad, &c) == GC_ERR_INVALID_ARGUMENT, "NaN transform");
    GC_CHECK(gc_collide(&box, &t, &box, &t, NULL) == GC_ERR_INVALID_ARGUMENT, "NULL out");
    double d;
    GC_CHECK(gc_gjk_distance(&box, NULL, &box, &t, &d, NULL, NULL) == GC_ERR_INVALID_ARGUMENT, "NULL transform");
    gc_hull_free(&box);
}

/* ------------------------------------------------------------------ fuzzing */

/* Largest overlap of the two shapes over candidate directions: face normals of both
 * (and, when edges is set, all edge-edge cross products): the exact minimum
 * translation distance for polytopes. Returns the min over directions of the
 * translation of B along d needed to separate. */
static double brute_mtd(const gcHull *a, const gcTransform *ta, const gcHull *b, const gcTransform *tb, int edges) {
    double best = DBL_MAX;
    gcVec3 dirs[2];
    for (int side = 0; side < 2; ++side) {
        const gcHull *h = side ? b : a;
        const gcTransform *t = side ? tb : ta;
        for (int f = 0; f < h->num_planes; ++f) {
            gcVec3 n = gc_mat3_mul_vec(&t->R, h->plane_normals[f]);
            dirs[0] = side ? gc_neg(n) : n;
            double o = world_support(a, ta, dirs[0]) + world_support(b, tb, gc_neg(dirs[0]));
            if (o < best) best = o;
        }
    }
    if (!edges) return best;
    for (int ta_i = 0; ta_i < a->num_triangles; ++ta_i)
        for (int ea = 0; ea < 3; ++ea) {
            int a0 = a->triangles[3 * ta_i + ea], a1 = a->triangles[3 * ta_i + (ea + 1) % 3];
            if (a0 > a1) continue; /* each undirected edge once */
            gcVec3 da = gc_mat3_mul_vec(&ta->R, gc_sub(a->vertices[a1], a->vertices[a0]));
            for (int tb_i = 0; tb_i < b->num_triangles; ++tb_i)
                for (int eb = 0; eb < 3; ++eb) {
                    int b0 = b->triangles[3 * tb_i + eb], b1 = b->triangles[3 * tb_i + (eb + 1) % 3];
                    if (b0 > b1) continue;
                    gcVec3 db = gc_mat3_mul_vec(&tb->R, gc_sub(b->vertices[b1], b->vertices[b0]));
                    gcVec3 n = gc_cross(da, db);
                    if (gc_len(n) < 1e-9 * gc_len(da) * gc_len(db)) continue;
                    n = gc_normalize(n);
                    for (int s = 0; s < 2; ++s) {
                        gcVec3 d = s ? gc_neg(n) : n;
                        double o = world_support(a, ta, d) + world_support(b, tb, gc_neg(d));
                        if (o < best) best = o;
                    }
                }
        }
    return best;
}

typedef struct FuzzStats {
    int pairs, separated, penetrating, warnings, errors, nan, fail_gap, fail_points, fail_lower, fail_sep,
        fail_min, fail_mtd, max_iterations, fail_pen, pen_early;
} FuzzStats;

/* gc_penetration against gc_collide's answer c (status s) on the same pair:
 * separated exactly when c.distance > 0; overlapping: the identical contact;
 * separated: a positive lower bound on the distance whose normal is a separating
 * axis and whose points are the support points on the surfaces. */
static int verify_penetration(const gcHull *a, const gcTransform *ta, const gcHull *b, const gcTransform *tb,
                              const gcContact *c, gcStatus s, double tol, FuzzStats *st, const char *label) {
    gcContact p;
    int sep = -1, fails = 0;
    gcStatus ps = gc_penetration(a, ta, b, tb, &p, &sep);
    if (ps != s) { fails++; fprintf(stderr, "%s: penetration status %d vs collide %d\n", label, ps, s); }
    if (sep != (c->distance > 0)) {
        fails++;
        fprintf(stderr, "%s: penetration separated=%d but collide distance %.17g\n", label, sep, c->distance);
    } else if (!sep) {
        if (!contact_identical(&p, c)) {
            fails++;
            fprintf(stderr, "%s: penetration contact differs from collide (%.17g vs %.17g)\n", label, p.distance,
                    c->distance);
        }
    } else {
        if (!contact_identical(&p, c)) st->pen_early++;
        double along = -(world_support(a, ta, p.normal) + world_support(b, tb, gc_neg(p.normal)));
        if (!contact_finite(&p) || !(p.distance > 0) || p.distance > c->distance + tol ||
            fabs(gc_len(p.normal) - 1) > 1e-9 || fabs(p.distance - along) > tol ||
            fabs(world_sd(a, ta, p.point_a)) > tol || fabs(world_sd(b, tb, p.point_b)) > tol ||
            fabs(gc_dot(gc_sub(p.point_b, p.point_a), p.normal) - p.distance) > tol) {
            fails++;
            fprintf(stderr, "%s: penetration separated answer: distance %.12g (collide %.12g, axis gap %.12g)\n",
                    label, p.distance, c->distance, along);
        }
    }
    if (fails) st->fail_pen++;
    return fails;
}

/* Checks one query against brute force; returns the number of failed checks. */
static int verify_pair(const gcHull *a, const gcTransform *ta, const gcHull *b, const gcTransform *tb,
                       int exact_mtd, FuzzStats *st, const char *label) {
    gcContact c;
    gcStatus s = gc_collide(a, ta, b, tb, &c);
    int fails = 0;
    st->pairs++;
    if (s < 0) { st->errors++; fails++; fprintf(stderr, "%s: status %d\n", label, s); return fails; }
    if (s == GC_WARN_MAX_ITERATIONS) st->warnings++;
    if (!contact_finite(&c)) { st->nan++; fails++; fprintf(stderr, "%s: NaN\n", label); return fails; }
    if (c.iterations > st->max_iterations) st->max_iterations = c.iterations;
    double size = gc_len(gc_sub(a->aabb_max, a->aabb_min)) + gc_len(gc_sub(b->aabb_max, b->aabb_min)) +
                  2 * (a->radius + b->radius);
    double tol = 1e-7 * size;
    fails += verify_penetration(a, ta, b, tb, &c, s, tol, st, label);
    if (fabs(gc_len(c.normal) - 1) > 1e-9) { fails++; fprintf(stderr, "%s: normal not unit\n", label); }
    /* witnesses on the surfaces */
    double sa = world_sd(a, ta, c.point_a), sb = world_sd(b, tb, c.point_b);
    if (fabs(sa) > tol || fabs(sb) > tol) {
        st->fail_points++; fails++;
        fprintf(stderr, "%s: witness off surface %g %g (dist %g)\n", label, sa, sb, c.distance);
    }
    /* the support-function bound along the reported normal: the true signed
     * distance is >= this; the reported one must not be larger */
    double along = -(world_support(a, ta, c.normal) + world_support(b, tb, gc_neg(c.normal)));
    if (c.distance >= 0) {
        st->separated++;
        if (fabs(gc_len(gc_sub(c.point_b, c.point_a)) - c.distance) > tol) {
            st->fail_gap++; fails++;
            fprintf(stderr, "%s: witness distance %g vs %g\n", label, gc_len(gc_sub(c.point_b, c.point_a)), c.distance);
        }
        if (c.distance - along > tol) {
            st->fail_lower++; fails++;
            fprintf(stderr, "%s: distance %.12g exceeds the separating-plane bound %.12g\n", label, c.distance, along);
        }
    } else {
        st->penetrating++;
        double depth = -c.distance;
        if (fabs(depth + along) > tol) {
            st->fail_lower++; fails++;
            fprintf(stderr, "%s: depth %.12g, overlap along normal %.12g\n", label, depth, -along);
        }
        /* translating B by the depth (plus a hair) separates; a bit less does not */
        gcTransform moved = *tb;
        moved.p = gc_madd(tb->p, c.normal, depth * (1 + 1e-6) + 1e-7 * size);
        gcContact m;
        gc_collide(a, ta, b, &moved, &m);
        if (!(m.distance > 0)) {
            st->fail_sep++; fails++;
            fprintf(stderr, "%s: moving by depth %g leaves %g\n", label, depth, m.distance);
        }
        if (depth > 1e-5 * size) {
            moved.p = gc_madd(tb->p, c.normal, depth * (1 - 1e-3));
            gc_collide(a, ta, b, &moved, &m);
            if (!(m.distance < 0)) {
                st->fail_min++; fails++;
                fprintf(stderr, "%s: moving by 0.999 depth separates (%g)\n", label, m.distance);
            }
        }
        /* never deeper than the best face-normal axis; equal to the exact MTD */
        double mtd = brute_mtd(a, ta, b, tb, exact_mtd);
        if (depth > mtd + tol || (exact_mtd && depth < mtd - tol)) {
            st->fail_mtd++; fails++;
            fprintf(stderr, "%s: depth %.12g vs brute-force MTD %.12g\n", label, depth, mtd);
        }
    }
    return fails;
}

static void random_hull(gcHull *h, int n, double sx, double sy, double sz) {
    double pts[3 * 128];
    for (;;) {
        for (int i = 0; i < n; ++i) {
            pts[3 * i] = rng_range(-sx, sx);
            pts[3 * i + 1] = rng_range(-sy, sy);
            pts[3 * i + 2] = rng_range(-sz, sz);
        }
        if (gc_hull_build(pts, n, 0, 0, h) == GC_OK) return;
    }
}

static void test_fuzz(void) {
    FuzzStats st;
    memset(&st, 0, sizeof(st));
    rng_seed(2024);
    int total_fail = 0;
    for (int k = 0; k < 3000; ++k) {
        gcHull a, b;
        int na = 4 + (int)(rng_uniform() * 125), nb = 4 + (int)(rng_uniform() * 125);
        int small = k % 4 == 0;
        if (small) { na = 4 + k % 9; nb = 4 + (k / 3) % 9; }
        random_hull(&a, na, rng_range(0.2, 1.5), rng_range(0.2, 1.5), rng_range(0.2, 1.5));
        random_hull(&b, nb, rng_range(0.2, 1.5), rng_range(0.2, 1.5), rng_range(0.2, 1.5));
        gcTransform ta = make_tf(rng_range(-1, 1), rng_range(-1, 1), rng_range(-1, 1), random_quat());
        double spread = k % 2 ? 1.0 : 3.0;
        gcTransform tb = make_tf(rng_range(-spread, spread), rng_range(-spread, spread), rng_range(-spread, spread),
                                 random_quat());
        char label[64];
        snprintf(label, sizeof label, "fuzz pair %d", k);
        total_fail += verify_pair(&a, &ta, &b, &tb, small, &st, label);
        /* with margins: rounded hulls */
        if (k % 5 == 0) {
            a.radius = 0.05;
            b.radius = 0.1;
            snprintf(label, sizeof label, "fuzz rounded pair %d", k);
            total_fail += verify_pair(&a, &ta, &b, &tb, 0, &st, label);
        }
        gc_hull_free(&a);
        gc_hull_free(&b);
    }
    printf("fuzz: %d queries, %d separated (%d proven early by gc_penetration), %d penetrating, %d warnings, "
           "max iterations %d\n", st.pairs, st.separated, st.pen_early, st.penetrating, st.warnings, st.max_iterations);
    GC_CHECK(total_fail == 0,
             "fuzz failures: %d (errors %d nan %d gap %d points %d bound %d sep %d min %d mtd %d penetration %d)",
             total_fail, st.errors, st.nan, st.fail_gap, st.fail_points, st.fail_lower, st.fail_sep, st.fail_min,
             st.fail_mtd, st.fail_pen);
    GC_CHECK(st.pen_early > 1000, "gc_penetration stops early on most separated pairs (%d)", st.pen_early);
    GC_CHECK(st.warnings == 0, "fuzz warnings: %d", st.warnings);
    GC_CHECK(st.separated > 500 && st.penetrating > 500, "fuzz covers both cases (%d, %d)", st.separated,
             st.penetrating);
}

/* ---------------------------------------------------------- regression corpus */

/* Format (whitespace separated, '#' starts a comment line):
 *   case <name>
 *   shape A|B box <hx> <hy> <hz> <radius>
 *   shape A|B sphere <radius>
 *   shape A|B capsule <half_length_along_x> <radius>
 *   shape A|B points <radius> <n> <x y z> * n
 *   pose A|B <px> <py> <pz> <axis x y z> <angle_degrees>
 *   expect distance <value> <tol>
 *   expect normal <nx> <ny> <nz> <tol>
 *   frames <n>        also run under n random rigid motions applied to both poses
 *   end
 * Every case also runs the generic brute-force checks of the fuzzer. */
typedef struct CorpusCase {
    char name[128];
    gcHull hull[2];
    int has_hull[2];
    gcTransform pose[2];
    int has_distance, has_normal, frames;
    double distance, distance_tol, normal_tol;
    gcVec3 normal;
} CorpusCase;

static int read_shape(FILE *f, gcHull *h) {
    char kind[32];
    if (fscanf(f, "%31s", kind) != 1) return 0;
    if (!strcmp(kind, "box")) {
        double hx, hy, hz, r;
        if (fscanf(f, "%lf %lf %lf %lf", &hx, &hy, &hz, &r) != 4) return 0;
        return make_box(hx, hy, hz, r, h) == GC_OK;
    }
    if (!strcmp(kind, "sphere")) {
        double r, c[3] = {0, 0, 0};
        if (fscanf(f, "%lf", &r) != 1) return 0;
        return gc_hull_build(c, 1, r, 0, h) == GC_OK;
    }
    if (!strcmp(kind, "capsule")) {
        double hl, r;
        if (fscanf(f, "%lf %lf", &hl, &r) != 2) return 0;
        double seg[6] = {-hl, 0, 0, hl, 0, 0};
        return gc_hull_build(seg, 2, r, 0, h) == GC_OK;
    }
    if (!strcmp(kind, "points")) {
        double r;
        int n;
        if (fscanf(f, "%lf %d", &r, &n) != 2 || n < 1 || n > 4096) return 0;
        double *p = (double *)malloc(sizeof(double) * 3 * (size_t)n);
        for (int i = 0; i < 3 * n; ++i)
            if (fscanf(f, "%lf", &p[i]) != 1) { free(p); return 0; }
        int ok = gc_hull_build(p, n, r, 0, h) == GC_OK;
        free(p);
        return ok;
    }
    return 0;
}

static void run_corpus_case(CorpusCase *cc, FuzzStats *st) {
    int small = cc->hull[0].num_vertices >= 4 && cc->hull[0].num_vertices <= 16 && cc->hull[0].radius == 0 &&
                cc->hull[1].num_vertices >= 4 && cc->hull[1].num_vertices <= 16 && cc->hull[1].radius == 0;
    rng_seed(99);
    for (int fr = 0; fr <= cc->frames; ++fr) {
        gcTransform ta = cc->pose[0], tb = cc->pose[1];
        gcMat3 G = gc_mat3_identity();
        if (fr > 0) {
            /* the same rigid motion applied to both */
            gcTransform g = make_tf(rng_range(-5, 5), rng_range(-5, 5), rng_range(-5, 5), random_quat());
            G = g.R;
            ta.R = gc_mat3_mul(&g.R, &cc->pose[0].R);
            ta.p = gc_transform_point(&g, cc->pose[0].p);
            tb.R = gc_mat3_mul(&g.R, &cc->pose[1].R);
            tb.p = gc_transform_point(&g, cc->pose[1].p);
        }
        char label[200];
        snprintf(label, sizeof label, "corpus %s (frame %d)", cc->name, fr);
        int fails = verify_pair(&cc->hull[0], &ta, &cc->hull[1], &tb, small, st, label);
        GC_CHECK(fails == 0, "%s: %d brute-force checks failed", label, fails);
        gcContact c;
        gcStatus s = gc_collide(&cc->hull[0], &ta, &cc->hull[1], &tb, &c);
        GC_CHECK(s == GC_OK, "%s: status %d", label, s);
        if (cc->has_distance)
            GC_CHECK(fabs(c.distance - cc->distance) <= cc->distance_tol, "%s: distance %.12g expected %.12g", label,
                     c.distance, cc->distance);
        if (cc->has_normal) {
            gcVec3 n = gc_mat3_mul_vec(&G, cc->normal);
            GC_CHECK(gc_len(gc_sub(c.normal, n)) <= cc->normal_tol, "%s: normal (%g %g %g) expected (%g %g %g)",
                     label, c.normal.x, c.normal.y, c.normal.z, n.x, n.y, n.z);
        }
    }
}

static void test_corpus(const char *path) {
    FILE *f = fopen(path, "r");
    GC_CHECK(f != NULL, "cannot open corpus %s (run from the repository root)", path);
    if (!f) return;
    FuzzStats st;
    memset(&st, 0, sizeof(st));
    CorpusCase cc;
    memset(&cc, 0, sizeof(cc));
    int in_case = 0, cases = 0, parse_errors = 0;
    char tok[128];
    while (fscanf(f, "%127s", tok) == 1) {
        if (tok[0] == '#') {
            int ch;
            while ((ch = fgetc(f)) != EOF && ch != '\n') {}
            continue;
        }
        if (!strcmp(tok, "case")) {
            memset(&cc, 0, sizeof(cc));
            cc.pose[0] = cc.pose[1] = gc_transform_identity();
            in_case = fscanf(f, "%127s", cc.name) == 1;
        } else if (in_case && (!strcmp(tok, "shape") || !strcmp(tok, "pose"))) {
            char which[8];
            if (fscanf(f, "%7s", which) != 1 || (which[0] != 'A' && which[0] != 'B')) { parse_errors++; break; }
            int k = which[0] == 'B';
            if (!strcmp(tok, "shape")) {
                cc.has_hull[k] = read_shape(f, &cc.hull[k]);
                if (!cc.has_hull[k]) { parse_errors++; fprintf(stderr, "corpus %s: bad shape\n", cc.name); }
            } else {
                double p[7];
                if (fscanf(f, "%lf %lf %lf %lf %lf %lf %lf", &p[0], &p[1], &p[2], &p[3], &p[4], &p[5], &p[6]) != 7) {
                    parse_errors++;
                    break;
                }
                gcQuat q = gc_len(gc_v3(p[3], p[4], p[5])) > 0 ? quat_axis_angle(gc_v3(p[3], p[4], p[5]), p[6] * kPi / 180)
                                                             : quat_identity();
                cc.pose[k] = make_tf(p[0], p[1], p[2], q);
            }
        } else if (in_case && !strcmp(tok, "expect")) {
            char what[32];
            if (fscanf(f, "%31s", what) != 1) { parse_errors++; break; }
            if (!strcmp(what, "distance")) {
                cc.has_distance = fscanf(f, "%lf %lf", &cc.distance, &cc.distance_tol) == 2;
            } else if (!strcmp(what, "normal")) {
                cc.has_normal = fscanf(f, "%lf %lf %lf %lf", &cc.normal.x, &cc.normal.y, &cc.normal.z, &cc.normal_tol) == 4;
                cc.normal = gc_normalize(cc.normal);
            } else {
                parse_errors++;
            }
        } else if (in_case && !strcmp(tok, "frames")) {
            if (fscanf(f, "%d", &cc.frames) != 1) parse_errors++;
        } else if (in_case && !strcmp(tok, "end")) {
            if (cc.has_hull[0] && cc.has_hull[1]) {
                run_corpus_case(&cc, &st);
                cases++;
            } else {
                parse_errors++;
            }
            gc_hull_free(&cc.hull[0]);
            gc_hull_free(&cc.hull[1]);
            in_case = 0;
        } else {
            fprintf(stderr, "corpus: unexpected token '%s'\n", tok);
            parse_errors++;
        }
    }
    fclose(f);
    printf("corpus: %d cases, %d queries, %d penetrating, max iterations %d, penetration mismatches %d\n", cases,
           st.pairs, st.penetrating, st.max_iterations, st.fail_pen);
    GC_CHECK(st.fail_pen == 0, "corpus: gc_penetration disagrees with gc_collide on %d queries", st.fail_pen);
    GC_CHECK(parse_errors == 0, "corpus parse errors: %d", parse_errors);
    GC_CHECK(cases >= 20, "corpus has %d cases", cases);
}

int main(void) {
    test_cube_hull();
    test_box_mass();
    test_tetra_mass();
    test_sphere_capsule_mass();
    test_degenerate_inputs();
    test_large_hull_support();
    test_point_query();
    test_box_box();
    test_spheres_capsules();
    test_invalid_queries();
    test_penetration();
    test_fuzz();
    test_corpus("native/tests/corpus/geometry_cases.txt");
    return gc_test_summary("test_geometry");
}
