"""Contact manifolds kept across steps: a pair that has barely moved reuses its contacts.

Clipping two boxes (or hulls) is the costly part of a narrow phase, and in a resting stack it
returns the same few contacts step after step. So, as Bullet does with its persistent
manifolds, each pair of boxes, hulls and planes (``kept_pairs``) keeps what it found: both
colliders' poses then, and every contact as two witness points (the surface points of A and of
B, each in its own collider's frame) and a normal in A's frame. A later step reuses the pair's
contacts, without calling its routine, while the relative motion since then is within the
tolerance; it refreshes each one from the witness points at the current poses, so depth and
point are exact for those two material points:

    p_A = c_A + R_A w_A,   p_B = c_B + R_B w_B,   n = R_A n_A,
    depth = (p_B − p_A) · n,   point = (p_A + p_B) / 2.

Valid means: every point of the smaller collider has moved at most ``tolerance`` [m] in the
larger one's frame (the chord bound |Δt| + ρ ‖ΔR‖_F / √2, ρ its bounding radius), and the pair's
reach now plus that motion stays inside the reach its contacts were computed with (so no
contact that has come within reach can be missing). To leave room for the second condition,
a kept pair is computed with its reach widened by the tolerance; contacts beyond the current
reach are dropped from what the step sees. Anything else (a new pair, a moving pair, a pair
with a sphere, capsule or particle) is computed afresh.
"""

from __future__ import annotations

from collections import namedtuple
from dataclasses import dataclass
from typing import Any

import numpy as np

from .. import shapes
from ..compiling import njit
from .narrow_phase import MAX_PER_PAIR, generate_contacts

# a step's pairs as the reuse reads them: pairs (K, 2) of global colliders, their keys (K,) int64
# (a · total + b), whether each keeps manifolds (K,) bool (``kept_pairs``), their reach (K,) [m]
KeyedPairs = namedtuple("KeyedPairs", ["pairs", "keys", "keeps", "reach"])


@dataclass(frozen=True)
class Manifolds:
    """Contacts kept per collider pair. K pairs, sorted by ``keys``; S = MAX_PER_PAIR slots."""

    keys: np.ndarray
    """(K,) int64, pair (a, b) of global colliders as a · total + b"""
    reach: np.ndarray
    """(K,) [m] the reach the contacts were computed with"""
    center: np.ndarray
    """(K, 2, 3) [m] the colliders' centres then"""
    rotation: np.ndarray
    """(K, 2, 3, 3) their rotations then (collider → world)"""
    count: np.ndarray
    """(K,) int64 contacts kept (0: near, not touching)"""
    witness: np.ndarray
    """(K, S, 2, 3) [m] each contact's surface points of A and B, in their own frames"""
    normal: np.ndarray
    """(K, S, 3) unit, from B into A, in A's frame"""
    feature: np.ndarray
    """(K, S) int64 feature number within the pair"""

    @classmethod
    def empty(cls) -> Manifolds:
        return cls(*no_manifolds())

    def __len__(self):
        return len(self.keys)


@njit(cache=True)
def no_manifolds() -> tuple:
    """The eight fields of Manifolds (``Manifolds.empty``'s) with no pair: what a detection with
    nothing to keep takes for ``kept`` (the loop's ``record``), compiled or not."""
    return (
        np.zeros(0, np.int64),
        np.zeros(0),
        np.zeros((0, 2, 3)),
        np.zeros((0, 2, 3, 3)),
        np.zeros(0, np.int64),
        np.zeros((0, MAX_PER_PAIR, 2, 3)),
        np.zeros((0, MAX_PER_PAIR, 3)),
        np.zeros((0, MAX_PER_PAIR), np.int64),
    )


