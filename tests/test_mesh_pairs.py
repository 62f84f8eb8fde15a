"""Capsules and convex hulls against static triangle meshes (contactlab.collision.mesh_contacts).

The reference for the randomized check is written here in plain NumPy, independently of the
compiled code: the exact point–triangle distance by projection on the plane (barycentric
test) else the nearest of the three point–segment distances, evaluated on a dense sampling
of the capsule's segment and then refined per triangle by a ternary search (the distance of
a point moving on a line from a convex set is convex in the parameter, so the minimum lies
within one sample spacing of the best sample).
"""

import numpy as np
import pytest

from contactlab import shapes
from contactlab.collision.capsule_mesh import capsule_mesh
from contactlab.collision.mesh_contacts import shapes_against_mesh
from contactlab.collision.polytope_mesh import convex_mesh
from contactlab.hulls import box_as_hull, hull_arrays
from contactlab.meshes import TriangleMesh, builtin_mesh_path, load_mesh


def rotation_about(axis, angle):
    axis = np.asarray(axis, dtype=float)
    axis = axis / np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def capsule_contacts(mesh, center, rotation, radius, half_length, margin=0.01, max_contacts=8):
    P, N = np.zeros((max_contacts, 3)), np.zeros((max_contacts, 3))
    D, F = np.zeros(max_contacts), np.zeros(max_contacts, dtype=np.int64)
    k = capsule_mesh(
        ((np.asarray(center, float), np.ascontiguousarray(rotation, float)), float(radius), float(half_length)),
        mesh.geometry,
        float(margin),
        (P, N, D, F),
        0,
        max_contacts,
    )
    return P[:k], N[:k], D[:k], F[:k]


def floor():
    vertices = np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]])
    return TriangleMesh(vertices, np.array([[0, 1, 2], [0, 2, 3]]))


LYING = rotation_about((0, 1, 0), np.pi / 2)  # body z along world x


def test_capsule_lying_on_one_triangle_gets_its_two_ends():
    P, N, D, F = capsule_contacts(floor(), (0.3, -0.4, 0.098), LYING, 0.1, 0.4)
    assert len(D) == 2
    np.testing.assert_allclose(D, 0.002, atol=1e-12)
    np.testing.assert_allclose(N, [[0, 0, 1]] * 2, atol=1e-12)
    np.testing.assert_allclose(np.sort(P[:, 0]), [-0.1, 0.7], atol=1e-12)
    np.testing.assert_allclose(P[:, 2], -0.001, atol=1e-12)  # midway: sphere bottom −0.002, floor 0
    assert sorted(F % 16) == [7, 8] and len(set(F)) == 2


@pytest.mark.parametrize("axis_angle", [0.0, np.pi / 2, np.pi / 4, 0.3])
def test_capsule_lying_across_or_along_the_shared_diagonal_gets_two(axis_angle):
    # rotate the lying capsule about z: 0 and π/2 cross the diagonal, π/4 lies on it
    R = rotation_about((0, 0, 1), axis_angle) @ LYING
    P, N, D, F = capsule_contacts(floor(), (0.0, 0.0, 0.097), R, 0.1, 0.5)
    assert len(D) == 2
    np.testing.assert_allclose(D, 0.003, atol=1e-12)
    np.testing.assert_allclose(N, [[0, 0, 1]] * 2, atol=1e-12)
    ends = np.array([R[:, 2] * s for s in (-0.5, 0.5)])[:, :2]
    got = P[np.argsort(P @ R[:, 2])][:, :2]
    np.testing.assert_allclose(got, ends, atol=1e-12)
    assert len(set(F)) == 2


def test_capsule_upright_gets_one_and_a_tilted_one_its_lower_end_first():
    P, N, D, F = capsule_contacts(floor(), (0.2, 0.1, 0.5 + 0.1 - 0.004), np.eye(3), 0.1, 0.5)
    assert len(D) == 1
    np.testing.assert_allclose(D, 0.004, atol=1e-12)
    np.testing.assert_allclose(N[0], [0, 0, 1], atol=1e-12)
    assert F[0] % 16 == 7  # the −z end
    # tilted by 0.3 rad: one end contact (the other end is far above the margin)
    R = rotation_about((0, 1, 0), 0.3)
    z = 0.5 * np.cos(0.3) + 0.1 - 0.004
    P, N, D, F = capsule_contacts(floor(), (0.2, 0.1, z), R, 0.1, 0.5)
    assert len(D) == 1
    np.testing.assert_allclose(D, 0.004, atol=1e-12)


