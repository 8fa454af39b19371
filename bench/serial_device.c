/* The device side of bench/bench_serial.py, and the bare C echo loop it is compared with.
 *
 *   serial_device device SECONDS RATE FINGERS [udp]   opens a pseudo-terminal, prints "PORT /dev/pts/N"
 *       (udp: a UDP socket on 127.0.0.1, "PORT udp:127.0.0.1:N", connected to the host that says hello),
 *       waits for the host's hello, answers with its capabilities, sends pose frames at RATE Hz
 *       (absolute CLOCK_MONOTONIC deadlines) for SECONDS, and measures for every pose the time
 *       until the force frame acknowledging it arrives. Prints one JSON line.
 *   serial_device echo PORT                      the bare host: a C loop on PORT (raw mode) that
 *       answers the hello and every pose with a zero force frame at once. No runtime, no Python.
 *
 * Both use the core's codec (native/src/device_codec.c), so the two hosts differ only in what
 * happens between a pose arriving and its force frame leaving. */
#define _GNU_SOURCE
#include "devices/device_codec.h"

#include <arpa/inet.h>
#include <errno.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <math.h>
#include <poll.h>
#include <sched.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#define MAX_POSES (1 << 22)
#define LAT_BINS 100000 /* 1 us bins to 100 ms */

static int64_t now_ns(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000000000LL + ts.tv_nsec;
}

static void raw_mode(int fd) {
    struct termios t;
    if (tcgetattr(fd, &t) == 0) {
        cfmakeraw(&t);
        tcsetattr(fd, TCSANOW, &t);
    }
}

static void send_frame(int fd, uint8_t type, uint16_t *seq, const uint8_t *p, size_t n) {
    uint8_t wire[GC_PROTO_WIRE_MAX + 1];
    size_t len = gc_frame_encode(type, (*seq)++, p, n, wire), off = 0;
    while (off < len) {
        ssize_t k = write(fd, wire + off, len - off);
        if (k > 0) off += (size_t)k;
        else if (k < 0 && errno != EAGAIN && errno != EINTR) return;
    }
}

static int echo(const char *port) {
    int fd;
    if (!strncmp(port, "udp:127.0.0.1:", 14)) { /* a connected UDP socket: read and write are datagrams */
        fd = socket(AF_INET, SOCK_DGRAM, 0);
        struct sockaddr_in to = {.sin_family = AF_INET, .sin_port = htons((uint16_t)atoi(port + 14)),
                                 .sin_addr.s_addr = htonl(INADDR_LOOPBACK)};
        struct timeval quiet = {1, 0}; /* no hang-up over UDP: a second of silence ends the echo */
        if (fd < 0 || connect(fd, (struct sockaddr *)&to, sizeof to) ||
            setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &quiet, sizeof quiet)) {
            perror(port);
            return 1;
        }
    } else {
        fd = open(port, O_RDWR | O_NOCTTY);
        if (fd < 0) {
            perror(port);
            return 1;
        }
        raw_mode(fd);
    }
    uint8_t hello[2] = {0, 0}, buf[4096], force[6 + 12 * GC_PROTO_MAX_FINGERS];
    uint16_t seq = 0;
    send_frame(fd, GC_MSG_HELLO_HOST, &seq, hello, 2);
    static gcFrameDecoder dec;
    gcFrame fr;
    for (;;) {
        ssize_t k = read(fd, buf, sizeof buf);
        if (k <= 0) break;
        for (ssize_t i = 0; i < k; ++i) {
            if (!gc_decoder_push(&dec, buf[i], &fr) || fr.type != GC_MSG_POSE) continue;
            int n = fr.payload[4];
            memset(force, 0, sizeof force);
            gc_put16(force, fr.seq);
            gc_put16(force + 2, 20000);
            force[4] = (uint8_t)n;
            send_frame(fd, GC_MSG_FORCE, &seq, force, 6 + 12 * (size_t)n);
        }
    }
    close(fd);
    return 0;
}

