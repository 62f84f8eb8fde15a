"""Shock propagation on velocities (Guendelman, Bridson and Fedkiw 2003, *Nonconvex rigid bodies
with stacking*, section 7): after a step's sweeps, one more pass over the contacts, level by
level from the ground up, each level's contacts swept with everything below that level held
fixed (its inverse mass taken as 0).

Why: a pile's weight must travel from the top to the ground and the reaction back up, and a
jammed pile's sweeps close on that answer by a few per cent a sweep (issue 38's traces), so a
solve cut short leaves the lower bodies sinking into what they rest on. In this pass a level
cannot push the one below it down: the contacts of level 1 bring the bodies resting on the
ground to their targets against the fixed ground, those of level 2 bring theirs to their targets
against level 1 as it now moves, and so on up, so that a pass leaves no contact of the load path
approaching faster than its target. What it gives up: the pass's impulses act on the upper side
only, with no reaction below, so the pass conserves no momentum; a stack's lower bodies carry the
weight the sweeps before gave them, not more. Its impulses are not carried to the next step
(``respond`` carries the sweeps' answer): they balance no load.

The levels (``entity_levels``): a body or particle in contact with something that cannot move
(the ground, an obstacle, a kinematic body or a pinned particle) is level 1, one in contact
with a level-1 one level 2, and so on: breadth-first over the contact graph. A contact's level is
the larger of its sides'. Level L's contacts are swept with the bodies and particles of levels
below L held; those that reach nothing fixed through the graph (a pile in free fall) come last,
with every levelled one held.
"""

from __future__ import annotations

import numpy as np

from ..compiling import njit
from .jacobian_rows import ContactRows, effective_masses
from .sequential import stable_buckets, sweep_contacts

UNREACHED = 1 << 40  # the level of what reaches nothing fixed through the contacts (below any int64 + 1)


@njit(cache=True)
def propagate_shock(
    rows: ContactRows,
    friction: np.ndarray,
    target: np.ndarray,
    impulses: np.ndarray,
    u: np.ndarray,
    order: np.ndarray,
    until: tuple[int, float],
) -> int:
    """The shock-propagation pass on the generalized velocity u (N,), changed in place: the
    contacts of ``rows`` level by level from the ground up (``entity_levels``), each level swept
    (``sequential.sweep_contacts``: targets ``target`` (C,) [m/s], Coulomb friction μ
    ``friction`` (C,)) at most ``until[0]`` times, until a sweep changes no contact's velocity by
    more than ``until[1]`` [m/s], with every body and particle of a lower level held fixed. The
    accumulated impulses start from ``impulses`` (C, 3) [N s] (the sweeps' answer: left as it is).
    ``order`` (C,) is the sweeps' order, highest contact first (``sequential.solve_order``): each
    level is taken in its reverse, bottom up. Returns the updates made, in whole sweeps of all
    contacts (rounded up)."""
    sweeps, tolerance = until
    C = friction.shape[0]
    level, entities, movable = entity_levels(rows)
    B = rows.body_inverse_mass.shape[0]
    contact_level = np.zeros(C, dtype=np.int64)
    top = 0  # the highest level reached
    for c in range(C):
        for s in range(2):
            for i in range(movable[c, s]):
                contact_level[c] = max(contact_level[c], level[entities[c, s, i]])
        if contact_level[c] < UNREACHED:
            top = max(top, contact_level[c])
    for c in range(C):  # what reaches nothing fixed: one level above the rest
        contact_level[c] = min(contact_level[c], top + 1)
    members, starts = stable_buckets(order[::-1].copy(), contact_level, top + 2)
    held = stable_buckets(np.arange(level.shape[0]), np.minimum(level, top + 1), top + 2)[0]
    # the pass's own masses (the bodies below held) and effective masses; the rows' sides as they are
    inverse_mass, inverse_inertia = rows.body_inverse_mass.copy(), rows.inverse_inertia.copy()
    particle_inverse_mass = rows.particle_inverse_mass.copy()
    k = rows.k.copy()
    fixed = ContactRows(
        rows.body,
        rows.particle,
        rows.weight,
        rows.arm,
        rows.frame,
        k,
        inverse_mass,
        inverse_inertia,
        particle_inverse_mass,
    )
    accumulated = impulses.copy()
    sides = (rows.body, rows.particle, rows.weight, rows.arm)
    masses = (inverse_mass, inverse_inertia, particle_inverse_mass)
    frozen = 0
    updates = 0
    for L in range(1, top + 2):
        while frozen < held.shape[0] and level[held[frozen]] < L:  # hold every entity below level L
            e = held[frozen]
            if e < B:
                inverse_mass[e] = 0.0
                for i in range(3):
                    for j in range(3):
                        inverse_inertia[e, i, j] = 0.0
            else:
                particle_inverse_mass[e - B] = 0.0
            frozen += 1
        count = starts[L + 1] - starts[L]
        if count == 0:
            continue
        group = members[starts[L] :]
        for i in range(count):
            effective_masses(group[i], rows.frame, sides, masses, k)
        for _sweep in range(sweeps):
            updates += count
            if sweep_contacts(group, count, target, accumulated, fixed, friction, u) <= tolerance:
                break
    return (updates + C - 1) // C


