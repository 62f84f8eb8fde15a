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
      the constraints method;
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
from ..contacts import side_apply_impulse, side_inverse_mass, side_point_velocity
from ..dynamics.integrators import advance_positions, free_velocities, world_inverse_inertia
from ..errors import InputError
from ..state import State
from . import StepInfo


@dataclass
class Options:
    """Settings of ``[method.impulse]``."""
    iterations: int = 30                  # sweeps of sequential impulses per step (at most)
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


@njit(cache=True)
def resolve_collisions(body_a, body_b, particles_a, particles_b, weights_a, weights_b,
                       r_a, r_b, normal, tangent1, tangent2, friction, restitution, gravity_normal,
                       gap_at_start, dt, threshold, body_inverse_mass, body_inverse_inertia_world,
                       particle_inverse_mass, body_velocity, body_angular_velocity, particle_velocity,
                       max_waves, sweeps, tolerance, tau):
    """Collision impulses (I2, R1–R4, F2) in waves, until no contact approaches.

    A wave is every contact that is approaching now: at the current velocities it would be
    closed by the end of the step, and its impact velocity u = v_n + g_n (τ − ½) h is below
    −threshold (τ: where in the step it closes, d₀ / (−h v_n) for a gap d₀ > 0 at the start,
    else 0). The wave's impulses are solved together — accumulated, λ ≥ 0 — so that each
    member leaves at −ε u + g_n (½ − τ) h (restitution; see ``relative_gravity``), with
    friction of at most μ λ (F2). Simultaneous impacts (a box landing flat on four corners)
    are thus one wave and stay symmetric, while an impact passed along a chain of touching
    bodies makes one wave per link (Newton's cradle: one ball in, one ball out). ``tau`` (C,)
    receives each contact's τ, −1 where it had no impact. Returns the number of waves.
    """
    C = normal.shape[0]
    target = np.empty(C)
    closes = np.empty(C)
    k_normal = np.empty(C)
    impulses = np.zeros((C, 3))
    members = np.empty(C, dtype=np.int64)
    for c in range(C):
        tau[c] = -1.0
        k_normal[c] = _effective_mass(c, normal[c], body_a, body_b, particles_a, particles_b, weights_a,
                                      weights_b, r_a, r_b, body_inverse_mass, body_inverse_inertia_world,
                                      particle_inverse_mass)
    for wave in range(max_waves):
        count = 0
        for c in range(C):
            if restitution[c] <= 0.0 or k_normal[c] <= 0.0:
                continue
            vn = _relative_velocity(c, normal[c], body_a, body_b, particles_a, particles_b, weights_a, weights_b,
                                    r_a, r_b, body_velocity, body_angular_velocity, particle_velocity)
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
                change = max(change, _solve_contact(
                    c, target[c], k_normal[c], impulses, body_a, body_b, particles_a, particles_b, weights_a,
                    weights_b, r_a, r_b, normal, tangent1, tangent2, friction, body_inverse_mass,
                    body_inverse_inertia_world, particle_inverse_mass, body_velocity, body_angular_velocity,
                    particle_velocity))
            if change <= tolerance:
                break
    return max_waves


@njit(cache=True)
def _effective_mass(c, d, body_a, body_b, particles_a, particles_b, weights_a, weights_b, r_a, r_b,
                    body_inverse_mass, body_inverse_inertia_world, particle_inverse_mass):
    """dᵀ J M⁻¹ Jᵀ d at contact c, both sides."""
    return (side_inverse_mass(body_a[c], particles_a[c], weights_a[c], r_a[c], d,
                              body_inverse_mass, body_inverse_inertia_world, particle_inverse_mass)
            + side_inverse_mass(body_b[c], particles_b[c], weights_b[c], r_b[c], d,
                                body_inverse_mass, body_inverse_inertia_world, particle_inverse_mass))


