"""What changes in time: positions, velocities, orientations, and what a method carries.

Shapes: B bodies, P particles. Angular velocity is in the world frame. ``carried`` (a Carry)
holds what a method keeps from one step to the next: the contact manifolds it may reuse, and each
contact's warm start or anchor by persistent contact id.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

if TYPE_CHECKING:
    from collections.abc import Mapping

    from .collision.manifolds import Manifolds

Positions = tuple[np.ndarray, np.ndarray, np.ndarray]
"""A state's positions as one value: (body_position (B, 3) [m], body_orientation (B, 4) unit
quaternions, particle_position (P, 3) [m]), the order of :attr:`State.positions`."""


class Carry(NamedTuple):
    """What a method keeps from one step to the next (none: :func:`Carry.none`)."""

    method: str
    """whose values these are ("impulse", "constraints", "projection", "penalty"; "" none): a
    method starts from another's values as from none"""
    manifolds: Manifolds | None
    """the contact manifolds pairs that barely move reuse (impulse, constraints, projection; None: none)"""
    ids: np.ndarray
    """(K,) int64: the persistent ids of last step's contacts"""
    values: np.ndarray
    """(K, 3): what each carries — impulses [N s] (impulse, constraints), first-pass λ [kg m]
    (projection), anchor offsets [m] (penalty)"""
    springs: np.ndarray | None = None
    """(P, 3) [m/s]: the cloth springs' backward Euler Δv of the step that made the state, where
    it solved them by conjugate gradients: the next step's solve starts from it (None: from the
    diagonal's guess). Any method's: the cloth's motion, not a contact's"""

    @classmethod
    def none(cls, method: str = "", manifolds: Manifolds | None = None) -> Carry:
        """No contact's values (``method``'s, beside these ``manifolds``)."""
        return cls(method, manifolds, np.zeros(0, dtype=np.int64), np.zeros((0, 3)))

    def of(self, method: str) -> tuple[np.ndarray, np.ndarray]:
        """(ids (K,), values (K, 3)) where they are ``method``'s, else both empty."""
        carry = self if self.method == method else Carry.none()
        return carry.ids, carry.values

    def copy(self) -> Carry:
        """The ids and values copied; the manifolds shared (a frozen Manifolds, never written)."""
        springs = None if self.springs is None else self.springs.copy()
        return self._replace(ids=self.ids.copy(), values=self.values.copy(), springs=springs)


@dataclass
class State:
    time: float
    """s"""
    body_position: np.ndarray
    """(B, 3) centre of mass, m"""
    body_orientation: np.ndarray
    """(B, 4) unit quaternion (w, x, y, z)"""
    body_velocity: np.ndarray
    """(B, 3) m/s"""
    body_angular_velocity: np.ndarray
    """(B, 3) rad/s, world frame"""
    particle_position: np.ndarray
    """(P, 3) m"""
    particle_velocity: np.ndarray
    """(P, 3) m/s"""
    carried: Carry = field(default_factory=Carry.none)
    """what a method keeps between steps"""

    def __repr__(self):
        bodies, particles = len(self.body_position), len(self.particle_position)
        return (
            f"State(t = {self.time:.6g} s, {bodies} bod{'y' if bodies == 1 else 'ies'}, "
            f"{particles} particle{'' if particles == 1 else 's'})"
        )

    @classmethod
    def assemble(
        cls,
        time: float,
        positions: tuple[np.ndarray, np.ndarray, np.ndarray],
        velocities: tuple[np.ndarray, np.ndarray, np.ndarray],
        carried: Carry | None = None,
    ) -> State:
        """A state from (body_position, body_orientation, particle_position) and
        (body_velocity, body_angular_velocity, particle_velocity)."""
        (bx, bq, px), (bv, bw, pv) = positions, velocities
        return cls(time, bx, bq, bv, bw, px, pv, Carry.none() if carried is None else carried)

    @classmethod
    def sampled(cls, samples: Mapping[str, np.ndarray], row: int) -> State:
        """The State of sample ``row`` of a run's ``samples`` (each series of SERIES by name,
        one row per sample: its time and six arrays), its arrays contiguous float copies;
        nothing carried."""
        bx, bq, bv, bw, px, pv = (np.array(samples[name][row], dtype=float) for name in ARRAYS)
        return cls(float(samples["time"][row]), bx, bq, bv, bw, px, pv)

    @property
    def positions(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(body_position, body_orientation, particle_position)."""
        return self.body_position, self.body_orientation, self.particle_position

    @property
    def velocities(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(body_velocity, body_angular_velocity, particle_velocity)."""
        return self.body_velocity, self.body_angular_velocity, self.particle_velocity

    def copy(self) -> State:
        return replace(
            self,
            body_position=self.body_position.copy(),
            body_orientation=self.body_orientation.copy(),
            body_velocity=self.body_velocity.copy(),
            body_angular_velocity=self.body_angular_velocity.copy(),
            particle_position=self.particle_position.copy(),
            particle_velocity=self.particle_velocity.copy(),
            carried=self.carried.copy(),
        )

    def max_speed(self) -> float:
        """The largest linear speed of a body centre or particle [m/s] (0 with none)."""
        return float(
            max(
                np.linalg.norm(self.body_velocity, axis=1).max(initial=0.0),
                np.linalg.norm(self.particle_velocity, axis=1).max(initial=0.0),
            )
        )

    def is_finite(self) -> bool:
        return all(
            np.isfinite(a).all()
            for a in (
                self.body_position,
                self.body_orientation,
                self.body_velocity,
                self.body_angular_velocity,
                self.particle_position,
                self.particle_velocity,
            )
        )


def array_shapes(body_count: int, particle_count: int) -> dict[str, tuple[int, int]]:
    """name -> shape of each of a State's six arrays, in field order, for B = ``body_count``
    bodies and P = ``particle_count`` particles: what a state is checked against and what a
    recorded sample of it holds."""
    B, P = body_count, particle_count
    return {
        "body_position": (B, 3),
        "body_orientation": (B, 4),
        "body_velocity": (B, 3),
        "body_angular_velocity": (B, 3),
        "particle_position": (P, 3),
        "particle_velocity": (P, 3),
    }


ARRAYS = tuple(array_shapes(0, 0))  # the six array fields' names, in order
