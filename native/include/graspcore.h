/* graspcore: friction-cone (god-object) haptic rendering and rigid-body dynamics
 * for multi-finger grasps.
 *
 * Units are SI (m, kg, N, s). Orientations are unit quaternions (w, x, y, z).
 * Bodies and fingers are named by small integer ids handed out by the world.
 * Every call returns a status; on an error the world is unchanged and
 * gc_world_last_error() says what was wrong, naming the argument.
 * Nothing allocates inside gc_world_step(): all storage is sized by gcWorldDef. */
#ifndef GRASPCORE_H
#define GRASPCORE_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef enum gcStatus {
    GC_OK = 0,
    GC_WARN_MAX_ITERATIONS = 1,     /* answer usable, iteration cap reached */
    GC_WARN_REJECTED = 2,           /* runtime input refused (NaN/Inf, time going back) and counted */
    GC_WARN_STOPPED = 3,            /* a body whose state would have become non-finite was put back
                                     * at its pose before the step, at rest, and counted */
    GC_ERR_INVALID_ARGUMENT = -1,
    GC_ERR_DEGENERATE = -2,         /* degenerate hull: coplanar, collinear, coincident points */
    GC_ERR_NO_MEMORY = -3,
    GC_ERR_UNKNOWN_ID = -4,
    GC_ERR_CAPACITY = -5,           /* a gcWorldDef capacity is exhausted */
    GC_ERR_BUSY = -6,               /* not allowed while the runtime threads run */
    GC_ERR_NOT_RUNNING = -7         /* a runtime call while the runtime is stopped */
} gcStatus;

const char *gc_status_string(gcStatus status);

typedef struct gcWorld gcWorld;

typedef enum gcFingerState { GC_FINGER_FREE = 0, GC_FINGER_STICK = 1, GC_FINGER_SLIP = 2 } gcFingerState;

typedef struct gcWorldDef {
    double gravity[3];      /* m/s^2, default (0, 0, -9.81) */
    int gyroscopic;         /* 1: keep -w x Jw in Euler's equation (default); 0: drop it as the source
                             * chapter does (Harwin & Barrow, docs/physics.md) */
    int max_bodies;         /* capacity, default 256 */
    int max_fingers;        /* capacity, default 32 */
    int max_parts;          /* convex parts over all bodies, default 4096 */
    /* Body-body contacts (docs/solver.md). */
    int threads;            /* threads solving collision chains, the caller included; default 1 (0 = 1) */
    int max_contacts;       /* contact manifolds (convex part pairs), default 2048 (0 = default);
                             * pairs beyond it are dropped and counted (gc_world_contact_overflow) */
} gcWorldDef;
gcWorldDef gc_default_world_def(void);

typedef struct gcPartDef {
    const double *points;   /* num_points xyz triples in the body frame */
    int num_points;         /* >= 4 for a hull; 1 = sphere, 2 = capsule (radius > 0) */
    double radius;          /* margin radius, default 0 */
} gcPartDef;

typedef struct gcBodyDef {
    double position[3];        /* body frame origin, world */
    double orientation[4];     /* w, x, y, z; normalised on creation */
    double linear_velocity[3];
    double angular_velocity[3];/* world frame, rad/s */
    int is_static;
    double mass;               /* kg, > 0 for a dynamic body */
    int has_inertia;           /* 1: use inertia[] instead of computing it from the parts */
    double inertia[9];         /* about the centre of mass, body axes, row-major, kg m^2 */
    int has_center_of_mass;    /* 1: use center_of_mass[] instead of the parts' centroid */
    double center_of_mass[3];  /* body frame */
    double mu_s;               /* static friction, default 0.8 */
    double mu_d;               /* dynamic friction, default 0.6, <= mu_s */
    double viscosity;          /* s: slip speed limit is depth/viscosity; 0 = pure Coulomb */
    double linear_damping;     /* 1/s, default 0 */
    double angular_damping;    /* 1/s, default 0 */
} gcBodyDef;
gcBodyDef gc_default_body_def(void);

/* A convex finger (a pad, a palm, a tool tip) has at most this many hull vertices. */
#define GC_MAX_FINGER_VERTICES 32
/* Corners of a finger's contact patch in the tick record and snapshots (docs/recording-format.md). */
#define GC_FINGER_PATCH_CORNERS 4

/* How a finger's force is found (docs/physics.md): the friction-cone god-objects, one per
 * convex part touched (xFCA), or the light-mass cursor: a mass on the finger's spring and
 * damper, kept outside all the convex parts together by a constraint solve. */
typedef enum gcFingerRenderer { GC_RENDERER_XFCA = 0, GC_RENDERER_CURSOR = 1 } gcFingerRenderer;

