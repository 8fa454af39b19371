/* Convex queries: support mapping, point query, GJK distance, EPA penetration.
 * No allocation; every loop has a fixed cap; every answer is finite. */
#include "geometry.h"

#include <float.h>
#include <string.h>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif

/* Relative tolerances, multiplied by the size of the pair (sum of AABB diagonals). */
#define GJK_REL_TOL 1e-10    /* distance accuracy; below this the cores are "touching" */
#define EPA_REL_TOL 1e-9     /* penetration depth accuracy */
/* Below this many vertices a linear scan beats hill climbing (measured with
 * bench/bench_gjk.sh: branchy graph walks lose to a tight loop). */
#ifndef GC_SUPPORT_BRUTE_MAX
#define GC_SUPPORT_BRUTE_MAX 128
#endif
#define EPA_MAX_VERTICES (GC_EPA_MAX_ITERATIONS + 8)
#define EPA_MAX_FACES (2 * EPA_MAX_VERTICES + 8)

/* ------------------------------------------------------------------ support */

/* Brute-force argmax of dot(v[i], d) over the array-of-structs vertices (hulls not
 * made by gc_hull_build); ties go to the lowest index. */
static int argmax_dot(const gcVec3 *v, int n, gcVec3 d) {
    int best = 0;
    double best_dot = gc_dot(v[0], d);
    for (int i = 1; i < n; ++i) {
        double x = gc_dot(v[i], d);
        if (x > best_dot) { best_dot = x; best = i; }
    }
    return best;
}

/* The same argmax over the structure-of-arrays copy (np a multiple of 4, padding =
 * vertex 0). Two passes per chunk: the dot products (computed exactly as gc_dot:
 * (x dx + y dy) + z dz, no contraction) are stored while a branch-free running
 * maximum is kept, then the first index holding that maximum is returned, so ties
 * go to the lowest index as in argmax_dot and the answers are bit-identical.
 * SSE2 (baseline x86-64) when available, plain C otherwise. */
#define GC_SOA_CHUNK 256
#if defined(__SSE2__)
static inline __m128d dot2(const double *X, const double *Y, const double *Z, int i, __m128d dx, __m128d dy,
                           __m128d dz) {
    return _mm_add_pd(_mm_add_pd(_mm_mul_pd(_mm_load_pd(X + i), dx), _mm_mul_pd(_mm_load_pd(Y + i), dy)),
                      _mm_mul_pd(_mm_load_pd(Z + i), dz));
}

static inline int lowest_bit(int mask) { /* mask != 0 */
#if defined(__GNUC__)
    return __builtin_ctz((unsigned)mask);
#else
    int i = 0;
    while (!((mask >> i) & 1)) ++i;
    return i;
#endif
}

static int argmax_soa(const double *X, const double *Y, const double *Z, int np, gcVec3 d) {
    __m128d dx = _mm_set1_pd(d.x), dy = _mm_set1_pd(d.y), dz = _mm_set1_pd(d.z);
    if (np <= 8) {
        /* Up to 8 vertices (boxes): all dot products stay in registers. */
        __m128d a0 = dot2(X, Y, Z, 0, dx, dy, dz), a1 = dot2(X, Y, Z, 2, dx, dy, dz), a2 = a0, a3 = a1;
        if (np == 8) {
            a2 = dot2(X, Y, Z, 4, dx, dy, dz);
            a3 = dot2(X, Y, Z, 6, dx, dy, dz);
        }
        __m128d m = _mm_max_pd(_mm_max_pd(a0, a1), _mm_max_pd(a2, a3));
        m = _mm_max_pd(m, _mm_unpackhi_pd(m, m));
        m = _mm_unpacklo_pd(m, m);
        int mask = _mm_movemask_pd(_mm_cmpeq_pd(a0, m)) | (_mm_movemask_pd(_mm_cmpeq_pd(a1, m)) << 2) |
                   (_mm_movemask_pd(_mm_cmpeq_pd(a2, m)) << 4) | (_mm_movemask_pd(_mm_cmpeq_pd(a3, m)) << 6);
        return mask ? lowest_bit(mask) : 0; /* 0: NaN direction */
    }
    _Alignas(16) double buf[GC_SOA_CHUNK];
    int best = 0;
    double best_dot = 0.0;
    for (int base = 0; base < np; base += GC_SOA_CHUNK) {
        int m = np - base < GC_SOA_CHUNK ? np - base : GC_SOA_CHUNK;
        const double *x = X + base, *y = Y + base, *z = Z + base;
        __m128d m0 = _mm_set1_pd(-DBL_MAX), m1 = m0;
        for (int i = 0; i < m; i += 4) {
            __m128d a0 = dot2(x, y, z, i, dx, dy, dz), a1 = dot2(x, y, z, i + 2, dx, dy, dz);
            _mm_store_pd(buf + i, a0);
            _mm_store_pd(buf + i + 2, a1);
            m0 = _mm_max_pd(a0, m0);
            m1 = _mm_max_pd(a1, m1);
        }
        m0 = _mm_max_pd(m0, m1);
        m0 = _mm_max_pd(m0, _mm_unpackhi_pd(m0, m0));
        double chunk_max = _mm_cvtsd_f64(m0);
        if (base > 0 && !(chunk_max > best_dot)) continue;
        m0 = _mm_unpacklo_pd(m0, m0);
        int found = -1;
        for (int i = 0; i < m; i += 4) {
            int mask = _mm_movemask_pd(_mm_cmpeq_pd(_mm_load_pd(buf + i), m0)) |
                       (_mm_movemask_pd(_mm_cmpeq_pd(_mm_load_pd(buf + i + 2), m0)) << 2);
            if (mask) { found = i + lowest_bit(mask); break; }
        }
        if (found < 0) return base == 0 ? 0 : best; /* NaN direction: any vertex */
        best = base + found;
        best_dot = chunk_max;
    }
    return best;
}
#else
static int argmax_soa(const double *X, const double *Y, const double *Z, int np, gcVec3 d) {
    int best = 0;
    double best_dot = X[0] * d.x + Y[0] * d.y + Z[0] * d.z;
    for (int i = 1; i < np; ++i) {
        double x = X[i] * d.x + Y[i] * d.y + Z[i] * d.z;
        if (x > best_dot) { best_dot = x; best = i; }
    }
    return best;
}
#endif

