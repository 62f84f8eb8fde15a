"""The methods side by side on one scene: runs, metrics, plots, videos and a report.

    result = compare("box_pyramid", ["impulse", "penalty"], "out/pyramid", duration=1.0)
    result.rows[0]["max_penetration_mm"]          # one dict per method, as in comparison.csv
    result.report_html                            # open it in a browser (no network needed)

Every method runs the same scene (with ``simulation.method`` set to it, so the scene's
``[method.NAME]`` options apply); the scene is loaded for every method before anything is
written, so a bad scene stops the comparison with an InputError and no output. Each run streams
its trajectory to disk as it goes (contactlab.store), and its video is drawn from it; the runs
go one after another, or, where it pays, to a Dask cluster through contactlab.cluster, the path
of contactlab.sweep (:func:`run_method` is one job). The metrics and plots read the
trajectories back. A method that blows up (SimulationDiverged) is reported as such, its trajectory up to then
kept, and the others go on. Into ``out`` (default ``out/<scene>-compare/``):

    <method>/trajectory.h5, summary.json      as `contactlab run` writes them
    <method>/plots/*.png                       contactlab.plots.write_plots
    <method>/video.mp4, video.gif, still.png   contactlab.render.render (video=True)
    plots/*.png                                one line per method (write_comparison_plots)
    comparison.csv, report.md, report.html

Every file is written atomically, and if the comparison fails (other than a method's own
divergence) the files and folders it created are removed again. The metrics are defined in
docs/compare.md.
"""

import csv
import html
import io
import math
import os
import urllib.parse
import warnings
from dataclasses import dataclass, field

import numpy as np

from . import cluster
from .errors import InputError, SimulationDiverged
from .methods import AVAILABLE
from .plots import PLOTS, total_energy, write_comparison_plots, write_plots
from .record import TRAJECTORY, atomic_path, make_folders, remove_empty, undo_written, write_summary
from .scene import load_scene
from .simulation import Run, simulate
from .store import open_trajectory

PARALLEL_WORK = 200_000     # steps × (bodies + particles) of all runs from which they go to a local cluster
TIMINGS = ("steps_per_second", "steps_per_second_median", "steps_per_second_low", "steps_per_second_high",
           "wall_seconds")     # the row's keys that differ from one run of the same computation to the next
TINY_ENERGY = 1e-9          # J: an energy scale below this (times max(1, |E(0)|)) gives no relative drift


@dataclass
class Comparison:
    """What :func:`compare` produced.

    rows: one dict per method, keys as the header of comparison.csv (units in the names, see
    docs/compare.md; None where a value is missing, "n/a" where it does not apply);
    out: the output folder; report_html, report_md, csv: paths of the three reports;
    summary_text: the plain-words paragraph of the report; skipped: methods left out because
    they do not support the scene (name → why); checks: method → its closed-form checks
    (contactlab.closed_form.Check); files: method → {name: path} of what it wrote.
    """
    rows: list
    out: str
    report_html: str
    report_md: str
    csv: str
    summary_text: str
    scene: str = ""
    skipped: dict = field(default_factory=dict)
    checks: dict = field(default_factory=dict)
    files: dict = field(default_factory=dict)

    def _repr_html_(self):              # Jupyter (contactlab.notebook): the table and the report's link
        from .notebook import comparison_html
        return comparison_html(self)


@dataclass
class _Outcome:
    """One method's run: ``run`` (contactlab.simulation.Run) or ``failure`` (the divergence message)."""
    method: str
    scene: object
    run: object = None
    failure: str = None
    failed_run: object = None    # the Run up to the blow-up (its trajectory streamed to disk)
    failed_at: float = None      # s, simulated time of the blow-up when the message says it
    warnings: list = field(default_factory=list)
    media: dict = field(default_factory=dict)        # the video, GIF and still drawn of it
    checks: list = field(default_factory=list)
    files: dict = field(default_factory=dict)
    row: dict = field(default_factory=dict)


# ---- choosing and running the methods ----------------------------------------------------------

def _method_names(methods):
    """(names, named): the methods to compare, and whether the caller named them."""
    if methods is None:
        return list(AVAILABLE), False
    if isinstance(methods, str):
        methods = methods.split(",")
    names = []
    for name in methods:
        name = str(name).strip()
        if name not in AVAILABLE:
            raise InputError("--methods", f"unknown method {name!r}; expected some of: {', '.join(AVAILABLE)}")
        if name not in names:
            names.append(name)
    if not names:
        raise InputError("--methods", f"expected at least one of: {', '.join(AVAILABLE)}")
    return names, True


def supports(method, scene) -> bool:
    """Whether ``method`` is meant to run ``scene``: every method supports every scene today.
    The hook for a method that cannot (besides this, a method whose set-up rejects the scene
    with an InputError is left out when the methods were not named)."""
    return True


def run_method(job) -> dict:
    """One method's run, here or on a Dask worker: load the scene for the method, simulate it
    streaming its trajectory to ``job["trajectory"]``, and (``job["video"]``: fps) render it
    beside that. Returns plain data: ``summary``, ``warnings`` [(category, message)], and
    ``failure``, ``failed_at`` [s] for a run a health check stopped, or ``media`` (name -> path)
    for a rendered one; ``input_error`` [field, message] for a scene the method refuses."""
    from .render import render
    result = {"warnings": []}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            scene = load_scene(job["scene"], job["overrides"])
            run = simulate(scene.model, scene.method, scene.dt, scene.duration,
                           scene.method_options.get(scene.method, {}), scene.integrator,
                           progress=job["progress"], scene_name=scene.name, allow_divergence=job["allow_divergence"],
                           trajectory=job["trajectory"])
            result["summary"] = run.summary
        except SimulationDiverged as error:
            result.update(summary=error.run.summary, failure=str(error), failed_at=error.time)
        except InputError as error:
            return {"input_error": [error.field, error.message], "warnings": []}
    result["summary"]["source"] = scene.origin(job["overrides"])     # how to load the scene again (the viewer)
    result["warnings"] = [(warning.category, str(warning.message)) for warning in caught]
    if job["video"] is not None and "failure" not in result:
        result["media"] = render(open_trajectory(job["trajectory"]), os.path.dirname(job["trajectory"]),
                                 fps=job["video"], title=f"{scene.name} — {scene.method}", progress=job["progress"])
    return result


