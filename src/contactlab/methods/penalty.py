"""Penalty forces (SPEC L1, P1–P5, D1, F3, M1): contacts as stiff springs.

One step is loop L1, stage by stage as on the slide:

1. collision detection at the current positions x (with the gaps this step's motion could
   close, so a spring that engages during the step is known to the implicit solve);
2. collision forces: a normal spring F_n = k δ (P1) — the force of the energy E = ½ k δ²
   (P3), since ∇δ = −n — with optional damping, never attractive; and Coulomb friction by an
   anchor spring (F3): on first contact an anchor is placed at the point, a tangential spring
   pulls the point back to it, and when that spring would pull harder than μ F_n the anchor
   is dragged along to the distance at which it pulls exactly μ F_n (slip);
3. internal forces: gravity (cloth springs join here);
4. integrate velocities and positions: the contact forces reach the degrees of freedom
   through the Jacobian, f = Jᵀ F_p (D1) — particles, rigid bodies (force and torque) and
   barycentric points alike — with symplectic or explicit Euler, or with backward Euler,
   which solves (M + h (h K + D)) v⁺ = M v* + h Jᵀ F₀ for the springs linearized at x
   (stiffness K = k JᵀJ, damping D = c JᵀJ; M1);
5. advance time; the anchors are carried to the next step by persistent contact id.

Granularity (P2) and the choice of normal (P4/P5) are options of collision detection.

The anchor of a contact is stored as its elongation s = point − anchor, a world vector in the
tangent plane that moves with side B; each step adds the tangential relative displacement of
the point, h v_t, so s measures how far the point slid since it stuck (``State.carried``, a
Carry of method "penalty": its ``values`` by its ``ids``, the persistent contact ids).

This module holds the method — its Options, ``step``, the guidance for k — and the stages'
Python forms; the compiled stages are in :mod:`contactlab.methods.penalty_springs` (stiffness,
springs, forces, amplification, anchors, the pass-through guard) and
:mod:`contactlab.methods.penalty_implicit` (the springs by backward Euler), which the compiled
loop (:mod:`contactlab.methods.loop_steps`, ``penalty_step``) calls too.
"""

from __future__ import annotations

from collections import namedtuple
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..collision import dynamic_cloth, half_thickness_sums, swept_distances
from ..compiling import njit
from ..contacts import ContactArrays, Contacts, jacobian, values_by_id, values_carried
from ..dynamics.generalized import implicit_base, stack, stacked, unstacked
from ..dynamics.integrators import carrying_springs, free_velocities, moved
from ..errors import InputError
from ..state import Carry, State
from ..validation import check_choices, check_counts, number, time_step
from .base import CollisionOptions, StepInfo
from .jacobian_rows import ContactRows, row_products
from .loop_stages import (
    LoopModel,
    LoopSettings,
    Motion,
    Specialization,
    build_rows,
    for_response,
    loop_inputs,
    solve,
    specialization,
)
from .penalty_implicit import free_dofs, implicit_spring_velocities, implicit_velocities, mass_blocks
from .penalty_springs import (
    GUARD_SWEEPS,
    GUARD_TOLERANCE,
    ImplicitSprings,
    Integrator,
    SpringSettings,
    anchors_after,
    damping_ratios,
    entities_of,
    explicit_velocities,
    normal_stiffness,
    slowest_approach,
    springs_implicit,
    springs_of,
    step_amplification,
)
from .penalty_springs import ContactSprings as ContactSprings  # re-exported: tests and callers build them here
from .penalty_springs import contact_spring_forces as contact_spring_forces  # re-exported: named here since SPEC P1
from .penalty_springs import elastic_energy as elastic_energy  # re-exported: named here since SPEC P3
from .sequential import contact_order

if TYPE_CHECKING:
    import scipy.sparse as sp

    from ..model import Model

ACCURATE_FREQUENCY_STEP = (
    0.25  # h ω of one spring under "auto": 25 steps per period (a box on four corners rings 2× faster)
)
LINEAR_SOLVERS = ("cg", "direct")
IMPLICIT_SPRINGS = ("auto", "always", "never")


