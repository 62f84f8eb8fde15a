"""The FCLIB problems under `newton`, against `nsgs` and `apgd` (issue 19) — `python benchmarks/fclib_newton.py`.

Every problem of data/fclib (the repository's copy; read with `contactlab.fclib.read_problem`) is solved from
r = 0 to the same tolerance (default 1e-8 on the normalized natural-map error,
`contactlab.lcp.natural_map_error`) by

* `newton` (semi-smooth Newton on the Alart–Curnier function, `contactlab.lcp.newton`), at most
  1000 Newton steps, no warm start;
* `nsgs`, at most 10 000 sweeps;
* `apgd`, at most 10 000 steps (with the function restart of issue 19).

Reported per problem and method: iterations (Newton steps, sweeps, gradient steps), the error
reached, whether it converged, and the time of one solve — the best of `--repeats` (default 3)
solves after one untimed solve of every problem, which compiles or loads the Numba cache. The
error is recomputed from r with `natural_map_error`, not taken from the solver. Threads are
pinned before NumPy loads, as in the other benchmarks: BLAS (used by SuperLU) on one thread,
`NUMBA_NUM_THREADS` = `--numba-threads` (default 2; the kernels used here are serial).

Writes benchmarks/results/fclib_newton.md (machine, thread counts, load, the table).

    python benchmarks/fclib_newton.py
    python benchmarks/fclib_newton.py --tol 1e-10 --repeats 5 --data data/fclib
"""

import os
import sys

from pinning import pin_threads  # the script's own folder is on sys.path

pin_threads(sys.argv)

import argparse  # noqa: E402  (after the thread pinning)
import platform  # noqa: E402
import time  # noqa: E402
from datetime import date  # noqa: E402
from pathlib import Path  # noqa: E402

import numba  # noqa: E402
import numpy as np  # noqa: E402
import scipy  # noqa: E402

import contactlab  # noqa: E402
from contactlab.errors import InputError  # noqa: E402
from contactlab.fclib import read_problem  # noqa: E402
from contactlab.fclib_bench import MAX_ITERATIONS as CAPS  # noqa: E402  (one table of caps)
from contactlab.fclib_bench import PROBLEM_SUFFIXES  # noqa: E402
from contactlab.lcp import natural_map_error, solve_friction_contact  # noqa: E402

HERE = Path(__file__).resolve().parent
DATA = HERE.parent / "data" / "fclib"


def machine():
    cpu = "unknown"
    try:
        with open("/proc/cpuinfo") as stream:
            for line in stream:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return dict(
        cpu=cpu,
        cores=os.cpu_count(),
        python=platform.python_version(),
        numpy=np.__version__,
        scipy=scipy.__version__,
        numba=numba.__version__,
        contactlab=contactlab.__version__,
        numba_threads=os.environ["NUMBA_NUM_THREADS"],
        blas_threads=os.environ["OPENBLAS_NUM_THREADS"],
        date=date.today().isoformat(),
    )


def solve(problem, method, tol):
    start = time.perf_counter()
    result = solve_friction_contact(
        problem.W, problem.q, problem.mu, method=method, tol=tol, max_iterations=CAPS[method]
    )
    return result, time.perf_counter() - start


def measure(problems, methods, tol, repeats):
    for problem in problems:  # untimed: compiles, or loads the Numba cache
        for method in methods:
            solve(problem, method, tol)
    rows = []
    for problem in problems:
        row = {"name": problem.name, "nc": problem.nc, "format": problem.source_format}
        for method in methods:
            best = None
            for _ in range(repeats):
                result, seconds = solve(problem, method, tol)
                best = seconds if best is None else min(best, seconds)
            error = natural_map_error(problem.W, problem.q, problem.mu, result.r)
            row[method] = dict(iterations=result.iterations, error=error, converged=bool(error <= tol), seconds=best)
        rows.append(row)
        print(
            problem.name,
            {m: (row[m]["iterations"], f"{row[m]['error']:.1e}", f"{1e3 * row[m]['seconds']:.1f} ms") for m in methods},
            flush=True,
        )
    return rows


