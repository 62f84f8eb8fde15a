"""The separating axis test of two convex hulls (the first stage of :mod:`.convex_convex`).

The candidate axes are the face normals of A, those of B, and the edge pairs that form a
face of the Minkowski difference A − B (the Gauss-map arc test of D. Gregorius, GDC 2013:
only those edge pairs can give the minimum, so the others are skipped without projecting
anything). The smallest overlap over them is the exact penetration depth when the hulls
overlap; when they are apart the largest separation is a lower bound of the distance. Hull
arrays as in :mod:`.convex` (:data:`.convex.HullArrays`). Compiled (``@njit(cache=True)``),
float64, without fastmath.
"""

from __future__ import annotations

import numpy as np

from ..compiling import njit
from .contact_output import Frame
from .convex import HullArrays
from .geometry import to_local

PARALLEL_SIN2 = 1e-12  # |e_a × e_b|² below this × |e_a|²|e_b|² (within 1e-6 rad of parallel): no edge axis


@njit(cache=True)
def _least_face_overlap(normal, offset, faces, points, count, margin, result, at):
    """The face axes of one hull against the other hull's ``points[:count]`` (both in one frame):
    each face's overlap is its offset − the least n · x over the points. Keeps the least overlap
    and its face in ``result[at]``, ``result[at + 1]`` (earliest on a tie); returns False as
    soon as a face separates the hulls by more than ``margin`` [m]."""
    for f in range(faces):
        n0, n1, n2 = normal[f, 0], normal[f, 1], normal[f, 2]
        lowest = np.inf
        for j in range(count):
            lowest = min(lowest, n0 * points[j, 0] + n1 * points[j, 1] + n2 * points[j, 2])
        overlap = offset[f] - lowest
        if overlap < -margin:
            return False
        if overlap < result[at]:
            result[at] = overlap
            result[at + 1] = f
    return True