@dataclass(frozen=True)
class Options(CollisionOptions):
    """Settings of ``[method.penalty]`` (after the collision settings of CollisionOptions)."""

    stiffness: object = "auto"
    """N/m per contact point, or "auto": each contact's load over allowed_penetration"""
    allowed_penetration: float = 0.0003
    """m: how deep "auto" stiffness lets each contact sink under the load it carries"""
    damping_ratio: object = "restitution"
    """ζ of each contact spring, or "restitution": ζ from the material's ε"""
    friction_stiffness: object = "auto"
    """N/m of the anchor springs (F3), or "auto": the normal stiffness"""
    contact_margin: float = 0.001
    """m: gaps this small are detected (their springs are slack)"""
    linear_solver: str = "cg"
    """backward Euler: cg (conjugate gradients, block-Jacobi-preconditioned) | direct (sparse Cholesky)"""
    linear_tolerance: float = 1e-10
    """backward Euler with cg: relative residual to reach"""
    implicit_iterations: int = 8
    """backward Euler: most passes to settle which springs act / slip (as many again, the slip forces
    held at μ k δ, where a step with slipping contacts did not settle)"""
    implicit_springs: str = "auto"
    """auto: backward Euler where an explicit step is unstable | always | never"""

    def __post_init__(self):
        super().__post_init__()
        self._settle("stiffness", _stiffness(self.stiffness, "stiffness"))
        self._settle("friction_stiffness", _stiffness(self.friction_stiffness, "friction_stiffness"))
        self._number("allowed_penetration", 0.0, strict=True)
        if self.damping_ratio != "restitution":
            if isinstance(self.damping_ratio, str):
                raise InputError(
                    "damping_ratio", f'expected a number ≥ 0 or "restitution", found {self.damping_ratio!r}'
                )
            self._number("damping_ratio", 0.0)
        self._number("linear_tolerance", 0.0, strict=True)
        check_choices(self, {"linear_solver": LINEAR_SOLVERS, "implicit_springs": IMPLICIT_SPRINGS})
        check_counts(self, {"implicit_iterations": 1})


def _stiffness(value, name):
    if value == "auto":
        return value
    if isinstance(value, str):
        raise InputError(name, f'expected a stiffness in N/m or "auto", found {value!r}')
    return number(value, name, 0.0, strict=True)


# ---- guidance for k -----------------------------------------------------------------------


@dataclass
class StiffnessAdvice:
    """What ``suggest_stiffness`` proposes, and why."""

    stiffness: float
    """N/m: the proposal"""
    needed: float
    """N/m: holds the load with the allowed penetration"""
    stable_limit: float
    """N/m: symplectic Euler diverges above this (h ω = 2) for the contact mass"""
    accurate_limit: float
    """N/m: h ω = 0.5, about 12 steps per oscillation of a contact spring"""
    penetration: float
    """m: the resting penetration under the load with the proposal"""
    reason: str
    """one sentence"""


def suggest_stiffness(
    mass: float,
    dt: float,
    allowed_penetration: float,
    gravity: float = 9.81,
    contacts: int = 1,
    contact_mass: float | None = None,
    integrator: str = "symplectic_euler",
) -> StiffnessAdvice:
    """Propose a penalty stiffness k [N/m] per contact point.

    mass [kg]: the load, resting on ``contacts`` contact points, under ``gravity`` [m/s²];
    allowed_penetration [m]: how deep it may sink, so k = m g / (contacts δ). contact_mass
    [kg] (default ``mass``): the smallest effective mass a single spring moves, which sets the
    stability of explicit integration: one spring oscillates at ω = √(k/m), and symplectic
    Euler follows it only while h ω < 2 (and well only for h ω ≲ 0.5). With an explicit
    integrator the proposal is capped at the accurate limit — the reason then says what time
    step would allow the needed stiffness; backward Euler is stable at any k and gets it.
    """
    dt = time_step(dt)
    allowed_penetration = number(allowed_penetration, "allowed_penetration", 0.0, strict=True)
    contact_mass = mass if contact_mass is None else contact_mass
    needed = mass * gravity / (contacts * allowed_penetration)
    stable = contact_mass * (2.0 / dt) ** 2
    accurate = contact_mass * (ACCURATE_FREQUENCY_STEP / dt) ** 2
    if integrator == "backward_euler" or needed <= accurate:
        k = needed
        reason = f"k = m g / (contacts δ) = {needed:.4g} N/m holds {mass:g} kg at {allowed_penetration:g} m"
        if needed > accurate:
            reason += " (backward Euler: stable at any stiffness, but contacts will be damped)"
    else:
        k = accurate
        step_needed = ACCURATE_FREQUENCY_STEP * np.sqrt(contact_mass / needed)
        reason = (
            f"a penetration of {allowed_penetration:g} m needs k = {needed:.4g} N/m, more than explicit "
            f"integration follows at dt = {dt:g} s (k ≤ {accurate:.4g} N/m); capped there, so the load "
            f"sinks {mass * gravity / (contacts * k):.3g} m: use dt ≤ {step_needed:.3g} s or "
            f'integrator = "backward_euler" for less'
        )
    return StiffnessAdvice(k, needed, stable, accurate, mass * gravity / (contacts * k), reason)


