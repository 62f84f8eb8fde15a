"""Quantities that judge a run: energies, penetration, momentum. Pure functions of a state.

``SERIES`` names what every sample of a run holds: its time, the state's arrays and these
quantities with the solver's figures — the compiled loop's ``Samples`` and the Recorder's
series (``contactlab.record``) alike."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from . import rotations
from .compiling import njit
from .dynamics.cloth import spring_energy
from .state import ARRAYS as STATE_ARRAYS

if TYPE_CHECKING:
    from .contacts import Contacts
    from .model import Model
    from .state import State

SERIES = (
    "time",
    *STATE_ARRAYS,
    "energy_kinetic",
    "energy_potential",
    "energy_elastic",
    "max_penetration",
    "contact_count",
    "solver_iterations",
    "solver_residual",
)


def kinetic_energy(model: Model, state: State) -> float:
    """½ m v² + ½ ωᵀ I ω over bodies, ½ m v² over particles [J]."""
    return float(
        kinetic(
            model.body_mass,
            model.body_inertia,
            rotations.to_matrix(state.body_orientation),
            state.body_velocity,
            state.body_angular_velocity,
            model.particle_mass,
            state.particle_velocity,
        )
    )


@njit(cache=True)
def kinetic(
    body_mass: np.ndarray,
    body_inertia: np.ndarray,
    body_rotation: np.ndarray,
    body_velocity: np.ndarray,
    body_angular_velocity: np.ndarray,
    particle_mass: np.ndarray,
    particle_velocity: np.ndarray,
) -> float:
    """``kinetic_energy`` from the arrays [J]: masses (B,), (P,) [kg], principal inertia (B, 3)
    [kg m²], rotations (B, 3, 3), velocities (B, 3), (B, 3) world, (P, 3)."""
    energy = 0.0
    for b in range(body_mass.shape[0]):
        v, w, R = body_velocity[b], body_angular_velocity[b], body_rotation[b]
        energy += 0.5 * body_mass[b] * (v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
        for i in range(3):
            spin = R[0, i] * w[0] + R[1, i] * w[1] + R[2, i] * w[2]  # body frame: Rᵀ ω
            energy += 0.5 * body_inertia[b, i] * spin * spin
    for p in range(particle_mass.shape[0]):
        v = particle_velocity[p]
        energy += 0.5 * particle_mass[p] * (v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    return energy


def potential_energy(model: Model, state: State, cloth: float | None = None) -> float:
    """Gravitational potential −m g·x (zero at the origin) plus the elastic energy
    Σ ½ k (l − L)² of the cloth springs [J]; ``cloth``: the cloth's elastic energy [J] as an
    engine with a cloth model of its own computed it (a peer's), in place of the springs'."""
    return float(
        gravitational(
            model.body_mass,
            state.body_position,
            model.particle_mass,
            state.particle_position,
            np.asarray(model.gravity, dtype=float),
        )
        + (spring_energy(model, state.particle_position) if cloth is None else cloth)
    )


@njit(cache=True)
def gravitational(
    body_mass: np.ndarray,
    body_position: np.ndarray,
    particle_mass: np.ndarray,
    particle_position: np.ndarray,
    gravity: np.ndarray,
) -> float:
    """The gravitational part of ``potential_energy``, Σ −m g·x over bodies and particles [J]."""
    energy = 0.0
    for masses, positions in ((body_mass, body_position), (particle_mass, particle_position)):
        for n in range(masses.shape[0]):
            x = positions[n]
            energy -= masses[n] * (x[0] * gravity[0] + x[1] * gravity[1] + x[2] * gravity[2])
    return energy


def max_penetration(contacts: Contacts) -> float:
    """Deepest overlap among contacts [m], 0 when none overlap."""
    return float(max(0.0, contacts.depth.max())) if contacts.count else 0.0


def sample_of(model: Model, state: State, contacts: Contacts, info: Any = None) -> dict[str, Any]:
    """One sample of a run, the series of SERIES by name: ``state``'s time and arrays, its
    energies [J] and the deepest overlap [m] among ``contacts`` (those of a collision pass at its
    own positions), with what the step that made it says (``info``, a method's StepInfo: its
    contact count, sweeps, last change and elastic energy, and a peer's ``cloth_energy`` where it
    has one; None, no step: the count of ``contacts``, no sweeps, no elastic energy)."""
    return dict(
        time=state.time,
        body_position=state.body_position,
        body_orientation=state.body_orientation,
        body_velocity=state.body_velocity,
        body_angular_velocity=state.body_angular_velocity,
        particle_position=state.particle_position,
        particle_velocity=state.particle_velocity,
        energy_kinetic=kinetic_energy(model, state),
        energy_potential=potential_energy(model, state, getattr(info, "cloth_energy", None)),
        energy_elastic=info.energy_elastic if info else 0.0,
        max_penetration=max_penetration(contacts),
        contact_count=info.contacts.count if info else contacts.count,
        solver_iterations=info.solver_iterations if info else 0,
        solver_residual=info.solver_residual if info else 0.0,
    )


def linear_momentum(model: Model, state: State) -> np.ndarray:
    """Total linear momentum (3,) [kg m/s]."""
    return model.body_mass @ state.body_velocity + model.particle_mass @ state.particle_velocity


def angular_momentum(model: Model, state: State, origin: ArrayLike = (0.0, 0.0, 0.0)) -> np.ndarray:
    """Total angular momentum about ``origin`` (3,) [kg m²/s]: spins plus orbital parts."""
    origin = np.asarray(origin, dtype=float)
    total = np.zeros(3)
    if model.body_count:
        inertia_world = rotations.world_inertia(rotations.to_matrix(state.body_orientation), model.body_inertia)
        total += np.einsum("bij,bj->i", inertia_world, state.body_angular_velocity)
        total += np.sum(np.cross(state.body_position - origin, model.body_mass[:, None] * state.body_velocity), axis=0)
    total += np.sum(
        np.cross(state.particle_position - origin, model.particle_mass[:, None] * state.particle_velocity), axis=0
    )
    return total
