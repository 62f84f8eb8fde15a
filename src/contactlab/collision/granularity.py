"""Contacts of mesh-like objects against static surfaces at a chosen SPEC P2 granularity and P4/P5 normal.

:func:`surface_contacts` is the general form: an object A given as its own triangle mesh
(vertices (V, 3) world, triangles (T, 3)) against a plane, sphere or box obstacle or a static
mesh (their signed distances: :mod:`.signed_distance`). Granularity P2a ``"object"``: one
contact, at the deepest vertex; P2b ``"vertex"``: one per penetrating vertex; P2c ``"samples"``:
one per penetrating sample, ``k × k`` per triangle (the centroids of the k² sub-triangles of a
k-subdivision), each carrying the triangle's 3 vertex indices and the 3 barycentric weights
(they sum to 1 and reproduce the sample point), so a force is distributed ``w_i F`` to vertex i
(D1). Normal P4 ``"object"``: the obstacle's normal at the closest point (a box's face normal:
discontinuous across its medial axis); P5 ``"vertex"``: the negated normal of A's own surface
at the point (area-weighted vertex normals, interpolated for samples): continuous, but not
guaranteed to point out of the obstacle. Cloth (:mod:`.cloth`) and rigid polytopes use it.

Rigid polytopes (boxes, convex hulls), :func:`polytope_contacts`:

The default contacts of a box or hull are its penetrating corners (P2b) with the surface's
normal (P4). ``collide(..., granularity=, normal=)`` replaces them, for every polytope body
against every static plane, sphere, box or mesh, by:

* ``"object"`` (P2a): one contact per body and surface, at its deepest point;
* ``"vertex"`` (P2b): one per penetrating vertex;
* ``"samples"`` (P2c): one per penetrating sample on the body's surface triangles,
  ``samples × samples`` per triangle;

with ``normal = "object"`` (P4: the surface's normal at its closest point, which guarantees
a separating force but jumps across the surface's medial axis) or ``"vertex"`` (P5: the
negated normal of the body's own surface at the point: continuous, but not always outward).

All bodies go through in one vectorized batch per surface: their hulls' fan triangles (built
once with the model) are placed in the world as one triangle soup.
"""

from __future__ import annotations

from collections import namedtuple
from typing import TYPE_CHECKING

import numpy as np

from .. import rotations, shapes
from ..compiling import njit
from ..errors import InputError
from ..meshes import TriangleMesh, vertex_normals
from .signed_distance import ShapeObstacle, model_obstacle, points_against_mesh, points_against_shape

if TYPE_CHECKING:
    from ..model import Model
    from ..state import State

GRANULARITIES = ("object", "vertex", "samples")  # P2a, P2b, P2c
NORMALS = ("object", "vertex")  # P4, P5
SURFACES = (shapes.PLANE, shapes.SPHERE, shapes.BOX, shapes.MESH)  # static kinds handled here
POLYTOPES = (shapes.BOX, shapes.CONVEX)


DetectionSettings = namedtuple(
    "DetectionSettings",
    ["margin", "granularity", "normal", "samples", "cloth_samples", "cloth_faces"],
    defaults=(0.0, "vertex", "object", 2, 0, True),
)
DetectionSettings.__doc__ = """How contacts are detected: ``collide``'s settings, as a method's CollisionOptions holds
them (``methods.base.CollisionOptions`` and ``collision.collide_keeping`` explain each): margin [m] (gaps
down to −margin become contacts), granularity and normal of boxes and hulls on static surfaces, samples per
triangle edge, cloth_samples (per cloth triangle edge against obstacles) and cloth_faces (whether an
obstacle's edge or corner meets a cloth triangle between its vertices). :func:`surface_contacts` reads the
margin, granularity, normal and samples."""


DEFAULT_SETTINGS = DetectionSettings()  # the corner contacts with the surface's normal, no margin


