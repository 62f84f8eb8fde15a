"""Narrow phase: one compiled function per shape pair, and a dispatcher.

Every pair function takes shape A then shape B and writes contacts whose normal points
from B into A, ``depth`` > 0 when overlapping (contacts down to ``depth = −margin`` are kept,
for speculative use), and ``point`` midway between the two surfaces. It returns how many
contacts it wrote (at most ``MAX_PER_PAIR``) and a feature number for each, which makes the
contact id persistent. Shapes are described as in :mod:`contactlab.shapes`: a kind, a row of
4 parameters, and a frame (:data:`.contact_output.Frame`: the centre and the rotation matrix,
body → world, as one argument: a pair routine's argument list then fits on a line).

This module holds the dispatcher (``generate_contacts`` over a scene's pairs, ``collide_pair``
for one) and what it needs (``supported``, the hull store); the pair routines live in a module
per family (:mod:`~contactlab.collision.primitive_pairs` for spheres and boxes against planes,
spheres and boxes, :mod:`~contactlab.collision.capsule`, :mod:`~contactlab.collision.capsule_box`,
:mod:`~contactlab.collision.box_box`, :mod:`~contactlab.collision.convex`,
:mod:`~contactlab.collision.convex_convex`, :mod:`~contactlab.collision.capsule_convex`), and
which of them a scene needs in :mod:`~contactlab.collision.families`.
"""

from collections import namedtuple
from typing import Any

import numpy as np
from numba import types
from numba.core.errors import TypingError
from numba.extending import overload

from .. import shapes
from ..compiling import njit
from .box_box import box_box
from .capsule import capsule_capsule, capsule_plane, sphere_capsule
from .capsule_box import capsule_box
from .capsule_convex import capsule_convex
from .contact_output import Frame, PairOutput
from .convex import convex_plane, sphere_convex, stored_hull
from .convex_convex import convex_convex
from .families import ALL_FAMILIES, BOX, CAPSULE, CONVEX, FAMILIES, PLANE, POINT, SPHERE
from .families import families_of as families_of  # re-exported: the narrow phase's callers name them here
from .families import family as family
from .families import needs_hulls as needs_hulls
from .families import scene_families as scene_families
from .primitive_pairs import box_plane, sphere_box, sphere_plane, sphere_sphere

MAX_PER_PAIR = 8

# the colliders where they stand, as the pairs' loop reads them: kinds (N,) int64, params (N, 4),
# centres (N, 3) [m], rotations (N, 3, 3) body → world
Placed = namedtuple("Placed", ["kinds", "params", "centers", "rotations"])


@njit(cache=True)
def supported(kind_a: int, kind_b: int) -> bool:
    """Whether a contact routine exists for this pair (order does not matter)."""
    if kind_a > kind_b:
        kind_a, kind_b = kind_b, kind_a
    if kind_b == PLANE:
        return kind_a != PLANE
    if kind_b == shapes.MESH:  # meshes are static: only dynamic shapes meet them
        return kind_a != PLANE
    return True


def empty_hull_store() -> tuple:
    """A hull store with no hulls, for pairs that need none (see Model.hull_store).

    Read-only like a Model's, so the compiled dispatch is the same one (Numba types read-only
    and writable arrays apart and would compile everything twice)."""
    store = (
        np.zeros(1, dtype=np.int64),
        np.zeros((0, 3)),
        np.zeros(1, dtype=np.int64),
        np.zeros((0, 3)),
        np.zeros(0),
        np.zeros(1, dtype=np.int64),
        np.zeros(0, dtype=np.int64),
        np.zeros(1, dtype=np.int64),
        np.zeros((0, 2), dtype=np.int64),
        np.zeros((0, 2), dtype=np.int64),
    )
    for array in store:
        array.flags.writeable = False
    return store


@njit(cache=True)
def _rank(kind):
    """Canonical order of a pair: the lower rank is shape A (round < capsule < box < convex < plane)."""
    if kind == SPHERE or kind == POINT:
        return 0
    if kind == CAPSULE:
        return 1
    if kind == BOX:
        return 2
    if kind == CONVEX:
        return 3
    return 9


def _pairs_loop(families, pairs, placed, reach, hull_store, out, out_owner, slot):
    """The contacts of every pair k of ``pairs`` (K, 2) of the colliders ``placed`` (a
    :data:`Placed`), reaching gaps down to ``reach[k]``,
    written from row ``slot`` on in pair order, with ``out_owner`` = k; returns how many were
    written. Each pair is taken in canonical order (rank of A ≤ rank of B; computed swapped and
    its normals flipped otherwise). A pair whose family is ``None`` in ``families`` (see
    FAMILIES), or that has no routine, gets none. Compiled, the overload below; run as Python
    (``NUMBA_DISABLE_JIT=1``), this body runs the same loop."""
    loop = _loop_for(tuple(family is not None for family in families))
    return loop(families, pairs, placed, reach, hull_store, out, out_owner, slot)


