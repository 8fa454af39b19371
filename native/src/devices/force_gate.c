/* The device-force gate (force_gate.h): the one place forces are ramped, clamped and zeroed. */
#include "force_gate.h"

#include "base/gc_math.h"

/* The ramp gain `elapsed` after the gate opened (0..1 over `ramp`, 1 without a ramp); a force
 * scaled by it, zeroed when not finite, its norm clamped to `limit`. */
static double ramp_gain(double elapsed, double ramp) { return ramp > 0 ? gc_min(1.0, elapsed / ramp) : 1.0; }
static gcVec3 gate_force(gcVec3 f, double gain, double limit, int *nonfinite) {
    f = gc_scale(f, gain);
    if (!gc_vec_finite(f)) {
        *nonfinite = 1;
        return gc_v3(0, 0, 0);
    }
    double norm = gc_len(f);
    return norm > limit ? gc_scale(f, limit / norm) : f;
}

void gc_force_gate_init(gcForceGate *g, int64_t ramp_ns, int enabled) {
    g->ramp_ns = ramp_ns;
    g->enabled = enabled != 0;
    g->estop = 0;
    g->on_since_ns = GC_GATE_OFF;
}

void gc_force_gate_enable(gcForceGate *g, int on) {
    g->enabled = on != 0;
    if (on) g->estop = 0;
    g->on_since_ns = GC_GATE_OFF;
}

void gc_force_gate_close(gcForceGate *g) { g->on_since_ns = GC_GATE_OFF; }

int gc_force_gate_estop(gcForceGate *g) {
    g->enabled = 0;
    g->on_since_ns = GC_GATE_OFF;
    if (g->estop) return 0;
    g->estop = 1;
    return 1;
}

double gc_force_gate_gain(gcForceGate *g, int ready, int64_t now) {
    if (!(ready && g->enabled && !g->estop)) {
        g->on_since_ns = GC_GATE_OFF;
        return 0.0;
    }
    if (g->on_since_ns == GC_GATE_OFF) g->on_since_ns = now;
    return ramp_gain((double)(now - g->on_since_ns), (double)g->ramp_ns);
}

int gc_force_gate_apply(double gain, double limit, const double *in, double *out, int n) {
    int nonfinite_count = 0;
    for (int i = 0; i < n; ++i) {
        int nonfinite = 0;
        gcVec3 f = gate_force(gc_v3(in[3 * i], in[3 * i + 1], in[3 * i + 2]), gain, limit, &nonfinite);
        nonfinite_count += nonfinite;
        out[3 * i] = f.x, out[3 * i + 1] = f.y, out[3 * i + 2] = f.z;
    }
    return nonfinite_count;
}

uint16_t gc_force_gate_ttl_us(double host_ttl_s, double device_ttl_max_s) {
    double ttl_us = fmin(host_ttl_s * 1e6, device_ttl_max_s > 0 ? device_ttl_max_s * 1e6 : 65535.0);
    return (uint16_t)fmin(ttl_us, 65535.0);
}
