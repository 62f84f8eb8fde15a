"""Cloth self-contact (issue 41): detection against brute force, and cloth that folds on itself,
falls on another cloth and rests in two layers without any edge passing through a triangle,
under each method that steps cloth."""

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from contactlab import ModelBuilder, simulate
from contactlab.collision import collide
from contactlab.collision.broad_phase import elements_between
from contactlab.collision.cloth_self import (
    allowed_gap,
    closest_on_segments,
    closest_on_triangle,
    cloth_elements,
    cloth_self_contacts,
    crossings,
    edge_edge,
    is_self_contact,
    vertex_triangle,
)
from contactlab.errors import InputError
from contactlab.health import Health

UPRIGHT = (np.cos(np.pi / 4), np.sin(np.pi / 4), 0.0, 0.0)  # 90° about x: the grid's y axis points up
THICKNESS = 0.004
METHODS = ("projection", "constraints", "impulse", "penalty")


def strip(self_collision=True):
    """A 0.1 × 0.6 m strip (4 × 24 vertices, 50 g) standing upright, its foot 1 mm above the floor."""
    b = ModelBuilder()
    b.add_material("cotton", friction=0.4, restitution=0.0)
    b.add_cloth(
        size=(0.1, 0.6),
        resolution=(4, 24),
        mass=0.05,
        position=(0, 0, 0.305),
        orientation=UPRIGHT,
        stretch_stiffness=500.0,
        shear_stiffness=50.0,
        bend_stiffness=0.5,
        damping=0.01,
        thickness=THICKNESS,
        material="cotton",
        self_collision=self_collision,
    )
    b.add_obstacle("plane", normal=(0, 0, 1), offset=0.0, material="cotton")
    return b.finalize()


def two_sheets(height, self_collision=True, n=6, shift=(0.0, 0.0), upper_size=0.2):
    """Two square sheets (n × n vertices, 20 g each): one of 0.2 m lying on the floor, the other
    of ``upper_size`` [m] flat ``height`` above it, moved by ``shift`` (x, y) [m]."""
    b = ModelBuilder()
    b.add_material("cotton", friction=0.4, restitution=0.0)
    for z, (dx, dy), size in ((THICKNESS, (0.0, 0.0), 0.2), (THICKNESS + height, shift, upper_size)):
        b.add_cloth(
            size=(size, size),
            resolution=(n, n),
            mass=0.02,
            position=(dx, dy, z),
            stretch_stiffness=500.0,
            shear_stiffness=50.0,
            bend_stiffness=0.5,
            damping=0.01,
            thickness=THICKNESS,
            material="cotton",
            self_collision=self_collision,
        )
    b.add_obstacle("plane", normal=(0, 0, 1), offset=0.0, material="cotton")
    return b.finalize()


def sheet_on_a_rod(self_collision=True):
    """A 0.3 m square sheet (10 × 10 vertices, 30 g) dropped from 5 cm onto a thin rod (a box 8 mm
    across, 0.5 m long, along x at z = 0.2 m): it folds over it, its two halves hanging side by side."""
    b = ModelBuilder()
    b.add_material("cotton", friction=0.4, restitution=0.0)
    b.add_cloth(
        size=(0.3, 0.3),
        resolution=(10, 10),
        mass=0.03,
        position=(0.0, 0.0, 0.25),
        stretch_stiffness=500.0,
        shear_stiffness=50.0,
        bend_stiffness=0.2,
        damping=0.01,
        thickness=THICKNESS,
        material="cotton",
        self_collision=self_collision,
    )
    b.add_obstacle("box", half_extents=(0.25, 0.004, 0.004), position=(0.0, 0.0, 0.2), material="cotton")
    return b.finalize()


def run(model, method, duration, dt=1 / 240, **options):
    return simulate(model, method, dt, duration, options, "backward_euler", record_every=4)


def crossed_samples(model, positions):
    """The recorded samples (indices) at which an edge of a cloth passes through one of its triangles."""
    return [k for k in range(len(positions)) if len(crossings(model, positions[k]))]


