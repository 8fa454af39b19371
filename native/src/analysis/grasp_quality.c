/* Grasp quality: the grasp wrench space of point contacts with linearised friction cones
 * (graspcore.h) and the measures read off it: closure (6-D, and the force-only and torque-only
 * conditions in 3-D), epsilon, the weakest direction, the volume, mu_min.
 *
 * Closure, epsilon and the weakest direction never need the whole hull:
 *  - A small linear program (gc_closure_lp: the largest t with sum lambda_i w_i = 0,
 *    sum lambda_i = 1, lambda_i >= t) decides closure, its answer certified against the hull's
 *    rule both ways (lp_decide); a hair from the boundary it leaves the decision to
 *  - the support-function search (nearest_run): a hull of a few of the points grows by the
 *    point furthest along its nearest facet's normal until that facet supports the whole set;
 *    its plane is then a facet plane of the full hull and none is nearer: epsilon exactly.
 * The volume (gcGraspDef.volume = 1, the default) needs every facet: the whole 6-D hull, built
 * by quickhull with simplicial facets (an initial simplex of well-spread points, an outside set
 * per facet, the furthest outside point added next, the facets it sees replaced by a cone of new
 * facets over the horizon). What makes both hulls fast on these inputs:
 *  - A new facet's hyperplane comes from the pencil of its two horizon facets (the visible F
 *    and the hidden G share the ridge, and the apex p must lie on the new plane:
 *    N = dist(p,F) G - dist(p,G) F), O(d) instead of solving a (d-1) x d system. A pencil
 *    that cancels is solved from the vertices instead. At the end every facet is checked
 *    against all its vertices (solved again if one is off by more than 1e-12 of the scale);
 *    the search solves the facet it answers with from its vertices.
 *  - New facets are linked to each other through a table of their ridges, keyed by sums of
 *    random words of the ridge's vertices (each facet carries its sums, updated in O(1)).
 *  - The volume of the simplex (c, N) (c a fixed interior point) follows from (c, F) by the
 *    same pencil: both are determinants affine in the apex and vanish on the hyperplane
 *    through c and the ridge.
 * Coplanar points (the k edge wrenches of one contact all lie on a 2-flat) are "not visible"
 * within the tolerance, so coplanar facets stay as adjacent simplices; the answers (the
 * hyperplanes, the volume) do not depend on how a flat face is cut into simplices.
 * mu_min follows the LP's margin as mu changes (Brent's method) and checks its answer with the
 * rule grasp_quality uses. All storage is in the workspace and grows only when a larger problem
 * comes. */
#include "grasp_quality.h"

#include <math.h>
#include <stdint.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define D GC_HULL_MAX_DIM
/* The hull's inner functions are compiled once per dimension (3 and 6), loops unrolled. */
#if defined(__GNUC__) || defined(__clang__)
#define GC_ALWAYS_INLINE inline __attribute__((always_inline))
#else
#define GC_ALWAYS_INLINE inline
#endif
#define GC_GRASP_MAX_EDGES 1024

static const double kTwoPi = 6.28318530717958647692;

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

static gcStatus set_error(gcGraspWorkspace *ws, gcStatus st, const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(ws->error, sizeof ws->error, fmt, ap);
    va_end(ap);
    return st;
}

gcGraspDef gc_default_grasp_def(void) {
    gcGraspDef def;
    memset(&def, 0, sizeof def);
    def.edges = 8;
    def.tolerance = 1e-10;
    def.max_facets = 1 << 20;
    def.volume = 1;
    return def;
}

gcGraspWorkspace *gc_grasp_workspace_create(void) {
    gcGraspWorkspace *ws = calloc(1, sizeof *ws);
    return ws;
}

void gc_grasp_workspace_destroy(gcGraspWorkspace *ws) {
    if (!ws) return;
    free(ws->wrench);
    free(ws->force);
    free(ws->torque);
    free(ws->residual);
    free(ws->next);
    free(ws->facets);
    free(ws->free_list);
    free(ws->visible);
    free(ws->created);
    free(ws->pending);
    free(ws->vertex_hash);
    free(ws->ridge_key);
    free(ws->ridge_facet);
    free(ws->ridge_stamp);
    free(ws->created_apex);
    free(ws->facet_off);
    free(ws->lp);
    free(ws->lp_basis);
    for (int k = 0; k < GC_REUSE_SLOTS; ++k) free(ws->reuse[k].wrench), free(ws->mu_min[k].input);
    free(ws);
}

const char *gc_grasp_workspace_error(const gcGraspWorkspace *ws) { return ws ? ws->error : "no workspace"; }

/* ---- storage ---------------------------------------------------------------------- */

static int grow(void **p, size_t count, size_t size) {
    void *q = realloc(*p, count * size);
    if (!q) return 0;
    *p = q;
    return 1;
}

static gcStatus ensure_points(gcGraspWorkspace *ws, int n) {
    if (n <= ws->cap_points) return GC_OK;
    int cap = ws->cap_points ? ws->cap_points : 64;
    while (cap < n) cap *= 2;
    if (!grow((void **)&ws->wrench, (size_t)cap * 6, sizeof(double)) ||
        !grow((void **)&ws->force, (size_t)cap * 3, sizeof(double)) ||
        !grow((void **)&ws->torque, (size_t)cap * 3, sizeof(double)) ||
        !grow((void **)&ws->residual, (size_t)cap * 6, sizeof(double)) ||
        !grow((void **)&ws->next, (size_t)cap, sizeof(int)) ||
        !grow((void **)&ws->vertex_hash, (size_t)cap * 2, sizeof(uint64_t)))
        return set_error(ws, GC_ERR_NO_MEMORY, "workspace: out of memory for %d wrenches", n);
    /* Two random words per point index (splitmix64), made once: the ridge keys sum them. */
    for (int i = ws->cap_points; i < cap; ++i) {
        uint64_t z = (uint64_t)(i + 1) * 0x9E3779B97F4A7C15ull;
        z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
        z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
        ws->vertex_hash[2 * i] = z ^ (z >> 31);
        z = (uint64_t)(i + 1) * 0xD1B54A32D192ED03ull;
        z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
        z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
        ws->vertex_hash[2 * i + 1] = z ^ (z >> 31);
    }
    ws->cap_points = cap;
    return GC_OK;
}

static gcStatus ensure_facets(gcGraspWorkspace *ws, int n, int max_facets) {
    if (n <= ws->cap_facets) return GC_OK;
    if (n > max_facets)
        return set_error(ws, GC_ERR_CAPACITY, "max_facets: the hull needs more than %d facets", max_facets);
    int cap = ws->cap_facets ? ws->cap_facets : 1024;
    while (cap < n) cap *= 2;
    if (cap > max_facets) cap = max_facets;
    if (!grow((void **)&ws->facets, (size_t)cap, sizeof(Facet)) ||
        !grow((void **)&ws->free_list, (size_t)cap, sizeof(int)) ||
        !grow((void **)&ws->visible, (size_t)cap, sizeof(int)) ||
        !grow((void **)&ws->created, (size_t)cap, sizeof(int)) ||
        !grow((void **)&ws->created_apex, (size_t)cap, sizeof(int)) ||
        !grow((void **)&ws->facet_off, (size_t)cap, sizeof(double)))
        return set_error(ws, GC_ERR_NO_MEMORY, "workspace: out of memory for %d facets", n);
    ws->cap_facets = cap;
    return GC_OK;
}

/* A ridge table of at least 2 x need slots (a power of two), emptied; only those slots are used,
 * so a small step touches few cache lines even after a large hull grew the table. */
static gcStatus ensure_ridges(gcGraspWorkspace *ws, int need) {
    int cap = 64;
    while (cap < 2 * need) cap *= 2;
    if (cap > ws->cap_ridges) {
        if (!grow((void **)&ws->ridge_key, (size_t)cap * 2, sizeof(uint64_t)) ||
            !grow((void **)&ws->ridge_facet, (size_t)cap, sizeof(int)) ||
            !grow((void **)&ws->ridge_stamp, (size_t)cap, sizeof(int)))
            return set_error(ws, GC_ERR_NO_MEMORY, "workspace: out of memory for %d ridges", need);
        for (int i = ws->cap_ridges; i < cap; ++i) ws->ridge_stamp[i] = 0;
        ws->cap_ridges = cap;
    }
    ws->ridge_slots = cap;
    if (++ws->ridge_gen == 0x7fffffff) {
        memset(ws->ridge_stamp, 0, sizeof(int) * (size_t)ws->cap_ridges);
        ws->ridge_gen = 1;
    }
    return GC_OK;
}

static gcStatus push_pending(gcGraspWorkspace *ws, int *count, int f) {
    if (*count >= ws->cap_pending) {
        int cap = ws->cap_pending ? ws->cap_pending * 2 : 1024;
        if (!grow((void **)&ws->pending, (size_t)cap, sizeof(int)))
            return set_error(ws, GC_ERR_NO_MEMORY, "workspace: out of memory");
        ws->cap_pending = cap;
    }
    ws->pending[(*count)++] = f;
    return GC_OK;
}

/* ---- small dense algebra -------------------------------------------------------------- */

static inline double dotd(const double *a, const double *b, int d) {
    double s = 0.0;
    for (int k = 0; k < d; ++k) s += a[k] * b[k];
    return s;
}

static inline double facet_dist(const Facet *f, const double *x, int d) { return dotd(f->n, x, d) + f->off; }

/* |det| of the d x d matrix a (row-major, destroyed), partial pivoting. */
static double abs_det(double *a, int d) {
    double det = 1.0;
    for (int c = 0; c < d; ++c) {
        int piv = c;
        for (int r = c + 1; r < d; ++r)
            if (fabs(a[r * d + c]) > fabs(a[piv * d + c])) piv = r;
        double p = a[piv * d + c];
        if (p == 0.0) return 0.0;
        if (piv != c)
            for (int k = 0; k < d; ++k) {
                double t = a[c * d + k];
                a[c * d + k] = a[piv * d + k];
                a[piv * d + k] = t;
            }
        det *= p;
        for (int r = c + 1; r < d; ++r) {
            double m = a[r * d + c] / p;
            for (int k = c + 1; k < d; ++k) a[r * d + k] -= m * a[c * d + k];
        }
    }
    return fabs(det);
}

