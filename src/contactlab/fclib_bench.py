"""Solver benchmarks over a folder of FCLIB problems, run through Dask (``contactlab fclib bench``).

    result = bench("data/fclib", solvers=["nsgs", "newton"], out="out/fclib-bench")
    result.table            # one row per (problem, solver)

Every problem file of a folder (FCLIB ``.hdf5`` / ``.h5``, Siconos ``.dat``) is solved by every
chosen solver of :func:`contactlab.lcp.solve_friction_contact`, from r = 0 to the same tolerance
on the normalized natural-map error. Each (problem, solver) pair is one job of
:mod:`contactlab.cluster`: a worker reads the file itself (the job carries the path, not the
matrices), solves it once untimed (Numba compiles, or loads its cache), then ``repeats`` times,
and keeps the best time. The error is recomputed from r with
:func:`contactlab.lcp.natural_map_error`, not taken from the solver. A file that cannot be read
or a solver that raises gives a row whose status says so; the other jobs go on.

Writes ``results.csv`` (the table), ``results.md`` (the table in Markdown, the settings and the
machine) and ``profile.png`` (the Dolan–Moré performance profile, :func:`performance_profile`)
into the output folder. See ``docs/fclib_bench.md``.
"""

from __future__ import annotations

import math
import numbers
import os
import socket
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from . import cluster
from .errors import InputError, first_line, shorten
from .fclib import read_problem
from .folder_lock import held
from .lcp import natural_map_error, solve_friction_contact
from .plots import DPI, STYLES, new_figure
from .record import atomic_path, make_folders, undo_written
from .threads import available_threads

if TYPE_CHECKING:
    from matplotlib.figure import Figure


SOLVERS = ("nsgs", "staggered", "apgd", "newton")
PROBLEM_SUFFIXES = (".hdf5", ".h5", ".dat")
MAX_ITERATIONS = {"newton": 1000, "nsgs": 10000, "staggered": 10000, "apgd": 10000}  # default caps
COLUMNS = ("problem", "contacts", "solver", "converged", "error", "iterations", "seconds", "worker", "status")
DEFAULT_OUT = os.path.join("out", "fclib-bench")


@dataclass
class Bench:
    """What :func:`bench` did: ``table`` (pandas.DataFrame, columns COLUMNS, one row per
    (problem, solver), problems in file-name order, solvers in the order asked), and the paths
    of the folder ``out`` and of the files written into it."""

    table: pd.DataFrame
    csv: Path
    markdown: Path
    profile_png: Path
    out: Path


@dataclass(frozen=True)
class Job:
    """One (problem, solver) solve, as sent to a worker: the problem's ``path``, the
    ``solver``, the tolerance ``tol`` on the normalized natural-map error (dimensionless), the
    ``max_iterations`` cap, and how many timed ``repeats``."""

    path: str
    solver: str
    tol: float
    max_iterations: int
    repeats: int


# ----------------------------------------------------------------------------- the jobs


def run_job(job: Job) -> dict:
    """Solve ``job`` where it runs (a Dask worker, or here) and return its row (COLUMNS):
    problem (file name), contacts (nc), solver, converged (error ≤ tol), error (normalized
    natural-map error of the r found, recomputed), iterations, seconds (the best of
    ``job.repeats`` solves after an untimed one [s]), worker (its address) and status ("ok",
    or "error: ..." when the file cannot be read or the solver raises — never raises itself)."""
    row = _failed_row(job, None, cluster.worker_address())
    try:
        problem = read_problem(job.path)
        row["contacts"] = problem.nc

        def solve():
            return solve_friction_contact(
                problem.W, problem.q, problem.mu, method=job.solver, tol=job.tol, max_iterations=job.max_iterations
            )

        solve()  # untimed: Numba compiles, or loads its cache
        best = math.inf
        for _ in range(job.repeats):
            start = time.perf_counter()
            result = solve()
            best = min(best, time.perf_counter() - start)
        error = natural_map_error(problem.W, problem.q, problem.mu, result.r)
    except Exception as failure:  # a bad file, a solver's error: the row says so
        row["status"] = _status(failure)
        return row
    row.update(
        converged=bool(error <= job.tol),
        error=float(error),
        iterations=int(result.iterations),
        seconds=best,
        status="ok",
    )
    return row


def _failed_row(job, failure, worker=""):
    """The row of ``job`` when it gave no result: status from ``failure`` ("" if None), the
    ``worker`` it ran on ("" when unknown)."""
    return dict(
        problem=Path(job.path).name,
        contacts=None,
        solver=job.solver,
        converged=False,
        error=math.nan,
        iterations=None,
        seconds=math.nan,
        worker=worker,
        status=_status(failure) if failure is not None else "",
    )


