"""Narrow phase: one compiled function per shape pair, and a dispatcher.

Every pair function takes shape A then shape B and writes contacts whose normal points
from B into A, ``depth`` > 0 when overlapping (contacts down to ``depth = −margin`` are kept,
for speculative use), and ``point`` midway between the two surfaces. It returns how many
contacts it wrote (at most ``MAX_PER_PAIR``) and a feature number for each, which makes the
contact id persistent. Shapes are described as in :mod:`contactlab.shapes`: a kind, a row of
4 parameters, a centre and a rotation matrix (body → world).
"""

import numpy as np
from numba import njit, types
from numba.core.errors import TypingError
from numba.extending import overload

from .. import shapes
from .box_box import box_box
from .capsule import capsule_capsule, capsule_plane, sphere_capsule
from .capsule_box import capsule_box
from .capsule_convex import capsule_convex
from .contact_output import write_contact
from .convex import convex_plane, hull_view, sphere_convex
from .convex_convex import convex_convex

MAX_PER_PAIR = 8

SPHERE, BOX, PLANE, POINT, CAPSULE, CONVEX = (
    shapes.SPHERE,
    shapes.BOX,
    shapes.PLANE,
    shapes.POINT,
    shapes.CAPSULE,
    shapes.CONVEX,
)


@njit(cache=True)
def sphere_plane(center, radius, plane, margin, out_point, out_normal, out_depth, out_feature, slot):
    """Sphere (or particle of this radius) A against the plane B = (n, offset).

    Written in scalars (no temporary arrays): it runs once per sphere and wall every step."""
    nx, ny, nz = plane[0], plane[1], plane[2]
    distance = center[0] * nx + center[1] * ny + center[2] * nz - plane[3]
    depth = radius - distance
    if depth < -margin:
        return 0
    back = 0.5 * (radius + distance)  # the point midway between the two surfaces
    write_contact(
        out_point,
        out_normal,
        out_depth,
        out_feature,
        slot,
        (center[0] - nx * back, center[1] - ny * back, center[2] - nz * back),
        (nx, ny, nz),
        depth,
        0,
    )
    return 1


@njit(cache=True)
def sphere_sphere(center_a, radius_a, center_b, radius_b, margin, out_point, out_normal, out_depth, out_feature, slot):
    """Sphere A against sphere B (either may be a particle: a sphere of radius ≥ 0).

    Written in scalars (no temporary arrays): a pile makes thousands of these pairs a step."""
    dx, dy, dz = center_a[0] - center_b[0], center_a[1] - center_b[1], center_a[2] - center_b[2]
    distance = np.sqrt(dx * dx + dy * dy + dz * dz)
    depth = radius_a + radius_b - distance
    if depth < -margin:
        return 0
    if distance > 1e-12:
        nx, ny, nz = dx / distance, dy / distance, dz / distance
    else:  # concentric: any direction separates; pick +z
        nx, ny, nz = 0.0, 0.0, 1.0
    # midway between the surfaces: ½ (centre_a − r_a n + centre_b + r_b n)
    back = 0.5 * (radius_b - radius_a)
    write_contact(
        out_point,
        out_normal,
        out_depth,
        out_feature,
        slot,
        (
            0.5 * (center_a[0] + center_b[0]) + back * nx,
            0.5 * (center_a[1] + center_b[1]) + back * ny,
            0.5 * (center_a[2] + center_b[2]) + back * nz,
        ),
        (nx, ny, nz),
        depth,
        0,
    )
    return 1


@njit(cache=True)
def box_plane(center, rotation, half_extents, plane, margin, out_point, out_normal, out_depth, out_feature, slot):
    """Box A against plane B: one contact per corner within the margin (feature = corner 0..7)."""
    normal = plane[:3]
    count = 0
    for corner in range(8):
        sx = 1.0 if corner & 1 else -1.0
        sy = 1.0 if corner & 2 else -1.0
        sz = 1.0 if corner & 4 else -1.0
        local = np.array([sx * half_extents[0], sy * half_extents[1], sz * half_extents[2]])
        x = center + rotation @ local
        distance = x[0] * normal[0] + x[1] * normal[1] + x[2] * normal[2] - plane[3]
        if -distance >= -margin:
            write_contact(
                out_point,
                out_normal,
                out_depth,
                out_feature,
                slot + count,
                x - normal * (0.5 * distance),
                normal,
                -distance,
                corner,
            )
            count += 1
    return count


