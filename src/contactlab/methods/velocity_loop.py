"""The compiled stepping loop: impulse and constraints (L3), projection (L2) and penalty (L1).

``simulate`` hands this loop the model's and the state's arrays and a number of steps; every
stage of every step — free motion, prediction, broad and narrow phase with kept manifolds,
contact rows, the collision waves or the impact targets, the warm-started sweeps, the split
at the time of impact; for projection the sweeps on displacements and the further
detect-and-project passes at the projected positions — and the recording of samples run in
compiled code, with no Python between steps. The stages are the ones
:mod:`contactlab.methods.impulse`, :mod:`contactlab.methods.constraints` and
:mod:`contactlab.methods.projection` name, and the same compiled functions serve both paths, so
the loop gives what their ``step`` gives (``tests/test_velocity_loop.py`` holds them equal).
A method's step is compiled only for the runs of that method (``compile_flags``).

Penalty (``penalty_step``, loop L1) runs in the same loop behind ``run``'s ``penalty`` flag:
detection at the step's start with the gaps its motion could close, the contact springs (the
stiffness of each contact from the load it carries, anchors carried by contact id), their
forces, the free velocities, the springs integrated explicitly (h M⁻¹ Jᵀ F through the rows)
or by backward Euler (matrix-free conjugate gradients on the rows), the guard that holds a
contact short of passing through, and the anchors moved on — the compiled stages of
:mod:`contactlab.methods.penalty`, which its ``step`` calls one by one.

It serves the scenes it can (``applies``): rigid bodies and free particles of the primitive and
convex shapes against planes and convex obstacles, the default contact granularity and normal
(vertex, object), symplectic or backward Euler (the same motion without cloth), for
constraints the matrix-free solver on velocities and for penalty the "cg" linear solver. A scene
with cloth or meshes, another
granularity, explicit Euler, or an assembled solver steps through the methods' ``step``, and
so does a driven scene (external forces or kinematic bodies, contactlab.driving): a force or path
given as a Python function cannot run in compiled code.

Arrays, as in the rest of contactlab: B bodies, P particles, O obstacles, N = B + P + O
colliders, C contacts; the generalized velocity u (6B + 3P,) in the DOF layout of
contactlab.contacts.
"""

from collections import namedtuple

import numpy as np
from numba import njit

from .. import rotations, shapes
from ..collision import assemble_contacts, candidate_pairs, collider_poses, half_thickness_sums
from ..collision.broad_phase import GRID_FROM
from ..collision.manifolds import Manifolds, reuse_or_generate
from ..collision.narrow_phase import FAMILIES, MAX_PER_PAIR, generate_contacts, needs_hulls
from ..contacts import ContactArrays, values_carried
from ..diagnostics import gravitational, kinetic
from ..dynamics.generalized import stacked, unstacked
from ..dynamics.integrators import gyroscopic_midpoint, moved
from ..state import State
from .impulse import resolve_collisions
from .penalty import (
    GUARD_SWEEPS,
    GUARD_TOLERANCE,
    anchors_after,
    entities_of,
    explicit_velocities,
    free_dofs,
    implicit_spring_velocities,
    mass_blocks,
    normal_stiffness,
    slowest_approach,
    spring_forces,
    spring_settings,
    springs_implicit,
    springs_of,
)
from .projection import advance, displaced, projection_targets
from .sequential import (
    PARALLEL_MIN_CONTACTS,
    SWEEP_GROUPS,
    contact_order,
    contact_rows,
    row_products,
    solve_sequential_impulses,
    split_into_slabs,
)
from .velocity_level import (
    earliest_impacts,
    gravity_along_normals,
    impact_targets,
    resting_targets,
    restitution_threshold,
)

LoopModel = namedtuple(
    "LoopModel",
    (
        "gravity",  # (3,) m/s²
        "body_inverse_mass",  # (B,) 1/kg
        "body_inertia",  # (B, 3) principal moments, kg m²
        "body_inverse_inertia",  # (B, 3) 1/(kg m²)
        "body_mass",  # (B,) kg
        "particle_mass",  # (P,) kg
        "particle_inverse_mass",  # (P,) 1/kg, 0 pinned
        "particle_pinned",  # (P,) bool
        "kinds",
        "params",  # (N,) int64, (N, 4): the colliders (Model.collider_table)
        "radius",  # (N,) bounding radii [m]
        "materials",  # (N,) int
        "obstacle_position",  # (O, 3) m
        "obstacle_rotation",  # (O, 3, 3)
        "material_friction",  # (M,)
        "material_restitution",  # (M,)
        "cloth_of",  # (B + P,) int, −1: no cloth (always, here)
    ),
)
LoopModel.__doc__ = "The model's arrays the loop reads (writable copies: Numba types read-only arrays apart)."

LoopSettings = namedtuple(
    "LoopSettings",
    (
        "dt",
        "iterations",
        "tolerance",
        "threshold",
        "stabilization",
        "slop",
        "max_push_velocity",
        "time_of_impact",
        "warm_start",
        "margin",
        "manifold_tolerance",
        "passes",
    ),
)
LoopSettings.__doc__ = """A method's Options as plain numbers: dt [s], sweeps, tolerance
([m/s]; projection: [m]), restitution threshold [m/s] (resolved), stabilization, slop [m], max push [m/s],
time of impact (bool), warm-start fraction, contact margin [m], manifold tolerance [m] (0: nothing kept),
detect-and-project passes. What a method's Options lack is 0 (False, 1 pass): see ``loop_settings``."""

