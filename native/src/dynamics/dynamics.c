/* Newton-Euler integration of dynamic bodies with an implicit finger coupling.
 *
 * Each finger contact is a spring k (and damper c) between the HIP and the body point
 * under the god-object. Stepped explicitly at 1 kHz, a light thin object held by stiff
 * fingers has modes far above the step rate and explodes (docs/physics.md), so the springs
 * are integrated with backward Euler, linearised about the current pose:
 *
 *   (M' + sum (k dt^2 + c dt) J^T J) v' = M v + dt (F_ext + sum J^T (f_spring + c v_hip))
 *
 * with J = [I | -[r]x] mapping the body twist to the velocity of the god-object at r
 * from the centre of mass. M is 6x6 block diagonal (m I, R I_body R^T); with the
 * gyroscopic term, L = I w has first turned for dt of free rotation (gyroscopic_rotation,
 * docs/physics.md), which keeps energy and |L| however fast the spin. The pose is
 * then advanced with the new twist: x += v' dt and R <- exp([w' dt]x) R, the world-frame
 * update the source chapter (Harwin & Barrow, "Multi-finger grasps in a dynamic
 * environment") prints transposed. */
#include "dynamics.h"

#include <string.h>

/* A += s * J^T J for J = [I | -[r]x]. */
static void add_point_coupling(double A[6][6], gcVec3 r, double s) {
    double rv[3] = {r.x, r.y, r.z};
    /* [r]x */
    double S[3][3] = {{0, -r.z, r.y}, {r.z, 0, -r.x}, {-r.y, r.x, 0}};
    double r2 = gc_len2(r);
    for (int i = 0; i < 3; ++i) {
        A[i][i] += s;
        for (int j = 0; j < 3; ++j) {
            A[i][3 + j] -= s * S[i][j];           /* I * (-[r]x) */
            A[3 + i][j] += s * S[i][j];           /* [r]x * I */
            A[3 + i][3 + j] += s * ((i == j ? r2 : 0.0) - rv[i] * rv[j]); /* -[r]x[r]x */
        }
    }
}

/* I_world w without forming I_world: R (I_body (R^T w)). */
static gcVec3 angular_momentum(const gcMat3 *R, const gcMat3 *inertia_local, gcVec3 w) {
    gcVec3 local = gc_mat3_tmul_vec(R, w);
    return gc_mat3_mul_vec(R, gc_mat3_mul_vec(inertia_local, local));
}

/* 3x3 solve by the adjugate (the Jacobian below is I + O(|w| dt), well conditioned). */
static gcVec3 solve3(const gcMat3 *A, gcVec3 b) {
    const double (*m)[3] = A->m;
    gcVec3 c0 = gc_v3(m[0][0], m[1][0], m[2][0]), c1 = gc_v3(m[0][1], m[1][1], m[2][1]),
           c2 = gc_v3(m[0][2], m[1][2], m[2][2]);
    gcVec3 r0 = gc_cross(c1, c2), r1 = gc_cross(c2, c0), r2 = gc_cross(c0, c1);
    double inv_det = 1.0 / gc_dot(c0, r0);
    return gc_v3(gc_dot(r0, b) * inv_det, gc_dot(r1, b) * inv_det, gc_dot(r2, b) * inv_det);
}

/* Largest rotation angle |w| h of one midpoint sub-step; Newton converges in a few
 * iterations below it. Spins of 2,000 rad/s at dt = 10 ms take 80 sub-steps. */
#define GC_GYRO_MAX_ANGLE 0.25
#define GC_GYRO_NEWTON_ITERATIONS 6
#define GC_GYRO_MAX_SUBSTEPS 256

/* Torque-free rotation of the body-frame angular momentum over dt: Euler's equation
 * dL/dt = L x (I^-1 L) by the implicit midpoint rule. Both |L|^2 and the kinetic energy
 * L.I^-1 L/2 are quadratic in L, and the midpoint rule keeps every quadratic invariant, so
 * neither can grow however fast the spin (the explicit w x Jw term, and the former
 * end-of-step inertia fixed point, both gain energy at a few hundred rad/s). Each sub-step
 * solves m = L + (h/2) m x (I^-1 m) for the midpoint m by Newton, then L' = 2m - L. */
