"""Hard constraints (SPEC W4, C1–C9, F4, F4a, F4b, M2, M4) in the constraint loop L3.

One step, stage by stage as on the slide:

1. internal forces → free velocities v*: gravity, and the cloth's springs (explicitly, or with
   backward Euler linearized into A = M − h D − h² K, M4);
2. integrate positions with v* (a prediction of how far everything sweeps);
3. collision detection over the swept step (speculative contacts: gaps down to what the motion
   could close, so nothing tunnels);
4. formulate the constraints: each contact keeps its distance d = nᵀ(p_A − p_B) ≥ 0 (C1) with a
   force λ n, λ ≥ 0 (C2), complementary (C3). On velocities (C5b, the default), the mixed LCP
   A v⁺ = b + Jᵀ λ, J_n v⁺ ≥ t, λ ≥ 0, λᵀ(J_n v⁺ − t) = 0 (C4), with t the target normal
   velocity of each contact (restitution at impact, no overlap at the end of the step, a
   fraction of an existing overlap removed — see methods.velocity_level; the same law as the
   impulse method, M2). Eliminating v⁺ gives the LCP (C6) B λ ≥ c with B = J A⁻¹ Jᵀ and
   c = t − J A⁻¹ b: assembled sparse, A⁻¹ applied block by block when A = M (block diagonal)
   and through a sparse factorization when cloth is implicit. With friction each contact
   has three rows (normal, two tangents) and the problem is FCLIB's local frictional contact
   problem u = W r + q, W = B, q = J v* − t, solved with ``contactlab.lcp``;
5. recompute velocities v⁺ = v* + A⁻¹ Jᵀ λ and positions x = x₀ + h v⁺ (split at the moment of
   impact as in the impulse method), so a resting body never creeps; advance time.

Solvers (``solver``): "matrix_free" (default) is projected Gauss-Seidel with friction right
after each normal (F4a) in sequential-impulse form — on v, without forming B — and warm
started from the last step's λ by persistent contact id; on implicit cloth, where B's rows
would need A⁻¹ Jᵀ in full (dense), it is "apgd": accelerated projected gradient needing only
products B x = J (A⁻¹ (Jᵀ x)), one back-solve each with the step's LU of A, which also gives v*
(``implicit_free_velocities``). "nsgs" (F4a) and "staggered" (F4b)
solve the assembled W, q, and "newton" solves it by semi-smooth Newton steps on the
Alart–Curnier function (``contactlab.lcp.newton``: a sparse LU a step, for stiff problems the
sweeps leave unconverged); "pgs", "redblack", "redblack_blocks", "jacobi" and "lemke" solve the frictionless LCP
B_nn λ_n ≥ c_n (friction ignored: use them to study C7–C9). The accelerations formulation
(C5a, ``formulation = "acceleration"``, see ``acceleration_target``) keeps resting contacts
resting but has no means to stop an impact within a step — why velocities are preferred
when things collide.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..compiling import njit
from ..contacts import jacobian
from ..dynamics.generalized import implicit_base, inverse_mass_matrix, stack, unstack
from ..dynamics.integrators import body_free_velocities, carrying_springs, factor_symmetric, free_velocities
from ..dynamics.sparse_cholesky import CholeskyFactor, ancestors, cholesky_solve_within
from ..errors import InputError
from ..state import Carry, State
from ..validation import check_choices
from . import velocity_level
from .base import StepInfo
from .jacobian_rows import row_products
from .loop_stages import (
    build_rows,
    loop_inputs,
    loop_model,
    loop_settings,
    solve,
    specialization,
)
from .sequential import contact_order
from .velocity_level import (
    VelocityOptions,
    predict_positions,
    split_at_impact,
    step_without_contacts,
    swept_contacts,
    targets,
    warm_impulses,
)

if TYPE_CHECKING:
    from ..contacts import Contacts
    from ..model import Model
    from .jacobian_rows import ContactRows

SOLVERS = (
    "matrix_free",
    "nsgs",
    "staggered",
    "apgd",
    "newton",
    "pgs",
    "redblack",
    "redblack_blocks",
    "jacobi",
    "lemke",
)
CONE_ONLY_SOLVERS = ("apgd", "newton")  # they solve the Coulomb cone, not its pyramid
FRICTIONLESS_SOLVERS = ("pgs", "redblack", "redblack_blocks", "jacobi", "lemke")
FORMULATIONS = ("velocity", "acceleration")


@dataclass(frozen=True)
class Options(VelocityOptions):
    """Settings of ``[method.constraints]``: the collision settings, what impulse and constraints
    share (VelocityOptions: its small steps with the matrix-free solver on velocities only), and
    the solver's."""

    solver: str = "matrix_free"
    """matrix_free | nsgs (F4a) | staggered (F4b) | apgd | newton | pgs | redblack | redblack_blocks | jacobi |
    lemke"""
    formulation: str = "velocity"
    """velocity (C5b) | acceleration (C5a)"""
    friction_model: str = "cone"
    """nsgs/staggered: cone (disk ‖r_t‖ ≤ μ r_n) | pyramid (inscribed box)"""
    tolerance: float | None = None
    """matrix_free: the largest change a sweep makes to a contact's velocity [m/s] (default 1e-7); pgs, redblack,
    redblack_blocks, jacobi, lemke: the LCP residual [m/s]; nsgs, staggered, apgd, newton: the relative natural-map
    error [1] (default 1e-6)"""
    omega: float = 1.0
    """over-relaxation factor [1] of pgs, redblack, redblack_blocks, jacobi (0 < ω ≤ 2)"""

    def __post_init__(self):
        super().__post_init__()
        check_choices(self, {"solver": SOLVERS, "formulation": FORMULATIONS, "friction_model": ("cone", "pyramid")})
        if self.solver in CONE_ONLY_SOLVERS and self.friction_model != "cone":
            raise InputError(
                "friction_model",
                f"solver {self.solver!r} solves the Coulomb cone only; use "
                f'friction_model = "cone", or solver "nsgs" or "staggered" for the pyramid',
            )
        if self.tolerance is None:  # each solver's own measure, so each its own default
            self._settle("tolerance", 1e-7 if self.solver == "matrix_free" else 1e-6)
        self._number("tolerance", 0.0, strict=True)
        self._number("omega", 0.0, strict=True, maximum=2.0)


