"""The compiled stages of penalty contact springs (SPEC P1, P3, F3, M1; loop L1, stages 2–5).

How stiff each contact's spring is (the load it carries over the allowed penetration), its
damping and its anchor (``springs_of``), the forces (``contact_spring_forces``, P1 and F3) and the
energy they store (P3), whether an explicit step would amplify them (``step_amplification``,
``springs_implicit``), the velocities they give (``explicit_velocities``), the guard that holds
a contact short of passing through (``slowest_approach``) and the anchors carried on
(``anchors_after``). :mod:`contactlab.methods.penalty`'s ``step`` calls them one by one from
Python and the compiled loop (:mod:`contactlab.methods.loop_steps`, ``penalty_step``) in
compiled code; the springs by backward Euler are :mod:`contactlab.methods.penalty_implicit`.

Arrays: C contacts, B bodies, P particles, N = 6B + 3P degrees of freedom; rows as
``jacobian_rows.ContactRows``.
"""

from __future__ import annotations

from enum import IntEnum
from typing import Any, NamedTuple

import numpy as np

from ..compiling import njit
from ..contacts import ContactArrays
from .jacobian_rows import ContactRows, apply_impulses, contact_velocity, row_products

# ---- one spring's step, and ζ from restitution ---------------------------------------------


class Integrator(IntEnum):
    """The integrators (``dynamics.integrators.INTEGRATORS``, by their names upper-cased) as the
    compiled stages take them: ``SpringSettings.integrator``, ``step_amplification``'s cases."""

    SYMPLECTIC_EULER = 0
    EXPLICIT_EULER = 1
    BACKWARD_EULER = 2


class ImplicitSprings(IntEnum):
    """When the contact springs step by backward Euler (``SpringSettings.implicit``): the Options'
    ``implicit_springs`` "never", "auto" (where the explicit step would grow) and "always", by
    their names upper-cased, and backward Euler's own (every step, by the integrator)."""

    NEVER = 0
    AUTO = 1
    ALWAYS = 2
    BY_INTEGRATOR = 3


@njit(cache=True)
def step_amplification(integrator: Integrator, w2: float, d: float) -> float:
    """``amplification``, compiled, for one of the three integrators; w2 = (h ω)², d = h c / m.
    The 2×2 step matrix on (x / h, v) and the moduli of its eigenvalues in closed form (a complex
    pair: both √det)."""
    if integrator == Integrator.SYMPLECTIC_EULER:  # v⁺ = v − (ω²h x + 2ζω h v),  x⁺ = x + h v⁺   (x in units of h)
        a, b, c, e = 1.0 - w2, 1.0 - d, -w2, 1.0 - d
    elif integrator == Integrator.EXPLICIT_EULER:  # x⁺ = x + h v,  v⁺ = v − h(ω² x + c/m v)
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
    return 1.0 / smallest if integrator == Integrator.BACKWARD_EULER else largest


@njit(cache=True)
def damping_ratios(restitution: np.ndarray) -> np.ndarray:
    """``damping_ratio_from_restitution``, compiled, on an array (C,)."""
    zeta = np.empty(restitution.shape[0])
    for c in range(zeta.shape[0]):
        if restitution[c] <= 0.0:
            zeta[c] = 1.0
        else:
            log = np.log(min(restitution[c], 1.0))
            zeta[c] = -log / np.sqrt(np.pi**2 + log**2)
    return zeta


# ---- the load each contact carries ----------------------------------------------------------

SUPPORT_COSINE = 0.3  # a contact whose normal is within 72° of "up" (against gravity) supports its upper side


@njit(cache=True)
def entities_of(body: np.ndarray, particles: np.ndarray, body_count: int) -> np.ndarray:
    """``contact_entities`` of one side, compiled: body (C,), particles (C, 3) → (C,) int64."""
    out = np.empty(body.shape[0], dtype=np.int64)
    for c in range(body.shape[0]):
        out[c] = body[c] if body[c] >= 0 else (body_count + particles[c, 0] if particles[c, 0] >= 0 else -1)
    return out


