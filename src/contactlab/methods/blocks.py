"""Block Gauss-Seidel per contact manifold (issue 38, item 2): the contacts between one pair of
bodies (a box's corners on the floor, or on the box below) solved together, their normal
impulses as one small LCP solved exactly, instead of corner after corner.

Why: Gauss-Seidel trades a box's weight between its corners a little each sweep (each corner
sees the others' last impulses); solving a manifold's normals at once settles the split in
one update, as Box2D v2's two-point block solver does in 2D. In 3D a box's four coplanar corners
on a face give a singular 4 × 4 block (three degrees of freedom: the normal velocity and two
tilts); the block is solved with a regularization of 1e-9 of its diagonal, which picks the split
nearest the even one.

Each sweep takes the blocks in the sweeps' order (``sequential.solve_order``, a block where its
highest contact falls) and, for each block: the exact normal LCP of its ≤ BLOCK contacts given
every other contact's impulse (``block_normals``), then ``sequential.sweep_contacts`` over its
contacts — Coulomb friction after the new normals, and the normals' own updates, which the exact
answer leaves at zero but for what friction changed.
"""

from __future__ import annotations

import numpy as np

from ..compiling import njit
from .jacobian_rows import ContactRows, apply_impulse, apply_impulses, body_coupling, contact_velocity
from .sequential import largest_row_change, stable_buckets, sweep_contacts

BLOCK = 4  # contacts solved together at most: a box face's corners (2⁴ active sets to try)
REGULARIZATION = 1e-9  # of the block's mean diagonal, added to it: a flat face's block is singular


@njit(cache=True)
def solve_in_blocks(
    rows: ContactRows,
    friction: np.ndarray,
    target: np.ndarray,
    u: np.ndarray,
    until: tuple[int, float],
    initial_impulses: np.ndarray,
    order: np.ndarray,
) -> tuple[np.ndarray, int, float]:
    """``sequential.solve_sequential_impulses`` (serial; ``order`` (C,) the sweeps' order) with each
    manifold's normals solved as one block (``manifold_blocks``, ``block_normals``): u (N,)
    changes in place, from the warm start ``initial_impulses`` (C, 3) [N s]; ``until`` = (at most
    this many sweeps, the tolerance [m/s] on a sweep's net change of any contact's velocity).
    Returns (impulses (C, 3) [N s], sweeps, the last sweep's change [m/s])."""
    iterations, tolerance = until
    impulses = initial_impulses.copy()
    apply_impulses(rows, impulses, u)
    members, starts = manifold_blocks(rows, order)
    couplings = block_couplings(rows, members, starts)
    before = np.empty_like(u)
    scratch = (np.empty((BLOCK, BLOCK)), np.empty(BLOCK), np.empty(BLOCK), np.empty(BLOCK), np.empty(BLOCK, np.int64))
    sweeps, change = 0, 0.0
    for sweep in range(iterations):
        sweeps = sweep + 1
        for i in range(u.shape[0]):
            before[i] = u[i]
        for k in range(starts.shape[0] - 1):
            block = members[starts[k] :]
            n = starts[k + 1] - starts[k]
            if n > 1:
                block_normals(block, n, couplings[k], rows, target, impulses, u, scratch)
            sweep_contacts(block, n, target, impulses, rows, friction, u)
        change = largest_row_change(rows, u, before, tolerance if sweeps < iterations else np.inf)
        if change <= tolerance:
            break
    return impulses, sweeps, change