static int device(double seconds, double rate, int fingers, int udp) {
    int m, keep = -1;
    if (udp) {
        m = socket(AF_INET, SOCK_DGRAM, 0);
        struct sockaddr_in a = {.sin_family = AF_INET, .sin_addr.s_addr = htonl(INADDR_LOOPBACK)};
        socklen_t len = sizeof a;
        if (m < 0 || bind(m, (struct sockaddr *)&a, sizeof a) || getsockname(m, (struct sockaddr *)&a, &len)) {
            perror("udp");
            return 1;
        }
        printf("PORT udp:127.0.0.1:%d\n", ntohs(a.sin_port));
    } else {
        m = posix_openpt(O_RDWR | O_NOCTTY);
        if (m < 0 || grantpt(m) || unlockpt(m)) {
            perror("posix_openpt");
            return 1;
        }
        raw_mode(m);
        keep = open(ptsname(m), O_RDWR | O_NOCTTY); /* the slave stays open: no hang-up between hosts */
        raw_mode(keep);
        printf("PORT %s\n", ptsname(m));
    }
    fflush(stdout);
    fcntl(m, F_SETFL, O_NONBLOCK);
    static gcFrameDecoder dec;
    gcFrame fr;
    uint8_t buf[8192];
    uint16_t seq = 0;
    int64_t *sent = calloc(65536, sizeof *sent);
    uint32_t *hist = calloc(LAT_BINS, sizeof *hist);
    /* Wait for the hello. */
    int64_t give_up = now_ns() + 30000000000LL;
    int hello = 0;
    while (!hello && now_ns() < give_up) {
        struct pollfd p = {.fd = m, .events = POLLIN};
        if (poll(&p, 1, 10) <= 0) continue;
        struct sockaddr_storage from;
        socklen_t from_len = sizeof from;
        /* recvfrom only on the UDP socket: on a pty master it fails (ENOTSOCK) and no hello comes */
        ssize_t k = udp ? recvfrom(m, buf, sizeof buf, 0, (struct sockaddr *)&from, &from_len) : read(m, buf, sizeof buf);
        for (ssize_t i = 0; i < k; ++i)
            if (gc_decoder_push(&dec, buf[i], &fr) && fr.type == GC_MSG_HELLO_HOST) hello = 1;
        if (hello && udp) connect(m, (struct sockaddr *)&from, from_len); /* that host, only, from now on */
    }
    if (!hello) {
        fprintf(stderr, "no hello\n");
        return 2;
    }
    uint8_t caps[12] = {(uint8_t)fingers, GC_CAP_FORCES, 0, 0};
    gc_put16(caps + 4, (uint16_t)rate);
    gc_putf32(caps + 6, 10.0f);
    gc_put16(caps + 10, 50);
    send_frame(m, GC_MSG_HELLO_DEVICE, &seq, caps, 12);

    int64_t period = (int64_t)(1e9 / rate), start = now_ns() + 200000000LL, end = start + (int64_t)(seconds * 1e9);
    int64_t next = start;
    uint64_t poses = 0, acked = 0, late_acks = 0;
    double max_us = 0;
    uint8_t pose[6 + 12 * GC_PROTO_MAX_FINGERS];
    while (next < end) {
        struct timespec ts = {next / 1000000000LL, next % 1000000000LL};
        clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, NULL);
        /* a pose: two fingers closing on x = +-0.03 (the host's scene grips a box there) */
        memset(pose, 0, sizeof pose);
        gc_put32(pose, (uint32_t)((next - start) / 1000));
        pose[4] = (uint8_t)fingers;
        for (int f = 0; f < fingers; ++f) gc_putf32(pose + 6 + 12 * f, (f & 1) ? -0.03f : 0.03f);
        sent[seq] = now_ns();
        send_frame(m, GC_MSG_POSE, &seq, pose, 6 + 12 * (size_t)fingers);
        poses++;
        next += period;
        /* Read until the next deadline. */
        for (;;) {
            int64_t left = next - now_ns();
            struct pollfd p = {.fd = m, .events = POLLIN};
            struct timespec to = {0, left > 0 ? left : 0};
            if (ppoll(&p, 1, &to, NULL) <= 0) break;
            ssize_t k = read(m, buf, sizeof buf);
            int64_t t = now_ns();
            for (ssize_t i = 0; i < k; ++i) {
                if (!gc_decoder_push(&dec, buf[i], &fr) || fr.type != GC_MSG_FORCE) continue;
                uint16_t ack = gc_le16(fr.payload);
                if (!sent[ack]) continue;
                double us = (double)(t - sent[ack]) / 1e3;
                sent[ack] = 0;
                acked++;
                if (us > 1000.0) late_acks++;
                if (us > max_us) max_us = us;
                int b = (int)us;
                hist[b < LAT_BINS ? b : LAT_BINS - 1]++;
            }
        }
    }
    /* Stragglers. */
    int64_t drain = now_ns() + 100000000LL;
    while (now_ns() < drain) {
        struct pollfd p = {.fd = m, .events = POLLIN};
        if (poll(&p, 1, 10) <= 0) continue;
        ssize_t k = read(m, buf, sizeof buf);
        for (ssize_t i = 0; i < k; ++i)
            if (gc_decoder_push(&dec, buf[i], &fr) && fr.type == GC_MSG_FORCE && sent[gc_le16(fr.payload)]) {
                sent[gc_le16(fr.payload)] = 0;
                acked++;
                late_acks++;
            }
    }
    double q[3] = {0.5, 0.99, 0.999}, v[3] = {0, 0, 0};
    for (int j = 0; j < 3; ++j) {
        uint64_t want = (uint64_t)ceil(q[j] * (double)acked), seen = 0;
        for (int i = 0; i < LAT_BINS; ++i)
            if ((seen += hist[i]) >= want) {
                v[j] = i + 1;
                break;
            }
    }
    uint64_t errors = 0;
    for (int k = 0; k < GC_FRAME_KINDS; ++k) errors += dec.errors[k];
    printf("{\"poses\": %llu, \"acknowledged\": %llu, \"unacknowledged\": %llu, \"late_over_1ms\": %llu, "
           "\"p50_us\": %.0f, \"p99_us\": %.0f, \"p999_us\": %.0f, \"max_us\": %.1f, \"frame_errors\": %llu, "
           "\"hist\": [",
           (unsigned long long)poses, (unsigned long long)acked, (unsigned long long)(poses - acked),
           (unsigned long long)late_acks, v[0], v[1], v[2], max_us, (unsigned long long)errors);
    const char *sep = ""; /* 1 us bins that were hit: [upper bound us, count] */
    for (int i = 0; i < LAT_BINS; ++i)
        if (hist[i]) printf("%s[%d, %u]", sep, i + 1, hist[i]), sep = ", ";
    printf("]}\n");
    if (keep >= 0) close(keep);
    close(m);
    return 0;
}

/* A device is hardware of its own, not a process competing with the host's load: run it
 * real-time when the OS allows (the echo host gets the same priority as graspcore's
 * serial thread, 70). */
static void realtime(int priority) {
    struct sched_param sp = {.sched_priority = priority};
    if (sched_setscheduler(0, SCHED_FIFO, &sp) != 0) fprintf(stderr, "serial_device: SCHED_FIFO refused, normal priority\n");
}

int main(int argc, char **argv) {
    if (argc == 3 && !strcmp(argv[1], "echo")) return realtime(70), echo(argv[2]);
    if ((argc == 5 || (argc == 6 && !strcmp(argv[5], "udp"))) && !strcmp(argv[1], "device"))
        return realtime(90), device(atof(argv[2]), atof(argv[3]), atoi(argv[4]), argc == 6);
    fprintf(stderr, "usage: serial_device device SECONDS RATE FINGERS [udp] | serial_device echo PORT\n");
    return 64;
}
