"""A contactlab Model in MuJoCo: MJCF written from the model, stepped, read back as contactlab States.

Written from :func:`contactlab.peers.translate.solids`, one MuJoCo body with a free joint per
contactlab body (its frame the body's centre of mass and principal axes, its mass and principal
moments given as an explicit ``<inertial>``, so MuJoCo computes none of its own), one geom per
shape: sphere, box (half extents), capsule (radius, half length along z), a convex body or
obstacle as a mesh of its hull's corners (MuJoCo takes their convex hull), a plane as an
infinite plane geom, a convex triangle-mesh obstacle as a mesh; each cloth a 2D flex after
them (contactlab.peers.mujoco_cloth). ``<option>`` sets the time step and gravity, and the
``discrete`` integrator where the scene has cloth (the only one that integrates a flex's
elasticity implicitly); everything else is MuJoCo's default (Newton solver, at most 100
iterations, the pyramidal friction cone, Euler integration, soft contacts with solimp 0.9 0.95
0.001).

Materials: MuJoCo gives a contact the larger of its two geoms' friction coefficients and the
mean of their ``solref``. It has no restitution coefficient: a contact is a spring-damper of
time constant 0.02 s (its default) and damping ratio ζ, critically damped (ζ = 1, no bounce) by
default, which a material with ε = 0 keeps. A material with ε > 0 gets the time constant
0.02 s or 20 time steps, the longer (:func:`bouncing_time_constant`), and the ζ at which
MuJoCo's own discrete contact then returns ε of the approach speed on average
(:func:`damping_for`: a sphere meets a plane at 1 m/s without gravity in a probe model, at five
depths within a step, ζ bisected). The continuous spring-damper's ζ = −ln ε / √(π² + ln² ε) is
not it: MuJoCo resolves such a contact in a few steps, and that ζ returned 0.86 of the speed for
ε = 0.8 at dt = 1 ms and flung the ball up to eight times as fast at dt = 1/240 s. Where the
scene's material pairs cannot all be met by those rules, the run says which (docs/peers.md).
"""

from __future__ import annotations

import functools

import mujoco
import numpy as np

from ..model import Model
from ..state import State
from . import translate
from .mujoco_cloth import Flexes

