/* Body-body contacts, chains and the contact solver against analytic answers:
 * resting box (height, no drift), inclined plane (stick below tan = mu_s, slide with
 * g (sin - mu_d cos) above), a stack of 5, momentum in a zero-gravity collision, chains
 * splitting and merging, thread-count-independent state hashes, capacity overflow. */
#include "graspcore.h"
#include "gc_test.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define DT 1e-3

static const double kPi = 3.14159265358979323846;

static int32_t add_box(gcWorld *w, double hx, double hy, double hz, const double pos[3], const double quat[4],
                       int is_static, double mass, double mu_s, double mu_d) {
    double pts[24];
    int k = 0;
    for (int i = 0; i < 8; ++i) {
        pts[k++] = (i & 1) ? hx : -hx;
        pts[k++] = (i & 2) ? hy : -hy;
        pts[k++] = (i & 4) ? hz : -hz;
    }
    gcPartDef part = {pts, 8, 0.0};
    gcBodyDef def = gc_default_body_def();
    memcpy(def.position, pos, sizeof def.position);
    if (quat) memcpy(def.orientation, quat, sizeof def.orientation);
    def.is_static = is_static;
    def.mass = mass;
    def.mu_s = mu_s;
    def.mu_d = mu_d;
    int32_t id = -1;
    gcStatus st = gc_world_add_body(w, &def, &part, 1, &id);
    GC_CHECK(st == GC_OK, "add_box: %s", gc_world_last_error(w));
    return id;
}

static gcWorld *make_world(int threads, double gz) {
    gcWorldDef def = gc_default_world_def();
    def.gravity[2] = gz;
    def.threads = threads;
    gcWorld *w = NULL;
    GC_CHECK(gc_world_create(&def, &w) == GC_OK, "world create");
    return w;
}

static void pose(gcWorld *w, int32_t b, double p[3], double q[4]) { gc_world_body_pose(w, b, p, q); }

static double dist3(const double a[3], const double b[3]) {
    return sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) + (a[2] - b[2]) * (a[2] - b[2]));
}

static void step_n(gcWorld *w, int n) {
    for (int i = 0; i < n; ++i) gc_world_step(w, DT);
}

static void test_resting_box(void) {
    gcWorld *w = make_world(1, -9.81);
    double table[3] = {0, 0, -0.05}, at[3] = {0, 0, 0.03};
    add_box(w, 0.2, 0.2, 0.05, table, NULL, 1, 0, 0.8, 0.6);
    int32_t b = add_box(w, 0.03, 0.03, 0.03, at, NULL, 0, 0.2, 0.8, 0.6);
    step_n(w, 500); /* settle */
    double p0[3], q0[4], p[3], q[4];
    pose(w, b, p0, q0);
    GC_CHECK_NEAR(p0[2], 0.03, 1e-5, "resting height = half extent within the slop");
    step_n(w, 10000);
    pose(w, b, p, q);
    GC_CHECK(dist3(p, p0) < 1e-6, "resting box drifted %.3g m in 10 s", dist3(p, p0));
    GC_CHECK(gc_world_contact_count(w) == 4, "a face on a face gives 4 points (got %d)", gc_world_contact_count(w));
    gcContactPoint cp[8];
    int n = gc_world_contacts(w, cp, 8);
    double total = 0;
    for (int i = 0; i < n && i < 8; ++i) total += cp[i].normal_impulse;
    GC_CHECK_NEAR(total / DT, 0.2 * 9.81, 1e-6, "contact force carries the weight");
    GC_CHECK(cp[0].sticking == 1, "resting contact sticks");
    gc_world_destroy(w);
}

/* A box on a static slab tilted by theta about x; returns the displacement along the
 * slope after `seconds` and the final down-slope speed. */
static void incline(double theta, double mu_s, double mu_d, double seconds, double *moved, double *speed,
                    double *accel) {
    gcWorld *w = make_world(1, -9.81);
    double q[4] = {cos(theta / 2), sin(theta / 2), 0, 0};
    double n[3] = {0, -sin(theta), cos(theta)}, down[3] = {0, -cos(theta), -sin(theta)};
    double origin[3] = {-0.05 * n[0], -0.05 * n[1], -0.05 * n[2]};
    add_box(w, 1.0, 1.0, 0.05, origin, q, 1, 0, mu_s, mu_d);
    double at[3] = {0.02 * n[0], 0.02 * n[1], 0.02 * n[2]};
    int32_t b = add_box(w, 0.02, 0.02, 0.02, at, q, 0, 0.2, mu_s, mu_d);
    double p0[3], p[3], qq[4], v[3], om[3];
    pose(w, b, p0, qq);
    int steps = (int)(seconds / DT + 0.5);
    double v_early = 0;
    for (int i = 0; i < steps; ++i) {
        gc_world_step(w, DT);
        if (i == steps / 4 - 1) {
            gc_world_body_velocity(w, b, v, om);
            v_early = v[0] * down[0] + v[1] * down[1] + v[2] * down[2];
        }
    }
    pose(w, b, p, qq);
    gc_world_body_velocity(w, b, v, om);
    *moved = (p[0] - p0[0]) * down[0] + (p[1] - p0[1]) * down[1] + (p[2] - p0[2]) * down[2];
    *speed = v[0] * down[0] + v[1] * down[1] + v[2] * down[2];
    *accel = (*speed - v_early) / (seconds - (steps / 4) * DT);
    gc_world_destroy(w);
}

