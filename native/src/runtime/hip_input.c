/* HIP input of the haptic loop: scripted tracks and timestamped samples (hip_input.h). */
#include "hip_input.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

gcVec3 gc_hip_track_sample(const gcHipTrack *tr, int finger, double t) {
    const double *ts = tr->times;
    const int n = tr->num_samples, nf = tr->num_fingers;
    const double tt = ts[0] + t;
    const double *p;
    if (tt <= ts[0] || n == 1) {
        p = &tr->positions[3 * finger];
        return gc_v3(p[0], p[1], p[2]);
    }
    if (tt >= ts[n - 1]) {
        p = &tr->positions[3 * ((size_t)(n - 1) * nf + finger)];
        return gc_v3(p[0], p[1], p[2]);
    }
    /* Last sample at or before tt (binary search: tracks hold minutes of frames). */
    int lo = 0, hi = n - 1;
    while (hi - lo > 1) {
        int mid = lo + (hi - lo) / 2;
        if (ts[mid] <= tt) lo = mid;
        else hi = mid;
    }
    const double a = (tt - ts[lo]) / (ts[lo + 1] - ts[lo]);
    const double *p0 = &tr->positions[3 * ((size_t)lo * nf + finger)];
    const double *p1 = &tr->positions[3 * ((size_t)(lo + 1) * nf + finger)];
    return gc_v3((1.0 - a) * p0[0] + a * p1[0], (1.0 - a) * p0[1] + a * p1[1], (1.0 - a) * p0[2] + a * p1[2]);
}

int gc_hip_track_orientation(const gcHipTrack *tr, int finger, double t, gcQuat *out) {
    if (!tr->orientations) return 0;
    const double *ts = tr->times;
    const int n = tr->num_samples, nf = tr->num_fingers;
    const double tt = ts[0] + t;
    const double *q;
    if (tt <= ts[0] || n == 1) {
        q = &tr->orientations[4 * finger];
    } else if (tt >= ts[n - 1]) {
        q = &tr->orientations[4 * ((size_t)(n - 1) * nf + finger)];
    } else {
        int lo = 0, hi = n - 1; /* as gc_hip_track_sample */
        while (hi - lo > 1) {
            int mid = lo + (hi - lo) / 2;
            if (ts[mid] <= tt) lo = mid;
            else hi = mid;
        }
        const double a = (tt - ts[lo]) / (ts[lo + 1] - ts[lo]);
        const double *q0 = &tr->orientations[4 * ((size_t)lo * nf + finger)];
        const double *q1 = &tr->orientations[4 * ((size_t)(lo + 1) * nf + finger)];
        /* q and -q are one rotation: interpolate along the shorter arc. */
        const double s = q0[0] * q1[0] + q0[1] * q1[1] + q0[2] * q1[2] + q0[3] * q1[3] < 0.0 ? -a : a;
        *out = (gcQuat){(1.0 - a) * q0[0] + s * q1[0], (1.0 - a) * q0[1] + s * q1[1], (1.0 - a) * q0[2] + s * q1[2],
                        (1.0 - a) * q0[3] + s * q1[3]};
        return 1;
    }
    *out = (gcQuat){q[0], q[1], q[2], q[3]};
    return 1;
}

int gc_hip_track_drives(const gcHipTrack *tr, int finger) {
    return tr && finger < tr->num_fingers && tr->scripted[finger];
}

int gc_hip_track_covers(const gcHipTrack *tr, int num_fingers) {
    if (!tr) return 0;
    for (int i = 0; i < num_fingers; ++i)
        if (!gc_hip_track_drives(tr, i)) return 0;
    return 1;
}

void gc_hip_track_free(gcHipTrack *tr) {
    if (!tr) return;
    free(tr->times);
    free(tr->positions);
    free(tr->scripted);
    free(tr->orientations);
    free(tr);
}

void gc_hip_follow_retarget(gcHipFollow *f, gcVec3 current, gcVec3 target, double interval, double dt) {
    f->from = current;
    f->to = target;
    f->elapsed = 0.0;
    f->turns = 0;
    /* A caller pushing every tick gets its sample at the next tick, exactly (its time stamps,
     * i * dt, differ from one another by dt only up to rounding). */
    f->duration = interval <= dt * (1.0 + 1e-6) ? dt : fmin(interval, GC_HIP_MAX_SEGMENT);
}

gcVec3 gc_hip_follow_advance(gcHipFollow *f, gcVec3 current, double dt, double max_speed) {
    f->elapsed += dt;
    gcVec3 target = f->to;
    if (f->elapsed < f->duration * (1.0 - 1e-9)) { /* (elapsed is a sum of dt: rounding) */
        double a = f->elapsed / f->duration;
        target = gc_add(gc_scale(f->from, 1.0 - a), gc_scale(f->to, a));
    }
    if (max_speed > 0.0) {
        gcVec3 d = gc_sub(target, current);
        double len = gc_len(d), cap = max_speed * dt;
        if (len > cap) target = gc_add(current, gc_scale(d, cap / len));
    }
    return target;
}

void gc_hip_follow_turn_to(gcHipFollow *f, gcQuat current, gcQuat target) {
    f->turns = 1;
    f->q_from = current;
    f->q_to = target;
}

