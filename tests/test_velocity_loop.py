"""Issue 18, deliverable 1: the compiled stepping loop of projection, impulse, constraints and penalty
(contactlab.methods.velocity_loop) against the independent path that calls the same stages one
by one from Python (the methods' ``step``): on every built-in scene the loop serves, the two give
bit-identical trajectories and diagnostics — the loop is a faster path, not other physics."""

import numba
import numpy as np
import pytest
from conftest import ball_on_plane

from contactlab import SimulationDiverged, simulate
from contactlab.methods import get, impulse, loop_stages, loop_steps, velocity_loop
from contactlab.record import SERIES
from contactlab.scene import builtin_scenes, load_scene

STEPS = 60


def _served(name, method):
    scene = load_scene(name)
    options = get(method).Options(**scene.method_options.get(method, {}))
    return scene, velocity_loop.applies(scene.model, method, options, scene.integrator)


# the driven scene under two methods, not four: what the loop adds for it, the drive's velocities in
# stage 1 (driving.drive_velocities), is one compiled function that every method's step shares, and a
# driven model compiles a loop of its own (tens of seconds of the suite)
TWO_METHODS = {"box_pushed": ("impulse", "projection")}
CASES = [
    (name, method)
    for name, _ in builtin_scenes()
    for method in TWO_METHODS.get(name, velocity_loop.METHODS)
    if _served(name, method)[1]
]


@pytest.mark.parametrize("method", velocity_loop.METHODS)
def test_the_loop_serves_rigid_and_driven_scenes_and_not_cloth_or_meshes(method):
    served = {name for name, _ in builtin_scenes() if _served(name, method)[1]}
    assert {
        "bouncing_ball",
        "box_pyramid",
        "box_stack",
        "sphere_pile",
        "newtons_cradle",
        "capsule_pile",
        "particles_box",
        "box_pushed",  # driven: a kinematic paddle on keyframes
    } <= served
    assert not served & {"cloth_drape", "cloth_table", "mesh_bowl"}


@pytest.mark.parametrize(
    "name,method,options",
    [(name, method, None) for name, method in CASES]
    + [
        # projection with more passes, half the warm start and no slop: every pass and the warm start count
        ("box_stack", "projection", {"passes": 3, "warm_start": 0.5, "slop": 0.0}),
        ("capsule_pile", "projection", {"passes": 4, "tolerance": 1e-6}),
    ],
)
def test_the_loop_gives_the_stitched_steps_numbers(name, method, options):
    scene, _ = _served(name, method)
    options = scene.method_options.get(method, {}) if options is None else options
    steps = min(STEPS, max(1, int(round(scene.duration / scene.dt))))
    looped = simulate(
        scene.model, method, scene.dt, steps * scene.dt, options, scene.integrator, record_every=7, compiled_loop=True
    )
    stitched = simulate(
        scene.model, method, scene.dt, steps * scene.dt, options, scene.integrator, record_every=7, compiled_loop=False
    )
    assert looped.summary["compiled_loop"] and not stitched.summary["compiled_loop"]
    for series in SERIES:
        assert np.array_equal(looped.arrays[series], stitched.arrays[series]), series
    for key in ("max_contacts", "max_penetration"):
        assert looped.summary[key] == stitched.summary[key], key
    assert looped.summary["solver"] == stitched.summary["solver"]
    assert looped.summary["implicit_spring_steps"] == stitched.summary["implicit_spring_steps"]
    # what the run carries on: the same method's values by the same ids, and the same manifolds
    looped_carry, stitched_carry = looped.state.carried, stitched.state.carried
    assert looped_carry.method == stitched_carry.method == method
    assert np.array_equal(looped_carry.ids, stitched_carry.ids)
    assert np.array_equal(looped_carry.values, stitched_carry.values)
    if looped_carry.manifolds is None or stitched_carry.manifolds is None:
        assert looped_carry.manifolds is stitched_carry.manifolds
    else:
        for field in vars(looped_carry.manifolds):
            left, right = getattr(looped_carry.manifolds, field), getattr(stitched_carry.manifolds, field)
            assert np.array_equal(left, right), field


@pytest.mark.parametrize("method", ["impulse", "projection"])
def test_a_run_goes_on_from_its_state_through_either_path(method):
    """Ten steps and ten more from the state reached are the twenty steps of one run, whether the
    second half steps in the loop or stitched: the carried warm start and manifolds pass over."""
    scene = load_scene("box_stack")
    whole = simulate(scene.model, method, scene.dt, 20 * scene.dt, compiled_loop=True)
    half = simulate(scene.model, method, scene.dt, 10 * scene.dt, compiled_loop=True)
    rest = simulate(scene.model, method, scene.dt, 10 * scene.dt, state=half.state, compiled_loop=False)
    assert np.array_equal(rest.arrays["body_position"][-1], whole.arrays["body_position"][-1])
    assert np.array_equal(rest.arrays["body_velocity"][-1], whole.arrays["body_velocity"][-1])
    assert rest.state.time == whole.state.time


def test_a_penalty_run_goes_on_from_its_state_through_either_path():
    """Penalty's anchors pass from the loop to the stitched step by contact id: ten steps and ten
    more are the twenty steps of one run (a box sliding to rest on the stack's floor)."""
    scene = load_scene("box_stack")
    whole = simulate(scene.model, "penalty", scene.dt, 20 * scene.dt, compiled_loop=True)
    half = simulate(scene.model, "penalty", scene.dt, 10 * scene.dt, compiled_loop=True)
    assert half.state.carried.method == "penalty" and half.state.carried.manifolds is None
    rest = simulate(scene.model, "penalty", scene.dt, 10 * scene.dt, state=half.state, compiled_loop=False)
    assert np.array_equal(rest.arrays["body_position"][-1], whole.arrays["body_position"][-1])
    assert np.array_equal(rest.state.carried.values, whole.state.carried.values)  # the anchor offsets


