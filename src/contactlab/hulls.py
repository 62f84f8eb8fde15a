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
way (the builder gives every box body such a hull, for the hull routines to meet it).
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from dataclasses import field as dataclass_field

import numpy as np
from numpy.typing import ArrayLike

from .errors import InputError

TOLERANCE = 1e-9  # geometric tolerance, × the diagonal of the points' bounding box
CONVEX_TOLERANCE = 1e-6  # require_convex: a point deeper inside than this × the diagonal is "inside"
DEFAULT_DENSITY = 1000.0  # [kg/m³] when neither mass nor density is given (water)


@dataclass(frozen=True)
class Hull:
    """A convex polyhedron in its body frame (principal axes, origin at the centre of mass).

    Attributes
    ----------
    vertices: (V, 3) corner positions [m], body frame.
    face_normal: (F, 3) outward unit normals; face_offset: (F,) [m], ``n · x = offset`` on the face.
    face_vertex_start: (F+1,) int; face_vertex_index: (K,) int — face f's corners, counter-clockwise
        seen from outside, are ``face_vertex_index[face_vertex_start[f]:face_vertex_start[f+1]]``.
    edge_vertex: (E, 2) int vertex indices (low first); edge_face: (E, 2) int the two faces joined.
    mass [kg], volume [m³], density [kg/m³].
    inertia: (3,) principal moments [kg m²] about the centre of mass (the body axes).
    inertia_tensor: (3, 3) [kg m²] about the centre of mass, in the given frame.
    orientation: (4,) unit quaternion (w, x, y, z), body → given frame.
    offset: (3,) [m] the centre of mass in the given frame: ``x_given = R x_body + offset``.
    radius: largest distance [m] of a vertex from the centre of mass.
    source_indices: (V,) int, the given point each vertex comes from.
    """

    vertices: np.ndarray
    face_normal: np.ndarray
    face_offset: np.ndarray
    face_vertex_start: np.ndarray
    face_vertex_index: np.ndarray
    edge_vertex: np.ndarray
    edge_face: np.ndarray
    mass: float
    volume: float
    density: float
    inertia: np.ndarray
    inertia_tensor: np.ndarray
    orientation: np.ndarray
    offset: np.ndarray
    radius: float
    source_indices: np.ndarray = dataclass_field(default=None, repr=False)

    @property
    def vertex_count(self) -> int:
        return len(self.vertices)

    @property
    def face_count(self) -> int:
        return len(self.face_normal)

    @property
    def edge_count(self) -> int:
        return len(self.edge_vertex)

    @property
    def center_of_mass(self) -> np.ndarray:
        """(3,) [m] the centre of mass in the frame the points were given in (= ``offset``)."""
        return self.offset

    @property
    def principal_axes(self) -> np.ndarray:
        """(3, 3) rotation matrix body → given frame; its columns are the principal axes."""
        return _quaternion_to_matrix(self.orientation)

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
        body_position = position + _quaternion_to_matrix(q) @ self.offset
        body_orientation = _quaternion_multiply(q, self.orientation)
        if body_orientation[0] < 0.0:
            body_orientation = -body_orientation
        return body_position, body_orientation

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
    points = _as_points(points, field)
    mass, density = _mass_or_density(mass, density, field)
    size = float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))
    if size == 0.0:
        raise InputError(field, f"expected points spanning a solid, found {len(points)} copies of one point")
    tolerance = TOLERANCE * size
    representative = _merge_close(points, tolerance)
    unique = np.unique(representative)
    if len(unique) < 4:
        raise InputError(field, f"expected at least 4 distinct points, found {len(unique)}")
    triangles, equations = _qhull(points[unique], field)
    triangles = unique[triangles]  # back to indices into ``points``
    faces, face_normals = _merge_coplanar(points, triangles, equations, tolerance)
    faces = _polygons(points, faces, face_normals, tolerance)
    volume, center, second_moment = _volume_moments(points, faces)
    if not volume > TOLERANCE * size**3:  # zero volume up to round-off
        raise InputError(
            field, f"expected points spanning a solid, found a flat or collinear set (volume {volume:.3g} m³)"
        )
    if require_convex:
        _check_convex(points, faces, face_normals, field, size)
    edges, edge_faces = _edges(faces, field)
    if mass is None:
        mass = density * volume
    else:
        density = mass / volume
    # inertia about the centre of mass: I = tr(C) 1 − C with C = ∫ ρ r rᵀ dV
    covariance = density * (second_moment - volume * np.outer(center, center))
    tensor = np.trace(covariance) * np.eye(3) - covariance
    tensor = 0.5 * (tensor + tensor.T)
    moments, axes = _principal(tensor)
    # renumber: the hull's own vertices 0..V−1 in the order of the given points
    used = np.unique(np.concatenate(faces))
    local = np.full(len(points), -1, dtype=np.int64)
    local[used] = np.arange(len(used))
    body_vertices = (points[used] - center) @ axes
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
        mass=float(mass),
        volume=float(volume),
        density=float(density),
        inertia=moments,
        inertia_tensor=tensor,
        orientation=_matrix_to_quaternion(axes),
        offset=center,
        radius=float(np.linalg.norm(body_vertices, axis=1).max()),
        source_indices=used,
    )


