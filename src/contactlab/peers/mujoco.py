"""A contactlab Model in MuJoCo: MJCF written from the model, stepped, read back as contactlab States.

Written from :func:`contactlab.peers.translate.solids`, one MuJoCo body with a free joint per
contactlab body (its frame the body's centre of mass and principal axes, its mass and principal
moments given as an explicit ``<inertial>``, so MuJoCo computes none of its own), one geom per
shape: sphere, box (half extents), capsule (radius, half length along z), a convex body or
obstacle as a mesh of its hull's corners (MuJoCo takes their convex hull), a plane as an
infinite plane geom, a convex triangle-mesh obstacle as a mesh. ``<option>`` sets the time step
and gravity; everything else is MuJoCo's default (Newton solver, at most 100 iterations, the
pyramidal friction cone, Euler integration, soft contacts with solimp 0.9 0.95 0.001).

Materials: MuJoCo gives a contact the larger of its two geoms' friction coefficients and the
mean of their ``solref``. It has no restitution coefficient: a contact is a spring-damper of
time constant 0.02 s (its default) and damping ratio ζ, critically damped (ζ = 1, no bounce) by
default; contactlab's ε becomes ζ = −ln ε / √(π² + ln² ε) (:func:`~.translate.damping_ratio`),
the ratio at which a linear spring-damper returns ε of the approach speed. Where the scene's
material pairs cannot all be met by those rules, the run says which (docs/peers.md).
"""

from __future__ import annotations

import mujoco
import numpy as np

from ..model import Model
from ..state import State
from . import translate

NAME = "mujoco"
TIME_CONSTANT = 0.02  # s: MuJoCo's default solref time constant, kept; only the damping ratio carries ε
TORSION, ROLLING = 0.005, 0.0001  # MuJoCo's default torsional and rolling friction (unused at condim 3)


def _numbers(values) -> str:
    return " ".join(repr(float(v)) for v in np.ravel(values))


