"""The compiled sweeps of the 3D friction problem (:mod:`contactlab.lcp.friction` states it):
non-smooth Gauss-Seidel (``nsgs_sweeps``, SPEC F4a) and the normal/friction alternation
(``staggered_sweeps``, SPEC F4b) on the reactions r (m,) = (3·nc,) in place, W in CSR arrays
(``indptr``, ``indices``, ``data``) and its 3×3 diagonal blocks (``diagonal_blocks``), and the
normalized natural-map error they stop on (``fill_velocity_error``), with the pieces of apgd's step: one
contact's cone projection (``_cone_point``, which the error's natural map uses too), the gradient
step (``apgd_step``) and the extrapolation. ``solve_friction_contact`` runs them; the
semi-smooth Newton solver (:mod:`contactlab.lcp.newton`) warm starts and restarts with NSGS.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np
import scipy.sparse as sp

from ..compiling import njit
from ..ordered_sums import ordered_dot
from .disk import disk_solve

_SQRT_HALF = math.sqrt(0.5)

# the problem the sweeps solve: W in CSR arrays (indptr, indices, data), q (m,), μ (nc,) and W's
# 3×3 diagonal blocks (nc, 3, 3) (``diagonal_blocks``)
Sweeping = namedtuple("Sweeping", ["indptr", "indices", "data", "q", "mu", "blocks"])


@njit(cache=True)
def _row_dot(indptr, indices, data, r, i):
    acc = 0.0
    for k in range(indptr[i], indptr[i + 1]):
        acc += data[k] * r[indices[k]]
    return acc


@njit(cache=True)
def _cone_point(m_a, zn, z1, z2):
    """(zn, z1, z2), one contact's [N, T1, T2], projected (Euclidean) on its cone ‖t‖ ≤ μ n of
    friction coefficient ``m_a``: 0 in the dual cone, itself inside, else onto the cone's side."""
    zt = math.sqrt(z1 * z1 + z2 * z2)
    if m_a * zt <= -zn:
        return 0.0, 0.0, 0.0
    if zt <= m_a * zn:
        return zn, z1, z2
    pn = (m_a * zt + zn) / (1.0 + m_a * m_a)
    scale = m_a * pn / zt
    return pn, scale * z1, scale * z2


