/* Serial devices (serial_io.c): the codec against tests/devices/protocol_vectors.txt (the
 * same file the Python codec is checked against), a fuzzed stream decoder, and a device
 * thread on a socket pair with the runtime running: hello, poses in, forces out (zero until
 * enabled, ramped, clamped to the device's limit), malformed and NaN frames dropped and
 * counted, and a device that falls silent or hangs up letting go of the body. */
#define _GNU_SOURCE
#include "gc_test.h"
#include "graspcore.h"
#include "devices/device_codec.h"
#include "devices/force_gate.h"
#include "runtime/hip_input.h"
#include "devices/device_hub.h"

#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <pthread.h>
#include <signal.h>
#include <stdlib.h>
#include <string.h>
#include <arpa/inet.h>
#include <netinet/in.h>
#include <stdio.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#define VECTORS "tests/devices/protocol_vectors.txt"

static int unhex(const char *s, uint8_t *out, size_t cap) {
    if (!strcmp(s, "-")) return 0;
    size_t n = strlen(s);
    if (n % 2 || n / 2 > cap) return -1;
    for (size_t i = 0; i < n / 2; ++i) {
        unsigned v;
        if (sscanf(s + 2 * i, "%2x", &v) != 1) return -1;
        out[i] = (uint8_t)v;
    }
    return (int)(n / 2);
}

static const char *kind_names[] = {"cobs", "short", "crc", "version", "type", "length", "overflow", "range"};

static void test_crc_and_cobs(void) {
    GC_CHECK(gc_crc16((const uint8_t *)"123456789", 9) == 0x29B1, "CRC check value 0x%04X", gc_crc16((const uint8_t *)"123456789", 9));
    uint8_t in[300], enc[400], dec[400];
    for (int i = 0; i < 255; ++i) in[i] = (uint8_t)(i + 1);
    size_t n = gc_cobs_encode(in, 254, enc), m = 0;
    GC_CHECK(n == 255 && enc[0] == 0xFF, "254 non-zero bytes: %zu bytes, code 0x%02X", n, enc[0]);
    GC_CHECK(gc_cobs_decode(enc, n, dec, sizeof dec, &m) == 0 && m == 254 && !memcmp(dec, in, 254), "round trip");
    const uint8_t z[1] = {0};
    n = gc_cobs_encode(z, 1, enc);
    GC_CHECK(n == 2 && enc[0] == 1 && enc[1] == 1, "one zero -> 01 01");
    const uint8_t past[2] = {0x05, 0x11};
    GC_CHECK(gc_cobs_decode(past, 2, dec, sizeof dec, &m) == -1, "a block running past the end is refused");
}

/* What the device thread takes of a valid POSE frame's payload: finite positions and, when it
 * carries them, unit orientations (gc_device_quat_usable). */
static int pose_payload_usable(const gcFrame *fr) {
    int n = fr->payload[4], ok = 1;
    for (int i = 0; i < 3 * n; ++i) ok &= isfinite(gc_lef32(fr->payload + 6 + 4 * i)) != 0;
    for (int i = 0; gc_pose_has_orientations(fr) && i < n; ++i) {
        const uint8_t *o = fr->payload + 6 + 12 * n + 16 * i;
        const double q[4] = {gc_lef32(o), gc_lef32(o + 4), gc_lef32(o + 8), gc_lef32(o + 12)};
        ok &= gc_device_quat_usable(q);
    }
    return ok;
}

static void test_vectors(void) {
    FILE *f = fopen(VECTORS, "r");
    GC_CHECK(f != NULL, "cannot open %s (run from the repository root)", VECTORS);
    if (!f) return;
    char line[8192];
    int ok_count = 0, bad_count = 0;
    while (fgets(line, sizeof line, f)) {
        if (line[0] == '#' || line[0] == '\n') continue;
        char kind[8], name[64], a[32], b[32], payload_hex[4096], wire_hex[4096];
        uint8_t payload[2048], wire[2048], out[GC_PROTO_WIRE_MAX + 1];
        if (sscanf(line, "%7s", kind) != 1) continue;
        if (!strcmp(kind, "ok")) {
            GC_CHECK(sscanf(line, "%*s %63s %31s %31s %4095s %4095s", name, a, b, payload_hex, wire_hex) == 5, "line: %s", line);
            int np = unhex(payload_hex, payload, sizeof payload), nw = unhex(wire_hex, wire, sizeof wire);
            int type = atoi(a), seq = atoi(b);
            size_t len = gc_frame_encode((uint8_t)type, (uint16_t)seq, payload, (size_t)np, out);
            GC_CHECK(len == (size_t)nw && !memcmp(out, wire, len), "%s: encoding differs", name);
            gcFrame fr;
            gcFrameError e = gc_frame_decode(wire, (size_t)nw - 1, &fr);
            GC_CHECK(e == GC_FRAME_OK && fr.type == type && fr.seq == seq && fr.len == (size_t)np &&
                         !memcmp(fr.payload, payload, (size_t)np),
                     "%s: decode (error %d)", name, e);
            ++ok_count;
        } else {
            char want[16];
            GC_CHECK(sscanf(line, "%*s %63s %15s %4095s", name, want, wire_hex) == 3, "line: %s", line);
            int nw = unhex(wire_hex, wire, sizeof wire);
            gcFrame fr;
            gcFrameError e = gc_frame_decode(wire, (size_t)nw - 1, &fr);
            if (!strcmp(want, "range")) /* a valid frame whose payload the device thread refuses */
                GC_CHECK(e == GC_FRAME_OK && fr.type == GC_MSG_POSE && !pose_payload_usable(&fr),
                         "%s: a pose frame with a NaN or a non-unit orientation", name);
            else
                GC_CHECK(e >= 0 && !strcmp(kind_names[e], want), "%s: error %s, want %s", name, e >= 0 ? kind_names[e] : "ok", want);
            ++bad_count;
        }
    }
    fclose(f);
    GC_CHECK(ok_count >= 10 && bad_count >= 8, "vectors read: %d ok, %d bad", ok_count, bad_count);
}

static uint32_t rng_state = 12345;
static uint32_t rng(void) {
    rng_state ^= rng_state << 13;
    rng_state ^= rng_state >> 17;
    rng_state ^= rng_state << 5;
    return rng_state;
}

static void test_fuzzed_decoder(void) {
    uint8_t frame[GC_PROTO_WIRE_MAX + 1], payload[64];
    for (int i = 0; i < 64; ++i) payload[i] = (uint8_t)(i * 37);
    payload[4] = 1; /* a one-finger pose */
    size_t flen = gc_frame_encode(GC_MSG_POSE, 77, payload, 18, frame);
    gcFrameDecoder *d = malloc(sizeof *d);
    gcFrame fr;
    int resynced = 0, trials = 2000;
    for (int t = 0; t < trials; ++t) {
        gc_decoder_reset(d);
        int n = 1 + (int)(rng() % 1500);
        for (int i = 0; i < n; ++i) (void)gc_decoder_push(d, (uint8_t)(rng() & 0xFF), &fr);
        (void)gc_decoder_push(d, 0, &fr);
        int got = 0;
        for (size_t i = 0; i < flen; ++i) got += gc_decoder_push(d, frame[i], &fr);
        resynced += got == 1 && fr.type == GC_MSG_POSE && fr.seq == 77 && fr.len == 18;
    }
    GC_CHECK(resynced == trials, "resynchronised after noise in %d of %d trials", resynced, trials);
    free(d);
}

/* ---- a device on a socket pair ------------------------------------------------------- */

typedef struct Dev {
    int fd;
    uint16_t seq;
    gcFrameDecoder dec;
    gcFrame last_force;
    int forces, enables, hellos;
    int last_enable;
    uint8_t status; /* the status byte of its poses */
    float forces_seen[16384][3]; /* finger 0 of the force frames received (test_recorded_forces) */
    int ramp_frames; /* force frames with 0 < z < RAMP_TOP: a force ramping in, not jumping */
} Dev;

#define RAMP_TOP 2.999 /* N: just under the 3 N the device in test_device_thread asks for */

static void dev_send(Dev *d, uint8_t type, const uint8_t *p, size_t n) {
    uint8_t wire[GC_PROTO_WIRE_MAX + 1];
    size_t len = gc_frame_encode(type, d->seq++, p, n, wire);
    GC_CHECK(write(d->fd, wire, len) == (ssize_t)len, "device write");
}

static void dev_pose(Dev *d, double x, double y, double z) {
    uint8_t p[18];
    gc_put32(p, d->seq * 1000u);
    p[4] = 1;
    p[5] = d->status;
    gc_putf32(p + 6, (float)x), gc_putf32(p + 10, (float)y), gc_putf32(p + 14, (float)z);
    dev_send(d, GC_MSG_POSE, p, 18);
}

static void dev_read(Dev *d, int timeout_ms) {
    struct pollfd pfd = {.fd = d->fd, .events = POLLIN};
    uint8_t buf[4096];
    while (poll(&pfd, 1, timeout_ms) > 0) {
        ssize_t k = read(d->fd, buf, sizeof buf);
        if (k <= 0) return;
        gcFrame fr;
        for (ssize_t i = 0; i < k; ++i) {
            if (!gc_decoder_push(&d->dec, buf[i], &fr)) continue;
            if (fr.type == GC_MSG_FORCE) {
                if (d->forces < 16384)
                    for (int c = 0; c < 3; ++c) d->forces_seen[d->forces][c] = gc_lef32(fr.payload + 6 + 4 * c);
                d->last_force = fr, d->forces++;
                double z = gc_lef32(fr.payload + 6 + 8);
                d->ramp_frames += z > 0.0 && z < RAMP_TOP;
            }
            if (fr.type == GC_MSG_HELLO_HOST) d->hellos++;
            if (fr.type == GC_MSG_ENABLE) d->enables++, d->last_enable = fr.payload[0];
        }
        timeout_ms = 0;
    }
}

static double force_z(const Dev *d) { return d->forces ? gc_lef32(d->last_force.payload + 6 + 8) : NAN; }

static void sleep_ms(int ms) {
    struct timespec ts = {ms / 1000, (long)(ms % 1000) * 1000000L};
    nanosleep(&ts, NULL);
}

/* Seconds on the monotonic clock. */
static double now_s(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

/* How long a test waits for a state before it fails (docs/testing.md): only a bound on a hang;
 * a busy machine may take seconds where a quiet one takes milliseconds. */
#define STATE_DEADLINE_S 60.0

/* Waits (up to STATE_DEADLINE_S, a millisecond at a time) for `cond`, re-evaluated each time: what the
 * device and haptic threads do is checked, not how soon a loaded machine lets them do it
 * (how soon over a real pty, the let-go's 0.25 s included: bench/bench_unplug.py). */
#define WAIT_UNTIL(cond) \
    for (double wait_end_ = now_s() + STATE_DEADLINE_S; !(cond) && now_s() < wait_end_;) sleep_ms(1)

/* Poses for `ms` milliseconds, one a millisecond, reading what comes back in between. */
static void stream(Dev *d, int ms, double z) {
    struct timespec next;
    clock_gettime(CLOCK_MONOTONIC, &next);
    for (int i = 0; i < ms; ++i) {
        dev_pose(d, 0, 0, z);
        dev_read(d, 0);
        next.tv_nsec += 1000000;
        if (next.tv_nsec >= 1000000000L) next.tv_nsec -= 1000000000L, next.tv_sec++;
        clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &next, NULL);
        dev_read(d, 0);
    }
}

static void spring(gcWorld *w, double out[3]) {
    gcSnapshot s;
    memset(&s, 0, sizeof s);
    s.spring_forces = out;
    gc_world_snapshot(w, &s);
}

