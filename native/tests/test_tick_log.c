/* The tick log (tick_log.c): record layout and contents, the state hash against its reference
 * definition, one record per haptic tick on the
 * manual clock, a full ring drops and counts (never waits), a consumer thread draining while
 * the real-time haptic loop fills it sees every tick once and in order, restart empties it,
 * calls refused while running. Built plain, with ASan/UBSan and with TSan. */
#define _POSIX_C_SOURCE 200809L
#include "graspcore.h"
#include "gc_test.h"
#include "world/world.h" /* the reference state hash reads the state it hashes */

#include <pthread.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

/* Offsets of the fixed fields and the arrays (graspcore.h). */
#define OFF_TICK 0
#define OFF_TIME 8
#define OFF_HASH 24
#define OFF_FLAGS 40

static uint64_t rec_u64(const unsigned char *r, size_t off) {
    uint64_t v;
    memcpy(&v, r + off, 8);
    return v;
}

static double rec_f64(const unsigned char *r, size_t off) {
    double v;
    memcpy(&v, r + off, 8);
    return v;
}

/* The 8 corners of a cube of half-size h. */
static void box_points(double pts[24], double h) {
    for (int i = 0; i < 8; ++i) {
        pts[3 * i] = (i & 1) ? h : -h;
        pts[3 * i + 1] = (i & 2) ? h : -h;
        pts[3 * i + 2] = (i & 4) ? h : -h;
    }
}

static gcWorld *pinch_world(void) {
    gcWorldDef wd = gc_default_world_def();
    gcWorld *w = NULL;
    GC_CHECK(gc_world_create(&wd, &w) == GC_OK, "create");
    double pts[24];
    box_points(pts, 0.03);
    gcPartDef part = {pts, 8, 0.0};
    gcBodyDef bd = gc_default_body_def();
    bd.mass = 0.1;
    bd.position[2] = 0.2;
    int32_t id;
    GC_CHECK(gc_world_add_body(w, &bd, &part, 1, &id) == GC_OK, "box");
    gcFingerDef fd = gc_default_finger_def();
    fd.position[0] = -0.035, fd.position[2] = 0.2;
    GC_CHECK(gc_world_add_finger(w, &fd, &id) == GC_OK, "finger 0");
    fd.position[0] = 0.035;
    GC_CHECK(gc_world_add_finger(w, &fd, &id) == GC_OK, "finger 1");
    return w;
}