@njit(cache=True)
def entity_levels(rows: ContactRows) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each body's and particle's level: 0 for what cannot move, 1 + the least level of what it
    touches for the rest, UNREACHED where no chain of contacts leads to anything fixed —
    breadth-first over the contacts of ``rows`` from everything that touches a fixed side.

    Returns (level (B + P,) int, bodies first, then particles; each contact's movable entities
    (C, 2, 4) int per side — a body's index, B + a particle's —; how many (C, 2))."""
    body, particle = rows.body, rows.particle
    inverse_mass, particle_inverse_mass = rows.body_inverse_mass, rows.particle_inverse_mass
    B, P, C = inverse_mass.shape[0], particle_inverse_mass.shape[0], body.shape[0]
    entities = np.empty((C, 2, 4), dtype=np.int64)
    count = np.zeros((C, 2), dtype=np.int64)
    touching = np.zeros(B + P + 1, dtype=np.int64)  # contacts per entity, then their starts
    for c in range(C):
        for s in range(2):
            n = 0
            b = body[c, s]
            if b >= 0 and inverse_mass[b] > 0.0:
                entities[c, s, n] = b
                n += 1
            for m in range(3):
                p = particle[c, s, m]
                if p < 0:  # packed: no more particles on this side
                    break
                if particle_inverse_mass[p] > 0.0:
                    entities[c, s, n] = B + p
                    n += 1
            count[c, s] = n
            for i in range(n):
                touching[entities[c, s, i] + 1] += 1
    for e in range(B + P):
        touching[e + 1] += touching[e]
    fill = touching[:-1].copy()
    contacts_of = np.empty(touching[B + P], dtype=np.int64)
    level = np.full(B + P, UNREACHED, dtype=np.int64)
    queue = np.empty(B + P, dtype=np.int64)
    queued = 0
    for c in range(C):
        for s in range(2):
            for i in range(count[c, s]):
                e = entities[c, s, i]
                contacts_of[fill[e]] = c
                fill[e] += 1
                if count[c, 1 - s] == 0 and level[e] == UNREACHED:  # against something fixed
                    level[e] = 1
                    queue[queued] = e
                    queued += 1
    head = 0
    while head < queued:  # breadth first: each entity queued once, at its least level
        e = queue[head]
        head += 1
        for j in range(touching[e], touching[e + 1]):
            c = contacts_of[j]
            for s in range(2):
                for i in range(count[c, s]):
                    f = entities[c, s, i]
                    if level[f] == UNREACHED:
                        level[f] = level[e] + 1
                        queue[queued] = f
                        queued += 1
    return level, entities, count
