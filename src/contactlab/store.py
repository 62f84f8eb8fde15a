"""The trajectory on disk: an HDF5 file (h5py) written in chunks while the run goes, read back lazily.

A run given a path (``simulate(..., trajectory="out/trajectory.h5")``, which ``contactlab run``
and ``contactlab compare`` do) hands its samples to a :class:`TrajectoryWriter` a chunk at a time
(:data:`CHUNK_BYTES`), so the memory a run holds stays flat however long it runs, and a run
stopped by a health check or a signal keeps every sample it made. The file grows under a
temporary name beside its path (``.partial-…``) and is renamed to it when the run ends, however it
ends — completed, diverged or interrupted, which its ``status`` attribute says; a run that fails
otherwise (a bug, a full disk) leaves nothing.

Layout (docs/trajectory.md): one dataset per array of ``diagnostics.SERIES``, T rows, resizable
along T and chunked by samples; the static arrays (names, cloth triangles, surfaces) as plain
datasets; attributes ``format`` (:data:`FORMAT`), ``version`` (:data:`VERSION`), ``status``,
``record_every``. Every chunk of numbers carries a Fletcher-32 checksum, so a damaged file is refused
on reading rather than drawn with wrong numbers. Series are stored uncompressed: floating-point trajectories shrink
only to
0.77–0.81 of their size under lzf or gzip (measured on a pile's positions) while compressing
would cost more time than the steps that made them.

:func:`open_trajectory` reads such a file back as a :class:`TrajectoryFile`, a read-only mapping
whose values are NumPy arrays read on access; :meth:`TrajectoryFile.rows` reads only some
samples, which is how ``render`` (the frames it draws) and ``export`` (every k-th sample) read
a long run without holding all of it.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Collection, Mapping, Sequence
from typing import Any

import h5py
import numpy as np

from . import interrupts
from .errors import InputError, first_line

FORMAT = "contactlab trajectory"
VERSION = 1
CHUNK_BYTES = 1 << 20  # bytes: a chunk of samples of one series is about this big (one sample at least)
STATUSES = ("running", "complete", "diverged", "interrupted")
_TEXT = h5py.string_dtype()  # UTF-8 strings (body names)


class TrajectoryWriter:
    """Streams the samples of one run into the HDF5 file ``path``.

    ``static``: name -> array written once (the topology and surfaces of
    ``record.static_arrays``); ``rows``: name -> (shape of one sample, dtype) of each series;
    ``expected``: about how many samples the run will make (chunks are no longer than that, so
    a short run's file is small; more may come).
    :meth:`append` adds samples, :meth:`finish` renames the file into place, :meth:`discard`
    removes it. Opening and finishing defer signals (a signal never leaves a file nobody removes).
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        static: Mapping[str, Any],
        rows: Mapping[str, tuple[tuple[int, ...], Any]],
        record_every: int = 1,
        expected: int = 1 << 16,
    ) -> None:
        self.path = os.fspath(path)
        directory = os.path.dirname(os.path.abspath(self.path))
        if not os.path.isdir(directory):
            raise InputError("trajectory", f"the folder {directory} does not exist; create it first")
        self.count = 0
        with interrupts.deferred():
            self.temporary = temporary_beside(self.path)
            try:
                self.file = h5py.File(self.temporary, "w")
                self.file.attrs.update(format=FORMAT, version=VERSION, status="running", record_every=record_every)
                for name, value in static.items():
                    value = np.asarray(value)
                    checked = {"fletcher32": True, "chunks": True} if value.size and value.dtype.kind != "U" else {}
                    self.file.create_dataset(
                        name, data=value.astype(_TEXT) if value.dtype.kind == "U" else value, **checked
                    )
                self.series, self.empty = {}, {}
                for name, (shape, dtype) in rows.items():
                    sample_size = int(np.prod(shape, dtype=np.int64))
                    if sample_size == 0 and shape:  # (T, 0, 3): nothing to store, written at the end
                        self.empty[name] = (shape, dtype)
                        continue
                    chunk = max(1, min(CHUNK_BYTES // (sample_size * np.dtype(dtype).itemsize), expected, 1 << 16))
                    self.series[name] = self.file.create_dataset(
                        name,
                        shape=(0, *shape),
                        maxshape=(None, *shape),
                        dtype=dtype,
                        chunks=(chunk, *shape),
                        fletcher32=True,
                    )
            except BaseException:
                self._remove()
                raise

    def append(self, samples: Mapping[str, np.ndarray]) -> None:
        """Add the samples ``samples`` (name -> array of n rows, every series the same n)."""
        count = len(next(iter(samples.values()))) if samples else 0
        if count == 0:
            return
        for name, dataset in self.series.items():
            dataset.resize(self.count + count, axis=0)
            dataset[self.count :] = samples[name]
        self.count += count
        self.file.flush()  # what is written so far is readable if the process is killed

    def finish(self, status: str = "complete") -> str:
        """Close the file, mark it with ``status`` (one of STATUSES) and rename it to its path
        (noted as written, :func:`contactlab.interrupts.note_written`); returns the path."""
        with interrupts.deferred():
            try:
                for name, (shape, dtype) in self.empty.items():
                    self.file.create_dataset(name, shape=(self.count, *shape), dtype=dtype)
                self.file.attrs["status"] = status
                self.file.close()
                os.replace(self.temporary, self.path)
            except BaseException:
                self._remove()
                raise
            interrupts.note_written(self.path)
        return self.path

    def discard(self) -> None:
        """Close and remove the file: the run left nothing."""
        with interrupts.deferred():
            self._remove()

    def _remove(self):
        file = getattr(self, "file", None)
        if file is not None and file.id.valid:
            file.close()
        if os.path.exists(self.temporary):
            os.unlink(self.temporary)


def temporary_beside(path: str) -> str:
    """An empty file beside ``path`` named ``.partial-<random><name>``, with the usual rights
    (mkstemp makes it private)."""
    handle, temporary = tempfile.mkstemp(
        dir=os.path.dirname(os.path.abspath(path)), prefix=".partial-", suffix=os.path.basename(path)
    )
    os.close(handle)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(temporary, 0o666 & ~umask)
    return temporary


def write(
    path: str | os.PathLike[str],
    arrays: Mapping[str, Any],
    record_every: int = 1,
    status: str = "complete",
    series: Collection[str] = (),
) -> str:
    """Write the trajectory ``arrays`` (held in memory: name -> array) to the HDF5 file ``path``
    at once, through the same writer a streaming run uses; the names in ``series`` are the
    per-sample ones (T rows), the rest are static."""
    static = {name: value for name, value in arrays.items() if name not in series}
    rows = {name: (np.shape(arrays[name])[1:], np.asarray(arrays[name]).dtype) for name in series}
    writer = TrajectoryWriter(
        path, static, rows, record_every, expected=len(arrays["time"]) if "time" in series else 1 << 16
    )
    try:
        writer.append({name: np.asarray(arrays[name]) for name in series})
    except BaseException:
        writer.discard()
        raise
    return writer.finish(status)


class TrajectoryFile(Mapping):
    """A trajectory file read back: a read-only mapping name -> NumPy array, each array read
    from the file when it is asked for (and not kept); ``status`` and ``record_every`` from
    its attributes; :meth:`rows` reads only some samples of a series. The file is open only
    while an array is being read."""

    def __init__(self, path: str | os.PathLike[str], field: str = "OUT_DIR") -> None:
        self.path, self.field = os.fspath(path), field
        with self._open() as file:
            if file.attrs.get("format") != FORMAT:
                raise InputError(field, f"{self.path} is an HDF5 file but not a contactlab trajectory")
            version = int(file.attrs.get("version", 0))
            if version > VERSION:
                raise InputError(
                    field,
                    f"{self.path} was written by a newer contactlab (trajectory format "
                    f"{version}, this one reads {VERSION}); update contactlab",
                )
            self.status = str(file.attrs.get("status", "complete"))
            self.record_every = int(file.attrs.get("record_every", 1))
            self.names = tuple(file.keys())
            self.shapes = {name: file[name].shape for name in self.names}
            kinds = {name: file[name].dtype for name in self.names}
        bad = [name for name, dtype in kinds.items() if dtype.kind == "O" and not h5py.check_string_dtype(dtype)]
        if bad:
            raise InputError(
                field, f"{self.path} holds {bad[0]} of a type contactlab never writes: this trajectory is damaged"
            )

    def _open(self):
        try:
            return h5py.File(self.path, "r")
        except (OSError, ValueError) as error:
            raise InputError(
                self.field,
                f"{self.path} is not a trajectory contactlab can read ({first_line(error)}); run the scene again",
            ) from None

    def __getitem__(self, name):
        if name not in self.names:
            raise KeyError(name)
        return self._read(name, ())

    def rows(self, name: str, samples: slice | Sequence[int] | np.ndarray) -> np.ndarray:
        """The samples ``samples`` (a slice, or sample indices in increasing order) of the
        series ``name``: reads those rows only."""
        return self._read(name, samples)

    def _read(self, name, selection):
        with self._open() as file:
            dataset = file[name]
            try:
                if dataset.size == 0:  # (T, 0, 3): no storage to select from
                    return np.zeros(dataset.shape, dtype=dataset.dtype)[selection]
                if h5py.check_string_dtype(dataset.dtype):
                    return dataset.asstr()[selection].astype(str)
                return dataset[selection]
            except (OSError, ValueError, TypeError) as error:
                raise InputError(
                    self.field, f"{self.path}: {name} cannot be read ({error}): this trajectory is damaged"
                ) from None

    def __contains__(self, name):  # without reading the array (Mapping's would read it)
        return name in self.names

    def __iter__(self):
        return iter(self.names)

    def __len__(self):
        return len(self.names)

    def __repr__(self):
        samples = self.shapes.get("time", (0,))[0]
        return f"TrajectoryFile({self.path!r}, {samples} samples, {self.status})"


def open_trajectory(path: str | os.PathLike[str], field: str = "OUT_DIR") -> TrajectoryFile:
    """The trajectory file ``path`` read back (InputError naming ``field`` when it is not one)."""
    if not os.path.isfile(path):
        raise InputError(field, f"{path} is not a file")
    return TrajectoryFile(path, field)