def amplification(integrator: str, dt: float, stiffness: float, mass: float, damping: float = 0.0) -> float:
    """Spectral radius of one step of a single contact spring (mass [kg], stiffness [N/m],
    damping [N s/m]) under ``integrator``: above 1 its oscillation grows every step."""
    return step_amplification(Integrator[integrator.upper()], stiffness / mass * dt * dt, damping / mass * dt)


def damping_ratio_from_restitution(restitution: float | np.ndarray) -> np.ndarray:
    """ζ of a spring-damper contact that rebounds with the coefficient ε (array or scalar):
    ε = exp(−ζ π / √(1 − ζ²)), so ζ = −ln ε / √(π² + ln² ε); ε = 0 gives ζ = 1 (critical)."""
    e = np.asarray(restitution, dtype=float)
    return damping_ratios(np.ascontiguousarray(e.ravel())).reshape(e.shape)


def lightest_contact_mass(model: Model) -> float:
    """The smallest mass a single contact spring can move [kg]: a particle's mass, or for a body
    1 / (1/m + R²/I_min) — a push at its farthest point R, turning it about its weakest axis."""
    masses = [np.inf]
    if model.body_count:
        reach = model.body_radii
        masses.append(np.min(1.0 / (model.body_inverse_mass + reach**2 / model.body_inertia.min(axis=1))))
    if model.particle_count:
        masses.append(model.particle_mass.min())
    return float(min(masses))


def divergence_advice(model: Model, dt: float, options: Options, integrator: str) -> str:
    """The likely fix, one clause, when a penalty run goes wrong (``contactlab.health``): for a
    given stiffness that the explicit step cannot follow on the lightest contact mass (with
    ``implicit_springs = "never"``), the time step or stiffness that would do and the switches
    that step such springs implicitly; else a smaller dt."""
    light = lightest_contact_mass(model)
    if integrator != "backward_euler" and options.implicit_springs == "never" and np.isfinite(light):
        ratios = (
            [options.damping_ratio]
            if options.damping_ratio != "restitution"
            else damping_ratio_from_restitution(np.unique(model.material_restitution)).tolist()
        )
        for k in (options.stiffness, options.friction_stiffness):
            if k == "auto":
                continue
            worst = max(amplification(integrator, dt, k, light, 2.0 * z * np.sqrt(k * light)) for z in ratios)
            if worst > 1.0 + 1e-12:
                limit = 2.0 * np.sqrt(light / k)
                instead = (
                    f"use dt < {limit:.3g} s, a stiffness below {light * (2.0 / dt) ** 2:.3g} N/m, "
                    if integrator == "symplectic_euler"
                    else "use damping, "
                )
                return (
                    f"dt = {dt:g} s is too long for penalty stiffness {k:.4g} N/m under {integrator} (a "
                    f"contact moving {light:.3g} kg grows {worst:.3g}× a step): {instead}implicit_springs = "
                    f'"auto" or integrator = "backward_euler"'
                )
    return f'use a smaller dt than {dt:g} s, or integrator = "backward_euler"'


