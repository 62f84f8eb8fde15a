"""Sparse Cholesky factors A = L Lᵀ of the symmetric positive definite systems of implicit cloth,
on 3 × 3 blocks.

Backward Euler's A = M − h D − h² K (dynamics.integrators.particle_system), and the constraint
system built on it (methods.constraints), is factored once a step and solved with a hundred
right-hand sides; its pattern is fixed by the springs, only the values change, and it is made
of 3 × 3 blocks (a particle's x, y, z; a body's linear or angular velocity). So the work is split
as CSparse splits it (Davis, *Direct Methods for Sparse Linear Systems*, 2006, ch. 4), on blocks:

* **analysis, once per pattern** (``analyse``, kept for the next matrix of the same pattern):
  a fill-reducing order of the blocks (SuperLU's minimum degree on the block pattern), the
  elimination tree, and from it the pattern of every block row of L (``_row_patterns``: the
  row subtrees, in the order the factorization visits them) and of every block column;
* **factorization, each matrix** (``cholesky_values``): the up-looking Cholesky on that fixed
  pattern — block row k of L from a triangular solve with the rows above, its diagonal block
  the 3 × 3 Cholesky factor of what is left (no pivoting: A is positive definite);
* **solves** (``cholesky_solve``): L y = P b, Lᵀ z = y, x = Pᵀ z, for one right-hand side or many.

One column index per nine entries, nine multiplications per index: on the 25 × 25
``cloth_drape`` (1 875 DOFs) it factors in about half of SciPy's SuperLU time and solves in
about half (on a 64 × 64 cloth: 0.37 against 0.68 s, and a twelfth). Where A's size is not a
multiple of 3 or a pivot block is not positive definite, ``cholesky`` returns None (the caller
falls back to SuperLU).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..compiling import njit

if TYPE_CHECKING:
    import scipy.sparse as sp

KEPT_ANALYSES = 8  # patterns whose analysis is kept (a run has one or two; a study a few scenes)


@dataclass(frozen=True)
class Analysis:
    """The symbolic block Cholesky of one nonzero pattern (N, N), N = 3 t, in CSparse's terms.

    order: (t,) int64, the original block at each position of C = P A Pᵀ;
    upper_start (t + 1,), upper_row (u,): block column k of C's upper triangle (block rows
    ≤ k, rising); upper_source (u, 3, 3): each entry's position in A's CSR ``data`` (−1: none);
    row_start (t + 1,), row_columns: the block columns of each block row of L left of its
    diagonal, in the order the factorization visits them;
    column_start (t + 1,), column_rows (b,): each block column of L, diagonal first, rows rising.
    """

    order: np.ndarray
    upper_start: np.ndarray
    upper_row: np.ndarray
    upper_source: np.ndarray
    row_start: np.ndarray
    row_columns: np.ndarray
    column_start: np.ndarray
    column_rows: np.ndarray


_analyses: dict[bytes, Analysis] = {}
_analyses_lock = threading.Lock()  # runs on several threads (a study's workers) share the kept analyses


def analyse(matrix: sp.csr_matrix) -> Analysis:
    """The ``Analysis`` of a CSR matrix's pattern (sorted indices, no duplicates, N = 3 t):
    computed on the first matrix of a pattern, then looked up (the last ``KEPT_ANALYSES`` kept)."""
    key = matrix.indptr.tobytes() + b"|" + matrix.indices.tobytes()
    with _analyses_lock:
        found = _analyses.get(key)
    if found is None:
        found = _analyse(matrix)  # outside the lock: two threads may both analyse, alike
        with _analyses_lock:
            if len(_analyses) >= KEPT_ANALYSES:
                _analyses.pop(next(iter(_analyses)))
            _analyses[key] = found
    return found


def _analyse(matrix: sp.csr_matrix) -> Analysis:
    import scipy.sparse as sp  # SciPy on first use: it is a tenth of `import contactlab`
    import scipy.sparse.linalg as spla

    t = matrix.shape[0] // 3
    indptr, indices = matrix.indptr.astype(np.int64), matrix.indices.astype(np.int64)
    block_start, block_column = _block_pattern(indptr, indices, t)
    # SuperLU's minimum degree order on the block pattern (A + Aᵀ), of the pattern alone: unit
    # entries on a diagonal that dominates them (no pivot moves); its column permutation sends
    # block i to position perm_c[i]
    counts = np.diff(block_start)
    pattern = sp.csc_matrix((np.ones(len(block_column)), block_column, block_start), shape=(t, t))
    dominant = pattern + sp.diags(np.full(t, float(counts.max(initial=0) + 1)), format="csc")
    perm = spla.splu(dominant, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
    order = np.argsort(perm.perm_c).astype(np.int64)
    upper_start, upper_row, upper_block = _permuted_upper(block_start, block_column, order)
    upper_source = _block_sources(indptr, indices, block_start, block_column, order, upper_block)
    parent = _elimination_tree(upper_start, upper_row)
    row_start, row_columns = _row_patterns(upper_start, upper_row, parent)
    column_start, column_rows = _column_patterns(row_start, row_columns)
    return Analysis(order, upper_start, upper_row, upper_source, row_start, row_columns, column_start, column_rows)


@njit(cache=True)
def _block_pattern(indptr, indices, t):
    """The block CSR pattern (start (t + 1,), column, columns rising) of a CSR pattern (N = 3 t):
    block (I, J) is there when any of its nine entries is."""
    start = np.zeros(t + 1, dtype=np.int64)
    column = np.empty(indices.shape[0], dtype=np.int64)
    seen = np.full(t, -1, dtype=np.int64)
    count = 0
    for block in range(t):
        first = count
        for row in range(3 * block, 3 * block + 3):
            for e in range(indptr[row], indptr[row + 1]):
                other = indices[e] // 3
                if seen[other] != block:
                    seen[other] = block
                    column[count] = other
                    count += 1
        column[first:count] = np.sort(column[first:count])
        start[block + 1] = count
    return start, column[:count].copy()


@njit(cache=True)
def _permuted_upper(start, column, order):
    """Block column k of C = P A Pᵀ's upper triangle for the symmetric block pattern (start,
    column) of A: block row order[k] of A is its block column order[k]. Returns (start (t + 1,),
    row, rising in each column, and the block of A each entry is, (original row, column))."""
    t = order.shape[0]
    position = np.empty(t, dtype=np.int64)
    for k in range(t):
        position[order[k]] = k
    upper_start = np.zeros(t + 1, dtype=np.int64)
    for k in range(t):
        for e in range(start[order[k]], start[order[k] + 1]):
            if position[column[e]] <= k:
                upper_start[k + 1] += 1
    for k in range(t):
        upper_start[k + 1] += upper_start[k]
    row = np.empty(upper_start[t], dtype=np.int64)
    block = np.empty((upper_start[t], 2), dtype=np.int64)
    for k in range(t):
        count = upper_start[k]
        for e in range(start[order[k]], start[order[k] + 1]):
            if position[column[e]] <= k:
                row[count] = position[column[e]]
                block[count, 0], block[count, 1] = column[e], order[k]  # A's block (row, column)
                count += 1
        rising = np.argsort(row[upper_start[k] : count], kind="mergesort")
        row[upper_start[k] : count] = row[upper_start[k] : count][rising]
        block[upper_start[k] : count] = block[upper_start[k] : count][rising]
    return upper_start, row, block


@njit(cache=True)
def _block_sources(indptr, indices, block_start, block_column, order, upper_block):
    """(u, 3, 3): for each entry of C's upper triangle, A's block (I, J) it is, the position in
    A's CSR data of each of its nine entries A[3 I + a, 3 J + b] (−1: not stored, 0)."""
    source = np.full((upper_block.shape[0], 3, 3), -1, dtype=np.int64)
    for u in range(upper_block.shape[0]):
        first, second = upper_block[u, 0], upper_block[u, 1]
        for a in range(3):
            row = 3 * first + a
            for e in range(indptr[row], indptr[row + 1]):
                if indices[e] // 3 == second:
                    source[u, a, indices[e] % 3] = e
    return source


