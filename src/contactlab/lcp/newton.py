"""Semi-smooth Newton method for the 3D Coulomb friction problem FC(W, q, μ) (FCLIB local form).

The problem (see :mod:`contactlab.lcp.friction`): nc contacts, each with local components
[N, T1, T2] (m = 3·nc unknowns); find the reactions r (m,) with::

    u = W r + q,     r^α ∈ K_μα = {‖r_T‖ ≤ μ_α r_N},     K*_μα ∋ û^α ⊥ r^α,
    û^α = u^α + [μ_α ‖u^α_T‖, 0, 0]                  (De Saxcé's change of variable, as in FCLIB)

W (m, m): Delassus operator [velocity / impulse]; q (m,): free relative velocity [velocity];
r (m,): impulses; μ (nc,): friction coefficients [-].

**The equation.** De Saxcé's complementarity is Coulomb's law: either the contact opens
(r^α = 0, u_N ≥ 0), or it sticks (u^α = 0, r^α ∈ K), or it slides (u_N = 0, r_T = −μ r_N u_T/‖u_T‖).
So is the zero of the Alart–Curnier function, which this module solves, per contact α::

    Φ^α(r) = [ r_N − P_R+(r_N − ρ_N u_N)                       ]   x_N = r_N − ρ_N u_N,
             [ r_T − P_D(μ (x_N)_+)(r_T − ρ_T u_T)             ]   y   = r_T − ρ_T u_T,

P_R+ the projection on [0, ∞), P_D(R) the projection on the disk of radius R = μ max(x_N, 0)
(the "AC" variant, Alart & Curnier 1991, Siconos' ``computeAlartCurnierSTD``). ρ_N, ρ_T > 0 (units of
impulse per velocity) change the function's scaling but not its zeros: Φ(r) = 0 exactly when r
solves FC(W, q, μ), i.e. when the FCLIB natural map ``F(r) = r − P_K(r − û)`` vanishes. Per
contact, ρ_N = 1/W_NN and ρ_T = 1/λ_max(W_TT) of the 3×3 diagonal block W_αα (Siconos'
"split spectral norm" choice): r_N − ρ_N u_N is then nsgs' normal update, and r_T − ρ_T u_T a
gradient step of length 1/λ_max on the contact's friction.

**Generalized Jacobian.** Φ depends on r directly and through u, so dΦ = A dr + B du with A, B
block diagonal (one 3×3 block per contact, :func:`_alart_curnier`), and an element of Clarke's
generalized Jacobian is ``J = A + B W`` (same sparsity as W, plus the diagonal blocks):

* normal, x_N > 0 (closed): Φ_N = ρ_N u_N, so B_NN = ρ_N; x_N ≤ 0 (open): Φ_N = r_N, A_NN = 1;
* tangent, ‖y‖ ≤ R with R > 0 (stick): Φ_T = ρ_T u_T, B_TT = ρ_T I;
* tangent otherwise (slide, or R = 0): Φ_T = r_T − R ŷ with ŷ = y/‖y‖ and Γ = (I − ŷŷᵀ)/‖y‖:
  A_TT = I − R Γ, B_TT = ρ_T R Γ and, when x_N > 0, A_TN = −μ ŷ, B_TN = μ ρ_N ŷ.

**One iteration.** Solve ``(A + B (W + δ I)) d = −Φ(r)`` by sparse LU (SciPy's SuperLU on the
CSR matrix read as the CSC of its transpose, so no conversion; minimum-degree ordering on
Jᵀ + J, since the pattern is structurally symmetric), then search along d. The shift δ I is a proximal
regularization: it is the Jacobian of Φ for the problem with W + δ I and q − δ r, whose
solutions are those of FC(W, q, μ) at a fixed point. It makes J invertible where W is singular
(more contact rows than degrees of freedom: box stacks, Capsules-i100 and i101) and damps the
steps while the active set (open / stick / slide) is still wrong. ``δ = w̄ min(κ, e)``, with
w̄ the mean |diagonal| of W, κ = 0.1 and e the current relative natural-map error, so it fades
as the iterate converges and the last steps are plain Newton steps (fast local convergence). If
SuperLU still reports a singular factor, δ is raised by 100× up to w̄, and past that the step is
steepest descent on the merit, −Jᵀ Φ.

**Globalization.** The merit is ψ(r) = ½‖Φ(r)‖². Armijo backtracking (halving t from 1, at most
30 times) accepts ``ψ(r + t d) ≤ C − 10⁻⁴ t ψ(r)`` with C Zhang & Hager's non-monotone reference,
the running weighted mean ``C ← (η Q C + ψ) / (η Q + 1)``, ``Q ← η Q + 1``, η = 0.9: the full
Newton step is accepted more often than with the monotone rule (C = ψ), which matters because
ψ has kinks at every contact that changes regime. C decreases at every accepted step, whereas
with Grippo et al.'s max-of-the-last-10 rule the merit climbed back again and again (on
BoxesStack1 with a weaker δ: 1e-4 → 4e-7 → 4e-4, over and over). The trial points cost O(m):
u + t W d, with W d computed once. If none of the 30 trials passes, t = 2⁻³⁰ is taken and the
watchdog below deals with the stall.

**Watchdog.** ψ may have stationary points that are not solutions (semi-smooth Newton on the
Alart–Curnier function can also cycle between regimes: a single ill-conditioned contact with
μ = 1.7 does). If the natural-map error has not fallen below 0.9 × its last mark in 30 iterations, the
solver runs non-smooth Gauss–Seidel sweeps from the iterate where it stands
(:func:`contactlab.lcp.friction_sweeps.nsgs_sweeps`; 20 the first time, twice as many at each later restart,
at most 5120), multiplies ρ by the next factor of (10, 0.1, 1) (another ρ, another merit
landscape, the same zeros), and restarts the non-monotone reference. The doubling makes the
method at least as robust as nsgs given enough iterations. On 9000 random small SPD problems
(1–5 contacts, tol 1e-12, 300 steps) 78 failed without the watchdog, 5 with a fixed 20 sweeps per
restart, none with the doubling.

It restarts from where it stands, not from the best iterate met (which is still what it
returns). The non-monotone search lets the iterates roam away from the best error while they look
for the open/stick/slide pattern, and on a pile that roaming is the way out: on Siconos' rock pile
(RockPile_tob1, 463 contacts, μ = 1, W of rank 743 for 1389 rows) the error falls to 1.1e-4 at
step 23, roams between 1e-2 and 1e-3 while C keeps falling, and the plain iteration converges from
there (2e-7 at step 100). Sent back to its step-23 iterate, the watchdog put it into a basin it never
left: 3.3e-6 after 1000 steps and 30 restarts (so did nsgs after 10 000 sweeps: 1.2e-5).
Restarting where it stands, it reaches 1e-8 in 146 steps (one restart). On 5500 random singular
problems (W = HᵀH with fewer rows in H than contact rows, 2–20 contacts, μ ≤ 2, tol 1e-8, 300
steps) 16 end above tol, against 17 when sent back; on 9000 random SPD ones (tol 1e-12) none either way.

**Warm start from nsgs** (``warm_sweeps``, off by default). Measured on the FCLIB files (tol 1e-8):
a few sweeps help where nsgs converges within them or nearly: after 5 sweeps Confeti,
FC3D_Example1 and FrictionContact3D_1c need no factorization at all, after 20 none of the nine
small problems does (0.6 → 0.2 ms each), and Box_Stacks needs 1 step instead of 6. They hurt on
the Capsules problems: Capsules-i101 takes 18 Newton steps after 5 sweeps, 28 after 20 and 131
after 100 instead of 12, Capsules-i125 231 after 100 instead of 10. The sweeps lower the error
by one or two orders of magnitude without finding the stick/slide pattern of those singular W
(more contact rows than degrees of freedom), and since δ follows the error, Newton then
starts from a nearly singular J with little damping; from r = 0 the strong early regularization
acts as a homotopy that finds the pattern in a few steps. So: sweeps for many small, easy
problems solved in a row; none for hard or degenerate ones.

Stopping: the normalized natural-map error of :func:`contactlab.lcp.natural_map_error`
(``‖F(r)‖ / max(‖q‖, ‖r‖, ‖u‖)``) ≤ tol, computed after every step; the best iterate met is
returned otherwise. Hot loops (Φ and its blocks per contact, filling J on its fixed pattern)
are compiled with Numba (``cache=True``).
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..compiling import njit
from .friction_sweeps import Sweeping, diagonal_blocks, fill_velocity_error, nsgs_sweeps

NONMONOTONE_WEIGHT = 0.9  # η of Zhang & Hager's reference (0: monotone Armijo)
ARMIJO_SLOPE = 1e-4  # ψ must fall by ARMIJO_SLOPE · t · ψ (a Newton step predicts 2 t ψ)
MAX_HALVINGS = 30  # line-search trials, t = 1 down to 2⁻²⁹
REGULARIZATION_CAP = 0.1  # κ: δ = w̄ min(κ, error)
WATCHDOG_PATIENCE = 30  # iterations without 10 % progress before the watchdog acts
WATCHDOG_PROGRESS = 0.9  # the factor the best error must beat within the patience
WATCHDOG_SWEEPS = 20  # nsgs sweeps the watchdog runs from the current iterate (doubled each time)
WATCHDOG_DOUBLINGS = 8  # at most 20 · 2⁸ = 5120 sweeps in one restart
RHO_FACTORS = (10.0, 0.1, 1.0)  # ρ scalings the watchdog cycles through


# ----------------------------------------------------------------------------- compiled parts


@njit(cache=True)
def _alart_curnier(r, u, mu, rho, phi, a_blocks, b_blocks, jacobian):
    """Fill Φ(r) (m,) of the module docstring at reactions r and velocities u = W r + q (both (m,)),
    and, if ``jacobian``, the blocks (nc, 3, 3) of ``dΦ = A dr + B du``. rho (m,): per contact
    (ρ_N, ρ_T, ρ_T). Returns the merit ψ = ½‖Φ‖²."""
    nc = mu.shape[0]
    merit = 0.0
    for a in range(nc):
        i = 3 * a
        rn, rt1, rt2 = r[i], r[i + 1], r[i + 2]
        rho_n, rho_t, m_a = rho[i], rho[i + 1], mu[a]
        if jacobian:
            for k in range(3):
                for col in range(3):
                    a_blocks[a, k, col] = 0.0
                    b_blocks[a, k, col] = 0.0
        xn = rn - rho_n * u[i]
        if xn > 0.0:  # closed: Φ_N = r_N − x_N = ρ_N u_N
            fn = rho_n * u[i]
            if jacobian:
                b_blocks[a, 0, 0] = rho_n
        else:  # open: Φ_N = r_N
            fn = rn
            if jacobian:
                a_blocks[a, 0, 0] = 1.0
        radius = m_a * xn if xn > 0.0 else 0.0
        y1 = rt1 - rho_t * u[i + 1]
        y2 = rt2 - rho_t * u[i + 2]
        ny = math.sqrt(y1 * y1 + y2 * y2)
        if radius > 0.0 and ny <= radius:  # stick: Φ_T = r_T − y = ρ_T u_T
            f1 = rho_t * u[i + 1]
            f2 = rho_t * u[i + 2]
            if jacobian:
                b_blocks[a, 1, 1] = rho_t
                b_blocks[a, 2, 2] = rho_t
        else:  # slide (or no friction available): Φ_T = r_T − R ŷ
            e1 = y1 / ny if ny > 0.0 else 0.0
            e2 = y2 / ny if ny > 0.0 else 0.0
            f1 = rt1 - radius * e1
            f2 = rt2 - radius * e2
            if jacobian:
                s = radius / ny if ny > 0.0 else 0.0  # R Γ = (R/‖y‖)(I − ŷŷᵀ)
                g11 = s * (1.0 - e1 * e1)
                g12 = -s * e1 * e2
                g22 = s * (1.0 - e2 * e2)
                a_blocks[a, 1, 1] = 1.0 - g11
                a_blocks[a, 1, 2] = -g12
                a_blocks[a, 2, 1] = -g12
                a_blocks[a, 2, 2] = 1.0 - g22
                b_blocks[a, 1, 1] = rho_t * g11
                b_blocks[a, 1, 2] = rho_t * g12
                b_blocks[a, 2, 1] = rho_t * g12
                b_blocks[a, 2, 2] = rho_t * g22
                if xn > 0.0:  # dR = μ (dr_N − ρ_N du_N)
                    a_blocks[a, 1, 0] = -m_a * e1
                    a_blocks[a, 2, 0] = -m_a * e2
                    b_blocks[a, 1, 0] = m_a * rho_n * e1
                    b_blocks[a, 2, 0] = m_a * rho_n * e2
        phi[i] = fn
        phi[i + 1] = f1
        phi[i + 2] = f2
        merit += fn * fn + f1 * f1 + f2 * f2
    return 0.5 * merit


@njit(cache=True)
def _fill_jacobian(w_indptr, w_indices, w_data, j_indptr, j_indices, a_blocks, b_blocks, delta, scratch, j_data):
    """j_data (nnz of the pattern) ← the values of ``A + B (W + δ I)`` on the fixed CSR pattern
    (j_indptr, j_indices) of :func:`_jacobian_pattern`. scratch: (3, m) zeros, left zero.

    Row 3α + k of B W is Σ_l B_α[k, l] W[3α + l, :]: the three rows of W of contact α are
    scattered into scratch, gathered on the pattern's columns, then cleared (O(nnz) in all)."""
    nc = a_blocks.shape[0]
    for a in range(nc):
        base = 3 * a
        for l in range(3):
            row = base + l
            for p in range(w_indptr[row], w_indptr[row + 1]):
                scratch[l, w_indices[p]] += w_data[p]
        for k in range(3):
            i = base + k
            b0 = b_blocks[a, k, 0]
            b1 = b_blocks[a, k, 1]
            b2 = b_blocks[a, k, 2]
            for p in range(j_indptr[i], j_indptr[i + 1]):
                c = j_indices[p]
                value = b0 * scratch[0, c] + b1 * scratch[1, c] + b2 * scratch[2, c]
                if base <= c < base + 3:
                    value += a_blocks[a, k, c - base] + delta * b_blocks[a, k, c - base]
                j_data[p] = value
        for l in range(3):
            row = base + l
            for p in range(w_indptr[row], w_indptr[row + 1]):
                scratch[l, w_indices[p]] = 0.0


