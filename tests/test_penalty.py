"""The penalty method (L1, P1–P5, D1, F3, M1) against closed-form results."""

import warnings

import numpy as np
import pytest
from conftest import ball_on_plane, cube_on_plane

from contactlab import ModelBuilder, collide, simulate
from contactlab.contacts import Contacts, jacobian, tangent_basis
from contactlab.dynamics.generalized import inverse_mass_matrix, unstack
from contactlab.dynamics.integrators import world_inverse_inertia
from contactlab.errors import InputError, SimulationDiverged
from contactlab.methods import jacobian_rows, penalty
from contactlab.scene import builtin_scenes, load_scene
from contactlab.state import Carry

G = 9.81
HALF = 0.05  # half edge of the test cubes [m]


def resting_cube(angle_degrees=0.0, friction=0.5, stiffness=1e4, mass=1.0, velocity=(0, 0, 0)):
    """A cube on a plane tilted by ``angle``, its four corners sunk to the static penetration
    m g cosθ / (4 k) of the springs. Returns (model, downhill unit vector)."""
    sink = mass * G * np.cos(np.radians(angle_degrees)) / (4 * stiffness)
    return cube_on_plane(angle_degrees, friction, mass, velocity, sink, HALF)


# ---- P1, P3: the normal spring ---------------------------------------------------------------


@pytest.mark.parametrize("integrator", ["symplectic_euler", "backward_euler"])
def test_resting_box_sinks_m_g_over_k_times_contacts(integrator):
    k = 2e4
    b = ModelBuilder()
    b.add_material("m", friction=0.5, restitution=0.0)
    b.add_body("box", half_extents=(HALF, HALF, HALF), mass=2.0, position=(0, 0, HALF + 0.01), material="m")
    b.add_obstacle("plane", normal=(0, 0, 1), material="m")
    run = simulate(b.finalize(), "penalty", dt=0.001, duration=1.0, options={"stiffness": k}, integrator=integrator)
    settled = run.arrays["time"] > 0.8
    depth = HALF - run.arrays["body_position"][settled, 0, 2]
    np.testing.assert_allclose(depth, 2.0 * G / (k * 4), rtol=0.02)
    assert (run.arrays["contact_count"][settled] == 4).all()


def test_elastic_energy_is_half_k_delta_squared_and_its_gradient_the_force():
    k = 5e3
    model = ball_on_plane(height=-0.004, friction=0.0)  # sunk 4 mm
    state = model.state()
    options = penalty.Options(stiffness=k, damping_ratio=0.0)
    _, info = penalty.step(model, state, 1e-9, options)  # a step too short to move
    np.testing.assert_allclose(info.energy_elastic, 0.5 * k * 0.004**2, rtol=1e-6)
    # F = −∇E with ∇δ = −n: the force along n equals the energy's slope against the depth
    springs = penalty.ContactSprings(
        np.array([k]), np.zeros(1), np.array([k]), np.zeros(1), np.zeros(1), np.zeros((1, 2))
    )
    forces, _ = penalty.contact_spring_forces(springs, np.array([0.004]), np.zeros((1, 3)))

    def energy(d):
        return penalty.elastic_energy(springs, np.array([d]), np.zeros((1, 2)))

    slope = (energy(0.004 + 1e-7) - energy(0.004 - 1e-7)) / 2e-7
    np.testing.assert_allclose(forces[0], [slope, 0, 0], rtol=1e-6)


def test_damping_is_optional_and_never_pulls():
    springs = penalty.ContactSprings(
        np.full(3, 1e4), np.full(3, 50.0), np.full(3, 1e4), np.zeros(3), np.zeros(3), np.zeros((3, 2))
    )
    depth = np.array([0.001, 0.001, -0.001])
    velocity = np.array([[-0.1, 0, 0], [1.0, 0, 0], [-1.0, 0, 0]])  # approaching, leaving fast, apart
    forces, _ = penalty.contact_spring_forces(springs, depth, velocity)
    np.testing.assert_allclose(forces[:, 0], [10.0 + 5.0, 0.0, 0.0])  # kδ − c v_n, clamped at 0
    undamped = penalty.ContactSprings(
        np.full(3, 1e4), np.zeros(3), np.full(3, 1e4), np.zeros(3), np.zeros(3), np.zeros((3, 2))
    )
    forces, _ = penalty.contact_spring_forces(undamped, depth, velocity)
    np.testing.assert_allclose(forces[:, 0], [10.0, 10.0, 0.0])  # the slide: F = k δ n exactly


