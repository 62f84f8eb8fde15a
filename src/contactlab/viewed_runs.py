"""The runs the viewer shows, opened from run folders, ``contactlab compare`` folders or
:class:`contactlab.simulation.Run` objects, each with its Model rebuilt from its summary when
it can be (for the contacts, :mod:`contactlab.sample_contacts`).
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from .errors import InputError
from .record import TRAJECTORY, load_run

if TYPE_CHECKING:
    from .model import Model
    from .simulation import Run


@dataclass(eq=False)
class Shown:
    """One run in the viewer: ``label`` ("scene — method"), ``arrays`` (a trajectory: a
    :class:`contactlab.store.TrajectoryFile` or the dict of a Run), ``summary`` (the run's
    summary.json, {} unknown), ``model`` (its Model, None when it cannot be rebuilt: no contacts
    then), ``offset`` (3,) [m] where its origin sits in the viewer, ``source`` what names it in
    an error (its folder; "arrays" for a Run). The Viewer adds its drawing state to it: the
    bodies' scene handles and colours, the colour scales' ranges."""

    label: str
    arrays: object
    summary: dict
    model: object = None
    offset: np.ndarray = field(default_factory=lambda: np.zeros(3))
    source: str = "arrays"


def _is_run(directory):
    return any(os.path.isfile(os.path.join(directory, name)) for name in (TRAJECTORY, "trajectory.npz"))


def run_folders(directory: str, field: str = "RUN_DIR") -> list[str]:
    """The run folders ``directory`` stands for: itself when it holds a trajectory, else its
    sub-folders that do (a ``contactlab compare`` output: one per method, in the order of
    :data:`contactlab.methods.AVAILABLE`, then by name; only the methods of its comparison.csv
    where it has one, so the folders an earlier comparison into the same --out left are not
    shown as this one's). InputError naming the folder otherwise."""
    from .methods import AVAILABLE

    directory = os.fspath(directory)
    if not os.path.isdir(directory):
        raise InputError(
            field,
            f"{directory} is not a folder; give the output folder of 'contactlab run' "
            f"(its --out) or of 'contactlab compare'",
        )
    if _is_run(directory):
        return [directory]
    compared = _compared_methods(directory)
    names = sorted(
        (
            name
            for name in os.listdir(directory)
            if _is_run(os.path.join(directory, name)) and (compared is None or name in compared)
        ),
        key=lambda name: (AVAILABLE.index(name) if name in AVAILABLE else len(AVAILABLE), name),
    )
    if not names:
        raise InputError(
            field,
            f"found no {TRAJECTORY} in {directory} nor in its sub-folders; give the output "
            f"folder of 'contactlab run' (its --out) or of 'contactlab compare'",
        )
    return [os.path.join(directory, name) for name in names]


def _compared_methods(directory: str) -> set[str] | None:
    """The methods (and peers) of the comparison.csv in ``directory``, or None where there is
    none that can be read."""
    import csv

    try:
        with open(os.path.join(directory, "comparison.csv"), encoding="utf-8", newline="") as stream:
            return {row["method"] for row in csv.DictReader(stream)}
    except (OSError, KeyError, csv.Error, UnicodeDecodeError):
        return None


def model_of(summary: Mapping[str, Any], arrays: Mapping[str, Any]) -> Model | None:
    """The Model of a run, loaded again from its summary's ``source`` (scene and overrides), or
    from the built-in scene its summary names; None when neither loads or the model's body and
    particle counts differ from the trajectory's (the scene file changed since)."""
    from .scene import load_scene

    source = summary.get("source")
    attempts = (
        [(source["scene"], source.get("overrides", []))] if isinstance(source, dict) and "scene" in source else []
    )
    if "scene" in summary:
        attempts.append((summary["scene"], [f"simulation.method={summary.get('method', 'impulse')}"]))
    if any(key not in arrays for key in ("body_position", "particle_position")):
        return None  # not a whole trajectory: the viewer says so, naming its folder
    shapes = getattr(arrays, "shapes", None) or {
        key: np.shape(arrays[key]) for key in ("body_position", "particle_position")
    }
    for scene, overrides in attempts:
        try:
            model = load_scene(scene, overrides).model
        except (InputError, OSError, TypeError):
            continue
        if (model.body_count, model.particle_count) == (shapes["body_position"][1], shapes["particle_position"][1]):
            return model
    return None


def _label(summary, fallback):
    return f"{summary['scene']} — {summary['method']}" if "scene" in summary else fallback


def open_runs(sources: Iterable[str | os.PathLike[str] | Run], field: str = "RUN_DIR") -> list[Shown]:
    """A :class:`Shown` for every run of ``sources``: run folders, compare folders (every
    method's run), or :class:`contactlab.simulation.Run` objects (shown from their arrays,
    in memory or on disk). InputError for a folder that is not a run."""
    shown = []
    for source in sources:
        if hasattr(source, "arrays") and hasattr(source, "summary"):
            summary = source.summary
            model = getattr(source, "model", None) or model_of(summary, source.arrays)
            shown.append(Shown(_label(summary, "run"), source.arrays, summary, model))
            continue
        for directory in run_folders(os.fspath(source), field):
            arrays, summary = load_run(directory, field)
            shown.append(
                Shown(
                    _label(summary, os.path.basename(os.path.normpath(directory))),
                    arrays,
                    summary,
                    model_of(summary, arrays),
                    source=directory,
                )
            )
    if not shown:
        raise InputError(field, "no run given; give a run's output folder")
    return shown
