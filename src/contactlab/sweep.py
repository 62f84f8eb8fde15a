"""Sweeps: every cell of a study (contactlab.study) run on a Dask cluster, one row per cell.

    from contactlab import sweep
    table = sweep.run("examples/studies/ball_dt.toml")          # here, or a local cluster where it pays
    table = sweep.run(study, scheduler="tcp://10.0.0.5:8786")    # an existing one

Cells go to the cluster through :mod:`contactlab.cluster`; each runs in a worker process on
one thread (``simulate(..., threads=1)``: the cluster's parallelism is the cells); with no
cluster asked for, a study of less work than a local cluster repays runs in this process
(``cluster.LOCAL_CLUSTER_PAYS_FROM``). As each
cell finishes, its row is written to ``OUT/cells/<key>.parquet`` (atomically), so an
interrupted sweep keeps every cell it finished and a rerun of the study skips them: the key
hashes the cell's scene text, method, settings, what it records and the contactlab version
(a changed scene file or a new contactlab runs again). A cell that diverges or raises is
recorded with its status and one line of message, and the sweep goes on; a cell whose
worker dies is run again by another worker (Dask's doing). At the end the rows of the study's
cells, in the study's order, are written to ``OUT/results.parquet`` and ``OUT/results.csv``,
and ``OUT/report.html`` with its plots (contactlab.sweep_report). A cell gives the same
numbers wherever it runs, bar its timings and its worker. The columns are in docs/sweep.md.
"""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

from . import __version__, cluster, interrupts
from .compare import TIMINGS
from .errors import InputError, SimulationDiverged
from .folder_lock import held
from .record import atomic_path, make_folders, remove_empty, replaced, stamps
from .study import Study, load_study, toml_value

if TYPE_CHECKING:
    import pandas as pd
    from distributed import Client


# what differs from one run of a cell to the next
TIMING_COLUMNS = (*TIMINGS, "compile_seconds", "cell_seconds", "worker")


def run(
    study: Study | str | os.PathLike[str],
    out: str | os.PathLike[str] | None = None,
    *,
    client: Client | None = None,
    scheduler: str | None = None,
    workers: int | None = None,
    progress: bool = False,
    log: Callable[[str], object] | None = None,
) -> pd.DataFrame:
    """Run every cell of ``study`` (a Study or the path of a study file) not done already in
    ``out`` (default ``out/<study name>-sweep``) on ``client``, or on a cluster from
    :func:`contactlab.cluster.connect` (``scheduler``: an address; ``workers``: local worker
    processes; neither: this process for a study of less than ``cluster.LOCAL_CLUSTER_PAYS_FROM``
    [s] of cells at its first cell's pace, else a local cluster); returns the table
    (pandas.DataFrame, one row per cell, in the study's order).
    ``log``: a function given one line of news (the dashboard's address, cells skipped)."""
    import pandas as pd

    study = study if isinstance(study, Study) else load_study(study)
    if client is None:
        cluster.check_cluster(scheduler, workers)  # a malformed address fails before anything runs
    out = os.fspath(out) if out is not None else os.path.join("out", f"{study.name}-sweep")
    cells_folder = os.path.join(out, "cells")
    made = make_folders(cells_folder)
    with held(out, "--out", made):  # one sweep at a time writes a folder (two computed the same cells twice)
        trajectories = {}  # with record = "trajectory": each cell's file as it was before the sweep
        try:
            if study.record == "trajectory":
                made += make_folders(os.path.join(out, "trajectories"))
            say = log or (lambda line: None)
            done = _finished_rows(cells_folder, study.cells, say)
            todo = [cell for cell in study.cells if cell.key not in done]
            counts = f"{len(study.cells)} cells: {len(study.cells) - len(todo)} done already, {len(todo)} to run"
            if not todo:
                say(counts)
            else:
                jobs = _jobs(todo, study, out)
                trajectories = stamps(job["trajectory"] for _, job in jobs if job["trajectory"])
                if client is not None:
                    _run_jobs(client, jobs, cells_folder, progress, say, counts)
                elif scheduler is None and workers is None:  # no cluster asked for: one only where it pays
                    say(counts)
                    rest = _run_here_while_small(jobs, cells_folder, say)
                    if rest:
                        with cluster.connect() as connected:
                            _run_jobs(connected, rest, cells_folder, progress, say, f"{len(rest)} cells to spread")
                else:
                    with cluster.connect(scheduler, workers) as connected:  # the counts once it is reached
                        _run_jobs(connected, jobs, cells_folder, progress, say, counts)
        except BaseException:
            if replaced(trajectories):  # the workers wrote trajectories (a stopped cell's, up to then)
                interrupts.note_written(os.path.join(out, "trajectories"))
            remove_empty(made)  # nothing finished: no folder left (finished cells stay)
            raise
        table = pd.DataFrame([done.get(cell.key) or _read_row(cells_folder, cell.key) for cell in study.cells])
        table = table.reindex(columns=_columns(study, table))
        _write_table(table, out)
        from .sweep_report import write_report

        write_report(study, table, out)
        return table