def test_restitution_sets_the_damping_ratio():
    eps = np.array([0.0, 0.5, 0.8, 1.0])
    zeta = penalty.damping_ratio_from_restitution(eps)
    np.testing.assert_allclose(zeta[[0, 3]], [1.0, 0.0])
    inner = zeta[1:3]
    np.testing.assert_allclose(np.exp(-inner * np.pi / np.sqrt(1 - inner**2)), eps[1:3], rtol=1e-12)


# ---- energy (P3, M1) ---------------------------------------------------------------------------


def test_undamped_bouncing_ball_keeps_its_energy_with_symplectic_euler():
    drop, k, dt = 0.05, 2500.0, 0.0005  # contact period 2π/√(k/m) = 126 ms = 251 steps
    model = ball_on_plane(height=drop, friction=0.0)
    run = simulate(
        model, "penalty", dt=dt, duration=2.8, options={"stiffness": k, "damping_ratio": 0.0}, record_every=4
    )
    a = run.arrays
    total = a["energy_kinetic"] + a["energy_potential"] + a["energy_elastic"]  # potential zero on the floor
    vz = a["body_velocity"][:, 0, 2]
    bounces = np.count_nonzero((vz[:-1] < 0) & (vz[1:] >= 0))
    assert bounces >= 10
    np.testing.assert_allclose(total, total[0], rtol=0.01)
    # symplectic Euler's energy error is bounded and of order h ω: it does not accumulate
    assert abs(total[-1] - total[0]) < 0.2 * np.abs(total - total[0]).max() + 1e-3 * total[0]
    assert a["energy_elastic"].max() > 0.5 * G * drop  # the springs did hold it


def test_backward_euler_loses_energy_and_never_gains():
    drop, k = 0.1, 1e4
    model = ball_on_plane(height=drop, friction=0.0)
    run = simulate(
        model,
        "penalty",
        dt=0.002,
        duration=1.0,
        options={"stiffness": k, "damping_ratio": 0.0},
        integrator="backward_euler",
    )
    a = run.arrays
    total = a["energy_kinetic"] + a["energy_potential"] + a["energy_elastic"]
    assert (np.diff(total) <= 1e-9).all()
    assert total[-1] < total[0] - 0.1 * G * drop


def test_implicit_stays_stable_where_explicit_blows_up():
    k, dt = 1e6, 0.004  # h √(2k/m) = 5.7 for the squeezed 1 kg ball: explicit cannot follow
    b = ModelBuilder()
    b.add_material("m", friction=0.0, restitution=0.0)
    b.add_body("sphere", radius=0.1, mass=1.0, position=(0, 0, 0.1), velocity=(0, 0, 0.1), material="m")
    b.add_obstacle("plane", normal=(0, 0, 1), offset=0.0, material="m")  # floor
    b.add_obstacle("plane", normal=(0, 0, -1), offset=-0.199, material="m")  # a plate 1 mm too low
    model = b.finalize()
    options = {"stiffness": k, "damping_ratio": 0.0}
    with pytest.raises(SimulationDiverged, match="too long for penalty stiffness 1e[+]06 N/m.*backward_euler"):
        simulate(model, "penalty", dt=dt, duration=2.0, options=dict(options, implicit_springs="never"))
    run = simulate(model, "penalty", dt=dt, duration=1.0, options=options, integrator="backward_euler")
    np.testing.assert_allclose(run.state.body_position[0, 2], 0.0995 - G / (2 * k), atol=1e-7)  # forces balance
    assert np.abs(run.state.body_velocity).max() < 1e-6
    # at its default (implicit_springs = "auto") the symplectic run steps these springs by backward
    # Euler, says so, and reaches the same balance
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        auto = simulate(model, "penalty", dt=dt, duration=1.0, options=options)
    assert auto.summary["integrator"] == "symplectic_euler" and auto.summary["implicit_spring_steps"] == 250
    np.testing.assert_allclose(auto.state.body_position[0, 2], 0.0995 - G / (2 * k), atol=1e-7)


