/* World-level C tests: a pinch held through the public API, determinism by state hash,
 * statuses for bad input, and a world left unchanged by a failed call. Run plain and
 * under ASan/UBSan by `make test`. */
#include <string.h>

#include "gc_test.h"
#include "graspcore.h"

static void box_points(double h, double out[24]) {
    int k = 0;
    for (int i = 0; i < 8; ++i) {
        out[k++] = (i & 1) ? h : -h;
        out[k++] = (i & 2) ? h : -h;
        out[k++] = (i & 4) ? h : -h;
    }
}

/* Two fingers pinch a 0.2 kg box 3 mm deep and lift it 5 cm; returns the state hash. */
static uint64_t run_pinch(double *out_z, gcFingerState *out_state) {
    gcWorldDef wd = gc_default_world_def();
    gcWorld *w = NULL;
    GC_CHECK(gc_world_create(&wd, &w) == GC_OK, "create");
    double pts[24];
    box_points(0.03, pts);
    gcPartDef part = {pts, 8, 0.0};
    gcBodyDef bd = gc_default_body_def();
    bd.mass = 0.2;
    int32_t box, f[2];
    GC_CHECK(gc_world_add_body(w, &bd, &part, 1, &box) == GC_OK, "add box: %s", gc_world_last_error(w));
    for (int i = 0; i < 2; ++i) {
        gcFingerDef fd = gc_default_finger_def();
        fd.damping = 2.0;
        fd.position[0] = (i ? 1 : -1) * 0.035;
        GC_CHECK(gc_world_add_finger(w, &fd, &f[i]) == GC_OK, "add finger");
    }
    for (int step = 0; step < 2000; ++step) {
        double lift = 0.05 * (step < 1000 ? step / 1000.0 : 1.0);
        for (int i = 0; i < 2; ++i) {
            double hip[3] = {(i ? 1 : -1) * 0.035, 0.0, lift};
            gc_world_set_hip(w, f[i], hip);
        }
        GC_CHECK(gc_world_step(w, 1e-3) == GC_OK, "step");
    }
    double pos[3], q[4];
    gc_world_body_pose(w, box, pos, q);
    int32_t contact;
    gc_world_finger_state(w, f[0], out_state, &contact);
    GC_CHECK(contact == box, "finger 0 touches the box");
    *out_z = pos[2];
    uint64_t hash = gc_world_state_hash(w);
    gc_world_destroy(w);
    return hash;
}

static void test_pinch_and_determinism(void) {
    double z1, z2;
    gcFingerState s1, s2;
    uint64_t h1 = run_pinch(&z1, &s1), h2 = run_pinch(&z2, &s2);
    GC_CHECK(h1 == h2, "same inputs, same hash (%llx vs %llx)", (unsigned long long)h1, (unsigned long long)h2);
    GC_CHECK(s1 == GC_FINGER_STICK, "held in stick");
    /* Lifted 5 cm, sagging m g / 2k = 0.98 mm. */
    GC_CHECK_NEAR(z1, 0.05 - 0.2 * 9.81 / 2000.0, 5e-5, "held box height");
}

