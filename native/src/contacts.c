/* Body-body contacts and the contact solver (docs/solver.md).
 *
 * Per step, between the velocity phase (gravity and the implicit finger springs, which
 * leave each body's effective-mass factor) and the position phase:
 *
 *  1. Broad phase: sort-and-sweep on the body AABBs (x axis; the order is kept between
 *     steps, so the insertion sort is near linear), then the parts' AABBs of each body
 *     pair. Candidate part pairs are sorted by key = part_a * max_parts + part_b.
 *  2. Narrow phase (in parallel, one output slot per candidate): gc_collide (GJK/EPA) gives
 *     the normal; when a face of either polytope lies along it, the incident face of the
 *     other is clipped against the reference face's side planes (Sutherland-Hodgman) and
 *     reduced to at most 4 points; otherwise the single GJK/EPA point is used. Points are
 *     matched to last step's manifold of the same pair by proximity in either body's frame
 *     and inherit its impulses (warm start) and its friction state and anchors.
 *  3. Chains (islands.c): union-find over dynamic bodies linked by manifolds.
 *  4. Solver, per chain (in parallel; a chain's result depends only on its own data):
 *     sequential impulses with the 6x6 effective masses; warm started; Coulomb friction as
 *     a 2x2 block per point projected on the true (circular) cone; static friction through
 *     friction anchors (no creep); then a split-impulse position pass that removes
 *     penetration beyond the slop without adding kinetic energy.
 *
 * Nothing here allocates after gc_contacts_create. */
#define _POSIX_C_SOURCE 200809L
#include "contacts.h"

#include <float.h>
#include <stdlib.h>
#include <string.h>

/* ------------------------------------------------------------------ lifetime */


gcStatus gc_contacts_create(gcWorld *w) {
    int threads = w->def.threads, cap = w->def.max_contacts;
    if (threads == 0) threads = 1;
    if (cap == 0) cap = GC_DEFAULT_MAX_CONTACTS;
    w->def.threads = threads;
    w->def.max_contacts = cap;
    struct gcContactSystem *cs = calloc(1, sizeof *cs);
    if (!cs) return GC_ERR_NO_MEMORY;
    w->contacts = cs;
    size_t nb = (size_t)w->def.max_bodies, np = (size_t)w->def.max_parts, nc = (size_t)cap;
    cs->capacity = cap;
    cs->manifolds = calloc(nc, sizeof *cs->manifolds);
    cs->previous = calloc(nc, sizeof *cs->previous);
    cs->candidates = calloc(nc, sizeof *cs->candidates);
    cs->candidates_scratch = calloc(nc, sizeof *cs->candidates_scratch);
    cs->sorted_bodies = calloc(nb, sizeof *cs->sorted_bodies);
    cs->part_min = calloc(np, sizeof *cs->part_min);
    cs->part_max = calloc(np, sizeof *cs->part_max);
    cs->parent = calloc(nb, sizeof *cs->parent);
    cs->body_chain = calloc(nb, sizeof *cs->body_chain);
    cs->chain_body_start = calloc(nb + 1, sizeof *cs->chain_body_start);
    cs->chain_bodies = calloc(nb, sizeof *cs->chain_bodies);
    cs->chain_manifold_start = calloc(nb + 1, sizeof *cs->chain_manifold_start);
    cs->chain_manifolds = calloc(nc, sizeof *cs->chain_manifolds);
    cs->cursor = calloc(nb + 1, sizeof *cs->cursor);
    cs->pseudo_v = calloc(nb, sizeof *cs->pseudo_v);
    cs->pseudo_w = calloc(nb, sizeof *cs->pseudo_w);
    cs->inv_mass = calloc(nb, sizeof *cs->inv_mass);
    cs->scratch = calloc((size_t)cs->capacity * GC_MANIFOLD_MAX_POINTS, sizeof *cs->scratch);
    if (!cs->inv_mass || !cs->scratch || !cs->manifolds || !cs->previous || !cs->candidates ||
        !cs->candidates_scratch || !cs->sorted_bodies || !cs->part_min ||
        !cs->part_max || !cs->parent || !cs->body_chain || !cs->chain_body_start || !cs->chain_bodies ||
        !cs->chain_manifold_start || !cs->chain_manifolds || !cs->cursor || !cs->pseudo_v || !cs->pseudo_w)
        return GC_ERR_NO_MEMORY; /* the caller destroys the world, which frees what was made */
    gcStatus st = gc_pool_create(threads, &cs->pool);
    if (st != GC_OK) return st;
    return GC_OK;
}

void gc_contacts_destroy(gcWorld *w) {
    struct gcContactSystem *cs = w->contacts;
    if (!cs) return;
    gc_pool_destroy(cs->pool);
    free(cs->manifolds);
    free(cs->previous);
    free(cs->candidates);
    free(cs->candidates_scratch);
    free(cs->sorted_bodies);
    free(cs->part_min);
    free(cs->part_max);
    free(cs->parent);
    free(cs->body_chain);
    free(cs->chain_body_start);
    free(cs->chain_bodies);
    free(cs->chain_manifold_start);
    free(cs->chain_manifolds);
    free(cs->cursor);
    free(cs->pseudo_v);
    free(cs->pseudo_w);
    free(cs->inv_mass);
    free(cs->scratch);
    free(cs);
    w->contacts = NULL;
}

/* ------------------------------------------------------------------ helpers */

/* Unit tangents t1, t2 with (n, t1, t2) right-handed; a fixed function of n. */
static void tangent_basis(gcVec3 n, gcVec3 *t1, gcVec3 *t2) {
    gcVec3 a = fabs(n.x) < 0.57735 ? gc_v3(1, 0, 0) : (fabs(n.y) < 0.57735 ? gc_v3(0, 1, 0) : gc_v3(0, 0, 1));
    *t1 = gc_normalize(gc_cross(n, a));
    *t2 = gc_cross(n, *t1);
}

static double hull_extent(const gcHull *h) { return gc_len(gc_sub(h->aabb_max, h->aabb_min)) + 2.0 * h->radius; }

/* ------------------------------------------------------------------ broad phase */

