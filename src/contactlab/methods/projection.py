"""Projection (SPEC W1, L2, M3): move colliding points back onto the surfaces.

One step is loop L2, stage by stage as on the slide:

1. internal forces: gravity (and cloth springs) → free velocities v*;
2. integrate velocities and positions: the predicted positions x̃ = x + h v*;
3. collision detection over the swept step: at the start positions x, every gap the step's
   motion could close (speculative contacts, box and hull manifolds kept), so a point may
   close a gap but never cross it, at any speed; then at the projected positions (a particle,
   or a cloth vertex, keeps its radius — the cloth's thickness — from every surface);
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
second-order overlap. An overlap up to ``slop`` is kept from growing but not pushed out (pushed
out, round-off overlaps become velocity and set stacks rocking); each step starts from the last
step's λ by contact id (``warm_start``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .. import rotations
from ..collision import swept_distances
from ..compiling import in_python, njit
from ..contacts import ContactArrays, values_carried
from ..dynamics.generalized import stack, unstack, unstacked
from ..dynamics.integrators import carrying_springs, free_velocities, moved
from ..state import Carry, Positions, State
from ..validation import check_counts
from .base import KeptManifoldOptions, StepInfo
from .jacobian_rows import row_products
from .loop_stages import (
    LoopModel,
    LoopSettings,
    Motion,
    Specialization,
    build_rows,
    detect,
    for_response,
    loop_inputs,
    loop_settings,
    poses,
    solve,
    specialization,
)
from .sequential import contact_order
from .velocity_level import swept_contacts

if TYPE_CHECKING:
    from ..model import Model
    from .jacobian_rows import ContactRows


@dataclass(frozen=True)
class Options(KeptManifoldOptions):
    """Settings of ``[method.projection]`` (after the collision settings of KeptManifoldOptions:
    the first pass of a step detects at the step's start, keeping box and hull manifolds)."""

    iterations: int = 100
    """Gauss-Seidel sweeps per projection (at most)"""
    tolerance: float = 1e-10
    """m: stop once a sweep moves no contact point more"""
    passes: int = 2
    """detect-and-project rounds per step"""
    contact_margin: float = 0.001
    """m: gaps this small are detected too"""
    slop: float = 0.0005
    """m of penetration left alone (the rest is projected out)"""
    warm_start: float = 1.0
    """fraction of last step's projection λ to start from (by contact id; 0 = cold)"""

    def __post_init__(self):
        super().__post_init__()
        check_counts(self, {"iterations": 1, "passes": 1})
        self._number("tolerance", 0.0)
        self._number("warm_start", 0.0, maximum=1.0)
        self._number("slop", 0.0)


def step(
    model: Model, state: State, dt: float, options: Options, integrator: str = "symplectic_euler"
) -> tuple[State, StepInfo]:
    """One step of loop L2 with projection; returns (new State, StepInfo). Stages 1–3 and every
    pass's detection run here, for every scene; the projection (``project``) and the further
    passes (``passes``, run as Python with this step's detection) are the code the compiled
    loop's step (``loop_steps.projection_step``) runs."""
    h = dt
    # 1. internal forces → free velocities v*
    free = free_velocities(model, state, h, integrator)
    v_free = stack(*free)
    # 2. integrate velocities and positions: x̃ = x + h v* (explicit Euler: the old velocities)
    moving = stack(*state.velocities) if integrator == "explicit_euler" else v_free
    predicted_displacement = h * moving
    sweep = swept_distances(model, *unstack(moving, model.body_count), h)
    # 3–4, over the swept step: the contacts at the start within reach of the step's motion
    # (speculative: a gap may close, never be crossed), projected — nothing passes through
    # anything, however fast; then at the projected positions, for what the linearization missed
    particle_motion = unstack(predicted_displacement, model.body_count)[2]
    contacts, manifolds = swept_contacts(model, state, options, sweep, particle_motion)
    arrays, motion, rotation, carried = loop_inputs(model, state, "projection")
    settings = loop_settings(model, "projection", options, dt)
    spec = for_response(specialization(model, "projection", options))
    found = contacts.arrays()
    warm = settings.warm_start * values_carried(carried[0], carried[1], found.feature_id)[0]
    zero = np.zeros_like(predicted_displacement)
    displacement, lam, total_sweeps, change = project(
        arrays, settings, spec, found, motion, rotation, (zero, predicted_displacement), warm
    )
    carried_on = carrying_springs(
        Carry("projection", manifolds, contacts.feature_id, lam), model, state, free[2], integrator
    )
    #    and again at the projected positions: the loop's own passes, their detection this step's
    #    (meshes, cloth and other granularities too), run from Python
    last = [contacts]

    def detect_projected(_model, _spec, at, _detecting):
        projected = State.assemble(
            state.time + h, (at.body_position, at.body_orientation, at.particle_position), state.velocities
        )
        last[0] = options.collide(model, projected, sweep, particle_motion=particle_motion)[0]
        return last[0].arrays(), rotations.matrices(at.body_orientation)

    displacement, _, total_sweeps, change, pushed = in_python(passes, detect_projected=detect_projected)(
        arrays, settings, spec, motion, (None, None), found, (displacement, total_sweeps, change, lam)
    )
    # 5. advance dt, velocities from the projected positions
    start = (motion.body_position, motion.body_orientation, motion.particle_position)
    positions, velocities = advance(start, v_free, displacement, predicted_displacement, h)
    new = State.assemble(state.time + h, positions, velocities, carried_on)
    return new, StepInfo(
        last[0], solver_iterations=total_sweeps, solver_residual=change, impulses=pushed / h
    )  # a correction Δx = M⁻¹ Jᵀ λ is the velocity change Δx / h


# ---- the compiled stages the Python step and the compiled loop (methods.velocity_loop) share ----


@njit(cache=True)
def projection_targets(rows: ContactRows, offset: np.ndarray, depth: np.ndarray, slop: float) -> np.ndarray:
    """The least normal displacement each contact must reach, (C,) [m]: J_n u ≥ J_n offset + δ,
    for contacts of depth δ (C,) [m] (> 0: overlapping) detected at positions the displacement
    ``offset`` (N,) [m, rad] reached from the step's start (``rows``, a ContactRows, built
    there). Of an overlap, the ``slop`` [m] is left alone (pushed out, round-off overlaps become
    velocity and set stacks rocking), but it is never let grow; a gap (δ ≤ 0) may close."""
    reached = row_products(rows, offset)
    target = np.empty(depth.shape[0])
    for c in range(depth.shape[0]):
        kept = max(depth[c] - slop, 0.0) if depth[c] > 0.0 else depth[c]
        target[c] = reached[c, 0] + kept
    return target


@njit(cache=True)
def displaced(positions: Positions, displacement: np.ndarray, h: float) -> Positions:
    """``positions`` (body positions (B, 3) [m], orientations (B, 4), particle positions (P, 3)
    [m], as ``State.positions``) moved over h [s] by a generalized displacement (N,) [m, rad]:
    translations added, rotation vectors applied by the exponential map (as velocities
    displacement / h for h, ``integrators.moved``)."""
    body_position, body_orientation, particle_position = positions
    rate = unstacked(displacement / h, body_position.shape[0])
    return moved(
        body_position,
        body_orientation,
        particle_position,
        rate[0],
        rate[1],
        rate[2],
        np.full(body_position.shape[0], h),
        np.full(particle_position.shape[0], h),
    )


@njit(cache=True)
def advance(
    positions: Positions, free: np.ndarray, displacement: np.ndarray, predicted: np.ndarray, h: float
) -> tuple[Positions, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Stage 5: the step's end from its start ``positions`` (as :func:`displaced` takes them):
    positions moved by the projected displacement (N,) [m, rad], velocities v = v* + (u − h v*) / h
    from the free ones ``free`` (N,) and the ``predicted`` displacement h v* (N,). Returns
    (positions, velocities ((B, 3), (B, 3), (P, 3)) [m/s, rad/s])."""
    velocity = free + (displacement - predicted) / h
    return displaced(positions, displacement, h), unstacked(velocity, positions[0].shape[0])


@njit(cache=True)
def displaced_motion(motion: Motion, displacement: np.ndarray, h: float) -> Motion:
    """The Motion at the positions a generalized displacement (N,) [m, rad] reaches from
    ``motion``'s over h [s] (``projection.displaced``; its velocities are ``motion``'s)."""
    position, orientation, particle = displaced(
        (motion.body_position, motion.body_orientation, motion.particle_position), displacement, h
    )
    return Motion(
        position, orientation, motion.body_velocity, motion.body_angular_velocity, particle, motion.particle_velocity
    )


@njit(cache=True)
def project(
    model: LoopModel,
    settings: LoopSettings,
    spec: Specialization,
    contacts: ContactArrays,
    at: Motion,
    rotation: np.ndarray,
    displacements: tuple[np.ndarray, np.ndarray],
    warm: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, int, float]:
    """Stage 4 of loop L2: the step's displacement (N,) [m, rad] corrected, a copy, so that no
    contact detected at the positions ``at`` (a Motion, with rotation (B, 3, 3)) ends deeper than
    its slop: J_n u ≥ J_n offset + δ (``projection_targets``), by the sweeps of ``solve`` on
    displacements from the warm start ``warm`` (C, 3) [kg m]. ``displacements`` = (offset, the
    displacement that reached ``at`` from the step's start; the displacement to correct), (N,)
    each; ``spec``: the run's Specialization (``for_response``: its ``slabs`` and ``parallel``
    read here). Returns (the corrected displacement, λ (C, 3) [kg m], sweeps, last correction
    [m]); no contact, no sweep."""
    offset, displacement = displacements
    if contacts.depth.shape[0] == 0:
        return displacement, np.zeros((0, 3)), 0, 0.0
    rows = build_rows(model, contacts, at, rotation)
    target = projection_targets(rows, offset, contacts.depth, settings.slop)
    corrected = displacement.copy()
    order = contact_order(contacts.point, contacts.feature_id, model.gravity)
    system = (corrected, target, warm, order)
    lam, sweeps, change = solve(settings, spec.slabs, spec.parallel, rows, contacts, at, system, None)
    return corrected, lam, sweeps, change


@njit(cache=True, inline="always")
def detect_projected(
    model: LoopModel, spec: Specialization, at: Motion, detecting: tuple
) -> tuple[ContactArrays, np.ndarray]:
    """Stage 3 of a further pass: the contacts at the projected positions ``at`` (a Motion),
    detected afresh (nothing kept) within the step's first ``reach`` (N,) [m]; ``detecting`` =
    (reach, the kept manifolds' fields, for their types). Returns (ContactArrays, the bodies'
    rotations (B, 3, 3) at ``at``). ``step`` runs ``passes`` with its own detection here."""
    reach, kept = detecting
    rotation, centers, rots = poses(model, at)
    contacts, _, _ = detect(model.colliders, spec.plan, spec.keeping, (centers, rots), reach, kept, 0.0, None)
    return contacts, rotation


@njit(cache=True)
def passes(
    model: LoopModel,
    settings: LoopSettings,
    spec: Specialization,
    motion: Motion,
    detecting: tuple,
    contacts: ContactArrays,
    progress: tuple,
) -> tuple[np.ndarray, ContactArrays, int, float, np.ndarray]:
    """Stages 3–4 again, ``settings.passes`` − 1 times at most: contacts detected afresh at the
    positions the projected displacement reaches from ``motion`` (``detect_projected``, given
    ``detecting``), and projected, cold, for what one linear projection left (curved surfaces,
    rotations); done once there is no contact, or a pass makes one sweep that moves nothing more
    than the tolerance. ``contacts``: the first pass's; ``progress`` = (the displacement (N,) after
    the first pass, its sweeps, its last correction [m], its λ (C, 3) [kg m]). Returns
    (displacement, the last pass's contacts, the sweeps of every pass summed, the last pass's last
    correction [m], each last contact's λ summed over the passes by contact id (C, 3) [kg m]).

    The one loop of passes: the compiled step (``loop_steps.projection_step``) runs it compiled,
    ``step`` runs it from Python (``compiling.in_python``) with its own detection."""
    displacement, sweeps, change, pushed = progress
    response = for_response(spec)
    for _ in range(settings.passes - 1):
        if contacts.depth.shape[0] == 0:
            break
        at = displaced_motion(motion, displacement, settings.dt)
        found, rotation = detect_projected(model, spec, at, detecting)
        displacement, more, made, change = project(
            model,
            settings,
            response,
            found,
            at,
            rotation,
            (displacement, displacement),
            np.zeros((found.depth.shape[0], 3)),
        )
        pushed = values_carried(contacts.feature_id, pushed, found.feature_id)[0] + more
        contacts = found
        sweeps += made
        if made <= 1 and change <= settings.tolerance:
            break
    return displacement, contacts, sweeps, change, pushed