@njit(cache=True)
def _elimination_tree(upper_start, upper_row):
    """The parent (t,) of each block column in the elimination tree of C (−1: a root), from its
    upper triangle's columns (cs_etree, path compression through ``ancestor``)."""
    t = upper_start.shape[0] - 1
    parent = np.full(t, -1, dtype=np.int64)
    ancestor = np.full(t, -1, dtype=np.int64)
    for k in range(t):
        for p in range(upper_start[k], upper_start[k + 1]):
            i = upper_row[p]
            while i != -1 and i < k:
                following = ancestor[i]
                ancestor[i] = k
                if following == -1:
                    parent[i] = k
                i = following
    return parent


@njit(cache=True)
def _row_patterns(upper_start, upper_row, parent):
    """The block columns of each block row k of L left of its diagonal: the nodes of the
    elimination tree reached from C's column k above the diagonal, walking up to k (cs_ereach),
    each path reversed so that a column comes after those it depends on. Returns (start (t + 1,),
    columns)."""
    t = upper_start.shape[0] - 1
    mark = np.full(t, -1, dtype=np.int64)
    stack = np.empty(t, dtype=np.int64)
    path = np.empty(t, dtype=np.int64)
    start = np.zeros(t + 1, dtype=np.int64)
    columns = np.empty(max(16, 4 * upper_row.shape[0]), dtype=np.int64)
    count = 0
    for k in range(t):
        mark[k] = k
        top = t
        for p in range(upper_start[k], upper_start[k + 1]):
            i = upper_row[p]
            length = 0
            while mark[i] != k:
                path[length] = i
                length += 1
                mark[i] = k
                i = parent[i]
            while length > 0:
                top -= 1
                length -= 1
                stack[top] = path[length]
        if count + t - top > columns.shape[0]:
            grown = np.empty(2 * (count + t - top), dtype=np.int64)
            for q in range(count):
                grown[q] = columns[q]
            columns = grown
        for q in range(top, t):
            columns[count] = stack[q]
            count += 1
        start[k + 1] = count
    return start, columns[:count].copy()


