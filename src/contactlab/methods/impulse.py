"""Impulses (SPEC I1, I2, R1–R4, F2, M2) inside the constraint loop L3.

One step, stage by stage as on the slide:

1. internal forces: gravity → free velocities v*;
2. integrate positions with v* (a prediction), which says how far everything sweeps;
3. collision detection over the swept step: contacts at the start positions with gaps down
   to what the motion could close (speculative contacts), so nothing tunnels;
4. formulate the contacts as impulses and solve them, in two phases:
   a. collisions (I2, R1–R4, F2): the contacts approaching now get, together, the normal
      impulses J_n = −(1 + ε) v_n / (J M⁻¹ Jᵀ) (R4 is this effective mass written out for two
      rigid bodies) and friction impulses of at most μ J_n; then the contacts those impulses
      set approaching, and so on: an impact travels down a chain of touching bodies one link
      at a time (Newton's cradle), while simultaneous impacts stay simultaneous;
   b. resting contacts (M2): sequential impulses with the accumulated normal impulse clamped
      at λ ≥ 0 and friction clamped to μ λ, until no impulse changes a velocity by more than
      the tolerance — this is projected Gauss-Seidel on velocities, the matrix-free twin of
      the constraints method — swept from the highest contact down along gravity (see
      ``solve_order``) and warm-started from last step's impulses (a new contact from the
      weight it bears, ``guess_new_impulses``);
5. recompute velocities and positions: x = x₀ + h v⁺ — so a body at rest stays put — with the
   time-of-impact correction below; advance time.

Where each stage is written: 1–3 in ``velocity_level.step`` (from Python, every scene) and
``loop_steps.velocity_step`` (the compiled loop), 4–5 once, in ``velocity_level.respond``, which
both call — the collision waves of 4a are ``velocity_level.resolve_collisions``. This module holds
the method's Options and its ``step``.

Friction (F2) is not written here: both phases sweep contacts with
:func:`contactlab.methods.sequential.sweep_contacts`, whose per-contact update clamps the
tangential impulse to the friction cone μ λ (the same sweep serves ``constraints``).

Time of impact. A contact that was open at the start of the step (gap d₀ > 0) closes at the
fraction τ = d₀ / (−h v_n*) of it. The body travels with v* until then and with v⁺ after, so
its position is x₀ + h(τ v* + (1 − τ) v⁺) (orientation likewise). This is what makes bounce
heights follow h₀ ε²ⁿ instead of bouncing early, from wherever the step happened to end.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from . import velocity_level
from .base import StepInfo
from .velocity_level import VelocityOptions

if TYPE_CHECKING:
    from ..model import Model
    from ..state import State


@dataclass(frozen=True)
class Options(VelocityOptions):
    """Settings of ``[method.impulse]`` (documented with units in docs/methods/impulse.md): the
    collision settings, what impulse and constraints share (VelocityOptions), and the tolerance."""

    tolerance: float = 1e-7
    """m/s: stop once a sweep changes no contact's velocity more"""

    def __post_init__(self):
        super().__post_init__()
        self._number("tolerance", 0.0)


def step(
    model: Model, state: State, dt: float, options: Options, integrator: str = "symplectic_euler"
) -> tuple[State, StepInfo]:
    """One step of loop L3 with impulses; returns (new State, StepInfo): stages 1–3 from Python,
    4–5 the compiled stages the compiled loop runs (``velocity_level.step``)."""
    return velocity_level.step("impulse", model, state, dt, options, integrator)
