"""Small compiled geometry kernels shared by the pair routines: 3-vector arithmetic and the
closest points of two segments.

Written out component by component (quick to compile, no temporaries beyond the (3,) result,
no BLAS); float64, no fastmath. Used by the capsule pairs (:mod:`.capsule`,
:mod:`.capsule_convex`) and the mesh features (:mod:`.mesh_features`).
"""

from __future__ import annotations

import numpy as np

from ..compiling import njit

LINE_SIN2 = 1e-20  # |a × b|² below this: lines treated as exactly parallel in closest points


@njit(cache=True)
def dot(a: np.ndarray, b: np.ndarray) -> float:
    """a · b for (3,) arrays."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True)
def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a × b for (3,) arrays, as a new array."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


@njit(cache=True)
def norm(a: np.ndarray) -> float:
    """|a| for a (3,) array."""
    return np.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])


@njit(cache=True)
def clamp(x: float, lo: float, hi: float) -> float:
    """x clamped to [lo, hi]."""
    return lo if x < lo else (hi if x > hi else x)


@njit(cache=True)
def column(rotation: np.ndarray, k: int) -> np.ndarray:
    """Column ``k`` of a 3×3 matrix, as a fresh contiguous (3,) array (the body axis k in world)."""
    return np.array([rotation[0, k], rotation[1, k], rotation[2, k]])


@njit(cache=True)
def rotate(rotation: np.ndarray, v: np.ndarray) -> np.ndarray:
    """rotation @ v for a 3×3 matrix, written out (cheaper to compile than the BLAS product)."""
    return np.array(
        [
            rotation[0, 0] * v[0] + rotation[0, 1] * v[1] + rotation[0, 2] * v[2],
            rotation[1, 0] * v[0] + rotation[1, 1] * v[1] + rotation[1, 2] * v[2],
            rotation[2, 0] * v[0] + rotation[2, 1] * v[1] + rotation[2, 2] * v[2],
        ]
    )


@njit(cache=True)
def unrotate(rotation: np.ndarray, v: np.ndarray) -> np.ndarray:
    """rotation.T @ v for a 3×3 matrix: :func:`rotate` through the transposed view (no copy;
    the same products summed in the same order)."""
    return rotate(rotation.T, v)


@njit(cache=True)
def sphere_gap(center_a: np.ndarray, center_b: np.ndarray, radii: float) -> tuple[np.ndarray, float, float]:
    """Two spheres of radii summing to ``radii`` [m] about center_a and center_b (3,) [m] (a
    capsule's: the closest points of its segment): (d = center_a − center_b (3,) [m], |d| [m],
    depth = radii − |d| [m], > 0 overlapping)."""
    d = axpy(center_a, -1.0, center_b)
    distance = norm(d)
    return d, distance, radii - distance


@njit(cache=True)
def row_difference(points: np.ndarray, i: int, j: int) -> tuple[float, float, float]:
    """points[i] − points[j] of an (n, 3) array, as three scalars (no temporary array)."""
    return points[i, 0] - points[j, 0], points[i, 1] - points[j, 1], points[i, 2] - points[j, 2]


@njit(cache=True)
def to_local(rotation: np.ndarray, center: np.ndarray, x: np.ndarray) -> np.ndarray:
    """rotation.T @ (x − center): the point x (3,) [m] in the frame of centre (3,) [m] and
    rotation (3, 3) (frame → world), one sum per component (no difference vector, no transposed copy)."""
    local = np.empty(3)
    for a in range(3):
        local[a] = (
            rotation[0, a] * (x[0] - center[0])
            + rotation[1, a] * (x[1] - center[1])
            + rotation[2, a] * (x[2] - center[2])
        )
    return local


@njit(cache=True)
def axpy(x: np.ndarray, scale: float, y: np.ndarray) -> np.ndarray:
    """x + scale · y for (3,) arrays, as a new array (written out: quick to compile, no temporaries)."""
    return np.array([x[0] + scale * y[0], x[1] + scale * y[1], x[2] + scale * y[2]])


@njit(cache=True)
def midpoint(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(a + b) / 2 for (3,) arrays."""
    return np.array([0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1]), 0.5 * (a[2] + b[2])])


@njit(cache=True)
def scaled(scale: float, a: np.ndarray) -> np.ndarray:
    """scale · a for a (3,) array."""
    return np.array([scale * a[0], scale * a[1], scale * a[2]])


@njit(cache=True)
def unit_axis(k: int, sign: float) -> np.ndarray:
    """sign · e_k, (3,)."""
    e = np.zeros(3)
    e[k] = sign
    return e


@njit(cache=True)
def segment_closest_parameters(
    center_a: np.ndarray, axis_a: np.ndarray, half_a: float, center_b: np.ndarray, axis_b: np.ndarray, half_b: float
) -> tuple[float, float]:
    """Closest points of two segments ``center + s · axis``, ``|s| ≤ half`` (unit axes).

    Returns ``(s, t)``: the parameters [m] of the closest points on segment A and segment B.
    Robust for zero-length segments (``half = 0``), parallel segments (then the point of A
    nearest to B's centre is chosen, clamped, so the answer is unique) and crossing segments.
    The line–line parameter is computed from cross products (``s = ((b × r)·(a × b)) /
    |a × b|²``, ``r = c_A − c_B``), which keeps its accuracy for nearly parallel axes; then
    it is clamped to A, B's parameter follows and is clamped, and A's is recomputed if B's
    was clamped (Ericson, Real-Time Collision Detection, 5.1.9).
    """
    r0 = center_a[0] - center_b[0]
    r1 = center_a[1] - center_b[1]
    r2 = center_a[2] - center_b[2]
    b = axis_a[0] * axis_b[0] + axis_a[1] * axis_b[1] + axis_a[2] * axis_b[2]
    c = axis_a[0] * r0 + axis_a[1] * r1 + axis_a[2] * r2
    f = axis_b[0] * r0 + axis_b[1] * r1 + axis_b[2] * r2
    n0 = axis_a[1] * axis_b[2] - axis_a[2] * axis_b[1]
    n1 = axis_a[2] * axis_b[0] - axis_a[0] * axis_b[2]
    n2 = axis_a[0] * axis_b[1] - axis_a[1] * axis_b[0]
    sin2 = n0 * n0 + n1 * n1 + n2 * n2
    if sin2 > LINE_SIN2:
        m0 = axis_b[1] * r2 - axis_b[2] * r1  # m = axis_b × r
        m1 = axis_b[2] * r0 - axis_b[0] * r2
        m2 = axis_b[0] * r1 - axis_b[1] * r0
        s = clamp((m0 * n0 + m1 * n1 + m2 * n2) / sin2, -half_a, half_a)
    else:
        s = clamp(-c, -half_a, half_a)  # parallel: A's point nearest B's centre
    t = b * s + f
    if t < -half_b:
        t = -half_b
        s = clamp(b * t - c, -half_a, half_a)
    elif t > half_b:
        t = half_b
        s = clamp(b * t - c, -half_a, half_a)
    return s, t
