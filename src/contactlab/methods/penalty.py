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

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numba import njit
import scipy.sparse.linalg as spla

from ..collision import collide, pass_through_depths, swept_distances
from ..contacts import jacobian, values_by_id
from ..dynamics.generalized import implicit_base, inverse_mass_matrix, stack, unstack
from ..dynamics.integrators import advance_positions, factor_symmetric, free_velocities
from ..errors import InputError
from ..state import State
from ..validation import check_choices, check_counts, number, time_step
from . import CollisionOptions, StepInfo
from .sequential import rows_of, solve_order, solve_sequential_impulses, sweep_groups

ACCURATE_FREQUENCY_STEP = 0.25    # h ω of one spring under "auto": 25 steps per period (a box on four corners rings 2× faster)
LINEAR_SOLVERS = ("cg", "direct")
IMPLICIT_SPRINGS = ("auto", "always", "never")


@dataclass
class Options(CollisionOptions):
    """Settings of ``[method.penalty]`` (after the collision settings of CollisionOptions)."""
    stiffness: object = "auto"            # N/m per contact point, or "auto": each contact's load over allowed_penetration
    allowed_penetration: float = 0.0003   # m: how deep "auto" stiffness lets each contact sink under the load it carries
    damping_ratio: object = "restitution"  # ζ of each contact spring, or "restitution": ζ from the material's ε
    friction_stiffness: object = "auto"   # N/m of the anchor springs (F3), or "auto": the normal stiffness
    contact_margin: float = 0.001         # m: gaps this small are detected (their springs are slack)
    linear_solver: str = "cg"             # backward Euler: cg (conjugate gradients, Jacobi-preconditioned) | direct (sparse LU)
    linear_tolerance: float = 1e-10       # backward Euler with cg: relative residual to reach
    implicit_iterations: int = 8          # backward Euler: most passes to settle which springs act / slip
    implicit_springs: str = "auto"        # auto: contact springs by backward Euler in the steps where the explicit step is unstable | always | never

    def __post_init__(self):
        super().__post_init__()
        self.stiffness = _stiffness(self.stiffness, "stiffness")
        self.friction_stiffness = _stiffness(self.friction_stiffness, "friction_stiffness")
        self.allowed_penetration = number(self.allowed_penetration, "allowed_penetration", 0.0, strict=True)
        if self.damping_ratio != "restitution":
            if isinstance(self.damping_ratio, str):
                raise InputError("damping_ratio", f"expected a number ≥ 0 or \"restitution\", "
                                 f"found {self.damping_ratio!r}")
            self.damping_ratio = number(self.damping_ratio, "damping_ratio", 0.0)
        self.linear_tolerance = number(self.linear_tolerance, "linear_tolerance", 0.0, strict=True)
        check_choices(self, {"linear_solver": LINEAR_SOLVERS, "implicit_springs": IMPLICIT_SPRINGS})
        check_counts(self, {"implicit_iterations": 1})


def _stiffness(value, name):
    if value == "auto":
        return value
    if isinstance(value, str):
        raise InputError(name, f"expected a stiffness in N/m or \"auto\", found {value!r}")
    return number(value, name, 0.0, strict=True)


# ---- guidance for k -----------------------------------------------------------------------

@dataclass
class StiffnessAdvice:
    """What ``suggest_stiffness`` proposes, and why."""
    stiffness: float        # N/m: the proposal
    needed: float           # N/m: holds the load with the allowed penetration
    stable_limit: float     # N/m: symplectic Euler diverges above this (h ω = 2) for the contact mass
    accurate_limit: float   # N/m: h ω = 0.5, about 12 steps per oscillation of a contact spring
    penetration: float      # m: the resting penetration under the load with the proposal
    reason: str             # one sentence


def suggest_stiffness(mass, dt, allowed_penetration, gravity=9.81, contacts=1, contact_mass=None,
                      integrator="symplectic_euler") -> StiffnessAdvice:
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
        reason = (f"a penetration of {allowed_penetration:g} m needs k = {needed:.4g} N/m, more than explicit "
                  f"integration follows at dt = {dt:g} s (k ≤ {accurate:.4g} N/m); capped there, so the load "
                  f"sinks {mass * gravity / (contacts * k):.3g} m: use dt ≤ {step_needed:.3g} s or "
                  f"integrator = \"backward_euler\" for less")
    return StiffnessAdvice(k, needed, stable, accurate, mass * gravity / (contacts * k), reason)


