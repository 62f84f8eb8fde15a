"""The compiled stepping loop: impulse and constraints (L3), projection (L2) and penalty (L1).

``simulate`` hands this loop the model's and the state's arrays and a number of steps; every
stage of every step — free motion, prediction, broad and narrow phase with kept manifolds,
contact rows, the collision waves or the impact targets, the warm-started sweeps, the split
at the time of impact; for projection the sweeps on displacements and the further
detect-and-project passes at the projected positions — and the recording of samples run in
compiled code, with no Python between steps. The stages are the ones
:mod:`contactlab.methods.impulse`, :mod:`contactlab.methods.constraints` and
:mod:`contactlab.methods.projection` name, and the same compiled functions serve both paths, so
the loop gives what their ``step`` gives (``tests/test_velocity_loop.py`` holds them equal).
A method's step is compiled only for the runs of that method (its ``Specialization``).

**Every run compiled, short ones included.** ``run_steps`` is compiled three times
(``LOOPS``), each with its method's step inlined (``velocity_step``, ``projection_step`` or
``penalty_step``): the step's code is compiled once, inside the loop, never on its own. So every run
the loop serves runs compiled from its first step, its next run in a fresh process loads it from
the cache, and no step's arrays cross a call between the loop and the step (calling the step by
address, as the loop did before, cost about 0.6 µs a step in references counted at the
crossing: a fifth of a one-ball step).

This module holds ``run_steps`` and the Python side (the model and settings in the loop's form, the Steppers,
``stepper_for``); the stages every step shares and the loop's data are in
:mod:`contactlab.methods.loop_stages`, each method's compiled step in
:mod:`contactlab.methods.loop_steps`.

Penalty (``penalty_step``, loop L1; the Specialization's ``penalty``) runs in the same loop:
detection at the step's start with the gaps its motion could close, the contact springs (the
stiffness of each contact from the load it carries, anchors carried by contact id), their
forces, the free velocities, the springs integrated explicitly (h M⁻¹ Jᵀ F through the rows)
or by backward Euler (matrix-free conjugate gradients on the rows), the guard that holds a
contact short of passing through, and the anchors moved on — the compiled stages of
:mod:`contactlab.methods.penalty_springs` and :mod:`contactlab.methods.penalty_implicit`, which
:mod:`contactlab.methods.penalty`'s ``step`` calls one by one.

It serves the scenes it can (``applies``): rigid bodies and free particles of the primitive and
convex shapes against planes and convex obstacles, the default contact granularity and normal
(vertex, object), symplectic or backward Euler (the same motion without cloth), for
constraints the matrix-free solver on velocities and for penalty the "cg" linear solver, driven
or not (external forces and kinematic paths given as constants or keyframes, contactlab.driving:
the loop and the methods' steps evaluate them with the same compiled ``drive_velocities``). A
scene with cloth or meshes, another granularity, explicit Euler, or an assembled solver steps
through the methods' ``step``, and so does a scene with a force or a path given as a Python
function, which compiled code cannot call. That path is a Stepping too (``StitchedStepper``):
``simulate`` advances, records and checks every run alike, in chunks, whichever steps it.

Arrays, as in the rest of contactlab: B bodies, P particles, O obstacles, N = B + P + O
colliders, C contacts; the generalized velocity u (6B + 3P,) in the DOF layout of
contactlab.contacts.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from types import FunctionType
from typing import TYPE_CHECKING, Any

import numpy as np

from .. import diagnostics, interrupts, shapes
from ..collision import collide
from ..collision.cloth_self import is_self_contact
from ..collision.manifolds import Manifolds
from ..compiling import inlined, njit
from ..driving import DriveTable, table_of
from ..state import Carry, State
from .base import CollisionOptions
from .loop_stages import (
    LoopModel,
    LoopSettings,
    Motion,
    Samples,
    Specialization,
    healthy,
    loop_model,
    loop_settings,
    poses,
    record,
    specialization,
    store,
)
from .loop_steps import penalty_step, projection_step, velocity_step
from .penalty import penalty_loop

if TYPE_CHECKING:
    from ..model import Model
    from .penalty import Options as PenaltyOptions

METHODS = ("projection", "impulse", "constraints", "penalty")  # the methods the loop steps
Rows = Callable[[int], Mapping[str, np.ndarray]]  # a count of samples -> arrays to record them into


def applies(model: Model, method: str, options: CollisionOptions, integrator: str) -> bool:
    """Whether this loop can step ``model`` under ``method`` ("projection", "impulse" or
    "constraints") with these Options and integrator (see the module docstring for what it serves)."""
    if method not in METHODS or integrator not in ("symplectic_euler", "backward_euler"):
        return False
    if model.spring_count or len(model.triangles) or (model.obstacle_shape == shapes.MESH).any():
        return False
    if model.drive is not None and model.drive.has_functions:  # Python functions: only the methods' step calls them
        return False
    if options.granularity != "vertex" or options.normal != "object":
        return False
    if method == "penalty":
        return options.linear_solver == "cg"
    return method != "constraints" or (options.solver == "matrix_free" and options.formulation == "velocity")


def run_steps(
    model: LoopModel,
    drive: DriveTable | None,
    settings: LoopSettings,
    spec: Specialization,
    start: tuple,
    schedule: tuple,
    samples: Samples,
) -> tuple:
    """``schedule`` = (steps, first index, last index, record every, max speed [m/s]): that many
    steps of ``model`` driven by ``drive`` (``driving.table_of``) by the run's ``step``
    (``velocity_step``, ``projection_step`` or ``penalty_step``, compiled for ``spec`` and
    inlined: ``LOOPS``), from ``start`` = (the state's arrays, a Motion changed in
    place; what the step carries; the time [s]), numbered from the first index; after step i, a
    sample into ``samples`` (row after row) where i is a multiple of record every or the last
    index. Stops early after a step that leaves a non-finite value or a speed above max speed.
    Returns (steps made, whether it stopped so, carried, time, samples written, most contacts,
    sweeps made, steps whose contact springs went implicit, penalty's conjugate-gradient
    iterations made)."""
    motion, carried, time = start
    steps, first_index, last_index, record_every, max_speed = schedule
    written = np.int64(0)  # int64, not the literal 0: record is compiled once for run and for LoopStepper.sample
    most = 0
    sweeps_made = 0
    implicit_steps = 0
    linear_made = 0
    # the poses at each step's start, computed once after the step before: its sample takes them too
    pose = poses(model, motion)
    for s in range(steps):
        index = first_index + s
        # every step has one signature and one result (loop_steps): no branch on the method here
        positions, velocities, carried, count, sweeps, change, clear, elastic, implicit, linear = method_step(
            model, drive, settings, spec, motion, pose, time, carried
        )
        store(motion, positions, velocities)
        pose = poses(model, motion)
        time += settings.dt
        most = max(most, count)
        sweeps_made += sweeps
        implicit_steps += implicit
        linear_made += linear
        if not healthy(motion, max_speed):
            return s + 1, True, carried, time, written, most, sweeps_made, implicit_steps, linear_made
        if index % record_every == 0 or index == last_index:
            record(samples, written, model, spec.plan, motion, pose, time, (count, sweeps, change, clear))
            samples.energy_elastic[written] = elastic
            written += 1
    return steps, False, carried, time, written, most, sweeps_made, implicit_steps, linear_made


def method_step(*arguments: Any) -> tuple:
    """Where ``run_steps`` takes its method's step: each of its compiled forms (``LOOPS``) puts
    that step's code here, inlined."""
    raise NotImplementedError("run_steps runs compiled, as one of LOOPS")


