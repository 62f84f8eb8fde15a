"""Fitting each method's settings to measured motion, on Dask: ``contactlab fit`` (docs/validate.md).

    from contactlab.fitting import fit
    result = fit("cube_toss.toml", files, ["materials.0.friction=0.05:0.6", "materials.0.restitution=0:0.8"])
    result.methods["impulse"]["values"], result.methods["impulse"]["holdout_error"]

The measurements are split (:func:`split`): every (1/``holdout``)-th file, in the order given,
is held out; the rest train. For each method, the varied settings (any ``--set`` path, each
within its ``LO:HI``) are fitted to minimise the *training error*, the median over the
training measurements of the position error of :mod:`contactlab.prediction` (a run that fails
counts as :data:`FAILED_ERROR`), and the fitted values are then judged on the held-out ones.

The optimiser is SciPy's bounded Nelder–Mead (``scipy.optimize.minimize``), over the settings
scaled to [0, 1], from the scene's own values (or the middle of a range that leaves them out),
with a first simplex a quarter of each range wide, stopped after ``evaluations`` points
(default :func:`default_evaluations`). Why: the error of a contact simulation against a
measurement is a noisy, piecewise-smooth function of its settings (a cube lands on another
corner, a contact begins a step later), so a gradient by finite differences measures the noise;
Nelder–Mead compares values only, takes one or two points a step, and so fits two to four
settings in a few dozen runs per measurement, where population methods (differential evolution)
need ten times as many.

Every point's runs — one per training measurement — go to a Dask cluster at once through
:mod:`contactlab.cluster` (a local one, or ``scheduler``), the path ``contactlab sweep`` takes,
each one :func:`contactlab.prediction.predict`. Each row is kept as it comes in
``OUT/evaluations/<key>.json``, the key hashing the scene's text, the settings, the method, the
measurement file's bytes and the contactlab version: the optimiser is deterministic, so a fit
stopped (Ctrl-C) and run again asks for the same points and finds them done. At the end,
``OUT/fit.json`` (:meth:`Fit.as_json`) and ``OUT/plots/fit_<setting>.png``.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from . import __version__, cluster, folder_lock, interrupts
from .errors import InputError
from .methods import method_names
from .prediction import checked_inputs, predict
from .record import atomic_path, make_folders, remove_empty

if TYPE_CHECKING:
    from distributed import Client

    from .measured import Measurement

FAILED_ERROR = 1000.0  # %: the position error a run that diverged or failed counts as
FIRST_STEP = 0.25  # the first simplex's size, as a fraction of each range
XATOL = 0.005  # stop when the simplex is this small a fraction of each range ...
FATOL = 0.01  # ... and its errors within this many percentage points
DIGITS = 6  # a point's scaled coordinates are rounded to this many digits (stable keys)
DEFAULT_HOLDOUT = 0.25


@dataclass(frozen=True)
class Vary:
    """A setting to fit: its ``--set`` ``path``, within [``low``, ``high``]; ``whole``: a whole
    number (an iteration count), its values rounded."""

    path: str
    low: float
    high: float
    whole: bool = False

    def value(self, scaled: float) -> float:
        value = float(self.low + round(float(scaled), DIGITS) * (self.high - self.low))
        return round(value) if self.whole else value

    def setting(self, value: float) -> str:
        """The ``--set`` string giving ``value`` to the setting ("PATH=0.35", "PATH=12")."""
        return f"{self.path}={round(value) if self.whole else float(value)!r}"


def parse_vary(text: str) -> Vary:
    """``"PATH=LO:HI"`` as a :class:`Vary`; InputError naming ``--vary`` otherwise."""
    match = re.fullmatch(r"\s*([^=\s]+)\s*=\s*([^:]+):(.+)", str(text))
    if not match:
        raise InputError("--vary", f"expected PATH=LO:HI (for example materials.0.friction=0.05:0.6), found {text!r}")
    path, low, high = match.groups()
    try:
        low_value, high_value = float(low), float(high)
    except ValueError:
        raise InputError(
            "--vary", f"expected numbers LO:HI after {path}=, found {low.strip()}:{high.strip()}"
        ) from None
    if not (math.isfinite(low_value) and math.isfinite(high_value) and low_value < high_value):
        raise InputError("--vary", f"expected finite LO < HI for {path}, found {low.strip()}:{high.strip()}")
    return Vary(path, low_value, high_value)


def split(count: int, holdout: float) -> tuple[list[int], list[int]]:
    """(training, held-out) indices of ``count`` measurements: round(``holdout`` × count) held
    out (at least one when ``holdout`` > 0), spread evenly in the order given; InputError naming
    ``--holdout`` for a fraction outside [0, 1) or one that leaves nothing to train on."""
    if isinstance(holdout, bool) or not isinstance(holdout, (int, float)) or not 0.0 <= holdout < 1.0:
        raise InputError("--holdout", f"expected a fraction from 0 up to (not including) 1, found {holdout!r}")
    held = 0 if holdout == 0 else max(1, round(holdout * count))
    if held >= count:
        raise InputError(
            "--holdout",
            f"holding out {held} of {count} measurement{'s' if count != 1 else ''} leaves none to fit on; "
            "give more measurements or --holdout 0",
        )
    out = [i for i in range(count) if (i + 1) * held // count > i * held // count]
    return [i for i in range(count) if i not in out], out


def default_evaluations(dimensions: int) -> int:
    """Points a method's fit evaluates at most: 15 per varied setting, plus 10."""
    return 10 + 15 * dimensions


