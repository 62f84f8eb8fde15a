"""A 16-cell study on a local Dask cluster against the same cells in series (issues 21, 59) —
`python benchmarks/sweep_speedup.py [--durations 5,20,60]`.

The study: the 5-level box pyramid under the four methods at two time steps and two
frictions (16 cells), each cell simulating the same ``--durations`` seconds, once per duration
given (default 5, 20 and 60 s): where a local cluster starts to pay is a matter of how much
work the study holds against the seconds a cluster takes to start. For each, in this order:

* **series**: every cell through ``contactlab.sweep.run_cell`` one after another in this
  process, after one untimed cell of each method (its kernels loaded), as a user without Dask would run them;
* **sweep**: ``contactlab.sweep.run`` on a local cluster of ``--workers`` single-threaded
  workers (default: one per core) whose workers ran one cell first (imports and compile cache
  loaded), from the call to its return, report included ("cells only"); and again on a fresh
  cluster into a fresh folder, the cluster's start and the workers' first loads counted too;
* **overhead**: 200 tasks that do nothing through ``contactlab.cluster.run_tasks`` on that
  cluster: the engine's cost per cell.

Also with ``--busy``: a second process spinning on one core throughout. Writes
benchmarks/results/sweep_speedup.md with the machine, the thread counts and the load, and the
series time at which the cluster, its start counted, becomes faster than the series
(interpolated in log time between the two durations that straddle a speed-up of 1).
"""

import argparse
import os
import shutil
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from peers import busy_core, machine, write_lines  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
STUDY = """
[study]
name = "speedup"
[grid]
scenes = ["box_pyramid"]
methods = ["penalty", "projection", "impulse", "constraints"]
[grid.set]
"simulation.dt" = [0.002, 0.001]
"materials.0.friction" = [0.6, 0.3]
"simulation.duration" = [{duration}]
"""


def _nothing(job):
    return job


def measure(workers, folder, duration):
    from contactlab import cluster, sweep
    from contactlab.study import load_study

    path = os.path.join(folder, "speedup.toml")
    with open(path, "w", encoding="utf-8") as stream:
        stream.write(STUDY.format(duration=float(duration)))
    study = load_study(path)
    assert len(study.cells) == 16, len(study.cells)
    jobs = [sweep._job(cell, study, folder) for cell in study.cells]
    for method in {cell.method: None for cell in study.cells}:  # untimed: each method's kernels loaded (or compiled)
        sweep.run_cell(next(job for job, cell in zip(jobs, study.cells) if cell.method == method))
    started = time.perf_counter()
    rows = [sweep.run_cell(job) for job in jobs]
    series = time.perf_counter() - started
    assert all(row["status"] == "ok" for row in rows), [row["message"] for row in rows]

    out = os.path.join(folder, "out")
    with cluster.connect(workers=workers) as client:
        client.wait_for_workers(workers)
        client.run(sweep.run_cell, jobs[0])  # every worker warm: imports and compile cache loaded
        started = time.perf_counter()
        table = sweep.run(study, out, client=client)
        cells_only = time.perf_counter() - started
        assert (table["status"] == "ok").all()
        started = time.perf_counter()
        for _ in cluster.run_tasks(client, _nothing, [(str(i), i) for i in range(200)]):
            pass
        overhead = (time.perf_counter() - started) / 200
    shutil.rmtree(out)
    started = time.perf_counter()
    sweep.run(study, out, workers=workers)  # a fresh cluster, counted
    whole = time.perf_counter() - started
    return {
        "series": series,
        "cells_only": cells_only,
        "whole": whole,
        "overhead": overhead,
        "cell_seconds": float(table["cell_seconds"].sum()),
    }


def pays_from(rows):
    """The series time [s] at which the whole sweep's speed-up (its cluster's start counted)
    reaches 1, interpolated in log series time between the rows (series [s], speed-up) that
    straddle it; None where no two do."""
    import math

    for (t0, s0), (t1, s1) in zip(rows, rows[1:]):
        if s0 < 1.0 <= s1:
            f = (1.0 - s0) / (s1 - s0)
            return math.exp(math.log(t0) + f * (math.log(t1) - math.log(t0)))
    return None


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=None)
    parser.add_argument("--busy", action="store_true", help="also measure with one core kept busy")
    parser.add_argument("--durations", default="5,20,60", help="simulated seconds of each cell, one study each")
    parser.add_argument("--out", default=os.path.join(HERE, "results", "sweep_speedup.md"))
    args = parser.parse_args()
    from contactlab.cluster import default_workers

    durations = [float(d) for d in args.durations.split(",")]
    lines = [
        "# A 16-cell study: a local Dask cluster against the cells in series",
        "",
        f"Written by `python benchmarks/sweep_speedup.py --durations {args.durations}` on "
        f"{time.strftime('%Y-%m-%d')}: {machine()['cpu']}, {machine()['cores']} cores; each cell on one thread "
        f"(simulate(threads=1)), one thread per worker.",
        "",
        "| load | workers | simulated s per cell | in series (s) | sweep, cells only (s) | speed-up | "
        "sweep with cluster start and report (s) | "
        "speed-up | engine overhead per cell (ms) | Σ cell time on workers (s) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    crossings = []
    for busy in [False, True] if args.busy else [False]:
        whole = []
        for duration in durations:
            with busy_core(busy), tempfile.TemporaryDirectory() as folder:
                load = os.getloadavg()[0]
                workers = args.workers or default_workers()  # as sweep.run chooses them, load and all
                result = measure(workers, folder, duration)
            what = f"one core busy (load {load:.2f} at start)" if busy else f"idle (load {load:.2f} at start)"
            row = (
                f"| {what} | {workers} | {duration:g} | {result['series']:.1f} | {result['cells_only']:.1f} | "
                f"{result['series'] / result['cells_only']:.2f}× | {result['whole']:.1f} | "
                f"{result['series'] / result['whole']:.2f}× | {result['overhead'] * 1000:.1f} | "
                f"{result['cell_seconds']:.1f} |"
            )
            print(row, flush=True)
            lines.append(row)
            whole.append((result["series"], result["series"] / result["whole"]))
        crossing = pays_from(whole)
        crossings.append(
            f"{'One core busy' if busy else 'Idle'}: the sweep, its cluster's start counted, "
            + (
                f"pays from about {crossing:.0f} s of cells in series."
                if crossing is not None
                else "did not cross a speed-up of 1 between these durations."
            )
        )
    write_lines(args.out, lines + [""] + crossings)


if __name__ == "__main__":
    main()
