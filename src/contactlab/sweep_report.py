"""The report of a sweep (contactlab.sweep): ``report.html`` and PNG plots, per scene.

* ``<scene>-pareto.png``: error against cost, one colour per method, every cell a point and
  the Pareto front (no other cell both cheaper and more accurate) as a black line. Cost is
  the run's wall time without compiling or loading kernels [s] (:func:`cost`: the first cell of
  each kind on each worker compiles, and counted so it looked the dearest); error the largest
  relative closed-form error where the scene has closed-form checks (contactlab.closed_form),
  else the deepest penetration [mm].
* ``<scene>-convergence.png`` (where ``simulation.dt`` is an axis): that error against dt on
  log-log axes, one line per method and per setting of the other axes, the observed order of
  convergence — the slope of a least-squares line through log error against log dt — in its
  legend, or, for a series that stalls (its finest refinements of dt no longer reduce the
  error: local orders below STALL_ORDER), "stalls from dt = …" and no order.
* ``<scene>-iterations.png`` (where an axis ends in ``.iterations``): sweeps per step and the
  largest solver residual against the iteration limit, one line per method.

All written atomically into the sweep's folder, beside ``results.parquet``.
"""

from __future__ import annotations

import html
import math
import os
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike

from .plots import STYLES, new_figure, save_figures
from .record import atomic_path

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from .study import Study


METHOD_COLOURS = {"penalty": "tab:blue", "projection": "tab:orange", "impulse": "tab:green", "constraints": "tab:red"}
METHOD_MARKERS = {"penalty": "o", "projection": "s", "impulse": "^", "constraints": "v"}  # coinciding runs show
DT_AXIS = "simulation.dt"
STALL_ORDER = 0.5  # a local order of convergence below this: refining dt no longer reduces the error


def accuracy(table: pd.DataFrame) -> tuple[str, pd.Series]:
    """(name of the error, a Series of it) for the rows of one scene: the closed-form error
    when any cell has one, else the deepest penetration [mm]."""
    if "closed_form_error" in table and table["closed_form_error"].notna().any():
        return "largest relative closed-form error", table["closed_form_error"].astype(float)
    if "max_penetration_mm" in table:
        return "max penetration (mm)", table["max_penetration_mm"].astype(float)
    return "max penetration (mm)", pd.Series(np.nan, index=table.index)


def pareto_front(cost: ArrayLike, error: ArrayLike) -> list[int]:
    """Indices of the cells no other cell beats on both ``cost`` and ``error`` (n,), by cost."""
    order = np.lexsort((error, cost))
    front, best = [], math.inf
    for index in order:
        if np.isfinite(cost[index]) and np.isfinite(error[index]) and error[index] < best:
            front.append(int(index))
            best = error[index]
    return front


def _usable(dt, error):
    """The points (dt, error) a log-log fit can use (both finite and > 0), as float arrays by decreasing dt."""
    dt, error = np.asarray(dt, dtype=float), np.asarray(error, dtype=float)
    usable = np.isfinite(dt) & np.isfinite(error) & (dt > 0) & (error > 0)
    order = np.argsort(-dt[usable], kind="stable")
    return dt[usable][order], error[usable][order]


def stalled_from(dt: ArrayLike, error: ArrayLike) -> float | None:
    """The dt [s] from which refining the step stops paying: going down in dt, each refinement
    from there on has a local order log(e₁/e₂) / log(dt₁/dt₂) below STALL_ORDER (the error
    barely falls, or grows); None when the finest refinement still converges. A plateau the
    series leaves again at a finer dt is no stall."""
    dt, error = _usable(dt, error)
    stall = None
    for i in range(len(dt) - 2, -1, -1):  # the finest pair first
        if dt[i + 1] == dt[i]:
            continue
        if np.log(error[i] / error[i + 1]) >= STALL_ORDER * np.log(dt[i] / dt[i + 1]):
            break
        stall = float(dt[i])
    return stall


