/* HIP input of the haptic loop (docs/runtime.md "Input"): what the loop makes of its inputs at
 * its own tick times, so that the haptic rate never depends on how often the caller pushes.
 *   - a scripted track (gc_world_set_hip_track): whole trajectories, sampled at every tick;
 *   - timestamped samples (gc_world_push_hips): the loop moves each HIP from where it is to the
 *     newest sample over the interval between the last two samples, at a bounded speed. */
#ifndef GC_HIP_INPUT_H
#define GC_HIP_INPUT_H

#include "world/body.h"

/* The world's scripted track: samples at increasing times, shared by all its fingers. */
typedef struct gcHipTrack {
    int num_samples, num_fingers;
    double *times;              /* num_samples, strictly increasing */
    double *positions;          /* num_samples x num_fingers x 3 */
    unsigned char *scripted;    /* num_fingers: 1 = the track drives this finger */
    double *orientations;       /* NULL (positions only) or num_samples x num_fingers x 4
                                 * (w x y z), as given (gc_world_set_hip_track_orientations) */
} gcHipTrack;

/* One finger following timestamped samples: a straight segment walked over `duration`. */
typedef struct gcHipFollow {
    gcVec3 from, to;
    double elapsed, duration;
    int turns;                  /* 1: the sample carried an orientation, walked with the position */
    gcQuat q_from, q_to;        /* q_to as pushed (normalised where applied) */
} gcHipFollow;

/* Longest interval a segment is stretched over: a sample older than this is reached sooner. */
#define GC_HIP_MAX_SEGMENT 0.25
/* A device's soft start (docs/devices.md): from its first pose of a session or of a connection,
 * the HIP walks to the device at most this fast (m/s) until it has reached it. */
#define GC_HIP_SOFT_START_SPEED 0.2

/* Position of `finger` at time t since the start of the track's times (times[0] + t), linear
 * between samples, held before the first and after the last. As the Python SampledTrajectory
 * computes it, operation for operation, so a threaded run sees the HIPs of a synchronous one. */
gcVec3 gc_hip_track_sample(const gcHipTrack *track, int finger, double t);
/* Orientation of `finger` at the same time as gc_hip_track_sample: the normalised lerp of the
 * two samples around it (the second's sign taken into the first's hemisphere), returned before
 * normalising, which the caller does as gc_world_set_finger_pose does. Held past either end.
 * 0 (out untouched) when the track carries no orientations. */
int gc_hip_track_orientation(const gcHipTrack *track, int finger, double t, gcQuat *out);
int gc_hip_track_drives(const gcHipTrack *track, int finger);
/* 1 when the track drives every finger of the world (no pushed input is expected). */
int gc_hip_track_covers(const gcHipTrack *track, int num_fingers);
void gc_hip_track_free(gcHipTrack *track);

/* A new sample `target` that the caller took `interval` s after its previous one. */
void gc_hip_follow_retarget(gcHipFollow *f, gcVec3 current, gcVec3 target, double interval, double dt);
/* The HIP one tick later, at most max_speed * dt from `current` (max_speed 0: unbounded). */
gcVec3 gc_hip_follow_advance(gcHipFollow *f, gcVec3 current, double dt, double max_speed);
/* After gc_hip_follow_retarget: the sample's orientation too, turned to from `current` over the
 * same interval (normalised lerp, the shorter arc; max_speed bounds positions only). */
void gc_hip_follow_turn_to(gcHipFollow *f, gcQuat current, gcQuat target);
/* After gc_hip_follow_advance: the orientation at the same point of the walk, before the
 * normalisation gc_world_set_finger_pose does; 0 (out untouched) when the sample had none. */
int gc_hip_follow_orientation(const gcHipFollow *f, gcQuat *out);

#endif
