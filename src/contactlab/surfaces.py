"""Triangle surfaces of a scene's shapes, for pictures and exports (not for collision).

Every rigid body gets one closed triangle surface in its own frame (a box or convex body its
hull's faces, a sphere an icosphere, a capsule a tessellated capsule); every static obstacle
gets one in world coordinates (a plane a finite square around the scene). They are written
into ``trajectory.npz`` (see ``docs/trajectory.md``) so that a run can be drawn or exported
from its trajectory alone:

=============================  ==========  =================================================
array                          shape       meaning
=============================  ==========  =================================================
``body_surface_vertices``      (V, 3) m    every body's surface vertices, body frame
``body_surface_vertex_start``  (B+1,)      body b owns vertices [start[b], start[b+1])
``body_surface_triangles``     (N, 3)      vertex indices into ``body_surface_vertices``
``body_surface_triangle_start``(B+1,)      body b owns triangles [start[b], start[b+1])
``obstacle_vertices``          (W, 3) m    obstacles' surface vertices, world frame
``obstacle_triangles``         (M, 3)      indices into ``obstacle_vertices``
``particle_radius``            (P,) m      contact radius of every particle
=============================  ==========  =================================================

Triangles are wound counter-clockwise seen from outside.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from . import icosphere, rotations, shapes

if TYPE_CHECKING:
    from .model import Model


SPHERE_SUBDIVISIONS = 1  # an icosphere of 80 triangles
CAPSULE_SEGMENTS = 8  # around the axis


def _hull_surface(hulls, index):
    """(vertices (V,3), triangles (T,3)) of packed hull ``index``, local indices."""
    v0, v1 = hulls["vertex_start"][index], hulls["vertex_start"][index + 1]
    t0, t1 = hulls["triangle_start"][index], hulls["triangle_start"][index + 1]
    return hulls["vertices"][v0:v1], hulls["triangles"][t0:t1]


@functools.cache
def _unit_sphere():
    """(vertices (42, 3), triangles (80, 3)) of the unit icosphere of SPHERE_SUBDIVISIONS = 1:
    trimesh.creation.icosphere's, written out in contactlab.icosphere (no trimesh import)."""
    return _read_only(np.array(icosphere.VERTICES, dtype=float)), _read_only(
        np.array(icosphere.TRIANGLES, dtype=np.int64)
    )


@functools.lru_cache(maxsize=64)
def _capsule(radius, half_length):
    import trimesh  # half a second to import: only scenes with capsules pay it

    mesh = trimesh.creation.capsule(height=2.0 * half_length, radius=radius, count=[CAPSULE_SEGMENTS, CAPSULE_SEGMENTS])
    return _read_only(mesh.vertices), _read_only(mesh.faces)


def _read_only(array):
    """A read-only copy: cached surfaces are shared by every body of that size."""
    array = np.array(array)
    array.flags.writeable = False
    return array


def _solid_surface(model, kind, params):
    """Surface of a solid shape about its own centre: (vertices (V,3) m, triangles (T,3)).
    Spheres and capsules are tessellated once per size (a pile of a thousand is one mesh)."""
    if kind == shapes.SPHERE:
        vertices, faces = _unit_sphere()
        return vertices * params[0], faces
    if kind == shapes.CAPSULE:
        return _capsule(float(params[0]), float(params[1]))
    if kind == shapes.BOX:  # its own 8-corner hull, kept in params[3]
        return _hull_surface(model.hulls, int(params[3]))
    if kind == shapes.CONVEX:
        return _hull_surface(model.hulls, int(params[0]))
    raise ValueError(f"shape {shapes.NAMES[kind]} has no solid surface")


