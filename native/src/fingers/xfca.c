/* Extended friction cone algorithm (xFCA): one god-object (GO) per finger per convex
 * part, kept on the part's surface and inside the friction circle of radius mu*depth
 * around the surface object (SO, the frictionless projection of the HIP).
 * The algorithm is the source chapter's (Harwin & Barrow, "Multi-finger grasps in a dynamic
 * environment"); docs/physics.md says how we read it, and the numbered steps below follow it.
 * All positions here are fingertip-sphere centres: the surface the centre sees is the
 * part inflated by the finger radius, so a point finger is radius 0. */
#include "xfca.h"

#include "cursor.h"

#include <string.h>

/* Conservative advancement is capped; a miss after the cap is treated as no contact
 * this step (the HIP is then still outside, so nothing is lost). */
#define GC_SWEEP_MAX_ITERATIONS 32
/* The sweep stops within this distance of the surface (m). */
#define GC_SWEEP_GAP 1e-6
/* Relative round-off allowed on the friction circle's radius. */
#define GC_CIRCLE_TOLERANCE 1e-9
/* Distances below this count as touching (m). */
#define GC_CONTACT_SLOP 1e-9
/* Smallest push toward the HIP (m): keeps a GO resting on a flat face in contact
 * despite rounding, far below anything a device resolves. */
#define GC_MIN_PUSH 1e-7
/* A push never exceeds this fraction of the part's thinnest width: no push-through. */
#define GC_PUSH_WIDTH_FRACTION 0.25

/* Signed distance of a fingertip centre to the part's surface, seen by a sphere of radius r. */
static double tip_query(const gcHull *h, gcVec3 p, double r, gcVec3 *normal) {
    double sd;
    gcVec3 sp;
    gc_point_query(h, p, &sd, &sp, normal);
    return sd - r;
}

/* Push depth that keeps the GO on a convex surface after a tangential move of dmax:
 * the surface falls rc - sqrt(rc^2 - dmax^2) below its tangent plane (docs/physics.md, step 5).
 * The inflated surface of a polyhedron has its tightest curvature, r, at the rounded
 * edges; for a point finger we allow a 45-degree fall. Bounded by the depth (never past
 * the HIP) and by a fraction of the part's thinnest width (never through a plate). */
static double push_depth(double rc, double dmax, double depth, double min_width) {
    double fall;
    if (rc <= 0.0)
        fall = dmax;
    else if (dmax >= rc)
        fall = rc;
    else
        fall = rc - sqrt(rc * rc - dmax * dmax);
    double push = fall + GC_MIN_PUSH;
    push = fmin(push, depth);
    push = fmin(push, GC_PUSH_WIDTH_FRACTION * min_width);
    return fmax(push, 0.0);
}

/* What a contact's god-object slides on: the hull (a body's part, or a convex finger for a
 * reversed contact), the radius of the sphere that enters it, and the body's friction. */
typedef struct gcSurface {
    const gcHull *hull;
    double radius;            /* of the entering sphere (the fingertip, or a body vertex's margin) */
    double mu_s, mu_d, viscosity;
} gcSurface;

/* Steps 4-6 for an existing contact, in the hull's frame. Returns 0 when contact is lost. */
static int update_contact(const gcSurface *sf, gcFingerContact *c, gcVec3 hip, double dt) {
    const gcHull *h = sf->hull;
    gcVec3 n = c->normal_local;
    double depth = gc_dot(n, gc_sub(c->go_local, hip));
    if (depth <= 0.0) return 0; /* the HIP crossed the GO's plane */
    c->depth = depth;
    gcVec3 so = gc_madd(hip, n, depth);
    /* Friction circle around the SO (step 4): the GO's offset in the plane. */
    gcVec3 offset = gc_sub(c->go_local, so);
    offset = gc_madd(offset, n, -gc_dot(offset, n));
    double dist = gc_len(offset);
    gcVec3 go = gc_add(so, offset);
    double static_radius = sf->mu_s * depth, dynamic_radius = sf->mu_d * depth;
    /* A GO left on the mu_d circle by the previous step is at rest on the surface: the
     * tolerance keeps re-surfacing round-off from counting as sliding. */
    int slipping;
    if (c->state == GC_FINGER_STICK)
        slipping = dist > static_radius;
    else
        slipping = dist > dynamic_radius * (1.0 + GC_CIRCLE_TOLERANCE) + GC_CONTACT_SLOP;
    if (slipping) {
        /* Onto the Coulomb (mu_d) circle; with viscosity, no further than the viscous
         * radius depth*dt/viscosity per step, so faster sliding trails further. */
        gcVec3 target = gc_madd(so, offset, dynamic_radius / dist);
        if (sf->viscosity > 0.0) {
            double max_move = depth * dt / sf->viscosity;
            gcVec3 move = gc_sub(target, go);
            double len = gc_len(move);
            if (len > max_move) target = gc_madd(go, move, max_move / len);
        }
        go = target;
        c->state = GC_FINGER_SLIP;
    } else {
        c->state = GC_FINGER_STICK;
    }
    double dmax = gc_len(gc_sub(go, c->go_local));
    /* Step 5: push toward the HIP so the GO cannot leave a convex surface. */
    double rc = sf->radius + h->radius;
    go = gc_madd(go, n, -push_depth(rc, dmax, depth, h->min_width + 2.0 * h->radius));
    /* Step 6: collision pass of the GO against the part, re-surface along the normal. */
    gcVec3 nn;
    double sd = tip_query(h, go, sf->radius, &nn);
    if (sd > GC_CONTACT_SLOP) return 0; /* the surface fell away faster than allowed */
    go = gc_madd(go, nn, -sd);
    c->go_local = go;
    c->normal_local = nn;
    return 1;
}