static double factorial(int d) {
    double f = 1.0;
    for (int k = 2; k <= d; ++k) f *= k;
    return f;
}

/* ---- the hull ------------------------------------------------------------------------ */

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

/* The facet's hyperplane solved from its vertices (complete pivoting on the d-1 edge vectors),
 * oriented away from c. 0 when the vertices are affinely dependent. */
static int exact_plane(const Hull *h, Facet *f) {
    int d = h->d;
    double a[D - 1][D];
    int col[D] = {0, 1, 2, 3, 4, 5};
    const double *v0 = point(h, f->v[0], d);
    for (int r = 0; r < d - 1; ++r) {
        const double *vr = point(h, f->v[r + 1], d);
        for (int k = 0; k < d; ++k) a[r][k] = vr[k] - v0[k];
    }
    for (int k = 0; k < d; ++k) col[k] = k;
    for (int s = 0; s < d - 1; ++s) {
        int pr = s, pc = s;
        double best = -1.0;
        for (int r = s; r < d - 1; ++r)
            for (int k = s; k < d; ++k)
                if (fabs(a[r][col[k]]) > best) best = fabs(a[r][col[k]]), pr = r, pc = k;
        if (!(best > 0.0)) return 0;
        if (pr != s)
            for (int k = 0; k < d; ++k) {
                double t = a[s][k];
                a[s][k] = a[pr][k];
                a[pr][k] = t;
            }
        int t = col[s];
        col[s] = col[pc];
        col[pc] = t;
        double p = a[s][col[s]];
        for (int r = s + 1; r < d - 1; ++r) {
            double m = a[r][col[s]] / p;
            if (m == 0.0) continue;
            for (int k = s; k < d; ++k) a[r][col[k]] -= m * a[s][col[k]];
        }
    }
    /* Null vector: the free column (col[d-1]) set to 1, back substitution for the pivots. */
    double x[D] = {0};
    x[col[d - 1]] = 1.0;
    for (int s = d - 2; s >= 0; --s) {
        double sum = 0.0;
        for (int k = s + 1; k < d; ++k) sum += a[s][col[k]] * x[col[k]];
        x[col[s]] = -sum / a[s][col[s]];
    }
    double len = sqrt(dotd(x, x, d));
    if (!(len > 0.0) || !isfinite(len)) return 0;
    double off = 0.0;
    for (int k = 0; k < d; ++k) x[k] /= len;
    for (int r = 0; r < d; ++r) off -= dotd(x, point(h, f->v[r], d), d);
    off /= d;
    double cd = dotd(x, h->c, d) + off;
    if (cd > 0.0) {
        for (int k = 0; k < d; ++k) x[k] = -x[k];
        off = -off;
        cd = -cd;
    }
    memcpy(f->n, x, sizeof(double) * (size_t)d);
    f->off = off;
    f->cdist = cd;
    return 1;
}

static double exact_volume(const Hull *h, const Facet *f) {
    int d = h->d;
    double a[D * D];
    for (int r = 0; r < d; ++r) {
        const double *v = point(h, f->v[r], d);
        for (int k = 0; k < d; ++k) a[r * d + k] = v[k] - h->c[k];
    }
    return abs_det(a, d) / factorial(d);
}

static inline int new_facet(Hull *h) {
    gcGraspWorkspace *ws = h->ws;
    int f = ws->num_free ? ws->free_list[--ws->num_free] : ws->high_water++;
    Facet *F = &ws->facets[f];
    F->outside = -1;
    F->furthest = -1;
    F->fdist = 0.0;
    F->tested = F->visible = -1;
    F->alive = 1;
    return f;
}

/* Puts point q in the outside set of facet f (it is dist above it). */
static inline void add_outside(Hull *h, Facet *F, int q, double dist) {
    h->ws->next[q] = F->outside;
    F->outside = q;
    if (F->furthest < 0 || dist > F->fdist) F->furthest = q, F->fdist = dist;
}

/* Greedy well-spread simplex: the point furthest from the centroid, then each time the point
 * furthest from the affine span of those chosen (Gram-Schmidt on residuals). Returns how many
 * affinely independent points it found (d + 1 for a full hull). */
static int initial_simplex(Hull *h, int *chosen) {
    int n = h->n, d = h->d;
    double *res = h->ws->residual;
    double mean[D] = {0};
    for (int i = 0; i < n; ++i)
        for (int k = 0; k < d; ++k) mean[k] += point(h, i, d)[k];
    for (int k = 0; k < d; ++k) mean[k] /= n;
    int first = 0;
    double best = -1.0;
    for (int i = 0; i < n; ++i) {
        double s = 0.0;
        for (int k = 0; k < d; ++k) s += (point(h, i, d)[k] - mean[k]) * (point(h, i, d)[k] - mean[k]);
        if (s > best) best = s, first = i;
    }
    chosen[0] = first;
    const double *o = point(h, first, d);
    for (int i = 0; i < n; ++i)
        for (int k = 0; k < d; ++k) res[i * 6 + k] = point(h, i, d)[k] - o[k];
    for (int m = 1; m <= d; ++m) {
        int pick = -1;
        double big = 0.0;
        for (int i = 0; i < n; ++i) {
            double s = dotd(&res[i * 6], &res[i * 6], d);
            if (s > big) big = s, pick = i;
        }
        if (pick < 0 || sqrt(big) <= h->tol) return m;
        chosen[m] = pick;
        double u[D], len = sqrt(big);
        for (int k = 0; k < d; ++k) u[k] = res[pick * 6 + k] / len;
        for (int i = 0; i < n; ++i) {
            double *r = &res[i * 6];
            double p = dotd(r, u, d);
            for (int k = 0; k < d; ++k) r[k] -= p * u[k];
        }
    }
    return d + 1;
}

gcStatus gc_span_rank(gcGraspWorkspace *ws, const double *points, int n, int d, double tolerance, int *rank) {
    *rank = 0;
    if (d < 1 || d > D) return set_error(ws, GC_ERR_INVALID_ARGUMENT, "d: %d, expected 1 to %d", d, D);
    gcStatus st = ensure_points(ws, n);
    if (st != GC_OK) return st;
    double *res = ws->residual;
    double scale = 0.0;
    for (int i = 0; i < n; ++i) {
        double s = dotd(points + (size_t)i * d, points + (size_t)i * d, d);
        if (s > scale) scale = s;
        for (int k = 0; k < d; ++k) res[i * 6 + k] = points[(size_t)i * d + k];
    }
    double tol = tolerance * sqrt(scale);
    if (!(scale > 0.0)) return GC_OK;
    for (int m = 0; m < d; ++m) {
        int pick = -1;
        double big = 0.0;
        for (int i = 0; i < n; ++i) {
            double s = dotd(&res[i * 6], &res[i * 6], d);
            if (s > big) big = s, pick = i;
        }
        if (pick < 0 || sqrt(big) <= tol) return GC_OK;
        *rank = m + 1;
        double u[D], len = sqrt(big);
        for (int k = 0; k < d; ++k) u[k] = res[pick * 6 + k] / len;
        for (int i = 0; i < n; ++i) {
            double *r = &res[i * 6];
            double p = dotd(r, u, d);
            for (int k = 0; k < d; ++k) r[k] -= p * u[k];
        }
    }
    return GC_OK;
}

/* The new facet N on horizon ridge i of the visible facet F (apex p replaces F's v[i]); its
 * plane and simplex volume from the pencil of F and the hidden neighbour G, checked. */
static GC_ALWAYS_INLINE void make_cone_facet(Hull *h, int d, int fi, int i, int p, int ni) {
    gcGraspWorkspace *ws = h->ws;
    Facet *F = &ws->facets[fi], *N = &ws->facets[ni];
    int gi = F->nb[i];
    Facet *G = &ws->facets[gi];
    for (int k = 0; k < d; ++k) {
        N->v[k] = F->v[k];
        N->nb[k] = -1;
        if (G->nb[k] == fi) G->nb[k] = ni;
    }
    N->v[i] = p;
    N->nb[i] = gi;
    const uint64_t *vh = ws->vertex_hash;
    N->key[0] = F->key[0] - vh[2 * F->v[i]] + vh[2 * p];
    N->key[1] = F->key[1] - vh[2 * F->v[i] + 1] + vh[2 * p + 1];

    double dF = F->pdist, dG = G->pdist;
    double len2 = 0.0;
    for (int k = 0; k < d; ++k) {
        N->n[k] = dF * G->n[k] - dG * F->n[k];
        len2 += N->n[k] * N->n[k];
    }
    double len = sqrt(len2);
    int ok = len > 0.05 * (dF + fabs(dG));
    if (ok) {
        double inv = 1.0 / len;
        for (int k = 0; k < d; ++k) N->n[k] *= inv;
        N->off = (dF * G->off - dG * F->off) * inv;
        N->cdist = (dF * G->cdist - dG * F->cdist) * inv;
        ok = N->cdist < 0.0;
        /* Residuals stay at rounding level (about 1e-16 of the scale on random grasps); the final
         * facets are checked against all their vertices at the end and solved again if not. */
    }
    if (!ok) exact_plane(h, N);
    if (!h->volumes) return;
    /* vol(c,N) / vol(c,F) = |H(p)| / |H(q)|, H the hyperplane through c and the ridge. */
    double gq = facet_dist(G, point(h, F->v[i], d), d);
    double num = G->cdist * dF - F->cdist * dG;
    if (ok && fabs(gq) > 1e3 * h->vtol && fabs(F->cdist) > 1e3 * h->vtol)
        N->vol = F->vol * fabs(num) / fabs(F->cdist * gq);
    else
        N->vol = exact_volume(h, N);
}

/* Index of x in a[0..d) (it is there). */
static inline int index_of(const int *a, int d, int x) {
    int at = -1;
    for (int k = 0; k < d; ++k) at = a[k] == x ? k : at;
    return at;
}

/* Links the new facets to each other. Two of them are neighbours when they share a ridge
 * holding the apex. A ridge is keyed by two independent sums of random 64-bit words of its
 * vertices (the facet's sums less the vertex it leaves out): 128 bits, so two different ridges
 * never meet by chance in practice; and every ridge must find exactly its one partner. */
