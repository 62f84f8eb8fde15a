"""Contacts of dynamic shapes against static triangle meshes, and the one dispatcher for them.

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
:func:`~.mesh_sweep.sweep_sphere_mesh` (or by speculative contacts with a margin ≥ the step's motion).

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

Convex hull against a mesh — :func:`convex_mesh`
    As :func:`box_mesh`: each hull vertex is a point (a sphere of radius 0) against
    the mesh with the sphere rules (at most ``CORNER_CONTACTS`` each; local index
    ``v mod 13`` for hull vertex v), plus the mesh vertices inside the hull grown by the margin
    (by its face planes), each vertex once by its owner triangle, pushed out through the hull
    face of least penetration among those whose contact normal leaves the mesh (local index
    13 + k, k the vertex's local index in its triangle); reduced as box_mesh does. Features of
    hull vertices v and v + 13 on the same triangle coincide (hulls of more than 13 vertices).

Capsule against a mesh: :mod:`.capsule_mesh` (a sphere of the capsule's radius at points of
its segment, with the same rules).

Batch — :func:`shapes_against_mesh`: every dynamic shape against one mesh, by kind.

Closest features and pseudo-normals: :mod:`.mesh_features`. Everything per contact is
compiled (``@njit(cache=True)``), float64, no fastmath.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from .. import shapes
from ..meshes import mesh_triangles_near
from .capsule_mesh import capsule_mesh
from .convex import hull_view
from .mesh_features import (
    EDGE2,
    FACE,
    FEATURES_PER_TRIANGLE,
    candidate_rows,
    closest_point_on_triangle,
    features_near,
    keep_deepest,
    keep_spread,
    nearest_feature,
    signed_normal,
    write_kept,
)

if TYPE_CHECKING:
    from ..meshes import MeshGeometry

MAX_PER_SHAPE = 8  # the usual cap of contacts per shape against one mesh (as MAX_PER_PAIR)
CORNER_CONTACTS = 4  # box–mesh contacts kept per box corner (the deepest local minima)
HULL_VERTEX_FEATURES = 13  # hull vertex v: 16 t + v mod 13; mesh vertex k inside the hull: 16 t + 13 + k

SPHERE, BOX, POINT, CAPSULE, CONVEX = shapes.SPHERE, shapes.BOX, shapes.POINT, shapes.CAPSULE, shapes.CONVEX
MESH_PARTNERS = (SPHERE, POINT, BOX, CAPSULE, CONVEX)  # the dynamic shapes with a routine against a mesh


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
def _corners_against_mesh(corners, local, mesh, margin, point, normal, depth, feature, count):
    """Each of a polytope's corners (V, 3) [m] as a point (a sphere of radius 0) against the
    mesh, with the sphere rules: at most ``CORNER_CONTACTS`` each, the deepest. Appends them to
    the candidate rows point, normal, depth, feature from ``count`` on, with feature
    ``16 · triangle + local[v]`` for corner v (local (V,) < 16); returns the new count."""
    corner_limit = count * 0 + CORNER_CONTACTS  # (an int64 variable, not a literal)
    corner_point = np.empty((CORNER_CONTACTS, 3))
    corner_normal = np.empty((CORNER_CONTACTS, 3))
    corner_depth = np.empty(CORNER_CONTACTS)
    corner_feature = np.empty(CORNER_CONTACTS, dtype=np.int64)
    for v in range(corners.shape[0]):
        found = sphere_mesh(
            corners[v],
            0.0,
            mesh,
            margin,
            corner_point,
            corner_normal,
            corner_depth,
            corner_feature,
            count * 0,
            corner_limit,
        )
        for k in range(found):
            for i in range(3):
                point[count, i] = corner_point[k, i]
                normal[count, i] = corner_normal[k, i]
            depth[count] = corner_depth[k]
            # the corner replaces the region
            feature[count] = FEATURES_PER_TRIANGLE * (corner_feature[k] // FEATURES_PER_TRIANGLE) + local[v]
            count += 1
    return count


# ---------------------------------------------------------------------------------------------
# sphere / particle against a mesh
# ---------------------------------------------------------------------------------------------


@njit(cache=True)
def sphere_mesh(
    center: np.ndarray,
    radius: float,
    mesh: MeshGeometry,
    margin: float,
    out_point: np.ndarray,
    out_normal: np.ndarray,
    out_depth: np.ndarray,
    out_feature: np.ndarray,
    slot: int,
    max_contacts: int,
) -> int:
    """Sphere (or particle) A of ``radius`` [m] at ``center`` (3,) against the static mesh B.

    Writes at most ``max_contacts`` contacts (the deepest) from ``slot`` on and returns how
    many; ``feature = 16 · triangle + region``. Rules (module docstring): a centre inside a
    one-sided mesh gets one contact, through the nearest feature; a centre outside gets one
    per local minimum of the distance within ``radius + margin``.
    """
    reach = radius + margin
    tol = mesh.tolerance
    candidates, closest, distance, region = features_near(
        mesh, center, reach, np.empty((32, 3)), np.empty(32), np.empty(32, dtype=np.int64)
    )
    nearest = nearest_feature(candidates, distance, region)
    if nearest < 0 or distance[nearest] > reach:
        # nothing within reach: a centre deeper than that inside a one-sided mesh?
        if mesh.two_sided or mesh.max_depth <= 0.0:
            return 0
        candidates, closest, distance, region = features_near(
            mesh, center, reach + mesh.max_depth, closest, distance, region
        )
        nearest = nearest_feature(candidates, distance, region)
        if nearest < 0 or distance[nearest] > reach + mesh.max_depth:
            return 0
    q = closest[nearest]
    signed, nx, ny, nz = signed_normal(
        mesh, candidates[nearest], region[nearest], center, q[0], q[1], q[2], distance[nearest]
    )
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
            px, py, pz, _ = closest_point_on_triangle(
                closest[i], mesh.vertices[other[0]], mesh.vertices[other[1]], mesh.vertices[other[2]]
            )
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
    point, normal, depth, feature = candidate_rows(n)
    count = 0
    for i in range(n):
        if not keep[i]:
            continue
        t = candidates[i]
        signed, nx, ny, nz = signed_normal(
            mesh, t, region[i], center, closest[i, 0], closest[i, 1], closest[i, 2], distance[i]
        )
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
    return write_kept(
        keep_deepest(depth[:count], max_contacts),
        point,
        normal,
        depth,
        feature,
        out_point,
        out_normal,
        out_depth,
        out_feature,
        slot,
    )


# ---------------------------------------------------------------------------------------------
# box against a mesh
# ---------------------------------------------------------------------------------------------


@njit(cache=True)
def box_mesh(
    center: np.ndarray,
    rotation: np.ndarray,
    half_extents: np.ndarray,
    mesh: MeshGeometry,
    margin: float,
    out_point: np.ndarray,
    out_normal: np.ndarray,
    out_depth: np.ndarray,
    out_feature: np.ndarray,
    slot: int,
    max_contacts: int,
) -> int:
    """Box A (centre (3,), rotation (3,3) body → world, half extents (3,)) against the static mesh B.

    Each corner as a point (a sphere of radius 0: inside/outside and local minima as for
    spheres; at most ``CORNER_CONTACTS`` per corner, the deepest), plus mesh vertices inside
    the box (module docstring). Writes at most ``max_contacts`` contacts from ``slot`` on and
    returns how many.
    """
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
    point, normal, depth, feature = candidate_rows(capacity)
    corners = np.empty((8, 3))
    for corner in range(8):  # local index: the corner, numbered as in box_plane
        sx = half_extents[0] if corner & 1 else -half_extents[0]
        sy = half_extents[1] if corner & 2 else -half_extents[1]
        sz = half_extents[2] if corner & 4 else -half_extents[2]
        for i in range(3):
            corners[corner, i] = center[i] + rotation[i, 0] * sx + rotation[i, 1] * sy + rotation[i, 2] * sz
    count = _corners_against_mesh(corners, np.arange(8), mesh, margin, point, normal, depth, feature, slot * 0)
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
    return write_kept(
        keep_spread(point[:count], depth[:count], max_contacts, mesh.tolerance),
        point,
        normal,
        depth,
        feature,
        out_point,
        out_normal,
        out_depth,
        out_feature,
        slot,
    )


# ---------------------------------------------------------------------------------------------
# convex hull against a mesh
# ---------------------------------------------------------------------------------------------


@njit(cache=True)
def convex_mesh(
    center: np.ndarray,
    rotation: np.ndarray,
    vertices: np.ndarray,
    face_normal: np.ndarray,
    face_offset: np.ndarray,
    face_vertex_start: np.ndarray,
    face_vertex_index: np.ndarray,
    mesh: MeshGeometry,
    margin: float,
    out_point: np.ndarray,
    out_normal: np.ndarray,
    out_depth: np.ndarray,
    out_feature: np.ndarray,
    slot: int,
    max_contacts: int,
) -> int:
    """Convex hull A (centre (3,) [m], rotation (3, 3) body → world; body-frame arrays as in
    :mod:`.convex`) against the static mesh B, as :func:`box_mesh` (module docstring).

    Writes at most ``max_contacts`` contacts from ``slot`` on and returns how many.
    ``face_vertex_start`` and ``face_vertex_index`` are accepted for the hull-argument order
    of :mod:`.convex`; the face planes alone decide what is inside.
    """
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
    point, normal, depth, feature = candidate_rows(capacity)
    count = _corners_against_mesh(
        world, np.arange(vertex_count) % HULL_VERTEX_FEATURES, mesh, margin, point, normal, depth, feature, slot * 0
    )
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
    return write_kept(
        keep_spread(point[:count], depth[:count], max_contacts, mesh.tolerance),
        point,
        normal,
        depth,
        feature,
        out_point,
        out_normal,
        out_depth,
        out_feature,
        slot,
    )


# ---------------------------------------------------------------------------------------------
# many shapes against one mesh
# ---------------------------------------------------------------------------------------------


@njit(cache=True)
def shapes_against_mesh(
    kinds: np.ndarray,
    params: np.ndarray,
    centers: np.ndarray,
    rotations_: np.ndarray,
    margins: np.ndarray,
    mesh: MeshGeometry,
    max_per_shape: int,
    hull_store: tuple[np.ndarray, ...] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Contacts of many dynamic shapes against one static mesh.

    kinds (N,), params (N, 4), centers (N, 3) [m], rotations_ (N, 3, 3), margins (N,) [m] per
    shape: spheres and particles (params[0]: radius), boxes (params[:3]: half extents),
    capsules (radius, half length) and convex hulls (params[0]: the hull index into
    ``hull_store``, the 10 packed hull arrays of ``Model.hull_store``; without a store hulls
    give none). max_per_shape: the cap of contacts per shape (``MAX_PER_SHAPE`` is the usual
    one). Returns point (C, 3), normal (C, 3), depth (C,), feature (C,) and owner (C,): the
    index of the shape each contact belongs to. Shapes with no routine (planes) give none.
    """
    count_shapes = kinds.shape[0]
    capacity = max(1, count_shapes * max_per_shape)
    point, normal, depth, feature = candidate_rows(capacity)
    owner = np.empty(capacity, dtype=np.int64)
    count = np.int64(capacity) * 0  # (not the literal 0: that would compile the callees twice)
    for s in range(count_shapes):
        kind = kinds[s]
        written = 0
        if kind == SPHERE or kind == POINT:
            written = sphere_mesh(
                centers[s], params[s, 0], mesh, margins[s], point, normal, depth, feature, count, max_per_shape
            )
        elif kind == BOX:
            written = box_mesh(
                centers[s],
                rotations_[s],
                params[s, :3],
                mesh,
                margins[s],
                point,
                normal,
                depth,
                feature,
                count,
                max_per_shape,
            )
        elif kind == CAPSULE:
            written = capsule_mesh(
                centers[s],
                rotations_[s],
                params[s, 0],
                params[s, 1],
                mesh,
                margins[s],
                point,
                normal,
                depth,
                feature,
                count,
                max_per_shape,
            )
        elif kind == CONVEX and hull_store is not None:
            (
                vertex_start,
                hull_vertices,
                face_start,
                face_normal,
                face_offset,
                face_vertex_start,
                face_vertex_index,
                edge_start,
                edge_vertex,
                edge_face,
            ) = hull_store
            v, fn, fo, fvs, fvi, _, _ = hull_view(
                vertex_start,
                hull_vertices,
                face_start,
                face_normal,
                face_offset,
                face_vertex_start,
                face_vertex_index,
                edge_start,
                edge_vertex,
                edge_face,
                np.int64(params[s, 0]),
            )
            written = convex_mesh(
                centers[s],
                rotations_[s],
                v,
                fn,
                fo,
                fvs,
                fvi,
                mesh,
                margins[s],
                point,
                normal,
                depth,
                feature,
                count,
                max_per_shape,
            )
        for k in range(count, count + written):
            owner[k] = s
        count += written
    return point[:count], normal[:count], depth[:count], feature[:count], owner[:count]
