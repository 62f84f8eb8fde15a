"""A body's inertia given in the builder or the scene file (issue 40, item 4): checked, and used
by every method — against closed forms computed here from the given numbers, not the model's."""

import numpy as np
import pytest

from contactlab import closed_form
from contactlab.builder import ModelBuilder
from contactlab.errors import InputError
from contactlab.rotations import to_matrix
from contactlab.scene import load_scene
from contactlab.simulation import simulate

METHODS = ("penalty", "projection", "impulse", "constraints")
GIVEN = np.array([0.002, 0.003, 0.004])  # kg m², a 1 kg cube of 0.2 m side has 0.00667 about each axis


def _spinning_cube(inertia=GIVEN, **keywords):
    """A cube spinning in free fall 10 m above a floor it never reaches in the runs here (1.3 m
    at most): torque-free. The floor makes the scene a box over a plane, as rod_impact, incline
    and sliding_block are, so its runs take the kernels those compile (a scene without any
    obstacle is a plan of its own, compiled for these tests alone)."""
    builder = ModelBuilder(gravity=(0, 0, -9.81))
    builder.add_body(
        "box",
        half_extents=(0.1, 0.1, 0.1),
        mass=1.0,
        inertia=inertia,
        position=(0, 0, 10.0),
        angular_velocity=(3.0, 1.0, 2.0),
        **keywords,
    )
    builder.add_obstacle("plane", normal=(0, 0, 1))
    return builder.finalize()


@pytest.mark.parametrize("method", METHODS)
def test_a_torque_free_spin_keeps_the_angular_momentum_of_the_given_inertia(method):
    # the uniform cube's inertia is isotropic, so it would spin at a constant ω; the given one
    # makes ω wander (Euler's equations) while L = R I Rᵀ ω, with I the numbers given, stays put
    model = _spinning_cube()
    assert model.body_inertia[0] == pytest.approx(GIVEN)
    run = simulate(model, method, 0.0005, 0.5, compiled_loop=False)
    assert run.summary["max_contacts"] == 0  # the floor stays out of reach
    R = to_matrix(run.arrays["body_orientation"][:, 0])
    w = run.arrays["body_angular_velocity"][:, 0]
    momentum = np.einsum("tij,j,tkj,tk->ti", R, GIVEN, R, w)
    assert np.linalg.norm(w[-1] - w[0]) > 0.5  # it wanders
    assert np.abs(momentum - momentum[0]).max() < 2e-3 * np.linalg.norm(momentum[0])
    energy = 0.5 * np.einsum("ti,ti->t", w, momentum)
    assert np.abs(energy - energy[0]).max() < 2e-3 * energy[0]


def test_the_compiled_loop_and_the_python_stages_agree_on_a_given_inertia():
    model = _spinning_cube()
    looped = simulate(model, "impulse", 0.001, 0.2, compiled_loop=True)
    stepped = simulate(model, "impulse", 0.001, 0.2, compiled_loop=False)
    assert looped.summary["max_contacts"] == stepped.summary["max_contacts"] == 0
    looped, stepped = looped.arrays, stepped.arrays
    assert np.array_equal(looped["body_angular_velocity"], stepped["body_angular_velocity"])
    assert np.array_equal(looped["body_orientation"], stepped["body_orientation"])


def _corner_impact(method, inertia):
    settings = [f"bodies.0.inertia={[float(x) for x in inertia]}", f"simulation.method={method}"]
    scene = load_scene("rod_impact", [*settings, "simulation.duration=0.4"])
    run = scene.simulate(compiled_loop=False)
    measured = {check.quantity: check.measured for check in closed_form.checks("rod_impact", scene.model, run.arrays)}
    return scene, run, measured


