"""Box–box contact manifold: hand-built configurations, symmetry, and randomized cross-checks.

The randomized checks compare against a brute-force NumPy reference written from the box
corners alone (support functions over 20 000 directions plus the 15 SAT axes), and, when
``python-fcl`` is installed, against FCL's box–box routine.
"""

import itertools

import numpy as np
import pytest
from conftest import random_rotations

from contactlab.collision.box_box import EDGE_FEATURE, FACE_ABS_TOL, FACE_REL_TOL, box_box, sat_overlaps

HALF = np.array([0.5, 0.5, 0.5])
I3 = np.eye(3)


def rot_z(angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rot_x(angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def contacts(center_a, rotation_a, half_a, center_b, rotation_b, half_b, margin=0.0):
    """Run box_box into fresh buffers (written from slot 3, to check the slot offset)."""
    slot = 3
    point = np.full((slot + 8, 3), np.nan)
    normal = np.full((slot + 8, 3), np.nan)
    depth = np.full(slot + 8, np.nan)
    feature = np.full(slot + 8, -1, dtype=np.int64)
    count = box_box(
        (np.asarray(center_a, float), np.asarray(rotation_a, float)),
        np.asarray(half_a, float),
        (np.asarray(center_b, float), np.asarray(rotation_b, float)),
        np.asarray(half_b, float),
        float(margin),
        (point, normal, depth, feature),
        slot,
    )
    assert 0 <= count <= 4
    assert np.isnan(depth[:slot]).all() and np.isnan(depth[slot + count :]).all()  # nothing outside
    s = slice(slot, slot + count)
    return point[s], normal[s], depth[s], feature[s]


def corners(center, rotation, half):
    signs = np.array(list(itertools.product((-1.0, 1.0), repeat=3)))
    return center + (signs * half) @ rotation.T


def interval_overlap(verts_a, verts_b, directions):
    """Overlap [m] of the projections of two vertex sets on each unit direction (rows): how far
    one must move along ±direction to separate them (negative: the gap between them)."""
    pa = verts_a @ directions.T
    pb = verts_b @ directions.T
    return np.minimum(pa.max(0) - pb.min(0), pb.max(0) - pa.min(0))


def oriented_overlap(verts_a, verts_b, n):
    """How far B reaches past A's lowest point along n (the overlap seen from normal n, B → A)."""
    return (verts_b @ n).max() - (verts_a @ n).min()


def sat_axes_from_corners(verts_a, verts_b):
    """The 15 SAT axes rebuilt from the corners (edges as corner differences), unit rows."""

    def edge_directions(v):  # corners in itertools.product order: bit 2 → x, bit 1 → y, bit 0 → z
        return np.array([v[4] - v[0], v[2] - v[0], v[1] - v[0]])

    ea, eb = edge_directions(verts_a), edge_directions(verts_b)
    axes = [e for e in ea] + [e for e in eb] + [np.cross(x, y) for x in ea for y in eb]
    axes = np.array(axes)
    length = np.linalg.norm(axes, axis=1)
    keep = length > 1e-6 * length.max()
    return axes[keep] / length[keep, None]


def fibonacci_sphere(count):
    k = np.arange(count) + 0.5
    z = 1 - 2 * k / count
    r = np.sqrt(1 - z * z)
    phi = np.pi * (1 + 5**0.5) * k
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def random_pairs(rng, count, reach=1.0):
    """Random boxes: half extents log-uniform in [0.05, 1] m, uniform orientations, B at the
    origin, A's centre in a random direction at up to ``reach`` × the sum of circumradii."""
    half_a = np.exp(rng.uniform(np.log(0.05), 0.0, (count, 3)))
    half_b = np.exp(rng.uniform(np.log(0.05), 0.0, (count, 3)))
    rot_a, rot_b = random_rotations(rng, count), random_rotations(rng, count)
    direction = rng.normal(size=(count, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    distance = rng.uniform(0.0, reach, count) * (np.linalg.norm(half_a, axis=1) + np.linalg.norm(half_b, axis=1))
    center_a = direction * distance[:, None]
    center_b = np.zeros((count, 3))
    return center_a, rot_a, half_a, center_b, rot_b, half_b


def sat_minimum(center_a, rotation_a, half_a, center_b, rotation_b, half_b):
    overlap, normal = np.empty(15), np.empty((15, 3))
    best = sat_overlaps((center_a, rotation_a), half_a, (center_b, rotation_b), half_b, overlap, normal)
    return overlap[best], normal[best], overlap


def polygon_area(points_2d):
    """Area of the convex hull of ≤ 4 points (shoelace after sorting by angle)."""
    c = points_2d.mean(0)
    order = np.argsort(np.arctan2(points_2d[:, 1] - c[1], points_2d[:, 0] - c[0]))
    p = points_2d[order]
    x, y = p[:, 0], p[:, 1]
    return 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def same_point_sets(p, q, atol):
    if len(p) != len(q):
        return False
    distance = np.linalg.norm(p[:, None, :] - q[None, :, :], axis=2)
    return bool((distance.min(axis=1) <= atol).all() and (distance.min(axis=0) <= atol).all())


def assert_features_valid(feature):
    assert ((feature >= 0) & (feature <= 7)).all()
    assert len(set(feature.tolist())) == len(feature)


# ---------------------------------------------------------------------------------------------
# (1) a cube resting on another, axis aligned


def test_cube_resting_on_cube_gives_the_four_corners():
    point, normal, depth, feature = contacts([0, 0, 0.999], I3, HALF, [0, 0, 0], I3, HALF)
    assert len(depth) == 4
    np.testing.assert_allclose(normal, np.tile([0.0, 0.0, 1.0], (4, 1)), atol=1e-15)  # B (below) into A
    np.testing.assert_allclose(depth, 0.001, rtol=1e-9)
    expected = np.array([[x, y, 0.4995] for x in (-0.5, 0.5) for y in (-0.5, 0.5)])
    assert same_point_sets(point, expected, atol=1e-12)  # the overlap square's corners, halfway
    assert_features_valid(feature)


def test_small_box_on_large_box_keeps_its_corners_with_corner_labels():
    """The larger face is the reference; the small box's 4 corners are the contacts and keep
    their features while the box slides and turns a little."""
    half_small, half_big = np.array([0.2, 0.1, 0.05]), np.array([2.0, 2.0, 0.5])
    first = None
    for step in range(20):
        angle, shift = 0.01 * step, 0.005 * step
        top = [shift, -shift, 0.5 + 0.05 - 0.002]
        point, normal, depth, feature = contacts(top, rot_z(angle), half_small, [0, 0, 0], I3, half_big)
        assert len(depth) == 4
        np.testing.assert_allclose(depth, 0.002, rtol=1e-9)
        expected = corners(np.array(top), rot_z(angle), half_small)
        expected = expected[expected[:, 2] < top[2]] + [0, 0, 0.001]
        assert same_point_sets(point, expected, atol=1e-12)
        assert (feature >= 4).all()  # reference face on B (the bigger box)
        local = (point - [shift, -shift, 0]) @ rot_z(angle)
        by_corner = {tuple(np.round(p, 9)): f for p, f in zip(local, feature)}
        if first is None:
            first = by_corner
        assert by_corner.keys() == first.keys() and by_corner == first


@pytest.mark.parametrize(
    "half_top, half_bottom, height",
    [(HALF, HALF, 0.999), (np.array([0.2, 0.3, 0.1]), np.array([1.0, 1.0, 0.5]), 0.599)],
)
def test_features_and_points_persist_under_jitter(half_top, half_bottom, height):
    """A resting box jittered by 10 µm and 10 µrad, as a solver leaves it from step to step:
    the contacts stay at the same 4 corners with the same features. For equal boxes stacked
    flush this needs the removal of nearly straight clipped corners."""
    rng = np.random.default_rng(11)
    reference = None
    for _step in range(200):
        angle = rng.normal(scale=1e-5, size=3)
        R = rot_x(angle[0]) @ rot_y(angle[1]) @ rot_z(angle[2])
        center = np.array([0.0, 0.0, height]) + rng.normal(scale=1e-5, size=3)
        point, normal, depth, feature = contacts(center, R, half_top, np.zeros(3), I3, half_bottom)
        assert len(depth) == 4
        if reference is None:
            reference = point, feature
            expected = corners(np.zeros(3), I3, half_top)[::2, :2]  # the 4 corners (x, y)
            assert same_point_sets(point[:, :2], expected, atol=1e-4)
            continue
        distance = np.linalg.norm(point[:, None] - reference[0][None], axis=2)
        assert distance.min(axis=1).max() < 1e-4
        assert (reference[1][distance.argmin(axis=1)] == feature).all()


# ---------------------------------------------------------------------------------------------
# (2) the top cube turned 45° about z: the intersection is a regular octagon


def test_cube_turned_45_degrees_gives_the_largest_quadrilateral_of_the_octagon():
    point, normal, depth, feature = contacts([0, 0, 0.999], rot_z(np.pi / 4), HALF, [0, 0, 0], I3, HALF)
    assert len(depth) == 4
    np.testing.assert_allclose(depth, 0.001, rtol=1e-9)
    np.testing.assert_allclose(normal, np.tile([0.0, 0.0, 1.0], (4, 1)), atol=1e-15)
    np.testing.assert_allclose(point[:, 2], 0.4995, atol=1e-12)
    t = np.sqrt(0.5) - 0.5  # where the turned square crosses the sides
    octagon = np.array(
        [[sx * 0.5, sy * t] for sx in (-1, 1) for sy in (-1, 1)]
        + [[sx * t, sy * 0.5] for sx in (-1, 1) for sy in (-1, 1)]
    )
    distance = np.linalg.norm(point[:, None, :2] - octagon[None], axis=2)
    assert (distance.min(axis=1) < 1e-12).all()  # every contact is a corner of the octagon
    best = max(polygon_area(octagon[list(s)]) for s in itertools.combinations(range(8), 4))
    assert polygon_area(point[:, :2]) == pytest.approx(best, rel=1e-12)
    assert_features_valid(feature)


def test_reduction_keeps_the_deepest_point():
    """A smaller cube turned 30° and tilted on a larger top face: all 4 of its bottom corners
    stick out, the clipped polygon is an octagon of crossing points at different depths."""
    half_top, half_bottom = np.array([0.3, 0.3, 0.3]), np.array([0.35, 0.35, 0.5])
    R = rot_x(0.003) @ rot_z(np.pi / 6)
    center = np.array([0.0, 0.0, 0.5 + 0.3 - 0.01])
    point, normal, depth, feature = contacts(center, R, half_top, [0, 0, 0], I3, half_bottom)
    assert len(depth) == 4
    np.testing.assert_allclose(normal, np.tile([0.0, 0.0, 1.0], (4, 1)), atol=1e-15)
    assert (feature >= 4).all()  # the larger face (B's) is the reference
    # independent: the bottom face's edges crossing the sides of the square |x|, |y| ≤ 0.35
    face = [center + R @ (np.array([sx, sy, -1.0]) * half_top) for sx, sy in ((1, 1), (-1, 1), (-1, -1), (1, -1))]
    inside = [c for c in face if (np.abs(c[:2]) <= 0.35).all()]
    assert not inside
    crossings = []
    for p0, p1 in zip(face, face[1:] + face[:1]):
        for axis in (0, 1):
            for value in (-0.35, 0.35):
                t = (value - p0[axis]) / (p1[axis] - p0[axis])
                x = p0 + t * (p1 - p0)
                if 0 <= t <= 1 and abs(x[1 - axis]) <= 0.35:
                    crossings.append(x)
    crossings = np.array(crossings)
    assert len(crossings) == 8
    expected_depth = 0.5 - crossings[:, 2]
    assert depth.max() == pytest.approx(expected_depth.max(), rel=1e-12)
    for p, d in zip(point, depth):  # each contact is one of the crossings, halfway up
        k = np.argmin(np.linalg.norm(crossings[:, :2] - p[:2], axis=1))
        np.testing.assert_allclose(p, crossings[k] + [0, 0, 0.5 * d], atol=1e-12)
        assert d == pytest.approx(expected_depth[k], rel=1e-12)


# ---------------------------------------------------------------------------------------------
# (3) edge against edge


def crossed_edges(overlap=0.001, offset=(0.0, 0.0)):
    """A: cube turned 45° about y (an edge along y at its bottom); B: cube turned 45° about x
    (an edge along x on its top). Their edges cross with ``overlap`` [m] of interpenetration."""
    top = 2 * np.sqrt(0.5) - overlap
    return [offset[0], offset[1], top], rot_y(np.pi / 4), HALF, [0, 0, 0], rot_x(np.pi / 4), HALF


def test_crossed_edges_give_one_contact_along_the_cross_product():
    point, normal, depth, feature = contacts(*crossed_edges())
    assert len(depth) == 1
    edge_a, edge_b = rot_y(np.pi / 4)[:, 1], rot_x(np.pi / 4)[:, 0]
    axis = np.cross(edge_a, edge_b)
    np.testing.assert_allclose(abs(normal[0] @ axis) / np.linalg.norm(axis), 1.0, atol=1e-14)
    np.testing.assert_allclose(normal[0], [0, 0, 1], atol=1e-14)
    assert depth[0] == pytest.approx(0.001, rel=1e-9)
    np.testing.assert_allclose(point[0], [0, 0, np.sqrt(0.5) - 0.0005], atol=1e-12)
    assert feature[0] == EDGE_FEATURE


def test_crossed_edges_off_centre():
    point, normal, depth, feature = contacts(*crossed_edges(0.002, offset=(0.2, -0.3)))
    assert len(depth) == 1
    assert depth[0] == pytest.approx(0.002, rel=1e-9)
    # B's top edge is the x axis at height √½; A's bottom edge is the line x = 0.2 along y
    np.testing.assert_allclose(point[0], [0.2, 0.0, np.sqrt(0.5) - 0.001], atol=1e-12)


@pytest.mark.parametrize("case", ["resting", "turned", "edges"])
def test_results_follow_a_rigid_motion_of_the_scene(case):
    rng = np.random.default_rng(7)
    scene = {
        "resting": ([0, 0, 0.999], I3, HALF, [0, 0, 0], I3, HALF),
        "turned": ([0, 0, 0.999], rot_z(np.pi / 4), HALF, [0, 0, 0], I3, HALF),
        "edges": crossed_edges(),
    }[case]
    ca, Ra, ha, cb, Rb, hb = scene
    base = contacts(*scene)
    for Q in random_rotations(rng, 5):
        shift = rng.normal(size=3)
        moved = contacts(Q @ np.asarray(ca, float) + shift, Q @ Ra, ha, Q @ np.asarray(cb, float) + shift, Q @ Rb, hb)
        assert same_point_sets(moved[0], base[0] @ Q.T + shift, atol=1e-12)
        np.testing.assert_allclose(moved[1], base[1] @ Q.T, atol=1e-12)
        np.testing.assert_allclose(np.sort(moved[2]), np.sort(base[2]), rtol=1e-9)


# ---------------------------------------------------------------------------------------------
# (4) swapping A and B


def assert_swap_symmetric(scene, margin=0.0, candidates=None):
    ca, Ra, ha, cb, Rb, hb = scene
    p1, n1, d1, f1 = contacts(ca, Ra, ha, cb, Rb, hb, margin)
    p2, n2, d2, f2 = contacts(cb, Rb, hb, ca, Ra, ha, margin)
    assert len(d1) == len(d2)
    if len(d1) == 0:
        return
    np.testing.assert_allclose(n2, -n1, atol=1e-12)
    if candidates is not None:
        # equal faces: the reference is A's either way, and the reduction of a regular octagon
        # may pick either of its two equal squares; both must be such a square
        for p in (p1, p2):
            assert (np.linalg.norm(p[:, None] - candidates[None], axis=2).min(axis=1) < 1e-12).all()
            assert polygon_area(p[:, :2]) == pytest.approx(polygon_area(p1[:, :2]), rel=1e-12)
        np.testing.assert_allclose(d1, d2, rtol=1e-9)
        return
    assert same_point_sets(p1, p2, atol=1e-12)
    order1, order2 = np.lexsort(np.round(p1, 9).T), np.lexsort(np.round(p2, 9).T)
    np.testing.assert_allclose(d1[order1], d2[order2], rtol=1e-9, atol=1e-14)


@pytest.mark.parametrize("case", ["resting", "turned", "edges", "near"])
def test_swapping_boxes_flips_the_normal_only(case):
    scene = {
        "resting": ([0, 0, 0.999], I3, HALF, [0, 0, 0], I3, HALF),
        "turned": ([0, 0, 0.999], rot_z(np.pi / 4), HALF, [0, 0, 0], I3, HALF),
        "edges": crossed_edges(),
        "near": ([0.1, 0.2, 1.003], rot_z(0.3), HALF, [0, 0, 0], I3, HALF),
    }[case]
    octagon = None
    if case == "turned":
        t = np.sqrt(0.5) - 0.5
        octagon = np.array(
            [[sx * 0.5, sy * t, 0.4995] for sx in (-1, 1) for sy in (-1, 1)]
            + [[sx * t, sy * 0.5, 0.4995] for sx in (-1, 1) for sy in (-1, 1)]
        )
    assert_swap_symmetric(scene, margin=0.01, candidates=octagon)


def test_swapping_random_boxes_flips_the_normal_only():
    """Boxes of different sizes: the choice of reference face does not depend on the order."""
    rng = np.random.default_rng(3)
    pairs = random_pairs(rng, 300)
    for k in range(300):
        assert_swap_symmetric(tuple(x[k] for x in pairs), margin=0.05)


# ---------------------------------------------------------------------------------------------
# (5) separation and the margin


def test_separated_boxes_give_nothing():
    assert len(contacts([0, 0, 1.01], I3, HALF, [0, 0, 0], I3, HALF)[2]) == 0
    assert len(contacts([3, 0, 0], rot_z(0.4), HALF, [0, 0, 0], I3, HALF, margin=0.1)[2]) == 0
    assert len(contacts(*crossed_edges(overlap=-0.01))[2]) == 0


def test_gap_within_margin_gives_negative_depths():
    point, normal, depth, feature = contacts([0, 0, 1.002], I3, HALF, [0, 0, 0], I3, HALF, margin=0.005)
    assert len(depth) == 4
    np.testing.assert_allclose(depth, -0.002, rtol=1e-9)
    np.testing.assert_allclose(point[:, 2], 0.501, atol=1e-12)  # still midway
    np.testing.assert_allclose(normal, np.tile([0.0, 0.0, 1.0], (4, 1)), atol=1e-15)
    assert len(contacts([0, 0, 1.002], I3, HALF, [0, 0, 0], I3, HALF, margin=0.001)[2]) == 0
    point, normal, depth, feature = contacts(*crossed_edges(overlap=-0.003), margin=0.005)
    assert len(depth) == 1 and depth[0] == pytest.approx(-0.003, rel=1e-9)
    np.testing.assert_allclose(point[0], [0, 0, np.sqrt(0.5) + 0.0015], atol=1e-12)


def test_tilted_box_keeps_only_corners_within_the_margin():
    """A box tilted about x rests on one edge: two corners touch, the other two are 2 cm up."""
    angle = np.arcsin(0.02 / 1.0)  # raises the far edge by 2 cm over 1 m
    R = rot_x(angle)
    lowest = corners(np.zeros(3), R, HALF)[:, 2].min()
    center = np.array([0, 0, 0.5 - lowest - 0.001])
    _, _, depth, _ = contacts(center, R, HALF, [0, 0, 0], I3, HALF, margin=0.005)
    assert len(depth) == 2 and depth == pytest.approx([0.001, 0.001], rel=1e-6)
    _, _, depth, _ = contacts(center, R, HALF, [0, 0, 0], I3, HALF, margin=0.05)
    assert len(depth) == 4
    depth = np.sort(depth)
    assert depth[2:] == pytest.approx([0.001, 0.001], rel=1e-6)
    # the raised corners: 19 mm up, measured across the (slightly tilted) reference face
    assert depth[0] == pytest.approx(depth[1], abs=1e-12) and -0.0195 < depth[0] < -0.018


# ---------------------------------------------------------------------------------------------
# (6) randomized cross-checks


RANDOM_PAIRS = 2500


@pytest.fixture(scope="module")
def random_scenes():
    return random_pairs(np.random.default_rng(2024), RANDOM_PAIRS)


def test_sat_depth_matches_brute_force_support_functions(random_scenes):
    """For overlapping boxes the smallest SAT overlap is the penetration depth: the minimum,
    over all directions, of the overlap of the two boxes' projections. Reference: corners
    projected on 20 000 directions and on the 15 axes rebuilt from the corners."""
    directions = fibonacci_sphere(20_000)
    va_all = np.array([corners(*(x[k] for x in random_scenes[:3])) for k in range(RANDOM_PAIRS)])
    vb_all = np.array([corners(*(x[k] for x in random_scenes[3:])) for k in range(RANDOM_PAIRS)])
    sampled = np.empty(RANDOM_PAIRS)
    for start in range(0, RANDOM_PAIRS, 32):  # the corners on every direction, in chunks
        pa = va_all[start : start + 32] @ directions.T  # (chunk, 8, directions)
        pb = vb_all[start : start + 32] @ directions.T
        overlap = np.minimum(pa.max(axis=1) - pb.min(axis=1), pb.max(axis=1) - pa.min(axis=1))
        sampled[start : start + 32] = overlap.min(axis=1)
    checked = 0
    for k in range(RANDOM_PAIRS):
        ca, Ra, ha, cb, Rb, hb = (x[k] for x in random_scenes)
        depth, _, _ = sat_minimum(ca, Ra, ha, cb, Rb, hb)
        va, vb = va_all[k], vb_all[k]
        exact = interval_overlap(va, vb, sat_axes_from_corners(va, vb)).min()
        scale = max(ha.max(), hb.max())
        assert depth == pytest.approx(exact, rel=1e-6, abs=1e-12 * scale)
        if exact >= 0.0:
            # overlapping: no direction overlaps less than the SAT depth, so the brute-force
            # minimum over the 20 000 directions and the 15 axes is the SAT depth ...
            checked += 1
            assert min(sampled[k], exact) == pytest.approx(depth, rel=1e-6, abs=1e-12 * scale)
            assert sampled[k] >= depth - 1e-12 * scale
            # ... and the sampled directions alone come close to it from above
            assert sampled[k] - depth < 0.05 * scale
        # separated: the 15 axes give a lower bound of the distance, which the sampling does not check
    assert checked > RANDOM_PAIRS // 3


def test_manifold_invariants_on_random_pairs(random_scenes):
    """Every contact's two surface points lie on the two boxes' surfaces, depths respect the
    margin and the chosen axis, and a pair has contacts exactly when no axis separates it by
    more than the margin."""
    margin = 0.02
    counts = np.zeros(5, dtype=int)
    for k in range(RANDOM_PAIRS):
        ca, Ra, ha, cb, Rb, hb = (x[k] for x in random_scenes)
        point, normal, depth, feature = contacts(ca, Ra, ha, cb, Rb, hb, margin)
        sat, _, overlaps = sat_minimum(ca, Ra, ha, cb, Rb, hb)
        scale = max(ha.max(), hb.max())
        tol = 1e-9 * scale
        counts[len(depth)] += 1
        if sat < -margin:
            assert len(depth) == 0
            continue
        if sat > tol:
            assert len(depth) >= 1  # overlapping boxes always get a contact
        if len(depth) == 0:
            continue
        assert_features_valid(feature)
        np.testing.assert_allclose(np.linalg.norm(normal, axis=1), 1.0, atol=1e-12)
        assert (normal == normal[0]).all()
        assert (depth >= -margin - tol).all()
        va, vb = corners(ca, Ra, ha), corners(cb, Rb, hb)
        n = normal[0]
        seen = oriented_overlap(va, vb, n)
        # the axis is the best one, or within the face-favouring tolerance of it
        assert seen >= sat - tol
        assert seen <= sat + FACE_REL_TOL * abs(sat) + FACE_ABS_TOL * scale + tol
        assert depth.max() <= seen + tol
        if max(np.abs(Ra.T @ n).max(), np.abs(Rb.T @ n).max()) < 1 - 1e-9:
            assert len(depth) == 1 and feature[0] == EDGE_FEATURE  # an edge–edge contact ...
            assert depth[0] == pytest.approx(seen, abs=tol)  # ... as deep as the axis overlap
        for p, d in zip(point, depth):
            for center, rotation, half, surface in ((ca, Ra, ha, p - 0.5 * d * n), (cb, Rb, hb, p + 0.5 * d * n)):
                local = rotation.T @ (surface - center)
                assert (np.abs(local) <= half + tol).all()  # inside the closed box ...
                assert (half - np.abs(local)).min() <= tol  # ... and on its surface
    assert counts[0] > 0 and counts[1] > 0 and counts[4] > 0


def test_agrees_with_fcl(random_scenes):
    fcl = pytest.importorskip("fcl")
    same_normal = 0
    colliding = 0
    for k in range(RANDOM_PAIRS):
        ca, Ra, ha, cb, Rb, hb = (x[k] for x in random_scenes)
        sat, _, _ = sat_minimum(ca, Ra, ha, cb, Rb, hb)
        scale = max(ha.max(), hb.max())
        if abs(sat) < 1e-9 * scale:
            continue  # touching: either answer is right
        point, normal, depth, feature = contacts(ca, Ra, ha, cb, Rb, hb)
        a = fcl.CollisionObject(fcl.Box(*(2 * ha)), fcl.Transform(Ra, ca))
        b = fcl.CollisionObject(fcl.Box(*(2 * hb)), fcl.Transform(Rb, cb))
        request = fcl.CollisionRequest(num_max_contacts=8, enable_contact=True)
        result = fcl.CollisionResult()
        hit = fcl.collide(a, b, request, result)
        assert (hit > 0) == (len(depth) > 0) == (sat > 0)
        if not hit:
            continue
        colliding += 1
        fcl_normal = -result.contacts[0].normal  # FCL's normal points from A into B
        fcl_depth = np.array([c.penetration_depth for c in result.contacts])
        fcl_point = np.array([c.pos for c in result.contacts])
        va, vb = corners(ca, Ra, ha), corners(cb, Rb, hb)
        if fcl_normal @ normal[0] > 1 - 1e-9:
            same_normal += 1
            # both keep the deepest point; with no reduction on either side the sets agree
            assert depth.max() == pytest.approx(fcl_depth.max(), rel=1e-9, abs=1e-12)
            if len(depth) < 4 and len(fcl_depth) < 4:
                assert same_point_sets(point, fcl_point, atol=1e-9 * scale)
        else:
            # a different choice among near-equal axes: both within the face-favouring tolerance
            band = sat + FACE_REL_TOL * abs(sat) + FACE_ABS_TOL * scale + 1e-9 * scale
            assert oriented_overlap(va, vb, normal[0]) <= band
            assert oriented_overlap(va, vb, fcl_normal) <= 1.06 * sat + 1e-9 * scale  # ODE: 5 % for edges
    assert colliding > RANDOM_PAIRS // 3
    assert same_normal >= 0.95 * colliding


# ---------------------------------------------------------------------------------------------
# through the narrow-phase dispatcher and collide()


def test_dispatcher_and_collide_use_box_box():
    from contactlab import ModelBuilder, collide
    from contactlab.collision.narrow_phase import BOX, collide_pair, empty_hull_store, supported

    assert supported(BOX, BOX)
    params = np.array([0.5, 0.5, 0.5, 0.0])
    out = (np.zeros((8, 3)), np.zeros((8, 3)), np.zeros(8), np.zeros(8, dtype=np.int64))
    count = collide_pair(
        (BOX, params, (np.array([0, 0, 0.999]), I3)), (BOX, params, (np.zeros(3), I3)), 0.0, empty_hull_store(), out, 0
    )
    assert count == 4
    np.testing.assert_allclose(out[1][:4], np.tile([0.0, 0.0, 1.0], (4, 1)))

    builder = ModelBuilder()
    builder.add_body("box", half_extents=(0.5, 0.5, 0.5), mass=1, position=(0, 0, 0))
    builder.add_body("box", half_extents=(0.2, 0.3, 0.1), mass=1, position=(0.1, 0, 0.599))
    model = builder.finalize()
    c = collide(model, model.state())
    assert c.count == 4
    assert (c.body_a == 0).all() and (c.body_b == 1).all()
    np.testing.assert_allclose(c.normal, np.tile([0.0, 0.0, -1.0], (4, 1)), atol=1e-15)  # B (on top) into A
    np.testing.assert_allclose(c.depth, 0.001, rtol=1e-9)
    assert len(set(c.feature_id.tolist())) == 4
