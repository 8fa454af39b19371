/* The runtime (runtime.c): the manual clock reproduces synchronous stepping bit for bit
 * (with hand-over of a pinched box to the haptic loop and back), 1000 start/stop cycles,
 * stop while the loops are busy and inputs arrive from other threads, the watchdog (stale
 * input, missed deadlines), the force clamp and ramp, NaN/Inf input rejected and counted,
 * mutating calls refused while running, the haptic thread's own setup (timer slack, memory
 * locked while running and unlocked at stop). Built plain, with ASan/UBSan and with TSan.
 * Asserts behaviour, never precise rates (CI machines are small and loaded). */
#define _POSIX_C_SOURCE 200809L
#include "graspcore.h"
#include "gc_test.h"

#include <dirent.h>
#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define DT 1e-3

static double now_s(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static void sleep_s(double s) {
    struct timespec ts = {(time_t)s, (long)((s - floor(s)) * 1e9)};
    nanosleep(&ts, NULL);
}

static int32_t add_box(gcWorld *w, double h, const double pos[3], int is_static, double mass) {
    double pts[24];
    for (int i = 0; i < 8; ++i) {
        pts[3 * i] = (i & 1) ? h : -h;
        pts[3 * i + 1] = (i & 2) ? h : -h;
        pts[3 * i + 2] = (i & 4) ? h : -h;
    }
    gcPartDef part = {pts, 8, 0.0};
    gcBodyDef def = gc_default_body_def();
    memcpy(def.position, pos, sizeof def.position);
    def.is_static = is_static;
    def.mass = mass;
    int32_t id = -1;
    GC_CHECK(gc_world_add_body(w, &def, &part, 1, &id) == GC_OK, "add_box: %s", gc_world_last_error(w));
    return id;
}

static int32_t add_finger(gcWorld *w, double x, double y, double z) {
    gcFingerDef def = gc_default_finger_def();
    def.damping = 2.0;
    def.position[0] = x, def.position[1] = y, def.position[2] = z;
    int32_t id = -1;
    GC_CHECK(gc_world_add_finger(w, &def, &id) == GC_OK, "add_finger: %s", gc_world_last_error(w));
    return id;
}

/* A 6 cm box pinched by two fingers at x = -/+0.041 (touching), a box resting on a static
 * table, and a box falling freely. */
static gcWorld *pinch_scene(void) {
    gcWorldDef def = gc_default_world_def();
    gcWorld *w = NULL;
    GC_CHECK(gc_world_create(&def, &w) == GC_OK, "create");
    double held[3] = {0, 0, 0}, table[3] = {0.5, 0, -0.1}, rest[3] = {0.5, 0, -0.07 + 1e-4}, fall[3] = {-0.5, 0, 0.2};
    add_box(w, 0.03, held, 0, 0.2);
    add_box(w, 0.05, table, 1, 1.0);
    add_box(w, 0.02, rest, 0, 0.1);
    add_box(w, 0.02, fall, 0, 0.1);
    add_finger(w, -0.041, 0, 0);
    add_finger(w, 0.041, 0, 0);
    return w;
}

/* HIPs at tick i: squeeze 3 mm and lift 5 cm over 0.5 s, hold, then open the hand. */
static void pinch_hips(int i, double hips[6]) {
    double lift = 0.05 * fmin(i / 500.0, 1.0);
    double open = i > 700 ? 0.03 * fmin((i - 700) / 100.0, 1.0) : 0.0;
    double hx[6] = {-0.035 - open, 0, lift, 0.035 + open, 0, lift};
    memcpy(hips, hx, sizeof hx);
}

static gcRuntimeDef manual_def(double object_rate, int max_adopted) {
    gcRuntimeDef def = gc_default_runtime_def();
    def.realtime = 0;
    def.object_rate = object_rate;
    def.max_adopted_bodies = max_adopted;
    return def;
}

/* Runs `ticks` ticks on the manual clock, stopping and restarting every `chunk`. */
static uint64_t run_manual(gcWorld *w, const gcRuntimeDef *def, int ticks, int chunk, int *max_adopted_seen) {
    double hips[6];
    int i = 0;
    while (i < ticks) {
        GC_CHECK(gc_world_start(w, def) == GC_OK, "start: %s", gc_world_last_error(w));
        for (int k = 0; k < chunk && i < ticks; ++k, ++i) {
            pinch_hips(i, hips);
            GC_CHECK(gc_world_push_hips(w, hips, 2, i * DT) == GC_OK, "push");
            GC_CHECK(gc_world_advance(w, 1, 0.0) == GC_OK, "advance: %s", gc_world_last_error(w));
            gcRuntimeStats st;
            gc_world_stats(w, &st);
            if (max_adopted_seen && st.adopted_bodies > *max_adopted_seen) *max_adopted_seen = st.adopted_bodies;
        }
        GC_CHECK(gc_world_stop(w) == GC_OK, "stop");
    }
    return gc_world_state_hash(w);
}

static void test_manual_clock_matches_step(void) {
    const int ticks = 1200;
    gcWorld *ref = pinch_scene();
    double hips[6], p_ref[3], q_ref[4];
    for (int i = 0; i < ticks; ++i) {
        pinch_hips(i, hips);
        gc_world_set_hips(ref, hips, 2);
        gc_world_step(ref, DT);
        if (i == 700) {
            gc_world_body_pose(ref, 0, p_ref, q_ref);
            GC_CHECK(fabs(p_ref[2] - 0.049) < 2e-3, "reference: the box is held up (z %g)", p_ref[2]);
        }
    }
    uint64_t expect = gc_world_state_hash(ref);
    gc_world_body_pose(ref, 0, p_ref, q_ref);
    GC_CHECK(p_ref[2] < 0.0, "reference: the box was dropped (z %g)", p_ref[2]);

    /* Equal rates: the haptic loop adopts the pinched box, hands it back when the hand
     * opens; the object manager steps the rest. Same bits as gc_world_step. */
    gcRuntimeDef def = manual_def(1000.0, 3);
    gcWorld *w = pinch_scene();
    int adopted = 0;
    uint64_t got = run_manual(w, &def, ticks, ticks, &adopted);
    GC_CHECK(got == expect, "manual clock, one run: hash %llx vs step %llx", (unsigned long long)got,
             (unsigned long long)expect);
    GC_CHECK(adopted == 1, "the pinched box was adopted (max %d)", adopted);
    gcRuntimeStats st;
    gc_world_stats(w, &st);
    GC_CHECK(st.adopted_bodies == 0, "handed back after the hand opened (%d)", st.adopted_bodies);
    gc_world_destroy(w);

    /* Stopping and restarting (mid-grasp) changes nothing either. */
    w = pinch_scene();
    got = run_manual(w, &def, ticks, 97, NULL);
    GC_CHECK(got == expect, "manual clock, restarted every 97 ticks: hash differs");
    gc_world_destroy(w);

    /* Without adoption the object manager steps the held box from the same springs. */
    def = manual_def(1000.0, 0);
    w = pinch_scene();
    adopted = 0;
    got = run_manual(w, &def, ticks, ticks, &adopted);
    GC_CHECK(got == expect && adopted == 0, "manual clock without adoption: hash differs or adopted %d", adopted);
    gc_world_destroy(w);

    /* Object manager at half rate: not the synchronous schedule, but deterministic, and the
     * held box (stepped by the haptic loop) is lifted all the same. */
    def = manual_def(500.0, 3);
    w = pinch_scene();
    uint64_t a = run_manual(w, &def, 600, 600, NULL);
    double p[3], q[4];
    gc_world_body_pose(w, 0, p, q);
    GC_CHECK(fabs(p[2] - 0.049) < 2e-3, "half-rate object manager: held box lifted to %g", p[2]);
    gc_world_destroy(w);
    w = pinch_scene();
    uint64_t b = run_manual(w, &def, 600, 600, NULL);
    GC_CHECK(a == b, "half-rate object manager: two runs differ");
    gc_world_destroy(w);
    gc_world_destroy(ref);
}

static void test_refused_while_running(void) {
    gcWorld *w = pinch_scene();
    double v[3] = {0, 0, 0}, q[4] = {1, 0, 0, 0};
    GC_CHECK(gc_world_push_hips(w, v, 1, 0.0) == GC_ERR_NOT_RUNNING, "push before start");
    GC_CHECK(gc_world_advance(w, 1, 0.0) == GC_ERR_NOT_RUNNING, "advance before start");
    gcRuntimeDef def = gc_default_runtime_def();
    def.haptic_rate = 5.0;
    GC_CHECK(gc_world_start(w, &def) == GC_ERR_INVALID_ARGUMENT && strstr(gc_world_last_error(w), "haptic_rate"),
             "bad haptic_rate named: %s", gc_world_last_error(w));
    def = gc_default_runtime_def();
    def.watchdog_timeout = 0.0005;
    GC_CHECK(gc_world_start(w, &def) == GC_ERR_INVALID_ARGUMENT && strstr(gc_world_last_error(w), "watchdog"),
             "bad watchdog named");
    def = manual_def(500, 3);
    GC_CHECK(gc_world_start(w, &def) == GC_OK, "start");
    GC_CHECK(gc_world_running(w), "running");
    GC_CHECK(gc_world_start(w, &def) == GC_ERR_BUSY, "second start");
    GC_CHECK(gc_world_step(w, DT) == GC_ERR_BUSY, "step while running");
    GC_CHECK(gc_world_set_hip(w, 0, v) == GC_ERR_BUSY, "set_hip while running");
    GC_CHECK(gc_world_set_hips(w, v, 1) == GC_ERR_BUSY, "set_hips while running");
    GC_CHECK(gc_world_set_gravity(w, v) == GC_ERR_BUSY, "set_gravity while running");
    GC_CHECK(gc_world_set_body_pose(w, 0, v, q) == GC_ERR_BUSY, "set_body_pose while running");
    GC_CHECK(gc_world_set_body_velocity(w, 0, v, v) == GC_ERR_BUSY, "set_body_velocity while running");
    GC_CHECK(gc_world_set_body_friction(w, 0, 1, 1, 0) == GC_ERR_BUSY, "set_body_friction while running");
    int32_t id;
    gcFingerDef fd = gc_default_finger_def();
    GC_CHECK(gc_world_add_finger(w, &fd, &id) == GC_ERR_BUSY, "add_finger while running");
    GC_CHECK(gc_world_advance(w, -1, 0.0) == GC_ERR_INVALID_ARGUMENT, "negative ticks");
    GC_CHECK(gc_world_advance(w, 10, 0.0) == GC_OK, "advance");
    /* Queries answer from the last snapshot. */
    gcSnapshot snap;
    memset(&snap, 0, sizeof snap);
    double poses[4 * 7];
    snap.poses = poses;
    GC_CHECK(gc_world_snapshot(w, &snap) == GC_OK && snap.tick == 10, "snapshot tick %llu", (unsigned long long)snap.tick);
    GC_CHECK(fabs(gc_world_time(w) - 0.010) < 1e-12, "time from the snapshot: %g", gc_world_time(w));
    double p[3], qq[4];
    gc_world_body_pose(w, 3, p, qq);
    GC_CHECK(p[2] == poses[3 * 7 + 2] && p[2] < 0.2, "body_pose from the snapshot: %g", p[2]);
    GC_CHECK(gc_world_stop(w) == GC_OK && !gc_world_running(w), "stop");
    GC_CHECK(gc_world_stop(w) == GC_OK, "second stop is a no-op");
    GC_CHECK(gc_world_step(w, DT) == GC_OK, "step after stop");
    gc_world_destroy(w);
}

/* Snapshot normals and velocities, without gravity: a 6 cm box squeezed 3 mm from -x and +x
 * (its normals point out of it: -x, +x), a free finger (normal 0), and a box whose centre of
 * mass is 10 cm off its frame origin, moving at 0.1 m/s in x and spinning at 2 rad/s about
 * z with an isotropic inertia (so both stay constant): its frame origin moves at
 * v + w x (origin - com). Running (display channel) and stopped (the world) alike. */
static void check_snapshot_normals_velocities(const gcSnapshot *s, const char *when) {
    const double *n = s->normals;
    GC_CHECK(fabs(n[0] + 1) < 1e-9 && fabs(n[1]) < 1e-9 && fabs(n[2]) < 1e-9, "%s: finger 0 normal (%g %g %g)",
             when, n[0], n[1], n[2]);
    GC_CHECK(fabs(n[3] - 1) < 1e-9 && fabs(n[4]) < 1e-9 && fabs(n[5]) < 1e-9, "%s: finger 1 normal (%g %g %g)",
             when, n[3], n[4], n[5]);
    GC_CHECK(n[6] == 0 && n[7] == 0 && n[8] == 0, "%s: free finger's normal is 0", when);
    GC_CHECK(s->contact_bodies[0] == 0 && s->contact_bodies[1] == 0 && s->contact_bodies[2] == -1,
             "%s: contacts %d %d %d", when, s->contact_bodies[0], s->contact_bodies[1], s->contact_bodies[2]);
    const double *v = &s->velocities[6], *p = &s->poses[7];
    /* origin - com = -(R c), R from the snapshot's own quaternion, c = (0.1, 0, 0). */
    double qw = p[3], qx = p[4], qy = p[5], qz = p[6];
    double rc[3] = {0.1 * (1 - 2 * (qy * qy + qz * qz)), 0.1 * 2 * (qx * qy + qw * qz), 0.1 * 2 * (qx * qz - qw * qy)};
    /* The def's velocity is the frame origin's: the centre of mass moves at
     * (0.1, 0, 0) + (0, 0, 2) x (0.1, 0, 0) = (0.1, 0.2, 0); the origin at that + w x (-R c). */
    double expect[3] = {0.1 + 2.0 * rc[1], 0.2 - 2.0 * rc[0], 0.0};
    GC_CHECK(fabs(v[0] - expect[0]) < 1e-9 && fabs(v[1] - expect[1]) < 1e-9 && fabs(v[2] - expect[2]) < 1e-9,
             "%s: origin velocity (%g %g %g) vs (%g %g %g)", when, v[0], v[1], v[2], expect[0], expect[1], expect[2]);
    GC_CHECK(fabs(v[3]) < 1e-12 && fabs(v[4]) < 1e-12 && fabs(v[5] - 2.0) < 1e-12, "%s: angular (%g %g %g)", when,
             v[3], v[4], v[5]);
    GC_CHECK(fabs(rc[1]) > 0.01, "%s: the offset body has turned (R c = %g %g)", when, rc[0], rc[1]);
}

static void test_snapshot_normals_velocities(void) {
    gcWorldDef wd = gc_default_world_def();
    wd.gravity[2] = 0.0;
    gcWorld *w = NULL;
    GC_CHECK(gc_world_create(&wd, &w) == GC_OK, "create");
    double at[3] = {0, 0, 0};
    add_box(w, 0.03, at, 0, 0.2);
    double pts[24];
    for (int i = 0; i < 8; ++i) {
        pts[3 * i] = (i & 1) ? 0.02 : -0.02;
        pts[3 * i + 1] = (i & 2) ? 0.02 : -0.02;
        pts[3 * i + 2] = (i & 4) ? 0.02 : -0.02;
    }
    gcPartDef part = {pts, 8, 0.0};
    gcBodyDef bd = gc_default_body_def();
    bd.position[0] = 1.0;
    bd.mass = 0.1;
    bd.has_center_of_mass = 1;
    bd.center_of_mass[0] = 0.1;
    bd.has_inertia = 1;
    bd.inertia[0] = bd.inertia[4] = bd.inertia[8] = 1e-3;
    bd.linear_velocity[0] = 0.1;
    bd.angular_velocity[2] = 2.0;
    int32_t spinner = -1;
    GC_CHECK(gc_world_add_body(w, &bd, &part, 1, &spinner) == GC_OK && spinner == 1, "spinner: %s",
             gc_world_last_error(w));
    add_finger(w, -0.041, 0, 0);
    add_finger(w, 0.041, 0, 0);
    add_finger(w, 0, 0, 1.0);
    double hips[9] = {-0.027, 0, 0, 0.027, 0, 0, 0, 0, 1.0};
    double poses[2 * 7], vel[2 * 6], normals[3 * 3];
    int32_t contacts[3];
    gcSnapshot s;
    memset(&s, 0, sizeof s);
    s.poses = poses, s.velocities = vel, s.normals = normals, s.contact_bodies = contacts;
    gcRuntimeDef def = manual_def(1000.0, 3);
    GC_CHECK(gc_world_start(w, &def) == GC_OK, "start: %s", gc_world_last_error(w));
    for (int i = 0; i < 200; ++i) {
        GC_CHECK(gc_world_push_hips(w, hips, 3, i * DT) == GC_OK, "push");
        gc_world_advance(w, 1, 0.0);
    }
    GC_CHECK(gc_world_snapshot(w, &s) == GC_OK, "snapshot while running");
    check_snapshot_normals_velocities(&s, "running");
    double running_normals[9];
    memcpy(running_normals, normals, sizeof normals);
    /* The world's own query answers from the snapshot: the same numbers. */
    double lin[3], ang[3];
    gc_world_body_velocity(w, 1, lin, ang);
    GC_CHECK(lin[0] == vel[6] && lin[1] == vel[7] && ang[2] == vel[11], "body_velocity agrees with the snapshot");
    GC_CHECK(gc_world_stop(w) == GC_OK, "stop");
    memset(vel, 0, sizeof vel);
    memset(normals, 0, sizeof normals);
    GC_CHECK(gc_world_snapshot(w, &s) == GC_OK, "snapshot stopped");
    check_snapshot_normals_velocities(&s, "stopped");
    GC_CHECK(memcmp(running_normals, normals, sizeof normals) == 0, "stopped: the same normals as running");
    gc_world_destroy(w);
}

static double norm3(const double *v) { return sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]); }

