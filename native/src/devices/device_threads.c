/* Device threads (docs/devices.md): one thread per serial port or UDP socket that owns its
 * descriptor's I/O. It reads bytes, decodes frames (device_codec.c), writes its fingers' HIPs
 * into their slots in the hub (device_hub.c), and answers each pose with a force frame built
 * from the latest haptic tick through the force gate (force_gate.c). It calls nothing of the
 * runtime and no public API: errors are counted in its statistics, never written to the world.
 * Also the API that attaches, commands and reads devices. Nothing here touches Python. */
#define _GNU_SOURCE

#include "device_codec.h"
#include "device_hub.h"
#include "force_gate.h"

#include "graspcore.h"
#include "world/body.h"
#include "base/small_dense.h"

#include <arpa/inet.h>
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <netinet/in.h>
#include <poll.h>
#include <pthread.h>
#include <sched.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <sys/socket.h>
#include <unistd.h>

#define GC_SERIAL_EVENTS 256
#define GC_LATENCY_BINS 10000 /* 1 us bins; the last collects the rest */
#define GC_HELLO_RETRY_NS 100000000LL
#define GC_HEARTBEAT_NS 100000000LL
#define GC_RATE_WINDOW_NS 250000000LL
#define GC_DROP_EVENT_NS 100000000LL
#define GC_ESTOP_STATUS_GRACE_NS 50000000LL /* poses may say "e-stop latched" this long after ENABLE(1) */

typedef struct gcSerialDevice gcSerialDevice;

struct gcSerialDevice {
    gcDeviceHub *hub;
    int id;
    int fd;
    gcSerialDef def;
    double A[9], b[3]; /* device metres -> world: x = A p + b */
    double A_inv[9];   /* forces sent (device axes) back to scene axes: f = A^-T f_dev */
    gcQuat A_rot;      /* the rotation of A (its polar factor): device orientations into the scene */
    int A_mirrors;     /* det A < 0: no rotation maps a device's orientations; positions only */
    pthread_t thread;
    _Atomic int run;
    _Atomic int enable_request, enable_generation, estop_request;
    /* Events: one writer (the thread), one reader (gc_world_serial_events). */
    gcSerialEvent events[GC_SERIAL_EVENTS];
    _Atomic unsigned ev_head, ev_tail;
    /* Statistics: the thread's copy is published under stats_mutex. */
    pthread_mutex_t stats_mutex;
    gcSerialStats published;
};

/* ---- a device thread ---------------------------------------------------------------------- */

typedef struct gcDeviceRun { /* the thread's own state */
    gcSerialDevice *dev;
    gcFrameDecoder dec;
    gcFrame frame;
    gcSerialStats s;
    uint16_t tx_seq, last_rx_seq; /* the device's sequence: +1 a frame of any type */
    int have_rx_seq;
    int host_estop;           /* our ESTOP is latched: said again while the device's poses do not show it */
    int64_t estop_sent_ns;
    int64_t last_pose_ns, last_tx_ns, last_hello_ns, last_publish_ns, last_drop_event_ns;
    gcForceGate gate;        /* enable, e-stop latch, ramp-in (s.enabled mirrors gate.enabled) */
    uint32_t episode;        /* this connection's number in the hub: a new one starts its fingers with a soft start */
    uint64_t drops_reported, foreign_reported;
    /* UDP: where frames go (the configured address, then the pinned device's). */
    int datagram, pinned;
    struct sockaddr_storage peer;
    socklen_t peer_len;
    int enable_generation, stalled;
    int hello_pending;       /* HELLO_HOST sent to a silent device, no HELLO_DEVICE yet: zero forces */
    int64_t enable_sent_ns;  /* when ENABLE(1) was last sent */
    double unit_scale;
    int64_t rate_window_ns;
    uint64_t rate_window_poses;
    uint32_t latency[GC_LATENCY_BINS];
    uint64_t latency_n;
    double latency_max_us;
    double hips[3 * GC_PROTO_MAX_FINGERS];
    double orientations[4 * GC_PROTO_MAX_FINGERS]; /* scene, w x y z: a pose's that carried them */
} gcDeviceRun;

static void emit(gcSerialDevice *d, int code, int value) {
    unsigned head = atomic_load_explicit(&d->ev_head, memory_order_relaxed);
    unsigned tail = atomic_load_explicit(&d->ev_tail, memory_order_acquire);
    if (head - tail >= GC_SERIAL_EVENTS) return; /* full: the reader is away; the counters still say it */
    gcSerialEvent *e = &d->events[head % GC_SERIAL_EVENTS];
    int64_t t = gc_clock_now_ns();
    e->time = (double)t / GC_NS_PER_S;
    e->session_time = gc_device_hub_session_time(d->hub, t);
    e->code = code;
    e->value = value;
    atomic_store_explicit(&d->ev_head, head + 1, memory_order_release);
}

