"""The driver: step a model with a method for a duration, recording every K steps.

run = simulate(model, method="impulse", dt=0.002, duration=2.0)
run.arrays["body_position"]      # (T, B, 3)
run.summary["max_penetration"]   # m
"""

from __future__ import annotations

import os
import time
import warnings
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields
from typing import Any, NamedTuple

import numpy as np
from numba.core import event as numba_event

from . import budget, interrupts, kernel_variants, methods, plausibility
from .collision import check_supported
from .compiling import FirstCompile, compile_notice
from .dynamics.integrators import INTEGRATORS
from .errors import InputError, SimulationDiverged
from .health import ENERGY_SERIES, HARD_SPEED, Health
from .methods import velocity_loop
from .model import Model
from .progress import bar as progress_bar
from .record import Recorder, streaming_recorder
from .state import State, array_shapes
from .store import TrajectoryFile
from .threads import ThreadChooser
from .validation import MAX_STEPS, one_of, run_length, whole_number


@dataclass
class Run:
    """What :func:`simulate` returns: the final state, the recorded samples and the summary.

    ``arrays`` holds the arrays of a trajectory file, in memory or, when the run streamed to a
    path, that file read back (a :class:`contactlab.store.TrajectoryFile`); ``summary`` holds
    what a run's ``summary.json`` does; docs/trajectory.md describes both. In Jupyter a Run
    shows itself as a compact HTML summary with a player of the run (contactlab.notebook);
    ``contactlab.viewer.view(run)`` opens it in the interactive viewer."""

    state: State | None
    """the final State (None for a comparison's run read back from its files)"""
    arrays: Mapping[str, Any]
    """the trajectory (see docs/trajectory.md): name -> array, a dict or a TrajectoryFile"""
    summary: dict[str, Any]
    """the JSON summary (see docs/trajectory.md)"""
    model: Model | None = None
    """the Model it ran (None for a run read back from a folder)"""

    def __repr__(self):
        s = self.summary
        return (
            f"Run({s.get('scene', '?')!r} with {s.get('method', '?')}: {s.get('steps', '?')} steps of "
            f"{s.get('dt', float('nan')):g} s, {s.get('samples', '?')} samples, final {self.state!r})"
        )


class Checked(NamedTuple):
    """A run's arguments as :func:`check_run` settled them: the method's module and options
    dataclass, dt and duration [s], the steps and the samples the run will record."""

    module: Any
    options: Any
    dt: float
    duration: float
    steps: int
    samples: int


def check_run(
    model: Model,
    method: str = "impulse",
    dt: float = 0.004,
    duration: float = 1.0,
    options: Any = None,
    integrator: str = "symplectic_euler",
    record_every: int = 1,
    *,
    state: State | None = None,
    scene_name: str = "custom",
    memory_limit: float | None = None,
    trajectory: str | os.PathLike[str] | None = None,
    streamed: bool | None = None,
    remedies: budget.Remedies = budget.SIMULATE,
) -> Checked:
    """Every check :func:`simulate` makes of its arguments before its first step, without
    stepping: the same InputError, naming the first bad one, for the same arguments (dt [s] > 0
    and finite, no longer than the duration [s], at most 10⁹ steps; the model something to move
    that the collision code supports; the method, its options and the integrator; the memory and,
    for a ``trajectory`` file, the disk the run needs by :func:`contactlab.budget.require`).
    ``streamed`` and ``remedies`` as there: a sweep checks its cells with its own advice."""
    module, options, dt, duration, steps = _checked_arguments(
        model, method, dt, duration, options, integrator, record_every, state, scene_name
    )
    check_supported(model)
    if memory_limit is not None and (
        isinstance(memory_limit, bool) or not isinstance(memory_limit, (int, float)) or not memory_limit > 0
    ):
        raise InputError("memory_limit", f"expected a number of bytes > 0 (math.inf: none), found {memory_limit!r}")
    if trajectory is not None and not isinstance(trajectory, (str, os.PathLike)):
        raise InputError("trajectory", f"expected a file path (str or os.PathLike) or None, found {_kind(trajectory)}")
    needed = budget.require(model, steps, record_every, memory_limit, trajectory, streamed=streamed, remedies=remedies)
    return Checked(module, options, dt, duration, steps, needed["samples"])


