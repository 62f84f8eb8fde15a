"""Projected Gauss-Seidel over contact rows, matrix-free (SPEC C7, F2, F4a on velocities or
displacements).

Every contact is three rows of the Jacobian J (normal, tangent1, tangent2) over one generalized
vector u in the DOF layout of contactlab.contacts. The same sweeps serve two methods:

* impulses (M2): u is the generalized velocity and the accumulated λ are impulses [N s];
* projection (M3): u is the generalized displacement of the step and λ are "position
  impulses" [kg m] — the equivalence of constraints on positions with projection.

Each update solves one contact's normal row for its target with the accumulated λ kept ≥ 0
(C2), then its friction rows with the accumulated tangential λ kept in the disk μ λ_n
(Coulomb, F2/F4a). The rows, their products with u and the impulses' effect on it are
:mod:`contactlab.methods.jacobian_rows`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import numpy as np
from numba import prange

from ..compiling import njit
from ..contacts import argsort_keys
from .jacobian_rows import ContactRows, apply_impulse, apply_impulses, contact_velocity, rows_in_order

if TYPE_CHECKING:
    from ..contacts import Contacts
    from ..state import State


@njit(cache=True)
def sweep_contacts(
    members: np.ndarray,
    count: int,
    target: np.ndarray,
    impulses: np.ndarray,
    rows: ContactRows,
    friction: np.ndarray,
    u: np.ndarray,
    gaps: tuple | None = None,
) -> float:
    """One Gauss-Seidel sweep (C7 on velocities) over contacts ``members[:count]`` in that order;
    returns the largest velocity change it made [m/s].

    Each contact c gets the normal impulse that brings v_n to ``target[c]`` [m/s] with the
    accumulated impulse kept ≥ 0 (C2), then Coulomb friction (F2, F4a): the accumulated
    tangential impulse that cancels the tangential velocity — taken after the normal impulse —
    kept in the disk μ λ_n; if it cannot stop the sliding the maximum applies, against the
    sliding. ``impulses`` (C, 3) [N s] and u change in place.

    The three row velocities are read in one pass over the contact's sides and the three
    impulses written back in one, as one impulse P: the same updates as row after row.

    ``gaps`` None: the targets are given. In a substep (``solve_in_substeps``), the substeps'
    gaps (``SubstepGaps``): each contact's target is first set from its gap now, in the same pass
    as its velocities rather than in one of its own (see ``SubstepGaps`` for the rule), and an
    overlapping contact of a soft step is a soft row: Δλ_n = −s k⁻¹ (v_n − target) − l λ_n, s and l
    the gaps' ``mass_scale`` and ``impulse_scale`` (1 and 0: the rigid update).
    """
    k = rows.k
    change = 0.0
    # a branch on a None argument: the whole-step sweep compiles none of the substeps' code. The
    # arrays are taken out of the tuple once, and the target is set here, not in a function of
    # its own: the arrays passed to one per contact are references counted each time (a
    # substep of the 1000-sphere pile 0.30 ms that way, 0.21 ms this way)
    if gaps is not None:
        start, fixed, travelled = gaps.start, gaps.fixed, gaps.travelled
    for m in range(count):
        c = members[m]
        if k[c, 0] <= 0.0:  # static against static: nothing can move
            continue
        stiffness, leak = 1.0, 0.0  # a rigid row: the whole correction, nothing of the old impulse let go
        if gaps is not None and not fixed[c]:  # the gap now, d₀ + h J_n ū
            gap = start[c] + gaps.dt * contact_velocity(c, rows, travelled)[0]
            if gap >= 0.0:
                target[c] = -gap / (gaps.dt / gaps.substeps)
            elif gaps.bias_rate <= 0.0:  # an overlap there at the step's start is pushed out at that overlap's speed
                target[c] = resting_target(start[c] if start[c] < 0.0 else gap, gaps)
            elif gaps.relax:  # a soft step's relaxing sweep: stop the approach, push nothing out
                target[c] = 0.0
            else:  # a soft contact: pushed out at bias_rate × the overlap, its row softened
                target[c] = min(-gaps.bias_rate * gap, gaps.max_push_velocity)
                stiffness, leak = gaps.mass_scale, gaps.impulse_scale
        vn, v1, v2 = contact_velocity(c, rows, u)
        old = impulses[c, 0]
        normal = max(0.0, old - stiffness * (vn - target[c]) * k[c, 5] - leak * old)
        impulses[c, 0] = normal
        dn = normal - old
        change = max(change, abs(dn) * k[c, 0])
        d1 = d2 = 0.0
        if friction[c] > 0.0:
            old1, old2 = impulses[c, 1], impulses[c, 2]
            new1 = old1 - (v1 + dn * k[c, 3]) * k[c, 6]
            new2 = old2 - (v2 + dn * k[c, 4]) * k[c, 7]
            squared = new1 * new1 + new2 * new2
            limit = friction[c] * normal
            if squared > limit * limit:  # sliding (compared squared: a sticking contact takes no root)
                scale = limit / np.sqrt(squared)
                new1 *= scale
                new2 *= scale
            d1, d2 = new1 - old1, new2 - old2
            impulses[c, 1], impulses[c, 2] = new1, new2
            change = max(change, abs(d1) * k[c, 1], abs(d2) * k[c, 2])
        apply_impulse(c, rows, dn, d1, d2, u)
    return change


@njit(cache=True)
def largest_row_change(rows: ContactRows, u: np.ndarray, before: np.ndarray, enough: float = np.inf) -> float:
    """max over contacts and their three rows of |J (u − before)| [m/s]: how much the
    generalized velocity's change from ``before`` to ``u`` (N,) moved any contact. Takes
    ``before`` as scratch: it is left holding u − before.

    Stops at the first contact whose change exceeds ``enough`` [m/s] and returns that change
    (then a lower bound of the max, itself > ``enough``): a sweep that is not the last needs
    only to know that it has not converged. The full pass costs ~9 µs a sweep on the 20-level
    pyramid's 1 600 contacts; stopping early took its six-sweep solve from 0.39 to 0.34 ms."""
    for i in range(u.shape[0]):
        before[i] = u[i] - before[i]
    change = 0.0
    for c in range(rows.k.shape[0]):
        dn, d1, d2 = contact_velocity(c, rows, before)
        change = max(change, abs(dn), abs(d1), abs(d2))
        if change > enough:
            break
    return change


