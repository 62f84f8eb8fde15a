"""Free motion: integrators, quaternions, the gyroscopic term, energy bookkeeping."""

import numpy as np
import pytest

from contactlab import ModelBuilder, diagnostics, rotations, simulate
from contactlab.dynamics.integrators import advance_positions, free_velocities


def spinning_brick(angular_velocity):
    b = ModelBuilder(gravity=(0, 0, 0))
    b.add_body("box", half_extents=(0.3, 0.2, 0.05), mass=2.0, angular_velocity=angular_velocity)
    return b.finalize()


@pytest.mark.parametrize("integrator", ["symplectic_euler", "explicit_euler"])
def test_free_fall_is_exact_parabola_sampled(integrator):
    b = ModelBuilder()
    b.add_particles([[0, 0, 10.0]], velocity=[[1.0, 0, 2.0]])
    run = simulate(b.finalize(), "impulse", dt=0.01, duration=1.0, integrator=integrator)
    t = run.arrays["time"]
    z = run.arrays["particle_position"][:, 0, 2]
    # symplectic Euler is leapfrog: positions are the parabola sampled, shifted by g h t / 2
    exact = 10 + 2 * t - 0.5 * 9.81 * t**2
    shift = -0.5 * 9.81 * 0.01 * t if integrator == "symplectic_euler" else 0.5 * 9.81 * 0.01 * t
    np.testing.assert_allclose(z, exact + shift, atol=1e-12)
    np.testing.assert_allclose(run.arrays["particle_position"][:, 0, 0], t, atol=1e-12)


def test_spinning_asymmetric_body_keeps_angular_momentum():
    """Spin near the unstable middle axis tumbles; energy and |L| are kept, L's direction to O(h)."""
    model = spinning_brick((0.05, 6.0, 0.05))
    state = model.state()
    L0 = diagnostics.angular_momentum(model, state)
    drift = {}
    for dt in (0.004, 0.002):
        run = simulate(model, "impulse", dt=dt, duration=5.0, state=state)
        L1 = diagnostics.angular_momentum(model, run.state)
        energy = run.arrays["energy_kinetic"]
        assert np.linalg.norm(L1) == pytest.approx(np.linalg.norm(L0), rel=1e-9)
        assert np.ptp(energy) < 1e-9 * energy[0]
        drift[dt] = np.linalg.norm(L1 - L0) / np.linalg.norm(L0)
        # it really tumbled: the spin about the body's middle axis (y) reversed
        R = rotations.to_matrix(run.arrays["body_orientation"][:, 0])
        spin_y = np.einsum("tji,tj->ti", R, run.arrays["body_angular_velocity"][:, 0])[:, 1]
        assert spin_y.min() < -3.0
    assert drift[0.002] < 0.005
    assert drift[0.002] == pytest.approx(drift[0.004] / 2, rel=0.05)  # first order in h


def test_torque_free_symmetric_spin_is_steady():
    b = ModelBuilder(gravity=(0, 0, 0))
    b.add_body("sphere", radius=0.1, mass=1.0, angular_velocity=(1.0, 2.0, 3.0))
    model = b.finalize()
    v, w, p = free_velocities(model, model.state(), 0.01)
    np.testing.assert_allclose(w[0], [1, 2, 3], atol=1e-14)


def test_quaternions_stay_unit_and_rotate_at_the_right_rate():
    q = np.array([[1.0, 0, 0, 0]])
    w = np.array([[0, 0, np.pi]])  # half a turn per second about z
    x = np.zeros((1, 3))
    for _ in range(1000):
        x, q, _ = advance_positions((x, q, np.zeros((0, 3))), (np.zeros((1, 3)), w, np.zeros((0, 3))), 0.001, 0.001)
    assert np.linalg.norm(q[0]) == pytest.approx(1.0, abs=1e-14)
    R = rotations.to_matrix(q)[0]
    np.testing.assert_allclose(R @ [1, 0, 0], [-1, 0, 0], atol=1e-9)


