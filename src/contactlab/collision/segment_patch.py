"""A capsule's segment against a face or an edge of the other shape (a box or a hull), in that
shape's frame: the contacts of the capsule–box (:mod:`.capsule_box`, :mod:`.segment_box`) and
capsule–hull (:mod:`.capsule_convex`) routines, which find the part of the segment over a face
or alongside an edge each in their own way and write its ends here.

Three bundles keep the argument lists short:

* ``segment`` (:data:`Segment`): ``(origin, direction, half_length, radius)``, capsule A in B's
  frame: its segment ``origin + s · direction`` (origin (3,) [m], ``direction`` a unit (3,),
  ``|s| ≤ half_length`` [m]) and its radius [m];
* ``part`` (:data:`Part`): ``(lo, hi)`` [m], the part ``lo ≤ s ≤ hi`` of that segment over a
  face or alongside an edge (``lo > hi``: none);
* ``sink`` (:data:`Sink`): ``(margin, frame, out)``, which contacts are written and where: those
  with depth ≥ −margin [m], through B's ``frame`` (:data:`.contact_output.Frame`: centre (3,)
  [m], rotation (3, 3) body → world; None: given in world coordinates already) into ``out``
  (:data:`.contact_output.PairOutput`), from index ``slot`` on.

A face is its plane ``normal · x = offset`` (:data:`Plane`: unit outward ``normal`` (3,), ``offset`` [m]).
An edge is ``(center, direction, half_length)`` (:data:`Edge`), in B's frame.
Compiled (``@njit(cache=True)``), float64, no fastmath.
"""

from collections import namedtuple

import numpy as np

from ..compiling import njit
from .contact_output import Frame, PairOutput, write_local_contact
from .geometry import axpy, clamp, dot, midpoint, segment_closest_parameters

Segment = tuple[np.ndarray, np.ndarray, float, float]  # (origin, direction, half_length, radius) in B's frame
Plane = tuple[np.ndarray, float]  # (unit outward normal (3,), offset [m]) of a face of B, in B's frame
Edge = tuple[np.ndarray, np.ndarray, float]  # (centre (3,) [m], unit direction (3,), half length [m]) of an edge of B
Part = tuple[float, float]  # (lo, hi) [m]: the part lo ≤ s ≤ hi of the segment
Sink = tuple[float, Frame | None, PairOutput]  # (margin [m], B's frame or None, out): contacts kept and where
# a segment's closest contact: point (3,) [m], unit normal (3,), depth [m], in B's frame, and
# the segment's parameter s [m] there
Closest = namedtuple("Closest", ["point", "normal", "depth", "s"])


@njit(cache=True)
def plane_contact(segment: Segment, s: float, plane: Plane, feature: int, sink: Sink, slot: int) -> int:
    """One contact of the segment point ``s`` [m] against the face ``plane`` = (normal, offset):
    normal the face's, depth ``radius − height above the plane`` [m] (exact over the face: the
    distance to a plane is linear along the segment), the point midway between the capsule's
    surface and the plane. Returns 1 if written (depth ≥ −margin), else 0."""
    origin, direction, _, radius = segment
    margin, frame, out = sink
    normal, offset = plane
    x = axpy(origin, s, direction)
    height = dot(normal, x) - offset
    depth = radius - height
    if depth < -margin:
        return 0
    write_local_contact(axpy(x, -0.5 * (radius + height), normal), normal, depth, feature, frame, out, slot)
    return 1


@njit(cache=True)
def face_patch_ends(
    segment: Segment, part: Part, s_keep: float, plane: Plane, face: int, tol: float, sink: Sink, slot: int
) -> int:
    """The contacts of a *face patch*: the two ends of the ``part`` ``(lo, hi)`` [m] of the
    segment over face number ``face`` (its ``plane``), each with its own depth
    (:func:`plane_contact`); ``s_keep`` [m], unless nan, is kept inside the part; a part shorter
    than ``tol`` [m] (or none, ``lo > hi``: grazing a side of the face within round-off) gives 1
    contact at its deeper end. Features ``(2 · face + end) mod 256``, ``end`` 0 at the low ``s``
    end, 1 at the high one (a single point: the side of the capsule centre it is on). Returns
    how many it wrote from ``slot`` on."""
    lo, hi = part
    direction, half_length = segment[1], segment[2]
    if s_keep == s_keep:  # not nan
        lo = min(lo, s_keep)
        hi = max(hi, s_keep)
    if lo > hi:  # grazing a side of the face within round-off
        lo = clamp(0.5 * (lo + hi), -half_length, half_length)
        hi = lo
    if hi - lo > tol:
        count = 0
        for end in range(2):
            s_end = lo if end == 0 else hi
            feature = (2 * face + end) & 255
            count += plane_contact(segment, s_end, plane, feature, sink, slot + count)
        return count
    # one point: the deeper end
    if dot(plane[0], direction) * (hi - lo) < 0.0:
        lo = hi
    end = 1 if lo > 0.0 else 0
    return plane_contact(segment, lo, plane, (2 * face + end) & 255, sink, slot)


