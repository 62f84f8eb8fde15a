"""How well each method predicts measured motion: ``contactlab validate`` (docs/validate.md).

    from contactlab.prediction import validate
    result = validate("cube_toss.toml", ["toss_01.h5", "toss_02.h5"], methods=["impulse", "penalty"])
    result.medians["impulse"]["position_error_pct"]

For every measurement (:mod:`contactlab.measured`) and method, :func:`predict` loads the scene
with the method and the measured duration, starts the measured bodies in the state of the first
sample, runs, and compares the run with the measurement at the measured times (the run's
samples interpolated: positions linearly, orientations along the shorter arc, normalized):

* ``position_error_pct``: the distance between the simulated and the measured centre of mass,
  as % of the body's size (the longest edge of its bounding box in its own frame, :func:`body_size`),
  averaged over the samples (and over the bodies measured);
* ``rotation_error_deg``: the angle of the rotation between the simulated and the measured
  orientation, degrees, averaged likewise;
* ``final_position_error_pct``: the position error at the last sample.

The starting velocities are the file's when it has them. Otherwise they are estimated from the
samples of the first :data:`ESTIMATE_SECONDS` (at least 3), where the body must fly free: the
velocity is the slope of a least-squares line through the positions less the fall gravity
gives (p − ½ g t² = p₀ + v t holds exactly in free flight, and a line averages the tracking
noise where a finite difference of two samples would multiply it), the angular velocity the
slope of a line through the rotation vectors of q(t) q(t₀)⁻¹ (exact for a constant spin).

A run that diverges, or fails, gives a row with that status and no errors (NaN); the others go
on. :func:`predict` is one job — plain data in, a row out — so :mod:`contactlab.fitting` runs it
on Dask workers; :func:`validate` runs the jobs here, one after another, and writes
``validation.csv``, ``report.md`` and the plots of measured and simulated paths
(:mod:`contactlab.prediction_report`).
"""

from __future__ import annotations

import math
import os
import time as clock
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from . import budget, rotations, shapes
from .errors import InputError, SimulationDiverged, first_line
from .measured import Measurement, read_measurement
from .methods import method_names
from .peers import PEERS, Inexpressible
from .record import make_folders

if TYPE_CHECKING:
    from .model import Model
    from .scene import Scene
    from .state import State

ESTIMATE_SECONDS = 0.05  # s of the first samples the starting velocities are estimated from
ERRORS = ("position_error_pct", "rotation_error_deg", "final_position_error_pct")
COLUMNS = ("measurement", "method", "status", *ERRORS, "samples", "duration_s", "velocities", "message", "seconds")
REMEDIES = budget.Remedies(  # what validate and fit offer a run that would not fit (it records every step)
    disk="cut the measurement into shorter files, or give a longer simulation.dt (--set)",
    memory="cut the measurement into shorter files, or give a longer simulation.dt (--set)",
    model="simulate fewer bodies, particles or cloth vertices",
)


# ---- the bodies measured ---------------------------------------------------------------------------


def body_size(model: Model, body: int) -> float:
    """The longest edge [m] of body ``body``'s bounding box in its own frame: a box's longest
    side, a sphere's diameter, a capsule's length with its caps, a hull's widest extent."""
    kind, params = int(model.body_shape[body]), model.body_params[body]
    if kind == shapes.BOX:
        return float(2.0 * params[:3].max())
    if kind == shapes.CAPSULE:
        return float(2.0 * (params[0] + params[1]))
    if kind == shapes.CONVEX:
        hull = int(params[0])
        start, end = model.hulls["vertex_start"][hull], model.hulls["vertex_start"][hull + 1]
        return float(np.ptp(model.hulls["vertices"][start:end], axis=0).max())
    return float(2.0 * params[0])


def matched_bodies(model: Model, measurement: Measurement) -> np.ndarray:
    """(B,) the scene's index of each body measured, by name (or in order where the file names
    none and measures every body); InputError naming the file's ``body_names`` otherwise."""
    field_name = f"{os.path.basename(measurement.path)}:body_names"
    count = measurement.position.shape[1]
    if measurement.body_names is None:
        if count != model.body_count:
            raise InputError(
                field_name,
                f"the file measures {count} bodies and names none, the scene has {model.body_count}; "
                "name the bodies measured (body_names)",
            )
        indices = np.arange(count)
    else:
        missing = [name for name in measurement.body_names if name not in model.body_names]
        if missing:
            raise InputError(
                field_name,
                f"no body named {missing[0]!r} in the scene (its bodies: {', '.join(map(repr, model.body_names))})",
            )
        indices = np.array([model.body_names.index(name) for name in measurement.body_names])
    moving = [model.body_names[i] for i in indices if model.body_kinematic[i]]
    if moving:
        raise InputError(field_name, f"the body {moving[0]!r} follows a path in the scene, so nothing predicts it")
    return indices