static void test_device_thread(void) {
    gcWorld *w = NULL;
    gcWorldDef wd = gc_default_world_def();
    GC_CHECK(gc_world_create(&wd, &w) == GC_OK, "create");
    double pts[24];
    for (int i = 0; i < 8; ++i) {
        pts[3 * i] = (i & 1) ? 0.1 : -0.1;
        pts[3 * i + 1] = (i & 2) ? 0.1 : -0.1;
        pts[3 * i + 2] = (i & 4) ? 0.0 : -0.2; /* top face at z = 0 */
    }
    gcPartDef part = {pts, 8, 0.0};
    gcBodyDef bd = gc_default_body_def();
    bd.is_static = 1;
    int32_t ground;
    GC_CHECK(gc_world_add_body(w, &bd, &part, 1, &ground) == GC_OK, "ground");
    gcFingerDef fd = gc_default_finger_def(); /* radius 8 mm, 1000 N/m */
    fd.position[2] = 0.05;
    int32_t finger;
    GC_CHECK(gc_world_add_finger(w, &fd, &finger) == GC_OK, "finger");
    gcRuntimeDef rd = gc_default_runtime_def();
    rd.priority = 0;
    rd.ramp_time = 0.0;
    GC_CHECK(gc_world_start(w, &rd) == GC_OK, "start: %s", gc_world_last_error(w));

    int sv[2];
    GC_CHECK(socketpair(AF_UNIX, SOCK_STREAM, 0, sv) == 0, "socketpair");
    fcntl(sv[0], F_SETFL, O_NONBLOCK);
    static Dev dev;
    memset(&dev, 0, sizeof dev);
    dev.fd = sv[1];
    gc_decoder_reset(&dev.dec);

    gcSerialDef sd = gc_default_serial_def();
    sd.num_fingers = 1;
    sd.transform[11] = -0.1; /* world z = device z - 0.1 */
    sd.ramp_time = 0.05;
    sd.max_force = 10.0;
    int32_t id = -1;
    sd.finger_offset = 1;
    GC_CHECK(gc_world_attach_serial(w, sv[0], &sd, &id) == GC_ERR_INVALID_ARGUMENT &&
                 strstr(gc_world_last_error(w), "finger_offset"),
             "a finger the world does not have is refused: %s", gc_world_last_error(w));
    sd.finger_offset = 0;
    GC_CHECK(gc_world_attach_serial(w, sv[0], &sd, &id) == GC_OK, "attach: %s", gc_world_last_error(w));

    dev_read(&dev, 200);
    GC_CHECK(dev.hellos >= 1, "the host says hello first");
    uint8_t hello[12 + 4];
    memset(hello, 0, sizeof hello);
    hello[0] = 1, hello[1] = GC_CAP_FORCES, hello[2] = 0;
    gc_put16(hello + 4, 1000);
    gc_putf32(hello + 6, 3.0f); /* the device's own limit: 3 N */
    gc_put16(hello + 10, 50);
    memcpy(hello + 12, "test", 4);
    dev_send(&dev, GC_MSG_HELLO_DEVICE, hello, sizeof hello);

    /* Pressing 2 mm into the ground (HIP z = -0.002, GO at the radius): 10 N of spring,
     * but nothing reaches the device before enable. */
    stream(&dev, 150, 0.098);
    double sp[3] = {0, 0, 0}; /* the soft start walks the 5 cm down at 0.2 m/s */
    WAIT_UNTIL((stream(&dev, 10, 0.098), spring(w, sp), fabs(sp[2] - 10.0) < 0.5));
    GC_CHECK(fabs(sp[2] - 10.0) < 0.5, "spring force %.3f N, expected k * 10 mm = 10 N", sp[2]);
    GC_CHECK(dev.forces > 100 && force_z(&dev) == 0.0, "%d force frames, z %.3f before enable", dev.forces, force_z(&dev));
    GC_CHECK(dev.enables >= 1 && dev.last_enable == 0, "the host tells the device forces are off");

    gc_world_serial_enable(w, id, 1);
    int before = dev.ramp_frames;
    stream(&dev, 150, 0.098);
    /* The 50 ms ramp is over by now; on a loaded machine the frames that say so can come late
     * (and the enable itself may be taken up late: the ramp is judged by the frames, not by
     * what one frame a fixed time after the enable says). */
    for (double end_ = now_s() + STATE_DEADLINE_S; now_s() < end_ && fabs(force_z(&dev) - 3.0) >= 1e-5;) stream(&dev, 50, 0.098);
    GC_CHECK(dev.ramp_frames - before >= 5, "ramping in: %d frames between 0 and 3 N", dev.ramp_frames - before);
    GC_CHECK(fabs(force_z(&dev) - 3.0) < 1e-5, "clamped to the device's 3 N: %.4f", force_z(&dev));
    GC_CHECK(dev.last_enable == 1, "ENABLE(1) sent");
    GC_CHECK(gc_le16(dev.last_force.payload + 2) == 20000, "TTL %u us", gc_le16(dev.last_force.payload + 2));

    /* Garbage, a NaN pose, a pose out of the workspace: dropped and counted; poses go on. */
    uint8_t junk[] = {0x33, 0x44, 0x00, 0x05, 0x01, 0x00};
    GC_CHECK(write(dev.fd, junk, sizeof junk) == sizeof junk, "junk");
    dev_pose(&dev, NAN, 0, 0.098);
    dev_pose(&dev, 0, 0, 50.0);
    stream(&dev, 50, 0.098);
    gcSerialStats st;
    WAIT_UNTIL((gc_world_serial_stats(w, id, &st), st.frame_errors[GC_FRAME_RANGE] >= 2 && st.dropped >= 4));
    /* Streaming on (a busy machine may pause this thread's stream past lost_timeout: then streaming again). */
    WAIT_UNTIL((stream(&dev, 5, 0.098), gc_world_serial_stats(w, id, &st), st.state == GC_SERIAL_STREAMING));
    GC_CHECK(st.state == GC_SERIAL_STREAMING && st.frame_errors[GC_FRAME_RANGE] == 2 && st.dropped >= 4,
             "state %d, range %llu, dropped %llu", st.state, (unsigned long long)st.frame_errors[GC_FRAME_RANGE],
             (unsigned long long)st.dropped);
    GC_CHECK(st.device_fingers == 1 && !strcmp(st.name, "test") && st.enabled == 1, "capabilities: %d '%s'",
             st.device_fingers, st.name);
    /* Measured (the rates and latencies are benchmarked: bench/bench_serial.py; a busy machine may
     * pause this thread's stream for longer than the rate's 0.25 s window). */
    GC_CHECK(st.poses > 100 && st.latency_p99_us > 0, "poses %llu, p99 %.0f us", (unsigned long long)st.poses,
             st.latency_p99_us);

    /* Random bytes between poses: never a crash (ASan), dropped and counted, poses go on. */
    uint64_t dropped_before = st.dropped, poses_before = st.poses;
    for (int burst = 0; burst < 40; ++burst) {
        uint8_t noise[512];
        for (size_t i = 0; i < sizeof noise; ++i) noise[i] = (uint8_t)rng();
        GC_CHECK(write(dev.fd, noise, sizeof noise) == sizeof noise, "noise");
        uint8_t zero = 0;
        GC_CHECK(write(dev.fd, &zero, 1) == 1, "delimiter");
        stream(&dev, 2, 0.098);
    }
    WAIT_UNTIL((gc_world_serial_stats(w, id, &st), st.dropped > dropped_before + 40 && st.poses >= poses_before + 75));
    WAIT_UNTIL((stream(&dev, 5, 0.098), gc_world_serial_stats(w, id, &st), st.state == GC_SERIAL_STREAMING));
    GC_CHECK(st.state == GC_SERIAL_STREAMING && st.dropped > dropped_before + 40 && st.poses >= poses_before + 75,
             "after noise: state %d, dropped %llu (was %llu), poses %llu (was %llu)", st.state,
             (unsigned long long)st.dropped, (unsigned long long)dropped_before, (unsigned long long)st.poses,
             (unsigned long long)poses_before);
    GC_CHECK(st.device_fingers == 1 && !strcmp(st.name, "test"), "the capabilities survive the noise");

    /* Silence: the finger lets go (no spring force), the device is lost. */
    WAIT_UNTIL((spring(w, sp), gc_world_serial_stats(w, id, &st), st.state == GC_SERIAL_LOST && fabs(sp[2]) < 1e-6));
    GC_CHECK(st.state == GC_SERIAL_LOST && fabs(sp[2]) < 1e-6, "silent: state %d, spring %.6f N", st.state, sp[2]);
    /* Poses again: it holds again. */
    stream(&dev, 100, 0.098);
    for (double end_ = now_s() + STATE_DEADLINE_S; now_s() < end_ && (spring(w, sp), fabs(sp[2] - 10.0) >= 0.5);) stream(&dev, 50, 0.098);
    GC_CHECK(fabs(sp[2] - 10.0) < 0.5, "recovered: spring %.3f N", sp[2]);
    /* Hang-up: let go again. */
    close(dev.fd);
    WAIT_UNTIL((spring(w, sp), gc_world_serial_stats(w, id, &st), st.state == GC_SERIAL_HANGUP && fabs(sp[2]) < 1e-6));
    /* (Two losses at least: the silence, the hang-up; a busy machine's pause of this thread's
     * stream may add one.) */
    GC_CHECK(st.state == GC_SERIAL_HANGUP && fabs(sp[2]) < 1e-6 && st.disconnects >= 2, "hang-up: state %d, spring %.6f, %llu",
             st.state, sp[2], (unsigned long long)st.disconnects);
    gcSerialEvent ev[64];
    int n = gc_world_serial_events(w, id, ev, 64), seen = 0;
    for (int i = 0; i < n; ++i) seen |= 1 << ev[i].code;
    int want = 1 << GC_SERIAL_EV_CONNECTED | 1 << GC_SERIAL_EV_ENABLED | 1 << GC_SERIAL_EV_LOST |
               1 << GC_SERIAL_EV_RECOVERED | 1 << GC_SERIAL_EV_DROPPED;
    GC_CHECK((seen & want) == want, "events 0x%x, want 0x%x", seen, want);
    GC_CHECK(gc_world_detach_serial(w, id) == GC_OK && gc_world_detach_serial(w, id) == GC_ERR_UNKNOWN_ID, "detach");
    /* A device read elsewhere pushes through the hub too. */
    double p[3] = {0, 0, 0.05}, bad[3] = {NAN, 0, 0};
    GC_CHECK(gc_world_push_device_hips(w, 1, 1, p) == GC_ERR_INVALID_ARGUMENT && strstr(gc_world_last_error(w), "1..1"),
             "a finger the world does not have: %s", gc_world_last_error(w));
    GC_CHECK(gc_world_push_device_hips(w, 0, 1, bad) == GC_WARN_REJECTED, "NaN refused");
    GC_CHECK(gc_world_push_device_hips(w, 0, 1, p) == GC_OK, "pushed");
    double hip[3];
    gcSnapshot hs;
    memset(&hs, 0, sizeof hs);
    hs.hips = hip;
    WAIT_UNTIL((gc_world_snapshot(w, &hs), fabs(hip[2] - 0.05) < 1e-12));
    GC_CHECK(fabs(hip[2] - 0.05) < 1e-12, "HIP from push_device_hips: %g", hip[2]);
    close(sv[0]);
    gc_world_stop(w);
    gc_world_destroy(w);
}

/* A device whose peer has already hung up: the thread's first write (its hello) fails with
 * EPIPE instead of SIGPIPE ending this process (SIGPIPE at its default action here, as in a
 * C host), and the device reports the hang-up. */
