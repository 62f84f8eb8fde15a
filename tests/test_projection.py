"""The projection method (W1, L2, M3) against closed-form results."""

import numpy as np
import pytest
from conftest import ball_on_plane, cube_on_plane

from contactlab import ModelBuilder, collide, simulate
from contactlab.dynamics.integrators import world_inverse_inertia
from contactlab.errors import InputError, SimulationDiverged
from contactlab.methods import projection
from contactlab.scene import builtin_scenes, load_scene

G = 9.81
HALF = 0.05


def particles_over_obstacles(rng, count=60):
    """Particles raining onto a floor, a sphere, a box and a tilted plane, radius 5 mm."""
    b = ModelBuilder()
    b.add_material("m", friction=0.4, restitution=0.0)
    positions = rng.uniform([-0.5, -0.5, 0.05], [0.5, 0.5, 0.6], size=(count, 3))
    b.add_particles(positions, rng.normal(scale=1.0, size=(count, 3)), mass=0.01, radius=0.005, material="m")
    b.add_obstacle("plane", normal=(0, 0, 1), material="m")
    b.add_obstacle("sphere", radius=0.2, position=(0.2, 0.1, 0.05), material="m")
    b.add_obstacle(
        "box",
        half_extents=(0.1, 0.15, 0.1),
        position=(-0.25, -0.2, 0.1),
        orientation=(np.cos(0.3), 0, 0, np.sin(0.3)),
        material="m",
    )
    return b.finalize()


@pytest.mark.parametrize("slop", [0.0, 0.0005])
def test_no_particle_stays_inside_after_a_projection(rng, slop):
    """W1: a projection removes the intersection — all of it with slop = 0, all but the slop
    (the overlap left alone so stacks rest without jitter) at the default."""
    model = particles_over_obstacles(rng)
    state = model.state()
    options = projection.Options(slop=slop)
    for _ in range(150):
        state, info = projection.step(model, state, 0.004, options)
        after = collide(model, state)  # depth counts from each particle's radius
        assert after.depth.max(initial=0.0) <= slop + 1e-6
    assert info.contacts.count > 0


def test_projected_points_do_not_keep_approaching():
    model = ball_on_plane(height=0.3, friction=0.0, restitution=0.9)
    run = simulate(model, "projection", dt=0.004, duration=0.5)
    landed = run.arrays["time"] > np.sqrt(2 * 0.3 / G) + 0.01
    z, vz = run.arrays["body_position"][landed, 0, 2], run.arrays["body_velocity"][landed, 0, 2]
    np.testing.assert_allclose(z, 0.1, atol=1e-9)  # on the surface: inelastic, whatever ε
    np.testing.assert_allclose(vz, 0.0, atol=1e-9)


def test_a_body_correction_splits_between_translation_and_rotation_by_mass_and_inertia():
    # a tilted box, no gravity, no motion, its lowest corner 2 mm into the floor: one projection
    from contactlab import rotations

    half, mass, corner_depth = np.array([0.1, 0.05, 0.2]), 3.0, 0.002
    angle = 0.4
    orientation = np.array([np.cos(angle / 2), np.sin(angle / 2) * 0.6, np.sin(angle / 2) * 0.8, 0.0])
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * half
    lowest = (corners @ rotations.to_matrix(orientation[None])[0].T)[:, 2].min()
    b = ModelBuilder(gravity=(0, 0, 0))
    b.add_material("m", friction=0.0, restitution=0.0)
    b.add_body(
        "box",
        half_extents=half,
        mass=mass,
        position=(0, 0, -lowest - corner_depth),
        orientation=orientation,
        material="m",
    )
    b.add_obstacle("plane", normal=(0, 0, 1), material="m")
    model = b.finalize()
    state = model.state()
    contacts = collide(model, state)
    assert contacts.count == 1 and contacts.depth[0] == pytest.approx(corner_depth, rel=1e-9)
    h = 0.01
    options = projection.Options(passes=1)
    new, _ = projection.step(model, state, h, options)
    n, r = contacts.normal[0], contacts.point[0] - state.body_position[0]
    inverse_inertia = world_inverse_inertia(model, state.body_orientation)[0]
    # J M⁻¹ Jᵀ λ = δ − slop: the overlap beyond the slop is projected out
    lam = (corner_depth - options.slop) / (1 / mass + np.cross(r, n) @ inverse_inertia @ np.cross(r, n))
    np.testing.assert_allclose(new.body_position[0] - state.body_position[0], lam * n / mass, rtol=1e-9)
    # the rotation vector of the step, h ω (velocities follow the projected positions)
    np.testing.assert_allclose(h * new.body_angular_velocity[0], lam * inverse_inertia @ np.cross(r, n), rtol=1e-9)