static void test_inclined_plane(void) {
    const double mu_s = 0.5, mu_d = 0.3, g = 9.81;
    double moved, speed, accel;
    /* tan(theta) = 0.9 mu_s: sticks. */
    double theta = atan(0.9 * mu_s);
    incline(theta, mu_s, mu_d, 2.0, &moved, &speed, &accel);
    GC_CHECK(fabs(moved) < 1e-6, "sticks below tan = mu_s: moved %.3g m", moved);
    /* Steeper than mu_s: slides with g (sin - mu_d cos). */
    double angles[3] = {atan(1.1 * mu_s), 35.0 * kPi / 180.0, 50.0 * kPi / 180.0};
    for (int i = 0; i < 3; ++i) {
        incline(angles[i], mu_s, mu_d, 0.4, &moved, &speed, &accel);
        double expect = g * (sin(angles[i]) - mu_d * cos(angles[i]));
        GC_CHECK(fabs(accel - expect) < 1e-6 * expect, "slides at %.2f deg: a %.9g vs %.9g", angles[i] * 180 / kPi,
                 accel, expect);
        GC_CHECK(fabs(moved - 0.5 * expect * 0.4 * 0.4) < 0.01 * 0.5 * expect * 0.16,
                 "slide distance %.6g vs %.6g", moved, 0.5 * expect * 0.16);
    }
}

static gcWorld *stack_world(int threads, int n, int32_t *ids) {
    gcWorld *w = make_world(threads, -9.81);
    double table[3] = {0, 0, -0.05};
    add_box(w, 0.3, 0.3, 0.05, table, NULL, 1, 0, 0.8, 0.6);
    for (int i = 0; i < n; ++i) {
        double at[3] = {0.001 * i, 0, 0.02 + 0.04 * i};
        ids[i] = add_box(w, 0.02, 0.02, 0.02, at, NULL, 0, 0.2, 0.8, 0.6);
    }
    return w;
}

static void test_stack(void) {
    int32_t ids[5];
    gcWorld *w = stack_world(1, 5, ids);
    double start[5][3], settled[5][3], p[3], q[4];
    for (int i = 0; i < 5; ++i) pose(w, ids[i], start[i], q);
    step_n(w, 1000);
    for (int i = 0; i < 5; ++i) pose(w, ids[i], settled[i], q);
    step_n(w, 10000);
    double worst = 0, worst_settled = 0;
    for (int i = 0; i < 5; ++i) {
        pose(w, ids[i], p, q);
        worst = fmax(worst, dist3(p, start[i]));
        worst_settled = fmax(worst_settled, dist3(p, settled[i]));
    }
    GC_CHECK(worst < 1e-4, "stack of 5 moved %.3g m in 11 s", worst);
    GC_CHECK(worst_settled < 1e-6, "settled stack of 5 drifted %.3g m in 10 s", worst_settled);
    GC_CHECK(gc_world_chain_count(w) == 1, "one chain (got %d)", gc_world_chain_count(w));
    gc_world_destroy(w);
}

/* Angular momentum about the world origin and kinetic energy of body b. */
static void body_momenta(gcWorld *w, int32_t b, double P[3], double L[3], double *energy) {
    double m, com[3], I[9], p[3], q[4], v[3], om[3];
    gc_world_body_mass(w, b, &m, com, I);
    pose(w, b, p, q);
    gc_world_body_velocity(w, b, v, om); /* of the origin, which is the COM for these boxes */
    double qw = q[0], x = q[1], y = q[2], z = q[3];
    double R[3][3] = {{1 - 2 * (y * y + z * z), 2 * (x * y - qw * z), 2 * (x * z + qw * y)},
                      {2 * (x * y + qw * z), 1 - 2 * (x * x + z * z), 2 * (y * z - qw * x)},
                      {2 * (x * z - qw * y), 2 * (y * z + qw * x), 1 - 2 * (x * x + y * y)}};
    double Iw[3][3] = {{0}}, Lw[3] = {0, 0, 0};
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            for (int k = 0; k < 3; ++k)
                for (int l = 0; l < 3; ++l) Iw[i][j] += R[i][k] * I[3 * k + l] * R[j][l];
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) Lw[i] += Iw[i][j] * om[j];
    for (int i = 0; i < 3; ++i) P[i] = m * v[i];
    L[0] = p[1] * P[2] - p[2] * P[1] + Lw[0];
    L[1] = p[2] * P[0] - p[0] * P[2] + Lw[1];
    L[2] = p[0] * P[1] - p[1] * P[0] + Lw[2];
    *energy = 0.5 * m * (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]) +
              0.5 * (om[0] * Lw[0] + om[1] * Lw[1] + om[2] * Lw[2]);
}

