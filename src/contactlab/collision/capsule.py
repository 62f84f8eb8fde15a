"""Capsule contacts: capsule–plane, sphere–capsule and capsule–capsule here; capsule–box in
:mod:`contactlab.collision.capsule_box`, on the segment–box geometry of
:mod:`contactlab.collision.segment_box`.

A capsule is the set of points within ``radius`` of a segment: the segment runs along the
capsule's BODY z axis (the third column of its body → world rotation matrix), from
``center − half_length · axis`` (the "−z end") to ``center + half_length · axis`` (the "+z
end"). A point on the segment is written ``center + s · axis`` with ``s ∈ [−half_length,
half_length]``; ``half_length = 0`` is a sphere and is handled everywhere.

Conventions as in :mod:`contactlab.collision.narrow_phase`: shape A is the first argument, the
unit normal points from B into A, ``depth`` > 0 when overlapping, contacts are kept down to
``depth = −margin`` (speculative contacts), each ``point`` lies midway between the two
surfaces, and every function writes its contacts from index ``slot`` on into ``out`` = (point
(N, 3), normal (N, 3), depth (N,), feature (N,) int64) (:data:`.contact_output.PairOutput`) and
returns how many it wrote (at most 2). A capsule is passed as one argument, :data:`Capsule`,
a sphere as :data:`.primitive_pairs.Sphere`. ``feature`` (0..255) names the contact within its pair so that it
keeps its number from step to step while it persists; each function documents its encoding.

Exactness
---------
The deepest contact of a pair has the exact penetration depth (= radius sum − distance for
separated pairs, the minimum translation distance for overlapping ones), up to round-off:

* capsule–plane: the signed distance is linear along the segment, so its extreme is an end;
* sphere–capsule, capsule–capsule: a capsule is a segment inflated by its radius, so the
  depth is ``r_A + r_B − distance(segment_A, segment_B)``, also when the segments cross
  (two crossing segments are separated by an arbitrarily small move along their common
  normal);
* capsule–box: ``radius − distance(segment, box)`` while the segment stays outside the box
  (the convex, piecewise quadratic squared distance along the segment is minimized exactly
  piece by piece); ``radius +`` the segment–box minimum translation distance once the segment
  enters the box, by the separating axis test over the 3 box face normals and the 3
  products ``axis × box edge`` (the face normals of the Minkowski difference of a segment and
  a box); there a face axis is preferred to an edge axis whose overlap is smaller by less
  than ``BOX_REL_EPS`` × the pair's size, which bounds the error.

The other contact of a 2-point contact (a line or a face patch) is exact where its depth is
the distance to a face (capsule–plane, capsule on a box face); along a parallel capsule or box
edge it is measured along the deepest contact's normal and may exceed the true local depth by
at most ``PARALLEL_SIN`` × the length of the contact line.

Everything is compiled (``@njit(cache=True)``), float64, without fastmath, and allocates only
small temporary arrays.
"""

import numpy as np

from ..compiling import njit
from .contact_output import Frame, PairOutput, write_contact
from .geometry import axpy, clamp, column, cross, dot, midpoint, norm, scaled, segment_closest_parameters, sphere_gap
from .primitive_pairs import Sphere
from .segment_patch import write_patch_ends

# (frame: centre (3,) [m], rotation (3, 3) body → world, the segment along its third column; radius, half length [m])
Capsule = tuple[Frame, float, float]

MAX_CONTACTS = 2  # contacts written per capsule pair, at most
PARALLEL_SIN = 1e-3  # capsule axes with |sin angle| below this are "parallel" (2-point contact)
OVERLAP_REL = 1e-6  # a parallel overlap shorter than this × (sum of half lengths and radii) is a point
NORMAL_EPS = 1e-12  # distances [m] below this give no direction; a fallback normal is used

CAPSULE_CAPSULE_SINGLE_FEATURE = 0


# ---------------------------------------------------------------------------------------------
# capsule – plane
# ---------------------------------------------------------------------------------------------


@njit(cache=True)
def capsule_plane(capsule: Capsule, plane: np.ndarray, margin: float, out: PairOutput, slot: int) -> int:
    """Capsule A against the plane B = (n, offset) (solid side n·x < offset; n unit).

    capsule = (frame, radius, half_length) (:data:`Capsule`; the segment along the frame's third
    column); plane: (4,) (n_x, n_y, n_z, offset [m]); margin [m].
    The signed distance to the plane is linear along the segment, so one contact per segment
    end within the margin is exact and a capsule lying flat gets 2 contacts of equal depth
    (it does not rock); the normal is the plane's.

    Features: 0 = the −z end (``center − half_length · axis``), 1 = the +z end. A capsule of
    zero half length has only the end 0.
    """
    frame, radius, half_length = capsule
    center, rotation = frame
    normal = plane[:3]
    axis = column(rotation, 2)
    count = 0
    ends = 2 if half_length > 0.0 else 1
    for end in range(ends):
        s = -half_length if end == 0 else half_length
        x = axpy(center, s, axis)
        distance = x[0] * normal[0] + x[1] * normal[1] + x[2] * normal[2] - plane[3]
        depth = radius - distance
        if depth >= -margin:
            point = axpy(x, -0.5 * (radius + distance), normal)
            write_contact(out, slot + count, point, normal, depth, end)
            count += 1
    return count


# ---------------------------------------------------------------------------------------------
# sphere – capsule
# ---------------------------------------------------------------------------------------------


