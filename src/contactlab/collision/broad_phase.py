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

Between two sets of mesh elements (cloth self-contact: vertices and triangles, edges and
edges), ``elements_between`` gives the pairs whose boxes overlap and that share no corner.
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
def element_boxes(
    position: np.ndarray, grow: np.ndarray, corners: np.ndarray, lower: np.ndarray, upper: np.ndarray
) -> None:
    """Write into ``lower``, ``upper`` (K, 3) [m] the boxes of the elements ``corners`` (K, k)
    int (vertices: k = 1, edges 2, triangles 3) about their particles' ``position`` (P, 3) [m],
    grown by the largest ``grow`` (P,) [m] of their corners."""
    for e in range(corners.shape[0]):
        g = 0.0
        for m in range(corners.shape[1]):
            g = max(g, grow[corners[e, m]])
        for d in range(3):
            low = high = position[corners[e, 0], d]
            for m in range(1, corners.shape[1]):
                low = min(low, position[corners[e, m], d])
                high = max(high, position[corners[e, m], d])
            lower[e, d] = low - g
            upper[e, d] = high + g


ELEMENT_GRID_CELLS = 8  # elements_between's grid: at most 8 cells per box of set B (+ 64)


@njit(cache=True)
def elements_between(
    position: np.ndarray, grow: np.ndarray, corners_a: np.ndarray, corners_b: np.ndarray, same: bool
) -> np.ndarray:
    """Pairs (i, j) (K, 2) int64, sorted, of an element i of set A and an element j of set B
    that have no corner in common and whose boxes overlap; ``same``: A is B (``corners_b`` is
    ``corners_a``), and only i < j is given.

    An element is a few particles, its corners: ``corners_a`` (NA, ka) and ``corners_b``
    (NB, kb) int index ``position`` (P, 3) [m] (a vertex: k = 1, an edge 2, a triangle 3). Its
    box bounds its corners, grown by the largest ``grow`` (P,) [m] of them (``element_boxes``).
    Cloth self-contact asks for vertices against triangles and edges against edges, so that no
    triangle is tested against a triangle; the health check for edges against triangles.

    A dense grid over B alone: cells of edge the mean of B's largest box extents (larger where
    that would make more than ELEMENT_GRID_CELLS cells per box, + 64; one cell where the boxes
    are not finite), each box of B in the one cell of its lower corner, counting-sorted into
    the cells' order with its bounds beside it. A box of A looks up the cells that the lower
    corner of a box of B overlapping it can lie in: along each axis from its own lower corner
    less B's widest extent (less a rounding-proof 1e-9 of it) to its upper corner, so that
    every pair is met once, none within one set; where A is B, only the cells from that of its
    own lower corner on, in the grid's order (x, then y, then z): a pair with a box in an
    earlier cell is met from that box, one in the same cell from the lower of the two. The
    elements of B sharing a corner with the box of A, most of those overlapping it in a mesh
    (its neighbours), are marked before it looks and passed over as the boxes are compared.
    Cost: some ten to forty boxes of B compared per box of A on a cloth, more where one box of
    B is much wider than the rest along an axis."""
    na, nb = corners_a.shape[0], corners_b.shape[0]
    if na == 0 or nb == 0:
        return np.empty((0, 2), dtype=np.int64)
    lower_b, upper_b = np.empty((nb, 3)), np.empty((nb, 3))
    element_boxes(position, grow, corners_b, lower_b, upper_b)
    if same:
        lower_a, upper_a = lower_b, upper_b
    else:
        lower_a, upper_a = np.empty((na, 3)), np.empty((na, 3))
        element_boxes(position, grow, corners_a, lower_a, upper_a)
    cell, origin, dims, widest = _element_grid(lower_b, upper_b)
    # B's boxes by cell: start (cells + 1,) of each cell's run, its members and their boxes (lower
    # then upper corner) in that order, and each member's place in it
    home = np.empty(nb, dtype=np.int64)
    start = np.zeros(dims[0] * dims[1] * dims[2] + 1, dtype=np.int64)
    for j in range(nb):
        x = _axis_cell(lower_b[j, 0], origin[0], cell, dims[0])
        y = _axis_cell(lower_b[j, 1], origin[1], cell, dims[1])
        z = _axis_cell(lower_b[j, 2], origin[2], cell, dims[2])
        home[j] = (x * dims[1] + y) * dims[2] + z
        start[home[j] + 1] += 1
    for c in range(start.shape[0] - 1):
        start[c + 1] += start[c]
    place, members, boxes = np.empty(nb, dtype=np.int64), np.empty(nb, dtype=np.int64), np.empty((nb, 6))
    fill = start[:-1].copy()
    for j in range(nb):
        place[j] = fill[home[j]]
        members[place[j]] = j
        for d in range(3):
            boxes[place[j], d], boxes[place[j], 3 + d] = lower_b[j, d], upper_b[j, d]
        fill[home[j]] += 1
    around, incident = _incident(corners_b, place, position.shape[0])
    mark = np.full(nb, -1, dtype=np.int64)  # mark[k] = i: B's k-th box in the grid shares a corner with i
    near = np.empty(nb, dtype=np.int64)  # the grid places of the boxes meeting i
    low, high = np.empty(3, dtype=np.int64), np.empty(3, dtype=np.int64)
    pairs = np.empty((max(16, na + nb), 2), dtype=np.int64)
    found = 0
    for i in range(na):
        for m in range(corners_a.shape[1]):
            p = corners_a[i, m]
            for q in range(around[p], around[p + 1]):
                mark[incident[q]] = i
        for d in range(3):
            reach = lower_a[i, d] - widest[d]
            low[d] = _axis_cell(reach - 1e-9 * (abs(reach) + widest[d]), origin[d], cell, dims[d])
            high[d] = _axis_cell(upper_a[i, d], origin[d], cell, dims[d])
        own = np.int64(-1)  # where A is B: the cell of i's lower corner, from which it looks on
        if same:
            x = _axis_cell(lower_a[i, 0], origin[0], cell, dims[0])
            y = _axis_cell(lower_a[i, 1], origin[1], cell, dims[1])
            z = _axis_cell(lower_a[i, 2], origin[2], cell, dims[2])
            own, low[0] = (x * dims[1] + y) * dims[2] + z, x
        l0, l1, l2 = lower_a[i, 0], lower_a[i, 1], lower_a[i, 2]
        u0, u1, u2 = upper_a[i, 0], upper_a[i, 1], upper_a[i, 2]
        n = 0
        for x in range(low[0], high[0] + 1):
            for y in range(low[1], high[1] + 1):
                row = (x * dims[1] + y) * dims[2]
                first, last = max(row + low[2], own), row + high[2]  # where A is B: no cell before i's own
                for k in range(start[first], start[max(first, last + 1)]):
                    near[n] = k  # kept where it meets i: no branch (as likely as not on a cloth)
                    n += (
                        (boxes[k, 0] <= u0)
                        & (l0 <= boxes[k, 3])
                        & (boxes[k, 1] <= u1)
                        & (l1 <= boxes[k, 4])
                        & (boxes[k, 2] <= u2)
                        & (l2 <= boxes[k, 5])
                        & (mark[k] != i)
                    )
        if found + n > pairs.shape[0]:
            pairs = _grown(pairs, found + n)
        for m in range(n):
            j = members[near[m]]
            if same and j < i and home[j] == own:
                continue  # in i's own cell: met from j too, which reports it
            pairs[found, 0], pairs[found, 1] = (min(i, j), max(i, j)) if same else (i, j)
            found += 1
    return _sorted_pairs(pairs[:found], na)


