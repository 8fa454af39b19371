/* Convex hull construction (incremental quickhull) and mass properties.
 * The only allocating part of the geometry module: called once per part at body
 * creation. Deterministic: points are processed in a fixed order (farthest first,
 * ties broken by input index). */
#include "geometry.h"

#include <float.h>
#include <stdlib.h>
#include <string.h>

/* Hulls with more vertices than this get vertex adjacency and hill-climbing support. */
#define GC_HILL_CLIMB_MIN_VERTICES 24

static const double kPi = 3.14159265358979323846;

typedef struct BuildFace {
    int v[3];   /* CCW from outside; edge i runs v[i] -> v[(i+1)%3] */
    int nb[3];  /* face across edge i */
    gcVec3 n;
    double d;
    int alive;
    int mark;   /* visibility stamp of the current iteration */
} BuildFace;

typedef struct Builder {
    const gcVec3 *pts;
    int n;
    double tol;
    BuildFace *faces;
    int num_faces, cap_faces;
    int *owner;          /* face whose outside set holds the point, -1 when none */
    double *owner_dist;  /* distance of the point above that face */
    int *horizon_of;     /* vertex -> index of the horizon edge starting there, -1 */
} Builder;

static double point_plane(const BuildFace *f, gcVec3 p) { return gc_dot(f->n, p) - f->d; }

static void face_plane(const Builder *b, BuildFace *f) {
    gcVec3 a = b->pts[f->v[0]], p1 = b->pts[f->v[1]], p2 = b->pts[f->v[2]];
    f->n = gc_normalize(gc_cross(gc_sub(p1, a), gc_sub(p2, a)));
    /* Offset from the mean of the three vertices: symmetric rounding. */
    f->d = (gc_dot(f->n, a) + gc_dot(f->n, p1) + gc_dot(f->n, p2)) / 3.0;
}

static int add_face(Builder *b, int v0, int v1, int v2) {
    if (b->num_faces == b->cap_faces) {
        int cap = b->cap_faces ? 2 * b->cap_faces : 64;
        BuildFace *nf = (BuildFace *)realloc(b->faces, (size_t)cap * sizeof(BuildFace));
        if (!nf) return -1;
        b->faces = nf;
        b->cap_faces = cap;
    }
    BuildFace *f = &b->faces[b->num_faces];
    f->v[0] = v0; f->v[1] = v1; f->v[2] = v2;
    f->nb[0] = f->nb[1] = f->nb[2] = -1;
    f->alive = 1;
    f->mark = -1;
    face_plane(b, f);
    return b->num_faces++;
}

/* Index of edge a->b in face f, or -1. */
static int face_edge(const BuildFace *f, int a, int b) {
    for (int i = 0; i < 3; ++i)
        if (f->v[i] == a && f->v[(i + 1) % 3] == b) return i;
    return -1;
}

/* Assign point i to the face (among faces[first..last)) it is farthest above, if > tol. */
static void assign_point(Builder *b, int i, int first, int last) {
    int best = -1;
    double best_d = b->tol;
    for (int f = first; f < last; ++f) {
        if (!b->faces[f].alive) continue;
        double d = point_plane(&b->faces[f], b->pts[i]);
        if (d > best_d) { best_d = d; best = f; }
    }
    b->owner[i] = best;
    b->owner_dist[i] = best >= 0 ? best_d : 0.0;
}

typedef struct HorizonEdge { int a, b, outside, new_face; } HorizonEdge;

/* Adds point `eye` to the hull. Returns 0 on success, 1 when the point is skipped
 * because the visible region is not a disc (numerically inconsistent), -1 on OOM. */