typedef struct gcFingerDef {
    double radius;          /* fingertip sphere, m (0 = point), default 0.008; a convex finger's
                             * hull is inflated by it */
    double stiffness;       /* N/m per point of contact (a sphere has one, a convex finger one per
                             * touching hull vertex), default 1000 */
    double damping;         /* N s/m on the HIP vs god-object-point velocity, default 0 */
    double position[3];     /* initial HIP */
    /* Convex finger (docs/physics.md "Area contacts"): NULL / 0 = a sphere of radius. Otherwise
     * num_points >= 4 xyz triples in the finger frame, not all coplanar, whose hull has at most
     * GC_MAX_FINGER_VERTICES vertices. Each hull vertex is a point of contact with a god-object
     * of its own, so a face lying on a face carries the pressure torque. */
    const double *points;
    int num_points;
    double orientation[4];  /* initial finger-frame orientation (w, x, y, z), default identity;
                             * normalised on creation */
    double torsion;         /* a soft sphere fingertip (docs/physics.md "Soft fingertips"): the radius
                             * rho (m) of the patch it presses, resisting a twist about the contact
                             * normal with stiffness k rho^2 up to mu F_n rho; default 0 = none.
                             * Sphere fingers only (a convex finger's patch has its own) */
    gcFingerRenderer renderer; /* default GC_RENDERER_XFCA */
    double cursor_mass;     /* kg, the cursor renderer's mass, >= 0, default 0.002 */
} gcFingerDef;
gcFingerDef gc_default_finger_def(void);

gcStatus gc_world_create(const gcWorldDef *def, gcWorld **out_world);
/* Message for the last failed gc_world_create on the calling thread, naming the gcWorldDef
 * field it refused (no world exists to hold it); empty after a success. */
const char *gc_world_create_error(void);
void gc_world_destroy(gcWorld *world);
/* Message for the last failed call on this world (empty when none). */
const char *gc_world_last_error(const gcWorld *world);

gcStatus gc_world_add_body(gcWorld *world, const gcBodyDef *def, const gcPartDef *parts,
                           int num_parts, int32_t *out_body);
gcStatus gc_world_add_finger(gcWorld *world, const gcFingerDef *def, int32_t *out_finger);
int gc_world_body_count(const gcWorld *world);
int gc_world_finger_count(const gcWorld *world);

gcStatus gc_world_set_gravity(gcWorld *world, const double gravity[3]);
gcStatus gc_world_set_hip(gcWorld *world, int32_t finger, const double position[3]);
/* The whole HIP of a finger: position and orientation (w, x, y, z, normalised here). A convex
 * finger turns with it; a sphere finger ignores the orientation. */
gcStatus gc_world_set_finger_pose(gcWorld *world, int32_t finger, const double position[3],
                                  const double orientation[4]);
gcStatus gc_world_finger_pose(const gcWorld *world, int32_t finger, double position[3], double orientation[4]);
/* count xyz triples for fingers 0..count-1. */
gcStatus gc_world_set_hips(gcWorld *world, const double *positions, int count);
gcStatus gc_world_set_body_velocity(gcWorld *world, int32_t body, const double linear[3],
                                    const double angular[3]);
gcStatus gc_world_set_body_pose(gcWorld *world, int32_t body, const double position[3],
                                const double orientation[4]);
gcStatus gc_world_set_body_friction(gcWorld *world, int32_t body, double mu_s, double mu_d,
                                    double viscosity);

gcStatus gc_world_step(gcWorld *world, double dt);
/* A HIP stream replayed: for each of `steps` rows of hips (num_fingers xyz triples: that step's
 * HIPs), gc_world_set_hips then gc_world_step(dt), then the tick record numbered first_tick + k
 * into records (steps records of gc_tick_record_size bytes; size bytes in all; NULL: none, the
 * steps alone). Bit for bit
 * what those calls one by one give (resim and sweep run it). Stops at the first error; *done
 * (if given) says how many steps ran. A body stopped on the way answers GC_WARN_STOPPED at the
 * end, after every step ran. */
gcStatus gc_world_step_hips(gcWorld *world, const double *hips, int num_fingers, int steps, double dt,
                            uint64_t first_tick, void *records, size_t size, int *done);
/* gc_world_step_hips with a short trace of each step instead of its tick record: what a sweep
 * reads of every tick (docs/sweeps.md), two fifths of a record's bytes and no state hash, field by
 * field (each a contiguous array, for numpy). `traces` holds `total` ticks, little-endian, packed:
 * time f64[total]; contact body i32[total][fingers] (-1 free); state i32[total][fingers]; force
 * (the coupling spring) f64[total][fingers][3]; god_object f64[total][fingers][3]; pose
 * f64[total][bodies][7] (the same values as the record's fields of those names):
 * total * gc_tick_trace_size(bodies, fingers) bytes. Step k goes to tick first + k. */
size_t gc_tick_trace_size(int num_bodies, int num_fingers);
/* Sets *names to the trace's fields (names of gc_tick_record_fields' rows, in the trace's order);
 * returns how many. */
int gc_tick_trace_fields(const char *const **names);
gcStatus gc_world_step_hips_trace(gcWorld *world, const double *hips, int num_fingers, int steps, double dt,
                                  int first, int total, void *traces, size_t size, int *done);

gcStatus gc_world_body_pose(const gcWorld *world, int32_t body, double position[3],
                            double orientation[4]);
gcStatus gc_world_body_velocity(const gcWorld *world, int32_t body, double linear[3],
                                double angular[3]);
/* Mass properties: mass, centre of mass (body frame), inertia about it (body axes). */
gcStatus gc_world_body_mass(const gcWorld *world, int32_t body, double *mass,
                            double center_of_mass[3], double inertia[9]);