/* One finger pressed 5 cm into a static block: a 50 N spring. */
static gcWorld *press_scene(void) {
    gcWorldDef wd = gc_default_world_def();
    gcWorld *w = NULL;
    gc_world_create(&wd, &w);
    double at[3] = {0, 0, 0};
    add_box(w, 0.1, at, 1, 1.0);
    add_finger(w, 0, 0, 0.2);
    return w;
}

static void device_force(gcWorld *w, double force[3], double spring[3], int *enabled) {
    gcSnapshot s;
    memset(&s, 0, sizeof s);
    s.forces = force;
    s.spring_forces = spring;
    gc_world_snapshot(w, &s);
    *enabled = s.forces_enabled;
}

static void test_clamp_ramp_watchdog(void) {
    gcWorld *w = press_scene();
    gcRuntimeDef def = manual_def(500, 3);
    def.max_force = 10.0;
    def.ramp_time = 0.2;
    def.hip_timeout = 0.05;
    def.watchdog_timeout = 0.004;
    GC_CHECK(gc_world_start(w, &def) == GC_OK, "start");
    double f[3], spring[3];
    int enabled;
    /* Forces are off until input arrives. */
    gc_world_advance(w, 5, 0.0);
    device_force(w, f, spring, &enabled);
    GC_CHECK(!enabled && norm3(f) == 0.0, "no input yet: device force %g", norm3(f));

    /* Sweep down into the block (entry needs the path), then hold 5 cm deep (the block's
     * top is at 0.1, the fingertip's radius 8 mm). */
    double hip[3] = {0, 0, 0.2};
    int t = 0;
    for (int i = 0; i <= 20; ++i, ++t) {
        hip[2] = 0.2 - (0.2 - 0.058) * (i < 19 ? i / 19.0 : 1.0);
        gc_world_push_hips(w, hip, 1, t * DT);
        gc_world_advance(w, 1, 0.0);
    }
    device_force(w, f, spring, &enabled);
    GC_CHECK(fabs(spring[2] - 50.0) < 1e-6, "spring force 50 N (%g)", spring[2]);
    /* Ramp: 20 ms of 200 ms in: a tenth of the spring, below the clamp. */
    GC_CHECK(enabled && fabs(f[2] - 5.0) < 0.3, "ramping: %g N", f[2]);
    for (int i = 0; i < 80; ++i, ++t) { /* to 100 ms: half the spring (25 N) is clamped to 10 */
        gc_world_push_hips(w, hip, 1, t * DT);
        gc_world_advance(w, 1, 0.0);
    }
    device_force(w, f, spring, &enabled);
    GC_CHECK(fabs(norm3(f) - 10.0) < 1e-9, "clamped to 10 N (%g)", norm3(f));
    GC_CHECK(fabs(spring[2] - 50.0) < 1e-6, "physics keeps the unclamped spring (%g)", spring[2]);

    /* A loop stalled past watchdog_timeout: zero, then ramp again. */
    gc_world_push_hips(w, hip, 1, t++ * DT);
    gc_world_advance(w, 1, 0.010);
    device_force(w, f, spring, &enabled);
    gcRuntimeStats st;
    gc_world_stats(w, &st);
    GC_CHECK(!enabled && norm3(f) == 0.0 && st.watchdog_trips == 1, "watchdog: %g N, %llu trips", norm3(f),
             (unsigned long long)st.watchdog_trips);
    gc_world_push_hips(w, hip, 1, t++ * DT);
    gc_world_advance(w, 10, 0.0);
    device_force(w, f, spring, &enabled);
    GC_CHECK(enabled && norm3(f) > 0.0 && norm3(f) < 10.0, "ramping in again after the watchdog: %g", norm3(f));

    /* Stale input: no push for longer than hip_timeout. */
    gc_world_advance(w, 60, 0.0);
    device_force(w, f, spring, &enabled);
    gc_world_stats(w, &st);
    GC_CHECK(!enabled && norm3(f) == 0.0 && st.stale_inputs == 1, "stale input: %g N, %llu stale", norm3(f),
             (unsigned long long)st.stale_inputs);
    GC_CHECK(fabs(spring[2] - 50.0) < 1e-6, "the physics goes on with the last HIP (%g)", spring[2]);

    /* NaN, Inf and time going backwards: rejected, counted, nothing changes. */
    double bad[3] = {0, NAN, 0}, inf[3] = {INFINITY, 0, 0}, up[3] = {0, 0, 0.5};
    GC_CHECK(gc_world_push_hips(w, bad, 1, t * DT) == GC_WARN_REJECTED, "NaN rejected");
    GC_CHECK(gc_world_push_hips(w, inf, 1, t * DT) == GC_WARN_REJECTED, "Inf rejected");
    GC_CHECK(gc_world_push_hips(w, hip, 1, NAN) == GC_WARN_REJECTED, "NaN time rejected");
    GC_CHECK(gc_world_push_hips(w, up, 1, 0.0) == GC_WARN_REJECTED, "older time rejected");
    GC_CHECK(gc_world_push_hips(w, hip, 2, t * DT) == GC_ERR_INVALID_ARGUMENT, "too many rows");
    gc_world_advance(w, 1, 0.0);
    gc_world_stats(w, &st);
    GC_CHECK(st.rejected_inputs == 4, "4 rejected (%llu)", (unsigned long long)st.rejected_inputs);
    gcSnapshot s;
    memset(&s, 0, sizeof s);
    double hips[3], go[3];
    s.hips = hips;
    s.god_objects = go;
    gc_world_snapshot(w, &s);
    GC_CHECK(hips[0] == 0.0 && hips[1] == 0.0 && hips[2] == hip[2] && isfinite(go[0] + go[1] + go[2]),
             "HIP unchanged by rejected input");
    /* Fresh input: forces come back, ramped. */
    gc_world_push_hips(w, hip, 1, t++ * DT);
    gc_world_advance(w, 2, 0.0);
    device_force(w, f, spring, &enabled);
    GC_CHECK(enabled && norm3(f) < 2.0, "back after fresh input, ramping (%g)", norm3(f));
    gc_world_stop(w);
    gc_world_destroy(w);
}

