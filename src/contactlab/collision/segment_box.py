"""A segment against an axis-aligned box, in the box's frame: the closest point of the segment
(``segment_box_closest``, exact), the part of the segment over a face (``face_interval``), the
contacts of that part against the face (``face_contact``, ``face_patch``) and of the part alongside
an edge (``write_patch_ends``). Capsule–box (:mod:`contactlab.collision.capsule_box`) is built on
them, and capsule–hull (:mod:`contactlab.collision.capsule_convex`) shares ``write_patch_ends``.

Conventions as in :mod:`contactlab.collision.capsule`: the segment is ``origin + s · direction``
(``direction`` a unit (3,), ``|s| ≤ half_length`` [m]), the box centred at the origin with
``half_extents`` (3,) [m]; contacts are written in world coordinates through the box's
``box_center`` (3,) and ``box_rotation`` (3, 3), from index ``slot`` on into ``out_point``
(N, 3), ``out_normal`` (N, 3), ``out_depth`` (N,), ``out_feature`` (N,) int64.
"""

import numpy as np
from numba import njit

from .contact_output import write_contact, write_local_contact
from .geometry import axpy, clamp, rotate, unit_axis


@njit(cache=True)
def _box_distance2(origin, direction, s, half_extents):
    """Squared distance [m²] from the point ``origin + s · direction`` (box frame) to the box."""
    total = 0.0
    for k in range(3):
        excess = abs(origin[k] + s * direction[k]) - half_extents[k]
        if excess > 0.0:
            total += excess * excess
    return total


@njit(cache=True)
def segment_box_closest(
    origin: np.ndarray, direction: np.ndarray, half_length: float, half_extents: np.ndarray
) -> tuple[float, float]:
    """Parameter of the segment point closest to an axis-aligned box centred at the origin.

    origin, direction: (3,) the segment ``origin + s · direction``, ``|s| ≤ half_length``, in the
    box's frame (direction unit); half_extents: (3,). Returns ``(s, distance²)``.
    The squared distance is convex in ``s`` and quadratic between the parameters where the
    segment crosses a slab plane ``x_k = ±h_k`` (at most 6): each piece is minimized in
    closed form and clamped to the piece, so the result is exact, with no iteration.
    """
    breaks = np.empty(8)
    breaks[0] = -half_length
    count = 1
    for k in range(3):
        if direction[k] != 0.0:
            for sign in (-1.0, 1.0):
                s = (sign * half_extents[k] - origin[k]) / direction[k]
                if -half_length < s < half_length:
                    breaks[count] = s
                    count += 1
    breaks[count] = half_length
    count += 1
    for i in range(1, count):  # insertion sort (at most 8 values)
        value = breaks[i]
        j = i - 1
        while j >= 0 and breaks[j] > value:
            breaks[j + 1] = breaks[j]
            j -= 1
        breaks[j + 1] = value
    best_s = -half_length
    best = _box_distance2(origin, direction, best_s, half_extents)
    for i in range(count - 1):
        s0 = breaks[i]
        s1 = breaks[i + 1]
        if not s1 > s0:
            continue
        middle = 0.5 * (s0 + s1)
        numerator = 0.0
        denominator = 0.0
        for k in range(3):
            x = origin[k] + middle * direction[k]
            if x > half_extents[k]:
                numerator += (origin[k] - half_extents[k]) * direction[k]
            elif x < -half_extents[k]:
                numerator += (origin[k] + half_extents[k]) * direction[k]
            else:
                continue
            denominator += direction[k] * direction[k]
        s = s1
        if denominator > 0.0:
            s = clamp(-numerator / denominator, s0, s1)
        value = _box_distance2(origin, direction, s, half_extents)
        if value < best:
            best = value
            best_s = s
    value = _box_distance2(origin, direction, half_length, half_extents)
    if value < best:
        best = value
        best_s = half_length
    return best_s, best


@njit(cache=True)
def face_interval(
    origin: np.ndarray, direction: np.ndarray, half_length: float, half_extents: np.ndarray, face_axis: int, tol: float
) -> tuple[float, float]:
    """Parameters ``(lo, hi)`` of the part of the segment over the face (the box's side slabs
    ``|x_j| ≤ h_j``, ``j ≠ face_axis``, widened by ``tol``); ``lo > hi`` when there is none."""
    lo = -half_length
    hi = half_length
    for j in range(3):
        if j == face_axis:
            continue
        if direction[j] == 0.0:
            if abs(origin[j]) > half_extents[j] + tol:
                return 1.0, -1.0
            continue
        t0 = (-half_extents[j] - origin[j]) / direction[j]
        t1 = (half_extents[j] - origin[j]) / direction[j]
        lo = max(lo, min(t0, t1))
        hi = min(hi, max(t0, t1))
    return lo, hi


