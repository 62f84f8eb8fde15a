"""Contacts of cloth with itself and with other cloths: vertex–triangle and edge–edge (issue 41).

A cloth's vertices are particles of radius ``thickness``, but two vertices of one cloth make
no particle contact (their springs keep them apart), and a vertex may pass between the
vertices of a triangle. Here the cloths whose ``self_collision`` is on meet as surfaces, after
Bridson, Fedkiw and Anderson (2002):

* **vertex–triangle**: a vertex v and a triangle f that does not have v as a corner, when the
  vertex's distance d to the triangle's closest point q (with barycentric weights w) is within
  the two thicknesses r_v + r_f and the reach. Side A is the vertex (weight 1), side B the
  triangle's three vertices with weights w (SPEC D1: a point carried by three particles); the
  normal is (x_v − q)/d, the face normal on the vertex's side where the vertex lies over the
  triangle's inside;
* **edge–edge**: two edges with no corner in common whose closest points p (on the first,
  weights 1 − s, s) and q (on the second, 1 − t, t) are both strictly inside them, within
  the two thicknesses and the reach. Side A is the first edge, side B the second; the normal
  is (p − q)/|p − q|. A closest point at an edge's end is a vertex near an edge, which the
  vertex–triangle contacts of that edge's triangles already find.

Depth counts from the thicknesses: δ = r_A + r_B − d, > 0 closer than the cloth's thickness
(r of a side: the largest radius of its particles). **Over the swept step**: a pair is a
contact when its gap d − r_A − r_B is at most the margin plus how far its two sides may move
relative to each other in the coming step, max |Δx_i − Δx_j| over a particle i of one side and
j of the other (Δx: each particle's predicted displacement; a point of a side moves by a convex
combination of its particles', so no two points of the sides approach more). Any two elements
that could meet during the step are so found at its start, and each method keeps their gap
from closing past zero (speculative contacts): a fast fold does not tunnel. Relative motion,
not each particle's own: a sheet falling flat at 3 m/s makes no contact with itself. Where only
each particle's swept distance is known (``collide`` called with ``sweep`` alone), the bound is
the sum of the two sides' largest sweeps.

The broad phase is ``broad_phase.elements_between``: a grid of the triangles' boxes that the
vertices' boxes look up, and one of the edges' boxes that they look up themselves (no triangle
is tested against a triangle), passing over the pairs that share a particle (most of the pairs
whose boxes overlap: neighbours). Each box is an element's at the step's start, grown by its
thickness, half the margin and how far its particles move relative to their mean displacement
(``reach_growth``): the cost grows with the number of vertices and of near pairs. The
contacts come vertex–triangle first, by vertex then triangle, then edge–edge, by first then
second edge: an order of the elements alone, the same on every run.

Contact ids: a self-contact names two of its particles as its collider pair, so that
``half_thickness_sums`` reads its pass-through depth r_A + r_B from them, and its element in
the feature: vertex–triangle (vertex, the triangle's first corner) with feature 2 f + 1 (f
the triangle's index in ``Model.triangles``), edge–edge (the first edge's two ends, which
never make a particle pair: they are one cloth's) with feature 2 e + 2 (e the second edge's
index in ``ClothElements.edges``). Particle–particle contacts have feature 0: no id is shared.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from ..compiling import njit
from ..contacts import ContactArrays, Contacts, tangent_frames
from ..model import derived
from .broad_phase import elements_between
from .contact_output import FEATURE_BITS

if TYPE_CHECKING:
    from ..model import Model
    from ..state import State


class ClothElements(NamedTuple):
    """The elements of the cloths whose ``self_collision`` is on, or of every cloth
    (:func:`every_cloth_element`), by global particle indices (a named tuple: compiled code
    takes it whole)."""

    triangles: np.ndarray
    """(F', 3) int64, the corners of each triangle"""
    triangle_index: np.ndarray
    """(F',) int64, each one's index in ``Model.triangles``"""
    edges: np.ndarray
    """(E, 2) int64, the triangles' edges, each once, lower index first, sorted"""
    vertices: np.ndarray
    """(V,) int64, the particles that are corners of those triangles, sorted"""

    @property
    def empty(self) -> bool:
        return len(self.triangles) == 0


@derived
def cloth_elements(model: Model) -> ClothElements:
    """The ClothElements of ``model``, built once and kept with it."""
    return _elements(model, only_self_colliding=True)


@derived
def every_cloth_element(model: Model) -> ClothElements:
    """The elements of every cloth of ``model``, its ``self_collision`` on or off (what a
    crossing is counted on where the cloth was let pass through itself), built once and kept."""
    return _elements(model, only_self_colliding=False)


def _elements(model: Model, only_self_colliding: bool) -> ClothElements:
    """The ClothElements of the cloths of ``model`` whose self_collision is on, or of all."""
    triangles = np.asarray(model.triangles, dtype=np.int64).reshape(-1, 3)
    cloth = model.particle_cloth[triangles[:, 0]] if len(triangles) else np.zeros(0, dtype=np.int64)
    flags = np.asarray(model.cloth_self_collision, dtype=bool)
    if not only_self_colliding:
        flags = np.ones_like(flags)
    chosen = np.nonzero(flags[cloth])[0] if len(triangles) else cloth
    kept = triangles[chosen]
    edges = np.sort(kept[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    edges = np.unique(edges, axis=0) if len(edges) else np.zeros((0, 2), dtype=np.int64)
    return ClothElements(
        triangles=kept,
        triangle_index=chosen.astype(np.int64),
        edges=edges.astype(np.int64),
        vertices=np.unique(kept).astype(np.int64),
    )


class SelfContactModel(NamedTuple):
    """What ``self_contact_arrays`` takes of a Model: built once and kept with it
    (:func:`self_contact_model`)."""

    elements: ClothElements
    """the elements of the self-colliding cloths (``cloth_elements``)"""
    radius: np.ndarray
    """(P,) [m], each particle's radius (its cloth's thickness)"""
    material: np.ndarray
    """(P,) int64, each particle's material"""
    material_friction: np.ndarray
    """(M,), each material's friction coefficient"""
    material_restitution: np.ndarray
    """(M,), each material's restitution"""
    body_count: int
    """B, the bodies before the particles among the colliders"""
    total: int
    """N = B + P + O, the collider count of the contact ids"""


@derived
def self_contact_model(model: Model) -> SelfContactModel:
    """The SelfContactModel of ``model``, built once and kept with it."""
    return SelfContactModel(
        cloth_elements(model),
        np.ascontiguousarray(model.particle_radius, dtype=float),
        np.ascontiguousarray(model.particle_material, dtype=np.int64),
        np.ascontiguousarray(model.material_friction, dtype=float),
        np.ascontiguousarray(model.material_restitution, dtype=float),
        int(model.body_count),
        int(model.body_count + model.particle_count + model.obstacle_count),
    )


def cloth_self_contacts(
    model: Model, state: State, margin: float, sweep: np.ndarray | None, particle_motion: np.ndarray | None = None
) -> Contacts:
    """The vertex–triangle and edge–edge contacts of the self-colliding cloths at ``state``.

    margin [m]: gaps down to this are kept; particle_motion (P, 3) [m]: each particle's
    predicted displacement over the coming step, whose relative part widens the reach (see the
    module); None: the sweep (B + P,) [m] of each body and particle bounds it instead (None too:
    standing still)."""
    cloth = self_contact_model(model)
    if cloth.elements.empty:
        return Contacts.empty()
    P = model.particle_count
    if particle_motion is not None:
        motion, spare = np.ascontiguousarray(particle_motion, dtype=float).reshape(P, 3), np.zeros(P)
    else:
        motion = np.zeros((P, 3))
        spare = np.array(sweep[model.body_count :], dtype=float) if sweep is not None else np.zeros(P)
    position = np.ascontiguousarray(state.particle_position, dtype=float)
    return Contacts.from_arrays(self_contact_arrays(position, (motion, spare, float(margin)), cloth))


def is_self_contact(contacts: Contacts) -> np.ndarray:
    """(C,) bool: the contacts made here — the only ones whose side B is carried by two
    particles or more (a triangle or an edge)."""
    return np.asarray(contacts.particles_b)[:, 1] >= 0


# ---- the compiled detection ----------------------------------------------------------------------


Point = np.ndarray | tuple[float, float, float]
"""A point (3,) [m]: a row of an array, or three floats (``_point``: no array view to make in a
loop over pairs)."""

Reach = tuple[np.ndarray, np.ndarray, float]
"""What widens a pair's reach beyond the thicknesses: (motion (P, 3) [m], each particle's
predicted displacement; spare (P,) [m], a distance each particle may move besides; margin [m])."""


@njit(cache=True)
def allowed_gap(reach: Reach, side_a: np.ndarray, side_b: np.ndarray) -> float:
    """The largest gap [m] at which the particles ``side_a`` and ``side_b`` (ints: tuples) make a
    contact: the margin, the most any particle of one side moves relative to one of the other,
    and each side's largest spare distance (see ``Reach``)."""
    motion, spare, margin = reach
    most = spare_a = spare_b = 0.0
    for i in side_a:
        spare_a = max(spare_a, spare[i])
        for j in side_b:
            dx, dy, dz = motion[i, 0] - motion[j, 0], motion[i, 1] - motion[j, 1], motion[i, 2] - motion[j, 2]
            most = max(most, dx * dx + dy * dy + dz * dz)
    for j in side_b:
        spare_b = max(spare_b, spare[j])
    return margin + np.sqrt(most) + spare_a + spare_b


@njit(cache=True)
def closest_on_triangle(x: Point, a: Point, b: Point, c: Point) -> tuple[float, float, float, bool]:
    """The point of triangle (a, b, c) (3,) [m] closest to x (3,) [m] (arrays or tuples), as its barycentric weights
    (w_a, w_b, w_c), and whether it lies strictly inside the triangle (not on an edge or a
    corner). Ericson, *Real-Time Collision Detection*, 5.1.5; a degenerate triangle (two corners
    at one point, or all three on a line) gives the closest of its corner and edge points."""
    ab0, ab1, ab2 = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    ac0, ac1, ac2 = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    ap0, ap1, ap2 = x[0] - a[0], x[1] - a[1], x[2] - a[2]
    d1 = ab0 * ap0 + ab1 * ap1 + ab2 * ap2
    d2 = ac0 * ap0 + ac1 * ap1 + ac2 * ap2
    if d1 <= 0.0 and d2 <= 0.0:
        return 1.0, 0.0, 0.0, False
    bp0, bp1, bp2 = x[0] - b[0], x[1] - b[1], x[2] - b[2]
    d3 = ab0 * bp0 + ab1 * bp1 + ab2 * bp2
    d4 = ac0 * bp0 + ac1 * bp1 + ac2 * bp2
    if d3 >= 0.0 and d4 <= d3:
        return 0.0, 1.0, 0.0, False
    vc = d1 * d4 - d3 * d2
    # an edge's region only where it has a length (d1 − d3 = |ab|², d2 − d6 = |ac|², (d4 − d3) +
    # (d5 − d6) = |bc|²): a point-like edge's test holds everywhere (its v is 0), its parameter 0 / 0
    if d1 - d3 > 0.0 and vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return 1.0 - v, v, 0.0, False
    cp0, cp1, cp2 = x[0] - c[0], x[1] - c[1], x[2] - c[2]
    d5 = ab0 * cp0 + ab1 * cp1 + ab2 * cp2
    d6 = ac0 * cp0 + ac1 * cp1 + ac2 * cp2
    if d6 >= 0.0 and d5 <= d6:
        return 0.0, 0.0, 1.0, False
    vb = d5 * d2 - d1 * d6
    if d2 - d6 > 0.0 and vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return 1.0 - w, 0.0, w, False
    va = d3 * d6 - d5 * d4
    if (d4 - d3) + (d5 - d6) > 0.0 and va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return 0.0, 1.0 - w, w, False
    if not va + vb + vc > 0.0:  # |ab × ac|² = 0, a triangle on a line that rounding let through: its edges
        return _closest_on_edges(x, a, b, c)
    denominator = 1.0 / (va + vb + vc)
    v = vb * denominator
    w = vc * denominator
    return 1.0 - v - w, v, w, True


@njit(cache=True)
def _closest_on_edges(x: Point, a: Point, b: Point, c: Point) -> tuple[float, float, float, bool]:
    """``closest_on_triangle`` for a triangle with no area: the closest point of its three edges,
    as barycentric weights, never inside."""
    corners = (a, b, c)
    best, weights = np.inf, np.array([1.0, 0.0, 0.0])
    for first in range(3):
        second = (first + 1) % 3
        start, end = corners[first], corners[second]
        s, _ = closest_on_segments(start, end, x, x)
        gap = 0.0
        for k in range(3):
            gap += (start[k] + s * (end[k] - start[k]) - x[k]) ** 2
        if gap < best:
            best = gap
            weights[:] = 0.0
            weights[first], weights[second] = 1.0 - s, s
    return weights[0], weights[1], weights[2], False


@njit(cache=True)
def closest_on_segments(p1: Point, q1: Point, p2: Point, q2: Point) -> tuple[float, float]:
    """Parameters (s, t) in [0, 1] of the closest points p1 + s (q1 − p1) and p2 + t (q2 − p2)
    of two segments (3,) [m] each (arrays or tuples); an end where clamped (exactly 0 or 1). Ericson, *Real-Time
    Collision Detection*, 5.1.9; for (nearly) parallel segments the closest of the pairs that put
    one segment's end against the other and of their crossing, s = 0 first (a tie: the overlap of
    parallel segments)."""
    d10, d11, d12 = q1[0] - p1[0], q1[1] - p1[1], q1[2] - p1[2]
    d20, d21, d22 = q2[0] - p2[0], q2[1] - p2[1], q2[2] - p2[2]
    r0, r1, r2 = p1[0] - p2[0], p1[1] - p2[1], p1[2] - p2[2]
    a = d10 * d10 + d11 * d11 + d12 * d12
    e = d20 * d20 + d21 * d21 + d22 * d22
    f = d20 * r0 + d21 * r1 + d22 * r2
    tiny = 1e-30
    if a <= tiny and e <= tiny:
        return 0.0, 0.0
    if a <= tiny:
        return 0.0, min(max(f / e, 0.0), 1.0)
    c = d10 * r0 + d11 * r1 + d12 * r2
    if e <= tiny:
        return min(max(-c / a, 0.0), 1.0), 0.0
    b = d10 * d20 + d11 * d21 + d12 * d22
    denominator = a * e - b * b
    parallel = not denominator > 1e-12 * a * e
    s = 0.0 if parallel else min(max((b * f - c * e) / denominator, 0.0), 1.0)
    s, t = _clamped_pair(s, a, b, c, e, f)
    if parallel:  # s = 1, t = 0 and t = 1 too (parallel: an end is closest), and the crossing of
        # two skew segments barely off parallel, whose s loses digits (divided by ~0) but not all
        d1, d2 = (d10, d11, d12), (d20, d21, d22)
        best = _gap_squared(s, t, p1, p2, d1, d2)
        crossing = min(max((b * f - c * e) / denominator, 0.0), 1.0) if denominator > 0.0 else 0.0
        ends = (
            _clamped_pair(crossing, a, b, c, e, f),
            _clamped_pair(1.0, a, b, c, e, f),
            (min(max(-c / a, 0.0), 1.0), 0.0),
            (min(max((b - c) / a, 0.0), 1.0), 1.0),
        )
        for s_end, t_end in ends:
            gap = _gap_squared(s_end, t_end, p1, p2, d1, d2)
            if gap < best:
                s, t, best = s_end, t_end, gap
    return s, t


@njit(cache=True, inline="always")
def _clamped_pair(s: float, a: float, b: float, c: float, e: float, f: float) -> tuple[float, float]:
    """``closest_on_segments``' t for a given s, and where t leaves [0, 1] it clamped and s taken
    again for it (Ericson's terms a, b, c, e, f)."""
    t = (b * s + f) / e
    if t < 0.0:
        return min(max(-c / a, 0.0), 1.0), 0.0
    if t > 1.0:
        return min(max((b - c) / a, 0.0), 1.0), 1.0
    return s, t


@njit(cache=True, inline="always")
def _gap_squared(s: float, t: float, p1: Point, p2: Point, d1: tuple, d2: tuple) -> float:
    """|p1 + s d1 − (p2 + t d2)|² [m²]."""
    gap = 0.0
    for k in range(3):
        gap += (p1[k] + s * d1[k] - p2[k] - t * d2[k]) ** 2
    return gap


@njit(cache=True, inline="always")
def _point(position: np.ndarray, i: int) -> tuple[float, float, float]:
    """Row i of ``position`` (P, 3) [m] as three floats."""
    return position[i, 0], position[i, 1], position[i, 2]


Touch = tuple[bool, float, tuple[float, float, float], tuple[float, float, float]]
"""What ``vertex_triangle`` and ``edge_edge`` say of a pair of elements besides their weights:
(whether a contact's normal is defined, its depth δ [m], its point (3,) [m] midway between the
surfaces, its unit normal (3,) from side B to side A). It is a contact where the normal is
defined and δ ≥ −``allowed_gap``."""


@njit(cache=True)
def vertex_triangle(
    x: Point, a: Point, b: Point, c: Point, radius_a: float, radius_b: float
) -> tuple[tuple[float, float, float], Touch]:
    """The vertex–triangle test (see the module) of the vertex at x (3,) [m] of radius
    ``radius_a`` [m] against the triangle (a, b, c) (3,) [m] of thickness ``radius_b`` (its
    corners' largest radius). Returns (the weights (w_a, w_b, w_c) of the triangle's closest
    point, the ``Touch``). Points and numbers alone, no array: called on every pair the
    broad phase finds, it costs no more than its arithmetic."""
    wa, wb, wc, inside = closest_on_triangle(x, a, b, c)
    g0 = x[0] - (wa * a[0] + wb * b[0] + wc * c[0])
    g1 = x[1] - (wa * a[1] + wb * b[1] + wc * c[1])
    g2 = x[2] - (wa * a[2] + wb * b[2] + wc * c[2])
    distance = np.sqrt(g0 * g0 + g1 * g1 + g2 * g2)
    depth = radius_a + radius_b - distance
    e0, e1, e2 = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    f0, f1, f2 = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    n0, n1, n2 = e1 * f2 - e2 * f1, e2 * f0 - e0 * f2, e0 * f1 - e1 * f0
    area = np.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
    defined = True
    if inside and area > 0.0:  # over the inside: the face normal, on the vertex's side
        side = 1.0 if n0 * g0 + n1 * g1 + n2 * g2 >= 0.0 else -1.0
        n0, n1, n2 = side * n0 / area, side * n1 / area, side * n2 / area
    elif distance > 0.0:
        n0, n1, n2 = g0 / distance, g1 / distance, g2 / distance
    elif area > 0.0:
        n0, n1, n2 = n0 / area, n1 / area, n2 / area
    else:  # a vertex on the corner of a degenerate triangle: no direction to push along
        defined = False
    lift = radius_b - 0.5 * depth  # from the triangle's closest point to midway
    point = (x[0] - g0 + lift * n0, x[1] - g1 + lift * n1, x[2] - g2 + lift * n2)
    return (wa, wb, wc), (defined, depth, point, (n0, n1, n2))


@njit(cache=True)
def edge_edge(
    p1: Point, q1: Point, p2: Point, q2: Point, radius_a: float, radius_b: float
) -> tuple[tuple[float, float], Touch]:
    """The edge–edge test (see the module) of the edge p1–q1 (3,) [m] of thickness
    ``radius_a`` [m] against the edge p2–q2 of ``radius_b``. Returns ((s, t), the weights of the
    second end of each edge at their closest points, the ``Touch``), its normal undefined
    where a closest point is an end of its edge (0 or 1: a vertex near an edge, which the
    vertex–triangle contacts find) — most pairs, which leave here. As ``vertex_triangle``: no
    array."""
    s, t = closest_on_segments(p1, q1, p2, q2)
    nowhere = (0.0, 0.0, 0.0)
    if not (0.0 < s < 1.0 and 0.0 < t < 1.0):
        return (s, t), (False, 0.0, nowhere, nowhere)
    y0, y1, y2 = p2[0] + t * (q2[0] - p2[0]), p2[1] + t * (q2[1] - p2[1]), p2[2] + t * (q2[2] - p2[2])
    g0 = p1[0] + s * (q1[0] - p1[0]) - y0
    g1 = p1[1] + s * (q1[1] - p1[1]) - y1
    g2 = p1[2] + s * (q1[2] - p1[2]) - y2
    distance = np.sqrt(g0 * g0 + g1 * g1 + g2 * g2)
    depth = radius_a + radius_b - distance
    if distance > 0.0:
        n0, n1, n2 = g0 / distance, g1 / distance, g2 / distance
    else:  # the edges cross: the normal of the plane of the two
        e0, e1, e2 = q1[0] - p1[0], q1[1] - p1[1], q1[2] - p1[2]
        f0, f1, f2 = q2[0] - p2[0], q2[1] - p2[1], q2[2] - p2[2]
        n0, n1, n2 = e1 * f2 - e2 * f1, e2 * f0 - e0 * f2, e0 * f1 - e1 * f0
        length = np.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
        if length == 0.0:
            return (s, t), (False, depth, nowhere, nowhere)
        n0, n1, n2 = n0 / length, n1 / length, n2 / length
    lift = radius_b - 0.5 * depth
    return (s, t), (True, depth, (y0 + lift * n0, y1 + lift * n1, y2 + lift * n2), (n0, n1, n2))


@njit(cache=True)
def self_contact_arrays(position: np.ndarray, reach: Reach, cloth: SelfContactModel) -> ContactArrays:
    """``cloth_self_contacts``, compiled: the ContactArrays of the vertex–triangle contacts, by
    vertex then triangle, then of the edge–edge ones, by first then second edge (the broad
    phase's order).

    position (P, 3) [m]; reach, a ``Reach``; cloth, the model's ``SelfContactModel``. Only the
    pairs that the broad phase finds near and sharing no particle are tested, in scalars: a
    few times as many as the contacts."""
    elements, radius = cloth.elements, cloth.radius
    triangles, edges, vertices = elements.triangles, elements.edges, elements.vertices
    grow = reach_growth(radius, reach, vertices)
    near = elements_between(position, grow, vertices.reshape(vertices.shape[0], 1), triangles, False)
    edge_pairs = elements_between(position, grow, edges, edges, True)
    capacity = near.shape[0] + edge_pairs.shape[0]
    particles_a = np.full((capacity, 3), -1, dtype=np.int64)
    particles_b = np.full((capacity, 3), -1, dtype=np.int64)
    weights_a, weights_b = np.zeros((capacity, 3)), np.zeros((capacity, 3))
    point, normal = np.empty((capacity, 3)), np.empty((capacity, 3))
    depth, friction, restitution = np.empty(capacity), np.empty(capacity), np.empty(capacity)
    feature_id = np.empty(capacity, dtype=np.int64)
    B, N = cloth.body_count, cloth.total
    count = 0
    for k in range(near.shape[0]):
        f = near[k, 1]
        v = vertices[near[k, 0]]
        corners = (triangles[f, 0], triangles[f, 1], triangles[f, 2])
        a, b, c = _point(position, corners[0]), _point(position, corners[1]), _point(position, corners[2])
        side_radius = max(radius[corners[0]], radius[corners[1]], radius[corners[2]])
        weights, (defined, d, at, unit) = vertex_triangle(_point(position, v), a, b, c, radius[v], side_radius)
        if not defined or d < -allowed_gap(reach, (v,), corners):
            continue
        particles_a[count, 0] = v
        weights_a[count, 0] = 1.0
        particles_b[count, 0], particles_b[count, 1], particles_b[count, 2] = corners
        weights_b[count, 0], weights_b[count, 1], weights_b[count, 2] = weights
        pair = (B + v) * N + B + corners[0]
        feature_id[count] = (pair << FEATURE_BITS) | (2 * elements.triangle_index[f] + 1)
        depth[count] = d
        point[count, 0], point[count, 1], point[count, 2] = at
        normal[count, 0], normal[count, 1], normal[count, 2] = unit
        friction[count], restitution[count] = _materials(cloth, v, corners[0])
        count += 1
    for k in range(edge_pairs.shape[0]):
        e, g = edge_pairs[k, 0], edge_pairs[k, 1]
        first, second = (edges[e, 0], edges[e, 1]), (edges[g, 0], edges[g, 1])
        p1, q1 = _point(position, first[0]), _point(position, first[1])
        p2, q2 = _point(position, second[0]), _point(position, second[1])
        radius_a, radius_b = max(radius[first[0]], radius[first[1]]), max(radius[second[0]], radius[second[1]])
        (s, t), (defined, d, at, unit) = edge_edge(p1, q1, p2, q2, radius_a, radius_b)
        if not defined or d < -allowed_gap(reach, first, second):
            continue
        particles_a[count, 0], particles_a[count, 1] = first
        weights_a[count, 0], weights_a[count, 1] = 1.0 - s, s
        particles_b[count, 0], particles_b[count, 1] = second
        weights_b[count, 0], weights_b[count, 1] = 1.0 - t, t
        pair = (B + first[0]) * N + B + first[1]
        feature_id[count] = (pair << FEATURE_BITS) | (2 * g + 2)
        depth[count] = d
        point[count, 0], point[count, 1], point[count, 2] = at
        normal[count, 0], normal[count, 1], normal[count, 2] = unit
        friction[count], restitution[count] = _materials(cloth, first[0], second[0])
        count += 1
    unit_normal = np.ascontiguousarray(normal[:count])
    t1, t2 = tangent_frames(unit_normal)
    nobody = np.full(count, -1, dtype=np.int64)
    return ContactArrays(
        nobody,
        nobody.copy(),
        particles_a[:count].copy(),
        particles_b[:count].copy(),
        weights_a[:count].copy(),
        weights_b[:count].copy(),
        point[:count].copy(),
        unit_normal,
        depth[:count].copy(),
        t1,
        t2,
        friction[:count].copy(),
        restitution[:count].copy(),
        feature_id[:count].copy(),
    )


@njit(cache=True)
def reach_growth(radius: np.ndarray, reach: Reach, vertices: np.ndarray) -> np.ndarray:
    """How far (P,) [m] the broad phase grows each particle's box about its start position: its
    radius, spare distance and half the margin, and how far it moves relative to ū, the mean
    displacement of ``vertices`` (V,). As |Δx_i − Δx_j| ≤ |Δx_i − ū| + |Δx_j − ū|, every pair
    ``allowed_gap`` lets make a contact has overlapping boxes so grown: the broad phase of
    ``self_contact_arrays`` misses none of the pairs a test of every pair would find."""
    motion, spare, margin = reach
    mean = np.zeros(3)
    for p in vertices:
        for d in range(3):
            mean[d] += motion[p, d] / max(vertices.shape[0], 1)
    grow = np.empty(radius.shape[0])
    for p in range(radius.shape[0]):
        dx, dy, dz = motion[p, 0] - mean[0], motion[p, 1] - mean[1], motion[p, 2] - mean[2]
        grow[p] = radius[p] + spare[p] + 0.5 * margin + np.sqrt(dx * dx + dy * dy + dz * dz)
    return grow


@njit(cache=True, inline="always")
def _materials(cloth: SelfContactModel, i: int, j: int) -> tuple[float, float]:
    """(μ, ε) of the materials of particles i and j combined as ``Model.pair_materials`` does."""
    a, b = cloth.material[i], cloth.material[j]
    return (
        np.sqrt(cloth.material_friction[a] * cloth.material_friction[b]),
        max(cloth.material_restitution[a], cloth.material_restitution[b]),
    )


# ---- crossings: the health check's test --------------------------------------------------------


def crossings(model: Model, particle_position: np.ndarray, every_cloth: bool = False) -> np.ndarray:
    """The (edge, triangle) pairs (K, 2) of the self-colliding cloths (``every_cloth``: of all
    cloths) at ``particle_position`` (P, 3) [m] where an edge passes through a triangle it has no
    corner of: indices into ``cloth_elements(model)`` (``every_cloth_element(model)``)'s
    ``edges`` and ``triangles``. None is the goal of self-contact."""
    elements = every_cloth_element(model) if every_cloth else cloth_elements(model)
    if elements.empty:
        return np.zeros((0, 2), dtype=np.int64)
    return edge_triangle_crossings(
        np.ascontiguousarray(particle_position, dtype=float), elements.triangles, elements.edges
    )


@njit(cache=True)
def edge_triangle_crossings(position: np.ndarray, triangles: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """``crossings``, compiled: the broad phase over the edges' and triangles' boxes, then for
    each (edge, triangle) pair with no shared corner (by edge, then triangle) whether the segment's ends lie strictly on
    the two sides of the triangle's plane and the point where it meets the plane inside the
    triangle (closed; an edge lying in the plane is not counted). position (P, 3) [m], triangles
    (F', 3), edges (E, 2). Returns (K, 2) int64 (edge, triangle)."""
    near = elements_between(position, np.zeros(position.shape[0]), edges, triangles, False)
    out = np.empty((near.shape[0], 2), dtype=np.int64)
    count = 0
    for k in range(near.shape[0]):
        e, f = near[k, 0], near[k, 1]
        a, b = edges[e, 0], edges[e, 1]
        corners = triangles[f]
        if segment_crosses_triangle(
            position[a], position[b], position[corners[0]], position[corners[1]], position[corners[2]]
        ):
            out[count, 0], out[count, 1] = e, f
            count += 1
    return out[:count].copy()


@njit(cache=True)
def segment_crosses_triangle(p: np.ndarray, q: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> bool:
    """Whether segment p–q (3,) [m] passes through triangle (a, b, c): p and q strictly on
    opposite sides of its plane and the crossing point inside it (edges included). In scalars
    (most candidate pairs leave at the first test, having allocated nothing)."""
    n0, n1, n2 = _cross(b[0] - a[0], b[1] - a[1], b[2] - a[2], c[0] - a[0], c[1] - a[1], c[2] - a[2])
    dp = n0 * (p[0] - a[0]) + n1 * (p[1] - a[1]) + n2 * (p[2] - a[2])
    dq = n0 * (q[0] - a[0]) + n1 * (q[1] - a[1]) + n2 * (q[2] - a[2])
    if not ((dp > 0.0 and dq < 0.0) or (dp < 0.0 and dq > 0.0)):
        return False
    along = dp / (dp - dq)
    x0, x1, x2 = p[0] + along * (q[0] - p[0]), p[1] + along * (q[1] - p[1]), p[2] + along * (q[2] - p[2])
    # inside: x on the inner side of each edge (u → w), measured along the normal
    for i in range(3):
        u = a if i == 0 else (b if i == 1 else c)
        w = b if i == 0 else (c if i == 1 else a)
        s0, s1, s2 = _cross(w[0] - u[0], w[1] - u[1], w[2] - u[2], x0 - u[0], x1 - u[1], x2 - u[2])
        if s0 * n0 + s1 * n1 + s2 * n2 < 0.0:
            return False
    return True


@njit(cache=True, inline="always")
def _cross(a0: float, a1: float, a2: float, b0: float, b1: float, b2: float) -> tuple[float, float, float]:
    """a × b of two vectors given by their components, as np.cross computes it."""
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0
