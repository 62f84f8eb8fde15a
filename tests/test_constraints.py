"""The constraints method (W4, C1–C9, F4, M2, M4) against closed-form results and against itself."""

import numpy as np
import pytest
from conftest import ball_on_plane, cube_on_plane
from hypothesis import given, settings
from hypothesis import strategies as st

from contactlab import ModelBuilder, simulate
from contactlab.collision import collide
from contactlab.contacts import jacobian
from contactlab.dynamics.generalized import inverse_mass_matrix, stack
from contactlab.dynamics.integrators import free_velocities
from contactlab.errors import InputError, SimulationDiverged
from contactlab.methods import constraints
from contactlab.methods.jacobian_rows import rows_of
from contactlab.methods.sequential import solve_order, solve_sequential_impulses, sweep_groups
from contactlab.scene import builtin_scenes, load_scene

G = 9.81
HALF = 0.05
# every step solved in small steps (sequential.solve_in_substeps), the contacts detected once: the
# closed forms below hold for it as for the whole-step solve (issue 38)
SUBSTEPPED = {"substeps": 8, "substep_when": "always"}
# sweeps (and collision waves) cut at 4, so that many steps end unconverged, with the
# shock-propagation pass (methods.shock)
SHOCKED = {"substeps": 1, "iterations": 4, "shock_sweeps": 8}
# each manifold's normals solved as one block (methods.blocks)
BLOCKS = {"substeps": 1, "block_solve": True}
WHOLE_OR_SUBSTEPPED = pytest.mark.parametrize("options", [{}, SUBSTEPPED], ids=["whole", "substepped"])
# shock propagation and block solves act where bodies rest on several contacts: the boxes' tests run them too
EVERY_SOLVE = pytest.mark.parametrize(
    "options", [{}, SUBSTEPPED, SHOCKED, BLOCKS], ids=["whole", "substepped", "shocked", "blocks"]
)


def apexes(height, velocity):
    turning = np.nonzero((velocity[:-1] > 0) & (velocity[1:] <= 0))[0]
    return np.array([height[i : i + 2].max() for i in turning])


@WHOLE_OR_SUBSTEPPED
@pytest.mark.parametrize("restitution", [0.0, 0.5, 0.8])
def test_bounce_apexes_follow_h0_eps_to_the_2n(restitution, options):
    model = ball_on_plane(restitution=restitution, height=1.0)
    fall = np.sqrt(2 / G)
    duration = fall * (1 + 2 * sum(restitution**k for k in range(1, 5)) + restitution**5) + 0.1
    run = simulate(model, "constraints", dt=0.001, duration=duration, options=options)
    z = run.arrays["body_position"][:, 0, 2] - 0.1
    found = apexes(z, run.arrays["body_velocity"][:, 0, 2])
    if restitution == 0.0:
        assert len(found) == 0
        np.testing.assert_allclose(z[run.arrays["time"] > fall + 0.01], 0.0, atol=1e-9)
    else:
        np.testing.assert_allclose(found[:5], restitution ** (2 * np.arange(1, 6)), rtol=0.01)


def test_velocities_stop_an_impact_and_accelerations_cannot():
    # C5b versus C5a: a ball dropped 0.5 m; on velocities it stops at the floor within the step,
    # on accelerations the floor only stops it from accelerating further into it
    model = ball_on_plane(height=0.5, restitution=0.0)
    on_velocities = simulate(model, "constraints", dt=0.004, duration=0.4)
    options = {"formulation": "acceleration", "stabilization": 0.0}
    on_accelerations = simulate(
        model, "constraints", dt=0.004, duration=0.4, options=options, allow_divergence=True
    )  # it sinks on through the floor
    impact_speed = np.sqrt(2 * G * 0.5)
    assert on_velocities.summary["max_penetration"] < 1e-9
    assert on_accelerations.summary["max_penetration"] > 0.5 * impact_speed * 0.004
    assert [v["check"] for v in on_accelerations.summary["health"]["violations"]] == ["depth"]
    # unless allowed, the health check stops the run once the ball's centre is behind the floor
    with pytest.raises(SimulationDiverged, match="behind a static plane: it went through") as stopped:
        simulate(model, "constraints", dt=0.004, duration=0.4, options=options)
    z = stopped.value.run.arrays["body_position"][:, 0, 2]
    assert z[-1] < -0.1 <= z[-2]  # the first sample with the centre a radius behind the floor


