"""Every contact as three rows of the Jacobian J over the generalized velocity, matrix-free.

The rows serve every method that solves or applies contact impulses: the Gauss-Seidel sweeps
of :mod:`contactlab.methods.sequential` (impulses and projection), the constraints method,
and the penalty springs. The layout:

The generalized velocity u (6B + 3P,) is the DOF layout of contactlab.contacts: body i owns
u[6i:6i+3] (linear, m/s) and u[6i+3:6i+6] (world angular, rad/s), particle j owns
u[6B+3j:6B+3j+3]. Row d of a contact's J (d = 0 normal n, 1 tangent t1, 2 tangent t2) gives
dᵀ(v_A − v_B) at the contact point, where side A (sign +1) and side B (sign −1) each move as
a rigid body (v + ω × r, r the lever arm) or as a weighted sum of up to three particles
(Σ w v_p: a vertex, an edge or triangle point). An impulse P = λ_n n + λ_1 t1 + λ_2 t2 [N s]
changes a body side by ±(P / m, I⁻¹ (r × P)) and a particle by ±w P / m_p: this is
M⁻¹ Jᵀ λ without forming J.

The rows are kept in that compact form, a ``ContactRows``: body (C, 2) int, particle (C, 2, 3)
int, weight (C, 2, 3), arm (C, 2, 3) [m], frame (C, 3, 3) (rows n, t1, t2), k (C, 8) [1/kg; kg],
body_inverse_mass (B,) [1/kg], inverse_inertia (B, 3, 3) world [1/(kg m²)],
particle_inverse_mass (P,) [1/kg]; −1 marks "no body" or "no particle". k[c, d] =
dᵀ J M⁻¹ Jᵀ d is the effective inverse mass of row d (R4's denominator); k[c, 3] and
k[c, 4] are t1ᵀ J M⁻¹ Jᵀ n and t2ᵀ J M⁻¹ Jᵀ n, how much a normal impulse changes the
tangential velocities; k[c, 5:8] are 1 / k[c, 0:3] (0 where nothing can move), so that an
update multiplies instead of dividing. A Gauss-Seidel update reads a contact's ~40 numbers
and the few bodies it touches: about 300 bytes per contact, a third of what storing the rows
as dense lines of J and M⁻¹ Jᵀ took. It is bound more by its chain of dependent arithmetic
than by memory: 45 ns per update on the 1000-sphere pile, against 54 ns before.
"""

from __future__ import annotations

from collections import namedtuple
from typing import TYPE_CHECKING, Any

import numpy as np

from ..compiling import njit

if TYPE_CHECKING:
    from ..contacts import Contacts
    from ..model import Model


ContactRows = namedtuple(
    "ContactRows",
    (
        "body",
        "particle",
        "weight",
        "arm",
        "frame",
        "k",
        "body_inverse_mass",
        "inverse_inertia",
        "particle_inverse_mass",
    ),
)
ContactRows.__doc__ = """The contacts' rows of J in the compact form above (a named tuple: compiled code takes it)."""


@njit(cache=True)
def contact_rows(sides: tuple, geometry: tuple, body_position: np.ndarray, masses: tuple) -> ContactRows:
    """The contacts' rows in the compact form above, a ``ContactRows``.

    C contacts: ``sides`` = (body_a, body_b (C,) int; particles_a, particles_b (C, 3) int;
    weights_a, weights_b (C, 3)), ``geometry`` = (point, normal, tangent1, tangent2) (C, 3) [m, 1],
    as a Contacts' fields; body_position (B, 3) [m] (the lever arm is point − centre of mass);
    ``masses`` = (the bodies' inverse masses (B,) [1/kg], their world inverse inertias (B, 3, 3)
    [1/(kg m²)], the particles' inverse masses (P,) [1/kg]).
    """
    body_a, body_b, particles_a, particles_b, weights_a, weights_b = sides
    point, normal, tangent1, tangent2 = geometry
    C = normal.shape[0]
    body = np.empty((C, 2), dtype=np.int64)
    particle = np.empty((C, 2, 3), dtype=np.int64)
    weight = np.zeros((C, 2, 3))
    arm = np.zeros((C, 2, 3))
    frame = np.empty((C, 3, 3))
    k = np.zeros((C, 8))
    for c in range(C):
        body[c, 0], body[c, 1] = body_a[c], body_b[c]
        used_a = used_b = 0  # a side's particles packed to the front, −1 after
        for i in range(3):
            particle[c, 0, i] = particle[c, 1, i] = -1  # not particle[c] = -1: less to compile
        for i in range(3):
            if particles_a[c, i] >= 0:
                particle[c, 0, used_a], weight[c, 0, used_a] = particles_a[c, i], weights_a[c, i]
                used_a += 1
            if particles_b[c, i] >= 0:
                particle[c, 1, used_b], weight[c, 1, used_b] = particles_b[c, i], weights_b[c, i]
                used_b += 1
            frame[c, 0, i], frame[c, 1, i], frame[c, 2, i] = normal[c, i], tangent1[c, i], tangent2[c, i]
        for side in range(2):
            if body[c, side] >= 0:
                for i in range(3):
                    arm[c, side, i] = point[c, i] - body_position[body[c, side], i]
        effective_masses(c, frame, (body, particle, weight, arm), masses, k)
    return ContactRows(body, particle, weight, arm, frame, k, *masses)