def amplification(integrator, dt, stiffness, mass, damping=0.0) -> float:
    """Spectral radius of one step of a single contact spring (mass [kg], stiffness [N/m],
    damping [N s/m]) under ``integrator``: above 1 its oscillation grows every step."""
    w2, d = stiffness / mass * dt * dt, damping / mass * dt
    if integrator == "symplectic_euler":       # v⁺ = v − (ω²h x + 2ζω h v),  x⁺ = x + h v⁺   (x in units of h)
        step = np.array([[1.0 - w2, 1.0 - d], [-w2, 1.0 - d]])
    elif integrator == "explicit_euler":       # x⁺ = x + h v,  v⁺ = v − h(ω² x + c/m v)
        step = np.array([[1.0, 1.0], [-w2, 1.0 - d]])
    else:                                      # backward Euler: the same at the new state
        step = np.linalg.inv(np.array([[1.0, -1.0], [w2, 1.0 + d]]))
    return float(np.max(np.abs(np.linalg.eigvals(step))))


def damping_ratio_from_restitution(restitution):
    """ζ of a spring-damper contact that rebounds with the coefficient ε (array or scalar):
    ε = exp(−ζ π / √(1 − ζ²)), so ζ = −ln ε / √(π² + ln² ε); ε = 0 gives ζ = 1 (critical)."""
    e = np.clip(np.asarray(restitution, dtype=float), 1e-300, 1.0)
    log = np.log(e)
    return np.where(np.asarray(restitution) <= 0.0, 1.0, -log / np.sqrt(np.pi ** 2 + log ** 2))


def lightest_contact_mass(model) -> float:
    """The smallest mass a single contact spring can move [kg]: a particle's mass, or for a body
    1 / (1/m + R²/I_min) — a push at its farthest point R, turning it about its weakest axis."""
    masses = [np.inf]
    if model.body_count:
        reach = model.body_radii
        masses.append(np.min(1.0 / (model.body_inverse_mass + reach ** 2 / model.body_inertia.min(axis=1))))
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
        ratios = ([options.damping_ratio] if options.damping_ratio != "restitution"
                  else damping_ratio_from_restitution(np.unique(model.material_restitution)).tolist())
        for k in (options.stiffness, options.friction_stiffness):
            if k == "auto":
                continue
            worst = max(amplification(integrator, dt, k, light, 2.0 * z * np.sqrt(k * light)) for z in ratios)
            if worst > 1.0 + 1e-12:
                limit = 2.0 * np.sqrt(light / k)
                instead = (f"use dt < {limit:.3g} s, a stiffness below {light * (2.0 / dt) ** 2:.3g} N/m, "
                           if integrator == "symplectic_euler" else "use damping, ")
                return (f"dt = {dt:g} s is too long for penalty stiffness {k:.4g} N/m under {integrator} (a "
                        f"contact moving {light:.3g} kg grows {worst:.3g}× a step): {instead}implicit_springs = "
                        f"\"auto\" or integrator = \"backward_euler\"")
    return f"use a smaller dt than {dt:g} s, or integrator = \"backward_euler\""


# ---- the load each contact carries ----------------------------------------------------------

SUPPORT_COSINE = 0.3      # a contact whose normal is within 72° of "up" (against gravity) supports its upper side


def contact_entities(contacts, body_count):
    """Each contact's two sides as entities (bodies 0..B−1, then particles B..B+P−1; a point on
    a cloth triangle counts as its first vertex; −1 a static side): (side A (C,), side B (C,))."""
    return tuple(np.where(body >= 0, body, np.where(particles[:, 0] >= 0, body_count + particles[:, 0], -1))
                 for body, particles in ((contacts.body_a, contacts.particles_a),
                                         (contacts.body_b, contacts.particles_b)))


