"""The frozen, static description of a scene: struct of arrays.

A :class:`Model` is built once by :class:`contactlab.builder.ModelBuilder` and never changes;
everything that evolves in time lives in :class:`contactlab.state.State`. Arrays are read-only.

Counts: B rigid bodies, P particles, O static obstacles, M materials, C cloths, F cloth
triangles, S cloth springs. Cloth vertices are particles (3 DOF each): the P particles are the
free ones and the vertices of every cloth, in the order they were added.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np

from . import rotations, shapes
from .counts import RowCount

if TYPE_CHECKING:
    from .driving import Drive
    from .meshes import TriangleMesh
    from .state import State

Built = TypeVar("Built")


@dataclass(frozen=True)
class Model:
    gravity: np.ndarray
    """(3,) m/s²"""
    # materials
    material_names: tuple[str, ...]
    """(M,)"""
    material_friction: np.ndarray
    """(M,) Coulomb μ"""
    material_restitution: np.ndarray
    """(M,) ε in [0, 1]"""
    # rigid bodies (6 DOF each: linear velocity, world angular velocity)
    body_names: tuple[str, ...]
    """(B,)"""
    body_shape: np.ndarray
    """(B,) int, a kind from contactlab.shapes"""
    body_params: np.ndarray
    """(B, 4) shape parameters [m]"""
    body_mass: np.ndarray
    """(B,) kg"""
    body_inertia: np.ndarray
    """(B, 3) principal moments in the body frame, kg m²"""
    body_material: np.ndarray
    """(B,) int index into materials"""
    # particles (3 DOF each)
    particle_mass: np.ndarray
    """(P,) kg"""
    particle_radius: np.ndarray
    """(P,) contact radius, m"""
    particle_material: np.ndarray
    """(P,) int"""
    # static obstacles
    obstacle_shape: np.ndarray
    """(O,) int kind"""
    obstacle_params: np.ndarray
    """(O, 4) shape parameters (see contactlab.shapes)"""
    obstacle_position: np.ndarray
    """(O, 3) m (centre; unused for planes)"""
    obstacle_orientation: np.ndarray
    """(O, 4) unit quaternion (w, x, y, z)"""
    obstacle_material: np.ndarray
    """(O,) int"""
    hulls: dict[str, np.ndarray] = field(repr=False, default=None)
    """convex hulls (of convex shapes and of every box), packed: see contactlab.hulls.pack_hulls"""
    meshes: tuple[TriangleMesh, ...] = field(repr=False, default=())
    """static triangle meshes in world coordinates (contactlab.meshes.TriangleMesh), by index"""
    initial: State = field(repr=False, default=None)
    """the state at time 0"""
    # cloth (see ModelBuilder.add_cloth): topology and mass-spring network over the particles
    cloth_names: tuple[str, ...] = ()
    """(C,)"""
    triangles: np.ndarray = field(repr=False, default_factory=lambda: np.zeros((0, 3), dtype=np.int64))
    """(F, 3) int, particle indices, counter-clockwise seen from the front"""
    particle_cloth: np.ndarray = field(repr=False, default=None)
    """(P,) int cloth index, −1 if none"""
    particle_pinned: np.ndarray = field(repr=False, default=None)
    """(P,) bool, held in place"""
    spring_particles: np.ndarray = field(repr=False, default_factory=lambda: np.zeros((0, 2), dtype=np.int64))
    """(S, 2) int, the two particles each spring joins"""
    spring_rest_length: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0))
    """(S,) m"""
    spring_stiffness: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0))
    """(S,) N/m"""
    spring_damping: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0))
    """(S,) N s/m"""
    cloth_self_collision: np.ndarray = field(repr=False, default=None)
    """(C,) bool, the cloth meets itself and the other such cloths as surfaces (collision.cloth_self)"""
    drive: Drive | None = field(repr=False, default=None)
    """external forces and kinematic paths (contactlab.driving.Drive); None: nothing drives the scene"""
    _derived: dict[Callable[[Model], Any], Any] = field(init=False, repr=False, compare=False, default_factory=dict)
    """what higher layers built from this model, by the function that built it (:func:`derived`)"""

    def __post_init__(self):
        # models built without cloth: no particle belongs to one, none is pinned
        if self.particle_cloth is None:
            object.__setattr__(self, "particle_cloth", np.full(len(self.particle_mass), -1, dtype=np.int64))
        if self.particle_pinned is None:
            object.__setattr__(self, "particle_pinned", np.zeros(len(self.particle_mass), dtype=bool))
        if self.cloth_self_collision is None:  # on by default, as ModelBuilder.add_cloth has it
            object.__setattr__(self, "cloth_self_collision", np.ones(len(self.cloth_names), dtype=bool))
        for _name, value in vars(self).items():
            for array in value.values() if isinstance(value, dict) else [value]:
                if isinstance(array, np.ndarray):
                    array.flags.writeable = False

    @property
    def hull_store(self) -> tuple:
        """The packed hull arrays as the compiled routines take them (see collision.convex.hull_view)."""
        h = self.hulls
        return (
            h["vertex_start"],
            h["vertices"],
            h["face_start"],
            h["face_normal"],
            h["face_offset"],
            h["face_vertex_start"],
            h["face_vertex_index"],
            h["edge_start"],
            h["edge_vertex"],
            h["edge_face"],
        )

    body_count = RowCount("body_names")
    """B, the number of rigid bodies."""
    particle_count = RowCount("particle_mass")
    """P, the number of particles (free ones and cloth vertices)."""
    obstacle_count = RowCount("obstacle_shape")
    """O, the number of static obstacles."""

    @property
    def body_kinematic(self) -> np.ndarray:
        """(B,) bool: the bodies that follow a path (``ModelBuilder.add_path``), of infinite mass."""
        return self.drive.kinematic if self.drive is not None else np.zeros(self.body_count, dtype=bool)

    @property
    def body_inverse_mass(self) -> np.ndarray:
        """(B,) 1/kg; 0 for kinematic bodies, so no contact moves them."""
        return np.where(self.body_kinematic, 0.0, 1.0 / self.body_mass)

    @property
    def body_inverse_inertia(self) -> np.ndarray:
        """(B, 3) inverse principal moments, 1/(kg m²); 0 for kinematic bodies."""
        return np.where(self.body_kinematic[:, None], 0.0, 1.0 / self.body_inertia)

    cloth_count = RowCount("cloth_names")
    """C, the number of cloths."""
    spring_count = RowCount("spring_rest_length")
    """S, the number of cloth springs."""

    @cached_property
    def body_radii(self) -> np.ndarray:
        """(B,) [m] radii of the spheres about the bodies' centres that enclose them
        (``shapes.bounding_radii``): fixed by the shapes, computed on first use and kept."""
        return shapes.bounding_radii(self.body_shape, self.body_params)

    @cached_property
    def collider_table(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The fixed part of collision's global collider arrays (bodies, then particles, then
        obstacles): kinds (N,) int64, params (N, 4), materials (N,) int and the obstacles'
        rotation matrices (O, 3, 3); built on first use and kept."""
        particle_params = np.zeros((self.particle_count, 4))
        particle_params[:, 0] = self.particle_radius
        kinds = np.concatenate(
            [self.body_shape, np.full(self.particle_count, shapes.POINT), self.obstacle_shape]
        ).astype(np.int64)
        params = np.concatenate([self.body_params, particle_params, self.obstacle_params])
        materials = np.concatenate([self.body_material, self.particle_material, self.obstacle_material])
        return kinds, params, materials, rotations.to_matrix(self.obstacle_orientation)

    @cached_property
    def collider_half_thickness(self) -> np.ndarray:
        """(N,) [m] per collider (bodies, particles, obstacles): how deep another shape's surface
        may sink into it before reaching its middle — a sphere's, capsule's or particle's radius,
        a box's smallest half extent, a hull's inradius about its origin, a mesh's ``max_depth``
        (how far below its surface a point is still found), a plane's ∞. Built on first use."""
        kinds, params = self.collider_table[0], self.collider_table[1]
        thickness = np.select(
            [kinds == shapes.BOX, kinds == shapes.PLANE], [params[:, :3].min(axis=1), np.inf], default=params[:, 0]
        )
        for g in np.nonzero(kinds == shapes.CONVEX)[0]:
            h = int(params[g, 0])
            start, end = self.hulls["face_start"][h], self.hulls["face_start"][h + 1]
            thickness[g] = max(0.0, float(self.hulls["face_offset"][start:end].min()))
        for g in np.nonzero(kinds == shapes.MESH)[0]:
            thickness[g] = self.meshes[int(params[g, 0])].max_depth
        return thickness

    @property
    def particle_inverse_mass(self) -> np.ndarray:
        """(P,) 1/kg; 0 for pinned particles, so every solver treats them as immovable."""
        return np.where(self.particle_pinned, 0.0, 1.0 / self.particle_mass)

    def pair_materials(
        self, material_a: int | np.ndarray, material_b: int | np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """(friction μ, restitution ε) of contacts between materials ``material_a`` and
        ``material_b`` (indices, scalars or arrays of one shape): μ = √(μ_a μ_b), the geometric
        mean, and ε = max(ε_a, ε_b), the larger."""
        return (
            np.sqrt(self.material_friction[material_a] * self.material_friction[material_b]),
            np.maximum(self.material_restitution[material_a], self.material_restitution[material_b]),
        )

    def state(self) -> State:
        """A fresh copy of the state at time 0."""
        return self.initial.copy()

    def __repr__(self):
        return f"Model({self.describe()})"

    def describe(self) -> str:
        kinds: dict[str, int] = {}
        for k in self.body_shape:
            kinds[shapes.NAMES[int(k)]] = kinds.get(shapes.NAMES[int(k)], 0) + 1
        parts = [f"{n} {k}{'es' if k == 'box' and n > 1 else 's' if n > 1 else ''}" for k, n in kinds.items()]
        free = int(np.count_nonzero(self.particle_cloth < 0))
        if free:
            parts.append(f"{free} particle{'s' if free > 1 else ''}")
        if self.cloth_count:
            vertices = self.particle_count - free
            parts.append(f"{self.cloth_count} cloth{'s' if self.cloth_count > 1 else ''} ({vertices} vertices)")
        parts.append(f"{self.obstacle_count} obstacle{'s' if self.obstacle_count != 1 else ''}")
        if self.drive is not None:  # driven: which bodies follow a path, whether forces push
            paths = int(self.body_kinematic.sum())
            parts.append(
                ", ".join(
                    ([f"{paths} on a path"] if paths else []) + (["external forces"] if self.drive.has_loads else [])
                )
            )
        return ", ".join(parts)


def derived(build: Callable[[Model], Built]) -> Callable[[Model], Built]:
    """``build``, a function of a Model, made to build its value once per Model and keep it.

    For what a higher layer builds from a Model's arrays alone — the collision's pair families
    (``collision.families.pair_families``), the cloth's sparse pattern
    (``dynamics.cloth.spring_pattern``), the compiled loop's arrays
    (``methods.loop_stages.loop_model``): a Model never changes, so each is built on first use and
    kept with the Model, which itself knows nothing of them (it imports no higher layer)."""

    @functools.wraps(build)
    def kept(model: Model) -> Built:
        values = model._derived
        if kept not in values:
            values[kept] = build(model)
        return values[kept]

    return kept
