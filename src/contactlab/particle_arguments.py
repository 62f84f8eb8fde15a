"""The arguments of :meth:`contactlab.builder.ModelBuilder.add_particles` checked: positions,
velocities, and masses and radii given as one number for all particles or one per particle.

Each bad value is an :class:`~contactlab.errors.InputError` naming the argument: the wrong
shape, a non-finite number, a mass ≤ 0 or a radius < 0, or a magnitude beyond
:data:`contactlab.validation.LIMITS`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from .errors import InputError
from .validation import LENGTH, MASS, SPEED, as_array


def particle_positions(position: ArrayLike) -> np.ndarray:
    """``position`` (count, 3) [m] checked (one point (3,) is taken as (1, 3)): finite, not empty."""
    points = as_array(position, "position", "a list of [x, y, z] points")
    if points.ndim == 1 and points.shape == (3,):
        points = points[None]
    if points.ndim != 2 or points.shape[1] != 3 or len(points) == 0:
        raise InputError("position", "expected a non-empty list of [x, y, z] points")
    if not np.isfinite(points).all():
        raise InputError("position", "expected finite numbers")
    LENGTH.check(points, "position")
    return points


def particle_values(
    position: np.ndarray, velocity: ArrayLike | None, mass: float | ArrayLike, radius: float | ArrayLike
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(velocity (count, 3) [m/s], mass (count,) [kg], radius (count,) [m]) of the particles at
    the checked ``position`` (count, 3): velocity None is at rest; mass > 0 and radius ≥ 0 one
    number for all or one per particle."""
    count = len(position)
    speeds = np.zeros_like(position) if velocity is None else velocity
    speeds = as_array(speeds, "velocity", "a list of [vx, vy, vz] velocities")
    if speeds.shape != position.shape:
        raise InputError("velocity", f"expected {count} velocities, one per position")
    if not np.isfinite(speeds).all():
        raise InputError("velocity", "expected finite numbers")
    SPEED.check(speeds, "velocity")
    masses = _per_particle(mass, "mass", count)
    if (masses <= 0).any() or not np.isfinite(masses).all():
        raise InputError("mass", f"must be greater than 0 (kg) for every particle, found {masses.min():g}")
    MASS.check(masses, "mass", positive=True)
    radii = _per_particle(radius, "radius", count)
    if (radii < 0).any() or not np.isfinite(radii).all():
        raise InputError("radius", f"must be at least 0 (m) for every particle, found {radii.min():g}")
    LENGTH.check(radii, "radius")
    return speeds, masses, radii


def _per_particle(value: float | ArrayLike, name: str, count: int) -> np.ndarray:
    """``value`` as (count,): one number for all particles, or one per particle."""
    array = as_array(value, name, f"a number or a list of {count} numbers")
    if array.ndim == 0 or array.shape == (count,):
        return np.broadcast_to(array, (count,)).copy()
    raise InputError(name, f"expected a number or a list of {count} numbers (one per particle), found {array.size}")
