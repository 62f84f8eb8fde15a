"""Unit quaternions (w, x, y, z) and rotation matrices.

Vectorized over the leading axis: ``q`` has shape (count, 4), matrices (count, 3, 3).
Angular velocities are in the world frame [rad/s].
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from .compiling import njit


def normalize(q: np.ndarray) -> np.ndarray:
    """Unit quaternions, shape (count, 4); a zero quaternion is an input error upstream."""
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def to_matrix(q: ArrayLike) -> np.ndarray:
    """Rotation matrices R (count, 3, 3) with x_world = R x_body, from unit q (count, 4) (or any
    leading shape (..., 4) → (..., 3, 3)). Compiled: it runs several times a step, and its
    NumPy form cost 24 µs for a single body."""
    q = np.asarray(q, dtype=float)
    flat = np.ascontiguousarray(q.reshape(-1, 4))
    if not flat.flags.writeable:  # a Model's arrays: Numba would compile a read-only twin
        flat = flat.copy()
    return matrices(flat).reshape(q.shape[:-1] + (3, 3))


@njit(cache=True)
def matrices(q: np.ndarray) -> np.ndarray:
    """``to_matrix`` on q (count, 4), the same arithmetic in the same order as element by element."""
    R = np.empty((q.shape[0], 3, 3))
    for i in range(q.shape[0]):
        w, x, y, z = q[i, 0], q[i, 1], q[i, 2], q[i, 3]
        R[i, 0, 0] = 1 - 2 * (y * y + z * z)
        R[i, 0, 1] = 2 * (x * y - w * z)
        R[i, 0, 2] = 2 * (x * z + w * y)
        R[i, 1, 0] = 2 * (x * y + w * z)
        R[i, 1, 1] = 1 - 2 * (x * x + z * z)
        R[i, 1, 2] = 2 * (y * z - w * x)
        R[i, 2, 0] = 2 * (x * z - w * y)
        R[i, 2, 1] = 2 * (y * z + w * x)
        R[i, 2, 2] = 1 - 2 * (x * x + y * y)
    return R


def multiply(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton product p ⊗ q, shapes (count, 4)."""
    pw, px, py, pz = p[..., 0], p[..., 1], p[..., 2], p[..., 3]
    qw, qx, qy, qz = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack(
        [
            pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
        ],
        axis=-1,
    )


def from_rotation_vector(phi: np.ndarray) -> np.ndarray:
    """Quaternions (count, 4) of rotations by angle |phi| about phi/|phi|; phi (count, 3) [rad]."""
    angle = np.linalg.norm(phi, axis=-1)
    half = 0.5 * angle
    # sin(half)/angle, with its limit 1/2 for tiny angles
    small = angle < 1e-8
    scale = np.where(small, 0.5 - angle * angle / 48.0, np.sin(half) / np.where(small, 1.0, angle))
    return np.concatenate([np.cos(half)[..., None], phi * scale[..., None]], axis=-1)


def integrate(q: np.ndarray, angular_velocity: np.ndarray, dt: float | np.ndarray) -> np.ndarray:
    """Orientation after rotating at constant world angular velocity for dt seconds.

    Uses the exponential map q⁺ = exp(dt ω / 2) ⊗ q, which stays unit; renormalized
    against round-off: normalize(multiply(from_rotation_vector(ω dt), q)), compiled (it runs
    for every body several times a step). Shapes: q (count, 4), angular_velocity (count, 3),
    dt a scalar, (count,) or (count, 1) [s].
    """
    q = np.ascontiguousarray(q, dtype=float)
    # a writable copy: the broadcast view is read-only, and for one body no copy would be made,
    # so Numba compiled a read-only twin of integrate_compiled
    step = np.broadcast_to(np.ravel(np.asarray(dt, dtype=float)), (len(q),)).copy()
    return integrate_compiled(q, np.ascontiguousarray(angular_velocity, dtype=float), step)


@njit(cache=True)
def integrate_compiled(q: np.ndarray, angular_velocity: np.ndarray, dt: np.ndarray) -> np.ndarray:
    """``integrate`` body by body, compiled; dt (count,) [s]."""
    out = np.empty_like(q)
    for i in range(q.shape[0]):
        px, py, pz = angular_velocity[i, 0] * dt[i], angular_velocity[i, 1] * dt[i], angular_velocity[i, 2] * dt[i]
        angle = np.sqrt(px * px + py * py + pz * pz)
        half = 0.5 * angle
        scale = 0.5 - angle * angle / 48.0 if angle < 1e-8 else np.sin(half) / angle  # sin(half)/angle → ½
        aw, ax, ay, az = np.cos(half), px * scale, py * scale, pz * scale
        qw, qx, qy, qz = q[i, 0], q[i, 1], q[i, 2], q[i, 3]
        w = aw * qw - ax * qx - ay * qy - az * qz  # a ⊗ q
        x = aw * qx + ax * qw + ay * qz - az * qy
        y = aw * qy - ax * qz + ay * qw + az * qx
        z = aw * qz + ax * qy - ay * qx + az * qw
        length = np.sqrt(w * w + x * x + y * y + z * z)
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = w / length, x / length, y / length, z / length
    return out


def world_inertia(R: ArrayLike, principal: ArrayLike) -> np.ndarray:
    """World-frame tensors R diag(principal) Rᵀ, shape (count, 3, 3); principal (count, 3)."""
    return world_tensors(np.ascontiguousarray(R, dtype=float), np.ascontiguousarray(principal, dtype=float))


@njit(cache=True)
def world_tensors(R: np.ndarray, principal: np.ndarray) -> np.ndarray:
    """``world_inertia``, compiled, entry by entry as Σ_k R_ik p_k R_jk (the stepping loop and the
    methods' steps take the same numbers from it)."""
    out = np.empty_like(R)
    for b in range(R.shape[0]):
        for i in range(3):
            for j in range(3):
                out[b, i, j] = (
                    R[b, i, 0] * principal[b, 0] * R[b, j, 0]
                    + R[b, i, 1] * principal[b, 1] * R[b, j, 1]
                    + R[b, i, 2] * principal[b, 2] * R[b, j, 2]
                )
    return out
