"""Checking input values: the magnitudes accepted and the checks every entry point shares.

The builder, the scene loader, the methods' Options, :func:`contactlab.simulate` and the
command line check what they are given with these functions, so one kind of mistake gets one
sentence wherever it is made. Each raises :class:`~contactlab.errors.InputError` naming the
field it is told (``name``), and returns the value converted (a float, a float array, ...).

The bounds of :data:`LIMITS` are far beyond any scene contactlab is for: past them the
squares and products the dynamics forms (m r², m v², 1/m) overflow or lose every digit, and a
run would report NaN energies (see Limits in docs/scene-format.md).
"""

from __future__ import annotations

import math
import os
from collections.abc import Collection, Mapping
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np
from numpy.typing import ArrayLike

from .errors import InputError

_T = TypeVar("_T")

# -- the magnitudes accepted ------------------------------------------------------------


@dataclass(frozen=True)
class Quantity:
    """The magnitudes accepted for one kind of value: at most ``largest`` [unit] in absolute
    value and, for a value that must be positive, at least ``smallest``."""

    what: str
    unit: str
    largest: float
    smallest: float = 0.0

    def check(self, values: ArrayLike, name: str, positive: bool = False) -> None:
        """InputError naming ``name`` unless every one of ``values`` (a number or an array of
        finite numbers) is within the bounds (``smallest`` only where ``positive``)."""
        if isinstance(values, float):  # one number (from ``number``): no array to build
            largest = smallest = abs(values)
        else:
            magnitudes = np.abs(np.asarray(values, dtype=float))
            if not magnitudes.size:
                return
            largest, smallest = magnitudes.max(), magnitudes.min()
        if largest > self.largest:
            raise InputError(
                name,
                f"expected a {self.what} of at most {self.largest:g}{self._unit}, found "
                f"{largest:g}{self._unit} (see Limits in docs/scene-format.md)",
            )
        if positive and smallest < self.smallest:
            raise InputError(
                name,
                f"expected a {self.what} of at least {self.smallest:g}{self._unit}, found "
                f"{smallest:g}{self._unit} (see Limits in docs/scene-format.md)",
            )

    @property
    def _unit(self):
        return f" {self.unit}" if self.unit else ""


LENGTH = Quantity("length", "m", 1e6, 1e-6)  # positions, sizes, offsets: 1000 km; sizes ≥ 1 µm
MASS = Quantity("mass", "kg", 1e12, 1e-12)  # given or from a density: a nanogram to a mountain
DENSITY = Quantity("density", "kg/m^3", 1e6)  # osmium is 22,590 kg/m³
AREAL_DENSITY = Quantity("areal density", "kg/m^2", 1e6)  # of cloth; canvas is about 0.3 kg/m²
SPEED = Quantity("speed", "m/s", 1e5)  # a rifle bullet is 1e3 m/s
ANGULAR_SPEED = Quantity("angular speed", "rad/s", 1e6)
ACCELERATION = Quantity("gravity", "m/s^2", 1e4)  # a thousand g
STIFFNESS = Quantity("stiffness", "N/m", 1e12)
DAMPING = Quantity("damping", "N s/m", 1e12)
FRICTION = Quantity("friction coefficient", "", 1e3)  # rubber on rubber is about 1
FACTOR = Quantity("scale factor", "", 1e6, 1e-6)
DIRECTION = Quantity("direction component", "", 1e6)  # normals and quaternions, normalized after
TIME = Quantity("time", "s", 1e9, 1e-9)  # dt and duration (contactlab.simulate)
FORCE = Quantity("force", "N", 1e12)  # external forces (add_force)
TORQUE = Quantity("torque", "N m", 1e12)
LIMITS = (
    LENGTH,
    MASS,
    DENSITY,
    AREAL_DENSITY,
    SPEED,
    ANGULAR_SPEED,
    ACCELERATION,
    STIFFNESS,
    DAMPING,
    FRICTION,
    FACTOR,
    DIRECTION,
    TIME,
    FORCE,
    TORQUE,
)
MAX_DYNAMIC = 200_000  # bodies, particles and cloth vertices in one model: seconds and gigabytes a step past it
MAX_STEPS = 10**9  # steps of one run at most (duration / dt); a run's record_every at most too
WHOLE_NUMBERS = (-(2**63), 2**63 - 1)  # whole numbers accepted: 64-bit, as TOML allows and compiled kernels take


