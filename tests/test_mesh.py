"""Static triangle meshes: loading, BVH, contacts against meshes, P2 granularities, P4/P5, swept test.

The independent references are written here in plain NumPy (closest point by projection
and clamping to the three edges, not the Voronoi-region walk of the compiled code) and
python-fcl's GJK distance.
"""

import numpy as np
import pytest

from contactlab.collision.granularity import DetectionSettings, sample_points, surface_contacts, triangle_samples
from contactlab.collision.mesh_contacts import shapes_against_mesh
from contactlab.collision.mesh_sweep import sweep_sphere_mesh
from contactlab.collision.polytope_mesh import box_mesh
from contactlab.collision.signed_distance import box_obstacle, plane_obstacle, sphere_obstacle
from contactlab.collision.sphere_mesh import sphere_mesh
from contactlab.errors import InputError
from contactlab.meshes import TriangleMesh, builtin_mesh_path, load_mesh, triangles_near, vertex_normals
from contactlab.shapes import BOX, POINT, SPHERE

trimesh = pytest.importorskip("trimesh")


# ---------------------------------------------------------------------------------------------
# helpers and independent references
# ---------------------------------------------------------------------------------------------


def square(half=1.0, z=0.0, two_sided=False):
    """The flat square [−half, half]² at height z as two triangles sharing the diagonal (0,0)–(2,2)."""
    V = np.array([[-half, -half, z], [half, -half, z], [half, half, z], [-half, half, z]])
    return TriangleMesh(V, [[0, 1, 2], [0, 2, 3]], two_sided=two_sided)


def grid(n, half=1.0):
    """A flat n × n vertex grid on [−half, half]² (z = 0), triangles wound +z."""
    xs = np.linspace(-half, half, n)
    X, Y = np.meshgrid(xs, xs)
    V = np.column_stack([X.ravel(), Y.ravel(), np.zeros(n * n)])
    T = []
    for i in range(n - 1):
        for j in range(n - 1):
            a = i * n + j
            T += [[a, a + 1, a + n + 1], [a, a + n + 1, a + n]]
    return V, np.array(T)


def buffers(size=64):
    return np.zeros((size, 3)), np.zeros((size, 3)), np.zeros(size), np.zeros(size, dtype=np.int64)


def sphere_contacts(mesh, center, radius, margin=0.0, max_contacts=8):
    P, N, D, F = buffers()
    k = sphere_mesh((np.asarray(center, float), radius), mesh.geometry, margin, (P, N, D, F), 0, max_contacts)
    return P[:k], N[:k], D[:k], F[:k]


def reference_closest(points, V, T):
    """Closest points (N, T, 3) of every triangle to every point, by projection then edge clamping."""
    a, b, c = V[T[:, 0]], V[T[:, 1]], V[T[:, 2]]  # (T, 3)
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    p = points[:, None, :]  # (N, 1, 3)
    projected = p - np.sum((p - a) * n, axis=2, keepdims=True) * n  # (N, T, 3)
    inside = np.ones(projected.shape[:2], dtype=bool)
    for u, v in ((a, b), (b, c), (c, a)):
        inside &= np.sum(np.cross(v - u, projected - u) * n, axis=2) >= 0.0
    best = projected.copy()
    best_d = np.where(inside, np.linalg.norm(p - projected, axis=2), np.inf)
    for u, v in ((a, b), (b, c), (c, a)):
        e = v - u
        s = np.clip(np.sum((p - u) * e, axis=2) / np.sum(e * e, axis=1), 0.0, 1.0)
        q = u + s[..., None] * e
        d = np.linalg.norm(p - q, axis=2)
        better = (~inside) & (d < best_d)
        best[better] = q[better]
        best_d = np.where(better, d, best_d)
    return best, best_d


def reference_distance(points, V, T):
    """Unsigned distance (N,) of points to a triangle soup, brute force."""
    return reference_closest(np.atleast_2d(points), V, T)[1].min(axis=1)


