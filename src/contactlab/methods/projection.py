"""Projection (SPEC W1, L2, M3): move colliding points back onto the surfaces.

One step is loop L2, stage by stage as on the slide:

1. internal forces: gravity (and cloth springs) → free velocities v*;
2. integrate velocities and positions: the predicted positions x̃ = x + h v*;
3. collision detection at x̃ (a particle, or a cloth vertex, keeps its radius — the cloth's
   thickness — from every surface);
4. project the positions of the colliding points onto the surfaces: the generalized
   displacement of the step, u = h v* at first, is corrected by M⁻¹ Jᵀ λ so that every
   contact's depth δ − J_n (u − h v*) is at most 0 (λ_n ≥ 0: a projection only pushes out).
   A rigid body's correction is split between translation and rotation by its inverse mass
   and inverse inertia (D1); a point on a cloth triangle moves its three vertices by their
   barycentric shares. Friction in position form: the tangential displacement of a projected
   point over the step, J_t u, is cancelled by at most μ λ_n (Coulomb, so a point sticks when
   it can and slides otherwise). This is projected Gauss-Seidel on displacements — the very
   sweeps of the impulse method, on positions instead of velocities (M3: constraints on
   positions with explicit integration are projection);
5. advance dt: velocities follow from the projected positions, v = v* + (u − h v*) / h, so a
   projected point does not keep approaching the surface it was put on.

Projection is inelastic: a projected point loses its approach speed, whatever the material's
restitution ε (use impulses for bounces, G2). ``passes`` repeats detection and projection on the
projected positions, for curved surfaces and rotations, where one linear projection leaves a
second-order overlap.
"""

from dataclasses import dataclass

import numpy as np

from ..builder import _number
from ..collision import collide, swept_distances
from ..dynamics.generalized import stack, unstack
from ..dynamics.integrators import advance_positions, free_velocities
from ..state import State
from . import CollisionOptions, StepInfo, check_counts
from .sequential import row_products, rows_of, solve_order, solve_sequential_impulses, sweep_groups


@dataclass
class Options(CollisionOptions):
    """Settings of ``[method.projection]`` (after the collision settings of CollisionOptions)."""
    iterations: int = 100                 # Gauss-Seidel sweeps per projection (at most)
    tolerance: float = 1e-9               # m: stop once a sweep moves no contact point more
    passes: int = 2                       # detect-and-project rounds per step
    contact_margin: float = 0.001         # m: gaps this small are detected too
    cloth_samples: int = 2                # samples per cloth triangle edge against obstacles (P2c); 0: vertices only

    def __post_init__(self):
        super().__post_init__()
        check_counts(self, {"iterations": 1, "passes": 1})
        self.tolerance = _number(self.tolerance, "tolerance", 0.0)


def project(model, state, predicted, displacement, options, sweep=None):
    """Project the colliding points of the predicted state onto the surfaces.

    state: the positions at the start of the step; predicted: the State at x + displacement;
    displacement u (N,) the generalized displacement of the step [m, rad] (body i: entries
    6i..6i+6 = translation and rotation vector; particle j: 6B+3j..). sweep (B + P,) [m]: how
    far each body and particle may still be pushed; gaps that small are detected too, as open
    constraints (λ = 0 while they stay open), so that no push of one contact drives a point
    through a surface nobody was watching. Returns (corrected displacement (N,), the
    contacts, sweeps, last correction [m]).
    """
    contacts = collide(model, predicted, options.contact_margin, sweep, options.granularity, options.normal,
                       options.samples, cloth_samples=options.cloth_samples)
    if contacts.count == 0:
        return displacement, contacts, 0, 0.0
    rows = rows_of(model, contacts, predicted.body_position, predicted.body_orientation)
    # depth after a further displacement Δu: δ − J_n Δu ≤ 0, i.e. J_n u ≥ J_n u_now + δ
    target = row_products(rows, displacement)[:, 0] + contacts.depth
    corrected = displacement.copy()
    _, sweeps, change = solve_sequential_impulses(rows, contacts.friction, target, corrected, options.iterations,
                                                  options.tolerance, np.zeros((contacts.count, 3)),
                                                  *sweep_groups(rows, contacts, predicted,
                                                                solve_order(contacts, model.gravity)))
    return corrected, contacts, sweeps, change


def step(model, state, dt, options, integrator="symplectic_euler"):
    """One step of loop L2 with projection; returns (new State, StepInfo)."""
    h = dt
    # 1. internal forces → free velocities v*
    v_free = stack(*free_velocities(model, state, h, integrator))
    # 2. integrate velocities and positions: x̃ = x + h v* (explicit Euler: the old velocities)
    moving = stack(*state.velocities) if integrator == "explicit_euler" else v_free
    predicted_displacement = h * moving
    displacement, total_sweeps, change = predicted_displacement, 0, 0.0
    sweep = swept_distances(model, *unstack(moving, model.body_count), h)
    for _ in range(options.passes):
        predicted = State.assemble(state.time + h, _displaced(model, state, displacement, h), state.velocities)
        # 3. collision detection at the predicted positions; 4. project the colliding points
        displacement, contacts, sweeps, change = project(model, state, predicted, displacement, options, sweep)
        total_sweeps += sweeps
        if contacts.count == 0 or (sweeps <= 1 and change <= options.tolerance):
            break
    # 5. advance dt, velocities from the projected positions
    velocity = v_free + (displacement - predicted_displacement) / h
    positions = _displaced(model, state, displacement, h)
    new = State.assemble(state.time + h, positions, unstack(velocity, model.body_count), state.carried)
    return new, StepInfo(contacts, solver_iterations=total_sweeps, solver_residual=change)


def _displaced(model, state, displacement, h):
    """Positions (body_position, body_orientation, particle_position) moved by a generalized
    displacement (N,): translations added, rotation vectors applied by the exponential map."""
    return advance_positions(*state.positions, *unstack(displacement / h, model.body_count), h, h)