def _parallel(workers, scheduler, scenes, video) -> bool:
    """Whether the methods' runs go to a Dask cluster (contactlab.cluster): on an existing one
    (``scheduler``) always; on a local one when ``workers`` asks for more than one, or, left to
    choose (None), when the machine has an idle core for a second run and the work is worth
    starting a cluster — videos to draw, or at least PARALLEL_WORK steps × bodies and particles."""
    if scheduler is not None:
        return True
    if workers is not None:
        return workers > 1
    if len(scenes) < 2:
        return False
    work = sum(max(1, round(scene.duration / scene.dt)) * (scene.model.body_count + scene.model.particle_count)
               for scene in scenes.values())
    return (video or work >= PARALLEL_WORK) and cluster.default_workers() > 1


def _run_all(scene_source, names, named, overrides, progress, allow_divergence, out, created, video,
             workers=None, scheduler=None):
    """Load the scene for every method, then run it with each, streaming each trajectory to
    out/<method>/trajectory.h5 and rendering it (``video``: fps, or None), one after another
    or on a Dask cluster (:func:`_parallel`); folders and files noted in ``created``.
    Returns (outcomes, skipped {method: why}, out)."""
    scenes = {name: load_scene(scene_source, [*overrides, f"simulation.method={name}"]) for name in names}
    out = os.fspath(out) if out is not None else os.path.join("out", f"{next(iter(scenes.values())).name}-compare")
    skipped, jobs = {}, []
    for name, scene in scenes.items():
        if not supports(name, scene):
            if named:
                raise InputError("--methods", f"{name} does not support the scene {scene.name}")
            skipped[name] = "not supported"
            continue
        created.folder(os.path.join(out, name))
        jobs.append((name, {**scene.origin([*overrides, f"simulation.method={name}"]),
                            "trajectory": os.path.abspath(os.path.join(out, name, TRAJECTORY)), "video": video,
                            "allow_divergence": allow_divergence, "progress": progress}))
    if _parallel(workers, scheduler, scenes, video is not None):
        with cluster.connect(scheduler, workers) as client:
            for job in jobs:
                job[1]["progress"] = False               # the bar is over the methods
            results = dict(cluster.run_tasks(client, run_method, jobs, progress, "methods"))
    else:
        results = {name: run_method(job) for name, job in jobs}
    outcomes, first_error = [], None
    for name, job in jobs:
        result = results[name]
        if isinstance(result, BaseException):
            raise result
        for category, message in result["warnings"]:
            warnings.warn(message, category, stacklevel=2)
        if "input_error" in result:
            error = InputError(*result["input_error"])
            if named:
                raise error
            skipped[name] = str(error)
            first_error = first_error or error
            remove_empty([os.path.join(out, name)])     # its folder, empty: the method left nothing
            continue
        trajectory = os.path.join(out, name, TRAJECTORY)
        created.add(trajectory, *result.get("media", {}).values())
        run = Run(None, open_trajectory(trajectory), result["summary"])
        outcome = _Outcome(name, scenes[name], warnings=[message for _, message in result["warnings"]],
                           media=result.get("media", {}))
        if "failure" in result:
            outcome.failure, outcome.failed_at, outcome.failed_run = result["failure"], result["failed_at"], run
        else:
            outcome.run = run
        outcomes.append(outcome)
    if not outcomes:
        raise first_error or InputError("--methods", "no method supports this scene")
    return outcomes, skipped, out


# ---- metrics -----------------------------------------------------------------------------------

def energy_scale(model, arrays) -> float:
    """The energy [J] a drift is measured against: the larger of (a) the most energy the run
    ever held above the lowest potential energy it reached, max E − min V, and (b) the
    potential energy of the initial configuration above its own lowest mass,
    Σ m_i |g| (h_i − min h), h the height against gravity (bodies' centres and particles)."""
    held = float(total_energy(arrays).max() - np.min(arrays["energy_potential"]))
    g = np.asarray(model.gravity, dtype=float)
    masses = np.concatenate([model.body_mass, model.particle_mass])
    if not masses.size or not np.any(g):
        return held
    positions = np.concatenate([arrays["body_position"][0], arrays["particle_position"][0]])
    heights = -(positions @ g) / np.linalg.norm(g)
    stored = float(np.linalg.norm(g) * masses @ (heights - heights.min()))
    return max(held, stored)


def momentum_drift(model, arrays):
    """‖P(T) − P(0) − M g T‖ [N·s], P = Σ m v over bodies and particles, M g T the impulse of
    gravity over the run. None when the scene has static obstacles or pinned particles: their
    forces are external, so momentum is not conserved and the number means nothing."""
    if model.obstacle_count or (model.particle_pinned is not None and np.any(model.particle_pinned)):
        return None
    momentum = model.body_mass @ arrays["body_velocity"] + model.particle_mass @ arrays["particle_velocity"]
    elapsed = float(arrays["time"][-1] - arrays["time"][0])
    mass = float(np.sum(model.body_mass) + np.sum(model.particle_mass))
    return float(np.linalg.norm(momentum[-1] - momentum[0] - mass * np.asarray(model.gravity) * elapsed))


