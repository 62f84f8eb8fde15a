"""Capsule–box contacts: the segment outside the box (closest points, face patches, edge lines)
or touching and inside it (a separating axis test), up to 2 contacts a pair.

Conventions and exactness as in :mod:`contactlab.collision.capsule` (whose module docstring
says how capsule–box is exact); the segment–box geometry is
:mod:`contactlab.collision.segment_box`.
"""

import numpy as np

from ..compiling import njit
from .capsule import PARALLEL_SIN, Capsule
from .contact_output import PairOutput, write_local_contact
from .geometry import axpy, clamp, column, dot, midpoint, norm, scaled, unit_axis, unrotate
from .primitive_pairs import Box
from .segment_box import face_interval, face_patch, segment_box_closest
from .segment_patch import Closest, dominant_face_contacts, edge_cross_point, write_patch_ends

BOX_REL_EPS = 1e-9  # capsule–box tolerances, × the pair's size (sum of half lengths, radius, half extents)
CROSS_AXIS_EPS = 1e-8  # |axis × box edge| below this: no SAT axis of its own (a face axis covers it)
CAPSULE_BOX_EDGE_FEATURE = 12  # capsule–box contacts alongside a box edge: 12 + 2 · edge + end (12..35)
CAPSULE_BOX_CROSS_FEATURE = 36  # the capsule–box contact of a segment inside the box, across an edge


@njit(cache=True)
def capsule_box(capsule: Capsule, box: Box, margin: float, out: PairOutput, slot: int) -> int:
    """Capsule A against box B (static or dynamic): up to 2 contacts.

    capsule = (frame, radius, half_length) (:data:`.capsule.Capsule`); box = (frame, half_extents)
    (:data:`.primitive_pairs.Box`); margin [m]. Work is done in the box's frame.

    1. **Segment outside the box** (distance > ``BOX_REL_EPS`` × size): the closest point
       ``p`` of the segment (:func:`segment_box_closest`, exact) and its box point ``q``
       (clamping); the deepest contact is ``p``–``q``: normal ``(p − q)/|p − q|``, depth
       ``radius − |p − q|``. Then by the box feature ``q`` lies on:

       * a **face**: a *face patch*: the segment is clipped to the face's side slabs and both
         ends of the clipped part become contacts with the face normal and their own exact
         depth (the closest point is one of them) — a capsule lying flat on a face gets 2
         contacts of equal depth, one overhanging an edge its end and the point over the edge,
         one standing on its end 1 (the far end is beyond the margin);
       * an **edge the segment is parallel to** (``|sin| < PARALLEL_SIN``): 2 contacts at the
         ends of the part of the segment alongside the edge, with the normal of the closest
         points and the depth along it (as for parallel capsules);
       * otherwise (an edge crossed at an angle, a corner): the closest-point contact, plus the
         far end of the *dominant face*'s patch (the face whose plane ``p`` is farthest above)
         if it is within the margin — so a capsule over a box edge keeps its end on the face
         while it tips over the edge, with the same features.
    2. **Segment touching or inside the box**: separating axis test over the 3 face normals and
       the 3 axes ``axis × edge`` (a face axis wins ties within ``BOX_REL_EPS`` × size). The
       depth is ``radius +`` the smallest overlap. A face axis gives a face patch as in 1 (the
       segment pushed out through that face, the clipped ends with their depths below it); an
       ``axis × edge`` axis gives 1 contact between the segment and the box edge that supports
       the box along the normal.

    Features:

    * face patch points: ``2 · face + end`` (0..11), ``face = 2 · k + (1 if the face is on the
      box's +k side else 0)`` (k = box axis), ``end`` = 0 for the end of the clipped part toward
      the capsule's −z end, 1 toward its +z end. The closest-point contact of the third case
      of 1 takes the feature of the dominant face's patch end it stands for (the end on its
      side), so contacts keep their numbers while a capsule slides over a face, overhangs an
      edge and tips over it;
    * edge line contacts: ``12 + 2 · edge + end`` (12..35), ``edge = 4 · m + 2 · (i side) +
      (j side)`` for the edge along box axis m whose other two coordinates (i < j) are on the
      + (1) or − (0) side;
    * the ``axis × edge`` contact of case 2: ``CAPSULE_BOX_CROSS_FEATURE`` (36).

    Where two faces are exactly equally far (a capsule end right over a box edge, along the
    diagonal) the dominant face, hence the feature, follows round-off.
    """
    frame_a, radius_a, half_length_a = capsule
    box_frame, half_extents = box
    center_a, rotation_a = frame_a
    box_center, box_rotation = box_frame
    origin = unrotate(box_rotation, axpy(center_a, -1.0, box_center))
    direction = unrotate(box_rotation, column(rotation_a, 2))
    segment = (origin, direction, half_length_a, radius_a)
    size = half_length_a + radius_a + half_extents[0] + half_extents[1] + half_extents[2]
    tol = BOX_REL_EPS * size
    s, distance2 = segment_box_closest(origin, direction, half_length_a, half_extents)
    distance = np.sqrt(distance2)
    depth = radius_a - distance
    if depth < -margin:
        return 0
    sink = (margin, box_frame, out)  # contacts kept and written through the box's frame
    if distance > tol:
        return _segment_outside(segment, s, distance, half_extents, tol, sink, slot)
    return _segment_inside(segment, half_extents, tol, sink, slot)