@dataclass
class Fit:
    """What :func:`fit` produced: ``methods`` (method -> ``values`` {path: value},
    ``train_error`` and ``holdout_error`` (medians of the position error, %; None without a
    held-out part), ``evaluations``), ``vary``, the ``train`` and ``holdout`` measurement
    names, ``out`` and the files written (``json``, ``plots``)."""

    methods: dict[str, dict[str, Any]]
    vary: list[Vary]
    train: list[str]
    holdout: list[str]
    out: str
    json: str = ""
    plots: list[str] = field(default_factory=list)

    def as_json(self) -> dict[str, Any]:
        return {
            "methods": self.methods,
            "vary": {v.path: [v.low, v.high] for v in self.vary},
            "train": self.train,
            "holdout": self.holdout,
            "error": "median over the measurements of the centre-position error averaged over each, % of body size",
            "optimizer": "scipy.optimize.minimize, method Nelder-Mead, bounded",
        }


def fit(
    scene: str | os.PathLike[str],
    measured: Sequence[str | os.PathLike[str]],
    vary: Sequence[str | Vary],
    methods: str | Sequence[str] | None = None,
    holdout: float = DEFAULT_HOLDOUT,
    out: str | os.PathLike[str] | None = None,
    *,
    overrides: Sequence[str] = (),
    evaluations: int | None = None,
    client: Client | None = None,
    scheduler: str | None = None,
    workers: int | None = None,
    progress: bool = False,
    log: Callable[[str], object] | None = None,
) -> Fit:
    """Fit the settings ``vary`` (``"PATH=LO:HI"`` strings or :class:`Vary`) of each of
    ``methods`` (default: all four) on ``scene`` (with the ``--set`` strings ``overrides``) to
    the training part of ``measured`` (files), judge them on the held-out part (``holdout``, a
    fraction), and write ``fit.json`` and the plots into ``out`` (default ``out/<scene>-fit``).
    The runs go to ``client``, or to a cluster from :func:`contactlab.cluster.connect`
    (``scheduler``, ``workers``). Every input is checked before a cluster starts."""

    varied = [item if isinstance(item, Vary) else parse_vary(item) for item in vary]
    if not varied:
        raise InputError("--vary", "give at least one setting to fit, as PATH=LO:HI")
    if len({v.path for v in varied}) != len(varied):
        raise InputError("--vary", "each setting may be varied once")
    names = method_names(methods)
    budget = default_evaluations(len(varied)) if evaluations is None else evaluations
    if isinstance(budget, bool) or not isinstance(budget, int) or budget < len(varied) + 1:
        raise InputError("--evaluations", f"expected a whole number ≥ {len(varied) + 1}, found {evaluations!r}")
    if client is None:
        cluster.check_cluster(scheduler, workers)
    loaded, source, measurements, names = checked_inputs(scene, measured, names, overrides)
    varied = [_checked(v, source, overrides, names) for v in varied]
    train, held = split(len(measurements), holdout)
    out = os.fspath(out) if out is not None else os.path.join("out", f"{loaded.name}-fit")
    start = [_start(source, v) for v in varied]
    say = log or (lambda line: None)
    made = make_folders(os.path.join(out, "evaluations"))
    with folder_lock.held(out, "--out", made):  # one fit at a time writes a folder
        try:
            context = _given(client) if client is not None else cluster.connect(scheduler, workers)
            with context as connected:
                say(f"Dask dashboard: {cluster.dashboard(connected)}")
                runs = _Runs(connected, source, overrides, os.path.join(out, "evaluations"), progress)
                result = {}
                evaluated = {}
                for method in names:
                    result[method], evaluated[method] = _fit_method(
                        runs, method, varied, start, [measurements[i] for i in train], budget, say
                    )
                    if held:
                        rows = runs.rows(method, varied, result[method]["values"], [measurements[i] for i in held])
                        result[method]["holdout_error"] = _median(rows)
                        say(f"{method}: held-out error {result[method]['holdout_error']:.3g} %")
        except BaseException:
            remove_empty(made)
            raise
        fitted = Fit(
            methods=result,
            vary=varied,
            train=[measurements[i].name for i in train],
            holdout=[measurements[i].name for i in held],
            out=out,
        )
        _write(fitted, evaluated)
    return fitted


