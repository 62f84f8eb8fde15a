"""The stages every compiled step shares, and the loop's data (loops L1–L3).

The arrays ``run_steps`` (:mod:`contactlab.methods.velocity_loop`) steps — the model's (LoopModel),
the settings as plain numbers (LoopSettings), the state's six arrays (Motion) and the recording
(Samples) — and the stages each method's compiled step (:mod:`contactlab.methods.loop_steps`)
calls: free motion (``integrators.free_flight``), how far each collider sweeps
(``collision.swept_reach``), detection with kept manifolds (``collision.detect``) — each the one
function the methods' steps from Python call too, inlined here —, the contact rows, the
sequential-impulse sweeps, and after a step the state stored, checked and recorded. They live
apart from the steps so that each step reads as its loop on the slide.

Numba caches each of these next to this file, but ``run_steps`` compiles them in and is refreshed
only when ``velocity_loop.py`` changes: after editing a stage here, delete the caches
(README, "For developers").

Arrays, as in the rest of contactlab: B bodies, P particles, O obstacles, N = B + P + O
colliders, C contacts; the generalized velocity u (6B + 3P,) in the DOF layout of
contactlab.contacts.
"""

from __future__ import annotations

from collections import namedtuple
from typing import TYPE_CHECKING, Any

import numpy as np
from numba import types
from numba.extending import overload

from .. import collision, diagnostics, rotations
from ..collision import Plan, colliders, detection_plan, keeping_for
from ..collision.geometry import norm
from ..collision.manifolds import copy_rows, no_manifolds
from ..collision.narrow_phase import MAX_PER_PAIR
from ..compiling import available_threads, inlined, njit
from ..contacts import ContactArrays
from ..diagnostics import SERIES
from ..driving import DriveTable, drive_velocities
from ..dynamics import integrators
from ..model import derived
from ..state import ARRAYS as STATE_ARRAYS
from .jacobian_rows import ContactRows, rows_at
from .sequential import (
    PARALLEL_MIN_CONTACTS,
    SWEEP_GROUPS,
    hopeless_change,
    solve_in_substeps,
    solve_sequential_impulses,
    split_into_slabs,
)

if TYPE_CHECKING:
    from ..model import Model
    from ..state import State
    from .base import CollisionOptions

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
        "colliders",  # the colliders as detection reads them (collision.Colliders, the same value)
    ),
)
LoopModel.__doc__ = """The model's arrays the loop reads (writable copies: Numba types read-only arrays apart).
Not its drive, which only free motion reads, an argument of its own (``driving.table_of``): every
other stage takes the LoopModel, so a driven scene's contacts, rows, sweeps and samples run the
undriven scene's compiled code, and no call passes the drive's nine arrays along (on a one-ball
scene, that cost a fifth of a step)."""


@derived
def loop_model(model: Model) -> LoopModel:
    """The LoopModel of a Model (writable copies of its arrays): built on first use and kept with
    the model (``contactlab.model.derived``)."""
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
        colliders(model),
    )


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
        "substeps",
        "substep_sweeps",
        "always_substep",
        "whole_sweeps",
        "shock_sweeps",
        "contact_hertz",
    ),
)
LoopSettings.__doc__ = """A method's Options as plain numbers: dt [s], sweeps, tolerance
([m/s]; projection: [m]), restitution threshold [m/s] (resolved), stabilization, slop [m], max push [m/s],
time of impact (bool), warm-start fraction, contact margin [m], manifold tolerance [m] (0: nothing kept),
detect-and-project passes, the velocity methods' substeps, sweeps a substep and whether every step is
substepped (else only an unconverged one), the most sweeps of a whole-step solve (``iterations``, or
fewer where an unconverged step goes on in substeps: ``substep_after``), the most sweeps a level of the
shock-propagation pass makes after an unconverged step (0: no pass), the substeps' soft contacts'
stiffness [Hz] (0: rigid). What a method's Options lack is 0 (False, 1 pass, 1 substep): see
``loop_settings``."""