@pytest.mark.parametrize("method, tolerance", [("impulse", 1e-4), ("constraints", 1e-4), ("penalty", 0.05)])
def test_a_corner_impact_spins_the_body_by_the_given_inertia(method, tolerance):
    # one impulse j n at the corner r: ω⁺ = I⁻¹ (r × j n), with I the given moments turned to the world
    inertia = np.array([0.0005, 0.1, 0.1])  # the uniform rod's are 0.000417, 0.0835, 0.0835
    scene, run, measured = _corner_impact(method, inertia)
    R = to_matrix(run.arrays["body_orientation"][0, 0])
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * [0.5, 0.025, 0.025]
    r = min(corners @ R.T, key=lambda c: c[2])
    g, drop = 9.81, run.arrays["body_position"][0, 0, 2] + r[2]
    up = np.array([0.0, 0.0, 1.0])
    inverse = R @ np.diag(1.0 / inertia) @ R.T
    j = (1.0 + 0.5) * np.sqrt(2 * g * drop) / (1.0 + up @ np.cross(inverse @ np.cross(r, up), r))
    spin = (inverse @ np.cross(r, j * up))[1]
    assert abs(spin) > 7.0 and abs(spin - (-7.621)) > 0.3  # not the uniform rod's answer
    assert measured["angular velocity about y after the impact"] == pytest.approx(spin, rel=tolerance)


def test_projection_turns_the_rod_by_the_given_inertia():
    # projection keeps no restitution to meet R4 with; its response to the corner still follows
    # the inertia: a rod stiffer to turn about y turns less by the end
    turned = []
    for inertia in ([0.0005, 0.1, 0.1], [0.0005, 0.3, 0.3]):
        _, run, _ = _corner_impact("projection", inertia)
        turned.append(np.abs(run.arrays["body_angular_velocity"][:, 0, 1]).max())
    assert turned[1] < 0.8 * turned[0]


def test_a_full_tensor_turns_a_sphere_and_a_hull_onto_its_principal_axes():
    c, s = np.cos(0.3), np.sin(0.3)
    axes = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])  # principal axes: 0.3 rad about z
    tensor = axes @ np.diag([0.002, 0.003, 0.004]) @ axes.T
    builder = ModelBuilder()
    builder.add_body("sphere", radius=0.1, mass=1.0, inertia=tensor.tolist())
    cube = np.array([[x, y, z] for x in (-0.1, 0.1) for y in (-0.1, 0.1) for z in (-0.1, 0.1)])
    builder.add_body("convex", points=cube, mass=1.0, inertia=tensor.tolist())
    model = builder.finalize()
    for body in range(2):
        assert model.body_inertia[body] == pytest.approx([0.002, 0.003, 0.004])
        R = to_matrix(model.initial.body_orientation[body])
        assert R @ np.diag(model.body_inertia[body]) @ R.T == pytest.approx(tensor, abs=1e-12)
    # the hull's corners are where they were given, in the world
    start, end = model.hulls["vertex_start"][0], model.hulls["vertex_start"][1]
    world = model.hulls["vertices"][start:end] @ to_matrix(model.initial.body_orientation[1]).T
    assert sorted(map(tuple, np.round(world, 12))) == sorted(map(tuple, np.round(cube, 12)))


@pytest.mark.parametrize(
    "inertia, words",
    [
        ([1.0, 1.0, 3.0], "break the triangle inequality"),
        ([-1.0, 1.0, 1.0], "expected a positive definite tensor"),
        ([[1, 0.1, 0], [0, 1, 0], [0, 0, 1]], "expected a symmetric tensor, found [0][1] = 0.1 but [1][0] = 0"),
        ([1.0, 2.0], "expected three principal moments"),
        ([1.0, float("nan"), 1.0], "expected finite numbers"),
        ([[1, 0.1, 0], [0.1, 1, 0], [0, 0, 1]], "a box's inertia must be diagonal in its own axes"),
    ],
)
def test_a_bad_inertia_is_one_sentence_naming_the_field(inertia, words):
    builder = ModelBuilder()
    with pytest.raises(InputError) as refused:
        builder.add_body("box", half_extents=(0.1, 0.1, 0.1), mass=1.0, inertia=inertia)
    assert refused.value.field == "inertia" and words in refused.value.message, refused.value


def test_the_scene_file_names_the_body_whose_inertia_is_wrong():
    with pytest.raises(InputError) as refused:
        load_scene("rod_impact", ["bodies.0.inertia=[[1, 2], [3]]"])
    assert refused.value.field == "bodies[0].inertia", refused.value
