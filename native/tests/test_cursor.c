/* The light-mass cursor renderer (cursor.c): a cursor finger pressed into the crease of an L
 * of two parts feels both walls exactly; crossing a 1 mm plate at 100 m/s it stays on the
 * near side; in the six-wall corner (three planes active of six in reach) its force is the sum
 * of the three walls; a bad renderer or mass is refused naming it. Built plain and with
 * ASan/UBSan (the active-set enumeration indexes fixed arrays). */
#include "graspcore.h"
#include "gc_test.h"

#include <math.h>
#include <string.h>

static void box(double pts[24], double hx, double hy, double hz, double cx, double cy, double cz) {
    for (int i = 0; i < 8; ++i) {
        pts[3 * i] = cx + ((i & 1) ? hx : -hx);
        pts[3 * i + 1] = cy + ((i & 2) ? hy : -hy);
        pts[3 * i + 2] = cz + ((i & 4) ? hz : -hz);
    }
}

static gcWorld *world(void) {
    gcWorldDef wd = gc_default_world_def();
    wd.gravity[2] = 0.0;
    gcWorld *w = NULL;
    GC_CHECK(gc_world_create(&wd, &w) == GC_OK, "world");
    return w;
}

static int32_t cursor_finger(gcWorld *w, const double at[3]) {
    gcFingerDef fd = gc_default_finger_def();
    fd.radius = 0.005;
    fd.renderer = GC_RENDERER_CURSOR;
    memcpy(fd.position, at, sizeof fd.position);
    int32_t id = -1;
    GC_CHECK(gc_world_add_finger(w, &fd, &id) == GC_OK, "cursor finger");
    return id;
}

/* Moves the HIP from `from` to `to` in n ticks, then holds it `hold` ticks. */
static void drive(gcWorld *w, const double from[3], const double to[3], int n, int hold) {
    for (int i = 1; i <= n + hold; ++i) {
        double s = i >= n ? 1.0 : (double)i / n, p[3];
        for (int k = 0; k < 3; ++k) p[k] = from[k] + (to[k] - from[k]) * s;
        GC_CHECK(gc_world_set_hip(w, 0, p) == GC_OK && gc_world_step(w, 1e-3) == GC_OK, "step %d", i);
    }
}

static void test_crease(void) {
    gcWorld *w = world();
    double floor_pts[24], wall_pts[24];
    box(floor_pts, 0.02, 0.02, 0.005, -0.01, 0, -0.005);
    box(wall_pts, 0.005, 0.02, 0.02, 0.005, 0, 0.01);
    gcPartDef parts[2] = {{floor_pts, 8, 0.0}, {wall_pts, 8, 0.0}};
    gcBodyDef bd = gc_default_body_def();
    bd.is_static = 1;
    bd.mu_s = bd.mu_d = 0.0;
    int32_t b;
    GC_CHECK(gc_world_add_body(w, &bd, parts, 2, &b) == GC_OK, "L body");
    double target[3] = {-0.005 + 0.0005, 0, 0.005 - 0.003}, start[3] = {target[0] - 0.004, 0, target[2] + 0.004};
    cursor_finger(w, start);
    drive(w, start, target, 300, 300);
    double f[3];
    gc_world_finger_force(w, 0, f);
    GC_CHECK(fabs(f[0] + 0.5) < 1e-9 && fabs(f[1]) < 1e-9 && fabs(f[2] - 3.0) < 1e-9, "crease force (%g %g %g)",
             f[0], f[1], f[2]);
    gc_world_destroy(w);
}

static void test_thin_plate_at_100_m_per_s(void) {
    gcWorld *w = world();
    double plate[24];
    box(plate, 0.05, 0.05, 0.0005, 0, 0, 0);
    gcPartDef part = {plate, 8, 0.0};
    gcBodyDef bd = gc_default_body_def();
    bd.is_static = 1;
    int32_t b;
    GC_CHECK(gc_world_add_body(w, &bd, &part, 1, &b) == GC_OK, "plate");
    double start[3] = {0, 0, 0.02}, end[3] = {0, 0, -0.05};
    cursor_finger(w, start);
    drive(w, start, end, 1, 20); /* 7 cm in one tick */
    double go[3], f[3];
    gc_world_god_object(w, 0, go);
    gc_world_finger_force(w, 0, f);
    GC_CHECK(go[2] >= 0.0055 - 1e-9, "the cursor stays above the plate (z %g)", go[2]);
    GC_CHECK(fabs(f[2] - 1000.0 * (0.0055 + 0.05)) < 1e-6, "the spring holds it: %g N", f[2]);
    gc_world_destroy(w);
}