def test_acceleration_formulation_holds_a_resting_box():
    b = ModelBuilder()
    b.add_material("m", friction=0.5, restitution=0.0)
    b.add_body("box", half_extents=(HALF,) * 3, mass=1.0, position=(0, 0, HALF), material="m")
    b.add_obstacle("plane", normal=(0, 0, 1), material="m")
    run = simulate(b.finalize(), "constraints", dt=0.004, duration=1.0, options={"formulation": "acceleration"})
    np.testing.assert_allclose(run.arrays["body_position"][:, 0, 2], HALF, atol=1e-6)


@pytest.mark.parametrize(
    "options",
    [{"solver": solver} for solver in ("matrix_free", "nsgs", "staggered", "apgd", "newton")]
    + [SUBSTEPPED, SHOCKED, BLOCKS],
    ids=["matrix_free", "nsgs", "staggered", "apgd", "newton", "substepped", "shocked", "blocks"],
)
def test_sliding_block_stops_at_v2_over_2_mu_g(options):
    v0, mu = 3.0, 0.3
    model, _ = cube_on_plane(friction=mu, velocity=(v0, 0, 0))
    run = simulate(model, "constraints", dt=0.004, duration=1.2, options=options)
    x, vx = run.arrays["body_position"][:, 0, 0], run.arrays["body_velocity"][:, 0, 0]
    stopped = np.argmax(np.abs(vx) < 1e-6)
    np.testing.assert_allclose(run.arrays["time"][stopped], v0 / (mu * G), rtol=0.03)
    np.testing.assert_allclose(x[-1], v0**2 / (2 * mu * G), rtol=0.03)


@EVERY_SOLVE
@pytest.mark.parametrize("friction, sticks", [(0.5, True), (0.2, False)])
def test_incline_sticks_below_the_friction_angle_and_slides_above(friction, sticks, options):
    theta = np.radians(20.0)
    model, downhill = cube_on_plane(20.0, friction)
    run = simulate(model, "constraints", dt=0.004, duration=2.0, options=options)
    t = run.arrays["time"]
    along = (run.arrays["body_position"][:, 0] - run.arrays["body_position"][0, 0]) @ downhill
    if sticks:
        assert np.abs(along).max() < 0.001
    else:
        acceleration = 2 * np.polyfit(t[t > 0.2], along[t > 0.2], 2)[0]
        np.testing.assert_allclose(acceleration, G * (np.sin(theta) - friction * np.cos(theta)), rtol=0.03)


@WHOLE_OR_SUBSTEPPED
def test_sphere_goes_from_sliding_to_rolling_at_five_sevenths(options):
    v0, mu = 3.0, 0.3
    model = ball_on_plane(height=0.0, friction=mu, velocity=(v0, 0, 0))
    run = simulate(model, "constraints", dt=0.002, duration=0.6, options=options)
    t, v = run.arrays["time"], run.arrays["body_velocity"][:, 0, 0]
    rolling_at = 2 * v0 / (7 * mu * G)
    np.testing.assert_allclose(v[t > rolling_at + 0.01], 5 / 7 * v0, rtol=1e-3)
    sliding = (t > 0.02) & (t < rolling_at - 0.02)
    np.testing.assert_allclose(np.diff(v[sliding]) / np.diff(t[sliding]), -mu * G, rtol=1e-3)


@EVERY_SOLVE
@pytest.mark.parametrize("name", ["box_stack", "box_pyramid"])
def test_stacks_stand_for_ten_seconds(name, options):
    scene = load_scene(name)
    run = simulate(scene.model, "constraints", scene.dt, 10.0, options, record_every=20)
    moved = np.linalg.norm(run.arrays["body_position"] - run.arrays["body_position"][0], axis=2)
    assert moved.max() < 0.01
    assert run.summary["max_penetration"] < 0.005


