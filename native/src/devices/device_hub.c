/* The device hub (device_hub.h): per-finger HIP slots in, the haptic tick out, what each
 * device was sent. Device threads and the API write here; nothing here calls the runtime, and
 * nothing a device thread calls writes the world's error message. */
#define _GNU_SOURCE
#include "device_hub.h"

#include "graspcore.h"
#include "world/body.h"

#include <math.h>
#include <stdlib.h>

gcDeviceHub *gc_device_hub_create(const gcWorld *w) {
    gcDeviceHub *h = calloc(1, sizeof *h);
    if (!h) return NULL;
    pthread_mutex_init(&h->api_mutex, NULL);
    pthread_mutex_init(&h->api_write_mutex, NULL);
    size_t nf = (size_t)w->def.max_fingers, n = nf * 3;
    h->world = (gcWorld *)w;
    h->max_fingers = w->def.max_fingers;
    h->slot = calloc(nf, sizeof *h->slot);
    h->owner = calloc(nf, sizeof *h->owner);
    h->claim = calloc(nf, sizeof *h->claim);
    h->force_bits = calloc(n, sizeof *h->force_bits);
    h->go_bits = calloc(n, sizeof *h->go_bits);
    h->hip_bits = calloc(n, sizeof *h->hip_bits);
    h->sent_seq = calloc(nf, sizeof *h->sent_seq);
    h->sent_bits = calloc(n, sizeof *h->sent_bits);
    h->sent_until_ns = calloc(nf, sizeof *h->sent_until_ns);
    h->driven = calloc(nf, sizeof *h->driven);
    h->recorded = calloc(n, sizeof *h->recorded);
    h->api_gate = calloc(nf, sizeof *h->api_gate);
    if (!h->api_gate || !h->slot || !h->owner || !h->claim || !h->force_bits || !h->go_bits || !h->hip_bits || !h->sent_seq || !h->sent_bits ||
        !h->sent_until_ns || !h->driven || !h->recorded) {
        gc_device_hub_destroy(h);
        return NULL;
    }
    for (size_t i = 0; i < nf; ++i) {
        gc_triple_reset(&h->slot[i].triple);
        atomic_init(&h->owner[i], GC_HUB_OWNER_NONE);
        gc_force_gate_init(&h->api_gate[i], 0, 0);
    }
    return h;
}

void gc_device_hub_destroy(gcDeviceHub *h) {
    if (!h) return;
    pthread_mutex_destroy(&h->api_mutex);
    pthread_mutex_destroy(&h->api_write_mutex);
    free(h->slot);
    free(h->owner);
    free(h->claim);
    free(h->force_bits);
    free(h->go_bits);
    free(h->hip_bits);
    free(h->sent_seq);
    free(h->sent_bits);
    free(h->sent_until_ns);
    free(h->driven);
    free(h->recorded);
    free(h->api_gate);
    free(h);
}

/* ---- HIPs in --------------------------------------------------------------------------- */

int gc_device_hub_claim(gcDeviceHub *h, int offset, int n, int owner) {
    for (int i = offset; i < offset + n; ++i) {
        int o = atomic_load_explicit(&h->owner[i], memory_order_acquire); /* after its last owner's release */
        if (o != GC_HUB_OWNER_NONE && o != owner) return 0;
    }
    for (int i = offset; i < offset + n; ++i) {
        if (atomic_load_explicit(&h->owner[i], memory_order_relaxed) == owner) continue;
        atomic_fetch_add_explicit(&h->claim[i], 1, memory_order_relaxed); /* the samples before are not ours */
        atomic_store_explicit(&h->owner[i], owner, memory_order_release);
    }
    return 1;
}

void gc_device_hub_release(gcDeviceHub *h, int offset, int n, int owner) {
    for (int i = offset; i < offset + n; ++i) {
        int o = owner;
        atomic_compare_exchange_strong_explicit(&h->owner[i], &o, GC_HUB_OWNER_NONE, memory_order_acq_rel,
                                                memory_order_relaxed);
    }
}

int gc_device_quat_usable(const double q[4]) {
    const double n2 = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3];
    return isfinite(n2) && fabs(n2 - 1.0) <= GC_DEVICE_QUAT_UNIT_TOL; /* NaN/Inf in q: n2 is not finite */
}

