"""Capsule against convex hull: hand-built configurations, the box special case against
:func:`capsule.capsule_box` (an independent implementation), and random hulls against a
brute-force NumPy reference written from the hull's points alone (SciPy's triangulation):

* overlapping: the segment–hull penetration is the minimum over unit directions u of the
  support overlap ``max_hull u·x − min_segment u·x``, attained at a face normal of the
  Minkowski sum (a hull face normal or ± segment × hull edge), evaluated over all of those
  plus 2000 spread directions; depth = radius + that minimum;
* apart: the segment–hull distance, minimized along the segment by golden section (the
  distance is convex along it) of the point–triangle distance to every hull triangle;
  depth = radius − distance.
"""

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from contactlab.collision.capsule_box import capsule_box
from contactlab.collision.capsule_convex import CAPSULE_CONVEX_CROSS_FEATURE, capsule_convex
from contactlab.hulls import box_as_hull, build_hull, hull_arrays, pack_hulls

I3 = np.eye(3)
CUBE_HALF = np.array([0.5, 0.5, 0.5])


def rotation_from_quaternion(q):
    q = np.asarray(q, dtype=float)
    w, x, y, z = q / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def random_rotation(rng):
    return rotation_from_quaternion(rng.normal(size=4))


def axis_rotation(axis):
    """A rotation whose third column is the unit ``axis``."""
    z = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


def outputs(n=4):
    return np.zeros((n, 3)), np.zeros((n, 3)), np.zeros(n), np.zeros(n, dtype=np.int64)


def run(center_a, rotation_a, radius, half_length, center_b, rotation_b, hull, margin=0.1):
    point, normal, depth, feature = outputs()
    count = capsule_convex(
        (np.asarray(center_a, float), rotation_a),
        radius,
        half_length,
        (np.asarray(center_b, float), rotation_b),
        hull,
        margin,
        (point, normal, depth, feature),
        0,
    )
    return count, point[:count], normal[:count], depth[:count], feature[:count]


@pytest.fixture(scope="module")
def cube():
    return hull_arrays(box_as_hull(CUBE_HALF), 0)


# ------------------------------------------------------------------------------------------
# hand-built configurations


def test_lying_flat_gives_two_equal_contacts(cube):
    # capsule along x, resting on the top face, 0.01 deep
    count, point, normal, depth, feature = run(
        [0.0, 0.0, 0.5 + 0.2 - 0.01], axis_rotation([1, 0, 0]), 0.2, 0.3, np.zeros(3), I3, cube
    )
    assert count == 2
    np.testing.assert_allclose(depth, [0.01, 0.01], atol=1e-12)
    np.testing.assert_allclose(normal, [[0, 0, 1], [0, 0, 1]], atol=1e-12)
    np.testing.assert_allclose(sorted(point[:, 0]), [-0.3, 0.3], atol=1e-12)
    np.testing.assert_allclose(point[:, 2], 0.5 - 0.005, atol=1e-12)  # midway between the surfaces
    assert feature[0] != feature[1] and 0 <= feature.min() and feature.max() <= 255
    # overhanging the edge: clipped at x = 0.5
    count, point, normal, depth, feature = run(
        [0.4, 0.0, 0.69], axis_rotation([1, 0, 0]), 0.2, 0.3, np.zeros(3), I3, cube
    )
    assert count == 2
    np.testing.assert_allclose(sorted(point[:, 0]), [0.1, 0.5], atol=1e-12)
    np.testing.assert_allclose(depth, [0.01, 0.01], atol=1e-12)