static int support_index(const gcHull *h, gcVec3 d, int start) {
    const gcVec3 *v = h->vertices;
    if (!h->adjacency || h->num_vertices <= GC_SUPPORT_BRUTE_MAX) {
        if (h->soa_x) return argmax_soa(h->soa_x, h->soa_y, h->soa_z, h->num_padded, d);
        return argmax_dot(v, h->num_vertices, d);
    }
    /* Steepest ascent over the vertex graph: on a convex polytope a vertex with no
     * better neighbour is a global maximum. Strict increase bounds the walk. */
    int cur = start, steps = 0;
    double best_dot = gc_dot(v[cur], d);
    for (;;) {
        int next = cur;
        for (int k = h->adjacency_start[cur]; k < h->adjacency_start[cur + 1]; ++k) {
            int j = h->adjacency[k];
            double x = gc_dot(v[j], d);
            if (x > best_dot) { best_dot = x; next = j; }
        }
        if (next == cur || ++steps > h->num_vertices) break;
        cur = next;
    }
    return cur;
}

gcVec3 gc_hull_support(const gcHull *hull, gcVec3 dir) {
    return hull->vertices[support_index(hull, dir, 0)];
}

static double hull_size(const gcHull *h) {
    return gc_len(gc_sub(h->aabb_max, h->aabb_min));
}

static int transform_ok(const gcTransform *t) {
    return gc_vec_finite(t->p) && gc_vec_finite(gc_v3(t->R.m[0][0], t->R.m[0][1], t->R.m[0][2])) &&
           gc_vec_finite(gc_v3(t->R.m[1][0], t->R.m[1][1], t->R.m[1][2])) &&
           gc_vec_finite(gc_v3(t->R.m[2][0], t->R.m[2][1], t->R.m[2][2]));
}

static int hull_ok(const gcHull *h) {
    return h && h->vertices && h->num_vertices >= 1 && isfinite(h->radius) && h->radius >= 0.0;
}

/* Any unit vector perpendicular to u (u unit). */
static gcVec3 any_perpendicular(gcVec3 u) {
    gcVec3 axis = fabs(u.x) < 0.57735 ? gc_v3(1, 0, 0) : (fabs(u.y) < 0.57735 ? gc_v3(0, 1, 0) : gc_v3(0, 0, 1));
    return gc_normalize(gc_cross(u, axis));
}

/* ------------------------------------------------------------- pair + simplex */

/* GJK/EPA run in A's local frame: only B's support needs a rotation, and only of
 * the direction (never of all vertices). */
typedef struct Pair {
    const gcHull *a, *b;
    gcMat3 R;    /* B local -> A local */
    gcVec3 p;    /* B's origin in A's frame */
    int ia, ib;  /* last support vertices: warm start for hill climbing */
} Pair;

typedef struct SVert {
    gcVec3 w, a, b;  /* w = a - b, all in A's frame */
    int ia, ib;
} SVert;

static SVert pair_support(Pair *q, gcVec3 d) {
    SVert s;
    q->ia = support_index(q->a, d, q->ia);
    q->ib = support_index(q->b, gc_mat3_tmul_vec(&q->R, gc_neg(d)), q->ib);
    s.ia = q->ia;
    s.ib = q->ib;
    s.a = q->a->vertices[q->ia];
    s.b = gc_add(gc_mat3_mul_vec(&q->R, q->b->vertices[q->ib]), q->p);
    s.w = gc_sub(s.a, s.b);
    return s;
}

static void pair_init(Pair *q, const gcHull *a, const gcTransform *ta, const gcHull *b, const gcTransform *tb) {
    q->a = a;
    q->b = b;
    q->R = gc_mat3_transpose(&ta->R);
    q->R = gc_mat3_mul(&q->R, &tb->R);
    q->p = gc_mat3_tmul_vec(&ta->R, gc_sub(tb->p, ta->p));
    q->ia = 0;
    q->ib = 0;
}

typedef struct Simplex {
    SVert v[4];
    double l[4];  /* barycentric weights of the closest point */
    gcVec3 p;     /* the closest point itself: computed directly, more accurate than sum l w */
    int n;
} Simplex;

static gcVec3 simplex_closest(const Simplex *s) { return s->p; }

static void simplex_witness(const Simplex *s, gcVec3 *pa, gcVec3 *pb) {
    gcVec3 a = gc_scale(s->v[0].a, s->l[0]), b = gc_scale(s->v[0].b, s->l[0]);
    for (int i = 1; i < s->n; ++i) {
        a = gc_madd(a, s->v[i].a, s->l[i]);
        b = gc_madd(b, s->v[i].b, s->l[i]);
    }
    *pa = a;
    *pb = b;
}

static void keep1(Simplex *s, int i) {
    s->v[0] = s->v[i];
    s->l[0] = 1.0;
    s->p = s->v[0].w;
    s->n = 1;
}

static void keep2(Simplex *s, int i, int j, double t) {
    SVert vi = s->v[i], vj = s->v[j];
    s->v[0] = vi;
    s->v[1] = vj;
    s->l[0] = 1.0 - t;
    s->l[1] = t;
    s->p = gc_madd(vi.w, gc_sub(vj.w, vi.w), t);
    s->n = 2;
}

/* Closest point of segment v0 v1 to the origin (Voronoi regions). */
static void solve2(Simplex *s) {
    gcVec3 a = s->v[0].w, ab = gc_sub(s->v[1].w, a);
    double t = -gc_dot(a, ab), dd = gc_dot(ab, ab);
    if (t <= 0.0 || dd <= 0.0) { keep1(s, 0); return; }
    if (t >= dd) { keep1(s, 1); return; }
    keep2(s, 0, 1, t / dd);
}

static double solve3_regions(Simplex *s);

/* Triangle: Voronoi-region tests (Ericson, RTCD 5.1.5); a degenerate (sliver)
 * triangle falls back to its best edge. */
