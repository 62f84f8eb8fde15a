"""Contacts against static triangle meshes, penalty granularities (P2) and normals (P4, P5).

Conventions as in :mod:`contactlab.collision.narrow_phase`: the mesh is always side B, the
normal points from the mesh INTO the dynamic shape A (the direction that separates A),
``depth`` > 0 when penetrating, contacts with ``depth ≥ −margin`` are kept (speculative), and
each ``point`` lies midway between the two surfaces. Meshes are
:class:`~contactlab.meshes.MeshGeometry` tuples (``TriangleMesh.geometry``), built once.

Inside and outside (see :mod:`contactlab.meshes`): a one-sided mesh (the default) has its
outside in front of its triangles (where the winding normal points); a point behind is
inside, by the sign of the pseudo-normal of the closest feature. Which side a point *came
from* is not known to a static query, so a sphere whose centre has crossed a thin one-sided
sheet from the front is pushed back out to the front, and one approaching from behind is
pushed through it. One-sided is meant for closed meshes (or surfaces whose back is never
reached, such as a terrain); an open sheet that can be approached from both sides should be
``two_sided``: it has no inside, and a shape is pushed back to the side its centre is on.
Crossing a thin sheet within one step is prevented by the swept test
:func:`sweep_sphere_mesh` (or by speculative contacts with a margin ≥ the step's motion).

Sphere (or particle, radius ≥ 0) against a mesh — :func:`sphere_mesh`
    For every triangle near the centre (BVH query, then the exact distance) the closest
    point ``q`` is found with its Voronoi region: the face, one of the 3 edges or one of the
    3 vertices (a point over the boundary of a triangle, within the tolerance, counts as the
    face). The nearest of them decides, by its pseudo-normal, whether the centre is inside a
    one-sided mesh (Bærentzen–Aanæs: exact for a closed mesh).

    * **Inside**: one contact, out through the nearest feature (as ``sphere_box`` does),
      depth = radius + distance. The search reaches ``mesh.max_depth`` below the surface;
      a centre deeper than that is lost.
    * **Outside** (and always for a two-sided mesh): the contacts are the **local minima of
      the distance from the centre over the mesh surface** within ``radius + margin``, each
      reported once. An edge or vertex point ``q`` of triangle t is dropped when another
      triangle that contains ``q`` (within the tolerance) has a closest point nearer the
      centre: ``q`` is then not a local minimum (the "ghost" edge contact of a sphere rolling
      over a floor made of several triangles). Points that coincide are one contact: a face
      point before an edge point before a vertex point, then the lowest triangle index.
      Features the centre is behind (the far side of a thin solid) give none.

    So a sphere resting on the shared diagonal of a flat two-triangle square gets exactly one
    contact (normal +z); a sphere in a concave corner gets one per wall. A face contact's
    normal is the triangle normal exactly; an edge or vertex contact's is the direction from
    ``q`` to the centre (reversed inside). ``feature = 16 · triangle + region`` (region 0: the
    face, 1–3: edges (0,1), (1,2), (2,0), 4–6: vertices 0, 1, 2), stable while the sphere
    stays over the same feature. At most ``max_contacts``, the deepest.

Box against a mesh — :func:`box_mesh`
    Each of the 8 corners is a point (a sphere of radius 0) against the mesh, with the rules
    above: outside, its local minima within the margin (a corner resting on the shared edge
    of a flat floor gives one contact); inside, one contact out through the nearest feature
    (never through the far side of a thin wall). Feature ``16 t + corner`` (corner 0–7
    numbered as in ``box_plane``). Plus the mesh vertices inside the box (grown by the
    margin), pushed out through the box face of least penetration among the faces whose
    contact normal points out of the mesh (positive dot with the vertex pseudo-normal),
    each vertex once, by its owner triangle (feature ``16 t + 8 + k``, k its local index).
    If there are more than ``max_contacts``: the deepest, then one at a time the contact
    farthest from those chosen. A box resting on a flat mesh floor gets its 4 bottom
    corners. Limitation: box edges crossing triangle edges away from any corner or vertex
    (a box lying across a sharp mesh ridge) give no contact.

Deformable / mesh-like objects against a static surface (SPEC P2, P4, P5) — :func:`surface_contacts`
    An object A given as its own triangle mesh (vertices (V, 3) world, triangles (T, 3))
    against a plane, sphere or box obstacle (a signed distance and normal function) or a
    static mesh. Granularity P2a ``"object"``: one contact, at the deepest vertex; P2b
    ``"vertex"``: one per penetrating vertex; P2c ``"sample"``: one per penetrating sample,
    ``k × k`` per triangle (the centroids of the k² sub-triangles of a k-subdivision), each
    carrying the triangle's 3 vertex indices and the 3 barycentric weights (they sum to 1 and
    reproduce the sample point), so a force is distributed ``w_i F`` to vertex i (D1). Normal
    P4 ``"object"``: the obstacle's normal at the closest point (a box's face normal:
    discontinuous across its medial axis); P5 ``"vertex"``: the negated normal of A's own
    surface at the point (area-weighted vertex normals, interpolated for samples):
    continuous, but not guaranteed to point out of the obstacle.

Swept test — :func:`sweep_sphere_mesh`
    The first triangle a sphere (radius ≥ 0) moving on a straight segment touches, by
    intersecting the segment with each nearby triangle inflated by the radius (the
    Minkowski sum: two offset faces, three edge cylinders, three vertex spheres); the time
    of impact in [0, 1] is exact for that shape.

Everything per contact is compiled (``@njit(cache=True)``), float64, no fastmath.
"""

from collections import namedtuple

import numpy as np
from numba import njit

from .. import rotations, shapes
from ..errors import InputError
from ..meshes import TriangleMesh, mesh_triangles_near, vertex_normals
from .contact_output import write_contact