static GC_ALWAYS_INLINE int link_new_facets(Hull *h, int d, int nc) {
    gcGraspWorkspace *ws = h->ws;
    if (ensure_ridges(ws, nc * (d - 1)) != GC_OK) return 0;
    Facet *fs = ws->facets;
    const uint64_t *vh = ws->vertex_hash;
    uint64_t *keys = ws->ridge_key;
    int *vals = ws->ridge_facet, *stamps = ws->ridge_stamp, gen = ws->ridge_gen;
    unsigned mask = (unsigned)ws->ridge_slots - 1u;
    int unmatched = 0;
    for (int c = 0; c < nc; ++c) {
        int nf = ws->created[c], apex = ws->created_apex[c];
        Facet *N = &fs[nf];
        uint64_t sum0 = N->key[0], sum1 = N->key[1];
        for (int j = 0; j < d; ++j) {
            if (j == apex || N->nb[j] >= 0) continue;
            uint64_t k0 = sum0 - vh[2 * N->v[j]], k1 = sum1 - vh[2 * N->v[j] + 1];
            unsigned slot = (unsigned)(k0 ^ (k0 >> 29)) & mask;
            for (;; slot = (slot + 1u) & mask) {
                if (stamps[slot] != gen) {
                    stamps[slot] = gen;
                    keys[2 * slot] = k0;
                    keys[2 * slot + 1] = k1;
                    vals[slot] = nf << 3 | j;
                    ++unmatched;
                    break;
                }
                if (keys[2 * slot] == k0 && keys[2 * slot + 1] == k1 && vals[slot] >= 0) {
                    int other = vals[slot] >> 3;
                    N->nb[j] = other;
                    fs[other].nb[vals[slot] & 7] = nf;
                    vals[slot] = -1;
                    --unmatched;
                    break;
                }
            }
        }
    }
    return unmatched == 0;
}

/* Makes point p (pdist above facet fi) a vertex: the facets that see it (breadth first from fi,
 * left in ws->visible[0 .. *out_nv), still alive) are replaced by a cone of new facets over the
 * horizon (ws->created[0 .. *out_nc)), linked. iter stamps this step (> every earlier one). */
static GC_ALWAYS_INLINE gcStatus add_apex(Hull *h, int d, int fi, int p, double pdist, int iter, int *out_nv,
                                          int *out_nc) {
    gcGraspWorkspace *ws = h->ws;
    gcStatus st;
    Facet *F0 = &ws->facets[fi];
    const double *pp = point(h, p, d);
    h->stamp = iter;
    /* Visible facets: breadth first from fi over neighbours that see p. */
    int nv = 0, horizon = 0;
    F0->tested = F0->visible = iter;
    F0->pdist = pdist;
    ws->visible[nv++] = fi;
    for (int s = 0; s < nv; ++s) {
        Facet *F = &ws->facets[ws->visible[s]];
        for (int k = 0; k < d; ++k) {
            Facet *G = &ws->facets[F->nb[k]];
            if (G->tested != iter) {
                G->tested = iter;
                G->pdist = facet_dist(G, pp, d);
                if (G->pdist > h->tol) {
                    G->visible = iter;
                    ws->visible[nv++] = F->nb[k];
                    continue;
                }
            }
            horizon += G->visible != iter;
        }
    }
    if ((st = ensure_facets(ws, ws->high_water + horizon, h->max_facets)) != GC_OK) return st;
    /* The cone: one new facet per horizon ridge, then the links between them. */
    int nc = 0;
    for (int s = 0; s < nv; ++s) {
        int vf = ws->visible[s];
        for (int k = 0; k < d; ++k) {
            if (ws->facets[ws->facets[vf].nb[k]].visible == iter) continue;
            int nf = new_facet(h);
            ws->created_apex[nc] = k;
            ws->created[nc++] = nf;
            make_cone_facet(h, d, vf, k, p, nf);
        }
    }
    if (!link_new_facets(h, d, nc))
        return set_error(ws, GC_ERR_DEGENERATE, "points: broken hull topology");
    *out_nv = nv;
    *out_nc = nc;
    return GC_OK;
}

/* Quickhull from the initial simplex (facets 0..d) until no facet has outside points. Written
 * for a constant d (3 and 6 get their own compiled copies). */
static GC_ALWAYS_INLINE gcStatus hull_run(Hull *h, int d) {
    gcGraspWorkspace *ws = h->ws;
    int n = h->n, num_pending = 0, iter = 0;
    gcStatus st;
    for (int f = 0; f <= d; ++f)
        if (ws->facets[f].furthest >= 0 && (st = push_pending(ws, &num_pending, f)) != GC_OK) return st;
    while (num_pending > 0) {
        int fi = ws->pending[--num_pending];
        Facet *F0 = &ws->facets[fi];
        if (!F0->alive || F0->furthest < 0) continue;
        /* Each step makes one more point a vertex: at most n steps. */
        if (++iter > n) return set_error(ws, GC_ERR_DEGENERATE, "points: the hull did not converge in %d steps", n);
        int p = F0->furthest, nv = 0, nc = 0;
        if ((st = add_apex(h, d, fi, p, F0->fdist, iter, &nv, &nc)) != GC_OK) return st;
        /* Outside points of the visible facets go to the first new facet they are above. */
        for (int s = 0; s < nv; ++s) {
            Facet *F = &ws->facets[ws->visible[s]];
            for (int q = F->outside; q >= 0;) {
                int nq = ws->next[q];
                if (q != p) {
                    const double *x = point(h, q, d);
                    for (int c = 0; c < nc; ++c) {
                        Facet *N = &ws->facets[ws->created[c]];
                        double dist = facet_dist(N, x, d);
                        if (dist > h->tol) {
                            add_outside(h, N, q, dist);
                            break;
                        }
                    }
                }
                q = nq;
            }
            F->alive = 0;
            ws->free_list[ws->num_free++] = ws->visible[s];
        }
        for (int c = 0; c < nc; ++c)
            if (ws->facets[ws->created[c]].furthest >= 0 &&
                (st = push_pending(ws, &num_pending, ws->created[c])) != GC_OK)
                return st;
    }
    return GC_OK;
}

static gcStatus hull_run6(Hull *h) { return hull_run(h, 6); }
static gcStatus hull_run3(Hull *h) { return hull_run(h, 3); }
static gcStatus hull_run_any(Hull *h) { return hull_run(h, h->d); }

/* The initial simplex of a hull of n points of dimension d (facets 0..d, planes solved), the
 * interior point c, the tolerances and the vertices' random words. *full 0 (and nothing made)
 * when the points span less than d affine dimensions. */
static gcStatus hull_begin(Hull *h, gcGraspWorkspace *ws, const double *points, int n, int d, double tolerance,
                           int max_facets, int volumes, int chosen[D + 1], int *full) {
    *full = 0;
    memset(h, 0, sizeof *h);
    h->ws = ws;
    h->pts = points;
    h->n = n;
    h->d = d;
    h->max_facets = max_facets;
    h->volumes = volumes;
    if (n < d + 1) return GC_OK;
    gcStatus st = ensure_points(ws, n);
    if (st != GC_OK) return st;
    double scale = 0.0;
    for (int i = 0; i < n; ++i) scale = fmax(scale, dotd(point(h, i, d), point(h, i, d), d));
    scale = sqrt(scale);
    if (!(scale > 0.0)) return GC_OK;
    h->tol = tolerance * scale;
    h->vtol = 1e-12 * scale;
    if (initial_simplex(h, chosen) < d + 1) return GC_OK;
    for (int k = 0; k < d; ++k) {
        double s = 0.0;
        for (int m = 0; m <= d; ++m) s += point(h, chosen[m], d)[k];
        h->c[k] = s / (d + 1);
    }
    st = ensure_facets(ws, 2 * (d + 1), max_facets);
    if (st != GC_OK) return st;
    ws->high_water = 0;
    ws->num_free = 0;
    for (int i = 0; i < n; ++i) ws->next[i] = -1;
    /* Facet m of the simplex leaves out chosen[m]; its ridge without chosen[k] faces facet k. */
    for (int m = 0; m <= d; ++m) {
        int f = new_facet(h);
        Facet *F = &ws->facets[f];
        int r = 0;
        for (int k = 0; k <= d; ++k) {
            if (k == m) continue;
            F->v[r] = chosen[k];
            F->nb[r] = k;
            ++r;
        }
        exact_plane(h, F);
        F->vol = volumes ? exact_volume(h, F) : 0.0;
        F->key[0] = F->key[1] = 0;
        for (int k = 0; k < d; ++k) F->key[0] += ws->vertex_hash[2 * F->v[k]], F->key[1] += ws->vertex_hash[2 * F->v[k] + 1];
    }
    *full = 1;
    return GC_OK;
}

gcStatus gc_hull_nd(gcGraspWorkspace *ws, const double *points, int n, int d, double tolerance,
                    int max_facets, gcHullSummary *out) {
    memset(out, 0, sizeof *out);
    out->result = GC_HULL_FLAT;
    out->offset_max = 0.0;
    if (d < 3 || d > D) return set_error(ws, GC_ERR_INVALID_ARGUMENT, "d: %d, expected 3 to %d", d, D);
    Hull h;
    int chosen[D + 1], full;
    gcStatus st = hull_begin(&h, ws, points, n, d, tolerance, max_facets, 1, chosen, &full);
    if (st != GC_OK || !full) return st;
    for (int i = 0; i < n; ++i) {
        if (index_of(chosen, d + 1, i) >= 0) continue;
        for (int f = 0; f <= d; ++f) {
            double dist = facet_dist(&ws->facets[f], point(&h, i, d), d);
            if (dist > h.tol) {
                add_outside(&h, &ws->facets[f], i, dist);
                break;
            }
        }
    }
    st = d == 6 ? hull_run6(&h) : d == 3 ? hull_run3(&h) : hull_run_any(&h);
    if (st != GC_OK) return st;

    /* The answer: volume, and the nearest facet with its plane solved from its vertices. */
    double volume = 0.0, best = -INFINITY;
    int facets = 0;
    for (int f = 0; f < ws->high_water; ++f) {
        Facet *F = &ws->facets[f];
        if (!F->alive) continue;
        ++facets;
        for (int r = 0; r < d; ++r)
            if (fabs(facet_dist(F, point(&h, F->v[r], d), d)) > h.vtol) {
                exact_plane(&h, F);
                break;
            }
        volume += F->vol;
        if (F->off > best) best = F->off;
    }
    double margin = 1e3 * h.vtol;
    int nearest = -1;
    double best_exact = -INFINITY;
    for (int f = 0; f < ws->high_water; ++f) {
        Facet *F = &ws->facets[f];
        if (!F->alive || F->off < best - margin) continue;
        exact_plane(&h, F);
        if (F->off > best_exact) best_exact = F->off, nearest = f;
    }
    out->result = GC_HULL_FULL;
    out->facets = facets;
    out->volume = volume;
    out->offset_max = best_exact;
    if (nearest >= 0) memcpy(out->nearest_normal, ws->facets[nearest].n, sizeof(double) * (size_t)d);
    return GC_OK;
}