static void solve3(Simplex *s) {
    if (solve3_regions(s) >= 0.0) return;
    Simplex best, t;
    double best_d = DBL_MAX;
    static const int edges[3][2] = {{0, 1}, {1, 2}, {0, 2}};
    for (int e = 0; e < 3; ++e) {
        t.v[0] = s->v[edges[e][0]];
        t.v[1] = s->v[edges[e][1]];
        t.n = 2;
        solve2(&t);
        double d = gc_len2(simplex_closest(&t));
        if (d < best_d) { best_d = d; best = t; }
    }
    *s = best;
}

/* Returns -1 when the triangle is too thin to classify the origin. */
static double solve3_regions(Simplex *s) {
    gcVec3 a = s->v[0].w, b = s->v[1].w, c = s->v[2].w;
    gcVec3 ab = gc_sub(b, a), ac = gc_sub(c, a);
    double d1 = -gc_dot(ab, a), d2 = -gc_dot(ac, a);
    if (d1 <= 0.0 && d2 <= 0.0) { keep1(s, 0); return 0.0; }
    double d3 = -gc_dot(ab, b), d4 = -gc_dot(ac, b);
    if (d3 >= 0.0 && d4 <= d3) { keep1(s, 1); return 0.0; }
    double vc = d1 * d4 - d3 * d2;
    if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) {
        if (d1 - d3 <= 0.0) { keep1(s, 0); return 0.0; }
        keep2(s, 0, 1, d1 / (d1 - d3));
        return 0.0;
    }
    double d5 = -gc_dot(ab, c), d6 = -gc_dot(ac, c);
    if (d6 >= 0.0 && d5 <= d6) { keep1(s, 2); return 0.0; }
    double vb = d5 * d2 - d1 * d6;
    if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) {
        if (d2 - d6 <= 0.0) { keep1(s, 0); return 0.0; }
        keep2(s, 0, 2, d2 / (d2 - d6));
        return 0.0;
    }
    double va = d3 * d6 - d5 * d4;
    if (va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0) {
        double den = (d4 - d3) + (d5 - d6);
        if (den <= 0.0) { keep1(s, 1); return 0.0; }
        keep2(s, 1, 2, (d4 - d3) / den);
        return 0.0;
    }
    if (!(va + vb + vc > 0.0)) return -1.0;
    /* Face region. Project the origin on the plane, then weights from sub-areas
     * around the projection: accurate on slivers where the products above cancel. */
    gcVec3 n = gc_cross(ab, ac);
    double nn = gc_dot(n, n);
    if (!(nn > 0.0)) return -1.0;
    gcVec3 p0 = gc_scale(n, gc_dot(n, a) / nn);
    double la = gc_dot(gc_cross(gc_sub(b, p0), gc_sub(c, p0)), n) / nn;
    double lb = gc_dot(gc_cross(gc_sub(c, p0), gc_sub(a, p0)), n) / nn;
    la = fmin(fmax(la, 0.0), 1.0);
    lb = fmin(fmax(lb, 0.0), 1.0 - la);
    s->l[0] = la;
    s->l[1] = lb;
    s->l[2] = 1.0 - la - lb;
    s->p = p0;
    s->n = 3;
    return 0.0;
}

/* Tetrahedron: returns 1 when it contains the origin (weights set), else reduces
 * to the closest face's sub-simplex. */
static int solve4(Simplex *s) {
    static const int faces[4][4] = {{0, 1, 2, 3}, {0, 2, 3, 1}, {0, 3, 1, 2}, {1, 3, 2, 0}};
    gcVec3 p[4] = {s->v[0].w, s->v[1].w, s->v[2].w, s->v[3].w};
    double vol = gc_dot(gc_sub(p[1], p[0]), gc_cross(gc_sub(p[2], p[0]), gc_sub(p[3], p[0])));
    double size = gc_len(gc_sub(p[1], p[0])) * gc_len(gc_sub(p[2], p[0])) * gc_len(gc_sub(p[3], p[0]));
    int flat = !(fabs(vol) > 1e-14 * size);
    double best_d = DBL_MAX;
    Simplex best;
    int any_outside = 0;
    for (int f = 0; f < 4; ++f) {
        gcVec3 a = p[faces[f][0]], b = p[faces[f][1]], c = p[faces[f][2]], opp = p[faces[f][3]];
        gcVec3 n = gc_cross(gc_sub(b, a), gc_sub(c, a));
        double side_origin = -gc_dot(n, a), side_opp = gc_dot(n, gc_sub(opp, a));
        if (!flat && !(side_origin * side_opp < 0.0)) continue;
        any_outside = 1;
        Simplex t;
        t.v[0] = s->v[faces[f][0]];
        t.v[1] = s->v[faces[f][1]];
        t.v[2] = s->v[faces[f][2]];
        t.n = 3;
        solve3(&t);
        double d = gc_len2(simplex_closest(&t));
        if (d < best_d) { best_d = d; best = t; }
    }
    if (!any_outside) {
        /* Barycentric weights from signed sub-volumes. */
        gcVec3 o = gc_v3(0, 0, 0);
        double l1 = gc_dot(gc_sub(o, p[0]), gc_cross(gc_sub(p[2], p[0]), gc_sub(p[3], p[0]))) / vol;
        double l2 = gc_dot(gc_sub(p[1], p[0]), gc_cross(gc_sub(o, p[0]), gc_sub(p[3], p[0]))) / vol;
        double l3 = gc_dot(gc_sub(p[1], p[0]), gc_cross(gc_sub(p[2], p[0]), gc_sub(o, p[0]))) / vol;
        s->l[0] = 1.0 - l1 - l2 - l3;
        s->l[1] = l1;
        s->l[2] = l2;
        s->l[3] = l3;
        s->p = o;
        s->n = 4;
        return 1;
    }
    *s = best;
    return 0;
}

/* ---------------------------------------------------------------------- GJK */

typedef struct GjkResult {
    double distance;   /* |v| */
    gcVec3 v;          /* closest point of A - B to the origin (A's frame) */
    int overlap;       /* cores intersect or touch within tolerance */
    int iterations;
    int capped;
    int separated;     /* stopped early on a separating axis (sep_margin >= 0 only) */
    SVert sep_w;       /* the support point that proved it: dot(v, w) > sep_margin |v| */
} GjkResult;