/* 1 when the whole frame was written. */
static int send_frame(gcDeviceRun *r, uint8_t type, const uint8_t *payload, size_t n) {
    uint8_t wire[GC_PROTO_WIRE_MAX + 1];
    size_t len = gc_frame_encode(type, r->tx_seq++, payload, n, wire);
    size_t off = 0;
    if (r->datagram) { /* one frame, one datagram: whole or not at all */
        ssize_t k;
        do k = sendto(r->dev->fd, wire, len, 0, (const struct sockaddr *)&r->peer, r->peer_len);
        while (k < 0 && errno == EINTR);
        if (k != (ssize_t)len) {
            r->s.write_errors++;
            return 0;
        }
        off = len;
    }
    while (off < len) {
        ssize_t k = write(r->dev->fd, wire + off, len - off);
        if (k > 0) {
            off += (size_t)k;
            continue;
        }
        if (k < 0 && errno == EINTR) continue;
        r->s.write_errors++; /* full (EAGAIN) or gone: the frame is lost, the TTL covers it */
        return 0;
    }
    r->last_tx_ns = gc_clock_now_ns();
    return 1;
}

/* The device renders nothing from now on (it was told ENABLE(0) or ESTOP, or stopped itself). */
static void sent_clear(gcDeviceHub *h, int offset, int n) {
    static const double zero[3] = {0, 0, 0};
    for (int i = offset; i < offset + n; ++i) gc_device_hub_sent(h, i, zero, 0);
}

static void send_enable(gcDeviceRun *r, int on) {
    uint8_t p = on ? 1 : 0;
    send_frame(r, GC_MSG_ENABLE, &p, 1);
    if (on) {
        r->host_estop = 0; /* ENABLE(1) clears a latched e-stop, on both sides (the gate's: take_requests) */
        r->enable_sent_ns = gc_clock_now_ns();
    } else {
        sent_clear(r->dev->hub, r->dev->def.finger_offset, r->dev->def.num_fingers);
    }
}

/* Forces off until the next ENABLE(1): an e-stop, the host's (reason 0) or the device's. */
static void latch_estop(gcDeviceRun *r, int reason) {
    int first = gc_force_gate_estop(&r->gate);
    r->s.enabled = 0;
    sent_clear(r->dev->hub, r->dev->def.finger_offset, r->dev->def.num_fingers);
    if (!first) return; /* a repeated ESTOP: one event, one count */
    r->s.estops++;
    emit(r->dev, GC_SERIAL_EV_ESTOP, reason);
}

static double percentile_us(const uint32_t *hist, uint64_t total, double q) {
    if (!total) return 0.0;
    uint64_t want = (uint64_t)ceil(q * (double)total), seen = 0;
    for (int i = 0; i < GC_LATENCY_BINS; ++i)
        if ((seen += hist[i]) >= want) return i + 1.0;
    return GC_LATENCY_BINS;
}

static void publish_stats(gcDeviceRun *r, int64_t t) {
    gcSerialStats *s = &r->s;
    s->dropped = 0;
    for (int k = 0; k < GC_FRAME_RANGE; ++k) s->frame_errors[k] = r->dec.errors[k]; /* range: counted here */
    for (int k = 0; k < GC_FRAME_KINDS; ++k) s->dropped += s->frame_errors[k];
    s->last_pose_age = r->last_pose_ns ? (double)(t - r->last_pose_ns) / GC_NS_PER_S : -1.0;
    s->latency_p50_us = percentile_us(r->latency, r->latency_n, 0.50);
    s->latency_p99_us = percentile_us(r->latency, r->latency_n, 0.99);
    s->latency_max_us = r->latency_max_us;
    pthread_mutex_lock(&r->dev->stats_mutex);
    r->dev->published = *s;
    pthread_mutex_unlock(&r->dev->stats_mutex);
    r->last_publish_ns = t;
}

/* The fingers let go: their HIPs follow their god-objects (zero spring force). */
static void let_go(gcDeviceRun *r) {
    gcSerialDevice *d = r->dev;
    double go[3 * GC_PROTO_MAX_FINGERS];
    if (!gc_device_hub_read(d->hub, d->def.finger_offset, d->def.num_fingers, NULL, go, NULL, NULL)) return;
    gc_device_hub_write_hips(d->hub, d->def.finger_offset, d->def.num_fingers, go, NULL, r->episode);
}

static void lose(gcDeviceRun *r, int state) {
    if (r->s.state == GC_SERIAL_STREAMING) {
        r->s.disconnects++;
        emit(r->dev, GC_SERIAL_EV_LOST, state == GC_SERIAL_HANGUP);
    }
    if (r->s.state != GC_SERIAL_HANGUP) r->s.state = state;
    gc_force_gate_close(&r->gate); /* ramps in again once back */
}

/* The force frame answering pose `ack`: the latest tick's forces of the device's fingers,
 * gated by enable, ramped, clamped, zeroed for a stalled loop, in device axes (f_dev = A^T f). */