def _checked_arguments(model, method, dt, duration, options, integrator, record_every, state, scene_name):
    """simulate()'s arguments checked, an InputError naming the first bad one; returns (the
    method's module, its Options, dt [s], duration [s], steps). dt and duration by
    contactlab.validation.run_length; options, a dict or None, built into the method's Options
    (checked there), an Options of the method taken as it is; the model has something to move;
    a given state has this model's shapes."""
    if not isinstance(model, Model):
        raise InputError(
            "model",
            f"expected a contactlab Model (ModelBuilder(...).finalize() or "
            f"load_scene(...).model), found {_kind(model)}",
        )
    if model.body_count + model.particle_count == 0:
        raise InputError(
            "model",
            "has no bodies and no particles (nor cloth): there is nothing to simulate; "
            "add a body, particles or a cloth",
        )
    dt, duration, steps = run_length(dt, duration)
    if (
        isinstance(record_every, bool)
        or not isinstance(record_every, (int, np.integer))
        or not 1 <= record_every <= MAX_STEPS
    ):
        raise InputError("record_every", f"expected a whole number from 1 to {MAX_STEPS:.0e}, found {record_every!r}")
    one_of(integrator, "integrator", INTEGRATORS)
    if integrator == "explicit_euler" and model.body_kinematic.any():
        raise InputError(
            "integrator",
            "explicit_euler moves positions by the velocities before the step, which "
            "cannot follow a kinematic body's path; use symplectic_euler or "
            "backward_euler",
        )
    if not isinstance(method, str):
        raise InputError("method", f"expected a method name ({', '.join(methods.AVAILABLE)}), found {_kind(method)}")
    module = methods.get(method)
    if options is None or isinstance(options, dict):
        strange = [key for key in options or {} if not isinstance(key, str)]
        if strange:
            raise InputError("options", f"expected option names (strings) as keys, found {strange[0]!r}")
        options = methods.make_options(module, options or {}, f"method.{method}")
    elif not isinstance(options, module.Options):
        raise InputError(
            "options",
            f"expected None, a dict or a contactlab.methods.{method}.Options for the "
            f"{method} method, found {_kind(options)}",
        )
    if state is not None:
        _check_state(model, state)
    if not isinstance(scene_name, str):
        raise InputError("scene_name", f"expected a string, found {_kind(scene_name)}")
    return module, options, dt, duration, steps


def _check_state(model, state):
    """InputError("state", ...) unless ``state`` is a State of ``model``'s shapes, finite."""
    if not isinstance(state, State):
        raise InputError(
            "state", f"expected a contactlab State (model.state(), or the state of a run), found {_kind(state)}"
        )
    for name, shape in array_shapes(model.body_count, model.particle_count).items():
        value = getattr(state, name)
        found = getattr(value, "shape", None)
        if not isinstance(value, np.ndarray) or value.shape != shape or value.dtype != np.float64:
            raise InputError(
                "state",
                f"its {name} is {_kind(value)} of shape {found}, where this model's "
                f"is an array of floats of shape {shape}: a state of another model?",
            )
    if not state.is_finite() or not isinstance(state.time, (int, float, np.number)) or not np.isfinite(state.time):
        raise InputError("state", "has a time, position or velocity that is not a finite number")


def _check_compiled_loop(compiled_loop: Any) -> None:
    """InputError naming ``compiled_loop`` unless it is None, True or False (simulate's and a Stepper's)."""
    if compiled_loop not in (None, True, False):
        raise InputError("compiled_loop", f"expected None, True or False, found {compiled_loop!r}")


def _kind(value):
    """What ``value`` is, for a message: its type's qualified name."""
    kind = type(value)
    name = kind.__name__ if kind.__module__ == "builtins" else f"{kind.__module__}.{kind.__qualname__}"
    return f"{'an' if name[0] in 'aeiou' else 'a'} {name}"


