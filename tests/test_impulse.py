"""The impulse response (I1, I2, R1–R4, F2) against closed-form results."""

import numpy as np
import pytest
from conftest import ball_on_plane

from contactlab import ModelBuilder, collide, simulate
from contactlab.contacts import jacobian
from contactlab.dynamics.generalized import stack, unstack
from contactlab.dynamics.integrators import free_velocities, world_inverse_inertia
from contactlab.methods import impulse, jacobian_rows, velocity_level

G = 9.81
# every step solved in small steps (sequential.solve_in_substeps), the contacts detected once: the
# closed forms below hold for it as for the whole-step solve (issue 38)
SUBSTEPPED = {"substeps": 8, "substep_when": "always"}
WHOLE_OR_SUBSTEPPED = pytest.mark.parametrize("options", [{}, SUBSTEPPED], ids=["whole", "substepped"])
# shock propagation and block solves (respond's, shared with constraints) run the boxes' closed forms in
# tests/test_constraints.py (EVERY_SOLVE)


def apexes(height, velocity):
    """Heights at the samples where the vertical velocity turns from up to down."""
    turning = np.nonzero((velocity[:-1] > 0) & (velocity[1:] <= 0))[0]
    return np.array([height[i : i + 2].max() for i in turning])


@WHOLE_OR_SUBSTEPPED
@pytest.mark.parametrize("restitution", [0.0, 0.5, 0.8, 1.0])
def test_bounce_apexes_follow_h0_eps_to_the_2n(restitution, options):
    model = ball_on_plane(restitution=restitution, height=1.0)
    fall = np.sqrt(2 * 1.0 / G)
    fifth_apex = fall * (1 + 2 * sum(restitution**k for k in range(1, 5)) + restitution**5)
    run = simulate(model, "impulse", dt=0.001, duration=fifth_apex + 0.1, options=options)
    z = run.arrays["body_position"][:, 0, 2] - 0.1
    found = apexes(z, run.arrays["body_velocity"][:, 0, 2])[:5]
    if restitution == 0.0:
        # h0 ε²ⁿ = 0: no apex at all, the ball stays down from the first touch on
        assert len(found) == 0
        landed = run.arrays["time"] > fall + 0.002
        np.testing.assert_allclose(z[landed], 0.0, atol=1e-9)
        return
    expected = 1.0 * restitution ** (2 * np.arange(1, 6))
    assert len(found) == 5
    np.testing.assert_allclose(found, expected, rtol=0.01)


@WHOLE_OR_SUBSTEPPED
def test_inelastic_ball_lands_and_stays(options):
    model = ball_on_plane(restitution=0.0, height=0.5)
    run = simulate(model, "impulse", dt=0.002, duration=1.0, options=options)
    z = run.arrays["body_position"][:, 0, 2]
    landed = run.arrays["time"] > np.sqrt(2 * 0.5 / G) + 0.01
    np.testing.assert_allclose(z[landed], 0.1, atol=1e-9)  # on the surface, not above, not in
    assert np.abs(run.arrays["body_velocity"][landed, 0, 2]).max() < 1e-9


@WHOLE_OR_SUBSTEPPED
def test_resting_sphere_stays_put_and_does_not_sink(options):
    model = ball_on_plane(height=0.0)
    run = simulate(model, "impulse", dt=0.004, duration=2.0, options=options)
    np.testing.assert_allclose(run.arrays["body_position"][:, 0], [[0, 0, 0.1]] * len(run.arrays["time"]), atol=1e-12)
    assert run.summary["max_penetration"] < 1e-12


def two_spheres(restitution, mass_a, mass_b, velocity_a, velocity_b):
    b = ModelBuilder(gravity=(0, 0, 0))
    b.add_material("m", friction=0.0, restitution=restitution)
    b.add_body("sphere", radius=0.1, mass=mass_a, position=(-0.2, 0, 0), velocity=velocity_a, material="m")
    b.add_body("sphere", radius=0.1, mass=mass_b, position=(0.2, 0, 0), velocity=velocity_b, material="m")
    return b.finalize()


