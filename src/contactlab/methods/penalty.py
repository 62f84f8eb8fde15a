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
the point, h v_t, so s measures how far the point slid since it stuck (``anchor_offsets`` in
``State.carried``, keyed by ``anchor_ids``).
"""

from collections import namedtuple
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numba import njit

from .. import rotations
from ..collision import collide, pass_through_depths, swept_distances
from ..contacts import jacobian, values_by_id
from ..dynamics.generalized import implicit_base, stack, unstack
from ..dynamics.integrators import advance_positions, factor_symmetric, free_velocities
from ..errors import InputError
from ..rotations import world_tensors
from ..state import State
from ..validation import check_choices, check_counts, number, time_step
from . import CollisionOptions, StepInfo
from .sequential import (
    along_rows,
    apply_impulses,
    contact_velocity,
    row_products,
    rows_of,
    solve_order,
    solve_sequential_impulses,
    sweep_groups,
)

ACCURATE_FREQUENCY_STEP = (
    0.25  # h ω of one spring under "auto": 25 steps per period (a box on four corners rings 2× faster)
)
LINEAR_SOLVERS = ("cg", "direct")
IMPLICIT_SPRINGS = ("auto", "always", "never")


@dataclass
class Options(CollisionOptions):
    """Settings of ``[method.penalty]`` (after the collision settings of CollisionOptions)."""

    stiffness: object = "auto"  # N/m per contact point, or "auto": each contact's load over allowed_penetration
    allowed_penetration: float = 0.0003  # m: how deep "auto" stiffness lets each contact sink under the load it carries
    damping_ratio: object = "restitution"  # ζ of each contact spring, or "restitution": ζ from the material's ε
    friction_stiffness: object = "auto"  # N/m of the anchor springs (F3), or "auto": the normal stiffness
    contact_margin: float = 0.001  # m: gaps this small are detected (their springs are slack)
    linear_solver: str = "cg"  # backward Euler: cg (conjugate gradients, Jacobi-preconditioned) | direct (sparse LU)
    linear_tolerance: float = 1e-10  # backward Euler with cg: relative residual to reach
    implicit_iterations: int = 8  # backward Euler: most passes to settle which springs act / slip
    implicit_springs: str = "auto"  # auto: backward Euler where an explicit step is unstable | always | never

    def __post_init__(self):
        super().__post_init__()
        self.stiffness = _stiffness(self.stiffness, "stiffness")
        self.friction_stiffness = _stiffness(self.friction_stiffness, "friction_stiffness")
        self.allowed_penetration = number(self.allowed_penetration, "allowed_penetration", 0.0, strict=True)
        if self.damping_ratio != "restitution":
            if isinstance(self.damping_ratio, str):
                raise InputError(
                    "damping_ratio", f'expected a number ≥ 0 or "restitution", found {self.damping_ratio!r}'
                )
            self.damping_ratio = number(self.damping_ratio, "damping_ratio", 0.0)
        self.linear_tolerance = number(self.linear_tolerance, "linear_tolerance", 0.0, strict=True)
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

    stiffness: float  # N/m: the proposal
    needed: float  # N/m: holds the load with the allowed penetration
    stable_limit: float  # N/m: symplectic Euler diverges above this (h ω = 2) for the contact mass
    accurate_limit: float  # N/m: h ω = 0.5, about 12 steps per oscillation of a contact spring
    penetration: float  # m: the resting penetration under the load with the proposal
    reason: str  # one sentence


def suggest_stiffness(
    mass, dt, allowed_penetration, gravity=9.81, contacts=1, contact_mass=None, integrator="symplectic_euler"
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


def amplification(integrator, dt, stiffness, mass, damping=0.0) -> float:
    """Spectral radius of one step of a single contact spring (mass [kg], stiffness [N/m],
    damping [N s/m]) under ``integrator``: above 1 its oscillation grows every step."""
    return step_amplification(INTEGRATORS.index(integrator), stiffness / mass * dt * dt, damping / mass * dt)


@njit(cache=True)
def step_amplification(integrator, w2, d):
    """``amplification``, compiled: integrator 0 symplectic, 1 explicit, 2 backward Euler (as in
    INTEGRATORS); w2 = (h ω)², d = h c / m. The 2×2 step matrix on (x / h, v) and the moduli of
    its eigenvalues in closed form (a complex pair: both √det)."""
    if integrator == 0:  # v⁺ = v − (ω²h x + 2ζω h v),  x⁺ = x + h v⁺   (x in units of h)
        a, b, c, e = 1.0 - w2, 1.0 - d, -w2, 1.0 - d
    elif integrator == 1:  # x⁺ = x + h v,  v⁺ = v − h(ω² x + c/m v)
        a, b, c, e = 1.0, 1.0, -w2, 1.0 - d
    else:  # backward Euler: the same at the new state; the step is this matrix's inverse
        a, b, c, e = 1.0, -1.0, w2, 1.0 + d
    half, det = 0.5 * (a + e), a * e - b * c
    disc = half * half - det
    if disc < 0.0:
        largest = smallest = np.sqrt(det)
    else:
        first, second = abs(half + np.sqrt(disc)), abs(half - np.sqrt(disc))
        largest, smallest = max(first, second), min(first, second)
    return 1.0 / smallest if integrator == 2 else largest


def damping_ratio_from_restitution(restitution):
    """ζ of a spring-damper contact that rebounds with the coefficient ε (array or scalar):
    ε = exp(−ζ π / √(1 − ζ²)), so ζ = −ln ε / √(π² + ln² ε); ε = 0 gives ζ = 1 (critical)."""
    e = np.asarray(restitution, dtype=float)
    return damping_ratios(np.ascontiguousarray(e.ravel())).reshape(e.shape)


@njit(cache=True)
def damping_ratios(restitution):
    """``damping_ratio_from_restitution``, compiled, on an array (C,)."""
    zeta = np.empty(restitution.shape[0])
    for c in range(zeta.shape[0]):
        if restitution[c] <= 0.0:
            zeta[c] = 1.0
        else:
            log = np.log(min(restitution[c], 1.0))
            zeta[c] = -log / np.sqrt(np.pi**2 + log**2)
    return zeta


def lightest_contact_mass(model) -> float:
    """The smallest mass a single contact spring can move [kg]: a particle's mass, or for a body
    1 / (1/m + R²/I_min) — a push at its farthest point R, turning it about its weakest axis."""
    masses = [np.inf]
    if model.body_count:
        reach = model.body_radii
        masses.append(np.min(1.0 / (model.body_inverse_mass + reach**2 / model.body_inertia.min(axis=1))))
    if model.particle_count:
        masses.append(model.particle_mass.min())
    return float(min(masses))


def divergence_advice(model, dt, options, integrator):
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

SUPPORT_COSINE = 0.3  # a contact whose normal is within 72° of "up" (against gravity) supports its upper side


def contact_entities(contacts, body_count):
    """Each contact's two sides as entities (bodies 0..B−1, then particles B..B+P−1; a point on
    a cloth triangle counts as its first vertex; −1 a static side): (side A (C,), side B (C,))."""
    return entities_of(contacts.body_a, contacts.particles_a, body_count), entities_of(
        contacts.body_b, contacts.particles_b, body_count
    )


@njit(cache=True)
def entities_of(body, particles, body_count):
    """``contact_entities`` of one side, compiled: body (C,), particles (C, 3) → (C,) int64."""
    out = np.empty(body.shape[0], dtype=np.int64)
    for c in range(body.shape[0]):
        out[c] = body[c] if body[c] >= 0 else (body_count + particles[c, 0] if particles[c, 0] >= 0 else -1)
    return out


@njit(cache=True)
def supported_loads(entity_a, entity_b, normal, body_position, particle_position, body_mass, particle_mass, gravity):
    """The weight each contact carries [N] (C,): every body and free particle, from the highest
    down, hands its own weight and what rests on it to the contacts it rests on (normals within
    72° of up, against ``gravity`` (3,) [m/s²]), in equal shares, and those pass it to the body
    or particle below; a static side takes it out. Contacts that support nothing carry the
    lighter side's weight per supporting contact. A kinematic body is given weight 0: it hands
    nothing down and, like a static side, does not count as the lighter side. Sides as ``contact_entities`` gives them.
    Arrays (C,), (C,), (C, 3), (B, 3), (P, 3), (B,), (P,) as in Contacts and State."""
    C, B, P = entity_a.shape[0], body_mass.shape[0], particle_mass.shape[0]
    g = np.sqrt(gravity[0] ** 2 + gravity[1] ** 2 + gravity[2] ** 2)
    loads = np.zeros(C)
    if g == 0.0 or C == 0:
        return loads
    up = -gravity / g
    upper = np.full(C, -1)  # the supported side's entity (bodies, then particles), −1: none
    lower = np.full(C, -1)
    supports = np.zeros(B + P, dtype=np.int64)
    for c in range(C):
        a, b = entity_a[c], entity_b[c]
        along = normal[c, 0] * up[0] + normal[c, 1] * up[1] + normal[c, 2] * up[2]  # normal: from B into A
        if along > SUPPORT_COSINE and a >= 0:
            upper[c], lower[c] = a, b
        elif along < -SUPPORT_COSINE and b >= 0:
            upper[c], lower[c] = b, a
        if upper[c] >= 0:
            supports[upper[c]] += 1
    weight = np.empty(B + P)
    height = np.empty(B + P)
    for e in range(B + P):
        position = body_position[e] if e < B else particle_position[e - B]
        weight[e] = g * (body_mass[e] if e < B else particle_mass[e - B])
        height[e] = position[0] * up[0] + position[1] * up[1] + position[2] * up[2]
    own_share = weight / np.maximum(supports, 1)
    carried = weight.copy()  # own weight plus everything handed down so far
    start = np.zeros(B + P + 1, dtype=np.int64)  # the contacts each entity rests on, grouped
    for c in range(C):
        if upper[c] >= 0:
            start[upper[c] + 1] += 1
    for e in range(B + P):
        start[e + 1] += start[e]
    filled = start[:-1].copy()
    resting_on = np.empty(start[-1], dtype=np.int64)
    for c in range(C):
        if upper[c] >= 0:
            resting_on[filled[upper[c]]] = c
            filled[upper[c]] += 1
    for e in np.argsort(-height):
        if supports[e] == 0:
            continue
        share = carried[e] / supports[e]
        for i in range(start[e], start[e + 1]):
            c = resting_on[i]
            loads[c] = share
            if lower[c] >= 0:
                carried[lower[c]] += share
    for c in range(C):
        if upper[c] < 0:  # a side contact: the lighter dynamic side's share
            least = np.inf
            for e in (entity_a[c], entity_b[c]):
                if e >= 0 and own_share[e] > 0.0:  # weightless: a kinematic body, a driven side
                    least = min(least, own_share[e])
            loads[c] = least if least < np.inf else 0.0
    return loads


# ---- the contact springs ------------------------------------------------------------------

ContactSprings = namedtuple(
    "ContactSprings",
    (
        "stiffness",  # (C,) k [N/m]
        "damping",  # (C,) c [N s/m] along the normal
        "friction_stiffness",  # (C,) k_t [N/m] of the anchor springs
        "friction_damping",  # (C,) c_t [N s/m]
        "friction",  # (C,) μ
        "elongation",  # (C, 2) s = point − anchor in (t1, t2) components [m]
        "inverse_effective_mass",  # (C, 3) J M⁻¹ Jᵀ of the normal and tangent rows [1/kg] (None: not known)
    ),
    defaults=(None,),
)
ContactSprings.__doc__ = "The springs of C contacts, as this step sees them (a named tuple: compiled code takes it)."

SpringSettings = namedtuple(
    "SpringSettings",
    (
        "stiffness",  # N/m, or −1: "auto" (each contact's load over allowed_penetration)
        "allowed_penetration",  # m
        "damping_ratio",  # ζ, or −1: from the material's restitution
        "friction_stiffness",  # N/m, or −1: "auto" (the normal stiffness)
        "implicit",  # 0 never, 1 auto (where the explicit step is unstable), 2 always, 3 backward Euler
        "integrator",  # 0 symplectic, 1 explicit, 2 backward Euler (``amplification``'s cases)
        "implicit_iterations",  # passes of the active set, at most
        "linear_tolerance",  # relative residual of the conjugate gradients
    ),
)
SpringSettings.__doc__ = "The penalty Options and integrator as plain numbers, for the compiled stages."
INTEGRATORS = ("symplectic_euler", "explicit_euler", "backward_euler")


def spring_settings(options, integrator):
    """The SpringSettings of these Options and integrator."""

    def number(value):
        return -1.0 if isinstance(value, str) else float(value)

    implicit = 3 if integrator == "backward_euler" else {"never": 0, "auto": 1, "always": 2}[options.implicit_springs]
    return SpringSettings(
        number(options.stiffness),
        float(options.allowed_penetration),
        number(options.damping_ratio),
        number(options.friction_stiffness),
        implicit,
        INTEGRATORS.index(integrator),
        int(options.implicit_iterations),
        float(options.linear_tolerance),
    )


def contact_stiffness(model, state, contacts, options):
    """k (C,) [N/m] of each contact's normal spring: the option's number, or for "auto" the load
    the contact carries (``supported_loads``) over ``allowed_penetration``, so every contact of
    a stack sinks about that far however much rests on it (``normal_stiffness``)."""
    return normal_stiffness(
        spring_settings(options, "symplectic_euler"),
        *contact_entities(contacts, model.body_count),
        contacts.normal,
        state.body_position,
        state.particle_position,
        np.where(model.body_kinematic, 0.0, model.body_mass),
        np.asarray(model.particle_mass, dtype=float),
        np.asarray(model.gravity, dtype=float),
    )


@njit(cache=True)
def normal_stiffness(
    settings, entity_a, entity_b, normal, body_position, particle_position, body_mass, particle_mass, gravity
):
    """``contact_stiffness``, compiled: sides as ``contact_entities``, the rest as ``supported_loads``."""
    if settings.stiffness >= 0.0:
        return np.full(entity_a.shape[0], settings.stiffness)
    return (
        supported_loads(entity_a, entity_b, normal, body_position, particle_position, body_mass, particle_mass, gravity)
        / settings.allowed_penetration
    )


def contact_springs(contacts, J, inverse_mass, carried, options, stiffness=None):
    """The springs of the contacts from the Jacobian J (3C, N) and M⁻¹ (N, N) (sparse), the
    anchors ``carried`` from the last step; ``springs_of`` says how."""
    C = contacts.count
    inverse_effective = np.asarray((J @ inverse_mass).multiply(J).sum(axis=1)).ravel().reshape(C, 3)
    k = np.full(C, float(options.stiffness)) if stiffness is None else np.asarray(stiffness, dtype=float)
    offsets, _ = values_by_id(carried.get("anchor_ids"), carried.get("anchor_offsets"), contacts.feature_id, 3)
    return springs_of(
        spring_settings(options, "symplectic_euler"),
        k,
        inverse_effective,
        contacts.restitution,
        contacts.friction,
        offsets,
        contacts.tangent1,
        contacts.tangent2,
    )


@njit(cache=True)
def springs_of(settings, stiffness, inverse_effective, restitution, friction, offsets, tangent1, tangent2):
    """The springs of C contacts: normal stiffness ``stiffness`` (C,) [N/m] (``normal_stiffness``),
    damping c = 2 ζ √(k m_eff) with each contact's effective mass m_eff = 1 / (J M⁻¹ Jᵀ) along its
    normal (and tangent) from ``inverse_effective`` (C, 3) [1/kg] (ζ the option's or from the
    restitution (C,)), friction stiffness the normal one where "auto", μ = ``friction`` (C,), and
    the anchor elongations ``offsets`` (C, 3) [m] carried from the last step turned into the
    current tangent plane (t1, t2 (C, 3)), their length kept (the plane may have turned)."""
    C = stiffness.shape[0]
    zeta = damping_ratios(restitution) if settings.damping_ratio < 0.0 else np.full(C, settings.damping_ratio)
    k_t = stiffness.copy() if settings.friction_stiffness < 0.0 else np.full(C, settings.friction_stiffness)
    damping, friction_damping, elongation = np.empty(C), np.empty(C), np.empty((C, 2))
    for c in range(C):
        n, t = inverse_effective[c, 0], inverse_effective[c, 1]
        damping[c] = 2.0 * zeta[c] * np.sqrt(stiffness[c] / n) if n > 0.0 else 0.0
        friction_damping[c] = 2.0 * zeta[c] * np.sqrt(k_t[c] / t) if t > 0.0 else 0.0
        o = offsets[c]
        e1 = o[0] * tangent1[c, 0] + o[1] * tangent1[c, 1] + o[2] * tangent1[c, 2]
        e2 = o[0] * tangent2[c, 0] + o[1] * tangent2[c, 1] + o[2] * tangent2[c, 2]
        length, projected = np.sqrt(o[0] * o[0] + o[1] * o[1] + o[2] * o[2]), np.sqrt(e1 * e1 + e2 * e2)
        scale = length / max(projected, 1e-300) if projected > 0.0 else 0.0
        elongation[c, 0], elongation[c, 1] = e1 * scale, e2 * scale
    return ContactSprings(stiffness, damping, k_t, friction_damping, friction, elongation, inverse_effective)


@njit(cache=True)
def springs_unstable(springs, entity_a, entity_b, entities, h, integrator):
    """Whether the explicit ``integrator`` (0 symplectic, 1 explicit Euler) at h [s] would amplify
    the contact springs' motion (``step_amplification`` > 1). Each of the ``entities`` bodies and
    particles rings at most at ω² = Σ k J M⁻¹ Jᵀ over the rows of the springs that hold it (a
    Gershgorin bound: a box on four corners, each with a normal and two anchor springs, rings
    √12 times faster than one spring alone), damped at the largest damping ratio among the
    contacts. Sides (C,) as ``contact_entities``."""
    inverse, k = springs.inverse_effective_mass, springs.stiffness
    total = np.zeros(entities)
    for side in (entity_a, entity_b):
        for c in range(side.shape[0]):
            if side[c] >= 0:
                total[side[c]] += k[c] * inverse[c, 0] + springs.friction_stiffness[c] * (inverse[c, 1] + inverse[c, 2])
    omega_squared = 0.0
    for e in range(entities):
        omega_squared = max(omega_squared, total[e])
    if omega_squared <= 0.0:
        return False
    zeta = 0.0
    for c in range(k.shape[0]):
        if k[c] > 0.0:
            zeta = max(zeta, springs.damping[c] * np.sqrt(inverse[c, 0]) / (2.0 * np.sqrt(k[c])))
    omega = np.sqrt(omega_squared)
    return step_amplification(integrator, omega_squared * h * h, 2.0 * zeta * omega * h) > 1.0 + 1e-12


@njit(cache=True)
def springs_implicit(settings, springs, entity_a, entity_b, entities, h):
    """Whether this step takes its contact springs by backward Euler: always under that
    integrator or with implicit_springs "always", never with "never" or without contacts, and
    under "auto" where the explicit step would amplify them (``springs_unstable``)."""
    if settings.implicit == 3:
        return True
    if entity_a.shape[0] == 0 or settings.implicit == 0:
        return False
    return settings.implicit == 2 or springs_unstable(springs, entity_a, entity_b, entities, h, settings.integrator)


@njit(cache=True)
def spring_forces(springs, depth, velocity):
    """Contact forces at penetration ``depth`` (C,) [m] and contact-point relative velocities
    ``velocity`` (C, 3) = (v_n, v_t1, v_t2) [m/s] (that is, J v reshaped).

    Normal (P1 with damping): F_n = k δ − c v_n where δ > 0, never negative (C2). Friction
    (F3): the anchor spring's pull F_t = −k_t s − c_t v_t; if |F_t| > μ F_n the contact slips:
    F_t is cut to μ F_n and the anchor is moved so the spring alone pulls that hard. Returns
    (forces (C, 3) = (F_n, F_t1, F_t2) [N], elongation after slipping (C, 2) [m]).
    """
    C = depth.shape[0]
    forces, elongation = np.empty((C, 3)), springs.elongation.copy()
    for c in range(C):
        normal = (
            max(springs.stiffness[c] * depth[c] - springs.damping[c] * velocity[c, 0], 0.0) if depth[c] > 0.0 else 0.0
        )
        k_t, c_t = springs.friction_stiffness[c], springs.friction_damping[c]
        t1 = -k_t * springs.elongation[c, 0] - c_t * velocity[c, 1]
        t2 = -k_t * springs.elongation[c, 1] - c_t * velocity[c, 2]
        limit, size = springs.friction[c] * normal, np.sqrt(t1 * t1 + t2 * t2)
        if size > limit:
            scale = limit / size
            t1, t2 = t1 * scale, t2 * scale
            elongation[c, 0], elongation[c, 1] = -t1 / k_t, -t2 / k_t
        forces[c, 0], forces[c, 1], forces[c, 2] = normal, t1, t2
    return forces, elongation


@njit(cache=True)
def elastic_energy(springs, depth, elongation):
    """Energy stored in the springs [J]: Σ ½ k δ² over compressed contacts (P3), plus ½ k_t |s|²
    of their anchor springs; depth (C,) [m], elongation (C, 2) [m]."""
    normal = anchors = 0.0
    for c in range(depth.shape[0]):
        if depth[c] > 0.0:
            normal += springs.stiffness[c] * depth[c] ** 2
            anchors += springs.friction_stiffness[c] * (elongation[c, 0] ** 2 + elongation[c, 1] ** 2)
    return 0.5 * normal + 0.5 * anchors


def distribute(J, inverse_mass, forces, dt):
    """Velocity change (N,) of the degrees of freedom from contact forces (C, 3) = (F_n, F_t1,
    F_t2) [N] acting for dt [s]: h M⁻¹ Jᵀ F (D1). For a particle that is h F / m, for a body
    h F / m and h I⁻¹ (r × F), for a point on a triangle each vertex's share w_i h F / m_i.
    (The step applies the same matrix-free, ``explicit_velocities``.)"""
    return dt * (inverse_mass @ (J.T @ forces.ravel()))


@njit(cache=True)
def explicit_velocities(rows, forces, v_free, h):
    """v* + h M⁻¹ Jᵀ F (N,): the contact forces (C, 3) [N] of ``spring_forces`` over h [s] added to
    the free velocities, contact by contact through the rows (``sequential.apply_impulses``)."""
    v_new = v_free.copy()
    apply_impulses(rows, h * forces, v_new)
    return v_new


@njit(cache=True)
def anchors_after(springs, rows, depth, moved_by, elongation, follow, tangent1, tangent2, h):
    """Stage 5: the anchors at the end of the step moved by ``moved_by`` (N,) over h [s]: where
    ``follow`` (an explicit step) the elongation (C, 2) [m] takes the point's tangential motion
    h v_t; a contact no longer pressed (depth after the step ≤ 0) drops its anchor. Returns
    (elongation (C, 2), the anchor offsets to carry (C, 3) = s₁ t1 + s₂ t2 [m], elastic energy
    at the end of the step [J])."""
    C = depth.shape[0]
    velocity = row_products(rows, moved_by)
    after = elongation.copy()
    offsets = np.empty((C, 3))
    depth_after = np.empty(C)
    for c in range(C):
        if follow:
            after[c, 0], after[c, 1] = elongation[c, 0] + h * velocity[c, 1], elongation[c, 1] + h * velocity[c, 2]
        depth_after[c] = depth[c] - h * velocity[c, 0]
        if depth_after[c] <= 0.0:
            after[c, 0] = after[c, 1] = 0.0
        for i in range(3):
            offsets[c, i] = after[c, 0] * tangent1[c, i] + after[c, 1] * tangent2[c, i]
    return after, offsets, elastic_energy(springs, depth_after, after)


# ---- the swept step: nothing passes through ----------------------------------------------

PASS_THROUGH_FRACTION = 0.5  # of a contact's pass-through depth: the deepest overlap a step may carry it to
GUARD_SWEEPS, GUARD_TOLERANCE = 100, 1e-6  # sweeps, m/s of the guard's solve


@njit(cache=True)
def slowest_approach(rows, velocity, depth, pass_through, h):
    """The guard of ``hold_back``: each contact's least normal velocity v_n ≥ −(D/2 − δ) / h
    (C,) [m/s] from its pass-through depth D (C,) [m] (``collision.half_thickness_sums``) and
    depth δ, and whether ``velocity`` (N,) goes below it anywhere (the rows tell, C × 3)."""
    slowest = -(PASS_THROUGH_FRACTION * pass_through - depth) / h
    below = False
    for c in range(depth.shape[0]):
        below = below or contact_velocity(c, rows, velocity)[0] < slowest[c]
    return slowest, below


def hold_back(model, state, contacts, rows, velocity, h):
    """The generalized velocity (N,) with which the step moves, held back where it would carry a
    contact past half its pass-through depth D (``collision.pass_through_depths``): every contact
    found over the swept step, open or closed, keeps v_n ≥ −(D/2 − δ) / h, δ its depth now [m].
    A gap may close and a spring engage as deep as it likes short of that; a fast or small body
    that no spring of this stiffness could stop in time stops on the surface instead of passing
    through (normal impulses only, by sequential sweeps). ``velocity`` itself where nothing would;
    ``rows`` (``sequential.contact_rows``): the step's Jacobian, which tells that."""
    slowest, below = slowest_approach(rows, velocity, contacts.depth, pass_through_depths(model, contacts), h)
    if not below:
        return velocity
    held = velocity.copy()
    solve_sequential_impulses(
        rows,
        np.zeros(contacts.count),
        slowest,
        held,
        GUARD_SWEEPS,
        GUARD_TOLERANCE,
        np.zeros((contacts.count, 3)),
        *sweep_groups(rows, contacts, state, solve_order(contacts, model.gravity)),
    )
    return held