static void test_layout_and_stopped_record(void) {
    GC_CHECK(gc_tick_record_size(2, 3) == 52 + 8 * (15 * 3 + 19 * 2) + 4 * 3 * 3 + 8 * 4 * 3 + 4 * 8 * 3 + 16, "size %zu",
             gc_tick_record_size(2, 3));
    GC_CHECK(gc_tick_record_size(0, 0) == 52 + 16, "empty world: the fixed fields and the schedule only");
    gcWorld *w = pinch_world();
    double hips[6] = {-0.025, 0, 0.2, 0.025, 0, 0.2};
    gc_world_set_hips(w, hips, 2);
    gc_world_step(w, 1e-3);
    size_t size = gc_tick_record_size(1, 2);
    unsigned char *r = calloc(1, size);
    GC_CHECK(gc_world_tick_record(w, 7, r, size - 1) == GC_ERR_INVALID_ARGUMENT, "short buffer refused");
    GC_CHECK(gc_world_tick_record(w, 7, r, size) == GC_OK, "record");
    GC_CHECK(rec_u64(r, OFF_TICK) == 7, "tick");
    GC_CHECK(rec_f64(r, OFF_TIME) == gc_world_time(w), "time");
    GC_CHECK(rec_u64(r, OFF_HASH) == gc_world_state_hash(w), "state hash");
    double pos[3], q[4], f[3], go[3];
    gc_world_body_pose(w, 0, pos, q);
    gc_world_finger_force(w, 1, f);
    gc_world_god_object(w, 1, go);
    const size_t arrays = 52, nf = 2;
    GC_CHECK(rec_f64(r, arrays + 8 * 3 * nf + 24 + 0) == go[0], "god-object of finger 1");       /* god_object[1].x */
    GC_CHECK(rec_f64(r, arrays + 8 * 6 * nf + 24 + 0) == f[0], "force of finger 1");            /* force[1].x */
    GC_CHECK(rec_f64(r, arrays + 8 * 9 * nf + 24 + 0) == f[0], "device force = force when stepped");
    GC_CHECK(rec_f64(r, arrays + 8 * 15 * nf + 16) == pos[2], "box z");                        /* pose[0].z */
    gcFingerState st;
    int32_t body;
    gc_world_finger_state(w, 1, &st, &body);
    int32_t rs, rb;
    const size_t patch = size - 16 - 4 * 2 * GC_FINGER_PATCH_CORNERS * nf; /* the fingers' patches, then the schedule */
    const size_t ints = patch - 8 * 4 * nf; /* state, contact and parts, then the fingers' orientations */
    uint32_t rp;
    memcpy(&rs, r + ints - 4 * 3 * nf + 4, 4);
    memcpy(&rb, r + ints - 4 * 2 * nf + 4, 4);
    memcpy(&rp, r + ints - 4 * nf + 4, 4);
    GC_CHECK(rs == (int32_t)st && rb == body && body == 0, "finger 1 touches the box: state %d body %d", rs, rb);
    GC_CHECK(rp == 1u, "finger 1 touches the box's part 0 only: parts %u", rp);
    GC_CHECK(rec_f64(r, ints + 32) == 1.0 && rec_f64(r, ints + 40) == 0.0, "finger 1's orientation: identity");
    GC_CHECK(rec_u64(r, size - 16) == 0 && rec_u64(r, size - 8) == 0, "no object manager: schedule 0, 0");
    double normal_x = rec_f64(r, arrays + 8 * 12 * nf + 24);                                    /* normal[1].x */
    GC_CHECK(normal_x > 0.99, "finger 1's contact normal is +x (%g)", normal_x);
    float corners[2 * GC_FINGER_PATCH_CORNERS];
    memcpy(corners, r + patch + sizeof corners, sizeof corners);
    for (int k = 0; k < 2 * GC_FINGER_PATCH_CORNERS; ++k)
        GC_CHECK(corners[k] == 0.0f, "a sphere finger's patch is zero (%g)", (double)corners[k]);
    free(r);
    gc_world_destroy(w);
}

/* The state hash as first defined (recordings carry it; re-simulation compares against it):
 * FNV-1a eight bytes a step, the tail byte by byte; time, bodies in four lanes, the lanes,
 * then each finger's HIP, force and contacts. tick_log.c computes it faster; never another value. */
static uint64_t ref_bytes(uint64_t h, const void *data, size_t n) {
    const unsigned char *p = data;
    for (; n >= 8; p += 8, n -= 8) {
        uint64_t v;
        memcpy(&v, p, 8);
        h = (h ^ v) * 1099511628211ull;
    }
    for (; n > 0; ++p, --n) h = (h ^ *p) * 1099511628211ull;
    return h;
}

static uint64_t ref_state_hash(const gcWorld *w) {
    uint64_t h = ref_bytes(14695981039346656037ull, &w->time, 8);
    uint64_t lane[4] = {h, h + 1, h + 2, h + 3};
    for (int i = 0; i < w->num_bodies; ++i) {
        const gcBodyState *s = &w->bodies[i].state;
        uint64_t l = lane[i & 3];
        l = ref_bytes(l, &s->com, sizeof s->com);
        l = ref_bytes(l, &s->q, sizeof s->q);
        l = ref_bytes(l, &s->v, sizeof s->v);
        lane[i & 3] = ref_bytes(l, &s->w, sizeof s->w);
    }
    h = ref_bytes(h, lane, sizeof lane);
    for (int i = 0; i < w->num_fingers; ++i) {
        const gcFinger *f = &w->fingers[i];
        h = ref_bytes(h, &f->hip, sizeof f->hip);
        h = ref_bytes(h, &f->force, sizeof f->force);
        for (int c = 0; c < f->num_contacts; ++c) {
            const gcFingerContact *k = &f->contacts[c];
            h = ref_bytes(h, &k->part, sizeof k->part);
            h = ref_bytes(h, &k->state, sizeof k->state);
            h = ref_bytes(h, &k->go_local, sizeof k->go_local);
            h = ref_bytes(h, &k->normal_local, sizeof k->normal_local);
        }
    }
    return h;
}