@njit(cache=True)
def convex_convex_sat(
    frame_a: Frame,
    hull_a: HullArrays,
    frame_b: Frame,
    hull_b: HullArrays,
    margin: float,
    result: np.ndarray,
    axis: np.ndarray,
) -> tuple[bool, np.ndarray, np.ndarray, np.ndarray]:
    """Separating axis test of hull A against hull B, in A's body frame.

    Arguments as for :func:`convex_convex` (the face corner lists are not used). Fills ``result``
    (8,) float: [0] the smallest overlap [m] over A's face normals, [1] that face, [2] the
    smallest over B's faces, [3] that face, [4] the smallest over the Minkowski-face edge pairs
    (+inf when none), [5] that edge of A, [6] that edge of B, [7] the minimum of the three:
    the penetration depth when ≥ 0; when < 0, minus a lower bound of the distance. ``axis``
    (3,): the unit edge axis, A's frame, from A towards B.

    Returns (close, vb, nb, ob): ``close`` False as soon as some axis separates the hulls by
    more than ``margin`` (``result`` then incomplete); B's vertices (Vb, 3), face normals
    (Fb, 3) and offsets (Fb,) in A's frame.
    """
    center_a, rotation_a = frame_a
    center_b, rotation_b = frame_b
    vertices_a, face_normal_a, face_offset_a, _, _, edge_vertex_a, edge_face_a = hull_a
    vertices_b, face_normal_b, face_offset_b, _, _, edge_vertex_b, edge_face_b = hull_b
    Rab = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            Rab[i, j] = (
                rotation_a[0, i] * rotation_b[0, j]
                + rotation_a[1, i] * rotation_b[1, j]
                + rotation_a[2, i] * rotation_b[2, j]
            )
    t = to_local(rotation_a, center_a, center_b)
    count_b = vertices_b.shape[0]
    vb = np.empty((count_b, 3))
    for j in range(count_b):
        for i in range(3):
            vb[j, i] = Rab[i, 0] * vertices_b[j, 0] + Rab[i, 1] * vertices_b[j, 1] + Rab[i, 2] * vertices_b[j, 2] + t[i]
    faces_b = face_offset_b.shape[0]
    nb = np.empty((faces_b, 3))
    ob = np.empty(faces_b)
    for g in range(faces_b):
        for i in range(3):
            nb[g, i] = (
                Rab[i, 0] * face_normal_b[g, 0] + Rab[i, 1] * face_normal_b[g, 1] + Rab[i, 2] * face_normal_b[g, 2]
            )
        ob[g] = face_offset_b[g] + nb[g, 0] * t[0] + nb[g, 1] * t[1] + nb[g, 2] * t[2]
    for k in range(8):
        result[k] = np.inf
    result[5] = -1.0
    result[6] = -1.0
    # faces of A, then of B
    if not _least_face_overlap(face_normal_a, face_offset_a, face_offset_a.shape[0], vb, count_b, margin, result, 0):
        return False, vb, nb, ob
    count_a = vertices_a.shape[0]
    if not _least_face_overlap(nb, ob, faces_b, vertices_a, count_a, margin, result, 2):
        return False, vb, nb, ob
    # edge pairs that form a face of the Minkowski difference A − B (Gauss-map arcs cross).
    # Per edge of B, once: the negated normals c, d of its two faces and d × c (rows of ``arcs``)
    edges_b = edge_vertex_b.shape[0]
    arcs = np.empty((edges_b, 9))
    for eb in range(edges_b):
        fb0 = edge_face_b[eb, 0]
        fb1 = edge_face_b[eb, 1]
        c0, c1, c2 = -nb[fb0, 0], -nb[fb0, 1], -nb[fb0, 2]
        d0, d1, d2 = -nb[fb1, 0], -nb[fb1, 1], -nb[fb1, 2]
        arcs[eb, 0], arcs[eb, 1], arcs[eb, 2] = c0, c1, c2
        arcs[eb, 3], arcs[eb, 4], arcs[eb, 5] = d0, d1, d2
        arcs[eb, 6] = d1 * c2 - d2 * c1
        arcs[eb, 7] = d2 * c0 - d0 * c2
        arcs[eb, 8] = d0 * c1 - d1 * c0
    for ea in range(edge_vertex_a.shape[0]):
        fa0 = edge_face_a[ea, 0]
        fa1 = edge_face_a[ea, 1]
        a0, a1, a2 = face_normal_a[fa0, 0], face_normal_a[fa0, 1], face_normal_a[fa0, 2]
        b0, b1, b2 = face_normal_a[fa1, 0], face_normal_a[fa1, 1], face_normal_a[fa1, 2]
        bxa0 = b1 * a2 - b2 * a1
        bxa1 = b2 * a0 - b0 * a2
        bxa2 = b0 * a1 - b1 * a0
        pa = vertices_a[edge_vertex_a[ea, 0]]
        qa = vertices_a[edge_vertex_a[ea, 1]]
        E0, E1, E2 = qa[0] - pa[0], qa[1] - pa[1], qa[2] - pa[2]
        length_a2 = E0 * E0 + E1 * E1 + E2 * E2
        for eb in range(edges_b):
            arc = arcs[eb]
            cba = arc[0] * bxa0 + arc[1] * bxa1 + arc[2] * bxa2
            dba = arc[3] * bxa0 + arc[4] * bxa1 + arc[5] * bxa2
            if cba * dba >= 0.0:
                continue
            adc = a0 * arc[6] + a1 * arc[7] + a2 * arc[8]
            bdc = b0 * arc[6] + b1 * arc[7] + b2 * arc[8]
            if adc * bdc >= 0.0 or cba * bdc <= 0.0:
                continue
            pb = vb[edge_vertex_b[eb, 0]]
            qb = vb[edge_vertex_b[eb, 1]]
            F0, F1, F2 = qb[0] - pb[0], qb[1] - pb[1], qb[2] - pb[2]
            L0 = E1 * F2 - E2 * F1
            L1 = E2 * F0 - E0 * F2
            L2 = E0 * F1 - E1 * F0
            length2 = L0 * L0 + L1 * L1 + L2 * L2
            if length2 < PARALLEL_SIN2 * length_a2 * (F0 * F0 + F1 * F1 + F2 * F2):
                continue
            length = np.sqrt(length2)
            L0, L1, L2 = L0 / length, L1 / length, L2 / length
            if L0 * pa[0] + L1 * pa[1] + L2 * pa[2] < 0.0:  # orient from A (origin inside) towards B
                L0, L1, L2 = -L0, -L1, -L2
            overlap = -(L0 * (pb[0] - pa[0]) + L1 * (pb[1] - pa[1]) + L2 * (pb[2] - pa[2]))
            if overlap < -margin:
                return False, vb, nb, ob
            if overlap < result[4]:
                result[4] = overlap
                result[5] = ea
                result[6] = eb
                axis[0], axis[1], axis[2] = L0, L1, L2
    result[7] = min(result[0], min(result[2], result[4]))
    return True, vb, nb, ob
