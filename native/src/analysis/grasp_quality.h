/* Grasp quality: the convex hull of points in 3 to 6 dimensions (the grasp wrench space and
 * its force and torque parts) and the measures read off it. No world types: this layer sits
 * beside the 3-D hull code. Public entry points are in graspcore.h; this header gives the
 * tests the d-dimensional hull itself. */
#ifndef GC_GRASP_QUALITY_H
#define GC_GRASP_QUALITY_H

#include "graspcore.h"

#define GC_HULL_MAX_DIM 6

typedef enum gcHullResult {
    GC_HULL_FULL = 0,   /* a d-dimensional hull was built */
    GC_HULL_FLAT = 1    /* the points span less than d affine dimensions (volume 0, no interior) */
} gcHullResult;

/* What a hull answers. offset_max: the largest signed distance of the origin to a facet
 * hyperplane (negative: the origin is inside every facet); the nearest facet's unit outward
 * normal in nearest_normal (distance -offset_max). */
typedef struct gcHullSummary {
    gcHullResult result;
    int facets;
    double volume;
    double offset_max;
    double nearest_normal[GC_HULL_MAX_DIM];
    int nearest_vertices[GC_HULL_MAX_DIM];  /* the nearest facet's points (gc_hull_nearest only) */
} gcHullSummary;

/* Hull of n points of dimension d (3..6), rows of d doubles; tolerance relative to the largest
 * point norm. GC_ERR_CAPACITY past def->max_facets, GC_ERR_NO_MEMORY; the message is in ws. */
gcStatus gc_hull_nd(gcGraspWorkspace *ws, const double *points, int n, int d, double tolerance,
                    int max_facets, gcHullSummary *out);

/* Dimension of the linear span of n points of dimension d (pivoted Gram-Schmidt, residuals
 * below tolerance x the largest norm count as zero). */
gcStatus gc_span_rank(gcGraspWorkspace *ws, const double *points, int n, int d, double tolerance, int *rank);

/* The nearest facet of the hull of n points of dimension d (3..6) without building the hull
 * (the support-function search). Origin inside: offset_max and nearest_normal as gc_hull_nd
 * gives them (the same facet plane, solved from its vertices). Origin outside or within the
 * tolerance of the boundary: offset_max >= -tolerance x scale, the origin's signed distance to a
 * supporting facet plane (not always the largest). facets and volume are -1 (not computed);
 * GC_HULL_FLAT as gc_hull_nd. */
gcStatus gc_hull_nearest(gcGraspWorkspace *ws, const double *points, int n, int d, double tolerance,
                         int max_facets, gcHullSummary *out);

/* The closure LP: *t_max = the largest t with sum lambda_i x_i = 0, sum lambda_i = 1,
 * lambda_i >= t over n points of dimension d (1..6); > 0 exactly when the origin is in the
 * relative interior of their hull. -INFINITY when t < -1 or there are no points.
 * GC_ERR_DEGENERATE if the simplex method hits its pivot cap. */
gcStatus gc_closure_lp(gcGraspWorkspace *ws, const double *points, int n, int d, double *t_max);

#endif