/* sep_margin < 0: run to convergence (distance query). sep_margin >= 0: also stop as
 * soon as a support point w along -v proves dist >= dot(v, w)/|v| > sep_margin. */
static void gjk(Pair *q, Simplex *s, double tol, double sep_margin, GjkResult *r) {
    gcVec3 ca = gc_scale(gc_add(q->a->aabb_min, q->a->aabb_max), 0.5);
    gcVec3 cb = gc_add(gc_mat3_mul_vec(&q->R, gc_scale(gc_add(q->b->aabb_min, q->b->aabb_max), 0.5)), q->p);
    gcVec3 d = gc_sub(cb, ca);
    if (gc_len2(d) == 0.0) d = gc_v3(1, 0, 0);
    s->v[0] = pair_support(q, d);
    s->l[0] = 1.0;
    s->p = s->v[0].w;
    s->n = 1;
    gcVec3 v = s->v[0].w;
    r->overlap = 0;
    r->capped = 1;
    r->separated = 0;
    int it = 0;
    while (it < GC_GJK_MAX_ITERATIONS) {
        ++it;
        double vv = gc_dot(v, v);
        if (vv <= tol * tol) { r->overlap = 1; r->capped = 0; break; }
        SVert w = pair_support(q, gc_neg(v));
        double vw = gc_dot(v, w.w);
        if (sep_margin >= 0.0 && vw > 0.0 && vw * vw > sep_margin * sep_margin * vv) {
            r->separated = 1;
            r->sep_w = w;
            r->capped = 0;
            break;
        }
        /* |v| - dist <= (v.v - v.w)/|v|: stop when that gap is within tolerance. */
        double gap = vv - vw;
        if (gap <= tol * sqrt(vv)) { r->capped = 0; break; }
        int duplicate = 0;
        for (int i = 0; i < s->n; ++i)
            if (s->v[i].ia == w.ia && s->v[i].ib == w.ib) duplicate = 1;
        if (duplicate) { r->capped = 0; break; }
        Simplex backup = *s;
        s->v[s->n++] = w;
        if (s->n == 2) solve2(s);
        else if (s->n == 3) solve3(s);
        else if (solve4(s)) { v = gc_v3(0, 0, 0); r->overlap = 1; r->capped = 0; break; }
        gcVec3 v_new = simplex_closest(s);
        if (!(gc_dot(v_new, v_new) < vv)) { *s = backup; r->capped = 0; break; } /* no progress: rounding */
        v = v_new;
    }
    r->v = v;
    r->distance = gc_len(v);
    if (r->distance <= tol) r->overlap = 1;
    r->iterations = it;
}

/* ---------------------------------------------------------------------- EPA */

typedef struct EpaFace {
    int v[3];    /* CCW from outside */
    int nb[3];   /* face across edge v[i] -> v[i+1] */
    gcVec3 n;
    int mark;
} EpaFace;

typedef struct Polytope {
    SVert v[EPA_MAX_VERTICES];
    int nv;
    EpaFace f[EPA_MAX_FACES];
    double d[EPA_MAX_FACES];  /* plane distance from the origin; DBL_MAX for dead slots */
    int nf;                   /* slots used so far */
    int free_slot[EPA_MAX_FACES], num_free;
    int horizon_of[EPA_MAX_VERTICES];
} Polytope;

static int epa_new_face(Polytope *P, int a, int b, int c) {
    gcVec3 pa = P->v[a].w, pb = P->v[b].w, pc = P->v[c].w;
    gcVec3 n = gc_cross(gc_sub(pb, pa), gc_sub(pc, pa));
    double len = gc_len(n);
    if (!(len > 0.0)) return -1;
    int slot;
    if (P->num_free > 0) slot = P->free_slot[--P->num_free];
    else if (P->nf < EPA_MAX_FACES) slot = P->nf++;
    else return -1;
    EpaFace *f = &P->f[slot];
    f->v[0] = a; f->v[1] = b; f->v[2] = c;
    f->nb[0] = f->nb[1] = f->nb[2] = -1;
    f->mark = -1;
    f->n = gc_scale(n, 1.0 / len);
    P->d[slot] = (gc_dot(f->n, pa) + gc_dot(f->n, pb) + gc_dot(f->n, pc)) / 3.0;
    return slot;
}

static int epa_edge(const EpaFace *f, int a, int b) {
    for (int i = 0; i < 3; ++i)
        if (f->v[i] == a && f->v[(i + 1) % 3] == b) return i;
    return -1;
}