@njit(cache=True)
def supported_loads(entity_a, entity_b, normal, body_position, particle_position, body_mass, particle_mass,
                    gravity):
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
    upper = np.full(C, -1)                # the supported side's entity (bodies, then particles), −1: none
    lower = np.full(C, -1)
    supports = np.zeros(B + P, dtype=np.int64)
    for c in range(C):
        a, b = entity_a[c], entity_b[c]
        along = normal[c, 0] * up[0] + normal[c, 1] * up[1] + normal[c, 2] * up[2]     # normal: from B into A
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
    carried = weight.copy()               # own weight plus everything handed down so far
    start = np.zeros(B + P + 1, dtype=np.int64)     # the contacts each entity rests on, grouped
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
        if upper[c] < 0:                  # a side contact: the lighter dynamic side's share
            least = np.inf
            for e in (entity_a[c], entity_b[c]):
                if e >= 0 and own_share[e] > 0.0:       # weightless: a kinematic body, a driven side
                    least = min(least, own_share[e])
            loads[c] = least if least < np.inf else 0.0
    return loads




# ---- the contact springs ------------------------------------------------------------------

@dataclass
class ContactSprings:
    """The springs of C contacts, as this step sees them."""
    stiffness: np.ndarray            # (C,) k [N/m]
    damping: np.ndarray              # (C,) c [N s/m] along the normal
    friction_stiffness: np.ndarray   # (C,) k_t [N/m] of the anchor springs
    friction_damping: np.ndarray     # (C,) c_t [N s/m]
    friction: np.ndarray             # (C,) μ
    elongation: np.ndarray           # (C, 2) s = point − anchor in (t1, t2) components [m]
    inverse_effective_mass: np.ndarray = None   # (C, 3) J M⁻¹ Jᵀ of the normal and tangent rows [1/kg]


def contact_stiffness(model, state, contacts, options):
    """k (C,) [N/m] of each contact's normal spring: the option's number, or for "auto" the load
    the contact carries (``supported_loads``) over ``allowed_penetration``, so every contact of
    a stack sinks about that far however much rests on it."""
    if options.stiffness != "auto":
        return np.full(contacts.count, float(options.stiffness))
    loads = supported_loads(*contact_entities(contacts, model.body_count), contacts.normal,
                            state.body_position, state.particle_position,
                            np.where(model.body_kinematic, 0.0, model.body_mass), np.asarray(model.particle_mass, dtype=float),
                            np.asarray(model.gravity, dtype=float))
    return loads / options.allowed_penetration


def contact_springs(contacts, J, inverse_mass, carried, options, stiffness=None):
    """The springs of the contacts: stiffness ``stiffness`` (C,) [N/m] (``contact_stiffness``;
    None: the option's number), damping c = 2 ζ √(k m_eff) with each contact's effective mass
    m_eff = 1 / (J M⁻¹ Jᵀ) along its normal (and tangent), friction stiffness the normal one
    where "auto", and the anchor elongations carried from the last step (turned into the
    current tangent plane)."""
    C = contacts.count
    inverse_effective = np.asarray((J @ inverse_mass).multiply(J).sum(axis=1)).ravel().reshape(C, 3)
    if options.damping_ratio == "restitution":
        zeta = damping_ratio_from_restitution(contacts.restitution)
    else:
        zeta = np.full(C, options.damping_ratio)

    def damping(k, inverse_mass_along):
        with np.errstate(divide="ignore", invalid="ignore"):     # 0/0: two immovable sides
            return np.where(inverse_mass_along > 0.0, 2.0 * zeta * np.sqrt(k / inverse_mass_along), 0.0)

    k = np.full(C, float(options.stiffness)) if stiffness is None else np.asarray(stiffness, dtype=float)
    k_t = k.copy() if options.friction_stiffness == "auto" else np.full(C, float(options.friction_stiffness))
    offsets, _ = values_by_id(carried.get("anchor_ids"), carried.get("anchor_offsets"), contacts.feature_id, 3)
    # the anchor's offset in the current tangent plane, its length kept (the plane may have turned)
    elongation = np.stack([np.einsum("ci,ci->c", offsets, contacts.tangent1),
                           np.einsum("ci,ci->c", offsets, contacts.tangent2)], axis=1)
    length, projected = np.linalg.norm(offsets, axis=1), np.linalg.norm(elongation, axis=1)
    elongation *= np.where(projected > 0.0, length / np.maximum(projected, 1e-300), 0.0)[:, None]
    return ContactSprings(k, damping(k, inverse_effective[:, 0]), k_t, damping(k_t, inverse_effective[:, 1]),
                          contacts.friction, elongation, inverse_effective)


