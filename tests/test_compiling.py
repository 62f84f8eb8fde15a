"""Compile what a scene uses, once: the narrow phase specialised on a scene's pair families
gives the contacts of the full dispatch, and a compilation says so on stderr."""

import io
import os
import subprocess
import sys

import numba
import numpy as np
import pytest

from contactlab import ModelBuilder, collide, simulate
from contactlab.collision import colliders, state_poses
from contactlab.collision.broad_phase import brute_force_pairs
from contactlab.collision.families import pair_families
from contactlab.collision.narrow_phase import (
    ALL_FAMILIES,
    FAMILIES,
    collide_pair,
    family,
    generate_contacts,
    needs_hulls,
)
from contactlab.compiling import NOTICE, FirstCompile, compile_notice, notices_to, one_notice

OCTAHEDRON = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]]) * 0.06
TETRAHEDRON = np.array([[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0], [0, 0, 0.1]]) - 0.025


def present(families):
    return {name for name, flag in zip(FAMILIES, families) if flag is not None}


def test_a_ball_on_the_floor_compiles_the_round_pairs_alone_as_a_pile_of_balls_does():
    """Families follow the kinds present, not how many of each: one ball on the floor compiles
    sphere–plane and sphere–sphere (never met, a branch not taken) and so the loop of a pile of
    balls on the floor; one box on the floor, that of a stack of boxes."""

    def families(shape, count, **size):
        b = ModelBuilder()
        for i in range(count):
            b.add_body(shape, mass=1, position=(0, 0, 1 + i), **size)
        b.add_obstacle("plane", normal=(0, 0, 1))
        return pair_families(b.finalize())

    assert present(families("sphere", 1, radius=0.1)) == {"sphere_sphere", "sphere_plane"}
    assert families("sphere", 1, radius=0.1) == families("sphere", 5, radius=0.1)
    assert not needs_hulls(families("sphere", 1, radius=0.1))
    assert present(families("box", 1, half_extents=(0.1,) * 3)) == {"box_box", "box_plane"}
    assert families("box", 1, half_extents=(0.1,) * 3) == families("box", 3, half_extents=(0.1,) * 3)


def test_scene_families_pair_dynamic_shapes_with_each_other_and_with_the_obstacles():
    b = ModelBuilder()
    b.add_body("sphere", radius=0.1, mass=1, position=(0, 0, 1))
    b.add_body("box", half_extents=(0.1, 0.1, 0.1), mass=1, position=(1, 0, 1))
    b.add_body("box", half_extents=(0.1, 0.1, 0.1), mass=1, position=(2, 0, 1))
    b.add_particles([[3, 0, 1]], radius=0.01)
    b.add_obstacle("plane", normal=(0, 0, 1))
    b.add_obstacle("convex", points=OCTAHEDRON, position=(5, 0, 0))
    model = b.finalize()
    # sphere and particle are both round: sphere_sphere; one sphere-like kind meets the boxes and so on
    assert present(pair_families(model)) == {
        "sphere_sphere",
        "sphere_box",
        "box_box",
        "sphere_plane",
        "box_plane",
        "sphere_convex",
        "convex_convex",
    }
    assert needs_hulls(pair_families(model))
    assert family(1, 5) == family(5, 1) == "convex_convex" and family(2, 2) is None and family(0, 6) is None


def mixed_model():
    """Every dynamic shape twice, particles, and every static shape: every pair family."""
    b = ModelBuilder()
    for i in range(2):
        z = 0.15 + 0.12 * i
        b.add_body("sphere", radius=0.05, mass=1, position=(0.01 * i, 0, z))
        b.add_body(
            "box",
            half_extents=(0.05, 0.04, 0.03),
            mass=1,
            position=(0.07, 0.01 * i, z),
            orientation=(0.9, 0.1, 0.3, 0.2),
        )
        b.add_body(
            "capsule",
            radius=0.03,
            half_length=0.05,
            mass=1,
            position=(0.04, 0.06, 0.18 + 0.05 * i),
            orientation=(0.8, 0.5, 0.2, 0.1),
        )
        b.add_body(
            "convex", points=OCTAHEDRON, mass=1, position=(0.0, 0.07, z + 0.02), orientation=(0.7, 0.2, 0.6, 0.3)
        )
        b.add_body("convex", points=TETRAHEDRON, mass=1, position=(0.06, 0.08, z + 0.05))
    b.add_particles([[0.03, 0.05, 0.2], [0.08, 0.06, 0.25], [0.05, 0.0, 0.12]], radius=0.02)
    b.add_obstacle("plane", normal=(0, 0, 1), offset=0.12)
    b.add_obstacle("box", half_extents=(0.05, 0.05, 0.05), position=(0.1, 0.0, 0.1))
    b.add_obstacle("sphere", radius=0.05, position=(-0.02, 0.06, 0.1))
    b.add_obstacle("convex", points=OCTAHEDRON, position=(0.0, -0.03, 0.1))
    return b.finalize()