NAME = "mujoco"
TIME_CONSTANT = 0.02  # s: MuJoCo's default solref time constant, kept for a material that does not bounce
BOUNCE_STEPS = 20  # time steps a bouncing material's time constant spans at least (the default's at dt = 1 ms)
TORSION, ROLLING = 0.005, 0.0001  # MuJoCo's default torsional and rolling friction (unused at condim 3)
PROBE_SPEED = 1.0  # m/s: the approach speed at which damping_for measures MuJoCo's bounce
BISECTIONS = 30  # halvings of the damping ratio's interval (0, 1]: ζ to 1e-9


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
        friction, damping = self._materials(model, dt)
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
        self.flexes = Flexes(model, lambda material: self._contact(material, friction, damping))
        self.notes += self.flexes.notes
        integrator = ' integrator="discrete"' if model.cloth_count else ""  # the cloth's elasticity needs it
        self.xml = (
            f'<mujoco model="contactlab"><option timestep="{float(dt)!r}" gravity="{_numbers(model.gravity)}"'
            f"{integrator}/><asset>{''.join(assets)}</asset><worldbody>{''.join(world)}{self.flexes.bodies}"
            f"</worldbody>{self.flexes.deformable}</mujoco>"
        )
        self.mj_model = mujoco.MjModel.from_xml_string(self.xml)
        self.data = mujoco.MjData(self.mj_model)
        self.flexes.bind(self.mj_model)
        self._start(model)
        self.settings = {
            "engine": NAME,
            "version": mujoco.__version__,
            "solver": _spelt(mujoco.mjtSolver(self.mj_model.opt.solver).name.removeprefix("mjSOL_")),
            "iterations": int(self.mj_model.opt.iterations),
            "cone": mujoco.mjtCone(self.mj_model.opt.cone).name.removeprefix("mjCONE_").lower(),
            "integrator": "MuJoCo "
            + _spelt(mujoco.mjtIntegrator(self.mj_model.opt.integrator).name.removeprefix("mjINT_")),
            "cloth": bool(model.cloth_count),
        }

    def _materials(self, model, dt):
        """Per material: the geoms' friction and solref damping ratio (see the module docstring)."""
        targets = translate.pair_targets(model)
        count = len(model.material_names)
        mu = {pair: value[0] for pair, value in targets.items()}
        zeta = {pair: damping_for(value[1], dt) for pair, value in targets.items()}
        own_mu = np.asarray(model.material_friction, dtype=float)
        own_zeta = np.array([damping_for(e, dt) for e in model.material_restitution])
        friction, missed = translate.closest_values(mu, max, [*translate.uniform(mu, count, float), own_mu])
        if missed:
            self.notes.append(
                translate.missed_sentence("MuJoCo", "friction", "the larger", missed, model.material_names)
            )
        self.time_constant = bouncing_time_constant(dt)
        damping, missed = translate.closest_values(
            zeta, lambda a, b: (a + b) / 2, [*translate.uniform(zeta, count, float), own_zeta]
        )
        if missed:
            self.notes.append(
                translate.missed_sentence("MuJoCo", "solref damping ratio", "their mean", missed, model.material_names)
            )
        if any(value[1] > 0 for value in targets.values()):
            names = model.material_names
            self.notes.append(
                "MuJoCo has no restitution coefficient: ε is given as the damping ratio ζ of its contact "
                f"spring-damper, with the solref time constant {self.time_constant:.3g} s (its default "
                f"{TIME_CONSTANT} s or {BOUNCE_STEPS} time steps, the longer), at which its own contact at "
                f"dt = {dt:g} s returns ε of a {PROBE_SPEED:g} m/s approach without gravity, on average: "
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
        common = self._contact(solid.material, friction, damping)
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

    def _contact(self, material, friction, damping):
        """The contact attributes of a geom or flex of ``material``: its friction and solref."""
        constant = TIME_CONSTANT if damping[material] >= 1.0 else self.time_constant  # a bouncing material's
        return (
            f'friction="{float(friction[material])!r} {TORSION} {ROLLING}" '
            f'solref="{constant!r} {float(damping[material])!r}"'
        )

    def _start(self, model):
        """The initial state: poses as built; velocities (the free joint's angular one is in the body frame)."""
        state = model.initial
        for b in range(model.body_count):
            dof = self.mj_model.jnt_dofadr[self.mj_model.body_jntadr[b + 1]]
            R = _matrix(state.body_orientation[b])
            self.data.qvel[dof : dof + 3] = state.body_velocity[b]
            self.data.qvel[dof + 3 : dof + 6] = R.T @ state.body_angular_velocity[b]
        self.flexes.start(self.data)
        mujoco.mj_forward(self.mj_model, self.data)

    def step(self, force: np.ndarray | None = None, torque: np.ndarray | None = None) -> None:
        """One time step, with the external ``force`` (B, 3) [N] and ``torque`` (B, 3) [N m]
        (world frame, at the centres of mass) held over it; None: none."""
        if force is not None and torque is not None:
            bodies = slice(1, 1 + self.model.body_count)  # a cloth's vertex bodies come after them
            self.data.xfrc_applied[bodies, :3] = force
            self.data.xfrc_applied[bodies, 3:] = torque
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
        now = float(d.time if time is None else time)
        return State(now, position, orientation, velocity, angular, *self.flexes.read(d))

    def cloth_energy(self, state: State) -> float:
        """The elastic energy [J] of MuJoCo's flexes at ``state``'s particle positions
        (contactlab.peers.mujoco_cloth.Flexes.energy): the cloth's own, not contactlab's springs'."""
        return self.flexes.energy(state.particle_position)

    def contacts(self) -> int:
        """The contacts of the last step."""
        return int(self.data.ncon)

    def iterations(self) -> int | None:
        """The solver's iterations in the last step (the most of any island)."""
        return int(np.max(self.data.solver_niter))

    def close(self) -> None:
        """Nothing to release (the model and data are freed with the object)."""


@functools.lru_cache(maxsize=256)
def damping_for(restitution: float, dt: float) -> float:
    """The solref damping ratio ζ (0, 1] at which MuJoCo's contact at time step ``dt`` [s]
    returns, on average, the share ``restitution`` (ε) of the approach speed (:func:`_bounce`:
    a sphere meets a plane at PROBE_SPEED without gravity), bisected (the bounce falls as ζ
    grows). ε ≤ 0: 1, MuJoCo's default (no bounce); an ε that ζ = 1 still exceeds: 1."""
    if restitution <= 0.0:
        return 1.0
    probe = _Probe(dt, bouncing_time_constant(dt))
    low, high = 0.0, 1.0  # the bounce at low exceeds ε, at high it does not
    if probe.bounce(high) >= restitution:
        return high
    for _ in range(BISECTIONS):
        middle = 0.5 * (low + high)
        if probe.bounce(middle) > restitution:
            low = middle
        else:
            high = middle
    return 0.5 * (low + high)


def bouncing_time_constant(dt: float) -> float:
    """The solref time constant [s] of a material that bounces at time step ``dt`` [s]: MuJoCo's
    default 0.02 s, or BOUNCE_STEPS steps where that is longer. A contact of damping ratio ζ
    lasts about π ζ time constants; MuJoCo's default at dt = 1 ms resolves a bounce of ε = 0.8 in
    4–5 steps, and the same time constant at dt = 1/240 s in one or two, where some impacts
    gain energy (up to 1.47 of the approach speed): 20 steps keep every dt at the default's 1 ms
    resolution."""
    return max(TIME_CONSTANT, BOUNCE_STEPS * float(dt))


class _Probe:
    """A 1 kg sphere (r = 0.1 m) over a plane in MuJoCo at time step ``dt`` [s] and solref time
    constant ``constant`` [s] (both geoms), no gravity."""

    RADIUS = 0.1
    PHASES = (0.1, 0.3, 0.5, 0.7, 0.9)  # where within a step the sphere reaches the plane, in steps

    def __init__(self, dt: float, constant: float) -> None:
        xml = (
            f'<mujoco><option timestep="{float(dt)!r}" gravity="0 0 0"/><worldbody>'
            f'<geom type="plane" size="0 0 1" solref="{constant!r} 1"/><body><freejoint/>'
            f'<geom type="sphere" size="{self.RADIUS}" mass="1" solref="{constant!r} 1"/></body>'
            "</worldbody></mujoco>"
        )
        self.model = mujoco.MjModel.from_xml_string(xml)
        self.data = mujoco.MjData(self.model)
        self.dt = float(dt)

    def bounce(self, zeta: float) -> float:
        """The share of PROBE_SPEED the sphere leaves with at damping ratio ``zeta`` (both geoms),
        the mean over PHASES: a discrete contact's bounce depends on how deep the first step
        that touches goes (by up to 10 % at 4–5 steps a contact), which a falling body meets at
        any depth."""
        m, d = self.model, self.data
        m.geom_solref[:, 1] = zeta
        shares = []
        for phase in self.PHASES:
            mujoco.mj_resetData(m, d)
            d.qpos[2] = self.RADIUS + phase * PROBE_SPEED * self.dt
            d.qvel[2] = -PROBE_SPEED
            touched, share = False, 0.0
            for _ in range(max(100, int(round(1.0 / self.dt)))):  # a contact lasts a few time constants
                mujoco.mj_step(m, d)
                touched = touched or d.ncon > 0
                if touched and d.ncon == 0:
                    share = max(float(d.qvel[2]), 0.0) / PROBE_SPEED
                    break
            shares.append(share)
        return float(np.mean(shares))


def _spelt(name: str) -> str:
    """MuJoCo's enum name as its docs write it: NEWTON → Newton, EULER → Euler, CG and PGS as they are."""
    return name if len(name) <= 3 else name.capitalize()


def _matrix(q: np.ndarray) -> np.ndarray:
    out = np.zeros(9)
    mujoco.mju_quat2Mat(out, np.asarray(q, dtype=float))
    return out.reshape(3, 3)
