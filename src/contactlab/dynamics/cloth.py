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
owns [3p, 3p + 3). Each stage is one compiled loop over the springs (Numba), which also sums
their pulls onto the particles: no Python loop per spring or per particle.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..compiling import njit
from ..model import derived

if TYPE_CHECKING:
    import scipy.sparse as sp

    from ..model import Model

Springs = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]  # what ``_springs`` gathers
TINY_LENGTH = 1e-12  # m: a spring shorter than this has no direction; its axis is taken as zero


def _axes(model, particle_position):
    """(length (S,) [m], u (S, 3)) of the springs at the given positions (P, 3) [m]."""
    return spring_axes(model.spring_particles, _float_rows(particle_position))


def _springs(model):
    """The model's spring arrays as the compiled kernels take them, gathered once: (particles (S, 2),
    stiffness k (S,) [N/m], rest length L (S,) [m], damping c (S,) [N s/m])."""
    return (model.spring_particles, model.spring_stiffness, model.spring_rest_length, model.spring_damping)


def _float_rows(array):
    """``array`` as the compiled kernels take it: a C-contiguous float64 array."""
    return np.ascontiguousarray(array, dtype=np.float64)


@njit(cache=True)
def _axis(particle_position, i, j):
    """(l [m], u_x, u_y, u_z) of the spring from particle i to j: d = x_j − x_i, l = |d|, u = d / l
    (u = 0 for a spring shorter than TINY_LENGTH: it has no direction)."""
    dx = particle_position[j, 0] - particle_position[i, 0]
    dy = particle_position[j, 1] - particle_position[i, 1]
    dz = particle_position[j, 2] - particle_position[i, 2]
    length = np.sqrt(dx * dx + dy * dy + dz * dz)
    if length <= TINY_LENGTH:
        return length, 0.0, 0.0, 0.0
    return length, dx / length, dy / length, dz / length


