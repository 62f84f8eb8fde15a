"""A trajectory read back: ``trajectory.npz`` loaded safely and its arrays checked.

``contactlab render`` and ``contactlab export`` draw and write whatever a ``trajectory.npz``
holds, so a damaged, truncated or hand-made file must fail as one InputError, never deep in
matplotlib, NumPy or a zip reader:

* :func:`load_npz` reads the archive with ``allow_pickle=False`` (nothing in it is ever
  unpickled: an object array is refused) and turns every way a file can fail to be a NumPy
  archive into an InputError;
* :func:`check_arrays` checks the arrays a drawing or an export uses against the shapes of
  docs/trajectory.md: numbers where numbers belong, the counts T, B, P, ... the same in every
  array, indices within what they index, finite coordinates no larger than
  :data:`MAX_COORDINATE` (a run that blew up is not drawn), times in order.

:func:`contactlab.render.render` and the exports call :func:`check_arrays` on what they are
given, so a trajectory passed from Python is held to the same rules as one read from disk.
"""

from __future__ import annotations

import os
import zipfile
import zlib
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.lib.npyio import NpzFile

from .errors import InputError, first_line

MAX_COORDINATE = 1e12  # m: positions and surface vertices beyond this are corrupt (scenes are ≤ 1e6 m)

# name -> (kind, shape): kind "float" (real numbers, finite), "index" (whole numbers) or "text";
# shape in the symbols of docs/trajectory.md ("B+1": one more than B).
SHAPES = {
    "time": ("float", ("T",)),
    "body_position": ("float", ("T", "B", 3)),
    "body_orientation": ("float", ("T", "B", 4)),
    "body_velocity": ("float", ("T", "B", 3)),
    "body_angular_velocity": ("float", ("T", "B", 3)),
    "particle_position": ("float", ("T", "P", 3)),
    "particle_velocity": ("float", ("T", "P", 3)),
    "body_names": ("text", ("B",)),
    "triangles": ("index", ("F", 3)),
    "particle_cloth": ("index", ("P",)),
    "body_surface_vertices": ("float", ("V", 3)),
    "body_surface_vertex_start": ("index", ("B+1",)),
    "body_surface_triangles": ("index", ("N", 3)),
    "body_surface_triangle_start": ("index", ("B+1",)),
    "obstacle_vertices": ("float", ("W", 3)),
    "obstacle_triangles": ("index", ("M", 3)),
    "particle_radius": ("float", ("P",)),
}
FINITE = (
    "body_position",
    "body_orientation",
    "particle_position",
    "body_surface_vertices",
    "obstacle_vertices",
    "particle_radius",
)  # what is drawn or exported: finite, ≤ MAX_COORDINATE
# index array -> (the array whose rows it indexes, the smallest index allowed)
INDEXES = {
    "triangles": ("particle_position", 0),
    "body_surface_triangles": ("body_surface_vertices", 0),
    "obstacle_triangles": ("obstacle_vertices", 0),
    "particle_cloth": (None, -1),
}
STARTS = {"body_surface_vertex_start": "body_surface_vertices", "body_surface_triangle_start": "body_surface_triangles"}

_NOT_AN_ARCHIVE = (OSError, ValueError, EOFError, KeyError, NotImplementedError, zipfile.BadZipFile, zlib.error)


def load_npz(path: str | os.PathLike[str], field: str = "OUT_DIR") -> dict[str, np.ndarray]:
    """Every array of the NumPy archive at ``path`` (name -> ndarray), read without unpickling
    anything; InputError naming ``field`` when the file is not such an archive (random bytes,
    a truncated or corrupt zip, a bare .npy, object arrays)."""
    try:
        archive = np.load(path, allow_pickle=False)
        if not isinstance(archive, NpzFile):
            raise ValueError("a single array, not an archive of arrays")
        with archive:
            return {name: archive[name] for name in archive.files}
    except _NOT_AN_ARCHIVE as error:
        raise InputError(
            field, f"{path} is not a trajectory contactlab can read ({_reason(error)}); run the scene again"
        ) from None


def _reason(error):
    text = first_line(error)
    if "pickle" in text:
        return "it holds Python objects, which contactlab never unpickles, or is not a NumPy file at all"
    return text