static void test_peer_gone_before_hello(void) {
    signal(SIGPIPE, SIG_DFL);
    gcWorld *w = NULL;
    gcWorldDef wd = gc_default_world_def();
    GC_CHECK(gc_world_create(&wd, &w) == GC_OK, "create");
    gcFingerDef fd = gc_default_finger_def();
    int32_t f;
    GC_CHECK(gc_world_add_finger(w, &fd, &f) == GC_OK, "finger");
    gcRuntimeDef rd = gc_default_runtime_def();
    rd.priority = 0;
    GC_CHECK(gc_world_start(w, &rd) == GC_OK, "start");
    int sv[2];
    GC_CHECK(socketpair(AF_UNIX, SOCK_STREAM, 0, sv) == 0, "socketpair");
    close(sv[1]);
    gcSerialDef sd = gc_default_serial_def();
    sd.priority = 0;
    int32_t id = -1;
    GC_CHECK(gc_world_attach_serial(w, sv[0], &sd, &id) == GC_OK, "attach: %s", gc_world_last_error(w));
    gcSerialStats st;
    memset(&st, 0, sizeof st);
    WAIT_UNTIL((gc_world_serial_stats(w, id, &st), st.state == GC_SERIAL_HANGUP));
    GC_CHECK(st.state == GC_SERIAL_HANGUP && st.write_errors >= 1, "state %d, write errors %llu", st.state,
             (unsigned long long)st.write_errors);
    GC_CHECK(gc_world_detach_serial(w, id) == GC_OK, "detach");
    close(sv[0]);
    gc_world_stop(w);
    gc_world_destroy(w);
}

/* Two devices on one world at once (two threads pushing into the hub; TSan): each drives
 * its own finger through its own frame, and each gets its own finger's force. */
static void test_two_devices(void) {
    gcWorld *w = NULL;
    gcWorldDef wd = gc_default_world_def();
    GC_CHECK(gc_world_create(&wd, &w) == GC_OK, "create");
    gcFingerDef fd = gc_default_finger_def();
    int32_t f;
    for (int i = 0; i < 2; ++i) {
        fd.position[0] = i ? 1.0 : -1.0;
        GC_CHECK(gc_world_add_finger(w, &fd, &f) == GC_OK, "finger");
    }
    gcRuntimeDef rd = gc_default_runtime_def();
    rd.priority = 0;
    GC_CHECK(gc_world_start(w, &rd) == GC_OK, "start");
    static Dev dev[2];
    int sv[2][2];
    int32_t id[2];
    for (int k = 0; k < 2; ++k) {
        GC_CHECK(socketpair(AF_UNIX, SOCK_STREAM, 0, sv[k]) == 0, "socketpair");
        fcntl(sv[k][0], F_SETFL, O_NONBLOCK);
        memset(&dev[k], 0, sizeof dev[k]);
        dev[k].fd = sv[k][1];
        gc_decoder_reset(&dev[k].dec);
        gcSerialDef sd = gc_default_serial_def();
        sd.priority = 0;
        sd.finger_offset = k;
        sd.transform[3] = k ? 1.0 : -1.0; /* x offset of each device's frame */
        GC_CHECK(gc_world_attach_serial(w, sv[k][0], &sd, &id[k]) == GC_OK, "attach %d: %s", k, gc_world_last_error(w));
        uint8_t hello[12] = {1, GC_CAP_FORCES, 0, 0};
        gc_put16(hello + 4, 1000);
        gc_putf32(hello + 6, 5.0f);
        gc_put16(hello + 10, 50);
        dev_read(&dev[k], 200);
        dev_send(&dev[k], GC_MSG_HELLO_DEVICE, hello, 12);
    }
    int32_t third;
    gcSerialDef sd = gc_default_serial_def();
    sd.finger_offset = 1;
    GC_CHECK(gc_world_attach_serial(w, sv[0][0], &sd, &third) == GC_ERR_INVALID_ARGUMENT &&
                 strstr(gc_world_last_error(w), "already driven by device 1"),
             "overlapping fingers refused: %s", gc_world_last_error(w));
    for (int i = 0; i < 300; ++i) { /* interleaved poses: device k at (0, 0.01 k, 0) in its frame */
        for (int k = 0; k < 2; ++k) dev_pose(&dev[k], 0, 0.01 * k, 0);
        for (int k = 0; k < 2; ++k) dev_read(&dev[k], 0);
        sleep_ms(1);
    }
    double hips[6];
    gcSnapshot s;
    memset(&s, 0, sizeof s);
    s.hips = hips;
    WAIT_UNTIL((gc_world_snapshot(w, &s), hips[0] == -1.0 && hips[1] == 0.0 && hips[3] == 1.0 &&
                fabs(hips[4] - 0.01) < 1e-7));
    GC_CHECK(hips[0] == -1.0 && hips[1] == 0.0 && hips[3] == 1.0 && fabs(hips[4] - 0.01) < 1e-7,
             "each device its finger: (%g %g) (%g %g)", hips[0], hips[1], hips[3], hips[4]);
    for (int k = 0; k < 2; ++k) {
        gcSerialStats st;
        /* Every pose taken and answered (a loaded machine may still be working through them). */
        WAIT_UNTIL((gc_world_serial_stats(w, id[k], &st), dev_read(&dev[k], 0),
                    st.poses >= 300 && st.forces_sent == st.poses && dev[k].forces >= 300));
        GC_CHECK(st.poses == 300 && st.forces_sent == st.poses && st.dropped == 0 && dev[k].forces >= 300,
                 "device %d: %llu poses, %llu forces, %d received", k, (unsigned long long)st.poses,
                 (unsigned long long)st.forces_sent, dev[k].forces);
    }
    gc_world_stop(w);
    gc_world_destroy(w); /* detaches both (their threads joined first) */
    for (int k = 0; k < 2; ++k) close(sv[k][0]), close(sv[k][1]);
}

/* ---- what the recording says the device got ------------------------------------------- */

/* The device force the newest drained tick record holds for finger 0 (a world of one finger
 * and one body), and how many records were drained; each record's checked by `check`. */
typedef struct Drained {
    int records, nonzero, unmatched;
    double last[3];
    double last_nonzero[3]; /* the last record with a force: a busy machine may pause this thread
                             * past the frame's TTL before it drains, and the last is zero then */
} Drained;

/* A record's device force (scene axes) is what some force frame carried (device axes), mapped
 * back by A^-T: for the frame below, A = 2 Rz(90 deg), so f = (-fy, fx, fz) / 2, exactly. */
static int sent_in_some_frame(const Dev *d, const double f[3]) {
    for (int k = 0; k < d->forces && k < 16384; ++k) {
        const float *g = d->forces_seen[k];
        if (f[0] == -0.5 * g[1] && f[1] == 0.5 * g[0] && f[2] == 0.5 * g[2]) return 1;
    }
    return 0;
}

static Drained drain(gcWorld *w, const Dev *d) {
    Drained out = {0, 0, 0, {0, 0, 0}, {0, 0, 0}};
    size_t size = gc_tick_record_size(1, 1);
    static unsigned char buf[4096 * 1024];
    int n;
    while ((n = gc_world_drain_ticks(w, buf, sizeof buf, (int)(sizeof buf / size))) > 0) {
        for (int k = 0; k < n; ++k) {
            double f[3];
            memcpy(f, buf + (size_t)k * size + 52 + 3 * 24, sizeof f); /* after hip, god_object, force */
            if (f[0] != 0 || f[1] != 0 || f[2] != 0) {
                out.nonzero++;
                out.unmatched += !sent_in_some_frame(d, f);
                memcpy(out.last_nonzero, f, sizeof f);
            }
            memcpy(out.last, f, sizeof f);
        }
        out.records += n;
    }
    return out;
}

static double world_time(gcWorld *w) {
    gcSnapshot s;
    memset(&s, 0, sizeof s);
    gc_world_snapshot(w, &s);
    return s.time;
}

/* The last event of `code` among those popped (-1 when none); its value in *value. */
static double event_time(gcWorld *w, int32_t id, int code, int *value) {
    gcSerialEvent ev[64];
    double t = -1;
    int n = gc_world_serial_events(w, id, ev, 64);
    for (int i = 0; i < n; ++i)
        if (ev[i].code == code) t = ev[i].session_time, *value = ev[i].value;
    return t;
}

/* The tick log records, for a finger a device drives, what the device was sent (in scene axes,
 * through a scaled, rotated workspace), not what the haptic loop computed: zero before enable,
 * zero from the device's ESTOP on (and from an e-stop only its poses' status reported), zero
 * once the last frame's TTL is over. Device events carry the session time they happened at. */
static void test_recorded_forces(void) {
    gcWorld *w = NULL;
    gcWorldDef wd = gc_default_world_def();
    GC_CHECK(gc_world_create(&wd, &w) == GC_OK, "create");
    double pts[24];
    for (int i = 0; i < 8; ++i) {
        pts[3 * i] = (i & 1) ? 0.1 : -0.1;
        pts[3 * i + 1] = (i & 2) ? 0.1 : -0.1;
        pts[3 * i + 2] = (i & 4) ? 0.0 : -0.2; /* top face at z = 0 */
    }
    gcPartDef part = {pts, 8, 0.0};
    gcBodyDef bd = gc_default_body_def();
    bd.is_static = 1;
    int32_t ground, finger;
    GC_CHECK(gc_world_add_body(w, &bd, &part, 1, &ground) == GC_OK, "ground");
    gcFingerDef fd = gc_default_finger_def();
    fd.position[2] = 0.05;
    GC_CHECK(gc_world_add_finger(w, &fd, &finger) == GC_OK, "finger");
    GC_CHECK(gc_world_set_tick_log(w, 1 << 15) == GC_OK, "tick log");
    gcRuntimeDef rd = gc_default_runtime_def();
    rd.priority = 0;
    rd.ramp_time = 0.0;
    rd.watchdog_timeout = 0.05; /* a loaded machine: this test is about the device path */
    GC_CHECK(gc_world_start(w, &rd) == GC_OK, "start: %s", gc_world_last_error(w));

    int sv[2];
    GC_CHECK(socketpair(AF_UNIX, SOCK_STREAM, 0, sv) == 0, "socketpair");
    fcntl(sv[0], F_SETFL, O_NONBLOCK);
    static Dev dev;
    memset(&dev, 0, sizeof dev);
    dev.fd = sv[1];
    gc_decoder_reset(&dev.dec);
    gcSerialDef sd = gc_default_serial_def();
    sd.priority = 0;
    sd.ramp_time = 0.0;
    sd.stall_timeout = 0.05;
    double A[16] = {0, -2, 0, 0, 2, 0, 0, 0, 0, 0, 2, -0.1, 0, 0, 0, 1}; /* 2 Rz(90), z - 0.1 */
    memcpy(sd.transform, A, sizeof A);
    int32_t id = -1;
    double singular[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1};
    memcpy(sd.transform, singular, sizeof singular);
    GC_CHECK(gc_world_attach_serial(w, sv[0], &sd, &id) == GC_ERR_INVALID_ARGUMENT &&
                 strstr(gc_world_last_error(w), "singular"),
             "a singular workspace frame is refused: %s", gc_world_last_error(w));
    memcpy(sd.transform, A, sizeof A);
    GC_CHECK(gc_world_attach_serial(w, sv[0], &sd, &id) == GC_OK, "attach: %s", gc_world_last_error(w));
    dev_read(&dev, 200);
    uint8_t hello[12] = {1, GC_CAP_FORCES, 0, 0};
    gc_put16(hello + 4, 1000);
    gc_putf32(hello + 6, 3.0f); /* device limit 3 N: the spring's 10 N is 20 N in device axes */
    gc_put16(hello + 10, 50);
    dev_send(&dev, GC_MSG_HELLO_DEVICE, hello, 12);

    /* HIP 2 mm into the ground (device z 0.049 -> world -0.002): 10 N up, none of it sent. */
    stream(&dev, 200, 0.049);
    Drained dr = drain(w, &dev);
    GC_CHECK(dr.records > 100 && dr.nonzero == 0, "before enable: %d records, %d with a device force", dr.records,
             dr.nonzero);

    gc_world_serial_enable(w, id, 1);
    for (double end_ = now_s() + STATE_DEADLINE_S; now_s() < end_ && fabs(force_z(&dev) - 3.0) >= 1e-6;) stream(&dev, 50, 0.049);
    GC_CHECK(fabs(force_z(&dev) - 3.0) < 1e-6, "3 N sent (clamped in device axes): %.4f", force_z(&dev));
    stream(&dev, 100, 0.049);
    dr = drain(w, &dev);
    /* (How many records carry it depends on how late a busy machine runs this thread and the
     * frames' 20 ms TTL: some, every one of them sent.) */
    GC_CHECK(dr.nonzero > 0 && dr.unmatched == 0, "enabled: %d records with a device force, %d not sent in any frame",
             dr.nonzero, dr.unmatched);
    GC_CHECK(dr.last_nonzero[0] == 0 && dr.last_nonzero[1] == 0 && dr.last_nonzero[2] == 1.5,
             "recorded (%g %g %g): the 3 N sent, in scene axes 1.5 N (the spring is 10 N)", dr.last_nonzero[0],
             dr.last_nonzero[1], dr.last_nonzero[2]);

    /* The device's stop button: ESTOP(1). Forces zero from then on, on both sides. */
    double before = world_time(w);
    uint8_t reason = 1;
    dev_send(&dev, GC_MSG_ESTOP, &reason, 1);
    stream(&dev, 100, 0.049);
    double after = world_time(w);
    dr = drain(w, &dev);
    GC_CHECK(dr.last[2] == 0.0 && force_z(&dev) == 0.0, "after the device's e-stop: recorded %g, sent %g", dr.last[2],
             force_z(&dev));
    int value = -1;
    double t_estop = event_time(w, id, GC_SERIAL_EV_ESTOP, &value);
    GC_CHECK(value == 1 && t_estop >= before - 0.002 && t_estop <= after,
             "estop event: value %d at session time %.4f, sent between %.4f and %.4f", value, t_estop, before, after);
    dev_send(&dev, GC_MSG_ESTOP, &reason, 1); /* repeated while latched: no second event */
    stream(&dev, 20, 0.049);
    gcSerialStats st;
    gc_world_serial_stats(w, id, &st);
    GC_CHECK(event_time(w, id, GC_SERIAL_EV_ESTOP, &value) < 0 && st.enabled == 0, "a repeated ESTOP is one e-stop");

    /* Forces on again; then an e-stop whose ESTOP frame was lost: only the poses' status says so. */
    gc_world_serial_enable(w, id, 1);
    for (double end_ = now_s() + STATE_DEADLINE_S; now_s() < end_ && fabs(force_z(&dev) - 3.0) >= 1e-6;) stream(&dev, 50, 0.049);
    GC_CHECK(fabs(force_z(&dev) - 3.0) < 1e-6, "re-enabled: %.4f", force_z(&dev));
    stream(&dev, 60, 0.049); /* past the grace after ENABLE(1) */
    dev.status = GC_STATUS_ESTOPPED;
    stream(&dev, 50, 0.049);
    dr = drain(w, &dev);
    value = -1;
    GC_CHECK(event_time(w, id, GC_SERIAL_EV_ESTOP, &value) > 0 && value == GC_ESTOP_REASON_STATUS,
             "an e-stop seen in the status: value %d", value);
    GC_CHECK(dr.last[2] == 0.0 && force_z(&dev) == 0.0, "and forces zero: recorded %g, sent %g", dr.last[2],
             force_z(&dev));

    /* Forces on, then silence: the record goes to zero when the last frame's TTL (20 ms) is over. */
    dev.status = 0;
    gc_world_serial_enable(w, id, 1);
    for (double end_ = now_s() + STATE_DEADLINE_S; now_s() < end_ && fabs(force_z(&dev) - 3.0) >= 1e-6;) stream(&dev, 50, 0.049);
    dr = drain(w, &dev);
    GC_CHECK(dr.last_nonzero[2] == 1.5 && dr.unmatched == 0, "forces again: %g", dr.last_nonzero[2]);
    sleep_ms(60);
    dr = drain(w, &dev);
    GC_CHECK(dr.records > 5 && dr.last[2] == 0.0, "silent past the TTL: %d records, last %g", dr.records, dr.last[2]);
    gc_world_stop(w);
    gc_world_destroy(w);
    close(sv[0]), close(sv[1]);
}

