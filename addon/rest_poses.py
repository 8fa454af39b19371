"""Where the last session started the dynamic bodies (stored on each object), so Reset Bodies
puts them back and the session panel can say which have moved since."""
from __future__ import annotations

import bpy


def store_rest_poses(context, links):
    for link in links:
        obj = bpy.data.objects.get(link.name)
        if obj is not None and not link.static:
            obj.grasp_lab.rest_matrix = [v for row in obj.matrix_world for v in row]
            obj.grasp_lab.has_rest = True


def moved_from_rest(context, tolerance: float = 1e-6) -> list:
    """Dynamic bodies that are not where the last session started them (Reset Bodies puts
    them back)."""
    out = []
    for obj in context.view_layer.objects:
        gl = obj.grasp_lab
        if gl.has_rest and gl.role == "DYNAMIC":
            now = [v for row in obj.matrix_world for v in row]
            if max(abs(a - b) for a, b in zip(now, gl.rest_matrix)) > tolerance:
                out.append(obj)
    return out


def restore_rest_poses(context) -> int:
    """Put bodies back where the last session started them. Returns how many moved."""
    from mathutils import Matrix
    n = 0
    for obj in context.view_layer.objects:
        gl = obj.grasp_lab
        if gl.has_rest and gl.role == "DYNAMIC":
            v = list(gl.rest_matrix)
            obj.matrix_world = Matrix([v[0:4], v[4:8], v[8:12], v[12:16]])
            n += 1
    return n
