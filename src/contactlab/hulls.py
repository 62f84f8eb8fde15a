"""Convex hulls: geometry, mass properties, and a packed layout for compiled contact code.

A :class:`Hull` is the convex hull of a point set, built once (NumPy/SciPy, no Numba):

* **Faces** are polygons, not triangles: the triangles Qhull returns are merged where they
  are coplanar, so a cube has 6 square faces, not 12 triangles. Each face has an outward
  unit normal ``n``, an offset (``n · x = offset`` on the face, ``n · x ≤ offset`` inside the
  hull) and its corners in counter-clockwise order seen from outside (right-hand rule about
  ``n``). Corners that lie on a straight edge (within a relative ``TOLERANCE``) are not
  vertices.
* **Edges** are the unique undirected edges between two faces, each with the two faces it
  joins; contact code needs them for the edge–edge axes of the separating axis test.
* **Mass properties** are those of the uniform solid: volume, centre of mass and inertia
  tensor, exact for the polyhedron (signed tetrahedra from a point inside, summed), then
  principal moments and axes.
* **Body frame.** Everything is stored in the body frame: the principal frame with its origin
  at the centre of mass. ``orientation`` (unit quaternion w, x, y, z) and ``offset`` [m] take
  it to the frame the points were given in: ``x_given = R(orientation) x_body + offset``.
  When the given frame is already principal (the inertia tensor about the centre of mass is
  diagonal: a box given along its axes, a regular tetrahedron, ...) the axes are kept as
  given (``orientation = (1, 0, 0, 0)``), so the body frame is the given frame moved to the
  centre of mass. :meth:`Hull.body_pose` turns a pose of the given frame into the pose of
  the body.

Packed layout (:func:`pack_hulls`), for H hulls with V vertices, F faces, K face corners and
E edges in all; every index is *local* to its hull (vertex indices count from the hull's
first vertex, face indices from its first face):

=====================  ===========  ============================================================
array                  shape        meaning
=====================  ===========  ============================================================
``vertex_start``       (H+1,) int   hull h owns vertices ``vertex_start[h] : vertex_start[h+1]``
``vertices``           (V, 3)       body-frame positions [m]
``face_start``         (H+1,) int   hull h owns faces ``face_start[h] : face_start[h+1]``
``face_normal``        (F, 3)       outward unit normals, body frame
``face_offset``        (F,)         plane offsets [m]: ``face_normal · x = face_offset`` on the face
``face_vertex_start``  (F+1,) int   face f's corners are ``face_vertex_index[face_vertex_start[f] :
                                    face_vertex_start[f+1]]`` (global positions in that array)
``face_vertex_index``  (K,) int     corner vertex indices (local), counter-clockwise from outside
``edge_start``         (H+1,) int   hull h owns edges ``edge_start[h] : edge_start[h+1]``
``edge_vertex``        (E, 2) int   the edge's two vertex indices (local), low first
``edge_face``          (E, 2) int   the two faces (local) the edge joins
``radius``             (H,)         largest distance [m] of a vertex from the centre of mass
=====================  ===========  ============================================================

:func:`hull_arrays` slices one hull out of a packed dict, in the argument order of the
compiled routines of :mod:`contactlab.collision.convex`; :func:`box_as_hull` packs a box the same
way (the builder gives every box body such a hull, for the hull routines to meet it);
:func:`join_packed` joins packed dicts and :func:`fan_triangles` adds every face's triangles.

The geometric steps of :func:`build_hull` (faces from Qhull's triangles, edges, mass moments,
principal frame) are in :mod:`contactlab.hull_geometry`.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, replace
from dataclasses import field as dataclass_field

import numpy as np
from numpy.typing import ArrayLike

from .counts import RowCount
from .errors import InputError
from .hull_geometry import (
    check_convex,
    face_polygons,
    hull_edges,
    matrix_to_quaternion,
    merge_close,
    merge_coplanar,
    principal_frame,
    qhull_triangles,
    quaternion_multiply,
    quaternion_to_matrix,
    volume_moments,
)

TOLERANCE = 1e-9  # geometric tolerance, × the diagonal of the points' bounding box
CONVEX_TOLERANCE = 1e-6  # require_convex: a point deeper inside than this × the diagonal is "inside"
DEFAULT_DENSITY = 1000.0  # [kg/m³] when neither mass nor density is given (water)


@dataclass(frozen=True)
class Hull:
    """A convex polyhedron in its body frame (principal axes, origin at the centre of mass)."""

    vertices: np.ndarray
    """(V, 3) corner positions [m], body frame."""
    face_normal: np.ndarray
    """(F, 3) outward unit normals."""
    face_offset: np.ndarray
    """(F,) [m], ``n · x = offset`` on the face."""
    face_vertex_start: np.ndarray
    """(F+1,) int: face f's corners, counter-clockwise seen from outside, are
    ``face_vertex_index[face_vertex_start[f]:face_vertex_start[f+1]]``."""
    face_vertex_index: np.ndarray
    """(K,) int, the faces' corners (see ``face_vertex_start``)."""
    edge_vertex: np.ndarray
    """(E, 2) int vertex indices (low first)."""
    edge_face: np.ndarray
    """(E, 2) int the two faces joined."""
    mass: float
    """[kg]"""
    volume: float
    """[m³]"""
    density: float
    """[kg/m³]"""
    inertia: np.ndarray
    """(3,) principal moments [kg m²] about the centre of mass (the body axes)."""
    inertia_tensor: np.ndarray
    """(3, 3) [kg m²] about the centre of mass, in the given frame."""
    orientation: np.ndarray
    """(4,) unit quaternion (w, x, y, z), body → given frame."""
    offset: np.ndarray
    """(3,) [m] the centre of mass in the given frame: ``x_given = R x_body + offset``."""
    radius: float
    """largest distance [m] of a vertex from the centre of mass."""
    source_indices: np.ndarray | None = dataclass_field(default=None, repr=False)
    """(V,) int, the given point each vertex comes from."""

    vertex_count = RowCount("vertices")
    """V, the number of corners."""
    face_count = RowCount("face_normal")
    """F, the number of faces."""
    edge_count = RowCount("edge_vertex")
    """E, the number of edges."""

    @property
    def center_of_mass(self) -> np.ndarray:
        """(3,) [m] the centre of mass in the frame the points were given in (= ``offset``)."""
        return self.offset

    @property
    def principal_axes(self) -> np.ndarray:
        """(3, 3) rotation matrix body → given frame; its columns are the principal axes."""
        return quaternion_to_matrix(self.orientation)

    def face(self, f: int) -> np.ndarray:
        """Vertex indices (counter-clockwise from outside) of face ``f``."""
        return self.face_vertex_index[self.face_vertex_start[f] : self.face_vertex_start[f + 1]]

    def given_vertices(self) -> np.ndarray:
        """(V, 3) the vertices [m] in the frame the points were given in."""
        return self.vertices @ self.principal_axes.T + self.offset

    def body_pose(
        self, position: ArrayLike = (0.0, 0.0, 0.0), orientation: ArrayLike = (1.0, 0.0, 0.0, 0.0)
    ) -> tuple[np.ndarray, np.ndarray]:
        """Pose of the body frame when the given frame is placed at ``position`` [m] with
        ``orientation`` (w, x, y, z) in the world: returns (body position (3,), body orientation (4,))."""
        position = np.asarray(position, dtype=float)
        q = np.asarray(orientation, dtype=float)
        q = q / np.linalg.norm(q)
        body_position = position + quaternion_to_matrix(q) @ self.offset
        body_orientation = quaternion_multiply(q, self.orientation)
        if body_orientation[0] < 0.0:
            body_orientation = -body_orientation
        return body_position, body_orientation

    def with_inertia(self, tensor: np.ndarray) -> Hull:
        """This hull with the inertia ``tensor`` (3, 3) [kg m²] about its centre of mass, in the
        frame its points were given in, in place of the uniform solid's: the body frame turned onto
        that tensor's principal axes (:func:`~contactlab.hull_geometry.principal_frame`: the given
        axes themselves for a diagonal tensor), the vertices and normals with it; the mass, centre
        of mass and shape are unchanged."""
        moments, axes = principal_frame(tensor)
        turn = axes.T @ self.principal_axes  # old body frame -> new body frame
        return replace(
            self,
            vertices=np.ascontiguousarray(self.vertices @ turn.T),
            face_normal=np.ascontiguousarray(self.face_normal @ turn.T),
            inertia=moments,
            inertia_tensor=np.array(tensor, dtype=float),
            orientation=matrix_to_quaternion(axes),
        )

    def __repr__(self):
        return (
            f"Hull({self.vertex_count} vertices, {self.face_count} faces, {self.edge_count} edges, "
            f"volume {self.volume:.6g} m³, mass {self.mass:.6g} kg)"
        )


