/* Grasp quality: the grasp wrench space of point contacts with linearised friction cones
 * (graspcore.h), built as an exact convex hull in 6 dimensions (3 for the force-only and
 * torque-only conditions), and the measures read off it: closure, epsilon, volume, the
 * weakest direction.
 *
 * The hull is quickhull with simplicial facets: an initial simplex of well-spread points,
 * an outside set per facet, the furthest outside point added next, the facets it sees
 * replaced by a cone of new facets over the horizon. Two things make it fast on these inputs:
 *  - A new facet's hyperplane comes from the pencil of its two horizon facets (the visible F
 *    and the hidden G share the ridge, and the apex p must lie on the new plane:
 *    N = dist(p,F) G - dist(p,G) F), O(d) instead of solving a (d-1) x d system. Each such
 *    plane is checked against all its vertices and solved from them when the check fails or
 *    the pencil is ill-conditioned; the planes that decide the answer (the nearest facet, any
 *    facet near the origin) are solved from their vertices at the end.
 *  - The volume of the simplex (c, N) (c a fixed interior point) follows from (c, F) by the
 *    same pencil: both are determinants affine in the apex and vanish on the hyperplane
 *    through c and the ridge.
 * Coplanar points (the k edge wrenches of one contact all lie on a 2-flat) are "not visible"
 * within the tolerance, so coplanar facets stay as adjacent simplices; the answers (the
 * hyperplanes, the volume) do not depend on how a flat face is cut into simplices.
 * All storage is in the workspace and grows only when a larger problem comes. */
#include "grasp_quality.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define D GC_HULL_MAX_DIM
#define GC_GRASP_MAX_EDGES 1024

static const double kTwoPi = 6.28318530717958647692;

typedef struct Facet {
    double n[D];        /* unit outward normal */
    double off;         /* n.x + off: signed distance of x */
    double cdist;       /* signed distance of the interior point c (< 0) */
    double vol;         /* volume of the simplex (c, facet) */
    double pdist;       /* signed distance of the current apex (valid when tested == stamp) */
    double fdist;       /* distance of the furthest outside point */
    int v[D];           /* vertices (point indices) */
    int nb[D];          /* nb[i]: the facet across the ridge without v[i] */
    int newf[D];        /* visible facets: the new facet built on horizon ridge i */
    int outside;        /* head of the outside-point list, -1 when empty */
    int furthest;       /* furthest outside point, -1 when the set is empty */
    int tested, visible;/* iteration stamps */
    int alive;
} Facet;

struct gcGraspWorkspace {
    char error[256];
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
        !grow((void **)&ws->next, (size_t)cap, sizeof(int)))
        return set_error(ws, GC_ERR_NO_MEMORY, "workspace: out of memory for %d wrenches", n);
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
        !grow((void **)&ws->created, (size_t)cap, sizeof(int)))
        return set_error(ws, GC_ERR_NO_MEMORY, "workspace: out of memory for %d facets", n);
    ws->cap_facets = cap;
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
} Hull;

static inline const double *point(const Hull *h, int i) { return h->pts + (size_t)i * (size_t)h->d; }

/* The facet's hyperplane solved from its vertices (complete pivoting on the d-1 edge vectors),
 * oriented away from c. 0 when the vertices are affinely dependent. */
static int exact_plane(const Hull *h, Facet *f) {
    int d = h->d;
    double a[D - 1][D];
    int col[D] = {0, 1, 2, 3, 4, 5};
    const double *v0 = point(h, f->v[0]);
    for (int r = 0; r < d - 1; ++r) {
        const double *vr = point(h, f->v[r + 1]);
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
    for (int r = 0; r < d; ++r) off -= dotd(x, point(h, f->v[r]), d);
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
        const double *v = point(h, f->v[r]);
        for (int k = 0; k < d; ++k) a[r * d + k] = v[k] - h->c[k];
    }
    return abs_det(a, d) / factorial(d);
}

