/* Serial haptic devices: the Grasp Lab protocol codec (docs/protocol.md) and one thread per
 * device that owns its file descriptor's I/O (docs/devices.md).
 *
 * The haptic loop publishes every tick's device forces, god-objects and HIPs into the hub
 * (gc_serial_hub_tick, a sequence lock: one writer, any number of readers, never waiting on
 * them). A device thread reads bytes, decodes frames, turns poses into HIPs of its fingers
 * in the hub's merged HIP array and pushes that array into the runtime, then answers with a
 * force frame built from the latest published tick. Nothing here touches Python. */
#define _GNU_SOURCE

#include "serial_io.h"

#include "graspcore.h"
#include "body.h"
#include "gc_math.h"
#include "runtime.h"

#include <arpa/inet.h>
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <netinet/in.h>
#include <poll.h>
#include <pthread.h>
#include <sched.h>
#include <signal.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#define GC_MAX_SERIAL_DEVICES 8
#define GC_SERIAL_EVENTS 256
#define GC_LATENCY_BINS 10000 /* 1 us bins; the last collects the rest */
#define GC_HELLO_RETRY_NS 100000000LL
#define GC_HEARTBEAT_NS 100000000LL
#define GC_RATE_WINDOW_NS 250000000LL
#define GC_DROP_EVENT_NS 100000000LL
#define GC_ESTOP_STATUS_GRACE_NS 50000000LL /* poses may say "e-stop latched" this long after ENABLE(1) */
#define NS 1000000000LL

/* ---- codec ---------------------------------------------------------------------------- */

uint16_t gc_crc16(const uint8_t *data, size_t n) {
    uint16_t crc = 0xFFFF;
    for (size_t i = 0; i < n; ++i) {
        crc ^= (uint16_t)(data[i] << 8);
        for (int b = 0; b < 8; ++b) crc = (crc & 0x8000) ? (uint16_t)((crc << 1) ^ 0x1021) : (uint16_t)(crc << 1);
    }
    return crc;
}

size_t gc_cobs_encode(const uint8_t *in, size_t n, uint8_t *out) {
    size_t code_at = 0, o = 1;
    uint8_t code = 1;
    int full = 0; /* the input so far ends with a full 254-byte block: no final block */
    for (size_t i = 0; i < n; ++i) {
        full = 0;
        if (in[i] == 0) {
            out[code_at] = code;
            code_at = o++;
            code = 1;
            continue;
        }
        out[o++] = in[i];
        if (++code == 0xFF) {
            out[code_at] = code;
            code_at = o++;
            code = 1;
            full = 1;
        }
    }
    if (full) return o - 1;
    out[code_at] = code;
    return o;
}

int gc_cobs_decode(const uint8_t *in, size_t n, uint8_t *out, size_t cap, size_t *out_n) {
    size_t i = 0, o = 0;
    while (i < n) {
        uint8_t code = in[i];
        if (code == 0 || i + code > n) return -1;
        for (size_t k = i + 1; k < i + code; ++k) {
            if (in[k] == 0 || o == cap) return -1;
            out[o++] = in[k];
        }
        i += code;
        if (code != 0xFF && i < n) {
            if (o == cap) return -1;
            out[o++] = 0;
        }
    }
    *out_n = o;
    return 0;
}

size_t gc_frame_encode(uint8_t type, uint16_t seq, const uint8_t *payload, size_t n, uint8_t *out) {
    uint8_t body[GC_PROTO_BODY_MAX];
    if (GC_PROTO_HEADER + n + 2 > sizeof body) return 0;
    body[0] = GC_PROTO_VERSION;
    body[1] = type;
    gc_put16(body + 2, seq);
    if (n) memcpy(body + GC_PROTO_HEADER, payload, n);
    size_t len = GC_PROTO_HEADER + n;
    gc_put16(body + len, gc_crc16(body, len));
    len += 2;
    size_t w = gc_cobs_encode(body, len, out);
    out[w] = 0;
    return w + 1;
}