# ---------------------------------------------------------------------------------------------
# loading
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("extension", ["obj", "stl", "ply"])
def test_load_each_format(tmp_path, extension):
    box = trimesh.creation.box(extents=(1.0, 2.0, 3.0))
    path = tmp_path / f"box.{extension}"
    box.export(path)
    mesh = load_mesh(path)
    assert mesh.vertex_count == 8 and mesh.triangle_count == 12  # STL's 36 corners merged
    np.testing.assert_allclose(mesh.bounds[0], [-0.5, -1.0, -1.5], atol=1e-6)
    centroids = mesh.vertices[mesh.triangles].mean(axis=1)
    assert np.all(np.sum(mesh.triangle_normals * centroids, axis=1) > 0.0)  # outward
    np.testing.assert_allclose(np.linalg.norm(mesh.vertex_normals, axis=1), 1.0)
    assert np.all(np.sum(mesh.vertex_normals * mesh.vertices, axis=1) > 0.0)
    scaled = load_mesh(path, scale=2.0)
    np.testing.assert_allclose(scaled.bounds[1], [1.0, 2.0, 3.0], atol=1e-6)
    moved = mesh.transformed((1.0, 2.0, 3.0), (np.cos(np.pi / 4), 0.0, 0.0, np.sin(np.pi / 4)))  # 90° about z
    np.testing.assert_allclose(moved.bounds[0], [1.0 - 1.0, 2.0 - 0.5, 3.0 - 1.5], atol=1e-6)
    assert moved.triangle_count == 12


def test_builtin_bowl_is_closed_and_faces_outward():
    bowl = load_mesh(builtin_mesh_path("bowl.obj"))
    assert bowl.triangle_count < 5000
    # a ball resting inside the bowl, on the inner bottom (z = 0.04): one contact, normal up
    P, N, D, F = sphere_contacts(bowl, (0.0, 0.0, 0.04 + 0.1 - 0.001), 0.1)
    assert len(D) >= 1
    deepest = np.argmax(D)
    assert N[deepest, 2] > 0.99 and abs(D[deepest] - 0.001) < 2e-3


def test_load_errors(tmp_path):
    with pytest.raises(InputError, match="no file") as error:
        load_mesh(tmp_path / "missing.obj", field="obstacles[0].file")
    assert error.value.field == "obstacles[0].file"
    garbage_text = tmp_path / "garbage.obj"
    garbage_text.write_text("hello world\nthis is not a mesh at all\n")
    with pytest.raises(InputError, match="no triangles"):
        load_mesh(garbage_text)
    rng = np.random.default_rng(3)
    for extension in ("ply", "stl"):
        broken = tmp_path / f"broken.{extension}"
        broken.write_bytes(rng.integers(0, 256, 500, dtype=np.uint8).tobytes())
        with pytest.raises(InputError):
            load_mesh(broken)
    empty = tmp_path / "empty.obj"
    empty.write_text("")
    with pytest.raises(InputError, match="no triangles"):
        load_mesh(empty)
    vertices_only = tmp_path / "points.obj"
    vertices_only.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    with pytest.raises(InputError, match="no triangles"):
        load_mesh(vertices_only)
    flat = tmp_path / "flat.obj"
    flat.write_text("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n")
    with pytest.raises(InputError, match="degenerate"):
        load_mesh(flat)
    not_finite = tmp_path / "nan.obj"
    not_finite.write_text("v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(InputError, match="non-finite"):
        load_mesh(not_finite)
    good = tmp_path / "good.obj"
    good.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    assert load_mesh(good).triangle_count == 1
    for scale in (0.0, -1.0, float("nan"), float("inf"), "big"):
        with pytest.raises(InputError, match="scale"):
            load_mesh(good, scale=scale)
    other = tmp_path / "mesh.xyz"
    other.write_text("0 0 0\n")
    with pytest.raises(InputError, match="unsupported"):
        load_mesh(other)
    with pytest.raises(InputError):
        TriangleMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 3]])
    with pytest.raises(InputError):
        TriangleMesh(np.zeros((3, 3)), np.zeros((0, 3), dtype=int))


# ---------------------------------------------------------------------------------------------
# BVH
# ---------------------------------------------------------------------------------------------