static int add_point(Builder *b, int eye, int stamp, int **stack_io, int *stack_cap,
                     HorizonEdge **horizon_io, int *horizon_cap) {
    gcVec3 p = b->pts[eye];
    int *stack = *stack_io;
    int top = 0, num_visible = 0;
    int f0 = b->owner[eye];
    /* Flood the visible region from the owning face: keeps it connected. */
    b->faces[f0].mark = stamp;
    stack[top++] = f0;
    int num_horizon = 0;
    while (top > 0) {
        int fi = stack[--top];
        ++num_visible;
        for (int e = 0; e < 3; ++e) {
            int g = b->faces[fi].nb[e];
            if (b->faces[g].mark == stamp) continue;
            if (point_plane(&b->faces[g], p) > b->tol) {
                b->faces[g].mark = stamp;
                if (top >= *stack_cap) {
                    int cap = 2 * *stack_cap;
                    int *ns = (int *)realloc(stack, (size_t)cap * sizeof(int));
                    if (!ns) { *stack_io = stack; return -1; }
                    stack = ns;
                    *stack_cap = cap;
                }
                stack[top++] = g;
            }
        }
    }
    *stack_io = stack;
    /* Horizon: edges of visible faces whose neighbour is not visible. */
    for (int fi = 0; fi < b->num_faces; ++fi) {
        BuildFace *f = &b->faces[fi];
        if (!f->alive || f->mark != stamp) continue;
        for (int e = 0; e < 3; ++e) {
            int g = f->nb[e];
            if (b->faces[g].mark == stamp) continue;
            if (num_horizon >= *horizon_cap) {
                int cap = 2 * *horizon_cap;
                HorizonEdge *nh = (HorizonEdge *)realloc(*horizon_io, (size_t)cap * sizeof(HorizonEdge));
                if (!nh) return -1;
                *horizon_io = nh;
                *horizon_cap = cap;
            }
            HorizonEdge h = {f->v[e], f->v[(e + 1) % 3], g, -1};
            (*horizon_io)[num_horizon++] = h;
        }
    }
    HorizonEdge *horizon = *horizon_io;
    /* The horizon must be one simple loop; otherwise leave the hull untouched. */
    int ok = num_horizon >= 3;
    for (int h = 0; h < num_horizon && ok; ++h) {
        if (b->horizon_of[horizon[h].a] != -1) ok = 0;
        else b->horizon_of[horizon[h].a] = h;
    }
    if (ok) {
        int h = 0, steps = 0;
        do {
            h = b->horizon_of[horizon[h].b];
            ++steps;
        } while (h > 0 && steps <= num_horizon);
        ok = (h == 0 && steps == num_horizon);
    }
    if (!ok) {
        for (int h = 0; h < num_horizon; ++h)
            if (b->horizon_of[horizon[h].a] == h) b->horizon_of[horizon[h].a] = -1;
        for (int fi = 0; fi < b->num_faces; ++fi)
            if (b->faces[fi].mark == stamp) b->faces[fi].mark = -1;
        return 1;
    }
    int first_new = b->num_faces;
    for (int h = 0; h < num_horizon; ++h) {
        int nf = add_face(b, horizon[h].a, horizon[h].b, eye);
        if (nf < 0) return -1;
        horizon[h].new_face = nf;
    }
    for (int h = 0; h < num_horizon; ++h) {
        BuildFace *f = &b->faces[horizon[h].new_face];
        BuildFace *out = &b->faces[horizon[h].outside];
        f->nb[0] = horizon[h].outside;
        out->nb[face_edge(out, horizon[h].b, horizon[h].a)] = horizon[h].new_face;
        f->nb[1] = horizon[b->horizon_of[horizon[h].b]].new_face;
    }
    for (int h = 0; h < num_horizon; ++h) {
        int next = b->horizon_of[horizon[h].b];
        b->faces[horizon[next].new_face].nb[2] = horizon[h].new_face;
    }
    for (int h = 0; h < num_horizon; ++h) b->horizon_of[horizon[h].a] = -1;
    for (int fi = 0; fi < first_new; ++fi)
        if (b->faces[fi].mark == stamp) b->faces[fi].alive = 0;
    /* Points outside the deleted faces move to the new faces (or become interior). */
    b->owner[eye] = -1;
    for (int i = 0; i < b->n; ++i) {
        int o = b->owner[i];
        if (o >= 0 && !b->faces[o].alive) assign_point(b, i, first_new, b->num_faces);
    }
    (void)num_visible;
    return 0;
}

