"""Capsule contacts: hand-computed configurations, role swaps, randomized cross-checks against
independent references, and feature persistence.

References used by the randomized checks (each on ≥ 2000 random configurations per pair):

* capsule–plane: FCL's capsule–halfspace depth for overlapping pairs; for separated ones the
  gap of 101 points sampled along the segment (the signed distance is linear along it), since
  ``fcl.distance`` against an ``fcl.Plane`` or ``fcl.Halfspace`` crashes python-fcl 0.7.0.11
  (segmentation fault) and a large thin box would go through FCL's inexact GJK.
* sphere–capsule: FCL (``fcl.distance`` when separated, ``fcl.collide`` depth when
  overlapping); FCL has closed forms here and agrees to round-off.
* capsule–capsule: ``fcl.distance`` for separated pairs (closed form, agrees to round-off).
  FCL's *penetration depth* for capsule–capsule (libccd's EPA) is not the minimum
  translation: for two crossing capsules it often returns a larger, non-minimal one (see
  ``test_fcl_capsule_capsule_depth_is_not_minimal``), so overlapping pairs are compared with
  ``r_A + r_B − min_s dist(p_A(s), segment_B)``, minimized by golden-section search (the
  distance is convex in s), and one-sidedly with FCL (its depth is never smaller than ours,
  beyond 1e-5 m: libccd's own tolerance).
* capsule–box: FCL's GJK distance for capsule–box is only good to ~3e-4 m here and its EPA
  depth is off by up to ~1 m (median ~1e-2 m) on these configurations, so: segment outside
  the box → ``r − min_s dist(p(s), box)`` (golden-section search); segment entering the box
  → ``r +`` the segment–box minimum translation distance from Qhull: the distance from the
  origin to the nearest facet of the hull of ``box corners − segment ends`` (the Minkowski
  difference). Independently of both,
  the support-function overlap ``max_B d·x − min_A d·x`` over 20 000 directions is never
  below our depth, and along our normal it equals our depth (so our depth is the minimum over
  directions, up to sampling). FCL's distance is checked too, at 2e-3 m.
"""

import numpy as np
import pytest
from conftest import random_rotations

from contactlab.collision.capsule import (
    PARALLEL_SIN,
    capsule_capsule,
    capsule_plane,
    segment_closest_parameters,
    sphere_capsule,
)
from contactlab.collision.capsule_box import CAPSULE_BOX_CROSS_FEATURE, CAPSULE_BOX_EDGE_FEATURE, capsule_box
from contactlab.collision.segment_box import segment_box_closest

I3 = np.eye(3)
RANDOM_COUNT = 2000
MARGIN_ALL = 100.0  # a margin that keeps every contact, to see the deepest one of separated pairs


