"""A first run that would wait longer on the compiler than it takes as Python steps as Python
(contactlab.kernel_variants): said in one line, the same numbers, and the kind recorded once a
compiled run has made it."""

import json
import os
import subprocess
import sys

import numba

from contactlab import kernel_variants
from contactlab.compare import compare
from contactlab.compiling import NOTICE, PackageStampedLocator, compile_notice, one_notice
from contactlab.first_run import CHOICE
from contactlab.methods import get, make_options
from contactlab.scene import load_scene


def _command(tmp_path, *arguments, **env):
    environment = {key: value for key, value in os.environ.items() if key not in (CHOICE, "NUMBA_DISABLE_JIT")}
    environment.update(NUMBA_CACHE_DIR=str(tmp_path / "cache"), **env)
    return subprocess.run(
        [sys.executable, "-m", "contactlab", *arguments],
        cwd=tmp_path,
        env=environment,
        capture_output=True,
        text=True,
        timeout=600,
    )


def test_a_short_first_run_steps_as_python_says_so_and_compiles_nothing(tmp_path):
    """The sliding block's 500 steps on an empty cache: one line on stderr, no compile notice, no
    kernel written to the cache, the closed-form expectations met, the summary saying so."""
    done = _command(tmp_path, "run", "sliding_block", "--json", "--no-plots", "--out", "block")
    assert done.returncode == 0, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("stepping as Python: about "), lines
    assert NOTICE not in done.stderr
    summary = json.loads(done.stdout)
    assert summary["kernels"] == "python" and summary["compile_seconds"] < 0.1
    assert all(check["passed"] for check in summary["checks"]), summary["checks"]
    assert not list((tmp_path / "cache").rglob("methods/*.nbc"))  # no step compiled


def test_the_kind_of_a_run_tells_apart_what_compiles_apart():
    """Runs that compile one loop share a kind (impulse and constraints share theirs); another
    loop, another shape family, another flag do not; the Python-wired path (cloth) has none."""
    ball, block, cloth = (load_scene(name) for name in ("bouncing_ball", "sliding_block", "cloth_drape"))

    def kind(scene, method=None):
        method = method or scene.method
        options = make_options(get(method), scene.method_options.get(method, {}), method)
        return kernel_variants.variant_of(scene.model, method, options, scene.integrator)

    assert kind(ball) == kind(load_scene("bouncing_ball", ["simulation.duration=1.0"]))
    assert kind(ball) != kind(block)  # sphere-plane against box-plane
    assert kind(ball, "constraints") == kind(ball) != kind(ball, "projection")  # one loop for the two
    assert kind(cloth) is None


def test_the_compile_estimate_is_the_median_of_this_machines_compiles(tmp_path, monkeypatch):
    monkeypatch.setattr(PackageStampedLocator, "folder_of", classmethod(lambda cls, root: tmp_path))
    assert kernel_variants.compiled_variants() == {}
    assert kernel_variants.compile_estimate() == kernel_variants.DEFAULT_COMPILE_SECONDS
    for name, seconds in (("a", 30.0), ("b", 50.0), ("c", 0.0), ("d", 40.0)):
        kernel_variants.remember(name, seconds)
    assert kernel_variants.compiled_variants() == {"a": 30.0, "b": 50.0, "c": 0.0, "d": 40.0}
    assert kernel_variants.compile_estimate() == 40.0  # loads (0 s) left out
    (tmp_path / kernel_variants.VARIANTS_FILE).write_text("not json")
    assert kernel_variants.compiled_variants() == {}  # a damaged record: every kind probes again