static gcRuntimeDef realtime_def(void) {
    gcRuntimeDef def = gc_default_runtime_def();
    def.watchdog_timeout = 0.05; /* loaded CI: trips are not what these tests look at */
    return def;
}

static void test_start_stop_cycles(void) {
    gcWorld *w = pinch_scene();
    gcRuntimeDef def = realtime_def();
    double hips[6];
    pinch_hips(0, hips);
    int failures = 0;
    double t0 = now_s();
    for (int i = 0; i < 1000; ++i) {
        if (gc_world_start(w, &def) != GC_OK) ++failures;
        if (i % 10 == 0) gc_world_push_hips(w, hips, 2, 0.0);
        if (i % 100 == 0) sleep_s(0.003); /* let the loops tick now and then */
        if (gc_world_stop(w) != GC_OK || gc_world_running(w)) ++failures;
    }
    GC_CHECK(failures == 0, "1000 start/stop cycles: %d failures", failures);
    GC_CHECK(now_s() - t0 < 60.0, "1000 cycles took %.1f s", now_s() - t0);
    GC_CHECK(gc_world_step(w, DT) == GC_OK, "synchronous step afterwards");
    gc_world_destroy(w);
}

typedef struct Pusher {
    gcWorld *world;
    atomic_int stop;
    long pushes, snapshots;
} Pusher;