static void test_bad_input_leaves_world_unchanged(void) {
    gcWorldDef wd = gc_default_world_def();
    wd.max_bodies = 2;
    gcWorld *w = NULL;
    gc_world_create(&wd, &w);
    double pts[24];
    box_points(0.01, pts);
    gcPartDef part = {pts, 8, 0.0};
    gcBodyDef bd = gc_default_body_def();
    int32_t id;
    GC_CHECK(gc_world_add_body(w, &bd, &part, 1, &id) == GC_OK, "first body");
    gc_world_step(w, 1e-3);
    uint64_t before = gc_world_state_hash(w);

    double flat[12] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0};
    gcPartDef flat_part = {flat, 4, 0.0};
    GC_CHECK(gc_world_add_body(w, &bd, &flat_part, 1, &id) == GC_ERR_DEGENERATE, "coplanar hull");
    GC_CHECK(strncmp(gc_world_last_error(w), "points", 6) == 0, "error names points: %s", gc_world_last_error(w));
    /* A compound whose second part is bad leaves no first part behind. */
    gcPartDef parts[2] = {part, flat_part};
    GC_CHECK(gc_world_add_body(w, &bd, parts, 2, &id) == GC_ERR_DEGENERATE, "bad compound");
    bd.mass = -1.0;
    GC_CHECK(gc_world_add_body(w, &bd, &part, 1, &id) == GC_ERR_INVALID_ARGUMENT, "negative mass");
    GC_CHECK(strncmp(gc_world_last_error(w), "mass", 4) == 0, "error names mass");
    bd.mass = 1.0;
    double nan_hip[3] = {0.0, NAN, 0.0};
    GC_CHECK(gc_world_set_hip(w, 0, nan_hip) == GC_ERR_UNKNOWN_ID, "no finger 0 yet");
    int32_t f;
    gcFingerDef fd = gc_default_finger_def();
    gc_world_add_finger(w, &fd, &f);
    before = gc_world_state_hash(w);
    GC_CHECK(gc_world_set_hip(w, f, nan_hip) == GC_ERR_INVALID_ARGUMENT, "NaN HIP");
    GC_CHECK(gc_world_step(w, -1.0) == GC_ERR_INVALID_ARGUMENT, "negative dt");
    GC_CHECK(gc_world_body_count(w) == 1, "one body still");
    GC_CHECK(gc_world_state_hash(w) == before, "state unchanged");
    GC_CHECK(gc_world_add_body(w, &bd, &part, 1, &id) == GC_OK && id == 1, "second body after errors");
    GC_CHECK(gc_world_add_body(w, &bd, &part, 1, &id) == GC_ERR_CAPACITY, "capacity");
    gc_world_destroy(w);
}

static void test_shapes_and_compounds(void) {
    gcWorldDef wd = gc_default_world_def();
    wd.gravity[2] = 0.0;
    gcWorld *w = NULL;
    gc_world_create(&wd, &w);
    double centre[3] = {0, 0, 0}, seg[6] = {-0.05, 0, 0, 0.05, 0, 0};
    gcPartDef sphere = {centre, 1, 0.02}, capsule = {seg, 2, 0.01};
    gcBodyDef bd = gc_default_body_def();
    int32_t s, c, k;
    GC_CHECK(gc_world_add_body(w, &bd, &sphere, 1, &s) == GC_OK, "sphere: %s", gc_world_last_error(w));
    bd.position[0] = 0.5; /* apart, so that body contacts leave them alone */
    GC_CHECK(gc_world_add_body(w, &bd, &capsule, 1, &c) == GC_OK, "capsule: %s", gc_world_last_error(w));
    bd.position[0] = -0.5;
    double a[24], b[24];
    box_points(0.01, a);
    box_points(0.01, b);
    for (int i = 0; i < 8; ++i) b[3 * i] += 0.04;
    gcPartDef parts[2] = {{a, 8, 0.0}, {b, 8, 0.0}};
    GC_CHECK(gc_world_add_body(w, &bd, parts, 2, &k) == GC_OK, "compound");
    double m, com[3], I[9];
    gc_world_body_mass(w, s, &m, com, I);
    GC_CHECK_NEAR(I[0], 0.4 * 1.0 * 0.02 * 0.02, 1e-12, "solid sphere inertia");
    gc_world_body_mass(w, k, &m, com, I);
    GC_CHECK_NEAR(com[0], 0.02, 1e-12, "compound centroid halfway");
    /* Two 2 cm cubes of 0.5 kg 4 cm apart: Izz = 2 (m a^2/6 + m d^2) with d = 2 cm. */
    GC_CHECK_NEAR(I[8], 2 * (0.5 * 0.02 * 0.02 / 6 + 0.5 * 0.02 * 0.02), 1e-12, "compound parallel axis");
    /* A point finger pressed into the sphere feels k * depth along the normal. */
    int32_t f;
    gcFingerDef fd = gc_default_finger_def();
    fd.radius = 0.0;
    fd.position[2] = 0.03;
    gc_world_add_finger(w, &fd, &f);
    for (int i = 1; i <= 10; ++i) {
        double hip[3] = {0, 0, 0.03 - 0.0115 * i / 10.0};
        gc_world_set_hip(w, f, hip);
        gc_world_step(w, 1e-3);
    }
    double force[3];
    gc_world_finger_force(w, f, force);
    GC_CHECK(force[2] > 0.0, "pushed out of the sphere");
    gc_world_destroy(w);
}

