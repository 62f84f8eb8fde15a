"""Graph coloring of LCP rows for the red-black (multi-color) Gauss-Seidel of SPEC C8.

Two rows i ≠ j are *coupled* when ``B[i, j] != 0`` or ``B[j, i] != 0``: updating one changes the
equation of the other. A coloring where no two coupled rows share a color lets every row of one
color be updated at the same time (in parallel) from the same values of the other colors, and
the result is exactly what a sequential Gauss-Seidel sweep in color order would give.

The coloring is greedy (Welsh-Powell: rows visited by decreasing number of neighbours, each
taking the smallest color none of its already colored neighbours has), so it uses at most
``max degree + 1`` colors. For contact LCPs, ``B = J A⁻¹ Jᵀ`` couples two contacts exactly
when they share a degree of freedom (a body), so the rows of one color touch disjoint bodies.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.sparse as sp

from ..compiling import njit
from ..errors import InputError
from ._checks import square_csr


@njit(cache=True)
def _greedy_color(indptr, indices, order):
    """Colors (n,) int64 of the graph in CSR adjacency form, visiting the vertices in ``order``."""
    n = indptr.shape[0] - 1
    colors = np.full(n, -1, dtype=np.int64)
    # forbidden[k] == v means color k is used by a neighbour of the vertex v being colored
    forbidden = np.full(n + 1, -1, dtype=np.int64)
    for step in range(n):
        v = order[step]
        for k in range(indptr[v], indptr[v + 1]):
            u = indices[k]
            if u != v and colors[u] >= 0:
                forbidden[colors[u]] = v
        color = 0
        while forbidden[color] == v:
            color += 1
        colors[v] = color
    return colors


def coupling_graph(B: sp.spmatrix | np.ndarray) -> sp.csr_matrix:
    """The symmetric sparsity pattern of ``B`` without its diagonal: a CSR matrix (n, n) whose
    entry (i, j) is 1 when rows i and j are coupled (``B[i, j] != 0`` or ``B[j, i] != 0``)."""
    csr = square_csr(B, "B")
    pattern = csr.copy()
    pattern.data = (pattern.data != 0).astype(np.float64)
    pattern.eliminate_zeros()
    graph = (pattern + pattern.T).tocsr()
    graph.setdiag(0)
    graph.eliminate_zeros()
    graph.data[:] = 1.0
    graph.sort_indices()
    return graph


def _color_graph(graph: sp.csr_matrix) -> np.ndarray:
    n = graph.shape[0]
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    degree = np.diff(graph.indptr)
    order = np.argsort(-degree, kind="stable").astype(np.int64)
    return _greedy_color(graph.indptr.astype(np.int64), graph.indices.astype(np.int64), order)


def color_rows(B: sp.spmatrix | np.ndarray) -> np.ndarray:
    """Color the rows of the LCP matrix ``B`` (SciPy sparse or dense, (n, n)) for SPEC C8.

    Returns ``colors`` (n,) int64 in ``0 .. ncolors-1`` such that two rows with the same color
    are never coupled: ``B[i, j] == 0`` and ``B[j, i] == 0`` whenever ``colors[i] == colors[j]``
    and ``i != j``. Zero entries stored explicitly do not count as couplings.
    """
    return _color_graph(coupling_graph(B))


@njit(cache=True)
def _breadth_first(rows, columns, start, base, level, queue):
    """Levels base + distance from ``start`` of its connected component, written into ``level``
    (−1: not reached yet), the neighbours of i being the columns of row i and the rows of column
    i stored in a matrix (``rows`` = its CSR (indptr, indices), ``columns`` its transpose's: B's
    coupling graph without forming B + Bᵀ); ``queue`` receives the component's vertices in the
    order reached. Returns how many there are."""
    level[start] = base
    queue[0] = start
    head, tail = 0, 1
    while head < tail:
        v = queue[head]
        head += 1
        for indptr, indices in (rows, columns):
            for k in range(indptr[v], indptr[v + 1]):
                u = indices[k]
                if level[u] < 0:
                    level[u] = level[v] + 1
                    queue[tail] = u
                    tail += 1
    return tail


@njit(cache=True)
def _levels(rows, columns):
    """Breadth-first levels (n,) int64 of a matrix's coupling graph (``rows``, ``columns`` as
    ``_breadth_first`` takes them): each connected component from a vertex at its far end (the
    last reached from its lowest-numbered vertex: a long, narrow level structure), its levels
    after those of the components before it. Two coupled rows are on the same level or on
    neighbouring ones (a stored zero counts as a coupling here: blocks only stay further apart)."""
    n = rows[0].shape[0] - 1
    level = np.full(n, -1, dtype=np.int64)
    queue = np.empty(n, dtype=np.int64)
    base = 0
    for seed in range(n):
        if level[seed] >= 0:
            continue
        count = _breadth_first(rows, columns, seed, base, level, queue)
        far = queue[count - 1]
        for i in range(count):
            level[queue[i]] = -1
        count = _breadth_first(rows, columns, far, base, level, queue)
        base = level[queue[count - 1]] + 1
    return level


def level_blocks(B: sp.spmatrix | np.ndarray, count: int) -> np.ndarray:
    """Cut the rows of ``B`` (n, n) into at most ``count`` blocks of about 1 / count of its stored
    entries each (a sweep's work) for block red-black Gauss-Seidel (``solve_lcp``'s
    ``redblack_blocks``): blocks (n,) int64 numbered 0, 1, … in order, each a run of whole
    breadth-first levels of the coupling graph.

    A row is coupled only with rows of its own level and the levels beside it, so only with rows
    of its own block and of the blocks numbered just before and after it: the even-numbered
    ("red") blocks never couple with each other, nor the odd ("black") ones."""
    csr = square_csr(B, "B")
    n = csr.shape[0]
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    transpose = csr.T.tocsr()
    level = _levels(
        (csr.indptr.astype(np.int64), csr.indices.astype(np.int64)),
        (transpose.indptr.astype(np.int64), transpose.indices.astype(np.int64)),
    )
    work = np.bincount(level, weights=np.diff(csr.indptr) + 1.0)  # entries of each level's rows
    before = np.cumsum(work) - work  # the work on the levels before each level
    block = np.minimum((before * count / work.sum()).astype(np.int64), count - 1)  # by where the level starts
    # numbered by the blocks that hold a level, so neighbouring levels are in blocks one apart
    return np.unique(block, return_inverse=True)[1].astype(np.int64)[level]


def color_contacts(index_lists: Sequence[Sequence[int]], n_dofs: int | None = None) -> np.ndarray:
    """Color rows given, for each row, the degrees of freedom (or bodies) it touches.

    ``index_lists``: a sequence of n integer sequences (e.g. ``[(body_a, body_b), ...]`` for n
    contacts). Returns ``colors`` (n,) int64 such that two rows sharing any index have different
    colors. ``n_dofs`` (optional) is the number of distinct indices (max index + 1 by default).
    This is the coloring of ``S Sᵀ`` for the row/DOF incidence matrix ``S``, the sparsity
    pattern of ``B = J A⁻¹ Jᵀ`` when A is block diagonal per body.
    """
    rows, cols = [], []
    for row, dofs in enumerate(index_lists):
        try:
            dof_array = np.asarray(list(dofs), dtype=np.int64).ravel()
        except (TypeError, ValueError):
            raise InputError(f"index_lists[{row}]", "expected a sequence of non-negative integers.") from None
        if dof_array.size and dof_array.min() < 0:
            raise InputError(f"index_lists[{row}]", "expected non-negative integers, found a negative index.")
        rows.append(np.full(dof_array.size, row, dtype=np.int64))
        cols.append(dof_array)
    n = len(rows)
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    rows = np.concatenate(rows)
    cols = np.concatenate(cols)
    width = int(cols.max()) + 1 if cols.size else 0
    if n_dofs is not None:
        if n_dofs < width:
            raise InputError("n_dofs", f"an index list holds index {width - 1}, not below n_dofs = {n_dofs}.")
        width = int(n_dofs)
    incidence = sp.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(n, width))
    return _color_graph(coupling_graph(incidence @ incidence.T))


def coloring_is_valid(B: sp.spmatrix | np.ndarray, colors: np.ndarray) -> bool:
    """True when no two distinct rows with the same color are coupled in ``B``."""
    graph = coupling_graph(B).tocoo()
    colors = np.asarray(colors)
    if colors.shape != (graph.shape[0],):
        return False
    return not np.any(colors[graph.row] == colors[graph.col])