/* Payload length the type requires (pose and force: by the finger count they carry). */
static int payload_length_ok(uint8_t type, const uint8_t *p, size_t n) {
    switch (type) {
    case GC_MSG_HELLO_HOST: return n == 2;
    case GC_MSG_HELLO_DEVICE: return n >= 12 && n <= 12 + GC_PROTO_NAME_MAX;
    case GC_MSG_POSE:
    case GC_MSG_FORCE: return n >= 6 && (size_t)p[4] * 12 == n - 6;
    case GC_MSG_ENABLE:
    case GC_MSG_ESTOP: return n == 1;
    case GC_MSG_HEARTBEAT: return n == 4;
    default: return 0;
    }
}

gcFrameError gc_frame_decode(const uint8_t *wire, size_t n, gcFrame *out) {
    uint8_t body[GC_PROTO_BODY_MAX];
    size_t len;
    if (n > GC_PROTO_WIRE_MAX) return GC_FRAME_LENGTH;
    if (gc_cobs_decode(wire, n, body, sizeof body, &len)) {
        /* A well-formed encoding that is merely too long for any frame is a length error. */
        return GC_FRAME_COBS;
    }
    if (len < GC_PROTO_HEADER + 2) return GC_FRAME_SHORT;
    if (gc_crc16(body, len - 2) != gc_le16(body + len - 2)) return GC_FRAME_CRC;
    if (body[0] != GC_PROTO_VERSION) return GC_FRAME_VERSION;
    uint8_t type = body[1];
    if (type < GC_MSG_HELLO_HOST || type > GC_MSG_HEARTBEAT) return GC_FRAME_TYPE;
    size_t plen = len - GC_PROTO_HEADER - 2;
    if (!payload_length_ok(type, body + GC_PROTO_HEADER, plen)) return GC_FRAME_LENGTH;
    out->type = type;
    out->seq = gc_le16(body + 2);
    out->len = plen;
    memcpy(out->payload, body + GC_PROTO_HEADER, plen);
    return GC_FRAME_OK;
}

void gc_decoder_reset(gcFrameDecoder *d) { memset(d, 0, sizeof *d); }

int gc_decoder_push(gcFrameDecoder *d, uint8_t byte, gcFrame *out) {
    if (byte != 0) {
        if (d->overflow) return 0;
        if (d->len == sizeof d->buf) {
            d->overflow = 1;
            d->errors[GC_FRAME_OVERFLOW]++;
            d->len = 0;
            return 0;
        }
        d->buf[d->len++] = byte;
        return 0;
    }
    if (d->overflow) {
        d->overflow = 0;
        return 0;
    }
    if (d->len == 0) return 0;
    gcFrameError e = gc_frame_decode(d->buf, d->len, out);
    d->len = 0;
    if (e != GC_FRAME_OK) {
        d->errors[e]++;
        return 0;
    }
    d->frames++;
    return 1;
}

/* ---- the hub ---------------------------------------------------------------------------- */

typedef struct gcSerialDevice gcSerialDevice;

struct gcSerialHub {
    gcWorld *world;
    int max_fingers;
    /* The latest tick (sequence lock; relaxed atomics so that readers never race). */
    _Atomic uint64_t seq;
    _Atomic int64_t tick_ns;
    _Atomic uint64_t tick_time_bits; /* the tick's session time (a double) */
    _Atomic int tick_enabled;
    _Atomic uint64_t *force_bits, *go_bits, *hip_bits; /* 3 per finger, doubles as bits */
    /* What each finger's device was last sent, in scene axes, and until when it renders it (its
     * TTL; 0: nothing): what the tick log records as the finger's device force. One writer a
     * finger (the thread of the device that drives it), a sequence lock a finger. */
    _Atomic uint32_t *sent_seq;
    _Atomic uint64_t *sent_bits;
    _Atomic int64_t *sent_until_ns;
    _Atomic unsigned char *driven; /* 1 once a serial device has driven the finger */
    _Atomic int any_driven;
    double *recorded; /* the haptic loop's scratch: the device forces it records */
    /* The merged HIPs every device thread pushes (fingers without a device keep theirs). */
    pthread_mutex_t hip_mutex;
    double *hips;
    int hips_ready, hip_count;
    double last_push_t;
    /* Devices (the API mutex guards attach/detach; threads never take it). */
    pthread_mutex_t api_mutex;
    gcSerialDevice *devices[GC_MAX_SERIAL_DEVICES];
};