SurfaceContacts = namedtuple("SurfaceContacts", ["point", "normal", "depth", "vertices", "weights", "feature"])
SurfaceContacts.__doc__ = """Contacts of a mesh-like object A against a static surface B (C contacts).

point (C, 3) [m] midway between A's point and B's surface; normal (C, 3) unit, from B into A;
depth (C,) [m], > 0 penetrating; vertices (C, 3) int64 indices of A's vertices carrying the
contact (−1 unused); weights (C, 3) their barycentric weights (sum 1; 0 where unused), so the
contact point of A is Σ w_i x_i and a force F is distributed as w_i F to vertex i (D1);
feature (C,) int64: 0 (P2a), the vertex (P2b), or triangle · k² + sample (P2c)."""


def triangle_samples(samples_per_edge: int) -> np.ndarray:
    """Barycentric weights (k², 3) of k × k samples on a triangle: the centroids of the k²
    congruent sub-triangles of its k-subdivision (every weight > 0, the samples even)."""
    k = int(samples_per_edge)
    rows = []
    for a in range(k):
        for b in range(k - a):
            rows.append((a + 1.0 / 3.0, b + 1.0 / 3.0))  # upward sub-triangle
            if a + b <= k - 2:
                rows.append((a + 2.0 / 3.0, b + 2.0 / 3.0))  # downward sub-triangle
    ab = np.array(rows) / k
    return np.column_stack([1.0 - ab[:, 0] - ab[:, 1], ab[:, 0], ab[:, 1]])