def simulate(
    model: Model,
    method: str = "impulse",
    dt: float = 0.004,
    duration: float = 1.0,
    options: Any = None,
    integrator: str = "symplectic_euler",
    record_every: int = 1,
    state: State | None = None,
    progress: bool = False,
    scene_name: str = "custom",
    threads: int | str | None = None,
    compiled_loop: bool | None = None,
    allow_divergence: bool = False,
    memory_limit: float | None = None,
    trajectory: str | os.PathLike[str] | None = None,
) -> Run:
    """Run ``model`` from ``state`` (default: its initial state) for ``duration`` seconds.

    method: a name from contactlab.methods; options: that method's Options, taken as they are (they
    were checked when built, as ``load_scene`` builds ``scene.options``), or a dict or None, built
    into them here; dt [s] > 0 and no longer than duration [s] (at most 10⁹ steps,
    :func:`contactlab.validation.run_length`); the model must hold a body or particle; record_every:
    sample every K steps (the first and last states are always sampled); progress: the steps
    shown on stderr (:mod:`contactlab.progress`: a bar on a terminal, else a line every 5 s); threads: "auto" (the
    default, see :func:`contactlab.threads.set_threads`: all cores, or one while that steps faster
    on a busy machine) or a whole number — results are bit for bit the same on any count;
    compiled_loop: for every method on the scenes the stepping loop serves, None (the default) or
    True runs them through the compiled loop, whatever the run's length, False through the
    method's own ``step`` (:func:`contactlab.methods.velocity_loop.stepper_for`) — the numbers are
    the same bit for bit either way, and either is advanced, recorded and health-checked by the
    same loop here, in chunks of about 0.1 s; allow_divergence: keep going when a health
    check fails (:mod:`contactlab.health`), recording it in the summary, instead of stopping;
    memory_limit [bytes]: the most the run may need by its estimate (:mod:`contactlab.budget`; None:
    half this machine's memory, ``math.inf`` none); trajectory: None (the default) keeps the samples
    in memory, in ``run.arrays``; a path (``"out/trajectory.h5"``, its folder existing) streams them
    into that HDF5 file as the run goes (:mod:`contactlab.store`), so memory stays flat however long
    the run, and ``run.arrays`` is the file read back (a :class:`contactlab.store.TrajectoryFile`).
    Raises InputError for bad arguments or a run that cannot fit, and SimulationDiverged (with the
    run up to then in its ``run``) when a health check fails: the state stops being finite, a speed
    beyond the scene's scale, an energy gain nothing explains, a contact deep enough to pass
    through. Ctrl-C (or SIGTERM) stops the run between steps with
    :class:`contactlab.interrupts.Interrupted`, a KeyboardInterrupt, whose ``run`` is the run up to
    then (its summary's ``interrupted`` says when); a streamed trajectory is kept either way, its
    ``status`` saying how the run ended.
    """
    with interrupts.deferred():  # compiling or stepping, a signal waits for a step boundary
        module, options, dt, duration, steps, samples = check_run(
            model,
            method,
            dt,
            duration,
            options,
            integrator,
            record_every,
            state=state,
            scene_name=scene_name,
            memory_limit=memory_limit,
            trajectory=trajectory,
        )
        chooser = ThreadChooser(threads)
        state = model.state() if state is None else state.copy()
        _check_compiled_loop(compiled_loop)
        # the run's clock and compile tally start here: the plausibility check's collide() is the
        # first to need the collision kernels, and compiles them on an empty cache
        clock = _Clock(
            numba_event.TimingListener(), FirstCompile(kernel_variants.compiling_notice), time.perf_counter()
        )
        with numba_event.install_listener("numba:compile", clock.compiling), compile_notice(clock.notice):
            for line in plausibility.warnings_for(model, state, dt, steps):  # a unit slip? one line each
                warnings.warn(line, plausibility.PlausibilityWarning, stacklevel=2)
        advice = getattr(module, "divergence_advice", None)
        health = Health(model, state, dt, advice(model, dt, options, integrator) if advice else None, allow_divergence)
        recorder = (
            Recorder(model, record_every, samples=samples)
            if trajectory is None
            else streaming_recorder(model, record_every, trajectory, samples)
        )
        try:
            plan = _Plan(model, module, method, dt, steps, options, integrator, scene_name, progress, compiled_loop)
            return _record_run(plan, recorder, state, chooser, health, clock)
        except BaseException:
            if recorder.sink is not None:  # not a run to keep (a bug, a full disk): nothing of it remains
                recorder.sink.discard()
            raise


