/* Newton-Euler integration of dynamic bodies with an implicit finger coupling.
 *
 * Each finger contact is a spring k (and damper c) between the HIP and the body point
 * under the god-object. Stepped explicitly at 1 kHz, a light thin object held by stiff
 * fingers has modes far above the step rate and explodes (DESIGN.md §2), so the springs
 * are integrated with backward Euler, linearised about the current pose:
 *
 *   (M' + sum (k dt^2 + c dt) J^T J) v' = M v + dt (F_ext + sum J^T (f_spring + c v_hip))
 *
 * with J = [I | -[r]x] mapping the body twist to the velocity of the god-object at r
 * from the centre of mass. M is 6x6 block diagonal (m I, R I_body R^T). The pose is
 * then advanced with the new twist: x += v' dt and R <- exp([w' dt]x) R, the world-frame
 * update the chapter prints transposed. */
#include "world_internal.h"

#include <string.h>

/* Cholesky factor of a 6x6 symmetric positive-definite matrix (lower); 0 on failure. */
static int cholesky6(const double A[6][6], double L[6][6]) {
    memset(L, 0, sizeof(double) * 36);
    for (int i = 0; i < 6; ++i) {
        for (int j = 0; j <= i; ++j) {
            double s = A[i][j];
            for (int k = 0; k < j; ++k) s -= L[i][k] * L[j][k];
            if (i == j) {
                if (!(s > 0.0)) return 0;
                L[i][i] = sqrt(s);
            } else {
                L[i][j] = s / L[j][j];
            }
        }
    }
    return 1;
}

static void cholesky_solve6(const double L[6][6], const double b[6], double x[6]) {
    double y[6];
    for (int i = 0; i < 6; ++i) {
        double s = b[i];
        for (int k = 0; k < i; ++k) s -= L[i][k] * y[k];
        y[i] = s / L[i][i];
    }
    for (int i = 5; i >= 0; --i) {
        double s = y[i];
        for (int k = i + 1; k < 6; ++k) s -= L[k][i] * x[k];
        x[i] = s / L[i][i];
    }
}

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

/* R A R^T: a body-frame tensor in world axes. */
static gcMat3 to_world(const gcMat3 *R, const gcMat3 *A) {
    gcMat3 RA = gc_mat3_mul(R, A);
    gcMat3 Rt = gc_mat3_transpose(R);
    return gc_mat3_mul(&RA, &Rt);
}

/* I_world w without forming I_world: R (I_body (R^T w)). */
static gcVec3 angular_momentum(const gcMat3 *R, const gcMat3 *inertia_local, gcVec3 w) {
    gcVec3 local = gc_mat3_tmul_vec(R, w);
    return gc_mat3_mul_vec(R, gc_mat3_mul_vec(inertia_local, local));
}

/* Fixed-point passes for the inertia at the end of the step (gyroscopic term); they stop
 * early once a pass returns the same angular velocity bit for bit (the next pass would
 * repeat it exactly, so the result does not depend on stopping). */
#define GC_GYRO_ITERATIONS 3

static gcMat3 end_of_step_rotation(const gcBody *b, gcVec3 omega, double dt) {
    return gc_quat_to_mat3(gc_quat_mul(gc_quat_from_rotation_vector(gc_scale(omega, dt)), b->q));
}

static int same_vec(gcVec3 a, gcVec3 b) { return a.x == b.x && a.y == b.y && a.z == b.z; }

