"""The sphere and box pair routines against planes, spheres and boxes: sphere–plane,
sphere–sphere, box–plane and sphere–box (a particle is a sphere of its radius).

Conventions as in :mod:`contactlab.collision.narrow_phase`, which dispatches to them: shape A
is the first argument, the normal points from B into A, ``depth`` > 0 when overlapping,
contacts down to ``depth = −margin`` are kept, each written from index ``slot`` on into ``out``
= (point (N, 3), normal (N, 3), depth (N,), feature (N,) int64)
(:data:`.contact_output.PairOutput`); each returns how many it wrote. A shape is passed as
one argument, the tuple of what places and sizes it: a sphere as :data:`Sphere`, a box as
:data:`Box`, a plane as its (4,) array (n_x, n_y, n_z, offset [m]), unit n, solid side
n · x < offset.
"""

import numpy as np

from ..compiling import njit
from .contact_output import Frame, PairOutput, write_contact
from .geometry import rotate, to_local

Sphere = tuple[np.ndarray, float]  # (centre (3,) [m], radius [m] ≥ 0) of a sphere or a particle
Box = tuple[Frame, np.ndarray]  # (frame: centre (3,) [m], rotation (3, 3) body → world; half extents (3,) [m])


@njit(cache=True)
def sphere_plane(sphere: Sphere, plane: np.ndarray, margin: float, out: PairOutput, slot: int) -> int:
    """Sphere (or particle of this radius) A against the plane B = (n, offset).

    Written in scalars (no temporary arrays): it runs once per sphere and wall every step."""
    center, radius = sphere
    nx, ny, nz = plane[0], plane[1], plane[2]
    distance = center[0] * nx + center[1] * ny + center[2] * nz - plane[3]
    depth = radius - distance
    if depth < -margin:
        return 0
    back = 0.5 * (radius + distance)  # the point midway between the two surfaces
    write_contact(
        out, slot, (center[0] - nx * back, center[1] - ny * back, center[2] - nz * back), (nx, ny, nz), depth, 0
    )
    return 1


@njit(cache=True)
def sphere_sphere(sphere_a: Sphere, sphere_b: Sphere, margin: float, out: PairOutput, slot: int) -> int:
    """Sphere A against sphere B (either may be a particle: a sphere of radius ≥ 0).

    Written in scalars (no temporary arrays): a pile makes thousands of these pairs a step."""
    center_a, radius_a = sphere_a
    center_b, radius_b = sphere_b
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
        out,
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
def box_plane(box: Box, plane: np.ndarray, margin: float, out: PairOutput, slot: int) -> int:
    """Box A against plane B: one contact per corner within the margin (feature = corner 0..7)."""
    frame, half_extents = box
    center, rotation = frame
    normal = plane[:3]
    count = 0
    for corner in range(8):
        sx = 1.0 if corner & 1 else -1.0
        sy = 1.0 if corner & 2 else -1.0
        sz = 1.0 if corner & 4 else -1.0
        local = np.array([sx * half_extents[0], sy * half_extents[1], sz * half_extents[2]])
        x = center + rotate(rotation, local)
        distance = x[0] * normal[0] + x[1] * normal[1] + x[2] * normal[2] - plane[3]
        if -distance >= -margin:
            write_contact(out, slot + count, x - normal * (0.5 * distance), normal, -distance, corner)
            count += 1
    return count


@njit(cache=True)
def sphere_box(sphere: Sphere, box: Box, margin: float, out: PairOutput, slot: int) -> int:
    """Sphere A (or particle) against box B, by the closest point of the box to the centre.

    A centre inside the box is pushed out through the nearest face (feature = 1 + face);
    outside, the feature is 0.
    """
    center, radius = sphere
    box_frame, half_extents = box
    box_center, box_rotation = box_frame
    local = to_local(box_rotation, box_center, center)
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
    normal = rotate(box_rotation, normal_local)
    surface_b = box_center + rotate(box_rotation, closest)
    surface_a = center - normal * radius
    write_contact(out, slot, 0.5 * (surface_a + surface_b), normal, depth, feature)
    return 1
