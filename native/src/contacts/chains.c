/* Collision chains (islands): dynamic bodies linked by contact manifolds.
 *
 * Union-find over body ids, the root of a set being its lowest id, so that the chains and
 * their numbering are a function of the contacts alone. A static body never joins a chain
 * (it would link every object on a table into one), and fingers never link bodies: a
 * finger is kinematic, its springs are part of a body's effective mass. A dynamic body
 * without contacts is a chain of its own. Chains are numbered by their lowest body id; a
 * chain's bodies and manifolds are listed in increasing id / key order, which fixes the
 * order in which the solver visits them whichever thread solves the chain. */
#include "contacts_internal.h"

static int32_t find_root(int32_t *parent, int32_t i) {
    while (parent[i] != i) {
        parent[i] = parent[parent[i]]; /* path halving */
        i = parent[i];
    }
    return i;
}

void gc_chains_build(gcWorld *w) {
    const gcModel *model = w->model;
    struct gcContactSystem *cs = w->contacts;
    int32_t *parent = cs->parent;
    int nb = w->num_bodies;
    for (int32_t i = 0; i < nb; ++i) parent[i] = i;
    for (int i = 0; i < cs->num_manifolds; ++i) {
        const gcManifold *m = &cs->manifolds[i];
        if (model->bodies[m->body_a].is_static || model->bodies[m->body_b].is_static) continue;
        int32_t ra = find_root(parent, m->body_a), rb = find_root(parent, m->body_b);
        if (ra == rb) continue;
        if (ra < rb) parent[rb] = ra;
        else parent[ra] = rb;
    }
    /* Number the chains in order of their lowest body id (the root). */
    int32_t *index_of_root = cs->cursor;
    int chains = 0;
    for (int32_t i = 0; i < nb; ++i) {
        if (model->bodies[i].is_static) {
            cs->body_chain[i] = -1;
            continue;
        }
        int32_t r = find_root(parent, i);
        if (r == i) index_of_root[i] = chains++;
        cs->body_chain[i] = index_of_root[r];
    }
    cs->num_chains = chains;
    /* Bodies per chain (counting sort, id order within a chain). */
    int32_t *start = cs->chain_body_start;
    for (int c = 0; c <= chains; ++c) start[c] = 0;
    for (int32_t i = 0; i < nb; ++i)
        if (cs->body_chain[i] >= 0) start[cs->body_chain[i] + 1]++;
    for (int c = 0; c < chains; ++c) start[c + 1] += start[c];
    int32_t *cursor = cs->cursor;
    for (int c = 0; c < chains; ++c) cursor[c] = start[c];
    for (int32_t i = 0; i < nb; ++i)
        if (cs->body_chain[i] >= 0) cs->chain_bodies[cursor[cs->body_chain[i]]++] = i;
    /* Manifolds per chain (key order within a chain): the chain of their dynamic body. */
    int32_t *mstart = cs->chain_manifold_start;
    for (int c = 0; c <= chains; ++c) mstart[c] = 0;
    for (int i = 0; i < cs->num_manifolds; ++i) {
        const gcManifold *m = &cs->manifolds[i];
        int32_t c = cs->body_chain[m->body_a] >= 0 ? cs->body_chain[m->body_a] : cs->body_chain[m->body_b];
        mstart[c + 1]++;
    }
    for (int c = 0; c < chains; ++c) mstart[c + 1] += mstart[c];
    for (int c = 0; c < chains; ++c) cursor[c] = mstart[c];
    for (int i = 0; i < cs->num_manifolds; ++i) {
        const gcManifold *m = &cs->manifolds[i];
        int32_t c = cs->body_chain[m->body_a] >= 0 ? cs->body_chain[m->body_a] : cs->body_chain[m->body_b];
        cs->chain_manifolds[cursor[c]++] = i;
    }
}

int gc_world_chain_count(const gcWorld *w) { return w->contacts ? w->contacts->num_chains : 0; }

gcStatus gc_world_body_chain(const gcWorld *w, int32_t body, int32_t *chain) {
    const gcModel *model = w->model;
    if (!w) return GC_ERR_INVALID_ARGUMENT;
    if (!chain) return gc_null_argument(w, "chain");
    if (body < 0 || body >= w->num_bodies) {
        gc_world_set_error(w, "body: unknown id %d", (int)body);
        return GC_ERR_UNKNOWN_ID;
    }
    const struct gcContactSystem *cs = w->contacts;
    /* Before the first step (or for a body added since), a dynamic body is alone. */
    if (model->bodies[body].is_static) *chain = -1;
    else if (!cs || body >= cs->num_sorted) *chain = -1;
    else *chain = cs->body_chain[body];
    return GC_OK;
}
