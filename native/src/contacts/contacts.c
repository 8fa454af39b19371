/* Body-body contacts (docs/solver.md): the contact system's storage, the order of a
 * step's jobs, and the queries. The jobs live in contact_broadphase.c,
 * contact_manifold.c, chains.c and contact_solver.c.
 *
 * Per step, between the velocity phase (gravity and the implicit finger springs, which
 * leave each body's effective-mass factor) and the position phase:
 *
 *  1. Broad phase: sort-and-sweep on the body AABBs (x axis; the order is kept between
 *     steps, so the insertion sort is near linear), then the parts' AABBs of each body
 *     pair. Candidate part pairs are sorted by key = part_a * max_parts + part_b.
 *  2. Narrow phase (in parallel, one output slot per candidate): gc_collide (GJK/EPA) gives
 *     the normal; when a face of either polytope lies along it, the incident face of the
 *     other is clipped against the reference face's side planes (Sutherland-Hodgman) and
 *     reduced to at most 4 points; otherwise the single GJK/EPA point is used. Points are
 *     matched to last step's manifold of the same pair by proximity in either body's frame
 *     and inherit its impulses (warm start) and its friction state and anchors.
 *  3. Chains (chains.c): union-find over dynamic bodies linked by manifolds.
 *  4. Solver, per chain (in parallel; a chain's result depends only on its own data):
 *     sequential impulses with the 6x6 effective masses; warm started; Coulomb friction as
 *     a 2x2 block per point projected on the true (circular) cone; static friction through
 *     friction anchors (no creep); then a split-impulse position pass that removes
 *     penetration beyond the slop without adding kinetic energy.
 *
 * Nothing here allocates after gc_contacts_create. */
#define _POSIX_C_SOURCE 200809L
#include "contacts_internal.h"

#include <float.h>
#include <stdlib.h>
#include <string.h>

/* ------------------------------------------------------------------ lifetime */


gcStatus gc_contacts_create(gcWorld *w) {
    int threads = w->def.threads, cap = w->def.max_contacts;
    if (threads == 0) threads = 1;
    if (cap == 0) cap = GC_DEFAULT_MAX_CONTACTS;
    w->def.threads = threads;
    w->def.max_contacts = cap;
    struct gcContactSystem *cs = calloc(1, sizeof *cs);
    if (!cs) return GC_ERR_NO_MEMORY;
    w->contacts = cs;
    size_t nb = (size_t)w->def.max_bodies, np = (size_t)w->def.max_parts, nc = (size_t)cap;
    cs->capacity = cap;
    cs->manifolds = calloc(nc, sizeof *cs->manifolds);
    cs->previous = calloc(nc, sizeof *cs->previous);
    cs->candidates = calloc(nc, sizeof *cs->candidates);
    cs->candidates_scratch = calloc(nc, sizeof *cs->candidates_scratch);
    cs->sorted_bodies = calloc(nb, sizeof *cs->sorted_bodies);
    cs->part_min = calloc(np, sizeof *cs->part_min);
    cs->part_max = calloc(np, sizeof *cs->part_max);
    cs->parent = calloc(nb, sizeof *cs->parent);
    cs->body_chain = calloc(nb, sizeof *cs->body_chain);
    cs->chain_body_start = calloc(nb + 1, sizeof *cs->chain_body_start);
    cs->chain_bodies = calloc(nb, sizeof *cs->chain_bodies);
    cs->chain_manifold_start = calloc(nb + 1, sizeof *cs->chain_manifold_start);
    cs->chain_manifolds = calloc(nc, sizeof *cs->chain_manifolds);
    cs->cursor = calloc(nb + 1, sizeof *cs->cursor);
    cs->pseudo_v = calloc(nb, sizeof *cs->pseudo_v);
    cs->pseudo_w = calloc(nb, sizeof *cs->pseudo_w);
    cs->inv_mass = calloc(nb, sizeof *cs->inv_mass);
    cs->scratch = calloc((size_t)cs->capacity * GC_MANIFOLD_MAX_POINTS, sizeof *cs->scratch);
    if (!cs->inv_mass || !cs->scratch || !cs->manifolds || !cs->previous || !cs->candidates ||
        !cs->candidates_scratch || !cs->sorted_bodies || !cs->part_min ||
        !cs->part_max || !cs->parent || !cs->body_chain || !cs->chain_body_start || !cs->chain_bodies ||
        !cs->chain_manifold_start || !cs->chain_manifolds || !cs->cursor || !cs->pseudo_v || !cs->pseudo_w)
        return GC_ERR_NO_MEMORY; /* the caller destroys the world, which frees what was made */
    gcStatus st = gc_pool_create(threads, &cs->pool);
    if (st != GC_OK) return st;
    return GC_OK;
}

void gc_contacts_destroy(gcWorld *w) {
    struct gcContactSystem *cs = w->contacts;
    if (!cs) return;
    gc_pool_destroy(cs->pool);
    free(cs->manifolds);
    free(cs->previous);
    free(cs->candidates);
    free(cs->candidates_scratch);
    free(cs->sorted_bodies);
    free(cs->part_min);
    free(cs->part_max);
    free(cs->parent);
    free(cs->body_chain);
    free(cs->chain_body_start);
    free(cs->chain_bodies);
    free(cs->chain_manifold_start);
    free(cs->chain_manifolds);
    free(cs->cursor);
    free(cs->pseudo_v);
    free(cs->pseudo_w);
    free(cs->inv_mass);
    free(cs->scratch);
    free(cs);
    w->contacts = NULL;
}

