"""Contact manifolds kept across steps (collision.manifolds): reused only while valid, refreshed
exactly at the current poses, recomputed as soon as the motion exceeds the tolerance."""

import numpy as np
import pytest

from contactlab import ModelBuilder, collide, rotations, simulate
from contactlab.collision import DetectionSettings, collide_keeping
from contactlab.errors import InputError
from contactlab.methods import constraints, impulse

TOL = 1e-4  # m
MARGIN = 0.002  # m


def box_on_plane(tilt=0.0, height=0.05):
    """A 0.1 m cube resting on z = 0 (overlap 0 at height 0.05), turned ``tilt`` rad about x."""
    b = ModelBuilder()
    b.add_body(
        "box",
        half_extents=(0.05, 0.05, 0.05),
        mass=1.0,
        position=(0.0, 0.0, height),
        orientation=tuple(rotations.from_rotation_vector(np.array([tilt, 0.0, 0.0]))),
    )
    b.add_obstacle("plane", normal=(0, 0, 1), offset=0.0)
    model = b.finalize()
    return model, model.state()


def keep(model, state, manifolds, tolerance=TOL, margin=MARGIN):
    return collide_keeping(model, state, manifolds, tolerance, DetectionSettings(margin))


def same_contacts(a, b):
    order_a, order_b = np.argsort(a.feature_id), np.argsort(b.feature_id)
    np.testing.assert_array_equal(a.feature_id[order_a], b.feature_id[order_b])
    return order_a, order_b


def test_first_call_equals_a_fresh_collision_and_keeps_the_pair():
    model, state = box_on_plane(height=0.049)  # 1 mm overlap: four corner contacts
    fresh = collide(model, state, MARGIN)
    contacts, kept = keep(model, state, None)
    assert fresh.count == contacts.count == 4
    for name in ("point", "normal", "depth", "feature_id", "body_a", "body_b"):
        np.testing.assert_array_equal(getattr(contacts, name), getattr(fresh, name))
    assert len(kept) == 1 and kept.count[0] == 4
    np.testing.assert_array_equal(kept.center[0, 0], state.body_position[0])
    # computed with the box's reach widened by the tolerance
    assert kept.reach[0] == pytest.approx(MARGIN + TOL)


def test_a_small_move_reuses_the_manifold_and_refreshes_depth_exactly():
    model, state = box_on_plane(height=0.049)
    _, kept = keep(model, state, None)
    state.body_position[0] += (2e-5, -1e-5, -3e-5)  # 3.7e-5 m < TOL: still valid
    contacts, again = keep(model, state, kept)
    np.testing.assert_array_equal(again.center, kept.center)  # the same manifold, not recomputed
    fresh = collide(model, state, MARGIN)
    i, j = same_contacts(contacts, fresh)
    # the witness points are the box's corners and the plane's points below them: the depth is exact
    np.testing.assert_allclose(contacts.depth[i], 0.001 + 3e-5, rtol=0, atol=1e-15)
    np.testing.assert_allclose(contacts.depth[i], fresh.depth[j], rtol=0, atol=1e-15)
    # the plane's witness stays where it was, so the midway point lags half the sideways move
    np.testing.assert_allclose(
        contacts.point[i], fresh.point[j] - 0.5 * np.array([2e-5, -1e-5, 0.0]), rtol=0, atol=1e-15
    )
    np.testing.assert_allclose(contacts.normal[i], fresh.normal[j], rtol=0, atol=1e-15)


def test_a_move_beyond_the_tolerance_recomputes():
    model, state = box_on_plane(height=0.049)
    _, kept = keep(model, state, None)
    state.body_position[0] += (1.5 * TOL, 0.0, 0.0)
    contacts, again = keep(model, state, kept)
    np.testing.assert_array_equal(again.center[0, 0], state.body_position[0])  # recorded afresh
    fresh = collide(model, state, MARGIN)
    np.testing.assert_array_equal(contacts.depth, fresh.depth)
    np.testing.assert_array_equal(contacts.point, fresh.point)