def scene_bounds(model: Model) -> tuple[np.ndarray, np.ndarray]:
    """(lower (3,), upper (3,)) [m] around the initial bodies, particles and bounded obstacles."""
    state = model.state()
    points = [state.body_position, state.particle_position]
    radii = [shapes.bounding_radii(model.body_shape, model.body_params), np.asarray(model.particle_radius)]
    bounded = model.obstacle_shape != shapes.PLANE
    bounded &= model.obstacle_shape != shapes.MESH
    points.append(model.obstacle_position[bounded])
    radii.append(shapes.bounding_radii(model.obstacle_shape[bounded], model.obstacle_params[bounded]))
    for mesh in model.meshes:
        points.append(mesh.vertices)
        radii.append(np.zeros(len(mesh.vertices)))
    centres, reach = np.concatenate(points), np.concatenate(radii)
    if len(centres) == 0:
        return -np.ones(3), np.ones(3)
    return (centres - reach[:, None]).min(axis=0), (centres + reach[:, None]).max(axis=0)


def _plane_surface(params, centre, half_size):
    """A square of half side ``half_size`` [m] on the plane n·x = d, centred at the foot of ``centre``."""
    normal, offset = params[:3], params[3]
    foot = centre - (normal @ centre - offset) * normal
    helper = np.eye(3)[np.argmin(np.abs(normal))]
    u = np.cross(normal, helper)
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    corners = foot + half_size * np.array([-u - v, u - v, u + v, -u + v])
    return corners, np.array([[0, 1, 2], [0, 2, 3]])


def surface_arrays(model: Model) -> dict[str, np.ndarray]:
    """The surface arrays of the module docstring, for ``model``."""
    vertices, triangles, vertex_start, triangle_start = [], [], [0], [0]
    for kind, params in zip(model.body_shape, model.body_params):
        v, t = _solid_surface(model, int(kind), params)
        triangles.append(np.asarray(t, dtype=np.int64) + vertex_start[-1])
        vertices.append(np.asarray(v, dtype=float))
        vertex_start.append(vertex_start[-1] + len(v))
        triangle_start.append(triangle_start[-1] + len(t))

    lower, upper = scene_bounds(model)
    centre, half_size = 0.5 * (lower + upper), max(0.6 * np.max(upper - lower), 1.0)
    world_vertices, world_triangles, count = [], [], 0
    rotation = rotations.to_matrix(np.asarray(model.obstacle_orientation, dtype=float))
    for o, (kind, params) in enumerate(zip(model.obstacle_shape, model.obstacle_params)):
        kind = int(kind)
        if kind == shapes.PLANE:
            v, t = _plane_surface(params, centre, half_size)
        elif kind == shapes.MESH:
            mesh = model.meshes[int(params[0])]
            v, t = mesh.vertices, mesh.triangles
        else:
            v, t = _solid_surface(model, kind, params)
            v = np.asarray(v) @ rotation[o].T + model.obstacle_position[o]
        world_vertices.append(np.asarray(v, dtype=float))
        world_triangles.append(np.asarray(t, dtype=np.int64) + count)
        count += len(v)

    def stack(arrays, width, dtype):
        return np.concatenate(arrays).astype(dtype) if arrays else np.zeros((0, width), dtype)

    return {
        "body_surface_vertices": stack(vertices, 3, float),
        "body_surface_vertex_start": np.array(vertex_start, dtype=np.int64),
        "body_surface_triangles": stack(triangles, 3, np.int64),
        "body_surface_triangle_start": np.array(triangle_start, dtype=np.int64),
        "obstacle_vertices": stack(world_vertices, 3, float),
        "obstacle_triangles": stack(world_triangles, 3, np.int64),
        "particle_radius": np.array(model.particle_radius, dtype=float),
    }


def posed_body_vertices(arrays: Mapping[str, Any], sample: int) -> np.ndarray:
    """World positions (V, 3) [m] of every body surface vertex at trajectory sample ``sample``.

    ``arrays``: a trajectory (the dict of ``simulate`` or an ``np.load`` of trajectory.npz).
    """
    start = arrays["body_surface_vertex_start"]
    owner = np.repeat(np.arange(len(start) - 1), np.diff(start))
    R = rotations.to_matrix(np.asarray(arrays["body_orientation"][sample], dtype=float))
    local = arrays["body_surface_vertices"]
    return np.einsum("vij,vj->vi", R[owner], local) + arrays["body_position"][sample][owner]
