"""Box–box contact manifold: separating axis test, then face clipping or an edge–edge point.

Conventions as everywhere in :mod:`contactlab.collision.narrow_phase`: the normal points from
box B into box A, ``depth`` > 0 when overlapping, contacts are kept down to
``depth = −margin`` (speculative contacts), and each ``point`` lies midway between the two
surfaces.

Algorithm
---------
1. **Separating axis test (SAT)** over the 15 candidate axes: the 3 face normals of A, the 3
   of B, and the 9 cross products ``a_i × b_j`` of their edge directions (an edge pair closer
   than 1e−6 rad to parallel gives no axis of its own; a face axis covers it). On a unit axis
   L the *overlap* of the two projections is ``r_A + r_B − |(c_A − c_B)·L|``. If any axis has
   an overlap below −margin the boxes are further apart than the margin: no contact. The
   smallest overlap over the 15 axes is the penetration depth (the minimum translation
   distance) of two overlapping boxes.
2. **Choice of the contact axis**, with a tolerance that favours faces over edges, as Box2D
   and Bullet do, so that a box resting on another does not flip between face and edge
   contacts from step to step:

   * an overlap ``o`` is *within tolerance* of a smaller one ``s`` when
     ``o ≤ s + FACE_REL_TOL · |s| + FACE_ABS_TOL · L`` (``L`` the largest half extent of the pair);
   * the best face of A and the best face of B are a *tie* when the larger of their overlaps
     is within tolerance of the smaller; in a tie the box with the larger face is the reference
     (A when the faces are equal) — a rule that does not depend on the order of the two boxes
     unless their faces are equal —, otherwise the smaller overlap wins;
   * an edge axis is taken only when the chosen face's overlap is not within tolerance of it.

   So the axis used never overlaps more than the SAT minimum plus the tolerance.
3. **Face contact**: the chosen face is the *reference* face; the *incident* face is the face
   of the other box whose normal is most anti-parallel to it. The incident face (4 corners)
   is clipped against the 4 side planes of the reference face (Sutherland–Hodgman; a
   quadrilateral clipped by 4 planes has at most 8 corners). Corners of the clipped polygon
   that are nearly straight (within ``COLLINEAR_TOL`` × the smaller face's half width of the
   chord of their neighbours: near-duplicates, or an edge crossing a side plane it nearly lies
   on, as with equal boxes stacked flush) are dropped. Clipped points whose depth below the
   reference plane is ≥ −margin are kept; if more than 4 remain they are reduced to 4: the
   deepest, the one farthest from it, the one making the largest triangle with those two, and
   the one adding the most area to that triangle (near-ties, within ``REDUCE_TIE``, go to the
   earliest point in polygon order, so round-off cannot switch between equivalent choices).
   Each contact point is the clipped
   incident point moved halfway toward the reference plane; its depth is its own distance
   below the reference plane.
4. **Edge–edge contact**: one point, midway between the closest points of the two supporting
   edges (the closest points are clamped to the edges); its depth is the overlap on the axis.

Feature numbers (0..7, so that ``pair · 8 + feature`` is an id)
---------------------------------------------------------------
``feature = 4 · owner + label``: ``owner`` is 0 when the reference face belongs to A, 1 when
it belongs to B; ``label`` (0..3) names the incident-face corner the point comes from — the
corner itself when it survives clipping, or the corner that was cut off when the point lies
where an incident edge crosses a side plane of the reference face (a reference-face corner
inherits the label the same way). Labels are assigned in the clipped polygon's order, each
point taking its own corner's label when still free and the smallest free label otherwise,
so the 1–4 points of one pair always carry different features. While the reference face,
the incident face and the clipping topology persist, every point keeps its feature: a box
resting on a larger one has its 4 corners as contacts, labelled 0..3 by corner, for as long
as it rests there. The reference face index itself does not fit into 3 bits and is not
encoded: a box that tips onto another face reuses the labels. An edge–edge contact has
feature ``EDGE_FEATURE`` (0).

Everything here is compiled (``@njit(cache=True)``), float64, without fastmath.
"""

from __future__ import annotations

import numpy as np

from ..compiling import njit
from .contact_output import Frame, PairOutput
from .contact_polygon import MAX_POINTS, REDUCE_TIE, clip_polygon, drop_collinear, reduce_to_four