int gc_hip_follow_orientation(const gcHipFollow *f, gcQuat *out) {
    if (!f->turns) return 0;
    if (f->elapsed >= f->duration * (1.0 - 1e-9)) { /* as gc_hip_follow_advance: reached */
        *out = f->q_to;
        return 1;
    }
    const double a = f->elapsed / f->duration;
    const gcQuat p = f->q_from, q = f->q_to;
    const double s = p.w * q.w + p.x * q.x + p.y * q.y + p.z * q.z < 0.0 ? -a : a;
    *out = (gcQuat){(1.0 - a) * p.w + s * q.w, (1.0 - a) * p.x + s * q.x, (1.0 - a) * p.y + s * q.y,
                    (1.0 - a) * p.z + s * q.z};
    return 1;
}

/* ---- the world API ------------------------------------------------------------------ */

static int finite_all(const double *v, size_t n) {
    for (size_t i = 0; i < n; ++i)
        if (!isfinite(v[i])) return 0;
    return 1;
}

gcStatus gc_world_set_hip_track(gcWorld *w, const double *times, const double *positions, int num_samples,
                                int num_fingers, const unsigned char *scripted) {
    if (!w) return GC_ERR_INVALID_ARGUMENT;
    if (w->locked) {
        gc_world_set_error(w, "set_hip_track: the runtime is running: stop it first");
        return GC_ERR_BUSY;
    }
    if (num_samples == 0) { /* clear */
        gc_hip_track_free(w->hip_track);
        w->hip_track = NULL;
        return GC_OK;
    }
    if (!times || !positions || num_samples < 0) {
        gc_world_set_error(w, "set_hip_track: times and positions are required (num_samples %d)", num_samples);
        return GC_ERR_INVALID_ARGUMENT;
    }
    if (num_fingers < 1 || num_fingers > w->num_fingers) {
        gc_world_set_error(w, "set_hip_track: num_fingers %d: the world has %d fingers", num_fingers,
                           w->num_fingers);
        return GC_ERR_INVALID_ARGUMENT;
    }
    for (int i = 0; i < num_samples; ++i) {
        if (!isfinite(times[i]) || (i > 0 && !(times[i] > times[i - 1]))) {
            gc_world_set_error(w, "set_hip_track: times[%d] = %g: times must be finite and strictly increasing", i,
                               times[i]);
            return GC_ERR_INVALID_ARGUMENT;
        }
    }
    size_t np = (size_t)num_samples * (size_t)num_fingers * 3;
    if (!finite_all(positions, np)) {
        gc_world_set_error(w, "set_hip_track: positions: a non-finite fingertip position");
        return GC_ERR_INVALID_ARGUMENT;
    }
    gcHipTrack *tr = calloc(1, sizeof *tr);
    if (tr) {
        tr->times = malloc((size_t)num_samples * sizeof(double));
        tr->positions = malloc(np * sizeof(double));
        tr->scripted = malloc((size_t)num_fingers);
    }
    if (!tr || !tr->times || !tr->positions || !tr->scripted) {
        gc_hip_track_free(tr);
        gc_world_set_error(w, "set_hip_track: out of memory for %d samples", num_samples);
        return GC_ERR_NO_MEMORY;
    }
    tr->num_samples = num_samples;
    tr->num_fingers = num_fingers;
    memcpy(tr->times, times, (size_t)num_samples * sizeof(double));
    memcpy(tr->positions, positions, np * sizeof(double));
    for (int i = 0; i < num_fingers; ++i) tr->scripted[i] = scripted ? scripted[i] != 0 : 1;
    gc_hip_track_free(w->hip_track);
    w->hip_track = tr;
    return GC_OK;
}

gcStatus gc_world_set_hip_track_orientations(gcWorld *w, const double *orientations) {
    if (!w) return GC_ERR_INVALID_ARGUMENT;
    if (w->locked) {
        gc_world_set_error(w, "set_hip_track_orientations: the runtime is running: stop it first");
        return GC_ERR_BUSY;
    }
    gcHipTrack *tr = w->hip_track;
    if (!tr) {
        gc_world_set_error(w, "set_hip_track_orientations: no HIP track: set_hip_track first");
        return GC_ERR_INVALID_ARGUMENT;
    }
    if (!orientations) { /* positions only again */
        free(tr->orientations);
        tr->orientations = NULL;
        return GC_OK;
    }
    size_t nq = (size_t)tr->num_samples * (size_t)tr->num_fingers;
    for (size_t i = 0; i < nq; ++i) {
        const double *q = &orientations[4 * i];
        double n2 = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3];
        if (!finite_all(q, 4) || !(n2 > 1e-20) || !isfinite(n2)) {
            gc_world_set_error(w,
                               "set_hip_track_orientations: sample %zu, finger %zu: not a finite non-zero "
                               "quaternion (w, x, y, z)",
                               i / (size_t)tr->num_fingers, i % (size_t)tr->num_fingers);
            return GC_ERR_INVALID_ARGUMENT;
        }
    }
    double *copy = malloc(4 * nq * sizeof(double));
    if (!copy) {
        gc_world_set_error(w, "set_hip_track_orientations: out of memory for %zu orientations", nq);
        return GC_ERR_NO_MEMORY;
    }
    memcpy(copy, orientations, 4 * nq * sizeof(double));
    free(tr->orientations);
    tr->orientations = copy;
    return GC_OK;
}