# ---- the load each contact carries ----------------------------------------------------------


def contact_entities(contacts: Contacts, body_count: int) -> tuple[np.ndarray, np.ndarray]:
    """Each contact's two sides as entities (bodies 0..B−1, then particles B..B+P−1; a point on
    a cloth triangle counts as its first vertex; −1 a static side): (side A (C,), side B (C,))."""
    return entities_of(contacts.body_a, contacts.particles_a, body_count), entities_of(
        contacts.body_b, contacts.particles_b, body_count
    )


# ---- the contact springs ------------------------------------------------------------------


def spring_settings(options: Options, integrator: str) -> SpringSettings:
    """The SpringSettings of these Options and integrator."""

    def number(value):
        return -1.0 if isinstance(value, str) else float(value)

    by_integrator = integrator == "backward_euler"
    implicit = ImplicitSprings.BY_INTEGRATOR if by_integrator else ImplicitSprings[options.implicit_springs.upper()]
    return SpringSettings(
        stiffness=number(options.stiffness),
        allowed_penetration=float(options.allowed_penetration),
        damping_ratio=number(options.damping_ratio),
        friction_stiffness=number(options.friction_stiffness),
        implicit=implicit,
        integrator=Integrator[integrator.upper()],
        implicit_iterations=int(options.implicit_iterations),
        linear_tolerance=float(options.linear_tolerance),
    )


def contact_stiffness(model: Model, state: State, contacts: Contacts, options: Options) -> np.ndarray:
    """k (C,) [N/m] of each contact's normal spring: the option's number, or for "auto" the load
    the contact carries (``supported_loads``) over ``allowed_penetration``, so every contact of
    a stack sinks about that far however much rests on it (``normal_stiffness``)."""
    loads = (
        np.where(model.body_kinematic, 0.0, model.body_mass),
        np.asarray(model.particle_mass, dtype=float),
        np.asarray(model.gravity, dtype=float),
    )
    return normal_stiffness(
        spring_settings(options, "symplectic_euler"),
        contact_entities(contacts, model.body_count),
        contacts.normal,
        (state.body_position, state.particle_position),
        loads,
        dynamic_cloth(model),
    )


def assembled_springs(
    contacts: Contacts,
    J: sp.spmatrix,
    inverse_mass: sp.spmatrix,
    carried: Carry,
    options: Options,
    stiffness: np.ndarray | None = None,
) -> ContactSprings:
    """The springs of the contacts from the assembled Jacobian J (3C, N) and M⁻¹ (N, N) (sparse),
    the anchors ``carried`` from the last step (``springs_of`` says how): the matrix form the
    tests hold the step's matrix-free springs (``springs_at``, from the rows) against."""
    C = contacts.count
    inverse_effective = np.asarray((J @ inverse_mass).multiply(J).sum(axis=1)).ravel().reshape(C, 3)
    k = np.full(C, float(options.stiffness)) if stiffness is None else np.asarray(stiffness, dtype=float)
    offsets, _ = values_by_id(*carried.of("penalty"), contacts.feature_id, 3)
    return springs_of(spring_settings(options, "symplectic_euler"), k, inverse_effective, contacts.arrays(), offsets)


def distribute(J: sp.spmatrix, inverse_mass: sp.spmatrix, forces: np.ndarray, dt: float) -> np.ndarray:
    """Velocity change (N,) of the degrees of freedom from contact forces (C, 3) = (F_n, F_t1,
    F_t2) [N] acting for dt [s]: h M⁻¹ Jᵀ F (D1). For a particle that is h F / m, for a body
    h F / m and h I⁻¹ (r × F), for a point on a triangle each vertex's share w_i h F / m_i.
    (The step applies the same matrix-free, ``explicit_velocities``.)"""
    return dt * (inverse_mass @ (J.T @ forces.ravel()))


# ---- the step: loop L1 --------------------------------------------------------------------


