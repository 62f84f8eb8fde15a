"""Capsules and convex hulls against static triangle meshes.

Conventions as in :mod:`contactlab.collision.mesh`: the mesh is side B, the normal points
from the mesh INTO the dynamic shape A, ``depth`` > 0 when penetrating, contacts with
``depth ≥ −margin`` are kept, each ``point`` lies midway between the two surfaces, and
``feature = 16 · triangle + local index`` (local index < 16).

Capsule against a mesh — :func:`capsule_mesh`
    The capsule is the segment ``center + s · axis``, ``|s| ≤ half_length`` (axis = the third
    column of the rotation), swept by a sphere of ``radius``. For every triangle near the
    capsule (BVH query with its bounds grown by radius + margin, + ``max_depth`` for a
    one-sided mesh) two kinds of candidate contacts are made, each a *sphere of the capsule's
    radius at one point x(s) of the segment* judged as :func:`~.mesh.sphere_mesh` judges a
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
    those chosen (as :func:`~.mesh.box_mesh`).

Convex hull against a mesh — :func:`convex_mesh`
    As :func:`~.mesh.box_mesh`: each hull vertex is a point (a sphere of radius 0) against
    the mesh with the sphere rules (at most ``CORNER_CONTACTS`` each; local index
    ``v mod 13`` for hull vertex v), plus the mesh vertices inside the hull grown by the margin
    (by its face planes), each vertex once by its owner triangle, pushed out through the hull
    face of least penetration among those whose contact normal leaves the mesh (local index
    13 + k, k the vertex's local index in its triangle); reduced as box_mesh does. Features of
    hull vertices v and v + 13 on the same triangle coincide (hulls of more than 13 vertices).
    Limitation (as box_mesh): hull edges crossing mesh edges away from any vertex give no
    contact.

Batch — :func:`shapes_against_mesh_extended`: :func:`~.mesh.shapes_against_mesh` plus CAPSULE
and CONVEX shapes.

Everything per contact is compiled (``@njit(cache=True)``), float64, no fastmath.
"""

import numpy as np
from numba import njit

from .. import shapes
from ..meshes import mesh_triangles_near
from .capsule import segment_closest_parameters
from .contact_output import write_contact
from .convex import hull_view
from .mesh import (CORNER_CONTACTS, EDGE2, FACE, FEATURES_PER_TRIANGLE, MAX_PER_SHAPE, _closest_feature,
                   _nearest, _signed_normal, _spread, box_mesh, closest_point_on_triangle, sphere_mesh)

SPHERE, BOX, POINT, CAPSULE, CONVEX = shapes.SPHERE, shapes.BOX, shapes.POINT, shapes.CAPSULE, shapes.CONVEX
END_FEATURE = 7            # capsule end contacts: 16 t + 7 (−z end), 16 t + 8 (+z end)
HULL_VERTEX_FEATURES = 13  # hull vertex v: 16 t + v mod 13; mesh vertex k inside the hull: 16 t + 13 + k
COPLANAR_COS = 1.0 - 1e-9  # two triangle normals with a dot product above this are coplanar

__all__ = ["capsule_mesh", "convex_mesh", "shapes_against_mesh_extended", "MAX_PER_SHAPE"]


# ---------------------------------------------------------------------------------------------
# capsule against a mesh
# ---------------------------------------------------------------------------------------------

@njit(cache=True)
def _distance_to_triangle(mesh, triangle, x):
    """Distance [m] of x (3,) from a triangle (exact closest point; inf for a degenerate one)."""
    nt = mesh.triangle_normals[triangle]
    if nt[0] == 0.0 and nt[1] == 0.0 and nt[2] == 0.0:
        return np.inf
    tri = mesh.triangles[triangle]
    qx, qy, qz, _ = closest_point_on_triangle(x, mesh.vertices[tri[0]], mesh.vertices[tri[1]],
                                              mesh.vertices[tri[2]])
    return np.sqrt((x[0] - qx) ** 2 + (x[1] - qy) ** 2 + (x[2] - qz) ** 2)


