"""Each method's compiled step, stage for stage as its Python ``step``: impulse and constraints
(``velocity_step``, loop L3), projection (``projection_step``, loop L2) and penalty
(``penalty_step``, loop L1).

``run`` (:mod:`contactlab.methods.velocity_loop`) calls the one step its flags choose; each is
built from the shared stages of :mod:`contactlab.methods.loop_stages` and the stages its
method's module names (:mod:`contactlab.methods.impulse`, :mod:`~contactlab.methods.velocity_level`,
:mod:`~contactlab.methods.projection`, :mod:`~contactlab.methods.penalty_springs`,
:mod:`~contactlab.methods.penalty_implicit`). The three steps share one module because they
share one signature and one convention: a flag that is None leaves its branch uncompiled.
``tests/test_velocity_loop.py`` holds each equal, bit for bit, to its method's ``step``.

Numba's cache of ``run`` is refreshed only when ``velocity_loop.py`` changes: after editing a
step here, delete the caches (README, "For developers").
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np

from ..collision import half_thickness_sums
from ..compiling import njit
from ..contacts import ContactArrays, values_carried
from ..dynamics.generalized import stacked
from .jacobian_rows import ContactRows, row_products
from .loop_stages import (
    LoopModel,
    LoopSettings,
    Motion,
    build_rows,
    detect,
    free_motion,
    moved,
    poses,
    solve,
    swept_clear,
    swept_reach,
)
from .penalty_implicit import free_dofs, implicit_spring_velocities, mass_blocks
from .penalty_springs import (
    ContactSprings,
    anchors_after,
    entities_of,
    explicit_velocities,
    normal_stiffness,
    slowest_approach,
    spring_forces,
    springs_implicit,
    springs_of,
)
from .projection import advance, displaced, projection_targets
from .sequential import contact_order
from .velocity_level import respond

# ---- impulse and constraints (loop L3) ------------------------------------------------------


@njit(cache=True, inline="always")  # into ``run``: no call that passes the model and the state whole
def velocity_step(
    model: LoopModel,
    settings: LoopSettings,
    plan: tuple,
    large: bool | None,
    keeping: bool | None,
    impulse: bool | None,
    constraints: bool | None,
    slabs: bool | None,
    parallel: bool | None,
    motion: Motion,
    start: tuple,
    carried: tuple,
) -> tuple:
    """One step of loop L3 with impulses or hard constraints on velocities.

    ``start`` = the poses at the step's start: the bodies' rotations (B, 3, 3), the colliders'
    centres (N, 3) and rotations (N, 3, 3) (``poses``; ``run`` computes them once for the sample
    before and this step); ``carried`` = (the kept manifolds' eight fields, last step's contact
    ids (K,), their impulses (K, 3)); ``plan`` and the flags ``large``, ``keeping``, ``impulse``,
    ``constraints``, ``slabs`` and ``parallel`` (True, or None to leave a stage's branch
    uncompiled) as ``Stepper`` sets them. Returns (positions, velocities — the state's six
    arrays, new —, the carried triple for the next step, the ContactArrays, sweeps made, the
    sweeps' last change [m/s])."""
    h = settings.dt
    rotation, centers, rots = start
    # 1. internal forces → free velocities v*
    free = free_motion(model, motion, rotation, h)
    # 2. predict: how far each body and particle sweeps this step
    reach = swept_reach(model, free[0], free[1], free[2], h, settings.margin)
    # 3. collision detection over the swept step
    contacts, manifolds, near = detect(
        model, plan, large, keeping, motion, centers, rots, reach, carried[0], settings.manifold_tolerance
    )
    if contacts.depth.shape[0] == 0:
        positions = moved(
            motion.body_position,
            motion.body_orientation,
            motion.particle_position,
            free[0],
            free[1],
            free[2],
            np.full(free[0].shape[0], h),
            np.full(free[2].shape[0], h),
        )
        clear = swept_clear(near, settings.margin)
        return positions, free, (manifolds, carried[1][:0], carried[2][:0]), contacts, 0, 0.0, clear
    # 4–5. the contact rows, their targets and the solve; positions split at the time of impact
    positions, velocities, impulses, sweeps, change = respond(
        model,
        settings,
        impulse,
        constraints,
        slabs,
        parallel,
        contacts,
        motion,
        rotation,
        free,
        free,
        (carried[1], carried[2]),
    )
    return positions, velocities, (manifolds, contacts.feature_id, impulses), contacts, sweeps, change, False


# ---- the stages of a projection step (loop L2) that the velocity methods do not take ---------


@njit(cache=True)
def project(
    model: LoopModel,
    settings: LoopSettings,
    slabs: bool | None,
    parallel: bool | None,
    contacts: ContactArrays,
    at: Motion,
    rotation: np.ndarray,
    offset: np.ndarray,
    displacement: np.ndarray,
    warm: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, int, float]:
    """Stage 4 of loop L2 (``projection.project``): the step's displacement (N,) [m, rad]
    corrected, a copy, so that no contact detected at the positions ``at`` (a Motion, with
    rotation (B, 3, 3)), which the displacement ``offset`` (N,) reached from the step's start,
    ends deeper than its slop: J_n u ≥ J_n offset + δ (``projection_targets``), by the sweeps of
    ``solve`` on displacements from the warm start ``warm`` (C, 3) [kg m]. Returns (the corrected
    displacement, λ (C, 3) [kg m], sweeps, last correction [m]); no contact, no sweep."""
    if contacts.depth.shape[0] == 0:
        return displacement, np.zeros((0, 3)), 0, 0.0
    rows = build_rows(model, contacts, at, rotation)
    target = projection_targets(rows, offset, contacts.depth, settings.slop)
    corrected = displacement.copy()
    order = contact_order(contacts.point, contacts.feature_id, model.gravity)
    lam, sweeps, change = solve(settings, slabs, parallel, rows, contacts, at, corrected, target, warm, order)
    return corrected, lam, sweeps, change


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


# ``passes`` repeats the head of ``projection_step``'s signature (and so does ``velocity_step``'s):
# deliberately, the flags one by one, not gathered into one tuple, for Numba drops a branch
# whose flag is None only where that flag is an argument of its own.
@njit(cache=True)
def passes(
    model: LoopModel,
    settings: LoopSettings,
    plan: tuple,
    large: bool | None,
    keeping: bool | None,
    slabs: bool | None,
    parallel: bool | None,
    motion: Motion,
    reach: np.ndarray,
    kept: tuple,
    contacts: ContactArrays,
    displacement: np.ndarray,
    sweeps: int,
    change: float,
) -> tuple[np.ndarray, ContactArrays, int, float]:
    """Stages 3–4 again, ``settings.passes`` − 1 times at most: contacts detected afresh (nothing
    kept, the same ``reach`` (N,) [m]) at the positions the projected ``displacement`` (N,)
    reaches from ``motion``, and projected, cold, for what one linear projection left (curved
    surfaces, rotations); done once there is no contact, or a pass makes one sweep that moves
    nothing more than the tolerance. Returns (displacement, the last pass's contacts, the sweeps
    of every pass summed, the last pass's last correction [m])."""
    for _ in range(settings.passes - 1):
        if contacts.depth.shape[0] == 0:
            break
        at = displaced_motion(motion, displacement, settings.dt)
        rotation, centers, rots = poses(model, at)
        contacts, _, _ = detect(model, plan, large, keeping, at, centers, rots, reach, kept, 0.0)
        displacement, _, more, change = project(
            model,
            settings,
            slabs,
            parallel,
            contacts,
            at,
            rotation,
            displacement,
            displacement,
            np.zeros((contacts.depth.shape[0], 3)),
        )
        sweeps += more
        if more <= 1 and change <= settings.tolerance:
            break
    return displacement, contacts, sweeps, change


# The steps' one signature (module docstring): the flags one by one, as in ``passes`` and
# ``velocity_step`` — not a tuple of them, for Numba prunes only on an argument typed None.
@njit(cache=True)
def projection_step(
    model: LoopModel,
    settings: LoopSettings,
    plan: tuple,
    large: bool | None,
    keeping: bool | None,
    slabs: bool | None,
    parallel: bool | None,
    motion: Motion,
    start: tuple,
    carried: tuple,
) -> tuple:
    """One step of loop L2 with projection (``projection.step``, stage for stage).

    ``start``, ``carried``, ``plan`` and the flags as for ``velocity_step`` (the carried values:
    last step's first-pass λ (K, 3) [kg m]). Returns (positions, velocities — the state's six
    arrays, new —, the carried triple for the next step, the last pass's ContactArrays, sweeps
    made in every pass, the last pass's last correction [m])."""
    h = settings.dt
    rotation, centers, rots = start
    # 1. internal forces → free velocities v*
    free = free_motion(model, motion, rotation, h)
    # 2. predict: the step's displacement u = h v*, and how far each body and particle sweeps
    v_free = stacked(free[0], free[1], free[2])
    predicted = h * v_free
    reach = swept_reach(model, free[0], free[1], free[2], h, settings.margin)
    # 3. collision detection over the swept step, at its start
    contacts, manifolds, near = detect(
        model, plan, large, keeping, motion, centers, rots, reach, carried[0], settings.manifold_tolerance
    )
    # 4. project the colliding points onto the surfaces, warm started by contact id
    warm = settings.warm_start * values_carried(carried[1], carried[2], contacts.feature_id)[0]
    displacement, lam, sweeps, change = project(
        model, settings, slabs, parallel, contacts, motion, rotation, np.zeros_like(predicted), predicted, warm
    )
    #    and again at the projected positions
    displacement, last, sweeps, change = passes(
        model,
        settings,
        plan,
        large,
        keeping,
        slabs,
        parallel,
        motion,
        reach,
        carried[0],
        contacts,
        displacement,
        sweeps,
        change,
    )
    # 5. advance dt, velocities from the projected positions
    start_positions = (motion.body_position, motion.body_orientation, motion.particle_position)
    positions, velocities = advance(start_positions, v_free, displacement, predicted, h)
    clear = swept_clear(near, settings.margin)
    return positions, velocities, (manifolds, contacts.feature_id, lam), last, sweeps, change, clear


# ---- penalty (loop L1): the stages of methods.penalty_springs and penalty_implicit ---------

PenaltyLoop = namedtuple(
    "PenaltyLoop",
    (
        "springs",  # methods.penalty_springs.SpringSettings
        "thickness",  # (N,) [m] Model.collider_half_thickness
        "particle_radius",  # (P,) [m]
        "guard",  # LoopSettings of hold_back's sweeps (GUARD_SWEEPS, GUARD_TOLERANCE)
    ),
)
PenaltyLoop.__doc__ = "What a penalty run adds to LoopModel and LoopSettings (``run``'s ``penalty`` flag)."


@njit(cache=True)
def penalty_step(
    model: LoopModel,
    settings: LoopSettings,
    plan: tuple,
    large: bool | None,
    slabs: bool | None,
    parallel: bool | None,
    penalty: PenaltyLoop,
    motion: Motion,
    start: tuple,
    carried: tuple,
) -> tuple:
    """One step of loop L1 with penalty forces (``methods.penalty.step``, stage for stage).

    ``carried`` = (manifolds, never kept here; last step's contact ids (K,); their anchor offsets
    (K, 3) [m]); ``start`` and the flags as ``velocity_step``'s. Returns (positions, velocities — the state's six
    arrays, new —, the carried triple, the ContactArrays, active-set passes, the last linear
    solve's relative residual, the elastic energy at the step's end [J], whether the springs
    went implicit under an explicit integrator, the conjugate-gradient iterations of its solves)."""
    h, B = settings.dt, motion.body_position.shape[0]
    rotation, centers, rots = start
    # 1. collision detection, with the gaps this step's motion could close
    reach = swept_reach(
        model, motion.body_velocity, motion.body_angular_velocity, motion.particle_velocity, h, settings.margin
    )
    contacts, manifolds, _ = detect(model, plan, large, None, motion, centers, rots, reach, carried[0], 0.0)
    rows = build_rows(model, contacts, motion, rotation)
    v = stacked(motion.body_velocity, motion.body_angular_velocity, motion.particle_velocity)
    # 2. collision forces: normal springs k δ and anchor springs carried by contact id (P1, F3)
    springs, sides = contact_springs(model, penalty, contacts, rows, motion, carried)
    forces, elongation = spring_forces(springs, contacts.depth, row_products(rows, v))
    # 3. internal forces (gravity) → free velocities v*
    free = free_motion(model, motion, rotation, h)
    v_free = stacked(free[0], free[1], free[2])
    # 4. integrate velocities: the forces as h M⁻¹ Jᵀ F, or the springs by backward Euler (M1)
    implicit = springs_implicit(penalty.springs, springs, sides[0], sides[1], sides[2], h)
    passes, residual, linear_iterations = 0, 0.0, 0
    if implicit:
        mass = mass_blocks(model.body_mass, model.body_inertia, rotation, model.particle_mass)
        v_new, forces, elongation, passes, residual, linear_iterations = implicit_spring_velocities(
            penalty.springs,
            springs,
            rows,
            contacts.depth,
            v_free,
            mass,
            free_dofs(model.particle_pinned, np.zeros(B, dtype=np.bool_)),
            h,
        )
    else:
        v_new = explicit_velocities(rows, forces, v_free, h)
    # 4b. over the swept step: no contact carried past half its pass-through depth
    v_new = hold_back(model, penalty, slabs, parallel, contacts, rows, motion, v_new, h)
    bodies = v_new[: 6 * B].reshape(B, 6)
    velocities = (bodies[:, :3].copy(), bodies[:, 3:].copy(), v_new[6 * B :].reshape(-1, 3).copy())
    positions = moved(
        motion.body_position,
        motion.body_orientation,
        motion.particle_position,
        velocities[0],
        velocities[1],
        velocities[2],
        np.full(B, h),
        np.full(velocities[2].shape[0], h),
    )
    # 5. advance the anchors of pressed contacts, by contact id
    elongation, offsets, energy = anchors_after(
        springs, rows, contacts.depth, v_new, elongation, not implicit, contacts.tangent1, contacts.tangent2, h
    )
    return (
        positions,
        velocities,
        (manifolds, contacts.feature_id, offsets),
        contacts,
        passes,
        residual,
        energy,
        implicit and penalty.springs.implicit != 3,
        linear_iterations,
    )


@njit(cache=True)
def contact_springs(
    model: LoopModel, penalty: PenaltyLoop, contacts: ContactArrays, rows: ContactRows, motion: Motion, carried: tuple
) -> tuple[ContactSprings, tuple]:
    """Stage 2a: the contacts' springs (``methods.penalty_springs.springs_of``): stiffness by the option
    or by the load each carries, the anchors of last step's contacts by id. Returns (ContactSprings,
    (side A (C,), side B (C,), B + P) as ``penalty.contact_entities``)."""
    B, P = motion.body_position.shape[0], motion.particle_position.shape[0]
    side_a = entities_of(contacts.body_a, contacts.particles_a, B)
    side_b = entities_of(contacts.body_b, contacts.particles_b, B)
    stiffness = normal_stiffness(
        penalty.springs,
        side_a,
        side_b,
        contacts.normal,
        motion.body_position,
        motion.particle_position,
        model.body_mass,
        model.particle_mass,
        model.gravity,
    )
    offsets = values_carried(carried[1], carried[2], contacts.feature_id)[0]
    springs = springs_of(penalty.springs, stiffness, rows.k[:, :3], contacts, offsets)
    return springs, (side_a, side_b, B + P)


# Where friction stands among a ContactArrays' fields: ``hold_back`` copies the others around it
# (two constants, as Numba slices a tuple only by constants, not by a sum of them).
_FRICTION = ContactArrays._fields.index("friction")
_AFTER_FRICTION = _FRICTION + 1


@njit(cache=True)
def hold_back(
    model: LoopModel,
    penalty: PenaltyLoop,
    slabs: bool | None,
    parallel: bool | None,
    contacts: ContactArrays,
    rows: ContactRows,
    motion: Motion,
    velocity: np.ndarray,
    h: float,
) -> np.ndarray:
    """Stage 4b (``methods.penalty.hold_back``): ``velocity`` (N,), or where it would carry a
    contact past half its pass-through depth, a copy held back by frictionless sweeps
    (``solve`` with the guard's settings) to v_n ≥ −(D/2 − δ) / h."""
    C = contacts.depth.shape[0]
    pass_through = half_thickness_sums(
        contacts.feature_id,
        contacts.particles_a,
        penalty.thickness,
        penalty.particle_radius,
        motion.body_position.shape[0] + motion.particle_position.shape[0],
    )
    slowest, below = slowest_approach(rows, velocity, contacts.depth, pass_through, h)
    if not below:
        return velocity
    held = velocity.copy()
    frictionless = ContactArrays(*contacts[:_FRICTION], np.zeros(C), *contacts[_AFTER_FRICTION:])
    solve(
        penalty.guard,
        slabs,
        parallel,
        rows,
        frictionless,
        motion,
        held,
        slowest,
        np.zeros((C, 3)),
        contact_order(contacts.point, contacts.feature_id, model.gravity),
    )
    return held
