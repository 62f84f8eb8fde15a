"""Impulses (SPEC I1, I2, R1–R4, F2, M2) inside the constraint loop L3.

One step, stage by stage as on the slide:

1. internal forces: gravity → free velocities v*;
2. integrate positions with v* (a prediction), which says how far everything sweeps;
3. collision detection over the swept step: contacts at the start positions with gaps down
   to what the motion could close (speculative contacts), so nothing tunnels;
4. formulate the contacts as impulses and solve them, in two phases:
   a. collisions (I2, R1–R4, F2): the contacts approaching now get, together, the normal
      impulses J_n = −(1 + ε) v_n / (J M⁻¹ Jᵀ) (R4 is this effective mass written out for two
      rigid bodies) and friction impulses of at most μ J_n; then the contacts those impulses
      set approaching, and so on: an impact travels down a chain of touching bodies one link
      at a time (Newton's cradle), while simultaneous impacts stay simultaneous;
   b. resting contacts (M2): sequential impulses with the accumulated normal impulse clamped
      at λ ≥ 0 and friction clamped to μ λ, until no impulse changes a velocity by more than
      the tolerance — this is projected Gauss-Seidel on velocities, the matrix-free twin of
      the constraints method — swept from the highest contact down along gravity (see
      ``solve_order``) and warm-started from last step's impulses (a new contact from the
      weight it bears, ``guess_new_impulses``);
5. recompute velocities and positions: x = x₀ + h v⁺ — so a body at rest stays put — with the
   time-of-impact correction below; advance time.

Friction (F2) is not written here: both phases sweep contacts with
:func:`contactlab.methods.sequential.sweep_contacts`, whose per-contact update clamps the
tangential impulse to the friction cone μ λ (the same sweep serves ``constraints``).

Time of impact. A contact that was open at the start of the step (gap d₀ > 0) closes at the
fraction τ = d₀ / (−h v_n*) of it. The body travels with v* until then and with v⁺ after, so
its position is x₀ + h(τ v* + (1 − τ) v⁺) (orientation likewise). This is what makes bounce
heights follow h₀ ε²ⁿ instead of bouncing early, from wherever the step happened to end.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..compiling import njit
from ..dynamics.generalized import stack, unstack
from ..dynamics.integrators import free_velocities
from ..errors import InputError
from ..state import State
from ..validation import check_counts, number
from .base import KeptManifoldOptions, StepInfo
from .jacobian_rows import contact_velocity, rows_of
from .sequential import solve_order, solve_sequential_impulses, sweep_contacts, sweep_groups
from .velocity_level import (
    detect,
    first_impulses,
    positions_split_at_impact,
    predict,
    relative_gravity,
    resting_target,
    restitution_threshold,
    step_without_contacts,
)

if TYPE_CHECKING:
    from ..model import Model
    from .jacobian_rows import ContactRows


@dataclass
class Options(KeptManifoldOptions):
    """Settings of ``[method.impulse]`` (documented with units in docs/methods/impulse.md), after
    the collision settings of KeptManifoldOptions."""

    iterations: int = 100
    """sweeps of sequential impulses per step, and collision waves (at most)"""
    tolerance: float = 1e-7
    """m/s: stop once a sweep changes no contact's velocity more"""
    restitution_threshold: float = -1.0
    """m/s: slower approaches bounce with ε = 0; < 0 means 2·|g|·dt"""
    stabilization: float = 0.2
    """fraction of an existing penetration removed per step (0 = none)"""
    slop: float = 0.0005
    """m of penetration left alone by the stabilization"""
    max_push_velocity: float = 1.0
    """m/s: the stabilization never pushes apart faster"""
    time_of_impact: bool = True
    """split the step at the impact (see module docs)"""
    warm_start: float = 1.0
    """fraction of last step's impulses to start from, and of a new contact's weight over the step
    (``velocity_level.guess_new_impulses``); 0 = cold"""

    def __post_init__(self):
        super().__post_init__()
        check_counts(self, {"iterations": 1})
        self.tolerance = number(self.tolerance, "tolerance", 0.0)
        self.restitution_threshold = number(self.restitution_threshold, "restitution_threshold")
        self.stabilization = number(self.stabilization, "stabilization", 0.0, maximum=1.0)
        self.slop = number(self.slop, "slop", 0.0)
        self.max_push_velocity = number(self.max_push_velocity, "max_push_velocity", 0.0)
        self.warm_start = number(self.warm_start, "warm_start", 0.0, maximum=1.0)
        if not isinstance(self.time_of_impact, bool):
            raise InputError("time_of_impact", f"expected true or false, found {self.time_of_impact!r}")