# ------------------------------------------------------------------------------------------
# construction


def build_hull(
    points: ArrayLike,
    field: str = "points",
    *,
    mass: float | None = None,
    density: float | None = None,
    require_convex: bool = False,
) -> Hull:
    """The convex hull of ``points`` (n, 3) [m] as a uniform solid, in its body frame.

    ``mass`` [kg] or ``density`` [kg/m³] (at most one; neither: ``DEFAULT_DENSITY``).
    ``require_convex``: the points must be the corners of a convex shape — a point lying
    inside the hull (deeper than ``CONVEX_TOLERANCE`` × the size) is an error, since a hull
    would silently fill in the shape's hollows.

    Raises :class:`~contactlab.errors.InputError` naming ``field`` for: not an (n, 3) array,
    fewer than 4 points, non-finite values, a flat or collinear set (zero volume), a
    non-convex set when ``require_convex``, and a bad mass or density.
    """
    xyz = _as_points(points, field)
    given_mass, given_density = _mass_or_density(mass, density, field)
    size = float(np.linalg.norm(xyz.max(axis=0) - xyz.min(axis=0)))
    if size == 0.0:
        raise InputError(field, f"expected xyz spanning a solid, found {len(xyz)} copies of one point")
    tolerance = TOLERANCE * size
    representative = merge_close(xyz, tolerance)
    unique = np.unique(representative)
    if len(unique) < 4:
        raise InputError(field, f"expected at least 4 distinct xyz, found {len(unique)}")
    triangles, equations = qhull_triangles(xyz[unique], field)
    triangles = unique[triangles]  # back to indices into ``xyz``
    faces, face_normals = merge_coplanar(xyz, triangles, equations, tolerance)
    faces = face_polygons(xyz, faces, face_normals, tolerance)
    volume, center, second_moment = volume_moments(xyz, faces)
    if not volume > TOLERANCE * size**3:  # zero volume up to round-off
        raise InputError(
            field, f"expected xyz spanning a solid, found a flat or collinear set (volume {volume:.3g} m³)"
        )
    if require_convex:
        check_convex(xyz, faces, face_normals, field, CONVEX_TOLERANCE * size)
    edges, edge_faces = hull_edges(faces, field)
    solid_mass, solid_density = _solid_mass(given_mass, given_density, volume)
    # inertia about the centre of mass: I = tr(C) 1 − C with C = ∫ ρ r rᵀ dV
    covariance = solid_density * (second_moment - volume * np.outer(center, center))
    tensor = np.trace(covariance) * np.eye(3) - covariance
    tensor = 0.5 * (tensor + tensor.T)
    moments, axes = principal_frame(tensor)
    # renumber: the hull's own vertices 0..V−1 in the order of the given xyz
    used = np.unique(np.concatenate(faces))
    local = np.full(len(xyz), -1, dtype=np.int64)
    local[used] = np.arange(len(used))
    body_vertices = (xyz[used] - center) @ axes
    normals = face_normals @ axes  # rows: the normals in the body frame
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    starts = np.concatenate([[0], np.cumsum([len(p) for p in faces])]).astype(np.int64)
    corners = local[np.concatenate(faces)]
    corner_face = np.repeat(np.arange(len(faces)), np.diff(starts))
    heights = np.einsum("ij,ij->i", body_vertices[corners], normals[corner_face])
    offsets = np.full(len(faces), -np.inf)
    np.maximum.at(offsets, corner_face, heights)
    return Hull(
        vertices=np.ascontiguousarray(body_vertices),
        face_normal=np.ascontiguousarray(normals),
        face_offset=offsets,
        face_vertex_start=starts,
        face_vertex_index=corners.astype(np.int64),
        edge_vertex=local[edges].astype(np.int64).reshape(-1, 2) if len(edges) else np.zeros((0, 2), np.int64),
        edge_face=edge_faces,
        mass=float(solid_mass),
        volume=float(volume),
        density=float(solid_density),
        inertia=moments,
        inertia_tensor=tensor,
        orientation=matrix_to_quaternion(axes),
        offset=center,
        radius=float(np.linalg.norm(body_vertices, axis=1).max()),
        source_indices=used,
    )


