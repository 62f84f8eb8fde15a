"""Issue 38, item 2: what the velocity-level solve's settings cost and buy on the benchmark's
pile and pyramid — steps/s (wall, and CPU ms a step by process_time), the largest overlap, the
drift, the boxes that moved, sweeps a step — for each setting given.

    python benchmarks/solver_settings.py --only pile1000 pyramid --set iterations=10 iterations=20
    python benchmarks/solver_settings.py --only pyramid --set "substeps=4 iterations=1"

Each ``--set`` is one run: space-separated key=value Options of ``constraints`` (``--method
impulse`` for the other); none given: the defaults. Rows go to stdout as JSON lines, with the
load average before and after and the threads the run used. Scenes and measures are
benchmarks/peers.py's own (``contactlab_pile``, ``contactlab_pyramid``, ``pile_measures``,
``moved``)."""

import sys

from pinning import pin_threads  # the script's own folder is on sys.path

pin_threads(sys.argv)

import argparse  # noqa: E402
import json  # noqa: E402
import os  # noqa: E402
import time  # noqa: E402

from peers import DT, PILE_WARMUP, contactlab_pile, contactlab_pyramid, moved, pile_measures  # noqa: E402

from contactlab import simulate  # noqa: E402

DURATIONS = {"pile1000": 3.0, "pile4000": 1.0, "pyramid": 5.0}
SAMPLE_EVERY = 12


def parse(setting):
    """Options from 'key=value key=value' (numbers as numbers, true/false as booleans)."""
    options = {}
    for pair in setting.split():
        key, value = pair.split("=", 1)
        if value.lower() in ("true", "false"):
            options[key] = value.lower() == "true"
            continue
        try:
            options[key] = int(value)
        except ValueError:
            try:
                options[key] = float(value)
            except ValueError:
                options[key] = value
    return options


def measure(scene, method, options, duration):
    if scene == "pyramid":
        model, half_width = contactlab_pyramid(), None
    else:
        model, half_width = contactlab_pile(int(scene[4:]))
    warmup = PILE_WARMUP if half_width else 3 * DT
    simulate(model, method, DT, warmup, options, compiled_loop=True)  # compiles
    load = os.getloadavg()[0]
    cpu = time.process_time()
    run = simulate(model, method, DT, duration, options, record_every=SAMPLE_EVERY)
    cpu = time.process_time() - cpu
    summary, arrays = run.summary, run.arrays
    steps = int(round(duration / DT))
    row = dict(
        scene=scene,
        method=method,
        options=options,
        duration=duration,
        steps_per_second=round(summary["steps_per_second"], 1),
        cpu_ms_per_step=round(1e3 * cpu / steps, 3),
        sweeps_per_step=round(summary["solver"]["mean_iterations"], 2),
        threads=summary["threads"],
        load=[round(load, 2), round(os.getloadavg()[0], 2)],
    )
    if half_width:
        penetration, drift = pile_measures(list(arrays["body_position"]), list(arrays["time"]), half_width)
        row.update(max_penetration_mm=round(1e3 * penetration, 3), drift_mm=round(1e3 * drift, 2))
    else:
        travel = moved(list(arrays["body_position"]))
        row.update(
            max_penetration_mm=round(1e3 * summary["max_penetration"], 3),
            drift_mm=round(1e3 * float(travel.max()), 3),
            moved_over_1mm=int((travel > 1e-3).sum()),
        )
    return row


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", nargs="+", default=list(DURATIONS), choices=list(DURATIONS))
    parser.add_argument("--set", nargs="*", default=[""], help="key=value Options, one run each")
    parser.add_argument("--method", default="constraints", choices=("constraints", "impulse"))
    parser.add_argument("--duration", type=float, help="sim seconds (default: per scene)")
    parser.add_argument("--numba-threads", default="2")  # read by pin_threads
    args = parser.parse_args()
    for scene in args.only:
        for setting in args.set:
            row = measure(scene, args.method, parse(setting), args.duration or DURATIONS[scene])
            print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