@pytest.mark.parametrize("restitution", [0.0, 0.3, 1.0])
@pytest.mark.parametrize("masses", [(1.0, 1.0), (1.0, 5.0), (3.0, 0.5)])
@WHOLE_OR_SUBSTEPPED
def test_head_on_collision_momentum_and_restitution(restitution, masses, options):
    va, vb = 2.0, -1.0
    model = two_spheres(restitution, *masses, (va, 0, 0), (vb, 0, 0))
    run = simulate(model, "impulse", dt=0.001, duration=0.3, options=options)
    v = run.arrays["body_velocity"][-1, :, 0]
    ma, mb = masses
    assert ma * v[0] + mb * v[1] == pytest.approx(ma * va + mb * vb, abs=1e-9)
    # R3: separation speed = ε × approach speed
    assert v[1] - v[0] == pytest.approx(restitution * (va - vb), abs=1e-9)


@WHOLE_OR_SUBSTEPPED
def test_newtons_cradle_one_in_one_out(options):
    b = ModelBuilder(gravity=(0, 0, 0))
    b.add_material("steel", friction=0.0, restitution=1.0)
    for i in range(5):
        b.add_body(
            "sphere",
            radius=0.05,
            mass=1.0,
            position=(0.1 * i, 0, 0),
            velocity=(1.0 if i == 0 else 0.0, 0, 0),
            material="steel",
        )
    model = b.finalize()
    state = model.state()
    state.body_position[0, 0] = -0.05  # the first ball 5 cm away from the row
    run = simulate(model, "impulse", dt=0.001, duration=0.2, options=options, state=state)
    v = run.arrays["body_velocity"][-1, :, 0]
    np.testing.assert_allclose(v, [0, 0, 0, 0, 1.0], atol=1e-6)


@WHOLE_OR_SUBSTEPPED
def test_sliding_block_stops_at_v2_over_2_mu_g(options):
    mu, v0 = 0.3, 3.0
    b = ModelBuilder()
    b.add_material("m", friction=mu)
    b.add_body(
        "box", half_extents=(0.05, 0.05, 0.05), mass=1.0, position=(0, 0, 0.05), velocity=(v0, 0, 0), material="m"
    )
    b.add_obstacle("plane", normal=(0, 0, 1), material="m")
    run = simulate(b.finalize(), "impulse", dt=0.002, duration=1.3, options=options)
    x = run.arrays["body_position"][:, 0, 0]
    vx = run.arrays["body_velocity"][:, 0, 0]
    assert x[-1] == pytest.approx(v0**2 / (2 * mu * G), rel=0.01)
    stopped = run.arrays["time"][np.argmax(vx <= 1e-6)]
    assert stopped == pytest.approx(v0 / (mu * G), abs=0.005)
    # it slides flat: no tipping (tilt under 10 µrad), no bouncing
    tilt = 2 * np.arccos(np.clip(np.abs(run.arrays["body_orientation"][:, 0, 0]), 0, 1))
    assert tilt.max() < 1e-5
    assert np.abs(run.arrays["body_position"][:, 0, 2] - 0.05).max() < 1e-6


@WHOLE_OR_SUBSTEPPED
def test_sphere_goes_from_sliding_to_rolling_at_five_sevenths(options):
    mu, v0 = 0.3, 3.0
    model = ball_on_plane(friction=mu, height=0.0, velocity=(v0, 0, 0))
    run = simulate(model, "impulse", dt=0.001, duration=1.0, options=options)
    t = run.arrays["time"]
    vx = run.arrays["body_velocity"][:, 0, 0]
    wy = run.arrays["body_angular_velocity"][:, 0, 1]
    rolling_time = 2 / 7 * v0 / (mu * G)
    after = t > rolling_time + 0.01
    np.testing.assert_allclose(vx[after], 5 / 7 * v0, rtol=1e-3)
    # rolling: v = ω r (the ball rests exactly on the surface: no overlap shortens r)
    np.testing.assert_allclose(wy[after] * 0.1, vx[after], rtol=1e-7)
    before = t < rolling_time - 0.01
    assert (vx[before] > 5 / 7 * v0 + 1e-3).all()  # still sliding before