/* A record's device force is A^-T of some force frame's float32 values, all three of them: a
 * workspace rotated about no axis makes the spring's force (up) a frame of three non-zero
 * values, none of them a float32 before it is sent. GCC 12's SLP vectorizer dropped the float32
 * rounding of one of them in what the host recorded as sent (the frame itself was right): the
 * record was off the frame by float32 rounding, ~1e-7 N. */
static void test_recorded_forces_are_the_frames(void) {
    gcWorld *w = NULL;
    gcWorldDef wd = gc_default_world_def();
    GC_CHECK(gc_world_create(&wd, &w) == GC_OK, "create");
    double pts[24];
    for (int i = 0; i < 8; ++i) {
        pts[3 * i] = (i & 1) ? 0.1 : -0.1;
        pts[3 * i + 1] = (i & 2) ? 0.1 : -0.1;
        pts[3 * i + 2] = (i & 4) ? 0.0 : -0.2; /* top face at z = 0 */
    }
    gcPartDef part = {pts, 8, 0.0};
    gcBodyDef bd = gc_default_body_def();
    bd.is_static = 1;
    int32_t ground, finger;
    GC_CHECK(gc_world_add_body(w, &bd, &part, 1, &ground) == GC_OK, "ground");
    gcFingerDef fd = gc_default_finger_def();
    fd.position[2] = 0.05;
    GC_CHECK(gc_world_add_finger(w, &fd, &finger) == GC_OK, "finger");
    GC_CHECK(gc_world_set_tick_log(w, 1 << 15) == GC_OK, "tick log");
    gcRuntimeDef rd = gc_default_runtime_def();
    rd.priority = 0;
    rd.ramp_time = 0.0;
    rd.watchdog_timeout = 0.05;
    GC_CHECK(gc_world_start(w, &rd) == GC_OK, "start: %s", gc_world_last_error(w));

    int sv[2];
    GC_CHECK(socketpair(AF_UNIX, SOCK_STREAM, 0, sv) == 0, "socketpair");
    fcntl(sv[0], F_SETFL, O_NONBLOCK);
    static Dev dev;
    memset(&dev, 0, sizeof dev);
    dev.fd = sv[1];
    gc_decoder_reset(&dev.dec);
    gcSerialDef sd = gc_default_serial_def();
    sd.priority = 0;
    sd.ramp_time = 0.0;
    sd.stall_timeout = 0.05;
    /* A rotation (A^-T = A) with entries k/3; the device's origin 1.3 mm under the ground's top:
     * a spring force under both limits (not clamped), (-1, 2, 2) / 3 of it in device axes. */
    const double R[9] = {2.0 / 3, -1.0 / 3, 2.0 / 3, 2.0 / 3, 2.0 / 3, -1.0 / 3, -1.0 / 3, 2.0 / 3, 2.0 / 3};
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) sd.transform[4 * i + j] = R[3 * i + j];
    sd.transform[11] = -0.0013;
    int32_t id = -1;
    GC_CHECK(gc_world_attach_serial(w, sv[0], &sd, &id) == GC_OK, "attach: %s", gc_world_last_error(w));
    dev_read(&dev, 200);
    uint8_t hello[12] = {1, GC_CAP_FORCES, 0, 0};
    gc_put16(hello + 4, 1000);
    gc_putf32(hello + 6, 20.0f);
    gc_put16(hello + 10, 50);
    dev_send(&dev, GC_MSG_HELLO_DEVICE, hello, 12);
    stream(&dev, 400, 0.0); /* the soft start walks the HIP there (5 cm at 0.2 m/s) */
    gc_world_serial_enable(w, id, 1);
    for (double end_ = now_s() + STATE_DEADLINE_S; now_s() < end_ && !(force_z(&dev) > 1.0);) stream(&dev, 50, 0.0);
    stream(&dev, 100, 0.0);
    double sp[3];
    spring(w, sp);
    GC_CHECK(sp[2] > 1.0 && sp[2] < sd.max_force && fabs(force_z(&dev) - sp[2] * 2 / 3) < 1e-3,
             "sent (device z) %.6f N: 2/3 of the spring's %.6f N (under the 10 N limit)", force_z(&dev), sp[2]);

    /* Every record with a device force is R g for a frame g, to the rounding of that product
     * (1e-15 N), far below float32's (1e-7 N at 5 N); g of three non-zero values. */
    size_t size = gc_tick_record_size(1, 1);
    static unsigned char buf[4096 * 1024];
    int n, nonzero = 0, unmatched = 0, full = 0;
    double worst = 0, example[3] = {0, 0, 0};
    while ((n = gc_world_drain_ticks(w, buf, sizeof buf, (int)(sizeof buf / size))) > 0) {
        for (int k = 0; k < n; ++k) {
            double f[3];
            memcpy(f, buf + (size_t)k * size + 52 + 3 * 24, sizeof f); /* after hip, god_object, force */
            if (f[0] == 0 && f[1] == 0 && f[2] == 0) continue;
            nonzero++;
            double best = INFINITY;
            const float *match = NULL;
            for (int m = 0; m < dev.forces && m < 16384; ++m) {
                const float *g = dev.forces_seen[m];
                double err = 0;
                for (int c = 0; c < 3; ++c)
                    err = fmax(err, fabs(f[c] - (R[3 * c] * g[0] + R[3 * c + 1] * g[1] + R[3 * c + 2] * g[2])));
                if (err < best) best = err, match = g;
            }
            full += match && match[0] != 0 && match[1] != 0 && match[2] != 0;
            if (best > 1e-12) unmatched++, memcpy(example, f, sizeof f);
            worst = fmax(worst, best);
        }
    }
    GC_CHECK(nonzero > 50 && full == nonzero, "%d records with a device force, %d of a frame of three non-zero values",
             nonzero, full);
    GC_CHECK(unmatched == 0, "%d of %d recorded device forces are not R g of any frame g (off by up to %.3g N), e.g. "
             "(%.17g %.17g %.17g)", unmatched, nonzero, worst, example[0], example[1], example[2]);
    gc_world_stop(w);
    gc_world_destroy(w);
    close(sv[0]), close(sv[1]);
}

/* A device whose poses say "e-stop latched" before forces are on (its ESTOP frame lost, or sent
 * before this connection): one e-stop, counted and recorded as seen in the status, not cleared
 * unseen by the ENABLE(1) that turns forces on; forces flow once the device has taken that up. */