@njit(cache=True)
def sphere_box(
    center, radius, box_center, box_rotation, half_extents, margin, out_point, out_normal, out_depth, out_feature, slot
):
    """Sphere A (or particle) against box B, by the closest point of the box to the centre.

    A centre inside the box is pushed out through the nearest face (feature = 1 + face);
    outside, the feature is 0.
    """
    local = box_rotation.T @ (center - box_center)
    closest = np.minimum(np.maximum(local, -half_extents), half_extents)
    delta = local - closest
    distance = np.sqrt(delta[0] * delta[0] + delta[1] * delta[1] + delta[2] * delta[2])
    if distance > 1e-12:
        normal_local = delta / distance
        depth = radius - distance
        feature = 0
    else:
        # inside: leave through the face with the least penetration
        gaps = half_extents - np.abs(local)
        axis = np.argmin(gaps)
        normal_local = np.zeros(3)
        sign = 1.0 if local[axis] >= 0.0 else -1.0
        normal_local[axis] = sign
        closest = local.copy()
        closest[axis] = sign * half_extents[axis]
        depth = radius + gaps[axis]
        feature = 1 + 2 * axis + (1 if sign > 0 else 0)
    if depth < -margin:
        return 0
    normal = box_rotation @ normal_local
    surface_b = box_center + box_rotation @ closest
    surface_a = center - normal * radius
    write_contact(
        out_point, out_normal, out_depth, out_feature, slot, 0.5 * (surface_a + surface_b), normal, depth, feature
    )
    return 1


@njit(cache=True)
def supported(kind_a, kind_b):
    """Whether a contact routine exists for this pair (order does not matter)."""
    if kind_a > kind_b:
        kind_a, kind_b = kind_b, kind_a
    if kind_b == PLANE:
        return kind_a != PLANE
    if kind_b == shapes.MESH:  # meshes are static: only dynamic shapes meet them
        return kind_a != PLANE
    return True


def empty_hull_store():
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


# -- which pair routines a scene needs ------------------------------------------------------
#
# Compiling every pair routine costs some 30 s on a cold cache, most of it for pairs a scene
# never has (box–box and capsule–box alone are 10 s; a ball on the floor needs sphere_plane
# only). So the dispatch below is specialised on a *families* tuple, one entry per routine in
# FAMILIES: ``True`` where the scene can have such a pair, ``None`` where it cannot. Numba types
# the two apart, and the dispatch's branches for the ``None`` entries are dropped before it is
# typed, so their routines are never compiled. Each distinct tuple is one cached
# specialization (a scene of spheres and boxes on planes: four routines).

FAMILIES = (
    "sphere_sphere",
    "sphere_capsule",
    "sphere_box",
    "sphere_plane",
    "capsule_capsule",
    "capsule_box",
    "capsule_plane",
    "box_box",
    "box_plane",
    "sphere_convex",
    "capsule_convex",
    "convex_convex",
    "convex_plane",
)
HULL_FAMILIES = frozenset(("sphere_convex", "capsule_convex", "convex_convex", "convex_plane"))  # need hull_store
ALL_FAMILIES = (True,) * len(FAMILIES)  # every routine (collide_pair; tests)

_CLASS = {SPHERE: "sphere", POINT: "sphere", CAPSULE: "capsule", BOX: "box", CONVEX: "convex", PLANE: "plane"}
_ROUTINE = {
    ("sphere", "sphere"): "sphere_sphere",
    ("sphere", "capsule"): "sphere_capsule",
    ("sphere", "box"): "sphere_box",
    ("sphere", "plane"): "sphere_plane",
    ("capsule", "capsule"): "capsule_capsule",
    ("capsule", "box"): "capsule_box",
    ("capsule", "plane"): "capsule_plane",
    ("box", "box"): "box_box",
    ("box", "plane"): "box_plane",
    ("sphere", "convex"): "sphere_convex",
    ("capsule", "convex"): "capsule_convex",
    ("box", "convex"): "convex_convex",
    ("convex", "convex"): "convex_convex",
    ("convex", "plane"): "convex_plane",
}