/* Grows GJK's final simplex into a tetrahedron around (or touching) the origin. */
static int epa_init(Pair *q, const Simplex *s, Polytope *P, double tol) {
    SVert p[4];
    int n = s->n;
    for (int i = 0; i < n; ++i) p[i] = s->v[i];
    if (n == 4) {
        double vol = gc_dot(gc_sub(p[1].w, p[0].w), gc_cross(gc_sub(p[2].w, p[0].w), gc_sub(p[3].w, p[0].w)));
        if (!(fabs(vol) > tol * tol * tol)) n = 3;
    }
    if (n == 3 && !(gc_len(gc_cross(gc_sub(p[1].w, p[0].w), gc_sub(p[2].w, p[0].w))) > tol * tol)) n = 2;
    if (n == 2 && !(gc_len(gc_sub(p[1].w, p[0].w)) > tol)) n = 1;
    if (n == 1) {
        static const double axes[6][3] = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
        double best = tol;
        int found = 0;
        for (int k = 0; k < 6; ++k) {
            SVert w = pair_support(q, gc_v3(axes[k][0], axes[k][1], axes[k][2]));
            double d = gc_len(gc_sub(w.w, p[0].w));
            if (d > best) { best = d; p[1] = w; found = 1; }
        }
        if (!found) return 0;
        n = 2;
    }
    if (n == 2) {
        gcVec3 u = gc_normalize(gc_sub(p[1].w, p[0].w));
        gcVec3 e1 = any_perpendicular(u), e2 = gc_cross(u, e1);
        double best = tol;
        int found = 0;
        for (int k = 0; k < 6; ++k) {
            double ang = k * (3.14159265358979323846 / 3.0);
            SVert w = pair_support(q, gc_add(gc_scale(e1, cos(ang)), gc_scale(e2, sin(ang))));
            double d = gc_len(gc_cross(gc_sub(w.w, p[0].w), u));
            if (d > best) { best = d; p[2] = w; found = 1; }
        }
        if (!found) return 0;
        n = 3;
    }
    if (n == 3) {
        gcVec3 nrm = gc_normalize(gc_cross(gc_sub(p[1].w, p[0].w), gc_sub(p[2].w, p[0].w)));
        SVert up = pair_support(q, nrm), down = pair_support(q, gc_neg(nrm));
        double hu = gc_dot(gc_sub(up.w, p[0].w), nrm), hd = -gc_dot(gc_sub(down.w, p[0].w), nrm);
        if (!(fmax(hu, hd) > tol)) return 0;
        p[3] = hu >= hd ? up : down;
    }
    /* Orient so that p3 lies below face (p0, p1, p2). */
    double vol = gc_dot(gc_sub(p[1].w, p[0].w), gc_cross(gc_sub(p[2].w, p[0].w), gc_sub(p[3].w, p[0].w)));
    if (vol > 0.0) { SVert t = p[1]; p[1] = p[2]; p[2] = t; }
    P->nv = 4;
    P->nf = 0;
    P->num_free = 0;
    for (int i = 0; i < 4; ++i) {
        P->v[i] = p[i];
        P->horizon_of[i] = -1;
    }
    static const int tet[4][3] = {{0, 1, 2}, {0, 3, 1}, {1, 3, 2}, {2, 3, 0}};
    /* tet_nb[f][e]: the face holding edge tet[f][e+1] -> tet[f][e] (fixed topology). */
    static const int tet_nb[4][3] = {{1, 2, 3}, {3, 2, 0}, {1, 3, 0}, {2, 1, 0}};
    for (int f = 0; f < 4; ++f)
        if (epa_new_face(P, tet[f][0], tet[f][1], tet[f][2]) != f) return 0;
    for (int f = 0; f < 4; ++f)
        for (int e = 0; e < 3; ++e) P->f[f].nb[e] = tet_nb[f][e];
    return 1;
}

/* Adds vertex w seen from face f0. Returns 0 when the visible region is not a
 * clean disc or capacity is exhausted (the polytope is then left unchanged). */
static int epa_expand(Polytope *P, int f0, SVert w, int stamp, double tol_visible) {
    if (P->nv >= EPA_MAX_VERTICES) return 0;
    int visible[EPA_MAX_FACES], num_visible = 0;
    int ha[EPA_MAX_FACES], hb[EPA_MAX_FACES], hout[EPA_MAX_FACES], hnew[EPA_MAX_FACES];
    int nh = 0, ok = 1;
    /* Flood the visible region from f0 (keeps it connected); horizon edges are
     * the visible faces' edges towards non-visible neighbours. */
    P->f[f0].mark = stamp;
    visible[num_visible++] = f0;
    for (int k = 0; k < num_visible; ++k) {
        EpaFace *f = &P->f[visible[k]];
        for (int e = 0; e < 3; ++e) {
            int g = f->nb[e];
            if (P->f[g].mark == stamp) continue;
            if (gc_dot(P->f[g].n, w.w) - P->d[g] > tol_visible) {
                P->f[g].mark = stamp;
                visible[num_visible++] = g;
            }
        }
    }
    for (int k = 0; k < num_visible && ok; ++k) {
        EpaFace *f = &P->f[visible[k]];
        for (int e = 0; e < 3; ++e) {
            int g = f->nb[e];
            if (P->f[g].mark == stamp) continue;
            if (nh >= EPA_MAX_FACES) { ok = 0; break; }
            ha[nh] = f->v[e];
            hb[nh] = f->v[(e + 1) % 3];
            hout[nh] = g;
            ++nh;
        }
    }
    /* One simple loop, or nothing changes. */
    for (int h = 0; h < nh && ok; ++h) {
        if (P->horizon_of[ha[h]] != -1) ok = 0;
        else P->horizon_of[ha[h]] = h;
    }
    if (ok && nh >= 3) { /* walk the loop from horizon edge 0 */
        int h = 0, steps = 0;
        do {
            h = P->horizon_of[hb[h]];
            ++steps;
        } while (h > 0 && steps <= nh);
        ok = h == 0 && steps == nh;
    } else {
        ok = 0;
    }
    /* Room for the new faces (the visible ones are recycled), non-degenerate ones. */
    if (P->num_free + (EPA_MAX_FACES - P->nf) + num_visible < nh) ok = 0;
    for (int h = 0; h < nh && ok; ++h) {
        gcVec3 a = P->v[ha[h]].w, b = P->v[hb[h]].w;
        if (!(gc_len2(gc_cross(gc_sub(b, a), gc_sub(w.w, a))) > 0.0)) ok = 0;
    }
    if (!ok) {
        for (int h = 0; h < nh; ++h)
            if (P->horizon_of[ha[h]] == h) P->horizon_of[ha[h]] = -1;
        for (int k = 0; k < num_visible; ++k) P->f[visible[k]].mark = -1;
        return 0;
    }
    for (int k = 0; k < num_visible; ++k) {
        P->d[visible[k]] = DBL_MAX;
        P->free_slot[P->num_free++] = visible[k];
    }
    int wi = P->nv++;
    P->v[wi] = w;
    P->horizon_of[wi] = -1;
    for (int h = 0; h < nh; ++h) {
        hnew[h] = epa_new_face(P, ha[h], hb[h], wi);
        if (hnew[h] < 0) return -1; /* cannot happen after the checks above */
    }
    for (int h = 0; h < nh; ++h) {
        EpaFace *f = &P->f[hnew[h]];
        EpaFace *out = &P->f[hout[h]];
        f->nb[0] = hout[h];
        out->nb[epa_edge(out, hb[h], ha[h])] = hnew[h];
        int next = P->horizon_of[hb[h]];
        f->nb[1] = hnew[next];
        P->f[hnew[next]].nb[2] = hnew[h];
    }
    for (int h = 0; h < nh; ++h) P->horizon_of[ha[h]] = -1;
    return 1;
}