@njit(cache=True, parallel=True)
def sweep_groups_in_parallel(
    members: np.ndarray,
    starts: np.ndarray,
    target: np.ndarray,
    impulses: np.ndarray,
    rows: ContactRows,
    friction: np.ndarray,
    u: np.ndarray,
    gaps: tuple | None,
) -> None:
    """One sweep of groups 0 … G−1 side by side (one thread each), then of the last group
    (``starts`` (G + 2,) from ``sweep_groups``; ``gaps`` as ``sweep_contacts`` takes them). Its
    largest single update is not returned: the solve stops on the sweep's net change
    (``largest_row_change``).

    The only parallel region of the sweeps: kept apart so that a serial solve never starts
    (or waits on) the thread pool — every array operation inside a ``parallel=True`` function
    becomes a parallel loop of its own."""
    groups = starts.shape[0] - 2
    for g in prange(groups):
        sweep_contacts(members[starts[g] :], starts[g + 1] - starts[g], target, impulses, rows, friction, u, gaps)
    sweep_contacts(
        members[starts[groups] :], members.shape[0] - starts[groups], target, impulses, rows, friction, u, gaps
    )


@njit(cache=True)
def sweep_until(
    rows: ContactRows,
    friction: np.ndarray,
    target: np.ndarray,
    impulses: np.ndarray,
    u: np.ndarray,
    until: tuple[int, float, bool, float],
    starts: np.ndarray | None,
    gaps: tuple | None,
) -> tuple[int, float]:
    """Sweeps over every contact in the order of ``rows`` (laid out in sweep order), ``until`` =
    (at most this many sweeps, the tolerance [m/s], exact, give_up [m/s]): until a whole sweep
    changes no contact's relative velocity by more than the tolerance, or the GIVE_UP_AT-th
    sweep's change exceeds ``give_up`` (``hopeless_change``; ∞: never); ``impulses`` (C, 3) [N s]
    and u change in place. ``starts`` as in ``solve_sequential_impulses`` (None: serial, the
    parallel sweep pruned); ``gaps`` as ``sweep_contacts`` takes them. Returns (sweeps made, the
    last sweep's largest velocity change [m/s]; with ``exact`` False, a sweep that reaches the
    cap looks only as far as the first contact that changed by more than the tolerance, and the
    change is then a lower bound; a solve given up returns a lower bound > ``give_up``)."""
    iterations, tolerance, exact, give_up = until
    C = friction.shape[0]
    groups = 1
    if starts is not None:  # None (one group): the parallel sweep is pruned, never compiled
        groups = starts.shape[0] - 2
    members = np.arange(C)
    before = np.empty_like(u)
    sweeps = 0
    change = 0.0
    for sweep in range(iterations):
        sweeps = sweep + 1
        for i in range(u.shape[0]):  # loops, not slice assignments: those compile an error message
            before[i] = u[i]
        if starts is None or groups == 1:
            sweep_contacts(members, C, target, impulses, rows, friction, u, gaps)
        else:
            sweep_groups_in_parallel(members, starts, target, impulses, rows, friction, u, gaps)
        # short of the cap, only whether some contact still moves by more than the tolerance
        # matters; the last sweep's change (returned) is exact either way: a sweep that stops
        # the solve passed every contact, and the cap's sweep takes them all
        enough = tolerance if sweeps < iterations or not exact else np.inf
        if sweeps == GIVE_UP_AT and give_up < np.inf:  # whether it is hopeless: look further
            enough = max(enough, give_up)
        change = largest_row_change(rows, u, before, enough)
        if change <= tolerance or (sweeps == GIVE_UP_AT and change > give_up):
            break
    return sweeps, change