def _run_here_while_small(jobs, cells_folder, say):
    """With no cluster asked for, run the first of ``jobs`` (key, job) in this process; if the
    others would take less than ``cluster.LOCAL_CLUSTER_PAYS_FROM`` [s] in series at its pace (its
    stepping: the seconds it spent compiling left out), run them here too, saying so. Returns the
    jobs left for a local cluster (none, or all but the first)."""
    key, job = jobs[0]
    if len(jobs) == 1:
        say("1 cell to run: it runs here (a local cluster would only add the seconds it takes to start)")
    row = run_cell(job)
    _write_row(cells_folder, key, row)
    rest = jobs[1:]
    pace = max(0.0, float(row.get("cell_seconds") or 0.0) - float(row.get("compile_seconds") or 0.0))
    if not rest or pace * len(rest) >= cluster.LOCAL_CLUSTER_PAYS_FROM:
        return rest
    say(
        f"the first cell ran in {pace:.2g} s: the {len(rest)} others (about {pace * len(rest):.2g} s) run here too "
        f"(a local cluster repays its start from about {cluster.LOCAL_CLUSTER_PAYS_FROM:g} s of cells)"
    )
    for key, job in rest:
        _write_row(cells_folder, key, run_cell(job))
    return []


def _jobs(cells, study, out):
    return [(cell.key, _job(cell, study, out)) for cell in cells]


def _job(cell, study, out):
    """What a worker needs to run ``cell``: plain data, so it pickles anywhere."""
    return {
        "key": cell.key,
        "scene": cell.scene,
        "method": cell.method,
        "overrides": cell.overrides(),
        "settings": [[path, _column_value(value)] for path, value in cell.settings],
        "trajectory": (
            os.path.abspath(os.path.join(out, "trajectories", f"{cell.key}.h5"))
            if study.record == "trajectory"
            else None
        ),
    }


def _run_jobs(client, jobs, cells_folder, progress, say, counts):
    say(counts)
    say(f"Dask dashboard: {cluster.dashboard(client)}")
    settings = {key: job for key, job in jobs}
    for key, row in cluster.run_tasks(client, run_cell, jobs, progress=progress, description="cells"):
        if isinstance(row, BaseException):  # the cell's workers kept dying, or a bug escaped
            row = _failed_row(settings[key], "error", f"{type(row).__name__}: {_one_line(row)}")
        _write_row(cells_folder, key, row)


def run_cell(job: Mapping[str, Any]) -> dict[str, Any]:
    """One cell, on a worker: load its scene with its settings, simulate, measure. Returns its
    row; never raises for the run's own failure (status "diverged" or "error")."""
    from . import peers
    from .closed_form import checks as closed_form_checks
    from .compare import metrics
    from .scene import load_scene

    started = time.perf_counter()
    try:
        scene = load_scene(job["scene"], job["overrides"])
        if job["method"] in peers.PEERS:  # the scene in a peer engine (contactlab.peers)
            run = peers.simulate(
                scene.model,
                job["method"],
                scene.dt,
                scene.duration,
                trajectory=job["trajectory"],
                scene_name=scene.name,
            )
        else:  # the compiled loop wherever it serves, short cells included: compiled once, cached for every worker
            run = scene.simulate(threads=1, trajectory=job["trajectory"])
    except peers.Inexpressible as gap:
        return _failed_row(job, "not run", gap.sentence, started)
    except SimulationDiverged as error:
        return _failed_row(job, "diverged", str(error), started, diverged_at=error.time)
    except Exception as error:  # InputError included: a study checked cannot fail that way
        return _failed_row(job, "error", f"{type(error).__name__}: {_one_line(error)}", started)
    row = _identity(job)
    row.update(status="ok", message="", integrator=run.summary["integrator"], dt_s=scene.dt, duration_s=scene.duration)
    measured = metrics(scene.model, run.arrays, run.summary)
    if measured["momentum_drift_Ns"] == "n/a":
        measured["momentum_drift_Ns"] = None  # one type per column
    row.update(measured)
    found = closed_form_checks(scene.name, scene.model, run.arrays)
    relative = [check.relative_error for check in found if check.relative_error is not None]
    reached = [error for error in relative if not math.isnan(error)]  # nan: the run never got there
    row["closed_form_error"] = max(reached) if reached else (math.inf if relative else None)
    row["closed_form_unreached"] = len(relative) - len(reached) if relative else None

    row["closed_form_checks"] = json.dumps([check.as_record() for check in found]) if found else None
    row["diverged_at_s"] = None
    row["trajectory"] = job["trajectory"]
    row["stepping"] = run.summary["stepping"]
    row["compile_seconds"] = run.summary.get("compile_seconds", 0.0)  # a worker's first cell of a kind
    row["cell_seconds"] = time.perf_counter() - started
    return row