static gcStatus make_sphere_or_capsule(gcVec3 p0, gcVec3 p1, int count, double radius, gcHull *out) {
    if (count == 1) p1 = p0;
    out->vertices = (gcVec3 *)malloc((size_t)count * sizeof(gcVec3));
    if (!out->vertices) return GC_ERR_NO_MEMORY;
    out->num_vertices = count;
    out->vertices[0] = p0;
    if (count == 2) {
        out->vertices[1] = p1;
        out->edges = (int *)malloc(2 * sizeof(int)); /* a capsule's segment is its one edge */
        if (!out->edges) return GC_ERR_NO_MEMORY;
        out->edges[0] = 0, out->edges[1] = 1;
        out->num_edges = 1;
    }
    out->radius = radius;
    out->aabb_min = gc_v3(fmin(p0.x, p1.x), fmin(p0.y, p1.y), fmin(p0.z, p1.z));
    out->aabb_max = gc_v3(fmax(p0.x, p1.x), fmax(p0.y, p1.y), fmax(p0.z, p1.z));
    out->min_width = 2.0 * radius;
    gcVec3 axis = gc_sub(p1, p0);
    double len = gc_len(axis);
    double r2 = radius * radius;
    double m_cyl = kPi * r2 * len;
    double m_sph = 4.0 / 3.0 * kPi * r2 * radius;
    out->volume = m_cyl + m_sph;
    out->centroid = gc_scale(gc_add(p0, p1), 0.5);
    /* Cylinder plus two hemispheres (hemisphere centroid 3r/8 from its flat face). */
    double i_axis = m_cyl * r2 / 2.0 + m_sph * 2.0 * r2 / 5.0;
    double i_perp = m_cyl * (len * len / 12.0 + r2 / 4.0) +
                    m_sph * (2.0 * r2 / 5.0 + len * len / 4.0 + 3.0 * len * radius / 8.0);
    gcVec3 u = len > 0.0 ? gc_scale(axis, 1.0 / len) : gc_v3(0, 0, 1);
    double uu[3] = {u.x, u.y, u.z};
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            out->inertia_unit.m[i][j] = (i == j ? i_perp : 0.0) + (i_axis - i_perp) * uu[i] * uu[j];
    return GC_OK;
}

/* Polyhedral volume, centroid and inertia from signed tetrahedra about a reference
 * point inside the hull (the vertex mean keeps the sums well conditioned). */
static void polyhedron_mass(gcHull *h) {
    gcVec3 ref = gc_v3(0, 0, 0);
    for (int i = 0; i < h->num_vertices; ++i) ref = gc_add(ref, h->vertices[i]);
    ref = gc_scale(ref, 1.0 / h->num_vertices);
    double vol6 = 0.0;
    gcVec3 first = gc_v3(0, 0, 0);
    double cov[3][3] = {{0}};
    for (int t = 0; t < h->num_triangles; ++t) {
        gcVec3 a = gc_sub(h->vertices[h->triangles[3 * t]], ref);
        gcVec3 b = gc_sub(h->vertices[h->triangles[3 * t + 1]], ref);
        gcVec3 c = gc_sub(h->vertices[h->triangles[3 * t + 2]], ref);
        double det = gc_dot(a, gc_cross(b, c));
        gcVec3 s = gc_add(gc_add(a, b), c);
        vol6 += det;
        first = gc_madd(first, s, det);
        /* Covariance of tetrahedron (0,a,b,c): det/120 (s s^T + a a^T + b b^T + c c^T). */
        double sv[3] = {s.x, s.y, s.z}, av[3] = {a.x, a.y, a.z}, bv[3] = {b.x, b.y, b.z},
               cv[3] = {c.x, c.y, c.z};
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j)
                cov[i][j] += det * (sv[i] * sv[j] + av[i] * av[j] + bv[i] * bv[j] + cv[i] * cv[j]);
    }
    double volume = vol6 / 6.0;
    gcVec3 c_rel = gc_scale(first, 1.0 / (4.0 * vol6));
    double cr[3] = {c_rel.x, c_rel.y, c_rel.z};
    double cc[3][3];
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) cc[i][j] = cov[i][j] / 120.0 - volume * cr[i] * cr[j];
    double tr = cc[0][0] + cc[1][1] + cc[2][2];
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) h->inertia_unit.m[i][j] = (i == j ? tr : 0.0) - cc[i][j];
    h->volume = volume;
    h->centroid = gc_add(ref, c_rel);
}

