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
from .contact_output import write_contact
from .box_box import box_box
from .capsule import capsule_box, capsule_capsule, capsule_plane, sphere_capsule
from .capsule_convex import capsule_convex
from .convex import convex_convex, convex_plane, hull_view, sphere_convex

MAX_PER_PAIR = 8

SPHERE, BOX, PLANE, POINT, CAPSULE, CONVEX = (shapes.SPHERE, shapes.BOX, shapes.PLANE, shapes.POINT,
                                              shapes.CAPSULE, shapes.CONVEX)


@njit(cache=True)
def sphere_plane(center, radius, plane, margin, out_point, out_normal, out_depth, out_feature, slot):
    """Sphere (or particle of this radius) A against the plane B = (n, offset).

    Written in scalars (no temporary arrays): it runs once per sphere and wall every step."""
    nx, ny, nz = plane[0], plane[1], plane[2]
    distance = center[0] * nx + center[1] * ny + center[2] * nz - plane[3]
    depth = radius - distance
    if depth < -margin:
        return 0
    back = 0.5 * (radius + distance)            # the point midway between the two surfaces
    write_contact(out_point, out_normal, out_depth, out_feature, slot,
                  (center[0] - nx * back, center[1] - ny * back, center[2] - nz * back), (nx, ny, nz), depth, 0)
    return 1


@njit(cache=True)
def sphere_sphere(center_a, radius_a, center_b, radius_b, margin,
                  out_point, out_normal, out_depth, out_feature, slot):
    """Sphere A against sphere B (either may be a particle: a sphere of radius ≥ 0).

    Written in scalars (no temporary arrays): a pile makes thousands of these pairs a step."""
    dx, dy, dz = center_a[0] - center_b[0], center_a[1] - center_b[1], center_a[2] - center_b[2]
    distance = np.sqrt(dx * dx + dy * dy + dz * dz)
    depth = radius_a + radius_b - distance
    if depth < -margin:
        return 0
    if distance > 1e-12:
        nx, ny, nz = dx / distance, dy / distance, dz / distance
    else:                       # concentric: any direction separates; pick +z
        nx, ny, nz = 0.0, 0.0, 1.0
    # midway between the surfaces: ½ (centre_a − r_a n + centre_b + r_b n)
    back = 0.5 * (radius_b - radius_a)
    write_contact(out_point, out_normal, out_depth, out_feature, slot,
                  (0.5 * (center_a[0] + center_b[0]) + back * nx, 0.5 * (center_a[1] + center_b[1]) + back * ny,
                   0.5 * (center_a[2] + center_b[2]) + back * nz), (nx, ny, nz), depth, 0)
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
            write_contact(out_point, out_normal, out_depth, out_feature, slot + count,
                   x - normal * (0.5 * distance), normal, -distance, corner)
            count += 1
    return count


@njit(cache=True)
def sphere_box(center, radius, box_center, box_rotation, half_extents, margin,
               out_point, out_normal, out_depth, out_feature, slot):
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
    write_contact(out_point, out_normal, out_depth, out_feature, slot, 0.5 * (surface_a + surface_b), normal, depth, feature)
    return 1


@njit(cache=True)
def supported(kind_a, kind_b):
    """Whether a contact routine exists for this pair (order does not matter)."""
    if kind_a > kind_b:
        kind_a, kind_b = kind_b, kind_a
    if kind_b == PLANE:
        return kind_a != PLANE
    if kind_b == shapes.MESH:            # meshes are static: only dynamic shapes meet them
        return kind_a != PLANE
    return True


