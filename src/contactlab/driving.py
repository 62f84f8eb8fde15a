"""Driving a scene: external forces and torques on bodies, and kinematic bodies on a path.

A :class:`Drive` is what ``ModelBuilder.add_force`` and ``ModelBuilder.add_path`` collected,
frozen into arrays on the Model (``model.drive``; None for a scene nothing drives).

* **Forces** [N] act at a body's centre of mass and **torques** [N m] about it, world frame:
  constant, piecewise linear in time (keyframes: the first value before the first time, the
  last after the last), or a callable ``t -> (force (3,), torque (3,))``. They enter every
  method's free velocities, v* = v + h M⁻¹ (m g + f_ext(t)), ω* likewise with I⁻¹ τ_ext(t),
  evaluated at the start of the step (``dynamics.integrators.body_free_velocities``).
* **Kinematic bodies** follow a prescribed pose: keyframes (positions linearly interpolated,
  orientations by slerp, held before the first and after the last time) or a callable
  ``t -> (position (3,), orientation quaternion (4,))``. Their inverse mass and inverse inertia
  are 0, so no contact moves them, and at each step their velocity is the one that carries
  their pose of now onto the path's pose at the step's end: contacts see the moving surface,
  friction drags, and the pose lands on the path (to round-off) under every method.

Keyframed forces and paths of all bodies are evaluated together (arrays padded to the longest
keyframe list); callables are called once each per step.
"""

from __future__ import annotations

from collections import namedtuple
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from .compiling import njit
from .errors import InputError
from .validation import DIRECTION, FORCE, LENGTH, TORQUE, unit_quaternion, vector

if TYPE_CHECKING:
    from .model import Model
    from .state import State
    from .validation import Quantity


PATH_VELOCITY_STEP = 1e-6  # s: the forward difference giving a kinematic body's velocity at time 0


# ---- checking the keyframes ------------------------------------------------------------------


def keyframe_times(times: ArrayLike, name: str = "times") -> np.ndarray:
    """``times`` as a float array (T,) of finite, strictly increasing numbers [s], T ≥ 1."""
    try:
        array = np.asarray(times, dtype=float)
    except (TypeError, ValueError, OverflowError):
        raise InputError(name, f"expected a list of times (s), found {times!r}") from None
    if array.ndim != 1 or len(array) == 0:
        raise InputError(name, f"expected a non-empty list of times (s), found {times!r}")
    if not np.isfinite(array).all():
        raise InputError(name, f"expected finite times (s), found {array.tolist()}")
    back = np.flatnonzero(np.diff(array) <= 0.0)
    if len(back):
        i = int(back[0])
        raise InputError(
            name,
            f"times must increase strictly, found {array[i + 1]:g} s after {array[i]:g} s (keyframes {i} and {i + 1})",
        )
    return array


def keyframe_values(
    values: ArrayLike, name: str, count: int, size: int, what: str, quantity: Quantity | None = None
) -> np.ndarray:
    """``values`` as a float array (count, size) of finite numbers (one row per keyframe), each
    within ``quantity``'s magnitudes (a contactlab.validation.Quantity) when one is given."""
    try:
        array = np.asarray(values, dtype=float)
    except (TypeError, ValueError, OverflowError):
        raise InputError(name, f"expected {count} lists of {size} numbers ({what}), found {values!r}") from None
    if array.shape != (count, size):
        raise InputError(
            name,
            f"expected {count} lists of {size} numbers ({what}), one per time, found an array of shape {array.shape}",
        )
    if not np.isfinite(array).all():
        raise InputError(name, f"expected finite numbers ({what}), found {array.tolist()}")
    if quantity is not None:
        quantity.check(array, name)
    return array