# ---- C6: the MLCP reduced to an LCP ----------------------------------------------------------


class SystemInverse:
    """Applies A⁻¹ for the MLCP's A: M⁻¹ block by block when A = M, a sparse factor of A (with the
    pinned degrees of freedom held) when the cloth is integrated implicitly (M4)."""

    def __init__(
        self, inverse_mass: sp.spmatrix | None = None, matrix: sp.spmatrix | None = None, free: np.ndarray | None = None
    ) -> None:
        self.inverse_mass = inverse_mass
        self.free = free
        # A is symmetric positive definite (clamped spring Jacobians, damping, masses)
        self.factor = None if matrix is None else factor_symmetric(matrix)

    def solve(self, rhs: np.ndarray | sp.spmatrix) -> np.ndarray:
        """A⁻¹ rhs for rhs (N,) or (N, k); pinned degrees of freedom get 0."""
        if self.factor is None:
            return self.inverse_mass @ rhs
        rhs = np.asarray(rhs.todense() if sp.issparse(rhs) else rhs, dtype=float)
        mask = self.free if rhs.ndim == 1 else self.free[:, None]
        return np.where(mask, self.factor.solve(np.where(mask, rhs, 0.0)), 0.0)


def lcp_matrices(
    J: sp.spmatrix, inverse: SystemInverse, v_free: np.ndarray, target: np.ndarray
) -> tuple[sp.spmatrix, np.ndarray]:
    """B = J A⁻¹ Jᵀ (3C, 3C) and q = J v* − t (3C,) of the local problem u = B λ + q (C6).

    J (3C, N) sparse; inverse: a SystemInverse; v_free v* = A⁻¹ b (N,); target t (3C,) (the
    normal rows' targets, 0 on tangent rows). The LCP of C6 in the spec's sign, B λ ≥ c, has
    c = t − J A⁻¹ b = −q.
    """
    A_inv_Jt = inverse.solve(J.T.tocsc() if inverse.factor is None else J.T)
    B = sp.csr_matrix(J @ A_inv_Jt)
    return B, J @ v_free - target


