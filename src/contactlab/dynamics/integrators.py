"""Time integration of the free motion (no contacts): velocities, then positions.

Two integrators, named in ``[simulation] integrator``:

* ``symplectic_euler`` (default): v⁺ = v + h M⁻¹ f, then x⁺ = x + h v⁺. The gyroscopic term
  ω × Iω is integrated implicitly by the midpoint rule in the body frame, which keeps the
  angular momentum and the rotational energy of a free spinning body.
* ``explicit_euler``: x⁺ = x + h v (the old velocity), v⁺ = v + h M⁻¹ f, gyroscopic term
  explicit. Included to show why the symplectic variant is the default.
* ``backward_euler``: v⁺ = v + h M⁻¹ f(x⁺, v⁺), x⁺ = x + h v⁺, the forces that depend on the
  state linearized and solved as one sparse system. The cloth springs are solved here (see
  ``particle_system``); penalty contacts by the method that owns them (see
  contactlab.methods.penalty), which may add its terms to ``particle_system``'s matrix. Gravity
  does not depend on the state, so for bodies and free particles it coincides with symplectic
  Euler (gyroscopic term implicit).

Cloth springs (contactlab.dynamics.cloth) are internal forces of the particles: the explicit
integrators add h M⁻¹ f_springs(x, v) to the particle velocities; backward Euler solves
(M − h D − h² K) Δv = h (f + h K v). Pinned particles (``model.particle_pinned``) keep zero
velocity under every integrator: gravity and springs do not move them.

Shapes: B bodies, P particles. Forces [N], torques [N m], world frame.
"""

from __future__ import annotations

from collections import namedtuple
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numba.extending import overload

from .. import rotations
from ..compiling import njit
from ..driving import drive_velocities
from ..model import derived
from .cloth import (
    SpringOperator,
    backward_euler_system,
    block_matrix,
    operator_blocks,
    operator_diagonal,
    spring_arrays,
    spring_blocks,
    spring_forces,
    spring_product,
)
from .sparse_cholesky import CholeskyFactor, cholesky

if TYPE_CHECKING:
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    from ..model import Model
    from ..state import Carry, State

INTEGRATORS = ("symplectic_euler", "explicit_euler", "backward_euler")


def world_inverse_inertia(model: Model, orientation: np.ndarray) -> np.ndarray:
    """I⁻¹ in world frame, (B, 3, 3), for orientations (B, 4)."""
    return rotations.world_inertia(rotations.to_matrix(orientation), model.body_inverse_inertia)


