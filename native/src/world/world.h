/* The world's layout (types only, no functions), shared by every layer of the core; the
 * layers themselves are listed in docs/architecture.md. */
#ifndef GC_WORLD_INTERNAL_H
#define GC_WORLD_INTERNAL_H

#include "geometry/geometry.h"
#include "graspcore.h"

#include <stdint.h>

/* gcWorldDef limits (checked by gc_world_create) and the contacts' default capacity. */
#define GC_MAX_THREADS 64
#define GC_MAX_CONTACTS_LIMIT (1 << 22)
#define GC_DEFAULT_MAX_CONTACTS 2048

/* One convex part of a body: its hull in the body frame. */
typedef struct gcPart {
    gcHull hull;
    int32_t body;
} gcPart;

/* What a step changes on a body (its "data" beside its gcBodyModel, as MuJoCo splits
 * mjData from mjModel): a plain value, so the runtime's shadows copy it whole and a
 * snapshot reads it without touching the world it came from. */
typedef struct gcBodyState {
    gcVec3 com;                     /* world; the COM is integrated, the frame origin derived */
    gcQuat q;                       /* body frame orientation */
    gcMat3 R;                       /* rotation of q (the world inertia is R I R^T) */
    gcVec3 v, w;                    /* linear (of the COM) and angular velocity, world */
    gcVec3 aabb_min, aabb_max;      /* world, of all parts, refreshed each step */
    gcVec3 residual_force, residual_torque; /* what the last step applied */
} gcBodyState;

/* A body's model: set when it is added (friction and damping by their setters, between
 * steps); no step changes it. */
typedef struct gcBodyModel {
    int is_static;
    int first_part, num_parts;      /* parts[first_part .. first_part+num_parts) */
    double mass, inv_mass;
    gcVec3 com_local;               /* centre of mass in the body frame */
    gcMat3 inertia_local;           /* about the COM, body axes */
    gcMat3 inv_inertia_local;
    double mu_s, mu_d, viscosity;
    double linear_damping, angular_damping;
} gcBodyModel;

/* A body in a world's state: its gcBodyState and the step's scratch. */
typedef struct gcBody {
    gcBodyState state;
    /* Step scratch: the effective mass used for this step's velocity, which contact
     * impulses go through. With a finger on the body (coupled) it is the mass matrix plus
     * the implicit finger coupling, kept as a 6x6 Cholesky factor; otherwise it is block
     * diagonal: inv_mass and the inverse world inertia at the orientation
     * inertia_rotation (formed only for bodies in contact). */
    int coupled;
    double effective_mass_factor[6][6];
    gcMat3 inertia_rotation;
    int effective_mass_valid;
    /* Momentum at the start of the step: the residual wrench is its rate of change. */
    gcVec3 step_start_momentum, step_start_angular_momentum;
    /* Pose at the start of the step, where a body whose state would turn non-finite is
     * stopped (nonfinite: its velocity solve broke down this step). */
    gcVec3 step_start_com;
    gcQuat step_start_q;
    int nonfinite;
} gcBody;

/* Contact between one finger and one part. The god-object (GO) and the contact plane
 * live in the part's body frame so that they move with the body. */
typedef struct gcFingerContact {
    int32_t part;                   /* -1 when the slot is unused */
    gcFingerState state;            /* FREE, STICK or SLIP */
    gcVec3 go_local;                /* god-object centre, body frame */
    gcVec3 normal_local;            /* contact plane normal (outward), body frame */
    double depth;                   /* HIP depth below the GO plane, last step */
    /* A soft fingertip (torsion > 0): the god-direction, the twist about the normal the body
     * holds for the finger (a unit vector in the contact plane, body frame), and the twist of
     * the finger's frame past it (rad, about the normal out of the body) after the last update. */
    gcVec3 twist_local;
    double twist;
    int32_t twist_axis;             /* the finger-frame axis (0 x, 1 y, 2 z) whose direction in the plane is
                                     * the finger's twist: the least aligned with the normal at touch */
    gcFingerState twist_state;      /* the twist's own stick or slip */
    /* A sphere finger, or a vertex of a convex finger entering a body (sample: its index): the GO
     * is on the body, in the body frame, and its spring pulls the vertex. Reversed: a vertex of the
     * body (sample: its index in the part, at body_point_local) entering a convex finger: the GO is
     * on the finger's surface, in the finger frame, and its spring pulls the body's vertex. */
    int32_t sample;
    int32_t reversed;
    gcVec3 body_point_local;        /* reversed: the body's vertex, body frame */
    double share;                   /* weight of its spring in the finger's force (xfca.c: seams) */
} gcFingerContact;