@pytest.mark.parametrize("integrator", ["symplectic_euler", "explicit_euler"])
def test_sliding_block_stops_at_v2_over_2_mu_g(integrator):
    v0, mu = 3.0, 0.3
    b = ModelBuilder()
    b.add_material("m", friction=mu, restitution=0.0)
    b.add_body("box", half_extents=(HALF,) * 3, mass=1.0, position=(0, 0, HALF), velocity=(v0, 0, 0), material="m")
    b.add_obstacle("plane", normal=(0, 0, 1), material="m")
    dt = 0.002
    run = simulate(b.finalize(), "projection", dt=dt, duration=1.2, integrator=integrator)
    x, vx = run.arrays["body_position"][:, 0, 0], run.arrays["body_velocity"][:, 0, 0]
    # stopped: slower than the projection resolves, its tolerance (a displacement per sweep) per step
    stopped = np.argmax(np.abs(vx) < projection.Options().tolerance / dt)
    assert stopped > 0
    np.testing.assert_allclose(run.arrays["time"][stopped], v0 / (mu * G), rtol=0.03)
    np.testing.assert_allclose(x[-1], v0**2 / (2 * mu * G), rtol=0.03)


def test_block_sticks_on_an_incline_flatter_than_its_friction_angle():
    model, _ = cube_on_plane(20.0, 0.5)
    run = simulate(model, "projection", dt=0.004, duration=2.0)
    drift = np.linalg.norm(run.arrays["body_position"][:, 0] - run.arrays["body_position"][0, 0], axis=1)
    assert drift.max() < 0.001


def test_block_slides_down_a_steeper_incline_at_g_sin_minus_mu_cos():
    theta, mu = np.radians(20.0), 0.2
    model, downhill = cube_on_plane(20.0, mu)
    run = simulate(model, "projection", dt=0.004, duration=1.5)
    t = run.arrays["time"]
    along = (run.arrays["body_position"][:, 0] - run.arrays["body_position"][0, 0]) @ downhill
    acceleration = 2 * np.polyfit(t[t > 0.2], along[t > 0.2], 2)[0]
    np.testing.assert_allclose(acceleration, G * (np.sin(theta) - mu * np.cos(theta)), rtol=0.03)


@pytest.mark.parametrize("name", ["box_stack", "box_pyramid", "mass_ratio_stack"])
def test_stacks_stand(name):
    scene = load_scene(name)
    run = simulate(scene.model, "projection", scene.dt, 2.0)
    moved = np.linalg.norm(run.arrays["body_position"] - run.arrays["body_position"][0], axis=2)
    assert moved.max() < 0.01
    assert run.summary["max_penetration"] < 0.001


@pytest.mark.parametrize(
    "table, field",
    [
        ({"iterations": 0}, "iterations"),
        ({"passes": 1.5}, "passes"),
        ({"cloth_samples": -1}, "cloth_samples"),
        ({"normal": "up"}, "normal"),
    ],
)
def test_bad_options_name_the_field(table, field):
    with pytest.raises(InputError, match=field):
        projection.Options(**table)


@pytest.mark.parametrize("name", [name for name, _ in builtin_scenes()])
def test_runs_every_built_in_scene(name):
    scene = load_scene(name)
    run = simulate(
        scene.model, "projection", scene.dt, 25 * scene.dt, scene.method_options.get("projection", {}), scene.integrator
    )
    assert run.state.is_finite()
    assert run.summary["max_penetration"] < 0.01


# ---- cloth -----------------------------------------------------------------------------------


def cloth_over(obstacles, size=0.6, resolution=9, height=0.3, friction=0.4, orientation=(1, 0, 0, 0), samples=None):
    """A light cloth (0.1 kg) at ``height`` over the given obstacles [(shape, kwargs)]."""
    b = ModelBuilder()
    b.add_material("m", friction=friction, restitution=0.0)
    b.add_cloth(
        size=(size, size),
        resolution=(resolution, resolution),
        position=(0, 0, height),
        orientation=orientation,
        mass=0.1,
        stretch_stiffness=500.0,
        shear_stiffness=50.0,
        bend_stiffness=1.0,
        damping=0.01,
        thickness=0.004,
        material="m",
    )
    for shape, kwargs in obstacles:
        b.add_obstacle(shape, material="m", **kwargs)
    return b.finalize()


def obstacle_depths(model, state):
    """Depths beyond the thickness of every cloth vertex against every obstacle (particle–obstacle
    contacts: one particle on side A, not a triangle's point between three)."""
    contacts = collide(model, state)
    static = (contacts.body_b < 0) & (contacts.particles_b[:, 0] < 0) & (contacts.particles_a[:, 1] < 0)
    return contacts.depth[static]


