"""ModelBuilder: add materials, bodies, particles and obstacles, then ``finalize()``.

Values are checked as they are added; a bad one raises :class:`~contactlab.errors.InputError`
naming the argument (the scene loader prefixes the scene-file path to it).

Example::

    builder = ModelBuilder()
    builder.add_material("rubber", friction=0.8, restitution=0.5)
    builder.add_body(shape="sphere", radius=0.1, mass=1.0, position=(0, 0, 1), material="rubber")
    builder.add_obstacle(shape="plane", normal=(0, 0, 1), offset=0.0)
    model = builder.finalize()
    state = model.state()
"""

import numpy as np

from . import rotations, shapes
from .errors import InputError
from .model import Model
from .state import State

DEFAULT_MATERIAL = ("default", 0.5, 0.0)   # name, friction μ, restitution ε


def _array(value, name, what):
    """value as a float array, or InputError naming the field (strings, ragged lists)."""
    try:
        return np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(name, f"expected {what}, found {value!r}") from None


def _vector(value, name, size=3):
    array = _array(value, name, f"a list of {size} numbers")
    if array.shape != (size,):
        raise InputError(name, f"expected a list of {size} numbers, found {value!r}")
    if not np.isfinite(array).all():
        raise InputError(name, f"expected finite numbers, found {value!r}")
    return array


def _number(value, name, minimum=None, strict=False, maximum=None):
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise InputError(name, f"expected a number, found {value!r}")
    value = float(value)
    if not np.isfinite(value):
        raise InputError(name, f"expected a finite number, found {value!r}")
    if minimum is not None and (value <= minimum if strict else value < minimum):
        bound = "greater than" if strict else "at least"
        raise InputError(name, f"must be {bound} {minimum:g}, found {value:g}")
    if maximum is not None and value > maximum:
        raise InputError(name, f"must be at most {maximum:g}, found {value:g}")
    return value


def _orientation(value, name):
    q = _vector(value, name, 4)
    norm = np.linalg.norm(q)
    if norm < 1e-12:
        raise InputError(name, "a zero quaternion is no rotation; use [1, 0, 0, 0] for none")
    return q / norm


