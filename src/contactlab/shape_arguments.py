"""Which shape takes which arguments, and the shape row (kind, params) those arguments make.

:class:`~contactlab.builder.ModelBuilder`'s ``add_body`` and ``add_obstacle`` take every
shape's arguments as keywords; the tables here say which of them each shape takes (any other
given, not None, is an :class:`~contactlab.errors.InputError` naming it), and the scene schema
(:mod:`contactlab.scene.schema`) reads its shape-specific keys from them too. The functions
turn checked arguments into what a :class:`~contactlab.model.Model` stores of a shape: its
kind (:mod:`contactlab.shapes`) and its four parameters, or a
:class:`~contactlab.hulls.Hull` for a convex shape and a
:class:`~contactlab.meshes.TriangleMesh` for a mesh obstacle.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from . import shapes
from .errors import InputError
from .validation import DIRECTION, FACTOR, LENGTH, as_array, file_path, number, one_of, vector

if TYPE_CHECKING:
    from .hulls import Hull
    from .meshes import TriangleMesh

BODY_SHAPE_ARGUMENTS = {
    "sphere": ("radius",),
    "box": ("half_extents",),
    "capsule": ("radius", "half_length"),
    "convex": ("points", "file", "scale"),
}
"""The shape-specific arguments of add_body that each shape takes."""
OBSTACLE_SHAPE_ARGUMENTS = {
    "plane": ("normal", "offset"),
    "sphere": ("radius", "position"),
    "box": ("half_extents", "position", "orientation"),
    "convex": ("points", "file", "scale", "position", "orientation"),
    "mesh": ("file", "scale", "position", "orientation"),
}
"""The shape-specific arguments of add_obstacle that each shape takes."""


def check_shape_arguments(shape: str, table: Mapping[str, Sequence[str]], given: Collection[str]) -> None:
    """InputError naming the first of ``given`` (names of shape-specific arguments) that
    ``shape`` takes not, by ``table`` (BODY_SHAPE_ARGUMENTS or OBSTACLE_SHAPE_ARGUMENTS)."""
    takes = table[shape]
    for name in given:
        if name not in takes:
            raise InputError(name, f"a {shape} takes no {name} (a {shape} takes: {', '.join(takes)})")


def checked_shape(shape: str, table: Mapping[str, Sequence[str]], given: Mapping[str, Any]) -> str:
    """``shape`` checked: one of ``table``'s names, given only its own arguments (``given``:
    name -> value of every shape-specific argument, None where left out)."""
    one_of(shape, "shape", table)
    check_shape_arguments(shape, table, [name for name, value in given.items() if value is not None])
    return shape


def solid_shape(
    shape: str,
    radius: float | None,
    half_extents: ArrayLike | None,
    kinds: Mapping[str, int],
    half_length: float | None = None,
) -> tuple[int, np.ndarray]:
    """(kind, params (4,)) of a sphere, box or capsule (``shape`` already checked) by ``kinds``
    (shapes.BODY_SHAPES or shapes.OBSTACLE_SHAPES): the radius [m] in params[0], a capsule's
    half length [m] in params[1], a box's half extents [m] in params[:3]."""
    kind = kinds[shape]
    params = np.zeros(4)
    if kind in (shapes.SPHERE, shapes.CAPSULE):
        if radius is None:
            raise InputError("radius", f"a {shape} needs a radius (m)")
        params[0] = number(radius, "radius", 0.0, strict=True, quantity=LENGTH)
    if kind == shapes.CAPSULE:
        if half_length is None:
            raise InputError("half_length", "a capsule needs a half_length (m): half its segment's length")
        params[1] = number(half_length, "half_length", 0.0, quantity=LENGTH)
    elif kind == shapes.BOX:
        if half_extents is None:
            raise InputError("half_extents", "a box needs half_extents = [hx, hy, hz] (m)")
        params[:3] = vector(half_extents, "half_extents", quantity=LENGTH, positive=True)
    return kind, params


def convex_hull(
    points: ArrayLike | None,
    file: str | None,
    scale: float | None,
    mass: float | None = None,
    density: float | None = None,
) -> Hull:
    """The convex hull of ``points`` (n, 3) [m] or of a mesh file's vertices, times ``scale``
    (default 1), as a uniform solid of ``mass`` [kg] or ``density`` [kg/m³] (neither: static
    geometry, whose mass is not used); InputError if the points are not convex."""
    from .hulls import build_hull, load_hull_points

    if (points is None) == (file is None):
        raise InputError("points", "a convex shape needs exactly one of points = [[x, y, z], ...] or file")
    scale = number(1.0 if scale is None else scale, "scale", 0.0, strict=True, quantity=FACTOR)
    if file is not None:
        corners, field = load_hull_points(file_path(file), scale, field="file"), "file"
    else:
        corners, field = as_array(points, "points", "a list of [x, y, z] points") * scale, "points"
    if np.isfinite(corners).all():  # (non-finite points: build_hull's error)
        LENGTH.check(corners, field)
    if mass is None and density is None:
        mass = 1.0  # static geometry: the mass is not used
    return build_hull(corners, field, mass=mass, density=density, require_convex=True)


def plane_params(normal: ArrayLike | None, offset: float | None) -> np.ndarray:
    """params (4,) of the plane obstacle whose solid side is ``normal · x ≤ offset``: the unit
    normal and the offset [m] divided by the given normal's length (offset default 0)."""
    if normal is None:
        raise InputError("normal", "a plane needs a normal = [nx, ny, nz]")
    n = vector(normal, "normal", quantity=DIRECTION)
    length = np.linalg.norm(n)
    if length < 1e-12:
        raise InputError("normal", "the normal must not be zero")
    offset = number(0.0 if offset is None else offset, "offset", quantity=LENGTH)
    return np.concatenate([n / length, [offset / length]])


def mesh_obstacle(file: str | None, scale: float | None, position: np.ndarray, orientation: np.ndarray) -> TriangleMesh:
    """The triangle mesh of ``file`` (OBJ, STL or PLY) times ``scale`` (default 1), placed at
    ``position`` (3,) [m] with ``orientation`` (4,) (w, x, y, z): in the world frame."""
    from .meshes import load_mesh

    if file is None:
        raise InputError("file", "a mesh obstacle needs a file (OBJ, STL or PLY)")
    scale = number(1.0 if scale is None else scale, "scale", 0.0, strict=True, quantity=FACTOR)
    mesh = load_mesh(file_path(file), scale, field="file")
    LENGTH.check(mesh.vertices, "file")
    return mesh.transformed(position, orientation)