@njit(cache=True)
def _column_patterns(row_start, row_columns):
    """The column form of L's block pattern from its rows: (start (t + 1,), rows), each column's
    diagonal first and its rows rising — the order the up-looking factorization fills it in."""
    t = row_start.shape[0] - 1
    start = np.zeros(t + 1, dtype=np.int64)
    for k in range(t):
        start[k + 1] += 1  # the diagonal
        for q in range(row_start[k], row_start[k + 1]):
            start[row_columns[q] + 1] += 1
    for k in range(t):
        start[k + 1] += start[k]
    rows = np.empty(start[t], dtype=np.int64)
    fill = start[:-1].copy()
    for k in range(t):  # row k enters its columns after every row above it
        rows[fill[k]] = k
        fill[k] += 1
        for q in range(row_start[k], row_start[k + 1]):
            rows[fill[row_columns[q]]] = k
            fill[row_columns[q]] += 1
    return start, rows


@njit(cache=True)
def cholesky_values(
    data: np.ndarray,
    upper_start: np.ndarray,
    upper_row: np.ndarray,
    upper_source: np.ndarray,
    row_start: np.ndarray,
    row_columns: np.ndarray,
    column_start: np.ndarray,
    column_rows: np.ndarray,
) -> tuple[np.ndarray, bool]:
    """The blocks of L (b, 3, 3), in the column order of the analysis, for A's CSR values ``data``
    (the ``Analysis`` arrays after it), by the up-looking factorization (cs_chol on blocks): for
    each block column i of row k's pattern, in its order, L_ki = W_i L_iiᵀ⁻¹ with W_i the block
    C_ki less what earlier columns took, which L_ki then takes from the blocks below it; the
    diagonal block L_kk is the 3 × 3 Cholesky factor of C_kk − Σ L_ki L_kiᵀ (lower triangular).
    Returns (blocks, whether every diagonal block was positive definite: A positive definite)."""
    t = upper_start.shape[0] - 1
    values = np.zeros((column_start[t], 3, 3))
    fill = column_start[:-1].copy()
    work = np.zeros((t, 3, 3))  # W: block row k, by block column
    pivot = np.empty((3, 3))
    for k in range(t):
        for p in range(upper_start[k], upper_start[k + 1]):
            i = upper_row[p]  # C_ik (i ≤ k), so W_i = C_ki = C_ikᵀ
            for a in range(3):
                for b in range(3):
                    e = upper_source[p, a, b]
                    work[i, b, a] = data[e] if e >= 0 else 0.0
        pivot[:] = work[k]
        work[k] = 0.0
        for q in range(row_start[k], row_start[k + 1]):
            i = row_columns[q]
            d = column_start[i]
            entry = values[fill[i]]
            for r in range(3):  # entry = W_i L_iiᵀ⁻¹, row by row (L_ii lower triangular)
                x0 = work[i, r, 0] / values[d, 0, 0]
                x1 = (work[i, r, 1] - x0 * values[d, 1, 0]) / values[d, 1, 1]
                x2 = (work[i, r, 2] - x0 * values[d, 2, 0] - x1 * values[d, 2, 1]) / values[d, 2, 2]
                entry[r, 0], entry[r, 1], entry[r, 2] = x0, x1, x2
            work[i] = 0.0
            for p in range(d + 1, fill[i]):  # W_j −= L_ki L_jiᵀ for the blocks below i
                j = column_rows[p]
                below = values[p]
                for r in range(3):
                    for c in range(3):
                        work[j, r, c] -= (
                            entry[r, 0] * below[c, 0] + entry[r, 1] * below[c, 1] + entry[r, 2] * below[c, 2]
                        )
            for r in range(3):
                for c in range(3):
                    pivot[r, c] -= entry[r, 0] * entry[c, 0] + entry[r, 1] * entry[c, 1] + entry[r, 2] * entry[c, 2]
            fill[i] += 1
        diagonal = values[fill[k]]
        fill[k] += 1
        if not pivot[0, 0] > 0.0:
            return values, False
        diagonal[0, 0] = np.sqrt(pivot[0, 0])
        diagonal[1, 0] = pivot[1, 0] / diagonal[0, 0]
        diagonal[2, 0] = pivot[2, 0] / diagonal[0, 0]
        rest = pivot[1, 1] - diagonal[1, 0] * diagonal[1, 0]
        if not rest > 0.0:
            return values, False
        diagonal[1, 1] = np.sqrt(rest)
        diagonal[2, 1] = (pivot[2, 1] - diagonal[2, 0] * diagonal[1, 0]) / diagonal[1, 1]
        rest = pivot[2, 2] - diagonal[2, 0] * diagonal[2, 0] - diagonal[2, 1] * diagonal[2, 1]
        if not rest > 0.0:
            return values, False
        diagonal[2, 2] = np.sqrt(rest)
    return values, True