class ModelBuilder:
    """Collects a scene and freezes it into a :class:`~contactlab.model.Model`."""

    def __init__(self, gravity=(0.0, 0.0, -9.81)):
        self.gravity = _vector(gravity, "gravity")
        self._materials = []          # (name, friction, restitution)
        self._bodies = []             # dicts
        self._particles = []          # dicts of arrays
        self._obstacles = []          # dicts
        self._hulls = []              # contactlab.hulls.Hull of the convex shapes
        self._meshes = []             # contactlab.meshes.TriangleMesh, world frame

    # -- materials -------------------------------------------------------------------
    def add_material(self, name, friction=0.5, restitution=0.0) -> int:
        """Add a material; returns its index. friction: Coulomb μ ≥ 0; restitution ε in [0, 1]."""
        if not isinstance(name, str) or not name:
            raise InputError("name", f"expected a non-empty string, found {name!r}")
        if any(m[0] == name for m in self._materials):
            raise InputError("name", f"material {name!r} is defined twice; give each a distinct name")
        self._materials.append((name, _number(friction, "friction", 0.0),
                                _number(restitution, "restitution", 0.0, maximum=1.0)))
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
        names = [m[0] for m in self._materials]
        if material in names:
            return names.index(material)
        known = ", ".join(repr(n) for n in names) or "none defined"
        raise InputError("material", f"unknown material {material!r} (known: {known})")

    # -- rigid bodies ----------------------------------------------------------------
    def add_body(self, shape, *, radius=None, half_extents=None, half_length=None, points=None, file=None,
                 scale=1.0, mass=None, density=None, position=(0, 0, 0), orientation=(1, 0, 0, 0),
                 velocity=(0, 0, 0), angular_velocity=(0, 0, 0), material=None, name=None) -> int:
        """Add a rigid body; returns its index.

        shape: "sphere" (needs radius [m]), "box" (needs half_extents [m], 3 numbers),
        "capsule" (needs radius and half_length [m]: the segment along the body z axis) or
        "convex" (the hull of ``points`` (n, 3) [m], or of the vertices of a mesh ``file``
        (OBJ/STL/PLY), times ``scale``; the points must be convex). Give exactly one of mass [kg]
        or density [kg/m³]; the inertia tensor follows from the shape as a uniform solid.
        position and orientation place the body's frame (for a convex shape, the frame its points
        are given in; the centre of mass follows). angular_velocity is world frame [rad/s].
        """
        if (mass is None) == (density is None):
            found = "neither" if mass is None else "both"
            raise InputError("mass", f"give exactly one of mass (kg) or density (kg/m^3), found {found}")
        position = _vector(position, "position")
        orientation = _orientation(orientation, "orientation")
        if shape == "convex":
            hull = self._hull(points, file, scale, mass=mass, density=density)
            kind, params = shapes.CONVEX, np.array([len(self._hulls), hull.radius, 0.0, 0.0])
            self._hulls.append(hull)
            mass, inertia = hull.mass, hull.inertia
            position, orientation = hull.body_pose(position, orientation)
        else:
            kind, params = self._solid_shape(shape, radius, half_extents, shapes.BODY_SHAPES, half_length)
            if mass is not None:
                mass = _number(mass, "mass", 0.0, strict=True)
            else:
                mass = _number(density, "density", 0.0, strict=True) * shapes.volume(kind, params)
            inertia = shapes.principal_inertia(kind, params, mass)
        index = len(self._bodies)
        self._bodies.append(dict(
            name=str(name) if name is not None else f"body{index}",
            kind=kind, params=params, mass=mass, inertia=inertia,
            position=position, orientation=orientation,
            velocity=_vector(velocity, "velocity"),
            angular_velocity=_vector(angular_velocity, "angular_velocity"),
            material=self._material_index(material)))
        return index

    @staticmethod
    def _hull(points, file, scale, mass=None, density=None):
        """The convex hull of ``points`` or of a mesh file's vertices (InputError if not convex)."""
        from .hulls import build_hull, load_hull_points
        if (points is None) == (file is None):
            raise InputError("points", "a convex shape needs exactly one of points = [[x, y, z], ...] or file")
        scale = _number(scale, "scale", 0.0, strict=True)
        if file is not None:
            points, field = load_hull_points(file, scale, field="file"), "file"
        else:
            points, field = _array(points, "points", "a list of [x, y, z] points") * scale, "points"
        if mass is None and density is None:
            mass = 1.0                   # static geometry: the mass is not used
        return build_hull(points, field, mass=mass, density=density, require_convex=True)

    @staticmethod
    def _solid_shape(shape, radius, half_extents, allowed, half_length=None):
        if shape not in allowed:
            raise InputError("shape", f"expected one of {', '.join(allowed)}, found {shape!r}")
        kind = allowed[shape]
        params = np.zeros(4)
        if kind in (shapes.SPHERE, shapes.CAPSULE):
            if radius is None:
                raise InputError("radius", f"a {shape} needs a radius (m)")
            params[0] = _number(radius, "radius", 0.0, strict=True)
        if kind == shapes.CAPSULE:
            if half_length is None:
                raise InputError("half_length", "a capsule needs a half_length (m): half its segment's length")
            params[1] = _number(half_length, "half_length", 0.0)
        elif kind == shapes.BOX:
            if half_extents is None:
                raise InputError("half_extents", "a box needs half_extents = [hx, hy, hz] (m)")
            he = _vector(half_extents, "half_extents")
            if (he <= 0).any():
                raise InputError("half_extents", f"every half extent must be positive, found {he.tolist()}")
            params[:3] = he
        return kind, params

    # -- particles -------------------------------------------------------------------
    def add_particles(self, position, velocity=None, *, mass=1.0, radius=0.0, material=None):
        """Add particles; returns their indices (range).

        position, velocity: (count, 3) [m], [m/s]; mass [kg] and radius [m] are per particle
        (one number for all, or one per particle). A radius of 0 makes a point.
        """
        position = _array(position, "position", "a list of [x, y, z] points")
        if position.ndim == 1 and position.shape == (3,):
            position = position[None]
        if position.ndim != 2 or position.shape[1] != 3 or len(position) == 0:
            raise InputError("position", "expected a non-empty list of [x, y, z] points")
        if not np.isfinite(position).all():
            raise InputError("position", "expected finite numbers")
        count = len(position)
        if velocity is None:
            velocity = np.zeros_like(position)
        velocity = _array(velocity, "velocity", "a list of [vx, vy, vz] velocities")
        if velocity.shape != position.shape:
            raise InputError("velocity", f"expected {count} velocities, one per position")
        if not np.isfinite(velocity).all():
            raise InputError("velocity", "expected finite numbers")
        masses = self._per_particle(mass, "mass", count)
        if (masses <= 0).any() or not np.isfinite(masses).all():
            raise InputError("mass", f"must be greater than 0 (kg) for every particle, found {masses.min():g}")
        radii = self._per_particle(radius, "radius", count)
        if (radii < 0).any() or not np.isfinite(radii).all():
            raise InputError("radius", f"must be at least 0 (m) for every particle, found {radii.min():g}")
        start = sum(len(p["position"]) for p in self._particles)
        self._particles.append(dict(position=position, velocity=velocity, mass=masses,
                                    radius=radii, material=self._material_index(material)))
        return range(start, start + count)

    @staticmethod
    def _per_particle(value, name, count):
        array = _array(value, name, f"a number or a list of {count} numbers")
        if array.ndim == 0 or array.shape == (count,):
            return np.broadcast_to(array, (count,)).copy()
        raise InputError(name, f"expected a number or a list of {count} numbers (one per particle), "
                               f"found {array.size}")

    # -- static obstacles ------------------------------------------------------------
    def add_obstacle(self, shape, *, normal=None, offset=0.0, radius=None, half_extents=None, points=None,
                     file=None, scale=1.0, position=(0, 0, 0), orientation=(1, 0, 0, 0), material=None) -> int:
        """Add static geometry; returns its index.

        "plane": the half-space normal · x ≤ offset is solid (normal need not be unit).
        "sphere": radius, position. "box": half_extents, position, orientation.
        "convex": points or file (and scale), placed by position and orientation.
        "mesh": a triangle mesh file (OBJ/STL/PLY) times scale, placed by position and
        orientation; its triangles' winding makes their front side the outside.
        """
        position = _vector(position, "position")
        orientation = _orientation(orientation, "orientation")
        if shape == "plane":
            if normal is None:
                raise InputError("normal", "a plane needs a normal = [nx, ny, nz]")
            n = _vector(normal, "normal")
            length = np.linalg.norm(n)
            if length < 1e-12:
                raise InputError("normal", "the normal must not be zero")
            params = np.concatenate([n / length, [_number(offset, "offset") / length]])
            kind = shapes.PLANE
        elif shape == "mesh":
            from .meshes import load_mesh
            if file is None:
                raise InputError("file", "a mesh obstacle needs a file (OBJ, STL or PLY)")
            scale = _number(scale, "scale", 0.0, strict=True)
            mesh = load_mesh(file, scale, field="file").transformed(position, orientation)
            kind, params = shapes.MESH, np.array([len(self._meshes), 0.0, 0.0, 0.0])
            self._meshes.append(mesh)
        elif shape == "convex":
            hull = self._hull(points, file, scale)
            kind, params = shapes.CONVEX, np.array([len(self._hulls), hull.radius, 0.0, 0.0])
            self._hulls.append(hull)
            position, orientation = hull.body_pose(position, orientation)
        else:
            kind, params = self._solid_shape(shape, radius, half_extents, shapes.OBSTACLE_SHAPES)
        self._obstacles.append(dict(kind=kind, params=params, position=position, orientation=orientation,
                                    material=self._material_index(material)))
        return len(self._obstacles) - 1

    def _pack_hulls(self, shapes_with_params):
        """Pack the convex hulls, then one 8-corner hull per box (its index stored in params[3])."""
        from .collision.convex import box_as_hull
        from .hulls import pack_hulls
        packs = [pack_hulls(self._hulls)]
        count = len(self._hulls)
        for item in shapes_with_params:
            if item["kind"] == shapes.BOX:
                item["params"] = item["params"].copy()
                item["params"][3] = count
                packs.append(box_as_hull(item["params"][:3]))
                count += 1
        packed = _concatenate_packed(packs)
        packed.update(_fan_triangles(packed))
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
            return (np.concatenate([p[key] for p in particles]).reshape(shape) if particles
                    else np.zeros(shape if shape[0] != -1 else (0,) + shape[1:]))

        initial = State(
            time=0.0,
            body_position=stack(bodies, "position", (-1, 3)),
            body_orientation=stack(bodies, "orientation", (-1, 4)),
            body_velocity=stack(bodies, "velocity", (-1, 3)),
            body_angular_velocity=stack(bodies, "angular_velocity", (-1, 3)),
            particle_position=cat("position", (-1, 3)),
            particle_velocity=cat("velocity", (-1, 3)),
        )
        particle_material = (np.concatenate([np.full(len(p["position"]), p["material"]) for p in particles])
                             if particles else np.zeros(0, dtype=np.int64))
        return Model(
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
        )


