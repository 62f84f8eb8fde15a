"""Internal forces of cloth: a network of damped Hooke springs between particles.

A spring s joins particles i = spring_particles[s, 0] and j = spring_particles[s, 1], with
rest length L, stiffness k [N/m] and damping c [N s/m] along its axis (see
``ModelBuilder.add_cloth``: stretch, shear and bending springs are all of this one kind).
With d = x_j − x_i, l = |d| and the unit axis u = d / l, the spring pulls i towards j by

    f_i = k (l − L) u + c ((v_j − v_i) · u) u,        f_j = −f_i,

(the force on j is −k (|d_ji| − L) d̂_ji written from j's side), and stores ½ k (l − L)².

Its Jacobians, for the implicit integrators, are 3×3 blocks:

    ∂f_i/∂x_j = K_s = k u uᵀ + k (1 − L/l)(I − u uᵀ),      ∂f_i/∂v_j = D_s = c u uᵀ,

and ∂f_i/∂x_i = −K_s, ∂f_j/∂x_i = K_s, ∂f_j/∂x_j = −K_s (D_s likewise). The position
derivative of the damping force is left out of K (the usual choice: it is small, and keeping it
makes K unsymmetric). K_s has the eigenvalue k along u and k (1 − L/l) across it: a compressed
spring (l < L) makes the transverse part negative, so the global K may lose its negative
semidefiniteness and M − h D − h² K its positive definiteness (the buckling instability of
implicit cloth). ``clamp_compressed=True`` replaces (1 − L/l) by max(0, 1 − L/l), the common
remedy (Choi and Ko 2002): K stays negative semidefinite and the matrix of backward Euler
stays symmetric positive definite, at the price of an approximate Jacobian for compressed
springs (the step's fixed point, f = 0 at rest, is unchanged).

Shapes: P particles, S springs; the DOF vector of the particles has 3P entries, particle p
owns [3p, 3p + 3). Everything is vectorized over springs (no Python loop per spring).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import scipy.sparse as sp

    from ..model import Model

TINY_LENGTH = 1e-12  # m: a spring shorter than this has no direction; its axis is taken as zero


def _axes(model, particle_position):
    """(i (S,), j (S,), d (S,3), l (S,), u (S,3)) of the springs at the given positions."""
    i, j = model.spring_particles[:, 0], model.spring_particles[:, 1]
    d = particle_position[j] - particle_position[i]
    length = np.sqrt(np.einsum("si,si->s", d, d))
    u = d / np.where(length > TINY_LENGTH, length, 1.0)[:, None]
    u[length <= TINY_LENGTH] = 0.0
    return i, j, d, length, u


def _gather(index_i, index_j, force_on_i, count):
    """Sum per-spring forces (S, 3) on i and their opposites on j into (count, 3)."""
    total = np.empty((count, 3))
    for axis in range(3):  # three bincounts: vectorized over the springs
        total[:, axis] = np.bincount(index_i, force_on_i[:, axis], minlength=count) - np.bincount(
            index_j, force_on_i[:, axis], minlength=count
        )
    return total


def spring_tensions(
    model: Model, particle_position: np.ndarray, particle_velocity: np.ndarray | None = None
) -> np.ndarray:
    """Scalar pull of each spring along its axis (S,) [N]: k (l − L) + c (v_j − v_i)·u
    (positive when it pulls its ends together)."""
    i, j, _, length, u = _axes(model, particle_position)
    tension = model.spring_stiffness * (length - model.spring_rest_length)
    if particle_velocity is not None:
        tension = tension + model.spring_damping * np.einsum("si,si->s", particle_velocity[j] - particle_velocity[i], u)
    return tension


def spring_forces(
    model: Model, particle_position: np.ndarray, particle_velocity: np.ndarray | None = None
) -> np.ndarray:
    """Spring forces on the particles (P, 3) [N] at positions (P, 3) [m] and velocities
    (P, 3) [m/s] (None: no damping force). Zero for particles without springs."""
    count = len(particle_position)
    if model.spring_count == 0:
        return np.zeros((count, 3))
    i, j, _, _, u = _axes(model, particle_position)
    tension = spring_tensions(model, particle_position, particle_velocity)
    return _gather(i, j, tension[:, None] * u, count)


@dataclass(frozen=True)
class SpringPattern:
    """Where each spring's four 3×3 blocks sit in a CSR matrix (3P, 3P) that also holds the whole
    diagonal: the sparsity of K, D and the backward Euler matrix, fixed by the cloth's topology,
    so a step fills the values and never sorts indices. nnz entries."""

    indptr: np.ndarray  # (3P + 1,) int64
    indices: np.ndarray  # (nnz,) int64, column of each entry, sorted within a row
    rows: np.ndarray  # (nnz,) int64, row of each entry
    slots: np.ndarray  # (S, 4, 3, 3) int64, entry of blocks (i, i), (j, j), (i, j), (j, i)
    diagonal: np.ndarray  # (3P,) int64, entry of each diagonal element

    def values(self, blocks: np.ndarray) -> np.ndarray:
        """Entries (nnz,) of the matrix with −B on each spring's (i, i) and (j, j) blocks and +B on
        its (i, j) and (j, i) blocks, for the springs' blocks B (S, 3, 3); springs sharing an entry add."""
        signed = np.stack([-blocks, -blocks, blocks, blocks], axis=1)
        return np.bincount(self.slots.ravel(), signed.ravel(), minlength=len(self.indices))

    def matrix(self, values: np.ndarray) -> sp.csr_matrix:
        """The CSR matrix (3P, 3P) with entries ``values`` (nnz,)."""
        import scipy.sparse as sp  # SciPy on first use: it is a tenth of `import contactlab`

        n = len(self.indptr) - 1
        return sp.csr_matrix((values, self.indices, self.indptr), shape=(n, n))