@njit(cache=True)
def _friction_impulse(c, old1, old2, limit, body_a, body_b, particles_a, particles_b, weights_a, weights_b,
                      r_a, r_b, tangent1, tangent2, body_inverse_mass, body_inverse_inertia_world,
                      particle_inverse_mass, body_velocity, body_angular_velocity, particle_velocity):
    """Coulomb friction (F2) on top of an existing tangential impulse (old1, old2).

    The impulse that cancels the tangential relative velocity, with the total kept in the disk
    of radius ``limit`` = μ J_n. Returns the new total (t1, t2) and the largest velocity change.
    """
    k1 = _effective_mass(c, tangent1[c], body_a, body_b, particles_a, particles_b, weights_a, weights_b,
                         r_a, r_b, body_inverse_mass, body_inverse_inertia_world, particle_inverse_mass)
    k2 = _effective_mass(c, tangent2[c], body_a, body_b, particles_a, particles_b, weights_a, weights_b,
                         r_a, r_b, body_inverse_mass, body_inverse_inertia_world, particle_inverse_mass)
    vt1 = _relative_velocity(c, tangent1[c], body_a, body_b, particles_a, particles_b, weights_a,
                             weights_b, r_a, r_b, body_velocity, body_angular_velocity, particle_velocity)
    vt2 = _relative_velocity(c, tangent2[c], body_a, body_b, particles_a, particles_b, weights_a,
                             weights_b, r_a, r_b, body_velocity, body_angular_velocity, particle_velocity)
    new1 = old1 - vt1 / k1
    new2 = old2 - vt2 / k2
    magnitude = np.sqrt(new1 * new1 + new2 * new2)
    if magnitude > limit:
        scale = limit / magnitude
        new1 *= scale
        new2 *= scale
    _apply(c, tangent1[c], new1 - old1, body_a, body_b, particles_a, particles_b, weights_a, weights_b, r_a, r_b,
           body_inverse_mass, body_inverse_inertia_world, particle_inverse_mass,
           body_velocity, body_angular_velocity, particle_velocity)
    _apply(c, tangent2[c], new2 - old2, body_a, body_b, particles_a, particles_b, weights_a, weights_b, r_a, r_b,
           body_inverse_mass, body_inverse_inertia_world, particle_inverse_mass,
           body_velocity, body_angular_velocity, particle_velocity)
    return new1, new2, max(abs(new1 - old1) * k1, abs(new2 - old2) * k2)


@njit(cache=True)
def solve_sequential_impulses(body_a, body_b, particles_a, particles_b, weights_a, weights_b,
                              r_a, r_b, normal, tangent1, tangent2, friction, target_normal_velocity,
                              body_inverse_mass, body_inverse_inertia_world, particle_inverse_mass,
                              body_velocity, body_angular_velocity, particle_velocity,
                              iterations, tolerance, initial_impulses):
    """Contact impulses with accumulated clamping; changes the velocity arrays in place (M2).

    ``initial_impulses`` (C, 3) are applied first (warm starting: last step's impulses of the
    same contacts), then corrected like any accumulated impulse.

    For every contact c (in order, repeatedly): the normal impulse that brings the normal
    relative velocity to ``target_normal_velocity[c]``, with the accumulated impulse kept ≥ 0
    (never attractive, C2), then friction with the accumulated tangential impulse kept in the
    disk μ λ_n (F2). Returns (impulses (C, 3) [N s] as (normal, t1, t2), sweeps made, largest
    velocity change in the last sweep [m/s]).
    """
    C = normal.shape[0]
    impulses = initial_impulses.copy()
    k_normal = np.empty(C)
    for c in range(C):
        k_normal[c] = _effective_mass(c, normal[c], body_a, body_b, particles_a, particles_b, weights_a,
                                      weights_b, r_a, r_b, body_inverse_mass, body_inverse_inertia_world,
                                      particle_inverse_mass)
        for d in range(3):
            direction = normal[c] if d == 0 else (tangent1[c] if d == 1 else tangent2[c])
            _apply(c, direction, impulses[c, d], body_a, body_b, particles_a, particles_b, weights_a, weights_b,
                   r_a, r_b, body_inverse_mass, body_inverse_inertia_world, particle_inverse_mass,
                   body_velocity, body_angular_velocity, particle_velocity)
    sweeps = 0
    change = 0.0
    for sweep in range(iterations):
        sweeps = sweep + 1
        change = 0.0
        for c in range(C):
            if k_normal[c] <= 0.0:        # static against static: nothing can move
                continue
            change = max(change, _solve_contact(
                c, target_normal_velocity[c], k_normal[c], impulses, body_a, body_b, particles_a, particles_b,
                weights_a, weights_b, r_a, r_b, normal, tangent1, tangent2, friction, body_inverse_mass,
                body_inverse_inertia_world, particle_inverse_mass, body_velocity, body_angular_velocity,
                particle_velocity))
        if change <= tolerance:
            break
    return impulses, sweeps, change


@njit(cache=True)
def _solve_contact(c, target, k_normal, impulses, body_a, body_b, particles_a, particles_b, weights_a, weights_b,
                   r_a, r_b, normal, tangent1, tangent2, friction, body_inverse_mass, body_inverse_inertia_world,
                   particle_inverse_mass, body_velocity, body_angular_velocity, particle_velocity):
    """One Gauss-Seidel update of contact c (C7 on velocities): the normal impulse that brings
    v_n to ``target`` with the accumulated impulse kept ≥ 0 (C2), then friction kept in the
    disk μ λ_n (F2). Updates ``impulses[c]`` and the velocities; returns the largest velocity
    change it made [m/s]."""
    vn = _relative_velocity(c, normal[c], body_a, body_b, particles_a, particles_b, weights_a, weights_b,
                            r_a, r_b, body_velocity, body_angular_velocity, particle_velocity)
    old = impulses[c, 0]
    impulses[c, 0] = max(0.0, old - (vn - target) / k_normal)
    _apply(c, normal[c], impulses[c, 0] - old, body_a, body_b, particles_a, particles_b, weights_a, weights_b,
           r_a, r_b, body_inverse_mass, body_inverse_inertia_world, particle_inverse_mass,
           body_velocity, body_angular_velocity, particle_velocity)
    change = abs(impulses[c, 0] - old) * k_normal
    if friction[c] > 0.0:
        new1, new2, friction_change = _friction_impulse(
            c, impulses[c, 1], impulses[c, 2], friction[c] * impulses[c, 0], body_a, body_b,
            particles_a, particles_b, weights_a, weights_b, r_a, r_b, tangent1, tangent2,
            body_inverse_mass, body_inverse_inertia_world, particle_inverse_mass, body_velocity,
            body_angular_velocity, particle_velocity)
        impulses[c, 1], impulses[c, 2] = new1, new2
        change = max(change, friction_change)
    return change


