"""A contactlab Model in pybullet (Bullet): built in a DIRECT client, stepped, read back as contactlab States.

Built from :func:`contactlab.peers.translate.solids`: one rigid body per contactlab body,
created with maximal coordinates (a ``btRigidBody``, Bullet's own rigid body; pybullet's
reduced-coordinate ``btMultiBody`` is for articulations) at its centre of mass and principal
axes, its mass and principal moments set (``localInertiaDiagonal``: Bullet would approximate a
convex hull's by its bounding box), its initial velocities set; shapes: sphere, box (half
extents), capsule (radius, and the distance between its caps' centres, twice the half length,
along z), a convex body or obstacle as a convex hull of its corners (``GEOM_MESH``), a plane as
``GEOM_PLANE`` of normal z in a body turned onto the plane's normal, a triangle-mesh obstacle as
a static concave triangle mesh. The time step and gravity are set; the rest is pybullet's
default (the sequential-impulse solver, 50 iterations, split impulse, restitution below 0.2 m/s
ignored), with two exceptions that make it the scene's physics rather than a setting: no
velocity damping (pybullet damps its reduced-coordinate bodies by 0.04 a second by default; the
maximal-coordinate bodies built here have none, and it is set to 0 to say so) and no sleeping
(Bullet freezes a body that rests for 2 s; contactlab never does). benchmarks/peers.py builds
its worlds here too.

Materials: Bullet gives a contact the product of its two bodies' friction coefficients and the
product of their restitutions. Each shape gets √μ of its material, so every pair gets
√(μ_a μ_b), contactlab's geometric mean, exactly. Restitution cannot always be met (contactlab
takes the larger ε): the values chosen meet every pair of the scene where a product can, and the
run names the pairs it cannot (docs/peers.md).
"""

from __future__ import annotations

import math
import os
import sys

import numpy as np

from ..model import Model
from ..state import State
from . import translate

NAME = "pybullet"


def _imported_quietly():
    """pybullet, imported without its build banner: its C code prints "pybullet build time: …"
    on standard error as it loads, a line before every command's own (its one line of error)."""
    sys.stderr.flush()
    kept = os.dup(2)
    try:
        with open(os.devnull, "w", encoding="ascii") as nowhere:
            os.dup2(nowhere.fileno(), 2)
            import pybullet
    finally:
        os.dup2(kept, 2)
        os.close(kept)
    return pybullet


pybullet = _imported_quietly()


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("pybullet")
    except PackageNotFoundError:  # a build without metadata: the API date
        return str(pybullet.getAPIVersion())