@njit(cache=True)
def natural_map_norms(mu: np.ndarray, r: np.ndarray, u: np.ndarray, pyramid: bool) -> tuple[float, float, float]:
    """(‖F(r)‖, ‖r‖, ‖u‖) for reactions r (m,) and velocities u (m,) = W r + q: F the cone's
    natural map, or the box split form for the pyramid (:mod:`contactlab.lcp.friction`)."""
    total = 0.0
    norm_r = 0.0
    norm_u = 0.0
    for a in range(r.shape[0] // 3):
        i = 3 * a
        rn, rt1, rt2 = r[i], r[i + 1], r[i + 2]
        un, ut1, ut2 = u[i], u[i + 1], u[i + 2]
        norm_r += rn * rn + rt1 * rt1 + rt2 * rt2
        norm_u += un * un + ut1 * ut1 + ut2 * ut2
        m_a = mu[a]
        if pyramid:
            fn = rn - max(0.0, rn - un)
            bound = m_a * max(rn, 0.0) * _SQRT_HALF
            f1 = rt1 - min(max(rt1 - ut1, -bound), bound)
            f2 = rt2 - min(max(rt2 - ut2, -bound), bound)
        else:
            # z = r − û, û = u + [μ‖u_T‖, 0, 0]; F = r − P_K(z)
            pn, p1, p2 = _cone_point(m_a, rn - un - m_a * math.sqrt(ut1 * ut1 + ut2 * ut2), rt1 - ut1, rt2 - ut2)
            fn, f1, f2 = rn - pn, rt1 - p1, rt2 - p2
        total += fn * fn + f1 * f1 + f2 * f2
    return math.sqrt(total), math.sqrt(norm_r), math.sqrt(norm_u)


@njit(cache=True)
def normalized_residual(mu: np.ndarray, r: np.ndarray, u: np.ndarray, pyramid: bool, norm_q: float) -> float:
    """The normalized natural-map error ‖F(r)‖ / max(|q|, ‖r‖, ‖u‖) (1 for a zero maximum) of r
    (m,) at u (m,) = W r + q, |q| given."""
    absolute, norm_r, norm_u = natural_map_norms(mu, r, u, pyramid)
    scale = max(norm_q, norm_r, norm_u)
    if scale <= 0.0:
        scale = 1.0
    return absolute / scale


@njit(cache=True)
def fill_velocity_error(
    indptr: np.ndarray,
    indices: np.ndarray,
    data: np.ndarray,
    q: np.ndarray,
    mu: np.ndarray,
    r: np.ndarray,
    u: np.ndarray,
    pyramid: bool,
    norm_q: float,
) -> float:
    """Fill ``u = W r + q`` and return the normalized residual (cone natural map, or box split form)."""
    m = q.shape[0]
    for i in range(m):
        u[i] = _row_dot(indptr, indices, data, r, i) + q[i]
    return normalized_residual(mu, r, u, pyramid, norm_q)


@njit(cache=True)
def project_cone(r: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """Each contact's (r_N, r_T) of r (3·nc,) projected on its cone ‖r_T‖ ≤ μ r_N (Euclidean), a
    new (3·nc,)."""
    out = np.empty_like(r)
    for a in range(r.shape[0] // 3):
        i = 3 * a
        out[i], out[i + 1], out[i + 2] = _cone_point(mu[a], r[i], r[i + 1], r[i + 2])
    return out


@njit(cache=True)
def apgd_step(
    y: np.ndarray, Wy: np.ndarray, q: np.ndarray, mu: np.ndarray, step: float, r: np.ndarray, new: np.ndarray
) -> float:
    """One projected gradient step of apgd (:func:`contactlab.lcp.friction._apgd`) from y (m,)
    with W y (m,): ``new = P_K(y − step · û)``, û = W y + q + [μ‖u_T‖, 0, 0] (De Saxcé's
    velocity, the gradient), written into ``new`` (m,). Returns ûᵀ (new − r) for the last
    iterate r (m,): above 0, the step went uphill (apgd's gradient restart)."""
    uphill = 0.0
    for a in range(q.shape[0] // 3):
        i = 3 * a
        u1, u2 = Wy[i + 1] + q[i + 1], Wy[i + 2] + q[i + 2]
        gn = Wy[i] + q[i] + mu[a] * math.sqrt(u1 * u1 + u2 * u2)
        pn, p1, p2 = _cone_point(mu[a], y[i] - step * gn, y[i + 1] - step * u1, y[i + 2] - step * u2)
        new[i], new[i + 1], new[i + 2] = pn, p1, p2
        uphill += gn * (pn - r[i]) + u1 * (p1 - r[i + 1]) + u2 * (p2 - r[i + 2])
    return uphill


@njit(cache=True)
def extrapolate(new: np.ndarray, old: np.ndarray, beta: float) -> np.ndarray:
    """Nesterov's extrapolation new + β (new − old), a new array (m,)."""
    out = np.empty_like(new)
    for i in range(new.shape[0]):
        out[i] = new[i] + beta * (new[i] - old[i])
    return out


@njit(cache=True)
def _friction_update(blocks, a, r, i, ut1, ut2, m_a, pyramid):
    """Solve contact a's friction exactly with its normal fixed (u_T given at the current r)."""
    rn = r[i]
    a00 = blocks[a, 1, 1]
    a01 = blocks[a, 1, 2]
    a10 = blocks[a, 2, 1]
    a11 = blocks[a, 2, 2]
    if pyramid:
        bound = m_a * rn * _SQRT_HALF
        # projected coordinate steps, exact per component; two passes couple T1 and T2
        for _ in range(2):
            for k in (1, 2):  # T1, then T2: its diagonal entry, and its column moves u_T
                diagonal = blocks[a, k, k]
                if diagonal > 0.0:
                    new = min(max(r[i + k] - (ut1 if k == 1 else ut2) / diagonal, -bound), bound)
                    delta = new - r[i + k]
                    r[i + k] = new
                    ut1 += blocks[a, 1, k] * delta
                    ut2 += blocks[a, 2, k] * delta
        return
    # b = u_T − W_TT r_T: the part of u_T that does not come from this contact's own friction
    b1 = ut1 - a00 * r[i + 1] - a01 * r[i + 2]
    b2 = ut2 - a10 * r[i + 1] - a11 * r[i + 2]
    x1, x2 = disk_solve(a00, a01, a10, a11, b1, b2, m_a * rn)
    r[i + 1] = x1
    r[i + 2] = x2


@njit(cache=True)
def _start(indptr, indices, data, q, mu, r, pyramid):
    """What both sweeps start from: (contact count nc, u (m,) holding W r + q, |q|, the error
    of r) for r (m,), q (m,) with m = 3 nc."""
    m = q.shape[0]
    u = np.empty(m)
    norm_q = math.sqrt(ordered_dot(q, q))  # in index order: the same bits compiled and as Python
    return m // 3, u, norm_q, fill_velocity_error(indptr, indices, data, q, mu, r, u, pyramid, norm_q)


@njit(cache=True)
def nsgs_sweeps(problem: Sweeping, r: np.ndarray, tol: float, max_iterations: int, pyramid: bool) -> tuple[int, float]:
    """Non-smooth Gauss-Seidel (SPEC F4a) of ``problem`` (a :data:`Sweeping`) on r (m,), in
    place. Returns (sweeps, error)."""
    indptr, indices, data, q, mu, blocks = problem
    nc, u, norm_q, error = _start(indptr, indices, data, q, mu, r, pyramid)
    if error <= tol:
        return 0, error
    for sweep in range(1, max_iterations + 1):
        for a in range(nc):
            i = 3 * a
            un = _row_dot(indptr, indices, data, r, i) + q[i]
            ut1 = _row_dot(indptr, indices, data, r, i + 1) + q[i + 1]
            ut2 = _row_dot(indptr, indices, data, r, i + 2) + q[i + 2]
            wnn = blocks[a, 0, 0]
            if wnn > 0.0:
                new = max(0.0, r[i] - un / wnn)
                delta = new - r[i]
                r[i] = new
                ut1 += blocks[a, 1, 0] * delta
                ut2 += blocks[a, 2, 0] * delta
            _friction_update(blocks, a, r, i, ut1, ut2, mu[a], pyramid)
        error = fill_velocity_error(indptr, indices, data, q, mu, r, u, pyramid, norm_q)
        if error <= tol:
            return sweep, error
    return max_iterations, error


@njit(cache=True)
def staggered_sweeps(
    problem: Sweeping, r: np.ndarray, tol: float, max_iterations: int, pyramid: bool, inner: int
) -> tuple[int, float]:
    """Staggered normal/friction iteration (SPEC F4b) of ``problem`` (a :data:`Sweeping`) on
    r (m,), in place. Returns (rounds, error).

    Each round: up to ``inner`` projected Gauss-Seidel sweeps over all normal rows (frictions
    fixed), then up to ``inner`` sweeps of exact friction solves over all contacts (normals
    fixed); a phase stops early when its largest change is below ``tol/10`` of the largest r."""
    indptr, indices, data, q, mu, blocks = problem
    nc, u, norm_q, error = _start(indptr, indices, data, q, mu, r, pyramid)
    if error <= tol:
        return 0, error
    for rnd in range(1, max_iterations + 1):
        for _ in range(inner):
            change = 0.0
            size = 0.0
            for a in range(nc):
                i = 3 * a
                wnn = blocks[a, 0, 0]
                if wnn > 0.0:
                    un = _row_dot(indptr, indices, data, r, i) + q[i]
                    new = max(0.0, r[i] - un / wnn)
                    change = max(change, abs(new - r[i]))
                    r[i] = new
                size = max(size, abs(r[i]))
            if change <= 0.1 * tol * size:
                break
        for _ in range(inner):
            change = 0.0
            size = 0.0
            for a in range(nc):
                i = 3 * a
                old1 = r[i + 1]
                old2 = r[i + 2]
                ut1 = _row_dot(indptr, indices, data, r, i + 1) + q[i + 1]
                ut2 = _row_dot(indptr, indices, data, r, i + 2) + q[i + 2]
                _friction_update(blocks, a, r, i, ut1, ut2, mu[a], pyramid)
                change = max(change, abs(r[i + 1] - old1), abs(r[i + 2] - old2))
                size = max(size, abs(r[i]))
            if change <= 0.1 * tol * size:
                break
        error = fill_velocity_error(indptr, indices, data, q, mu, r, u, pyramid, norm_q)
        if error <= tol:
            return rnd, error
    return max_iterations, error


def diagonal_blocks(csr: sp.csr_matrix, nc: int) -> np.ndarray:
    """The 3×3 diagonal blocks W_αα, shape (nc, 3, 3)."""
    base = 3 * np.arange(nc)
    rows = (base[:, None, None] + np.arange(3)[None, :, None]) + np.zeros((1, 1, 3), dtype=np.int64)
    cols = (base[:, None, None] + np.arange(3)[None, None, :]) + np.zeros((1, 3, 1), dtype=np.int64)
    if nc == 0:
        return np.zeros((0, 3, 3))
    values = np.asarray(csr[rows.ravel(), cols.ravel()]).ravel()
    return values.reshape(nc, 3, 3).astype(np.float64)
