"""Contact springs by backward Euler (SPEC M1; loop L1, stage 4).

The springs' system (M + h (h K + D)) v⁺ = M v* + h Jᵀ F₀, with the active set of engaged
normal springs and sticking or slipping anchors settled by repeated solves: compiled and
matrix-free (``implicit_spring_velocities``, M as its blocks, J and Jᵀ through the contact rows,
conjugate gradients) for rigid bodies and free particles, and with SciPy on the assembled
system (``implicit_velocities``) where cloth joins the base system or the direct solver is
chosen. :mod:`contactlab.methods.penalty`'s ``step`` chooses between them; the compiled loop
(:mod:`contactlab.methods.loop_steps`, ``penalty_step``) takes the first.

Arrays: C contacts, B bodies, P particles, N = 6B + 3P degrees of freedom; rows as
``jacobian_rows.ContactRows``; springs as ``penalty_springs.ContactSprings``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import numpy as np
import scipy.sparse as sp

from ..compiling import njit
from ..dynamics.integrators import PRODUCTS, block_conjugate_gradients, factor_symmetric
from ..dynamics.integrators import conjugate_gradients as sparse_conjugate_gradients
from ..ordered_sums import ordered_dot
from ..rotations import world_tensors
from .jacobian_rows import ContactRows, along_rows, contact_velocity, row_products
from .penalty_springs import ContactSprings, SpringSettings

# ---- backward Euler -----------------------------------------------------------------------
#
# The springs' system (M + h (h K + D)) v⁺ = M v* + h Jᵀ F₀ is solved matrix-free: M as its
# blocks (body masses (B,), world inertia tensors (B, 3, 3), particle masses (P,)), J and Jᵀ
# through the contact rows (``jacobian_rows.ContactRows``), the springs as a weight (C, 3) per row.

if TYPE_CHECKING:
    from .penalty import Options


GO_ON, STOP, HOLD = 0, 1, 2  # what ``pass_verdict`` says of a pass


@njit(cache=True, inline="always")
def pass_verdict(settled: bool, held: bool, passes: int, iterations: int, slipping: bool) -> int:
    """After pass ``passes`` of the springs' fixed point (``implicit_spring_velocities`` and
    ``implicit_velocities`` alike): STOP when the springs ``settled``, or when ``held`` slip
    forces have had their ``iterations`` more passes; at pass ``iterations``, STOP when nothing is
    ``slipping``, else HOLD the slip forces (and settle the engaged springs afresh); else GO_ON."""
    if settled or (held and passes == 2 * iterations):
        return STOP
    if passes == iterations:
        return HOLD if slipping else STOP
    return GO_ON


@njit(cache=True)
def mass_blocks(
    body_mass: np.ndarray, body_inertia: np.ndarray, rotation: np.ndarray, particle_mass: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """M's blocks at the rotations (B, 3, 3): (body_mass (B,) [kg], world inertia R I Rᵀ (B, 3, 3)
    [kg m²], particle_mass (P,) [kg])."""
    return body_mass, world_tensors(rotation, body_inertia), particle_mass


@njit(cache=True)
def free_dofs(particle_pinned: np.ndarray, body_fixed: np.ndarray) -> np.ndarray:
    """(N,) 1.0 for each DOF that moves, 0.0 for a pinned particle's (particle_pinned (P,) bool)
    and a kinematic body's (body_fixed (B,) bool: its path, not the springs, moves it)."""
    body_count = body_fixed.shape[0]
    free = np.ones(6 * body_count + 3 * particle_pinned.shape[0])
    for b in range(body_count):
        if body_fixed[b]:
            free[6 * b : 6 * b + 6] = 0.0
    for p in range(particle_pinned.shape[0]):
        if particle_pinned[p]:
            free[6 * body_count + 3 * p] = free[6 * body_count + 3 * p + 1] = free[6 * body_count + 3 * p + 2] = 0.0
    return free


