"""Issue 36, item 1: the built-in scenes that joined the compiled loop, on each path.

    python3 benchmarks/loop_scenes.py                  # box_pushed, impulse and projection
    python3 benchmarks/loop_scenes.py --first-run      # also each path's first run on an empty cache

``box_pushed`` (a kinematic paddle on keyframes pushes a box) stepped through the methods' ``step``
until its drive became a compiled stage (``driving.drive_velocities``) that the loop and the
methods' steps share. For each scene and
method: the whole scene's steps/s (the summary's figure: stepping only) and the process CPU time
of the run, through the compiled loop (``compiled_loop=True``, after a run that compiles it)
and through the methods' step (``compiled_loop=False``). ``--first-run``: each path's first run
of the scene in a fresh process on an empty Numba cache (CPU and wall seconds, compiling
included), which is what a user meets once per scene's mix of shapes. Written to
``benchmarks/results/loop_scenes.md`` with the thread count and the load average.
"""

import os
import subprocess
import sys
import tempfile
import time

SCENES = ("box_pushed",)
METHODS = ("impulse", "projection")
HERE = os.path.dirname(os.path.abspath(__file__))


def warm_rates(name, method):
    """[(path, steps/s, CPU ms of the run)] through the loop and through the methods' step."""
    from contactlab import simulate
    from contactlab.scene import load_scene

    scene = load_scene(name)
    rows = []
    for path, compiled_loop in (("loop", True), ("step", False)):
        simulate(scene.model, method, scene.dt, 0.05, compiled_loop=compiled_loop)  # compiles or loads
        started = time.process_time()
        run = simulate(scene.model, method, scene.dt, scene.duration, compiled_loop=compiled_loop)
        rows.append((path, run.summary["steps_per_second"], 1e3 * (time.process_time() - started)))
    return rows


FIRST_RUN = """
import sys, time
started, wall = time.process_time(), time.perf_counter()
from contactlab import simulate
from contactlab.scene import load_scene
scene = load_scene(sys.argv[1])
simulate(scene.model, sys.argv[2], scene.dt, scene.duration, compiled_loop=sys.argv[3] == "loop")
print(time.process_time() - started, time.perf_counter() - wall)
"""


def first_run(name, method, path):
    """(CPU s, wall s) of a fresh process's first run on an empty compile cache."""
    with tempfile.TemporaryDirectory() as cache:
        out = subprocess.run(
            [sys.executable, "-c", FIRST_RUN, name, method, path],
            env=dict(os.environ, NUMBA_CACHE_DIR=cache),
            capture_output=True,
            text=True,
            check=True,
        )
    cpu, wall = (float(x) for x in out.stdout.split()[-2:])
    return cpu, wall


def main(argv):
    from contactlab.compiling import available_threads

    lines = [
        "# Driven scenes: compiled loop against the methods' step",
        "",
        f"Numba threads {available_threads()}, load average {os.getloadavg()[0]:.2f} at the start.",
        "",
        "| scene | method | path | steps/s | CPU ms of the run |"
        + (" first run CPU s | first run wall s |" if "--first-run" in argv else ""),
        "|---|---|---|---|---|" + ("---|---|" if "--first-run" in argv else ""),
    ]
    for name in SCENES:
        for method in METHODS:
            for path, rate, cpu in warm_rates(name, method):
                row = f"| {name} | {method} | {path} | {rate:.0f} | {cpu:.0f} |"
                if "--first-run" in argv:
                    first_cpu, first_wall = first_run(name, method, path)
                    row += f" {first_cpu:.1f} | {first_wall:.1f} |"
                lines.append(row)
                print(row, flush=True)
    lines += ["", f"Load average {os.getloadavg()[0]:.2f} at the end."]
    with open(os.path.join(HERE, "results", "loop_scenes.md"), "w") as out:
        out.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main(sys.argv[1:])
