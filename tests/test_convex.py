"""Convex hulls (geometry, mass properties, input errors) and their contact manifolds.

Mass properties are checked against closed forms and against ``trimesh``'s independent
implementation. Contacts are checked on hand-built configurations, and on ≥ 2000 random
hull pairs against a brute-force NumPy reference written from the points alone: the
penetration depth of two convex sets is the minimum over unit directions d of the overlap of
their support functions, ``max_B d·x − min_A d·x``; the minimum is attained at a face normal
of their Minkowski difference, i.e. at a face normal of either hull or a cross product of
two of their edges, so evaluating it over all of those (taken from SciPy's triangulated
hulls, not from :mod:`contactlab.hulls`), plus 20 000 spread directions, gives it exactly.
``python-fcl`` is compared too, but its EPA (libccd) often stops at a non-minimal direction
(its depth is then too large, by up to ~100 %), so it is used only as an upper bound for the
depth and a reference for the distance of separated pairs (GJK), which it gets right.
"""

import itertools

import numpy as np
import pytest
from conftest import random_rotations
from scipy.spatial import ConvexHull

from contactlab.collision import convex as cx
from contactlab.collision import convex_convex as cc
from contactlab.collision import convex_sat
from contactlab.errors import InputError
from contactlab.hulls import Hull, box_as_hull, build_hull, hull_arrays, load_hull_points, pack_hulls

I3 = np.eye(3)
CUBE = np.array(list(itertools.product((-0.5, 0.5), repeat=3)))  # unit cube corners
REGULAR_TETRAHEDRON = np.array([[1.0, 1.0, 1.0], [1.0, -1.0, -1.0], [-1.0, 1.0, -1.0], [-1.0, -1.0, 1.0]])


# ------------------------------------------------------------------------------------------
# helpers