Motion = namedtuple("Motion", STATE_ARRAYS)
Motion.__doc__ = "The state's six arrays, (B, 3), (B, 4), (B, 3), (B, 3), (P, 3), (P, 3), changed in place."

Samples = namedtuple("Samples", SERIES)
Samples.__doc__ = "Preallocated recording arrays, one row per sample: the series of contactlab.diagnostics.SERIES."


# ---- the Options and the scene as the loop's settings and flags ----------------------------

PARALLEL_MIN_COLLIDERS = 100  # fewer bodies and particles: no parallel sweep is compiled in

Specialization = namedtuple(
    "Specialization",
    ("plan", "keeping", "constraints", "impulse", "projection", "slabs", "parallel", "penalty", "shock", "blocks"),
)
Specialization.__doc__ = """What a run's compiled code is specialized for, as one value: the detection Plan;
``keeping`` (True: a pair family that keeps manifolds and a manifold tolerance > 0); the method
(``constraints``, ``impulse``: whether it is the run's, values the one velocity loop of both reads as
it runs; ``projection``: True for projection's runs, None for the others; ``penalty``:
penalty's PenaltyLoop, else None); ``slabs`` (True: PARALLEL_MIN_CONTACTS contacts are possible,
MAX_PER_PAIR per pair) and ``parallel`` (True: several threads and PARALLEL_MIN_COLLIDERS bodies and
particles); ``shock`` and ``blocks`` (True: the Options' shock propagation, block solves). A flag that is
None leaves its branch uncompiled; the numbers are the same whatever it holds (``shock`` and ``blocks``
aside, which are the Options' own choices).

Numba leaves a branch uncompiled only where it tests an *argument* typed None, never a field of a tuple:
each flag reaches the one kernel that branches on it as an argument of its own (``candidate_pairs``
``large``, ``targets`` ``impulse`` and ``constraints``, ``solve`` ``slabs`` and ``parallel``,
``velocity_level.shock_pass`` ``shock``, ``velocity_level.block_pass`` ``blocks``), or is
chosen on by its type when compiling (``collision._kept_or_fresh``, ``for_response``)."""