def surface_contacts(
    vertices: np.ndarray,
    triangles: np.ndarray,
    obstacle: ShapeObstacle | TriangleMesh,
    settings: DetectionSettings = DEFAULT_SETTINGS,
    max_depth: float | None = None,
    object_vertex_normals: np.ndarray | None = None,
) -> SurfaceContacts:
    """Contacts of object A (its triangle mesh) against a static surface B, at a SPEC P2 granularity.

    vertices: (V, 3) world positions of A [m]; triangles: (T, 3) int, wound outward.
    obstacle: a :class:`ShapeObstacle` (:func:`plane_obstacle`, :func:`sphere_obstacle`,
    :func:`box_obstacle`) or a static :class:`~contactlab.meshes.TriangleMesh`.
    settings: a :class:`DetectionSettings` (its cloth fields are not read), of which:
    granularity: ``"object"`` (P2a: one contact, at the deepest vertex), ``"vertex"`` (P2b: one
    per vertex with depth ≥ −margin) or ``"samples"`` (P2c: one per sample with depth ≥ −margin,
    ``samples × samples`` per triangle). normal: ``"object"`` (P4: B's normal at its closest
    point) or ``"vertex"`` (P5: −(A's own area-weighted normal at the point), interpolated
    with the weights for samples). margin [m]: gaps down to this are kept. max_depth [m]:
    against a mesh, how deep a penetration is looked for (default: the mesh's ``max_depth``).
    object_vertex_normals: (V, 3) to reuse, else computed from A.
    """
    granularity, normal, margin, samples = settings.granularity, settings.normal, settings.margin, settings.samples
    if granularity not in GRANULARITIES:
        raise InputError("granularity", f"expected one of {', '.join(GRANULARITIES)}, found {granularity!r}")
    if normal not in NORMALS:
        raise InputError("normal", f"expected one of {', '.join(NORMALS)}, found {normal!r}")
    if not (np.isfinite(margin) and margin >= 0.0):
        raise InputError("margin", f"the margin must be a finite number ≥ 0, found {margin}")
    vertices = np.ascontiguousarray(vertices, dtype=float)
    triangles = np.ascontiguousarray(triangles, dtype=np.int64)
    k = int(samples)
    if granularity == "samples" and k < 1:
        raise InputError("samples", f"the samples per triangle edge must be ≥ 1, found {samples}")
    if granularity == "samples":
        pattern = triangle_samples(k)  # (S, 3)
        points = sample_points(vertices, triangles, pattern)  # (T·S, 3), sample t · S + s
    else:
        points = vertices
    if isinstance(obstacle, TriangleMesh):
        if max_depth is None:
            max_depth = obstacle.max_depth
        signed, obstacle_normal, closest, _ = points_against_mesh(points, obstacle.geometry, float(margin + max_depth))
    elif isinstance(obstacle, ShapeObstacle):
        signed, obstacle_normal, closest = points_against_shape(
            points,
            int(obstacle.kind),
            np.asarray(obstacle.params, dtype=float),
            np.asarray(obstacle.position, dtype=float),
            np.ascontiguousarray(obstacle.rotation, dtype=float),
        )
    else:
        raise InputError("obstacle", f"expected a ShapeObstacle or a TriangleMesh, found {type(obstacle).__name__}")
    depth = -signed
    if granularity == "object":
        chosen = np.array([int(np.argmax(depth))]) if len(depth) and depth.max() >= -margin else np.zeros(0, int)
    else:
        chosen = np.nonzero(depth >= -margin)[0]
    # the chosen points' carriers, barycentric weights and features (only theirs are made)
    if granularity == "samples":
        carriers, weights, features = triangles[chosen // len(pattern)], pattern[chosen % len(pattern)], chosen
    else:
        carriers = np.full((len(chosen), 3), -1, dtype=np.int64)
        carriers[:, 0] = chosen
        weights = np.zeros((len(chosen), 3))
        weights[:, 0] = 1.0
        features = chosen.astype(np.int64)
    if normal == "object":
        normals = obstacle_normal[chosen]
    else:
        own = (
            vertex_normals(vertices, triangles)
            if object_vertex_normals is None
            else np.asarray(object_vertex_normals, dtype=float)
        )
        blended = np.einsum("ck,ckd->cd", weights, own[np.maximum(carriers, 0)])
        length = np.linalg.norm(blended, axis=1, keepdims=True)
        normals = -blended / np.where(length > 0.0, length, 1.0)
    return SurfaceContacts(
        point=0.5 * (points[chosen] + closest[chosen]),
        normal=normals,
        depth=depth[chosen],
        vertices=carriers,
        weights=weights,
        feature=np.zeros(len(chosen), dtype=np.int64) if granularity == "object" else features,
    )


@njit(cache=True)
def sample_points(vertices: np.ndarray, triangles: np.ndarray, pattern: np.ndarray) -> np.ndarray:
    """The samples (T·S, 3) [m] of every triangle (T, 3) of ``vertices`` (V, 3) [m] at the
    barycentric weights ``pattern`` (S, 3) (``triangle_samples``): sample t · S + s is
    Σ_k pattern[s, k] x[triangles[t, k]], summed over k in order."""
    S = pattern.shape[0]
    points = np.empty((triangles.shape[0] * S, 3))
    for t in range(triangles.shape[0]):
        a, b, c = triangles[t, 0], triangles[t, 1], triangles[t, 2]
        for s in range(S):
            for d in range(3):
                points[t * S + s, d] = (
                    pattern[s, 0] * vertices[a, d] + pattern[s, 1] * vertices[b, d] + pattern[s, 2] * vertices[c, d]
                )
    return points


def _soup(model, state, bodies):
    """World vertices (V,3), triangles (T,3), each vertex's body (V,) and local index (V,),
    each triangle's body (T,) and local index (T,), for the given polytope bodies."""
    hulls = model.hulls
    hull = np.where(
        model.body_shape[bodies] == shapes.CONVEX, model.body_params[bodies, 0], model.body_params[bodies, 3]
    ).astype(np.int64)

    def ranges(start, count):
        """Concatenated aranges start[i] .. start[i]+count[i]-1, with the owner and local index."""
        owner = np.repeat(np.arange(len(count)), count)
        local = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
        return start[owner] + local, owner, local

    v_count = hulls["vertex_start"][hull + 1] - hulls["vertex_start"][hull]
    v_index, v_owner, v_local = ranges(hulls["vertex_start"][hull], v_count)
    R = rotations.to_matrix(state.body_orientation[bodies])
    world = np.einsum("vij,vj->vi", R[v_owner], hulls["vertices"][v_index]) + state.body_position[bodies][v_owner]
    t_count = hulls["triangle_start"][hull + 1] - hulls["triangle_start"][hull]
    t_index, t_owner, t_local = ranges(hulls["triangle_start"][hull], t_count)
    first_vertex = np.cumsum(v_count) - v_count
    triangles = hulls["triangles"][t_index] + first_vertex[t_owner][:, None]
    return world, triangles, bodies[v_owner], v_local, bodies[t_owner], t_local


def angle_weighted_normals(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Unit vertex normals (V, 3): the triangles' normals weighted by their angle at the vertex.

    Unlike area weighting this does not depend on how a polygon face was split into triangles
    (a cube's corner gets the diagonal (±1, ±1, ±1)/√3 whichever way its faces are fanned)."""
    corners = vertices[triangles]  # (T, 3, 3)
    face = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    face /= np.linalg.norm(face, axis=1, keepdims=True)
    normals = np.zeros_like(vertices)
    for k in range(3):
        u = corners[:, (k + 1) % 3] - corners[:, k]
        w = corners[:, (k + 2) % 3] - corners[:, k]
        cosine = np.einsum("ti,ti->t", u, w) / (np.linalg.norm(u, axis=1) * np.linalg.norm(w, axis=1))
        np.add.at(normals, triangles[:, k], np.arccos(np.clip(cosine, -1, 1))[:, None] * face)
    return normals / np.linalg.norm(normals, axis=1, keepdims=True)


def polytope_contacts(
    model: Model, state: State, granularity: str, normal: str, samples: int, margin: float, total: int
) -> tuple[list[tuple[np.ndarray, ...]], np.ndarray, np.ndarray]:
    """Contacts (a, b, point, normal, depth, feature) of every box and hull body against every
    static plane, sphere, box and mesh, and the (body, obstacle) pairs they replace."""
    bodies = np.nonzero(np.isin(model.body_shape, POLYTOPES))[0]
    obstacles = np.nonzero(np.isin(model.obstacle_shape, SURFACES))[0]
    empty = (np.zeros(0, np.int64),) * 2 + (np.zeros((0, 3)),) * 2 + (np.zeros(0), np.zeros(0, np.int64))
    if len(bodies) == 0 or len(obstacles) == 0:
        return [empty], bodies, obstacles
    world, triangles, vertex_body, vertex_local, triangle_body, triangle_local = _soup(model, state, bodies)
    own_normals = angle_weighted_normals(world, triangles) if normal == "vertex" else None
    samples_per_triangle = samples * samples
    parts = []
    dynamic = model.body_count + model.particle_count
    for o in obstacles:
        surface = (
            model.meshes[int(model.obstacle_params[o, 0])]
            if model.obstacle_shape[o] == shapes.MESH
            else model_obstacle(model, o)
        )
        settings = DetectionSettings(margin, "vertex" if granularity == "object" else granularity, normal, samples)
        found = surface_contacts(world, triangles, surface, settings, object_vertex_normals=own_normals)
        if granularity == "samples":
            triangle = found.feature // samples_per_triangle
            body = triangle_body[triangle]
            feature = triangle_local[triangle] * samples_per_triangle + found.feature % samples_per_triangle
        else:
            body = vertex_body[found.vertices[:, 0]]
            feature = vertex_local[found.vertices[:, 0]]
        keep = np.arange(len(body))
        if granularity == "object":  # P2a: the deepest contact of each body
            order = np.lexsort((-found.depth, body))
            keep = order[np.r_[True, body[order][1:] != body[order][:-1]]] if len(order) else order
        parts.append(
            (
                body[keep],
                np.full(len(keep), dynamic + o),
                found.point[keep],
                found.normal[keep],
                found.depth[keep],
                feature[keep],
            )
        )
    return parts, bodies, obstacles
