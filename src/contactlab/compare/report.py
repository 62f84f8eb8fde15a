"""The comparison's report: the table's cells, the plain words, and the texts of
comparison.csv, report.md and report.html (docs/compare.md, "Reading the report").

Everything here turns the outcomes of contactlab.compare.run, their rows filled by
contactlab.compare.measures, into text; contactlab.compare.run writes it. The HTML page's
style and script are the package's files report.css and report.js, inlined so the page
works from disk with no network.
"""

from __future__ import annotations

import csv
import html
import io
import math
import os
import urllib.parse
from collections.abc import Mapping, Sequence
from importlib import resources
from typing import TYPE_CHECKING, Any

from ..plots import PLOTS
from .measures import ROW_KEYS, blew_up, dissipative, same_computation

if TYPE_CHECKING:
    from ..closed_form import Check
    from ..scene import Scene
    from .run import Outcome

# ---- the table: cells built once, written as CSV, Markdown and HTML ------------------------------


def _number(format_spec):
    return lambda value: format(value, format_spec)


# how the report shows each key of a row (measures.ROW_KEYS): its heading, and how a value reads
SHOWN = {
    "method": ("method", str),
    "status": ("status", str),
    "expectations": ("expectations met", str),
    "integrator": ("integrator", str),
    "dt_s": ("dt (ms)", lambda value: f"{value * 1000:.4g}"),
    "steps": ("steps", str),
    "steps_per_second": ("steps/s", _number(",.0f")),
    "steps_per_second_median": ("steps/s (median)", _number(",.0f")),
    "steps_per_second_low": ("steps/s, 1st quartile", _number(",.0f")),
    "steps_per_second_high": ("steps/s, 3rd quartile", _number(",.0f")),
    "wall_seconds": ("wall (s)", _number(".3g")),
    "max_contacts": ("max contacts", str),
    "max_penetration_mm": ("max penetration (mm)", _number(".3g")),
    "mean_penetration_mm": ("mean penetration (mm)", _number(".3g")),
    "energy_drift_J": ("energy drift (J)", _number("+.3g")),
    "energy_drift_relative": ("energy drift (% of scale)", lambda value: f"{value * 100:+.3g}"),
    "momentum_drift_Ns": ("momentum drift (N·s)", _number(".3g")),
    "max_solver_iterations": ("max iterations", str),
    "mean_solver_iterations": ("sweeps per step", _number(".3g")),
    "max_solver_residual": ("max residual (method units)", _number(".3g")),
}
COLUMNS = tuple((key, *SHOWN[key]) for key in ROW_KEYS)  # (row key, heading, show), the CSV's order

