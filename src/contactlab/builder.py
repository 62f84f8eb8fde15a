"""ModelBuilder: add materials, bodies, particles, cloth and obstacles, then ``finalize()``.

Values are checked as they are added (by :mod:`contactlab.validation`); a bad one raises
:class:`~contactlab.errors.InputError` naming the argument (the scene loader prefixes the
scene-file path to it): its type, its range (positive masses and sizes, restitution in
[0, 1], ...), its magnitude against the generous limits of
:data:`contactlab.validation.LIMITS` (a ball of radius 10²⁰⁰ m is refused, not simulated into
NaN energies), and that each shape is given only the arguments it takes
(:data:`~contactlab.shape_arguments.BODY_SHAPE_ARGUMENTS`,
:data:`~contactlab.shape_arguments.OBSTACLE_SHAPE_ARGUMENTS`). A cloth's mesh and springs
are laid out by :mod:`contactlab.cloth_mesh`.

Example::

    builder = ModelBuilder()
    builder.add_material("rubber", friction=0.8, restitution=0.5)
    builder.add_body(shape="sphere", radius=0.1, mass=1.0, position=(0, 0, 1), material="rubber")
    builder.add_obstacle(shape="plane", normal=(0, 0, 1), offset=0.0)
    model = builder.finalize()
    state = model.state()
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from . import cloth_mesh, shapes
from .body_inertia import checked_tensor, principal
from .driving import force_record, pack, path_record, start_on_paths
from .errors import InputError
from .hull_geometry import matrix_to_quaternion
from .model import Model
from .particle_arguments import particle_positions, particle_values
from .rotations import multiply
from .shape_arguments import (
    BODY_SHAPE_ARGUMENTS,
    OBSTACLE_SHAPE_ARGUMENTS,
    checked_shape,
    convex_hull,
    mesh_obstacle,
    plane_params,
    solid_shape,
)
from .state import State
from .validation import (
    ACCELERATION,
    ANGULAR_SPEED,
    DAMPING,
    DENSITY,
    FRICTION,
    LENGTH,
    MASS,
    SPEED,
    STIFFNESS,
    check_dynamic_count,
    derived_mass,
    number,
    unit_quaternion,
    vector,
)

if TYPE_CHECKING:
    from .hulls import Hull
    from .meshes import TriangleMesh

DEFAULT_MATERIAL = ("default", 0.5, 0.0)  # name, friction μ, restitution ε

# what the add_* methods accept: a material or body by index or name; a force or path as values or as a
# function of time [s]
MaterialRef = int | str | None
BodyRef = int | str
DriveValue = ArrayLike | Callable[[float], tuple] | None


def _principal_frame(shape: str, tensor: np.ndarray, orientation: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(principal moments (3,) [kg m²], the body's orientation) of a sphere, box or capsule given
    the inertia ``tensor`` (3, 3) in its frame, placed at ``orientation``: a sphere's frame turns
    onto the tensor's principal axes (its geometry is the same in any frame); a box's and a
    capsule's cannot (their geometry is fixed to their axes), so their tensor must be diagonal."""
    moments, axes = principal(tensor)
    if np.allclose(axes, np.eye(3)):
        return moments, orientation
    if shape != "sphere":
        raise InputError(
            "inertia",
            f"a {shape}'s inertia must be diagonal in its own axes (its frame is its principal frame); "
            "give [Ixx, Iyy, Izz], or the shape as convex points, whose frame turns onto the tensor's axes",
        )
    turned = multiply(orientation, matrix_to_quaternion(axes))
    return moments, turned if turned[0] >= 0.0 else -turned