FACE_REL_TOL = 0.05  # relative tolerance favouring the reference face's box, and faces over edges
FACE_ABS_TOL = 1e-5  # absolute part of that tolerance, × the largest half extent of the pair [-]
PARALLEL_SIN2 = 1e-12  # |a_i × b_j|² below this (edges within 1e-6 rad of parallel): no edge axis
MAX_CONTACTS = MAX_POINTS  # contacts written per box pair, at most
EDGE_FEATURE = 0  # feature of the single edge–edge contact
COLLINEAR_TOL = 1e-4  # clipped corners this close (× the smaller face's half width) to a straight line are dropped

_NO_AXIS = -1
_UP = np.array([0.0, 0.0, 1.0])  # the reference face's normal in its own (u, v, h) frame


@njit(cache=True)
def sat_overlaps(
    frame_a: Frame, half_a: np.ndarray, frame_b: Frame, half_b: np.ndarray, overlap: np.ndarray, normal: np.ndarray
) -> int:
    """Projection overlap on each of the 15 SAT axes.

    Fills ``overlap`` (15,) [m] and ``normal`` (15, 3) (unit, oriented from B into A): indices
    0..2 are the faces of A (body axes x, y, z), 3..5 the faces of B, 6 + 3 i + j the edge axis
    ``a_i × b_j``. A (near-)parallel edge pair gets overlap +inf and a zero normal.
    Returns the index of the smallest overlap.
    """
    center_a, rotation_a = frame_a
    center_b, rotation_b = frame_b
    d0 = center_a[0] - center_b[0]
    d1 = center_a[1] - center_b[1]
    d2 = center_a[2] - center_b[2]
    for axis in range(15):
        if axis < 3:
            L0, L1, L2 = rotation_a[0, axis], rotation_a[1, axis], rotation_a[2, axis]
        elif axis < 6:
            L0, L1, L2 = rotation_b[0, axis - 3], rotation_b[1, axis - 3], rotation_b[2, axis - 3]
        else:
            i = (axis - 6) // 3
            j = (axis - 6) % 3
            a0, a1, a2 = rotation_a[0, i], rotation_a[1, i], rotation_a[2, i]
            b0, b1, b2 = rotation_b[0, j], rotation_b[1, j], rotation_b[2, j]
            L0 = a1 * b2 - a2 * b1
            L1 = a2 * b0 - a0 * b2
            L2 = a0 * b1 - a1 * b0
            length2 = L0 * L0 + L1 * L1 + L2 * L2
            if length2 < PARALLEL_SIN2:
                overlap[axis] = np.inf
                normal[axis, 0] = 0.0
                normal[axis, 1] = 0.0
                normal[axis, 2] = 0.0
                continue
            length = np.sqrt(length2)
            L0 /= length
            L1 /= length
            L2 /= length
        # projection radii of the two boxes on L, written out (no loop, no allocation: hot path)
        ra = (
            half_a[0] * abs(rotation_a[0, 0] * L0 + rotation_a[1, 0] * L1 + rotation_a[2, 0] * L2)
            + half_a[1] * abs(rotation_a[0, 1] * L0 + rotation_a[1, 1] * L1 + rotation_a[2, 1] * L2)
            + half_a[2] * abs(rotation_a[0, 2] * L0 + rotation_a[1, 2] * L1 + rotation_a[2, 2] * L2)
        )
        rb = (
            half_b[0] * abs(rotation_b[0, 0] * L0 + rotation_b[1, 0] * L1 + rotation_b[2, 0] * L2)
            + half_b[1] * abs(rotation_b[0, 1] * L0 + rotation_b[1, 1] * L1 + rotation_b[2, 1] * L2)
            + half_b[2] * abs(rotation_b[0, 2] * L0 + rotation_b[1, 2] * L1 + rotation_b[2, 2] * L2)
        )
        distance = d0 * L0 + d1 * L1 + d2 * L2
        sign = 1.0 if distance >= 0.0 else -1.0
        overlap[axis] = ra + rb - abs(distance)
        normal[axis, 0] = sign * L0
        normal[axis, 1] = sign * L1
        normal[axis, 2] = sign * L2
    best = 0
    for axis in range(1, 15):
        if overlap[axis] < overlap[best]:
            best = axis
    return best


