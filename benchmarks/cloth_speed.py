"""cloth_drape's speed under each method, against another checkout of contactlab (issue 57's 10×).

    python3 benchmarks/cloth_speed.py --base /path/to/base/src [--rounds 2] [--methods impulse projection]

Each round runs, for the base checkout's sources and then for this one's (each in a fresh process,
``PYTHONPATH`` set to the sources, one thread), every method at its defaults on the built-in
``cloth_drape`` (25 × 25 vertices, self-collision on, backward Euler at 1/120 s): an untimed run of
0.6 s first (kernels compiled or loaded, contacts met), then the first 1.0 s timed (fall and
landing), then 40 steps from the draped state at 1.5 s. Each figure is given as steps per second of
wall time and per second of the process's CPU time (one thread: on a shared machine the steadier
of the two, as waiting for a core does not count). Rounds alternate base and this checkout, so the
load they meet is alike. Written to ``benchmarks/results/cloth_speed.json`` with the date, the
machine's cores, the load average before and after, and the thread count.
"""

import argparse
import json
import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
SOURCES = os.path.join(os.path.dirname(HERE), "src")
METHODS = ("projection", "impulse", "constraints")

MEASURE = r"""
import json, sys, time
from contactlab import simulate
from contactlab.scene import load_scene
from contactlab.threads import set_threads

set_threads(1)
scene = load_scene("cloth_drape")
out = {}
for method in sys.argv[1:]:
    options = scene.options.get(method)

    def run(seconds, state=None, every=1):
        return simulate(
            scene.model, method, scene.dt, seconds, options, scene.integrator, state=state, record_every=every
        )

    def timed(seconds, state=None, every=1):
        wall, cpu = time.perf_counter(), time.process_time()
        result = run(seconds, state, every)
        steps = round(seconds / scene.dt)
        return result, steps / (time.perf_counter() - wall), steps / (time.process_time() - cpu)

    run(0.6, every=1000)
    first, wall, cpu = timed(1.0)
    draped = run(1.5, every=1000).state
    _, draped_wall, draped_cpu = timed(40 * scene.dt, draped, 40)
    out[method] = {
        "first_second": {"wall": wall, "cpu": cpu},
        "draped": {"wall": draped_wall, "cpu": draped_cpu},
        "most_contacts": int(first.summary["max_contacts"]),
    }
print("RESULT " + json.dumps(out))
"""


def measure(sources: str, methods: list[str]) -> dict:
    """One fresh process on ``sources``: {method: figures} (see the module)."""
    env = dict(os.environ, PYTHONPATH=sources, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    done = subprocess.run(
        [sys.executable, "-c", MEASURE, *methods], env=env, capture_output=True, text=True, check=True
    )
    line = next(line for line in done.stdout.splitlines() if line.startswith("RESULT "))
    return json.loads(line[len("RESULT ") :])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--base", required=True, help="the base checkout's src folder")
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--methods", nargs="+", default=list(METHODS))
    args = parser.parse_args()
    rounds = []
    load_before = os.getloadavg()
    for number in range(args.rounds):
        row = {}
        for name, sources in (("base", args.base), ("now", SOURCES)):
            row[name] = measure(sources, args.methods)
            for method, figures in row[name].items():
                print(
                    f"round {number + 1} {name:4s} {method:12s} first 1 s {figures['first_second']['wall']:7.1f} "
                    f"steps/s ({figures['first_second']['cpu']:7.1f} per CPU s), draped "
                    f"{figures['draped']['wall']:7.1f} ({figures['draped']['cpu']:7.1f}), "
                    f"load {os.getloadavg()[0]:.2f}",
                    flush=True,
                )
        rounds.append(row)
    record = {
        "date": time.strftime("%Y-%m-%d %H:%M"),
        "cores": os.cpu_count(),
        "threads": 1,
        "load_before": load_before,
        "load_after": os.getloadavg(),
        "base": args.base,
        "rounds": rounds,
    }
    path = os.path.join(HERE, "results", "cloth_speed.json")
    with open(path, "w", encoding="utf-8") as out:
        json.dump(record, out, indent=1)
    print("wrote", path)


if __name__ == "__main__":
    main()
