/* The contact solver, per chain (docs/solver.md; in parallel, a chain's result depends
 * only on its own data): sequential impulses with the 6x6 effective masses; warm started;
 * Coulomb friction as a 2x2 block per point projected on the true (circular) cone; static
 * friction through friction anchors (no creep); then a split-impulse position pass that
 * removes penetration beyond the slop without adding kinetic energy. */
#define _POSIX_C_SOURCE 200809L
#include "contacts_internal.h"

#include <float.h>
#include <stdlib.h>
#include <string.h>


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
    const gcModel *model = w->model;
    gcPointScratch *scratch = scratch_of(w->contacts, m);
    const gcBody *A = &w->bodies[m->body_a], *B = &w->bodies[m->body_b];
    struct gcContactSystem *cs = w->contacts;
    const double *ma = model->bodies[m->body_a].is_static ? NULL : cs->inv_mass[m->body_a];
    const double *mb = model->bodies[m->body_b].is_static ? NULL : cs->inv_mass[m->body_b];
    gcVec3 dirs[3] = {m->normal, m->t1, m->t2};
    for (int k = 0; k < m->num_points; ++k) {
        gcManifoldPoint *p = &m->points[k];
        gcPointScratch *q = &scratch[k];
        gcVec3 ra = gc_sub(p->point, A->state.com), rb = gc_sub(p->point, B->state.com);
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
            gcVec3 wa = gc_add(A->state.com, gc_mat3_mul_vec(&A->state.R, p->anchor_a));
            gcVec3 wb = gc_add(B->state.com, gc_mat3_mul_vec(&B->state.R, p->anchor_b));
            gcVec3 da = gc_sub(wa, p->point), db = gc_sub(wb, p->point);
            da = gc_madd(da, m->normal, -gc_dot(da, m->normal));
            db = gc_madd(db, m->normal, -gc_dot(db, m->normal));
            if (gc_len(da) > GC_ANCHOR_RESET || gc_len(db) > GC_ANCHOR_RESET) p->anchored = 0;
        }
        if (m->sticking && !p->anchored) {
            p->anchor_a = gc_mat3_tmul_vec(&A->state.R, gc_sub(p->point, A->state.com));
            p->anchor_b = gc_mat3_tmul_vec(&B->state.R, gc_sub(p->point, B->state.com));
            p->anchored = 1;
        } else if (m->sticking) {
            gcVec3 wa = gc_add(A->state.com, gc_mat3_mul_vec(&A->state.R, p->anchor_a));
            gcVec3 wb = gc_add(B->state.com, gc_mat3_mul_vec(&B->state.R, p->anchor_b));
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
    const gcModel *model = w->model;
    SolverBodies s;
    gcBody *A = &w->bodies[m->body_a], *B = &w->bodies[m->body_b];
    /* A body without a valid effective mass (degenerate, or stepped by another runtime
     * thread this step) is immovable here and never written. */
    int da = !model->bodies[m->body_a].is_static && A->effective_mass_valid;
    int db = !model->bodies[m->body_b].is_static && B->effective_mass_valid;
    if (lin) { /* pseudo-velocities of the position pass */
        s.va = da ? &lin[m->body_a] : NULL;
        s.wa = da ? &ang[m->body_a] : NULL;
        s.vb = db ? &lin[m->body_b] : NULL;
        s.wb = db ? &ang[m->body_b] : NULL;
    } else {
        s.va = da ? &A->state.v : NULL;
        s.wa = da ? &A->state.w : NULL;
        s.vb = db ? &B->state.v : NULL;
        s.wb = db ? &B->state.w : NULL;
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
    const gcModel *model = w->model;
    struct gcContactSystem *cs = w->contacts;
    if (!cs || chain < 0 || chain >= cs->num_chains) return;
    int m0 = cs->chain_manifold_start[chain], m1 = cs->chain_manifold_start[chain + 1];
    if (m0 == m1) return;
    const int32_t *list = cs->chain_manifolds;
    int b0 = cs->chain_body_start[chain], b1 = cs->chain_body_start[chain + 1];
    /* Each body's inverse effective mass (with the finger coupling), once per step. */
    for (int i = b0; i < b1; ++i) {
        int32_t id = cs->chain_bodies[i];
        gc_body_inverse_effective_mass(&model->bodies[id], &w->bodies[id], cs->inv_mass[id]);
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
        b->state.com = gc_madd(b->state.com, pv, dt);
        b->state.q = gc_quat_normalize(gc_quat_mul(gc_quat_from_rotation_vector(gc_scale(pw, dt)), b->state.q));
        b->state.R = gc_quat_to_mat3(b->state.q);
    }
}

#define GC_POOL_MIN_POINTS 128 /* solver on the pool when the chains besides the largest have this many points */

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

