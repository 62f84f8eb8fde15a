"""A study file: which runs a sweep makes (``contactlab sweep STUDY.toml``; docs/sweep.md).

A study names scenes, methods and axes over any setting, as a full grid, as explicit cells,
or both::

    [study]
    name = "ball_dt"                 # default: the file's name
    record = "summary"               # or "trajectory": each cell also keeps its trajectory.h5

    [grid]
    scenes = ["bouncing_ball", "my_scene.toml"]      # built-in names, or files beside the study
    methods = ["impulse", "penalty"]                 # default: all four
    peers = ["mujoco", "pybullet"]                   # engines beside them (contactlab.peers; default none)
    [grid.set]                                       # axes: a --set path -> its values
    "simulation.dt" = [0.01, 0.005, 0.0025]
    "materials.0.friction" = [0.2, 0.5]

    [[cells]]                                        # cells given one by one
    scene = "box_pyramid"
    method = "constraints"
    set = { "method.constraints.iterations" = 20 }

Any setting a scene file holds is an axis, by the path ``contactlab run --set`` takes
(``simulation.dt``, ``method.impulse.iterations``, ``materials.0.restitution``,
``bodies.0.array.count`` for the size of a pile). :func:`load_study` reads and checks the
file — every cell's scene is loaded with its settings, so a wrong path or value fails before
anything runs, with the field path of the mistake — and returns a :class:`Study`, whose
:class:`Cell` s each carry a key: a hash of the scene's text, the method, the settings, what
is recorded and the contactlab version, which is how a rerun knows a cell is done.
"""

from __future__ import annotations

import copy
import hashlib
import itertools
import json
import math
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from . import __version__, budget
from .errors import InputError
from .methods import AVAILABLE
from .peers import PEERS, engine
from .scene.loader import read_source, scene_from_raw
from .scene.schema import did_you_mean, show
from .scene.toml import parse_toml

RECORD = ("summary", "trajectory")
RUN_FIELDS = {  # a run-level refusal (contactlab.simulation.check_run) -> the scene settings behind it
    "dt": ("simulation.dt",),
    "duration": ("simulation.duration",),
    "": ("simulation.dt", "simulation.duration"),  # dt longer than the duration
    "record_every": ("simulation.duration", "simulation.dt"),  # the samples would not fit in memory
}
REMEDIES = budget.Remedies(  # what a study offers a cell that would not fit (it records every step)
    disk="give the cell a shorter simulation.duration or a longer simulation.dt",
    memory="give the cell a shorter simulation.duration or a longer simulation.dt, or stream each cell's "
    'samples to a file with record = "trajectory" under [study]',
    model="simulate fewer bodies, particles or cloth vertices in the cell",
)
MAX_CELLS = 100_000  # cells a study may have
CHECK_NEWS_SECONDS = 2.0  # s: checking a study longer than this says how far it got (then every 5 s)
KEYS = {
    "study": ("name", "record", "description"),
    "grid": ("scenes", "methods", "peers", "set"),
    "cells": ("scene", "method", "set"),
}


@dataclass(frozen=True)
class Cell:
    """One run of a study: ``scene`` (a built-in name or a path), ``method``, ``settings``
    (``--set`` path -> value, in the order given) and ``key`` (hex digest naming it)."""

    scene: str
    method: str
    settings: tuple
    """((path, value), ...)"""
    record: str
    key: str

    def overrides(self) -> list:
        """The settings as ``--set`` strings, the method last: ``["simulation.dt=0.01", ...]``; a
        peer's cell (contactlab.peers) loads the scene with the method its file names."""
        method = [] if self.method in PEERS else [f"simulation.method={self.method}"]
        return [f"{path}={toml_value(value)}" for path, value in self.settings] + method


@dataclass
class Study:
    """A study read from ``path``: ``name``, ``record``, ``cells`` and the ``axes`` (the
    setting paths any cell sets, in order of first appearance)."""

    name: str
    path: str
    record: str
    cells: list
    axes: list = field(default_factory=list)
    description: str = ""


