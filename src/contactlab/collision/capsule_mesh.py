"""Capsules against static triangle meshes.

Conventions as in :mod:`.sphere_mesh`: the mesh is side B, the normal points from the mesh
INTO the capsule A, ``depth`` > 0 when penetrating, contacts with ``depth ≥ −margin`` are
kept, each ``point`` lies midway between the two surfaces, and ``feature = 16 · triangle +
local index`` (local index < 16).

The capsule is the segment ``center + s · axis``, ``|s| ≤ half_length`` (axis = the third
column of the rotation), swept by a sphere of ``radius``. For every triangle near the
capsule (BVH query with its bounds grown by radius + margin, + ``max_depth`` for a
one-sided mesh) two kinds of candidate contacts are made, each a *sphere of the capsule's
radius at one point x(s) of the segment* judged as :func:`~.sphere_mesh.sphere_mesh` judges a
sphere (the closest feature of the triangle to x(s), its region, signed distance by the
pseudo-normal, the normal of the face exactly or the direction q → x):

* **end contacts** (local index 7: the −z end, 8: the +z end): a segment end that lies
  over the triangle's face (its closest point is the FACE region). A capsule lying flat on
  a face therefore gets its two ends (it does not rock), and — like ``capsule_plane`` — a
  slightly tilted one keeps both while the upper end is within the margin.
* **the closest contact** (local index = the region: 0 face, 1–3 edges, 4–6 vertices):
  the closest pair between the segment and the triangle (the minimum of: each end against
  the triangle, the segment against each of the 3 edges, the segment crossing the
  triangle; ties go to an end), unless it is an end over the face (already an end contact).

Duplicates and ghosts are removed with the sphere rules, applied at each contact's own
segment point x: (1) an edge or vertex point q is dropped when another candidate triangle
that contains q is nearer x (by more than the tolerance): q is not a local minimum; a FACE
contact in the interior of the segment (the end of a parallel patch on a triangle's
boundary) is dropped when a coplanar neighbour contains q: the support goes on there
(a flat capsule across the shared diagonal of a floor gets its 2 ends only); (2) contacts
at the same segment point and the same mesh point are one: face before edge before vertex,
then the lowest triangle; (3) a point x behind its feature (the far side of a thin solid)
gives a contact only if that feature is the nearest to x of all candidates (x inside the
mesh: out through the nearest feature, depth = radius + distance, as for a sphere).
If more than ``max_contacts`` remain: the deepest, then repeatedly the one farthest from
those chosen (as :func:`~.polytope_mesh.box_mesh`).

Compiled (``@njit(cache=True)``), float64, no fastmath.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..compiling import njit
from ..meshes import boxes_overlap, mesh_triangles_near
from .capsule import Capsule
from .contact_output import PairOutput, pair_output
from .mesh_features import (
    EDGE2,
    FACE,
    FEATURES_PER_TRIANGLE,
    closest_feature,
    closest_point_on_triangle,
    distance_to_triangle,
    keep_spread,
    nearest_feature,
    segment_triangle_closest,
    signed_normal,
    write_kept,
)

if TYPE_CHECKING:
    from ..meshes import MeshGeometry

END_FEATURE = 7  # capsule end contacts: 16 t + 7 (−z end), 16 t + 8 (+z end)
COPLANAR_COS = 1.0 - 1e-9  # two triangle normals with a dot product above this are coplanar


@njit(cache=True)
def capsule_mesh(
    capsule: Capsule, mesh: MeshGeometry, margin: float, out: PairOutput, slot: int, max_contacts: int
) -> int:
    """Capsule A (a :data:`.capsule.Capsule`: frame = (centre (3,) [m], rotation (3, 3) body →
    world), the segment along its third column, radius, half length [m]) against the static
    mesh B (module docstring).

    Writes at most ``max_contacts`` contacts from ``slot`` on and returns how many;
    ``feature = 16 · triangle + local`` (local: region 0–6 of the closest contact, 7 / 8 the
    −z / +z end over the face).
    """
    (center, rotation), radius, half_length = capsule
    tol = mesh.tolerance
    reach = radius + margin
    deep = 0.0 if mesh.two_sided else mesh.max_depth
    axis = np.empty(3)
    lower = np.empty(3)
    upper = np.empty(3)
    for i in range(3):
        axis[i] = rotation[i, 2]
        extent = abs(axis[i]) * half_length + reach + deep
        lower[i] = center[i] - extent
        upper[i] = center[i] + extent
    candidates = mesh_triangles_near(mesh, lower, upper, np.empty(32, dtype=np.int64))
    n = candidates.shape[0]
    # candidate records: segment parameter, triangle, closest point, region, distance, local index
    capacity = 3 * n
    rec_s = np.empty(capacity)
    rec_triangle = np.empty(capacity, dtype=np.int64)
    rec_q = np.empty((capacity, 3))
    rec_region = np.empty(capacity, dtype=np.int64)
    rec_distance = np.empty(capacity)
    rec_local = np.empty(capacity, dtype=np.int64)
    count = 0
    x = np.empty(3)
    ends = 2 if half_length > 0.0 else 1
    for c in range(n):
        t = candidates[c]
        nt = mesh.triangle_normals[t]
        if nt[0] == 0.0 and nt[1] == 0.0 and nt[2] == 0.0:
            continue
        # end contacts: an end over the face
        for end in range(ends):
            s = -half_length if end == 0 else half_length
            for i in range(3):
                x[i] = center[i] + s * axis[i]
            qx, qy, qz, region, d = closest_feature(mesh, t, x, tol)
            if region == FACE and d <= reach + deep:
                rec_s[count], rec_triangle[count], rec_region[count], rec_distance[count] = s, t, region, d
                rec_q[count, 0], rec_q[count, 1], rec_q[count, 2] = qx, qy, qz
                rec_local[count] = END_FEATURE + end
                count += 1
        # the closest pair of segment and triangle
        s, d_pair = segment_triangle_closest(center, axis, half_length, mesh, t, tol)
        if d_pair > reach + deep:
            continue
        for i in range(3):
            x[i] = center[i] + s * axis[i]
        qx, qy, qz, region, d = closest_feature(mesh, t, x, tol)
        at_end = abs(s - half_length) <= tol or abs(s + half_length) <= tol
        if region == FACE and at_end:
            continue  # an end over the face: an end contact already
        rec_s[count], rec_triangle[count], rec_region[count], rec_distance[count] = s, t, region, d
        rec_q[count, 0], rec_q[count, 1], rec_q[count, 2] = qx, qy, qz
        rec_local[count] = region
        count += 1
    keep = np.ones(count, dtype=np.bool_)
    other_distance = np.empty(n)
    near_lower, near_upper = np.empty(3), np.empty(3)  # the box about a record's q, ± twice the tolerance
    other_region = np.full(n, FACE, dtype=np.int64)
    rows = pair_output(count)
    point, normal, depth, feature = rows
    found = 0
    for r in range(count):
        s = rec_s[r]
        t = rec_triangle[r]
        for i in range(3):
            x[i] = center[i] + s * axis[i]
        q = rec_q[r]
        for i in range(3):
            near_lower[i], near_upper[i] = q[i] - 2.0 * tol, q[i] + 2.0 * tol
        nt = mesh.triangle_normals[t]
        interior = abs(s - half_length) > tol and abs(s + half_length) > tol
        # (1) not a local minimum. Only a candidate whose box reaches q (grown by twice the
        # tolerance, far beyond rounding) can contain q: the others are passed over before the
        # distance from x and the closest point to q are computed, which made this pass
        # quadratic in the candidates (a capsule lying in a fine mesh meets hundreds)
        for c in range(n):
            j = candidates[c]
            if j == t or not boxes_overlap(mesh.triangle_lower, mesh.triangle_upper, j, near_lower, near_upper):
                continue
            other_distance[c] = distance_to_triangle(mesh, j, x)
            if other_distance[c] == np.inf:
                continue
            other = mesh.triangles[j]
            px, py, pz, _ = closest_point_on_triangle(
                q, mesh.vertices[other[0]], mesh.vertices[other[1]], mesh.vertices[other[2]]
            )
            contains = (px - q[0]) ** 2 + (py - q[1]) ** 2 + (pz - q[2]) ** 2 <= tol * tol
            if not contains:
                continue
            if rec_region[r] != FACE and other_distance[c] < rec_distance[r] - tol:
                keep[r] = False
                break
            if rec_region[r] == FACE and interior:
                nj = mesh.triangle_normals[j]
                if nj[0] * nt[0] + nj[1] * nt[1] + nj[2] * nt[2] >= COPLANAR_COS:
                    keep[r] = False
                    break
        if not keep[r]:
            continue
        # (2) one contact per (segment point, mesh point)
        rank_r = 0 if rec_region[r] == FACE else (1 if rec_region[r] <= EDGE2 else 2)
        for k in range(count):
            if k == r or not keep[k] or abs(rec_s[k] - s) > tol:
                continue
            rank_k = 0 if rec_region[k] == FACE else (1 if rec_region[k] <= EDGE2 else 2)
            if rank_k > rank_r or (rank_k == rank_r and rec_triangle[k] > t):
                continue
            if rank_k == rank_r and rec_triangle[k] == t and k > r:
                continue
            ex, ey, ez = rec_q[k, 0] - q[0], rec_q[k, 1] - q[1], rec_q[k, 2] - q[2]
            if ex * ex + ey * ey + ez * ez <= tol * tol:
                keep[r] = False
                break
        if not keep[r]:
            continue
        # (3) sign, normal, depth
        signed, nx, ny, nz = signed_normal(mesh, t, rec_region[r], x, q[0], q[1], q[2], rec_distance[r])
        if signed < 0.0:  # the sphere at x: the distances of all candidates from x
            for c in range(n):
                other_distance[c] = distance_to_triangle(mesh, candidates[c], x)
            nearest = nearest_feature(candidates, other_distance, other_region)
            if nearest < 0 or candidates[nearest] != t or other_distance[nearest] < rec_distance[r] - tol:
                keep[r] = False
                continue
        elif rec_distance[r] > reach:
            keep[r] = False
            continue
        this_depth = radius - signed
        if this_depth < -margin:
            keep[r] = False
            continue
        normal[found, 0], normal[found, 1], normal[found, 2] = nx, ny, nz
        depth[found] = this_depth
        point[found, 0] = 0.5 * (x[0] - radius * nx + q[0])
        point[found, 1] = 0.5 * (x[1] - radius * ny + q[1])
        point[found, 2] = 0.5 * (x[2] - radius * nz + q[2])
        feature[found] = FEATURES_PER_TRIANGLE * t + rec_local[r]
        found += 1
    return write_kept(keep_spread(point[:found], depth[:found], max_contacts, tol), rows, out, slot)