def rot_x(angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


ALONG_X = rot_y(np.pi / 2)  # body z → world +x
ALONG_Y = rot_x(-np.pi / 2)  # body z → world +y


def random_unit(rng, count):
    v = rng.normal(size=(count, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def fibonacci_sphere(count):
    k = np.arange(count) + 0.5
    z = 1 - 2 * k / count
    r = np.sqrt(1 - z * z)
    phi = np.pi * (1 + 5**0.5) * k
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def _f(x):
    return np.ascontiguousarray(x, dtype=np.float64)


SHAPE_ARGUMENTS = {"sphere": 2, "capsule": 4, "box": 3, "plane": 1}  # run's flat arguments per shape


def _shape(kind, args):
    """One shape as the pair routines take it, from run's flat arguments: a sphere (centre,
    radius), a capsule ((centre, rotation), radius, half length), a box ((centre, rotation),
    half extents), a plane its (4,) array."""
    if kind == "capsule":
        return ((args[0], args[1]), args[2], args[3])
    if kind == "box":
        return ((args[0], args[1]), args[2])
    if kind == "sphere":
        return (args[0], args[1])
    return args[0]


def _shapes(function, args):
    """The arguments of pair routine ``function`` (named ``shapeA_shapeB``) as its two shapes."""
    kind_a, kind_b = function.__name__.split("_")
    split = SHAPE_ARGUMENTS[kind_a]
    return _shape(kind_a, args[:split]), _shape(kind_b, args[split:])


def run(function, *args, margin=0.0):
    """Call a pair function into NaN-filled buffers, written from slot 3; return the contacts."""
    slot = 3
    point = np.full((slot + 4, 3), np.nan)
    normal = np.full((slot + 4, 3), np.nan)
    depth = np.full(slot + 4, np.nan)
    feature = np.full(slot + 4, -1, dtype=np.int64)
    args = tuple(_f(a) if isinstance(a, (np.ndarray, list, tuple)) else float(a) for a in args)
    args = _shapes(function, args)
    count = function(*args, float(margin), (point, normal, depth, feature), slot)
    assert 0 <= count <= 2
    assert np.isnan(depth[:slot]).all() and np.isnan(depth[slot + count :]).all()  # nothing outside
    s = slice(slot, slot + count)
    if count:
        assert (np.abs(np.sqrt((normal[s] ** 2).sum(axis=1)) - 1.0) < 1e-12).all()  # unit normals
        assert (depth[s] >= -margin).all()
        assert ((feature[s] >= 0) & (feature[s] <= 255)).all()
        assert count == 1 or feature[slot] != feature[slot + 1]
    return point[s], normal[s], depth[s], feature[s]


def deepest(contacts):
    point, normal, depth, feature = contacts
    k = int(np.argmax(depth))
    return point[k], normal[k], depth[k], feature[k]


# signed distance functions of the shapes (for "point is midway between the surfaces")


def sdf_capsule(x, center, rotation, radius, half_length):
    axis = rotation[:, 2]
    s = np.clip((x - center) @ axis, -half_length, half_length)
    return np.linalg.norm(x - center - s * axis) - radius


def sdf_box(x, center, rotation, half_extents):
    local = rotation.T @ (x - center)
    q = np.abs(local) - half_extents
    return np.linalg.norm(np.maximum(q, 0.0)) + min(q.max(), 0.0)


def assert_midway(point, normal, depth, sdf_a, sdf_b, atol=1e-9):
    """A's surface at point − δ/2 n, B's at point + δ/2 n (deepest contact of a pair)."""
    assert abs(sdf_a(point - 0.5 * depth * normal)) < atol
    assert abs(sdf_b(point + 0.5 * depth * normal)) < atol


# ---------------------------------------------------------------------------------------------
# (1) hand-computed configurations
# ---------------------------------------------------------------------------------------------

GROUND = np.array([0.0, 0.0, 1.0, 0.0])


def test_capsule_lying_flat_on_a_plane_gets_two_equal_contacts():
    point, normal, depth, feature = run(capsule_plane, [0, 0, 0.09], ALONG_X, 0.1, 0.5, GROUND)
    assert len(depth) == 2
    np.testing.assert_allclose(depth, [0.01, 0.01], atol=1e-15)
    np.testing.assert_allclose(normal, [[0, 0, 1], [0, 0, 1]], atol=1e-15)
    order = np.argsort(point[:, 0])
    np.testing.assert_allclose(point[order], [[-0.5, 0, -0.005], [0.5, 0, -0.005]], atol=1e-15)
    assert feature[order].tolist() == [0, 1]  # 0 = the −z end (here at x = −0.5)


def test_capsule_standing_on_a_plane_gets_one_contact_at_its_lower_end():
    point, normal, depth, feature = run(capsule_plane, [0.3, -0.2, 0.55], I3, 0.1, 0.5, GROUND)
    assert len(depth) == 1
    np.testing.assert_allclose(depth, [0.05], atol=1e-15)
    np.testing.assert_allclose(normal[0], [0, 0, 1])
    np.testing.assert_allclose(point[0], [0.3, -0.2, -0.025], atol=1e-15)  # between −0.05 and 0
    assert feature.tolist() == [0]
    # upside down: the +z end is the lower one
    _, _, _, feature = run(capsule_plane, [0.3, -0.2, 0.55], rot_x(np.pi), 0.1, 0.5, GROUND)
    assert feature.tolist() == [1]


def test_capsule_plane_tilted_and_speculative():
    plane = np.array([0.0, 0.6, 0.8, 0.5])  # unit normal, offset 0.5
    R = rot_x(0.3)
    center, radius, half = np.array([0.1, 0.2, 0.7]), 0.15, 0.4
    ends = [center - half * R[:, 2], center + half * R[:, 2]]
    expected = [radius - (e @ plane[:3] - plane[3]) for e in ends]
    point, normal, depth, feature = run(capsule_plane, center, R, radius, half, plane, margin=1.0)
    assert len(depth) == 2
    np.testing.assert_allclose(depth[np.argsort(feature)], expected, atol=1e-14)
    for p, d, f in zip(point, depth, feature):
        np.testing.assert_allclose(p, ends[f] - plane[:3] * (radius - 0.5 * d), atol=1e-14)
    # a gap beyond the margin: nothing; within it: a contact of negative depth
    assert len(run(capsule_plane, [0, 0, 0.15], ALONG_X, 0.1, 0.5, GROUND, margin=0.04)[2]) == 0
    _, _, depth, _ = run(capsule_plane, [0, 0, 0.15], ALONG_X, 0.1, 0.5, GROUND, margin=0.06)
    np.testing.assert_allclose(depth, [-0.05, -0.05], atol=1e-15)


def test_sphere_on_capsule_side_and_cap():
    # above the middle of a capsule lying along x
    point, normal, depth, feature = run(sphere_capsule, [0.1, 0, 0.25], 0.1, [0, 0, 0], ALONG_X, 0.2, 0.5)
    assert len(depth) == 1 and feature.tolist() == [0]
    np.testing.assert_allclose(depth, [0.05], atol=1e-15)
    np.testing.assert_allclose(normal[0], [0, 0, 1], atol=1e-15)
    np.testing.assert_allclose(point[0], [0.1, 0, 0.175], atol=1e-15)
    # beyond the +x cap, on the axis: sphere against the end's sphere
    point, normal, depth, feature = run(sphere_capsule, [0.75, 0, 0], 0.1, [0, 0, 0], ALONG_X, 0.2, 0.5)
    np.testing.assert_allclose(depth, [0.05], atol=1e-15)
    np.testing.assert_allclose(normal[0], [1, 0, 0], atol=1e-15)
    np.testing.assert_allclose(point[0], [0.675, 0, 0], atol=1e-15)
    # a particle (radius 0) touching the cap diagonally
    c = np.array([0.5, 0.0, 0.0]) + 0.19 * np.array([0.6, 0.0, 0.8])
    point, normal, depth, _ = run(sphere_capsule, c, 0.0, [0, 0, 0], ALONG_X, 0.2, 0.5)
    np.testing.assert_allclose(depth, [0.01], atol=1e-15)
    np.testing.assert_allclose(normal[0], [0.6, 0, 0.8], atol=1e-15)
    np.testing.assert_allclose(point[0], [0.5, 0, 0] + 0.195 * np.array([0.6, 0, 0.8]), atol=1e-15)


def test_sphere_centre_on_the_capsule_segment_is_pushed_out_sideways():
    for c in ([0.2, 0, 0], [0.5, 0, 0]):  # inside the segment, on its end
        point, normal, depth, _ = run(sphere_capsule, c, 0.1, [0, 0, 0], ALONG_X, 0.2, 0.5)
        np.testing.assert_allclose(depth, [0.3], atol=1e-15)  # r_A + r_B
        assert abs(normal[0] @ [1, 0, 0]) < 1e-15  # perpendicular to the axis
        assert np.isfinite(point).all()


def test_parallel_capsules_side_by_side_get_two_contacts():
    for rotation_b in (ALONG_X, rot_y(-np.pi / 2)):  # same and opposite direction
        point, normal, depth, feature = run(
            capsule_capsule, [0, 0, 0.35], ALONG_X, 0.2, 0.5, [0, 0, 0], rotation_b, 0.2, 0.5
        )
        assert len(depth) == 2
        np.testing.assert_allclose(depth, [0.05, 0.05], atol=1e-15)
        np.testing.assert_allclose(normal, [[0, 0, 1], [0, 0, 1]], atol=1e-15)
        order = np.argsort(feature)
        assert feature[order].tolist() == [1, 2]
        np.testing.assert_allclose(point[order], [[-0.5, 0, 0.175], [0.5, 0, 0.175]], atol=1e-15)
    # shifted along the axis: the contacts sit at the ends of the overlap of the two
    point, normal, depth, feature = run(
        capsule_capsule, [0.3, 0, 0.35], ALONG_X, 0.2, 0.5, [0, 0, 0], ALONG_X, 0.2, 0.5
    )
    order = np.argsort(feature)
    np.testing.assert_allclose(point[order], [[-0.2, 0, 0.175], [0.5, 0, 0.175]], atol=1e-15)
    np.testing.assert_allclose(depth, [0.05, 0.05], atol=1e-15)
    # a short capsule on a long one: the overlap is the short one
    point, _, depth, _ = run(capsule_capsule, [1.0, 0, 0.35], ALONG_X, 0.2, 0.25, [0, 0, 0], ALONG_X, 0.2, 2.0)
    np.testing.assert_allclose(np.sort(point[:, 0]), [0.75, 1.25], atol=1e-15)


def test_nearly_parallel_capsules_keep_two_contacts_and_the_exact_depth():
    """Tilted by less than PARALLEL_SIN: still 2 contacts; the deeper one has the exact depth
    r_A + r_B − distance, the other the depth along the same normal."""
    tilt = 0.3 * PARALLEL_SIN
    R = rot_y(np.pi / 2 + tilt)
    point, normal, depth, feature = run(capsule_capsule, [0, 0, 0.35], R, 0.2, 0.5, [0, 0, 0], ALONG_X, 0.2, 0.5)
    assert len(depth) == 2
    # the +z end is the lower one: its contact is the closest point, normal +z; the −z end's
    # depth is measured along the same normal
    np.testing.assert_allclose(normal, [[0, 0, 1], [0, 0, 1]], atol=1e-15)
    np.testing.assert_allclose(depth.max(), 0.4 - (0.35 - 0.5 * np.sin(tilt)), atol=1e-14)
    s = point[:, 0] / np.cos(tilt)  # A's parameter at each contact
    np.testing.assert_allclose(depth, 0.4 - (0.35 - s * np.sin(tilt)), atol=1e-14)
    assert feature[np.argmax(depth)] == 2
    # skew over B (turned about z): the closest point is in the middle, both ends get its depth
    R = rot_z(tilt) @ ALONG_X
    point, normal, depth, feature = run(capsule_capsule, [0, 0, 0.35], R, 0.2, 0.5, [0, 0, 0], ALONG_X, 0.2, 0.5)
    assert sorted(feature.tolist()) == [1, 2]
    np.testing.assert_allclose(depth, [0.05, 0.05], atol=1e-14)
    np.testing.assert_allclose(normal, [[0, 0, 1], [0, 0, 1]], atol=1e-14)
    # tilted beyond the tolerance: a single contact
    R = rot_y(np.pi / 2 + 3 * PARALLEL_SIN)
    _, _, depth, feature = run(capsule_capsule, [0, 0, 0.35], R, 0.2, 0.5, [0, 0, 0], ALONG_X, 0.2, 0.5)
    assert feature.tolist() == [0]


def test_crossed_capsules_get_one_contact():
    point, normal, depth, feature = run(
        capsule_capsule, [0.1, 0.2, 0.35], ALONG_Y, 0.2, 0.5, [0, 0, 0], ALONG_X, 0.2, 0.5
    )
    assert len(depth) == 1 and feature.tolist() == [0]
    np.testing.assert_allclose(depth, [0.05], atol=1e-15)
    np.testing.assert_allclose(normal[0], [0, 0, 1], atol=1e-15)
    np.testing.assert_allclose(point[0], [0.1, 0, 0.175], atol=1e-15)


def test_crossing_segments_and_coincident_capsules():
    # segments intersect: depth = r_A + r_B, along the common normal (⊥ both axes)
    _, normal, depth, _ = run(capsule_capsule, [0, 0, 0], ALONG_Y, 0.2, 0.5, [0, 0, 0], ALONG_X, 0.3, 0.5)
    np.testing.assert_allclose(depth, [0.5], atol=1e-15)
    np.testing.assert_allclose(np.abs(normal[0]), [0, 0, 1], atol=1e-15)
    # crossing but centres apart along the common normal direction: the normal points B → A
    _, normal, depth, _ = run(capsule_capsule, [0, 0.3, 1e-14], ALONG_Y, 0.2, 0.5, [0, 0, 0], ALONG_X, 0.3, 0.5)
    np.testing.assert_allclose(normal[0], [0, 0, 1], atol=1e-12)
    # identical capsules at the same place: finite, depth r_A + r_B, normal ⊥ axis
    point, normal, depth, _ = run(capsule_capsule, [0, 0, 0], ALONG_X, 0.2, 0.5, [0, 0, 0], ALONG_X, 0.2, 0.5)
    np.testing.assert_allclose(depth, 0.4, atol=1e-15)
    assert np.isfinite(point).all() and (np.abs(normal @ [1, 0, 0]) < 1e-15).all()


def test_collinear_capsules_end_to_end_get_one_contact():
    point, normal, depth, feature = run(capsule_capsule, [1.35, 0, 0], ALONG_X, 0.2, 0.5, [0, 0, 0], ALONG_X, 0.2, 0.5)
    assert len(depth) == 1 and feature.tolist() == [0]
    np.testing.assert_allclose(depth, [0.05], atol=1e-15)
    np.testing.assert_allclose(normal[0], [1, 0, 0], atol=1e-15)
    np.testing.assert_allclose(point[0], [0.675, 0, 0], atol=1e-15)


def test_zero_length_capsules():
    # two spheres (half length 0)
    point, normal, depth, _ = run(capsule_capsule, [0, 0.3, 0], I3, 0.2, 0.0, [0, 0, 0], ALONG_X, 0.15, 0.0)
    np.testing.assert_allclose(depth, [0.05], atol=1e-15)
    np.testing.assert_allclose(normal[0], [0, 1, 0], atol=1e-15)
    np.testing.assert_allclose(point[0], [0, 0.125, 0], atol=1e-15)
    point, normal, depth, _ = run(capsule_plane, [0, 0, 0.05], ALONG_X, 0.1, 0.0, GROUND)
    assert len(depth) == 1
    point, normal, depth, _ = run(capsule_box, [0, 0, 1.05], I3, 0.1, 0.0, [0, 0, 0], I3, [1, 1, 1])
    np.testing.assert_allclose(depth, [0.05], atol=1e-15)


BOX_HALF = np.array([1.0, 1.0, 0.5])


def test_capsule_lying_flat_on_a_box_face_gets_two_contacts():
    point, normal, depth, feature = run(capsule_box, [0, 0.3, 0.65], ALONG_X, 0.2, 0.5, [0, 0, 0], I3, BOX_HALF)
    assert len(depth) == 2
    np.testing.assert_allclose(depth, [0.05, 0.05], atol=1e-15)
    np.testing.assert_allclose(normal, [[0, 0, 1], [0, 0, 1]], atol=1e-15)
    order = np.argsort(feature)
    assert feature[order].tolist() == [10, 11]  # face +z (2·2+1 = 5): 2·5 + end
    np.testing.assert_allclose(point[order], [[-0.5, 0.3, 0.475], [0.5, 0.3, 0.475]], atol=1e-15)
    # on a rotated, moved box (its +y face up)
    Rb = rot_x(np.pi / 2)  # body y → world z
    point2, normal2, depth2, feature2 = run(
        capsule_box, [2, 0.3, 1.65], ALONG_X, 0.2, 0.5, [2, 0, 1], Rb, [1.0, 0.5, 1.0]
    )
    np.testing.assert_allclose(depth2, [0.05, 0.05], atol=1e-14)
    np.testing.assert_allclose(normal2, [[0, 0, 1], [0, 0, 1]], atol=1e-15)
    assert sorted(feature2.tolist()) == [6, 7]  # face +y (2·1+1 = 3)


def test_capsule_overhanging_a_box_edge_keeps_its_end_and_the_edge_point():
    point, normal, depth, feature = run(capsule_box, [0.8, 0, 0.65], ALONG_X, 0.2, 0.5, [0, 0, 0], I3, BOX_HALF)
    assert len(depth) == 2
    np.testing.assert_allclose(depth, [0.05, 0.05], atol=1e-15)
    order = np.argsort(point[:, 0])
    np.testing.assert_allclose(point[order], [[0.3, 0, 0.475], [1.0, 0, 0.475]], atol=1e-15)
    assert feature[order].tolist() == [10, 11]


def test_capsule_end_poking_into_a_box_gets_one_contact():
    # the end's sphere dips into the top face (segment outside)
    point, normal, depth, feature = run(capsule_box, [0.2, 0.1, 1.15], I3, 0.2, 0.5, [0, 0, 0], I3, BOX_HALF)
    assert len(depth) == 1 and feature.tolist() == [10]
    np.testing.assert_allclose(depth, [0.05], atol=1e-15)
    np.testing.assert_allclose(normal[0], [0, 0, 1], atol=1e-15)
    np.testing.assert_allclose(point[0], [0.2, 0.1, 0.475], atol=1e-15)
    # the segment itself enters the box by 0.1: depth r + 0.1, pushed out through the top
    point, normal, depth, feature = run(capsule_box, [0.2, 0.1, 0.9], I3, 0.2, 0.5, [0, 0, 0], I3, BOX_HALF)
    assert len(depth) == 1 and feature.tolist() == [10]
    np.testing.assert_allclose(depth, [0.3], atol=1e-15)
    np.testing.assert_allclose(normal[0], [0, 0, 1], atol=1e-15)
    np.testing.assert_allclose(point[0], [0.2, 0.1, 0.35], atol=1e-15)  # between 0.2 and 0.5
    # tilted, poking in with its −z end through the −x face
    R = rot_y(np.pi / 2 + 0.4)  # body z mostly along +x
    center = np.array([-1.5, 0.2, 0.1])
    point, normal, depth, feature = run(capsule_box, center, R, 0.2, 0.6, [0, 0, 0], I3, BOX_HALF)
    end = center + 0.6 * R[:, 2]  # the +z end is inside the box
    assert len(depth) == 1
    assert feature.tolist() == [2 * 0 + 1]  # face −x (0), the +z end's side
    np.testing.assert_allclose(normal[0], [-1, 0, 0], atol=1e-15)
    np.testing.assert_allclose(depth[0], 0.2 - sdf_box(end, np.zeros(3), I3, BOX_HALF), atol=1e-14)


def test_capsule_along_a_box_edge_and_across_a_corner():
    # parallel to the box's x edge at (y, z) = (1, 0.5), diagonally above it
    point, normal, depth, feature = run(capsule_box, [0, 1.1, 0.6], ALONG_X, 0.2, 0.5, [0, 0, 0], I3, BOX_HALF)
    assert len(depth) == 2  # a line contact alongside the edge
    assert sorted(feature.tolist()) == [CAPSULE_BOX_EDGE_FEATURE + 2 * 3, CAPSULE_BOX_EDGE_FEATURE + 2 * 3 + 1]
    np.testing.assert_allclose(depth, [0.2 - np.sqrt(0.02)] * 2, atol=1e-15)
    np.testing.assert_allclose(normal, [[0, np.sqrt(0.5), np.sqrt(0.5)]] * 2, atol=1e-15)
    np.testing.assert_allclose(np.sort(point[:, 0]), [-0.5, 0.5], atol=1e-15)
    # standing above the corner (1, 1, 0.5), offset diagonally: 1 contact
    point, normal, depth, feature = run(capsule_box, [1.1, 1.1, 1.1], I3, 0.2, 0.5, [0, 0, 0], I3, BOX_HALF)
    assert len(depth) == 1 and feature[0] in (0 * 2 + 2, 1 * 4 + 2, 2 * 4 + 2)  # the −z end of face +x, +y or +z
    np.testing.assert_allclose(depth, [0.2 - np.sqrt(0.03)], atol=1e-15)
    np.testing.assert_allclose(normal[0], np.full(3, np.sqrt(1 / 3)), atol=1e-15)
    np.testing.assert_allclose(point[0], [1, 1, 0.5] + 0.5 * (np.sqrt(0.03) - 0.2) * normal[0], atol=1e-15)


def test_segment_cutting_a_box_edge_uses_the_edge_axis():
    """A horizontal capsule crossing the vertical edge (1, 1, z) of a cube diagonally: the
    least overlap is along (1, 1, 0)/√2, an axis × edge direction, not a face normal."""
    u = np.array([1.0, -1.0, 0.0]) / np.sqrt(2)
    R = np.column_stack([np.array([0, 0, 1.0]), np.cross(u, [0, 0, 1.0]), u])
    R = np.column_stack([np.cross(R[:, 1], u), R[:, 1], u])
    center, radius = np.array([0.95, 0.95, 0.0]), 0.1
    point, normal, depth, feature = run(capsule_box, center, R, radius, 0.5, [0, 0, 0], I3, [1.0, 1.0, 1.0])
    assert len(depth) == 1 and feature.tolist() == [CAPSULE_BOX_CROSS_FEATURE]
    overlap = np.sqrt(2) - 1.9 / np.sqrt(2)
    np.testing.assert_allclose(depth, [radius + overlap], atol=1e-14)
    np.testing.assert_allclose(normal[0], [np.sqrt(0.5), np.sqrt(0.5), 0], atol=1e-14)
    surface_a = center - radius * normal[0]
    np.testing.assert_allclose(point[0], 0.5 * (surface_a + [1, 1, 0]), atol=1e-14)


def test_capsule_inside_a_box_leaves_through_the_nearest_face():
    point, normal, depth, feature = run(capsule_box, [0.1, 0.2, 0.3], ALONG_Y, 0.1, 0.4, [0, 0, 0], I3, BOX_HALF)
    # overlaps: x: 1 − 0.1 = 0.9, y: 0.4 + 1 − 0.2 = 1.2, z: 0.5 − 0.3 = 0.2 → +z face
    np.testing.assert_allclose(depth, [0.3, 0.3], atol=1e-15)
    np.testing.assert_allclose(normal, [[0, 0, 1], [0, 0, 1]], atol=1e-15)
    assert sorted(feature.tolist()) == [10, 11]


def test_speculative_capsule_box_contacts():
    args = ([0, 0, 0.75], ALONG_X, 0.2, 0.5, [0, 0, 0], I3, BOX_HALF)  # gap 0.05
    assert len(run(capsule_box, *args, margin=0.04)[2]) == 0
    _, _, depth, _ = run(capsule_box, *args, margin=0.06)
    np.testing.assert_allclose(depth, [-0.05, -0.05], atol=1e-15)


def test_segment_closest_parameters_edge_cases():
    x, y = np.array([1.0, 0, 0]), np.array([0, 1.0, 0])
    z = np.zeros(3)
    assert segment_closest_parameters(z, x, 1.0, _f([0.3, 0.5, 1]), y, 1.0) == pytest.approx((0.3, -0.5))
    assert segment_closest_parameters(z, x, 1.0, _f([0.3, 5, 1]), y, 1.0) == pytest.approx((0.3, -1.0))
    assert segment_closest_parameters(z, x, 0.0, _f([0.3, 5, 1]), y, 0.0) == (0.0, 0.0)
    s, t = segment_closest_parameters(z, x, 1.0, _f([0.5, 1, 0]), x, 1.0)  # parallel: A's point nearest B's centre
    assert (s, t) == pytest.approx((0.5, 0.0))
    s, distance2 = segment_box_closest(_f([0, 0, 2.0]), x, 3.0, _f([1, 1, 1]))
    assert distance2 == pytest.approx(1.0) and abs(s) <= 1.0


# ---------------------------------------------------------------------------------------------
# (2) swapping roles
# ---------------------------------------------------------------------------------------------


def test_sphere_capsule_equals_capsule_capsule_with_zero_half_length():
    rng = np.random.default_rng(21)
    rotations = random_rotations(rng, 400)
    for k in range(200):
        center_a = rng.normal(size=3) * 0.6
        ra, rb, hb = rng.uniform(0.0, 0.4), rng.uniform(0.05, 0.4), rng.uniform(0.0, 1.0)
        Rb = rotations[k]
        p1, n1, d1, _ = run(sphere_capsule, center_a, ra, [0, 0, 0], Rb, rb, hb, margin=MARGIN_ALL)
        p2, n2, d2, _ = run(
            capsule_capsule, center_a, rotations[200 + k], ra, 0.0, [0, 0, 0], Rb, rb, hb, margin=MARGIN_ALL
        )
        assert len(d1) == len(d2) == 1
        np.testing.assert_allclose(d2, d1, atol=1e-13)
        np.testing.assert_allclose(n2, n1, atol=1e-12)
        np.testing.assert_allclose(p2, p1, atol=1e-13)
        # and with the roles swapped: capsule A against a sphere B (capsule of length 0)
        p3, n3, d3, _ = run(
            capsule_capsule, [0, 0, 0], Rb, rb, hb, center_a, rotations[200 + k], ra, 0.0, margin=MARGIN_ALL
        )
        np.testing.assert_allclose(d3, d1, atol=1e-13)
        np.testing.assert_allclose(n3, -n1, atol=1e-12)
        np.testing.assert_allclose(p3, p1, atol=1e-13)


def test_capsule_capsule_swapped_flips_the_normal_only():
    rng = np.random.default_rng(22)
    rotations = random_rotations(rng, 600)
    for k in range(300):
        ra, rb = rng.uniform(0.05, 0.4, 2)
        ha, hb = rng.uniform(0.0, 1.0, 2)
        center_a = rng.normal(size=3) * 0.8
        Ra, Rb = rotations[k], rotations[300 + k]
        a = run(capsule_capsule, center_a, Ra, ra, ha, [0, 0, 0], Rb, rb, hb, margin=MARGIN_ALL)
        b = run(capsule_capsule, [0, 0, 0], Rb, rb, hb, center_a, Ra, ra, ha, margin=MARGIN_ALL)
        assert len(a[2]) == len(b[2]) == 1  # random axes are never parallel
        np.testing.assert_allclose(b[2], a[2], atol=1e-13)
        np.testing.assert_allclose(b[1], -a[1], atol=1e-9)
        np.testing.assert_allclose(b[0], a[0], atol=1e-9)


def test_parallel_pair_swapped_gives_the_same_contact_line():
    a = run(capsule_capsule, [0.3, 0.1, 0.35], ALONG_X, 0.2, 0.5, [0, 0, 0], ALONG_X, 0.25, 0.7)
    b = run(capsule_capsule, [0, 0, 0], ALONG_X, 0.25, 0.7, [0.3, 0.1, 0.35], ALONG_X, 0.2, 0.5)
    np.testing.assert_allclose(np.sort(b[0][:, 0]), np.sort(a[0][:, 0]), atol=1e-15)
    np.testing.assert_allclose(b[2], a[2], atol=1e-15)
    np.testing.assert_allclose(b[1], -a[1], atol=1e-15)


def test_zero_length_capsule_matches_the_sphere_routines():
    """A capsule of half length 0 against a plane / a box is the sphere of narrow_phase."""
    from contactlab.collision.narrow_phase import sphere_box, sphere_plane

    rng = np.random.default_rng(23)
    rotations = random_rotations(rng, 400)
    half = np.array([0.7, 0.4, 0.2])
    for k in range(200):
        center = rng.normal(size=3) * 0.8
        radius = rng.uniform(0.05, 0.5)
        plane = np.r_[random_unit(rng, 1)[0], rng.uniform(-0.5, 0.5)]
        a = run(capsule_plane, center, rotations[k], radius, 0.0, plane, margin=MARGIN_ALL)
        b = run(sphere_plane, center, radius, plane, margin=MARGIN_ALL)
        for x, y in zip(a, b):
            np.testing.assert_allclose(x, y, atol=1e-13)
        a = run(
            capsule_box, center, rotations[k], radius, 0.0, [0.1, 0, 0], rotations[200 + k], half, margin=MARGIN_ALL
        )
        b = run(sphere_box, center, radius, [0.1, 0, 0], rotations[200 + k], half, margin=MARGIN_ALL)
        np.testing.assert_allclose(a[2], b[2], atol=1e-13)
        np.testing.assert_allclose(a[1], b[1], atol=1e-12)
        np.testing.assert_allclose(a[0], b[0], atol=1e-12)


# ---------------------------------------------------------------------------------------------
# (3) randomized cross-checks against independent implementations
# ---------------------------------------------------------------------------------------------


def golden_section_min(function, lo, hi, iterations=110):
    """Minimum of convex functions on [lo, hi] (arrays, one problem per entry), vectorized."""
    invphi = (np.sqrt(5.0) - 1.0) / 2.0
    lo, hi = lo.astype(float).copy(), hi.astype(float).copy()
    c = hi - invphi * (hi - lo)
    d = lo + invphi * (hi - lo)
    fc, fd = function(c), function(d)
    for _ in range(iterations):
        left = fc < fd  # the minimum is in [lo, d]
        hi = np.where(left, d, hi)
        lo = np.where(left, lo, c)
        new = np.where(left, hi - invphi * (hi - lo), lo + invphi * (hi - lo))
        fnew = function(new)
        c, d, fc, fd = (
            np.where(left, new, d),
            np.where(left, c, new),
            np.where(left, fnew, fd),
            np.where(left, fc, fnew),
        )
    return np.minimum.reduce([fc, fd, function(lo), function(hi)])


def random_capsules(rng, count):
    """Radii in [0.02, 0.5] m, half lengths in [0, 1] m (5 % exactly 0), uniform orientations."""
    radius = rng.uniform(0.02, 0.5, count)
    half = rng.uniform(0.0, 1.0, count)
    half[rng.random(count) < 0.05] = 0.0
    return radius, half, random_rotations(rng, count)


def placed(rng, count, reach):
    """Centres in a random direction at up to 1.15 × ``reach`` (about half of them overlap)."""
    return random_unit(rng, count) * (rng.uniform(0.0, 1.15, count) * reach)[:, None]


def fcl_signed_depth(fcl, geometry_a, rotation_a, center_a, geometry_b, rotation_b, center_b):
    """(depth, collided): FCL's deepest penetration if the shapes collide, else −distance."""
    a = fcl.CollisionObject(geometry_a, fcl.Transform(rotation_a, center_a))
    b = fcl.CollisionObject(geometry_b, fcl.Transform(rotation_b, center_b))
    result = fcl.CollisionResult()
    if fcl.collide(a, b, fcl.CollisionRequest(num_max_contacts=8, enable_contact=True), result):
        return max(c.penetration_depth for c in result.contacts), True
    return -fcl.distance(a, b, fcl.DistanceRequest(), fcl.DistanceResult()), False


def test_capsule_plane_random_against_fcl_halfspace():
    fcl = pytest.importorskip("fcl")
    rng = np.random.default_rng(31)
    radius, half, rotation = random_capsules(rng, RANDOM_COUNT)
    normal = random_unit(rng, RANDOM_COUNT)
    offset = rng.uniform(-1.0, 1.0, RANDOM_COUNT)
    center = rng.normal(size=(RANDOM_COUNT, 3)) * 0.8
    samples = np.linspace(-1.0, 1.0, 101)
    overlapping = 0
    for k in range(RANDOM_COUNT):
        plane = np.r_[normal[k], offset[k]]
        point, n, depth, feature = run(
            capsule_plane, center[k], rotation[k], radius[k], half[k], plane, margin=MARGIN_ALL
        )
        assert len(depth) == (2 if half[k] > 0 else 1)
        # each end's contact: its own depth
        ends = center[k] + np.outer([-half[k], half[k]], rotation[k][:, 2])
        np.testing.assert_allclose(depth, radius[k] - (ends[feature] @ normal[k] - offset[k]), atol=1e-13)
        best = depth.max()
        gap = (center[k] + np.outer(samples * half[k], rotation[k][:, 2])) @ normal[k] - offset[k] - radius[k]
        assert abs(-best - gap.min()) < 1e-12
        if best > 0:
            overlapping += 1
            a = fcl.CollisionObject(fcl.Capsule(radius[k], 2 * half[k]), fcl.Transform(rotation[k], center[k]))
            b = fcl.CollisionObject(fcl.Halfspace(normal[k], offset[k]), fcl.Transform())
            result = fcl.CollisionResult()
            assert fcl.collide(a, b, fcl.CollisionRequest(num_max_contacts=8, enable_contact=True), result)
            reference = max(c.penetration_depth for c in result.contacts)
            assert abs(best - reference) <= max(1e-7, 1e-6 * reference)
    assert overlapping > RANDOM_COUNT // 5


def test_sphere_capsule_random_against_fcl():
    fcl = pytest.importorskip("fcl")
    rng = np.random.default_rng(32)
    radius_b, half_b, rotation_b = random_capsules(rng, RANDOM_COUNT)
    radius_a = rng.uniform(0.0, 0.5, RANDOM_COUNT)
    center_a = placed(rng, RANDOM_COUNT, radius_a + radius_b + half_b)
    collided = 0
    for k in range(RANDOM_COUNT):
        contacts = run(
            sphere_capsule,
            center_a[k],
            radius_a[k],
            [0, 0, 0],
            rotation_b[k],
            radius_b[k],
            half_b[k],
            margin=MARGIN_ALL,
        )
        point, normal, depth, _ = deepest(contacts)
        assert_midway(
            point,
            normal,
            depth,
            lambda x: np.linalg.norm(x - center_a[k]) - radius_a[k],
            lambda x: sdf_capsule(x, np.zeros(3), rotation_b[k], radius_b[k], half_b[k]),
        )
        if radius_a[k] == 0.0:
            continue
        reference, hit = fcl_signed_depth(
            fcl,
            fcl.Sphere(radius_a[k]),
            I3,
            center_a[k],
            fcl.Capsule(radius_b[k], 2 * half_b[k]),
            rotation_b[k],
            np.zeros(3),
        )
        collided += hit
        if hit:
            assert abs(depth - reference) <= max(1e-7, 1e-6 * reference)
        else:
            assert abs(depth - reference) <= 1e-6
    assert collided > RANDOM_COUNT // 5


def test_capsule_capsule_random_against_fcl_and_golden_section():
    fcl = pytest.importorskip("fcl")
    rng = np.random.default_rng(33)
    radius_a, half_a, rotation_a = random_capsules(rng, RANDOM_COUNT)
    radius_b, half_b, rotation_b = random_capsules(rng, RANDOM_COUNT)
    # a tenth of the pairs exactly parallel or antiparallel (the 2-contact branch)
    parallel = rng.random(RANDOM_COUNT) < 0.1
    rotation_a[parallel] = rotation_b[parallel] @ rot_x(np.pi * rng.integers(0, 2))
    center_a = placed(rng, RANDOM_COUNT, radius_a + radius_b + half_a + half_b)
    axis_a, axis_b = rotation_a[:, :, 2], rotation_b[:, :, 2]

    # independent reference: min over s of the distance of A's point s to segment B
    def distance_to_b(s):
        p = center_a + s[:, None] * axis_a
        t = np.clip(np.einsum("ij,ij->i", p, axis_b), -half_b, half_b)
        return np.linalg.norm(p - t[:, None] * axis_b, axis=1)

    reference = radius_a + radius_b - golden_section_min(distance_to_b, -half_a, half_a)

    depth = np.empty(RANDOM_COUNT)
    two = 0
    for k in range(RANDOM_COUNT):
        contacts = run(
            capsule_capsule,
            center_a[k],
            rotation_a[k],
            radius_a[k],
            half_a[k],
            [0, 0, 0],
            rotation_b[k],
            radius_b[k],
            half_b[k],
            margin=MARGIN_ALL,
        )
        two += len(contacts[2]) == 2
        point, normal, depth[k], _ = deepest(contacts)
        assert_midway(
            point,
            normal,
            depth[k],
            lambda x: sdf_capsule(x, center_a[k], rotation_a[k], radius_a[k], half_a[k]),
            lambda x: sdf_capsule(x, np.zeros(3), rotation_b[k], radius_b[k], half_b[k]),
        )
    assert two > 20
    np.testing.assert_allclose(depth, reference, rtol=1e-6, atol=1e-9)

    # FCL: its distance (separated pairs) agrees; its penetration depth is a valid but often
    # non-minimal translation, so it may only be larger than ours.
    separated = 0
    for k in range(RANDOM_COUNT):
        fcl_depth, hit = fcl_signed_depth(
            fcl,
            fcl.Capsule(radius_a[k], 2 * half_a[k]),
            rotation_a[k],
            center_a[k],
            fcl.Capsule(radius_b[k], 2 * half_b[k]),
            rotation_b[k],
            np.zeros(3),
        )
        if hit:
            assert fcl_depth >= depth[k] - 1e-5
        else:
            separated += 1
            assert abs(fcl_depth - depth[k]) <= 1e-6
    assert RANDOM_COUNT // 5 < separated < RANDOM_COUNT * 4 // 5


def test_fcl_capsule_capsule_depth_is_not_minimal():
    """Why FCL is not the reference for overlapping capsule pairs: two crossing capsules
    (r = 0.5, half length 1) whose centres are 0.3 apart along one axis can be separated by
    moving 1.0 along their common normal, yet FCL reports 1.7 (along the other axis)."""
    fcl = pytest.importorskip("fcl")
    depth, hit = fcl_signed_depth(
        fcl, fcl.Capsule(0.5, 2.0), I3, np.array([0, 0, 0.3]), fcl.Capsule(0.5, 2.0), ALONG_X, np.zeros(3)
    )
    ours = run(capsule_capsule, [0, 0, 0.3], I3, 0.5, 1.0, [0, 0, 0], ALONG_X, 0.5, 1.0)[2]
    assert hit and ours == pytest.approx([1.0]) and depth > 1.5


def test_capsule_box_random_against_independent_references():
    scipy_spatial = pytest.importorskip("scipy.spatial")
    fcl = pytest.importorskip("fcl")
    rng = np.random.default_rng(34)
    radius, half, rotation = random_capsules(rng, RANDOM_COUNT)
    half[half == 0.0] = 1e-3  # keep the Minkowski difference full-dimensional for Qhull
    box_half = rng.uniform(0.05, 1.0, (RANDOM_COUNT, 3))
    box_rotation = random_rotations(rng, RANDOM_COUNT)
    box_center = rng.normal(size=(RANDOM_COUNT, 3)) * 0.1
    center = box_center + placed(rng, RANDOM_COUNT, radius + half + np.linalg.norm(box_half, axis=1))
    axis = rotation[:, :, 2]

    depth = np.empty(RANDOM_COUNT)
    normal = np.empty((RANDOM_COUNT, 3))
    kinds = np.empty(RANDOM_COUNT, dtype=np.int64)
    for k in range(RANDOM_COUNT):
        contacts = run(
            capsule_box,
            center[k],
            rotation[k],
            radius[k],
            half[k],
            box_center[k],
            box_rotation[k],
            box_half[k],
            margin=MARGIN_ALL,
        )
        point, normal[k], depth[k], kinds[k] = deepest(contacts)
        assert_midway(
            point,
            normal[k],
            depth[k],
            lambda x: sdf_capsule(x, center[k], rotation[k], radius[k], half[k]),
            lambda x: sdf_box(x, box_center[k], box_rotation[k], box_half[k]),
        )

    # segment–box distance: golden-section search over the segment of the point–box distance
    def distance_to_box(s):
        p = center + s[:, None] * axis - box_center
        local = np.einsum("nji,nj->ni", box_rotation, p)
        return np.linalg.norm(local - np.clip(local, -box_half, box_half), axis=1)

    distance = golden_section_min(distance_to_box, -half, half)

    inside = distance < 1e-12
    reference = radius - distance
    # segment entering the box: Qhull on box corners − segment ends (the Minkowski difference)
    signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float)
    for k in np.flatnonzero(inside):
        corners = box_center[k] + (signs * box_half[k]) @ box_rotation[k].T
        ends = center[k] + np.outer([-half[k], half[k]], axis[k])
        difference = (corners[:, None, :] - ends[None, :, :]).reshape(-1, 3)
        hull = scipy_spatial.ConvexHull(difference)
        assert (hull.equations[:, 3] < 1e-12).all()  # the origin is inside
        reference[k] = radius[k] + (-hull.equations[:, 3]).min()
    assert 100 < inside.sum() < RANDOM_COUNT // 2
    np.testing.assert_allclose(depth, reference, rtol=1e-6, atol=1e-7)

    # support functions: along our normal the overlap is our depth; no sampled direction
    # (20 000, plus our normals) has a smaller one
    def overlap(d, rows):
        box_support = np.einsum("nmk,nk->nm", d, box_center[rows]) + np.einsum(
            "nmj,nj->nm", np.abs(np.einsum("nmk,nkj->nmj", d, box_rotation[rows])), box_half[rows]
        )
        capsule_low = (
            np.einsum("nmk,nk->nm", d, center[rows])
            - half[rows, None] * np.abs(np.einsum("nmk,nk->nm", d, axis[rows]))
            - radius[rows, None]
        )
        return box_support - capsule_low

    rows = np.arange(RANDOM_COUNT)
    np.testing.assert_allclose(overlap(normal[:, None, :], rows)[:, 0], depth, rtol=1e-9, atol=1e-12)
    rows = np.flatnonzero(inside)
    rotations_side_by_side = box_rotation[rows].transpose(1, 0, 2).reshape(3, -1)  # (3, 3 · rows)
    for d in np.array_split(fibonacci_sphere(20000), 8):  # (M, 3) each
        box_support = d @ box_center[rows].T + (
            np.abs(d @ rotations_side_by_side).reshape(len(d), len(rows), 3) * box_half[rows]
        ).sum(axis=2)
        capsule_low = d @ center[rows].T - half[rows] * np.abs(d @ axis[rows].T) - radius[rows]
        assert ((box_support - capsule_low).min(axis=0) >= depth[rows] - 1e-12).all()

    # FCL's GJK distance (fully separated pairs), which is only good to ~3e-4 m here
    separated = 0
    for k in range(RANDOM_COUNT):
        if depth[k] < -1e-3:
            separated += 1
            fcl_depth, hit = fcl_signed_depth(
                fcl,
                fcl.Capsule(radius[k], 2 * half[k]),
                rotation[k],
                center[k],
                fcl.Box(*(2 * box_half[k])),
                box_rotation[k],
                box_center[k],
            )
            assert not hit and abs(fcl_depth - depth[k]) < 2e-3
    assert separated > RANDOM_COUNT // 5


# ---------------------------------------------------------------------------------------------
# (4) feature persistence
# ---------------------------------------------------------------------------------------------


def jitter(rng, center, rotation, size=1e-4):
    angle = rng.normal(scale=size, size=3)
    return (
        np.asarray(center, float) + rng.normal(scale=size, size=3),
        rot_x(angle[0]) @ rot_y(angle[1]) @ rot_z(angle[2]) @ rotation,
    )


def assert_persistent(make_contacts, rng, steps=100, tolerance=5e-3):
    """Contacts of jittered configurations: the same features, each near its first position."""
    first_point, _, _, first_feature = make_contacts(rng, 0.0)
    assert len(first_feature) > 0
    reference = dict(zip(first_feature.tolist(), first_point))
    for _ in range(steps):
        point, _, _, feature = make_contacts(rng, 1e-4)
        assert sorted(feature.tolist()) == sorted(reference)
        for p, f in zip(point, feature.tolist()):
            assert np.linalg.norm(p - reference[f]) < tolerance


@pytest.mark.parametrize(
    "center, rotation, expected",
    [
        ([0.0, 0.0, 0.09], ALONG_X, [0, 1]),  # lying flat: both ends
        ([0.0, 0.0, 0.55], I3, [0]),  # standing: the lower end
        ([0.0, 0.0, 0.5], rot_x(0.3), [0]),  # tilted on its −z end
    ],
)
def test_capsule_plane_features_persist(center, rotation, expected):
    rng = np.random.default_rng(41)

    def make(rng, size):
        c, R = jitter(rng, center, rotation, size) if size else (np.asarray(center, float), rotation)
        return run(capsule_plane, c, R, 0.1, 0.5, GROUND, margin=0.01)

    assert sorted(make(rng, 0)[3].tolist()) == expected
    assert_persistent(make, rng)


@pytest.mark.parametrize(
    "center_a, rotation_a, expected",
    [
        ([0.0, 0.0, 0.39], ALONG_X, [1, 2]),  # side by side
        ([0.1, 0.0, 0.39], ALONG_Y, [0]),  # crossed
    ],
)
def test_capsule_capsule_features_persist(center_a, rotation_a, expected):
    rng = np.random.default_rng(42)

    def make(rng, size):
        c, R = jitter(rng, center_a, rotation_a, size) if size else (np.asarray(center_a, float), rotation_a)
        return run(capsule_capsule, c, R, 0.2, 0.5, [0, 0, 0], ALONG_X, 0.2, 0.5, margin=0.01)

    assert sorted(make(rng, 0)[3].tolist()) == expected
    assert_persistent(make, rng)


@pytest.mark.parametrize(
    "center, rotation, half, expected",
    [
        ([0.0, 0.3, 0.69], ALONG_X, 0.5, [10, 11]),  # lying on the top face
        ([0.8, 0.0, 0.69], ALONG_X, 0.5, [10, 11]),  # overhanging the +x edge
        ([0.2, 0.1, 1.19], I3, 0.5, [10]),  # standing on the top face
        ([0.0, 1.1, 0.6], ALONG_X, 0.5, [18, 19]),  # along the top +y edge (edge 3)
        ([1.19, 0.0, 0.0], I3, 0.3, [2, 3]),  # upright against the +x face (face 1)
        ([1.1, 0.0, 1.05], rot_y(0.3), 0.5, [10]),  # tilted, its end over the +x top edge
    ],
)
def test_capsule_box_features_persist(center, rotation, half, expected):
    rng = np.random.default_rng(43)

    def make(rng, size):
        c, R = jitter(rng, center, rotation, size) if size else (np.asarray(center, float), rotation)
        return run(capsule_box, c, R, 0.2, half, [0, 0, 0], I3, BOX_HALF, margin=0.02)

    assert sorted(make(rng, 0)[3].tolist()) == expected
    assert_persistent(make, rng)


def test_capsule_sliding_over_a_box_edge_keeps_its_features():
    """A capsule sliding along +x over the top face and past its edge: the two contacts keep
    features 10 (the −z end side) and 11 until the far end leaves the face."""
    seen = []
    for x in np.linspace(0.0, 1.4, 57):
        point, _, depth, feature = run(
            capsule_box, [x, 0, 0.69], ALONG_X, 0.2, 0.5, [0, 0, 0], I3, BOX_HALF, margin=0.02
        )
        by_feature = dict(zip(feature.tolist(), point))
        seen.append(sorted(by_feature))
        if x - 0.5 < 1.0:
            assert sorted(by_feature) == [10, 11]
            np.testing.assert_allclose(by_feature[10][0], x - 0.5, atol=1e-14)
            np.testing.assert_allclose(by_feature[11][0], min(x + 0.5, 1.0), atol=1e-14)
    assert seen[0] == [10, 11]


def test_capsule_tipping_over_a_box_edge_keeps_its_features():
    """A capsule overhanging the +x edge, turned about the edge by ±0.01 rad: whether the
    deepest point is on the face or on the edge, the contacts are its end on the face (10)
    and the point at the edge (11)."""
    for angle in np.linspace(-0.01, 0.01, 21):
        R = rot_y(angle) @ ALONG_X
        center = np.array([1.0, 0.0, 0.69]) + rot_y(angle) @ np.array([-0.2, 0.0, 0.0])
        point, normal, depth, feature = run(capsule_box, center, R, 0.2, 0.5, [0, 0, 0], I3, BOX_HALF, margin=0.02)
        assert sorted(feature.tolist()) == [10, 11]
        by_feature = dict(zip(feature.tolist(), point))
        assert by_feature[10][0] < 0.31 and abs(by_feature[11][0] - 1.0) < 0.01
        np.testing.assert_allclose(depth.max(), 0.2 - sdf_capsule_to_box(center, R, 0.5), atol=1e-12)


def sdf_capsule_to_box(center, rotation, half):
    """Distance of the segment to the box BOX_HALF at the origin (golden-section search)."""

    def distance(s):
        p = center + s[:, None] * rotation[:, 2]
        return np.linalg.norm(p - np.clip(p, -BOX_HALF, BOX_HALF), axis=1)

    return golden_section_min(distance, np.array([-half]), np.array([half]))[0]


def test_sphere_capsule_feature_persists_from_side_to_cap():
    for x in np.linspace(0.0, 0.9, 31):
        direction = np.array([max(x - 0.5, 0.0), 0.0, 0.3])
        center = np.array([min(x, 0.5), 0.0, 0.0]) + 0.29 * direction / np.linalg.norm(direction)
        _, _, depth, feature = run(sphere_capsule, center, 0.1, [0, 0, 0], ALONG_X, 0.2, 0.5)
        assert feature.tolist() == [0]
        np.testing.assert_allclose(depth, [0.01], atol=1e-14)