static void update_part_aabbs(gcWorld *w) {
    struct gcContactSystem *cs = w->contacts;
    const double h = 0.5 * GC_CONTACT_MARGIN;
    for (int32_t bi = 0; bi < w->num_bodies; ++bi) {
        const gcBody *b = &w->bodies[bi];
        gcTransform t = gc_body_transform(b);
        for (int p = b->first_part; p < b->first_part + b->num_parts; ++p) {
            const gcHull *hull = &w->parts[p].hull;
            if (b->num_parts == 1) {
                cs->part_min[p] = gc_sub(b->aabb_min, gc_v3(h, h, h));
                cs->part_max[p] = gc_add(b->aabb_max, gc_v3(h, h, h));
                continue;
            }
            /* Centre/extent form: |R| e bounds the rotated box. */
            gcVec3 c = gc_scale(gc_add(hull->aabb_min, hull->aabb_max), 0.5);
            gcVec3 e = gc_scale(gc_sub(hull->aabb_max, hull->aabb_min), 0.5);
            gcVec3 wc = gc_transform_point(&t, c);
            double ex[3];
            for (int i = 0; i < 3; ++i)
                ex[i] = fabs(t.R.m[i][0]) * e.x + fabs(t.R.m[i][1]) * e.y + fabs(t.R.m[i][2]) * e.z + hull->radius + h;
            cs->part_min[p] = gc_v3(wc.x - ex[0], wc.y - ex[1], wc.z - ex[2]);
            cs->part_max[p] = gc_v3(wc.x + ex[0], wc.y + ex[1], wc.z + ex[2]);
        }
    }
}

static int body_before(const gcWorld *w, int32_t a, int32_t b) {
    double xa = w->bodies[a].aabb_min.x, xb = w->bodies[b].aabb_min.x;
    return xa < xb || (xa == xb && a < b);
}

/* Candidates in key order (the previous step's manifolds are matched by merging): LSD
 * radix sort on the key's bytes, up to the bytes max_parts^2 needs (3 for 4096 parts).
 * glibc's qsort with a comparison callback cost ~10% of a 100-body pile's step. */
static void sort_candidates(struct gcContactSystem *cs, int64_t max_key) {
    int n = cs->num_candidates;
    gcCandidate *src = cs->candidates, *dst = cs->candidates_scratch;
    int passes = 0;
    for (int64_t k = max_key; k > 0; k >>= 8) ++passes;
    for (int pass = 0; pass < passes; ++pass) {
        int shift = 8 * pass, count[257] = {0};
        for (int i = 0; i < n; ++i) count[((src[i].key >> shift) & 0xff) + 1]++;
        for (int d = 0; d < 256; ++d) count[d + 1] += count[d];
        for (int i = 0; i < n; ++i) dst[count[(src[i].key >> shift) & 0xff]++] = src[i];
        gcCandidate *t = src;
        src = dst;
        dst = t;
    }
    if (src != cs->candidates) memcpy(cs->candidates, src, (size_t)n * sizeof *src);
}

static void broad_phase(gcWorld *w) {
    struct gcContactSystem *cs = w->contacts;
    update_part_aabbs(w);
    /* Keep last step's order; append new bodies; insertion sort (near linear when sorted). */
    for (int32_t i = cs->num_sorted; i < w->num_bodies; ++i) cs->sorted_bodies[i] = i;
    cs->num_sorted = w->num_bodies;
    int32_t *s = cs->sorted_bodies;
    for (int i = 1; i < cs->num_sorted; ++i) {
        int32_t v = s[i];
        int j = i - 1;
        while (j >= 0 && body_before(w, v, s[j])) {
            s[j + 1] = s[j];
            --j;
        }
        s[j + 1] = v;
    }
    const double h = 0.5 * GC_CONTACT_MARGIN;
    gcVec3 hv = gc_v3(h, h, h);
    int64_t max_parts = w->def.max_parts;
    cs->num_candidates = 0;
    for (int i = 0; i < cs->num_sorted; ++i) {
        const gcBody *A = &w->bodies[s[i]];
        double hi_x = A->aabb_max.x + 2.0 * h;
        gcVec3 amin = gc_sub(A->aabb_min, hv), amax = gc_add(A->aabb_max, hv);
        for (int j = i + 1; j < cs->num_sorted; ++j) {
            const gcBody *B = &w->bodies[s[j]];
            if (B->aabb_min.x > hi_x) break;
            if (A->is_static && B->is_static) continue;
            if (!gc_aabb_overlap(amin, amax, gc_sub(B->aabb_min, hv), gc_add(B->aabb_max, hv))) continue;
            int32_t lo = s[i] < s[j] ? s[i] : s[j], hi = s[i] < s[j] ? s[j] : s[i];
            const gcBody *L = &w->bodies[lo], *H = &w->bodies[hi];
            for (int pa = L->first_part; pa < L->first_part + L->num_parts; ++pa) {
                for (int pb = H->first_part; pb < H->first_part + H->num_parts; ++pb) {
                    if (!gc_aabb_overlap(cs->part_min[pa], cs->part_max[pa], cs->part_min[pb], cs->part_max[pb]))
                        continue;
                    if (cs->num_candidates >= cs->capacity) {
                        cs->overflow++;
                        continue;
                    }
                    gcCandidate *c = &cs->candidates[cs->num_candidates++];
                    c->part_a = pa;
                    c->part_b = pb;
                    c->key = (int64_t)pa * max_parts + pb;
                }
            }
        }
    }
    sort_candidates(cs, max_parts * max_parts - 1);
}

/* ------------------------------------------------------------------ manifolds */

#define GC_MAX_POLY 64
#define GC_MAX_CLIP 136

typedef struct RawPoint {
    gcVec3 pa, pb;      /* on A's and B's surfaces, world */
    double separation;
} RawPoint;

/* Index of the triangle of h whose outward normal (local) is most along dir (local). */
static int best_face(const gcHull *h, gcVec3 dir, double *cosine) {
    int best = 0;
    double bd = -DBL_MAX;
    for (int i = 0; i < h->num_planes; ++i) {
        double d = gc_dot(h->plane_normals[i], dir);
        if (d > bd) {
            bd = d;
            best = i;
        }
    }
    *cosine = bd;
    return best;
}

/* The polygon (world, counter-clockwise seen from outside) of the face containing
 * triangle tri: every hull vertex on that triangle's plane, ordered by angle. */