static void send_forces(gcDeviceRun *r, uint16_t ack, int64_t t) {
    gcSerialDevice *d = r->dev;
    int n = r->s.device_fingers, m = d->def.num_fingers < n ? d->def.num_fingers : n;
    double f[3 * GC_PROTO_MAX_FINGERS];
    int tick_enabled = 0;
    int64_t tick = gc_device_hub_read(d->hub, d->def.finger_offset, m, f, NULL, NULL, &tick_enabled);
    int stalled = !tick || t - tick > (int64_t)(d->def.stall_timeout * GC_NS_PER_S);
    if (stalled != r->stalled) {
        if (stalled) r->s.stall_zeroes++;
        emit(d, GC_SERIAL_EV_STALL, stalled);
        r->stalled = stalled;
    }
    int ready = r->s.renders_forces && !stalled && tick_enabled && !r->hello_pending;
    double gain = gc_force_gate_gain(&r->gate, ready, t);
    r->s.gain = gain;
    const double *A = d->A;
    for (int i = 0; i < m; ++i) { /* in device axes, f_dev = A^T f, then through the one gate */
        const double fw[3] = {f[3 * i], f[3 * i + 1], f[3 * i + 2]};
        for (int c = 0; c < 3; ++c) f[3 * i + c] = A[c] * fw[0] + A[3 + c] * fw[1] + A[6 + c] * fw[2];
    }
    gc_force_gate_apply(gain, fmin(d->def.max_force, r->s.device_force_max), f, f, m);
    uint8_t p[6 + 12 * GC_PROTO_MAX_FINGERS];
    gc_put16(p, ack);
    gc_put16(p + 2, gc_force_gate_ttl_us(d->def.force_ttl, r->s.device_ttl_max));
    p[4] = (uint8_t)n;
    p[5] = r->s.sends_orientations ? GC_FORCE_TAKES_ORIENTATION : 0; /* the device may send them from now on */
    double sent[3 * GC_PROTO_MAX_FINGERS]; /* what the frame carries, back in scene axes */
    for (int i = 0; i < n; ++i) {
        uint8_t *values = p + 6 + 12 * i;
        for (int c = 0; c < 3; ++c) gc_putf32(values + 4 * c, i < m ? (float)f[3 * i + c] : 0.0f);
        if (i >= m) continue;
        /* Read back from the frame's bytes: the values the device gets. ((double)(float)x kept
         * in a double array was not: GCC 12.2's SLP vectorizer dropped one of the roundings.) */
        const double v[3] = {gc_lef32(values), gc_lef32(values + 4), gc_lef32(values + 8)};
        for (int c = 0; c < 3; ++c) /* f = A^-T f_dev */
            sent[3 * i + c] = d->A_inv[c] * v[0] + d->A_inv[3 + c] * v[1] + d->A_inv[6 + c] * v[2];
    }
    if (!send_frame(r, GC_MSG_FORCE, p, 6 + 12 * (size_t)n)) return; /* not sent: the last frame's TTL runs on */
    r->s.forces_sent++;
    int64_t until = r->last_tx_ns + (int64_t)gc_le16(p + 2) * 1000;
    for (int i = 0; i < m; ++i) gc_device_hub_sent(d->hub, d->def.finger_offset + i, &sent[3 * i], until);
}

static void on_hello(gcDeviceRun *r, const gcFrame *fr) {
    const uint8_t *p = fr->payload;
    int n = p[0], units = p[2];
    float fmax = gc_lef32(p + 6);
    if (n < 1 || n > GC_PROTO_MAX_FINGERS || units > 1 || !isfinite(fmax) || fmax < 0) {
        r->s.frame_errors[GC_FRAME_RANGE]++;
        return;
    }
    gcSerialStats *s = &r->s;
    s->device_fingers = n;
    s->renders_forces = (p[1] & GC_CAP_FORCES) != 0;
    s->sends_orientations = (p[1] & GC_CAP_ORIENTATION) && !r->dev->A_mirrors; /* said in every FORCE */
    s->units = units;
    s->device_rate = gc_le16(p + 4);
    s->device_force_max = fmax;
    s->device_ttl_max = gc_le16(p + 10) * 1e-3;
    size_t name_len = fr->len - 12;
    memcpy(s->name, p + 12, name_len);
    s->name[name_len] = 0;
    r->unit_scale = units == 1 ? 1e-3 : 1.0;
    if (s->state != GC_SERIAL_STREAMING) {
        emit(r->dev, GC_SERIAL_EV_CONNECTED, n);
        r->episode = atomic_fetch_add_explicit(&r->dev->hub->connections, 1, memory_order_relaxed) + 1;
    }
    s->state = GC_SERIAL_STREAMING;
    r->have_rx_seq = 0; /* a restarted device may start its sequence anywhere */
    r->last_pose_ns = 0;
    send_enable(r, s->enabled);
    r->hello_pending = 0;
}