def poured_pile(grid, layers, friction=0.5, spacing=0.11, radius=0.05):
    """Spheres (1 kg, r = 5 cm) in layers of grid × grid, 11 cm apart, every other layer shifted
    by 5 mm so the columns cannot balance, the lowest 0.2 m up, inside a box of four walls."""
    b = ModelBuilder()
    b.add_material("rubber", friction=friction, restitution=0.0)
    start = -(grid - 1) * spacing / 2
    for layer in range(layers):
        shift = 0.005 * (layer % 2)
        for i in range(grid):
            for j in range(grid):
                centre = (start + shift + spacing * i, start + shift + spacing * j, 0.2 + spacing * layer)
                b.add_body("sphere", radius=radius, mass=1.0, position=centre, material="rubber")
    half_width = grid * spacing / 2 + 0.005
    b.add_obstacle("plane", normal=(0, 0, 1), offset=0.0, material="rubber")
    for normal in ((1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0)):
        b.add_obstacle("plane", normal=normal, offset=-half_width, material="rubber")
    return b.finalize()


@pytest.mark.parametrize("solver", ["cg", "direct"])
def test_a_frictional_pile_on_stiff_springs_never_flings_a_sphere(solver):
    """160 spheres poured into a narrow box at dt = 1/240 s with penalty's defaults: the "auto"
    stiffness of the lower contacts (their load over 0.3 mm) needs backward Euler springs. A
    slipping contact's force μ F_n⁺ was once solved again with each solve's F_n⁺, and through
    the neighbours' stiff springs each solve multiplied it: this pile gained 963 J over its
    1091 J at t = 0.27 s and the run stopped (the 1000-sphere pile of benchmarks/ flung spheres
    at 106 m/s). Contacts only take energy out of a pile dropped at rest, so no sphere may move
    faster than a free fall from the highest start. Both linear solvers: the compiled matrix-free
    one and SciPy's on the assembled system, each with its own settling of the springs."""
    model = poured_pile(grid=4, layers=10)
    run = simulate(model, "penalty", dt=1 / 240, duration=0.6, options={"linear_solver": solver})
    assert run.summary["implicit_spring_steps"] > 0  # the path under test
    assert run.summary["solver"]["max_iterations"] > 8  # and a step with slipping contacts that did not settle in 8
    highest = run.arrays["body_position"][0, :, 2].max()
    speeds = np.linalg.norm(run.arrays["body_velocity"], axis=2)
    assert speeds.max() < np.sqrt(2 * G * highest)


@pytest.mark.parametrize("solver", ["cg", "direct"])
def test_linear_solvers_agree(solver):
    model, _ = resting_cube(angle_degrees=10.0, friction=0.3, velocity=(0.5, 0.2, 0))
    options = {"stiffness": 1e4, "linear_solver": solver, "linear_tolerance": 1e-12}
    run = simulate(model, "penalty", dt=0.002, duration=0.1, options=options, integrator="backward_euler")
    reference = simulate(
        model,
        "penalty",
        dt=0.002,
        duration=0.1,
        options=dict(options, linear_solver="direct"),
        integrator="backward_euler",
    )
    np.testing.assert_allclose(run.state.body_position, reference.state.body_position, atol=1e-9)
    assert run.summary["solver"]["max_residual"] < 1e-9


def test_summary_reports_the_conjugate_gradient_iterations_per_step():
    # a cube resting on four corners under backward Euler: every step solves the springs' system
    # (6 DOFs), which conjugate gradients finish in at most 6 iterations a pass in exact arithmetic
    model, _ = resting_cube()
    run = simulate(model, "penalty", dt=0.002, duration=0.1, options={"stiffness": 1e4}, integrator="backward_euler")
    solver = run.summary["solver"]
    assert 1.0 <= solver["cg_iterations_per_step"] <= 2 * 6 * solver["mean_iterations"]
    # nothing touches: no solve, no iteration
    b = ModelBuilder()
    b.add_body("sphere", radius=0.1, mass=1.0, position=(0, 0, 5.0))
    b.add_obstacle("plane", normal=(0, 0, 1))
    falling = simulate(b.finalize(), "penalty", dt=0.002, duration=0.1, integrator="backward_euler")
    assert falling.summary["max_contacts"] == 0 and falling.summary["solver"]["cg_iterations_per_step"] == 0.0


# ---- F3: friction by anchor springs ------------------------------------------------------------