@njit(cache=True)
def _segment_outside(segment, s, distance, half_extents, tol, sink, slot):
    """Case 1 of :func:`capsule_box` (box frame): the segment is outside the box; ``s`` is its
    closest point's parameter, ``distance`` > 0 the segment–box distance; ``sink`` as in
    :mod:`.segment_patch`."""
    origin, direction, half_length_a, radius_a = segment
    depth = radius_a - distance
    p = axpy(origin, s, direction)
    q = np.empty(3)
    outside = 0
    face_axis = np.int64(0)  # np.int64, not 0: callees are compiled once, not also for Literal[int](0)
    largest = -1e300
    for k in range(3):
        q[k] = clamp(p[k], -half_extents[k], half_extents[k])
        excess = abs(p[k]) - half_extents[k]
        if excess > tol:
            outside += 1
        if excess > largest:
            largest = excess
            face_axis = k
    face_sign = 1.0 if p[face_axis] > 0.0 else -1.0
    face = 2 * face_axis + (1 if face_sign > 0.0 else 0)
    if outside <= 1:
        return face_patch(segment, half_extents, face, s, tol, sink, slot)
    normal_local = scaled(1.0 / distance, axpy(p, -1.0, q))
    point_local = midpoint(axpy(p, -radius_a, normal_local), q)

    if outside == 2:
        edge_axis = np.int64(0)
        for k in range(3):
            if abs(p[k]) - half_extents[k] <= tol:
                edge_axis = k
        across = np.sqrt(max(0.0, 1.0 - direction[edge_axis] * direction[edge_axis]))
        if across < PARALLEL_SIN and abs(direction[edge_axis]) > 0.0:
            # parallel to the edge: the part of the segment alongside it
            t0 = (-half_extents[edge_axis] - origin[edge_axis]) / direction[edge_axis]
            t1 = (half_extents[edge_axis] - origin[edge_axis]) / direction[edge_axis]
            lo = max(-half_length_a, min(t0, t1))
            hi = min(half_length_a, max(t0, t1))
            if hi - lo > tol and lo - tol <= s <= hi + tol:
                i = (edge_axis + 1) % 3
                j = (edge_axis + 2) % 3
                if i > j:
                    i, j = j, i
                edge = 4 * edge_axis + 2 * (1 if p[i] > 0.0 else 0) + (1 if p[j] > 0.0 else 0)
                feature = CAPSULE_BOX_EDGE_FEATURE + 2 * edge
                return write_patch_ends(segment, (lo, hi), s, depth, normal_local, feature, sink, slot)

    # an edge crossed at an angle, or a corner: the closest point stands for the end of the
    # dominant face's patch on its side; the other end of that patch is kept too
    part = face_interval(origin, direction, half_length_a, half_extents, face_axis, tol)
    plane = (unit_axis(face_axis, face_sign), half_extents[face_axis])
    closest = Closest(point_local, normal_local, depth, s)
    return dominant_face_contacts(segment, part, closest, plane, face, tol, sink, slot)


@njit(cache=True)
def _segment_inside(segment, half_extents, tol, sink, slot):
    """Case 2 of :func:`capsule_box` (box frame): the segment touches or enters the box."""
    origin, direction, half_length_a, radius_a = segment
    margin, frame, out = sink
    best_face = np.int64(0)
    best_face_overlap = 1e300
    for k in range(3):
        overlap = half_length_a * abs(direction[k]) + half_extents[k] - abs(origin[k])
        if overlap < best_face_overlap:
            best_face_overlap = overlap
            best_face = k
    best_edge = np.int64(-1)
    best_edge_overlap = 1e300
    best_edge_axis = np.zeros(3)
    for k in range(3):
        axis = np.zeros(3)
        axis[(k + 1) % 3] = direction[(k + 2) % 3]  # direction × e_k
        axis[(k + 2) % 3] = -direction[(k + 1) % 3]
        length = norm(axis)
        if length < CROSS_AXIS_EPS:
            continue
        axis = scaled(1.0 / length, axis)
        # the segment is perpendicular to this axis: its projection is one number
        overlap = (
            half_extents[0] * abs(axis[0])
            + half_extents[1] * abs(axis[1])
            + half_extents[2] * abs(axis[2])
            - abs(dot(origin, axis))
        )
        if overlap < best_edge_overlap:
            best_edge_overlap = overlap
            best_edge = k
            best_edge_axis = axis
    if best_edge < 0 or best_face_overlap <= best_edge_overlap + tol:
        face = 2 * best_face + (1 if origin[best_face] >= 0.0 else 0)
        return face_patch(segment, half_extents, face, np.nan, tol, sink, slot)

    depth = radius_a + best_edge_overlap
    if depth < -margin:
        return 0
    normal_local = scaled(1.0 if dot(origin, best_edge_axis) >= 0.0 else -1.0, best_edge_axis)
    # the box edge parallel to e_k that supports the box along the normal
    edge_center = np.zeros(3)
    for j in range(3):
        if j != best_edge:
            edge_center[j] = half_extents[j] if normal_local[j] >= 0.0 else -half_extents[j]
    edge_direction = unit_axis(best_edge, 1.0)
    point_local = edge_cross_point(segment, (edge_center, edge_direction, half_extents[best_edge]), normal_local)
    write_local_contact(point_local, normal_local, depth, np.int64(CAPSULE_BOX_CROSS_FEATURE), frame, out, slot)
    return 1
