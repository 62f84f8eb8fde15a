"""Where a point or a segment lies over a face polygon of a convex hull (hull frame).

The face queries of the capsule–hull routine (:mod:`.capsule_convex`): the part of a segment
over a face (clipped by the side planes of its polygon) and whether a point projects into a
face. Hull arrays as in :mod:`.convex` (:data:`.convex.HullArrays`). Compiled
(``@njit(cache=True)``), float64, without fastmath.
"""

from __future__ import annotations

import numpy as np

from ..compiling import njit
from .convex import HullArrays


@njit(cache=True)
def _side_normal(vertices, face_vertex_index, start, stop, i, n):
    """Edge i of a face polygon (its corners ``face_vertex_index[start:stop]``, counter-clockwise
    seen from outside, face normal ``n`` (3,)): its first corner a (3,) [m] and its outward side
    normal e × n, not normalized (three floats)."""
    a = vertices[face_vertex_index[i]]
    b = vertices[face_vertex_index[i + 1 if i + 1 < stop else start]]
    e0, e1, e2 = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    return a, e1 * n[2] - e2 * n[1], e2 * n[0] - e0 * n[2], e0 * n[1] - e1 * n[0]


@njit(cache=True)
def segment_over_face(
    origin: np.ndarray, direction: np.ndarray, half_length: float, hull: HullArrays, face: int, tol: float
) -> tuple[float, float]:
    """Parameters ``(lo, hi)`` [m] of the part of the segment ``origin + s · direction``,
    ``|s| ≤ half_length`` (hull frame; origin (3,) [m], direction (3,) unit), over face ``face``
    (inside all side planes of its polygon, widened by ``tol`` [m]); ``lo > hi`` when there is none."""
    vertices, face_normal, _, face_vertex_start, face_vertex_index = hull[:5]
    base = face_vertex_start[0]
    start = face_vertex_start[face] - base
    stop = face_vertex_start[face + 1] - base
    n = face_normal[face]
    lo = -half_length
    hi = half_length
    for i in range(start, stop):
        a, m0, m1, m2 = _side_normal(vertices, face_vertex_index, start, stop, i, n)
        length = np.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
        if length == 0.0:
            continue
        m0, m1, m2 = m0 / length, m1 / length, m2 / length
        limit = m0 * a[0] + m1 * a[1] + m2 * a[2] + tol
        at_origin = m0 * origin[0] + m1 * origin[1] + m2 * origin[2]
        rate = m0 * direction[0] + m1 * direction[1] + m2 * direction[2]
        if rate == 0.0:
            if at_origin > limit:
                return 1.0, -1.0
            continue
        t = (limit - at_origin) / rate
        if rate > 0.0:
            hi = min(hi, t)
        else:
            lo = max(lo, t)
    return lo, hi


@njit(cache=True)
def projects_into_face(x: np.ndarray, hull: HullArrays, face: int) -> bool:
    """Whether the point ``x`` (3,) [m] (hull frame) projects into face ``face``'s polygon (closed)."""
    vertices, face_normal, _, face_vertex_start, face_vertex_index = hull[:5]
    base = face_vertex_start[0]
    start = face_vertex_start[face] - base
    stop = face_vertex_start[face + 1] - base
    n = face_normal[face]
    for i in range(start, stop):
        a, m0, m1, m2 = _side_normal(vertices, face_vertex_index, start, stop, i, n)
        if m0 * (x[0] - a[0]) + m1 * (x[1] - a[1]) + m2 * (x[2] - a[2]) > 0.0:
            return False
    return True