# ----------------------------------------------------------------------------- helpers


def split_rho(blocks: np.ndarray) -> np.ndarray:
    """ρ (3·nc,) = per contact (1/W_NN, 1/λ_max(W_TT), 1/λ_max(W_TT)) from the diagonal blocks
    (nc, 3, 3) of W (units: impulse per velocity). A block without a positive value there takes
    1 / the mean positive diagonal of W (1 if none is positive)."""
    nc = blocks.shape[0]
    wnn, t11, t22 = blocks[:, 0, 0], blocks[:, 1, 1], blocks[:, 2, 2]
    t12 = 0.5 * (blocks[:, 1, 2] + blocks[:, 2, 1])
    largest = 0.5 * (t11 + t22) + np.sqrt(0.25 * (t11 - t22) ** 2 + t12**2)
    diagonal = np.concatenate([wnn, t11, t22])
    positive = diagonal[diagonal > 0.0]
    fallback = 1.0 / positive.mean() if positive.size else 1.0
    rho = np.empty((nc, 3))
    rho[:, 0] = np.where(wnn > 0.0, 1.0 / np.where(wnn > 0.0, wnn, 1.0), fallback)
    rho[:, 1] = np.where(largest > 0.0, 1.0 / np.where(largest > 0.0, largest, 1.0), fallback)
    rho[:, 2] = rho[:, 1]
    return rho.ravel()