def step(
    model: Model, state: State, dt: float, options: Options, integrator: str = "symplectic_euler"
) -> tuple[State, StepInfo]:
    """One step of loop L1 with penalty forces; returns (new State, StepInfo). Detection and the
    free velocities run here, for every scene (cloth, meshes, driven bodies, every integrator);
    the springs (``springs_at``), their integration (``integrate_velocities``, or SciPy's on an assembled
    system, ``implicit_velocities``) and the guard and anchors (``finish``) are the compiled
    stages the compiled loop's step (``loop_steps.penalty_step``) runs."""
    h = dt
    guard, penalty = penalty_loop(model, options, integrator, dt)
    # 1. collision detection, with the gaps this step's motion could close
    sweep = swept_distances(model, *state.velocities, h)
    contacts, _ = options.collide(model, state, sweep, particle_motion=h * state.particle_velocity)
    arrays, motion, rotation, carried = loop_inputs(model, state, "penalty")
    found = contacts.arrays()
    rows = build_rows(arrays, found, motion, rotation)
    # 2. collision forces F = k δ n and anchor springs (P1, F3), at the current state
    v = stacked(motion.body_velocity, motion.body_angular_velocity, motion.particle_velocity)
    springs, forces, elongation, implicit = springs_at(arrays, penalty, found, rows, motion, v, carried, h)
    # 3. internal forces (gravity, cloth springs, external forces) → free velocities v* = v + h M⁻¹ f
    free = free_velocities(model, state, h, integrator)
    v_free = stack(*free)
    # 4. integrate velocities, the contact forces distributed as Jᵀ F (D1); the springs by
    # backward Euler (M1) under that integrator, or where an explicit step would grow
    if implicit and (options.linear_solver != "cg" or (model.spring_count and integrator == "backward_euler")):
        J = jacobian(contacts, state.body_position, model.body_count, model.particle_count)
        base = implicit_base(model, state, h, v_free, cloth_implicit=integrator == "backward_euler")
        integrated = implicit_velocities(springs, J, base, v_free, contacts.depth, h, options)
    else:
        at_start = (springs, forces, elongation, implicit)
        integrated = integrate_velocities(arrays, penalty, found, rows, rotation, at_start, v_free, h)
    v_new, forces, elongation, passes, residual, linear_iterations = integrated
    # 4b–5. no contact carried past half its pass-through depth; positions; the anchors go on
    spec = for_response(specialization(model, "penalty", options, penalty))
    positions, velocities, offsets, energy = finish(
        arrays, guard, spec, found, rows, motion, (v, v_new), (springs, elongation, implicit)
    )
    carried_on = carrying_springs(
        Carry("penalty", None, contacts.feature_id, offsets), model, state, free[2], integrator
    )
    new = State.assemble(state.time + dt, positions, velocities, carried_on)
    return new, StepInfo(
        contacts,
        solver_iterations=int(passes),
        solver_residual=float(residual),
        linear_iterations=int(linear_iterations),
        energy_elastic=float(energy),
        implicit_springs=bool(implicit) and integrator != "backward_euler",
        impulses=h * forces,
    )


# ---- the compiled stages the step from Python and the compiled loop share ------------------

PenaltyLoop = namedtuple(
    "PenaltyLoop",
    (
        "springs",  # methods.penalty_springs.SpringSettings
        "thickness",  # (N,) [m] Model.collider_half_thickness
        "particle_radius",  # (P,) [m]
        "fixed",  # (B,) bool: kinematic bodies (moved by their paths: no spring moves them, none rests its weight)
        "cloth",  # (B + P,) int: the cloth of each body and particle, −1 none (its springs carry its weight)
    ),
)
PenaltyLoop.__doc__ = "What a penalty step adds to LoopModel: its SpringSettings and what its guard reads."


