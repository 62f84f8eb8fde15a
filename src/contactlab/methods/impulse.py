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
      ``solve_order``) and warm-started from last step's impulses;
5. recompute velocities and positions: x = x₀ + h v⁺ — so a body at rest stays put — with the
   time-of-impact correction below; advance time.

Time of impact. A contact that was open at the start of the step (gap d₀ > 0) closes at the
fraction τ = d₀ / (−h v_n*) of it. The body travels with v* until then and with v⁺ after, so
its position is x₀ + h(τ v* + (1 − τ) v⁺) (orientation likewise). This is what makes bounce
heights follow h₀ ε²ⁿ instead of bouncing early, from wherever the step happened to end.
"""

from dataclasses import dataclass

import numpy as np
from numba import njit

from ..builder import _number
from ..collision import GRANULARITIES, NORMALS, collide, swept_distances
from ..dynamics.integrators import advance_positions, free_velocities, world_inverse_inertia
from ..errors import InputError
from ..state import State
from . import StepInfo


@dataclass
class Options:
    """Settings of ``[method.impulse]`` (documented with units in docs/methods/impulse.md)."""
    iterations: int = 100                 # sweeps of sequential impulses per step, and collision waves (at most)
    tolerance: float = 1e-6               # m/s: stop sweeping when no impulse changes a velocity more
    restitution_threshold: float = -1.0   # m/s: slower approaches bounce with ε = 0; < 0 means 2·|g|·dt
    stabilization: float = 0.2            # fraction of an existing penetration removed per step (0 = none)
    slop: float = 0.0005                  # m of penetration left alone by the stabilization
    max_push_velocity: float = 1.0        # m/s: the stabilization never pushes apart faster
    time_of_impact: bool = True           # split the step at the impact (see module docs)
    contact_margin: float = 0.002         # m: gaps this small become (speculative) contacts
    warm_start: float = 1.0               # fraction of last step's impulses to start from (0 = cold)
    granularity: str = "vertex"           # boxes and hulls on static surfaces: object | vertex | samples (P2)
    normal: str = "object"                # their contact normal: object (P4) | vertex (P5)
    samples: int = 2                      # samples per triangle edge for granularity = "samples"

    def __post_init__(self):
        if isinstance(self.iterations, bool) or not isinstance(self.iterations, int) or self.iterations < 1:
            raise InputError("iterations", f"expected a whole number ≥ 1, found {self.iterations!r}")
        self.tolerance = _number(self.tolerance, "tolerance", 0.0)
        self.restitution_threshold = _number(self.restitution_threshold, "restitution_threshold")
        self.stabilization = _number(self.stabilization, "stabilization", 0.0, maximum=1.0)
        self.slop = _number(self.slop, "slop", 0.0)
        self.max_push_velocity = _number(self.max_push_velocity, "max_push_velocity", 0.0)
        self.contact_margin = _number(self.contact_margin, "contact_margin", 0.0)
        self.warm_start = _number(self.warm_start, "warm_start", 0.0, maximum=1.0)
        for name, allowed in (("granularity", GRANULARITIES), ("normal", NORMALS)):
            if getattr(self, name) not in allowed:
                raise InputError(name, f"expected one of {', '.join(allowed)}, found {getattr(self, name)!r}")
        if isinstance(self.samples, bool) or not isinstance(self.samples, int) or self.samples < 1:
            raise InputError("samples", f"expected a whole number ≥ 1, found {self.samples!r}")
        if not isinstance(self.time_of_impact, bool):
            raise InputError("time_of_impact", f"expected true or false, found {self.time_of_impact!r}")


# ---- the compiled solver: every contact as three rows of J over the generalized velocity ----
#
# The generalized velocity u (6B + 3P,) is the DOF layout of contactlab.contacts: body i owns
# u[6i:6i+3] (linear, m/s) and u[6i+3:6i+6] (world angular, rad/s), particle j owns
# u[6B+3j:6B+3j+3]. A contact touches at most ROW_WIDTH entries of u (6 per rigid-body side,
# 3 per particle of a side). For each contact c and direction d (0: normal, 1: tangent1,
# 2: tangent2) ``jac[c, d]`` holds that row of J (v_n = Σ jac · u[index]) and ``push[c, d]``
# the matching column of M⁻¹ Jᵀ (an impulse λ changes u[index] by λ · push), so that
# k[c, d] = jac · push = dᵀ J M⁻¹ Jᵀ d is the effective inverse mass of R4. Precomputing the
# rows once per step keeps the Gauss-Seidel sweeps to two short dot products per update.

ROW_WIDTH = 18


@njit(cache=True)
def contact_rows(body_a, body_b, particles_a, particles_b, weights_a, weights_b, r_a, r_b,
                 normal, tangent1, tangent2, body_inverse_mass, body_inverse_inertia_world,
                 particle_inverse_mass):
    """The contacts' Jacobian rows over the generalized velocity (see above).

    Shapes: C contacts; r_a, r_b (C, 3) lever arms [m]; body_inverse_inertia_world (B, 3, 3).
    Returns index (C, ROW_WIDTH) int (entries of u), width (C,) int (how many are used),
    jac (C, 3, ROW_WIDTH) [1 or m], push (C, 3, ROW_WIDTH) [1/kg or 1/(kg m)] and
    k (C, 3) [1/kg]: the effective inverse mass of each row.
    """
    C = normal.shape[0]
    B = body_inverse_mass.shape[0]
    index = np.zeros((C, ROW_WIDTH), dtype=np.int64)
    width = np.zeros(C, dtype=np.int64)
    jac = np.zeros((C, 3, ROW_WIDTH))
    push = np.zeros((C, 3, ROW_WIDTH))
    k = np.zeros((C, 3))
    direction = np.empty(3)
    for c in range(C):
        n = 0
        for side in range(2):
            sign = 1.0 if side == 0 else -1.0
            body = body_a[c] if side == 0 else body_b[c]
            if body >= 0:
                r = r_a[c] if side == 0 else r_b[c]
                inverse_inertia = body_inverse_inertia_world[body]
                for i in range(6):
                    index[c, n + i] = 6 * body + i
                for d in range(3):
                    for i in range(3):
                        direction[i] = normal[c, i] if d == 0 else (tangent1[c, i] if d == 1 else tangent2[c, i])
                    a0 = r[1] * direction[2] - r[2] * direction[1]        # r × d
                    a1 = r[2] * direction[0] - r[0] * direction[2]
                    a2 = r[0] * direction[1] - r[1] * direction[0]
                    for i in range(3):
                        jac[c, d, n + i] = sign * direction[i]
                        push[c, d, n + i] = sign * direction[i] * body_inverse_mass[body]
                        jac[c, d, n + 3 + i] = sign * (a0 if i == 0 else (a1 if i == 1 else a2))
                        push[c, d, n + 3 + i] = sign * (inverse_inertia[i, 0] * a0 + inverse_inertia[i, 1] * a1
                                                        + inverse_inertia[i, 2] * a2)
                n += 6
            for m in range(3):
                p = particles_a[c, m] if side == 0 else particles_b[c, m]
                if p < 0:
                    continue
                w = weights_a[c, m] if side == 0 else weights_b[c, m]
                for i in range(3):
                    index[c, n + i] = 6 * B + 3 * p + i
                for d in range(3):
                    for i in range(3):
                        value = normal[c, i] if d == 0 else (tangent1[c, i] if d == 1 else tangent2[c, i])
                        jac[c, d, n + i] = sign * w * value
                        push[c, d, n + i] = sign * w * value * particle_inverse_mass[p]
                n += 3
        width[c] = n
        for d in range(3):
            total = 0.0
            for e in range(n):
                total += jac[c, d, e] * push[c, d, e]
            k[c, d] = total
    return index, width, jac, push, k


@njit(cache=True, inline="always")
def _row_velocity(c, d, index, width, jac, u):
    """Row d of contact c applied to u: dᵀ(v_A − v_B) at the contact [m/s]."""
    total = 0.0
    for e in range(width[c]):
        total += jac[c, d, e] * u[index[c, e]]
    return total


@njit(cache=True, inline="always")
def _apply(c, d, amount, index, width, push, u):
    """Impulse ``amount`` [N s] along row d of contact c: +amount·d on A, −amount·d on B (R1, R2)."""
    for e in range(width[c]):
        u[index[c, e]] += amount * push[c, d, e]


@njit(cache=True, inline="always")
def _friction_impulse(c, limit, impulses, index, width, jac, push, k, u):
    """Coulomb friction (F2) on top of the accumulated tangential impulse ``impulses[c, 1:3]``.

    The impulse that cancels the tangential relative velocity, with the total kept in the disk
    of radius ``limit`` = μ λ_n [N s]: if it does not stop the sliding the maximum applies,
    against the sliding. Updates ``impulses[c]`` and u; returns the largest velocity change [m/s].
    """
    old1, old2 = impulses[c, 1], impulses[c, 2]
    new1 = old1 - _row_velocity(c, 1, index, width, jac, u) / k[c, 1]
    new2 = old2 - _row_velocity(c, 2, index, width, jac, u) / k[c, 2]
    magnitude = np.sqrt(new1 * new1 + new2 * new2)
    if magnitude > limit:
        scale = limit / magnitude
        new1 *= scale
        new2 *= scale
    _apply(c, 1, new1 - old1, index, width, push, u)
    _apply(c, 2, new2 - old2, index, width, push, u)
    impulses[c, 1], impulses[c, 2] = new1, new2
    return max(abs(new1 - old1) * k[c, 1], abs(new2 - old2) * k[c, 2])


@njit(cache=True, inline="always")
def _solve_contact(c, target, impulses, index, width, jac, push, k, friction, u):
    """One Gauss-Seidel update of contact c (C7 on velocities): the normal impulse that brings
    v_n to ``target`` [m/s] with the accumulated impulse kept ≥ 0 (C2), then friction kept in
    the disk μ λ_n (F2). Updates ``impulses[c]`` [N s] and u; returns the largest velocity
    change it made [m/s]."""
    vn = _row_velocity(c, 0, index, width, jac, u)
    old = impulses[c, 0]
    impulses[c, 0] = max(0.0, old - (vn - target) / k[c, 0])
    _apply(c, 0, impulses[c, 0] - old, index, width, push, u)
    change = abs(impulses[c, 0] - old) * k[c, 0]
    if friction[c] > 0.0:
        change = max(change, _friction_impulse(c, friction[c] * impulses[c, 0], impulses, index, width, jac,
                                               push, k, u))
    return change


@njit(cache=True)
def resolve_collisions(index, width, jac, push, k, friction, restitution, gravity_normal, gap_at_start, dt,
                       threshold, u, max_waves, sweeps, tolerance, tau, order):
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

    Rows as from ``contact_rows``; gravity_normal, gap_at_start (C,) [m/s², m]; u the
    generalized velocity (changed in place); ``tau`` (C,) receives each contact's τ, −1 where
    it had no impact; ``order`` (C,) int is the order in which a wave's members are swept (see
    ``solve_order``). Returns the number of waves.
    """
    C = k.shape[0]
    target = np.empty(C)
    closes = np.empty(C)
    impulses = np.zeros((C, 3))
    members = np.empty(C, dtype=np.int64)
    for c in range(C):
        tau[c] = -1.0
    for wave in range(max_waves):
        count = 0
        for o in range(C):
            c = order[o]
            if restitution[c] <= 0.0 or k[c, 0] <= 0.0:
                continue
            vn = _row_velocity(c, 0, index, width, jac, u)
            if vn >= 0.0 or gap_at_start[c] + dt * vn > 0.0:      # separating, or still open at the end
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
        for sweep in range(sweeps):
            change = 0.0
            for m in range(count):
                c = members[m]
                change = max(change, _solve_contact(c, target[c], impulses, index, width, jac, push, k,
                                                    friction, u))
            if change <= tolerance:
                break
    return max_waves


