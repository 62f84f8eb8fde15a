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

from ..errors import InputError
from ..validation import check_choices, check_counts, number
from . import velocity_level
from .base import KeptManifoldOptions, StepInfo
from .velocity_level import SUBSTEP_WHEN

if TYPE_CHECKING:
    from ..model import Model
    from ..state import State


@dataclass
class Options(KeptManifoldOptions):
    """Settings of ``[method.impulse]`` (documented with units in docs/methods/impulse.md), after
    the collision settings of KeptManifoldOptions."""

    iterations: int = 100
    """sweeps of sequential impulses per step, and collision waves (at most)"""
    substeps: int = 16
    """a step left unconverged is solved again in this many substeps, contacts detected once (1 = never)"""
    substep_after: int = 12
    """with substeps > 1, the resting sweeps stop after this many (and iterations) and a step still above the
    tolerance goes on in substeps"""
    substep_sweeps: int = 1
    """sweeps per substep (at most)"""
    substep_when: str = "unconverged"
    """unconverged (a step the whole-step sweeps leave above the tolerance) | always"""
    tolerance: float = 1e-7
    """m/s: stop once a sweep changes no contact's velocity more"""
    restitution_threshold: float = -1.0
    """m/s: slower approaches bounce with ε = 0; < 0 means 2·|g|·dt"""
    stabilization: float = 0.2
    """fraction of an existing penetration removed per step (0 = none)"""
    slop: float = 0.0005
    """m of penetration left alone by the stabilization"""
    max_push_velocity: float = 1.0
    """m/s: the stabilization never pushes apart faster"""
    time_of_impact: bool = True
    """split the step at the impact (see module docs)"""
    warm_start: float = 1.0
    """fraction of last step's impulses to start from, and of a new contact's weight over the step
    (``velocity_level.guess_new_impulses``); 0 = cold"""

    def __post_init__(self):
        super().__post_init__()
        check_counts(self, {"iterations": 1, "substeps": 1, "substep_sweeps": 1, "substep_after": 1})
        check_choices(self, {"substep_when": SUBSTEP_WHEN})
        self.tolerance = number(self.tolerance, "tolerance", 0.0)
        self.restitution_threshold = number(self.restitution_threshold, "restitution_threshold")
        self.stabilization = number(self.stabilization, "stabilization", 0.0, maximum=1.0)
        self.slop = number(self.slop, "slop", 0.0)
        self.max_push_velocity = number(self.max_push_velocity, "max_push_velocity", 0.0)
        self.warm_start = number(self.warm_start, "warm_start", 0.0, maximum=1.0)
        if not isinstance(self.time_of_impact, bool):
            raise InputError("time_of_impact", f"expected true or false, found {self.time_of_impact!r}")


def step(
    model: Model, state: State, dt: float, options: Options, integrator: str = "symplectic_euler"
) -> tuple[State, StepInfo]:
    """One step of loop L3 with impulses; returns (new State, StepInfo): stages 1–3 from Python,
    4–5 the compiled stages the compiled loop runs (``velocity_level.step``)."""
    return velocity_level.step("impulse", model, state, dt, options, integrator)
