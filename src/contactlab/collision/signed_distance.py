"""Signed distances of points from static surfaces: planes, spheres, boxes and triangle meshes.

The distance is < 0 inside the solid, the normal points out of it, and the closest surface
point comes with both. A static surface is a :class:`ShapeObstacle` (:func:`plane_obstacle`,
:func:`sphere_obstacle`, :func:`box_obstacle`, :func:`model_obstacle`) or a mesh
(:class:`~contactlab.meshes.MeshGeometry`, judged by the closest feature's pseudo-normal as in
:mod:`.mesh_features`). The P2 granularities (:mod:`.granularity`), cloth samples
(:mod:`.cloth`) and the closed-form references (:mod:`contactlab.closed_form`) ask these.
"""

from __future__ import annotations

from collections import namedtuple
from typing import TYPE_CHECKING

import numpy as np

from .. import rotations, shapes
from ..compiling import njit
from ..errors import InputError
from .geometry import to_local
from .mesh_features import features_near, nearest_feature, signed_normal

if TYPE_CHECKING:
    from ..meshes import MeshGeometry
    from ..model import Model

SPHERE, BOX, PLANE = shapes.SPHERE, shapes.BOX, shapes.PLANE


ShapeObstacle = namedtuple("ShapeObstacle", ["kind", "params", "position", "rotation"])
ShapeObstacle.__doc__ = """A convex static surface: a kind of :mod:`contactlab.shapes` (PLANE, SPHERE, BOX),
its parameter row (4,), its centre (3,) [m] and rotation matrix (3, 3) (body → world)."""


def plane_obstacle(normal: np.ndarray, offset: float = 0.0) -> ShapeObstacle:
    """The plane {x : n · x = offset} (solid side n · x < offset); n and offset are divided by |n|."""
    n = np.asarray(normal, dtype=float).reshape(3)
    length = np.linalg.norm(n)
    if not np.isfinite(length) or length == 0.0:
        raise InputError("normal", f"the plane normal must be non-zero and finite, found {n.tolist()}")
    return ShapeObstacle(PLANE, np.array([*(n / length), float(offset) / length]), np.zeros(3), np.eye(3))


def sphere_obstacle(center: np.ndarray, radius: float) -> ShapeObstacle:
    """A solid sphere of ``radius`` [m] at ``center`` (3,)."""
    if not radius > 0.0:
        raise InputError("radius", f"the sphere radius must be positive, found {radius}")
    return ShapeObstacle(
        SPHERE, np.array([float(radius), 0.0, 0.0, 0.0]), np.asarray(center, dtype=float).reshape(3), np.eye(3)
    )


def box_obstacle(
    center: np.ndarray,
    half_extents: np.ndarray,
    quaternion: tuple[float, float, float, float] | np.ndarray = (1.0, 0.0, 0.0, 0.0),
) -> ShapeObstacle:
    """A solid box of ``half_extents`` (3,) [m] at ``center`` (3,), orientation (w, x, y, z)."""
    h = np.asarray(half_extents, dtype=float).reshape(3)
    if not np.all(h > 0.0):
        raise InputError("half_extents", f"the box half extents must be positive, found {h.tolist()}")
    q = np.asarray(quaternion, dtype=float).reshape(4)
    R = rotations.to_matrix((q / np.linalg.norm(q))[None])[0]
    return ShapeObstacle(BOX, np.array([h[0], h[1], h[2], 0.0]), np.asarray(center, dtype=float).reshape(3), R)


def model_obstacle(model: Model, index: int) -> ShapeObstacle:
    """The :class:`ShapeObstacle` of obstacle ``index`` of a :class:`~contactlab.model.Model`."""
    R = rotations.to_matrix(np.asarray(model.obstacle_orientation[index], dtype=float)[None])[0]
    return ShapeObstacle(
        int(model.obstacle_shape[index]),
        np.asarray(model.obstacle_params[index], dtype=float),
        np.asarray(model.obstacle_position[index], dtype=float),
        R,
    )