def test_the_specialised_narrow_phase_gives_the_contacts_of_the_full_dispatch():
    model = mixed_model()
    assert present(pair_families(model)) == set(FAMILIES)
    kinds, params = colliders(model).kinds, colliders(model).params
    centers, rots = state_poses(model, model.state())
    pairs = brute_force_pairs(np.full((len(kinds), 3), -1.0), np.full((len(kinds), 3), 1.0))  # every pair
    dynamic = model.body_count + model.particle_count
    pairs = pairs[(pairs[:, 0] < dynamic) & np.array([family(kinds[a], kinds[b]) is not None for a, b in pairs])]
    reach = np.full(len(pairs), 0.02)
    everything = generate_contacts(pairs, kinds, params, centers, rots, reach, model.hull_store, ALL_FAMILIES)
    found = {name: 0 for name in FAMILIES}
    for (a, b), count in zip(pairs, np.bincount(everything[4], minlength=len(pairs))):
        found[family(kinds[a], kinds[b])] += count
    assert all(found.values()), found  # every family touches somewhere in this scene
    # each family alone, over its own pairs, and the scene's own families over all of them
    for name in FAMILIES:
        mine = np.array([family(kinds[a], kinds[b]) == name for a, b in pairs])
        alone = tuple(True if other == name else None for other in FAMILIES)
        hulls = model.hull_store if needs_hulls(alone) else None
        got = generate_contacts(pairs[mine], kinds, params, centers, rots, reach[mine], hulls, alone)
        rows = np.isin(everything[4], np.nonzero(mine)[0])
        for column, expected in zip(got[:4], everything[:4]):
            np.testing.assert_array_equal(column, expected[rows])
    scene = generate_contacts(pairs, kinds, params, centers, rots, reach, model.hull_store, pair_families(model))
    for column, expected in zip(scene, everything):
        np.testing.assert_array_equal(column, expected)
    # and pair by pair, as collide_pair computes them (either order)
    out = (np.zeros((8, 3)), np.zeros((8, 3)), np.zeros(8), np.zeros(8, dtype=np.int64))
    for k, (a, b) in enumerate(pairs):
        count = collide_pair(
            (kinds[a], params[a], (centers[a], rots[a])),
            (kinds[b], params[b], (centers[b], rots[b])),
            reach[k],
            model.hull_store,
            out,
            0,
        )
        rows = everything[4] == k
        assert count == rows.sum()
        np.testing.assert_array_equal(out[1][:count], everything[1][rows])


def test_a_family_left_out_is_not_compiled_in():
    """The dispatch of a ball on the floor calls the round pairs' routines, sphere_plane and
    sphere_sphere (the kinds present, see above), and no other pair routine."""
    fresh = numba.njit(generate_contacts.py_func)  # not cached: its code is built here
    b = ModelBuilder()
    b.add_body("sphere", radius=0.1, mass=1, position=(0, 0, 0.05))
    b.add_obstacle("plane", normal=(0, 0, 1))
    model = b.finalize()
    kinds, params = colliders(model).kinds, colliders(model).params
    centers, rots = state_poses(model, model.state())
    pairs = np.array([[0, 1]], dtype=np.int64)
    point, *_ = fresh(pairs, kinds, params, centers, rots, np.zeros(1), None, pair_families(model))
    assert len(point) == 1
    code = "".join(fresh.inspect_llvm().values())
    assert "sphere_plane" in code and "sphere_sphere" in code
    for other in ("box_box", "capsule_box", "sphere_box", "convex_convex", "box_plane"):
        assert other not in code