static gcVec3 free_rotation(gcVec3 L, const gcMat3 *inv_inertia, double dt) {
    double spin = gc_len(gc_mat3_mul_vec(inv_inertia, L)) * dt;
    int substeps = (int)ceil(spin / GC_GYRO_MAX_ANGLE);
    if (substeps < 1) substeps = 1;
    if (substeps > GC_GYRO_MAX_SUBSTEPS) substeps = GC_GYRO_MAX_SUBSTEPS;
    double half = 0.5 * dt / substeps;
    for (int s = 0; s < substeps; ++s) {
        /* Explicit predictor, then Newton until the residual is at rounding level. */
        gcVec3 m = gc_madd(L, gc_cross(L, gc_mat3_mul_vec(inv_inertia, L)), half);
        for (int it = 0; it < GC_GYRO_NEWTON_ITERATIONS; ++it) {
            gcVec3 om = gc_mat3_mul_vec(inv_inertia, m);
            gcVec3 residual = gc_sub(gc_sub(m, L), gc_scale(gc_cross(m, om), half));
            if (!(gc_len2(residual) > 1e-32 * gc_len2(m))) break;
            /* d/dm (m x A m) = [m]x A - [A m]x */
            gcMat3 J;
            for (int j = 0; j < 3; ++j) {
                gcVec3 col = gc_v3(inv_inertia->m[0][j], inv_inertia->m[1][j], inv_inertia->m[2][j]);
                gcVec3 e = gc_v3(j == 0, j == 1, j == 2);
                gcVec3 d = gc_sub(gc_cross(m, col), gc_cross(om, e));
                J.m[0][j] = e.x - half * d.x, J.m[1][j] = e.y - half * d.y, J.m[2][j] = e.z - half * d.z;
            }
            m = gc_sub(m, solve3(&J, residual));
        }
        L = gc_sub(gc_scale(m, 2.0), L);
    }
    return L;
}

/* Rotation vector of the smallest rotation taking direction u onto direction t. */
static gcVec3 rotation_between(gcVec3 u, gcVec3 t) {
    gcVec3 axis = gc_cross(u, t);
    double s = gc_len(axis), c = gc_dot(u, t);
    if (!(s > 0.0)) return gc_v3(0, 0, 0);
    if (s < 1e-6 * c) return gc_scale(axis, 1.0 / c); /* tan = angle to 1e-12 of it */
    return gc_scale(axis, atan2(s, c) / s);
}

/* Below this rotation per step (|w| dt, rad) the term changes w by less than 1e-9 of
 * itself (w^2 dt against w): a body held or at rest skips it. */
#define GC_GYRO_NEGLIGIBLE_SPIN 1e-9
/* Below this, the pose correction (third order in |w| dt, ~1e-13 rad here) is skipped. */
#define GC_GYRO_NEGLIGIBLE_HAIR 1e-4

/* The gyroscopic term, before the forces: the body's angular velocity after dt of free
 * rotation (world frame). The body-frame momentum L_b' keeps |L| and the energy; the pose
 * the step will reach, R' = exp([w' dt]) R, then holds the world momentum R' L_b' a hair
 * (third order in |w| dt) off the one it started with. Turning the start pose by that
 * hair, about the centre of mass, makes the step end on the starting world momentum
 * exactly, so a free body keeps L (vector), |L| and its energy to round-off. */
static gcVec3 gyroscopic_rotation(const gcBodyModel *m, gcBody *b, double dt) {
    double spin = gc_len(b->state.w) * dt;
    if (!(spin > GC_GYRO_NEGLIGIBLE_SPIN)) return b->state.w;
    gcVec3 L_world = angular_momentum(&b->state.R, &m->inertia_local, b->state.w);
    gcVec3 L_body = gc_mat3_tmul_vec(&b->state.R, L_world);
    gcVec3 L_end = free_rotation(L_body, &m->inv_inertia_local, dt);
    /* A spin too fast for the sub-step cap can break Newton down: then hold the body-frame
     * momentum (energy and |L| exactly kept, the precession of this step lost). */
    if (!gc_vec_finite(L_end)) L_end = L_body;
    /* Round-off guard: never more |L| or energy than at the start. */
    gcVec3 om_body = gc_mat3_mul_vec(&m->inv_inertia_local, L_body);
    gcVec3 om_end = gc_mat3_mul_vec(&m->inv_inertia_local, L_end);
    double shrink = 1.0, e0 = gc_dot(L_body, om_body), e1 = gc_dot(L_end, om_end);
    double l0 = gc_len2(L_body), l1 = gc_len2(L_end);
    if (e1 > e0) shrink = sqrt(e0 / e1);
    if (l1 * shrink * shrink > l0) shrink = sqrt(l0 / l1);
    if (!(shrink == 1.0)) {
        if (!isfinite(shrink)) return b->state.w;
        L_end = gc_scale(L_end, shrink);
        om_end = gc_scale(om_end, shrink);
    }
    gcVec3 om_world = gc_mat3_mul_vec(&b->state.R, om_end);
    if (spin < GC_GYRO_NEGLIGIBLE_HAIR) return om_world;
    gcMat3 R_end = gc_quat_to_mat3(gc_quat_mul(gc_quat_from_rotation_vector(gc_scale(om_world, dt)), b->state.q));
    gcVec3 hair = rotation_between(gc_mat3_mul_vec(&R_end, L_end), L_world);
    if (gc_len2(hair) > 0.0) {
        b->state.q = gc_quat_normalize(gc_quat_mul(gc_quat_from_rotation_vector(hair), b->state.q));
        b->state.R = gc_quat_to_mat3(b->state.q);
    }
    return gc_mat3_mul_vec(&b->state.R, om_end);
}

