"""Narrow phase against hand-computed configurations, the broad phase against brute force."""

import numpy as np
import pytest

from contactlab import ModelBuilder, collide, rotations
from contactlab.collision.broad_phase import (
    brute_force_pairs,
    grid_pairs,
    neighbour_cell_pairs,
    overlapping_pairs,
    sweep_and_prune,
)
from contactlab.errors import InputError


def contacts_of(builder):
    model = builder.finalize()
    return collide(model, model.state())


def test_sphere_plane_depth_normal_point():
    b = ModelBuilder()
    b.add_body("sphere", radius=0.1, mass=1, position=(0.3, -0.2, 0.09))
    b.add_obstacle("plane", normal=(0, 0, 2), offset=0.0)  # normal is normalized
    c = contacts_of(b)
    assert c.count == 1
    assert c.depth[0] == pytest.approx(0.01)
    np.testing.assert_allclose(c.normal[0], [0, 0, 1])
    np.testing.assert_allclose(c.point[0], [0.3, -0.2, -0.005])  # midway between the surfaces
    assert c.body_a[0] == 0 and c.body_b[0] == -1 and (c.particles_b[0] == -1).all()


def test_tilted_plane_with_offset():
    b = ModelBuilder()
    n = np.array([1.0, 0.0, 1.0]) / np.sqrt(2)
    b.add_obstacle("plane", normal=n, offset=0.5)
    b.add_body("sphere", radius=0.2, mass=1, position=tuple(n * (0.5 + 0.15)))
    c = contacts_of(b)
    assert c.depth[0] == pytest.approx(0.05)
    np.testing.assert_allclose(c.normal[0], n, atol=1e-12)


def test_sphere_sphere_normal_points_from_b_into_a():
    b = ModelBuilder()
    b.add_body("sphere", radius=0.1, mass=1, position=(0, 0, 0))
    b.add_body("sphere", radius=0.2, mass=1, position=(0.25, 0, 0))
    c = contacts_of(b)
    assert c.count == 1 and c.depth[0] == pytest.approx(0.05)
    # A is the lower index (body 0), B is body 1 on its +x side: normal B→A is −x
    assert (c.body_a[0], c.body_b[0]) == (0, 1)
    np.testing.assert_allclose(c.normal[0], [-1, 0, 0])
    np.testing.assert_allclose(c.point[0], [0.075, 0, 0])


def test_particles_against_plane_and_static_sphere():
    b = ModelBuilder()
    b.add_particles([[0, 0, -0.01], [5, 0, 1.0], [5, 0, 0.5 + 0.003]], radius=0.0)
    b.add_obstacle("plane", normal=(0, 0, 1), offset=0.0)
    b.add_obstacle("sphere", radius=0.5, position=(5, 0, 0))
    c = contacts_of(b)
    assert c.count == 1  # the point above the sphere is 3 mm off
    assert c.particles_a[0, 0] == 0 and c.weights_a[0, 0] == 1.0
    assert c.depth[0] == pytest.approx(0.01)
    b2 = ModelBuilder()
    b2.add_particles([[5, 0, 0.49]], radius=0.02)
    b2.add_obstacle("sphere", radius=0.5, position=(5, 0, 0))
    c2 = contacts_of(b2)
    assert c2.depth[0] == pytest.approx(0.03)
    np.testing.assert_allclose(c2.normal[0], [0, 0, 1])


def test_box_plane_gives_the_penetrating_corners():
    b = ModelBuilder()
    b.add_body("box", half_extents=(0.2, 0.1, 0.05), mass=1, position=(0, 0, 0.049))
    b.add_obstacle("plane", normal=(0, 0, 1))
    c = contacts_of(b)
    assert c.count == 4
    np.testing.assert_allclose(c.depth, 0.001)
    np.testing.assert_allclose(np.sort(np.abs(c.point[:, :2]), axis=0), [[0.2, 0.1]] * 4)
    assert len(set(c.feature_id)) == 4