/* ---- the origin's nearest facet by support queries -------------------------------------- */

/* The support-function search (after Zheng, IEEE T-RO 2013): an inner polytope P, the hull of a
 * few of the points, grows until the facet of P that decides (the one the origin is furthest
 * outside of, or nearest to when it is inside) lies on a supporting plane of the whole set: no
 * point more than the tolerance beyond it. Then that plane is a facet plane of the full hull, and
 * because P lies inside the full hull, no facet of the full hull is nearer the origin: the answer
 * is the full hull's, exactly, without building it. Each step adds the support point of the
 * deciding facet's normal (a new vertex of P), so at most n steps. */
static GC_ALWAYS_INLINE gcStatus nearest_run(Hull *h, int d, gcHullSummary *out) {
    gcGraspWorkspace *ws = h->ws;
    int n = h->n;
    for (int f = 0; f < ws->high_water; ++f) ws->facet_off[f] = ws->facets[f].alive ? ws->facets[f].off : -INFINITY;
    for (int iter = 1;; ++iter) {
        if (iter > n + 1)
            return set_error(ws, GC_ERR_DEGENERATE, "points: the support search did not converge in %d steps", n);
        int fb = -1;
        double best = -INFINITY;
        const double *offs = ws->facet_off;
        for (int f = 0; f < ws->high_water; ++f)
            if (offs[f] > best) best = offs[f], fb = f;
        Facet *F = &ws->facets[fb];
        int p = -1;
        double gap;
        /* The answer is read off a plane solved from the facet's vertices (the pencil planes are
         * good to rounding, not exact): solved when the support query first finds it supporting. */
        for (int exact = 0;; exact = 1) {
            double support = -INFINITY;
            for (int i = 0; i < n; ++i) {
                double s = dotd(F->n, point(h, i, d), d);
                if (s > support) support = s, p = i;
            }
            gap = support + F->off;    /* how far the support point is beyond F's plane */
            if (gap > h->tol) break;
            if (exact) {
                out->result = GC_HULL_FULL;
                out->offset_max = F->off;
                memcpy(out->nearest_normal, F->n, sizeof(double) * (size_t)d);
                memcpy(out->nearest_vertices, F->v, sizeof(int) * (size_t)d);
                return GC_OK;
            }
            exact_plane(h, F);
            ws->facet_off[fb] = F->off;
        }
        int nv = 0, nc = 0;
        gcStatus st = add_apex(h, d, fb, p, gap, iter, &nv, &nc);
        if (st != GC_OK) return st;
        for (int s = 0; s < nv; ++s) {
            ws->facets[ws->visible[s]].alive = 0;
            ws->facet_off[ws->visible[s]] = -INFINITY;
            ws->free_list[ws->num_free++] = ws->visible[s];
        }
        for (int c = 0; c < nc; ++c) ws->facet_off[ws->created[c]] = ws->facets[ws->created[c]].off;
    }
}

static gcStatus nearest_run6(Hull *h, gcHullSummary *out) { return nearest_run(h, 6, out); }
static gcStatus nearest_run3(Hull *h, gcHullSummary *out) { return nearest_run(h, 3, out); }
static gcStatus nearest_run_any(Hull *h, gcHullSummary *out) { return nearest_run(h, h->d, out); }

gcStatus gc_hull_nearest(gcGraspWorkspace *ws, const double *points, int n, int d, double tolerance,
                         int max_facets, gcHullSummary *out) {
    memset(out, 0, sizeof *out);
    out->result = GC_HULL_FLAT;
    out->facets = -1;
    out->volume = -1.0;
    if (d < 3 || d > D) return set_error(ws, GC_ERR_INVALID_ARGUMENT, "d: %d, expected 3 to %d", d, D);
    Hull h;
    int chosen[D + 1], full;
    gcStatus st = hull_begin(&h, ws, points, n, d, tolerance, max_facets, 0, chosen, &full);
    if (st != GC_OK || !full) return st;
    return d == 6 ? nearest_run6(&h, out) : d == 3 ? nearest_run3(&h, out) : nearest_run_any(&h, out);
}

/* ---- the closure LP ------------------------------------------------------------------------ */

/* Largest t with sum_i lambda_i x_i = 0, sum_i lambda_i = 1, lambda_i >= t (lambda_i >= -1 too,
 * which only matters when t < 0). With lambda_i = mu_i + tau - 1 (mu, tau >= 0) it is the
 * standard form  sum mu_i x_i + tau S = S,  sum mu_i + n tau = 1 + n,  maximise tau,  S = sum x_i,
 * solved by the two-phase simplex method on a dense tableau of d + 1 rows (artificial variables
 * first, then tau). Dantzig's rule, switching to Bland's (no cycling) after a run of degenerate
 * pivots; capped. The points are scaled by 1 / the largest norm (t does not change). */
static void lp_pivot(double *T, int rows, int cols, int r, int c) {
    double *pr = T + (size_t)r * cols;
    double inv = 1.0 / pr[c];
    for (int k = 0; k < cols; ++k) pr[k] *= inv;
    pr[c] = 1.0;
    for (int q = 0; q <= rows; ++q) {
        if (q == r) continue;
        double *pq = T + (size_t)q * cols, m = pq[c];
        if (m == 0.0) continue;
        for (int k = 0; k < cols; ++k) pq[k] -= m * pr[k];
        pq[c] = 0.0;
    }
}

/* Minimises the objective row (row `rows`) over the columns [0, allowed). 1 when optimal, 0 when
 * the cap was reached; -1 unbounded (cannot happen here: tau <= (1 + n) / n). */
static int lp_minimise(double *T, int *basis, int rows, int cols, int allowed, int cap, int bland) {
    const double cost_eps = 1e-12, pivot_eps = 1e-11;
    double *obj = T + (size_t)rows * cols;
    int rhs = cols - 1, degenerate_run = 0;
    for (int it = 0; it < cap; ++it) {
        int enter = -1;
        double most = -cost_eps;
        for (int j = 0; j < allowed; ++j) {
            if (obj[j] < most) {
                enter = j;
                if (bland) break;
                most = obj[j];
            }
        }
        if (enter < 0) return 1;
        int leave = -1;
        double ratio = INFINITY;
        for (int r = 0; r < rows; ++r) {
            double a = T[(size_t)r * cols + enter];
            if (a <= pivot_eps) continue;
            double q = T[(size_t)r * cols + rhs] / a;
            if (q < ratio || (q == ratio && basis[r] < basis[leave])) ratio = q, leave = r;
        }
        if (leave < 0) return -1;
        /* Near-degenerate pivots (a step of rounding size) count as degenerate: Dantzig's rule
         * can cycle through them numerically (an antipodal pair tilted by 1e-10 did). Past
         * rows + allowed pivots in all, Bland's rule from then on too. */
        degenerate_run = ratio <= 1e-13 ? degenerate_run + 1 : 0;
        if (degenerate_run > 2 * rows || it > rows + allowed) bland = 1;
        lp_pivot(T, rows, cols, leave, enter);
        basis[leave] = enter;
    }
    return 0;
}

/* The tableau's constraint rows for the points (scaled by inv), objective row and artificial
 * columns zero. */
static void lp_fill(double *T, const double *points, int n, int d, int cols, double inv) {
    int rows = d + 1, tau = n, rhs = cols - 1;
    memset(T, 0, sizeof(double) * (size_t)(rows + 1) * (size_t)cols);
    for (int i = 0; i < n; ++i) {
        for (int k = 0; k < d; ++k) {
            double x = points[(size_t)i * d + k] * inv;
            T[(size_t)k * cols + i] = x;
            T[(size_t)k * cols + tau] += x;
            T[(size_t)k * cols + rhs] += x;
        }
        T[(size_t)d * cols + i] = 1.0;
    }
    T[(size_t)d * cols + tau] = n;
    T[(size_t)d * cols + rhs] = 1.0 + n;
}

/* Makes the columns warm[0 .. rows) basic (Gauss-Jordan, largest pivot per column). 1 when they
 * form a basis whose solution is feasible (right-hand sides >= 0 up to rounding). */
static int lp_warm_basis(double *T, int *basis, int rows, int cols, const int *warm) {
    int rhs = cols - 1;
    for (int r = 0; r < rows; ++r) basis[r] = -1;
    for (int k = 0; k < rows; ++k) {
        int c = warm[k], pick = -1;
        double big = 1e-9;
        for (int r = 0; r < rows; ++r)
            if (basis[r] < 0 && fabs(T[(size_t)r * cols + c]) > big) big = fabs(T[(size_t)r * cols + c]), pick = r;
        if (pick < 0) return 0;
        lp_pivot(T, rows, cols, pick, c);
        basis[pick] = c;
    }
    for (int r = 0; r < rows; ++r) {
        double *v = &T[(size_t)r * cols + rhs];
        if (*v < -1e-9) return 0;
        if (*v < 0.0) *v = 0.0;
    }
    return 1;
}

/* gc_closure_lp; warm (d + 1 column indices, or NULL) is an optimal basis of an earlier LP over
 * the same number of points, tried first (a nearby problem's basis is often still optimal or a
 * pivot or two away), and holds this one's on return (warm[0] -1 when there is none). */