def test_anchor_spring_sticks_under_the_limit_and_slips_to_exactly_mu_fn():
    k, mu = 1e4, 0.5
    springs = penalty.ContactSprings(
        np.full(2, k),
        np.zeros(2),
        np.full(2, k),
        np.zeros(2),
        np.full(2, mu),
        np.array([[0.0002, 0.0], [0.003, 0.004]]),
    )
    forces, elongation = penalty.contact_spring_forces(springs, np.full(2, 0.001), np.zeros((2, 3)))
    # normal force 10 N, limit 5 N: the first pulls 2 N and sticks, the second would pull 50 N
    np.testing.assert_allclose(forces[0], [10.0, -2.0, 0.0])
    np.testing.assert_allclose(elongation[0], [0.0002, 0.0])  # anchor stays
    np.testing.assert_allclose(np.linalg.norm(forces[1, 1:]), mu * 10.0)
    np.testing.assert_allclose(forces[1, 1:] / np.linalg.norm(forces[1, 1:]), [-0.6, -0.8])
    np.testing.assert_allclose(np.linalg.norm(elongation[1]), mu * 10.0 / k)  # anchor dragged along


def test_anchors_live_in_the_state_keyed_by_contact_id():
    model, _ = resting_cube(angle_degrees=20.0, friction=0.5)
    run = simulate(model, "penalty", dt=0.001, duration=0.05, options={"stiffness": 1e4})
    carried = run.state.carried
    contacts = collide(model, run.state, 0.001)
    assert carried.method == "penalty"  # the anchors: offsets [m] by persistent contact id
    assert set(contacts.feature_id) == set(carried.ids[np.linalg.norm(carried.values, axis=1) > 0])
    # the anchors hold the block: together they pull m g sinθ up the slope
    pull = 4 * 1e4 * np.linalg.norm(carried.values, axis=1).mean()
    np.testing.assert_allclose(pull, G * np.sin(np.radians(20)), rtol=0.05)


@pytest.mark.parametrize("integrator", ["symplectic_euler", "backward_euler"])
def test_sliding_block_stops_at_v2_over_2_mu_g(integrator):
    v0, mu = 3.0, 0.3
    model, _ = resting_cube(friction=mu, velocity=(v0, 0, 0))
    run = simulate(model, "penalty", dt=0.001, duration=1.3, options={"stiffness": 1e4}, integrator=integrator)
    x, vx = run.arrays["body_position"][:, 0, 0], run.arrays["body_velocity"][:, 0, 0]
    stopped = np.argmax(np.abs(vx) < 0.005 * v0)
    np.testing.assert_allclose(run.arrays["time"][stopped], v0 / (mu * G), rtol=0.03)
    np.testing.assert_allclose(x[stopped], v0**2 / (2 * mu * G), rtol=0.03)
    np.testing.assert_allclose(x[-1], v0**2 / (2 * mu * G), rtol=0.03)  # and stays stopped


@pytest.mark.parametrize("integrator", ["symplectic_euler", "backward_euler"])
def test_block_sticks_on_an_incline_flatter_than_its_friction_angle(integrator):
    model, _ = resting_cube(angle_degrees=20.0, friction=0.5)  # tan 20° = 0.36 < 0.5
    run = simulate(model, "penalty", dt=0.001, duration=2.0, options={"stiffness": 1e4}, integrator=integrator)
    drift = np.linalg.norm(run.arrays["body_position"][:, 0] - run.arrays["body_position"][0, 0], axis=1)
    assert drift.max() < 0.001


def test_block_slides_down_a_steeper_incline_at_g_sin_minus_mu_cos():
    theta, mu = np.radians(20.0), 0.2  # tan 20° = 0.36 > 0.2
    model, downhill = resting_cube(angle_degrees=20.0, friction=mu)
    run = simulate(model, "penalty", dt=0.001, duration=1.5, options={"stiffness": 1e4})
    t = run.arrays["time"]
    along = (run.arrays["body_position"][:, 0] - run.arrays["body_position"][0, 0]) @ downhill
    later = t > 0.3
    acceleration = 2 * np.polyfit(t[later], along[later], 2)[0]
    np.testing.assert_allclose(acceleration, G * (np.sin(theta) - mu * np.cos(theta)), rtol=0.03)


def test_sliding_sphere_rolls_at_five_sevenths():
    v0, mu = 2.0, 0.3
    model = ball_on_plane(height=-G / 1e4, friction=mu, velocity=(v0, 0, 0))
    run = simulate(model, "penalty", dt=0.001, duration=0.6, options={"stiffness": 1e4})
    speed = run.arrays["body_velocity"][:, 0, 0]
    rolling_at = 2 * v0 / (7 * mu * G)
    after = run.arrays["time"] > rolling_at + 0.05
    np.testing.assert_allclose(speed[after], 5 / 7 * v0, rtol=0.01)


