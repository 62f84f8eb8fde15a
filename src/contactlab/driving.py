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

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from . import rotations
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


def bracket(times: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
    """For padded keyframe times (K, T) and a time t [s]: (index i (K,) of the segment
    [t_i, t_i+1] holding t, fraction w (K,) in [0, 1] of the way along it); clamped at the ends."""
    K, T = times.shape
    index = np.clip((times <= t).sum(axis=1) - 1, 0, T - 2)
    rows = np.arange(K)
    start, end = times[rows, index], times[rows, index + 1]
    return index, np.clip((t - start) / (end - start), 0.0, 1.0)


def interpolate(times: np.ndarray, values: np.ndarray, t: float) -> np.ndarray:
    """Linear interpolation (K, d) of padded keyframes (``pad_keyframes``) at time t [s]."""
    index, w = bracket(times, t)
    rows = np.arange(len(index))
    return (1.0 - w)[:, None] * values[rows, index] + w[:, None] * values[rows, index + 1]


def slerp(q0: np.ndarray, q1: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Spherical linear interpolation (K, 4) from unit quaternions q0 to q1 (K, 4) by fractions
    w (K,), along the shorter arc."""
    dot = np.sum(q0 * q1, axis=1)
    q1 = np.where(dot[:, None] < 0.0, -q1, q1)
    dot = np.abs(dot)
    angle = np.arccos(np.clip(dot, -1.0, 1.0))
    sine = np.sin(angle)
    near = sine < 1e-9  # (nearly) the same rotation: linear, then normalized
    safe = np.where(near, 1.0, sine)
    a = np.where(near, 1.0 - w, np.sin((1.0 - w) * angle) / safe)
    b = np.where(near, w, np.sin(w * angle) / safe)
    return rotations.normalize(a[:, None] * q0 + b[:, None] * q1)


def rotation_vectors(q_from: np.ndarray, q_to: np.ndarray) -> np.ndarray:
    """The world rotation vectors φ (K, 3) [rad] with exp(φ) ⊗ q_from = q_to (the shorter way),
    for unit quaternions (K, 4): the inverse of ``rotations.integrate`` over one step."""
    conjugate = q_from * np.array([1.0, -1.0, -1.0, -1.0])
    relative = rotations.multiply(q_to, conjugate)
    relative = np.where(relative[:, :1] < 0.0, -relative, relative)
    vector = relative[:, 1:]
    sine = np.linalg.norm(vector, axis=1)
    angle = 2.0 * np.arctan2(sine, relative[:, 0])
    scale = np.where(sine > 1e-12, angle / np.where(sine > 1e-12, sine, 1.0), 2.0 / relative[:, 0])
    return vector * scale[:, None]


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

    def loads(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """The external (force (B, 3) [N], torque (B, 3) [N m]) at time t [s], world frame."""
        force, torque = self.constant_force.copy(), self.constant_torque.copy()
        if len(self.keyed_body):
            values = interpolate(self.keyed_times, self.keyed_loads, t)
            np.add.at(force, self.keyed_body, values[:, :3])
            np.add.at(torque, self.keyed_body, values[:, 3:])
        for body, function in self.force_functions:
            f, tau = called_load(function, t)
            force[body] += f
            torque[body] += tau
        return force, torque

    def poses(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Where the kinematic bodies' paths are at time t [s]: (bodies (Q,) int, positions
        (Q, 3) [m], orientations (Q, 4) unit quaternions)."""
        bodies = [self.path_body]
        positions = [interpolate(self.path_times, self.path_positions, t)]
        index, w = bracket(self.path_times, t)
        rows = np.arange(len(index))
        orientations = [slerp(self.path_orientations[rows, index], self.path_orientations[rows, index + 1], w)]
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
        world frame)."""
        bodies, position, orientation = self.poses(t + h)
        velocity = (position - body_position[bodies]) / h
        return bodies, velocity, rotation_vectors(body_orientation[bodies], orientation) / h


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