static void integrate_velocity(gcWorld *w, int32_t id, double dt) {
    const gcModel *model = w->model;
    gcBody *b = &w->bodies[id];
    const gcBodyModel *m = &model->bodies[id];
    b->step_start_com = b->state.com;
    b->step_start_q = b->state.q;
    b->step_start_momentum = gc_scale(b->state.v, m->mass);
    b->step_start_angular_momentum = angular_momentum(&b->state.R, &m->inertia_local, b->state.w);
    gcVec3 L = b->step_start_angular_momentum;
    if (w->def.gyroscopic) L = angular_momentum(&b->state.R, &m->inertia_local, gyroscopic_rotation(m, b, dt));
    gcVec3 force = gc_scale(model->gravity, m->mass);
    gcVec3 torque = gc_v3(0, 0, 0);
    double C[6][6]; /* finger coupling: sum (k dt^2 + c dt) J^T J */
    int coupled = 0;

    gcTransform frame = gc_body_transform(m, &b->state);
    for (int fi = 0; fi < w->num_fingers; ++fi) {
        const gcFinger *f = &w->fingers[fi];
        const gcFingerModel *fm = &model->fingers[fi];
        for (int ci = 0; ci < f->num_contacts; ++ci) {
            const gcFingerContact *c = &f->contacts[ci];
            if (model->parts[c->part].body != id) continue;
            if (!coupled) memset(C, 0, sizeof C);
            coupled = 1;
            /* The reaction acts at the GO (docs/physics.md), which moves rigidly with the body
             * while it sticks: the same lever in the torque and in the coupling keeps the
             * implicit model consistent with the explicit force. */
            gcVec3 tip, tip_velocity, go;
            gc_finger_contact_ends(fm, f, c, &frame, &tip, &tip_velocity, &go);
            gcVec3 r = gc_sub(go, b->state.com);
            /* Weighted as the finger's force is (xfca.c: seams of a decomposed body; cursor.c). */
            double k = fm->stiffness * c->share, damping = fm->damping * c->share;
            gcVec3 spring = gc_scale(gc_sub(tip, go), k);
            /* Implicit part: the velocity-dependent terms move into the matrix. */
            gcVec3 explicit_part = gc_madd(spring, tip_velocity, damping);
            force = gc_add(force, explicit_part);
            torque = gc_add(torque, gc_cross(r, explicit_part));
            add_point_coupling(C, r, k * dt * dt + damping * dt);
            if (fm->torsion > 0.0) {
                /* A soft fingertip's twist spring k rho^2 about the normal (weighted as its spring),
                 * implicit as the springs: the body's spin about n this step unwinds it by dt (n . w'). */
                gcVec3 n = gc_mat3_mul_vec(&b->state.R, c->normal_local);
                double kt = k * fm->torsion * fm->torsion;
                torque = gc_madd(torque, n, kt * c->twist);
                double nv[3] = {n.x, n.y, n.z};
                for (int i = 0; i < 3; ++i)
                    for (int j = 0; j < 3; ++j) C[3 + i][3 + j] += kt * dt * dt * nv[i] * nv[j];
            }
        }
    }

    gcVec3 p = gc_add(b->step_start_momentum, gc_scale(force, dt));
    gcVec3 Lnew = gc_add(L, gc_scale(torque, dt));
    /* With the gyroscopic term, L is already the momentum after dt of free rotation and the
     * pose has taken its hair (gyroscopic_rotation); the forces act on the inertia there. */
    gcVec3 v, omega;
    b->coupled = coupled;
    b->inertia_rotation = b->state.R; /* contacts form R I^-1 R^T from it, for bodies that touch */
    if (!coupled) {
        /* No finger on it: the effective mass is the block-diagonal mass matrix, inverted
         * directly (no 6x6 factor); contacts use the same blocks. */
        v = gc_scale(p, m->inv_mass);
        gcVec3 L_body = gc_mat3_tmul_vec(&b->state.R, Lnew);
        omega = gc_mat3_mul_vec(&b->state.R, gc_mat3_mul_vec(&m->inv_inertia_local, L_body));
        b->effective_mass_valid = 1;
    } else {
        double rhs[6] = {p.x, p.y, p.z, Lnew.x, Lnew.y, Lnew.z}, x[6];
        gcMat3 inertia_world = gc_to_world(&b->state.R, &m->inertia_local);
        double A[6][6];
        memcpy(A, C, sizeof A);
        for (int i = 0; i < 3; ++i) {
            A[i][i] += m->mass;
            for (int j = 0; j < 3; ++j) A[3 + i][3 + j] += inertia_world.m[i][j];
        }
        b->effective_mass_valid = gc_cholesky6(A, b->effective_mass_factor);
        if (!b->effective_mass_valid) { /* only a non-finite input gets here */
            b->nonfinite = 1;
            return;
        }
        gc_cholesky_solve6(b->effective_mass_factor, rhs, x);
        omega = gc_v3(x[3], x[4], x[5]);
        v = gc_v3(x[0], x[1], x[2]);
    }
    gcVec3 om = omega;
    if (m->linear_damping > 0.0) v = gc_scale(v, 1.0 / (1.0 + dt * m->linear_damping));
    if (m->angular_damping > 0.0) om = gc_scale(om, 1.0 / (1.0 + dt * m->angular_damping));
    if (!gc_vec_finite(v) || !gc_vec_finite(om)) {
        b->effective_mass_valid = 0; /* immovable in the contact solve; stopped after it */
        b->nonfinite = 1;
        return;
    }
    b->state.v = v;
    b->state.w = om;
}

