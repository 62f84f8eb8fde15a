"""Narrow phase: one compiled function per shape pair, and a dispatcher.

Every pair function takes shape A then shape B and writes contacts whose normal points
from B into A, ``depth`` > 0 when overlapping (contacts down to ``depth = −margin`` are kept,
for speculative use), and ``point`` midway between the two surfaces. It returns how many
contacts it wrote (at most ``MAX_PER_PAIR``) and a feature number for each, which makes the
contact id persistent. Shapes are described as in :mod:`contactlab.shapes`: a kind, a row of
4 parameters, a centre and a rotation matrix (body → world).
"""

import numpy as np
from numba import njit

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


@njit(cache=True, inline="always")
def _primitives_ordered(kind_a, params_a, center_a, rotation_a, kind_b, params_b, center_b, rotation_b,
                        margin, out_point, out_normal, out_depth, out_feature, slot):
    """The pairs without a convex hull, in canonical order (rank of A ≤ rank of B); 0 contacts
    for an unknown pair."""
    round_a = kind_a == SPHERE or kind_a == POINT
    round_b = kind_b == SPHERE or kind_b == POINT
    if round_a and round_b:
        return sphere_sphere(center_a, params_a[0], center_b, params_b[0], margin,
                             out_point, out_normal, out_depth, out_feature, slot)
    if round_a and kind_b == CAPSULE:
        return sphere_capsule(center_a, params_a[0], center_b, rotation_b, params_b[0], params_b[1], margin,
                              out_point, out_normal, out_depth, out_feature, slot)
    if round_a and kind_b == BOX:
        return sphere_box(center_a, params_a[0], center_b, rotation_b, params_b[:3], margin,
                          out_point, out_normal, out_depth, out_feature, slot)
    if round_a and kind_b == PLANE:
        return sphere_plane(center_a, params_a[0], params_b, margin, out_point, out_normal, out_depth, out_feature, slot)
    if kind_a == CAPSULE and kind_b == CAPSULE:
        return capsule_capsule(center_a, rotation_a, params_a[0], params_a[1], center_b, rotation_b, params_b[0],
                               params_b[1], margin, out_point, out_normal, out_depth, out_feature, slot)
    if kind_a == CAPSULE and kind_b == BOX:
        return capsule_box(center_a, rotation_a, params_a[0], params_a[1], center_b, rotation_b, params_b[:3],
                           margin, out_point, out_normal, out_depth, out_feature, slot)
    if kind_a == CAPSULE and kind_b == PLANE:
        return capsule_plane(center_a, rotation_a, params_a[0], params_a[1], params_b, margin,
                             out_point, out_normal, out_depth, out_feature, slot)
    if kind_a == BOX and kind_b == BOX:
        return box_box(center_a, rotation_a, params_a[:3], center_b, rotation_b, params_b[:3], margin,
                       out_point, out_normal, out_depth, out_feature, slot)
    if kind_a == BOX and kind_b == PLANE:
        return box_plane(center_a, rotation_a, params_a[:3], params_b, margin,
                         out_point, out_normal, out_depth, out_feature, slot)
    return 0


@njit(cache=True)
def _hulls_ordered(kind_a, params_a, center_a, rotation_a, kind_b, params_b, center_b, rotation_b,
                   margin, hull_store, out_point, out_normal, out_depth, out_feature, slot):
    """The pairs with a convex hull, in canonical order; 0 contacts for an unknown pair.

    hull_store: the model's packed hulls (Model.hull_store); convex shapes and boxes index it.
    """
    round_a = kind_a == SPHERE or kind_a == POINT
    if kind_a == CAPSULE and kind_b == CONVEX:
        b = _hull(hull_store, params_b[0])
        return capsule_convex(center_a, rotation_a, params_a[0], params_a[1], center_b, rotation_b,
                              b[0], b[1], b[2], b[3], b[4], b[5], b[6], margin,
                              out_point, out_normal, out_depth, out_feature, slot)
    if round_a and kind_b == CONVEX:
        b = _hull(hull_store, params_b[0])
        return sphere_convex(center_a, params_a[0], center_b, rotation_b, b[0], b[1], b[2], b[3], b[4], margin,
                             out_point, out_normal, out_depth, out_feature, slot)
    if (kind_a == BOX or kind_a == CONVEX) and kind_b == CONVEX:
        a = _hull(hull_store, params_a[0] if kind_a == CONVEX else params_a[3])
        b = _hull(hull_store, params_b[0])
        return convex_convex(center_a, rotation_a, a[0], a[1], a[2], a[3], a[4], a[5], a[6],
                             center_b, rotation_b, b[0], b[1], b[2], b[3], b[4], b[5], b[6], margin,
                             out_point, out_normal, out_depth, out_feature, slot)
    if kind_a == CONVEX and kind_b == PLANE:
        a = _hull(hull_store, params_a[0])
        return convex_plane(center_a, rotation_a, a[0], params_b, margin,
                            out_point, out_normal, out_depth, out_feature, slot)
    return 0