static int face_polygon(const gcHull *h, const gcTransform *t, int tri, gcVec3 *out) {
    gcVec3 n = h->plane_normals[tri];
    double off = h->plane_offsets[tri];
    double tol = 1e-7 * hull_extent(h);
    gcVec3 local[GC_MAX_POLY];
    int count = 0;
    for (int i = 0; i < h->num_vertices && count < GC_MAX_POLY; ++i)
        if (fabs(gc_dot(n, h->vertices[i]) - off) <= tol) local[count++] = h->vertices[i];
    if (count < 3) {
        count = 3;
        for (int k = 0; k < 3; ++k) local[k] = h->vertices[h->triangles[3 * tri + k]];
    }
    gcVec3 c = gc_v3(0, 0, 0);
    for (int i = 0; i < count; ++i) c = gc_add(c, local[i]);
    c = gc_scale(c, 1.0 / count);
    gcVec3 u, v;
    tangent_basis(n, &u, &v);
    double angle[GC_MAX_POLY];
    for (int i = 0; i < count; ++i) { /* pseudo-angle in [0, 4): monotone in the angle, no atan2 */
        gcVec3 d = gc_sub(local[i], c);
        double x = gc_dot(d, u), y = gc_dot(d, v), r = fabs(x) + fabs(y);
        double slope = r > 0.0 ? y / r : 0.0;
        angle[i] = x >= 0.0 ? (y >= 0.0 ? slope : 4.0 + slope) : 2.0 - slope;
    }
    for (int i = 1; i < count; ++i) { /* insertion sort by angle */
        double a = angle[i];
        gcVec3 p = local[i];
        int j = i - 1;
        while (j >= 0 && angle[j] > a) {
            angle[j + 1] = angle[j];
            local[j + 1] = local[j];
            --j;
        }
        angle[j + 1] = a;
        local[j + 1] = p;
    }
    for (int i = 0; i < count; ++i) out[i] = gc_transform_point(t, local[i]);
    return count;
}

/* Keeps the part of polygon in (n_in points) on the side dot(n, x) <= d. */
static int clip_polygon(const gcVec3 *in, int n_in, gcVec3 n, double d, gcVec3 *out) {
    int n_out = 0;
    if (n_in == 2) { /* a segment (capsule core) */
        double da = gc_dot(n, in[0]) - d, db = gc_dot(n, in[1]) - d;
        if (da > 0 && db > 0) return 0;
        gcVec3 a = in[0], b = in[1];
        if (da > 0) a = gc_add(in[0], gc_scale(gc_sub(in[1], in[0]), da / (da - db)));
        if (db > 0) b = gc_add(in[0], gc_scale(gc_sub(in[1], in[0]), da / (da - db)));
        out[0] = a;
        out[1] = b;
        return 2;
    }
    for (int i = 0; i < n_in; ++i) {
        gcVec3 a = in[i], b = in[(i + 1) % n_in];
        double da = gc_dot(n, a) - d, db = gc_dot(n, b) - d;
        if (da <= 0) {
            if (n_out < GC_MAX_CLIP) out[n_out++] = a;
            if (db > 0 && n_out < GC_MAX_CLIP) out[n_out++] = gc_add(a, gc_scale(gc_sub(b, a), da / (da - db)));
        } else if (db <= 0 && n_out < GC_MAX_CLIP) {
            out[n_out++] = gc_add(a, gc_scale(gc_sub(b, a), da / (da - db)));
        }
    }
    return n_out;
}

/* Reduces pts to at most 4 that keep the deepest point and span the largest area. */
static int reduce_points(RawPoint *pts, int n, gcVec3 normal) {
    if (n <= GC_MANIFOLD_MAX_POINTS) return n;
    int chosen[4];
    int c0 = 0;
    for (int i = 1; i < n; ++i)
        if (pts[i].separation < pts[c0].separation) c0 = i;
    chosen[0] = c0;
    int c1 = -1;
    double best = -1;
    for (int i = 0; i < n; ++i) {
        double d = gc_len2(gc_sub(pts[i].pb, pts[c0].pb));
        if (i != c0 && d > best) best = d, c1 = i;
    }
    chosen[1] = c1;
    /* Third: largest triangle area with the first two, either side. */
    int c2 = -1;
    double best_area = -1;
    gcVec3 e01 = gc_sub(pts[c1].pb, pts[c0].pb);
    double sign = 1.0;
    for (int i = 0; i < n; ++i) {
        if (i == c0 || i == c1) continue;
        double a = gc_dot(gc_cross(e01, gc_sub(pts[i].pb, pts[c0].pb)), normal);
        if (fabs(a) > best_area) best_area = fabs(a), c2 = i, sign = a >= 0 ? 1.0 : -1.0;
    }
    chosen[2] = c2;
    /* Fourth: the point farthest outside the triangle (largest added area). */
    int tri[3] = {c0, c1, c2};
    int c3 = -1;
    double best_add = 0.0;
    for (int i = 0; i < n; ++i) {
        if (i == c0 || i == c1 || i == c2) continue;
        for (int e = 0; e < 3; ++e) {
            gcVec3 p = pts[tri[e]].pb, q = pts[tri[(e + 1) % 3]].pb;
            double a = -sign * gc_dot(gc_cross(gc_sub(q, p), gc_sub(pts[i].pb, p)), normal);
            if (a > best_add) best_add = a, c3 = i;
        }
    }
    int m = c3 >= 0 ? 4 : 3;
    if (c3 >= 0) chosen[3] = c3;
    RawPoint keep[4];
    for (int i = 0; i < m; ++i) keep[i] = pts[chosen[i]];
    for (int i = 0; i < m; ++i) pts[i] = keep[i];
    return m;
}

/* Contact points of parts a (transform ta) and b given gc_collide's answer. Returns the
 * count and the manifold normal (A towards B). */
