"""Contacts of cloth against static obstacles: at triangle samples (SPEC P2c) and where an
obstacle's edge or corner reaches a triangle between its vertices.

A cloth's vertices are particles, so collision detection already keeps each of them a radius
(the cloth's thickness) from every surface (P2b). A coarse cloth can still be pierced between
its vertices — a table's corner poking up through the middle of a triangle. Here every cloth
triangle is also sampled, ``samples × samples`` points per triangle (the centroids of its
k-subdivision, see ``collision.granularity.surface_contacts``), and each sample closer to an obstacle
than the thickness is a contact whose side A is the triangle's three particles with the
sample's barycentric weights: a response at the sample moves vertex i by its share w_i (D1).

Samples thin the gaps, they do not close them: a rod narrower than the samples' spacing still
passes between them. So every method also gets, at its defaults, the *face contacts*
(``cloth_face_contacts``): for each triangle near a box or sphere obstacle, the point of the
triangle closest to it (for a sphere the point closest to its centre; for a box alternating
projections between the two convex sets, which meet the closest pair of disjoint ones), made a
contact where that point lies on an edge or inside the face and comes closer to the obstacle
than every vertex by more than half the thickness — an obstacle's edge or corner between the
vertices, which the vertices' own contacts do not see. A plane is always nearest a vertex; a
static mesh keeps its vertex and sample contacts.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .. import shapes
from ..compiling import njit
from ..contacts import Contacts, tangent_basis
from ..model import derived
from .cloth_self import closest_on_triangle
from .contact_output import FEATURE_BITS
from .granularity import SURFACES, DetectionSettings, surface_contacts
from .signed_distance import ShapeObstacle, model_obstacle, shape_signed_distance

if TYPE_CHECKING:
    from ..model import Model
    from ..state import State


def cloth_sample_contacts(
    model: Model, state: State, samples: int, normal: str, margin: float, feature_base: int
) -> Contacts:
    """Contacts of the samples of every cloth triangle with every static plane, sphere, box and mesh.

    samples: per triangle edge (k × k per triangle); normal: "object" (P4) or "vertex" (P5);
    margin [m]: gaps down to this beyond the thickness are kept; feature_base: the first
    contact-id pair number free for these contacts (ids are (feature_base + triangle · O +
    obstacle) << 24 | sample). Depth counts from the thickness: > 0 when a sample is closer
    to the surface than the cloth's thickness.
    """
    triangles = model.triangles
    obstacles = np.nonzero(np.isin(model.obstacle_shape, SURFACES))[0]
    if samples < 1 or len(triangles) == 0 or len(obstacles) == 0:
        return Contacts.empty()
    thickness = model.particle_radius
    reach = margin + float(thickness[triangles].max())
    per_triangle = samples * samples
    parts = []
    for o in obstacles:
        surface = (
            model.meshes[int(model.obstacle_params[o, 0])]
            if model.obstacle_shape[o] == shapes.MESH
            else model_obstacle(model, o)
        )
        found = surface_contacts(
            state.particle_position, triangles, surface, DetectionSettings(reach, "samples", normal, samples)
        )
        depth = found.depth + np.einsum("ck,ck->c", found.weights, thickness[found.vertices])
        keep = depth >= -margin
        if not keep.any():
            continue
        triangle = found.feature[keep] // per_triangle
        pair = feature_base + triangle * model.obstacle_count + o
        parts.append(
            triangle_contacts(
                model,
                o,
                (found.vertices[keep], found.weights[keep]),
                (found.point[keep], found.normal[keep], depth[keep]),
                (pair << FEATURE_BITS) | (found.feature[keep] % per_triangle),
            )
        )
    return Contacts.concatenate(parts)


def triangle_contacts(
    model: Model, obstacle: int, on_cloth: tuple[np.ndarray, np.ndarray], where: tuple, ids: np.ndarray
) -> Contacts:
    """C contacts of points of cloth triangles with static ``obstacle``: ``on_cloth`` = (each
    point's triangle corners (C, 3) as particles, its barycentric weights (C, 3)), ``where`` =
    (point (C, 3) [m], normal (C, 3) from the obstacle into the cloth, depth (C,) [m]), the
    contact ``ids`` (C,); the friction and restitution of the cloth's material with the obstacle's."""
    vertices, weights = on_cloth
    point, normal, depth = where
    count = len(vertices)
    t1, t2 = tangent_basis(normal)
    friction, restitution = model.pair_materials(
        model.particle_material[vertices[:, 0]], np.full(count, model.obstacle_material[obstacle])
    )
    return Contacts(
        body_a=np.full(count, -1),
        body_b=np.full(count, -1),
        particles_a=vertices,
        particles_b=np.full((count, 3), -1),
        weights_a=weights,
        weights_b=np.zeros((count, 3)),
        point=point,
        normal=normal,
        depth=depth,
        tangent1=t1,
        tangent2=t2,
        friction=friction,
        restitution=restitution,
        feature_id=ids,
    )


FACE = (1 << FEATURE_BITS) - 1  # a face contact's feature within its (triangle, obstacle) pair: no sample's index
PROJECTIONS = 12  # alternating projections a triangle makes towards a box
EDGE_SNAP = 1e-3  # a barycentric weight below this is an edge's or a corner's point (0.1 % of the triangle across)


def cloth_face_contacts(model: Model, state: State, margin: float, feature_base: int) -> Contacts:
    """Contacts where a box or sphere obstacle reaches a cloth triangle between its vertices (see
    the module): at most one per triangle and obstacle, side A the triangle's particles with the
    point's barycentric weights, the obstacle's outward normal there (P4), depth counted from the
    thickness. margin [m]: gaps down to this beyond the thickness are kept; ids as the samples'
    (``cloth_sample_contacts``), with the feature ``FACE``."""
    triangles = model.triangles
    obstacles = np.nonzero(np.isin(model.obstacle_shape, (shapes.SPHERE, shapes.BOX)))[0]
    if len(triangles) == 0 or len(obstacles) == 0:
        return Contacts.empty()
    parts = []
    positions = np.asarray(state.particle_position, dtype=float)
    thickness = np.asarray(model.particle_radius, dtype=float)
    owned = edge_owned(model)
    for o in obstacles:
        triangle, weights, point, normal, depth = faces_against(
            positions, triangles, owned, thickness, model_obstacle(model, o), float(margin)
        )
        if len(triangle):
            pair = feature_base + triangle * model.obstacle_count + o
            parts.append(
                triangle_contacts(
                    model, o, (triangles[triangle], weights), (point, normal, depth), (pair << FEATURE_BITS) | FACE
                )
            )
    return Contacts.concatenate(parts)


@derived
def edge_owned(model: Model) -> np.ndarray:
    """(T, 3) bool: whether triangle t owns its edge k (corners k, k + 1): the first triangle
    holding an edge owns it, so a point on an edge two triangles share makes one contact."""
    triangles = np.asarray(model.triangles, dtype=np.int64)
    edges = np.stack([triangles, np.roll(triangles, -1, axis=1)], axis=-1).reshape(-1, 2)
    edges.sort(axis=1)
    _, first = np.unique(edges, axis=0, return_index=True)
    owned = np.zeros(len(edges), dtype=np.bool_)
    owned[first] = True
    return owned.reshape(-1, 3)


@njit(cache=True)
def _distance(kind, params, position, rotation, x):
    """[m] the signed distance of x (3,) from the obstacle (``shape_signed_distance``'s), a
    sphere's without the arrays that function returns (the face contacts ask it of every vertex)."""
    if kind == shapes.SPHERE:
        return np.sqrt((x[0] - position[0]) ** 2 + (x[1] - position[1]) ** 2 + (x[2] - position[2]) ** 2) - params[0]
    return shape_signed_distance(kind, params, position, rotation, x)[0]


@njit(cache=True)
def faces_against(
    positions: np.ndarray,
    triangles: np.ndarray,
    owned: np.ndarray,
    thickness: np.ndarray,
    obstacle: ShapeObstacle,
    margin: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``cloth_face_contacts`` for one obstacle, compiled: positions (P, 3) [m], triangles (T, 3),
    owned (T, 3) bool (``edge_owned``), thickness (P,) [m], the ``obstacle`` (a ShapeObstacle,
    whose fields ``shape_signed_distance`` takes), margin [m]. Returns (triangle (F,) int64,
    weights (F, 3), point (F, 3) [m], normal (F, 3), depth (F,) [m]) of the F contacts."""
    kind, params, position, rotation = obstacle
    T = triangles.shape[0]
    # the obstacle's bounds: a sphere's radius, a box's half extents turned into the world
    extent = np.empty(3)
    for i in range(3):
        extent[i] = params[0] if kind == shapes.SPHERE else 0.0
        if kind == shapes.BOX:
            for a in range(3):
                extent[i] += abs(rotation[i, a]) * params[a]
    found_triangle = np.empty(T, dtype=np.int64)
    found = np.empty((T, 10))  # weights, point, normal, depth
    count = 0
    x = np.empty(3)
    for t in range(T):
        a, b, c = positions[triangles[t, 0]], positions[triangles[t, 1]], positions[triangles[t, 2]]
        reach = margin + max(thickness[triangles[t, 0]], thickness[triangles[t, 1]], thickness[triangles[t, 2]])
        apart = False
        for i in range(3):
            low, high = min(a[i], b[i], c[i]) - reach, max(a[i], b[i], c[i]) + reach
            apart = apart or low > position[i] + extent[i] or high < position[i] - extent[i]
        if apart:
            continue
        if kind == shapes.SPHERE:  # nearest the sphere: nearest its centre
            wa, wb, wc, _ = closest_on_triangle(position, a, b, c)
        else:
            wa, wb, wc = 1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0
            for _ in range(PROJECTIONS):
                for i in range(3):
                    x[i] = wa * a[i] + wb * b[i] + wc * c[i]
                signed, _, closest = shape_signed_distance(kind, params, position, rotation, x)
                if signed <= 0.0:  # inside: this point of the triangle is in the obstacle
                    break
                wa, wb, wc, _ = closest_on_triangle(closest, a, b, c)
        # a point within EDGE_SNAP of an edge or a corner (projections reach them from inside,
        # rounding leaves a hair) is on it
        wa, wb, wc = wa if wa >= EDGE_SNAP else 0.0, wb if wb >= EDGE_SNAP else 0.0, wc if wc >= EDGE_SNAP else 0.0
        total = wa + wb + wc
        wa, wb, wc = wa / total, wb / total, wc / total
        weights = (wa, wb, wc)
        if max(wa, wb, wc) >= 1.0:  # a corner: the vertex's own contact
            continue
        mine = True
        for k in range(3):
            if weights[k] == 0.0:  # on the edge opposite corner k (corners k + 1, k + 2): its first triangle's
                mine = owned[t, (k + 1) % 3]
        if not mine:
            continue
        for i in range(3):
            x[i] = wa * a[i] + wb * b[i] + wc * c[i]
        signed = _distance(kind, params, position, rotation, x)
        half = 0.5 * (
            wa * thickness[triangles[t, 0]] + wb * thickness[triangles[t, 1]] + wc * thickness[triangles[t, 2]]
        )
        depth = 2.0 * half - signed
        if depth < -margin:
            continue
        nearest_vertex = min(
            _distance(kind, params, position, rotation, a),
            _distance(kind, params, position, rotation, b),
            _distance(kind, params, position, rotation, c),
        )
        if signed > nearest_vertex - half:  # no nearer than the vertices: theirs are the contacts
            continue
        _, normal, closest = shape_signed_distance(kind, params, position, rotation, x)
        found_triangle[count] = t
        found[count, 0], found[count, 1], found[count, 2] = wa, wb, wc
        for i in range(3):
            found[count, 3 + i] = 0.5 * (x[i] + closest[i])
            found[count, 6 + i] = normal[i]
        found[count, 9] = depth
        count += 1
    return (
        found_triangle[:count].copy(),
        found[:count, 0:3].copy(),
        found[:count, 3:6].copy(),
        found[:count, 6:9].copy(),
        found[:count, 9].copy(),
    )