# what each column means, printed in the report itself so it reads without docs/compare.md
MEANINGS = {
    "status": "ok, or blew up at t = … s (a health check stopped the run), or for a peer engine "
    "not run: what of the scene it cannot express, and why",
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
    "max_solver_iterations": "the most sweeps the contact solver made in one step (0: it has none; "
    "–: a peer engine that does not report them)",
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
    shown.append(
        (
            "<check> (unit, expected …), within ± …",
            "a closed-form or stated expectation: measured (measured − expected) and pass or FAIL",
        )
    )
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
    allowed = f", within ± {next(iter(tolerances)):.2g}" if len(tolerances) == 1 and None not in tolerances else ""
    return f"{quantity} ({unit}{shown}){allowed}"


def _check_cell(check):
    if check is None:
        return "–"
    word = {True: " pass", False: " FAIL", None: ""}[check.passed]
    if not math.isfinite(check.measured):
        return "not reached" + word
    return f"{check.measured:.4g} ({check.error:+.2g}){word}"


def table_cells(outcomes: Sequence[Outcome]) -> tuple[list[str], list[list[str]]]:
    """(headings, rows of cell texts) of the report table: the CSV's columns, with each check
    shown as "measured (error)" under a heading that carries its expected value."""
    headings = [heading for _, heading, _ in COLUMNS]
    cells = [[_show(outcome.row.get(key), show) for key, _, show in COLUMNS] for outcome in outcomes]
    quantities: dict[tuple[str, str], list[Check]] = {}
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
    """A CSV cell: empty for a missing value (None, or not finite), the value as text else."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return ""
    return str(value)


def csv_text(rows: Sequence[Mapping[str, Any]]) -> str:
    """comparison.csv: a header of the rows' keys, then one line per method."""
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


ENERGY_NOISE_SHARE = 0.02  # two energy drifts closer than this share of the larger are not ranked ...
ENERGY_NOISE_FLOOR = 1e-6  # J ... nor those closer than this (rounding: drifts near 0)
PENETRATION_NOISE_MM = 1e-3  # mm: overlaps this shallow are none (rounding), and are not ranked


def _same_shown(one, other):
    """Whether two values read the same to the 3 significant digits the report shows."""
    return f"{one:.3g}" == f"{other:.3g}"


def _energy_alike(one: float, other: float) -> bool:
    """Whether two energy drifts' magnitudes [J] are within noise of each other: apart by at
    most ENERGY_NOISE_SHARE of the larger, or by at most ENERGY_NOISE_FLOOR."""
    one, other = abs(one), abs(other)
    return abs(one - other) <= max(ENERGY_NOISE_SHARE * max(one, other), ENERGY_NOISE_FLOOR)


def _penetration_alike(one: float, other: float) -> bool:
    """Whether two deepest overlaps [mm] are alike: the same to the digits shown, or both within
    PENETRATION_NOISE_MM (projection's 9.4e-8 mm and impulse's 3.4e-7 mm are both none)."""
    return _same_shown(one, other) or max(one, other) <= PENETRATION_NOISE_MM


def _group(values, leader, alike):
    """The names whose value is ``alike`` the ``leader`` value, in their order."""
    return [name for name, v in values.items() if alike(v, leader)]


def _names(names):
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]


def _span(values, names, show):
    """``show`` of the values of ``names``: one value, or "<lowest> to <highest>" when they read differently."""
    low, high = min(values[name] for name in names), max(values[name] for name in names)
    return show(low) if show(low) == show(high) else f"{show(low)} to {show(high)}"


def _ranking(ran, labels, value, lowest, show, alike=_same_shown, lead=""):
    """ "<best label>: <methods> (<value>); <worst label>: <methods> (<value>)", each group
    the methods whose value is ``alike`` its leader's (the same to the digits shown, or within
    the noise band ``alike`` states); when every method is alike the best, ``labels[2]`` and
    their values (each group's in brackets, after ``lead``): nothing is ranked inside the noise."""
    values = {outcome.method: value(outcome) for outcome in ran}
    best_value = min(values.values()) if lowest else max(values.values())
    worst_value = max(values.values()) if lowest else min(values.values())
    best = _group(values, best_value, alike)
    if len(ran) > 1 and len(best) == len(ran):
        return f"{labels[2]} ({lead}{_span(values, best, show)})."
    worst = [name for name in _group(values, worst_value, alike) if name not in best]
    tail = f"; {labels[1]}: {_names(worst)} ({lead}{_span(values, worst, show)})" if len(ran) > 1 else ""
    return f"{labels[0]}: {_names(best)} ({lead}{_span(values, best, show)}){tail}."