def toml_value(value: object) -> str:
    """``value`` spelt as TOML (what ``--set`` reads back to the same value)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf") if math.isinf(value) else repr(value)
    if isinstance(value, int):
        return str(value)
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(item) for item in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{json.dumps(str(k))} = {toml_value(v)}" for k, v in value.items()) + "}"
    raise InputError("set", f"a value of a kind TOML has no spelling for: {show(value)}")


def load_study(path: str | os.PathLike[str], log: Callable[[str], object] | None = None) -> Study:
    """Read, check and expand the study file ``path``; InputError with the field path of any
    mistake. ``log``: a function given a line of news every few seconds of a long check."""
    name, text, origin = read_source(path)
    raw = parse_toml(text)
    _check_keys(raw, ("study", "grid", "cells"), "")
    head = _table(raw.get("study", {}), "study")
    _check_keys(head, KEYS["study"], "study")
    record = head.get("record", "summary")
    if record not in RECORD:
        raise InputError("study.record", f"expected one of {', '.join(RECORD)}, found {show(record)}")
    study_name = head.get("name", name)
    if not isinstance(study_name, str) or not study_name or os.sep in study_name or "/" in study_name:
        raise InputError("study.name", f"expected a name usable as a folder name, found {show(study_name)}")
    base = Path(origin).parent
    specs = []  # (field, scene, method, settings)
    if "grid" in raw:
        specs += _grid_cells(_table(raw["grid"], "grid"))
    cells = raw.get("cells", [])
    if not isinstance(cells, list):
        raise InputError("cells", f"expected [[cells]] tables, found {show(cells)}")
    for index, cell in enumerate(cells):
        where = f"cells[{index}]"
        cell = _table(cell, where)
        _check_keys(cell, KEYS["cells"], where)
        for key in ("scene", "method"):
            if key not in cell:
                raise InputError(f"{where}.{key}", f"a cell needs a {key}")
        specs.append((where, cell["scene"], cell["method"], _settings(cell.get("set", {}), f"{where}.set")))
    if not specs:
        raise InputError("", "the study has no cells: give a [grid] with scenes, or [[cells]]")
    if len(specs) > MAX_CELLS:
        raise InputError(
            "grid", f"the study has {len(specs):,} cells, more than the {MAX_CELLS:,} a study may have; split it"
        )
    return Study(
        study_name,
        origin,
        record,
        _checked_cells(specs, base, record, log),
        axes=list(dict.fromkeys(path for *_, settings in specs for path, _ in settings)),
        description=head.get("description", ""),
    )


def _grid_cells(grid):
    _check_keys(grid, KEYS["grid"], "grid")
    scenes = _list(grid.get("scenes"), "grid.scenes")
    methods = _list(grid.get("methods", list(AVAILABLE)), "grid.methods")
    peers = _list(grid["peers"], "grid.peers") if "peers" in grid else []
    for peer in peers:
        if not isinstance(peer, str) or peer not in PEERS:
            raise InputError("grid.peers", f"unknown peer {show(peer)}{did_you_mean(peer, PEERS)}")
        engine(peer, "grid.peers")  # installed, or the one line that says what to install
    axes = _table(grid.get("set", {}), "grid.set")
    values = []
    for path, options in axes.items():
        options = _list(options, f"grid.set.{toml_value(path)}")
        values.append([(path, value) for value in options])
    return [
        ("grid", scene, method, tuple(chosen))
        for scene in scenes
        for method in [*methods, *peers]
        for chosen in itertools.product(*values)
    ]


def _field(where, key):
    """Where a cell's ``key`` ("scene", "method" or "set") is written in the study file."""
    return (
        {"scene": "grid.scenes", "method": "grid.methods", "set": "grid.set"}[key]
        if where == "grid"
        else f"{where}.{key}"
    )


def _checked_cells(specs, base, record, log=None):
    """The Cells of ``specs``, checked by loading their scenes as a run would, though not once
    per cell (a millisecond each; 100,000 cells took 70 s): each scene with each method once, on
    the settings of a cell that has that method, and each distinct setting (path = value) once,
    on the settings of the scene's first cell with that one changed. Every method and every
    value is so checked, and a mistake named by its field; settings that are each valid but
    clash together (a body's material with a materials list another setting shortened, say)
    fail when their cell runs, recorded as an ``error`` row. ``log``: a function given a line
    every few seconds while checking lasts more than :data:`CHECK_NEWS_SECONDS`."""
    cells, seen, scenes, checked, loads = [], set(), {}, set(), 0
    plain, limited = {}, set()  # each (scene, method) as its file has it; the run limits checked
    started = time.monotonic()
    news = started + CHECK_NEWS_SECONDS  # when to say how far the check got
    for where, scene, method, settings in specs:
        if not isinstance(scene, str) or not scene:
            raise InputError(
                _field(where, "scene"), f"expected a built-in scene name or a .toml file, found {show(scene)}"
            )
        if not isinstance(method, str) or method not in (*AVAILABLE, *PEERS):
            raise InputError(
                _field(where, "method"),
                f"unknown method {show(method)}{did_you_mean(method, (*AVAILABLE, *PEERS))}",
            )
        if method in PEERS:
            engine(method, _field(where, "method") if where != "grid" else "grid.peers")
        source = scene if not scene.endswith(".toml") or os.path.isabs(scene) else str(base / scene)
        if source not in scenes:
            try:
                name, text, origin = read_source(source)
                scenes[source] = (name, text, origin, parse_toml(text), settings)
            except InputError as error:
                raise InputError(_field(where, "scene"), error.message) from None
        name, text, origin, raw, first = scenes[source]
        cell = Cell(source, method, settings, record, _key(text, method, settings, record))
        if cell.key in seen:  # the same cell twice (grid and list) runs once
            continue
        seen.add(cell.key)
        cells.append(cell)
        trials = []  # the settings to load the scene with: the cell's, or the first cell's with one changed
        if (source, method) not in checked:
            checked.add((source, method))
            checked.update((source, path, toml_value(value)) for path, value in settings)
            trials.append(settings)
        for path, value in settings:
            if (source, path, toml_value(value)) not in checked:
                checked.add((source, path, toml_value(value)))
                trials.append(tuple((p, v) for p, v in first if p != path) + ((path, value),))
        for trial in trials:
            loads += 1
            try:
                scene_from_raw(name, copy.deepcopy(raw), origin, Cell(source, method, trial, record, "").overrides())
                if (source, method) not in plain:  # the scene as its file has it: what a cell's run is held to
                    plain[source, method] = scene_from_raw(
                        name, copy.deepcopy(raw), origin, Cell(source, method, (), record, "").overrides()
                    )
            except InputError as error:  # named by the setting it came from, where it did
                raise _cell_error(error, (error.field or "",), where, scene, method, settings, trial) from None
        _check_limits(plain[source, method], settings, record, limited, where, scene)
        if log is not None and time.monotonic() > news:
            log(
                f"checking the study: {len(seen):,} of {len(specs):,} cells ({loads:,} scene loads), "
                f"{time.monotonic() - started:.0f} s so far"
            )
            news = time.monotonic() + 5.0
    return cells