def test_a_compare_of_kinds_not_compiled_says_their_wait_together_once(tmp_path, monkeypatch, capsys):
    """A compare whose kinds this machine has no record of says, once, at its first compile, the
    wait of all of them: impulse and constraints share a loop, projection has its own, so two
    kinds at the 45 s estimate (nothing recorded) each. Measured before: ``compare box_pyramid``
    said "about 45 s" and compiled for 225 s. Once recorded, nothing is said. (The kernels may be
    in Numba's cache already, compiled by another test: then nothing compiles and nothing is
    said, which this test cannot tell from a failure to say — so it forces one compile, of a
    kernel of its own, inside the command.)"""
    monkeypatch.setattr(kernel_variants, "_record", lambda: tmp_path / kernel_variants.VARIANTS_FILE)
    monkeypatch.setattr(kernel_variants, "_REMEMBERED", set())  # what this process recorded elsewhere
    methods = ["impulse", "constraints", "projection"]
    with one_notice():  # as a command runs it: the notice once, whatever the runs then compile
        compare("bouncing_ball", methods, tmp_path / "a", duration=0.02, video=False, workers=1)
        with compile_notice():
            numba.njit(lambda x: x + 1)(1)  # a compile of its own, in case the runs compiled nothing
    said = [line for line in capsys.readouterr().err.splitlines() if line.startswith(NOTICE)]
    total = 2 * kernel_variants.DEFAULT_COMPILE_SECONDS
    assert len(said) == 1 and f"about {total:.0f} s on this machine for 2 kinds of run" in said[0], said
    assert len(kernel_variants.compiled_variants()) == 2  # the runs recorded both kinds
    with one_notice():
        compare("bouncing_ball", methods, tmp_path / "b", duration=0.02, video=False, workers=1)
    assert NOTICE not in capsys.readouterr().err


def test_an_uncachable_kernel_warns_instead_of_failing(tmp_path):
    """Numba names the kernel's file when it warns that a kernel cannot be cached: the package's
    locator has it (an AttributeError once, which NUMBA_OPT=0 brought out)."""
    folder = tmp_path / "packages" / "uncachable"
    folder.mkdir(parents=True)
    (folder / "__init__.py").write_text(
        "from contactlab.compiling import PackageStampedLocator as L\n\nL.stamp_package(__path__[0])\n"
    )
    (folder / "kernel.py").write_text(
        "from numba import njit, objmode\n\n\n@njit(cache=True)\ndef lifted(x):\n"
        "    with objmode(y='float64'):\n        y = float(x) + 1.0\n    return y\n"
    )
    script = (
        "import warnings\nwarnings.simplefilter('always')\nfrom uncachable.kernel import lifted\nprint(lifted(1.0))"
    )
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(tmp_path / "packages"), *sys.path]),
        "NUMBA_OPT": "0",
        "NUMBA_CACHE_DIR": str(tmp_path / "cache"),
    }
    done = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "2.0"
    assert "Cannot cache compiled function" in done.stderr and "kernel.py" in done.stderr