static int manifold_points(const gcHull *a, const gcTransform *ta, const gcHull *b, const gcTransform *tb,
                           const gcContact *c, RawPoint *pts, gcVec3 *normal) {
    gcVec3 n = c->normal;
    int poly_a = a->num_vertices >= 4 && a->num_planes > 0, poly_b = b->num_vertices >= 4 && b->num_planes > 0;
    double cos_a = -2, cos_b = -2;
    int fa = 0, fb = 0;
    if (poly_a) fa = best_face(a, gc_mat3_tmul_vec(&ta->R, n), &cos_a);
    if (poly_b) fb = best_face(b, gc_mat3_tmul_vec(&tb->R, gc_neg(n)), &cos_b);
    int ref_is_a = cos_a >= cos_b - 1e-9;
    double best_cos = ref_is_a ? cos_a : cos_b;
    const gcHull *ref = ref_is_a ? a : b, *inc = ref_is_a ? b : a;
    const gcTransform *tr = ref_is_a ? ta : tb, *ti = ref_is_a ? tb : ta;
    int count = 0;
    if (best_cos >= GC_FACE_CONTACT_COS && (inc->num_vertices >= 4 || inc->num_vertices == 2)) {
        gcVec3 ref_poly[GC_MAX_POLY], inc_poly[GC_MAX_POLY];
        int ref_tri = ref_is_a ? fa : fb;
        int nr = face_polygon(ref, tr, ref_tri, ref_poly);
        gcVec3 nref = gc_mat3_mul_vec(&tr->R, ref->plane_normals[ref_tri]);
        int ni;
        if (inc->num_vertices == 2) {
            inc_poly[0] = gc_transform_point(ti, inc->vertices[0]);
            inc_poly[1] = gc_transform_point(ti, inc->vertices[1]);
            ni = 2;
            /* Only a capsule lying along the face gives a segment contact. */
            gcVec3 axis = gc_normalize(gc_sub(inc_poly[1], inc_poly[0]));
            if (fabs(gc_dot(axis, nref)) > 0.1) ni = 0;
        } else {
            double cos_i;
            int inc_tri = best_face(inc, gc_mat3_tmul_vec(&ti->R, gc_neg(nref)), &cos_i);
            ni = face_polygon(inc, ti, inc_tri, inc_poly);
        }
        if (ni > 0) {
            gcVec3 buf_a[GC_MAX_CLIP], buf_b[GC_MAX_CLIP];
            int nc = ni;
            for (int i = 0; i < ni; ++i) buf_a[i] = inc_poly[i];
            gcVec3 *cur = buf_a, *next = buf_b;
            for (int e = 0; e < nr && nc > 0; ++e) {
                gcVec3 p = ref_poly[e], q = ref_poly[(e + 1) % nr];
                gcVec3 side = gc_normalize(gc_cross(gc_sub(q, p), nref));
                nc = clip_polygon(cur, nc, side, gc_dot(side, p), next);
                gcVec3 *tmp = cur;
                cur = next;
                next = tmp;
            }
            RawPoint raw[GC_MAX_CLIP];
            int nraw = 0;
            double off = gc_dot(nref, ref_poly[0]);
            for (int i = 0; i < nc; ++i) {
                double d = gc_dot(nref, cur[i]) - off;
                double s = d - ref->radius - inc->radius;
                if (s >= GC_CONTACT_MARGIN) continue;
                gcVec3 on_inc = gc_madd(cur[i], nref, -inc->radius);
                gcVec3 on_ref = gc_madd(cur[i], nref, ref->radius - d);
                raw[nraw].pa = ref_is_a ? on_ref : on_inc;
                raw[nraw].pb = ref_is_a ? on_inc : on_ref;
                raw[nraw].separation = s;
                nraw++;
            }
            gcVec3 nm = ref_is_a ? nref : gc_neg(nref);
            nraw = reduce_points(raw, nraw, nm);
            if (nraw > 0) {
                for (int i = 0; i < nraw; ++i) pts[i] = raw[i];
                *normal = nm;
                count = nraw;
            }
        }
    }
    if (count == 0) {
        pts[0].pa = c->point_a;
        pts[0].pb = c->point_b;
        pts[0].separation = c->distance;
        *normal = n;
        count = 1;
    }
    return count;
}

static const gcManifold *find_previous(const struct gcContactSystem *cs, int64_t key) {
    int lo = 0, hi = cs->num_previous - 1;
    while (lo <= hi) {
        int mid = lo + (hi - lo) / 2;
        int64_t k = cs->previous[mid].key;
        if (k == key) return &cs->previous[mid];
        if (k < key) lo = mid + 1;
        else hi = mid - 1;
    }
    return NULL;
}

/* Whether the pair moved (relative to itself) less than the reuse tolerances since the
 * manifold was computed: translation of B's COM in A's frame, and the angle of the
 * relative rotation (from the trace: |R_ref^T R - I| small). */
static int reusable(const gcManifold *old, gcVec3 rel_p, const gcMat3 *rel_R) {
    if (old->num_points == 0) return 0;
    if (gc_len2(gc_sub(rel_p, old->ref_position)) > GC_REUSE_DISTANCE * GC_REUSE_DISTANCE) return 0;
    double trace = 0.0; /* trace(R_ref^T R) = 1 + 2 cos(angle) */
    for (int i = 0; i < 3; ++i)
        for (int k = 0; k < 3; ++k) trace += old->ref_rotation.m[k][i] * rel_R->m[k][i];
    double one_minus_cos = 0.5 * (3.0 - trace);
    return one_minus_cos < 0.5 * GC_REUSE_ANGLE * GC_REUSE_ANGLE;
}

/* Narrow phase for candidate i: fills manifolds[i] (num_points 0 when apart). */
static void narrow_pair(gcWorld *w, int i) {
    struct gcContactSystem *cs = w->contacts;
    const gcCandidate *cand = &cs->candidates[i];
    gcManifold *m = &cs->manifolds[i];
    m->key = cand->key;
    m->part_a = cand->part_a;
    m->part_b = cand->part_b;
    m->body_a = w->parts[cand->part_a].body;
    m->body_b = w->parts[cand->part_b].body;
    m->num_points = 0;
    m->reused = 0;
    const gcBody *A = &w->bodies[m->body_a], *B = &w->bodies[m->body_b];
    const gcHull *ha = &w->parts[m->part_a].hull, *hb = &w->parts[m->part_b].hull;
    const gcManifold *old = find_previous(cs, m->key);
    /* B relative to A, in A's COM frame. */
    gcVec3 rel_p = gc_mat3_tmul_vec(&A->R, gc_sub(B->com, A->com));
    gcMat3 At = gc_mat3_transpose(&A->R);
    gcMat3 rel_R = gc_mat3_mul(&At, &B->R);
    if (old && reusable(old, rel_p, &rel_R)) {
        /* The pair has hardly moved relative to itself since its manifold was computed:
         * keep the material points, refresh their world positions and separations. */
        *m = *old;
        m->normal = gc_mat3_mul_vec(&A->R, old->normal_local_a);
        tangent_basis(m->normal, &m->t1, &m->t2);
        for (int k = 0; k < m->num_points; ++k) {
            gcManifoldPoint *p = &m->points[k];
            gcVec3 pa = gc_add(A->com, gc_mat3_mul_vec(&A->R, p->local_a));
            gcVec3 pb = gc_add(B->com, gc_mat3_mul_vec(&B->R, p->local_b));
            p->point = gc_scale(gc_add(pa, pb), 0.5);
            p->separation = gc_dot(m->normal, gc_sub(pb, pa));
        }
        m->reused = 1;
        return;
    }
    gcTransform ta = gc_body_transform(A), tb = gc_body_transform(B);
    gcContact c;
    gcStatus st = gc_collide(ha, &ta, hb, &tb, &c);
    if (st < 0 || !(c.distance < GC_CONTACT_MARGIN)) return;
    RawPoint raw[GC_MANIFOLD_MAX_POINTS];
    gcVec3 normal;
    int n = manifold_points(ha, &ta, hb, &tb, &c, raw, &normal);
    m->normal = normal;
    tangent_basis(normal, &m->t1, &m->t2);
    m->mu_s = sqrt(A->mu_s * B->mu_s);
    m->mu_d = sqrt(A->mu_d * B->mu_d);
    if (m->mu_d > m->mu_s) m->mu_d = m->mu_s;
    m->ref_position = rel_p;
    m->ref_rotation = rel_R;
    m->normal_local_a = gc_mat3_tmul_vec(&A->R, normal);
    int used[GC_MANIFOLD_MAX_POINTS] = {0, 0, 0, 0};
    double match = 0.25 * fmin(ha->min_width, hb->min_width);
    if (!(match < 0.002)) match = 0.002;
    for (int k = 0; k < n; ++k) {
        gcManifoldPoint *p = &m->points[k];
        memset(p, 0, sizeof *p);
        p->local_a = gc_mat3_tmul_vec(&A->R, gc_sub(raw[k].pa, A->com));
        p->local_b = gc_mat3_tmul_vec(&B->R, gc_sub(raw[k].pb, B->com));
        p->point = gc_scale(gc_add(raw[k].pa, raw[k].pb), 0.5);
        p->separation = raw[k].separation;
        if (!old) continue;
        int best = -1;
        double bd = match * match;
        for (int j = 0; j < old->num_points; ++j) {
            if (used[j]) continue;
            const gcManifoldPoint *q = &old->points[j];
            double d = fmin(gc_len2(gc_sub(q->local_a, p->local_a)), gc_len2(gc_sub(q->local_b, p->local_b)));
            if (d < bd) bd = d, best = j;
        }
        if (best >= 0) {
            const gcManifoldPoint *q = &old->points[best];
            used[best] = 1;
            p->normal_impulse = q->normal_impulse;
            p->friction_impulse = q->friction_impulse;
            p->anchored = q->anchored;
            p->anchor_a = q->anchor_a;
            p->anchor_b = q->anchor_b;
        }
    }
    m->sticking = old ? old->sticking : 1;
    m->reused = 0;
    m->num_points = n;
}