@njit(cache=True, inline="always")
def effective_masses(c: int, frame: np.ndarray, sides: tuple, masses: tuple, k: np.ndarray) -> None:
    """Fill k[c] (the contact's row of ``ContactRows.k``, (8,)) from its ``frame`` (C, 3, 3), its
    ``sides`` = the rows' (body, particle, weight, arm) and ``masses`` = (the bodies' inverse
    masses (B,) [1/kg], world inverse inertias (B, 3, 3), the particles' inverse masses (P,)):
    what ``contact_rows`` builds, and what shock propagation rebuilds with the bodies below held
    (their inverse masses 0, ``methods.shock``)."""
    for d in range(5):
        row, column = (d, d) if d < 3 else (d - 2, 0)
        k[c, d] = _coupling(c, frame[c, row], frame[c, column], sides, masses)
    for d in range(3):
        k[c, 5 + d] = 1.0 / k[c, d] if k[c, d] > 0.0 else 0.0


@njit(cache=True, inline="always")
def _coupling(c, d, e, sides, masses):
    """dᵀ J M⁻¹ Jᵀ e of contact c for two world directions d, e (3,): the velocity along d that a
    unit impulse along e makes, summed over both sides [1/kg]. ``sides`` = the rows' (body,
    particle, weight, arm) as ``contact_rows`` fills them; ``masses`` as it takes them."""
    body, particle, weight, arm = sides
    inverse_mass, inverse_inertia, particle_inverse_mass = masses
    total = 0.0
    dot = d[0] * e[0] + d[1] * e[1] + d[2] * e[2]
    for side in range(2):
        b = body[c, side]
        if b >= 0:
            masses_b = (inverse_mass[b], inverse_inertia[b])
            total = body_coupling(total, 1.0, (arm[c, side], arm[c, side]), (d, e), masses_b)
        for m in range(3):
            p = particle[c, side, m]
            if p < 0:
                break
            total += weight[c, side, m] ** 2 * particle_inverse_mass[p] * dot
    return total


@njit(cache=True, inline="always")
def body_coupling(total: float, sign: float, arms: tuple, directions: tuple, masses: tuple) -> float:
    """``total`` + sign · (dᵀ e / m + (r_d × d)ᵀ I⁻¹ (r_e × e)) [1/kg]: the velocity along d, at the
    point of lever arm r_d, that a unit impulse along e at the point of lever arm r_e makes on one
    rigid body, ``arms`` = (r_d, r_e) (3,) [m], ``directions`` = (d, e) (3,), ``masses`` = (1/m
    [1/kg], the world I⁻¹ (3, 3)); each term added to the total in turn. A contact's own rows
    (``_coupling``: r_d = r_e) and two contacts' coupling (``blocks``)."""
    (rd_arm, re_arm), (d, e), (inverse_mass, inverse_inertia) = arms, directions, masses
    rd = (
        rd_arm[1] * d[2] - rd_arm[2] * d[1],
        rd_arm[2] * d[0] - rd_arm[0] * d[2],
        rd_arm[0] * d[1] - rd_arm[1] * d[0],
    )
    re = (
        re_arm[1] * e[2] - re_arm[2] * e[1],
        re_arm[2] * e[0] - re_arm[0] * e[2],
        re_arm[0] * e[1] - re_arm[1] * e[0],
    )
    total += sign * (inverse_mass * (d[0] * e[0] + d[1] * e[1] + d[2] * e[2]))
    for i in range(3):
        for j in range(3):
            total += sign * (rd[i] * inverse_inertia[i, j] * re[j])
    return total


