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

from collections import namedtuple
from typing import TYPE_CHECKING

import numpy as np

from ..compiling import njit
from ..model import derived

if TYPE_CHECKING:
    import scipy.sparse as sp

    from ..model import Model

SpringArrays = namedtuple("SpringArrays", ("particles", "stiffness", "rest_length", "damping"))
SpringArrays.__doc__ = """The model's spring arrays as the compiled kernels take them: particles (S, 2) int64,
stiffness k (S,) [N/m], rest length L (S,) [m], damping c (S,) [N s/m]."""
TINY_LENGTH = 1e-12  # m: a spring shorter than this has no direction; its axis is taken as zero


def _axes(model, particle_position):
    """(length (S,) [m], u (S, 3)) of the springs at the given positions (P, 3) [m]."""
    return spring_axes(model.spring_particles, _float_rows(particle_position))


def spring_arrays(model: Model) -> SpringArrays:
    """The model's ``SpringArrays``."""
    return SpringArrays(model.spring_particles, model.spring_stiffness, model.spring_rest_length, model.spring_damping)


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
    """(k (l − L) + c (v_j − v_i)·u [N], u (3 floats)) of spring s of ``springs`` (``spring_arrays``);
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
def forces(
    springs: SpringArrays, particle_position: np.ndarray, particle_velocity: np.ndarray, damped: bool
) -> np.ndarray:
    """``spring_forces`` on the model's spring arrays ``springs`` (``spring_arrays``): f_i = tension · u
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
    return forces(spring_arrays(model), x, v, particle_velocity is not None)


BlockPattern = namedtuple("BlockPattern", ("start", "column", "slots", "diagonal"))
BlockPattern.__doc__ = """Where the springs' 3×3 blocks sit in a block CSR matrix over the P particles
(3P × 3P in nb blocks) that also holds every particle's diagonal block: the sparsity of K, D and
the backward Euler matrix, fixed by the cloth's topology, so a step fills the values and never
sorts indices. ``start`` (P + 1,) int64, the first block of each row; ``column`` (nb,) int64,
each block's particle column, sorted within a row; ``slots`` (S, 4) int64, the blocks (i, i),
(j, j), (i, j), (j, i) of each spring; ``diagonal`` (P,) int64, each particle's (p, p) block."""