#define GC_NARROW_CHUNK 8
#define GC_POOL_MIN_PAIRS 64   /* narrow phase on the pool from this many candidate pairs */
#define GC_POOL_MIN_POINTS 128 /* solver on the pool when the chains besides the largest have this many points */

typedef struct NarrowJob {
    gcWorld *world;
    int count;
} NarrowJob;

static void narrow_task(void *ctx, int index) {
    NarrowJob *job = ctx;
    int end = (index + 1) * GC_NARROW_CHUNK;
    if (end > job->count) end = job->count;
    for (int i = index * GC_NARROW_CHUNK; i < end; ++i) narrow_pair(job->world, i);
}

void gc_contacts_detect(gcWorld *w) {
    struct gcContactSystem *cs = w->contacts;
    if (!cs) return;
    /* Last step's manifolds become `previous` (for matching); this step writes the other. */
    gcManifold *tmp = cs->previous;
    cs->previous = cs->manifolds;
    cs->num_previous = cs->num_manifolds;
    cs->manifolds = tmp;
    cs->num_manifolds = 0;
    broad_phase(w);
    NarrowJob job = {w, cs->num_candidates};
    int tasks = (cs->num_candidates + GC_NARROW_CHUNK - 1) / GC_NARROW_CHUNK;
    /* Reused manifolds cost next to nothing: judge the work by last step's full pairs. */
    int busy = cs->num_candidates >= GC_POOL_MIN_PAIRS && cs->full_pairs >= GC_POOL_MIN_PAIRS / 2;
    gc_pool_run(busy ? cs->pool : NULL, narrow_task, &job, tasks);
    /* Compact, keeping the key order. */
    int n = 0;
    cs->full_pairs = 0;
    for (int i = 0; i < cs->num_candidates; ++i) {
        cs->full_pairs += !cs->manifolds[i].reused;
        if (cs->manifolds[i].num_points == 0) continue;
        if (n != i) cs->manifolds[n] = cs->manifolds[i];
        n++;
    }
    cs->num_manifolds = n;
    gc_chains_build(w);
}

/* ------------------------------------------------------------------ solver */

static inline double dot6(gcVec3 d, gcVec3 ang, const double W[6]) {
    return d.x * W[0] + d.y * W[1] + d.z * W[2] + ang.x * W[3] + ang.y * W[4] + ang.z * W[5];
}

static inline void add_twist(gcVec3 *v, gcVec3 *om, const double W[6], double s) {
    v->x += W[0] * s;
    v->y += W[1] * s;
    v->z += W[2] * s;
    om->x += W[3] * s;
    om->y += W[4] * s;
    om->z += W[5] * s;
}

typedef struct SolverBodies {
    gcVec3 *va, *wa, *vb, *wb; /* NULL for a static body */
} SolverBodies;

static inline void apply(const gcPointScratch *q, int k, double lambda, const SolverBodies *s) {
    if (s->vb) add_twist(s->vb, s->wb, q->wb[k], lambda);
    if (s->va) add_twist(s->va, s->wa, q->wa[k], -lambda);
}

/* out = M x for a body's row-major 6x6 inverse effective mass (NULL: a static body,
 * out = 0). Without a finger on the body M is block diagonal: m^-1 I and I_world^-1. */
static void mul_inv_mass(const double *M, int dense, const double x[6], double out[6]) {
    if (!M) {
        for (int i = 0; i < 6; ++i) out[i] = 0.0;
        return;
    }
    if (!dense) {
        out[0] = M[0] * x[0];
        out[1] = M[0] * x[1];
        out[2] = M[0] * x[2];
        for (int i = 3; i < 6; ++i) {
            const double *r = M + 6 * i;
            out[i] = r[3] * x[3] + r[4] * x[4] + r[5] * x[5];
        }
        return;
    }
    for (int i = 0; i < 6; ++i) {
        const double *r = M + 6 * i;
        out[i] = r[0] * x[0] + r[1] * x[1] + r[2] * x[2] + r[3] * x[3] + r[4] * x[4] + r[5] * x[5];
    }
}

/* The solver's per-point scratch of a manifold of this step (rebuilt by prepare_manifold,
 * kept apart so that manifolds copied between steps stay small). */
static inline gcPointScratch *scratch_of(struct gcContactSystem *cs, const gcManifold *m) {
    return &cs->scratch[(m - cs->manifolds) * GC_MANIFOLD_MAX_POINTS];
}