/* First contact (steps 1-3): sweep the fingertip from the previous HIP to the current one
 * by conservative advancement, so a fast HIP enters through the face it crossed. */
static int find_entry(double radius, const gcHull *h, gcVec3 from, gcVec3 to, gcVec3 *go, gcVec3 *normal) {
    gcVec3 seg = gc_sub(to, from);
    double len = gc_len(seg);
    gcVec3 n;
    double d = tip_query(h, from, radius, &n);
    if (d <= GC_CONTACT_SLOP) {
        /* Already inside at the start (the body moved onto the finger, or the first
         * step): leave along the least-penetration normal. */
        d = tip_query(h, to, radius, &n);
        if (d > GC_CONTACT_SLOP) return 0;
        *go = gc_madd(to, n, -d);
        *normal = n;
        return 1;
    }
    if (len <= 0.0) return 0;
    /* Advance to a small gap short of the surface, where the normal is well defined
     * (a point exactly on an edge has no unique one). */
    double t = 0.0;
    for (int it = 0; it < GC_SWEEP_MAX_ITERATIONS; ++it) {
        t += (d - 0.5 * GC_SWEEP_GAP) / len;
        if (t >= 1.0) {
            d = tip_query(h, to, radius, &n);
            if (d > GC_CONTACT_SLOP) return 0;
            t = 1.0;
        }
        gcVec3 p = gc_madd(from, seg, t);
        d = tip_query(h, p, radius, &n);
        if (d <= GC_SWEEP_GAP || t >= 1.0) {
            *go = gc_madd(p, n, -d);
            *normal = n;
            return 1;
        }
    }
    return 0;
}

static int has_contact_with(const gcFinger *f, int32_t part, int32_t sample, int32_t reversed) {
    for (int i = 0; i < f->num_contacts; ++i)
        if (f->contacts[i].part == part && f->contacts[i].sample == sample && f->contacts[i].reversed == reversed)
            return 1;
    return 0;
}

/* Rotation vector of q * conj(p): the finger frame's turn over the step. */
static gcVec3 turn_between(gcQuat p, gcQuat q) {
    gcQuat pc = {p.w, -p.x, -p.y, -p.z};
    gcQuat d = gc_quat_mul(q, pc);
    if (d.w < 0.0) d.w = -d.w, d.x = -d.x, d.y = -d.y, d.z = -d.z;
    gcVec3 v = gc_v3(d.x, d.y, d.z);
    double s = gc_len(v);
    if (!(s > 0.0)) return gc_v3(0, 0, 0);
    return gc_scale(v, 2.0 * atan2(s, d.w) / s);
}

static gcSurface body_surface(const gcBodyModel *b, const gcHull *h, double radius) {
    gcSurface sf = {h, radius, b->mu_s, b->mu_d, b->viscosity};
    return sf;
}

/* The body frame a convex finger's contacts are evaluated in: the body's pose advanced by its
 * velocity over the step. The HIP has already moved this step and the body not yet, so on the
 * current pose a carried body would lag its HIP by v dt, which the friction circle of a light
 * load on several points (mu k depth is a few tenths of a millimetre) mistakes for sliding: a pad
 * carrying a 0.5 kg box on 4 points at 10 kN/m slipped at 0.1 m/s (docs/physics.md "Area
 * contacts"). Sphere fingers keep the current pose (their results are unchanged). */
static gcTransform predicted_transform(const gcBodyModel *m, const gcBody *b, double dt) {
    if (m->is_static) return gc_body_transform(m, &b->state);
    gcQuat q = gc_quat_normalize(gc_quat_mul(gc_quat_from_rotation_vector(gc_scale(b->state.w, dt)), b->state.q));
    gcTransform t;
    t.R = gc_quat_to_mat3(q);
    t.p = gc_sub(gc_madd(b->state.com, b->state.v, dt), gc_mat3_mul_vec(&t.R, m->com_local));
    return t;
}