def _as_points(points: ArrayLike, field: str) -> np.ndarray:
    try:
        points = np.array(points, dtype=float)
    except (TypeError, ValueError):
        raise InputError(
            field, "expected an array of 3D points (n, 3) [m], found values that are not numbers"
        ) from None
    if points.ndim != 2 or points.shape[1] != 3:
        raise InputError(field, f"expected an array of 3D points of shape (n, 3), found shape {points.shape}")
    if len(points) < 4:
        raise InputError(field, f"expected at least 4 points to enclose a solid, found {len(points)}")
    bad = ~np.isfinite(points).all(axis=1)
    if bad.any():
        raise InputError(
            field,
            f"expected finite coordinates, found {int(bad.sum())} points with NaN or infinite "
            f"values (first: point {int(np.argmax(bad))})",
        )
    return points


def _mass_or_density(mass: float | None, density: float | None, field: str) -> tuple[float | None, float | None]:
    if mass is not None and density is not None:
        raise InputError(field, "expected a mass or a density, found both")
    for name, value in (("mass", mass), ("density", density)):
        if value is not None:
            try:
                value = float(value)
            except (TypeError, ValueError):
                raise InputError(field, f"expected the {name} to be a positive number, found {value!r}") from None
            if not (np.isfinite(value) and value > 0.0):
                raise InputError(field, f"expected the {name} to be a positive finite number, found {value}")
    if mass is None and density is None:
        density = DEFAULT_DENSITY
    return (None if mass is None else float(mass)), (None if density is None else float(density))