class World:
    """One MuJoCo model and data of a contactlab ``model`` stepped at ``dt`` [s].

    ``xml`` is the MJCF it was built from; ``settings`` the engine's settings as used (its
    version, solver, cone, iterations, integrator); ``notes`` the sentences saying how the
    scene's materials were mapped and what they could not meet."""

    name = NAME

    def __init__(self, model: Model, dt: float) -> None:
        self.model = model
        bodies, obstacles = translate.solids(model)
        self.notes: list[str] = []
        friction, damping = self._materials(model)
        assets: list[str] = []
        world: list[str] = []
        for index, solid in enumerate(obstacles):
            world.append(self._geom(solid, f"obstacle{index}", friction, damping, assets))
        for solid in bodies:
            b = solid.body
            mass, inertia = model.body_mass[b], model.body_inertia[b]
            world.append(
                f'<body name="body{b}" pos="{_numbers(solid.position)}" quat="{_numbers(solid.orientation)}">'
                f'<freejoint/><inertial pos="0 0 0" mass="{float(mass)!r}" diaginertia="{_numbers(inertia)}"/>'
                + self._geom(solid, f"body{b}", friction, damping, assets, placed=False)
                + "</body>"
            )
        self.xml = (
            f'<mujoco model="contactlab"><option timestep="{float(dt)!r}" gravity="{_numbers(model.gravity)}"/>'
            f"<asset>{''.join(assets)}</asset><worldbody>{''.join(world)}</worldbody></mujoco>"
        )
        self.mj_model = mujoco.MjModel.from_xml_string(self.xml)
        self.data = mujoco.MjData(self.mj_model)
        self._start(model)
        self.settings = {
            "engine": NAME,
            "version": mujoco.__version__,
            "solver": _spelt(mujoco.mjtSolver(self.mj_model.opt.solver).name.removeprefix("mjSOL_")),
            "iterations": int(self.mj_model.opt.iterations),
            "cone": mujoco.mjtCone(self.mj_model.opt.cone).name.removeprefix("mjCONE_").lower(),
            "integrator": "MuJoCo "
            + _spelt(mujoco.mjtIntegrator(self.mj_model.opt.integrator).name.removeprefix("mjINT_")),
        }

    def _materials(self, model):
        """Per material: the geoms' friction and solref damping ratio (see the module docstring)."""
        targets = translate.pair_targets(model)
        count = len(model.material_names)
        mu = {pair: value[0] for pair, value in targets.items()}
        zeta = {pair: translate.damping_ratio(value[1]) for pair, value in targets.items()}
        own_mu = np.asarray(model.material_friction, dtype=float)
        own_zeta = np.array([translate.damping_ratio(e) for e in model.material_restitution])
        friction, missed = translate.fit(mu, max, [*translate.uniform(mu, count, float), own_mu])
        if missed:
            self.notes.append(
                translate.missed_sentence("MuJoCo", "friction", "the larger", missed, model.material_names)
            )
        damping, missed = translate.fit(
            zeta, lambda a, b: (a + b) / 2, [*translate.uniform(zeta, count, float), own_zeta]
        )
        if missed:
            self.notes.append(
                translate.missed_sentence("MuJoCo", "solref damping ratio", "their mean", missed, model.material_names)
            )
        if any(value[1] > 0 for value in targets.values()):
            names = model.material_names
            self.notes.append(
                "MuJoCo has no restitution coefficient: ε is given as the damping ratio ζ = −ln ε / √(π² + ln² ε) "
                f"of its contact spring-damper (solref time constant {TIME_CONSTANT} s, its default): "
                + ", ".join(
                    f"{names[a]}–{names[b]} ε {value[1]:.3g} → ζ {(damping[a] + damping[b]) / 2:.3g}"
                    for (a, b), value in targets.items()
                )
                + "."
            )
        return friction, damping

    def _geom(self, solid, name, friction, damping, assets, placed=True):
        """The MJCF geom of ``solid`` (its pose written where ``placed``: an obstacle's; a body's
        geom sits at its body's frame), adding a mesh asset where it needs one."""
        m = solid.material
        common = f'friction="{float(friction[m])!r} {TORSION} {ROLLING}" solref="{TIME_CONSTANT} {float(damping[m])!r}"'
        pose = f' pos="{_numbers(solid.position)}" quat="{_numbers(solid.orientation)}"' if placed else ""
        if solid.kind == "plane":
            return f'<geom name="{name}" type="plane" size="0 0 1"{pose} {common}/>'
        if solid.kind in ("sphere", "box", "capsule"):
            return f'<geom name="{name}" type="{solid.kind}" size="{_numbers(solid.size)}"{pose} {common}/>'
        if solid.kind == "convex":
            assets.append(f'<mesh name="{name}" vertex="{_numbers(solid.vertices)}"/>')
        else:  # a convex triangle mesh in world coordinates (translate.gaps refuses the others)
            faces = " ".join(str(int(i)) for i in np.ravel(solid.triangles))
            assets.append(f'<mesh name="{name}" vertex="{_numbers(solid.vertices)}" face="{faces}"/>')
            pose = ""
        return f'<geom name="{name}" type="mesh" mesh="{name}"{pose} {common}/>'

    def _start(self, model):
        """The initial state: poses as built; velocities (the free joint's angular one is in the body frame)."""
        state = model.initial
        for b in range(model.body_count):
            dof = self.mj_model.jnt_dofadr[self.mj_model.body_jntadr[b + 1]]
            R = _matrix(state.body_orientation[b])
            self.data.qvel[dof : dof + 3] = state.body_velocity[b]
            self.data.qvel[dof + 3 : dof + 6] = R.T @ state.body_angular_velocity[b]
        mujoco.mj_forward(self.mj_model, self.data)

    def step(self, force: np.ndarray | None = None, torque: np.ndarray | None = None) -> None:
        """One time step, with the external ``force`` (B, 3) [N] and ``torque`` (B, 3) [N m]
        (world frame, at the centres of mass) held over it; None: none."""
        if force is not None and torque is not None:
            self.data.xfrc_applied[1:, :3] = force
            self.data.xfrc_applied[1:, 3:] = torque
        mujoco.mj_step(self.mj_model, self.data)

    def state(self, time: float | None = None) -> State:
        """The present state as a contactlab State at ``time`` [s] (default: MuJoCo's clock),
        its angular velocity turned into the world frame."""
        B, m, d = self.model.body_count, self.mj_model, self.data
        position, orientation = np.zeros((B, 3)), np.zeros((B, 4))
        velocity, angular = np.zeros((B, 3)), np.zeros((B, 3))
        for b in range(B):
            joint = m.body_jntadr[b + 1]
            q, v = m.jnt_qposadr[joint], m.jnt_dofadr[joint]
            position[b] = d.qpos[q : q + 3]
            orientation[b] = d.qpos[q + 3 : q + 7] / np.linalg.norm(d.qpos[q + 3 : q + 7])
            velocity[b] = d.qvel[v : v + 3]
            angular[b] = _matrix(orientation[b]) @ d.qvel[v + 3 : v + 6]
        empty = np.zeros((0, 3))
        now = float(d.time if time is None else time)
        return State(now, position, orientation, velocity, angular, empty, empty.copy())

    def contacts(self) -> int:
        """The contacts of the last step."""
        return int(self.data.ncon)

    def iterations(self) -> int | None:
        """The solver's iterations in the last step (the most of any island)."""
        return int(np.max(self.data.solver_niter))

    def close(self) -> None:
        """Nothing to release (the model and data are freed with the object)."""


def _spelt(name: str) -> str:
    """MuJoCo's enum name as its docs write it: NEWTON → Newton, EULER → Euler, CG and PGS as they are."""
    return name if len(name) <= 3 else name.capitalize()


def _matrix(q: np.ndarray) -> np.ndarray:
    out = np.zeros(9)
    mujoco.mju_quat2Mat(out, np.asarray(q, dtype=float))
    return out.reshape(3, 3)
