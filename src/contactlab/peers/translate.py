"""The engine-neutral half of translating a contactlab Model for a peer engine (MuJoCo, pybullet).

What every peer is given of a finalized :class:`~contactlab.model.Model`, and what no peer can
be given, so that contactlab.peers.mujoco and contactlab.peers.pybullet each only spell it in
their engine's terms:

* :func:`solids`: each body's and each static obstacle's collision shape as a :class:`Solid`
  (kind, sizes [m], pose, material, a convex body's hull corners, a mesh's triangles);
* :func:`sheets`: each cloth as a :class:`Sheet` (its vertices in the model's particle order,
  triangles, masses, pinned vertices, thickness, material) with the isotropic membrane closest
  to its spring network (:func:`membrane`), for an engine whose cloth is a continuum;
* :func:`gaps`: one sentence for each thing in the model a peer cannot express (cloth for
  pybullet, particles, a kinematic path, a non-convex mesh for MuJoCo), so the caller reports it
  instead of running a different scene;
* :func:`pair_targets` and :func:`closest_values`: contactlab's contact materials (μ = √(μ_a μ_b),
  ε = max(ε_a, ε_b) of the two colliders' materials) against an engine that keeps one value per
  shape and combines two by its own rule (pybullet multiplies, MuJoCo takes the larger friction
  and the mean of the damping): the per-material values that meet contactlab's pairs, and a
  sentence for each pair of this scene that the rule cannot meet (MuJoCo's stand-in for a
  restitution coefficient it lacks is its own: contactlab.peers.mujoco.damping_for).

The mapping is written out per engine in docs/peers.md.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from .. import shapes
from ..model import Model

PEERS = ("mujoco", "pybullet")  # the engines contactlab.peers can run a scene in
MATCHED = 1e-9  # a combined value this close to contactlab's is the same
POISSON = 1.0 / 3.0  # the Poisson ratio of the isotropic membrane closest to any network of central springs
FLEX_MUJOCO = (4, 0)  # the MuJoCo whose 2D flex elasticity has the constants its documentation states


@dataclass(frozen=True)
class Solid:
    """One collision shape a peer is given, in SI units.

    kind: "sphere", "box", "capsule", "convex", "mesh" or "plane"; size: sphere (radius,), box
    (half_x, half_y, half_z), capsule (radius, half_length) along its local z axis, otherwise ();
    position (3,) [m] and orientation (4,) unit quaternion (w, x, y, z): a body's centre of mass
    and principal frame, an obstacle's pose (a plane: its point nearest the origin, and a
    rotation taking z onto its normal); normal (3,): a plane's outward unit normal (the solid
    side is behind it); vertices (V, 3) [m]: a convex shape's hull corners in its own frame, a
    mesh's vertices in the world frame; triangles (T, 3) int: a mesh's, counter-clockwise seen
    from outside; material: index into the model's materials; body: the body's index, −1 for an
    obstacle."""

    kind: str
    size: tuple[float, ...]
    position: np.ndarray
    orientation: np.ndarray
    material: int
    body: int = -1
    normal: np.ndarray | None = None
    vertices: np.ndarray | None = None
    triangles: np.ndarray | None = None


@dataclass(frozen=True)
class Sheet:
    """One cloth a peer is given, in SI units; V vertices, F triangles.

    particles (V,) int: the model's particle index of each vertex, in order (a cloth's vertices
    are consecutive particles); triangles (F, 3) int: indices into these V vertices,
    counter-clockwise seen from the front; position (V, 3) [m] and velocity (V, 3) [m/s]: the
    initial state; mass (V,) [kg]; pinned (V,) bool: held in place; thickness [m]: the contact
    radius of every vertex; material: index into the model's materials; self_collision: whether
    it meets itself as a surface; stretch_modulus E t [N/m] and rayleigh β [s]: the membrane of
    :func:`membrane` (its Poisson ratio is POISSON)."""

    name: str
    particles: np.ndarray
    triangles: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    mass: np.ndarray
    pinned: np.ndarray
    thickness: float
    material: int
    self_collision: bool
    stretch_modulus: float
    rayleigh: float


def membrane(
    position: np.ndarray,
    triangles: np.ndarray,
    spring_particles: np.ndarray,
    stiffness: np.ndarray,
    rest_length: np.ndarray,
    damping: np.ndarray,
) -> tuple[float, float]:
    """(E t [N/m], β [s]): the isotropic membrane (Poisson ratio POISSON) closest to a network of
    springs, and the Rayleigh damping coefficient closest to its dashpots.

    position (V, 3) [m], triangles (F, 3) and spring_particles (S, 2) index the same vertices;
    stiffness k (S,) [N/m], rest_length L (S,) [m], damping c (S,) [N s/m]. Under a small uniform
    strain ε of the sheet (area A) a spring along the unit vector n stretches by L n·ε·n, so the
    network stores the energy of the membrane stiffness C = Σ k L² n⊗n⊗n⊗n / A. The isotropic C
    closest to it (the Frobenius norm) is its average over the directions in the plane: Lamé
    λ = μ = Σ k L² / (8 A) for any directions, which is Poisson's ratio 1/3 (the Cauchy
    relation of central springs) and E t = 4 μ (λ + μ) / (λ + 2 μ) = Σ k L² / (3 A). Under a
    uniform dilation it stores exactly the network's energy; a lattice's stiffer and softer
    directions (a square grid's lines and diagonals) are averaged. The dashpots c (v_j − v_i)·u
    are the same sum with c for k, so Rayleigh damping β C matches their average with
    β = Σ c L² / Σ k L² (0 without springs)."""
    a, b, c = (position[triangles[:, k]] for k in range(3))
    area = 0.5 * float(np.linalg.norm(np.cross(b - a, c - a), axis=1).sum())
    squared = np.asarray(rest_length, dtype=float) ** 2
    weight = float(np.asarray(stiffness, dtype=float) @ squared)
    if area <= 0.0 or weight <= 0.0:
        return 0.0, 0.0
    return weight / (3.0 * area), float(np.asarray(damping, dtype=float) @ squared) / weight


def sheets(model: Model) -> list[Sheet]:
    """Every cloth of ``model`` as a :class:`Sheet`, in the model's cloth order, posed as its
    initial state has it."""
    state = model.initial
    cloth_of = np.asarray(model.particle_cloth)
    springs = np.asarray(model.spring_particles)
    triangles = np.asarray(model.triangles)
    found = []
    for c, name in enumerate(model.cloth_names):
        particles = np.flatnonzero(cloth_of == c)
        first = int(particles[0])
        own = cloth_of[springs[:, 0]] == c if len(springs) else np.zeros(0, dtype=bool)
        faces = triangles[cloth_of[triangles[:, 0]] == c] - first
        position = np.array(state.particle_position[particles])
        stretch, rayleigh = membrane(
            position,
            faces,
            springs[own] - first,
            np.asarray(model.spring_stiffness)[own],
            np.asarray(model.spring_rest_length)[own],
            np.asarray(model.spring_damping)[own],
        )
        found.append(
            Sheet(
                name,
                particles,
                faces,
                position,
                np.array(state.particle_velocity[particles]),
                np.array(model.particle_mass[particles], dtype=float),
                np.array(model.particle_pinned[particles], dtype=bool),
                float(model.particle_radius[first]),
                int(model.particle_material[first]),
                bool(model.cloth_self_collision[c]),
                stretch,
                rayleigh,
            )
        )
    return found


def hull_vertices(model: Model, hull: int) -> np.ndarray:
    """(V, 3) [m] the corners of the model's packed hull ``hull``, in its shape's own frame."""
    start, end = model.hulls["vertex_start"][hull], model.hulls["vertex_start"][hull + 1]
    return np.array(model.hulls["vertices"][start:end])


def _sized(kind: int, params: np.ndarray) -> tuple[str, tuple[float, ...]]:
    name = shapes.NAMES[int(kind)]
    if kind == shapes.SPHERE:
        return name, (float(params[0]),)
    if kind == shapes.BOX:
        return name, tuple(float(x) for x in params[:3])
    if kind == shapes.CAPSULE:
        return name, (float(params[0]), float(params[1]))
    return name, ()


def solids(model: Model) -> tuple[list[Solid], list[Solid]]:
    """(bodies, obstacles): the collision shape of every body (index order) and static obstacle,
    posed as the model's initial state has them."""
    state = model.initial
    bodies = []
    for b in range(model.body_count):
        shape = (model.body_shape[b], model.body_params[b], int(model.body_material[b]))
        bodies.append(_placed(model, shape, state.body_position[b], state.body_orientation[b], body=b))
    obstacles = []
    for o in range(model.obstacle_count):
        kind, size = _sized(model.obstacle_shape[o], model.obstacle_params[o])
        params, material = model.obstacle_params[o], int(model.obstacle_material[o])
        if kind == "plane":
            normal = np.array(params[:3])
            obstacles.append(Solid(kind, (), normal * params[3], _z_onto(normal), material, normal=normal))
        elif kind == "mesh":
            mesh = model.meshes[int(params[0])]
            obstacles.append(
                Solid(
                    kind,
                    (),
                    np.zeros(3),
                    np.array([1.0, 0.0, 0.0, 0.0]),
                    material,
                    vertices=np.array(mesh.vertices),
                    triangles=np.array(mesh.triangles),
                )
            )
        else:
            shape = (model.obstacle_shape[o], params, material)
            obstacles.append(_placed(model, shape, model.obstacle_position[o], model.obstacle_orientation[o]))
    return bodies, obstacles


def _placed(model: Model, shape: tuple, position: np.ndarray, orientation: np.ndarray, body: int = -1) -> Solid:
    """The Solid of a body or an obstacle that stands somewhere (not a plane or a mesh): its
    ``shape`` = (kind, params (4,), material), at ``position`` with ``orientation``; a hull's
    vertices with it."""
    kind, size = _sized(shape[0], shape[1])
    vertices = hull_vertices(model, int(shape[1][0])) if kind == "convex" else None
    return Solid(kind, size, np.array(position), np.array(orientation), shape[2], body=body, vertices=vertices)


def _z_onto(normal: np.ndarray) -> np.ndarray:
    """The unit quaternion (w, x, y, z) of the shortest rotation taking +z onto ``normal`` (unit)."""
    z = np.array([0.0, 0.0, 1.0])
    w = 1.0 + float(normal @ z)
    if w < 1e-12:  # normal = −z: half a turn about x
        return np.array([0.0, 1.0, 0.0, 0.0])
    q = np.concatenate([[w], np.cross(z, normal)])
    return q / np.linalg.norm(q)


def is_convex_mesh(vertices: np.ndarray, triangles: np.ndarray) -> bool:
    """Whether the closed triangle mesh (vertices (V, 3) [m], triangles (T, 3)) is convex: no
    vertex in front of any triangle's plane by more than 1e-9 of its size."""
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    normals = np.cross(b - a, c - a)
    lengths = np.linalg.norm(normals, axis=1)
    keep = lengths > 0
    normals, a = normals[keep] / lengths[keep, None], a[keep]
    size = float(np.ptp(vertices, axis=0).max()) or 1.0
    ahead = np.einsum("tk,tvk->tv", normals, vertices[None, :, :] - a[:, None, :])
    return bool(ahead.max(initial=0.0) <= 1e-9 * size)


def gaps(model: Model, peer: str) -> list[str]:
    """One sentence for each thing of ``model`` the engine ``peer`` (one of PEERS) cannot be
    given; [] when the whole scene translates. A scene with a gap is not run by that peer: a run
    of a scene with a part left out would be a run of another scene."""
    found = []
    cloth = int(np.count_nonzero(model.particle_cloth >= 0))
    free = model.particle_count - cloth
    if model.cloth_count:
        found += _cloth_gaps(model, peer, cloth)
    if free:
        found.append(
            f"{free} free particles (3 degrees of freedom each, a contact radius that may be 0) are no rigid "
            f"body {peer} is given"
        )
    kinematic = np.flatnonzero(model.body_kinematic)
    if kinematic.size:
        names = ", ".join(repr(model.body_names[b]) for b in kinematic[:3])
        found.append(
            f"the body {names} follows a kinematic path (add_path), which the translation does not drive in {peer}"
        )
    if peer == "mujoco":
        for o in np.flatnonzero(model.obstacle_shape == shapes.MESH):
            mesh = model.meshes[int(model.obstacle_params[o, 0])]
            if mesh.two_sided or not is_convex_mesh(np.asarray(mesh.vertices), np.asarray(mesh.triangles)):
                found.append(
                    f"obstacle {o} is a non-convex triangle mesh, and MuJoCo collides a mesh as its convex hull, "
                    "which would fill its hollows"
                )
    return found


def _cloth_gaps(model: Model, peer: str, vertices: int) -> list[str]:
    """The sentences of :func:`gaps` for the model's cloths (``vertices`` of them in all)."""
    if peer == "pybullet":
        return [
            f"contactlab's mass-spring cloth ({model.cloth_count} cloth, {vertices} vertices) has no faithful "
            "counterpart in pybullet: its deformable cloth (loadSoftBody, in a world reset for deformables) gives "
            "every edge of its triangle mesh one spring stiffness and every bending link another, where contactlab's "
            "stretch, shear (both diagonals of a grid cell, one of which no triangle has) and bend springs have their "
            "own, and that world steps the rigid bodies with another solver than the one the rest of the scene is "
            "translated for"
        ]
    found = []
    version = _installed("mujoco")
    if version is not None and version < FLEX_MUJOCO:
        found.append(
            f"the cloth is given to MuJoCo as a flex with continuum elasticity, whose 2D constants MuJoCo "
            f"{'.'.join(map(str, version))} states otherwise than it computes (fixed in MuJoCo "
            f"{'.'.join(map(str, FLEX_MUJOCO))}): install MuJoCo {'.'.join(map(str, FLEX_MUJOCO))} or later"
        )
    thin = [
        name
        for c, name in enumerate(model.cloth_names)
        if not model.particle_radius[model.particle_cloth == c].min() > 0
    ]
    if thin:
        found.append(
            f"the cloth {', '.join(map(repr, thin[:3]))} has thickness 0, and a MuJoCo 2D flex needs a positive radius "
            "to collide"
        )
    return found


def _installed(package: str) -> tuple[int, ...] | None:
    """The (major, minor) version of an installed ``package``, None where it is not installed or unreadable."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return tuple(int(part) for part in version(package).split(".")[:2])
    except (PackageNotFoundError, ValueError):
        return None


def pair_targets(model: Model) -> dict[tuple[int, int], tuple[float, float]]:
    """(material a, material b), a ≤ b -> (μ, ε) contactlab gives their contacts, for every pair
    of materials that can meet in this scene: two movers' (a body, or a cloth; a material with
    itself only when two movers have it or a cloth that meets itself does), and a mover's with an
    obstacle's (obstacles never meet)."""
    cloths = [int(model.particle_material[model.particle_cloth == c][0]) for c in range(model.cloth_count)]
    body = [int(m) for m in model.body_material] + cloths
    selves = {m for c, m in enumerate(cloths) if model.cloth_self_collision[c]}
    pairs = set()
    for i, a in enumerate(sorted(set(body))):
        for b in sorted(set(body))[i:]:
            if a != b or body.count(a) > 1 or a in selves:
                pairs.add((a, b))
    for a in set(body):
        for b in {int(m) for m in model.obstacle_material}:
            pairs.add((min(a, b), max(a, b)))
    targets = {}
    for a, b in sorted(pairs):
        friction, restitution = model.pair_materials(a, b)
        targets[(a, b)] = (float(friction), float(restitution))
    return targets


