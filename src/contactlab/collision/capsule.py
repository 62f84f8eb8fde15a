"""Capsule contacts: capsule–plane, sphere–capsule, capsule–capsule and capsule–box.

A capsule is the set of points within ``radius`` of a segment: the segment runs along the
capsule's BODY z axis (the third column of its body → world rotation matrix), from
``center − half_length · axis`` (the "−z end") to ``center + half_length · axis`` (the "+z
end"). A point on the segment is written ``center + s · axis`` with ``s ∈ [−half_length,
half_length]``; ``half_length = 0`` is a sphere and is handled everywhere.

Conventions as in :mod:`contactlab.collision.narrow_phase`: shape A is the first argument, the
unit normal points from B into A, ``depth`` > 0 when overlapping, contacts are kept down to
``depth = −margin`` (speculative contacts), each ``point`` lies midway between the two
surfaces, and every function writes its contacts from index ``slot`` on into ``out_point``
(N, 3), ``out_normal`` (N, 3), ``out_depth`` (N,), ``out_feature`` (N,) int64 and returns how
many it wrote (at most 2). ``feature`` (0..255) names the contact within its pair so that it
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
from numba import njit

from .contact_output import write_contact, write_local_contact
from .geometry import (
    axpy,
    clamp,
    column,
    cross,
    dot,
    midpoint,
    norm,
    rotate,
    scaled,
    segment_closest_parameters,
    unit_axis,
    unrotate,
)

MAX_CONTACTS = 2  # contacts written per capsule pair, at most
PARALLEL_SIN = 1e-3  # capsule axes with |sin angle| below this are "parallel" (2-point contact)
OVERLAP_REL = 1e-6  # a parallel overlap shorter than this × (sum of half lengths and radii) is a point
NORMAL_EPS = 1e-12  # distances [m] below this give no direction; a fallback normal is used
BOX_REL_EPS = 1e-9  # capsule–box tolerances, × the pair's size (sum of half lengths, radius, half extents)
CROSS_AXIS_EPS = 1e-8  # |axis × box edge| below this: no SAT axis of its own (a face axis covers it)

CAPSULE_BOX_EDGE_FEATURE = 12  # capsule–box contacts alongside a box edge: 12 + 2 · edge + end (12..35)
CAPSULE_BOX_CROSS_FEATURE = 36  # the capsule–box contact of a segment inside the box, across an edge
CAPSULE_CAPSULE_SINGLE_FEATURE = 0


# ---------------------------------------------------------------------------------------------
# capsule – plane
# ---------------------------------------------------------------------------------------------


@njit(cache=True)
def capsule_plane(
    center, rotation, radius, half_length, plane, margin, out_point, out_normal, out_depth, out_feature, slot
):
    """Capsule A against the plane B = (n, offset) (solid side n·x < offset; n unit).

    center: (3,) [m]; rotation: (3, 3) body → world, the segment along its third column;
    radius, half_length [m]; plane: (4,) (n_x, n_y, n_z, offset [m]); margin [m].
    The signed distance to the plane is linear along the segment, so one contact per segment
    end within the margin is exact and a capsule lying flat gets 2 contacts of equal depth
    (it does not rock); the normal is the plane's.

    Features: 0 = the −z end (``center − half_length · axis``), 1 = the +z end. A capsule of
    zero half length has only the end 0.
    """
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
            write_contact(out_point, out_normal, out_depth, out_feature, slot + count, point, normal, depth, end)
            count += 1
    return count


# ---------------------------------------------------------------------------------------------
# sphere – capsule
# ---------------------------------------------------------------------------------------------


@njit(cache=True)
def sphere_capsule(
    center_a,
    radius_a,
    center_b,
    rotation_b,
    radius_b,
    half_length_b,
    margin,
    out_point,
    out_normal,
    out_depth,
    out_feature,
    slot,
):
    """Sphere (or particle: a sphere of radius ≥ 0) A against capsule B: at most 1 contact.

    center_a: (3,) [m]; radius_a [m]; center_b: (3,) [m]; rotation_b: (3, 3) body → world;
    radius_b, half_length_b [m]; margin [m]. The sphere centre's closest point on B's segment
    makes this a sphere–sphere contact. A centre on the segment (no direction) is pushed out
    along B's body x axis, perpendicular to the segment.

    Features: 0 (the one contact; it keeps its number as it slides from the side to a cap).
    """
    axis = column(rotation_b, 2)
    s = clamp(dot(axpy(center_a, -1.0, center_b), axis), -half_length_b, half_length_b)
    closest = axpy(center_b, s, axis)
    d = axpy(center_a, -1.0, closest)
    distance = norm(d)
    depth = radius_a + radius_b - distance
    if depth < -margin:
        return 0
    if distance > NORMAL_EPS:
        normal = scaled(1.0 / distance, d)
    else:
        normal = column(rotation_b, 0)
    point = midpoint(axpy(center_a, -radius_a, normal), axpy(closest, radius_b, normal))
    write_contact(out_point, out_normal, out_depth, out_feature, slot, point, normal, depth, np.int64(0))
    return 1


# ---------------------------------------------------------------------------------------------
# capsule – capsule
# ---------------------------------------------------------------------------------------------


@njit(cache=True)
def capsule_capsule(
    center_a,
    rotation_a,
    radius_a,
    half_a,
    center_b,
    rotation_b,
    radius_b,
    half_b,
    margin,
    out_point,
    out_normal,
    out_depth,
    out_feature,
    slot,
):
    """Capsule A against capsule B: 1 contact, or 2 when the axes are (nearly) parallel.

    center_*: (3,) [m]; rotation_*: (3, 3) body → world (segment along the third column);
    radius_*, half_* (half lengths) [m]; margin [m].

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
    axis_a = column(rotation_a, 2)
    axis_b = column(rotation_b, 2)
    s, t = segment_closest_parameters(center_a, axis_a, half_a, center_b, axis_b, half_b)
    # closest points, distance and depth as in sphere_capsule (deliberately kept apart from it:
    # two segments can lie parallel and get a 2-point patch, a sphere cannot)
    point_a = axpy(center_a, s, axis_a)
    point_b = axpy(center_b, t, axis_b)
    d = axpy(point_a, -1.0, point_b)
    distance = norm(d)
    depth = radius_a + radius_b - distance
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
            slope = dot(normal, axis_a)
            count = 0
            for end in range(2):
                s_end = lo if end == 0 else hi
                depth_end = depth - slope * (s_end - s)
                if depth_end >= -margin:
                    surface_a = axpy(axpy(center_a, s_end, axis_a), -radius_a, normal)
                    point = axpy(surface_a, 0.5 * depth_end, normal)
                    write_contact(
                        out_point, out_normal, out_depth, out_feature, slot + count, point, normal, depth_end, 1 + end
                    )
                    count += 1
            return count

    point = midpoint(axpy(point_a, -radius_a, normal), axpy(point_b, radius_b, normal))
    write_contact(
        out_point,
        out_normal,
        out_depth,
        out_feature,
        slot,
        point,
        normal,
        depth,
        np.int64(CAPSULE_CAPSULE_SINGLE_FEATURE),
    )
    return 1