static gcStatus closure_lp(gcGraspWorkspace *ws, const double *points, int n, int d, int *warm, double *t_max) {
    *t_max = -INFINITY;
    if (d < 1 || d > D) return set_error(ws, GC_ERR_INVALID_ARGUMENT, "d: %d, expected 1 to %d", d, D);
    int start[D + 1], has_warm = warm && warm[0] >= 0;
    if (has_warm) memcpy(start, warm, sizeof(int) * (size_t)(d + 1));
    if (warm) warm[0] = -1;
    if (n < 1) return GC_OK;
    int rows = d + 1, tau = n, art = n + 1, cols = n + 1 + rows + 1, rhs = cols - 1;
    size_t need = (size_t)(rows + 1) * (size_t)cols;
    if (need > (size_t)ws->cap_lp) {
        if (!grow((void **)&ws->lp, need, sizeof(double)) || !grow((void **)&ws->lp_basis, D + 1, sizeof(int)))
            return set_error(ws, GC_ERR_NO_MEMORY, "workspace: out of memory for the closure LP");
        ws->cap_lp = (int)need;
    }
    double *T = ws->lp;
    int *basis = ws->lp_basis;
    double scale = 0.0;
    for (int i = 0; i < n; ++i) scale = fmax(scale, dotd(points + (size_t)i * d, points + (size_t)i * d, d));
    if (!(scale > 0.0)) return GC_OK;
    double inv = 1.0 / sqrt(scale);
    int cap = 50 * (n + rows) + 100, res;
    double *obj = T + (size_t)rows * cols;
    lp_fill(T, points, n, d, cols, inv);
    if (!has_warm || !lp_warm_basis(T, basis, rows, cols, start)) {
        /* Phase 1: artificial a_r in row r (rows with a negative right-hand side negated first).
         * It cannot be unbounded in exact arithmetic (the artificials' sum is >= 0); a stop on
         * "unbounded" is rounding, short of a feasible point, and would read as "t < -1" (three
         * fingers at 120 degrees tilted by 1e-3, mu 10, t* 0.04, did): phase 1 again with
         * Bland's rule from the start, which takes another path. */
        for (int attempt = 0; attempt < 2; ++attempt) {
            if (has_warm || attempt) lp_fill(T, points, n, d, cols, inv);
            for (int r = 0; r < rows; ++r) {
                double *pr = T + (size_t)r * cols;
                if (pr[rhs] < 0.0)
                    for (int k = 0; k < cols; ++k) pr[k] = -pr[k];
                pr[art + r] = 1.0;
                basis[r] = art + r;
                for (int k = 0; k < art; ++k) obj[k] -= pr[k];
                obj[rhs] -= pr[rhs];
            }
            res = lp_minimise(T, basis, rows, cols, art + rows, cap, attempt);
            if (res != -1) break;
        }
        if (res == 0)
            return set_error(ws, GC_ERR_DEGENERATE, "points: the closure LP did not converge in %d pivots", cap);
        if (-obj[rhs] > 1e-9 * (1.0 + n)) return GC_OK;   /* infeasible: t < -1, the origin is far outside */
        /* Artificials still basic (at zero) leave for any structural column; a row with none is
         * redundant and is emptied. */
        for (int r = 0; r < rows; ++r) {
            if (basis[r] < art) continue;
            double *pr = T + (size_t)r * cols;
            int c = -1;
            double big = 1e-9;
            for (int j = 0; j < art; ++j)
                if (fabs(pr[j]) > big) big = fabs(pr[j]), c = j;
            if (c >= 0) {
                lp_pivot(T, rows, cols, r, c);
                basis[r] = c;
            } else {
                for (int k = 0; k < cols; ++k) pr[k] = 0.0;
            }
        }
    }
    /* Phase 2: minimise -tau, artificials barred. */
    for (int k = 0; k < cols; ++k) obj[k] = 0.0;
    obj[tau] = -1.0;
    for (int r = 0; r < rows; ++r)
        if (basis[r] == tau) {
            const double *pr = T + (size_t)r * cols;
            for (int k = 0; k < cols; ++k) obj[k] += pr[k];
            obj[tau] = 0.0;
        }
    res = lp_minimise(T, basis, rows, cols, art, cap, 0);
    if (res == 0) return set_error(ws, GC_ERR_DEGENERATE, "points: the closure LP did not converge in %d pivots", cap);
    double tau_value = 0.0;
    int structural = 1;
    for (int r = 0; r < rows; ++r) {
        if (basis[r] == tau) tau_value = T[(size_t)r * cols + rhs];
        structural = structural && basis[r] < art;
    }
    *t_max = tau_value - 1.0;
    if (warm && structural) memcpy(warm, basis, sizeof(int) * (size_t)rows);
    return GC_OK;
}

gcStatus gc_closure_lp(gcGraspWorkspace *ws, const double *points, int n, int d, double *t_max) {
    return closure_lp(ws, points, n, d, NULL, t_max);
}

/* ---- the grasp wrench space ---------------------------------------------------------------- */

static gcStatus check_def(gcGraspWorkspace *ws, const gcGraspDef *def) {
    if (def->edges < 3 || def->edges > GC_GRASP_MAX_EDGES)
        return set_error(ws, GC_ERR_INVALID_ARGUMENT, "edges: %d, expected 3 to %d", def->edges, GC_GRASP_MAX_EDGES);
    if (!(def->tolerance > 0.0) || !(def->tolerance < 1e-3))
        return set_error(ws, GC_ERR_INVALID_ARGUMENT, "tolerance: %g, expected in (0, 1e-3)", def->tolerance);
    if (def->max_facets < 16)
        return set_error(ws, GC_ERR_INVALID_ARGUMENT, "max_facets: %d, expected >= 16", def->max_facets);
    return GC_OK;
}

/* Checks one contact set and writes its edge wrenches, forces and torques; *count = rows.
 * mu NULL: every contact has mu_all. A soft contact (def->torsion[i] = rho > 0) adds its two
 * torsion generators after its cone's edges. */
static gcStatus build_wrenches(gcGraspWorkspace *ws, const gcGraspDef *def, const double *points, const double *normals,
                               const double *mu, double mu_all, int num_contacts, const double center[3],
                               double radius, int *count) {
    if (num_contacts < 0)
        return set_error(ws, GC_ERR_INVALID_ARGUMENT, "points: %d contacts, expected >= 0", num_contacts);
    if (num_contacts > 0 && (!points || !normals))
        return set_error(ws, GC_ERR_INVALID_ARGUMENT, "%s: NULL", points ? "normals" : "points");
    if (!center) return set_error(ws, GC_ERR_INVALID_ARGUMENT, "center: NULL");
    for (int k = 0; k < 3; ++k)
        if (!isfinite(center[k])) return set_error(ws, GC_ERR_INVALID_ARGUMENT, "center: not finite");
    if (!(radius > 0.0) || !isfinite(radius))
        return set_error(ws, GC_ERR_INVALID_ARGUMENT, "radius: %g, expected a finite number > 0", radius);
    const int edges = def->edges;
    const double *torsion = def->torsion;
    if ((long long)num_contacts * edges > 1000000)
        return set_error(ws, GC_ERR_INVALID_ARGUMENT, "points: %d contacts x %d edges is too many", num_contacts,
                         edges);
    gcStatus st = ensure_points(ws, num_contacts * (edges + (torsion ? 2 : 0)));
    if (st != GC_OK) return st;
    if (ws->edges_cached != edges) {
        for (int j = 0; j < edges; ++j) {
            ws->cos_table[j] = cos(kTwoPi * j / edges);
            ws->sin_table[j] = sin(kTwoPi * j / edges);
        }
        ws->edges_cached = edges;
    }
    double inv_r = 1.0 / radius;
    int rows = 0;
    for (int i = 0; i < num_contacts; ++i) {
        const double *p = points + 3 * i, *nn = normals + 3 * i;
        double m = mu ? mu[i] : mu_all;
        if (!isfinite(p[0]) || !isfinite(p[1]) || !isfinite(p[2]))
            return set_error(ws, GC_ERR_INVALID_ARGUMENT, "points: row %d is not finite", i);
        if (!isfinite(nn[0]) || !isfinite(nn[1]) || !isfinite(nn[2]))
            return set_error(ws, GC_ERR_INVALID_ARGUMENT, "normals: row %d is not finite", i);
        double len = sqrt(nn[0] * nn[0] + nn[1] * nn[1] + nn[2] * nn[2]);
        if (!(len > 1e-12))
            return set_error(ws, GC_ERR_INVALID_ARGUMENT, "normals: row %d is a zero vector", i);
        if (!isfinite(m) || m < 0.0)
            return set_error(ws, GC_ERR_INVALID_ARGUMENT, "mu: %g at contact %d, expected a finite number >= 0", m, i);
        if (torsion && (!isfinite(torsion[i]) || torsion[i] < 0.0))
            return set_error(ws, GC_ERR_INVALID_ARGUMENT, "torsion: %g at contact %d, expected a finite number >= 0",
                             torsion[i], i);
        double n[3] = {nn[0] / len, nn[1] / len, nn[2] / len};
        /* t1 = normalize(n x a), a the world axis least aligned with n (ties: x, y, z). */
        int axis = 0;
        if (fabs(n[1]) < fabs(n[axis])) axis = 1;
        if (fabs(n[2]) < fabs(n[axis])) axis = 2;
        double a[3] = {0, 0, 0};
        a[axis] = 1.0;
        double t1[3] = {n[1] * a[2] - n[2] * a[1], n[2] * a[0] - n[0] * a[2], n[0] * a[1] - n[1] * a[0]};
        double l1 = sqrt(t1[0] * t1[0] + t1[1] * t1[1] + t1[2] * t1[2]);
        for (int k = 0; k < 3; ++k) t1[k] /= l1;
        double t2[3] = {n[1] * t1[2] - n[2] * t1[1], n[2] * t1[0] - n[0] * t1[2], n[0] * t1[1] - n[1] * t1[0]};
        double r[3] = {p[0] - center[0], p[1] - center[1], p[2] - center[2]};
        int k_edges = m > 0.0 ? edges : 1;
        for (int j = 0; j < k_edges; ++j) {
            double cs = m * ws->cos_table[j], sn = m * ws->sin_table[j];
            double f[3];
            for (int k = 0; k < 3; ++k) f[k] = n[k] + cs * t1[k] + sn * t2[k];
            double t[3] = {(r[1] * f[2] - r[2] * f[1]) * inv_r, (r[2] * f[0] - r[0] * f[2]) * inv_r,
                           (r[0] * f[1] - r[1] * f[0]) * inv_r};
            double *w = ws->wrench + 6 * rows, *fo = ws->force + 3 * rows, *to = ws->torque + 3 * rows;
            for (int k = 0; k < 3; ++k) w[k] = fo[k] = f[k], w[3 + k] = to[k] = t[k];
            ++rows;
        }
        /* Soft contact: the normal force with a torque of +-mu rho about the normal (GraspIt's
         * soft-contact generators): torsional friction up to mu rho Fn. */
        double twist = torsion ? m * torsion[i] * inv_r : 0.0;
        for (int sign = -1; twist > 0.0 && sign <= 1; sign += 2) {
            double t[3] = {(r[1] * n[2] - r[2] * n[1]) * inv_r + sign * twist * n[0],
                           (r[2] * n[0] - r[0] * n[2]) * inv_r + sign * twist * n[1],
                           (r[0] * n[1] - r[1] * n[0]) * inv_r + sign * twist * n[2]};
            double *w = ws->wrench + 6 * rows, *fo = ws->force + 3 * rows, *to = ws->torque + 3 * rows;
            for (int k = 0; k < 3; ++k) w[k] = fo[k] = n[k], w[3 + k] = to[k] = t[k];
            ++rows;
        }
    }
    *count = rows;
    return GC_OK;
}

