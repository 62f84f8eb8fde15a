"""The swept test against static triangle meshes: no tunnelling through thin sheets.

A static query cannot tell which side of a thin one-sided sheet a point came from (see
:mod:`.sphere_mesh`); :func:`sweep_sphere_mesh` finds the first triangle a sphere (radius
≥ 0) moving on a straight segment touches, by intersecting the segment with each nearby
triangle inflated by the radius (the Minkowski sum: two offset faces, three edge cylinders,
three vertex spheres); the time of impact in [0, 1] is exact for that shape.

Compiled (``@njit(cache=True)``), float64, no fastmath.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..compiling import njit
from ..meshes import mesh_triangles_near
from .mesh_features import FACE, closest_point_on_triangle

if TYPE_CHECKING:
    from ..meshes import MeshGeometry


@njit(cache=True)
def _segment_crosses_triangle(start, motion, a, b, c, nt, tol):
    """Time t in [0, 1] at which start + t motion crosses the triangle's plane inside it (inf: never)."""
    s0 = (start[0] - a[0]) * nt[0] + (start[1] - a[1]) * nt[1] + (start[2] - a[2]) * nt[2]
    rate = motion[0] * nt[0] + motion[1] * nt[1] + motion[2] * nt[2]
    if rate == 0.0 or s0 * rate > 0.0 or (s0 == 0.0 and rate > 0.0):
        return np.inf  # parallel, moving away, or leaving the plane towards the front
    t = -s0 / rate
    if t < 0.0 or t > 1.0:
        return np.inf
    p = np.empty(3)
    for i in range(3):
        p[i] = start[i] + t * motion[i]
    qx, qy, qz, _ = closest_point_on_triangle(p, a, b, c)
    if (qx - p[0]) ** 2 + (qy - p[1]) ** 2 + (qz - p[2]) ** 2 > tol * tol:
        return np.inf
    return t


@njit(cache=True)
def _segment_enters_sphere(start, motion, center, radius):
    """First t in [0, 1] with |start + t motion − center| = radius, start outside (inf: never)."""
    wx, wy, wz = start[0] - center[0], start[1] - center[1], start[2] - center[2]
    a = motion[0] * motion[0] + motion[1] * motion[1] + motion[2] * motion[2]
    b = wx * motion[0] + wy * motion[1] + wz * motion[2]
    c = wx * wx + wy * wy + wz * wz - radius * radius
    if a == 0.0 or b >= 0.0:
        return np.inf
    if c <= 0.0:
        return 0.0  # touching already (within rounding) and moving in
    disc = b * b - a * c
    if disc < 0.0:
        return np.inf
    t = (-b - np.sqrt(disc)) / a
    if t < 0.0:
        t = 0.0
    return t if t <= 1.0 else np.inf


@njit(cache=True)
def _segment_enters_cylinder(start, motion, a, b, radius):
    """First t in [0, 1] at which the segment enters the finite cylinder of ``radius`` about edge ab."""
    ex, ey, ez = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    ee = ex * ex + ey * ey + ez * ez
    if ee == 0.0:
        return np.inf
    wx, wy, wz = start[0] - a[0], start[1] - a[1], start[2] - a[2]
    we = (wx * ex + wy * ey + wz * ez) / ee
    me = (motion[0] * ex + motion[1] * ey + motion[2] * ez) / ee
    # components perpendicular to the edge
    px, py, pz = wx - we * ex, wy - we * ey, wz - we * ez
    mx, my, mz = motion[0] - me * ex, motion[1] - me * ey, motion[2] - me * ez
    A = mx * mx + my * my + mz * mz
    B = px * mx + py * my + pz * mz
    C = px * px + py * py + pz * pz - radius * radius
    if A == 0.0 or B >= 0.0:
        return np.inf
    if C <= 0.0:
        t = 0.0  # touching already (within rounding) and moving in
    else:
        disc = B * B - A * C
        if disc < 0.0:
            return np.inf
        t = (-B - np.sqrt(disc)) / A
    if t > 1.0:
        return np.inf
    u = we + t * me
    if u < 0.0 or u > 1.0:
        return np.inf
    return t