def rot_x(angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_z(angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def quaternion_matrix(q):
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def ellipsoid_points(rng, count):
    """``count`` points on a random ellipsoid (semi-axes 0.3..1.5 m), turned and moved."""
    d = rng.normal(size=(count, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return d * rng.uniform(0.3, 1.5, size=3) @ random_rotations(rng, 1)[0].T + rng.normal(scale=0.2, size=3)


def arrays(hull):
    return hull_arrays(pack_hulls([hull]), 0)


def buffers(slot):
    return (
        np.full((slot + 8, 3), np.nan),
        np.full((slot + 8, 3), np.nan),
        np.full(slot + 8, np.nan),
        np.full(slot + 8, -1, dtype=np.int64),
    )


def _unpack(out, slot, count):
    point, normal, depth, feature = out
    assert 0 <= count <= cx.MAX_CONTACTS
    assert np.isnan(depth[:slot]).all() and np.isnan(depth[slot + count :]).all()  # nothing outside
    s = slice(slot, slot + count)
    return point[s], normal[s], depth[s], feature[s]


def hull_hull(arr_a, R_a, c_a, arr_b, R_b, c_b, margin=0.0, slot=3):
    """convex_convex into fresh buffers, written from ``slot`` (to check the offset)."""
    out = buffers(slot)
    count = cc.convex_convex(
        (np.asarray(c_a, float), np.ascontiguousarray(R_a, dtype=float)),
        arr_a,
        (np.asarray(c_b, float), np.ascontiguousarray(R_b, dtype=float)),
        arr_b,
        float(margin),
        out,
        slot,
    )
    return _unpack(out, slot, count)


def hull_plane(arr, R, c, plane, margin=0.0, slot=2):
    out = buffers(slot)
    count = cx.convex_plane(
        (np.asarray(c, float), np.ascontiguousarray(R, dtype=float)),
        arr,
        np.asarray(plane, float),
        float(margin),
        out,
        slot,
    )
    return _unpack(out, slot, count)


def sphere_hull(center, radius, arr, R, c, margin=0.0, slot=1):
    out = buffers(slot)
    count = cx.sphere_convex(
        np.asarray(center, float),
        float(radius),
        (np.asarray(c, float), np.ascontiguousarray(R, dtype=float)),
        arr,
        float(margin),
        out,
        slot,
    )
    return _unpack(out, slot, count)


def sat_depth(arr_a, R_a, c_a, arr_b, R_b, c_b):
    """The SAT minimum overlap [m] (penetration depth when ≥ 0)."""
    result = np.empty(8)
    axis = np.zeros(3)
    convex_sat.convex_convex_sat(
        (np.asarray(c_a, float), np.ascontiguousarray(R_a)),
        arr_a,
        (np.asarray(c_b, float), np.ascontiguousarray(R_b)),
        arr_b,
        np.inf,
        result,
        axis,
    )
    return result[7]


def signed_distance(world_points, x):
    """Signed distance-like height of points x (k, 3) w.r.t. the hull of world_points: 0 on the
    surface, < 0 inside (SciPy's face planes, independent of contactlab.hulls)."""
    equations = ConvexHull(world_points).equations
    return (np.atleast_2d(x) @ equations[:, :3].T + equations[:, 3]).max(axis=1)


def sphere_directions(count):
    """``count`` unit vectors spread evenly over the sphere (Fibonacci lattice)."""
    k = np.arange(count) + 0.5
    z = 1 - 2 * k / count
    r = np.sqrt(1 - z * z)
    phi = np.pi * (1 + 5**0.5) * k
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


class Reference:
    """Per hull, in the body frame: SciPy's triangle normals and triangle edge vectors."""

    def __init__(self, hull):
        triangulated = ConvexHull(hull.vertices)
        self.normals = triangulated.equations[:, :3]
        edges = np.concatenate(
            [triangulated.simplices[:, [0, 1]], triangulated.simplices[:, [1, 2]], triangulated.simplices[:, [2, 0]]]
        )
        edges = np.unique(np.sort(edges, axis=1), axis=0)
        self.edges = hull.vertices[edges[:, 1]] - hull.vertices[edges[:, 0]]


def support_overlap(world_a, world_b, directions):
    """min over the unit ``directions`` (D, 3) and their opposites of max_B d·x − min_A d·x."""
    d = np.ascontiguousarray(directions.T)
    along_a = world_a[:, 0:1] * d[0] + world_a[:, 1:2] * d[1] + world_a[:, 2:3] * d[2]  # (V, D)
    along_b = world_b[:, 0:1] * d[0] + world_b[:, 1:2] * d[1] + world_b[:, 2:3] * d[2]
    return min((along_b.max(axis=0) - along_a.min(axis=0)).min(), (along_a.max(axis=0) - along_b.min(axis=0)).min())


def brute_force_depth(world_a, world_b, ref_a, R_a, ref_b, R_b):
    """The penetration depth when ≥ 0: ``support_overlap`` over both hulls' face normals and
    all cross products of an edge of A with an edge of B (SciPy's triangulations)."""
    cross = np.cross((ref_a.edges @ R_a.T)[:, None, :], (ref_b.edges @ R_b.T)[None, :, :]).reshape(-1, 3)
    length = np.linalg.norm(cross, axis=1)
    keep = length > 1e-9 * length.max()
    d = np.concatenate([ref_a.normals @ R_a.T, ref_b.normals @ R_b.T, cross[keep] / length[keep, None]])
    return support_overlap(world_a, world_b, d)


def overlap_along(world_a, world_b, n):
    """How far B reaches into A along the normal n (B → A): max_B n·x − min_A n·x."""
    return (world_b @ n).max() - (world_a @ n).min()


# ------------------------------------------------------------------------------------------
# hull geometry and mass properties


def test_box_corners_give_the_box():
    half = np.array([0.5, 1.0, 1.5])
    offset = np.array([1.0, -2.0, 3.0])
    hull = build_hull(CUBE * 2 * half + offset, mass=2.0)
    assert isinstance(hull, Hull)
    assert (hull.vertex_count, hull.face_count, hull.edge_count) == (8, 6, 12)
    assert hull.volume == pytest.approx(8 * half.prod(), rel=1e-12)
    x2, y2, z2 = (2 * half) ** 2
    assert np.allclose(hull.inertia, 2.0 / 12 * np.array([y2 + z2, x2 + z2, x2 + y2]), rtol=1e-12)
    assert np.allclose(hull.offset, offset, atol=1e-12)
    assert np.allclose(hull.orientation, [1, 0, 0, 0])  # already principal: axes kept
    assert np.allclose(np.abs(hull.vertices), half, atol=1e-12)
    # faces: outward unit normals, offsets = half extents, corners counter-clockwise from outside
    for f in range(hull.face_count):
        n = hull.face_normal[f]
        corners = hull.vertices[hull.face(f)]
        assert len(corners) == 4
        assert np.allclose(corners @ n, hull.face_offset[f], atol=1e-12)
        turning = sum(np.cross(corners[k], corners[(k + 1) % 4]) for k in range(4))
        assert turning @ n > 0.0
        assert hull.face_offset[f] == pytest.approx(half[np.argmax(np.abs(n))])
    # every edge joins two faces that both contain it
    for (a, b), (f, g) in zip(hull.edge_vertex, hull.edge_face):
        assert {a, b} <= set(hull.face(f).tolist()) and {a, b} <= set(hull.face(g).tolist())


def test_turned_box_keeps_its_moments_and_places_back():
    rng = np.random.default_rng(3)
    half = np.array([0.3, 0.5, 0.9])
    R = random_rotations(rng, 1)[0]
    points = (CUBE * 2 * half) @ R.T + [0.5, 0.2, -0.1]
    hull = build_hull(points, density=500.0)
    assert hull.mass == pytest.approx(500.0 * 8 * half.prod(), rel=1e-12)
    x2, y2, z2 = (2 * half) ** 2
    expected = hull.mass / 12 * np.array([y2 + z2, x2 + z2, x2 + y2])
    assert np.allclose(np.sort(hull.inertia), np.sort(expected), rtol=1e-10)
    # body → given frame reproduces the given points; the principal axes diagonalize the tensor
    given = hull.given_vertices()
    assert max(np.linalg.norm(points - p, axis=1).min() for p in given) < 1e-12
    axes = hull.principal_axes
    assert np.allclose(axes.T @ hull.inertia_tensor @ axes, np.diag(hull.inertia), atol=1e-12 * hull.inertia.max())
    assert np.allclose(quaternion_matrix(hull.orientation), axes)
    # placing the given frame somewhere places the body consistently
    q = np.array([0.8, 0.1, -0.3, 0.5])
    q /= np.linalg.norm(q)
    position = np.array([1.0, 2.0, 3.0])
    body_position, body_orientation = hull.body_pose(position, q)
    world_from_given = points @ quaternion_matrix(q).T + position
    world_from_body = hull.vertices @ quaternion_matrix(body_orientation).T + body_position
    assert max(np.linalg.norm(world_from_given - p, axis=1).min() for p in world_from_body) < 1e-12


def test_regular_tetrahedron():
    edge = 2.0 * np.sqrt(2.0)
    hull = build_hull(REGULAR_TETRAHEDRON + [0.3, 0.0, -1.0], mass=3.0)
    assert (hull.vertex_count, hull.face_count, hull.edge_count) == (4, 4, 6)
    assert hull.volume == pytest.approx(edge**3 / (6 * np.sqrt(2)), rel=1e-12)
    assert np.allclose(hull.inertia, 3.0 * edge**2 / 20, rtol=1e-12)  # isotropic: m a²/20
    assert np.allclose(hull.offset, [0.3, 0.0, -1.0], atol=1e-12)


def test_right_tetrahedron_off_centre():
    """Vertices 0, a e_x, b e_y, c e_z: centre of mass (a, b, c)/4 and the closed-form tensor."""
    a, b, c = 1.0, 2.0, 3.0
    mass = 6.0
    hull = build_hull([[0, 0, 0], [a, 0, 0], [0, b, 0], [0, 0, c]], mass=mass)
    assert hull.volume == pytest.approx(a * b * c / 6, rel=1e-12)
    centre = np.array([a, b, c]) / 4
    assert np.allclose(hull.offset, centre, atol=1e-14)
    # second moments about the origin: ∫x² = m a²/10, ∫xy = m ab/20 (per unit mass × mass)
    v = np.array([a, b, c])
    second = mass / 20 * (np.diag(v * v) + np.outer(v, v))
    covariance = second - mass * np.outer(centre, centre)
    tensor = np.trace(covariance) * I3 - covariance
    assert np.allclose(hull.inertia_tensor, tensor, rtol=1e-12, atol=1e-14)
    axes = hull.principal_axes
    assert np.allclose(axes.T @ tensor @ axes, np.diag(hull.inertia), atol=1e-12)
    assert np.allclose(np.sort(hull.inertia), np.linalg.eigvalsh(tensor), rtol=1e-12)
    assert np.linalg.det(axes) == pytest.approx(1.0)


def test_asymmetric_set_matches_trimesh():
    trimesh = pytest.importorskip("trimesh")
    rng = np.random.default_rng(11)
    points = np.concatenate([ellipsoid_points(rng, 40), rng.normal(scale=0.1, size=(10, 3))])  # some inside
    hull = build_hull(points, density=1.0)
    reference = trimesh.convex.convex_hull(points)
    assert hull.volume == pytest.approx(reference.volume, rel=1e-12)
    assert np.allclose(hull.offset, reference.center_mass, atol=1e-12)
    assert np.allclose(
        hull.inertia_tensor, reference.moment_inertia, atol=1e-12 * np.abs(reference.moment_inertia).max()
    )
    axes = hull.principal_axes
    diagonal = axes.T @ hull.inertia_tensor @ axes
    assert np.abs(diagonal - np.diag(np.diag(diagonal))).max() < 1e-12 * hull.inertia.max()
    assert np.allclose(np.diag(diagonal), hull.inertia, rtol=1e-12)
    assert len(hull.source_indices) == hull.vertex_count == len(reference.vertices)


def test_coplanar_triangles_merge_and_near_duplicates_collapse():
    # a cube with points on its faces and edges, and corners repeated with 1e-13 m of noise
    rng = np.random.default_rng(0)
    extra = np.array([[0.0, 0.0, 0.5], [0.25, -0.1, -0.5], [0.5, 0.0, 0.0], [0.5, 0.5, 0.0]])
    points = np.concatenate([CUBE, extra, CUBE + rng.normal(scale=1e-13, size=CUBE.shape)])
    hull = build_hull(points, require_convex=True)
    assert (hull.vertex_count, hull.face_count, hull.edge_count) == (8, 6, 12)
    assert hull.volume == pytest.approx(1.0, rel=1e-9)
    # a finely subdivided side: still one face, with its 4 corners only
    grid = np.array([[x, y, 0.5] for x in np.linspace(-0.5, 0.5, 5) for y in np.linspace(-0.5, 0.5, 5)])
    hull = build_hull(np.concatenate([CUBE, grid]))
    assert hull.face_count == 6 and all(len(hull.face(f)) == 4 for f in range(6))


def test_pack_and_slice():
    rng = np.random.default_rng(2)
    hulls = [build_hull(CUBE), build_hull(ellipsoid_points(rng, 12)), build_hull(REGULAR_TETRAHEDRON)]
    packed = pack_hulls(hulls)
    assert packed["vertex_start"].tolist() == [0, 8, 8 + hulls[1].vertex_count, 12 + hulls[1].vertex_count]
    assert packed["face_vertex_start"][-1] == len(packed["face_vertex_index"])
    assert packed["vertices"].shape == (packed["vertex_start"][-1], 3)
    for h, hull in enumerate(hulls):
        v, n, o, fvs, fvi, ev, ef = hull_arrays(packed, h)
        assert np.array_equal(v, hull.vertices) and np.array_equal(n, hull.face_normal)
        assert np.array_equal(o, hull.face_offset) and np.array_equal(fvi, hull.face_vertex_index)
        assert np.array_equal(fvs - fvs[0], hull.face_vertex_start)
        assert np.array_equal(ev, hull.edge_vertex) and np.array_equal(ef, hull.edge_face)
        store = (
            packed["vertex_start"],
            packed["vertices"],
            packed["face_start"],
            packed["face_normal"],
            packed["face_offset"],
            packed["face_vertex_start"],
            packed["face_vertex_index"],
            packed["edge_start"],
            packed["edge_vertex"],
            packed["edge_face"],
        )
        view = cx.hull_view(store, h)
        for x, y in zip(view, (v, n, o, fvs, fvi, ev, ef)):
            assert np.array_equal(x, y)
    assert np.allclose(packed["radius"][0], np.sqrt(0.75))


def test_box_as_hull_matches_the_built_box():
    half = np.array([0.2, 0.4, 0.7])
    box = box_as_hull(half)
    hull = build_hull(CUBE * 2 * half)
    assert np.allclose(box["vertices"][:, 0] > 0, [i & 1 for i in range(8)])  # corner bits as box_plane
    assert np.allclose(box["vertices"][:, 2] > 0, [bool(i & 4) for i in range(8)])
    for f in range(6):
        corners = box["vertices"][box["face_vertex_index"][4 * f : 4 * f + 4]]
        n = box["face_normal"][f]
        assert np.allclose(corners @ n, box["face_offset"][f])
        assert sum(np.cross(corners[k], corners[(k + 1) % 4]) for k in range(4)) @ n > 0.0
    # the same contacts from either description
    rng = np.random.default_rng(4)
    for _ in range(20):
        R_a, R_b = random_rotations(rng, 2)
        c_b = rng.normal(scale=0.4, size=3)
        from_box = hull_hull(hull_arrays(box, 0), R_a, np.zeros(3), arrays(hull), R_b, c_b, margin=0.05)
        from_points = hull_hull(arrays(hull), R_a, np.zeros(3), arrays(hull), R_b, c_b, margin=0.05)
        assert len(from_box[2]) == len(from_points[2])
        assert np.allclose(np.sort(from_box[2]), np.sort(from_points[2]), atol=1e-12)


# ------------------------------------------------------------------------------------------
# input errors


@pytest.mark.parametrize(
    "points, words",
    [
        (CUBE[:3], "at least 4"),
        (np.zeros((5, 3)), "copies of one point"),
        (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [0.5, 0.2, 0]], float), "flat or collinear"),
        (np.array([[0, 0, 0], [1, 1, 1], [2, 2, 2], [3, 3, 3]], float), "flat or collinear"),
        (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, np.nan]]), "finite"),
        (np.zeros((4, 2)), "shape (n, 3)"),
    ],
)
def test_bad_point_sets(points, words):
    with pytest.raises(InputError) as error:
        build_hull(points, field="bodies[2].points")
    assert error.value.field == "bodies[2].points"
    assert words in error.value.message
    assert error.value.message.count(". ") == 0  # one sentence


