"""Loop L3, written once for the two velocity-level methods (SPEC M2: constraints on
velocities are impulses): impulses (methods.impulse) and hard constraints on velocities swept
matrix-free (methods.constraints, C5b).

Stages 1–3 from Python for every scene (``predict_positions``: positions moved with the free velocities,
how far everything sweeps; ``swept_contacts``: contacts over the swept step; ``step_without_contacts``),
their arithmetic the compiled loop's own (free flight under gravity, ``integrators.free_flight``; the
swept reach, ``collision.swept_reach``; the broad and narrow phase kernels) with what only this path
serves added (cloth springs, explicit Euler, meshes, a force given as a Python function);
stages 4–5 compiled, in ``respond`` — the contacts' rows, the targets of their normal rows
(``targets``: impulses' collision waves, ``resolve_collisions``, then resting targets;
constraints' simultaneous ``impact_targets``), the warm start (``warm_impulses``), the sweeps
(``loop_stages.solve``) and the positions split at the time of impact (``split_at_impact``).
``respond`` is what the compiled loop's step (``loop_steps.velocity_step``) runs and what
``step`` calls from Python for the scenes the loop does not serve (cloth, meshes, a force or
path given as a Python function, explicit Euler): each stage exists once.

Both methods ask each contact's normal relative velocity after the step to reach a target,
and both move the positions with the corrected velocities, split at the moment of impact:

* a contact that closes during the step with impact velocity u_n below −threshold leaves at
  −ε u_n (restitution, I1/R3), measured at the moment of impact (``gravity_along_normals``);
* any other contact must not end the step overlapping: v_n ≥ −d₀/h for a gap d₀ (speculative
  contacts), or pushes out a fraction of an existing overlap (``resting_targets``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..collision import swept_distances
from ..compiling import njit
from ..contacts import ContactArrays, values_carried
from ..dynamics.generalized import stacked, unstacked
from ..dynamics.integrators import advance_positions, carrying_springs, free_velocities, moved
from ..errors import InputError
from ..state import Carry, State
from ..validation import check_choices, check_counts, check_flags
from .base import KeptManifoldOptions, StepInfo
from .blocks import solve_in_blocks
from .jacobian_rows import ContactRows, contact_velocity, row_products
from .loop_stages import (
    LoopModel,
    LoopSettings,
    Motion,
    Specialization,
    build_rows,
    for_response,
    loop_inputs,
    loop_settings,
    solve,
    specialization,
)
from .penalty_springs import SUPPORT_COSINE, entities_of, supported_loads
from .sequential import contact_order, resting_target, sweep_contacts
from .shock import propagate_shock

if TYPE_CHECKING:
    from ..collision.manifolds import Manifolds
    from ..contacts import Contacts
    from ..model import Model
    from .constraints import Options as ConstraintsOptions
    from .impulse import Options as ImpulseOptions


def predict_positions(
    model: Model, state: State, free: tuple[np.ndarray, np.ndarray, np.ndarray], integrator: str, h: float
) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray], np.ndarray]:
    """Stage 2: positions integrated with the free velocities ``free`` (body (B, 3), angular (B, 3),
    particle (P, 3)) over h [s] — a prediction of how far everything sweeps. Returns (the
    velocities that move the positions: v*, or the old ones under explicit Euler; the predicted
    positions; each collider's swept distance [m])."""
    move = state.velocities if integrator == "explicit_euler" else free
    predicted = advance_positions(state.positions, move, h, h)
    return move, predicted, swept_distances(model, move[0], free[1], move[2], h)


def swept_contacts(
    model: Model,
    state: State,
    options: KeptManifoldOptions,
    sweep: np.ndarray,
    particle_motion: np.ndarray | None = None,
) -> tuple[Contacts, Manifolds | None]:
    """Stage 3: collision detection over the swept step — contacts at the start positions with
    gaps down to what the motion could close (speculative contacts, so nothing tunnels: each
    collider's ``sweep`` (B + P,) [m]; for cloth self-contact, the particles' relative
    displacements, from ``particle_motion`` (P, 3) [m], None: the sweep), box, hull and plane
    pairs that barely moved keeping last step's manifolds. Returns (Contacts, the manifolds to
    carry)."""
    return options.collide(model, state, sweep, state.carried.manifolds, options.manifold_tolerance, particle_motion)


def step_without_contacts(
    state: State, h: float, positions: tuple[tuple, tuple], contacts: Contacts, carried: Carry
) -> tuple[State, StepInfo]:
    """The step of a method when nothing touches: ``positions`` = (the predicted positions, the
    free velocities) stand; ``carried``: no contact's values (none persists), the manifolds and
    the cloth's springs (``Carry.none(method, manifolds)``, ``carrying_springs``). Returns
    (State, StepInfo)."""
    predicted, free = positions
    return State.assemble(state.time + h, predicted, free, carried), StepInfo(contacts)


SUBSTEP_WHEN = ("unconverged", "always")
"""When a velocity method's step is solved in substeps (Options ``substep_when``): only where the
whole-step sweeps leave it above the tolerance, or every step."""


@dataclass(frozen=True)
class VelocityOptions(KeptManifoldOptions):
    """What the Options of impulse and constraints share, after the collision settings: the
    sweeps, the small steps, the warm start and the velocity targets of stages 4–5, which
    ``respond`` runs for both (documented with units in docs/methods/impulse.md and
    constraints.md). Constraints reads the small steps with its matrix-free solver on velocities
    only."""

    iterations: int = 100
    """sweeps per step (at most): impulse's sequential impulses and collision waves, constraints'
    solver sweeps (newton: Newton steps)"""
    substeps: int = 16
    """a step left unconverged is solved again in this many substeps, contacts detected once (1 = never)"""
    substep_after: int = 12
    """with substeps > 1, the whole-step sweeps stop after this many (and iterations), or after 4 where
    their change is too far above the tolerance to reach it (sequential.hopeless_change), and a step
    still above the tolerance goes on in substeps"""
    substep_sweeps: int = 1
    """sweeps per substep (at most)"""
    substep_when: str = "unconverged"
    """unconverged (a step the whole-step sweeps leave above the tolerance) | always"""
    contact_hertz: float = 0.0
    """Hz: in substeps, an overlap is a soft contact of this stiffness (damping ratio 10) pushed out by it, each
    substep's sweeps followed by a relaxing sweep (Box2D v3's soft step); 0 = rigid, pushed out by the stabilization"""
    block_solve: bool = False
    """the whole-step sweeps solve the normals of each manifold (a pair of bodies' contacts, 4 at most) as one
    small LCP, exactly (methods.blocks), then their friction"""
    shock_sweeps: int = 0
    """a step the sweeps leave above the tolerance ends with a shock-propagation pass, level by level from
    the ground up with the levels below held (methods.shock), of at most this many sweeps a level; 0 = none.
    Instead of substeps: needs substeps = 1"""
    warm_start: float = 1.0
    """fraction of last step's impulses to start from (by contact id), and of a new contact's weight
    over the step (``guess_new_impulses``); 0 = cold"""
    restitution_threshold: float = -1.0
    """m/s: slower approaches bounce with ε = 0; < 0 means 2·|g|·dt"""
    stabilization: float = 0.2
    """fraction of an existing penetration removed per step (0 = none)"""
    slop: float = 0.0005
    """m of penetration left alone by the stabilization"""
    max_push_velocity: float = 1.0
    """m/s: the stabilization never pushes apart faster"""
    time_of_impact: bool = True
    """split the step at the impact (see methods.impulse)"""

    def __post_init__(self):
        super().__post_init__()
        check_counts(self, {"iterations": 1, "substeps": 1, "substep_sweeps": 1, "substep_after": 1, "shock_sweeps": 0})
        if self.shock_sweeps > 0 and self.substeps > 1:
            raise InputError(
                "shock_sweeps",
                f"shock propagation ends an unconverged step instead of substeps; set substeps = 1 with "
                f"shock_sweeps = {self.shock_sweeps}, or shock_sweeps = 0",
            )
        check_choices(self, {"substep_when": SUBSTEP_WHEN})
        self._number("warm_start", 0.0, maximum=1.0)
        self._number("restitution_threshold")
        self._number("stabilization", 0.0, maximum=1.0)
        self._number("slop", 0.0)
        self._number("max_push_velocity", 0.0)
        self._number("contact_hertz", 0.0)
        check_flags(self, ("block_solve", "time_of_impact"))


LOAD_PATH_FROM = 2  # bodies and particles: fewer cannot rest on one another (guess_new_impulses)


@njit(cache=True)
def guess_new_impulses(
    warm: np.ndarray,
    found: np.ndarray,
    contacts: ContactArrays,
    positions: tuple[np.ndarray, np.ndarray],
    loads: tuple,
    settings: LoopSettings,
    cloth_of: np.ndarray,
) -> None:
    """The warm start of the contacts that carry nothing from the last step (``found`` (C,) False):
    the weight each would bear at rest, over the step. ``warm`` (C, 3) [N s] holds the carried
    impulses times the fraction f = ``settings.warm_start``; a new contact whose normal lies within
    72° of vertical gets f · W h along its normal, W [N] its share of the load path
    (``penalty_springs.supported_loads``: each body's weight and what rests on it, shared among
    the contacts it rests on), h = ``settings.dt`` [s]; the others keep 0. ``positions`` = (the
    bodies' (B, 3), the particles' (P, 3)) [m]; ``loads`` = (body masses (B,), particle masses
    (P,)) [kg], gravity (3,) [m/s²]).

    A scene of fewer than LOAD_PATH_FROM bodies and particles has no load path to build (its
    one body's contacts find its weight in a sweep or two): nothing is guessed there.
    ``cloth_of`` is ``Colliders.cloth_of`` (the cloth of each body and particle, whose springs
    carry its weight in the load path).

    Why: started from zero, a stack must build its load path sweep by sweep, the weight of the
    top box reaching the floor only after as many sweeps as there are levels; started from the
    weights, a 20-level pyramid's solve takes about half the sweeps over 5 s (9.2 → 4.9), most
    of it in the first second. The solve itself, and so its answer to the tolerance, is
    unchanged: a guess too large (an impact, a contact about to open) is taken back by the
    accumulated clamping like any warm start."""
    fraction, h = settings.warm_start, settings.dt
    (body_position, particle_position), gravity = positions, loads[2]
    B = body_position.shape[0]
    g = np.sqrt(gravity[0] ** 2 + gravity[1] ** 2 + gravity[2] ** 2)
    if fraction <= 0.0 or g == 0.0 or found.all() or B + particle_position.shape[0] < LOAD_PATH_FROM:
        return  # weightless, or nothing new to guess: the carried values as they are
    sides = (
        entities_of(contacts.body_a, contacts.particles_a, B),
        entities_of(contacts.body_b, contacts.particles_b, B),
    )
    weights = supported_loads(sides, contacts.normal, positions, loads, cloth_of)
    for c in range(found.shape[0]):
        if found[c]:
            continue
        normal = contacts.normal[c]
        along = (normal[0] * gravity[0] + normal[1] * gravity[1] + normal[2] * gravity[2]) / g
        if abs(along) > SUPPORT_COSINE:
            warm[c, 0] = fraction * weights[c] * h


@njit(cache=True)
def resting_targets(gap_at_start: np.ndarray, settings: LoopSettings) -> np.ndarray:
    """The least normal relative velocity each contact may end the step of ``settings.dt`` [s] with
    (C,) [m/s], from each gap at the step's start d₀ (C,) [m] (> 0 open, < 0 overlapping).

    Velocity-level non-penetration (C5b): the gap at the end of the step, d₀ + h v_n, must not
    be negative, so v_n ≥ −d₀/h; an open contact (d₀ > 0) may still approach that fast — a
    speculative contact. An existing penetration (d₀ < 0) is removed gradually: a fraction
    ``settings.stabilization`` of its depth beyond ``settings.slop`` [m] per step, never faster
    than ``settings.max_push_velocity`` [m/s] (a deep overlap must not turn into a launch)."""
    target = np.empty_like(gap_at_start)
    for c in range(gap_at_start.shape[0]):
        target[c] = resting_target(gap_at_start[c], settings)
    return target


@njit(cache=True)
def gravity_along_normals(
    body_a: np.ndarray,
    body_b: np.ndarray,
    particles_a: np.ndarray,
    particles_b: np.ndarray,
    normal: np.ndarray,
    gravity: np.ndarray,
) -> np.ndarray:
    """g_n per contact (C,) [m/s²]: the normal component of the gravity of A relative to B,
    (dynamic A − dynamic B) n · g.

    Symplectic Euler carries velocities at the middle of the step (it is leapfrog), so the
    velocity at the moment of impact is u = v_n* + g_n (τ − ½) h. Restitution reverses u and
    gravity acts over the rest of the step (see ``resolve_collisions``)."""
    out = np.empty(normal.shape[0])
    for c in range(normal.shape[0]):
        dynamic_a = 1.0 if body_a[c] >= 0 or particles_a[c, 0] >= 0 else 0.0
        dynamic_b = 1.0 if body_b[c] >= 0 or particles_b[c, 0] >= 0 else 0.0
        out[c] = (dynamic_a - dynamic_b) * (
            normal[c, 0] * gravity[0] + normal[c, 1] * gravity[1] + normal[c, 2] * gravity[2]
        )
    return out


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
    """τ per body (B,) and particle (P,): the earliest impact among its contacts (tau (C,), −1
    where a contact had none); 0 for an entity with no impact, whose velocity change then acts
    over the whole step."""
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


@njit(cache=True, inline="always")
def impact_of(gap: float, normal_velocity: float, gravity_normal: float, h: float) -> tuple[float, float]:
    """(τ, u) of a contact that closes within the step of h [s]: τ = d₀ / (−h v_n), at most 1,
    the fraction of the step at which its gap d₀ [m] (0 where ≤ 0) closes at the normal velocity
    v_n < 0 [m/s], and its velocity at that moment u = v_n + g_n (τ − ½) h [m/s] (symplectic
    Euler is leapfrog: v_n is the velocity at mid-step)."""
    closes = min(gap / (-normal_velocity * h), 1.0) if gap > 0.0 else 0.0
    return closes, normal_velocity + gravity_normal * (closes - 0.5) * h


@njit(cache=True, inline="always")
def bounce_target(restitution: float, impact: float, gravity_normal: float, closes: float, h: float) -> float:
    """[m/s] the mid-step normal velocity at which a contact that met at the impact velocity u
    [m/s] at τ (``impact_of``) leaves: −ε u + g_n (½ − τ) h."""
    return -restitution * impact + gravity_normal * (0.5 - closes) * h


@njit(cache=True)
def impact_targets(
    gap_at_start: np.ndarray,
    normal_velocity: np.ndarray,
    gravity_normal: np.ndarray,
    restitution: np.ndarray,
    settings: LoopSettings,
) -> tuple[np.ndarray, np.ndarray]:
    """Every contact's target normal velocity, all contacts at once (a simultaneous impact: the
    constraints method, C5b).

    gap_at_start d₀ (C,) [m]; normal_velocity v_n* (C,) [m/s] without contact forces;
    gravity_normal g_n (C,) [m/s²]; restitution ε (C,); h = ``settings.dt`` [s]. A contact that
    closes within the step (v_n* < 0, d₀ + h v_n* ≤ 0) does so at the fraction τ = d₀ / (−h v_n*)
    of it, with the impact velocity u = v_n* + g_n (τ − ½) h (symplectic Euler is leapfrog); if u <
    −``settings.threshold`` [m/s] and ε > 0 it must leave at −ε u + g_n (½ − τ) h. Every other
    contact gets ``resting_targets`` (the settings' stabilization, slop [m] and max push velocity
    [m/s]). Returns (target (C,) [m/s], τ (C,), −1 where there was no impact)."""
    h, threshold = settings.dt, settings.threshold
    C = gap_at_start.shape[0]
    target = np.empty(C)
    tau = np.empty(C)
    for c in range(C):
        gap, vn = gap_at_start[c], normal_velocity[c]
        if vn < 0.0 and gap + h * vn <= 0.0 and restitution[c] > 0.0:  # closing within the step: a bounce?
            closes, impact = impact_of(gap, vn, gravity_normal[c], h)
            if impact < -threshold:
                target[c] = bounce_target(restitution[c], impact, gravity_normal[c], closes, h)
                tau[c] = closes
                continue
        target[c] = resting_target(gap, settings)
        tau[c] = -1.0
    return target, tau


# ---- stages 4–5, compiled: what the compiled loop and the methods' step both run ------------


@njit(cache=True)
def resolve_collisions(
    rows: ContactRows,
    materials: tuple[np.ndarray, np.ndarray],
    gravity_normal: np.ndarray,
    gap_at_start: np.ndarray,
    u: np.ndarray,
    tau: np.ndarray,
    order: np.ndarray,
    settings: LoopSettings,
) -> int:
    """Collision impulses (I2, R1–R4, F2) in waves, until no contact approaches.

    A wave is every contact that is approaching now: at the current velocities it would be
    closed by the end of the step, and its impact velocity u_n = v_n + g_n (τ − ½) h is below
    −threshold (τ: where in the step it closes, d₀ / (−h v_n) for a gap d₀ > 0 at the start,
    else 0). The wave's impulses are solved together — accumulated, λ ≥ 0 — so that each
    member leaves at −ε u_n + g_n (½ − τ) h (restitution; see ``gravity_along_normals``), with
    friction of at most μ λ (F2). A single contact gets j = −(1 + ε) u_n / k in one update
    (R4 with k = J M⁻¹ Jᵀ). Simultaneous impacts (a box landing flat on four corners) are
    thus one wave and stay symmetric, while an impact passed along a chain of touching
    bodies makes one wave per link (Newton's cradle: one ball in, one ball out).

    ``rows`` as from ``contact_rows``; ``materials`` = (friction μ, restitution ε) (C,) each;
    gravity_normal, gap_at_start (C,) [m/s², m]; u the generalized velocity (changed in place);
    ``tau`` (C,) receives each contact's τ, −1 where it had no impact; ``order`` (C,) int is the
    order in which a wave's members are swept (see ``solve_order``); of the ``settings``: h =
    ``dt`` [s], the ``threshold`` [m/s], and ``iterations``, the most waves and the most sweeps of
    one, each stopping once no contact's velocity changes by more than ``tolerance`` [m/s].
    Returns the number of waves.
    """
    friction, restitution = materials
    dt, threshold, tolerance = settings.dt, settings.threshold, settings.tolerance
    max_waves = sweeps = settings.iterations
    k = rows.k
    C = k.shape[0]
    target = np.empty(C)
    closes = np.empty(C)
    impulses = np.zeros((C, 3))
    members = np.empty(C, dtype=np.int64)
    for c in range(C):
        tau[c] = -1.0
    for wave in range(max_waves):
        count = np.int64(0)  # not a literal 0, which would compile sweep_contacts twice
        for o in range(C):
            c = order[o]
            if restitution[c] <= 0.0 or k[c, 0] <= 0.0:
                continue
            vn = contact_velocity(c, rows, u)[0]
            if vn >= 0.0 or gap_at_start[c] + dt * vn > 0.0:  # separating, or still open at the end
                continue
            closes[c], impact = impact_of(gap_at_start[c], vn, gravity_normal[c], dt)
            if impact < -threshold:
                target[c] = bounce_target(restitution[c], impact, gravity_normal[c], closes[c], dt)
                tau[c] = closes[c] if tau[c] < 0.0 else min(tau[c], closes[c])
                impulses[c, 0] = impulses[c, 1] = impulses[c, 2] = 0.0
                members[count] = c
                count += 1
        if count == 0:
            return wave
        for _sweep in range(sweeps):
            if sweep_contacts(members, count, target, impulses, rows, friction, u) <= tolerance:
                break
    return max_waves


@njit(cache=True)
def targets(
    model: LoopModel,
    settings: LoopSettings,
    impulse: bool | None,
    constraints: bool | None,
    contacts: ContactArrays,
    rows: ContactRows,
    u: np.ndarray,
    order: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Stage 4b: each normal row's target velocity (C,) [m/s] and time of impact τ (C,) (−1:
    none). Impulse: the collision waves (``resolve_collisions``) change u, then every
    contact rests (``resting_targets``); constraints: all impacts at once (``impact_targets``).
    ``impulse``, ``constraints``: whether the run is that method's, read as the step runs: impulse
    and constraints runs share one compiled loop (a kind of run fewer to compile)."""
    gap_at_start = -contacts.depth
    gravity_normal = gravity_along_normals(
        contacts.body_a, contacts.body_b, contacts.particles_a, contacts.particles_b, contacts.normal, model.gravity
    )
    if impulse:
        tau = np.empty(gap_at_start.shape[0])
        materials = (contacts.friction, contacts.restitution)
        resolve_collisions(rows, materials, gravity_normal, gap_at_start, u, tau, order, settings)
        return resting_targets(gap_at_start, settings), tau
    if not constraints:  # neither: no velocity method (never so; see ``specialization``)
        raise ValueError("targets: neither impulse nor constraints")
    normal_velocity = row_products(rows, u)[:, 0]
    return impact_targets(gap_at_start, normal_velocity, gravity_normal, contacts.restitution, settings)


@njit(cache=True, inline="always")
def warm_impulses(
    model: LoopModel,
    settings: LoopSettings,
    contacts: ContactArrays,
    motion: Motion,
    carried_ids: np.ndarray,
    carried_values: np.ndarray,
) -> np.ndarray:
    """The solve's first impulses (C, 3) [N s] (warm start): last step's impulses ``carried_values``
    (K, 3) of the contacts ``carried_ids`` (K,) that persist (by id), times the warm-start
    fraction; a new contact's weight over the step (``guess_new_impulses``); zeros at fraction 0."""
    values, found = values_carried(carried_ids, carried_values, contacts.feature_id)
    warm = settings.warm_start * values
    positions = (motion.body_position, motion.particle_position)
    loads = (model.body_mass, model.particle_mass, model.gravity)
    guess_new_impulses(warm, found, contacts, positions, loads, settings, model.colliders.cloth_of)
    return warm


@njit(cache=True)
def split_at_impact(
    model: LoopModel,
    contacts: ContactArrays,
    motion: Motion,
    tau: np.ndarray,
    velocities: tuple,
    solved: np.ndarray,
    settings: LoopSettings,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stage 5: positions x = x₀ + h v⁺ (h = ``settings.dt`` [s]), with the part of the step before
    each body's and particle's earliest impact (τ (C,) per contact, −1 where none;
    ``earliest_impacts``) travelled with the velocities that moved the prediction and the rest with
    them corrected by the solve, move + (v⁺ − v*), v⁺ the generalized velocity ``solved`` (N,):
    ``velocities`` = (move: v*, or the old velocities under explicit Euler; v*, the free
    velocities), each (body (B, 3), angular (B, 3), particle (P, 3)). ``settings.time_of_impact``
    False: no split (τ = −1 everywhere). Returns (body positions (B, 3) [m], orientations (B, 4),
    particle positions (P, 3) [m])."""
    move, free = velocities
    h = settings.dt
    B, P = motion.body_position.shape[0], motion.particle_position.shape[0]
    if not settings.time_of_impact:
        tau = np.full(tau.shape[0], -1.0)
    tau_body, tau_particle = earliest_impacts(
        contacts.body_a, contacts.body_b, contacts.particles_a, contacts.particles_b, tau, B, P
    )
    after = (solved[: 6 * B].reshape(B, 6), solved[6 * B :].reshape(P, 3))
    corrected_body = move[0] + (after[0][:, :3] - free[0])
    corrected_angular = move[1] + (after[0][:, 3:] - free[1])
    corrected_particle = move[2] + (after[1] - free[2])
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


# inlined into the compiled loop's step, where a call that passes the model and the state whole
# costs more than a ball's arithmetic; from Python (``step``) a dispatcher of its own
@njit(cache=True, inline="always")
def respond(
    model: LoopModel,
    settings: LoopSettings,
    spec: Specialization,
    contacts: ContactArrays,
    motion: Motion,
    rotation: np.ndarray,
    velocities: tuple,
    carried: tuple,
) -> tuple:
    """Stages 4–5 of loop L3 for the contacts detected at ``motion``'s positions (the bodies'
    rotations (B, 3, 3) ``rotation``): their rows, the targets of the normal rows (impulses: the
    collision waves first; constraints: all impacts at once), the warm-started sweeps of
    sequential impulses (projected Gauss-Seidel on velocities, C7) from the free velocities
    v*, and the positions split at the time of impact. ``velocities`` = (what moved the
    prediction, v*: each (body (B, 3), angular (B, 3), particle (P, 3))); ``spec``: the run's
    Specialization (its ``impulse``, ``constraints``, ``slabs`` and ``parallel`` read here);
    ``carried`` = (last step's contact ids (K,), their impulses (K, 3)). Returns (positions,
    velocities v⁺ ((B, 3), (B, 3), (P, 3)), impulses (C, 3) [N s] — the warm start carried to the
    next step —, sweeps made, the sweeps' last change [m/s]).

    With ``settings.substeps`` n > 1 (small steps): a step whose solve ends above the tolerance
    (capped at ``settings.whole_sweeps`` sweeps), or every step where ``settings.always_substep``,
    is solved again in n substeps of h/n (``sequential.solve_in_substeps``) from the velocity at
    the step's start, gravity added a substep at a time, warm-started from that answer; the
    positions then move with the substeps' mean velocity. With ``settings.shock_sweeps`` > 0
    (and no substeps), a step the solve leaves above the tolerance ends with the shock-propagation
    pass (``shock.propagate_shock``), its impulses not carried. A step that converges is the plain
    solve's, bit for bit. A substepped step returns the substeps' summed impulses, or, where the
    whole-step sweeps ran to their cap without giving up, the whole-step answer (the warm start
    the next step's sweeps settle from)."""
    # 4. formulate the contact rows, their targets (collisions first, for impulses), and solve
    move, free = velocities
    rows = build_rows(model, contacts, motion, rotation)
    u = stacked(free[0], free[1], free[2])
    order = contact_order(contacts.point, contacts.feature_id, model.gravity)
    target, tau = targets(model, settings, spec.impulse, spec.constraints, contacts, rows, u, order)
    warm = warm_impulses(model, settings, contacts, motion, carried[0], carried[1])
    if settings.substeps <= 1:
        impulses, sweeps, change = _whole_step_solve(settings, spec, rows, contacts, motion, (u, target, warm, order))
        if change > settings.tolerance:  # unconverged: the shock pass, where the Options ask for it
            sweeps += shock_pass(spec.shock, settings, rows, contacts.friction, (u, target, impulses, order))
        return _respond_end(model, settings, contacts, motion, tau, velocities, (u, u, impulses, sweeps, change))
    # small steps (settings.substeps > 1): the whole step's solve first, unless always substepped; a step it
    # leaves unconverged is solved again in substeps from the velocity at the start, warm-started from its answer
    entry = u.copy()
    impulses, sweeps, change = warm, 0, np.inf
    if not settings.always_substep:
        impulses, sweeps, change = _whole_step_solve(settings, spec, rows, contacts, motion, (u, target, warm, order))
    if change <= settings.tolerance:
        return _respond_end(model, settings, contacts, motion, tau, velocities, (u, u, impulses, sweeps, change))
    n = settings.substeps
    start = stacked(motion.body_velocity, motion.body_angular_velocity, motion.particle_velocity)
    free_u = stacked(free[0], free[1], free[2])
    increment = np.empty_like(u)
    for i in range(u.shape[0]):  # gravity a substep at a time; the collision waves' impulses (impulse) at once
        increment[i] = (free_u[i] - start[i]) / n
        u[i] = entry[i] - (free_u[i] - start[i])
    fixed = tau >= 0.0  # constraints' bounces keep their targets; impulse's were its waves
    if spec.impulse:
        fixed[:] = False
    travelled = np.empty_like(u)
    substepping = (fixed, -contacts.depth, increment, travelled)
    whole = impulses
    impulses, more, change = solve(
        settings, spec.slabs, spec.parallel, rows, contacts, motion, (u, target, whole, order), substepping
    )
    as_before_where_unpushed(contacts, impulses, free[0].shape[0], entry, u, travelled)
    # the impulses carried on, the next step's warm start: the substeps' sum, but where the
    # whole-step sweeps ran to their cap (close, not given up), their answer — a stack's redundant
    # supports share its load as the whole-step sweeps share it, and the next step's sweeps start
    # from there; from the substeps' share they stalled (a pyramid of touching boxes: 18.3
    # sweeps a step instead of 3.7)
    if sweeps >= settings.whole_sweeps:
        impulses = whole
    sweeps += more
    return _respond_end(model, settings, contacts, motion, tau, velocities, (u, travelled, impulses, sweeps, change))


@njit(cache=True, inline="always")
def _whole_step_solve(settings, spec, rows, contacts, motion, system):
    """``respond``'s whole-step solve: in blocks per manifold where the Options ask for it
    (``block_pass``), else ``loop_stages.solve``'s sweeps."""
    impulses, sweeps, change = block_pass(spec.blocks, settings, rows, contacts.friction, system)
    if sweeps < 0:  # no block solve asked for
        return solve(settings, spec.slabs, spec.parallel, rows, contacts, motion, system, None)
    return impulses, sweeps, change


@njit(cache=True)
def block_pass(
    blocks: bool | None, settings: LoopSettings, rows: ContactRows, friction: np.ndarray, system: tuple
) -> tuple[np.ndarray, int, float]:
    """``blocks.solve_in_blocks`` (serial) of ``system`` = (u (N,), changed in place; the targets
    (C,) [m/s]; the warm start (C, 3) [N s]; the sweep order (C,)), at most ``settings.whole_sweeps``
    sweeps to ``settings.tolerance``: (impulses (C, 3) [N s], sweeps, last change [m/s]). ``blocks``
    None (the Specialization's: no block solve asked for) compiles none of it and returns −1 sweeps."""
    if blocks is None:
        return np.empty((0, 3)), -1, 0.0
    u, target, warm, order = system
    return solve_in_blocks(rows, friction, target, u, (settings.whole_sweeps, settings.tolerance), warm, order)


@njit(cache=True)
def shock_pass(
    shock: bool | None, settings: LoopSettings, rows: ContactRows, friction: np.ndarray, system: tuple
) -> int:
    """``shock.propagate_shock`` on ``system`` = (u (N,), changed in place; the targets (C,) [m/s];
    the sweeps' impulses (C, 3) [N s], left as they are; the sweep order (C,)), at most
    ``settings.shock_sweeps`` sweeps a level to ``settings.tolerance``; returns the sweeps it made.
    ``shock`` None (the Specialization's: no shock propagation asked for) compiles none of it."""
    if shock is None:
        return 0
    u, target, impulses, order = system
    return propagate_shock(rows, friction, target, impulses, u, order, (settings.shock_sweeps, settings.tolerance))


@njit(cache=True)
def as_before_where_unpushed(
    contacts: ContactArrays, impulses: np.ndarray, B: int, entry: np.ndarray, u: np.ndarray, travelled: np.ndarray
) -> None:
    """After a substepped solve: every body and particle that no contact pushed (each of its
    contacts' normal impulses (C, 3) summed over the substeps is 0) gets back the velocity it
    entered the solve with, ``entry`` (N,) — v*, and for impulse the collision waves' — as its
    final velocity u and the one it travels with (``travelled``), both (N,) and changed in
    place: it moves as in a step without that contact, the symplectic Euler step whose flight
    the bounce heights' closed form holds to (substeps of gravity alone would move it by
    h² g (n − 1) / 2n more each step it has a speculative contact). ``B`` bodies."""
    pushed = np.zeros(u.shape[0], dtype=np.bool_)
    for c in range(impulses.shape[0]):
        if impulses[c, 0] == 0.0:  # a normal impulse ≥ 0 in every substep: none in any
            continue
        for b in (contacts.body_a[c], contacts.body_b[c]):
            if b >= 0:
                for i in range(6):
                    pushed[6 * b + i] = True
        for k in range(3):
            for p in (contacts.particles_a[c, k], contacts.particles_b[c, k]):
                if p >= 0:
                    for i in range(3):
                        pushed[6 * B + 3 * p + i] = True
    for i in range(u.shape[0]):
        if not pushed[i]:
            u[i] = entry[i]
            travelled[i] = entry[i]


@njit(cache=True, inline="always")
def _respond_end(model, settings, contacts, motion, tau, velocities, solved):
    """``respond``'s stage 5 and its result: ``solved`` = (the solved velocity u (N,), what the
    positions move with (N,) — u, or its mean over the substeps —, impulses, sweeps, change); the
    positions split at the time of impact."""
    u, travelled, impulses, sweeps, change = solved
    # 5. recompute positions from the corrected velocities (their mean over the substeps), split at the time of impact
    positions = split_at_impact(model, contacts, motion, tau, velocities, travelled, settings)
    return positions, unstacked(u, motion.body_position.shape[0]), impulses, sweeps, change


# ---- the step from Python: stages 1–3 for any scene, 4–5 compiled ---------------------------


def step(
    method: str,
    model: Model,
    state: State,
    dt: float,
    options: ImpulseOptions | ConstraintsOptions,
    integrator: str = "symplectic_euler",
) -> tuple[State, StepInfo]:
    """One step of loop L3 with impulses (``method`` "impulse") or hard constraints on velocities
    swept matrix-free ("constraints"); returns (new State, StepInfo). Stages 1–3 run here, for
    every scene (cloth springs, meshes, driven bodies, every integrator); stages 4–5 are
    ``respond``, the very code the compiled loop (methods.velocity_loop) runs."""
    h = dt
    # 1. internal forces → free velocities v*
    free = _floats(free_velocities(model, state, h, integrator))
    # 2. integrate positions (a prediction): how far each body and particle sweeps this step
    move, predicted, sweep = predict_positions(model, state, free, integrator, h)
    # 3. collision detection over the swept step
    contacts, manifolds = swept_contacts(model, state, options, sweep, h * move[2])
    if contacts.count == 0:
        carried = carrying_springs(Carry.none(method, manifolds), model, state, free[2], integrator)
        return step_without_contacts(state, h, (predicted, free), contacts, carried)
    # 4–5. the contacts' response, and the positions after it
    arrays, motion, rotation, carried = loop_inputs(model, state, method)
    settings = loop_settings(model, method, options, dt)
    spec = for_response(specialization(model, method, options))
    positions, velocities, impulses, sweeps, change = respond(
        arrays, settings, spec, contacts.arrays(), motion, rotation, (_floats(move), free), carried
    )
    kept = carrying_springs(Carry(method, manifolds, contacts.feature_id, impulses), model, state, free[2], integrator)
    new = State.assemble(state.time + h, positions, velocities, kept)
    return new, StepInfo(contacts, solver_iterations=int(sweeps), solver_residual=float(change), impulses=impulses)


def _floats(arrays: tuple) -> tuple:
    """Each array as a writable, C-contiguous float64 copy: the one type the compiled stages are
    compiled for (a read-only or strided array would compile them again)."""
    return tuple(np.array(a, dtype=float) for a in arrays)