@njit(cache=True)
def _face_contacts(box_a, box_b, face, contact_normal, margin, real, out, slot):
    """Clip the incident box's face against reference face ``face`` (0..2: A's face on that
    axis, 3..5: B's on axis face − 3), whose outward normal is ``contact_normal`` on B and its
    opposite on A; the other box is the incident one. Each box is (centre (3,) [m], rotation
    (3, 3), half extents (3,) [m]); ``real``: ≥ 100 floats of scratch."""
    owner = 1 if face >= 3 else 0  # 0: the reference face is A's, 1: B's
    if owner == 1:
        reference, incident, axis, outward_sign = box_b, box_a, face - 3, 1.0
    else:
        reference, incident, axis, outward_sign = box_a, box_b, face, -1.0
    center_ref, rotation_ref, half_ref = reference
    center_inc, rotation_inc, half_inc = incident
    # the tie tolerance's length: the largest half extent of the pair (box_box's)
    scale = max(max(half_ref[0], half_ref[1], half_ref[2]), max(half_inc[0], half_inc[1], half_inc[2]))
    whole = np.empty(48, dtype=np.int64)
    out_point, out_normal, out_depth, out_feature = out
    m0 = outward_sign * contact_normal[0]
    m1 = outward_sign * contact_normal[1]
    m2 = outward_sign * contact_normal[2]
    # scratch: floats (clip buffers, reduction scores, face centre, frame) and integers
    # (corner labels, kept positions, surviving rows, final labels)
    polygon = real[:48].reshape((2, 8, 3))
    score = real[48:56]
    fc = real[56:59]
    local = real[59:68].reshape((3, 3))
    flat = real[68:92].reshape((8, 3))  # the polygon's (u, v, 0): its shadow on the reference face
    height = real[92:100]
    labels = whole[:16].reshape((2, 8))
    keep = whole[16:24]
    rows = whole[24:32]
    label_of = whole[32:36]
    used = whole[36:40]
    # reference face: centre, in-plane axes U, V with half widths hu, hv
    along = rotation_ref[0, axis] * m0 + rotation_ref[1, axis] * m1 + rotation_ref[2, axis] * m2
    side = 1.0 if along >= 0.0 else -1.0
    for c in range(3):
        fc[c] = center_ref[c] + side * half_ref[axis] * rotation_ref[c, axis]
    iu = (axis + 1) % 3
    iv = (axis + 2) % 3
    hu = half_ref[iu]
    hv = half_ref[iv]
    # incident face: the face of the other box most anti-parallel to the reference normal
    k_inc = 0
    best = -1.0
    dot_inc = 0.0
    for k in range(3):
        dk = rotation_inc[0, k] * m0 + rotation_inc[1, k] * m1 + rotation_inc[2, k] * m2
        if abs(dk) > best:
            best = abs(dk)
            k_inc = k
            dot_inc = dk
    s_inc = -1.0 if dot_inc > 0.0 else 1.0
    ku = (k_inc + 1) % 3
    kv = (k_inc + 2) % 3
    # incident face centre and half edges in the reference frame:
    # (u, v, h) = ((x − fc)·U, (x − fc)·V, (x − fc)·m)
    for r in range(3):  # rows of local: centre, half edge along ku, half edge along kv
        if r == 0:
            x0 = center_inc[0] + s_inc * half_inc[k_inc] * rotation_inc[0, k_inc] - fc[0]
            x1 = center_inc[1] + s_inc * half_inc[k_inc] * rotation_inc[1, k_inc] - fc[1]
            x2 = center_inc[2] + s_inc * half_inc[k_inc] * rotation_inc[2, k_inc] - fc[2]
        else:
            k = ku if r == 1 else kv
            x0 = half_inc[k] * rotation_inc[0, k]
            x1 = half_inc[k] * rotation_inc[1, k]
            x2 = half_inc[k] * rotation_inc[2, k]
        local[r, 0] = x0 * rotation_ref[0, iu] + x1 * rotation_ref[1, iu] + x2 * rotation_ref[2, iu]
        local[r, 1] = x0 * rotation_ref[0, iv] + x1 * rotation_ref[1, iv] + x2 * rotation_ref[2, iv]
        local[r, 2] = x0 * m0 + x1 * m1 + x2 * m2
    # its corners, labels 0..3 counter-clockwise about the incident face's own axes: (+,+) (−,+) (−,−) (+,−)
    for corner in range(4):
        su = 1.0 if (corner == 0 or corner == 3) else -1.0
        sv = 1.0 if corner < 2 else -1.0
        for c in range(3):
            polygon[0, corner, c] = local[0, c] + su * local[1, c] + sv * local[2, c]
        labels[0, corner] = corner
    distance = np.empty(polygon.shape[1])
    count = polygon.shape[1] // 2  # 4 corners (not a literal constant: spares Numba a specialization)
    source = 0
    for plane in range(4):  # u ≤ hu, −u ≤ hu, v ≤ hv, −v ≤ hv
        coordinate = plane // 2
        sign = 1.0 if plane % 2 == 0 else -1.0
        limit = hu if coordinate == 0 else hv
        # clip the polygon (rows (u, v, h), labelled by incident corner) to sign·x[coordinate] ≤ limit
        for k in range(count):
            distance[k] = sign * polygon[source, k, coordinate] - limit
        count = clip_polygon(polygon[source], labels[source], count, distance, polygon[1 - source], labels[1 - source])
        source = 1 - source
    points = polygon[0]
    # the polygon lies inside both faces: its size sets the tolerance for straight corners
    tolerance = COLLINEAR_TOL * min(min(hu, hv), min(half_inc[ku], half_inc[kv]))
    # straightness is judged in the reference plane, on the polygon's shadow (u, v, 0)
    for k in range(count):
        flat[k, 0] = points[k, 0]
        flat[k, 1] = points[k, 1]
        flat[k, 2] = 0.0
        rows[k] = k
    count = drop_collinear(flat, rows, count, tolerance, _UP, np.inf)
    for k in range(count):  # rows[k] ≥ k: compacting in place is safe
        for c in range(3):
            points[k, c] = points[rows[k], c]
        labels[0, k] = labels[0, rows[k]]
        height[k] = points[k, 2]
    # keep the points below the reference face, or above it by at most the margin
    kept = count - count  # 0, typed like count (see above)
    for k in range(count):
        if points[k, 2] <= margin:
            keep[kept] = k
            kept += 1
    kept = reduce_to_four(flat, height, keep, kept, _UP, REDUCE_TIE * scale, score)
    # labels: own corner's label when free, else the smallest free one (polygon order both times)
    for k in range(4):
        used[k] = 0
        label_of[k] = -1
    for k in range(kept):
        own = labels[0, keep[k]]
        if used[own] == 0:
            used[own] = 1
            label_of[k] = own
    for k in range(kept):
        if label_of[k] < 0:
            for free in range(4):
                if used[free] == 0:
                    used[free] = 1
                    label_of[k] = free
                    break
    for k in range(kept):
        u = points[keep[k], 0]
        v = points[keep[k], 1]
        h = points[keep[k], 2]
        row = slot + k
        for c in range(3):
            # incident point moved halfway to the reference plane: fc + u U + v V + (h/2) m
            out_point[row, c] = (
                fc[c] + u * rotation_ref[c, iu] + v * rotation_ref[c, iv] + 0.5 * h * outward_sign * contact_normal[c]
            )
            out_normal[row, c] = contact_normal[c]
        out_depth[row] = -h
        out_feature[row] = 4 * owner + label_of[k]
    return kept