@njit(cache=True)
def supported_loads(
    sides: tuple[np.ndarray, np.ndarray],
    normal: np.ndarray,
    positions: tuple[np.ndarray, np.ndarray],
    loads: tuple,
    cloth_of: np.ndarray,
) -> np.ndarray:
    """The weight each contact carries [N] (C,): every body and free particle, from the highest
    down, hands its own weight and what rests on it to the contacts it rests on (normals within
    72° of up, against ``gravity`` (3,) [m/s²]), in equal shares, and those pass it to the body
    or particle below; a static side takes it out. Contacts that support nothing carry the
    lighter side's weight per supporting contact. A kinematic body is given weight 0: it hands
    nothing down and, like a static side, does not count as the lighter side. ``sides`` = (entity
    of side A, of side B) (C,) each, as ``contact_entities`` gives them; normal (C, 3);
    ``positions`` = (bodies (B, 3), particles (P, 3)) [m]; ``loads`` = (body masses (B,),
    particle masses (P,)) [kg], gravity (3,) [m/s²]).

    A cloth's vertices also carry one another's weight along its springs: ``cloth_of`` (B + P,)
    int, the cloth of each body and particle (−1: none). A cloth is one step of the load path,
    like a body: its whole weight and what rests on any of its vertices go, in equal shares, to
    the contacts by which it rests on something other than itself (the foot of a strip standing
    on the floor carries the strip; a cloth lying on another hands its weight to the whole lower
    one), each at least its vertex's own weight (a sheet lying flat: the mean vertex weight, or its own); it
    comes in that order at the mean height of those resting vertices. A contact of a cloth with
    itself (a fold lying on the cloth) carries its vertex's own weight and hands nothing down."""
    (entity_a, entity_b), (body_position, particle_position) = sides, positions
    body_mass, particle_mass, gravity = loads
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
    # the load path's nodes: each body and particle, but a cloth's vertices one node, B + P + its index
    K = max(cloth_of.max() + 1, 0)
    node = np.arange(B + P)
    for e in range(B + P):
        if cloth_of[e] >= 0:
            node[e] = B + P + cloth_of[e]
    N = B + P + K
    external = np.zeros(C, dtype=np.bool_)  # resting on another node (not a cloth on itself)
    node_supports = np.zeros(N, dtype=np.int64)
    carried = np.zeros(N)  # own weight plus everything handed down so far
    members, node_height = np.zeros(N), np.zeros(N)
    for e in range(B + P):
        carried[node[e]] += weight[e]
        node_height[node[e]] += height[e]
        members[node[e]] += 1.0
    node_height /= np.maximum(members, 1.0)  # a body's or particle's height; a cloth's mean height, or
    resting_height, resting = np.zeros(N), np.zeros(N)  # where it rests on something, its resting vertices'
    for c in range(C):
        if upper[c] >= 0 and (lower[c] < 0 or node[lower[c]] != node[upper[c]]):
            external[c] = True
            node_supports[node[upper[c]]] += 1
            resting_height[node[upper[c]]] += height[upper[c]]
            resting[node[upper[c]]] += 1.0
    for n in range(B + P, N):
        if resting[n] > 0.0:
            node_height[n] = resting_height[n] / resting[n]
    start = np.zeros(N + 1, dtype=np.int64)  # the contacts each node rests on, grouped
    for c in range(C):
        if external[c]:
            start[node[upper[c]] + 1] += 1
    for n in range(N):
        start[n + 1] += start[n]
    filled = start[:-1].copy()
    resting_on = np.empty(start[-1], dtype=np.int64)
    for c in range(C):
        if external[c]:
            resting_on[filled[node[upper[c]]]] = c
            filled[node[upper[c]]] += 1
    for n in np.argsort(-node_height, kind="mergesort"):
        if node_supports[n] == 0:
            continue
        share = carried[n] / node_supports[n]
        for i in range(start[n], start[n + 1]):
            c = resting_on[i]
            loads[c] = max(share, own_share[upper[c]])  # a cloth's vertex: at least its own weight
            if lower[c] >= 0:
                carried[node[lower[c]]] += share
    for c in range(C):
        if upper[c] >= 0 and not external[c]:  # a fold resting on its own cloth: its vertex's own weight
            loads[c] = own_share[upper[c]]
    for c in range(C):
        if upper[c] < 0:  # a side contact: the lighter dynamic side's share
            least = np.inf
            for e in (entity_a[c], entity_b[c]):
                if e >= 0 and own_share[e] > 0.0:  # weightless: a kinematic body, a driven side
                    least = min(least, own_share[e])
            loads[c] = least if least < np.inf else 0.0
    return loads