def _check_limits(loaded, settings, record, limited, where, scene):
    """The limits ``simulate`` holds a run to (:func:`contactlab.simulation.check_run`: dt,
    duration, steps, memory), for a cell of ``loaded`` (its scene and method as the file has them)
    with ``settings``' dt and duration where it sets them; each distinct (scene, method, dt,
    duration) once (``limited``, the ones checked). The memory is the file's model's: a setting
    that changes the model's size is held to it when its cell runs."""
    from .simulation import check_run

    given = {_dotted(path): value for path, value in settings}
    dt, duration = given.get("simulation.dt", loaded.dt), given.get("simulation.duration", loaded.duration)
    key = (id(loaded), repr(dt), repr(duration))
    if key in limited:
        return
    limited.add(key)
    try:  # the limits simulate holds a run to (contactlab run's), before a cluster starts
        check_run(
            loaded.model,
            loaded.method,
            dt,
            duration,
            loaded.options[loaded.method],
            loaded.integrator,
            scene_name=loaded.name,
            streamed=record == "trajectory",
            remedies=REMEDIES,
        )
    except InputError as error:
        fields = RUN_FIELDS.get(error.field or "", (error.field or "",))
        raise _cell_error(error, fields, where, scene, loaded.method, settings) from None


def _cell_error(error, fields, where, scene, method, settings, loaded_with=None):
    """``error`` of one cell as one InputError, placed at the first of ``fields`` (scene setting
    paths) that the settings the scene was loaded with (``loaded_with``; default the cell's
    ``settings``) give, or at the cell with the first field named."""
    paths = {_dotted(path): path for path, _ in (settings if loaded_with is None else loaded_with)}
    setting = next((paths[_dotted(name)] for name in fields if _dotted(name) in paths), None)
    place = f"{_field(where, 'set')}.{toml_value(setting)}" if setting else where
    inner = f"{fields[0]}: " if fields[0] and not setting else ""
    return InputError(place, f"{scene} with {method} {_described(settings)}: {inner}{error.message}")


def _dotted(path):
    return path.replace("[", ".").replace("]", "")


def _key(scene_text, method, settings, record):
    identity = {
        "scene": hashlib.sha256(scene_text.encode()).hexdigest(),
        "method": method,
        "settings": [[path, toml_value(value)] for path, value in settings],
        "record": record,
        "contactlab": __version__,
    }
    return hashlib.sha256(json.dumps(identity, sort_keys=True).encode()).hexdigest()[:20]


def _described(settings):
    return "(" + ", ".join(f"{path} = {show(value)}" for path, value in settings) + ")" if settings else "(defaults)"


def _settings(table, where):
    table = _table(table, where)
    return tuple((str(path), value) for path, value in table.items())


def _table(value, where):
    if not isinstance(value, dict):
        raise InputError(where, f"expected a table, found {show(value)}")
    return value


def _list(value, where):
    if value is None:
        raise InputError(where, "missing: give a list")
    if not isinstance(value, list) or not value:
        raise InputError(where, f"expected a list of at least one value, found {show(value)}")
    return value


def _check_keys(table, known, where):
    for key in table:
        if key not in known:
            place = f"{where}.{key}" if where else key
            raise InputError(place, f"unknown key{did_you_mean(key, known)}")