/* Bodies 0..6 (four at a time and a tail of three), fingers pinching the first box and
 * standing on another: the fast hash equals the reference, in the world and in its record,
 * also for a 4-byte field whose upper bytes are not zero (the byte-by-byte path). */
static void test_state_hash_reference(void) {
    gcWorld *w = pinch_world();
    double pts[24];
    box_points(pts, 0.02);
    gcPartDef part = {pts, 8, 0.0};
    int32_t id;
    for (int b = 0; b < 6; ++b) {
        gcBodyDef bd = gc_default_body_def();
        bd.mass = 0.05 + 0.01 * b;
        bd.position[0] = 0.2 + 0.1 * b, bd.position[2] = 0.1 + 0.01 * b;
        bd.angular_velocity[1] = 0.3 * b;
        GC_CHECK(gc_world_add_body(w, &bd, &part, 1, &id) == GC_OK, "box %d", b);
    }
    gcFingerDef fd = gc_default_finger_def();
    fd.position[0] = 0.2, fd.position[2] = 0.13;
    GC_CHECK(gc_world_add_finger(w, &fd, &id) == GC_OK, "finger on box 1");
    double hips[9] = {-0.025, 0, 0.2, 0.025, 0, 0.2, 0.2, 0, 0.115};
    int touching = 0;
    for (int s = 0; s < 50; ++s) {
        gc_world_set_hips(w, hips, 3);
        gc_world_step(w, 1e-3);
        GC_CHECK(gc_world_state_hash(w) == ref_state_hash(w), "step %d: hash as the reference", s);
        for (int i = 0; i < w->num_fingers; ++i) touching += w->fingers[i].num_contacts > 0;
    }
    GC_CHECK(touching > 0, "fingers in contact: their contacts hashed");
    size_t size = gc_tick_record_size(w->num_bodies, w->num_fingers);
    unsigned char *r = calloc(1, size);
    GC_CHECK(gc_world_tick_record(w, 3, r, size) == GC_OK, "record");
    GC_CHECK(rec_u64(r, OFF_HASH) == ref_state_hash(w), "record's hash as the reference");
    int f = 0;
    while (f < w->num_fingers && w->fingers[f].num_contacts == 0) ++f;
    if (f < w->num_fingers) { /* only hashed, never stepped: a value no step writes */
        w->fingers[f].contacts[0].state = (gcFingerState)0x10203;
        GC_CHECK(gc_world_state_hash(w) == ref_state_hash(w), "4-byte field of three non-zero bytes");
        w->fingers[f].contacts[0].part += 256;
        GC_CHECK(gc_world_state_hash(w) == ref_state_hash(w), "part id over 255");
    }
    free(r);
    gc_world_destroy(w);
}