def resting_spheres(rng, friction=0.0):
    """Spheres of mixed masses resting on a floor and on each other (every contact pressed)."""
    b = ModelBuilder()
    b.add_material("m", friction=friction, restitution=0.0)
    r = 0.1
    for i in range(4):
        b.add_body("sphere", radius=r, mass=rng.uniform(0.5, 3.0), position=(2.5 * r * i, 0, r), material="m")
    for i in range(3):  # each touches two of the row below
        b.add_body(
            "sphere",
            radius=r,
            mass=rng.uniform(0.5, 3.0),
            position=(2.5 * r * i + 1.25 * r, 0, r + np.sqrt((2 * r) ** 2 - (1.25 * r) ** 2)),
            material="m",
        )
    b.add_obstacle("plane", normal=(0, 0, 1), material="m")
    return b.finalize()


def contact_problem(model, dt=0.004):
    """The contacts, Jacobian, rows, free velocity and targets of the first step of ``model``."""
    state = model.state()
    options = constraints.Options()
    v_free = stack(*free_velocities(model, state, dt))
    contacts = collide(model, state, options.contact_margin)
    rows = rows_of(model, contacts, state.body_position, state.body_orientation)
    J = jacobian(contacts, state.body_position, model.body_count, model.particle_count)
    target = np.zeros((contacts.count, 3))
    gap = -contacts.depth
    target[:, 0] = np.maximum(-gap / dt, 0.0)  # no overlap at the end: v_n ≥ 0 here
    return state, contacts, rows, J, v_free, target


@pytest.mark.parametrize("friction", [0.0, 0.4])
def test_matrix_free_and_assembled_give_the_same_lambda(rng, friction):
    from contactlab.lcp import solve_friction_contact, solve_lcp

    model = resting_spheres(rng, friction)
    state, contacts, rows, J, v_free, target = contact_problem(model)
    assert contacts.count == 10
    u = v_free.copy()
    lam_free, _, change = solve_sequential_impulses(
        rows,
        contacts.friction,
        target[:, 0],
        u,
        (20000, 1e-14),
        np.zeros((contacts.count, 3)),
        sweep_groups(rows, contacts, state, solve_order(contacts, model.gravity)),
    )
    inverse = constraints.SystemInverse(inverse_mass=inverse_mass_matrix(model, state.body_orientation))
    B, q = constraints.lcp_matrices(J, inverse, v_free, target.ravel())
    if friction == 0.0:
        normal = np.arange(0, 3 * contacts.count, 3)
        exact = solve_lcp(B[normal][:, normal], -q[normal], method="lemke")
        assert exact.converged
        np.testing.assert_allclose(lam_free[:, 0], exact.lam, atol=1e-8)
        pgs = solve_lcp(B[normal][:, normal], -q[normal], method="pgs", tol=1e-13, max_iterations=20000)
        np.testing.assert_allclose(pgs.lam, exact.lam, atol=1e-8)
    else:
        result = solve_friction_contact(B, q, contacts.friction, method="nsgs", tol=1e-12, max_iterations=20000)
        np.testing.assert_allclose(lam_free.ravel(), result.r, atol=1e-8)
    # and the matrix-free velocities are v* + M⁻¹ Jᵀ λ
    np.testing.assert_allclose(u, v_free + inverse.solve(J.T @ lam_free.ravel()), atol=1e-10)


def sphere_column(rng):
    """Four frictionless spheres of mixed masses stacked straight up on the floor."""
    b = ModelBuilder()
    b.add_material("m", friction=0.0, restitution=0.0)
    for i in range(4):
        b.add_body("sphere", radius=0.1, mass=rng.uniform(0.5, 3.0), position=(0, 0, 0.1 + 0.2 * i), material="m")
    b.add_obstacle("plane", normal=(0, 0, 1), material="m")
    return b.finalize()