static void test_estop_in_status_before_enable(void) {
    gcWorld *w = NULL;
    gcWorldDef wd = gc_default_world_def();
    GC_CHECK(gc_world_create(&wd, &w) == GC_OK, "create");
    double pts[24];
    for (int i = 0; i < 8; ++i) {
        pts[3 * i] = (i & 1) ? 0.1 : -0.1;
        pts[3 * i + 1] = (i & 2) ? 0.1 : -0.1;
        pts[3 * i + 2] = (i & 4) ? 0.0 : -0.2; /* top face at z = 0 */
    }
    gcPartDef part = {pts, 8, 0.0};
    gcBodyDef bd = gc_default_body_def();
    bd.is_static = 1;
    int32_t ground, finger;
    GC_CHECK(gc_world_add_body(w, &bd, &part, 1, &ground) == GC_OK, "ground");
    gcFingerDef fd = gc_default_finger_def();
    fd.position[2] = 0.05;
    GC_CHECK(gc_world_add_finger(w, &fd, &finger) == GC_OK, "finger");
    gcRuntimeDef rd = gc_default_runtime_def();
    rd.priority = 0;
    rd.ramp_time = 0.0;
    rd.watchdog_timeout = 0.05;
    GC_CHECK(gc_world_start(w, &rd) == GC_OK, "start: %s", gc_world_last_error(w));
    int sv[2];
    GC_CHECK(socketpair(AF_UNIX, SOCK_STREAM, 0, sv) == 0, "socketpair");
    fcntl(sv[0], F_SETFL, O_NONBLOCK);
    static Dev dev;
    memset(&dev, 0, sizeof dev);
    dev.fd = sv[1];
    gc_decoder_reset(&dev.dec);
    gcSerialDef sd = gc_default_serial_def();
    sd.priority = 0;
    sd.ramp_time = 0.0;
    sd.stall_timeout = 0.05;
    int32_t id = -1;
    GC_CHECK(gc_world_attach_serial(w, sv[0], &sd, &id) == GC_OK, "attach: %s", gc_world_last_error(w));
    dev_read(&dev, 200);
    uint8_t hello[12] = {1, GC_CAP_FORCES, 0, 0};
    gc_put16(hello + 4, 1000);
    gc_putf32(hello + 6, 3.0f);
    gc_put16(hello + 10, 50);
    dev_send(&dev, GC_MSG_HELLO_DEVICE, hello, 12);
    dev.status = GC_STATUS_ESTOPPED; /* latched, no ESTOP frame */
    stream(&dev, 400, -0.002); /* the soft start walks the HIP 2 mm into the ground */
    gcSerialStats st;
    WAIT_UNTIL((gc_world_serial_stats(w, id, &st), st.estops > 0));
    int value = -1;
    double t_estop = event_time(w, id, GC_SERIAL_EV_ESTOP, &value);
    GC_CHECK(st.estops == 1 && value == GC_ESTOP_REASON_STATUS && t_estop < world_time(w),
             "forces off, the status says e-stop: %d e-stops, event value %d at %.4f s", (int)st.estops, value,
             t_estop);
    stream(&dev, 100, -0.002);
    gc_world_serial_stats(w, id, &st);
    GC_CHECK(st.estops == 1, "said again in every pose: still one e-stop (%d)", (int)st.estops);
    /* Forces on: ENABLE(1) clears it on both sides (the device drops its status bit). */
    gc_world_serial_enable(w, id, 1);
    WAIT_UNTIL((dev_read(&dev, 1), dev.last_enable == 1));
    dev.status = 0;
    for (double end_ = now_s() + STATE_DEADLINE_S; now_s() < end_ && fabs(force_z(&dev) - 3.0) >= 1e-6;) stream(&dev, 50, -0.002);
    gc_world_serial_stats(w, id, &st);
    GC_CHECK(fabs(force_z(&dev) - 3.0) < 1e-6 && st.estops == 1 && st.enabled,
             "enabled: %.4f N sent, %d e-stops", force_z(&dev), (int)st.estops);
    gc_world_stop(w);
    gc_world_destroy(w);
    close(sv[0]), close(sv[1]);
}

/* Host-side rules of docs/protocol.md: the device's sequence counts frames of every type (a
 * HEARTBEAT between poses is no gap, a frame that never came is); a silent device gets a
 * HELLO_HOST every 100 ms (so that one that restarted answers); the host's ESTOP is said
 * again while the device's poses do not show it latched. */
static void test_protocol_rules(void) {
    gcWorld *w = NULL;
    gcWorldDef wd = gc_default_world_def();
    GC_CHECK(gc_world_create(&wd, &w) == GC_OK, "create");
    gcFingerDef fd = gc_default_finger_def();
    int32_t f;
    GC_CHECK(gc_world_add_finger(w, &fd, &f) == GC_OK, "finger");
    gcRuntimeDef rd = gc_default_runtime_def();
    rd.priority = 0;
    GC_CHECK(gc_world_start(w, &rd) == GC_OK, "start");
    int sv[2];
    GC_CHECK(socketpair(AF_UNIX, SOCK_STREAM, 0, sv) == 0, "socketpair");
    fcntl(sv[0], F_SETFL, O_NONBLOCK);
    static Dev dev;
    memset(&dev, 0, sizeof dev);
    dev.fd = sv[1];
    gc_decoder_reset(&dev.dec);
    gcSerialDef sd = gc_default_serial_def();
    sd.priority = 0;
    int32_t id;
    GC_CHECK(gc_world_attach_serial(w, sv[0], &sd, &id) == GC_OK, "attach");
    dev_read(&dev, 200);
    uint8_t hello[12] = {1, GC_CAP_FORCES, 0, 0};
    gc_put16(hello + 4, 1000);
    gc_putf32(hello + 6, 5.0f);
    gc_put16(hello + 10, 50);
    dev_send(&dev, GC_MSG_HELLO_DEVICE, hello, 12);
    gcSerialStats st;
    for (int i = 0; i < 100; ++i) { /* a heartbeat after every pose: its seq is the next one */
        dev_pose(&dev, 0, 0, 0.05);
        uint8_t hb[4] = {0};
        dev_send(&dev, GC_MSG_HEARTBEAT, hb, 4);
        dev_read(&dev, 0);
        sleep_ms(1);
    }
    WAIT_UNTIL((gc_world_serial_stats(w, id, &st), st.poses >= 100 && st.heartbeats >= 100));
    GC_CHECK(st.poses == 100 && st.heartbeats == 100 && st.sequence_gaps == 0,
             "heartbeats between poses: %llu poses, %llu heartbeats, %llu gaps", (unsigned long long)st.poses,
             (unsigned long long)st.heartbeats, (unsigned long long)st.sequence_gaps);
    dev.seq += 3; /* three frames lost on the way */
    stream(&dev, 20, 0.05);
    WAIT_UNTIL((gc_world_serial_stats(w, id, &st), st.poses >= 120));
    GC_CHECK(st.sequence_gaps == 3, "three frames missing: %llu gaps", (unsigned long long)st.sequence_gaps);

    /* The host's e-stop: ESTOP(0), and again every 100 ms while the poses say "not latched". */
    gc_world_serial_estop(w, id);
    int estops = 0;
    for (int k = 0; k < 5; ++k) {
        uint8_t buf[4096];
        for (int i = 0; i < 60; ++i) { /* poses without the e-stop bit, counting ESTOP frames */
            dev_pose(&dev, 0, 0, 0.05);
            struct pollfd pfd = {.fd = dev.fd, .events = POLLIN};
            while (poll(&pfd, 1, 1) > 0) {
                ssize_t n = read(dev.fd, buf, sizeof buf);
                if (n <= 0) break;
                gcFrame fr;
                for (ssize_t j = 0; j < n; ++j)
                    if (gc_decoder_push(&dev.dec, buf[j], &fr) && fr.type == GC_MSG_ESTOP) estops++;
            }
        }
    }
    GC_CHECK(estops >= 2, "the host's ESTOP said again while the device does not show it: %d frames", estops);
    dev.status = GC_STATUS_ESTOPPED; /* now latched at the device: no more */
    stream(&dev, 50, 0.05);
    int hellos = dev.hellos;
    sleep_ms(350); /* silent: lost after 0.1 s, then hellos */
    dev_read(&dev, 10);
    GC_CHECK(dev.hellos >= hellos + 2, "hellos to a silent device: %d", dev.hellos - hellos);
    gc_world_serial_stats(w, id, &st);
    GC_CHECK(st.state == GC_SERIAL_LOST, "state %d", st.state);
    dev_send(&dev, GC_MSG_HELLO_DEVICE, hello, 12); /* it restarted: its sequence starts again */
    dev.seq = 0;
    stream(&dev, 50, 0.05);
    uint64_t gaps = st.sequence_gaps;
    WAIT_UNTIL((gc_world_serial_stats(w, id, &st), st.state == GC_SERIAL_STREAMING && st.poses > 200));
    GC_CHECK(st.state == GC_SERIAL_STREAMING && st.sequence_gaps == gaps, "streaming again, gaps %llu (were %llu)",
             (unsigned long long)st.sequence_gaps, (unsigned long long)gaps);
    gc_world_stop(w);
    gc_world_destroy(w);
    close(sv[0]), close(sv[1]);
}

/* A device attached before the runtime starts (a session connecting its devices first): its
 * poses are refused, counted, and leave the world's last error alone (the API thread's: TSan
 * sees any write from the device thread racing the error calls below); once the runtime runs
 * the same thread drives the finger. */
static void test_attach_before_start(void) {
    gcWorld *w = NULL;
    gcWorldDef wd = gc_default_world_def();
    GC_CHECK(gc_world_create(&wd, &w) == GC_OK, "create");
    gcFingerDef fd = gc_default_finger_def();
    int32_t f;
    GC_CHECK(gc_world_add_finger(w, &fd, &f) == GC_OK, "finger");
    int sv[2];
    GC_CHECK(socketpair(AF_UNIX, SOCK_STREAM, 0, sv) == 0, "socketpair");
    fcntl(sv[0], F_SETFL, O_NONBLOCK);
    static Dev dev;
    memset(&dev, 0, sizeof dev);
    dev.fd = sv[1];
    gc_decoder_reset(&dev.dec);
    gcSerialDef sd = gc_default_serial_def();
    sd.priority = 0;
    int32_t id;
    GC_CHECK(gc_world_attach_serial(w, sv[0], &sd, &id) == GC_OK, "attach before start: %s", gc_world_last_error(w));
    dev_read(&dev, 200);
    uint8_t hello[12] = {1, GC_CAP_FORCES, 0, 0};
    gc_put16(hello + 4, 1000);
    gc_putf32(hello + 6, 5.0f);
    gc_put16(hello + 10, 50);
    dev_send(&dev, GC_MSG_HELLO_DEVICE, hello, 12);
    for (int i = 0; i < 50; ++i) { /* poses while stopped, errors set on this thread meanwhile */
        dev_pose(&dev, 0, 0, 0.03);
        double nan3[3] = {NAN, 0, 0};
        GC_CHECK(gc_world_set_hip(w, f, nan3) == GC_ERR_INVALID_ARGUMENT, "a NaN HIP refused");
        GC_CHECK(strstr(gc_world_last_error(w), "position") != NULL || strstr(gc_world_last_error(w), "finite"),
                 "this thread's error stays: %s", gc_world_last_error(w));
        dev_read(&dev, 0);
        sleep_ms(1);
    }
    gcSerialStats st;
    WAIT_UNTIL((gc_world_serial_stats(w, id, &st), st.poses >= 50));
    GC_CHECK(st.poses == 50 && st.push_rejected == 0, "poses before start: %llu, all in the slots (refused %llu)",
             (unsigned long long)st.poses, (unsigned long long)st.push_rejected);
    gcRuntimeDef rd = gc_default_runtime_def();
    rd.priority = 0;
    GC_CHECK(gc_world_start(w, &rd) == GC_OK, "start with a device streaming: %s", gc_world_last_error(w));
    stream(&dev, 100, 0.03);
    double hip[3] = {0, 0, 0};
    gcSnapshot hs;
    memset(&hs, 0, sizeof hs);
    hs.hips = hip;
    WAIT_UNTIL((stream(&dev, 5, 0.03), gc_world_snapshot(w, &hs), fabs(hip[2] - 0.03) < 1e-7)); /* soft start: 0.15 s */
    GC_CHECK(fabs(hip[2] - 0.03) < 1e-7, "the device drives the finger once running: z %g", hip[2]);
    gc_world_stop(w);
    gc_world_destroy(w);
    close(sv[0]), close(sv[1]);
}

/* ---- UDP ---------------------------------------------------------------------------------- */

static int udp_socket(int *port) {
    int fd = socket(AF_INET, SOCK_DGRAM, 0);
    struct sockaddr_in a = {.sin_family = AF_INET, .sin_addr.s_addr = htonl(INADDR_LOOPBACK)};
    GC_CHECK(fd >= 0 && bind(fd, (struct sockaddr *)&a, sizeof a) == 0, "udp bind");
    socklen_t len = sizeof a;
    getsockname(fd, (struct sockaddr *)&a, &len);
    *port = ntohs(a.sin_port);
    fcntl(fd, F_SETFL, O_NONBLOCK);
    return fd;
}

static void udp_send(int fd, int port, uint8_t type, uint16_t seq, const uint8_t *p, size_t n) {
    uint8_t wire[GC_PROTO_WIRE_MAX + 1];
    size_t len = gc_frame_encode(type, seq, p, n, wire);
    struct sockaddr_in to = {.sin_family = AF_INET, .sin_port = htons((uint16_t)port),
                             .sin_addr.s_addr = htonl(INADDR_LOOPBACK)};
    GC_CHECK(sendto(fd, wire, len, 0, (struct sockaddr *)&to, sizeof to) == (ssize_t)len, "udp send");
}

