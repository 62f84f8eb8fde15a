"""Issue 22: values that look like a unit slip get one warning line before the run
(contactlab.plausibility); a run of very many steps asks for --yes on the command line."""

import os
import subprocess
import sys
import warnings

import pytest

from contactlab import ModelBuilder, simulate
from contactlab.plausibility import MANY_STEPS, PlausibilityWarning, warnings_for
from contactlab.scene import builtin_scenes, load_scene


def _caught(model, dt=0.01, duration=0.02):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        simulate(model, "impulse", dt, duration)
    return [str(w.message) for w in caught if issubclass(w.category, PlausibilityWarning)]


def test_a_ball_of_radius_4_meant_as_centimetres_is_flagged_for_starting_inside_the_floor():
    """bouncing_ball with radius = 4: its centre 1.1 m up, so it starts 4 − 1.1 = 2.9 m in the floor."""
    scene = load_scene("bouncing_ball", ["bodies.0.radius=4"])
    found = _caught(scene.model)
    centre = scene.model.initial.body_position[0, 2]
    assert found == [
        f"body 'ball' starts {4 - centre:.3g} m deep inside what it touches (its bounding radius is "
        f"4 m): lengths are in metres; move it out, or is a size or a position in other units?"
    ]


def test_one_body_far_larger_than_the_rest_is_flagged_alone():
    b = ModelBuilder()
    for x, radius in ((0.0, 0.1), (30.0, 5.0), (2.0, 0.1)):
        b.add_body("sphere", radius=radius, mass=1.0, position=(x, 0, 10))
    assert _caught(b.finalize()) == [
        "body 'body1' has a bounding radius of 5 m, 50× the bodies' median 0.1 m: lengths are in metres"
    ]


def test_very_many_steps_are_flagged_from_the_threshold_on():
    model = load_scene("bouncing_ball").model
    assert warnings_for(model, model.state(), 0.002, MANY_STEPS) == []
    assert warnings_for(model, model.state(), 0.002, MANY_STEPS + 1) == [
        f"the run makes {MANY_STEPS + 1:,} steps (duration {(MANY_STEPS + 1) * 0.002:.6g} s at dt = 0.002 s): "
        f"times are in seconds"
    ]


@pytest.mark.parametrize("name", [name for name, _ in builtin_scenes()])
def test_no_built_in_scene_looks_like_a_unit_slip(name):
    scene = load_scene(name)
    assert warnings_for(scene.model, scene.model.state(), scene.dt, round(scene.duration / scene.dt)) == []


def test_the_command_line_asks_for_yes_before_750000_steps(tmp_path):
    result = subprocess.run(
        [sys.executable, "-m", "contactlab", "run", "bouncing_ball", "--duration", "1500", "--dt", "0.002"],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp_path,
    )
    assert result.returncode == 2 and result.stderr == (
        "error: bouncing_ball: --yes: the run would make 750,000 steps (duration 1500 s at dt = 0.002 s): "
        "times are in seconds; add --yes to run it\n"
    )
    assert os.listdir(tmp_path) == []