static void on_pose(gcDeviceRun *r, const gcFrame *fr, int64_t t_read) {
    gcSerialDevice *d = r->dev;
    gcSerialStats *s = &r->s;
    const uint8_t *p = fr->payload;
    int n = p[4];
    if (!s->device_fingers) return; /* poses before the hello: not ours to read yet */
    int m = d->def.num_fingers < n ? d->def.num_fingers : n;
    const int oriented = gc_pose_has_orientations(fr);
    if (oriented && !s->sends_orientations) { /* not what its hello (or our FORCE frames) allowed */
        r->dec.errors[GC_FRAME_LENGTH]++;
        return;
    }
    int ok = n == s->device_fingers;
    for (int i = 0; i < m && ok && oriented; ++i) { /* unit, turned into the scene by A's rotation */
        const uint8_t *o = p + 6 + GC_PROTO_POSE_FINGER * n + 16 * i;
        const double q[4] = {gc_lef32(o), gc_lef32(o + 4), gc_lef32(o + 8), gc_lef32(o + 12)};
        ok = gc_device_quat_usable(q);
        gcQuat w = gc_quat_mul(d->A_rot, (gcQuat){q[0], q[1], q[2], q[3]});
        r->orientations[4 * i] = w.w, r->orientations[4 * i + 1] = w.x;
        r->orientations[4 * i + 2] = w.y, r->orientations[4 * i + 3] = w.z;
    }
    for (int i = 0; i < m && ok; ++i) {
        double x[3];
        for (int c = 0; c < 3; ++c) {
            x[c] = r->unit_scale * gc_lef32(p + 6 + 12 * i + 4 * c);
            ok &= isfinite(x[c]) && fabs(x[c]) <= d->def.max_position;
        }
        for (int c = 0; c < 3 && ok; ++c)
            r->hips[3 * i + c] = d->A[3 * c] * x[0] + d->A[3 * c + 1] * x[1] + d->A[3 * c + 2] * x[2] + d->b[c];
    }
    if (!ok) {
        s->frame_errors[GC_FRAME_RANGE]++;
        return;
    }
    if (s->state == GC_SERIAL_LOST) {
        emit(d, GC_SERIAL_EV_RECOVERED, 0);
        s->state = GC_SERIAL_STREAMING;
        /* Its fingers were let go meanwhile: a new episode, a soft start back to the device. */
        r->episode = atomic_fetch_add_explicit(&d->hub->connections, 1, memory_order_relaxed) + 1;
    }
    /* A pose saying "e-stop latched" that we have not latched: its ESTOP frame was lost on the
     * way, or sent before this connection. Forces on or off, it is an e-stop, counted and
     * recorded (else the ENABLE(1) that turns forces on would clear it unseen); a device that
     * has not yet taken up our ENABLE(1) may still say so for a moment. */
    if ((p[5] & GC_STATUS_ESTOPPED) && !r->gate.estop && t_read - r->enable_sent_ns > GC_ESTOP_STATUS_GRACE_NS)
        latch_estop(r, GC_ESTOP_REASON_STATUS);
    /* Ours, not shown latched in its poses: our ESTOP may have been lost; say it again. */
    if (r->host_estop && !(p[5] & GC_STATUS_ESTOPPED) && t_read - r->estop_sent_ns > GC_HELLO_RETRY_NS) {
        uint8_t reason = 0;
        send_frame(r, GC_MSG_ESTOP, &reason, 1);
        r->estop_sent_ns = t_read;
    }
    r->last_pose_ns = t_read;
    s->poses++;
    s->oriented_poses += (uint64_t)oriented;
    r->rate_window_poses++;
    gc_device_hub_write_hips(d->hub, d->def.finger_offset, m, r->hips, oriented ? r->orientations : NULL, r->episode);
    send_forces(r, fr->seq, t_read);
    double us = (double)(gc_clock_now_ns() - t_read) / 1e3;
    int bin = (int)us;
    r->latency[bin < GC_LATENCY_BINS ? bin : GC_LATENCY_BINS - 1]++;
    r->latency_n++;
    if (us > r->latency_max_us) r->latency_max_us = us;
}

static void on_frame(gcDeviceRun *r, const gcFrame *fr, int64_t t) {
    /* Frames of the device's sequence that never arrived (any type: its seq counts them all). */
    if (fr->type == GC_MSG_HELLO_DEVICE) r->have_rx_seq = 0;
    int16_t ahead = (int16_t)(fr->seq - r->last_rx_seq);
    if (r->datagram && r->have_rx_seq && ahead <= 0) {
        /* UDP delivered it late or twice: a pose would move the HIPs back in time (dropped);
         * an ESTOP still stops, whenever it comes. */
        if (fr->type == GC_MSG_POSE) {
            if (ahead == 0) r->s.duplicate_poses++;
            else r->s.late_poses++;
            return;
        }
        if (fr->type == GC_MSG_ESTOP) latch_estop(r, fr->payload[0]);
        return;
    }
    if (r->have_rx_seq) r->s.sequence_gaps += (uint16_t)(fr->seq - r->last_rx_seq - 1);
    r->last_rx_seq = fr->seq;
    r->have_rx_seq = 1;
    switch (fr->type) {
    case GC_MSG_HELLO_DEVICE: on_hello(r, fr); break;
    case GC_MSG_POSE: on_pose(r, fr, t); break;
    case GC_MSG_ESTOP: latch_estop(r, fr->payload[0]); break;
    case GC_MSG_HEARTBEAT: r->s.heartbeats++; break;
    default: break; /* host-bound types only */
    }
}