static void *pusher_main(void *arg) {
    Pusher *p = arg;
    double hips[6];
    int i = 0;
    while (!atomic_load(&p->stop)) {
        pinch_hips(i % 700, hips);
        if (gc_world_push_hips(p->world, hips, 2, i * DT) == GC_OK) p->pushes++;
        ++i;
    }
    return NULL;
}

static void *snapshot_main(void *arg) {
    Pusher *p = arg;
    double poses[256 * 7], forces[2 * 3];
    while (!atomic_load(&p->stop)) {
        gcSnapshot s;
        memset(&s, 0, sizeof s);
        s.poses = poses;
        s.forces = forces;
        gc_world_snapshot(p->world, &s);
        gcRuntimeStats st;
        gc_world_stats(p->world, &st);
        p->snapshots++;
    }
    return NULL;
}

/* Many bodies keep the object manager busy; inputs and snapshots come from two other
 * threads; the haptic loop is stalled when stop() arrives. */
static void test_stop_while_busy(void) {
    gcWorldDef wd = gc_default_world_def();
    gcWorld *w = NULL;
    gc_world_create(&wd, &w);
    double at[3] = {0, 0, 0};
    add_box(w, 0.03, at, 0, 0.2);
    add_finger(w, -0.041, 0, 0);
    add_finger(w, 0.041, 0, 0);
    double floor_at[3] = {0, 0, -1.0};
    add_box(w, 0.5, floor_at, 1, 1.0);
    for (int i = 0; i < 120; ++i) { /* a pile falling onto the floor */
        double p[3] = {-0.4 + 0.08 * (i % 10), -0.4 + 0.08 * ((i / 10) % 10), -0.45 + 0.06 * (i / 100)};
        add_box(w, 0.02, p, 0, 0.05);
    }
    gcRuntimeDef def = realtime_def();
    for (int round = 0; round < 3; ++round) {
        GC_CHECK(gc_world_start(w, &def) == GC_OK, "start");
        Pusher p = {w, 0, 0, 0};
        pthread_t a, b;
        pthread_create(&a, NULL, pusher_main, &p);
        pthread_create(&b, NULL, snapshot_main, &p);
        sleep_s(0.1);
        gc_world_debug_stall(w, 0.03);
        sleep_s(0.001);
        double t0 = now_s();
        GC_CHECK(gc_world_stop(w) == GC_OK, "stop while busy");
        double took = now_s() - t0;
        GC_CHECK(took < 5.0, "stop returned after %.3f s", took);
        atomic_store(&p.stop, 1);
        pthread_join(a, NULL);
        pthread_join(b, NULL);
        GC_CHECK(p.pushes > 0 && p.snapshots > 0, "inputs (%ld) and snapshots (%ld) went through", p.pushes,
                 p.snapshots);
        int finite = 1;
        const double *poses = gc_world_body_pose_array(w);
        for (int i = 0; i < 7 * gc_world_body_count(w); ++i) finite &= isfinite(poses[i]);
        GC_CHECK(finite, "state finite after stop");
        GC_CHECK(gc_world_time(w) > 0.0, "time advanced (%g)", gc_world_time(w));
    }
    gc_world_destroy(w);
}