/* ------------------------------------------------------------------ a step */

void gc_contacts_detect(gcWorld *w) {
    struct gcContactSystem *cs = w->contacts;
    if (!cs) return;
    /* Last step's manifolds become `previous` (for matching); this step writes the other. */
    gcManifold *tmp = cs->previous;
    cs->previous = cs->manifolds;
    cs->num_previous = cs->num_manifolds;
    cs->manifolds = tmp;
    cs->num_manifolds = 0;
    gc_broad_phase(w);
    gc_narrow_phase(w);
    gc_chains_build(w);
}

void gc_contacts_step(gcWorld *w, double dt) {
    gc_contacts_detect(w);
    gc_contacts_solve(w, dt);
}

/* ------------------------------------------------------------------ queries */

int gc_world_contact_count(const gcWorld *w) {
    const struct gcContactSystem *cs = w->contacts;
    int n = 0;
    if (!cs) return 0;
    for (int i = 0; i < cs->num_manifolds; ++i) n += cs->manifolds[i].num_points;
    return n;
}

int gc_world_contacts(const gcWorld *w, gcContactPoint *out, int capacity) {
    const struct gcContactSystem *cs = w->contacts;
    int n = 0;
    if (!cs) return 0;
    for (int i = 0; i < cs->num_manifolds; ++i) {
        const gcManifold *m = &cs->manifolds[i];
        for (int k = 0; k < m->num_points; ++k, ++n) {
            if (!out || n >= capacity) continue;
            const gcManifoldPoint *p = &m->points[k];
            gcContactPoint *o = &out[n];
            o->body_a = m->body_a;
            o->body_b = m->body_b;
            o->point[0] = p->point.x, o->point[1] = p->point.y, o->point[2] = p->point.z;
            o->normal[0] = m->normal.x, o->normal[1] = m->normal.y, o->normal[2] = m->normal.z;
            o->separation = p->separation;
            o->normal_impulse = p->normal_impulse;
            o->friction_impulse[0] = p->friction_impulse.x;
            o->friction_impulse[1] = p->friction_impulse.y;
            o->friction_impulse[2] = p->friction_impulse.z;
            o->sticking = m->sticking;
        }
    }
    return n;
}

int64_t gc_world_contact_overflow(const gcWorld *w) { return w->contacts ? w->contacts->overflow : 0; }

/* ------------------------------------------------------------------ shadow worlds */

int gc_contacts_chain_of(const gcWorld *w, int32_t body, int32_t *out, int capacity) {
    const struct gcContactSystem *cs = w->contacts;
    int c = cs && body < cs->num_sorted ? cs->body_chain[body] : -1;
    if (c < 0 || c >= cs->num_chains) { /* no chains yet: the body alone */
        if (capacity > 0) out[0] = body;
        return 1;
    }
    int b0 = cs->chain_body_start[c], b1 = cs->chain_body_start[c + 1];
    for (int i = b0; i < b1 && i - b0 < capacity; ++i) out[i - b0] = cs->chain_bodies[i];
    return b1 - b0;
}

void gc_contacts_copy_state(gcWorld *dst, const gcWorld *src) {
    struct gcContactSystem *d = dst->contacts;
    const struct gcContactSystem *c = src->contacts;
    if (!d || !c) return;
    int n = c->num_manifolds < d->capacity ? c->num_manifolds : d->capacity;
    memcpy(d->manifolds, c->manifolds, (size_t)n * sizeof *c->manifolds);
    d->num_manifolds = n;
    memcpy(d->sorted_bodies, c->sorted_bodies, (size_t)c->num_sorted * sizeof *c->sorted_bodies);
    d->num_sorted = c->num_sorted;
    d->overflow = c->overflow;
    gc_chains_build(dst);
}

/* The dynamic body of a manifold (a static body never owns one). */
static int32_t manifold_owner(const gcWorld *w, const gcManifold *m) {
    const gcModel *model = w->model;
    return model->bodies[m->body_a].is_static ? m->body_b : m->body_a;
}

/* Both lists are sorted by key; the result is too. */
void gc_contacts_merge(gcWorld *dst, const gcWorld *first, const gcWorld *second,
                       int (*from_first)(const void *ctx, int32_t body), const void *ctx) {
    struct gcContactSystem *cs = dst->contacts;
    const struct gcContactSystem *ch = first->contacts, *co = second->contacts;
    if (!cs || !ch || !co) return;
    int i = 0, j = 0, n = 0;
    while ((i < ch->num_manifolds || j < co->num_manifolds) && n < cs->capacity) {
        const gcManifold *a = i < ch->num_manifolds ? &ch->manifolds[i] : NULL;
        const gcManifold *b = j < co->num_manifolds ? &co->manifolds[j] : NULL;
        const gcManifold *pick = NULL;
        if (a && (!b || a->key <= b->key)) {
            if (from_first(ctx, manifold_owner(first, a))) pick = a;
            else if (b && b->key == a->key) pick = b;
            if (b && b->key == a->key) ++j;
            ++i;
        } else {
            if (!from_first(ctx, manifold_owner(second, b))) pick = b;
            ++j;
        }
        if (pick) cs->manifolds[n++] = *pick;
    }
    cs->num_manifolds = n;
    memcpy(cs->sorted_bodies, co->sorted_bodies, (size_t)co->num_sorted * sizeof *co->sorted_bodies);
    cs->num_sorted = co->num_sorted;
    cs->overflow = co->overflow > ch->overflow ? co->overflow : ch->overflow;
    gc_chains_build(dst);
}
