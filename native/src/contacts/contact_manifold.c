/* Narrow phase and contact manifolds (docs/solver.md), in parallel with one output slot per
 * candidate: gc_collide (GJK/EPA) gives the normal; when a face of either polytope lies along
 * it, the incident face of the other is clipped against the reference face's side planes
 * (Sutherland-Hodgman) and reduced to at most 4 points; otherwise the single GJK/EPA point
 * is used. Points are matched to last step's manifold of the same pair by proximity in
 * either body's frame and inherit its impulses (warm start), friction state and anchors. */
#define _POSIX_C_SOURCE 200809L
#include "contacts_internal.h"

#include <float.h>
#include <stdlib.h>
#include <string.h>

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
    double tol = 1e-7 * gc_hull_extent(h);
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
    gc_tangent_basis(n, &u, &v);
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
    const gcModel *model = w->model;
    struct gcContactSystem *cs = w->contacts;
    const gcCandidate *cand = &cs->candidates[i];
    gcManifold *m = &cs->manifolds[i];
    m->key = cand->key;
    m->part_a = cand->part_a;
    m->part_b = cand->part_b;
    m->body_a = model->parts[cand->part_a].body;
    m->body_b = model->parts[cand->part_b].body;
    m->num_points = 0;
    m->reused = 0;
    const gcBody *A = &w->bodies[m->body_a], *B = &w->bodies[m->body_b];
    const gcBodyModel *Am = &model->bodies[m->body_a], *Bm = &model->bodies[m->body_b];
    const gcHull *ha = &model->parts[m->part_a].hull, *hb = &model->parts[m->part_b].hull;
    const gcManifold *old = find_previous(cs, m->key);
    /* B relative to A, in A's COM frame. */
    gcVec3 rel_p = gc_mat3_tmul_vec(&A->state.R, gc_sub(B->state.com, A->state.com));
    gcMat3 At = gc_mat3_transpose(&A->state.R);
    gcMat3 rel_R = gc_mat3_mul(&At, &B->state.R);
    if (old && reusable(old, rel_p, &rel_R)) {
        /* The pair has hardly moved relative to itself since its manifold was computed:
         * keep the material points, refresh their world positions and separations. */
        *m = *old;
        m->normal = gc_mat3_mul_vec(&A->state.R, old->normal_local_a);
        gc_tangent_basis(m->normal, &m->t1, &m->t2);
        for (int k = 0; k < m->num_points; ++k) {
            gcManifoldPoint *p = &m->points[k];
            gcVec3 pa = gc_add(A->state.com, gc_mat3_mul_vec(&A->state.R, p->local_a));
            gcVec3 pb = gc_add(B->state.com, gc_mat3_mul_vec(&B->state.R, p->local_b));
            p->point = gc_scale(gc_add(pa, pb), 0.5);
            p->separation = gc_dot(m->normal, gc_sub(pb, pa));
        }
        m->reused = 1;
        return;
    }
    gcTransform ta = gc_body_transform(Am, &A->state), tb = gc_body_transform(Bm, &B->state);
    gcContact c;
    gcStatus st = gc_collide(ha, &ta, hb, &tb, &c);
    if (st < 0 || !(c.distance < GC_CONTACT_MARGIN)) return;
    RawPoint raw[GC_MANIFOLD_MAX_POINTS];
    gcVec3 normal;
    int n = manifold_points(ha, &ta, hb, &tb, &c, raw, &normal);
    m->normal = normal;
    gc_tangent_basis(normal, &m->t1, &m->t2);
    m->mu_s = sqrt(Am->mu_s * Bm->mu_s);
    m->mu_d = sqrt(Am->mu_d * Bm->mu_d);
    if (m->mu_d > m->mu_s) m->mu_d = m->mu_s;
    m->ref_position = rel_p;
    m->ref_rotation = rel_R;
    m->normal_local_a = gc_mat3_tmul_vec(&A->state.R, normal);
    int used[GC_MANIFOLD_MAX_POINTS] = {0, 0, 0, 0};
    double match = 0.25 * fmin(ha->min_width, hb->min_width);
    if (!(match < 0.002)) match = 0.002;
    for (int k = 0; k < n; ++k) {
        gcManifoldPoint *p = &m->points[k];
        memset(p, 0, sizeof *p);
        p->local_a = gc_mat3_tmul_vec(&A->state.R, gc_sub(raw[k].pa, A->state.com));
        p->local_b = gc_mat3_tmul_vec(&B->state.R, gc_sub(raw[k].pb, B->state.com));
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

void gc_narrow_phase(gcWorld *w) {
    struct gcContactSystem *cs = w->contacts;
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
}
