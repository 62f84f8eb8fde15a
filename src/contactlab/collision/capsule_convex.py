"""Capsule against a convex hull: up to 2 contacts.

Conventions as in :mod:`contactlab.collision.capsule` and :mod:`contactlab.collision.convex`:
capsule A's segment runs along its body z axis (third column of its rotation), ``center ±
half_length · axis``; hull B is given by its body-frame arrays, one argument (``vertices`` (V, 3),
``face_normal`` (F, 3), ``face_offset`` (F,), ``face_vertex_start`` (F+1,) — global offsets,
its first entry is subtracted —, ``face_vertex_index`` (K,), ``edge_vertex`` (E, 2),
``edge_face`` (E, 2)), a centre and a rotation (body → world). The normal is a unit vector
from B into A, ``depth`` > 0 when overlapping, contacts kept down to ``depth = −margin``, each
point midway between the two surfaces.

The routine mirrors :func:`contactlab.collision.capsule_box.capsule_box` feature by feature, with
the box's 6 faces, 12 edges and 8 corners replaced by the hull's; on a hull that is a box
(:func:`contactlab.hulls.box_as_hull`) it gives the same deepest contact.

1. **Segment apart from the hull** (distance > ``BOX_REL_EPS`` × size): the exact segment–hull
   distance is the minimum over (each segment end, each face polygon it projects into) and
   (the segment, each hull edge) (:func:`geometry.segment_closest_parameters`); the closest
   points ``p`` (segment) and ``q`` (hull) give the normal ``(p − q)/|p − q|`` and the depth
   ``radius − |p − q|``. By the hull feature ``q`` lies on (a face interior wins ties within
   the tolerance):

   * a face: a *face patch*: the segment is clipped against the side planes of the face
     polygon and both ends of the clipped part are contacts with the face normal and their own
     depth (``radius −`` height above the face, exact): a capsule lying flat gets 2 contacts of
     equal depth, one standing on its end 1;
   * an edge the segment is parallel to (``|sin| < PARALLEL_SIN``): 2 contacts at the ends of
     the part of the segment alongside the edge, normal of the closest points, depth along it;
   * otherwise (an edge at an angle, a vertex): the closest-point contact, plus the far end of
     the *dominant face*'s patch (the face whose plane ``p`` is highest above) within margin.
2. **Segment touching or inside the hull**: separating axis test of the segment against the
   hull. The faces of the Minkowski sum of a segment and a polytope are the hull faces and the
   parallelograms ``segment × edge``; an edge gives a face only when the plane normal to the
   segment crosses the edge's Gauss arc (its two face normals lie on opposite sides of it),
   and then its outward normal is ``±(axis × edge)`` oriented into the arc, with the edge
   itself as the hull's support; so the test is O(F + E) and exact. A face axis is preferred
   to an edge axis within ``BOX_REL_EPS`` × size. A face axis gives a face patch as in 1; an
   edge axis one contact (closest points of the segment and that edge), depth ``radius +``
   overlap.

The deepest contact is exact: ``radius − distance`` apart, ``radius +`` the minimum overlap
(the segment–hull minimum translation distance) otherwise. Where the face patch of a face
axis would leave out the segment's deepest end (it does not lie over the face polygon), the
patch is stretched to that end, whose contact point then lies over the face's plane just
beyond its polygon (``capsule_box`` clips there instead and under-reports the depth).

Features (0..255), stable while the contact keeps its kind and hull feature:

* face patch points (also the closest-point contact of the third case of 1, which stands for
  the dominant face's patch end on its side): ``(2 · face + end) mod 256``, ``end`` = 0 for
  the end toward the capsule's −z end, 1 toward its +z end;
* parallel edge line contacts: ``(2 · (F + edge) + end) mod 256`` (F = face count);
* the edge-axis contact of case 2: ``CAPSULE_CONVEX_CROSS_FEATURE`` (255).

The two contacts of a pair always differ (the same face or edge, different ``end``).

Everything is compiled (``@njit(cache=True)``), float64, no fastmath.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np

from ..compiling import njit
from .capsule import PARALLEL_SIN
from .capsule_box import BOX_REL_EPS, CROSS_AXIS_EPS
from .contact_output import Frame, PairOutput, write_local_contact
from .convex import HullArrays
from .geometry import axpy, clamp, column, dot, midpoint, scaled, segment_closest_parameters, unrotate
from .hull_faces import projects_into_face, segment_over_face
from .segment_patch import Closest, dominant_face_contacts, edge_cross_point, face_patch_ends, write_patch_ends

MAX_CONTACTS = 2

# the hull's edge nearest a segment apart from it: its number, the segment's parameter s [m] and
# the edge's point q (3,) [m] closest to each other, their distance [m], and whether q is an end
NearestEdge = namedtuple("NearestEdge", ["edge", "s", "q", "distance", "at_vertex"])
CAPSULE_CONVEX_CROSS_FEATURE = 255


@njit(cache=True)
def _face_patch(segment, hull, face, s_keep, tol, sink, slot):
    """The face patch of the segment over hull face ``face`` (:func:`.segment_patch.face_patch_ends`;
    ``s_keep``, unless nan, kept inside it; ``sink`` as in :mod:`.segment_patch`). Features
    ``(2 · face + end) mod 256``."""
    origin, direction, half_length, _ = segment
    part = segment_over_face(origin, direction, half_length, hull, face, tol)
    plane = (hull[1][face], hull[2][face])
    return face_patch_ends(segment, part, s_keep, plane, face, tol, sink, slot)


@njit(cache=True)
def capsule_convex(
    frame_a: Frame,
    radius_a: float,
    half_length_a: float,
    frame_b: Frame,
    hull: HullArrays,
    margin: float,
    out: PairOutput,
    slot: int,
) -> int:
    """Capsule A against hull B (static or dynamic): up to 2 contacts from ``slot`` on.

    frame_a = (center_a (3,) [m], rotation_a (3, 3) body → world; segment along its third column);
    radius_a, half_length_a [m]; frame_b = (center_b (3,) [m], rotation_b (3, 3)) and the hull's body-frame
    arrays (module docstring); margin [m]. Returns the number of contacts written (0..2).
    Algorithm and features: module docstring.
    """
    center_a, rotation_a = frame_a
    center_b, rotation_b = frame_b
    vertices, face_normal, face_offset, _, _, edge_vertex, edge_face = hull
    origin = unrotate(rotation_b, axpy(center_a, -1.0, center_b))
    direction = unrotate(rotation_b, column(rotation_a, 2))
    segment = (origin, direction, half_length_a, radius_a)
    frame = frame_b
    sink = (margin, frame, out)  # contacts kept and written through the hull's frame
    face_count = face_offset.shape[0]
    extent = 0.0
    for v in range(vertices.shape[0]):
        extent = max(extent, abs(vertices[v, 0]) + abs(vertices[v, 1]) + abs(vertices[v, 2]))
    size = half_length_a + radius_a + extent
    tol = BOX_REL_EPS * size
    reach = radius_a + margin

    # separating axis test of the segment: faces
    best_face = 0
    best_face_overlap = np.inf
    for f in range(face_count):
        n = face_normal[f]
        overlap = face_offset[f] - dot(n, origin) + half_length_a * abs(dot(n, direction))
        if overlap < -reach:
            return 0  # separated by more than radius + margin
        if overlap < best_face_overlap:
            best_face_overlap = overlap
            best_face = f
    # edges whose Gauss arc the plane normal to the segment crosses
    best_edge = -1
    best_edge_overlap = np.inf
    best_edge_axis = np.zeros(3)
    for e in range(edge_vertex.shape[0]):
        n0 = face_normal[edge_face[e, 0]]
        n1 = face_normal[edge_face[e, 1]]
        c0 = dot(n0, direction)
        c1 = dot(n1, direction)
        if c0 * c1 > 0.0 or (c0 == 0.0 and c1 == 0.0):
            continue
        a = vertices[edge_vertex[e, 0]]
        b = vertices[edge_vertex[e, 1]]
        u0, u1, u2 = b[0] - a[0], b[1] - a[1], b[2] - a[2]
        u_length = np.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
        if u_length == 0.0:
            continue
        u0, u1, u2 = u0 / u_length, u1 / u_length, u2 / u_length
        l0 = direction[1] * u2 - direction[2] * u1
        l1 = direction[2] * u0 - direction[0] * u2
        l2 = direction[0] * u1 - direction[1] * u0
        length = np.sqrt(l0 * l0 + l1 * l1 + l2 * l2)
        if length < CROSS_AXIS_EPS:
            continue
        l0, l1, l2 = l0 / length, l1 / length, l2 / length
        if l0 * (n0[0] + n1[0]) + l1 * (n0[1] + n1[1]) + l2 * (n0[2] + n1[2]) < 0.0:
            l0, l1, l2 = -l0, -l1, -l2  # into the arc: the edge supports the hull along it
        overlap = l0 * (a[0] - origin[0]) + l1 * (a[1] - origin[1]) + l2 * (a[2] - origin[2])
        if overlap < -reach:
            return 0
        if overlap < best_edge_overlap:
            best_edge_overlap = overlap
            best_edge = e
            best_edge_axis[0], best_edge_axis[1], best_edge_axis[2] = l0, l1, l2

    if min(best_face_overlap, best_edge_overlap) < 0.0:
        # apart: the exact distance over (segment ends × face polygons) and (segment × edges)
        ends = 2 if half_length_a > 0.0 else 1
        face_distance = np.inf
        face_s = 0.0
        face_id = -1
        for f in range(face_count):
            n = face_normal[f]
            for end in range(ends):
                s = -half_length_a if end == 0 else half_length_a
                x = axpy(origin, s, direction)
                height = dot(n, x) - face_offset[f]
                if height > 0.0 and height < face_distance:
                    if projects_into_face(x, hull, f):
                        face_distance = height
                        face_s = s
                        face_id = f
        edge_distance = np.inf
        edge_s = 0.0
        edge_id = -1
        edge_at_end = False
        edge_q = np.zeros(3)
        for e in range(edge_vertex.shape[0]):
            a = vertices[edge_vertex[e, 0]]
            b = vertices[edge_vertex[e, 1]]
            middle = midpoint(a, b)
            span = axpy(b, -1.0, a)
            half = 0.5 * np.sqrt(dot(span, span))
            if half == 0.0:
                continue
            unit = scaled(0.5 / half, span)
            s, t = segment_closest_parameters(origin, direction, half_length_a, middle, unit, half)
            p = axpy(origin, s, direction)
            q = axpy(middle, t, unit)
            d = axpy(p, -1.0, q)
            distance = np.sqrt(dot(d, d))
            if distance < edge_distance:
                edge_distance = distance
                edge_s = s
                edge_id = e
                edge_at_end = abs(t) >= half
                edge_q = q
        distance = min(face_distance, edge_distance)
        depth = radius_a - distance
        if depth < -margin:
            return 0
        if distance > tol:
            if face_id >= 0 and face_distance <= edge_distance + tol:
                # the closest point lies inside a face: a face patch
                return _face_patch(segment, hull, face_id, face_s, tol, sink, slot)
            nearest = NearestEdge(edge_id, edge_s, edge_q, edge_distance, edge_at_end)
            return _apart_edge(segment, nearest, hull, tol, sink, slot)

    # touching or overlapping: the separating axis with the least overlap (faces win near ties)
    if best_edge < 0 or best_face_overlap <= best_edge_overlap + tol:
        # the patch is clipped to the face; should that cut off the segment's deepest end
        # (which has the exact depth radius + overlap), the patch is stretched to keep it
        s_keep = np.nan
        slope = dot(face_normal[best_face], direction)
        if slope != 0.0 and half_length_a > 0.0:
            s_deep = -half_length_a if slope > 0.0 else half_length_a
            lo, hi = segment_over_face(origin, direction, half_length_a, hull, best_face, tol)
            if lo > hi or -slope * (s_deep - clamp(s_deep, lo, hi)) > tol:
                s_keep = s_deep
        return _face_patch(segment, hull, best_face, s_keep, tol, sink, slot)
    depth = radius_a + best_edge_overlap
    if depth < -margin:
        return 0
    a = vertices[edge_vertex[best_edge, 0]]
    b = vertices[edge_vertex[best_edge, 1]]
    span = axpy(b, -1.0, a)
    half = 0.5 * np.sqrt(dot(span, span))
    edge_center, edge_direction = midpoint(a, b), scaled(0.5 / half, span)
    point_local = edge_cross_point(segment, (edge_center, edge_direction, half), best_edge_axis)
    write_local_contact(point_local, best_edge_axis, depth, CAPSULE_CONVEX_CROSS_FEATURE, frame, out, slot)
    return 1


@njit(cache=True)
def _apart_edge(segment, nearest, hull, tol, sink, slot):
    """Case 1 of the module docstring when the hull's closest point ``q`` lies on edge ``edge``
    (``at_vertex``: at one of its ends), at ``distance`` [m] from the segment's point at its
    parameter ``s`` (the :data:`NearestEdge` ``nearest``); ``sink`` as in :mod:`.segment_patch`."""
    edge, s, q, distance, at_vertex = nearest
    origin, direction, half_length_a, radius_a = segment
    vertices, face_normal, face_offset, _, _, edge_vertex, _ = hull
    depth = radius_a - distance
    p = axpy(origin, s, direction)
    normal_local = scaled(1.0 / distance, axpy(p, -1.0, q))
    face_count = face_offset.shape[0]
    if not at_vertex:
        a = vertices[edge_vertex[edge, 0]]
        b = vertices[edge_vertex[edge, 1]]
        span = axpy(b, -1.0, a)
        length = np.sqrt(dot(span, span))
        unit = scaled(1.0 / length, span)
        along = dot(unit, direction)
        across = np.sqrt(max(0.0, 1.0 - along * along))
        if across < PARALLEL_SIN and abs(along) > 0.0:
            # parallel to the edge: the part of the segment alongside it
            t0 = (dot(unit, a) - dot(unit, origin)) / along
            t1 = (dot(unit, b) - dot(unit, origin)) / along
            lo = max(-half_length_a, min(t0, t1))
            hi = min(half_length_a, max(t0, t1))
            if hi - lo > tol and lo - tol <= s <= hi + tol:
                # (2 (F + edge)) mod 256 is even: adding the end (0, 1) commutes with the mod
                feature = (2 * (face_count + edge)) & 255
                return write_patch_ends(segment, (lo, hi), s, depth, normal_local, feature, sink, slot)
    # an edge crossed at an angle, or a vertex: the closest point stands for the end of the
    # dominant face's patch on its side; the other end of that patch is kept too
    face = 0
    highest = -np.inf
    for f in range(face_count):
        height = dot(face_normal[f], p) - face_offset[f]
        if height > highest:
            highest = height
            face = f
    part = segment_over_face(origin, direction, half_length_a, hull, face, tol)
    closest = Closest(midpoint(axpy(p, -radius_a, normal_local), q), normal_local, depth, s)
    plane = (face_normal[face], face_offset[face])
    return dominant_face_contacts(segment, part, closest, plane, face, tol, sink, slot)
