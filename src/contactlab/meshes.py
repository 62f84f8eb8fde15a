"""Static triangle meshes: loading, derived normals, and a bounding volume hierarchy.

A :class:`TriangleMesh` is built once (obstacles do not move) and carries everything the
compiled contact routines against meshes (:mod:`contactlab.collision.mesh_contacts`) need, as flat arrays:

=========================  ===========  =====================================================
array                      shape        meaning
=========================  ===========  =====================================================
``vertices``               (V, 3)       positions [m]
``triangles``              (T, 3) int   vertex indices; counter-clockwise seen from the front
``triangle_normals``       (T, 3)       unit, outward by the winding (right-hand rule);
                                        zero for a degenerate (zero-area) triangle
``vertex_normals``         (V, 3)       unit, area-weighted mean of the adjacent triangles'
                                        normals (zero for a vertex no triangle uses)
``edges``                  (E, 2) int   unique undirected edges, vertex indices (low, high)
``triangle_edges``         (T, 3) int   edge ids; local edge k joins local vertices k, k+1
``edge_normals``           (E, 3)       pseudo-normal of each edge: normalized sum of the
                                        normals of its triangles
``vertex_pseudo_normals``  (V, 3)       angle-weighted pseudo-normal of each vertex
``vertex_owner``           (V,) int     the lowest-index non-degenerate triangle using the
                                        vertex (−1: none), so a vertex is handled once
=========================  ===========  =====================================================

Inside and outside. The front side of a triangle (where its normal points) is outside. The
sign of a point's distance to the mesh is the sign of ``(x − q) · ψ`` where ``q`` is the
closest point and ``ψ`` the pseudo-normal of the feature ``q`` lies on (the face normal,
an edge normal or an angle-weighted vertex normal): for a closed, consistently wound mesh
this is exactly inside/outside (Bærentzen and Aanæs, 2005). A mesh made ``two_sided``
(an open sheet: a cloth-like wall, a single triangle) has no inside: both sides are
outside and a point is pushed back to the side it is on.

BVH layout (flat arrays, breadth-first order with node 0 the root, built once by median
splits along the axis of widest centroid spread, at most ``LEAF_SIZE`` triangles per leaf):
node ``i`` has bounds ``node_lower[i]``, ``node_upper[i]`` (N, 3); a leaf has
``node_left[i] == node_right[i] == −1`` and ``node_count[i] > 0`` triangles,
``node_order[node_start[i] : node_start[i] + node_count[i]]``; an inner node has
``node_count[i] == 0`` and children ``node_left[i]``, ``node_right[i]``.
``triangle_lower`` / ``triangle_upper`` (T, 3) are each triangle's own box.
"""

from __future__ import annotations

import os
from collections import namedtuple

import numpy as np
from numpy.typing import ArrayLike

from . import rotations
from .compiling import njit
from .counts import RowCount
from .errors import InputError, first_line

LEAF_SIZE = 4
MESH_FORMATS = (".obj", ".stl", ".ply")
DEGENERATE_AREA = 1e-12  # a triangle whose |e1 × e2| is below this × (longest edge)² has no normal
TOLERANCE = 1e-9  # geometric tolerance of the contact routines, × the mesh's bounding diagonal

# Everything the compiled routines need, in one argument (a namedtuple of arrays: Numba passes it
# by reference). ``tolerance`` [m] is a length below which two points are the same point;
# ``max_depth`` [m] how far below a one-sided mesh's surface a point is still found (inside).
MeshGeometry = namedtuple(
    "MeshGeometry",
    [
        "vertices",
        "triangles",
        "triangle_normals",
        "vertex_normals",
        "triangle_edges",
        "edge_normals",
        "vertex_pseudo_normals",
        "vertex_owner",
        "node_lower",
        "node_upper",
        "node_left",
        "node_right",
        "node_start",
        "node_count",
        "node_order",
        "triangle_lower",
        "triangle_upper",
        "tolerance",
        "two_sided",
        "max_depth",
    ],
)
GEOMETRY_ARRAYS = MeshGeometry._fields[:-3]  # its arrays: all but tolerance, two_sided and max_depth