def observed_order(dt: ArrayLike, error: ArrayLike) -> float | None:
    """The slope of log(error) against log(dt) by least squares; None under two usable points,
    and None for a series that stalls (stalled_from): no order describes it."""
    dt, error = _usable(dt, error)
    if len(dt) < 2 or len(np.unique(dt)) < 2 or stalled_from(dt, error) is not None:
        return None
    return float(np.polyfit(np.log(dt), np.log(error), 1)[0])


def convergence_words(dt: ArrayLike, error: ArrayLike) -> str:
    """What a convergence plot's legend says of one series: "order 1.98", "stalls from dt = 0.002 s",
    or "" (too few points)."""
    stall = stalled_from(dt, error)
    if stall is not None:
        return f"stalls from dt = {stall:g} s"
    order = observed_order(dt, error)
    return f"order {order:.2f}" if order is not None else ""


def _ok(table):
    return table[table["status"] == "ok"] if len(table) else table


def _finite(x, y):
    """The points of (x, y) with both finite, as float arrays."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    keep = np.isfinite(x) & np.isfinite(y)
    return x[keep], y[keep]


def cost(rows: pd.DataFrame) -> pd.Series:
    """Each cell's cost [s]: its run's wall time less the time it spent compiling or loading
    kernels (``compile_seconds``; rows of an older contactlab have none: their wall time)."""
    compiling = rows["compile_seconds"].astype(float).fillna(0.0) if "compile_seconds" in rows else 0.0
    return (rows["wall_seconds"].astype(float) - compiling).clip(lower=0.0)


def _pareto_figure(scene, rows):
    label, error = accuracy(rows)
    costs = cost(rows)
    figure, (ax,) = new_figure(f"{scene}: error against cost")
    for method, group in rows.groupby("method", sort=False):
        points = _finite(costs[group.index], error[group.index])
        unmeasured = len(group) - len(points[0])  # no finite error: a check never reached
        shown = f"{method} ({unmeasured} of {len(group)} cells without a finite error)" if unmeasured else method
        ax.scatter(*points, label=shown, s=24, color=METHOD_COLOURS.get(method), marker=METHOD_MARKERS.get(method, "o"))
    cost_values = costs.to_numpy()
    front = pareto_front(cost_values, error.to_numpy())
    if front:
        on_front = (cost_values[front], error.to_numpy()[front])
        ax.plot(*on_front, color="black", drawstyle="steps-post", lw=1, label="Pareto front")
    _log_axes(ax, cost_values, error.to_numpy())
    ax.set_xlabel("wall time of the run, compiling left out (s)")
    ax.set_ylabel(label)
    ax.legend(loc="best", fontsize="small")
    return figure


def _convergence_figure(scene, rows, axes):
    label, error = accuracy(rows)
    figure, (ax,) = new_figure(f"{scene}: convergence in dt")
    others = [axis for axis in axes if axis != DT_AXIS and axis in rows and rows[axis].nunique() > 1]
    styles = {}
    for (method, *setting), group in rows.groupby(["method", *others], sort=False, dropna=False):
        group = group.sort_values(DT_AXIS)
        words = convergence_words(group[DT_AXIS], error[group.index])
        shown = ", ".join(f"{axis.split('.')[-1]} = {value}" for axis, value in zip(others, setting))
        name = f"{method}{f' ({shown})' if shown else ''}" + (f": {words}" if words else "")
        style = styles.setdefault(tuple(setting), STYLES[len(styles) % len(STYLES)])
        ax.plot(
            *_finite(group[DT_AXIS], error[group.index]),
            label=name,
            linestyle=style,
            color=METHOD_COLOURS.get(method),
            marker=METHOD_MARKERS.get(method, "o"),
            markerfacecolor="none",
        )
    _log_axes(ax, rows[DT_AXIS].astype(float).to_numpy(), error.to_numpy())
    ax.set_xlabel("dt (s)")
    ax.set_ylabel(label)
    ax.legend(loc="best", fontsize="small")
    return figure


def _iterations_figure(scene, rows, axis):
    figure, (top, bottom) = new_figure(f"{scene}: solver against {axis}", rows=2)
    for method, group in rows.groupby("method", sort=False):
        group = group.sort_values(axis)
        look = {"color": METHOD_COLOURS.get(method), "marker": METHOD_MARKERS.get(method, "o"), "label": method}
        top.plot(group[axis], group["mean_solver_iterations"], **look)
        bottom.plot(group[axis], group["max_solver_residual"].astype(float), **look)
    top.set_ylabel("sweeps per step")
    top.legend(loc="best", fontsize="small")
    bottom.set_xlabel(axis)
    bottom.set_ylabel("largest residual")
    residual = rows["max_solver_residual"].astype(float).to_numpy()
    if np.any(residual > 0):
        bottom.set_yscale("log")
    return figure


def _log_axes(ax, x, y):
    """Log scales on the axes whose finite values (of the points drawn) are all > 0."""
    x, y = _finite(x, y)
    for values, scale in ((x, ax.set_xscale), (y, ax.set_yscale)):
        if values.size and np.all(values > 0):
            scale("log")


def figures(study: Study, table: pd.DataFrame) -> dict[str, Figure]:
    """name -> matplotlib Figure of every plot the study's table supports (see above)."""
    result = {}
    ok = _ok(table)
    for scene, rows in ok.groupby("scene", sort=False):
        if "wall_seconds" in rows and rows["wall_seconds"].notna().any():
            result[f"{scene}-pareto"] = _pareto_figure(scene, rows)
        if DT_AXIS in rows and rows[DT_AXIS].nunique() >= 2:
            result[f"{scene}-convergence"] = _convergence_figure(scene, rows, study.axes)
        for axis in study.axes:
            if axis.endswith(".iterations") and axis in rows and rows[axis].nunique() >= 2:
                result[f"{scene}-iterations-{axis.split('.')[1]}"] = _iterations_figure(scene, rows, axis)
    return result