class World:
    """One pybullet client (DIRECT: no window) holding a contactlab ``model``, stepped at ``dt`` [s].

    ``settings``: the engine's settings as used; ``notes``: how the materials were mapped and
    what they could not meet; ``bodies``: pybullet's body id of each contactlab body."""

    name = NAME

    def __init__(self, model: Model, dt: float) -> None:
        self.model = model
        self.client = pybullet.connect(pybullet.DIRECT)
        self.notes: list[str] = []
        try:
            self._build(model, dt)
        except BaseException:
            pybullet.disconnect(self.client)
            raise
        parameters = pybullet.getPhysicsEngineParameters(physicsClientId=self.client)
        self.settings = {
            "engine": NAME,
            "version": _version(),
            "solver": "sequential impulse",
            "integrator": "Bullet semi-implicit Euler",
            "iterations": int(parameters["numSolverIterations"]),
            "restitution_velocity_threshold": float(parameters.get("restitutionVelocityThreshold", 0.2)),
            "coordinates": "maximal",
            "damping": 0.0,
            "sleeping": False,
        }

    def _build(self, model, dt):
        p, c = pybullet, self.client
        p.setGravity(*map(float, model.gravity), physicsClientId=c)
        p.setTimeStep(float(dt), physicsClientId=c)
        friction, restitution = self._materials(model)
        bodies, obstacles = translate.solids(model)
        for solid in obstacles:
            shape = self._shape(solid)
            body = p.createMultiBody(
                0.0,
                shape,
                basePosition=list(map(float, solid.position)),
                baseOrientation=_xyzw(solid.orientation),
                physicsClientId=c,
            )
            p.changeDynamics(
                body,
                -1,
                lateralFriction=friction[solid.material],
                restitution=restitution[solid.material],
                physicsClientId=c,
            )
        self.bodies = []
        state = model.initial
        for solid in bodies:
            b = solid.body
            body = p.createMultiBody(
                float(model.body_mass[b]),
                self._shape(solid),
                basePosition=list(map(float, solid.position)),
                baseOrientation=_xyzw(solid.orientation),
                useMaximalCoordinates=True,
                physicsClientId=c,
            )
            p.changeDynamics(
                body,
                -1,
                mass=float(model.body_mass[b]),
                localInertiaDiagonal=list(map(float, model.body_inertia[b])),
                lateralFriction=friction[solid.material],
                restitution=restitution[solid.material],
                linearDamping=0.0,
                angularDamping=0.0,
                activationState=p.ACTIVATION_STATE_DISABLE_SLEEPING,
                physicsClientId=c,
            )
            p.resetBaseVelocity(
                body,
                list(map(float, state.body_velocity[b])),
                list(map(float, state.body_angular_velocity[b])),
                physicsClientId=c,
            )
            self.bodies.append(body)

    def _materials(self, model):
        """Per material: the shapes' friction (√μ) and restitution (see the module docstring)."""
        targets = translate.pair_targets(model)
        count = len(model.material_names)
        friction = np.sqrt(np.asarray(model.material_friction, dtype=float))
        epsilon = {pair: value[1] for pair, value in targets.items()}
        own = np.asarray(model.material_restitution, dtype=float)
        restitution, missed = translate.closest_values(
            epsilon,
            lambda a, b: a * b,
            [
                *translate.uniform(epsilon, count, math.sqrt),
                np.where(translate.static_only(model), 1.0, own),  # a static surface passes the body's ε on
                np.sqrt(own),
            ],
        )
        if missed:
            self.notes.append(
                translate.missed_sentence("pybullet", "restitution", "their product", missed, model.material_names)
            )
        return friction, restitution

    def _shape(self, solid):
        p, c = pybullet, self.client
        if solid.kind == "sphere":
            return p.createCollisionShape(p.GEOM_SPHERE, radius=solid.size[0], physicsClientId=c)
        if solid.kind == "box":
            return p.createCollisionShape(p.GEOM_BOX, halfExtents=list(solid.size), physicsClientId=c)
        if solid.kind == "capsule":
            radius, half_length = solid.size
            return p.createCollisionShape(p.GEOM_CAPSULE, radius=radius, height=2 * half_length, physicsClientId=c)
        if solid.kind == "plane":
            # the plane's own normal is z: the body's orientation (translate.solids: z onto the normal) turns it
            return p.createCollisionShape(p.GEOM_PLANE, planeNormal=[0.0, 0.0, 1.0], physicsClientId=c)
        if solid.kind == "convex":
            return p.createCollisionShape(p.GEOM_MESH, vertices=solid.vertices.tolist(), physicsClientId=c)
        return p.createCollisionShape(  # a static triangle mesh, concave
            p.GEOM_MESH,
            vertices=solid.vertices.tolist(),
            indices=[int(i) for i in np.ravel(solid.triangles)],
            physicsClientId=c,
        )

    def step(self, force: np.ndarray | None = None, torque: np.ndarray | None = None) -> None:
        """One time step, with the external ``force`` (B, 3) [N] and ``torque`` (B, 3) [N m]
        (world frame, at the centres of mass) over it (pybullet forgets them after the step)."""
        p, c = pybullet, self.client
        if force is not None and torque is not None:
            for b, body in enumerate(self.bodies):
                if force[b].any():
                    at = p.getBasePositionAndOrientation(body, physicsClientId=c)[0]
                    p.applyExternalForce(body, -1, list(force[b]), at, p.WORLD_FRAME, physicsClientId=c)
                if torque[b].any():
                    p.applyExternalTorque(body, -1, list(torque[b]), p.WORLD_FRAME, physicsClientId=c)
        p.stepSimulation(physicsClientId=c)

    def state(self, time: float = 0.0) -> State:
        """The present state as a contactlab State at ``time`` [s] (pybullet keeps no clock)."""
        p, c, B = pybullet, self.client, len(self.bodies)
        position, orientation = np.zeros((B, 3)), np.zeros((B, 4))
        velocity, angular = np.zeros((B, 3)), np.zeros((B, 3))
        for b, body in enumerate(self.bodies):
            x, q = p.getBasePositionAndOrientation(body, physicsClientId=c)
            v, w = p.getBaseVelocity(body, physicsClientId=c)
            position[b], velocity[b], angular[b] = x, v, w
            orientation[b] = (q[3], q[0], q[1], q[2])
        empty = np.zeros((0, 3))
        return State(float(time), position, orientation, velocity, angular, empty, empty.copy())

    def contacts(self) -> int:
        """The contact points of the last step."""
        return len(pybullet.getContactPoints(physicsClientId=self.client))

    def iterations(self) -> int | None:
        """None: pybullet does not say how many sweeps its solver made."""
        return None

    def close(self) -> None:
        """Disconnect the client."""
        pybullet.disconnect(self.client)


def _xyzw(q: np.ndarray) -> list[float]:
    """A unit quaternion (w, x, y, z) in pybullet's order (x, y, z, w)."""
    return [float(q[1]), float(q[2]), float(q[3]), float(q[0])]
