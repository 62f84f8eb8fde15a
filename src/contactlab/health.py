"""The health of a run: what ``simulate`` checks about its own physics as it goes.

A run that goes wrong numerically seldom fails by itself: a ball thrown 184 km up by a spring
too stiff for the step, boxes 24 m under the floor, a pile whose energy grew 7,300-fold all
end with finite numbers. So every run checks finite and speed after every step (the stepper
stops itself there), and the rest at every recorded sample, all of a chunk of steps (about
0.1 s) at once after it (``simulate``; the first sample that fails ends the trajectory), and the
state at the chunk's end:

- **finite**: every position, orientation and velocity is a finite number;
- **speed**: no body centre or particle moves faster than ``SPEED_FACTOR`` times the scene's
  speed scale — its fastest initial speed, or the fall speed √(2 g L) over the scene's size L,
  whichever is larger (at least 1 m/s);
- **energy**: the total energy (kinetic + gravitational + elastic) never exceeds its start by
  more than ``ENERGY_GAIN`` times the scene's energy scale, its initial kinetic energy plus
  Σ m g L (nothing outside the scene does work on it: gravity is in the potential). Not on
  scenes with cloth: the recorded total leaves out the cloth springs' own energy; nor on driven
  scenes (contactlab.driving): external forces and kinematic bodies do outside work;
- **depth**: no contact is deeper than ``DEPTH_FRACTION`` of its pass-through depth (the two
  sides' half thicknesses, ``collision.pass_through_depths``: deeper, one side has reached the
  other's middle), and no body or particle centre lies behind a static plane by more than its
  own half thickness (it went through the floor);
- **crossing**: no edge of a cloth whose ``self_collision`` is on passes through a triangle of
  its own or of another such cloth (``collision.cloth_self.crossings``), beyond those it
  started with: self-contact is there to keep cloth from ever passing through itself.

A violation stops the run with :class:`contactlab.errors.SimulationDiverged`: one sentence
naming the check, the time and the likely fix, with the run up to that point in its ``run``
attribute (its summary marked ``"diverged"``). ``allow_divergence=True`` (``--allow-divergence``)
keeps the physics checks to the summary's ``health`` list and goes on, for studies of
blow-ups; a non-finite state always stops the run, having nothing left to step.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from . import shapes
from .collision import collide, pass_through_depths
from .collision.cloth_self import cloth_elements, crossings
from .driving import too_fast
from .model import derived
from .state import State

if TYPE_CHECKING:
    from .contacts import Contacts
    from .model import Model


SPEED_FACTOR = 10.0  # × the scene's speed scale
ENERGY_GAIN = 0.5  # × the scene's energy scale
DEPTH_FRACTION = 0.75  # × a contact's pass-through depth
HARD_SPEED = 1e6  # m/s: beyond this (or non-finite) the state is unusable, whatever is allowed
ENERGY_SERIES = ("time", "energy_kinetic", "energy_potential", "energy_elastic")  # what check_samples reads


@dataclass
class Violation:
    """What a check found: ``check`` (finite | speed | energy | depth | crossing), at ``time`` [s], in one
    sentence ``what`` (no fix: see ``Health.message``)."""

    check: str
    time: float
    what: str


class Health:
    """The checks of one run of ``model`` from ``state`` at time step ``dt`` [s].

    ``advice``: one clause, the likely fix when the run goes wrong (the method's
    ``divergence_advice``, else a smaller dt); ``allow_divergence``: record physics
    violations instead of stopping on them (see the module docstring)."""

    def __init__(
        self, model: Model, state: State, dt: float, advice: str | None = None, allow_divergence: bool = False
    ) -> None:
        self.model = model
        self.dt = dt
        self.allow_divergence = allow_divergence
        self.advice = advice or f"use a smaller dt than {dt:g} s"
        self.violations: list[Violation] = []
        scales = _model_scales(model)
        g = scales.gravity
        size = max(_scene_size(scales, state), 0.1)
        speeds = np.linalg.norm(np.concatenate([state.body_velocity, state.particle_velocity]), axis=1)
        self.speed_limit = SPEED_FACTOR * float(max(1.0, speeds.max(initial=0.0), np.sqrt(2.0 * g * size)))
        self.initial_energy: float | None = None  # the first recorded sample's, once there is one
        self.energy_scale = _kinetic(model, state) + scales.mass * g * size
        self.plane_normals, self.plane_offsets = scales.plane_normals, scales.plane_offsets
        self.half_thickness = scales.half_thickness
        self.initial_depth_ratio = 0.0  # see start()
        self.thinnest = scales.thinnest
        self.self_colliding = scales.self_colliding
        # a cloth may start through itself (a mesh file so folded): only more crossings than that are flagged
        self.initial_crossings = len(crossings(model, state.particle_position)) if self.self_colliding else 0

    # ---- the checks --------------------------------------------------------------------------

    def check_state(self, state: State) -> Violation | None:
        """Finite and speed, on a State; stops the run (returns the Violation) or records it."""
        speed = state.max_speed()
        if not (speed <= HARD_SPEED and state.is_finite()):
            return self._found(
                Violation("finite", state.time, f"the state stopped being finite (or passed {HARD_SPEED:g} m/s)"),
                always=True,
            )
        if speed > self.speed_limit:
            return self._found(
                Violation(
                    "speed",
                    state.time,
                    f"a body or particle reached {speed:.3g} m/s, "
                    f"{SPEED_FACTOR:g}× the scene's speed scale "
                    f"({self.speed_limit / SPEED_FACTOR:.3g} m/s)",
                )
            )
        return None

    def check_samples(self, arrays: Mapping[str, np.ndarray], first: int = 0) -> Violation | None:
        """Energy, speed and finite on recorded samples ``arrays`` (the trajectory's series,
        rows from ``first`` on). Returns the first Violation that stops the run, or None."""
        energy = arrays["energy_kinetic"] + arrays["energy_potential"] + arrays["energy_elastic"]
        if self.model.spring_count or self.model.drive is not None:
            # the total leaves the cloth's springs out, or outside work goes in: finite only
            energy = np.where(np.isfinite(energy), 0.0, energy)
        if self.initial_energy is None:
            if not len(energy):
                return None  # no sample yet: nothing to check, nothing to start from
            self.initial_energy = float(energy[0])
        initial = self.initial_energy
        energy = energy[first:]
        if not len(energy) or (
            (energy - initial).max() <= ENERGY_GAIN * self.energy_scale + 1e-9 and energy.min() > -np.inf
        ):
            return None  # every row finite and within the gain: the usual case, in three reductions
        # the first row that is not finite and the first that gained too much, found at once (a
        # Python loop over rows cost a 720-step ball's run about a fifth of its time)
        unfinite = _first(~np.isfinite(energy))
        gained = _first(energy - initial > ENERGY_GAIN * self.energy_scale + 1e-9)  # NaN: False
        if gained is not None and (unfinite is None or gained < unfinite):
            gain = float(energy[gained]) - initial
            found = self._found(
                Violation(
                    "energy",
                    float(arrays["time"][first + gained]),
                    f"the total energy rose {gain:.3g} J above its start ({initial:.4g} "
                    f"J), more than {ENERGY_GAIN:g}× the scene's energy scale "
                    f"({self.energy_scale:.3g} J) and with no outside work to explain it",
                )
            )
            if found:
                return found
        if unfinite is not None:
            time = float(arrays["time"][first + unfinite])
            return self._found(Violation("finite", time, "the energy stopped being finite"), always=True)
        return None

    def start(self, state: State, deepest: float | None = None) -> None:
        """Note how deep the run starts (a scene may begin overlapping, or with a pinned vertex
        inside an obstacle): the depth check then trips only past that. ``deepest`` [m]: the
        deepest overlap at ``state`` where it was measured already (its recorded sample), 0
        sparing the collision pass."""
        if deepest == 0.0:
            self.initial_depth_ratio = 0.0
            return
        ratio, _ = self._depth_ratios(collide(self.model, state))
        self.initial_depth_ratio = float(ratio.max(initial=0.0))

    def _depth_ratios(self, contacts):
        """(each contact's depth over DEPTH_FRACTION of its pass-through depth (C,), 0 where
        neither side can move (static, kinematic bodies or pinned cloth vertices); the
        pass-through depths (C,) [m])."""
        if contacts.count == 0:
            return np.zeros(0), np.zeros(0)
        through = pass_through_depths(self.model, contacts)
        free = np.r_[~np.asarray(self.model.particle_pinned, dtype=bool), False]  # index −1: no particle
        moves = np.r_[~self.model.body_kinematic, False]  # index −1: no body
        movable = moves[contacts.body_a] | moves[contacts.body_b]
        for side in (contacts.particles_a, contacts.particles_b):
            movable |= free[side].any(axis=1)
        return np.where(movable, contacts.depth / (DEPTH_FRACTION * through), 0.0), through

    def check_contacts(self, state: State, contacts: Contacts) -> Violation | None:
        """Depth and crossing, on a State and the contacts of its own positions (a collision pass)."""
        if contacts.count:
            ratio, through = self._depth_ratios(contacts)
            worst = int(np.argmax(ratio))
            if ratio[worst] > max(1.0, 1.1 * self.initial_depth_ratio):
                return self._found(
                    Violation(
                        "depth",
                        state.time,
                        f"a contact is {contacts.depth[worst] * 1000:.3g} mm "
                        f"deep, past {DEPTH_FRACTION:g} of the depth at which "
                        f"one side reaches the other's middle "
                        f"({through[worst] * 1000:.3g} mm)",
                    )
                )
        return self._behind_planes(state) or self._crossing(state)

    def _crossing(self, state):
        """The crossing check (see the module): an edge of a self-colliding cloth through a triangle."""
        if not self.self_colliding:
            return None
        found = len(crossings(self.model, state.particle_position))
        if found <= self.initial_crossings:
            return None
        return self._found(
            Violation(
                "crossing",
                state.time,
                f"{found - self.initial_crossings} edge{'s' if found - self.initial_crossings > 1 else ''} "
                "of a cloth passed through its triangles, though the cloth collides with itself",
            )
        )

    def check_sampled_depths(self, samples: Mapping[str, np.ndarray]) -> Violation | None:
        """``check_depth`` at every sample of ``samples`` (the series by name, one row per sample),
        in order: the first Violation that stops the run, or None. Only the rows that may fail
        are looked at one by one (a collision pass where the deepest overlap is past the quick
        bound, the crossings of a self-colliding cloth): whether a centre lies behind a plane
        is decided for all rows at once."""
        if not len(samples["time"]) or self._all_recorded():
            return None
        deep = samples["max_penetration"] > self._quick_bound()  # NaN: not deep (the finite check's)
        rows = np.ones(len(deep), dtype=bool) if self.self_colliding else deep | self._rows_behind_planes(samples)
        for row in np.flatnonzero(rows):
            violation = self.check_depth(State.sampled(samples, int(row)), float(samples["max_penetration"][row]))
            if violation is not None:
                return violation
        return None

    def _all_recorded(self):
        """Whether divergence is allowed and the depth and crossing checks have each recorded theirs."""
        checks = {"depth", "crossing"} if self.self_colliding else {"depth"}
        return self.allow_divergence and checks <= {v.check for v in self.violations}

    def _quick_bound(self):
        """[m] the deepest overlap no contact can pass the depth check within (``check_depth``)."""
        return DEPTH_FRACTION * self.thinnest * max(1.0, 1.1 * self.initial_depth_ratio)

    def _rows_behind_planes(self, samples):
        """(n,) bool: the samples with a body or particle centre behind a static plane by more
        than its half thickness (``_behind_planes``, every row at once)."""
        if not len(self.plane_offsets) or not len(self.half_thickness):
            return np.zeros(len(samples["time"]), dtype=bool)
        return (self._behind(samples["body_position"], samples["particle_position"]) > 1e-9).any(axis=(1, 2))

    def _behind(self, bodies, particles):
        """How far each body and particle centre lies behind each static plane, past its half
        thickness [m]: (..., B + P, O), of the centres (..., B, 3) and (..., P, 3) of one state
        or of n samples."""
        centres = np.concatenate([bodies, particles], axis=-2) if particles.shape[-2] else bodies
        return self.plane_offsets - centres @ self.plane_normals.T - self.half_thickness[:, None]

    def check_depth(self, state: State, deepest: float | None) -> Violation | None:
        """``check_contacts`` on the contacts of ``state``'s own positions, where ``deepest`` [m],
        the deepest overlap there, may be known already (its recorded sample's; None: not known).
        No contact can pass the depth check while ``deepest`` stays within DEPTH_FRACTION of the
        thinnest dynamic collider's half thickness (a lower bound of every pass-through depth),
        so the collision pass is made only past that, or where ``deepest`` is not known."""
        if deepest is not None and deepest <= self._quick_bound():
            return self._behind_planes(state) or self._crossing(state)
        return self.check_contacts(state, collide(self.model, state))

    def _behind_planes(self, state):
        if not len(self.plane_offsets) or not len(self.half_thickness):
            return None
        behind = self._behind(np.asarray(state.body_position), np.reshape(state.particle_position, (-1, 3)))
        worst = np.unravel_index(np.argmax(behind), behind.shape)  # a NaN first: it is not > 1e-9, nothing said
        if behind[worst] > 1e-9:
            return self._found(
                Violation(
                    "depth",
                    state.time,
                    f"a body or particle centre is "
                    f"{behind[worst] + self.half_thickness[worst[0]]:.3g} m "
                    f"behind a static plane: it went through",
                )
            )
        return None

    # ---- what is done with a violation ---------------------------------------------------------

    def _found(self, violation, always=False):
        """The violation that stops the run, or None where divergence is allowed (kept in
        ``violations`` once per check)."""
        if always or not self.allow_divergence:
            return violation
        if all(v.check != violation.check for v in self.violations):
            self.violations.append(violation)
        return None

    def message(self, violation: Violation) -> str:
        """The one sentence a stopped run reports: what went wrong, then the likely fix — a
        driving input that alone is too fast for the scene (:func:`contactlab.driving.too_fast`),
        else the method's advice."""
        culprit = too_fast(self.model, violation.time, self.dt, min(self.speed_limit, HARD_SPEED))
        return f"the run went wrong at t = {violation.time:.4g} s: {violation.what}; {culprit or self.advice}"

    def summary(self) -> dict[str, Any]:
        """The summary's ``health`` entry: the checks' limits and what was let pass."""
        return {
            "speed_limit": self.speed_limit,
            "energy_scale": self.energy_scale,
            "energy_gain": ENERGY_GAIN,
            "depth_fraction": DEPTH_FRACTION,
            "allow_divergence": self.allow_divergence,
            "violations": [{"check": v.check, "time": v.time, "what": v.what} for v in self.violations],
        }


class _Scales(NamedTuple):
    """What the checks take from a Model alone, built once a model (a study runs one many times)."""

    gravity: float
    """|g| [m/s²]"""
    mass: float
    """the bodies' and particles' total [kg]"""
    plane_normals: np.ndarray
    """(Pl, 3) the static planes' unit normals"""
    plane_offsets: np.ndarray
    """(Pl,) [m] their offsets along them"""
    half_thickness: np.ndarray
    """(B + P,) [m] each body's and particle's, inf where pinned or kinematic (never checked)"""
    thinnest: float
    """[m] the least half thickness of a dynamic collider: the least pass-through depth"""
    self_colliding: bool
    """a cloth collides with itself (the crossing check)"""
    planes: tuple
    """the static planes as ``_scene_size`` reads them: (normal (3,), offset [m], |normal|) each"""
    solids: np.ndarray
    """(S, 3) [m] the centres of the obstacles that are not planes"""


@derived
def _model_scales(model: Model) -> _Scales:
    """The _Scales of ``model``, kept with it (``model.derived``)."""
    kinds = model.collider_table[0]
    dynamic = model.body_count + model.particle_count
    params = model.collider_table[1][dynamic:][kinds[dynamic:] == shapes.PLANE]
    length = np.linalg.norm(params[:, :3], axis=1)
    return _Scales(
        gravity=float(np.linalg.norm(model.gravity)),
        mass=float(np.sum(model.body_mass) + np.sum(model.particle_mass)),
        plane_normals=params[:, :3] / length[:, None] if len(params) else np.zeros((0, 3)),
        plane_offsets=params[:, 3] / length if len(params) else np.zeros(0),
        half_thickness=(
            model.collider_half_thickness[:dynamic]
            + np.r_[np.where(model.body_kinematic, np.inf, 0.0), np.where(model.particle_pinned, np.inf, 0.0)]
        ),
        thinnest=float(model.collider_half_thickness[:dynamic].min(initial=np.inf)),
        self_colliding=not cloth_elements(model).empty,
        planes=tuple((normal, offset, np.linalg.norm(normal)) for normal, offset in zip(params[:, :3], params[:, 3])),
        solids=np.asarray(model.obstacle_position)[kinds[dynamic:] != shapes.PLANE],
    )


def _scene_size(scales, state):
    """L [m]: the largest extent of the dynamic centres and the finite obstacles together, or
    the greatest height of a dynamic centre above a static plane, whichever is larger."""
    centres = np.concatenate([state.body_position, state.particle_position])
    points = np.concatenate([centres, scales.solids]) if len(scales.solids) else centres
    size = float(np.ptp(points, axis=0).max()) if len(points) > 1 else 0.0
    if len(centres):
        for normal, offset, length in scales.planes:
            size = max(size, float((centres @ normal - offset).max() / length))
    return size


def _kinetic(model, state):
    from .diagnostics import kinetic_energy

    return float(kinetic_energy(model, state))


def _first(flags: np.ndarray) -> int | None:
    """The index of the first True of ``flags`` (n,) bool, or None when there is none."""
    index = int(np.argmax(flags)) if len(flags) else 0
    return index if len(flags) and flags[index] else None