def test_matrix_free_rows_equal_the_assembled_jacobian():
    """The solver's matrix-free rows against the assembled J and J M⁻¹ Jᵀ: the effective masses
    k (diagonal and normal-tangent couplings), J u, and u + M⁻¹ Jᵀ λ, for body, particle and
    static sides."""
    b = ModelBuilder()
    b.add_body("box", half_extents=(0.3, 0.1, 0.05), mass=2.0, position=(0, 0, 0.04), orientation=(0.9, 0.1, 0.3, 0.2))
    b.add_body("sphere", radius=0.1, mass=0.7, position=(0.25, 0.1, 0.2))
    b.add_particles([[1, 1, -0.01], [2, 2, 0.0]], mass=[0.3, 0.5], radius=0.02)
    b.add_obstacle("plane", normal=(0, 0, 1))
    model = b.finalize()
    state = model.state()
    contacts = collide(model, state)
    assert contacts.count >= 4
    J = jacobian(contacts, state.body_position, model.body_count, model.particle_count)
    inv_inertia = world_inverse_inertia(model, state.body_orientation)
    blocks = [np.diag(np.full(3, 1 / m)) for m in model.body_mass]
    Minv = np.zeros((J.shape[1], J.shape[1]))
    for i in range(model.body_count):
        Minv[6 * i : 6 * i + 3, 6 * i : 6 * i + 3] = blocks[i]
        Minv[6 * i + 3 : 6 * i + 6, 6 * i + 3 : 6 * i + 6] = inv_inertia[i]
    for j, m in enumerate(model.particle_mass):
        k = 6 * model.body_count + 3 * j
        Minv[k : k + 3, k : k + 3] = np.eye(3) / m
    W = J @ Minv @ J.T
    rows = jacobian_rows.rows_of(model, contacts, state.body_position, state.body_orientation)
    k = rows.k
    for c in range(contacts.count):
        for d in range(3):
            assert k[c, d] == pytest.approx(W[3 * c + d, 3 * c + d], rel=1e-12)
        assert k[c, 3] == pytest.approx(W[3 * c + 1, 3 * c], rel=1e-12, abs=1e-14)
        assert k[c, 4] == pytest.approx(W[3 * c + 2, 3 * c], rel=1e-12, abs=1e-14)
    rng = np.random.default_rng(3)
    u = rng.normal(size=J.shape[1])
    np.testing.assert_allclose(jacobian_rows.row_products(rows, u).ravel(), J @ u, rtol=1e-12, atol=1e-12)
    lam = rng.normal(size=(contacts.count, 3))
    after = u.copy()
    for c in range(contacts.count):
        jacobian_rows.apply_impulse(c, rows, lam[c, 0], lam[c, 1], lam[c, 2], after)
    np.testing.assert_allclose(after, u + Minv @ J.T @ lam.ravel(), rtol=1e-12, atol=1e-12)


def test_rod_corner_impact_matches_r4_by_hand():
    """A tilted rod strikes the ground with one corner: one step of the method against R4."""
    eps, mass = 0.5, 2.0
    half = np.array([0.5, 0.025, 0.025])
    angle = np.radians(30)
    q = np.array([np.cos(angle / 2), 0.0, np.sin(angle / 2), 0.0])
    b = ModelBuilder(gravity=(0, 0, 0))
    b.add_material("m", friction=0.0, restitution=eps)
    # only the lowest corner within reach: the rod tilted about y with a thin y extent gives 2 corners
    # at the same height; tilt about x a little too so that exactly one corner strikes
    q2 = np.array([np.cos(0.05), np.sin(0.05), 0.0, 0.0])
    from contactlab import rotations

    q = rotations.multiply(q2[None], q[None])[0]
    R = rotations.to_matrix(q[None])[0]
    corners = np.array(np.meshgrid(*[[-1, 1]] * 3)).T.reshape(-1, 3) * half
    world = corners @ R.T
    lowest = world[np.argmin(world[:, 2])]
    v0, w0 = np.array([0.3, 0.0, -2.0]), np.array([0.0, 1.5, 0.4])
    b.add_body(
        "box",
        half_extents=half,
        mass=mass,
        position=(0, 0, -lowest[2] - 1e-4),
        orientation=q,
        velocity=v0,
        angular_velocity=w0,
        material="m",
    )
    b.add_obstacle("plane", normal=(0, 0, 1), material="m")
    model = b.finalize()
    state, info = impulse.step(model, model.state(), 1e-3, impulse.Options(time_of_impact=False))
    w0 = free_velocities(model, model.state(), 1e-3)[1][0]  # ω after the gyroscopic term
    assert info.contacts.count == 1
    # R4 by hand, at the configuration the contact was found in (the start of the step)
    n = np.array([0.0, 0.0, 1.0])
    r = info.contacts.point[0] - np.array([0, 0, -lowest[2] - 1e-4])
    np.testing.assert_allclose(r, lowest + [0, 0, 0.5e-4], atol=1e-12)  # the corner, mid-gap
    I_inv = world_inverse_inertia(model, q[None])[0]
    v_rel = v0 + np.cross(w0, r)
    j = -(1 + eps) * n @ v_rel / (1 / mass + n @ np.cross(I_inv @ np.cross(r, n), r))
    np.testing.assert_allclose(state.body_velocity[0], v0 + j * n / mass, atol=1e-6)
    np.testing.assert_allclose(state.body_angular_velocity[0], w0 + I_inv @ np.cross(r, j * n), atol=1e-6)
    # and the restitution law R3 holds at the contact
    v_after = state.body_velocity[0] + np.cross(state.body_angular_velocity[0], r)
    assert n @ v_after == pytest.approx(-eps * (n @ v_rel), abs=1e-9)