def closest_values(
    targets: dict[tuple[int, int], float],
    combine: Callable[[float, float], float],
    candidates: Sequence[np.ndarray],
) -> tuple[np.ndarray, dict[tuple[int, int], tuple[float, float]]]:
    """The per-material values (M,), among ``candidates``, whose pairs' ``combine`` (the
    engine's rule for two shapes' values) comes closest to ``targets`` ((a, b) -> the value
    contactlab's pair has, in the engine's terms) — the first of the closest —, and the pairs it
    misses: (a, b) -> (the engine's value, the target)."""
    best, best_error = candidates[0], math.inf
    for values in candidates:
        error = max((abs(combine(values[a], values[b]) - t) for (a, b), t in targets.items()), default=0.0)
        if error < best_error - MATCHED:
            best, best_error = values, error
    missed = {
        pair: (float(combine(best[pair[0]], best[pair[1]])), float(t))
        for pair, t in targets.items()
        if abs(combine(best[pair[0]], best[pair[1]]) - t) > MATCHED
    }
    return np.asarray(best, dtype=float), missed


def uniform(targets: dict[tuple[int, int], float], count: int, value: Callable[[float], float]) -> list[np.ndarray]:
    """[every material given ``value(t)``] when every pair's target is the same t, else []: the
    candidate that meets any combining rule where the scene has one kind of contact."""
    distinct = {round(t, 12) for t in targets.values()}
    if len(distinct) != 1:
        return []
    return [np.full(count, value(next(iter(targets.values()))))]


def static_only(model: Model) -> np.ndarray:
    """(M,) bool: the materials only static obstacles use (no body or particle has them)."""
    only = np.zeros(len(model.material_names), dtype=bool)
    only[np.asarray(model.obstacle_material, dtype=int)] = True
    only[np.asarray(model.body_material, dtype=int)] = False
    only[np.asarray(model.particle_material, dtype=int)] = False
    return only


def missed_sentence(engine: str, quantity: str, rule: str, missed: dict, names: Sequence[str]) -> str:
    """One sentence naming the material pairs whose ``quantity`` ``engine``'s ``rule`` cannot meet."""
    pairs = list(missed.items())
    shown = "; ".join(f"{names[a]}–{names[b]} {got:.3g} instead of {want:.3g}" for (a, b), (got, want) in pairs[:4])
    more = f" and {len(pairs) - 4} more pairs" if len(pairs) > 4 else ""
    return (
        f"{engine} combines two shapes' {quantity} by {rule}, which cannot give every pair contactlab's: {shown}{more}."
    )
