/* Device firmware written from docs/protocol.md alone (no header or code of Grasp Lab), on a
 * pseudo-terminal: the check that the document is enough to build a device. A hardware maker's
 * main loop: frame in, frame out, a TTL watchdog, an ENABLE/ESTOP latch.
 *
 *   firmware_from_doc SECONDS ESTOP_AT_S
 *
 * Prints "PORT /dev/pts/N", waits for HELLO_HOST, streams POSE frames of 2 fingers at 1 kHz in
 * millimetres (at x = +-35 mm), a HEARTBEAT every 50 ms between them, presses its stop button
 * at ESTOP_AT_S (< 0: never), and after SECONDS (or when the host hangs up) prints one JSON line
 * of what it saw. Force limit 2 N, TTL limit 30 ms. */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <poll.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#define FINGERS 2
#define FORCE_MAX 2.0f
#define TTL_MAX_MS 30
#define MAX_ENCODED 398 /* §1: the largest encoding, delimiter excluded */

static double now_s(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + ts.tv_nsec * 1e-9;
}

/* ---- §1 framing ---- */
static uint16_t crc16(const uint8_t *p, size_t n) {
    uint16_t crc = 0xFFFF;
    for (size_t i = 0; i < n; ++i) {
        crc ^= (uint16_t)(p[i] << 8);
        for (int b = 0; b < 8; ++b) crc = (crc & 0x8000) ? (uint16_t)((crc << 1) ^ 0x1021) : (uint16_t)(crc << 1);
    }
    return crc;
}

/* COBS: pieces of up to 253 non-zero bytes after a code k + 1; 0xFF blocks of 254 with no zero. */
static size_t cobs_encode(const uint8_t *in, size_t n, uint8_t *out) {
    size_t code_at = 0, o = 1;
    uint8_t code = 1;
    for (size_t i = 0; i < n; ++i) {
        if (in[i] == 0) {
            out[code_at] = code, code_at = o++, code = 1;
            continue;
        }
        out[o++] = in[i];
        if (++code == 0xFF) {
            out[code_at] = code, code_at = o++, code = 1;
            if (i + 1 == n) return o - 1; /* the body ended after a 0xFF block: no final code */
        }
    }
    out[code_at] = code;
    return o;
}

static int cobs_decode(const uint8_t *in, size_t n, uint8_t *out, size_t *out_n) {
    size_t i = 0, o = 0;
    while (i < n) {
        uint8_t code = in[i];
        if (code == 0 || i + code > n) return -1;
        for (size_t k = i + 1; k < i + code; ++k) out[o++] = in[k];
        i += code;
        if (code != 0xFF && i < n) out[o++] = 0;
    }
    *out_n = o;
    return 0;
}

static int fd;
static uint16_t seq;