@derived
def spring_blocks(model: Model) -> BlockPattern:
    """The ``BlockPattern`` of ``model``'s springs (``spring_particles`` (S, 2) among its P
    particles): fixed by the topology, built on first use and kept with the model."""
    P, S = model.particle_count, model.spring_count
    i, j = model.spring_particles[:, 0], model.spring_particles[:, 1]
    keys = np.concatenate([i * P + j, j * P + i, np.arange(P) * (P + 1)])
    unique, entry = np.unique(keys, return_inverse=True)
    start = np.concatenate([[0], np.cumsum(np.bincount(unique // P, minlength=P))]).astype(np.int64)
    diagonal = entry[2 * S :].astype(np.int64)
    slots = np.stack([diagonal[i], diagonal[j], entry[:S], entry[S : 2 * S]], axis=1).astype(np.int64)
    return BlockPattern(start, (unique % P).astype(np.int64), slots, diagonal)


def block_matrix(pattern: BlockPattern, value: np.ndarray) -> sp.csr_matrix:
    """The CSR matrix (3P, 3P) of the blocks ``value`` (nb, 3, 3) on ``pattern`` (every stored
    entry kept, zeros included: the pattern is the same each step)."""
    import scipy.sparse as sp  # SciPy on first use: it is a tenth of `import contactlab`

    n = 3 * (len(pattern.start) - 1)
    return sp.bsr_matrix((value, pattern.column, pattern.start), shape=(n, n)).tocsr()


SpringOperator = namedtuple("SpringOperator", ("particles", "along", "across", "axis", "mass", "pinned"))
SpringOperator.__doc__ = """The backward Euler matrix A = M − h D − h² K of the particles, matrix-free: each spring's
share C_s = h D_s + h² K_s = along_s u uᵀ + across_s I (``spring_terms``), so that
A x = M x + Σ_s (C_s (x_i − x_j) on i, − C_s (x_i − x_j) on j) (``spring_product``): per spring
five numbers rather than four 3 × 3 blocks. ``particles`` (S, 2) int64; ``along``, ``across``
(S,) [kg]; ``axis`` u (S, 3); ``mass`` (P,) [kg]; ``pinned`` (P,) bool, whose rows and columns
are the identity's (their Δv is 0 and they couple to nothing)."""


@njit(cache=True)
def spring_terms(springs: SpringArrays, particle_position: np.ndarray, clamp_compressed: bool) -> tuple:
    """Each spring's stiffness block K_s = k u uᵀ + k (1 − L/l)(I − u uᵀ) (module docstring) as
    K_s = along u uᵀ + across I: (axis u (S, 3), along = k (1 − t) (S,) [N/m], across = k t (S,)
    [N/m]) with t = 1 − L/l, 0 for a spring without direction, clamped at 0 if
    ``clamp_compressed``."""
    spring_particles, stiffness, rest_length, _ = springs
    S = spring_particles.shape[0]
    axis, along, across = np.empty((S, 3)), np.empty(S), np.empty(S)
    for s in range(S):
        length, axis[s, 0], axis[s, 1], axis[s, 2] = _axis(
            particle_position, spring_particles[s, 0], spring_particles[s, 1]
        )
        transverse = 1.0 - rest_length[s] / length if length > TINY_LENGTH else 0.0
        if clamp_compressed:
            transverse = max(transverse, 0.0)
        along[s] = stiffness[s] * (1.0 - transverse)
        across[s] = stiffness[s] * transverse
    return axis, along, across


@njit(cache=True)
def add_spring_terms(terms: SpringOperator, x: np.ndarray, out: np.ndarray) -> None:
    """out += Σ_s (C_s (x_i − x_j) on i, − C_s (x_i − x_j) on j) for x and out (P, 3), each
    spring's C_s = along_s u uᵀ + across_s I of ``terms`` (a ``SpringOperator``'s, or K's own
    terms: then out −= K x), in spring order."""
    particles = terms.particles
    for s in range(particles.shape[0]):
        i, j = particles[s, 0], particles[s, 1]
        u = terms.axis[s]
        d0, d1, d2 = x[i, 0] - x[j, 0], x[i, 1] - x[j, 1], x[i, 2] - x[j, 2]
        along = terms.along[s] * (u[0] * d0 + u[1] * d1 + u[2] * d2)
        across = terms.across[s]
        w0, w1, w2 = along * u[0] + across * d0, along * u[1] + across * d1, along * u[2] + across * d2
        out[i, 0] += w0
        out[i, 1] += w1
        out[i, 2] += w2
        out[j, 0] -= w0
        out[j, 1] -= w1
        out[j, 2] -= w2


@njit(cache=True)
def spring_product(operator: SpringOperator, x: np.ndarray, out: np.ndarray) -> None:
    """out = A x (P, 3) for the ``SpringOperator`` A and x (P, 3), in spring order (the same bits
    on every rerun); a pinned particle's row 0 (its x is 0 wherever this is used)."""
    for p in range(x.shape[0]):
        for a in range(3):
            out[p, a] = operator.mass[p] * x[p, a]
    add_spring_terms(operator, x, out)
    for p in range(x.shape[0]):
        if operator.pinned[p]:
            out[p] = 0.0


@njit(cache=True)
def operator_diagonal(operator: SpringOperator) -> np.ndarray:
    """A's diagonal blocks (P, 3, 3) [kg]: m I + Σ C_s over the particle's springs (the identity
    for a pinned particle)."""
    P = operator.mass.shape[0]
    diagonal = np.zeros((P, 3, 3))
    for p in range(P):
        for a in range(3):
            diagonal[p, a, a] = operator.mass[p]
    for s in range(operator.particles.shape[0]):
        u = operator.axis[s]
        for end in range(2):
            p = operator.particles[s, end]
            for a in range(3):
                for b in range(3):
                    diagonal[p, a, b] += operator.along[s] * u[a] * u[b]
                diagonal[p, a, a] += operator.across[s]
    for p in range(P):
        if operator.pinned[p]:
            diagonal[p] = np.eye(3)
    return diagonal


@njit(cache=True)
def operator_blocks(pattern: BlockPattern, operator: SpringOperator) -> np.ndarray:
    """A's blocks (nb, 3, 3) [kg] on ``pattern`` (for a sparse matrix: ``block_matrix``): the
    diagonal blocks of ``operator_diagonal``, − C_s on each spring's (i, j) and (j, i) blocks
    (0 where either end is pinned), springs sharing a block summed in spring order."""
    value = np.zeros((pattern.column.shape[0], 3, 3))
    diagonal = operator_diagonal(operator)
    for p in range(diagonal.shape[0]):
        value[pattern.diagonal[p]] = diagonal[p]
    for s in range(operator.particles.shape[0]):
        if operator.pinned[operator.particles[s, 0]] or operator.pinned[operator.particles[s, 1]]:
            continue
        u = operator.axis[s]
        for a in range(3):
            for b in range(3):
                share = operator.along[s] * u[a] * u[b] + (operator.across[s] if a == b else 0.0)
                value[pattern.slots[s, 2], a, b] -= share
                value[pattern.slots[s, 3], a, b] -= share
    return value


@njit(cache=True)
def backward_euler_system(
    springs: SpringArrays,
    particle_mass: np.ndarray,
    particle_pinned: np.ndarray,
    gravity: np.ndarray,
    particle_position: np.ndarray,
    particle_velocity: np.ndarray,
    h: float,
) -> tuple[SpringOperator, np.ndarray]:
    """The particles' backward Euler step under gravity (3,) [m/s²] and the springs, linearized at
    the positions x (P, 3) [m] and velocities v (P, 3) [m/s], over h [s]:
    M (v⁺ − v) = h f(x + h v⁺, v⁺) with f ≈ f + K (x⁺ − x) + D (v⁺ − v), so

        (M − h D − h² K) Δv = h (f + h K v),        Δv = v⁺ − v,

    K with the compressed springs' transverse stiffness clamped (symmetric positive definite:
    module docstring). Returns (A as a ``SpringOperator``, the right-hand side (P, 3) [kg m/s],
    0 for a pinned particle)."""
    x, v = particle_position, particle_velocity
    particles, damping = springs[0], springs[3]
    force = forces(springs, x, v, True)
    axis, along, across = spring_terms(springs, x, True)
    stiffness = SpringOperator(particles, along, across, axis, particle_mass, particle_pinned)
    pull = np.zeros(x.shape)  # − K v
    add_spring_terms(stiffness, v, pull)
    rhs = np.empty(x.shape)
    for p in range(x.shape[0]):
        for a in range(3):
            held = particle_pinned[p]
            rhs[p, a] = 0.0 if held else h * ((particle_mass[p] * gravity[a] + force[p, a]) - h * pull[p, a])
    operator = SpringOperator(
        particles, h * damping + h * h * along, h * h * across, axis, particle_mass, particle_pinned
    )
    return operator, rhs


def spring_jacobians(
    model: Model,
    particle_position: np.ndarray,
    particle_velocity: np.ndarray | None = None,
    clamp_compressed: bool = False,
) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """(K, D): the Jacobians ∂f/∂x [N/m] and ∂f/∂v [N s/m] of ``spring_forces``, SciPy CSR
    matrices (3P, 3P), symmetric, with the blocks of the module docstring (on the pattern of
    ``spring_blocks(model)``, whose diagonal is always stored).

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
    springs, pattern = spring_arrays(model), spring_blocks(model)
    axis, along, across = spring_terms(springs, _float_rows(particle_position), clamp_compressed)
    massless, free = np.zeros(count), np.zeros(count, dtype=bool)
    # K = −(the matrix whose spring shares are K_s, massless): −Σ K_s on the diagonal, +K_s off it; D likewise
    K = SpringOperator(springs.particles, along, across, axis, massless, free)
    D = SpringOperator(springs.particles, springs.damping, np.zeros_like(across), axis, massless, free)
    return block_matrix(pattern, -operator_blocks(pattern, K)), block_matrix(pattern, -operator_blocks(pattern, D))


def spring_energy(model: Model, particle_position: np.ndarray) -> float:
    """Elastic energy of the springs Σ ½ k (l − L)² [J] at positions (P, 3) [m]."""
    if model.spring_count == 0:
        return 0.0
    length, _ = _axes(model, particle_position)
    return float(0.5 * np.sum(model.spring_stiffness * (length - model.spring_rest_length) ** 2))
