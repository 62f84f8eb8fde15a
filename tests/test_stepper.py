"""The public per-step API (issue 57, item 2): a Stepper steps what simulate steps, bit for bit,
through the compiled loop or the methods' step, and the state it shows is the one the next
step starts from."""

import numpy as np
import pytest

from contactlab import ModelBuilder, Stepper, simulate
from contactlab.errors import InputError, SimulationDiverged
from contactlab.scene import load_scene
from contactlab.state import ARRAYS


def same_state(a, b):
    return all(np.array_equal(getattr(a, name), getattr(b, name)) for name in ARRAYS) and a.time == b.time


def small_cloth():
    b = ModelBuilder()
    b.add_material("cotton", friction=0.4, restitution=0.0)
    b.add_cloth(
        size=(0.2, 0.2), resolution=(4, 4), mass=0.02, position=(0.0, 0.0, 0.03), thickness=0.004, material="cotton"
    )
    b.add_obstacle("plane", normal=(0, 0, 1), offset=0.0, material="cotton")
    return b.finalize()


@pytest.mark.parametrize("method", ["impulse", "penalty"])
def test_steps_one_at_a_time_or_many_give_simulates_state_bit_for_bit(method):
    model = load_scene("bouncing_ball").model
    run = simulate(model, method, 0.002, 1.2, record_every=600)
    one, many = Stepper(model, method, dt=0.002), Stepper(model, method, dt=0.002)
    for _ in range(600):
        one.step()
    many.step(250)
    many.step(350)
    assert one.compiled and one.steps_made == many.steps_made == 600
    assert same_state(one.state, run.state) and same_state(many.state, run.state)


def test_a_cloth_steps_through_the_methods_step_as_simulate_does():
    model = small_cloth()
    run = simulate(model, "projection", 1 / 120, 0.25, None, "backward_euler", record_every=30)
    stepper = Stepper(model, "projection", dt=1 / 120, integrator="backward_euler")
    stepper.step(30)
    assert not stepper.compiled
    assert same_state(stepper.state, run.state)


def test_what_the_loop_writes_into_the_state_is_where_the_next_step_starts():
    model = load_scene("bouncing_ball").model
    stepper = Stepper(model, "impulse", dt=0.001)
    stepper.step(100)
    z = stepper.state.body_position[0, 2]
    stepper.state.body_velocity[0] = (1.0, 0.0, 0.0)  # a push along x, no fall speed
    stepper.step()
    # one symplectic Euler step from that velocity: x moves by v dt, z by −g dt²
    assert stepper.state.body_position[0, 0] == pytest.approx(0.001, abs=1e-15)
    assert stepper.state.body_position[0, 2] == pytest.approx(z - 9.81 * 1e-6, abs=1e-15)
    kept = stepper.state.copy()
    stepper.step()
    assert kept.time == pytest.approx(0.101) and stepper.time == pytest.approx(0.102)


@pytest.mark.parametrize(
    "arguments, field",
    [
        ({"dt": 0.0}, "dt"),
        ({"method": "verlet"}, "method"),
        ({"options": {"iterations": -1}}, "iterations"),
        ({"compiled_loop": "yes"}, "compiled_loop"),
    ],
)
def test_bad_arguments_name_their_field_as_simulates_do(arguments, field):
    with pytest.raises(InputError, match=field):
        Stepper(load_scene("bouncing_ball").model, **arguments)


def test_a_step_count_must_be_a_whole_number():
    stepper = Stepper(load_scene("bouncing_ball").model, "impulse", dt=0.001)
    for bad in (0, 1.5, True):
        with pytest.raises(InputError, match="steps"):
            stepper.step(bad)


def test_a_state_gone_infinite_stops_the_steps_with_the_time():
    stepper = Stepper(load_scene("bouncing_ball").model, "impulse", dt=0.001)
    stepper.state.body_velocity[0, 2] = np.inf
    with pytest.raises(SimulationDiverged, match="finite") as stopped:
        stepper.step(10)
    assert stopped.value.time == pytest.approx(0.001)