# ---- D1: one distribution through the Jacobian ---------------------------------------------------


def mixed_contacts(rng, B, P, count):
    """Random contacts: body–body, body–static, particle–body and triangle-sample–static."""

    def side(kind):
        body, particles, weights = -1, np.full(3, -1), np.zeros(3)
        if kind == "body":
            body = rng.integers(B)
        elif kind == "particle":
            particles[0], weights[0] = rng.integers(P), 1.0
        elif kind == "triangle":
            particles[:] = rng.choice(P, 3, replace=False)
            weights[:] = rng.dirichlet(np.ones(3))
        return body, particles, weights

    kinds = [("body", "body"), ("body", "static"), ("particle", "body"), ("triangle", "static")]
    rows = [side(a) + side(b) for a, b in (kinds[i % 4] for i in range(count))]
    normal = rng.normal(size=(count, 3))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    t1, t2 = tangent_basis(normal)

    def column(i):
        return np.array([r[i] for r in rows])

    return Contacts(
        body_a=column(0),
        body_b=column(3),
        particles_a=column(1),
        particles_b=column(4),
        weights_a=column(2),
        weights_b=column(5),
        point=rng.normal(size=(count, 3)),
        normal=normal,
        depth=np.full(count, 0.001),
        tangent1=t1,
        tangent2=t2,
        friction=np.zeros(count),
        restitution=np.zeros(count),
        feature_id=np.arange(count),
    )


def test_forces_reach_particles_bodies_and_triangle_points_through_j_transpose(rng):
    b = ModelBuilder()
    for i in range(3):
        b.add_body(
            "box",
            half_extents=(0.1, 0.2, 0.3),
            mass=1.0 + i,
            position=rng.normal(size=3),
            orientation=rng.normal(size=4),
        )
    b.add_particles(rng.normal(size=(5, 3)), mass=0.5)
    model = b.finalize()
    state = model.state()
    contacts = mixed_contacts(rng, 3, 5, 12)
    forces = rng.normal(size=(12, 3))
    J = jacobian(contacts, state.body_position, 3, 5)
    change = penalty.distribute(J, inverse_mass_matrix(model, state.body_orientation), forces, 0.01)
    # the same velocity change matrix-free, contact by contact, through the solver's rows
    rows = jacobian_rows.rows_of(model, contacts, state.body_position, state.body_orientation)
    u = np.zeros(3 * 6 + 5 * 3)
    for c in range(12):
        jacobian_rows.apply_impulse(c, rows, *(0.01 * forces[c]), u)
    np.testing.assert_allclose(change, u, atol=1e-12)
    # and by hand for one body contact: h F / m and h I⁻¹ (r × F)
    c = 1
    world_force = forces[c] @ np.stack([contacts.normal[c], contacts.tangent1[c], contacts.tangent2[c]])
    body = contacts.body_a[c]
    linear, angular, _ = unstack(
        penalty.distribute(
            J[3 * c : 3 * c + 3], inverse_mass_matrix(model, state.body_orientation), forces[c : c + 1], 0.01
        ),
        3,
    )
    np.testing.assert_allclose(linear[body], 0.01 * world_force / model.body_mass[body], atol=1e-12)
    r = contacts.point[c] - state.body_position[body]
    np.testing.assert_allclose(
        angular[body],
        0.01 * world_inverse_inertia(model, state.body_orientation)[body] @ np.cross(r, world_force),
        atol=1e-12,
    )


# ---- P4 versus P5 ------------------------------------------------------------------------------

SPACING = 0.0002  # m between the probed positions of the corner


