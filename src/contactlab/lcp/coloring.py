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
