"""Broad phase: which axis-aligned bounding boxes overlap (compiled).

Three algorithms, one answer (``overlapping_pairs`` picks):

* sweep and prune along x: sort by lower x bound and sweep. O(n log n + k) when the boxes
  are spread out along x, but a dense pile stacks many boxes over the same x interval and
  the sweep then tests O(n²) pairs;
* a neighbour-cell grid (``neighbour_cell_pairs``), for many boxes of similar size packed in
  a compact region (a pile): cells as large as the largest box along each axis, each box in
  the one cell of its lower corner, a box tested against the boxes of its own and the 26
  neighbouring cells. About one box per cell in a pile, so some 10–20 tests per box;
* a uniform hash grid (``grid_pairs``), for everything else: cells as large as the typical
  box, each box entered in every cell it touches (a large box in many), pairs tested only
  within a cell. O(n + k) for piles of similar sizes, whatever their arrangement, but a
  dense pile puts 10 boxes or more in a cell and tests about 10 candidates per true pair.
"""

from __future__ import annotations

import numpy as np

from .. import shapes
from ..compiling import njit

GRID_FROM = 1000  # boxes: from this many on, the hash grid (equal speed at 1000, 7x faster at 10000)


NEIGHBOUR_GRID_SIZE_RATIO = 4.0  # neighbour cells only if no box is 4x the median box along an axis
NEIGHBOUR_GRID_CELLS = 8  # ... and the grid has at most 8 cells per box (+ 4096)