@njit(cache=True)
def mass_product(mass: tuple, x: np.ndarray, out: np.ndarray) -> np.ndarray:
    """out = M x (N,) for M's blocks ``mass`` (``mass_blocks``) and x (N,); returns out."""
    body_mass, inertia, particle_mass = mass
    B = body_mass.shape[0]
    for b in range(B):
        o = 6 * b
        for i in range(3):
            out[o + i] = body_mass[b] * x[o + i]
            out[o + 3 + i] = inertia[b, i, 0] * x[o + 3] + inertia[b, i, 1] * x[o + 4] + inertia[b, i, 2] * x[o + 5]
    for p in range(particle_mass.shape[0]):
        for i in range(3):
            out[6 * B + 3 * p + i] = particle_mass[p] * x[6 * B + 3 * p + i]
    return out


@njit(cache=True)
def transpose_product(rows: ContactRows, values: np.ndarray, out: np.ndarray) -> np.ndarray:
    """out += Jᵀ λ (N,) for each contact's row values λ (C, 3) (normal, t1, t2); returns out."""
    for c in range(values.shape[0]):
        along_rows(c, rows, values[c, 0], values[c, 1], values[c, 2], out, False)
    return out


class SpringSystem(NamedTuple):
    """A = M + F Jᵀ W J F, the matrix of a backward Euler pass, as compiled code takes it."""

    rows: ContactRows
    """the contacts' rows of J"""
    weight: np.ndarray
    """(C, 3) W: the springs' weights h (h k + c) on the rows (normal, t1, t2), 0 for a spring not acting"""
    mass: tuple
    """M's blocks (``mass_blocks``)"""
    free: np.ndarray
    """(N,) F = diag(free): 1.0 for a DOF that moves, 0.0 for a pinned particle's or a kinematic body's"""
    scratch: np.ndarray
    """(N,) the products' scratch (``system_product``'s ``kept``)"""


@njit(cache=True)
def system_product(system: SpringSystem, x: np.ndarray, kept: np.ndarray, out: np.ndarray) -> np.ndarray:
    """out = A x (N,) for the ``system`` A; ``kept`` (N,) is scratch. Allocates nothing: the
    conjugate gradients call it every iteration. Returns out."""
    rows, weight, mass, free, _ = system
    N = x.shape[0]
    for i in range(N):
        kept[i] = free[i] * x[i]
        out[i] = 0.0
    for c in range(weight.shape[0]):
        vn, v1, v2 = contact_velocity(c, rows, kept)
        along_rows(c, rows, weight[c, 0] * vn, weight[c, 1] * v1, weight[c, 2] * v2, out, False)
    mass_product(mass, x, kept)
    for i in range(N):
        out[i] = kept[i] + free[i] * out[i]
    return out


@njit(cache=True)
def system_diagonal(system: SpringSystem) -> np.ndarray:
    """The diagonal of A (``SpringSystem``) (N,): M's and Σ W (J_row,i)² over the rows."""
    rows, weight, mass, free, _ = system
    body_mass, inertia, particle_mass = mass
    B = body_mass.shape[0]
    diagonal = np.empty(free.shape[0])
    for b in range(B):
        for i in range(3):
            diagonal[6 * b + i], diagonal[6 * b + 3 + i] = body_mass[b], inertia[b, i, i]
    for p in range(particle_mass.shape[0]):
        for i in range(3):
            diagonal[6 * B + 3 * p + i] = particle_mass[p]
    for c in range(weight.shape[0]):
        for d in range(3):
            w, direction = weight[c, d], rows.frame[c, d]
            if w == 0.0:
                continue
            for side in range(2):
                b = rows.body[c, side]
                if b >= 0:
                    r = rows.arm[c, side]
                    lever = (
                        r[1] * direction[2] - r[2] * direction[1],
                        r[2] * direction[0] - r[0] * direction[2],
                        r[0] * direction[1] - r[1] * direction[0],
                    )
                    for i in range(3):
                        diagonal[6 * b + i] += free[6 * b + i] * w * direction[i] ** 2
                        diagonal[6 * b + 3 + i] += free[6 * b + 3 + i] * w * lever[i] ** 2
                for m in range(3):
                    p = rows.particle[c, side, m]
                    if p < 0:
                        break
                    for i in range(3):
                        o = 6 * B + 3 * p + i
                        diagonal[o] += free[o] * w * (rows.weight[c, side, m] * direction[i]) ** 2
    return diagonal


