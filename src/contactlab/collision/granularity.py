"""Contacts of rigid polytopes (boxes, convex hulls) against static surfaces at a chosen SPEC
P2 granularity and P4/P5 normal.

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

import numpy as np

from .. import rotations, shapes
from .mesh import model_obstacle, surface_contacts

GRANULARITIES = ("object", "vertex", "samples")
NORMALS = ("object", "vertex")
SURFACES = (shapes.PLANE, shapes.SPHERE, shapes.BOX, shapes.MESH)    # static kinds handled here
POLYTOPES = (shapes.BOX, shapes.CONVEX)


def _soup(model, state, bodies):
    """World vertices (V,3), triangles (T,3), each vertex's body (V,) and local index (V,),
    each triangle's body (T,) and local index (T,), for the given polytope bodies."""
    hulls = model.hulls
    hull = np.where(model.body_shape[bodies] == shapes.CONVEX, model.body_params[bodies, 0],
                    model.body_params[bodies, 3]).astype(np.int64)

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


def angle_weighted_normals(vertices, triangles):
    """Unit vertex normals (V, 3): the triangles' normals weighted by their angle at the vertex.

    Unlike area weighting this does not depend on how a polygon face was split into triangles
    (a cube's corner gets the diagonal (±1, ±1, ±1)/√3 whichever way its faces are fanned)."""
    corners = vertices[triangles]                                            # (T, 3, 3)
    face = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    face /= np.linalg.norm(face, axis=1, keepdims=True)
    normals = np.zeros_like(vertices)
    for k in range(3):
        u = corners[:, (k + 1) % 3] - corners[:, k]
        w = corners[:, (k + 2) % 3] - corners[:, k]
        cosine = np.einsum("ti,ti->t", u, w) / (np.linalg.norm(u, axis=1) * np.linalg.norm(w, axis=1))
        np.add.at(normals, triangles[:, k], np.arccos(np.clip(cosine, -1, 1))[:, None] * face)
    return normals / np.linalg.norm(normals, axis=1, keepdims=True)


def polytope_contacts(model, state, granularity, normal, samples, margin, total):
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
        surface = (model.meshes[int(model.obstacle_params[o, 0])] if model.obstacle_shape[o] == shapes.MESH
                   else model_obstacle(model, o))
        found = surface_contacts(world, triangles, surface, "sample" if granularity == "samples" else "vertex",
                                 normal, margin, samples, object_vertex_normals=own_normals)
        if granularity == "samples":
            triangle = found.feature // samples_per_triangle
            body = triangle_body[triangle]
            feature = triangle_local[triangle] * samples_per_triangle + found.feature % samples_per_triangle
        else:
            body = vertex_body[found.vertices[:, 0]]
            feature = vertex_local[found.vertices[:, 0]]
        keep = np.arange(len(body))
        if granularity == "object":                     # P2a: the deepest contact of each body
            order = np.lexsort((-found.depth, body))
            keep = order[np.r_[True, body[order][1:] != body[order][:-1]]] if len(order) else order
        parts.append((body[keep], np.full(len(keep), dynamic + o), found.point[keep], found.normal[keep],
                      found.depth[keep], feature[keep]))
    return parts, bodies, obstacles