def _loop_with(step: Any, name: str) -> Any:
    """``run_steps`` compiled with ``step`` (a step of loop_steps) inlined as its ``method_step``:
    its code once, the step's too, and no call between them (each step's arrays would cross it,
    their references counted)."""
    template = run_steps
    names = dict(template.__globals__, method_step=inlined(step))
    loop = FunctionType(template.__code__, names, name, template.__defaults__)
    loop.__qualname__, loop.__doc__ = name, template.__doc__  # its own cache entries
    return njit(cache=True)(loop)


LOOPS = {
    "velocity": _loop_with(velocity_step, "run_velocity_steps"),
    "projection": _loop_with(projection_step, "run_projection_steps"),
    "penalty": _loop_with(penalty_step, "run_penalty_steps"),
}


# ---- from Python: the model, the settings and the state in the loop's form, and back --------


class Stepping:
    """What ``simulate`` advances a run with, whichever path steps it (``stepper_for``): the
    compiled loop (LoopStepper, PenaltyStepper) or the method's own ``step`` (StitchedStepper).

    ``advance(steps, first_index, last_index, record_every, max_speed, rows)`` makes that many steps
    from the state reached and returns the samples it recorded; ``sample(rows)`` records the state
    as it stands; ``state()`` is the State reached, carrying what the method's ``step`` carries (so a
    run may go on through either path), ``reached()`` the same for a look; the tallies
    (``max_contacts``, ``sweeps_made``, ``implicit_spring_steps``, ``linear_iterations_made``,
    ``self_contacts``, ``recording_seconds``) sum what the steps made. A subclass writes the steps
    (``_steps``) and one sample of the state as it stands (``_sample_now``)."""

    model: Model
    compiled = True
    """whether the run steps through the compiled loop (summary ``compiled_loop``)"""
    recording_seconds = 0.0
    """[s] of recording apart from the stepping (the loop's samples are written within its steps)"""

    def sample(self, rows: Rows | None = None) -> dict[str, np.ndarray]:
        """The sample of the state as it stands (no step made: its contacts those of a fresh
        collision pass, 0 sweeps), as a dict of the series: what ``Recorder.sample`` records.
        ``rows``: where it is recorded (see ``advance``)."""
        samples = self._samples(1, rows)
        self._sample_now(samples)
        return samples._asdict()

    def advance(
        self,
        steps: int,
        first_index: int,
        last_index: int,
        record_every: int,
        max_speed: float,
        rows: Rows | None = None,
    ) -> tuple[int, bool, dict[str, np.ndarray]]:
        """Make ``steps`` steps numbered from ``first_index``, each sampled where its index is a
        multiple of ``record_every`` or the run's ``last_index``; stop after a step that leaves a
        non-finite value or a speed above ``max_speed`` [m/s]. Returns (steps made, whether it
        stopped so, the samples recorded as a dict of the series). ``rows``: a function of a
        count of samples giving the arrays to record them into (the Recorder's ``reserve``: its
        buffer's rows, no copy made); None: arrays of their own."""
        count = samples_in(steps, first_index, last_index, record_every)
        samples = self._samples(count, rows)
        made, diverged, written = self._steps(samples, (steps, first_index, last_index, record_every, max_speed))
        series = samples._asdict()
        if written < count:  # stopped early: the rows written only
            series = {name: array[:written] for name, array in series.items()}
        return made, diverged, series

    def _samples(self, count: int, rows: Rows | None) -> Samples:
        """Samples for ``count`` samples: the arrays ``rows(count)`` gives (name -> (count, ...),
        in the order of SERIES: the Recorder's ``reserve``, recorded into in place), or empty
        ones of their own where ``rows`` is None."""
        return empty_samples(self.model, count) if rows is None else Samples(**rows(count))

    def _steps(self, samples: Samples, schedule: tuple) -> tuple[int, bool, int]:
        """``advance``'s steps, ``schedule`` = (steps, first index, last index, record every, max
        speed), recorded into ``samples``: (steps made, whether stopped for the state, samples written)."""
        raise NotImplementedError

    def _sample_now(self, samples: Samples) -> None:
        """The state as it stands into the first row of ``samples``."""
        raise NotImplementedError

    def state(self) -> State:
        """The State reached, to keep: it carries what the method's ``step`` carries."""
        raise NotImplementedError

    def reached(self) -> State:
        """The State reached, for a look: its arrays those the next ``advance`` starts from."""
        raise NotImplementedError