def force_record(
    body: int, force: Any = None, torque: ArrayLike | None = None, times: ArrayLike | None = None
) -> dict[str, Any]:
    """The record :func:`pack` takes of one ``ModelBuilder.add_force`` (see it for the three
    ways to give a force), its arguments checked: dict(body, force, torque, times, function),
    force and torque (3,) [N], [N m], or (T, 3) with times (T,) [s]. InputError naming the
    argument."""
    if callable(force):
        _given_alone("force", "torque", {"torque": torque, "times": times})
        return dict(body=body, force=None, torque=None, times=None, function=force)
    if times is None:
        force, torque = (
            np.zeros(3) if value is None else vector(value, name, quantity=quantity)
            for value, name, quantity in ((force, "force", FORCE), (torque, "torque", TORQUE))
        )
    else:
        times = keyframe_times(times)
        force, torque = (
            np.zeros((len(times), 3)) if value is None else keyframe_values(value, name, len(times), 3, unit, quantity)
            for value, name, unit, quantity in ((force, "force", "N", FORCE), (torque, "torque", "N m", TORQUE))
        )
    return dict(body=body, force=force, torque=torque, times=times, function=None)


def path_record(
    body: int, positions: Any, orientations: ArrayLike | None, times: ArrayLike | None, orientation: np.ndarray
) -> dict[str, Any]:
    """The record :func:`pack` takes of one ``ModelBuilder.add_path`` (see it for the three ways
    to give a path), its arguments checked: dict(body, times (T,) [s], positions (T, 3) [m],
    orientations (T, 4) unit quaternions, function); a path without orientations keeps the
    body's ``orientation`` (4,) throughout. InputError naming the argument."""
    if callable(positions):
        _given_alone("path", "orientation", {"orientations": orientations, "times": times})
        return dict(body=body, times=None, positions=None, orientations=None, function=positions)
    if times is None:
        times = np.zeros(1)
        positions = vector(positions, "positions", quantity=LENGTH)[None]
        orientations = None if orientations is None else unit_quaternion(orientations, "orientations")[None]
    else:
        times = keyframe_times(times)
        positions = keyframe_values(positions, "positions", len(times), 3, "m", LENGTH)
        if orientations is not None:
            orientations = keyframe_values(
                orientations, "orientations", len(times), 4, "quaternions w, x, y, z", DIRECTION
            )
            norms = np.linalg.norm(orientations, axis=1)
            if (norms < 1e-12).any():
                raise InputError(
                    "orientations",
                    f"keyframe {int(np.argmin(norms))} is a zero quaternion, no rotation; use [1, 0, 0, 0] for none",
                )
            orientations = orientations / norms[:, None]
    if orientations is None:
        orientations = np.repeat(orientation[None], len(times), axis=0)
    return dict(body=body, times=times, positions=positions, orientations=orientations, function=None)


def _given_alone(kind, returns, others):
    """InputError naming the first of ``others`` (argument name -> value) given, not None, with
    a ``kind`` function, which returns the ``returns`` itself."""
    for name, value in others.items():
        if value is not None:
            raise InputError(
                name, f"a {kind} function returns the {returns} itself; give no {' or '.join(others)} with it"
            )


# ---- evaluating padded keyframes, all at once -------------------------------------------------


def pad_keyframes(
    times_list: Sequence[np.ndarray], values_list: Sequence[np.ndarray], size: int
) -> tuple[np.ndarray, np.ndarray]:
    """Keyframe lists of different lengths as padded arrays: times (K, T) and values (K, T, size),
    T the longest list (at least 2); a shorter list is continued by its last value at later
    times, so interpolation past its end holds that value."""
    longest = max([2] + [len(t) for t in times_list])
    K = len(times_list)
    times, values = np.zeros((K, longest)), np.zeros((K, longest, size))
    for k, (t, v) in enumerate(zip(times_list, values_list)):
        n = len(t)
        times[k, :n], times[k, n:] = t, t[-1] + np.arange(1, longest - n + 1)
        values[k, :n], values[k, n:] = v, v[-1]
    return times, values


DriveTable = namedtuple(
    "DriveTable",
    (
        "constant_force",  # (B, 3) N: the constant forces summed per body
        "constant_torque",  # (B, 3) N m
        "keyed_body",  # (K,) int: the body of each keyframed load
        "keyed_times",  # (K, T) s, padded (pad_keyframes)
        "keyed_loads",  # (K, T, 6) N, N m: force then torque
        "path_body",  # (Q,) int: the body of each keyframed path
        "path_times",  # (Q, T) s, padded
        "path_positions",  # (Q, T, 3) m
        "path_orientations",  # (Q, T, 4) unit quaternions
    ),
)
DriveTable.__doc__ = """A Drive's keyframes and constant loads as the compiled kernels take them (writable
copies): what both the methods' steps and the compiled loop evaluate, with the same functions."""