typedef struct EpaResult {
    double depth;       /* of the cores, >= -tol */
    gcVec3 normal;      /* A's frame, from A towards B */
    gcVec3 pa, pb;      /* A's frame */
    int iterations;
    int capped;         /* iteration cap hit */
    int ok;             /* 0: could not run, caller must fall back */
} EpaResult;

static void epa(Pair *q, const Simplex *s, double tol, EpaResult *r) {
    Polytope P;
    r->ok = 0;
    r->capped = 0;
    r->iterations = 0;
    if (!epa_init(q, s, &P, tol)) return;
    double tol_visible = 1e-3 * tol;
    double best_upper = DBL_MAX;
    gcVec3 upper_n = gc_v3(0, 0, 1);
    SVert upper_w;
    memset(&upper_w, 0, sizeof(upper_w));
    int face = -1, converged = 0, it = 0;
    while (it < GC_EPA_MAX_ITERATIONS) {
        ++it;
        face = -1;
        double dmin = DBL_MAX;
        for (int i = 0; i < P.nf; ++i)
            if (P.d[i] < dmin) { dmin = P.d[i]; face = i; }
        if (face < 0) break;
        gcVec3 n = P.f[face].n;
        SVert w = pair_support(q, n);
        double upper = gc_dot(w.w, n);
        if (upper < best_upper) { best_upper = upper; upper_n = n; upper_w = w; }
        if (upper - dmin <= tol) { converged = 1; break; }
        if (epa_expand(&P, face, w, it, tol_visible) != 1) break;
    }
    r->iterations = it;
    if (!converged && it >= GC_EPA_MAX_ITERATIONS) r->capped = 1;
    if (converged && face >= 0) {
        EpaFace *f = &P.f[face];
        Simplex t;
        for (int k = 0; k < 3; ++k) t.v[k] = P.v[f->v[k]];
        t.n = 3;
        solve3(&t);
        simplex_witness(&t, &r->pa, &r->pb);
        r->depth = P.d[face];
        r->normal = f->n;
        r->ok = 1;
        return;
    }
    if (best_upper < DBL_MAX) {
        /* Not converged: the smallest support value seen is a translation that
         * certainly separates the cores; prefer over-pushing to under-pushing. */
        r->depth = best_upper;
        r->normal = upper_n;
        r->pa = upper_w.a;
        r->pb = gc_madd(upper_w.a, upper_n, -best_upper);
        r->ok = 2;
    }
}

/* Separating-axis fallback over both hulls' face normals: an upper bound on the
 * penetration depth that always separates. Directions in A's frame. */
static void sat_fallback(Pair *q, EpaResult *r) {
    double best = r->ok ? r->depth : DBL_MAX;
    gcVec3 best_n = r->ok ? r->normal : gc_v3(0, 0, 1);
    for (int side = 0; side < 2; ++side) {
        const gcHull *h = side == 0 ? q->a : q->b;
        int count = h->num_planes;
        for (int i = -3; i < count; ++i) {
            gcVec3 n;
            if (i < 0) n = gc_v3(i == -3, i == -2, i == -1); /* axes: shapes without faces */
            else n = side == 0 ? h->plane_normals[i] : gc_neg(gc_mat3_mul_vec(&q->R, h->plane_normals[i]));
            for (int sign = 0; sign < (i < 0 ? 2 : 1); ++sign) {
                gcVec3 m = sign ? gc_neg(n) : n;
                double depth = gc_dot(pair_support(q, m).w, m);
                if (depth < best) { best = depth; best_n = m; }
            }
        }
    }
    SVert w = pair_support(q, best_n);
    r->depth = best;
    r->normal = best_n;
    r->pa = w.a;
    r->pb = gc_madd(w.a, best_n, -best);
    r->ok = 2;
}

/* ------------------------------------------------------- closed-form shapes */

/* Closest points between segments p1-q1 and p2-q2 (either may be a point).
 * Ericson, RTCD 5.1.9. */
static void segment_segment(gcVec3 p1, gcVec3 q1, gcVec3 p2, gcVec3 q2, gcVec3 *c1, gcVec3 *c2) {
    gcVec3 d1 = gc_sub(q1, p1), d2 = gc_sub(q2, p2), r = gc_sub(p1, p2);
    double a = gc_dot(d1, d1), e = gc_dot(d2, d2), f = gc_dot(d2, r);
    double s, t;
    if (a <= 0.0 && e <= 0.0) {
        s = t = 0.0;
    } else if (a <= 0.0) {
        s = 0.0;
        t = fmin(fmax(f / e, 0.0), 1.0);
    } else {
        double c = gc_dot(d1, r);
        if (e <= 0.0) {
            t = 0.0;
            s = fmin(fmax(-c / a, 0.0), 1.0);
        } else {
            double b = gc_dot(d1, d2), denom = a * e - b * b;
            s = denom > 0.0 ? fmin(fmax((b * f - c * e) / denom, 0.0), 1.0) : 0.0;
            t = (b * s + f) / e;
            if (t < 0.0) {
                t = 0.0;
                s = fmin(fmax(-c / a, 0.0), 1.0);
            } else if (t > 1.0) {
                t = 1.0;
                s = fmin(fmax((b - c) / a, 0.0), 1.0);
            }
        }
    }
    *c1 = gc_madd(p1, d1, s);
    *c2 = gc_madd(p2, d2, t);
}

