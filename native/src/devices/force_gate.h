/* The device-force gate (force_gate.c), one for every device kind and for the runtime's own
 * safety stage: forces leave the host only through it. Enable, a latched e-stop, the caller's
 * readiness (watchdog, fresh input, a running loop), the ramp-in, the clamp, NaN zeroing, and
 * the time a force frame is rendered (its TTL). */
#ifndef GC_FORCE_GATE_H
#define GC_FORCE_GATE_H

#include <stdint.h>

typedef struct gcForceGate {
    int64_t ramp_ns;       /* 0: no ramp */
    int enabled;           /* the caller's enable (cleared by an e-stop) */
    int estop;             /* latched until the next enable */
    int64_t on_since_ns;   /* GC_GATE_OFF while the gain is zero */
} gcForceGate;
#define GC_GATE_OFF INT64_MIN

void gc_force_gate_init(gcForceGate *g, int64_t ramp_ns, int enabled);
/* On clears a latched e-stop; either way the ramp starts again. */
void gc_force_gate_enable(gcForceGate *g, int on);
/* The gain is zero, and ramps in again once it may (a device lost, a loop that stalled). */
void gc_force_gate_close(gcForceGate *g);
/* Forces off until the next enable; 1 when this latched it (a repeated e-stop: 0). */
int gc_force_gate_estop(gcForceGate *g);
/* The gain at `now`: 0 unless enabled, not e-stopped and `ready`; from the instant all three
 * hold, it ramps from 0 to 1 over ramp_ns. */
double gc_force_gate_gain(gcForceGate *g, int ready, int64_t now);
/* n forces (3 each): scaled by gain, zeroed when not finite, each norm clamped to limit.
 * Returns how many were not finite (NaN never leaves). in and out may be the same array. */
int gc_force_gate_apply(double gain, double limit, const double *in, double *out, int n);
/* How long a force frame is rendered, in us: the host's TTL, at most the device's ttl_max
 * (0: none said), at most the 16-bit field. */
uint16_t gc_force_gate_ttl_us(double host_ttl_s, double device_ttl_max_s);

#endif