# -- a strip piling on the floor ---------------------------------------------------------------------
@pytest.mark.parametrize("method", METHODS)
def test_a_strip_dropped_upright_piles_in_folds_and_never_passes_through_itself(method):
    model = strip()
    positions = run(model, method, 0.8).arrays["particle_position"]
    assert crossed_samples(model, positions) == []
    final = positions[-1]
    assert final[:, 2].max() < 0.1  # it fell over and piled up: 0.6 m of strip within 10 cm of the floor
    assert final[:, 2].min() > 0.5 * THICKNESS  # on the floor, not through it
    assert np.ptp(final[:, :2], axis=0).max() < 0.45  # folded: its ends closer than its length


def test_without_self_collision_the_same_strip_passes_through_itself():
    model = strip(self_collision=False)
    positions = run(model, "projection", 0.8).arrays["particle_position"]
    assert len(crossed_samples(strip(), positions)) > 3


# -- a sheet over a rod ------------------------------------------------------------------------------
@pytest.mark.parametrize("method", METHODS)
def test_a_sheet_folds_over_a_thin_rod_and_its_halves_hang_without_passing_through_each_other(method):
    model = sheet_on_a_rod()
    # the triangles' samples meet the rod (P2c): 8 mm of rod fits between the vertices, 33 mm apart
    positions = run(model, method, 0.7, cloth_samples=2).arrays["particle_position"]
    assert crossed_samples(model, positions) == []
    final = positions[-1]
    assert final[:, 2].max() < 0.22 and final[:, 2].mean() < 0.15  # its top on the rod, the rest hanging
    assert final[:, 2].min() > 0.05  # held by the rod, not fallen
    assert (final[:, 1] > 0).sum() > 30 and (final[:, 1] < 0).sum() > 30  # a half hanging on each side


def test_without_self_collision_the_halves_hanging_from_the_rod_pass_through_each_other():
    positions = run(sheet_on_a_rod(False), "projection", 0.7, cloth_samples=2).arrays["particle_position"]
    assert len(crossed_samples(sheet_on_a_rod(), positions)) > 3


# -- a cloth on a cloth ------------------------------------------------------------------------------
@pytest.mark.parametrize("method", METHODS)
def test_a_cloth_falling_on_another_stays_above_it(method):
    model = two_sheets(0.08, shift=(0.03, 0.02))
    positions = run(model, method, 0.5).arrays["particle_position"]
    assert crossed_samples(model, positions) == []
    lower, upper = positions[-1][:36], positions[-1][36:]
    over = (np.abs(upper[:, 0]) < 0.09) & (np.abs(upper[:, 1]) < 0.09)  # the part above the lower sheet
    assert over.sum() > 10
    # the lower sheet lies at z = thickness, the upper's vertices two thicknesses above it
    assert lower[:, 2].max() < 1.5 * THICKNESS
    assert upper[over, 2].min() > lower[:, 2].max() + 1.5 * THICKNESS, upper[over, 2].min()


def test_without_self_collision_a_cloth_falls_through_another():
    model = two_sheets(0.08, self_collision=False, shift=(0.03, 0.02))
    upper = run(model, "projection", 0.5).arrays["particle_position"][-1][36:]
    over = (np.abs(upper[:, 0]) < 0.09) & (np.abs(upper[:, 1]) < 0.09)
    assert upper[over, 2].min() < 2.0 * THICKNESS  # through the lower sheet's triangles, onto the floor


@pytest.mark.parametrize("method", METHODS)
def test_two_layers_resting_flat_stay_put(method):
    """Closed form: the upper sheet rests 2 × thickness above the lower, which rests a
    thickness above the floor (the sum of the radii apart); nothing slides. The upper sheet is
    smaller and its vertices lie over the lower's triangles, not over its vertices."""
    model = two_sheets(2.0 * THICKNESS, shift=(0.011, 0.006), upper_size=0.16)
    start = model.state().particle_position
    # penalty's springs give way allowed_penetration per layer (0.3 mm by default, the upper sheet 2 of them
    # down as in a stack of boxes): 0.1 mm here, so that both layers sit within the tolerance below
    options = {"allowed_penetration": 1e-4} if method == "penalty" else {}
    final = run(model, method, 0.3, **options).arrays["particle_position"][-1]
    np.testing.assert_allclose(final[:36, 2], THICKNESS, atol=0.6e-3)
    np.testing.assert_allclose(final[36:, 2], 3.0 * THICKNESS, atol=0.6e-3)
    np.testing.assert_allclose(final[:, :2], start[:, :2], atol=0.5e-3)


