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

import numpy as np
import scipy.sparse as sp

TINY_LENGTH = 1e-12     # m: a spring shorter than this has no direction; its axis is taken as zero


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
    for axis in range(3):      # three bincounts: vectorized over the springs
        total[:, axis] = (np.bincount(index_i, force_on_i[:, axis], minlength=count)
                          - np.bincount(index_j, force_on_i[:, axis], minlength=count))
    return total


def spring_tensions(model, particle_position, particle_velocity=None):
    """Scalar pull of each spring along its axis (S,) [N]: k (l − L) + c (v_j − v_i)·u
    (positive when it pulls its ends together)."""
    i, j, _, length, u = _axes(model, particle_position)
    tension = model.spring_stiffness * (length - model.spring_rest_length)
    if particle_velocity is not None:
        tension = tension + model.spring_damping * np.einsum(
            "si,si->s", particle_velocity[j] - particle_velocity[i], u)
    return tension


def spring_forces(model, particle_position, particle_velocity=None):
    """Spring forces on the particles (P, 3) [N] at positions (P, 3) [m] and velocities
    (P, 3) [m/s] (None: no damping force). Zero for particles without springs."""
    count = len(particle_position)
    if model.spring_count == 0:
        return np.zeros((count, 3))
    i, j, _, _, u = _axes(model, particle_position)
    tension = spring_tensions(model, particle_position, particle_velocity)
    return _gather(i, j, tension[:, None] * u, count)


def _assemble(i, j, blocks, count):
    """The (3 count × 3 count) CSR matrix with −B on (i,i) and (j,j), +B on (i,j) and (j,i)
    for each spring's block B (S, 3, 3)."""
    rows3 = np.arange(3)[None, :, None]
    cols3 = np.arange(3)[None, None, :]
    ri, rj = 3 * i[:, None, None] + rows3, 3 * j[:, None, None] + rows3
    ci, cj = 3 * i[:, None, None] + cols3, 3 * j[:, None, None] + cols3
    shape9 = blocks.shape
    rows = np.concatenate([np.broadcast_to(r, shape9).ravel() for r in (ri, rj, ri, rj)])
    cols = np.concatenate([np.broadcast_to(c, shape9).ravel() for c in (ci, cj, cj, ci)])
    values = np.concatenate([-blocks.ravel(), -blocks.ravel(), blocks.ravel(), blocks.ravel()])
    return sp.csr_matrix((values, (rows, cols)), shape=(3 * count, 3 * count))


def spring_jacobians(model, particle_position, particle_velocity=None, clamp_compressed=False):
    """(K, D): the Jacobians ∂f/∂x [N/m] and ∂f/∂v [N s/m] of ``spring_forces``, SciPy CSR
    matrices (3P, 3P), symmetric, with the blocks of the module docstring.

    K leaves out the position derivative of the damping force (exact when the damping is 0 or
    the velocities are equal along each spring). ``clamp_compressed``: drop the negative
    transverse stiffness of compressed springs, so K is negative semidefinite (see the module
    docstring); False gives the exact derivative. ``particle_velocity`` is not used (D does not
    depend on it); it is accepted so the call mirrors ``spring_forces``.
    """
    count = len(particle_position)
    if model.spring_count == 0:
        empty = sp.csr_matrix((3 * count, 3 * count))
        return empty, empty.copy()
    i, j, _, length, u = _axes(model, particle_position)
    k, rest = model.spring_stiffness, model.spring_rest_length
    outer = u[:, :, None] * u[:, None, :]                               # (S, 3, 3) u uᵀ
    with np.errstate(divide="ignore", invalid="ignore"):
        transverse = np.where(length > TINY_LENGTH, 1.0 - rest / length, 0.0)
    if clamp_compressed:
        transverse = np.maximum(transverse, 0.0)
    stiffness_blocks = k[:, None, None] * (outer + transverse[:, None, None] * (np.eye(3) - outer))
    damping_blocks = model.spring_damping[:, None, None] * outer
    return _assemble(i, j, stiffness_blocks, count), _assemble(i, j, damping_blocks, count)


def spring_energy(model, particle_position) -> float:
    """Elastic energy of the springs Σ ½ k (l − L)² [J] at positions (P, 3) [m]."""
    if model.spring_count == 0:
        return 0.0
    _, _, _, length, _ = _axes(model, particle_position)
    return float(0.5 * np.sum(model.spring_stiffness * (length - model.spring_rest_length) ** 2))