def overlapping_pairs(lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Pairs (i, j), i < j, whose boxes overlap, sorted; lower/upper (N, 3) [m] → int64 array (K, 2)."""
    if len(lower) < 2:  # one body, no pair (and nothing to compile for it)
        return np.zeros((0, 2), dtype=np.int64)
    return boxes_overlapping(lower, upper, True)


@njit(cache=True)
def boxes_overlapping(lower: np.ndarray, upper: np.ndarray, large: bool | None) -> np.ndarray:
    """``overlapping_pairs``, compiled (the stepping loops call it): the sweep below GRID_FROM
    boxes, else the neighbour-cell grid where the boxes suit it, else the hash grid. ``large``
    None says there are always fewer than GRID_FROM boxes: the grids are then not compiled
    (True: they may be needed)."""
    if lower.shape[0] < 2:
        return np.zeros((0, 2), dtype=np.int64)
    if large is None:  # a branch on a None argument: Numba drops the other before typing
        return sweep_and_prune(lower, upper)
    if lower.shape[0] < GRID_FROM:
        return sweep_and_prune(lower, upper)
    pairs, done = neighbour_cell_pairs(lower, upper)
    if done:
        return pairs  # already sorted by (i, j)
    pairs = grid_pairs(lower, upper)
    key = pairs[:, 0] * lower.shape[0] + pairs[:, 1]  # one sort key per pair (i < j < N)
    return pairs[np.argsort(key, kind="mergesort")]  # an order independent of the hashing


@njit(cache=True)
def _append_pair(pairs, found, a, b):
    """``pairs`` (capacity, 2) with (min(a, b), max(a, b)) written in row ``found``: the same
    array, or a copy of twice the capacity when it was full."""
    if found == pairs.shape[0]:
        grown = np.empty((2 * found, 2), dtype=np.int64)
        for row in range(found):  # not grown[:found] = pairs: a slice assignment compiles
            grown[row, 0] = pairs[row, 0]  # Numba's shape-mismatch message, seconds on a cold cache
            grown[row, 1] = pairs[row, 1]
        pairs = grown
    pairs[found, 0] = min(a, b)
    pairs[found, 1] = max(a, b)
    return pairs


@njit(cache=True)
def sweep_and_prune(lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Pairs (i, j), i < j, whose boxes overlap, by sweeping along x (see the module)."""
    count = lower.shape[0]
    order = np.argsort(lower[:, 0], kind="mergesort")
    pairs = np.empty((max(16, 4 * count), 2), dtype=np.int64)
    found = np.int64(0)  # not a literal 0: _append_pair would compile twice
    for position in range(count):
        i = order[position]
        upper_x = upper[i, 0]
        for next_position in range(position + 1, count):
            j = order[next_position]
            if lower[j, 0] > upper_x:
                break
            if (
                lower[j, 1] <= upper[i, 1]
                and lower[i, 1] <= upper[j, 1]
                and lower[j, 2] <= upper[i, 2]
                and lower[i, 2] <= upper[j, 2]
            ):
                pairs = _append_pair(pairs, found, i, j)
                found += 1
    return pairs[:found]


# the grids' one box test: an axis loop with early returns, a plain compiled call (LLVM inlines it). It times
# as the six-term test written out in each grid did (10 000 boxes, best of 30); inline="always" counted the
# references of lower and upper on every call (2x slower on a dense pile), returning the `and` chain 1.8x
@njit(cache=True)
def _boxes_overlap(lower: np.ndarray, upper: np.ndarray, i: int, j: int) -> bool:
    """Whether boxes i and j of ``lower``, ``upper`` (N, 3) [m] overlap (closed intervals; not
    where a bound is NaN)."""
    for d in range(3):
        if not lower[j, d] <= upper[i, d]:
            return False
        if not lower[i, d] <= upper[j, d]:
            return False
    return True


@njit(cache=True)
def neighbour_cell_pairs(lower: np.ndarray, upper: np.ndarray) -> tuple[np.ndarray, bool]:
    """(pairs (K, 2) sorted by (i, j), True) of the overlapping boxes by the neighbour-cell grid
    (see the module); (empty, False) when the boxes do not suit it — sizes too mixed, or spread
    over too many cells — and another algorithm must answer.

    Cell edges are the largest box extent along each axis, so two overlapping boxes have lower
    corners at most one cell apart on every axis: the 27 cells around a box's own hold every
    box it can overlap.
    """
    n = lower.shape[0]
    none = np.empty((0, 2), dtype=np.int64)
    cell = np.empty(3)
    origin = np.empty(3)
    dims = np.empty(3, dtype=np.int64)
    extent = np.empty(n)
    for d in range(3):
        for i in range(n):
            extent[i] = upper[i, d] - lower[i, d]
        cell[d] = extent.max()
        if not cell[d] > 0.0 or cell[d] > NEIGHBOUR_GRID_SIZE_RATIO * np.median(extent):
            return none, False
        origin[d] = lower[:, d].min()
        span = (lower[:, d].max() - origin[d]) / cell[d]
        if span > NEIGHBOUR_GRID_CELLS * n + 4096:
            return none, False
        dims[d] = np.int64(span) + 1
    if dims[0] * dims[1] * dims[2] > NEIGHBOUR_GRID_CELLS * n + 4096:
        return none, False
    # counting sort of the boxes by the cell of their lower corner
    coords = np.empty((n, 3), dtype=np.int64)
    cell_of = np.empty(n, dtype=np.int64)
    for i in range(n):
        for d in range(3):
            coords[i, d] = min(np.int64((lower[i, d] - origin[d]) / cell[d]), dims[d] - 1)
        cell_of[i] = (coords[i, 0] * dims[1] + coords[i, 1]) * dims[2] + coords[i, 2]
    start = np.zeros(dims[0] * dims[1] * dims[2] + 1, dtype=np.int64)
    for i in range(n):
        start[cell_of[i] + 1] += 1
    for c in range(start.shape[0] - 1):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    members = np.empty(n, dtype=np.int64)
    for i in range(n):
        members[fill[cell_of[i]]] = i
        fill[cell_of[i]] += 1
    pairs = np.empty((max(16, 4 * n), 2), dtype=np.int64)
    found = np.int64(0)  # not a literal 0: _append_pair would compile twice
    for i in range(n):
        first = found
        for x in range(max(coords[i, 0] - 1, 0), min(coords[i, 0] + 2, dims[0])):
            for y in range(max(coords[i, 1] - 1, 0), min(coords[i, 1] + 2, dims[1])):
                for z in range(max(coords[i, 2] - 1, 0), min(coords[i, 2] + 2, dims[2])):
                    c = (x * dims[1] + y) * dims[2] + z
                    for k in range(start[c], start[c + 1]):
                        j = members[k]
                        if j > i and _boxes_overlap(lower, upper, i, j):
                            pairs = _append_pair(pairs, found, i, j)
                            found += 1
        for a in range(first + 1, found):  # insertion sort of i's partners: pairs come out sorted
            j = pairs[a, 1]
            b = a
            while b > first and pairs[b - 1, 1] > j:
                pairs[b, 1] = pairs[b - 1, 1]
                b -= 1
            pairs[b, 1] = j
    return pairs[:found], True


@njit(cache=True)
def _grid_cells(lower: np.ndarray, upper: np.ndarray) -> tuple[float, np.ndarray, np.ndarray, int]:
    """The hash grid's cells of boxes (N, 3) [m]: cells of edge twice the median of the boxes'
    largest extents (so a typical box touches at most 2 cells per axis). Returns the cell's edge
    [m], the cell indices of each box's lower and upper corner (N, 3) int64 and the number of
    (box, cell) entries."""
    n = lower.shape[0]
    extent = np.empty(n)
    for i in range(n):
        extent[i] = max(upper[i, 0] - lower[i, 0], upper[i, 1] - lower[i, 1], upper[i, 2] - lower[i, 2])
    cell = 2.0 * np.median(extent)
    if not cell > 0.0:
        cell = max(1e-9, extent.max())
    low = np.floor(lower / cell).astype(np.int64)
    high = np.floor(upper / cell).astype(np.int64)
    count = 0
    for i in range(n):
        count += (high[i, 0] - low[i, 0] + 1) * (high[i, 1] - low[i, 1] + 1) * (high[i, 2] - low[i, 2] + 1)
    return cell, low, high, count


@njit(cache=True)
def grid_pairs(lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Pairs (i, j), i < j, whose boxes overlap, by a uniform hash grid (see the module).

    The cell edge is twice the median of the boxes' largest extents, so a typical box touches
    at most 2 cells per axis; a larger box is entered in every cell it touches. A pair is
    reported only from the cell holding the larger of its two lower corners, so once.
    """
    n = lower.shape[0]
    _, low, high, count = _grid_cells(lower, upper)
    keys = np.empty(count, dtype=np.int64)
    boxes = np.empty(count, dtype=np.int64)
    cells = np.empty((count, 3), dtype=np.int64)
    e = 0
    for i in range(n):
        for x in range(low[i, 0], high[i, 0] + 1):
            for y in range(low[i, 1], high[i, 1] + 1):
                for z in range(low[i, 2], high[i, 2] + 1):
                    keys[e] = (x * 73856093) ^ (y * 19349663) ^ (z * 83492791)
                    boxes[e] = i
                    cells[e, 0], cells[e, 1], cells[e, 2] = x, y, z
                    e += 1
    order = np.argsort(keys, kind="mergesort")
    pairs = np.empty((max(16, 4 * n), 2), dtype=np.int64)
    found = np.int64(0)  # not a literal 0: _append_pair would compile twice
    start = 0
    while start < count:
        stop = start + 1
        while stop < count and keys[order[stop]] == keys[order[start]]:
            stop += 1
        for p in range(start, stop):
            ep = order[p]
            a = boxes[ep]
            for q in range(p + 1, stop):
                eq = order[q]
                b = boxes[eq]
                if (
                    a == b
                    or cells[ep, 0] != cells[eq, 0]
                    or cells[ep, 1] != cells[eq, 1]
                    or cells[ep, 2] != cells[eq, 2]
                ):
                    continue  # the same box twice, or another cell with the same hash
                if not _boxes_overlap(lower, upper, a, b):
                    continue
                home = True  # the cell of the larger lower corner reports it
                for d in range(3):
                    if max(low[a, d], low[b, d]) != cells[ep, d]:
                        home = False
                if not home:
                    continue
                pairs = _append_pair(pairs, found, a, b)
                found += 1
        start = stop
    return pairs[:found]


@njit(cache=True)
def boxes_between(
    lower_a: np.ndarray, upper_a: np.ndarray, lower_b: np.ndarray, upper_b: np.ndarray, same: bool
) -> np.ndarray:
    """Pairs (i, j) (K, 2) int64 of a box i of set A (``lower_a``, ``upper_a`` (NA, 3) [m]) and a
    box j of set B (NB, 3) that overlap; ``same``: A is B, and only i < j is given. By a uniform
    hash grid over B alone, as ``grid_pairs`` builds its grid (cells twice the median of B's
    largest extents, a box entered in every cell it touches), but A's boxes only look B's up, so
    that no pair within one set is ever tested (cloth self-contact: vertices against triangles,
    not triangles against triangles), and the entries are put in order by a counting sort on
    their hash, not a sort. A pair is reported from the cell of the larger of its lower corners
    only, so once; in the order of A's boxes."""
    na, nb = lower_a.shape[0], lower_b.shape[0]
    pairs = np.empty((max(16, 4 * max(na, nb)), 2), dtype=np.int64)
    if na == 0 or nb == 0:
        return pairs[:0]
    cell, low, high, count = _grid_cells(lower_b, upper_b)
    slots = 1
    while slots < 2 * count:
        slots *= 2
    start = np.zeros(slots + 1, dtype=np.int64)
    for j in range(nb):
        for x in range(low[j, 0], high[j, 0] + 1):
            for y in range(low[j, 1], high[j, 1] + 1):
                for z in range(low[j, 2], high[j, 2] + 1):
                    start[_slot(x, y, z, slots) + 1] += 1
    for h in range(slots):
        start[h + 1] += start[h]
    fill = start[:-1].copy()
    members = np.empty(count, dtype=np.int64)
    cells = np.empty((count, 3), dtype=np.int64)
    for j in range(nb):
        for x in range(low[j, 0], high[j, 0] + 1):
            for y in range(low[j, 1], high[j, 1] + 1):
                for z in range(low[j, 2], high[j, 2] + 1):
                    h = _slot(x, y, z, slots)
                    members[fill[h]] = j
                    cells[fill[h], 0], cells[fill[h], 1], cells[fill[h], 2] = x, y, z
                    fill[h] += 1
    found = 0
    for i in range(na):
        lo0, hi0 = np.int64(np.floor(lower_a[i, 0] / cell)), np.int64(np.floor(upper_a[i, 0] / cell))
        lo1, hi1 = np.int64(np.floor(lower_a[i, 1] / cell)), np.int64(np.floor(upper_a[i, 1] / cell))
        lo2, hi2 = np.int64(np.floor(lower_a[i, 2] / cell)), np.int64(np.floor(upper_a[i, 2] / cell))
        for x in range(lo0, hi0 + 1):
            for y in range(lo1, hi1 + 1):
                for z in range(lo2, hi2 + 1):
                    h = _slot(x, y, z, slots)
                    for k in range(start[h], start[h + 1]):
                        j = members[k]
                        if (same and j <= i) or cells[k, 0] != x or cells[k, 1] != y or cells[k, 2] != z:
                            continue  # the pair's other order, or another cell of the same hash
                        if not (
                            lower_b[j, 0] <= upper_a[i, 0]
                            and lower_a[i, 0] <= upper_b[j, 0]
                            and lower_b[j, 1] <= upper_a[i, 1]
                            and lower_a[i, 1] <= upper_b[j, 1]
                            and lower_b[j, 2] <= upper_a[i, 2]
                            and lower_a[i, 2] <= upper_b[j, 2]
                        ):
                            continue
                        if max(lo0, low[j, 0]) != x or max(lo1, low[j, 1]) != y or max(lo2, low[j, 2]) != z:
                            continue  # reported from the cell of the larger lower corner
                        if found == pairs.shape[0]:
                            grown = np.empty((2 * found, 2), dtype=np.int64)
                            for row in range(found):
                                grown[row, 0], grown[row, 1] = pairs[row, 0], pairs[row, 1]
                            pairs = grown
                        pairs[found, 0], pairs[found, 1] = i, j
                        found += 1
    return pairs[:found]


@njit(cache=True, inline="always")
def _slot(x: int, y: int, z: int, slots: int) -> int:
    """The hash table slot of cell (x, y, z) among ``slots`` (a power of two)."""
    return ((x * 73856093) ^ (y * 19349663) ^ (z * 83492791)) & (slots - 1)


def brute_force_pairs(lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """The same pairs by testing every pair (NumPy, O(n²)): the reference for tests."""
    overlap = ((lower[:, None, :] <= upper[None, :, :]) & (lower[None, :, :] <= upper[:, None, :])).all(axis=2)
    i, j = np.nonzero(np.triu(overlap, k=1))
    return np.stack([i, j], axis=1).astype(np.int64)


@njit(cache=True)
def static_pairs(
    lower: np.ndarray, upper: np.ndarray, kinds: np.ndarray, params: np.ndarray, dynamic: int
) -> np.ndarray:
    """Candidate pairs (K, 2) of the dynamic colliders 0 … dynamic−1 with the static ones after
    them, obstacle by obstacle, each in collider order: against a plane (normal n, offset in
    ``params``) when the bounds' centre lies within their half-width along n of its front,
    against any other obstacle when the bounds overlap; meshes are left out (their pairs come
    from their own triangle grid). ``lower``, ``upper`` (N, 3) [m]; ``kinds`` (N,) int."""
    N = kinds.shape[0]
    out = np.empty(((N - dynamic) * dynamic, 2), dtype=np.int64)
    count = 0
    for g in range(dynamic, N):
        if kinds[g] == shapes.MESH:
            continue
        plane = kinds[g] == shapes.PLANE
        for i in range(dynamic):
            if plane:
                half_width = 0.0
                height = 0.0
                for k in range(3):
                    half_width += abs(upper[i, k] - lower[i, k]) * abs(params[g, k])
                    height += 0.5 * (upper[i, k] + lower[i, k]) * params[g, k]
                near = height - params[g, 3] <= half_width * 0.5
            else:
                near = True
                for k in range(3):
                    near = near and lower[i, k] <= upper[g, k] and lower[g, k] <= upper[i, k]
            if near:
                out[count, 0] = i
                out[count, 1] = g
                count += 1
    return out[:count]