def _solid_mass(mass: float | None, density: float | None, volume: float) -> tuple[float, float]:
    """(mass [kg], density [kg/m³]) of a uniform solid of ``volume`` [m³] of the given mass or,
    that None, of the given density (_mass_or_density gives one of the two)."""
    if mass is not None:
        return mass, mass / volume
    assert density is not None  # _mass_or_density defaults it when no mass is given
    return density * volume, density


# ------------------------------------------------------------------------------------------
# files


def load_hull_points(path: str | os.PathLike[str], scale: float = 1.0, field: str = "file") -> np.ndarray:
    """The vertices (n, 3) [m] of the triangles of an OBJ, STL or PLY file, × ``scale``: the
    hull of the vertices is what :func:`build_hull` makes of them.

    Read by :func:`contactlab.meshes.load_mesh`, with its errors (InputError naming ``field``
    for a bad scale, a missing file, an unsupported format, an unreadable file, no triangles).
    """
    from .meshes import load_mesh

    return load_mesh(path, scale, field=field).vertices.copy()


# ------------------------------------------------------------------------------------------
# packed layout


def pack_hulls(hulls: Iterable[Hull]) -> dict[str, np.ndarray]:
    """Concatenate hulls into flat arrays (see the module docstring for names and shapes)."""
    hulls = list(hulls)
    vertex_counts = [h.vertex_count for h in hulls]
    face_counts = [h.face_count for h in hulls]
    edge_counts = [h.edge_count for h in hulls]
    corner_counts = [len(h.face_vertex_index) for h in hulls]
    face_vertex_start = [np.zeros(1, dtype=np.int64)]
    base = 0
    for h, corners in zip(hulls, corner_counts):
        face_vertex_start.append(h.face_vertex_start[1:] + base)
        base += corners

    def cat(arrays, shape, dtype):
        arrays = [np.asarray(a, dtype=dtype).reshape((-1,) + shape) for a in arrays]
        return np.ascontiguousarray(np.concatenate(arrays)) if arrays else np.zeros((0,) + shape, dtype)

    return {
        "vertex_start": np.concatenate([[0], np.cumsum(vertex_counts)]).astype(np.int64),
        "vertices": cat([h.vertices for h in hulls], (3,), float),
        "face_start": np.concatenate([[0], np.cumsum(face_counts)]).astype(np.int64),
        "face_normal": cat([h.face_normal for h in hulls], (3,), float),
        "face_offset": cat([h.face_offset for h in hulls], (), float),
        "face_vertex_start": np.concatenate(face_vertex_start).astype(np.int64),
        "face_vertex_index": cat([h.face_vertex_index for h in hulls], (), np.int64),
        "edge_start": np.concatenate([[0], np.cumsum(edge_counts)]).astype(np.int64),
        "edge_vertex": cat([h.edge_vertex for h in hulls], (2,), np.int64),
        "edge_face": cat([h.edge_face for h in hulls], (2,), np.int64),
        "radius": np.array([h.radius for h in hulls], dtype=float),
    }


