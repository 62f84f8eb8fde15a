"""Shock propagation (issue 38, item 2; contactlab.methods.shock): the levels of the contact
graph, the pass's closed form on a column, and the mass-ratio stacks it holds where the sweeps
alone crush them."""

import numpy as np
import pytest
from test_health import _mass_ratio_stack
from test_sweeps import problem

from contactlab import InputError, ModelBuilder, simulate
from contactlab.methods import constraints, sequential, shock
from contactlab.methods.loop_stages import loop_settings
from contactlab.methods.velocity_level import resting_targets

DT = 1 / 240
RADIUS = 0.05


def column_and_pair(masses):
    """Spheres of ``masses`` (bottom first) stacked on a floor, touching; beside them, in the
    air, two spheres touching each other only."""
    b = ModelBuilder()
    b.add_material("m", friction=0.5, restitution=0.0)
    for i, mass in enumerate(masses):
        b.add_body("sphere", radius=RADIUS, mass=mass, position=(0, 0, RADIUS + 2 * RADIUS * i), material="m")
    for x in (1.0, 1.0 + 2 * RADIUS):
        b.add_body("sphere", radius=RADIUS, mass=1.0, position=(x, 0, 1.0), material="m")
    b.add_obstacle("plane", normal=(0, 0, 1), material="m")
    return b.finalize()


def unconverged_solve(model, sweeps):
    """The model's contacts at its start, solved cold for ``sweeps`` sweeps: (contacts, rows,
    order, targets, impulses, u)."""
    _, contacts, rows, order, u, _ = problem(model)
    target = resting_targets(-contacts.depth, loop_settings(model, "constraints", constraints.Options(), DT))
    impulses, _, change = sequential.solve_sequential_impulses(
        rows, contacts.friction, target, u, (sweeps, 1e-7), np.zeros((contacts.count, 3)), (order, None)
    )
    return contacts, rows, order, target, impulses, u, change


def test_levels_count_contacts_from_what_cannot_move():
    """The floor's sphere is level 1, each above it one more; two spheres touching only each
    other reach nothing fixed."""
    model = column_and_pair([1.0, 1.0, 1.0])
    contacts, rows, *_ = unconverged_solve(model, 1)
    level, entities, count = shock.entity_levels(rows)
    np.testing.assert_array_equal(level, [1, 2, 3, shock.UNREACHED, shock.UNREACHED])
    assert count.sum() == 2 * contacts.count - 1  # every side movable but the floor's


def test_after_the_pass_a_column_stands_still_whatever_its_masses():
    """A column whose masses grow 10× a level, its sweeps cut at 2 (far from converged: the
    bodies still sink), then the pass with enough sweeps a level: every body's velocity is the
    closed form of a column resting on the floor, zero (the touching gaps' targets are 0), and
    the pass's impulses are not written back."""
    model = column_and_pair([1.0, 10.0, 100.0, 1000.0])
    contacts, rows, order, target, impulses, u, change = unconverged_solve(model, 2)
    assert change > 1e-3 and u[2:24:6].min() < -1e-3  # unconverged: the column still sinks
    before = impulses.copy()
    made = shock.propagate_shock(rows, contacts.friction, target, impulses, u, order, (20, 1e-12))
    np.testing.assert_allclose(u[:24], 0.0, atol=1e-10)  # the column: linear and angular
    assert u[26] < -0.03  # the pair in the air keeps falling (g h = 0.041 m/s)
    np.testing.assert_array_equal(impulses, before)
    assert 1 <= made <= 20


@pytest.mark.parametrize("ratio", [1e4, 3e4, 1e5])
def test_shock_propagation_holds_a_heavy_box_on_a_light_one(ratio):
    """A box 10⁴–10⁵ times heavier on a 1 kg box, dt = 1/240 s for 5 s: without the pass the light
    box is crushed out sideways (test_health: energy or speed check; constraints and impulse give
    the same run here, ε = 0); with it both stand, within 0.5 mm of their resting heights and
    sideways."""
    run = simulate(_mass_ratio_stack(ratio), "constraints", DT, 5.0, {"substeps": 1, "shock_sweeps": 4})
    position = run.state.body_position
    np.testing.assert_allclose(position[:, 2], [0.05, 0.15], atol=5e-4)
    assert np.abs(position[:, :2]).max() < 5e-4


def test_a_converged_step_is_untouched_by_the_pass():
    """A light stack converges every step: the pass never runs, the run is the same bit for bit."""
    model = _mass_ratio_stack(10.0)
    plain = simulate(model, "constraints", DT, 0.5, {"substeps": 1})
    shocked = simulate(model, "constraints", DT, 0.5, {"substeps": 1, "shock_sweeps": 4})
    np.testing.assert_array_equal(plain.state.body_position, shocked.state.body_position)


@pytest.mark.parametrize(
    "options, words",
    [
        ({"shock_sweeps": 4}, "set substeps = 1"),
        ({"shock_sweeps": -1, "substeps": 1}, "shock_sweeps"),
    ],
)
def test_shock_sweeps_needs_no_substeps_and_a_count(options, words):
    with pytest.raises(InputError, match=words):
        simulate(_mass_ratio_stack(10.0), "constraints", DT, 0.1, options)