def penalty_loop(model: Model, options: Options, integrator: str, dt: float) -> tuple[LoopSettings, PenaltyLoop]:
    """(the LoopSettings of ``hold_back``'s sweeps — GUARD_SWEEPS, GUARD_TOLERANCE, steps of dt
    [s], the contact margin —, the PenaltyLoop of these Options and integrator)."""
    guard = LoopSettings(
        dt=float(dt),
        iterations=GUARD_SWEEPS,
        tolerance=GUARD_TOLERANCE,
        threshold=0.0,
        stabilization=0.0,
        slop=0.0,
        max_push_velocity=0.0,
        time_of_impact=False,
        warm_start=0.0,
        margin=float(options.contact_margin),
        manifold_tolerance=0.0,
        passes=1,
        substeps=1,
        substep_sweeps=1,
        always_substep=False,
        whole_sweeps=GUARD_SWEEPS,
        shock_sweeps=0,
        contact_hertz=0.0,
    )
    penalty = PenaltyLoop(
        springs=spring_settings(options, integrator),
        thickness=np.array(model.collider_half_thickness, dtype=float),
        particle_radius=np.array(model.particle_radius, dtype=float),
        fixed=np.array(model.body_kinematic, dtype=np.bool_),
        cloth=dynamic_cloth(model),
    )
    return guard, penalty


@njit(cache=True)
def springs_at(
    model: LoopModel,
    penalty: PenaltyLoop,
    contacts: ContactArrays,
    rows: ContactRows,
    motion: Motion,
    v: np.ndarray,
    carried: tuple,
    h: float,
) -> tuple[ContactSprings, np.ndarray, np.ndarray, bool]:
    """Stage 2: the contacts' springs (``penalty_springs.springs_of``: the stiffness of the option
    or of the load each carries, ``normal_stiffness``; the anchors of last step's contacts,
    ``carried`` = (ids (K,), offsets (K, 3) [m])), their forces at the velocity ``v`` (N,) —
    (C, 3) [N] and the anchors' elongations (C, 2) [m], ``contact_spring_forces`` — and whether the step
    integrates them by backward Euler (``springs_implicit``, over h [s])."""
    B = motion.body_position.shape[0]
    side_a = entities_of(contacts.body_a, contacts.particles_a, B)
    side_b = entities_of(contacts.body_b, contacts.particles_b, B)
    loads = np.where(penalty.fixed, 0.0, model.body_mass)  # a kinematic body rests its weight on nothing
    stiffness = normal_stiffness(
        penalty.springs,
        (side_a, side_b),
        contacts.normal,
        (motion.body_position, motion.particle_position),
        (loads, model.particle_mass, model.gravity),
        penalty.cloth,
    )
    offsets = values_carried(carried[0], carried[1], contacts.feature_id)[0]
    springs = springs_of(penalty.springs, stiffness, rows.k[:, :3], contacts, offsets)
    forces, elongation = contact_spring_forces(springs, contacts.depth, row_products(rows, v))
    dynamic = B + motion.particle_position.shape[0]
    return springs, forces, elongation, springs_implicit(penalty.springs, springs, side_a, side_b, dynamic, h)


@njit(cache=True)
def integrate_velocities(
    model: LoopModel,
    penalty: PenaltyLoop,
    contacts: ContactArrays,
    rows: ContactRows,
    rotation: np.ndarray,
    at_start: tuple,
    v_free: np.ndarray,
    h: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, float, int]:
    """Stage 4: the velocities after the step (N,) from the free ones ``v_free``: the springs
    ``at_start`` = (ContactSprings, forces (C, 3) [N], elongations (C, 2) [m], implicit), their
    forces applied as h M⁻¹ Jᵀ F
    (``explicit_velocities``), or where implicit the springs by backward Euler on the rows
    (``implicit_spring_velocities``: matrix-free conjugate gradients, the bodies' mass blocks at
    the rotations (B, 3, 3) ``rotation``), over h [s]. Returns (v⁺, forces, elongations,
    active-set passes, the last linear solve's relative residual, conjugate-gradient iterations)."""
    springs, forces, elongation, implicit = at_start
    if not implicit:
        return explicit_velocities(rows, forces, v_free, h), forces, elongation, 0, 0.0, 0
    mass = mass_blocks(model.body_mass, model.body_inertia, rotation, model.particle_mass)
    dofs = free_dofs(model.particle_pinned, penalty.fixed)
    return implicit_spring_velocities(penalty.springs, springs, rows, contacts.depth, v_free, mass, dofs, h)


