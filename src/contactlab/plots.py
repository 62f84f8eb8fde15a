"""Plots of one run, or of several runs side by side: energy, penetration, contacts, solver.

    paths = write_plots(run.arrays, "out/ball/plots", title="bouncing_ball — impulse")
    paths = write_comparison_plots({"impulse": arrays_a, "penalty": arrays_b}, "out/cmp/plots")

Both write ``energy.png``, ``penetration.png``, ``contacts.png`` and ``residual.png``
(800 × 450 px, 100 dpi) and return ``{"energy": path, ...}``. One run's energy plot shows its
kinetic, potential, elastic and total energy; a comparison's shows the total of each run (one
line per method). The other three plots draw one line per run either way. matplotlib's Agg
canvas only (no pyplot, no display); every file is written atomically, and a call that fails
leaves none of its files behind.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from . import interrupts
from .methods import AVAILABLE
from .record import atomic_path, make_folders, undo_written

if TYPE_CHECKING:
    from matplotlib.axes import Axes


PLOTS = ("energy", "penetration", "contacts", "residual")
DPI = 100
SIZE_INCHES = (8.0, 4.5)  # 800 × 450 px at DPI
LOG_SPAN = 100.0  # residuals spanning more than this factor get a log axis
ENERGY_TERMS = (
    ("energy_kinetic", "kinetic"),
    ("energy_potential", "potential"),
    ("energy_elastic", "elastic (contact springs)"),
)
RESIDUAL_LABEL = "solver residual (method units)"


@dataclass
class Line:
    """One series of a plot: ``values`` against ``time`` [s]."""

    label: str
    time: np.ndarray
    values: np.ndarray
    color: str
    style: str = "-"
    width: float = 1.4


def total_energy(arrays: Mapping[str, Any]) -> np.ndarray:
    """Kinetic + potential + elastic energy of each sample [J]."""
    return arrays["energy_kinetic"] + arrays["energy_potential"] + arrays["energy_elastic"]


STYLES = ("-", "--", "-.", ":")  # one per run, so runs that coincide still show


def _look(index, label):
    """(colour, line style) of a run: fixed per method name, so a method looks the same in every
    comparison (whichever others ran); by position for other labels."""
    if label in AVAILABLE:
        index = AVAILABLE.index(label)
    return f"C{index % 10}", STYLES[index % len(STYLES)]


def _series(runs, key, scale=1.0):
    """One Line per run: ``arrays[key] * scale``."""
    return [
        Line(str(label), arrays["time"], np.asarray(arrays[key], dtype=float) * scale, *_look(index, label))
        for index, (label, arrays) in enumerate(runs.items())
    ]


def _energy_lines(runs, components):
    if not components:
        return [
            Line(str(label), arrays["time"], total_energy(arrays), *_look(index, label))
            for index, (label, arrays) in enumerate(runs.items())
        ]
    (arrays,) = runs.values()
    lines = [
        Line(name, arrays["time"], np.asarray(arrays[key], dtype=float), f"C{index}")
        for index, (key, name) in enumerate(ENERGY_TERMS)
    ]
    return lines + [Line("total", arrays["time"], total_energy(arrays), "black", width=2.0)]


def _residual_lines(runs):
    """Residual lines, each labelled "(no solver)" when its run never iterated; and whether the
    positive residuals span more than LOG_SPAN (then the axis is logarithmic)."""
    lines = _series(runs, "solver_residual")
    for line, arrays in zip(lines, runs.values()):
        if not np.any(np.asarray(arrays["solver_iterations"]) > 0):
            line.label += " (no solver)"
    positive = np.concatenate([line.values[line.values > 0] for line in lines] + [np.zeros(0)])
    log = positive.size > 0 and positive.max() > LOG_SPAN * positive.min()
    if log:
        for line in lines:
            line.values = np.where(line.values > 0, line.values, np.nan)
    return lines, log


def draw(ax: Axes, lines: Iterable[Any], ylabel: str, *, log: bool = False, legend: bool = True) -> None:
    """Draw ``lines`` on ``ax`` with a labelled time axis [s], ``ylabel``, grid and legend:
    the one function every plot goes through."""
    for line in lines:
        ax.plot(line.time, line.values, label=line.label, color=line.color, linewidth=line.width, linestyle=line.style)
    if log:
        ax.set_yscale("log")
    ax.set_xlabel("time (s)")
    ax.set_ylabel(ylabel)
    ax.grid(True, which="major", alpha=0.4)
    if legend and lines:
        ax.legend(loc="best", fontsize="small")


def new_figure(title: str | None, rows: int = 1) -> tuple[Figure, np.ndarray]:
    """A Figure of ``rows`` axes stacked, sharing x (an array of them), titled ``title`` (none: untitled);
    every plot of the package starts from it."""
    figure = Figure(figsize=SIZE_INCHES, dpi=DPI, layout="constrained")
    FigureCanvasAgg(figure)
    axes = figure.subplots(rows, 1, sharex=True, squeeze=False)[:, 0]
    if title:
        figure.suptitle(title)
    return figure, axes


def build_figures(
    runs: Mapping[str, Mapping[str, Any]], *, components: bool = False, title: str | None = None
) -> dict[str, Figure]:
    """The four Figures (name → matplotlib Figure, names as PLOTS) of ``runs``, a dict
    {label: trajectory arrays}. ``components``: the energy plot shows kinetic, potential,
    elastic and total of the one run instead of one total per run."""
    if not runs:
        raise ValueError("no runs to plot")
    if components and len(runs) != 1:
        raise ValueError("energy components are drawn for a single run only")
    comparing = not components
    prefix = f"{title}: " if title else ""
    figures = {}

    figure, (ax,) = new_figure(f"{prefix}{'total energy' if comparing else 'energy'}")
    draw(ax, _energy_lines(runs, components), "total energy (J)" if comparing else "energy (J)")
    figures["energy"] = figure

    figure, (ax,) = new_figure(f"{prefix}deepest penetration")
    draw(ax, _series(runs, "max_penetration", 1000.0), "max penetration (mm)")
    figures["penetration"] = figure

    figure, (ax,) = new_figure(f"{prefix}contacts")
    draw(ax, _series(runs, "contact_count"), "contacts in the step")
    figures["contacts"] = figure

    note = " — units differ by method" if comparing and len(runs) > 1 else ""
    figure, (top, bottom) = new_figure(f"{prefix}contact solver{note}", rows=2)
    lines, log = _residual_lines(runs)
    draw(top, lines, RESIDUAL_LABEL, log=log)
    top.set_xlabel("")
    draw(bottom, _series(runs, "solver_iterations"), "iterations", legend=False)
    figures["residual"] = figure
    return figures


def save_figures(figures: Mapping[str, Figure], directory: str) -> dict[str, str]:
    """Write each Figure as ``directory/<name>.png``; on failure remove what this call wrote
    (and the folders it created)."""
    made, written = make_folders(os.fspath(directory)), {}
    try:
        for name, figure in figures.items():
            interrupts.check()  # Ctrl-C or SIGTERM: between pictures
            path = os.path.join(directory, f"{name}.png")
            with atomic_path(path) as temporary:
                figure.savefig(temporary, format="png", dpi=DPI)
            written[name] = path
    except BaseException:
        undo_written(written.values(), made)
        raise
    return written


def write_plots(arrays: Mapping[str, Any], directory: str, *, title: str | None = None) -> dict[str, str]:
    """energy.png, penetration.png, contacts.png, residual.png of one run (its trajectory
    arrays, docs/trajectory.md) into ``directory`` (created if needed); returns
    {"energy": path, "penetration": path, "contacts": path, "residual": path}.

    energy: kinetic, potential, elastic and total [J]; penetration: max_penetration [mm];
    contacts: contact_count; residual: solver_residual [method units] (log axis when it spans
    decades) above solver_iterations. All against time [s]."""
    label = "run" if title is None else str(title)
    return save_figures(build_figures({label: arrays}, components=True, title=title), directory)


def write_comparison_plots(
    runs: Mapping[str, Mapping[str, Any]], directory: str, *, title: str | None = None
) -> dict[str, str]:
    """``runs``: {method name: trajectory arrays}. The same four pictures with one line per
    method (the energy plot: each method's total energy [J]); returns {"energy": path, ...}."""
    return save_figures(build_figures(dict(runs), components=False, title=title), directory)