@pytest.mark.parametrize("solver", ["pgs", "redblack", "redblack_blocks", "jacobi", "lemke"])
def test_frictionless_lcp_solvers_hold_a_column(rng, solver):
    model = sphere_column(rng)
    run = simulate(
        model,
        "constraints",
        dt=0.004,
        duration=0.5,
        options={"solver": solver, "omega": 0.7 if solver == "jacobi" else 1.0, "iterations": 500},
    )
    moved = np.linalg.norm(run.arrays["body_position"] - run.arrays["body_position"][0], axis=2)
    assert moved.max() < 1e-3
    assert run.summary["max_penetration"] < 1e-3


def test_newton_holds_the_stack_with_the_reactions_of_converged_sweeps():
    """solver = "newton" in a run: the box stack stands, each step solved to its tolerance in a
    few Newton steps, and one step's reactions are those of nsgs converged far (an independent
    method on the same W, q)."""
    scene = load_scene("box_stack")
    run = simulate(scene.model, "constraints", scene.dt, 1.0, {"solver": "newton", "tolerance": 1e-10})
    moved = np.linalg.norm(run.arrays["body_position"] - run.arrays["body_position"][0], axis=2)
    assert moved.max() < 1e-3
    assert run.summary["solver"]["max_residual"] <= 1e-10
    assert run.summary["solver"]["max_iterations"] < 30
    state = run.state
    newton = constraints.step(scene.model, state, scene.dt, constraints.Options(solver="newton", tolerance=1e-12))
    sweeps = constraints.step(
        scene.model, state, scene.dt, constraints.Options(solver="nsgs", tolerance=1e-12, iterations=20000)
    )
    np.testing.assert_allclose(newton[0].body_velocity, sweeps[0].body_velocity, atol=1e-7)
    np.testing.assert_allclose(newton[0].body_position, sweeps[0].body_position, atol=1e-9)


def test_newton_and_apgd_refuse_the_friction_pyramid():
    for solver in ("newton", "apgd"):
        with pytest.raises(InputError, match="friction_model"):
            constraints.Options(solver=solver, friction_model="pyramid")


def test_residual_and_iterations_are_recorded():
    scene = load_scene("box_pyramid")
    run = simulate(scene.model, "constraints", scene.dt, 0.2, {"solver": "nsgs", "tolerance": 1e-8})
    assert run.arrays["solver_iterations"].shape == run.arrays["time"].shape
    sweeps, residual = run.arrays["solver_iterations"][1:], run.arrays["solver_residual"][1:]
    assert sweeps.max() >= 1
    # a step that made no sweep started within the tolerance: its warm start (last step's
    # reactions, by contact id, in a tangent basis that keeps its directions) already solved it
    assert np.all(residual[sweeps == 0] <= 1e-8)
    assert run.summary["solver"]["max_iterations"] == run.arrays["solver_iterations"].max()
    assert run.summary["solver"]["max_residual"] == pytest.approx(run.arrays["solver_residual"].max())


def test_cloth_with_implicit_springs_and_hard_constraints_runs_where_explicit_projection_cannot():
    # M4: 1/60 s; the symplectic cloth blows up at that step under projection
    b = ModelBuilder()
    b.add_material("m", friction=0.4, restitution=0.0)
    b.add_cloth(
        size=(0.6, 0.6),
        resolution=(9, 9),
        position=(0, 0, 0.3),
        mass=0.1,
        stretch_stiffness=1000.0,
        shear_stiffness=100.0,
        bend_stiffness=1.0,
        damping=0.01,
        thickness=0.004,
        material="m",
    )
    b.add_obstacle("sphere", radius=0.15, position=(0.0, 0.0, 0.0), material="m")
    b.add_obstacle("plane", normal=(0, 0, 1), material="m")
    model = b.finalize()
    with pytest.raises(SimulationDiverged):
        simulate(model, "projection", dt=1 / 60, duration=1.0)
    run = simulate(model, "constraints", dt=1 / 60, duration=1.5, integrator="backward_euler")
    assert run.state.is_finite()
    # the overlap, counted from the thickness at the vertices and between them (the sphere
    # reaches the triangles' middles, 75 mm from their corners): what the landing step lets in,
    # the stabilization pushes out a step at a time (a fifth of it a step), down to the slop
    slop = 0.0005
    excess = run.arrays["max_penetration"] - slop
    landed = int(np.argmax(excess > 0.0))
    assert landed > 0 and np.all(np.diff(excess[landed : landed + 20]) < 0.0)  # one sample a step
    assert excess[landed + 60] < 0.01 * excess[landed]  # a second after the landing
    assert excess[-1] < 1e-6
    kinetic = run.arrays["energy_kinetic"]
    assert kinetic[-1] < 0.05 * kinetic.max()  # it landed and is settling