class Stepper:
    """A run you step yourself, in your own loop, at the speed ``simulate`` steps it.

    Built once from the model, the method, its options, dt [s] and the integrator (checked as
    :func:`simulate` checks them, the same InputError for the same bad argument), from ``state``
    (default: the model's initial state, copied). Each :meth:`step` makes steps through the same
    stepping ``simulate`` uses — the compiled loop wherever it serves the scene, with no Python
    between the steps of one call, else the method's own ``step`` — so the numbers are bit for bit
    those of ``simulate`` with the same arguments. Between calls, :attr:`state` is the state
    reached: read it (sensors, your own recording) and write into its arrays in place (control:
    a velocity set, a body moved); the next step starts from what you wrote.

    Example — a ball dropped on the floor, its apexes read in the loop::

        stepper = Stepper(model, "impulse", dt=0.001)
        while stepper.time < 2.0:
            stepper.step()
            z, vz = stepper.state.body_position[0, 2], stepper.state.body_velocity[0, 2]

    Nothing is recorded, health-checked (beyond a state that stops being finite or passes
    ``health.HARD_SPEED``, which raises SimulationDiverged) or timed here: ``simulate`` does that,
    over the same stepping. ``compiled_loop`` as for ``simulate``."""

    def __init__(
        self,
        model: Model,
        method: str = "impulse",
        dt: float = 0.004,
        options: Any = None,
        integrator: str = "symplectic_euler",
        *,
        state: State | None = None,
        compiled_loop: bool | None = None,
    ) -> None:
        _, options, dt, _, _ = _checked_arguments(model, method, dt, dt, options, integrator, 1, state, "custom")
        check_supported(model)
        _check_compiled_loop(compiled_loop)
        self.model, self.method, self.options, self.integrator, self.dt = model, method, options, integrator, dt
        start = model.state() if state is None else state.copy()
        self._notice = FirstCompile(kernel_variants.compiling_notice)
        with compile_notice(self._notice):
            self.stepping = velocity_loop.stepper_for(model, method, options, integrator, dt, start, compiled_loop)
        self.steps_made = 0
        """steps made since it was built"""
        no_rows = velocity_loop.empty_samples(model, 0)._asdict()
        self._no_rows = lambda count: no_rows  # a step records nothing: samples of no row

    @property
    def compiled(self) -> bool:
        """Whether it steps through the compiled loop (else through the method's ``step``)."""
        return self.stepping.compiled

    @property
    def state(self) -> State:
        """The State reached, its arrays the ones the next step starts from: write into them in
        place to change it (``state.copy()`` keeps one as it is now)."""
        return self.stepping.reached()

    @property
    def time(self) -> float:
        """[s] the time reached."""
        return float(self.stepping.reached().time)

    def step(self, steps: int = 1) -> None:
        """Make ``steps`` (a whole number ≥ 1) steps of dt. Raises SimulationDiverged, with the
        time, where a step leaves a non-finite value or a speed above ``health.HARD_SPEED``."""
        whole_number(steps, "steps", 1)
        first = self.steps_made + 1
        arguments = (steps, first, 0, NEVER_SAMPLED, HARD_SPEED, self._no_rows)
        if self.steps_made and self.stepping.compiled:  # the loop compiled whole at its first call
            made, diverged, _ = self.stepping.advance(*arguments)
        else:  # a first call, or the methods' step, whose stages compile as a run first meets them
            with compile_notice(self._notice):
                made, diverged, _ = self.stepping.advance(*arguments)
        self.steps_made += made
        if diverged:
            raise SimulationDiverged(
                f"the state stopped being finite or passed {HARD_SPEED:g} m/s at t = {self.time:.6g} s; "
                f"use a smaller dt than {self.dt:g} s",
                time=self.time,
            )


NEVER_SAMPLED = 2**62  # a record_every no step index reaches: Stepper.step records nothing


class _Clock(NamedTuple):
    """What times a run from its first compilation on: Numba's compile events, the notice they
    print once, and the wall clock's start [s, time.perf_counter]."""

    compiling: numba_event.TimingListener
    notice: FirstCompile
    started: float


class _Plan(NamedTuple):
    """What simulate() settled for the run, gathered so the stepping is handed it in one piece."""

    model: Model
    module: Any
    """the method's module (contactlab.methods)"""
    method: str
    dt: float
    """[s]"""
    steps: int
    options: Any
    """the method's options dataclass"""
    integrator: str
    scene_name: str
    progress: bool
    compiled_loop: bool | None


