"""Threads on an idle and on a busy machine: contactlab's default thread setting against one
thread and against every thread, on each benchmark scene — `python benchmarks/threads.py`.

Issue 18's target: with a second busy process on the machine, the default setting ("auto") is
at least as fast as one thread on every benchmark scene. For each scene and each load (idle;
one process spinning on a core) the three settings are run in turn, twice, from the same
settled state, and the better of the two runs of each is kept (the machine's noise only ever
slows a run down). Results are bit for bit the same on any setting (tests/test_threads.py), so
only steps/s is compared. Writes benchmarks/results/threads.json and benchmarks/results/threads.md
with the machine, Numba's threading layer, the thread counts and the load average of each row.

    python benchmarks/threads.py                 # every scene (about 6 minutes on 2 cores)
    python benchmarks/threads.py --only pile1000 --seconds 0.5
"""

import argparse
import json
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

import peers  # noqa: E402, I001  (the scenes; pins BLAS threads before NumPy loads, so first)
import numba  # noqa: E402
from contactlab import simulate  # noqa: E402
from contactlab.scene import load_scene  # noqa: E402

SETTINGS = ("auto", 1, numba.config.NUMBA_NUM_THREADS)


def scenes():
    """key -> (model, method, dt, settle seconds): settled before timing, so every setting
    times the same resting or landing phase."""
    builtin = load_scene("box_pyramid")
    return {
        "box_pyramid": lambda: (builtin.model, "impulse", builtin.dt, 0.2),
        "pyramid": lambda: (peers.contactlab_pyramid(20), "constraints", peers.DT, 0.2),
        "pile1000": lambda: (peers.contactlab_pile(1000)[0], "constraints", peers.DT, 0.3),
        "pile4000": lambda: (peers.contactlab_pile(4000)[0], "constraints", peers.DT, 0.3),
    }


def measure(model, method, dt, state, seconds, setting):
    run = simulate(model, method, dt, seconds, state=state, threads=setting)
    return {
        "steps_per_second": run.summary["steps_per_second"],
        "steps_at": run.summary["threads"]["steps_at"],
        "mean_sweeps": run.summary["solver"]["mean_iterations"],
    }


def scene_rows(key, make, seconds, repeats):
    model, method, dt, settle = make()
    settled = simulate(model, method, dt, settle, compiled_loop=True).state  # also compiles every kernel
    rows = []
    for load in ("idle", "one busy core"):
        with peers.busy_core(load != "idle"):
            best = {}
            for _ in range(repeats):
                for setting in SETTINGS:
                    result = measure(model, method, dt, settled, seconds, setting)
                    if setting not in best or result["steps_per_second"] > best[setting]["steps_per_second"]:
                        best[setting] = result
            load_average = os.getloadavg()[0]
        auto, one = best["auto"]["steps_per_second"], best[1]["steps_per_second"]
        rows.append(
            {
                "scene": key,
                "method": method,
                "load": load,
                "load_average_1min": load_average,
                "settings": {str(setting): best[setting] for setting in SETTINGS},
                "auto_over_one": auto / one,
            }
        )
        print(
            f"{key:12s} {load:14s} "
            + "  ".join(f"{setting}: {best[setting]['steps_per_second']:8.1f}" for setting in SETTINGS)
            + f"  auto/1 = {auto / one:.2f}",
            flush=True,
        )
    return rows


def write_markdown(results, path):
    threads_all = results["machine"]["numba_threads"]
    lines = [
        "# Threads on an idle and on a busy machine",
        "",
        f"Written by `python benchmarks/threads.py` on {results['date']}: {results['machine']['cpu']}, "
        f"{results['machine']['cores']} cores, Numba {results['machine']['numba']} "
        f"(threading layer `{results['machine']['threading_layer']}`, NUMBA_NUM_THREADS = {threads_all}, "
        f"GOMP_SPINCOUNT = {results['machine']['gomp_spincount']}). Each figure is the better of "
        f"{results['repeats']} runs of {results['seconds']} s of simulated time from the same settled "
        "state; 'one busy core' is a second process spinning on one core for the whole row. "
        "steps/s counts the stepping only.",
        "",
        f"| scene | method | load | load avg (1 min) | auto | 1 thread | {threads_all} threads | auto / 1 "
        "| steps of auto on 1 / all | sweeps per step |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for row in results["rows"]:
        settings = row["settings"]
        steps_at = settings["auto"]["steps_at"]
        lines.append(
            f"| {row['scene']} | {row['method']} | {row['load']} | {row['load_average_1min']:.2f} | "
            f"{settings['auto']['steps_per_second']:.1f} | {settings['1']['steps_per_second']:.1f} | "
            f"{settings[str(threads_all)]['steps_per_second']:.1f} | {row['auto_over_one']:.2f} | "
            f"{steps_at.get('1', 0)} / {steps_at.get(str(threads_all), 0)} | "
            f"{settings['auto']['mean_sweeps']:.1f} |"
        )
    met = all(row["auto_over_one"] >= 0.95 for row in results["rows"] if row["load"] != "idle")
    lines += [
        "",
        f"Target (auto at least as fast as one thread with a busy core, within 5 % of noise): "
        f"**{'met' if met else 'not met'}**.",
        "",
    ]
    with open(path, "w") as stream:
        stream.write("\n".join(lines))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", nargs="*", default=None, help="some of: " + " ".join(scenes()))
    parser.add_argument("--seconds", type=float, default=0.5, help="simulated seconds per timed run")
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--out", default=os.path.join(HERE, "results"))
    args = parser.parse_args()
    chosen = {key: make for key, make in scenes().items() if not args.only or key in args.only}
    rows = []
    for key, make in chosen.items():
        rows += scene_rows(key, make, args.seconds, args.repeats)
    machine = peers.machine()
    machine.update(
        numba=numba.__version__,
        numba_threads=numba.config.NUMBA_NUM_THREADS,
        threading_layer=numba.threading_layer(),
        gomp_spincount=os.environ.get("GOMP_SPINCOUNT"),
    )
    results = {
        "date": time.strftime("%Y-%m-%d"),
        "machine": machine,
        "seconds": args.seconds,
        "repeats": args.repeats,
        "rows": rows,
    }
    os.makedirs(args.out, exist_ok=True)
    with open(os.path.join(args.out, "threads.json"), "w") as stream:
        json.dump(results, stream, indent=1)
    write_markdown(results, os.path.join(args.out, "threads.md"))
    print(f"wrote {os.path.join(args.out, 'threads.md')}")


if __name__ == "__main__":
    main()