static void test_manual_clock_and_overflow(void) {
    gcWorld *w = pinch_world();
    GC_CHECK(gc_world_set_tick_log(w, -1) == GC_ERR_INVALID_ARGUMENT, "negative capacity refused");
    GC_CHECK(gc_world_set_tick_log(w, 16) == GC_OK, "set_tick_log");
    gcRuntimeDef rd = gc_default_runtime_def();
    rd.realtime = 0;
    GC_CHECK(gc_world_start(w, &rd) == GC_OK, "start");
    size_t size = gc_tick_record_size(1, 2);
    unsigned char *buf = malloc(64 * size);
    GC_CHECK(gc_world_set_tick_log(w, 8) == GC_ERR_BUSY, "set_tick_log refused while running");
    GC_CHECK(gc_world_tick_record(w, 0, buf, size) == GC_ERR_BUSY, "tick_record refused while running");
    gc_world_advance(w, 5, 0.0);
    GC_CHECK(gc_world_drain_ticks(w, buf, 64 * size, 64) == 5, "five ticks, five records");
    for (int k = 0; k < 5; ++k) GC_CHECK(rec_u64(buf + k * size, OFF_TICK) == (uint64_t)(k + 1), "tick %d", k);
    GC_CHECK(gc_world_drain_ticks(w, buf, 64 * size, 64) == 0, "drained");
    gc_world_advance(w, 40, 0.0);       /* nobody drains: 16 kept, 24 dropped and counted */
    GC_CHECK(gc_world_tick_log_overflow(w) == 24, "overflow %llu", (unsigned long long)gc_world_tick_log_overflow(w));
    GC_CHECK(gc_world_drain_ticks(w, buf, 3 * size + 1, 64) == 3, "the buffer size bounds a drain");
    int n = gc_world_drain_ticks(w, buf, 64 * size, 64);
    GC_CHECK(n == 13, "the rest of the 16 kept (%d)", n);
    GC_CHECK(rec_u64(buf + 12 * size, OFF_TICK) == 21, "the oldest are kept, the newest dropped");
    GC_CHECK((rec_u64(buf, OFF_FLAGS) & 0xffffffffu) <= 1, "flags");
    gc_world_stop(w);
    GC_CHECK(gc_world_start(w, &rd) == GC_OK, "restart");
    GC_CHECK(gc_world_tick_log_overflow(w) == 0 && gc_world_drain_ticks(w, buf, 64 * size, 64) == 0,
             "a start empties the ring and its count");
    gc_world_stop(w);
    GC_CHECK(gc_world_set_tick_log(w, 0) == GC_OK && gc_world_drain_ticks(w, buf, 64 * size, 64) == 0, "off");
    free(buf);
    gc_world_destroy(w);
}

typedef struct {
    gcWorld *w;
    size_t size;
    _Atomic int stop;
    uint64_t seen, last_tick, out_of_order;
} Drainer;

static void *drain_main(void *arg) {
    Drainer *d = arg;
    unsigned char *buf = malloc(32 * d->size);
    for (;;) {
        int stopping = atomic_load(&d->stop);
        int n = gc_world_drain_ticks(d->w, buf, 32 * d->size, 32);
        for (int k = 0; k < n; ++k) {
            uint64_t t = rec_u64(buf + k * d->size, OFF_TICK);
            if (t != d->last_tick + 1) d->out_of_order++;
            d->last_tick = t;
            d->seen++;
        }
        if (stopping && n == 0) break;
        struct timespec ts = {0, 200000};
        nanosleep(&ts, NULL);
    }
    free(buf);
    return NULL;
}

static void test_threads(void) {
    gcWorld *w = pinch_world();
    GC_CHECK(gc_world_set_tick_log(w, 4096) == GC_OK, "set_tick_log");
    gcRuntimeDef rd = gc_default_runtime_def();
    rd.priority = 0;
    Drainer d = {w, gc_tick_record_size(1, 2), 0, 0, 0, 0};
    GC_CHECK(gc_world_start(w, &rd) == GC_OK, "start: %s", gc_world_last_error(w));
    pthread_t th;
    pthread_create(&th, NULL, drain_main, &d);
    double hips[6] = {-0.025, 0, 0.2, 0.025, 0, 0.2};
    for (int i = 0; i < 30; ++i) {
        gc_world_push_hips(w, hips, 2, 0.01 * i);
        struct timespec ts = {0, 10000000};
        nanosleep(&ts, NULL);
    }
    gc_world_stop(w);
    atomic_store(&d.stop, 1);
    pthread_join(th, NULL);
    gcRuntimeStats st;
    gc_world_stats(w, &st);
    GC_CHECK(d.seen > 100, "records drained while the loop ran: %llu", (unsigned long long)d.seen);
    GC_CHECK(d.seen + gc_world_tick_log_overflow(w) == st.haptic_ticks, "every tick recorded or counted: "
             "%llu + %llu vs %llu", (unsigned long long)d.seen, (unsigned long long)gc_world_tick_log_overflow(w),
             (unsigned long long)st.haptic_ticks);
    GC_CHECK(gc_world_tick_log_overflow(w) != 0 || d.out_of_order == 0, "in order, none twice");
    gc_world_destroy(w);
}