def specialization(model: Model, method: str, options: CollisionOptions, penalty: Any = None) -> Specialization:
    """The Specialization of ``method``'s runs on ``model`` with these Options (``penalty``: penalty's
    PenaltyLoop): a first run compiles a fraction of the loop — a ball on the floor needs neither
    the grid broad phase, nor kept manifolds, nor the slab split; projection not the velocity
    methods' step, nor they projection's. Impulse and constraints differ by values, not types:
    their runs share one compiled loop."""
    dynamic, obstacles = model.body_count + model.particle_count, model.obstacle_count
    most_contacts = MAX_PER_PAIR * (dynamic * (dynamic - 1) // 2 + dynamic * obstacles)
    return Specialization(
        detection_plan(model),
        keeping_for(model, getattr(options, "manifold_tolerance", 0.0)),
        method == "constraints",
        method == "impulse",
        True if method == "projection" else None,
        True if most_contacts >= PARALLEL_MIN_CONTACTS else None,
        True if available_threads() > 1 and dynamic >= PARALLEL_MIN_COLLIDERS else None,
        penalty,
        True if getattr(options, "shock_sweeps", 0) > 0 else None,
        True if getattr(options, "block_solve", False) else None,
    )


def for_response(spec: Specialization) -> Specialization:
    """``spec`` without what only detection reads (its Plan and ``keeping``): what the response's
    kernels (``respond``, ``project``, ``finish``) take, so that they are compiled once for every
    scene of one method and one solve, whatever its shapes."""
    return spec._replace(plan=None, keeping=None)


# chosen by the types of the Plan and keeping: the same tuple where both are None, else a new one
# without them (no copy)
@overload(for_response, inline="always")
def _for_response_compiled(spec):  # type: ignore[no-untyped-def]  # Numba: unannotated as the impl
    if isinstance(spec.types[0], types.NoneType) and isinstance(spec.types[1], types.NoneType):
        return lambda spec: spec
    return lambda spec: Specialization(None, None, *spec[2:])


def restitution_threshold(model: Model, h: float, options: CollisionOptions) -> float:
    """Approaches slower than this [m/s] get no bounce (impulse, constraints): the Options'
    ``restitution_threshold``, or 2 |g| h where it is < 0, for steps of h [s]."""
    if options.restitution_threshold >= 0:
        return float(options.restitution_threshold)
    return float(2.0 * np.linalg.norm(model.gravity) * h)


def loop_settings(model: Model, method: str, options: CollisionOptions, dt: float) -> LoopSettings:
    """The LoopSettings of ``method``'s Options for steps of dt [s], the restitution threshold
    resolved (``restitution_threshold``). Projection has no threshold, stabilization, push limit
    or time of impact (0, False there); the velocity methods make 1 pass."""
    velocity = method != "projection"
    return LoopSettings(
        dt=float(dt),
        iterations=int(options.iterations),
        tolerance=float(options.tolerance),
        threshold=restitution_threshold(model, dt, options) if velocity else 0.0,
        stabilization=float(options.stabilization) if velocity else 0.0,
        slop=float(options.slop),
        max_push_velocity=float(options.max_push_velocity) if velocity else 0.0,
        time_of_impact=bool(options.time_of_impact) if velocity else False,
        warm_start=float(options.warm_start),
        margin=float(options.contact_margin),
        manifold_tolerance=float(options.manifold_tolerance),
        passes=1 if velocity else int(options.passes),
        substeps=substeps(options),
        substep_sweeps=int(getattr(options, "substep_sweeps", 1)),
        always_substep=getattr(options, "substep_when", "unconverged") == "always",
        whole_sweeps=whole_sweeps(options),
        shock_sweeps=int(getattr(options, "shock_sweeps", 0)),
        contact_hertz=float(getattr(options, "contact_hertz", 0.0)),
    )


def substeps(options: CollisionOptions) -> int:
    """The substeps an unconverged step goes on in: the Options' ``substeps``; 1 (none) where they
    have none (projection, penalty) and in constraints' accelerations formulation, which solves
    each step whole."""
    if getattr(options, "formulation", "velocity") != "velocity":
        return 1
    return int(getattr(options, "substeps", 1))


def whole_sweeps(options: CollisionOptions) -> int:
    """The most sweeps of one whole-step solve: ``iterations``, and no more than ``substep_after``
    where a step they leave unconverged goes on in substeps (``substeps`` > 1)."""
    if substeps(options) > 1:
        return int(min(options.iterations, options.substep_after))
    return int(options.iterations)


def loop_inputs(model: Model, state: State, method: str) -> tuple[LoopModel, Motion, np.ndarray, tuple]:
    """What the compiled stages take in a method's step from Python (``velocity_level.step``,
    ``projection.step``, ``penalty.step``, which apply the drive themselves in
    ``integrators.free_velocities``): (the LoopModel, the state's arrays as a Motion, the
    bodies' rotations (B, 3, 3), (last step's contact ids (K,), their values (K, 3)) where the
    state carries ``method``'s (``Carry.of``), else both empty)."""
    # copies, writable and contiguous: a read-only or strided array is another Numba type, and a
    # stage typed anew mid-run compiles again (a State's arrays may be views, or the Model's own)
    motion = Motion(*(np.array(getattr(state, name), dtype=float) for name in STATE_ARRAYS))
    ids, values = state.carried.of(method)
    carried = (np.array(ids, dtype=np.int64), np.array(values, dtype=float).reshape(-1, 3))
    return loop_model(model), motion, rotations.matrices(motion.body_orientation), carried


# ---- the stages every step shares (loops L1–L3) --------------------------------------------

# Each array a compiled call passes or returns is a reference taken and released, an atomic
# operation each, and on a one-ball scene these cost more than the arithmetic (608 a recorded
# airborne step before this, most of its time; 442 since). So the small kernels a step and its
# sample call are inlined here: the same Python functions, as dispatchers of their own that Numba
# inlines (their own dispatchers stay as they are for every other caller), and Numba's
# reference-count pruning then drops many of the pairs. Not detection: its Plan's None families
# leave their routines uncompiled, a pruning of arguments that an inlined copy (whose arguments
# are no longer arguments) does not get.
collider_poses = inlined(collision.collider_poses)
detect = collision.detect
# stages 1 (under gravity) and 2, as the methods' steps run them
free_flight = inlined(integrators.free_flight)
swept_reach = inlined(collision.swept_reach)
moved = inlined(integrators.moved)
kinetic = inlined(diagnostics.kinetic)
gravitational = inlined(diagnostics.gravitational)


# The stages a step runs that take the LoopModel or the Motion whole are inlined into their
# callers (or unpack them there and call a function of plain arrays): a call that passes a named
# tuple of 17 arrays takes and releases a reference to each, which on a one-ball scene cost more
# than the stage's arithmetic. (``store``, ``healthy`` and ``record``, which ``run_steps`` calls
# between steps, are not: linked into ``run_steps``, they measured as fast, and inlining them cost
# about 5 s of ``run_steps``'s compile. ``poses`` is inlined and calls ``poses_of``, which takes
# the five arrays it reads: 4–5 % of a ball run.)


@njit(cache=True, inline="always")
def free_motion(
    model: LoopModel, drive: DriveTable | None, motion: Motion, rotation: np.ndarray, h: float, t: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stage 1: velocities after h [s] under gravity, v* = v + h g (the gyroscopic term by the
    midpoint rule; pinned particles held), and in a driven scene the external loads at the step's
    start t [s] and the kinematic bodies' path velocities (``drive``'s, ``driving.drive_velocities``,
    which the methods' steps call too): (body (B, 3), angular (B, 3), particle (P, 3))."""
    body, angular, particle = free_flight(
        model.gravity,
        model.body_inertia,
        model.particle_pinned,
        motion.body_velocity,
        motion.body_angular_velocity,
        motion.particle_velocity,
        rotation,
        h,
    )
    inverse = (model.body_inverse_mass, model.body_inverse_inertia)
    pose = (rotation, motion.body_position, motion.body_orientation)
    drive_velocities(drive, t, h, inverse, pose, None, body, angular)  # None: nothing compiled
    return body, angular, particle


_norm = inlined(norm)  # geometry.norm, inlined into healthy


@njit(cache=True, inline="always")
def poses(model: LoopModel, motion: Motion) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The poses at ``motion``'s positions: the bodies' rotation matrices (B, 3, 3), and the
    colliders' centres (N, 3) [m] and rotations (N, 3, 3) (``collision.collider_poses``): what a
    step (``start``), ``detect`` and ``record`` take, computed once for a sample and the step
    after it. Inlined, it hands ``poses_of`` the five arrays it reads, not the two tuples whole
    (whose every array's reference a call takes and releases: 0.17 µs of a one-ball step)."""
    table = model.colliders
    return poses_of(
        motion.body_orientation,
        motion.body_position,
        motion.particle_position,
        table.obstacle_position,
        table.obstacle_rotation,
    )


@njit(cache=True)
def poses_of(
    body_orientation: np.ndarray,
    body_position: np.ndarray,
    particle_position: np.ndarray,
    obstacle_position: np.ndarray,
    obstacle_rotation: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``poses`` from the arrays: orientations (B, 4), positions (B, 3) [m], particle positions
    (P, 3) [m], the obstacles' positions (O, 3) [m] and rotations (O, 3, 3)."""
    rotation = rotations.matrices(body_orientation)
    centers, rots = collider_poses(body_position, rotation, particle_position, obstacle_position, obstacle_rotation)
    return rotation, centers, rots


@njit(cache=True, inline="always")
def swept_clear(near: bool, margin: float) -> bool:
    """Whether a step whose ``detect`` found no pair (``near`` False) leaves every collider clear
    of every other at its end: true where the step then moves them by the free velocities its
    ``swept_reach`` took (impulse, constraints, projection; not penalty, whose reach is taken
    before gravity) and the contact ``margin`` [m] > 0 — each collider's bounds at the end lie
    within its swept bounds by half the margin, far beyond rounding, so the zero-reach broad
    phase of ``record`` would find no pair either."""
    return not near and margin > 0.0


@njit(cache=True)
def build_rows(model: LoopModel, contacts: ContactArrays, motion: Motion, rotation: np.ndarray) -> ContactRows:
    """Stage 4a: the contacts' rows of J (a ContactRows) at the step's start."""
    inverse_inertia = rotations.world_tensors(rotation, model.body_inverse_inertia)
    return rows_at(
        contacts, motion.body_position, model.body_inverse_mass, inverse_inertia, model.particle_inverse_mass
    )


@njit(cache=True)
def solve(
    settings: LoopSettings,
    slabs: bool | None,
    parallel: bool | None,
    rows: ContactRows,
    contacts: ContactArrays,
    motion: Motion,
    system: tuple,
    substepping: tuple | None,
) -> tuple[np.ndarray, int, float]:
    """Stage 4c: the warm-started sweeps of sequential impulses, ``system`` = (u (N,), changed in
    place; the normal rows' targets (C,) [m/s]; the first impulses (C, 3) [N s]; the sweep order
    (C,)), the contacts grouped for threads as ``sequential.sweep_groups`` does (``slabs`` None: never
    PARALLEL_MIN_CONTACTS contacts, never grouped); ``parallel`` None compiles no parallel sweep
    (the groups are then swept one after the other: the same numbers). ``substepping`` None: one
    solve over the step; else (fixed (C,) bool, gaps at the start (C,) [m], the free motion's
    increment a substep (N,), the mean velocity over the substeps (N,), filled) for
    ``sequential.solve_in_substeps`` in ``settings.substeps`` substeps. Returns (impulses (C, 3)
    [N s], sweeps, last change [m/s])."""
    order = system[3]
    C = order.shape[0]
    grouped, starts = order, np.array([0, C, C])
    if slabs is None:
        return _solve_grouped(settings, rows, contacts, system, grouped, None, substepping)
    if C >= PARALLEL_MIN_CONTACTS:
        positions = (motion.body_position, motion.particle_position)
        grouped, starts = split_into_slabs(order, contacts.point, rows, positions, SWEEP_GROUPS)
    if parallel is None:
        return _solve_grouped(settings, rows, contacts, system, grouped, None, substepping)
    return _solve_grouped(settings, rows, contacts, system, grouped, starts, substepping)


@njit(cache=True, inline="always")
def _solve_grouped(settings, rows, contacts, system, order, starts, substepping):
    """``solve``'s sweeps in ``order`` with the groups ``starts`` (None: serial): in one solve, or in substeps."""
    u, target, warm = system[0], system[1], system[2]
    if substepping is None:  # with substeps to follow (respond), a hopeless whole-step solve gives up early
        until = (settings.whole_sweeps, settings.tolerance)
        give_up = hopeless_change(settings.whole_sweeps, settings.tolerance) if settings.substeps > 1 else np.inf
        return solve_sequential_impulses(rows, contacts.friction, target, u, until, warm, (order, starts), give_up)
    return solve_in_substeps(rows, contacts.friction, target, u, substepping, settings, warm, (order, starts))


# ---- after a step: the state stored, checked and recorded ---------------------------------


# store and healthy copy or check array by array through inlined helpers, not over a tuple of
# the arrays: each array a call or a tuple holds is a reference taken and released (an atomic
# operation each), which on a one-ball scene cost more than the copying itself


@njit(cache=True)
def store(motion: Motion, positions: tuple, velocities: tuple) -> None:
    """Copy a step's new positions and velocities into the state's arrays."""
    copy_rows(motion.body_position, positions[0])
    copy_rows(motion.body_orientation, positions[1])
    copy_rows(motion.particle_position, positions[2])
    copy_rows(motion.body_velocity, velocities[0])
    copy_rows(motion.body_angular_velocity, velocities[1])
    copy_rows(motion.particle_velocity, velocities[2])


@njit(cache=True)
def healthy(motion: Motion, max_speed: float) -> bool:
    """Every value finite and no body centre or particle faster than max_speed [m/s]."""
    # every array checked whole, without returning early: one exit keeps the pruning effective
    finite = (
        _finite(motion.body_position)
        & _finite(motion.body_velocity)
        & _finite(motion.body_angular_velocity)
        & _finite(motion.particle_position)
        & _finite(motion.particle_velocity)
        & _finite(motion.body_orientation)
    )
    return finite and _within(motion.body_velocity, max_speed) & _within(motion.particle_velocity, max_speed)


@njit(cache=True, inline="always")
def _finite(array):
    """Whether every entry of the 2-D ``array`` is finite."""
    finite = True
    for n in range(array.shape[0]):
        for i in range(array.shape[1]):
            finite &= np.isfinite(array[n, i])
    return finite


@njit(cache=True, inline="always")
def _within(velocity, max_speed):
    """Whether no row of ``velocity`` (n, 3) is longer than max_speed."""
    within = True
    for n in range(velocity.shape[0]):
        within &= _norm(velocity[n]) <= max_speed
    return within


@njit(cache=True)
def record(
    samples: Samples,
    row: int,
    model: LoopModel,
    plan: Plan,
    motion: Motion,
    at: tuple,
    time: float,
    tally: tuple,
) -> None:
    """Sample ``row``: the state, its energies (``diagnostics``: kinetic, gravitational) and its
    deepest overlap, measured afresh at its own positions by the one detection (``detect``, with
    no reach and nothing kept, as ``collision.collide`` runs it for a sample from Python), and
    ``tally`` = the step's (contact count, sweeps, last change, clear): where the count is −1 (no
    step), that of the fresh pass. ``plan``: the run's detection Plan. ``at`` = the bodies'
    rotations (B, 3, 3) and the colliders' centres and rotations at ``motion``'s positions
    (``poses``), which the next step starts from too. ``clear``: the step before found nothing
    within its swept reach (``swept_clear``), so nothing overlaps here and the fresh pass, which
    would find no pair, is not made."""
    contact_count, sweeps, change, clear = tally
    rotation, centers, rots = at
    samples.time[row] = time
    copy_rows(samples.body_position[row], motion.body_position)
    copy_rows(samples.body_orientation[row], motion.body_orientation)
    copy_rows(samples.body_velocity[row], motion.body_velocity)
    copy_rows(samples.body_angular_velocity[row], motion.body_angular_velocity)
    copy_rows(samples.particle_position[row], motion.particle_position)
    copy_rows(samples.particle_velocity[row], motion.particle_velocity)
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
    deepest, found = 0.0, 0
    # after a step that found nothing within its swept reach nothing overlaps (the fresh pass
    # would find no pair): on an airborne ball the pass was a quarter of a sampled step
    if not clear:
        touching = np.zeros(model.colliders.kinds.shape[0])
        depth = detect(model.colliders, plan, None, (centers, rots), touching, no_manifolds(), 0.0, None)[0].depth
        found = depth.shape[0]
        if found:
            deepest = max(0.0, depth.max())
    samples.max_penetration[row] = deepest
    samples.contact_count[row] = found if contact_count < 0 else contact_count
    samples.solver_iterations[row] = sweeps
    samples.solver_residual[row] = change
