"""Contacts: the one struct of arrays every method consumes, and its Jacobian (SPEC D1).

A contact joins side A and side B. Each side is a rigid body (``body_*`` ≥ 0), or a point
carried by up to three particles with barycentric weights (a particle: one index with weight
1; a sample on a cloth triangle: three), or nothing (static geometry). The normal points from
B into A (the direction that separates A), ``depth`` > 0 when penetrating, and the relative
velocity is v_rel = v_A − v_B, so ``normal · v_rel`` < 0 means approaching.

Generalized velocity (DOF layout): body i owns entries [6i, 6i+6) = (linear, world angular);
particle j owns [6B + 3j, 6B + 3j + 3). The velocity of the contact point is J v with

* rigid body: J = [I, −[r]×] (normal row [nᵀ, (r × n)ᵀ]), r = point − centre of mass;
* particle(s): J = [w0 I, w1 I, w2 I].

Forces distribute as F_x = Jᵀ F_p (D1). Shapes: C contacts.
"""

from __future__ import annotations

from collections import namedtuple
from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING

import numpy as np

from .compiling import njit

if TYPE_CHECKING:
    from scipy.sparse import csr_matrix


@dataclass
class Contacts:
    body_a: np.ndarray
    """(C,) int, −1 when side A is not a rigid body"""
    body_b: np.ndarray
    """(C,) int"""
    particles_a: np.ndarray
    """(C, 3) int particle indices carrying side A's point, −1 unused"""
    particles_b: np.ndarray
    """(C, 3) int"""
    weights_a: np.ndarray
    """(C, 3) barycentric weights of those particles"""
    weights_b: np.ndarray
    """(C, 3)"""
    point: np.ndarray
    """(C, 3) world contact point, midway between the surfaces [m]"""
    normal: np.ndarray
    """(C, 3) unit, from B into A"""
    depth: np.ndarray
    """(C,) penetration [m], > 0 overlapping, < 0 a gap"""
    tangent1: np.ndarray
    """(C, 3) unit, ⟂ normal"""
    tangent2: np.ndarray
    """(C, 3) unit, normal × tangent1"""
    friction: np.ndarray
    """(C,) combined Coulomb μ"""
    restitution: np.ndarray
    """(C,) combined ε"""
    feature_id: np.ndarray
    """(C,) int64 persistent id: (collider pair, feature), stable while the contact lasts"""

    @property
    def count(self) -> int:
        return len(self.depth)

    @classmethod
    def from_arrays(cls, arrays: Sequence[np.ndarray]) -> Contacts:
        """The Contacts of a ``ContactArrays`` (what compiled code builds)."""
        return cls(*arrays)

    def arrays(self) -> ContactArrays:
        """These contacts as a ``ContactArrays`` (the same arrays, not copied): what compiled code takes."""
        return ContactArrays(*(getattr(self, f.name) for f in fields(self)))

    @classmethod
    def empty(cls) -> Contacts:
        return cls.concatenate([])

    @classmethod
    def concatenate(cls, parts: Sequence[Contacts]) -> Contacts:
        """Join several Contacts (empty list → no contacts)."""
        shapes = dict(
            body_a=(0,),
            body_b=(0,),
            particles_a=(0, 3),
            particles_b=(0, 3),
            weights_a=(0, 3),
            weights_b=(0, 3),
            point=(0, 3),
            normal=(0, 3),
            depth=(0,),
            tangent1=(0, 3),
            tangent2=(0, 3),
            friction=(0,),
            restitution=(0,),
            feature_id=(0,),
        )
        ints = {"body_a", "body_b", "particles_a", "particles_b", "feature_id"}
        out = {}
        for f in fields(cls):
            arrays = [getattr(p, f.name) for p in parts]
            dtype = np.int64 if f.name in ints else float
            out[f.name] = np.concatenate(arrays).astype(dtype) if arrays else np.zeros(shapes[f.name], dtype)
        return cls(**out)


ContactArrays = namedtuple("ContactArrays", [f.name for f in fields(Contacts)])  # type: ignore[misc]
ContactArrays.__doc__ = (
    """The fields of a Contacts, in order, as a named tuple: the form compiled code builds and reads."""
)


def values_by_id(
    previous_ids: np.ndarray | None, previous_values: np.ndarray | None, feature_id: np.ndarray, width: int
) -> tuple[np.ndarray, np.ndarray]:
    """What a method carried for each contact from the last step, matched by persistent id.

    previous_ids (K,) int64 and previous_values (K, width) as stored last step (None: nothing
    carried); feature_id (C,) the contacts now. Returns (values (C, width), zero for contacts
    that are new, found (C,) bool).
    """
    C = len(feature_id)
    if previous_ids is None or len(previous_ids) == 0 or C == 0:
        return np.zeros((C, width)), np.zeros(C, dtype=bool)
    return values_carried(
        np.asarray(previous_ids, dtype=np.int64),
        np.asarray(previous_values, dtype=float).reshape(len(previous_ids), width),
        np.asarray(feature_id, dtype=np.int64),
    )