def test_bvh_query_equals_brute_force():
    rng = np.random.default_rng(1)
    centers = rng.uniform(-1.0, 1.0, (700, 3))
    V = (centers[:, None, :] + rng.normal(0.0, 0.05, (700, 3, 3))).reshape(-1, 3)
    T = np.arange(len(V)).reshape(-1, 3)
    mesh = TriangleMesh(V, T)
    out = np.empty(len(T), dtype=np.int64)
    small = np.empty(3, dtype=np.int64)
    for _ in range(1500):
        lower = rng.uniform(-1.2, 1.0, 3)
        upper = lower + rng.uniform(0.0, 0.5, 3)
        found = triangles_near(mesh.geometry, lower, upper, out)
        brute = np.nonzero(np.all((mesh.triangle_lower <= upper) & (mesh.triangle_upper >= lower), axis=1))[0]
        assert np.array_equal(np.sort(out[:found]), brute)
        # a too small buffer still reports the full count
        assert triangles_near(mesh.geometry, lower, upper, small) == found


# ---------------------------------------------------------------------------------------------
# sphere and box against a mesh
# ---------------------------------------------------------------------------------------------


def test_sphere_on_two_triangle_square_gets_one_contact():
    mesh = square()
    radius = 0.1
    # inside a face, exactly over the shared diagonal, a hair either side of it, over the
    # centre vertex where both triangles meet, near a corner vertex, and slightly sunk in
    for x, y in [
        (0.4, -0.3),
        (0.3, 0.3),
        (0.3 + 1e-13, 0.3),
        (0.3, 0.3 + 1e-13),
        (0.0, 0.0),
        (-0.7, -0.7),
        (0.95, 0.95),
        (0.6, 0.2),
    ]:
        for height in (0.1, 0.09, 0.105):
            P, N, D, F = sphere_contacts(mesh, (x, y, height), radius, margin=0.01)
            assert len(D) == 1, (x, y, height, F)
            np.testing.assert_allclose(N[0], [0.0, 0.0, 1.0], atol=1e-12)
            assert D[0] == pytest.approx(radius - height, abs=1e-12)
            np.testing.assert_allclose(P[0], [x, y, 0.5 * (height - radius)], atol=1e-12)
    # a sphere beyond the margin: none; over the outer edge: one edge contact, tilted normal
    assert len(sphere_contacts(mesh, (0.2, 0.1, 0.2), radius, margin=0.05)[2]) == 0
    P, N, D, F = sphere_contacts(mesh, (1.06, 0.3, 0.079), radius)
    offset = np.array([0.06, 0.0, 0.079])
    assert len(D) == 1 and F[0] == 16 * 0 + 2  # triangle 0, edge (1, 2)
    np.testing.assert_allclose(N[0], offset / np.linalg.norm(offset), atol=1e-12)
    assert D[0] == pytest.approx(radius - np.linalg.norm(offset), abs=1e-12)


def test_sphere_on_tessellated_floor_has_no_ghost_contacts():
    V, T = grid(9)
    mesh = TriangleMesh(V, T)
    rng = np.random.default_rng(2)
    for _ in range(300):
        x, y = rng.uniform(-0.8, 0.8, 2)
        height = rng.uniform(0.05, 0.1)
        P, N, D, F = sphere_contacts(mesh, (x, y, height), 0.1)
        assert len(D) == 1
        np.testing.assert_allclose(N[0], [0.0, 0.0, 1.0], atol=1e-12)
        assert D[0] == pytest.approx(0.1 - height, abs=1e-12)


def test_sphere_in_a_concave_corner_touches_both_walls():
    # floor z = 0 and wall x = 0 (facing +x), a sphere of radius 0.1 in the corner
    V = np.array([[0, -1, 0], [1, -1, 0], [1, 1, 0], [0, 1, 0], [0, -1, 1], [0, 1, 1.0]])
    T = [[0, 1, 2], [0, 2, 3], [0, 3, 5], [0, 5, 4]]
    mesh = TriangleMesh(V, T)
    P, N, D, F = sphere_contacts(mesh, (0.09, 0.2, 0.095), 0.1)
    assert len(D) == 2
    order = np.argsort(N[:, 0])
    np.testing.assert_allclose(N[order], [[0, 0, 1], [1, 0, 0]], atol=1e-12)
    np.testing.assert_allclose(D[order], [0.005, 0.01], atol=1e-12)