# ---- backward Euler -----------------------------------------------------------------------
#
# The springs' system (M + h (h K + D)) v⁺ = M v* + h Jᵀ F₀ is solved matrix-free: M as its
# blocks (body masses (B,), world inertia tensors (B, 3, 3), particle masses (P,)), J and Jᵀ
# through the contact rows (``sequential.ContactRows``), the springs as a weight (C, 3) per row.


@njit(cache=True)
def mass_blocks(body_mass, body_inertia, rotation, particle_mass):
    """M's blocks at the rotations (B, 3, 3): (body_mass (B,) [kg], world inertia R I Rᵀ (B, 3, 3)
    [kg m²], particle_mass (P,) [kg])."""
    return body_mass, world_tensors(rotation, body_inertia), particle_mass


@njit(cache=True)
def free_dofs(particle_pinned, body_fixed):
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
def mass_product(mass, x, out):
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
def transpose_product(rows, values, out):
    """out += Jᵀ λ (N,) for each contact's row values λ (C, 3) (normal, t1, t2); returns out."""
    for c in range(values.shape[0]):
        along_rows(c, rows, values[c, 0], values[c, 1], values[c, 2], out, False)
    return out


@njit(cache=True)
def system_product(rows, weight, mass, free, x, kept, out):
    """out = A x (N,) with A = M + F Jᵀ W J F: the springs' weights W (C, 3) on J's rows,
    F = diag(free) (N,) (1 for a DOF that moves, 0 for a pinned particle's); ``kept`` (N,) is
    scratch. Allocates nothing: the conjugate gradients call it every iteration. Returns out."""
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
def system_diagonal(rows, weight, mass, free):
    """The diagonal of A (``system_product``) (N,): M's and Σ W (J_row,i)² over the rows."""
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
def conjugate_gradients(rows, weight, mass, free, rhs, guess, tolerance, most):
    """A v = rhs (``system_product``) by conjugate gradients with the Jacobi preconditioner
    diag(A), from ``guess`` (N,), until |r| ≤ tolerance |rhs| or ``most`` iterations. Returns
    (v (N,), |A v − rhs| / |rhs|, iterations)."""
    N = rhs.shape[0]
    diagonal = system_diagonal(rows, weight, mass, free)
    x, r, z, p, Ap, kept = guess.copy(), np.empty(N), np.empty(N), np.empty(N), np.empty(N), np.empty(N)
    system_product(rows, weight, mass, free, x, kept, Ap)
    for i in range(N):
        if diagonal[i] == 0.0:  # a DOF with no mass and no spring: left as it is
            diagonal[i] = 1.0
        r[i] = rhs[i] - Ap[i]
        z[i] = r[i] / diagonal[i]
        p[i] = z[i]
    scale = max(np.sqrt(np.dot(rhs, rhs)), 1e-300)
    rz = np.dot(r, z)
    iterations = 0
    while iterations < most and np.sqrt(np.dot(r, r)) > tolerance * scale and rz != 0.0:
        system_product(rows, weight, mass, free, p, kept, Ap)
        alpha = rz / np.dot(p, Ap)
        for i in range(N):
            x[i] += alpha * p[i]
            r[i] -= alpha * Ap[i]
            z[i] = r[i] / diagonal[i]
        following = np.dot(r, z)
        beta = following / rz
        for i in range(N):
            p[i] = z[i] + beta * p[i]
        rz = following
        iterations += 1
    system_product(rows, weight, mass, free, x, kept, Ap)
    for i in range(N):
        Ap[i] -= rhs[i]
    return x, np.sqrt(np.dot(Ap, Ap)) / scale, iterations