MAX_PER_SHAPE = 8         # the usual cap of contacts per shape against one mesh (as MAX_PER_PAIR)
CORNER_CONTACTS = 4       # box–mesh contacts kept per box corner (the deepest local minima)
FACE, EDGE0, EDGE1, EDGE2, VERTEX0, VERTEX1, VERTEX2 = 0, 1, 2, 3, 4, 5, 6
FEATURES_PER_TRIANGLE = 16

SPHERE, BOX, PLANE, POINT = shapes.SPHERE, shapes.BOX, shapes.PLANE, shapes.POINT


# ---------------------------------------------------------------------------------------------
# small geometry kernels (scalar arithmetic: no allocation in the inner loops)
# ---------------------------------------------------------------------------------------------

@njit(cache=True)
def closest_point_on_triangle(p, a, b, c):
    """Closest point (qx, qy, qz) of triangle (a, b, c) to p, and its region (FACE, EDGE*, VERTEX*).

    Ericson, Real-Time Collision Detection, 5.1.5: the Voronoi regions of the vertices,
    then of the edges, then the face. Edge k joins local vertices k and k + 1.
    """
    abx, aby, abz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    acx, acy, acz = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    apx, apy, apz = p[0] - a[0], p[1] - a[1], p[2] - a[2]
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        return a[0], a[1], a[2], VERTEX0
    bpx, bpy, bpz = p[0] - b[0], p[1] - b[1], p[2] - b[2]
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0.0 and d4 <= d3:
        return b[0], b[1], b[2], VERTEX1
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return a[0] + v * abx, a[1] + v * aby, a[2] + v * abz, EDGE0
    cpx, cpy, cpz = p[0] - c[0], p[1] - c[1], p[2] - c[2]
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
    if d6 >= 0.0 and d5 <= d6:
        return c[0], c[1], c[2], VERTEX2
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return a[0] + w * acx, a[1] + w * acy, a[2] + w * acz, EDGE2
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return b[0] + w * (c[0] - b[0]), b[1] + w * (c[1] - b[1]), b[2] + w * (c[2] - b[2]), EDGE1
    denominator = 1.0 / (va + vb + vc)
    v = vb * denominator
    w = vc * denominator
    return (a[0] + abx * v + acx * w, a[1] + aby * v + acy * w, a[2] + abz * v + acz * w, FACE)


@njit(cache=True)
def _pseudo_normal(mesh, triangle, region):
    """The pseudo-normal (3,) of a triangle's face, edge or vertex (a view of the mesh arrays)."""
    if region == FACE:
        return mesh.triangle_normals[triangle]
    if region <= EDGE2:
        return mesh.edge_normals[mesh.triangle_edges[triangle, region - EDGE0]]
    return mesh.vertex_pseudo_normals[mesh.triangles[triangle, region - VERTEX0]]


@njit(cache=True)
def _deepest(depth, limit):
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
def _spread(points, depth, limit, tolerance):
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


# ---------------------------------------------------------------------------------------------
# sphere / particle against a mesh
# ---------------------------------------------------------------------------------------------

@njit(cache=True)
def _closest_feature(mesh, triangle, x, tol):
    """Closest point (qx, qy, qz) of a triangle to x, its region and distance [m].

    An edge or vertex point that is x's projection on the triangle's plane (within ``tol``:
    x lies over the triangle's boundary) counts as the FACE, so that a sphere exactly over
    a shared edge of a flat floor gets a face contact with the exact face normal. On the
    face the distance is |(x − q) · n|, exact in the height even where q has round-off.
    """
    tri = mesh.triangles[triangle]
    qx, qy, qz, region = closest_point_on_triangle(x, mesh.vertices[tri[0]], mesh.vertices[tri[1]],
                                                   mesh.vertices[tri[2]])
    dx, dy, dz = x[0] - qx, x[1] - qy, x[2] - qz
    d2 = dx * dx + dy * dy + dz * dz
    nt = mesh.triangle_normals[triangle]
    along = dx * nt[0] + dy * nt[1] + dz * nt[2]
    if region == FACE or d2 - along * along <= tol * tol:
        # on the face, the distance is the height over its plane (free of the round-off of q)
        return qx, qy, qz, FACE, abs(along)
    return qx, qy, qz, region, np.sqrt(d2)


@njit(cache=True)
def _signed_normal(mesh, triangle, region, x, qx, qy, qz, distance):
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
    psi = _pseudo_normal(mesh, triangle, region)
    s = dx * psi[0] + dy * psi[1] + dz * psi[2]
    if region == FACE:
        return s, nt[0], nt[1], nt[2]
    if distance <= tol:
        return 0.0, psi[0], psi[1], psi[2]
    if s < 0.0:
        return -distance, -dx / distance, -dy / distance, -dz / distance
    return distance, dx / distance, dy / distance, dz / distance


@njit(cache=True)
def _nearest(candidates, distance, region):
    """Position of the nearest candidate (ties: a face first, then the lowest triangle); −1 if none."""
    best = -1
    for i in range(candidates.shape[0]):
        if distance[i] == np.inf:
            continue
        if (best < 0 or distance[i] < distance[best]
                or (distance[i] == distance[best]
                    and (region[i] < region[best]
                         or (region[i] == region[best] and candidates[i] < candidates[best])))):
            best = i
    return best


@njit(cache=True)
def _features_near(mesh, center, reach, closest, distance, region):
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
        if normal_t[0] == 0.0 and normal_t[1] == 0.0 and normal_t[2] == 0.0:   # degenerate
            distance[i] = np.inf
            region[i] = FACE
            continue
        qx, qy, qz, r, d = _closest_feature(mesh, t, center, mesh.tolerance)
        closest[i, 0], closest[i, 1], closest[i, 2] = qx, qy, qz
        region[i] = r
        distance[i] = d
    return candidates, closest[:n], distance[:n], region[:n]