def write_report(study: Study, table: pd.DataFrame, out: str) -> dict[str, str]:
    """The plots and ``report.html`` of ``study``'s ``table`` into ``out``; name -> path."""
    paths = save_figures(figures(study, table), os.path.join(out, "plots"))
    path = os.path.join(out, "report.html")
    with atomic_path(path) as temporary, open(temporary, "w", encoding="utf-8") as stream:
        stream.write(_html(study, table, paths, out))
    return {**paths, "report": path}


def _html(study, table, plots, out):
    counts = table["status"].value_counts().to_dict() if len(table) else {}
    status = ", ".join(f"{count} {name}" for name, count in counts.items())
    shown = table.drop(
        columns=[c for c in ("key", "closed_form_checks", "trajectory", "contactlab_version") if c in table]
    )
    images = "\n".join(
        f'<figure><img src="{html.escape(os.path.relpath(path, out))}" alt="{html.escape(name)}">'
        f"<figcaption>{html.escape(name)}</figcaption></figure>"
        for name, path in plots.items()
    )
    failed = table[table["status"] != "ok"] if len(table) else table
    failures = "".join(
        f"<li><code>{html.escape(str(row['scene']))}</code> {html.escape(str(row['method']))}: "
        f"{html.escape(str(row['status']))} — {html.escape(str(row['message']))}</li>"
        for _, row in failed.iterrows()
    )
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{html.escape(study.name)} — contactlab sweep</title>
<style>body{{font-family:sans-serif;margin:2em}} table{{border-collapse:collapse;font-size:small}}
td,th{{border:1px solid #ccc;padding:2px 6px}} figure{{display:inline-block;margin:0 1em 1em 0}}
img{{max-width:640px}}</style></head><body>
<h1>Sweep {html.escape(study.name)}</h1>
<p>{html.escape(study.description)}</p>
<p>{len(table)} cells ({html.escape(status)}); axes: {html.escape(", ".join(study.axes) or "none")}.
The table: <a href="results.parquet">results.parquet</a>, <a href="results.csv">results.csv</a>.</p>
{f"<h2>Cells that did not finish</h2><ul>{failures}</ul>" if failures else ""}
<h2>Plots</h2>
{images or "<p>No plot: the study has no finished cell with a cost.</p>"}
<h2>Cells</h2>
{shown.to_html(index=False, na_rep="–", float_format=lambda v: f"{v:.4g}", escape=True)}
</body></html>
"""
