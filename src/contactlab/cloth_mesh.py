"""A cloth's mesh and spring network, as ``ModelBuilder.add_cloth`` lays them out.

Two sources of a mesh: a grid (:func:`grid`: ``size`` (w, h) [m] and ``resolution`` (nx, ny)
vertices in the cloth's local xy plane) or a triangle mesh file (:func:`from_file`: OBJ, STL or
PLY, read with trimesh). :func:`lay_out` places either in the world and turns it into what the
Model holds of a cloth: vertex positions, triangles, springs with their stiffness and rest
length, each vertex's share of the mass, and the pinned vertices.

This is the cloth's geometry when it is built; its forces while it moves (the springs pulling
and their Jacobians) are :mod:`contactlab.dynamics.cloth`'s concern.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from . import rotations
from .errors import InputError, first_line
from .validation import (
    AREAL_DENSITY,
    FACTOR,
    LENGTH,
    MASS,
    as_array,
    check_dynamic_count,
    derived_mass,
    file_path,
    number,
    vector,
)

PINNED_NAMES = ("corners", "top_corners", "top_edge", "bottom_edge", "left_edge", "right_edge")


@dataclass
class ClothMesh:
    """A cloth in its local frame, before it is placed: V vertices, F triangles and the vertex
    pairs (local indices) of its three spring families."""

    vertices: np.ndarray
    """(V, 3) [m]"""
    triangles: np.ndarray
    """(F, 3) int64, counter-clockwise seen from +z of a grid"""
    stretch: np.ndarray
    """(E, 2) int64: grid lines, or every triangle edge of a mesh file"""
    shear: np.ndarray
    """(H, 2) int64: both diagonals of each grid cell; none for a mesh file"""
    bend: np.ndarray
    """(G, 2) int64: vertices two apart, or the far corners of triangles sharing an edge"""
    named: dict
    """vertex set name -> local indices (a grid's PINNED_NAMES; none for a mesh file)"""


@dataclass
class LaidOut:
    """A cloth placed in the world: what ``ModelBuilder.add_cloth`` stores of it."""

    position: np.ndarray
    """(V, 3) [m] world positions of the vertices"""
    triangles: np.ndarray
    """(F, 3) int64 local vertex indices"""
    springs: np.ndarray
    """(S, 2) int64 local vertex pairs: stretch, then shear, then bend"""
    stiffness: np.ndarray
    """(S,) [N/m]"""
    rest: np.ndarray
    """(S,) [m] the springs' lengths as built"""
    mass: np.ndarray
    """(V,) [kg] each vertex's share of the cloth's mass"""
    pinned: np.ndarray
    """(V,) bool: held in place"""


def grid(size: ArrayLike | None, resolution: Sequence[int] | None) -> ClothMesh:
    """A grid cloth of ``size`` (w, h) [m] and ``resolution`` (nx, ny ≥ 2) vertices, centred on
    its origin: vertex (a, b) is local index a + nx b, at (−w/2 + a w/(nx−1), −h/2 + b h/(ny−1), 0).
    InputError naming "size" or "resolution"."""
    if resolution is None:
        raise InputError("resolution", "a grid cloth needs resolution = [nx, ny] (vertices along x and y)")
    width, height = vector(size, "size", 2, quantity=LENGTH, positive=True)
    counts = as_array(resolution, "resolution", "a list of 2 whole numbers")
    if counts.shape != (2,) or not np.all(np.isfinite(counts)) or not np.all(counts == np.round(counts)):
        raise InputError("resolution", f"expected a list of 2 whole numbers, found {resolution!r}")
    nx, ny = (int(c) for c in counts)
    if nx < 2 or ny < 2:
        raise InputError("resolution", f"must be at least 2 vertices along each axis, found [{nx}, {ny}]")
    check_dynamic_count(nx * ny, "resolution", f"a cloth of {nx} x {ny} vertices")
    a, b = np.meshgrid(np.arange(nx), np.arange(ny), indexing="xy")  # (ny, nx): a along x, fastest
    vertices = np.stack(
        [-width / 2 + a.ravel() * width / (nx - 1), -height / 2 + b.ravel() * height / (ny - 1), np.zeros(nx * ny)],
        axis=1,
    )
    vid = a + nx * b  # (ny, nx) vertex index

    def pairs(first, second):
        return np.stack([first.ravel(), second.ravel()], axis=1).astype(np.int64)

    corner00, corner10, corner01, corner11 = vid[:-1, :-1], vid[:-1, 1:], vid[1:, :-1], vid[1:, 1:]
    triangles = np.concatenate(
        [
            np.stack([corner00.ravel(), corner10.ravel(), corner11.ravel()], axis=1),
            np.stack([corner00.ravel(), corner11.ravel(), corner01.ravel()], axis=1),
        ]
    )
    named = {
        "corners": np.array([vid[0, 0], vid[0, -1], vid[-1, 0], vid[-1, -1]]),
        "top_corners": np.array([vid[-1, 0], vid[-1, -1]]),
        "top_edge": vid[-1, :],
        "bottom_edge": vid[0, :],
        "left_edge": vid[:, 0],
        "right_edge": vid[:, -1],
    }
    return ClothMesh(
        vertices,
        triangles.astype(np.int64),
        stretch=np.concatenate([pairs(vid[:, :-1], vid[:, 1:]), pairs(vid[:-1, :], vid[1:, :])]),
        shear=np.concatenate([pairs(corner00, corner11), pairs(corner10, corner01)]),
        bend=np.concatenate([pairs(vid[:, :-2], vid[:, 2:]), pairs(vid[:-2, :], vid[2:, :])]),
        named=named,
    )


def from_file(file: str | os.PathLike[str], scale: float) -> ClothMesh:
    """A cloth from a mesh file: its vertices [m] times ``scale``, coincident ones merged (the
    first kept in place, so indices follow the file's order otherwise), degenerate triangles
    dropped; stretch springs along the edges, bend springs between the far corners of each two
    triangles sharing an edge, no shear springs, no named vertex sets. InputError naming
    "file" or "scale"."""
    from .meshes import MESH_FORMATS

    scale = number(scale, "scale", 0.0, strict=True, quantity=FACTOR)
    path = file_path(file)
    if not os.path.isfile(path):
        raise InputError("file", f"expected an existing file, found no file at {path}")
    if os.path.splitext(path)[1].lower() not in MESH_FORMATS:
        raise InputError("file", f"unsupported mesh format of {path}; expected .obj, .stl or .ply")
    try:
        import trimesh

        loaded = trimesh.load(path, force="mesh", process=False)
        vertices = np.asarray(loaded.vertices, dtype=float)
        faces = np.asarray(loaded.faces, dtype=np.int64)
    except Exception as error:  # trimesh raises many types on broken files
        raise InputError("file", f"could not read the mesh file {path} ({first_line(error)})") from None
    if faces.ndim != 2 or faces.shape[1:] != (3,) or len(faces) == 0 or len(vertices) == 0:
        raise InputError("file", f"the mesh file {path} contains no triangles")
    if not np.all(np.isfinite(vertices)):
        raise InputError("file", f"the mesh file {path} has non-finite vertex coordinates")
    # merge coincident vertices, numbering the survivors in order of first appearance
    _, first, inverse = np.unique(vertices, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)
    renumber = np.empty(len(first), dtype=np.int64)
    renumber[order] = np.arange(len(first))
    vertices = vertices[first[order]] * scale
    LENGTH.check(vertices, "file")
    faces = renumber[inverse.reshape(-1)][faces]
    faces = faces[(faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 2] != faces[:, 0])]
    if len(faces) == 0:
        raise InputError("file", f"the mesh file {path} has only degenerate triangles")
    # edges: each unordered pair once; bends: the two far corners of triangles sharing an edge
    half_edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    opposite = np.concatenate([faces[:, 2], faces[:, 0], faces[:, 1]])
    edges, edge_of = np.unique(np.sort(half_edges, axis=1), axis=0, return_inverse=True)
    edge_of = edge_of.reshape(-1)
    order = np.argsort(edge_of, kind="stable")
    sorted_edges, sorted_opposite = edge_of[order], opposite[order]
    shared = np.nonzero(sorted_edges[1:] == sorted_edges[:-1])[0]  # consecutive half-edges of one edge
    bends = np.stack([sorted_opposite[shared], sorted_opposite[shared + 1]], axis=1)
    bends = bends[bends[:, 0] != bends[:, 1]]
    return ClothMesh(
        vertices, faces, edges.astype(np.int64), np.zeros((0, 2), dtype=np.int64), bends.astype(np.int64), {}
    )


