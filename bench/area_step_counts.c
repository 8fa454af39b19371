/* The core's cost of the contact patch it now reports (gcFinger.patch, for the grasp analysis),
 * counted in instructions: 3000 steps (dt = 1 ms) of a plate resting on a palm (a convex finger,
 * 4 contact points) or of a box squeezed and lifted by three sphere fingers, under callgrind with
 * collection in gc_world_step only; run against two builds of the core (docs/benchmarks.md
 * "Area contacts in the grasp analysis"):
 *
 *   cc -std=c11 -O2 -g -ffp-contract=off -Inative/include bench/area_step_counts.c build/c/libgraspcore.a \
 *      -lm -lpthread -o build/area_step_counts
 *   valgrind --tool=callgrind --toggle-collect=gc_world_step build/area_step_counts palm|spheres
 *
 * It prints the state hash at the end (the same in both builds: the patch is an output). */
#include <stdio.h>
#include <string.h>

#include "graspcore.h"

static void box(double hx, double hy, double hz, double *out) {
    int k = 0;
    for (int i = 0; i < 2; ++i)
        for (int j = 0; j < 2; ++j)
            for (int l = 0; l < 2; ++l) {
                out[k++] = i ? hx : -hx;
                out[k++] = j ? hy : -hy;
                out[k++] = l ? hz : -hz;
            }
}

int main(int argc, char **argv) {
    int palm = argc > 1 && strcmp(argv[1], "palm") == 0;
    gcWorldDef wd = gc_default_world_def();
    gcWorld *w = NULL;
    if (gc_world_create(&wd, &w) != GC_OK) return 1;
    double body[24], hull[24];
    int32_t id;
    gcBodyDef bd = gc_default_body_def();
    gcFingerDef fd = gc_default_finger_def();
    fd.damping = 2.0;
    if (palm) {
        box(0.1, 0.1, 0.005, body);
        box(0.045, 0.04, 0.01, hull);
        fd.radius = 0.0, fd.points = hull, fd.num_points = 8, fd.position[2] = -0.01;
        gc_world_add_finger(w, &fd, &id);
        bd.mass = 0.4, bd.position[2] = 0.005;
    } else {
        box(0.03, 0.03, 0.03, body);
        const double y[3] = {-0.012, 0.012, 0.0}, x[3] = {0.045, 0.045, -0.045};
        for (int i = 0; i < 3; ++i) {
            fd.position[0] = x[i], fd.position[1] = y[i];
            gc_world_add_finger(w, &fd, &id);
        }
        bd.mass = 0.2;
    }
    gcPartDef part = {body, 8, 0.0};
    gc_world_add_body(w, &bd, &part, 1, &id);
    for (int s = 1; s <= 3000; ++s) {
        if (!palm) { /* close over 0.5 s (the -x finger twice as deep), lift 5 cm from 1.5 s */
            double u = s < 500 ? s / 500.0 : 1.0, lift = s > 1500 ? 0.05 * (s - 1500) / 1500.0 : 0.0;
            const double y[3] = {-0.012, 0.012, 0.0}, x0[3] = {0.045, 0.045, -0.045}, x1[3] = {0.035, 0.035, -0.032};
            for (int i = 0; i < 3; ++i) {
                double hip[3] = {x0[i] + u * (x1[i] - x0[i]), y[i], lift};
                gc_world_set_hip(w, i, hip);
            }
        }
        gc_world_step(w, 1e-3);
    }
    printf("%s: state hash %016llx\n", palm ? "palm" : "spheres", (unsigned long long)gc_world_state_hash(w));
    gc_world_destroy(w);
    return 0;
}
