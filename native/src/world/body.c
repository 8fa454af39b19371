/* A body's derived state after its pose changed (rotation, pose view, world bounds) and its
 * effective mass for this step. */
#include "body.h"

#include <string.h>

void gc_body_refresh_derived(gcWorld *w, int32_t id) {
    const gcModel *model = w->model;
    gcBody *b = &w->bodies[id];
    const gcBodyModel *m = &model->bodies[id];
    b->state.q = gc_quat_normalize(b->state.q);
    b->state.R = gc_quat_to_mat3(b->state.q);
    gcTransform frame = gc_body_transform(m, &b->state);
    gcVec3 origin = frame.p;
    double *pose = &w->pose_array[7 * id];
    pose[0] = origin.x, pose[1] = origin.y, pose[2] = origin.z;
    pose[3] = b->state.q.w, pose[4] = b->state.q.x, pose[5] = b->state.q.y, pose[6] = b->state.q.z;
    /* World AABB of all parts: each part's local box turned into world axes (centre
     * transformed, half extents through |R|), grown by the part's radius. */
    gcVec3 lo = gc_v3(INFINITY, INFINITY, INFINITY), hi = gc_neg(lo);
    for (int p = m->first_part; p < m->first_part + m->num_parts; ++p) {
        const gcHull *h = &model->parts[p].hull;
        gcVec3 centre = gc_transform_point(&frame, gc_scale(gc_add(h->aabb_min, h->aabb_max), 0.5));
        gcVec3 half = gc_scale(gc_sub(h->aabb_max, h->aabb_min), 0.5);
        double e[3];
        for (int i = 0; i < 3; ++i)
            e[i] = fabs(b->state.R.m[i][0]) * half.x + fabs(b->state.R.m[i][1]) * half.y + fabs(b->state.R.m[i][2]) * half.z + h->radius;
        lo = gc_v3(gc_min(lo.x, centre.x - e[0]), gc_min(lo.y, centre.y - e[1]), gc_min(lo.z, centre.z - e[2]));
        hi = gc_v3(gc_max(hi.x, centre.x + e[0]), gc_max(hi.y, centre.y + e[1]), gc_max(hi.z, centre.z + e[2]));
    }
    b->state.aabb_min = lo;
    b->state.aabb_max = hi;
}

void gc_body_inverse_effective_mass(const gcBodyModel *m, const gcBody *b, double M[36]) {
    memset(M, 0, 36 * sizeof(double));
    if (m->is_static || !b->effective_mass_valid) return;
    if (!b->coupled) {
        gcMat3 inv_inertia_world = gc_to_world(&b->inertia_rotation, &m->inv_inertia_local);
        for (int i = 0; i < 3; ++i) {
            M[6 * i + i] = m->inv_mass;
            for (int j = 0; j < 3; ++j) M[6 * (3 + i) + 3 + j] = inv_inertia_world.m[i][j];
        }
        return;
    }
    for (int j = 0; j < 6; ++j) {
        double e[6] = {0, 0, 0, 0, 0, 0}, col[6];
        e[j] = 1.0;
        gc_cholesky_solve6(b->effective_mass_factor, e, col);
        for (int r = 0; r < 6; ++r) M[6 * r + j] = col[r];
    }
}