struct gcSerialDevice {
    gcSerialHub *hub;
    int fd;
    gcSerialDef def;
    double A[9], b[3]; /* device metres -> world: x = A p + b */
    double A_inv[9];   /* forces sent (device axes) back to scene axes: f = A^-T f_dev */
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

static int64_t now_ns(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * NS + ts.tv_nsec;
}

static void store_d(_Atomic uint64_t *slot, double v) {
    uint64_t u;
    memcpy(&u, &v, 8);
    atomic_store_explicit(slot, u, memory_order_relaxed);
}

static double load_d(_Atomic uint64_t *slot) {
    uint64_t u = atomic_load_explicit(slot, memory_order_relaxed);
    double v;
    memcpy(&v, &u, 8);
    return v;
}

/* A sequence-locked read: acquire, so that the sequence number read after it is not read before. */
static double load_d_acquire(_Atomic uint64_t *slot) {
    uint64_t u = atomic_load_explicit(slot, memory_order_acquire);
    double v;
    memcpy(&v, &u, 8);
    return v;
}

gcSerialHub *gc_serial_hub_create(const gcWorld *w) {
    gcSerialHub *h = calloc(1, sizeof *h);
    if (!h) return NULL;
    pthread_mutex_init(&h->hip_mutex, NULL);
    pthread_mutex_init(&h->api_mutex, NULL);
    size_t n = (size_t)w->def.max_fingers * 3;
    h->world = (gcWorld *)w;
    h->max_fingers = w->def.max_fingers;
    h->force_bits = calloc(n, sizeof *h->force_bits);
    h->go_bits = calloc(n, sizeof *h->go_bits);
    h->hip_bits = calloc(n, sizeof *h->hip_bits);
    h->hips = calloc(n, sizeof *h->hips);
    h->sent_seq = calloc((size_t)w->def.max_fingers, sizeof *h->sent_seq);
    h->sent_bits = calloc(n, sizeof *h->sent_bits);
    h->sent_until_ns = calloc((size_t)w->def.max_fingers, sizeof *h->sent_until_ns);
    h->driven = calloc((size_t)w->def.max_fingers, sizeof *h->driven);
    h->recorded = calloc(n, sizeof *h->recorded);
    if (!h->force_bits || !h->go_bits || !h->hip_bits || !h->hips || !h->sent_seq || !h->sent_bits ||
        !h->sent_until_ns || !h->driven || !h->recorded) {
        gc_serial_hub_destroy(h);
        return NULL;
    }
    h->last_push_t = -INFINITY;
    return h;
}

void gc_serial_hub_tick(gcSerialHub *h, const gcWorld *hap, const double *device_force, int enabled, int64_t t) {
    uint64_t s = atomic_load_explicit(&h->seq, memory_order_relaxed);
    atomic_store_explicit(&h->seq, s + 1, memory_order_relaxed);
    atomic_thread_fence(memory_order_release);
    for (int i = 0; i < hap->num_fingers; ++i) {
        const gcFinger *f = &hap->fingers[i];
        store_d(&h->force_bits[3 * i], device_force[3 * i]);
        store_d(&h->force_bits[3 * i + 1], device_force[3 * i + 1]);
        store_d(&h->force_bits[3 * i + 2], device_force[3 * i + 2]);
        store_d(&h->go_bits[3 * i], f->god_object.x);
        store_d(&h->go_bits[3 * i + 1], f->god_object.y);
        store_d(&h->go_bits[3 * i + 2], f->god_object.z);
        store_d(&h->hip_bits[3 * i], f->hip.x);
        store_d(&h->hip_bits[3 * i + 1], f->hip.y);
        store_d(&h->hip_bits[3 * i + 2], f->hip.z);
    }
    atomic_store_explicit(&h->tick_ns, t, memory_order_relaxed);
    store_d(&h->tick_time_bits, hap->time);
    atomic_store_explicit(&h->tick_enabled, enabled, memory_order_relaxed);
    atomic_store_explicit(&h->seq, s + 2, memory_order_release);
}

/* A finger's last sent force (scene axes) and until when the device renders it. */
static void sent_store(gcSerialHub *h, int finger, const double f[3], int64_t until_ns) {
    uint32_t s = atomic_load_explicit(&h->sent_seq[finger], memory_order_relaxed);
    atomic_store_explicit(&h->sent_seq[finger], s + 1, memory_order_relaxed);
    atomic_thread_fence(memory_order_release);
    for (int c = 0; c < 3; ++c) store_d(&h->sent_bits[3 * finger + c], f[c]);
    atomic_store_explicit(&h->sent_until_ns[finger], until_ns, memory_order_relaxed);
    atomic_store_explicit(&h->sent_seq[finger], s + 2, memory_order_release);
}

/* The device renders nothing from now on (it was told ENABLE(0) or ESTOP, or stopped itself). */
static void sent_clear(gcSerialHub *h, int offset, int n) {
    static const double zero[3] = {0, 0, 0};
    for (int i = offset; i < offset + n; ++i) sent_store(h, i, zero, 0);
}

const double *gc_serial_hub_recorded_forces(gcSerialHub *h, const double *device_force, int num_fingers) {
    if (!atomic_load_explicit(&h->any_driven, memory_order_acquire)) return device_force;
    int64_t now = 0;
    for (int i = 0; i < num_fingers; ++i) {
        double *out = &h->recorded[3 * i];
        if (!atomic_load_explicit(&h->driven[i], memory_order_acquire)) {
            memcpy(out, &device_force[3 * i], 3 * sizeof(double));
            continue;
        }
        if (!now) now = now_ns(); /* the device threads' clock, whatever clock the loop runs on */
        /* A writer preempted mid-store must not hold the haptic loop: after a few tries the
         * finger keeps what the previous tick recorded (a millisecond old). */
        for (int attempt = 0; attempt < 8; ++attempt) {
            uint32_t s1 = atomic_load_explicit(&h->sent_seq[i], memory_order_acquire);
            if (s1 & 1) continue;
            double v[3];
            for (int c = 0; c < 3; ++c) v[c] = load_d_acquire(&h->sent_bits[3 * i + c]);
            int64_t until = atomic_load_explicit(&h->sent_until_ns[i], memory_order_acquire);
            if (atomic_load_explicit(&h->sent_seq[i], memory_order_relaxed) != s1) continue;
            for (int c = 0; c < 3; ++c) out[c] = now < until ? v[c] : 0.0; /* its TTL over: the device let go */
            break;
        }
    }
    return h->recorded;
}

/* The session time of monotonic instant t: the latest tick's time plus the time since its
 * wake-up (-1 before the first tick). */
static double hub_session_time(gcSerialHub *h, int64_t t) {
    for (int attempt = 0;; ++attempt) {
        if (attempt >= 64) { /* the haptic loop was preempted mid-publication: let it run */
            struct timespec pause = {0, 1000};
            nanosleep(&pause, NULL);
        }
        uint64_t s1 = atomic_load_explicit(&h->seq, memory_order_acquire);
        if (s1 & 1) continue;
        int64_t tick = atomic_load_explicit(&h->tick_ns, memory_order_acquire);
        double time = load_d_acquire(&h->tick_time_bits);
        if (atomic_load_explicit(&h->seq, memory_order_relaxed) != s1) continue;
        return s1 ? time + (double)(t - tick) / NS : -1.0;
    }
}

/* Fingers [offset, offset + n) of the latest tick: forces, god-objects, HIPs (NULL to skip).
 * Returns the tick's clock (0: no tick yet) and whether its forces were enabled. */
static int64_t hub_read(gcSerialHub *h, int offset, int n, double *force, double *go, double *hip, int *enabled) {
    for (int attempt = 0;; ++attempt) {
        if (attempt >= 64) { /* the writer was preempted mid-tick: let it run (we may be real-time) */
            struct timespec pause = {0, 1000};
            nanosleep(&pause, NULL);
        }
        uint64_t s1 = atomic_load_explicit(&h->seq, memory_order_acquire);
        if (s1 & 1) continue;
        for (int k = 3 * offset; k < 3 * (offset + n); ++k) {
            if (force) force[k - 3 * offset] = load_d(&h->force_bits[k]);
            if (go) go[k - 3 * offset] = load_d(&h->go_bits[k]);
            if (hip) hip[k - 3 * offset] = load_d(&h->hip_bits[k]);
        }
        int64_t t = atomic_load_explicit(&h->tick_ns, memory_order_relaxed);
        int e = atomic_load_explicit(&h->tick_enabled, memory_order_relaxed);
        atomic_thread_fence(memory_order_acquire);
        if (atomic_load_explicit(&h->seq, memory_order_relaxed) == s1) {
            if (enabled) *enabled = e;
            return s1 ? t : 0;
        }
    }
}

/* Writes fingers [offset, offset + n) of the merged HIPs and pushes them all. */
static gcStatus hub_push(gcSerialHub *h, int offset, int n, const double *positions) {
    pthread_mutex_lock(&h->hip_mutex);
    memcpy(&h->hips[3 * offset], positions, (size_t)n * 3 * sizeof(double));
    double t = (double)now_ns() / NS;
    if (t <= h->last_push_t) t = nextafter(h->last_push_t, INFINITY);
    h->last_push_t = t;
    gcStatus st = gc_runtime_push_input(h->world, h->hips, NULL, h->hip_count, t); /* no error message: not ours */
    pthread_mutex_unlock(&h->hip_mutex);
    return st;
}

/* The merged HIPs cover fingers 0..end-1 from now on. Fingers without a device keep their
 * HIPs: the array starts from the latest tick (or the world, before the runtime's first). */
static void hub_claim_fingers(gcSerialHub *h, const gcWorld *w, int end) {
    pthread_mutex_lock(&h->hip_mutex);
    if (!h->hips_ready) {
        if (!hub_read(h, 0, w->num_fingers, NULL, NULL, h->hips, NULL))
            memcpy(h->hips, w->hip_array, (size_t)w->num_fingers * 3 * sizeof(double));
        h->hips_ready = 1;
    }
    if (end > h->hip_count) h->hip_count = end;
    pthread_mutex_unlock(&h->hip_mutex);
}

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
    int64_t last_pose_ns, last_tx_ns, last_hello_ns, enabled_since_ns, last_publish_ns, last_drop_event_ns;
    uint64_t drops_reported, foreign_reported;
    /* UDP: where frames go (the configured address, then the pinned device's). */
    int datagram, pinned;
    struct sockaddr_storage peer;
    socklen_t peer_len;
    int enable_generation, stalled;
    int estop_latched;       /* an e-stop, until the next ENABLE(1) */
    int hello_pending;       /* HELLO_HOST sent to a silent device, no HELLO_DEVICE yet: zero forces */
    int64_t enable_sent_ns;  /* when ENABLE(1) was last sent */
    double unit_scale;
    int64_t rate_window_ns;
    uint64_t rate_window_poses;
    uint32_t latency[GC_LATENCY_BINS];
    uint64_t latency_n;
    double latency_max_us;
    double hips[3 * GC_PROTO_MAX_FINGERS];
} gcDeviceRun;