def test_carried_values_follow_their_contact_ids():
    from contactlab.contacts import values_by_id

    previous_ids = np.array([50, 7, 31, 12], dtype=np.int64)
    previous = np.array([[5.0, 0.5], [0.7, 0.07], [3.1, 0.31], [1.2, 0.12]])
    values, found = values_by_id(previous_ids, previous, np.array([12, 99, 50, 7, 0]), 2)
    np.testing.assert_array_equal(found, [True, False, True, True, False])
    np.testing.assert_array_equal(values, [[1.2, 0.12], [0, 0], [5.0, 0.5], [0.7, 0.07], [0, 0]])
    empty, none = values_by_id(None, None, np.array([3, 4]), 3)
    assert empty.shape == (2, 3) and not empty.any() and not none.any()


@settings(max_examples=200, deadline=None)
@given(
    ids=st.lists(st.integers(0, 10**12), unique=True, max_size=40),
    kept=st.lists(st.booleans(), min_size=40, max_size=40),
    new=st.lists(st.integers(-5, 10**12), max_size=10),
    swaps=st.lists(st.integers(0, 45), max_size=6),
    shuffle=st.randoms(use_true_random=False),
    shuffled=st.booleans(),
)
def test_carried_values_match_a_lookup_by_id_in_any_order(ids, kept, new, swaps, shuffle, shuffled):
    """Contacts as they come step to step: last step's in order with some gone, some new ones
    between them and a few swapped a place or more (found at or near their expected place), or
    in any order (the sorted lookup): each value is the one its id had, whichever way it was
    found."""
    from contactlab.contacts import values_by_id

    previous_ids = np.array(ids, dtype=np.int64)
    previous = np.arange(3 * len(ids), dtype=float).reshape(-1, 3) + 0.5
    now = [i for i, keep in zip(ids, kept) if keep]
    for position, fresh in enumerate(new):
        now.insert(position * 7 % (len(now) + 1), fresh)
    for i in swaps:
        if i + 3 < len(now):
            now[i], now[i + 3] = now[i + 3], now[i]
    if shuffled:
        shuffle.shuffle(now)
    values, found = values_by_id(previous_ids, previous, np.array(now, dtype=np.int64), 3)
    lookup = dict(zip(ids, previous))
    assert found.tolist() == [i in lookup for i in now]
    np.testing.assert_array_equal(values, np.reshape([lookup.get(i, np.zeros(3)) for i in now], (-1, 3)))


def test_each_body_moves_to_its_earliest_impact_first():
    from contactlab.methods.velocity_level import earliest_impacts

    model, _ = cube_on_plane()
    contacts = collide(model, model.state(), 0.01)
    assert contacts.count == 4
    sides = (contacts.body_a, contacts.body_b, contacts.particles_a, contacts.particles_b)
    tau = np.array([-1.0, 0.6, 0.25, -1.0])
    tau_body, tau_particle = earliest_impacts(*sides, tau, model.body_count, model.particle_count)
    np.testing.assert_array_equal(tau_body, [0.25])
    assert tau_particle.shape == (0,)
    no_impact = earliest_impacts(*sides, np.full(4, -1.0), model.body_count, model.particle_count)
    np.testing.assert_array_equal(no_impact[0], [0.0])