def corner_in_edge_forces(normal_choice):
    """A cube whose corner points at the edge of a static block (x < 0, z < 0), pushed in at
    positions that cross the block's medial plane x = z; the penalty force of its one deepest
    point (P2a) at each, with the normal chosen by P4 ("object") or P5 ("vertex")."""
    # a rotation taking the cube's corner (−1, −1, −1)/√3 onto (−1, 0, −1)/√2
    a = np.array([-1.0, -1.0, -1.0]) / np.sqrt(3)
    target = np.array([-1.0, 0.0, -1.0]) / np.sqrt(2)
    axis = np.cross(a, target)
    angle = np.arcsin(np.linalg.norm(axis))
    quaternion = np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * axis / np.linalg.norm(axis)])
    options = penalty.Options(stiffness=1e4, granularity="object", normal=normal_choice)
    totals = []
    for shift in np.arange(-10, 11) * SPACING / np.sqrt(2):  # the corner at (−2 mm + s, 0, −2 mm − s)
        tip = np.array([-0.002 + shift, 0.0, -0.002 - shift])
        b = ModelBuilder(gravity=(0, 0, 0))
        b.add_body(
            "box", half_extents=(HALF,) * 3, mass=1.0, position=tip - HALF * np.sqrt(3) * target, orientation=quaternion
        )
        b.add_obstacle("box", half_extents=(0.5, 0.5, 0.5), position=(-0.5, 0, -0.5))
        model = b.finalize()
        state = model.state()
        contacts = collide(model, state, 0.0, None, options.granularity, options.normal)
        J = jacobian(contacts, state.body_position, 1, 0)
        inverse_mass = inverse_mass_matrix(model, state.body_orientation)
        springs = penalty.assembled_springs(contacts, J, inverse_mass, Carry.none(), options)
        forces, _ = penalty.contact_spring_forces(springs, contacts.depth, np.zeros((contacts.count, 3)))
        totals.append(forces[:, :1] * contacts.normal)
    assert all(len(f) == 1 for f in totals)
    return np.concatenate(totals)


def test_p4_normal_jumps_across_the_medial_axis_and_p5_is_continuous():
    p4, p5 = corner_in_edge_forces("object"), corner_in_edge_forces("vertex")
    k = 1e4
    # P4: the block's face normal, +z on one side of the medial plane and +x on the other
    np.testing.assert_allclose(p4[0] / np.linalg.norm(p4[0]), [0, 0, 1], atol=1e-9)
    np.testing.assert_allclose(p4[-1] / np.linalg.norm(p4[-1]), [1, 0, 0], atol=1e-9)
    jump = np.linalg.norm(np.diff(p4, axis=0), axis=1).max()
    assert jump > 1.3 * k * 0.0019  # a quarter turn of a force k δ with δ ≈ 1.9 mm
    # P5: the corner's own (negated) normal, always (1, 0, 1)/√2; the force changes no faster
    # than k times how far the corner moved
    np.testing.assert_allclose(
        p5 / np.linalg.norm(p5, axis=1, keepdims=True),
        np.tile(np.array([1, 0, 1]) / np.sqrt(2), (len(p5), 1)),
        atol=1e-9,
    )
    assert np.linalg.norm(np.diff(p5, axis=0), axis=1).max() <= 1.0001 * k * SPACING


# ---- k guidance --------------------------------------------------------------------------------


def test_suggested_stiffness_holds_the_load_at_the_allowed_penetration():
    advice = penalty.suggest_stiffness(mass=2.0, dt=0.001, allowed_penetration=0.002, contacts=4, contact_mass=0.5)
    np.testing.assert_allclose(advice.stiffness, 2.0 * G / (4 * 0.002))
    np.testing.assert_allclose(advice.penetration, 0.002)
    assert advice.stiffness < advice.accurate_limit < advice.stable_limit


def test_suggested_stiffness_is_capped_for_explicit_steps_and_says_what_would_do():
    advice = penalty.suggest_stiffness(mass=100.0, dt=0.004, allowed_penetration=0.001, contact_mass=0.2)
    assert advice.stiffness == advice.accurate_limit < advice.needed
    assert "backward_euler" in advice.reason and "dt ≤" in advice.reason
    implicit = penalty.suggest_stiffness(
        mass=100.0, dt=0.004, allowed_penetration=0.001, contact_mass=0.2, integrator="backward_euler"
    )
    assert implicit.stiffness == implicit.needed


def test_amplification_marks_the_symplectic_stability_limit():
    # one undamped spring: symplectic Euler is stable exactly while h ω < 2; explicit Euler never
    assert penalty.amplification("symplectic_euler", 0.01, 1.99**2 * 1e4, 1.0) <= 1 + 1e-12
    assert penalty.amplification("symplectic_euler", 0.01, 2.01**2 * 1e4, 1.0) > 1.01
    assert penalty.amplification("explicit_euler", 0.01, 1e2, 1.0) > 1.0
    assert penalty.amplification("backward_euler", 0.01, 1e12, 1.0) < 1.0


