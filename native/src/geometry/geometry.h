/* Convex geometry: hulls, support mapping, GJK distance, EPA penetration,
 * the point/sphere-vs-convex fast path, and polyhedral mass properties.
 * Private to the core. Every query has capped iterations and returns a status;
 * none allocates (hull building does, once, at body creation). */
#ifndef GC_GEOMETRY_H
#define GC_GEOMETRY_H

#include "base/gc_math.h"
#include "graspcore.h"

/* A convex shape is a "core" point set plus a margin radius:
 *   hull      = >= 4 non-coplanar points, radius >= 0
 *   sphere    = 1 point, radius > 0
 *   capsule   = 2 points, radius > 0
 * The surface is the core inflated by the radius (Minkowski sum with a ball). */
typedef struct gcHull {
    int num_vertices;
    gcVec3 *vertices;          /* hull vertices only (interior points dropped) */
    int num_triangles;
    int *triangles;            /* 3 * num_triangles vertex indices, CCW seen from outside */
    int num_planes;
    gcVec3 *plane_normals;     /* one per triangle, outward unit */
    double *plane_offsets;     /* plane: dot(n, x) = offset */
    int *adjacency;            /* optional vertex adjacency (CSR) for hill-climbing; may be NULL */
    int *adjacency_start;      /* num_vertices + 1 entries when adjacency != NULL */
    double radius;             /* margin radius (sphere/capsule) */
    gcVec3 aabb_min, aabb_max; /* of the core, local frame */
    double min_width;          /* smallest extent over the face normals (thin plates); 2*radius for spheres */
    int num_edges;             /* feature edges (where faces meet at an angle; a capsule's segment) */
    int *edges;                /* 2 * num_edges vertex indices; NULL when none */
    double volume;             /* of the inflated shape for spheres/capsules, of the hull otherwise */
    gcVec3 centroid;           /* volume centroid, local frame */
    gcMat3 inertia_unit;       /* inertia tensor about the centroid for unit density, local axes */
    /* Structure-of-arrays copy of `vertices` for the vectorised support scan, built by
     * gc_hull_build: soa_x, soa_y, soa_z each hold num_padded entries (num_vertices
     * rounded up to a multiple of 4; the padding repeats vertex 0), 32-byte aligned,
     * one allocation starting at soa_x. NULL in a hull not made by gc_hull_build: the
     * queries then read `vertices`. Do not edit `vertices` of a built hull (the copy
     * would go stale). */
    double *soa_x, *soa_y, *soa_z;
    int num_padded;
} gcHull;

/* Build from n points (xyz triples). tolerance: points closer than this to a face are
 * merged (pass 0 for an automatic, scale-relative tolerance).
 * GC_ERR_DEGENERATE when the points are coplanar/collinear/coincident and radius == 0
 * (n == 1 or 2 with radius > 0 gives a sphere or a capsule). */
gcStatus gc_hull_build(const double *points, int n, double radius, double tolerance, gcHull *out);
void gc_hull_free(gcHull *hull);

/* Farthest core point along dir (local frame). */
gcVec3 gc_hull_support(const gcHull *hull, gcVec3 dir);

/* Closest-point query of a point against the core, local frame.
 * Returns the signed distance from p to the *inflated* surface (negative inside),
 * the closest surface point and the outward unit normal there.
 * Exact for hulls: outside by GJK on the core, inside by the least-penetrated face. */
gcStatus gc_point_query(const gcHull *hull, gcVec3 p, double *signed_distance,
                        gcVec3 *surface_point, gcVec3 *normal);

/* Result of a convex-convex query between A (at ta) and B (at tb), world frame. */
typedef struct gcContact {
    double distance;   /* signed, between inflated surfaces: > 0 apart, < 0 penetrating */
    gcVec3 normal;     /* unit, from A towards B */
    gcVec3 point_a;    /* on A's inflated surface */
    gcVec3 point_b;    /* on B's inflated surface */
    int iterations;    /* GJK + EPA iterations used */
} gcContact;

/* GJK distance between the cores, then EPA when the cores overlap; radii are
 * subtracted at the end. Never loops more than GC_GJK_MAX_ITERATIONS /
 * GC_EPA_MAX_ITERATIONS; returns GC_WARN_MAX_ITERATIONS with the best answer so
 * far when the cap is hit, never NaN. */
#define GC_GJK_MAX_ITERATIONS 64
#define GC_EPA_MAX_ITERATIONS 64
gcStatus gc_collide(const gcHull *a, const gcTransform *ta, const gcHull *b,
                    const gcTransform *tb, gcContact *out);

/* Penetration query with libccd's ccdGJKPenetration contract: GJK stops as soon as
 * it finds a separating axis (no distance computed); when the shapes overlap, EPA
 * gives the depth, normal and witness points exactly as gc_collide does.
 * *separated (required) is set to 1 when the inflated shapes do not touch, 0 when
 * they overlap. Then:
 *   separated == 0: *out is what gc_collide returns (distance <= 0).
 *   separated == 1: out->distance > 0 is only a LOWER BOUND on the true distance
 *     (the gap between the two support planes of the separating axis), normal is
 *     that axis (unit, A towards B), point_a / point_b are the support points of A
 *     along normal and of B along -normal on the inflated surfaces. When GJK had to
 *     converge to prove separation the values are gc_collide's exact ones.
 * separated == 1 exactly when gc_collide's distance would be > 0. */
gcStatus gc_penetration(const gcHull *a, const gcTransform *ta, const gcHull *b,
                        const gcTransform *tb, gcContact *out, int *separated);

/* Plain GJK distance between cores (no radii): >= 0; 0 when they overlap. */
gcStatus gc_gjk_distance(const gcHull *a, const gcTransform *ta, const gcHull *b,
                         const gcTransform *tb, double *distance, gcVec3 *point_a, gcVec3 *point_b);

#endif