# -- numbers and arrays -------------------------------------------------------------------


def number(
    value: object,
    name: str,
    minimum: float | None = None,
    strict: bool = False,
    maximum: float | None = None,
    quantity: Quantity | None = None,
) -> float:
    """``value`` (an int or float, numpy's too, never a bool) as a finite float, at least
    ``minimum`` (greater than it where ``strict``), at most ``maximum``, and within
    ``quantity``'s magnitudes when one is given (its smallest where ``strict``: a value that
    must be positive). InputError naming ``name``: "expected a number", "expected a finite
    number", "must be greater than / at least / at most ...", or the quantity's bounds."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise InputError(name, f"expected a number, found {value!r}")
    try:
        value = float(value)
    except OverflowError:  # a Python int beyond the float range
        value = float("inf")
    if not math.isfinite(value):
        raise InputError(name, f"expected a finite number, found {value!r}")
    if minimum is not None and (value <= minimum if strict else value < minimum):
        bound = "greater than" if strict else "at least"
        raise InputError(name, f"must be {bound} {minimum:g}, found {value:g}")
    if maximum is not None and value > maximum:
        raise InputError(name, f"must be at most {maximum:g}, found {value:g}")
    if quantity is not None:
        quantity.check(value, name, strict)
    return value


def time_step(dt: object, name: str = "dt") -> float:
    """The time step ``dt`` [s] as a float greater than 0 and within :data:`TIME` (1 ns to
    10⁹ s): the one check of a time step, wherever one enters (``simulate``,
    ``penalty.suggest_stiffness``). InputError naming ``name`` as :func:`number` words it."""
    return number(dt, name, 0.0, strict=True, quantity=TIME)


def run_length(dt: object, duration: object) -> tuple[float, float, int]:
    """(dt [s], duration [s], steps) of a run: both times by :func:`time_step`, dt no longer
    than the duration, and at most :data:`MAX_STEPS` steps (duration / dt rounded, at least 1).
    InputError naming "dt" or "duration" (or "" when dt is longer than the duration)."""
    dt = time_step(dt)
    duration = time_step(duration, "duration")
    if dt > duration:
        raise InputError(
            "",
            f"dt = {dt:g} s is longer than duration = {duration:g} s, so the run would make one "
            f"whole step of {dt:g} s; give a dt no longer than the duration",
        )
    if duration / dt > MAX_STEPS + 0.5:
        raise InputError(
            "dt", f"duration / dt = {duration / dt:.3g} steps, more than the {MAX_STEPS:.0e} a run may make"
        )
    return dt, duration, max(1, int(round(duration / dt)))


def whole_number(value: object, name: str, minimum: int) -> int:
    """``value`` unchanged if it is an int (a Python int, never a bool) of at least ``minimum``;
    InputError naming ``name`` "expected a whole number ≥ minimum" otherwise."""
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise InputError(name, f"expected a whole number ≥ {minimum}, found {value!r}")
    return value


def sixty_four_bits(value: int, name: str) -> int:
    """``value`` (an int) unchanged if it is within :data:`WHOLE_NUMBERS`, the 64 bits the
    compiled kernels take; InputError naming ``name`` otherwise."""
    if not WHOLE_NUMBERS[0] <= value <= WHOLE_NUMBERS[1]:
        raise InputError(
            name, f"expected a whole number of at most 64 bits, found one of {len(str(abs(value)))} digits"
        )
    return value


def one_of(value: _T, name: str, values: Collection[str]) -> _T:
    """``value`` unchanged if it is one of ``values`` (a tuple of strings, or a dict whose
    keys are); InputError naming ``name`` "expected one of ..., found ..." otherwise."""
    if not isinstance(value, str) or value not in values:
        raise InputError(name, f"expected one of {', '.join(values)}, found {value!r}")
    return value


def check_choices(options: object, allowed: Mapping[str, Collection[str]]) -> None:
    """:func:`one_of` on each attribute of ``options`` named in ``allowed`` (name -> tuple of
    values): the choices of a method's Options."""
    for name, values in allowed.items():
        one_of(getattr(options, name), name, values)