class LoopStepper(Stepping):
    """Steps one run of ``method`` on ``model`` through the compiled loop (``run_steps``)."""

    def __init__(
        self, model: Model, method: str, options: CollisionOptions, integrator: str, dt: float, state: State
    ) -> None:
        self._start(model, method, state, state.carried.manifolds or Manifolds.empty())
        self.keep_manifolds = options.manifold_tolerance > 0.0
        self.settings = loop_settings(model, method, options, dt)
        self.spec = specialization(model, method, options)

    def _start(self, model, method, state, kept):
        """What every LoopStepper holds: the model, the method, the state's time, arrays (copies) and
        carried values beside the ``kept`` manifolds, the tallies."""
        self.model, self.method = model, method
        self.carried = _carried(kept, *state.carried.of(method))
        self.time = float(state.time)
        self.motion = Motion(
            *(
                np.array(a, dtype=float)
                for a in (
                    state.body_position,
                    state.body_orientation,
                    state.body_velocity,
                    state.body_angular_velocity,
                    state.particle_position,
                    state.particle_velocity,
                )
            )
        )
        self.max_contacts = 0
        self.sweeps_made = 0
        self.last_contacts = 0
        self.implicit_spring_steps = 0
        self.linear_iterations_made = 0
        self.self_contacts = 0  # cloth self-contacts: none on the scenes the loop serves

    def _sample_now(self, samples: Samples) -> None:
        model, motion = loop_model(self.model), self.motion  # the loop's own ``record``
        record(samples, 0, model, self.spec.plan, motion, poses(model, motion), self.time, (-1, 0, 0.0, False))

    def _steps(self, samples: Samples, schedule: tuple) -> tuple[int, bool, int]:
        steps, first_index, last_index, record_every, max_speed = schedule
        arguments = self._run_arguments(steps, first_index, last_index, record_every, samples, max_speed)
        made, diverged, self.carried, self.time, written, most, sweeps, implicit, linear = self.loop(*arguments)
        self.max_contacts = max(self.max_contacts, most)
        self.sweeps_made += sweeps
        self.implicit_spring_steps += implicit
        self.linear_iterations_made += linear
        return made, diverged, written

    def _run_arguments(self, steps, first_index, last_index, record_every, samples, max_speed):
        start = (self.motion, self.carried, self.time)
        schedule = (steps, first_index, last_index, record_every, max_speed)
        return loop_model(self.model), table_of(self.model.drive), self.settings, self.spec, start, schedule, samples

    @property
    def loop(self) -> Any:
        """This run's compiled loop (one of ``LOOPS``): its method's step inlined."""
        if self.spec.penalty is not None:
            return LOOPS["penalty"]
        return LOOPS["projection" if self.spec.projection is not None else "velocity"]

    @property
    def parallel(self) -> bool:
        """Whether this run's loop has a parallel sweep compiled in (the Specialization's ``parallel``)."""
        return self.spec.parallel is not None

    def state(self) -> State:
        """The State reached (copies), carrying the method's values and, where it keeps them, its manifolds."""
        made, ids, values = self.carried
        carried = Carry(self.method, Manifolds(*made) if self.keep_manifolds else None, ids, values)
        return State(self.time, *(array.copy() for array in self.motion), carried)

    def reached(self) -> State:
        """The State reached as the loop holds it, for a look (the health checks): its arrays
        the loop's own, which the next ``advance`` changes, and nothing carried; ``state()``
        for one to keep."""
        return State(self.time, *self.motion)