def triangle_areas(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Areas (F,) [m²] of triangles (F, 3) over vertices (V, 3)."""
    e1 = vertices[triangles[:, 1]] - vertices[triangles[:, 0]]
    e2 = vertices[triangles[:, 2]] - vertices[triangles[:, 0]]
    return 0.5 * np.linalg.norm(np.cross(e1, e2), axis=1)


def check_self_thickness(vertices: np.ndarray, triangles: np.ndarray, thickness: float) -> None:
    """InputError naming "thickness" unless twice ``thickness`` [m] is less than the shortest
    height of the triangles (F, 3) over vertices (V, 3) [m] (of those of positive area): a
    self-colliding cloth (collision.cloth_self) keeps its elements 2 × thickness apart, and a
    vertex nearer than that to a neighbouring element at rest would push it away."""
    corners = vertices[triangles]
    longest = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max(axis=1)
    area = triangle_areas(vertices, triangles)
    useful = area > 0.0
    height = float((2.0 * area[useful] / longest[useful]).min(initial=np.inf))
    if not 2.0 * thickness < height:
        raise InputError(
            "thickness",
            f"twice the thickness ({2.0 * thickness:.3g} m) must be less than the cloth's shortest triangle "
            f"height ({height:.3g} m) when it collides with itself; make it thinner, or set self_collision = false",
        )


def pinned_vertices(
    pinned: int | str | Sequence[int | str] | None, count: int, named: Mapping[str, Sequence[int]]
) -> np.ndarray:
    """Mask (count,) of the vertices ``pinned`` names: local indices and names of ``named``
    (one alone or a list; None: none). InputError naming "pinned"."""
    if pinned is None:
        pinned = ()
    if isinstance(pinned, (str, int, np.integer)):
        pinned = [pinned]
    mask = np.zeros(count, dtype=bool)
    try:
        items = list(pinned)
    except TypeError:
        raise InputError("pinned", f"expected a list of vertex indices or names, found {pinned!r}") from None
    for item in items:
        if isinstance(item, str):
            if item not in named:
                known = ", ".join(named) if named else "none: a mesh cloth takes vertex indices only"
                raise InputError("pinned", f"unknown vertex set {item!r} (known: {known})")
            mask[named[item]] = True
        elif isinstance(item, (int, np.integer)) and not isinstance(item, bool):
            if not 0 <= item < count:
                raise InputError("pinned", f"vertex index {item} is outside this cloth's vertices 0..{count - 1}")
            mask[int(item)] = True
        else:
            raise InputError("pinned", f"expected vertex indices or names, found {item!r}")
    return mask


def lay_out(
    mesh: ClothMesh,
    from_a_file: bool,
    position: np.ndarray,
    orientation: np.ndarray,
    mass: float | None,
    density: float | None,
    stiffness: Sequence[float],
    pinned: int | str | Sequence[int | str] | None,
) -> LaidOut:
    """``mesh`` (from :func:`grid`, or :func:`from_file` where ``from_a_file``) placed at
    ``position`` (3,) [m] turned by the unit quaternion ``orientation`` (4,), with springs of
    ``stiffness`` (stretch, shear, bend) [N/m]. Of ``mass`` [kg] (the whole cloth) and
    ``density`` [kg/m²] one is given; a grid's mass is shared evenly over its vertices, a mesh
    file's by triangle areas (a third of each triangle's to each corner). InputError naming
    "size" (a grid) or "file" (zero area, a vertex in no triangle of positive area, two vertices
    on one spot), "mass", "density" or "pinned"."""
    field = "file" if from_a_file else "size"
    count = len(mesh.vertices)
    world = rotations.to_matrix(orientation[None])[0]
    vertex_position = mesh.vertices @ world.T + position
    area = triangle_areas(vertex_position, mesh.triangles)
    if area.sum() <= 0.0:
        raise InputError(field, "the cloth has zero area")
    if from_a_file:
        share = np.bincount(mesh.triangles.ravel(), np.repeat(area / 3.0, 3), minlength=count)
        if (share <= 0.0).any():
            raise InputError(
                "file",
                f"vertex {int(np.argmin(share))} of the mesh is in no triangle of positive area, so it gets no mass",
            )
        share = share / share.sum()
    else:
        share = np.full(count, 1.0 / count)
    if mass is not None:
        total = number(mass, "mass", 0.0, strict=True, quantity=MASS)
    else:
        total = number(density, "density", 0.0, strict=True, quantity=AREAL_DENSITY) * area.sum()
        derived_mass(total, "density")
    pinned_mask = pinned_vertices(pinned, count, mesh.named)
    groups = (mesh.stretch, mesh.shear, mesh.bend)
    springs = np.concatenate(groups).astype(np.int64).reshape(-1, 2)
    rest = np.linalg.norm(vertex_position[springs[:, 1]] - vertex_position[springs[:, 0]], axis=1)
    if (rest <= 0.0).any():
        raise InputError(field, "two vertices of the cloth coincide")
    return LaidOut(
        vertex_position,
        mesh.triangles,
        springs,
        np.concatenate([np.full(len(g), k) for g, k in zip(groups, stiffness)]),
        rest,
        total * share,
        pinned_mask,
    )