/* The LP's answer, checked both ways against the hull's rule (closed: the origin more than
 * tolerance x scale inside, scale the largest point norm). With t* the LP's optimum:
 *  - t* <= tolerance / (2 rows): not closed. A hull holding the ball of radius e > tolerance x
 *    scale about the origin has t* > tolerance / (rows (1 + tolerance)): the origin is
 *    (x + s g) / (1 + s) with g the centroid, |x| = e, s = e / |g|.
 *  - closed when sigma_min(X) > 2 tolerance x scale (1 + rows t*) / t* (checked by a Cholesky
 *    factorisation of X^T X less that squared): for any unit u, with a_i = u.x_i and m their
 *    largest, sum lambda_i a_i = 0 and lambda_i >= t* give m >= t* sum_i max(0, -a_i) >=
 *    t* (sum_i |a_i| - rows m), so m >= t* sigma_min / (1 + rows t*), and the distance from
 *    the origin to the boundary is the least m over u.
 * Otherwise (the origin within a hair of the boundary, or a flat set) *answer is -1: undecided. */
static gcStatus lp_decide(gcGraspWorkspace *ws, const gcGraspDef *def, const double *pts, int rows, int d,
                          int *answer) {
    *answer = 0;
    double t;
    gcStatus st = gc_closure_lp(ws, pts, rows, d, &t);
    if (st == GC_ERR_DEGENERATE) {      /* the LP did not converge: the support search decides */
        ws->error[0] = '\0';
        *answer = -1;
        return GC_OK;
    }
    if (st != GC_OK || !(t > 0.5 * def->tolerance / rows)) return st;
    *answer = -1;
    double gram[D * D] = {0}, scale2 = 0.0;
    for (int i = 0; i < rows; ++i) {
        const double *x = pts + (size_t)i * d;
        scale2 = fmax(scale2, dotd(x, x, d));
        for (int r = 0; r < d; ++r)
            for (int c = 0; c <= r; ++c) gram[r * D + c] += x[r] * x[c];
    }
    double s = 2.0 * def->tolerance * sqrt(scale2) * (1.0 + rows * t) / t;
    for (int r = 0; r < d; ++r) gram[r * D + r] -= s * s;
    /* Cholesky: positive definite (with room) exactly when every pivot is positive. */
    for (int c = 0; c < d; ++c) {
        double p = gram[c * D + c];
        for (int k = 0; k < c; ++k) p -= gram[c * D + k] * gram[c * D + k];
        if (!(p > 1e-12 * scale2)) return GC_OK;
        p = sqrt(p);
        gram[c * D + c] = p;
        for (int r = c + 1; r < d; ++r) {
            double v = gram[r * D + c];
            for (int k = 0; k < c; ++k) v -= gram[r * D + k] * gram[c * D + k];
            gram[r * D + c] = v / p;
        }
    }
    *answer = 1;
    return GC_OK;
}

/* Closure without the full hull: the LP decides (lp_decide); the support search finds the nearest
 * facet when nearest is set or the LP left it undecided, and then decides with the hull's rule,
 * so it answers as the hull would. When the nearest facet is wanted from 32 points up the search
 * goes alone: it decides closure itself, and such sets are mostly closed, where the LP would be
 * spent for nothing (10 contacts x 8 edges: 65 instead of 73 µs; 3 x 8, mostly open: the LP
 * first, 6.7 instead of 8.4 µs). rank may be NULL. */
static gcStatus closure_fast(gcGraspWorkspace *ws, const gcGraspDef *def, const double *pts, int rows, int d,
                             int nearest, int *closed, int *rank, gcHullSummary *summary) {
    memset(summary, 0, sizeof *summary);
    *closed = 0;
    int answer = -1;
    gcStatus st = GC_OK;
    if (!nearest || rows < 32) st = lp_decide(ws, def, pts, rows, d, &answer);
    if (st != GC_OK) return st;
    if (answer != 0 && (nearest || answer < 0)) {
        if ((st = gc_hull_nearest(ws, pts, rows, d, def->tolerance, def->max_facets, summary)) != GC_OK) return st;
        double scale = 0.0;
        for (int i = 0; i < rows; ++i) scale = fmax(scale, dotd(pts + (size_t)i * d, pts + (size_t)i * d, d));
        answer = summary->result == GC_HULL_FULL && summary->offset_max < -def->tolerance * sqrt(scale);
    }
    *closed = answer;
    if (rank) {
        *rank = d;
        if (!answer) st = gc_span_rank(ws, pts, rows, d, def->tolerance, rank);
    }
    return st;
}

/* The measures without the full hull; volume and facets are -1 (not computed). */
static gcStatus quality_fast(gcGraspWorkspace *ws, const gcGraspDef *def, int rows, gcGraspQuality *out) {
    memset(out, 0, sizeof *out);
    out->volume = -1.0;
    out->facets = -1;
    int closed, rank;
    gcHullSummary s;
    gcStatus st = closure_fast(ws, def, ws->wrench, rows, 6, 1, &closed, &rank, &s);
    if (st != GC_OK) return st;
    out->rank = rank;
    out->force_closure = closed;
    if (closed) {
        out->epsilon = -s.offset_max;
        memcpy(out->weakest, s.nearest_normal, sizeof out->weakest);
        memcpy(ws->nearest_vertices, s.nearest_vertices, sizeof ws->nearest_vertices);
        /* The force and torque parts of a ball of radius epsilon about the origin are balls of
         * that radius in the projections, and their scales are no larger: both 3-D conditions hold. */
        out->force_only_closure = out->torque_closure = 1;
        return GC_OK;
    }
    if ((st = closure_fast(ws, def, ws->force, rows, 3, 0, &closed, NULL, &s)) != GC_OK) return st;
    out->force_only_closure = closed;
    if ((st = closure_fast(ws, def, ws->torque, rows, 3, 0, &closed, NULL, &s)) != GC_OK) return st;
    out->torque_closure = closed;
    return GC_OK;
}

/* def->volume 1 adds the whole 6-D hull, for its volume and facet count. Closure, epsilon and the
 * weakest direction stay the fast path's, which support queries certify: the hull's own nearest
 * facet can be wrong where facets are thin. Two antipodal contacts and mu = 1e-5 make facets whose
 * vertices lie in two clusters 1e-5 wide; a plane fixed by such vertices to within the tolerance
 * can tilt by tolerance / 1e-5, and miss the origin by more than epsilon (the hull alone said "not
 * closed" up to mu = 1.8e-5 where qhull and the search find epsilon = 0.045 mu). The volume, a sum
 * over all facets, is not sensitive to it (1e-9 of qhull's there). */
static gcStatus quality_of_built(gcGraspWorkspace *ws, const gcGraspDef *def, int rows, gcGraspQuality *out) {
    gcStatus st = quality_fast(ws, def, rows, out);
    if (st != GC_OK || !def->volume) return st;
    out->volume = 0.0;
    out->facets = 0;
    if (out->rank < 6) return GC_OK;
    gcHullSummary s;
    if ((st = gc_hull_nd(ws, ws->wrench, rows, 6, def->tolerance, def->max_facets, &s)) != GC_OK) return st;
    if (s.result == GC_HULL_FULL) {
        out->volume = s.volume;
        out->facets = s.facets;
    }
    return GC_OK;
}

/* gcGraspDef.reuse: the slot whose wrenches are nearest the set's (rows of ws->wrench), and that
 * distance delta (the largest Euclidean distance between corresponding wrenches); -1 if no slot
 * has as many rows, or every one is further than `limit`. */
static int reuse_nearest_slot(const gcGraspWorkspace *ws, const gcGraspDef *def, int rows, double limit,
                              double *delta) {
    int best = -1;
    double best2 = limit * limit;
    for (int k = 0; k < GC_REUSE_SLOTS; ++k) {
        const ReuseSlot *r = &ws->reuse[k];
        if (r->rows != rows || r->edges != def->edges || r->tolerance != def->tolerance) continue;
        double worst = 0.0;
        for (int i = 0; i < rows && worst <= best2; ++i) {
            double s = 0.0;
            for (int c = 0; c < 6; ++c) {
                double e = ws->wrench[6 * i + c] - r->wrench[6 * i + c];
                s += e * e;
            }
            worst = fmax(worst, s);
        }
        if (worst <= best2) best2 = worst, best = k;
    }
    *delta = sqrt(best2);
    return best;
}

/* gcGraspDef.reuse. Every wrench moved by at most delta from the slot's set, so every support
 * value did, and epsilon (the least support value over unit directions) is at least the slot's
 * less delta. The slot's nearest facet, its plane solved from the new wrenches, supports them all
 * within the tolerance: epsilon is at most its support value. When the two bounds are within
 * 1e-12 relative (and the lower one is past the tolerance, so the set is closed as a search would
 * decide), that facet is the answer. 1 when it is. */
