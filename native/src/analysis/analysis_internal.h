/* The grasp analysis' private layout (analysis/ only): the workspace that owns all its storage,
 * the d-dimensional hull's facets, and what its files share. grasp_workspace.c makes the storage,
 * hull_nd.c builds hulls and searches them, closure_lp.c decides closure by a linear program,
 * grasp_quality.c turns contacts into wrenches and reads the measures off them. */
#ifndef GC_ANALYSIS_INTERNAL_H
#define GC_ANALYSIS_INTERNAL_H

#include "grasp_quality.h"

#include <math.h>
#include <stdint.h>
#include <string.h>

#define D GC_HULL_MAX_DIM
/* The hull's inner functions are compiled once per dimension (3 and 6), loops unrolled. */
#if defined(__GNUC__) || defined(__clang__)
#define GC_ALWAYS_INLINE inline __attribute__((always_inline))
#else
#define GC_ALWAYS_INLINE inline
#endif
#define GC_GRASP_MAX_EDGES 1024

typedef struct Facet {
    /* What the walks and the visibility search read, in one cache line. */
    int v[D];           /* vertices (point indices) */
    int nb[D];          /* nb[i]: the facet across the ridge without v[i] */
    int tested, visible;/* iteration stamps */
    double pdist;       /* signed distance of the current apex (valid when tested == stamp) */
    double n[D];        /* unit outward normal */
    double off;         /* n.x + off: signed distance of x */
    double cdist;       /* signed distance of the interior point c (< 0) */
    double vol;         /* volume of the simplex (c, facet) */
    double fdist;       /* distance of the furthest outside point */
    uint64_t key[2];    /* sums of the vertices' random words (ridge keys, see link_new_facets) */
    int outside;        /* head of the outside-point list, -1 when empty */
    int furthest;       /* furthest outside point, -1 when the set is empty */
    int alive;
} Facet;

/* A set's answer kept for gcGraspDef.reuse: its edge wrenches, epsilon (from a search) and the
 * points of its nearest facet. */
#define GC_REUSE_SLOTS 4
typedef struct ReuseSlot {
    int rows, edges, cap;
    double tolerance, epsilon;
    double *wrench;     /* rows x 6 */
    int vertices[D];
} ReuseSlot;

/* A mu_min answer kept for gcGraspDef.reuse: the contacts it was found for (points, normals,
 * center, radius in one row) and mu_max. */
typedef struct MuMinSlot {
    int contacts, edges, cap, rows;
    double tolerance, mu_max, answer;
    double margin;      /* the support search's epsilon at the answer, 0 when the LP decided there */
    double *input;      /* 6 x contacts + 4, then rows x 6: the edge wrenches at the answer */
} MuMinSlot;

struct gcGraspWorkspace {
    char error[256];
    MuMinSlot mu_min[GC_REUSE_SLOTS];
    int mu_min_next;
    ReuseSlot reuse[GC_REUSE_SLOTS];
    int reuse_next;     /* the slot the next new set takes */
    int nearest_vertices[D];    /* of the last quality_fast answer in closure */
    int cap_points;
    double *wrench;     /* cap_points x 6 */
    double *force;      /* cap_points x 3 */
    double *torque;     /* cap_points x 3 */
    double *residual;   /* cap_points x 6: Gram-Schmidt residuals */
    int *next;          /* outside-set links per point */
    int cap_facets;
    Facet *facets;
    int high_water;     /* facets[0 .. high_water) have been used */
    int *free_list;
    int num_free;
    int *visible;       /* cap_facets: this iteration's visible facets */
    int *created;       /* cap_facets: this iteration's new facets */
    int cap_pending;
    int *pending;       /* stack of facets that had outside points when made */
    uint64_t *vertex_hash; /* cap_points x 2: two random 64-bit words per point */
    int cap_ridges;     /* the ridge table of one iteration (open addressing) */
    int ridge_slots;    /* the part of it this iteration uses (a power of two) */
    uint64_t *ridge_key;    /* two words per slot */
    int *ridge_facet;   /* facet << 3 | slot; -1 after its match */
    int *ridge_stamp;
    int ridge_gen;
    int *created_apex;  /* cap_facets: where the apex sits in each new facet */
    double *facet_off;  /* cap_facets: the support search's copy of each live facet's off (-inf
                         * when dead), scanned without touching the facets */
    int cap_lp;
    double *lp;         /* the closure LP's tableau */
    int *lp_basis;
    int edges_cached;
    double cos_table[GC_GRASP_MAX_EDGES], sin_table[GC_GRASP_MAX_EDGES];
};
/* A hull being built or searched: the points, the tolerances, the interior point. */
typedef struct Hull {
    gcGraspWorkspace *ws;
    const double *pts;
    int n, d;
    double tol;         /* absolute: visibility and flatness */
    double vtol;        /* absolute: a pencil plane must pass this close to its vertices */
    double c[D];        /* interior point (centroid of the initial simplex) */
    int stamp;
    int max_facets;
    int volumes;        /* 0: the simplex volumes are not needed (the support-function search) */
} Hull;

static inline const double *point(const Hull *h, int i, int d) { return h->pts + (size_t)i * (size_t)d; }

static inline double dotd(const double *a, const double *b, int d) {
    double s = 0.0;
    for (int k = 0; k < d; ++k) s += a[k] * b[k];
    return s;
}

static inline double facet_dist(const Facet *f, const double *x, int d) { return dotd(f->n, x, d) + f->off; }

/* grasp_workspace.c: the message (always returns st) and the storage, grown only when a larger
 * problem comes. */
gcStatus gc_grasp_set_error(gcGraspWorkspace *ws, gcStatus st, const char *fmt, ...);
/* realloc to count x size; 0 (and *p unchanged) when out of memory. */
int gc_grasp_grow(void **p, size_t count, size_t size);
gcStatus gc_grasp_ensure_points(gcGraspWorkspace *ws, int n);
gcStatus gc_grasp_ensure_facets(gcGraspWorkspace *ws, int n, int max_facets);
gcStatus gc_grasp_ensure_ridges(gcGraspWorkspace *ws, int need);
gcStatus gc_grasp_push_pending(gcGraspWorkspace *ws, int *count, int f);
/* hull_nd.c: a facet's hyperplane solved from its vertices, oriented away from h->c; 0 when the
 * vertices are affinely dependent. */
int gc_hull_exact_plane(const Hull *h, Facet *f);
/* closure_lp.c: the closure LP (gc_closure_lp) with an optional warm basis. */
gcStatus gc_closure_lp_warm(gcGraspWorkspace *ws, const double *points, int n, int d, int *warm, double *t_max);

#endif