/* A HIP stream replayed by gc_world_step_hips gives the records of set_hips + step +
 * tick_record one by one, byte for byte (the fingers squeeze the box and lift it); bad
 * arguments are refused before any step. */
static void pinch_hips(double *hips, int steps) {
    for (int k = 0; k < steps; ++k) {
        double squeeze = 0.035 - 0.004 * (k < 100 ? k / 100.0 : 1.0), lift = k < 100 ? 0.0 : 0.0005 * (k - 100);
        double row[6] = {-squeeze, 0, 0.2 + lift, squeeze, 0, 0.2 + lift};
        memcpy(hips + 6 * k, row, sizeof row);
    }
}

static void test_step_hips(void) {
    enum { STEPS = 300 };
    size_t size = gc_tick_record_size(1, 2);
    double *hips = malloc(sizeof(double) * 6 * STEPS);
    unsigned char *one = calloc(STEPS, size), *all = calloc(STEPS, size);
    pinch_hips(hips, STEPS);
    gcWorld *a = pinch_world(), *b = pinch_world();
    for (int k = 0; k < STEPS; ++k) {
        gc_world_set_hips(a, hips + 6 * k, 2);
        gc_world_step(a, 0.001);
        gc_world_tick_record(a, 1 + (uint64_t)k, one + size * (size_t)k, size);
    }
    int done = -1;
    GC_CHECK(gc_world_step_hips(b, hips, 2, STEPS, 0.001, 1, all, size * STEPS, &done) == GC_OK, "step_hips: %s",
             gc_world_last_error(b));
    GC_CHECK(done == STEPS, "steps done: %d", done);
    GC_CHECK(memcmp(one, all, size * STEPS) == 0, "the same records byte for byte");
    GC_CHECK(gc_world_state_hash(a) == gc_world_state_hash(b), "the same state");
    GC_CHECK(rec_u64(all + size * (STEPS - 1), OFF_TICK) == STEPS, "records numbered from first_tick");
    gcWorld *c = pinch_world();
    GC_CHECK(gc_world_step_hips(c, hips, 2, STEPS, 0.001, 1, NULL, 0, &done) == GC_OK && done == STEPS, "no records");
    GC_CHECK(gc_world_state_hash(c) == gc_world_state_hash(a), "the steps alone: the same state");
    gc_world_destroy(c);
    GC_CHECK(rec_f64(all + size * (STEPS - 1), OFF_TIME) > 0.29, "time advanced");
    double t = gc_world_time(b);
    GC_CHECK(gc_world_step_hips(b, hips, 2, 2, 0.001, 1, all, size, &done) == GC_ERR_INVALID_ARGUMENT && done == 0,
             "a buffer for one record refused for two");
    GC_CHECK(strstr(gc_world_last_error(b), "records") != NULL, "names records: %s", gc_world_last_error(b));
    GC_CHECK(gc_world_step_hips(b, hips, 2, -1, 0.001, 1, all, size, &done) == GC_ERR_INVALID_ARGUMENT, "steps < 0");
    GC_CHECK(gc_world_step_hips(b, hips, 2, 1, -0.001, 1, all, size, &done) == GC_ERR_INVALID_ARGUMENT && done == 0,
             "a bad dt stops at the first step");
    hips[2] = NAN;
    GC_CHECK(gc_world_step_hips(b, hips, 2, 1, 0.001, 1, all, size, &done) == GC_ERR_INVALID_ARGUMENT && done == 0,
             "a NaN HIP refused");
    GC_CHECK(gc_world_time(b) == t, "nothing stepped by the refused calls");
    gc_world_destroy(a);
    gc_world_destroy(b);
    free(hips);
    free(one);
    free(all);
}