NEARBY = 64  # ids before and after the expected place that values_carried looks at first
SCANNED = 16  # contacts still unmatched that values_carried looks up one by one, not by a sort


@njit(cache=True)
def values_carried(
    previous_ids: np.ndarray, previous_values: np.ndarray, feature_id: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``values_by_id``, compiled. previous_ids (K,) int64 (K may be 0; distinct, as contact ids
    are), previous_values (K, width); feature_id (C,) int64.

    Contacts mostly come in last step's order (kept manifolds, pairs in broad-phase order), a
    few manifolds' corners swapped at most: each contact looks for its id just after the last
    one matched, then among the NEARBY ids either side. Contacts still unmatched (new ones, or
    ones that moved far in the order) are looked for in all of last step's ids, one by one if
    there are at most SCANNED of them, else by bisection in those ids sorted, the sort made
    only then. On a settled 20-level pyramid (1 600 contacts, all kept, blocks of up to a dozen
    reordered by up to 20 places in about one step in six) no step of 120 sorts: 30–58 → 8–10 µs
    a step, and the stepping loop 1,090 → 1,210 steps/s (one thread, best of four)."""
    K, width, C = previous_ids.shape[0], previous_values.shape[1], feature_id.shape[0]
    place = np.empty(C, dtype=np.int64)  # where each contact's id was last step, −1: not there
    unmatched = 0
    hint = 0  # the place after the last match
    for c in range(C):
        place[c] = -1
        if hint < K and previous_ids[hint] == feature_id[c]:
            place[c] = hint
        else:
            place[c] = _index_in(previous_ids, feature_id[c], max(0, hint - NEARBY), min(K, hint + NEARBY + 1))
        if place[c] >= 0:
            hint = place[c] + 1
        else:
            unmatched += 1
    if 0 < unmatched <= SCANNED:  # a few: one pass over last step's ids each
        for c in range(C):
            if place[c] < 0:
                place[c] = _index_in(previous_ids, feature_id[c], 0, K)
    elif unmatched > 0 and K > 0:
        order = argsort_keys(previous_ids)
        sorted_ids = np.empty(K, dtype=np.int64)
        for i in range(K):  # a loop, and the bisection below by hand: less to compile than
            sorted_ids[i] = previous_ids[order[i]]  # NumPy's gather and searchsorted
        for c in range(C):
            if place[c] >= 0:
                continue
            p, high = 0, K  # the first place whose id is ≥ the contact's (searchsorted, side "left")
            while p < high:
                middle = (p + high) >> 1
                if sorted_ids[middle] < feature_id[c]:
                    p = middle + 1
                else:
                    high = middle
            if p < K and sorted_ids[p] == feature_id[c]:
                place[c] = order[p]
    values = np.zeros((C, width))
    found = np.zeros(C, dtype=np.bool_)
    for c in range(C):
        if place[c] >= 0:
            found[c] = True
            for j in range(width):  # not values[c, :] = …: a slice assignment
                values[c, j] = previous_values[place[c], j]  # compiles Numba's shape-mismatch message
    return values, found


@njit(cache=True, inline="always")
def _index_in(ids: np.ndarray, wanted: int, low: int, high: int) -> int:
    """The first place q in [low, high) with ids[q] == wanted, −1 if none (a linear search)."""
    for q in range(low, high):
        if ids[q] == wanted:
            return q
    return -1


@njit(cache=True)
def argsort_keys(keys: np.ndarray) -> np.ndarray:
    """The order (K,) int64 that sorts the int64 ``keys`` (K,) ascending: for distinct keys
    (contact ids) ``np.argsort``'s; equal keys in some order. A quicksort (median of three,
    the shorter side first, short runs by insertion) in one function: Numba's own argsort is
    five, a second of a cold start to compile, and this one runs as fast."""
    n = keys.shape[0]
    order = np.empty(n, dtype=np.int64)
    for i in range(n):
        order[i] = i
    pending = np.empty(128 if n > 16 else 0, dtype=np.int64)  # (low, high) pairs, ≤ log2(n) of them
    top = 0
    low, high = 0, n - 1
    while True:
        while high - low >= 16:
            middle = (low + high) >> 1
            if keys[order[middle]] < keys[order[low]]:
                order[low], order[middle] = order[middle], order[low]
            if keys[order[high]] < keys[order[middle]]:
                order[high], order[middle] = order[middle], order[high]
                if keys[order[middle]] < keys[order[low]]:
                    order[low], order[middle] = order[middle], order[low]
            pivot = keys[order[middle]]
            i, j = low, high
            while i <= j:
                while keys[order[i]] < pivot:
                    i += 1
                while pivot < keys[order[j]]:
                    j -= 1
                if i <= j:
                    order[i], order[j] = order[j], order[i]
                    i += 1
                    j -= 1
            if j - low < high - i:  # the longer side waits, the shorter is split next
                pending[top], pending[top + 1] = i, high
                high = j
            else:
                pending[top], pending[top + 1] = low, j
                low = i
            top += 2
        for a in range(low + 1, high + 1):
            item = order[a]
            key = keys[item]
            b = a
            while b > low and key < keys[order[b - 1]]:
                order[b] = order[b - 1]
                b -= 1
            order[b] = item
        if top == 0:
            return order
        top -= 2
        low, high = pending[top], pending[top + 1]


def tangent_basis(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit tangents (C, 3) each, with (t1, t2, n) right-handed, from unit normals (C, 3)."""
    return tangent_frames(np.ascontiguousarray(normal, dtype=float))