def test_the_summary_counts_self_contacts():
    resting = dict(height=2.0 * THICKNESS, shift=(0.011, 0.006), upper_size=0.16)
    on = run(two_sheets(**resting), "projection", 0.05).summary["self_contacts"]
    off = run(two_sheets(self_collision=False, **resting), "projection", 0.05).summary["self_contacts"]
    assert on > 36 and off == 0  # every vertex of the upper sheet over a triangle of the lower, and more


def test_the_health_check_stops_a_run_at_an_edge_through_a_triangle_but_not_at_those_it_started_with():
    model = two_sheets(0.01, n=2, shift=(0.03, 0.05))
    state = model.state()
    health = Health(model, state, 0.01)
    assert health.check_contacts(state, collide(model, state)) is None
    through = model.state()
    through.particle_position[4, 2] = 0.0  # a corner of the upper sheet pulled down through the lower, to the floor
    violation = health.check_contacts(through, collide(model, through))
    assert violation is not None and violation.check == "crossing", violation
    assert Health(model, through, 0.01).check_contacts(through, collide(model, through)) is None  # it began so
    unchecked = two_sheets(0.01, self_collision=False, n=2, shift=(0.03, 0.05))
    assert Health(unchecked, unchecked.state(), 0.01).check_contacts(through, collide(unchecked, through)) is None


# -- detection ---------------------------------------------------------------------------------------
def brute_force_contacts(model, position, reach):
    """Every vertex–triangle pair of the model, by vertex then triangle, then every edge–edge
    pair, by first then second edge, tested one by one: a list of the contacts as tuples (id,
    particles_a, weights_a, particles_b, weights_b, depth, point, normal), in that order."""
    elements = cloth_elements(model)
    radius = model.particle_radius
    total = model.body_count + model.particle_count + model.obstacle_count
    found = []
    for v in elements.vertices:
        for f, corners in enumerate(elements.triangles):
            corners = tuple(int(c) for c in corners)
            if v in corners:
                continue
            weights, (defined, depth, point, normal) = vertex_triangle(
                position[v], *position[list(corners)], radius[v], radius[list(corners)].max()
            )
            if defined and depth >= -allowed_gap(reach, (int(v),), corners):
                feature = ((v * total + corners[0]) << 24) | (2 * elements.triangle_index[f] + 1)
                found.append((feature, (v, -1, -1), (1, 0, 0), corners, weights, depth, point, normal))
    edges = elements.edges
    for i in range(len(edges)):
        for j in range(i + 1, len(edges)):
            if set(edges[i]) & set(edges[j]):
                continue
            first, second = tuple(int(p) for p in edges[i]), tuple(int(p) for p in edges[j])
            (s, t), (defined, depth, point, normal) = edge_edge(
                *position[list(first)], *position[list(second)], radius[list(first)].max(), radius[list(second)].max()
            )
            if defined and depth >= -allowed_gap(reach, first, second):
                feature = ((first[0] * total + first[1]) << 24) | (2 * j + 2)
                found.append((feature, (*first, -1), (1 - s, s, 0), (*second, -1), (1 - t, t, 0), depth, point, normal))
    return found