void gc_dynamics_velocities(gcWorld *w, double dt) {
    const gcModel *model = w->model;
    for (int32_t i = 0; i < w->num_bodies; ++i) {
        gcBody *b = &w->bodies[i];
        if (model->bodies[i].is_static) {
            b->state.residual_force = gc_v3(0, 0, 0);
            b->state.residual_torque = gc_v3(0, 0, 0);
            continue;
        }
        if (w->body_active && !w->body_active[i]) {
            b->effective_mass_valid = 0; /* another runtime thread steps it: immovable here */
            continue;
        }
        integrate_velocity(w, i, dt);
    }
}

static int body_state_finite(const gcBody *b) {
    return gc_vec_finite(b->state.com) && gc_vec_finite(b->state.v) && gc_vec_finite(b->state.w) && isfinite(b->state.q.w) &&
           isfinite(b->state.q.x) && isfinite(b->state.q.y) && isfinite(b->state.q.z);
}

/* A body whose step would leave it non-finite (a solve that broke down on extreme input)
 * goes back to its pose at the start of the step, at rest, and is counted; its neighbours
 * and the fingers only ever see that finite state. */
static void stop_body(gcWorld *w, int32_t id) {
    gcBody *b = &w->bodies[id];
    b->state.com = b->step_start_com;
    b->state.q = b->step_start_q;
    b->state.v = gc_v3(0, 0, 0);
    b->state.w = gc_v3(0, 0, 0);
    b->nonfinite = 0;
    gc_body_refresh_derived(w, id);
    b->state.residual_force = gc_v3(0, 0, 0);
    b->state.residual_torque = gc_v3(0, 0, 0);
    if (w->step_stopped_bodies++ == 0) w->first_stopped_body = id;
    w->stopped_bodies++;
}

void gc_dynamics_positions(gcWorld *w, double dt) {
    const gcModel *model = w->model;
    for (int32_t i = 0; i < w->num_bodies; ++i) {
        gcBody *b = &w->bodies[i];
        const gcBodyModel *m = &model->bodies[i];
        if (m->is_static || (w->body_active && !w->body_active[i])) continue;
        b->state.com = gc_madd(b->state.com, b->state.v, dt);
        b->state.q = gc_quat_normalize(gc_quat_mul(gc_quat_from_rotation_vector(gc_scale(b->state.w, dt)), b->state.q));
        if (b->nonfinite || !body_state_finite(b)) {
            stop_body(w, i);
            continue;
        }
        gc_body_refresh_derived(w, i);
        /* The residual wrench is what the step actually applied (gravity, the implicit
         * finger springs at their end-of-step stretch, contacts): the rate of change of
         * momentum. Evaluating the springs at the start of the step instead would be off
         * by k dt v for a body carried at speed v. */
        gcVec3 L = angular_momentum(&b->state.R, &m->inertia_local, b->state.w);
        b->state.residual_force = gc_scale(gc_sub(gc_scale(b->state.v, m->mass), b->step_start_momentum), 1.0 / dt);
        b->state.residual_torque = gc_scale(gc_sub(L, b->step_start_angular_momentum), 1.0 / dt);
    }
}