def _identity(job):
    row = {"key": job["key"], "scene": os.path.splitext(os.path.basename(job["scene"]))[0], "method": job["method"]}
    row.update({path: value for path, value in job["settings"]})
    row.update(worker=cluster.worker_address(), contactlab_version=__version__)
    return row


def _failed_row(job, status, message, started=None, diverged_at=None):
    row = _identity(job)
    row.update(
        status=status,
        message=message,
        diverged_at_s=diverged_at,
        cell_seconds=time.perf_counter() - started if started is not None else None,
    )
    return row


def _column_value(value):
    """A setting as a table cell: numbers, booleans and text as they are, lists and tables as TOML."""
    return value if isinstance(value, (bool, int, float, str)) else toml_value(value)


def _one_line(error):
    text = " ".join(str(error).split())
    return text if len(text) <= 300 else text[:297] + "..."


# ---- the table on disk -----------------------------------------------------------------------------


def _write_row(folder, key, row):
    import pandas as pd

    path = os.path.join(folder, f"{key}.parquet")
    with atomic_path(path) as temporary:
        pd.DataFrame([row]).to_parquet(temporary, index=False)
    interrupts.note_written(path, removed=True)  # an interrupted sweep names the folder of the cells
    if folder not in interrupts.written_paths():  # it kept, not every cell's file
        interrupts.note_written(folder)


def _finished_rows(folder, cells, say) -> dict[str, dict]:
    """key -> row of each of ``cells`` whose file an earlier sweep left in ``folder``. A file
    that cannot be read (cut short by a crash or a full disk, damaged since) does not count:
    its cell runs again and overwrites it, and ``say`` is told so in one line."""
    names = set(os.listdir(folder))
    rows, damaged = {}, []
    for cell in cells:
        name = f"{cell.key}.parquet"
        if name not in names:
            continue
        try:
            rows[cell.key] = _row(os.path.join(folder, name))
        except Exception as error:  # pyarrow's errors, an empty table: not a finished cell
            damaged.append((name, _one_line(error)))
    if len(damaged) == 1:
        name, reason = damaged[0]
        say(f"{os.path.join(folder, name)} could not be read ({reason}); that cell runs again")
    elif damaged:
        some = "; ".join(f"{name}: {reason}" for name, reason in damaged[:2])
        more = f"; and {len(damaged) - 2} more" if len(damaged) > 2 else ""
        say(f"{len(damaged)} cell files in {folder} could not be read ({some}{more}); those cells run again")
    return rows


def _row(path) -> dict:
    """The row of the cell file ``path`` (pyarrow's error when it cannot be read)."""
    import pandas as pd

    return pd.read_parquet(path).iloc[0].to_dict()


def _read_row(folder, key) -> dict:
    path = os.path.join(folder, f"{key}.parquet")
    try:
        return _row(path)
    except Exception as error:  # a file damaged since: that cell runs again next time
        os.unlink(path)
        raise InputError(
            "OUT",
            f"{path} could not be read ({_one_line(error)}); it was removed, so run the study again to redo that cell",
        ) from None


def _columns(study, table):
    """Identity, the study's axes, then the rest in the order the rows give them."""
    first = ["key", "scene", "method", *study.axes, "status", "message"]
    return [*first, *[column for column in table.columns if column not in first]]


def _write_table(table, out):
    with atomic_path(os.path.join(out, "results.parquet")) as temporary:
        table.to_parquet(temporary, index=False)
    with atomic_path(os.path.join(out, "results.csv")) as temporary:
        table.to_csv(temporary, index=False)
