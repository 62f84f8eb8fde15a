"""What ``contactlab validate`` and ``contactlab fit`` write: tables, reports and plots.

* :func:`write_validation`: ``validation.csv`` (one row per measurement and method, the columns
  of :data:`contactlab.prediction.COLUMNS`), ``report.md`` (the medians, the best method, the
  rows) and ``plots/<measurement>.png``, the measured path and each method's overlaid: height
  against time, and the path seen from above (the first :data:`MAX_PATH_PLOTS` measurements).
* :func:`write_fit_plots`: ``plots/fit_<setting>.png``, the training error of every point a fit
  evaluated against each varied setting, one colour per method, the fitted values marked.

Every file is written atomically, and on a failure the files and folders written so far are
removed again (``record.undo_written``).
"""

from __future__ import annotations

import csv
import math
import os
import re
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from . import interrupts
from .record import atomic_path, make_folders, undo_written

if TYPE_CHECKING:
    from .measured import Measurement
    from .prediction import Validation
    from .scene import Scene

MAX_PATH_PLOTS = 24  # measurements whose paths are drawn (a data set of hundreds would be as many pictures)
COLOURS = {"penalty": "tab:red", "projection": "tab:green", "impulse": "tab:blue", "constraints": "tab:purple"}


def write_validation(
    result: Validation, scene: Scene, measurements: Sequence[Measurement], columns: Sequence[str]
) -> None:
    """Write ``result``'s table (``columns``), report and path plots into ``result.out``, filling its paths."""
    made = make_folders(os.path.join(result.out, "plots"))
    written: list[str] = []
    try:
        result.csv = os.path.join(result.out, "validation.csv")
        write_csv(result.csv, result.rows, columns)
        written.append(result.csv)
        for measurement in measurements[:MAX_PATH_PLOTS]:
            interrupts.check()  # Ctrl-C or SIGTERM: between pictures (it waited for the whole report)
            rows = [row for row in result.rows if row["measurement"] == measurement.name and "simulated" in row]
            path = os.path.join(result.out, "plots", f"{_file_name(measurement.name)}.png")
            _path_plot(path, measurement, rows)
            written.append(path)
            result.plots.append(path)
        interrupts.check()
        result.report = os.path.join(result.out, "report.md")
        _write_text(result.report, validation_markdown(result, scene, len(measurements)))
        written.append(result.report)
    except BaseException:
        undo_written(written, made)
        raise


def write_csv(path: str, rows: Sequence[Mapping[str, Any]], columns: Sequence[str]) -> None:
    """``rows`` (dicts) as CSV with ``columns``, written atomically."""
    with atomic_path(path) as temporary, open(temporary, "w", newline="", encoding="utf-8") as stream:
        writer = csv.writer(stream)
        writer.writerow(columns)
        for row in rows:
            writer.writerow([_cell(row.get(column)) for column in columns])


def _cell(value):
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    return f"{value:.6g}" if isinstance(value, float) else value


def _write_text(path, text):
    with atomic_path(path) as temporary, open(temporary, "w", encoding="utf-8") as stream:
        stream.write(text)


def _file_name(name):
    return re.sub(r"[^A-Za-z0-9_.-]", "_", name) or "measurement"


def table_text(rows: Sequence[Mapping[str, Any]]) -> str:
    """The rows as the plain table ``contactlab validate`` prints."""
    header = f"{'measurement':24s} {'method':12s} {'status':9s} {'position %':>10s} {'rotation °':>10s} {'final %':>8s}"
    lines = [header]
    for row in rows:
        lines.append(
            f"{row['measurement'][:24]:24s} {row['method']:12s} {row['status']:9s} "
            f"{_number(row['position_error_pct']):>10s} {_number(row['rotation_error_deg']):>10s} "
            f"{_number(row['final_position_error_pct']):>8s}"
        )
    return "\n".join(lines)


def _number(value):
    return "—" if value is None or not math.isfinite(value) else f"{value:.3g}"