@njit(cache=True)
def spring_axes(spring_particles: np.ndarray, particle_position: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each spring's length l (S,) [m] and unit axis u (S, 3) from i to j, at positions (P, 3) [m]."""
    S = spring_particles.shape[0]
    length, u = np.empty(S), np.empty((S, 3))
    for s in range(S):
        length[s], u[s, 0], u[s, 1], u[s, 2] = _axis(particle_position, spring_particles[s, 0], spring_particles[s, 1])
    return length, u


@njit(cache=True)
def _tension(springs, particle_position, particle_velocity, damped, s):
    """(k (l − L) + c (v_j − v_i)·u [N], u (3 floats)) of spring s of ``springs`` (``_springs``);
    without the damping term unless ``damped``."""
    spring_particles, stiffness, rest_length, damping = springs
    i, j = spring_particles[s, 0], spring_particles[s, 1]
    length, ux, uy, uz = _axis(particle_position, i, j)
    tension = stiffness[s] * (length - rest_length[s])
    if damped:
        closing = (
            (particle_velocity[j, 0] - particle_velocity[i, 0]) * ux
            + (particle_velocity[j, 1] - particle_velocity[i, 1]) * uy
            + (particle_velocity[j, 2] - particle_velocity[i, 2]) * uz
        )
        tension = tension + damping[s] * closing
    return tension, ux, uy, uz


@njit(cache=True)
def forces(springs: Springs, particle_position: np.ndarray, particle_velocity: np.ndarray, damped: bool) -> np.ndarray:
    """``spring_forces`` on the model's spring arrays ``springs`` (``_springs``): f_i = tension · u
    on i, −f_i on j, summed into (P, 3) [N] in one pass over the springs. The pulls on the i ends
    and on the j ends are summed apart, in spring order, and subtracted at the end: a fixed order
    (reruns give the same bits) that also matches the bincount sums of the NumPy version this
    replaced."""
    P = particle_position.shape[0]
    on_i, on_j = np.zeros((P, 3)), np.zeros((P, 3))
    spring_particles = springs[0]
    for s in range(spring_particles.shape[0]):
        tension, ux, uy, uz = _tension(springs, particle_position, particle_velocity, damped, s)
        i, j = spring_particles[s, 0], spring_particles[s, 1]
        on_i[i, 0] += tension * ux
        on_i[i, 1] += tension * uy
        on_i[i, 2] += tension * uz
        on_j[j, 0] += tension * ux
        on_j[j, 1] += tension * uy
        on_j[j, 2] += tension * uz
    return on_i - on_j


def spring_forces(
    model: Model, particle_position: np.ndarray, particle_velocity: np.ndarray | None = None
) -> np.ndarray:
    """Spring forces on the particles (P, 3) [N] at positions (P, 3) [m] and velocities
    (P, 3) [m/s] (None: no damping force). Zero for particles without springs."""
    if model.spring_count == 0:
        return np.zeros((len(particle_position), 3))
    x = _float_rows(particle_position)
    v = x if particle_velocity is None else _float_rows(particle_velocity)
    return forces(_springs(model), x, v, particle_velocity is not None)


@dataclass(frozen=True)
class SpringPattern:
    """Where each spring's four 3×3 blocks sit in a CSR matrix (3P, 3P) that also holds the whole
    diagonal: the sparsity of K, D and the backward Euler matrix, fixed by the cloth's topology,
    so a step fills the values and never sorts indices. nnz entries."""

    indptr: np.ndarray
    """(3P + 1,) int64"""
    indices: np.ndarray
    """(nnz,) int64, column of each entry, sorted within a row"""
    rows: np.ndarray
    """(nnz,) int64, row of each entry"""
    slots: np.ndarray
    """(S, 4, 3, 3) int64, entry of blocks (i, i), (j, j), (i, j), (j, i)"""
    diagonal: np.ndarray
    """(3P,) int64, entry of each diagonal element"""

    def values(self, blocks: np.ndarray) -> np.ndarray:
        """Entries (nnz,) of the matrix with −B on each spring's (i, i) and (j, j) blocks and +B on
        its (i, j) and (j, i) blocks, for the springs' blocks B (S, 3, 3); springs sharing an entry add."""
        return pattern_values(self.slots, _float_rows(blocks), len(self.indices))

    def matrix(self, values: np.ndarray) -> sp.csr_matrix:
        """The CSR matrix (3P, 3P) with entries ``values`` (nnz,)."""
        import scipy.sparse as sp  # SciPy on first use: it is a tenth of `import contactlab`

        n = len(self.indptr) - 1
        return sp.csr_matrix((values, self.indices, self.indptr), shape=(n, n))


@derived
def spring_pattern(model: Model) -> SpringPattern:
    """The ``SpringPattern`` of ``model``'s springs (``spring_particles`` (S, 2) among its P
    particles): fixed by the topology, built on first use and kept with the model."""
    n = 3 * model.particle_count
    i, j = model.spring_particles[:, 0], model.spring_particles[:, 1]
    dof = np.arange(3)
    first = 3 * np.stack([i, j, i, j], axis=1)[:, :, None, None] + dof[None, None, :, None]
    second = 3 * np.stack([i, j, j, i], axis=1)[:, :, None, None] + dof[None, None, None, :]
    keys = np.concatenate([(first * n + second).ravel(), np.arange(n) * (n + 1)])
    unique, entry = np.unique(keys, return_inverse=True)
    rows = unique // n
    indptr = np.concatenate([[0], np.cumsum(np.bincount(rows, minlength=n))])
    slots = entry[: keys.size - n].reshape(len(i), 4, 3, 3)
    return SpringPattern(indptr, unique % n, rows, slots, entry[keys.size - n :])


@njit(cache=True)
def pattern_values(slots: np.ndarray, blocks: np.ndarray, nnz: int) -> np.ndarray:
    """``SpringPattern.values``, compiled: −B_s added at the entries ``slots`` (S, 4, 3, 3) of the
    (i, i) and (j, j) blocks, +B_s at those of (i, j) and (j, i), for blocks (S, 3, 3); (nnz,).
    Entries shared by several springs are summed in spring order (reruns give the same bits)."""
    values = np.zeros(nnz)
    for s in range(slots.shape[0]):
        for block in range(4):
            sign = -1.0 if block < 2 else 1.0
            for a in range(3):
                for b in range(3):
                    values[slots[s, block, a, b]] += sign * blocks[s, a, b]
    return values


@njit(cache=True)
def blocks_of(springs: Springs, particle_position: np.ndarray, clamp_compressed: bool) -> tuple[np.ndarray, np.ndarray]:
    """``jacobian_blocks`` on the model's spring arrays ``springs`` (``_springs``), (S,):
    K_s = k u uᵀ + k (1 − L/l)(I − u uᵀ) and D_s = c u uᵀ (S, 3, 3), written as
    k (u uᵀ + (1 − L/l)(I − u uᵀ)); 1 − L/l is 0 for a spring without direction and clamped at 0
    if ``clamp_compressed``."""
    spring_particles, stiffness, rest_length, damping = springs
    S = spring_particles.shape[0]
    K, D = np.empty((S, 3, 3)), np.empty((S, 3, 3))
    for s in range(S):
        length, ux, uy, uz = _axis(particle_position, spring_particles[s, 0], spring_particles[s, 1])
        transverse = 1.0 - rest_length[s] / length if length > TINY_LENGTH else 0.0
        if clamp_compressed:
            transverse = max(transverse, 0.0)
        u = (ux, uy, uz)
        for a in range(3):
            for b in range(3):
                outer = u[a] * u[b]
                identity = 1.0 if a == b else 0.0
                K[s, a, b] = stiffness[s] * (outer + transverse * (identity - outer))
                D[s, a, b] = damping[s] * outer
    return K, D


def jacobian_blocks(
    model: Model, particle_position: np.ndarray, clamp_compressed: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """Each spring's blocks K_s [N/m] and D_s [N s/m] (S, 3, 3) of the module docstring, at
    positions (P, 3) [m]; ``clamp_compressed`` as in ``spring_jacobians``."""
    return blocks_of(_springs(model), _float_rows(particle_position), clamp_compressed)


@njit(cache=True)
def spring_block_product(spring_particles: np.ndarray, blocks: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """``block_product`` on the springs' particles (S, 2): B_s (v_j − v_i) added on i and
    subtracted on j, each end's sum kept apart in spring order (as ``forces``); (P, 3)."""
    P = vectors.shape[0]
    on_i, on_j = np.zeros((P, 3)), np.zeros((P, 3))
    for s in range(spring_particles.shape[0]):
        i, j = spring_particles[s, 0], spring_particles[s, 1]
        for a in range(3):
            pull = 0.0
            for b in range(3):
                pull += blocks[s, a, b] * (vectors[j, b] - vectors[i, b])
            on_i[i, a] += pull
            on_j[j, a] += pull
    return on_i - on_j


def block_product(model: Model, blocks: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """(Σ_s B_s over the springs, assembled as in ``SpringPattern.values``) applied to ``vectors``
    (P, 3): each spring adds B_s (v_j − v_i) on i and its opposite on j; (P, 3)."""
    return spring_block_product(model.spring_particles, _float_rows(blocks), _float_rows(vectors))


def spring_jacobians(
    model: Model,
    particle_position: np.ndarray,
    particle_velocity: np.ndarray | None = None,
    clamp_compressed: bool = False,
) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """(K, D): the Jacobians ∂f/∂x [N/m] and ∂f/∂v [N s/m] of ``spring_forces``, SciPy CSR
    matrices (3P, 3P), symmetric, with the blocks of the module docstring (on the pattern of
    ``spring_pattern(model)``, whose diagonal is always stored).

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
    pattern = spring_pattern(model)
    return pattern.matrix(pattern.values(stiffness)), pattern.matrix(pattern.values(damping))


def spring_energy(model: Model, particle_position: np.ndarray) -> float:
    """Elastic energy of the springs Σ ½ k (l − L)² [J] at positions (P, 3) [m]."""
    if model.spring_count == 0:
        return 0.0
    length, _ = _axes(model, particle_position)
    return float(0.5 * np.sum(model.spring_stiffness * (length - model.spring_rest_length) ** 2))