def test_non_convex_set_needs_a_mesh():
    rng = np.random.default_rng(5)
    inside = rng.uniform(-0.3, 0.3, size=(3, 3))
    points = np.concatenate([CUBE, inside, [[0.5, 0.0, 0.0]]])  # a face point is not "inside"
    build_hull(points)  # fine without require_convex
    with pytest.raises(InputError) as error:
        build_hull(points, require_convex=True, field="shape")
    assert "the points are not convex: 3 of 12 lie inside their hull" in error.value.message
    assert 'shape = "mesh"' in error.value.message
    with pytest.raises(InputError, match="mass"):
        build_hull(CUBE, mass=-1.0)
    with pytest.raises(InputError, match="both"):
        build_hull(CUBE, mass=1.0, density=2.0)


def test_load_hull_points(tmp_path):
    pytest.importorskip("trimesh")
    obj = tmp_path / "cube.obj"
    obj.write_text(
        "".join(f"v {x} {y} {z}\n" for x, y, z in CUBE)
        + "f 1 2 4 3\nf 5 7 8 6\nf 1 5 6 2\nf 3 4 8 7\nf 1 3 7 5\nf 2 6 8 4\n"
    )
    points = load_hull_points(obj, scale=2.0)
    assert points.shape == (8, 3) and np.allclose(np.abs(points), 1.0)
    hull = build_hull(points)
    assert hull.face_count == 6 and hull.volume == pytest.approx(8.0)
    with pytest.raises(InputError) as error:
        load_hull_points(tmp_path / "missing.obj", field="bodies[0].file")
    assert error.value.field == "bodies[0].file" and "no file" in error.value.message
    broken = tmp_path / "broken.stl"
    broken.write_bytes(b"\x00\x01binary junk that is not an STL file" * 3)
    with pytest.raises(InputError, match="broken.stl"):
        load_hull_points(broken)
    empty = tmp_path / "empty.obj"
    empty.write_text("# nothing here\nthis is not obj\n")
    with pytest.raises(InputError, match="empty.obj"):
        load_hull_points(empty)
    with pytest.raises(InputError, match=".xyz"):
        other = tmp_path / "points.xyz"
        other.write_text("0 0 0\n")
        load_hull_points(other)


