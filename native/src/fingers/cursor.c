/* The light-mass haptic cursor (the source chapter, Harwin & Barrow, §2.4.1.2): a finger
 * renderer beside xFCA, chosen per finger. The cursor is a very light mass m coupled to the
 * HIP by the finger's spring k and damper c, kept outside every convex part of every body
 * by a constraint solve against all the parts it could reach in the tick together, so it
 * cannot fall into the cracks between them; friction by the friction-cone rule on its
 * contact. docs/physics.md, "The light-mass cursor".
 *
 * One tick, world frame:
 * 1. Free motion, backward Euler (stable for any m, k, c at the haptic rate):
 *      (m + c dt + k dt^2) v' = m v + dt (k (HIP - x0) + c v_HIP),   x* = x0 + dt v'.
 * 2. Constraints, linearised at the cursor's position x_l (first x0, which is outside every
 *    part): per part whose inflated surface the cursor could reach, the plane through the
 *    closest surface point with the surface normal. For a convex part that plane separates
 *    the whole part from x_l, so any point on its outer side is outside the part: the solve
 *    can never cross a part, however thin and however fast the HIP (no push-through).
 * 3. The frictionless position: the projection of x* onto the intersection of those half
 *    spaces, exact: at most three planes are active in 3-D, so every active set of one, two
 *    or three planes is tried and the one meeting the KKT conditions (feasible, multipliers
 *    >= 0) is the answer. Then the planes are taken again at the new position (x_l moves
 *    toward x*, never away: x_l satisfies the new planes) and the projection repeated,
 *    GC_CURSOR_LINEARISATIONS times at most. Worst case per finger per tick:
 *    GC_CURSOR_LINEARISATIONS x (a point query per part in reach + 92 active sets of 8
 *    planes) for the projection, and as many again for a slip on a curved surface.
 * 4. Friction on the contact (friction-cone rule): the constraint pushed the cursor by
 *    depth d = |x_f - x*| along the contact normal; the previous contact point stays (stick)
 *    while it lies within mu_s d of x_f in the tangent plane, else the cursor goes to the
 *    mu_d d circle (slip), re-projected onto the constraints. So |F_t| <= mu |F_n| for the
 *    spring, as in xFCA.
 * The contact is stored as one finger contact per active part (its god-object is the
 * cursor, body frame; its share the part's part of the constraint's multipliers), so the
 * body gets the reaction at the cursor through the same implicit coupling as xFCA's
 * god-objects (dynamics.c) and the cursor rides with the body it touches. */
#include "cursor.h"

#include <string.h>

#define GC_CURSOR_LINEARISATIONS 4
#define GC_CURSOR_MAX_PLANES GC_MAX_CONTACTS_PER_FINGER
/* Distances below this count as touching (m). */
#define GC_CURSOR_SLOP 1e-9
/* A Gram matrix of an active set whose determinant is below this (relative) is degenerate
 * (parallel planes): the set is skipped, a smaller one covers it. */
#define GC_CURSOR_SINGULAR 1e-12

typedef struct gcCursorPlane {
    gcVec3 n, c; /* outward unit normal and a point: the half-space n.(x - c) >= 0 */
    int32_t part;
} gcCursorPlane;

/* Signed distance of the cursor's centre to a part's surface inflated by the finger radius,
 * with the closest point and the outward normal, world frame. */
static double part_query(const gcWorld *w, const gcFingerModel *fm, int32_t p, gcVec3 x, gcVec3 *normal) {
    const gcModel *model = w->model;
    const gcPart *part = &model->parts[p];
    gcTransform fr = gc_world_body_transform(w, part->body);
    double sd;
    gcVec3 sp, n;
    gc_point_query(&part->hull, gc_inv_transform_point(&fr, x), &sd, &sp, &n);
    *normal = gc_mat3_mul_vec(&fr.R, n);
    return sd - fm->radius;
}

/* The planes of step 2 at x, for the parts the cursor could reach going to `target`: the
 * nearest GC_CURSOR_MAX_PLANES of them. */
