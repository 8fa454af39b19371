/* The contact system's private layout, shared only by the contact files (contacts.c,
 * contact_broadphase.c, contact_manifold.c, chains.c, contact_solver.c). Everything else
 * goes through contacts.h. See docs/solver.md. */
#ifndef GC_CONTACTS_INTERNAL_H
#define GC_CONTACTS_INTERNAL_H

#include "contacts.h"

#include "base/threadpool.h"
#include "world/world.h"

#include <stdint.h>

/* Tuning, SI units (docs/solver.md says why each value). */
#define GC_MANIFOLD_MAX_POINTS 4
#define GC_CONTACT_MARGIN 0.002        /* m: pairs closer than this get (speculative) points */
#define GC_CONTACT_SLOP 1e-5           /* m: penetration left alone by the position pass */
#define GC_POSITION_BETA 0.2           /* fraction of the penetration beyond slop removed per step */
#define GC_MAX_CORRECTION_SPEED 0.2    /* m/s: cap on the position pass's pseudo-velocity */
#define GC_ANCHOR_BETA 0.3             /* fraction of the friction-anchor error removed per step */
#define GC_ANCHOR_RESET 1e-4           /* m: an anchor this far from its contact point is renewed */
#define GC_SLIP_SPEED 1e-4             /* m/s: a saturated patch slower than this still sticks */
#define GC_VELOCITY_ITERATIONS 12      /* cap; the solve stops earlier once converged */
#define GC_SOLVER_TOLERANCE 1e-8       /* m/s: velocity error at which a chain's solve stops */
#define GC_POSITION_ITERATIONS 4
#define GC_FACE_CONTACT_COS 0.996      /* face clipping when a face normal is within ~5 deg of the normal */
#define GC_REUSE_DISTANCE 2e-5         /* m: a manifold is reused while the pair moved less than this */
#define GC_REUSE_ANGLE 2e-4            /* rad: ... and turned less than this relative to each other */

typedef struct gcManifoldPoint {
    gcVec3 local_a, local_b;     /* the contact on each surface, COM-relative body axes */
    gcVec3 anchor_a, anchor_b;   /* friction anchors (same frames) while anchored */
    gcVec3 point;                /* world, midway between the surfaces */
    double separation;           /* m, < 0 penetrating */
    double normal_impulse;       /* accumulated this step (warm start for the next) */
    gcVec3 friction_impulse;     /* accumulated, world */
    int anchored;                /* anchors valid (the manifold sticks and this point is pressed) */
} gcManifoldPoint;

/* Solver scratch of one manifold point, rebuilt every step (not copied between steps). */
typedef struct gcPointScratch {
    gcVec3 ang_a[3], ang_b[3];   /* r x d for d = n, t1, t2 */
    double wa[3][6], wb[3][6];   /* (effective mass)^-1 [d; r x d] per body (0 for static) */
    double inv_kn;               /* 1 / normal effective mass */
    double inv_kt[2][2];         /* inverse of the 2x2 tangential effective mass */
    double inv_kt_max;           /* 1 / its largest eigenvalue (isotropic step for sliding) */
    double lambda_t[2];          /* friction impulse on t1, t2 */
    double target_n, target_t[2];
    double position_impulse;
    int saturated;               /* friction was on the cone at its last update */
} gcPointScratch;

typedef struct gcManifold {
    int64_t key;                 /* part_a * max_parts + part_b, part_a < part_b */
    int32_t part_a, part_b, body_a, body_b;
    int num_points;
    gcVec3 normal;               /* world, from A towards B */
    gcVec3 t1, t2;
    double mu_s, mu_d;           /* combined: geometric means */
    int sticking;                /* 1: static friction (mu_s, anchors), 0: sliding (mu_d) */
    gcManifoldPoint points[GC_MANIFOLD_MAX_POINTS];
    /* Where the pair was when the manifold was last computed (for reuse): B's COM and axes
     * in A's COM frame, and the normal in A's axes. */
    gcVec3 ref_position;
    gcMat3 ref_rotation;
    gcVec3 normal_local_a;
    int reused;                  /* this step's points were refreshed, not recomputed */
} gcManifold;

typedef struct gcCandidate {
    int64_t key;
    int32_t part_a, part_b;
} gcCandidate;

struct gcContactSystem {
    int capacity;                /* max_contacts: manifolds (part pairs) */
    int num_manifolds, num_previous;
    gcManifold *manifolds, *previous; /* this step's and the last step's, sorted by key */
    int num_candidates;
    gcCandidate *candidates, *candidates_scratch; /* the second: radix-sort buffer */
    int32_t *sorted_bodies;      /* broad-phase order, kept between steps (insertion sort) */
    int num_sorted;
    gcVec3 *part_min, *part_max; /* world AABBs of the parts, inflated by the margin */
    int64_t overflow;            /* candidate pairs dropped for want of max_contacts */
    int full_pairs;              /* pairs computed in full (not reused) last step: pool heuristic */
    /* Chains (chains.c). */
    int32_t *parent;             /* union-find over bodies */
    int32_t *body_chain;         /* chain index per body, -1 for static bodies */
    int num_chains;
    int32_t *chain_body_start;   /* num_chains + 1 */
    int32_t *chain_bodies;
    int32_t *chain_manifold_start;
    int32_t *chain_manifolds;
    int32_t *cursor;             /* scratch for the counting sorts */
    /* Solver. */
    gcVec3 *pseudo_v, *pseudo_w; /* split-impulse position pass */
    double (*inv_mass)[36];      /* per body: (effective mass)^-1, row-major 6x6, this step */
    gcPointScratch *scratch;     /* GC_MANIFOLD_MAX_POINTS per manifold slot */
    double dt;
    gcPool *pool;
};

/* The jobs of a step, in order. contact_broadphase.c: candidate part pairs. */
void gc_broad_phase(gcWorld *world);
/* contact_manifold.c: a manifold per candidate (in parallel), compacted in key order. */
void gc_narrow_phase(gcWorld *world);
/* chains.c: collision chains from the manifolds. */
void gc_chains_build(gcWorld *world);
/* contact_solver.c: a chain's solve (prepare, warm start, velocity and position passes). */
void gc_contacts_solve_chain(gcWorld *world, int chain, double dt);

/* Unit tangents t1, t2 with (n, t1, t2) right-handed; a fixed function of n. */
static inline void gc_tangent_basis(gcVec3 n, gcVec3 *t1, gcVec3 *t2) {
    gcVec3 a = fabs(n.x) < 0.57735 ? gc_v3(1, 0, 0) : (fabs(n.y) < 0.57735 ? gc_v3(0, 1, 0) : gc_v3(0, 0, 1));
    *t1 = gc_normalize(gc_cross(n, a));
    *t2 = gc_cross(n, *t1);
}

static inline double gc_hull_extent(const gcHull *h) { return gc_len(gc_sub(h->aabb_max, h->aabb_min)) + 2.0 * h->radius; }


#endif