/* Structure-of-arrays copy of the vertices (see gcHull): x[], y[], z[] padded to a
 * multiple of 4 with copies of vertex 0, so that the support scan runs on whole
 * aligned blocks and the padding never wins over vertex 0 (ties go to the lowest index). */
static gcStatus build_soa(gcHull *h) {
    int np = (h->num_vertices + 3) & ~3;
    /* 3 * np doubles is a multiple of 96 bytes, hence of the 32-byte alignment. */
    double *block = (double *)aligned_alloc(32, (size_t)np * 3 * sizeof(double));
    if (!block) return GC_ERR_NO_MEMORY;
    h->soa_x = block;
    h->soa_y = block + np;
    h->soa_z = block + 2 * np;
    h->num_padded = np;
    for (int i = 0; i < np; ++i) {
        gcVec3 v = h->vertices[i < h->num_vertices ? i : 0];
        h->soa_x[i] = v.x;
        h->soa_y[i] = v.y;
        h->soa_z[i] = v.z;
    }
    return GC_OK;
}

void gc_hull_free(gcHull *hull) {
    if (!hull) return;
    free(hull->edges);
    free(hull->soa_x);
    free(hull->vertices);
    free(hull->triangles);
    free(hull->plane_normals);
    free(hull->plane_offsets);
    free(hull->adjacency);
    free(hull->adjacency_start);
    memset(hull, 0, sizeof(*hull));
}

/* Faces within this of parallel are one face (its triangles' shared edges are not features). */
#define GC_FEATURE_EDGE_COS (1.0 - 1e-6)

typedef struct EdgeRef {
    int64_t key; /* min * nv + max */
    int tri;
} EdgeRef;

static int compare_edge_refs(const void *pa, const void *pb) {
    const EdgeRef *a = pa, *b = pb;
    if (a->key != b->key) return a->key < b->key ? -1 : 1;
    return (a->tri > b->tri) - (a->tri < b->tri);
}

/* The hull's feature edges: each triangle edge whose two triangles are not coplanar (the
 * diagonals that split a planar face are left out), found by sorting the 3 nt edge keys. */
static gcStatus find_feature_edges(gcHull *out) {
    int nt = out->num_triangles, nv = out->num_vertices;
    if (nt == 0) return GC_OK;
    EdgeRef *refs = (EdgeRef *)malloc((size_t)nt * 3 * sizeof(EdgeRef));
    out->edges = (int *)malloc((size_t)nt * 3 * sizeof(int)); /* at most 3 nt / 2 edges */
    if (!refs || !out->edges) {
        free(refs);
        return GC_ERR_NO_MEMORY;
    }
    for (int t = 0; t < nt; ++t)
        for (int k = 0; k < 3; ++k) {
            int a = out->triangles[3 * t + k], c = out->triangles[3 * t + (k + 1) % 3];
            int lo = a < c ? a : c, hi = a < c ? c : a;
            refs[3 * t + k].key = (int64_t)lo * nv + hi;
            refs[3 * t + k].tri = t;
        }
    qsort(refs, (size_t)nt * 3, sizeof *refs, compare_edge_refs);
    int ne = 0;
    for (int i = 0; i < 3 * nt;) {
        int j = i + 1;
        while (j < 3 * nt && refs[j].key == refs[i].key) ++j;
        int feature = j - i != 2 ||
                      gc_dot(out->plane_normals[refs[i].tri], out->plane_normals[refs[i + 1].tri]) < GC_FEATURE_EDGE_COS;
        if (feature) {
            out->edges[2 * ne] = (int)(refs[i].key / nv);
            out->edges[2 * ne + 1] = (int)(refs[i].key % nv);
            ++ne;
        }
        i = j;
    }
    free(refs);
    out->num_edges = ne;
    return GC_OK;
}