def _rates(summary):
    """steps/s: the whole run's, and as repeated measurements the median over its ~0.1 s
    windows of stepping and their quartiles (summary.json's ``steps_per_second_spread``; None
    for a run too short to time)."""
    spread = summary.get("steps_per_second_spread")
    if not spread:
        return {"steps_per_second": summary["steps_per_second"], "steps_per_second_median": None,
                "steps_per_second_low": None, "steps_per_second_high": None}
    return {"steps_per_second": summary["steps_per_second"], "steps_per_second_median": spread["median"],
            "steps_per_second_low": spread["low"], "steps_per_second_high": spread["high"]}


def metrics(model, arrays, summary) -> dict:
    """The numbers of one run (keys as in comparison.csv; units in docs/compare.md)."""
    energy = total_energy(arrays)
    drift = float(energy[-1] - energy[0])
    scale = energy_scale(model, arrays)
    momentum = momentum_drift(model, arrays)
    iterations = summary["solver"]["max_iterations"]
    return {
        "steps": summary["steps"],
        **_rates(summary),
        "wall_seconds": summary["wall_seconds"],
        "max_contacts": summary["max_contacts"],
        "max_penetration_mm": summary["max_penetration"] * 1000.0,
        "mean_penetration_mm": float(np.mean(arrays["max_penetration"])) * 1000.0,
        "energy_drift_J": drift,
        "energy_drift_relative": drift / scale if scale > TINY_ENERGY * max(1.0, abs(energy[0])) else None,
        "momentum_drift_Ns": "n/a" if momentum is None else momentum,
        "max_solver_iterations": iterations,
        "mean_solver_iterations": summary["solver"]["mean_iterations"],
        "max_solver_residual": summary["solver"]["max_residual"] if iterations > 0 else None,
    }


def _closed_form_checks(scene_name, model, arrays):
    try:
        from . import closed_form
    except ModuleNotFoundError as error:        # not there yet: no checks
        if error.name != f"{__package__}.closed_form":
            raise
        return []
    return closed_form.checks(scene_name, model, arrays)


def expectation_verdict(checks) -> str:
    """The scene's stated expectations on one run, in a word and a count: "pass (2 of 2)",
    "FAIL (1 of 2)" — met of those with a verdict —, or "n/a" when the scene states none."""
    judged = [check.passed for check in checks if check.passed is not None]
    if not judged:
        return "n/a"
    return f"{'pass' if all(judged) else 'FAIL'} ({sum(judged)} of {len(judged)})"


def _check_column(check):
    return f"{check.quantity} error ({check.unit})"


def _fill_rows(outcomes):
    """Each outcome's row: identity, status, metrics, one error column per check quantity."""
    for outcome in outcomes:
        scene = outcome.scene
        row = {"method": outcome.method,
               "status": "ok" if outcome.run else _blew_up(outcome),
               "integrator": scene.integrator, "dt_s": scene.dt}
        if outcome.run:
            row.update(metrics(scene.model, outcome.run.arrays, outcome.run.summary))
            outcome.checks = _closed_form_checks(scene.name, scene.model, outcome.run.arrays)
            row["expectations"] = expectation_verdict(outcome.checks)
        outcome.row = row
    check_columns = []
    for outcome in outcomes:
        for check in outcome.checks:
            if _check_column(check) not in check_columns:
                check_columns.append(_check_column(check))
    for outcome in outcomes:
        errors = {_check_column(check): check.error for check in outcome.checks}
        outcome.row = {key: outcome.row.get(key, errors.get(key)) for key in [*ROW_KEYS, *check_columns]}


def _blew_up(outcome):
    return f"blew up at t = {outcome.failed_at:.4g} s" if outcome.failed_at is not None else "blew up"


# ---- the table: cells built once, written as CSV, Markdown and HTML ------------------------------

def _number(format_spec):
    return lambda value: format(value, format_spec)


# (row key, report heading, how the report shows a value); the CSV header is the keys
COLUMNS = (
    ("method", "method", str),
    ("status", "status", str),
    ("expectations", "expectations met", str),
    ("integrator", "integrator", str),
    ("dt_s", "dt (ms)", lambda value: f"{value * 1000:.4g}"),
    ("steps", "steps", str),
    ("steps_per_second", "steps/s", _number(",.0f")),
    ("steps_per_second_median", "steps/s (median)", _number(",.0f")),
    ("steps_per_second_low", "steps/s, 1st quartile", _number(",.0f")),
    ("steps_per_second_high", "steps/s, 3rd quartile", _number(",.0f")),
    ("wall_seconds", "wall (s)", _number(".3g")),
    ("max_contacts", "max contacts", str),
    ("max_penetration_mm", "max penetration (mm)", _number(".3g")),
    ("mean_penetration_mm", "mean penetration (mm)", _number(".3g")),
    ("energy_drift_J", "energy drift (J)", _number("+.3g")),
    ("energy_drift_relative", "energy drift (% of scale)", lambda value: f"{value * 100:+.3g}"),
    ("momentum_drift_Ns", "momentum drift (N·s)", _number(".3g")),
    ("max_solver_iterations", "max iterations", str),
    ("mean_solver_iterations", "sweeps per step", _number(".3g")),
    ("max_solver_residual", "max residual (method units)", _number(".3g")),
)
ROW_KEYS = tuple(key for key, _, _ in COLUMNS)

