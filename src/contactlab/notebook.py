"""How a Model, a Run and a comparison show themselves in Jupyter (as HTML).

In a notebook, a cell ending in ``model``, ``run`` or ``compare(...)`` shows a compact HTML
summary instead of a dump of arrays: a model its parts; a run what it did (steps, where the time
went, penetration, energy, how it ended) beside an inline player of the run (contactlab.render:
an MP4 of 320 × 240 at up to PLAYER_FPS frames per second and at most PLAYER_FRAMES frames,
drawn when shown, in real time, with the browser's play, pause and scrub controls; the last
sample as a still where no video can be drawn); a comparison its table, with a link to its
report. Everything is escaped; videos and pictures are inline, so the notebook needs no file
beside it. For an interactive 3D view, ``contactlab.viewer.view(run)`` opens the viewer.

A Model and a Run belong to lower layers, which know nothing of presentation: :func:`register`
tells IPython's HTML formatter how to show them, by their classes' names. ``import contactlab``
calls it when IPython is loaded (a notebook's kernel), and ``%load_ext contactlab.notebook``
does it by hand. A comparison, of this layer, has its own ``_repr_html_``.
"""

from __future__ import annotations

import base64
import html
import os
import tempfile
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .compare import Comparison
    from .model import Model
    from .simulation import Run


PLAYER_FPS = 12  # frames per second of the inline player at most
PLAYER_FRAMES = 120  # frames of it at most (a long run plays at fewer frames per second)


def register(shell: Any = None) -> None:
    """Show a Model (:func:`model_html`) and a Run (:func:`run_html`) as HTML in ``shell``, an
    IPython shell (default: the running one; none running: nothing happens). Registered by the
    classes' module and name, so nothing of contactlab is imported for it."""
    if shell is None:
        from IPython import get_ipython

        shell = get_ipython()
    if shell is None:
        return
    html = shell.display_formatter.formatters["text/html"]
    html.for_type_by_name("contactlab.model", "Model", model_html)
    html.for_type_by_name("contactlab.simulation", "Run", run_html)


load_ipython_extension = register  # %load_ext contactlab.notebook


def _table(rows) -> str:
    cells = "".join(
        f"<tr><th style='text-align:left;padding-right:1em'>{html.escape(str(key))}</th>"
        f"<td>{html.escape(str(value))}</td></tr>"
        for key, value in rows
    )
    return f"<table>{cells}</table>"


def model_html(model: Model) -> str:
    """A Model: what it holds, its materials and gravity."""
    rows = [
        ("holds", model.describe()),
        ("materials", ", ".join(model.material_names) or "default"),
        ("gravity", f"{tuple(float(g) for g in model.gravity)} m/s²"),
    ]
    return f"<div><b>contactlab Model</b>{_table(rows)}</div>"


def run_html(run: Run, picture: bool = True) -> str:
    """A Run: its summary's main numbers and (``picture``) an inline player of it (its last sample
    drawn, where no video can be)."""
    s = run.summary
    ended = (
        "diverged: " + s["diverged"]["message"]
        if s.get("diverged")
        else f"interrupted ({s['interrupted']['signal']})"
        if s.get("interrupted")
        else "completed"
    )
    energy = s["energy"]
    rows = [
        ("scene, method", f"{s['scene']}, {s['method']} ({s['integrator']})"),
        ("steps", f"{s['steps']:,} of {s['dt']:g} s, {s.get('samples', '?')} samples"),
        (
            "time",
            f"{s['wall_seconds']:.3g} s: {s['compile_seconds']:.3g} s compiling or loading kernels, "
            f"{s['steps_per_second']:,.0f} steps/s stepping",
        ),
        (
            "deepest penetration",
            f"{s['max_penetration'] * 1000:.3g} mm (at the end {s['final_penetration'] * 1000:.3g} mm)",
        ),
        ("total energy", f"{energy['initial']:.4g} J at the start, {energy['final']:.4g} J at the end"),
        ("ended", ended),
    ]
    image = _player(run.arrays) if picture else ""
    return (
        f"<div style='display:flex;gap:1em;align-items:flex-start'>{image}"
        f"<div><b>contactlab Run</b>{_table(rows)}</div></div>"
    )


def comparison_html(result: Comparison) -> str:
    """A comparison (contactlab.compare.Comparison): one row per method, and its report."""
    columns = (
        ("method", "method"),
        ("status", "status"),
        ("steps_per_second", "steps/s"),
        ("max_penetration_mm", "max penetration (mm)"),
        ("energy_drift_J", "energy drift (J)"),
    )
    head = "".join(f"<th>{html.escape(title)}</th>" for _, title in columns)
    body = "".join(
        "<tr>" + "".join(f"<td>{html.escape(_shown(row.get(key)))}</td>" for key, _ in columns) + "</tr>"
        for row in result.rows
    )
    return (
        f"<div><b>contactlab comparison of {html.escape(result.scene)}</b>"
        f"<table><tr>{head}</tr>{body}</table>"
        f"<p>{html.escape(result.summary_text)}</p>"
        f"<p>Report: <a href='{html.escape(result.report_html)}'>{html.escape(result.report_html)}</a></p></div>"
    )


def _shown(value):
    if isinstance(value, float):
        return f"{value:.4g}"
    return "–" if value is None else str(value)


def _player(arrays) -> str:
    """The run as an inline <video> with controls (MP4, 320 × 240, real time), its last sample
    as the poster (the still ``render`` draws with the video); the still alone when no video can
    be drawn (a single sample, no video encoder), "" when nothing can (a run gone NaN)."""
    from .errors import InputError
    from .render import render

    time = arrays["time"]
    duration = float(time[-1] - time[0]) if len(time) > 1 else 0.0
    if duration <= 0.0:
        return _still(arrays)
    fps = min(PLAYER_FPS, PLAYER_FRAMES / duration)
    with tempfile.TemporaryDirectory() as folder:
        try:
            paths = render(arrays, folder, fps=fps, width=320, height=240, formats=("mp4",))
        except InputError:  # a run that blew up: nothing finite to draw
            return ""
        except (OSError, RuntimeError):  # no video encoder here: the still alone
            return _still(arrays)
        video, poster = _data_uri(paths["mp4"], "video/mp4"), _data_uri(paths["still"], "image/png")
    return (
        "<video controls loop muted playsinline width='320' height='240' "
        f"poster='{poster}' src='{video}'>{_image(poster)}</video>"
    )


def _still(arrays) -> str:
    """The last sample drawn small, as an inline <img>; "" when the trajectory cannot be drawn."""
    from .errors import InputError
    from .render import still

    with tempfile.TemporaryDirectory() as folder:
        path = os.path.join(folder, "still.png")
        try:
            still(arrays, path, width=320, height=240)
        except InputError:  # a run that blew up: nothing finite to draw
            return ""
        return _image(_data_uri(path, "image/png"))


def _data_uri(path, kind) -> str:
    """The file at ``path`` as a data: URI of MIME type ``kind``."""
    with open(path, "rb") as stream:
        return f"data:{kind};base64,{base64.b64encode(stream.read()).decode('ascii')}"


def _image(uri) -> str:
    """An inline 320 × 240 <img> of the last sample from its data: URI."""
    return f"<img src='{uri}' width='320' height='240' alt='the last sample'>"