static gcStatus finish_hull(Builder *b, double radius, gcHull *out) {
    int *remap = (int *)malloc((size_t)b->n * sizeof(int));
    if (!remap) return GC_ERR_NO_MEMORY;
    for (int i = 0; i < b->n; ++i) remap[i] = -1;
    int nt = 0, nv = 0;
    for (int f = 0; f < b->num_faces; ++f) {
        if (!b->faces[f].alive) continue;
        ++nt;
        for (int k = 0; k < 3; ++k) remap[b->faces[f].v[k]] = 0;
    }
    for (int i = 0; i < b->n; ++i)
        if (remap[i] == 0) remap[i] = nv++;
    out->num_vertices = nv;
    out->num_triangles = nt;
    out->num_planes = nt;
    out->radius = radius;
    out->vertices = (gcVec3 *)malloc((size_t)nv * sizeof(gcVec3));
    out->triangles = (int *)malloc((size_t)nt * 3 * sizeof(int));
    out->plane_normals = (gcVec3 *)malloc((size_t)nt * sizeof(gcVec3));
    out->plane_offsets = (double *)malloc((size_t)nt * sizeof(double));
    out->adjacency_start = (int *)calloc((size_t)nv + 1, sizeof(int));
    out->adjacency = (int *)malloc((size_t)nt * 3 * sizeof(int));
    if (!out->vertices || !out->triangles || !out->plane_normals || !out->plane_offsets ||
        !out->adjacency_start || !out->adjacency) {
        free(remap);
        return GC_ERR_NO_MEMORY;
    }
    for (int i = 0; i < b->n; ++i)
        if (remap[i] >= 0) out->vertices[remap[i]] = b->pts[i];
    int t = 0;
    for (int f = 0; f < b->num_faces; ++f) {
        if (!b->faces[f].alive) continue;
        for (int k = 0; k < 3; ++k) out->triangles[3 * t + k] = remap[b->faces[f].v[k]];
        out->plane_normals[t] = b->faces[f].n;
        out->plane_offsets[t] = b->faces[f].d;
        ++t;
    }
    free(remap);
    /* Vertex adjacency: on a closed manifold every directed edge a->b occurs once. */
    for (int k = 0; k < 3 * nt; ++k) out->adjacency_start[out->triangles[k] + 1]++;
    for (int i = 0; i < nv; ++i) out->adjacency_start[i + 1] += out->adjacency_start[i];
    int *fill = (int *)calloc((size_t)nv, sizeof(int));
    if (!fill) return GC_ERR_NO_MEMORY;
    for (int tri = 0; tri < nt; ++tri)
        for (int k = 0; k < 3; ++k) {
            int a = out->triangles[3 * tri + k], bb = out->triangles[3 * tri + (k + 1) % 3];
            out->adjacency[out->adjacency_start[a] + fill[a]++] = bb;
        }
    free(fill);
    if (nv <= GC_HILL_CLIMB_MIN_VERTICES) {
        free(out->adjacency);
        free(out->adjacency_start);
        out->adjacency = NULL;
        out->adjacency_start = NULL;
    }
    if (find_feature_edges(out) != GC_OK) return GC_ERR_NO_MEMORY;
    /* Thin faces have normals good to ~eps/width: push each plane out to its
     * farthest vertex so that no vertex is ever outside a plane. */
    for (int f = 0; f < nt; ++f) {
        double far = gc_dot(out->plane_normals[f], gc_hull_support(out, out->plane_normals[f]));
        if (far > out->plane_offsets[f]) out->plane_offsets[f] = far;
    }
    out->aabb_min = out->aabb_max = out->vertices[0];
    for (int i = 1; i < nv; ++i) {
        gcVec3 v = out->vertices[i];
        out->aabb_min = gc_v3(fmin(out->aabb_min.x, v.x), fmin(out->aabb_min.y, v.y), fmin(out->aabb_min.z, v.z));
        out->aabb_max = gc_v3(fmax(out->aabb_max.x, v.x), fmax(out->aabb_max.y, v.y), fmax(out->aabb_max.z, v.z));
    }
    double min_width = DBL_MAX;
    for (int f = 0; f < nt; ++f) {
        gcVec3 n = out->plane_normals[f];
        gcVec3 s = gc_hull_support(out, gc_neg(n));
        double w = out->plane_offsets[f] - gc_dot(n, s);
        if (w < min_width) min_width = w;
    }
    out->min_width = min_width + 2.0 * radius;
    polyhedron_mass(out);
    return GC_OK;
}