def _checked(vary: Vary, source: str, overrides: Sequence[str], methods: Sequence[str]) -> Vary:
    """``vary`` as its runs will set it, each end of its range loaded with each method as a run
    would load it: whole where the setting takes whole numbers only (an iteration count refuses
    1.0 and takes 1) and the range's ends are whole. InputError naming ``--vary`` otherwise."""
    from .scene import load_scene

    ends_whole = vary.low == round(vary.low) and vary.high == round(vary.high)
    refused = None
    for candidate in (vary, replace(vary, whole=True)) if ends_whole else (vary,):
        try:
            for end in (vary.low, vary.high):
                for method in methods:
                    load_scene(source, [*overrides, candidate.setting(end), f"simulation.method={method}"])
            return candidate
        except InputError as error:
            refused = refused or InputError("--vary", f"{candidate.setting(end)}: {error}")
    raise refused


class _given:
    """A client the caller holds, as a context (not closed at the end)."""

    def __init__(self, client):
        self.client = client

    def __enter__(self):
        return self.client

    def __exit__(self, *exc):
        return False


def _start(source: str, vary: Vary) -> float:
    """The scaled start of ``vary``: the scene's own value (``source``: a built-in name or a
    file) where it is a number in range, else 0.5 (the --set overrides aside)."""
    from .scene.loader import read_source
    from .scene.toml import parse_toml

    node: Any = parse_toml(read_source(source)[1])
    for part in vary.path.replace("[", ".").replace("]", "").split("."):
        key: Any = int(part) if part.isdigit() else part
        try:
            node = node[key]
        except (KeyError, IndexError, TypeError):
            return 0.5
    if isinstance(node, (int, float)) and not isinstance(node, bool) and vary.low <= node <= vary.high:
        return (node - vary.low) / (vary.high - vary.low)
    return 0.5


