"""A rigid body's inertia as given (``add_body(inertia=...)``, ``inertia = ...`` in a scene file).

Two spellings, both about the body's centre of mass, in the frame its shape is given in (a box's
or capsule's own axes, the frame a convex shape's points are given in), in kg m²:

* ``[Ixx, Iyy, Izz]``: the principal moments, the axes being that frame's;
* a full symmetric 3×3 tensor ``[[Ixx, Ixy, Ixz], [Ixy, Iyy, Iyz], [Ixz, Iyz, Izz]]``.

:func:`checked_tensor` checks either and returns the 3×3 tensor: numbers, finite, symmetric,
positive definite, and the triangle inequality of the principal moments (each at most the sum of
the other two, which every real mass distribution meets). :func:`principal` splits it into the
principal moments (3,) and the rotation (3, 3) whose columns are the principal axes in the given
frame: contactlab keeps a body's frame on its principal axes (``Model.body_inertia`` holds three
moments), so a tensor with off-diagonal terms turns the body's frame by that rotation — see
:meth:`contactlab.builder.ModelBuilder.add_body` for which shapes take one.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from .errors import InputError
from .hull_geometry import principal_frame

SYMMETRY_TOLERANCE = 1e-9  # relative to the largest term: a tensor this close to symmetric counts as symmetric
SPELLINGS = "three principal moments [Ixx, Iyy, Izz] or a 3x3 tensor (kg m^2)"
TRIANGLE_TOLERANCE = 1e-9  # relative to the sum of the moments: round-off in a thin rod's or a flat plate's


def checked_tensor(value: ArrayLike, name: str = "inertia") -> np.ndarray:
    """The inertia tensor (3, 3) [kg m²] of ``value`` (three principal moments or a symmetric
    3×3 tensor); InputError naming ``name`` for anything else, in one sentence."""
    try:
        array = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(name, f"expected {SPELLINGS}, found values that are not numbers") from None
    if array.shape not in ((3,), (3, 3)):
        raise InputError(
            name,
            f"expected {SPELLINGS}, found an array of shape {array.shape}",
        )
    if not np.isfinite(array).all():
        raise InputError(name, "expected finite numbers (kg m^2), found inf or nan")
    tensor = np.diag(array) if array.ndim == 1 else array
    scale = float(np.abs(tensor).max())
    asymmetry = np.abs(tensor - tensor.T)
    if asymmetry.max() > SYMMETRY_TOLERANCE * scale:
        i, j = np.unravel_index(int(np.argmax(asymmetry)), (3, 3))
        raise InputError(
            name,
            f"expected a symmetric tensor, found [{i}][{j}] = {tensor[i, j]:g} but [{j}][{i}] = {tensor[j, i]:g}",
        )
    tensor = 0.5 * (tensor + tensor.T)
    moments = np.linalg.eigvalsh(tensor)
    if not moments.min() > 0.0:
        raise InputError(
            name,
            f"expected a positive definite tensor (every principal moment > 0 kg m^2), "
            f"found principal moments {_listed(moments)}",
        )
    largest = float(moments.max())
    if largest > (moments.sum() - largest) * (1.0 + TRIANGLE_TOLERANCE):
        raise InputError(
            name,
            f"the principal moments {_listed(moments)} break the triangle inequality (the largest, "
            f"{largest:g}, exceeds the sum of the other two, {moments.sum() - largest:g}), which no mass can have",
        )
    return tensor


def principal(tensor: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(moments (3,) [kg m²], axes (3, 3)) of a checked tensor: the columns of ``axes`` are the
    principal axes in the given frame (a proper rotation, the identity for a diagonal tensor, else
    the one nearest it: :func:`contactlab.hull_geometry.principal_frame`)."""
    return principal_frame(tensor)


def _listed(moments):
    return ", ".join(f"{m:g}" for m in moments) + " kg m^2"