# what each column means, printed in the report itself so it reads without docs/compare.md
MEANINGS = {
    "status": "ok, or blew up at t = … s (a health check stopped the run)",
    "expectations": "how many of the scene's stated expectations (the checks below the table: a closed form, "
                    "a structure that must stand, nothing inside an obstacle) the run met; n/a: it states none",
    "dt_s": "the time step",
    "steps_per_second": "the stepping rate over the whole run (compiling and the first step left out)",
    "steps_per_second_median": "the same rate measured over every ~0.1 s window of the run: the median window, "
                               "then the middle half of the windows (1st to 3rd quartile); two methods whose "
                               "middle halves overlap are equally fast within the machine's noise",
    "wall_seconds": "the whole run: stepping, compiling and recording",
    "max_contacts": "the most contacts in one step",
    "max_penetration_mm": "the deepest overlap of any two things at any sample",
    "mean_penetration_mm": "the mean over the samples of each sample's deepest overlap",
    "energy_drift_J": "total energy (kinetic + potential + elastic in contact springs) at the end minus at the start",
    "energy_drift_relative": "that drift as a share of the run's energy scale (see the notes)",
    "momentum_drift_Ns": "‖P(T) − P(0) − M g T‖: a conservation check where nothing static acts (n/a otherwise)",
    "max_solver_iterations": "the most sweeps the contact solver made in one step (0: it has none)",
    "mean_solver_iterations": "the solver's sweeps per step, over every step: what the run paid",
    "max_solver_residual": "the solver's largest last change, in the method's own unit (see the notes)",
}


def _meanings():
    """(heading, meaning) of each column the report's table has a meaning for, in table order."""
    headings = {key: heading for key, heading, _ in COLUMNS}
    shown = []
    for key, meaning in MEANINGS.items():
        if key == "steps_per_second_median":
            shown.append(("steps/s (median), 1st and 3rd quartile", meaning))
        else:
            shown.append((headings[key], meaning))
    shown.append(("<check> (unit, expected …), within ± …",
                  "a closed-form or stated expectation: measured (measured − expected) and pass or FAIL"))
    return shown


def _show(value, show):
    """A value as the report shows it: "–" when missing or not finite, "n/a" as it is."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "–"
    return value if isinstance(value, str) else show(value)


def _check_heading(quantity, unit, checks):
    expected = {check.expected for check in checks}
    shown = f", expected {next(iter(expected)):.4g}" if len(expected) == 1 else ""
    tolerances = {check.tolerance for check in checks}
    allowed = (f", within ± {next(iter(tolerances)):.2g}" if len(tolerances) == 1 and None not in tolerances
               else "")
    return f"{quantity} ({unit}{shown}){allowed}"


def _check_cell(check):
    if check is None:
        return "–"
    word = {True: " pass", False: " FAIL", None: ""}[check.passed]
    if not math.isfinite(check.measured):
        return "not reached" + word
    return f"{check.measured:.4g} ({check.error:+.2g}){word}"


def _table(outcomes):
    """(headings, rows of cell texts) of the report table: the CSV's columns, with each check
    shown as "measured (error)" under a heading that carries its expected value."""
    headings = [heading for _, heading, _ in COLUMNS]
    cells = [[_show(outcome.row.get(key), show) for key, _, show in COLUMNS] for outcome in outcomes]
    quantities = {}
    for outcome in outcomes:
        for check in outcome.checks:
            quantities.setdefault((check.quantity, check.unit), []).append(check)
    for (quantity, unit), checks in quantities.items():
        headings.append(_check_heading(quantity, unit, checks))
        for outcome, row in zip(outcomes, cells):
            found = [check for check in outcome.checks if (check.quantity, check.unit) == (quantity, unit)]
            row.append(_check_cell(found[0] if found else None))
    return headings, cells


def _csv_value(value):
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return ""
    return str(value)


def _csv_text(rows):
    stream = io.StringIO()
    writer = csv.writer(stream, lineterminator="\n")
    writer.writerow(list(rows[0]))
    for row in rows:
        writer.writerow([_csv_value(value) for value in row.values()])
    return stream.getvalue()


def _markdown_table(headings, cells):
    def line(texts):
        return "| " + " | ".join(text.replace("|", "\\|") for text in texts) + " |"
    return "\n".join([line(headings), "|" + "---|" * len(headings), *(line(row) for row in cells)])


def _html_table(headings, cells):
    head = "".join(f"<th>{html.escape(text)}</th>" for text in headings)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(text)}</td>" for text in row) + "</tr>" for row in cells)
    return f"<table>\n<thead><tr>{head}</tr></thead>\n<tbody>{body}</tbody>\n</table>"


# ---- words ------------------------------------------------------------------------------------

def _leaders(outcomes, value, lowest):
    """Methods sharing the best ``value`` (to the 3 significant digits the report shows)."""
    values = {outcome.method: value(outcome) for outcome in outcomes}
    best = min(values.values()) if lowest else max(values.values())
    return [name for name, v in values.items() if f"{v:.3g}" == f"{best:.3g}"], best


def _names(names):
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]


def _ranking(ran, labels, value, lowest, show):
    """"<best label>: <methods> (<value>); <worst label>: <methods> (<value>)", or, when all
    share the best value, that they do."""
    best, best_value = _leaders(ran, value, lowest)
    if len(ran) > 1 and len(best) == len(ran):
        return f"{labels[0]}: all the same ({show(best_value)})."
    worst, worst_value = _leaders(ran, value, not lowest)
    tail = f"; {labels[1]}: {_names(worst)} ({show(worst_value)})" if len(ran) > 1 else ""
    return f"{labels[0]}: {_names(best)} ({show(best_value)}){tail}."


def _alike(one, other):
    """Whether two runs' speeds are within noise: their middle halves (the quartiles of their
    ~0.1 s windows) overlap. Without a spread (a run too short to time) nothing is said."""
    lows = [o.row.get("steps_per_second_low") for o in (one, other)]
    highs = [o.row.get("steps_per_second_high") for o in (one, other)]
    if None in lows or None in highs:
        return False
    return lows[0] <= highs[1] and lows[1] <= highs[0]


def _speed_sentence(ran):
    """Who stepped fastest and slowest by the median rate, naming the methods whose speed is
    within noise of the fastest (their middle halves overlap), so a reordering between two
    runs of the same comparison is not read as a result."""
    def rate(outcome):
        median = outcome.row.get("steps_per_second_median")
        return outcome.row["steps_per_second"] if median is None else median
    ordered = sorted(ran, key=rate, reverse=True)
    fastest = ordered[0]
    noise = [o.method for o in ordered[1:] if _alike(fastest, o)]
    text = f"Fastest: {fastest.method} ({rate(fastest):,.0f} steps/s, median)"
    if noise and len(noise) == len(ordered) - 1:
        return text + f"; {_names(noise)} within noise of it (their middle halves overlap)."
    if noise:
        text += f"; {_names(noise)} within noise of it"
    slowest = ordered[-1]
    if len(ordered) > 1 and slowest.method not in noise:
        text += f"; slowest: {slowest.method} ({rate(slowest):,.0f} steps/s)"
    return text + "."


def _expectation_sentence(ran):
    """Which methods met the scene's stated expectations, and what each one that did not
    missed, with the number; empty when the scene states none."""
    judged = [o for o in ran if any(check.passed is not None for check in o.checks)]
    if not judged:
        return ""
    met = [o.method for o in judged if all(check.passed is not False for check in o.checks)]
    missed = []
    for outcome in judged:
        failed = [check for check in outcome.checks if check.passed is False]
        if failed:
            missed.append(f"{outcome.method} (" + "; ".join(
                (f"{check.quantity} {check.measured:.3g} {check.unit}" if math.isfinite(check.measured)
                 else f"{check.quantity} not reached")
                + f", expected {check.expected:.3g} ± {check.tolerance:.2g}" for check in failed) + ")")
    parts = []
    if met:
        parts.append(f"met by {_names(met)}")
    if missed:
        parts.append(f"missed by {_names(missed)}")
    return "The scene's stated expectations: " + "; ".join(parts) + "."


def _dissipative(model):
    """Whether the scene's contacts lose energy by design (restitution < 1 or friction > 0)."""
    used = np.concatenate([model.body_material, model.particle_material, model.obstacle_material]).astype(int)
    return bool(used.size and (np.any(model.material_restitution[used] < 1.0)
                               or np.any(model.material_friction[used] > 0.0)))