@njit(cache=True)
def sphere_mesh(center, radius, mesh, margin, out_point, out_normal, out_depth, out_feature, slot, max_contacts):
    """Sphere (or particle) A of ``radius`` [m] at ``center`` (3,) against the static mesh B.

    Writes at most ``max_contacts`` contacts (the deepest) from ``slot`` on and returns how
    many; ``feature = 16 · triangle + region``. Rules (module docstring): a centre inside a
    one-sided mesh gets one contact, through the nearest feature; a centre outside gets one
    per local minimum of the distance within ``radius + margin``.
    """
    reach = radius + margin
    tol = mesh.tolerance
    candidates, closest, distance, region = _features_near(
        mesh, center, reach, np.empty((32, 3)), np.empty(32), np.empty(32, dtype=np.int64))
    nearest = _nearest(candidates, distance, region)
    if nearest < 0 or distance[nearest] > reach:
        # nothing within reach: a centre deeper than that inside a one-sided mesh?
        if mesh.two_sided or mesh.max_depth <= 0.0:
            return 0
        candidates, closest, distance, region = _features_near(mesh, center, reach + mesh.max_depth,
                                                               closest, distance, region)
        nearest = _nearest(candidates, distance, region)
        if nearest < 0 or distance[nearest] > reach + mesh.max_depth:
            return 0
    q = closest[nearest]
    signed, nx, ny, nz = _signed_normal(mesh, candidates[nearest], region[nearest], center,
                                        q[0], q[1], q[2], distance[nearest])
    if signed < 0.0:
        if max_contacts < 1:
            return 0
        # inside: one contact, out through the nearest feature (as sphere_box does)
        out_normal[slot, 0], out_normal[slot, 1], out_normal[slot, 2] = nx, ny, nz
        for i in range(3):
            out_point[slot, i] = 0.5 * (center[i] - radius * out_normal[slot, i] + q[i])
        out_depth[slot] = radius - signed
        out_feature[slot] = FEATURES_PER_TRIANGLE * candidates[nearest] + region[nearest]
        return 1
    n = candidates.shape[0]
    keep = np.zeros(n, dtype=np.bool_)
    for i in range(n):
        keep[i] = distance[i] <= reach
    # 1. not a local minimum: another triangle containing q_i is nearer the centre
    for i in range(n):
        if not keep[i] or region[i] == FACE:
            continue
        for j in range(n):
            if j == i or not distance[j] < distance[i] - tol:
                continue
            other = mesh.triangles[candidates[j]]
            px, py, pz, _ = closest_point_on_triangle(closest[i], mesh.vertices[other[0]], mesh.vertices[other[1]],
                                                      mesh.vertices[other[2]])
            ex, ey, ez = px - closest[i, 0], py - closest[i, 1], pz - closest[i, 2]
            if ex * ex + ey * ey + ez * ez <= tol * tol:
                keep[i] = False
                break
    # 2. one contact per point: face before edge before vertex, then the lowest triangle
    for i in range(n):
        if not keep[i]:
            continue
        rank_i = 0 if region[i] == FACE else (1 if region[i] <= EDGE2 else 2)
        for j in range(n):
            if j == i or not keep[j]:
                continue
            rank_j = 0 if region[j] == FACE else (1 if region[j] <= EDGE2 else 2)
            if rank_j > rank_i or (rank_j == rank_i and candidates[j] > candidates[i]):
                continue
            ex = closest[j, 0] - closest[i, 0]
            ey = closest[j, 1] - closest[i, 1]
            ez = closest[j, 2] - closest[i, 2]
            if ex * ex + ey * ey + ez * ez <= tol * tol:
                keep[i] = False
                break
    # 3. normal, signed distance, depth; features the centre is behind (the far side of a
    #    thin solid) are dropped: the centre is outside
    point = np.empty((n, 3))
    normal = np.empty((n, 3))
    depth = np.empty(n)
    feature = np.empty(n, dtype=np.int64)
    count = 0
    for i in range(n):
        if not keep[i]:
            continue
        t = candidates[i]
        signed, nx, ny, nz = _signed_normal(mesh, t, region[i], center, closest[i, 0], closest[i, 1],
                                            closest[i, 2], distance[i])
        this_depth = radius - signed
        if signed < 0.0 or this_depth < -margin:
            continue
        normal[count, 0], normal[count, 1], normal[count, 2] = nx, ny, nz
        depth[count] = this_depth
        # midway between the sphere's surface (centre − r n) and the mesh point q
        point[count, 0] = 0.5 * (center[0] - radius * nx + closest[i, 0])
        point[count, 1] = 0.5 * (center[1] - radius * ny + closest[i, 1])
        point[count, 2] = 0.5 * (center[2] - radius * nz + closest[i, 2])
        feature[count] = FEATURES_PER_TRIANGLE * t + region[i]
        count += 1
    # 4. the deepest max_contacts
    taken = _deepest(depth[:count], max_contacts)
    written = 0
    for i in range(count):
        if taken[i]:
            write_contact(out_point, out_normal, out_depth, out_feature, slot + written, point[i], normal[i], depth[i],
                   feature[i])
            written += 1
    return written


# ---------------------------------------------------------------------------------------------
# box against a mesh
# ---------------------------------------------------------------------------------------------

