"""Projected Gauss-Seidel over contact rows, matrix-free (SPEC C7, F2, F4a on velocities or
displacements).

Every contact is three rows of the Jacobian J (normal, tangent1, tangent2) over one generalized
vector u in the DOF layout of contactlab.contacts. The same sweeps serve two methods:

* impulses (M2): u is the generalized velocity and the accumulated λ are impulses [N s];
* projection (M3): u is the generalized displacement of the step and λ are "position
  impulses" [kg m] — the equivalence of constraints on positions with projection.

Each update solves one contact's normal row for its target with the accumulated λ kept ≥ 0
(C2), then its friction rows with the accumulated tangential λ kept in the disk μ λ_n
(Coulomb, F2/F4a).
"""

import numpy as np
from numba import njit

# ---- the compiled solver: every contact as three rows of J over the generalized velocity ----
#
# The generalized velocity u (6B + 3P,) is the DOF layout of contactlab.contacts: body i owns
# u[6i:6i+3] (linear, m/s) and u[6i+3:6i+6] (world angular, rad/s), particle j owns
# u[6B+3j:6B+3j+3]. A contact touches at most ROW_WIDTH entries of u (6 per rigid-body side,
# 3 per particle of a side). For each contact c and direction d (0: normal, 1: tangent1,
# 2: tangent2) ``jac[c, d]`` holds that row of J (v_n = Σ jac · u[index]) and ``push[c, d]``
# the matching column of M⁻¹ Jᵀ (an impulse λ changes u[index] by λ · push), so that
# k[c, d] = jac · push = dᵀ J M⁻¹ Jᵀ d is the effective inverse mass of R4; k[c, 3] and
# k[c, 4] are jac[c, 1] · push[c, 0] and jac[c, 2] · push[c, 0], how much a normal impulse
# changes the tangential velocities. Precomputing the rows once per step keeps a contact's
# Gauss-Seidel update to one pass over its entries of u (the three row velocities together)
# and one pass back (the three impulses together).

ROW_WIDTH = 18


@njit(cache=True)
def contact_rows(body_a, body_b, particles_a, particles_b, weights_a, weights_b, r_a, r_b,
                 normal, tangent1, tangent2, body_inverse_mass, body_inverse_inertia_world,
                 particle_inverse_mass):
    """The contacts' Jacobian rows over the generalized velocity (see above).

    Shapes: C contacts; r_a, r_b (C, 3) lever arms [m]; body_inverse_inertia_world (B, 3, 3).
    Returns index (C, ROW_WIDTH) int (entries of u), width (C,) int (how many are used),
    jac (C, 3, ROW_WIDTH) [1 or m], push (C, 3, ROW_WIDTH) [1/kg or 1/(kg m)] and
    k (C, 5) [1/kg]: the effective inverse mass of each row, then the normal row's coupling
    into the two tangent rows (see above).
    """
    C = normal.shape[0]
    B = body_inverse_mass.shape[0]
    index = np.zeros((C, ROW_WIDTH), dtype=np.int64)
    width = np.zeros(C, dtype=np.int64)
    jac = np.zeros((C, 3, ROW_WIDTH))
    push = np.zeros((C, 3, ROW_WIDTH))
    k = np.zeros((C, 5))
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
        for d in range(5):
            row, column = (d, d) if d < 3 else (d - 2, 0)
            total = 0.0
            for e in range(n):
                total += jac[c, row, e] * push[c, column, e]
            k[c, d] = total
    return index, width, jac, push, k


@njit(cache=True, inline="always")
def _row_velocity(c, d, index, width, jac, u):
    """Row d of contact c applied to u: dᵀ(v_A − v_B) at the contact [m/s]."""
    total = 0.0
    for e in range(width[c]):
        total += jac[c, d, e] * u[index[c, e]]
    return total