def check_counts(options: object, least: Mapping[str, int]) -> None:
    """:func:`whole_number` and :func:`sixty_four_bits` on each attribute of ``options`` named
    in ``least`` (name -> minimum): the counts of a method's Options (sweeps, passes, samples),
    which the compiled kernels take."""
    for name, minimum in least.items():
        sixty_four_bits(whole_number(getattr(options, name), name, minimum), name)


def check_flags(options: object, names: Collection[str]) -> None:
    """InputError naming the first attribute of ``options`` among ``names`` that is not True or
    False: the switches of a method's Options."""
    for name in names:
        value = getattr(options, name)
        if not isinstance(value, bool):
            raise InputError(name, f"expected true or false, found {value!r}")


def as_array(value: Any, name: str, what: str) -> np.ndarray:
    """``value`` as a float array of any shape; InputError naming ``name`` "expected ``what``"
    for strings, ragged lists and ints beyond the float range."""
    try:
        return np.asarray(value, dtype=float)
    except (TypeError, ValueError, OverflowError):
        raise InputError(name, f"expected {what}, found {value!r}") from None


def vector(
    value: Any, name: str, size: int = 3, quantity: Quantity | None = None, positive: bool = False
) -> np.ndarray:
    """``value`` as a float array (size,) of finite numbers, each within ``quantity``'s
    magnitudes when one is given, and greater than 0 where ``positive``; InputError naming
    ``name`` otherwise."""
    array = as_array(value, name, f"a list of {size} numbers")
    if array.shape != (size,):
        raise InputError(name, f"expected a list of {size} numbers, found {value!r}")
    if not np.isfinite(array).all():
        raise InputError(name, f"expected finite numbers, found {value!r}")
    if positive and (array <= 0).any():
        raise InputError(name, f"every component must be positive (greater than 0), found {array.tolist()}")
    if quantity is not None:
        quantity.check(array, name, positive)
    return array


def unit_quaternion(value: Any, name: str) -> np.ndarray:
    """``value`` (w, x, y, z) as a unit quaternion (4,), components within :data:`DIRECTION`;
    InputError naming ``name`` for a zero one."""
    q = vector(value, name, 4, quantity=DIRECTION)
    norm = np.linalg.norm(q)
    if norm < 1e-12:
        raise InputError(name, "a zero quaternion is no rotation; use [1, 0, 0, 0] for none")
    return q / norm


def file_path(file: object) -> str:
    """``file`` (a str or os.PathLike) as a path string; InputError("file", ...) otherwise."""
    if not isinstance(file, (str, os.PathLike)):
        raise InputError("file", f"expected the path of a mesh file (OBJ, STL or PLY), found {file!r}")
    return os.fspath(file)


# -- model sizes ----------------------------------------------------------------------------


def derived_mass(mass: float, name: str) -> None:
    """InputError naming ``name`` (the density it came from) unless ``mass`` [kg] is within
    the bounds of :data:`MASS`."""
    if not MASS.smallest <= mass <= MASS.largest:
        raise InputError(
            name,
            f"gives a mass of {mass:g} kg, outside the {MASS.smallest:g} to {MASS.largest:g} kg "
            f"accepted (see Limits in docs/scene-format.md)",
        )


def check_dynamic_count(count: int, field: str, what: str, already: int = 0) -> None:
    """InputError naming ``field`` when ``what`` (``count`` more bodies, particles or cloth
    vertices, after ``already``) would take a model past :data:`MAX_DYNAMIC`, before anything
    is built."""
    if already + count > MAX_DYNAMIC:
        raise InputError(
            field,
            f"{what} would make {already + count:,} bodies, particles and cloth vertices, more "
            f"than the {MAX_DYNAMIC:,} a model may hold (each costs kilobytes of memory a step)",
        )