@njit(cache=True)
def tangent_frames(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``tangent_basis``, compiled: it runs on every contact of every step."""
    C = normal.shape[0]
    t1 = np.empty((C, 3))
    t2 = np.empty((C, 3))
    for c in range(C):
        nx, ny, nz = normal[c, 0], normal[c, 1], normal[c, 2]
        # t1 = n × x̂, or n × ŷ where n is closest to ±x̂. The choice changes only where |n_x|
        # passes max(|n_y|, |n_z|), 45° from the axes: a face normal a hair off an axis keeps
        # its basis from step to step, so last step's friction impulses, stored along (t1, t2),
        # still point the same way when they warm-start this step's (choosing by the least
        # aligned axis flipped t1 by 90° whenever two tiny components swapped sizes).
        if abs(nx) >= abs(ny) and abs(nx) >= abs(nz):  # n × ŷ
            ux, uy, uz = -nz, 0.0, nx
        else:  # n × x̂
            ux, uy, uz = 0.0, nz, -ny
        length = np.sqrt(ux * ux + uy * uy + uz * uz)
        ux, uy, uz = ux / length, uy / length, uz / length
        t1[c, 0], t1[c, 1], t1[c, 2] = ux, uy, uz
        t2[c, 0], t2[c, 1], t2[c, 2] = ny * uz - nz * uy, nz * ux - nx * uz, nx * uy - ny * ux
    return t1, t2


def jacobian(contacts: Contacts, body_position: np.ndarray, body_count: int, particle_count: int) -> csr_matrix:
    """The contact Jacobian as a SciPy CSR matrix, shape (3C, 6B + 3P).

    Rows 3c, 3c+1, 3c+2 are the normal, tangent1 and tangent2 directions of contact c
    applied to v_rel = v_A − v_B. ``body_position`` (B, 3) are the centres of mass the lever
    arms are measured from (the positions the contacts were detected at).
    """
    C = contacts.count
    directions = np.stack([contacts.normal, contacts.tangent1, contacts.tangent2], axis=1)  # (C,3,3)
    rows, cols, vals = [], [], []
    row_index = np.arange(3 * C).reshape(C, 3)
    for body, particles, weights, sign in (
        (contacts.body_a, contacts.particles_a, contacts.weights_a, 1.0),
        (contacts.body_b, contacts.particles_b, contacts.weights_b, -1.0),
    ):
        has_body = body >= 0
        if has_body.any():
            c = np.nonzero(has_body)[0]
            r = contacts.point[c] - body_position[body[c]]  # (k,3)
            linear = directions[c]  # (k,3,3)
            angular = np.cross(r[:, None, :], linear)  # r × d
            block = np.concatenate([linear, angular], axis=2) * sign  # (k,3,6)
            rows.append(np.repeat(row_index[c], 6, axis=1).ravel())
            cols.append((6 * body[c][:, None, None] + np.arange(6)[None, None, :]).repeat(3, axis=1).ravel())
            vals.append(block.ravel())
        for k in range(3):
            has = particles[:, k] >= 0
            if has.any():
                c = np.nonzero(has)[0]
                block = directions[c] * (sign * weights[c, k])[:, None, None]  # (k,3,3)
                rows.append(np.repeat(row_index[c], 3, axis=1).ravel())
                col0 = 6 * body_count + 3 * particles[c, k]
                cols.append((col0[:, None, None] + np.arange(3)[None, None, :]).repeat(3, axis=1).ravel())
                vals.append(block.ravel())
    import scipy.sparse as sp  # here, not at the top: it is a tenth of `import contactlab`

    shape = (3 * C, 6 * body_count + 3 * particle_count)
    if not rows:
        return sp.csr_matrix(shape)
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=shape)