@njit(cache=True)
def solve_sequential_impulses(index, width, jac, push, k, friction, target_normal_velocity, u,
                              iterations, tolerance, initial_impulses, order):
    """Contact impulses with accumulated clamping; changes the generalized velocity u in place (M2).

    ``initial_impulses`` (C, 3) [N s] are applied first (warm starting: last step's impulses
    of the same contacts), then corrected like any accumulated impulse.

    For every contact c (in ``order`` (C,) int, see ``solve_order``; repeatedly): the normal impulse that brings the normal
    relative velocity to ``target_normal_velocity[c]`` [m/s], with the accumulated impulse
    kept ≥ 0 (never attractive, C2), then friction with the accumulated tangential impulse
    kept in the disk μ λ_n (F2). Returns (impulses (C, 3) [N s] as (normal, t1, t2), sweeps
    made, largest velocity change in the last sweep [m/s]).
    """
    C = k.shape[0]
    impulses = initial_impulses.copy()
    for c in range(C):
        for d in range(3):
            _apply(c, d, impulses[c, d], index, width, push, u)
    sweeps = 0
    change = 0.0
    for sweep in range(iterations):
        sweeps = sweep + 1
        change = 0.0
        for o in range(C):
            c = order[o]
            if k[c, 0] <= 0.0:        # static against static: nothing can move
                continue
            change = max(change, _solve_contact(c, target_normal_velocity[c], impulses, index, width, jac, push,
                                                k, friction, u))
        if change <= tolerance:
            break
    return impulses, sweeps, change