@njit(cache=True)
def implicit_spring_velocities(settings, springs, rows, depth, v_free, mass, free, h):
    """Backward Euler for the contact springs: v⁺ with M v⁺ = M v* + h Jᵀ F(x + h v⁺, v⁺), where
    M v⁺ = M v* is the step without contacts (rigid bodies and free particles: M as
    ``mass_blocks``); ``free`` (N,) 1.0 for the DOFs that may move, 0.0 for a pinned
    particle's; v_free (N,) the velocities without contacts, depth (C,) [m], h [s].

    The springs are linear in v⁺ along the Jacobian fixed at x: δ⁺ = δ − h J_n v⁺ and
    s⁺ = s + h J_t v⁺, so an engaged normal spring adds h (h k + c) J_nᵀ J_n to the matrix and
    h k δ J_nᵀ to the right-hand side, and a sticking anchor spring likewise along J_t.

    Friction is settled first, as in plasticity's return mapping: a pass with every pressed
    contact sticking (the elastic predictor) says which anchor springs would pull harder than
    μ F_n; those contacts slip in the direction of that pull, with the force μ F_n⁺ of the
    latest pass. Then the engaged normal springs (F_n⁺ > 0) and the slip forces are found by
    repeating the solve (``conjugate_gradients``) until they stop changing (an active-set
    iteration; for convex energies such as a plane's, and no friction, it is the exact backward
    Euler step, which never adds energy). Returns (v⁺ (N,), forces (C, 3) [N], elongation
    after the step (C, 2) [m], passes, relative residual of the last linear solve).
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
    engaged, sticks, slips = np.empty(C, np.bool_), np.empty(C, np.bool_), np.zeros(C, np.bool_)
    for c in range(C):
        engaged[c] = depth[c] - h * start[c, 0] > 0.0
        sticks[c] = engaged[c] and mu[c] > 0.0
    slip_force, slip_direction = np.zeros((C, 2)), np.zeros((C, 2))
    weight, pull = np.empty((C, 3)), np.empty((C, 3))
    normal, trial, elongation = np.zeros(C), np.zeros((C, 2)), np.zeros((C, 2))
    base = mass_product(mass, v_free, np.empty(v_free.shape[0]))
    v_new, residual, passes = v_free, 0.0, 0
    for passes in range(1, settings.implicit_iterations + 1):
        for c in range(C):
            weight[c, 0] = h * (h * k[c] + c_n[c]) if engaged[c] else 0.0
            weight[c, 1] = weight[c, 2] = h * (h * k_t[c] + c_t[c]) if sticks[c] else 0.0
            pull[c, 0] = k[c] * depth[c] if engaged[c] else 0.0
            for d in range(2):
                pull[c, 1 + d] = -k_t[c] * springs.elongation[c, d] if sticks[c] else slip_force[c, d]
        rhs = base + free * (h * transpose_product(rows, pull, np.zeros(v_free.shape[0])))
        v_new, residual, _ = conjugate_gradients(
            rows, weight, mass, free, rhs, v_new, settings.linear_tolerance, 10 * v_free.shape[0]
        )
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
        for c in range(C):  # μ F_n⁺ along the slip, F_n⁺ of this pass
            for d in range(2):
                force = slip_direction[c, d] * mu[c] * normal[c]
                settled = settled and abs(force - slip_force[c, d]) <= 1e-9 * max(1.0, largest) + 1e-6 * abs(
                    slip_force[c, d]
                )
                slip_force[c, d] = force
        if settled:
            break
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
    return v_new, forces, elongation, passes, residual


def implicit_velocities(springs, J, A0, b0, free, v_free, depth, dt, options):
    """``implicit_spring_velocities`` with any base system A₀ v⁺ = b₀ (N, N) sparse
    (``dynamics.generalized.implicit_base``: the cloth's linearized springs for cloth vertices
    under backward Euler) and the Jacobian J (3C, N) sparse, solved by SciPy (``linear_solver``
    "direct", or "cg" there): the path of cloth under backward Euler and of the direct solver.
    ``free`` (N,) bool. Returns what ``implicit_spring_velocities`` returns."""
    h = dt
    C = len(depth)
    k, c, k_t, c_t = springs.stiffness, springs.damping, springs.friction_stiffness, springs.friction_damping
    engaged = depth - h * (J @ v_free)[0::3] > 0.0
    sticks = engaged & (springs.friction > 0.0)
    slip_force = np.zeros((C, 2))
    keep = sp.diags(free.astype(float))
    v_new, residual = v_free, 0.0
    for passes in range(1, options.implicit_iterations + 1):
        weight = np.column_stack(
            [engaged * h * (h * k + c), np.repeat((sticks * h * (h * k_t + c_t))[:, None], 2, axis=1)]
        )
        pull = np.column_stack(
            [engaged * k * depth, np.where(sticks[:, None], -k_t[:, None] * springs.elongation, slip_force)]
        )
        A = (A0 + keep @ (J.T @ sp.diags(weight.ravel()) @ J) @ keep).tocsr()
        rhs = b0 + free * (h * (J.T @ pull.ravel()))
        v_new = _solve(A, rhs, v_new, options)
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
        new_slip_force = slip_direction * limit[:, None]  # μ F_n⁺ along it, F_n⁺ of this pass
        settled = (
            np.array_equal(now_engaged, engaged)
            and np.array_equal(now_sticks, sticks)
            and np.allclose(new_slip_force, slip_force, rtol=1e-6, atol=1e-9 * max(1.0, limit.max(initial=0.0)))
        )
        engaged, sticks, slip_force = now_engaged, now_sticks, new_slip_force
        if settled:
            break
    # return mapping: an anchor spring never pulls harder than μ F_n at the end of the step
    tangential = np.where(sticks[:, None], trial, slip_force)
    size, limit = np.linalg.norm(tangential, axis=1), springs.friction * normal
    over = size > limit
    tangential[over] *= (limit[over] / size[over])[:, None]
    elongation = np.where((sticks & ~over)[:, None], elongation, -tangential / k_t[:, None])
    elongation[~engaged] = 0.0
    return v_new, np.column_stack([normal, tangential]), elongation, passes, residual


def _solve(A, rhs, guess, options):
    if options.linear_solver == "direct":  # A is symmetric positive definite (conjugate gradients need it too)
        return factor_symmetric(A).solve(rhs)
    diagonal = A.diagonal()
    preconditioner = spla.LinearOperator(A.shape, matvec=lambda x: x / diagonal)
    solution, info = spla.cg(A, rhs, x0=guess, rtol=options.linear_tolerance, maxiter=10 * A.shape[0], M=preconditioner)
    return solution


# ---- the step: loop L1 --------------------------------------------------------------------


def step(model, state, dt, options, integrator="symplectic_euler"):
    """One step of loop L1 with penalty forces; returns (new State, StepInfo). Its compiled stages
    are called one by one from Python; ``simulate`` steps the scenes the compiled loop serves
    (methods.velocity_loop, ``penalty_step``) through that loop instead, which gives the very
    same numbers."""
    h, settings = dt, spring_settings(options, integrator)
    # 1. collision detection, with the gaps this step's motion could close
    sweep = swept_distances(model, *state.velocities, h)
    contacts = collide(
        model,
        state,
        options.contact_margin,
        sweep,
        options.granularity,
        options.normal,
        options.samples,
        cloth_samples=options.cloth_samples,
    )
    rows = rows_of(model, contacts, state.body_position, state.body_orientation)
    offsets, _ = values_by_id(
        state.carried.get("anchor_ids"), state.carried.get("anchor_offsets"), contacts.feature_id, 3
    )
    springs = springs_of(
        settings,
        contact_stiffness(model, state, contacts, options),
        rows.k[:, :3],
        contacts.restitution,
        contacts.friction,
        offsets,
        contacts.tangent1,
        contacts.tangent2,
    )
    v = stack(*state.velocities)
    # 2. collision forces F = k δ n and anchor springs (P1, F3), at the current state
    forces, elongation = spring_forces(springs, contacts.depth, row_products(rows, v))
    # 3. internal forces (gravity) → free velocities v* = v + h M⁻¹ f
    v_free = stack(*free_velocities(model, state, h, integrator))
    # 4. integrate velocities and positions, the contact forces distributed as Jᵀ F (D1); the
    # springs by backward Euler (M1) under that integrator, or where an explicit step would grow
    passes, residual = 0, 0.0
    implicit = springs_implicit(
        settings, springs, *contact_entities(contacts, model.body_count), model.body_count + model.particle_count, h
    )
    if implicit:
        v_new, forces, elongation, passes, residual = _implicit(
            model, state, contacts, springs, rows, v_free, h, options, integrator
        )
        moved_by = v_new
    else:
        v_new = explicit_velocities(rows, forces, v_free, h)
        moved_by = v if integrator == "explicit_euler" else v_new
    # 4b. over the swept step: no contact carried past half its pass-through depth
    held = hold_back(model, state, contacts, rows, moved_by, h) if contacts.count else moved_by
    if held is not moved_by:
        v_new = v_new + (held - moved_by) if integrator == "explicit_euler" and not implicit else held
        moved_by = held
    positions = advance_positions(*state.positions, *unstack(moved_by, model.body_count), h, h)
    # 5. advance dt; the anchors of pressed contacts go on, by contact id
    elongation, offsets, energy = anchors_after(
        springs, rows, contacts.depth, moved_by, elongation, not implicit, contacts.tangent1, contacts.tangent2, h
    )
    carried = dict(state.carried, anchor_ids=contacts.feature_id, anchor_offsets=offsets)
    new = State.assemble(state.time + dt, positions, unstack(v_new, model.body_count), carried)
    return new, StepInfo(
        contacts,
        solver_iterations=passes,
        solver_residual=residual,
        energy_elastic=energy,
        implicit_springs=implicit and integrator != "backward_euler",
        impulses=h * forces,
    )


def _implicit(model, state, contacts, springs, rows, v_free, h, options, integrator):
    """The springs by backward Euler: the compiled matrix-free solve where the system without
    contacts is M (no cloth stepped implicitly) and the solver is "cg"; else with SciPy on the
    assembled system (``implicit_velocities``)."""
    if options.linear_solver == "cg" and not (model.spring_count and integrator == "backward_euler"):
        mass = mass_blocks(
            np.asarray(model.body_mass, dtype=float),
            np.asarray(model.body_inertia, dtype=float),
            rotations.matrices(np.ascontiguousarray(state.body_orientation, dtype=float)),
            np.asarray(model.particle_mass, dtype=float),
        )
        return implicit_spring_velocities(
            spring_settings(options, integrator),
            springs,
            rows,
            contacts.depth,
            v_free,
            mass,
            free_dofs(model.particle_pinned, np.asarray(model.body_kinematic, dtype=np.bool_)),
            h,
        )
    J = jacobian(contacts, state.body_position, model.body_count, model.particle_count)
    A0, b0, free = implicit_base(model, state, h, v_free, cloth_implicit=integrator == "backward_euler")
    return implicit_velocities(springs, J, A0, b0, free, v_free, contacts.depth, h, options)