def brute_force(model, position, reach):
    """``brute_force_contacts`` as {id: depth}."""
    return {contact[0]: contact[5] for contact in brute_force_contacts(model, position, reach)}


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    crumple=st.floats(0.0, 0.08),
    sweep=st.floats(0.0, 0.02),
    margin=st.floats(0.0, 0.01),
    relative=st.booleans(),
)
def test_detection_finds_exactly_the_pairs_brute_force_finds(seed, crumple, sweep, margin, relative):
    """Over random crumplings of two small sheets, with random displacements over the step (each
    particle's own, ``relative``, or only how far each may move): the broad phase misses no pair."""
    model = two_sheets(0.01, n=4, shift=(0.02, -0.03))
    rng = np.random.default_rng(seed)
    P = model.particle_count
    position = model.state().particle_position + crumple * rng.normal(size=(P, 3))
    state = model.state()
    state.particle_position[:] = position
    if relative:
        motion = np.array([0.0, 0.0, -0.05]) + sweep * rng.normal(size=(P, 3))  # falling, and apart
        contacts = cloth_self_contacts(model, state, margin, None, motion)
        reach = (motion, np.zeros(P), margin)
    else:
        sweeps = sweep * rng.random(P)
        contacts = cloth_self_contacts(model, state, margin, sweeps)
        reach = (np.zeros((P, 3)), sweeps, margin)
    expected = brute_force(model, position, reach)
    assert sorted(contacts.feature_id.tolist()) == sorted(expected)
    assert len(set(contacts.feature_id.tolist())) == contacts.count  # ids are unique
    np.testing.assert_allclose(contacts.depth, [expected[i] for i in contacts.feature_id.tolist()])
    # each contact's normal is unit and its two sides' points lie the distance r_A + r_B − δ apart along it
    point_a = np.einsum("ck,ckd->cd", contacts.weights_a, position[contacts.particles_a])
    point_b = np.einsum("ck,ckd->cd", contacts.weights_b, position[contacts.particles_b])
    gap = np.einsum("cd,cd->c", point_a - point_b, contacts.normal)
    np.testing.assert_allclose(np.linalg.norm(contacts.normal, axis=1), 1.0)
    np.testing.assert_allclose(gap, 2 * THICKNESS - contacts.depth, atol=1e-12)


def test_a_sheet_falling_flat_makes_no_contact_with_itself():
    """Reach is relative motion: a sheet falling as one at 3 m/s (2.5 cm a step) is no nearer
    to itself at the step's end; bounded by each vertex's own sweep, every neighbour would be."""
    model = two_sheets(0.01, n=6)
    P = model.particle_count
    motion = np.tile([0.0, 0.0, -0.025], (P, 1))
    assert cloth_self_contacts(model, model.state(), 0.001, None, motion).count == 0
    sweep = np.full(P, 0.025)
    assert cloth_self_contacts(model, model.state(), 0.001, sweep).count > 10 * P


def folded_cloth(n=8):
    """A 0.2 m square sheet (n × n vertices) folded in two along x = 0.02 m: the part beyond
    lies over the rest 1.5 thicknesses up (within the two thicknesses of it), 1 mm crumpled."""
    b = ModelBuilder()
    b.add_material("cotton", friction=0.4, restitution=0.2)
    b.add_cloth(size=(0.2, 0.2), resolution=(n, n), mass=0.02, thickness=THICKNESS, material="cotton")
    model = b.finalize()
    position = model.state().particle_position.copy()
    beyond = position[:, 0] > 0.02
    position[beyond, 0] = 0.04 - position[beyond, 0]
    position[beyond, 2] += 1.5 * THICKNESS
    return model, position + 0.001 * np.random.default_rng(3).normal(size=position.shape)