def empty_hull_store():
    """A hull store with no hulls, for pairs that need none (see Model.hull_store).

    Read-only like a Model's, so the compiled dispatch is the same one (Numba types read-only
    and writable arrays apart and would compile everything twice)."""
    store = (np.zeros(1, dtype=np.int64), np.zeros((0, 3)), np.zeros(1, dtype=np.int64), np.zeros((0, 3)),
             np.zeros(0), np.zeros(1, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros(1, dtype=np.int64),
             np.zeros((0, 2), dtype=np.int64), np.zeros((0, 2), dtype=np.int64))
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

FAMILIES = ("sphere_sphere", "sphere_capsule", "sphere_box", "sphere_plane", "capsule_capsule", "capsule_box",
            "capsule_plane", "box_box", "box_plane", "sphere_convex", "capsule_convex", "convex_convex",
            "convex_plane")
HULL_FAMILIES = frozenset(("sphere_convex", "capsule_convex", "convex_convex", "convex_plane"))  # need hull_store
ALL_FAMILIES = (True,) * len(FAMILIES)         # every routine (collide_pair; tests)

_CLASS = {SPHERE: "sphere", POINT: "sphere", CAPSULE: "capsule", BOX: "box", CONVEX: "convex", PLANE: "plane"}
_ROUTINE = {("sphere", "sphere"): "sphere_sphere", ("sphere", "capsule"): "sphere_capsule",
            ("sphere", "box"): "sphere_box", ("sphere", "plane"): "sphere_plane",
            ("capsule", "capsule"): "capsule_capsule", ("capsule", "box"): "capsule_box",
            ("capsule", "plane"): "capsule_plane", ("box", "box"): "box_box", ("box", "plane"): "box_plane",
            ("sphere", "convex"): "sphere_convex", ("capsule", "convex"): "capsule_convex",
            ("box", "convex"): "convex_convex", ("convex", "convex"): "convex_convex",
            ("convex", "plane"): "convex_plane"}


def family(kind_a, kind_b):
    """The name in FAMILIES of the routine for a pair of shape kinds, in either order; None for
    a pair this narrow phase has no routine for (two planes; meshes, see collision.mesh_pairs)."""
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
    (vertex_start, vertices, face_start, face_normal, face_offset, face_vertex_start, face_vertex_index,
     edge_start, edge_vertex, edge_face) = hull_store
    return hull_view(vertex_start, vertices, face_start, face_normal, face_offset, face_vertex_start,
                     face_vertex_index, edge_start, edge_vertex, edge_face, np.int64(index))


def _ordered(families, kind_a, params_a, center_a, rotation_a, kind_b, params_b, center_b, rotation_b,
             margin, hull_store, out_point, out_normal, out_depth, out_feature, slot):
    """The pair routines in canonical order (rank of A ≤ rank of B): the contacts of the pair
    written from ``slot`` on, their count returned; 0 for an unknown pair or one whose family
    is ``None`` in ``families``. Compiled code only (see the overload below)."""
    raise NotImplementedError("compiled code only")


@overload(_ordered)
def _ordered_for(families, kind_a, params_a, center_a, rotation_a, kind_b, params_b, center_b, rotation_b,
                 margin, hull_store, out_point, out_normal, out_depth, out_feature, slot):
    """The dispatch for one families type: its ``None`` entries are constant False here, so
    Numba prunes their branches before typing and never compiles those routines."""
    if not isinstance(families, types.BaseTuple) or len(families) != len(FAMILIES):
        raise TypingError(f"families: expected a tuple of {len(FAMILIES)} True or None, found {families}")
    (has_sphere_sphere, has_sphere_capsule, has_sphere_box, has_sphere_plane, has_capsule_capsule,
     has_capsule_box, has_capsule_plane, has_box_box, has_box_plane, has_sphere_convex, has_capsule_convex,
     has_convex_convex, has_convex_plane) = (not isinstance(t, types.NoneType) for t in families.types)

    def ordered(families, kind_a, params_a, center_a, rotation_a, kind_b, params_b, center_b, rotation_b,
                margin, hull_store, out_point, out_normal, out_depth, out_feature, slot):
        round_a = kind_a == SPHERE or kind_a == POINT
        round_b = kind_b == SPHERE or kind_b == POINT
        if has_sphere_sphere:
            if round_a and round_b:
                return sphere_sphere(center_a, params_a[0], center_b, params_b[0], margin,
                                     out_point, out_normal, out_depth, out_feature, slot)
        if has_sphere_capsule:
            if round_a and kind_b == CAPSULE:
                return sphere_capsule(center_a, params_a[0], center_b, rotation_b, params_b[0], params_b[1],
                                      margin, out_point, out_normal, out_depth, out_feature, slot)
        if has_sphere_box:
            if round_a and kind_b == BOX:
                return sphere_box(center_a, params_a[0], center_b, rotation_b, params_b[:3], margin,
                                  out_point, out_normal, out_depth, out_feature, slot)
        if has_sphere_plane:
            if round_a and kind_b == PLANE:
                return sphere_plane(center_a, params_a[0], params_b, margin,
                                    out_point, out_normal, out_depth, out_feature, slot)
        if has_capsule_capsule:
            if kind_a == CAPSULE and kind_b == CAPSULE:
                return capsule_capsule(center_a, rotation_a, params_a[0], params_a[1], center_b, rotation_b,
                                       params_b[0], params_b[1], margin,
                                       out_point, out_normal, out_depth, out_feature, slot)
        if has_capsule_box:
            if kind_a == CAPSULE and kind_b == BOX:
                return capsule_box(center_a, rotation_a, params_a[0], params_a[1], center_b, rotation_b,
                                   params_b[:3], margin, out_point, out_normal, out_depth, out_feature, slot)
        if has_capsule_plane:
            if kind_a == CAPSULE and kind_b == PLANE:
                return capsule_plane(center_a, rotation_a, params_a[0], params_a[1], params_b, margin,
                                     out_point, out_normal, out_depth, out_feature, slot)
        if has_box_box:
            if kind_a == BOX and kind_b == BOX:
                return box_box(center_a, rotation_a, params_a[:3], center_b, rotation_b, params_b[:3], margin,
                               out_point, out_normal, out_depth, out_feature, slot)
        if has_box_plane:
            if kind_a == BOX and kind_b == PLANE:
                return box_plane(center_a, rotation_a, params_a[:3], params_b, margin,
                                 out_point, out_normal, out_depth, out_feature, slot)
        if has_sphere_convex:
            if round_a and kind_b == CONVEX:
                b = _hull(hull_store, params_b[0])
                return sphere_convex(center_a, params_a[0], center_b, rotation_b, b[0], b[1], b[2], b[3], b[4],
                                     margin, out_point, out_normal, out_depth, out_feature, slot)
        if has_capsule_convex:
            if kind_a == CAPSULE and kind_b == CONVEX:
                b = _hull(hull_store, params_b[0])
                return capsule_convex(center_a, rotation_a, params_a[0], params_a[1], center_b, rotation_b,
                                      b[0], b[1], b[2], b[3], b[4], b[5], b[6], margin,
                                      out_point, out_normal, out_depth, out_feature, slot)
        if has_convex_convex:
            if (kind_a == BOX or kind_a == CONVEX) and kind_b == CONVEX:
                a = _hull(hull_store, params_a[0] if kind_a == CONVEX else params_a[3])
                b = _hull(hull_store, params_b[0])
                return convex_convex(center_a, rotation_a, a[0], a[1], a[2], a[3], a[4], a[5], a[6],
                                     center_b, rotation_b, b[0], b[1], b[2], b[3], b[4], b[5], b[6], margin,
                                     out_point, out_normal, out_depth, out_feature, slot)
        if has_convex_plane:
            if kind_a == CONVEX and kind_b == PLANE:
                a = _hull(hull_store, params_a[0])
                return convex_plane(center_a, rotation_a, a[0], params_b, margin,
                                    out_point, out_normal, out_depth, out_feature, slot)
        return 0

    return ordered


@njit(cache=True, inline="always")
def _flip_normals(out_normal, slot, count):
    """Reverse the normals of rows slot … slot + count − 1 (a pair computed swapped)."""
    for i in range(slot, slot + count):
        for k in range(3):
            out_normal[i, k] = -out_normal[i, k]


@njit(cache=True, inline="always")
def collide_families(families, kind_a, params_a, center_a, rotation_a, kind_b, params_b, center_b, rotation_b,
                     margin, hull_store, out_point, out_normal, out_depth, out_feature, slot):
    """``collide_pair`` with only the routines of ``families`` (see FAMILIES): a pair of another
    family gets 0 contacts. ``hull_store`` may be None when no hull family is in ``families``.

    A pair given out of canonical order is computed swapped and its normals flipped, so
    swapping the two shapes flips the normal and nothing else."""
    if _rank(kind_a) <= _rank(kind_b):
        return _ordered(families, kind_a, params_a, center_a, rotation_a, kind_b, params_b, center_b, rotation_b,
                        margin, hull_store, out_point, out_normal, out_depth, out_feature, slot)
    count = _ordered(families, kind_b, params_b, center_b, rotation_b, kind_a, params_a, center_a, rotation_a,
                     margin, hull_store, out_point, out_normal, out_depth, out_feature, slot)
    _flip_normals(out_normal, slot, count)
    return count


@njit(cache=True)
def collide_pair(kind_a, params_a, center_a, rotation_a, kind_b, params_b, center_b, rotation_b,
                 margin, hull_store, out_point, out_normal, out_depth, out_feature, slot):
    """Contacts of shape A against shape B written from ``slot`` on; returns their count
    (at most MAX_PER_PAIR). Every routine is compiled in: the scene-wide narrow phase
    (``generate_contacts``) compiles only the families it is given.

    kind, params (4,), centre (3,) [m] and rotation (3, 3) (body → world) of each shape;
    margin [m]: contacts with gaps down to −margin are kept; hull_store: the model's packed
    hulls (Model.hull_store, or ``empty_hull_store()``); out_point, out_normal (n, 3),
    out_depth (n,) [m], out_feature (n,) int64: the rows written from ``slot`` on."""
    return collide_families(ALL_FAMILIES, kind_a, params_a, center_a, rotation_a, kind_b, params_b, center_b,
                            rotation_b, margin, hull_store, out_point, out_normal, out_depth, out_feature, slot)


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
    owner = np.empty(capacity, dtype=np.int64)      # which pair each contact came from
    # an int64 from the start: a literal 0 would have Numba type every routine for slot = 0 first
    # and compile each of them twice
    count = np.int64(0)
    for k in range(len(pairs)):
        a, b = pairs[k, 0], pairs[k, 1]
        written = collide_families(families, kinds[a], params[a], centers[a], rotations_[a],
                                   kinds[b], params[b], centers[b], rotations_[b],
                                   reach[k], hull_store, point, normal, depth, feature, count)
        for c in range(count, count + written):
            owner[c] = k
        count += written
    return point[:count], normal[:count], depth[:count], feature[:count], owner[:count]
