/* The device hub (device_hub.c, docs/devices.md): the runtime's side of every device, made with
 * the world so that a device may attach before the session starts. Three channels, none of
 * which the haptic loop ever waits on:
 *   HIPs in     one triple buffer a finger: the finger's device writes it, the haptic tick
 *               takes the latest sample (one writer a finger: its owner);
 *   tick out    every haptic tick's gated forces, god-objects and HIPs, a sequence lock the
 *               device threads read;
 *   sent        what each finger's device was last sent and until when it renders it (its
 *               TTL), a sequence lock a finger: what the tick log records as the device force. */
#ifndef GC_DEVICE_HUB_H
#define GC_DEVICE_HUB_H

#include "world/world.h"
#include "force_gate.h"
#include "base/gc_sync.h"

#include <pthread.h>

#define GC_MAX_DEVICES 8
#define GC_HUB_OWNER_NONE (-1)
#define GC_HUB_OWNER_API GC_MAX_DEVICES /* gc_world_push_device_hips: a device read elsewhere */

/* One sample of a finger's device. */
typedef struct gcDeviceSample {
    double hip[3];      /* scene metres */
    double q[4];        /* the finger's orientation (w, x, y, z, unit) when has_q */
    int has_q;          /* 0: positions only, the finger keeps its orientation */
    double t;           /* s, CLOCK_MONOTONIC when the device thread took it */
    uint64_t serial;    /* the finger's write count: 0 never written */
    uint32_t episode;   /* the device's connection: a new one starts with a soft start */
    uint32_t claim;     /* the finger's claim it was written under: an older owner's is not taken */
} gcDeviceSample;

typedef struct gcHipSlot {
    gcTriple triple;
    gcDeviceSample sample[3];
    uint64_t writes;    /* the writer's */
} gcHipSlot;

typedef struct gcDeviceHub {
    gcWorld *world;
    int max_fingers;
    /* HIPs in. owner: GC_HUB_OWNER_NONE, a device id, or GC_HUB_OWNER_API. */
    gcHipSlot *slot;
    _Atomic int *owner;
    _Atomic uint32_t *claim;         /* per finger: +1 each time an owner claims it */
    _Atomic uint32_t connections;    /* every device connection so far: each its own episode */
    _Atomic uint64_t rejected_inputs; /* device poses pushed through the API and refused (stats add them) */
    pthread_mutex_t api_write_mutex; /* among API writers of slots only; device threads never take it */
    gcForceGate *api_gate;           /* per finger a device read elsewhere drives: its force gate */
    int64_t ramp_ns;                 /* the running runtime's ramp_time (set by gc_world_start) */
    /* Tick out (sequence lock; relaxed atomics so that readers never race). */
    _Atomic uint64_t seq;
    _Atomic int64_t tick_ns;
    _Atomic uint64_t tick_time_bits; /* the tick's session time (a double) */
    _Atomic int tick_enabled;
    _Atomic uint64_t *force_bits, *go_bits, *hip_bits; /* 3 per finger, doubles as bits */
    /* Sent. driven: 1 once a device has recorded what it sent the finger. */
    _Atomic uint32_t *sent_seq;
    _Atomic uint64_t *sent_bits;
    _Atomic int64_t *sent_until_ns;
    _Atomic unsigned char *driven;
    _Atomic int any_driven;
    double *recorded; /* the haptic loop's scratch: the device forces it records */
    /* Devices (device_threads.c; api_mutex guards attach and detach, threads never take it). */
    pthread_mutex_t api_mutex;
    struct gcSerialDevice *devices[GC_MAX_DEVICES];
} gcDeviceHub;

gcDeviceHub *gc_device_hub_create(const gcWorld *world);
/* After the devices were detached (device_threads.c) and the runtime freed. */
void gc_device_hub_destroy(gcDeviceHub *hub);

/* ---- HIPs in ---- */
/* Fingers [offset, offset + n) to `owner`: 0 when one of them has another owner. */
int gc_device_hub_claim(gcDeviceHub *hub, int offset, int n, int owner);
void gc_device_hub_release(gcDeviceHub *hub, int offset, int n, int owner);
/* The finger's owner writes its samples (positions: 3 a finger, finite; orientations: NULL, or
 * 4 a finger, each passing gc_device_quat_usable), stamped now. */
void gc_device_hub_write_hips(gcDeviceHub *hub, int offset, int n, const double *positions,
                              const double *orientations, uint32_t episode);
/* A device's orientation (w, x, y, z) is taken only when finite and unit within
 * GC_DEVICE_QUAT_UNIT_TOL (|q|^2 - 1): a device sends a rotation, never a scaled one. */
#define GC_DEVICE_QUAT_UNIT_TOL 1e-3
int gc_device_quat_usable(const double q[4]);
/* The haptic loop only: finger i's latest sample; 0 when no owner drives it now. */
int gc_device_hub_latest_hip(gcDeviceHub *hub, int finger, gcDeviceSample *out);

/* ---- tick out ---- */
/* The haptic loop, after each tick's safety stage: its gated forces (3 a finger), god-objects
 * and HIPs (in `hap`). */
void gc_device_hub_tick(gcDeviceHub *hub, const gcWorld *hap, const double *device_force, int forces_enabled,
                        int64_t now_ns);
/* Fingers [offset, offset + n) of the latest tick: forces, god-objects, HIPs (NULL to skip).
 * Returns the tick's clock (0: no tick yet) and whether its forces were enabled. */
int64_t gc_device_hub_read(gcDeviceHub *hub, int offset, int n, double *force, double *go, double *hip,
                           int *enabled);
/* The session time of monotonic instant t: the latest tick's time plus the time since its
 * wake-up (-1 before the runtime's first tick). */
double gc_device_hub_session_time(gcDeviceHub *hub, int64_t t);

/* ---- sent ---- */
/* A finger's last sent force (scene axes) and until when the device renders it (0: nothing). */
void gc_device_hub_sent(gcDeviceHub *hub, int finger, const double f[3], int64_t until_ns);
/* The haptic loop, for the tick log: `device_force` itself while no device has recorded what it
 * sent; else a copy in which each such finger has what its device was last sent, or zero once
 * that frame's TTL is over. Never blocks, never allocates. */
const double *gc_device_hub_recorded_forces(gcDeviceHub *hub, const double *device_force, int num_fingers);

/* How long a device may go without a haptic tick before its forces are zeroed (a stalled loop):
 * gcSerialDef.stall_timeout's default, for devices read elsewhere. */
#define GC_DEVICE_STALL_NS 5000000LL

/* device_threads.c: detaches every device, joining its thread (before the runtime is freed). */
void gc_device_threads_stop_all(gcDeviceHub *hub);

#endif