# ---- the contact springs ------------------------------------------------------------------


class ContactSprings(NamedTuple):
    """The springs of C contacts, as this step sees them (a named tuple: compiled code takes it)."""

    stiffness: np.ndarray
    """(C,) k [N/m]"""
    damping: np.ndarray
    """(C,) c [N s/m] along the normal"""
    friction_stiffness: np.ndarray
    """(C,) k_t [N/m] of the anchor springs"""
    friction_damping: np.ndarray
    """(C,) c_t [N s/m]"""
    friction: np.ndarray
    """(C,) μ"""
    elongation: np.ndarray
    """(C, 2) s = point − anchor in (t1, t2) components [m]"""
    inverse_effective_mass: np.ndarray | None = None
    """(C, 3) J M⁻¹ Jᵀ of the normal and tangent rows [1/kg] (None: not known)"""


class SpringSettings(NamedTuple):
    """The penalty Options and integrator as plain numbers, for the compiled stages."""

    stiffness: float
    """N/m, or −1: "auto" (each contact's load over allowed_penetration)"""
    allowed_penetration: float
    """m"""
    damping_ratio: float
    """ζ, or −1: from the material's restitution"""
    friction_stiffness: float
    """N/m, or −1: "auto" (the normal stiffness)"""
    implicit: ImplicitSprings
    integrator: Integrator
    implicit_iterations: int
    """passes of the active set, at most"""
    linear_tolerance: float
    """relative residual of the conjugate gradients"""


@njit(cache=True)
def normal_stiffness(settings: SpringSettings, *loads_of: Any) -> np.ndarray:
    """``contact_stiffness``, compiled: each contact's normal stiffness (C,) [N/m], the fixed one
    of ``settings`` or its supported load over the allowed penetration. ``loads_of``: the
    arguments of ``supported_loads`` (sides, normal, positions, loads, cloth_of), in its order."""
    if settings.stiffness >= 0.0:
        return np.full(loads_of[1].shape[0], settings.stiffness)
    return supported_loads(*loads_of) / settings.allowed_penetration


@njit(cache=True)
def springs_of(
    settings: SpringSettings,
    stiffness: np.ndarray,
    inverse_effective: np.ndarray,
    contacts: ContactArrays,
    offsets: np.ndarray,
) -> ContactSprings:
    """The springs of C ``contacts`` (a ContactArrays: ``Contacts.arrays()`` in a method's step):
    normal stiffness ``stiffness`` (C,) [N/m] (``normal_stiffness``), damping c = 2 ζ √(k m_eff)
    with each contact's effective mass m_eff = 1 / (J M⁻¹ Jᵀ) along its normal (and tangent) from
    ``inverse_effective`` (C, 3) [1/kg] (ζ the option's or from their restitution (C,)), friction
    stiffness the normal one where "auto", μ their friction (C,), and the anchor elongations
    ``offsets`` (C, 3) [m] carried from the last step turned into their tangent plane now (t1, t2
    (C, 3)), their length kept (the plane may have turned)."""
    restitution, friction, tangent1, tangent2 = (
        contacts.restitution,
        contacts.friction,
        contacts.tangent1,
        contacts.tangent2,
    )
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
def springs_unstable(
    springs: ContactSprings, entity_a: np.ndarray, entity_b: np.ndarray, entities: int, h: float, integrator: int
) -> bool:
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
def springs_implicit(
    settings: SpringSettings,
    springs: ContactSprings,
    entity_a: np.ndarray,
    entity_b: np.ndarray,
    entities: int,
    h: float,
) -> bool:
    """Whether this step takes its contact springs by backward Euler: always under that
    integrator or with implicit_springs "always", never with "never" or without contacts, and
    under "auto" where the explicit step would amplify them (``springs_unstable``)."""
    if settings.implicit == ImplicitSprings.BY_INTEGRATOR:
        return True
    if entity_a.shape[0] == 0 or settings.implicit == ImplicitSprings.NEVER:
        return False
    return settings.implicit == ImplicitSprings.ALWAYS or springs_unstable(
        springs, entity_a, entity_b, entities, h, settings.integrator
    )