def box_as_hull(half_extents: ArrayLike) -> dict[str, np.ndarray]:
    """The packed arrays (as :func:`pack_hulls` makes them, H = 1) of a box
    with ``half_extents`` (3,) [m], centred on its body origin along its body axes.

    Vertex ``i`` is the corner (±hx, ±hy, ±hz) with bit 0 of ``i`` the sign of x, bit 1 of y,
    bit 2 of z (set: +), as in :func:`contactlab.collision.narrow_phase.box_plane`; faces ``2k`` and ``2k+1`` are
    −axis k and +axis k.
    """
    half = np.asarray(half_extents, dtype=float).reshape(3)
    if not (np.isfinite(half).all() and (half > 0.0).all()):
        raise ValueError(f"half extents must be positive and finite, found {half}")
    signs = np.array([[1.0 if i & 1 else -1.0, 1.0 if i & 2 else -1.0, 1.0 if i & 4 else -1.0] for i in range(8)])
    vertices = signs * half
    normals, offsets, polygons = [], [], []
    for k in range(3):
        for sign in (-1.0, 1.0):
            n = np.zeros(3)
            n[k] = sign
            ids = np.nonzero(signs[:, k] == sign)[0]
            u = np.zeros(3)
            u[(k + 1) % 3] = 1.0
            v = np.cross(n, u)  # u × v = n
            angle = np.arctan2(signs[ids] @ v, signs[ids] @ u)
            polygons.append(ids[np.argsort(angle)])
            normals.append(n)
            offsets.append(half[k])
    edges, edge_faces = hull_edges(polygons, "half_extents")
    return {
        "vertex_start": np.array([0, 8], dtype=np.int64),
        "vertices": np.ascontiguousarray(vertices),
        "face_start": np.array([0, 6], dtype=np.int64),
        "face_normal": np.array(normals),
        "face_offset": np.array(offsets),
        "face_vertex_start": np.arange(0, 25, 4, dtype=np.int64),
        "face_vertex_index": np.concatenate(polygons).astype(np.int64),
        "edge_start": np.array([0, len(edges)], dtype=np.int64),
        "edge_vertex": edges,
        "edge_face": edge_faces,
        "radius": np.array([float(np.linalg.norm(half))]),
    }


def join_packed(packs: Sequence[Mapping[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """Join packed hull dicts (the layout of :func:`pack_hulls`) into one, shifting their start indices."""
    starts = {
        "vertex_start": "vertices",
        "face_start": "face_normal",
        "edge_start": "edge_vertex",
        "face_vertex_start": "face_vertex_index",
    }
    out: dict[str, list[np.ndarray]] = {key: [] for key in packs[0]}
    base = {key: 0 for key in starts}
    for k, hull_pack in enumerate(packs):
        for key, values in hull_pack.items():
            if key in starts:
                shifted = values + base[key]
                out[key].append(shifted if k == 0 else shifted[1:])
                base[key] += len(hull_pack[starts[key]])
            else:
                out[key].append(values)
    return {key: np.ascontiguousarray(np.concatenate(values)) for key, values in out.items()}


def fan_triangles(packed: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Triangles of every hull's faces, fanned from each face's first corner (built once).

    Returns triangle_start (H+1,) int64 and triangles (T, 3) int64, local vertex indices, wound
    like the faces (counter-clockwise from outside)."""
    triangles: list[tuple[int, int, int]] = []
    counts = []
    fvs, fvi = packed["face_vertex_start"], packed["face_vertex_index"]
    for h in range(len(packed["vertex_start"]) - 1):
        before = len(triangles)
        for f in range(packed["face_start"][h], packed["face_start"][h + 1]):
            corners = fvi[fvs[f] : fvs[f + 1]]
            triangles.extend((corners[0], corners[i], corners[i + 1]) for i in range(1, len(corners) - 1))
        counts.append(len(triangles) - before)
    return {
        "triangle_start": np.concatenate([[0], np.cumsum(counts)]).astype(np.int64),
        "triangles": np.array(triangles, dtype=np.int64).reshape(-1, 3),
    }


def hull_arrays(packed: Mapping[str, np.ndarray], h: int) -> tuple[np.ndarray, ...]:
    """One hull's arrays out of a packed dict, as the compiled routines take them:
    (vertices, face_normal, face_offset, face_vertex_start, face_vertex_index, edge_vertex, edge_face).

    ``face_vertex_start`` keeps its global values; the routines subtract its first entry, so
    it indexes the sliced ``face_vertex_index``. All slices are views (no copy)."""
    v0, v1 = packed["vertex_start"][h], packed["vertex_start"][h + 1]
    f0, f1 = packed["face_start"][h], packed["face_start"][h + 1]
    e0, e1 = packed["edge_start"][h], packed["edge_start"][h + 1]
    fvs = packed["face_vertex_start"][f0 : f1 + 1]
    return (
        packed["vertices"][v0:v1],
        packed["face_normal"][f0:f1],
        packed["face_offset"][f0:f1],
        fvs,
        packed["face_vertex_index"][fvs[0] : fvs[-1]],
        packed["edge_vertex"][e0:e1],
        packed["edge_face"][e0:e1],
    )