static void total_momenta(gcWorld *w, int32_t a, int32_t b, double P[3], double L[3], double *energy) {
    double Pa[3], La[3], Ea, Pb[3], Lb[3], Eb;
    body_momenta(w, a, Pa, La, &Ea);
    body_momenta(w, b, Pb, Lb, &Eb);
    for (int i = 0; i < 3; ++i) P[i] = Pa[i] + Pb[i], L[i] = La[i] + Lb[i];
    *energy = Ea + Eb;
}

static void test_momentum(void) {
    gcWorld *w = make_world(1, 0.0);
    double a[3] = {-0.1, 0, 0}, b[3] = {0.1, 0.01, 0.005};
    double qb[4] = {cos(0.2), 0.3 * sin(0.2), 0.2 * sin(0.2), sin(0.2) * 0.93};
    int32_t ia = add_box(w, 0.03, 0.03, 0.03, a, NULL, 0, 0.3, 0.8, 0.6);
    int32_t ib = add_box(w, 0.02, 0.025, 0.03, b, qb, 0, 0.1, 0.8, 0.6);
    double va[3] = {0.05, 0.0, 0.0}, vb[3] = {-0.07, 0.005, 0.0}, wa[3] = {0, 0, 0.1}, wb[3] = {0.2, 0, 0};
    gc_world_set_body_velocity(w, ia, va, wa);
    gc_world_set_body_velocity(w, ib, vb, wb);
    double P0[3], L0[3], E0, P[3], L[3], E;
    total_momenta(w, ia, ib, P0, L0, &E0);
    int touched = 0;
    for (int i = 0; i < 3000; ++i) {
        gc_world_step(w, DT);
        if (gc_world_contact_count(w) > 0) touched = 1;
    }
    GC_CHECK(touched, "the boxes collided");
    total_momenta(w, ia, ib, P, L, &E);
    for (int k = 0; k < 3; ++k) GC_CHECK_NEAR(P[k], P0[k], 1e-12, "linear momentum conserved");
    /* Impulses act at one point on both bodies, so they conserve angular momentum exactly;
     * the split-impulse position pass moves the bodies apart without momentum (x changes,
     * m v does not), which changes x x m v by a little when the corners dig in. */
    double Lnorm = sqrt(L0[0] * L0[0] + L0[1] * L0[1] + L0[2] * L0[2]);
    for (int k = 0; k < 3; ++k) GC_CHECK_NEAR(L[k], L0[k], 1e-3 * Lnorm, "angular momentum conserved");
    GC_CHECK(E < E0 && E > 0.05 * E0, "an inelastic collision loses some energy: %.6g -> %.6g J", E0, E);
    gc_world_destroy(w);
}

static void test_chains(void) {
    gcWorld *w = make_world(1, -9.81);
    double table[3] = {0, 0, -0.05};
    add_box(w, 0.5, 0.5, 0.05, table, NULL, 1, 0, 0.8, 0.6);
    double a[3] = {-0.1, 0, 0.02}, b[3] = {0.1, 0, 0.02}, c[3] = {0.1, 0, 0.06};
    int32_t ia = add_box(w, 0.02, 0.02, 0.02, a, NULL, 0, 0.2, 0.8, 0.6);
    int32_t ib = add_box(w, 0.02, 0.02, 0.02, b, NULL, 0, 0.2, 0.8, 0.6);
    int32_t ic = add_box(w, 0.02, 0.02, 0.02, c, NULL, 0, 0.2, 0.8, 0.6);
    step_n(w, 10);
    int32_t ca, cb, cc, ct;
    gc_world_body_chain(w, 0, &ct);
    gc_world_body_chain(w, ia, &ca);
    gc_world_body_chain(w, ib, &cb);
    gc_world_body_chain(w, ic, &cc);
    GC_CHECK(ct == -1, "the static table is in no chain");
    GC_CHECK(gc_world_chain_count(w) == 2 && ca != cb && cb == cc,
             "the table does not join chains: %d chains, a %d b %d c %d", gc_world_chain_count(w), ca, cb, cc);
    /* Move box a against box b: merge. */
    double q[4] = {1, 0, 0, 0}, next[3] = {0.1 - 0.04, 0, 0.02};
    gc_world_set_body_pose(w, ia, next, q);
    step_n(w, 2);
    gc_world_body_chain(w, ia, &ca);
    gc_world_body_chain(w, ib, &cb);
    GC_CHECK(gc_world_chain_count(w) == 1 && ca == cb, "merged: %d chains", gc_world_chain_count(w));
    /* Lift box c away: it splits off. */
    double up[3] = {0.3, 0.3, 0.5};
    gc_world_set_body_pose(w, ic, up, q);
    step_n(w, 1);
    gc_world_body_chain(w, ia, &ca);
    gc_world_body_chain(w, ic, &cc);
    GC_CHECK(gc_world_chain_count(w) == 2 && ca != cc, "split: %d chains", gc_world_chain_count(w));
    gc_world_destroy(w);
}