def generalized_velocity(body_velocity, body_angular_velocity, particle_velocity):
    """Pack (B, 3), (B, 3), (P, 3) velocities into u (6B + 3P,) in the contacts' DOF layout."""
    B = len(body_velocity)
    u = np.empty(6 * B + 3 * len(particle_velocity))
    bodies = u[:6 * B].reshape(B, 6)
    bodies[:, :3] = body_velocity
    bodies[:, 3:] = body_angular_velocity
    u[6 * B:] = particle_velocity.ravel()
    return u


def split_velocity(u, body_count):
    """Unpack u (6B + 3P,) into copies of (body_velocity, body_angular_velocity, particle_velocity)."""
    bodies = u[:6 * body_count].reshape(body_count, 6)
    return bodies[:, :3].copy(), bodies[:, 3:].copy(), u[6 * body_count:].reshape(-1, 3).copy()


def lever_arms(contacts, body_position):
    """r = point − centre of mass for each side, (C, 3) each; zero for non-body sides."""
    def arm(body):
        r = np.zeros((contacts.count, 3))
        has = body >= 0
        r[has] = contacts.point[has] - body_position[body[has]]
        return r
    return arm(contacts.body_a), arm(contacts.body_b)


def step(model, state, dt, options, integrator="symplectic_euler"):
    """One step of loop L3 with impulses; returns (new State, StepInfo)."""
    # 1. internal forces → free velocities v*
    v_body, w_body, v_particle = free_velocities(model, state, dt, integrator)
    # velocities that move the positions: v* (symplectic) or the old ones (explicit Euler)
    if integrator == "explicit_euler":
        move = (state.body_velocity, state.body_angular_velocity, state.particle_velocity)
    else:
        move = (v_body, w_body, v_particle)
    # 2. integrate positions (a prediction): how far each body and particle sweeps this step
    free = (v_body, w_body, v_particle)
    predicted = advance_positions(*state.positions, *move, dt, dt)
    sweep = swept_distances(model, move[0], w_body, move[2], dt)
    # 3. collision detection over the swept step: contacts at the start positions, with gaps
    #    down to what the motion could close (speculative contacts: nothing tunnels)
    contacts = collide(model, state, options.contact_margin, sweep, options.granularity, options.normal,
                       options.samples)
    if contacts.count == 0:
        carried = {k: v for k, v in state.carried.items() if not k.startswith("impulse_")}
        return State.assemble(state.time + dt, predicted, free, carried), StepInfo(contacts)
    # 4. formulate the impulses and solve them: collisions first (I2, F2), then resting contacts (M2)
    r_a, r_b = lever_arms(contacts, state.body_position)
    inverse_inertia = world_inverse_inertia(model, state.body_orientation)
    gap_at_start = -contacts.depth                         # d₀
    threshold = options.restitution_threshold
    if threshold < 0:
        threshold = 2.0 * np.linalg.norm(model.gravity) * dt
    rows = contact_rows(contacts.body_a, contacts.body_b, contacts.particles_a, contacts.particles_b,
                        contacts.weights_a, contacts.weights_b, r_a, r_b, contacts.normal, contacts.tangent1,
                        contacts.tangent2, model.body_inverse_mass, inverse_inertia, model.particle_inverse_mass)
    u = generalized_velocity(v_body, w_body, v_particle)
    order = solve_order(contacts, model.gravity)
    tau_contact = np.empty(contacts.count)
    resolve_collisions(*rows, contacts.friction, contacts.restitution, relative_gravity(model, contacts),
                       gap_at_start, dt, threshold, u, options.iterations, options.iterations, options.tolerance,
                       tau_contact, order)
    warm = warm_start_impulses(state.carried, contacts.feature_id, options.warm_start)
    impulses, sweeps, change = solve_sequential_impulses(*rows, contacts.friction,
                                                         resting_target(gap_at_start, dt, options), u,
                                                         options.iterations, options.tolerance, warm, order)
    v_body_new, w_body_new, v_particle_new = split_velocity(u, model.body_count)
    # 5. recompute positions from the corrected velocities, split at the time of impact
    if not options.time_of_impact:
        tau_contact[:] = -1.0
    tau_body, tau_particle = entity_impact_fractions(model, contacts, tau_contact)
    solved = (v_body_new, w_body_new, v_particle_new)
    corrected = tuple(m + (after - before) for m, after, before in zip(move, solved, free))
    mid = advance_positions(*state.positions, *move, tau_body * dt, tau_particle * dt)
    positions = advance_positions(*mid, *corrected, (1 - tau_body) * dt, (1 - tau_particle) * dt)
    carried = dict(state.carried, impulse_ids=contacts.feature_id, impulse_values=impulses)
    new = State.assemble(state.time + dt, positions, solved, carried)
    return new, StepInfo(contacts, solver_iterations=sweeps, solver_residual=change)