/* Sum of finger reactions (and gravity) on the body; torque about the centre of mass. */
gcStatus gc_world_residual_wrench(const gcWorld *world, int32_t body, double force[3],
                                  double torque[3]);
gcStatus gc_world_finger_force(const gcWorld *world, int32_t finger, double force[3]);
/* Convex finger: the torque of its contacts about the HIP (sum (GO_i - HIP) x f_i), what a 6-DOF
 * device renders beside the force; a soft sphere fingertip's twist torque; 0 for a plain sphere.
 * GC_ERR_BUSY while the runtime runs. */
gcStatus gc_world_finger_torque(const gcWorld *world, int32_t finger, double torque[3]);
/* One point of a finger's contact patch (a sphere finger has at most one per part it touches). */
typedef struct gcFingerContactPoint {
    int32_t body;           /* the body touched */
    int32_t sample;         /* not reversed: the convex finger's hull vertex (0 for a sphere);
                             * reversed: the vertex of the body's part that entered the finger */
    int32_t reversed;       /* 1: a body vertex inside a convex finger, its god-object on the finger */
    int32_t state;          /* gcFingerState: stick or slip */
    double point[3];        /* world, where the body receives the force: the god-object on the body
                             * (a fingertip centre), or the body's vertex */
    double normal[3];       /* world, outward from the body */
    double force[3];        /* N, on the finger (the body gets the opposite at point) */
} gcFingerContactPoint;
/* Copies up to capacity contact points of the finger; *out_count: how many it has (may exceed
 * capacity). GC_ERR_BUSY while the runtime runs (its snapshots do not carry the patch; so for
 * gc_world_finger_torque). */
gcStatus gc_world_finger_contacts(const gcWorld *world, int32_t finger, gcFingerContactPoint *out, int capacity,
                                  int *out_count);
gcStatus gc_world_god_object(const gcWorld *world, int32_t finger, double position[3]);
gcStatus gc_world_finger_state(const gcWorld *world, int32_t finger, gcFingerState *state,
                               int32_t *contact_body);

/* Zero-copy bulk views, laid out contiguously and never reallocated:
 * poses are 7 doubles a body (x, y, z, qw, qx, qy, qz), the others 3 a finger.
 * Valid until gc_world_destroy; updated by gc_world_step. */
const double *gc_world_body_pose_array(const gcWorld *world);
const double *gc_world_god_object_array(const gcWorld *world);
const double *gc_world_finger_force_array(const gcWorld *world);
const double *gc_world_hip_array(const gcWorld *world);

/* Body-body contacts (docs/solver.md). Friction between two bodies combines their
 * coefficients by the geometric mean: mu_s = sqrt(mu_s_a mu_s_b), mu_d = sqrt(mu_d_a mu_d_b).
 * One entry per contact point of the last step, in a fixed order. */
typedef struct gcContactPoint {
    int32_t body_a, body_b;     /* body_a < body_b */
    double point[3];            /* world, midway between the two surfaces */
    double normal[3];           /* unit, from body_a towards body_b */
    double separation;          /* m, negative when penetrating (speculative points are > 0) */
    double normal_impulse;      /* N s over the last step (force = impulse / dt) */
    double friction_impulse[3]; /* N s, world */
    int sticking;               /* 1: static friction holds (anchored), 0: sliding */
} gcContactPoint;
int gc_world_contact_count(const gcWorld *world);
/* Copies up to capacity points; returns how many exist (may exceed capacity). */
int gc_world_contacts(const gcWorld *world, gcContactPoint *out, int capacity);
/* Contact pairs dropped since creation because max_contacts was exhausted. */
int64_t gc_world_contact_overflow(const gcWorld *world);
/* Collision chains of the last step: dynamic bodies linked by contacts (a static body never
 * joins two chains; fingers do not link chains). A dynamic body without contacts is a chain
 * of its own. Chains are numbered 0..count-1 by their lowest body id; static bodies get -1. */
int gc_world_chain_count(const gcWorld *world);
gcStatus gc_world_body_chain(const gcWorld *world, int32_t body, int32_t *chain);

/* Bodies stopped since creation because their state would have become non-finite
 * (gc_world_step answers GC_WARN_STOPPED for the step that stopped them). */
int64_t gc_world_stopped_bodies(const gcWorld *world);

/* 64-bit hash of the full dynamic state (bit-exact), for determinism checks. */
uint64_t gc_world_state_hash(const gcWorld *world);
double gc_world_time(const gcWorld *world);

/* ---- Runtime: the haptic loop and the object manager on threads (docs/runtime.md) ----
 * gc_world_start hands the world to a haptic loop (god-objects, finger springs, and the
 * bodies it adopts: the chain of a touched body while it has at most max_adopted_bodies)
 * and an object manager (every other body, steps of at most 2 ms). While it runs, the
 * world's mutating calls answer GC_ERR_BUSY and its queries and views answer from the last
 * gc_world_snapshot; gc_world_stop puts the final state back. push_hips, snapshot and stats
 * may be called from any thread; the loops never wait on them. */