/* The finger's frame as a transform (its HIP and orientation). */
static gcTransform finger_transform(const gcFinger *f) {
    gcTransform t;
    t.R = f->R;
    t.p = f->hip;
    return t;
}

/* Seams of a decomposed body. Where one finger touches several convex parts of one body,
 * each part has its own GO. Two things go wrong when their springs are simply summed:
 * near a seam between parts of one smooth surface, two GOs sit on nearly the same plane at
 * nearly the same depth, so the force doubles; and at a seam, a part's GO on its own
 * rounded edge lies inside the neighbouring part, off the body's surface, and pushes the
 * finger back as a ridge would. So each spring i is weighted by
 *   share_i = e_i / sum_j e_j max(0, n_i . n_j),   e_i = g_i d_i,
 *   g_i = max(0, 1 - (b_i - b_min) / (GC_SEAM_BURIAL * D))
 * over the finger's contacts on the same body: d depth, n plane normal, D the deepest d,
 * b how deep the GO lies inside the other parts touched (inflated by the finger radius)
 * and b_min the least b. Parallel planes at equal depth share the force (the mean); planes
 * 90 degrees or more apart (a real crease, the two walls of a slot) add (share 1). Only a
 * GO buried deeper than the others loses weight: in a concave crease every GO lies inside
 * the other part (by the other's depth), so equal depths keep the plain sum there. A
 * contact that starts or ends at zero depth, or sinks into a neighbour, weighs nothing
 * then, so the total stays continuous. A lone contact has share exactly 1 (d / d), as
 * before. docs/physics.md. */
#define GC_SEAM_BURIAL 1.0

static void blend_seams(const gcWorld *w, const gcFingerModel *fm, gcFinger *f) {
    const gcModel *model = w->model;
    double effective[GC_MAX_CONTACTS_PER_FINGER], burial[GC_MAX_CONTACTS_PER_FINGER];
    int shared[GC_MAX_CONTACTS_PER_FINGER];
    for (int i = 0; i < f->num_contacts; ++i) {
        const gcFingerContact *c = &f->contacts[i];
        int32_t body = model->parts[c->part].body;
        effective[i] = c->depth;
        burial[i] = 0.0;
        shared[i] = 0;
        for (int j = 0; j < f->num_contacts; ++j) {
            const gcFingerContact *o = &f->contacts[j];
            if (j == i || model->parts[o->part].body != body) continue;
            shared[i] = 1;
            gcVec3 n;
            burial[i] = fmax(burial[i], -tip_query(&model->parts[o->part].hull, c->go_local, fm->radius, &n));
        }
    }
    for (int i = 0; i < f->num_contacts; ++i) {
        if (!shared[i]) continue;
        const gcFingerContact *c = &f->contacts[i];
        int32_t body = model->parts[c->part].body;
        double deepest = 0.0, least = burial[i];
        for (int j = 0; j < f->num_contacts; ++j) {
            if (model->parts[f->contacts[j].part].body != body) continue;
            deepest = fmax(deepest, f->contacts[j].depth);
            least = fmin(least, burial[j]);
        }
        double sunk = burial[i] - least;
        if (sunk > 0.0) effective[i] = c->depth * fmax(0.0, 1.0 - sunk / (GC_SEAM_BURIAL * deepest));
    }
    for (int i = 0; i < f->num_contacts; ++i) {
        gcFingerContact *c = &f->contacts[i];
        int32_t body = model->parts[c->part].body;
        double overlap = 0.0;
        for (int j = 0; j < f->num_contacts; ++j) {
            const gcFingerContact *o = &f->contacts[j];
            if (model->parts[o->part].body != body) continue;
            overlap += effective[j] * (j == i ? 1.0 : fmax(0.0, gc_dot(c->normal_local, o->normal_local)));
        }
        c->share = overlap > 0.0 ? effective[i] / overlap : 0.0;
    }
}

/* Two convex shapes touch from one side: a new contact of a convex finger with a part whose
 * normal (out of the body, world) opposes one the finger already has with that part entered from
 * the far side (the HIP went through a thin plate, its far vertices then met the plate's far face)
 * and is refused; the existing god-objects keep the finger on the side it touched first. */
static int opposes_existing(const gcFinger *f, const gcBody *b, int32_t part, gcVec3 normal_world) {
    for (int i = 0; i < f->num_contacts; ++i) {
        const gcFingerContact *c = &f->contacts[i];
        if (c->part == part && gc_dot(gc_finger_point_normal(f, c, &b->state.R), normal_world) < 0.0) return 1;
    }
    return 0;
}

/* New contacts of one contact sample (a sphere finger's HIP, or one vertex of a convex finger):
 * broad phase on its swept box, then the sweep per part. */
