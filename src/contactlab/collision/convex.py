"""Convex polytopes (hulls) against a plane and a sphere, and the hull arrays every hull routine takes.

Conventions as everywhere in :mod:`contactlab.collision.narrow_phase`: shape A first, the
normal is a unit vector from B into A (the direction that separates A), ``depth`` > 0 when
overlapping, contacts are kept down to ``depth = −margin`` (speculative contacts), each
``point`` lies midway between the two surfaces, and every routine writes its contacts from
``slot`` on into ``out`` = (point (N, 3), normal (N, 3), depth (N,), feature (N,) int64)
(:data:`.contact_output.PairOutput`), and returns how many it wrote (at most ``MAX_CONTACTS`` = 4).

A hull is passed as one argument, its body-frame arrays in this order (:data:`HullArrays`; see
:mod:`contactlab.hulls`, :func:`hulls.hull_arrays`), plus a centre (3,) [m] and a rotation (3, 3)
body → world:

``vertices`` (V, 3) [m]; ``face_normal`` (F, 3) outward unit; ``face_offset`` (F,) [m];
``face_vertex_start`` (F+1,) int and ``face_vertex_index`` (K,) int: face f's corners,
counter-clockwise seen from outside, are ``face_vertex_index[face_vertex_start[f] − s0 :
face_vertex_start[f+1] − s0]`` with ``s0 = face_vertex_start[0]`` (so slices of a packed
layout work unchanged); ``edge_vertex`` (E, 2) int and ``edge_face`` (E, 2) int.
The origin of the body frame must lie inside the hull (it is the centre of mass).
A box is such a hull too: :func:`contactlab.hulls.box_as_hull`.

Algorithms
----------
* ``convex_plane``: every vertex within the margin of the plane is a candidate; more than 4
  are reduced to 4 (below).
* ``sphere_convex``: the largest signed face distance ``s = n·x − offset`` of the centre
  decides: ``s ≤ 0`` the centre is inside, and leaves through that face (least
  penetration); otherwise the closest point of the surface is the projection on that face if
  it falls inside the face polygon, else the closest point over the edges of the faces that
  see the centre.
* Reduction to 4 (``convex_plane``, as hull–hull: :func:`.contact_polygon.reduce_to_four`):
  the deepest point (near-ties, within ``REDUCE_TIE`` × size, to the first in order), the
  point farthest from it in the contact plane, the one making the largest triangle with
  those two, and the one adding most area to that triangle (nothing if it adds none).

Feature numbers (0..255)
------------------------
* ``convex_plane``: the vertex index (``v mod 256``); a hull's box corners keep
  :func:`narrow_phase.box_plane`'s corner numbers. Vertex indices are unique, so features
  collide only for hulls with more than 256 vertices; a collision inside one pair moves to
  the next free number (``+1 mod 256``), so the ≤ 4 contacts of a pair always differ.
* ``sphere_convex``: 0. A pair has one contact, so the pair alone names it, and a constant
  keeps its warm start while the sphere rolls from face to edge to face.

Hull against hull: :mod:`.convex_convex`.

Everything here is compiled (``@njit(cache=True)``), float64, without fastmath.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np

from ..compiling import njit
from ..hulls import box_as_hull  # noqa: F401  (re-exported while branches that import it from here merge)
from .contact_output import Frame, PairOutput
from .contact_polygon import MAX_POINTS, REDUCE_TIE, claim_feature, reduce_to_four

MAX_CONTACTS = MAX_POINTS  # contacts written per pair, at most
SPHERE_FEATURE = 0

# One hull's body-frame arrays, in this order (module docstring): vertices, face_normal,
# face_offset, face_vertex_start, face_vertex_index, edge_vertex, edge_face. Every hull routine
# takes them as this one argument (as :func:`hull_view` and :func:`contactlab.hulls.hull_arrays` give them).
HullArrays = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]

# the candidate contacts of a hull on a plane or a face (``write_reduced``): points (·, 3) [m]
# in the hull's frame, their height (·,) [m] above the plane, and keep[:count], the rows kept
Candidates = namedtuple("Candidates", ["points", "height", "keep", "count"])


@njit(cache=True)
def write_reduced(
    frame: Frame,
    candidates: Candidates,
    axis: np.ndarray,
    tie: float,
    direction: np.ndarray,
    sign: float,
    out: PairOutput,
    slot: int,
) -> int:
    """The contacts of a hull on a plane (``convex_plane``) or on a face (hull–hull,
    :func:`.convex_convex._face_contacts`): of the ``candidates`` (:data:`Candidates`)
    ``keep[:count]``, rows of ``points`` (·, 3) [m] in ``frame`` = (centre (3,) [m], rotation
    (3, 3) → world) at ``height`` (·,) [m] above the plane (unit normal ``axis`` (3,) in that
    frame), at most 4 (``reduce_to_four``; depth ties within ``tie`` [m]), written from ``slot``
    on and moved halfway down to the plane:
    point = frame point − height / 2 · ``direction`` (the plane normal in the world, (3,)),
    normal = ``sign`` · direction, depth = −height. Returns how many; ``keep[:n]`` names them
    (the caller writes their features)."""
    center, rotation = frame
    points, height, keep, count = candidates
    out_point, out_normal, out_depth, _ = out
    if count > MAX_CONTACTS:
        count = reduce_to_four(points, height, keep, count, axis, tie, np.empty(count))
    for k in range(count):
        p = keep[k]
        h = height[p]
        row = slot + k
        for c in range(3):
            x = (
                center[c]
                + rotation[c, 0] * points[p, 0]
                + rotation[c, 1] * points[p, 1]
                + rotation[c, 2] * points[p, 2]
            )
            out_point[row, c] = x - 0.5 * h * direction[c]
            out_normal[row, c] = sign * direction[c]
        out_depth[row] = -h
    return count


# ------------------------------------------------------------------------------------------
# hull against plane


@njit(cache=True)
def convex_plane(frame: Frame, hull: HullArrays, plane: np.ndarray, margin: float, out: PairOutput, slot: int) -> int:
    """Hull A (``frame`` = (centre (3,) [m], rotation (3, 3) body → world), its arrays ``hull``) against the
    plane B = (n, offset) (4,): one contact per vertex within the margin, reduced to at most 4.
    Feature: the vertex index (mod 256, see the module docstring)."""
    center, rotation = frame
    out_feature = out[3]
    vertices = hull[0]
    n0, n1, n2 = plane[0], plane[1], plane[2]
    # the plane normal in the body frame, and the height of the body origin above the plane
    l0 = rotation[0, 0] * n0 + rotation[1, 0] * n1 + rotation[2, 0] * n2
    l1 = rotation[0, 1] * n0 + rotation[1, 1] * n1 + rotation[2, 1] * n2
    l2 = rotation[0, 2] * n0 + rotation[1, 2] * n1 + rotation[2, 2] * n2
    base = center[0] * n0 + center[1] * n1 + center[2] * n2 - plane[3]
    count_vertices = vertices.shape[0]
    height = np.empty(count_vertices)
    keep = np.empty(count_vertices, dtype=np.int64)
    count = 0
    extent = 0.0
    for v in range(count_vertices):
        h = base + vertices[v, 0] * l0 + vertices[v, 1] * l1 + vertices[v, 2] * l2
        height[v] = h
        extent = max(extent, abs(vertices[v, 0]) + abs(vertices[v, 1]) + abs(vertices[v, 2]))
        if h <= margin:
            keep[count] = v
            count += 1
    if count == 0:
        return 0
    # reduced in the hull's frame (the plane normal there is l), as hull–hull reduces its clipped points
    count = write_reduced(
        frame,
        Candidates(vertices, height, keep, count),
        np.array([l0, l1, l2]),
        REDUCE_TIE * extent,
        plane[:3],
        1.0,
        out,
        slot,
    )
    used = np.zeros(256, dtype=np.bool_)
    for k in range(count):
        out_feature[slot + k] = claim_feature(keep[k], used)
    return count


# ------------------------------------------------------------------------------------------
# sphere against hull


@njit(cache=True)
def _closest_on_segment(px, py, pz, a, b, out):
    """Closest point of segment a b (3,) to p, into ``out`` (3,); returns its squared distance."""
    d0, d1, d2 = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    length2 = d0 * d0 + d1 * d1 + d2 * d2
    t = 0.0
    if length2 > 0.0:
        t = ((px - a[0]) * d0 + (py - a[1]) * d1 + (pz - a[2]) * d2) / length2
        t = min(max(t, 0.0), 1.0)
    out[0] = a[0] + t * d0
    out[1] = a[1] + t * d1
    out[2] = a[2] + t * d2
    r0, r1, r2 = px - out[0], py - out[1], pz - out[2]
    return r0 * r0 + r1 * r1 + r2 * r2


@njit(cache=True)
def sphere_convex(
    center: np.ndarray, radius: float, hull_frame: Frame, hull: HullArrays, margin: float, out: PairOutput, slot: int
) -> int:
    """Sphere (or particle: radius ≥ 0) A, centre (3,) [m], against hull B (``hull_frame`` = (centre (3,)
    [m], rotation (3, 3) body → world), its arrays ``hull``): one contact.

    Inside the hull the centre leaves through the face of least penetration; outside, the
    normal runs from the closest surface point to the centre. Feature: ``SPHERE_FEATURE``.
    """
    hull_center, hull_rotation = hull_frame
    out_point, out_normal, out_depth, out_feature = out
    vertices, face_normal, face_offset, face_vertex_start, face_vertex_index = hull[:5]
    r = hull_rotation
    d0 = center[0] - hull_center[0]
    d1 = center[1] - hull_center[1]
    d2 = center[2] - hull_center[2]
    x0 = r[0, 0] * d0 + r[1, 0] * d1 + r[2, 0] * d2  # the centre in the hull's frame
    x1 = r[0, 1] * d0 + r[1, 1] * d1 + r[2, 1] * d2
    x2 = r[0, 2] * d0 + r[1, 2] * d1 + r[2, 2] * d2
    face_count = face_offset.shape[0]
    best = 0
    best_s = -np.inf
    for f in range(face_count):
        s = face_normal[f, 0] * x0 + face_normal[f, 1] * x1 + face_normal[f, 2] * x2 - face_offset[f]
        if s > best_s:
            best_s = s
            best = f
    if best_s > radius + margin:  # the distance is at least best_s: too far
        return 0
    base = face_vertex_start[0]
    closest = np.empty(3)
    candidate = np.empty(3)
    if best_s <= 0.0:
        # inside: out through the face of least penetration
        n0, n1, n2 = face_normal[best, 0], face_normal[best, 1], face_normal[best, 2]
        closest[0] = x0 - best_s * n0
        closest[1] = x1 - best_s * n1
        closest[2] = x2 - best_s * n2
        depth = radius - best_s
    else:
        best_d2 = np.inf
        for f in range(face_count):
            s = face_normal[f, 0] * x0 + face_normal[f, 1] * x1 + face_normal[f, 2] * x2 - face_offset[f]
            if s <= 0.0:
                continue  # this face does not see the centre
            m0, m1, m2 = face_normal[f, 0], face_normal[f, 1], face_normal[f, 2]
            q0, q1, q2 = x0 - s * m0, x1 - s * m1, x2 - s * m2  # projection on the face plane
            start = face_vertex_start[f] - base
            stop = face_vertex_start[f + 1] - base
            corners = stop - start
            inside = True
            for k in range(corners):
                a = vertices[face_vertex_index[start + k]]
                b = vertices[face_vertex_index[start + (k + 1) % corners]]
                e0, e1, e2 = b[0] - a[0], b[1] - a[1], b[2] - a[2]
                # outward side direction (e × m) of this polygon edge
                o0 = e1 * m2 - e2 * m1
                o1 = e2 * m0 - e0 * m2
                o2 = e0 * m1 - e1 * m0
                if (q0 - a[0]) * o0 + (q1 - a[1]) * o1 + (q2 - a[2]) * o2 > 0.0:
                    inside = False
                    break
            if inside:
                if s * s < best_d2:
                    best_d2 = s * s
                    closest[0], closest[1], closest[2] = q0, q1, q2
                if f == best:
                    break  # the largest face distance is a lower bound: done
                continue
            for k in range(corners):
                a = vertices[face_vertex_index[start + k]]
                b = vertices[face_vertex_index[start + (k + 1) % corners]]
                d2_edge = _closest_on_segment(x0, x1, x2, a, b, candidate)
                if d2_edge < best_d2:
                    best_d2 = d2_edge
                    closest[0], closest[1], closest[2] = candidate[0], candidate[1], candidate[2]
        distance = np.sqrt(best_d2)
        depth = radius - distance
        if depth < -margin:
            return 0
    # the normal (hull frame) from the closest point to the centre
    g0, g1, g2 = x0 - closest[0], x1 - closest[1], x2 - closest[2]
    length = np.sqrt(g0 * g0 + g1 * g1 + g2 * g2)
    if best_s <= 0.0 or length <= 1e-12 * (1.0 + abs(best_s)):
        g0, g1, g2 = face_normal[best, 0], face_normal[best, 1], face_normal[best, 2]
    else:
        g0, g1, g2 = g0 / length, g1 / length, g2 / length
    for c in range(3):
        normal = r[c, 0] * g0 + r[c, 1] * g1 + r[c, 2] * g2
        surface_b = hull_center[c] + r[c, 0] * closest[0] + r[c, 1] * closest[1] + r[c, 2] * closest[2]
        surface_a = center[c] - normal * radius
        out_point[slot, c] = 0.5 * (surface_a + surface_b)
        out_normal[slot, c] = normal
    out_depth[slot] = depth
    out_feature[slot] = SPHERE_FEATURE
    return 1


@njit(cache=True)
def hull_view(hull_store: tuple, h: int) -> HullArrays:
    """Hull ``h``'s arrays out of a packed hull store, as views: (vertices, face_normal,
    face_offset, face_vertex_start, face_vertex_index, edge_vertex, edge_face), the argument
    order of the routines here. ``hull_store``: the ten arrays of
    :func:`contactlab.hulls.pack_hulls` as ``Model.hull_store`` orders them (vertex_start,
    vertices, face_start, face_normal, face_offset, face_vertex_start, face_vertex_index,
    edge_start, edge_vertex, edge_face). The compiled twin of :func:`contactlab.hulls.hull_arrays`."""
    (
        vertex_start,
        vertices,
        face_start,
        face_normal,
        face_offset,
        face_vertex_start,
        face_vertex_index,
        edge_start,
        edge_vertex,
        edge_face,
    ) = hull_store
    f0 = face_start[h]
    f1 = face_start[h + 1]
    fvs = face_vertex_start[f0 : f1 + 1]
    return (
        vertices[vertex_start[h] : vertex_start[h + 1]],
        face_normal[f0:f1],
        face_offset[f0:f1],
        fvs,
        face_vertex_index[fvs[0] : fvs[fvs.shape[0] - 1]],
        edge_vertex[edge_start[h] : edge_start[h + 1]],
        edge_face[edge_start[h] : edge_start[h + 1]],
    )


@njit(cache=True)
def stored_hull(hull_store: tuple, index: float) -> HullArrays:
    """Hull number ``index`` (a collider's float parameter) out of a model's packed hull store
    (Model.hull_store), as :func:`hull_view` gives it."""
    return hull_view(hull_store, np.int64(index))