def validation_markdown(result: Validation, scene: Scene, count: int) -> str:
    """report.md of a validation."""
    lines = [
        f"# {scene.name}: methods against {count} measurement{'s' if count != 1 else ''}",
        "",
        "Each method starts from every measurement's first sample and runs for its duration; the errors are "
        "averaged over the measured samples: the centre's distance as % of the body's size (the longest edge "
        "of its bounding box), the rotation between simulated and measured orientation in degrees, and the "
        "distance at the last sample as % of the size (docs/validate.md).",
        "",
        "## Medians over the measurements",
        "",
        "| method | position error % | rotation error ° | final position error % | runs that failed |",
        "|---|---|---|---|---|",
    ]
    for method, values in result.medians.items():
        lines.append(
            f"| {method} | {_number(values['position_error_pct'])} | {_number(values['rotation_error_deg'])} | "
            f"{_number(values['final_position_error_pct'])} | {values['failed']} |"
        )
    if result.best is not None:
        lines += ["", f"Best predictor here: **{result.best}** (the lowest median position error)."]
    lines += [
        "",
        "## Every measurement",
        "",
        "| measurement | method | status | position % | rotation ° | final % | velocities |",
        "|---|---|---|---|---|---|---|",
    ]
    for row in result.rows:
        lines.append(
            f"| {row['measurement']} | {row['method']} | {row['status']} | {_number(row['position_error_pct'])} | "
            f"{_number(row['rotation_error_deg'])} | {_number(row['final_position_error_pct'])} | "
            f"{row.get('velocities') or ''} |"
        )
    if result.plots:
        more = f" (the first {MAX_PATH_PLOTS})" if count > MAX_PATH_PLOTS else ""
        lines += ["", f"## Paths{more}", ""]
        lines += [f"![{os.path.basename(path)}](plots/{os.path.basename(path)})" for path in result.plots]
    return "\n".join(lines) + "\n"


def _figure(columns=1):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt, *plt.subplots(1, columns, figsize=(5.0 * columns, 4.0))


def _save(plt, figure, path):
    figure.tight_layout()
    with atomic_path(path) as temporary:
        figure.savefig(temporary, dpi=90, format="png")
    plt.close(figure)


def _path_plot(path: str, measurement: Measurement, rows: Sequence[Mapping[str, Any]]) -> None:
    """Height against time and the path from above: the measurement's dots, each method's line."""
    plt, figure, (height, above) = _figure(2)
    t = measurement.time - measurement.time[0]
    for b in range(measurement.position.shape[1]):
        label = "measured" if b == 0 else None
        height.plot(t, measurement.position[:, b, 2], "k.", markersize=3, label=label)
        above.plot(measurement.position[:, b, 0], measurement.position[:, b, 1], "k.", markersize=3, label=label)
        for row in rows:
            simulated, colour = row["simulated"][:, b], COLOURS.get(row["method"])
            label = row["method"] if b == 0 else None
            height.plot(t, simulated[:, 2], color=colour, label=label)
            above.plot(simulated[:, 0], simulated[:, 1], color=colour, label=label)
    height.set(xlabel="time (s)", ylabel="height z (m)", title=measurement.name)
    above.set(xlabel="x (m)", ylabel="y (m)", title="seen from above")
    above.set_aspect("equal", adjustable="datalim")
    height.legend(fontsize=8)
    _save(plt, figure, path)


def write_fit_plots(
    folder: str,
    paths: Sequence[str],
    evaluated: Mapping[str, Sequence[tuple[Sequence[float], float]]],
    fitted: Mapping[str, Sequence[float]],
) -> list[str]:
    """``folder/fit_<setting>.png`` for each varied setting of ``paths``: the training error (%)
    of every point a method's fit evaluated (``evaluated``: method -> [(values, error)]) against
    that setting, the fitted value (``fitted``: method -> values) marked; returns the files."""
    written = []
    for k, setting in enumerate(paths):
        interrupts.check()  # Ctrl-C or SIGTERM: between pictures
        plt, figure, axes = _figure()
        for method, points in evaluated.items():
            finite = [(values[k], error) for values, error in points if math.isfinite(error)]
            if finite:
                x, y = np.array(finite).T
                axes.plot(x, y, "o", color=COLOURS.get(method), alpha=0.4, markersize=4, label=method)
            if method in fitted:
                axes.axvline(fitted[method][k], color=COLOURS.get(method), linestyle="--", linewidth=1)
        axes.set(xlabel=setting, ylabel="median position error, training (%)", title=f"fit over {setting}")
        axes.legend(fontsize=8)
        path = os.path.join(folder, f"fit_{_file_name(setting)}.png")
        _save(plt, figure, path)
        written.append(path)
    return written
