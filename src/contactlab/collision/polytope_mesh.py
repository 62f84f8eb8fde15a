"""Boxes and convex hulls against a static triangle mesh: their corners as points, and the mesh
vertices inside them.

Conventions (sides, normals, depth, margin, inside and outside) as in :mod:`.sphere_mesh`.

Box against a mesh — :func:`box_mesh`
    Each of the 8 corners is a point (a sphere of radius 0) against the mesh, with the rules
    of :mod:`.sphere_mesh`: outside, its local minima within the margin (a corner resting on the shared edge
    of a flat floor gives one contact); inside, one contact out through the nearest feature
    (never through the far side of a thin wall). Feature ``16 t + corner`` (corner 0–7
    numbered as in ``box_plane``). Plus the mesh vertices inside the box (grown by the
    margin), pushed out through the box face of least penetration among the faces whose
    contact normal points out of the mesh (positive dot with the vertex pseudo-normal),
    each vertex once, by its owner triangle (feature ``16 t + 8 + k``, k its local index).
    If there are more than ``max_contacts``: the deepest, then one at a time the contact
    farthest from those chosen. A box resting on a flat mesh floor gets its 4 bottom
    corners. Limitation: box edges crossing triangle edges away from any corner or vertex

Convex hull against a mesh — :func:`convex_mesh`
    As :func:`box_mesh`: each hull vertex is a point (a sphere of radius 0) against
    the mesh with the sphere rules (at most ``CORNER_CONTACTS`` each; local index
    ``v mod 13`` for hull vertex v), plus the mesh vertices inside the hull grown by the margin
    (by its face planes), each vertex once by its owner triangle, pushed out through the hull
    face of least penetration among those whose contact normal leaves the mesh (local index
    13 + k, k the vertex's local index in its triangle); reduced as box_mesh does. Features of
    hull vertices v and v + 13 on the same triangle coincide (hulls of more than 13 vertices).

Compiled (``@njit(cache=True)``), float64, no fastmath.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..compiling import njit
from ..meshes import mesh_triangles_near
from .contact_output import Frame, PairOutput, pair_output
from .convex import HullArrays
from .mesh_features import FEATURES_PER_TRIANGLE, keep_spread, write_kept
from .primitive_pairs import Box
from .sphere_mesh import sphere_mesh

if TYPE_CHECKING:
    from ..meshes import MeshGeometry

CORNER_CONTACTS = 4  # box–mesh contacts kept per box corner (the deepest local minima)
HULL_VERTEX_FEATURES = 13  # hull vertex v: 16 t + v mod 13; mesh vertex k inside the hull: 16 t + 13 + k


@njit(cache=True)
def _mesh_vertices_near(mesh, candidates, center, rotation):
    """The vertices of the candidate triangles, each once (by its owner triangle), seen from a
    shape at ``center`` (3,) [m] with ``rotation`` (3, 3) body → world: vertex (n,), owner
    triangle (n,), the vertex's local index in that triangle (n,), its body-frame position
    (n, 3) [m], and side (n,): −1 where a two-sided mesh's vertex pseudo-normal points away
    from the centre (a contact must leave the mesh towards the centre's side), else +1."""
    capacity = 3 * candidates.shape[0]
    vertex = np.empty(capacity, dtype=np.int64)
    owner = np.empty(capacity, dtype=np.int64)
    index = np.empty(capacity, dtype=np.int64)
    local = np.empty((capacity, 3))
    side = np.empty(capacity)
    n = 0
    for c in range(candidates.shape[0]):
        t = candidates[c]
        for k in range(3):
            v = mesh.triangles[t, k]
            if mesh.vertex_owner[v] != t:
                continue
            p = mesh.vertices[v]
            for a in range(3):
                local[n, a] = (
                    rotation[0, a] * (p[0] - center[0])
                    + rotation[1, a] * (p[1] - center[1])
                    + rotation[2, a] * (p[2] - center[2])
                )
            psi = mesh.vertex_pseudo_normals[v]
            side[n] = 1.0
            if (
                mesh.two_sided
                and ((center[0] - p[0]) * psi[0] + (center[1] - p[1]) * psi[1] + (center[2] - p[2]) * psi[2]) < 0.0
            ):
                side[n] = -1.0
            vertex[n], owner[n], index[n] = v, t, k
            n += 1
    return vertex[:n], owner[:n], index[:n], local[:n], side[:n]


@njit(cache=True)
def _corners_against_mesh(corners, local, mesh, margin, rows, count):
    """Each of a polytope's corners (V, 3) [m] as a point (a sphere of radius 0) against the
    mesh, with the sphere rules: at most ``CORNER_CONTACTS`` each, the deepest. Appends them to
    the candidate ``rows`` (:data:`.contact_output.PairOutput`) from ``count`` on, with feature
    ``16 · triangle + local[v]`` for corner v (local (V,) < 16); returns the new count."""
    point, normal, depth, feature = rows
    corner_limit = count * 0 + CORNER_CONTACTS  # (an int64 variable, not a literal)
    corner_rows = pair_output(CORNER_CONTACTS)
    corner_point, corner_normal, corner_depth, corner_feature = corner_rows
    for v in range(corners.shape[0]):
        found = sphere_mesh((corners[v], 0.0), mesh, margin, corner_rows, count * 0, corner_limit)
        for k in range(found):
            for i in range(3):
                point[count, i] = corner_point[k, i]
                normal[count, i] = corner_normal[k, i]
            depth[count] = corner_depth[k]
            # the corner replaces the region
            feature[count] = FEATURES_PER_TRIANGLE * (corner_feature[k] // FEATURES_PER_TRIANGLE) + local[v]
            count += 1
    return count


@njit(cache=True)
def box_mesh(box: Box, mesh: MeshGeometry, margin: float, out: PairOutput, slot: int, max_contacts: int) -> int:
    """Box A (a :data:`.primitive_pairs.Box`: frame = (centre (3,) [m], rotation (3, 3) body →
    world), half extents (3,) [m]) against the static mesh B.

    Each corner as a point (a sphere of radius 0: inside/outside and local minima as for
    spheres; at most ``CORNER_CONTACTS`` per corner, the deepest), plus mesh vertices inside
    the box (module docstring). Writes at most ``max_contacts`` contacts from ``slot`` on and
    returns how many.
    """
    (center, rotation), half_extents = box
    # mesh triangles near the box (grown by the margin): their vertices may lie inside it
    lower = np.empty(3)
    upper = np.empty(3)
    for i in range(3):
        reach = (
            abs(rotation[i, 0]) * half_extents[0]
            + abs(rotation[i, 1]) * half_extents[1]
            + abs(rotation[i, 2]) * half_extents[2]
        ) + margin
        lower[i] = center[i] - reach
        upper[i] = center[i] + reach
    candidates = mesh_triangles_near(mesh, lower, upper, np.empty(32, dtype=np.int64))
    # all candidate contacts: corners (at most CORNER_CONTACTS each), then mesh vertices
    capacity = 8 * CORNER_CONTACTS + 3 * candidates.shape[0]
    rows = pair_output(capacity)
    point, normal, depth, feature = rows
    corners = np.empty((8, 3))
    for corner in range(8):  # local index: the corner, numbered as in box_plane
        sx = half_extents[0] if corner & 1 else -half_extents[0]
        sy = half_extents[1] if corner & 2 else -half_extents[1]
        sz = half_extents[2] if corner & 4 else -half_extents[2]
        for i in range(3):
            corners[corner, i] = center[i] + rotation[i, 0] * sx + rotation[i, 1] * sy + rotation[i, 2] * sz
    count = _corners_against_mesh(corners, np.arange(8), mesh, margin, rows, slot * 0)
    # mesh vertices inside the box (grown by the margin), each once: by its owner triangle
    vertex, owner, index, local, side = _mesh_vertices_near(mesh, candidates, center, rotation)
    for n in range(vertex.shape[0]):
        inside = True
        for a in range(3):
            if abs(local[n, a]) > half_extents[a] + margin:
                inside = False
        if not inside:
            continue
        v = mesh.vertices[vertex[n]]
        psi = mesh.vertex_pseudo_normals[vertex[n]]
        best_gap, best_axis, best_sign = np.inf, -1, 1.0
        for a in range(3):
            sign = 1.0 if local[n, a] >= 0.0 else -1.0
            # contact normal = −(outward face normal) = −sign · R[:, a]; must leave the mesh
            along = -sign * (rotation[0, a] * psi[0] + rotation[1, a] * psi[1] + rotation[2, a] * psi[2])
            gap = half_extents[a] - abs(local[n, a])
            if side[n] * along > 0.0 and gap < best_gap:
                best_gap, best_axis, best_sign = gap, a, sign
        if best_axis < 0 or best_gap < -margin:
            continue
        for i in range(3):
            face = best_sign * rotation[i, best_axis]
            normal[count, i] = -face
            point[count, i] = v[i] + 0.5 * best_gap * face
        depth[count] = best_gap
        feature[count] = FEATURES_PER_TRIANGLE * owner[n] + 8 + index[n]
        count += 1
    return write_kept(keep_spread(point[:count], depth[:count], max_contacts, mesh.tolerance), rows, out, slot)


@njit(cache=True)
def convex_mesh(
    frame: Frame, hull: HullArrays, mesh: MeshGeometry, margin: float, out: PairOutput, slot: int, max_contacts: int
) -> int:
    """Convex hull A (``frame`` = (centre (3,) [m], rotation (3, 3) body → world); body-frame arrays
    :data:`.convex.HullArrays`) against the static mesh B, as :func:`box_mesh` (module docstring).

    Writes at most ``max_contacts`` contacts from ``slot`` on and returns how many. The
    vertices and the face planes alone decide what is inside (not the face corner lists or edges).
    """
    center, rotation = frame
    vertices, face_normal, face_offset = hull[0], hull[1], hull[2]
    vertex_count = vertices.shape[0]
    face_count = face_normal.shape[0]
    world = np.empty((vertex_count, 3))
    lower = np.full(3, np.inf)
    upper = np.full(3, -np.inf)
    for v in range(vertex_count):
        for i in range(3):
            world[v, i] = (
                center[i]
                + rotation[i, 0] * vertices[v, 0]
                + rotation[i, 1] * vertices[v, 1]
                + rotation[i, 2] * vertices[v, 2]
            )
            lower[i] = min(lower[i], world[v, i])
            upper[i] = max(upper[i], world[v, i])
    for i in range(3):
        lower[i] -= margin
        upper[i] += margin
    candidates = mesh_triangles_near(mesh, lower, upper, np.empty(32, dtype=np.int64))
    capacity = vertex_count * CORNER_CONTACTS + 3 * candidates.shape[0]
    rows = pair_output(capacity)
    point, normal, depth, feature = rows
    count = _corners_against_mesh(world, np.arange(vertex_count) % HULL_VERTEX_FEATURES, mesh, margin, rows, slot * 0)
    # mesh vertices inside the hull (its face planes moved out by the margin), each once
    vertex, owner, index, local, side = _mesh_vertices_near(mesh, candidates, center, rotation)
    for n in range(vertex.shape[0]):
        inside = True
        for f in range(face_count):
            if (
                face_normal[f, 0] * local[n, 0]
                + face_normal[f, 1] * local[n, 1]
                + face_normal[f, 2] * local[n, 2]
                - face_offset[f]
            ) > margin:
                inside = False
                break
        if not inside:
            continue
        p = mesh.vertices[vertex[n]]
        psi = mesh.vertex_pseudo_normals[vertex[n]]
        best_gap, best_face = np.inf, -1
        for f in range(face_count):
            wx = (
                rotation[0, 0] * face_normal[f, 0]
                + rotation[0, 1] * face_normal[f, 1]
                + rotation[0, 2] * face_normal[f, 2]
            )
            wy = (
                rotation[1, 0] * face_normal[f, 0]
                + rotation[1, 1] * face_normal[f, 1]
                + rotation[1, 2] * face_normal[f, 2]
            )
            wz = (
                rotation[2, 0] * face_normal[f, 0]
                + rotation[2, 1] * face_normal[f, 1]
                + rotation[2, 2] * face_normal[f, 2]
            )
            # contact normal = −(outward face normal); it must leave the mesh
            along = -(wx * psi[0] + wy * psi[1] + wz * psi[2])
            gap = face_offset[f] - (
                face_normal[f, 0] * local[n, 0] + face_normal[f, 1] * local[n, 1] + face_normal[f, 2] * local[n, 2]
            )
            if side[n] * along > 0.0 and gap < best_gap:
                best_gap, best_face = gap, f
        if best_face < 0 or best_gap < -margin:
            continue
        for i in range(3):
            face = (
                rotation[i, 0] * face_normal[best_face, 0]
                + rotation[i, 1] * face_normal[best_face, 1]
                + rotation[i, 2] * face_normal[best_face, 2]
            )
            normal[count, i] = -face
            point[count, i] = p[i] + 0.5 * best_gap * face
        depth[count] = best_gap
        feature[count] = FEATURES_PER_TRIANGLE * owner[n] + HULL_VERTEX_FEATURES + index[n]
        count += 1
    return write_kept(keep_spread(point[:count], depth[:count], max_contacts, mesh.tolerance), rows, out, slot)
