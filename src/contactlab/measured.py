"""A measured-motion file: the recorded poses of real bodies, read and checked (docs/validate.md).

An HDF5 file with the names of contactlab's own trajectory file (docs/trajectory.md), so a
``trajectory.h5`` of a run is itself a measurement:

=========================  ============  ==================================================
dataset                    shape         meaning
=========================  ============  ==================================================
``time``                   (T,)          s, strictly increasing, T ≥ 2 (need not start at 0)
``body_position``          (T, B, 3)     m, each body's centre of mass, world frame
``body_orientation``       (T, B, 4)     unit quaternions w, x, y, z, body frame → world
``body_velocity``          (T, B, 3)     m/s, world frame (optional)
``body_angular_velocity``  (T, B, 3)     rad/s, world frame (optional; with ``body_velocity``)
``body_names``             (B,)          text, the scene's names of the bodies measured
=========================  ============  ==================================================

``body_names`` may be left out when B is the scene's number of bodies (then in the scene's
order). The body frame is contactlab's (its principal frame, docs/scene-format.md): for a box
or sphere with a diagonal inertia, the shape's own axes.

:func:`read_measurement` checks everything a comparison relies on and turns each mistake into
one :class:`~contactlab.errors.InputError` naming the file and dataset: a file that is not
HDF5, a missing dataset, numbers that are not finite, counts that disagree, time that does
not increase, quaternions further than :data:`QUATERNION_TOLERANCE` from unit length (then
they are normalized), positions beyond :data:`MAX_POSITION` (millimetres given for metres).
:func:`write_measurement` writes one (atomically).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .errors import InputError, first_line

QUATERNION_TOLERANCE = 1e-3  # |‖q‖ − 1| accepted (a tracker's rounding); normalized after
MAX_POSITION = 1e3  # m: a tracked body further than this from the origin was given in millimetres
LIKELY_SPEED = 100.0  # m/s: a tracked body faster than this between two samples was likely given in millimetres
MAX_SAMPLES = 10_000_000  # samples a file may hold
VECTORS = ("body_position", "body_velocity", "body_angular_velocity")


@dataclass(frozen=True)
class Measurement:
    """One measured motion: ``time`` (T,) [s]; ``body_names`` (B,); ``position`` (T, B, 3) [m];
    ``orientation`` (T, B, 4) unit quaternions (w, x, y, z); ``velocity`` and
    ``angular_velocity`` (T, B, 3) [m/s], [rad/s] world frame, or None where the file has none;
    ``path`` the file, ``name`` its stem."""

    path: str
    name: str
    time: np.ndarray
    body_names: tuple[str, ...] | None
    position: np.ndarray
    orientation: np.ndarray
    velocity: np.ndarray | None = None
    angular_velocity: np.ndarray | None = None

    @property
    def duration(self) -> float:
        """s, from the first sample to the last."""
        return float(self.time[-1] - self.time[0])


def read_measurement(path: str | os.PathLike[str]) -> Measurement:
    """The measurement in the HDF5 file ``path``, checked (see the module's docstring)."""
    import h5py

    path = os.fspath(path)
    shown = os.path.basename(path) or path
    if not os.path.isfile(path):
        raise InputError(shown, f"no such file {path!r}" if not os.path.exists(path) else "expected an HDF5 file")
    try:
        with h5py.File(path, "r") as file:
            found = {name: _read(file, name, shown) for name in (*VECTORS, "time", "body_orientation", "body_names")}
    except InputError:
        raise
    except Exception as error:  # h5py's OSError for a file that is not HDF5, a truncated one, ...
        raise InputError(shown, f"cannot read it as an HDF5 file ({first_line(error)})") from None
    return _checked(path, shown, found)


def _read(file, name, shown):
    if name not in file:
        return None
    data = file[name]
    if not hasattr(data, "shape"):
        raise InputError(f"{shown}:{name}", "expected a dataset, found a group")
    if data.size > 4 * 3 * MAX_SAMPLES:
        raise InputError(
            f"{shown}:{name}", f"holds {data.size:,} values, more than a measurement may ({MAX_SAMPLES:,} samples)"
        )
    values = data[()]
    if name == "body_names":
        return values
    if values.dtype.kind not in "iuf":
        raise InputError(f"{shown}:{name}", f"expected numbers, found values of type {values.dtype}")
    return np.asarray(values, dtype=float)


def _checked(path, shown, found):
    for name in ("time", "body_position", "body_orientation"):
        if found[name] is None:
            raise InputError(f"{shown}:{name}", "missing: a measurement needs time, body_position and body_orientation")
    time = found["time"]
    if time.ndim != 1 or len(time) < 2:
        raise InputError(f"{shown}:time", f"expected (T,) times with T ≥ 2, found shape {time.shape}")
    count = len(time)
    bodies = found["body_position"].shape[1] if found["body_position"].ndim == 3 else None
    for name, width in (
        ("body_position", 3),
        ("body_orientation", 4),
        ("body_velocity", 3),
        ("body_angular_velocity", 3),
    ):
        values = found[name]
        if values is not None and (values.ndim != 3 or values.shape != (count, bodies, width) or not bodies):
            raise InputError(
                f"{shown}:{name}",
                f"expected shape ({count}, B, {width}) with B ≥ 1, one row per time, found {values.shape}",
            )
    for name, values in found.items():
        if name != "body_names" and values is not None and not np.isfinite(values).all():
            index = np.argwhere(~np.isfinite(values))[0]
            raise InputError(
                f"{shown}:{name}", f"expected finite numbers, found {values[tuple(index)]} at sample {index[0]}"
            )
    steps = np.diff(time)
    if not (steps > 0).all():
        k = int(np.argmax(steps <= 0)) + 1
        raise InputError(
            f"{shown}:time",
            f"expected strictly increasing times (s), found {time[k]:g} after {time[k - 1]:g} at sample {k}",
        )
    norms = np.linalg.norm(found["body_orientation"], axis=2)
    if np.abs(norms - 1.0).max() > QUATERNION_TOLERANCE:
        k, b = np.unravel_index(int(np.argmax(np.abs(norms - 1.0))), norms.shape)
        raise InputError(
            f"{shown}:body_orientation",
            f"expected unit quaternions (w, x, y, z), found one of length {norms[k, b]:.6g} at sample {k}, body {b}",
        )
    far = np.abs(found["body_position"]).max()
    if far > MAX_POSITION:
        raise InputError(
            f"{shown}:body_position",
            f"a body is {far:g} m from the origin, beyond the {MAX_POSITION:g} m a tracked body can be; "
            "positions are in metres (millimetres divided by 1000)",
        )
    _warn_of_speed(shown, found["time"], found["body_position"])
    if (found["body_velocity"] is None) != (found["body_angular_velocity"] is None):
        given = "body_velocity" if found["body_velocity"] is not None else "body_angular_velocity"
        raise InputError(f"{shown}:{given}", "give body_velocity and body_angular_velocity together, or neither")
    return Measurement(
        path=path,
        name=os.path.splitext(os.path.basename(path))[0],
        time=time,
        body_names=_names(found["body_names"], bodies, shown),
        position=found["body_position"],
        orientation=found["body_orientation"] / norms[..., None],
        velocity=found["body_velocity"],
        angular_velocity=found["body_angular_velocity"],
    )


def _warn_of_speed(shown: str, time: np.ndarray, position: np.ndarray) -> None:
    """A warning (one line) where a body moves faster than :data:`LIKELY_SPEED` between two
    samples (``time`` (T,) [s], ``position`` (T, B, 3)): positions in millimetres within
    :data:`MAX_POSITION` (600 m) were taken as metres, and every error was 1000 times too large."""
    if len(time) < 2:
        return
    speeds = np.linalg.norm(np.diff(position, axis=0), axis=2) / np.diff(time)[:, None]
    fastest = float(speeds.max())
    if fastest > LIKELY_SPEED:
        import warnings

        k = int(np.unravel_index(int(np.argmax(speeds)), speeds.shape)[0])
        warnings.warn(
            f"{shown}:body_position: a body moves at {fastest:.3g} m/s between samples {k} and {k + 1}; "
            "positions are in metres (millimetres divided by 1000)",
            stacklevel=3,
        )


def _names(names, bodies, shown):
    if names is None:
        return None
    names = np.asarray(names)
    if names.shape != (bodies,):
        raise InputError(
            f"{shown}:body_names", f"expected {bodies} names, one per body of body_position, found shape {names.shape}"
        )
    decoded = tuple(
        name.decode("utf-8", "replace") if isinstance(name, bytes) else str(name) for name in names.tolist()
    )
    if len(set(decoded)) != len(decoded):
        raise InputError(f"{shown}:body_names", f"expected distinct names, found {', '.join(map(repr, decoded))}")
    return decoded


def write_measurement(
    path: str | os.PathLike[str],
    time: ArrayLike,
    body_names: tuple[str, ...] | list[str],
    position: ArrayLike,
    orientation: ArrayLike,
    velocity: ArrayLike | None = None,
    angular_velocity: ArrayLike | None = None,
) -> str:
    """Write a measured-motion file (shapes as :class:`Measurement`'s) atomically; returns ``path``."""
    import h5py

    from .record import atomic_path

    path = os.fspath(path)
    with atomic_path(path) as temporary, h5py.File(temporary, "w") as file:
        file.create_dataset("time", data=np.asarray(time, dtype=float))
        file.create_dataset("body_position", data=np.asarray(position, dtype=float))
        file.create_dataset("body_orientation", data=np.asarray(orientation, dtype=float))
        if velocity is not None:
            file.create_dataset("body_velocity", data=np.asarray(velocity, dtype=float))
        if angular_velocity is not None:
            file.create_dataset("body_angular_velocity", data=np.asarray(angular_velocity, dtype=float))
        file.create_dataset("body_names", data=np.array([str(name) for name in body_names], dtype=h5py.string_dtype()))
    return path


def write_synthetic(
    path: str | os.PathLike[str],
    arrays: dict[str, np.ndarray] | Any,
    every: int = 1,
    position_noise: float = 0.0,
    angle_noise: float = 0.0,
    velocities: bool = False,
    seed: int = 0,
) -> str:
    """A measurement made of a run (its ``arrays``: every ``every``-th sample), as a tracker
    would record it: Gaussian noise of ``position_noise`` [m] on each coordinate, and each
    orientation turned about a random axis by a Gaussian angle of ``angle_noise`` [rad];
    ``velocities``: keep the run's velocities (noise-free) in the file. What the tests and
    data/measured/ use to know the settings behind a measurement. Returns ``path``."""
    from .rotations import from_rotation_vector, multiply

    rng = np.random.default_rng(seed)
    time = np.asarray(arrays["time"])[::every]
    position = np.array(arrays["body_position"])[::every]
    orientation = np.array(arrays["body_orientation"])[::every]
    position += rng.normal(0.0, position_noise, position.shape) if position_noise else 0.0
    if angle_noise:
        axes = rng.normal(size=orientation.shape[:-1] + (3,))
        axes /= np.linalg.norm(axes, axis=-1, keepdims=True)
        turns = from_rotation_vector(axes * rng.normal(0.0, angle_noise, orientation.shape[:-1] + (1,)))
        orientation = multiply(turns, orientation)
    kept = {}
    if velocities:
        kept = dict(
            velocity=np.asarray(arrays["body_velocity"])[::every],
            angular_velocity=np.asarray(arrays["body_angular_velocity"])[::every],
        )
    return write_measurement(path, time, list(arrays["body_names"]), position, orientation, **kept)