def family(kind_a, kind_b):
    """The name in FAMILIES of the routine for a pair of shape kinds, in either order; None for
    a pair this narrow phase has no routine for (two planes; meshes, see collision.mesh_contacts)."""
    a, b = _CLASS.get(int(kind_a)), _CLASS.get(int(kind_b))
    return _ROUTINE.get((a, b)) or _ROUTINE.get((b, a))


def families_of(kind_pairs):
    """The families tuple (see FAMILIES) of an iterable of (kind_a, kind_b) pairs."""
    present = {family(a, b) for a, b in kind_pairs}
    return tuple(True if name in present else None for name in FAMILIES)


def scene_families(dynamic_kinds, static_kinds):
    """The families tuple of a scene: every pair of two dynamic colliders (two of one kind only
    if there are two such colliders) and of a dynamic collider with a static one.

    dynamic_kinds: (B + P,) the bodies' kinds and POINT per particle; static_kinds: (O,)."""
    kinds, counts = np.unique(np.asarray(dynamic_kinds, dtype=np.int64), return_counts=True)
    statics = set(np.asarray(static_kinds, dtype=np.int64).tolist())
    pairs = [(a, b) for i, a in enumerate(kinds.tolist()) for b in kinds[i:].tolist() if a != b or counts[i] > 1]
    pairs += [(a, b) for a in kinds.tolist() for b in statics]
    return families_of(pairs)


def needs_hulls(families):
    """Whether a families tuple includes a routine that reads the hull store."""
    return any(flag is not None and name in HULL_FAMILIES for name, flag in zip(FAMILIES, families))


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


@njit(cache=True)
def _hull(hull_store, index):
    """Hull number ``index`` (a float parameter) out of the store, as collision.convex.hull_view gives it."""
    (
        vertex_start,
        vertices,
        face_start,
        face_normal,
        face_offset,
        face_vertex_start,
        face_vertex_index,
        edge_start,
        edge_vertex,
        edge_face,
    ) = hull_store
    return hull_view(
        vertex_start,
        vertices,
        face_start,
        face_normal,
        face_offset,
        face_vertex_start,
        face_vertex_index,
        edge_start,
        edge_vertex,
        edge_face,
        np.int64(index),
    )


def _pairs_loop(
    families,
    pairs,
    kinds,
    params,
    centers,
    rotations_,
    reach,
    hull_store,
    out_point,
    out_normal,
    out_depth,
    out_feature,
    out_owner,
    slot,
):
    """The contacts of every pair k of ``pairs`` (K, 2), reaching gaps down to ``reach[k]``,
    written from row ``slot`` on in pair order, with ``out_owner`` = k; returns how many were
    written. Each pair is taken in canonical order (rank of A ≤ rank of B; computed swapped and
    its normals flipped otherwise). A pair whose family is ``None`` in ``families`` (see
    FAMILIES), or that has no routine, gets none. Compiled code only (the overload below)."""
    raise NotImplementedError("compiled code only")