static void emit(gcSerialDevice *d, int code, int value) {
    unsigned head = atomic_load_explicit(&d->ev_head, memory_order_relaxed);
    unsigned tail = atomic_load_explicit(&d->ev_tail, memory_order_acquire);
    if (head - tail >= GC_SERIAL_EVENTS) return; /* full: the reader is away; the counters still say it */
    gcSerialEvent *e = &d->events[head % GC_SERIAL_EVENTS];
    int64_t t = now_ns();
    e->time = (double)t / NS;
    e->session_time = hub_session_time(d->hub, t);
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
    r->last_tx_ns = now_ns();
    return 1;
}

static void send_enable(gcDeviceRun *r, int on) {
    uint8_t p = on ? 1 : 0;
    send_frame(r, GC_MSG_ENABLE, &p, 1);
    if (on) {
        r->estop_latched = r->host_estop = 0; /* ENABLE(1) clears a latched e-stop, on both sides */
        r->enable_sent_ns = now_ns();
    } else {
        sent_clear(r->dev->hub, r->dev->def.finger_offset, r->dev->def.num_fingers);
    }
}

/* Forces off until the next ENABLE(1): an e-stop, the host's (reason 0) or the device's. */
static void latch_estop(gcDeviceRun *r, int reason) {
    r->s.enabled = 0;
    r->enabled_since_ns = 0;
    sent_clear(r->dev->hub, r->dev->def.finger_offset, r->dev->def.num_fingers);
    if (r->estop_latched) return; /* a repeated ESTOP: one event, one count */
    r->estop_latched = 1;
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
    s->last_pose_age = r->last_pose_ns ? (double)(t - r->last_pose_ns) / NS : -1.0;
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
    if (!hub_read(d->hub, d->def.finger_offset, d->def.num_fingers, NULL, go, NULL, NULL)) return;
    if (hub_push(d->hub, d->def.finger_offset, d->def.num_fingers, go) < 0) r->s.push_rejected++;
}