def spring_pattern(spring_particles: np.ndarray, count: int) -> SpringPattern:
    """The ``SpringPattern`` of springs joining ``spring_particles`` (S, 2) among ``count`` particles."""
    n = 3 * count
    i, j = spring_particles[:, 0], spring_particles[:, 1]
    dof = np.arange(3)
    first = 3 * np.stack([i, j, i, j], axis=1)[:, :, None, None] + dof[None, None, :, None]
    second = 3 * np.stack([i, j, j, i], axis=1)[:, :, None, None] + dof[None, None, None, :]
    keys = np.concatenate([(first * n + second).ravel(), np.arange(n) * (n + 1)])
    unique, entry = np.unique(keys, return_inverse=True)
    rows = unique // n
    indptr = np.concatenate([[0], np.cumsum(np.bincount(rows, minlength=n))])
    slots = entry[: keys.size - n].reshape(len(i), 4, 3, 3)
    return SpringPattern(indptr, unique % n, rows, slots, entry[keys.size - n :])


def jacobian_blocks(
    model: Model, particle_position: np.ndarray, clamp_compressed: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """Each spring's blocks K_s [N/m] and D_s [N s/m] (S, 3, 3) of the module docstring, at
    positions (P, 3) [m]; ``clamp_compressed`` as in ``spring_jacobians``."""
    _, _, _, length, u = _axes(model, particle_position)
    k, rest = model.spring_stiffness, model.spring_rest_length
    outer = u[:, :, None] * u[:, None, :]  # (S, 3, 3) u uᵀ
    with np.errstate(divide="ignore", invalid="ignore"):
        transverse = np.where(length > TINY_LENGTH, 1.0 - rest / length, 0.0)
    if clamp_compressed:
        transverse = np.maximum(transverse, 0.0)
    stiffness = k[:, None, None] * (outer + transverse[:, None, None] * (np.eye(3) - outer))
    return stiffness, model.spring_damping[:, None, None] * outer


def block_product(model: Model, blocks: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """(Σ_s B_s over the springs, assembled as in ``SpringPattern.values``) applied to ``vectors``
    (P, 3): each spring adds B_s (v_j − v_i) on i and its opposite on j; (P, 3)."""
    i, j = model.spring_particles[:, 0], model.spring_particles[:, 1]
    pull = np.einsum("sab,sb->sa", blocks, vectors[j] - vectors[i])
    return _gather(i, j, pull, len(vectors))


def spring_jacobians(
    model: Model,
    particle_position: np.ndarray,
    particle_velocity: np.ndarray | None = None,
    clamp_compressed: bool = False,
) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """(K, D): the Jacobians ∂f/∂x [N/m] and ∂f/∂v [N s/m] of ``spring_forces``, SciPy CSR
    matrices (3P, 3P), symmetric, with the blocks of the module docstring (on the pattern of
    ``model.spring_pattern``, whose diagonal is always stored).

    K leaves out the position derivative of the damping force (exact when the damping is 0 or
    the velocities are equal along each spring). ``clamp_compressed``: drop the negative
    transverse stiffness of compressed springs, so K is negative semidefinite (see the module
    docstring); False gives the exact derivative. ``particle_velocity`` is not used (D does not
    depend on it); it is accepted so the call mirrors ``spring_forces``.
    """
    count = len(particle_position)
    if model.spring_count == 0:
        import scipy.sparse as sp

        empty = sp.csr_matrix((3 * count, 3 * count))
        return empty, empty.copy()
    stiffness, damping = jacobian_blocks(model, particle_position, clamp_compressed)
    pattern = model.spring_pattern
    return pattern.matrix(pattern.values(stiffness)), pattern.matrix(pattern.values(damping))


def spring_energy(model: Model, particle_position: np.ndarray) -> float:
    """Elastic energy of the springs Σ ½ k (l − L)² [J] at positions (P, 3) [m]."""
    if model.spring_count == 0:
        return 0.0
    _, _, _, length, _ = _axes(model, particle_position)
    return float(0.5 * np.sum(model.spring_stiffness * (length - model.spring_rest_length) ** 2))