def _energy_sentence(ran):
    """Who kept the total energy best and worst by |drift|, naming together the methods whose
    drifts are within noise (_energy_alike), and nobody best or worst when all are."""
    return _ranking(
        ran,
        ("Energy kept best", "worst", "Energy kept: all within noise of one another"),
        lambda o: abs(o.row["energy_drift_J"]),
        True,
        lambda v: f"{v:.3g} J",
        _energy_alike,
        "total energy changed by ",
    )


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
    runs of the same comparison is not read as a result; no ranking where a run was timed in
    one window only (its quartiles are its median: no spread to tell noise from a difference)."""

    def rate(outcome):
        median = outcome.row.get("steps_per_second_median")
        return outcome.row["steps_per_second"] if median is None else median

    unspread = [o.method for o in ran if o.row.get("steps_per_second_low") == o.row.get("steps_per_second_high")]
    if len(ran) > 1 and unspread:  # issue 59: a ranking by one timing each changed from one compare to the next
        return (
            f"Speed: not ranked: {_names(unspread)} stepped too briefly to be timed in more than one "
            "~0.1 s window, so no spread tells a difference from the machine's noise (steps/s in the table)."
        )
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
            missed.append(
                f"{outcome.method} ("
                + "; ".join(
                    (
                        f"{check.quantity} {check.measured:.3g} {check.unit}"
                        if math.isfinite(check.measured)
                        else f"{check.quantity} not reached"
                    )
                    + f", expected {check.expected:.3g} ± {check.tolerance:.2g}"
                    for check in failed
                )
                + ")"
            )
    parts = []
    if met:
        parts.append(f"met by {_names(met)}")
    if missed:
        parts.append(f"missed by {_names(missed)}")
    return "The scene's stated expectations: " + "; ".join(parts) + "."


def paragraph(scene: Scene, outcomes: Sequence[Outcome], skipped: Mapping[str, str]) -> str:
    """The plain-words paragraph: fastest, least penetration, best energy, expectations met,
    failures and the methods left out (``skipped``: name → why)."""
    ran = [outcome for outcome in outcomes if outcome.run]
    sentences = []
    if ran:
        duration = ran[0].run.arrays["time"][-1]  # type: ignore[union-attr]  # a run that ran
        sentences.append(
            f"{len(outcomes)} method{'s' if len(outcomes) > 1 else ''} on {scene.name} "
            f"for {duration:.3g} s of simulated time."
        )
        sentences.append(_speed_sentence(ran))
        sentences.append(
            _ranking(
                ran,
                ("Least penetration", "deepest", "Least penetration: all the same"),
                lambda o: o.row["max_penetration_mm"],
                True,
                lambda v: f"{v:.3g} mm",
                _penetration_alike,
            )
        )
        sentences.append(_energy_sentence(ran))
        if dissipative(scene.model):
            sentences.append(
                "Restitution below 1 or friction makes this scene lose energy by design, "
                "so part of every energy change is physical."
            )
        sentences.append(_expectation_sentence(ran))
    else:
        sentences.append(f"No method finished {scene.name}.")
    for outcome in outcomes:
        if outcome.gap:
            sentences.append(f"{outcome.gap}, so it was not run.")
        if outcome.failure:
            sentences.append(
                f"{outcome.method} {blew_up(outcome)} ({outcome.scene.integrator}, "
                f"dt = {outcome.scene.dt:g} s): it needs a smaller dt or a softer setting."
            )
    for name, why in skipped.items():
        sentences.append(f"{name} was left out: {why}.")
    return " ".join(sentence for sentence in sentences if sentence)


def _notes(outcomes):
    """Caveats worth printing under the table, as plain sentences."""
    notes = [
        "Energy drift is the total energy (kinetic + potential + elastic) at the end minus at "
        "the start; its % is of the run's energy scale: the larger of the most kinetic plus potential "
        "energy it held above the lowest potential energy it reached (the contact springs' elastic "
        "energy left out: it depends on the method), and the initial potential energy above the "
        "lowest mass.",
        f"Energy drifts are ranked only when they differ by more than {ENERGY_NOISE_SHARE:.0%} of the "
        f"larger and by more than {ENERGY_NOISE_FLOOR * 1e6:g} µJ; closer drifts are named together, "
        "within noise of one another.",
        "Solver residuals are in each method's own unit (impulse, constraints: m/s of the last "
        "sweep; projection: m; penalty with backward Euler: relative linear residual), so compare "
        "them within a method, not across.",
    ]
    if any(outcome.row.get("momentum_drift_Ns") == "n/a" for outcome in outcomes):
        notes.append(
            "Momentum drift is n/a: the scene has static obstacles (or pinned cloth), whose "
            "forces change the momentum, so it is no conservation check here."
        )
    else:
        notes.append(
            "Momentum drift ‖P(T) − P(0) − M g T‖ is a conservation check: no obstacles act on "
            "this scene, so anything but rounding is an error of the method."
        )
    for group, largest in same_computation(outcomes):
        notes.append(
            f"{_names(group)} computed the same trajectory to within rounding (positions apart by "
            f"{largest:.2g} m at most): at these settings they solve the same problem the same way, "
            f"so their numbers are one result, not {len(group)} that agree (their speeds still differ)."
        )
    for outcome in outcomes:
        notes += [f"{outcome.method}: {text}" for text in outcome.notes]
        notes += [f"{outcome.method}: warning: {text}" for text in outcome.warnings]
    return notes


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
            measured = (
                f"{check.measured:.6g} (error {check.error:+.3g}{share})"
                if math.isfinite(check.measured)
                else "not reached"
            )
            word = {True: ": pass", False: ": FAIL", None: ""}[check.passed]
            parts.append(f"{method} {measured}{word}")
        first = entries[0][1]
        allowed = f" ± {first.tolerance:.3g}" if first.tolerance is not None else ""
        lines.append((quantity, unit, f"expected {first.expected:.6g}{allowed} — " + "; ".join(parts)))
    return lines


def report_texts(
    scene: Scene,
    outcomes: Sequence[Outcome],
    summary_text: str,
    table: tuple[list[str], list[list[str]]],
    plot_paths: Mapping[str, str],
    out: str,
) -> tuple[str, str]:
    """The text of report.md and of report.html (``_markdown_text``, ``_html_text``) from the
    same parts: ``table`` from :func:`table_cells`, ``plot_paths`` the comparison plots (name →
    path), links relative to ``out``."""
    parts = (scene, outcomes, summary_text, table, plot_paths, out)
    return _markdown_text(*parts), _html_text(*parts)


def _markdown_text(scene, outcomes, summary_text, table, plot_paths, out):
    """report.md: the paragraph, the table (``table``: :func:`table_cells`), the checks, each
    method's files, the comparison plots (``plot_paths``: name → path) and the notes; links
    relative to ``out``."""
    files_lines = []
    for outcome in outcomes:
        if outcome.gap:
            files_lines.append(f"- **{outcome.method}**: not run: {outcome.gap}")
            continue
        if not outcome.run:
            files_lines.append(f"- **{outcome.method}**: {blew_up(outcome)}: {outcome.failure}")
            continue
        links = [f"[{name}]({_link(out, path)})" for name, path in outcome.files.items()]
        files_lines.append(f"- **{outcome.method}**: " + " · ".join(links))
    checks = [f"- **{quantity}** ({unit}): {text}" for quantity, unit, text in _check_lines(outcomes)]
    text = [
        f"# {scene.name}: the methods compared",
        "",
        scene.description,
        "",
        summary_text,
        "",
        "## Numbers",
        "",
        _markdown_table(*table),
        "",
        "What the columns mean:",
        "",
        *(f"- **{heading}**: {meaning}" for heading, meaning in _meanings()),
        "",
    ]
    if checks:
        text += ["## Expectations and closed-form checks", "", *checks, ""]
    text += [
        "## Files",
        "",
        *files_lines,
        "",
        "## Comparison plots",
        "",
        *(f"![{name}]({_link(out, path)})" for name, path in plot_paths.items()),
        "",
        "## Notes",
        "",
        *(f"- {note}" for note in _notes(outcomes)),
        "",
    ]
    return "\n".join(text)


def _key_numbers(row):
    return (
        f"expectations {row['expectations']} · {row['steps_per_second']:,.0f} steps/s · "
        f"max penetration {row['max_penetration_mm']:.3g} mm · energy drift {row['energy_drift_J']:+.3g} J"
    )


def _media(outcome, out):
    """The video of one method: MP4 with its GIF inside as the fallback, or the GIF or still alone."""
    files = outcome.files
    if "mp4" in files:
        poster = f' poster="{html.escape(_link(out, files["still"]))}"' if "still" in files else ""
        fallback = files.get("gif") or files.get("still")
        inner = (
            f'<img src="{html.escape(_link(out, fallback))}" alt="{html.escape(outcome.method)}">' if fallback else ""
        )
        return (
            f'<video controls autoplay muted loop playsinline preload="auto"{poster}>'
            f'<source src="{html.escape(_link(out, files["mp4"]))}" type="video/mp4">{inner}</video>'
        )
    for name in ("gif", "still"):
        if name in files:
            return f'<img src="{html.escape(_link(out, files[name]))}" alt="{html.escape(outcome.method)}">'
    return ""


def _card(outcome, out):
    name = f'<span class="name">{html.escape(outcome.method)}</span>'
    if not outcome.run:
        status, why = ("not run", outcome.gap) if outcome.gap else (blew_up(outcome), outcome.failure)
        return (
            f'<figure class="card"><div class="failed">{html.escape(status)}</div>'
            f"<figcaption>{name}<br>{html.escape(why or '')}</figcaption></figure>"
        )
    return (
        f'<figure class="card">{_media(outcome, out)}<figcaption>{name} '
        f"({html.escape(outcome.row['integrator'])}, dt = {outcome.scene.dt * 1000:.4g} ms)<br>"
        f"{html.escape(_key_numbers(outcome.row))}</figcaption></figure>"
    )


def _images(paths, out):
    return "".join(
        f'<a href="{html.escape(_link(out, path))}"><img src="{html.escape(_link(out, path))}" '
        f'alt="{html.escape(name)}"></a>'
        for name, path in paths.items()
    )


def _method_details(outcome, out):
    if not outcome.run:
        return ""
    plots = {name: outcome.files[f"plot {name}"] for name in PLOTS if f"plot {name}" in outcome.files}
    links = " · ".join(
        f'<a href="{html.escape(_link(out, path))}">{html.escape(name)}</a>' for name, path in outcome.files.items()
    )
    return (
        f"<details><summary>{html.escape(outcome.method)}</summary>"
        f'<p>{links}</p><div class="plots">{_images(plots, out)}</div></details>'
    )


def _html_text(scene, outcomes, summary_text, table, plot_paths, out):
    """report.html: what report.md holds, with each method's video in a card, its plots folded
    away, and the style and script of report.css and report.js inlined."""
    check_items = "".join(
        f"<li><b>{html.escape(quantity)}</b> ({html.escape(unit)}): {html.escape(text)}</li>"
        for quantity, unit, text in _check_lines(outcomes)
    )
    title = f"{scene.name}: the methods compared"
    parts = [
        "<!doctype html>",
        '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>{html.escape(title)}</title><style>\n{_asset('report.css')}</style></head>",
        '<body data-status="pending">',
        f"<h1>{html.escape(title)}</h1>",
        f'<p class="description">{html.escape(scene.description)}</p>',
        f'<p class="summary">{html.escape(summary_text)}</p>',
        '<section class="videos">' + "".join(_card(outcome, out) for outcome in outcomes) + "</section>",
        "<h2>Numbers</h2>",
        f'<div class="scroll">{_html_table(*table)}</div>',
        '<details class="notes"><summary>What the columns mean</summary><dl>'
        + "".join(f"<dt>{html.escape(heading)}</dt><dd>{html.escape(meaning)}</dd>" for heading, meaning in _meanings())
        + "</dl></details>",
    ]
    if check_items:
        parts += ["<h2>Expectations and closed-form checks</h2>", f"<ul>{check_items}</ul>"]
    parts += [
        "<h2>Comparison plots</h2>",
        f'<div class="plots">{_images(plot_paths, out)}</div>',
        "<h2>Each method</h2>",
        *(_method_details(outcome, out) for outcome in outcomes),
        '<h2>Notes</h2><ul class="notes">'
        + "".join(f"<li>{html.escape(note)}</li>" for note in _notes(outcomes))
        + "</ul>",
        f"<script>\n{_asset('report.js')}</script>",
        "</body></html>",
        "",
    ]
    return "\n".join(parts)


def _asset(name) -> str:
    """The text of one of the package's files (report.css, report.js)."""
    return resources.files(__package__).joinpath(name).read_text(encoding="utf-8")