@njit(cache=True)
def sweep_contacts(members, count, target, impulses, index, width, jac, push, k, friction, u):
    """One Gauss-Seidel sweep (C7 on velocities) over contacts ``members[:count]`` in that order;
    returns the largest velocity change it made [m/s].

    Each contact c gets the normal impulse that brings v_n to ``target[c]`` [m/s] with the
    accumulated impulse kept ≥ 0 (C2), then Coulomb friction (F2, F4a): the accumulated
    tangential impulse that cancels the tangential velocity — taken after the normal impulse —
    kept in the disk μ λ_n; if it cannot stop the sliding the maximum applies, against the
    sliding. ``impulses`` (C, 3) [N s] and u change in place.

    The three row velocities are read in one pass over the contact's entries of u and the
    three impulses written back in one: the same updates as row after row. (Written as one
    loop on purpose: the same update as a separate inlined function ran 2.3× slower.)
    """
    change = 0.0
    for m in range(count):
        c = members[m]
        if k[c, 0] <= 0.0:                  # static against static: nothing can move
            continue
        vn = v1 = v2 = 0.0
        for e in range(width[c]):
            value = u[index[c, e]]
            vn += jac[c, 0, e] * value
            v1 += jac[c, 1, e] * value
            v2 += jac[c, 2, e] * value
        old = impulses[c, 0]
        normal = max(0.0, old - (vn - target[c]) / k[c, 0])
        impulses[c, 0] = normal
        dn = normal - old
        change = max(change, abs(dn) * k[c, 0])
        d1 = d2 = 0.0
        if friction[c] > 0.0:
            old1, old2 = impulses[c, 1], impulses[c, 2]
            new1 = old1 - (v1 + dn * k[c, 3]) / k[c, 1]
            new2 = old2 - (v2 + dn * k[c, 4]) / k[c, 2]
            magnitude = np.sqrt(new1 * new1 + new2 * new2)
            limit = friction[c] * normal
            if magnitude > limit:
                scale = limit / magnitude
                new1 *= scale
                new2 *= scale
            d1, d2 = new1 - old1, new2 - old2
            impulses[c, 1], impulses[c, 2] = new1, new2
            change = max(change, abs(d1) * k[c, 1], abs(d2) * k[c, 2])
        for e in range(width[c]):
            u[index[c, e]] += dn * push[c, 0, e] + d1 * push[c, 1, e] + d2 * push[c, 2, e]
    return change


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
        for e in range(width[c]):
            u[index[c, e]] += (impulses[c, 0] * push[c, 0, e] + impulses[c, 1] * push[c, 1, e]
                               + impulses[c, 2] * push[c, 2, e])
    # the rows laid out in sweep order: each sweep then reads memory front to back (twice as
    # fast on a 4000-sphere pile as jumping through it), with the very same updates
    index_o, width_o, jac_o, push_o = index[order], width[order], jac[order], push[order]
    k_o, friction_o, target_o, impulses_o = k[order], friction[order], target_normal_velocity[order], impulses[order]
    members = np.arange(C)
    sweeps = 0
    change = 0.0
    for sweep in range(iterations):
        sweeps = sweep + 1
        change = sweep_contacts(members, C, target_o, impulses_o, index_o, width_o, jac_o, push_o, k_o,
                                friction_o, u)
        if change <= tolerance:
            break
    impulses[order] = impulses_o
    return impulses, sweeps, change


def rows_of(model, contacts, body_position, body_orientation):
    """``contact_rows`` of a Contacts at the given body positions (B, 3) and orientations (B, 4)
    (the state the contacts were detected at): index, width, jac, push, k."""
    from ..dynamics.integrators import world_inverse_inertia
    r_a, r_b = lever_arms(contacts, body_position)
    return contact_rows(contacts.body_a, contacts.body_b, contacts.particles_a, contacts.particles_b,
                        contacts.weights_a, contacts.weights_b, r_a, r_b, contacts.normal, contacts.tangent1,
                        contacts.tangent2, model.body_inverse_mass, world_inverse_inertia(model, body_orientation),
                        model.particle_inverse_mass)


def lever_arms(contacts, body_position):
    """r = point − centre of mass for each side, (C, 3) each; zero for non-body sides."""
    def arm(body):
        r = np.zeros((contacts.count, 3))
        has = body >= 0
        r[has] = contacts.point[has] - body_position[body[has]]
        return r
    return arm(contacts.body_a), arm(contacts.body_b)


def solve_order(contacts, gravity):
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
    gravity = np.asarray(gravity, dtype=float)
    if not np.any(gravity):
        return np.arange(contacts.count)
    height = np.round(contacts.point @ -gravity / np.linalg.norm(gravity), 9)
    scramble = (contacts.feature_id.astype(np.uint64) * np.uint64(2654435761)) % np.uint64(4294967291)
    return np.lexsort((scramble, -height))


@njit(cache=True)
def row_products(index, width, jac, u):
    """J u per contact (C, 3): each contact's normal and tangent rows applied to u."""
    C = width.shape[0]
    out = np.zeros((C, 3))
    for c in range(C):
        for d in range(3):
            out[c, d] = _row_velocity(c, d, index, width, jac, u)
    return out