/* Every error path names what was wrong: NULL pointers, runtime calls while stopped, and
 * gc_world_create, which has no world to hold the message. */
static void expect_error(gcWorld *w, gcStatus got, gcStatus want, const char *prefix) {
    const char *msg = gc_world_last_error(w);
    GC_CHECK(got == want && strncmp(msg, prefix, strlen(prefix)) == 0, "status %d (want %d), message '%s' (want '%s...')",
             (int)got, (int)want, msg, prefix);
}

static void test_every_error_names_its_argument(void) {
    gcWorld *w = NULL;
    gcWorldDef def = gc_default_world_def();
    def.max_parts = 0;
    GC_CHECK(gc_world_create(&def, &w) == GC_ERR_INVALID_ARGUMENT && !w, "max_parts 0 refused");
    GC_CHECK(strncmp(gc_world_create_error(), "max_parts:", 10) == 0, "create error: '%s'", gc_world_create_error());
    def = gc_default_world_def();
    GC_CHECK(gc_world_create(&def, &w) == GC_OK && gc_world_create_error()[0] == 0, "created, no message left");
    int32_t id;
    gcFingerDef fd = gc_default_finger_def();
    expect_error(w, gc_world_add_body(w, NULL, NULL, 0, &id), GC_ERR_INVALID_ARGUMENT, "def:");
    expect_error(w, gc_world_add_finger(w, &fd, NULL), GC_ERR_INVALID_ARGUMENT, "out_finger:");
    GC_CHECK(gc_world_add_finger(w, &fd, &id) == GC_OK, "finger added");
    double p[3];
    expect_error(w, gc_world_god_object(w, id, NULL), GC_ERR_INVALID_ARGUMENT, "position:");
    expect_error(w, gc_world_finger_force(w, 7, p), GC_ERR_UNKNOWN_ID, "finger:");
    expect_error(w, gc_world_push_hips(w, p, 1, 0.0), GC_ERR_NOT_RUNNING, "push_hips:");
    expect_error(w, gc_world_debug_stall(w, 0.0), GC_ERR_NOT_RUNNING, "debug_stall:");
    expect_error(w, gc_world_snapshot(w, NULL), GC_ERR_INVALID_ARGUMENT, "snapshot:");
    expect_error(w, gc_world_stats(w, NULL), GC_ERR_INVALID_ARGUMENT, "stats:");
    expect_error(w, gc_world_start(w, NULL), GC_ERR_INVALID_ARGUMENT, "def:");
    expect_error(w, gc_world_step(w, -1.0), GC_ERR_INVALID_ARGUMENT, "dt:");
    gc_world_destroy(w);
}

/* A convex pad (a 6 x 6 x 1 cm box finger) under a small box and, beside it, under a plate wider
 * than the pad: both rest level, carried by the pad's vertices (the plate) and by the box's
 * corners inside the pad (the box); a lift of the pad carries both. Errors name points. */