/* Real threads: the loops tick, the pinched box is adopted and handed back, the watchdog
 * trips on a stalled loop, the reader-side watchdog zeroes a stale publication. */
static void test_realtime(void) {
    gcWorld *w = pinch_scene();
    gcRuntimeDef def = realtime_def();
    def.ramp_time = 0.0;
    GC_CHECK(gc_world_start(w, &def) == GC_OK, "start");
    gcRuntimeStats st;
    gc_world_stats(w, &st);
    GC_CHECK(st.running && st.realtime && st.priority_note[0], "stats: running, note '%s'", st.priority_note);
    double hips[6];
    pinch_hips(300, hips);
    int adopted = 0;
    double t0 = now_s();
    while (now_s() - t0 < 10.0 && !adopted) {
        gc_world_push_hips(w, hips, 2, now_s() - t0);
        sleep_s(0.002);
        gc_world_stats(w, &st);
        adopted = st.adopted_bodies == 1;
    }
    GC_CHECK(adopted, "the pinched box was adopted");
    /* Open the hand: handed back to the object manager, which goes on stepping it. */
    double open[6] = {-0.2, 0, 0.03, 0.2, 0, 0.03};
    t0 = now_s();
    int back = 0;
    while (now_s() - t0 < 10.0 && !back) {
        gc_world_push_hips(w, open, 2, 100.0 + now_s() - t0);
        sleep_s(0.002);
        gc_world_stats(w, &st);
        back = st.adopted_bodies == 0;
    }
    GC_CHECK(back, "handed back");
    gcSnapshot s;
    memset(&s, 0, sizeof s);
    double poses[4 * 7];
    s.poses = poses;
    gc_world_snapshot(w, &s);
    double z0 = poses[2], tm0 = s.object_time;
    /* Until the object manager has stepped it (60 s: only a hang's bound, docs/testing.md). */
    for (t0 = now_s(); now_s() - t0 < 60.0 && !(s.object_time > tm0 && poses[2] < z0);) {
        sleep_s(0.01);
        gc_world_push_hips(w, open, 2, 200.0 + now_s() - t0);
        gc_world_snapshot(w, &s);
    }
    GC_CHECK(s.object_time > tm0 && poses[2] < z0, "the released box falls (z %g -> %g)", z0, poses[2]);

    /* A stalled loop trips the watchdog. */
    gc_world_debug_stall(w, 0.1);
    t0 = now_s();
    int tripped = 0;
    while (now_s() - t0 < 10.0 && !tripped) {
        gc_world_push_hips(w, open, 2, 300.0 + now_s() - t0);
        sleep_s(0.005);
        gc_world_stats(w, &st);
        tripped = st.watchdog_trips > 0;
    }
    GC_CHECK(tripped, "watchdog tripped by a 100 ms stall");
    /* The reader sees a publication older than the watchdog timeout as zero force: looked at
     * until it does, within a stall long enough that a busy machine's pauses of this thread fit. */
    gc_world_debug_stall(w, 2.0);
    double f[6];
    memset(&s, 0, sizeof s);
    s.forces = f;
    for (t0 = now_s(), gc_world_snapshot(w, &s); now_s() - t0 < 1.5 && (s.forces_enabled || norm3(f) != 0.0);) {
        sleep_s(0.005);
        gc_world_snapshot(w, &s);
    }
    GC_CHECK(!s.forces_enabled && norm3(f) == 0.0 && norm3(f + 3) == 0.0, "stalled loop: forces zero");
    gc_world_stop(w);
    gc_world_stats(w, &st);
    GC_CHECK(!st.running && st.haptic_ticks > 10 && st.object_ticks > 5 && st.haptic_rate > 0.0,
             "ticks %llu / %llu, rate %g", (unsigned long long)st.haptic_ticks, (unsigned long long)st.object_ticks,
             st.haptic_rate);
    GC_CHECK(st.jitter_p50_us <= st.jitter_p99_us && st.jitter_p99_us <= st.jitter_max_us + 1.0,
             "jitter percentiles ordered: %g %g %g", st.jitter_p50_us, st.jitter_p99_us, st.jitter_max_us);
    gc_world_destroy(w);
}