static void integrate_velocity(gcWorld *w, int32_t id, double dt) {
    gcBody *b = &w->bodies[id];
    gcVec3 L = angular_momentum(&b->R, &b->inertia_local, b->w);
    gcVec3 force = gc_scale(w->gravity, b->mass);
    gcVec3 torque = gc_v3(0, 0, 0);
    double C[6][6]; /* finger coupling: sum (k dt^2 + c dt) J^T J */
    int coupled = 0;

    gcTransform frame = gc_body_transform(b);
    for (int fi = 0; fi < w->num_fingers; ++fi) {
        const gcFinger *f = &w->fingers[fi];
        for (int ci = 0; ci < f->num_contacts; ++ci) {
            const gcFingerContact *c = &f->contacts[ci];
            if (w->parts[c->part].body != id) continue;
            if (!coupled) memset(C, 0, sizeof C);
            coupled = 1;
            /* The reaction acts at the GO (DESIGN.md §2), which moves rigidly with the body
             * while it sticks: the same lever in the torque and in the coupling keeps the
             * implicit model consistent with the explicit force. */
            gcVec3 go = gc_transform_point(&frame, c->go_local);
            gcVec3 r = gc_sub(go, b->com);
            gcVec3 spring = gc_scale(gc_sub(f->hip, go), f->stiffness);
            /* Implicit part: the velocity-dependent terms move into the matrix. */
            gcVec3 explicit_part = gc_madd(spring, f->hip_velocity, f->damping);
            force = gc_add(force, explicit_part);
            torque = gc_add(torque, gc_cross(r, explicit_part));
            add_point_coupling(C, r, f->stiffness * dt * dt + f->damping * dt);
        }
    }
    b->step_start_momentum = gc_scale(b->v, b->mass);
    b->step_start_angular_momentum = L;

    gcVec3 p = gc_add(b->step_start_momentum, gc_scale(force, dt));
    gcVec3 Lnew = gc_add(L, gc_scale(torque, dt));
    /* Gyroscopic term: d(J w)/dt = T is J w_dot = T - w x J w. Solving J(t+dt) w' = L + dt T
     * with the inertia at the end-of-step orientation keeps it implicitly (no explicit
     * w x J w, which drifts on a tumbling body) and conserves L. The end orientation
     * depends on w', hence a few fixed-point passes. Without the term (the chapter's
     * form) the inertia stays J(t). */
    gcVec3 v, omega = b->w;
    int passes = w->def.gyroscopic ? GC_GYRO_ITERATIONS : 1;
    gcMat3 Rend = b->R;
    b->coupled = coupled;
    if (!coupled) {
        /* No finger on it: the effective mass is the block-diagonal mass matrix, inverted
         * directly (no 6x6 factor); contacts use the same blocks. */
        v = gc_scale(p, b->inv_mass);
        for (int pass = 0; pass < passes; ++pass) {
            if (w->def.gyroscopic) Rend = end_of_step_rotation(b, omega, dt);
            gcVec3 next = gc_mat3_mul_vec(&Rend, gc_mat3_mul_vec(&b->inv_inertia_local, gc_mat3_tmul_vec(&Rend, Lnew)));
            int converged = pass > 0 && same_vec(next, omega);
            omega = next;
            if (converged) break;
        }
        b->inertia_rotation = Rend; /* contacts form R I^-1 R^T from it, for bodies that touch */
        b->effective_mass_valid = 1;
    } else {
        double rhs[6] = {p.x, p.y, p.z, Lnew.x, Lnew.y, Lnew.z}, x[6];
        for (int pass = 0; pass < passes; ++pass) {
            if (w->def.gyroscopic) Rend = end_of_step_rotation(b, omega, dt);
            gcMat3 Inext = to_world(&Rend, &b->inertia_local);
            double A[6][6];
            memcpy(A, C, sizeof A);
            for (int i = 0; i < 3; ++i) {
                A[i][i] += b->mass;
                for (int j = 0; j < 3; ++j) A[3 + i][3 + j] += Inext.m[i][j];
            }
            b->effective_mass_valid = cholesky6(A, b->effective_mass_factor);
            if (!b->effective_mass_valid) return; /* cannot happen for a physical inertia; keep the state */
            cholesky_solve6(b->effective_mass_factor, rhs, x);
            gcVec3 next = gc_v3(x[3], x[4], x[5]);
            int converged = pass > 0 && same_vec(next, omega);
            omega = next;
            if (converged) break;
        }
        v = gc_v3(x[0], x[1], x[2]);
    }
    gcVec3 om = omega;
    if (b->linear_damping > 0.0) v = gc_scale(v, 1.0 / (1.0 + dt * b->linear_damping));
    if (b->angular_damping > 0.0) om = gc_scale(om, 1.0 / (1.0 + dt * b->angular_damping));
    if (!gc_vec_finite(v) || !gc_vec_finite(om)) {
        b->effective_mass_valid = 0;
        return;
    }
    b->v = v;
    b->w = om;
}

void gc_body_inverse_effective_mass(const gcBody *b, double M[36]) {
    memset(M, 0, 36 * sizeof(double));
    if (b->is_static || !b->effective_mass_valid) return;
    if (!b->coupled) {
        gcMat3 inv_inertia_world = to_world(&b->inertia_rotation, &b->inv_inertia_local);
        for (int i = 0; i < 3; ++i) {
            M[6 * i + i] = b->inv_mass;
            for (int j = 0; j < 3; ++j) M[6 * (3 + i) + 3 + j] = inv_inertia_world.m[i][j];
        }
        return;
    }
    for (int j = 0; j < 6; ++j) {
        double e[6] = {0, 0, 0, 0, 0, 0}, col[6];
        e[j] = 1.0;
        cholesky_solve6(b->effective_mass_factor, e, col);
        for (int r = 0; r < 6; ++r) M[6 * r + j] = col[r];
    }
}

void gc_dynamics_velocities(gcWorld *w, double dt) {
    for (int32_t i = 0; i < w->num_bodies; ++i) {
        gcBody *b = &w->bodies[i];
        if (b->is_static) {
            b->residual_force = gc_v3(0, 0, 0);
            b->residual_torque = gc_v3(0, 0, 0);
            continue;
        }
        if (w->body_active && !w->body_active[i]) {
            b->effective_mass_valid = 0; /* another runtime thread steps it: immovable here */
            continue;
        }
        integrate_velocity(w, i, dt);
    }
}

void gc_dynamics_positions(gcWorld *w, double dt) {
    for (int32_t i = 0; i < w->num_bodies; ++i) {
        gcBody *b = &w->bodies[i];
        if (b->is_static || (w->body_active && !w->body_active[i])) continue;
        b->com = gc_madd(b->com, b->v, dt);
        b->q = gc_quat_normalize(gc_quat_mul(gc_quat_from_rotation_vector(gc_scale(b->w, dt)), b->q));
        gc_body_refresh_derived(w, i);
        /* The residual wrench is what the step actually applied (gravity, the implicit
         * finger springs at their end-of-step stretch, contacts): the rate of change of
         * momentum. Evaluating the springs at the start of the step instead would be off
         * by k dt v for a body carried at speed v. */
        gcVec3 L = angular_momentum(&b->R, &b->inertia_local, b->w);
        b->residual_force = gc_scale(gc_sub(gc_scale(b->v, b->mass), b->step_start_momentum), 1.0 / dt);
        b->residual_torque = gc_scale(gc_sub(L, b->step_start_angular_momentum), 1.0 / dt);
    }
}