static void test_convex_finger(void) {
    gcWorldDef wd = gc_default_world_def();
    gcWorld *w = NULL;
    GC_CHECK(gc_world_create(&wd, &w) == GC_OK, "create");
    double pad_pts[24], small[24], plate[24];
    box_points(0.03, pad_pts);
    box_points(0.01, small);
    box_points(0.05, plate);
    for (int i = 0; i < 8; ++i) pad_pts[3 * i + 2] /= 3.0, plate[3 * i + 2] /= 10.0; /* pad 2 cm, plate 1 cm thick */
    gcFingerDef fd = gc_default_finger_def();
    fd.radius = 0.0;
    fd.damping = 2.0;
    fd.points = pad_pts;
    fd.num_points = 8;
    int32_t pads[2], bodies[2];
    for (int i = 0; i < 2; ++i) {
        fd.position[0] = i * 0.5;
        fd.position[2] = -0.01;
        GC_CHECK(gc_world_add_finger(w, &fd, &pads[i]) == GC_OK, "add pad: %s", gc_world_last_error(w));
    }
    gcBodyDef bd = gc_default_body_def();
    bd.mass = 0.1;
    bd.position[2] = 0.01;
    gcPartDef part = {small, 8, 0.0};
    GC_CHECK(gc_world_add_body(w, &bd, &part, 1, &bodies[0]) == GC_OK, "add box");
    bd.position[0] = 0.5;
    bd.position[2] = 0.005;
    part.points = plate;
    GC_CHECK(gc_world_add_body(w, &bd, &part, 1, &bodies[1]) == GC_OK, "add plate");
    for (int step = 0; step < 2000; ++step) {
        double lift = step < 1000 ? 0.0 : 0.05 * (step - 1000) / 1000.0;
        for (int i = 0; i < 2; ++i) {
            double hip[3] = {i * 0.5, 0.0, -0.01 + lift}, q[4] = {1, 0, 0, 0};
            GC_CHECK(gc_world_set_finger_pose(w, pads[i], hip, q) == GC_OK, "set pose");
        }
        GC_CHECK(gc_world_step(w, 1e-3) == GC_OK, "step");
    }
    double sag = 0.1 * 9.81 / 4.0 / fd.stiffness;
    for (int i = 0; i < 2; ++i) {
        double pos[3], q[4];
        gc_world_body_pose(w, bodies[i], pos, q);
        GC_CHECK_NEAR(pos[2], (i ? 0.005 : 0.01) + 0.05 - sag, 2e-4, "carried body height");
        GC_CHECK(fabs(q[1]) < 1e-4 && fabs(q[2]) < 1e-4, "level: %g %g", q[1], q[2]);
        gcFingerContactPoint cps[8];
        int n = -1;
        GC_CHECK(gc_world_finger_contacts(w, pads[i], cps, 8, &n) == GC_OK, "contacts");
        GC_CHECK(n == 4, "4 contact points, got %d", n);
        for (int k = 0; k < n && k < 8; ++k) GC_CHECK(cps[k].reversed == (i == 0), "reversed on the small box only");
        double force[3];
        gc_world_finger_force(w, pads[i], force);
        GC_CHECK_NEAR(force[2], -0.1 * 9.81, 1e-3, "the pad feels the weight");
    }
    /* The patches for the analysis (gcSnapshot.patches): the small box's 4 bottom corners (+-1 cm,
     * reversed contacts) on the first pad, the second pad's 4 top corners (+-3 cm) under the plate. */
    float patches[2 * 2 * GC_FINGER_PATCH_CORNERS];
    gcSnapshot snap;
    memset(&snap, 0, sizeof snap);
    snap.patches = patches;
    GC_CHECK(gc_world_snapshot(w, &snap) == GC_OK, "snapshot");
    for (int i = 0; i < 2; ++i)
        for (int k = 0; k < 2 * GC_FINGER_PATCH_CORNERS; ++k)
            GC_CHECK(fabs(fabs(patches[2 * GC_FINGER_PATCH_CORNERS * i + k]) - (i ? 0.03 : 0.01)) < 1e-6,
                     "pad %d's patch corner coordinate %d: %g", i, k, (double)patches[2 * GC_FINGER_PATCH_CORNERS * i + k]);
    int count;
    GC_CHECK(gc_world_finger_contacts(w, 7, NULL, 0, &count) == GC_ERR_UNKNOWN_ID, "unknown finger");
    GC_CHECK(gc_world_finger_contacts(w, pads[0], NULL, 4, &count) == GC_ERR_INVALID_ARGUMENT, "no array");
    double flat[12] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0};
    fd.points = flat;
    fd.num_points = 4;
    int32_t bad;
    GC_CHECK(gc_world_add_finger(w, &fd, &bad) == GC_ERR_DEGENERATE, "coplanar points refused");
    GC_CHECK(strncmp(gc_world_last_error(w), "points:", 7) == 0, "message names points: %s", gc_world_last_error(w));
    fd.points = NULL;
    GC_CHECK(gc_world_add_finger(w, &fd, &bad) == GC_ERR_INVALID_ARGUMENT, "points NULL with num_points 4");
    GC_CHECK(gc_world_finger_count(w) == 2, "no finger added by a failed call");
    gc_world_destroy(w);
}