def test_box_landing_flat_rebounds_straight_without_spin():
    """Four corners strike at once: one simultaneous impact, v⁺ = −ε v⁻, no rotation."""
    eps = 0.5
    b = ModelBuilder()
    b.add_material("m", friction=0.4, restitution=eps)
    b.add_body("box", half_extents=(0.2, 0.1, 0.05), mass=1.0, position=(0, 0, 0.95), material="m")
    b.add_obstacle("plane", normal=(0, 0, 1), material="m")
    run = simulate(b.finalize(), "impulse", dt=0.001, duration=0.75)  # the apex comes at 0.64 s
    vz = run.arrays["body_velocity"][:, 0, 2]
    bounce = np.argmax(vz > 0)
    impact_speed = np.sqrt(2 * G * 0.9)
    # leapfrog: the sampled velocity is that of mid-step, off by at most g h from the instant
    assert vz[bounce] == pytest.approx(eps * impact_speed, abs=G * 0.001)
    # spin only at the level of the solver tolerance (1e-6 m/s at corners 0.05–0.2 m out)
    assert np.abs(run.arrays["body_angular_velocity"]).max() < 1e-6 / 0.05
    z = run.arrays["body_position"][:, 0, 2] - 0.05
    apex = z[bounce:].max()
    assert apex == pytest.approx(eps**2 * 0.9, rel=0.01)


def test_particles_without_rigid_bodies_collide():
    b = ModelBuilder()
    b.add_material("m", restitution=0.5)
    b.add_particles([[0, 0, 0.5], [0.3, 0, 0.2]], radius=0.01, material="m")
    b.add_obstacle("plane", normal=(0, 0, 1), material="m")
    run = simulate(b.finalize(), "impulse", dt=0.001, duration=1.5)
    z = run.arrays["particle_position"][:, :, 2]
    assert z.min() >= 0.01 - 1e-12  # never below the plane
    assert run.arrays["particle_velocity"][:, 0, 2].max() > 0.5 * np.sqrt(2 * G * 0.49) - 0.02  # bounced


def test_domino_chain_falls_all_the_way():
    from contactlab import rotations
    from contactlab.scene import load_scene

    scene = load_scene("domino_chain")
    run = simulate(scene.model, scene.method, scene.dt, scene.duration)
    R = rotations.to_matrix(run.arrays["body_orientation"][-1])
    tilt = np.degrees(np.arccos(np.clip(R[:, 2, 2], -1, 1)))  # body z axis against the vertical
    assert (tilt > 60).all()  # every domino went over
    assert run.summary["max_penetration"] < 1e-3


def test_warm_starting_carries_impulses_by_contact_id_and_steadies_a_pyramid():
    from contactlab.scene import load_scene

    scene = load_scene("box_pyramid")
    run = simulate(scene.model, "impulse", scene.dt, 2.0, {"warm_start": 1.0})
    moved = np.linalg.norm(run.arrays["body_position"][-1] - run.arrays["body_position"][0], axis=1)
    assert moved.max() < 1e-4  # 0.1 mm in 2 s
    # the carried impulses hold the weight: the floor's contacts carry all 15 boxes, m g h per step
    from contactlab.collision import FEATURE_BITS

    ids, values = run.state.carried.of("impulse")
    colliders = scene.model.body_count + scene.model.obstacle_count
    on_floor = (ids >> FEATURE_BITS) % colliders == scene.model.body_count  # B is the floor plane
    assert values[on_floor, 0].sum() == pytest.approx(15 * 1.0 * G * scene.dt, rel=1e-3)
    cold = simulate(scene.model, "impulse", scene.dt, 2.0, {"warm_start": 0.0})
    moved_cold = np.linalg.norm(cold.arrays["body_position"][-1] - cold.arrays["body_position"][0], axis=1)
    assert moved_cold.max() > 10 * moved.max()  # what warm starting buys