def test_collide_gives_the_same_contacts_whatever_the_shapes_around():
    """A sphere–box pair's contacts in a scene of spheres and boxes equal those in a scene
    that also holds capsules and hulls far away (another families specialization)."""

    def scene(extra):
        b = ModelBuilder()
        b.add_body("sphere", radius=0.1, mass=1, position=(0, 0, 0.19))
        b.add_body(
            "box", half_extents=(0.1, 0.1, 0.1), mass=1, position=(0.05, 0.02, 0.0), orientation=(0.95, 0.1, 0.2, 0.1)
        )
        if extra:
            b.add_body("capsule", radius=0.05, half_length=0.1, mass=1, position=(10, 0, 10))
            b.add_body("convex", points=OCTAHEDRON, mass=1, position=(20, 0, 10))
        b.add_obstacle("plane", normal=(0, 0, 1), offset=-0.09)
        return b.finalize()

    plain, extended = scene(False), scene(True)
    assert pair_families(plain) != pair_families(extended)
    a, b = collide(plain, plain.state(), margin=0.01), collide(extended, extended.state(), margin=0.01)
    assert a.count == b.count > 0
    for name in ("point", "normal", "depth", "body_a", "body_b"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


def test_a_compilation_prints_the_notice_once():
    stream = io.StringIO()
    with compile_notice(FirstCompile(stream=stream)) as listener:
        assert not listener.said

        @numba.njit  # a function no cache holds: it compiles here
        def fresh(x):
            return x + 1.0

        @numba.njit
        def another(x):
            return fresh(x) * 2.0

        assert another(1.0) == 4.0
    assert listener.said
    with compile_notice(listener):  # a run's later block: no second line

        @numba.njit
        def third(x):
            return x - 1.0

        assert third(1.0) == 0.0
    assert stream.getvalue() == NOTICE + "\n"
    assert "first use" in NOTICE


def test_a_command_says_it_once_however_many_runs_compile_and_a_worker_hands_it_on(capsys):
    # issue 59: a comparison or sweep in one process printed it at each run that compiled
    def compile_one():
        with compile_notice() as listener:
            numba.njit(lambda x: x + 1.0)(1.0)  # a function of its own: it compiles
        return listener.said

    assert compile_one() and compile_one()  # two runs outside a command: a line each
    assert capsys.readouterr().err == 2 * (NOTICE + "\n")
    with one_notice():
        assert compile_one() and compile_one()
    assert capsys.readouterr().err == NOTICE + "\n"
    sent = []
    with notices_to(sent.append):  # a job on a Dask worker: to the command, nothing printed
        assert compile_one()
    assert sent == [NOTICE] and capsys.readouterr().err == ""


def test_nothing_is_printed_when_nothing_compiles(capsys):
    @numba.njit
    def ready(x):
        return x * 3.0

    ready(1.0)  # compiled before the block
    with compile_notice() as listener:
        assert ready(2.0) == 6.0
    assert not listener.said
    assert capsys.readouterr().err == ""


def test_a_run_says_so_on_stderr_only_when_it_compiles(capsys):
    b = ModelBuilder()
    b.add_body("sphere", radius=0.1, mass=1, position=(0, 0, 0.2))
    b.add_obstacle("plane", normal=(0, 0, 1))
    model = b.finalize()
    simulate(model, "impulse", dt=0.01, duration=0.3)  # compiles or loads what it needs
    capsys.readouterr()
    run = simulate(model, "impulse", dt=0.01, duration=0.3)
    captured = capsys.readouterr()
    assert NOTICE not in captured.err and captured.out == ""
    assert run.summary["compile_seconds"] >= 0.0 and run.summary["steps_per_second"] > 0.0


@pytest.mark.parametrize("path", ["loop", "stitched"])
def test_compiling_before_the_first_step_is_said_and_counted_once(path, monkeypatch, capsys):
    """The first sample's collide() compiles the collision kernels before the first step: the
    notice comes then, not again when a later step compiles, and compile_seconds counts both —
    stepping in the compiled loop (a later chunk of steps compiles) or stitched (a later step)."""
    import time

    from numba.core import event

    from contactlab.methods import impulse, velocity_loop

    calls = []

    def compiling_first(real):
        """The first sample (the Stepper's: the loop's own, or the stitched one's) compiles."""

        def sample(self, *args):
            if not calls:
                with event.trigger_event("numba:compile", data={}):
                    time.sleep(0.2)
            return real(self, *args)

        return sample

    def compiling_on_a_later_call(real, number):
        def call(*args):
            calls.append(1)
            if len(calls) == number:
                with event.trigger_event("numba:compile", data={}):
                    time.sleep(0.2)
            return real(*args)

        return call

    if path == "loop":
        monkeypatch.setattr(velocity_loop.LoopStepper, "sample", compiling_first(velocity_loop.LoopStepper.sample))
        monkeypatch.setattr(
            velocity_loop.LoopStepper, "advance", compiling_on_a_later_call(velocity_loop.LoopStepper.advance, 2)
        )
    else:
        monkeypatch.setattr(
            velocity_loop.StitchedStepper, "sample", compiling_first(velocity_loop.StitchedStepper.sample)
        )
        monkeypatch.setattr(impulse, "step", compiling_on_a_later_call(impulse.step, 3))
    b = ModelBuilder()
    b.add_body("sphere", radius=0.1, mass=1.0, position=(0, 0, 1.0))
    run = simulate(b.finalize(), "impulse", dt=0.01, duration=0.1, compiled_loop=path == "loop")
    assert len(calls) >= (2 if path == "loop" else 3)  # the loop: chunks of 1 step, then the other 9
    assert capsys.readouterr().err.count(NOTICE) == 1
    assert run.summary["compile_seconds"] >= 0.4


def test_compiling_in_the_plausibility_check_is_said_and_counted(monkeypatch, capsys):
    """The plausibility check's collide() on the initial state is the first to need the collision
    kernels: on an empty cache it compiles them before the first sample. The notice comes then,
    and compile_seconds and wall_seconds both count it."""
    import time

    from numba.core import event

    from contactlab import plausibility

    real = plausibility.warnings_for

    def compiling_check(*args):
        with event.trigger_event("numba:compile", data={}):
            time.sleep(0.3)
        return real(*args)

    b = ModelBuilder()
    b.add_body("sphere", radius=0.1, mass=1.0, position=(0, 0, 1.0))
    model = b.finalize()
    simulate(model, "impulse", dt=0.01, duration=0.05)  # compiles or loads the run's kernels
    capsys.readouterr()
    monkeypatch.setattr(plausibility, "warnings_for", compiling_check)
    run = simulate(model, "impulse", dt=0.01, duration=0.05)
    assert capsys.readouterr().err.count(NOTICE) == 1
    assert run.summary["compile_seconds"] >= 0.3
    assert run.summary["wall_seconds"] >= run.summary["compile_seconds"]


# A caller in one file, its callee in another: the shape of the stepping loop and its stages.
CALLEE = "{njit}\n\n\n@njit(cache=True)\ndef value():\n    return {answer}\n"
CALLER = "{njit}\nfrom .callee import value\n\n\n@njit(cache=True)\ndef total():\n    return value() + 0\n"
STAMPED = "from contactlab.compiling import njit"
PLAIN = "from numba import njit"
STAMP_INIT = "from contactlab.compiling import PackageStampedLocator as L\n\nL.stamp_package(__path__[0])\n"


@pytest.mark.parametrize("where", ["beside the sources", "NUMBA_CACHE_DIR"])
def test_an_edited_callee_in_another_file_makes_the_callers_cache_stale(tmp_path, where):
    """The CI failure of stop 35, in small: a cached caller whose callee, in another file, changed
    (a newer contactlab pip-installed over an older one, or another commit checked out). Numba
    stamps an entry with its own file alone and loads the caller's old machine code, old callee
    and all (the package "plain", Numba's documented limit); a package stamped as contactlab's
    kernels are (PackageStampedLocator) compiles the caller afresh."""
    for package, njit_line in (("stamped", STAMPED), ("plain", PLAIN)):
        folder = tmp_path / "packages" / package
        folder.mkdir(parents=True)
        (folder / "__init__.py").write_text(STAMP_INIT if package == "stamped" else "")
        (folder / "callee.py").write_text(CALLEE.format(njit=njit_line, answer=1))
        (folder / "caller.py").write_text(CALLER.format(njit=njit_line))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path / "packages"), *sys.path])}
    env.pop("NUMBA_CACHE_DIR", None)
    if where == "NUMBA_CACHE_DIR":
        env["NUMBA_CACHE_DIR"] = str(tmp_path / "numba-cache")
    script = "import stamped.caller, plain.caller; print(stamped.caller.total(), plain.caller.total())"

    def totals():
        done = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=120)
        assert done.returncode == 0, done.stderr
        return done.stdout.split()

    assert totals() == ["1", "1"]
    for package, njit_line in (("stamped", STAMPED), ("plain", PLAIN)):
        (tmp_path / "packages" / package / "callee.py").write_text(CALLEE.format(njit=njit_line, answer=2))
    assert totals() == ["2", "1"]  # the stamped caller sees its callee's edit; Numba alone keeps 1
    assert totals() == ["2", "1"]  # and the fresh entry is the one the next process loads


