"""The matrix-free Gauss-Seidel sweeps (methods.sequential) split over threads (C8): the groups
share nothing that moves, the parallel sweep is bit for bit the serial sweep in the grouped
order, and it converges to the same velocities as the plain serial order."""

import numpy as np
import pytest

from contactlab import ModelBuilder, collide
from contactlab.dynamics.generalized import stack
from contactlab.dynamics.integrators import free_velocities
from contactlab.methods import jacobian_rows, sequential

RADIUS = 0.05
DT = 1 / 240


def sphere_lattice(side=6, layers=8, overlap=1e-3, friction=0.0):
    """side × side × layers spheres on a floor, each touching its six neighbours with ``overlap``
    [m], and one pinned-free particle row on top so that particle sides are covered too."""
    b = ModelBuilder()
    b.add_material("m", friction=friction, restitution=0.0)
    spacing = 2 * RADIUS - overlap
    for i in range(side):
        for j in range(side):
            for k in range(layers):
                b.add_body(
                    "sphere",
                    radius=RADIUS,
                    mass=1.0 + 0.1 * ((i + 2 * j + 3 * k) % 5),
                    position=(i * spacing, j * spacing, RADIUS - overlap / 2 + k * spacing),
                    material="m",
                )
    top = RADIUS - overlap / 2 + (layers - 1) * spacing + RADIUS + 0.01 - overlap
    b.add_particles([[i * spacing, 0.0, top] for i in range(side)], mass=0.2, radius=0.01, material="m")
    b.add_obstacle("plane", normal=(0, 0, 1), material="m")
    return b.finalize()


def problem(model):
    state = model.state()
    contacts = collide(model, state, 0.002)
    rows = jacobian_rows.rows_of(model, contacts, state.body_position, state.body_orientation)
    order = sequential.solve_order(contacts, model.gravity)
    u = stack(*free_velocities(model, state, DT))
    target = np.maximum(contacts.depth / DT * 0.2, 0.0)  # push a fifth of each overlap out
    return state, contacts, rows, order, u, target


def entities(contacts, model, c):
    """The movable bodies and particles of contact c, as ("b", i) / ("p", j)."""
    found = set()
    for body, particles in (
        (contacts.body_a[c], contacts.particles_a[c]),
        (contacts.body_b[c], contacts.particles_b[c]),
    ):
        if body >= 0:
            found.add(("b", int(body)))
        found.update(("p", int(p)) for p in particles if p >= 0 and model.particle_inverse_mass[p] > 0)
    return found


def test_groups_share_nothing_that_moves_and_keep_the_sweep_order():
    model = sphere_lattice()
    state, contacts, rows, order, u, target = problem(model)
    assert contacts.count > 700
    grouped, starts = sequential.sweep_groups(rows, contacts, state, order, groups=2, min_contacts=0)
    assert sorted(grouped.tolist()) == list(range(contacts.count))  # a permutation
    assert starts[0] == 0 and starts[-1] == contacts.count and np.all(np.diff(starts) >= 0)
    owners = {}
    rank = np.empty(contacts.count, dtype=int)
    rank[order] = np.arange(contacts.count)
    for g in range(len(starts) - 1):
        members = grouped[starts[g] : starts[g + 1]]
        assert np.all(np.diff(rank[members]) > 0)  # each group in sweep order
        if g == len(starts) - 2:
            continue  # the spanning group runs alone
        for c in members:
            for entity in entities(contacts, model, c):
                assert owners.setdefault(entity, g) == g  # never in two parallel groups
    sizes = np.diff(starts)
    assert min(sizes[:2]) > 0.3 * contacts.count and sizes[2] < 0.2 * contacts.count  # balanced, few spanning


def test_parallel_sweep_is_the_serial_sweep_in_the_grouped_order_bit_for_bit():
    model = sphere_lattice(friction=0.5)
    state, contacts, rows, order, u0, target = problem(model)
    grouped, starts = sequential.sweep_groups(rows, contacts, state, order, groups=2, min_contacts=0)
    assert len(starts) == 4
    warm = np.zeros((contacts.count, 3))
    u_parallel, u_serial = u0.copy(), u0.copy()
    lam_parallel, sweeps, _ = sequential.solve_sequential_impulses(
        rows, contacts.friction, target, u_parallel, (30, -1.0), warm, (grouped, starts)
    )
    lam_serial, _, _ = sequential.solve_sequential_impulses(
        rows,
        contacts.friction,
        target,
        u_serial,
        (30, -1.0),
        warm,
        (grouped, np.array([0, contacts.count, contacts.count])),
    )
    assert sweeps == 30
    np.testing.assert_array_equal(lam_parallel, lam_serial)
    np.testing.assert_array_equal(u_parallel, u_serial)