@njit(cache=True, inline="always")
def _flip_normals(out_normal, slot, count):
    """Reverse the normals of rows slot … slot + count − 1 (a pair computed swapped)."""
    for i in range(slot, slot + count):
        for k in range(3):
            out_normal[i, k] = -out_normal[i, k]


@njit(cache=True, inline="always")
def collide_primitive_pair(kind_a, params_a, center_a, rotation_a, kind_b, params_b, center_b, rotation_b,
                           margin, out_point, out_normal, out_depth, out_feature, slot):
    """``collide_pair`` for two shapes neither of which is convex (spheres, points, capsules,
    boxes, planes): the same contacts without the hull store. Handing a tuple of ten arrays to
    a function costs more than a sphere pair itself (~150 ns against ~15), so the per-pair loop
    calls this for every pair that needs no hull."""
    if _rank(kind_a) <= _rank(kind_b):
        return _primitives_ordered(kind_a, params_a, center_a, rotation_a, kind_b, params_b, center_b, rotation_b,
                                   margin, out_point, out_normal, out_depth, out_feature, slot)
    count = _primitives_ordered(kind_b, params_b, center_b, rotation_b, kind_a, params_a, center_a, rotation_a,
                                margin, out_point, out_normal, out_depth, out_feature, slot)
    _flip_normals(out_normal, slot, count)
    return count


@njit(cache=True)
def _hull(hull_store, index):
    """Hull number ``index`` (a float parameter) out of the store, as collision.convex.hull_view gives it."""
    (vertex_start, vertices, face_start, face_normal, face_offset, face_vertex_start, face_vertex_index,
     edge_start, edge_vertex, edge_face) = hull_store
    return hull_view(vertex_start, vertices, face_start, face_normal, face_offset, face_vertex_start,
                     face_vertex_index, edge_start, edge_vertex, edge_face, np.int64(index))


@njit(cache=True)
def collide_pair(kind_a, params_a, center_a, rotation_a, kind_b, params_b, center_b, rotation_b,
                 margin, hull_store, out_point, out_normal, out_depth, out_feature, slot):
    """Contacts of shape A against shape B written from ``slot`` on; returns their count.

    A pair given out of canonical order is computed swapped and its normals flipped, so
    swapping the two shapes flips the normal and nothing else.
    """
    if kind_a != CONVEX and kind_b != CONVEX:
        return collide_primitive_pair(kind_a, params_a, center_a, rotation_a, kind_b, params_b, center_b,
                                      rotation_b, margin, out_point, out_normal, out_depth, out_feature, slot)
    if _rank(kind_a) <= _rank(kind_b):
        return _hulls_ordered(kind_a, params_a, center_a, rotation_a, kind_b, params_b, center_b, rotation_b,
                              margin, hull_store, out_point, out_normal, out_depth, out_feature, slot)
    count = _hulls_ordered(kind_b, params_b, center_b, rotation_b, kind_a, params_a, center_a, rotation_a,
                           margin, hull_store, out_point, out_normal, out_depth, out_feature, slot)
    _flip_normals(out_normal, slot, count)
    return count


@njit(cache=True)
def generate_contacts(pairs, kinds, params, centers, rotations_, reach, hull_store):
    """The narrow phase over ``pairs`` (K, 2) of global colliders: (point, normal, depth, feature,
    owner) of every contact, owner being its pair's row, with gaps down to ``reach`` (K,) [m] of
    its pair. ``hull_store`` is None when no collider
    is a convex hull: that specialization never compiles the hull routines (``collide_pair``),
    which are most of a cold start's compile time (about 40 of 90 s for a bouncing ball)."""
    capacity = len(pairs) * MAX_PER_PAIR
    point = np.empty((capacity, 3))
    normal = np.empty((capacity, 3))
    depth = np.empty(capacity)
    feature = np.empty(capacity, dtype=np.int64)
    owner = np.empty(capacity, dtype=np.int64)      # which pair each contact came from
    count = 0
    for k in range(len(pairs)):
        a, b = pairs[k, 0], pairs[k, 1]
        hull = False
        if hull_store is not None:          # pruned at compile time when there is no hull
            if kinds[a] == shapes.CONVEX or kinds[b] == shapes.CONVEX:
                hull = True
                written = collide_pair(kinds[a], params[a], centers[a], rotations_[a],
                                       kinds[b], params[b], centers[b], rotations_[b],
                                       reach[k], hull_store, point, normal, depth, feature, count)
        if not hull:    # the same contacts without handing over the hull store (see collide_primitive_pair)
            written = collide_primitive_pair(kinds[a], params[a], centers[a], rotations_[a],
                                             kinds[b], params[b], centers[b], rotations_[b],
                                             reach[k], point, normal, depth, feature, count)
        owner[count:count + written] = k
        count += written
    return point[:count], normal[:count], depth[:count], feature[:count], owner[:count]
