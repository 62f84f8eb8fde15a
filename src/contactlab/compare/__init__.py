"""The methods side by side on one scene: runs, metrics, plots, videos and a report.

    result = compare("box_pyramid", ["impulse", "penalty"], "out/pyramid", duration=1.0)
    result.rows[0]["max_penetration_mm"]          # one dict per method, as in comparison.csv
    result.report_html                            # open it in a browser (no network needed)

Every method runs the same scene (with ``simulation.method`` set to it, so the scene's
``[method.NAME]`` options apply). Into ``out`` (default ``out/<scene>-compare/``):

    <method>/trajectory.h5, summary.json      as `contactlab run` writes them
    <method>/plots/*.png                       contactlab.plots.write_plots
    <method>/video.mp4, video.gif, still.png   contactlab.render.render (video=True)
    plots/*.png                                one line per method (write_comparison_plots)
    comparison.csv, report.md, report.html

The package, in the order the data flows: ``run`` chooses the methods, runs them and writes
their files (:func:`compare`); ``measures`` turns each run into its row of numbers and
verdicts; ``report`` turns the rows into the table, the plain words and the three reports,
with ``report.css`` and ``report.js`` inlined into report.html. The metrics are defined in
docs/compare.md.
"""

from .measures import (
    ROW_KEYS,
    SAME_WITHIN,
    TIMINGS,
    TINY_ENERGY,
    energy_scale,
    expectation_verdict,
    metrics,
    momentum_drift,
    same_computation,
)
from .report import COLUMNS, MEANINGS
from .run import PARALLEL_WORK, Comparison, compare, run_method, supports

__all__ = [
    "COLUMNS",
    "MEANINGS",
    "PARALLEL_WORK",
    "ROW_KEYS",
    "SAME_WITHIN",
    "TIMINGS",
    "TINY_ENERGY",
    "Comparison",
    "compare",
    "energy_scale",
    "expectation_verdict",
    "metrics",
    "momentum_drift",
    "run_method",
    "same_computation",
    "supports",
]
