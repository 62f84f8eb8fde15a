"""Contact manifolds of two convex polytopes (hulls): the separating axis test and face clipping.

Conventions and the hull arrays as in :mod:`.convex`: shape A first, the normal a unit
vector from B into A, ``depth`` > 0 when overlapping, contacts kept down to
``depth = −margin``, each ``point`` midway between the surfaces, at most ``MAX_CONTACTS`` = 4
written from ``slot`` on.

Algorithm
---------
``convex_convex``: the separating axis test (:mod:`.convex_sat`) over the face normals of A, of B, and the
edge pairs that form a face of the Minkowski difference (the Gauss-map arc test of
D. Gregorius, GDC 2013: only those edge pairs can give the minimum, so the others are
skipped without projecting anything). The smallest overlap is the exact penetration depth
when the hulls overlap; when they are apart the largest separation is a lower bound of the
distance (exact when the closest features are a face and something), so speculative
contacts are conservative. Faces are favoured over edges, and the larger face among two
nearly equal faces is the reference (A's when equal), with the tolerances of
:mod:`.box_box` (``FACE_REL_TOL`` relative, ``FACE_ABS_TOL`` × the larger hull radius),
so a resting hull does not flip between face and edge contacts (the axis used never
overlaps more than the minimum plus that tolerance). A face axis gives a manifold: the
*incident* face — of the faces around the other hull's deepest vertex, the one most
anti-parallel to the reference normal — is clipped against the side planes of the
reference face (Sutherland–Hodgman); the clipped points at most ``margin`` above the
reference plane are the contacts, each moved halfway to the reference plane, its depth its
own distance below that plane. Since the deepest vertex is on the incident face, the
deepest contact has the full overlap on the axis whenever that vertex lies over the
reference face. If clipping leaves nothing (a deep or grazing contact on a favoured,
non-minimal axis), the exact minimum axis is used instead; if that face clips to nothing
too, the incident hull's deepest vertex is the one contact (its projection lies on the
reference face, since that face is the minimum). An edge axis gives one contact midway
between the closest points of the two edges, with the axis overlap as its depth.
The clipped polygon's nearly straight corners are dropped and it is reduced to 4 points as
box–box does it (:mod:`.contact_polygon`).

Feature numbers (0..255)
------------------------
Face contact: ``fold(FNV-1a(reference face, incident face, label))``
where ``label`` is an incident-hull vertex: the incident vertex the point is, or, for a point
where clipping cut the incident polygon, the vertex that was cut off there (so a corner cut
by a hair keeps its label, as in :mod:`.box_box`; a reference-face corner inherits the label
the same way). Edge–edge contact: ``fold(FNV-1a(−1 − min(a, b), −1, max(a, b)))`` for edges
``a``, ``b`` of the two hulls. ``FNV-1a`` is the 32-bit Fowler–Noll–Vo hash over these
integers and ``fold(h) = (h ⊕ h≫8 ⊕ h≫16 ⊕ h≫24) mod 256``; a feature already taken in the
pair moves to the next free number (polygon order). So a contact keeps its feature while
its reference face, incident face and clipping topology persist, including through
round-off jitter of faces stacked flush (nearly straight corners of the clipped polygon,
within ``COLLINEAR_TOL`` × the shorter face's shortest edge of the chord of their
neighbours, are dropped first, unless deeper than both neighbours by more than
``DEPTH_TOL`` × size); tipping onto another face gives
new features. Which hull is A does not enter: swapping A and B gives the same features.

Everything here is compiled (``@njit(cache=True)``), float64, without fastmath.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np

from ..compiling import njit
from .contact_output import Frame, PairOutput
from .contact_polygon import MAX_POINTS, REDUCE_TIE, claim_feature, clip_polygon, drop_collinear
from .convex import Candidates, HullArrays, write_reduced
from .convex_sat import convex_convex_sat
from .geometry import segment_closest_parameters

MAX_CONTACTS = MAX_POINTS  # contacts written per pair, at most
FACE_REL_TOL = 0.05  # relative tolerance favouring faces over edges, and the larger reference face
FACE_ABS_TOL = 1e-5  # absolute part of that tolerance, × the larger hull radius [-]
DEPTH_TOL = 1e-9  # a nearly straight clipped corner deeper than its neighbours by this × size is kept
COLLINEAR_TOL = 1e-4  # clipped corners this close to straight (× the shorter face's shortest edge) are dropped

# how one face is clipped (``_face_contacts``): the reference face's number on its hull, the
# sign of the contact normal along its outward normal (+1 on B, −1 on A), the margin [m], the
# pair's size [m] (for tolerances), and whether the deepest incident vertex stands in when the
# clipping leaves nothing. Scalars only: the record costs a call nothing.
FaceClip = namedtuple("FaceClip", ["face", "sign", "margin", "scale", "fallback"])

_FNV_OFFSET = 2166136261
_FNV_PRIME = 16777619


@njit(cache=True)
def _mix(h, value):
    """One FNV-1a step over a 32-bit integer (h and the result in 0..2³²−1)."""
    return ((h ^ (value & 0xFFFFFFFF)) * _FNV_PRIME) & 0xFFFFFFFF


@njit(cache=True)
def _feature_of(ref_face, inc_face, vertex):
    """0..255 from (reference face, incident face, vertex) by FNV-1a, folded to 8 bits."""
    h = _mix(_mix(_mix(_FNV_OFFSET, ref_face), inc_face), vertex)
    return (h ^ (h >> 8) ^ (h >> 16) ^ (h >> 24)) & 255


@njit(cache=True)
def _clip_side(source, label, count, plane_point, plane_normal, distance, target, target_label):
    """Clip polygon ``source`` (rows, 3) to plane_normal · (x − plane_point) ≤ 0 (one side plane of
    the reference face); ``distance`` is scratch space. Returns the new count (see
    contact_polygon.clip_polygon)."""
    for k in range(count):
        distance[k] = (
            plane_normal[0] * (source[k, 0] - plane_point[0])
            + plane_normal[1] * (source[k, 1] - plane_point[1])
            + plane_normal[2] * (source[k, 2] - plane_point[2])
        )
    return clip_polygon(source, label, count, distance, target, target_label)


@njit(cache=True)
def _shortest_edge(points, fvs, fvi, f):
    """Length [m] of the shortest edge of face f."""
    base = fvs[0]
    start = fvs[f] - base
    corners = fvs[f + 1] - fvs[f]
    shortest = np.inf
    for k in range(corners):
        a = points[fvi[start + k]]
        b = points[fvi[start + (k + 1) % corners]]
        shortest = min(shortest, (b[0] - a[0]) ** 2 + (b[1] - a[1]) ** 2 + (b[2] - a[2]) ** 2)
    return np.sqrt(shortest)


@njit(cache=True)
def _face_area(points, face_vertex_start, face_vertex_index, f, normal):
    """Area [m²] of face f (corners ``points`` rows), about its unit ``normal``."""
    base = face_vertex_start[0]
    start = face_vertex_start[f] - base
    stop = face_vertex_start[f + 1] - base
    a = points[face_vertex_index[start]]
    total = 0.0
    for k in range(start + 1, stop - 1):
        b = points[face_vertex_index[k]]
        c = points[face_vertex_index[k + 1]]
        u0, u1, u2 = b[0] - a[0], b[1] - a[1], b[2] - a[2]
        v0, v1, v2 = c[0] - a[0], c[1] - a[1], c[2] - a[2]
        total += (u1 * v2 - u2 * v1) * normal[0] + (u2 * v0 - u0 * v2) * normal[1] + (u0 * v1 - u1 * v0) * normal[2]
    return 0.5 * abs(total)


@njit(cache=True)
def _face_contacts(reference, incident, clip, frame_a, out, slot):
    """Clip the incident face against reference face ``clip.face`` (a :data:`FaceClip`);
    everything in A's frame.

    ``reference``, ``incident``: the two hulls in A's frame, each (vertices (·, 3), face normals
    (·, 3), face offsets (·,), face_vertex_start, face_vertex_index); ``clip.sign`` = +1 when the
    reference face is on B (contact normal = its outward normal), −1 when on A. If clipping
    leaves nothing within ``clip.margin``, the incident hull's deepest vertex is the one contact
    when ``clip.fallback``, else nothing. ``frame_a`` = (centre (3,) [m], rotation (3, 3)) of A.
    Writes world contacts; returns their count.
    """
    ref_face, sign, margin, scale, fallback = clip
    ref_points, ref_normals, ref_offsets, ref_fvs, ref_fvi = reference
    ref_normal, ref_offset = ref_normals[ref_face], ref_offsets[ref_face]
    inc_points, inc_normal, _, inc_fvs, inc_fvi = incident
    rotation_a = frame_a[1]
    m0, m1, m2 = ref_normal[0], ref_normal[1], ref_normal[2]
    # the incident hull's deepest vertex (its support point along −ref_normal) ...
    deepest = 0
    lowest = np.inf
    for v in range(inc_points.shape[0]):
        h = m0 * inc_points[v, 0] + m1 * inc_points[v, 1] + m2 * inc_points[v, 2]
        if h < lowest:
            lowest = h
            deepest = v
    # ... and the incident face: of the faces around that vertex, the most anti-parallel to the
    # reference normal (so the deepest point is always on it and survives clipping when it lies
    # over the reference face)
    inc_base = inc_fvs[0]
    inc_face = 0
    best = np.inf
    for g in range(inc_normal.shape[0]):
        around = False
        for k in range(inc_fvs[g] - inc_base, inc_fvs[g + 1] - inc_base):
            if inc_fvi[k] == deepest:
                around = True
                break
        if around:
            d = inc_normal[g, 0] * m0 + inc_normal[g, 1] * m1 + inc_normal[g, 2] * m2
            if d < best:
                best = d
                inc_face = g
    ref_base = ref_fvs[0]
    ref_start = ref_fvs[ref_face] - ref_base
    ref_corners = ref_fvs[ref_face + 1] - ref_fvs[ref_face]
    inc_start = inc_fvs[inc_face] - inc_base
    inc_corners = inc_fvs[inc_face + 1] - inc_fvs[inc_face]
    capacity = inc_corners + ref_corners + 1
    polygon = np.empty((2, capacity, 3))
    labels = np.empty((2, capacity), dtype=np.int64)
    distance = np.empty(capacity)
    for k in range(inc_corners):
        v = inc_fvi[inc_start + k]
        for c in range(3):
            polygon[0, k, c] = inc_points[v, c]
        labels[0, k] = v
    count = inc_corners
    side_normal = np.empty(3)
    source = 0
    for side in range(ref_corners):
        a = ref_points[ref_fvi[ref_start + side]]
        b = ref_points[ref_fvi[ref_start + (side + 1) % ref_corners]]
        e0, e1, e2 = b[0] - a[0], b[1] - a[1], b[2] - a[2]
        side_normal[0] = e1 * m2 - e2 * m1  # e × m: outward in the face plane
        side_normal[1] = e2 * m0 - e0 * m2
        side_normal[2] = e0 * m1 - e1 * m0
        count = _clip_side(
            polygon[source], labels[source], count, a, side_normal, distance, polygon[1 - source], labels[1 - source]
        )
        source = 1 - source
        if count == 0:
            break
    points = polygon[source]
    point_labels = labels[source]
    # drop nearly straight corners, at a tolerance set by the smaller face
    if count > 2:
        tolerance = COLLINEAR_TOL * min(
            _shortest_edge(ref_points, ref_fvs, ref_fvi, ref_face),
            _shortest_edge(inc_points, inc_fvs, inc_fvi, inc_face),
        )
        count = drop_collinear(points, point_labels, count, tolerance, ref_normal, DEPTH_TOL * scale)
    height = distance  # reuse: height above the reference plane
    keep = np.empty(max(capacity, 1), dtype=np.int64)
    kept = 0
    for k in range(count):
        h = m0 * points[k, 0] + m1 * points[k, 1] + m2 * points[k, 2] - ref_offset
        height[k] = h
        if h <= margin:
            keep[kept] = k
            kept += 1
    if kept == 0:
        if not fallback:
            return 0
        # grazing, or deep: the incident hull's deepest vertex is the one contact
        lowest -= ref_offset
        if lowest > margin:
            return 0
        for c in range(3):
            points[0, c] = inc_points[deepest, c]
        height[0] = lowest
        point_labels[0] = deepest
        keep[0] = 0
        kept = 1
    # reduced and written as convex_plane's vertices: moved halfway down to the reference plane,
    # whose normal in the world is ``direction``
    direction = np.empty(3)
    for c in range(3):
        direction[c] = rotation_a[c, 0] * m0 + rotation_a[c, 1] * m1 + rotation_a[c, 2] * m2
    kept = write_reduced(
        frame_a, Candidates(points, height, keep, kept), ref_normal, REDUCE_TIE * scale, direction, sign, out, slot
    )
    used = np.zeros(256, dtype=np.bool_)
    for k in range(kept):
        out[3][slot + k] = claim_feature(_feature_of(ref_face, inc_face, point_labels[keep[k]]), used)
    return kept


@njit(cache=True)
def convex_convex(
    frame_a: Frame, hull_a: HullArrays, frame_b: Frame, hull_b: HullArrays, margin: float, out: PairOutput, slot: int
) -> int:
    """Hull A against hull B: up to 4 contacts written from ``slot`` on; returns their count.

    Each hull: its frame (centre (3,) [m], rotation (3, 3) body → world) and its body-frame arrays
    (:data:`.convex.HullArrays`). ``margin`` [m]: contacts kept down to depth −margin. Outputs
    as in the module docstring; 0 when some axis separates the hulls by more than the margin.
    """
    center_a, rotation_a = frame_a
    center_b, rotation_b = frame_b
    vertices_a, face_normal_a, face_offset_a, face_vertex_start_a, face_vertex_index_a, edge_vertex_a, _ = hull_a
    vertices_b, face_normal_b, _, face_vertex_start_b, face_vertex_index_b, edge_vertex_b, _ = hull_b
    result = np.empty(8)
    axis = np.zeros(3)
    close, vb, nb, ob = convex_convex_sat(frame_a, hull_a, frame_b, hull_b, margin, result, axis)
    if not close:
        return 0
    scale = 0.0
    for i in range(vertices_a.shape[0]):
        scale = max(scale, vertices_a[i, 0] ** 2 + vertices_a[i, 1] ** 2 + vertices_a[i, 2] ** 2)
    for j in range(vertices_b.shape[0]):
        scale = max(scale, vertices_b[j, 0] ** 2 + vertices_b[j, 1] ** 2 + vertices_b[j, 2] ** 2)
    scale = np.sqrt(scale)
    absolute = FACE_ABS_TOL * scale
    over_a = result[0]
    over_b = result[2]
    face_a = int(result[1])
    face_b = int(result[3])
    lower = min(over_a, over_b)
    if max(over_a, over_b) <= lower + FACE_REL_TOL * abs(lower) + absolute:
        # a tie: the larger face is the reference (A's when equal), for stability in time
        area_a = _face_area(vertices_a, face_vertex_start_a, face_vertex_index_a, face_a, face_normal_a[face_a])
        area_b = _face_area(vertices_b, face_vertex_start_b, face_vertex_index_b, face_b, face_normal_b[face_b])
        use_b = area_b > area_a * (1.0 + 1e-9)
    else:
        use_b = over_b < over_a
    face_overlap = over_b if use_b else over_a
    over_e = result[4]
    chosen = 1 if use_b else 0  # 0: face of A, 1: face of B, 2: edge pair
    if over_e < np.inf and face_overlap > over_e + FACE_REL_TOL * abs(over_e) + absolute:
        chosen = 2  # the edge axis is clearly better than any face
    # the exact minimum (first of A's face, B's face, edge on ties)
    exact = 0
    if over_b < over_a:
        exact = 1
    if over_e < min(over_a, over_b):
        exact = 2
    # the favoured axis first; should its face clip to nothing (deep or grazing contact), the
    # exact minimum, whose witness points are sure to lie on both surfaces
    # both hulls in A's frame (vertices, face normals and offsets, face corner lists), and A's pose
    local_a = (vertices_a, face_normal_a, face_offset_a, face_vertex_start_a, face_vertex_index_a)
    local_b = (vb, nb, ob, face_vertex_start_b, face_vertex_index_b)
    frame_a = (center_a, rotation_a)
    for attempt in range(2):
        kind = chosen if attempt == 0 else exact
        if attempt == 1 and exact == chosen:
            break
        fallback = kind == exact
        if kind == 2:
            edges = (int(result[5]), int(result[6]))
            return _edge_contact(
                (vertices_a, edge_vertex_a), (vb, edge_vertex_b), edges, axis, over_e, frame_a, out, slot
            )
        if kind == 1:
            # reference face on B (its outward normal is the contact normal); incident hull A
            clip = FaceClip(face_b, 1.0, margin, scale, fallback)
            count = _face_contacts(local_b, local_a, clip, frame_a, out, slot)
        else:
            # reference face on A (its outward normal points from A to B); incident hull B
            clip = FaceClip(face_a, -1.0, margin, scale, fallback)
            count = _face_contacts(local_a, local_b, clip, frame_a, out, slot)
        if count > 0:
            return count
    return 0


@njit(cache=True, inline="always")
def _segment(p, q):
    """The segment p q (3,) as (centre (3,), unit axis (3,), half length) for
    ``geometry.segment_closest_parameters`` (an edge of no length: any axis, half length 0)."""
    axis = np.empty(3)
    length = np.sqrt((q[0] - p[0]) ** 2 + (q[1] - p[1]) ** 2 + (q[2] - p[2]) ** 2)
    for i in range(3):
        axis[i] = (q[i] - p[i]) / length if length > 0.0 else (1.0 if i == 0 else 0.0)
    center = np.empty(3)
    for i in range(3):
        center[i] = 0.5 * (p[i] + q[i])
    return center, axis, 0.5 * length


@njit(cache=True)
def _edge_contact(edges_a, edges_b, edges, axis, overlap, frame_a, out, slot):
    """One contact midway between the closest points of edge ``ea`` of A and ``eb`` of B
    (``edges``), each hull's edges given as (vertices (·, 3), edge_vertex (E, 2)), all in A's
    frame; ``axis`` (3,) unit from A towards B, ``overlap`` [m] the depth on it."""
    vertices_a, edge_vertex_a = edges_a
    vb, edge_vertex_b = edges_b
    ea, eb = edges
    origin, rotation_a = frame_a
    out_point, out_normal, out_depth, out_feature = out
    # the closest points of the two edges, as the capsules' segments find them (geometry)
    center_a, axis_a, half_a = _segment(vertices_a[edge_vertex_a[ea, 0]], vertices_a[edge_vertex_a[ea, 1]])
    center_b, axis_b, half_b = _segment(vb[edge_vertex_b[eb, 0]], vb[edge_vertex_b[eb, 1]])
    s, t = segment_closest_parameters(center_a, axis_a, half_a, center_b, axis_b, half_b)
    m0 = 0.5 * (center_a[0] + s * axis_a[0] + center_b[0] + t * axis_b[0])
    m1 = 0.5 * (center_a[1] + s * axis_a[1] + center_b[1] + t * axis_b[1])
    m2 = 0.5 * (center_a[2] + s * axis_a[2] + center_b[2] + t * axis_b[2])
    for c in range(3):
        out_point[slot, c] = origin[c] + rotation_a[c, 0] * m0 + rotation_a[c, 1] * m1 + rotation_a[c, 2] * m2
        # the axis points from A towards B; the contact normal from B into A is its opposite
        out_normal[slot, c] = -(rotation_a[c, 0] * axis[0] + rotation_a[c, 1] * axis[1] + rotation_a[c, 2] * axis[2])
    out_depth[slot] = overlap
    out_feature[slot] = _feature_of(-1 - min(ea, eb), -1, max(ea, eb))  # symmetric: swapping A, B keeps it
    return 1