def test_box_resting_on_a_mesh_floor_gets_its_four_corners():
    mesh = square(half=2.0)
    half = np.array([0.3, 0.3, 0.2])
    P, N, D, F = buffers()
    for yaw in (0.0, np.pi / 4, 0.3):  # yaw π/4 puts two corners on the diagonal
        c, s = np.cos(yaw), np.sin(yaw)
        R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        for sink in (0.0, 0.002):
            k = box_mesh(((np.array([0.1, -0.05, 0.2 - sink]), R), half), mesh.geometry, 0.01, (P, N, D, F), 0, 8)
            assert k == 4, (yaw, sink, F[:k])
            np.testing.assert_allclose(N[:k], np.tile([0.0, 0.0, 1.0], (4, 1)), atol=1e-12)
            np.testing.assert_allclose(D[:k], sink, atol=1e-12)
            assert len(set((F[:k] % 16).tolist())) == 4  # four different corners
            np.testing.assert_allclose(P[:k, 2], -0.5 * sink, atol=1e-12)
    # a finely meshed floor: mesh vertices under the box add contacts, reduced to at most 8
    V, T = grid(11)
    fine = TriangleMesh(V, T)
    k = box_mesh(((np.array([0.05, 0.03, 0.199]), np.eye(3)), half), fine.geometry, 0.01, (P, N, D, F), 0, 8)
    assert 4 <= k <= 8
    np.testing.assert_allclose(N[:k], np.tile([0.0, 0.0, 1.0], (k, 1)), atol=1e-12)
    np.testing.assert_allclose(D[:k], 0.001, atol=1e-12)
    corners_xy = {(round(x, 9), round(y, 9)) for x in (-0.25, 0.35) for y in (-0.27, 0.33)}
    assert corners_xy <= {(round(x, 9), round(y, 9)) for x, y in P[:k, :2]}
    # a box hovering beyond the margin: nothing
    assert box_mesh(((np.array([0.0, 0.0, 0.25]), np.eye(3)), half), mesh.geometry, 0.01, (P, N, D, F), 0, 8) == 0


def test_box_on_a_mesh_peak_gets_vertex_contact():
    # a pyramid tip (one vertex) poking into the bottom face of a box
    V = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0], [0, 0, 0.5]])
    T = [[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]]
    mesh = TriangleMesh(V, T)
    P, N, D, F = buffers()
    k = box_mesh(
        ((np.array([0.0, 0.0, 0.5 + 0.2 - 0.01]), np.eye(3)), np.array([0.3, 0.3, 0.2])),
        mesh.geometry,
        0.0,
        (P, N, D, F),
        0,
        8,
    )
    assert k == 1 and F[0] % 16 >= 8
    np.testing.assert_allclose(N[0], [0.0, 0.0, 1.0])
    assert D[0] == pytest.approx(0.01)


def test_shapes_against_mesh_batch():
    mesh = square(half=2.0)
    kinds = np.array([SPHERE, POINT, BOX, SPHERE], dtype=np.int64)
    params = np.array([[0.1, 0, 0, 0], [0.0, 0, 0, 0], [0.3, 0.3, 0.2, 0], [0.1, 0, 0, 0]])
    centers = np.array([[0.5, 0.5, 0.09], [0.2, -0.3, -0.001], [-1.0, -1.0, 0.2], [0.0, 0.0, 3.0]])
    rots = np.ascontiguousarray(np.broadcast_to(np.eye(3), (4, 3, 3)))
    point, normal, depth, feature, owner = shapes_against_mesh(
        kinds, params, centers, rots, np.zeros(4), mesh.geometry, 8
    )
    assert owner.tolist() == [0, 1, 2, 2, 2, 2]
    np.testing.assert_allclose(depth, [0.01, 0.001, 0, 0, 0, 0], atol=1e-12)