/* gc_world_step_hips_trace: each field's array holds, tick by tick, the bytes of the record's
 * field of that name from gc_world_step_hips on the same HIPs; bad ranges refused. */
static void test_step_hips_trace(void) {
    enum { N = 300 };
    gcWorld *a = pinch_world(), *b = pinch_world();
    double *hips = malloc(sizeof(double) * 6 * N);
    for (int k = 0; k < N; ++k) {
        double x = 0.032, z = 0.2 + 0.0002 * (k > 50 ? k - 50 : 0);
        double h[6] = {-x, 0, z, x, 0, z};
        memcpy(&hips[6 * k], h, sizeof h);
    }
    size_t rsize = gc_tick_record_size(1, 2), tsize = gc_tick_trace_size(1, 2);
    GC_CHECK(tsize == 8 + 56 * 2 + 56, "trace size %zu", tsize);
    unsigned char *rec = malloc(rsize * N), *tr = malloc(tsize * (N + 1));
    GC_CHECK(gc_world_step_hips(a, hips, 2, N, 1e-3, 1, rec, rsize * N, NULL) == GC_OK, "records");
    int done = 0;
    GC_CHECK(gc_world_step_hips_trace(b, hips, 2, 100, 1e-3, 1, N + 1, tr, tsize * (N + 1), &done) == GC_OK &&
                 done == 100, "trace, first part");
    GC_CHECK(gc_world_step_hips_trace(b, hips + 600, 2, N - 100, 1e-3, 101, N + 1, tr, tsize * (N + 1), &done) ==
                 GC_OK, "trace, the rest");
    const size_t T = N + 1, nf = 2;
    const unsigned char *time = tr, *contact = time + 8 * T, *state = contact + 4 * nf * T;
    const unsigned char *force = state + 4 * nf * T, *go = force + 24 * nf * T, *pose = go + 24 * nf * T;
    /* record offsets: god_object after hip, force after it; pose after the normals; state,
     * contact after the wrenches */
    const size_t R_GO = 52 + 48, R_FORCE = 52 + 96, R_POSE = 52 + 240, R_STATE = R_POSE + 56 + 48 + 48;
    int same = 0, touching = 0;
    for (size_t k = 0; k < N; ++k) {
        const unsigned char *r = rec + rsize * k;
        size_t t = k + 1;
        same += memcmp(time + 8 * t, r + 8, 8) == 0 && memcmp(go + 48 * t, r + R_GO, 48) == 0 &&
                memcmp(force + 48 * t, r + R_FORCE, 48) == 0 && memcmp(pose + 56 * t, r + R_POSE, 56) == 0 &&
                memcmp(state + 8 * t, r + R_STATE, 8) == 0 && memcmp(contact + 8 * t, r + R_STATE + 8, 8) == 0;
        int32_t c;
        memcpy(&c, contact + 8 * t, 4);
        touching += c == 0;
    }
    GC_CHECK(same == N && touching > N / 2, "trace = records' fields: %d of %d ticks (touching %d)", same, N, touching);
    GC_CHECK(gc_world_state_hash(a) == gc_world_state_hash(b), "the same final state");
    GC_CHECK(gc_world_step_hips_trace(b, hips, 2, 10, 1e-3, N - 5, N + 1, tr, tsize * (N + 1), NULL) ==
                 GC_ERR_INVALID_ARGUMENT && strstr(gc_world_last_error(b), "first"),
             "steps past the end refused: %s", gc_world_last_error(b));
    GC_CHECK(gc_world_step_hips_trace(b, hips, 2, 10, 1e-3, 0, N + 1, tr, tsize * N, NULL) == GC_ERR_INVALID_ARGUMENT,
             "a buffer too small refused");
    free(hips), free(rec), free(tr);
    gc_world_destroy(a);
    gc_world_destroy(b);
}

int main(void) {
    test_step_hips();
    test_step_hips_trace();
    test_layout_and_stopped_record();
    test_state_hash_reference();
    test_manual_clock_and_overflow();
    test_threads();
    return gc_test_summary("test_tick_log");
}