@overload(_pairs_loop)
def _pairs_loop_for(
    families,
    pairs,
    kinds,
    params,
    centers,
    rotations_,
    reach,
    hull_store,
    out_point,
    out_normal,
    out_depth,
    out_feature,
    out_owner,
    slot,
):
    """The loop for one families type. Its ``None`` entries are the constant False here, so
    Numba drops those routines' branches before typing and never compiles them. The loop and
    the dispatch are one function: a call per pair that handed over the arrays (and the hull
    store's ten) would cost more than a sphere pair itself."""
    if not isinstance(families, types.BaseTuple) or len(families) != len(FAMILIES):
        raise TypingError(f"families: expected a tuple of {len(FAMILIES)} True or None, found {families}")
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
    ) = (not isinstance(t, types.NoneType) for t in families.types)

    def loop(
        families,
        pairs,
        kinds,
        params,
        centers,
        rotations_,
        reach,
        hull_store,
        out_point,
        out_normal,
        out_depth,
        out_feature,
        out_owner,
        slot,
    ):
        count = slot
        for k in range(pairs.shape[0]):
            a, b = pairs[k, 0], pairs[k, 1]
            swapped = _rank(kinds[a]) > _rank(kinds[b])
            if swapped:
                a, b = b, a
            kind_a, kind_b = kinds[a], kinds[b]
            params_a, center_a, rotation_a = params[a], centers[a], rotations_[a]
            params_b, center_b, rotation_b = params[b], centers[b], rotations_[b]
            margin = reach[k]
            round_a = kind_a == SPHERE or kind_a == POINT
            round_b = kind_b == SPHERE or kind_b == POINT
            written = 0
            if has_sphere_sphere:
                if round_a and round_b:
                    written = sphere_sphere(
                        center_a,
                        params_a[0],
                        center_b,
                        params_b[0],
                        margin,
                        out_point,
                        out_normal,
                        out_depth,
                        out_feature,
                        count,
                    )
            if has_sphere_capsule:
                if round_a and kind_b == CAPSULE:
                    written = sphere_capsule(
                        center_a,
                        params_a[0],
                        center_b,
                        rotation_b,
                        params_b[0],
                        params_b[1],
                        margin,
                        out_point,
                        out_normal,
                        out_depth,
                        out_feature,
                        count,
                    )
            if has_sphere_box:
                if round_a and kind_b == BOX:
                    written = sphere_box(
                        center_a,
                        params_a[0],
                        center_b,
                        rotation_b,
                        params_b[:3],
                        margin,
                        out_point,
                        out_normal,
                        out_depth,
                        out_feature,
                        count,
                    )
            if has_sphere_plane:
                if round_a and kind_b == PLANE:
                    written = sphere_plane(
                        center_a, params_a[0], params_b, margin, out_point, out_normal, out_depth, out_feature, count
                    )
            if has_capsule_capsule:
                if kind_a == CAPSULE and kind_b == CAPSULE:
                    written = capsule_capsule(
                        center_a,
                        rotation_a,
                        params_a[0],
                        params_a[1],
                        center_b,
                        rotation_b,
                        params_b[0],
                        params_b[1],
                        margin,
                        out_point,
                        out_normal,
                        out_depth,
                        out_feature,
                        count,
                    )
            if has_capsule_box:
                if kind_a == CAPSULE and kind_b == BOX:
                    written = capsule_box(
                        center_a,
                        rotation_a,
                        params_a[0],
                        params_a[1],
                        center_b,
                        rotation_b,
                        params_b[:3],
                        margin,
                        out_point,
                        out_normal,
                        out_depth,
                        out_feature,
                        count,
                    )
            if has_capsule_plane:
                if kind_a == CAPSULE and kind_b == PLANE:
                    written = capsule_plane(
                        center_a,
                        rotation_a,
                        params_a[0],
                        params_a[1],
                        params_b,
                        margin,
                        out_point,
                        out_normal,
                        out_depth,
                        out_feature,
                        count,
                    )
            if has_box_box:
                if kind_a == BOX and kind_b == BOX:
                    written = box_box(
                        center_a,
                        rotation_a,
                        params_a[:3],
                        center_b,
                        rotation_b,
                        params_b[:3],
                        margin,
                        out_point,
                        out_normal,
                        out_depth,
                        out_feature,
                        count,
                    )
            if has_box_plane:
                if kind_a == BOX and kind_b == PLANE:
                    written = box_plane(
                        center_a,
                        rotation_a,
                        params_a[:3],
                        params_b,
                        margin,
                        out_point,
                        out_normal,
                        out_depth,
                        out_feature,
                        count,
                    )
            if has_sphere_convex:
                if round_a and kind_b == CONVEX:
                    hb = _hull(hull_store, params_b[0])
                    written = sphere_convex(
                        center_a,
                        params_a[0],
                        center_b,
                        rotation_b,
                        hb[0],
                        hb[1],
                        hb[2],
                        hb[3],
                        hb[4],
                        margin,
                        out_point,
                        out_normal,
                        out_depth,
                        out_feature,
                        count,
                    )
            if has_capsule_convex:
                if kind_a == CAPSULE and kind_b == CONVEX:
                    hb = _hull(hull_store, params_b[0])
                    written = capsule_convex(
                        center_a,
                        rotation_a,
                        params_a[0],
                        params_a[1],
                        center_b,
                        rotation_b,
                        hb[0],
                        hb[1],
                        hb[2],
                        hb[3],
                        hb[4],
                        hb[5],
                        hb[6],
                        margin,
                        out_point,
                        out_normal,
                        out_depth,
                        out_feature,
                        count,
                    )
            if has_convex_convex:
                if (kind_a == BOX or kind_a == CONVEX) and kind_b == CONVEX:
                    ha = _hull(hull_store, params_a[0] if kind_a == CONVEX else params_a[3])
                    hb = _hull(hull_store, params_b[0])
                    written = convex_convex(
                        center_a,
                        rotation_a,
                        ha[0],
                        ha[1],
                        ha[2],
                        ha[3],
                        ha[4],
                        ha[5],
                        ha[6],
                        center_b,
                        rotation_b,
                        hb[0],
                        hb[1],
                        hb[2],
                        hb[3],
                        hb[4],
                        hb[5],
                        hb[6],
                        margin,
                        out_point,
                        out_normal,
                        out_depth,
                        out_feature,
                        count,
                    )
            if has_convex_plane:
                if kind_a == CONVEX and kind_b == PLANE:
                    ha = _hull(hull_store, params_a[0])
                    written = convex_plane(
                        center_a,
                        rotation_a,
                        ha[0],
                        params_b,
                        margin,
                        out_point,
                        out_normal,
                        out_depth,
                        out_feature,
                        count,
                    )
            for c in range(count, count + written):
                if swapped:  # normals from B into A of the pair as given
                    for i in range(3):
                        out_normal[c, i] = -out_normal[c, i]
                out_owner[c] = k
            count += written
        return count - slot

    return loop