@njit(cache=True)
def block_product(system: SpringSystem, x: np.ndarray, out: np.ndarray) -> None:
    """out = A x (``system_product``) on x and out as (N / 3, 3), the layout of
    ``block_conjugate_gradients``."""
    system_product(system, x.reshape(-1), system.scratch, out.reshape(-1))


PRODUCTS[SpringSystem] = block_product  # what the conjugate gradients apply to a SpringSystem


@njit(cache=True)
def spring_conjugate_gradients(
    system: SpringSystem, rhs: np.ndarray, guess: np.ndarray, tolerance: float, most: int
) -> tuple[np.ndarray, float, int]:
    """A v = rhs (``SpringSystem``) by ``integrators.block_conjugate_gradients`` with the Jacobi
    preconditioner diag(A) (its 3 × 3 blocks' diagonals; 1 for a DOF with no mass and no
    spring, left as it is), from ``guess`` (N,), until |r| < tolerance |rhs| or ``most``
    iterations. Returns (v (N,), |A v − rhs| / |rhs|, iterations)."""
    N = rhs.shape[0]
    diagonal = system_diagonal(system)
    blocks = np.zeros((N // 3, 3, 3))
    for i in range(N):
        blocks[i // 3, i % 3, i % 3] = diagonal[i] if diagonal[i] != 0.0 else 1.0
    v = guess.copy()
    iterations, _ = block_conjugate_gradients(
        system, blocks, rhs.reshape((N // 3, 3)), v.reshape((N // 3, 3)), (tolerance, most)
    )
    residual = system_product(system, v, system.scratch, np.empty(N))
    for i in range(N):
        residual[i] -= rhs[i]
    return v, np.sqrt(ordered_dot(residual, residual)) / max(np.sqrt(ordered_dot(rhs, rhs)), 1e-300), iterations


@njit(cache=True)
def implicit_spring_velocities(
    settings: SpringSettings,
    springs: ContactSprings,
    rows: ContactRows,
    depth: np.ndarray,
    v_free: np.ndarray,
    mass: tuple,
    free: np.ndarray,
    h: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, float, int]:
    """Backward Euler for the contact springs: v⁺ with M v⁺ = M v* + h Jᵀ F(x + h v⁺, v⁺), where
    M v⁺ = M v* is the step without contacts (rigid bodies and free particles: M as
    ``mass_blocks``); ``free`` (N,) 1.0 for the DOFs that may move, 0.0 for a pinned
    particle's and a kinematic body's, whose v⁺ is their v* (v_free (N,), the velocities
    without contacts: a kinematic body's is its path's); depth (C,) [m], h [s].

    The springs are linear in v⁺ along the Jacobian fixed at x: δ⁺ = δ − h J_n v⁺ and
    s⁺ = s + h J_t v⁺, so an engaged normal spring adds h (h k + c) J_nᵀ J_n to the matrix and
    h k δ J_nᵀ to the right-hand side, and a sticking anchor spring likewise along J_t. J v⁺ is
    the contact's relative velocity, both sides: the part of it a DOF that does not move with
    the springs gives (a paddle on its path) is known, and its h (h k + c) J_nᵀ J_n v* goes to
    the right-hand side. (Left out, the springs took a moving kinematic body for one at rest:
    a box pushed at 0.5 m/s by a paddle sat 7.9 mm deep, its springs holding 1 J and the step
    reporting 257 N while 2.9 N acted.)

    Friction is settled first, as in plasticity's return mapping: a pass with every pressed
    contact sticking (the elastic predictor) says which anchor springs would pull harder than
    μ F_n; those contacts slip in the direction of that pull, with the force μ F_n⁺ of the
    latest pass. Then the engaged normal springs (F_n⁺ > 0) and the slip forces are found by
    repeating the solve (``spring_conjugate_gradients``) until they stop changing (an active-set
    iteration; for convex energies such as a plane's, and no friction, it is the exact backward
    Euler step, which never adds energy). Where the passes have not settled after
    ``implicit_iterations`` and some contact slips, the slip forces are taken as μ k δ, the
    normal springs' force at the step's start, and the engaged springs are settled again from
    the first guess (as many passes again at most): with stiff springs the slip forces need
    not settle at all, as a
    slip force moves the bodies, which presses the neighbours' springs by about μ k h² / m
    times as much again, and each pass multiplied them (a 1000-sphere pile at dt = 1/240 s
    flung spheres at 100 m/s). Returns (v⁺ (N,), forces (C, 3) [N], elongation
    after the step (C, 2) [m], passes, relative residual of the last linear solve, conjugate-gradient
    iterations summed over the passes).
    """
    C = depth.shape[0]
    k, c_n, k_t, c_t, mu = (
        springs.stiffness,
        springs.damping,
        springs.friction_stiffness,
        springs.friction_damping,
        springs.friction,
    )
    start = row_products(rows, v_free)
    # the contact velocities (C, 3) the DOFs that do not move with the springs (a kinematic body
    # on its path) give: their v⁺ is v*, so their side of h (h K + D) v⁺ is known and goes right
    driven = row_products(rows, (1.0 - free) * v_free)
    is_driven = np.any(driven != 0.0)
    guess, engaged, sticks = np.empty(C, np.bool_), np.empty(C, np.bool_), np.empty(C, np.bool_)
    slips = np.zeros(C, np.bool_)
    for c in range(C):
        guess[c] = depth[c] - h * start[c, 0] > 0.0
        engaged[c] = guess[c]
        sticks[c] = engaged[c] and mu[c] > 0.0
    slip_force, slip_direction = np.zeros((C, 2)), np.zeros((C, 2))
    weight, pull = np.empty((C, 3)), np.empty((C, 3))
    normal, trial, elongation = np.zeros(C), np.zeros((C, 2)), np.zeros((C, 2))
    base = mass_product(mass, v_free, np.empty(v_free.shape[0]))
    scratch = np.empty(v_free.shape[0])  # the conjugate gradients' products
    v_new, residual, passes, linear_iterations = v_free, 0.0, 0, 0
    held = False  # whether the slip forces are held at μ k δ (the step did not settle)
    while passes < 2 * settings.implicit_iterations:
        passes += 1
        for c in range(C):
            weight[c, 0] = h * (h * k[c] + c_n[c]) if engaged[c] else 0.0
            weight[c, 1] = weight[c, 2] = h * (h * k_t[c] + c_t[c]) if sticks[c] else 0.0
            pull[c, 0] = k[c] * depth[c] if engaged[c] else 0.0
            for d in range(2):
                pull[c, 1 + d] = -k_t[c] * springs.elongation[c, d] if sticks[c] else slip_force[c, d]
        rhs = base + free * (h * transpose_product(rows, pull, np.zeros(v_free.shape[0])))
        if is_driven:
            rhs -= free * transpose_product(rows, weight * driven, np.zeros(v_free.shape[0]))
        v_new, residual, iterations = spring_conjugate_gradients(
            SpringSystem(rows, weight, mass, free, scratch), rhs, v_new, settings.linear_tolerance, 10 * v_free.shape[0]
        )
        linear_iterations += iterations
        # the forces at the new state say which springs act
        velocity = row_products(rows, v_new)
        settled = True
        largest = 0.0
        for c in range(C):
            depth_new = depth[c] - h * velocity[c, 0]
            force = k[c] * depth_new - c_n[c] * velocity[c, 0]
            now_engaged = depth_new > 0.0 and force > 0.0
            normal[c] = force if now_engaged else 0.0
            largest = max(largest, mu[c] * normal[c])
            for d in range(2):
                elongation[c, d] = springs.elongation[c, d] + h * velocity[c, 1 + d]
                trial[c, d] = -k_t[c] * elongation[c, d] - c_t[c] * velocity[c, 1 + d]
            size, limit = np.sqrt(trial[c, 0] ** 2 + trial[c, 1] ** 2), mu[c] * normal[c]
            if passes == 1:  # the elastic predictor decides who slips, and which way
                slips[c] = sticks[c] and size > limit
                for d in range(2):
                    slip_direction[c, d] = trial[c, d] / max(size, 1e-300) if slips[c] else 0.0
                now_sticks = sticks[c] and not slips[c]
            else:
                now_sticks = sticks[c] and now_engaged
            settled = settled and now_engaged == engaged[c] and now_sticks == sticks[c]
            engaged[c], sticks[c] = now_engaged, now_sticks
        for c in range(C):  # μ F_n⁺ along the slip, F_n⁺ of this pass (held: μ k δ while engaged)
            for d in range(2):
                if held:
                    force = slip_direction[c, d] * mu[c] * k[c] * max(depth[c], 0.0) if engaged[c] else 0.0
                else:
                    force = slip_direction[c, d] * mu[c] * normal[c]
                settled = settled and abs(force - slip_force[c, d]) <= 1e-9 * max(1.0, largest) + 1e-6 * abs(
                    slip_force[c, d]
                )
                slip_force[c, d] = force
        verdict = pass_verdict(settled, held, passes, settings.implicit_iterations, slips.any())
        if verdict == STOP:
            break
        if verdict == HOLD:
            held = True  # unsettled slip forces: hold them, and settle the engaged springs afresh
            for c in range(C):
                engaged[c] = guess[c]
                sticks[c] = guess[c] and mu[c] > 0.0 and not slips[c]
                for d in range(2):
                    slip_force[c, d] = slip_direction[c, d] * mu[c] * k[c] * max(depth[c], 0.0) if guess[c] else 0.0
    # return mapping: an anchor spring never pulls harder than μ F_n at the end of the step
    forces = np.empty((C, 3))
    for c in range(C):
        t1, t2 = (trial[c, 0], trial[c, 1]) if sticks[c] else (slip_force[c, 0], slip_force[c, 1])
        size, limit = np.sqrt(t1 * t1 + t2 * t2), mu[c] * normal[c]
        over = size > limit
        if over:
            t1, t2 = t1 * (limit / size), t2 * (limit / size)
        if not (sticks[c] and not over):
            elongation[c, 0], elongation[c, 1] = -t1 / k_t[c], -t2 / k_t[c]
        if not engaged[c]:
            elongation[c, 0] = elongation[c, 1] = 0.0
        forces[c, 0], forces[c, 1], forces[c, 2] = normal[c], t1, t2
    return v_new, forces, elongation, passes, residual, linear_iterations


def implicit_velocities(
    springs: ContactSprings,
    J: sp.spmatrix,
    base: tuple,
    v_free: np.ndarray,
    depth: np.ndarray,
    dt: float,
    options: Options,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, float, int]:
    """``implicit_spring_velocities`` with any base system ``base`` = (A₀ (N, N) sparse, b₀ (N,),
    free (N,) bool) of A₀ v⁺ = b₀ (``dynamics.generalized.implicit_base``: the cloth's linearized
    springs for cloth vertices under backward Euler) and the Jacobian J (3C, N) sparse, solved by
    SciPy (``linear_solver`` "direct", or "cg" there): the path of cloth under backward Euler and
    of the direct solver. Returns what ``implicit_spring_velocities`` returns."""
    A0, b0, free = base
    h = dt
    C = len(depth)
    k, c, k_t, c_t = springs.stiffness, springs.damping, springs.friction_stiffness, springs.friction_damping
    guess = depth - h * (J @ v_free)[0::3] > 0.0
    engaged = guess
    sticks = engaged & (springs.friction > 0.0)
    slip_force = np.zeros((C, 2))
    keep = sp.diags(free.astype(float))
    driven = J @ np.where(free, 0.0, v_free)  # J v* of the DOFs that do not move with the springs (3C,)
    v_new, residual, linear_iterations = v_free, 0.0, 0
    held = False  # whether the slip forces are held at μ k δ (the step did not settle)
    held_limit = springs.friction * k * np.maximum(depth, 0.0)  # μ k δ, the normal springs' force at the start
    for passes in range(1, 2 * options.implicit_iterations + 1):
        weight = np.column_stack(
            [engaged * h * (h * k + c), np.repeat((sticks * h * (h * k_t + c_t))[:, None], 2, axis=1)]
        )
        pull = np.column_stack(
            [engaged * k * depth, np.where(sticks[:, None], -k_t[:, None] * springs.elongation, slip_force)]
        )
        A = (A0 + keep @ (J.T @ sp.diags(weight.ravel()) @ J) @ keep).tocsr()
        rhs = b0 + free * (h * (J.T @ pull.ravel()))
        if np.any(driven):  # the known side of the springs' velocity terms (see implicit_spring_velocities)
            rhs -= free * (J.T @ (weight.ravel() * driven))
        v_new, iterations = _solve(A, rhs, v_new, options)
        linear_iterations += iterations
        residual = float(np.linalg.norm(A @ v_new - rhs) / max(np.linalg.norm(rhs), 1e-300))
        # the forces at the new state say which springs act
        velocity = (J @ v_new).reshape(C, 3)
        depth_new = depth - h * velocity[:, 0]
        normal = k * depth_new - c * velocity[:, 0]
        now_engaged = (depth_new > 0.0) & (normal > 0.0)
        normal = np.where(now_engaged, normal, 0.0)
        elongation = springs.elongation + h * velocity[:, 1:]
        trial = -k_t[:, None] * elongation - c_t[:, None] * velocity[:, 1:]
        size, limit = np.linalg.norm(trial, axis=1), springs.friction * normal
        if passes == 1:  # the elastic predictor decides who slips, and which way
            slips = sticks & (size > limit)
            slip_direction = np.where(slips[:, None], trial / np.maximum(size, 1e-300)[:, None], 0.0)
            now_sticks = sticks & ~slips
        else:
            now_sticks = sticks & now_engaged
        # μ F_n⁺ along it, F_n⁺ of this pass (held: μ k δ while engaged)
        new_slip_force = slip_direction * (np.where(now_engaged, held_limit, 0.0) if held else limit)[:, None]
        settled = (
            np.array_equal(now_engaged, engaged)
            and np.array_equal(now_sticks, sticks)
            and np.allclose(new_slip_force, slip_force, rtol=1e-6, atol=1e-9 * max(1.0, limit.max(initial=0.0)))
        )
        engaged, sticks, slip_force = now_engaged, now_sticks, new_slip_force
        verdict = pass_verdict(settled, held, passes, options.implicit_iterations, bool(slips.any()))
        if verdict == STOP:
            break
        if verdict == HOLD:
            held = True  # unsettled slip forces: hold them, and settle the engaged springs afresh
            engaged, sticks = guess, guess & (springs.friction > 0.0) & ~slips
            slip_force = slip_direction * np.where(guess, held_limit, 0.0)[:, None]
    # return mapping: an anchor spring never pulls harder than μ F_n at the end of the step
    tangential = np.where(sticks[:, None], trial, slip_force)
    size, limit = np.linalg.norm(tangential, axis=1), springs.friction * normal
    over = size > limit
    tangential[over] *= (limit[over] / size[over])[:, None]
    elongation = np.where((sticks & ~over)[:, None], elongation, -tangential / k_t[:, None])
    elongation[~engaged] = 0.0
    return v_new, np.column_stack([normal, tangential]), elongation, passes, residual, linear_iterations


def _solve(A, rhs, guess, options):
    """(x, conjugate-gradient iterations) of A x = rhs: compiled block-Jacobi-preconditioned conjugate
    gradients (``integrators.conjugate_gradients``) from ``guess``, or the sparse direct solve."""
    if options.linear_solver == "direct":  # A is symmetric positive definite (conjugate gradients need it too)
        return factor_symmetric(A).solve(rhs), 0
    solution, iterations, _ = sparse_conjugate_gradients(
        A, rhs, guess, np.ones(A.shape[0], dtype=np.bool_), options.linear_tolerance, 10 * A.shape[0]
    )
    return solution, iterations