def solve_order(contacts, gravity):
    """The order of the Gauss-Seidel sweeps (C,) int: highest contact point first along −g.

    In a stack the top contact is solved first, and the impulse it puts on the body below is
    passed on, contact by contact, down to the ground within the same sweep: the load path is
    followed in one sweep instead of creeping one link per sweep. This is what keeps a heavy
    body on a light one (mass ratio 100) from sinking with a modest iteration count. Contacts
    at one height (the four corners of a face) keep the collision order (a stable sort);
    without gravity the order is that of the collision detection.
    """
    height = contacts.point @ -np.asarray(gravity, dtype=float)
    return np.argsort(-height, kind="stable")


def warm_start_impulses(carried, feature_id, fraction):
    """Last step's resting-contact impulses (C, 3) for the contacts that persist, by id; 0 for new ones."""
    warm = np.zeros((len(feature_id), 3))
    ids, values = carried.get("impulse_ids"), carried.get("impulse_values")
    if fraction <= 0.0 or ids is None or len(ids) == 0:
        return warm
    order = np.argsort(ids)
    place = np.clip(np.searchsorted(ids, feature_id, sorter=order), 0, len(ids) - 1)
    found = ids[order[place]] == feature_id
    warm[found] = fraction * values[order[place[found]]]
    return warm