@njit(cache=True)
def _edge_contact(box_a, box_b, edge_axis, normal, depth, ends, out, slot):
    """One contact midway between the closest points of edge ∥a_i of A and edge ∥b_j of B, the
    SAT's axis ``edge_axis`` = 6 + 3 i + j (a_i × b_j); each box (centre (3,) [m], rotation (3, 3),
    half extents (3,) [m]); ``ends``: (2, 3) scratch."""
    center_a, rotation_a, half_a = box_a
    center_b, rotation_b, half_b = box_b
    i = (edge_axis - 6) // 3
    j = (edge_axis - 6) % 3
    out_point, out_normal, out_depth, out_feature = out
    # supporting edges: A's edge furthest along −n, B's furthest along +n
    pa = ends[0]
    pb = ends[1]
    for c in range(3):
        pa[c] = center_a[c]
        pb[c] = center_b[c]
    for k in range(3):
        if k != i:
            ak_n = rotation_a[0, k] * normal[0] + rotation_a[1, k] * normal[1] + rotation_a[2, k] * normal[2]
            s = -1.0 if ak_n > 0.0 else 1.0
            for c in range(3):
                pa[c] += s * half_a[k] * rotation_a[c, k]
        if k != j:
            bk_n = rotation_b[0, k] * normal[0] + rotation_b[1, k] * normal[1] + rotation_b[2, k] * normal[2]
            s = 1.0 if bk_n >= 0.0 else -1.0
            for c in range(3):
                pb[c] += s * half_b[k] * rotation_b[c, k]
    # closest points of the lines pa + t a, pb + u b (a, b unit; not parallel here)
    cos_ab = 0.0
    w_a = 0.0
    w_b = 0.0
    for c in range(3):
        cos_ab += rotation_a[c, i] * rotation_b[c, j]
        w_a += (pa[c] - pb[c]) * rotation_a[c, i]
        w_b += (pa[c] - pb[c]) * rotation_b[c, j]
    denominator = 1.0 - cos_ab * cos_ab
    t = (cos_ab * w_b - w_a) / denominator
    u = w_b + t * cos_ab
    t = min(max(t, -half_a[i]), half_a[i])
    u = min(max(u, -half_b[j]), half_b[j])
    for c in range(3):
        out_point[slot, c] = 0.5 * (pa[c] + t * rotation_a[c, i] + pb[c] + u * rotation_b[c, j])
        out_normal[slot, c] = normal[c]
    out_depth[slot] = depth
    out_feature[slot] = EDGE_FEATURE
    return 1


