"""Closest features of static triangle meshes, and the choice among a shape's candidate contacts:
what every mesh routine is built on.

A point's closest point on a triangle comes with its Voronoi region (the face, one of the
3 edges, one of the 3 vertices); the region's *pseudo-normal* (Bærentzen–Aanæs: exact for a
closed mesh) tells whether the point is inside a one-sided mesh. The contact routines
(:mod:`.sphere_mesh`, :mod:`.polytope_mesh`, :mod:`.capsule_mesh`), the static signed
distances (:mod:`.signed_distance`) and the swept test (:mod:`.mesh_sweep`) all judge a point
by these rules, so they agree on what is inside. A shape's candidate contacts (rows of
:func:`.contact_output.pair_output`) are chosen by :func:`keep_deepest` or
:func:`keep_spread` when there are more than it may keep, and written by :func:`write_kept`.
Meshes are :class:`~contactlab.meshes.MeshGeometry` tuples (``TriangleMesh.geometry``).

Everything is compiled (``@njit(cache=True)``), float64, no fastmath; scalar arithmetic, no
allocation in the inner loops.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..compiling import njit
from ..meshes import mesh_triangles_near
from .contact_output import PairOutput, write_contact
from .geometry import segment_closest_parameters

if TYPE_CHECKING:
    from ..meshes import MeshGeometry

FACE, EDGE0, EDGE1, EDGE2, VERTEX0, VERTEX1, VERTEX2 = 0, 1, 2, 3, 4, 5, 6  # Voronoi regions of a triangle
FEATURES_PER_TRIANGLE = 16  # contact feature = 16 · triangle + local index (local index < 16)


@njit(cache=True)
def edge_projections(
    p: np.ndarray, vertex: np.ndarray, ab: tuple[float, float, float], ac: tuple[float, float, float]
) -> tuple[float, float]:
    """(ab · (p − vertex), ac · (p − vertex)): the point p (3,) [m] relative to a triangle's
    vertex (3,) [m], projected on its edges ab and ac (3 scalars each, [m]) — the numbers that
    place p in or out of that vertex's Voronoi region (``closest_point_on_triangle``)."""
    vx, vy, vz = p[0] - vertex[0], p[1] - vertex[1], p[2] - vertex[2]
    return ab[0] * vx + ab[1] * vy + ab[2] * vz, ac[0] * vx + ac[1] * vy + ac[2] * vz


@njit(cache=True, inline="always")
def _vertex_then_edge(
    own: float,
    across: float,
    along_edge: float,
    along_other: float,
    vertex: tuple[float, float, float],
    a: tuple[float, float, float],
    edge: tuple[float, float, float],
    regions: tuple[int, int],
) -> tuple[float, float, float, float, int]:
    """Ericson's test of a triangle's ``vertex`` (b or c; 3 scalars [m]), then of the ``edge`` from
    its corner ``a`` to it, for a point p given by its projections: ``own``, ``across`` = (p −
    vertex) on that edge and on the other edge from a; ``along_edge``, ``along_other`` = (p − a)
    on them. Returns the edge's barycentric test value (vc for b, vb for c in
    ``closest_point_on_triangle``), and the closest point (qx, qy, qz) with the vertex's or the
    edge's region (``regions`` = (vertex region, edge region)) when p lies in one, else region −1
    (and a point of no meaning).

    Inlined, and given no array: as a called function (returning a region or none) capsule-mesh
    contacts ran ~13 % slower, and an inlined copy given the arrays p, a and the vertex counted
    their references (~45 % slower queries)."""
    vertex_region, edge_region = regions
    if own >= 0.0 and across <= own:
        return 0.0, vertex[0], vertex[1], vertex[2], vertex_region
    barycentric = along_edge * across - own * along_other
    if barycentric <= 0.0 and along_edge >= 0.0 and own <= 0.0:
        t = along_edge / (along_edge - own)
        return barycentric, a[0] + t * edge[0], a[1] + t * edge[1], a[2] + t * edge[2], edge_region
    return barycentric, 0.0, 0.0, 0.0, -1