/* A sphere finger touches at most 8 parts at once; a convex finger's vertices together hold at
 * most GC_MAX_FINGER_CONTACTS contacts (docs/physics.md "Area contacts"): a face on a face takes 4. */
#define GC_MAX_CONTACTS_PER_FINGER 8
#define GC_MAX_FINGER_CONTACTS 16

/* A finger's model: set when it is added; no step changes it. */
typedef struct gcFingerModel {
    double radius, stiffness, damping;
    double torsion;                 /* soft fingertip: radius of its pressed patch (m), 0 = none */
    gcFingerRenderer renderer;      /* xFCA god-objects, or the light-mass cursor (cursor.c) */
    double cursor_mass;             /* kg, the cursor renderer's */
    /* Convex finger: its hull's vertices in the finger frame (0 = a sphere of radius), each a
     * point of contact with a god-object of its own; the HIP is the frame's pose. */
    int num_vertices;
    gcVec3 vertices[GC_MAX_FINGER_VERTICES];
} gcFingerModel;

/* A finger in a world's state. */
typedef struct gcFinger {
    gcVec3 cursor, cursor_velocity; /* the cursor's centre and velocity, world (cursor renderer) */
    gcVec3 hip, hip_prev, hip_velocity;
    int hip_initialised;
    int num_contacts;
    gcFingerContact contacts[GC_MAX_FINGER_CONTACTS];
    /* Outputs. */
    gcVec3 god_object;              /* world: force-weighted GO, or the HIP when free */
    gcVec3 force;                   /* rendered to the device: k (GO - HIP) + damping */
    gcVec3 torque;                  /* convex finger: about the HIP, sum (GO_i - HIP) x f_i; 0 for a sphere */
    gcVec3 normal;                  /* world: the reported contact's outward normal, 0 when free */
    /* A convex finger's contact patch on the reported body, for the grasp analysis: up to
     * GC_FINGER_PATCH_CORNERS corners of the hull of its contact points (on the body's surface)
     * as offsets (u, v) from the reported contact point along the analysis's tangent axes t1, t2
     * of the inward normal; fewer corners: the last repeats. All zero for a sphere finger. */
    float patch[2 * GC_FINGER_PATCH_CORNERS];
    int32_t contact_body;           /* -1 when free */
    gcFingerState state;
    /* The finger frame's orientation: what a convex finger turns with; any finger reports it. */
    gcQuat q, q_prev;
    gcMat3 R, R_prev;
    gcVec3 hip_angular_velocity;
} gcFinger;

/* While the runtime runs: what the last gc_world_snapshot showed. The world's queries
 * answer from it, so a snapshot never writes into the simulation state of the world. */
typedef struct gcShown {
    double time;
    gcBodyState *bodies;            /* per body */
    gcFinger *fingers;              /* per finger: hip, god_object, force, state, contact_body */
} gcShown;

/* The model (MuJoCo's mjModel): what no step changes. The world API edits it between steps
 * (never while the runtime runs: `locked`); the world and the runtime's shadows read the one
 * copy, which the world owns. Sized by the world's capacities at creation. */
typedef struct gcModel {
    gcVec3 gravity;
    int num_parts;
    gcPart *parts;                  /* max_parts */
    gcBodyModel *bodies;            /* max_bodies; the world's num_bodies are in use */
    gcFingerModel *fingers;         /* max_fingers; the world's num_fingers are in use */
    /* Convex fingers' hulls in the finger frame, inflated by the finger radius (max_fingers). */
    gcHull *finger_hulls;
} gcModel;