class ModelBuilder:
    """Collects a scene and freezes it into a :class:`~contactlab.model.Model`."""

    def __init__(self, gravity: ArrayLike = (0.0, 0.0, -9.81)) -> None:
        self.gravity = vector(gravity, "gravity", quantity=ACCELERATION)
        self._materials: list[tuple[str, float, float]] = []  # (name, friction, restitution)
        self._bodies: list[dict[str, Any]] = []  # dicts
        self._particles: list[dict[str, Any]] = []  # dicts of arrays (a cloth's vertices are one group)
        self._cloths: list[dict[str, Any]] = []  # dicts: name, first particle, triangles and springs (local indices)
        self._obstacles: list[dict[str, Any]] = []  # dicts
        self._hulls: list[Hull] = []  # contactlab.hulls.Hull of the convex shapes
        self._meshes: list[TriangleMesh] = []  # contactlab.meshes.TriangleMesh, world frame
        self._forces: list[dict[str, Any]] = []  # dicts: body, force, torque, times, function (see add_force)
        self._paths: list[dict[str, Any]] = []  # dicts: body, times, positions, orientations, function (see add_path)

    # -- materials -------------------------------------------------------------------
    def add_material(self, name: str, friction: float = 0.5, restitution: float = 0.0) -> int:
        """Add a material; returns its index. friction: Coulomb μ ≥ 0; restitution ε in [0, 1]."""
        if not isinstance(name, str) or not name:
            raise InputError("name", f"expected a non-empty string, found {name!r}")
        if any(m[0] == name for m in self._materials):
            raise InputError("name", f"material {name!r} is defined twice; give each a distinct name")
        self._materials.append(
            (
                name,
                number(friction, "friction", 0.0, quantity=FRICTION),
                number(restitution, "restitution", 0.0, maximum=1.0),
            )
        )
        return len(self._materials) - 1

    def _material_index(self, material) -> int:
        if material is None:
            for i, m in enumerate(self._materials):
                if m[0] == DEFAULT_MATERIAL[0]:
                    return i
            self._materials.append(DEFAULT_MATERIAL)
            return len(self._materials) - 1
        if isinstance(material, (int, np.integer)) and not isinstance(material, bool):
            if 0 <= material < len(self._materials):
                return int(material)
            raise InputError("material", f"no material with index {material}")
        if not isinstance(material, str):
            raise InputError("material", f"expected a material name or index, found {material!r}")
        names = [m[0] for m in self._materials]
        if material in names:
            return names.index(material)
        known = ", ".join(repr(n) for n in names)
        builtin = (
            f"{DEFAULT_MATERIAL[0]!r}, contactlab's own (friction {DEFAULT_MATERIAL[1]}, restitution "
            f"{DEFAULT_MATERIAL[2]}), what a body without a material gets"
        )
        raise InputError(
            "material",
            f"unknown material {material!r}: the materials are "
            f"{known + ' and ' if known else ''}{builtin}; define {material!r} "
            f"first (add_material, or [[materials]] in a scene file)",
        )

    # -- rigid bodies ----------------------------------------------------------------
    # add_body and add_obstacle spell out the shape arguments they share (radius, half_extents, points,
    # file, scale, placement, material) one keyword each, on purpose: the public signatures are what
    # help(), editors and the API docs show, and a shared **kwargs spec would hide them (issue 23's
    # `duplicates` lists the two as a pair; the checks behind the arguments are shared, in shape_arguments)
    def add_body(
        self,
        shape: str,
        *,
        radius: float | None = None,
        half_extents: ArrayLike | None = None,
        half_length: float | None = None,
        points: ArrayLike | None = None,
        file: str | None = None,
        scale: float | None = None,
        mass: float | None = None,
        density: float | None = None,
        inertia: ArrayLike | None = None,
        position: ArrayLike = (0, 0, 0),
        orientation: ArrayLike = (1, 0, 0, 0),
        velocity: ArrayLike = (0, 0, 0),
        angular_velocity: ArrayLike = (0, 0, 0),
        material: MaterialRef = None,
        name: str | None = None,
    ) -> int:
        """Add a rigid body; returns its index.

        shape: "sphere" (needs radius [m]), "box" (needs half_extents [m], 3 numbers),
        "capsule" (needs radius and half_length [m]: the segment along the body z axis) or
        "convex" (the hull of ``points`` (n, 3) [m], or of the vertices of a mesh ``file``
        (OBJ/STL/PLY), times ``scale`` (default 1); the points must be convex); a shape given an
        argument of another (a sphere's half_extents) is an InputError. Give exactly one of mass
        [kg] or density [kg/m³]; the inertia tensor follows from the shape as a uniform solid,
        unless ``inertia`` [kg m²] gives it (:mod:`contactlab.body_inertia`): three principal moments
        [Ixx, Iyy, Izz] along the shape's own axes, or a symmetric 3×3 tensor in that frame (for a
        convex shape, the frame its points are given in), about the centre of mass. The body's frame
        is always principal: a tensor with off-diagonal terms turns it onto the tensor's principal
        axes, which a sphere and a convex shape take (a sphere's orientation, a hull's vertices turn
        with it) and a box or capsule, whose geometry is fixed to its frame, refuse.
        position and orientation place the body's frame (for a convex shape, the frame its points
        are given in; the centre of mass follows). angular_velocity is world frame [rad/s].
        Magnitudes are checked against :data:`~contactlab.validation.LIMITS` (the mass a density gives too).
        """
        shape = checked_shape(
            shape,
            BODY_SHAPE_ARGUMENTS,
            dict(
                radius=radius, half_extents=half_extents, half_length=half_length, points=points, file=file, scale=scale
            ),
        )
        if (mass is None) == (density is None):
            found = "neither" if mass is None else "both"
            raise InputError("mass", f"give exactly one of mass (kg) or density (kg/m^3), found {found}")
        if mass is not None:
            mass = number(mass, "mass", 0.0, strict=True, quantity=MASS)
        else:
            density = number(density, "density", 0.0, strict=True, quantity=DENSITY)
        position = vector(position, "position", quantity=LENGTH)
        orientation = unit_quaternion(orientation, "orientation")
        tensor = None if inertia is None else checked_tensor(inertia, "inertia")
        if shape == "convex":
            hull = convex_hull(points, file, scale, mass=mass, density=density)
            if tensor is not None:
                hull = hull.with_inertia(tensor)
            kind, params = shapes.CONVEX, np.array([len(self._hulls), hull.radius, 0.0, 0.0])
            mass, inertia = hull.mass, hull.inertia
            position, orientation = hull.body_pose(position, orientation)
        else:
            kind, params = solid_shape(shape, radius, half_extents, shapes.BODY_SHAPES, half_length)
            if density is not None:
                mass = density * shapes.volume(kind, params)
            if tensor is None:  # mass: given, or derived from density just above (exactly one, checked above)
                inertia = shapes.principal_inertia(kind, params, mass)  # type: ignore[arg-type]
            else:
                inertia, orientation = _principal_frame(shape, tensor, orientation)
        if density is not None:
            derived_mass(mass, "density")  # type: ignore[arg-type]  # mass was just derived from density
        if shape == "convex":
            self._hulls.append(hull)
        check_dynamic_count(1, "shape", "another body", self._dynamic_count())
        index = len(self._bodies)
        self._bodies.append(
            dict(
                name=str(name) if name is not None else f"body{index}",
                kind=kind,
                params=params,
                mass=mass,
                inertia=inertia,
                position=position,
                orientation=orientation,
                velocity=vector(velocity, "velocity", quantity=SPEED),
                angular_velocity=vector(angular_velocity, "angular_velocity", quantity=ANGULAR_SPEED),
                material=self._material_index(material),
            )
        )
        return index

    # -- driving: external forces, kinematic paths (contactlab.driving) ----------------------
    def _body_index(self, body) -> int:
        """The index of ``body``, given by index or name; InputError("body") if there is none."""
        names = [b["name"] for b in self._bodies]
        if isinstance(body, (int, np.integer)) and not isinstance(body, bool):
            if 0 <= body < len(names):
                return int(body)
            raise InputError("body", f"no body with index {body} (there are {len(names)})")
        if isinstance(body, str) and body in names:
            return names.index(body)
        import difflib

        close = difflib.get_close_matches(str(body), names, n=1)
        hint = f"; did you mean {close[0]!r}?" if close else f" (the bodies: {', '.join(map(repr, names)) or 'none'})"
        raise InputError("body", f"no body named {body!r}{hint}")

    def add_force(
        self, body: BodyRef, force: DriveValue = None, torque: ArrayLike | None = None, times: ArrayLike | None = None
    ) -> None:
        """Push ``body`` (index or name) with an external force at its centre of mass and a torque
        about it, world frame, added to gravity in every method's free velocities.

        - constant: ``force`` (3,) [N], ``torque`` (3,) [N m] (either may be left out: zero);
        - piecewise linear: ``times`` (T,) [s], strictly increasing, and ``force``, ``torque``
          (T, 3) one row per time (either may be left out: zero); before the first time the first
          value, after the last the last;
        - a function of time: ``force`` a callable ``t [s] -> (force (3,) [N], torque (3,) [N m])``,
          called once a step with the step's start time (``torque`` and ``times`` left out).

        Several forces on one body add up. A model with forces steps through the methods' ``step``
        (not the compiled loop of impulse and constraints)."""
        self._forces.append(force_record(self._body_index(body), force, torque, times))

    def add_path(
        self,
        body: BodyRef,
        positions: DriveValue,
        orientations: ArrayLike | None = None,
        times: ArrayLike | None = None,
    ) -> None:
        """Make ``body`` (index or name) kinematic: its pose follows a path instead of its forces.

        - keyframes: ``times`` (T,) [s], strictly increasing, ``positions`` (T, 3) [m] of its
          centre of mass, ``orientations`` (T, 4) unit quaternions (w, x, y, z) (default: the
          orientation it was added with, throughout); positions interpolated linearly,
          orientations by slerp, the first pose held before the first time and the last after;
        - a fixed pose: ``positions`` (3,) and ``orientations`` (4,) or None, no times;
        - a function of time: ``positions`` a callable ``t [s] -> (position (3,) [m], orientation
          (4,))``, ``orientations`` and ``times`` left out.

        A kinematic body has infinite mass (inverse mass and inertia 0): contacts push on it and
        it is not pushed back. At each step its velocity is the one that carries it onto the path
        over that step, which contacts and friction see; its pose at time 0 is the path's there
        (its position and orientation from ``add_body`` are replaced). Its mass, still needed by
        ``add_body``, only enters the energy and momentum diagnostics. The explicit_euler
        integrator, which moves positions by the old velocities, cannot follow a path and is
        refused for such models."""
        index = self._body_index(body)
        if any(p["body"] == index for p in self._paths):
            raise InputError("body", f"body {self._bodies[index]['name']!r} already has a path; give it one only")
        self._paths.append(path_record(index, positions, orientations, times, self._bodies[index]["orientation"]))

    def _dynamic_count(self):
        """Bodies, particles and cloth vertices added so far."""
        return len(self._bodies) + sum(len(group["position"]) for group in self._particles)

    # -- particles -------------------------------------------------------------------
    def add_particles(
        self,
        position: ArrayLike,
        velocity: ArrayLike | None = None,
        *,
        mass: float | ArrayLike = 1.0,
        radius: float | ArrayLike = 0.0,
        material: MaterialRef = None,
    ) -> range:
        """Add particles; returns their indices (range).

        position, velocity: (count, 3) [m], [m/s]; mass [kg] and radius [m] are per particle
        (one number for all, or one per particle). A radius of 0 makes a point.
        """
        position = particle_positions(position)
        count = len(position)
        check_dynamic_count(count, "position", f"{count:,} more particles", self._dynamic_count())
        velocity, masses, radii = particle_values(position, velocity, mass, radius)
        start = sum(len(p["position"]) for p in self._particles)
        self._particles.append(
            dict(
                position=position, velocity=velocity, mass=masses, radius=radii, material=self._material_index(material)
            )
        )
        return range(start, start + count)

    # -- cloth -----------------------------------------------------------------------
    def add_cloth(
        self,
        *,
        size: ArrayLike | None = None,
        resolution: Sequence[int] | None = None,
        file: str | None = None,
        scale: float = 1.0,
        position: ArrayLike = (0, 0, 0),
        orientation: ArrayLike = (1, 0, 0, 0),
        velocity: ArrayLike = (0, 0, 0),
        mass: float | None = None,
        density: float | None = None,
        stretch_stiffness: float = 1000.0,
        shear_stiffness: float = 100.0,
        bend_stiffness: float = 10.0,
        damping: float = 0.0,
        pinned: int | str | Sequence[int | str] = (),
        thickness: float = 0.005,
        self_collision: bool = True,
        material: MaterialRef = None,
        name: str | None = None,
    ) -> range:
        """Add a mass-spring cloth; returns the particle indices of its vertices (a range).

        Its vertices are particles (3 DOF each) of radius ``thickness`` [m], so the particle
        contacts keep every vertex that far from obstacles. Two ways to give its shape:

        * a grid: ``size`` = (w, h) [m] and ``resolution`` = (nx, ny) vertices (each ≥ 2), in
          the cloth's local xy plane, centred on its origin. Vertex (a, b) (a along x, b along
          y) is particle ``start + a + nx b``, at local (−w/2 + a w/(nx−1), −h/2 + b h/(ny−1), 0).
          Springs: stretch along the grid lines, shear along both diagonals of each cell, bend
          between vertices two apart along x and along y. Each cell is two triangles.
          The mass is split evenly over the vertices.
        * a triangle mesh ``file`` (OBJ, STL or PLY, read with trimesh) times ``scale``:
          stretch springs along the triangle edges and bend springs between the two opposite
          corners of each pair of triangles sharing an edge; no shear springs (the triangles'
          edges already resist shear; ``shear_stiffness`` is not used). Coincident vertices are
          merged (the first one kept, so indices follow the file's order otherwise); the mass
          is split by triangle areas, a third of each triangle's to each corner.

        position [m] and orientation (w, x, y, z) place the local frame; velocity [m/s] is the
        initial velocity of every free vertex. Give exactly one of mass [kg] (the whole cloth)
        or density [kg/m²] (areal). stretch_stiffness, shear_stiffness, bend_stiffness [N/m]
        ≥ 0 (per spring) and damping [N s/m] ≥ 0 (along every spring's axis). Every spring's
        rest length is its length as built.

        pinned: vertices held in place (zero velocity, zero inverse mass): a list of vertex
        indices into this cloth (0-based, as above) and, for a grid, any of the names
        "corners" (the four corners), "top_corners" (the two at y = +h/2), "top_edge" (the
        row at y = +h/2), "bottom_edge" (y = −h/2), "left_edge" (x = −w/2), "right_edge"
        (x = +w/2); one name or index alone is accepted too.

        self_collision: the cloth meets itself and the other self-colliding cloths as surfaces
        (vertex–triangle and edge–edge contacts kept ``thickness`` apart, see
        :mod:`contactlab.collision.cloth_self`); False: only its vertices meet other cloths'
        vertices, and it passes through itself. On, twice the thickness must be less than its
        triangles' shortest height, or neighbouring elements would touch at rest.
        """
        if (mass is None) == (density is None):
            found = "neither" if mass is None else "both"
            raise InputError("mass", f"give exactly one of mass (kg) or density (kg/m^2), found {found}")
        position = vector(position, "position", quantity=LENGTH)
        orientation = unit_quaternion(orientation, "orientation")
        velocity = vector(velocity, "velocity", quantity=SPEED)
        stiffness = {
            key: number(value, key, 0.0, quantity=STIFFNESS)
            for key, value in (
                ("stretch_stiffness", stretch_stiffness),
                ("shear_stiffness", shear_stiffness),
                ("bend_stiffness", bend_stiffness),
            )
        }
        damping = number(damping, "damping", 0.0, quantity=DAMPING)
        thickness = number(thickness, "thickness", 0.0, quantity=LENGTH)
        if (size is None) == (file is None):
            raise InputError("size", "a cloth needs exactly one of size and resolution (a grid) or file (a mesh)")
        if file is not None and resolution is not None:
            raise InputError("resolution", "a cloth from a mesh file takes no resolution")
        mesh = cloth_mesh.grid(size, resolution) if file is None else cloth_mesh.from_file(file, scale)
        cloth = cloth_mesh.lay_out(
            mesh, file is not None, position, orientation, mass, density, tuple(stiffness.values()), pinned
        )
        if not isinstance(self_collision, (bool, np.bool_)):
            raise InputError("self_collision", f"expected true or false, found {self_collision!r}")
        if self_collision:
            cloth_mesh.check_self_thickness(cloth.position, cloth.triangles, thickness)
        count = len(cloth.position)
        vertex_velocity = np.where(cloth.pinned[:, None], 0.0, velocity[None, :])
        check_dynamic_count(
            count, "resolution" if file is None else "file", f"a cloth of {count:,} vertices", self._dynamic_count()
        )
        start = sum(len(p["position"]) for p in self._particles)
        index = len(self._cloths)
        self._particles.append(
            dict(
                position=cloth.position,
                velocity=vertex_velocity,
                mass=cloth.mass,
                radius=np.full(count, thickness),
                material=self._material_index(material),
                cloth=index,
                pinned=cloth.pinned,
            )
        )
        self._cloths.append(
            dict(
                name=str(name) if name is not None else f"cloth{index}",
                start=start,
                triangles=cloth.triangles,
                springs=cloth.springs,
                stiffness=cloth.stiffness,
                rest=cloth.rest,
                damping=np.full(len(cloth.springs), damping),
                self_collision=bool(self_collision),
            )
        )
        return range(start, start + count)

    # -- static obstacles ------------------------------------------------------------
    # the shape arguments spelled out as add_body's, on purpose: see the comment there
    def add_obstacle(
        self,
        shape: str,
        *,
        normal: ArrayLike | None = None,
        offset: float | None = None,
        radius: float | None = None,
        half_extents: ArrayLike | None = None,
        points: ArrayLike | None = None,
        file: str | None = None,
        scale: float | None = None,
        position: ArrayLike | None = None,
        orientation: ArrayLike | None = None,
        material: MaterialRef = None,
    ) -> int:
        """Add static geometry; returns its index.

        "plane": the half-space normal · x ≤ offset is solid (normal need not be unit).
        "sphere": radius, position. "box": half_extents, position, orientation.
        "convex": points or file (and scale), placed by position and orientation.
        "mesh": a triangle mesh file (OBJ/STL/PLY) times scale, placed by position and
        orientation; its triangles' winding makes their front side the outside.
        Defaults: offset 0 [m], scale 1, position the origin, orientation none; a shape given an
        argument it does not take (a plane's position) is an InputError.
        """
        shape = checked_shape(
            shape,
            OBSTACLE_SHAPE_ARGUMENTS,
            dict(  # every shape argument as given
                normal=normal,
                offset=offset,
                radius=radius,
                half_extents=half_extents,
                points=points,
                file=file,
                scale=scale,
                position=position,
                orientation=orientation,
            ),
        )
        position = vector((0, 0, 0) if position is None else position, "position", quantity=LENGTH)
        orientation = unit_quaternion((1, 0, 0, 0) if orientation is None else orientation, "orientation")
        if shape == "plane":
            kind, params = shapes.PLANE, plane_params(normal, offset)
        elif shape == "mesh":
            kind, params = shapes.MESH, np.array([len(self._meshes), 0.0, 0.0, 0.0])
            self._meshes.append(mesh_obstacle(file, scale, position, orientation))
        elif shape == "convex":
            hull = convex_hull(points, file, scale)
            kind, params = shapes.CONVEX, np.array([len(self._hulls), hull.radius, 0.0, 0.0])
            self._hulls.append(hull)
            position, orientation = hull.body_pose(position, orientation)
        else:
            kind, params = solid_shape(shape, radius, half_extents, shapes.OBSTACLE_SHAPES)
        self._obstacles.append(
            dict(
                kind=kind,
                params=params,
                position=position,
                orientation=orientation,
                material=self._material_index(material),
            )
        )
        return len(self._obstacles) - 1

    def _pack_hulls(self, shapes_with_params):
        """Pack the convex hulls, then one 8-corner hull per box (its index stored in params[3])."""
        from .hulls import box_as_hull, fan_triangles, join_packed, pack_hulls

        packs = [pack_hulls(self._hulls)]
        count = len(self._hulls)
        for item in shapes_with_params:
            if item["kind"] == shapes.BOX:
                item["params"] = item["params"].copy()
                item["params"][3] = count
                packs.append(box_as_hull(item["params"][:3]))
                count += 1
        packed = join_packed(packs)
        packed.update(fan_triangles(packed))
        return packed

    # -- freeze ------------------------------------------------------------------------
    def finalize(self) -> Model:
        """Freeze into a Model whose ``state()`` is the initial state."""
        if not self._materials:
            self._material_index(None)
        bodies, particles, obstacles = self._bodies, self._particles, self._obstacles
        hulls = self._pack_hulls(bodies + obstacles)

        def stack(items, key, shape, dtype=float):
            return np.array([item[key] for item in items], dtype=dtype).reshape(shape)

        def cat(key, shape):
            return (
                np.concatenate([p[key] for p in particles]).reshape(shape)
                if particles
                else np.zeros(shape if shape[0] != -1 else (0,) + shape[1:])
            )

        initial = State(
            time=0.0,
            body_position=stack(bodies, "position", (-1, 3)),
            body_orientation=stack(bodies, "orientation", (-1, 4)),
            body_velocity=stack(bodies, "velocity", (-1, 3)),
            body_angular_velocity=stack(bodies, "angular_velocity", (-1, 3)),
            particle_position=cat("position", (-1, 3)),
            particle_velocity=cat("velocity", (-1, 3)),
        )
        particle_material = (
            np.concatenate([np.full(len(p["position"]), p["material"]) for p in particles])
            if particles
            else np.zeros(0, dtype=np.int64)
        )
        particle_cloth = (
            np.concatenate([np.full(len(p["position"]), p.get("cloth", -1)) for p in particles])
            if particles
            else np.zeros(0)
        ).astype(np.int64)
        particle_pinned = (
            np.concatenate([p.get("pinned", np.zeros(len(p["position"]), dtype=bool)) for p in particles])
            if particles
            else np.zeros(0)
        ).astype(bool)
        cloths = self._cloths

        def cloth_cat(key, shape, offset=False, dtype=float):
            parts = [c[key] + (c["start"] if offset else 0) for c in cloths]
            return (np.concatenate(parts) if parts else np.zeros(0)).astype(dtype).reshape(shape)

        drive = pack(len(bodies), self._forces, self._paths)
        start_on_paths(drive, initial)
        return Model(
            drive=drive,
            gravity=self.gravity.copy(),
            material_names=tuple(m[0] for m in self._materials),
            material_friction=np.array([m[1] for m in self._materials]),
            material_restitution=np.array([m[2] for m in self._materials]),
            body_names=tuple(b["name"] for b in bodies),
            body_shape=stack(bodies, "kind", (-1,), np.int64),
            body_params=stack(bodies, "params", (-1, 4)),
            body_mass=stack(bodies, "mass", (-1,)),
            body_inertia=stack(bodies, "inertia", (-1, 3)),
            body_material=stack(bodies, "material", (-1,), np.int64),
            particle_mass=cat("mass", (-1,)),
            particle_radius=cat("radius", (-1,)),
            particle_material=particle_material.astype(np.int64),
            obstacle_shape=stack(obstacles, "kind", (-1,), np.int64),
            obstacle_params=stack(obstacles, "params", (-1, 4)),
            obstacle_position=stack(obstacles, "position", (-1, 3)),
            obstacle_orientation=stack(obstacles, "orientation", (-1, 4)),
            obstacle_material=stack(obstacles, "material", (-1,), np.int64),
            hulls=hulls,
            meshes=tuple(self._meshes),
            initial=initial,
            cloth_names=tuple(c["name"] for c in cloths),
            triangles=cloth_cat("triangles", (-1, 3), offset=True, dtype=np.int64),
            particle_cloth=particle_cloth,
            particle_pinned=particle_pinned,
            spring_particles=cloth_cat("springs", (-1, 2), offset=True, dtype=np.int64),
            spring_rest_length=cloth_cat("rest", (-1,)),
            spring_stiffness=cloth_cat("stiffness", (-1,)),
            spring_damping=cloth_cat("damping", (-1,)),
            cloth_self_collision=np.array([c["self_collision"] for c in cloths], dtype=bool),
        )