/* Requests from the API: enable changes and host e-stops. */
static void take_requests(gcDeviceRun *r) {
    gcSerialDevice *d = r->dev;
    if (atomic_exchange_explicit(&d->estop_request, 0, memory_order_acq_rel)) {
        uint8_t reason = 0;
        send_frame(r, GC_MSG_ESTOP, &reason, 1);
        r->gate.estop = 0; /* the host's own e-stop is always an event */
        latch_estop(r, 0);
        r->host_estop = 1;
        r->estop_sent_ns = gc_clock_now_ns();
    }
    int gen = atomic_load_explicit(&d->enable_generation, memory_order_acquire);
    if (gen != r->enable_generation) {
        r->enable_generation = gen;
        int on = atomic_load_explicit(&d->enable_request, memory_order_relaxed);
        gc_force_gate_enable(&r->gate, on);
        r->s.enabled = on;
        send_enable(r, on);
        emit(d, GC_SERIAL_EV_ENABLED, on);
    }
}

static int same_address(const struct sockaddr_storage *a, socklen_t a_len, const struct sockaddr_storage *b,
                        socklen_t b_len) {
    if (a_len != b_len || a->ss_family != b->ss_family) return 0;
    if (a->ss_family == AF_INET) {
        const struct sockaddr_in *x = (const void *)a, *y = (const void *)b;
        return x->sin_port == y->sin_port && x->sin_addr.s_addr == y->sin_addr.s_addr;
    }
    const struct sockaddr_in6 *x = (const void *)a, *y = (const void *)b;
    return x->sin6_port == y->sin6_port && !memcmp(&x->sin6_addr, &y->sin6_addr, sizeof x->sin6_addr);
}

/* UDP: every waiting datagram, one frame each. Before the hello only a HELLO_DEVICE is taken
 * (it pins the session to its sender); after it, only the pinned sender's datagrams. */
static void read_datagrams(gcDeviceRun *r, uint8_t *buf, size_t cap, int64_t t) {
    for (int budget = 0; budget < 64; ++budget) { /* capped: requests and timers run in between */
        struct sockaddr_storage from;
        socklen_t from_len = sizeof from;
        ssize_t k = recvfrom(r->dev->fd, buf, cap, MSG_DONTWAIT, (struct sockaddr *)&from, &from_len);
        if (k < 0) return; /* EAGAIN: no more (an ICMP error from an earlier send: ignored) */
        if (r->pinned && !same_address(&from, from_len, &r->peer, r->peer_len)) {
            r->s.foreign_datagrams++;
            continue;
        }
        size_t n = (size_t)k;
        if ((n == 0 || buf[n - 1] != 0) && n < cap) buf[n++] = 0; /* a datagram is one frame: it ends here */
        for (size_t i = 0; i < n; ++i) {
            if (!gc_decoder_push(&r->dec, buf[i], &r->frame)) continue;
            if (!r->pinned && r->frame.type != GC_MSG_HELLO_DEVICE) {
                r->s.foreign_datagrams++; /* not the hello: nobody is the device yet */
                continue;
            }
            if (!r->pinned) {
                r->peer = from, r->peer_len = from_len, r->pinned = 1;
                char host[INET6_ADDRSTRLEN] = "";
                int port = 0;
                if (from.ss_family == AF_INET) {
                    const struct sockaddr_in *a = (const void *)&from;
                    inet_ntop(AF_INET, &a->sin_addr, host, sizeof host);
                    port = ntohs(a->sin_port);
                } else {
                    const struct sockaddr_in6 *a = (const void *)&from;
                    inet_ntop(AF_INET6, &a->sin6_addr, host, sizeof host);
                    port = ntohs(a->sin6_port);
                }
                snprintf(r->s.peer, sizeof r->s.peer, "%s:%d", host, port);
            }
            on_frame(r, &r->frame, t);
        }
    }
}

