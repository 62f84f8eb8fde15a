"""A segment against an axis-aligned box, in the box's frame: the closest point of the segment
(``segment_box_closest``, exact), the part of the segment over a face (``face_interval``) and
the contacts of that part against the face (``face_patch``, through the plane routines of
:mod:`.segment_patch` that capsule–hull shares). Capsule–box (:mod:`contactlab.collision.capsule_box`)
is built on them.

Conventions as in :mod:`contactlab.collision.capsule`: the segment is ``origin + s · direction``
(``direction`` a unit (3,), ``|s| ≤ half_length`` [m]), the box centred at the origin with
``half_extents`` (3,) [m]; contacts are written in world coordinates through the box's frame,
from index ``slot`` on, as the ``sink`` (:data:`.segment_patch.Sink`) says.
"""

import numpy as np

from ..compiling import njit
from .geometry import clamp, unit_axis
from .segment_patch import Segment, Sink, face_patch_ends


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
def face_patch(
    segment: Segment, half_extents: np.ndarray, face: int, s_keep: float, tol: float, sink: Sink, slot: int
) -> int:
    """Contacts of the segment (``segment``, box frame, :data:`.segment_patch.Segment`) against
    box face ``face`` = ``2 · k + (1 if on the box's +k side else 0)`` (k = box axis), the plane
    ``x[k] = ±h[k]``: the two ends of the part of the segment over the face (``s_keep``, unless
    nan, is kept inside that part), each with its own depth; a part shorter than ``tol`` gives 1
    contact at its deeper end (:func:`.segment_patch.face_patch_ends`). Features ``2 · face +
    end``, ``end`` 0 at the low ``s`` end, 1 at the high one (a single point: the side of the
    capsule centre it is on). ``sink`` as in :mod:`.segment_patch`.
    """
    origin, direction, half_length, _ = segment
    face_axis = face // 2
    face_sign = 1.0 if face & 1 else -1.0
    part = face_interval(origin, direction, half_length, half_extents, face_axis, tol)
    plane = (unit_axis(face_axis, face_sign), half_extents[face_axis])
    return face_patch_ends(segment, part, s_keep, plane, face, tol, sink, slot)