struct gcWorld {
    /* Configuration, as created (a shadow: its own copy, with its own thread count). */
    gcWorldDef def;
    /* The model, read-only in a step: own_model for the world, the world's for a shadow
     * (whose own_model is NULL). */
    const gcModel *model;
    gcModel *own_model;
    /* The state (MuJoCo's mjData): what a step changes. A runtime shadow holds its own copy
     * of all of it, in arrays of its own, and no pointer of the world's but the model
     * (runtime.c: shadow_alloc, shadow_load). */
    double time;
    int num_bodies, num_fingers;
    gcBody *bodies;
    gcFinger *fingers;
    /* Zero-copy output arrays, sized by the capacities. */
    double *pose_array;             /* 7 per body */
    double *god_object_array;       /* 3 per finger */
    double *force_array;            /* 3 per finger */
    double *hip_array;              /* 3 per finger */
    /* Bodies stopped because their state would have become non-finite: since creation, and
     * in the current step (the first one's id, for the message). */
    int64_t stopped_bodies;
    int step_stopped_bodies;
    int32_t first_stopped_body;
    /* Contacts (manifolds and their warm starts), chains and the worker pool (contacts.c,
     * chains.c, threadpool.c): a shadow has its own. */
    struct gcContactSystem *contacts;
    /* NULL: a step moves every dynamic body. Otherwise only bodies with body_active[i] != 0
     * move; the others are stepped by another runtime thread and are immovable here (their
     * effective mass is marked invalid). Set only in the runtime's per-thread shadows. */
    const unsigned char *body_active;
    char last_error[256];
    /* The world's services, NULL in a shadow. */
    /* Runtime (runtime.c): made on the first gc_world_start, freed by gc_world_destroy. */
    struct gcRuntime *runtime;
    /* Per-tick log for recorders (tick_log.c); NULL when off. */
    struct gcTickLog *tick_log;
    /* Devices (device_hub.c): made with the world, so that one may attach before the runtime starts. */
    struct gcDeviceHub *hub;
    /* Scripted HIP track (hip_input.c), sampled by the runtime's haptic loop. */
    struct gcHipTrack *hip_track;
    /* 1 while the runtime owns the dynamic state: calls that would change it are refused. */
    int locked;
    /* The runtime's gcShown while it runs, NULL otherwise. */
    const gcShown *shown;
};

/* The body frame (the user's origin, not the centre of mass) as a transform, from a body's
 * model and a state of it. */
static inline gcTransform gc_body_transform(const gcBodyModel *m, const gcBodyState *s) {
    gcTransform t;
    t.R = s->R;
    t.p = gc_sub(s->com, gc_mat3_mul_vec(&s->R, m->com_local));
    return t;
}

/* Body b's frame in a world (or shadow): its model and its state there. */
static inline gcTransform gc_world_body_transform(const gcWorld *w, int32_t b) {
    return gc_body_transform(&w->model->bodies[b], &w->bodies[b].state);
}

/* The HIP of contact sample s: a sphere finger's HIP, or vertex s of a convex finger at the
 * finger's pose (now, at the previous step, and its velocity); m is the finger's model. */
static inline gcVec3 gc_finger_tip(const gcFingerModel *m, const gcFinger *f, int s) {
    return m->num_vertices ? gc_add(f->hip, gc_mat3_mul_vec(&f->R, m->vertices[s])) : f->hip;
}
static inline gcVec3 gc_finger_tip_prev(const gcFingerModel *m, const gcFinger *f, int s) {
    return m->num_vertices ? gc_add(f->hip_prev, gc_mat3_mul_vec(&f->R_prev, m->vertices[s])) : f->hip_prev;
}
static inline gcVec3 gc_finger_tip_velocity(const gcFingerModel *m, const gcFinger *f, int s) {
    if (!m->num_vertices) return f->hip_velocity;
    return gc_add(f->hip_velocity, gc_cross(f->hip_angular_velocity, gc_mat3_mul_vec(&f->R, m->vertices[s])));
}

/* The two ends of a finger contact's spring, world: the finger's end (anchor: its HIP or vertex,
 * or for a reversed contact the GO on its surface) with that point's velocity, and the body point
 * (the GO on the body, or the body's vertex) where the body receives the reaction. */
static inline void gc_finger_contact_ends(const gcFingerModel *m, const gcFinger *f, const gcFingerContact *c,
                                          const gcTransform *body, gcVec3 *anchor, gcVec3 *anchor_velocity,
                                          gcVec3 *body_point) {
    if (!c->reversed) {
        *anchor = gc_finger_tip(m, f, c->sample);
        *anchor_velocity = gc_finger_tip_velocity(m, f, c->sample);
        *body_point = gc_transform_point(body, c->go_local);
        return;
    }
    gcVec3 arm = gc_mat3_mul_vec(&f->R, c->go_local);
    *anchor = gc_add(f->hip, arm);
    *anchor_velocity = gc_add(f->hip_velocity, gc_cross(f->hip_angular_velocity, arm));
    *body_point = gc_transform_point(body, c->body_point_local);
}

/* A finger contact's normal, world, outward from the body. */
static inline gcVec3 gc_finger_point_normal(const gcFinger *f, const gcFingerContact *c, const gcMat3 *body_R) {
    return c->reversed ? gc_neg(gc_mat3_mul_vec(&f->R, c->normal_local)) : gc_mat3_mul_vec(body_R, c->normal_local);
}

#endif