# ---------------------------------------------------------------------------------------------
# normals
# ---------------------------------------------------------------------------------------------


def triangle_normals(vertices: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals (T, 3) by the winding, and the doubled areas (T,) [m²]; degenerate: zero normal."""
    v0, v1, v2 = vertices[triangles[:, 0]], vertices[triangles[:, 1]], vertices[triangles[:, 2]]
    cross = np.cross(v1 - v0, v2 - v0)
    doubled_area = np.linalg.norm(cross, axis=1)
    longest = np.max(
        np.stack(
            [np.sum((v1 - v0) ** 2, axis=1), np.sum((v2 - v1) ** 2, axis=1), np.sum((v0 - v2) ** 2, axis=1)], axis=1
        ),
        axis=1,
    )
    degenerate = doubled_area <= DEGENERATE_AREA * longest
    normals = np.where(degenerate[:, None], 0.0, cross / np.where(degenerate, 1.0, doubled_area)[:, None])
    return normals, np.where(degenerate, 0.0, doubled_area)


def vertex_normals(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals (V, 3) of a triangle mesh (vertices (V, 3), triangles (T, 3)).

    Vectorized, cheap enough to call every step for a deforming object (P5 needs them).
    A vertex used by no triangle (or only by degenerate ones) gets a zero normal.
    """
    vertices = np.asarray(vertices, dtype=float)
    triangles = np.asarray(triangles, dtype=np.int64)
    v0, v1, v2 = vertices[triangles[:, 0]], vertices[triangles[:, 1]], vertices[triangles[:, 2]]
    weighted = np.cross(v1 - v0, v2 - v0)  # normal × 2 area
    summed = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(summed, triangles[:, k], weighted)
    length = np.linalg.norm(summed, axis=1)
    return np.where(length[:, None] > 0.0, summed / np.where(length > 0.0, length, 1.0)[:, None], 0.0)


def _pseudo_normals(vertices, triangles, normals):
    """Edges (E,2), triangle edges (T,3), edge pseudo-normals (E,3), angle-weighted vertex pseudo-normals (V,3)."""
    T = len(triangles)
    directed = np.stack([triangles, np.roll(triangles, -1, axis=1)], axis=2).reshape(-1, 2)  # (3T, 2): k → k+1
    undirected = np.sort(directed, axis=1)
    edges, inverse = np.unique(undirected, axis=0, return_inverse=True)
    triangle_edges = inverse.reshape(T, 3).astype(np.int64)
    edge_sum = np.zeros((len(edges), 3))
    np.add.at(edge_sum, triangle_edges.ravel(), np.repeat(normals, 3, axis=0))
    edge_normals = _unit_rows(edge_sum)
    # angle of each triangle at each of its corners
    angles = np.zeros((T, 3))
    for k in range(3):
        a = vertices[triangles[:, k]]
        u = vertices[triangles[:, (k + 1) % 3]] - a
        w = vertices[triangles[:, (k + 2) % 3]] - a
        angles[:, k] = np.arctan2(np.linalg.norm(np.cross(u, w), axis=1), np.sum(u * w, axis=1))
    vertex_sum = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(vertex_sum, triangles[:, k], normals * angles[:, k : k + 1])
    return edges.astype(np.int64), triangle_edges, edge_normals, _unit_rows(vertex_sum)


def _unit_rows(a):
    length = np.linalg.norm(a, axis=1)
    return np.where(length[:, None] > 0.0, a / np.where(length > 0.0, length, 1.0)[:, None], 0.0)


# ---------------------------------------------------------------------------------------------
# BVH
# ---------------------------------------------------------------------------------------------


def build_bvh(
    triangle_lower: ArrayLike, triangle_upper: ArrayLike, leaf_size: int = LEAF_SIZE
) -> tuple[np.ndarray, ...]:
    """Median-split BVH over boxes (T, 3) [m], built level by level with vectorized NumPy.

    Returns (node_lower, node_upper, node_left, node_right, node_start, node_count,
    node_order) in the layout of the module docstring. Each node's triangles are split at
    the median of their centroids along the axis where the centroids spread most (ties in
    the key keep index order, so the tree is deterministic).
    """
    triangle_lower = np.asarray(triangle_lower, dtype=float)
    triangle_upper = np.asarray(triangle_upper, dtype=float)
    count = len(triangle_lower)
    centroid = 0.5 * (triangle_lower + triangle_upper)
    order = np.arange(count, dtype=np.int64)
    starts, ends = [np.array([0])], [np.array([count])]
    lefts, rights = [], []
    frontier_first, total = 0, 1  # node ids of the current level: frontier_first .. total − 1
    levels = [(0, 1)]
    while True:
        level_start = np.concatenate(starts)[frontier_first:total]
        level_end = np.concatenate(ends)[frontier_first:total]
        split = np.nonzero(level_end - level_start > leaf_size)[0]
        left = np.full(total - frontier_first, -1, dtype=np.int64)
        right = np.full(total - frontier_first, -1, dtype=np.int64)
        if len(split) == 0:
            lefts.append(left)
            rights.append(right)
            break
        s, e = level_start[split], level_end[split]
        lengths = e - s
        offsets = np.cumsum(lengths) - lengths
        segment = np.repeat(np.arange(len(split)), lengths)
        positions = np.repeat(s, lengths) + np.arange(lengths.sum()) - np.repeat(offsets, lengths)
        members = order[positions]
        c = centroid[members]
        spread = np.maximum.reduceat(c, offsets, axis=0) - np.minimum.reduceat(c, offsets, axis=0)
        axis = np.argmax(spread, axis=1)
        key = c[np.arange(len(c)), axis[segment]]
        order[positions] = members[np.lexsort((key, segment))]
        middle = (s + e) // 2
        children = total + 2 * np.arange(len(split))
        left[split] = children
        right[split] = children + 1
        lefts.append(left)
        rights.append(right)
        starts.append(np.column_stack([s, middle]).ravel())
        ends.append(np.column_stack([middle, e]).ravel())
        frontier_first, total = total, total + 2 * len(split)
        levels.append((frontier_first, total))
    node_start = np.concatenate(starts).astype(np.int64)
    node_end = np.concatenate(ends).astype(np.int64)
    node_left = np.concatenate(lefts).astype(np.int64)
    node_right = np.concatenate(rights).astype(np.int64)
    leaf = node_left < 0
    node_count = np.where(leaf, node_end - node_start, 0).astype(np.int64)
    node_lower = np.empty((total, 3))
    node_upper = np.empty((total, 3))
    # leaves: the boxes of their triangles (leaf ranges partition 0..T−1)
    leaves = np.nonzero(leaf)[0]
    leaves = leaves[np.argsort(node_start[leaves], kind="stable")]
    node_lower[leaves] = np.minimum.reduceat(triangle_lower[order], node_start[leaves], axis=0)
    node_upper[leaves] = np.maximum.reduceat(triangle_upper[order], node_start[leaves], axis=0)
    # inner nodes, deepest level first: the union of the two children
    for first, last in reversed(levels):
        ids = np.arange(first, last)
        ids = ids[~leaf[ids]]
        node_lower[ids] = np.minimum(node_lower[node_left[ids]], node_lower[node_right[ids]])
        node_upper[ids] = np.maximum(node_upper[node_left[ids]], node_upper[node_right[ids]])
    return node_lower, node_upper, node_left, node_right, node_start, node_count, order


# the BVH query's one box test, for its nodes and its triangles (capsule_mesh's ghost test takes it too).
# Keep it an axis loop with early returns, inlined: returning one six-term `not (a or b or ...)`
# expression made the query 3.8 times slower
# (Numba 0.68, boxes about the mesh_bowl scene's bowl), while this form compiles to the machine code of the
# test written out twice (the same instructions, registers aside) and times the same
@njit(cache=True, inline="always")
def boxes_overlap(lowers: np.ndarray, uppers: np.ndarray, row: int, lower: np.ndarray, upper: np.ndarray) -> bool:
    """Whether box ``row`` of ``lowers``, ``uppers`` (N, 3) [m] overlaps [lower, upper] (3,) (closed intervals)."""
    for axis in range(3):
        if lowers[row, axis] > upper[axis] or uppers[row, axis] < lower[axis]:
            return False
    return True


@njit(cache=True)
def triangles_near(mesh: MeshGeometry, lower: np.ndarray, upper: np.ndarray, out: np.ndarray) -> int:
    """Triangles of ``mesh`` whose boxes overlap the box [lower, upper] (3,) [m] (closed intervals),
    found down the mesh's bounding-volume hierarchy (its ``node_*`` arrays).

    Writes their indices into ``out`` (int64) and returns how many there are. When there
    are more than ``len(out)`` only the first ``len(out)`` are written and the full count is
    returned, so a caller can grow ``out`` and ask again. Order: BVH leaf order.
    """
    stack = np.empty(128, dtype=np.int64)  # median splits: depth ≤ log2(T) + 1, 2 pushed per level
    stack[0] = 0
    top = 1
    found = 0
    capacity = out.shape[0]
    while top > 0:
        top -= 1
        node = stack[top]
        if not boxes_overlap(mesh.node_lower, mesh.node_upper, node, lower, upper):
            continue
        if mesh.node_count[node] > 0:
            for k in range(mesh.node_start[node], mesh.node_start[node] + mesh.node_count[node]):
                t = mesh.node_order[k]
                if not boxes_overlap(mesh.triangle_lower, mesh.triangle_upper, t, lower, upper):
                    continue
                if found < capacity:
                    out[found] = t
                found += 1
        else:
            stack[top] = mesh.node_right[node]
            stack[top + 1] = mesh.node_left[node]
            top += 2
    return found


@njit(cache=True)
def mesh_triangles_near(mesh: MeshGeometry, lower: np.ndarray, upper: np.ndarray, buffer: np.ndarray) -> np.ndarray:
    """:func:`triangles_near`, growing ``buffer`` when it is too small.

    Returns the candidate indices (a view of the buffer, or of a larger new array).
    """
    while True:  # at most twice: a second query into a buffer of the size the first found
        found = triangles_near(mesh, lower, upper, buffer)
        if found <= buffer.shape[0]:
            return buffer[:found]
        buffer = np.empty(found, dtype=np.int64)


# ---------------------------------------------------------------------------------------------
# the mesh
# ---------------------------------------------------------------------------------------------


class TriangleMesh:
    """A static triangle mesh with its normals, pseudo-normals and BVH (see the module docstring).

    vertices: (V, 3) [m]; triangles: (T, 3) integer vertex indices, wound counter-clockwise
    seen from the outside. ``two_sided``: an open sheet with no inside (both sides outside).
    ``max_depth`` [m]: how deep below the surface of a one-sided mesh a point (a particle's
    or sphere's centre) is still found and pushed out; deeper, it is lost (it has tunnelled).
    A larger value costs a larger search for every shape near the mesh with no triangle
    within its reach, and more than half the thinnest wall is useless (a point past the
    middle of a wall is pushed out of the far side). Default: 1 % of the bounding box
    diagonal. Arrays are read-only; :meth:`transformed` makes a moved copy.
    """

    def __init__(
        self,
        vertices: ArrayLike,
        triangles: ArrayLike,
        two_sided: bool = False,
        max_depth: float | None = None,
        field: str = "mesh",
    ) -> None:
        vertices = np.array(vertices, dtype=float)
        triangles = np.array(triangles)
        if vertices.ndim != 2 or vertices.shape[1] != 3:
            raise InputError(field, f"vertices must have shape (V, 3), found {vertices.shape}")
        if triangles.ndim != 2 or triangles.shape[1] != 3 or not np.issubdtype(triangles.dtype, np.integer):
            raise InputError(
                field, f"triangles must be integers of shape (T, 3), found {triangles.dtype} {triangles.shape}"
            )
        if len(triangles) == 0:
            raise InputError(field, "the mesh has no triangles")
        if not np.all(np.isfinite(vertices)):
            raise InputError(field, "the mesh has non-finite vertex coordinates")
        if triangles.min() < 0 or triangles.max() >= len(vertices):
            raise InputError(
                field,
                f"triangle vertex indices must lie in [0, {len(vertices) - 1}], "
                f"found {triangles.min()}..{triangles.max()}",
            )
        triangles = triangles.astype(np.int64)
        self.two_sided = bool(two_sided)
        self.vertices = vertices
        self.triangles = triangles
        self.triangle_normals, doubled_area = triangle_normals(vertices, triangles)
        if not np.any(doubled_area > 0.0):
            raise InputError(field, "every triangle of the mesh is degenerate (zero area)")
        self.triangle_areas = 0.5 * doubled_area
        self.vertex_normals = vertex_normals(vertices, triangles)
        (self.edges, self.triangle_edges, self.edge_normals, self.vertex_pseudo_normals) = _pseudo_normals(
            vertices, triangles, self.triangle_normals
        )
        owner = np.full(len(vertices), len(triangles), dtype=np.int64)
        good = np.nonzero(doubled_area > 0.0)[0]
        for k in range(3):
            np.minimum.at(owner, triangles[good, k], good)
        self.vertex_owner = np.where(owner == len(triangles), -1, owner)
        corners = vertices[triangles]  # (T, 3, 3)
        self.triangle_lower = corners.min(axis=1)
        self.triangle_upper = corners.max(axis=1)
        (
            self.node_lower,
            self.node_upper,
            self.node_left,
            self.node_right,
            self.node_start,
            self.node_count,
            self.node_order,
        ) = build_bvh(self.triangle_lower, self.triangle_upper, LEAF_SIZE)
        self.bounds = (vertices[triangles.ravel()].min(axis=0), vertices[triangles.ravel()].max(axis=0))
        diagonal = float(np.linalg.norm(self.bounds[1] - self.bounds[0]))
        self.tolerance = TOLERANCE * max(diagonal, 1e-3)
        if max_depth is None:
            max_depth = 0.01 * diagonal
        if not (np.isfinite(max_depth) and max_depth >= 0.0):
            raise InputError(field, f"max_depth must be a finite number ≥ 0, found {max_depth}")
        self.max_depth = float(max_depth)
        for name in (*GEOMETRY_ARRAYS, "triangle_areas", "edges"):
            getattr(self, name).flags.writeable = False
        arrays = [getattr(self, name) for name in GEOMETRY_ARRAYS]
        self.geometry = MeshGeometry._make([*arrays, float(self.tolerance), self.two_sided, self.max_depth])

    vertex_count = RowCount("vertices")
    """V, the number of vertices."""
    triangle_count = RowCount("triangles")
    """T, the number of triangles."""

    def transformed(
        self, position: ArrayLike = (0.0, 0.0, 0.0), quaternion: ArrayLike = (1.0, 0.0, 0.0, 0.0)
    ) -> TriangleMesh:
        """The mesh moved to the world frame: x_world = R(quaternion) x + position.

        position (3,) [m]; quaternion (4,) (w, x, y, z), normalized here. The BVH is rebuilt
        (once: obstacles are static).
        """
        q = np.asarray(quaternion, dtype=float).reshape(4)
        norm = np.linalg.norm(q)
        if not np.isfinite(norm) or norm == 0.0:
            raise InputError("orientation", f"the quaternion must be non-zero and finite, found {q.tolist()}")
        R = rotations.to_matrix((q / norm)[None])[0]
        world = self.vertices @ R.T + np.asarray(position, dtype=float).reshape(3)
        return TriangleMesh(world, self.triangles, two_sided=self.two_sided, max_depth=self.max_depth)

    def __repr__(self):
        return (
            f"TriangleMesh({self.vertex_count} vertices, {self.triangle_count} triangles"
            f"{', two-sided' if self.two_sided else ''})"
        )


def load_mesh(
    path: str | os.PathLike[str],
    scale: float = 1.0,
    field: str = "file",
    two_sided: bool = False,
    max_depth: float | None = None,
) -> TriangleMesh:
    """Read an OBJ, STL or PLY file into a :class:`TriangleMesh` (vertices × ``scale`` [m]).

    ``two_sided`` and ``max_depth`` as in :class:`TriangleMesh`. Uses ``trimesh`` (loaded
    without its processing, so nothing is silently repaired); polygons are triangulated,
    exactly coincident vertices merged (STL stores none shared) and degenerate triangles
    (zero area, repeated vertices) dropped. Raises
    :class:`~contactlab.errors.InputError` naming ``field`` for a missing file, an unsupported
    format, an unreadable file, a mesh with no (non-degenerate) triangles, non-finite vertex
    coordinates, and a scale that is not a positive finite number.
    """
    try:
        scale = float(scale)
    except (TypeError, ValueError):
        raise InputError(field, f"the mesh scale must be a positive number, found {scale!r}") from None
    if not np.isfinite(scale) or scale <= 0.0:
        raise InputError(field, f"the mesh scale must be a positive finite number, found {scale}")
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise InputError(field, f"expected an existing file, found no file at {path}")
    extension = os.path.splitext(path)[1].lower()
    if extension not in MESH_FORMATS:
        raise InputError(field, f"unsupported mesh format '{extension}' of {path}; expected .obj, .stl or .ply")
    try:
        import trimesh
    except ImportError:  # pragma: no cover - a runtime dependency
        raise InputError(field, "reading mesh files needs the 'trimesh' package (pip install trimesh)") from None
    try:
        loaded = trimesh.load(path, force="mesh", process=False)
        vertices = np.asarray(loaded.vertices, dtype=float)
        faces = np.asarray(loaded.faces)
    except Exception as error:  # trimesh raises many types on broken files
        raise InputError(field, f"could not read the mesh file {path} ({first_line(error)})") from None
    if faces.ndim != 2 or len(faces) == 0 or vertices.ndim != 2 or len(vertices) == 0:
        raise InputError(field, f"the mesh file {path} contains no triangles")
    if faces.shape[1] != 3 or faces.min() < 0 or faces.max() >= len(vertices):
        raise InputError(field, f"the mesh file {path} has faces that are not valid triangles")
    used = vertices[np.unique(faces)]
    if not np.all(np.isfinite(used)):
        raise InputError(field, f"the mesh file {path} has non-finite vertex coordinates")
    # merge exactly coincident vertices, drop unused ones
    unique, inverse = np.unique(vertices, axis=0, return_inverse=True)
    faces = inverse.reshape(-1)[faces]
    faces = faces[(faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 2] != faces[:, 0])]
    if len(faces) > 0:
        _, doubled = triangle_normals(unique, faces)
        faces = faces[doubled > 0.0]
    if len(faces) == 0:
        raise InputError(field, f"the mesh file {path} has only degenerate triangles")
    kept, faces = np.unique(faces, return_inverse=True)
    vertices = unique[kept] * scale
    return TriangleMesh(vertices, faces.reshape(-1, 3), two_sided=two_sided, max_depth=max_depth, field=field)


def builtin_mesh_path(name: str) -> str:
    """Path of a mesh file shipped with contactlab (``scene/meshes/NAME``)."""
    return os.path.join(os.path.dirname(__file__), "scene", "meshes", name)