def test_tilted_box_touches_with_one_corner():
    angle = np.radians(30)
    q = (np.cos(angle / 2), 0.0, np.sin(angle / 2), 0.0)  # about y
    half = np.array([0.5, 0.025, 0.025])
    R = rotations.to_matrix(np.array([q]))[0]
    lowest = min((R @ (half * s))[2] for s in np.array(np.meshgrid(*[[-1, 1]] * 3)).T.reshape(-1, 3))
    b = ModelBuilder()
    b.add_body("box", half_extents=half, mass=1, position=(0, 0, -lowest - 0.002), orientation=q)
    b.add_obstacle("plane", normal=(0, 0, 1))
    c = contacts_of(b)
    assert c.count == 2  # the two corners of the lowest edge (thin in y)
    np.testing.assert_allclose(c.depth, 0.002, atol=1e-12)


def test_sphere_against_static_box_outside_and_inside():
    b = ModelBuilder()
    b.add_obstacle("box", half_extents=(1, 1, 1), position=(0, 0, 0))
    b.add_body("sphere", radius=0.1, mass=1, position=(1.05, 1.05, 0.0))  # near an edge
    c = contacts_of(b)
    expected_normal = np.array([1, 1, 0]) / np.sqrt(2)
    np.testing.assert_allclose(c.normal[0], expected_normal)
    assert c.depth[0] == pytest.approx(0.1 - np.sqrt(2) * 0.05)
    b2 = ModelBuilder()
    b2.add_obstacle("box", half_extents=(1, 1, 1))
    b2.add_body("sphere", radius=0.1, mass=1, position=(0.0, 0.0, 0.95))  # centre inside, near the top
    c2 = contacts_of(b2)
    np.testing.assert_allclose(c2.normal[0], [0, 0, 1])
    assert c2.depth[0] == pytest.approx(0.15)


def test_swapping_shapes_flips_the_normal_and_nothing_else():
    from contactlab import shapes
    from contactlab.collision.narrow_phase import collide_pair, empty_hull_store

    rng = np.random.default_rng(3)
    for _ in range(200):
        q = rotations.normalize(rng.normal(size=(1, 4)))
        R = rotations.to_matrix(q)[0]
        box = (shapes.BOX, np.array([0.3, 0.2, 0.1, 0]), (rng.normal(scale=0.1, size=3), R))
        sphere = (shapes.SPHERE, np.array([0.15, 0, 0, 0]), (rng.normal(scale=0.2, size=3), np.eye(3)))
        out = (np.zeros((8, 3)), np.zeros((8, 3)), np.zeros(8), np.zeros(8, dtype=np.int64))
        out2 = (np.zeros((8, 3)), np.zeros((8, 3)), np.zeros(8), np.zeros(8, dtype=np.int64))
        n1 = collide_pair(box, sphere, 0.0, empty_hull_store(), out, 0)
        n2 = collide_pair(sphere, box, 0.0, empty_hull_store(), out2, 0)
        assert n1 == n2
        np.testing.assert_allclose(out[1][:n1], -out2[1][:n2])
        np.testing.assert_allclose(out[0][:n1], out2[0][:n2])
        np.testing.assert_allclose(out[2][:n1], out2[2][:n2])


def test_broad_phase_equals_brute_force(rng):
    for count in (1, 2, 50, 500):
        centers = rng.uniform(-1, 1, size=(count, 3))
        half = rng.uniform(0.01, 0.15, size=(count, 3))
        fast = overlapping_pairs(centers - half, centers + half)
        slow = brute_force_pairs(centers - half, centers + half)
        assert sorted(map(tuple, fast)) == sorted(map(tuple, slow))