Motion = namedtuple(
    "Motion",
    (
        "body_position",
        "body_orientation",
        "body_velocity",
        "body_angular_velocity",
        "particle_position",
        "particle_velocity",
    ),
)
Motion.__doc__ = "The state's six arrays, (B, 3), (B, 4), (B, 3), (B, 3), (P, 3), (P, 3), changed in place."

Samples = namedtuple(
    "Samples",
    (
        "time",
        "body_position",
        "body_orientation",
        "body_velocity",
        "body_angular_velocity",
        "particle_position",
        "particle_velocity",
        "energy_kinetic",
        "energy_potential",
        "energy_elastic",
        "max_penetration",
        "contact_count",
        "solver_iterations",
        "solver_residual",
    ),
)
Samples.__doc__ = "Preallocated recording arrays, one row per sample: the series of contactlab.record.SERIES."


METHODS = ("projection", "impulse", "constraints", "penalty")  # the methods the loop steps


def applies(model, method, options, integrator):
    """Whether this loop can step ``model`` under ``method`` ("projection", "impulse" or
    "constraints") with these Options and integrator (see the module docstring for what it serves)."""
    if method not in METHODS or integrator not in ("symplectic_euler", "backward_euler"):
        return False
    if model.spring_count or len(model.triangles) or (model.obstacle_shape == shapes.MESH).any():
        return False
    if model.drive is not None:  # external forces or kinematic paths: the methods' step applies them
        return False
    if options.granularity != "vertex" or options.normal != "object":
        return False
    if method == "penalty":
        return options.linear_solver == "cg"
    return method != "constraints" or (options.solver == "matrix_free" and options.formulation == "velocity")


# ---- the stages of one step (loop L3) ------------------------------------------------------


@njit(cache=True)
def free_motion(model, motion, rotation, h):
    """Stage 1: velocities after h [s] under gravity alone, v* = v + h g (the gyroscopic term by the
    midpoint rule; pinned particles held): (body (B, 3), angular (B, 3), particle (P, 3))."""
    body = motion.body_velocity + h * model.gravity
    angular = gyroscopic_midpoint(rotation, model.body_inertia, motion.body_angular_velocity, h, 4)
    particle = motion.particle_velocity + h * model.gravity
    for p in range(particle.shape[0]):
        if model.particle_pinned[p]:
            particle[p, 0] = particle[p, 1] = particle[p, 2] = 0.0
    return body, angular, particle


@njit(cache=True)
def swept_reach(model, body_velocity, angular_velocity, particle_velocity, h, margin):
    """Stage 2: how far each collider reaches this step (N,) [m]: half the contact margin, plus
    for a dynamic one the distance it sweeps, h |v| (+ h |ω| r for a body's farthest point)."""
    B, P = body_velocity.shape[0], particle_velocity.shape[0]
    reach = np.full(model.kinds.shape[0], 0.5 * margin)
    for b in range(B):
        reach[b] += h * (_norm(body_velocity[b]) + _norm(angular_velocity[b]) * model.radius[b])
    for p in range(P):
        reach[B + p] += h * _norm(particle_velocity[p])
    return reach


@njit(cache=True, inline="always")
def _norm(v):
    return np.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])


@njit(cache=True)
def detect(model, plan, large, keeping, motion, rotation, reach, kept, tolerance):
    """Stage 3: the contacts at the step's start within ``reach`` (speculative contacts), box,
    hull and plane pairs that barely moved reusing the ``kept`` manifolds (Manifolds' eight fields)
    when ``tolerance`` [m] > 0. ``plan`` = (families, hull store) of the narrow phase; ``large``
    and ``keeping`` None: never a grid broad phase, never a kept manifold (see ``Stepper``).
    Returns (ContactArrays, the manifolds to keep)."""
    families, hull_store = plan
    B, P = motion.body_position.shape[0], motion.particle_position.shape[0]
    centers, rots = collider_poses(
        motion.body_position, rotation, motion.particle_position, model.obstacle_position, model.obstacle_rotation
    )
    _, _, pairs = candidate_pairs(model.kinds, model.params, centers, rots, reach, B + P, model.cloth_of, large)
    total = model.kinds.shape[0]
    made = (kept[0][:0], kept[1][:0], kept[2][:0], kept[3][:0], kept[4][:0], kept[5][:0], kept[6][:0], kept[7][:0])
    if keeping is None:  # no pair keeps a manifold (reuse_or_generate would find none)
        found = generate_contacts(
            pairs,
            model.kinds,
            model.params,
            centers,
            rots,
            reach[pairs[:, 0]] + reach[pairs[:, 1]],
            hull_store,
            families,
        )
    elif tolerance > 0.0:
        found, made = reuse_or_generate(
            pairs,
            model.kinds,
            model.params,
            centers,
            rots,
            reach,
            model.radius,
            hull_store,
            families,
            kept,
            tolerance,
            total,
        )
    else:
        found = generate_contacts(
            pairs,
            model.kinds,
            model.params,
            centers,
            rots,
            reach[pairs[:, 0]] + reach[pairs[:, 1]],
            hull_store,
            families,
        )
    point, normal, depth, feature, owner = found
    contacts = assemble_contacts(
        pairs[owner, 0],
        pairs[owner, 1],
        point,
        normal,
        depth,
        feature,
        B,
        P,
        model.materials,
        model.material_friction,
        model.material_restitution,
        total,
    )
    return contacts, made