static void find_new_contacts(gcWorld *w, const gcFingerModel *fm, gcFinger *f, int32_t sample, int capacity,
                              double dt) {
    gcVec3 now = gc_finger_tip(fm, f, sample), prev = gc_finger_tip_prev(fm, f, sample);
    /* The swept box of finite points: gc_min/gc_max (fmin/fmax are libm calls). */
    gcVec3 lo = gc_v3(gc_min(now.x, prev.x), gc_min(now.y, prev.y), gc_min(now.z, prev.z));
    gcVec3 hi = gc_v3(gc_max(now.x, prev.x), gc_max(now.y, prev.y), gc_max(now.z, prev.z));
    gcVec3 pad = gc_v3(fm->radius, fm->radius, fm->radius);
    lo = gc_sub(lo, pad);
    hi = gc_add(hi, pad);
    /* The model in a local, as in every step function: the extension builds with
     * -fno-strict-aliasing, so w->model would be read again after each store. */
    const gcModel *model = w->model;
    for (int32_t bi = 0; bi < w->num_bodies && f->num_contacts < capacity; ++bi) {
        const gcBody *b = &w->bodies[bi];
        const gcBodyModel *bm = &model->bodies[bi];
        if (!gc_aabb_overlap(lo, hi, b->state.aabb_min, b->state.aabb_max)) continue;
        gcTransform fr = fm->num_vertices ? predicted_transform(bm, b, dt) : gc_body_transform(bm, &b->state);
        gcVec3 from = gc_inv_transform_point(&fr, prev), to = gc_inv_transform_point(&fr, now);
        for (int p = bm->first_part; p < bm->first_part + bm->num_parts; ++p) {
            if (f->num_contacts >= capacity) break;
            if (has_contact_with(f, p, sample, 0)) continue;
            const gcHull *h = &model->parts[p].hull;
            gcVec3 go, n;
            if (!find_entry(fm->radius, h, from, to, &go, &n)) continue;
            if (fm->num_vertices && opposes_existing(f, b, p, gc_mat3_mul_vec(&b->state.R, n))) continue;
            gcFingerContact c;
            memset(&c, 0, sizeof c);
            c.part = p;
            c.sample = sample;
            c.state = GC_FINGER_STICK;
            c.go_local = go;
            c.normal_local = n;
            gcSurface sf = body_surface(bm, h, fm->radius);
            if (update_contact(&sf, &c, to, dt)) f->contacts[f->num_contacts++] = c;
        }
    }
}

/* Points along a body's feature edges, as reversed contacts: spaced no wider than the finger's
 * thinnest width, so an edge crossing the finger (a pencil across a palm, a can's side along
 * it) has a point inside it whenever the edge passes through the finger; at most this many per
 * edge. A point's sample id is num_vertices + edge * GC_EDGE_SAMPLES + k. */
#define GC_EDGE_SAMPLES 32

/* The reversed candidate at body point x (body frame): swept in the finger's frame from where
 * it was against the finger a step ago (the body now, the finger at its previous pose) to
 * where it will be (the body's predicted pose, the finger now). */
static void try_reversed(gcFinger *f, const gcHull *fh, const gcBodyModel *bm, const gcBody *b, int32_t part,
                         const gcHull *h, int32_t sample, gcVec3 x, const gcTransform *fr, const gcTransform *fr_prev,
                         const gcTransform *ff, const gcTransform *ff_prev, double dt) {
    if (has_contact_with(f, part, sample, 1)) return;
    gcVec3 v = gc_inv_transform_point(ff, gc_transform_point(fr, x)), go, n;
    gcVec3 v_prev = gc_inv_transform_point(ff_prev, gc_transform_point(fr_prev, x));
    if (!find_entry(h->radius, fh, v_prev, v, &go, &n)) return;
    if (opposes_existing(f, b, part, gc_neg(gc_mat3_mul_vec(&f->R, n)))) return;
    gcFingerContact c;
    memset(&c, 0, sizeof c);
    c.part = part;
    c.sample = sample;
    c.reversed = 1;
    c.body_point_local = x;
    c.state = GC_FINGER_STICK;
    c.go_local = go;
    c.normal_local = n;
    gcSurface sf = body_surface(bm, fh, h->radius);
    if (update_contact(&sf, &c, v, dt)) f->contacts[f->num_contacts++] = c;
}

static int outside_box(gcVec3 p, gcVec3 lo, gcVec3 hi, double pad) {
    return p.x < lo.x - pad || p.y < lo.y - pad || p.z < lo.z - pad || p.x > hi.x + pad || p.y > hi.y + pad ||
           p.z > hi.z + pad;
}

/* Reversed contacts of a convex finger: the vertices of the bodies' parts inside the finger (a
 * box corner on a palm wider than the box), and points along their edges (a can's side across
 * a palm), each with a god-object on the finger's surface. Without them a body smaller than
 * the finger's face would pass between its vertices (docs/physics.md "Area contacts"). */