@njit(cache=True)
def dominant_face_contacts(
    segment: Segment, part: Part, closest: Closest, plane: Plane, face: int, tol: float, sink: Sink, slot: int
) -> int:
    """The closest-point contact of a segment crossing an edge at an angle or passing a corner
    (``closest``, :data:`Closest`, in B's frame, at the segment's closest parameter ``s`` [m]),
    standing for the end on its side of the ``part`` ``(lo, hi)`` [m] of the segment over the
    *dominant face* (number ``face``, its ``plane``), and that part's other end
    (:func:`plane_contact`) when it is longer than ``tol`` and apart from ``s``. Features as
    :func:`face_patch_ends` gives them, so contacts keep their numbers while a capsule slides
    over a face and tips over its edge. Returns how many it wrote from ``slot`` on."""
    point_local, normal_local, depth, s = closest
    lo, hi = part
    _, frame, out = sink
    if lo <= hi:
        end = 1 if s > 0.5 * (lo + hi) else 0
    else:
        end = 1 if s > 0.0 else 0
    write_local_contact(point_local, normal_local, depth, (2 * face + end) & 255, frame, out, slot)
    count = 1
    if hi - lo > tol:
        other = lo if end == 1 else hi
        if abs(other - s) > tol:
            feature = (2 * face + 1 - end) & 255
            count += plane_contact(segment, other, plane, feature, sink, slot + count)
    return count


@njit(cache=True)
def write_patch_ends(
    segment: Segment, part: Part, s: float, depth: float, normal_local: np.ndarray, feature: int, sink: Sink, slot: int
) -> int:
    """The two ends s = lo, hi [m] of the ``part`` of capsule A's segment that lies alongside an
    edge of B, as contacts with normal ``normal_local`` (3,): depth ``depth − slope · (s_end − s)``
    [m] from the depth at the closest point s, ``slope = normal_local · direction`` (the depth
    measured along that normal), ends shallower than −margin left out; features ``feature`` and
    ``feature + 1``. Returns how many it wrote from ``slot`` on. A sink's frame None: segment and
    normal are in world coordinates, and so written (the parallel patch of
    :func:`.capsule.capsule_capsule`)."""
    origin, direction, _, radius_a = segment
    lo, hi = part
    margin, frame, out = sink
    slope = dot(normal_local, direction)
    count = 0
    for end in range(2):
        s_end = lo if end == 0 else hi
        depth_end = depth - slope * (s_end - s)
        if depth_end >= -margin:
            surface_a = axpy(axpy(origin, s_end, direction), -radius_a, normal_local)
            point_local = axpy(surface_a, 0.5 * depth_end, normal_local)
            write_local_contact(point_local, normal_local, depth_end, feature + end, frame, out, slot + count)
            count += 1
    return count


@njit(cache=True)
def edge_cross_point(segment: Segment, edge: Edge, normal_local: np.ndarray) -> np.ndarray:
    """Where a segment crossing an edge of B touches it (the separating axis ``normal_local``
    (3,) is segment × edge), in B's frame (3,) [m]: midway between the closest points of the
    capsule's surface and the edge ``edge_center + t · edge_direction`` (3,), ``|t| ≤
    edge_half`` [m] (:data:`Edge`). The caller writes the one contact there
    (``write_local_contact``, its depth the overlap on that axis)."""
    origin, direction, half_length, radius = segment
    edge_center, edge_direction, edge_half = edge
    s, t = segment_closest_parameters(origin, direction, half_length, edge_center, edge_direction, edge_half)
    p = axpy(origin, s, direction)
    q = axpy(edge_center, t, edge_direction)
    return midpoint(axpy(p, -radius, normal_local), q)