@njit(cache=True)
def build_rows(model, contacts, motion, rotation):
    """Stage 4a: the contacts' rows of J (a ContactRows) at the step's start."""
    inverse_inertia = rotations.world_tensors(rotation, model.body_inverse_inertia)
    return contact_rows(
        contacts.body_a,
        contacts.body_b,
        contacts.particles_a,
        contacts.particles_b,
        contacts.weights_a,
        contacts.weights_b,
        contacts.point,
        motion.body_position,
        contacts.normal,
        contacts.tangent1,
        contacts.tangent2,
        model.body_inverse_mass,
        inverse_inertia,
        model.particle_inverse_mass,
    )


@njit(cache=True)
def solve(settings, slabs, parallel, rows, contacts, motion, u, target, warm, order):
    """Stage 4c: the warm-started sweeps of sequential impulses on u (changed in place), the
    contacts grouped for threads as ``sequential.sweep_groups`` does (``slabs`` None: never
    PARALLEL_MIN_CONTACTS contacts, never grouped); ``parallel`` None compiles no parallel sweep
    (the groups are then swept one after the other: the same numbers). Returns (impulses (C, 3)
    [N s], sweeps, last change [m/s])."""
    C = order.shape[0]
    grouped, starts = order, np.array([0, C, C])
    if slabs is None:
        return solve_sequential_impulses(
            rows, contacts.friction, target, u, settings.iterations, settings.tolerance, warm, grouped, None
        )
    if C >= PARALLEL_MIN_CONTACTS:
        grouped, starts = split_into_slabs(
            order,
            contacts.point,
            rows.body,
            rows.particle,
            motion.body_position,
            rows.body_inverse_mass,
            motion.particle_position,
            rows.particle_inverse_mass,
            SWEEP_GROUPS,
        )
    if parallel is None:
        return solve_sequential_impulses(
            rows, contacts.friction, target, u, settings.iterations, settings.tolerance, warm, grouped, None
        )
    return solve_sequential_impulses(
        rows, contacts.friction, target, u, settings.iterations, settings.tolerance, warm, grouped, starts
    )


@njit(cache=True)
def split_at_impact(model, contacts, motion, tau, move, solved, h, time_of_impact):
    """Stage 5: positions x₀ + h(τ v* + (1 − τ) v⁺) per body and particle, τ its earliest
    impact (``velocity_level.positions_split_at_impact``; no split unless ``time_of_impact``)."""
    B, P = motion.body_position.shape[0], motion.particle_position.shape[0]
    if not time_of_impact:
        tau = np.full(tau.shape[0], -1.0)
    tau_body, tau_particle = earliest_impacts(
        contacts.body_a, contacts.body_b, contacts.particles_a, contacts.particles_b, tau, B, P
    )
    after = (solved[: 6 * B].reshape(B, 6), solved[6 * B :].reshape(P, 3))
    corrected_body = move[0] + (after[0][:, :3] - move[0])
    corrected_angular = move[1] + (after[0][:, 3:] - move[1])
    corrected_particle = move[2] + (after[1] - move[2])
    mid = moved(
        motion.body_position,
        motion.body_orientation,
        motion.particle_position,
        move[0],
        move[1],
        move[2],
        tau_body * h,
        tau_particle * h,
    )
    return moved(
        mid[0],
        mid[1],
        mid[2],
        corrected_body,
        corrected_angular,
        corrected_particle,
        (1 - tau_body) * h,
        (1 - tau_particle) * h,
    )


@njit(cache=True)
def targets(model, settings, impulse, contacts, rows, u, order):
    """Stage 4b: each normal row's target velocity (C,) [m/s] and time of impact τ (C,) (−1:
    none). Impulse: the collision waves (``impulse.resolve_collisions``) change u, then every
    contact rests (``resting_target``); constraints: all impacts at once (``normal_targets``).
    ``impulse``: True for the impulse method, None for constraints (the other is not compiled)."""
    h = settings.dt
    gap_at_start = -contacts.depth
    gravity_normal = gravity_along_normals(
        contacts.body_a, contacts.body_b, contacts.particles_a, contacts.particles_b, contacts.normal, model.gravity
    )
    if impulse is not None:
        tau = np.empty(gap_at_start.shape[0])
        resolve_collisions(
            rows,
            contacts.friction,
            contacts.restitution,
            gravity_normal,
            gap_at_start,
            h,
            settings.threshold,
            u,
            settings.iterations,
            settings.iterations,
            settings.tolerance,
            tau,
            order,
        )
        return resting_targets(gap_at_start, h, settings.stabilization, settings.slop, settings.max_push_velocity), tau
    normal_velocity = row_products(rows, u)[:, 0]
    return impact_targets(
        gap_at_start,
        normal_velocity,
        gravity_normal,
        contacts.restitution,
        h,
        settings.threshold,
        settings.stabilization,
        settings.slop,
        settings.max_push_velocity,
    )