def _two_box_stack(top_mass, bottom_mass=1.0):
    b = ModelBuilder()
    b.add_material("m", friction=0.5, restitution=0.0)
    b.add_body("box", half_extents=(0.05,) * 3, mass=bottom_mass, position=(0, 0, 0.05), material="m")
    b.add_body("box", half_extents=(0.05,) * 3, mass=top_mass, position=(0, 0, 0.15), material="m")
    b.add_obstacle("plane", normal=(0, 0, 1), material="m")
    return b.finalize()


def test_a_new_contact_starts_from_the_weight_it_bears():
    """Two boxes stacked, touching, no impulse carried: the warm start of each of the four corners
    between them is a quarter of the top box's weight over the step, m_top g h / 4, and of each
    corner on the floor a quarter of both, (m_top + m_bottom) g h / 4, along the normal; times
    warm_start; nothing at all at warm_start 0."""
    from contactlab.methods.loop_stages import loop_inputs, loop_settings
    from contactlab.methods.velocity_level import warm_impulses

    model, h = _two_box_stack(3.0, 1.0), 1 / 240
    state = model.state()
    contacts = collide(model, state)
    between = (contacts.body_a >= 0) & (contacts.body_b >= 0)
    assert between.sum() == 4 and (~between).sum() == 4

    def first_impulses(fraction):
        settings = loop_settings(model, "impulse", impulse.Options(warm_start=fraction), h)
        arrays, motion, _, carried = loop_inputs(model, state, "impulse")
        return warm_impulses(arrays, settings, contacts.arrays(), motion, *carried)

    for fraction in (1.0, 0.5):
        warm = first_impulses(fraction)
        np.testing.assert_allclose(warm[between, 0], fraction * 3.0 * G * h / 4, rtol=1e-12)
        np.testing.assert_allclose(warm[~between, 0], fraction * 4.0 * G * h / 4, rtol=1e-12)
        assert np.all(warm[:, 1:] == 0.0)  # no friction guessed
    assert np.all(first_impulses(0.0) == 0.0)


@WHOLE_OR_SUBSTEPPED
@pytest.mark.parametrize("method", ["impulse", "constraints"])
def test_a_box_a_thousand_times_heavier_stands_on_a_light_one(method, options):
    """1:1000 at the defaults: the light box carries the heavy one for 5 s, the top box within
    1 mm of where it started, nothing deeper than 1 mm. Started from zero impulses, the sweeps
    built the heavy box's load path too slowly and it crushed the light one out sideways."""
    run = simulate(_two_box_stack(1000.0), method, 1 / 240, 5.0, options)
    moved = np.linalg.norm(run.arrays["body_position"][-1] - run.arrays["body_position"][0], axis=1)
    assert moved.max() < 1e-3
    assert run.arrays["max_penetration"].max() < 1e-3


def test_capsules_come_to_rest_lying_flat_stacked_and_on_a_box():
    b = ModelBuilder()
    b.add_material("m", friction=0.5)
    lying = (np.cos(np.pi / 4), np.sin(np.pi / 4), 0, 0)  # axis along world y
    b.add_body(
        "capsule", radius=0.05, half_length=0.2, mass=1.0, position=(0, 0, 0.06), orientation=lying, material="m"
    )
    b.add_body(
        "capsule", radius=0.05, half_length=0.2, mass=1.0, position=(0, 0, 0.17), orientation=lying, material="m"
    )
    b.add_body("box", half_extents=(0.1, 0.1, 0.1), mass=1.0, position=(0.5, 0, 0.1), material="m")
    b.add_body(
        "capsule", radius=0.05, half_length=0.05, mass=1.0, position=(0.5, 0, 0.26), orientation=lying, material="m"
    )
    b.add_obstacle("plane", normal=(0, 0, 1), material="m")
    run = simulate(b.finalize(), "impulse", 1 / 240, 1.5)
    z = run.arrays["body_position"][-1, :, 2]
    np.testing.assert_allclose(z, [0.05, 0.15, 0.1, 0.25], atol=1e-3)
    assert np.abs(run.arrays["body_velocity"][-1]).max() < 1e-3
    assert run.summary["energy"]["max"] <= run.summary["energy"]["initial"] + 1e-9  # nothing launched
    assert run.summary["max_penetration"] < 1e-3