static void find_reversed_contacts(gcWorld *w, const gcFingerModel *fm, gcFinger *f, const gcHull *fh, double dt) {
    const gcModel *model = w->model;
    gcTransform ff = finger_transform(f), ff_prev;
    ff_prev.R = f->R_prev;
    ff_prev.p = f->hip_prev;
    gcVec3 lo = gc_v3(INFINITY, INFINITY, INFINITY), hi = gc_neg(lo);
    for (int s = 0; s < fm->num_vertices; ++s) {
        gcVec3 v = gc_finger_tip(fm, f, s);
        lo = gc_v3(fmin(lo.x, v.x), fmin(lo.y, v.y), fmin(lo.z, v.z));
        hi = gc_v3(fmax(hi.x, v.x), fmax(hi.y, v.y), fmax(hi.z, v.z));
    }
    gcVec3 pad = gc_v3(fh->radius, fh->radius, fh->radius);
    lo = gc_sub(lo, pad);
    hi = gc_add(hi, pad);
    double spacing = fh->min_width + 2.0 * fh->radius;
    for (int32_t bi = 0; bi < w->num_bodies && f->num_contacts < GC_MAX_FINGER_CONTACTS; ++bi) {
        const gcBody *b = &w->bodies[bi];
        const gcBodyModel *bm = &model->bodies[bi];
        if (!gc_aabb_overlap(lo, hi, b->state.aabb_min, b->state.aabb_max)) continue;
        gcTransform fr = predicted_transform(bm, b, dt), fr_prev = gc_body_transform(bm, &b->state);
        for (int p = bm->first_part; p < bm->first_part + bm->num_parts; ++p) {
            const gcHull *h = &model->parts[p].hull;
            for (int32_t j = 0; j < h->num_vertices && f->num_contacts < GC_MAX_FINGER_CONTACTS; ++j) {
                if (outside_box(gc_transform_point(&fr, h->vertices[j]), lo, hi, h->radius)) continue;
                try_reversed(f, fh, bm, b, p, h, j, h->vertices[j], &fr, &fr_prev, &ff, &ff_prev, dt);
            }
            for (int e = 0; e < h->num_edges && f->num_contacts < GC_MAX_FINGER_CONTACTS; ++e) {
                gcVec3 a = h->vertices[h->edges[2 * e]], c = h->vertices[h->edges[2 * e + 1]];
                gcVec3 aw = gc_transform_point(&fr, a), cw = gc_transform_point(&fr, c);
                gcVec3 elo = gc_v3(fmin(aw.x, cw.x), fmin(aw.y, cw.y), fmin(aw.z, cw.z));
                gcVec3 ehi = gc_v3(fmax(aw.x, cw.x), fmax(aw.y, cw.y), fmax(aw.z, cw.z));
                if (!gc_aabb_overlap(gc_sub(lo, gc_v3(h->radius, h->radius, h->radius)),
                                     gc_add(hi, gc_v3(h->radius, h->radius, h->radius)), elo, ehi))
                    continue;
                double wanted = ceil(gc_len(gc_sub(c, a)) / spacing) - 1.0; /* capped before the cast */
                int n = wanted < (double)GC_EDGE_SAMPLES ? (int)wanted : GC_EDGE_SAMPLES;
                for (int k = 0; k < n && f->num_contacts < GC_MAX_FINGER_CONTACTS; ++k) {
                    double t = (double)(k + 1) / (double)(n + 1);
                    gcVec3 x = gc_madd(a, gc_sub(c, a), t);
                    if (outside_box(gc_transform_point(&fr, x), lo, hi, h->radius)) continue;
                    try_reversed(f, fh, bm, b, p, h, h->num_vertices + e * GC_EDGE_SAMPLES + k, x, &fr, &fr_prev, &ff,
                                 &ff_prev, dt);
                }
            }
        }
    }
}

/* ---- Soft fingertips: torsional friction about the contact normal (docs/physics.md) ---- */

/* v projected on the plane of unit normal n, normalised; zero when v is (nearly) along n. */
static gcVec3 in_plane(gcVec3 v, gcVec3 n) {
    gcVec3 p = gc_madd(v, n, -gc_dot(v, n));
    double len = gc_len(p);
    return len > 1e-6 ? gc_scale(p, 1.0 / len) : gc_v3(0, 0, 0);
}

static gcVec3 finger_axis(const gcFinger *f, int axis) {
    return gc_v3(f->R.m[0][axis], f->R.m[1][axis], f->R.m[2][axis]);
}

/* The finger's twist past the body's god-direction about the normal n (world, out of the body),
 * rad; 0 when either direction is undefined (the finger's axis turned onto the normal). */
static double twist_angle(const gcFinger *f, const gcFingerContact *c, const gcMat3 *body_R, gcVec3 n) {
    gcVec3 h = in_plane(finger_axis(f, c->twist_axis), n), g = in_plane(gc_mat3_mul_vec(body_R, c->twist_local), n);
    if (gc_len2(h) == 0.0 || gc_len2(g) == 0.0) return 0.0;
    return atan2(gc_dot(n, gc_cross(g, h)), gc_dot(g, h));
}