def _status(failure) -> str:
    """ "error: <type>: <first line>" of an exception, one short line."""
    first = first_line(failure)
    name = type(failure).__name__
    return shorten(f"error: {name}: {first}" if first != name else f"error: {name}")


def _machine() -> dict:
    """Where a worker runs: host, cores, NUMBA_NUM_THREADS and the 1-minute load average."""
    return dict(
        host=socket.gethostname(), cores=os.cpu_count(), numba_threads=available_threads(), load=os.getloadavg()[0]
    )


# ----------------------------------------------------------------------------- the performance profile


def performance_profile(
    times: np.ndarray, solved: np.ndarray, solvers: Sequence[str] | None = None
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """The Dolan–Moré performance profile of S solvers on P problems.

    ``times``: (P, S) solve times [s] (any unit, > 0 where solved); ``solved``: (P, S) bools,
    whether solver s solved problem p (its time is ignored otherwise). The ratio of a solved
    pair is its time over the best time of the solvers that solved the problem; an unsolved
    pair, and every pair of a problem no solver solved, has an infinite ratio.

    Returns ``(taus, fractions)``: ``taus`` the increasing ratios at which a fraction changes —
    1, then every finite ratio up to the largest — and ``fractions`` {solver: (len(taus),)
    array}: ρ_s(τ), the fraction of the P problems whose ratio for s is ≤ τ, a step function
    constant between the taus. Keys: ``solvers`` (S names), or the column indices 0…S−1."""
    times = np.asarray(times, dtype=np.float64)
    solved = np.asarray(solved, dtype=bool)
    if times.ndim != 2 or times.shape != solved.shape or times.shape[0] == 0:
        raise InputError(
            "times",
            f"expected times and solved of one shape (problems ≥ 1, solvers), found {times.shape} and {solved.shape}.",
        )
    names = list(range(times.shape[1])) if solvers is None else list(solvers)
    if len(names) != times.shape[1]:
        raise InputError("solvers", f"expected {times.shape[1]} solver names, found {len(names)}.")
    if not np.all(np.isfinite(times[solved]) & (times[solved] > 0)):
        raise InputError("times", "expected a positive finite time for every solved pair.")
    usable = np.where(solved, times, np.inf)
    best = usable.min(axis=1, keepdims=True)  # inf where no solver solved the problem
    with np.errstate(invalid="ignore"):
        ratios = np.where(solved, usable / best, np.inf)
    taus = np.unique(np.concatenate(([1.0], ratios[np.isfinite(ratios)])))
    within = ratios[:, :, None] <= taus[None, None, :]  # (P, S, T)
    fractions = within.sum(axis=0) / times.shape[0]
    return taus, {name: fractions[index] for index, name in enumerate(names)}


def profile_figure(taus: np.ndarray, fractions: Mapping[str, np.ndarray], title: str) -> Figure:
    """A Figure of the profile (:func:`performance_profile`'s output): one step line per solver,
    τ on a log2 axis from 1 to past the largest ratio."""
    figure, (ax,) = new_figure(title)
    right = max(2.0, float(taus[-1]) * 2**0.25)  # room to see the last step
    for index, (solver, values) in enumerate(fractions.items()):
        ax.step(
            np.append(taus, right),
            np.append(values, values[-1]),
            where="post",
            label=str(solver),
            color=f"C{index % 10}",
            linestyle=STYLES[index % len(STYLES)],
            linewidth=1.6,
        )
    ax.set_xscale("log", base=2)
    ax.set_xlim(1.0, right)
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlabel("τ: within τ × the best solver's time on the problem")
    ax.set_ylabel("fraction of problems solved")
    ax.grid(True, which="major", alpha=0.4)
    ax.legend(loc="lower right", fontsize="small")
    return figure


# ----------------------------------------------------------------------------- the benchmark


def problem_files(directory: str | os.PathLike[str]) -> list[Path]:
    """The problem files (PROBLEM_SUFFIXES) of the folder ``directory``, sorted by name;
    InputError("DIR") when it is not a folder or holds none."""
    folder = Path(directory)
    if not folder.is_dir():
        raise InputError("DIR", f"expected a folder of FCLIB problems, found no folder at {folder}.")
    files = sorted(path for path in folder.iterdir() if path.is_file() and path.suffix.lower() in PROBLEM_SUFFIXES)
    if not files:
        kinds = ", ".join(PROBLEM_SUFFIXES)
        raise InputError("DIR", f"expected FCLIB problem files ({kinds}) in {folder}, found none.")
    return files


def check_solvers(solvers: str | Sequence[str] | None) -> list[str]:
    """``solvers`` (None: all of SOLVERS; names, or one comma-separated string) as a list of
    distinct names in the order given; InputError("--solvers") naming the choices otherwise."""
    if solvers is None:
        return list(SOLVERS)
    names = solvers.split(",") if isinstance(solvers, str) else list(solvers)
    names = [name.strip() if isinstance(name, str) else name for name in names]
    unknown = [name for name in names if name not in SOLVERS]
    if unknown or not names:
        found = ", ".join(repr(name) for name in unknown) if unknown else "none"
        raise InputError("--solvers", f"expected solvers among {', '.join(SOLVERS)}, found {found}.")
    return list(dict.fromkeys(names))


def _caps(max_iterations, solvers) -> dict:
    """solver -> iteration cap: ``max_iterations`` for all, or MAX_ITERATIONS when None."""
    if max_iterations is None:
        return {solver: MAX_ITERATIONS[solver] for solver in solvers}
    if isinstance(max_iterations, bool) or not isinstance(max_iterations, numbers.Integral) or max_iterations < 1:
        raise InputError("--max-iterations", f"expected a whole number ≥ 1, found {max_iterations!r}.")
    return {solver: int(max_iterations) for solver in solvers}


def _check_settings(tol, repeats):
    """InputError unless tol is a positive finite number and repeats a whole number ≥ 1."""
    if isinstance(tol, bool) or not isinstance(tol, numbers.Real) or not (0 < tol < math.inf):
        raise InputError("--tol", f"expected a positive finite tolerance, found {tol!r}.")
    if isinstance(repeats, bool) or not isinstance(repeats, numbers.Integral) or repeats < 1:
        raise InputError("--repeats", f"expected a whole number of timed solves ≥ 1, found {repeats!r}.")


def bench(
    directory: str | os.PathLike[str],
    solvers: str | Sequence[str] | None = None,
    out: str | os.PathLike[str] | None = None,
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    tol: float = 1e-8,
    max_iterations: int | None = None,
    repeats: int = 3,
    progress: bool = False,
) -> Bench:
    """Solve every problem file of ``directory`` with every solver of ``solvers`` (default:
    all of SOLVERS) on Dask, and write results.csv, results.md and profile.png into ``out``
    (default ``out/fclib-bench``, created if needed; one bench at a time writes it: a second is
    refused with an InputError naming the first's process, contactlab.folder_lock).

    ``scheduler``: a Dask scheduler's address (``tcp://HOST:PORT``), or None for a local
    cluster of ``workers`` single-threaded processes (default: one per core;
    :func:`contactlab.cluster.connect`). ``tol``: the tolerance on the normalized natural-map
    error (dimensionless); a row is converged when its error ≤ tol. ``max_iterations``: one
    cap for every solver, or None for MAX_ITERATIONS (newton 1000 Newton steps, the others
    10 000 sweeps, rounds or steps). ``repeats``: timed solves per job, after an untimed one;
    the best time is kept. ``progress``: progress on stderr (contactlab.progress).

    Every argument is checked before any work: InputError naming the field ("DIR",
    "--solvers", "--tol", "--max-iterations", "--repeats", "--out", "--workers", "--scheduler").
    """
    solvers = check_solvers(solvers)
    caps = _caps(max_iterations, solvers)
    out = Path(DEFAULT_OUT if out is None else out)
    _check_settings(tol, repeats)
    cluster.check_cluster(scheduler, workers)
    repeats = int(repeats)
    files = problem_files(directory)
    jobs = {
        f"fclib-{index}-{solver}": Job(str(path.resolve()), solver, float(tol), caps[solver], repeats)
        for index, path in enumerate(files)
        for solver in solvers
    }

    made = make_folders(str(out))  # InputError for an --out that is there and is not a folder
    with held(str(out), "--out", made):  # one bench at a time writes a folder; a second is refused
        rows = {}
        with cluster.connect(scheduler, workers) as client:
            before = client.run(_machine, on_error="ignore")
            for key, result in cluster.run_tasks(client, run_job, jobs.items(), progress, "fclib bench"):
                rows[key] = _failed_row(jobs[key], result) if isinstance(result, BaseException) else result
            after = client.run(_machine, on_error="ignore")

        table = pd.DataFrame([rows[key] for key in jobs], columns=list(COLUMNS))  # jobs' order: problems, solvers
        table = table.astype({"contacts": "Int64", "iterations": "Int64", "converged": bool})
        settings = dict(directory=str(directory), tol=float(tol), caps=caps, repeats=repeats)
        return _write(table, solvers, out, settings, _machine_line(before, after))


# ----------------------------------------------------------------------------- the files


def _write(table, solvers, out, settings, machine) -> Bench:
    """results.csv, results.md and profile.png of ``table`` into the folder ``out``; on failure
    the files this call wrote are removed."""
    paths = Bench(table, out / "results.csv", out / "results.md", out / "profile.png", out)
    written = []
    try:
        with atomic_path(str(paths.csv)) as temporary:
            table.to_csv(temporary, index=False)
        written.append(str(paths.csv))
        with atomic_path(str(paths.markdown)) as temporary:
            Path(temporary).write_text(markdown(table, solvers, settings, machine), encoding="utf-8")
        written.append(str(paths.markdown))
        times, solved = _matrices(table, solvers)
        taus, fractions = performance_profile(times, solved, solvers)
        title = f"Performance profile: {len(times)} FCLIB problems, tol {settings['tol']:g}"
        figure = profile_figure(taus, fractions, title)
        with atomic_path(str(paths.profile_png)) as temporary:
            figure.savefig(temporary, format="png", dpi=DPI)
        written.append(str(paths.profile_png))
    except BaseException:
        undo_written(written)
        raise
    return paths


def _matrices(table, solvers):
    """(times (P, S) [s], solved (P, S)) of the table, problems in the table's order."""
    problems = list(dict.fromkeys(table["problem"]))

    def grid(column):
        return table.pivot(index="problem", columns="solver", values=column).reindex(index=problems, columns=solvers)

    return grid("seconds").to_numpy(dtype=np.float64), grid("converged").fillna(False).to_numpy(dtype=bool)


def _cell(value, column) -> str:
    """A table value as Markdown: blank when missing, errors and times to 3 figures."""
    if column == "converged":
        return "yes" if value else "**no**"
    if pd.isna(value):
        return ""
    if column == "error":
        return f"{value:.2e}"
    if column == "seconds":
        return f"{value:.3g}"
    return str(value).replace("|", "\\|")


def markdown(table: Any, solvers: Sequence[str], settings: Mapping[str, Any], machine: str) -> str:
    """results.md: the settings, the table (COLUMNS), solved counts and total times per solver,
    and the ``machine`` line."""
    caps = ", ".join(f"{solver} {settings['caps'][solver]}" for solver in solvers)
    lines = [
        f"# FCLIB benchmark: {', '.join(solvers)}",
        "",
        f"Problems: every file of `{settings['directory']}`, each solved from r = 0 to tol = {settings['tol']:g} "
        f"on the normalized natural-map error (`natural_map_error`, recomputed from r); iteration caps: {caps}. "
        f"seconds: the best of {settings['repeats']} timed solve{'s' if settings['repeats'] != 1 else ''} [s], "
        f"after an untimed one (Numba compile or cache load).",
        "",
        "| " + " | ".join(COLUMNS) + " |",
        "|" + "---|" * len(COLUMNS),
    ]
    for row in table.itertuples(index=False):
        lines.append("| " + " | ".join(_cell(getattr(row, column), column) for column in COLUMNS) + " |")
    problems = table["problem"].nunique()
    summary = []
    for solver in solvers:
        rows = table[table["solver"] == solver]
        summary.append(
            f"{solver} {int(rows['converged'].sum())} of {problems} solved, "
            f"{rows['seconds'].sum(skipna=True):.3g} s in all"
        )
    lines += ["", "Per solver: " + "; ".join(summary) + ".", "", machine, ""]
    return "\n".join(lines)


def _machine_line(before, after) -> str:
    """One sentence on the machines of the workers (``client.run(_machine)`` before and after
    the jobs: {worker address: dict})."""
    if not before:
        return "Machine: unknown (no worker answered)."
    hosts = {}
    for address, info in before.items():
        hosts.setdefault(info["host"], []).append((info, (after or {}).get(address)))
    parts = []
    for host, entries in hosts.items():
        info = entries[0][0]
        loads_after = [later["load"] for _, later in entries if later]
        load_after = f"{loads_after[0]:.2f}" if loads_after else "unknown"
        parts.append(
            f"{host} ({info['cores']} cores, NUMBA_NUM_THREADS {info['numba_threads']}, "
            f"{len(entries)} Dask worker{'s' if len(entries) != 1 else ''}), load average (1 min) "
            f"{info['load']:.2f} before the jobs, {load_after} after"
        )
    return "Machine: " + "; ".join(parts) + "."