@njit(cache=True)
def free_flight(
    gravity: np.ndarray,
    inertia: np.ndarray,
    pinned: np.ndarray,
    body_velocity: np.ndarray,
    angular_velocity: np.ndarray,
    particle_velocity: np.ndarray,
    rotation: np.ndarray,
    h: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stage 1 under gravity alone (symplectic and backward Euler; the compiled loop runs it as
    the methods' steps do): v* = v + h g for bodies and particles (body_velocity (B, 3),
    particle_velocity (P, 3) [m/s], gravity (3,) [m/s²]), pinned particles ((P,) bool) held at
    rest, and each body's ω after h [s] of torque-free rotation by the implicit midpoint rule
    (``gyroscopic_midpoint``, 4 Newton steps; rotation (B, 3, 3), inertia (B, 3) principal
    [kg m²], angular_velocity (B, 3) [rad/s]). Solves I(ω₂ − ω₁) + h ω̄ × Iω̄ = 0 with ω̄ =
    (ω₁ + ω₂)/2: the midpoint rule keeps every quadratic invariant of Euler's equations, so
    both ½ ωᵀIω and |Iω| are conserved up to the Newton tolerance. Returns new arrays (body,
    angular, particle)."""
    # element by element, not v + h g: the array expression allocates h g and broadcasts (the same sums)
    body = np.empty_like(body_velocity)
    _add_gravity(body, body_velocity, gravity, h)
    angular = gyroscopic_midpoint(rotation, inertia, angular_velocity, h, 4)
    particle = np.empty_like(particle_velocity)
    _add_gravity(particle, particle_velocity, gravity, h)
    for p in range(particle.shape[0]):
        if pinned[p]:
            particle[p, 0] = particle[p, 1] = particle[p, 2] = 0.0
    return body, angular, particle


@njit(cache=True, inline="always")
def _add_gravity(out, velocity, gravity, h):
    for n in range(velocity.shape[0]):
        for i in range(3):
            out[n, i] = velocity[n, i] + h * gravity[i]


@njit(cache=True, inline="always")  # inlined into free_flight, and so into the compiled loop
def gyroscopic_midpoint(
    rotation: np.ndarray, inertia: np.ndarray, angular_velocity: np.ndarray, dt: float, newton_steps: int
) -> np.ndarray:
    """ω after h of torque-free rotation (``free_flight``), body by body: rotation (B, 3, 3) body → world,
    inertia (B, 3) principal [kg m²], angular_velocity (B, 3) world [rad/s]. A body with an
    isotropic inertia, or at rest, keeps its ω (it has no gyroscopic torque); the others take
    ``newton_steps`` Newton steps on I(ω₂ − ω₁) + h ω̄ × Iω̄ = 0 in the body frame."""
    result = angular_velocity.copy()
    scratch = np.empty((4, 3))  # the Newton step's Jacobian (rows 0-2) and residual (row 3): one allocation
    jacobian, residual = scratch[:3], scratch[3]
    for b in range(rotation.shape[0]):
        mean = (inertia[b, 0] + inertia[b, 1] + inertia[b, 2]) / 3.0
        spread = max(abs(inertia[b, 0] - mean), abs(inertia[b, 1] - mean), abs(inertia[b, 2] - mean))
        if not spread > 0.0 or (
            angular_velocity[b, 0] == 0.0 and angular_velocity[b, 1] == 0.0 and angular_velocity[b, 2] == 0.0
        ):
            continue
        R, I = rotation[b], inertia[b]
        w1 = np.empty(3)
        for i in range(3):  # body frame: Rᵀ ω
            w1[i] = (
                R[0, i] * angular_velocity[b, 0] + R[1, i] * angular_velocity[b, 1] + R[2, i] * angular_velocity[b, 2]
            )
        w2 = w1.copy()
        for _ in range(newton_steps):
            m0, m1, m2 = 0.5 * (w1[0] + w2[0]), 0.5 * (w1[1] + w2[1]), 0.5 * (w1[2] + w2[2])
            l0, l1, l2 = I[0] * m0, I[1] * m1, I[2] * m2  # I ω̄
            residual[0] = I[0] * (w2[0] - w1[0]) + dt * (m1 * l2 - m2 * l1)
            residual[1] = I[1] * (w2[1] - w1[1]) + dt * (m2 * l0 - m0 * l2)
            residual[2] = I[2] * (w2[2] - w1[2]) + dt * (m0 * l1 - m1 * l0)
            # ∂/∂ω₂ = I + ½ h ([ω̄]× I − [I ω̄]×)
            jacobian[0, 0], jacobian[0, 1], jacobian[0, 2] = (
                I[0],
                0.5 * dt * (-m2 * I[1] + l2),
                0.5 * dt * (m1 * I[2] - l1),
            )
            jacobian[1, 0], jacobian[1, 1], jacobian[1, 2] = (
                0.5 * dt * (m2 * I[0] - l2),
                I[1],
                0.5 * dt * (-m0 * I[2] + l0),
            )
            jacobian[2, 0], jacobian[2, 1], jacobian[2, 2] = (
                0.5 * dt * (-m1 * I[0] + l1),
                0.5 * dt * (m0 * I[1] - l0),
                I[2],
            )
            step = _solve3(jacobian, residual)
            for i in range(3):
                w2[i] -= step[i]
        for i in range(3):
            result[b, i] = R[i, 0] * w2[0] + R[i, 1] * w2[1] + R[i, 2] * w2[2]
    return result


@njit(cache=True)
def _solve3(A, b):
    """x (3,) with A x = b for a 3 × 3 A, by Gaussian elimination with partial pivoting."""
    M = A.copy()
    x = b.copy()
    for k in range(3):
        pivot = k
        for i in range(k + 1, 3):
            if abs(M[i, k]) > abs(M[pivot, k]):
                pivot = i
        if pivot != k:
            for j in range(3):
                M[k, j], M[pivot, j] = M[pivot, j], M[k, j]
            x[k], x[pivot] = x[pivot], x[k]
        for i in range(k + 1, 3):
            factor = M[i, k] / M[k, k]
            for j in range(k, 3):
                M[i, j] -= factor * M[k, j]
            x[i] -= factor * x[k]
    for k in range(2, -1, -1):
        for j in range(k + 1, 3):
            x[k] -= M[k, j] * x[j]
        x[k] /= M[k, k]
    return x


def _gyroscopic_explicit(model, orientation, angular_velocity, dt):
    """ω + h I⁻¹(−ω × Iω), world frame."""
    if len(angular_velocity) == 0:
        return angular_velocity.copy()
    R = rotations.to_matrix(orientation)
    inertia_world = rotations.world_inertia(R, model.body_inertia)
    L = np.einsum("bij,bj->bi", inertia_world, angular_velocity)
    inv = rotations.world_inertia(R, model.body_inverse_inertia)
    return angular_velocity - dt * np.einsum("bij,bj->bi", inv, np.cross(angular_velocity, L))


@dataclass
class ParticleSystem:
    """The backward Euler system of the particles, A Δv = rhs, over all 3P particle DOFs.

    matrix: A = M − h D − h² K, CSR (3P, 3P) [kg], symmetric positive definite (K with the
    compressed springs' transverse stiffness clamped, see contactlab.dynamics.cloth). Rows and
    columns of pinned particles are the identity, with rhs 0: their Δv is 0 and they are
    removed from the coupling (their velocity is held at 0).
    rhs: h (f + h K v) (3P,) [kg m/s], f = m g + spring forces + given forces at (x, v).
    coupled: (P,) bool, the particles that need the linear solve (in a spring, not pinned);
    for the others A is m I and Δv = h f / m directly.
    """

    matrix: object
    rhs: np.ndarray
    coupled: np.ndarray


def particle_system(model: Model, state: State, dt: float) -> ParticleSystem:
    """The backward Euler step of the particles under gravity and the cloth springs, linearized at
    ``state`` (see ``ParticleSystem``; ``cloth.backward_euler_system`` builds it).

    A method may add its own implicit terms (contact springs) to ``matrix`` and ``rhs`` and solve
    them together (``solve_particle_system``)."""
    operator, rhs = _system_of(model, state, dt)
    return ParticleSystem(_matrix_of(model, operator), rhs.reshape(-1), coupled_particles(model))


def _system_of(model: Model, state: State, dt: float) -> tuple[SpringOperator, np.ndarray]:
    """``cloth.backward_euler_system`` of ``model`` at ``state`` over dt [s]: (A, rhs (P, 3))."""
    return backward_euler_system(
        spring_arrays(model),
        model.particle_mass,
        model.particle_pinned,
        np.asarray(model.gravity, dtype=float),
        np.array(state.particle_position, dtype=float),
        np.array(state.particle_velocity, dtype=float),
        dt,
    )


def _matrix_of(model: Model, operator: SpringOperator) -> sp.csr_matrix:
    """The SciPy CSR matrix (3P, 3P) of ``model``'s backward Euler ``operator``, on its fixed block
    pattern (``cloth.spring_blocks``)."""
    pattern = spring_blocks(model)
    return block_matrix(pattern, operator_blocks(pattern, operator))


@derived
def coupled_particles(model: Model) -> np.ndarray:
    """(P,) bool: the particles the backward Euler step solves together (in a spring, not pinned)."""
    coupled = np.zeros(model.particle_count, dtype=bool)
    coupled[model.spring_particles.ravel()] = True
    return coupled & ~model.particle_pinned


def factor_symmetric(matrix: sp.spmatrix) -> CholeskyFactor | spla.SuperLU:
    """A factor of a symmetric positive definite matrix (N, N) for repeated solves
    (``.solve(rhs)``, rhs (N,) or (N, k)): the block Cholesky factor of
    contactlab.dynamics.sparse_cholesky where N is a multiple of 3 (every system of bodies and
    particles), its fill-reducing order and pattern analysed once per pattern; otherwise, or
    where a pivot block is not positive definite, a sparse LU (SciPy's SuperLU) with a
    fill-reducing ordering of A + Aᵀ and diagonal pivots, which keep that ordering (a positive
    definite matrix needs no row exchanges; the default threshold pivoting breaks the symmetric
    ordering: on a draped 64 × 64 cloth its factor was 20x denser and took 30 s, against 0.17 s
    this way). On ``cloth_drape`` (1 875 DOFs) the Cholesky factor takes half SuperLU's time and
    a solve about half of its (a twelfth on a 64 × 64 cloth); both give the same solution up to round-off."""
    factor = cholesky(matrix)
    if factor is not None:
        return factor
    import scipy.sparse as sp  # SciPy on first use: it is a tenth of `import contactlab`
    import scipy.sparse.linalg as spla

    return spla.splu(
        sp.csc_matrix(matrix), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True}
    )


def solve_particle_system(
    system: ParticleSystem, model: Model, tolerance: float = 1e-6, solver: str = "cg", guess: np.ndarray | None = None
) -> np.ndarray:
    """Δv (P, 3) [m/s] of a ``ParticleSystem``: the coupled particles by conjugate gradients
    with a block Jacobi preconditioner (``solver="cg"``, to the relative residual ``tolerance`` —
    the linearization itself is only first-order accurate, so 1e-6 is plenty; a sparse direct
    solve if it does not converge in max(100, coupled DOFs) iterations) or by a sparse direct
    solve (``"direct"``); the others from their diagonal. ``guess`` (P, 3): where the conjugate
    gradients start on the coupled particles (None: from the diagonal's answer, rhs / A_ii).
    ``model`` is accepted for symmetry with ``particle_system`` and not used."""
    coupled = np.repeat(system.coupled, 3)
    return solve_coupled(system.matrix, system.rhs, coupled, tolerance, solver, guess)[0].reshape(-1, 3)


def solve_coupled(
    matrix: sp.spmatrix,
    rhs: np.ndarray,
    coupled: np.ndarray,
    tolerance: float = 1e-6,
    solver: str = "cg",
    guess: np.ndarray | None = None,
) -> tuple[np.ndarray, int]:
    """x (N,) of A x = rhs for a symmetric positive definite A (N, N) whose rows and columns
    outside ``coupled`` (N,) bool hold only their diagonal: those from the diagonal, the coupled
    ones as ``solve_particle_system`` says (``solver`` "cg": compiled block-Jacobi-preconditioned
    conjugate gradients to the relative residual ``tolerance``, a sparse direct solve if they do
    not converge in max(100, N_coupled) iterations; "direct": the sparse direct solve; ``guess``
    (N values, None: none): where the conjugate gradients start on the coupled rows). Returns
    (x, conjugate-gradient iterations made)."""
    A = matrix.tocsr()
    delta = rhs / A.diagonal()  # exact for the uncoupled rows (A = m I there)
    if not coupled.any():
        return delta, 0
    if guess is not None and guess.size == delta.size:
        delta[coupled] = guess.reshape(-1)[coupled]
    iterations, converged = 0, False
    if solver == "cg":
        delta, iterations, converged = conjugate_gradients(
            A, rhs, delta, coupled, tolerance, max(100, int(coupled.sum()))
        )
    if not converged:
        dofs = np.nonzero(coupled)[0]
        delta[dofs] = factor_symmetric(A[dofs][:, dofs].tocsr()).solve(rhs[dofs])
    return delta, iterations


def spring_step(model: Model, state: State, dt: float, tolerance: float = 1e-6, solver: str = "cg") -> np.ndarray:
    """Δv (P, 3) [m/s] of the particles' backward Euler step (``cloth.backward_euler_system``) at
    ``state`` over dt [s], as ``solve_particle_system`` gives it, without SciPy unless the conjugate
    gradients do not converge or ``solver`` is "direct": ``backward_euler_solve`` on the system's
    blocks, from last step's Δv (``state.carried.springs``: the draped cloth's next is close)."""
    operator, rhs = _system_of(model, state, dt)
    coupled = coupled_particles(model)
    if solver == "cg":
        guess = state.carried.springs
        guess = np.zeros((0, 3)) if guess is None else np.asarray(guess, dtype=float)
        most = max(100, 3 * int(coupled.sum()))
        delta, _, converged = backward_euler_solve(operator, rhs, coupled, guess, (tolerance, most))
        if converged:
            return delta
    return solve_coupled(_matrix_of(model, operator), rhs.reshape(-1), np.repeat(coupled, 3), tolerance, "direct")[
        0
    ].reshape(-1, 3)


@njit(cache=True)
def backward_euler_solve(
    operator: SpringOperator, rhs: np.ndarray, coupled: np.ndarray, guess: np.ndarray, stop: tuple
) -> tuple[np.ndarray, int, bool]:
    """Δv (P, 3) of A Δv = rhs for A as a ``cloth.SpringOperator`` and rhs (P, 3)
    (``cloth.backward_euler_system``): the particles outside ``coupled`` (P,) bool from their
    diagonal (m I, or the identity of a pinned one), the coupled ones by
    ``block_conjugate_gradients`` from ``guess`` (P, 3) (empty: from the diagonal's answer) until
    ``stop`` = (relative tolerance, most iterations). Returns (Δv, iterations, converged)."""
    P = rhs.shape[0]
    diagonal = operator_diagonal(operator)
    delta, b, y = np.empty((P, 3)), np.zeros((P, 3)), np.zeros((P, 3))
    for p in range(P):
        for a in range(3):
            alone = rhs[p, a] / diagonal[p, a, a]
            if not coupled[p]:
                delta[p, a] = alone
            else:
                b[p, a] = rhs[p, a]
                y[p, a] = guess[p, a] if guess.shape[0] == P else alone
    iterations, converged = block_conjugate_gradients(operator, diagonal, b, y, stop)
    for p in range(P):
        if coupled[p]:
            delta[p] = y[p]
    return delta, iterations, converged


def conjugate_gradients(
    matrix: sp.spmatrix, rhs: np.ndarray, guess: np.ndarray, active: np.ndarray, tolerance: float, most: int
) -> tuple[np.ndarray, int, bool]:
    """A x = rhs on the ``active`` (N,) bool rows and columns of the sparse matrix A (N, N), N a
    multiple of 3, by conjugate gradients with the block Jacobi preconditioner (the inverse of
    A's 3 × 3 diagonal blocks: a particle's x, y, z, a body's linear or angular velocity), from
    ``guess`` (N,) (whose other entries are returned as they are), until |r| < tolerance |rhs|
    over the active rows or ``most`` iterations (the stopping rule of SciPy's ``cg`` with
    atol = 0). The active part is taken out once as 3 × 3 blocks (``_active_blocks``): a block
    product reads one column index per nine entries. One thread, sums in index order: the same
    bits on every rerun. Returns (x (N,), iterations, converged)."""
    A = matrix.tocsr()
    csr = (A.indptr.astype(np.int64), A.indices.astype(np.int64), np.ascontiguousarray(A.data, dtype=np.float64))
    rhs, guess = np.ascontiguousarray(rhs, dtype=np.float64), np.ascontiguousarray(guess, dtype=np.float64)
    return _block_conjugate_gradients(csr, rhs, guess, np.asarray(active, dtype=np.bool_), tolerance, most)


@njit(cache=True)
def _block_conjugate_gradients(csr, rhs, guess, active, tolerance, most):
    """``conjugate_gradients`` compiled, on A as its CSR arrays ``csr`` = (indptr (N + 1,) int64,
    indices (nnz,) int64, data (nnz,) float64): ``block_conjugate_gradients`` over the 3 × 3
    blocks of ``_active_blocks``."""
    indptr, indices, data = csr
    x = guess.copy()
    triples, start, column, value = _active_blocks(indptr, indices, data, active)
    t = triples.shape[0]
    b, y = np.zeros((t, 3)), np.zeros((t, 3))
    for k in range(t):
        for d in range(3):
            dof = 3 * triples[k] + d
            if active[dof]:
                b[k, d], y[k, d] = rhs[dof], x[dof]
    matrix = BlockMatrix(start, column, value, _diagonal_blocks(start, column))
    iterations, converged = block_conjugate_gradients(matrix, value[matrix.diagonal_at], b, y, (tolerance, most))
    for k in range(t):
        for d in range(3):
            if active[3 * triples[k] + d]:
                x[3 * triples[k] + d] = y[k, d]
    return x, iterations, converged


BlockMatrix = namedtuple("BlockMatrix", ("start", "column", "value", "diagonal_at"))
BlockMatrix.__doc__ = """A symmetric matrix in block CSR: start (t + 1,) int64, column (nb,) int64 sorted within
each row, value (nb, 3, 3), diagonal_at (t,) int64 the position of each row's diagonal block."""


PRODUCTS: dict[type, Callable] = {}
"""The product of each kind of operator ``block_conjugate_gradients`` takes, by its type: a
compiled function (operator, x, out) that sets out = A x, x and out (t, 3). A ``BlockMatrix``'s
and a cloth's ``SpringOperator``'s are registered here, a higher layer's where it is defined
(penalty's ``SpringSystem``): each kind compiles the conjugate gradients once, for every scene."""


def product(operator: Any, x: np.ndarray, out: np.ndarray) -> None:
    """out = A x by the product ``PRODUCTS`` registers for the operator's type."""
    PRODUCTS[type(operator)](operator, x, out)


@overload(product)
def _product_compiled(operator, x, out):  # type: ignore[no-untyped-def]  # Numba: unannotated as the impl
    kernel = PRODUCTS[operator.instance_class]
    return lambda operator, x, out: kernel(operator, x, out)


@njit(cache=True)
def block_conjugate_gradients(
    operator: Any, diagonal: np.ndarray, b: np.ndarray, y: np.ndarray, stop: tuple
) -> tuple[int, bool]:
    """A y = b for A symmetric positive definite, b and y (t, 3), by conjugate gradients with the
    block Jacobi preconditioner (the inverse of A's 3 × 3 diagonal blocks ``diagonal`` (t, 3, 3):
    a particle's x, y, z, a body's linear or angular velocity), from y (changed in place), until
    |r| < tolerance |b| or a most of iterations, ``stop`` = (tolerance, most) (the stopping rule
    of SciPy's ``cg`` with atol = 0). A is ``operator`` as its type's product applies it
    (``PRODUCTS``: a ``BlockMatrix``, a cloth's ``SpringOperator``, the penalty springs'
    ``SpringSystem``). One thread, sums in index order:
    the same bits on every rerun. Returns (iterations, converged)."""
    tolerance, most = stop
    t = b.shape[0]
    scale = 0.0
    for k in range(t):
        for d in range(3):
            scale += b[k, d] * b[k, d]
    if scale == 0.0:  # b = 0: so is y
        y[:] = 0.0
        return 0, True
    inverse = _diagonal_inverses(diagonal)
    r, z, p, q = np.empty((t, 3)), np.empty((t, 3)), np.zeros((t, 3)), np.empty((t, 3))
    limit = tolerance * np.sqrt(scale)
    product(operator, y, q)
    for k in range(t):
        for d in range(3):
            r[k, d] = b[k, d] - q[k, d]
    residual, current = _precondition(inverse, r, z)
    iterations, converged, previous = 0, False, 1.0
    while True:
        if np.sqrt(residual) < limit:
            converged = True
            break
        if iterations == most:
            break
        beta = current / previous if iterations > 0 else 0.0
        for k in range(t):
            for d in range(3):
                p[k, d] = z[k, d] + beta * p[k, d]
        product(operator, p, q)
        curvature = 0.0
        for k in range(t):
            for d in range(3):
                curvature += p[k, d] * q[k, d]
        alpha = current / curvature
        previous = current
        for k in range(t):
            for d in range(3):
                y[k, d] += alpha * p[k, d]
                r[k, d] -= alpha * q[k, d]
        residual, current = _precondition(inverse, r, z)
        iterations += 1
    return iterations, converged


@njit(cache=True)
def _active_blocks(indptr, indices, data, active):
    """A's active rows and columns as 3 × 3 blocks: the triples (t,) of DOFs (3 i, 3 i + 1,
    3 i + 2) with an active DOF, in order, and the block CSR arrays (start (t + 1,), column
    (nb,), value (nb, 3, 3)) of A over them, renumbered 0..t−1. An inactive DOF of an active
    triple gets 1 on the diagonal and 0 elsewhere: with 0 on its right-hand side and guess it
    stays 0, and the active DOFs iterate as on the compact system of the active DOFs alone."""
    n = indptr.shape[0] - 1
    number = np.full(n // 3, -1)
    t = 0
    for triple in range(n // 3):
        if active[3 * triple] or active[3 * triple + 1] or active[3 * triple + 2]:
            number[triple] = t
            t += 1
    triples = np.empty(t, dtype=np.int64)
    for triple in range(n // 3):
        if number[triple] >= 0:
            triples[number[triple]] = triple
    start = np.zeros(t + 1, dtype=np.int64)
    slot = np.full(t, -1)  # the block of the row of blocks being built in each block column
    column = np.empty(indices.shape[0], dtype=np.int64)
    value = np.zeros((indices.shape[0], 3, 3))
    count = 0
    for k in range(t):
        first = count
        for d in range(3):
            row = 3 * triples[k] + d
            if not active[row]:
                continue
            for e in range(indptr[row], indptr[row + 1]):
                other = number[indices[e] // 3]
                if not active[indices[e]] or other < 0:
                    continue
                if slot[other] < first:
                    slot[other] = count
                    column[count] = other
                    value[count] = 0.0
                    count += 1
                value[slot[other], d, indices[e] % 3] += data[e]
        diagonal = slot[k] if slot[k] >= first else -1
        if diagonal < 0:  # no stored diagonal block (only where a triple's active DOFs have none)
            slot[k] = count
            column[count] = k
            value[count] = 0.0
            diagonal = count
            count += 1
        for d in range(3):
            if not active[3 * triples[k] + d]:
                value[diagonal, d, d] = 1.0
        _sort_blocks(column, value, first, count)
        start[k + 1] = count
    return triples, start, column[:count].copy(), value[:count].copy()


@njit(cache=True)
def _sort_blocks(column, value, first, stop):
    """The blocks first..stop−1 of a row put in order of their column, by insertion (a row has a
    dozen): products then sum in index order, as a CSR row's entries."""
    held = np.empty((3, 3))
    for a in range(first + 1, stop):
        c = column[a]
        held[:] = value[a]
        b = a
        while b > first and column[b - 1] > c:
            column[b] = column[b - 1]
            value[b] = value[b - 1]
            b -= 1
        column[b] = c
        value[b] = held


@njit(cache=True)
def _symmetric_product(matrix, x, out):
    """out = A x for the ``BlockMatrix`` A, x and out (t, 3), reading only its diagonal blocks and
    those above: each block B at (r, c), c > r, adds B x_c to row r and Bᵀ x_r to row c (the half
    of the blocks a full product would read again transposed)."""
    start, column, value, diagonal_at = matrix
    out[:] = 0.0
    for row in range(start.shape[0] - 1):
        d = diagonal_at[row]
        x0, x1, x2 = x[row, 0], x[row, 1], x[row, 2]
        o0 = value[d, 0, 0] * x0 + value[d, 0, 1] * x1 + value[d, 0, 2] * x2
        o1 = value[d, 1, 0] * x0 + value[d, 1, 1] * x1 + value[d, 1, 2] * x2
        o2 = value[d, 2, 0] * x0 + value[d, 2, 1] * x1 + value[d, 2, 2] * x2
        for e in range(d + 1, start[row + 1]):
            c = column[e]
            y0, y1, y2 = x[c, 0], x[c, 1], x[c, 2]
            o0 += value[e, 0, 0] * y0 + value[e, 0, 1] * y1 + value[e, 0, 2] * y2
            o1 += value[e, 1, 0] * y0 + value[e, 1, 1] * y1 + value[e, 1, 2] * y2
            o2 += value[e, 2, 0] * y0 + value[e, 2, 1] * y1 + value[e, 2, 2] * y2
            out[c, 0] += value[e, 0, 0] * x0 + value[e, 1, 0] * x1 + value[e, 2, 0] * x2
            out[c, 1] += value[e, 0, 1] * x0 + value[e, 1, 1] * x1 + value[e, 2, 1] * x2
            out[c, 2] += value[e, 0, 2] * x0 + value[e, 1, 2] * x1 + value[e, 2, 2] * x2
        out[row, 0] += o0
        out[row, 1] += o1
        out[row, 2] += o2


PRODUCTS[BlockMatrix] = _symmetric_product
PRODUCTS[SpringOperator] = spring_product


@njit(cache=True)
def _diagonal_blocks(start, column):
    """(t,) int64: where each row's diagonal block is in the block CSR arrays (every row has one)."""
    t = start.shape[0] - 1
    at = np.empty(t, dtype=np.int64)
    for k in range(t):
        for e in range(start[k], start[k + 1]):
            if column[e] == k:
                at[k] = e
    return at


@njit(cache=True)
def _diagonal_inverses(diagonal):
    """(t, 3, 3): the inverse of each of the blocks ``diagonal`` (t, 3, 3) (each symmetric
    positive definite), by Gauss-Jordan elimination without pivoting."""
    t = diagonal.shape[0]
    inverse = np.zeros((t, 3, 3))
    a = np.empty((3, 3))
    for k in range(t):
        a[:] = diagonal[k]
        out = inverse[k]
        for i in range(3):
            out[i, i] = 1.0
        for i in range(3):
            pivot = 1.0 / a[i, i]
            for j in range(3):
                a[i, j] *= pivot
                out[i, j] *= pivot
            for other in range(3):
                if other != i:
                    factor = a[other, i]
                    for j in range(3):
                        a[other, j] -= factor * a[i, j]
                        out[other, j] -= factor * out[i, j]
    return inverse


@njit(cache=True)
def _precondition(inverse, r, z):
    """z = P⁻¹ r, block by block (``_diagonal_inverses``), r and z (t, 3); returns (r · r, r · z),
    summed in index order."""
    residual, current = 0.0, 0.0
    for k in range(r.shape[0]):
        for d in range(3):
            z[k, d] = inverse[k, d, 0] * r[k, 0] + inverse[k, d, 1] * r[k, 1] + inverse[k, d, 2] * r[k, 2]
        for d in range(3):
            residual += r[k, d] * r[k, d]
            current += r[k, d] * z[k, d]
    return residual, current


def free_velocities(
    model: Model,
    state: State,
    dt: float,
    integrator: str = "symplectic_euler",
    linear_solver: str = "cg",
    linear_tolerance: float = 1e-6,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Velocities after dt under gravity, cloth springs and the scene's external forces, without
    contacts.

    Bodies: see ``body_free_velocities``. Particles: explicit and symplectic Euler add
    h M⁻¹ (m g + f_springs(x, v)); backward Euler solves ``particle_system``
    (springs implicit) with ``solve_particle_system`` (``linear_solver`` "cg" or "direct",
    ``linear_tolerance``). Pinned particles get zero velocity. Returns (body_velocity (B,3),
    body_angular_velocity (B,3), particle_velocity (P,3)).
    """
    body_velocity, angular, particle_velocity = _flight(model, state, dt, integrator)
    if model.spring_count:
        if integrator == "backward_euler":
            particle_velocity = state.particle_velocity + spring_step(model, state, dt, linear_tolerance, linear_solver)
        else:
            springs = spring_forces(model, state.particle_position, state.particle_velocity)
            particle_velocity += dt * springs * model.particle_inverse_mass[:, None]
        if model.particle_pinned.any():
            particle_velocity[model.particle_pinned] = 0.0
    _drive(model, state, dt, body_velocity, angular)
    return body_velocity, angular, particle_velocity


def carrying_springs(carry: Carry, model: Model, state: State, particle_velocity: np.ndarray, integrator: str) -> Carry:
    """``carry`` with this step's cloth springs' backward Euler Δv (``Carry.springs``, (P, 3)
    [m/s]: the free particle velocities ``particle_velocity`` less ``state``'s), for the next
    step's solve to start from; ``carry`` itself where no spring was solved implicitly."""
    if not (model.spring_count and integrator == "backward_euler"):
        return carry
    return carry._replace(springs=np.asarray(particle_velocity, dtype=float) - state.particle_velocity)


def body_free_velocities(
    model: Model, state: State, dt: float, integrator: str = "symplectic_euler"
) -> tuple[np.ndarray, np.ndarray]:
    """The rigid bodies' part of ``free_velocities`` (the constraints method calls it alone: its
    particles are solved with the contacts): (body_velocity (B,3) [m/s], body_angular_velocity
    (B,3) [rad/s]) after dt under gravity. The gyroscopic term is explicit under explicit Euler
    and implicit (midpoint, ``free_flight``) otherwise; gravity does not depend on the state, so
    backward Euler's bodies move as symplectic Euler's.

    A driven model (``model.drive``, contactlab.driving) adds its external forces and torques
    [N], [N m] at the step's start time ``state.time``, and gives each kinematic body the
    velocity that carries it onto its path over the step (their inverse mass is 0: gravity and
    forces do not move them). External forces reach the bodies only this way
    (``ModelBuilder.add_force``)."""
    body_velocity, angular, _ = _flight(model, state, dt, integrator)
    _drive(model, state, dt, body_velocity, angular)
    return body_velocity, angular


def _flight(model, state, dt, integrator):
    """(body, angular, particle) velocities after dt under gravity alone, pinned particles at rest:
    ``free_flight`` (the compiled loop's stage 1), or under explicit Euler the explicit gyroscopic term."""
    if integrator == "explicit_euler":
        particle = state.particle_velocity + dt * model.gravity
        particle[np.asarray(model.particle_pinned, dtype=bool)] = 0.0
        angular = _gyroscopic_explicit(model, state.body_orientation, state.body_angular_velocity, dt)
        return state.body_velocity + dt * model.gravity, angular, particle
    orientation = np.array(state.body_orientation, dtype=float)
    return free_flight(
        *_flight_constants(model),
        np.array(state.body_velocity, dtype=float),
        np.array(state.body_angular_velocity, dtype=float),
        np.array(state.particle_velocity, dtype=float),
        rotations.matrices(orientation),
        float(dt),
    )


@derived
def _flight_constants(model: Model) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What ``free_flight`` reads of a Model — gravity (3,), the bodies' principal inertia (B, 3),
    the pinned particles (P,) — as writable copies (a read-only array is another type to Numba, and
    compiles it again), made once per Model."""
    return (
        np.array(model.gravity, dtype=float),
        np.array(model.body_inertia, dtype=float),
        np.array(model.particle_pinned, dtype=np.bool_),
    )


def _drive(model, state, dt, body_velocity, angular):
    """A driven model's loads and kinematic paths at the step's start, added to the bodies' free
    velocities in place: the compiled stage the compiled loop runs too, then any Python functions' paths."""
    drive = model.drive
    if drive is None:
        return
    t = float(state.time)
    position, orientation = (np.array(a, dtype=float) for a in (state.body_position, state.body_orientation))
    inverse = (np.array(model.body_inverse_mass, dtype=float), np.array(model.body_inverse_inertia, dtype=float))
    pose = (rotations.matrices(orientation), position, orientation)
    drive_velocities(drive.table, t, float(dt), inverse, pose, drive.function_loads(t), body_velocity, angular)
    bodies, velocity, turning = drive.function_path_velocities(position, orientation, t, dt)
    body_velocity[bodies], angular[bodies] = velocity, turning


def advance_positions(
    positions: tuple[np.ndarray, np.ndarray, np.ndarray],
    velocities: tuple[np.ndarray, np.ndarray, np.ndarray],
    body_dt: float | np.ndarray,
    particle_dt: float | np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions and orientations moved at constant velocities for a time step.

    positions: (body_position (B,3) [m], body_orientation (B,4), particle_position (P,3) [m]),
    as ``State.positions``; velocities: (body_velocity (B,3) [m/s], body_angular_velocity (B,3)
    [rad/s], particle_velocity (P,3) [m/s]), as ``State.velocities``. body_dt: scalar or (B,)
    [s]; particle_dt: scalar or (P,) [s] (per-entity steps serve the time-of-impact update of
    the impulse method). Returns the positions moved, in the same order.
    """
    body_dt = np.broadcast_to(np.asarray(body_dt, dtype=float), (len(positions[0]),)).copy()
    particle_dt = np.broadcast_to(np.asarray(particle_dt, dtype=float), (len(positions[2]),)).copy()
    arrays = (np.ascontiguousarray(a, dtype=float) for a in (*positions, *velocities))
    return moved(*arrays, body_dt, particle_dt)


@njit(cache=True)
def moved(
    body_position: np.ndarray,
    body_orientation: np.ndarray,
    particle_position: np.ndarray,
    body_velocity: np.ndarray,
    body_angular_velocity: np.ndarray,
    particle_velocity: np.ndarray,
    body_dt: np.ndarray,
    particle_dt: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``advance_positions``, compiled, with body_dt (B,) and particle_dt (P,) [s]: x + Δt v, and
    the orientations turned by Δt ω (``rotations.integrate``)."""
    position = np.empty_like(body_position)
    for b in range(body_position.shape[0]):
        for i in range(3):
            position[b, i] = body_position[b, i] + body_dt[b] * body_velocity[b, i]
    particles = np.empty_like(particle_position)
    for p in range(particle_position.shape[0]):
        for i in range(3):
            particles[p, i] = particle_position[p, i] + particle_dt[p] * particle_velocity[p, i]
    return position, rotations.integrate_compiled(body_orientation, body_angular_velocity, body_dt), particles
