"""Compiled iterations for the LCP ``w = B λ − c ≥ 0, λ ≥ 0, λᵀ w = 0`` (SPEC C6–C9).

All loops over rows run inside Numba (``@njit(cache=True)``) on the CSR arrays of B, in one
kernel, :func:`projected_sweeps`, for the four methods:

* projected Gauss-Seidel (SPEC C7) with over-relaxation ω: the rows as one color;
* projected Jacobi (``jacobi``): every row from the previous iterate;
* multi-color ("red-black") Gauss-Seidel (SPEC C8): colors visited in order, the rows of one
  color updated in parallel (``prange``), which is race-free because same-colored rows are not
  coupled (see :mod:`contactlab.lcp.coloring`);
* block red-black Gauss-Seidel (``redblack_blocks``): the rows cut into blocks, red and black
  alternately, that couple only with the blocks beside them (``coloring.level_blocks``); the red
  blocks are swept side by side (``prange``), each in its rows' order as in ``pgs``, then the
  black ones. Two colors a sweep instead of a dozen or more, and the serial order within a block.

Each color is a run of blocks and each block a run of rows (one row a block for ``redblack``,
one block of every row for ``pgs`` and ``jacobi``): one loop serves all four.

One row update is the exact solution of row i holding the others fixed, then the projection::

    λ_i ← max(0, λ_i − ω (B_i· λ − c_i) / B_ii)

Rows with ``B_ii <= 0`` are left at their start value (callers reject negative diagonals). The
convergence measure, computed after each sweep, is the natural-map residual
``‖λ − max(0, λ − w)‖₂ = ‖min(λ, w)‖₂`` (absolute, in the units of w).
"""

from __future__ import annotations

import math

import numpy as np
from numba import prange

from ..compiling import njit


@njit(cache=True)
def _residual_rows(indptr, indices, data, c, lam, w, start, stop):
    """Fill ``w = B λ − c`` on rows [start, stop) and return Σ (λ_i − max(0, λ_i − w_i))² over them."""
    total = 0.0
    for i in range(start, stop):
        acc = -c[i]
        for k in range(indptr[i], indptr[i + 1]):
            acc += data[k] * lam[indices[k]]
        w[i] = acc
        r = lam[i] - max(0.0, lam[i] - acc)
        total += r * r
    return total


@njit(cache=True)
def lcp_residual(
    indptr: np.ndarray, indices: np.ndarray, data: np.ndarray, c: np.ndarray, lam: np.ndarray, w: np.ndarray
) -> float:
    """Fill ``w = B λ − c`` and return ``‖λ − max(0, λ − w)‖₂`` (sequential)."""
    return math.sqrt(_residual_rows(indptr, indices, data, c, lam, w, 0, c.shape[0]))


RESIDUAL_CHUNKS = 8  # row blocks of the parallel residual (a few per thread, for balance)


@njit(cache=True, parallel=True)
def lcp_residual_parallel(
    indptr: np.ndarray, indices: np.ndarray, data: np.ndarray, c: np.ndarray, lam: np.ndarray, w: np.ndarray
) -> float:
    """Same as :func:`lcp_residual`, in ``RESIDUAL_CHUNKS`` blocks of rows in parallel."""
    n = c.shape[0]
    partial = np.zeros(RESIDUAL_CHUNKS)
    for chunk in prange(RESIDUAL_CHUNKS):
        partial[chunk] = _residual_rows(
            indptr, indices, data, c, lam, w, chunk * n // RESIDUAL_CHUNKS, (chunk + 1) * n // RESIDUAL_CHUNKS
        )
    total = 0.0  # in index order: NumPy's sum (run as Python) would pair them up
    for chunk in range(RESIDUAL_CHUNKS):
        total += partial[chunk]
    return math.sqrt(total)