@pytest.mark.parametrize("angle, reused", [(0.5 * TOL / 0.0866, True), (1.5 * TOL / 0.0866, False)])
def test_turning_counts_by_the_chord_of_the_bounding_radius(angle, reused):
    """ρ = √3 · 0.05 = 0.0866 m for the cube: a turn θ moves its corners up to ρ θ."""
    model, state = box_on_plane(height=0.049)
    _, kept = keep(model, state, None)
    state.body_orientation[0] = rotations.from_rotation_vector(np.array([0.0, angle, 0.0]))
    contacts, again = keep(model, state, kept)
    assert np.array_equal(again.rotation, kept.rotation) == reused
    fresh = collide(model, state, MARGIN)
    i, j = same_contacts(contacts, fresh)
    # recomputed: exact; reused: the normal kept in the box's frame has turned with it by θ,
    # which changes a depth of about 1 mm by at most 1 mm · θ (first order in θ)
    np.testing.assert_allclose(contacts.depth[i], fresh.depth[j], rtol=0, atol=0.0011 * angle if reused else 1e-15)


def box_off_an_edge(gap):
    """Two 0.1 m cubes without gravity: A at the origin, B turned 45° about z with a face
    ``gap`` [m] from A's vertical edge at (0.05, 0.05). Their bounding boxes overlap whatever
    the gap, so the pair is always in the broad phase."""
    b = ModelBuilder(gravity=(0, 0, 0))
    b.add_body("box", half_extents=(0.05, 0.05, 0.05), mass=1.0)
    diagonal = np.array([1.0, 1.0, 0.0]) / np.sqrt(2)
    b.add_body(
        "box",
        half_extents=(0.05, 0.05, 0.05),
        mass=1.0,
        position=tuple(np.array([0.05, 0.05, 0.0]) + (0.05 + gap) * diagonal),
        orientation=tuple(rotations.from_rotation_vector(np.array([0.0, 0.0, np.pi / 4]))),
    )
    model = b.finalize()
    return model, model.state(), diagonal


def test_a_wider_reach_than_computed_recomputes():
    """A pair whose reach grows beyond what its manifold was computed with (a faster sweep)
    could now have contacts the manifold never looked for: it is computed afresh."""
    model, state, _ = box_off_an_edge(0.005)
    contacts, kept = keep(model, state, None)
    assert contacts.count == 0 and len(kept) == 1 and kept.count[0] == 0  # near, not touching: kept empty
    contacts, again = collide_keeping(model, state, kept, TOL, DetectionSettings(MARGIN), np.array([0.0, 0.004]))
    assert contacts.count == 2  # the edge's two ends
    np.testing.assert_allclose(contacts.depth, -0.005, rtol=0, atol=1e-12)
    assert again.count[0] == 2


def test_contacts_beyond_the_current_reach_are_left_out_until_they_come_within_it():
    """A manifold computed with the widened reach keeps contacts the margin excludes; when B
    comes 0.4 tolerance closer the reused contacts are reported, at their refreshed gap."""
    model, state, diagonal = box_off_an_edge(MARGIN + 0.25 * TOL)
    contacts, kept = keep(model, state, None)
    assert contacts.count == 0 and kept.count.tolist() == [2]
    state.body_position[1] -= 0.4 * TOL * diagonal
    contacts, again = keep(model, state, kept)
    np.testing.assert_array_equal(again.center, kept.center)  # reused
    assert contacts.count == 2
    np.testing.assert_allclose(contacts.depth, -(MARGIN - 0.15 * TOL), rtol=0, atol=1e-12)
    fresh = collide(model, state, MARGIN)
    i, j = same_contacts(contacts, fresh)
    np.testing.assert_allclose(contacts.depth[i], fresh.depth[j], rtol=0, atol=1e-12)


