"""Issue 18, "results hold": a rerun of any built-in scene, with each method, gives a bit-identical
trajectory — on one thread or with the automatic thread setting, with the kernels just
compiled or loaded from the cache."""

import numpy as np
import pytest

from contactlab import InputError, SimulationDiverged, simulate
from contactlab.methods import AVAILABLE
from contactlab.scene import builtin_scenes, load_scene

STEPS = 12
FIELDS = (
    "body_position",
    "body_orientation",
    "body_velocity",
    "body_angular_velocity",
    "particle_position",
    "particle_velocity",
    "contact_count",
    "solver_iterations",
    "solver_residual",
)


def _run(scene, method, threads):
    """The trajectory of STEPS steps, or the divergence's message (a result that must repeat too)."""
    options = scene.method_options.get(method, {})
    try:
        return simulate(
            scene.model, method, scene.dt, STEPS * scene.dt, options, scene.integrator, threads=threads
        ).arrays
    except SimulationDiverged as error:
        return str(error)


@pytest.mark.parametrize("name", [name for name, _ in builtin_scenes()])
def test_a_rerun_of_a_builtin_scene_is_bit_identical(name):
    scene = load_scene(name)
    ran = 0
    for method in AVAILABLE:
        try:
            first = _run(scene, method, 1)
        except InputError:  # a method whose set-up refuses this scene (compare leaves it out)
            continue
        again = _run(scene, method, "auto")
        ran += 1
        if isinstance(first, str):
            assert again == first
            continue
        for field in FIELDS:
            np.testing.assert_array_equal(again[field], first[field], err_msg=f"{name} with {method}: {field}")
    assert ran >= 2


INTERPRETED = """
import sys
import numpy as np
sys.path.insert(0, sys.argv[2])
from test_reruns import FIELDS, _run
from contactlab.scene import load_scene
from contactlab.kernel_variants import interpreted
assert interpreted()
arrays = {}
for run in sys.argv[3:]:
    name, method = run.split("/")
    ran = _run(load_scene(name), method, 1)
    for field in FIELDS:
        arrays[f"{name}/{method}/{field}"] = np.asarray(ran if isinstance(ran, str) else ran[field])
np.savez(sys.argv[1], **arrays)
"""


def boxes_touch(name):
    """Whether two boxes of the built-in scene ``name`` can touch (it holds two or more)."""
    from contactlab.shapes import BOX

    return int((load_scene(name).model.collider_table[0] == BOX).sum()) >= 2


def rigid_runs(touching):
    """(scene, method) of every built-in scene and method that the compiled loop steps, of the
    scenes where two boxes can touch (``touching``) or of the others."""
    from contactlab.kernel_variants import variant_of
    from contactlab.methods import get, make_options

    runs = []
    for name, _ in builtin_scenes():
        scene = load_scene(name)
        for method in AVAILABLE:
            options = make_options(get(method), scene.method_options.get(method, {}), method)
            if boxes_touch(name) == touching and variant_of(scene.model, method, options, scene.integrator) is not None:
                runs.append((name, method))
    return runs


@pytest.mark.parametrize("touching", [False, True], ids=["no boxes touching", "boxes touching"])
def test_every_builtin_rigid_scene_steps_as_python_as_it_steps_compiled(tmp_path, touching):
    """The kernels run as Python (NUMBA_DISABLE_JIT=1: what a short first run does, see
    contactlab.first_run) are the compiled kernels' own source: every built-in scene that the
    compiled loop steps gives the same trajectory bit for bit either way, under every method.
    Split in two for the suite's workers: the scenes where two boxes can touch (box_pushed,
    box_stack, box_pyramid, card_house, domino_chain, mass_ratio_stack), and the others. What
    had broken it, each mended: NumPy's and Numba's BLAS builds (np.dot, the 3×3 @ products),
    NumPy's pairwise sums, Numba's quicksort ordering equal keys (two boxes at one height) unlike
    NumPy's, and float ** int (repeated products compiled, one pow as Python)."""
    import os
    import subprocess
    import sys

    runs = rigid_runs(touching)
    assert len(runs) >= (20 if touching else 30)
    saved = tmp_path / "interpreted.npz"
    env = dict(os.environ, NUMBA_DISABLE_JIT="1")
    done = subprocess.run(
        [sys.executable, "-c", INTERPRETED, str(saved), os.path.dirname(__file__), *(f"{n}/{m}" for n, m in runs)],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    interpreted = np.load(saved)
    for name, method in runs:
        compiled = _run(load_scene(name), method, 1)
        for field in FIELDS:
            expected = np.asarray(compiled if isinstance(compiled, str) else compiled[field])
            found = interpreted[f"{name}/{method}/{field}"]
            np.testing.assert_array_equal(found, expected, err_msg=f"{name} {method}: {field}")