def test_auto_stiffness_is_each_contacts_load_over_the_allowed_penetration():
    """Three cubes of 3, 2 and 1 kg stacked on the floor: a corner under the top cube carries a
    quarter of 1 kg's weight, under the middle one a quarter of 3 kg's, on the floor a quarter
    of 6 kg's; "auto" gives each spring that load over allowed_penetration, so after settling
    each level has sunk that far and the top cube 3 δ (backward Euler springs: no ringing)."""
    b = ModelBuilder()
    b.add_material("m", friction=0.5, restitution=0.0)
    for level, mass in enumerate((3.0, 2.0, 1.0)):
        b.add_body("box", half_extents=(HALF,) * 3, mass=mass, position=(0, 0, HALF + 2 * HALF * level), material="m")
    b.add_obstacle("plane", normal=(0, 0, 1), material="m")
    model = b.finalize()
    state = model.state()
    options = penalty.Options()
    contacts = collide(model, state, 1e-6)
    loads = np.sort(penalty.contact_stiffness(model, state, contacts, options) * options.allowed_penetration)
    np.testing.assert_allclose(loads, np.repeat([1.0, 3.0, 6.0], 4) * G / 4, rtol=1e-12)
    run = simulate(model, "penalty", dt=1 / 240, duration=2.0, record_every=48)
    sunk = 2 * HALF * np.arange(3) + HALF - run.state.body_position[:, 2]
    np.testing.assert_allclose(sunk, options.allowed_penetration * np.arange(1, 4), rtol=0.02)
    assert run.summary["implicit_spring_steps"] == run.summary["steps"]


def _standing_strip(rows, bend_stiffness=0.5):
    """A 0.1 m square of cloth (4 × ``rows`` vertices, 50 g, 4 mm thick) stood upright on the
    floor, its foot row just touching it."""
    b = ModelBuilder()
    b.add_material("cotton", friction=0.4, restitution=0.0)
    b.add_cloth(
        size=(0.1, 0.1),
        resolution=(4, rows),
        mass=0.05,
        position=(0, 0, 0.004 + 0.05),
        orientation=(np.cos(np.pi / 4), np.sin(np.pi / 4), 0.0, 0.0),  # 90° about x: the grid's y axis up
        stretch_stiffness=500.0,
        shear_stiffness=50.0,
        bend_stiffness=bend_stiffness,
        damping=0.01,
        thickness=0.004,
        material="cotton",
    )
    b.add_obstacle("plane", normal=(0, 0, 1), material="cotton")
    return b.finalize()


def test_auto_stiffness_counts_the_weight_a_cloths_springs_bring_to_the_vertices_it_stands_on():
    """A cloth standing on its foot row: its springs carry the whole 50 g down to the four foot
    vertices, so under "auto" their contacts share m g, Σ k δ_allowed = m g, and the strip sinks
    δ_allowed (and no more) under its weight, however many rows stand above the foot. A sheet
    lying flat rests each vertex on its own contact: each carries the mean vertex weight, or that
    vertex's own where it is more (never less than its own)."""
    options = penalty.Options()
    delta = options.allowed_penetration
    model = _standing_strip(rows=8)
    state = model.state()
    contacts = collide(model, state, 1e-6)
    loads = penalty.contact_stiffness(model, state, contacts, options) * delta
    np.testing.assert_allclose(loads, np.full(4, 0.05 * G / 4), rtol=1e-12)
    run = simulate(model, "penalty", 1 / 240, 0.25, integrator="backward_euler", record_every=6)
    times, heights = run.arrays["time"], run.arrays["particle_position"][:, :, 2]
    sunk = 0.004 - heights[times > 0.1].min(axis=1)  # settled, still upright (it topples later)
    assert heights[-1].max() > 0.1  # standing
    assert sunk.max() <= 1.1 * delta
    assert sunk.min() >= 0.8 * delta  # on its springs, not floating
    b = ModelBuilder()
    b.add_material("cotton", friction=0.4, restitution=0.0)
    b.add_cloth(size=(0.1, 0.1), resolution=(4, 4), mass=0.05, position=(0, 0, 0.004), thickness=0.004)
    b.add_obstacle("plane", normal=(0, 0, 1), material="cotton")
    flat = b.finalize()
    contacts = collide(flat, flat.state(), 1e-6)
    loads = penalty.contact_stiffness(flat, flat.state(), contacts, options) * delta
    resting = flat.particle_mass[contacts.particles_a[:, 0]]
    np.testing.assert_allclose(loads, np.maximum(resting, flat.particle_mass.mean()) * G, rtol=1e-12)


def _largest_motion(run):
    positions = run.arrays["body_position"]
    return np.linalg.norm(positions - positions[0], axis=2).max()