def _record_run(plan, recorder, state, chooser, health, clock):
    """Step and record the run; the Run, or SimulationDiverged or Interrupted carrying it
    (``error.run``), the trajectory up to then included. ``clock``: a ``_Clock`` started
    before the run's first collision (the plausibility check's)."""
    model, module, method, dt, steps, options, integrator, scene_name, progress, compiled_loop = plan
    compiling, notice, run_started = clock  # the run: its first sample, the steps, the other samples
    stepper = velocity_loop.stepper_for(model, method, options, integrator, dt, state, compiled_loop)
    if not stepper.parallel:
        chooser.nothing_parallel()  # a small scene's loop: no thread trials, no chunks cut short by them
    with numba_event.install_listener("numba:compile", compiling), compile_notice(notice):
        stepper.sample(recorder.reserve)  # the stepper's own recording, which the steps use too
        recorder.commit(1)
    setup_compile_seconds = _seconds(compiling)
    health.check_samples(recorder.latest(ENERGY_SERIES), 0)  # the energy to hold the run to
    # and how deep it starts, from the first sample (no collision pass of its own)
    health.start(state, float(recorder.latest(("max_penetration",))["max_penetration"][0]))
    tally = Tally()
    stopped = interrupted = None
    with (
        numba_event.install_listener("numba:compile", compiling),
        compile_notice(notice),
        progress_bar(steps, f"{scene_name} ({method})", "step", progress) as bar,
        chooser,
    ):
        try:
            state = _step(stepper, steps, recorder, chooser, compiling, tally, bar, health)
        except _Stopped as stop:
            stopped, state = stop.violation, stop.state
        except interrupts.Interrupted as signal_stop:
            interrupted, state = signal_stop, stepper.state()
            tally.take(stepper)
    wall = time.perf_counter() - run_started
    recorder.flush()
    totals = recorder.totals
    status = "diverged" if stopped is not None else "interrupted" if interrupted is not None else "complete"
    arrays = recorder.arrays() if recorder.sink is None else TrajectoryFile(recorder.sink.finish(status))
    first_step_seconds, stepping_seconds = tally.first_step_seconds, tally.stepping_seconds
    steps_made = int(round((state.time - totals.first_time) / dt))
    taken = steps if status == "complete" else steps_made  # what the summary counts: a stopped run's steps
    ordinary_step = stepping_seconds / (taken - 1) if taken > 1 else 0.0
    summary = {
        "scene": scene_name,
        "method": method,
        "integrator": integrator,
        "dt": dt,
        "steps": taken,
        "options": _options_table(options),
        "wall_seconds": wall,
        "first_step_seconds": first_step_seconds,
        "compile_seconds": (
            setup_compile_seconds + max(0.0, first_step_seconds - ordinary_step) + tally.later_compile_seconds
        ),
        "recording_seconds": tally.recording_seconds,
        "compiled_loop": stepper.compiled,
        "stepping": "compiled loop" if stepper.compiled else "python",
        "kernels": "python" if kernel_variants.interpreted() else "compiled",
        "implicit_spring_steps": tally.implicit_spring_steps,
        "threads": chooser.summary(),
        **run_measures(model, tally, totals, taken),
        "solver": {
            "max_iterations": totals.max_iterations,
            "mean_iterations": tally.sweeps_made / max(1, taken),
            "cg_iterations_per_step": tally.linear_iterations_made / max(1, taken),
            "max_residual": totals.max_residual,
        },
        "health": health.summary(),
        "diverged": None,
        "interrupted": None,
    }
    if stopped is not None:
        message = health.message(stopped)
        summary["diverged"] = {
            "check": stopped.check,
            "time": stopped.time,
            "message": message,
            "steps_made": steps_made,
        }
        raise SimulationDiverged(message, time=stopped.time, run=Run(state, arrays, summary, model))
    if interrupted is not None:
        summary["interrupted"] = {"signal": interrupted.name, "time": totals.last_time, "steps_made": steps_made}
        interrupted.run = Run(state, arrays, summary, model)
        raise interrupted
    if stepper.compiled:  # this kind of run is compiled on this machine from now on
        kernel_variants.remember(
            kernel_variants.variant_of(model, method, options, integrator), summary["compile_seconds"]
        )
    return Run(state, arrays, summary, model)


def _options_table(options: Any) -> dict[str, Any]:
    """The summary's ``options``: ``asdict(options)``, without its deep copies where every field
    is a number, a string or None (as every method's Options are: 15 µs of a tiny run)."""
    table = {f.name: getattr(options, f.name) for f in fields(options)}
    if all(isinstance(value, (int, float, str, type(None))) for value in table.values()):
        return table
    return asdict(options)