def cell(entry):
    mark = "" if entry["converged"] else " **no**"
    return f"{entry['iterations']} | {entry['error']:.1e}{mark} | {1e3 * entry['seconds']:.1f}"


def write_markdown(path, rows, methods, tol, repeats, info, load, data, unread=()):
    lines = [
        "# FCLIB problems: " + ", ".join(f"`{m}`" for m in methods),
        "",
        f"Problems: every file of `{data}` that `read_problem` reads (the others are listed at the end).",
        "",
        f"Written by `python benchmarks/fclib_newton.py` on {info['date']}: {info['cpu']}, {info['cores']} cores, "
        f"Python {info['python']}, NumPy {info['numpy']}, SciPy {info['scipy']}, Numba {info['numba']} "
        f"(NUMBA_NUM_THREADS = {info['numba_threads']}; BLAS threads = {info['blas_threads']}; the Newton "
        f"step's SuperLU and every kernel here run on one thread). Load average (1 min) {load[0]:.2f} before, "
        f"{load[1]:.2f} after.",
        "",
        f"Each problem from r = 0 to tol = {tol:g} on the normalized natural-map error "
        f"(`natural_map_error`, recomputed from r); caps: "
        + ", ".join(f"{m} {CAPS[m]}" for m in methods)
        + f". Time: the best of {repeats} solves [ms], after an untimed solve of every problem (Numba "
        "compile or cache load). Iterations: Newton steps (one sparse LU each), nsgs sweeps, apgd steps.",
        "",
        "| file | nc | " + " | ".join(f"{m} iterations | {m} error | {m} ms" for m in methods) + " |",
        "|---|---|" + "---|---|---|" * len(methods),
    ]
    for row in rows:
        lines.append(f"| {row['name']} | {row['nc']} | " + " | ".join(cell(row[m]) for m in methods) + " |")
    solved = {m: sum(row[m]["converged"] for row in rows) for m in methods}
    lines += [
        "",
        "Solved to tol: " + ", ".join(f"{m} {solved[m]} of {len(rows)}" for m in methods) + ".",
        "Total time: " + ", ".join(f"{m} {1e3 * sum(row[m]['seconds'] for row in rows):.0f} ms" for m in methods) + ".",
    ]
    if unread:
        lines += ["", f"Not read ({len(unread)}): " + "; ".join(unread) + "."]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")


def shown(folder):
    """The folder as the results name it: relative to the repository when inside it."""
    relative = os.path.relpath(folder.resolve(), HERE.parent)
    return folder if relative.startswith("..") else relative


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DATA, help="folder of FCLIB .hdf5 / Siconos .dat files")
    parser.add_argument("--tol", type=float, default=1e-8)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--methods", nargs="*", default=["newton", "nsgs", "apgd"])
    parser.add_argument("--numba-threads", default="2", help="NUMBA_NUM_THREADS (set before Numba loads)")
    parser.add_argument("--out", type=Path, default=HERE / "results" / "fclib_newton.md")
    args = parser.parse_args()
    if not args.data.is_dir():
        sys.exit(f"no FCLIB data folder at {args.data}")
    files = sorted(p for p in args.data.iterdir() if p.suffix.lower() in PROBLEM_SUFFIXES)
    problems, unread = [], []
    for path in files:  # a folder such as Siconos' test data also holds 2D and global problems
        try:
            problems.append(read_problem(path))
        except InputError as failure:
            unread.append(f"{path.name} ({failure.message})")
    before = os.getloadavg()[0]
    rows = measure(problems, args.methods, args.tol, args.repeats)
    after = os.getloadavg()[0]
    info, load = machine(), (before, after)
    write_markdown(args.out, rows, args.methods, args.tol, args.repeats, info, load, shown(args.data), unread)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