def explicit_unstable(springs, contacts, dt, integrator, model):
    """Whether the explicit ``integrator`` at dt [s] would amplify the contact springs' motion
    (``amplification`` > 1). Each body or particle rings at most at ω² = Σ k J M⁻¹ Jᵀ over the
    rows of the springs that hold it (a Gershgorin bound: a box on four corners, each with a
    normal and two anchor springs, rings √12 times faster than one spring alone), damped at the
    largest damping ratio among the contacts."""
    if contacts.count == 0:
        return False
    inverse = springs.inverse_effective_mass
    rows = springs.stiffness * inverse[:, 0] + springs.friction_stiffness * (inverse[:, 1] + inverse[:, 2])
    entities = np.zeros(model.body_count + model.particle_count)
    for entity in contact_entities(contacts, model.body_count):
        np.add.at(entities, entity[entity >= 0], rows[entity >= 0])
    omega_squared = float(entities.max(initial=0.0))
    if omega_squared <= 0.0:
        return False
    with np.errstate(divide="ignore", invalid="ignore"):
        zeta = np.where(springs.stiffness > 0.0,
                        springs.damping * np.sqrt(inverse[:, 0]) / (2.0 * np.sqrt(springs.stiffness)), 0.0)
    omega = np.sqrt(omega_squared)
    return amplification(integrator, dt, omega_squared, 1.0, 2.0 * float(np.nanmax(zeta)) * omega) > 1.0 + 1e-12


def spring_forces(springs, depth, velocity):
    """Contact forces at penetration ``depth`` (C,) [m] and contact-point relative velocities
    ``velocity`` (C, 3) = (v_n, v_t1, v_t2) [m/s] (that is, J v reshaped).

    Normal (P1 with damping): F_n = k δ − c v_n where δ > 0, never negative (C2). Friction
    (F3): the anchor spring's pull F_t = −k_t s − c_t v_t; if |F_t| > μ F_n the contact slips:
    F_t is cut to μ F_n and the anchor is moved so the spring alone pulls that hard. Returns
    (forces (C, 3) = (F_n, F_t1, F_t2) [N], elongation after slipping (C, 2) [m]).
    """
    normal = np.where(depth > 0.0, np.maximum(springs.stiffness * depth - springs.damping * velocity[:, 0], 0.0),
                      0.0)
    tangential = (-springs.friction_stiffness[:, None] * springs.elongation
                  - springs.friction_damping[:, None] * velocity[:, 1:])
    limit = springs.friction * normal
    size = np.linalg.norm(tangential, axis=1)
    slips = size > limit
    tangential[slips] *= (limit[slips] / size[slips])[:, None]
    elongation = springs.elongation.copy()
    elongation[slips] = -tangential[slips] / springs.friction_stiffness[slips, None]
    return np.column_stack([normal, tangential]), elongation


def elastic_energy(springs, depth, elongation) -> float:
    """Energy stored in the springs [J]: Σ ½ k δ² over compressed contacts (P3), plus ½ k_t |s|²
    of their anchor springs."""
    pressed = depth > 0.0
    return float(0.5 * np.sum(springs.stiffness[pressed] * depth[pressed] ** 2)
                 + 0.5 * np.sum(springs.friction_stiffness[pressed] * np.sum(elongation[pressed] ** 2, axis=1)))


def distribute(J, inverse_mass, forces, dt):
    """Velocity change (N,) of the degrees of freedom from contact forces (C, 3) = (F_n, F_t1,
    F_t2) [N] acting for dt [s]: h M⁻¹ Jᵀ F (D1). For a particle that is h F / m, for a body
    h F / m and h I⁻¹ (r × F), for a point on a triangle each vertex's share w_i h F / m_i."""
    return dt * (inverse_mass @ (J.T @ forces.ravel()))


# ---- the swept step: nothing passes through ----------------------------------------------