void gc_device_hub_write_hips(gcDeviceHub *h, int offset, int n, const double *positions,
                              const double *orientations, uint32_t episode) {
    const double t = (double)gc_clock_now_ns() / GC_NS_PER_S;
    for (int k = 0; k < n; ++k) {
        gcHipSlot *s = &h->slot[offset + k];
        gcDeviceSample *out = &s->sample[s->triple.back];
        memcpy(out->hip, &positions[3 * k], sizeof out->hip);
        out->has_q = orientations != NULL;
        if (orientations) memcpy(out->q, &orientations[4 * k], sizeof out->q);
        out->t = t;
        out->serial = ++s->writes;
        out->episode = episode;
        out->claim = atomic_load_explicit(&h->claim[offset + k], memory_order_relaxed); /* ours: we claimed it */
        gc_triple_publish(&s->triple);
    }
}

int gc_device_hub_latest_hip(gcDeviceHub *h, int finger, gcDeviceSample *out) {
    if (atomic_load_explicit(&h->owner[finger], memory_order_acquire) == GC_HUB_OWNER_NONE) return 0;
    int fresh;
    gcHipSlot *s = &h->slot[finger];
    *out = s->sample[gc_triple_latest(&s->triple, &fresh)];
    return out->serial != 0 && out->claim == atomic_load_explicit(&h->claim[finger], memory_order_acquire);
}

/* ---- tick out --------------------------------------------------------------------------- */

void gc_device_hub_tick(gcDeviceHub *h, const gcWorld *hap, const double *device_force, int enabled, int64_t t) {
    uint64_t s = atomic_load_explicit(&h->seq, memory_order_relaxed);
    atomic_store_explicit(&h->seq, s + 1, memory_order_relaxed);
    atomic_thread_fence(memory_order_release);
    for (int i = 0; i < hap->num_fingers; ++i) {
        const gcFinger *f = &hap->fingers[i];
        for (int c = 0; c < 3; ++c) gc_atomic_store_double(&h->force_bits[3 * i + c], device_force[3 * i + c]);
        gc_atomic_store_double(&h->go_bits[3 * i], f->god_object.x);
        gc_atomic_store_double(&h->go_bits[3 * i + 1], f->god_object.y);
        gc_atomic_store_double(&h->go_bits[3 * i + 2], f->god_object.z);
        gc_atomic_store_double(&h->hip_bits[3 * i], f->hip.x);
        gc_atomic_store_double(&h->hip_bits[3 * i + 1], f->hip.y);
        gc_atomic_store_double(&h->hip_bits[3 * i + 2], f->hip.z);
    }
    atomic_store_explicit(&h->tick_ns, t, memory_order_relaxed);
    gc_atomic_store_double(&h->tick_time_bits, hap->time);
    atomic_store_explicit(&h->tick_enabled, enabled, memory_order_relaxed);
    atomic_store_explicit(&h->seq, s + 2, memory_order_release);
}

/* The writer was preempted mid-publication: let it run (the reader may be real-time). */
static void yield_to_writer(int attempt) {
    if (attempt >= 64) {
        struct timespec pause = {0, 1000};
        nanosleep(&pause, NULL);
    }
}

double gc_device_hub_session_time(gcDeviceHub *h, int64_t t) {
    for (int attempt = 0;; ++attempt) {
        yield_to_writer(attempt);
        uint64_t s1 = atomic_load_explicit(&h->seq, memory_order_acquire);
        if (s1 & 1) continue;
        int64_t tick = atomic_load_explicit(&h->tick_ns, memory_order_acquire);
        double time = gc_atomic_load_double_acquire(&h->tick_time_bits);
        if (atomic_load_explicit(&h->seq, memory_order_relaxed) != s1) continue;
        return s1 ? time + (double)(t - tick) / GC_NS_PER_S : -1.0;
    }
}