@pytest.mark.parametrize("moving", [False, True])
def test_on_a_folded_cloth_detection_gives_the_contacts_of_a_test_of_every_pair_in_their_order(moving):
    """The whole of each contact (ids, particles, weights, depth, point, normal, materials) and
    their order — vertex–triangle by vertex then triangle, then edge–edge by first then second
    edge — as every pair tested one by one gives them, at rest and with the halves moving apart
    and across each other."""
    model, position = folded_cloth()
    P = model.particle_count
    motion = np.zeros((P, 3))
    if moving:
        motion[position[:, 2] > 0.5 * THICKNESS] = (0.002, -0.001, 0.003)
    state = model.state()
    state.particle_position[:] = position
    contacts = cloth_self_contacts(model, state, 0.0005, None, motion)
    expected = brute_force_contacts(model, position, (motion, np.zeros(P), 0.0005))
    assert contacts.count == len(expected) > 50
    assert is_self_contact(contacts).all()
    assert contacts.feature_id.tolist() == [c[0] for c in expected]
    for field, k in (("particles_a", 1), ("weights_a", 2), ("particles_b", 3), ("weights_b", 4), ("depth", 5)):
        np.testing.assert_allclose(
            getattr(contacts, field), [c[k] for c in expected], rtol=0, atol=1e-15, err_msg=field
        )
    np.testing.assert_allclose(contacts.point, [c[6] for c in expected], rtol=0, atol=1e-15)
    np.testing.assert_allclose(contacts.normal, [c[7] for c in expected], rtol=0, atol=1e-15)
    np.testing.assert_allclose(contacts.friction, 0.4)
    np.testing.assert_allclose(contacts.restitution, 0.2)
    edge_edges = (contacts.feature_id & 1) == 0
    assert edge_edges.any() and not edge_edges[: np.argmax(edge_edges)].any()  # vertex–triangle first


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    count_a=st.integers(0, 60),
    count_b=st.integers(0, 60),
    same=st.booleans(),
    corners=st.tuples(st.integers(1, 3), st.integers(1, 3)),
)
def test_elements_between_two_sets_are_those_a_test_of_every_pair_finds(seed, count_a, count_b, same, corners):
    """Elements of 1 to 3 corners, sizes over two orders of magnitude, a third of their corners
    shared with another element: the pairs whose grown boxes overlap and that share no corner,
    in (i, j) order."""
    rng = np.random.default_rng(seed)
    k_a, k_b = (corners[0], corners[0]) if same else corners
    count_b = count_a if same else count_b

    def corner_points(count, k):  # each element's corners within its own size of a random point
        size = np.exp(rng.normal(-3.0, 1.0, size=(count, 1, 1)))
        return (rng.random((count, 1, 3)) + size * rng.random((count, k, 3))).reshape(-1, 3)

    position = np.concatenate([corner_points(count_a, k_a), corner_points(0 if same else count_b, k_b)])
    corners_a = np.arange(count_a * k_a, dtype=np.int64).reshape(count_a, k_a)
    corners_b = corners_a if same else count_a * k_a + np.arange(count_b * k_b, dtype=np.int64).reshape(count_b, k_b)
    if len(position):  # a third of the corners taken from another element
        shared = rng.random(corners_b.shape) < 1 / 3
        corners_b[shared] = rng.integers(0, len(position), size=shared.sum())
    grow = 0.01 * rng.random(len(position))
    found = elements_between(position, grow, corners_a, corners_b, same)

    def boxes(c):
        g = grow[c].max(axis=1, initial=0.0)[:, None]
        return position[c].min(axis=1, initial=np.inf) - g, position[c].max(axis=1, initial=-np.inf) + g

    (lower_a, upper_a), (lower_b, upper_b) = boxes(corners_a), boxes(corners_b)
    overlap = ((lower_a[:, None] <= upper_b[None]) & (lower_b[None] <= upper_a[:, None])).all(axis=2)
    overlap &= ~(corners_a[:, None, :, None] == corners_b[None, :, None, :]).any(axis=(2, 3))
    if same:
        overlap = np.triu(overlap, k=1)
    assert found.tolist() == [list(pair) for pair in zip(*(index.tolist() for index in np.nonzero(overlap)))]


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(-1.0, 1.0), min_size=12, max_size=12))
# degenerate cases Hypothesis found: a triangle with two corners at one point (its edge there had
# divided 0 by 0, and its region was taken for any point), segments 1e-7 off parallel that meet
# at an end or cross (s = 0 was taken for them)
@example([0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0])
@example([0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.192092896e-07, 0.0, 0.0, 0.0])
@example([0.0, 0.0, 1.0, 1.192092896e-07, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.192092896e-07, 1.0])
def test_closest_points_are_no_farther_than_any_sampled_point(values):
    x, a, b, c = np.array(values).reshape(4, 3)
    wa, wb, wc, _ = closest_on_triangle(x, a, b, c)
    assert min(wa, wb, wc) >= -1e-12 and abs(wa + wb + wc - 1.0) < 1e-12
    best = np.linalg.norm(x - (wa * a + wb * b + wc * c))
    u, v = np.meshgrid(np.linspace(0, 1, 41), np.linspace(0, 1, 41))
    inside = u + v <= 1.0
    samples = a + u[inside, None] * (b - a) + v[inside, None] * (c - a)
    assert best <= np.linalg.norm(samples - x, axis=1).min() + 1e-12
    s, t = closest_on_segments(x, a, b, c)
    best = np.linalg.norm(x + s * (a - x) - (b + t * (c - b)))
    grid = np.linspace(0, 1, 101)
    sampled = np.linalg.norm((x + grid[:, None, None] * (a - x)) - (b + grid[None, :, None] * (c - b)), axis=2)
    assert best <= sampled.min() + 1e-12