# A whole-step solve that a substepped one would replace (``velocity_level.respond`` with
# substeps > 1) gives up at its GIVE_UP_AT-th sweep when its change is so far above the tolerance
# that even a change falling FASTEST_RATE-fold a sweep could not reach it within the cap. The
# 20-level pyramid's resting steps fall 0.27-0.5-fold a sweep, stand below 2e-7 m/s after 4
# sweeps and converge in 3-6; the jammed 1000-sphere pile's fall 0.3-0.5-fold at first, then
# 0.9-fold, and stand at 7e-3 to 6e-2 m/s after 4 sweeps, where this gives up at 1.5e-3
# (tolerance 1e-7, cap 12): 8 sweeps of 12 saved on every such step.
GIVE_UP_AT = 4
FASTEST_RATE = 0.3


@njit(cache=True, inline="always")
def hopeless_change(iterations: int, tolerance: float) -> float:
    """The change [m/s] above which a solve capped at ``iterations`` sweeps gives up at its
    GIVE_UP_AT-th: tolerance / FASTEST_RATE^(iterations − GIVE_UP_AT)."""
    return tolerance / FASTEST_RATE ** float(max(iterations - GIVE_UP_AT, 0))  # pow, as Python takes it


@njit(cache=True)
def solve_sequential_impulses(
    rows: ContactRows,
    friction: np.ndarray,
    target_normal_velocity: np.ndarray,
    u: np.ndarray,
    until: tuple[int, float],
    initial_impulses: np.ndarray,
    sequence: tuple,
    give_up: float = np.inf,
) -> tuple[np.ndarray, int, float]:
    """Contact impulses with accumulated clamping; changes the generalized velocity u in place (M2).

    ``rows`` as from ``contact_rows``. ``initial_impulses`` (C, 3) [N s] are applied first
    (warm starting: last step's impulses of the same contacts), then corrected like any
    accumulated impulse.

    For every contact c (in ``sequence`` = (order (C,) int, starts); repeatedly): the normal
    impulse that brings the normal relative velocity to ``target_normal_velocity[c]`` [m/s], with
    the accumulated impulse kept ≥ 0 (never attractive, C2), then friction with the accumulated
    tangential impulse kept in the disk μ λ_n (F2). ``order`` and ``starts`` (G + 2,) int come from
    ``sweep_groups``: groups 0 … G−1 of a sweep run side by side on G threads, then the last
    group (``sweep_groups_in_parallel``); ``starts`` None, or one group (G = 1), is the plain serial sweep in
    ``order``, which never touches the thread pool.

    ``until`` = (at most this many sweeps, the tolerance [m/s]): the sweeps stop once a whole
    sweep changes no contact's relative velocity (normal or tangential, J Δu over the sweep) by
    more than the tolerance. Not the largest single
    update: in a stack each box stands on several corners, infinitely many impulse splits
    among them give the same velocities, and Gauss-Seidel keeps trading impulse between
    corners at a steady rate (3e-6 m/s per update on the 20-level pyramid, for ever) while
    the velocities have long stopped changing. ``give_up`` [m/s]: a solve whose change after
    GIVE_UP_AT sweeps is above it stops there (``hopeless_change``; ∞, the default: never).
    Returns (impulses (C, 3) [N s] as (normal, t1, t2), sweeps made, that largest velocity change
    over the last sweep [m/s]).
    """
    order, starts = sequence
    C = friction.shape[0]
    impulses = initial_impulses.copy()
    apply_impulses(rows, impulses, u)
    # the rows laid out in sweep order: each sweep then reads memory front to back (twice as
    # fast on a 4000-sphere pile as jumping through it), with the very same updates
    rows_o = rows_in_order(rows, order)
    friction_o, target_o, impulses_o = friction[order], target_normal_velocity[order], impulses[order]
    # np.bool_, not the literal True: a literal would be a type of its own in the tuple
    whole = (until[0], until[1], np.bool_(True), float(give_up))
    sweeps, change = sweep_until(rows_o, friction_o, target_o, impulses_o, u, whole, starts, None)
    for i in range(C):
        for d in range(3):
            impulses[order[i], d] = impulses_o[i, d]
    return impulses, sweeps, change