@njit(cache=True, inline="always")
def _relax_row(indptr, indices, data, diag, c, lam, source, omega, i):
    """One projected update of row i, λ_i ← max(0, λ_i − ω (B_i· s − c_i) / B_ii), with s the
    ``source`` iterate: λ itself (Gauss-Seidel: the rows updated so far count) or the last
    sweep's (Jacobi). Rows with B_ii ≤ 0 are left alone. Inlined: as a call inside ``prange``
    the colored sweep ran 1.4× slower than the sequential one on one thread."""
    d = diag[i]
    if d > 0.0:
        acc = -c[i]
        for k in range(indptr[i], indptr[i + 1]):
            acc += data[k] * source[indices[k]]
        value = lam[i] - omega * acc / d
        lam[i] = value if value > 0.0 else 0.0


@njit(cache=True, parallel=True)
def projected_sweeps(
    indptr: np.ndarray,
    indices: np.ndarray,
    data: np.ndarray,
    diag: np.ndarray,
    c: np.ndarray,
    lam: np.ndarray,
    omega: float,
    tol: float,
    max_iterations: int,
    groups: tuple[np.ndarray, np.ndarray],
    min_parallel: int,
    jacobi: bool,
) -> tuple[int, float]:
    """Projected Gauss-Seidel or Jacobi sweeps on λ (n,), updated in place, until the residual is
    ``<= tol`` or ``max_iterations`` sweeps. Returns ``(sweeps, residual)``.

    ``groups`` = (color_start (ncolors + 1,), block_start (nblocks + 1,)): color k is blocks
    ``color_start[k]:color_start[k + 1]``, visited in color order, and block b rows
    ``block_start[b]:block_start[b + 1]``, swept in order. One color of one block is projected
    Gauss-Seidel (SPEC C7); several colors whose blocks do not couple with each other (numbered
    so by :mod:`contactlab.lcp.coloring`), multi-color Gauss-Seidel (SPEC C8: blocks of one row)
    or block red-black Gauss-Seidel (two colors of blocks of many rows). The blocks of a color of
    at least ``min_parallel`` rows are swept in parallel (``prange``), and the residual too once
    n ≥ ``min_parallel`` (waking the thread pool costs more than a small group's work, and much
    more when the cores are busy). Blocks coupled within a color need ``min_parallel > n``, as do
    runs that must give the sequential residual to the last bit. ``jacobi``: every row from the
    last sweep's iterate (projected Jacobi). One kernel for all four, so the sweep and the
    stopping test are written once; its sequential path is no slower than the plain (not
    parallel=True) Gauss-Seidel kernel it replaced (measured on a 3000-row problem)."""
    color_start, block_start = groups
    n = c.shape[0]
    w = np.empty(n)
    ncolors = color_start.shape[0] - 1
    source = lam.copy() if jacobi else lam  # Gauss-Seidel reads λ itself, updated row by row
    parallel_residual = n >= min_parallel
    if parallel_residual:
        residual = lcp_residual_parallel(indptr, indices, data, c, lam, w)
    else:
        residual = lcp_residual(indptr, indices, data, c, lam, w)
    if residual <= tol:
        return 0, residual
    for sweep in range(1, max_iterations + 1):
        if jacobi:
            for i in range(n):  # a loop, not source[:] = lam: parallel=True would spread that on threads
                source[i] = lam[i]
        for color in range(ncolors):
            first = color_start[color]
            last = color_start[color + 1]
            if block_start[last] - block_start[first] >= min_parallel:
                for b in prange(first, last):
                    for i in range(block_start[b], block_start[b + 1]):
                        _relax_row(indptr, indices, data, diag, c, lam, source, omega, i)
            else:
                for b in range(first, last):
                    for i in range(block_start[b], block_start[b + 1]):
                        _relax_row(indptr, indices, data, diag, c, lam, source, omega, i)
        if parallel_residual:
            residual = lcp_residual_parallel(indptr, indices, data, c, lam, w)
        else:
            residual = lcp_residual(indptr, indices, data, c, lam, w)
        if residual <= tol:
            return sweep, residual
    return max_iterations, residual
