"""A 16-cell study on a local Dask cluster against the same cells in series (issue 21) —
`python benchmarks/sweep_speedup.py`.

The study: the 5-level box pyramid (5 s) under the four methods at two time steps and two
frictions (16 cells, 1–10 s each). Measured in one
run, in this order:

* **series**: every cell through ``contactlab.sweep.run_cell`` one after another in this
  process, after one untimed cell (Numba's cache loaded), as a user without Dask would run them;
* **sweep**: ``contactlab.sweep.run`` on a local cluster of ``--workers`` single-threaded
  workers (default: one per core) whose workers ran one cell first (imports and compile cache
  loaded), from the call to its return, report included ("cells only"); and again on a fresh
  cluster into a fresh folder, the cluster's start and the workers' first loads counted too;
* **overhead**: 200 tasks that do nothing through ``contactlab.cluster.run_tasks`` on that
  cluster: the engine's cost per cell.

Also with ``--busy``: a second process spinning on one core throughout. Writes
benchmarks/results/sweep_speedup.md with the machine, the thread counts and the load.
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
"""


def _nothing(job):
    return job


def measure(workers, folder):
    from contactlab import cluster, sweep
    from contactlab.study import load_study

    path = os.path.join(folder, "speedup.toml")
    with open(path, "w", encoding="utf-8") as stream:
        stream.write(STUDY)
    study = load_study(path)
    assert len(study.cells) == 16, len(study.cells)
    jobs = [sweep._job(cell, study, folder) for cell in study.cells]
    sweep.run_cell(jobs[0])  # untimed: the compile cache is loaded
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


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=None)
    parser.add_argument("--busy", action="store_true", help="also measure with one core kept busy")
    parser.add_argument("--out", default=os.path.join(HERE, "results", "sweep_speedup.md"))
    args = parser.parse_args()
    from contactlab.cluster import default_workers

    lines = [
        "# A 16-cell study: a local Dask cluster against the cells in series",
        "",
        f"Written by `python benchmarks/sweep_speedup.py` on {time.strftime('%Y-%m-%d')}: "
        f"{machine()['cpu']}, {machine()['cores']} cores; each cell on one thread (simulate(threads=1)), "
        f"one thread per worker.",
        "",
        "| load | workers | in series (s) | sweep, cells only (s) | speed-up | "
        "sweep with cluster start and report (s) | "
        "speed-up | engine overhead per cell (ms) | Σ cell time on workers (s) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for busy in [False, True] if args.busy else [False]:
        with busy_core(busy), tempfile.TemporaryDirectory() as folder:
            load = os.getloadavg()[0]
            workers = args.workers or default_workers()  # as sweep.run chooses them, load and all
            result = measure(workers, folder)
        what = f"one core busy (load {load:.2f} at start)" if busy else f"idle (load {load:.2f} at start)"
        row = (
            f"| {what} | {workers} | {result['series']:.1f} | {result['cells_only']:.1f} | "
            f"{result['series'] / result['cells_only']:.2f}× | {result['whole']:.1f} | "
            f"{result['series'] / result['whole']:.2f}× | {result['overhead'] * 1000:.1f} | "
            f"{result['cell_seconds']:.1f} |"
        )
        print(row, flush=True)
        lines.append(row)
    write_lines(args.out, lines)


if __name__ == "__main__":
    main()