@njit(cache=True, inline="always")
def resting_target(gap: float, settings: tuple) -> float:
    """The least normal relative velocity [m/s] a contact of gap ``gap`` [m] (> 0 open, < 0
    overlapping) may end a step of dt [s] with (C5b): −gap/dt while open (it may close, not
    overlap: a speculative contact), else a fraction ``stabilization`` of the overlap beyond
    ``slop`` [m] pushed out per step, never faster than ``max_push_velocity`` [m/s] — dt and these
    three of the ``settings`` (a LoopSettings, or the SubstepGaps a substep's ``sweep_contacts``
    reads, which hold them too) (``velocity_level.resting_targets`` and ``impact_targets``, and each substep of
    ``solve_in_substeps``)."""
    dt = settings.dt
    if gap >= 0.0:
        return -gap / dt
    return min(settings.stabilization * max(-gap - settings.slop, 0.0) / dt, settings.max_push_velocity)


@njit(cache=True)
def solve_in_substeps(
    rows: ContactRows,
    friction: np.ndarray,
    target_normal_velocity: np.ndarray,
    u: np.ndarray,
    substepping: tuple,
    settings: tuple,
    initial_impulses: np.ndarray,
    sequence: tuple,
) -> tuple[np.ndarray, int, float]:
    """``solve_sequential_impulses`` in n = ``settings.substeps`` small steps of h/n with the
    contacts detected once (small steps, Macklin et al. 2019; the substeps of Box2D v3's soft
    step and PhysX's TGS): u (N,) enters as the velocity at the step's start and each substep
    adds ``increment`` (N,) (the free motion's change over h/n: gravity), sweeps the contacts
    (at most ``settings.substep_sweeps`` sweeps to ``settings.tolerance``, warm-started from the
    substep before), and so moves each contact's gap by h/n times its normal velocity — the rows
    of J fixed at the step's start, the gaps to first order (the gap at the start plus J_n of the
    displacement so far), no detection in between. The targets come from the gaps, each set as
    the sweep reaches its contact (``sweep_contacts``): ``resting_target`` over h/n for an open
    contact, the stabilization's push for an overlap, or with ``settings.contact_hertz`` > 0 a soft
    contact's, each substep's sweeps then followed by a relaxing sweep (``SubstepGaps``; Box2D
    v3's soft step). ``substepping`` = (fixed (C,) bool: a
    contact that keeps its ``target_normal_velocity`` (a bounce); the gaps (C,) [m] at the step's
    start; ``increment``; ``travelled`` (N,), which receives the mean of the substeps' velocities,
    with which the positions move: x = x₀ + h ū, each substep a symplectic Euler step).
    ``settings`` a LoopSettings; ``initial_impulses`` (C, 3) [N s] over the whole step (the
    warm start, a 1/n share of it starting the first substep); ``sequence`` as in
    ``solve_sequential_impulses``. u leaves as the velocity at the step's end. Returns (impulses (C, 3) [N s]
    summed over the substeps, sweeps made over all substeps, the last sweep's largest velocity
    change [m/s]).

    A substep starts from the last one's impulses: their effect on u, M⁻¹ Jᵀ λ (``applied``),
    is carried as a vector and updated by what each substep's sweeps changed, not applied anew
    contact by contact (a pass over the rows each substep). Only the last substep's last
    sweep measures its change exactly; the others stop looking at the first contact that moved
    by more than the tolerance (``sweep_until``'s ``exact``)."""
    fixed, gap, increment, travelled = substepping
    order, starts = sequence
    C = friction.shape[0]
    N = u.shape[0]
    n = settings.substeps
    rows_o = rows_in_order(rows, order)
    friction_o, target_o, gap_o = friction[order], target_normal_velocity[order], gap[order]
    share = initial_impulses[order] / n  # a substep's impulses: the step's over n
    applied = np.zeros(N)  # M⁻¹ Jᵀ share
    apply_impulses(rows_o, share, applied)
    total = np.zeros((C, 3))
    before = np.empty(N)
    for i in range(N):
        travelled[i] = 0.0
    pushing = (settings.dt, settings.substeps, settings.stabilization, settings.slop, settings.max_push_velocity)
    soft = soft_contact(settings.contact_hertz, settings.dt / n)
    fixed_o = fixed[order]
    gaps = SubstepGaps(gap_o, fixed_o, travelled, *pushing, *soft, False)
    # the relaxing sweep reads the gaps at the substep's start, as its sweep did: the velocity it
    # settles is the one the substep moved with (from the gaps after it, it held the last
    # substep's velocity to the next step's speculative gap, and a falling ball lost its bounce)
    before_moving = np.zeros(N)
    relaxing = SubstepGaps(gap_o, fixed_o, before_moving, *pushing, *soft, True)
    sweeps, change = 0, 0.0
    for substep in range(n):
        for i in range(N):
            u[i] += increment[i] + applied[i]
            before[i] = u[i]
        last = substep == n - 1
        until = (settings.substep_sweeps, settings.tolerance, last and soft[0] <= 0.0, np.inf)
        made, change = sweep_until(rows_o, friction_o, target_o, share, u, until, starts, gaps)
        sweeps += made
        if soft[0] > 0.0:
            for i in range(N):
                before_moving[i] = travelled[i]
        for i in range(N):
            travelled[i] += u[i] / n
        if soft[0] > 0.0:  # the soft step's relaxing sweep, after the positions moved
            until = (settings.substep_sweeps, settings.tolerance, last, np.inf)
            made, change = sweep_until(rows_o, friction_o, target_o, share, u, until, starts, relaxing)
            sweeps += made
        for i in range(N):
            applied[i] += u[i] - before[i]
        for c in range(C):
            for d in range(3):
                total[c, d] += share[c, d]
    impulses = np.empty((C, 3))
    for i in range(C):
        for d in range(3):
            impulses[order[i], d] = total[i, d]
    return impulses, sweeps, change