def draped_cloth(n=8):
    """An n × n cloth (0.5 m, 50 g, stiff springs) lying over a sphere and the floor, after 0.4 s
    under constraints with backward Euler at 1/120 s: (model, state) with many vertex contacts."""
    b = ModelBuilder()
    b.add_material("m", friction=0.4, restitution=0.0)
    b.add_cloth(
        size=(0.5, 0.5),
        resolution=(n, n),
        position=(0, 0, 0.25),
        mass=0.05,
        stretch_stiffness=1000.0,
        shear_stiffness=100.0,
        bend_stiffness=1.0,
        damping=0.01,
        thickness=0.004,
        material="m",
    )
    b.add_obstacle("sphere", radius=0.1, position=(0.05, 0.0, 0.0), material="m")
    b.add_obstacle("plane", normal=(0, 0, 1), material="m")
    model = b.finalize()
    return model, simulate(model, "constraints", dt=1 / 120, duration=0.4, integrator="backward_euler").state


def test_implicit_cloth_free_velocities_from_the_factor_equal_conjugate_gradients():
    model, state = draped_cloth()
    by_factor, inverse = constraints.implicit_free_velocities(model, state, 1 / 120)
    by_cg = free_velocities(model, state, 1 / 120, "backward_euler", linear_tolerance=1e-13)
    for a, b in zip(by_factor, by_cg):
        np.testing.assert_allclose(a, b, atol=1e-10)
    assert inverse.factor is not None


def test_implicit_cloth_products_reach_the_assembled_answer():
    # matrix_free on implicit cloth solves with products J A⁻¹ Jᵀ x (apgd); nsgs sweeps the assembled
    # W = J A⁻¹ Jᵀ: converged, both give the step's one answer
    model, state = draped_cloth()
    contacts = collide(model, state, constraints.Options().contact_margin)
    assert contacts.count > 20
    h = 1 / 120
    steps = {}
    for solver in ("matrix_free", "nsgs"):
        options = constraints.Options(solver=solver, iterations=50000, tolerance=1e-10, warm_start=0.0)
        steps[solver] = constraints.step(model, state, h, options, "backward_euler")
    (by_products, info), (by_rows, _) = steps["matrix_free"], steps["nsgs"]
    assert info.solver_residual <= 1e-10
    np.testing.assert_allclose(by_products.particle_velocity, by_rows.particle_velocity, atol=1e-6)
    np.testing.assert_allclose(
        by_products.carried.values,
        by_rows.carried.values,
        atol=1e-6 * np.abs(by_rows.carried.values).max(),
    )


def test_implicit_cloth_whose_only_contact_is_a_pinned_vertex_runs():
    # the pinned corner starts inside a sphere: its contact's row of W = J A⁻¹ Jᵀ is zero, so W = 0
    b = ModelBuilder()
    b.add_material("m", friction=0.4, restitution=0.0)
    b.add_cloth(
        size=(0.4, 0.4),
        resolution=(5, 5),
        position=(0, 0, 0.3),
        mass=0.05,
        stretch_stiffness=1000.0,
        shear_stiffness=100.0,
        bend_stiffness=1.0,
        damping=0.01,
        thickness=0.004,
        material="m",
        pinned=[0],
    )
    b.add_obstacle("sphere", radius=0.05, position=(-0.2, -0.2, 0.3), material="m")
    model = b.finalize()
    run = simulate(model, "constraints", dt=1 / 120, duration=0.05, integrator="backward_euler")
    assert run.summary["max_contacts"] >= 1 and run.state.is_finite()
    np.testing.assert_array_equal(run.state.particle_position[0], model.initial.particle_position[0])


def test_compiled_delassus_product_gives_the_bits_of_the_sparse_solves():
    # apgd's product W x = J A⁻¹ Jᵀ x in one compiled call, against SciPy's products around the
    # factor's own solve (SystemInverse.solve, pinned DOFs held): the same sums in the same order
    model, state = draped_cloth()
    contacts = collide(model, state, constraints.Options().contact_margin)
    _, inverse = constraints.implicit_free_velocities(model, state, 1 / 120)
    J = jacobian(contacts, state.body_position, model.body_count, model.particle_count)
    assert isinstance(inverse.factor, constraints.CholeskyFactor)  # so the compiled product serves
    operator = constraints.delassus_operator(J, inverse)
    x = np.random.default_rng(3).normal(size=J.shape[0])
    np.testing.assert_array_equal(operator @ x, J @ inverse.solve(J.T @ x))


