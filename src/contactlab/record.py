"""Recorder: samples states and diagnostics every K steps, in memory or streamed to disk.

The simulation never does I/O itself: it hands states to :meth:`Recorder.sample`, or the
compiled loop records into rows of the Recorder's buffer (:meth:`Recorder.reserve`, then
:meth:`Recorder.commit`). The Recorder gathers them in chunks of
about ``store.CHUNK_BYTES``; each chunk is kept in memory (``simulate(...).arrays``) or, when
the run streams (``simulate(..., trajectory=path)``), handed to a ``store.TrajectoryWriter`` and
forgotten, so a long run's memory stays flat. Either way :class:`Totals` keeps what the summary
needs (energies, depths, solver figures) as the chunks pass. Other files are written whole,
through :func:`atomic_path` (a temporary file, then a rename, so an interrupted run leaves no
half-written file). The arrays are documented in ``docs/trajectory.md``.
"""

from __future__ import annotations

import contextlib
import functools
import json
import math
import os
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from . import diagnostics, interrupts, store, surfaces
from .collision import collide
from .diagnostics import SERIES
from .errors import InputError
from .model import derived
from .state import array_shapes
from .trajectory import check_arrays, check_shapes

if TYPE_CHECKING:
    from .contacts import Contacts
    from .model import Model
    from .state import State

WHOLE_SERIES = ("contact_count", "solver_iterations")  # 64-bit whole numbers; the rest are floats
DRAWN = (  # what a picture of a run reads (render, viewer, export): its time, poses and surfaces
    "time",
    "body_position",
    "body_orientation",
    "particle_position",
    "particle_radius",
    "particle_cloth",
    "triangles",
    "body_surface_vertices",
    "body_surface_vertex_start",
    "body_surface_triangles",
    "body_surface_triangle_start",
    "obstacle_vertices",
    "obstacle_triangles",
)
TRAJECTORY = "trajectory.h5"  # the file name of a run's trajectory in its output folder


def series_rows(model: Model) -> dict[str, tuple[tuple[int, ...], type]]:
    """name -> (shape of one sample, dtype) of every series of a run of ``model``."""
    return dict(_series_rows(model.body_count, model.particle_count))


def sample_bytes(model: Model) -> int:
    """Bytes one sample of a run of ``model`` takes (every series of :func:`series_rows`)."""
    return _sample_bytes(model.body_count, model.particle_count)


@functools.lru_cache(maxsize=64)
def _series_rows(body_count: int, particle_count: int) -> tuple[tuple[str, tuple[tuple[int, ...], type]], ...]:
    """``series_rows`` of B bodies and P particles, as pairs (kept: a run asks it three times)."""
    shapes = array_shapes(body_count, particle_count)
    return tuple((name, (shapes.get(name, ()), np.int64 if name in WHOLE_SERIES else np.float64)) for name in SERIES)


@functools.lru_cache(maxsize=64)
def _sample_bytes(body_count: int, particle_count: int) -> int:
    """``sample_bytes`` of B bodies and P particles."""
    return sum(
        int(np.prod(shape, dtype=np.int64)) * np.dtype(dtype).itemsize
        for _, (shape, dtype) in _series_rows(body_count, particle_count)
    )


def static_arrays(model: Model) -> dict[str, np.ndarray]:
    """What does not change during a run of ``model``: body_names (B,), the cloth topology
    triangles (F, 3) and particle_cloth (P,), and the shapes' surfaces for drawing and export
    (contactlab.surfaces). Built once a model (read-only arrays): a study runs one model many
    times, and the surfaces cost a tiny run a tenth of its time."""
    return dict(_static_arrays(model))


@derived
def _static_arrays(model: Model) -> dict[str, np.ndarray]:
    """``static_arrays``, built once and kept with the Model (``model.derived``)."""
    arrays = {
        "body_names": np.array(model.body_names, dtype=str),
        "triangles": np.array(model.triangles, dtype=np.int64).reshape(-1, 3),
        "particle_cloth": np.array(model.particle_cloth, dtype=np.int64),
        **surfaces.surface_arrays(model),
    }
    for array in arrays.values():
        array.flags.writeable = False
    return arrays