@njit(cache=True)
def segment_triangle_closest(center, axis, half_length, mesh, triangle, tol):
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
        d = _distance_to_triangle(mesh, triangle, x)
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
    h0 = ((center[0] - half_length * axis[0] - v0[0]) * nt[0] + (center[1] - half_length * axis[1] - v0[1]) * nt[1]
          + (center[2] - half_length * axis[2] - v0[2]) * nt[2])
    h1 = ((center[0] + half_length * axis[0] - v0[0]) * nt[0] + (center[1] + half_length * axis[1] - v0[1]) * nt[1]
          + (center[2] + half_length * axis[2] - v0[2]) * nt[2])
    if best_d > tol and h0 * h1 < 0.0:
        s = -half_length + 2.0 * half_length * h0 / (h0 - h1)
        for i in range(3):
            x[i] = center[i] + s * axis[i]
        d = _distance_to_triangle(mesh, triangle, x)
        if d < best_d - tol:
            best_s, best_d = s, d
    return best_s, best_d


@njit(cache=True)
def capsule_mesh(center, rotation, radius, half_length, mesh, margin, out_point, out_normal, out_depth,
                 out_feature, slot, max_contacts):
    """Capsule A (centre (3,) [m], rotation (3, 3) body → world, the segment along its third
    column, ``radius``, ``half_length`` [m]) against the static mesh B (module docstring).

    Writes at most ``max_contacts`` contacts from ``slot`` on and returns how many;
    ``feature = 16 · triangle + local`` (local: region 0–6 of the closest contact, 7 / 8 the
    −z / +z end over the face).
    """
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
            qx, qy, qz, region, d = _closest_feature(mesh, t, x, tol)
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
        qx, qy, qz, region, d = _closest_feature(mesh, t, x, tol)
        at_end = abs(s - half_length) <= tol or abs(s + half_length) <= tol
        if region == FACE and at_end:
            continue                                   # an end over the face: an end contact already
        rec_s[count], rec_triangle[count], rec_region[count], rec_distance[count] = s, t, region, d
        rec_q[count, 0], rec_q[count, 1], rec_q[count, 2] = qx, qy, qz
        rec_local[count] = region
        count += 1
    keep = np.ones(count, dtype=np.bool_)
    other_distance = np.empty(n)
    other_region = np.zeros(n, dtype=np.int64)
    point = np.empty((count, 3))
    normal = np.empty((count, 3))
    depth = np.empty(count)
    feature = np.empty(count, dtype=np.int64)
    found = 0
    for r in range(count):
        s = rec_s[r]
        t = rec_triangle[r]
        for i in range(3):
            x[i] = center[i] + s * axis[i]
        q = rec_q[r]
        # the sphere at x: the distances of all candidates from x
        nt = mesh.triangle_normals[t]
        for c in range(n):
            other_distance[c] = _distance_to_triangle(mesh, candidates[c], x)
            other_region[c] = FACE
        interior = abs(s - half_length) > tol and abs(s + half_length) > tol
        # (1) not a local minimum
        for c in range(n):
            j = candidates[c]
            if j == t or other_distance[c] == np.inf:
                continue
            other = mesh.triangles[j]
            px, py, pz, _ = closest_point_on_triangle(q, mesh.vertices[other[0]], mesh.vertices[other[1]],
                                                      mesh.vertices[other[2]])
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
        signed, nx, ny, nz = _signed_normal(mesh, t, rec_region[r], x, q[0], q[1], q[2], rec_distance[r])
        if signed < 0.0:
            nearest = _nearest(candidates, other_distance, other_region)
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
    chosen = _spread(point[:found], depth[:found], max_contacts, tol)
    written = 0
    for i in range(found):
        if chosen[i] and written < max_contacts:
            write_contact(out_point, out_normal, out_depth, out_feature, slot + written, point[i], normal[i],
                          depth[i], feature[i])
            written += 1
    return written


# ---------------------------------------------------------------------------------------------
# convex hull against a mesh
# ---------------------------------------------------------------------------------------------