# ------------------------------------------------------------------------------------------
# contacts: hand-built configurations


def test_cube_resting_on_plane_gives_four_corners():
    cube = arrays(build_hull(CUBE))
    d = 0.01
    point, normal, depth, feature = hull_plane(cube, I3, [0.3, -0.2, 0.5 - d], [0, 0, 1, 0])
    assert len(depth) == 4
    assert np.allclose(depth, d) and np.allclose(normal, [0, 0, 1])
    assert np.allclose(point[:, 2], -d / 2)  # midway between the surfaces
    assert np.allclose(np.sort(point[:, 0]), [-0.2, -0.2, 0.8, 0.8])
    assert len(set(feature.tolist())) == 4 and feature.min() >= 0 and feature.max() <= 255
    # a box as a hull numbers its corners like box_plane
    from contactlab.collision.narrow_phase import box_plane

    box = box_as_hull([0.5, 0.5, 0.5])
    R = rot_x(0.3) @ rot_z(0.2)
    c = np.array([0.0, 0.0, 0.6])  # all 8 corners within the margin
    _, _, hull_depth, hull_feature = hull_plane(hull_arrays(box, 0), R, c, [0, 0, 1, 0], margin=2.0)
    out = buffers(0)
    count = box_plane(((c, R), np.array([0.5, 0.5, 0.5])), np.array([0, 0, 1, 0.0]), 2.0, out, 0)
    box_depth, box_feature = out[2][:count], out[3][:count]
    assert len(box_depth) > 4 and len(hull_depth) == 4  # more corners in the margin: reduced
    depth_of_corner = dict(zip(box_feature.tolist(), box_depth.tolist()))
    for corner, depth in zip(hull_feature.tolist(), hull_depth.tolist()):
        assert depth == pytest.approx(depth_of_corner[corner], abs=1e-12)
    assert hull_depth.max() == pytest.approx(box_depth.max())  # the deepest corner is kept


