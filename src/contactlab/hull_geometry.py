"""The steps :func:`contactlab.hulls.build_hull` takes from a point set to a convex polyhedron.

NumPy and SciPy only, run once per hull: points within a tolerance merged, Qhull's triangles
merged into polygon faces (:func:`merge_coplanar`), each face's corners kept and ordered
counter-clockwise from outside (:func:`face_polygons`), the edges between faces
(:func:`hull_edges`), the exact volume, centroid and second moment of the solid
(:func:`volume_moments`), its principal frame (:func:`principal_frame`) and that frame as a
quaternion. Every tolerance here is a length [m], already scaled by the caller to the size of
the point set.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .errors import InputError


def merge_close(points: np.ndarray, tolerance: float) -> np.ndarray:
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


def qhull_triangles(points: np.ndarray, field: str) -> tuple[np.ndarray, np.ndarray]:
    from scipy.spatial import ConvexHull, QhullError

    try:
        hull = ConvexHull(points)
    except QhullError:
        raise InputError(
            field, "expected points spanning a solid, found a flat or collinear set (zero volume)"
        ) from None
    return hull.simplices.astype(np.int64), hull.equations


def merge_coplanar(
    points: np.ndarray, triangles: np.ndarray, equations: np.ndarray, tolerance: float
) -> tuple[list[np.ndarray], np.ndarray]:
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


def _corners_2d(uv: np.ndarray, tolerance: float) -> list[int]:
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


def _plane_basis(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors u, v with u × v = normal."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = helper - (helper @ normal) * normal
    u /= np.sqrt(u @ u)
    v = np.array(
        [normal[1] * u[2] - normal[2] * u[1], normal[2] * u[0] - normal[0] * u[2], normal[0] * u[1] - normal[1] * u[0]]
    )
    return u, v


def face_polygons(
    points: np.ndarray, faces: list[np.ndarray], normals: np.ndarray, tolerance: float
) -> list[np.ndarray]:
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


def _small_triangle(uv: np.ndarray, tolerance: float) -> bool:
    """Whether a triangle (3, 2) has a corner within ``tolerance`` [m] of the opposite side."""
    (ax, ay), (bx, by), (cx, cy) = uv.tolist()
    twice_area = abs((bx - ax) * (cy - ay) - (by - ay) * (cx - ax))
    longest = max(np.hypot(bx - ax, by - ay), np.hypot(cx - bx, cy - by), np.hypot(ax - cx, ay - cy))
    return twice_area <= tolerance * longest


def volume_moments(points: np.ndarray, polygons: Sequence[np.ndarray]) -> tuple[float, np.ndarray, np.ndarray]:
    """Volume [m³], centroid (3,) [m] and second moment ∫ r rᵀ dV (3, 3) [m⁵] about the origin
    of the closed polyhedron with outward-wound ``polygons``, exactly: signed tetrahedra from a
    reference point r0 (the mean of the vertices) to each fan triangle of each face."""
    r0 = points[np.unique(np.concatenate(polygons))].mean(axis=0)
    fan = []
    for polygon in polygons:
        for k in range(1, len(polygon) - 1):
            fan.append((polygon[0], polygon[k], polygon[k + 1]))
    tris = np.array(fan, dtype=np.int64)
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


def check_convex(
    points: np.ndarray, polygons: Sequence[np.ndarray], normals: np.ndarray, field: str, depth: float
) -> None:
    """InputError when some given point lies inside the hull (faces ``polygons``, outward unit
    ``normals`` (F, 3)) deeper than ``depth`` [m] (build_hull: CONVEX_TOLERANCE × the size)."""
    offsets = np.array([(points[p] @ n).max() for p, n in zip(polygons, normals)])
    height = (points @ normals.T - offsets).max(axis=1)  # ≤ 0 inside; 0 on the surface
    inside = height < -depth
    if inside.any():
        raise InputError(
            field,
            f"the points are not convex: {int(inside.sum())} of {len(points)} lie inside "
            f'their hull; use shape = "mesh" for a static non-convex object',
        )


def hull_edges(polygons: Sequence[np.ndarray], field: str) -> tuple[np.ndarray, np.ndarray]:
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


def principal_frame(tensor: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Principal moments (3,) and a proper rotation (3, 3) whose columns are the principal axes.

    An already diagonal tensor keeps the given axes. Otherwise the eigenvectors are
    permuted and signed to stay as close as possible to the given axes (no gratuitous turn).
    """
    scale = np.trace(tensor)
    off_diagonal = np.abs(tensor - np.diag(np.diag(tensor))).max()
    if off_diagonal <= 1e-12 * scale:
        return np.diag(tensor).copy(), np.eye(3)
    moments, axes = np.linalg.eigh(tensor)
    best, best_score = (0, 1, 2), -1.0
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


def matrix_to_quaternion(R: np.ndarray) -> np.ndarray:
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


def quaternion_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrix (3, 3) of a unit quaternion (4,) (w, x, y, z)."""
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def quaternion_multiply(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton product p ⊗ q of two quaternions (4,)."""
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
