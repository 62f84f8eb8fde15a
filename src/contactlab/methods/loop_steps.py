"""Each method's compiled step, the one ``run_steps`` (:mod:`contactlab.methods.velocity_loop`) calls:
impulse and constraints (``velocity_step``, loop L3), projection (``projection_step``, loop L2)
and penalty (``penalty_step``, loop L1).

Each compiles stages 1–3 (free motion, how far each collider sweeps, detection with kept
manifolds: ``integrators.free_flight``, ``collision.swept_reach`` and ``collision.detect``, inlined)
and calls for the rest the compiled stages its method's step from Python calls too, each written
once: ``velocity_level.respond`` (stages 4–5 of L3), ``projection.project`` and ``passes`` (stage
4 of L2 and the further detect-and-project passes), and ``penalty.springs_at``,
``integrate_velocities`` and ``finish`` (stages 2, 4 and 4b–5 of L1). The step from Python runs
the same stages 1–3 for every scene (cloth springs, meshes, every integrator), and this loop runs
the rigid ones (a driven scene's loads and paths are ``driving.drive_velocities`` in both);
``tests/test_velocity_loop.py`` checks that the two paths give the same numbers, bit for bit. The
three steps share one module because they share one signature, ``(model, drive, settings, spec,
motion, start, time, carried)`` (``drive``: the scene's DriveTable or None, ``driving.table_of``,
which only free motion reads), and one result, ``(positions, velocities, carried, contacts, sweeps,
change, clear, elastic energy, implicit, linear iterations)`` (a method without a value gives 0 or
False): ``run_steps`` calls whichever its run has without a branch. What each is compiled for is
one value, the run's Specialization.
"""

from __future__ import annotations

import numpy as np

from ..compiling import njit
from ..contacts import values_carried
from ..driving import DriveTable
from ..dynamics.generalized import stacked
from .loop_stages import (
    LoopModel,
    LoopSettings,
    Motion,
    Specialization,
    build_rows,
    detect,
    for_response,
    free_motion,
    moved,
    swept_clear,
    swept_reach,
)
from .penalty import finish, integrate_velocities, springs_at
from .penalty_springs import ImplicitSprings
from .projection import advance, passes, project
from .velocity_level import respond

# ---- impulse and constraints (loop L3) ------------------------------------------------------


