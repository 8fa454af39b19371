/* Convex hulls in 3 to 6 dimensions (gc_hull_nd: quickhull for the volume and the facet count)
 * and the support-function search for the facet nearest the origin (gc_hull_nearest), and the
 * rank of a point set (gc_span_rank). See grasp_quality.c for how the analysis uses them and
 * what makes them fast on wrench sets. */
#include "analysis_internal.h"
#include "base/small_dense.h"

static double factorial(int d) {
    double f = 1.0;
    for (int k = 2; k <= d; ++k) f *= k;
    return f;
}

/* The facet's hyperplane solved from its vertices (complete pivoting on the d-1 edge vectors),
 * oriented away from c. 0 when the vertices are affinely dependent. */
int gc_hull_exact_plane(const Hull *h, Facet *f) {
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
    return gc_abs_det(a, d) / factorial(d);
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
    if (d < 1 || d > D) return gc_grasp_set_error(ws, GC_ERR_INVALID_ARGUMENT, "d: %d, expected 1 to %d", d, D);
    gcStatus st = gc_grasp_ensure_points(ws, n);
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
    if (!ok) gc_hull_exact_plane(h, N);
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
    if (gc_grasp_ensure_ridges(ws, nc * (d - 1)) != GC_OK) return 0;
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
    if ((st = gc_grasp_ensure_facets(ws, ws->high_water + horizon, h->max_facets)) != GC_OK) return st;
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
        return gc_grasp_set_error(ws, GC_ERR_DEGENERATE, "points: broken hull topology");
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
        if (ws->facets[f].furthest >= 0 && (st = gc_grasp_push_pending(ws, &num_pending, f)) != GC_OK) return st;
    while (num_pending > 0) {
        int fi = ws->pending[--num_pending];
        Facet *F0 = &ws->facets[fi];
        if (!F0->alive || F0->furthest < 0) continue;
        /* Each step makes one more point a vertex: at most n steps. */
        if (++iter > n) return gc_grasp_set_error(ws, GC_ERR_DEGENERATE, "points: the hull did not converge in %d steps", n);
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
                (st = gc_grasp_push_pending(ws, &num_pending, ws->created[c])) != GC_OK)
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
    gcStatus st = gc_grasp_ensure_points(ws, n);
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
    st = gc_grasp_ensure_facets(ws, 2 * (d + 1), max_facets);
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
        gc_hull_exact_plane(h, F);
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
    if (d < 3 || d > D) return gc_grasp_set_error(ws, GC_ERR_INVALID_ARGUMENT, "d: %d, expected 3 to %d", d, D);
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
                gc_hull_exact_plane(&h, F);
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
        gc_hull_exact_plane(&h, F);
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
            return gc_grasp_set_error(ws, GC_ERR_DEGENERATE, "points: the support search did not converge in %d steps", n);
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
            gc_hull_exact_plane(h, F);
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
    if (d < 3 || d > D) return gc_grasp_set_error(ws, GC_ERR_INVALID_ARGUMENT, "d: %d, expected 3 to %d", d, D);
    Hull h;
    int chosen[D + 1], full;
    gcStatus st = hull_begin(&h, ws, points, n, d, tolerance, max_facets, 0, chosen, &full);
    if (st != GC_OK || !full) return st;
    return d == 6 ? nearest_run6(&h, out) : d == 3 ? nearest_run3(&h, out) : nearest_run_any(&h, out);
}
