"""``solve_lcp``: one entry point for the LCP of SPEC C6, ``w = B λ − c ≥ 0, λ ≥ 0, λᵀ w = 0``."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..errors import InputError
from . import pgs as _kernels
from ._checks import choice, finite_vector, positive_float, positive_int, square_csr
from .coloring import color_rows, level_blocks
from .lemke import lemke

if TYPE_CHECKING:
    import scipy.sparse as sp

LCP_METHODS = ("pgs", "redblack", "redblack_blocks", "jacobi", "lemke")

#: A color group of ``redblack`` with at least this many rows is updated in parallel (``prange``);
#: smaller groups run on one thread, where the thread-pool wake-up would cost more than the work.
REDBLACK_MIN_PARALLEL_ROWS = 128

#: ``redblack_blocks`` cuts n rows into 4 blocks per BLOCK_ROWS rows or part (at least 4: two
#: red, two black): a number fixed by n alone, so the answer is the same on any thread count.
BLOCK_ROWS = 16384


def block_count(n: int) -> int:
    """The blocks ``redblack_blocks`` cuts n rows into: 4 per BLOCK_ROWS rows or part."""
    return 4 * max(1, -(-n // BLOCK_ROWS))


@dataclass
class LCPResult:
    """Answer of :func:`solve_lcp`."""

    lam: np.ndarray
    """(n,) the multipliers λ ≥ 0 (for contacts: normal impulses or forces)."""
    w: np.ndarray
    """(n,) ``B λ − c`` at ``lam`` (for contacts: the constraint velocity / acceleration / gap)."""
    iterations: int
    """sweeps (pgs, redblack, jacobi) or pivots (lemke) done."""
    residual: float
    """``‖λ − max(0, λ − w)‖₂`` at ``lam``, absolute (units of w); 0 exactly at a solution."""
    converged: bool
    """True when ``residual <= tol`` (and, for lemke, the pivoting ended on a solution)."""
    method: str
    """the method used."""
    message: str = ""
    """one sentence on how it ended (why it did not converge, when it did not)."""
    colors: int = 0
    """number of colors used (redblack only, else 0)."""


def solve_lcp(
    B: sp.spmatrix | np.ndarray,
    c: np.ndarray,
    method: str = "pgs",
    tol: float = 1e-8,
    max_iterations: int = 1000,
    warm_start: np.ndarray | None = None,
    omega: float = 1.0,
) -> LCPResult:
    """Solve the LCP ``w = B λ − c ≥ 0, λ ≥ 0, λᵀ w = 0`` (SPEC C6).

    Parameters
    ----------
    B: (n, n) SciPy sparse matrix or dense array; for contacts ``B = J A⁻¹ Jᵀ`` (SPEC C6).
       ``pgs``, ``redblack`` and ``jacobi`` need a non-negative diagonal (rows with ``B_ii = 0``
       are not updated) and converge for symmetric positive (semi)definite B (jacobi only for
       diagonally dominant B); ``lemke`` accepts any B.
    c: (n,) right-hand side; for contacts ``c = d − J A⁻¹ b``.
    method: ``"pgs"`` (SPEC C7), ``"redblack"`` (SPEC C8: rows colored so that no two of a color
       couple, each color's rows updated in parallel), ``"redblack_blocks"`` (block red-black
       Gauss-Seidel: the rows cut into ``block_count(n)`` blocks, red and black alternately, of
       whole breadth-first levels of the coupling graph, ``coloring.level_blocks``; the red blocks
       swept side by side, each in its rows' order as pgs sweeps them, then the black), ``"jacobi"``
       or ``"lemke"`` (exact).
    tol: absolute tolerance on the residual ``‖λ − max(0, λ − w)‖₂`` (units of w).
    max_iterations: sweep limit (iterative methods) or pivot limit (lemke).
    warm_start: (n,) start λ for the iterative methods (negative entries are set to 0); lemke
       ignores it.
    omega: relaxation factor ω in (0, 2) for pgs, redblack and jacobi (1 = plain Gauss-Seidel).

    Returns an :class:`LCPResult`; a method that stops before ``tol`` reports ``converged=False``
    with the residual it reached (SPEC C9: Gauss-Seidel converges slowly with many constraints).
    Bad input raises :class:`contactlab.errors.InputError`.
    """
    method = choice(method, LCP_METHODS, "method")
    csr = square_csr(B, "B")
    n = csr.shape[0]
    c = finite_vector(c, n, "c")
    tol = positive_float(tol, "tol")
    max_iterations = positive_int(max_iterations, "max_iterations")
    omega = positive_float(omega, "omega")
    if omega >= 2.0:
        raise InputError("omega", f"expected a relaxation factor in (0, 2), got {omega!r}.")
    lam = np.zeros(n) if warm_start is None else np.maximum(finite_vector(warm_start, n, "warm_start"), 0.0)

    if method == "lemke":
        lam, iterations, status, message = lemke(csr.toarray(), -c, max_iterations)
        w = csr @ lam - c
        residual = float(np.linalg.norm(lam - np.maximum(0.0, lam - w)))
        converged = status == "solved" and residual <= tol
        if status == "solved" and not converged:
            message = (
                f"Lemke's pivoting ended on a solution but round-off leaves a residual {residual:.3e} "
                f"above tol = {tol:.1e}."
            )
        return LCPResult(lam, w, iterations, residual, converged, method, message)

    diag = csr.diagonal()
    if np.any(diag < 0.0):
        row = int(np.flatnonzero(diag < 0.0)[0])
        raise InputError(
            "B",
            f"{method} needs a non-negative diagonal, but B[{row}, {row}] = {diag[row]:.3g}; "
            "use method='lemke' for such matrices.",
        )
    indptr = csr.indptr.astype(np.int64)
    indices = csr.indices.astype(np.int64)
    data = csr.data
    ncolors = 0
    if n == 0:
        iterations, residual = 0, 0.0
    elif method in ("redblack", "redblack_blocks"):
        if method == "redblack":  # blocks of one row, colored
            blocks = np.arange(n, dtype=np.int64)
            colors = color_rows(csr)
        else:  # blocks of whole levels, red and black alternately
            blocks = level_blocks(csr, block_count(n))
            colors = blocks % 2
        ncolors = int(colors.max()) + 1
        # rows in order of color, then block, then their own: color_start indexes the blocks
        order = np.lexsort((blocks, colors)).astype(np.int64)
        first = np.flatnonzero(np.r_[True, blocks[order][1:] != blocks[order][:-1]])  # each block's first row
        block_start = np.append(first, n).astype(np.int64)
        color_start = np.searchsorted(colors[order][first], np.arange(ncolors + 1)).astype(np.int64)
        # the problem renumbered color by color (P B Pᵀ), so that each color's rows and their
        # λ lie together in memory and a thread reads its share front to back
        permuted = csr[order][:, order].tocsr()
        permuted.sort_indices()
        lam_permuted = np.ascontiguousarray(lam[order])
        iterations, residual = _kernels.projected_sweeps(
            permuted.indptr.astype(np.int64),
            permuted.indices.astype(np.int64),
            permuted.data,
            diag[order],
            np.ascontiguousarray(c[order]),
            lam_permuted,
            omega,
            tol,
            max_iterations,
            (color_start, block_start),
            REDBLACK_MIN_PARALLEL_ROWS,
            False,
        )
        lam[order] = lam_permuted
    else:
        # one color of one block of coupled rows, never split across threads: the sequential sweep
        one = (np.array([0, 1], dtype=np.int64), np.array([0, n], dtype=np.int64))
        iterations, residual = _kernels.projected_sweeps(
            indptr, indices, data, diag, c, lam, omega, tol, max_iterations, one, n + 1, method == "jacobi"
        )
    w = csr @ lam - c
    residual = float(np.linalg.norm(lam - np.maximum(0.0, lam - w)))
    converged = residual <= tol
    if converged:
        message = f"{method} reached the residual {residual:.3e} <= tol in {iterations} sweeps."
    else:
        message = (
            f"{method} stopped after {iterations} sweeps at the residual {residual:.3e}, above "
            f"tol = {tol:.1e} (slow convergence, SPEC C9, or an LCP this method cannot solve)."
        )
    return LCPResult(lam, w, int(iterations), residual, converged, method, message, ncolors)