def _as_points(points, field):
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


def _mass_or_density(mass, density, field):
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


def _merge_close(points, tolerance):
    """For each point, the index of the first point within ``tolerance`` [m] of it (chains merged)."""
    from scipy.spatial import cKDTree

    parent = np.arange(len(points))
    pairs = cKDTree(points).query_pairs(tolerance, output_type="ndarray")

    def root(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i, j in pairs:
        ri, rj = root(i), root(j)
        if ri != rj:
            parent[max(ri, rj)] = min(ri, rj)
    return np.array([root(i) for i in range(len(points))], dtype=np.int64)


def _qhull(points, field):
    from scipy.spatial import ConvexHull, QhullError

    try:
        hull = ConvexHull(points)
    except QhullError:
        raise InputError(
            field, "expected points spanning a solid, found a flat or collinear set (zero volume)"
        ) from None
    return hull.simplices.astype(np.int64), hull.equations


def _merge_coplanar(points, triangles, equations, tolerance):
    """Group the hull triangles into faces: neighbours whose planes agree within tolerance.

    Returns (faces, normals): a list of vertex-index arrays (unordered) per face and their
    outward unit normals (F, 3) (the mean of the triangles' normals). Triangles are joined
    through shared edges only (a plane supporting a convex set meets it in one connected
    face), with union–find; a triangle joins its neighbour when their unit normals differ by
    less than 1e−6 rad and each one's vertices lie within ``tolerance`` of the other's plane.
    """
    count = len(triangles)
    parent = np.arange(count)

    def root(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    # the neighbour pairs: triangles sharing an undirected edge (sorted edge keys, then runs)
    edge_keys = np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]), axis=1)
    owner = np.tile(np.arange(count), 3)
    order = np.lexsort((edge_keys[:, 1], edge_keys[:, 0]))
    keys, owner = edge_keys[order], owner[order]
    same = (keys[1:] == keys[:-1]).all(axis=1)
    s_idx, t_idx = owner[:-1][same], owner[1:][same]
    normals = equations[:, :3]
    offsets = -equations[:, 3]
    close = np.einsum("ij,ij->i", normals[s_idx], normals[t_idx]) >= 1.0 - 5e-13
    for s, t in zip(s_idx[close].tolist(), t_idx[close].tolist()):
        if (
            np.abs(points[triangles[t]] @ normals[s] - offsets[s]).max() > tolerance
            or np.abs(points[triangles[s]] @ normals[t] - offsets[t]).max() > tolerance
        ):
            continue
        rs, rt = root(s), root(t)
        if rs != rt:
            parent[max(rs, rt)] = min(rs, rt)
    roots = np.array([root(t) for t in range(count)])
    order = np.argsort(roots, kind="stable")
    groups = np.split(order, np.nonzero(np.diff(roots[order]))[0] + 1)
    faces = [np.unique(triangles[members]) if len(members) > 1 else triangles[members[0]] for members in groups]
    sums = np.add.reduceat(normals[order], np.concatenate([[0], np.cumsum([len(g) for g in groups])[:-1]]), axis=0)
    return faces, sums / np.linalg.norm(sums, axis=1, keepdims=True)