static int new_facet(Hull *h) {
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
        for (int k = 0; k < d; ++k) mean[k] += point(h, i)[k];
    for (int k = 0; k < d; ++k) mean[k] /= n;
    int first = 0;
    double best = -1.0;
    for (int i = 0; i < n; ++i) {
        double s = 0.0;
        for (int k = 0; k < d; ++k) s += (point(h, i)[k] - mean[k]) * (point(h, i)[k] - mean[k]);
        if (s > best) best = s, first = i;
    }
    chosen[0] = first;
    const double *o = point(h, first);
    for (int i = 0; i < n; ++i)
        for (int k = 0; k < d; ++k) res[i * 6 + k] = point(h, i)[k] - o[k];
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
static void make_cone_facet(Hull *h, int fi, int i, int p, int ni) {
    gcGraspWorkspace *ws = h->ws;
    Facet *F = &ws->facets[fi], *N = &ws->facets[ni];
    int d = h->d, gi = F->nb[i];
    Facet *G = &ws->facets[gi];
    memcpy(N->v, F->v, sizeof(int) * (size_t)d);
    N->v[i] = p;
    N->nb[i] = gi;
    for (int k = 0; k < d; ++k)
        if (G->nb[k] == fi) G->nb[k] = ni;
    F->newf[i] = ni;

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
        for (int r = 0; ok && r < d; ++r)
            if (fabs(facet_dist(N, point(h, N->v[r]), d)) > h->vtol) ok = 0;
    }
    if (!ok) exact_plane(h, N);
    /* vol(c,N) / vol(c,F) = |H(p)| / |H(q)|, H the hyperplane through c and the ridge. */
    double gq = facet_dist(G, point(h, F->v[i]), d);
    double num = G->cdist * dF - F->cdist * dG;
    if (ok && fabs(gq) > 1e3 * h->vtol && fabs(F->cdist) > 1e3 * h->vtol)
        N->vol = F->vol * fabs(num) / fabs(F->cdist * gq);
    else
        N->vol = exact_volume(h, N);
}

/* Index of x in a[0..d) (it is there). */
static inline int index_of(const int *a, int d, int x) {
    for (int k = 0; k < d; ++k)
        if (a[k] == x) return k;
    return -1;
}

/* The new facet across N's ridge without v[j]: rotate around the (d-3)-face the ridge shares
 * with the horizon, through visible facets, to the next horizon ridge. */
static int neighbour_across(const Hull *h, int fi, int i, int j) {
    const Facet *fs = h->ws->facets;
    int d = h->d;
    int cur = fi, drop = fs[fi].v[j], keep = fs[fi].v[i];
    for (int guard = 0; guard < h->ws->cap_facets; ++guard) {
        int k = index_of(fs[cur].v, d, drop);
        if (k < 0) return -1;
        int nxt = fs[cur].nb[k];
        if (fs[nxt].visible != h->stamp) return fs[cur].newf[k];
        int m = index_of(fs[nxt].nb, d, cur);
        if (m < 0) return -1;
        int w = fs[nxt].v[m];
        cur = nxt;
        drop = keep;
        keep = w;
    }
    return -1;
}