/* The twist's friction circle, as steps 3-4 for the god-object: the spring k rho^2 twist holds
 * while |twist| <= mu_s depth / rho (the torque mu_s F_n rho, F_n = k depth); past it the
 * god-direction slips to mu_d depth / rho behind the finger's, and sticks again inside that. */
static void update_twist(const gcFingerModel *fm, const gcFinger *f, const gcBodyModel *bm, const gcBody *b,
                         gcFingerContact *c, int fresh) {
    gcVec3 n = gc_mat3_mul_vec(&b->state.R, c->normal_local);
    if (fresh) {
        double best = 2.0;
        for (int a = 0; a < 3; ++a) {
            double along = fabs(gc_dot(finger_axis(f, a), n));
            if (along < best) best = along, c->twist_axis = a;
        }
    }
    gcVec3 h = in_plane(finger_axis(f, c->twist_axis), n);
    double phi = fresh ? 0.0 : twist_angle(f, c, &b->state.R, n);
    if (fresh || gc_len2(h) == 0.0 || gc_len2(in_plane(gc_mat3_mul_vec(&b->state.R, c->twist_local), n)) == 0.0) {
        c->twist_local = gc_mat3_tmul_vec(&b->state.R, h); /* (re)anchored where the finger points */
        c->twist = 0.0;
        c->twist_state = GC_FINGER_STICK;
        return;
    }
    double limit_s = bm->mu_s * c->depth / fm->torsion, limit_d = bm->mu_d * c->depth / fm->torsion;
    int slipping = c->twist_state == GC_FINGER_STICK ? fabs(phi) > limit_s
                                                     : fabs(phi) > limit_d * (1.0 + GC_CIRCLE_TOLERANCE);
    if (slipping) {
        double kept = phi > 0.0 ? limit_d : -limit_d; /* the god-direction trails the finger's by this */
        gcVec3 side = gc_cross(n, h);
        gcVec3 g = gc_add(gc_scale(h, cos(kept)), gc_scale(side, -sin(kept)));
        c->twist_local = gc_mat3_tmul_vec(&b->state.R, g);
        phi = kept;
    }
    c->twist_state = slipping ? GC_FINGER_SLIP : GC_FINGER_STICK;
    c->twist = phi;
}

static void finger_update(gcWorld *w, int32_t id, double dt) {
    const gcModel *model = w->model;
    gcFinger *f = &w->fingers[id];
    const gcFingerModel *fm = &model->fingers[id];
    const gcHull *fh = &model->finger_hulls[id];
    f->hip_velocity = gc_scale(gc_sub(f->hip, f->hip_prev), 1.0 / dt);
    if (fm->num_vertices) f->hip_angular_velocity = gc_scale(turn_between(f->q_prev, f->q), 1.0 / dt);
    /* Existing contacts, compacting away the ones that ended. */
    int kept = 0;
    for (int i = 0; i < f->num_contacts; ++i) {
        gcFingerContact *c = &f->contacts[i]; /* updated in place; a lost one is overwritten */
        const gcPart *part = &model->parts[c->part];
        const gcBody *b = &w->bodies[part->body];
        const gcBodyModel *bm = &model->bodies[part->body];
        gcTransform fr = fm->num_vertices ? predicted_transform(bm, b, dt) : gc_body_transform(bm, &b->state);
        int alive;
        if (!c->reversed) {
            gcSurface sf = body_surface(bm, &part->hull, fm->radius);
            alive = update_contact(&sf, c, gc_inv_transform_point(&fr, gc_finger_tip(fm, f, c->sample)), dt);
        } else {
            gcSurface sf = body_surface(bm, fh, part->hull.radius);
            gcTransform ff = finger_transform(f);
            gcVec3 v = gc_inv_transform_point(&ff, gc_transform_point(&fr, c->body_point_local));
            alive = update_contact(&sf, c, v, dt);
        }
        if (alive) {
            if (kept != i) f->contacts[kept] = *c;
            kept++;
        }
    }
    int existing = kept;
    f->num_contacts = kept;
    if (!fm->num_vertices) {
        find_new_contacts(w, fm, f, 0, GC_MAX_CONTACTS_PER_FINGER, dt);
        for (int i = 0; i < f->num_contacts && fm->torsion > 0.0; ++i) {
            int32_t body = model->parts[f->contacts[i].part].body;
            update_twist(fm, f, &model->bodies[body], &w->bodies[body], &f->contacts[i], i >= existing);
        }
        blend_seams(w, fm, f);
        return;
    }
    /* A convex finger: every hull vertex is a fingertip of its own, and every body vertex inside
     * the finger a reversed one (docs/physics.md "Area contacts"). */
    for (int32_t s = 0; s < fm->num_vertices && f->num_contacts < GC_MAX_FINGER_CONTACTS; ++s)
        find_new_contacts(w, fm, f, s, GC_MAX_FINGER_CONTACTS, dt);
    find_reversed_contacts(w, fm, f, fh, dt);
    /* Its points are a patch, not parts of one surface seen twice: no seam blend, each spring
     * whole (docs/physics.md "Renderers and finger shapes"). */
    for (int i = 0; i < f->num_contacts; ++i) f->contacts[i].share = 1.0;
}

