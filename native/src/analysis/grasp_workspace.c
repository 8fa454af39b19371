/* The grasp workspace (graspcore.h): its defaults, its error message and its storage, which
 * grows only when a larger problem comes and is reused by every call after. */
#include "analysis_internal.h"

#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>

gcStatus gc_grasp_set_error(gcGraspWorkspace *ws, gcStatus st, const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(ws->error, sizeof ws->error, fmt, ap);
    va_end(ap);
    return st;
}

gcGraspDef gc_default_grasp_def(void) {
    gcGraspDef def;
    memset(&def, 0, sizeof def);
    def.edges = 8;
    def.tolerance = 1e-10;
    def.max_facets = 1 << 20;
    def.volume = 1;
    return def;
}

gcGraspWorkspace *gc_grasp_workspace_create(void) {
    gcGraspWorkspace *ws = calloc(1, sizeof *ws);
    return ws;
}

void gc_grasp_workspace_destroy(gcGraspWorkspace *ws) {
    if (!ws) return;
    free(ws->wrench);
    free(ws->force);
    free(ws->torque);
    free(ws->residual);
    free(ws->next);
    free(ws->facets);
    free(ws->free_list);
    free(ws->visible);
    free(ws->created);
    free(ws->pending);
    free(ws->vertex_hash);
    free(ws->ridge_key);
    free(ws->ridge_facet);
    free(ws->ridge_stamp);
    free(ws->created_apex);
    free(ws->facet_off);
    free(ws->lp);
    free(ws->lp_basis);
    for (int k = 0; k < GC_REUSE_SLOTS; ++k) free(ws->reuse[k].wrench), free(ws->mu_min[k].input);
    free(ws);
}

const char *gc_grasp_workspace_error(const gcGraspWorkspace *ws) { return ws ? ws->error : "no workspace"; }

/* ---- storage ---------------------------------------------------------------------- */

int gc_grasp_grow(void **p, size_t count, size_t size) {
    void *q = realloc(*p, count * size);
    if (!q) return 0;
    *p = q;
    return 1;
}

gcStatus gc_grasp_ensure_points(gcGraspWorkspace *ws, int n) {
    if (n <= ws->cap_points) return GC_OK;
    int cap = ws->cap_points ? ws->cap_points : 64;
    while (cap < n) cap *= 2;
    if (!gc_grasp_grow((void **)&ws->wrench, (size_t)cap * 6, sizeof(double)) ||
        !gc_grasp_grow((void **)&ws->force, (size_t)cap * 3, sizeof(double)) ||
        !gc_grasp_grow((void **)&ws->torque, (size_t)cap * 3, sizeof(double)) ||
        !gc_grasp_grow((void **)&ws->residual, (size_t)cap * 6, sizeof(double)) ||
        !gc_grasp_grow((void **)&ws->next, (size_t)cap, sizeof(int)) ||
        !gc_grasp_grow((void **)&ws->vertex_hash, (size_t)cap * 2, sizeof(uint64_t)))
        return gc_grasp_set_error(ws, GC_ERR_NO_MEMORY, "workspace: out of memory for %d wrenches", n);
    /* Two random words per point index (splitmix64), made once: the ridge keys sum them. */
    for (int i = ws->cap_points; i < cap; ++i) {
        uint64_t z = (uint64_t)(i + 1) * 0x9E3779B97F4A7C15ull;
        z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
        z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
        ws->vertex_hash[2 * i] = z ^ (z >> 31);
        z = (uint64_t)(i + 1) * 0xD1B54A32D192ED03ull;
        z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
        z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
        ws->vertex_hash[2 * i + 1] = z ^ (z >> 31);
    }
    ws->cap_points = cap;
    return GC_OK;
}

gcStatus gc_grasp_ensure_facets(gcGraspWorkspace *ws, int n, int max_facets) {
    if (n <= ws->cap_facets) return GC_OK;
    if (n > max_facets)
        return gc_grasp_set_error(ws, GC_ERR_CAPACITY, "max_facets: the hull needs more than %d facets", max_facets);
    int cap = ws->cap_facets ? ws->cap_facets : 1024;
    while (cap < n) cap *= 2;
    if (cap > max_facets) cap = max_facets;
    if (!gc_grasp_grow((void **)&ws->facets, (size_t)cap, sizeof(Facet)) ||
        !gc_grasp_grow((void **)&ws->free_list, (size_t)cap, sizeof(int)) ||
        !gc_grasp_grow((void **)&ws->visible, (size_t)cap, sizeof(int)) ||
        !gc_grasp_grow((void **)&ws->created, (size_t)cap, sizeof(int)) ||
        !gc_grasp_grow((void **)&ws->created_apex, (size_t)cap, sizeof(int)) ||
        !gc_grasp_grow((void **)&ws->facet_off, (size_t)cap, sizeof(double)))
        return gc_grasp_set_error(ws, GC_ERR_NO_MEMORY, "workspace: out of memory for %d facets", n);
    ws->cap_facets = cap;
    return GC_OK;
}

/* A ridge table of at least 2 x need slots (a power of two), emptied; only those slots are used,
 * so a small step touches few cache lines even after a large hull grew the table. */
gcStatus gc_grasp_ensure_ridges(gcGraspWorkspace *ws, int need) {
    int cap = 64;
    while (cap < 2 * need) cap *= 2;
    if (cap > ws->cap_ridges) {
        if (!gc_grasp_grow((void **)&ws->ridge_key, (size_t)cap * 2, sizeof(uint64_t)) ||
            !gc_grasp_grow((void **)&ws->ridge_facet, (size_t)cap, sizeof(int)) ||
            !gc_grasp_grow((void **)&ws->ridge_stamp, (size_t)cap, sizeof(int)))
            return gc_grasp_set_error(ws, GC_ERR_NO_MEMORY, "workspace: out of memory for %d ridges", need);
        for (int i = ws->cap_ridges; i < cap; ++i) ws->ridge_stamp[i] = 0;
        ws->cap_ridges = cap;
    }
    ws->ridge_slots = cap;
    if (++ws->ridge_gen == 0x7fffffff) {
        memset(ws->ridge_stamp, 0, sizeof(int) * (size_t)ws->cap_ridges);
        ws->ridge_gen = 1;
    }
    return GC_OK;
}

gcStatus gc_grasp_push_pending(gcGraspWorkspace *ws, int *count, int f) {
    if (*count >= ws->cap_pending) {
        int cap = ws->cap_pending ? ws->cap_pending * 2 : 1024;
        if (!gc_grasp_grow((void **)&ws->pending, (size_t)cap, sizeof(int)))
            return gc_grasp_set_error(ws, GC_ERR_NO_MEMORY, "workspace: out of memory");
        ws->cap_pending = cap;
    }
    ws->pending[(*count)++] = f;
    return GC_OK;
}