def _summary_text(scene, outcomes, skipped):
    """The plain-words paragraph: fastest, least penetration, best energy, failures."""
    ran = [outcome for outcome in outcomes if outcome.run]
    sentences = []
    if ran:
        duration = ran[0].run.arrays["time"][-1]
        sentences.append(f"{len(outcomes)} method{'s' if len(outcomes) > 1 else ''} on {scene.name} "
                         f"for {duration:.3g} s of simulated time.")
        sentences.append(_speed_sentence(ran))
        sentences.append(_ranking(ran, ("Least penetration", "deepest"), lambda o: o.row["max_penetration_mm"], True,
                                  lambda v: f"{v:.3g} mm"))
        sentences.append(_ranking(ran, ("Energy kept best", "worst"), lambda o: abs(o.row["energy_drift_J"]), True,
                                  lambda v: f"total energy changed by {v:.3g} J"))
        if _dissipative(scene.model):
            sentences.append("Restitution below 1 or friction makes this scene lose energy by design, "
                             "so part of every energy change is physical.")
        sentences.append(_expectation_sentence(ran))
    else:
        sentences.append(f"No method finished {scene.name}.")
    for outcome in outcomes:
        if outcome.failure:
            sentences.append(f"{outcome.method} {_blew_up(outcome)} ({outcome.scene.integrator}, "
                             f"dt = {outcome.scene.dt:g} s): it needs a smaller dt or a softer setting.")
    for name, why in skipped.items():
        sentences.append(f"{name} was left out: {why}.")
    return " ".join(sentence for sentence in sentences if sentence)


def _notes(outcomes):
    """Caveats worth printing under the table, as plain sentences."""
    notes = ["Energy drift is the total energy (kinetic + potential + elastic) at the end minus at "
             "the start; its % is of the run's energy scale: the larger of the most energy it held above "
             "the lowest potential energy it reached, and the initial potential energy above the lowest "
             "mass.",
             "Solver residuals are in each method's own unit (impulse, constraints: m/s of the last "
             "sweep; projection: m; penalty with backward Euler: relative linear residual), so compare "
             "them within a method, not across."]
    if any(outcome.row.get("momentum_drift_Ns") == "n/a" for outcome in outcomes):
        notes.append("Momentum drift is n/a: the scene has static obstacles (or pinned cloth), whose "
                     "forces change the momentum, so it is no conservation check here.")
    else:
        notes.append("Momentum drift ‖P(T) − P(0) − M g T‖ is a conservation check: no obstacles act on "
                     "this scene, so anything but rounding is an error of the method.")
    for group, largest in same_computation(outcomes):
        notes.append(f"{_names(group)} computed the same trajectory to within rounding (positions apart by "
                     f"{largest:.2g} m at most): at these settings they solve the same problem the same way, "
                     f"so their numbers are one result, not {len(group)} that agree (their speeds still differ).")
    for outcome in outcomes:
        notes += [f"{outcome.method}: warning: {text}" for text in outcome.warnings]
    return notes