@njit(cache=True)
def sphere_capsule(sphere: Sphere, capsule: Capsule, margin: float, out: PairOutput, slot: int) -> int:
    """Sphere (or particle: a sphere of radius ≥ 0) A against capsule B: at most 1 contact.

    sphere = (center_a (3,) [m], radius_a [m]); capsule = (frame_b, radius_b, half_length_b)
    (:data:`Capsule`); margin [m]. The sphere centre's closest point on B's segment
    makes this a sphere–sphere contact. A centre on the segment (no direction) is pushed out
    along B's body x axis, perpendicular to the segment.

    Features: 0 (the one contact; it keeps its number as it slides from the side to a cap).
    """
    center_a, radius_a = sphere
    frame_b, radius_b, half_length_b = capsule
    center_b, rotation_b = frame_b
    axis = column(rotation_b, 2)
    s = clamp(dot(axpy(center_a, -1.0, center_b), axis), -half_length_b, half_length_b)
    closest = axpy(center_b, s, axis)
    d, distance, depth = sphere_gap(center_a, closest, radius_a + radius_b)
    if depth < -margin:
        return 0
    if distance > NORMAL_EPS:
        normal = scaled(1.0 / distance, d)
    else:
        normal = column(rotation_b, 0)
    point = midpoint(axpy(center_a, -radius_a, normal), axpy(closest, radius_b, normal))
    write_contact(out, slot, point, normal, depth, np.int64(0))
    return 1


# ---------------------------------------------------------------------------------------------
# capsule – capsule
# ---------------------------------------------------------------------------------------------


@njit(cache=True)
def capsule_capsule(capsule_a: Capsule, capsule_b: Capsule, margin: float, out: PairOutput, slot: int) -> int:
    """Capsule A against capsule B: 1 contact, or 2 when the axes are (nearly) parallel.

    capsule_* = (frame_*, radius_*, half_*) (:data:`Capsule`: segment along the frame's third
    column, half_* its half length [m]); margin [m].

    The closest points ``p_A``, ``p_B`` of the two segments (:func:`segment_closest_parameters`)
    give the normal ``n = (p_A − p_B)/|p_A − p_B|`` and the depth ``r_A + r_B − |p_A − p_B|``.
    Crossing segments (distance 0) use their common normal ``a × b``, oriented from B's centre
    to A's; collinear overlapping ones a direction perpendicular to A's axis.

    When ``|sin(angle between the axes)| < PARALLEL_SIN`` and B's projection on A's axis
    overlaps A over a length of at least ``OVERLAP_REL`` × the pair's size, the contact is a
    line: two points at the ends ``s_lo < s_hi`` of that overlap interval on A, like a box
    face contact. Both use the normal of the closest points; the depth of each is measured
    along it, ``depth(s) = depth_closest − (n · a)(s − s_closest)``, which is exact at the
    closest point (the interval holds it, and it is one of the ends or ``n ⊥ a`` there) and,
    at the other end, exceeds the true local depth by at most ``PARALLEL_SIN`` × the overlap
    length. Two capsules lying side by side so get 2 contacts of equal depth and do not rock.
    (If the closest point lies outside the interval, which needs the segments to meet nearly
    end to end, the single contact is used.)

    Features: 0 = the single closest-point contact; 1 = the parallel contact at ``s_lo`` (the
    end of the overlap toward A's −z end), 2 = the one at ``s_hi``.
    """
    frame_a, radius_a, half_a = capsule_a
    frame_b, radius_b, half_b = capsule_b
    center_a, rotation_a = frame_a
    center_b, rotation_b = frame_b
    axis_a = column(rotation_a, 2)
    axis_b = column(rotation_b, 2)
    s, t = segment_closest_parameters(center_a, axis_a, half_a, center_b, axis_b, half_b)
    point_a = axpy(center_a, s, axis_a)
    point_b = axpy(center_b, t, axis_b)
    d, distance, depth = sphere_gap(point_a, point_b, radius_a + radius_b)
    if depth < -margin:
        return 0
    axes_cross = cross(axis_a, axis_b)
    sin_angle = norm(axes_cross)
    if distance > NORMAL_EPS:
        normal = scaled(1.0 / distance, d)
    elif sin_angle > NORMAL_EPS:
        # the segments cross: their common normal, pointing from B's centre toward A's
        normal = scaled(1.0 / sin_angle, axes_cross)
        if dot(normal, axpy(center_a, -1.0, center_b)) < 0.0:
            normal = scaled(-1.0, normal)
    else:
        # collinear and touching: any direction perpendicular to the axes separates
        normal = column(rotation_a, 0)

    if sin_angle < PARALLEL_SIN and half_a > 0.0 and half_b > 0.0:
        # B's projection onto A's axis, intersected with A
        b_cos = dot(axis_a, axis_b)
        middle = -dot(axpy(center_a, -1.0, center_b), axis_a)
        reach = abs(b_cos) * half_b
        lo = max(-half_a, middle - reach)
        hi = min(half_a, middle + reach)
        size = half_a + half_b + radius_a + radius_b
        tol = OVERLAP_REL * size
        if hi - lo > tol and lo - tol <= s <= hi + tol:
            # A's segment against B's, in world coordinates (no frame): features 1 and 2
            segment_a = (center_a, axis_a, half_a, radius_a)
            return write_patch_ends(segment_a, (lo, hi), s, depth, normal, 1, (margin, None, out), slot)

    point = midpoint(axpy(point_a, -radius_a, normal), axpy(point_b, radius_b, normal))
    write_contact(out, slot, point, normal, depth, np.int64(CAPSULE_CAPSULE_SINGLE_FEATURE))
    return 1