@njit(cache=True, inline="always")
def contact_velocity(c: int, rows: ContactRows, u: np.ndarray) -> tuple[float, float, float]:
    """Contact c's three row velocities (v_n, v_t1, v_t2) = rows of J applied to u [m/s]."""
    body, particle, weight, arm, frame = rows.body, rows.particle, rows.weight, rows.arm, rows.frame
    B = rows.body_inverse_mass.shape[0]
    vx = vy = vz = 0.0  # v_A − v_B at the contact point
    for side in range(2):
        s = 1.0 - 2.0 * side
        b = body[c, side]
        if b >= 0:
            o = 6 * b
            rx, ry, rz = arm[c, side, 0], arm[c, side, 1], arm[c, side, 2]
            wx, wy, wz = u[o + 3], u[o + 4], u[o + 5]
            vx += s * (u[o] + wy * rz - wz * ry)
            vy += s * (u[o + 1] + wz * rx - wx * rz)
            vz += s * (u[o + 2] + wx * ry - wy * rx)
        for m in range(3):
            p = particle[c, side, m]
            if p < 0:  # packed: no more particles on this side
                break
            o = 6 * B + 3 * p
            w = s * weight[c, side, m]
            vx += w * u[o]
            vy += w * u[o + 1]
            vz += w * u[o + 2]
    return (
        frame[c, 0, 0] * vx + frame[c, 0, 1] * vy + frame[c, 0, 2] * vz,
        frame[c, 1, 0] * vx + frame[c, 1, 1] * vy + frame[c, 1, 2] * vz,
        frame[c, 2, 0] * vx + frame[c, 2, 1] * vy + frame[c, 2, 2] * vz,
    )


@njit(cache=True, inline="always")
def apply_impulse(c: int, rows: ContactRows, dn: float, d1: float, d2: float, u: np.ndarray) -> None:
    """Add contact c's impulse (dn, d1, d2) [N s] along (n, t1, t2) to u: u += M⁻¹ Jᵀ λ."""
    along_rows(c, rows, dn, d1, d2, u, True)


@njit(cache=True, inline="always")
def along_rows(c: int, rows: ContactRows, dn: float, d1: float, d2: float, u: np.ndarray, inverse_mass: bool) -> None:
    """u += M⁻¹ Jᵀ λ for contact c's λ = (dn, d1, d2) along (n, t1, t2) where ``inverse_mass``
    (a velocity change from an impulse [N s]), else u += Jᵀ λ (a generalized force from a force
    [N]): the world vector P = dn n + d1 t1 + d2 t2 on each side, ±(P, r × P) for a body (times
    1/m and I⁻¹), ±w P for a particle (times 1/m_p; a pinned one never written)."""
    body, particle, weight, arm, frame = rows.body, rows.particle, rows.weight, rows.arm, rows.frame
    inverse, inverse_inertia, particle_inverse_mass = (
        rows.body_inverse_mass,
        rows.inverse_inertia,
        rows.particle_inverse_mass,
    )
    B = inverse.shape[0]
    px = dn * frame[c, 0, 0] + d1 * frame[c, 1, 0] + d2 * frame[c, 2, 0]
    py = dn * frame[c, 0, 1] + d1 * frame[c, 1, 1] + d2 * frame[c, 2, 1]
    pz = dn * frame[c, 0, 2] + d1 * frame[c, 1, 2] + d2 * frame[c, 2, 2]
    for side in range(2):
        s = 1.0 - 2.0 * side
        b = body[c, side]
        if b >= 0:
            o = 6 * b
            a = s * inverse[b] if inverse_mass else s
            u[o] += a * px
            u[o + 1] += a * py
            u[o + 2] += a * pz
            rx, ry, rz = arm[c, side, 0], arm[c, side, 1], arm[c, side, 2]
            tx, ty, tz = s * (ry * pz - rz * py), s * (rz * px - rx * pz), s * (rx * py - ry * px)  # ±r × P
            if inverse_mass:
                for i in range(3):
                    u[o + 3 + i] += (
                        inverse_inertia[b, i, 0] * tx + inverse_inertia[b, i, 1] * ty + inverse_inertia[b, i, 2] * tz
                    )
            else:
                u[o + 3] += tx
                u[o + 4] += ty
                u[o + 5] += tz
        for m in range(3):
            p = particle[c, side, m]
            if p < 0:  # packed: no more particles on this side
                break
            a = s * weight[c, side, m] * particle_inverse_mass[p] if inverse_mass else s * weight[c, side, m]
            if a == 0.0:  # pinned: never written (see sweep_groups)
                continue
            o = 6 * B + 3 * p
            u[o] += a * px
            u[o + 1] += a * py
            u[o + 2] += a * pz