static void test_six_wall_corner(void) {
    gcWorld *w = world();
    double pts[6][24];
    gcPartDef parts[6];
    const double half = 0.02, t = 0.004;
    for (int axis = 0; axis < 3; ++axis)
        for (int s = 0; s < 2; ++s) {
            double c[3] = {0, 0, 0}, h[3] = {half + t, half + t, half + t};
            c[axis] = (s ? 1 : -1) * (half + t / 2);
            h[axis] = t / 2;
            int i = 2 * axis + s;
            box(pts[i], h[0], h[1], h[2], c[0], c[1], c[2]);
            parts[i] = (gcPartDef){pts[i], 8, 0.0};
        }
    gcBodyDef bd = gc_default_body_def();
    bd.is_static = 1;
    bd.mu_s = bd.mu_d = 0.0;
    int32_t b;
    GC_CHECK(gc_world_add_body(w, &bd, parts, 6, &b) == GC_OK, "cavity");
    double centre[3] = {0, 0, 0}, corner[3] = {half - 0.005 + 0.001, half - 0.005 + 0.002, half - 0.005 + 0.003};
    cursor_finger(w, centre);
    drive(w, centre, corner, 200, 300);
    double f[3];
    gc_world_finger_force(w, 0, f);
    GC_CHECK(fabs(f[0] + 1.0) < 1e-9 && fabs(f[1] + 2.0) < 1e-9 && fabs(f[2] + 3.0) < 1e-9,
             "three walls: (%g %g %g)", f[0], f[1], f[2]);
    gc_world_destroy(w);
}

static void test_arguments(void) {
    gcWorld *w = world();
    gcFingerDef fd = gc_default_finger_def();
    GC_CHECK(fd.renderer == GC_RENDERER_XFCA && fd.cursor_mass == 0.002, "defaults");
    int32_t id;
    fd.renderer = (gcFingerRenderer)7;
    GC_CHECK(gc_world_add_finger(w, &fd, &id) == GC_ERR_INVALID_ARGUMENT &&
                 strncmp(gc_world_last_error(w), "renderer:", 9) == 0, "renderer refused: %s", gc_world_last_error(w));
    fd.renderer = GC_RENDERER_CURSOR;
    fd.cursor_mass = -1.0;
    GC_CHECK(gc_world_add_finger(w, &fd, &id) == GC_ERR_INVALID_ARGUMENT &&
                 strncmp(gc_world_last_error(w), "cursor_mass:", 12) == 0, "mass refused: %s", gc_world_last_error(w));
    /* The cursor renders sphere fingers without torsion (docs/physics.md "Renderers and finger shapes"). */
    fd.cursor_mass = 0.002;
    fd.torsion = 0.01;
    GC_CHECK(gc_world_add_finger(w, &fd, &id) == GC_ERR_INVALID_ARGUMENT &&
                 strncmp(gc_world_last_error(w), "renderer:", 9) == 0, "torsion refused: %s", gc_world_last_error(w));
    fd.torsion = 0.0;
    double pad[24];
    for (int i = 0; i < 8; ++i)
        pad[3 * i] = i & 1 ? 0.01 : -0.01, pad[3 * i + 1] = i & 2 ? 0.01 : -0.01, pad[3 * i + 2] = i & 4 ? 0.002 : -0.002;
    fd.points = pad;
    fd.num_points = 8;
    GC_CHECK(gc_world_add_finger(w, &fd, &id) == GC_ERR_INVALID_ARGUMENT &&
                 strncmp(gc_world_last_error(w), "renderer:", 9) == 0, "convex finger refused: %s", gc_world_last_error(w));
    GC_CHECK(gc_world_finger_count(w) == 0, "nothing added");
    fd.renderer = GC_RENDERER_XFCA;
    GC_CHECK(gc_world_add_finger(w, &fd, &id) == GC_OK, "the pad with xFCA: %s", gc_world_last_error(w));
    gc_world_destroy(w);
}

int main(void) {
    test_crease();
    test_thin_plate_at_100_m_per_s();
    test_six_wall_corner();
    test_arguments();
    return gc_test_summary("test_cursor");
}