@njit(cache=True)
def closest_point_on_triangle(
    p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray
) -> tuple[float, float, float, int]:
    """Closest point (qx, qy, qz) of triangle (a, b, c) to p, and its region (FACE, EDGE*, VERTEX*).

    Ericson, Real-Time Collision Detection, 5.1.5: the Voronoi regions of the vertices,
    then of the edges, then the face. Edge k joins local vertices k and k + 1.
    """
    abx, aby, abz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    acx, acy, acz = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    ab, ac = (abx, aby, abz), (acx, acy, acz)
    # each vertex region is tested alike, in Ericson's scalar form (no arrays: the innermost query)
    d1, d2 = edge_projections(p, a, ab, ac)
    if d1 <= 0.0 and d2 <= 0.0:
        return a[0], a[1], a[2], VERTEX0
    # vertex b then edge ab, vertex c then edge ac: one test, ab and ac swapped (d6, d5 play d3, d4)
    corner = (a[0], a[1], a[2])
    d3, d4 = edge_projections(p, b, ab, ac)
    vc, qx, qy, qz, region = _vertex_then_edge(d3, d4, d1, d2, (b[0], b[1], b[2]), corner, ab, (VERTEX1, EDGE0))
    if region >= 0:
        return qx, qy, qz, region
    d6, d5 = edge_projections(p, c, ac, ab)
    vb, qx, qy, qz, region = _vertex_then_edge(d6, d5, d2, d1, (c[0], c[1], c[2]), corner, ac, (VERTEX2, EDGE2))
    if region >= 0:
        return qx, qy, qz, region
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return b[0] + w * (c[0] - b[0]), b[1] + w * (c[1] - b[1]), b[2] + w * (c[2] - b[2]), EDGE1
    denominator = 1.0 / (va + vb + vc)
    v = vb * denominator
    w = vc * denominator
    return (a[0] + abx * v + acx * w, a[1] + aby * v + acy * w, a[2] + abz * v + acz * w, FACE)


@njit(cache=True)
def pseudo_normal(mesh: MeshGeometry, triangle: int, region: int) -> np.ndarray:
    """The pseudo-normal (3,) of a triangle's face, edge or vertex (a view of the mesh arrays)."""
    if region == FACE:
        return mesh.triangle_normals[triangle]
    if region <= EDGE2:
        return mesh.edge_normals[mesh.triangle_edges[triangle, region - EDGE0]]
    return mesh.vertex_pseudo_normals[mesh.triangles[triangle, region - VERTEX0]]


@njit(cache=True)
def closest_feature(
    mesh: MeshGeometry, triangle: int, x: np.ndarray, tol: float
) -> tuple[float, float, float, int, float]:
    """Closest point (qx, qy, qz) of a triangle to x, its region and distance [m].

    An edge or vertex point that is x's projection on the triangle's plane (within ``tol``:
    x lies over the triangle's boundary) counts as the FACE, so that a sphere exactly over
    a shared edge of a flat floor gets a face contact with the exact face normal. On the
    face the distance is |(x − q) · n|, exact in the height even where q has round-off.
    """
    tri = mesh.triangles[triangle]
    qx, qy, qz, region = closest_point_on_triangle(
        x, mesh.vertices[tri[0]], mesh.vertices[tri[1]], mesh.vertices[tri[2]]
    )
    dx, dy, dz = x[0] - qx, x[1] - qy, x[2] - qz
    d2 = dx * dx + dy * dy + dz * dz
    nt = mesh.triangle_normals[triangle]
    along = dx * nt[0] + dy * nt[1] + dz * nt[2]
    if region == FACE or d2 - along * along <= tol * tol:
        # on the face, the distance is the height over its plane (free of the round-off of q)
        return qx, qy, qz, FACE, abs(along)
    return qx, qy, qz, region, np.sqrt(d2)


@njit(cache=True)
def signed_normal(
    mesh: MeshGeometry, triangle: int, region: int, x: np.ndarray, qx: float, qy: float, qz: float, distance: float
) -> tuple[float, float, float, float]:
    """Signed distance [m] of x from the mesh feature at q, and the outward normal (nx, ny, nz).

    One-sided: the sign of (x − q) · pseudo-normal; the face normal exactly on a face; the
    direction q → x (reversed inside) on an edge or vertex. Two-sided: never inside; a face
    normal points to x's side.
    """
    nt = mesh.triangle_normals[triangle]
    dx, dy, dz = x[0] - qx, x[1] - qy, x[2] - qz
    tol = mesh.tolerance
    if mesh.two_sided:
        v0 = mesh.vertices[mesh.triangles[triangle, 0]]
        side = 1.0
        if (x[0] - v0[0]) * nt[0] + (x[1] - v0[1]) * nt[1] + (x[2] - v0[2]) * nt[2] < 0.0:
            side = -1.0
        if region == FACE or distance <= tol:
            return distance, side * nt[0], side * nt[1], side * nt[2]
        return distance, dx / distance, dy / distance, dz / distance
    psi = pseudo_normal(mesh, triangle, region)
    s = dx * psi[0] + dy * psi[1] + dz * psi[2]
    if region == FACE:
        return s, nt[0], nt[1], nt[2]
    if distance <= tol:
        return 0.0, psi[0], psi[1], psi[2]
    if s < 0.0:
        return -distance, -dx / distance, -dy / distance, -dz / distance
    return distance, dx / distance, dy / distance, dz / distance