def _jacobian_pattern(csr, nc):
    """CSR pattern (indptr, indices, int64, sorted) of ``A + B W`` for any block-diagonal A, B:
    row 3α + k holds the union of the columns of W's rows 3α, 3α+1, 3α+2 and the diagonal block."""
    m = 3 * nc
    ones = sp.bsr_matrix((np.ones((nc, 3, 3)), np.arange(nc), np.arange(nc + 1)), shape=(m, m)).tocsr()
    structure = sp.csr_matrix((np.ones(csr.nnz), csr.indices, csr.indptr), shape=(m, m))
    pattern = (ones @ structure + ones).tocsr()
    pattern.sort_indices()
    return pattern.indptr.astype(np.int64), pattern.indices.astype(np.int64)


def _newton_step(j_indptr, j_indices, j_data, rhs):
    """Solve J d = rhs with J in CSR (j_*): SuperLU factorizes the CSC view (that is Jᵀ) and solves
    the transposed system. Returns d, or None when the factor is singular or d is not finite."""
    m = rhs.shape[0]
    transposed = sp.csc_matrix((j_data, j_indices, j_indptr), shape=(m, m))
    try:
        d = spla.splu(transposed, permc_spec="MMD_AT_PLUS_A").solve(rhs, trans="T")
    except RuntimeError:  # "Factor is exactly singular"
        return None
    return d if np.all(np.isfinite(d)) else None