# ---------------------------------------------------------------------------------------------
# randomized cross-check against independent implementations
# ---------------------------------------------------------------------------------------------


def test_sphere_mesh_cross_check_random():
    fcl = pytest.importorskip("fcl")
    rng = np.random.default_rng(7)
    ball = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    xs = np.linspace(-1.0, 1.0, 9)
    X, Y = np.meshgrid(xs, xs)
    terrain_V = np.column_stack([X.ravel(), Y.ravel(), 0.15 * np.sin(3 * X.ravel()) * np.cos(2 * Y.ravel())])
    _, terrain_T = grid(9)
    cases = [
        (TriangleMesh(ball.vertices, ball.faces, max_depth=0.3), "closed"),
        (TriangleMesh(terrain_V, terrain_T, two_sided=True), "sheet"),
    ]
    checked = with_contacts = 0
    for mesh, kind in cases:
        V, T = mesh.vertices, mesh.triangles
        model = fcl.BVHModel()
        model.beginModel(len(V), len(T))
        model.addSubModel(V, T)
        model.endModel()
        fcl_mesh = fcl.CollisionObject(model, fcl.Transform())
        count = 1500
        if kind == "closed":
            directions = rng.normal(size=(count, 3))
            directions /= np.linalg.norm(directions, axis=1, keepdims=True)
            centers = directions * rng.uniform(0.75, 1.3, (count, 1))
        else:
            centers = np.column_stack([rng.uniform(-0.9, 0.9, (count, 2)), rng.uniform(-0.4, 0.4, count)])
        radii = rng.uniform(0.0, 0.25, count)
        margins = rng.uniform(0.0, 0.05, count)
        mesh_points = []
        _, distance = reference_closest(centers, V, T)
        minimum = distance.min(axis=1)
        inside = (
            np.all(np.sum((centers[:, None, :] - V[T[:, 0]]) * mesh.triangle_normals, axis=2) < 0.0, axis=1)
            if kind == "closed"
            else np.zeros(count, dtype=bool)
        )
        for i in range(count):
            c, r, m = centers[i], radii[i], margins[i]
            deep = r + m + mesh.max_depth
            if abs(minimum[i] - (r + m)) < 1e-7 or abs(minimum[i] - deep) < 1e-7:
                continue  # on the boundary of the search: either answer
            P, N, D, F = sphere_contacts(mesh, c, r, margin=m, max_contacts=64)
            # outside: searched within radius + margin; inside a closed mesh, max_depth deeper
            expect_any = minimum[i] <= r + m or (inside[i] and minimum[i] <= deep)
            assert (len(D) > 0) == expect_any, (kind, i)
            checked += 1
            if not expect_any:
                continue
            with_contacts += 1
            # the mesh point of each contact: point = ½ (c − r n + q)
            q = 2.0 * P - c + r * N
            mesh_points.append(q)
            gaps = np.linalg.norm(q - c, axis=1)
            nearest = np.argmin(gaps)
            assert gaps[nearest] == pytest.approx(minimum[i], abs=1e-9)
            signed = -minimum[i] if inside[i] else minimum[i]
            assert D[nearest] == pytest.approx(r - signed, abs=1e-9)
            np.testing.assert_allclose(np.linalg.norm(N, axis=1), 1.0, atol=1e-12)
            assert np.all(D >= -m - 1e-12)
            if kind == "closed":
                # inside: one contact; a convex body seen from outside: one local minimum
                assert len(D) == 1
                assert np.dot(N[0], c) > 0.0
            if kind == "sheet":
                # two-sided: each contact pushes towards the centre's side
                assert np.all(np.sum(N * (c - q), axis=1) >= -1e-12)
            if not inside[i] and minimum[i] > 1e-3 and r > 1e-3 and i % 4 == 0:
                request, result = fcl.DistanceRequest(), fcl.DistanceResult()
                sphere = fcl.CollisionObject(fcl.Sphere(r), fcl.Transform(c))
                gap = fcl.distance(sphere, fcl_mesh, request, result)
                if gap > 1e-6:  # (python-fcl returns a denormal, not −1, for an overlap)
                    assert gap == pytest.approx(-D[nearest], abs=1e-6)
        # every contact's mesh point lies on the mesh
        assert np.all(reference_distance(np.concatenate(mesh_points), V, T) < 1e-9)
    assert checked >= 2000 and with_contacts >= 1500