def test_parallel_sweeps_converge_to_the_velocities_of_the_plain_order():
    """Frictionless, so the converged velocities are unique (a monotone LCP): the grouped
    parallel order and the plain top-to-bottom order must agree, and meet every target."""
    model = sphere_lattice()
    state, contacts, rows, order, u0, target = problem(model)
    grouped, starts = sequential.sweep_groups(rows, contacts, state, order, groups=2, min_contacts=0)
    results = []
    for sweep_order, sweep_starts in ((grouped, starts), (order, np.array([0, contacts.count, contacts.count]))):
        u = u0.copy()
        lam, sweeps, change = sequential.solve_sequential_impulses(
            rows,
            contacts.friction,
            target,
            u,
            (20000, 1e-13),
            np.zeros((contacts.count, 3)),
            (sweep_order, sweep_starts),
        )
        assert change <= 1e-13
        vn = jacobian_rows.row_products(rows, u)[:, 0]
        assert np.all(vn >= target - 1e-9)  # every contact meets its target
        assert np.all(lam[:, 0] * (vn - target) <= 1e-9)  # complementary
        results.append(u)
    np.testing.assert_allclose(results[0], results[1], atol=1e-8)


@pytest.mark.parametrize("size, groups", [((3, 3), 2), ((6, 8), 1)])
def test_below_the_threshold_or_in_one_group_the_sweep_is_serial(size, groups):
    model = sphere_lattice(*size)
    state, contacts, rows, order, u, target = problem(model)
    grouped, starts = sequential.sweep_groups(rows, contacts, state, order, groups=groups)
    assert groups == 1 or contacts.count < sequential.PARALLEL_MIN_CONTACTS
    np.testing.assert_array_equal(grouped, order)
    assert starts is None  # one group: the serial sweep, nothing parallel compiled
    lam, sweeps, _ = sequential.solve_sequential_impulses(
        rows, contacts.friction, target, u.copy(), (20, -1.0), np.zeros((contacts.count, 3)), (grouped, starts)
    )
    lam_array, _, _ = sequential.solve_sequential_impulses(
        rows,
        contacts.friction,
        target,
        u.copy(),
        (20, -1.0),
        np.zeros((contacts.count, 3)),
        (grouped, np.array([0, contacts.count, contacts.count])),
    )
    np.testing.assert_array_equal(lam, lam_array)  # the same sweep as one group given explicitly