def test_penalty_holds_an_eight_box_stack_and_the_twenty_level_pyramid():
    """Issue 19, at the method's defaults and dt = 1/240 over 5 s: the 8-box stack moves < 20 mm
    and the 210-box pyramid < 10 mm (each contact sinks about allowed_penetration under its load)."""
    from conftest import box_column, box_pyramid

    stack = simulate(box_column(8), "penalty", 1 / 240, 5.0, record_every=24)
    assert _largest_motion(stack) < 0.020
    pyramid = simulate(box_pyramid(20), "penalty", 1 / 240, 5.0, record_every=24)
    assert _largest_motion(pyramid) < 0.010


@pytest.mark.parametrize(
    "table, field",
    [
        ({"stiffness": "soft"}, "stiffness"),
        ({"stiffness": -1.0}, "stiffness"),
        ({"damping_ratio": "lots"}, "damping_ratio"),
        ({"linear_solver": "lu"}, "linear_solver"),
        ({"implicit_iterations": 0}, "implicit_iterations"),
        ({"allowed_penetration": 0.0}, "allowed_penetration"),
    ],
)
def test_bad_options_name_the_field(table, field):
    with pytest.raises(InputError, match=field):
        penalty.Options(**table)


# ---- every scene its shapes allow --------------------------------------------------------------


@pytest.mark.parametrize("name", [name for name, _ in builtin_scenes()])
def test_runs_every_built_in_scene(name):
    scene = load_scene(name)
    options = scene.method_options.get("penalty", {})
    run = simulate(scene.model, "penalty", scene.dt, 25 * scene.dt, options, scene.integrator)
    assert run.state.is_finite()
    assert run.summary["options"]["stiffness"] == options.get("stiffness", "auto")


# ---- cloth (barycentric points, implicit together with the cloth's springs) ----------------------


@pytest.mark.parametrize("integrator, dt", [("symplectic_euler", 0.0005), ("backward_euler", 0.01)])
def test_a_resting_cloth_sinks_each_vertex_m_g_over_k(integrator, dt):
    k, thickness = 100.0, 0.004
    b = ModelBuilder()
    b.add_material("m", friction=0.5, restitution=0.0)
    b.add_cloth(
        size=(0.4, 0.4),
        resolution=(5, 5),
        position=(0, 0, thickness),
        mass=0.25,
        stretch_stiffness=200.0,
        shear_stiffness=20.0,
        bend_stiffness=1.0,
        damping=0.05,
        thickness=thickness,
        material="m",
    )
    b.add_obstacle("plane", normal=(0, 0, 1), material="m")
    run = simulate(
        b.finalize(), "penalty", dt=dt, duration=1.0, options={"stiffness": k}, integrator=integrator, record_every=10
    )
    sink = thickness - run.state.particle_position[:, 2]
    np.testing.assert_allclose(sink, 0.01 * G / k, rtol=0.02)  # each vertex carries 10 g
    # springs stepped implicitly solve a linear system (SciPy's matrix, compiled CG) every step,
    # from the velocities without contacts, which at rest often meet the tolerance already;
    # explicit ones solve none
    implicit = integrator == "backward_euler" or run.summary["implicit_spring_steps"] > 0
    assert (run.summary["solver"]["cg_iterations_per_step"] > 0.0) == implicit


def test_cloth_corner_pinned_hangs_in_contact_without_moving_the_pin():
    b = ModelBuilder()
    b.add_material("m", friction=0.3, restitution=0.0)
    b.add_cloth(
        size=(0.4, 0.4),
        resolution=(6, 6),
        position=(0, 0, 0.3),
        orientation=(np.cos(0.6), np.sin(0.6), 0, 0),
        mass=0.1,
        stretch_stiffness=500.0,
        shear_stiffness=50.0,
        bend_stiffness=1.0,
        damping=0.05,
        pinned=["top_edge"],
        thickness=0.004,
        material="m",
    )
    b.add_obstacle("sphere", radius=0.12, position=(0.0, 0.05, 0.2), material="m")
    model = b.finalize()
    run = simulate(
        model,
        "penalty",
        dt=0.01,
        duration=0.5,
        options={"stiffness": 500.0, "cloth_samples": 2},
        integrator="backward_euler",
        record_every=10,
    )
    pinned = model.particle_pinned
    np.testing.assert_array_equal(run.state.particle_position[pinned], model.initial.particle_position[pinned])
    assert run.state.is_finite() and run.arrays["contact_count"].max() > 0