def test_a_vertex_over_a_triangle_meets_it_along_the_face_normal_on_its_side():
    model = two_sheets(0.001, n=2)  # two squares of two triangles, 1 mm apart: 2 × 4 mm of thickness overlap
    contacts = cloth_self_contacts(model, model.state(), 0.0, None)
    assert contacts.count > 0 and is_self_contact(contacts).all()
    vertex_over = contacts.particles_b[:, 2] >= 0
    np.testing.assert_allclose(np.abs(contacts.normal[vertex_over, 2]), 1.0)
    upper_is_a = contacts.particles_a[:, 0] >= 4
    np.testing.assert_allclose(np.sign(contacts.normal[:, 2]), np.where(upper_is_a, 1.0, -1.0))
    np.testing.assert_allclose(contacts.depth, 2 * THICKNESS - 0.001)
    # collide reports them with everything else, and a cloth with self_collision off makes none
    assert is_self_contact(collide(model, model.state())).sum() == contacts.count
    assert not is_self_contact(collide(two_sheets(0.001, False, n=2), two_sheets(0.001, False, n=2).state())).any()


def test_crossings_finds_an_edge_through_a_triangle():
    model = two_sheets(0.01, n=2)
    state = model.state()
    assert len(crossings(model, state.particle_position)) == 0
    state.particle_position[4, 2] = -0.02  # a corner of the upper sheet pulled down through the lower
    found = crossings(model, state.particle_position)
    assert len(found) > 0
    elements = cloth_elements(model)
    moved = np.concatenate([elements.edges[found[:, 0]], elements.triangles[found[:, 1]]], axis=1)
    assert (moved == 4).any(axis=1).all()  # each crossing has the moved corner in its edge or its triangle


# -- the scene key -----------------------------------------------------------------------------------
def test_self_collision_is_on_by_default_and_checked():
    b = ModelBuilder()
    b.add_cloth(size=(0.2, 0.2), resolution=(3, 3), mass=0.01)
    b.add_cloth(size=(0.2, 0.2), resolution=(3, 3), mass=0.01, self_collision=False)
    assert b.finalize().cloth_self_collision.tolist() == [True, False]
    with pytest.raises(InputError) as caught:
        ModelBuilder().add_cloth(size=(0.2, 0.2), resolution=(3, 3), mass=0.01, self_collision="yes")
    assert caught.value.field == "self_collision"
    with pytest.raises(InputError) as caught:  # 2 × 0.05 m of thickness against 0.07 m triangle heights
        ModelBuilder().add_cloth(size=(0.2, 0.2), resolution=(3, 3), mass=0.01, thickness=0.05)
    assert caught.value.field == "thickness" and "self_collision = false" in caught.value.message
    ModelBuilder().add_cloth(size=(0.2, 0.2), resolution=(3, 3), mass=0.01, thickness=0.05, self_collision=False)