static void prepare_manifold(gcWorld *w, gcManifold *m, double dt) {
    gcPointScratch *scratch = scratch_of(w->contacts, m);
    const gcBody *A = &w->bodies[m->body_a], *B = &w->bodies[m->body_b];
    struct gcContactSystem *cs = w->contacts;
    const double *ma = A->is_static ? NULL : cs->inv_mass[m->body_a];
    const double *mb = B->is_static ? NULL : cs->inv_mass[m->body_b];
    gcVec3 dirs[3] = {m->normal, m->t1, m->t2};
    for (int k = 0; k < m->num_points; ++k) {
        gcManifoldPoint *p = &m->points[k];
        gcPointScratch *q = &scratch[k];
        gcVec3 ra = gc_sub(p->point, A->com), rb = gc_sub(p->point, B->com);
        for (int d = 0; d < 3; ++d) {
            q->ang_a[d] = gc_cross(ra, dirs[d]);
            q->ang_b[d] = gc_cross(rb, dirs[d]);
            double ja[6] = {dirs[d].x, dirs[d].y, dirs[d].z, q->ang_a[d].x, q->ang_a[d].y, q->ang_a[d].z};
            double jb[6] = {dirs[d].x, dirs[d].y, dirs[d].z, q->ang_b[d].x, q->ang_b[d].y, q->ang_b[d].z};
            mul_inv_mass(ma, A->coupled, ja, q->wa[d]);
            mul_inv_mass(mb, B->coupled, jb, q->wb[d]);
        }
        /* K = J M^-1 J^T is symmetric: the normal and tangential blocks are what the rows use. */
        double kn = dot6(dirs[0], q->ang_b[0], q->wb[0]) + dot6(dirs[0], q->ang_a[0], q->wa[0]);
        double k11 = dot6(dirs[1], q->ang_b[1], q->wb[1]) + dot6(dirs[1], q->ang_a[1], q->wa[1]);
        double k22 = dot6(dirs[2], q->ang_b[2], q->wb[2]) + dot6(dirs[2], q->ang_a[2], q->wa[2]);
        double k12 = dot6(dirs[1], q->ang_b[1], q->wb[2]) + dot6(dirs[1], q->ang_a[1], q->wa[2]);
        q->inv_kn = kn > 0.0 ? 1.0 / kn : 0.0;
        double det = k11 * k22 - k12 * k12;
        if (det > 1e-300 * (k11 * k22 + 1e-300) && k11 > 0 && k22 > 0) {
            q->inv_kt[0][0] = k22 / det;
            q->inv_kt[1][1] = k11 / det;
            q->inv_kt[0][1] = q->inv_kt[1][0] = -k12 / det;
        } else {
            memset(q->inv_kt, 0, sizeof q->inv_kt);
        }
        double kmax = 0.5 * (k11 + k22) + sqrt(0.25 * (k11 - k22) * (k11 - k22) + k12 * k12);
        q->inv_kt_max = kmax > 0.0 ? 1.0 / kmax : 0.0;
        /* Normal: a speculative point (apart) may close its gap this step, no more. */
        q->target_n = -gc_max(p->separation, 0.0) / dt;
        /* Static friction: the anchors (one material point on each body) must not slide. */
        q->target_t[0] = q->target_t[1] = 0.0;
        if (!m->sticking) p->anchored = 0;
        if (m->sticking && p->anchored) {
            gcVec3 wa = gc_add(A->com, gc_mat3_mul_vec(&A->R, p->anchor_a));
            gcVec3 wb = gc_add(B->com, gc_mat3_mul_vec(&B->R, p->anchor_b));
            gcVec3 da = gc_sub(wa, p->point), db = gc_sub(wb, p->point);
            da = gc_madd(da, m->normal, -gc_dot(da, m->normal));
            db = gc_madd(db, m->normal, -gc_dot(db, m->normal));
            if (gc_len(da) > GC_ANCHOR_RESET || gc_len(db) > GC_ANCHOR_RESET) p->anchored = 0;
        }
        if (m->sticking && !p->anchored) {
            p->anchor_a = gc_mat3_tmul_vec(&A->R, gc_sub(p->point, A->com));
            p->anchor_b = gc_mat3_tmul_vec(&B->R, gc_sub(p->point, B->com));
            p->anchored = 1;
        } else if (m->sticking) {
            gcVec3 wa = gc_add(A->com, gc_mat3_mul_vec(&A->R, p->anchor_a));
            gcVec3 wb = gc_add(B->com, gc_mat3_mul_vec(&B->R, p->anchor_b));
            gcVec3 e = gc_sub(wb, wa);
            q->target_t[0] = -GC_ANCHOR_BETA * gc_dot(e, m->t1) / dt;
            q->target_t[1] = -GC_ANCHOR_BETA * gc_dot(e, m->t2) / dt;
        }
        /* Warm start: last step's impulses (friction re-projected on this step's tangents). */
        q->lambda_t[0] = gc_dot(p->friction_impulse, m->t1);
        q->lambda_t[1] = gc_dot(p->friction_impulse, m->t2);
        q->position_impulse = 0.0;
    }
}

static SolverBodies solver_bodies(gcWorld *w, const gcManifold *m, gcVec3 *lin, gcVec3 *ang) {
    SolverBodies s;
    gcBody *A = &w->bodies[m->body_a], *B = &w->bodies[m->body_b];
    /* A body without a valid effective mass (degenerate, or stepped by another runtime
     * thread this step) is immovable here and never written. */
    int da = !A->is_static && A->effective_mass_valid, db = !B->is_static && B->effective_mass_valid;
    if (lin) { /* pseudo-velocities of the position pass */
        s.va = da ? &lin[m->body_a] : NULL;
        s.wa = da ? &ang[m->body_a] : NULL;
        s.vb = db ? &lin[m->body_b] : NULL;
        s.wb = db ? &ang[m->body_b] : NULL;
    } else {
        s.va = da ? &A->v : NULL;
        s.wa = da ? &A->w : NULL;
        s.vb = db ? &B->v : NULL;
        s.wb = db ? &B->w : NULL;
    }
    return s;
}

static void warm_start(gcWorld *w, gcManifold *m) {
    gcPointScratch *scratch = scratch_of(w->contacts, m);
    SolverBodies s = solver_bodies(w, m, NULL, NULL);
    for (int k = 0; k < m->num_points; ++k) {
        const gcManifoldPoint *p = &m->points[k];
        const gcPointScratch *q = &scratch[k];
        apply(q, 0, p->normal_impulse, &s);
        apply(q, 1, q->lambda_t[0], &s);
        apply(q, 2, q->lambda_t[1], &s);
    }
}

/* The two bodies' twists, held in locals while a manifold is solved (the bodies differ, so
 * nothing aliases); a static body is a zero twist that is never written back. */
typedef struct LocalTwists {
    gcVec3 va, wa, vb, wb;
} LocalTwists;

static inline LocalTwists load_twists(const SolverBodies *s) {
    LocalTwists t;
    gcVec3 zero = {0.0, 0.0, 0.0};
    t.va = s->va ? *s->va : zero;
    t.wa = s->wa ? *s->wa : zero;
    t.vb = s->vb ? *s->vb : zero;
    t.wb = s->wb ? *s->wb : zero;
    return t;
}