/* The analysis's tangent axes of an inward normal n (unit): t1 = normalize(n x a), a the world
 * axis of smallest |n.a| (ties: x, then y, then z), t2 = n x t1 (graspcore.h, gcGraspDef). */
static void tangent_axes(gcVec3 n, gcVec3 *t1, gcVec3 *t2) {
    double c[3] = {fabs(n.x), fabs(n.y), fabs(n.z)};
    int axis = 0;
    if (c[1] < c[axis]) axis = 1;
    if (c[2] < c[axis]) axis = 2;
    *t1 = gc_cross(n, gc_v3(axis == 0, axis == 1, axis == 2));
    *t1 = gc_scale(*t1, 1.0 / gc_len(*t1));
    *t2 = gc_cross(n, *t1);
}

static double cross2(const double *o, const double *a, const double *b) {
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]);
}

/* A convex finger's patch (gcFinger.patch): the n points (u, v) in the tangent plane, their 2-D
 * hull (monotone chain), then while it has more than GC_FINGER_PATCH_CORNERS corners the one
 * whose triangle with its neighbours is smallest dropped (the kept polygon loses the least area;
 * it lies inside the patch, so the analysis never overstates what the patch resists). */
static void patch_corners(double (*uv)[2], int n, float *out) {
    for (int i = 1; i < n; ++i) /* sort by u, then v (n <= GC_MAX_FINGER_CONTACTS) */
        for (int j = i; j > 0 && (uv[j][0] < uv[j - 1][0] || (uv[j][0] == uv[j - 1][0] && uv[j][1] < uv[j - 1][1]));
             --j) {
            double t0 = uv[j][0], t1 = uv[j][1];
            uv[j][0] = uv[j - 1][0], uv[j][1] = uv[j - 1][1], uv[j - 1][0] = t0, uv[j - 1][1] = t1;
        }
    int hull[2 * GC_MAX_FINGER_CONTACTS + 1], h = 0;
    for (int i = 0; i < n; ++i) { /* lower chain */
        while (h >= 2 && cross2(uv[hull[h - 2]], uv[hull[h - 1]], uv[i]) <= 0.0) --h;
        hull[h++] = i;
    }
    for (int i = n - 2, lower = h + 1; i >= 0; --i) { /* upper chain */
        while (h >= lower && cross2(uv[hull[h - 2]], uv[hull[h - 1]], uv[i]) <= 0.0) --h;
        hull[h++] = i;
    }
    if (h > 1) --h; /* the last repeats the first */
    if (n == 1) h = 1;
    while (h > GC_FINGER_PATCH_CORNERS) {
        int drop = 0;
        double least = INFINITY;
        for (int k = 0; k < h; ++k) {
            double area = fabs(cross2(uv[hull[(k + h - 1) % h]], uv[hull[k]], uv[hull[(k + 1) % h]]));
            if (area < least) least = area, drop = k;
        }
        for (int k = drop; k + 1 < h; ++k) hull[k] = hull[k + 1];
        --h;
    }
    /* Fewer corners than slots (a segment, a triangle): the last repeats, so that a corner at
     * (0, 0), the contact point itself, stays a corner; no points at all: zeros. */
    memset(out, 0, 2 * GC_FINGER_PATCH_CORNERS * sizeof *out);
    for (int k = 0; k < GC_FINGER_PATCH_CORNERS && h > 0; ++k) {
        int c = hull[k < h ? k : h - 1];
        out[2 * k] = (float)uv[c][0], out[2 * k + 1] = (float)uv[c][1];
    }
}

/* Force rendered to the device and the finger's reported GO/state: a sphere finger reports its
 * deepest contact's GO, normal and state (the analysis takes the GO, the normal and the body as one
 * contact); a convex finger the centroid of its contacts' god-objects weighted by their
 * normal force (the chapter's pressure centroid), the torque of its contacts about the HIP, and
 * slip when any of them slips. */