@pytest.mark.parametrize("layout", ["pile", "mixed sizes", "one huge box", "all in one place", "one far away"])
def test_hash_grid_equals_sweep_and_prune_and_brute_force(rng, layout):
    count = 1500
    if layout == "pile":  # a dense column: the case where sweep and prune tests O(n²)
        centers = rng.uniform([-0.5, -0.5, 0.0], [0.5, 0.5, 3.0], size=(count, 3))
        half = np.full((count, 3), 0.05)
    elif layout == "mixed sizes":
        centers = rng.uniform(-2, 2, size=(count, 3))
        half = rng.uniform(0.001, 0.3, size=(count, 3))
    elif layout == "one huge box":
        centers = rng.uniform(-1, 1, size=(count, 3))
        half = np.full((count, 3), 0.02)
        half[7] = 1.5
    elif layout == "all in one place":
        centers = rng.normal(scale=1e-3, size=(count, 3))
        half = np.full((count, 3), 0.01)
    else:  # a grid spanning 1e6 m would need 10^21 cells: hashed instead
        centers = rng.uniform(-1, 1, size=(count, 3))
        centers[3] = 1e6
        half = np.full((count, 3), 0.02)
    lower, upper = centers - half, centers + half
    expected = sorted(map(tuple, brute_force_pairs(lower, upper)))
    assert sorted(map(tuple, grid_pairs(lower, upper))) == expected
    assert sorted(map(tuple, sweep_and_prune(lower, upper))) == expected
    neighbours, done = neighbour_cell_pairs(lower, upper)
    # a box 75x the others' size, or one 1e6 m away (10^21 cells): left to the hash grid
    assert done == (layout not in ("one huge box", "one far away"))
    if done:
        assert list(map(tuple, neighbours)) == expected  # sorted as they come
    assert list(map(tuple, overlapping_pairs(lower, upper))) == expected  # sorted, no duplicates


def test_contact_ids_persist_while_the_contact_lasts():
    b = ModelBuilder()
    b.add_body("box", half_extents=(0.1, 0.1, 0.1), mass=1, position=(0, 0, 0.099))
    b.add_obstacle("plane", normal=(0, 0, 1))
    model = b.finalize()
    state = model.state()
    first = collide(model, state)
    state.body_position[0, 0] += 0.01
    state.body_position[0, 2] -= 0.0005
    second = collide(model, state)
    assert sorted(first.feature_id) == sorted(second.feature_id)


# ---- no tunnelling: speculative contacts over the swept step ------------------------------


def _fast_scene(add_obstacles, body="sphere"):
    from contactlab import simulate

    b = ModelBuilder(gravity=(0, 0, 0))
    b.add_material("m", friction=0.0, restitution=0.0)
    radius, dt = 0.01, 0.001
    speed = 10 * radius / dt  # 10 radii per step
    if body == "sphere":
        b.add_body("sphere", radius=radius, mass=1.0, position=(-0.0537, 0, 0), velocity=(speed, 0, 0), material="m")
    else:
        b.add_particles([[-0.0537, 0, 0]], velocity=[[speed, 0, 0]], radius=radius, material="m")
    add_obstacles(b)
    run = simulate(b.finalize(), "impulse", dt=dt, duration=0.02)
    key = "body_position" if body == "sphere" else "particle_position"
    return run.arrays[key][:, 0, 0], radius


@pytest.mark.parametrize("body", ["sphere", "particle"])
def test_nothing_fast_passes_through_a_plane(body):
    x, radius = _fast_scene(lambda b: b.add_obstacle("plane", normal=(-1, 0, 0), offset=0.0, material="m"), body)
    assert x.max() <= -radius + 1e-12


@pytest.mark.parametrize("body", ["sphere", "particle"])
def test_nothing_fast_passes_through_a_thin_box_wall(body):
    # a wall 2 mm thick: at 10 radii (0.1 m) per step, a test at the end positions would miss it
    x, radius = _fast_scene(
        lambda b: b.add_obstacle("box", half_extents=(0.001, 1, 1), position=(0, 0, 0), material="m"), body
    )
    assert x.max() <= -0.001 - radius + 1e-12