def test_recording_every_k_steps_samples_the_same_states():
    scene = load_scene("box_stack")
    every = simulate(scene.model, "constraints", scene.dt, 30 * scene.dt, record_every=1, compiled_loop=True).arrays
    sparse = simulate(scene.model, "constraints", scene.dt, 30 * scene.dt, record_every=4, compiled_loop=True).arrays
    steps = np.r_[0, np.arange(4, 31, 4), 30]
    assert np.array_equal(sparse["time"], every["time"][steps])
    assert np.array_equal(sparse["body_position"], every["body_position"][steps])
    assert np.array_equal(sparse["max_penetration"], every["max_penetration"][steps])


def test_a_ball_dropped_in_the_loop_bounces_to_the_closed_form_apex():
    """h₁ = r + ε² (h₀ − r) for a ball dropped from h₀ (the time-of-impact split, in the loop)."""
    model = ball_on_plane(restitution=0.8, friction=0.0, height=0.95, radius=0.05)
    run = simulate(model, "impulse", 1 / 240, 1.2, compiled_loop=True)
    assert run.summary["threads"]["setting"] == "auto"
    height = run.arrays["body_position"][:, 0, 2]
    bounced = np.argmax(np.diff(height) > 0)  # the first step that rises
    apex = height[bounced:].max()
    expected = 0.05 + 0.8**2 * (1.0 - 0.05)
    assert abs(apex - expected) < 2e-3 * expected


def test_the_loop_stops_at_the_step_that_passes_the_speed_limit(monkeypatch):
    """The loop checks the health's speed limit after every step: with the limit at a tenth of
    the scene's speed scale (√(2 g h) for a ball h = 5 m up), a falling ball stops the run at
    the first step faster than that, v = g t, with the run up to then kept."""
    from contactlab import health

    monkeypatch.setattr(health, "SPEED_FACTOR", 0.1)
    model = ball_on_plane(height=5.0, radius=0.05, friction=0.0)
    dt, g = 0.004, 9.81
    limit = 0.1 * np.sqrt(2 * g * 5.0)
    with pytest.raises(SimulationDiverged, match="reached .* m/s") as stopped:
        simulate(model, "impulse", dt, 1.0, compiled_loop=True)
    steps = int(np.floor(limit / (g * dt))) + 1  # the first with g n dt > limit
    run = stopped.value.run
    assert run.summary["compiled_loop"] and run.summary["diverged"]["check"] == "speed"
    assert stopped.value.time == pytest.approx(steps * dt)
    assert run.arrays["time"][-1] == pytest.approx(steps * dt)


def test_a_run_of_any_length_steps_through_the_compiled_loop_with_its_step_inlined():
    """Issue 36: a short run on an empty cache stepped the loop's body from Python (about 30 ms a
    720-step ball run against 3 ms compiled), because compiling the loop linked a step compiled on
    its own and cost 10–14 s more. Each of the loop's compiled forms (``velocity_loop.LOOPS``) now
    holds its method's step inlined, compiled only there: every run takes the loop however short,
    and the step is never compiled on its own."""
    scene = load_scene("bouncing_ball")
    model, options = scene.model, impulse.Options()
    stepper = velocity_loop.stepper_for(model, "impulse", options, scene.integrator, scene.dt, model.state())
    short = simulate(model, "impulse", scene.dt, 10 * scene.dt)
    assert short.summary["compiled_loop"] and short.summary["stepping"] == "compiled loop"
    assert stepper.loop is velocity_loop.LOOPS["velocity"] and stepper.loop.signatures
    assert not loop_steps.velocity_step.signatures  # inlined into the loop, not compiled on its own
    not_compiled = velocity_loop.stepper_for(
        model, "impulse", options, scene.integrator, scene.dt, model.state(), compiled_loop=False
    )
    assert not not_compiled.compiled  # the method's own step (StitchedStepper)


def test_compiled_loop_must_be_a_yes_or_no():
    from contactlab import InputError

    with pytest.raises(InputError, match="compiled_loop"):
        simulate(load_scene("bouncing_ball").model, "impulse", 0.01, 0.1, compiled_loop="yes")


def test_projection_takes_the_loop_and_compiles_only_its_own_step():
    """simulate(method="projection") takes the loop as the velocity methods do; the loop is told
    the method by its Specialization, whose ``projection`` is None for the steps that do not take
    it (Numba then leaves projection uncompiled there), and calls the projection's step. Impulse and
    constraints differ by value (False, True), not type: their runs share one compiled loop."""
    scene = load_scene("box_stack")
    model, options = scene.model, get("projection").Options(passes=3)
    stepper = velocity_loop.stepper_for(model, "projection", options, scene.integrator, scene.dt, model.state())
    assert isinstance(stepper, velocity_loop.LoopStepper) and stepper.settings.passes == 3
    methods = ("constraints", "impulse", "projection")
    assert [getattr(stepper.spec, name) for name in methods] == [False, False, True]
    assert stepper.loop is velocity_loop.LOOPS["projection"]
    spec = loop_stages.specialization(model, "impulse", impulse.Options())
    assert [getattr(spec, name) for name in methods] == [False, True, None]
    spec = loop_stages.specialization(model, "constraints", get("constraints").Options())
    assert [getattr(spec, name) for name in methods] == [True, False, None]
    assert numba.typeof(spec) == numba.typeof(loop_stages.specialization(model, "impulse", impulse.Options()))
    assert simulate(model, "projection", scene.dt, 10 * scene.dt).summary["compiled_loop"]