def test_capsule_rests_lying_on_a_convex_hull_and_a_hull_rests_on_a_capsule_bed():
    b = ModelBuilder()
    b.add_material("m", friction=0.6)
    slab = [[x, y, z] for x in (-0.3, 0.3) for y in (-0.3, 0.3) for z in (0.0, 0.1)]
    b.add_obstacle("convex", points=slab, material="m")
    lying = (np.cos(np.pi / 4), np.sin(np.pi / 4), 0, 0)
    b.add_body(
        "capsule", radius=0.04, half_length=0.15, mass=1.0, position=(0, 0, 0.145), orientation=lying, material="m"
    )
    run = simulate(b.finalize(), "impulse", 1 / 240, 1.5)
    np.testing.assert_allclose(run.arrays["body_position"][-1, 0], [0, 0, 0.14], atol=1e-3)
    assert np.abs(run.arrays["body_angular_velocity"][-1]).max() < 1e-3  # two contacts: no rocking
    assert run.summary["max_penetration"] < 1e-3


def block_on_incline(theta, mu):
    """The built-in ``incline`` scene with any angle and friction: a 1 kg, 0.1 m cube whose bottom
    face lies on a plane through the origin tilted by ``theta`` [rad] about y."""
    normal = np.array([-np.sin(theta), 0.0, np.cos(theta)])
    b = ModelBuilder()
    b.add_material("wood", friction=mu, restitution=0.0)
    b.add_body(
        "box",
        half_extents=(0.05, 0.05, 0.05),
        mass=1.0,
        position=0.05 * normal,
        orientation=(np.cos(-theta / 2), 0.0, np.sin(-theta / 2), 0.0),
        material="wood",
    )
    b.add_obstacle("plane", normal=normal, offset=0.0, material="wood")
    return b.finalize(), normal


def test_block_on_the_builtin_incline_sticks_when_tan_theta_is_below_mu():
    from contactlab.scene import load_scene

    scene = load_scene("incline")
    assert scene.method_options == {}  # the defaults
    normal = scene.model.obstacle_params[0, :3]
    theta = np.arccos(normal[2])
    assert np.tan(theta) < scene.model.material_friction[0]  # 0.36 < 0.5: static friction holds
    run = simulate(scene.model, "impulse", scene.dt, 2.0)
    drift = np.linalg.norm(run.arrays["body_position"][:, 0] - run.arrays["body_position"][0, 0], axis=1)
    assert drift.max() < 1e-3  # under 1 mm in 2 s


@pytest.mark.parametrize("degrees, mu", [(20, 0.2), (30, 0.3), (35, 0.1)])
def test_block_slides_down_an_incline_at_g_sin_minus_mu_cos(degrees, mu):
    theta = np.radians(degrees)
    assert np.tan(theta) > mu
    model, normal = block_on_incline(theta, mu)
    run = simulate(model, "impulse", 0.004, 1.0)
    downhill = np.array([-np.cos(theta), 0.0, -np.sin(theta)])  # along the plane, ⟂ normal
    assert downhill @ normal == pytest.approx(0.0, abs=1e-15)
    t = run.arrays["time"]
    speed = run.arrays["body_velocity"][:, 0] @ downhill
    slope = np.polyfit(t[t > 0.05], speed[t > 0.05], 1)[0]
    assert slope == pytest.approx(G * (np.sin(theta) - mu * np.cos(theta)), rel=0.03)
    # it slides on its face: it neither leaves the plane nor tips
    height = run.arrays["body_position"][:, 0] @ normal
    assert np.abs(height - 0.05).max() < 1e-3
    tilt = 2 * np.arccos(
        np.clip(
            np.abs(rotations_relative(run.arrays["body_orientation"][:, 0], run.arrays["body_orientation"][0, 0])), 0, 1
        )
    )
    assert tilt.max() < 1e-3


def rotations_relative(q, q0):
    """w component of q ⊗ q0⁻¹ for unit quaternions q (T, 4), q0 (4,): cos of half the turn between them."""
    return q @ q0