/* Destroying a running world stops it. */
/* ASan and TSan intercept mlock and munlock as no-ops (they return 0, nothing is locked). */
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define MLOCK_IGNORED 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer)
#define MLOCK_IGNORED 1
#endif
#endif
#ifndef MLOCK_IGNORED
#define MLOCK_IGNORED 0
#endif

/* VmLck of this process in KiB (-1 where /proc is missing). */
static long locked_kib(void) {
    FILE *f = fopen("/proc/self/status", "r");
    if (!f) return -1;
    char line[256];
    long kib = -1;
    while (fgets(line, sizeof line, f))
        if (sscanf(line, "VmLck: %ld", &kib) == 1) break;
    fclose(f);
    return kib;
}

/* How many of this process's threads have exactly `ns` of timer slack; -1 when another
 * thread's slack cannot be read (it needs CAP_SYS_NICE) or there is no /proc. */
static int threads_with_slack(long ns) {
    DIR *d = opendir("/proc/self/task");
    if (!d) return -1;
    int n = 0, readable = 0;
    struct dirent *e;
    while ((e = readdir(d))) {
        if (e->d_name[0] == '.') continue;
        char path[300];
        snprintf(path, sizeof path, "/proc/%.255s/timerslack_ns", e->d_name);
        FILE *f = fopen(path, "r");
        long v;
        if (f && fscanf(f, "%ld", &v) == 1) {
            ++readable;
            n += v == ns;
        }
        if (f) fclose(f);
    }
    closedir(d);
    return readable > 1 ? n : -1;
}

/* The haptic thread sets itself up before its first tick: its note says how it runs (a
 * short time slice at normal priority) and what memory is locked; its timer slack is 1 ns;
 * the locked memory is unlocked at stop, also over repeated start/stop. */
static void test_haptic_thread_setup(void) {
    gcWorld *w = pinch_scene();
    gcRuntimeDef def = realtime_def();
    def.priority = 0;
    long before = locked_kib();
    for (int cycle = 0; cycle < 3; ++cycle) {
        GC_CHECK(gc_world_start(w, &def) == GC_OK, "start");
        gcRuntimeStats st;
        gc_world_stats(w, &st);
        GC_CHECK(!st.rt_priority && strstr(st.priority_note, "normal priority (priority=0), ") &&
                     strstr(st.priority_note, " slice; "),
                 "note at normal priority: '%s'", st.priority_note);
        long kib = 0;
        const char *lock = strstr(st.priority_note, "; ") + 2;
        if (sscanf(lock, "%ld KiB locked", &kib) == 1) {
            long now = locked_kib(); /* blocks sharing a page count once here */
            GC_CHECK(kib > 0 && (now < 0 || now > before || MLOCK_IGNORED), "VmLck %ld KiB with %ld KiB locked (%ld before)",
                     now, kib, before);
        } else {
            GC_CHECK(strncmp(lock, "memory not locked (", 19) == 0, "memory note: '%s'", lock);
        }
        int slack = threads_with_slack(1);
        GC_CHECK(slack != 0, "a thread (the haptic loop) has 1 ns timer slack");
        gc_world_stop(w);
        long after = locked_kib();
        GC_CHECK(after == before, "VmLck back to %ld KiB after stop (%ld)", before, after);
    }
    gc_world_destroy(w);
}

static void test_destroy_running(void) {
    gcWorld *w = pinch_scene();
    gcRuntimeDef def = realtime_def();
    GC_CHECK(gc_world_start(w, &def) == GC_OK, "start");
    sleep_s(0.01);
    gc_world_destroy(w);
    GC_CHECK(1, "destroyed while running");
}

/* A 4 cm cube finger (a pad) pressing a resting box; `sphere` adds a sphere finger too. */
static gcWorld *pad_scene(void) {
    gcWorldDef wd = gc_default_world_def();
    gcWorld *w = NULL;
    GC_CHECK(gc_world_create(&wd, &w) == GC_OK, "create");
    double box[3] = {0, 0, 0.021};
    add_box(w, 0.02, box, 0, 0.1);
    double pts[24];
    for (int i = 0; i < 8; ++i)
        pts[3 * i] = (i & 1) ? 0.02 : -0.02, pts[3 * i + 1] = (i & 2) ? 0.02 : -0.02,
        pts[3 * i + 2] = (i & 4) ? 0.0 : -0.04;
    gcFingerDef def = gc_default_finger_def();
    def.damping = 2.0;
    def.radius = 0.0;
    def.points = pts;
    def.num_points = 8;
    int32_t id = -1;
    GC_CHECK(gc_world_add_finger(w, &def, &id) == GC_OK, "add pad: %s", gc_world_last_error(w));
    add_finger(w, 0.3, 0, 0.1);
    return w;
}