def test_cube_hull_on_a_mesh_floor_gets_its_four_bottom_corners():
    hull = box_as_hull([0.1, 0.1, 0.1])
    store = tuple(
        hull[k]
        for k in (
            "vertex_start",
            "vertices",
            "face_start",
            "face_normal",
            "face_offset",
            "face_vertex_start",
            "face_vertex_index",
            "edge_start",
            "edge_vertex",
            "edge_face",
        )
    )
    mesh = floor()
    P, N = np.zeros((8, 3)), np.zeros((8, 3))
    D, F = np.zeros(8), np.zeros(8, dtype=np.int64)
    k = convex_mesh(
        (np.array([0.05, 0.02, 0.1 - 0.003]), np.eye(3)),
        hull_arrays(hull, 0),
        mesh.geometry,
        0.01,
        (P, N, D, F),
        0,
        8,
    )
    assert k == 4
    np.testing.assert_allclose(D[:k], 0.003, atol=1e-12)
    np.testing.assert_allclose(N[:k], [[0, 0, 1]] * 4, atol=1e-12)
    assert len(set(F[:k])) == 4
    # through the batch, with a capsule, a sphere and a box alongside
    kinds = np.array([shapes.CONVEX, shapes.CAPSULE, shapes.SPHERE, shapes.BOX], dtype=np.int64)
    params = np.array([[0, 0.17, 0, 0], [0.1, 0.4, 0, 0], [0.1, 0, 0, 0], [0.1, 0.1, 0.1, 0]], dtype=float)
    centers = np.array([[0.05, 0.02, 0.097], [0.3, -0.4, 0.098], [-0.5, 0.5, 0.099], [0.5, 0.5, 0.0995]])
    rotations = np.array([np.eye(3), LYING, np.eye(3), np.eye(3)])
    point, normal, depth, feature, owner = shapes_against_mesh(
        kinds, params, centers, rotations, np.full(4, 0.01), mesh.geometry, 8, store
    )
    assert np.bincount(owner, minlength=4).tolist() == [4, 2, 1, 4]
    np.testing.assert_allclose(depth[owner == 0], 0.003, atol=1e-12)
    np.testing.assert_allclose(depth[owner == 1], 0.002, atol=1e-12)
    np.testing.assert_allclose(depth[owner == 3], 0.0005, atol=1e-12)


# ---------------------------------------------------------------------------------------------
# the independent NumPy reference
# ---------------------------------------------------------------------------------------------


def point_segment_distance(p, a, b):
    """p (..., 3) against segments a, b (T, 3): distances (..., T)."""
    ab = b - a
    t = np.clip(np.einsum("...tk,tk->...t", p[..., None, :] - a, ab) / np.einsum("tk,tk->t", ab, ab), 0.0, 1.0)
    closest = a + t[..., None] * ab
    return np.linalg.norm(p[..., None, :] - closest, axis=-1)


def point_triangle_distance(p, A, B, C):
    """Exact distances (S, T) of points p (S, 3) from triangles (A, B, C) (T, 3 each)."""
    n = np.cross(B - A, C - A)
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    rel = p[:, None, :] - A  # (S, T, 3)
    height = np.einsum("stk,tk->st", rel, n)
    foot = p[:, None, :] - height[..., None] * n  # projection on the plane
    inside = np.ones(height.shape, dtype=bool)
    for u, v in ((A, B), (B, C), (C, A)):
        inside &= np.einsum("stk,tk->st", np.cross(v - u, foot - u), n) >= 0.0
    edges = np.minimum(
        np.minimum(point_segment_distance(p, A, B), point_segment_distance(p, B, C)), point_segment_distance(p, C, A)
    )
    return np.where(inside, np.abs(height), edges)


def segment_mesh_distance(center, axis, half_length, A, B, C, samples=33):
    """Distance of the segment from the triangles: dense sampling, then a ternary search per triangle."""
    s = np.linspace(-half_length, half_length, samples)
    d = point_triangle_distance(center + s[:, None] * axis, A, B, C)  # (S, T)
    step = s[1] - s[0] if samples > 1 else 0.0
    # the distance is 1-Lipschitz along the segment: only triangles within a step of the best can win
    near = d.min(axis=0) <= d.min() + step
    A, B, C, d = A[near], B[near], C[near], d[:, near]
    best = d.argmin(axis=0)
    lo = np.clip(s[best] - step, -half_length, half_length)
    hi = np.clip(s[best] + step, -half_length, half_length)
    AA, BB, CC = np.concatenate([A, A]), np.concatenate([B, B]), np.concatenate([C, C])
    for _ in range(34):  # the bracket shrinks to 2 steps × (2/3)^34 < 1e-5 steps
        m1 = lo + (hi - lo) / 3.0
        m2 = hi - (hi - lo) / 3.0
        both = _diagonal(center + np.concatenate([m1, m2])[:, None] * axis, AA, BB, CC)
        d1, d2 = both[: len(m1)], both[len(m1) :]
        hi = np.where(d1 < d2, m2, hi)
        lo = np.where(d1 < d2, lo, m1)
    refined = _diagonal(center + (0.5 * (lo + hi))[:, None] * axis, A, B, C)
    return min(refined.min(), d.min())