static void udp_pose(int fd, int port, uint16_t seq, double z) {
    uint8_t p[18] = {0};
    p[4] = 1;
    gc_putf32(p + 6, 0.0f), gc_putf32(p + 10, 0.0f), gc_putf32(p + 14, (float)z);
    udp_send(fd, port, GC_MSG_POSE, seq, p, 18);
}

/* The datagram transport: hello to the configured address, the session pinned to the sender
 * of the HELLO_DEVICE, a second sender dropped and counted, late and duplicated poses dropped
 * (the HIP stays at the newest pose), the device's address in the stats. */
static void test_udp(void) {
    gcWorld *w = NULL;
    gcWorldDef wd = gc_default_world_def();
    GC_CHECK(gc_world_create(&wd, &w) == GC_OK, "create");
    gcFingerDef fd = gc_default_finger_def();
    int32_t f;
    GC_CHECK(gc_world_add_finger(w, &fd, &f) == GC_OK, "finger");
    gcRuntimeDef rd = gc_default_runtime_def();
    rd.priority = 0;
    GC_CHECK(gc_world_start(w, &rd) == GC_OK, "start");
    int host_port, dev_port, other_port;
    int host = udp_socket(&host_port), dev = udp_socket(&dev_port), other = udp_socket(&other_port);
    gcSerialDef sd = gc_default_serial_def();
    sd.priority = 0;
    int32_t id;
    sd.lost_timeout = 1.0; /* the last pose is sent once: the soft start walks to it meanwhile */
    strcpy(sd.udp_host, "not-an-address");
    sd.udp_port = dev_port;
    GC_CHECK(gc_world_attach_serial(w, host, &sd, &id) == GC_ERR_INVALID_ARGUMENT &&
                 strstr(gc_world_last_error(w), "udp_host"), "a host name refused: %s", gc_world_last_error(w));
    strcpy(sd.udp_host, "127.0.0.1");
    GC_CHECK(gc_world_attach_serial(w, host, &sd, &id) == GC_OK, "attach udp: %s", gc_world_last_error(w));
    uint8_t buf[512];
    ssize_t k = -1;
    for (double end_ = now_s() + STATE_DEADLINE_S; k < 0 && now_s() < end_; sleep_ms(1)) k = recv(dev, buf, sizeof buf, 0);
    gcFrame fr;
    GC_CHECK(k > 1 && gc_frame_decode(buf, (size_t)k - 1, &fr) == GC_FRAME_OK && fr.type == GC_MSG_HELLO_HOST,
             "HELLO_HOST to the configured address (%zd bytes)", k);
    uint8_t hello[12] = {1, GC_CAP_FORCES, 0, 0};
    gc_put16(hello + 4, 1000);
    gc_putf32(hello + 6, 5.0f);
    gc_put16(hello + 10, 50);
    udp_pose(other, host_port, 0, 0.9); /* before the hello: nobody is the device yet */
    udp_send(dev, host_port, GC_MSG_HELLO_DEVICE, 0, hello, 12);
    uint16_t seq = 1;
    for (int i = 0; i < 50; ++i, sleep_ms(1)) {
        udp_pose(dev, host_port, seq++, 0.01); /* centimetres: the soft start walks there in 0.1 s */
        udp_pose(other, host_port, (uint16_t)(1000 + i), 0.9); /* a second sender: ignored */
    }
    udp_pose(dev, host_port, (uint16_t)(seq + 1), 0.02); /* newest */
    udp_pose(dev, host_port, seq, 0.015);                /* late: the one before */
    udp_pose(dev, host_port, (uint16_t)(seq + 1), 0.02); /* again */
    gcSerialStats st;
    WAIT_UNTIL((gc_world_serial_stats(w, id, &st), st.poses >= 51 && st.late_poses + st.duplicate_poses >= 2));
    GC_CHECK(st.poses == 51 && st.late_poses == 1 && st.duplicate_poses == 1 && st.sequence_gaps == 1,
             "poses %llu, late %llu, duplicate %llu, gaps %llu", (unsigned long long)st.poses,
             (unsigned long long)st.late_poses, (unsigned long long)st.duplicate_poses,
             (unsigned long long)st.sequence_gaps);
    GC_CHECK(st.foreign_datagrams == 51, "foreign datagrams %llu", (unsigned long long)st.foreign_datagrams);
    char want[64];
    snprintf(want, sizeof want, "127.0.0.1:%d", dev_port);
    GC_CHECK(!strcmp(st.peer, want), "peer '%s', want '%s'", st.peer, want);
    double hip[3] = {0, 0, 0};
    gcSnapshot hs;
    memset(&hs, 0, sizeof hs);
    hs.hips = hip;
    WAIT_UNTIL((gc_world_snapshot(w, &hs), fabs(hip[2] - 0.02) < 1e-7));
    sleep_ms(20);
    gc_world_snapshot(w, &hs);
    GC_CHECK(fabs(hip[2] - 0.02) < 1e-7, "the newest pose holds (not the late one, not the intruder's): %g", hip[2]);
    k = -1;
    int forces = 0;
    while ((k = recv(dev, buf, sizeof buf, 0)) > 0)
        forces += gc_frame_decode(buf, (size_t)k - 1, &fr) == GC_FRAME_OK && fr.type == GC_MSG_FORCE;
    GC_CHECK(forces >= 50, "force frames back to the device: %d", forces);
    GC_CHECK(recv(other, buf, sizeof buf, 0) < 0, "nothing sent to the other sender");
    gc_world_stop(w);
    gc_world_destroy(w);
    close(host), close(dev), close(other);
}

/* ---- the force gate and the soft start ------------------------------------------------------ */

/* The one gate: closed until enabled, a linear ramp from the instant it may open, NaN zeroed and
 * counted, each force's norm clamped, an e-stop latched until the next enable, the TTL field. */
static void test_force_gate(void) {
    gcForceGate g;
    gc_force_gate_init(&g, 100, 0); /* a 100 ns ramp */
    GC_CHECK(gc_force_gate_gain(&g, 1, 0) == 0.0, "closed until enabled");
    gc_force_gate_enable(&g, 1);
    GC_CHECK(gc_force_gate_gain(&g, 0, 5) == 0.0, "closed while not ready");
    GC_CHECK(gc_force_gate_gain(&g, 1, 1000) == 0.0, "the ramp starts when it may open");
    GC_CHECK(fabs(gc_force_gate_gain(&g, 1, 1025) - 0.25) < 1e-15, "a quarter of the ramp: %g",
             gc_force_gate_gain(&g, 1, 1025));
    GC_CHECK(gc_force_gate_gain(&g, 1, 1100) == 1.0 && gc_force_gate_gain(&g, 1, 5000) == 1.0, "full after the ramp");
    GC_CHECK(gc_force_gate_gain(&g, 0, 5001) == 0.0 && gc_force_gate_gain(&g, 1, 5002) == 0.0 &&
                 fabs(gc_force_gate_gain(&g, 1, 5052) - 0.5) < 1e-15,
             "not ready for a moment: it ramps in again from zero");
    GC_CHECK(gc_force_gate_estop(&g) == 1 && gc_force_gate_estop(&g) == 0, "an e-stop latches once");
    GC_CHECK(gc_force_gate_gain(&g, 1, 6000) == 0.0 && !g.enabled, "e-stopped: closed, disabled");
    gc_force_gate_enable(&g, 1);
    GC_CHECK(!g.estop && gc_force_gate_gain(&g, 1, 7000) == 0.0 && gc_force_gate_gain(&g, 1, 7100) == 1.0,
             "enable clears the e-stop and ramps in again");
    const double in[9] = {3, 4, 0, NAN, 0, 0, 0.3, 0.4, 0};
    double out[9];
    int nonfinite = gc_force_gate_apply(1.0, 2.0, in, out, 3);
    GC_CHECK(nonfinite == 1 && out[3] == 0 && out[4] == 0 && out[5] == 0, "NaN zeroed and counted");
    GC_CHECK(fabs(out[0] - 1.2) < 1e-15 && fabs(out[1] - 1.6) < 1e-15, "|(3, 4, 0)| = 5 clamped to 2: (%g, %g)", out[0],
             out[1]);
    GC_CHECK(out[6] == 0.3 && out[7] == 0.4, "under the limit: untouched");
    gc_force_gate_apply(0.5, 2.0, in, out, 3);
    GC_CHECK(out[6] == 0.15 && out[7] == 0.2 && fabs(out[0] - 1.2) < 1e-15, "scaled by the gain, then clamped");
    GC_CHECK(gc_force_gate_ttl_us(0.02, 0.0) == 20000 && gc_force_gate_ttl_us(0.02, 0.005) == 5000 &&
                 gc_force_gate_ttl_us(1.0, 0.0) == 65535,
             "TTL: the host's, at most the device's, at most 16 bits");
}

/* Finger 0's HIP (of a world with at most 8 fingers). */
static void hip_of(gcWorld *w, double hip[3]) {
    double all[3 * 8];
    gcSnapshot s;
    memset(&s, 0, sizeof s);
    s.hips = all;
    gc_world_snapshot(w, &s);
    memcpy(hip, all, 3 * sizeof(double));
}

/* A device's first sample 5 cm from the HIP: the HIP walks there on a straight line at exactly
 * GC_HIP_SOFT_START_SPEED (no tick moves it further), arrives after 0.05 / (0.1 dt) ticks and
 * stays; a new session (stop, start) walks again, and a finger no device drives is not held. */
static void test_soft_start(void) {
    gcWorld *w = NULL;
    gcWorldDef wd = gc_default_world_def();
    GC_CHECK(gc_world_create(&wd, &w) == GC_OK, "create");
    gcFingerDef fd = gc_default_finger_def();
    int32_t f0, f1;
    GC_CHECK(gc_world_add_finger(w, &fd, &f0) == GC_OK && gc_world_add_finger(w, &fd, &f1) == GC_OK, "fingers");
    gcRuntimeDef rd = gc_default_runtime_def();
    rd.realtime = 0;
    const double dt = 1.0 / rd.haptic_rate, step = GC_HIP_SOFT_START_SPEED * dt;
    const double far[3] = {0.03, 0.0, 0.04}; /* 5 cm away */
    GC_CHECK(gc_world_push_device_hips(w, 0, 1, far) == GC_ERR_NOT_RUNNING, "stopped: not running");
    for (int session = 0; session < 2; ++session) {
        GC_CHECK(gc_world_start(w, &rd) == GC_OK, "start: %s", gc_world_last_error(w));
        double prev[3];
        hip_of(w, prev);
        double d0 = sqrt((far[0] - prev[0]) * (far[0] - prev[0]) + (far[2] - prev[2]) * (far[2] - prev[2]));
        GC_CHECK(gc_world_push_device_hips(w, 0, 1, far) == GC_OK, "pushed");
        int ticks = 0, arrived = -1;
        double max_step = 0, off_line = 0;
        for (; ticks < 2000 && arrived < 0; ++ticks) {
            GC_CHECK(gc_world_advance(w, 1, 0.0) == GC_OK, "advance");
            double h[3];
            hip_of(w, h);
            double s2 = 0;
            for (int c = 0; c < 3; ++c) s2 += (h[c] - prev[c]) * (h[c] - prev[c]);
            max_step = fmax(max_step, sqrt(s2));
            off_line = fmax(off_line, fabs(h[1]) + fabs(h[0] * far[2] - h[2] * far[0]));
            memcpy(prev, h, sizeof h);
            if (h[0] == far[0] && h[1] == far[1] && h[2] == far[2]) arrived = ticks + 1;
        }
        int expect = (int)ceil(d0 / step - 1e-9);
        GC_CHECK(max_step <= step * (1 + 1e-9), "session %d: no tick moves the HIP more than %.3g m: %.6g m", session,
                 step, max_step);
        GC_CHECK(arrived >= expect && arrived <= expect + 1, "session %d: arrived after %d ticks, %.4f m at %.3g m/tick "
                 "wants %d", session, arrived, d0, step, expect);
        GC_CHECK(off_line < 1e-12, "a straight line: %g", off_line);
        GC_CHECK(gc_world_advance(w, 50, 0.0) == GC_OK, "advance");
        double h[3];
        hip_of(w, h);
        GC_CHECK(h[0] == far[0] && h[2] == far[2], "stays at the device's pose");
        const double near1[3] = {0.0, 0.0, 0.2}; /* finger 1 through push_hips: no soft start */
        double rows[6] = {h[0], h[1], h[2], near1[0], near1[1], near1[2]};
        GC_CHECK(gc_world_push_hips(w, rows, 2, 1.0 + session) == GC_OK, "push_hips: %s", gc_world_last_error(w));
        GC_CHECK(gc_world_advance(w, 1, 0.0) == GC_OK, "advance");
        double both[6];
        gcSnapshot s;
        memset(&s, 0, sizeof s);
        s.hips = both;
        gc_world_snapshot(w, &s);
        GC_CHECK(both[5] == 0.2 && both[0] == far[0], "finger 1 jumps (pushed, not a device); finger 0 is its device's");
        double back[6] = {0, 0, 0, 0, 0, 0};
        GC_CHECK(gc_world_stop(w) == GC_OK, "stop");
        for (int i = 0; i < 2; ++i) GC_CHECK(gc_world_set_hip(w, i, back) == GC_OK, "home");
    }
    gc_world_destroy(w);
}