def test_many_vertices_on_a_plane_reduce_to_four():
    ring = [(np.cos(t), np.sin(t), z) for t in np.linspace(0, 2 * np.pi, 32, endpoint=False) for z in (-0.5, 0.5)]
    cylinder = arrays(build_hull(np.array(ring)))
    point, normal, depth, feature = hull_plane(cylinder, I3, [0, 0, 0.49], [0, 0, 1, 0])
    assert len(depth) == 4 and np.allclose(depth, 0.01)
    xy = point[:, :2]
    order = np.argsort(np.arctan2(xy[:, 1], xy[:, 0]))
    x, y = xy[order].T
    area = 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))
    assert area > 1.9  # ≈ the inscribed square (2), of π
    assert len(set(feature.tolist())) == 4
    # above the plane, within the margin: speculative contacts with negative depth
    point, normal, depth, feature = hull_plane(cylinder, I3, [0, 0, 0.52], [0, 0, 1, 0], margin=0.05)
    assert len(depth) == 4 and np.allclose(depth, -0.02)
    assert len(hull_plane(cylinder, I3, [0, 0, 0.52], [0, 0, 1, 0], margin=0.01)[2]) == 0


def test_cube_on_cube_gives_four_contacts():
    cube = arrays(build_hull(CUBE))
    d = 0.02
    top = np.array([0.3, 0.1, 1.0 - d])
    point, normal, depth, feature = hull_hull(cube, I3, top, cube, I3, np.zeros(3))
    assert len(depth) == 4
    assert np.allclose(normal, [0, 0, 1]) and np.allclose(depth, d)
    assert np.allclose(point[:, 2], 0.5 - d / 2)
    # the corners of the overlap of the two squares
    assert np.allclose(np.sort(np.unique(np.round(point[:, 0], 12))), [-0.2, 0.5])
    assert np.allclose(np.sort(np.unique(np.round(point[:, 1], 12))), [-0.4, 0.5])
    assert len(set(feature.tolist())) == 4
    # features persist under a small motion that keeps the topology
    moved = hull_hull(cube, rot_z(1e-4), top + [1e-4, -2e-4, 1e-5], cube, I3, np.zeros(3))
    assert sorted(moved[3].tolist()) == sorted(feature.tolist())
    # a turned top cube: an octagon of overlap, reduced to 4 around it
    point, normal, depth, feature = hull_hull(cube, rot_z(np.pi / 4), [0, 0, 1.0 - d], cube, I3, np.zeros(3))
    assert len(depth) == 4 and np.allclose(depth, d) and np.allclose(normal, [0, 0, 1])
    # speculative: a gap of 0.01 within a margin of 0.05
    point, normal, depth, feature = hull_hull(cube, I3, [0.3, 0.1, 1.01], cube, I3, np.zeros(3), margin=0.05)
    assert len(depth) == 4 and np.allclose(depth, -0.01)
    assert len(hull_hull(cube, I3, [0.3, 0.1, 1.01], cube, I3, np.zeros(3), margin=0.005)[2]) == 0


def test_flush_stack_keeps_its_corners_and_features_under_jitter():
    """Equal cubes stacked flush: round-off or solver jitter must not move contacts along the
    edges (a nearly parallel edge crosses a side plane anywhere) nor renumber them."""
    cube = arrays(build_hull(CUBE))
    rng = np.random.default_rng(6)
    first = None
    for size in (1e-12, 1e-10, 1e-8, 1e-6, 1e-5):
        for _ in range(10):
            R = rot_z(rng.normal() * size) @ rot_x(rng.normal() * size)
            point, normal, depth, feature = hull_hull(
                cube, R, np.array([0, 0, 0.98]) + rng.normal(scale=size, size=3), cube, I3, np.zeros(3)
            )
            assert len(depth) == 4
            assert np.allclose(np.abs(point[:, :2]), 0.5, atol=10 * size + 1e-12)  # the 4 corners
            assert np.allclose(depth, 0.02, atol=10 * size + 1e-12)
            first = sorted(feature.tolist()) if first is None else first
            assert sorted(feature.tolist()) == first