@njit(cache=True)
def collide_pair(
    kind_a,
    params_a,
    center_a,
    rotation_a,
    kind_b,
    params_b,
    center_b,
    rotation_b,
    margin,
    hull_store,
    out_point,
    out_normal,
    out_depth,
    out_feature,
    slot,
):
    """Contacts of shape A against shape B written from ``slot`` on; returns their count
    (at most MAX_PER_PAIR). Swapping the two shapes flips the normal and nothing else. Every
    routine is compiled in: the scene-wide narrow phase (``generate_contacts``) compiles only
    the families it is given.

    kind, params (4,), centre (3,) [m] and rotation (3, 3) (body → world) of each shape;
    margin [m]: contacts with gaps down to −margin are kept; hull_store: the model's packed
    hulls (Model.hull_store, or ``empty_hull_store()``); out_point, out_normal (n, 3),
    out_depth (n,) [m], out_feature (n,) int64: the rows written from ``slot`` on."""
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
    owner = np.empty(out_depth.shape[0], dtype=np.int64)
    return _pairs_loop(
        ALL_FAMILIES,
        np.array([[0, 1]], dtype=np.int64),
        kinds,
        params,
        centers,
        rotations_,
        np.full(1, margin),
        hull_store,
        out_point,
        out_normal,
        out_depth,
        out_feature,
        owner,
        np.int64(slot),
    )


@njit(cache=True)
def generate_contacts(pairs, kinds, params, centers, rotations_, reach, hull_store, families):
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
        kinds,
        params,
        centers,
        rotations_,
        reach,
        hull_store,
        point,
        normal,
        depth,
        feature,
        owner,
        np.int64(0),
    )
    return point[:count], normal[:count], depth[:count], feature[:count], owner[:count]