static void lose(gcDeviceRun *r, int state) {
    if (r->s.state == GC_SERIAL_STREAMING) {
        r->s.disconnects++;
        emit(r->dev, GC_SERIAL_EV_LOST, state == GC_SERIAL_HANGUP);
    }
    if (r->s.state != GC_SERIAL_HANGUP) r->s.state = state;
    r->enabled_since_ns = 0;
}

/* The force frame answering pose `ack`: the latest tick's forces of the device's fingers,
 * gated by enable, ramped, clamped, zeroed for a stalled loop, in device axes (f_dev = A^T f). */
static void send_forces(gcDeviceRun *r, uint16_t ack, int64_t t) {
    gcSerialDevice *d = r->dev;
    int n = r->s.device_fingers, m = d->def.num_fingers < n ? d->def.num_fingers : n;
    double f[3 * GC_PROTO_MAX_FINGERS];
    int tick_enabled = 0;
    int64_t tick = hub_read(d->hub, d->def.finger_offset, m, f, NULL, NULL, &tick_enabled);
    int stalled = !tick || t - tick > (int64_t)(d->def.stall_timeout * NS);
    if (stalled != r->stalled) {
        if (stalled) r->s.stall_zeroes++;
        emit(d, GC_SERIAL_EV_STALL, stalled);
        r->stalled = stalled;
    }
    int on = r->s.enabled && r->s.renders_forces && !stalled && tick_enabled && !r->hello_pending;
    if (!on)
        r->enabled_since_ns = 0;
    else if (!r->enabled_since_ns)
        r->enabled_since_ns = t;
    double gain = on ? gc_ramp_gain((double)(t - r->enabled_since_ns), d->def.ramp_time * NS) : 0.0;
    r->s.gain = gain;
    double limit = fmin(d->def.max_force, r->s.device_force_max);
    uint8_t p[6 + 12 * GC_PROTO_MAX_FINGERS];
    gc_put16(p, ack);
    double ttl_us = fmin(d->def.force_ttl * 1e6, r->s.device_ttl_max > 0 ? r->s.device_ttl_max * 1e6 : 65535.0);
    gc_put16(p + 2, (uint16_t)fmin(ttl_us, 65535.0));
    p[4] = (uint8_t)n;
    p[5] = 0;
    double sent[3 * GC_PROTO_MAX_FINGERS]; /* what the frame carries, back in scene axes */
    for (int i = 0; i < n; ++i) {
        double v[3] = {0, 0, 0};
        if (i < m && gain > 0) { /* in device axes, f_dev = A^T f, through the one gate */
            const double *fw = &f[3 * i], *A = d->A;
            int nonfinite = 0;
            gcVec3 g = gc_gate_force(gc_v3(A[0] * fw[0] + A[3] * fw[1] + A[6] * fw[2],
                                           A[1] * fw[0] + A[4] * fw[1] + A[7] * fw[2],
                                           A[2] * fw[0] + A[5] * fw[1] + A[8] * fw[2]),
                                     gain, limit, &nonfinite);
            v[0] = g.x, v[1] = g.y, v[2] = g.z;
        }
        for (int c = 0; c < 3; ++c) {
            v[c] = (float)v[c];
            gc_putf32(p + 6 + 12 * i + 4 * c, (float)v[c]);
        }
        if (i < m)
            for (int c = 0; c < 3; ++c) /* f = A^-T f_dev */
                sent[3 * i + c] = d->A_inv[c] * v[0] + d->A_inv[3 + c] * v[1] + d->A_inv[6 + c] * v[2];
    }
    if (!send_frame(r, GC_MSG_FORCE, p, 6 + 12 * (size_t)n)) return; /* not sent: the last frame's TTL runs on */
    r->s.forces_sent++;
    int64_t until = r->last_tx_ns + (int64_t)gc_le16(p + 2) * 1000;
    for (int i = 0; i < m; ++i) sent_store(d->hub, d->def.finger_offset + i, &sent[3 * i], until);
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
    s->units = units;
    s->device_rate = gc_le16(p + 4);
    s->device_force_max = fmax;
    s->device_ttl_max = gc_le16(p + 10) * 1e-3;
    size_t name_len = fr->len - 12;
    memcpy(s->name, p + 12, name_len);
    s->name[name_len] = 0;
    r->unit_scale = units == 1 ? 1e-3 : 1.0;
    if (s->state != GC_SERIAL_STREAMING) emit(r->dev, GC_SERIAL_EV_CONNECTED, n);
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
    int ok = n == s->device_fingers;
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
    }
    /* A pose saying "e-stop latched" while forces are on: an ESTOP frame was lost on the way
     * (a device that has not yet taken up our ENABLE(1) may still say so for a moment). */
    if ((p[5] & GC_STATUS_ESTOPPED) && s->enabled && t_read - r->enable_sent_ns > GC_ESTOP_STATUS_GRACE_NS)
        latch_estop(r, GC_ESTOP_REASON_STATUS);
    /* Ours, not shown latched in its poses: our ESTOP may have been lost; say it again. */
    if (r->host_estop && !(p[5] & GC_STATUS_ESTOPPED) && t_read - r->estop_sent_ns > GC_HELLO_RETRY_NS) {
        uint8_t reason = 0;
        send_frame(r, GC_MSG_ESTOP, &reason, 1);
        r->estop_sent_ns = t_read;
    }
    r->last_pose_ns = t_read;
    s->poses++;
    r->rate_window_poses++;
    if (hub_push(d->hub, d->def.finger_offset, m, r->hips) < 0) s->push_rejected++;
    send_forces(r, fr->seq, t_read);
    double us = (double)(now_ns() - t_read) / 1e3;
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
        r->estop_latched = 0; /* the host's own e-stop is always an event */
        latch_estop(r, 0);
        r->host_estop = 1;
        r->estop_sent_ns = now_ns();
    }
    int gen = atomic_load_explicit(&d->enable_generation, memory_order_acquire);
    if (gen != r->enable_generation) {
        r->enable_generation = gen;
        int on = atomic_load_explicit(&d->enable_request, memory_order_relaxed);
        r->s.enabled = on;
        r->enabled_since_ns = 0;
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
    r->last_hello_ns = r->rate_window_ns = now_ns();
    uint8_t buf[4096];
    while (atomic_load_explicit(&d->run, memory_order_acquire)) {
        take_requests(r);
        struct pollfd pfd = {.fd = d->fd, .events = POLLIN};
        int pr = poll(&pfd, 1, 1);
        int64_t t = now_ns();
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
                   t - r->last_pose_ns > (int64_t)(d->def.lost_timeout * NS)) {
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
            r->s.pose_rate = (double)r->rate_window_poses * NS / (double)(t - r->rate_window_ns);
            r->rate_window_poses = 0;
            r->rate_window_ns = t;
        }
        if (t - r->last_publish_ns > 10000000LL) publish_stats(r, t);
    }
    publish_stats(r, now_ns());
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
    gcSerialHub *h = w ? w->serial : NULL;
    if (!h || id < 0 || id >= GC_MAX_SERIAL_DEVICES) return NULL;
    return h->devices[id];
}