@njit(cache=True)
def kept_pairs(kinds: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """(K,) bool: the pairs that keep manifolds: boxes and convex hulls against each other and
    against planes. Their contacts sit at vertices, edges and faces, which move with the
    bodies; a sphere's or a capsule's contact point rolls over its surface instead, so
    witness points fixed in it would tilt the normal as it rolls (a lying capsule crept
    sideways at 1.5 mm/s on kept contacts)."""
    flat = (kinds == shapes.BOX) | (kinds == shapes.CONVEX) | (kinds == shapes.PLANE)
    return flat[pairs[:, 0]] & flat[pairs[:, 1]]


@njit(cache=True)
def _still_valid(keyed, radius, at, kept, tolerance):
    """For each pair k (K,) of ``keyed`` (:data:`KeyedPairs`), the row of its kept manifold if
    that is still valid, else −1 (see the module's docstring). ``radius`` (N,) bounding radii
    [m]; ``at`` = (centres (N, 3) [m], rotations (N, 3, 3)); ``kept`` the last manifolds' eight
    fields (keys sorted), of which the keys, reaches, centres and rotations are read."""
    pairs, keys, keeps, pair_reach = keyed
    centers, rotations_ = at
    kept_keys, reach_then, center_then, rotation_then = kept[0], kept[1], kept[2], kept[3]
    K = pairs.shape[0]
    row = np.full(K, -1, dtype=np.int64)
    if kept_keys.shape[0] == 0:
        return row
    place = np.searchsorted(kept_keys, keys)
    for k in range(K):
        m = place[k]
        if not keeps[k] or m >= kept_keys.shape[0] or kept_keys[m] != keys[k]:
            continue
        a, b = pairs[k, 0], pairs[k, 1]
        # the frame of the larger collider (a static plane's, if there is one); the other's motion in it
        ref, mover, ref_side = (a, b, 0) if radius[a] >= radius[b] else (b, a, 1)
        R, R0 = rotations_[ref], rotation_then[m, ref_side]
        Q, Q0 = rotations_[mover], rotation_then[m, 1 - ref_side]
        shift = 0.0
        turn = 0.0
        for i in range(3):
            # t = Rᵀ (c_mover − c_ref) now and then; R_rel = Rᵀ Q now and then
            t = 0.0
            t0 = 0.0
            for j in range(3):
                t += R[j, i] * (centers[mover, j] - centers[ref, j])
                t0 += R0[j, i] * (center_then[m, 1 - ref_side, j] - center_then[m, ref_side, j])
            shift += (t - t0) ** 2
            for l in range(3):
                r = 0.0
                r0 = 0.0
                for j in range(3):
                    r += R[j, i] * Q[j, l]
                    r0 += R0[j, i] * Q0[j, l]
                turn += (r - r0) ** 2
        motion = np.sqrt(shift) + radius[mover] * np.sqrt(0.5 * turn)
        if motion <= tolerance and pair_reach[k] + motion <= reach_then[m]:
            row[k] = m
    return row


# Row copies written as loops (``_copy1(a[r], b[m])`` for ``a[r] = b[m]``): Numba compiles an
# array assignment together with its shape-mismatch message, seconds of string formatting on
# a cold cache. Same shape on both sides; 1, 2 or 3 dimensions.


@njit(cache=True, inline="always")
def _copy1(destination, source):
    for i in range(destination.shape[0]):
        destination[i] = source[i]


@njit(cache=True, inline="always")
def copy_rows(destination: np.ndarray, source: np.ndarray) -> None:
    """destination[i, j] = source[i, j] for every row i and column j of destination (2-D
    arrays): a loop, which compiles no NumPy copy routine and, inlined, passes no array."""
    for i in range(destination.shape[0]):
        for j in range(destination.shape[1]):
            destination[i, j] = source[i, j]


@njit(cache=True, inline="always")
def _copy3(destination, source):
    for i in range(destination.shape[0]):
        for j in range(destination.shape[1]):
            for k in range(destination.shape[2]):
                destination[i, j, k] = source[i, j, k]


@njit(cache=True)
def _combine(keyed, computed_reach, row, at, fresh, kept):
    """The step's contacts in pair order, and the manifolds to keep, sorted by key.

    Pair k of ``keyed`` (:data:`KeyedPairs`), at ``at`` = (centres (N, 3) [m], rotations
    (N, 3, 3)), takes its kept manifold's contacts refreshed at the current poses when ``row[k]``
    ≥ 0 (the manifold itself is kept as it is), else its ``fresh`` contacts (point, normal,
    depth, feature, owner, as ``generate_contacts`` gave them, owner indexing ``pairs``),
    recorded as a new manifold when ``keeps[k]``. ``kept``: the last manifolds, the eight fields
    as ``reuse_or_generate`` takes them. Contacts deeper in the gap than ``pair_reach`` [m] are
    left out."""
    pairs, keys, keeps, pair_reach = keyed
    centers, rotations_ = at
    point, normal, depth, feature, owner = fresh
    _, kept_reach, kept_center, kept_rotation, kept_count, kept_witness, kept_normal, kept_feature = kept
    K, S = pairs.shape[0], MAX_PER_PAIR
    capacity = point.shape[0]
    for k in range(K):
        if row[k] >= 0:
            capacity += kept_count[row[k]]
    out_point = np.empty((capacity, 3))
    out_normal = np.empty((capacity, 3))
    out_depth = np.empty(capacity)
    out_feature = np.empty(capacity, dtype=np.int64)
    out_owner = np.empty(capacity, dtype=np.int64)
    M = 0
    for k in range(K):
        if keeps[k]:
            M += 1
    new_keys = np.empty(M, dtype=np.int64)
    new_reach = np.empty(M)
    new_center = np.empty((M, 2, 3))
    new_rotation = np.empty((M, 2, 3, 3))
    new_count = np.zeros(M, dtype=np.int64)
    new_witness = np.zeros((M, S, 2, 3))
    new_normal = np.zeros((M, S, 3))
    new_feature = np.zeros((M, S), dtype=np.int64)
    c = 0  # contacts written
    f = 0  # next fresh contact
    r = 0  # manifolds written
    for k in range(K):
        a, b = pairs[k, 0], pairs[k, 1]
        m = row[k]
        if m >= 0:  # reused: refreshed from the witness points
            new_keys[r], new_reach[r], new_count[r] = keys[k], kept_reach[m], kept_count[m]
            copy_rows(new_center[r], kept_center[m])
            _copy3(new_rotation[r], kept_rotation[m])
            _copy3(new_witness[r], kept_witness[m])
            copy_rows(new_normal[r], kept_normal[m])
            _copy1(new_feature[r], kept_feature[m])
            r += 1
            for s in range(kept_count[m]):
                gap = 0.0
                for i in range(3):
                    pa = centers[a, i]
                    pb = centers[b, i]
                    n = 0.0
                    for j in range(3):
                        pa += rotations_[a, i, j] * kept_witness[m, s, 0, j]
                        pb += rotations_[b, i, j] * kept_witness[m, s, 1, j]
                        n += rotations_[a, i, j] * kept_normal[m, s, j]
                    out_point[c, i] = 0.5 * (pa + pb)
                    out_normal[c, i] = n
                    gap += (pb - pa) * n
                if gap >= -pair_reach[k]:
                    out_depth[c], out_feature[c], out_owner[c] = gap, kept_feature[m, s], k
                    c += 1
            continue
        if keeps[k]:  # computed afresh: kept as a new manifold
            new_keys[r], new_reach[r] = keys[k], computed_reach[k]
            _copy1(new_center[r, 0], centers[a])
            _copy1(new_center[r, 1], centers[b])
            copy_rows(new_rotation[r, 0], rotations_[a])
            copy_rows(new_rotation[r, 1], rotations_[b])
        while f < owner.shape[0] and owner[f] == k:
            if keeps[k]:
                s = new_count[r]
                for i in range(3):  # surface points of A and B: midway ∓ half the depth along n, in own frames
                    wa = 0.0
                    wb = 0.0
                    n = 0.0
                    for j in range(3):
                        sa = point[f, j] - 0.5 * depth[f] * normal[f, j]
                        sb = point[f, j] + 0.5 * depth[f] * normal[f, j]
                        wa += rotations_[a, j, i] * (sa - centers[a, j])
                        wb += rotations_[b, j, i] * (sb - centers[b, j])
                        n += rotations_[a, j, i] * normal[f, j]
                    new_witness[r, s, 0, i], new_witness[r, s, 1, i], new_normal[r, s, i] = wa, wb, n
                new_feature[r, s] = feature[f]
                new_count[r] = s + 1
            if depth[f] >= -pair_reach[k]:
                _copy1(out_point[c], point[f])
                _copy1(out_normal[c], normal[f])
                out_depth[c], out_feature[c], out_owner[c] = depth[f], feature[f], k
                c += 1
            f += 1
        if keeps[k]:
            r += 1
    order = np.argsort(new_keys, kind="mergesort")
    return (
        (out_point[:c], out_normal[:c], out_depth[:c], out_feature[:c], out_owner[:c]),
        (
            new_keys[order],
            new_reach[order],
            new_center[order],
            new_rotation[order],
            new_count[order],
            new_witness[order],
            new_normal[order],
            new_feature[order],
        ),
    )


@njit(cache=True)
def reuse_or_generate(
    table: Any,
    plan: Any,
    pairs: np.ndarray,
    at: tuple[np.ndarray, np.ndarray],
    reach: np.ndarray,
    kept: tuple[np.ndarray, ...],
    tolerance: float,
) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, ...]]:
    """``generate_contacts`` over ``pairs`` (K, 2), reusing the still valid manifolds ``kept`` (the
    last step's, as the tuple of Manifolds' eight fields) of ``kept_pairs``, with motion
    ``tolerance`` [m] > 0 (``collision.detect`` calls it): ``table`` the colliders (a
    ``collision.Colliders``: their kinds (N,), params (N, 4) and bounding radii (N,) [m] are
    read), at ``at`` = (centres (N, 3) [m], rotations (N, 3, 3)); ``reach`` (N,) per collider [m];
    ``plan`` (``collision.Plan``) the hull store and families ``generate_contacts`` takes.
    Returns ((point, normal, depth, feature, owner), the eight fields of the manifolds to keep).
    Contacts come in pair order, as from ``generate_contacts``; a pair that keeps nothing gets
    exactly what ``generate_contacts`` gives it."""
    kept_keys, kept_reach, kept_center, kept_rotation, kept_count, kept_witness, kept_normal, kept_feature = kept
    kinds, params = table.kinds, table.params
    centers, rots = at
    first, second = pairs[:, 0], pairs[:, 1]
    keys = first * kinds.shape[0] + second
    pair_reach = reach[first] + reach[second]
    keeps = kept_pairs(kinds, pairs)
    if not keeps.any():  # a pile of spheres: nothing to keep, nothing to look up
        empty = (
            kept_keys[:0],
            kept_reach[:0],
            kept_center[:0],
            kept_rotation[:0],
            kept_count[:0],
            kept_witness[:0],
            kept_normal[:0],
            kept_feature[:0],
        )
        return (
            generate_contacts(pairs, kinds, params, centers, rots, pair_reach, plan.hull_store, plan.families),
            empty,
        )
    keyed = KeyedPairs(pairs, keys, keeps, pair_reach)
    row = _still_valid(keyed, table.radius, at, kept, tolerance)
    fresh = np.nonzero(row < 0)[0]
    widened = pair_reach + tolerance * keeps  # a kept manifold reaches a tolerance further
    point, normal, depth, feature, owner = generate_contacts(
        pairs[fresh], kinds, params, centers, rots, widened[fresh], plan.hull_store, plan.families
    )
    return _combine(keyed, widened, row, at, (point, normal, depth, feature, fresh[owner]), kept)