static void *device_main(void *arg) {
    gcDeviceRun *r = arg;
    gcSerialDevice *d = r->dev;
    pthread_setname_np(pthread_self(), "gc-serial");
    /* A peer that hangs up must not kill the host process: writing to it raises SIGPIPE, whose
     * default action ends the process (Python ignores it; a C host or an embedding may not).
     * Blocked in this thread, the write fails with EPIPE and the hang-up is handled as such. */
    sigset_t pipe_signal;
    sigemptyset(&pipe_signal);
    sigaddset(&pipe_signal, SIGPIPE);
    pthread_sigmask(SIG_BLOCK, &pipe_signal, NULL);
    if (d->def.priority > 0) { /* as the haptic loop: real-time when the OS allows it */
        struct sched_param sp = {.sched_priority = d->def.priority};
        r->s.rt_priority = pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp) == 0;
    }
    uint8_t hello[2];
    gc_put16(hello, 0);
    send_frame(r, GC_MSG_HELLO_HOST, hello, 2);
    r->last_hello_ns = r->rate_window_ns = gc_clock_now_ns();
    uint8_t buf[4096];
    while (atomic_load_explicit(&d->run, memory_order_acquire)) {
        take_requests(r);
        struct pollfd pfd = {.fd = d->fd, .events = POLLIN};
        int pr = poll(&pfd, 1, 1);
        int64_t t = gc_clock_now_ns();
        if (r->datagram) {
            if (pr > 0) read_datagrams(r, buf, sizeof buf, t); /* no hang-up: silence is a loss */
        } else if (pr > 0 && (pfd.revents & POLLIN)) {
            ssize_t k = read(d->fd, buf, sizeof buf);
            if (k > 0) {
                for (ssize_t i = 0; i < k; ++i)
                    if (gc_decoder_push(&r->dec, buf[i], &r->frame)) on_frame(r, &r->frame, t);
            } else if (k == 0 || (errno != EAGAIN && errno != EINTR)) {
                lose(r, GC_SERIAL_HANGUP);
            }
        } else if (pr > 0 && (pfd.revents & (POLLHUP | POLLERR | POLLNVAL))) {
            lose(r, GC_SERIAL_HANGUP);
        }
        if (r->s.state == GC_SERIAL_HANGUP) {
            let_go(r);
            struct timespec pause = {0, 2000000}; /* a hung-up descriptor polls ready at once */
            nanosleep(&pause, NULL);
        } else if (r->s.state == GC_SERIAL_STREAMING && r->last_pose_ns &&
                   t - r->last_pose_ns > (int64_t)(d->def.lost_timeout * GC_NS_PER_S)) {
            lose(r, GC_SERIAL_LOST);
        }
        if (r->s.state == GC_SERIAL_LOST) let_go(r);
        /* No capabilities yet, or silent: hello every 100 ms (a device that restarted answers it). */
        if ((r->s.state == GC_SERIAL_WAITING || r->s.state == GC_SERIAL_LOST) && t - r->last_hello_ns > GC_HELLO_RETRY_NS) {
            send_frame(r, GC_MSG_HELLO_HOST, hello, 2);
            r->hello_pending = 1; /* a device that takes it turns forces off: none until its hello */
            r->last_hello_ns = t;
        }
        if (r->s.state != GC_SERIAL_HANGUP && t - r->last_tx_ns > GC_HEARTBEAT_NS) {
            uint8_t hb[4];
            gc_put32(hb, (uint32_t)(t / 1000));
            send_frame(r, GC_MSG_HEARTBEAT, hb, 4);
        }
        if (r->s.foreign_datagrams != r->foreign_reported && t - r->last_drop_event_ns > GC_DROP_EVENT_NS) {
            emit(d, GC_SERIAL_EV_FOREIGN, (int)(r->s.foreign_datagrams - r->foreign_reported));
            r->foreign_reported = r->s.foreign_datagrams;
        }
        uint64_t drops = r->s.dropped;
        if (drops != r->drops_reported && t - r->last_drop_event_ns > GC_DROP_EVENT_NS) {
            emit(d, GC_SERIAL_EV_DROPPED, (int)(drops - r->drops_reported));
            r->drops_reported = drops;
            r->last_drop_event_ns = t;
        }
        if (t - r->rate_window_ns >= GC_RATE_WINDOW_NS) {
            r->s.pose_rate = (double)r->rate_window_poses * GC_NS_PER_S / (double)(t - r->rate_window_ns);
            r->rate_window_poses = 0;
            r->rate_window_ns = t;
        }
        if (t - r->last_publish_ns > 10000000LL) publish_stats(r, t);
    }
    publish_stats(r, gc_clock_now_ns());
    free(r);
    return NULL;
}

/* ---- API ----------------------------------------------------------------------------- */

gcSerialDef gc_default_serial_def(void) {
    gcSerialDef d;
    memset(&d, 0, sizeof d);
    d.num_fingers = 1;
    for (int i = 0; i < 4; ++i) d.transform[5 * i] = 1.0;
    d.force_ttl = 0.02;
    d.lost_timeout = 0.1;
    d.max_force = 10.0;
    d.ramp_time = 0.5;
    d.max_position = 10.0;
    d.stall_timeout = 0.005;
    d.priority = 70;
    return d;
}

static gcSerialDevice *device_of(gcWorld *w, int32_t id) {
    gcDeviceHub *h = w ? w->hub : NULL;
    if (!h || id < 0 || id >= GC_MAX_DEVICES) return NULL;
    return h->devices[id];
}

/* The determinant of the upper-left 3x3 of a row-major 4x4. */
static double det3(const double *m) {
    return m[0] * (m[5] * m[10] - m[6] * m[9]) - m[1] * (m[4] * m[10] - m[6] * m[8]) + m[2] * (m[4] * m[9] - m[5] * m[8]);
}

/* The rotation of a non-singular A (row-major 3x3, det > 0): its polar factor, the rotation
 * nearest to it (A itself when A is one; A / s for a uniform scale s), by the iteration
 * R <- (R + R^-T) / 2 (quadratic convergence; capped). */
static gcQuat rotation_of(const double *A) {
    gcMat3 R;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) R.m[i][j] = A[3 * i + j];
    for (int it = 0; it < 64; ++it) {
        gcMat3 inv, next;
        if (!gc_invert_mat3(&R, &inv)) break;
        double change = 0.0;
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) {
                next.m[i][j] = 0.5 * (R.m[i][j] + inv.m[j][i]);
                change = fmax(change, fabs(next.m[i][j] - R.m[i][j]));
            }
        R = next;
        if (change < 1e-15) break;
    }
    return gc_mat3_to_quat(&R);
}