@njit(cache=True)
def apply_impulses(rows: ContactRows, impulses: np.ndarray, u: np.ndarray) -> None:
    """u += M⁻¹ Jᵀ λ for every contact's impulses (C, 3) [N s] as (normal, t1, t2)."""
    for c in range(impulses.shape[0]):
        apply_impulse(c, rows, impulses[c, 0], impulses[c, 1], impulses[c, 2], u)


@njit(cache=True)
def rows_in_order(rows: ContactRows, order: np.ndarray) -> ContactRows:
    """``rows`` with the per-contact arrays taken in ``order`` (C,) int; the body data as is.

    Copied in one loop over the contacts, not by six fancy indexings: Numba's gather of a
    multi-dimensional array by an index array goes element by element through a generic
    iterator (38 µs a step for the pyramid's 1 600 contacts, against 22 µs here)."""
    C = order.shape[0]
    body = np.empty((C, 2), dtype=rows.body.dtype)
    particle = np.empty((C, 2, 3), dtype=rows.particle.dtype)
    weight = np.empty((C, 2, 3))
    arm = np.empty((C, 2, 3))
    frame = np.empty((C, 3, 3))
    k = np.empty((C, 8))
    for i in range(C):
        c = order[i]
        for side in range(2):
            body[i, side] = rows.body[c, side]
            for j in range(3):
                particle[i, side, j] = rows.particle[c, side, j]
                weight[i, side, j] = rows.weight[c, side, j]
                arm[i, side, j] = rows.arm[c, side, j]
        for d in range(3):
            for j in range(3):
                frame[i, d, j] = rows.frame[c, d, j]
        for d in range(8):
            k[i, d] = rows.k[c, d]
    return ContactRows(
        body, particle, weight, arm, frame, k, rows.body_inverse_mass, rows.inverse_inertia, rows.particle_inverse_mass
    )


@njit(cache=True, inline="always")  # into the compiled loop's ``build_rows``: no call more than before
def rows_at(
    contacts: Any,  # a ContactArrays, whose fields (Contacts') mypy cannot see: they are named at run time
    body_position: np.ndarray,
    body_inverse_mass: np.ndarray,
    body_inverse_inertia_world: np.ndarray,
    particle_inverse_mass: np.ndarray,
) -> ContactRows:
    """``contact_rows`` of a ``ContactArrays`` at body positions (B, 3) [m], with the bodies' inverse
    masses (B,) [1/kg] and world inverse inertias (B, 3, 3) [1/(kg m²)] there, and the particles'
    inverse masses (P,) [1/kg]: the one place that hands the contacts' fields to it, for the
    methods' steps (``rows_of``) and the compiled loop's (``loop_stages.build_rows``) alike."""
    sides = (
        contacts.body_a,
        contacts.body_b,
        contacts.particles_a,
        contacts.particles_b,
        contacts.weights_a,
        contacts.weights_b,
    )
    geometry = (contacts.point, contacts.normal, contacts.tangent1, contacts.tangent2)
    masses = (body_inverse_mass, body_inverse_inertia_world, particle_inverse_mass)
    return contact_rows(sides, geometry, body_position, masses)


def rows_of(model: Model, contacts: Contacts, body_position: np.ndarray, body_orientation: np.ndarray) -> ContactRows:
    """``contact_rows`` of a Contacts at the given body positions (B, 3) and orientations (B, 4)
    (the state the contacts were detected at)."""
    from ..dynamics.integrators import world_inverse_inertia

    return rows_at(
        contacts.arrays(),
        body_position,
        model.body_inverse_mass,
        world_inverse_inertia(model, body_orientation),
        model.particle_inverse_mass,
    )


@njit(cache=True)
def row_products(rows: ContactRows, u: np.ndarray) -> np.ndarray:
    """J u per contact (C, 3): each contact's normal and tangent rows applied to u [m/s]."""
    C = rows.k.shape[0]
    out = np.empty((C, 3))
    for c in range(C):
        out[c, 0], out[c, 1], out[c, 2] = contact_velocity(c, rows, u)
    return out