@njit(cache=True)
def cholesky_solve(
    order: np.ndarray, column_start: np.ndarray, column_rows: np.ndarray, values: np.ndarray, rhs: np.ndarray
) -> np.ndarray:
    """x (N, m) with A x = rhs (N, m) from A's block factor L (``cholesky_values``) and its
    analysis' ``order``, ``column_start``, ``column_rows``: L y = P b forward, Lᵀ z = y backward,
    x = Pᵀ z."""
    out = np.empty_like(rhs)
    y = np.empty((order.shape[0], 3))
    every = np.arange(order.shape[0])
    for m in range(rhs.shape[1]):
        _solve_on(order, column_start, column_rows, values, every, rhs, m, out, y)
    return out


@njit(cache=True)
def cholesky_solve_within(
    order: np.ndarray,
    column_start: np.ndarray,
    column_rows: np.ndarray,
    values: np.ndarray,
    reach: np.ndarray,
    rhs: np.ndarray,
) -> np.ndarray:
    """``cholesky_solve`` for a right-hand side (N, m) that is zero outside the blocks whose
    positions in the factor's order ``reach`` (``ancestors``) holds, x read only there: the
    triangular solves visit those positions alone (the rest of y stays 0, and Lᵀ z = y reads
    only ancestors). Returns x (N, m), right on the reach's blocks (the same values as
    ``cholesky_solve``'s there, up to the sign of a zero) and 0 elsewhere."""
    out = np.zeros_like(rhs)
    y = np.empty((order.shape[0], 3))
    for m in range(rhs.shape[1]):
        _solve_on(order, column_start, column_rows, values, reach, rhs, m, out, y)
    return out


