"""Solve one contact LCP three ways: projected Gauss-Seidel, its colored parallel form, and Lemke.

    python3 examples/lcp_column.py

A column of N unit masses resting on the floor under gravity, at the velocity level: the
normal impulses λ must carry every mass above, λ_k = (N − k) m g h. B = J M⁻¹ Jᵀ is the
tridiagonal Delassus matrix of the column; the LCP is w = B λ − c ≥ 0, λ ≥ 0, λᵀw = 0 with
c = the velocity each contact must cancel (SPEC C6–C8).
"""

import numpy as np
import scipy.sparse as sp

from contactlab.lcp import solve_lcp

N = 10  # masses in the column
MASS = 1.0  # kg
G, H = 9.81, 0.01  # m/s², s


def column_lcp():
    """B (N, N) sparse and c (N,): contact 0 is floor–mass 0, contact k is mass k−1 – mass k."""
    J = sp.diags([np.ones(N), -np.ones(N - 1)], [0, -1]).tocsr()  # gap rate of contact k
    B = (J @ J.T / MASS).tocsr()
    free_velocity = np.full(N, -G * H)  # gravity over one step
    c = -(J @ free_velocity)  # cancel the approach speed
    return B, c


def main():
    B, c = column_lcp()
    exact = (N - np.arange(N)) * MASS * G * H
    for method in ("pgs", "redblack", "lemke"):
        result = solve_lcp(B, c, method=method, tol=1e-12, max_iterations=20000)
        error = np.max(np.abs(result.lam - exact))
        print(
            f"{method:9s} converged={result.converged} after {result.iterations} "
            f"{'pivots' if method == 'lemke' else 'sweeps'}; largest error {error:.2e} N s"
        )


if __name__ == "__main__":
    main()