SOFT_DAMPING_RATIO = 10.0  # ζ of a soft contact: Box2D v3's contact damping ratio, heavily overdamped


@njit(cache=True)
def soft_contact(hertz: float, h: float) -> tuple[float, float, float]:
    """A soft contact's (bias rate [1/s], mass scale, impulse scale) for a substep of h [s]: a
    damped spring of frequency ``hertz`` [Hz] (at most a quarter of the substep rate, 1/4h) and
    damping ratio SOFT_DAMPING_RATIO, solved implicitly (Box2D v3's soft step, after Catto's
    "Soft constraints"): with ω = 2π f, a₁ = 2ζ + hω, a₂ = hω a₁, a₃ = 1/(1 + a₂), the bias rate
    ω/a₁, the mass scale a₂ a₃, the impulse scale a₃. ``hertz`` 0: (0, 1, 0), a rigid row."""
    if hertz <= 0.0:
        return 0.0, 1.0, 0.0
    omega = 2.0 * np.pi * min(hertz, 0.25 / h)
    a1 = 2.0 * SOFT_DAMPING_RATIO + h * omega
    a2 = h * omega * a1
    a3 = 1.0 / (1.0 + a2)
    return omega / a1, a2 * a3, a3


class SubstepGaps(NamedTuple):
    """What a substep's sweep (``sweep_contacts`` in ``solve_in_substeps``) sets each contact's
    target from, every array in the sweep order, before it updates the contact.

    The rule, for a substep of hs = h/n [s]: the contact's gap now is d = d₀ + h J_n ū (d₀ its
    gap at the step's start, h ū the displacement of the substeps done, J fixed over the step).
    An open contact (d ≥ 0) may close it, not overlap: target −d/hs. An overlap is pushed out at
    the stabilization's per-step speed (``resting_target``), that of the overlap at the step's
    start where there was one then. A ``fixed`` contact keeps its target.

    Not a target that heads for the gap the whole step's target leaves, (d₀ + h v − d)/(time
    left): that made up within the step what a substep's one sweep left undone (the 1000-sphere
    pile's deepest overlap fell from 0.96 to 0.68 mm at 8 substeps), but it holds every corner
    of a resting box at its starting gap, and the 20-level pyramid, substepped every step, slid
    apart (51 mm, 97 boxes > 1 mm in 5 s, against 0.03 mm).

    Soft contacts (``bias_rate`` > 0, Box2D v3's soft step): an overlap is a damped spring of
    ``soft_contact``'s stiffness instead, pushed out at −bias_rate d as the sweep finds it, its
    row softened (``sweep_contacts``); after each substep's sweeps a relaxing sweep (``relax``)
    takes the push out of the velocities, so that it moves the bodies apart without launching
    them. An open contact is rigid either way."""

    start: np.ndarray  # (C,) [m] each contact's gap at the step's start (> 0 open, < 0 overlapping)
    fixed: np.ndarray  # (C,) bool: the contact keeps the target it came with (a bounce)
    travelled: np.ndarray  # (N,) the generalized velocities' sum over the substeps done, over n
    # the run's LoopSettings' own (a flat tuple: a parallel sweep cannot take a tuple within one)
    dt: float  # the whole step h [s]
    substeps: int  # n
    stabilization: float  # resting_target's three
    slop: float
    max_push_velocity: float
    # soft contacts (``soft_contact``; bias_rate 0: rigid, the rule above)
    bias_rate: float  # [1/s] an overlap d < 0 is pushed out at −bias_rate d (at most max_push_velocity)
    mass_scale: float  # the share of a rigid row's correction a soft row makes
    impulse_scale: float  # the share of its accumulated impulse a soft row lets go each update
    relax: bool  # a relaxing sweep: overlaps are held (target 0), rigid