class PenaltyStepper(LoopStepper):
    """A LoopStepper of a penalty run (``penalty_step``): its anchors carried as ``penalty.step`` carries
    them, no manifolds kept."""

    def __init__(self, model: Model, options: PenaltyOptions, integrator: str, dt: float, state: State) -> None:
        self._start(model, "penalty", state, Manifolds.empty())  # penalty keeps no manifold
        self.keep_manifolds = False
        self.settings, penalty = penalty_loop(model, options, integrator, dt)  # settings: hold_back's sweeps
        self.spec = specialization(model, "penalty", options, penalty)


def _carried(kept: Manifolds, ids: np.ndarray, values: np.ndarray) -> tuple:
    """What ``run_steps`` carries from step to step, from a State's Carry: the ``kept`` manifolds'
    eight fields, last step's contact ids (K,) and their values (K, 3) (impulses, projection λ or
    penalty anchor offsets), as the compiled steps' types (int64, float64 (K, 3))."""
    return (
        (kept.keys, kept.reach, kept.center, kept.rotation, kept.count, kept.witness, kept.normal, kept.feature),
        np.asarray(ids, dtype=np.int64),
        np.asarray(values, dtype=float).reshape(-1, 3),
    )


class StitchedStepper(Stepping):
    """Steps one run of ``method`` on ``model`` through the method's own ``step``, called from
    Python once a step — the stages stitched together in Python, each the compiled code the loop
    runs where the loop has it — for the scenes the loop does not serve (``applies``: cloth,
    meshes, another granularity or normal, explicit Euler, an assembled solver, a force or path
    given as a Python function) and for any run with ``compiled_loop=False``.

    A sample's contacts are those of a collision pass at the sampled state's own positions
    (``collision.collide``), as the loop's ``record`` makes them; ``self_contacts`` is the most
    cloth self-contacts among them. A chunk also ends after the step in which a signal came
    (``interrupts.pending``): Ctrl-C is answered within a step, as the loop's chunk of about
    0.1 s is."""

    compiled = False
    parallel = True  # its kernels (cloth springs and self-contact, the CG solve) may take threads

    def __init__(
        self, model: Model, method: str, options: CollisionOptions, integrator: str, dt: float, state: State
    ) -> None:
        from . import get

        self.model, self.method, self.options, self.integrator, self.dt = model, method, options, integrator, dt
        self.step = get(method).step
        self.current = state
        self.max_contacts = self.sweeps_made = self.implicit_spring_steps = self.linear_iterations_made = 0
        self.self_contacts = 0
        self.recording_seconds = 0.0  # [s] of the samples' collision passes and copies, apart from the steps

    def _sample_now(self, samples: Samples) -> None:
        self._record(samples, 0, self.current, None)

    def _steps(self, samples: Samples, schedule: tuple) -> tuple[int, bool, int]:
        steps, first_index, last_index, record_every, max_speed = schedule
        written = 0
        for index in range(first_index, first_index + steps):
            state, info = self.step(self.model, self.current, self.dt, self.options, self.integrator)
            self.current = state
            self.max_contacts = max(self.max_contacts, info.contacts.count)
            self.sweeps_made += info.solver_iterations
            self.implicit_spring_steps += info.implicit_springs
            self.linear_iterations_made += info.linear_iterations
            if not (state.max_speed() <= max_speed and state.is_finite()):
                return index - first_index + 1, True, written
            if index % record_every == 0 or index == last_index:
                self._record(samples, written, state, info)
                written += 1
            if interrupts.pending():  # a signal: the chunk ends here, and simulate's check raises
                return index - first_index + 1, False, written
        return steps, False, written

    def _record(self, samples: Samples, row: int, state: State, info: Any) -> None:
        started = time.perf_counter()
        contacts = collide(self.model, state)
        self.self_contacts = max(self.self_contacts, int(is_self_contact(contacts).sum()))
        for name, value in diagnostics.sample_of(self.model, state, contacts, info).items():
            getattr(samples, name)[row] = value
        self.recording_seconds += time.perf_counter() - started

    def state(self) -> State:
        """The State reached, carrying what the method's ``step`` carries."""
        return self.current

    def reached(self) -> State:
        """The State reached (``state``): the health checks' look."""
        return self.current