def start_state(model: Model, measurement: Measurement, indices: np.ndarray) -> tuple[State, str]:
    """The model's initial state with the measured bodies (scene indices ``indices``) put in the
    pose of the first sample, with the file's velocities there ("file") or the ones estimated
    from the first samples ("estimated", see the module's docstring); the state and which."""
    state = model.state()
    state.body_position[indices] = measurement.position[0]
    state.body_orientation[indices] = measurement.orientation[0]
    if measurement.velocity is not None:
        state.body_velocity[indices] = measurement.velocity[0]
        state.body_angular_velocity[indices] = measurement.angular_velocity[0]  # type: ignore[index]
        return state, "file"
    velocity, angular_velocity = estimated_velocities(measurement, model.gravity)
    state.body_velocity[indices] = velocity
    state.body_angular_velocity[indices] = angular_velocity
    return state, "estimated"


def estimated_velocities(measurement: Measurement, gravity: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(velocity (B, 3) [m/s], angular velocity (B, 3) [rad/s]) at the first sample, from the
    samples of the first :data:`ESTIMATE_SECONDS` (at least 3, at most all): least-squares slopes
    of p − ½ g t² and of the rotation vectors of q(t) q(t₀)⁻¹ against t."""
    t = measurement.time - measurement.time[0]
    count = max(min(3, len(t)), int(np.searchsorted(t, ESTIMATE_SECONDS, side="right")))
    t = t[:count]
    design = np.stack([np.ones(count), t], axis=1)
    falling = measurement.position[:count] - 0.5 * gravity * t[:, None, None] ** 2  # (k, B, 3)
    first = measurement.orientation[0]
    inverse = first * np.array([1.0, -1.0, -1.0, -1.0])
    turned = rotations.multiply(measurement.orientation[:count], inverse[None])  # (k, B, 4): q(t) q(t0)⁻¹
    turned *= np.where(turned[..., :1] < 0.0, -1.0, 1.0)
    vectors = _rotation_vectors(turned)
    bodies = measurement.position.shape[1]
    slopes = np.linalg.lstsq(design, np.concatenate([falling, vectors], axis=2).reshape(count, -1), rcond=None)[0][1]
    slopes = slopes.reshape(bodies, 6)
    return slopes[:, :3], slopes[:, 3:]


def _rotation_vectors(q: np.ndarray) -> np.ndarray:
    """Rotation vectors (..., 3) [rad] of unit quaternions (..., 4) with w ≥ 0."""
    sine = np.linalg.norm(q[..., 1:], axis=-1)
    angle = 2.0 * np.arctan2(sine, q[..., 0])
    scale = np.where(sine > 1e-12, angle / np.maximum(sine, 1e-300), 2.0)
    return q[..., 1:] * scale[..., None]


# ---- one measurement with one method: a job ----------------------------------------------------------


def scene_overrides(method: str, measurement: Measurement, settings: Sequence[str] = ()) -> list[str]:
    """The ``--set`` strings of a run of ``method`` over ``measurement``'s duration, after ``settings``
    (a peer engine's run keeps the scene's method: it is not one of contactlab's)."""
    chosen = [] if method in PEERS else [f"simulation.method={method}"]
    return [*settings, *chosen, f"simulation.duration={measurement.duration!r}"]


def predict(job: Mapping[str, Any]) -> dict[str, Any]:
    """One measurement with one method, here or on a Dask worker. ``job``: ``scene`` (a
    built-in name or a file's absolute path), ``settings`` (``--set`` strings), ``method`` (one
    of the four, or a peer engine, "mujoco" or "pybullet": contactlab.peers, started from the
    same measured state),
    ``measurement`` (the file's path), ``paths`` (whether to return the simulated path).
    Returns the row (:data:`COLUMNS`; with ``paths``, also ``simulated``: positions (T, B, 3)
    [m] at the measured times); a run that diverges or fails gives its status and message,
    never an exception."""
    from .scene import load_scene

    started = clock.perf_counter()
    measurement = read_measurement(job["measurement"])
    row: dict[str, Any] = {"measurement": measurement.name, "method": job["method"], "samples": len(measurement.time)}
    row["duration_s"] = measurement.duration
    try:
        scene = load_scene(job["scene"], scene_overrides(job["method"], measurement, job.get("settings", ())))
        indices = matched_bodies(scene.model, measurement)
        state, row["velocities"] = start_state(scene.model, measurement, indices)
        if job["method"] in PEERS:
            from . import peers

            started_there = replace(scene.model, initial=state)  # a peer starts from its model's state
            run = peers.simulate(started_there, job["method"], scene.dt, scene.duration, scene_name=scene.name)
        else:
            run = scene.simulate(state=state, threads=1)
    except SimulationDiverged as error:
        return _failed(row, "diverged", first_line(error), started)
    except Inexpressible as error:  # a peer that cannot be given the scene: said, not failed
        return _failed(row, "not run", str(error), started)
    except Exception as error:  # a setting the scene refuses, a bug: the row says so, the others go on
        return _failed(row, "error", f"{type(error).__name__}: {first_line(error)}", started)
    sizes = np.array([body_size(scene.model, i) for i in indices])
    errors, simulated = compared(run.arrays, measurement, indices, sizes)
    row.update(status="ok", message="", **errors, seconds=clock.perf_counter() - started)
    if job.get("paths"):
        row["simulated"] = simulated
    return row


def compared(
    arrays: Mapping[str, np.ndarray], measurement: Measurement, indices: np.ndarray, sizes: np.ndarray
) -> tuple[dict[str, float], np.ndarray]:
    """(the errors of :data:`ERRORS`, the simulated positions (T, B, 3) [m]) of a run's
    ``arrays`` (from time 0) against ``measurement`` (from its first time), for the bodies
    ``indices`` of sizes ``sizes`` (B,) [m]."""
    sample = measurement.time - measurement.time[0]
    times = np.asarray(arrays["time"])
    after = np.clip(np.searchsorted(times, sample, side="right"), 1, len(times) - 1)
    before = after - 1
    weight = np.clip((sample - times[before]) / (times[after] - times[before]), 0.0, 1.0)[:, None, None]
    position = np.asarray(arrays["body_position"])[:, indices]
    orientation = np.asarray(arrays["body_orientation"])[:, indices]
    simulated = (1.0 - weight) * position[before] + weight * position[after]
    q0, q1 = orientation[before], orientation[after]
    q1 = q1 * np.where(np.sum(q0 * q1, axis=-1, keepdims=True) < 0.0, -1.0, 1.0)
    turned = (1.0 - weight) * q0 + weight * q1
    turned /= np.linalg.norm(turned, axis=-1, keepdims=True)
    distance = np.linalg.norm(simulated - measurement.position, axis=-1) / sizes * 100.0  # (T, B) %
    alignment = np.clip(np.abs(np.sum(turned * measurement.orientation, axis=-1)), 0.0, 1.0)
    angle = np.degrees(2.0 * np.arccos(alignment))
    return {
        "position_error_pct": float(distance.mean()),
        "rotation_error_deg": float(angle.mean()),
        "final_position_error_pct": float(distance[-1].mean()),
    }, simulated


def _failed(row, status, message, started):
    row.update(status=status, message=message, seconds=clock.perf_counter() - started)
    row.update({name: math.nan for name in ERRORS})
    row.setdefault("velocities", None)
    return row


# ---- validate: every measurement with every method -------------------------------------------------------


@dataclass
class Validation:
    """What :func:`validate` produced: ``rows`` (one dict per measurement and method, keys
    :data:`COLUMNS`), ``medians`` (method -> the median of each error of :data:`ERRORS` over its
    measurements that ran, and ``failed``: how many did not), ``best`` (the method of the lowest
    median position error), ``out`` and the paths written: ``csv``, ``report``, ``plots``."""

    rows: list[dict[str, Any]]
    medians: dict[str, dict[str, float]]
    best: str | None
    out: str
    csv: str = ""
    report: str = ""
    plots: list[str] = field(default_factory=list)

    def as_json(self) -> dict[str, Any]:
        """The rows and medians as one JSON-ready object (NaN as null)."""
        return {
            "rows": [{key: _plain(row.get(key)) for key in COLUMNS} for row in self.rows],
            "medians": {method: {k: _plain(v) for k, v in values.items()} for method, values in self.medians.items()},
            "best": self.best,
        }


def _plain(value):
    return None if isinstance(value, float) and not math.isfinite(value) else value


def checked_inputs(
    scene: str | os.PathLike[str],
    measured: Sequence[str | os.PathLike[str]],
    methods: str | Sequence[str] | None,
    settings: Sequence[str],
) -> tuple[Scene, str, list[Measurement], list[str]]:
    """(the scene as given, the source a worker loads it from, the measurements, the methods),
    every one checked as a run would use it: each file read, its bodies matched, the scene
    loaded with each method and each measured duration. InputError for the first mistake."""
    from .scene import load_scene

    names = method_names(methods)
    if isinstance(measured, (str, os.PathLike)) or not measured:
        raise InputError("MEASURED", "expected one or more measured-motion files (.h5)")
    loaded = load_scene(scene, list(settings))
    source = loaded.origin()["scene"]
    measurements = [read_measurement(path) for path in measured]
    stems = [m.name for m in measurements]
    twice = next((name for name in stems if stems.count(name) > 1), None)
    if twice is not None:
        raise InputError(
            "MEASURED", f"two files are named {twice!r}; the rows name each measurement by its file's name"
        )
    for measurement in measurements:
        matched_bodies(loaded.model, measurement)
        for method in names:
            checked = load_scene(source, scene_overrides(method, measurement, settings))
            try:  # the run limits: a measured duration shorter than the scene's dt, ...
                checked.check(remedies=REMEDIES)
            except InputError as error:  # one too long to hold: the measurement's fault, not a record_every's
                field = os.path.basename(measurement.path) if error.field == "record_every" else error.field
                raise InputError(field, error.message) from None
    return loaded, source, measurements, names


def medians(rows: Sequence[Mapping[str, Any]], methods: Sequence[str]) -> dict[str, dict[str, float]]:
    """Method -> the median of each error over its rows that ran, and ``failed``, the rows that did not."""
    result = {}
    for method in methods:
        mine = [row for row in rows if row["method"] == method]
        ran = [row for row in mine if row["status"] == "ok"]
        values = {name: float(np.median([row[name] for row in ran])) if ran else math.nan for name in ERRORS}
        result[method] = {**values, "failed": len(mine) - len(ran)}
    return result


def best_method(found: Mapping[str, Mapping[str, float]]) -> str | None:
    """The method of the lowest median position error (None when none ran)."""
    ranked = [(values["position_error_pct"], method) for method, values in found.items()]
    ranked = [pair for pair in ranked if math.isfinite(pair[0])]
    return min(ranked)[1] if ranked else None


def validate(
    scene: str | os.PathLike[str],
    measured: Sequence[str | os.PathLike[str]],
    methods: str | Sequence[str] | None = None,
    out: str | os.PathLike[str] | None = None,
    *,
    overrides: Sequence[str] = (),
    peers: str | Sequence[str] | None = None,
) -> Validation:
    """Run every method of ``methods`` (default: all four) from each measurement of ``measured``
    (measured-motion files) on ``scene`` (a built-in name or a .toml file, with the ``--set``
    strings ``overrides``) and write the rows, report and plots into ``out`` (default
    ``out/<scene>-validate``), with the engines ``peers`` ("mujoco", "pybullet"; a list or a
    comma-separated string) started from the same measured states beside them (their rows
    named by the engine; one a scene it cannot express is "not run", saying why). Every input
    is checked before anything runs or is written."""
    from .folder_lock import held
    from .peers import peer_names
    from .prediction_report import write_validation

    loaded, source, measurements, names = checked_inputs(scene, measured, methods, overrides)
    names += peer_names(peers)
    out = os.fspath(out) if out is not None else os.path.join("out", f"{loaded.name}-validate")
    made = make_folders(out)  # a file there fails now, not after the runs
    with held(out, "--out", made):  # one validate at a time writes a folder; one left empty goes again
        rows = []
        for measurement in measurements:
            for method in names:
                job = {
                    "scene": source,
                    "settings": list(overrides),
                    "method": method,
                    "measurement": os.path.abspath(measurement.path),
                    "paths": True,
                }
                rows.append(predict(job))
        found = medians(rows, names)
        result = Validation(rows=rows, medians=found, best=best_method(found), out=out)
        write_validation(result, loaded, measurements, COLUMNS)
    return result