# A parallel sweep needs enough contacts to pay for its fork and join (~1 µs each on idle
# cores): below this count every sweep runs as one group. From it on the contacts are split
# into SWEEP_GROUPS groups, whatever the machine, so that a run gives the same numbers on one
# core as on many (the groups are swept on as many threads as there are, up to SWEEP_GROUPS).
PARALLEL_MIN_CONTACTS = 1000
SWEEP_GROUPS = 2


@njit(cache=True)
def split_into_slabs(
    order: np.ndarray, point: np.ndarray, rows: ContactRows, positions: tuple, slabs: int
) -> tuple[np.ndarray, np.ndarray]:
    """``sweep_groups``' work on the packed sides of ``rows``, the contacts at ``point`` (C, 3) [m],
    the bodies and particles at ``positions`` = ((B, 3), (P, 3)) [m]: (order (C,), starts (slabs + 2,))."""
    body, particle = rows.body, rows.particle
    body_inverse_mass, particle_inverse_mass = rows.body_inverse_mass, rows.particle_inverse_mass
    body_position, particle_position = positions
    C = order.shape[0]
    axis, extent = 0, -1.0  # the axis along which the contacts spread most
    for a in range(3):
        spread = point[:, a].max() - point[:, a].min()
        if spread > extent:
            axis, extent = a, spread
    along = np.sort(point[:, axis])
    cuts = np.empty(slabs - 1)  # slab boundaries at the contacts' quantiles
    for i in range(slabs - 1):
        cuts[i] = along[(i + 1) * C // slabs]
    group = np.empty(C, dtype=np.int64)
    for c in range(C):
        g = -1  # the slab that owns every movable entity of c
        for side in range(2):
            b = body[c, side]
            if b >= 0 and body_inverse_mass[b] > 0.0:
                g = _joined(g, np.searchsorted(cuts, body_position[b, axis], side="right"))
            for m in range(3):
                p = particle[c, side, m]
                if p < 0:  # packed: no more particles on this side
                    break
                if particle_inverse_mass[p] > 0.0:
                    g = _joined(g, np.searchsorted(cuts, particle_position[p, axis], side="right"))
        group[c] = slabs if g < 0 else g  # spanning two slabs (or touching nothing movable): last
    return stable_buckets(order, group, slabs + 1)  # stable: each group keeps the order it had


@njit(cache=True)
def stable_buckets(items: np.ndarray, key: np.ndarray, buckets: int) -> tuple[np.ndarray, np.ndarray]:
    """``items`` (n,) int sorted by ``key[item]`` (an int in 0 … buckets − 1), stable (a counting
    sort): (the sorted items (n,), starts (buckets + 1,)), bucket b ``sorted[starts[b]:starts[b + 1]]``.
    The slabs' groups (``split_into_slabs``), shock propagation's levels, the manifolds' blocks."""
    count = np.zeros(buckets + 1, dtype=np.int64)
    for i in range(items.shape[0]):
        count[key[items[i]] + 1] += 1
    starts = np.cumsum(count)
    fill = starts[:-1].copy()
    out = np.empty_like(items)
    for i in range(items.shape[0]):
        b = key[items[i]]
        out[fill[b]] = items[i]
        fill[b] += 1
    return out, starts


@njit(cache=True, inline="always")
def _joined(g, slab):
    """The common slab of a contact so far (−1: none yet) and one more entity's slab; −2 when they differ."""
    if g == -1 or g == slab:
        return slab
    return -2


def sweep_groups(
    rows: ContactRows,
    contacts: Contacts,
    state: State,
    order: np.ndarray,
    groups: int = SWEEP_GROUPS,
    min_contacts: int = PARALLEL_MIN_CONTACTS,
) -> tuple[np.ndarray, np.ndarray | None]:
    """Group the contacts so that a Gauss-Seidel sweep can run on several threads (C8) and still
    be one serial sweep: returns (order (C,) int, starts (G + 2,) int, or None for one group —
    so that ``solve_sequential_impulses`` compiles no parallel sweep for a scene that never
    needs one, 2–3 s of a cold start). ``rows`` from ``contact_rows`` of ``contacts``; ``state``
    holds the positions the bodies and particles are sorted into slabs by.

    Space is cut across the axis along which the contacts spread most into G = ``groups``
    slabs of equal contact count (G = 1 below ``min_contacts`` contacts). A contact all of
    whose movable bodies and particles lie in slab g joins group g (order[starts[g]:starts[g+1]]);
    the rest — contacts that span two slabs — form the last group, swept after the others.
    Two contacts of different slabs share nothing that moves (static sides and pinned
    particles are never written), so the groups can be swept at once, each in ``order`` (its
    load path kept top to bottom), and the result is, bit for bit, the serial sweep in the
    returned order, on any number of threads.
    """
    C = len(order)
    if groups < 2 or C < min_contacts:
        return np.asarray(order), None
    return split_into_slabs(
        np.asarray(order), contacts.point, rows, (state.body_position, state.particle_position), groups
    )


def solve_order(contacts: Contacts, gravity: np.ndarray) -> np.ndarray:
    """The order of the Gauss-Seidel sweeps (C,) int: highest contact point first along −g.

    In a stack the top contact is solved first, and the impulse it puts on the body below is
    passed on, contact by contact, down to the ground within the same sweep: the load path is
    followed in one sweep instead of creeping one link per sweep. This is what keeps a heavy
    body on a light one (mass ratio 100) from sinking with a modest iteration count.

    Contacts at one height (the four corners of a face; heights equal to 1 nm) are taken in
    an order scrambled by contact id — fixed from step to step, but not the collision order,
    in which every face's corners come in the same pattern: a sweep cut short by its iteration
    cap leaves each first-visited corner a little more impulse, and with the same pattern on
    every level a 20-level pyramid leaned 0.55 mm sideways (1.04 mm at the top; 0.65 mm with
    the scrambled order). Without gravity the order is that of the collision detection.
    """
    return contact_order(
        np.ascontiguousarray(contacts.point, dtype=float), contacts.feature_id, np.asarray(gravity, dtype=float)
    )


@njit(cache=True)
def contact_order(point: np.ndarray, feature_id: np.ndarray, gravity: np.ndarray) -> np.ndarray:
    """``solve_order``, compiled: point (C, 3) [m], feature_id (C,) int64, gravity (3,) [m/s²]."""
    C = point.shape[0]
    g = np.sqrt(gravity[0] * gravity[0] + gravity[1] * gravity[1] + gravity[2] * gravity[2])
    if g == 0.0:
        return np.arange(C)
    height = np.empty(C)  # along −g, to the nanometre
    scramble = np.empty(C, dtype=np.int64)
    down = np.empty(C)  # −height, whose bits become the sort keys
    for c in range(C):
        height[c] = np.round(-(point[c, 0] * gravity[0] + point[c, 1] * gravity[1] + point[c, 2] * gravity[2]) / g, 9)
        scramble[c] = np.int64((np.uint64(feature_id[c]) * np.uint64(2654435761)) % np.uint64(4294967291))
        down[c] = -height[c]
    # sort int64 keys, not the floats: the bits of −height with the negatives' magnitude bits
    # flipped order as the floats do (−0 just before +0; any finite height), so the sort is the
    # one the warm-start matching (contacts.values_carried) compiles anyway, not a second one
    # for floats (a cold start compiles one sort, not two); the ties are ordered by
    # _order_ties whatever the sort left them in, so the order is the one np.argsort gave
    keys = down.view(np.int64)
    for c in range(C):
        if keys[c] < 0:
            keys[c] ^= np.int64(0x7FFFFFFFFFFFFFFF)
    return _order_ties(argsort_keys(keys), height, scramble)


@njit(cache=True)
def _order_ties(order, height, scramble):
    """``order`` (C,) int, sorted by height, with each run of equal heights (a few face corners,
    or one level of a pyramid) put in order of ``scramble``, then of index, by insertion: in
    all, np.lexsort((scramble, −height)) — the very same order — in a third of its time
    (0.32 → 0.1 ms on 3 300 contacts: one NumPy sort of one key, then a linear pass)."""
    start = 0
    C = order.shape[0]
    while start < C:
        stop = start + 1
        while stop < C and height[order[stop]] == height[order[start]]:
            stop += 1
        for a in range(start + 1, stop):
            c = order[a]
            b = a
            while b > start and (
                scramble[order[b - 1]] > scramble[c] or (scramble[order[b - 1]] == scramble[c] and order[b - 1] > c)
            ):
                order[b] = order[b - 1]
                b -= 1
            order[b] = c
        start = stop
    return order