@njit(cache=True)
def box_box(
    frame_a: Frame, half_a: np.ndarray, frame_b: Frame, half_b: np.ndarray, margin: float, out: PairOutput, slot: int
) -> int:
    """Box A against box B: up to 4 contacts written from ``slot`` on; returns their count.

    Parameters: frames (centre (3,) [m], rotation (3, 3) body → world), half extents (3,) [m],
    ``margin`` [m] (contacts kept down to depth −margin). Outputs: the rows ``out`` (point (·, 3)
    [m], normal (·, 3) unit from B into A, depth (·,) [m], feature (·,) in 0..7, see the module
    docstring; :data:`.contact_output.PairOutput`). Returns 0 when the boxes are further apart than the
    margin on some separating axis.
    """
    center_a, rotation_a = frame_a
    center_b, rotation_b = frame_b
    # scratch for the whole call, in two allocations (each small allocation costs ~50 ns)
    work = np.empty(15 * 4 + 100)
    overlap = work[:15]
    normal = work[15:60].reshape((15, 3))
    sat_overlaps(frame_a, half_a, frame_b, half_b, overlap, normal)
    best_a = 0
    best_b = 3
    best_e = _NO_AXIS
    for axis in range(15):
        if overlap[axis] < -margin:
            return 0
        if axis < 3:
            if overlap[axis] < overlap[best_a]:
                best_a = axis
        elif axis < 6:
            if overlap[axis] < overlap[best_b]:
                best_b = axis
        elif overlap[axis] < np.inf:
            if best_e == _NO_AXIS or overlap[axis] < overlap[best_e]:
                best_e = axis
    scale = max(max(half_a[0], half_a[1], half_a[2]), max(half_b[0], half_b[1], half_b[2]))
    absolute = FACE_ABS_TOL * scale
    over_a = overlap[best_a]
    over_b = overlap[best_b]
    lower = min(over_a, over_b)
    if max(over_a, over_b) <= lower + FACE_REL_TOL * abs(lower) + absolute:
        # a tie: the larger face is the reference (A's when equal), for stability in time
        area_a = half_a[(best_a + 1) % 3] * half_a[(best_a + 2) % 3]
        area_b = half_b[(best_b - 3 + 1) % 3] * half_b[(best_b - 3 + 2) % 3]
        use_b = area_b > area_a * (1.0 + 1e-9)
    else:
        use_b = over_b < over_a
    face = best_b if use_b else best_a
    box_a = (center_a, rotation_a, half_a)
    box_b = (center_b, rotation_b, half_b)
    if best_e != _NO_AXIS:
        over_e = overlap[best_e]
        if overlap[face] > over_e + FACE_REL_TOL * abs(over_e) + absolute:
            # the edge axis is clearly better than any face
            ends = work[60:66].reshape((2, 3))
            return _edge_contact(box_a, box_b, best_e, normal[best_e], over_e, ends, out, slot)
    # reference face on B (face 3..5): its outward normal is the contact normal, incident box A;
    # on A: its outward normal points from A towards B, incident box B
    return _face_contacts(box_a, box_b, face, normal[face], margin, work[60:], out, slot)