def test_only_polytope_and_plane_pairs_are_kept_and_the_rest_match_collide_bit_for_bit():
    """Spheres (and capsules) roll: their contact point is no material point, so their pairs
    are computed every step, exactly as ``collide`` computes them."""
    b = ModelBuilder()
    rng = np.random.default_rng(3)
    for p in rng.uniform([-0.2, -0.2, 0.04], [0.2, 0.2, 0.3], size=(60, 3)):
        b.add_body("sphere", radius=0.05, mass=1.0, position=tuple(p))
    b.add_body("box", half_extents=(0.05, 0.04, 0.03), mass=1.0, position=(0.0, 0.0, 0.029))
    b.add_body("capsule", radius=0.03, half_length=0.1, mass=1.0, position=(0.3, 0.3, 0.029))
    b.add_obstacle("plane", normal=(0, 0, 1), offset=0.0)
    model = b.finalize()
    state = model.state()
    fresh = collide(model, state, MARGIN)
    contacts, kept = keep(model, state, None)
    for name in ("point", "normal", "depth", "feature_id", "body_a", "body_b"):
        np.testing.assert_array_equal(getattr(contacts, name), getattr(fresh, name))
    box, total = 60, model.body_count + model.obstacle_count
    assert kept.keys.tolist() == [box * total + model.body_count]  # the box on the plane only
    assert kept.count.tolist() == [4]
    state.body_position[:] += 1e-5  # everything moves a little
    contacts, again = keep(model, state, kept)
    np.testing.assert_array_equal(again.center, kept.center)  # the box's pair is reused
    fresh = collide(model, state, MARGIN)
    not_box = ~((fresh.body_a == box) & (fresh.body_b == -1))
    for name in ("point", "normal", "depth", "feature_id"):
        np.testing.assert_array_equal(
            getattr(contacts, name)[~((contacts.body_a == box) & (contacts.body_b == -1))],
            getattr(fresh, name)[not_box],
        )


def test_a_resting_stack_reuses_every_manifold_and_matches_fresh_contacts():
    """Three boxes settle; afterwards each step reuses every pair, and what it reuses agrees
    with a fresh collision of the same state."""
    b = ModelBuilder()
    b.add_material("wood", friction=0.6, restitution=0.0)
    for level in range(3):
        b.add_body(
            "box",
            half_extents=(0.05, 0.05, 0.05),
            mass=1.0,
            position=(0.01 * level, 0, 0.05 + 0.1 * level),
            material="wood",
        )
    b.add_obstacle("plane", normal=(0, 0, 1), offset=0.0, material="wood")
    model = b.finalize()
    dt = 1 / 240
    state = simulate(model, "constraints", dt, 1.0, {"iterations": 50}).state
    kept = state.carried.manifolds
    assert len(kept) == 3 and kept.count.tolist() == [4, 4, 4]
    options = constraints.Options(iterations=50)
    state, _ = constraints.step(model, state, dt, options)
    np.testing.assert_array_equal(state.carried.manifolds.center, kept.center)  # all three reused
    contacts, _ = keep(model, state, state.carried.manifolds)
    fresh = collide(model, state, MARGIN)
    i, j = same_contacts(contacts, fresh)
    np.testing.assert_allclose(contacts.depth[i], fresh.depth[j], rtol=0, atol=1e-9)
    np.testing.assert_allclose(contacts.point[i], fresh.point[j], rtol=0, atol=TOL)


@pytest.mark.parametrize("module", [constraints, impulse])
def test_tolerance_must_not_be_negative(module):
    with pytest.raises(InputError, match="manifold_tolerance"):
        module.Options(manifold_tolerance=-1e-4)


@pytest.mark.parametrize("method", ["constraints", "impulse"])
def test_a_box_slides_the_same_distance_with_or_without_kept_manifolds(method):
    """μ g d = v² / 2 either way: a sliding box moves more than the tolerance every step, so
    its contacts are recomputed, and it comes to rest on reused ones."""
    stops = []
    for tolerance in (0.0, TOL):
        b = ModelBuilder()
        b.add_material("steel", friction=0.4, restitution=0.0)
        b.add_body(
            "box",
            half_extents=(0.05, 0.05, 0.05),
            mass=1.0,
            position=(0, 0, 0.05),
            velocity=(2.0, 0, 0),
            material="steel",
        )
        b.add_obstacle("plane", normal=(0, 0, 1), offset=0.0, material="steel")
        run = simulate(b.finalize(), method, 1 / 240, 0.8, {"iterations": 50, "manifold_tolerance": tolerance})
        stops.append(run.state.body_position[0, 0])
    expected = 2.0**2 / (2 * 0.4 * 9.81)
    assert stops[0] == pytest.approx(expected, abs=0.01)
    assert stops[1] == pytest.approx(stops[0], abs=1e-6)