@njit(cache=True)
def velocity_step(model, settings, plan, large, keeping, impulse, slabs, parallel, motion, carried):
    """One step of loop L3 with impulses or hard constraints on velocities.

    ``carried`` = (the kept manifolds' eight fields, last step's contact ids (K,), their impulses
    (K, 3)); ``plan`` and the flags ``large``, ``keeping``, ``impulse``, ``slabs`` and ``parallel`` (True,
    or None to leave a stage's branch uncompiled) as ``Stepper`` sets them. Returns (positions, velocities — the
    state's six arrays, new —, the carried triple
    for the next step, the ContactArrays, sweeps made, the sweeps' last change [m/s])."""
    h = settings.dt
    rotation = rotations.matrices(motion.body_orientation)
    # 1. internal forces → free velocities v*
    free = free_motion(model, motion, rotation, h)
    # 2. predict: how far each body and particle sweeps this step
    reach = swept_reach(model, free[0], free[1], free[2], h, settings.margin)
    # 3. collision detection over the swept step
    contacts, manifolds = detect(
        model, plan, large, keeping, motion, rotation, reach, carried[0], settings.manifold_tolerance
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
        return positions, free, (manifolds, carried[1][:0], carried[2][:0]), contacts, 0, 0.0
    # 4. formulate the contact rows, their targets (collisions first, for impulses), and solve
    rows = build_rows(model, contacts, motion, rotation)
    u = stacked(free[0], free[1], free[2])
    order = contact_order(contacts.point, contacts.feature_id, model.gravity)
    target, tau = targets(model, settings, impulse, contacts, rows, u, order)
    warm = settings.warm_start * values_carried(carried[1], carried[2], contacts.feature_id)[0]
    impulses, sweeps, change = solve(settings, slabs, parallel, rows, contacts, motion, u, target, warm, order)
    # 5. recompute positions from the corrected velocities, split at the time of impact
    positions = split_at_impact(model, contacts, motion, tau, free, u, h, settings.time_of_impact)
    velocities = unstacked(u, free[0].shape[0])
    return positions, velocities, (manifolds, contacts.feature_id, impulses), contacts, sweeps, change


# ---- the stages of a projection step (loop L2) that the velocity methods do not take ---------


@njit(cache=True)
def project(model, settings, slabs, parallel, contacts, at, rotation, offset, displacement, warm):
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
def displaced_motion(motion, displacement, h):
    """The Motion at the positions a generalized displacement (N,) [m, rad] reaches from
    ``motion``'s over h [s] (``projection.displaced``; its velocities are ``motion``'s)."""
    position, orientation, particle = displaced(
        motion.body_position, motion.body_orientation, motion.particle_position, displacement, h
    )
    return Motion(
        position, orientation, motion.body_velocity, motion.body_angular_velocity, particle, motion.particle_velocity
    )


@njit(cache=True)
def passes(
    model, settings, plan, large, keeping, slabs, parallel, motion, reach, kept, contacts, displacement, sweeps, change
):
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
        rotation = rotations.matrices(at.body_orientation)
        contacts, _ = detect(model, plan, large, keeping, at, rotation, reach, kept, 0.0)
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


@njit(cache=True)
def projection_step(model, settings, plan, large, keeping, slabs, parallel, motion, carried):
    """One step of loop L2 with projection (``projection.step``, stage for stage).

    ``carried``, ``plan`` and the flags as for ``velocity_step`` (the carried values: last step's
    first-pass λ (K, 3) [kg m]). Returns (positions, velocities — the state's six arrays, new —,
    the carried triple for the next step, the last pass's ContactArrays, sweeps made in every
    pass, the last pass's last correction [m])."""
    h = settings.dt
    rotation = rotations.matrices(motion.body_orientation)
    # 1. internal forces → free velocities v*
    free = free_motion(model, motion, rotation, h)
    # 2. predict: the step's displacement u = h v*, and how far each body and particle sweeps
    v_free = stacked(free[0], free[1], free[2])
    predicted = h * v_free
    reach = swept_reach(model, free[0], free[1], free[2], h, settings.margin)
    # 3. collision detection over the swept step, at its start
    contacts, manifolds = detect(
        model, plan, large, keeping, motion, rotation, reach, carried[0], settings.manifold_tolerance
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
    positions, velocities = advance(
        motion.body_position, motion.body_orientation, motion.particle_position, v_free, displacement, predicted, h
    )
    return positions, velocities, (manifolds, contacts.feature_id, lam), last, sweeps, change


@njit(cache=True)
def run(
    model,
    settings,
    plan,
    large,
    keeping,
    velocity,
    impulse,
    projection,
    slabs,
    parallel,
    penalty,
    motion,
    carried,
    time,
    steps,
    first_index,
    last_index,
    record_every,
    samples,
    max_speed,
):
    """``steps`` steps of ``velocity_step`` (``velocity`` True), ``projection_step``
    (``projection`` True) or ``penalty_step`` (``penalty`` a PenaltyLoop) — exactly one of the
    three flags is not None, and the steps whose flag is None are not compiled — from the state
    ``motion`` at ``time`` [s] (changed in place), numbered from ``first_index``; after step i, a
    sample into ``samples`` (row after row) where i is a multiple of ``record_every`` or
    ``last_index``. Stops early after a step that leaves a non-finite value or a speed above
    ``max_speed`` [m/s]. Returns (steps made, whether it stopped so, carried, time, samples
    written, most contacts, sweeps made, steps whose contact springs went implicit)."""
    written = 0
    most = 0
    sweeps_made = 0
    implicit_steps = 0
    for s in range(steps):
        index = first_index + s
        elastic, implicit = 0.0, False
        # separate ifs, not if-else: Numba drops a branch only where its flag is None (as an
        # argument typed None), and exactly one flag is not None (compile_flags)
        if projection is not None:
            positions, velocities, carried, contacts, sweeps, change = projection_step(
                model, settings, plan, large, keeping, slabs, parallel, motion, carried
            )
        if velocity is not None:
            positions, velocities, carried, contacts, sweeps, change = velocity_step(
                model, settings, plan, large, keeping, impulse, slabs, parallel, motion, carried
            )
        if penalty is not None:
            positions, velocities, carried, contacts, sweeps, change, elastic, implicit = penalty_step(
                model, settings, plan, large, slabs, parallel, penalty, motion, carried
            )
        _store(motion, positions, velocities)
        time += settings.dt
        count = contacts.depth.shape[0]
        most = max(most, count)
        sweeps_made += sweeps
        implicit_steps += implicit
        if not _healthy(motion, max_speed):
            return s + 1, True, carried, time, written, most, sweeps_made, implicit_steps
        if index % record_every == 0 or index == last_index:
            record(samples, written, model, plan, large, motion, time, count, sweeps, change)
            samples.energy_elastic[written] = elastic
            written += 1
    return steps, False, carried, time, written, most, sweeps_made, implicit_steps


@njit(cache=True)
def _store(motion, positions, velocities):
    """Copy a step's new positions and velocities into the state's arrays."""
    for target, source in (
        (motion.body_position, positions[0]),
        (motion.body_velocity, velocities[0]),
        (motion.body_angular_velocity, velocities[1]),
        (motion.particle_position, positions[2]),
        (motion.particle_velocity, velocities[2]),
    ):
        for n in range(target.shape[0]):
            for i in range(3):
                target[n, i] = source[n, i]
    for b in range(motion.body_orientation.shape[0]):
        for i in range(4):
            motion.body_orientation[b, i] = positions[1][b, i]


@njit(cache=True)
def _healthy(motion, max_speed):
    """Every value finite and no body centre or particle faster than max_speed [m/s]."""
    for array in (
        motion.body_position,
        motion.body_velocity,
        motion.body_angular_velocity,
        motion.particle_position,
        motion.particle_velocity,
    ):
        for n in range(array.shape[0]):
            for i in range(3):
                if not np.isfinite(array[n, i]):
                    return False
    for b in range(motion.body_orientation.shape[0]):
        for i in range(4):
            if not np.isfinite(motion.body_orientation[b, i]):
                return False
    for velocity in (motion.body_velocity, motion.particle_velocity):
        for n in range(velocity.shape[0]):
            if _norm(velocity[n]) > max_speed:
                return False
    return True


@njit(cache=True)
def record(samples, row, model, plan, large, motion, time, contact_count, sweeps, change):
    """Sample ``row``: the state, its energies (``diagnostics``: kinetic, gravitational) and its
    deepest overlap, measured afresh at its own positions (as ``Recorder.sample`` does); the
    step's ``contact_count``, or where it is −1 (no step) that of the fresh pass."""
    samples.time[row] = time
    for target, source in (
        (samples.body_position, motion.body_position),
        (samples.body_velocity, motion.body_velocity),
        (samples.body_angular_velocity, motion.body_angular_velocity),
        (samples.particle_position, motion.particle_position),
        (samples.particle_velocity, motion.particle_velocity),
    ):
        for n in range(source.shape[0]):
            for i in range(3):
                target[row, n, i] = source[n, i]
    for b in range(motion.body_orientation.shape[0]):
        for i in range(4):
            samples.body_orientation[row, b, i] = motion.body_orientation[b, i]
    rotation = rotations.matrices(motion.body_orientation)
    samples.energy_kinetic[row] = kinetic(
        model.body_mass,
        model.body_inertia,
        rotation,
        motion.body_velocity,
        motion.body_angular_velocity,
        model.particle_mass,
        motion.particle_velocity,
    )
    samples.energy_potential[row] = gravitational(
        model.body_mass, motion.body_position, model.particle_mass, motion.particle_position, model.gravity
    )
    samples.energy_elastic[row] = 0.0
    centers, rots = collider_poses(
        motion.body_position, rotation, motion.particle_position, model.obstacle_position, model.obstacle_rotation
    )
    touching = np.zeros(model.kinds.shape[0])
    _, _, pairs = candidate_pairs(
        model.kinds,
        model.params,
        centers,
        rots,
        touching,
        motion.body_position.shape[0] + motion.particle_position.shape[0],
        model.cloth_of,
        large,
    )
    depth = generate_contacts(
        pairs, model.kinds, model.params, centers, rots, np.zeros(pairs.shape[0]), plan[1], plan[0]
    )[2]
    samples.max_penetration[row] = max(0.0, depth.max()) if depth.shape[0] else 0.0
    samples.contact_count[row] = depth.shape[0] if contact_count < 0 else contact_count
    samples.solver_iterations[row] = sweeps
    samples.solver_residual[row] = change


# ---- from Python: the model, the settings and the state in the loop's form, and back --------

# ---- penalty (loop L1): the stages of methods.penalty, compiled into the loop -------------

PenaltyLoop = namedtuple(
    "PenaltyLoop",
    (
        "springs",  # methods.penalty.SpringSettings
        "thickness",  # (N,) [m] Model.collider_half_thickness
        "particle_radius",  # (P,) [m]
        "guard",  # LoopSettings of hold_back's sweeps (GUARD_SWEEPS, GUARD_TOLERANCE)
    ),
)
PenaltyLoop.__doc__ = "What a penalty run adds to LoopModel and LoopSettings (``run``'s ``penalty`` flag)."


@njit(cache=True)
def penalty_step(model, settings, plan, large, slabs, parallel, penalty, motion, carried):
    """One step of loop L1 with penalty forces (``methods.penalty.step``, stage for stage).

    ``carried`` = (manifolds, never kept here; last step's contact ids (K,); their anchor offsets
    (K, 3) [m]); flags as ``velocity_step``'s. Returns (positions, velocities — the state's six
    arrays, new —, the carried triple, the ContactArrays, active-set passes, the last linear
    solve's relative residual, the elastic energy at the step's end [J], whether the springs
    went implicit under an explicit integrator)."""
    h, B = settings.dt, motion.body_position.shape[0]
    rotation = rotations.matrices(motion.body_orientation)
    # 1. collision detection, with the gaps this step's motion could close
    reach = swept_reach(
        model, motion.body_velocity, motion.body_angular_velocity, motion.particle_velocity, h, settings.margin
    )
    contacts, manifolds = detect(model, plan, large, None, motion, rotation, reach, carried[0], 0.0)
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
    passes, residual = 0, 0.0
    if implicit:
        mass = mass_blocks(model.body_mass, model.body_inertia, rotation, model.particle_mass)
        v_new, forces, elongation, passes, residual = implicit_spring_velocities(
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
    )


@njit(cache=True)
def contact_springs(model, penalty, contacts, rows, motion, carried):
    """Stage 2a: the contacts' springs (``methods.penalty.springs_of``): stiffness by the option
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
    springs = springs_of(
        penalty.springs,
        stiffness,
        rows.k[:, :3],
        contacts.restitution,
        contacts.friction,
        offsets,
        contacts.tangent1,
        contacts.tangent2,
    )
    return springs, (side_a, side_b, B + P)


@njit(cache=True)
def hold_back(model, penalty, slabs, parallel, contacts, rows, motion, velocity, h):
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
    frictionless = ContactArrays(
        contacts.body_a,
        contacts.body_b,
        contacts.particles_a,
        contacts.particles_b,
        contacts.weights_a,
        contacts.weights_b,
        contacts.point,
        contacts.normal,
        contacts.depth,
        contacts.tangent1,
        contacts.tangent2,
        np.zeros(C),
        contacts.restitution,
        contacts.feature_id,
    )
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


# ---- from Python: the model, the settings and the state in the loop's form, and back --------

PARALLEL_MIN_COLLIDERS = 100  # fewer bodies and particles: no parallel sweep is compiled in
KEPT_FAMILIES = ("box_box", "box_plane", "convex_convex", "convex_plane")  # pairs that keep manifolds


def compile_flags(model, method, options):
    """(large, keeping, velocity, impulse, projection, slabs, parallel): True, or None where the
    scene can never need that branch of the loop, which Numba then leaves uncompiled (a first
    run compiles a fraction of the loop: a ball on the floor needs neither the grid broad phase,
    nor kept manifolds, nor the slab split; projection not the velocity methods' step, nor they
    projection's) — the numbers are the same either way. large: at least GRID_FROM bodies and
    particles; keeping: a pair family that keeps manifolds and a manifold tolerance > 0;
    velocity, impulse, projection: the method is impulse or constraints, impulse, projection
    (penalty: all three None, its PenaltyLoop the flag after these);
    slabs: PARALLEL_MIN_CONTACTS contacts are possible (MAX_PER_PAIR per pair); parallel:
    several threads and PARALLEL_MIN_COLLIDERS bodies and particles."""
    from ..threads import available_threads

    dynamic, obstacles = model.body_count + model.particle_count, model.obstacle_count
    present = {name for name, flag in zip(FAMILIES, model.pair_families) if flag is not None}
    most_contacts = MAX_PER_PAIR * (dynamic * (dynamic - 1) // 2 + dynamic * obstacles)
    return (
        True if dynamic >= GRID_FROM else None,
        True if getattr(options, "manifold_tolerance", 0.0) > 0.0 and present & set(KEPT_FAMILIES) else None,
        True if method in ("impulse", "constraints") else None,
        True if method == "impulse" else None,
        True if method == "projection" else None,
        True if most_contacts >= PARALLEL_MIN_CONTACTS else None,
        True if available_threads() > 1 and dynamic >= PARALLEL_MIN_COLLIDERS else None,
    )


def loop_model(model):
    """The LoopModel of a Model (writable copies of its arrays; see Model.stepping_arrays)."""
    kinds, params, materials, obstacle_rotation = model.collider_table
    B, P = model.body_count, model.particle_count
    copy = np.array  # np.array copies: a writable, contiguous array
    return LoopModel(
        copy(model.gravity, dtype=float),
        copy(model.body_inverse_mass, dtype=float),
        copy(model.body_inertia, dtype=float),
        copy(model.body_inverse_inertia, dtype=float),
        copy(model.body_mass, dtype=float),
        copy(model.particle_mass, dtype=float),
        copy(model.particle_inverse_mass, dtype=float),
        copy(model.particle_pinned, dtype=np.bool_),
        copy(kinds, dtype=np.int64),
        copy(params, dtype=float),
        copy(shapes.bounding_radii(kinds, params), dtype=float),
        copy(materials, dtype=np.int64),
        copy(model.obstacle_position, dtype=float),
        copy(obstacle_rotation, dtype=float),
        copy(model.material_friction, dtype=float),
        copy(model.material_restitution, dtype=float),
        np.full(B + P, -1, dtype=np.int64),
    )


def loop_settings(model, method, options, dt):
    """The LoopSettings of ``method``'s Options for steps of dt [s], the restitution threshold
    resolved (``restitution_threshold``). Projection has no threshold, stabilization, push limit
    or time of impact (0, False there); the velocity methods make 1 pass."""
    velocity = method != "projection"
    return LoopSettings(
        float(dt),
        int(options.iterations),
        float(options.tolerance),
        float(restitution_threshold(model, dt, options)) if velocity else 0.0,
        float(options.stabilization) if velocity else 0.0,
        float(options.slop),
        float(options.max_push_velocity) if velocity else 0.0,
        bool(options.time_of_impact) if velocity else False,
        float(options.warm_start),
        float(options.contact_margin),
        float(options.manifold_tolerance),
        1 if velocity else int(options.passes),
    )


class Stepper:
    """Steps one run of ``method`` on ``model`` through the compiled loop.

    ``advance(steps, first_index, last_index, record_every)`` makes that many steps from the
    state given at construction and returns the samples it recorded; ``state()`` is the State
    reached, with the warm-start data carried under the same keys as the method's ``step``
    (so a run may go on through either path)."""

    def __init__(self, model, method, options, integrator, dt, state):
        self._start(model, state)
        self.prefix = {"impulse": "impulse_", "constraints": "constraint_", "projection": "projection_"}[method]
        # projection.step carries its λ every step, none included; the velocity methods drop theirs then
        self.carries_empty = method == "projection"
        self.keep_manifolds = options.manifold_tolerance > 0.0
        self.settings = loop_settings(model, method, options, dt)
        self.flags = compile_flags(model, method, options) + (None,)  # penalty: None (PenaltyStepper)
        kept = state.carried.get("manifolds") or Manifolds.empty()
        ids = state.carried.get(self.prefix + "ids")
        values = state.carried.get(self.prefix + "values")
        self.carried = (
            (kept.keys, kept.reach, kept.center, kept.rotation, kept.count, kept.witness, kept.normal, kept.feature),
            np.zeros(0, dtype=np.int64) if ids is None else np.asarray(ids, dtype=np.int64),
            np.zeros((0, 3)) if values is None else np.asarray(values, dtype=float).reshape(-1, 3),
        )
        self.other = {k: v for k, v in state.carried.items() if k != "manifolds" and not k.startswith(self.prefix)}

    def _start(self, model, state):
        """What every Stepper holds: the model, the narrow phase's plan, the state's time and
        arrays (copies), the tallies."""
        self.model = model
        families = model.pair_families
        self.plan = (families, model.hull_store if needs_hulls(families) else None)
        self.time = float(state.time)
        self.motion = Motion(
            *(
                np.array(a, dtype=float)
                for a in (
                    state.body_position,
                    state.body_orientation,
                    state.body_velocity,
                    state.body_angular_velocity,
                    state.particle_position,
                    state.particle_velocity,
                )
            )
        )
        self.max_contacts = 0
        self.sweeps_made = 0
        self.last_contacts = 0
        self.implicit_spring_steps = 0

    def samples_for(self, count):
        """Empty Samples for ``count`` samples."""
        B, P = self.model.body_count, self.model.particle_count
        return Samples(
            np.empty(count),
            np.empty((count, B, 3)),
            np.empty((count, B, 4)),
            np.empty((count, B, 3)),
            np.empty((count, B, 3)),
            np.empty((count, P, 3)),
            np.empty((count, P, 3)),
            np.empty(count),
            np.empty(count),
            np.empty(count),
            np.empty(count),
            np.empty(count, dtype=np.int64),
            np.empty(count, dtype=np.int64),
            np.empty(count),
        )

    def sample(self):
        """The sample of the state as it stands (no step made: its contacts those of the fresh
        collision pass, 0 sweeps), as a dict of
        the series, recorded by the loop's ``record``: what ``Recorder.sample`` records."""
        samples = self.samples_for(1)
        record(samples, 0, self.model.stepping_arrays, self.plan, self.flags[0], self.motion, self.time, -1, 0, 0.0)
        return samples._asdict()

    def advance(self, steps, first_index, last_index, record_every, max_speed):
        """Make ``steps`` steps (numbered from ``first_index``). Returns (steps made, whether the
        state blew up — see ``run`` —, the Samples recorded as a dict of the series)."""
        indices = np.arange(first_index, first_index + steps)
        count = int(np.count_nonzero((indices % record_every == 0) | (indices == last_index)))
        samples = self.samples_for(count)
        made, diverged, self.carried, self.time, written, most, sweeps, implicit = run(
            *self._run_arguments(steps, first_index, last_index, record_every, samples, max_speed)
        )
        self.max_contacts = max(self.max_contacts, most)
        self.sweeps_made += sweeps
        self.implicit_spring_steps += implicit
        return made, diverged, {name: array[:written] for name, array in samples._asdict().items()}

    def _run_arguments(self, steps, first_index, last_index, record_every, samples, max_speed):
        return (
            self.model.stepping_arrays,
            self.settings,
            self.plan,
            *self.flags,
            self.motion,
            self.carried,
            self.time,
            steps,
            first_index,
            last_index,
            record_every,
            samples,
            max_speed,
        )

    def compiled_already(self):
        """Whether ``run`` has machine code for this run's argument types, in memory or in Numba's
        disk cache: stepping through the loop then costs no compilation (see ``stepper_for``)."""
        types = tuple(run.typeof_pyval(a) for a in self._run_arguments(1, 1, 1, 1, self.samples_for(1), 1.0))
        if types in run.overloads:
            return True
        try:  # Numba's cache index, as Dispatcher.compile consults it (internal API: any change → no)
            key = run._cache._index_key(types, run.targetctx.codegen())
            return key in run._cache._cache_file._load_index()
        except Exception:  # noqa: BLE001 — a Numba without this internal layout: assume not cached
            return False

    def state(self):
        """The State reached (copies), with the carried data under the method's keys."""
        made, ids, values = self.carried
        carried = dict(self.other)
        carried["manifolds"] = Manifolds(*made) if self.keep_manifolds else None
        if len(ids) or self.carries_empty:
            carried[self.prefix + "ids"], carried[self.prefix + "values"] = ids, values
        m = self.motion
        return State(
            self.time,
            m.body_position.copy(),
            m.body_orientation.copy(),
            m.body_velocity.copy(),
            m.body_angular_velocity.copy(),
            m.particle_position.copy(),
            m.particle_velocity.copy(),
            carried,
        )


class PenaltyStepper(Stepper):
    """A Stepper of a penalty run (``penalty_step``): its anchors carried under ``penalty.step``'s
    keys (anchor_ids, anchor_offsets), no manifolds kept."""

    def __init__(self, model, options, integrator, dt, state):
        self._start(model, state)
        self.settings = LoopSettings(
            float(dt),
            GUARD_SWEEPS,
            GUARD_TOLERANCE,
            0.0,
            0.0,
            0.0,
            0.0,
            False,
            0.0,
            float(options.contact_margin),
            0.0,
            1,
        )  # hold_back's sweeps
        self.flags = compile_flags(model, "penalty", options) + (
            PenaltyLoop(
                spring_settings(options, integrator),
                np.array(model.collider_half_thickness, dtype=float),
                np.array(model.particle_radius, dtype=float),
                self.settings,
            ),
        )
        ids, offsets = state.carried.get("anchor_ids"), state.carried.get("anchor_offsets")
        self.carried = (
            _no_manifolds(),
            np.zeros(0, dtype=np.int64) if ids is None else np.asarray(ids, np.int64),
            np.zeros((0, 3)) if offsets is None else np.asarray(offsets, dtype=float).reshape(-1, 3),
        )
        self.other = {k: v for k, v in state.carried.items() if k not in ("anchor_ids", "anchor_offsets")}

    def state(self):
        """The State reached (copies), its anchors under the keys ``penalty.step`` carries them by."""
        _, ids, offsets = self.carried
        m = self.motion
        return State(
            self.time,
            m.body_position.copy(),
            m.body_orientation.copy(),
            m.body_velocity.copy(),
            m.body_angular_velocity.copy(),
            m.particle_position.copy(),
            m.particle_velocity.copy(),
            dict(self.other, anchor_ids=ids, anchor_offsets=offsets),
        )


def _no_manifolds():
    """The eight fields of no kept manifold (Manifolds.empty()), the form ``run`` carries them in."""
    kept = Manifolds.empty()
    return (kept.keys, kept.reach, kept.center, kept.rotation, kept.count, kept.witness, kept.normal, kept.feature)


LOOP_COMPILE_SECONDS = 30.0  # s: about what compiling ``run`` costs on an empty cache (2-core machine)
GLUE_SECONDS = (1e-4, 8e-6)  # s a step, and s a body or particle a step: the Python the loop saves


def repays_compiling(model, steps):
    """Whether ``steps`` steps of ``model`` through the methods' ``step`` would spend more time in
    Python glue between kernels (measured: about 0.1 ms a step plus 8 µs a body, see
    benchmarks/profile_methods.py) than compiling the loop costs on an empty cache."""
    per_step = GLUE_SECONDS[0] + GLUE_SECONDS[1] * (model.body_count + model.particle_count)
    return steps * per_step > LOOP_COMPILE_SECONDS


def stepper_for(model, method, options, integrator, dt, state, steps, compiled_loop=None):
    """A Stepper for this run of ``steps`` steps, or None to step through the methods' ``step``.

    None where the loop does not serve the scene (``applies``) or ``compiled_loop`` is False.
    Where ``compiled_loop`` is None (the default), the loop is taken when its machine code is
    already compiled or cached for this scene's types, or when the run is long enough to repay
    compiling it (``repays_compiling``): a first, short run on an empty cache compiles only the
    kernels (seconds) and steps them from Python; both paths give the same numbers bit for bit.
    True: the loop wherever it serves, compiling it if need be."""
    if compiled_loop is False or not applies(model, method, options, integrator):
        return None
    stepper = (
        PenaltyStepper(model, options, integrator, dt, state)
        if method == "penalty"
        else Stepper(model, method, options, integrator, dt, state)
    )
    if compiled_loop or repays_compiling(model, steps) or stepper.compiled_already():
        return stepper
    return None
