"""3D Coulomb friction problems in FCLIB local form (SPEC F4, F4a, F4b).

Problem ``FC(W, q, μ)``: for nc contacts, each with its local components ordered
[N, T1, T2] (m = 3·nc unknowns), find the reactions r (m,) and relative velocities u (m,) with::

    u = W r + q,     r^α ∈ K_μα = {‖r_T‖ ≤ μ_α r_N},     K*_μα ∋ û^α ⊥ r^α,
    û^α = u^α + [μ_α ‖u^α_T‖, 0, 0]            (De Saxcé's modified velocity)

(W: (m, m) Delassus operator, units of velocity per impulse; q: (m,) free relative velocity.)
Equivalently, per contact: ``0 ≤ u_N ⊥ r_N ≥ 0`` and, given r_N, the friction r_T minimizes the
tangential work ``½ r_Tᵀ W_TT r_T + b_Tᵀ r_T`` over the disk ``‖r_T‖ ≤ μ r_N`` (maximal
dissipation: a sliding contact's friction opposes its slip velocity, a sticking one has u_T = 0).

Solvers (all sweeps compiled with Numba, ``cache=True``, in :mod:`contactlab.lcp.friction_sweeps`):

* ``nsgs`` — non-smooth Gauss-Seidel, SPEC F4a: for each contact in turn, its normal component is
  solved exactly (others fixed) and projected on r_N ≥ 0, then right after its friction is solved
  exactly on the 3×3 diagonal block ``W_αα`` with the new r_N: the 2-D minimization over the disk
  (by the secular equation ``‖(W_TT + νI)⁻¹ b‖ = μ r_N``, ν ≥ 0, :mod:`contactlab.lcp.disk`) for
  ``friction_model="cone"``, or
  over the inscribed square ``|r_Ti| ≤ μ r_N / √2`` (corners on the circle, so it never allows more
  friction than the cone) for ``friction_model="pyramid"``, by projected coordinate steps.
* ``staggered`` — SPEC F4b: all normal components with the frictions fixed (projected
  Gauss-Seidel sweeps on the normal rows), then all frictions with the normals fixed (disk or box
  solves), and the pair of phases iterated.
* ``apgd`` — accelerated projected gradient (Nesterov's method with gradient restarts, as Mazhar,
  Heyn, Negrut and Tasora 2015 use for contact, and a function restart on the residual, see
  :func:`_apgd`) on De Saxcé's form of the problem:
  ``r ← P_K(y − (W y + q + [μ‖u_T‖, 0, 0]) / L)``, y extrapolated from the last two iterates, L ≥
  the largest eigenvalue of W (estimated by power iteration unless given). The projection is
  onto the whole cone at once, so no contact waits for another, and it needs W only as products
  W x, one per iteration: W may be a ``scipy.sparse.linalg.LinearOperator`` (for instance
  J A⁻¹ Jᵀ x through a factorization of A, never forming J A⁻¹ Jᵀ). Its fixed points are the
  Coulomb solutions (the De Saxcé term makes sliding contacts keep u_N = 0, not the μ‖u_T‖ of
  the convex relaxation); with the cone model only.
* ``newton`` — semi-smooth Newton on the Alart–Curnier function, sparse LU, non-monotone line
  search, proximal regularization and a watchdog: :mod:`contactlab.lcp.newton`. Cone model only.

Error (``FrictionResult.error``, the Siconos measure): the natural-map residual
``F^α(r) = r^α − P_Kμα(r^α − û^α)``, ``‖F(r)‖₂ / max(‖q‖, ‖r‖, ‖u‖)`` (1 replaces a zero
maximum). For ``friction_model="pyramid"`` the error is the same map with the cone replaced by the
split box conditions ``r_N − max(0, r_N − u_N)`` and ``r_T − clip(r_T − u_T, ±μ r_N/√2)``, since
the box model has different solutions than the cone one.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..errors import InputError
from ._checks import choice, finite_vector, positive_float, positive_int, square_csr
from .friction_sweeps import (
    Sweeping,
    apgd_step,
    diagonal_blocks,
    extrapolate,
    natural_map_norms,
    normalized_residual,
    nsgs_sweeps,
    project_cone,
    staggered_sweeps,
)
from .newton import solve_newton

FRICTION_METHODS = ("nsgs", "staggered", "apgd", "newton")
OPERATOR_METHODS = ("apgd",)  # those that need W only as products W x
FRICTION_MODELS = ("cone", "pyramid")


@dataclass
class FrictionResult:
    """Answer of :func:`solve_friction_contact`."""

    r: np.ndarray
    """(3·nc,) reactions [N, T1, T2] per contact (impulses, in the units of W's columns)."""
    u: np.ndarray
    """(3·nc,) relative velocities ``W r + q``."""
    iterations: int
    """sweeps (nsgs), normal/friction rounds (staggered), gradient steps (apgd) or Newton steps
    (newton; sweeps it ran besides are not counted) done."""
    converged: bool
    """True when ``error <= tol``."""
    error: float
    """normalized natural-map residual (module docstring), at ``r``."""
    method: str
    """``"nsgs"``, ``"staggered"``, ``"apgd"`` or ``"newton"``."""
    friction_model: str = "cone"
    """``"cone"`` or ``"pyramid"``."""
    message: str = ""
    """one sentence on how it ended."""


# ----------------------------------------------------------------------------- public API


def _check_problem(W, q, mu):
    """(W as CSR — or the LinearOperator itself —, q, mu (nc,)) checked; InputError otherwise."""
    csr = W if isinstance(W, spla.LinearOperator) else square_csr(W, "W")
    m = csr.shape[0]
    if csr.shape[1] != m:
        raise InputError("W", f"expected a square operator, got shape {csr.shape}.")
    if m % 3 != 0:
        raise InputError("W", f"expected a (3·nc, 3·nc) matrix for 3D contacts, got shape {csr.shape}.")
    nc = m // 3
    q = finite_vector(q, m, "q")
    if np.ndim(mu) == 0:
        mu = np.full(nc, float(mu))
    mu = finite_vector(mu, nc, "mu")
    if np.any(mu < 0.0):
        raise InputError("mu", "friction coefficients must be non-negative.")
    return csr, q, mu


def natural_map_error(
    W: sp.spmatrix | np.ndarray, q: np.ndarray, mu: np.ndarray, r: np.ndarray, normalization: str = "max"
) -> float:
    """Natural-map residual of the FCLIB local problem at r (FCLIB/Siconos measure).

    ``F^α(r) = r^α − P_Kμα(r^α − û^α)`` with ``u = W r + q`` and ``û^α = u^α + [μ_α‖u^α_T‖, 0, 0]``.
    Returns ``‖F(r)‖₂`` divided by: ``max(‖q‖, ‖r‖, ‖u‖)`` for ``normalization="max"`` (Siconos
    since 2019, the default; 1 replaces a zero maximum), ``‖q‖`` for ``"q"`` (Siconos 2018),
    ``1 + sqrt(‖q‖)`` for ``"fclib"`` (fclib_merit_local) or nothing for ``"none"``.
    W: (3·nc, 3·nc); q, r: (3·nc,); mu: (nc,) or a scalar.
    """
    csr, q, mu = _check_problem(W, q, mu)
    r = finite_vector(r, q.shape[0], "r")
    normalization = choice(normalization, ("max", "q", "fclib", "none"), "normalization")
    u = csr @ r + q
    absolute, norm_r, norm_u = natural_map_norms(mu, r, u, False)
    norm_q = float(np.linalg.norm(q))
    if normalization == "max":
        scale = max(norm_q, norm_r, norm_u)
        return absolute / scale if scale > 0 else absolute
    if normalization == "q":
        return absolute / norm_q if norm_q > 0 else absolute
    if normalization == "fclib":
        return absolute / (1.0 + np.sqrt(norm_q))
    return absolute


def largest_eigenvalue(
    product: Callable[[np.ndarray], np.ndarray],
    size: int,
    iterations: int = 30,
    rtol: float = 1e-3,
    start: np.ndarray | None = None,
) -> float:
    """The largest eigenvalue of a symmetric positive semidefinite operator given by ``product``
    (x (size,) → W x), by power iteration from ``start`` (or ones) until it changes by less than
    ``rtol``; at most ``iterations`` products. It approaches from below."""
    x = np.ones(size) if start is None or not np.any(start) else np.abs(start) + 1e-3 * np.abs(start).max()
    x /= np.linalg.norm(x)
    estimate = 0.0
    for _ in range(iterations):
        y = product(x)
        norm = float(np.linalg.norm(y))
        if norm == 0.0:
            return 0.0
        previous, estimate = estimate, float(x @ y)
        x = y / norm
        if abs(estimate - previous) <= rtol * estimate:
            break
    return max(estimate, norm)


LIPSCHITZ_SAFETY = 1.2  # L = 1.2 × the power iteration's estimate, which approaches from below
RESTART_RISE = 2.0  # apgd restarts its momentum when the error exceeds this × the phase's lowest


def _apgd(product, q, mu, r, tol, max_iterations, lipschitz):
    """Accelerated projected gradient on De Saxcé's form of FC(W, q, μ) (module docstring), from r
    (3·nc,) in the cone. W enters only through ``product`` (x → W x), once per iteration: W y
    follows from W r by linearity. Returns (best r, W times it, iterations, its normalized error).

    Momentum restarts (θ ← 1, no extrapolation), after O'Donoghue & Candès (2015), on either test:

    * gradient: ``g(y)ᵀ (r_new − r) > 0``, the step went uphill;
    * function: the normalized natural-map error rose above ``RESTART_RISE`` (2) × the lowest error
      met since the last restart. The De Saxcé problem has no objective to watch (the μ‖u_T‖ term
      is not a gradient), so the residual stands in for it; it is not monotone even without
      momentum, hence the factor 2 rather than "any increase" (which restarts at nearly every
      step and loses the acceleration: Capsules-i125 then stops at 3.5e-7 after 10 000 steps).
      Without this test apgd oscillates for ever between 4.3e-5 and about 5e-4 on Capsules-i100,
      and stalls at 3.9e-6 on Capsules-i101; with it both reach 1e-8 (docs/lcp.md).
    """
    norm_q = math.sqrt(float(q @ q))

    def error_of(r, Wr):
        return normalized_residual(mu, r, Wr + q, False, norm_q)

    Wr = product(r)
    best, best_W, best_error = r.copy(), Wr, error_of(r, Wr)
    if best_error <= tol or lipschitz <= 0.0:
        return best, best_W, 0, best_error
    step = 1.0 / lipschitz
    y, Wy, theta = r.copy(), Wr.copy(), 1.0
    phase_lowest = math.inf  # lowest error since the last restart
    for iteration in range(1, max_iterations + 1):
        new = np.empty_like(r)
        uphill = apgd_step(y, Wy, q, mu, step, r, new)  # new = P_K(y − step û(W y + q))
        W_new = product(new)
        error = error_of(new, W_new)
        if error < best_error:
            best, best_W, best_error = new, W_new, error
            if error <= tol:
                return best, best_W, iteration, best_error
        phase_lowest = min(phase_lowest, error)
        next_theta = 0.5 * theta * (math.sqrt(theta * theta + 4.0) - theta)
        beta = theta * (1.0 - theta) / (theta * theta + next_theta)
        if uphill > 0.0 or error > RESTART_RISE * phase_lowest:
            beta, next_theta = 0.0, 1.0  # restart the momentum
            phase_lowest = error
        y, Wy = extrapolate(new, r, beta), extrapolate(W_new, Wr, beta)
        r, Wr, theta = new, W_new, next_theta
    return best, best_W, max_iterations, best_error


def solve_friction_contact(
    W: sp.spmatrix | np.ndarray | spla.LinearOperator,
    q: np.ndarray,
    mu: np.ndarray,
    method: str = "nsgs",
    tol: float = 1e-6,
    max_iterations: int = 1000,
    r0: np.ndarray | None = None,
    friction_model: str = "cone",
    lipschitz: float | None = None,
    warm_sweeps: int = 0,
) -> FrictionResult:
    """Solve the 3D Coulomb friction problem ``u = W r + q``, ``r ∈ K_μ``, ``û ⊥ r`` (FCLIB local form).

    Parameters
    ----------
    W: (3·nc, 3·nc) SciPy sparse or dense Delassus matrix, per contact [N, T1, T2]; for ``apgd``
       also a ``scipy.sparse.linalg.LinearOperator`` (symmetric positive semidefinite).
    q: (3·nc,) free relative velocity.
    mu: (nc,) friction coefficients (or one scalar for all contacts), ≥ 0.
    method: ``"nsgs"`` (SPEC F4a), ``"staggered"`` (SPEC F4b), ``"apgd"`` (module docstring) or
       ``"newton"``: semi-smooth Newton on the Alart–Curnier function with a non-monotone line
       search and sparse LU (:mod:`contactlab.lcp.newton`), for problems the sweeps leave unsolved
       and for tight tolerances (every FCLIB file here to 1e-8 in at most a few dozen steps).
    tol: tolerance on the normalized natural-map error (module docstring).
    max_iterations: sweep limit (nsgs), normal/friction round limit (staggered), step limit (apgd)
       or Newton-step limit (newton; each step is one sparse LU of a matrix shaped like W).
    r0: (3·nc,) start reactions (projected on the cone); zero by default.
    friction_model: ``"cone"`` (the disk ‖r_T‖ ≤ μ r_N) or ``"pyramid"`` (the inscribed square
       |r_Ti| ≤ μ r_N / √2; not with ``apgd``).
    lipschitz: apgd's L, at least W's largest eigenvalue (its step is 1/L); by default 1.2 × a
       power iteration's estimate. 0 declares W = 0: r = 0 is returned, with its error.
    warm_sweeps: newton only: nsgs sweeps from r0 before the first Newton step (0 by default; see
       :mod:`contactlab.lcp.newton` for where they help and where they hurt).

    A solver that stops above tol returns ``converged=False`` with the error it reached (apgd and
    newton: the best iterate they met).
    Bad input raises :class:`contactlab.errors.InputError`.
    """
    method = choice(method, FRICTION_METHODS, "method")
    friction_model = choice(friction_model, FRICTION_MODELS, "friction_model")
    if method in ("apgd", "newton") and friction_model != "cone":
        raise InputError("friction_model", f"{method} solves the cone model; use nsgs or staggered for the pyramid.")
    operator = isinstance(W, spla.LinearOperator)
    if operator and method not in OPERATOR_METHODS:
        raise InputError(
            "W",
            f"{method} sweeps the rows of W, so it needs W as a matrix; "
            f"only {', '.join(OPERATOR_METHODS)} takes a LinearOperator.",
        )
    csr, q, mu = _check_problem(W, q, mu)
    tol = positive_float(tol, "tol")
    max_iterations = positive_int(max_iterations, "max_iterations")
    if isinstance(warm_sweeps, bool) or not isinstance(warm_sweeps, numbers.Integral) or warm_sweeps < 0:
        raise InputError("warm_sweeps", f"expected a non-negative integer, got {warm_sweeps!r}.")
    m = q.shape[0]
    nc = m // 3
    r = np.zeros(m) if r0 is None else project_cone(finite_vector(r0, m, "r0"), mu)
    pyramid = friction_model == "pyramid"
    if m == 0:
        iterations, error = 0, 0.0
    elif method == "apgd":
        product = csr.dot  # a sparse matrix's or a LinearOperator's W x
        if lipschitz is None:
            lipschitz = LIPSCHITZ_SAFETY * largest_eigenvalue(product, m, start=r)
        lipschitz = positive_float(lipschitz, "lipschitz", zero=True)
        if lipschitz == 0.0:  # W = 0 (say, only pinned points touch): reactions change nothing
            r[:] = 0.0
        r, Wr, iterations, error = _apgd(product, q, mu, r, tol, max_iterations, lipschitz)
    elif method == "newton":
        r, iterations, error, restarts = solve_newton(csr, q, mu, r, tol, max_iterations, int(warm_sweeps))
    else:
        blocks = diagonal_blocks(csr, nc)
        problem = Sweeping(csr.indptr.astype(np.int64), csr.indices.astype(np.int64), csr.data, q, mu, blocks)
        if method == "nsgs":
            iterations, error = nsgs_sweeps(problem, r, tol, max_iterations, pyramid)
        else:
            iterations, error = staggered_sweeps(problem, r, tol, max_iterations, pyramid, 25)
    u = (Wr if method == "apgd" and m else csr @ r) + q
    converged = bool(error <= tol)
    if converged:
        message = f"{method} reached the error {error:.3e} <= tol in {iterations} iterations."
    else:
        message = f"{method} stopped after {iterations} iterations at the error {error:.3e}, above tol = {tol:.1e}."
    if method == "newton" and m and restarts:
        message = message[:-1] + f" (the watchdog restarted it {restarts} times)."
    return FrictionResult(r, u, int(iterations), converged, float(error), method, friction_model, message)