int64_t gc_device_hub_read(gcDeviceHub *h, int offset, int n, double *force, double *go, double *hip, int *enabled) {
    for (int attempt = 0;; ++attempt) {
        yield_to_writer(attempt);
        uint64_t s1 = atomic_load_explicit(&h->seq, memory_order_acquire);
        if (s1 & 1) continue;
        for (int k = 3 * offset; k < 3 * (offset + n); ++k) {
            if (force) force[k - 3 * offset] = gc_atomic_load_double(&h->force_bits[k]);
            if (go) go[k - 3 * offset] = gc_atomic_load_double(&h->go_bits[k]);
            if (hip) hip[k - 3 * offset] = gc_atomic_load_double(&h->hip_bits[k]);
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

/* ---- sent ------------------------------------------------------------------------------- */

void gc_device_hub_sent(gcDeviceHub *h, int finger, const double f[3], int64_t until_ns) {
    uint32_t s = atomic_load_explicit(&h->sent_seq[finger], memory_order_relaxed);
    atomic_store_explicit(&h->sent_seq[finger], s + 1, memory_order_relaxed);
    atomic_thread_fence(memory_order_release);
    for (int c = 0; c < 3; ++c) gc_atomic_store_double(&h->sent_bits[3 * finger + c], f[c]);
    atomic_store_explicit(&h->sent_until_ns[finger], until_ns, memory_order_relaxed);
    atomic_store_explicit(&h->sent_seq[finger], s + 2, memory_order_release);
    if (!atomic_load_explicit(&h->driven[finger], memory_order_relaxed)) {
        atomic_store_explicit(&h->driven[finger], 1, memory_order_release);
        atomic_store_explicit(&h->any_driven, 1, memory_order_release);
    }
}

const double *gc_device_hub_recorded_forces(gcDeviceHub *h, const double *device_force, int num_fingers) {
    if (!atomic_load_explicit(&h->any_driven, memory_order_acquire)) return device_force;
    int64_t now = 0;
    for (int i = 0; i < num_fingers; ++i) {
        double *out = &h->recorded[3 * i];
        if (!atomic_load_explicit(&h->driven[i], memory_order_acquire)) {
            memcpy(out, &device_force[3 * i], 3 * sizeof(double));
            continue;
        }
        if (!now) now = gc_clock_now_ns(); /* the device threads' clock, whatever clock the loop runs on */
        /* A writer preempted mid-store must not hold the haptic loop: after a few tries the
         * finger keeps what the previous tick recorded (a millisecond old). */
        for (int attempt = 0; attempt < 8; ++attempt) {
            uint32_t s1 = atomic_load_explicit(&h->sent_seq[i], memory_order_acquire);
            if (s1 & 1) continue;
            double v[3];
            for (int c = 0; c < 3; ++c) v[c] = gc_atomic_load_double_acquire(&h->sent_bits[3 * i + c]);
            int64_t until = atomic_load_explicit(&h->sent_until_ns[i], memory_order_acquire);
            if (atomic_load_explicit(&h->sent_seq[i], memory_order_relaxed) != s1) continue;
            for (int c = 0; c < 3; ++c) out[c] = now < until ? v[c] : 0.0; /* its TTL over: the device let go */
            break;
        }
    }
    return h->recorded;
}

/* ---- the API: devices read elsewhere (SpaceMouse, glove) --------------------------------- */

static const char *check_fingers(const gcWorld *w, int offset, int count_) {
    if (count_ < 1 || offset < 0 || offset + count_ > w->num_fingers) return "not all fingers of the world";
    return NULL;
}

gcStatus gc_world_push_device_hips(gcWorld *w, int offset, int count_, const double *positions) {
    return gc_world_push_device_poses(w, offset, count_, positions, NULL);
}

gcStatus gc_world_push_device_poses(gcWorld *w, int offset, int count_, const double *positions,
                                    const double *orientations) {
    if (!w || !positions || !w->hub) return GC_ERR_INVALID_ARGUMENT;
    if (check_fingers(w, offset, count_)) {
        gc_world_set_error(w, "finger_offset, count: fingers %d..%d are not all fingers of the world", offset,
                           offset + count_ - 1);
        return GC_ERR_INVALID_ARGUMENT;
    }
    if (!w->runtime || !w->locked) return GC_ERR_NOT_RUNNING;
    int usable = 1;
    for (int i = 0; i < 3 * count_; ++i) usable &= isfinite(positions[i]) != 0;
    for (int i = 0; orientations && i < count_; ++i) usable &= gc_device_quat_usable(&orientations[4 * i]);
    if (!usable) { /* nothing of the sample is taken */
        gc_atomic_increment(&w->hub->rejected_inputs); /* the runtime's stats add these */
        return GC_WARN_REJECTED;
    }
    gcDeviceHub *h = w->hub;
    pthread_mutex_lock(&h->api_write_mutex); /* callers on several threads: one writer a finger at a time */
    if (!gc_device_hub_claim(h, offset, count_, GC_HUB_OWNER_API)) {
        pthread_mutex_unlock(&h->api_write_mutex);
        gc_world_set_error(w, "finger_offset, count: fingers %d..%d: a serial device drives some of them", offset,
                           offset + count_ - 1);
        return GC_ERR_INVALID_ARGUMENT;
    }
    gc_device_hub_write_hips(h, offset, count_, positions, orientations, 1);
    pthread_mutex_unlock(&h->api_write_mutex);
    return GC_OK;
}

gcStatus gc_world_device_forces_sent(gcWorld *w, int offset, int count_, const double *forces) {
    if (!w || !forces || !w->hub) return GC_ERR_INVALID_ARGUMENT;
    if (check_fingers(w, offset, count_)) {
        gc_world_set_error(w, "finger_offset, count: fingers %d..%d are not all fingers of the world", offset,
                           offset + count_ - 1);
        return GC_ERR_INVALID_ARGUMENT;
    }
    for (int i = 0; i < 3 * count_; ++i)
        if (!isfinite(forces[i])) return GC_WARN_REJECTED;
    gcDeviceHub *h = w->hub;
    pthread_mutex_lock(&h->api_write_mutex);
    for (int i = 0; i < count_; ++i) gc_device_hub_sent(h, offset + i, &forces[3 * i], INT64_MAX);
    pthread_mutex_unlock(&h->api_write_mutex);
    return GC_OK;
}

gcStatus gc_world_device_forces(gcWorld *w, int offset, int count_, int enable, double *out) {
    if (!w || !out || !w->hub) return GC_ERR_INVALID_ARGUMENT;
    if (check_fingers(w, offset, count_)) {
        gc_world_set_error(w, "finger_offset, count: fingers %d..%d are not all fingers of the world", offset,
                           offset + count_ - 1);
        return GC_ERR_INVALID_ARGUMENT;
    }
    gcDeviceHub *h = w->hub;
    for (int i = offset; i < offset + count_; ++i)
        if (atomic_load_explicit(&h->owner[i], memory_order_acquire) != GC_HUB_OWNER_API) {
            gc_world_set_error(w, "finger_offset, count: finger %d is not driven through push_device_hips", i);
            return GC_ERR_INVALID_ARGUMENT;
        }
    memset(out, 0, 3 * (size_t)count_ * sizeof(double));
    if (!w->runtime || !w->locked) return GC_ERR_NOT_RUNNING;
    /* As a device thread answers a pose (device_threads.c send_forces): the latest tick's gated
     * forces, zero for a stalled loop, through the fingers' own gate. */
    int tick_enabled = 0;
    int64_t now = gc_clock_now_ns(), tick = gc_device_hub_read(h, offset, count_, out, NULL, NULL, &tick_enabled);
    int ready = tick && now - tick <= GC_DEVICE_STALL_NS && tick_enabled;
    pthread_mutex_lock(&h->api_write_mutex);
    for (int i = 0; i < count_; ++i) {
        gcForceGate *g = &h->api_gate[offset + i];
        g->ramp_ns = h->ramp_ns;
        if (g->enabled != (enable != 0)) gc_force_gate_enable(g, enable);
        gc_force_gate_apply(gc_force_gate_gain(g, ready, now), INFINITY, &out[3 * i], &out[3 * i], 1);
        gc_device_hub_sent(h, offset + i, &out[3 * i], INT64_MAX); /* until device_forces_sent says more */
    }
    pthread_mutex_unlock(&h->api_write_mutex);
    return GC_OK;
}