def _diagonal(points, A, B, C):
    """Distance of points[t] (T, 3) from triangle t: the diagonal of point_triangle_distance."""
    n = np.cross(B - A, C - A)
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    height = np.einsum("tk,tk->t", points - A, n)
    foot = points - height[:, None] * n
    inside = np.ones(len(A), dtype=bool)
    for u, v in ((A, B), (B, C), (C, A)):
        inside &= np.einsum("tk,tk->t", np.cross(v - u, foot - u), n) >= 0.0

    def seg(a, b):
        ab = b - a
        t = np.clip(np.einsum("tk,tk->t", points - a, ab) / np.einsum("tk,tk->t", ab, ab), 0.0, 1.0)
        return np.linalg.norm(points - (a + t[:, None] * ab), axis=1)

    return np.where(inside, np.abs(height), np.minimum(np.minimum(seg(A, B), seg(B, C)), seg(C, A)))


def test_capsule_resting_in_the_builtin_bowl():
    bowl = load_mesh(builtin_mesh_path("bowl.obj"))
    A, B, C = (bowl.vertices[bowl.triangles[:, k]] for k in range(3))
    radius, half_length = 0.05, 0.15
    for angle in (0.0, 0.7):
        R = rotation_about((0, 0, 1), angle) @ LYING
        center = np.array([0.01, -0.02, 0.04 + radius + 0.01])
        axis = R[:, 2]
        # lower it until it penetrates by about 2 mm (reference distance from the NumPy code)
        reference = segment_mesh_distance(center, axis, half_length, A, B, C)
        center[2] -= reference - radius + 0.002
        reference = segment_mesh_distance(center, axis, half_length, A, B, C)
        P, N, D, F = capsule_contacts(bowl, center, R, radius, half_length, margin=0.005)
        assert 1 <= len(D) <= 8
        assert abs(D.max() - (radius - reference)) < 1e-9
        assert np.all(N[:, 2] > 0.5)  # out of the bowl's inner surface, upwards
        np.testing.assert_allclose(np.linalg.norm(N, axis=1), 1.0, atol=1e-12)
        assert len(set(F)) == len(F)


def test_capsule_against_a_random_mesh_matches_the_numpy_reference():
    rng = np.random.default_rng(7)
    g = 7
    xs, ys = np.meshgrid(np.linspace(0, 1, g), np.linspace(0, 1, g), indexing="ij")
    heights = 0.08 * rng.random((g, g))
    vertices = np.column_stack([xs.ravel(), ys.ravel(), heights.ravel()])
    triangles = []
    for i in range(g - 1):
        for j in range(g - 1):
            a, b, c, d = i * g + j, (i + 1) * g + j, (i + 1) * g + j + 1, i * g + j + 1
            triangles += [[a, b, c], [a, c, d]]
    mesh = TriangleMesh(vertices, np.array(triangles))
    A, B, C = (mesh.vertices[mesh.triangles[:, k]] for k in range(3))
    margin = 0.03
    compared = 0
    worst = 0.0
    for trial in range(4000):
        if compared >= 2000:
            break
        radius = rng.uniform(0.03, 0.12)
        half_length = rng.uniform(0.0, 0.25)
        R = np.linalg.qr(rng.normal(size=(3, 3)))[0]
        center = np.array([rng.uniform(0.3, 0.7), rng.uniform(0.3, 0.7), 0.0])
        cell = np.minimum((center[:2] * (g - 1)).astype(int), g - 2)
        top = heights[cell[0] : cell[0] + 2, cell[1] : cell[1] + 2].max()
        center[2] = top + rng.uniform(0.0, 0.09)
        axis = R[:, 2]
        ends = center + np.array([-half_length, half_length])[:, None] * axis
        if not np.all((ends[:, :2] > 0.02) & (ends[:, :2] < 0.98)):
            continue  # keep the segment over the terrain's interior
        # only triangles whose bounds come within radius + margin of the segment's bounds can
        # matter: the reference is exact when ≤ radius + margin, and larger otherwise
        grow = radius + margin + 1e-3
        lower, upper = ends.min(axis=0) - grow, ends.max(axis=0) + grow
        near = np.all((np.minimum(np.minimum(A, B), C) <= upper) & (np.maximum(np.maximum(A, B), C) >= lower), axis=1)
        reference = (
            segment_mesh_distance(center, axis, half_length, A[near], B[near], C[near]) if near.any() else np.inf
        )
        if reference < 1e-4:  # the segment touches the terrain: skipped
            continue
        P, N, D, F = capsule_contacts(mesh, center, R, radius, half_length, margin=margin)
        expected = radius - reference
        if expected < -margin + 1e-7:
            assert len(D) == 0 or D.max() < expected + 1e-6
            continue
        if expected < -margin + 1e-6:
            continue  # at the margin's threshold: either answer
        assert len(D) >= 1, (trial, expected)
        error = abs(D.max() - expected)
        worst = max(worst, error)
        assert error < 1e-6, (trial, D.max(), expected)
        assert np.all(D >= -margin - 1e-12)
        np.testing.assert_allclose(np.linalg.norm(N, axis=1), 1.0, atol=1e-12)
        assert np.all(N[:, 2] > 0.0)  # out of a terrain seen from above
        assert len(set(F)) == len(F)
        compared += 1
    assert compared >= 2000, compared