static int gather_planes(const gcWorld *w, const gcFingerModel *fm, gcVec3 x, gcVec3 target, gcCursorPlane *planes) {
    const gcModel *model = w->model;
    double reach = gc_len(gc_sub(target, x)) + GC_CURSOR_SLOP;
    double dist[GC_CURSOR_MAX_PLANES];
    int count = 0;
    gcVec3 lo = gc_v3(fmin(x.x, target.x), fmin(x.y, target.y), fmin(x.z, target.z));
    gcVec3 hi = gc_v3(fmax(x.x, target.x), fmax(x.y, target.y), fmax(x.z, target.z));
    gcVec3 pad = gc_v3(fm->radius, fm->radius, fm->radius);
    lo = gc_sub(lo, pad);
    hi = gc_add(hi, pad);
    for (int32_t bi = 0; bi < w->num_bodies; ++bi) {
        const gcBody *b = &w->bodies[bi];
        const gcBodyModel *m = &model->bodies[bi];
        if (!gc_aabb_overlap(lo, hi, b->state.aabb_min, b->state.aabb_max)) continue;
        for (int32_t p = m->first_part; p < m->first_part + m->num_parts; ++p) {
            gcVec3 n;
            double sd = part_query(w, fm, p, x, &n);
            if (sd > reach) continue;
            /* Keep the nearest: insert by distance, dropping the farthest when full. */
            int at = count < GC_CURSOR_MAX_PLANES ? count : GC_CURSOR_MAX_PLANES - 1;
            if (count == GC_CURSOR_MAX_PLANES && sd >= dist[at]) continue;
            while (at > 0 && dist[at - 1] > sd) {
                dist[at] = dist[at - 1];
                planes[at] = planes[at - 1];
                --at;
            }
            dist[at] = sd;
            planes[at].n = n;
            planes[at].c = gc_madd(x, n, -sd);
            planes[at].part = p;
            if (count < GC_CURSOR_MAX_PLANES) ++count;
        }
    }
    return count;
}

static double violation(const gcCursorPlane *pl, gcVec3 x) { return gc_dot(pl->n, gc_sub(x, pl->c)); }

/* Projection of `target` onto the active set s (k = 1..3 planes): x = target + sum l_i n_i
 * on all k planes. 0 when degenerate or a multiplier is negative. */
static int project_on(const gcCursorPlane *planes, const int *s, int k, gcVec3 target, gcVec3 *x, double *lambda) {
    double G[3][3], r[3];
    for (int i = 0; i < k; ++i) {
        r[i] = -violation(&planes[s[i]], target);
        for (int j = 0; j < k; ++j) G[i][j] = gc_dot(planes[s[i]].n, planes[s[j]].n);
    }
    double l[3] = {0, 0, 0};
    if (k == 1) {
        l[0] = r[0];
    } else if (k == 2) {
        double det = G[0][0] * G[1][1] - G[0][1] * G[1][0];
        if (!(fabs(det) > GC_CURSOR_SINGULAR)) return 0;
        l[0] = (r[0] * G[1][1] - G[0][1] * r[1]) / det;
        l[1] = (G[0][0] * r[1] - G[1][0] * r[0]) / det;
    } else {
        gcVec3 c0 = gc_v3(G[0][0], G[1][0], G[2][0]), c1 = gc_v3(G[0][1], G[1][1], G[2][1]),
               c2 = gc_v3(G[0][2], G[1][2], G[2][2]);
        gcVec3 r0 = gc_cross(c1, c2), r1 = gc_cross(c2, c0), r2 = gc_cross(c0, c1);
        double det = gc_dot(c0, r0);
        if (!(fabs(det) > GC_CURSOR_SINGULAR)) return 0;
        gcVec3 rv = gc_v3(r[0], r[1], r[2]);
        l[0] = gc_dot(r0, rv) / det, l[1] = gc_dot(r1, rv) / det, l[2] = gc_dot(r2, rv) / det;
    }
    gcVec3 p = target;
    for (int i = 0; i < k; ++i) {
        if (l[i] < 0.0) return 0;
        p = gc_madd(p, planes[s[i]].n, l[i]);
        lambda[i] = l[i];
    }
    *x = p;
    return 1;
}

static int feasible(const gcCursorPlane *planes, int count, gcVec3 x) {
    for (int i = 0; i < count; ++i)
        if (violation(&planes[i], x) < -GC_CURSOR_SLOP) return 0;
    return 1;
}

/* Step 3: the exact projection of target onto the planes' half spaces. `from` satisfies
 * them all (the answer when no active set qualifies, which only round-off can cause).
 * lambda_out[i] is plane i's multiplier. */