def samples_in(steps: int, first_index: int, last_index: int, record_every: int) -> int:
    """How many samples ``steps`` steps numbered from ``first_index`` make: one for each index
    that is a multiple of ``record_every``, and one for the run's ``last_index`` where it is
    among them and no such multiple."""
    end = first_index + steps - 1  # the last index of these steps; indices start at 1
    count = end // record_every - (first_index - 1) // record_every
    if first_index <= last_index <= end and last_index % record_every:
        count += 1
    return count


def empty_samples(model: Model, count: int) -> Samples:
    """Empty Samples for ``count`` samples of ``model``'s run."""
    B, P = model.body_count, model.particle_count
    return Samples(
        np.empty(count),
        np.empty((count, B, 3)),
        np.empty((count, B, 4)),
        np.empty((count, B, 3)),
        np.empty((count, B, 3)),
        np.empty((count, P, 3)),
        np.empty((count, P, 3)),
        np.empty(count),
        np.empty(count),
        np.empty(count),
        np.empty(count),
        np.empty(count, dtype=np.int64),
        np.empty(count, dtype=np.int64),
        np.empty(count),
    )


def stepper_for(
    model: Model,
    method: str,
    options: CollisionOptions,
    integrator: str,
    dt: float,
    state: State,
    compiled_loop: bool | None = None,
) -> Stepping:
    """The Stepping of this run: through the compiled loop wherever it serves the scene
    (``applies``) unless ``compiled_loop`` is False (None and True: the loop wherever it
    serves), else through the method's ``step`` (StitchedStepper)."""
    if compiled_loop is False or not applies(model, method, options, integrator):
        return StitchedStepper(model, method, options, integrator, dt, state)
    if method == "penalty":
        return PenaltyStepper(model, options, integrator, dt, state)
    return LoopStepper(model, method, options, integrator, dt, state)