/* Sphere/capsule pairs (world frame). */
static gcStatus collide_rounded(const gcHull *a, const gcTransform *ta, const gcHull *b,
                                const gcTransform *tb, gcContact *out) {
    gcVec3 p1 = gc_transform_point(ta, a->vertices[0]);
    gcVec3 q1 = gc_transform_point(ta, a->vertices[a->num_vertices - 1]);
    gcVec3 p2 = gc_transform_point(tb, b->vertices[0]);
    gcVec3 q2 = gc_transform_point(tb, b->vertices[b->num_vertices - 1]);
    gcVec3 c1, c2;
    segment_segment(p1, q1, p2, q2, &c1, &c2);
    gcVec3 delta = gc_sub(c2, c1);
    double dist = gc_len(delta);
    double size = gc_len(gc_sub(q1, p1)) + gc_len(gc_sub(q2, p2)) + a->radius + b->radius;
    gcVec3 n;
    if (dist > 1e-12 * size) {
        n = gc_scale(delta, 1.0 / dist);
    } else {
        /* Cores cross: the separating direction is perpendicular to both axes,
         * oriented by the centres (deterministic when those coincide too). */
        gcVec3 centre = gc_sub(gc_scale(gc_add(p2, q2), 0.5), gc_scale(gc_add(p1, q1), 0.5));
        gcVec3 d1 = gc_normalize(gc_sub(q1, p1)), d2 = gc_normalize(gc_sub(q2, p2));
        gcVec3 axis = gc_len2(d1) > 0.0 ? d1 : d2;
        n = gc_cross(d1, d2);
        if (!(gc_len(n) > 1e-9)) {
            n = gc_len2(axis) > 0.0 ? gc_sub(centre, gc_scale(axis, gc_dot(centre, axis))) : centre;
            if (!(gc_len(n) > 1e-12 * size)) n = gc_len2(axis) > 0.0 ? any_perpendicular(axis) : gc_v3(0, 0, 1);
        }
        n = gc_normalize(n);
        if (gc_dot(n, centre) < 0.0) n = gc_neg(n);
        dist = 0.0;
    }
    out->normal = n;
    out->distance = dist - a->radius - b->radius;
    out->point_a = gc_madd(c1, n, a->radius);
    out->point_b = gc_madd(c2, n, -b->radius);
    out->iterations = 0;
    return GC_OK;
}

/* ---------------------------------------------------------------- queries */

gcStatus gc_gjk_distance(const gcHull *a, const gcTransform *ta, const gcHull *b,
                         const gcTransform *tb, double *distance, gcVec3 *point_a, gcVec3 *point_b) {
    if (!hull_ok(a) || !hull_ok(b) || !ta || !tb || !transform_ok(ta) || !transform_ok(tb))
        return GC_ERR_INVALID_ARGUMENT;
    Pair q;
    Simplex s;
    GjkResult r;
    pair_init(&q, a, ta, b, tb);
    double tol = GJK_REL_TOL * (hull_size(a) + hull_size(b)) + 4.0 * DBL_EPSILON * gc_len(q.p);
    gjk(&q, &s, tol, -1.0, &r);
    gcVec3 pa, pb;
    simplex_witness(&s, &pa, &pb);
    if (r.overlap) pb = pa;
    if (distance) *distance = r.overlap ? 0.0 : gc_len(gc_sub(pa, pb));
    if (point_a) *point_a = gc_transform_point(ta, pa);
    if (point_b) *point_b = gc_transform_point(ta, pb);
    return r.capped ? GC_WARN_MAX_ITERATIONS : GC_OK;
}

/* Point against a bare core via GJK; returns the closest core point. */
static int core_closest_point(const gcHull *h, gcVec3 p, gcVec3 *closest) {
    gcHull point;
    memset(&point, 0, sizeof(point));
    point.num_vertices = 1;
    point.vertices = &p;
    point.aabb_min = point.aabb_max = p;
    Pair q;
    q.a = h;
    q.b = &point;
    q.R = gc_mat3_identity();
    q.p = gc_v3(0, 0, 0);
    q.ia = q.ib = 0;
    Simplex s;
    GjkResult r;
    gjk(&q, &s, GJK_REL_TOL * hull_size(h) + 4.0 * DBL_EPSILON * gc_len(p), -1.0, &r);
    gcVec3 pb;
    simplex_witness(&s, closest, &pb);
    return r.capped;
}

/* Whether p, outside the plane of face `face` by s, projects onto the face itself: the
 * projection is then inside every other face plane, and so (the hull lies in the face's
 * half-space) the closest point of the hull. */
static int projects_into_face(const gcHull *h, gcVec3 p, int face, double s) {
    gcVec3 q = gc_madd(p, h->plane_normals[face], -s);
    for (int i = 0; i < h->num_planes; ++i)
        if (i != face && gc_dot(h->plane_normals[i], q) - h->plane_offsets[i] > 0.0) return 0;
    return 1;
}

gcStatus gc_point_query(const gcHull *hull, gcVec3 p, double *signed_distance,
                        gcVec3 *surface_point, gcVec3 *normal) {
    if (!hull_ok(hull) || !gc_vec_finite(p)) return GC_ERR_INVALID_ARGUMENT;
    double r = hull->radius;
    double size = hull_size(hull) + r;
    gcVec3 core, n;
    double core_dist;
    int capped = 0;
    if (hull->num_vertices <= 2) {
        gcVec3 a = hull->vertices[0], b = hull->vertices[hull->num_vertices - 1];
        gcVec3 ab = gc_sub(b, a);
        double dd = gc_dot(ab, ab);
        double t = dd > 0.0 ? fmin(fmax(gc_dot(gc_sub(p, a), ab) / dd, 0.0), 1.0) : 0.0;
        core = gc_madd(a, ab, t);
        gcVec3 delta = gc_sub(p, core);
        core_dist = gc_len(delta);
        if (core_dist > 1e-12 * size) n = gc_scale(delta, 1.0 / core_dist);
        else n = dd > 0.0 ? any_perpendicular(gc_scale(ab, 1.0 / sqrt(dd))) : gc_v3(0, 0, 1);
    } else {
        /* Least-penetrated face plane: exact signed distance when inside. */
        int best = 0;
        double best_s = -DBL_MAX;
        for (int i = 0; i < hull->num_planes; ++i) {
            double s = gc_dot(hull->plane_normals[i], p) - hull->plane_offsets[i];
            if (s > best_s) { best_s = s; best = i; }
        }
        n = hull->plane_normals[best];
        if (best_s <= 0.0) {
            core_dist = best_s;
            core = gc_madd(p, n, -best_s);
        } else if (projects_into_face(hull, p, best, best_s)) {
            /* Outside the one face's plane only, over the face: the closest point is the
             * projection (a sphere finger resting on a face needs no GJK). */
            core_dist = best_s;
            core = gc_madd(p, n, -best_s);
        } else {
            capped = core_closest_point(hull, p, &core);
            gcVec3 delta = gc_sub(p, core);
            core_dist = gc_len(delta);
            /* On the surface within rounding: the face normal is the stable choice. */
            if (core_dist > 1e-12 * size) n = gc_scale(delta, 1.0 / core_dist);
        }
    }
    if (signed_distance) *signed_distance = core_dist - r;
    if (surface_point) *surface_point = gc_madd(core, n, r);
    if (normal) *normal = n;
    return capped ? GC_WARN_MAX_ITERATIONS : GC_OK;
}