typedef struct gcRuntimeDef {
    double haptic_rate;         /* Hz, default 1000 */
    double object_rate;         /* Hz, <= haptic_rate, default 500; each object tick covers
                                 * 1/object_rate in steps of at most 2 ms */
    int max_adopted_bodies;     /* adopt a touched chain while it has at most this many bodies;
                                 * default 3, 0 = never adopt */
    double release_delay;       /* s a chain stays adopted after its last touch, default 0.05 */
    double max_force;           /* N, device force clamp (norm per finger), default 10 */
    double ramp_time;           /* s, device forces ramp in from 0 when enabled, default 0.5 */
    double watchdog_timeout;    /* s, a haptic period longer than this zeroes device forces
                                 * (then they ramp in again), default 0.005 */
    double hip_timeout;         /* s, device forces are zero while the last push_hips is older, default 0.1 */
    int realtime;               /* 1: threads on CLOCK_MONOTONIC (default); 0: manual clock,
                                 * no threads, ticks run by gc_world_advance (deterministic) */
    int priority;               /* SCHED_FIFO priority tried for the haptic loop, default 80;
                                 * 0 = normal priority. Refused -> normal priority, said in stats */
    double max_hip_speed;       /* m/s, the fastest a pushed HIP moves towards its sample;
                                 * default 0 = unbounded (a device's own motion); interactive
                                 * input (a mouse at display rate) sets a bound */
} gcRuntimeDef;
gcRuntimeDef gc_default_runtime_def(void);

gcStatus gc_world_start(gcWorld *world, const gcRuntimeDef *def);
/* Joins the threads and puts the final state back into the world; GC_OK when not running. */
gcStatus gc_world_stop(gcWorld *world);
int gc_world_running(const gcWorld *world);
/* Manual clock only: run `ticks` haptic ticks (and the object ticks that fall among them) on
 * the calling thread. `delay` s is added to the clock before the first, as a stalled loop. */
gcStatus gc_world_advance(gcWorld *world, int ticks, double delay);
/* Manual clock only: `steps` haptic ticks replaying a recorded threaded session
 * (docs/runtime.md "Replaying a recorded schedule"): each tick's HIPs (3 per finger for all
 * num_fingers fingers) and orientations (4 per finger, or NULL) as recorded, and the object
 * manager's ticks run and their results taken on the recorded hand-over schedule (the records'
 * object_ticks and object_reads), so that every tick is the recorded one bit for bit. Records
 * into `records` (steps of gc_tick_record_size bytes, size in all; NULL: none); *done = ticks
 * replayed. A schedule that cannot have happened is GC_ERR_INVALID_ARGUMENT naming the step. */
gcStatus gc_world_replay_ticks(gcWorld *world, const double *hips, const double *orientations, int num_fingers,
                               const uint64_t *object_ticks, const uint64_t *object_reads, int steps,
                               void *records, size_t size, int *done);
/* HIPs of fingers 0..count-1 (xyz triples) sampled at time t (s, the caller's clock), from any
 * thread. The haptic loop moves each HIP from where it is to this sample over the interval since
 * the previous sample (at most 0.25 s), at most max_hip_speed: a caller pushing every haptic tick
 * gets its HIPs at the next tick exactly, a slow caller (a 5 Hz display) gives a smooth path.
 * Fingers driven by the scripted track ignore pushed samples.
 * GC_OK: taken; GC_WARN_REJECTED: NaN/Inf or t older than the last push (counted, ignored). */
gcStatus gc_world_push_hips(gcWorld *world, const double *positions, int count, double t);
/* push_hips with each finger's orientation too (count quaternions w, x, y, z; NULL = positions
 * only, as push_hips): a convex finger turns from where it is to the sample over the same
 * interval as its position walks (normalised lerp, the shorter arc; max_hip_speed bounds the
 * position only), normalised as gc_world_set_finger_pose does, so a caller pushing every tick
 * gets set_finger_pose + step bit for bit. A push without orientations leaves them where they
 * are. A non-finite or zero quaternion rejects the push (GC_WARN_REJECTED, counted). */
gcStatus gc_world_push_finger_poses(gcWorld *world, const double *positions, const double *orientations, int count,
                                    double t);

/* A scripted HIP track for the runtime (set while stopped): num_samples times (s, strictly
 * increasing) and num_samples x num_fingers xyz positions for fingers 0..num_fingers-1. At its
 * tick k (from 1) after gc_world_start the haptic loop puts each scripted finger's HIP at the
 * track's linear interpolation at times[0] + k / haptic_rate, held past either end: what
 * gc_world_set_hips before every gc_world_step of 1 / haptic_rate would give, bit for bit.
 * scripted (NULL = all) says which fingers the track drives; the others follow
 * gc_world_push_hips. num_samples 0 clears the track. GC_ERR_BUSY while running. */
gcStatus gc_world_set_hip_track(gcWorld *world, const double *times, const double *positions, int num_samples,
                                int num_fingers, const unsigned char *scripted);
/* Orientations for the track just set (set while stopped; a new set_hip_track drops them):
 * num_samples x num_fingers quaternions (w, x, y, z), finite and non-zero, so a convex finger
 * (a palm) turns as it moves. Sampled at the same times as the positions by normalised lerp
 * (the shorter arc), held past either end, then normalised as gc_world_set_finger_pose does:
 * set_finger_pose before every gc_world_step of 1 / haptic_rate gives the same world, bit for
 * bit. NULL drops them (positions only); a sphere finger ignores them. */
