"""The generalized velocity and the mass matrix of SPEC D1.

Every degree of freedom in one vector v of length N = 6B + 3P: body i owns [6i, 6i+6) =
(linear velocity [m/s], world angular velocity [rad/s]); particle j owns [6B + 3j, 6B + 3j + 3).
The mass matrix is block diagonal: m I₃ and the world inertia tensor per body, m I₃ per
particle. This is the layout of ``contacts.jacobian``, so a contact force F_p (3C,) acts on the
degrees of freedom as f = Jᵀ F_p and changes their velocities by h M⁻¹ Jᵀ F_p.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from .. import rotations
from ..compiling import njit
from .integrators import particle_system

if TYPE_CHECKING:
    from ..model import Model
    from ..state import State


def stack(body_velocity: np.ndarray, body_angular_velocity: np.ndarray, particle_velocity: np.ndarray) -> np.ndarray:
    """v (N,) from body_velocity (B,3), body_angular_velocity (B,3), particle_velocity (P,3)."""
    return stacked(
        *(np.ascontiguousarray(a, dtype=float) for a in (body_velocity, body_angular_velocity, particle_velocity))
    )


def unstack(v: np.ndarray, body_count: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(body_velocity (B,3), body_angular_velocity (B,3), particle_velocity (P,3)) from v (N,),
    copies, for B = body_count."""
    return unstacked(np.ascontiguousarray(v, dtype=float), body_count)


@njit(cache=True)
def stacked(body_velocity: np.ndarray, body_angular_velocity: np.ndarray, particle_velocity: np.ndarray) -> np.ndarray:
    """``stack``, compiled (the compiled steps call it too): v (N,) from (B, 3), (B, 3), (P, 3).
    Copied by loops: two concatenations and a ravel compile three of NumPy's routines, about half
    a second of a cold start, and allocate two arrays more."""
    B, P = body_velocity.shape[0], particle_velocity.shape[0]
    v = np.empty(6 * B + 3 * P)
    for i in range(B):
        for j in range(3):
            v[6 * i + j] = body_velocity[i, j]
            v[6 * i + 3 + j] = body_angular_velocity[i, j]
    for p in range(P):
        for j in range(3):
            v[6 * B + 3 * p + j] = particle_velocity[p, j]
    return v


@njit(cache=True)
def unstacked(v: np.ndarray, body_count: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``unstack``, compiled (the compiled steps call it too): copies (B, 3), (B, 3), (P, 3) of a
    C-contiguous v (N,), by loops (less to compile than copies of strided views)."""
    B = body_count
    P = (v.shape[0] - 6 * B) // 3
    linear, angular, particle = np.empty((B, 3)), np.empty((B, 3)), np.empty((P, 3))
    for i in range(B):
        for j in range(3):
            linear[i, j] = v[6 * i + j]
            angular[i, j] = v[6 * i + 3 + j]
    for p in range(P):
        for j in range(3):
            particle[p, j] = v[6 * B + 3 * p + j]
    return linear, angular, particle


def _block_diagonal(body_linear, body_angular, particle):
    """CSR (N, N) from per-body scalars (B,), per-body 3×3 blocks (B,3,3), per-particle scalars (P,)."""
    B, P = len(body_linear), len(particle)
    blocks = np.zeros((B, 6, 6))
    blocks[:, :3, :3] = body_linear[:, None, None] * np.eye(3)
    blocks[:, 3:, 3:] = body_angular
    rows = (6 * np.arange(B)[:, None, None] + np.arange(6)[None, :, None]).repeat(6, axis=2)
    cols = (6 * np.arange(B)[:, None, None] + np.arange(6)[None, None, :]).repeat(6, axis=1)
    diagonal = 6 * B + np.arange(3 * P)
    return sp.csr_matrix(
        (
            np.concatenate([blocks.ravel(), np.repeat(particle, 3)]),
            (np.concatenate([rows.ravel(), diagonal]), np.concatenate([cols.ravel(), diagonal])),
        ),
        shape=(6 * B + 3 * P, 6 * B + 3 * P),
    )


def mass_matrix(model: Model, body_orientation: np.ndarray) -> sp.csr_matrix:
    """M (N, N) CSR [kg, kg m²] at the given orientations (B, 4)."""
    R = rotations.to_matrix(body_orientation)
    return _block_diagonal(model.body_mass, rotations.world_inertia(R, model.body_inertia), model.particle_mass)


def inverse_mass_matrix(model: Model, body_orientation: np.ndarray) -> sp.csr_matrix:
    """M⁻¹ (N, N) CSR [1/kg, 1/(kg m²)] at the given orientations (B, 4)."""
    R = rotations.to_matrix(body_orientation)
    return _block_diagonal(
        model.body_inverse_mass, rotations.world_inertia(R, model.body_inverse_inertia), model.particle_inverse_mass
    )


def implicit_base(
    model: Model, state: State, dt: float, v_free: np.ndarray, cloth_implicit: bool = True
) -> tuple[sp.csr_matrix, np.ndarray, np.ndarray]:
    """The backward Euler system without contacts, A₀ v⁺ = b₀, over all N degrees of freedom.

    Bodies: M v⁺ = M v* (gravity and the gyroscopic term are already in v*). Particles: the
    cloth's linearized springs, A_p = M − h D − h² K and A_p v⁺ = A_p v + h (f + h K v) (see
    dynamics.integrators.particle_system), so contact springs added to A₀ are solved together
    with the cloth's own; with ``cloth_implicit`` False (the cloth stepped explicitly, its
    springs already in v*) M v⁺ = M v* for particles too. Returns (A₀ CSR (N, N), b₀ (N,), free (N,) bool: the DOFs
    that move —
    a pinned vertex's and a kinematic body's do not).
    """
    B = model.body_count
    M = mass_matrix(model, state.body_orientation)
    bodies = M[: 6 * B, : 6 * B]
    if model.spring_count and cloth_implicit:
        system = particle_system(model, state, dt)
        particles = system.matrix
        b_particles = particles @ state.particle_velocity.ravel() + system.rhs
    else:
        particles = M[6 * B :, 6 * B :]
        b_particles = particles @ v_free[6 * B :]
    A0 = sp.block_diag([bodies, particles], format="csr")
    free = np.concatenate([np.repeat(~model.body_kinematic, 6), np.repeat(~model.particle_pinned, 3)])
    return A0, np.concatenate([bodies @ v_free[: 6 * B], b_particles]), free
