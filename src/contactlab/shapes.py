"""Shape kinds, their parameters, and mass properties.

Every collider carries an integer ``kind`` and a parameter row of 4 floats:

=========  =============================================  ======================
kind       params                                         used by
=========  =============================================  ======================
SPHERE     (radius, 0, 0, 0)                              bodies, obstacles
BOX        (half_x, half_y, half_z, 0)                    bodies, obstacles
PLANE      (normal_x, normal_y, normal_z, offset)         obstacles
POINT      (radius, 0, 0, 0)  a particle: sphere of r ≥ 0 particles
CAPSULE    (radius, half_length, 0, 0)                    bodies
CONVEX     (hull index, bounding radius, 0, 0)            bodies, obstacles
MESH       (mesh index, 0, 0, 0)                          obstacles (static triangle meshes)
=========  =============================================  ======================

A box also keeps, in its 4th parameter, the index of its own 8-corner hull in the model's
hull store, so that box–convex pairs run through the convex routines.

A plane is the set {x : normal · x = offset}; its solid side is normal · x < offset.
A capsule is the segment from −half_length to +half_length along its body z axis, swept by a
sphere of its radius.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

SPHERE = 0
BOX = 1
PLANE = 2
POINT = 3
CAPSULE = 4
CONVEX = 5
MESH = 6

BODY_SHAPES = {"sphere": SPHERE, "box": BOX, "capsule": CAPSULE, "convex": CONVEX}
OBSTACLE_SHAPES = {"plane": PLANE, "sphere": SPHERE, "box": BOX, "convex": CONVEX, "mesh": MESH}
NAMES = {
    SPHERE: "sphere",
    BOX: "box",
    PLANE: "plane",
    POINT: "particle",
    CAPSULE: "capsule",
    CONVEX: "convex",
    MESH: "mesh",
}


def volume(kind: int, params: np.ndarray) -> float:
    """Volume [m³] of a solid shape."""
    if kind == SPHERE:
        return 4.0 / 3.0 * np.pi * params[0] ** 3
    if kind == BOX:
        return 8.0 * params[0] * params[1] * params[2]
    if kind == CAPSULE:
        r, h = params[0], params[1]
        return np.pi * r * r * 2.0 * h + 4.0 / 3.0 * np.pi * r**3
    raise ValueError(f"shape {NAMES[kind]} has no volume")


def principal_inertia(kind: int, params: np.ndarray, mass: float) -> np.ndarray:
    """Principal moments of inertia [kg m²], shape (3,), of a uniform solid about its centre."""
    if kind == SPHERE:
        return np.full(3, 0.4 * mass * params[0] ** 2)
    if kind == BOX:
        x2, y2, z2 = (2.0 * params[0]) ** 2, (2.0 * params[1]) ** 2, (2.0 * params[2]) ** 2
        return mass / 12.0 * np.array([y2 + z2, x2 + z2, x2 + y2])
    if kind == CAPSULE:
        # a cylinder of length H = 2h plus two hemispherical caps, the mass split by volume
        r, H = params[0], 2.0 * params[1]
        cylinder = mass * (np.pi * r * r * H) / volume(kind, params)
        caps = mass - cylinder
        axial = cylinder * r * r / 2.0 + caps * 2.0 * r * r / 5.0
        transverse = cylinder * (r * r / 4.0 + H * H / 12.0) + caps * (
            2.0 * r * r / 5.0 + H * H / 4.0 + 3.0 * H * r / 8.0
        )
        return np.array([transverse, transverse, axial])
    raise ValueError(f"shape {NAMES[kind]} has no inertia")


def bounding_radii(kinds: ArrayLike, params: np.ndarray) -> np.ndarray:
    """Radii [m] (N,) of spheres about the shapes' centres that enclose them; planes: inf."""
    kinds = np.asarray(kinds)
    return np.select(
        [kinds == BOX, kinds == PLANE, kinds == CAPSULE, kinds == CONVEX],
        [np.linalg.norm(params[:, :3], axis=1), np.inf, params[:, 0] + params[:, 1], params[:, 1]],
        default=params[:, 0],
    )