/* Quickhull from the tetrahedron (i0, i1, i2, i3) (pn: the normal of the face (i0, i1, i2)): the
 * furthest outside point added until none is left, then the hull finished and inflated by radius. */
static gcStatus quickhull(const gcVec3 *pts, int n, double tol, double radius, int i0, int i1, int i2, int i3,
                          gcVec3 pn, gcHull *out) {
    Builder b;
    memset(&b, 0, sizeof(b));
    b.pts = pts;
    b.n = n;
    b.tol = tol;
    b.owner = (int *)malloc((size_t)n * sizeof(int));
    b.owner_dist = (double *)malloc((size_t)n * sizeof(double));
    b.horizon_of = (int *)malloc((size_t)n * sizeof(int));
    int stack_cap = 64, horizon_cap = 64;
    int *stack = (int *)malloc((size_t)stack_cap * sizeof(int));
    HorizonEdge *horizon = (HorizonEdge *)malloc((size_t)horizon_cap * sizeof(HorizonEdge));
    gcStatus status = GC_OK;
    if (!b.owner || !b.owner_dist || !b.horizon_of || !stack || !horizon) {
        status = GC_ERR_NO_MEMORY;
        goto done;
    }
    for (int i = 0; i < n; ++i) b.horizon_of[i] = -1;

    /* Initial tetrahedron, oriented so that i3 is below face (i0, i1, i2). */
    if (gc_dot(gc_sub(pts[i3], pts[i0]), pn) > 0.0) { int t = i1; i1 = i2; i2 = t; }
    int tet[4][3] = {{i0, i1, i2}, {i0, i3, i1}, {i1, i3, i2}, {i2, i3, i0}};
    for (int f = 0; f < 4; ++f)
        if (add_face(&b, tet[f][0], tet[f][1], tet[f][2]) < 0) { status = GC_ERR_NO_MEMORY; goto done; }
    for (int f = 0; f < 4; ++f)
        for (int e = 0; e < 3; ++e)
            for (int g = 0; g < 4; ++g)
                if (g != f && face_edge(&b.faces[g], b.faces[f].v[(e + 1) % 3], b.faces[f].v[e]) >= 0)
                    b.faces[f].nb[e] = g;
    for (int i = 0; i < n; ++i) {
        if (i == i0 || i == i1 || i == i2 || i == i3) { b.owner[i] = -1; continue; }
        assign_point(&b, i, 0, 4);
    }
    for (int stamp = 0;; ++stamp) {
        int eye = -1;
        double far = 0.0;
        for (int i = 0; i < n; ++i)
            if (b.owner[i] >= 0 && b.owner_dist[i] > far) { far = b.owner_dist[i]; eye = i; }
        if (eye < 0) break;
        int r = add_point(&b, eye, stamp, &stack, &stack_cap, &horizon, &horizon_cap);
        if (r < 0) { status = GC_ERR_NO_MEMORY; goto done; }
        if (r > 0) b.owner[eye] = -1; /* skipped: within rounding of the hull */
    }
    status = finish_hull(&b, radius, out);
    if (status == GC_OK) status = build_soa(out);
done:
    free(b.faces);
    free(b.owner);
    free(b.owner_dist);
    free(b.horizon_of);
    free(stack);
    free(horizon);
    if (status != GC_OK) gc_hull_free(out);
    return status;
}