# ---------------------------------------------------------------------------------------------
# P2 granularities, P4 / P5 normals
# ---------------------------------------------------------------------------------------------


def cloth_pushed_into_plane():
    V, T = grid(6)
    V = V.copy()
    V[:, 2] = -0.03 + 0.1 * V[:, 0] + 0.02 * V[:, 1] ** 2  # tilted, curved, partly below z = 0
    return V, T


@pytest.mark.parametrize("samples", [1, 2, 3])
def test_p2_granularities_on_a_plane(samples):
    V, T = cloth_pushed_into_plane()
    plane = plane_obstacle((0.0, 0.0, 2.0), 0.0)  # z = 0, normal normalized
    below = -V[:, 2]
    whole = surface_contacts(V, T, plane, DetectionSettings(granularity="object"))
    assert len(whole.depth) == 1
    assert whole.depth[0] == pytest.approx(below.max())
    assert whole.vertices[0, 0] == np.argmax(below) and np.all(whole.vertices[0, 1:] == -1)
    per_vertex = surface_contacts(V, T, plane, DetectionSettings(granularity="vertex"))
    assert len(per_vertex.depth) == np.count_nonzero(below >= 0.0)
    np.testing.assert_allclose(per_vertex.depth, below[per_vertex.vertices[:, 0]])
    np.testing.assert_allclose(per_vertex.normal, np.tile([0.0, 0.0, 1.0], (len(per_vertex.depth), 1)))
    # samples: k × k per triangle; weights sum to 1 and reproduce the sample point
    pattern = triangle_samples(samples)
    assert pattern.shape == (samples * samples, 3) and np.all(pattern > 0.0)
    np.testing.assert_allclose(pattern.mean(axis=0), 1.0 / 3.0)
    sample_z = np.einsum("sk,tk->ts", pattern, V[T][:, :, 2])
    sampled = surface_contacts(V, T, plane, DetectionSettings(granularity="samples", samples=samples))
    assert len(sampled.depth) == np.count_nonzero(sample_z <= 0.0)
    np.testing.assert_allclose(sampled.weights.sum(axis=1), 1.0)
    x = np.einsum("ck,ckd->cd", sampled.weights, V[sampled.vertices])
    np.testing.assert_allclose(x[:, 2], -sampled.depth, atol=1e-15)
    np.testing.assert_allclose(sampled.point, x + 0.5 * sampled.depth[:, None] * [0.0, 0.0, 1.0], atol=1e-15)
    assert np.all(sampled.vertices == T[sampled.feature // (samples * samples)])
    # margin: gaps down to −margin are included
    with_margin = surface_contacts(V, T, plane, DetectionSettings(granularity="vertex", margin=0.05))
    assert len(with_margin.depth) == np.count_nonzero(below >= -0.05)
    for bad in (dict(granularity="triangle"), dict(normal="average"), dict(granularity="samples", samples=0)):
        with pytest.raises(InputError):
            surface_contacts(V, T, plane, DetectionSettings(**bad))


@pytest.mark.parametrize("samples", [1, 2, 3])
def test_compiled_samples_are_the_barycentric_sums_in_order(samples):
    # sample t · S + s of the compiled sampling is Σ_k w_sk x_tk, the same bits as the NumPy sum
    # it replaced; surface_contacts then makes carriers and weights for the chosen samples alone
    V, T = cloth_pushed_into_plane()
    pattern = triangle_samples(samples)
    expected = np.einsum("sk,tkd->tsd", pattern, V[T]).reshape(-1, 3)
    np.testing.assert_array_equal(sample_points(V, T.astype(np.int64), pattern), expected)
    sampled = surface_contacts(
        V, T, plane_obstacle((0.0, 0.0, 1.0), 0.0), DetectionSettings(granularity="samples", samples=samples)
    )
    np.testing.assert_array_equal(sampled.weights, pattern[sampled.feature % len(pattern)])
    np.testing.assert_array_equal(sampled.point[:, :2], expected[sampled.feature, :2])


def test_p2b_against_sphere_and_mesh_obstacles():
    V, T = cloth_pushed_into_plane()
    # a mesh floor gives the same vertices and depths as the plane
    floor = square(half=3.0)
    plane = plane_obstacle((0.0, 0.0, 1.0), 0.0)
    on_plane = surface_contacts(V, T, plane, DetectionSettings(granularity="vertex"))
    on_mesh = surface_contacts(V, T, floor, DetectionSettings(granularity="vertex"), max_depth=0.5)
    np.testing.assert_array_equal(on_mesh.vertices, on_plane.vertices)
    np.testing.assert_allclose(on_mesh.depth, on_plane.depth, atol=1e-14)
    np.testing.assert_allclose(on_mesh.normal, on_plane.normal, atol=1e-15)
    sampled = surface_contacts(V, T, floor, DetectionSettings(granularity="samples", samples=2), max_depth=0.5)
    assert len(sampled.depth) == len(
        surface_contacts(V, T, plane, DetectionSettings(granularity="samples", samples=2)).depth
    )
    # a sphere obstacle of radius 0.5 at (0, 0, −0.45): vertices within it
    ball = sphere_obstacle((0.0, 0.0, -0.45), 0.5)
    contacts = surface_contacts(V, T, ball, DetectionSettings(granularity="vertex"))
    gaps = np.linalg.norm(V - [0.0, 0.0, -0.45], axis=1) - 0.5
    assert len(contacts.depth) == np.count_nonzero(gaps <= 0.0) > 0
    np.testing.assert_allclose(contacts.depth, -gaps[contacts.vertices[:, 0]])
    radial = V[contacts.vertices[:, 0]] - [0.0, 0.0, -0.45]
    np.testing.assert_allclose(contacts.normal, radial / np.linalg.norm(radial, axis=1, keepdims=True))


def test_p4_jumps_across_the_medial_axis_and_p5_is_continuous():
    box = box_obstacle((0.0, 0.0, 0.0), (1.0, 1.0, 1.0))
    # a small closed tetrahedron whose lowest vertex 0 dips into the box near its +x/+z edge
    base = np.array([[0.0, 0.0, 0.0], [0.3, 0.1, 0.4], [-0.1, 0.3, 0.4], [-0.1, -0.3, 0.4]])
    T = np.array([[0, 2, 1], [0, 3, 2], [0, 1, 3], [1, 2, 3]])
    assert np.all(
        np.einsum(
            "td,td->t",
            np.cross(base[T[:, 1]] - base[T[:, 0]], base[T[:, 2]] - base[T[:, 0]]),
            base[T].mean(axis=1) - base.mean(axis=0),
        )
        > 0.0
    )  # wound outward
    previous = {}
    jumps = {"object": 0.0, "vertex": 0.0}
    # vertex 0 travels along x at z = 0.9: it crosses the medial plane x = z of the box at x = 0.9
    for x in np.linspace(0.85, 0.95, 201):
        V = base + [x, 0.0, 0.9]
        for choice in ("object", "vertex"):
            c = surface_contacts(V, T, box, DetectionSettings(granularity="vertex", normal=choice))
            row = np.nonzero(c.vertices[:, 0] == 0)[0]
            assert len(row) == 1
            assert c.depth[row[0]] == pytest.approx(min(1.0 - x, 0.1))  # depth continuous
            n = c.normal[row[0]]
            if choice in previous:
                jumps[choice] = max(jumps[choice], np.linalg.norm(n - previous[choice]))
            previous[choice] = n
    assert jumps["object"] == pytest.approx(np.sqrt(2.0))  # (0,0,1) → (1,0,0) in one small step
    assert jumps["vertex"] < 1e-12  # −(vertex normal): does not jump
    np.testing.assert_allclose(previous["vertex"], -vertex_normals(base, T)[0])


# ---------------------------------------------------------------------------------------------
# swept test: no tunnelling through a thin sheet
# ---------------------------------------------------------------------------------------------


def test_fast_particle_is_caught_by_a_single_triangle_sheet():
    sheet = TriangleMesh([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [0.0, 1.0, 0.0]], [[0, 1, 2]], two_sided=True)
    radius = 0.01
    start = np.array([0.1, 0.0, 3.0 * radius])
    end = start - [0.0, 0.0, 10.0 * radius]  # 10 radii in one step, through the sheet
    # the static test at the end position sees the particle on the far side: it would tunnel
    P, N, D, F = sphere_contacts(sheet, end, radius)
    assert len(D) == 0
    hit, toi, triangle, normal = sweep_sphere_mesh(start, end, radius, sheet.geometry)
    assert hit and triangle == 0
    assert toi == pytest.approx(0.2)  # the centre is one radius above the sheet
    np.testing.assert_allclose(normal, [0.0, 0.0, 1.0])
    # from below, the normal faces down; a point particle (radius 0) hits at the plane itself
    hit, toi, _, normal = sweep_sphere_mesh(-start, -end, radius, sheet.geometry)
    assert hit and toi == pytest.approx(0.2) and normal[2] == pytest.approx(-1.0)
    hit, toi, _, _ = sweep_sphere_mesh(start, end, 0.0, sheet.geometry)
    assert hit and toi == pytest.approx(0.3)
    # starting in contact (centre half a radius above), the centre's own crossing still counts
    hit, toi, _, _ = sweep_sphere_mesh(np.array([0.1, 0.0, 0.5 * radius]), end, radius, sheet.geometry)
    assert hit and toi == pytest.approx(0.5 * radius / (7.5 * radius))
    # moving away, or passing beside the sheet: no hit
    assert not sweep_sphere_mesh(end, end - [0, 0, 1.0], radius, sheet.geometry)[0]
    assert not sweep_sphere_mesh(start + [2.0, 0, 0], end + [2.0, 0, 0], radius, sheet.geometry)[0]
    # a run of steps: the particle stops on the sheet instead of passing through
    z = 0.5
    for _ in range(100):
        position = np.array([0.1, 0.0, z])
        target = position - [0.0, 0.0, 10.0 * radius]
        hit, toi, _, _ = sweep_sphere_mesh(position, target, radius, sheet.geometry)
        z = (position + toi * (target - position))[2] if hit else target[2]
    assert z == pytest.approx(radius)


def test_swept_time_of_impact_matches_dense_sampling():
    rng = np.random.default_rng(11)
    V, T = grid(4)
    V = V.copy()
    V[:, 2] = 0.2 * rng.uniform(-1.0, 1.0, len(V))
    mesh = TriangleMesh(V, T, two_sided=True)
    times = np.linspace(0.0, 1.0, 1001)
    compared = 0
    for _ in range(80):
        radius = rng.uniform(0.0, 0.2)
        start = np.array([*rng.uniform(-1.0, 1.0, 2), rng.uniform(0.4, 0.8)])
        end = np.array([*rng.uniform(-1.0, 1.0, 2), rng.uniform(-0.8, 0.0)])
        if reference_distance(start, V, T)[0] <= radius:
            continue
        hit, toi, triangle, normal = sweep_sphere_mesh(start, end, radius, mesh.geometry)
        path = start + times[:, None] * (end - start)
        distance = reference_distance(path, V, T)
        touching = np.nonzero(distance <= radius)[0]
        if not hit:
            assert len(touching) == 0
        elif len(touching) == 0:  # a graze between two samples
            assert distance.min() - radius < np.linalg.norm(end - start) * times[1]
        else:
            step = times[1]
            assert times[touching[0]] - step - 1e-12 <= toi <= times[touching[0]] + 1e-12
            at = start + toi * (end - start)
            assert reference_distance(at, V, T)[0] == pytest.approx(radius, abs=1e-9)
            compared += 1
    assert compared > 30
