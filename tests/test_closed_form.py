"""The closed-form answers of the built-in scenes: the formulas against the scenes' stated
numbers, the measurements against runs of the exact methods, and the guards that keep a changed
scene from being checked against a formula that no longer applies."""

import numpy as np
import pytest

from contactlab import closed_form
from contactlab.closed_form import Check
from contactlab.scene import builtin_scenes, load_scene
from contactlab.simulation import simulate


def _run(name, method="impulse", overrides=(), duration=None):
    scene = load_scene(name, list(overrides) + [f"simulation.method={method}"])
    run = simulate(
        scene.model,
        method,
        scene.dt,
        duration or scene.duration,
        scene.method_options.get(method, {}),
        scene.integrator,
        scene_name=name,
    )
    return scene, closed_form.checks(name, scene.model, run.arrays)


def _by_quantity(found):
    return {check.quantity: check for check in found}


def test_check_error_and_relative_error():
    check = Check("x", "m", 2.0, 2.5)
    assert check.error == 0.5 and check.relative_error == 0.25
    assert Check("y", "m", 0.0, 0.1).relative_error is None


def test_expected_values_are_the_scenes_stated_numbers():
    # the numbers written in the scenes' descriptions, computed independently of closed_form
    bounce = _by_quantity(_run("bouncing_ball", duration=1.6)[1])
    assert bounce["rebound 1 apex"].expected == pytest.approx(0.64, rel=1e-12)
    assert bounce["rebound 2 apex"].expected == pytest.approx(0.8**4, rel=1e-12)
    slide = _by_quantity(_run("sliding_block", duration=0.1)[1])
    assert slide["stopping distance"].expected == pytest.approx(9.0 / (2 * 0.3 * 9.81), rel=1e-3)
    assert slide["stopping time"].expected == pytest.approx(3.0 / (0.3 * 9.81), rel=1e-3)
    roll = _by_quantity(_run("rolling_sphere", duration=0.1)[1])
    assert roll["rolling speed"].expected == pytest.approx(15.0 / 7.0, rel=1e-12)
    rod = _by_quantity(_run("rod_impact", duration=0.4)[1])
    assert rod["vertical velocity after the impact"].expected == pytest.approx(-1.599, abs=5e-4)
    assert rod["angular velocity about y after the impact"].expected == pytest.approx(-7.621, abs=5e-4)
    assert _by_quantity(_run("incline", duration=0.1)[1])["distance down the slope"].expected == 0.0


@pytest.mark.parametrize(
    "name, duration, tolerance",
    [
        ("bouncing_ball", 1.6, 1e-4),  # impulses hit the apex to the step's accuracy
        ("rod_impact", 0.4, 1e-4),  # R4 exactly: one impulse at the corner
        ("rolling_sphere", 1.0, 0.02),  # the end of sliding is read at sample times (dt 0.002 s)
        ("sliding_block", 1.5, 0.01),
        ("newtons_cradle", 0.5, 1e-9),  # sequential impulses pass the velocity down the row
    ],
)
def test_impulses_meet_the_closed_form(name, duration, tolerance):
    found = _run(name, duration=duration)[1]
    assert found
    for check in found:
        if check.relative_error is None:
            assert abs(check.error) < 1e-6, check
        else:
            assert check.relative_error < tolerance, check


def test_a_changed_scene_is_checked_against_its_own_answer():
    scene, found = _run("sliding_block", overrides=["bodies.0.velocity=[2,0,0]"], duration=0.1)
    mu = np.sqrt(
        np.prod(scene.model.material_friction[[scene.model.body_material[0], scene.model.obstacle_material[0]]])
    )
    assert _by_quantity(found)["stopping distance"].expected == pytest.approx(4.0 / (2 * mu * 9.81), rel=1e-12)
    # a steeper slope than the friction angle slides at g (sin θ − μ cos θ)
    theta = np.radians(40.0)
    _, found = _run("incline", overrides=[f"obstacles.0.normal=[{-np.sin(theta)},0,{np.cos(theta)}]"], duration=0.3)
    a = 9.81 * (np.sin(theta) - 0.5 * np.cos(theta))
    assert found[0].expected == pytest.approx(0.5 * a * 0.3**2, rel=1e-6)


def test_no_check_when_the_formula_no_longer_applies():
    assert _run("bouncing_ball", overrides=["bodies.0.velocity=[0,0,1]"], duration=0.05)[1] == []
    assert _run("rod_impact", overrides=["materials.0.friction=0.5"], duration=0.05)[1] == []
    assert closed_form.checks("cloth_drape", None, {}) == []


# ---- verdicts: each scene's stated expectation as a check with a tolerance ---------------------


def test_a_check_passes_within_its_tolerance_and_fails_outside_or_unreached():
    assert Check("x", "m", 1.0, 1.015, 0.02).passed is True
    assert Check("x", "m", 1.0, 1.03, 0.02).passed is False
    assert Check("x", "m", 1.0, float("nan"), 0.02).passed is False  # never reached
    assert Check("x", "m", 1.0, 1.0).passed is None  # no tolerance, no verdict
    assert Check("x", "m", 1.0, 1.03, 0.02).verdict() == "x: 1.03 m (expected 1 ± 0.02): FAIL"
    assert Check("x", "m", 1.0, 1.03, 0.02).as_record() == {
        "quantity": "x",
        "unit": "m",
        "expected": 1.0,
        "measured": 1.03,
        "tolerance": 0.02,
        "passed": False,
    }