static inline void store_twists(const SolverBodies *s, const LocalTwists *t) {
    if (s->va) *s->va = t->va, *s->wa = t->wa;
    if (s->vb) *s->vb = t->vb, *s->wb = t->wb;
}

/* Velocity of B relative to A at the point, along direction k (d is that direction). */
static inline double rel_vel(const gcPointScratch *q, int k, gcVec3 d, gcVec3 dv, const LocalTwists *t) {
    return gc_dot(d, dv) + gc_dot(q->ang_b[k], t->wb) - gc_dot(q->ang_a[k], t->wa);
}

static inline void apply_local(const gcPointScratch *q, int k, double lambda, LocalTwists *t) {
    add_twist(&t->vb, &t->wb, q->wb[k], lambda);
    add_twist(&t->va, &t->wa, q->wa[k], -lambda);
}

/* One Gauss-Seidel pass over the manifold's rows; returns the largest velocity error a
 * row saw before its update (sliding friction rows and separating normals excepted). */
static double solve_velocity(gcWorld *w, gcManifold *m) {
    gcPointScratch *scratch = scratch_of(w->contacts, m);
    SolverBodies s = solver_bodies(w, m, NULL, NULL);
    LocalTwists t = load_twists(&s);
    double residual = 0.0;
    double mu = m->sticking ? m->mu_s : m->mu_d;
    /* Friction first (its bound uses the current normal impulses), normals last. */
    for (int k = 0; k < m->num_points; ++k) {
        gcManifoldPoint *p = &m->points[k];
        gcPointScratch *q = &scratch[k];
        double limit = mu * p->normal_impulse;
        gcVec3 dv = gc_sub(t.vb, t.va);
        double e1 = rel_vel(q, 1, m->t1, dv, &t) - q->target_t[0];
        double e2 = rel_vel(q, 2, m->t2, dv, &t) - q->target_t[1];
        double l1 = q->lambda_t[0] - (q->inv_kt[0][0] * e1 + q->inv_kt[0][1] * e2);
        double l2 = q->lambda_t[1] - (q->inv_kt[1][0] * e1 + q->inv_kt[1][1] * e2);
        q->saturated = l1 * l1 + l2 * l2 > limit * limit;
        if (q->saturated) {
            /* Sliding. The block step projected on the disc would settle where the impulse
             * is parallel to K^-1 v, not to v; an isotropic step settles where it opposes
             * the slip velocity (Coulomb's maximal dissipation). Then the true cone. */
            l1 = q->lambda_t[0] - e1 * q->inv_kt_max;
            l2 = q->lambda_t[1] - e2 * q->inv_kt_max;
            double len2 = l1 * l1 + l2 * l2;
            if (len2 > limit * limit) {
                double scale = limit > 0.0 ? limit / sqrt(len2) : 0.0;
                l1 *= scale;
                l2 *= scale;
            }
        } else {
            residual = gc_max(residual, fabs(e1) + fabs(e2));
        }
        apply_local(q, 1, l1 - q->lambda_t[0], &t);
        apply_local(q, 2, l2 - q->lambda_t[1], &t);
        q->lambda_t[0] = l1;
        q->lambda_t[1] = l2;
    }
    for (int k = 0; k < m->num_points; ++k) {
        gcManifoldPoint *p = &m->points[k];
        gcPointScratch *q = &scratch[k];
        double vn = rel_vel(q, 0, m->normal, gc_sub(t.vb, t.va), &t);
        double l = p->normal_impulse - (vn - q->target_n) * q->inv_kn;
        if (l < 0.0) l = 0.0;
        if (l > 0.0 || vn < q->target_n) residual = gc_max(residual, fabs(vn - q->target_n));
        apply_local(q, 0, l - p->normal_impulse, &t);
        p->normal_impulse = l;
    }
    store_twists(&s, &t);
    return residual;
}

/* After the velocity iterations: the reported impulses, then the stick/slip transition of
 * the whole manifold. Coulomb's law bounds each point by mu times its own normal impulse, but
 * how a rigid contact patch shares its load between points is not unique: deciding slip per
 * point would let one lightly loaded corner drop to mu_d and drag the patch with it below
 * mu_s. The patch slips when every pressed point was on its cone at its last update and
 * it slides faster than GC_SLIP_SPEED: an unconverged first solve of a fresh contact
 * saturates without the patch really sliding. */
static void finish_velocity(gcWorld *w, gcManifold *m) {
    gcPointScratch *scratch = scratch_of(w->contacts, m);
    SolverBodies s = solver_bodies(w, m, NULL, NULL);
    LocalTwists t = load_twists(&s);
    int pressed = 0, all_saturated = 1;
    double slip2 = 0.0;
    for (int k = 0; k < m->num_points; ++k) {
        gcManifoldPoint *p = &m->points[k];
        gcPointScratch *q = &scratch[k];
        p->friction_impulse = gc_add(gc_scale(m->t1, q->lambda_t[0]), gc_scale(m->t2, q->lambda_t[1]));
        if (!(p->normal_impulse > 0.0)) {
            p->anchored = 0; /* not pressed: anchor afresh at the next touch */
            continue;
        }
        pressed = 1;
        if (!q->saturated) all_saturated = 0;
        gcVec3 dv = gc_sub(t.vb, t.va);
        double e1 = rel_vel(q, 1, m->t1, dv, &t) - q->target_t[0];
        double e2 = rel_vel(q, 2, m->t2, dv, &t) - q->target_t[1];
        slip2 = gc_max(slip2, e1 * e1 + e2 * e2);
    }
    if (!pressed) {
        m->sticking = 1;
    } else if (all_saturated && slip2 > GC_SLIP_SPEED * GC_SLIP_SPEED) {
        m->sticking = 0; /* on the cone: sliding */
    } else if (!m->sticking) {
        m->sticking = 1; /* inside the mu_d cone: it stopped; anchors are set at the next step */
        for (int k = 0; k < m->num_points; ++k) m->points[k].anchored = 0;
    }
}