def table_of(drive: Drive | None) -> DriveTable | None:
    """What the compiled loop steps a model's ``drive`` with: its DriveTable, or None where
    nothing drives it (an argument typed None, so that none of the drive's code is compiled:
    5–7 s of a first run, measured with an empty table in its place)."""
    return None if drive is None else drive.table


@njit(cache=True)
def segment(times: np.ndarray, k: int, t: float) -> tuple[int, float]:
    """For row k of padded keyframe times (K, T) [s] and a time t [s]: (index i of the segment
    [t_i, t_i+1] holding t, fraction w in [0, 1] of the way along it), clamped at the ends."""
    count = 0
    for j in range(times.shape[1]):
        if times[k, j] <= t:
            count += 1
    i = min(max(count - 1, 0), times.shape[1] - 2)
    return i, min(max((t - times[k, i]) / (times[k, i + 1] - times[k, i]), 0.0), 1.0)


@njit(cache=True)
def keyed_value(times: np.ndarray, values: np.ndarray, k: int, t: float) -> np.ndarray:
    """Row k of padded keyframes (times (K, T) [s], values (K, T, d)) at time t [s], linearly
    interpolated within the segment holding t, held at the first and last value outside them:
    (d,)."""
    i, w = segment(times, k, t)
    return (1.0 - w) * values[k, i] + w * values[k, i + 1]


@njit(cache=True)
def keyed_loads(table: DriveTable, t: float) -> tuple[np.ndarray, np.ndarray]:
    """The constant and keyframed external (force (B, 3) [N], torque (B, 3) [N m]) at time t [s],
    world frame, summed per body."""
    force, torque = table.constant_force.copy(), table.constant_torque.copy()
    for k in range(table.keyed_body.shape[0]):
        value = keyed_value(table.keyed_times, table.keyed_loads, k, t)
        force[table.keyed_body[k]] += value[:3]
        torque[table.keyed_body[k]] += value[3:]
    return force, torque


@njit(cache=True)
def path_poses(table: DriveTable, t: float) -> tuple[np.ndarray, np.ndarray]:
    """Where the keyframed paths are at time t [s]: positions (Q, 3) [m] interpolated linearly,
    orientations (Q, 4) by spherical linear interpolation along the shorter arc (within 1e-9 rad
    of the same rotation: linearly, then normalized)."""
    Q = table.path_body.shape[0]
    positions, orientations = np.empty((Q, 3)), np.empty((Q, 4))
    times = table.path_times
    for q in range(Q):
        positions[q] = keyed_value(times, table.path_positions, q, t)
        i, w = segment(times, q, t)
        q0, q1 = table.path_orientations[q, i], table.path_orientations[q, i + 1]
        dot = q0[0] * q1[0] + q0[1] * q1[1] + q0[2] * q1[2] + q0[3] * q1[3]
        sign = -1.0 if dot < 0.0 else 1.0
        angle = np.arccos(min(abs(dot), 1.0))
        sine = np.sin(angle)
        if sine < 1e-9:
            a, b = 1.0 - w, w
        else:
            a, b = np.sin((1.0 - w) * angle) / sine, np.sin(w * angle) / sine
        blend = a * q0 + (b * sign) * q1
        orientations[q] = blend / np.sqrt(blend[0] ** 2 + blend[1] ** 2 + blend[2] ** 2 + blend[3] ** 2)
    return positions, orientations