def test_tetrahedron_vertex_pokes_a_face():
    # a tetrahedron standing on a vertex (pointing down) over a large box's top face
    tet = build_hull(REGULAR_TETRAHEDRON * 0.3)
    vertex = tet.vertices[np.argmin(tet.vertices @ [1, 1, 1])]  # turn this vertex to −z
    axis = np.cross(vertex / np.linalg.norm(vertex), [0, 0, -1.0])
    angle = np.arcsin(np.linalg.norm(axis))
    if vertex[2] > 0:
        angle = np.pi - angle
    k = axis / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    R = I3 + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K
    tip = R @ vertex
    assert np.allclose(tip / np.linalg.norm(tip), [0, 0, -1])
    d = 0.01
    c_tet = np.array([0.1, 0.2, 0.5 + np.linalg.norm(tip) - d])  # tip at height 0.5 − d
    slab = box_as_hull([2.0, 2.0, 0.5])
    point, normal, depth, feature = hull_hull(arrays(tet), R, c_tet, hull_arrays(slab, 0), I3, np.zeros(3))
    assert len(depth) == 1
    assert depth[0] == pytest.approx(d) and np.allclose(normal[0], [0, 0, 1])
    assert np.allclose(point[0], [0.1, 0.2, 0.5 - d / 2])
    # swapping A and B flips the normal only
    p2, n2, d2, f2 = hull_hull(hull_arrays(slab, 0), I3, np.zeros(3), arrays(tet), R, c_tet)
    assert np.allclose(p2, point) and np.allclose(n2, -normal) and np.allclose(d2, depth) and (f2 == feature).all()


def test_edge_against_edge():
    # two cubes turned 45° about perpendicular axes meet edge to edge
    cube = arrays(build_hull(CUBE))
    R_a = rot_x(np.pi / 4)  # lowest edge of A along x
    s = np.sqrt(0.5)
    R_b = np.array([[s, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, s]])  # 45° about y: highest edge of B along y
    reach = np.sqrt(0.5)  # centre to edge of a cube turned 45°
    d = 0.01
    c_a = np.array([0.0, 0.0, 2 * reach - d])
    point, normal, depth, feature = hull_hull(cube, R_a, c_a, cube, R_b, np.zeros(3))
    assert len(depth) == 1 and depth[0] == pytest.approx(d)
    assert np.allclose(normal[0], [0, 0, 1]) and np.allclose(point[0], [0, 0, reach - d / 2])
    p2, n2, d2, f2 = hull_hull(cube, R_b, np.zeros(3), cube, R_a, c_a)
    assert np.allclose(p2, point) and np.allclose(n2, -normal) and np.allclose(d2, depth) and (f2 == feature).all()


def test_resting_face_is_preferred_to_a_slightly_better_edge():
    # a box on a wide slab, tilted by 0.5°: faces win over the edge axis within the tolerance
    slab = hull_arrays(box_as_hull([3.0, 3.0, 0.5]), 0)
    box = hull_arrays(box_as_hull([0.5, 0.5, 0.5]), 0)
    R = rot_x(np.radians(0.5))
    lowest = (box_as_hull([0.5, 0.5, 0.5])["vertices"] @ R.T)[:, 2].min()
    point, normal, depth, feature = hull_hull(box, R, [0, 0, 0.5 - lowest - 0.001], slab, I3, np.zeros(3), margin=0.02)
    assert len(depth) == 4 and np.allclose(normal, [0, 0, 1])
    assert depth.max() == pytest.approx(0.001)


def test_sphere_against_hull():
    cube = arrays(build_hull(CUBE))
    R = rot_z(0.3)
    c = np.array([1.0, 0.0, 0.0])
    # over a face
    point, normal, depth, feature = sphere_hull(c + R @ [0.1, 0.2, 0.7], 0.25, cube, R, c)
    assert depth[0] == pytest.approx(0.05) and np.allclose(normal[0], R @ [0, 0, 1])
    assert np.allclose(point[0], c + R @ [0.1, 0.2, 0.5 - 0.025])
    # near a corner
    corner = np.array([0.5, 0.5, 0.5])
    direction = np.array([1.0, 2.0, 2.0]) / 3.0
    point, normal, depth, feature = sphere_hull(c + R @ (corner + 0.1 * direction), 0.15, cube, R, c)
    assert depth[0] == pytest.approx(0.05) and np.allclose(normal[0], R @ direction)
    # near an edge, a particle (radius 0) within the margin
    point, normal, depth, feature = sphere_hull(c + R @ [0.6, 0.0, 0.6], 0.0, cube, R, c, margin=0.2)
    assert depth[0] == pytest.approx(-0.1 * np.sqrt(2)) and np.allclose(normal[0], R @ [np.sqrt(0.5), 0, np.sqrt(0.5)])
    assert len(sphere_hull(c + R @ [0.6, 0.0, 0.6], 0.0, cube, R, c, margin=0.1)[2]) == 0
    # inside: out through the nearest face
    point, normal, depth, feature = sphere_hull(c + R @ [0.1, -0.35, 0.0], 0.1, cube, R, c)
    assert depth[0] == pytest.approx(0.25) and np.allclose(normal[0], R @ [0, -1, 0]) and feature[0] == 0


