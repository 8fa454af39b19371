"""Automatic convex decomposition of a closed triangle mesh (numpy only).

A small, predictable scheme rather than a full V-HACD:

1. split the mesh into connected islands;
2. an island whose concavity (how far its own vertices stick out above its face
   planes, relative to its size) exceeds ``tolerance`` is cut in two by the
   mid-plane across its longest bounding-box axis, the halves are split into
   islands again, and so on up to ``max_depth`` cuts.

Each piece is returned as the points whose convex hull is the part. The cap of a
cut never needs triangulating: its corners are the edge/plane intersection points,
which are vertices of the clipped triangles, and a cap never makes a piece concave.
"""
from __future__ import annotations

import numpy as np


def islands(triangles: np.ndarray, n_vertices: int) -> list:
    """Triangle index arrays of the connected components (shared vertices)."""
    parent = np.arange(n_vertices)

    def find(i):
        root = i
        while parent[root] != root:
            root = parent[root]
        while parent[i] != root:
            parent[i], i = root, parent[i]
        return root

    for a, b, c in triangles.tolist():
        ra, rb, rc = find(a), find(b), find(c)
        r = min(ra, rb, rc)
        parent[ra] = parent[rb] = parent[rc] = r
    roots = np.array([find(i) for i in triangles[:, 0].tolist()], dtype=np.int64)
    return [np.nonzero(roots == r)[0] for r in np.unique(roots)]


def concavity(vertices: np.ndarray, triangles: np.ndarray, max_samples: int = 1500) -> float:
    """Largest height of a vertex above a face plane, as a fraction of the piece's size."""
    used = np.unique(triangles)
    pts = vertices[used]
    size = float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0)))
    if size == 0.0:
        return 0.0
    tri = vertices[triangles]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area2 = np.linalg.norm(n, axis=1)
    ok = area2 > 1e-12 * size * size
    tri, n = tri[ok], n[ok] / area2[ok, None]
    if len(tri) == 0:
        return 0.0
    rng = np.random.default_rng(0)
    if len(tri) > max_samples:
        sel = rng.choice(len(tri), max_samples, replace=False)
        tri, n = tri[sel], n[sel]
    if len(pts) > max_samples:
        pts = pts[rng.choice(len(pts), max_samples, replace=False)]
    heights = (pts @ n.T) - np.einsum("ij,ij->i", tri[:, 0], n)[None, :]
    return float(max(heights.max(), 0.0)) / size


def clip(vertices: np.ndarray, triangles: np.ndarray, normal, offset: float, keep_above: bool):
    """Triangles of the part of the surface on one side of the plane ``x . normal = offset``.

    Returns (vertices, triangles); new vertices on straddling edges are computed once
    per edge (from its lower-index end) so neighbouring triangles share them.
    """
    s = vertices @ np.asarray(normal, dtype=np.float64) - offset
    side = s > 0 if keep_above else s <= 0
    kept = side[triangles]
    full = triangles[kept.all(axis=1)]
    part = triangles[kept.any(axis=1) & ~kept.all(axis=1)]
    new_vertices = []
    edge_vertex = {}

    def cut(a, b):
        key = (a, b) if a < b else (b, a)
        idx = edge_vertex.get(key)
        if idx is None:
            p, q = key
            t = s[p] / (s[p] - s[q])
            new_vertices.append(vertices[p] + t * (vertices[q] - vertices[p]))
            idx = len(vertices) + len(new_vertices) - 1
            edge_vertex[key] = idx
        return idx

    out = []
    for tri in part.tolist():
        poly = []
        for i in range(3):
            a, b = tri[i], tri[(i + 1) % 3]
            if side[a]:
                poly.append(a)
            if side[a] != side[b]:
                poly.append(cut(a, b))
        for k in range(1, len(poly) - 1):
            out.append((poly[0], poly[k], poly[k + 1]))
    v = np.vstack([vertices, np.array(new_vertices).reshape(-1, 3)])
    t = np.vstack([full, np.array(out, dtype=np.int64).reshape(-1, 3)])
    return v, t


def decompose(vertices, triangles, tolerance: float = 0.03, max_depth: int = 4,
              max_parts: int = 64) -> list:
    """Convex parts (as point arrays) approximating a closed mesh."""
    vertices = np.asarray(vertices, dtype=np.float64)
    triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    parts = []
    stack = [(vertices, triangles, 0)]
    while stack:
        v, t, depth = stack.pop()
        for isl in islands(t, len(v)):
            tt = t[isl]
            used = np.unique(tt)
            if len(used) < 4:
                continue
            if depth >= max_depth or len(parts) + len(stack) >= max_parts or \
                    concavity(v, tt) <= tolerance:
                parts.append(v[used])
                continue
            pts = v[used]
            lo, hi = pts.min(axis=0), pts.max(axis=0)
            axis = int(np.argmax(hi - lo))
            normal = np.zeros(3)
            normal[axis] = 1.0
            mid = 0.5 * (lo[axis] + hi[axis])
            for keep_above in (False, True):
                cv, ct = clip(v, tt, normal, mid, keep_above)
                if len(ct):
                    stack.append((cv, ct, depth + 1))
    return parts