def check_arrays(arrays: Mapping[str, Any], field: str = "arrays") -> None:
    """InputError naming ``field`` unless the arrays of ``arrays`` named in SHAPES (those
    present) have their documented kinds and shapes, agree on the counts, index within range,
    and hold finite coordinates within MAX_COORDINATE and times in order."""
    for name, (kind, _) in SHAPES.items():
        if name in arrays:
            _check_kind(np.asarray(arrays[name]), name, kind, field)
    check_shapes({name: np.shape(arrays[name]) for name in SHAPES if name in arrays}, field)
    for name in FINITE:
        if name in arrays:
            _check_finite(np.asarray(arrays[name], dtype=float), name, arrays, field)
    if "time" in arrays:
        time = np.asarray(arrays["time"], dtype=float)
        if not np.isfinite(time).all():
            raise InputError(field, "time holds numbers that are not finite: this trajectory is damaged")
        if np.any(np.diff(time) < 0):
            raise InputError(field, "time goes backwards between samples: this is not a recorded run")
    for name, (target, smallest) in INDEXES.items():
        if name in arrays:
            rows = _row_count(arrays, target, name)
            _check_indices(np.asarray(arrays[name]), name, smallest, rows, field)
    for name, target in STARTS.items():
        if name in arrays and target in arrays:
            start = np.asarray(arrays[name])
            if len(start) == 0 or start[0] != 0 or np.any(np.diff(start) < 0) or start[-1] != len(arrays[target]):
                raise InputError(
                    field,
                    f"{name} is not a list of starts from 0 to the {len(arrays[target])} rows "
                    f"of {target}: this trajectory is damaged",
                )


def _check_kind(array, name, kind, field):
    wanted = {"float": "fiu", "index": "iu", "text": "US"}[kind]
    if array.size and array.dtype.kind not in wanted:
        words = {"float": "numbers", "index": "whole numbers", "text": "names"}[kind]
        raise InputError(
            field, f"{name} holds {array.dtype} values where it should hold {words}: this trajectory is damaged"
        )


def check_shapes(shapes: Mapping[str, tuple[int, ...]], field: str = "arrays") -> None:
    """InputError naming ``field`` unless the shapes ``shapes`` (name -> tuple, of the arrays
    of SHAPES present) have their documented dimensions and agree on the counts T, B, P, ...
    (checked before a file's samples are read, so that no read goes beyond them)."""
    sizes: dict[str, int] = {}  # the counts (T, B, ...) met so far
    for name, (_, shape) in SHAPES.items():
        if name in shapes:
            _check_shape(tuple(shapes[name]), name, shape, sizes, field)


def _check_shape(found, name, shape, sizes, field):
    """The shape ``found`` of the array ``name`` against ``shape``."""
    if len(found) != len(shape):
        raise InputError(
            field,
            f"{name} has {len(found)} dimensions where it should have {len(shape)} "
            f"({', '.join(map(str, shape))}): this trajectory is damaged",
        )
    for axis, (symbol, size) in enumerate(zip(shape, found)):
        if isinstance(symbol, int):
            expected, counted = symbol, None
        else:
            counted, offset = (symbol[:-2], 1) if symbol.endswith("+1") else (symbol, 0)
            if counted not in sizes:
                sizes[counted] = size - offset
            expected = sizes[counted] + offset
        if size != expected:
            what = f"{symbol} = {expected}" if counted else str(expected)
            raise InputError(
                field,
                f"{name} has {size} entries along axis {axis} where the other arrays give "
                f"{what}: this trajectory is damaged",
            )


def _check_finite(values, name, arrays, field):
    """InputError unless ``values`` are finite and within MAX_COORDINATE; for a series (T, n, k),
    the message says the time of the first sample (of those given) that is not."""
    bad = ~np.isfinite(values) | (np.abs(values) > MAX_COORDINATE)
    if bad.any():
        where = ""
        if values.ndim == 3 and "time" in arrays:  # (T, n, k): say from when
            first = int(np.argmax(bad.reshape(len(values), -1).any(axis=1)))
            where = f" at t = {float(np.asarray(arrays['time'])[first]):.4g} s (the first sample used that is)"
        raise InputError(
            field,
            f"{name} holds numbers that are not finite or beyond {MAX_COORDINATE:g}{where} "
            f"(a run that blew up, or a damaged file): nothing to draw or export",
        )


def _row_count(arrays, target, name):
    if target is None:
        return None
    if target not in arrays:
        return None
    array = np.asarray(arrays[target])
    return array.shape[1] if target == "particle_position" else len(array)


def _check_indices(indices, name, smallest, rows, field):
    if indices.size == 0:
        return
    low, high = int(indices.min()), int(indices.max())
    if low < smallest or (rows is not None and high >= rows):
        allowed = f"{smallest} to {rows - 1}" if rows is not None else f"at least {smallest}"
        raise InputError(
            field, f"{name} holds indices from {low} to {high} where they must be {allowed}: this trajectory is damaged"
        )
