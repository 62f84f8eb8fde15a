"""What every method module builds on: the collision settings its Options start with
(:class:`CollisionOptions`, :class:`KeptManifoldOptions`) and the :class:`StepInfo` its ``step``
returns beside the new State. Re-exported by :mod:`contactlab.methods`, which finds the methods
by name; the method modules import them from here, below it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from ..collision import GRANULARITIES, NORMALS, DetectionSettings, collide_keeping
from ..contacts import Contacts
from ..validation import check_choices, check_counts, check_flags, number

if TYPE_CHECKING:
    from ..collision.manifolds import Manifolds
    from ..model import Model
    from ..state import State


@dataclass
class StepInfo:
    """What a step reports besides the new state."""

    contacts: Contacts
    """the contacts the response acted on"""
    solver_iterations: int = 0
    """sweeps the solver made (0 where there is none)"""
    solver_residual: float = 0.0
    """the solver's last change or residual (method-specific units, documented)"""
    linear_iterations: int = 0
    """conjugate-gradient iterations of the step's linear solves (penalty's implicit springs)"""
    energy_elastic: float = 0.0
    """energy stored in contact springs [J]"""
    implicit_springs: bool = False
    """penalty: contact springs stepped by backward Euler, the explicit step being unstable"""
    impulses: np.ndarray | None = None
    """(C, 3) [N s] each contact's push on side A over the step, along (normal, tangent1, tangent2) of ``contacts``;
    None: no contacts (the viewer's arrows)"""


@dataclass(frozen=True)
class CollisionOptions:
    """The collision-detection settings every method's Options starts with, declared and
    checked here once (see docs/collision.md); a method that wants another default declares
    the field again with it.

    Every method's Options are frozen: checked and normalized once, when built (``__post_init__``
    settles each value with ``_number`` or ``_settle``), and never changed after; another setting
    is another Options (``dataclasses.replace``)."""

    contact_margin: float = 0.002
    """m: gaps this small become (speculative) contacts"""
    granularity: str = "vertex"
    """boxes and hulls on static surfaces: object | vertex | samples (P2)"""
    normal: str = "object"
    """their contact normal: object (P4) | vertex (P5)"""
    samples: int = 2
    """samples per triangle edge for granularity = "samples" """
    cloth_samples: int = 0
    """samples per cloth triangle edge against obstacles (P2c); 0: vertices only"""
    cloth_faces: bool = True
    """a box's or sphere's edge or corner reaching a cloth triangle between its vertices makes a
    contact there (collision.cloth); False: the cloth meets obstacles at its vertices (and samples) only"""

    def __post_init__(self):
        self._number("contact_margin", 0.0)
        check_choices(self, {"granularity": GRANULARITIES, "normal": NORMALS})
        check_counts(self, {"samples": 1, "cloth_samples": 0})
        check_flags(self, ("cloth_faces",))

    def _settle(self, name: str, value: Any) -> None:
        """Field ``name`` set to its checked ``value`` while the Options are built (they are frozen)."""
        object.__setattr__(self, name, value)

    def _number(self, name: str, minimum: float | None = None, **bounds: Any) -> None:
        """Field ``name`` checked by ``validation.number`` (``minimum`` and its other bounds) and settled as a float."""
        self._settle(name, number(getattr(self, name), name, minimum, **bounds))

    def collide(
        self,
        model: Model,
        state: State,
        sweep: np.ndarray | None,
        manifolds: Manifolds | None = None,
        tolerance: float = 0.0,
        particle_motion: np.ndarray | None = None,
    ) -> tuple[Contacts, Manifolds | None]:
        """``collide_keeping`` with these settings: the contacts of ``state`` down to gaps of
        ``contact_margin`` [m], or each collider's ``sweep`` (B + P,) [m] where larger, and the
        manifolds to carry; pairs that moved less than ``tolerance`` [m] keep theirs from
        ``manifolds`` (last step's; None or 0: nothing kept, as ``collide``); particle_motion
        (P, 3) [m]: the particles' predicted displacements, for cloth self-contact (None: the sweep)."""
        settings = DetectionSettings(
            self.contact_margin, self.granularity, self.normal, self.samples, self.cloth_samples, self.cloth_faces
        )
        return collide_keeping(model, state, manifolds, tolerance, settings, sweep, particle_motion)


@dataclass(frozen=True)
class KeptManifoldOptions(CollisionOptions):
    """CollisionOptions and the tolerance under which a pair's contacts are reused from the last
    step (the methods that step positions once per step: impulse, constraints)."""

    manifold_tolerance: float = 1e-4
    """m: box, hull and plane pairs that moved less reuse last contacts (0 = never)"""

    def __post_init__(self):
        super().__post_init__()
        self._number("manifold_tolerance", 0.0)