@njit(cache=True)
def face_contact(
    origin: np.ndarray,
    direction: np.ndarray,
    s: float,
    radius: float,
    half_extents: np.ndarray,
    face_axis: int,
    face_sign: float,
    feature: int,
    margin: float,
    box_center: np.ndarray,
    box_rotation: np.ndarray,
    out_point: np.ndarray,
    out_normal: np.ndarray,
    out_depth: np.ndarray,
    out_feature: np.ndarray,
    slot: int,
) -> int:
    """One contact of the segment point ``s`` (box frame) against the face ``x[face_axis] =
    face_sign · h``: normal the face's, depth ``radius − height above the face`` (exact over the
    face: the distance to a face is linear along the segment). Returns 1 if written (depth ≥
    −margin), else 0."""
    x = axpy(origin, s, direction)
    height = face_sign * x[face_axis] - half_extents[face_axis]
    depth = radius - height
    if depth < -margin:
        return 0
    normal_local = unit_axis(face_axis, face_sign)
    point = axpy(box_center, 1.0, rotate(box_rotation, axpy(x, -0.5 * (radius + height), normal_local)))
    write_contact(
        out_point, out_normal, out_depth, out_feature, slot, point, rotate(box_rotation, normal_local), depth, feature
    )
    return 1


@njit(cache=True)
def face_patch(
    origin: np.ndarray,
    direction: np.ndarray,
    half_length: float,
    radius: float,
    half_extents: np.ndarray,
    face_axis: int,
    face_sign: float,
    s_keep: float,
    margin: float,
    tol: float,
    box_center: np.ndarray,
    box_rotation: np.ndarray,
    out_point: np.ndarray,
    out_normal: np.ndarray,
    out_depth: np.ndarray,
    out_feature: np.ndarray,
    slot: int,
) -> int:
    """Contacts of the segment (box frame) against one box face: the two ends of the part of
    the segment over the face (``s_keep``, unless nan, is kept inside that part), each with its
    own depth; a part shorter than ``tol`` gives 1 contact at its deeper end.
    Features ``2 · face + end``, ``face = 2 · face_axis + (face_sign > 0)``, ``end`` 0 at the
    low ``s`` end, 1 at the high one (a single point: the side of the capsule centre it is on).
    """
    lo, hi = face_interval(origin, direction, half_length, half_extents, face_axis, tol)
    if s_keep == s_keep:  # not nan
        lo = min(lo, s_keep)
        hi = max(hi, s_keep)
    if lo > hi:  # grazing a side of the face within round-off
        lo = clamp(0.5 * (lo + hi), -half_length, half_length)
        hi = lo
    face = 2 * face_axis + (1 if face_sign > 0.0 else 0)
    if hi - lo > tol:
        count = face_contact(
            origin,
            direction,
            lo,
            radius,
            half_extents,
            face_axis,
            face_sign,
            2 * face,
            margin,
            box_center,
            box_rotation,
            out_point,
            out_normal,
            out_depth,
            out_feature,
            slot,
        )
        count += face_contact(
            origin,
            direction,
            hi,
            radius,
            half_extents,
            face_axis,
            face_sign,
            2 * face + 1,
            margin,
            box_center,
            box_rotation,
            out_point,
            out_normal,
            out_depth,
            out_feature,
            slot + count,
        )
        return count
    # one point: the deeper end
    if face_sign * direction[face_axis] * (hi - lo) < 0.0:
        lo = hi
    end = 1 if lo > 0.0 else 0
    return face_contact(
        origin,
        direction,
        lo,
        radius,
        half_extents,
        face_axis,
        face_sign,
        2 * face + end,
        margin,
        box_center,
        box_rotation,
        out_point,
        out_normal,
        out_depth,
        out_feature,
        slot,
    )


@njit(cache=True)
def write_patch_ends(
    origin: np.ndarray,
    direction: np.ndarray,
    lo: float,
    hi: float,
    s: float,
    depth: float,
    slope: float,
    radius_a: float,
    normal_local: np.ndarray,
    margin: float,
    feature: int,
    center: np.ndarray,
    rotation: np.ndarray,
    out_point: np.ndarray,
    out_normal: np.ndarray,
    out_depth: np.ndarray,
    out_feature: np.ndarray,
    slot: int,
) -> int:
    """The two ends s = lo, hi [m] of the part of capsule A's segment ``origin + s · direction``
    (in the frame of B, at ``center`` (3,) [m] with ``rotation`` (3, 3)) that lies alongside an
    edge of B, as contacts with normal ``normal_local`` (3,): depth ``depth − slope · (s_end −
    s)`` [m] from the depth at the closest point s, ends shallower than −margin left out;
    features ``feature`` and ``feature + 1``. Shared by capsule–box and capsule–hull.
    Returns how many it wrote from ``slot`` on."""
    count = 0
    for end in range(2):
        s_end = lo if end == 0 else hi
        depth_end = depth - slope * (s_end - s)
        if depth_end >= -margin:
            surface_a = axpy(axpy(origin, s_end, direction), -radius_a, normal_local)
            write_local_contact(
                axpy(surface_a, 0.5 * depth_end, normal_local),
                normal_local,
                depth_end,
                feature + end,
                center,
                rotation,
                out_point,
                out_normal,
                out_depth,
                out_feature,
                slot + count,
            )
            count += 1
    return count