@njit(cache=True)
def velocity_step(
    model: LoopModel,
    drive: DriveTable | None,
    settings: LoopSettings,
    spec: Specialization,
    motion: Motion,
    start: tuple,
    time: float,
    carried: tuple,
) -> tuple:
    """One step of loop L3 with impulses or hard constraints on velocities (``spec``'s
    ``impulse`` or ``constraints``).

    ``start`` = the poses at the step's start: the bodies' rotations (B, 3, 3), the colliders'
    centres (N, 3) and rotations (N, 3, 3) (``poses``; ``run_steps`` computes them once for the sample
    before and this step); ``time`` = the step's start [s] (a driven scene's loads and paths);
    ``carried`` = (the kept manifolds' eight fields, last step's contact ids (K,), their impulses
    (K, 3)). Returns the steps' one result (module docstring): the sweeps made and their last
    change [m/s]."""
    h = settings.dt
    rotation, centers, rots = start
    # 1. internal forces → free velocities v*
    free = free_motion(model, drive, motion, rotation, h, time)
    # 2. predict: how far each body and particle sweeps this step
    reach = swept_reach(model.colliders.radius, free[0], free[1], free[2], h, settings.margin)
    # 3. collision detection over the swept step
    contacts, manifolds, near = detect(
        model.colliders, spec.plan, spec.keeping, (centers, rots), reach, carried[0], settings.manifold_tolerance, None
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
        return positions, free, (manifolds, carried[1][:0], carried[2][:0]), 0, 0, 0.0, clear, 0.0, False, 0
    # 4–5. the contact rows, their targets and the solve; positions split at the time of impact
    positions, velocities, impulses, sweeps, change = respond(
        model, settings, spec, contacts, motion, rotation, (free, free), (carried[1], carried[2])
    )
    count = contacts.depth.shape[0]
    return (
        positions,
        velocities,
        (manifolds, contacts.feature_id, impulses),
        count,
        sweeps,
        change,
        False,
        0.0,
        False,
        0,
    )


# ---- projection (loop L2) ---------------------------------------------------------------


@njit(cache=True)
def projection_step(
    model: LoopModel,
    drive: DriveTable | None,
    settings: LoopSettings,
    spec: Specialization,
    motion: Motion,
    start: tuple,
    time: float,
    carried: tuple,
) -> tuple:
    """One step of loop L2 with projection (``projection.step``, stage for stage).

    ``start`` and ``carried`` as for ``velocity_step`` (the carried values: last step's first-pass
    λ (K, 3) [kg m]). Returns the steps' one result: the last pass's contact count, sweeps made in
    every pass, the last pass's last correction [m]."""
    h = settings.dt
    rotation, centers, rots = start
    # 1. internal forces → free velocities v*
    free = free_motion(model, drive, motion, rotation, h, time)
    # 2. predict: the step's displacement u = h v*, and how far each body and particle sweeps
    v_free = stacked(free[0], free[1], free[2])
    predicted = h * v_free
    reach = swept_reach(model.colliders.radius, free[0], free[1], free[2], h, settings.margin)
    # 3. collision detection over the swept step, at its start
    contacts, manifolds, near = detect(
        model.colliders, spec.plan, spec.keeping, (centers, rots), reach, carried[0], settings.manifold_tolerance, None
    )
    # 4. project the colliding points onto the surfaces, warm started by contact id
    warm = settings.warm_start * values_carried(carried[1], carried[2], contacts.feature_id)[0]
    displacement, lam, sweeps, change = project(
        model, settings, for_response(spec), contacts, motion, rotation, (np.zeros_like(predicted), predicted), warm
    )
    #    and again at the projected positions
    displacement, last, sweeps, change, _ = passes(
        model, settings, spec, motion, (reach, carried[0]), contacts, (displacement, sweeps, change, lam)
    )
    # 5. advance dt, velocities from the projected positions
    start_positions = (motion.body_position, motion.body_orientation, motion.particle_position)
    positions, velocities = advance(start_positions, v_free, displacement, predicted, h)
    clear = swept_clear(near, settings.margin)
    count = last.depth.shape[0]
    return positions, velocities, (manifolds, contacts.feature_id, lam), count, sweeps, change, clear, 0.0, False, 0


# ---- penalty (loop L1): the stages of methods.penalty_springs and penalty_implicit ---------


@njit(cache=True)
def penalty_step(
    model: LoopModel,
    drive: DriveTable | None,
    settings: LoopSettings,
    spec: Specialization,
    motion: Motion,
    start: tuple,
    time: float,
    carried: tuple,
) -> tuple:
    """One step of loop L1 with penalty forces (``spec.penalty``, a PenaltyLoop): detection and the
    free velocities compiled here, the springs, their integration, the guard and the anchors the
    stages of :mod:`contactlab.methods.penalty` that its ``step`` from Python calls too.

    ``carried`` = (manifolds, never kept here; last step's contact ids (K,); their anchor offsets
    (K, 3) [m]); ``settings`` the guard's (``penalty.penalty_loop``); ``start`` as
    ``velocity_step``'s. Returns the steps' one result: active-set passes, the last linear solve's
    relative residual, the elastic energy at the step's end [J], whether the springs went implicit
    under an explicit integrator, the conjugate-gradient iterations of its solves."""
    h = settings.dt
    penalty = spec.penalty
    rotation, centers, rots = start
    # 1. collision detection, with the gaps this step's motion could close
    reach = swept_reach(
        model.colliders.radius,
        motion.body_velocity,
        motion.body_angular_velocity,
        motion.particle_velocity,
        h,
        settings.margin,
    )
    contacts, manifolds, _ = detect(
        model.colliders, spec.plan, spec.keeping, (centers, rots), reach, carried[0], 0.0, None
    )
    rows = build_rows(model, contacts, motion, rotation)
    # 2. collision forces: normal springs k δ and anchor springs carried by contact id (P1, F3)
    v = stacked(motion.body_velocity, motion.body_angular_velocity, motion.particle_velocity)
    springs, forces, elongation, implicit = springs_at(
        model, penalty, contacts, rows, motion, v, (carried[1], carried[2]), h
    )
    # 3. internal forces (gravity) → free velocities v*
    free = free_motion(model, drive, motion, rotation, h, time)
    v_free = stacked(free[0], free[1], free[2])
    # 4. integrate velocities: the forces as h M⁻¹ Jᵀ F, or the springs by backward Euler (M1)
    v_new, forces, elongation, active_passes, residual, linear_iterations = integrate_velocities(
        model, penalty, contacts, rows, rotation, (springs, forces, elongation, implicit), v_free, h
    )
    # 4b–5. no contact carried past half its pass-through depth; positions; the anchors go on
    positions, velocities, offsets, energy = finish(
        model, settings, for_response(spec), contacts, rows, motion, (v, v_new), (springs, elongation, implicit)
    )
    return (
        positions,
        velocities,
        (manifolds, contacts.feature_id, offsets),
        contacts.depth.shape[0],
        active_passes,
        residual,
        np.bool_(False),
        energy,
        implicit and penalty.springs.implicit != ImplicitSprings.BY_INTEGRATOR,
        linear_iterations,
    )