def run_measures(model: Model, tally: Tally, totals: Any, steps: int) -> dict[str, Any]:
    """What a run's summary measures, alike for a method's run and a peer engine's
    (contactlab.peers): steps/s over the ``steps`` made after the first (which compiles; with its
    spread, ``Tally``), the model's bodies and particles, the most contacts, the most cloth
    self-contacts in a sample, the deepest and the final overlap [m], the energy, and the
    samples recorded (``totals``, the Recorder's)."""
    return {
        "steps_per_second": (
            (steps - 1) / tally.stepping_seconds
            if steps > 1 and tally.stepping_seconds > 0
            else 1.0 / max(tally.first_step_seconds, 1e-9)
            if steps >= 1
            else 0.0  # no step made (a run stopped before its first)
        ),
        "steps_per_second_spread": tally.rate_spread(),
        "bodies": model.body_count,
        "particles": model.particle_count,
        "max_contacts": tally.max_contacts,
        "self_contacts": tally.self_contacts,
        "max_penetration": totals.max_penetration,
        "final_penetration": totals.final_penetration,
        "energy": totals.energy(),
        "samples": totals.count,
    }


class _Stopped(Exception):
    """A health check stopped the run: ``violation`` (health.Violation), at ``state``."""

    def __init__(self, violation, state):
        super().__init__(violation.what)
        self.violation, self.state = violation, state


@dataclass
class Tally:
    """What the stepping measured, whichever path stepped."""

    first_step_seconds: float = 0.0
    """the first step, compiling the kernels on first use"""
    stepping_seconds: float = 0.0
    """the later steps: stepping only, no Python recording, no compiling"""
    later_compile_seconds: float = 0.0
    """kernels first needed after the first step (say, at the first contact)"""
    recording_seconds: float = 0.0
    max_contacts: int = 0
    sweeps_made: int = 0
    """solver sweeps summed over every step (recorded or not)"""
    implicit_spring_steps: int = 0
    """penalty: steps whose contact springs went implicit (explicit unstable)"""
    linear_iterations_made: int = 0
    """penalty: conjugate-gradient iterations of the implicit springs, every step"""
    self_contacts: int = 0
    """the most cloth self-contacts (collision.cloth_self) in one sample"""
    window_rates: list[float] = field(default_factory=list)
    """steps/s of each WINDOW_SECONDS of stepping"""
    window: list[Any] = field(default_factory=lambda: [0, 0.0])
    """the window being filled: steps, seconds"""

    def take(self, stepper: Any) -> None:
        """The counts the run's stepper kept (methods.velocity_loop)."""
        self.max_contacts, self.sweeps_made = stepper.max_contacts, stepper.sweeps_made
        self.implicit_spring_steps = stepper.implicit_spring_steps
        self.linear_iterations_made = stepper.linear_iterations_made
        self.self_contacts = stepper.self_contacts

    def timed(self, step_index: int, elapsed: float, compiled: float, steps: int = 1) -> bool:
        """Book the ``steps`` steps from ``step_index`` on that took ``elapsed`` [s], ``compiled``
        [s] of it compiling; returns whether they say anything of the thread count (nothing compiled)."""
        if step_index == 1:
            self.first_step_seconds = elapsed
            return False
        self.stepping_seconds += elapsed - compiled
        self.later_compile_seconds += compiled
        if compiled == 0.0:  # a window of plain stepping: one measurement of the rate
            self.window[0] += steps
            self.window[1] += elapsed
            if self.window[1] >= WINDOW_SECONDS:
                self.window_rates.append(self.window[0] / self.window[1])
                self.window = [0, 0.0]
        return compiled == 0.0

    def rate_spread(self) -> dict[str, float] | None:
        """The stepping rate as repeated measurements: {"median", "low", "high" (the quartiles)
        [steps/s], "windows": how many WINDOW_SECONDS windows} — a short run's last, partial
        window counts when fewer than three are full; None when nothing was timed."""
        rates = list(self.window_rates)
        if len(rates) < 3 and self.window[1] > 0:
            rates.append(self.window[0] / self.window[1])
        if not rates:
            return None
        # one rate (a tiny run's one window) is every quartile: np.percentile's answer, without its 50 µs
        low, median, high = rates * 3 if len(rates) == 1 else np.percentile(rates, [25, 50, 75])
        return {"median": float(median), "low": float(low), "high": float(high), "windows": len(rates)}