def test_fast_sphere_does_not_pass_through_another():
    from contactlab import simulate

    b = ModelBuilder(gravity=(0, 0, 0))
    b.add_material("m", friction=0.0, restitution=0.0)
    b.add_body("sphere", radius=0.01, mass=1.0, position=(-0.0537, 0, 0), velocity=(100.0, 0, 0), material="m")
    b.add_body("sphere", radius=0.01, mass=1.0, position=(0.0, 0, 0), material="m")
    run = simulate(b.finalize(), "impulse", dt=0.001, duration=0.02)
    x = run.arrays["body_position"][:, :, 0]
    assert (x[:, 1] - x[:, 0] >= 2 * 0.01 - 1e-9).all()  # never overlapping, never crossed
    np.testing.assert_allclose(run.arrays["body_velocity"][-1, :, 0], [50.0, 50.0])  # inelastic: shared


def test_collider_rotations_are_laid_out_for_the_compiled_pair_routines():
    """The narrow phase is compiled for C-ordered rotations; rotations.to_matrix returns other
    strides, which would compile a second, slower specialization (Numba warns about it)."""
    from contactlab.collision import state_poses

    b = ModelBuilder()
    b.add_body("box", half_extents=(0.1, 0.1, 0.1), mass=1, orientation=(0.9, 0.1, 0.3, 0.2))
    b.add_obstacle("plane", normal=(0, 0, 1))
    model = b.finalize()
    assert state_poses(model, model.state())[1].flags.c_contiguous


