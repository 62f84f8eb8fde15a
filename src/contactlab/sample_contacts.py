"""One recorded sample of a trajectory as the viewer inspects it: its State, and the contacts
and contact forces at it, rebuilt from the run's Model (contacts are not stored in a trajectory).

The points, normals and depths come from :func:`contactlab.collision.collide` on the recorded
state; the forces from a step of the run's method from that state
(:attr:`contactlab.methods.StepInfo.impulses` over the step's dt), warm started by one step
before it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from .errors import InputError
from .record import SERIES, read_trajectory

if TYPE_CHECKING:
    from .model import Model
    from .state import State

# the trajectory's series that make a State: its time, then positions and velocities in State's field order
STATE_SERIES = SERIES[: SERIES.index("particle_velocity") + 1]


@dataclass
class ContactView:
    """What the viewer draws of one sample's contacts. points (C, 3) [m], normals (C, 3) unit
    (from B into A), depth (C,) [m] (> 0 overlapping), from collide() on the recorded state;
    force_points (K, 3) [m] and forces (K, 3) [N] from one step of the method: the force on side A,
    or on side B where A is static geometry (what a moving thing feels);
    body_depth (B,) [m] the deepest overlap of each body (0 when it touches nothing)."""

    points: np.ndarray
    normals: np.ndarray
    depth: np.ndarray
    force_points: np.ndarray
    forces: np.ndarray
    body_depth: np.ndarray


def state_at(arrays: Mapping[str, Any], sample: int) -> State:
    """The :class:`contactlab.state.State` recorded at trajectory sample ``sample``."""
    from .state import State

    return State.sampled(read_trajectory(arrays, STATE_SERIES, [sample]), 0)


def contacts_at(model: Model, summary: Mapping[str, Any], state: State) -> ContactView:
    """The :class:`ContactView` of ``state`` for ``model``; forces only when the summary names
    a method, its options and dt (else none)."""
    from . import methods
    from .collision import collide

    found = collide(model, state)
    depth = np.maximum(found.depth, 0.0)
    body_depth = np.zeros(model.body_count)
    for side in (found.body_a, found.body_b):
        touching = side >= 0
        np.maximum.at(body_depth, side[touching], depth[touching])
    force_points, forces = np.zeros((0, 3)), np.zeros((0, 3))
    if summary.get("method") in methods.AVAILABLE and "dt" in summary:
        module = methods.get(summary["method"])
        try:
            options = methods.make_options(module, summary.get("options") or {}, f"method.{summary['method']}")
        except InputError:
            options = module.Options()

        def step(start):
            return module.step(model, start, summary["dt"], options, summary.get("integrator", "symplectic_euler"))

        warm = step(state)[0].carried  # a first step finds what to warm start from, as the run had
        _, info = step(dataclasses.replace(state, carried=warm))
        if info.impulses is not None and info.contacts.count:
            c = info.contacts
            push = (
                info.impulses[:, :1] * c.normal
                + info.impulses[:, 1:2] * c.tangent1
                + info.impulses[:, 2:3] * c.tangent2
            ) / summary["dt"]
            static_a = (c.body_a < 0) & (c.particles_a[:, 0] < 0)  # the floor's side: show what B feels
            push[static_a] *= -1.0
            acting = np.linalg.norm(push, axis=1) > 0.0
            force_points, forces = c.point[acting], push[acting]
    return ContactView(found.point, found.normal, found.depth, force_points, forces, body_depth)