@njit(cache=True)
def _grown(pairs: np.ndarray, needed: int) -> np.ndarray:
    """A copy of ``pairs`` (K, 2) int64 with room for ``needed`` rows at least, twice K or more."""
    grown = np.empty((max(2 * pairs.shape[0], needed), 2), dtype=np.int64)
    for row in range(pairs.shape[0]):  # not a slice assignment: see _append_pair
        grown[row, 0], grown[row, 1] = pairs[row, 0], pairs[row, 1]
    return grown


@njit(cache=True)
def _element_grid(lower: np.ndarray, upper: np.ndarray) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """``elements_between``'s grid over the boxes ``lower``, ``upper`` (N, 3) [m], N > 0: (the
    cell's edge [m], the origin (3,) [m] and the number of cells (3,) int64 along each axis, the
    boxes' widest extent (3,) [m] along each)."""
    n = lower.shape[0]
    widest, origin, top = np.zeros(3), np.full(3, np.inf), np.full(3, -np.inf)
    total = largest = 0.0
    for j in range(n):
        extent = 0.0
        for d in range(3):
            extent = max(extent, upper[j, d] - lower[j, d])
            widest[d] = max(widest[d], upper[j, d] - lower[j, d])
            origin[d] = min(origin[d], lower[j, d])
            top[d] = max(top[d], lower[j, d])
        total += extent
        largest = max(largest, extent)
    cell = total / n
    if not cell > 0.0:
        cell = max(1e-9, largest)
    dims = np.ones(3, dtype=np.int64)
    for _ in range(64):  # cells of twice the edge until few enough; 64 times: bounds not finite
        count = 1.0
        for d in range(3):
            count *= np.floor((top[d] - origin[d]) / cell) + 1.0
        if count <= ELEMENT_GRID_CELLS * n + 64:
            for d in range(3):
                dims[d] = np.int64((top[d] - origin[d]) / cell) + 1
            break
        cell *= 2.0
    return cell, origin, dims, widest