def delassus_operator(J: sp.spmatrix, inverse: SystemInverse) -> spla.LinearOperator:
    """W = J A⁻¹ Jᵀ (3C, 3C) as a LinearOperator, x ↦ J (A⁻¹ (Jᵀ x)): one solve with A per
    product, W never formed. J (3C, N) sparse; inverse: a SystemInverse. With A's block Cholesky
    factor (every system of bodies and particles) the product is one compiled call,
    ``delassus_product``; with SuperLU's factor it goes through ``SystemInverse.solve``."""
    size = (J.shape[0], J.shape[0])
    factor = inverse.factor
    if not isinstance(factor, CholeskyFactor):
        transpose = J.T.tocsr()
        return spla.LinearOperator(size, matvec=lambda x: J @ inverse.solve(transpose @ x), dtype=float)
    rows, columns = _csr_arrays(J), _csr_arrays(J.T.tocsr())
    a = factor.analysis
    touched = np.unique(rows[1] // 3)  # the blocks (particles, bodies' halves) J's rows reach
    reach = ancestors(a.order, a.column_start, a.column_rows, touched)
    solve_with = (a.order, a.column_start, a.column_rows, factor.values, reach)

    def product(x):  # x (3C,) or (3C, 1), as LinearOperator.matvec passes it
        return delassus_product(
            rows, columns, inverse.free, solve_with, np.ascontiguousarray(x, dtype=np.float64).ravel()
        )

    return spla.LinearOperator(size, matvec=product, dtype=float)


def _csr_arrays(matrix: sp.csr_matrix) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(indptr, indices, data) of a CSR matrix, as int64, int64 and float64 arrays."""
    return (
        matrix.indptr.astype(np.int64),
        matrix.indices.astype(np.int64),
        np.ascontiguousarray(matrix.data, dtype=np.float64),
    )


@njit(cache=True)
def delassus_product(
    rows: tuple[np.ndarray, np.ndarray, np.ndarray],
    columns: tuple[np.ndarray, np.ndarray, np.ndarray],
    free: np.ndarray,
    factor: tuple,
    x: np.ndarray,
) -> np.ndarray:
    """W x = J A⁻¹ Jᵀ x (3C,) for x (3C,), as ``SystemInverse.solve`` applies A⁻¹ (pinned
    degrees of freedom held at 0): ``rows`` J (3C, N) and ``columns`` Jᵀ (N, 3C) as CSR arrays
    (indptr, indices, data), ``free`` (N,) bool, ``factor`` A's block Cholesky factor as
    (order, column_start, column_rows, values, reach) (``sparse_cholesky.cholesky_solve_within``'s
    arrays; reach: the ``ancestors`` of the blocks J touches, about 80 % of L on the draped
    ``cloth_drape``). Sums in the order of SciPy's CSR products, so the same bits as the SciPy
    path (up to the sign of a zero)."""
    indptr, indices, data = columns
    n = free.shape[0]
    rhs = np.zeros((n, 1))
    for i in range(n):
        if free[i]:
            acc = 0.0
            for e in range(indptr[i], indptr[i + 1]):
                acc += data[e] * x[indices[e]]
            rhs[i, 0] = acc
    order, column_start, column_rows, values, reach = factor
    solved = cholesky_solve_within(order, column_start, column_rows, values, reach, rhs)
    indptr, indices, data = rows
    out = np.empty(indptr.shape[0] - 1)
    for row in range(out.shape[0]):
        acc = 0.0
        for e in range(indptr[row], indptr[row + 1]):
            if free[indices[e]]:
                acc += data[e] * solved[indices[e], 0]
        out[row] = acc
    return out


def delassus_bound(J: sp.spmatrix, inverse_mass: sp.spmatrix) -> float:
    """An upper bound on the largest eigenvalue of W = J A⁻¹ Jᵀ [m/s per N s]: the largest
    absolute row sum of J M⁻¹ Jᵀ (Gershgorin). It holds because A ⪰ M: backward Euler's
    A = M − h D − h² K adds −h D − h² K ⪰ 0 (clamped springs, damping), so A⁻¹ ⪯ M⁻¹.
    J (3C, N) sparse; inverse_mass M⁻¹ (N, N) sparse."""
    return float(abs(J @ inverse_mass @ J.T).sum(axis=1).max())


def solve_assembled(
    J: sp.spmatrix,
    inverse: SystemInverse,
    inverse_mass: sp.spmatrix,
    v_free: np.ndarray,
    target: np.ndarray,
    friction: np.ndarray,
    warm: np.ndarray,
    options: Options,
) -> tuple[np.ndarray, int, float]:
    """λ (C, 3) of the problem u = W λ + q with ``options.solver``; (λ, iterations, residual).
    apgd takes W as the operator ``delassus_operator`` and its step from ``delassus_bound``
    (``inverse_mass`` M⁻¹ (N, N) sparse); the others sweep W assembled by ``lcp_matrices``."""
    from ..lcp import solve_friction_contact, solve_lcp

    solver = options.solver
    C = len(friction)
    if solver == "apgd":
        result = solve_friction_contact(
            delassus_operator(J, inverse),
            J @ v_free - target,
            friction,
            method="apgd",
            tol=options.tolerance,
            max_iterations=options.iterations,
            r0=warm.ravel(),
            lipschitz=delassus_bound(J, inverse_mass),
        )
        return result.r.reshape(C, 3), result.iterations, result.error
    B, q = lcp_matrices(J, inverse, v_free, target)
    if solver in FRICTIONLESS_SOLVERS:
        normal_rows = np.arange(0, 3 * C, 3)
        result = solve_lcp(
            B[normal_rows][:, normal_rows],
            -q[normal_rows],
            method=solver,
            tol=options.tolerance,
            max_iterations=options.iterations,
            warm_start=warm[:, 0],
            omega=options.omega,
        )
        lam = np.zeros((C, 3))
        lam[:, 0] = result.lam
        return lam, result.iterations, result.residual
    method = "nsgs" if solver == "matrix_free" else solver  # the same F4a sweeps, on W
    result = solve_friction_contact(
        B,
        q,
        friction,
        method=method,
        tol=options.tolerance,
        max_iterations=options.iterations,
        r0=warm.ravel(),
        friction_model=options.friction_model,
    )
    return result.r.reshape(C, 3), result.iterations, result.error


def acceleration_target(
    current_velocity: np.ndarray, free_velocity: np.ndarray, gap_at_start: np.ndarray, dt: float, options: Options
) -> np.ndarray:
    """C5a: the constraints differentiated once, J_n a ≥ 0 for the contacts that touch (d ≤ slop),
    written as a velocity target after one step of a: v_n⁺ ≥ v_n (the normal velocity they
    have now, ``current_velocity``), plus the stabilization of an overlap. An open contact
    has no constraint on accelerations (its target lies below its free velocity, so it never
    binds), and a touching contact already approaching keeps approaching: accelerations
    cannot stop an impact within a step. All (C,) [m/s, m]."""
    push = np.minimum(
        options.stabilization * np.maximum(-gap_at_start - options.slop, 0.0) / dt, options.max_push_velocity
    )
    touching = gap_at_start <= options.slop  # within the slop: in contact, d ≈ 0
    return np.where(touching, np.minimum(current_velocity, 0.0) + push, free_velocity - 1.0)


# ---- the step: loop L3 --------------------------------------------------------------------


def implicit_free_velocities(
    model: Model, state: State, h: float
) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray], SystemInverse]:
    """Backward Euler's free velocities with the cloth (M4) from one factorization of
    A = M − h D − h² K, which the contact solve then reuses: (free velocities as
    ``free_velocities`` returns them, the SystemInverse of A). One LU and one solve cost about
    what the conjugate gradients of ``free_velocities`` cost alone (320 iterations on a draped
    64 × 64 cloth)."""
    bodies = body_free_velocities(model, state, h, "backward_euler")
    # implicit_base reads only the bodies' part of v* once there are springs
    A0, b0, free_dofs = implicit_base(model, state, h, stack(*bodies, np.zeros((model.particle_count, 3))))
    inverse = SystemInverse(matrix=A0, free=free_dofs)
    return unstack(inverse.solve(b0), model.body_count), inverse


def normal_row_targets(
    model: Model,
    state: State,
    contacts: Contacts,
    rows: ContactRows,
    v_free: np.ndarray,
    h: float,
    options: Options,
) -> tuple[np.ndarray, np.ndarray]:
    """Stage 4a: each normal row's target velocity (C,) [m/s] and time of impact τ (C,) (−1:
    none) — on velocities (C5b: ``velocity_level.targets``, what the matrix-free step and the
    compiled loop compute) or on accelerations (C5a)."""
    if options.formulation == "velocity":  # the sweep order is impulse's alone: any order does
        settings = loop_settings(model, "constraints", options, h)
        order = np.arange(contacts.count)
        return targets(loop_model(model), settings, False, True, contacts.arrays(), rows, v_free, order)
    gap_at_start = -contacts.depth
    normal_velocity = row_products(rows, v_free)[:, 0]
    current = row_products(rows, stack(*state.velocities))[:, 0]
    return (acceleration_target(current, normal_velocity, gap_at_start, h, options), np.full(contacts.count, -1.0))


def solve_constraints(
    model: Model,
    state: State,
    contacts: Contacts,
    v_free: np.ndarray,
    target: np.ndarray,
    warm: np.ndarray,
    options: Options,
    implicit_inverse: SystemInverse | None = None,
) -> tuple[np.ndarray, np.ndarray, int, float]:
    """Stage 4b with an assembled problem: the reactions λ (C, 3) [N s] and v⁺ = v* + A⁻¹ Jᵀ λ
    (N,), with the solver's sweeps and residual, for the solvers other than "matrix_free"
    (which sweeps the rows, ``loop_stages.solve``), and for any solver on implicit cloth
    (``implicit_inverse``: the SystemInverse of stage 1)."""
    inverse_mass = inverse_mass_matrix(model, state.body_orientation)
    # A = M, or with implicit cloth the A factored in stage 1
    inverse = SystemInverse(inverse_mass=inverse_mass) if implicit_inverse is None else implicit_inverse
    J = jacobian(contacts, state.body_position, model.body_count, model.particle_count)
    targets = np.zeros((contacts.count, 3))
    targets[:, 0] = target
    # on implicit cloth, matrix_free means products with W = J A⁻¹ Jᵀ (apgd): sweeps would
    # need W's rows, that is A⁻¹ Jᵀ in full — dense, seconds a step on a 64 × 64 drape
    if options.solver == "matrix_free":
        options = replace(options, solver="apgd")
    lam, iterations, residual = solve_assembled(
        J, inverse, inverse_mass, v_free, targets.ravel(), contacts.friction, warm, options
    )
    return lam, v_free + inverse.solve(J.T @ lam.ravel()), iterations, residual


def step(
    model: Model, state: State, dt: float, options: Options, integrator: str = "symplectic_euler"
) -> tuple[State, StepInfo]:
    """One step of loop L3 with hard constraints; returns (new State, StepInfo). On velocities
    with the matrix-free solver (the default) and no implicit cloth this is
    ``velocity_level.step``, whose stages 4–5 are the compiled loop's own; the accelerations
    formulation, the assembled solvers and implicit cloth take the stages below, with the same
    compiled rows, warm start and split at the time of impact."""
    implicit_cloth = integrator == "backward_euler" and model.spring_count > 0
    if options.solver == "matrix_free" and options.formulation == "velocity" and not implicit_cloth:
        return velocity_level.step("constraints", model, state, dt, options, integrator)
    h = dt
    # 1. internal forces → free velocities v* (A v* = b)
    inverse = None
    if implicit_cloth:
        free, inverse = implicit_free_velocities(model, state, h)
    else:
        free = free_velocities(model, state, h, integrator)
    v_free = stack(*free)
    # 2. integrate positions (a prediction): how far each body and particle sweeps this step
    move, predicted, sweep = predict_positions(model, state, free, integrator, h)
    # 3. collision detection over the swept step
    contacts, manifolds = swept_contacts(model, state, options, sweep, h * move[2])
    if contacts.count == 0:
        carried = carrying_springs(Carry.none("constraints", manifolds), model, state, free[2], integrator)
        return step_without_contacts(state, h, (predicted, free), contacts, carried)
    # 4. formulate the constraints: targets of the normal rows (C1–C5), then the LCP (C6) and its solve
    arrays, motion, rotation, carried = loop_inputs(model, state, "constraints")
    settings = loop_settings(model, "constraints", options, dt)
    found = contacts.arrays()
    rows = build_rows(arrays, found, motion, rotation)
    target, tau = normal_row_targets(model, state, contacts, rows, v_free, h, options)
    warm = warm_impulses(arrays, settings, found, motion, carried[0], carried[1])
    if options.solver == "matrix_free" and inverse is None:  # the accelerations formulation, swept
        v_new = v_free.copy()
        order = contact_order(found.point, found.feature_id, arrays.gravity)
        spec = specialization(model, "constraints", options)
        system = (v_new, target, warm, order)
        lam, iterations, residual = solve(settings, spec.slabs, spec.parallel, rows, found, motion, system, None)
    else:
        lam, v_new, iterations, residual = solve_constraints(
            model, state, contacts, v_free, target, warm, options, inverse
        )
    # 5. recompute velocities and positions (x = x₀ + h v⁺), split at the time of impact
    floats = tuple(np.array(v, dtype=float) for v in (*move, *free))  # as velocity_level._floats
    positions = split_at_impact(arrays, found, motion, tau, (floats[:3], floats[3:]), v_new, settings)
    carried_on = carrying_springs(
        Carry("constraints", manifolds, contacts.feature_id, lam), model, state, free[2], integrator
    )
    new = State.assemble(state.time + h, positions, unstack(v_new, model.body_count), carried_on)
    return new, StepInfo(contacts, solver_iterations=int(iterations), solver_residual=float(residual), impulses=lam)