/* A HIP track's orientations: the manual clock equals set_finger_pose + step bit for bit (the
 * second sample given as -q: the shorter arc), and bad orientations are refused by name. */
static void test_track_orientations(void) {
    enum { N = 3, TICKS = 40 };
    const double c = cos(0.1), s = sin(0.1);
    const double times[N] = {0.0, 0.01, 0.025};
    double pos[N * 2 * 3] = {0}, quat[N * 2 * 4] = {0};
    const double q_pad[N][4] = {{1, 0, 0, 0}, {-c, -s, 0, 0}, {c * c - s * s, 2 * s * c, 0, 0}};
    for (int k = 0; k < N; ++k) {
        pos[6 * k + 2] = 0.001 * k;
        pos[6 * k + 3] = 0.3, pos[6 * k + 5] = 0.1;
        memcpy(&quat[8 * k], q_pad[k], sizeof q_pad[k]);
        quat[8 * k + 4] = 1.0;
    }
    gcWorld *ref = pad_scene();
    for (int i = 0; i < TICKS; ++i) {
        double tt = (i + 1) * DT, p[3], q[4];
        int lo = tt >= times[1] ? 1 : 0;
        if (tt >= times[N - 1]) {
            memcpy(p, &pos[6 * (N - 1)], sizeof p);
            memcpy(q, q_pad[N - 1], sizeof q);
        } else {
            double a = (tt - times[lo]) / (times[lo + 1] - times[lo]);
            const double *q0 = q_pad[lo], *q1 = q_pad[lo + 1];
            double sa = q0[0] * q1[0] + q0[1] * q1[1] + q0[2] * q1[2] + q0[3] * q1[3] < 0.0 ? -a : a;
            for (int j = 0; j < 3; ++j) p[j] = (1.0 - a) * pos[6 * lo + j] + a * pos[6 * (lo + 1) + j];
            for (int j = 0; j < 4; ++j) q[j] = (1.0 - a) * q0[j] + sa * q1[j];
        }
        GC_CHECK(gc_world_set_finger_pose(ref, 0, p, q) == GC_OK, "reference pose");
        gc_world_step(ref, DT);
    }
    gcWorld *w = pad_scene();
    GC_CHECK(gc_world_set_hip_track_orientations(w, quat) == GC_ERR_INVALID_ARGUMENT &&
                 strstr(gc_world_last_error(w), "set_hip_track first"),
             "orientations without a track: %s", gc_world_last_error(w));
    GC_CHECK(gc_world_set_hip_track(w, times, pos, N, 2, NULL) == GC_OK, "track");
    quat[8 * 1 + 4] = NAN;
    GC_CHECK(gc_world_set_hip_track_orientations(w, quat) == GC_ERR_INVALID_ARGUMENT &&
                 strstr(gc_world_last_error(w), "sample 1, finger 1"),
             "a NaN orientation: %s", gc_world_last_error(w));
    quat[8 * 1 + 4] = 0.0;
    GC_CHECK(gc_world_set_hip_track_orientations(w, quat) == GC_ERR_INVALID_ARGUMENT, "a zero orientation");
    quat[8 * 1 + 4] = 1.0;
    GC_CHECK(gc_world_set_hip_track_orientations(w, quat) == GC_OK, "orientations: %s", gc_world_last_error(w));
    gcRuntimeDef def = manual_def(1000.0, 3);
    GC_CHECK(gc_world_start(w, &def) == GC_OK, "start");
    GC_CHECK(gc_world_set_hip_track_orientations(w, NULL) == GC_ERR_BUSY, "refused while running");
    GC_CHECK(gc_world_advance(w, TICKS, 0.0) == GC_OK, "advance");
    gc_world_stop(w);
    GC_CHECK(gc_world_state_hash(w) == gc_world_state_hash(ref), "track orientations: hash differs from set_finger_pose");
    double p[3], q[4], pr[3], qr[4];
    gc_world_finger_pose(w, 0, p, q);
    gc_world_finger_pose(ref, 0, pr, qr);
    GC_CHECK(memcmp(q, qr, sizeof q) == 0 && fabs(q[1] - sin(0.2)) < 1e-15, "pad turned 0.4 rad: x %.17g", q[1]);
    gc_world_destroy(w);

    /* The same poses pushed every tick (a device): set_finger_pose + step again. */
    gcWorld *ref2 = pad_scene();
    w = pad_scene();
    GC_CHECK(gc_world_start(w, &def) == GC_OK, "start");
    double zero_q[8] = {0, 0, 0, 0, 1, 0, 0, 0};
    GC_CHECK(gc_world_push_finger_poses(w, pos, zero_q, 2, 0.0) == GC_WARN_REJECTED, "a zero quaternion is rejected");
    for (int i = 0; i < TICKS; ++i) {
        double pp[6], qq[8];
        const double a = (double)(i % 7) / 7.0, ang = 0.05 * i; /* wobbling in position and turn */
        pp[0] = 0.001 * a, pp[1] = 0.0, pp[2] = 0.0005 * i, pp[3] = 0.3, pp[4] = 0.0, pp[5] = 0.1;
        qq[0] = cos(ang), qq[1] = 0.0, qq[2] = sin(ang), qq[3] = 0.0;
        if (i % 2) qq[0] = -qq[0], qq[2] = -qq[2]; /* -q: the same rotation */
        qq[4] = 1.0, qq[5] = qq[6] = qq[7] = 0.0;
        gc_world_set_finger_pose(ref2, 0, pp, qq);
        gc_world_set_finger_pose(ref2, 1, &pp[3], &qq[4]);
        gc_world_step(ref2, DT);
        GC_CHECK(gc_world_push_finger_poses(w, pp, qq, 2, i * DT) == GC_OK, "push %d", i);
        gc_world_advance(w, 1, 0.0);
    }
    gc_world_stop(w);
    GC_CHECK(gc_world_state_hash(w) == gc_world_state_hash(ref2), "pushed orientations: hash differs from set_finger_pose");
    gc_world_destroy(w);
    gc_world_destroy(ref2);
    gc_world_destroy(ref);
}