@njit(cache=True, inline="always")
def _axis_cell(x: float, origin: float, cell: float, dims: int) -> int:
    """The grid cell (0 … dims − 1) of coordinate x [m] along one axis: clamped at both ends, 0
    for NaN; never decreasing as x grows."""
    t = (x - origin) / cell
    if not t > 0.0:
        return 0
    if t >= dims - 1:
        return dims - 1
    return np.int64(t)


@njit(cache=True)
def _incident(corners: np.ndarray, place: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray]:
    """The elements ``corners`` (N, k) around each of ``count`` particles, by their ``place``
    (N,): (start (count + 1,), places) int64, particle p's in places[start[p]:start[p + 1]]."""
    start = np.zeros(count + 1, dtype=np.int64)
    for j in range(corners.shape[0]):
        for m in range(corners.shape[1]):
            start[corners[j, m] + 1] += 1
    for p in range(count):
        start[p + 1] += start[p]
    fill = start[:-1].copy()
    places = np.empty(start[count], dtype=np.int64)
    for j in range(corners.shape[0]):
        for m in range(corners.shape[1]):
            places[fill[corners[j, m]]] = place[j]
            fill[corners[j, m]] += 1
    return start, places


@njit(cache=True)
def _sorted_pairs(pairs: np.ndarray, count: int) -> np.ndarray:
    """``pairs`` (K, 2) int64, their first entries in 0 … count − 1, sorted by (first, second): a
    counting sort by the first, then an insertion sort of each first's few seconds."""
    start = np.zeros(count + 1, dtype=np.int64)
    for k in range(pairs.shape[0]):
        start[pairs[k, 0] + 1] += 1
    for i in range(count):
        start[i + 1] += start[i]
    out = np.empty_like(pairs)
    fill = start[:-1].copy()
    for k in range(pairs.shape[0]):
        i, j = pairs[k, 0], pairs[k, 1]
        b = fill[i]
        out[b, 0] = i
        while b > start[i] and out[b - 1, 1] > j:
            out[b, 1] = out[b - 1, 1]
            b -= 1
        out[b, 1] = j
        fill[i] += 1
    return out


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