def test_every_built_in_check_carries_the_tolerance_the_module_sets():
    # bouncing ball: 2 % of the apex plus 1 mm; sliding block's time: 2 % plus one sample interval
    bounce = _by_quantity(_run("bouncing_ball", duration=1.6)[1])
    assert bounce["rebound 1 apex"].tolerance == pytest.approx(0.02 * 0.64 + 1e-3, rel=1e-12)
    scene, found = _run("sliding_block", duration=0.1)
    assert _by_quantity(found)["stopping time"].tolerance == pytest.approx(
        0.02 * 3.0 / (0.3 * 9.81) + scene.dt, rel=1e-9
    )
    stack = _by_quantity(_run("box_stack", duration=0.05)[1])
    assert stack["largest body displacement"].tolerance == 0.01 and stack["deepest overlap"].tolerance == 0.005


@pytest.mark.parametrize(
    "name, duration",
    [
        ("bouncing_ball", 1.6),
        ("rod_impact", 0.4),
        ("sliding_block", 1.5),
        ("newtons_cradle", 0.5),
        ("box_stack", 1.0),
        ("card_house", 0.5),
        ("incline", 0.5),
        ("particles_box", 1.0),
        ("domino_chain", 3.0),
        ("cloth_fold", 1.5),
    ],
)
def test_impulses_meet_every_stated_expectation(name, duration):
    found = _run(name, duration=duration)[1]
    assert found and all(check.passed for check in found), [check.verdict() for check in found]


@pytest.mark.parametrize("method", ["penalty", "projection", "impulse", "constraints"])
def test_every_method_pushes_the_box_at_the_paddles_speed_against_sliding_friction(method):
    found = _run("box_pushed", method=method)[1]
    assert len(found) == 2 and all(check.passed for check in found), [check.verdict() for check in found]


def test_a_method_that_misses_an_expectation_fails_it_with_the_number():
    # projection is inelastic: the ball never rebounds, so the apexes are never reached
    bounce = _by_quantity(_run("bouncing_ball", method="projection", duration=1.0)[1])
    assert bounce["rebound 1 apex"].passed is False and "not reached" in bounce["rebound 1 apex"].verdict()
    # a stack launched sideways at 1 m/s does not stand: it slides far beyond 1 cm
    stack = _by_quantity(_run("box_stack", overrides=["bodies.0.velocity=[1,0,0]"], duration=0.3)[1])
    displacement = stack["largest body displacement"]
    assert displacement.measured > 0.1 and displacement.passed is False


def test_a_strip_that_passes_through_itself_or_still_stands_misses_cloth_folds_expectation():
    # issue 59: cloth_fold stated none. Its bounds follow from its thickness t = 4 mm and its 24
    # rows: at least two layers, 3t; at most every row a layer resting on the one below, t + 23·2t
    _, found = _run("cloth_fold", duration=0.2)  # the strip still stands: no heap yet
    height = _by_quantity(found)["heap height"]
    assert height.expected - height.tolerance == pytest.approx(0.012) and height.measured > 0.25
    assert height.expected + height.tolerance == pytest.approx(0.188) and height.passed is False
    _, found = _run("cloth_fold", overrides=["cloth.0.self_collision=false"])  # it falls through itself
    crossed = _by_quantity(found)["edges through the cloth"]
    assert crossed.measured > 0 and crossed.passed is False, crossed.verdict()


@pytest.mark.parametrize(
    "name",
    [
        pytest.param(
            name,
            marks=pytest.mark.xfail(
                strict=True,
                reason="cloth_table states it slides off the table and falls to the floor, but in its 3 s "
                "it slides about 5 cm and hangs over the edge (measured under every method): its "
                "expectation waits for a scene that does what it says",
            ),
        )
        if name == "cloth_table"
        else name
        for name, _ in builtin_scenes()
    ],
)
def test_every_built_in_scene_states_an_expectation(name):
    # issue 59: cloth_fold stated none. Two steps under the scene's own method: the checks apply
    # to the scene as it is built (a check whose layout no longer fits gives none)
    scene = load_scene(name)
    assert _run(name, method=scene.method, duration=2 * scene.dt)[1], name


def test_nothing_inside_an_obstacle_is_measured_from_the_centres():
    # a particle put 2 cm behind the floor of particles_box: its centre is 2 cm inside the floor's half-space
    from contactlab.closed_form import _centres_inside_obstacles

    scene = load_scene("particles_box")
    positions = np.array([[[0.0, 0.0, 0.3], [0.1, 0.0, -0.02]]])
    assert _centres_inside_obstacles(scene.model, positions) == pytest.approx(0.02, abs=1e-12)
    assert _centres_inside_obstacles(scene.model, positions[:, :1]) == 0.0
