"""Contact-response methods, one module per method of the lecture, each a ``step``.

A method module provides:

* ``Options``: a dataclass of its settings (the ``[method.NAME]`` table of a scene file),
  every field with a default and a docstring line;
* ``step(model, state, dt, options, integrator) -> (State, StepInfo)``: one time step that
  follows the method's loop (L1, L2 or L3) in named stages;
* optionally ``divergence_advice(model, dt, options, integrator) -> str``: the likely fix, one
  clause, that ``contactlab.health`` gives when a run of this method goes wrong (penalty: the
  time step or stiffness an explicit step could follow).
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from types import ModuleType
from typing import TYPE_CHECKING

import numpy as np

from ..collision import GRANULARITIES, NORMALS, collide_keeping
from ..contacts import Contacts
from ..errors import InputError
from ..validation import check_choices, check_counts, number

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


AVAILABLE = ("penalty", "projection", "impulse", "constraints")


@dataclass
class CollisionOptions:
    """The collision-detection settings every method's Options starts with, declared and
    checked here once (see docs/collision.md); a method that wants another default declares
    the field again with it."""

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

    def __post_init__(self):
        self.contact_margin = number(self.contact_margin, "contact_margin", 0.0)
        check_choices(self, {"granularity": GRANULARITIES, "normal": NORMALS})
        check_counts(self, {"samples": 1, "cloth_samples": 0})

    def collide(
        self,
        model: Model,
        state: State,
        sweep: np.ndarray | None,
        manifolds: Manifolds | None = None,
        tolerance: float = 0.0,
    ) -> tuple[Contacts, Manifolds | None]:
        """``collide_keeping`` with these settings: the contacts of ``state`` down to gaps of
        ``contact_margin`` [m], or each collider's ``sweep`` (B + P,) [m] where larger, and the
        manifolds to carry; pairs that moved less than ``tolerance`` [m] keep theirs from
        ``manifolds`` (last step's; None or 0: nothing kept, as ``collide``)."""
        return collide_keeping(
            model,
            state,
            manifolds,
            tolerance,
            self.contact_margin,
            sweep,
            self.granularity,
            self.normal,
            self.samples,
            self.cloth_samples,
        )


@dataclass
class KeptManifoldOptions(CollisionOptions):
    """CollisionOptions and the tolerance under which a pair's contacts are reused from the last
    step (the methods that step positions once per step: impulse, constraints)."""

    manifold_tolerance: float = 1e-4
    """m: box, hull and plane pairs that moved less reuse last contacts (0 = never)"""

    def __post_init__(self):
        super().__post_init__()
        self.manifold_tolerance = number(self.manifold_tolerance, "manifold_tolerance", 0.0)


def get(name: str) -> ModuleType:
    """The method module called ``name``; InputError for an unknown or unavailable one."""
    if name == "impulse":
        from . import impulse

        return impulse
    if name == "penalty":
        from . import penalty

        return penalty
    if name == "projection":
        from . import projection

        return projection
    if name == "constraints":
        from . import constraints

        return constraints
    raise InputError("method", f"unknown method {name!r}; expected one of: {', '.join(AVAILABLE)}")


def make_options(module: ModuleType, table: dict[str, object], path: str) -> CollisionOptions:
    """Build ``module.Options`` from a scene-file table (dict); unknown keys are InputErrors."""
    import difflib

    known = {f.name: f for f in fields(module.Options)}
    values = {}
    for key, value in table.items():
        if key not in known:
            close = difflib.get_close_matches(key, known, n=1)
            hint = f"; did you mean {close[0]!r}?" if close else f"; known keys: {', '.join(known)}"
            raise InputError(f"{path}.{key}", f"unknown option{hint}")
        values[key] = value
    try:
        return module.Options(**values)
    except InputError as error:
        raise InputError(f"{path}.{error.field}", error.message) from None