PASS_THROUGH_FRACTION = 0.5   # of a contact's pass-through depth: the deepest overlap a step may carry it to
GUARD_SWEEPS, GUARD_TOLERANCE = 100, 1e-6      # sweeps, m/s of the guard's solve


def hold_back(model, state, contacts, J, velocity, h):
    """The generalized velocity (N,) with which the step moves, held back where it would carry a
    contact past half its pass-through depth D (``collision.pass_through_depths``): every contact
    found over the swept step, open or closed, keeps v_n ≥ −(D/2 − δ) / h, δ its depth now [m].
    A gap may close and a spring engage as deep as it likes short of that; a fast or small body
    that no spring of this stiffness could stop in time stops on the surface instead of passing
    through (normal impulses only, by sequential sweeps). ``velocity`` itself where nothing would;
    J (3C, N): the step's Jacobian, which tells that without the sweeps' rows."""
    limit = PASS_THROUGH_FRACTION * pass_through_depths(model, contacts)
    slowest = -(limit - contacts.depth) / h
    if not ((J @ velocity)[0::3] < slowest).any():
        return velocity
    rows = rows_of(model, contacts, state.body_position, state.body_orientation)
    held = velocity.copy()
    solve_sequential_impulses(rows, np.zeros(contacts.count), slowest, held, GUARD_SWEEPS, GUARD_TOLERANCE,
                              np.zeros((contacts.count, 3)), *sweep_groups(rows, contacts, state,
                                                                           solve_order(contacts, model.gravity)))
    return held


# ---- backward Euler -----------------------------------------------------------------------

def implicit_velocities(springs, J, A0, b0, free, v_free, depth, dt, options):
    """Backward Euler for the contact springs: v⁺ with A₀ v⁺ = b₀ + h Jᵀ F(x + h v⁺, v⁺), where
    A₀ v⁺ = b₀ is the step without contacts (``dynamics.generalized.implicit_base``: M v⁺ = M v* for rigid bodies and
    free particles, the cloth's linearized springs for cloth vertices); ``free`` (N,) bool masks
    the DOFs that may move, v_free (N,) the velocities without contacts.

    The springs are linear in v⁺ along the Jacobian fixed at x: δ⁺ = δ − h J_n v⁺ and
    s⁺ = s + h J_t v⁺, so an engaged normal spring adds h (h k + c) J_nᵀ J_n to the matrix and
    h k δ J_nᵀ to the right-hand side, and a sticking anchor spring likewise along J_t.

    Friction is settled first, as in plasticity's return mapping: a pass with every pressed
    contact sticking (the elastic predictor) says which anchor springs would pull harder than
    μ F_n; those contacts slip in the direction of that pull, with the force μ F_n⁺ of the
    latest pass. Then the engaged normal springs (F_n⁺ > 0) and the slip forces are found by
    repeating the solve until they stop changing (an active-set iteration; for convex energies
    such as a plane's, and no friction, it is the exact backward Euler step, which never adds
    energy). Returns (v⁺ (N,), forces (C, 3), elongation after the
    step (C, 2), passes, relative residual of the last linear solve).
    """
    h = dt
    C = len(depth)
    k, c, k_t, c_t = springs.stiffness, springs.damping, springs.friction_stiffness, springs.friction_damping
    engaged = depth - h * (J @ v_free)[0::3] > 0.0
    sticks = engaged & (springs.friction > 0.0)
    slip_force = np.zeros((C, 2))
    keep = sp.diags(free.astype(float))
    v_new, residual = v_free, 0.0
    for passes in range(1, options.implicit_iterations + 1):
        weight = np.column_stack([engaged * h * (h * k + c),
                                  np.repeat((sticks * h * (h * k_t + c_t))[:, None], 2, axis=1)])
        pull = np.column_stack([engaged * k * depth,
                                np.where(sticks[:, None], -k_t[:, None] * springs.elongation, slip_force)])
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
        if passes == 1:              # the elastic predictor decides who slips, and which way
            slips = sticks & (size > limit)
            slip_direction = np.where(slips[:, None], trial / np.maximum(size, 1e-300)[:, None], 0.0)
            now_sticks = sticks & ~slips
        else:
            now_sticks = sticks & now_engaged
        new_slip_force = slip_direction * limit[:, None]      # μ F_n⁺ along it, F_n⁺ of this pass
        settled = (np.array_equal(now_engaged, engaged) and np.array_equal(now_sticks, sticks)
                   and np.allclose(new_slip_force, slip_force, rtol=1e-6, atol=1e-9 * max(1.0, limit.max(initial=0.0))))
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
    if options.linear_solver == "direct":     # A is symmetric positive definite (conjugate gradients need it too)
        return factor_symmetric(A).solve(rhs)
    diagonal = A.diagonal()
    preconditioner = spla.LinearOperator(A.shape, matvec=lambda x: x / diagonal)
    solution, info = spla.cg(A, rhs, x0=guess, rtol=options.linear_tolerance, maxiter=10 * A.shape[0],
                             M=preconditioner)
    return solution