@njit(cache=True)
def nearest_feature(candidates: np.ndarray, distance: np.ndarray, region: np.ndarray) -> int:
    """Position of the nearest candidate (ties: a face first, then the lowest triangle); −1 if none."""
    best = -1
    for i in range(candidates.shape[0]):
        if distance[i] == np.inf:
            continue
        if (
            best < 0
            or distance[i] < distance[best]
            or (
                distance[i] == distance[best]
                and (region[i] < region[best] or (region[i] == region[best] and candidates[i] < candidates[best]))
            )
        ):
            best = i
    return best


@njit(cache=True)
def features_near(
    mesh: MeshGeometry, center: np.ndarray, reach: float, closest: np.ndarray, distance: np.ndarray, region: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Candidate triangles within the box center ± reach, with closest points, distances, regions.

    Fills the given arrays when they are long enough, else new ones; returns
    (candidates, closest, distance, region).
    """
    lower = np.empty(3)
    upper = np.empty(3)
    for i in range(3):
        lower[i] = center[i] - reach
        upper[i] = center[i] + reach
    candidates = mesh_triangles_near(mesh, lower, upper, np.empty(32, dtype=np.int64))
    n = candidates.shape[0]
    if n > distance.shape[0]:
        closest = np.empty((n, 3))
        distance = np.empty(n)
        region = np.empty(n, dtype=np.int64)
    for i in range(n):
        t = candidates[i]
        normal_t = mesh.triangle_normals[t]
        if normal_t[0] == 0.0 and normal_t[1] == 0.0 and normal_t[2] == 0.0:  # degenerate
            distance[i] = np.inf
            region[i] = FACE
            continue
        qx, qy, qz, r, d = closest_feature(mesh, t, center, mesh.tolerance)
        closest[i, 0], closest[i, 1], closest[i, 2] = qx, qy, qz
        region[i] = r
        distance[i] = d
    return candidates, closest[:n], distance[:n], region[:n]


@njit(cache=True)
def distance_to_triangle(mesh: MeshGeometry, triangle: int, x: np.ndarray) -> float:
    """Distance [m] of x (3,) from a triangle (exact closest point; inf for a degenerate one)."""
    nt = mesh.triangle_normals[triangle]
    if nt[0] == 0.0 and nt[1] == 0.0 and nt[2] == 0.0:
        return np.inf
    tri = mesh.triangles[triangle]
    qx, qy, qz, _ = closest_point_on_triangle(x, mesh.vertices[tri[0]], mesh.vertices[tri[1]], mesh.vertices[tri[2]])
    return np.sqrt((x[0] - qx) ** 2 + (x[1] - qy) ** 2 + (x[2] - qz) ** 2)


@njit(cache=True)
def segment_triangle_closest(
    center: np.ndarray, axis: np.ndarray, half_length: float, mesh: MeshGeometry, triangle: int, tol: float
) -> tuple[float, float]:
    """Segment parameter s [m] of the closest pair between the segment center + s·axis (|s| ≤
    half_length, unit axis) and a triangle of the mesh, and that distance [m].

    The minimum of: the two ends against the triangle, the segment against each edge, and the
    segment crossing the triangle (distance 0). Ties (within ``tol``) go to the ends, the −z
    end first, so a segment parallel to a face it lies over answers an end.
    """
    tri = mesh.triangles[triangle]
    x = np.empty(3)
    best_s, best_d = -half_length, np.inf
    for end in range(2):
        s = -half_length if end == 0 else half_length
        for i in range(3):
            x[i] = center[i] + s * axis[i]
        d = distance_to_triangle(mesh, triangle, x)
        if d < best_d - tol:
            best_s, best_d = s, d
    edge_center = np.empty(3)
    edge_axis = np.empty(3)
    for k in range(3):
        a = mesh.vertices[tri[k]]
        b = mesh.vertices[tri[(k + 1) % 3]]
        length = np.sqrt((b[0] - a[0]) ** 2 + (b[1] - a[1]) ** 2 + (b[2] - a[2]) ** 2)
        if length == 0.0:
            continue
        for i in range(3):
            edge_center[i] = 0.5 * (a[i] + b[i])
            edge_axis[i] = (b[i] - a[i]) / length
        s, u = segment_closest_parameters(center, axis, half_length, edge_center, edge_axis, 0.5 * length)
        dx = center[0] + s * axis[0] - edge_center[0] - u * edge_axis[0]
        dy = center[1] + s * axis[1] - edge_center[1] - u * edge_axis[1]
        dz = center[2] + s * axis[2] - edge_center[2] - u * edge_axis[2]
        d = np.sqrt(dx * dx + dy * dy + dz * dz)
        if d < best_d - tol:
            best_s, best_d = s, d
    # the segment crossing the triangle's plane inside it
    nt = mesh.triangle_normals[triangle]
    v0 = mesh.vertices[tri[0]]
    h0 = (
        (center[0] - half_length * axis[0] - v0[0]) * nt[0]
        + (center[1] - half_length * axis[1] - v0[1]) * nt[1]
        + (center[2] - half_length * axis[2] - v0[2]) * nt[2]
    )
    h1 = (
        (center[0] + half_length * axis[0] - v0[0]) * nt[0]
        + (center[1] + half_length * axis[1] - v0[1]) * nt[1]
        + (center[2] + half_length * axis[2] - v0[2]) * nt[2]
    )
    if best_d > tol and h0 * h1 < 0.0:
        s = -half_length + 2.0 * half_length * h0 / (h0 - h1)
        for i in range(3):
            x[i] = center[i] + s * axis[i]
        d = distance_to_triangle(mesh, triangle, x)
        if d < best_d - tol:
            best_s, best_d = s, d
    return best_s, best_d


# ---------------------------------------------------------------------------------------------
# choosing among a shape's candidate contacts against a mesh
# ---------------------------------------------------------------------------------------------


@njit(cache=True)
def keep_deepest(depth: np.ndarray, limit: int) -> np.ndarray:
    """Mask (C,) of the ``limit`` deepest of the contacts with ``depth`` (C,) (ties: the earliest)."""
    count = depth.shape[0]
    taken = np.zeros(count, dtype=np.bool_)
    for _ in range(min(count, limit)):
        best = -1
        for k in range(count):
            if not taken[k] and (best < 0 or depth[k] > depth[best]):
                best = k
        taken[best] = True
    return taken


@njit(cache=True)
def keep_spread(points: np.ndarray, depth: np.ndarray, limit: int, tolerance: float) -> np.ndarray:
    """Mask (C,) of at most ``limit`` of the contacts at ``points`` (C, 3) with ``depth`` (C,): the
    deepest (the first within ``tolerance``), then repeatedly the one farthest from those
    chosen (ties: the earliest)."""
    count = depth.shape[0]
    chosen = np.ones(count, dtype=np.bool_)
    if count <= limit:
        return chosen
    deepest = -np.inf
    for k in range(count):
        chosen[k] = False
        deepest = max(deepest, depth[k])
    last = 0
    while depth[last] < deepest - tolerance:
        last += 1
    chosen[last] = True
    nearest = np.empty(count)
    for k in range(count):
        nearest[k] = np.inf
    for _ in range(limit - 1):
        best, best_k = -1.0, -1
        for k in range(count):
            if chosen[k]:
                continue
            dx = points[k, 0] - points[last, 0]
            dy = points[k, 1] - points[last, 1]
            dz = points[k, 2] - points[last, 2]
            nearest[k] = min(nearest[k], dx * dx + dy * dy + dz * dz)
            if nearest[k] > best * (1.0 + 1e-9) + 1e-300:
                best, best_k = nearest[k], k
        chosen[best_k] = True
        last = best_k
    return chosen


@njit(cache=True)
def write_kept(chosen: np.ndarray, candidates: PairOutput, out: PairOutput, slot: int) -> int:
    """Write the ``candidates`` (rows as :data:`.contact_output.PairOutput`, C of them) marked in
    ``chosen`` (C,) into ``out`` from ``slot`` on, in their order; returns how many."""
    point, normal, depth, feature = candidates
    written = 0
    for i in range(chosen.shape[0]):
        if chosen[i]:
            write_contact(out, slot + written, point[i], normal[i], depth[i], feature[i])
            written += 1
    return written