@njit(cache=True)
def _relative_velocity(c, d, body_a, body_b, particles_a, particles_b, weights_a, weights_b, r_a, r_b,
                       body_velocity, body_angular_velocity, particle_velocity):
    """dᵀ (v_A − v_B) at contact c."""
    return (side_point_velocity(body_a[c], particles_a[c], weights_a[c], r_a[c], d,
                                body_velocity, body_angular_velocity, particle_velocity)
            - side_point_velocity(body_b[c], particles_b[c], weights_b[c], r_b[c], d,
                                  body_velocity, body_angular_velocity, particle_velocity))


@njit(cache=True)
def _apply(c, d, impulse, body_a, body_b, particles_a, particles_b, weights_a, weights_b, r_a, r_b,
           body_inverse_mass, body_inverse_inertia_world, particle_inverse_mass,
           body_velocity, body_angular_velocity, particle_velocity):
    """+impulse·d on side A and −impulse·d on side B (R1)."""
    side_apply_impulse(body_a[c], particles_a[c], weights_a[c], r_a[c], d, impulse,
                       body_inverse_mass, body_inverse_inertia_world, particle_inverse_mass,
                       body_velocity, body_angular_velocity, particle_velocity)
    side_apply_impulse(body_b[c], particles_b[c], weights_b[c], r_b[c], d, -impulse,
                       body_inverse_mass, body_inverse_inertia_world, particle_inverse_mass,
                       body_velocity, body_angular_velocity, particle_velocity)


def lever_arms(contacts, body_position):
    """r = point − centre of mass for each side, (C, 3) each; zero for non-body sides."""
    def arm(body):
        r = np.zeros((contacts.count, 3))
        has = body >= 0
        r[has] = contacts.point[has] - body_position[body[has]]
        return r
    return arm(contacts.body_a), arm(contacts.body_b)


def relative_normal_velocity(contacts, r_a, r_b, body_velocity, body_angular_velocity, particle_velocity):
    """nᵀ(v_A − v_B) per contact, (C,), vectorized."""
    def side(body, particles, weights, r):
        v = np.zeros((contacts.count, 3))
        has = body >= 0
        v[has] = body_velocity[body[has]] + np.cross(body_angular_velocity[body[has]], r[has])
        for k in range(3):
            p = particles[:, k]
            v[p >= 0] += weights[p >= 0, k, None] * particle_velocity[p[p >= 0]]
        return v
    v_rel = (side(contacts.body_a, contacts.particles_a, contacts.weights_a, r_a)
             - side(contacts.body_b, contacts.particles_b, contacts.weights_b, r_b))
    return np.einsum("ci,ci->c", v_rel, contacts.normal)


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
    vn_free = relative_normal_velocity(contacts, r_a, r_b, v_body, w_body, v_particle)
    gap_at_start = -contacts.depth                         # d₀
    threshold = options.restitution_threshold
    if threshold < 0:
        threshold = 2.0 * np.linalg.norm(model.gravity) * dt
    v_body_new, w_body_new, v_particle_new = v_body.copy(), w_body.copy(), v_particle.copy()
    arrays = (contacts.body_a, contacts.body_b, contacts.particles_a, contacts.particles_b,
              contacts.weights_a, contacts.weights_b, r_a, r_b, contacts.normal, contacts.tangent1,
              contacts.tangent2, contacts.friction)
    masses = (model.body_inverse_mass, inverse_inertia, model.particle_inverse_mass)
    velocities = (v_body_new, w_body_new, v_particle_new)
    tau_contact = np.empty(contacts.count)
    resolve_collisions(*arrays, contacts.restitution, relative_gravity(model, contacts), gap_at_start, dt,
                       threshold, *masses, *velocities, options.iterations, options.iterations, options.tolerance,
                       tau_contact)
    warm = warm_start_impulses(state.carried, contacts.feature_id, options.warm_start)
    impulses, sweeps, change = solve_sequential_impulses(*arrays, resting_target(gap_at_start, dt, options),
                                                         *masses, *velocities, options.iterations,
                                                         options.tolerance, warm)
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