def test_a_compile_is_said_with_its_time_recorded_and_never_waited_on_again(tmp_path):
    """The one real compile from an empty cache the suite makes (about a minute on 2 cores), and
    what follows it:

    1. NUMBA_DISABLE_JIT=0 set by the user compiles even a short first run (no probe): one notice
       on stderr saying about how long (45 s: nothing recorded yet), the JSON alone on stdout, the
       kind recorded as compiled here with the seconds it took;
    2. the next run of that kind loads it, compiled, silently (no probe, no notice);
    3. ``contactlab compile`` finds it built and does nothing;
    4. with the record gone (the kernels kept), ``contactlab compile`` builds the kind in a worker
       process of its own, with progress, and records it again: a run then waits on nothing."""
    first = _command(
        tmp_path,
        "run",
        "bouncing_ball",
        "--duration",
        "0.05",
        "--json",
        "--no-plots",
        "--out",
        "a",
        NUMBA_DISABLE_JIT="0",
    )
    assert first.returncode == 0, first.stderr
    said = [line for line in first.stderr.splitlines() if line.startswith(NOTICE)]
    estimate = f"about {kernel_variants.DEFAULT_COMPILE_SECONDS:.0f} s on this machine"  # none recorded yet
    assert len(said) == 1 and estimate in said[0], first.stderr  # how long, said once
    summary = json.loads(first.stdout)  # stdout: the JSON alone
    assert summary["kernels"] == "compiled" and summary["compile_seconds"] > 0.0
    recorded = list((tmp_path / "cache").rglob(kernel_variants.VARIANTS_FILE))
    assert len(recorded) == 1
    kinds = json.loads(recorded[0].read_text())
    ball = load_scene("bouncing_ball")
    kind = kernel_variants.variant_of(ball.model, "impulse", ball.options["impulse"], ball.integrator)
    assert list(kinds) == [kind]
    assert kinds[kind] > 1.0  # the seconds it spent compiling

    again = _command(tmp_path, "run", "bouncing_ball", "--duration", "0.05", "--json", "--no-plots", "--out", "b")
    assert again.returncode == 0, again.stderr
    assert again.stderr == "" and json.loads(again.stdout)["kernels"] == "compiled"

    nothing = _command(tmp_path, "compile", "bouncing_ball", "rolling_sphere", "--methods", "impulse")
    assert nothing.returncode == 0, nothing.stderr
    assert nothing.stdout.startswith("Compiled 0 kinds of run in ") and "; 1 were compiled already;" in nothing.stdout

    recorded[0].unlink()
    done = _command(tmp_path, "compile", "bouncing_ball", "--methods", "impulse", "--workers", "1")
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("Compiled 1 kinds of run in ")
    assert "compiling 1 kinds of run in 1 processes (about " in done.stderr
    assert list(json.loads(recorded[0].read_text())) == [kind]
    run = _command(tmp_path, "run", "bouncing_ball", "--duration", "0.05", "--json", "--no-plots", "--out", "c")
    assert run.returncode == 0, run.stderr
    assert run.stderr == "" and json.loads(run.stdout)["kernels"] == "compiled"


def test_compile_takes_one_job_a_kind_and_refuses_bad_input(tmp_path):
    from contactlab.precompile import jobs_for

    jobs, refused = jobs_for(["bouncing_ball", "rolling_sphere", "sliding_block"], ["impulse"])
    assert [job.scene for job in jobs] == ["bouncing_ball", "sliding_block"]  # the two spheres: one kind
    assert refused == []
    bad = _command(tmp_path, "compile", "bouncing_ball", "--methods", "impulse,bogus")
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and "--methods" in bad.stderr
    nothing = _command(tmp_path, "compile", "no_such_scene")
    assert nothing.returncode == 2 and nothing.stderr.count("\n") == 1


def test_old_kernel_folders_are_pruned_to_the_most_recent(tmp_path, monkeypatch):
    """Each content of the sources has a kernel folder; only the most recently used are kept."""
    import time

    from contactlab import compiling

    monkeypatch.setattr(compiling, "kernel_cache_root", lambda: tmp_path)
    for index in range(5):
        folder = tmp_path / f"contactlab-{index:020d}-numba0.1"
        folder.mkdir()
        stamp = time.time() - 100 + index
        os.utime(folder, (stamp, stamp))
    (tmp_path / "otherpackage-0-numba0.1").mkdir()
    compiling.prune_kernel_folders("contactlab", keep=2)
    assert sorted(path.name for path in tmp_path.iterdir()) == [
        "contactlab-00000000000000000003-numba0.1",
        "contactlab-00000000000000000004-numba0.1",
        "otherpackage-0-numba0.1",
    ]


def test_a_probe_that_met_no_contact_does_not_speak_for_a_scene_of_many_colliders():
    """sphere_pile's first steps are in the air (no contact, cheap as Python) where its run ends in
    a pile of a thousand contacts (seconds a step as Python): its probe answers infinity, so the
    run compiles; a scene of a few colliders (the ball, also in the air) keeps its probe's time."""
    import math

    from contactlab.first_run import FEW_COLLIDERS, probe

    pile, ball = load_scene("sphere_pile"), load_scene("bouncing_ball")
    assert pile.model.body_count + pile.model.particle_count > FEW_COLLIDERS
    assert probe(pile, 480) == math.inf
    assert 0.0 < probe(ball, 480) < math.inf