@overload(_pairs_loop)
def _pairs_loop_for(families, pairs, placed, reach, hull_store, out, out_owner, slot):
    """The loop for one families type. Its ``None`` entries are the constant False here, so
    Numba drops those routines' branches before typing and never compiles them."""
    if not isinstance(families, types.BaseTuple) or len(families) != len(FAMILIES):
        raise TypingError(f"families: expected a tuple of {len(FAMILIES)} True or None, found {families}")
    return _loop_for(tuple(not isinstance(t, types.NoneType) for t in families.types))


def _loop_for(present: tuple[bool, ...]) -> Any:
    """The pairs' loop with the routine of each family whose flag in ``present`` (one a FAMILIES
    entry) is True. The loop and the dispatch are one function: a call per pair that handed over
    the arrays (and the hull store's ten) would cost more than a sphere pair itself."""
    (
        has_sphere_sphere,
        has_sphere_capsule,
        has_sphere_box,
        has_sphere_plane,
        has_capsule_capsule,
        has_capsule_box,
        has_capsule_plane,
        has_box_box,
        has_box_plane,
        has_sphere_convex,
        has_capsule_convex,
        has_convex_convex,
        has_convex_plane,
    ) = present

    def loop(families, pairs, placed, reach, hull_store, out, out_owner, slot):
        kinds, params, centers, rotations_ = placed
        count = slot
        for k in range(pairs.shape[0]):
            a, b = pairs[k, 0], pairs[k, 1]
            swapped = _rank(kinds[a]) > _rank(kinds[b])
            if swapped:
                a, b = b, a
            kind_a, kind_b = kinds[a], kinds[b]
            params_a, center_a, rotation_a = params[a], centers[a], rotations_[a]
            params_b, center_b, rotation_b = params[b], centers[b], rotations_[b]
            frame_a, frame_b = (center_a, rotation_a), (center_b, rotation_b)  # (centre, rotation): a Frame
            margin = reach[k]
            round_a = kind_a == SPHERE or kind_a == POINT
            round_b = kind_b == SPHERE or kind_b == POINT
            written = 0
            if has_sphere_sphere:
                if round_a and round_b:
                    written = sphere_sphere((center_a, params_a[0]), (center_b, params_b[0]), margin, out, count)
            if has_sphere_capsule:
                if round_a and kind_b == CAPSULE:
                    written = sphere_capsule(
                        (center_a, params_a[0]), (frame_b, params_b[0], params_b[1]), margin, out, count
                    )
            if has_sphere_box:
                if round_a and kind_b == BOX:
                    written = sphere_box((center_a, params_a[0]), (frame_b, params_b[:3]), margin, out, count)
            if has_sphere_plane:
                if round_a and kind_b == PLANE:
                    written = sphere_plane((center_a, params_a[0]), params_b, margin, out, count)
            if has_capsule_capsule:
                if kind_a == CAPSULE and kind_b == CAPSULE:
                    written = capsule_capsule(
                        (frame_a, params_a[0], params_a[1]), (frame_b, params_b[0], params_b[1]), margin, out, count
                    )
            if has_capsule_box:
                if kind_a == CAPSULE and kind_b == BOX:
                    written = capsule_box(
                        (frame_a, params_a[0], params_a[1]), (frame_b, params_b[:3]), margin, out, count
                    )
            if has_capsule_plane:
                if kind_a == CAPSULE and kind_b == PLANE:
                    written = capsule_plane((frame_a, params_a[0], params_a[1]), params_b, margin, out, count)
            if has_box_box:
                if kind_a == BOX and kind_b == BOX:
                    written = box_box(frame_a, params_a[:3], frame_b, params_b[:3], margin, out, count)
            if has_box_plane:
                if kind_a == BOX and kind_b == PLANE:
                    written = box_plane((frame_a, params_a[:3]), params_b, margin, out, count)
            if has_sphere_convex:
                if round_a and kind_b == CONVEX:
                    hb = stored_hull(hull_store, params_b[0])
                    written = sphere_convex(center_a, params_a[0], frame_b, hb, margin, out, count)
            if has_capsule_convex:
                if kind_a == CAPSULE and kind_b == CONVEX:
                    hb = stored_hull(hull_store, params_b[0])
                    written = capsule_convex(frame_a, params_a[0], params_a[1], frame_b, hb, margin, out, count)
            if has_convex_convex:
                if (kind_a == BOX or kind_a == CONVEX) and kind_b == CONVEX:
                    ha = stored_hull(hull_store, params_a[0] if kind_a == CONVEX else params_a[3])
                    hb = stored_hull(hull_store, params_b[0])
                    written = convex_convex(frame_a, ha, frame_b, hb, margin, out, count)
            if has_convex_plane:
                if kind_a == CONVEX and kind_b == PLANE:
                    ha = stored_hull(hull_store, params_a[0])
                    written = convex_plane(frame_a, ha, params_b, margin, out, count)
            for c in range(count, count + written):
                if swapped:  # normals from B into A of the pair as given
                    for i in range(3):
                        out[1][c, i] = -out[1][c, i]
                out_owner[c] = k
            count += written
        return count - slot

    return loop