/* A threaded session with its tick log, the haptic loop stalled now and then (object results
 * skipped, taken late): replayed on the manual clock from its records' HIPs and hand-over
 * schedule, every tick's state hash is the recorded one. The same replay with one result taken
 * a tick early diverges; a schedule that cannot have happened is refused. */
static void test_replay_schedule(void) {
    enum { TICKS = 900, CAP = 4096 };
    gcWorld *w = pinch_scene();
    double times[TICKS + 1], track[(TICKS + 1) * 6];
    for (int i = 0; i <= TICKS; ++i) times[i] = i * DT, pinch_hips(i, &track[6 * i]);
    GC_CHECK(gc_world_set_hip_track(w, times, track, TICKS + 1, 2, NULL) == GC_OK, "track: %s", gc_world_last_error(w));
    GC_CHECK(gc_world_set_tick_log(w, CAP) == GC_OK, "tick log");
    gcRuntimeDef def = realtime_def();
    GC_CHECK(gc_world_start(w, &def) == GC_OK, "start: %s", gc_world_last_error(w));
    for (int k = 0; k < 4; ++k) {
        sleep_s(0.12);
        gc_world_debug_stall(w, 0.009); /* ~4 object ticks while the haptic loop sleeps */
    }
    sleep_s(0.4);
    gcRuntimeStats ran; /* 400 ticks at least, however late a busy machine runs them (60 s: a hang) */
    for (double t0 = now_s(); gc_world_stats(w, &ran), ran.haptic_ticks < 400 && now_s() - t0 < 60.0;) sleep_s(0.01);
    GC_CHECK(gc_world_stop(w) == GC_OK, "stop");
    size_t size = gc_tick_record_size(4, 2);
    unsigned char *rec = malloc(size * CAP), *out = malloc(size * CAP);
    int n = gc_world_drain_ticks(w, rec, size * CAP, CAP);
    GC_CHECK(n > 300 && gc_world_tick_log_overflow(w) == 0, "%d ticks recorded, none dropped", n);
    double *hips = malloc(sizeof(double) * 6 * (size_t)n), *quats = malloc(sizeof(double) * 8 * (size_t)n);
    uint64_t *otick = malloc(sizeof(uint64_t) * (size_t)n), *reads = malloc(sizeof(uint64_t) * (size_t)n);
    int skipped = 0;
    for (int k = 0; k < n; ++k) {
        const unsigned char *r = rec + size * (size_t)k;
        memcpy(&hips[6 * k], r + 52, 48);
        memcpy(&quats[8 * k], r + size - 16 - 64, 64);
        memcpy(&otick[k], r + size - 16, 8);
        memcpy(&reads[k], r + size - 8, 8);
        if (k && otick[k] > otick[k - 1] + 1) skipped++;
    }
    GC_CHECK(skipped > 0, "stalls made the haptic loop skip object results (%d times)", skipped);
    gcWorld *r = pinch_scene();
    gcRuntimeDef manual = manual_def(def.object_rate, def.max_adopted_bodies);
    GC_CHECK(gc_world_start(r, &manual) == GC_OK, "start replay");
    int done = 0;
    GC_CHECK(gc_world_replay_ticks(r, hips, quats, 2, otick, reads, n, out, size * (size_t)n, &done) == GC_OK &&
                 done == n, "replay: %s", gc_world_last_error(r));
    gc_world_stop(r);
    int same = 0;
    for (int k = 0; k < n; ++k) same += memcmp(rec + size * (size_t)k + 24, out + size * (size_t)k + 24, 8) == 0;
    GC_CHECK(same == n, "replayed state hashes: %d of %d equal", same, n);
    /* One result taken a tick late (the falling box's state with it): the replay runs, and
     * parts from the recording at that tick. */
    int late = -1;
    for (int k = n / 2; k + 1 < n && late < 0; ++k)
        if (otick[k] > otick[k - 1] && otick[k + 1] == otick[k]) late = k;
    GC_CHECK(late > 0, "a result to take late");
    if (late > 0) {
        otick[late] = otick[late - 1];
        gcWorld *p = pinch_scene();
        GC_CHECK(gc_world_start(p, &manual) == GC_OK, "start perturbed");
        GC_CHECK(gc_world_replay_ticks(p, hips, quats, 2, otick, reads, n, out, size * (size_t)n, NULL) == GC_OK,
                 "perturbed replay: %s", gc_world_last_error(p));
        gc_world_stop(p);
        int first = -1;
        for (int k = 0; k < n && first < 0; ++k)
            if (memcmp(rec + size * (size_t)k + 24, out + size * (size_t)k + 24, 8) != 0) first = k;
        GC_CHECK(first == late, "a result taken a tick late parts there (tick index %d, expected %d)", first, late);
        gc_world_destroy(p);
    }
    /* A schedule going back is refused, naming the step; the ticks before it ran. */
    gcWorld *b = pinch_scene();
    GC_CHECK(gc_world_start(b, &manual) == GC_OK, "start refused");
    uint64_t back[3] = {1, 2, 1};
    uint64_t held[3] = {0, 0, 0};
    GC_CHECK(gc_world_replay_ticks(b, hips, NULL, 2, held, back, 3, NULL, 0, &done) == GC_ERR_INVALID_ARGUMENT &&
                 done == 2 && strstr(gc_world_last_error(b), "step 2") && strstr(gc_world_last_error(b), "goes back"),
             "refused: %s (done %d)", gc_world_last_error(b), done);
    gc_world_stop(b);
    gc_world_destroy(b);
    gc_world_destroy(r);
    gc_world_destroy(w);
    free(rec), free(out), free(hips), free(quats), free(otick), free(reads);
}

int main(void) {
    test_manual_clock_matches_step();
    test_track_orientations();
    test_refused_while_running();
    test_snapshot_normals_velocities();
    test_clamp_ramp_watchdog();
    test_start_stop_cycles();
    test_stop_while_busy();
    test_realtime();
    test_haptic_thread_setup();
    test_destroy_running();
    test_replay_schedule();
    return gc_test_summary("test_runtime");
}