@njit(cache=True)
def contact_spring_forces(
    springs: ContactSprings, depth: np.ndarray, velocity: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
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
def elastic_energy(springs: ContactSprings, depth: np.ndarray, elongation: np.ndarray) -> float:
    """Energy stored in the springs [J]: Σ ½ k δ² over compressed contacts (P3), plus ½ k_t |s|²
    of their anchor springs; depth (C,) [m], elongation (C, 2) [m]."""
    normal = anchors = 0.0
    for c in range(depth.shape[0]):
        if depth[c] > 0.0:
            normal += springs.stiffness[c] * depth[c] ** 2
            anchors += springs.friction_stiffness[c] * (elongation[c, 0] ** 2 + elongation[c, 1] ** 2)
    return 0.5 * normal + 0.5 * anchors


@njit(cache=True)
def explicit_velocities(rows: ContactRows, forces: np.ndarray, v_free: np.ndarray, h: float) -> np.ndarray:
    """v* + h M⁻¹ Jᵀ F (N,): the contact forces (C, 3) [N] of ``contact_spring_forces`` over h [s]
    added to the free velocities, contact by contact through the rows (``jacobian_rows.apply_impulses``)."""
    v_new = v_free.copy()
    apply_impulses(rows, h * forces, v_new)
    return v_new


@njit(cache=True)
def anchors_after(
    springs: ContactSprings,
    rows: ContactRows,
    contacts: tuple,
    moved_by: np.ndarray,
    elongation: np.ndarray,
    follow: bool,
    h: float,
) -> tuple[np.ndarray, np.ndarray, float]:
    """Stage 5: the anchors at the end of the step moved by ``moved_by`` (N,) over h [s]: where
    ``follow`` (an explicit step) the elongation (C, 2) [m] takes the point's tangential motion
    h v_t; a contact no longer pressed (depth after the step ≤ 0) drops its anchor. ``contacts``
    = (depth (C,) [m], tangent1, tangent2 (C, 3)) as the contacts' fields. Returns
    (elongation (C, 2), the anchor offsets to carry (C, 3) = s₁ t1 + s₂ t2 [m], elastic energy
    at the end of the step [J])."""
    depth, tangent1, tangent2 = contacts
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
def slowest_approach(
    rows: ContactRows, velocity: np.ndarray, depth: np.ndarray, pass_through: np.ndarray, h: float
) -> tuple[np.ndarray, bool]:
    """The guard of ``hold_back``: each contact's least normal velocity v_n ≥ −(D/2 − δ) / h
    (C,) [m/s] from its pass-through depth D (C,) [m] (``collision.half_thickness_sums``) and
    depth δ, and whether ``velocity`` (N,) goes below it anywhere (the rows tell, C × 3)."""
    slowest = -(PASS_THROUGH_FRACTION * pass_through - depth) / h
    below = False
    for c in range(depth.shape[0]):
        below = below or contact_velocity(c, rows, velocity)[0] < slowest[c]
    return slowest, below
