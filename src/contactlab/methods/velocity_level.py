"""What the velocity-level methods share (SPEC M2: constraints on velocities are impulses).

The stages of loop L3 both steps are made of, named as on the slide: ``predict`` (positions
moved with the free velocities: how far everything sweeps), ``detect`` (contacts over the
swept step), ``step_without_contacts``, and ``positions_split_at_impact`` (x = x₀ + h v⁺, the
motion before the moment of impact taken with v*).

Impulses (methods.impulse) and hard constraints on velocities (methods.constraints, C5b) both
ask each contact's normal relative velocity after the step to reach a target, and both move
the positions with the corrected velocities, split at the moment of impact. The targets:

* a contact that closes during the step with impact velocity u_n below −threshold leaves at
  −ε u_n (restitution, I1/R3), measured at the moment of impact (``relative_gravity``);
* any other contact must not end the step overlapping: v_n ≥ −d₀/h for a gap d₀ (speculative
  contacts), or pushes out a fraction of an existing overlap (``resting_target``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from ..collision import swept_distances
from ..compiling import njit
from ..contacts import ContactArrays, values_by_id
from ..dynamics.integrators import advance_positions
from ..state import State
from .base import StepInfo
from .loop_stages import loop_model
from .penalty_springs import SUPPORT_COSINE, entities_of, supported_loads

if TYPE_CHECKING:
    from ..collision.manifolds import Manifolds
    from ..contacts import Contacts
    from ..model import Model
    from .base import KeptManifoldOptions
    from .constraints import Options as ConstraintsOptions
    from .impulse import Options as ImpulseOptions


def predict(
    model: Model, state: State, free: tuple[np.ndarray, np.ndarray, np.ndarray], integrator: str, h: float
) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray], np.ndarray]:
    """Stage 2: positions integrated with the free velocities ``free`` (body (B, 3), angular (B, 3),
    particle (P, 3)) over h [s] — a prediction of how far everything sweeps. Returns (the
    velocities that move the positions: v*, or the old ones under explicit Euler; the predicted
    positions; each collider's swept distance [m])."""
    move = state.velocities if integrator == "explicit_euler" else free
    predicted = advance_positions(state.positions, move, h, h)
    return move, predicted, swept_distances(model, move[0], free[1], move[2], h)


def detect(
    model: Model, state: State, options: KeptManifoldOptions, sweep: np.ndarray
) -> tuple[Contacts, Manifolds | None]:
    """Stage 3: collision detection over the swept step — contacts at the start positions with
    gaps down to what the motion could close (speculative contacts, so nothing tunnels), box,
    hull and plane pairs that barely moved keeping last step's manifolds. Returns (Contacts,
    the manifolds to carry)."""
    return options.collide(model, state, sweep, state.carried.get("manifolds"), options.manifold_tolerance)


def step_without_contacts(
    state: State,
    h: float,
    predicted: tuple[np.ndarray, np.ndarray, np.ndarray],
    free: tuple[np.ndarray, np.ndarray, np.ndarray],
    contacts: Contacts,
    manifolds: Manifolds | None,
    warm_prefix: str,
) -> tuple[State, StepInfo]:
    """The step when nothing touches: the prediction stands; the warm-start values carried under
    keys starting with ``warm_prefix`` are dropped (no contact persists). Returns (State, StepInfo)."""
    carried = {key: value for key, value in state.carried.items() if not key.startswith(warm_prefix)}
    carried["manifolds"] = manifolds
    return State.assemble(state.time + h, predicted, free, carried), StepInfo(contacts)


LOAD_PATH_FROM = 2  # bodies and particles: fewer cannot rest on one another (guess_new_impulses)


@njit(cache=True)
def guess_new_impulses(
    warm: np.ndarray,
    found: np.ndarray,
    fraction: float,
    contacts: ContactArrays,
    body_position: np.ndarray,
    particle_position: np.ndarray,
    masses: tuple[np.ndarray, np.ndarray],
    gravity: np.ndarray,
    h: float,
) -> None:
    """The warm start of the contacts that carry nothing from the last step (``found`` (C,) False):
    the weight each would bear at rest, over the step. ``warm`` (C, 3) [N s] holds the carried
    impulses times ``fraction`` (the Options' warm_start); a new contact whose normal lies within
    72° of vertical gets ``fraction`` · W h along its normal, W [N] its share of the load path
    (``penalty_springs.supported_loads``: each body's weight and what rests on it, shared among
    the contacts it rests on), h [s]; the others keep 0. ``masses`` = (body masses (B,),
    particle masses (P,)) [kg], positions (B, 3), (P, 3) [m], ``gravity`` (3,) [m/s²].

    A scene of fewer than LOAD_PATH_FROM bodies and particles has no load path to build (its
    one body's contacts find its weight in a sweep or two): nothing is guessed there, and
    ``first_impulses`` does not call this, so a ball's first run does not compile it.

    Why: started from zero, a stack must build its load path sweep by sweep, the weight of the
    top box reaching the floor only after as many sweeps as there are levels; started from the
    weights, a 20-level pyramid's solve takes about half the sweeps over 5 s (9.2 → 4.9), most
    of it in the first second. The solve itself, and so its answer to the tolerance, is
    unchanged: a guess too large (an impact, a contact about to open) is taken back by the
    accumulated clamping like any warm start."""
    B = body_position.shape[0]
    g = np.sqrt(gravity[0] ** 2 + gravity[1] ** 2 + gravity[2] ** 2)
    if fraction <= 0.0 or g == 0.0 or found.all() or B + particle_position.shape[0] < LOAD_PATH_FROM:
        return  # weightless, or nothing new to guess: the carried values as they are
    loads = supported_loads(
        entities_of(contacts.body_a, contacts.particles_a, B),
        entities_of(contacts.body_b, contacts.particles_b, B),
        contacts.normal,
        body_position,
        particle_position,
        masses[0],
        masses[1],
        gravity,
    )
    for c in range(found.shape[0]):
        if found[c]:
            continue
        normal = contacts.normal[c]
        along = (normal[0] * gravity[0] + normal[1] * gravity[1] + normal[2] * gravity[2]) / g
        if abs(along) > SUPPORT_COSINE:
            warm[c, 0] = fraction * loads[c] * h


def first_impulses(
    model: Model, state: State, contacts: Contacts, prefix: str, fraction: float, h: float
) -> np.ndarray:
    """The solve's first impulses (C, 3) [N s] (warm start): last step's, carried under the keys
    ``prefix`` + "ids" / "values", for the contacts that persist (by id), times ``fraction``;
    a new contact's weight over the step h [s] (``guess_new_impulses``); zeros when ``fraction``
    is 0."""
    if fraction <= 0.0:
        return np.zeros((contacts.count, 3))
    values, found = values_by_id(
        state.carried.get(prefix + "ids"), state.carried.get(prefix + "values"), contacts.feature_id, 3
    )
    warm = fraction * values
    if model.body_count + model.particle_count < LOAD_PATH_FROM:
        return warm  # nothing to guess (guess_new_impulses), and nothing compiled for it
    arrays = loop_model(model)  # the masses and gravity as the compiled loop takes them
    guess_new_impulses(
        warm,
        found,
        fraction,
        contacts.arrays(),
        np.ascontiguousarray(state.body_position, dtype=float),
        np.ascontiguousarray(state.particle_position, dtype=float),
        (arrays.body_mass, arrays.particle_mass),
        arrays.gravity,
        h,
    )
    return warm


def restitution_threshold(model: Model, h: float, options: ImpulseOptions | ConstraintsOptions) -> float:
    """Approaches slower than this [m/s] get no bounce: the option, or 2 |g| h where it is < 0."""
    if options.restitution_threshold >= 0:
        return options.restitution_threshold
    return 2.0 * np.linalg.norm(model.gravity) * h


def positions_split_at_impact(
    model: Model,
    state: State,
    contacts: Contacts,
    tau: np.ndarray,
    move: tuple[np.ndarray, np.ndarray, np.ndarray],
    free: tuple[np.ndarray, np.ndarray, np.ndarray],
    solved: tuple[np.ndarray, np.ndarray, np.ndarray],
    h: float,
    time_of_impact: bool,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stage 5: positions x = x₀ + h v⁺, with the part of the step before each body's earliest
    impact (τ (C,) per contact, −1 where none; see ``entity_impact_fractions``) travelled with
    the velocities that moved the prediction (``move``) and the rest with them corrected by the
    solve (``solved`` − ``free``). ``time_of_impact`` False: no split (τ = −1 everywhere)."""
    if not time_of_impact:
        tau = np.full(contacts.count, -1.0)
    tau_body, tau_particle = entity_impact_fractions(model, contacts, tau)
    corrected = tuple(m + (after - before) for m, after, before in zip(move, solved, free))
    mid = advance_positions(state.positions, move, tau_body * h, tau_particle * h)
    return advance_positions(mid, corrected, (1 - tau_body) * h, (1 - tau_particle) * h)


def resting_target(gap_at_start: np.ndarray, dt: float, options: ImpulseOptions | ConstraintsOptions) -> np.ndarray:
    """The least normal relative velocity each contact may end the step with (C,) [m/s].

    Velocity-level non-penetration (C5b): the gap at the end of the step, d₀ + h v_n, must not
    be negative, so v_n ≥ −d₀/h; an open contact (d₀ > 0) may still approach that fast — a
    speculative contact. An existing penetration (d₀ < 0) is removed gradually: a fraction
    ``stabilization`` of its depth beyond ``slop`` per step, never faster than
    ``max_push_velocity`` (a deep overlap must not turn into a launch).
    """
    return resting_targets(
        np.asarray(gap_at_start, dtype=float), dt, options.stabilization, options.slop, options.max_push_velocity
    )


@njit(cache=True)
def resting_targets(
    gap_at_start: np.ndarray, dt: float, stabilization: float, slop: float, max_push_velocity: float
) -> np.ndarray:
    """``resting_target``, compiled, with the options' three numbers [1, m, m/s]."""
    target = np.empty_like(gap_at_start)
    for c in range(gap_at_start.shape[0]):
        target[c] = _resting(gap_at_start[c], dt, stabilization, slop, max_push_velocity)
    return target


@njit(cache=True, inline="always")
def _resting(gap, dt, stabilization, slop, max_push_velocity):
    """One contact's ``resting_target`` [m/s]."""
    if gap >= 0.0:
        return -gap / dt
    return min(stabilization * max(-gap - slop, 0.0) / dt, max_push_velocity)


def relative_gravity(model: Model, contacts: Contacts) -> np.ndarray:
    """g_n per contact (C,) [m/s²]: the normal component of the gravity of A relative to B.

    Symplectic Euler carries velocities at the middle of the step (it is leapfrog), so the
    velocity at the moment of impact is u = v_n* + g_n (τ − ½) h. Restitution reverses u and
    gravity acts over the rest of the step (see ``resolve_collisions``).
    """
    return gravity_along_normals(
        contacts.body_a,
        contacts.body_b,
        contacts.particles_a,
        contacts.particles_b,
        np.ascontiguousarray(contacts.normal, dtype=float),
        np.asarray(model.gravity, dtype=float),
    )


@njit(cache=True)
def gravity_along_normals(
    body_a: np.ndarray,
    body_b: np.ndarray,
    particles_a: np.ndarray,
    particles_b: np.ndarray,
    normal: np.ndarray,
    gravity: np.ndarray,
) -> np.ndarray:
    """``relative_gravity``, compiled: (dynamic A − dynamic B) n · g per contact (C,) [m/s²]."""
    out = np.empty(normal.shape[0])
    for c in range(normal.shape[0]):
        dynamic_a = 1.0 if body_a[c] >= 0 or particles_a[c, 0] >= 0 else 0.0
        dynamic_b = 1.0 if body_b[c] >= 0 or particles_b[c, 0] >= 0 else 0.0
        out[c] = (dynamic_a - dynamic_b) * (
            normal[c, 0] * gravity[0] + normal[c, 1] * gravity[1] + normal[c, 2] * gravity[2]
        )
    return out


def entity_impact_fractions(model: Model, contacts: Contacts, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """τ per body (B,) and particle (P,): the earliest impact among its contacts (tau (C,),
    −1 where a contact had none); 0 for an entity with no impact, whose velocity change then
    acts over the whole step."""
    return earliest_impacts(
        contacts.body_a,
        contacts.body_b,
        contacts.particles_a,
        contacts.particles_b,
        np.asarray(tau, dtype=float),
        model.body_count,
        model.particle_count,
    )


@njit(cache=True)
def earliest_impacts(
    body_a: np.ndarray,
    body_b: np.ndarray,
    particles_a: np.ndarray,
    particles_b: np.ndarray,
    tau: np.ndarray,
    body_count: int,
    particle_count: int,
) -> tuple[np.ndarray, np.ndarray]:
    """``entity_impact_fractions``, compiled (one pass over the contacts' sides)."""
    tau_body = np.ones(body_count)
    tau_particle = np.ones(particle_count)
    for c in range(tau.shape[0]):
        t = 1.0 if tau[c] < 0.0 else tau[c]
        for body in (body_a[c], body_b[c]):
            if body >= 0 and t < tau_body[body]:
                tau_body[body] = t
        for k in range(3):
            for p in (particles_a[c, k], particles_b[c, k]):
                if p >= 0 and t < tau_particle[p]:
                    tau_particle[p] = t
    for b in range(body_count):
        if tau_body[b] == 1.0:
            tau_body[b] = 0.0
    for p in range(particle_count):
        if tau_particle[p] == 1.0:
            tau_particle[p] = 0.0
    return tau_body, tau_particle


def normal_targets(
    gap_at_start: ArrayLike,  # array-likes: converted to float arrays for ``impact_targets``
    normal_velocity: ArrayLike,
    gravity_normal: ArrayLike,
    restitution: ArrayLike,
    dt: float,
    threshold: float,
    options: ImpulseOptions | ConstraintsOptions,
) -> tuple[np.ndarray, np.ndarray]:
    """Every contact's target normal velocity, all contacts at once (a simultaneous impact).

    gap_at_start d₀ (C,) [m]; normal_velocity v_n* (C,) [m/s] without contact forces;
    gravity_normal g_n (C,) [m/s²]; restitution ε (C,); threshold [m/s]. A contact that closes
    within the step (v_n* < 0, d₀ + h v_n* ≤ 0) does so at the fraction τ = d₀ / (−h v_n*) of it,
    with the impact velocity u = v_n* + g_n (τ − ½) h (symplectic Euler is leapfrog); if u <
    −threshold and ε > 0 it must leave at −ε u + g_n (½ − τ) h. Every other contact gets
    ``resting_target``. Returns (target (C,) [m/s], τ (C,), −1 where there was no impact).
    """
    return impact_targets(
        *(np.asarray(a, dtype=float) for a in (gap_at_start, normal_velocity, gravity_normal, restitution)),
        dt,
        threshold,
        options.stabilization,
        options.slop,
        options.max_push_velocity,
    )


@njit(cache=True)
def impact_targets(
    gap_at_start: np.ndarray,
    normal_velocity: np.ndarray,
    gravity_normal: np.ndarray,
    restitution: np.ndarray,
    dt: float,
    threshold: float,
    stabilization: float,
    slop: float,
    max_push_velocity: float,
) -> tuple[np.ndarray, np.ndarray]:
    """``normal_targets``, compiled, with the options' stabilization, slop and max push velocity."""
    h = dt
    C = gap_at_start.shape[0]
    target = np.empty(C)
    tau = np.empty(C)
    for c in range(C):
        gap, vn = gap_at_start[c], normal_velocity[c]
        closing = vn < 0.0 and gap + h * vn <= 0.0
        closes = min(gap / (-vn * h), 1.0) if gap > 0.0 and closing else 0.0
        impact = vn + gravity_normal[c] * (closes - 0.5) * h
        if closing and restitution[c] > 0.0 and impact < -threshold:
            target[c] = -restitution[c] * impact + gravity_normal[c] * (0.5 - closes) * h
            tau[c] = closes
        else:
            target[c] = _resting(gap, dt, stabilization, slop, max_push_velocity)
            tau[c] = -1.0
    return target, tau