Collider = tuple[int, np.ndarray, Frame]
"""One shape where it stands: (kind (``shapes.SPHERE``…), params (4,) as ``Model.body_params``,
frame (centre (3,) [m], rotation (3, 3) body → world; :data:`.contact_output.Frame`))."""


@njit(cache=True)
def collide_pair(a: Collider, b: Collider, margin: float, hull_store: tuple, out: PairOutput, slot: int) -> int:
    """Contacts of shape A against shape B (each a :data:`Collider`) written from ``slot`` on;
    returns their count (at most MAX_PER_PAIR). Swapping the two shapes flips the normal and
    nothing else. Every routine is compiled in: the scene-wide narrow phase
    (``generate_contacts``) compiles only the families it is given.

    margin [m]: contacts with gaps down to −margin are kept; hull_store: the model's packed
    hulls (Model.hull_store, or ``empty_hull_store()``); out: the rows (point (n, 3) [m],
    normal (n, 3), depth (n,) [m], feature (n,) int64; :data:`.contact_output.PairOutput`)
    written from ``slot`` on."""
    kind_a, params_a, (center_a, rotation_a) = a
    kind_b, params_b, (center_b, rotation_b) = b
    kinds = np.array([kind_a, kind_b], dtype=np.int64)
    params = np.empty((2, 4))
    centers = np.empty((2, 3))
    rotations_ = np.empty((2, 3, 3))
    for i in range(4):
        params[0, i], params[1, i] = params_a[i], params_b[i]
    for i in range(3):
        centers[0, i], centers[1, i] = center_a[i], center_b[i]
        for j in range(3):
            rotations_[0, i, j], rotations_[1, i, j] = rotation_a[i, j], rotation_b[i, j]
    owner = np.empty(out[2].shape[0], dtype=np.int64)
    return _pairs_loop(
        ALL_FAMILIES,
        np.array([[0, 1]], dtype=np.int64),
        Placed(kinds, params, centers, rotations_),
        np.full(1, margin),
        hull_store,
        out,
        owner,
        np.int64(slot),
    )


@njit(cache=True)
def generate_contacts(
    pairs: np.ndarray,
    kinds: np.ndarray,
    params: np.ndarray,
    centers: np.ndarray,
    rotations_: np.ndarray,
    reach: np.ndarray,
    hull_store: tuple | None,
    families: tuple,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The narrow phase over ``pairs`` (K, 2) of global colliders: (point (C, 3) [m], normal
    (C, 3), depth (C,) [m], feature (C,), owner (C,)) of every contact, owner being its
    pair's row, with gaps down to ``reach`` (K,) [m] of its pair; contacts in pair order.

    kinds (N,), params (N, 4), centers (N, 3) [m], rotations_ (N, 3, 3): the colliders.
    ``families`` (see FAMILIES; ``scene_families``) says which pair routines are compiled in:
    it must cover every pair's family. ``hull_store`` (Model.hull_store) may be None when no
    hull family is in it."""
    capacity = len(pairs) * MAX_PER_PAIR
    point = np.empty((capacity, 3))
    normal = np.empty((capacity, 3))
    depth = np.empty(capacity)
    feature = np.empty(capacity, dtype=np.int64)
    owner = np.empty(capacity, dtype=np.int64)  # which pair each contact came from
    # the slot as an int64, not a literal 0: Numba would type every routine for slot = 0
    # first and compile each of them twice
    count = _pairs_loop(
        families,
        pairs,
        Placed(kinds, params, centers, rotations_),
        reach,
        hull_store,
        (point, normal, depth, feature),
        owner,
        np.int64(0),
    )
    return point[:count], normal[:count], depth[:count], feature[:count], owner[:count]