@njit(cache=True)
def rotation_vector(q_from: np.ndarray, q_to: np.ndarray) -> np.ndarray:
    """The world rotation vector φ (3,) [rad] with exp(φ) ⊗ q_from = q_to, the shorter way, for
    unit quaternions (4,): the inverse of ``rotations.integrate`` over one step."""
    w0, x0, y0, z0 = q_from[0], -q_from[1], -q_from[2], -q_from[3]  # the conjugate of q_from
    w1, x1, y1, z1 = q_to[0], q_to[1], q_to[2], q_to[3]
    w = w1 * w0 - x1 * x0 - y1 * y0 - z1 * z0  # q_to ⊗ conjugate
    x = w1 * x0 + x1 * w0 + y1 * z0 - z1 * y0
    y = w1 * y0 - x1 * z0 + y1 * w0 + z1 * x0
    z = w1 * z0 + x1 * y0 - y1 * x0 + z1 * w0
    if w < 0.0:
        w, x, y, z = -w, -x, -y, -z
    sine = np.sqrt(x * x + y * y + z * z)
    scale = 2.0 * np.arctan2(sine, w) / sine if sine > 1e-12 else 2.0 / w
    return np.array([x * scale, y * scale, z * scale])


@njit(cache=True)
def path_velocities(
    table: DriveTable, body_position: np.ndarray, body_orientation: np.ndarray, t: float, h: float
) -> tuple[np.ndarray, np.ndarray]:
    """The keyframed kinematic bodies' velocities over the step from t to t + h [s]: those that
    carry their present pose (body_position (B, 3) [m], body_orientation (B, 4)) onto the path's
    pose at t + h: (velocity (Q, 3) [m/s], angular velocity (Q, 3) [rad/s]), world frame."""
    positions, orientations = path_poses(table, t + h)
    Q = positions.shape[0]
    velocity, angular = np.empty((Q, 3)), np.empty((Q, 3))
    for q in range(Q):
        b = table.path_body[q]
        velocity[q] = (positions[q] - body_position[b]) / h
        angular[q] = rotation_vector(body_orientation[b], orientations[q]) / h
    return velocity, angular


@njit(cache=True)
def drive_velocities(
    table: DriveTable | None,
    t: float,
    h: float,
    inverse: tuple[np.ndarray, np.ndarray],
    pose: tuple[np.ndarray, np.ndarray, np.ndarray],
    extra: tuple[np.ndarray, np.ndarray] | None,
    velocity: np.ndarray,
    angular: np.ndarray,
) -> None:
    """A drive's part of the bodies' free velocities (loops L1–L3, stage 1), in place: the
    external loads at the step's start t [s] (the table's, plus ``extra`` (force (B, 3) [N],
    torque (B, 3) [N m]), a Python force function's, or None) added as v* += h m⁻¹ f and
    ω* += h I⁻¹ τ (I⁻¹ in the world frame), then each keyframed kinematic body given the
    velocity that carries it onto its path over the step, h [s]. ``inverse`` = the bodies'
    (inverse masses (B,) [1/kg], principal inverse inertias (B, 3) [1/(kg m²)]); ``pose`` = their
    (rotations (B, 3, 3), positions (B, 3) [m], orientations (B, 4)) at the step's start;
    ``velocity``, ``angular`` (B, 3) [m/s], [rad/s]. ``table`` None (a scene nothing drives, an
    argument typed None): nothing, and nothing of this is compiled."""
    if table is None:
        return
    force, torque = keyed_loads(table, t)
    if extra is not None:
        force += extra[0]
        torque += extra[1]
    inverse_mass, inverse_inertia = inverse
    rotation, position, orientation = pose
    for b in range(velocity.shape[0]):
        R = rotation[b]
        for i in range(3):
            velocity[b, i] += h * force[b, i] * inverse_mass[b]
            change = 0.0  # (R diag(I⁻¹) Rᵀ τ)_i
            for k in range(3):
                along = R[0, k] * torque[b, 0] + R[1, k] * torque[b, 1] + R[2, k] * torque[b, 2]  # (Rᵀ τ)_k
                change += R[i, k] * inverse_inertia[b, k] * along
            angular[b, i] += h * change
    moving, turning = path_velocities(table, position, orientation, t, h)
    for q in range(table.path_body.shape[0]):
        velocity[table.path_body[q]] = moving[q]
        angular[table.path_body[q]] = turning[q]


# ---- the drive of a model ---------------------------------------------------------------------