def test_bounds_enclose_every_shape(rng):
    """The broad phase's boxes contain every point of the shapes (sampled on their surfaces)."""
    from contactlab.collision import _bounds, colliders, state_poses

    b = ModelBuilder()
    for _ in range(20):
        q = rng.normal(size=4)
        b.add_body("capsule", radius=0.05, half_length=0.2, mass=1, orientation=q, position=rng.normal(size=3))
        b.add_body(
            "box", half_extents=(0.3, 0.1, 0.05), mass=1, orientation=rng.normal(size=4), position=rng.normal(size=3)
        )
        b.add_body("sphere", radius=0.1, mass=1, position=rng.normal(size=3))
    model = b.finalize()
    state = model.state()
    kinds, params = colliders(model).kinds, colliders(model).params
    centers, rots = state_poses(model, state)
    lower, upper = _bounds(kinds, params, centers, rots, np.zeros(len(kinds)))
    R = rotations.to_matrix(state.body_orientation)
    directions = rng.normal(size=(500, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    for i, (kind, p) in enumerate(zip(model.body_shape, model.body_params)):
        if kind == 4:  # capsule: segment ends plus radius
            local = np.concatenate([directions * p[0] + [0, 0, p[1]], directions * p[0] - [0, 0, p[1]]])
        elif kind == 1:
            local = np.clip(directions * 10, -p[:3], p[:3])
        else:
            local = directions * p[0]
        world = local @ R[i].T + state.body_position[i]
        assert (world >= lower[i] - 1e-12).all() and (world <= upper[i] + 1e-12).all()


def test_mesh_bowl_holds_everything_dropped_into_it():
    from contactlab import simulate
    from contactlab.scene import load_scene

    scene = load_scene("mesh_bowl")
    run = simulate(scene.model, scene.method, scene.dt, 2.0)
    mesh = scene.model.meshes[0]
    lowest_inner = 0.04  # the bowl's wall is 4 cm thick at the bottom
    assert run.arrays["particle_position"][:, :, 2].min() >= lowest_inner + 0.01 - 1e-3
    radial = np.linalg.norm(run.arrays["particle_position"][-1, :, :2], axis=1)
    assert radial.max() < 0.5  # all inside the rim
    assert np.abs(run.arrays["particle_velocity"][-1]).max() < 1e-3
    assert run.summary["max_penetration"] < 3e-3
    assert mesh.triangles.shape[0] == 1536


@pytest.mark.parametrize("body", ["sphere", "particle"])
def test_nothing_fast_passes_through_a_one_triangle_sheet(tmp_path, body):
    (tmp_path / "sheet.obj").write_text("v 0 -1 -1\nv 0 1 -1\nv 0 0 2\nf 1 3 2\n")  # front side −x

    def sheet(b):
        b.add_obstacle("mesh", file=str(tmp_path / "sheet.obj"), material="m")

    x, radius = _fast_scene(sheet, body)
    assert x.max() <= -radius + 1e-9


def test_mesh_input_errors(tmp_path):
    (tmp_path / "junk.obj").write_text("this is not a mesh\n")
    for file, words in (("missing.obj", "missing.obj"), ("junk.obj", "junk.obj")):
        b = ModelBuilder()
        with pytest.raises(InputError) as error:
            b.add_obstacle("mesh", file=str(tmp_path / file))
        assert error.value.field == "file" and words in error.value.message
    with pytest.raises(InputError) as error:
        ModelBuilder().add_obstacle("mesh", file=str(tmp_path / "junk.obj"), scale=0.0)
    assert error.value.field == "scale"


def test_every_dynamic_shape_rests_on_a_mesh_floor(tmp_path):
    from contactlab import simulate

    (tmp_path / "floor.obj").write_text("v -2 -2 0\nv 2 -2 0\nv 2 2 0\nv -2 2 0\nf 1 2 3\nf 1 3 4\n")
    b = ModelBuilder()
    b.add_material("m", friction=0.6)
    b.add_obstacle("mesh", file=str(tmp_path / "floor.obj"), material="m")
    lying = (np.cos(np.pi / 4), np.sin(np.pi / 4), 0, 0)
    b.add_body("capsule", radius=0.05, half_length=0.2, mass=1, position=(-1, 0, 0.06), orientation=lying, material="m")
    cube = [[x, y, z] for x in (-0.1, 0.1) for y in (-0.1, 0.1) for z in (-0.1, 0.1)]
    b.add_body("convex", points=cube, mass=1, position=(1, 0, 0.11), material="m")
    b.add_body("box", half_extents=(0.1, 0.1, 0.1), mass=1, position=(0, 1, 0.11), material="m")
    b.add_body("sphere", radius=0.1, mass=1, position=(0, -1, 0.11), material="m")
    run = simulate(b.finalize(), "impulse", 1 / 240, 1.0)
    np.testing.assert_allclose(run.arrays["body_position"][-1, :, 2], [0.05, 0.1, 0.1, 0.1], atol=1e-3)
    assert np.abs(run.arrays["body_velocity"][-1]).max() < 1e-3


# ---- SPEC P2 granularity and P4/P5 normals for rigid polytopes --------------------------


def _box_and_hull_on_plane(tilt=0.0):
    b = ModelBuilder()
    q = (np.cos(tilt / 2), np.sin(tilt / 2), 0.0, 0.0)
    b.add_body("box", half_extents=(0.1, 0.1, 0.1), mass=1, position=(0, 0, 0.099), orientation=q)
    cube = [[x, y, z] for x in (-0.1, 0.1) for y in (-0.1, 0.1) for z in (-0.1, 0.1)]
    b.add_body("convex", points=cube, mass=1, position=(1, 0, 0.098), orientation=q)
    b.add_obstacle("plane", normal=(0, 0, 1))
    return b.finalize()


@pytest.mark.parametrize(
    "granularity, samples, per_body", [("object", 2, 1), ("vertex", 2, 4), ("samples", 2, 8), ("samples", 3, 18)]
)
def test_p2_granularity_counts(granularity, samples, per_body):
    model = _box_and_hull_on_plane()
    c = collide(model, model.state(), 0.0, None, granularity, "object", samples)
    assert np.bincount(c.body_a).tolist() == [per_body, per_body]
    np.testing.assert_allclose(c.normal, np.tile([0, 0, 1.0], (c.count, 1)))
    # the deepest contact of each body is its true depth
    assert [c.depth[c.body_a == i].max() for i in (0, 1)] == pytest.approx([0.001, 0.002])
    assert len(set(c.feature_id)) == c.count


def test_p5_normal_is_the_negated_surface_normal_of_the_body():
    model = _box_and_hull_on_plane()
    c = collide(model, model.state(), 0.0, None, "vertex", "vertex")
    corners = c.point - model.state().body_position[c.body_a]
    expected = -np.sign(corners) / np.sqrt(3)  # −(a cube corner's own normal)
    np.testing.assert_allclose(c.normal, expected, atol=1e-12)  # a diagonal, not the plane's
    assert (c.normal[:, 2] > 0).all() and (np.abs(c.normal[:, :2]) > 0.5).all()  # not the plane's normal


def test_vertex_and_sample_contacts_hold_a_box_flat_one_contact_per_object_does_not():
    """The lecture's trade-off of P2: one force for the whole object cannot hold a box flat."""
    from contactlab import simulate

    drift = {}
    for options in ({"granularity": "object"}, {"granularity": "samples", "samples": 2}, {"granularity": "vertex"}):
        b = ModelBuilder()
        b.add_body("box", half_extents=(0.1, 0.1, 0.1), mass=1, position=(0, 0, 0.1))
        b.add_obstacle("plane", normal=(0, 0, 1))
        run = simulate(b.finalize(), "impulse", 1 / 240, 1.0, options)
        drift[options["granularity"]] = np.abs(run.arrays["body_position"][-1] - [0, 0, 0.1]).max()
    assert drift["vertex"] < 1e-4 and drift["samples"] < 1e-4
    assert drift["object"] > 10 * drift["vertex"]
    with pytest.raises(InputError):
        simulate(b.finalize(), "impulse", 1 / 240, 0.1, {"granularity": "faces"})


# ---- no method tunnels (issue 19): a small, fast body against a thin plate --------------------

PLATE_HALF = 0.005  # m: a 1 cm plate
SMALL = 0.01  # m: the thrown sphere's, particle's and cloth vertices' radius


def _thrown_at_a_plate(kind, speed):
    """A plate 1 cm thick at z = 0 and, 0.3 m above it, a 1 cm sphere, particle or small cloth
    thrown down at ``speed`` [m/s] (at 1/240 s, 200 m/s is 83 cm a step: 40 of its diameters)."""
    b = ModelBuilder()
    b.add_material("m", friction=0.0, restitution=0.0)
    b.add_obstacle("box", half_extents=(0.5, 0.5, PLATE_HALF), position=(0, 0, 0), material="m")
    if kind == "sphere":
        b.add_body("sphere", radius=SMALL, mass=0.01, position=(0, 0, 0.3), velocity=(0, 0, -speed), material="m")
    elif kind == "particle":
        b.add_particles([[0, 0, 0.3]], [[0, 0, -speed]], mass=0.01, radius=SMALL, material="m")
    else:
        b.add_cloth(
            size=(0.1, 0.1),
            resolution=(3, 3),
            position=(0, 0, 0.3),
            velocity=(0, 0, -speed),
            mass=0.05,
            thickness=SMALL,
            material="m",
        )
    return b.finalize()


@pytest.mark.parametrize("method", ["impulse", "constraints", "penalty", "projection"])
@pytest.mark.parametrize("kind", ["sphere", "particle", "cloth"])
@pytest.mark.parametrize("speed", [5.0, 200.0])
def test_nothing_fast_tunnels_through_a_thin_box(method, kind, speed):
    """Under every method: no centre or vertex ever crosses the plate's middle, and all come to
    rest on it, above its top face but for a penalty spring's overlap (at most half the
    pass-through depth, PLATE_HALF + SMALL, by penalty's guard)."""
    from contactlab import simulate

    model = _thrown_at_a_plate(kind, speed)
    run = simulate(model, method, dt=1 / 240, duration=0.4)
    z = run.arrays["body_position" if kind == "sphere" else "particle_position"][..., 2]
    deepest = 0.5 * (PLATE_HALF + SMALL) if method == "penalty" else 1e-6
    assert z.min() >= PLATE_HALF + SMALL - deepest - 1e-9
    assert np.all(z[-1] > PLATE_HALF)  # resting on top, not below