def resting_target(gap_at_start, dt, options):
    """The least normal relative velocity each contact may end the step with (C,) [m/s].

    Velocity-level non-penetration (C5b): the gap at the end of the step, d₀ + h v_n, must not
    be negative, so v_n ≥ −d₀/h; an open contact (d₀ > 0) may still approach that fast — a
    speculative contact. An existing penetration (d₀ < 0) is removed gradually: a fraction
    ``stabilization`` of its depth beyond ``slop`` per step, never faster than
    ``max_push_velocity`` (a deep overlap must not turn into a launch).
    """
    push = np.minimum(options.stabilization * np.maximum(-gap_at_start - options.slop, 0.0) / dt,
                      options.max_push_velocity)
    return np.where(gap_at_start >= 0.0, -gap_at_start / dt, push)


def relative_gravity(model, contacts):
    """g_n per contact (C,) [m/s²]: the normal component of the gravity of A relative to B.

    Symplectic Euler carries velocities at the middle of the step (it is leapfrog), so the
    velocity at the moment of impact is u = v_n* + g_n (τ − ½) h. Restitution reverses u and
    gravity acts over the rest of the step (see ``resolve_collisions``).
    """
    dynamic_a = (contacts.body_a >= 0) | (contacts.particles_a[:, 0] >= 0)
    dynamic_b = (contacts.body_b >= 0) | (contacts.particles_b[:, 0] >= 0)
    return (dynamic_a.astype(float) - dynamic_b) * (contacts.normal @ model.gravity)


def entity_impact_fractions(model, contacts, tau):
    """τ per body (B,) and particle (P,): the earliest impact among its contacts (tau (C,),
    −1 where a contact had none); 0 for an entity with no impact, whose velocity change then
    acts over the whole step."""
    tau_body = np.ones(model.body_count)
    tau_particle = np.ones(model.particle_count)
    tau = np.where(tau < 0.0, 1.0, tau)
    for body in (contacts.body_a, contacts.body_b):
        has = body >= 0
        np.minimum.at(tau_body, body[has], tau[has])
    for particles in (contacts.particles_a, contacts.particles_b):
        for k in range(3):
            has = particles[:, k] >= 0
            np.minimum.at(tau_particle, particles[has, k], tau[has])
    return np.where(tau_body == 1.0, 0.0, tau_body), np.where(tau_particle == 1.0, 0.0, tau_particle)
