"""What a picture of a trajectory frames: the static obstacles around what moves, and the camera's box.

:func:`scenery` splits the obstacles' triangles (the trajectory's ``obstacle_vertices`` and
``obstacle_triangles``) into flat pieces (a plane's square, a flat mesh) and solid ones, bounds
what moves over the samples read (bodies' surfaces, particles with their radius, solid
obstacles), and cuts every flat piece to a rectangle around that, reaching :data:`MARGIN` of
its size beyond it, each plane cut to the free side of the others so that walls end at the
floor. :func:`axis_limits` is the box the camera shows. :func:`contactlab.render.still`,
:func:`contactlab.render.render` and the viewer frame their scenes through these.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from . import surfaces

MARGIN = 0.15  # planes reach this share of the content's size beyond it

# (lower (3,), upper (3,)) [m], corners of an axis-aligned box
Bounds = tuple[np.ndarray, np.ndarray]


def face_normals(faces: np.ndarray) -> np.ndarray:
    """Unit normals (N, 3) of triangles ``faces`` (N, 3, 3), right-handed (counter-clockwise)."""
    normals = np.cross(faces[:, 1] - faces[:, 0], faces[:, 2] - faces[:, 0])
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    return normals / np.where(length > 0, length, 1.0)


def _obstacle_pieces(triangles: np.ndarray) -> np.ndarray:
    """Label (M,) of the connected piece (one obstacle) each triangle belongs to.

    Every obstacle owns a contiguous range of vertices, so pieces are the runs of triangles
    whose vertex-index ranges overlap.
    """
    if len(triangles) == 0:
        return np.zeros(0, dtype=np.int64)
    low, high = triangles.min(axis=1), triangles.max(axis=1)
    order = np.argsort(low, kind="stable")
    reach = np.maximum.accumulate(high[order])
    new = np.concatenate([[True], low[order][1:] > reach[:-1]])
    labels = np.empty(len(triangles), dtype=np.int64)
    labels[order] = np.cumsum(new) - 1
    return labels


def _split_obstacles(vertices: np.ndarray, triangles: np.ndarray) -> tuple[list[np.ndarray], np.ndarray]:
    """Static obstacles as (flat, solid): ``flat`` a list of the faces (n, 3, 3) [m] of every
    flat piece (a plane's square, a flat mesh), ``solid`` the faces (m, 3, 3) [m] of all others."""
    flat: list[np.ndarray] = []
    solid: list[np.ndarray] = []
    labels = _obstacle_pieces(triangles)
    for label in range(labels.max(initial=-1) + 1):
        faces = vertices[triangles[labels == label]]
        points = faces.reshape(-1, 3)
        spread = np.linalg.svd(points - points.mean(axis=0), compute_uv=False)
        (flat if spread[-1] <= 1e-9 * max(spread[0], 1e-12) else solid).append(faces)
    return flat, np.concatenate(solid) if solid else np.zeros((0, 3, 3))


def _clip(polygon: np.ndarray, halfspaces: Sequence[tuple[np.ndarray, float]]) -> np.ndarray:
    """The part (k, 3) of the convex polygon (n, 3) where normal · x ≥ offset for every
    (normal (3,), offset) of ``halfspaces`` (Sutherland–Hodgman)."""
    for normal, offset in halfspaces:
        if len(polygon) == 0:
            break
        inside = polygon @ normal - offset  # ≥ 0 inside
        kept = []
        for i in range(len(polygon)):
            j = (i + 1) % len(polygon)
            if inside[i] >= 0:
                kept.append(polygon[i])
            if (inside[i] >= 0) != (inside[j] >= 0):
                kept.append(polygon[i] + (polygon[j] - polygon[i]) * inside[i] / (inside[i] - inside[j]))
        polygon = np.array(kept).reshape(-1, 3)
    return polygon


def cut_flat(flat: Sequence[np.ndarray], lower: np.ndarray, upper: np.ndarray) -> tuple[list[np.ndarray], np.ndarray]:
    """The flat obstacles as (polygons, normals): each face cut to the rectangle of its plane
    that covers the box ``lower``–``upper`` (3,) [m] seen along the plane's normal, and to the
    free side of every plane (a square of 2 triangles, wound counter-clockwise seen from its
    free side), so that walls end at the floor. polygons: list of (k, 3) [m]; normals (n, 3)."""
    corners = np.array(np.meshgrid(*zip(lower, upper))).reshape(3, -1).T
    normals = [face_normals(faces[:1])[0] for faces in flat]
    planes = [(i, normals[i], normals[i] @ faces[0, 0] - 1e-9) for i, faces in enumerate(flat) if len(faces) == 2]
    polygons, polygon_normals = [], []
    for i, (faces, normal) in enumerate(zip(flat, normals)):
        helper = np.eye(3)[np.argmin(np.abs(normal))]  # the world axis most along the plane
        u = helper - (helper @ normal) * normal
        u /= np.linalg.norm(u)
        halfspaces = [(n, o) for j, n, o in planes if j != i]
        for direction in (u, np.cross(normal, u)):
            extent = corners @ direction
            halfspaces += [(direction, extent.min()), (-direction, -extent.max())]
        for face in faces:
            polygon = _clip(face, halfspaces)
            if len(polygon) >= 3:
                polygons.append(polygon)
                polygon_normals.append(normal)
    return polygons, np.reshape(polygon_normals, (-1, 3))


def _content_bounds(arrays: Mapping[str, Any], solid_obstacles: np.ndarray) -> Bounds | None:
    """(lower (3,), upper (3,)) [m] of everything but flat obstacles over the whole trajectory:
    the bodies' surfaces in every sample, particles ± their radius, solid obstacles; None when
    there is none of these."""
    points = [solid_obstacles.reshape(-1, 3)]
    if len(arrays["body_surface_vertices"]):
        posed = [surfaces.posed_body_vertices(arrays, sample) for sample in range(len(arrays["time"]))]
        points += [np.array([p.min(axis=0) for p in posed]), np.array([p.max(axis=0) for p in posed])]
    position, radius = arrays["particle_position"], arrays["particle_radius"][:, None]
    if position.size:
        points += [(position - radius).min(axis=1), (position + radius).max(axis=1)]
    every = np.concatenate(points)
    if len(every) == 0:
        return None
    return every.min(axis=0), every.max(axis=0)


def _view_box(content: Bounds | None, flat: Sequence[np.ndarray]) -> Bounds:
    """(lower, upper) [m] the flat obstacles are cut to: the content's box made at least half
    as wide as its widest side in every direction, grown by MARGIN of that side."""
    if content is None:
        if not flat:
            return -np.ones(3), np.ones(3)
        points = np.concatenate([faces.reshape(-1, 3) for faces in flat])
        return points.min(axis=0), points.max(axis=0)
    lower, upper = content
    centre, half = 0.5 * (lower + upper), 0.5 * (upper - lower)
    size = max(half.max(), 0.05)
    half = np.maximum(half, 0.5 * size) + MARGIN * size
    return centre - half, centre + half


def axis_limits(content: Bounds | None, flat_polygons: Sequence[np.ndarray]) -> Bounds:
    """Axis limits (lower (3,), upper (3,)) [m] around the content and the cut flat obstacles,
    no side shorter than 5 % of the longest (for the box aspect)."""
    points = [np.concatenate(flat_polygons)] if flat_polygons else []
    if content is not None:
        points.append(np.stack(content))
    if not points:
        return -np.ones(3), np.ones(3)
    every = np.concatenate(points)
    lower, upper = every.min(axis=0), every.max(axis=0)
    centre, half = 0.5 * (lower + upper), 0.5 * (upper - lower)
    half = np.maximum(half, max(0.05 * half.max(), 1e-3))
    return centre - half, centre + half


def scenery(arrays: Mapping[str, Any]) -> tuple[Any, list[np.ndarray], np.ndarray, np.ndarray]:
    """The static obstacles framed around what moves in the trajectory ``arrays`` (its samples
    all read: pass the few that frame it), as still(), render() and the viewer draw them:
    (content: (lower (3,), upper (3,)) [m] of the bodies, particles and solid obstacles over
    the samples, or None; flat: the plane squares and flat meshes cut to a rectangle around the
    content, a list of convex polygons (k, 3) [m]; their unit normals (n, 3); solid: the faces
    (m, 3, 3) [m] of the other obstacles)."""
    flat, solid = _split_obstacles(arrays["obstacle_vertices"], arrays["obstacle_triangles"])
    content = _content_bounds(arrays, solid)
    flat_polygons, flat_normals = cut_flat(flat, *_view_box(content, flat))
    return content, flat_polygons, flat_normals, solid
