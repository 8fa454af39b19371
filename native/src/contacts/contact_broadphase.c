/* Broad phase (docs/solver.md): sort-and-sweep on the body AABBs along x (the order is
 * kept between steps, so the insertion sort is near linear), then the parts' AABBs of each
 * body pair. Candidate part pairs are sorted by key = part_a * max_parts + part_b. */
#define _POSIX_C_SOURCE 200809L
#include "contacts_internal.h"

#include <float.h>
#include <stdlib.h>
#include <string.h>

static void update_part_aabbs(gcWorld *w) {
    const gcModel *model = w->model;
    struct gcContactSystem *cs = w->contacts;
    const double h = 0.5 * GC_CONTACT_MARGIN;
    for (int32_t bi = 0; bi < w->num_bodies; ++bi) {
        const gcBody *b = &w->bodies[bi];
        const gcBodyModel *m = &model->bodies[bi];
        gcTransform t = gc_body_transform(m, &b->state);
        for (int p = m->first_part; p < m->first_part + m->num_parts; ++p) {
            const gcHull *hull = &model->parts[p].hull;
            if (m->num_parts == 1) {
                cs->part_min[p] = gc_sub(b->state.aabb_min, gc_v3(h, h, h));
                cs->part_max[p] = gc_add(b->state.aabb_max, gc_v3(h, h, h));
                continue;
            }
            /* Centre/extent form: |R| e bounds the rotated box. */
            gcVec3 c = gc_scale(gc_add(hull->aabb_min, hull->aabb_max), 0.5);
            gcVec3 e = gc_scale(gc_sub(hull->aabb_max, hull->aabb_min), 0.5);
            gcVec3 wc = gc_transform_point(&t, c);
            double ex[3];
            for (int i = 0; i < 3; ++i)
                ex[i] = fabs(t.R.m[i][0]) * e.x + fabs(t.R.m[i][1]) * e.y + fabs(t.R.m[i][2]) * e.z + hull->radius + h;
            cs->part_min[p] = gc_v3(wc.x - ex[0], wc.y - ex[1], wc.z - ex[2]);
            cs->part_max[p] = gc_v3(wc.x + ex[0], wc.y + ex[1], wc.z + ex[2]);
        }
    }
}

static int body_before(const gcWorld *w, int32_t a, int32_t b) {
    double xa = w->bodies[a].state.aabb_min.x, xb = w->bodies[b].state.aabb_min.x;
    return xa < xb || (xa == xb && a < b);
}

/* Candidates in key order (the previous step's manifolds are matched by merging): LSD
 * radix sort on the key's bytes, up to the bytes max_parts^2 needs (3 for 4096 parts).
 * glibc's qsort with a comparison callback cost ~10% of a 100-body pile's step. */
/* Keys are unique (one candidate per part pair), so any sort gives the same order. */
#define GC_INSERTION_SORT_MAX 32

static void sort_candidates(struct gcContactSystem *cs, int64_t max_key) {
    int n = cs->num_candidates;
    if (n <= GC_INSERTION_SORT_MAX) { /* a few pairs (a held object): no radix passes over 256 bins */
        gcCandidate *c = cs->candidates;
        for (int i = 1; i < n; ++i) {
            gcCandidate v = c[i];
            int j = i - 1;
            for (; j >= 0 && c[j].key > v.key; --j) c[j + 1] = c[j];
            c[j + 1] = v;
        }
        return;
    }
    gcCandidate *src = cs->candidates, *dst = cs->candidates_scratch;
    int passes = 0;
    for (int64_t k = max_key; k > 0; k >>= 8) ++passes;
    for (int pass = 0; pass < passes; ++pass) {
        int shift = 8 * pass, count[257] = {0};
        for (int i = 0; i < n; ++i) count[((src[i].key >> shift) & 0xff) + 1]++;
        for (int d = 0; d < 256; ++d) count[d + 1] += count[d];
        for (int i = 0; i < n; ++i) dst[count[(src[i].key >> shift) & 0xff]++] = src[i];
        gcCandidate *t = src;
        src = dst;
        dst = t;
    }
    if (src != cs->candidates) memcpy(cs->candidates, src, (size_t)n * sizeof *src);
}

void gc_broad_phase(gcWorld *w) {
    const gcModel *model = w->model;
    struct gcContactSystem *cs = w->contacts;
    update_part_aabbs(w);
    /* Keep last step's order; append new bodies; insertion sort (near linear when sorted). */
    for (int32_t i = cs->num_sorted; i < w->num_bodies; ++i) cs->sorted_bodies[i] = i;
    cs->num_sorted = w->num_bodies;
    int32_t *s = cs->sorted_bodies;
    for (int i = 1; i < cs->num_sorted; ++i) {
        int32_t v = s[i];
        int j = i - 1;
        while (j >= 0 && body_before(w, v, s[j])) {
            s[j + 1] = s[j];
            --j;
        }
        s[j + 1] = v;
    }
    const double h = 0.5 * GC_CONTACT_MARGIN;
    gcVec3 hv = gc_v3(h, h, h);
    int64_t max_parts = w->def.max_parts;
    cs->num_candidates = 0;
    for (int i = 0; i < cs->num_sorted; ++i) {
        const gcBody *A = &w->bodies[s[i]];
        double hi_x = A->state.aabb_max.x + 2.0 * h;
        gcVec3 amin = gc_sub(A->state.aabb_min, hv), amax = gc_add(A->state.aabb_max, hv);
        for (int j = i + 1; j < cs->num_sorted; ++j) {
            const gcBody *B = &w->bodies[s[j]];
            if (B->state.aabb_min.x > hi_x) break;
            if (model->bodies[s[i]].is_static && model->bodies[s[j]].is_static) continue;
            if (!gc_aabb_overlap(amin, amax, gc_sub(B->state.aabb_min, hv), gc_add(B->state.aabb_max, hv))) continue;
            int32_t lo = s[i] < s[j] ? s[i] : s[j], hi = s[i] < s[j] ? s[j] : s[i];
            const gcBodyModel *L = &model->bodies[lo], *H = &model->bodies[hi];
            for (int pa = L->first_part; pa < L->first_part + L->num_parts; ++pa) {
                for (int pb = H->first_part; pb < H->first_part + H->num_parts; ++pb) {
                    if (!gc_aabb_overlap(cs->part_min[pa], cs->part_max[pa], cs->part_min[pb], cs->part_max[pb]))
                        continue;
                    if (cs->num_candidates >= cs->capacity) {
                        cs->overflow++;
                        continue;
                    }
                    gcCandidate *c = &cs->candidates[cs->num_candidates++];
                    c->part_a = pa;
                    c->part_b = pb;
                    c->key = (int64_t)pa * max_parts + pb;
                }
            }
        }
    }
    sort_candidates(cs, max_parts * max_parts - 1);
}