@njit(cache=True)
def finish(
    model: LoopModel,
    guard: LoopSettings,
    spec: Specialization,
    contacts: ContactArrays,
    rows: ContactRows,
    motion: Motion,
    velocities: tuple,
    spring_state: tuple,
) -> tuple:
    """Stages 4b–5 of the run ``spec`` (``for_response``: its PenaltyLoop ``penalty``, and the
    guard's ``slabs`` and ``parallel``): ``velocities`` = (v at the step's start, v⁺ of
    ``integrate_velocities``) (N,) each; ``spring_state`` = (ContactSprings, elongations (C, 2)
    [m], implicit). The velocity that moves the step — v⁺, or v under explicit Euler with explicit
    springs — held back where it would
    carry a contact past half its pass-through depth (``hold_back``), the positions moved by it
    over ``guard.dt``, and the anchors of pressed contacts moved on (``anchors_after``). Returns
    (positions, velocities ((B, 3), (B, 3), (P, 3)), anchor offsets (C, 3) [m], the springs'
    elastic energy at the step's end [J])."""
    v, v_new = velocities
    springs, elongation, implicit = spring_state
    h, B = guard.dt, motion.body_position.shape[0]
    explicit_euler = spec.penalty.springs.integrator == Integrator.EXPLICIT_EULER and not implicit
    moved_by = v if explicit_euler else v_new
    held, changed = hold_back(model, guard, spec, contacts, rows, motion, moved_by)
    if changed:
        v_new = v_new + (held - moved_by) if explicit_euler else held
        moved_by = held
    by = unstacked(moved_by, B)
    positions = moved(
        motion.body_position,
        motion.body_orientation,
        motion.particle_position,
        by[0],
        by[1],
        by[2],
        np.full(B, h),
        np.full(by[2].shape[0], h),
    )
    geometry = (contacts.depth, contacts.tangent1, contacts.tangent2)
    elongation, offsets, energy = anchors_after(springs, rows, geometry, moved_by, elongation, not implicit, h)
    return positions, unstacked(v_new, B), offsets, energy


# Where friction stands among a ContactArrays' fields: ``hold_back`` copies the others around it
# (two constants, as Numba slices a tuple only by constants, not by a sum of them).
_FRICTION = ContactArrays._fields.index("friction")
_AFTER_FRICTION = _FRICTION + 1


@njit(cache=True)
def hold_back(
    model: LoopModel,
    guard: LoopSettings,
    spec: Specialization,
    contacts: ContactArrays,
    rows: ContactRows,
    motion: Motion,
    velocity: np.ndarray,
) -> tuple[np.ndarray, bool]:
    """Stage 4b: the generalized velocity (N,) with which the step moves, held back where it would
    carry a contact past half its pass-through depth D (``collision.half_thickness_sums``): every
    contact found over the swept step, open or closed, keeps v_n ≥ −(D/2 − δ) / h, δ its depth now
    [m]. A gap may close and a spring engage as deep as it likes short of that; a fast or small
    body that no spring of this stiffness could stop in time stops on the surface instead of
    passing through (normal impulses only, by frictionless sweeps: ``solve`` with the ``guard``'s
    settings; ``spec``'s PenaltyLoop, ``slabs`` and ``parallel``, as ``finish``). Returns
    (``velocity`` itself, False, where nothing would; else a held copy, True)."""
    penalty = spec.penalty
    C = contacts.depth.shape[0]
    pass_through = half_thickness_sums(
        contacts.feature_id,
        contacts.particles_a,
        penalty.thickness,
        penalty.particle_radius,
        motion.body_position.shape[0] + motion.particle_position.shape[0],
    )
    slowest, below = slowest_approach(rows, velocity, contacts.depth, pass_through, guard.dt)
    if not below:
        return velocity, False
    held = velocity.copy()
    frictionless = ContactArrays(*contacts[:_FRICTION], np.zeros(C), *contacts[_AFTER_FRICTION:])
    order = contact_order(contacts.point, contacts.feature_id, model.gravity)
    system = (held, slowest, np.zeros((C, 3)), order)
    solve(guard, spec.slabs, spec.parallel, rows, frictionless, motion, system, None)
    return held, True