@dataclass
class Totals:
    """What a run's summary says of all its samples, gathered chunk by chunk."""

    count: int = 0
    """samples"""
    first_time: float = math.nan
    """s"""
    last_time: float = math.nan
    """s"""
    energy_initial: float = math.nan
    """J, kinetic + potential + elastic"""
    energy_final: float = math.nan
    """J"""
    energy_max: float = -math.inf
    """J, the largest finite one (the initial one if none is)"""
    max_penetration: float = 0.0
    """m, NaNs skipped"""
    final_penetration: float = math.nan
    """m"""
    max_iterations: int = 0
    max_residual: float = 0.0

    def add(self, chunk: Mapping[str, np.ndarray]) -> None:
        """Take in the samples of ``chunk`` (name -> array of n rows)."""
        n = len(chunk["time"])
        if n == 0:
            return
        energy = chunk["energy_kinetic"] + chunk["energy_potential"] + chunk["energy_elastic"]
        if self.count == 0:
            self.first_time, self.energy_initial = float(chunk["time"][0]), float(energy[0])
        self.count += n
        self.last_time, self.energy_final = float(chunk["time"][-1]), float(energy[-1])
        top = float(energy.max())  # the largest finite one where finite (NaN and +inf would show)
        if not math.isfinite(top):
            finite = energy[np.isfinite(energy)]
            top = float(finite.max()) if finite.size else -math.inf
        self.energy_max = max(self.energy_max, top)
        deepest = chunk["max_penetration"].max()  # NaN where one is
        self.max_penetration = float(
            max(self.max_penetration, deepest)
            if deepest == deepest
            else np.nanmax(np.append(chunk["max_penetration"], self.max_penetration))
        )
        self.final_penetration = float(chunk["max_penetration"][-1])
        self.max_iterations = max(self.max_iterations, int(np.max(chunk["solver_iterations"])))
        self.max_residual = float(max(self.max_residual, np.max(chunk["solver_residual"])))

    def energy(self) -> dict[str, float]:
        """The summary's energy: {initial, final, max} [J]."""
        return {
            "initial": self.energy_initial,
            "final": self.energy_final,
            "max": self.energy_max if self.energy_max > -math.inf else self.energy_initial,
        }