SAME_WITHIN = 1e-9          # m (and unit quaternion components): trajectories this close are one computation


def same_computation(outcomes) -> list:
    """(method names, largest difference [m]) of each group of runs whose positions,
    orientations and particles agree within SAME_WITHIN at every sample: rounding, not physics."""
    ran = [outcome for outcome in outcomes if outcome.run is not None]
    series = {outcome.method: [np.asarray(outcome.run.arrays[name]) for name in
                               ("body_position", "body_orientation", "particle_position")] for outcome in ran}
    groups, placed = [], set()
    for index, outcome in enumerate(ran):
        if outcome.method in placed:
            continue
        group, largest = [outcome.method], 0.0
        for other in ran[index + 1:]:
            if other.method in placed:
                continue
            mine, theirs = series[outcome.method], series[other.method]
            if all(a.shape == b.shape for a, b in zip(mine, theirs)):
                apart = [float(np.max(np.abs(a - b))) if a.size else 0.0 for a, b in zip(mine, theirs)]
                if max(apart) <= SAME_WITHIN:
                    group.append(other.method)
                    largest = max(largest, apart[0], apart[2])       # positions [m]
        if len(group) > 1:
            placed.update(group)
            groups.append((group, largest))
    return groups


# ---- the reports ------------------------------------------------------------------------------

def _link(out, path):
    """``path`` relative to ``out``, with / separators, quoted for a URL."""
    return urllib.parse.quote(os.path.relpath(path, out).replace(os.sep, "/"))


def _check_lines(outcomes):
    """(quantity, unit, text) of each closed-form quantity: expected, then each method's measure."""
    quantities = {}
    for outcome in outcomes:
        for check in outcome.checks:
            quantities.setdefault((check.quantity, check.unit), []).append((outcome.method, check))
    lines = []
    for (quantity, unit), entries in quantities.items():
        parts = []
        for method, check in entries:
            relative = check.relative_error
            share = f", {relative * 100:.3g} %" if relative is not None and math.isfinite(relative) else ""
            measured = (f"{check.measured:.6g} (error {check.error:+.3g}{share})"
                        if math.isfinite(check.measured) else "not reached")
            word = {True: ": pass", False: ": FAIL", None: ""}[check.passed]
            parts.append(f"{method} {measured}{word}")
        first = entries[0][1]
        allowed = f" ± {first.tolerance:.3g}" if first.tolerance is not None else ""
        lines.append((quantity, unit, f"expected {first.expected:.6g}{allowed} — " + "; ".join(parts)))
    return lines


def _markdown(scene, outcomes, skipped, summary_text, table, plot_paths, out):
    files_lines = []
    for outcome in outcomes:
        if not outcome.run:
            files_lines.append(f"- **{outcome.method}**: {_blew_up(outcome)}: {outcome.failure}")
            continue
        links = [f"[{name}]({_link(out, path)})" for name, path in outcome.files.items()]
        files_lines.append(f"- **{outcome.method}**: " + " · ".join(links))
    checks = [f"- **{quantity}** ({unit}): {text}" for quantity, unit, text in _check_lines(outcomes)]
    text = [f"# {scene.name}: the methods compared", "",
            scene.description, "", summary_text, "",
            "## Numbers", "", _markdown_table(*table), "",
            "What the columns mean:", "", *(f"- **{heading}**: {meaning}" for heading, meaning in _meanings()), ""]
    if checks:
        text += ["## Expectations and closed-form checks", "", *checks, ""]
    text += ["## Files", "", *files_lines, "",
             "## Comparison plots", "",
             *(f"![{name}]({_link(out, path)})" for name, path in plot_paths.items()), "",
             "## Notes", "", *(f"- {note}" for note in _notes(outcomes)), ""]
    return "\n".join(text)


CSS = """
body { font-family: system-ui, -apple-system, "Segoe UI", sans-serif; margin: 1.5rem; color: #222; }
h1 { font-size: 1.5rem; margin-bottom: 0.2rem; }
.description { color: #555; margin-top: 0; }
.summary { background: #f4f6f8; border-left: 4px solid #4a7bb7; padding: 0.6rem 0.9rem; }
.videos { display: grid; grid-template-columns: repeat(auto-fit, minmax(280px, 1fr)); gap: 1rem; }
.card { margin: 0; border: 1px solid #ddd; border-radius: 6px; padding: 0.5rem; background: #fff; }
.card video, .card img { width: 100%; height: auto; display: block; background: #fafafa; }
.card figcaption { font-size: 0.9rem; margin-top: 0.4rem; }
.card .name { font-weight: 600; font-size: 1rem; }
.failed { min-height: 120px; display: flex; align-items: center; justify-content: center;
          background: #fdecea; color: #a4262c; font-weight: 600; border-radius: 4px; }
.scroll { overflow-x: auto; }
table { border-collapse: collapse; font-size: 0.85rem; margin: 0.5rem 0; }
th, td { border: 1px solid #ccc; padding: 0.25rem 0.45rem; text-align: right; }
td { white-space: nowrap; }
th { background: #eef1f4; }
td:first-child, td:nth-child(2), td:nth-child(3) { text-align: left; }
.plots { display: grid; grid-template-columns: repeat(auto-fit, minmax(420px, 1fr)); gap: 0.8rem; }
.plots img { width: 100%; height: auto; border: 1px solid #eee; }
details { margin: 0.6rem 0; } summary { cursor: pointer; font-weight: 600; }
.notes { font-size: 0.85rem; color: #444; }
"""