class _Runs:
    """The runs of a fit: each (method, settings, measurement) once, kept in ``folder``."""

    def __init__(self, client, source, overrides, folder, progress):
        self.client, self.source, self.overrides, self.folder, self.progress = (
            client,
            source,
            list(overrides),
            folder,
            progress,
        )
        self.scene_text = _digest_text(source)
        self.file_digests: dict[str, str] = {}

    def rows(self, method: str, varied: Sequence[Vary], values: Mapping[str, float], measurements) -> list[dict]:
        """The rows of ``method`` with the settings ``values`` over ``measurements``: those kept
        read back, the others run on the cluster (all at once) and kept."""
        settings = [*self.overrides, *(v.setting(values[v.path]) for v in varied)]
        found, jobs = {}, []
        for measurement in measurements:
            key = self._key(method, settings, measurement)
            kept = self._read(key)
            if kept is not None:
                found[key] = kept
            else:
                job = {
                    "scene": self.source,
                    "settings": settings,
                    "method": method,
                    "measurement": os.path.abspath(measurement.path),
                }
                jobs.append((key, job))
        for key, row in cluster.run_tasks(self.client, predict, jobs, progress=self.progress, description="runs"):
            if isinstance(row, BaseException):  # its workers kept dying, or a bug escaped
                row = {"status": "error", "message": f"{type(row).__name__}: {row}", "position_error_pct": math.nan}
            found[key] = row
            self._keep(key, row)
        return [found[self._key(method, settings, m)] for m in measurements]

    def _key(self, method, settings, measurement):
        path = os.path.abspath(measurement.path)
        if path not in self.file_digests:
            with open(path, "rb") as stream:
                self.file_digests[path] = hashlib.sha256(stream.read()).hexdigest()
        identity = [self.scene_text, method, settings, self.file_digests[path], __version__]
        return hashlib.sha256(json.dumps(identity).encode()).hexdigest()[:24]

    def _read(self, key):
        try:
            with open(os.path.join(self.folder, f"{key}.json"), encoding="utf-8") as stream:
                row = json.load(stream)
        except (OSError, ValueError):  # not run yet, or a file cut short: run again
            return None
        return row if isinstance(row, dict) and "status" in row else None

    def _keep(self, key, row):
        path = os.path.join(self.folder, f"{key}.json")
        with atomic_path(path) as temporary, open(temporary, "w", encoding="utf-8") as stream:
            json.dump({name: _plain(value) for name, value in row.items() if name != "simulated"}, stream)
        interrupts.note_written(path, removed=True)  # an interrupted fit names the folder it kept
        if self.folder not in interrupts.written_paths():
            interrupts.note_written(self.folder)


def _digest_text(source):
    from .scene.loader import read_source

    return hashlib.sha256(read_source(source)[1].encode()).hexdigest()


def _plain(value):
    return None if isinstance(value, float) and not math.isfinite(value) else value


def _median(rows) -> float:
    errors = [row.get("position_error_pct") for row in rows]
    errors = [e if isinstance(e, (int, float)) and math.isfinite(e) else FAILED_ERROR for e in errors]
    return float(np.median(errors))


def _fit_method(runs, method, varied, start, training: Sequence[Measurement], budget, say):
    """Nelder–Mead over the scaled settings of ``method``; (its entry of fit.json, the points
    evaluated [(values, training error)])."""
    from scipy.optimize import minimize

    points: list[tuple[list[float], float]] = []

    def error(scaled):
        values = {v.path: v.value(u) for v, u in zip(varied, np.clip(scaled, 0.0, 1.0))}
        found = _median(runs.rows(method, varied, values, training))
        points.append(([values[v.path] for v in varied], found))
        shown = ", ".join(f"{path}={value:.4g}" for path, value in values.items())
        say(f"{method}: point {len(points)}: {shown}: training error {found:.3g} %")
        return found

    first = np.array(start, dtype=float)
    simplex = [first]
    for k in range(len(varied)):
        corner = first.copy()
        corner[k] += FIRST_STEP if first[k] + FIRST_STEP <= 1.0 else -FIRST_STEP
        simplex.append(corner)
    minimize(
        error,
        first,
        method="Nelder-Mead",
        bounds=[(0.0, 1.0)] * len(varied),
        options={"initial_simplex": np.array(simplex), "maxfev": budget, "xatol": XATOL, "fatol": FATOL},
    )
    values, best = min(points, key=lambda point: point[1])
    entry = {
        "values": {v.path: value for v, value in zip(varied, values)},
        "train_error": best,
        "holdout_error": None,
        "evaluations": len(points),
    }
    return entry, points


def _write(fitted: Fit, evaluated) -> None:
    from .prediction_report import write_fit_plots
    from .record import undo_written

    plots = os.path.join(fitted.out, "plots")
    made = make_folders(plots)
    written: list[str] = []
    try:
        fitted.plots = write_fit_plots(
            plots,
            [v.path for v in fitted.vary],
            evaluated,
            {method: list(entry["values"].values()) for method, entry in fitted.methods.items()},
        )
        written += fitted.plots
        interrupts.check()
        fitted.json = os.path.join(fitted.out, "fit.json")
        with atomic_path(fitted.json) as temporary, open(temporary, "w", encoding="utf-8") as stream:
            json.dump(fitted.as_json(), stream, indent=2)
    except BaseException:
        undo_written(written, made)
        raise