# ----------------------------------------------------------------------------- the solver


def solve_newton(
    csr: sp.csr_matrix,
    q: np.ndarray,
    mu: np.ndarray,
    r: np.ndarray,
    tol: float,
    max_iterations: int,
    warm_sweeps: int = 0,
) -> tuple[np.ndarray, int, float, int]:
    """Semi-smooth Newton (module docstring) on FC(W, q, μ) from r.

    csr: (m, m) W as SciPy CSR with sorted indices; q (m,); mu (nc,); r (m,) start reactions
    (in the cones); tol: on the normalized natural-map error; max_iterations: Newton steps (each
    one sparse LU); warm_sweeps: nsgs sweeps before the first step (module docstring).
    Returns (r, iterations, error, restarts): the best iterate met, the Newton steps taken, its
    normalized natural-map error and how many times the watchdog acted.

    The problem is positively homogeneous in (q, r): r solves FC(W, c q, μ) when r / c solves
    FC(W, q, μ), c > 0, and the normalized error is the same. So it is solved for q / max|q| and
    r / max|q|, and the merit ½‖Φ‖² neither underflows nor overflows whatever the units
    (q ~ 1e-160 did underflow).
    """
    scale = float(np.abs(q).max()) if q.size else 0.0  # max |q|: its square cannot underflow
    if not scale > 0.0:
        scale = 1.0
    r_scaled, iterations, error, restarts = _solve_unit(csr, q / scale, mu, r / scale, tol, max_iterations, warm_sweeps)
    return r_scaled * scale, iterations, error, restarts