# ---------------------------------------------------------------------------------------------
# capsule – box
# ---------------------------------------------------------------------------------------------


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
def segment_box_closest(origin, direction, half_length, half_extents):
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
def _face_interval(origin, direction, half_length, half_extents, face_axis, tol):
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
def _face_contact(
    origin,
    direction,
    s,
    radius,
    half_extents,
    face_axis,
    face_sign,
    feature,
    margin,
    box_center,
    box_rotation,
    out_point,
    out_normal,
    out_depth,
    out_feature,
    slot,
):
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
def _face_patch(
    origin,
    direction,
    half_length,
    radius,
    half_extents,
    face_axis,
    face_sign,
    s_keep,
    margin,
    tol,
    box_center,
    box_rotation,
    out_point,
    out_normal,
    out_depth,
    out_feature,
    slot,
):
    """Contacts of the segment (box frame) against one box face: the two ends of the part of
    the segment over the face (``s_keep``, unless nan, is kept inside that part), each with its
    own depth; a part shorter than ``tol`` gives 1 contact at its deeper end.
    Features ``2 · face + end``, ``face = 2 · face_axis + (face_sign > 0)``, ``end`` 0 at the
    low ``s`` end, 1 at the high one (a single point: the side of the capsule centre it is on).
    """
    lo, hi = _face_interval(origin, direction, half_length, half_extents, face_axis, tol)
    if s_keep == s_keep:  # not nan
        lo = min(lo, s_keep)
        hi = max(hi, s_keep)
    if lo > hi:  # grazing a side of the face within round-off
        lo = clamp(0.5 * (lo + hi), -half_length, half_length)
        hi = lo
    face = 2 * face_axis + (1 if face_sign > 0.0 else 0)
    if hi - lo > tol:
        count = _face_contact(
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
        count += _face_contact(
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
    return _face_contact(
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
    origin,
    direction,
    lo,
    hi,
    s,
    depth,
    slope,
    radius_a,
    normal_local,
    margin,
    feature,
    center,
    rotation,
    out_point,
    out_normal,
    out_depth,
    out_feature,
    slot,
):
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


@njit(cache=True)
def capsule_box(
    center_a,
    rotation_a,
    radius_a,
    half_length_a,
    box_center,
    box_rotation,
    half_extents,
    margin,
    out_point,
    out_normal,
    out_depth,
    out_feature,
    slot,
):
    """Capsule A against box B (static or dynamic): up to 2 contacts.

    center_a: (3,) [m]; rotation_a: (3, 3) body → world (segment along its third column);
    radius_a, half_length_a [m]; box_center: (3,) [m]; box_rotation: (3, 3) body → world;
    half_extents: (3,) [m]; margin [m]. Work is done in the box's frame.

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
    origin = unrotate(box_rotation, axpy(center_a, -1.0, box_center))
    direction = unrotate(box_rotation, column(rotation_a, 2))
    size = half_length_a + radius_a + half_extents[0] + half_extents[1] + half_extents[2]
    tol = BOX_REL_EPS * size
    s, distance2 = segment_box_closest(origin, direction, half_length_a, half_extents)
    distance = np.sqrt(distance2)
    depth = radius_a - distance
    if depth < -margin:
        return 0

    if distance > tol:
        return _segment_outside(
            origin,
            direction,
            s,
            distance,
            radius_a,
            half_length_a,
            half_extents,
            margin,
            tol,
            box_center,
            box_rotation,
            out_point,
            out_normal,
            out_depth,
            out_feature,
            slot,
        )
    return _segment_inside(
        origin,
        direction,
        radius_a,
        half_length_a,
        half_extents,
        margin,
        tol,
        box_center,
        box_rotation,
        out_point,
        out_normal,
        out_depth,
        out_feature,
        slot,
    )


@njit(cache=True)
def _segment_outside(
    origin,
    direction,
    s,
    distance,
    radius_a,
    half_length_a,
    half_extents,
    margin,
    tol,
    box_center,
    box_rotation,
    out_point,
    out_normal,
    out_depth,
    out_feature,
    slot,
):
    """Case 1 of :func:`capsule_box` (box frame): the segment is outside the box; ``s`` is its
    closest point's parameter, ``distance`` > 0 the segment–box distance."""
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
    if outside <= 1:
        return _face_patch(
            origin,
            direction,
            half_length_a,
            radius_a,
            half_extents,
            face_axis,
            face_sign,
            s,
            margin,
            tol,
            box_center,
            box_rotation,
            out_point,
            out_normal,
            out_depth,
            out_feature,
            slot,
        )
    normal_local = scaled(1.0 / distance, axpy(p, -1.0, q))
    point_local = midpoint(axpy(p, -radius_a, normal_local), q)
    slope = dot(normal_local, direction)

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
                return write_patch_ends(
                    origin,
                    direction,
                    lo,
                    hi,
                    s,
                    depth,
                    slope,
                    radius_a,
                    normal_local,
                    margin,
                    CAPSULE_BOX_EDGE_FEATURE + 2 * edge,
                    box_center,
                    box_rotation,
                    out_point,
                    out_normal,
                    out_depth,
                    out_feature,
                    slot,
                )

    # an edge crossed at an angle, or a corner: the closest point stands for the end of the
    # dominant face's patch on its side; the other end of that patch is kept too
    face = 2 * face_axis + (1 if face_sign > 0.0 else 0)
    lo, hi = _face_interval(origin, direction, half_length_a, half_extents, face_axis, tol)
    if lo <= hi:
        end = 1 if s > 0.5 * (lo + hi) else 0
    else:
        end = 1 if s > 0.0 else 0
    write_local_contact(
        point_local,
        normal_local,
        depth,
        2 * face + end,
        box_center,
        box_rotation,
        out_point,
        out_normal,
        out_depth,
        out_feature,
        slot,
    )
    count = 1
    if hi - lo > tol:
        other = lo if end == 1 else hi
        if abs(other - s) > tol:
            count += _face_contact(
                origin,
                direction,
                other,
                radius_a,
                half_extents,
                face_axis,
                face_sign,
                2 * face + 1 - end,
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


@njit(cache=True)
def _segment_inside(
    origin,
    direction,
    radius_a,
    half_length_a,
    half_extents,
    margin,
    tol,
    box_center,
    box_rotation,
    out_point,
    out_normal,
    out_depth,
    out_feature,
    slot,
):
    """Case 2 of :func:`capsule_box` (box frame): the segment touches or enters the box."""
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
        face_sign = 1.0 if origin[best_face] >= 0.0 else -1.0
        return _face_patch(
            origin,
            direction,
            half_length_a,
            radius_a,
            half_extents,
            best_face,
            face_sign,
            np.nan,
            margin,
            tol,
            box_center,
            box_rotation,
            out_point,
            out_normal,
            out_depth,
            out_feature,
            slot,
        )

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
    s, t = segment_closest_parameters(
        origin, direction, half_length_a, edge_center, edge_direction, half_extents[best_edge]
    )
    p = axpy(origin, s, direction)
    q = axpy(edge_center, t, edge_direction)
    write_local_contact(
        midpoint(axpy(p, -radius_a, normal_local), q),
        normal_local,
        depth,
        np.int64(CAPSULE_BOX_CROSS_FEATURE),
        box_center,
        box_rotation,
        out_point,
        out_normal,
        out_depth,
        out_feature,
        slot,
    )
    return 1