def test_upright_on_face_gives_one_contact(cube):
    count, point, normal, depth, feature = run([0.1, -0.2, 0.5 + 0.3 + 0.2 - 0.02], I3, 0.2, 0.3, np.zeros(3), I3, cube)
    assert count == 1
    np.testing.assert_allclose(depth, [0.02], atol=1e-12)
    np.testing.assert_allclose(normal[0], [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(point[0], [0.1, -0.2, 0.49], atol=1e-12)


def test_end_poking_an_edge_gives_one_contact(cube):
    # the capsule's −z end sits beyond the edge x = y = 0.5 (z = 0), pointing away diagonally
    direction = np.array([1.0, 1.0, 0.3]) / np.linalg.norm([1.0, 1.0, 0.3])
    tip = np.array([0.5, 0.5, 0.0]) + 0.15 * np.array([1.0, 1.0, 0.0]) / np.sqrt(2)
    count, point, normal, depth, feature = run(
        tip + 0.4 * direction, axis_rotation(direction), 0.2, 0.4, np.zeros(3), I3, cube
    )
    assert count == 1
    np.testing.assert_allclose(depth, [0.05], atol=1e-12)
    np.testing.assert_allclose(normal[0], [1 / np.sqrt(2), 1 / np.sqrt(2), 0.0], atol=1e-12)


def test_separated_within_margin_negative_depth(cube):
    count, point, normal, depth, feature = run(
        [0.0, 0.0, 0.5 + 0.2 + 0.03], axis_rotation([1, 0, 0]), 0.2, 0.3, np.zeros(3), I3, cube, margin=0.05
    )
    assert count == 2
    np.testing.assert_allclose(depth, [-0.03, -0.03], atol=1e-12)
    count = run([0.0, 0.0, 0.5 + 0.2 + 0.06], axis_rotation([1, 0, 0]), 0.2, 0.3, np.zeros(3), I3, cube, margin=0.05)[0]
    assert count == 0


def test_segment_deep_across_an_edge_uses_the_edge_axis(cube):
    # a segment along (1, −1, 0) crossing the cube near the edge x = y = 0.5: the axis
    # (1, 1, 0)/√2 overlaps 0.1/√2, less than every face (0.5 for z, 0.757 for x and y)
    count, point, normal, depth, feature = run(
        [0.45, 0.45, 0.0], axis_rotation([1, -1, 0]), 0.1, 1.0, np.zeros(3), I3, cube
    )
    assert count == 1
    np.testing.assert_allclose(normal[0], [1 / np.sqrt(2), 1 / np.sqrt(2), 0], atol=1e-12)
    np.testing.assert_allclose(depth[0], 0.1 + 0.1 / np.sqrt(2), atol=1e-12)
    assert feature[0] == CAPSULE_CONVEX_CROSS_FEATURE


def test_rotated_and_moved_hull(cube):
    rotation = rotation_from_quaternion([0.9, 0.1, -0.3, 0.2])
    shift = np.array([1.0, -2.0, 0.5])
    # the flat capsule of the first test, carried along with the cube
    center = shift + rotation @ np.array([0.0, 0.0, 0.69])
    count, point, normal, depth, feature = run(
        center, rotation @ axis_rotation([1, 0, 0]), 0.2, 0.3, shift, rotation, cube
    )
    assert count == 2
    np.testing.assert_allclose(depth, [0.01, 0.01], atol=1e-12)
    np.testing.assert_allclose(normal, [rotation[:, 2]] * 2, atol=1e-12)


# ------------------------------------------------------------------------------------------
# boxes: against capsule_box


def test_box_hulls_agree_with_capsule_box():
    rng = np.random.default_rng(7)
    p1, n1, d1, f1 = outputs()
    p2, n2, d2, f2 = outputs()
    compared = 0
    for _ in range(2500):
        half = rng.uniform(0.2, 1.0, 3)
        hull = hull_arrays(box_as_hull(half), 0)
        center_a = rng.uniform(-1.5, 1.5, 3)
        rotation_a = random_rotation(rng)
        radius = rng.uniform(0.05, 0.5)
        half_length = rng.uniform(0.0, 1.0) if rng.random() < 0.9 else 0.0
        center_b = rng.normal(size=3) * 0.1
        rotation_b = random_rotation(rng)
        margin = 0.2
        count_box = capsule_box(
            ((center_a, rotation_a), radius, half_length), ((center_b, rotation_b), half), margin, (p1, n1, d1, f1), 0
        )
        count_hull = capsule_convex(
            (center_a, rotation_a), radius, half_length, (center_b, rotation_b), hull, margin, (p2, n2, d2, f2), 0
        )
        assert count_box == count_hull
        if count_box == 0:
            continue
        compared += 1
        i = np.argmax(d1[:count_box])
        j = np.argmax(d2[:count_hull])
        assert abs(d1[i] - d2[j]) <= 1e-9
        np.testing.assert_allclose(n2[j], n1[i], atol=1e-9)
        np.testing.assert_allclose(np.linalg.norm(n2[:count_hull], axis=1), 1.0, atol=1e-12)
        # every contact, not only the deepest: the same points and depths, up to the round-off
        # of clipping a nearly grazing segment at a side plane (features differ only in the
        # numbering of edge contacts)
        np.testing.assert_allclose(d2[:count_hull], d1[:count_box], atol=1e-6)
        np.testing.assert_allclose(p2[:count_hull], p1[:count_box], atol=1e-6)
    assert compared > 1000


# ------------------------------------------------------------------------------------------
# random hulls: against a brute-force reference


def _point_triangle_distance(x, a, b, c, normal):
    """Distance from the point x (3,) to each triangle (a, b, c) (T, 3) each, unit normals (T, 3)."""
    height = np.einsum("ij,ij->i", x - a, normal)
    projection = x - height[:, None] * normal
    inside = np.ones(len(a), dtype=bool)
    for p, q in ((a, b), (b, c), (c, a)):
        inside &= np.einsum("ij,ij->i", np.cross(q - p, projection - p), normal) >= 0.0
    best = np.where(inside, np.abs(height), np.inf)
    for p, q in ((a, b), (b, c), (c, a)):
        e = q - p
        t = np.clip(np.einsum("ij,ij->i", x - p, e) / np.einsum("ij,ij->i", e, e), 0.0, 1.0)
        best = np.minimum(best, np.linalg.norm(x - (p + t[:, None] * e), axis=1))
    return best


def _reference(points, triangles, origin, direction, half_length, directions):
    """(penetration of the segment ≥ 0, or −distance) and the reference normal, hull frame."""
    ends = np.array([origin - half_length * direction, origin + half_length * direction])
    a, b, c = points[triangles[:, 0]], points[triangles[:, 1]], points[triangles[:, 2]]
    normals = np.cross(b - a, c - a)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    wound = normals.copy()  # as the corners wind (the point–triangle test needs it)
    normals *= np.sign(np.einsum("ij,ij->i", normals, a - points.mean(axis=0)))[:, None]  # SciPy's may point in
    edges = np.concatenate([b - a, c - b, a - c])
    cross = np.cross(direction, edges)
    keep = np.linalg.norm(cross, axis=1) > 1e-9
    cross = cross[keep] / np.linalg.norm(cross[keep], axis=1, keepdims=True)
    axes = np.concatenate([normals, cross, -cross, directions])
    overlap = (points @ axes.T).max(axis=0) - (ends @ axes.T).min(axis=0)
    k = np.argmin(overlap)
    if overlap[k] >= 0.0:
        return overlap[k], axes[k]

    def distance(s):
        return _point_triangle_distance(origin + s * direction, a, b, c, wound).min()

    lo, hi = -half_length, half_length
    golden = (np.sqrt(5.0) - 1.0) / 2.0
    x1, x2 = hi - golden * (hi - lo), lo + golden * (hi - lo)
    f1, f2 = distance(x1), distance(x2)
    for _ in range(50):
        if f1 < f2:
            hi, x2, f2 = x2, x1, f1
            x1 = hi - golden * (hi - lo)
            f1 = distance(x1)
        else:
            lo, x1, f1 = x1, x2, f2
            x2 = lo + golden * (hi - lo)
            f2 = distance(x2)
    best = min(f1, f2, distance(-half_length), distance(half_length))
    return -best, None


def test_random_hulls_against_brute_force():
    rng = np.random.default_rng(11)
    spread = rng.normal(size=(2000, 3))
    spread /= np.linalg.norm(spread, axis=1, keepdims=True)
    checked_overlap = checked_apart = 0
    point, normal, depth, feature = outputs()
    for trial in range(32):
        semi_axes = rng.uniform(0.3, 1.0, 3)
        raw = rng.normal(size=(rng.integers(8, 40), 3))
        raw /= np.linalg.norm(raw, axis=1, keepdims=True)
        hull = build_hull(raw * semi_axes)
        arrays = (
            hull.vertices,
            hull.face_normal,
            hull.face_offset,
            hull.face_vertex_start,
            hull.face_vertex_index,
            hull.edge_vertex,
            hull.edge_face,
        )
        triangles = ConvexHull(hull.vertices).simplices
        for _ in range(15):
            center_a = rng.uniform(-0.8, 0.8, 3)
            rotation_a = random_rotation(rng)
            radius = rng.uniform(0.05, 0.4)
            half_length = rng.uniform(0.0, 0.8)
            center_b = rng.normal(size=3) * 0.1
            rotation_b = random_rotation(rng)
            margin = 0.3
            count = capsule_convex(
                (center_a, rotation_a),
                radius,
                half_length,
                (center_b, rotation_b),
                arrays,
                margin,
                (point, normal, depth, feature),
                0,
            )
            origin = rotation_b.T @ (center_a - center_b)
            direction = rotation_b.T @ rotation_a[:, 2]
            value, _ = _reference(hull.vertices, triangles, origin, direction, half_length, spread)
            expected = radius + value
            if expected < -margin - 1e-9:
                assert count == 0
                continue
            if expected > -margin + 1e-9:
                assert count >= 1
            if count == 0:
                continue
            assert count <= 2
            k = np.argmax(depth[:count])
            assert abs(depth[k] - expected) <= 1e-6, (trial, depth[:count], expected)
            # the normal is a minimizing direction: the overlap along it is the penetration
            # (or, apart, the separation along it is the distance)
            n_local = rotation_b.T @ normal[k]
            ends = np.array([origin - half_length * direction, origin + half_length * direction])
            along = (hull.vertices @ n_local).max() - (ends @ n_local).min()
            assert abs(along - value) <= 1e-6
            assert np.all((feature[:count] >= 0) & (feature[:count] <= 255))
            if count == 2:
                assert feature[0] != feature[1]
            if value >= 0.0:
                checked_overlap += 1
            else:
                checked_apart += 1
    assert checked_overlap > 80 and checked_apart > 80, (checked_overlap, checked_apart)


def test_hull_sliced_out_of_a_packed_layout_gives_the_same_contacts():
    # face_vertex_start of the second hull starts at a global offset; the routine subtracts it
    rng = np.random.default_rng(3)
    first = build_hull(rng.normal(size=(20, 3)))
    raw = rng.normal(size=(25, 3))
    second = build_hull(raw / np.linalg.norm(raw, axis=1, keepdims=True) * [0.8, 0.5, 0.4])
    packed = pack_hulls([first, second])
    sliced = hull_arrays(packed, 1)
    assert sliced[3][0] > 0
    alone = (
        second.vertices,
        second.face_normal,
        second.face_offset,
        second.face_vertex_start,
        second.face_vertex_index,
        second.edge_vertex,
        second.edge_face,
    )
    for _ in range(200):
        pose = (
            rng.uniform(-0.9, 0.9, 3),
            random_rotation(rng),
            0.2,
            0.3,
            rng.normal(size=3) * 0.1,
            random_rotation(rng),
        )
        got = run(*pose, sliced)
        expected = run(*pose, alone)
        assert got[0] == expected[0]
        for x, y in zip(got[1:], expected[1:]):
            np.testing.assert_array_equal(x, y)


def test_features_persist_while_sliding_and_tipping_over_an_edge(cube):
    # a flat capsule slides along +x over the top face and past its edge: the two face-patch
    # features keep their numbers throughout (as capsule_box's do)
    seen = set()
    for x in np.linspace(0.0, 0.75, 40):
        count, point, normal, depth, feature = run(
            [x, 0.0, 0.69], axis_rotation([1, 0, 0]), 0.2, 0.3, np.zeros(3), I3, cube
        )
        assert count >= 1
        seen.update(int(f) for f in feature)
    assert seen <= {10, 11}  # top face = face 5 of box_as_hull: 2·5 + end