@njit(cache=True)
def shape_signed_distance(
    kind: int, params: np.ndarray, position: np.ndarray, rotation: np.ndarray, x: np.ndarray
) -> tuple[float, np.ndarray, np.ndarray]:
    """Signed distance [m] (< 0 inside), outward unit normal (3,) and closest surface point (3,)
    of a plane, sphere or box obstacle at the point x (3,).

    Box: outside, the normal points from the closest point to x; inside, it is the normal of
    the face of least penetration (the first in x, y, z order on a tie) — so it jumps across
    the box's medial axis (P4).
    """
    normal = np.zeros(3)
    closest = np.empty(3)
    if kind == PLANE:
        d = x[0] * params[0] + x[1] * params[1] + x[2] * params[2] - params[3]
        for i in range(3):
            normal[i] = params[i]
            closest[i] = x[i] - d * params[i]
        return d, normal, closest
    if kind == SPHERE:
        dx, dy, dz = x[0] - position[0], x[1] - position[1], x[2] - position[2]
        length = np.sqrt(dx * dx + dy * dy + dz * dz)
        if length > 0.0:
            normal[0], normal[1], normal[2] = dx / length, dy / length, dz / length
        else:
            normal[2] = 1.0
        for i in range(3):
            closest[i] = position[i] + params[0] * normal[i]
        return length - params[0], normal, closest
    # box
    local = to_local(rotation, position, x)
    clamped = np.empty(3)
    outside = 0.0
    for a in range(3):
        clamped[a] = min(max(local[a], -params[a]), params[a])
        outside += (local[a] - clamped[a]) ** 2
    normal_local = np.zeros(3)
    if outside > 0.0:
        distance = np.sqrt(outside)
        for a in range(3):
            normal_local[a] = (local[a] - clamped[a]) / distance
        signed = distance
    else:
        axis = 0
        gap = params[0] - abs(local[0])
        for a in range(1, 3):
            if params[a] - abs(local[a]) < gap:
                gap = params[a] - abs(local[a])
                axis = a
        sign = 1.0 if local[axis] >= 0.0 else -1.0
        normal_local[axis] = sign
        clamped[axis] = sign * params[axis]
        signed = -gap
    for i in range(3):
        normal[i] = (
            rotation[i, 0] * normal_local[0] + rotation[i, 1] * normal_local[1] + rotation[i, 2] * normal_local[2]
        )
        closest[i] = position[i] + (
            rotation[i, 0] * clamped[0] + rotation[i, 1] * clamped[1] + rotation[i, 2] * clamped[2]
        )
    return signed, normal, closest


@njit(cache=True)
def mesh_signed_distance(mesh: MeshGeometry, x: np.ndarray, reach: float) -> tuple[float, np.ndarray, np.ndarray, int]:
    """Signed distance [m], outward normal (3,), closest point (3,) and triangle of the point of
    the mesh closest to x (3,), searched within ``reach`` [m]; triangle −1 (distance +inf)
    when nothing is that near. The sign is that of the closest feature's pseudo-normal
    (a two-sided mesh: always ≥ 0); the normal as in :func:`sphere_mesh`.
    """
    candidates, closest, distance, region = features_near(
        mesh, x, reach, np.empty((32, 3)), np.empty(32), np.empty(32, dtype=np.int64)
    )
    nearest = nearest_feature(candidates, distance, region)
    normal = np.zeros(3)
    q = np.zeros(3)
    if nearest < 0 or distance[nearest] > reach:
        return np.inf, normal, q, -1
    for i in range(3):
        q[i] = closest[nearest, i]
    signed, normal[0], normal[1], normal[2] = signed_normal(
        mesh, candidates[nearest], region[nearest], x, q[0], q[1], q[2], distance[nearest]
    )
    return signed, normal, q, candidates[nearest]


@njit(cache=True)
def points_against_shape(
    points: np.ndarray, kind: int, params: np.ndarray, position: np.ndarray, rotation: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`shape_signed_distance` for points (N, 3): signed distance (N,), normal (N, 3), closest (N, 3)."""
    count = points.shape[0]
    signed = np.empty(count)
    normal = np.empty((count, 3))
    closest = np.empty((count, 3))
    for k in range(count):
        d, n, q = shape_signed_distance(kind, params, position, rotation, points[k])
        signed[k] = d
        for i in range(3):
            normal[k, i] = n[i]
            closest[k, i] = q[i]
    return signed, normal, closest


@njit(cache=True)
def points_against_mesh(
    points: np.ndarray, mesh: MeshGeometry, reach: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`mesh_signed_distance` for points (N, 3): signed distance (N,) (+inf beyond
    ``reach``), normal (N, 3), closest (N, 3), triangle (N,)."""
    count = points.shape[0]
    signed = np.empty(count)
    normal = np.empty((count, 3))
    closest = np.empty((count, 3))
    triangle = np.empty(count, dtype=np.int64)
    for k in range(count):
        d, n, q, t = mesh_signed_distance(mesh, points[k], reach)
        signed[k] = d
        triangle[k] = t
        for i in range(3):
            normal[k, i] = n[i]
            closest[k, i] = q[i]
    return signed, normal, closest, triangle