static void solve_position(gcWorld *w, gcManifold *m, double dt) {
    gcPointScratch *scratch = scratch_of(w->contacts, m);
    struct gcContactSystem *cs = w->contacts;
    SolverBodies s = solver_bodies(w, m, cs->pseudo_v, cs->pseudo_w);
    LocalTwists t = load_twists(&s);
    for (int k = 0; k < m->num_points; ++k) {
        gcManifoldPoint *p = &m->points[k];
        gcPointScratch *q = &scratch[k];
        double depth = -(p->separation + GC_CONTACT_SLOP);
        if (!(depth > 0.0) && q->position_impulse == 0.0) continue;
        double target = depth > 0.0 ? fmin(GC_POSITION_BETA * depth / dt, GC_MAX_CORRECTION_SPEED) : 0.0;
        double vn = rel_vel(q, 0, m->normal, gc_sub(t.vb, t.va), &t);
        double l = q->position_impulse - (vn - target) * q->inv_kn;
        if (l < 0.0) l = 0.0;
        apply_local(q, 0, l - q->position_impulse, &t);
        q->position_impulse = l;
    }
    store_twists(&s, &t);
}

void gc_contacts_solve_chain(gcWorld *w, int chain, double dt) {
    struct gcContactSystem *cs = w->contacts;
    if (!cs || chain < 0 || chain >= cs->num_chains) return;
    int m0 = cs->chain_manifold_start[chain], m1 = cs->chain_manifold_start[chain + 1];
    if (m0 == m1) return;
    const int32_t *list = cs->chain_manifolds;
    int b0 = cs->chain_body_start[chain], b1 = cs->chain_body_start[chain + 1];
    /* Each body's inverse effective mass (with the finger coupling), once per step. */
    for (int i = b0; i < b1; ++i) {
        int32_t id = cs->chain_bodies[i];
        gc_body_inverse_effective_mass(&w->bodies[id], cs->inv_mass[id]);
    }
    for (int i = m0; i < m1; ++i) prepare_manifold(w, &cs->manifolds[list[i]], dt);
    for (int i = m0; i < m1; ++i) warm_start(w, &cs->manifolds[list[i]]);
    /* Gauss-Seidel until every row meets its velocity target within GC_SOLVER_TOLERANCE
     * (the impulses of a statically indeterminate stack may still wander along the null
     * space; the velocities are what moves the bodies), or the iteration cap. A chain's own
     * data decide, so the count does not depend on the thread that solves it. */
    for (int it = 0; it < GC_VELOCITY_ITERATIONS; ++it) {
        double residual = 0.0;
        for (int i = m0; i < m1; ++i) residual = gc_max(residual, solve_velocity(w, &cs->manifolds[list[i]]));
        if (residual <= GC_SOLVER_TOLERANCE) break;
    }
    for (int i = m0; i < m1; ++i) finish_velocity(w, &cs->manifolds[list[i]]);
    /* Split-impulse position pass: pseudo-velocities move the poses, not the momenta. */
    for (int i = b0; i < b1; ++i) {
        int32_t id = cs->chain_bodies[i];
        cs->pseudo_v[id] = gc_v3(0, 0, 0);
        cs->pseudo_w[id] = gc_v3(0, 0, 0);
    }
    int any = 0;
    for (int i = m0; i < m1 && !any; ++i) {
        const gcManifold *m = &cs->manifolds[list[i]];
        for (int k = 0; k < m->num_points; ++k)
            if (m->points[k].separation < -GC_CONTACT_SLOP) any = 1;
    }
    if (!any) return;
    for (int it = 0; it < GC_POSITION_ITERATIONS; ++it)
        for (int i = m0; i < m1; ++i) solve_position(w, &cs->manifolds[list[i]], dt);
    for (int i = b0; i < b1; ++i) {
        int32_t id = cs->chain_bodies[i];
        gcBody *b = &w->bodies[id];
        gcVec3 pv = cs->pseudo_v[id], pw = cs->pseudo_w[id];
        if (gc_len2(pv) == 0.0 && gc_len2(pw) == 0.0) continue;
        b->com = gc_madd(b->com, pv, dt);
        b->q = gc_quat_normalize(gc_quat_mul(gc_quat_from_rotation_vector(gc_scale(pw, dt)), b->q));
        b->R = gc_quat_to_mat3(b->q);
    }
}

typedef struct SolveJob {
    gcWorld *world;
    double dt;
} SolveJob;

static void solve_task(void *ctx, int index) {
    SolveJob *job = ctx;
    gc_contacts_solve_chain(job->world, index, job->dt);
}

void gc_contacts_solve(gcWorld *w, double dt) {
    struct gcContactSystem *cs = w->contacts;
    if (!cs || cs->num_manifolds == 0) return;
    cs->dt = dt;
    SolveJob job = {w, dt};
    /* Waking a worker costs a few microseconds: hand chains to the pool only when the
     * chains other than the largest hold enough points to pay for it. The result is the
     * same either way. */
    int total = 0, largest = 0;
    for (int c = 0; c < cs->num_chains; ++c) {
        int points = 0;
        for (int i = cs->chain_manifold_start[c]; i < cs->chain_manifold_start[c + 1]; ++i)
            points += cs->manifolds[cs->chain_manifolds[i]].num_points;
        total += points;
        if (points > largest) largest = points;
    }
    gc_pool_run(total - largest >= GC_POOL_MIN_POINTS ? cs->pool : NULL, solve_task, &job, cs->num_chains);
}

void gc_contacts_step(gcWorld *w, double dt) {
    gc_contacts_detect(w);
    gc_contacts_solve(w, dt);
}

/* ------------------------------------------------------------------ queries */

int gc_world_contact_count(const gcWorld *w) {
    const struct gcContactSystem *cs = w->contacts;
    int n = 0;
    if (!cs) return 0;
    for (int i = 0; i < cs->num_manifolds; ++i) n += cs->manifolds[i].num_points;
    return n;
}

int gc_world_contacts(const gcWorld *w, gcContactPoint *out, int capacity) {
    const struct gcContactSystem *cs = w->contacts;
    int n = 0;
    if (!cs) return 0;
    for (int i = 0; i < cs->num_manifolds; ++i) {
        const gcManifold *m = &cs->manifolds[i];
        for (int k = 0; k < m->num_points; ++k, ++n) {
            if (!out || n >= capacity) continue;
            const gcManifoldPoint *p = &m->points[k];
            gcContactPoint *o = &out[n];
            o->body_a = m->body_a;
            o->body_b = m->body_b;
            o->point[0] = p->point.x, o->point[1] = p->point.y, o->point[2] = p->point.z;
            o->normal[0] = m->normal.x, o->normal[1] = m->normal.y, o->normal[2] = m->normal.z;
            o->separation = p->separation;
            o->normal_impulse = p->normal_impulse;
            o->friction_impulse[0] = p->friction_impulse.x;
            o->friction_impulse[1] = p->friction_impulse.y;
            o->friction_impulse[2] = p->friction_impulse.z;
            o->sticking = m->sticking;
        }
    }
    return n;
}

int64_t gc_world_contact_overflow(const gcWorld *w) { return w->contacts ? w->contacts->overflow : 0; }