/* Convex fingers turned and thrown through a box, a capsule, a sphere and a long prism (body
 * vertices, feature edges, a capsule's segment), for ASan/UBSan: every output stays finite. */
static void test_convex_finger_tumbling(void) {
    gcWorldDef wd = gc_default_world_def();
    wd.gravity[2] = 0.0; /* the bodies stay where the pads sweep */
    gcWorld *w = NULL;
    GC_CHECK(gc_world_create(&wd, &w) == GC_OK, "create");
    double box[24], seg[6] = {-0.08, 0, 0, 0.08, 0, 0}, dot[3] = {0, 0, 0};
    box_points(0.03, box);
    gcBodyDef bd = gc_default_body_def();
    gcPartDef parts[3] = {{box, 8, 0.0}, {seg, 2, 0.005}, {dot, 1, 0.02}};
    int32_t id;
    for (int i = 0; i < 3; ++i) {
        bd.position[0] = 0.1 * i;
        GC_CHECK(gc_world_add_body(w, &bd, &parts[i], 1, &id) == GC_OK, "body %d: %s", i, gc_world_last_error(w));
    }
    double pad[24];
    box_points(0.04, pad);
    for (int i = 0; i < 8; ++i) pad[3 * i + 2] *= 0.1;
    gcFingerDef fd = gc_default_finger_def();
    fd.points = pad;
    fd.num_points = 8;
    int32_t f[2];
    fd.radius = 0.0;
    GC_CHECK(gc_world_add_finger(w, &fd, &f[0]) == GC_OK, "pad");
    fd.radius = 0.004;
    GC_CHECK(gc_world_add_finger(w, &fd, &f[1]) == GC_OK, "rounded pad");
    uint64_t state = 12345;
    int finite = 1, touched = 0, reversed = 0;
    for (int step = 0; step < 3000; ++step) {
        for (int k = 0; k < 2; ++k) {
            double r[7];
            for (int j = 0; j < 7; ++j) {
                state = state * 6364136223846793005ull + 1442695040888963407ull;
                r[j] = (double)(state >> 11) / 9007199254740992.0 - 0.5;
            }
            double t = 1e-3 * step, pos[3] = {0.1 + 0.15 * sin(t + k) + 0.01 * r[0], 0.02 * r[1], 0.05 * cos(2 * t) + 0.01 * r[2]};
            double q[4] = {1.0 + r[3], r[4], r[5], r[6]};
            GC_CHECK(gc_world_set_finger_pose(w, f[k], pos, q) == GC_OK, "pose");
        }
        gcStatus st = gc_world_step(w, 1e-3);
        GC_CHECK(st == GC_OK || st == GC_WARN_STOPPED, "step %d", st);
        const double *poses = gc_world_body_pose_array(w), *forces = gc_world_finger_force_array(w);
        for (int i = 0; i < 21; ++i) finite &= isfinite(poses[i]) != 0;
        for (int i = 0; i < 6; ++i) finite &= isfinite(forces[i]) != 0;
        for (int k = 0; k < 2; ++k) {
            gcFingerContactPoint cps[16];
            int n = 0;
            GC_CHECK(gc_world_finger_contacts(w, f[k], cps, 16, &n) == GC_OK, "contacts");
            touched += n > 0;
            for (int c = 0; c < n && c < 16; ++c) {
                reversed += cps[c].reversed;
                for (int j = 0; j < 3; ++j) finite &= isfinite(cps[c].point[j]) && isfinite(cps[c].force[j]);
            }
        }
    }
    GC_CHECK(finite, "every pose, force and contact point finite");
    GC_CHECK(touched > 100 && reversed > 0, "the pads touched (%d finger-steps, %d reversed points)", touched, reversed);
    gc_world_destroy(w);
}

int main(void) {
    test_convex_finger();
    test_convex_finger_tumbling();
    test_every_error_names_its_argument();
    test_pinch_and_determinism();
    test_bad_input_leaves_world_unchanged();
    test_shapes_and_compounds();
    return gc_test_summary("test_world");
}