@njit(cache=True)
def sweep_sphere_mesh(
    start: np.ndarray, end: np.ndarray, radius: float, mesh: MeshGeometry
) -> tuple[bool, float, int, np.ndarray]:
    """First contact of a sphere (radius ≥ 0 [m]) moving from ``start`` to ``end`` (3,) with the mesh.

    Returns (hit, time_of_impact in [0, 1], triangle, normal (3,)). The normal points from
    the triangle towards the sphere's centre at impact (the triangle's normal, oriented
    towards the side the sphere came from, for a face hit). No hit: (False, 1.0, −1, 0).

    Each nearby triangle is inflated by the radius (its Minkowski sum with the sphere) and
    the segment of the centre is intersected with it. A triangle the sphere already overlaps
    at the start is handled by the static contact; for it only the centre's own crossing of
    the triangle counts, so a sphere that starts in contact still cannot pass through.
    Conservative (never misses a crossing) and exact in the time of impact.
    """
    motion = np.empty(3)
    lower = np.empty(3)
    upper = np.empty(3)
    for i in range(3):
        motion[i] = end[i] - start[i]
        lower[i] = min(start[i], end[i]) - radius
        upper[i] = max(start[i], end[i]) + radius
    candidates = mesh_triangles_near(mesh, lower, upper, np.empty(64, dtype=np.int64))
    tol = mesh.tolerance
    best_t, best_triangle = np.inf, -1
    for c in range(candidates.shape[0]):
        t_index = candidates[c]
        if (
            mesh.triangle_normals[t_index, 2] == 0.0
            and mesh.triangle_normals[t_index, 0] == 0.0
            and mesh.triangle_normals[t_index, 1] == 0.0
        ):
            continue
        tri = mesh.triangles[t_index]
        a, b, cc = mesh.vertices[tri[0]], mesh.vertices[tri[1]], mesh.vertices[tri[2]]
        nt = mesh.triangle_normals[t_index]
        qx, qy, qz, _ = closest_point_on_triangle(start, a, b, cc)
        start_distance = np.sqrt((start[0] - qx) ** 2 + (start[1] - qy) ** 2 + (start[2] - qz) ** 2)
        if radius <= 0.0 or start_distance < radius - tol:
            t = _segment_crosses_triangle(start, motion, a, b, cc, nt, tol)
        else:
            t = np.inf
            # the two faces offset by the radius, on the start's side
            s0 = (start[0] - a[0]) * nt[0] + (start[1] - a[1]) * nt[1] + (start[2] - a[2]) * nt[2]
            side = 1.0 if s0 >= 0.0 else -1.0
            rate = side * (motion[0] * nt[0] + motion[1] * nt[1] + motion[2] * nt[2])
            if rate < 0.0:
                # (start within rounding of the offset face, t_face < 0 by a hair: it touches now)
                t_face = max(0.0, (radius - side * s0) / rate)
                if t_face <= 1.0:
                    p = np.empty(3)
                    height = s0 + side * rate * t_face  # the centre's height at t_face
                    for i in range(3):
                        p[i] = start[i] + t_face * motion[i] - height * nt[i]
                    px, py, pz, _ = closest_point_on_triangle(p, a, b, cc)
                    if (px - p[0]) ** 2 + (py - p[1]) ** 2 + (pz - p[2]) ** 2 <= tol * tol:
                        t = t_face
            t = min(t, _segment_enters_cylinder(start, motion, a, b, radius))
            t = min(t, _segment_enters_cylinder(start, motion, b, cc, radius))
            t = min(t, _segment_enters_cylinder(start, motion, cc, a, radius))
            t = min(t, _segment_enters_sphere(start, motion, a, radius))
            t = min(t, _segment_enters_sphere(start, motion, b, radius))
            t = min(t, _segment_enters_sphere(start, motion, cc, radius))
        if t < best_t or (t == best_t and t_index < best_triangle):
            best_t, best_triangle = t, t_index
    normal = np.zeros(3)
    if best_triangle < 0:
        return False, 1.0, -1, normal
    tri = mesh.triangles[best_triangle]
    nt = mesh.triangle_normals[best_triangle]
    at = np.empty(3)
    for i in range(3):
        at[i] = start[i] + best_t * motion[i]
    qx, qy, qz, region = closest_point_on_triangle(
        at, mesh.vertices[tri[0]], mesh.vertices[tri[1]], mesh.vertices[tri[2]]
    )
    dx, dy, dz = at[0] - qx, at[1] - qy, at[2] - qz
    d = np.sqrt(dx * dx + dy * dy + dz * dz)
    if region == FACE or d <= tol:
        # face (or the centre itself crossing): the normal facing where the sphere came from
        s0 = (
            (start[0] - mesh.vertices[tri[0], 0]) * nt[0]
            + (start[1] - mesh.vertices[tri[0], 1]) * nt[1]
            + (start[2] - mesh.vertices[tri[0], 2]) * nt[2]
        )
        side = 1.0 if s0 >= 0.0 else -1.0
        normal[0], normal[1], normal[2] = side * nt[0], side * nt[1], side * nt[2]
    else:
        normal[0], normal[1], normal[2] = dx / d, dy / d, dz / d
    return True, best_t, best_triangle, normal