gcStatus gc_world_set_hip_track_orientations(gcWorld *world, const double *orientations);

/* One haptic tick's consistent view. Arrays are the caller's (NULL to skip), sized for
 * gc_world_body_count / gc_world_finger_count. When stopped: the world's state, forces 0. */
typedef struct gcSnapshot {
    double time;                /* s, haptic loop's simulated time */
    double object_time;         /* s, object manager's simulated time as last seen */
    uint64_t tick;              /* haptic ticks since start */
    int forces_enabled;         /* 0: device forces held at zero (watchdog, stale input) */
    int num_bodies, num_fingers;
    double *poses;              /* 7 per body: x y z qw qx qy qz */
    double *residual_wrenches;  /* 6 per body: force, torque about the centre of mass */
    uint8_t *adopted;           /* per body: 1 while the haptic loop steps it */
    double *god_objects;        /* 3 per finger */
    double *hips;               /* 3 per finger */
    double *forces;             /* 3 per finger: device force (clamped, ramped, watchdog) */
    double *spring_forces;      /* 3 per finger: the physics spring force, unclamped */
    int32_t *finger_states;     /* gcFingerState per finger */
    int32_t *contact_bodies;    /* per finger, -1 when free */
    double *normals;            /* 3 per finger: plane normal of the contact whose god-object, state
                                 * and body it reports (its deepest), world, pointing out of the
                                 * body touched (as in the tick record); 0 when free */
    double *velocities;         /* 6 per body: linear velocity of the body frame origin, angular
                                 * (world), as gc_world_body_velocity */
    float *patches;             /* 2 GC_FINGER_PATCH_CORNERS per finger: a convex finger's contact
                                 * patch as in the tick record's `patch` (docs/recording-format.md);
                                 * zeros for a sphere finger or when free */
} gcSnapshot;
gcStatus gc_world_snapshot(gcWorld *world, gcSnapshot *snapshot);

typedef struct gcRuntimeStats {
    int running, realtime;
    int rt_priority;            /* 1: the haptic loop runs at SCHED_FIFO */
    char priority_note[128];
    double haptic_rate, object_rate;   /* achieved, Hz (manual clock: per simulated second) */
    double object_speed;        /* object manager's simulated time / wall time (< 1: behind) */
    uint64_t haptic_ticks, object_ticks;
    double jitter_p50_us, jitter_p99_us, jitter_max_us; /* |haptic period - nominal| */
    double tick_max_us;         /* longest haptic tick (its work, real-time clock) */
    double tick_mean_us;        /* mean haptic tick (its work) */
    double wake_max_us;         /* latest wake-up of the haptic loop after its deadline */
    uint64_t overruns;          /* haptic ticks that ended past the next deadline */
    uint64_t late_periods;      /* haptic periods late by more than one period */
    uint64_t object_overruns;
    int adopted_bodies;
    uint64_t accepted_inputs, rejected_inputs;
    uint64_t watchdog_trips, stale_inputs, nonfinite_forces;
    uint64_t stopped_bodies;    /* bodies stopped by either loop: their state would have become non-finite */
    int forces_enabled;
    double haptic_time, object_time;
} gcRuntimeStats;
gcStatus gc_world_stats(gcWorld *world, gcRuntimeStats *stats);
/* Test hook: the haptic loop sleeps this long before its next tick, as a stalled loop. */
gcStatus gc_world_debug_stall(gcWorld *world, double seconds);

/* ---- Tick log: one record per tick for recorders (docs/recording-format.md) ----
 * A record is gc_tick_record_size(bodies, fingers) bytes, little-endian, packed: tick u64,
 * time f64, object_time f64, state_hash u64, period_us f32, work_us f32, flags u32 (bit 0:
 * device forces enabled), adopted u32, log_us f32 (what recording the previous tick cost, real
 * time); then per finger hip, god_object, force (the coupling
 * spring), device_force (after the safety layer), normal (of the reported contact, world; 0
 * when free) as 3 f64 each; per body pose (7 f64),
 * velocity (linear of the body frame origin, angular; 6 f64), residual wrench (6 f64); per
 * finger state i32, contact body i32 (-1 free); per finger parts u32 (bit i: touches part i of
 * its body, parts past 31 on bit 31); per finger orientation (w, x, y, z) 4 f64 (the identity
 * for a sphere finger); the threaded runtime's hand-over schedule: object_tick u64 (the object
 * manager tick whose result the haptic loop holds after this tick), object_reads u64 (object
 * ticks that had taken a haptic message before this tick published its own); both 0 outside
 * the runtime. Each field was added at the end: older records are their prefix. */
size_t gc_tick_record_size(int num_bodies, int num_fingers);
/* The same layout as a table, for readers (graspcore.tick_dtype): the fields in record order,
 * each `count` items of `type` (a little-endian numpy type string: "<u8", "<f8", "<f4", "<u4",
 * "<i4") of `size` bytes, once per record or per finger or per body. */