def test_energy_terms_of_a_known_state():
    b = ModelBuilder()
    b.add_body("sphere", radius=0.5, mass=2.0, position=(0, 0, 3.0), velocity=(1, 0, 0), angular_velocity=(0, 0, 2.0))
    b.add_particles([[0, 0, 1.0]], velocity=[[0, 3.0, 0]], mass=0.5)
    model = b.finalize()
    state = model.state()
    inertia = 0.4 * 2.0 * 0.25
    assert diagnostics.kinetic_energy(model, state) == pytest.approx(0.5 * 2 * 1 + 0.5 * inertia * 4 + 0.5 * 0.5 * 9)
    assert diagnostics.potential_energy(model, state) == pytest.approx(9.81 * (2 * 3 + 0.5 * 1))


def test_elastic_bounce_conserves_energy():
    from conftest import ball_on_plane

    run = simulate(ball_on_plane(restitution=1.0, height=0.5), "impulse", dt=0.001, duration=2.0)
    total = run.arrays["energy_kinetic"] + run.arrays["energy_potential"]
    # leapfrog carries velocity half a step off the position: the sampled energy wobbles by m g |v| h / 2
    wobble = 1.0 * 9.81 * np.sqrt(2 * 9.81 * 0.5) * 0.001
    assert np.abs(total - total[0]).max() < wobble


@pytest.mark.parametrize("dt", ["scalar", "column", "per body"])
def test_compiled_orientation_step_is_the_exponential_map(rng, dt):
    """rotations.integrate (compiled) against exp(h ω / 2) ⊗ q written with the vectorized
    quaternion functions, for a scalar step, a (B, 1) column and one step per body; zero and
    tiny angular velocities take the series branch. Then against a closed form: a turn about z
    at ω for h turns by the angle ω h."""
    q = rotations.normalize(rng.normal(size=(50, 4)))
    w = rng.normal(size=(50, 3)) * 5.0
    w[:2] = 0.0
    w[2] = [1e-12, 0.0, 0.0]
    h = {"scalar": 1 / 240, "column": np.full((50, 1), 1 / 240), "per body": rng.uniform(0, 0.02, 50)}[dt]
    column = np.reshape(h, (-1, 1)) if np.ndim(h) else h
    expected = rotations.normalize(rotations.multiply(rotations.from_rotation_vector(w * column), q))
    np.testing.assert_allclose(rotations.integrate(q, w, h), expected, rtol=0, atol=1e-15)
    turned = rotations.integrate(np.array([[1.0, 0, 0, 0]]), np.array([[0, 0, 3.0]]), 0.1)[0]
    np.testing.assert_allclose(turned, [np.cos(0.15), 0, 0, np.sin(0.15)], atol=1e-15)


@pytest.mark.parametrize("path", ["loop", "stitched"])
def test_compilation_during_the_run_is_timed_apart_from_the_steps(path, monkeypatch):
    # a step (stitched) or a chunk of steps (the compiled loop) that "compiles" for 0.3 s (a Numba
    # compile event, as at a first contact): the summary counts it in compile_seconds and leaves
    # it out of steps_per_second
    import time

    from numba.core import event

    from contactlab.methods import impulse, velocity_loop

    calls = []

    def compiling_on_call(number, real):
        def call(*args):
            calls.append(1)
            if len(calls) == number:
                with event.trigger_event("numba:compile", data={}):
                    time.sleep(0.3)
            return real(*args)

        return call

    if path == "loop":
        stepper = velocity_loop.LoopStepper
        monkeypatch.setattr(stepper, "advance", compiling_on_call(2, stepper.advance))
    else:
        monkeypatch.setattr(impulse, "step", compiling_on_call(5, impulse.step))
    b = ModelBuilder()
    b.add_body("sphere", radius=0.1, mass=1.0, position=(0, 0, 1.0))
    run = simulate(b.finalize(), "impulse", dt=0.01, duration=0.1, compiled_loop=path == "loop")
    assert len(calls) == 10 if path == "stitched" else len(calls) >= 2  # ten steps, or chunks 1, then 9
    assert run.summary["compile_seconds"] >= 0.3
    assert run.summary["steps_per_second"] > 9 / 0.3  # the 0.3 s is not in the 9 steps' time
    assert run.summary["wall_seconds"] >= 0.3