# ------------------------------------------------------------------------------------------
# randomized cross-checks


@pytest.fixture(scope="module")
def random_hulls():
    rng = np.random.default_rng(2024)
    hulls = [build_hull(ellipsoid_points(rng, int(rng.integers(5, 25)))) for _ in range(80)]
    packed = pack_hulls(hulls)
    return hulls, [hull_arrays(packed, h) for h in range(len(hulls))], [Reference(h) for h in hulls]


def test_random_hull_pairs_against_brute_force_and_fcl(random_hulls):
    """3000 random pairs (points on random ellipsoids, random poses, overlapping or near)."""
    fcl = pytest.importorskip("fcl")
    hulls, hull_arrays_, references = random_hulls
    rng = np.random.default_rng(7)
    spread = sphere_directions(20000)
    fcl_geometry = []
    for hull in hulls:
        faces = np.concatenate([[len(hull.face(f))] + hull.face(f).tolist() for f in range(hull.face_count)])
        fcl_geometry.append(fcl.Convex(hull.vertices, hull.face_count, faces.astype(np.int64)))
    overlapping = separated = exact_axis = fcl_agrees = 0
    worst = {"sat": 0.0, "max_depth_exact": 0.0, "surface": 0.0, "swap": 0.0}
    for trial in range(3000):
        i, j = rng.integers(0, len(hulls), 2)
        hull_a, hull_b = hulls[i], hulls[j]
        R_a, R_b = random_rotations(rng, 2)
        c_a = rng.normal(size=3)
        world_a = hull_a.vertices @ R_a.T + c_a
        # B along a random direction u, overlapping A along u by −0.05 .. 1 × the larger radius
        u = rng.normal(size=3)
        u /= np.linalg.norm(u)
        scale = max(hull_a.radius, hull_b.radius)
        turned_b = hull_b.vertices @ R_b.T
        c_b = ((world_a @ u).max() + (turned_b @ -u).max() + rng.uniform(-1.0, 0.05) * scale) * u
        world_b = turned_b + c_b
        arr_a, arr_b = hull_arrays_[i], hull_arrays_[j]
        margin = 0.1 * scale
        depth_sat = sat_depth(arr_a, R_a, c_a, arr_b, R_b, c_b)
        point, normal, depth, feature = hull_hull(arr_a, R_a, c_a, arr_b, R_b, c_b, margin=margin)
        obj_a = fcl.CollisionObject(fcl_geometry[i], fcl.Transform(R_a, c_a))
        obj_b = fcl.CollisionObject(fcl_geometry[j], fcl.Transform(R_b, c_b))
        # features: distinct, in 0..255; normals unit and shared by the manifold
        assert len(set(feature.tolist())) == len(feature) and ((0 <= feature) & (feature <= 255)).all()
        if len(depth):
            assert np.allclose(np.linalg.norm(normal, axis=1), 1.0, atol=1e-12)
            assert np.allclose(normal, normal[0], atol=1e-12)
            assert (depth >= -margin - 1e-12 * scale).all()
        truth = brute_force_depth(world_a, world_b, references[i], R_a, references[j], R_b)
        if trial % 10 == 0 and truth > 0.0:
            # 20 000 spread directions never find less overlap (the minimum is at a candidate)
            assert support_overlap(world_a, world_b, spread) >= truth - 1e-12 * scale
        if truth > 0.0:
            overlapping += 1
            # the SAT minimum is the penetration depth
            worst["sat"] = max(worst["sat"], abs(depth_sat - truth) / scale)
            assert depth_sat == pytest.approx(truth, rel=1e-9, abs=1e-12 * scale)
            assert 1 <= len(depth) <= 4
            # the axis used overlaps at least the minimum, and at most the face-bias tolerance more
            along = overlap_along(world_a, world_b, normal[0])
            assert truth - 1e-12 * scale <= along <= truth * (1 + cc.FACE_REL_TOL) + cc.FACE_ABS_TOL * scale + 1e-12
            # no contact deeper than that; the deepest has all of it when the exact axis is used
            assert depth.max() <= along + 1e-12 * scale
            if along <= truth + 1e-12 * scale:
                exact_axis += 1
                worst["max_depth_exact"] = max(worst["max_depth_exact"], abs(depth.max() - truth) / truth)
                assert depth.max() == pytest.approx(truth, rel=1e-6, abs=cc.DEPTH_TOL * scale)
            # both surface points (point ∓ depth/2 · normal) on their hulls' surfaces
            on_a = signed_distance(world_a, point - 0.5 * depth[:, None] * normal)
            on_b = signed_distance(world_b, point + 0.5 * depth[:, None] * normal)
            worst["surface"] = max(worst["surface"], np.abs(on_a).max() / scale, np.abs(on_b).max() / scale)
            assert np.abs(on_a).max() < 1e-9 * scale and np.abs(on_b).max() < 1e-9 * scale
            # fcl (EPA): never below the true depth; often equal
            result = fcl.CollisionResult()
            fcl.collide(obj_a, obj_b, fcl.CollisionRequest(enable_contact=True, num_max_contacts=1), result)
            assert result.contacts, "fcl finds no collision in an overlapping pair"
            fcl_depth = result.contacts[0].penetration_depth
            assert fcl_depth >= truth - 1e-9 * scale
            fcl_agrees += abs(fcl_depth - truth) <= 1e-6 * truth
        else:
            separated += 1
            distance = fcl.distance(obj_a, obj_b, fcl.DistanceRequest(), fcl.DistanceResult())
            # the SAT separation is a lower bound of the distance (exact for face-type closest features)
            assert -depth_sat <= distance + 1e-9 * scale
            assert -depth_sat <= -truth + 1e-12 * scale
            if distance <= margin:
                assert len(depth) >= 1
            if -depth_sat > margin:
                assert len(depth) == 0
        # swapping A and B flips the normal and nothing else
        p2, n2, d2, f2 = hull_hull(arr_b, R_b, c_b, arr_a, R_a, c_a, margin=margin)
        assert len(d2) == len(depth)
        if len(depth):
            o1, o2 = np.lexsort(point.T), np.lexsort(p2.T)
            difference = max(
                np.abs(point[o1] - p2[o2]).max(), np.abs(normal[o1] + n2[o2]).max(), np.abs(depth[o1] - d2[o2]).max()
            )
            worst["swap"] = max(worst["swap"], difference / scale)
            assert difference < 1e-9 * scale
            assert sorted(feature.tolist()) == sorted(f2.tolist())
    assert overlapping >= 600 and separated >= 600
    assert exact_axis >= 0.6 * overlapping
    assert fcl_agrees >= 0.4 * overlapping  # fcl's EPA stops early in the others
    print(
        f"\n{overlapping} overlapping, {separated} apart; exact axis {exact_axis}; fcl within 1e-6: "
        f"{fcl_agrees}; worst relative errors {worst}"
    )