static int reuse_answer(gcGraspWorkspace *ws, const gcGraspDef *def, int rows, gcGraspQuality *out) {
    double scale = 0.0, delta;
    for (int i = 0; i < rows; ++i) scale = fmax(scale, dotd(ws->wrench + 6 * i, ws->wrench + 6 * i, 6));
    scale = sqrt(scale);
    int k = reuse_nearest_slot(ws, def, rows, 1e-12 * scale, &delta);
    if (k < 0) return 0;
    const ReuseSlot *r = &ws->reuse[k];
    Hull h;
    memset(&h, 0, sizeof h);
    h.ws = ws;
    h.pts = ws->wrench;
    h.n = rows;
    h.d = 6;            /* h.c = 0, the origin: inside, so the plane is oriented outwards */
    Facet F;
    memset(&F, 0, sizeof F);
    memcpy(F.v, r->vertices, sizeof F.v);
    if (!exact_plane(&h, &F)) return 0;
    double support = -INFINITY;
    for (int i = 0; i < rows; ++i) support = fmax(support, dotd(F.n, ws->wrench + 6 * i, 6));
    double lower = r->epsilon - delta, tol = def->tolerance * scale;
    if (!(support + F.off <= tol) || !(lower > tol) || !(support - lower <= 1e-12 * support)) return 0;
    memset(out, 0, sizeof *out);
    out->force_closure = out->force_only_closure = out->torque_closure = 1;
    out->rank = 6;
    out->epsilon = -F.off;
    memcpy(out->weakest, F.n, sizeof out->weakest);
    out->volume = -1.0;
    out->facets = -1;
    return 1;
}

/* Keeps a closed set's answer (quality_fast's) for gcGraspDef.reuse, in the slot of the nearest
 * remembered set of as many rows (within 1e-6 of the scale: the same body, moved on) or the
 * oldest. */
static gcStatus reuse_remember(gcGraspWorkspace *ws, const gcGraspDef *def, int rows, const gcGraspQuality *q) {
    double scale = 0.0, delta;
    for (int i = 0; i < rows; ++i) scale = fmax(scale, dotd(ws->wrench + 6 * i, ws->wrench + 6 * i, 6));
    int k = reuse_nearest_slot(ws, def, rows, 1e-6 * sqrt(scale), &delta);
    if (k < 0) {
        k = ws->reuse_next;
        ws->reuse_next = (k + 1) % GC_REUSE_SLOTS;
    }
    ReuseSlot *r = &ws->reuse[k];
    r->rows = 0;
    if (rows > r->cap) {
        if (!grow((void **)&r->wrench, (size_t)rows * 6, sizeof(double)))
            return set_error(ws, GC_ERR_NO_MEMORY, "workspace: out of memory");
        r->cap = rows;
    }
    memcpy(r->wrench, ws->wrench, sizeof(double) * 6 * (size_t)rows);
    memcpy(r->vertices, ws->nearest_vertices, sizeof r->vertices);
    r->rows = rows;
    r->edges = def->edges;
    r->tolerance = def->tolerance;
    r->epsilon = q->epsilon;
    return GC_OK;
}

gcStatus gc_grasp_quality(gcGraspWorkspace *ws, const gcGraspDef *def, const double *points,
                          const double *normals, const double *mu, int num_contacts, const double center[3],
                          double radius, gcGraspQuality *out) {
    if (!ws) return GC_ERR_INVALID_ARGUMENT;
    ws->error[0] = '\0';
    if (!out) return set_error(ws, GC_ERR_INVALID_ARGUMENT, "out: NULL");
    memset(out, 0, sizeof *out);
    gcGraspDef dflt = gc_default_grasp_def();
    if (!def) def = &dflt;
    gcStatus st = check_def(ws, def);
    if (st != GC_OK) return st;
    if (num_contacts > 0 && !mu) return set_error(ws, GC_ERR_INVALID_ARGUMENT, "mu: NULL");
    int rows;
    if ((st = build_wrenches(ws, def, points, normals, mu, 0.0, num_contacts, center, radius, &rows)) != GC_OK)
        return st;
    int reuse = def->reuse && !def->volume && rows > 6;
    if (reuse && reuse_answer(ws, def, rows, out)) return GC_OK;
    if ((st = quality_of_built(ws, def, rows, out)) != GC_OK) return st;
    return reuse && out->force_closure ? reuse_remember(ws, def, rows, out) : GC_OK;
}

gcStatus gc_grasp_quality_batch(gcGraspWorkspace *ws, const gcGraspDef *def, const double *points,
                                const double *normals, const double *mu, const int32_t *counts, int num_sets,
                                const double *centers, const double *radii, gcGraspQuality *out) {
    if (!ws) return GC_ERR_INVALID_ARGUMENT;
    ws->error[0] = '\0';
    if (num_sets < 0) return set_error(ws, GC_ERR_INVALID_ARGUMENT, "counts: %d sets, expected >= 0", num_sets);
    if (num_sets > 0 && (!counts || !centers || !radii || !out))
        return set_error(ws, GC_ERR_INVALID_ARGUMENT, "%s: NULL",
                         !counts ? "counts" : !centers ? "centers" : !radii ? "radii" : "out");
    size_t row = 0;
    for (int s = 0; s < num_sets; ++s) {
        if (counts[s] < 0)
            return set_error(ws, GC_ERR_INVALID_ARGUMENT, "counts: %d at set %d, expected >= 0", counts[s], s);
        gcGraspDef set_def = def ? *def : gc_default_grasp_def();
        if (set_def.torsion) set_def.torsion += row;
        gcStatus st = gc_grasp_quality(ws, &set_def, points ? points + 3 * row : NULL,
                                       normals ? normals + 3 * row : NULL, mu ? mu + row : NULL, counts[s],
                                       centers + 3 * s, radii[s], &out[s]);
        if (st != GC_OK) {
            char inner[sizeof ws->error];
            memcpy(inner, ws->error, sizeof inner);
            return set_error(ws, st, "set %d: %s", s, inner);
        }
        row += (size_t)counts[s];
    }
    return GC_OK;
}

/* gcGraspDef.reuse for mu_min: the remembered answer for contacts within 1e-9 of these (relative
 * to their largest coordinate), or -1 (none). 'remember' stores `answer` for them instead. */
static int mu_min_slot(gcGraspWorkspace *ws, const gcGraspDef *def, const double *points, const double *normals,
                       int num_contacts, const double center[3], double radius, double mu_max) {
    for (int k = 0; k < GC_REUSE_SLOTS; ++k) {
        const MuMinSlot *m = &ws->mu_min[k];
        if (m->contacts != num_contacts || m->edges != def->edges || m->tolerance != def->tolerance ||
            m->mu_max != mu_max)
            continue;
        double big = 0.0, diff = 0.0;
        const double *x = m->input;
        for (int i = 0; i < 3 * num_contacts; ++i) {
            big = fmax(big, fmax(fabs(points[i]), fabs(normals[i])));
            diff = fmax(diff, fmax(fabs(points[i] - x[i]), fabs(normals[i] - x[3 * num_contacts + i])));
        }
        for (int i = 0; i < 3; ++i) {
            big = fmax(big, fabs(center[i]));
            diff = fmax(diff, fabs(center[i] - x[6 * num_contacts + i]));
        }
        diff = fmax(diff, fabs(radius - x[6 * num_contacts + 3]) * big / radius);
        if (diff <= 1e-9 * big) return k;
    }
    return -1;
}

/* Keeps answer (and, margin > 0, the rows edge wrenches at it in ws->wrench) for these contacts. */
static void mu_min_remember(gcGraspWorkspace *ws, const gcGraspDef *def, const double *points,
                            const double *normals, int num_contacts, const double center[3], double radius,
                            double mu_max, double answer, double margin, int rows) {
    int k = mu_min_slot(ws, def, points, normals, num_contacts, center, radius, mu_max);
    if (k < 0) {
        k = ws->mu_min_next;
        ws->mu_min_next = (k + 1) % GC_REUSE_SLOTS;
    }
    MuMinSlot *m = &ws->mu_min[k];
    m->contacts = -1;
    int need = 6 * num_contacts + 4 + (margin > 0.0 ? 6 * rows : 0);
    if (need > m->cap) {
        if (!grow((void **)&m->input, (size_t)need, sizeof(double))) return;  /* not kept */
        m->cap = need;
    }
    m->margin = margin > 0.0 ? margin : 0.0;
    m->rows = m->margin > 0.0 ? rows : 0;
    memcpy(m->input + 6 * num_contacts + 4, ws->wrench, sizeof(double) * 6 * (size_t)m->rows);
    memcpy(m->input, points, sizeof(double) * 3 * (size_t)num_contacts);
    memcpy(m->input + 3 * num_contacts, normals, sizeof(double) * 3 * (size_t)num_contacts);
    memcpy(m->input + 6 * num_contacts, center, sizeof(double) * 3);
    m->input[6 * num_contacts + 3] = radius;
    m->contacts = num_contacts;
    m->edges = def->edges;
    m->tolerance = def->tolerance;
    m->mu_max = mu_max;
    m->answer = answer;
}

static gcStatus mu_min_search(gcGraspWorkspace *ws, const gcGraspDef *def, const double *points,
                              const double *normals, int num_contacts, const double center[3], double radius,
                              double mu_max, double *out_mu, double *margin, int *rows_at);

/* Closed at the remembered answer of slot m (its wrenches now in ws->wrench, rows of them), as
 * grasp_quality decides: when the support search decided it there (margin > 0, its epsilon) and
 * every wrench moved by delta, epsilon is at least margin - delta now, and more than twice the
 * tolerance of that settles it without a search; else closure_fast. */
static gcStatus mu_min_closed_again(gcGraspWorkspace *ws, const gcGraspDef *def, const MuMinSlot *m, int rows,
                                    int *closed) {
    if (m->margin > 0.0 && m->rows == rows) {
        const double *old = m->input + 6 * m->contacts + 4;
        double scale = 0.0, delta = 0.0;
        for (int i = 0; i < rows; ++i) {
            double s2 = 0.0;
            for (int c = 0; c < 6; ++c) {
                double e = ws->wrench[6 * i + c] - old[6 * i + c];
                s2 += e * e;
            }
            delta = fmax(delta, s2);
            scale = fmax(scale, dotd(ws->wrench + 6 * i, ws->wrench + 6 * i, 6));
        }
        if (m->margin - sqrt(delta) > 2.0 * def->tolerance * sqrt(scale)) {
            *closed = 1;
            return GC_OK;
        }
    }
    gcHullSummary summary;
    return closure_fast(ws, def, ws->wrench, rows, 6, 0, closed, NULL, &summary);
}