def test_no_cloth_vertex_stays_inside_an_obstacle_after_a_projection():
    model = cloth_over(
        [("sphere", dict(radius=0.15, position=(0.05, 0.0, 0.0))), ("plane", dict(normal=(0, 0, 1)))], height=0.25
    )
    state = model.state()
    options = projection.Options()
    deepest = []
    for _ in range(120):
        state, info = projection.step(model, state, 1 / 120, options, "backward_euler")
        deepest.append(obstacle_depths(model, state).max(initial=-1.0))
    assert max(deepest) <= 1e-6
    assert max(deepest) > -0.001  # it did land on them


@pytest.mark.parametrize("friction, sticks", [(0.5, True), (0.2, False)])
def test_cloth_sticks_on_an_incline_only_when_tan_theta_is_below_mu(friction, sticks):
    theta = np.radians(20.0)
    normal = np.array([-np.sin(theta), 0.0, np.cos(theta)])
    model = cloth_over(
        [("plane", dict(normal=normal))],
        size=0.2,
        resolution=5,
        friction=friction,
        height=0.0,
        orientation=(np.cos(theta / 2), 0.0, -np.sin(theta / 2), 0.0),
    )
    state = model.state()
    state.particle_position += 0.004 * normal  # lying on the slope at its thickness
    run = simulate(
        model, "projection", dt=0.004, duration=2.0, state=state, record_every=5, integrator="backward_euler"
    )
    centre = run.arrays["particle_position"].mean(axis=1)
    drift = np.linalg.norm(centre - centre[0], axis=1)
    if sticks:
        assert drift.max() < 0.001
    else:
        t = run.arrays["time"]
        downhill = -np.array([np.cos(theta), 0.0, np.sin(theta)])
        along = (centre - centre[0]) @ downhill
        acceleration = 2 * np.polyfit(t[t > 0.2], along[t > 0.2], 2)[0]
        np.testing.assert_allclose(acceleration, G * (np.sin(theta) - friction * np.cos(theta)), rtol=0.03)


@pytest.mark.parametrize("method", ["projection", "impulse", "constraints"])
@pytest.mark.parametrize("cloth_samples, cloth_faces, pierced", [(0, False, True), (4, False, False), (0, True, False)])
def test_triangle_samples_or_face_contacts_stop_a_corner_poking_through_a_coarse_cloth(
    cloth_samples, cloth_faces, pierced, method
):
    # a 2 × 2-vertex cloth (two triangles, 0.5 m) dropped centred on a 0.1 m post: its
    # vertices never touch the post, only samples inside its triangles (P2c) or the post's
    # corners met by the triangles (collision.cloth's face contacts, on by default) can
    post = ("box", dict(half_extents=(0.05, 0.05, 0.1), position=(0.0, 0.0, 0.1)))
    model = cloth_over([post, ("plane", dict(normal=(0, 0, 1)))], size=0.5, resolution=2, height=0.3)
    options = {"cloth_samples": cloth_samples, "cloth_faces": cloth_faces}
    run = simulate(model, method, dt=0.004, duration=0.6, options=options, record_every=10)
    lowest = run.state.particle_position[:, 2].min()
    if pierced:
        assert lowest < 0.05  # fell past the post to the floor
    else:
        assert lowest > 0.15  # held up by the post's top (z = 0.2)


def test_backward_euler_drapes_at_ten_times_a_step_symplectic_euler_cannot_take():
    scene = load_scene("cloth_drape")  # backward Euler at 1/120 s by default
    with pytest.raises(SimulationDiverged):
        simulate(scene.model, "projection", scene.dt / 10, 0.35, integrator="symplectic_euler", record_every=50)
    run = simulate(scene.model, "projection", scene.dt, 0.35, integrator="backward_euler")
    assert run.state.is_finite() and obstacle_depths(scene.model, run.state).max(initial=-1.0) <= 1e-6
    assert run.arrays["contact_count"][-1] > 0  # it reached the sphere


def _largest_motion(run):
    positions = run.arrays["body_position"]
    return np.linalg.norm(positions - positions[0], axis=2).max()


def test_projection_holds_the_twenty_level_pyramid():
    """Issue 19: every box of the 210-box pyramid within 1 mm of where it started after 5 s at
    dt = 1/240, at the method's defaults (position-level friction keeps the static contacts static)."""
    from conftest import box_pyramid

    run = simulate(box_pyramid(20), "projection", 1 / 240, 5.0, record_every=60)
    assert _largest_motion(run) < 1e-3
    assert run.summary["solver"]["mean_iterations"] < 100  # converged to the tolerance, not at the cap


def test_projection_holds_an_eight_box_stack():
    from conftest import box_column

    run = simulate(box_column(8), "projection", 1 / 240, 5.0, record_every=60)
    assert _largest_motion(run) < 1e-3