@dataclass(frozen=True)
class Drive:
    """Forces and paths of a model with B bodies (see the module docstring).

    kinematic (B,) bool: the bodies on a path. constant_force, constant_torque (B, 3) [N], [N m]:
    the constant loads summed per body. keyed_body (K,) int, keyed_times (K, T) [s], keyed_loads
    (K, T, 6) [N, N m]: piecewise-linear loads, force then torque. force_functions: ((body,
    callable t -> (force (3,), torque (3,))), ...). path_body (Q,) int, path_times (Q, T) [s],
    path_positions (Q, T, 3) [m], path_orientations (Q, T, 4): keyframed paths;
    path_functions: ((body, callable t -> (position (3,), orientation (4,))), ...)."""

    kinematic: np.ndarray
    constant_force: np.ndarray
    constant_torque: np.ndarray
    keyed_body: np.ndarray
    keyed_times: np.ndarray
    keyed_loads: np.ndarray
    force_functions: tuple
    path_body: np.ndarray
    path_times: np.ndarray
    path_positions: np.ndarray
    path_orientations: np.ndarray
    path_functions: tuple

    def __post_init__(self):
        for value in vars(self).values():
            if isinstance(value, np.ndarray):
                value.flags.writeable = False

    @property
    def has_loads(self) -> bool:
        return bool(
            self.constant_force.any() or self.constant_torque.any() or len(self.keyed_body) or self.force_functions
        )

    @property
    def has_functions(self) -> bool:
        """Whether a force or a path is a Python function (which compiled code cannot call)."""
        return bool(self.force_functions or self.path_functions)

    @cached_property
    def table(self) -> DriveTable:
        """The keyframes and constant loads as the compiled kernels take them (writable copies)."""
        return DriveTable(*(np.array(getattr(self, name)) for name in DriveTable._fields))

    def function_loads(self, t: float) -> tuple[np.ndarray, np.ndarray] | None:
        """The Python force functions' (force (B, 3) [N], torque (B, 3) [N m]) at time t [s]
        summed per body, None where there are none."""
        if not self.force_functions:
            return None
        force, torque = np.zeros(self.constant_force.shape), np.zeros(self.constant_torque.shape)
        for body, function in self.force_functions:
            f, tau = called_load(function, t)
            force[body] += f
            torque[body] += tau
        return force, torque

    def loads(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """The external (force (B, 3) [N], torque (B, 3) [N m]) at time t [s], world frame."""
        force, torque = keyed_loads(self.table, float(t))
        extra = self.function_loads(t)
        if extra is not None:
            force += extra[0]
            torque += extra[1]
        return force, torque

    def poses(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Where the kinematic bodies' paths are at time t [s]: (bodies (Q,) int, positions
        (Q, 3) [m], orientations (Q, 4) unit quaternions), the keyframed paths' first."""
        position, orientation = path_poses(self.table, float(t))
        bodies, positions, orientations = [self.path_body], [position], [orientation]
        for body, function in self.path_functions:
            position, orientation = called_pose(function, t)
            bodies.append(np.array([body]))
            positions.append(position[None])
            orientations.append(orientation[None])
        return np.concatenate(bodies), np.concatenate(positions), np.concatenate(orientations)

    def path_velocities(
        self, body_position: np.ndarray, body_orientation: np.ndarray, t: float, h: float
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The kinematic bodies' velocities over the step from t to t + h [s]: those that carry
        their present pose (body_position (B, 3), body_orientation (B, 4)) onto the path's pose
        at t + h. Returns (bodies (Q,), velocity (Q, 3) [m/s], angular velocity (Q, 3) [rad/s],
        world frame), the keyframed paths' first (``path_velocities``, compiled), then the
        functions' (``function_path_velocities``)."""
        position, orientation = np.array(body_position, dtype=float), np.array(body_orientation, dtype=float)
        velocity, angular = path_velocities(self.table, position, orientation, float(t), float(h))
        bodies, velocities, angulars = self.function_path_velocities(position, orientation, t, h)
        return (
            np.concatenate([self.path_body, bodies]),
            np.concatenate([velocity, velocities]),
            np.concatenate([angular, angulars]),
        )

    def function_path_velocities(
        self, body_position: np.ndarray, body_orientation: np.ndarray, t: float, h: float
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``path_velocities`` of the paths given as Python functions alone (each called at t + h):
        (bodies (F,), velocity (F, 3) [m/s], angular velocity (F, 3) [rad/s]); F = 0 without any."""
        bodies, velocity, angular = [], np.zeros((len(self.path_functions), 3)), np.zeros((len(self.path_functions), 3))
        for f, (body, function) in enumerate(self.path_functions):
            target, turned = called_pose(function, t + h)
            bodies.append(body)
            velocity[f] = (target - body_position[body]) / h
            angular[f] = rotation_vector(np.ascontiguousarray(body_orientation[body], dtype=float), turned) / h
        return np.array(bodies, dtype=np.int64), velocity, angular


def called_load(function: Callable[[float], Any], t: float) -> tuple[np.ndarray, np.ndarray]:
    """(force (3,) [N], torque (3,) [N m]) of a force callable at time t [s], checked."""
    return called_pair(function, t, "force", (3, 3), "(force [N] (3,), torque [N m] (3,))")


def called_pose(function: Callable[[float], Any], t: float) -> tuple[np.ndarray, np.ndarray]:
    """(position (3,) [m], unit orientation (4,)) of a path callable at time t [s], checked:
    InputError("positions") for a zero quaternion too."""
    position, orientation = called_pair(
        function, t, "positions", (3, 4), "(position [m] (3,), orientation quaternion (w, x, y, z) (4,))"
    )
    norm = np.linalg.norm(orientation)
    if not norm >= 1e-12:
        raise InputError(
            "positions",
            f"the path function returned the zero quaternion at t = {t:g} s; use [1, 0, 0, 0] for no rotation",
        )
    return position, orientation / norm


def called_pair(
    function: Callable[[float], Any], t: float, name: str, sizes: tuple[int, int], expected: str
) -> tuple[np.ndarray, np.ndarray]:
    """The two float arrays of ``sizes`` that ``function(t)`` returns, finite; else
    InputError(``name``) saying what it returned at t [s] and the ``expected`` pair."""
    try:
        result = function(float(t))
    except InputError:
        raise
    except Exception as error:
        raise InputError(name, f"the function raised {type(error).__name__} at t = {t:g} s: {error}") from None
    try:
        first, second = (np.asarray(part, dtype=float) for part in result)
    except (TypeError, ValueError):  # not a pair of numbers or arrays of numbers
        fits = False
    else:
        fits = (first.shape, second.shape) == ((sizes[0],), (sizes[1],)) and bool(
            np.isfinite(first).all() and np.isfinite(second).all()
        )
    if not fits:
        raise InputError(name, f"the function returned {result!r} at t = {t:g} s; expected {expected}, finite numbers")
    return first, second


def pack(body_count: int, forces: Sequence[Mapping[str, Any]], paths: Sequence[Mapping[str, Any]]) -> Drive | None:
    """The Drive of ``body_count`` bodies from the builder's records, or None when there are
    neither forces nor paths. forces: dicts (body, force (3,) or (T, 3), torque likewise, times
    (T,) or None, function or None); paths: dicts (body, times (T,) or None, positions (T, 3),
    orientations (T, 4), function or None)."""
    if not forces and not paths:
        return None
    constant_force, constant_torque = np.zeros((body_count, 3)), np.zeros((body_count, 3))
    keyed = [f for f in forces if f["times"] is not None]
    for f in forces:
        if f["times"] is None and f["function"] is None:
            constant_force[f["body"]] += f["force"]
            constant_torque[f["body"]] += f["torque"]
    keyed_times, keyed_loads = pad_keyframes(
        [f["times"] for f in keyed], [np.hstack([f["force"], f["torque"]]) for f in keyed], 6
    )
    framed = [p for p in paths if p["function"] is None]
    path_times, path_positions = pad_keyframes([p["times"] for p in framed], [p["positions"] for p in framed], 3)
    _, path_orientations = pad_keyframes([p["times"] for p in framed], [p["orientations"] for p in framed], 4)
    kinematic = np.zeros(body_count, dtype=bool)
    kinematic[[p["body"] for p in paths]] = True
    return Drive(
        kinematic=kinematic,
        constant_force=constant_force,
        constant_torque=constant_torque,
        keyed_body=np.array([f["body"] for f in keyed], dtype=np.int64),
        keyed_times=keyed_times,
        keyed_loads=keyed_loads,
        force_functions=tuple((f["body"], f["function"]) for f in forces if f["function"] is not None),
        path_body=np.array([p["body"] for p in framed], dtype=np.int64),
        path_times=path_times,
        path_positions=path_positions,
        path_orientations=path_orientations,
        path_functions=tuple((p["body"], p["function"]) for p in paths if p["function"] is not None),
    )


def too_fast(model: Model, t: float, dt: float, speed_limit: float) -> str | None:
    """When a run of ``model`` went wrong at time ``t`` [s] (step ``dt`` [s]): a clause naming
    the driving input that alone carries a body past ``speed_limit`` [m/s] by then, or None.

    Candidates: a kinematic body's path, at the speed it moves over the step before ``t``; an
    external force, at the speed |f| t / m it would give its body alone by ``t``; a torque, at
    the speed |I⁻¹ τ| t r it would spin the body's surface to (r its bounding radius). The
    largest past the limit is named: a 10¹² N push, or a path that jumps 10⁶ m in a nanosecond,
    is the input's fault, which no smaller dt mends."""
    drive = model.drive
    if drive is None:
        return None
    found = []  # (speed [m/s], clause)
    before = max(t - dt, 0.0)
    try:  # a callable is asked again here; what it says cannot hide the run's own error
        bodies, now, _ = drive.poses(t)
        _, earlier, _ = drive.poses(before)
        span = t - before if t > before else dt
        for body, speed in zip(bodies, np.linalg.norm(now - earlier, axis=1) / span):
            found.append((speed, f"the path of {model.body_names[body]!r} moves it at {speed:.3g} m/s then"))
        loads = [drive.loads(time) for time in (before, t)]
    except Exception:
        return None
    force = np.max([np.linalg.norm(f, axis=1) for f, _ in loads], axis=0)  # (B,) [N]
    torque = np.max([np.linalg.norm(tau, axis=1) for _, tau in loads], axis=0)  # (B,) [N m]
    elapsed = max(t, dt)
    spin = torque * model.body_inverse_inertia.max(axis=1) * elapsed * model.body_radii  # [m/s]
    for body in np.flatnonzero(~drive.kinematic & ((force > 0) | (torque > 0))):
        name, mass, speed = model.body_names[body], model.body_mass[body], force[body] / model.body_mass[body] * elapsed
        pushed = f"{force[body]:.3g} N on {mass:.3g} kg, alone would speed it to {speed:.3g} m/s by then"
        found.append((speed, f"the force on {name!r}, {pushed}"))
        spun = f"{torque[body]:.3g} N m, alone would spin its surface to {spin[body]:.3g} m/s by then"
        found.append((spin[body], f"the torque on {name!r}, {spun}"))
    speed, clause = max(found, default=(0.0, ""), key=lambda pair: pair[0])
    if not speed > speed_limit:
        return None
    kind = "path" if clause.startswith("the path") else clause.split()[1]
    return (
        f"{clause}, past the {speed_limit:.3g} m/s this scene allows: the {kind} is the likely problem "
        f"(its values, units or times), not the time step"
    )


def start_on_paths(drive: Drive | None, state: State) -> State:
    """``state`` (changed in place) with its kinematic bodies at their paths' poses at its time
    and moving at the paths' velocities there (a forward difference of PATH_VELOCITY_STEP)."""
    if drive is None or not drive.kinematic.any():
        return state
    bodies, position, orientation = drive.poses(state.time)
    state.body_position[bodies], state.body_orientation[bodies] = position, orientation
    bodies, velocity, angular = drive.path_velocities(
        state.body_position, state.body_orientation, state.time, PATH_VELOCITY_STEP
    )
    state.body_velocity[bodies], state.body_angular_velocity[bodies] = velocity, angular
    return state