static const char *check_serial_def(const gcWorld *w, int fd, const gcSerialDef *d) {
    if (fd < 0 || fcntl(fd, F_GETFD) == -1) return "fd: must be an open file descriptor";
    if (d->num_fingers < 1 || d->num_fingers > GC_PROTO_MAX_FINGERS) return "num_fingers: must be 1..32";
    if (d->finger_offset < 0 || d->finger_offset + d->num_fingers > w->num_fingers)
        return "finger_offset, num_fingers: the device's fingers must be fingers of the world";
    for (int i = 0; i < 16; ++i)
        if (!isfinite(d->transform[i])) return "transform: must be finite";
    if (d->transform[12] != 0 || d->transform[13] != 0 || d->transform[14] != 0 || d->transform[15] != 1)
        return "transform: the last row must be (0, 0, 0, 1)";
    if (!(fabs(det3(d->transform)) > 1e-12)) return "transform: singular (a workspace frame must keep three dimensions)";
    if (!(d->force_ttl > 0 && d->force_ttl <= 0.065)) return "force_ttl: must be in (0, 0.065] s";
    if (!(d->lost_timeout > 0 && isfinite(d->lost_timeout))) return "lost_timeout: must be a finite number > 0";
    if (!(d->max_force >= 0 && isfinite(d->max_force))) return "max_force: must be a finite number >= 0";
    if (!(d->ramp_time >= 0 && isfinite(d->ramp_time))) return "ramp_time: must be a finite number >= 0";
    if (!(d->max_position > 0)) return "max_position: must be > 0";
    if (!(d->stall_timeout > 0 && isfinite(d->stall_timeout))) return "stall_timeout: must be a finite number > 0";
    if (d->priority < 0 || d->priority > 99) return "priority: must be 0..99";
    if (d->udp_port < 0 || d->udp_port > 65535) return "udp_port: must be 1..65535 (0: a byte stream)";
    if (d->udp_port && !memchr(d->udp_host, 0, sizeof d->udp_host)) return "udp_host: longer than 63 bytes";
    if (d->udp_port) {
        struct in6_addr a6;
        struct in_addr a4;
        if (inet_pton(AF_INET, d->udp_host, &a4) != 1 && inet_pton(AF_INET6, d->udp_host, &a6) != 1)
            return "udp_host: not a numeric IPv4 or IPv6 address";
    }
    return NULL;
}

gcStatus gc_world_attach_serial(gcWorld *w, int fd, const gcSerialDef *def, int32_t *out_device) {
    if (!w || !def || !out_device) return GC_ERR_INVALID_ARGUMENT;
    gcDeviceHub *h = w->hub;
    if (!h) return GC_ERR_NO_MEMORY;
    const char *bad = check_serial_def(w, fd, def);
    if (bad) {
        gc_world_set_error(w, "%s", bad);
        return GC_ERR_INVALID_ARGUMENT;
    }
    pthread_mutex_lock(&h->api_mutex);
    int id = -1;
    for (int i = 0; i < GC_MAX_DEVICES && id < 0; ++i)
        if (!h->devices[i]) id = i;
    for (int i = 0; i < GC_MAX_DEVICES; ++i) {
        const gcSerialDevice *o = h->devices[i];
        if (o && def->finger_offset < o->def.finger_offset + o->def.num_fingers &&
            o->def.finger_offset < def->finger_offset + def->num_fingers) {
            pthread_mutex_unlock(&h->api_mutex);
            gc_world_set_error(w, "finger_offset: fingers %d..%d are already driven by device %d", def->finger_offset,
                               def->finger_offset + def->num_fingers - 1, i);
            return GC_ERR_INVALID_ARGUMENT;
        }
    }
    if (id >= 0 && !gc_device_hub_claim(h, def->finger_offset, def->num_fingers, id)) {
        pthread_mutex_unlock(&h->api_mutex);
        gc_world_set_error(w, "finger_offset: fingers %d..%d: a device read elsewhere drives some of them "
                              "(push_device_hips)", def->finger_offset, def->finger_offset + def->num_fingers - 1);
        return GC_ERR_INVALID_ARGUMENT;
    }
    if (id < 0) {
        pthread_mutex_unlock(&h->api_mutex);
        gc_world_set_error(w, "attach_serial: at most %d devices", GC_MAX_DEVICES);
        return GC_ERR_CAPACITY;
    }
    gcSerialDevice *d = calloc(1, sizeof *d);
    gcDeviceRun *r = calloc(1, sizeof *r);
    if (!d || !r) {
        free(d);
        free(r);
        pthread_mutex_unlock(&h->api_mutex);
        return GC_ERR_NO_MEMORY;
    }
    d->hub = h;
    d->id = id;
    d->fd = fd;
    d->def = *def;
    for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) d->A[3 * i + j] = def->transform[4 * i + j];
        d->b[i] = def->transform[4 * i + 3];
    }
    const double *A = d->A, inv_det = 1.0 / det3(def->transform); /* checked non-zero */
    for (int i = 0; i < 3; ++i) /* the inverse as the transposed cofactor matrix */
        for (int j = 0; j < 3; ++j) {
            int i1 = (j + 1) % 3, i2 = (j + 2) % 3, j1 = (i + 1) % 3, j2 = (i + 2) % 3;
            d->A_inv[3 * i + j] = (A[3 * i1 + j1] * A[3 * i2 + j2] - A[3 * i1 + j2] * A[3 * i2 + j1]) * inv_det;
        }
    d->A_mirrors = inv_det < 0;
    d->A_rot = d->A_mirrors ? (gcQuat){1, 0, 0, 0} : rotation_of(A);
    pthread_mutex_init(&d->stats_mutex, NULL);
    atomic_store(&d->run, 1);
    r->dev = d;
    gc_force_gate_init(&r->gate, gc_seconds_to_ns(def->ramp_time), 0);
    r->unit_scale = 1.0;
    if (def->udp_port) { /* frames go there until a HELLO_DEVICE pins the session to its sender */
        r->datagram = 1;
        struct sockaddr_in *a4 = (void *)&r->peer;
        struct sockaddr_in6 *a6 = (void *)&r->peer;
        if (inet_pton(AF_INET, def->udp_host, &a4->sin_addr) == 1) {
            a4->sin_family = AF_INET, a4->sin_port = htons((uint16_t)def->udp_port);
            r->peer_len = sizeof *a4;
        } else {
            inet_pton(AF_INET6, def->udp_host, &a6->sin6_addr);
            a6->sin6_family = AF_INET6, a6->sin6_port = htons((uint16_t)def->udp_port);
            r->peer_len = sizeof *a6;
        }
    }
    gc_decoder_reset(&r->dec);
    sent_clear(h, def->finger_offset, def->num_fingers); /* recorded: nothing sent yet */
    if (pthread_create(&d->thread, NULL, device_main, r)) {
        gc_device_hub_release(h, def->finger_offset, def->num_fingers, id);
        pthread_mutex_destroy(&d->stats_mutex);
        free(d);
        free(r);
        pthread_mutex_unlock(&h->api_mutex);
        gc_world_set_error(w, "attach_serial: cannot start the device thread");
        return GC_ERR_NO_MEMORY;
    }
    h->devices[id] = d;
    pthread_mutex_unlock(&h->api_mutex);
    *out_device = id;
    return GC_OK;
}