# Sets document.body.dataset.status to "ok" once every <img> has loaded and every <video> has
# data, or to "error: <sources>" for those that did not; a video that cannot play is replaced
# by the GIF inside it.
SCRIPT = """
(function () {
  var LIMIT = 5000;
  function imageState(img) {
    return new Promise(function (resolve) {
      function check() { resolve(img.complete && img.naturalWidth > 0 ? null : img.getAttribute('src')); }
      if (img.complete) { check(); return; }
      img.addEventListener('load', check);
      img.addEventListener('error', check);
      setTimeout(check, LIMIT);
    });
  }
  function videoState(video) {
    return new Promise(function (resolve) {
      var done = false;
      function finish(value) { if (!done) { done = true; resolve(value); } }
      function failed() {
        if (done) { return; }
        var fallback = video.querySelector('img');
        var source = video.querySelector('source');
        var src = source ? source.getAttribute('src') : video.getAttribute('src');
        if (!fallback) { finish(src); return; }
        var gif = fallback.cloneNode(true);
        video.replaceWith(gif);
        imageState(gif).then(finish);
      }
      if (video.readyState >= 1) { finish(null); return; }
      if (video.networkState === 3) { failed(); return; }
      video.addEventListener('loadedmetadata', function () { finish(null); });
      video.addEventListener('loadeddata', function () { finish(null); });
      var sources = video.querySelectorAll('source');
      (sources.length ? sources[sources.length - 1] : video).addEventListener('error', failed);
      setTimeout(function () { if (video.readyState >= 1) { finish(null); } else { failed(); } }, LIMIT);
    });
  }
  window.addEventListener('load', function () {
    var videos = Array.prototype.slice.call(document.querySelectorAll('video'));
    Promise.all(videos.map(videoState)).then(function (videoErrors) {
      var images = Array.prototype.slice.call(document.querySelectorAll('img')).filter(function (img) {
        return !img.closest('video');
      });
      return Promise.all(images.map(imageState)).then(function (imageErrors) {
        return videoErrors.concat(imageErrors);
      });
    }).then(function (errors) {
      var bad = errors.filter(Boolean);
      document.body.dataset.status = bad.length ? 'error: ' + bad.join(' ') : 'ok';
    });
  });
})();
"""


def _key_numbers(row):
    return (f"expectations {row['expectations']} · {row['steps_per_second']:,.0f} steps/s · "
            f"max penetration {row['max_penetration_mm']:.3g} mm · energy drift {row['energy_drift_J']:+.3g} J")


def _media(outcome, out):
    """The video of one method: MP4 with its GIF inside as the fallback, or the GIF or still alone."""
    files = outcome.files
    if "mp4" in files:
        poster = f' poster="{html.escape(_link(out, files["still"]))}"' if "still" in files else ""
        fallback = files.get("gif") or files.get("still")
        inner = f'<img src="{html.escape(_link(out, fallback))}" alt="{html.escape(outcome.method)}">' if fallback else ""
        return (f'<video controls autoplay muted loop playsinline preload="auto"{poster}>'
                f'<source src="{html.escape(_link(out, files["mp4"]))}" type="video/mp4">{inner}</video>')
    for name in ("gif", "still"):
        if name in files:
            return f'<img src="{html.escape(_link(out, files[name]))}" alt="{html.escape(outcome.method)}">'
    return ""


def _card(outcome, out):
    name = f'<span class="name">{html.escape(outcome.method)}</span>'
    if not outcome.run:
        return (f'<figure class="card"><div class="failed">{html.escape(_blew_up(outcome))}</div>'
                f'<figcaption>{name}<br>{html.escape(outcome.failure)}</figcaption></figure>')
    return (f'<figure class="card">{_media(outcome, out)}<figcaption>{name} '
            f'({html.escape(outcome.scene.integrator)}, dt = {outcome.scene.dt * 1000:.4g} ms)<br>'
            f'{html.escape(_key_numbers(outcome.row))}</figcaption></figure>')


def _images(paths, out):
    return "".join(f'<a href="{html.escape(_link(out, path))}"><img src="{html.escape(_link(out, path))}" '
                   f'alt="{html.escape(name)}"></a>' for name, path in paths.items())


def _method_details(outcome, out):
    if not outcome.run:
        return ""
    plots = {name: outcome.files[f"plot {name}"] for name in PLOTS if f"plot {name}" in outcome.files}
    links = " · ".join(f'<a href="{html.escape(_link(out, path))}">{html.escape(name)}</a>'
                       for name, path in outcome.files.items())
    return (f"<details><summary>{html.escape(outcome.method)}</summary>"
            f"<p>{links}</p><div class=\"plots\">{_images(plots, out)}</div></details>")


def _html(scene, outcomes, skipped, summary_text, table, plot_paths, out):
    check_items = "".join(f"<li><b>{html.escape(quantity)}</b> ({html.escape(unit)}): {html.escape(text)}</li>"
                          for quantity, unit, text in _check_lines(outcomes))
    title = f"{scene.name}: the methods compared"
    parts = [
        "<!doctype html>", '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>{html.escape(title)}</title><style>{CSS}</style></head>",
        '<body data-status="pending">',
        f"<h1>{html.escape(title)}</h1>",
        f'<p class="description">{html.escape(scene.description)}</p>',
        f'<p class="summary">{html.escape(summary_text)}</p>',
        '<section class="videos">' + "".join(_card(outcome, out) for outcome in outcomes) + "</section>",
        "<h2>Numbers</h2>", f'<div class="scroll">{_html_table(*table)}</div>',
        '<details class="notes"><summary>What the columns mean</summary><dl>'
        + "".join(f"<dt>{html.escape(heading)}</dt><dd>{html.escape(meaning)}</dd>" for heading, meaning in _meanings())
        + "</dl></details>",
    ]
    if check_items:
        parts += ["<h2>Expectations and closed-form checks</h2>", f"<ul>{check_items}</ul>"]
    parts += ["<h2>Comparison plots</h2>", f'<div class="plots">{_images(plot_paths, out)}</div>',
              "<h2>Each method</h2>", *(_method_details(outcome, out) for outcome in outcomes),
              '<h2>Notes</h2><ul class="notes">'
              + "".join(f"<li>{html.escape(note)}</li>" for note in _notes(outcomes)) + "</ul>",
              f"<script>{SCRIPT}</script>", "</body></html>", ""]
    return "\n".join(parts)