def test_delassus_bound_lies_above_the_largest_eigenvalue_of_j_a_inverse_jt():
    model, state = draped_cloth()
    contacts = collide(model, state, constraints.Options().contact_margin)
    _, inverse = constraints.implicit_free_velocities(model, state, 1 / 120)
    J = jacobian(contacts, state.body_position, model.body_count, model.particle_count)
    W = constraints.delassus_operator(J, inverse)
    dense = W.matmat(np.eye(W.shape[0]))
    largest = np.linalg.eigvalsh(0.5 * (dense + dense.T)).max()
    bound = constraints.delassus_bound(J, inverse_mass_matrix(model, state.body_orientation))
    assert largest <= bound
    assert bound < 10 * largest  # and near enough to serve as apgd's step


@pytest.mark.parametrize(
    "table, field",
    [
        ({"solver": "gauss"}, "solver"),
        ({"formulation": "force"}, "formulation"),
        ({"omega": 2.5}, "omega"),
        ({"iterations": 0}, "iterations"),
        ({"friction_model": "disk"}, "friction_model"),
        ({"substeps": 0}, "substeps"),
        ({"substep_sweeps": 0}, "substep_sweeps"),
        ({"substep_when": "never"}, "substep_when"),
    ],
)
def test_bad_options_name_the_field(table, field):
    with pytest.raises(InputError, match=field):
        constraints.Options(**table)


@pytest.mark.parametrize("name", [name for name, _ in builtin_scenes()])
def test_runs_every_built_in_scene(name):
    scene = load_scene(name)
    run = simulate(
        scene.model,
        "constraints",
        scene.dt,
        25 * scene.dt,
        scene.method_options.get("constraints", {}),
        scene.integrator,
    )
    assert run.state.is_finite()
    assert run.summary["max_penetration"] < 0.01


@pytest.mark.parametrize("method", ["constraints", "impulse"])
def test_a_step_the_sweeps_converge_is_the_plain_solve_bit_for_bit(method):
    """Substeps take only a step that ``substep_after`` sweeps leave above the tolerance: a run whose
    every step converges sooner is the run without substeps, to the last bit."""
    scene = load_scene("box_stack")
    plain = simulate(scene.model, method, scene.dt, 1.0, {"substeps": 1})
    assert plain.arrays["solver_iterations"].max() <= constraints.Options().substep_after
    default = simulate(scene.model, method, scene.dt, 1.0)
    for name in ("body_position", "body_orientation", "body_velocity", "solver_residual"):
        np.testing.assert_array_equal(default.arrays[name], plain.arrays[name])


def test_substeps_hold_a_pile_the_same_sweeps_cannot():
    """Eight substeps of one sweep against eight whole-step sweeps on a pile of 150 spheres dropped
    into a box: no more sweeps a step, and the substeps leave the shallower overlaps (small steps,
    issue 38): what one substep's sweep leaves undone shows in its gaps, which the next
    substep's targets correct within the step."""
    b = ModelBuilder()
    b.add_material("m", friction=0.5, restitution=0.0)
    for k in range(6):
        shift = 0.005 * (k % 2)
        for i in range(5):
            for j in range(5):
                position = (shift + 0.11 * (i - 2), shift + 0.11 * (j - 2), 0.06 + 0.11 * k)
                b.add_body("sphere", radius=0.05, mass=1.0, position=position, material="m")
    b.add_obstacle("plane", normal=(0, 0, 1), material="m")
    for normal in ((1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0)):
        b.add_obstacle("plane", normal=normal, offset=-0.28, material="m")
    model = b.finalize()
    whole = simulate(model, "constraints", 1 / 240, 1.5, {"iterations": 8, "substeps": 1}, record_every=4)
    small = simulate(model, "constraints", 1 / 240, 1.5, {"substeps": 8, "substep_when": "always"}, record_every=4)
    assert small.arrays["solver_iterations"].max() <= 8  # one sweep a substep: no more than the whole step's cap
    # 0.72 mm against 0.94 mm (deterministic: the same on any thread count); on the 1000-sphere
    # pile 8 substeps hold 0.96-1.07 mm where 10 whole-step sweeps leave 1.9 mm (benchmarks/README.md)
    assert small.summary["max_penetration"] < 0.8 * whole.summary["max_penetration"]