gcStatus gc_grasp_mu_min(gcGraspWorkspace *ws, const gcGraspDef *def, const double *points,
                         const double *normals, int num_contacts, const double center[3], double radius,
                         double mu_max, double *out_mu) {
    if (!ws) return GC_ERR_INVALID_ARGUMENT;
    ws->error[0] = '\0';
    if (!out_mu) return set_error(ws, GC_ERR_INVALID_ARGUMENT, "out_mu: NULL");
    *out_mu = INFINITY;
    gcGraspDef dflt = gc_default_grasp_def();
    if (!def) def = &dflt;
    gcStatus st = check_def(ws, def);
    if (st != GC_OK) return st;
    if (!(mu_max >= 0.0) || !isfinite(mu_max))
        return set_error(ws, GC_ERR_INVALID_ARGUMENT, "mu_max: %g, expected a finite number >= 0", mu_max);
    double margin = 0.0;
    int rows_at = 0;
    if (!def->reuse || def->torsion || num_contacts < 1 || !points || !normals || !center)
        return mu_min_search(ws, def, points, normals, num_contacts, center, radius, mu_max, out_mu, &margin,
                             &rows_at);
    /* Reuse: the remembered answer m for nearly these contacts, checked as the search would have
     * left it: closed at m and open 2e-6 below, as grasp_quality decides (the LP, which settles
     * both away from the boundary); 0 closed at 0; inf open at mu_max by the LP (an LP "no" is
     * never a "yes"). Else the search, remembered. */
    int k = mu_min_slot(ws, def, points, normals, num_contacts, center, radius, mu_max);
    if (k >= 0) {
        double m = ws->mu_min[k].answer, t;
        int rows, closed = 0, open = 0;
        if ((st = build_wrenches(ws, def, points, normals, NULL, isfinite(m) ? m : mu_max, num_contacts,
                                 center, radius, &rows)) != GC_OK)
            return st;
        if (isfinite(m)) {
            if ((st = mu_min_closed_again(ws, def, &ws->mu_min[k], rows, &closed)) != GC_OK) return st;
            if (closed && m > 0.0) {
                if ((st = build_wrenches(ws, def, points, normals, NULL, fmax(m - 2e-6, 0.0), num_contacts,
                                         center, radius, &rows)) != GC_OK)
                    return st;
                gcHullSummary summary;
                int below = 1;
                if ((st = closure_fast(ws, def, ws->wrench, rows, 6, 0, &below, NULL, &summary)) != GC_OK) return st;
                open = !below;
            }
            if (closed && (m == 0.0 || open)) {
                *out_mu = m;
                return GC_OK;
            }
        } else {
            open = closure_lp(ws, ws->wrench, rows, 6, NULL, &t) == GC_OK && t <= 0.5 * def->tolerance / rows;
            ws->error[0] = '\0';
            if (open) return GC_OK;         /* *out_mu is INFINITY */
        }
    }
    if ((st = mu_min_search(ws, def, points, normals, num_contacts, center, radius, mu_max, out_mu, &margin,
                            &rows_at)) != GC_OK)
        return st;
    mu_min_remember(ws, def, points, normals, num_contacts, center, radius, mu_max, *out_mu, margin, rows_at);
    return GC_OK;
}

/* The search; for a finite answer, *margin is the support search's epsilon there (0 when the LP
 * decided) and ws->wrench holds its *rows_at edge wrenches. */
static gcStatus mu_min_search(gcGraspWorkspace *ws, const gcGraspDef *def, const double *points,
                              const double *normals, int num_contacts, const double center[3], double radius,
                              double mu_max, double *out_mu, double *margin, int *rows_at) {
    gcStatus st;
    int rows, closed;
    *margin = 0.0;
    *rows_at = 0;
    double t;
    gcHullSummary summary;
    /* In closure at mu as grasp_quality answers it (the LP, then the support search). */
#define CLOSED_AT(m)                                                                                          \
    do {                                                                                                      \
        if ((st = build_wrenches(ws, def, points, normals, NULL, (m), num_contacts, center, radius,     \
                                 &rows)) != GC_OK ||                                                          \
            (st = closure_fast(ws, def, ws->wrench, rows, 6, 0, &closed, NULL, &summary)) != GC_OK)           \
            return st;                                                                                        \
    } while (0)
    CLOSED_AT(0.0);     /* one wrench per contact */
    if (closed) {
        *out_mu = 0.0;
        *margin = summary.facets == -1 ? -summary.offset_max : 0.0;
        *rows_at = rows;
        return GC_OK;
    }
    /* The same LP with the margin it found: g(mu) = mu (t*(mu) - threshold), > 0 exactly when
     * closed. t* grows like a - b / mu over the range that matters (the edges' spread from the
     * normal wrench scales with mu), so g is close to a straight line and the root is found in a
     * few secant steps. */
#define MARGIN_AT(m, g)                                                                                       \
    do {                                                                                                      \
        if ((st = build_wrenches(ws, def, points, normals, NULL, (m), num_contacts, center, radius,     \
                                 &rows)) != GC_OK)                                                            \
            return st;                                                                                        \
        st = closure_lp(ws, ws->wrench, rows, 6, warm, &t);                                                   \
        if (st == GC_ERR_DEGENERATE) {                                                                        \
            /* The LP did not converge: closed or not as grasp_quality decides, and a margin of     \
             * rounding size with that sign (Brent's method then bisects). */                                \
            ws->error[0] = '\0';                                                                              \
            warm[0] = -1;                                                                                     \
            if ((st = closure_fast(ws, def, ws->wrench, rows, 6, 0, &closed, NULL, &summary)) != GC_OK)       \
                return st;                                                                                    \
            t = closed ? def->tolerance / rows : -1.0;                                                        \
        } else if (st != GC_OK) {                                                                             \
            return st;                                                                                        \
        }                                                                                                     \
        (g) = (m) * (fmax(t, -1.0) - 0.5 * def->tolerance / rows);                                            \
    } while (0)
    if (mu_max == 0.0) return GC_OK;
    int warm[D + 1] = {-1};   /* each LP starts from the last one's optimal basis */
    /* An LP "no" is never a "yes": not closed at mu_max. A "yes" is checked at the end. */
    double glo = 0.0, ghi = 0.0, b_start = mu_max;
    MARGIN_AT(mu_max, ghi);
    if (!(ghi > 0.0)) return GC_OK;
    /* The bracket's open end: mu_max / 100 if open there, else 0 (g(0) = 0 is no help to the
     * interpolation: -g(mu_max / 100) stands in for it). */
    double lo = 0.01 * mu_max, g1;
    MARGIN_AT(lo, g1);
    if (g1 > 0.0) {
        b_start = lo;
        ghi = g1;
        lo = 0.0;
        glo = -g1;
    } else {
        glo = fmin(g1, -1e-300);
    }
    /* Brent's method on g over [lo, b]: inverse quadratic or secant steps while they stay in
     * the bracket and shrink it fast enough, bisection otherwise; each step at least 0.4e-6, so
     * the bracket ends within 0.8e-6 around the root. b is the latest point, c the other end of
     * the bracket (g of the opposite sign), a the point before b. */
    const double step_min = 0.4e-6;
    double a = lo, b = b_start, c = lo, fa = glo, fb = ghi, fc = glo, d = b - a, e = b - a, g_closed = ghi;
    for (int it = 0; it < 200; ++it) {
        if ((fb > 0.0) == (fc > 0.0)) {
            c = a;
            fc = fa;
            d = e = b - a;
        }
        if (fabs(fc) < fabs(fb)) {
            a = b, b = c, c = a;
            fa = fb, fb = fc, fc = fa;
        }
        double half = 0.5 * (c - b);
        if (fabs(half) <= step_min) break;
        if (fabs(e) >= step_min && fabs(fa) > fabs(fb)) {
            double s = fb / fa, p, q;
            if (a == c) {
                p = 2.0 * half * s;
                q = 1.0 - s;
            } else {
                double qa = fa / fc, r = fb / fc;
                p = s * (2.0 * half * qa * (qa - r) - (b - a) * (r - 1.0));
                q = (qa - 1.0) * (r - 1.0) * (s - 1.0);
            }
            if (p > 0.0) q = -q;
            p = fabs(p);
            if (2.0 * p < fmin(3.0 * half * q - fabs(step_min * q), fabs(e * q))) {
                e = d;
                d = p / q;
            } else {
                d = e = half;
            }
        } else {
            d = e = half;
        }
        a = b;
        fa = fb;
        b += fabs(d) > step_min ? d : copysign(step_min, half);
        MARGIN_AT(b, fb);
        /* t* exactly 0 over a range of mu (the origin on a face of the hull, e.g. two contacts
         * that balance each other): no slope to follow, and a zero that is not the root. Minus
         * the last closed margin stands in for it, which sends the next step about halfway. */
        if (fb > 0.0)
            g_closed = fb;
        else if (fabs(t) <= 1e-12)
            fb = -g_closed;
    }
    /* The root is in (open end, open end + 0.8e-6]: answer open end + 1e-6, closed as well and
     * far enough from the root (about 0.2e-6 at least) for the LP's certificate to settle it
     * without the support search, most times. */
    double hi = fmin((fb > 0.0 ? c : b) + 1e-6, mu_max);
#undef MARGIN_AT
    /* The LP may call a set closed whose origin is within the tolerance of the hull's boundary
     * (grasp_quality: not closed); the root it brackets is then below the closure's by about the
     * tolerance. Step up to the first mu grasp_quality calls closed; none up to mu_max: inf. */
    for (double step = 1e-9;; step *= 2.0) {
        CLOSED_AT(hi);
        if (closed) break;
        if (hi >= mu_max) return GC_OK;
        hi = fmin(hi + step, mu_max);
    }
#undef CLOSED_AT
    *out_mu = hi;
    *margin = summary.facets == -1 ? -summary.offset_max : 0.0;   /* the search ran (facets -1) */
    *rows_at = rows;
    return GC_OK;
}