def test_jacobian_form_equals_r4_term_by_term_for_two_rigid_bodies(rng):
    """j = −(1+ε) v_n / (J M⁻¹ Jᵀ) from the solver's Jacobian rows against R4 written out, for two
    boxes in random orientations; the solver's single-contact impulse then satisfies R2 and R3."""
    from conftest import random_rotations

    from contactlab.contacts import tangent_basis
    from contactlab.methods.loop_stages import loop_settings

    # the collision stage's settings: h = 1 ms, every approach bounces, 10 waves and sweeps to 1e-12 m/s
    options = impulse.Options(iterations=10, tolerance=1e-12, restitution_threshold=0.0)
    settings = loop_settings(ball_on_plane(), "impulse", options, 1e-3)
    for _trial in range(20):
        R = random_rotations(rng, 2)  # R_a, R_b (2, 3, 3)
        mass = rng.uniform(0.2, 5.0, 2)
        half = rng.uniform(0.02, 0.5, (2, 3))
        inertia_body = mass[:, None] / 3 * (half[:, [1, 0, 0]] ** 2 + half[:, [2, 2, 1]] ** 2)  # box moments
        inverse_world = np.array([R[i] @ np.diag(1 / inertia_body[i]) @ R[i].T for i in range(2)])  # M⁻¹
        r_body = rng.uniform(-1, 1, (2, 3)) * half  # r_a, r_b in the body frames
        r_world = np.einsum("bij,bj->bi", R, r_body)  # R r
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        v, w = rng.normal(size=(2, 3)), rng.normal(size=(2, 3))
        eps = rng.uniform(0, 1)
        # R4, term by term
        v_rel = v[0] + np.cross(w[0], r_world[0]) - v[1] - np.cross(w[1], r_world[1])
        denominator = (
            1 / mass[0]
            + 1 / mass[1]
            + n @ np.cross(inverse_world[0] @ np.cross(r_world[0], n), r_world[0])
            + n @ np.cross(inverse_world[1] @ np.cross(r_world[1], n), r_world[1])
        )
        j_r4 = -(1 + eps) * (n @ v_rel) / denominator
        # the Jacobian form: J written out, against the rows the solver sweeps (bodies placed so
        # that the contact point, the origin, has these lever arms)
        t1, t2 = tangent_basis(n[None])
        no_particles = -np.ones((1, 3), np.int64)
        sides = (np.array([0]), np.array([1]), no_particles, no_particles, np.zeros((1, 3)), np.zeros((1, 3)))
        rows = jacobian_rows.contact_rows(
            sides, (np.zeros((1, 3)), n[None], t1, t2), -r_world, (1 / mass, inverse_world, np.zeros(0))
        )
        k = rows.k
        u = stack(v, w, np.zeros((0, 3)))
        J = np.concatenate([n, np.cross(r_world[0], n), -n, -np.cross(r_world[1], n)])
        M_inv = np.zeros((12, 12))
        for i in range(2):
            M_inv[6 * i : 6 * i + 3, 6 * i : 6 * i + 3] = np.eye(3) / mass[i]
            M_inv[6 * i + 3 : 6 * i + 6, 6 * i + 3 : 6 * i + 6] = inverse_world[i]
        assert J @ u == pytest.approx(n @ v_rel, rel=1e-12, abs=1e-12)  # v_n = J v
        assert jacobian_rows.row_products(rows, u)[0, 0] == pytest.approx(J @ u, rel=1e-12, abs=1e-12)
        assert k[0, 0] == pytest.approx(J @ M_inv @ J, rel=1e-12)  # J M⁻¹ Jᵀ
        assert k[0, 0] == pytest.approx(denominator, rel=1e-12)  # = R4's denominator
        j = -(1 + eps) * (J @ u) / k[0, 0]
        assert j == pytest.approx(j_r4, rel=1e-12, abs=1e-12)
        # the collision stage applies exactly this j when the bodies approach (R2, R3)
        if n @ v_rel >= 0:
            continue
        tau = np.empty(1)
        materials = (np.zeros(1), np.array([eps]))  # frictionless, restitution ε
        velocity_level.resolve_collisions(rows, materials, np.zeros(1), np.zeros(1), u, tau, np.array([0]), settings)
        after_v, after_w, _ = unstack(u, 2)
        for i, sign in ((0, 1.0), (1, -1.0)):
            np.testing.assert_allclose(after_v[i], v[i] + sign * j * n / mass[i], rtol=1e-10, atol=1e-12)
            np.testing.assert_allclose(
                after_w[i], w[i] + inverse_world[i] @ np.cross(r_world[i], sign * j * n), rtol=1e-10, atol=1e-12
            )
        v_rel_after = after_v[0] + np.cross(after_w[0], r_world[0]) - after_v[1] - np.cross(after_w[1], r_world[1])
        assert n @ v_rel_after == pytest.approx(-eps * (n @ v_rel), abs=1e-12)