static void finger_outputs(gcWorld *w, int32_t id) {
    const gcModel *model = w->model;
    gcFinger *f = &w->fingers[id];
    const gcFingerModel *fm = &model->fingers[id];
    gcVec3 force = gc_v3(0, 0, 0), torque = gc_v3(0, 0, 0), centroid = gc_v3(0, 0, 0);
    double deepest = -1.0, weight = 0.0;
    int slipping = 0;
    gcVec3 surface[GC_MAX_FINGER_CONTACTS]; /* a convex finger's contact points on the bodies */
    f->god_object = f->hip;
    f->normal = gc_v3(0, 0, 0);
    if (fm->num_vertices) memset(f->patch, 0, sizeof f->patch); /* a sphere's stays zero (add_finger) */
    f->contact_body = -1;
    f->state = GC_FINGER_FREE;
    for (int i = 0; i < f->num_contacts; ++i) {
        const gcFingerContact *c = &f->contacts[i];
        const int32_t body = model->parts[c->part].body;
        const gcBody *b = &w->bodies[body];
        const gcBodyModel *bm = &model->bodies[body];
        gcTransform fr = gc_body_transform(bm, &b->state);
        gcVec3 tip, tip_velocity, go;
        gc_finger_contact_ends(fm, f, c, &fr, &tip, &tip_velocity, &go);
        /* A sphere finger's springs on one body's parts weighted at seams (blend_seams); a convex
         * finger's share is 1. */
        double k = fm->stiffness * c->share, damping = fm->damping * c->share;
        gcVec3 stretch = gc_sub(go, tip), dv = gc_v3(0, 0, 0);
        force = gc_madd(force, stretch, k);
        if (fm->damping > 0.0) {
            /* Damping on the HIP vs the body point at the god-object. */
            gcVec3 v_point = bm->is_static ? gc_v3(0, 0, 0) : gc_add(b->state.v, gc_cross(b->state.w, gc_sub(go, b->state.com)));
            dv = gc_sub(v_point, tip_velocity);
            force = gc_madd(force, dv, damping);
        }
        if (fm->torsion > 0.0) { /* the soft fingertip's twist spring, on the pose the body reached */
            gcVec3 n = gc_mat3_mul_vec(&b->state.R, c->normal_local);
            torque = gc_madd(torque, n, -k * fm->torsion * fm->torsion * twist_angle(f, c, &b->state.R, n));
        }
        if (fm->num_vertices) {
            gcVec3 fc = gc_madd(gc_scale(stretch, k), dv, damping);
            torque = gc_add(torque, gc_cross(gc_sub(go, f->hip), fc));
            centroid = gc_madd(centroid, go, c->depth);
            /* on the body's surface: a fingertip centre less the radius, or the body's vertex */
            surface[i] = c->reversed ? go : gc_madd(go, gc_finger_point_normal(f, c, &b->state.R), -fm->radius);
            weight += c->depth;
            slipping |= c->state == GC_FINGER_SLIP;
        }
        if (c->depth > deepest) {
            deepest = c->depth;
            f->god_object = go;
            f->normal = gc_finger_point_normal(f, c, &b->state.R);
            f->contact_body = model->parts[c->part].body;
            f->state = c->state;
        }
    }
    if (fm->num_vertices && f->num_contacts) {
        if (weight > 0.0) f->god_object = gc_scale(centroid, 1.0 / weight);
        f->state = slipping ? GC_FINGER_SLIP : GC_FINGER_STICK;
        /* The patch on the reported body, about the analysis's contact point GO - radius normal
         * (a unit normal always, from the deepest contact; checked so that no patch is ever NaN). */
        gcVec3 n_in = gc_neg(f->normal), t1, t2, p = gc_madd(f->god_object, f->normal, -fm->radius);
        tangent_axes(n_in, &t1, &t2);
        double uv[GC_MAX_FINGER_CONTACTS][2];
        int m = 0;
        for (int i = 0; i < f->num_contacts && gc_dot(n_in, n_in) > 0.5; ++i) {
            if (model->parts[f->contacts[i].part].body != f->contact_body) continue;
            gcVec3 r = gc_sub(surface[i], p);
            uv[m][0] = gc_dot(r, t1), uv[m][1] = gc_dot(r, t2), ++m;
        }
        patch_corners(uv, m, f->patch);
    }
    f->force = force;
    f->torque = torque;
    double *out = &w->force_array[3 * id];
    out[0] = force.x, out[1] = force.y, out[2] = force.z;
    out = &w->god_object_array[3 * id];
    out[0] = f->god_object.x, out[1] = f->god_object.y, out[2] = f->god_object.z;
}

void gc_xfca_update(gcWorld *w, double dt) {
    const gcModel *model = w->model;
    for (int32_t i = 0; i < w->num_fingers; ++i) {
        if (model->fingers[i].renderer == GC_RENDERER_CURSOR)
            gc_cursor_finger_update(w, i, dt);
        else
            finger_update(w, i, dt);
    }
}

void gc_xfca_outputs(gcWorld *w) {
    const gcModel *model = w->model;
    for (int32_t i = 0; i < w->num_fingers; ++i) {
        if (model->fingers[i].renderer == GC_RENDERER_CURSOR)
            gc_cursor_finger_outputs(w, i);
        else
            finger_outputs(w, i);
    }
}