typedef enum gcTickFieldScope { GC_TICK_ONCE = 0, GC_TICK_PER_FINGER = 1, GC_TICK_PER_BODY = 2 } gcTickFieldScope;
typedef struct gcTickField {
    const char *name;
    const char *type;
    int size;
    gcTickFieldScope scope;
    int count;   /* values per finger/body (or once) */
    int columns; /* 0: a vector of count; else count / columns rows of columns (the patch's corners) */
} gcTickField;
/* Sets *fields to the table; returns how many fields it has. */
int gc_tick_record_fields(const gcTickField **fields);
/* Bits of a record's flags. */
enum { GC_TICK_FORCES_ENABLED = 1 }; /* device forces enabled (not held at zero by the safety layer) */
/* The stopped world as one record (after a gc_world_step); device_force = force. */
gcStatus gc_world_tick_record(gcWorld *world, uint64_t tick, void *out, size_t size);
/* While stopped: a ring of `capacity` records (0 = off) that gc_world_start sizes and empties
 * and every haptic tick fills; a full ring drops the tick and counts it, never waits. */
gcStatus gc_world_set_tick_log(gcWorld *world, int capacity);
/* Copies up to max_records (and size bytes) of the oldest undrained records; returns how many,
 * or a negative gcStatus. From any thread (callers take turns), while the loops run, while the
 * world starts or stops; not during gc_world_set_tick_log or gc_world_destroy. */
int gc_world_drain_ticks(gcWorld *world, void *out, size_t size, int max_records);
/* Ticks dropped on a full ring since the last gc_world_start. */
uint64_t gc_world_tick_log_overflow(const gcWorld *world);
/* ---- Serial haptic devices (docs/protocol.md, docs/devices.md) ----
 * A device speaks the Grasp Lab serial protocol on a file descriptor the caller opened and
 * configured (pyserial: raw mode, the baud rate) and keeps open until detach. A C thread per
 * device owns the descriptor's I/O: it says hello, turns pose frames into HIPs of fingers
 * finger_offset.. (through transform) pushed into the runtime, and answers every pose with a
 * force frame from the haptic loop's latest device forces. Forces stay zero until
 * gc_world_serial_enable; they ramp in, are clamped per finger, and are zeroed when the
 * haptic loop stalls. A device silent for lost_timeout is lost: its fingers let go (their
 * HIPs follow their god-objects, so no force on bodies or device) until poses come again.
 * With devices attached, the hub is the HIP producer: do not call push_hips as well. */
typedef struct gcSerialDef {
    int finger_offset;          /* first world finger the device drives */
    int num_fingers;            /* world fingers it drives, >= 1 (a device with fewer drives fewer) */
    double transform[16];       /* row-major 4x4, device metres -> world; default identity */
    double force_ttl;           /* s, time to live of each force frame, default 0.02 */
    double lost_timeout;        /* s without a valid pose before the fingers let go, default 0.1 */
    double max_force;           /* N per finger (norm); the device's own limit applies too; default 10 */
    double ramp_time;           /* s, forces ramp in after enable or reconnection, default 0.5 */
    double max_position;        /* m, a pose coordinate beyond this (device metres) is out of range, default 10 */
    double stall_timeout;       /* s, haptic-loop output older than this: zero forces, default 0.005 */
    int priority;               /* SCHED_FIFO priority tried for the device thread, default 70 (below the
                                 * haptic loop's 80); 0 = normal. Refused -> normal, said in stats */
    /* UDP (docs/protocol.md section 7): fd is a bound datagram socket, one frame a datagram.
     * Frames go to udp_host:udp_port until a HELLO_DEVICE pins the session to the address that
     * sent it; datagrams from any other address are then dropped and counted (foreign). Late
     * and duplicated poses are dropped and counted, so that a HIP never goes back in time.
     * udp_port 0 (default): a byte stream (serial port, pty, stream socket). */
    char udp_host[64];          /* numeric IPv4 or IPv6 address */
    int udp_port;
} gcSerialDef;
gcSerialDef gc_default_serial_def(void);

typedef enum gcSerialState {
    GC_SERIAL_WAITING = 0,      /* hello sent, no capabilities yet */
    GC_SERIAL_STREAMING = 1,
    GC_SERIAL_LOST = 2,         /* no valid pose for lost_timeout: fingers let go */
    GC_SERIAL_HANGUP = 3        /* the descriptor hung up or failed: fingers let go */
} gcSerialState;

typedef enum gcSerialEventCode {
    GC_SERIAL_EV_CONNECTED = 1, /* capabilities received (value: device finger count) */
    GC_SERIAL_EV_LOST = 2,      /* value: 1 hang-up, 0 silence */
    GC_SERIAL_EV_RECOVERED = 3, /* poses again after a loss */
    GC_SERIAL_EV_ENABLED = 4,   /* value: 1 on, 0 off */
    GC_SERIAL_EV_ESTOP = 5,     /* value: reason (0 host, 1 device button, 2 device fault, other bytes as the
                                 * device sent them; GC_ESTOP_REASON_STATUS: only a pose's status said so) */
    GC_SERIAL_EV_STALL = 6,     /* value: 1 forces zeroed for a stalled haptic loop, 0 resumed */
    GC_SERIAL_EV_DROPPED = 7,   /* value: frames dropped since the previous such event (at most 10 Hz) */
    GC_SERIAL_EV_FOREIGN = 8    /* UDP: datagrams from another address since the previous such event (at most 10 Hz) */
} gcSerialEventCode;
enum { GC_ESTOP_REASON_STATUS = 256 }; /* an e-stop seen in a pose's status bit 1 (its ESTOP frame was lost) */
typedef struct gcSerialEvent {
    double time;                /* s, CLOCK_MONOTONIC, when the device thread observed it */
    double session_time;        /* s, the same instant on the session clock (the latest haptic tick's
                                 * time plus the time since it); -1 before the runtime's first tick */
    int32_t code;               /* gcSerialEventCode */
    int32_t value;
} gcSerialEvent;

