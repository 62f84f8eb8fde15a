"""Lemke's complementary pivoting method with a covering vector, for general LCPs.

Solves ``w = M z + q ≥ 0, z ≥ 0, zᵀ w = 0`` for any square M (non-symmetric included), dense.
:func:`contactlab.lcp.solve_lcp` calls it with ``M = B``, ``q = −c``.

Method (Lemke 1965; Cottle, Pang & Stone, *The Linear Complementarity Problem*, §4.4):

* add an artificial variable z₀ with covering vector e = (1, …, 1): ``w = M z + q + e z₀``;
* start from the basis w with z₀ = −min(q) (almost complementary and feasible);
* repeatedly bring in the complement of the variable that just left, choosing the leaving row by
  the **lexicographic** minimum-ratio rule (ratios of the right-hand side, then of the columns of
  the current basis inverse), which makes every pivot strictly lexicographically increasing and
  rules out cycling under degeneracy;
* stop when z₀ leaves (a solution) or when the entering column has no positive entry: a
  **secondary ray**. Then no solution was found; when M is copositive-plus (e.g. positive
  semidefinite, or any matrix whose symmetric part is PSD), the ray proves that the LCP has none.

The final basis is then re-solved directly (``M_SS z_S = −q_S`` for the basic z's) so the answer
is exact to round-off, not to the accumulated pivoting error.
"""

from __future__ import annotations

import numpy as np


def _lexicographic_row(rhs, tableau, column, n, z0_row, pivot_tol):
    """Leaving row for entering ``column`` (n,), or -1 when nothing blocks (a ray)."""
    candidates = np.flatnonzero(column > pivot_tol)
    if candidates.size == 0:
        return -1
    ratios = rhs[candidates] / column[candidates]
    best = ratios.min()
    ties = candidates[ratios <= best + 1e-12 * max(1.0, abs(best))]
    if z0_row >= 0 and np.any(ties == z0_row):
        return z0_row  # let z0 leave as soon as it can: that ends the method
    j = 0
    while ties.size > 1 and j < n:
        values = tableau[ties, j] / column[ties]
        low = values.min()
        ties = ties[values <= low + 1e-12 * max(1.0, abs(low))]
        j += 1
    return int(ties[0])


def lemke(M: np.ndarray, q: np.ndarray, max_pivots: int) -> tuple[np.ndarray, int, str, str]:
    """Run Lemke's method on ``w = M z + q``.

    Returns ``(z, pivots, status, message)`` with status ``"solved"``, ``"ray"`` or
    ``"max_pivots"``; on a ray or the pivot limit z is the last basic point (not a solution).
    """
    n = q.shape[0]
    if n == 0 or np.all(q >= 0.0):
        return np.zeros(n), 0, "solved", "c <= 0: λ = 0 solves the LCP."
    # columns 0..n-1: w, n..2n-1: z, 2n: z0. Columns 0..n-1 always hold the basis inverse.
    tableau = np.hstack([np.eye(n), -M, -np.ones((n, 1))])
    rhs = q.astype(np.float64).copy()
    basis = np.arange(n)

    # first pivot: z0 enters, the most negative q leaves (ties broken lexicographically)
    low = rhs.min()
    ties = np.flatnonzero(rhs <= low + 1e-12 * max(1.0, abs(low)))
    row = int(ties[-1])  # lexicographic minimum of the rows (q_i, e_i) among ties
    entering = 2 * n
    pivots = 0
    while True:
        p = tableau[row, entering]
        tableau[row] /= p
        rhs[row] /= p
        col = tableau[:, entering].copy()
        col[row] = 0.0
        tableau -= np.outer(col, tableau[row])
        rhs -= col * rhs[row]
        leaving = basis[row]
        basis[row] = entering
        pivots += 1
        if leaving == 2 * n:
            status, message = "solved", f"Lemke's method found a solution in {pivots} pivots."
            break
        entering = leaving + n if leaving < n else leaving - n
        if pivots >= max_pivots:
            status = "max_pivots"
            message = (
                f"Lemke's method stopped at the pivot limit ({max_pivots}) before finding a solution; "
                "raise max_iterations."
            )
            break
        column = tableau[:, entering]
        z0_rows = np.flatnonzero(basis == 2 * n)
        z0_row = int(z0_rows[0]) if z0_rows.size else -1
        row = _lexicographic_row(rhs, tableau, column, n, z0_row, 1e-11 * max(1.0, np.abs(column).max()))
        if row < 0:
            kind = f"z[{entering - n}]" if entering >= n else f"w[{entering}]"
            status = "ray"
            message = (
                f"Lemke's method ended on a secondary ray after {pivots} pivots ({kind} can grow without "
                "bound): no solution was found; if B is copositive-plus (e.g. positive semidefinite) "
                "the LCP has no solution."
            )
            break
    z = np.zeros(n)
    in_z = (basis >= n) & (basis < 2 * n)
    z[basis[in_z] - n] = np.maximum(rhs[in_z], 0.0)
    if status == "solved":
        z = _refine(M, q, basis, n, z)
    return z, pivots, status, message


def _refine(M, q, basis, n, z):
    """Re-solve the final complementary basis exactly; keep the pivoted z if that fails."""
    active = np.sort(basis[(basis >= n) & (basis < 2 * n)] - n)
    if active.size == 0:
        return z
    try:
        z_active = np.linalg.solve(M[np.ix_(active, active)], -q[active])
    except np.linalg.LinAlgError:
        return z
    candidate = np.zeros(n)
    candidate[active] = np.maximum(z_active, 0.0)

    def error(x):
        w = M @ x + q
        return np.linalg.norm(x - np.maximum(0.0, x - w))

    return candidate if error(candidate) <= error(z) else z