# ---- the step: loop L1 --------------------------------------------------------------------

def step(model, state, dt, options, integrator="symplectic_euler"):
    """One step of loop L1 with penalty forces; returns (new State, StepInfo)."""
    h = dt
    # 1. collision detection, with the gaps this step's motion could close
    sweep = swept_distances(model, *state.velocities, h)
    contacts = collide(model, state, options.contact_margin, sweep, options.granularity, options.normal,
                       options.samples, cloth_samples=options.cloth_samples)
    J = jacobian(contacts, state.body_position, model.body_count, model.particle_count)
    inverse_mass = inverse_mass_matrix(model, state.body_orientation)
    springs = contact_springs(contacts, J, inverse_mass, state.carried, options,
                              contact_stiffness(model, state, contacts, options))
    v = stack(*state.velocities)
    # 2. collision forces F = k δ n and anchor springs (P1, F3), at the current state
    forces, elongation = spring_forces(springs, contacts.depth, (J @ v).reshape(-1, 3))
    # 3. internal forces (gravity) → free velocities v* = v + h M⁻¹ f
    v_free = stack(*free_velocities(model, state, h, integrator))
    # 4. integrate velocities and positions, the contact forces distributed as Jᵀ F (D1); the
    # springs by backward Euler (M1) under that integrator, or where an explicit step would grow
    passes, residual = 0, 0.0
    implicit = integrator == "backward_euler" or (contacts.count > 0 and (
        options.implicit_springs == "always"
        or (options.implicit_springs == "auto"
            and explicit_unstable(springs, contacts, h, integrator, model))))
    if implicit:
        A0, b0, free = implicit_base(model, state, h, v_free, cloth_implicit=integrator == "backward_euler")
        v_new, forces, elongation, passes, residual = implicit_velocities(
            springs, J, A0, b0, free, v_free, contacts.depth, h, options)
        moved_by = v_new
    else:
        v_new = v_free + distribute(J, inverse_mass, forces, h)
        moved_by = v if integrator == "explicit_euler" else v_new
    # 4b. over the swept step: no contact carried past half its pass-through depth
    held = hold_back(model, state, contacts, J, moved_by, h) if contacts.count else moved_by
    if held is not moved_by:
        v_new = v_new + (held - moved_by) if integrator == "explicit_euler" and not implicit else held
        moved_by = held
    if not implicit:
        # the anchors follow the point's tangential motion over the step
        elongation = elongation + h * (J @ moved_by).reshape(-1, 3)[:, 1:]
    positions = advance_positions(*state.positions, *unstack(moved_by, model.body_count), h, h)
    # 5. advance dt; the anchors of pressed contacts go on, by contact id
    depth_after = contacts.depth - h * (J @ moved_by)[0::3]
    elongation[depth_after <= 0.0] = 0.0
    carried = dict(state.carried, anchor_ids=contacts.feature_id,
                   anchor_offsets=elongation[:, :1] * contacts.tangent1 + elongation[:, 1:] * contacts.tangent2)
    new = State.assemble(state.time + dt, positions, unstack(v_new, model.body_count), carried)
    return new, StepInfo(contacts, solver_iterations=passes, solver_residual=residual,
                         energy_elastic=elastic_energy(springs, depth_after, elongation),
                         implicit_springs=implicit and integrator != "backward_euler", impulses=h * forces)
