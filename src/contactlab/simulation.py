"""The driver: step a model with a method for a duration, recording every K steps.

    run = simulate(model, method="impulse", dt=0.002, duration=2.0)
    run.arrays["body_position"]      # (T, B, 3)
    run.summary["max_penetration"]   # m
"""

import time
from dataclasses import asdict, dataclass

import numpy as np
from numba.core import event as numba_event
from tqdm import tqdm

from . import methods
from .methods import velocity_loop
from .builder import _number
from .collision import check_supported
from .compiling import FirstCompile, compile_notice
from .dynamics.integrators import INTEGRATORS
from .errors import InputError, SimulationDiverged
from .record import Recorder
from .threads import ThreadChooser


MAX_SPEED = 1e6   # m/s: a point of a body or a particle moving faster has blown up (no contact scene gets near)


@dataclass
class Run:
    state: object        # the final State
    arrays: dict         # the trajectory (see docs/trajectory.md)
    summary: dict        # the JSON summary (see docs/cli.md)


def simulate(model, method="impulse", dt=0.004, duration=1.0, options=None, integrator="symplectic_euler",
             record_every=1, state=None, progress=False, scene_name="custom", threads=None,
             compiled_loop=None) -> Run:
    """Run ``model`` from ``state`` (default: its initial state) for ``duration`` seconds.

    method: a name from contactlab.methods; options: that method's Options (or a dict of
    them); dt [s] > 0; record_every: sample every K steps (the first and last states are
    always sampled); threads: "auto" (the default, see :func:`contactlab.threads.set_threads`:
    all cores, or one while that steps faster on a busy machine) or a whole number — results are
    bit for bit the same on any count; compiled_loop: for impulse and constraints on the scenes
    the compiled stepping loop serves, None (the default) takes it when it is compiled or cached
    already or the run is long enough to repay compiling it, True always, False never
    (:func:`contactlab.methods.velocity_loop.stepper_for`) — the numbers are the same bit for bit
    either way. Raises InputError for bad arguments, SimulationDiverged
    if the state stops being finite.
    """
    dt = _number(dt, "dt", 0.0, strict=True)
    duration = _number(duration, "duration", 0.0, strict=True)
    if isinstance(record_every, bool) or not isinstance(record_every, (int, np.integer)) or record_every < 1:
        raise InputError("record_every", f"expected a whole number ≥ 1, found {record_every!r}")
    if integrator not in INTEGRATORS:
        raise InputError("integrator", f"expected one of {', '.join(INTEGRATORS)}, found {integrator!r}")
    module = methods.get(method)
    if options is None or isinstance(options, dict):
        options = methods.make_options(module, options or {}, f"method.{method}")
    check_supported(model)
    if hasattr(module, "prepare"):
        options = module.prepare(model, dt, options, integrator)
    chooser = ThreadChooser(threads)
    state = model.state() if state is None else state.copy()
    steps = max(1, int(round(duration / dt)))
    recorder = Recorder(model, record_every)
    compiling = numba_event.TimingListener()       # Numba's own clock of its compilations
    notice = FirstCompile()                        # one line on stderr at the first compilation
    run_started = time.perf_counter()              # the run: its first sample, the steps, the other samples
    if compiled_loop not in (None, True, False):
        raise InputError("compiled_loop", f"expected None, True or False, found {compiled_loop!r}")
    stepper = velocity_loop.stepper_for(model, method, options, integrator, dt, state, steps, compiled_loop)
    with numba_event.install_listener("numba:compile", compiling), compile_notice(notice):
        if stepper is None:
            recorder.sample(state)                 # its collide() compiles the collision kernels first
        else:
            recorder.extend(stepper.sample())      # the loop's own recording, which the steps use too
    setup_compile_seconds = _seconds(compiling)
    tally = Tally()
    with numba_event.install_listener("numba:compile", compiling), compile_notice(notice), \
            tqdm(total=steps, delay=1.0, disable=not progress, unit="step", leave=False,
                 desc=f"{scene_name} ({method})") as bar, chooser:
        if stepper is None:
            state = _step_in_python(module, model, state, dt, options, integrator, steps, recorder, chooser,
                                    compiling, tally, bar)
        else:
            state = _step_compiled(stepper, steps, recorder, chooser, compiling, tally, bar, dt)
    wall = time.perf_counter() - run_started
    first_step_seconds, stepping_seconds = tally.first_step_seconds, tally.stepping_seconds
    ordinary_step = stepping_seconds / (steps - 1) if steps > 1 else 0.0
    arrays = recorder.arrays()
    energy = arrays["energy_kinetic"] + arrays["energy_potential"] + arrays["energy_elastic"]
    summary = {
        "scene": scene_name, "method": method, "integrator": integrator, "dt": dt, "steps": steps,
        "options": asdict(options),
        "wall_seconds": wall,
        "first_step_seconds": first_step_seconds,
        "compile_seconds": (setup_compile_seconds + max(0.0, first_step_seconds - ordinary_step)
                            + tally.later_compile_seconds),
        "recording_seconds": tally.recording_seconds,
        "compiled_loop": stepper is not None,
        "implicit_spring_steps": tally.implicit_spring_steps,
        "threads": chooser.summary(),
        "steps_per_second": ((steps - 1) / stepping_seconds if steps > 1 and stepping_seconds > 0
                             else 1.0 / max(first_step_seconds, 1e-9)),
        "bodies": model.body_count, "particles": model.particle_count, "max_contacts": tally.max_contacts,
        "max_penetration": float(arrays["max_penetration"].max()),
        "final_penetration": float(arrays["max_penetration"][-1]),
        "energy": {"initial": float(energy[0]), "final": float(energy[-1]), "max": float(energy.max())},
        "solver": {"max_iterations": int(arrays["solver_iterations"].max()),
                   "mean_iterations": tally.sweeps_made / steps,
                   "max_residual": float(arrays["solver_residual"].max())},
    }
    return Run(state, arrays, summary)