static gcVec3 project(const gcCursorPlane *planes, int count, gcVec3 target, gcVec3 from, double *lambda_out) {
    for (int i = 0; i < count; ++i) lambda_out[i] = 0.0;
    if (feasible(planes, count, target)) return target;
    gcVec3 best = from;
    double best_dist = INFINITY;
    int s[3];
    double lambda[3];
    int best_set[3] = {-1, -1, -1}, best_k = 0;
    double best_lambda[3] = {0, 0, 0};
    /* Every active set of one, two and three planes: at most 8 + 28 + 56 = 92. */
    for (int k = 1; k <= 3 && k <= count; ++k) {
        int last = count - k; /* s[0] <= last */
        for (s[0] = 0; s[0] <= last; ++s[0])
            for (s[1] = s[0] + 1; s[1] <= (k > 1 ? count - k + 1 : s[0] + 1); ++s[1])
                for (s[2] = s[1] + 1; s[2] <= (k > 2 ? count - 1 : s[1] + 1); ++s[2]) {
                    gcVec3 x;
                    if (project_on(planes, s, k, target, &x, lambda) && feasible(planes, count, x)) {
                        double d = gc_len2(gc_sub(x, target));
                        if (d < best_dist) {
                            best = x, best_dist = d, best_k = k;
                            for (int i = 0; i < k; ++i) best_set[i] = s[i], best_lambda[i] = lambda[i];
                        }
                    }
                }
    }
    for (int i = 0; i < best_k; ++i) lambda_out[best_set[i]] = best_lambda[i];
    return best;
}

/* Steps 2-3 from a feasible `from` toward `target`: planes re-taken at each new position. */
static gcVec3 solve(const gcWorld *w, const gcFingerModel *fm, gcVec3 from, gcVec3 target, gcCursorPlane *planes,
                    int *count, double *lambda) {
    gcVec3 x = from;
    *count = 0;
    for (int it = 0; it < GC_CURSOR_LINEARISATIONS; ++it) {
        *count = gather_planes(w, fm, x, target, planes);
        gcVec3 next = project(planes, *count, target, x, lambda);
        double moved = gc_len(gc_sub(next, x));
        x = next;
        if (moved <= GC_CURSOR_SLOP) break;
    }
    return x;
}

/* The cursor's position at the start of the tick: on the body it touches (moved with it),
 * else where it was left. */
static gcVec3 cursor_position(const gcWorld *w, const gcFinger *f) {
    const gcModel *model = w->model;
    if (f->num_contacts == 0) return f->cursor;
    const gcFingerContact *c = &f->contacts[0];
    gcTransform fr = gc_world_body_transform(w, model->parts[c->part].body);
    return gc_transform_point(&fr, c->go_local);
}