static uint64_t pile_hash(int threads) {
    gcWorld *w = make_world(threads, -9.81);
    double table[3] = {0, 0, -0.05};
    add_box(w, 0.5, 0.5, 0.05, table, NULL, 1, 0, 0.8, 0.6);
    /* Twelve separate stacks (twelve chains: enough work for the pool) and a pile falling
     * onto each other. */
    for (int s = 0; s < 12; ++s)
        for (int i = 0; i < 3; ++i) {
            double at[3] = {-0.35 + 0.1 * (s % 6), 0.2 + 0.1 * (s / 6), 0.02 + 0.0405 * i};
            double q[4] = {cos(0.05 * i), 0, 0, sin(0.05 * i)};
            add_box(w, 0.02, 0.02, 0.02, at, q, 0, 0.1 + 0.05 * (s % 4), 0.8, 0.6);
        }
    for (int i = 0; i < 12; ++i) {
        double at[3] = {-0.1 + 0.013 * (i % 4), -0.1 + 0.011 * (i / 4), 0.05 + 0.045 * i};
        double q[4] = {cos(0.3 * i), sin(0.3 * i) * 0.6, 0, sin(0.3 * i) * 0.8};
        add_box(w, 0.02, 0.015, 0.01, at, q, 0, 0.1, 0.8, 0.6);
    }
    step_n(w, 600);
    uint64_t h = gc_world_state_hash(w);
    GC_CHECK(gc_world_chain_count(w) >= 13, "several chains (got %d)", gc_world_chain_count(w));
    gc_world_destroy(w);
    return h;
}

static void test_thread_independence(void) {
    uint64_t h1 = pile_hash(1), h2 = pile_hash(2), h4 = pile_hash(4);
    GC_CHECK(h1 == h2 && h1 == h4, "state hash differs with threads: %llx %llx %llx", (unsigned long long)h1,
             (unsigned long long)h2, (unsigned long long)h4);
}

/* The static body need not come first: manifolds where body B is static. */
static void test_static_last(void) {
    gcWorld *w = make_world(1, -9.81);
    double a[3] = {0, 0, 0.02}, table[3] = {0, 0, -0.05};
    int32_t b = add_box(w, 0.02, 0.02, 0.02, a, NULL, 0, 0.2, 0.8, 0.6);
    add_box(w, 0.3, 0.3, 0.05, table, NULL, 1, 0, 0.8, 0.6);
    step_n(w, 500);
    double p[3], q[4];
    pose(w, b, p, q);
    GC_CHECK_NEAR(p[2], 0.02, 1e-5, "rests on a static body added after it");
    gc_world_destroy(w);
}

static void test_overflow(void) {
    gcWorldDef def = gc_default_world_def();
    def.max_contacts = 2;
    gcWorld *w = NULL;
    GC_CHECK(gc_world_create(&def, &w) == GC_OK, "create with max_contacts 2");
    double table[3] = {0, 0, -0.05};
    add_box(w, 0.5, 0.5, 0.05, table, NULL, 1, 0, 0.8, 0.6);
    for (int i = 0; i < 4; ++i) {
        double at[3] = {-0.2 + 0.1 * i, 0, 0.02};
        add_box(w, 0.02, 0.02, 0.02, at, NULL, 0, 0.2, 0.8, 0.6);
    }
    GC_CHECK(gc_world_step(w, DT) == GC_OK, "a step with too many pairs still succeeds");
    GC_CHECK(gc_world_contact_overflow(w) == 2, "two pairs counted as dropped (got %lld)",
             (long long)gc_world_contact_overflow(w));
    gc_world_destroy(w);
    def = gc_default_world_def();
    def.threads = 65;
    GC_CHECK(gc_world_create(&def, &w) == GC_ERR_INVALID_ARGUMENT, "threads > 64 refused");
}

int main(void) {
    test_resting_box();
    test_inclined_plane();
    test_stack();
    test_momentum();
    test_chains();
    test_thread_independence();
    test_static_last();
    test_overflow();
    return gc_test_summary("test_contacts");
}