/* A device that falls silent halfway through its soft start (a busy machine pausing it) and then
 * streams again: the sample after the silence is walked over a long segment (slower than the soft
 * speed), and the next one, a tick later, asks for the rest of the way at once. The soft start
 * holds until the HIP is at the device's pose: no tick moves it more than the soft speed allows.
 * (Sample times are the real clock's: the sleep makes the silence at least 0.3 s, whatever the load.) */
static void test_soft_start_survives_a_silence(void) {
    gcWorld *w = NULL;
    gcWorldDef wd = gc_default_world_def();
    GC_CHECK(gc_world_create(&wd, &w) == GC_OK, "create");
    gcFingerDef fd = gc_default_finger_def();
    int32_t f0;
    GC_CHECK(gc_world_add_finger(w, &fd, &f0) == GC_OK, "finger");
    gcRuntimeDef rd = gc_default_runtime_def();
    rd.realtime = 0;
    const double step = GC_HIP_SOFT_START_SPEED / rd.haptic_rate;
    const double far[3] = {0.0, 0.0, 0.05};
    GC_CHECK(gc_world_start(w, &rd) == GC_OK, "start: %s", gc_world_last_error(w));
    double prev[3], h[3], max_step = 0;
    hip_of(w, prev);
    int arrived = -1;
    for (int tick = 0; tick < 2000 && arrived < 0; ++tick) {
        if (tick == 0 || tick == 131 || tick >= 132) GC_CHECK(gc_world_push_device_hips(w, 0, 1, far) == GC_OK, "push");
        if (tick == 131) sleep_ms(300); /* 2.6 cm walked, 2.4 cm to go: silence, then a sample */
        GC_CHECK(gc_world_advance(w, 1, 0.0) == GC_OK, "advance");
        hip_of(w, h);
        double s2 = 0;
        for (int c = 0; c < 3; ++c) s2 += (h[c] - prev[c]) * (h[c] - prev[c]);
        max_step = fmax(max_step, sqrt(s2));
        memcpy(prev, h, sizeof h);
        if (h[2] == far[2]) arrived = tick + 1;
    }
    GC_CHECK(max_step <= step * (1 + 1e-9), "after a silence: no tick moves the HIP more than %.3g m: %.6g m", step,
             max_step);
    GC_CHECK(arrived >= 250, "5 cm at the soft speed: arrived after %d ticks, wants at least 250", arrived);
    GC_CHECK(gc_world_stop(w) == GC_OK, "stop");
    gc_world_destroy(w);
}

/* A device read elsewhere (push_device_hips from another thread) beside a serial device thread,
 * both writing their fingers' slots while the haptic loop reads them (TSan: no race), each
 * finger its own writer: a finger a device drives is refused to the other, and free again once
 * that device is detached. */
typedef struct ApiPusher {
    gcWorld *w;
    int pushes, refused;
} ApiPusher;

static void *api_pusher(void *arg) {
    ApiPusher *p = arg;
    for (int i = 1; i <= 300; ++i) {
        double x[3] = {1.0, 0.0001 * i, 0.0};
        if (gc_world_push_device_hips(p->w, 1, 1, x) == GC_OK) p->pushes++;
        else p->refused++;
        sleep_ms(1);
    }
    return NULL;
}

static void test_device_beside_api_writer(void) {
    gcWorld *w = NULL;
    gcWorldDef wd = gc_default_world_def();
    GC_CHECK(gc_world_create(&wd, &w) == GC_OK, "create");
    gcFingerDef fd = gc_default_finger_def();
    int32_t f;
    for (int i = 0; i < 2; ++i) {
        fd.position[0] = i ? 1.0 : -1.0;
        GC_CHECK(gc_world_add_finger(w, &fd, &f) == GC_OK, "finger");
    }
    int sv[2];
    GC_CHECK(socketpair(AF_UNIX, SOCK_STREAM, 0, sv) == 0, "socketpair");
    fcntl(sv[0], F_SETFL, O_NONBLOCK);
    static Dev dev;
    memset(&dev, 0, sizeof dev);
    dev.fd = sv[1];
    gc_decoder_reset(&dev.dec);
    gcSerialDef sd = gc_default_serial_def();
    sd.priority = 0;
    sd.transform[3] = -1.0;
    int32_t id;
    GC_CHECK(gc_world_attach_serial(w, sv[0], &sd, &id) == GC_OK, "attach before start: %s", gc_world_last_error(w));
    gcRuntimeDef rd = gc_default_runtime_def();
    rd.priority = 0;
    GC_CHECK(gc_world_start(w, &rd) == GC_OK, "start");
    uint8_t hello[12] = {1, GC_CAP_FORCES, 0, 0};
    gc_put16(hello + 4, 1000);
    gc_putf32(hello + 6, 5.0f);
    gc_put16(hello + 10, 50);
    dev_read(&dev, 200);
    dev_send(&dev, GC_MSG_HELLO_DEVICE, hello, 12);
    const double x0[3] = {-1.0, 0.0, 0.0};
    GC_CHECK(gc_world_push_device_hips(w, 0, 1, x0) == GC_ERR_INVALID_ARGUMENT &&
                 strstr(gc_world_last_error(w), "a serial device drives"),
             "a serial device's finger refused to push_device_hips: %s", gc_world_last_error(w));
    ApiPusher pusher = {w, 0, 0};
    pthread_t th;
    GC_CHECK(pthread_create(&th, NULL, api_pusher, &pusher) == 0, "pusher thread");
    for (int i = 1; i <= 300; ++i) {
        dev_pose(&dev, 0, 0.0001 * i, 0);
        dev_read(&dev, 0);
        sleep_ms(1);
    }
    pthread_join(th, NULL);
    GC_CHECK(pusher.pushes == 300 && pusher.refused == 0, "API pushes %d, refused %d", pusher.pushes, pusher.refused);
    int32_t other;
    gcSerialDef sd1 = gc_default_serial_def();
    sd1.finger_offset = 1;
    GC_CHECK(gc_world_attach_serial(w, sv[0], &sd1, &other) == GC_ERR_INVALID_ARGUMENT &&
                 strstr(gc_world_last_error(w), "push_device_hips"),
             "a finger push_device_hips drives refused to a serial device: %s", gc_world_last_error(w));
    double hips[6];
    gcSnapshot s;
    memset(&s, 0, sizeof s);
    s.hips = hips;
    WAIT_UNTIL((dev_pose(&dev, 0, 0.03, 0), dev_read(&dev, 0), gc_world_snapshot(w, &s),
                fabs(hips[1] - 0.03) < 1e-7 && fabs(hips[4] - 0.03) < 1e-7));
    GC_CHECK(hips[0] == -1.0 && fabs(hips[1] - 0.03) < 1e-7 && hips[3] == 1.0 && fabs(hips[4] - 0.03) < 1e-7,
             "each writer its finger: (%g %g) (%g %g)", hips[0], hips[1], hips[3], hips[4]);
    GC_CHECK(gc_world_detach_serial(w, id) == GC_OK, "detach");
    GC_CHECK(gc_world_push_device_hips(w, 0, 1, x0) == GC_OK, "free once its device is detached: %s",
             gc_world_last_error(w));
    gc_world_stop(w);
    gc_world_destroy(w);
    close(sv[0]), close(sv[1]);
}

/* A device read in Python (push_device_hips) pressing 5 mm into the ground: its forces
 * (gc_world_device_forces) come from the haptic tick through the same gate as a device
 * thread's: zero until enabled, then the runtime's device force (5 N here, no ramp), zero again
 * once disabled; only for fingers driven that way. */
static void test_device_forces_for_api_fingers(void) {
    gcWorld *w = NULL;
    gcWorldDef wd = gc_default_world_def();
    GC_CHECK(gc_world_create(&wd, &w) == GC_OK, "create");
    double pts[24];
    for (int i = 0; i < 8; ++i) {
        pts[3 * i] = (i & 1) ? 0.1 : -0.1;
        pts[3 * i + 1] = (i & 2) ? 0.1 : -0.1;
        pts[3 * i + 2] = (i & 4) ? 0.0 : -0.2; /* top face at z = 0 */
    }
    gcPartDef part = {pts, 8, 0.0};
    gcBodyDef bd = gc_default_body_def();
    bd.is_static = 1;
    int32_t ground, f;
    GC_CHECK(gc_world_add_body(w, &bd, &part, 1, &ground) == GC_OK, "ground");
    gcFingerDef fd = gc_default_finger_def(); /* radius 8 mm, 1000 N/m */
    fd.position[2] = 0.008;
    for (int i = 0; i < 2; ++i) GC_CHECK(gc_world_add_finger(w, &fd, &f) == GC_OK, "finger");
    gcRuntimeDef rd = gc_default_runtime_def();
    rd.priority = 0;
    rd.ramp_time = 0.0;
    rd.watchdog_timeout = 0.5; /* a loaded test machine: this test is about the gate */
    double out[3] = {1, 1, 1};
    GC_CHECK(gc_world_start(w, &rd) == GC_OK, "start");
    GC_CHECK(gc_world_device_forces(w, 0, 1, 1, out) == GC_ERR_INVALID_ARGUMENT &&
                 strstr(gc_world_last_error(w), "push_device_hips"),
             "a finger no device read elsewhere drives: %s", gc_world_last_error(w));
    const double press[3] = {0, 0, 0.003}; /* 5 mm into the ground */
    double sp[6] = {0};
    gcSnapshot s;
    memset(&s, 0, sizeof s);
    s.spring_forces = sp;
    WAIT_UNTIL((gc_world_push_device_hips(w, 0, 1, press), gc_world_snapshot(w, &s), fabs(sp[2] - 5.0) < 1e-6));
    GC_CHECK(fabs(sp[2] - 5.0) < 1e-6, "spring %g N", sp[2]);
    GC_CHECK(gc_world_device_forces(w, 0, 1, 0, out) == GC_OK && out[0] == 0 && out[1] == 0 && out[2] == 0,
             "zero until enabled: %g", out[2]);
    WAIT_UNTIL((gc_world_device_forces(w, 0, 1, 1, out), fabs(out[2] - 5.0) < 1e-6));
    GC_CHECK(fabs(out[2] - 5.0) < 1e-6 && out[0] == 0 && out[1] == 0, "enabled: the tick's device force, %g N",
             out[2]);
    GC_CHECK(gc_world_device_forces(w, 0, 1, 0, out) == GC_OK && out[2] == 0, "disabled: zero again");
    gc_world_stop(w);
    GC_CHECK(gc_world_device_forces(w, 0, 1, 1, out) == GC_ERR_NOT_RUNNING && out[2] == 0, "stopped: zero");
    gc_world_destroy(w);
}


