"""ModelBuilder: mass properties, frozen arrays, and one clear error per bad value."""

import numpy as np
import pytest

from contactlab import InputError, ModelBuilder


def test_inertia_from_shape_and_density():
    b = ModelBuilder()
    b.add_body("box", half_extents=(0.5, 0.25, 0.1), density=1000.0)
    b.add_body("sphere", radius=0.2, mass=3.0)
    model = b.finalize()
    mass = 1000.0 * 1.0 * 0.5 * 0.2
    assert model.body_mass[0] == pytest.approx(mass)
    np.testing.assert_allclose(model.body_inertia[0], mass / 12 * np.array([0.25 + 0.04, 1 + 0.04, 1 + 0.25]))
    np.testing.assert_allclose(model.body_inertia[1], 0.4 * 3.0 * 0.04)


def test_model_is_frozen_and_state_is_a_fresh_copy():
    b = ModelBuilder()
    b.add_body("sphere", radius=0.2, mass=3.0, position=(1, 2, 3))
    model = b.finalize()
    with pytest.raises(ValueError):
        model.body_mass[0] = 5.0
    s1 = model.state()
    s1.body_position[0, 0] = 99.0
    assert model.state().body_position[0, 0] == 1.0


def test_empty_groups_give_empty_arrays():
    b = ModelBuilder()
    b.add_obstacle("plane", normal=(0, 0, 1))
    model = b.finalize()
    assert model.body_count == 0 and model.particle_count == 0
    assert model.state().body_position.shape == (0, 3)
    assert model.state().particle_velocity.shape == (0, 3)


@pytest.mark.parametrize(
    "call, field",
    [
        (lambda b: b.add_body("sphere", radius=-1.0, mass=1.0), "radius"),
        (lambda b: b.add_body("sphere", radius=0.1, mass=-2.0), "mass"),
        (lambda b: b.add_body("sphere", radius=0.1, mass=0.0), "mass"),
        (lambda b: b.add_body("sphere", radius=0.1), "mass"),
        (lambda b: b.add_body("sphere", radius=0.1, mass=1.0, density=5.0), "mass"),
        (lambda b: b.add_body("box", half_extents=(1, 0, 1), mass=1.0), "half_extents"),
        (lambda b: b.add_body("box", half_extents=(1, 1), mass=1.0), "half_extents"),
        (lambda b: b.add_body("cylinder", radius=1.0, mass=1.0), "shape"),
        (lambda b: b.add_body("sphere", radius=0.1, mass=1.0, position=(0, float("nan"), 0)), "position"),
        (lambda b: b.add_body("sphere", radius=0.1, mass=1.0, orientation=(0, 0, 0, 0)), "orientation"),
        (lambda b: b.add_body("sphere", radius=0.1, mass=1.0, material="steel"), "material"),
        (lambda b: b.add_material("m", friction=-0.1), "friction"),
        (lambda b: b.add_material("m", restitution=1.5), "restitution"),
        (lambda b: b.add_particles([[0, 0, 0]], mass=0.0), "mass"),
        (lambda b: b.add_particles([[0, 0, 0]], velocity=[[0, 0, 0], [1, 1, 1]]), "velocity"),
        (lambda b: b.add_obstacle("plane", normal=(0, 0, 0)), "normal"),
        (lambda b: b.add_body("sphere", radius=0.1, mass=1.0, velocity="fast"), "velocity"),
        (lambda b: b.add_particles([[0, 0, 0], [1, 1]]), "position"),
        (lambda b: b.add_particles([[0, 0, 0], [1, 1, 1]], mass=[1.0, 2.0, 3.0]), "mass"),
        (lambda b: b.add_particles([[0, 0, 0]], radius=-0.5), "radius"),
    ],
)
def test_bad_values_raise_one_clear_error(call, field):
    with pytest.raises(InputError) as error:
        call(ModelBuilder())
    assert error.value.field == field
    assert "\n" not in str(error.value)


def test_messages_show_plain_numbers():
    with pytest.raises(InputError) as error:
        ModelBuilder().add_body("box", half_extents=(0.1, -0.1, 0.1), mass=1.0)
    assert "[0.1, -0.1, 0.1]" in str(error.value)


def test_capsule_mass_properties_against_voxels():
    b = ModelBuilder()
    b.add_body("capsule", radius=0.05, half_length=0.12, density=1000.0)
    model = b.finalize()
    r, h, n = 0.05, 0.12, 161
    axis = [np.linspace(-r, r, n), np.linspace(-r, r, n), np.linspace(-h - r, h + r, 3 * n)]
    x, y, z = np.meshgrid(*axis, indexing="ij")
    inside = x**2 + y**2 + np.maximum(np.abs(z) - h, 0) ** 2 <= r**2
    cell = np.prod([a[1] - a[0] for a in axis])
    mass = 1000.0 * inside.sum() * cell
    assert model.body_mass[0] == pytest.approx(mass, rel=3e-3)
    dm = 1000.0 * cell
    Ixx = dm * np.sum((y**2 + z**2)[inside])
    Izz = dm * np.sum((x**2 + y**2)[inside])
    np.testing.assert_allclose(model.body_inertia[0], [Ixx, Ixx, Izz], rtol=5e-3)


def test_an_unknown_material_names_the_materials_there_are_default_included():
    with pytest.raises(InputError) as error:
        ModelBuilder().add_body("sphere", radius=0.1, mass=1.0, material="steel")
    assert "unknown material 'steel': the materials are 'default', contactlab's own (friction 0.5" in str(error.value)
    b = ModelBuilder()
    b.add_material("rubber", friction=0.9, restitution=0.8)
    with pytest.raises(InputError) as error:
        b.add_body("sphere", radius=0.1, mass=1.0, material="steel")
    assert "the materials are 'rubber' and 'default'" in str(error.value)
    assert "define 'steel' first" in str(error.value)


def test_state_model_and_run_print_in_one_short_line():
    from contactlab import simulate

    b = ModelBuilder()
    b.add_body("sphere", radius=0.1, mass=1.0, position=(0, 0, 1))
    b.add_body("box", half_extents=(0.1, 0.1, 0.1), mass=1.0, position=(1, 0, 1))
    b.add_obstacle("plane", normal=(0, 0, 1))
    model = b.finalize()
    run = simulate(model, "impulse", 0.01, 0.02, scene_name="two")
    assert repr(model) == "Model(1 sphere, 1 box, 1 obstacle)"
    assert repr(run.state) == "State(t = 0.02 s, 2 bodies, 0 particles)"
    assert repr(run) == f"Run('two' with impulse: 2 steps of 0.01 s, 3 samples, final {run.state!r})"