/* A is a sphere: query its centre against B (or the reverse when flip). */
static gcStatus collide_sphere(const gcHull *sphere, const gcTransform *ts, const gcHull *other,
                               const gcTransform *to, int sphere_is_b, gcContact *out) {
    gcVec3 centre = gc_transform_point(ts, sphere->vertices[0]);
    double sd;
    gcVec3 sp, n;
    gcStatus st = gc_point_query(other, gc_inv_transform_point(to, centre), &sd, &sp, &n);
    if (st < 0) return st;
    gcVec3 nw = gc_mat3_mul_vec(&to->R, n); /* outward from `other`, towards the sphere */
    gcVec3 spw = gc_transform_point(to, sp);
    gcVec3 on_sphere = gc_madd(centre, nw, -sphere->radius);
    out->distance = sd - sphere->radius;
    out->iterations = 0;
    if (sphere_is_b) {
        out->normal = nw;
        out->point_a = spw;
        out->point_b = on_sphere;
    } else {
        out->normal = gc_neg(nw);
        out->point_a = on_sphere;
        out->point_b = spw;
    }
    return st;
}

/* Hull pairs (neither is a sphere; not both rounded segments). early: stop GJK on
 * the first separating axis (gc_penetration); *separated is then set when it did. */
static gcStatus collide_hulls(const gcHull *a, const gcTransform *ta, const gcHull *b,
                              const gcTransform *tb, int early, gcContact *out, int *separated) {
    Pair q;
    Simplex s;
    GjkResult g;
    pair_init(&q, a, ta, b, tb);
    double size = hull_size(a) + hull_size(b);
    double tol = GJK_REL_TOL * size + 4.0 * DBL_EPSILON * gc_len(q.p);
    /* Early exit only when the lower bound clears the radii by the GJK tolerance:
     * gc_collide would then certainly report a positive distance too. */
    gjk(&q, &s, tol, early ? a->radius + b->radius + tol : -1.0, &g);
    gcStatus status = g.capped ? GC_WARN_MAX_ITERATIONS : GC_OK;
    gcVec3 n, pa, pb;
    double core_dist;
    int iterations = g.iterations;
    *separated = 0;
    if (g.separated) {
        double len = gc_len(g.v);
        n = gc_scale(g.v, -1.0 / len);
        pa = g.sep_w.a;
        pb = g.sep_w.b;
        core_dist = gc_dot(g.v, g.sep_w.w) / len;
        *separated = 1;
    } else if (!g.overlap) {
        simplex_witness(&s, &pa, &pb);
        gcVec3 delta = gc_sub(pb, pa);
        core_dist = gc_len(delta);
        /* The normal from GJK's closest point v (computed directly, e.g. as the
         * triangle's normal): accurate even when the gap is a hairline and pb - pa
         * is mostly rounding of the witness points. */
        double vlen = gc_len(g.v);
        n = vlen > 0.0 ? gc_scale(g.v, -1.0 / vlen) : gc_scale(delta, 1.0 / core_dist);
    } else {
        EpaResult e;
        epa(&q, &s, EPA_REL_TOL * size + 4.0 * DBL_EPSILON * gc_len(q.p), &e);
        iterations += e.iterations;
        if (e.ok != 1) {
            sat_fallback(&q, &e);
            status = GC_WARN_MAX_ITERATIONS;
        }
        n = e.normal;
        pa = e.pa;
        pb = e.pb;
        core_dist = -e.depth;
    }
    n = gc_mat3_mul_vec(&ta->R, n);
    pa = gc_transform_point(ta, pa);
    pb = gc_transform_point(ta, pb);
    if (!(gc_vec_finite(n) && gc_vec_finite(pa) && gc_vec_finite(pb) && isfinite(core_dist))) {
        /* Cannot happen with finite inputs; keep the promise of never returning NaN. */
        n = gc_v3(0, 0, 1);
        pa = pb = ta->p;
        core_dist = 0.0;
        status = GC_WARN_MAX_ITERATIONS;
        *separated = 0;
    }
    out->normal = n;
    out->distance = core_dist - a->radius - b->radius;
    out->point_a = gc_madd(pa, n, a->radius);
    out->point_b = gc_madd(pb, n, -b->radius);
    out->iterations = iterations;
    if (out->distance > 0.0) *separated = 1;
    return status;
}

static gcStatus collide_dispatch(const gcHull *a, const gcTransform *ta, const gcHull *b,
                                 const gcTransform *tb, int early, gcContact *out, int *separated) {
    if (!out || !hull_ok(a) || !hull_ok(b) || !ta || !tb || !transform_ok(ta) || !transform_ok(tb))
        return GC_ERR_INVALID_ARGUMENT;
    gcStatus st;
    if (a->num_vertices <= 2 && b->num_vertices <= 2) st = collide_rounded(a, ta, b, tb, out);
    else if (a->num_vertices == 1) st = collide_sphere(a, ta, b, tb, 0, out);
    else if (b->num_vertices == 1) st = collide_sphere(b, tb, a, ta, 1, out);
    else return collide_hulls(a, ta, b, tb, early, out, separated);
    if (st >= 0) *separated = out->distance > 0.0;
    return st;
}

gcStatus gc_collide(const gcHull *a, const gcTransform *ta, const gcHull *b,
                    const gcTransform *tb, gcContact *out) {
    int separated;
    return collide_dispatch(a, ta, b, tb, 0, out, &separated);
}

gcStatus gc_penetration(const gcHull *a, const gcTransform *ta, const gcHull *b,
                        const gcTransform *tb, gcContact *out, int *separated) {
    if (!separated) return GC_ERR_INVALID_ARGUMENT;
    *separated = 0;
    return collide_dispatch(a, ta, b, tb, 1, out, separated);
}
