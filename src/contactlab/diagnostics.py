"""Quantities that judge a run: energies, penetration, momentum. Pure functions of a state."""

import numpy as np

from . import rotations
from .dynamics.cloth import spring_energy


def kinetic_energy(model, state) -> float:
    """½ m v² + ½ ωᵀ I ω over bodies, ½ m v² over particles [J]."""
    energy = 0.5 * np.sum(model.body_mass * np.einsum("bi,bi->b", state.body_velocity, state.body_velocity))
    if model.body_count:
        R = rotations.to_matrix(state.body_orientation)
        w_body = np.einsum("bji,bj->bi", R, state.body_angular_velocity)
        energy += 0.5 * np.sum(model.body_inertia * w_body * w_body)
    energy += 0.5 * np.sum(model.particle_mass * np.einsum("pi,pi->p", state.particle_velocity,
                                                            state.particle_velocity))
    return float(energy)


def potential_energy(model, state) -> float:
    """Gravitational potential −m g·x (zero at the origin) plus the elastic energy
    Σ ½ k (l − L)² of the cloth springs [J]."""
    return float(-np.sum(model.body_mass * (state.body_position @ model.gravity))
                 - np.sum(model.particle_mass * (state.particle_position @ model.gravity))
                 + spring_energy(model, state.particle_position))


def max_penetration(contacts) -> float:
    """Deepest overlap among contacts [m], 0 when none overlap."""
    return float(max(0.0, contacts.depth.max())) if contacts.count else 0.0


def linear_momentum(model, state):
    """Total linear momentum (3,) [kg m/s]."""
    return model.body_mass @ state.body_velocity + model.particle_mass @ state.particle_velocity


def angular_momentum(model, state, origin=(0.0, 0.0, 0.0)):
    """Total angular momentum about ``origin`` (3,) [kg m²/s]: spins plus orbital parts."""
    origin = np.asarray(origin, dtype=float)
    total = np.zeros(3)
    if model.body_count:
        inertia_world = rotations.world_inertia(rotations.to_matrix(state.body_orientation), model.body_inertia)
        total += np.einsum("bij,bj->i", inertia_world, state.body_angular_velocity)
        total += np.sum(np.cross(state.body_position - origin,
                                 model.body_mass[:, None] * state.body_velocity), axis=0)
    total += np.sum(np.cross(state.particle_position - origin,
                             model.particle_mass[:, None] * state.particle_velocity), axis=0)
    return total