def positions_moved_and_sunk(run):
    """(largest displacement of any body from its start [m], deepest any body got below its start [m])."""
    p = run.arrays["body_position"]
    moved = np.linalg.norm(p - p[0], axis=2).max()
    sunk = (p[0, :, 2] - p[:, :, 2]).max()
    return moved, sunk


@pytest.mark.parametrize("name", ["box_stack", "box_pyramid", "mass_ratio_stack"])
def test_stacks_stand_for_ten_seconds_with_default_settings(name):
    """Every box moves < 1 cm and nothing sinks > 5 mm in 10 s, with no [method.impulse] tuning."""
    from contactlab.scene import load_scene

    scene = load_scene(name)
    assert scene.method == "impulse" and scene.method_options == {}
    run = simulate(scene.model, "impulse", scene.dt, 10.0)
    moved, sunk = positions_moved_and_sunk(run)
    assert moved < 0.01
    assert sunk < 0.005
    assert run.summary["max_penetration"] < 0.005


def test_position_correction_removes_a_fraction_of_the_overlap_per_step():
    """A box started 3 mm into the floor: with stabilization β the overlap beyond the slop shrinks
    by (1 − β) per step, (d − slop)ₙ = (d₀ − slop)(1 − β)ⁿ; with β = 0 it stays. The JSON summary's
    max_penetration is the same 3 mm for both (the worst overlap of the run): the correction shows
    in the per-sample max_penetration of the trajectory."""
    d0 = 0.003
    b = ModelBuilder()
    b.add_material("m", friction=0.5)
    b.add_body("box", half_extents=(0.05, 0.05, 0.05), mass=1.0, position=(0, 0, 0.05 - d0), material="m")
    b.add_obstacle("plane", normal=(0, 0, 1), material="m")
    model = b.finalize()
    # the whole-step solve's law: substeps of one sweep each (the default for a step these sweeps leave
    # unconverged after substep_after) follow it to 6e-7 m here, not to the tolerance
    whole = {"substeps": 1}
    options = impulse.Options(**whole)
    beta, slop = options.stabilization, options.slop
    corrected = simulate(model, "impulse", 0.004, 0.2, whole)
    n = np.arange(len(corrected.arrays["time"]))
    expected = slop + (d0 - slop) * (1 - beta) ** n
    # the solver stops once no impulse changes a velocity by more than its tolerance: each step may
    # leave up to tolerance × h of the correction undone
    assert np.all(np.abs(corrected.arrays["max_penetration"] - expected) <= options.tolerance * 0.004 * n + 1e-15)
    assert corrected.summary["max_penetration"] == pytest.approx(d0, rel=1e-9)
    left = simulate(model, "impulse", 0.004, 0.2, {**whole, "stabilization": 0.0})
    assert np.all(np.abs(left.arrays["max_penetration"] - d0) <= options.tolerance * 0.004 * n + 1e-15)
    assert left.summary["max_penetration"] == pytest.approx(d0, abs=options.tolerance * 0.2)


def builtin_names():
    from contactlab.scene import builtin_scenes

    known_gain = pytest.mark.xfail(
        strict=True,
        reason=(
            "impulses see M⁻¹ while backward Euler cloth springs see A = M − hD − h²K: the split stores "
            "energy in the springs of a cloth caught on the table's edge, or of a strip pressed upright on "
            "the floor by its own weight (cloth_fold: 0.150 J to 0.214 J in 0.25 s, self-contact on or off alike; "
            "0.1500 J at a quarter of its dt) (known limitation, see docs/methods/impulse.md); the constraints "
            "method solves both together"
        ),
    )
    gaining = ("cloth_table", "cloth_fold")
    return [pytest.param(name, marks=known_gain) if name in gaining else name for name, _ in builtin_scenes()]


@pytest.mark.parametrize("name", builtin_names())
def test_every_builtin_scene_runs_without_diverging(name):
    """Every built-in scene (rigid bodies, particles, both) for 0.25 s with the impulse method: the
    state stays finite, nothing sinks deep, and no energy is created beyond the small push that
    removes the overlaps a scene may start with."""
    from contactlab.scene import load_scene

    scene = load_scene(name)
    options = scene.method_options if scene.method == "impulse" else {}
    run = simulate(scene.model, "impulse", scene.dt, min(0.25, scene.duration), options, scene.integrator)
    assert run.state.is_finite()
    assert run.summary["max_penetration"] < 0.01
    energy = run.summary["energy"]
    assert energy["max"] <= energy["initial"] + 0.1 * abs(energy["initial"]) + 1e-9
