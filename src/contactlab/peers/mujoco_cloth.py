"""contactlab's cloth in MuJoCo: each cloth a 2D flex of its own vertices and triangles.

Written from :func:`contactlab.peers.translate.sheets`. Every free vertex is a MuJoCo body at
its initial position with three slide joints along the world axes and its own mass (what
``<flexcomp>`` generates, written out here so that the vertices keep contactlab's particle
order and per-vertex masses, which flexcomp would number itself and split evenly); a pinned
vertex is a vertex of the world body, held where it is. One ``<flex dim="2">`` per cloth joins
them by contactlab's triangles (counter-clockwise seen from the front, as MuJoCo wants them),
its radius the cloth's thickness, so MuJoCo keeps its triangles that far from obstacles, bodies
and (``selfcollide``) each other.

Stiffness: MuJoCo's 2D flex has no springs (edge stiffness is for 1D flexes, and the
``discrete`` integrator refuses it): its elasticity is a continuum membrane (Saint
Venant–Kirchhoff, Young's modulus E, Poisson ratio ν, thickness t) and a hinge bending energy.
The membrane is the isotropic one closest to the cloth's springs (translate.membrane: E t =
Σ k L² / 3A, ν = 1/3, Rayleigh damping β = Σ c L² / Σ k L²), given as E = E t / t with t twice
the radius, the thickness MuJoCo suggests. No bending (``elastic2d="stretch"``): contactlab's
bend springs, between vertices two apart, lengthen by a part of the square of a small bend and
store energy of its fourth power, so the sheet has no bending stiffness at rest to match, and
MuJoCo's hinge energy, of the bend's square, would give it one. MuJoCo integrates flex
elasticity implicitly only with its ``discrete`` integrator (it refuses ``implicit`` and
``implicitfast``, and ``Euler`` diverges on these stiff membranes at the scenes' time steps),
so a scene with cloth is stepped with it: the one setting of MuJoCo's that the translation
changes, as contactlab's cloth scenes choose backward Euler.

Reading back is vectorised: positions are each vertex's rest position plus its three slide
joints' ``qpos`` (``flexvert_xpos`` is the kinematics of the step's start, one step behind
after ``mj_step``), velocities their ``qvel``; a pinned vertex stays where it is, at rest.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from ..model import Model
from . import translate

INERTIA_BOX = 0.005  # m: the side of a vertex body's inertia box, flexcomp's default (slide joints: it never acts)
AXES = np.arange(3)  # a vertex's three slide joints, x, y and z, are consecutive


def _numbers(values) -> str:
    return " ".join(repr(float(v)) for v in np.ravel(values))


def _name(cloth: int, vertex: int | np.integer) -> str:
    return f"cloth{cloth}_{vertex}"


class Flexes:
    """The cloths of ``model`` as MuJoCo flexes, on either side of MuJoCo's compile.

    Before: ``bodies`` (the vertex bodies, MJCF for the worldbody), ``deformable`` (the
    ``<deformable>`` element, "" without cloth) and ``notes`` (a sentence per cloth: how it was
    given), written with ``contact(material)``, the contact attributes (friction, solref) of a
    material's geoms. After: :meth:`bind` to the compiled model, then :meth:`start` and
    :meth:`read` move the vertices' state in and out of ``mjData``, P particles at once."""

    def __init__(self, model: Model, contact: Callable[[int], str]) -> None:
        self.sheets = translate.sheets(model)
        self.particles = model.particle_count
        self.position = np.array(model.initial.particle_position, dtype=float).reshape(-1, 3)
        self.velocity = np.array(model.initial.particle_velocity, dtype=float).reshape(-1, 3)
        bodies, flexes, self.notes = [], [], []
        for c, sheet in enumerate(self.sheets):
            inertia = sheet.mass * INERTIA_BOX**2 / 6.0  # a box of side INERTIA_BOX about any axis
            bodies += [
                f'<body name="{_name(c, v)}" pos="{_numbers(sheet.position[v])}"><inertial pos="0 0 0" '
                f'mass="{float(sheet.mass[v])!r}" diaginertia="{_numbers([inertia[v]] * 3)}"/>'
                '<joint type="slide" axis="1 0 0"/><joint type="slide" axis="0 1 0"/>'
                '<joint type="slide" axis="0 0 1"/></body>'
                for v in np.flatnonzero(~sheet.pinned)
            ]
            names = " ".join("world" if sheet.pinned[v] else _name(c, v) for v in range(len(sheet.mass)))
            local = np.where(sheet.pinned[:, None], sheet.position, 0.0)
            thickness = 2.0 * sheet.thickness
            flexes.append(
                f'<flex name="cloth{c}" dim="2" radius="{sheet.thickness!r}" body="{names}" '
                f'vertex="{_numbers(local)}" element="{" ".join(str(int(i)) for i in sheet.triangles.ravel())}">'
                f'<contact {contact(sheet.material)} selfcollide="{"auto" if sheet.self_collision else "none"}"/>'
                f'<elasticity young="{sheet.stretch_modulus / thickness!r}" poisson="{translate.POISSON!r}" '
                f'thickness="{thickness!r}" damping="{sheet.rayleigh!r}" elastic2d="stretch"/></flex>'
            )
            self.notes.append(
                f"The cloth {sheet.name!r} is a MuJoCo flex of its {len(sheet.mass):,} vertices and "
                f"{len(sheet.triangles):,} triangles, radius its thickness {sheet.thickness:g} m, stretched by the "
                f"isotropic membrane closest to its springs (E t = {sheet.stretch_modulus:.4g} N/m, Poisson ratio 1/3, "
                f"Rayleigh damping {sheet.rayleigh:.3g} s), without bending stiffness (its bend springs have none at "
                "rest; docs/peers.md)."
            )
        self.bodies = "".join(bodies)
        self.deformable = f"<deformable>{''.join(flexes)}</deformable>" if flexes else ""
        self._membranes()

    def _membranes(self):
        """Each triangle's rest state for :meth:`energy`: its corners (F, 3) as particles, the
        inverse (F, 2, 2) of its rest edges in its own plane, its rest area (F,) [m²] and its
        membrane's t μ and t λ* (F,) [N/m] of Young's modulus and Poisson's ratio."""
        corners, inverse, area, shear, lame = [], [], [], [], []
        nu = translate.POISSON
        for sheet in self.sheets:
            x = sheet.position[sheet.triangles]  # (F, 3, 3): corner, axis
            e1, e2 = x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]
            normal = np.cross(e1, e2)
            double = np.linalg.norm(normal, axis=1)
            u = e1 / np.linalg.norm(e1, axis=1)[:, None]
            w = np.cross(normal / double[:, None], u)
            rest = np.stack([np.einsum("fk,fk->f", e1, u), np.einsum("fk,fk->f", e2, u)], axis=1)  # (F, 2): u row
            rest = np.stack([rest, np.stack([np.zeros(len(u)), np.einsum("fk,fk->f", e2, w)], axis=1)], axis=1)
            corners.append(sheet.particles[sheet.triangles])
            inverse.append(np.linalg.inv(rest))
            area.append(0.5 * double)
            shear.append(np.full(len(u), sheet.stretch_modulus / (2.0 * (1.0 + nu))))
            lame.append(np.full(len(u), sheet.stretch_modulus * nu / (1.0 - nu * nu)))
        self._corners = np.concatenate(corners) if corners else np.zeros((0, 3), dtype=np.int64)
        self._inverse, self._area, self._shear, self._lame = (
            np.concatenate(part) if part else np.zeros(0) for part in (inverse, area, shear, lame)
        )

    def energy(self, position: np.ndarray) -> float:
        """The elastic energy [J] MuJoCo's membranes store at particle positions (P, 3) [m]:
        Σ over triangles of rest area × (t μ tr(E²) + ½ t λ* tr(E)²), E = ½ (Fᵀ F − I) the Green
        strain of the triangle's deformation gradient F (3 × 2, from its rest plane), as MuJoCo's
        documentation states its 2D Saint Venant–Kirchhoff flex (elastic2d "stretch")."""
        x = position[self._corners]
        edges = np.stack([x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]], axis=2)  # (F, 3, 2)
        gradient = edges @ self._inverse
        strain = 0.5 * (np.swapaxes(gradient, 1, 2) @ gradient - np.eye(2))
        trace = strain[:, 0, 0] + strain[:, 1, 1]
        squares = np.einsum("fij,fij->f", strain, strain)
        return float(self._area @ (self._shear * squares + 0.5 * self._lame * trace * trace))

    def bind(self, mj_model: Any) -> None:
        """Find each free vertex's slide joints in the compiled ``mj_model``."""
        free = [
            (sheet.particles[v], _name(c, v))
            for c, sheet in enumerate(self.sheets)
            for v in np.flatnonzero(~sheet.pinned)
        ]
        self._free = np.array([p for p, _ in free], dtype=np.int64)
        bodies = np.array([mj_model.body(name).id for _, name in free], dtype=np.int64)
        joints = np.asarray(mj_model.body_jntadr)[bodies] if len(bodies) else np.zeros(0, dtype=np.int64)
        self._qpos = np.asarray(mj_model.jnt_qposadr)[joints][:, None] + AXES  # (free, 3)
        self._dof = np.asarray(mj_model.jnt_dofadr)[joints][:, None] + AXES

    def start(self, data: Any) -> None:
        """Give the free vertices their initial velocities in ``data`` (their positions are the bodies')."""
        data.qvel[self._dof] = self.velocity[self._free]

    def read(self, data: Any) -> tuple[np.ndarray, np.ndarray]:
        """(position (P, 3) [m], velocity (P, 3) [m/s]) of every particle in ``data``: a pinned
        vertex where it started, at rest."""
        position, velocity = self.position.copy(), np.zeros((self.particles, 3))
        position[self._free] += data.qpos[self._qpos]
        velocity[self._free] = data.qvel[self._dof]
        return position, velocity