@njit(cache=True)
def resolve_collisions(
    rows: ContactRows,
    friction: np.ndarray,
    restitution: np.ndarray,
    gravity_normal: np.ndarray,
    gap_at_start: np.ndarray,
    dt: float,
    threshold: float,
    u: np.ndarray,
    max_waves: int,
    sweeps: int,
    tolerance: float,
    tau: np.ndarray,
    order: np.ndarray,
) -> int:
    """Collision impulses (I2, R1–R4, F2) in waves, until no contact approaches.

    A wave is every contact that is approaching now: at the current velocities it would be
    closed by the end of the step, and its impact velocity u_n = v_n + g_n (τ − ½) h is below
    −threshold (τ: where in the step it closes, d₀ / (−h v_n) for a gap d₀ > 0 at the start,
    else 0). The wave's impulses are solved together — accumulated, λ ≥ 0 — so that each
    member leaves at −ε u_n + g_n (½ − τ) h (restitution; see ``relative_gravity``), with
    friction of at most μ λ (F2). A single contact gets j = −(1 + ε) u_n / k in one update
    (R4 with k = J M⁻¹ Jᵀ). Simultaneous impacts (a box landing flat on four corners) are
    thus one wave and stay symmetric, while an impact passed along a chain of touching
    bodies makes one wave per link (Newton's cradle: one ball in, one ball out).

    ``rows`` as from ``contact_rows``; gravity_normal, gap_at_start (C,) [m/s², m]; u the
    generalized velocity (changed in place); ``tau`` (C,) receives each contact's τ, −1 where
    it had no impact; ``order`` (C,) int is the order in which a wave's members are swept (see
    ``solve_order``). Returns the number of waves.
    """
    k = rows.k
    C = k.shape[0]
    target = np.empty(C)
    closes = np.empty(C)
    impulses = np.zeros((C, 3))
    members = np.empty(C, dtype=np.int64)
    for c in range(C):
        tau[c] = -1.0
    for wave in range(max_waves):
        count = np.int64(0)  # not a literal 0, which would compile sweep_contacts twice
        for o in range(C):
            c = order[o]
            if restitution[c] <= 0.0 or k[c, 0] <= 0.0:
                continue
            vn = contact_velocity(c, rows, u)[0]
            if vn >= 0.0 or gap_at_start[c] + dt * vn > 0.0:  # separating, or still open at the end
                continue
            closes[c] = min(1.0, gap_at_start[c] / (-vn * dt)) if gap_at_start[c] > 0.0 else 0.0
            impact = vn + gravity_normal[c] * (closes[c] - 0.5) * dt
            if impact < -threshold:
                target[c] = -restitution[c] * impact + gravity_normal[c] * (0.5 - closes[c]) * dt
                tau[c] = closes[c] if tau[c] < 0.0 else min(tau[c], closes[c])
                impulses[c, 0] = impulses[c, 1] = impulses[c, 2] = 0.0
                members[count] = c
                count += 1
        if count == 0:
            return wave
        for _sweep in range(sweeps):
            if sweep_contacts(members, count, target, impulses, rows, friction, u) <= tolerance:
                break
    return max_waves


def step(
    model: Model, state: State, dt: float, options: Options, integrator: str = "symplectic_euler"
) -> tuple[State, StepInfo]:
    """One step of loop L3 with impulses; returns (new State, StepInfo). Its compiled stages are
    called one by one from Python; ``simulate`` steps the scenes the compiled loop serves
    (methods.velocity_loop) through that loop instead, which gives the very same numbers."""
    h = dt
    # 1. internal forces → free velocities v*
    free = free_velocities(model, state, h, integrator)
    # 2. integrate positions (a prediction): how far each body and particle sweeps this step
    move, predicted, sweep = predict(model, state, free, integrator, h)
    # 3. collision detection over the swept step
    contacts, manifolds = detect(model, state, options, sweep)
    if contacts.count == 0:
        return step_without_contacts(state, h, predicted, free, contacts, manifolds, "impulse_")
    # 4. formulate the impulses and solve them: collisions first (I2, F2), then resting contacts (M2)
    gap_at_start = -contacts.depth  # d₀
    rows = rows_of(model, contacts, state.body_position, state.body_orientation)
    u = stack(*free)
    order = solve_order(contacts, model.gravity)
    tau = np.empty(contacts.count)
    resolve_collisions(
        rows,
        contacts.friction,
        contacts.restitution,
        relative_gravity(model, contacts),
        gap_at_start,
        h,
        restitution_threshold(model, h, options),
        u,
        options.iterations,
        options.iterations,
        options.tolerance,
        tau,
        order,
    )
    warm = first_impulses(model, state, contacts, "impulse_", options.warm_start, h)
    impulses, sweeps, change = solve_sequential_impulses(
        rows,
        contacts.friction,
        resting_target(gap_at_start, h, options),
        u,
        options.iterations,
        options.tolerance,
        warm,
        *sweep_groups(rows, contacts, state, order),
    )
    solved = unstack(u, model.body_count)
    # 5. recompute positions from the corrected velocities, split at the time of impact
    positions = positions_split_at_impact(model, state, contacts, tau, move, free, solved, h, options.time_of_impact)
    carried = dict(state.carried, manifolds=manifolds, impulse_ids=contacts.feature_id, impulse_values=impulses)
    new = State.assemble(state.time + h, positions, solved, carried)
    return new, StepInfo(contacts, solver_iterations=sweeps, solver_residual=change, impulses=impulses)