def _advance(bar, step_index, made):
    """Move the progress bar by ``made`` steps; after the first step, which compiled the kernels
    (or loaded them), its clock starts again, so its rate and time left are the stepping's."""
    if step_index == 1:
        bar.restart()
    bar.update(made)


CHUNK_SECONDS = 0.1  # s: the compiled loop returns to Python about this often (progress, Ctrl-C, threads)
# the next chunk at most this many times the last: its pace, measured on few steps, may be off,
# but each call into the loop costs tens of µs (its arguments' unboxing), so a run of a tiny
# scene (a few µs a step) should reach its full chunk in few calls (1, 64, 4096, …: the first
# step's pace counts where it compiled nothing; a 720-step ball run makes three, 0.04 ms less
# than with 16, benchmarks/README.md, thirtieth round). At worst, where the first step is far
# cheaper than those after it, the second chunk is 64 of them
CHUNK_GROWTH = 64
WINDOW_SECONDS = 0.1  # s of stepping per measurement of the rate (summary "steps_per_second_spread")


def _step(stepper, steps, recorder, chooser, compiling, tally, bar, health):
    """Step the run's ``stepper`` (methods.velocity_loop: the compiled loop, or the method's own
    ``step`` from Python) in chunks of steps that each take about CHUNK_SECONDS; the first step
    alone, which compiles. Samples are recorded inside, into the recorder's buffer (a chunk no
    longer than its samples fit there: memory stays flat); the stepper stops itself past the
    health's speed limit, and the rest is checked after each chunk."""

    # the loop stops where check_state would: past the scene's speed limit, and always past HARD_SPEED
    speed_limit = HARD_SPEED if health.allow_divergence else min(health.speed_limit, HARD_SPEED)
    step_index, chunk = 1, 1
    while step_index <= steps:
        interrupts.check()
        count = min(chunk, steps - step_index + 1, chooser.steps_at_this_count() or steps, recorder.steps_that_fit())
        compiled_before, recorded_before = _seconds(compiling), stepper.recording_seconds
        chooser.before_step(count)
        started = time.perf_counter()
        made, diverged, samples = stepper.advance(
            count, step_index, steps, recorder.record_every, speed_limit, recorder.reserve
        )  # recorded into the recorder's buffer
        recording = stepper.recording_seconds - recorded_before  # the loop's own: none (within its steps)
        tally.recording_seconds += recording
        elapsed = time.perf_counter() - started - recording
        compiled = _seconds(compiling) - compiled_before
        if tally.timed(step_index, elapsed, compiled, made):
            chooser.after_steps(made, elapsed)
        reached = stepper.reached()  # checked, not kept: no copies
        # every sample, in order: the first that fails ends the trajectory; then the state reached
        times = samples["time"]
        violation = _earlier(health.check_samples(samples, 0), health.check_sampled_depths(samples))
        kept = len(times) if violation is None else int(np.searchsorted(times, violation.time, side="right"))
        if violation is None and diverged:
            violation = health.check_state(reached)
        recorder.commit(kept)
        if violation is None and not (kept and times[-1] == reached.time):
            violation = health.check_depth(reached, None)  # and the chunk's end, where it is no sample
        if violation is not None:
            tally.take(stepper)
            if kept and times[kept - 1] == violation.time:
                raise _Stopped(violation, State.sampled(samples, kept - 1))
            recorder.extend(stepper.sample())  # the state that went wrong ends the trajectory
            raise _Stopped(violation, stepper.state())
        if step_index > 1 or compiled == 0.0:  # the next chunk: about CHUNK_SECONDS of steps at this pace
            chunk = max(1, min(CHUNK_GROWTH * chunk, int(CHUNK_SECONDS * made / max(elapsed, 1e-9))))
        _advance(bar, step_index, made)
        step_index += made
    tally.take(stepper)
    return stepper.state()


def _earlier(first, second):
    """The earlier of two Violations (or None), the first where they are at one time."""
    if first is None or (second is not None and second.time < first.time):
        return second
    return first


def _seconds(listener):
    """Seconds a Numba TimingListener has measured so far (0 before its first event)."""
    return listener.duration if listener.done else 0.0