void gc_cursor_finger_update(gcWorld *w, int32_t id, double dt) {
    const gcModel *model = w->model;
    gcFinger *f = &w->fingers[id];
    const gcFingerModel *fm = &model->fingers[id];
    f->hip_velocity = gc_scale(gc_sub(f->hip, f->hip_prev), 1.0 / dt);
    gcVec3 x0 = cursor_position(w, f);
    int was_touching = f->num_contacts > 0;
    gcFingerState was = was_touching ? f->contacts[0].state : GC_FINGER_FREE;
    /* A body moved onto the cursor: leave along the least penetration first. */
    for (int pass = 0; pass < 2; ++pass) {
        gcCursorPlane inside[GC_CURSOR_MAX_PLANES];
        int count = gather_planes(w, fm, x0, x0, inside);
        gcVec3 out = x0;
        for (int i = 0; i < count; ++i)
            if (violation(&inside[i], x0) < 0.0) out = gc_madd(out, inside[i].n, -violation(&inside[i], x0));
        x0 = out;
    }
    /* 1. Free motion (backward Euler). */
    double k = fm->stiffness, c = fm->damping, m = fm->cursor_mass;
    double a = m + c * dt + k * dt * dt;
    gcVec3 mom = gc_scale(f->cursor_velocity, m);
    gcVec3 pull = gc_add(gc_scale(gc_sub(f->hip, x0), k), gc_scale(f->hip_velocity, c));
    gcVec3 v = gc_scale(gc_madd(mom, pull, dt), 1.0 / a);
    gcVec3 target = gc_madd(x0, v, dt);
    /* 2-3. The frictionless position against every part in reach. */
    gcCursorPlane planes[GC_CURSOR_MAX_PLANES];
    double lambda[GC_CURSOR_MAX_PLANES];
    int count;
    gcVec3 xf = solve(w, fm, x0, target, planes, &count, lambda);
    gcVec3 push = gc_sub(xf, target);
    double depth = gc_len(push);
    gcVec3 x = xf;
    gcFingerState state = GC_FINGER_FREE;
    double lambda_sum = 0.0;
    for (int i = 0; i < count; ++i) lambda_sum += lambda[i];
    if (lambda_sum > 0.0 && depth > 0.0) {
        /* 4. Friction on the contact, mu of the part that carries most of it. */
        int main_plane = 0;
        for (int i = 1; i < count; ++i)
            if (lambda[i] > lambda[main_plane]) main_plane = i;
        const gcBodyModel *b = &model->bodies[model->parts[planes[main_plane].part].body];
        gcVec3 n = gc_scale(push, 1.0 / depth);
        gcVec3 offset = gc_sub(x0, xf);
        offset = gc_madd(offset, n, -gc_dot(offset, n));
        double dist = gc_len(offset);
        double radius = (was == GC_FINGER_STICK ? b->mu_s : b->mu_d) * depth;
        if (was_touching && dist <= radius) {
            x = x0; /* stick: the contact point stays (x0 is outside every part) */
            state = GC_FINGER_STICK;
        } else if (was_touching && dist > 0.0) {
            /* Slip onto the mu_d circle, then back onto the constraints from x_f. */
            gcVec3 slip = gc_madd(xf, offset, b->mu_d * depth / dist);
            gcCursorPlane sp[GC_CURSOR_MAX_PLANES];
            double sl[GC_CURSOR_MAX_PLANES];
            int sc;
            x = solve(w, fm, xf, slip, sp, &sc, sl);
            state = GC_FINGER_SLIP;
            /* The parts it rests on now: those of the slip's solve that hold it, else the
             * frictionless solve's (a slip within one face meets no new plane). */
            double sum = 0.0;
            for (int i = 0; i < sc; ++i) sum += sl[i];
            if (sum > 0.0) {
                memcpy(planes, sp, (size_t)sc * sizeof *sp);
                memcpy(lambda, sl, (size_t)sc * sizeof *sl);
                count = sc;
                lambda_sum = sum;
            }
        } else {
            state = GC_FINGER_STICK; /* first touch: where the constraint put it */
        }
    }
    /* The contacts: one per part the constraint pushes on, the cursor as their god-object. */
    f->num_contacts = 0;
    for (int i = 0; i < count && lambda_sum > 0.0; ++i) {
        if (!(lambda[i] > 0.0)) continue;
        const gcPart *part = &model->parts[planes[i].part];
        gcTransform fr = gc_world_body_transform(w, part->body);
        gcFingerContact *fc = &f->contacts[f->num_contacts++];
        memset(fc, 0, sizeof *fc);
        fc->part = planes[i].part;
        fc->state = state;
        fc->go_local = gc_inv_transform_point(&fr, x);
        fc->normal_local = gc_mat3_tmul_vec(&fr.R, planes[i].n);
        fc->depth = depth * lambda[i] / lambda_sum;
        fc->share = lambda[i] / lambda_sum;
    }
    f->cursor_velocity = gc_scale(gc_sub(x, f->cursor), 1.0 / dt);
    f->cursor = x;
}

void gc_cursor_finger_outputs(gcWorld *w, int32_t id) {
    const gcModel *model = w->model;
    gcFinger *f = &w->fingers[id];
    const gcFingerModel *fm = &model->fingers[id];
    gcVec3 x = cursor_position(w, f), v = f->cursor_velocity;
    f->normal = gc_v3(0, 0, 0);
    f->contact_body = -1;
    f->state = GC_FINGER_FREE;
    double deepest = -1.0;
    for (int i = 0; i < f->num_contacts; ++i) {
        const gcFingerContact *c = &f->contacts[i];
        const gcBody *b = &w->bodies[model->parts[c->part].body];
        f->normal = gc_madd(f->normal, gc_mat3_mul_vec(&b->state.R, c->normal_local), c->share);
        if (c->depth > deepest) {
            deepest = c->depth;
            f->contact_body = model->parts[c->part].body;
            f->state = c->state;
            /* Touching, it moves with the body point under it. */
            v = model->bodies[f->contact_body].is_static
                    ? gc_v3(0, 0, 0)
                    : gc_add(b->state.v, gc_cross(b->state.w, gc_sub(x, b->state.com)));
        }
    }
    double nl = gc_len(f->normal);
    if (nl > 0.0) f->normal = gc_scale(f->normal, 1.0 / nl);
    f->cursor = x;
    f->god_object = x;
    f->force = gc_add(gc_scale(gc_sub(x, f->hip), fm->stiffness), gc_scale(gc_sub(v, f->hip_velocity), fm->damping));
    double *out = &w->force_array[3 * id];
    out[0] = f->force.x, out[1] = f->force.y, out[2] = f->force.z;
    out = &w->god_object_array[3 * id];
    out[0] = x.x, out[1] = x.y, out[2] = x.z;
}