# One kernel, compiled for a type of its own by each of several processes at once, each saving
# its entry slowly (the window of the race widened to a second), then loaded by a fresh process.
TYPED_KERNEL = "{njit}\n\n\n@njit(cache=True)\ndef twice_plus_one(x):\n    return x * 2 + 1\n"
SAVE_SLOWLY = """
import sys, time
from numba.core import caching
index_saved = caching.IndexDataCacheFile._save_index
def slowly(self, overloads):
    time.sleep(1.0)
    index_saved(self, overloads)
caching.IndexDataCacheFile._save_index = slowly
import numpy as np
import contactlab.compiling
from kernels.typed import twice_plus_one
print(repr(twice_plus_one(getattr(np, sys.argv[1])(3))))
"""
LOAD_ALL = """
import numpy as np
import contactlab.compiling
from kernels.typed import twice_plus_one
values = [repr(twice_plus_one(getattr(np, name)(3))) for name in {types}]
assert not twice_plus_one.stats.cache_misses, twice_plus_one.stats.cache_misses
print(" ".join(values))
"""


def test_processes_saving_one_kernel_for_different_types_at_once_keep_its_cache_whole(tmp_path):
    """Numba picks a new signature's data file by reading the index, and writes the index, then
    the data, unlocked: processes saving one function at once took one file name for several
    signatures, and a later process loaded another signature's machine code (the suite crashed
    so). ``contactlab.compiling`` saves under a lock of the index: each signature's entry is
    its own, and a fresh process loads every one of them with no compiling."""
    folder = tmp_path / "packages" / "kernels"
    folder.mkdir(parents=True)
    (folder / "__init__.py").write_text(STAMP_INIT)
    (folder / "typed.py").write_text(TYPED_KERNEL.format(njit=STAMPED))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path / "packages"), *sys.path])}
    env["NUMBA_CACHE_DIR"] = str(tmp_path / "numba-cache")
    types = ["int8", "int16", "int32", "float32", "float64", "complex128"]
    saving = [
        subprocess.Popen([sys.executable, "-c", SAVE_SLOWLY, name], env=env, stdout=subprocess.PIPE, text=True)
        for name in types
    ]
    outputs = [process.communicate(timeout=180)[0].strip() for process in saving]
    assert all(process.returncode == 0 for process in saving)
    assert [complex(value.strip("()")) for value in outputs] == [7] * len(types)
    loaded = subprocess.run(
        [sys.executable, "-c", LOAD_ALL.format(types=types)], env=env, capture_output=True, text=True, timeout=180
    )
    assert loaded.returncode == 0, loaded.stderr
    assert loaded.stdout.split() == outputs  # each type's own machine code: its own value and type