def test_the_accelerations_formulation_sweeps_to_its_iteration_cap_not_to_substep_after():
    """Only the velocity formulation goes on in substeps after ``substep_after`` whole-step
    sweeps; the accelerations formulation has none to go on with, so a slow solve there takes
    every sweep ``iterations`` allows (it stopped at 12 before)."""
    b = ModelBuilder()
    b.add_material("m", friction=0.5, restitution=0.0)
    spacing = 0.1 - 1e-3  # a lattice of spheres, each overlapping its neighbours by 1 mm: jammed
    for i in range(5):
        for j in range(5):
            for k in range(4):
                position = (i * spacing, j * spacing, 0.05 - 5e-4 + k * spacing)
                b.add_body("sphere", radius=0.05, mass=1.0 + 0.1 * ((i + 2 * j + 3 * k) % 5), position=position)
    b.add_obstacle("plane", normal=(0, 0, 1), material="m")
    model = b.finalize()
    options = constraints.Options(formulation="acceleration", iterations=60, tolerance=1e-12)
    state, info = constraints.step(model, model.state(), 1 / 240, options)
    assert options.substep_after < info.solver_iterations <= 60


def touching_pyramid(levels):
    """A 2-D pyramid of 0.1 m boxes (1 kg, μ 0.6) whose rows' boxes touch side to side."""
    b = ModelBuilder()
    b.add_material("wood", friction=0.6, restitution=0.0)
    for level in range(levels):
        n = levels - level
        for i in range(n):
            position = ((i - (n - 1) / 2) * 0.1, 0.0, 0.05 + 0.1 * level)
            b.add_body("box", half_extents=(0.05, 0.05, 0.05), mass=1.0, position=position, material="wood")
    b.add_obstacle("plane", normal=(0, 0, 1), material="wood")
    return b.finalize()


def test_a_substepped_step_whose_sweeps_ran_to_their_cap_carries_their_answer():
    """A step the whole-step sweeps leave above the tolerance after ``substep_after`` sweeps
    (close: not given up) goes on in substeps, and carries the whole-step answer to the next
    step as its warm start, not the substeps' sum: the same impulses, bit for bit, as a step
    capped at those sweeps with no substeps, while the boxes move as the substeps moved them."""
    model = touching_pyramid(4)
    options = constraints.Options()
    default, info = constraints.step(model, model.state(), 1 / 240, options)
    assert info.solver_iterations == options.substep_after + options.substeps  # ran to the cap, then substeps
    plain = constraints.Options(substeps=1, iterations=options.substep_after)
    capped, capped_info = constraints.step(model, model.state(), 1 / 240, plain)
    assert capped_info.solver_iterations == options.substep_after
    np.testing.assert_array_equal(info.impulses, capped_info.impulses)
    assert not np.array_equal(default.body_velocity, capped.body_velocity)


def test_a_pyramid_of_touching_boxes_stands_and_its_steps_converge_without_substeps():
    """Touching boxes with friction are statically indeterminate (a box's weight can rest on its
    neighbours' side friction as well as on the boxes below). Warm-started from the whole-step
    answer of the steps that needed substeps, the sweeps settle: after the first steps nearly
    every step converges within ``substep_after`` sweeps, and no box moves 1 mm in 1 s. (With
    the substeps' sum carried on, the steps kept stalling just above the tolerance: 18.3 sweeps a
    step on the 20-level pyramid against 3.7 now.)"""
    model = touching_pyramid(10)
    run = simulate(model, "constraints", 1 / 240, 1.0)
    sweeps = run.arrays["solver_iterations"][1:]
    # 24 of the 240 steps, the first ones among them (150 with the substeps' sum carried on)
    assert np.count_nonzero(sweeps > constraints.Options().substep_after) <= 40
    travel = np.linalg.norm(run.arrays["body_position"] - run.arrays["body_position"][0], axis=2)
    assert travel.max() < 1e-3