class Recorder:
    """Collects the samples (T of them) of a run of ``model``, every ``record_every`` steps;
    with a ``sink`` (store.TrajectoryWriter) they go to it in chunks instead of staying in memory.
    ``samples``: about how many there will be (a buffer no longer than that).

    Samples come in three ways, all through the buffer: a State (``sample``), arrays recorded
    elsewhere (``extend``), or rows handed out by ``reserve`` that a writer fills in place and
    ``commit`` takes in — the compiled loop records straight into the buffer, with no arrays of
    its own to allocate and copy each chunk of steps."""

    def __init__(
        self,
        model: Model,
        record_every: int = 1,
        sink: store.TrajectoryWriter | None = None,
        samples: int | None = None,
    ) -> None:
        self.model = model
        self.record_every = record_every
        self.sink = sink
        self.rows = series_rows(model)
        self.chunk_samples: int = max(  # type: ignore[assignment]  # min(n, inf) is n
            1, min(store.CHUNK_BYTES // max(1, sample_bytes(model)), samples or math.inf)
        )
        # the chunk being filled, name -> (chunk_samples, ...); None until a sample needs it (a
        # full one kept in memory is passed on whole, not copied, and a new one made)
        self.buffer: dict[str, np.ndarray] | None = None
        self.filled = 0  # samples in the buffer
        self.apart: dict[str, np.ndarray] | None = None  # reserve's rows for more than a buffer holds
        self.kept: list[dict[str, np.ndarray]] = []  # without a sink: the chunks passed on, in order
        self.last: dict[str, np.ndarray] = None  # type: ignore[assignment]  # set by the first flush; name -> the last sample passed on (one row)
        self.totals = Totals()

    def sample(self, state: State, info: Any = None) -> Contacts:
        """Record ``state`` (``info``: the StepInfo of the step that made it, None: no step);
        penetration is measured on its own positions (collision pass), whose Contacts it returns."""
        contacts = collide(self.model, state)
        rows = self.reserve(1)
        for name, value in diagnostics.sample_of(self.model, state, contacts, info).items():
            rows[name][0] = value
        self.commit(1)
        return contacts

    def extend(self, samples: Mapping[str, np.ndarray]) -> None:
        """Add samples recorded elsewhere: ``samples`` maps each name of SERIES to an array with
        one row per sample."""
        count = len(samples["time"])
        rows = self.reserve(count)
        for name in SERIES:
            rows[name][...] = samples[name]
        self.commit(count)

    def reserve(self, count: int) -> dict[str, np.ndarray]:
        """Rows for the next ``count`` samples, name -> an array (count, ...) of each series of
        SERIES, in that order, to be written in place and then taken in by ``commit``: the
        buffer's next rows (passed on first where it has no room for them), or arrays of their
        own where there are more than a buffer holds."""
        if self.filled + count > self.chunk_samples:
            self.flush()
        if count > self.chunk_samples:
            self.apart = {name: np.empty((count, *shape), dtype=dtype) for name, (shape, dtype) in self.rows.items()}
            return self.apart
        if self.buffer is None:
            self.buffer = {
                name: np.empty((self.chunk_samples, *shape), dtype=dtype) for name, (shape, dtype) in self.rows.items()
            }
        end = self.filled + count
        return {name: values[self.filled : end] for name, values in self.buffer.items()}

    def steps_that_fit(self) -> int:
        """The most steps in a row whose samples the buffer holds at once, at least 1 (``count``
        steps make at most ``count // record_every + 1`` samples)."""
        return max(1, (self.chunk_samples - 1) * self.record_every)

    def commit(self, count: int) -> None:
        """Take in the first ``count`` samples of the rows ``reserve`` gave last, written by now."""
        if self.apart is not None:
            apart, self.apart = self.apart, None
            if count:
                self._pass_on({name: values[:count] for name, values in apart.items()}, reused=False)
            return
        self.filled += count
        if self.filled == self.chunk_samples:
            self.flush()

    def latest(self, names: Iterable[str] = SERIES) -> dict[str, np.ndarray]:
        """The last sample of the series ``names``, as arrays of one row."""
        if self.filled and self.buffer is not None:
            buffer = self.buffer
            return {name: buffer[name][self.filled - 1 : self.filled].copy() for name in names}
        return {name: self.last[name].copy() for name in names}

    def flush(self) -> None:
        """Pass the samples in the buffer on: to the sink, or to the chunks kept in memory."""
        if not self.filled or self.buffer is None:
            return
        chunk = {name: values[: self.filled] for name, values in self.buffer.items()}
        if self.sink is None and self.filled == self.chunk_samples:
            self.buffer = None  # kept whole: the next sample makes a new one
        self.filled = 0
        self._pass_on(chunk, reused=self.buffer is not None)

    def _pass_on(self, chunk: dict[str, np.ndarray], reused: bool) -> None:
        """Hand the samples ``chunk`` (name -> rows) on: to the sink, written at once, or to the
        chunks kept in memory, copied where ``reused`` (rows of the buffer, to be filled again)."""
        self.totals.add(chunk)
        if self.sink is not None:
            self.sink.append(chunk)
            self.last = {name: values[-1:].copy() for name, values in chunk.items()}
            return
        if reused:
            chunk = {name: values.copy() for name, values in chunk.items()}
        self.kept.append(chunk)
        self.last = {name: values[-1:] for name, values in chunk.items()}

    def arrays(self) -> dict[str, np.ndarray]:
        """The trajectory held in memory, as arrays: time (T,), body_position (T,B,3), … and
        the static arrays (:func:`static_arrays`)."""
        self.flush()
        out = {
            name: (
                (self.kept[0][name] if len(self.kept) == 1 else np.concatenate([chunk[name] for chunk in self.kept]))
                if self.kept
                else np.zeros((0, *shape), dtype=dtype)
            )
            for name, (shape, dtype) in self.rows.items()
        }
        out.update(static_arrays(self.model))
        return out


def streaming_recorder(model: Model, record_every: int, path: str | os.PathLike[str], samples: int) -> Recorder:
    """A Recorder whose samples (about ``samples`` of them) stream into the trajectory file
    ``path`` (store.TrajectoryWriter); its ``sink.finish(status)`` or ``sink.discard()`` ends the file."""
    writer = store.TrajectoryWriter(path, static_arrays(model), series_rows(model), record_every, expected=samples)
    return Recorder(model, record_every, writer, samples)


@contextlib.contextmanager
def atomic_path(path: str) -> Iterator[str]:
    """Yield a temporary path beside ``path`` (same suffix) to write to; on success it is
    renamed to ``path``, on any failure it is removed, so ``path`` is never half-written.

        with atomic_path("out/video.mp4") as temporary:
            imageio.mimwrite(temporary, frames)
    """
    temporary = None
    try:
        with interrupts.deferred():  # a signal waits until the temporary file is known, to be removed
            temporary = store.temporary_beside(path)
        yield temporary
        with interrupts.deferred():  # renamed and noted as written, or neither
            os.replace(temporary, path)
            interrupts.note_written(path)
    except BaseException as error:
        if temporary is not None and os.path.exists(temporary):
            os.unlink(temporary)
        if isinstance(error, OSError) and error.filename is None and error.errno is not None:
            error.filename = path  # a write's ENOSPC names no file: the message then says which output
        raise


def make_folders(path: str, field: str = "--out") -> list[str]:
    """Create the folder ``path`` and whichever of its parents are missing; returns the folders
    created, outermost first (for :func:`remove_empty`). InputError naming ``field`` when one of
    them is something else already (a file, /dev/null), before anything is created."""
    missing = []
    while path and not os.path.isdir(path):
        if os.path.lexists(path):
            raise InputError(field, f"{path} is there and is not a folder; give a new folder or an existing one")
        missing.append(path)
        path = os.path.dirname(path)
    missing.reverse()
    for folder in missing:
        os.makedirs(folder, exist_ok=True)
    return missing


def remove_empty(folders: Sequence[str]) -> None:
    """Remove those of ``folders`` (as :func:`make_folders` returns them) that are empty, innermost first."""
    for folder in reversed(folders):
        with contextlib.suppress(OSError):
            os.rmdir(folder)


def undo_written(paths: Iterable[str], folders: Sequence[str] = ()) -> None:
    """After a failed or interrupted write of several files: remove ``paths`` (those this call
    completed), un-note them (``interrupts.note_written``), and remove the ``folders`` this call
    created (:func:`make_folders`) that are empty again, so nothing of the call remains."""
    for path in paths:
        if os.path.exists(path):
            os.unlink(path)
        interrupts.note_written(path, removed=True)
    remove_empty(folders)


def stamps(paths: Iterable[str]) -> dict[str, tuple[int, int, int] | None]:
    """Each of ``paths`` with its file's identity now (inode, size, modification time [ns]), or
    None where there is none; :func:`replaced` says which files were written since."""
    found: dict[str, tuple[int, int, int] | None] = {}
    for path in paths:
        try:
            status = os.stat(path)
        except OSError:
            found[path] = None
        else:
            found[path] = (status.st_ino, status.st_size, status.st_mtime_ns)
    return found


def replaced(before: Mapping[str, tuple[int, int, int] | None]) -> list[str]:
    """Those paths of ``before`` (:func:`stamps`) whose file is new or replaced since: what another
    process (a Dask worker) completed, every file being renamed into place when complete."""
    now = stamps(before)
    return [path for path, stamp in now.items() if stamp is not None and stamp != before[path]]


def read_trajectory(
    arrays: Mapping[str, Any], keys: Iterable[str], samples: slice | Sequence[int] | np.ndarray | None = None
) -> dict[str, np.ndarray]:
    """The trajectory arrays named in ``keys`` as plain NumPy arrays, from
    ``simulate(...).arrays``, a trajectory file read back (``store.TrajectoryFile``) or the
    dict of an older trajectory.npz; with ``samples`` (a slice, or sample indices in
    increasing order) only those samples of the series (the static arrays whole), read from a
    file without reading the rest. InputError("arrays", ...) when a key is missing (a
    trajectory written before contactlab recorded surfaces) or there is no sample."""
    missing = [key for key in keys if key not in arrays]
    if missing:
        raise InputError(
            "arrays",
            f"not a trajectory with surfaces: missing {', '.join(missing)}; "
            f"record the run again with this version of contactlab",
        )
    if samples is None:
        out = {key: np.asarray(arrays[key]) for key in keys}
    else:
        shapes = getattr(arrays, "shapes", None) or {key: np.shape(arrays[key]) for key in keys}
        check_shapes({key: shapes[key] for key in keys}, "arrays")  # no read beyond the samples there are
        rows = getattr(arrays, "rows", lambda key, chosen: np.asarray(arrays[key])[chosen])
        out = {key: rows(key, samples) if key in SERIES else np.asarray(arrays[key]) for key in keys}
    if "time" in out and len(out["time"]) == 0:
        raise InputError("arrays", "the trajectory has no samples")
    return out


def checked_times(arrays: Mapping[str, Any]) -> np.ndarray:
    """The trajectory's time (T,) [s], read whole and checked (finite, in order, at least one
    sample): what a reader needs to choose the samples it will read."""
    time = read_trajectory(arrays, ("time",))["time"]
    check_arrays({"time": time})
    return time


def sample_count(arrays: Mapping[str, Any]) -> int:
    """T, the samples of a trajectory (a dict of arrays or a store.TrajectoryFile), read
    without reading the series; InputError when it has no time."""
    if "time" not in arrays:
        raise InputError("arrays", "not a trajectory: it has no time")
    shapes = getattr(arrays, "shapes", None)
    return shapes["time"][0] if shapes is not None else len(np.asarray(arrays["time"]))


def _atomic_write(path, write):
    with atomic_path(path) as temporary, open(temporary, "wb") as stream:
        write(stream)


def write_summary(directory: str, summary: Mapping[str, Any]) -> str:
    """Write ``summary.json`` into ``directory`` (atomically); returns its path."""
    path = os.path.join(directory, "summary.json")
    _atomic_write(path, lambda s: s.write((json.dumps(summary, indent=2) + "\n").encode()))
    return path


def load_run(directory: str, field: str = "OUT_DIR") -> tuple[Mapping[str, Any], dict[str, Any]]:
    """(trajectory, summary) of an earlier run's output folder ``directory``. The trajectory is
    trajectory.h5 read back lazily (contactlab.store), or the trajectory.npz of an older
    contactlab read without unpickling anything (contactlab.trajectory.load_npz); render, export
    and the viewer check its arrays. The summary is {} unless summary.json is a regular file
    holding a JSON object that names the scene and the method. A folder that is not a run is an
    InputError on ``field`` (the option or argument that named it)."""
    from .trajectory import load_npz

    path, older = os.path.join(directory, TRAJECTORY), os.path.join(directory, "trajectory.npz")
    if os.path.isfile(path):
        arrays: Mapping[str, Any] = store.open_trajectory(path, field)
    elif os.path.isfile(older):
        arrays, path = load_npz(older, field), older
    else:
        raise InputError(
            field, f"found no {TRAJECTORY} in {directory}; give the folder a 'contactlab run' wrote (its --out)"
        )
    if "body_surface_vertices" not in arrays:
        raise InputError(
            field, f"{path} was written by an older contactlab without the shapes' surfaces; run the scene again"
        )
    summary_path = os.path.join(directory, "summary.json")
    summary = {}
    if os.path.isfile(summary_path):  # never open a FIFO or a device of that name
        try:
            with open(summary_path, encoding="utf-8") as stream:
                summary = json.load(stream)
        except (OSError, ValueError, RecursionError):
            summary = {}
    named = isinstance(summary, dict) and all(isinstance(summary.get(key), str) for key in ("scene", "method"))
    return arrays, summary if named else {}


def write_outputs(directory: str, arrays: Mapping[str, Any], summary: Mapping[str, Any]) -> None:
    """Write a trajectory held in memory (``arrays``) as ``trajectory.h5`` and ``summary`` as
    ``summary.json`` into ``directory`` (created if needed).

    On failure nothing is left behind: no partial file, and no folder this call created.
    """
    made, written = make_folders(directory), []
    try:
        written.append(
            store.write(os.path.join(directory, TRAJECTORY), arrays, series=[name for name in SERIES if name in arrays])
        )
        written.append(write_summary(directory, summary))
    except BaseException:
        undo_written(written, made)
        raise