@njit(cache=True)
def manifold_blocks(rows: ContactRows, order: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The contacts grouped by the pair of bodies they join (every static side one and the same;
    a contact with a particle alone), cut into blocks of at most BLOCK in ``order``, the blocks
    in the order of their first contact in ``order``: (members (C,), starts (K + 1,)), block k
    ``members[starts[k]:starts[k + 1]]``."""
    C = order.shape[0]
    B = rows.body_inverse_mass.shape[0]
    rank = np.empty(C, dtype=np.int64)
    for i in range(C):
        rank[order[i]] = i
    key = np.empty(C, dtype=np.int64)  # the pair, then the rank within it
    for c in range(C):
        if rows.particle[c, 0, 0] >= 0 or rows.particle[c, 1, 0] >= 0:
            pair = (B + 1) * (B + 1) + c  # alone
        else:
            a, b = rows.body[c, 0] + 1, rows.body[c, 1] + 1
            pair = min(a, b) * (B + 1) + max(a, b)
        key[c] = pair * C + rank[c]
    by_pair = np.argsort(key, kind="mergesort")
    first = np.empty(C, dtype=np.int64)  # each block's first rank, for its place in the sweep
    block_of = np.empty(C, dtype=np.int64)
    blocks = 0
    size = 0
    for i in range(C):
        c = by_pair[i]
        if i == 0 or key[c] // C != key[by_pair[i - 1]] // C or size == BLOCK:
            first[blocks] = rank[c]
            blocks += 1
            size = 0
        block_of[c] = blocks - 1
        size += 1
    place = np.argsort(first[:blocks], kind="mergesort")  # blocks in sweep order
    position = np.empty(blocks, dtype=np.int64)
    for k in range(blocks):
        position[place[k]] = k
    placed = np.empty(C, dtype=np.int64)  # each contact's block, numbered in sweep order
    for c in range(C):
        placed[c] = position[block_of[c]]
    return stable_buckets(order, placed, blocks)  # within a block, the sweep order


@njit(cache=True)
def block_couplings(rows: ContactRows, members: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """Each block's normal Delassus block (K, BLOCK, BLOCK) [1/kg]: entry (a, b) the normal
    velocity of contact a that a unit normal impulse on contact b makes, n_aᵀ J_a M⁻¹ J_bᵀ n_b,
    summed over the bodies they share (blocks join bodies only)."""
    K = starts.shape[0] - 1
    out = np.zeros((K, BLOCK, BLOCK))
    for k in range(K):
        n = starts[k + 1] - starts[k]
        for a in range(n):
            for b in range(n):
                out[k, a, b] = _normal_coupling(members[starts[k] + a], members[starts[k] + b], rows)
    return out


@njit(cache=True, inline="always")
def _normal_coupling(i, j, rows):
    """n_iᵀ J_i M⁻¹ J_jᵀ n_j for two contacts between bodies (no particles) [1/kg]."""
    total = 0.0
    for si in range(2):
        b = rows.body[i, si]
        if b < 0:
            continue
        for sj in range(2):
            if rows.body[j, sj] == b:
                sign = (1.0 - 2.0 * si) * (1.0 - 2.0 * sj)
                arms = (rows.arm[i, si], rows.arm[j, sj])
                masses = (rows.body_inverse_mass[b], rows.inverse_inertia[b])
                total = body_coupling(total, sign, arms, (rows.frame[i, 0], rows.frame[j, 0]), masses)
    return total


@njit(cache=True)
def block_normals(
    block: np.ndarray,
    n: int,
    coupling: np.ndarray,
    rows: ContactRows,
    target: np.ndarray,
    impulses: np.ndarray,
    u: np.ndarray,
    scratch: tuple,
) -> None:
    """The exact normal impulses of the block's contacts ``block[:n]`` given every other impulse:
    the LCP x ≥ 0, w = A x + q ≥ 0, xᵀ w = 0, with A the block's ``coupling`` (regularized) and
    q = v_n − target − A λ_old, by trying the active sets from the largest (all contacts pushing)
    down and keeping the first whose x ≥ 0 and w ≥ 0 (none found: the block is left to the
    sweep); ``impulses`` (C, 3) [N s] and u change in place."""
    A, q, x, rhs, active = scratch
    mean = 0.0
    for a in range(n):
        mean += coupling[a, a] / n
    for a in range(n):
        c = block[a]
        q[a] = contact_velocity(c, rows, u)[0] - target[c]
        for b in range(n):
            q[a] -= coupling[a, b] * impulses[block[b], 0]
    for size in range(n, -1, -1):
        for mask in range(1 << n):
            if _bits(mask) != size:
                continue
            if _active_set(mask, n, coupling, mean * REGULARIZATION, q, (A, x, rhs, active)):
                for a in range(n):
                    c = block[a]
                    change = x[a] - impulses[c, 0]
                    impulses[c, 0] = x[a]
                    apply_impulse(c, rows, change, 0.0, 0.0, u)
                return


@njit(cache=True, inline="always")
def _bits(mask):
    """How many bits ``mask`` has set."""
    count = 0
    while mask:
        count += mask & 1
        mask >>= 1
    return count


@njit(cache=True)
def _active_set(mask, n, coupling, epsilon, q, scratch):
    """Whether the contacts of ``mask`` pushing (w = 0) and the rest not (x = 0) solve the block's
    LCP; the answer left in x (n,). The active rows' system solved by Gaussian elimination with
    partial pivoting; ``scratch`` = (A, x, rhs, active)."""
    A, x, rhs, active = scratch
    m = 0
    for a in range(n):
        x[a] = 0.0
        if mask >> a & 1:
            active[m] = a
            m += 1
    for r in range(m):
        for s in range(m):
            A[r, s] = coupling[active[r], active[s]] + (epsilon if r == s else 0.0)
        rhs[r] = -q[active[r]]
    for col in range(m):  # elimination
        pivot = col
        for r in range(col + 1, m):
            if abs(A[r, col]) > abs(A[pivot, col]):
                pivot = r
        if abs(A[pivot, col]) <= 1e-300:
            return False
        if pivot != col:
            for s in range(m):
                A[col, s], A[pivot, s] = A[pivot, s], A[col, s]
            rhs[col], rhs[pivot] = rhs[pivot], rhs[col]
        for r in range(col + 1, m):
            f = A[r, col] / A[col, col]
            for s in range(col, m):
                A[r, s] -= f * A[col, s]
            rhs[r] -= f * rhs[col]
    for r in range(m - 1, -1, -1):
        value = rhs[r]
        for s in range(r + 1, m):
            value -= A[r, s] * x[active[s]]
        x[active[r]] = value / A[r, r]
        if x[active[r]] < 0.0:
            return False
    for a in range(n):  # the inactive contacts must not approach
        if mask >> a & 1:
            continue
        w = q[a]
        for r in range(m):
            w += coupling[a, active[r]] * x[active[r]]
        if w < -1e-12:
            return False
    return True