@dataclass
class Tally:
    """What the stepping measured, whichever path stepped."""
    first_step_seconds: float = 0.0      # the first step, compiling the kernels on first use
    stepping_seconds: float = 0.0        # the later steps: stepping only, no Python recording, no compiling
    later_compile_seconds: float = 0.0   # kernels first needed after the first step (say, at the first contact)
    recording_seconds: float = 0.0
    max_contacts: int = 0
    sweeps_made: int = 0                 # solver sweeps summed over every step (recorded or not)
    implicit_spring_steps: int = 0       # penalty: steps whose contact springs went implicit (explicit unstable)

    def timed(self, step_index, elapsed, compiled):
        """Book the steps from ``step_index`` on that took ``elapsed`` [s], ``compiled`` [s] of
        it compiling; returns whether they say anything of the thread count (nothing compiled)."""
        if step_index == 1:
            self.first_step_seconds = elapsed
            return False
        self.stepping_seconds += elapsed - compiled
        self.later_compile_seconds += compiled
        return compiled == 0.0


def _diverged(state_time, dt):
    return SimulationDiverged(f"the simulation blew up at t = {state_time:.4g} s (velocities passed {MAX_SPEED:g} "
                              f"m/s or became infinite); use a smaller dt than {dt:g} s", time=state_time)


def _step_in_python(module, model, state, dt, options, integrator, steps, recorder, chooser, compiling, tally, bar):
    """Step with the method's ``step``, one Python call a step (cloth, meshes, penalty, projection…)."""
    record_every = recorder.record_every
    for step_index in range(1, steps + 1):
        compiled_before = _seconds(compiling)
        chooser.before_step()
        started = time.perf_counter()
        state, info = module.step(model, state, dt, options, integrator)
        elapsed = time.perf_counter() - started
        if tally.timed(step_index, elapsed, _seconds(compiling) - compiled_before):
            chooser.after_step(elapsed)
        tally.max_contacts = max(tally.max_contacts, info.contacts.count)
        tally.sweeps_made += info.solver_iterations
        tally.implicit_spring_steps += info.implicit_springs
        if not state.is_finite() or state.max_speed() > MAX_SPEED:
            raise _diverged(state.time, dt)
        if step_index % record_every == 0 or step_index == steps:
            started = time.perf_counter()
            recorder.sample(state, info)
            tally.recording_seconds += time.perf_counter() - started
        bar.update(1)
    return state


CHUNK_SECONDS = 0.1     # s: the compiled loop returns to Python about this often (progress, Ctrl-C, threads)


def _step_compiled(stepper, steps, recorder, chooser, compiling, tally, bar, dt):
    """Step through the compiled loop (methods.velocity_loop), in chunks of steps that each take
    about CHUNK_SECONDS; the first step alone, which compiles. Samples are recorded inside."""
    step_index, chunk = 1, 1
    while step_index <= steps:
        count = min(chunk, steps - step_index + 1, chooser.steps_at_this_count() or steps)
        compiled_before = _seconds(compiling)
        chooser.before_step(count)
        started = time.perf_counter()
        made, diverged, samples = stepper.advance(count, step_index, steps, recorder.record_every, MAX_SPEED)
        elapsed = time.perf_counter() - started
        if tally.timed(step_index, elapsed, _seconds(compiling) - compiled_before):
            chooser.after_steps(made, elapsed)
        recorder.extend(samples)
        if diverged:
            raise _diverged(stepper.time, dt)
        if step_index > 1:          # the next chunk: about CHUNK_SECONDS of steps at this pace
            chunk = max(1, min(2 * chunk, int(CHUNK_SECONDS * made / max(elapsed, 1e-9))))
        step_index += made
        bar.update(made)
    tally.max_contacts, tally.sweeps_made = stepper.max_contacts, stepper.sweeps_made
    return stepper.state()


def _seconds(listener):
    """Seconds a Numba TimingListener has measured so far (0 before its first event)."""
    return listener.duration if listener.done else 0.0