typedef struct gcSerialStats {
    int state;                  /* gcSerialState */
    int enabled;                /* forces enabled by the caller (and not e-stopped since) */
    int device_fingers, renders_forces, units;
    double device_rate, device_force_max, device_ttl_max;
    char name[33];
    double pose_rate;           /* Hz over the last 0.25 s window */
    double last_pose_age;       /* s since the last valid pose (-1: none yet) */
    uint64_t poses, forces_sent, heartbeats;
    uint64_t dropped;           /* frames dropped, the sum of the errors below */
    uint64_t frame_errors[8];   /* cobs, short, crc, version, type, length, overflow, range */
    uint64_t sequence_gaps;     /* device frames (any type) missing from its sequence numbers */
    uint64_t disconnects, estops, stall_zeroes, write_errors, push_rejected;
    double latency_p50_us, latency_p99_us, latency_max_us; /* pose read -> force frame written */
    double gain;                /* current ramp gain 0..1 (0 while disabled) */
    int rt_priority;            /* 1: the device thread runs at SCHED_FIFO */
    uint64_t late_poses, duplicate_poses; /* UDP: poses older than, or the same as, the newest taken: dropped */
    uint64_t foreign_datagrams; /* UDP: from an address other than the pinned device's: dropped */
    char peer[64];              /* UDP: the device's address once pinned ("" before) */
    int sends_orientations;     /* its hello offers orientations (HELLO_DEVICE flags bit 1) and the host takes
                                 * them (a workspace frame that does not mirror) */
    uint64_t oriented_poses;    /* poses that carried the fingers' orientations */
} gcSerialStats;

gcStatus gc_world_attach_serial(gcWorld *world, int fd, const gcSerialDef *def, int32_t *out_device);
/* Joins the device's thread (the descriptor stays open); its fingers keep their last HIPs. */
gcStatus gc_world_detach_serial(gcWorld *world, int32_t device);
gcStatus gc_world_serial_enable(gcWorld *world, int32_t device, int enable);
gcStatus gc_world_serial_estop(gcWorld *world, int32_t device);
gcStatus gc_world_serial_stats(gcWorld *world, int32_t device, gcSerialStats *stats);
/* Pops up to capacity safety events, oldest first; returns how many. */
int gc_world_serial_events(gcWorld *world, int32_t device, gcSerialEvent *out, int capacity);
/* HIPs of fingers finger_offset .. finger_offset+count-1 from a device read elsewhere (a
 * SpaceMouse, a glove), merged with the serial devices' fingers and pushed the same way:
 * the call to use instead of push_hips while serial devices are attached.
 * GC_WARN_REJECTED: a NaN/Inf position (nothing pushed, counted in rejected_inputs). */
gcStatus gc_world_push_device_hips(gcWorld *world, int finger_offset, int count, const double *positions);
/* push_device_hips with each finger's orientation too (count quaternions w, x, y, z; NULL =
 * positions only): a convex finger turns from where it is to the sample over the same interval as
 * its position walks (normalised lerp, the shorter arc, as gc_world_push_finger_poses). Each
 * quaternion must be finite and unit (| |q|^2 - 1 | <= 1e-3): GC_WARN_REJECTED otherwise, as for
 * a NaN/Inf position (nothing taken; both counted in the runtime's rejected_inputs). */
gcStatus gc_world_push_device_poses(gcWorld *world, int finger_offset, int count, const double *positions,
                                    const double *orientations);
/* What such a device was sent for fingers finger_offset.. (3 a finger, scene axes; zeros for an
 * input-only device), held until the next call: recorded in the tick log as their device force,
 * as the serial devices' frames are. GC_WARN_REJECTED: a NaN/Inf force (nothing stored). */
gcStatus gc_world_device_forces_sent(gcWorld *world, int finger_offset, int count, const double *forces);
/* The forces for fingers finger_offset.. of such a device (3 a finger, scene axes, into out): what
 * a serial device thread would send them, from the latest haptic tick (not the display's
 * snapshot) through the same gate: zero until `enable`, ramped in over the runtime's ramp_time
 * from then, zero while the haptic loop stalls or its forces are off. Recorded as the fingers'
 * device force until device_forces_sent says what the device actually got. The fingers must be
 * driven through gc_world_push_device_hips. GC_ERR_NOT_RUNNING (out zero) while stopped. */
gcStatus gc_world_device_forces(gcWorld *world, int finger_offset, int count, int enable, double *out);