gcStatus gc_hull_nd(gcGraspWorkspace *ws, const double *points, int n, int d, double tolerance,
                    int max_facets, gcHullSummary *out) {
    memset(out, 0, sizeof *out);
    out->result = GC_HULL_FLAT;
    out->offset_max = 0.0;
    if (d < 3 || d > D) return set_error(ws, GC_ERR_INVALID_ARGUMENT, "d: %d, expected 3 to %d", d, D);
    if (n < d + 1) return GC_OK;
    gcStatus st = ensure_points(ws, n);
    if (st != GC_OK) return st;
    Hull h;
    memset(&h, 0, sizeof h);
    h.ws = ws;
    h.pts = points;
    h.n = n;
    h.d = d;
    h.max_facets = max_facets;
    double scale = 0.0;
    for (int i = 0; i < n; ++i) scale = fmax(scale, dotd(point(&h, i), point(&h, i), d));
    scale = sqrt(scale);
    if (!(scale > 0.0)) return GC_OK;
    h.tol = tolerance * scale;
    h.vtol = 1e-12 * scale;

    int chosen[D + 1];
    if (initial_simplex(&h, chosen) < d + 1) return GC_OK;
    for (int k = 0; k < d; ++k) {
        double s = 0.0;
        for (int m = 0; m <= d; ++m) s += point(&h, chosen[m])[k];
        h.c[k] = s / (d + 1);
    }
    st = ensure_facets(ws, 2 * (d + 1), max_facets);
    if (st != GC_OK) return st;
    ws->high_water = 0;
    ws->num_free = 0;
    /* Facet m of the simplex leaves out chosen[m]; its ridge without chosen[k] faces facet k. */
    for (int m = 0; m <= d; ++m) {
        int f = new_facet(&h);
        Facet *F = &ws->facets[f];
        int r = 0;
        for (int k = 0; k <= d; ++k) {
            if (k == m) continue;
            F->v[r] = chosen[k];
            F->nb[r] = k;
            ++r;
        }
        exact_plane(&h, F);
        F->vol = exact_volume(&h, F);
    }
    for (int i = 0; i < n; ++i) ws->next[i] = -1;
    int num_pending = 0;
    for (int i = 0; i < n; ++i) {
        if (index_of(chosen, d + 1, i) >= 0) continue;
        for (int f = 0; f <= d; ++f) {
            double dist = facet_dist(&ws->facets[f], point(&h, i), d);
            if (dist > h.tol) {
                add_outside(&h, &ws->facets[f], i, dist);
                break;
            }
        }
    }
    for (int f = 0; f <= d; ++f)
        if (ws->facets[f].furthest >= 0 && (st = push_pending(ws, &num_pending, f)) != GC_OK) return st;

    int iter = 0;
    while (num_pending > 0) {
        int fi = ws->pending[--num_pending];
        Facet *F0 = &ws->facets[fi];
        if (!F0->alive || F0->furthest < 0) continue;
        /* Each step makes one more point a vertex: at most n steps. */
        if (++iter > n) return set_error(ws, GC_ERR_DEGENERATE, "points: the hull did not converge in %d steps", n);
        int p = F0->furthest;
        const double *pp = point(&h, p);
        h.stamp = iter;
        /* Visible facets: breadth first from fi over neighbours that see p. */
        int nv = 0;
        F0->tested = F0->visible = iter;
        F0->pdist = F0->fdist;
        ws->visible[nv++] = fi;
        int horizon = 0;
        for (int s = 0; s < nv; ++s) {
            Facet *F = &ws->facets[ws->visible[s]];
            for (int k = 0; k < d; ++k) {
                Facet *G = &ws->facets[F->nb[k]];
                if (G->tested != iter) {
                    G->tested = iter;
                    G->pdist = facet_dist(G, pp, d);
                    if (G->pdist > h.tol) {
                        G->visible = iter;
                        ws->visible[nv++] = F->nb[k];
                        continue;
                    }
                }
                if (G->visible != iter) ++horizon;
            }
        }
        st = ensure_facets(ws, ws->high_water + horizon, max_facets);
        if (st != GC_OK) return st;
        /* The cone: one new facet per horizon ridge. */
        int nc = 0;
        for (int s = 0; s < nv; ++s) {
            int vf = ws->visible[s];
            for (int k = 0; k < d; ++k) {
                int g = ws->facets[vf].nb[k];
                if (ws->facets[g].visible == iter) continue;
                int nf = new_facet(&h);
                ws->created[nc++] = nf;
                make_cone_facet(&h, vf, k, p, nf);
                ws->facets[nf].tested = ws->facets[nf].visible = -1;
            }
        }
        /* Links between new facets: across each ridge that holds the apex. */
        for (int s = 0; s < nv; ++s) {
            int vf = ws->visible[s];
            for (int k = 0; k < d; ++k) {
                if (ws->facets[ws->facets[vf].nb[k]].visible == iter) continue;
                int nf = ws->facets[vf].newf[k];
                for (int j = 0; j < d; ++j) {
                    if (j == k) continue;
                    int other = neighbour_across(&h, vf, k, j);
                    if (other < 0) return set_error(ws, GC_ERR_DEGENERATE, "points: broken hull topology");
                    ws->facets[nf].nb[j] = other;
                }
            }
        }
        /* Outside points of the visible facets go to the first new facet they are above. */
        for (int s = 0; s < nv; ++s) {
            Facet *F = &ws->facets[ws->visible[s]];
            for (int q = F->outside; q >= 0;) {
                int nq = ws->next[q];
                if (q != p) {
                    const double *x = point(&h, q);
                    for (int c = 0; c < nc; ++c) {
                        Facet *N = &ws->facets[ws->created[c]];
                        double dist = facet_dist(N, x, d);
                        if (dist > h.tol) {
                            add_outside(&h, N, q, dist);
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

    /* The answer: volume, and the nearest facet with its plane solved from its vertices. */
    double volume = 0.0, best = -INFINITY;
    int facets = 0;
    for (int f = 0; f < ws->high_water; ++f) {
        Facet *F = &ws->facets[f];
        if (!F->alive) continue;
        ++facets;
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
 * mu NULL: every contact has mu_all. */
static gcStatus build_wrenches(gcGraspWorkspace *ws, int edges, const double *points, const double *normals,
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
    if ((long long)num_contacts * edges > 1000000)
        return set_error(ws, GC_ERR_INVALID_ARGUMENT, "points: %d contacts x %d edges is too many", num_contacts,
                         edges);
    gcStatus st = ensure_points(ws, num_contacts * edges);
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
    }
    *count = rows;
    return GC_OK;
}

/* Strictly inside a d-dimensional point set's hull (rank d first); *rank its linear rank. */
static gcStatus closure_of(gcGraspWorkspace *ws, const gcGraspDef *def, const double *pts, int rows, int d,
                           int *closed, int *rank, gcHullSummary *summary) {
    *closed = 0;
    memset(summary, 0, sizeof *summary);
    gcStatus st = gc_span_rank(ws, pts, rows, d, def->tolerance, rank);
    if (st != GC_OK || *rank < d) return st;
    st = gc_hull_nd(ws, pts, rows, d, def->tolerance, def->max_facets, summary);
    if (st != GC_OK) return st;
    if (summary->result != GC_HULL_FULL) return GC_OK;
    double scale = 0.0;
    for (int i = 0; i < rows; ++i) scale = fmax(scale, dotd(pts + (size_t)i * d, pts + (size_t)i * d, d));
    *closed = summary->offset_max < -def->tolerance * sqrt(scale);
    return GC_OK;
}

static gcStatus quality_of_built(gcGraspWorkspace *ws, const gcGraspDef *def, int rows, gcGraspQuality *out) {
    memset(out, 0, sizeof *out);
    int closed, rank;
    gcHullSummary s;
    gcStatus st = closure_of(ws, def, ws->force, rows, 3, &closed, &rank, &s);
    if (st != GC_OK) return st;
    out->force_only_closure = closed;
    if ((st = closure_of(ws, def, ws->torque, rows, 3, &closed, &rank, &s)) != GC_OK) return st;
    out->torque_closure = closed;
    if ((st = closure_of(ws, def, ws->wrench, rows, 6, &closed, &rank, &s)) != GC_OK) return st;
    out->rank = rank;
    if (s.result != GC_HULL_FULL) return GC_OK;
    out->facets = s.facets;
    out->volume = s.volume;
    out->force_closure = closed;
    if (closed) {
        out->epsilon = -s.offset_max;
        memcpy(out->weakest, s.nearest_normal, sizeof out->weakest);
    }
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
    if ((st = build_wrenches(ws, def->edges, points, normals, mu, 0.0, num_contacts, center, radius, &rows)) != GC_OK)
        return st;
    return quality_of_built(ws, def, rows, out);
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
        gcStatus st = gc_grasp_quality(ws, def, points ? points + 3 * row : NULL, normals ? normals + 3 * row : NULL,
                                       mu ? mu + row : NULL, counts[s], centers + 3 * s, radii[s], &out[s]);
        if (st != GC_OK) {
            char inner[sizeof ws->error];
            memcpy(inner, ws->error, sizeof inner);
            return set_error(ws, st, "set %d: %s", s, inner);
        }
        row += (size_t)counts[s];
    }
    return GC_OK;
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
    int rows, closed, rank;
    gcHullSummary s;
    /* closed_at(mu): the 6-D closure test for every contact at mu. */
#define CLOSED_AT(m)                                                                                          \
    do {                                                                                                      \
        if ((st = build_wrenches(ws, def->edges, points, normals, NULL, (m), num_contacts, center, radius,     \
                                 &rows)) != GC_OK)                                                            \
            return st;                                                                                        \
        if ((st = closure_of(ws, def, ws->wrench, rows, 6, &closed, &rank, &s)) != GC_OK) return st;           \
    } while (0)
    CLOSED_AT(0.0);
    if (closed) {
        *out_mu = 0.0;
        return GC_OK;
    }
    CLOSED_AT(mu_max);
    if (!closed) return GC_OK;
    double lo = 0.0, hi = mu_max;
    for (int it = 0; it < 100 && hi - lo > 1e-6; ++it) {
        double mid = 0.5 * (lo + hi);
        CLOSED_AT(mid);
        if (closed)
            hi = mid;
        else
            lo = mid;
    }
#undef CLOSED_AT
    *out_mu = hi;
    return GC_OK;
}