def closest_on_triangles(x, triangles):
    """Distance from point x (3,) to the union of triangles (T, 3, 3), by regions (vectorized)."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    height = np.einsum("ij,ij->i", x - a, n)
    q = x - height[:, None] * n
    inside = np.ones(len(a), dtype=bool)
    for p0, p1 in ((a, b), (b, c), (c, a)):
        inside &= np.einsum("ij,ij->i", np.cross(p1 - p0, q - p0), n) >= 0.0
    best = np.where(inside, np.abs(height), np.inf)
    for p0, p1 in ((a, b), (b, c), (c, a)):
        e = p1 - p0
        t = np.clip(np.einsum("ij,ij->i", x - p0, e) / np.einsum("ij,ij->i", e, e), 0.0, 1.0)
        best = np.minimum(best, np.linalg.norm(x - (p0 + t[:, None] * e), axis=1))
    return best.min()


def test_random_spheres_against_brute_force(random_hulls):
    hulls, hull_arrays_, _ = random_hulls
    rng = np.random.default_rng(8)
    for _trial in range(600):
        h = int(rng.integers(0, len(hulls)))
        hull = hulls[h]
        R = random_rotations(rng, 1)[0]
        c = rng.normal(size=3)
        world = hull.vertices @ R.T + c
        centre = c + rng.normal(size=3) * hull.radius * 0.8
        radius = float(rng.uniform(0.0, 0.5))
        margin = 0.2
        point, normal, depth, feature = sphere_hull(centre, radius, hull_arrays_[h], R, c, margin=margin)
        triangulated = ConvexHull(world)
        height = (centre @ triangulated.equations[:, :3].T + triangulated.equations[:, 3]).max()
        if height <= 0.0:
            truth = radius - height  # inside: out through the nearest face
        else:
            truth = radius - closest_on_triangles(centre, world[triangulated.simplices])
        if truth < -margin:
            assert len(depth) == 0
            continue
        assert len(depth) == 1 and feature[0] == 0
        assert depth[0] == pytest.approx(truth, abs=1e-12)
        surface_b = point[0] + 0.5 * depth[0] * normal[0]
        surface_a = point[0] - 0.5 * depth[0] * normal[0]
        assert abs(signed_distance(world, surface_b)[0]) < 1e-12
        assert np.allclose(surface_a, centre - radius * normal[0], atol=1e-12)
        if height > 1e-9:  # outside: along centre − closest point
            assert np.allclose(normal[0], (centre - surface_b) / np.linalg.norm(centre - surface_b), atol=1e-9)


def test_random_hulls_on_a_plane(random_hulls):
    hulls, hull_arrays_, _ = random_hulls
    rng = np.random.default_rng(9)
    for _trial in range(300):
        h = int(rng.integers(0, len(hulls)))
        R = random_rotations(rng, 1)[0]
        normal = rng.normal(size=3)
        normal /= np.linalg.norm(normal)
        c = rng.normal(size=3)
        world = hulls[h].vertices @ R.T + c
        offset = (world @ normal).min() + rng.uniform(-0.05, 0.3)
        heights = world @ normal - offset
        point, n, depth, feature = hull_plane(hull_arrays_[h], R, c, [*normal, offset], margin=0.02)
        candidates = np.nonzero(heights <= 0.02)[0]
        assert len(depth) == min(len(candidates), 4) or (len(candidates) > 4 and len(depth) == 3)
        if len(depth):
            assert depth.max() == pytest.approx(-heights.min(), abs=1e-12)
            assert set(feature.tolist()) <= set(candidates.tolist())  # vertex indices (< 256 here)
            assert np.allclose(point - 0.5 * depth[:, None] * n, world[feature], atol=1e-12)