def _concatenate_packed(packs):
    """Join packed hull dicts (contactlab.hulls.pack_hulls layout), shifting their start indices."""
    starts = {"vertex_start": "vertices", "face_start": "face_normal", "edge_start": "edge_vertex",
              "face_vertex_start": "face_vertex_index"}
    out = {key: [] for key in packs[0]}
    base = {key: 0 for key in starts}
    for number, pack in enumerate(packs):
        for key, values in pack.items():
            if key in starts:
                shifted = values + base[key]
                out[key].append(shifted if number == 0 else shifted[1:])
                base[key] += len(pack[starts[key]])
            else:
                out[key].append(values)
    return {key: np.ascontiguousarray(np.concatenate(values)) for key, values in out.items()}


def _fan_triangles(packed):
    """Triangles of every hull's faces, fanned from each face's first corner (built once).

    Returns triangle_start (H+1,) int64 and triangles (T, 3) int64, local vertex indices, wound
    like the faces (counter-clockwise from outside)."""
    triangles, counts = [], []
    fvs, fvi = packed["face_vertex_start"], packed["face_vertex_index"]
    for h in range(len(packed["vertex_start"]) - 1):
        before = len(triangles)
        for f in range(packed["face_start"][h], packed["face_start"][h + 1]):
            corners = fvi[fvs[f]:fvs[f + 1]]
            triangles.extend((corners[0], corners[i], corners[i + 1]) for i in range(1, len(corners) - 1))
        counts.append(len(triangles) - before)
    return {"triangle_start": np.concatenate([[0], np.cumsum(counts)]).astype(np.int64),
            "triangles": np.array(triangles, dtype=np.int64).reshape(-1, 3)}
