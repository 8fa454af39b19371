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
#include "analysis_internal.h"

#include <stdlib.h>

static const double kTwoPi = 6.28318530717958647692;

static gcStatus check_def(gcGraspWorkspace *ws, const gcGraspDef *def) {
    if (def->edges < 3 || def->edges > GC_GRASP_MAX_EDGES)
        return gc_grasp_set_error(ws, GC_ERR_INVALID_ARGUMENT, "edges: %d, expected 3 to %d", def->edges, GC_GRASP_MAX_EDGES);
    if (!(def->tolerance > 0.0) || !(def->tolerance < 1e-3))
        return gc_grasp_set_error(ws, GC_ERR_INVALID_ARGUMENT, "tolerance: %g, expected in (0, 1e-3)", def->tolerance);
    if (def->max_facets < 16)
        return gc_grasp_set_error(ws, GC_ERR_INVALID_ARGUMENT, "max_facets: %d, expected >= 16", def->max_facets);
    return GC_OK;
}

/* Checks one contact set and writes its edge wrenches, forces and torques; *count = rows.
 * mu NULL: every contact has mu_all. A soft contact (def->torsion[i] = rho > 0) adds its two
 * torsion generators after its cone's edges. */
static gcStatus build_wrenches(gcGraspWorkspace *ws, const gcGraspDef *def, const double *points, const double *normals,
                               const double *mu, double mu_all, int num_contacts, const double center[3],
                               double radius, int *count) {
    if (num_contacts < 0)
        return gc_grasp_set_error(ws, GC_ERR_INVALID_ARGUMENT, "points: %d contacts, expected >= 0", num_contacts);
    if (num_contacts > 0 && (!points || !normals))
        return gc_grasp_set_error(ws, GC_ERR_INVALID_ARGUMENT, "%s: NULL", points ? "normals" : "points");
    if (!center) return gc_grasp_set_error(ws, GC_ERR_INVALID_ARGUMENT, "center: NULL");
    for (int k = 0; k < 3; ++k)
        if (!isfinite(center[k])) return gc_grasp_set_error(ws, GC_ERR_INVALID_ARGUMENT, "center: not finite");
    if (!(radius > 0.0) || !isfinite(radius))
        return gc_grasp_set_error(ws, GC_ERR_INVALID_ARGUMENT, "radius: %g, expected a finite number > 0", radius);
    const int edges = def->edges;
    const double *torsion = def->torsion;
    if ((long long)num_contacts * edges > 1000000)
        return gc_grasp_set_error(ws, GC_ERR_INVALID_ARGUMENT, "points: %d contacts x %d edges is too many", num_contacts,
                         edges);
    gcStatus st = gc_grasp_ensure_points(ws, num_contacts * (edges + (torsion ? 2 : 0)));
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
            return gc_grasp_set_error(ws, GC_ERR_INVALID_ARGUMENT, "points: row %d is not finite", i);
        if (!isfinite(nn[0]) || !isfinite(nn[1]) || !isfinite(nn[2]))
            return gc_grasp_set_error(ws, GC_ERR_INVALID_ARGUMENT, "normals: row %d is not finite", i);
        double len = sqrt(nn[0] * nn[0] + nn[1] * nn[1] + nn[2] * nn[2]);
        if (!(len > 1e-12))
            return gc_grasp_set_error(ws, GC_ERR_INVALID_ARGUMENT, "normals: row %d is a zero vector", i);
        if (!isfinite(m) || m < 0.0)
            return gc_grasp_set_error(ws, GC_ERR_INVALID_ARGUMENT, "mu: %g at contact %d, expected a finite number >= 0", m, i);
        if (torsion && (!isfinite(torsion[i]) || torsion[i] < 0.0))
            return gc_grasp_set_error(ws, GC_ERR_INVALID_ARGUMENT, "torsion: %g at contact %d, expected a finite number >= 0",
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
    if (!gc_hull_exact_plane(&h, &F)) return 0;
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
        if (!gc_grasp_grow((void **)&r->wrench, (size_t)rows * 6, sizeof(double)))
            return gc_grasp_set_error(ws, GC_ERR_NO_MEMORY, "workspace: out of memory");
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
    if (!out) return gc_grasp_set_error(ws, GC_ERR_INVALID_ARGUMENT, "out: NULL");
    memset(out, 0, sizeof *out);
    gcGraspDef dflt = gc_default_grasp_def();
    if (!def) def = &dflt;
    gcStatus st = check_def(ws, def);
    if (st != GC_OK) return st;
    if (num_contacts > 0 && !mu) return gc_grasp_set_error(ws, GC_ERR_INVALID_ARGUMENT, "mu: NULL");
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
    if (num_sets < 0) return gc_grasp_set_error(ws, GC_ERR_INVALID_ARGUMENT, "counts: %d sets, expected >= 0", num_sets);
    if (num_sets > 0 && (!counts || !centers || !radii || !out))
        return gc_grasp_set_error(ws, GC_ERR_INVALID_ARGUMENT, "%s: NULL",
                         !counts ? "counts" : !centers ? "centers" : !radii ? "radii" : "out");
    size_t row = 0;
    for (int s = 0; s < num_sets; ++s) {
        if (counts[s] < 0)
            return gc_grasp_set_error(ws, GC_ERR_INVALID_ARGUMENT, "counts: %d at set %d, expected >= 0", counts[s], s);
        gcGraspDef set_def = def ? *def : gc_default_grasp_def();
        if (set_def.torsion) set_def.torsion += row;
        gcStatus st = gc_grasp_quality(ws, &set_def, points ? points + 3 * row : NULL,
                                       normals ? normals + 3 * row : NULL, mu ? mu + row : NULL, counts[s],
                                       centers + 3 * s, radii[s], &out[s]);
        if (st != GC_OK) {
            char inner[sizeof ws->error];
            memcpy(inner, ws->error, sizeof inner);
            return gc_grasp_set_error(ws, st, "set %d: %s", s, inner);
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
        if (!gc_grasp_grow((void **)&m->input, (size_t)need, sizeof(double))) return;  /* not kept */
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
    if (!out_mu) return gc_grasp_set_error(ws, GC_ERR_INVALID_ARGUMENT, "out_mu: NULL");
    *out_mu = INFINITY;
    gcGraspDef dflt = gc_default_grasp_def();
    if (!def) def = &dflt;
    gcStatus st = check_def(ws, def);
    if (st != GC_OK) return st;
    if (!(mu_max >= 0.0) || !isfinite(mu_max))
        return gc_grasp_set_error(ws, GC_ERR_INVALID_ARGUMENT, "mu_max: %g, expected a finite number >= 0", mu_max);
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
            open = gc_closure_lp_warm(ws, ws->wrench, rows, 6, NULL, &t) == GC_OK && t <= 0.5 * def->tolerance / rows;
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
/* One mu_min search: the contacts, and what the last evaluation left (its rows, closure, summary,
 * LP margin t and optimal basis, which the next LP starts from). */
typedef struct MuSearch {
    gcGraspWorkspace *ws;
    const gcGraspDef *def;
    const double *points, *normals, *center;
    int num_contacts;
    double radius;
    int rows, closed;
    gcHullSummary summary;
    double t;
    int warm[D + 1];
} MuSearch;

/* In closure at mu as grasp_quality answers it (the LP, then the support search). */
static gcStatus closed_at(MuSearch *s, double mu) {
    gcStatus st = build_wrenches(s->ws, s->def, s->points, s->normals, NULL, mu, s->num_contacts, s->center,
                                 s->radius, &s->rows);
    if (st != GC_OK) return st;
    return closure_fast(s->ws, s->def, s->ws->wrench, s->rows, 6, 0, &s->closed, NULL, &s->summary);
}

/* The same LP with the margin it found: g(mu) = mu (t*(mu) - threshold), > 0 exactly when closed.
 * t* grows like a - b / mu over the range that matters (the edges' spread from the normal wrench
 * scales with mu), so g is close to a straight line and the root is found in a few secant steps. */
static gcStatus margin_at(MuSearch *s, double mu, double *g) {
    gcGraspWorkspace *ws = s->ws;
    gcStatus st = build_wrenches(ws, s->def, s->points, s->normals, NULL, mu, s->num_contacts, s->center,
                                 s->radius, &s->rows);
    if (st != GC_OK) return st;
    st = gc_closure_lp_warm(ws, ws->wrench, s->rows, 6, s->warm, &s->t);
    if (st == GC_ERR_DEGENERATE) {
        /* The LP did not converge: closed or not as grasp_quality decides, and a margin of
         * rounding size with that sign (Brent's method then bisects). */
        ws->error[0] = '\0';
        s->warm[0] = -1;
        if ((st = closure_fast(ws, s->def, ws->wrench, s->rows, 6, 0, &s->closed, NULL, &s->summary)) != GC_OK)
            return st;
        s->t = s->closed ? s->def->tolerance / s->rows : -1.0;
    } else if (st != GC_OK) {
        return st;
    }
    *g = mu * (fmax(s->t, -1.0) - 0.5 * s->def->tolerance / s->rows);
    return GC_OK;
}

/* Brent's method on g over [lo, b]: inverse quadratic or secant steps while they stay in the
 * bracket and shrink it fast enough, bisection otherwise; each step at least 0.4e-6, so the
 * bracket ends within 0.8e-6 around the root. b is the latest point, c the other end of the
 * bracket (g of the opposite sign), a the point before b. *root_open: the bracket's open end. */
static gcStatus brent_root(MuSearch *s, double lo, double glo, double b_start, double ghi, double *root_open) {
    const double step_min = 0.4e-6;
    double a = lo, b = b_start, c = lo, fa = glo, fb = ghi, fc = glo, d = b - a, e = b - a, g_closed = ghi;
    gcStatus st;
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
            double s_ = fb / fa, p, q;
            if (a == c) {
                p = 2.0 * half * s_;
                q = 1.0 - s_;
            } else {
                double qa = fa / fc, r = fb / fc;
                p = s_ * (2.0 * half * qa * (qa - r) - (b - a) * (r - 1.0));
                q = (qa - 1.0) * (r - 1.0) * (s_ - 1.0);
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
        if ((st = margin_at(s, b, &fb)) != GC_OK) return st;
        /* t* exactly 0 over a range of mu (the origin on a face of the hull, e.g. two contacts
         * that balance each other): no slope to follow, and a zero that is not the root. Minus
         * the last closed margin stands in for it, which sends the next step about halfway. */
        if (fb > 0.0)
            g_closed = fb;
        else if (fabs(s->t) <= 1e-12)
            fb = -g_closed;
    }
    *root_open = fb > 0.0 ? c : b;
    return GC_OK;
}

static gcStatus mu_min_search(gcGraspWorkspace *ws, const gcGraspDef *def, const double *points,
                              const double *normals, int num_contacts, const double center[3], double radius,
                              double mu_max, double *out_mu, double *margin, int *rows_at) {
    *margin = 0.0;
    *rows_at = 0;
    MuSearch s = {.ws = ws, .def = def, .points = points, .normals = normals, .center = center,
                  .num_contacts = num_contacts, .radius = radius, .warm = {-1}};
    gcStatus st;
    if ((st = closed_at(&s, 0.0)) != GC_OK) return st;     /* one wrench per contact */
    if (s.closed) {
        *out_mu = 0.0;
        *margin = s.summary.facets == -1 ? -s.summary.offset_max : 0.0;
        *rows_at = s.rows;
        return GC_OK;
    }
    if (mu_max == 0.0) return GC_OK;
    /* An LP "no" is never a "yes": not closed at mu_max. A "yes" is checked at the end. */
    double glo = 0.0, ghi = 0.0, b_start = mu_max;
    if ((st = margin_at(&s, mu_max, &ghi)) != GC_OK) return st;
    if (!(ghi > 0.0)) return GC_OK;
    /* The bracket's open end: mu_max / 100 if open there, else 0 (g(0) = 0 is no help to the
     * interpolation: -g(mu_max / 100) stands in for it). */
    double lo = 0.01 * mu_max, g1;
    if ((st = margin_at(&s, lo, &g1)) != GC_OK) return st;
    if (g1 > 0.0) {
        b_start = lo;
        ghi = g1;
        lo = 0.0;
        glo = -g1;
    } else {
        glo = fmin(g1, -1e-300);
    }
    double open_end;
    if ((st = brent_root(&s, lo, glo, b_start, ghi, &open_end)) != GC_OK) return st;
    /* The root is in (open end, open end + 0.8e-6]: answer open end + 1e-6, closed as well and
     * far enough from the root (about 0.2e-6 at least) for the LP's certificate to settle it
     * without the support search, most times. */
    double hi = fmin(open_end + 1e-6, mu_max);
    /* The LP may call a set closed whose origin is within the tolerance of the hull's boundary
     * (grasp_quality: not closed); the root it brackets is then below the closure's by about the
     * tolerance. Step up to the first mu grasp_quality calls closed; none up to mu_max: inf. */
    for (double step = 1e-9;; step *= 2.0) {
        if ((st = closed_at(&s, hi)) != GC_OK) return st;
        if (s.closed) break;
        if (hi >= mu_max) return GC_OK;
        hi = fmin(hi + step, mu_max);
    }
    *out_mu = hi;
    *margin = s.summary.facets == -1 ? -s.summary.offset_max : 0.0;   /* the search ran (facets -1) */
    *rows_at = s.rows;
    return GC_OK;
}