@njit(cache=True)
def box_mesh(center, rotation, half_extents, mesh, margin, out_point, out_normal, out_depth, out_feature,
             slot, max_contacts):
    """Box A (centre (3,), rotation (3,3) body → world, half extents (3,)) against the static mesh B.

    Each corner as a point (a sphere of radius 0: inside/outside and local minima as for
    spheres; at most ``CORNER_CONTACTS`` per corner, the deepest), plus mesh vertices inside
    the box (module docstring). Writes at most ``max_contacts`` contacts from ``slot`` on and
    returns how many.
    """
    corner_limit = max_contacts * 0 + CORNER_CONTACTS       # (an int64 variable, not a literal)
    # mesh triangles near the box (grown by the margin): their vertices may lie inside it
    lower = np.empty(3)
    upper = np.empty(3)
    for i in range(3):
        reach = (abs(rotation[i, 0]) * half_extents[0] + abs(rotation[i, 1]) * half_extents[1]
                 + abs(rotation[i, 2]) * half_extents[2]) + margin
        lower[i] = center[i] - reach
        upper[i] = center[i] + reach
    candidates = mesh_triangles_near(mesh, lower, upper, np.empty(32, dtype=np.int64))
    # all candidate contacts: corners (at most CORNER_CONTACTS each), then mesh vertices
    capacity = 8 * CORNER_CONTACTS + 3 * candidates.shape[0]
    point = np.empty((capacity, 3))
    normal = np.empty((capacity, 3))
    depth = np.empty(capacity)
    feature = np.empty(capacity, dtype=np.int64)
    corner_point = np.empty((CORNER_CONTACTS, 3))
    corner_normal = np.empty((CORNER_CONTACTS, 3))
    corner_depth = np.empty(CORNER_CONTACTS)
    corner_feature = np.empty(CORNER_CONTACTS, dtype=np.int64)
    x = np.empty(3)
    count = 0
    for corner in range(8):
        sx = half_extents[0] if corner & 1 else -half_extents[0]
        sy = half_extents[1] if corner & 2 else -half_extents[1]
        sz = half_extents[2] if corner & 4 else -half_extents[2]
        for i in range(3):
            x[i] = center[i] + rotation[i, 0] * sx + rotation[i, 1] * sy + rotation[i, 2] * sz
        found = sphere_mesh(x, 0.0, mesh, margin, corner_point, corner_normal, corner_depth, corner_feature,
                            slot * 0, corner_limit)
        for k in range(found):
            for i in range(3):
                point[count, i] = corner_point[k, i]
                normal[count, i] = corner_normal[k, i]
            depth[count] = corner_depth[k]
            # the corner replaces the region: 16 · triangle + corner
            feature[count] = FEATURES_PER_TRIANGLE * (corner_feature[k] // FEATURES_PER_TRIANGLE) + corner
            count += 1
    # mesh vertices inside the box (grown by the margin), each once: by its owner triangle
    local = np.empty(3)
    for c in range(candidates.shape[0]):
        t = candidates[c]
        tri = mesh.triangles[t]
        for k in range(3):
            vertex = tri[k]
            if mesh.vertex_owner[vertex] != t:
                continue
            v = mesh.vertices[vertex]
            inside = True
            for a in range(3):
                local[a] = (rotation[0, a] * (v[0] - center[0]) + rotation[1, a] * (v[1] - center[1])
                            + rotation[2, a] * (v[2] - center[2]))
                if abs(local[a]) > half_extents[a] + margin:
                    inside = False
            if not inside:
                continue
            psi = mesh.vertex_pseudo_normals[vertex]
            psi_sign = 1.0
            if mesh.two_sided and ((center[0] - v[0]) * psi[0] + (center[1] - v[1]) * psi[1]
                                   + (center[2] - v[2]) * psi[2]) < 0.0:
                psi_sign = -1.0
            best_gap, best_axis, best_sign = np.inf, -1, 1.0
            for a in range(3):
                sign = 1.0 if local[a] >= 0.0 else -1.0
                # contact normal = −(outward face normal) = −sign · R[:, a]; must leave the mesh
                along = -sign * (rotation[0, a] * psi[0] + rotation[1, a] * psi[1] + rotation[2, a] * psi[2])
                gap = half_extents[a] - abs(local[a])
                if psi_sign * along > 0.0 and gap < best_gap:
                    best_gap, best_axis, best_sign = gap, a, sign
            if best_axis < 0 or best_gap < -margin:
                continue
            for i in range(3):
                face = best_sign * rotation[i, best_axis]
                normal[count, i] = -face
                point[count, i] = v[i] + 0.5 * best_gap * face
            depth[count] = best_gap
            feature[count] = FEATURES_PER_TRIANGLE * t + 8 + k
            count += 1
    chosen = _spread(point[:count], depth[:count], max_contacts, mesh.tolerance)
    written = 0
    for i in range(count):
        if chosen[i]:
            write_contact(out_point, out_normal, out_depth, out_feature, slot + written, point[i], normal[i], depth[i],
                   feature[i])
            written += 1
    return written


@njit(cache=True)
def mesh_supported(kind):
    """Whether a dynamic shape of this kind has a contact routine against a mesh."""
    return kind == SPHERE or kind == POINT or kind == BOX


@njit(cache=True)
def shapes_against_mesh(kinds, params, centers, rotations_, margins, mesh, max_per_shape):
    """Contacts of many dynamic shapes against one static mesh.

    kinds (N,), params (N, 4), centers (N, 3), rotations_ (N, 3, 3), margins (N,) [m] per shape;
    max_per_shape: the cap of contacts per shape (``MAX_PER_SHAPE`` is the usual one).
    Returns point (C, 3), normal (C, 3), depth (C,), feature (C,) and owner (C,): the index
    of the shape each contact belongs to. Shapes with no routine (planes) give none.
    """
    count_shapes = kinds.shape[0]
    capacity = max(1, count_shapes * max_per_shape)
    point = np.empty((capacity, 3))
    normal = np.empty((capacity, 3))
    depth = np.empty(capacity)
    feature = np.empty(capacity, dtype=np.int64)
    owner = np.empty(capacity, dtype=np.int64)
    count = np.int64(capacity) * 0          # (not the literal 0: that would compile the callees twice)
    for s in range(count_shapes):
        kind = kinds[s]
        written = 0
        if kind == SPHERE or kind == POINT:
            written = sphere_mesh(centers[s], params[s, 0], mesh, margins[s], point, normal, depth, feature,
                                  count, max_per_shape)
        elif kind == BOX:
            written = box_mesh(centers[s], rotations_[s], params[s, :3], mesh, margins[s], point, normal, depth,
                               feature, count, max_per_shape)
        for k in range(count, count + written):
            owner[k] = s
        count += written
    return point[:count], normal[:count], depth[:count], feature[:count], owner[:count]


# ---------------------------------------------------------------------------------------------
# signed distance and normal of static surfaces (for P2, P4, P5)
# ---------------------------------------------------------------------------------------------

ShapeObstacle = namedtuple("ShapeObstacle", ["kind", "params", "position", "rotation"])
ShapeObstacle.__doc__ = """A convex static surface: a kind of :mod:`contactlab.shapes` (PLANE, SPHERE, BOX),
its parameter row (4,), its centre (3,) [m] and rotation matrix (3, 3) (body → world)."""


def plane_obstacle(normal, offset=0.0):
    """The plane {x : n · x = offset} (solid side n · x < offset); n and offset are divided by |n|."""
    n = np.asarray(normal, dtype=float).reshape(3)
    length = np.linalg.norm(n)
    if not np.isfinite(length) or length == 0.0:
        raise InputError("normal", f"the plane normal must be non-zero and finite, found {n.tolist()}")
    return ShapeObstacle(PLANE, np.array([*(n / length), float(offset) / length]), np.zeros(3), np.eye(3))


def sphere_obstacle(center, radius):
    """A solid sphere of ``radius`` [m] at ``center`` (3,)."""
    if not radius > 0.0:
        raise InputError("radius", f"the sphere radius must be positive, found {radius}")
    return ShapeObstacle(SPHERE, np.array([float(radius), 0.0, 0.0, 0.0]),
                         np.asarray(center, dtype=float).reshape(3), np.eye(3))


def box_obstacle(center, half_extents, quaternion=(1.0, 0.0, 0.0, 0.0)):
    """A solid box of ``half_extents`` (3,) [m] at ``center`` (3,), orientation (w, x, y, z)."""
    h = np.asarray(half_extents, dtype=float).reshape(3)
    if not np.all(h > 0.0):
        raise InputError("half_extents", f"the box half extents must be positive, found {h.tolist()}")
    q = np.asarray(quaternion, dtype=float).reshape(4)
    R = rotations.to_matrix((q / np.linalg.norm(q))[None])[0]
    return ShapeObstacle(BOX, np.array([h[0], h[1], h[2], 0.0]), np.asarray(center, dtype=float).reshape(3), R)


def model_obstacle(model, index):
    """The :class:`ShapeObstacle` of obstacle ``index`` of a :class:`~contactlab.model.Model`."""
    R = rotations.to_matrix(np.asarray(model.obstacle_orientation[index], dtype=float)[None])[0]
    return ShapeObstacle(int(model.obstacle_shape[index]), np.asarray(model.obstacle_params[index], dtype=float),
                         np.asarray(model.obstacle_position[index], dtype=float), R)


@njit(cache=True)
def shape_signed_distance(kind, params, position, rotation, x):
    """Signed distance [m] (< 0 inside), outward unit normal (3,) and closest surface point (3,)
    of a plane, sphere or box obstacle at the point x (3,).

    Box: outside, the normal points from the closest point to x; inside, it is the normal of
    the face of least penetration (the first in x, y, z order on a tie) — so it jumps across
    the box's medial axis (P4).
    """
    normal = np.zeros(3)
    closest = np.empty(3)
    if kind == PLANE:
        d = x[0] * params[0] + x[1] * params[1] + x[2] * params[2] - params[3]
        for i in range(3):
            normal[i] = params[i]
            closest[i] = x[i] - d * params[i]
        return d, normal, closest
    if kind == SPHERE:
        dx, dy, dz = x[0] - position[0], x[1] - position[1], x[2] - position[2]
        length = np.sqrt(dx * dx + dy * dy + dz * dz)
        if length > 0.0:
            normal[0], normal[1], normal[2] = dx / length, dy / length, dz / length
        else:
            normal[2] = 1.0
        for i in range(3):
            closest[i] = position[i] + params[0] * normal[i]
        return length - params[0], normal, closest
    # box
    local = np.empty(3)
    for a in range(3):
        local[a] = (rotation[0, a] * (x[0] - position[0]) + rotation[1, a] * (x[1] - position[1])
                    + rotation[2, a] * (x[2] - position[2]))
    clamped = np.empty(3)
    outside = 0.0
    for a in range(3):
        clamped[a] = min(max(local[a], -params[a]), params[a])
        outside += (local[a] - clamped[a]) ** 2
    normal_local = np.zeros(3)
    if outside > 0.0:
        distance = np.sqrt(outside)
        for a in range(3):
            normal_local[a] = (local[a] - clamped[a]) / distance
        signed = distance
    else:
        axis = 0
        gap = params[0] - abs(local[0])
        for a in range(1, 3):
            if params[a] - abs(local[a]) < gap:
                gap = params[a] - abs(local[a])
                axis = a
        sign = 1.0 if local[axis] >= 0.0 else -1.0
        normal_local[axis] = sign
        clamped[axis] = sign * params[axis]
        signed = -gap
    for i in range(3):
        normal[i] = (rotation[i, 0] * normal_local[0] + rotation[i, 1] * normal_local[1]
                     + rotation[i, 2] * normal_local[2])
        closest[i] = position[i] + (rotation[i, 0] * clamped[0] + rotation[i, 1] * clamped[1]
                                    + rotation[i, 2] * clamped[2])
    return signed, normal, closest


@njit(cache=True)
def mesh_signed_distance(mesh, x, reach):
    """Signed distance [m], outward normal (3,), closest point (3,) and triangle of the point of
    the mesh closest to x (3,), searched within ``reach`` [m]; triangle −1 (distance +inf)
    when nothing is that near. The sign is that of the closest feature's pseudo-normal
    (a two-sided mesh: always ≥ 0); the normal as in :func:`sphere_mesh`.
    """
    candidates, closest, distance, region = _features_near(
        mesh, x, reach, np.empty((32, 3)), np.empty(32), np.empty(32, dtype=np.int64))
    nearest = _nearest(candidates, distance, region)
    normal = np.zeros(3)
    q = np.zeros(3)
    if nearest < 0 or distance[nearest] > reach:
        return np.inf, normal, q, -1
    for i in range(3):
        q[i] = closest[nearest, i]
    signed, normal[0], normal[1], normal[2] = _signed_normal(mesh, candidates[nearest], region[nearest], x,
                                                             q[0], q[1], q[2], distance[nearest])
    return signed, normal, q, candidates[nearest]


@njit(cache=True)
def points_against_shape(points, kind, params, position, rotation):
    """:func:`shape_signed_distance` for points (N, 3): signed distance (N,), normal (N, 3), closest (N, 3)."""
    count = points.shape[0]
    signed = np.empty(count)
    normal = np.empty((count, 3))
    closest = np.empty((count, 3))
    for k in range(count):
        d, n, q = shape_signed_distance(kind, params, position, rotation, points[k])
        signed[k] = d
        for i in range(3):
            normal[k, i] = n[i]
            closest[k, i] = q[i]
    return signed, normal, closest


@njit(cache=True)
def points_against_mesh(points, mesh, reach):
    """:func:`mesh_signed_distance` for points (N, 3): signed distance (N,) (+inf beyond
    ``reach``), normal (N, 3), closest (N, 3), triangle (N,)."""
    count = points.shape[0]
    signed = np.empty(count)
    normal = np.empty((count, 3))
    closest = np.empty((count, 3))
    triangle = np.empty(count, dtype=np.int64)
    for k in range(count):
        d, n, q, t = mesh_signed_distance(mesh, points[k], reach)
        signed[k] = d
        triangle[k] = t
        for i in range(3):
            normal[k, i] = n[i]
            closest[k, i] = q[i]
    return signed, normal, closest, triangle


# ---------------------------------------------------------------------------------------------
# P2 granularities with the P4 / P5 normals
# ---------------------------------------------------------------------------------------------

SurfaceContacts = namedtuple("SurfaceContacts", ["point", "normal", "depth", "vertices", "weights", "feature"])
SurfaceContacts.__doc__ = """Contacts of a mesh-like object A against a static surface B (C contacts).

point (C, 3) [m] midway between A's point and B's surface; normal (C, 3) unit, from B into A;
depth (C,) [m], > 0 penetrating; vertices (C, 3) int64 indices of A's vertices carrying the
contact (−1 unused); weights (C, 3) their barycentric weights (sum 1; 0 where unused), so the
contact point of A is Σ w_i x_i and a force F is distributed as w_i F to vertex i (D1);
feature (C,) int64: 0 (P2a), the vertex (P2b), or triangle · k² + sample (P2c)."""

GRANULARITIES = ("object", "vertex", "sample")     # P2a, P2b, P2c
NORMALS = ("object", "vertex")                     # P4, P5


def triangle_samples(samples_per_edge):
    """Barycentric weights (k², 3) of k × k samples on a triangle: the centroids of the k²
    congruent sub-triangles of its k-subdivision (every weight > 0, the samples even)."""
    k = int(samples_per_edge)
    rows = []
    for a in range(k):
        for b in range(k - a):
            rows.append((a + 1.0 / 3.0, b + 1.0 / 3.0))          # upward sub-triangle
            if a + b <= k - 2:
                rows.append((a + 2.0 / 3.0, b + 2.0 / 3.0))      # downward sub-triangle
    ab = np.array(rows) / k
    return np.column_stack([1.0 - ab[:, 0] - ab[:, 1], ab[:, 0], ab[:, 1]])


def surface_contacts(vertices, triangles, obstacle, granularity="vertex", normal="object", margin=0.0,
                     samples=2, max_depth=None, object_vertex_normals=None) -> SurfaceContacts:
    """Contacts of object A (its triangle mesh) against a static surface B, at a SPEC P2 granularity.

    vertices: (V, 3) world positions of A [m]; triangles: (T, 3) int, wound outward.
    obstacle: a :class:`ShapeObstacle` (:func:`plane_obstacle`, :func:`sphere_obstacle`,
    :func:`box_obstacle`) or a static :class:`~contactlab.meshes.TriangleMesh`.
    granularity: ``"object"`` (P2a: one contact, at the deepest vertex), ``"vertex"`` (P2b: one
    per vertex with depth ≥ −margin) or ``"sample"`` (P2c: one per sample with depth ≥ −margin,
    ``samples × samples`` per triangle). normal: ``"object"`` (P4: B's normal at its closest
    point) or ``"vertex"`` (P5: −(A's own area-weighted normal at the point), interpolated
    with the weights for samples). margin [m]: gaps down to this are kept. max_depth [m]:
    against a mesh, how deep a penetration is looked for (default: the mesh's ``max_depth``).
    object_vertex_normals: (V, 3) to reuse, else computed from A.
    """
    if granularity not in GRANULARITIES:
        raise InputError("granularity", f"expected one of {', '.join(GRANULARITIES)}, found {granularity!r}")
    if normal not in NORMALS:
        raise InputError("normal", f"expected one of {', '.join(NORMALS)}, found {normal!r}")
    if not (np.isfinite(margin) and margin >= 0.0):
        raise InputError("margin", f"the margin must be a finite number ≥ 0, found {margin}")
    vertices = np.ascontiguousarray(vertices, dtype=float)
    triangles = np.ascontiguousarray(triangles, dtype=np.int64)
    k = int(samples)
    if granularity == "sample" and k < 1:
        raise InputError("samples", f"the samples per triangle edge must be ≥ 1, found {samples}")
    if granularity == "sample":
        weights_pattern = triangle_samples(k)                                   # (S, 3)
        S = len(weights_pattern)
        corner_positions = vertices[triangles]                                  # (T, 3, 3)
        points = np.einsum("sk,tkd->tsd", weights_pattern, corner_positions).reshape(-1, 3)
        carriers = np.repeat(triangles, S, axis=0)                              # (T·S, 3)
        weights = np.tile(weights_pattern, (len(triangles), 1))
        features = np.arange(len(points), dtype=np.int64)                       # t · k² + s
    else:
        points = vertices
        carriers = np.full((len(vertices), 3), -1, dtype=np.int64)
        carriers[:, 0] = np.arange(len(vertices))
        weights = np.zeros((len(vertices), 3))
        weights[:, 0] = 1.0
        features = np.arange(len(vertices), dtype=np.int64)
    if isinstance(obstacle, TriangleMesh):
        if max_depth is None:
            max_depth = obstacle.max_depth
        signed, obstacle_normal, closest, _ = points_against_mesh(points, obstacle.geometry,
                                                                  float(margin + max_depth))
    elif isinstance(obstacle, ShapeObstacle):
        signed, obstacle_normal, closest = points_against_shape(
            points, int(obstacle.kind), np.asarray(obstacle.params, dtype=float),
            np.asarray(obstacle.position, dtype=float), np.ascontiguousarray(obstacle.rotation, dtype=float))
    else:
        raise InputError("obstacle", f"expected a ShapeObstacle or a TriangleMesh, found {type(obstacle).__name__}")
    depth = -signed
    if granularity == "object":
        chosen = np.array([int(np.argmax(depth))]) if len(depth) and depth.max() >= -margin else np.zeros(0, int)
    else:
        chosen = np.nonzero(depth >= -margin)[0]
    if normal == "object":
        normals = obstacle_normal[chosen]
    else:
        own = vertex_normals(vertices, triangles) if object_vertex_normals is None else np.asarray(
            object_vertex_normals, dtype=float)
        blended = np.einsum("ck,ckd->cd", weights[chosen], own[np.maximum(carriers[chosen], 0)])
        length = np.linalg.norm(blended, axis=1, keepdims=True)
        normals = -blended / np.where(length > 0.0, length, 1.0)
    return SurfaceContacts(
        point=0.5 * (points[chosen] + closest[chosen]),
        normal=normals,
        depth=depth[chosen],
        vertices=carriers[chosen],
        weights=weights[chosen],
        feature=np.zeros(len(chosen), dtype=np.int64) if granularity == "object" else features[chosen],
    )


# ---------------------------------------------------------------------------------------------
# swept sphere (no tunnelling through thin meshes)
# ---------------------------------------------------------------------------------------------

@njit(cache=True)
def _segment_crosses_triangle(start, motion, a, b, c, nt, tol):
    """Time t in [0, 1] at which start + t motion crosses the triangle's plane inside it (inf: never)."""
    s0 = (start[0] - a[0]) * nt[0] + (start[1] - a[1]) * nt[1] + (start[2] - a[2]) * nt[2]
    rate = motion[0] * nt[0] + motion[1] * nt[1] + motion[2] * nt[2]
    if rate == 0.0 or s0 * rate > 0.0 or (s0 == 0.0 and rate > 0.0):
        return np.inf          # parallel, moving away, or leaving the plane towards the front
    t = -s0 / rate
    if t < 0.0 or t > 1.0:
        return np.inf
    p = np.empty(3)
    for i in range(3):
        p[i] = start[i] + t * motion[i]
    qx, qy, qz, _ = closest_point_on_triangle(p, a, b, c)
    if (qx - p[0]) ** 2 + (qy - p[1]) ** 2 + (qz - p[2]) ** 2 > tol * tol:
        return np.inf
    return t


@njit(cache=True)
def _segment_enters_sphere(start, motion, center, radius):
    """First t in [0, 1] with |start + t motion − center| = radius, start outside (inf: never)."""
    wx, wy, wz = start[0] - center[0], start[1] - center[1], start[2] - center[2]
    a = motion[0] * motion[0] + motion[1] * motion[1] + motion[2] * motion[2]
    b = wx * motion[0] + wy * motion[1] + wz * motion[2]
    c = wx * wx + wy * wy + wz * wz - radius * radius
    if a == 0.0 or b >= 0.0:
        return np.inf
    if c <= 0.0:
        return 0.0                 # touching already (within rounding) and moving in
    disc = b * b - a * c
    if disc < 0.0:
        return np.inf
    t = (-b - np.sqrt(disc)) / a
    if t < 0.0:
        t = 0.0
    return t if t <= 1.0 else np.inf


@njit(cache=True)
def _segment_enters_cylinder(start, motion, a, b, radius):
    """First t in [0, 1] at which the segment enters the finite cylinder of ``radius`` about edge ab."""
    ex, ey, ez = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    ee = ex * ex + ey * ey + ez * ez
    if ee == 0.0:
        return np.inf
    wx, wy, wz = start[0] - a[0], start[1] - a[1], start[2] - a[2]
    we = (wx * ex + wy * ey + wz * ez) / ee
    me = (motion[0] * ex + motion[1] * ey + motion[2] * ez) / ee
    # components perpendicular to the edge
    px, py, pz = wx - we * ex, wy - we * ey, wz - we * ez
    mx, my, mz = motion[0] - me * ex, motion[1] - me * ey, motion[2] - me * ez
    A = mx * mx + my * my + mz * mz
    B = px * mx + py * my + pz * mz
    C = px * px + py * py + pz * pz - radius * radius
    if A == 0.0 or B >= 0.0:
        return np.inf
    if C <= 0.0:
        t = 0.0                    # touching already (within rounding) and moving in
    else:
        disc = B * B - A * C
        if disc < 0.0:
            return np.inf
        t = (-B - np.sqrt(disc)) / A
    if t > 1.0:
        return np.inf
    u = we + t * me
    if u < 0.0 or u > 1.0:
        return np.inf
    return t


@njit(cache=True)
def sweep_sphere_mesh(start, end, radius, mesh):
    """First contact of a sphere (radius ≥ 0 [m]) moving from ``start`` to ``end`` (3,) with the mesh.

    Returns (hit, time_of_impact in [0, 1], triangle, normal (3,)). The normal points from
    the triangle towards the sphere's centre at impact (the triangle's normal, oriented
    towards the side the sphere came from, for a face hit). No hit: (False, 1.0, −1, 0).

    Each nearby triangle is inflated by the radius (its Minkowski sum with the sphere) and
    the segment of the centre is intersected with it. A triangle the sphere already overlaps
    at the start is handled by the static contact; for it only the centre's own crossing of
    the triangle counts, so a sphere that starts in contact still cannot pass through.
    Conservative (never misses a crossing) and exact in the time of impact.
    """
    motion = np.empty(3)
    lower = np.empty(3)
    upper = np.empty(3)
    for i in range(3):
        motion[i] = end[i] - start[i]
        lower[i] = min(start[i], end[i]) - radius
        upper[i] = max(start[i], end[i]) + radius
    candidates = mesh_triangles_near(mesh, lower, upper, np.empty(64, dtype=np.int64))
    tol = mesh.tolerance
    best_t, best_triangle = np.inf, -1
    for c in range(candidates.shape[0]):
        t_index = candidates[c]
        if (mesh.triangle_normals[t_index, 2] == 0.0 and mesh.triangle_normals[t_index, 0] == 0.0
                and mesh.triangle_normals[t_index, 1] == 0.0):
            continue
        tri = mesh.triangles[t_index]
        a, b, cc = mesh.vertices[tri[0]], mesh.vertices[tri[1]], mesh.vertices[tri[2]]
        nt = mesh.triangle_normals[t_index]
        qx, qy, qz, _ = closest_point_on_triangle(start, a, b, cc)
        start_distance = np.sqrt((start[0] - qx) ** 2 + (start[1] - qy) ** 2 + (start[2] - qz) ** 2)
        if radius <= 0.0 or start_distance < radius - tol:
            t = _segment_crosses_triangle(start, motion, a, b, cc, nt, tol)
        else:
            t = np.inf
            # the two faces offset by the radius, on the start's side
            s0 = (start[0] - a[0]) * nt[0] + (start[1] - a[1]) * nt[1] + (start[2] - a[2]) * nt[2]
            side = 1.0 if s0 >= 0.0 else -1.0
            rate = side * (motion[0] * nt[0] + motion[1] * nt[1] + motion[2] * nt[2])
            if rate < 0.0:
                # (start within rounding of the offset face, t_face < 0 by a hair: it touches now)
                t_face = max(0.0, (radius - side * s0) / rate)
                if t_face <= 1.0:
                    p = np.empty(3)
                    height = s0 + side * rate * t_face          # the centre's height at t_face
                    for i in range(3):
                        p[i] = start[i] + t_face * motion[i] - height * nt[i]
                    px, py, pz, _ = closest_point_on_triangle(p, a, b, cc)
                    if (px - p[0]) ** 2 + (py - p[1]) ** 2 + (pz - p[2]) ** 2 <= tol * tol:
                        t = t_face
            t = min(t, _segment_enters_cylinder(start, motion, a, b, radius))
            t = min(t, _segment_enters_cylinder(start, motion, b, cc, radius))
            t = min(t, _segment_enters_cylinder(start, motion, cc, a, radius))
            t = min(t, _segment_enters_sphere(start, motion, a, radius))
            t = min(t, _segment_enters_sphere(start, motion, b, radius))
            t = min(t, _segment_enters_sphere(start, motion, cc, radius))
        if t < best_t or (t == best_t and t_index < best_triangle):
            best_t, best_triangle = t, t_index
    normal = np.zeros(3)
    if best_triangle < 0:
        return False, 1.0, -1, normal
    tri = mesh.triangles[best_triangle]
    nt = mesh.triangle_normals[best_triangle]
    at = np.empty(3)
    for i in range(3):
        at[i] = start[i] + best_t * motion[i]
    qx, qy, qz, region = closest_point_on_triangle(at, mesh.vertices[tri[0]], mesh.vertices[tri[1]],
                                                   mesh.vertices[tri[2]])
    dx, dy, dz = at[0] - qx, at[1] - qy, at[2] - qz
    d = np.sqrt(dx * dx + dy * dy + dz * dz)
    if region == FACE or d <= tol:
        # face (or the centre itself crossing): the normal facing where the sphere came from
        s0 = ((start[0] - mesh.vertices[tri[0], 0]) * nt[0] + (start[1] - mesh.vertices[tri[0], 1]) * nt[1]
              + (start[2] - mesh.vertices[tri[0], 2]) * nt[2])
        side = 1.0 if s0 >= 0.0 else -1.0
        normal[0], normal[1], normal[2] = side * nt[0], side * nt[1], side * nt[2]
    else:
        normal[0], normal[1], normal[2] = dx / d, dy / d, dz / d
    return True, best_t, best_triangle, normal


@njit(cache=True)
def sweep_spheres_mesh(starts, ends, radii, mesh):
    """:func:`sweep_sphere_mesh` for N spheres: hit (N,) bool, toi (N,), triangle (N,), normal (N, 3)."""
    count = starts.shape[0]
    hit = np.zeros(count, dtype=np.bool_)
    toi = np.ones(count)
    triangle = np.full(count, -1, dtype=np.int64)
    normal = np.zeros((count, 3))
    for k in range(count):
        h, t, tri, n = sweep_sphere_mesh(starts[k], ends[k], radii[k], mesh)
        hit[k] = h
        toi[k] = t
        triangle[k] = tri
        for i in range(3):
            normal[k, i] = n[i]
    return hit, toi, triangle, normal