@njit(cache=True)
def ancestors(order: np.ndarray, column_start: np.ndarray, column_rows: np.ndarray, blocks: np.ndarray) -> np.ndarray:
    """The positions (rising) in the factor's order of ``blocks`` (original block numbers, repeats
    allowed) and of all their ancestors in the elimination tree, whose parent of a column is its
    first row below the diagonal: where L y = P b can be nonzero when b is zero off ``blocks``,
    and all that Lᵀ z = y reads to give z on them."""
    t = order.shape[0]
    position = np.empty(t, dtype=np.int64)
    for k in range(t):
        position[order[k]] = k
    mark = np.zeros(t, dtype=np.bool_)
    for block in blocks:
        j = position[block]
        while j >= 0 and not mark[j]:
            mark[j] = True
            j = column_rows[column_start[j] + 1] if column_start[j + 1] - column_start[j] > 1 else -1
    return np.nonzero(mark)[0].astype(np.int64)


@njit(cache=True)
def _solve_on(order, column_start, column_rows, values, reach, rhs, m, out, y):
    """Column m of rhs (N, m) solved into out's column m, visiting the positions ``reach``
    (rising; all of them for a full solve), y (t, 3) the work array."""
    for k in reach:
        for a in range(3):
            y[k, a] = rhs[3 * order[k] + a, m]
    for j in reach:  # forward: y_j = L_jj⁻¹ y_j, then y_r −= L_rj y_j below
        d = values[column_start[j]]
        y0 = y[j, 0] / d[0, 0]
        y1 = (y[j, 1] - d[1, 0] * y0) / d[1, 1]
        y2 = (y[j, 2] - d[2, 0] * y0 - d[2, 1] * y1) / d[2, 2]
        y[j, 0], y[j, 1], y[j, 2] = y0, y1, y2
        for p in range(column_start[j] + 1, column_start[j + 1]):
            r = column_rows[p]
            for a in range(3):
                y[r, a] -= values[p, a, 0] * y0 + values[p, a, 1] * y1 + values[p, a, 2] * y2
    for q in range(reach.shape[0] - 1, -1, -1):  # backward: z_j = L_jjᵀ⁻¹ (y_j − Σ L_rjᵀ z_r)
        j = reach[q]
        s0, s1, s2 = y[j, 0], y[j, 1], y[j, 2]
        for p in range(column_start[j] + 1, column_start[j + 1]):
            r = column_rows[p]
            z0, z1, z2 = y[r, 0], y[r, 1], y[r, 2]
            s0 -= values[p, 0, 0] * z0 + values[p, 1, 0] * z1 + values[p, 2, 0] * z2
            s1 -= values[p, 0, 1] * z0 + values[p, 1, 1] * z1 + values[p, 2, 1] * z2
            s2 -= values[p, 0, 2] * z0 + values[p, 1, 2] * z1 + values[p, 2, 2] * z2
        d = values[column_start[j]]
        z2 = s2 / d[2, 2]
        z1 = (s1 - d[2, 1] * z2) / d[1, 1]
        z0 = (s0 - d[1, 0] * z1 - d[2, 0] * z2) / d[0, 0]
        y[j, 0], y[j, 1], y[j, 2] = z0, z1, z2
    for k in reach:
        for a in range(3):
            out[3 * order[k] + a, m] = y[k, a]


class CholeskyFactor:
    """A = L Lᵀ of a symmetric positive definite matrix (N, N), for repeated solves."""

    def __init__(self, analysis: Analysis, values: np.ndarray) -> None:
        self.analysis = analysis
        self.values = values

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """A⁻¹ rhs for rhs (N,) or (N, m)."""
        b = np.asarray(rhs, dtype=np.float64)
        a = self.analysis
        columns = np.ascontiguousarray(b.reshape(len(b), -1))
        return cholesky_solve(a.order, a.column_start, a.column_rows, self.values, columns).reshape(b.shape)


def cholesky(matrix: sp.spmatrix) -> CholeskyFactor | None:
    """The ``CholeskyFactor`` of a symmetric matrix (N, N); None where N is not a multiple of 3
    or the matrix is not positive definite. Its pattern's ``Analysis`` is computed once and kept."""
    import scipy.sparse as sp

    A = sp.csr_matrix(matrix)
    if A.shape[0] % 3 or A.shape[0] == 0:
        return None
    A.sum_duplicates()  # sorted indices, one entry each: the pattern's key
    a = analyse(A)
    values, positive = cholesky_values(
        np.ascontiguousarray(A.data, dtype=np.float64),
        a.upper_start,
        a.upper_row,
        a.upper_source,
        a.row_start,
        a.row_columns,
        a.column_start,
        a.column_rows,
    )
    return CholeskyFactor(a, values) if positive else None