@njit(cache=True)
def convex_mesh(center, rotation, vertices, face_normal, face_offset, face_vertex_start, face_vertex_index, mesh,
                margin, out_point, out_normal, out_depth, out_feature, slot, max_contacts):
    """Convex hull A (centre (3,) [m], rotation (3, 3) body → world; body-frame arrays as in
    :mod:`.convex`) against the static mesh B, as :func:`~.mesh.box_mesh` (module docstring).

    Writes at most ``max_contacts`` contacts from ``slot`` on and returns how many.
    ``face_vertex_start`` and ``face_vertex_index`` are accepted for the hull-argument order
    of :mod:`.convex`; the face planes alone decide what is inside.
    """
    corner_limit = max_contacts * 0 + CORNER_CONTACTS
    vertex_count = vertices.shape[0]
    face_count = face_normal.shape[0]
    world = np.empty((vertex_count, 3))
    lower = np.full(3, np.inf)
    upper = np.full(3, -np.inf)
    for v in range(vertex_count):
        for i in range(3):
            world[v, i] = (center[i] + rotation[i, 0] * vertices[v, 0] + rotation[i, 1] * vertices[v, 1]
                           + rotation[i, 2] * vertices[v, 2])
            lower[i] = min(lower[i], world[v, i])
            upper[i] = max(upper[i], world[v, i])
    for i in range(3):
        lower[i] -= margin
        upper[i] += margin
    candidates = mesh_triangles_near(mesh, lower, upper, np.empty(32, dtype=np.int64))
    capacity = vertex_count * CORNER_CONTACTS + 3 * candidates.shape[0]
    point = np.empty((capacity, 3))
    normal = np.empty((capacity, 3))
    depth = np.empty(capacity)
    feature = np.empty(capacity, dtype=np.int64)
    corner_point = np.empty((CORNER_CONTACTS, 3))
    corner_normal = np.empty((CORNER_CONTACTS, 3))
    corner_depth = np.empty(CORNER_CONTACTS)
    corner_feature = np.empty(CORNER_CONTACTS, dtype=np.int64)
    count = 0
    for v in range(vertex_count):
        found = sphere_mesh(world[v], 0.0, mesh, margin, corner_point, corner_normal, corner_depth, corner_feature,
                            slot * 0, corner_limit)
        for k in range(found):
            for i in range(3):
                point[count, i] = corner_point[k, i]
                normal[count, i] = corner_normal[k, i]
            depth[count] = corner_depth[k]
            feature[count] = (FEATURES_PER_TRIANGLE * (corner_feature[k] // FEATURES_PER_TRIANGLE)
                              + v % HULL_VERTEX_FEATURES)
            count += 1
    # mesh vertices inside the hull (its face planes moved out by the margin), each once
    local = np.empty(3)
    for c in range(candidates.shape[0]):
        t = candidates[c]
        tri = mesh.triangles[t]
        for k in range(3):
            vertex = tri[k]
            if mesh.vertex_owner[vertex] != t:
                continue
            p = mesh.vertices[vertex]
            for a in range(3):
                local[a] = (rotation[0, a] * (p[0] - center[0]) + rotation[1, a] * (p[1] - center[1])
                            + rotation[2, a] * (p[2] - center[2]))
            inside = True
            for f in range(face_count):
                if (face_normal[f, 0] * local[0] + face_normal[f, 1] * local[1] + face_normal[f, 2] * local[2]
                        - face_offset[f]) > margin:
                    inside = False
                    break
            if not inside:
                continue
            psi = mesh.vertex_pseudo_normals[vertex]
            psi_sign = 1.0
            if mesh.two_sided and ((center[0] - p[0]) * psi[0] + (center[1] - p[1]) * psi[1]
                                   + (center[2] - p[2]) * psi[2]) < 0.0:
                psi_sign = -1.0
            best_gap, best_face = np.inf, -1
            for f in range(face_count):
                wx = rotation[0, 0] * face_normal[f, 0] + rotation[0, 1] * face_normal[f, 1] + rotation[0, 2] * face_normal[f, 2]
                wy = rotation[1, 0] * face_normal[f, 0] + rotation[1, 1] * face_normal[f, 1] + rotation[1, 2] * face_normal[f, 2]
                wz = rotation[2, 0] * face_normal[f, 0] + rotation[2, 1] * face_normal[f, 1] + rotation[2, 2] * face_normal[f, 2]
                # contact normal = −(outward face normal); it must leave the mesh
                along = -(wx * psi[0] + wy * psi[1] + wz * psi[2])
                gap = face_offset[f] - (face_normal[f, 0] * local[0] + face_normal[f, 1] * local[1]
                                        + face_normal[f, 2] * local[2])
                if psi_sign * along > 0.0 and gap < best_gap:
                    best_gap, best_face = gap, f
            if best_face < 0 or best_gap < -margin:
                continue
            for i in range(3):
                face = (rotation[i, 0] * face_normal[best_face, 0] + rotation[i, 1] * face_normal[best_face, 1]
                        + rotation[i, 2] * face_normal[best_face, 2])
                normal[count, i] = -face
                point[count, i] = p[i] + 0.5 * best_gap * face
            depth[count] = best_gap
            feature[count] = FEATURES_PER_TRIANGLE * t + HULL_VERTEX_FEATURES + k
            count += 1
    chosen = _spread(point[:count], depth[:count], max_contacts, mesh.tolerance)
    written = 0
    for i in range(count):
        if chosen[i] and written < max_contacts:
            write_contact(out_point, out_normal, out_depth, out_feature, slot + written, point[i], normal[i],
                          depth[i], feature[i])
            written += 1
    return written


# ---------------------------------------------------------------------------------------------
# many shapes against one mesh
# ---------------------------------------------------------------------------------------------

@njit(cache=True)
def mesh_supported_extended(kind):
    """Whether a dynamic shape of this kind has a contact routine against a mesh (with this module)."""
    return kind == SPHERE or kind == POINT or kind == BOX or kind == CAPSULE or kind == CONVEX


@njit(cache=True)
def shapes_against_mesh_extended(kinds, params, centers, rotations_, margins, hull_store, mesh, max_per_shape):
    """:func:`~.mesh.shapes_against_mesh` with capsules (params: radius, half length) and convex
    hulls (params[0]: the hull index into ``hull_store``, the 10 packed hull arrays of
    ``Model.hull_store``) as well. Returns point (C, 3), normal (C, 3), depth (C,),
    feature (C,), owner (C,)."""
    (vertex_start, hull_vertices, face_start, face_normal, face_offset, face_vertex_start, face_vertex_index,
     edge_start, edge_vertex, edge_face) = hull_store
    count_shapes = kinds.shape[0]
    capacity = max(1, count_shapes * max_per_shape)
    point = np.empty((capacity, 3))
    normal = np.empty((capacity, 3))
    depth = np.empty(capacity)
    feature = np.empty(capacity, dtype=np.int64)
    owner = np.empty(capacity, dtype=np.int64)
    count = np.int64(capacity) * 0
    for s in range(count_shapes):
        kind = kinds[s]
        written = 0
        if kind == SPHERE or kind == POINT:
            written = sphere_mesh(centers[s], params[s, 0], mesh, margins[s], point, normal, depth, feature,
                                  count, max_per_shape)
        elif kind == BOX:
            written = box_mesh(centers[s], rotations_[s], params[s, :3], mesh, margins[s], point, normal, depth,
                               feature, count, max_per_shape)
        elif kind == CAPSULE:
            written = capsule_mesh(centers[s], rotations_[s], params[s, 0], params[s, 1], mesh, margins[s], point,
                                   normal, depth, feature, count, max_per_shape)
        elif kind == CONVEX:
            h = np.int64(params[s, 0])
            v, fn, fo, fvs, fvi, ev, ef = hull_view(vertex_start, hull_vertices, face_start, face_normal,
                                                    face_offset, face_vertex_start, face_vertex_index, edge_start,
                                                    edge_vertex, edge_face, h)
            written = convex_mesh(centers[s], rotations_[s], v, fn, fo, fvs, fvi, mesh, margins[s], point, normal,
                                  depth, feature, count, max_per_shape)
        for k in range(count, count + written):
            owner[k] = s
        count += written
    return point[:count], normal[:count], depth[:count], feature[:count], owner[:count]