static void put16(uint8_t *p, unsigned v) { p[0] = (uint8_t)v, p[1] = (uint8_t)(v >> 8); }
static void put32(uint8_t *p, uint32_t v) { for (int i = 0; i < 4; ++i) p[i] = (uint8_t)(v >> (8 * i)); }
static void putf(uint8_t *p, float f) { uint32_t u; memcpy(&u, &f, 4); put32(p, u); }
static unsigned get16(const uint8_t *p) { return (unsigned)(p[0] | p[1] << 8); }
static float getf(const uint8_t *p) {
    uint32_t u = (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
    float f;
    memcpy(&f, &u, 4);
    return f;
}

static void send_frame(uint8_t type, const uint8_t *payload, size_t n) {
    uint8_t body[400], wire[MAX_ENCODED + 2];
    body[0] = 1, body[1] = type;
    put16(body + 2, seq++);
    memcpy(body + 4, payload, n);
    put16(body + 4 + n, crc16(body, 4 + n));
    size_t w = cobs_encode(body, 6 + n, wire);
    wire[w++] = 0;
    for (size_t off = 0; off < w;) {
        ssize_t k = write(fd, wire + off, w - off);
        if (k > 0) off += (size_t)k;
        else if (k < 0 && errno != EAGAIN && errno != EINTR) return;
    }
}

/* ---- the device's state (§3) ---- */
static int streaming, enabled, estop_latched;
static float rendered[FINGERS][3];
static double ttl_deadline; /* forces may be rendered until then */
static double last_force_at;
static struct {
    int hellos, enables, disables, force_frames, rejected, estops_received, ttl_expiries;
    int forces_while_off; /* FORCE frames with a non-zero force while off or latched (the host's duty) */
    int dropped[4];       /* cobs, short, crc, version/type/length */
    double max_norm, max_ttl_gap_ms;
    long poses, heartbeats;
} seen;

static void zero_forces(void) { memset(rendered, 0, sizeof rendered); }

static void on_force(const uint8_t *p, size_t n, double t) {
    seen.force_frames++;
    unsigned ttl_us = get16(p + 2);
    int fingers = p[4];
    int ok = fingers == FINGERS && n == 6 + 12u * FINGERS && ttl_us >= 1 && ttl_us <= TTL_MAX_MS * 1000u;
    float f[FINGERS][3];
    for (int i = 0; ok && i < FINGERS; ++i)
        for (int c = 0; c < 3; ++c) ok &= isfinite(f[i][c] = getf(p + 6 + 12 * i + 4 * c));
    if (!ok) { /* rejected: every force zero at once */
        seen.rejected++;
        zero_forces();
        return;
    }
    int nonzero = 0;
    for (int i = 0; i < FINGERS; ++i) nonzero |= f[i][0] != 0 || f[i][1] != 0 || f[i][2] != 0;
    if (!enabled || estop_latched) {
        seen.forces_while_off += nonzero;
        return;
    }
    for (int i = 0; i < FINGERS; ++i) {
        double norm = sqrt(f[i][0] * f[i][0] + f[i][1] * f[i][1] + f[i][2] * f[i][2]);
        double s = norm > FORCE_MAX ? FORCE_MAX / norm : 1.0;
        for (int c = 0; c < 3; ++c) rendered[i][c] = (float)(f[i][c] * s);
        if (norm * s > seen.max_norm) seen.max_norm = norm * s;
    }
    ttl_deadline = t + ttl_us * 1e-6;
    last_force_at = t;
}

static void hello_device(void) {
    uint8_t p[12 + 8];
    p[0] = FINGERS, p[1] = 1 /* renders forces */, p[2] = 1 /* millimetres */, p[3] = 0;
    put16(p + 4, 1000);
    putf(p + 6, FORCE_MAX);
    put16(p + 10, TTL_MAX_MS);
    memcpy(p + 12, "doc-fw-1", 8);
    send_frame(0x02, p, sizeof p);
}

static void on_frame(const uint8_t *enc, size_t n, double t) {
    uint8_t body[400];
    size_t len;
    if (n > MAX_ENCODED || cobs_decode(enc, n, body, &len)) { seen.dropped[0]++; return; }
    if (len < 6) { seen.dropped[1]++; return; }
    if (crc16(body, len - 2) != get16(body + len - 2)) { seen.dropped[2]++; return; }
    const uint8_t *p = body + 4;
    size_t pn = len - 6;
    uint8_t type = body[1];
    int length_ok = (type == 0x01 && pn == 2) || (type == 0x04 && pn >= 6) || ((type == 0x05 || type == 0x06) && pn == 1) ||
                    (type == 0x07 && pn == 4);
    if (body[0] != 1 || !length_ok) { seen.dropped[3]++; return; }
    switch (type) {
    case 0x01: /* HELLO_HOST: capabilities, forces off, a latched e-stop stays latched */
        seen.hellos++;
        enabled = 0;
        zero_forces();
        hello_device();
        streaming = 1;
        break;
    case 0x04: on_force(p, pn, t); break;
    case 0x05:
        if (p[0] == 1) {
            enabled = 1, estop_latched = 0, seen.enables++;
        } else {
            enabled = 0, seen.disables++;
            zero_forces();
        }
        break;
    case 0x06:
        seen.estops_received++;
        estop_latched = 1;
        zero_forces();
        break;
    default: break; /* HEARTBEAT: the host is alive */
    }
}

/* A pseudo-terminal in raw mode (bytes pass unchanged): our end in *master, its path in name. */
static int openpty_raw(int *master, int *slave, char *name, size_t cap) {
    int m = posix_openpt(O_RDWR | O_NOCTTY);
    if (m < 0 || grantpt(m) || unlockpt(m) || ptsname_r(m, name, cap)) return -1;
    int s = open(name, O_RDWR | O_NOCTTY); /* held open: the host's close is not a hang-up of ours */
    struct termios tio;
    for (int k = 0; k < 2; ++k) {
        int f = k ? s : m;
        if (tcgetattr(f, &tio) == 0) cfmakeraw(&tio), tcsetattr(f, TCSANOW, &tio);
    }
    fcntl(m, F_SETFL, O_NONBLOCK);
    *master = m, *slave = s;
    return s < 0;
}

int main(int argc, char **argv) {
    double seconds = argc > 1 ? atof(argv[1]) : 2.0, estop_at = argc > 2 ? atof(argv[2]) : -1.0;
    int slave;
    char name[64];
    if (openpty_raw(&fd, &slave, name, sizeof name)) return 2;
    printf("PORT %s\n", name);
    fflush(stdout);
    uint8_t zero = 0;
    (void)!write(fd, &zero, 1); /* flush a half-received frame at the host */
    uint8_t rx[MAX_ENCODED];
    size_t rx_n = 0;
    int overflow = 0;
    double start = 0, next_pose = 0, next_heartbeat = 0, wait_until = now_s() + 30;
    int pressed = 0;
    for (;;) {
        double t = now_s();
        if (!streaming && t > wait_until) break;
        if (start && t - start >= seconds) break;
        int timeout_ms = streaming ? 0 : 10;
        struct pollfd pfd = {.fd = fd, .events = POLLIN};
        if (poll(&pfd, 1, timeout_ms) > 0) {
            if (pfd.revents & (POLLHUP | POLLERR)) break; /* the host hung up */
            uint8_t buf[4096];
            ssize_t k = read(fd, buf, sizeof buf);
            if (k <= 0 && errno != EAGAIN) break;
            t = now_s();
            for (ssize_t i = 0; i < k; ++i) {
                if (buf[i] != 0) {
                    if (rx_n == sizeof rx) overflow = 1, rx_n = 0;
                    if (!overflow) rx[rx_n++] = buf[i];
                    continue;
                }
                if (!overflow && rx_n) on_frame(rx, rx_n, t);
                rx_n = 0, overflow = 0;
            }
        }
        t = now_s();
        if (streaming && !start) start = next_pose = t, next_heartbeat = t + 0.05; /* the first hello came */
        if (ttl_deadline && t > ttl_deadline) { /* the TTL watchdog */
            zero_forces();
            seen.ttl_expiries++;
            if ((t - last_force_at) * 1e3 > seen.max_ttl_gap_ms) seen.max_ttl_gap_ms = (t - last_force_at) * 1e3;
            ttl_deadline = 0;
        }
        if (!streaming) continue;
        if (estop_at >= 0 && !pressed && t - start >= estop_at) { /* the stop button */
            pressed = 1, estop_latched = 1;
            zero_forces();
            uint8_t reason = 1;
            send_frame(0x06, &reason, 1);
        }
        if (t >= next_heartbeat) {
            uint8_t hb[4];
            put32(hb, (uint32_t)(t * 1e6));
            send_frame(0x07, hb, 4);
            seen.heartbeats++;
            next_heartbeat += 0.05;
        }
        if (t >= next_pose) {
            uint8_t p[6 + 12 * FINGERS];
            put32(p, (uint32_t)((t - start) * 1e6));
            p[4] = FINGERS;
            p[5] = (uint8_t)((enabled && !estop_latched) | (estop_latched << 1));
            for (int i = 0; i < FINGERS; ++i) {
                putf(p + 6 + 12 * i, i ? -35.0f : 35.0f); /* mm */
                putf(p + 10 + 12 * i, 0.0f);
                putf(p + 14 + 12 * i, 0.0f);
            }
            send_frame(0x03, p, sizeof p);
            seen.poses++;
            next_pose += 0.001;
            if (next_pose < t - 0.1) next_pose = t;
        }
        struct timespec nap = {0, 200000};
        nanosleep(&nap, NULL);
    }
    printf("REPORT {\"hellos\": %d, \"enables\": %d, \"disables\": %d, \"force_frames\": %d, \"rejected\": %d, "
           "\"estops_received\": %d, \"ttl_expiries\": %d, \"max_ttl_gap_ms\": %.3f, \"forces_while_off\": %d, "
           "\"dropped\": [%d, %d, %d, %d], \"max_norm\": %.6f, \"poses\": %ld, \"heartbeats\": %ld, "
           "\"estop_latched\": %d, \"rendered_at_end\": %.6f}\n",
           seen.hellos, seen.enables, seen.disables, seen.force_frames, seen.rejected, seen.estops_received,
           seen.ttl_expiries, seen.max_ttl_gap_ms, seen.forces_while_off, seen.dropped[0], seen.dropped[1],
           seen.dropped[2], seen.dropped[3], seen.max_norm, seen.poses, seen.heartbeats, estop_latched,
           sqrt(rendered[0][0] * rendered[0][0] + rendered[0][1] * rendered[0][1] + rendered[0][2] * rendered[0][2]));
    close(slave);
    return 0;
}