def _corners_2d(uv, tolerance):
    """Indices of the strict corners of the convex hull of 2D points ``uv`` (m, 2), counter-
    clockwise (Andrew's monotone chain; points within ``tolerance`` [m] of an edge are dropped)."""
    order = np.lexsort((uv[:, 1], uv[:, 0])).tolist()
    xy = uv.tolist()

    def turn(o, a, b):
        # signed distance of b from the line o → a (left positive)
        dx, dy = xy[a][0] - xy[o][0], xy[a][1] - xy[o][1]
        length = (dx * dx + dy * dy) ** 0.5
        cross = dx * (xy[b][1] - xy[o][1]) - dy * (xy[b][0] - xy[o][0])
        return cross / length if length > 0.0 else 0.0

    def chain(indices):
        hull = []
        for i in indices:
            while len(hull) >= 2 and turn(hull[-2], hull[-1], i) <= tolerance:
                hull.pop()
            hull.append(i)
        return hull

    lower = chain(order)
    upper = chain(order[::-1])
    return lower[:-1] + upper[:-1]


def _plane_basis(normal):
    """Two unit vectors u, v with u × v = normal."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = helper - (helper @ normal) * normal
    u /= np.sqrt(u @ u)
    v = np.array(
        [normal[1] * u[2] - normal[2] * u[1], normal[2] * u[0] - normal[0] * u[2], normal[0] * u[1] - normal[1] * u[0]]
    )
    return u, v


def _polygons(points, faces, normals, tolerance):
    """Order each face's vertices counter-clockwise seen from outside; drop non-corners.

    Pass 1 finds each face's strict corners (2D hull in the face plane); a vertex is kept
    when it is a strict corner of at least one face. Pass 2 orders each face's kept vertices
    by angle about its corners' mean, so that a vertex kept for one face but nearly straight
    on another stays in both and every edge is shared by exactly two faces. (A triangle whose
    corners are all kept needs no sorting, only orienting.)
    """
    bases, corner_sets = [], []
    kept = set()
    for ids, n in zip(faces, normals):
        u, v = _plane_basis(n)
        x = points[ids]
        uv = np.stack([x @ u, x @ v], axis=1)
        corners = ids[_corners_2d(uv, tolerance)] if len(ids) > 3 or _small_triangle(uv, tolerance) else ids
        kept.update(corners.tolist())
        bases.append((u, v))
        corner_sets.append(corners)
    polygons = []
    for ids, (u, v), corners in zip(faces, bases, corner_sets):
        ids = np.array([i for i in ids.tolist() if i in kept], dtype=np.int64)
        middle = points[corners].mean(axis=0)
        d = points[ids] - middle
        angle = np.arctan2(d @ v, d @ u)
        polygons.append(ids[np.argsort(angle, kind="stable")])
    return polygons


def _small_triangle(uv, tolerance):
    """Whether a triangle (3, 2) has a corner within ``tolerance`` [m] of the opposite side."""
    (ax, ay), (bx, by), (cx, cy) = uv.tolist()
    twice_area = abs((bx - ax) * (cy - ay) - (by - ay) * (cx - ax))
    longest = max(np.hypot(bx - ax, by - ay), np.hypot(cx - bx, cy - by), np.hypot(ax - cx, ay - cy))
    return twice_area <= tolerance * longest


def _volume_moments(points, polygons):
    """Volume [m³], centroid (3,) [m] and second moment ∫ r rᵀ dV (3, 3) [m⁵] about the origin
    of the closed polyhedron with outward-wound ``polygons``, exactly: signed tetrahedra from a
    reference point r0 (the mean of the vertices) to each fan triangle of each face."""
    r0 = points[np.unique(np.concatenate(polygons))].mean(axis=0)
    tris = []
    for polygon in polygons:
        for k in range(1, len(polygon) - 1):
            tris.append((polygon[0], polygon[k], polygon[k + 1]))
    tris = np.array(tris, dtype=np.int64)
    a = points[tris[:, 0]] - r0
    b = points[tris[:, 1]] - r0
    c = points[tris[:, 2]] - r0
    det = np.einsum("ij,ij->i", a, np.cross(b, c))  # 6 × signed volume of (r0, a, b, c)
    volume = det.sum() / 6.0
    if volume <= 0.0:
        return 0.0, r0, np.zeros((3, 3))
    centroid_rel = (det[:, None] * (a + b + c)).sum(axis=0) / 24.0 / volume
    # ∫ x xᵀ over the tetrahedron (0, a, b, c) = det/120 · (Σ_i v_i v_iᵀ + (Σ v_i)(Σ v_i)ᵀ)
    s = a + b + c
    second_rel = (
        np.einsum("t,ti,tj->ij", det, a, a)
        + np.einsum("t,ti,tj->ij", det, b, b)
        + np.einsum("t,ti,tj->ij", det, c, c)
        + np.einsum("t,ti,tj->ij", det, s, s)
    ) / 120.0
    # shift the second moment from r0 to the origin of the given frame
    m1 = volume * centroid_rel
    second = second_rel + np.outer(m1, r0) + np.outer(r0, m1) + volume * np.outer(r0, r0)
    return float(volume), r0 + centroid_rel, second


def _check_convex(points, polygons, normals, field, size):
    """InputError when some given point lies inside the hull by more than CONVEX_TOLERANCE × size."""
    offsets = np.array([(points[p] @ n).max() for p, n in zip(polygons, normals)])
    height = (points @ normals.T - offsets).max(axis=1)  # ≤ 0 inside; 0 on the surface
    inside = height < -CONVEX_TOLERANCE * size
    if inside.any():
        raise InputError(
            field,
            f"the points are not convex: {int(inside.sum())} of {len(points)} lie inside "
            f'their hull; use shape = "mesh" for a static non-convex object',
        )


def _edges(polygons, field):
    """Unique edges (E, 2) (vertex ids, low first) and the faces (E, 2) each joins."""
    directed = {}
    for f, polygon in enumerate(polygons):
        for k in range(len(polygon)):
            a, b = int(polygon[k]), int(polygon[(k + 1) % len(polygon)])
            if (a, b) in directed:
                raise InputError(
                    field,
                    "could not build a consistent hull from these points (an edge is used "
                    "twice in one direction); they are numerically degenerate",
                )
            directed[(a, b)] = f
    edges, faces = [], []
    for (a, b), f in directed.items():
        if (b, a) not in directed:
            raise InputError(
                field,
                "could not build a consistent hull from these points (an edge has no "
                "neighbouring face); they are numerically degenerate",
            )
        if a < b:
            edges.append((a, b))
            faces.append((f, directed[(b, a)]))
    return np.array(edges, dtype=np.int64).reshape(-1, 2), np.array(faces, dtype=np.int64).reshape(-1, 2)


def _principal(tensor):
    """Principal moments (3,) and a proper rotation (3, 3) whose columns are the principal axes.

    An already diagonal tensor keeps the given axes. Otherwise the eigenvectors are
    permuted and signed to stay as close as possible to the given axes (no gratuitous turn).
    """
    scale = np.trace(tensor)
    off_diagonal = np.abs(tensor - np.diag(np.diag(tensor))).max()
    if off_diagonal <= 1e-12 * scale:
        return np.diag(tensor).copy(), np.eye(3)
    moments, axes = np.linalg.eigh(tensor)
    best, best_score = None, -1.0
    for perm in ((0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0)):
        score = sum(abs(axes[i, perm[i]]) for i in range(3))
        if score > best_score:
            best, best_score = perm, score
    axes = axes[:, best]
    moments = moments[list(best)]
    for i in range(3):
        if axes[i, i] < 0.0:
            axes[:, i] = -axes[:, i]
    if np.linalg.det(axes) < 0.0:
        weakest = int(np.argmin(np.abs(np.diag(axes))))
        axes[:, weakest] = -axes[:, weakest]
    return moments, axes


def _matrix_to_quaternion(R):
    """Unit quaternion (w, x, y, z), w ≥ 0, of a proper rotation matrix (Shepperd's method)."""
    trace = np.trace(R)
    if trace > 0.0:
        s = 2.0 * np.sqrt(1.0 + trace)
        q = np.array([0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s])
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = 2.0 * np.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        q = np.array([(R[2, 1] - R[1, 2]) / s, 0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s])
    elif R[1, 1] > R[2, 2]:
        s = 2.0 * np.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2])
        q = np.array([(R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s])
    else:
        s = 2.0 * np.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1])
        q = np.array([(R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s])
    q /= np.linalg.norm(q)
    return -q if q[0] < 0.0 else q


def _quaternion_to_matrix(q):
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def _quaternion_multiply(p, q):
    pw, px, py, pz = p
    qw, qx, qy, qz = q
    return np.array(
        [
            pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
        ]
    )


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
    edges, edge_faces = _edges(polygons, "half_extents")
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