def test_every_kernel_is_stamped_with_the_whole_package():
    """Every module of contactlab takes njit from contactlab.compiling, and its kernels' cache
    entries carry the digest of all the package's sources."""
    from contactlab import compiling
    from contactlab.methods import velocity_loop

    package = os.path.dirname(compiling.__file__)
    for folder, _, files in os.walk(package):
        for name in files:
            if name.endswith(".py") and name != "compiling.py":
                with open(os.path.join(folder, name), encoding="utf-8") as source:
                    text = source.read()
                assert "from numba import njit" not in text, f"{name}: take njit from contactlab.compiling"
    for kernel in (velocity_loop.LOOPS["velocity"], generate_contacts):
        locator = kernel._cache._impl.locator
        assert isinstance(locator, compiling.PackageStampedLocator)
        assert locator.get_source_stamp() == ("package sources", compiling.sources_digest(package))
        assert locator.get_cache_path() == kernel._cache._cache_path


def test_detection_from_python_is_the_loops_code_and_compiles_nothing_of_its_own():
    """``collide`` runs ``collision.detect`` as Python (``compiling.in_python``), calling the
    kernels the compiled loop calls: it compiles no whole-detection kernel of its own (2 s a
    scene), and the same code compiled, as the loop inlines it, gives the same contacts bit for
    bit, fresh and reusing kept manifolds alike."""
    from contactlab import collision
    from contactlab.collision.manifolds import Manifolds
    from contactlab.compiling import in_python

    model = mixed_model()
    state = model.state()
    collide(model, state, margin=0.02)
    assert collision.detect.signatures == []  # ran as Python, not compiled on its own

    @numba.njit
    def compiled(table, plan, keeping, at, reach, kept, tolerance):
        return collision.detect(table, plan, keeping, at, reach, kept, tolerance, None)

    table, plan = collision.colliders(model), collision.detection_plan(model)
    at = state_poses(model, state)
    reach = np.full(len(table.kinds), 0.01)
    kept = tuple(vars(Manifolds.empty()).values())
    for keeping, tolerance in ((None, 0.0), (True, 1e-3)):
        python = in_python(collision.detect)(table, plan, keeping, at, reach, kept, tolerance, None)
        machine = compiled(table, plan, keeping, at, reach, kept, tolerance)
        assert python[2] and machine[2] and len(python[0].depth) > 10
        for ours, theirs in zip(python[0] + python[1], machine[0] + machine[1]):
            np.testing.assert_array_equal(ours, theirs)