/* A device slot's orientation (gc_world_push_device_poses) reaches a convex finger through the
 * threaded haptic tick: the finger ends at the device's quaternion; a sample without one leaves
 * it where it is; a non-unit or non-finite quaternion is refused and counted as a NaN position
 * is, nothing of the sample taken. */
static void test_device_orientation_turns_a_convex_finger(void) {
    gcWorld *w = NULL;
    gcWorldDef wd = gc_default_world_def();
    GC_CHECK(gc_world_create(&wd, &w) == GC_OK, "create");
    double pts[24];
    for (int i = 0; i < 8; ++i) {
        pts[3 * i] = (i & 1) ? 0.04 : -0.04;
        pts[3 * i + 1] = (i & 2) ? 0.03 : -0.03;
        pts[3 * i + 2] = (i & 4) ? 0.01 : -0.01;
    }
    gcFingerDef fd = gc_default_finger_def();
    fd.radius = 0.0;
    fd.points = pts;
    fd.num_points = 8;
    int32_t palm;
    GC_CHECK(gc_world_add_finger(w, &fd, &palm) == GC_OK, "palm: %s", gc_world_last_error(w));
    gcRuntimeDef rd = gc_default_runtime_def();
    rd.priority = 0;
    GC_CHECK(gc_world_start(w, &rd) == GC_OK, "start");
    const double a = 0.3, here[3] = {0, 0, 0.02}; /* 0.3 rad about (0.6, 0, 0.8) */
    const double q[4] = {cos(a / 2), 0.6 * sin(a / 2), 0.0, 0.8 * sin(a / 2)};
    const double scaled[4] = {2 * q[0], 2 * q[1], 2 * q[2], 2 * q[3]}, nan_q[4] = {NAN, 0, 0, 0};
    const double nan_p[3] = {0, NAN, 0}, far[3] = {0, 0, 0.5};
    GC_CHECK(gc_world_push_device_poses(w, 0, 1, far, scaled) == GC_WARN_REJECTED, "a scaled quaternion refused");
    GC_CHECK(gc_world_push_device_poses(w, 0, 1, far, nan_q) == GC_WARN_REJECTED, "a NaN quaternion refused");
    GC_CHECK(gc_world_push_device_poses(w, 0, 1, nan_p, q) == GC_WARN_REJECTED, "a NaN position refused");
    GC_CHECK(gc_world_push_device_hips(w, 0, 1, nan_p) == GC_WARN_REJECTED, "a NaN position refused");
    gcRuntimeStats st;
    GC_CHECK(gc_world_stats(w, &st) == GC_OK && st.rejected_inputs == 4 && st.accepted_inputs == 0,
             "all four counted: %llu", (unsigned long long)st.rejected_inputs);
    for (int k = 0; k < 200; ++k) { /* 0.2 s of samples, a millisecond apart */
        GC_CHECK(gc_world_push_device_poses(w, 0, 1, here, q) == GC_OK, "pushed");
        sleep_ms(1);
    }
    const double elsewhere[3] = {0, 0, 0.03};
    for (int k = 0; k < 50; ++k) { /* positions only: the orientation stays */
        GC_CHECK(gc_world_push_device_hips(w, 0, 1, elsewhere) == GC_OK, "pushed");
        sleep_ms(1);
    }
    sleep_ms(20);
    gc_world_stop(w);
    double p[3], o[4];
    GC_CHECK(gc_world_finger_pose(w, palm, p, o) == GC_OK, "pose");
    for (int c = 0; c < 4; ++c) GC_CHECK(fabs(o[c] - q[c]) < 1e-12, "orientation[%d] %.15f, want %.15f", c, o[c], q[c]);
    GC_CHECK(fabs(p[2] - 0.03) < 1e-12, "the later position taken: %g", p[2]);
    gc_world_destroy(w);
}


static void dev_pose_oriented(Dev *d, double z, const double q[4]) {
    uint8_t p[6 + GC_PROTO_ORIENTED_FINGER];
    gc_put32(p, d->seq * 1000u);
    p[4] = 1;
    p[5] = d->status;
    gc_putf32(p + 6, 0.0f), gc_putf32(p + 10, 0.0f), gc_putf32(p + 14, (float)z);
    for (int c = 0; c < 4; ++c) gc_putf32(p + 18 + 4 * c, (float)q[c]);
    dev_send(d, GC_MSG_POSE, p, sizeof p);
}

/* A device's orientations over the protocol (docs/protocol.md §2): offered in its hello
 * (flags bit 1), taken by the host in every FORCE (flags bit 0), then sent after the positions;
 * the finger turns to the workspace frame's rotation times the device's. A device that did not
 * offer them has its oriented poses dropped (length); a non-unit one is dropped (range); a
 * mirrored workspace frame takes positions only. */
static void test_serial_orientations(void) {
    gcWorld *w = NULL;
    gcWorldDef wd = gc_default_world_def();
    GC_CHECK(gc_world_create(&wd, &w) == GC_OK, "create");
    double pts[24];
    for (int i = 0; i < 8; ++i) {
        pts[3 * i] = (i & 1) ? 0.04 : -0.04;
        pts[3 * i + 1] = (i & 2) ? 0.03 : -0.03;
        pts[3 * i + 2] = (i & 4) ? 0.01 : -0.01;
    }
    gcFingerDef fd = gc_default_finger_def();
    fd.radius = 0.0, fd.points = pts, fd.num_points = 8;
    int32_t palm;
    GC_CHECK(gc_world_add_finger(w, &fd, &palm) == GC_OK, "palm: %s", gc_world_last_error(w));
    gcRuntimeDef rd = gc_default_runtime_def();
    rd.priority = 0;
    GC_CHECK(gc_world_start(w, &rd) == GC_OK, "start");
    int sv[2];
    GC_CHECK(socketpair(AF_UNIX, SOCK_STREAM, 0, sv) == 0, "socketpair");
    fcntl(sv[0], F_SETFL, O_NONBLOCK);
    static Dev dev;
    memset(&dev, 0, sizeof dev);
    dev.fd = sv[1];
    gc_decoder_reset(&dev.dec);
    gcSerialDef sd = gc_default_serial_def();
    sd.num_fingers = 1;
    /* The workspace: 90 deg about z, scaled by 2 (the rotation of A is its polar factor). */
    const double A[9] = {0, -2, 0, 2, 0, 0, 0, 0, 2};
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) sd.transform[4 * i + j] = A[3 * i + j];
    int32_t id;
    GC_CHECK(gc_world_attach_serial(w, sv[0], &sd, &id) == GC_OK, "attach: %s", gc_world_last_error(w));
    dev_read(&dev, 200);
    uint8_t hello[12];
    memset(hello, 0, sizeof hello);
    hello[0] = 1, hello[1] = 0; /* positions only */
    gc_put16(hello + 4, 1000);
    dev_send(&dev, GC_MSG_HELLO_DEVICE, hello, sizeof hello);
    const double a = 0.4, tilt[4] = {cos(a / 2), sin(a / 2), 0, 0}; /* about the device's x */
    gcSerialStats st;
    for (int k = 0; k < 50; ++k) dev_pose(&dev, 0, 0, 0.01), dev_read(&dev, 1);
    for (int k = 0; k < 20; ++k) dev_pose_oriented(&dev, 0.01, tilt), dev_read(&dev, 1);
    WAIT_UNTIL((gc_world_serial_stats(w, id, &st), st.frame_errors[GC_FRAME_LENGTH] >= 20)); /* published every 10 ms */
    GC_CHECK(st.frame_errors[GC_FRAME_LENGTH] == 20 && !st.sends_orientations && st.oriented_poses == 0,
             "a device that did not offer them: its oriented poses dropped (length %llu)",
             (unsigned long long)st.frame_errors[GC_FRAME_LENGTH]);
    GC_CHECK(dev.forces > 0 && dev.last_force.payload[5] == 0, "FORCE flags 0 for it: %d", dev.last_force.payload[5]);

    hello[1] = GC_CAP_ORIENTATION;
    dev_send(&dev, GC_MSG_HELLO_DEVICE, hello, sizeof hello);
    int forces_before = dev.forces;
    for (int k = 0; k < 20; ++k) dev_pose(&dev, 0, 0, 0.01), dev_read(&dev, 1);
    WAIT_UNTIL((dev_read(&dev, 1), dev.forces > forces_before + 5));
    GC_CHECK(dev.last_force.payload[5] == GC_FORCE_TAKES_ORIENTATION, "the host takes them: FORCE flags %d",
             dev.last_force.payload[5]);
    const double scaled[4] = {2, 0, 0, 0};
    for (int k = 0; k < 5; ++k) dev_pose_oriented(&dev, 0.01, scaled), dev_read(&dev, 1);
    for (int k = 0; k < 200; ++k) dev_pose_oriented(&dev, 0.01, tilt), dev_read(&dev, 1);
    WAIT_UNTIL((gc_world_serial_stats(w, id, &st), st.oriented_poses >= 200));
    GC_CHECK(st.sends_orientations && st.oriented_poses == 200 && st.frame_errors[GC_FRAME_RANGE] == 5,
             "oriented poses %llu, range %llu", (unsigned long long)st.oriented_poses,
             (unsigned long long)st.frame_errors[GC_FRAME_RANGE]);
    GC_CHECK(gc_world_detach_serial(w, id) == GC_OK, "detach");

    /* A mirrored frame: the host does not take them, whatever the hello offers. */
    sd.transform[10] = -2;
    GC_CHECK(gc_world_attach_serial(w, sv[0], &sd, &id) == GC_OK, "attach mirrored: %s", gc_world_last_error(w));
    dev_read(&dev, 200);
    dev_send(&dev, GC_MSG_HELLO_DEVICE, hello, sizeof hello);
    forces_before = dev.forces;
    for (int k = 0; k < 20; ++k) dev_pose(&dev, 0, 0, 0.01), dev_read(&dev, 1);
    WAIT_UNTIL((dev_read(&dev, 1), dev.forces > forces_before + 5));
    WAIT_UNTIL((gc_world_serial_stats(w, id, &st), st.poses >= 20));
    GC_CHECK(st.poses >= 20 && !st.sends_orientations && dev.last_force.payload[5] == 0, "mirrored: FORCE flags %d",
             dev.last_force.payload[5]);
    GC_CHECK(gc_world_detach_serial(w, id) == GC_OK, "detach");
    gc_world_stop(w);

    /* The palm ended at Rz(90 deg) times the device's tilt about x: tilted about the scene's y. */
    double p[3], o[4];
    GC_CHECK(gc_world_finger_pose(w, palm, p, o) == GC_OK, "pose");
    const double h = sqrt(0.5), want[4] = {h * tilt[0], h * tilt[1], h * tilt[1], h * tilt[0]};
    for (int c = 0; c < 4; ++c) GC_CHECK(fabs(o[c] - want[c]) < 1e-6, "orientation[%d] %.9f, want %.9f", c, o[c], want[c]);
    close(sv[0]), close(sv[1]);
    gc_world_destroy(w);
}

int main(void) {
    test_crc_and_cobs();
    test_force_gate();
    test_soft_start();
    test_soft_start_survives_a_silence();
    test_vectors();
    test_fuzzed_decoder();
    test_device_thread();
    test_two_devices();
    test_recorded_forces();
    test_recorded_forces_are_the_frames();
    test_estop_in_status_before_enable();
    test_protocol_rules();
    test_attach_before_start();
    test_device_beside_api_writer();
    test_device_forces_for_api_fingers();
    test_device_orientation_turns_a_convex_finger();
    test_serial_orientations();
    test_udp();
    test_peer_gone_before_hello();
    return gc_test_summary("test_serial_io");
}