gcStatus gc_hull_build(const double *points, int n, double radius, double tolerance, gcHull *out) {
    if (!out) return GC_ERR_INVALID_ARGUMENT;
    memset(out, 0, sizeof(*out));
    if (!points || n < 1 || !isfinite(radius) || radius < 0.0 || !isfinite(tolerance) || tolerance < 0.0)
        return GC_ERR_INVALID_ARGUMENT;
    for (int i = 0; i < 3 * n; ++i)
        if (!isfinite(points[i])) return GC_ERR_INVALID_ARGUMENT;
    const gcVec3 *pts = (const gcVec3 *)(const void *)points;
    /* gcVec3 is three packed doubles; reading through it avoids a copy. */
    _Static_assert(sizeof(gcVec3) == 3 * sizeof(double), "gcVec3 must be packed");

    gcVec3 lo = pts[0], hi = pts[0];
    double max_abs = 0.0;
    int ext_lo[3] = {0, 0, 0}, ext_hi[3] = {0, 0, 0};
    for (int i = 0; i < n; ++i) {
        double c[3] = {pts[i].x, pts[i].y, pts[i].z};
        double l[3] = {lo.x, lo.y, lo.z}, h[3] = {hi.x, hi.y, hi.z};
        for (int k = 0; k < 3; ++k) {
            if (c[k] < l[k]) { l[k] = c[k]; ext_lo[k] = i; }
            if (c[k] > h[k]) { h[k] = c[k]; ext_hi[k] = i; }
            if (fabs(c[k]) > max_abs) max_abs = fabs(c[k]);
        }
        lo = gc_v3(l[0], l[1], l[2]);
        hi = gc_v3(h[0], h[1], h[2]);
    }
    gcVec3 ext = gc_sub(hi, lo);
    double extent = fmax(ext.x, fmax(ext.y, ext.z));
    /* Scale-relative: relative to the size, plus rounding of large coordinates. */
    double tol = tolerance > 0.0 ? tolerance : 1e-10 * extent + 8.0 * DBL_EPSILON * max_abs;

    if (extent <= tol) {
        if (radius > 0.0) {
            gcStatus st = make_sphere_or_capsule(gc_scale(gc_add(lo, hi), 0.5), gc_v3(0, 0, 0), 1, radius, out);
            if (st == GC_OK) st = build_soa(out);
            if (st != GC_OK) gc_hull_free(out);
            return st;
        }
        return GC_ERR_DEGENERATE;
    }
    int axis = ext.x >= ext.y && ext.x >= ext.z ? 0 : (ext.y >= ext.z ? 1 : 2);
    int i0 = ext_lo[axis], i1 = ext_hi[axis];
    gcVec3 dir = gc_normalize(gc_sub(pts[i1], pts[i0]));
    int i2 = -1;
    double best = tol;
    for (int i = 0; i < n; ++i) {
        double d = gc_len(gc_cross(gc_sub(pts[i], pts[i0]), dir));
        if (d > best) { best = d; i2 = i; }
    }
    if (i2 < 0) {
        if (radius > 0.0) {
            /* Collinear: a capsule between the two extreme points along the line. */
            int lo_i = 0, hi_i = 0;
            for (int i = 1; i < n; ++i) {
                double t = gc_dot(pts[i], dir);
                if (t < gc_dot(pts[lo_i], dir)) lo_i = i;
                if (t > gc_dot(pts[hi_i], dir)) hi_i = i;
            }
            gcStatus st = make_sphere_or_capsule(pts[lo_i], pts[hi_i], 2, radius, out);
            if (st == GC_OK) st = build_soa(out);
            if (st != GC_OK) gc_hull_free(out);
            return st;
        }
        return GC_ERR_DEGENERATE;
    }
    gcVec3 pn = gc_normalize(gc_cross(gc_sub(pts[i1], pts[i0]), gc_sub(pts[i2], pts[i0])));
    int i3 = -1;
    best = tol;
    for (int i = 0; i < n; ++i) {
        double d = fabs(gc_dot(gc_sub(pts[i], pts[i0]), pn));
        if (d > best) { best = d; i3 = i; }
    }
    if (i3 < 0) return GC_ERR_DEGENERATE; /* coplanar: no volume, even with a radius */

    return quickhull(pts, n, tol, radius, i0, i1, i2, i3, pn, out);
}