def _keep_best(r, error, best_r, best_error):
    """The lower of ``error`` (of r (m,)) and ``best_error`` (of best_r (m,)); r is copied into
    best_r when it is the better iterate."""
    if error < best_error:
        best_r[:] = r
        return error
    return best_error


def _solve_unit(csr, q, mu, r, tol, max_iterations, warm_sweeps):
    """:func:`solve_newton` on the problem scaled to max|q| = 1 (or q = 0); r (m,) is overwritten."""
    m = q.shape[0]
    nc = m // 3
    w_indptr = csr.indptr.astype(np.int64)
    w_indices = csr.indices.astype(np.int64)
    w_data = csr.data
    blocks = diagonal_blocks(csr, nc)
    base_rho = split_rho(blocks)
    rho = base_rho.copy()
    diagonal = np.abs(csr.diagonal())
    w_bar = float(diagonal.mean()) if diagonal.size and diagonal.mean() > 0.0 else 1.0
    norm_q = float(np.linalg.norm(q))
    u = np.empty(m)

    if warm_sweeps > 0:
        nsgs_sweeps(Sweeping(w_indptr, w_indices, w_data, q, mu, blocks), r, tol, warm_sweeps, False)
    error = fill_velocity_error(w_indptr, w_indices, w_data, q, mu, r, u, False, norm_q)  # also u = W r + q
    best_r, best_error = r.copy(), error
    if error <= tol:
        return best_r, 0, best_error, 0

    j_indptr, j_indices = _jacobian_pattern(csr, nc)
    j_data = np.empty(j_indices.shape[0])
    scratch = np.zeros((3, m))
    a_blocks = np.zeros((nc, 3, 3))
    b_blocks = np.zeros((nc, 3, 3))
    phi = np.empty(m)
    trial_phi = np.empty(m)

    mark_error, mark_at = error, 0  # the watchdog's reference: last 10 % progress and when
    restarts = 0
    reference, weight = None, 0.0  # Zhang–Hager's C and Q (None: restart from ψ)
    for iteration in range(1, max_iterations + 1):
        merit = _alart_curnier(r, u, mu, rho, phi, a_blocks, b_blocks, True)
        if reference is None:
            reference, weight = merit, 1.0
        else:
            next_weight = NONMONOTONE_WEIGHT * weight + 1.0
            reference = (NONMONOTONE_WEIGHT * weight * reference + merit) / next_weight
            weight = next_weight

        # Newton direction on A + B (W + δ I), δ raised if the factor is singular
        delta = w_bar * min(REGULARIZATION_CAP, error)
        direction = None
        while direction is None:
            _fill_jacobian(w_indptr, w_indices, w_data, j_indptr, j_indices, a_blocks, b_blocks, delta, scratch, j_data)
            direction = _newton_step(j_indptr, j_indices, j_data, -phi)
            if direction is None:
                if delta >= w_bar:
                    break
                delta = min(w_bar, max(100.0 * delta, 1e-12 * w_bar))
        if direction is None:  # singular even at δ = w̄: steepest descent on ψ, d = −Jᵀ Φ
            jacobian = sp.csr_matrix((j_data, j_indices, j_indptr), shape=(m, m))
            direction = -(jacobian.T @ phi)

        # non-monotone Armijo search on ψ along r + t d (u + t W d); t = 2⁻³⁰ if none passes
        w_direction = csr @ direction
        step = 1.0
        for _ in range(MAX_HALVINGS):
            trial = _alart_curnier(
                r + step * direction, u + step * w_direction, mu, rho, trial_phi, a_blocks, b_blocks, False
            )
            if trial <= reference - ARMIJO_SLOPE * step * merit:
                break
            step *= 0.5
        r += step * direction
        error = fill_velocity_error(w_indptr, w_indices, w_data, q, mu, r, u, False, norm_q)

        best_error = _keep_best(r, error, best_r, best_error)
        if error <= tol:
            return best_r, iteration, best_error, restarts
        if error < WATCHDOG_PROGRESS * mark_error:
            mark_error, mark_at = error, iteration
        elif iteration - mark_at >= WATCHDOG_PATIENCE:
            # stalled: Gauss–Seidel sweeps from here (twice as many as last time), another ρ
            restarts += 1
            sweeps = WATCHDOG_SWEEPS * 2 ** min(restarts - 1, WATCHDOG_DOUBLINGS)
            nsgs_sweeps(Sweeping(w_indptr, w_indices, w_data, q, mu, blocks), r, tol, sweeps, False)
            rho = RHO_FACTORS[(restarts - 1) % len(RHO_FACTORS)] * base_rho
            error = fill_velocity_error(w_indptr, w_indices, w_data, q, mu, r, u, False, norm_q)
            best_error = _keep_best(r, error, best_r, best_error)
            if error <= tol:  # as when it was kept: best_error > tol until now, so this error is the best
                return best_r, iteration, best_error, restarts
            mark_error, mark_at = error, iteration
            reference = None
    return best_r, max_iterations, best_error, restarts