def test_sweep_order_is_highest_first_with_ties_scrambled_by_id(rng):
    # the compiled order equals NumPy's lexsort by (−height, scramble), ties of both by index
    for count in (0, 1, 7, 500, 5000):
        height = np.round(rng.choice(rng.uniform(-1, 3, max(1, count // 6)), count), 9)
        scramble = rng.integers(0, 40, count)
        order = sequential._order_ties(np.argsort(-height), height, scramble)
        np.testing.assert_array_equal(order, np.lexsort((scramble, -height)))
    model = sphere_lattice()
    contacts = collide(model, model.state(), 0.002)
    order = sequential.solve_order(contacts, model.gravity)
    height = contacts.point[order, 2]
    assert np.all(np.diff(height) <= 1e-9)  # top to bottom
    assert sorted(order.tolist()) == list(range(contacts.count))


def test_compiled_order_sorts_heights_by_their_bits_as_numpy_sorts_the_floats(rng):
    # contact_order sorts int64 keys made of −height's bits: the same order as NumPy's lexsort
    # of the rounded floats, ties (equal heights, +0 and −0 among them) by scramble then index
    gravity = np.array([0.0, 0.0, -9.81])
    for count in (0, 1, 2, 17, 300, 3000):
        point = rng.normal(size=(count, 3))
        point[:, 2] = rng.choice(np.r_[0.0, -0.0, 1e-12, -1e-12, rng.uniform(-5, 5, max(1, count // 7))], count)
        feature_id = rng.integers(0, 1 << 40, count)
        height = np.round(point[:, 2], 9)
        scramble = ((feature_id.astype(np.uint64) * np.uint64(2654435761)) % np.uint64(4294967291)).astype(np.int64)
        expected = np.lexsort((np.arange(count), scramble, -height))
        np.testing.assert_array_equal(sequential.contact_order(point, feature_id, gravity), expected)


def test_argsort_of_ids_is_numpys_for_distinct_keys_and_sorts_repeats(rng):
    from contactlab.contacts import argsort_keys

    for count in (0, 1, 2, 16, 17, 40, 1000, 5000):
        keys = rng.choice(1 << 50, count, replace=False).astype(np.int64) - (1 << 49)
        np.testing.assert_array_equal(argsort_keys(keys), np.argsort(keys, kind="stable"))
        np.testing.assert_array_equal(argsort_keys(np.sort(keys)), np.arange(count))  # already sorted
        np.testing.assert_array_equal(argsort_keys(np.sort(keys)[::-1].copy()), np.arange(count)[::-1])
        repeated = rng.integers(0, 4, count)
        order = argsort_keys(repeated)
        assert sorted(order.tolist()) == list(range(count))  # a permutation
        np.testing.assert_array_equal(repeated[order], np.sort(repeated))


def test_a_stack_stops_on_a_sweeps_net_change_where_single_updates_never_settle():
    """Ten boxes stacked, settled: each box stands on four corners, so the load's split among
    them is not unique, and single updates keep trading impulse between corners long after the
    velocities have stopped changing. The sweeps stop once a whole sweep changes no contact's
    velocity by more than the tolerance, well before the cap, though one more sweep's largest
    single update is still far above it."""
    from contactlab import simulate
    from contactlab.collision import DetectionSettings, collide_keeping, swept_distances
    from contactlab.contacts import values_by_id
    from contactlab.methods import impulse
    from contactlab.methods.loop_stages import loop_settings
    from contactlab.methods.velocity_level import resting_targets
    from contactlab.scene import load_scene

    scene = load_scene("box_stack")
    model, dt = scene.model, scene.dt
    state = simulate(model, "impulse", dt, 0.5).state
    # the stack settles on the even split of each box's load that its new contacts' warm start
    # gives (velocity_level.guess_new_impulses), a fixed point of the sweeps; split it unevenly
    # (+30 % and −30 % in turn) and let it settle again: the corners then trade impulse
    values = state.carried.values.copy()  # the impulses [N s]
    values[:, 0] *= np.resize([1.3, 0.7], len(values))
    state.carried = state.carried._replace(values=values)
    state = simulate(model, "impulse", dt, 0.35, state=state).state
    options = impulse.Options()
    v, w, p = free_velocities(model, state, dt)
    settings = DetectionSettings(options.contact_margin, options.granularity, options.normal, options.samples)
    contacts, _ = collide_keeping(
        model, state, state.carried.manifolds, options.manifold_tolerance, settings, swept_distances(model, v, w, p, dt)
    )
    rows = jacobian_rows.rows_of(model, contacts, state.body_position, state.body_orientation)
    order = sequential.solve_order(contacts, model.gravity)
    warm, found = values_by_id(*state.carried.of("impulse"), contacts.feature_id, 3)
    assert found.all()  # every contact warm-started
    target = resting_targets(-contacts.depth, loop_settings(model, "impulse", options, dt))
    u = stack(v, w, p)
    lam, sweeps, change = sequential.solve_sequential_impulses(
        rows, contacts.friction, target, u, (100, 1e-7), warm, (order, np.array([0, contacts.count, contacts.count]))
    )
    assert sweeps < 50 and change <= 1e-7
    before = u.copy()
    largest_update = sequential.sweep_contacts(order, contacts.count, target, lam, rows, contacts.friction, u)
    assert largest_update > 10 * 1e-7  # the single-update rule would have gone on
    assert sequential.largest_row_change(rows, u, before) < largest_update


def _solve(problem_of, cap, give_up):
    """The lattice's solve from a zero warm start, capped at ``cap`` sweeps to 1e-7 m/s."""
    contacts, rows, order, u0, target = problem_of
    u = u0.copy()
    lam, sweeps, change = sequential.solve_sequential_impulses(
        rows, contacts.friction, target, u, (cap, 1e-7), np.zeros((contacts.count, 3)), (order, None), give_up
    )
    return lam, u, sweeps, change


def test_a_solve_that_cannot_reach_the_tolerance_within_its_cap_gives_up_at_its_fourth_sweep():
    """A stacked lattice pushed out of its overlaps from no warm start converges far more slowly
    than a change falling 0.3-fold a sweep (FASTEST_RATE): with substeps to follow, its
    whole-step solve stops at sweep GIVE_UP_AT, exactly where a solve capped there would; a
    ``give_up`` just above that sweep's change lets it go on, exactly as a solve never given up."""
    model = sphere_lattice(friction=0.5)
    state, contacts, rows, order, u0, target = problem(model)
    lattice = (contacts, rows, order, u0, target)
    cap, at = 12, sequential.GIVE_UP_AT
    hopeless = sequential.hopeless_change(cap, 1e-7)
    assert hopeless == pytest.approx(1e-7 / sequential.FASTEST_RATE ** (cap - at))
    lam_at, u_at, sweeps_at, change_at = _solve(lattice, at, np.inf)  # capped there: its change exact
    assert sweeps_at == at and change_at > hopeless  # hopeless indeed
    lam, u, sweeps, change = _solve(lattice, cap, hopeless)
    assert sweeps == at and change > hopeless  # a lower bound, but above the line
    np.testing.assert_array_equal(lam, lam_at)
    np.testing.assert_array_equal(u, u_at)
    # a line just above the fourth sweep's change: the solve goes on to its cap, as if never given up
    lam_on, u_on, sweeps_on, change_on = _solve(lattice, cap, change_at * 1.01)
    lam_all, u_all, sweeps_all, change_all = _solve(lattice, cap, np.inf)
    assert sweeps_on == sweeps_all == cap
    np.testing.assert_array_equal(lam_on, lam_all)
    np.testing.assert_array_equal(u_on, u_all)
    assert change_on == change_all