/* The determinant of the upper-left 3x3 of a row-major 4x4. */
static double det3(const double *m) {
    return m[0] * (m[5] * m[10] - m[6] * m[9]) - m[1] * (m[4] * m[10] - m[6] * m[8]) + m[2] * (m[4] * m[9] - m[5] * m[8]);
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
    gcSerialHub *h = w->serial;
    if (!h) return GC_ERR_NO_MEMORY;
    const char *bad = check_serial_def(w, fd, def);
    if (bad) {
        gc_world_set_error(w, "%s", bad);
        return GC_ERR_INVALID_ARGUMENT;
    }
    pthread_mutex_lock(&h->api_mutex);
    int id = -1;
    for (int i = 0; i < GC_MAX_SERIAL_DEVICES && id < 0; ++i)
        if (!h->devices[i]) id = i;
    for (int i = 0; i < GC_MAX_SERIAL_DEVICES; ++i) {
        const gcSerialDevice *o = h->devices[i];
        if (o && def->finger_offset < o->def.finger_offset + o->def.num_fingers &&
            o->def.finger_offset < def->finger_offset + def->num_fingers) {
            pthread_mutex_unlock(&h->api_mutex);
            gc_world_set_error(w, "finger_offset: fingers %d..%d are already driven by device %d", def->finger_offset,
                               def->finger_offset + def->num_fingers - 1, i);
            return GC_ERR_INVALID_ARGUMENT;
        }
    }
    if (id < 0) {
        pthread_mutex_unlock(&h->api_mutex);
        gc_world_set_error(w, "attach_serial: at most %d devices", GC_MAX_SERIAL_DEVICES);
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
    pthread_mutex_init(&d->stats_mutex, NULL);
    atomic_store(&d->run, 1);
    r->dev = d;
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
    hub_claim_fingers(h, w, def->finger_offset + def->num_fingers);
    for (int i = def->finger_offset; i < def->finger_offset + def->num_fingers; ++i)
        atomic_store_explicit(&h->driven[i], 1, memory_order_release);
    atomic_store_explicit(&h->any_driven, 1, memory_order_release);
    if (pthread_create(&d->thread, NULL, device_main, r)) {
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
    pthread_mutex_destroy(&d->stats_mutex);
    free(d);
}

gcStatus gc_world_detach_serial(gcWorld *w, int32_t id) {
    gcSerialDevice *d = device_of(w, id);
    if (!d) return GC_ERR_UNKNOWN_ID;
    pthread_mutex_lock(&w->serial->api_mutex);
    w->serial->devices[id] = NULL;
    pthread_mutex_unlock(&w->serial->api_mutex);
    device_stop(d);
    return GC_OK;
}

void gc_serial_hub_detach_all(gcSerialHub *h) {
    if (!h) return;
    for (int i = 0; i < GC_MAX_SERIAL_DEVICES; ++i) {
        if (h->devices[i]) device_stop(h->devices[i]);
        h->devices[i] = NULL;
    }
}

void gc_serial_hub_destroy(gcSerialHub *h) {
    if (!h) return;
    gc_serial_hub_detach_all(h);
    pthread_mutex_destroy(&h->hip_mutex);
    pthread_mutex_destroy(&h->api_mutex);
    free(h->force_bits);
    free(h->go_bits);
    free(h->hip_bits);
    free(h->hips);
    free(h->sent_seq);
    free(h->sent_bits);
    free(h->sent_until_ns);
    free(h->driven);
    free(h->recorded);
    free(h);
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

gcStatus gc_world_push_device_hips(gcWorld *w, int offset, int count, const double *positions) {
    if (!w || !positions || !w->serial) return GC_ERR_INVALID_ARGUMENT;
    if (count < 1 || offset < 0 || offset + count > w->num_fingers) {
        gc_world_set_error(w, "finger_offset, count: fingers %d..%d are not all fingers of the world", offset,
                           offset + count - 1);
        return GC_ERR_INVALID_ARGUMENT;
    }
    for (int i = 0; i < 3 * count; ++i)
        if (!isfinite(positions[i])) return GC_WARN_REJECTED;
    hub_claim_fingers(w->serial, w, offset + count);
    return hub_push(w->serial, offset, count, positions);
}

gcStatus gc_world_device_forces_sent(gcWorld *w, int offset, int count, const double *forces) {
    if (!w || !forces || !w->serial) return GC_ERR_INVALID_ARGUMENT;
    if (count < 1 || offset < 0 || offset + count > w->num_fingers) {
        gc_world_set_error(w, "finger_offset, count: fingers %d..%d are not all fingers of the world", offset,
                           offset + count - 1);
        return GC_ERR_INVALID_ARGUMENT;
    }
    for (int i = 0; i < 3 * count; ++i)
        if (!isfinite(forces[i])) return GC_WARN_REJECTED;
    gcSerialHub *h = w->serial;
    pthread_mutex_lock(&h->hip_mutex); /* callers on several threads: one writer a finger at a time */
    for (int i = 0; i < count; ++i) {
        sent_store(h, offset + i, &forces[3 * i], INT64_MAX);
        atomic_store_explicit(&h->driven[offset + i], 1, memory_order_release);
    }
    pthread_mutex_unlock(&h->hip_mutex);
    atomic_store_explicit(&h->any_driven, 1, memory_order_release);
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