/* ---- Grasp quality (docs/api.md "Grasp quality") ----
 * The grasp wrench space (GWS) of point contacts with linearised friction cones: edge j of
 * contact i is f = n_i + mu_i (cos(2 pi j/k) t1_i + sin(2 pi j/k) t2_i), t1 = normalize(n x a)
 * with a the world axis of smallest |n.a| (ties: x, then y, then z), t2 = n x t1; its wrench is
 * (f, (p - center) x f / radius). A contact with mu 0 gives one wrench (its k edges coincide).
 * The GWS is the convex hull of the edge wrenches (6-D); force closure = the origin strictly
 * inside it. Exact, no sampling: closure by a linear program, epsilon and the weakest direction
 * by a support-function search (each answer certified against the hull), the volume from the
 * whole hull. A workspace holds all storage; it grows to the largest problem it has seen and is
 * reused without allocating. */
typedef struct gcGraspDef {
    int edges;              /* friction cone edges per contact, >= 3, default 8 */
    double tolerance;       /* relative to the largest wrench norm: rank, flatness, visibility and
                             * "strictly inside" (origin more than this far inside every facet);
                             * default 1e-10 */
    int max_facets;         /* cap on the facets alive at once, default 1 << 20 (GC_ERR_CAPACITY past it) */
    int volume;             /* 1 (default): build the whole 6-D hull, for its volume and facet count.
                             * 0: the fast path, no hull: closure flags by a linear program, epsilon
                             * and weakest by support queries (the same values); volume and facets
                             * are then -1 (not computed) */
    int reuse;              /* 0 (default). 1, with volume 0: the workspace keeps the answers of the
                             * last few sets it found in closure; a set whose edge wrenches are each
                             * within delta of one of those (same count), delta so small that the
                             * remembered epsilon less delta and the support of the same facet
                             * re-solved from the new wrenches are within 1e-12 relative, gets that
                             * facet (epsilon, weakest) without a new search: a held body in a still
                             * hand, whose contacts the haptic loop dithers in the last bits. Exact to
                             * those 1e-12; among equally near facets the weakest direction may be
                             * another than a fresh call's */
    const double *torsion;  /* NULL (default): point contacts. Else one value per contact (a batch: per
                             * row of its concatenated contacts): rho >= 0 (m), the radius of a soft
                             * contact's pressed patch; rho > 0 adds the wrenches (n, ((p - center) x n
                             * +- mu rho n) / radius): torsional friction about the normal up to
                             * mu rho Fn (GraspIt's soft contacts, docs/analysis.md) */
} gcGraspDef;
gcGraspDef gc_default_grasp_def(void);

typedef struct gcGraspQuality {
    int32_t force_closure;      /* 1: origin strictly inside the 6-D GWS */
    int32_t force_only_closure; /* 1: origin strictly inside the hull of the edge forces (3-D) */
    int32_t torque_closure;     /* 1: origin strictly inside the hull of the scaled edge torques (3-D) */
    int32_t rank;               /* dimension of the linear span of the edge wrenches, 0..6 */
    int32_t facets;             /* simplicial facets of the 6-D hull (0 when it is not full-dimensional) */
    int32_t reserved;
    double epsilon;             /* distance from the origin to the nearest facet; 0 when not in closure */
    double volume;              /* 6-D volume of the GWS; 0 when it is not full-dimensional */
    double weakest[6];          /* unit outward normal of the nearest facet (fx fy fz tx ty tz); 0 when not
                                 * in closure */
} gcGraspQuality;

typedef struct gcGraspWorkspace gcGraspWorkspace;
/* NULL when out of memory. */
gcGraspWorkspace *gc_grasp_workspace_create(void);
void gc_grasp_workspace_destroy(gcGraspWorkspace *ws);
/* Message for the last failed call with this workspace, naming the argument (empty when none). */
const char *gc_grasp_workspace_error(const gcGraspWorkspace *ws);

/* One contact set: num_contacts >= 0 rows of points, normals (xyz, inward, normalised here; a zero
 * normal is an error) and mu (>= 0). def NULL = defaults. */
gcStatus gc_grasp_quality(gcGraspWorkspace *ws, const gcGraspDef *def, const double *points,
                          const double *normals, const double *mu, int num_contacts, const double center[3],
                          double radius, gcGraspQuality *out);
/* num_sets contact sets: counts[s] contacts each, their rows concatenated in points, normals, mu;
 * centers 3 and radii 1 per set; out num_sets results. Stops at the first bad set (the message
 * names it). */
gcStatus gc_grasp_quality_batch(gcGraspWorkspace *ws, const gcGraspDef *def, const double *points,
                                const double *normals, const double *mu, const int32_t *counts, int num_sets,
                                const double *centers, const double *radii, gcGraspQuality *out);
/* The smallest friction coefficient (the same at every contact) at which the set is in force
 * closure, by bisection to 1e-6 (closure only grows with mu): 0 for frictionless closure,
 * INFINITY when not in closure at mu_max. */
gcStatus gc_grasp_mu_min(gcGraspWorkspace *ws, const gcGraspDef *def, const double *points,
                         const double *normals, int num_contacts, const double center[3], double radius,
                         double mu_max, double *out_mu);


#ifdef __cplusplus
}
#endif
#endif