# ---- writing ----------------------------------------------------------------------------------

class _Created:
    """Files and folders one compare() call wrote, so a failure can remove them again."""

    def __init__(self):
        self.files, self.folders = [], []

    def folder(self, path):
        self.folders += make_folders(path)

    def add(self, *paths):
        self.files += paths

    def text(self, path, text):
        with atomic_path(path) as temporary:
            with open(temporary, "w", encoding="utf-8", newline="") as stream:
                stream.write(text)
        self.add(path)
        return path

    def remove(self):
        undo_written(self.files)                              # an interrupted compare says it wrote nothing
        for folder in self.folders:                           # what a stopped worker was writing
            for name in os.listdir(folder) if os.path.isdir(folder) else ():
                if name.startswith(".partial-"):
                    os.unlink(os.path.join(folder, name))
        remove_empty(self.folders)


def _video_fps(video, fps):
    """``fps`` checked (contactlab.render: InputError) before any run when ``video``, else None."""
    if not video:
        return None
    from .render import check_settings
    return check_settings(fps)[0]


def _write_method(outcome, out, created):
    """summary.json and plots of one run into out/<method>, beside the trajectory it streamed
    and the video drawn of it; a run that blew up gets its summary only."""
    directory = os.path.join(out, outcome.method)
    run = outcome.run or outcome.failed_run
    if run is None:
        return
    run.summary["trajectory"] = os.path.join(directory, TRAJECTORY)
    files = {"trajectory": run.summary["trajectory"], "summary": write_summary(directory, run.summary)}
    created.add(files["summary"])
    if outcome.run is not None:
        created.folder(os.path.join(directory, "plots"))
        title = f"{outcome.scene.name} — {outcome.method}"
        plots = write_plots(run.arrays, os.path.join(directory, "plots"), title=title)
        created.add(*plots.values())
        files.update({f"plot {name}": path for name, path in plots.items()})
        files = {**outcome.media, **files}
    outcome.files = files


def compare(scene_source, methods=None, out=None, *, overrides=(), duration=None, video=True,
            progress=False, fps=30, allow_divergence=False, workers=None, scheduler=None) -> Comparison:
    """Run ``scene_source`` (a built-in name or a .toml path) with each of ``methods`` and write
    the comparison into ``out`` (default ``out/<scene>-compare/``).

    methods: names (a list, or one comma-separated string); None: every method of
    contactlab.methods.AVAILABLE that supports the scene. overrides: "dotted.key=value"
    strings as the command line's --set; duration [s]: overrides simulation.duration;
    video: render each run (contactlab.render) at ``fps`` frames per second; progress: tqdm
    bars on stderr; allow_divergence: each run's (see ``simulate``); workers, scheduler: where the
    runs go — one after another here, or on a Dask cluster, local (``workers`` processes) or at
    the address ``scheduler`` (contactlab.cluster); None: a local cluster when it pays (see
    docs/compare.md). Raises InputError for a bad
    scene, an unknown method or bad options, before anything is written. A method that blows up
    (a failed health check) is reported, not raised.
    """
    names, named = _method_names(methods)
    overrides = [*overrides] + ([f"simulation.duration={duration}"] if duration is not None else [])
    video = _video_fps(video, fps)                   # a missing renderer or a bad fps fails before the runs
    created = _Created()
    try:
        outcomes, skipped, out = _run_all(scene_source, names, named, overrides, progress, allow_divergence,
                                          out, created, video, workers, scheduler)
        scene = outcomes[0].scene
        _fill_rows(outcomes)
        summary_text = _summary_text(scene, outcomes, skipped)
        for outcome in outcomes:
            _write_method(outcome, out, created)
        ran = {outcome.method: outcome.run.arrays for outcome in outcomes if outcome.run}
        plot_paths = {}
        if ran:
            created.folder(os.path.join(out, "plots"))
            plot_paths = write_comparison_plots(ran, os.path.join(out, "plots"), title=scene.name)
            created.add(*plot_paths.values())
        rows = [outcome.row for outcome in outcomes]
        table = _table(outcomes)
        csv_path = created.text(os.path.join(out, "comparison.csv"), _csv_text(rows))
        md_path = created.text(os.path.join(out, "report.md"),
                               _markdown(scene, outcomes, skipped, summary_text, table, plot_paths, out))
        html_path = created.text(os.path.join(out, "report.html"),
                                 _html(scene, outcomes, skipped, summary_text, table, plot_paths, out))
    except BaseException:
        created.remove()
        raise
    return Comparison(rows=rows, out=out, report_html=html_path, report_md=md_path, csv=csv_path,
                      summary_text=summary_text, scene=scene.name, skipped=skipped,
                      checks={outcome.method: outcome.checks for outcome in outcomes},
                      files={outcome.method: outcome.files for outcome in outcomes})