static void device_stop(gcSerialDevice *d) {
    atomic_store_explicit(&d->run, 0, memory_order_release);
    pthread_join(d->thread, NULL);
    gc_device_hub_release(d->hub, d->def.finger_offset, d->def.num_fingers, d->id);
    pthread_mutex_destroy(&d->stats_mutex);
    free(d);
}

gcStatus gc_world_detach_serial(gcWorld *w, int32_t id) {
    gcSerialDevice *d = device_of(w, id);
    if (!d) return GC_ERR_UNKNOWN_ID;
    pthread_mutex_lock(&w->hub->api_mutex);
    w->hub->devices[id] = NULL;
    pthread_mutex_unlock(&w->hub->api_mutex);
    device_stop(d);
    return GC_OK;
}

void gc_device_threads_stop_all(gcDeviceHub *h) {
    if (!h) return;
    for (int i = 0; i < GC_MAX_DEVICES; ++i) {
        if (h->devices[i]) device_stop(h->devices[i]);
        h->devices[i] = NULL;
    }
}

gcStatus gc_world_serial_enable(gcWorld *w, int32_t id, int enable) {
    gcSerialDevice *d = device_of(w, id);
    if (!d) return GC_ERR_UNKNOWN_ID;
    atomic_store_explicit(&d->enable_request, enable != 0, memory_order_relaxed);
    atomic_fetch_add_explicit(&d->enable_generation, 1, memory_order_release);
    return GC_OK;
}

gcStatus gc_world_serial_estop(gcWorld *w, int32_t id) {
    gcSerialDevice *d = device_of(w, id);
    if (!d) return GC_ERR_UNKNOWN_ID;
    atomic_store_explicit(&d->estop_request, 1, memory_order_release);
    return GC_OK;
}

gcStatus gc_world_serial_stats(gcWorld *w, int32_t id, gcSerialStats *out) {
    gcSerialDevice *d = device_of(w, id);
    if (!d || !out) return d ? GC_ERR_INVALID_ARGUMENT : GC_ERR_UNKNOWN_ID;
    pthread_mutex_lock(&d->stats_mutex);
    *out = d->published;
    pthread_mutex_unlock(&d->stats_mutex);
    return GC_OK;
}

int gc_world_serial_events(gcWorld *w, int32_t id, gcSerialEvent *out, int capacity) {
    gcSerialDevice *d = device_of(w, id);
    if (!d || !out) return 0;
    unsigned tail = atomic_load_explicit(&d->ev_tail, memory_order_relaxed);
    unsigned head = atomic_load_explicit(&d->ev_head, memory_order_acquire);
    int n = 0;
    while (tail != head && n < capacity) out[n++] = d->events[tail++ % GC_SERIAL_EVENTS];
    atomic_store_explicit(&d->ev_tail, tail, memory_order_release);
    return n;
}
