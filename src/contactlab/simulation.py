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
             record_every=1, state=None, progress=False, scene_name="custom", threads=None) -> Run:
    """Run ``model`` from ``state`` (default: its initial state) for ``duration`` seconds.

    method: a name from contactlab.methods; options: that method's Options (or a dict of
    them); dt [s] > 0; record_every: sample every K steps (the first and last states are
    always sampled); threads: "auto" (the default, see :func:`contactlab.threads.set_threads`:
    all cores, or one while that steps faster on a busy machine) or a whole number — results are
    bit for bit the same on any count. Raises InputError for bad arguments, SimulationDiverged
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
    with numba_event.install_listener("numba:compile", compiling), compile_notice(notice):
        recorder.sample(state)                     # its collide() compiles the collision kernels first
    setup_compile_seconds = _seconds(compiling)
    max_contacts = 0
    sweeps_made = 0                   # solver sweeps summed over every step (recorded or not)
    first_step_seconds = 0.0          # the first step, compiling the kernels on first use
    stepping_seconds = 0.0            # the later steps: step() calls only, no recording, no compiling
    later_compile_seconds = 0.0       # kernels first needed after the first step (say, at the first contact)
    recording_seconds = 0.0
    with numba_event.install_listener("numba:compile", compiling), compile_notice(notice), \
            tqdm(total=steps, delay=1.0, disable=not progress, unit="step", leave=False,
                 desc=f"{scene_name} ({method})") as bar, chooser:
        for step_index in range(1, steps + 1):
            compiled_before = _seconds(compiling)
            chooser.before_step()
            started = time.perf_counter()
            state, info = module.step(model, state, dt, options, integrator)
            elapsed = time.perf_counter() - started
            if step_index == 1:
                first_step_seconds = elapsed
            else:
                compiled = _seconds(compiling) - compiled_before
                stepping_seconds += elapsed - compiled
                later_compile_seconds += compiled
                if compiled == 0.0:           # a step that compiled says nothing of the threads
                    chooser.after_step(elapsed)
            max_contacts = max(max_contacts, info.contacts.count)
            sweeps_made += info.solver_iterations
            if not state.is_finite() or state.max_speed() > MAX_SPEED:
                raise SimulationDiverged(
                    f"the simulation blew up at t = {state.time:.4g} s (velocities passed {MAX_SPEED:g} m/s or "
                    f"became infinite); use a smaller dt than {dt:g} s", time=state.time)
            if step_index % record_every == 0 or step_index == steps:
                started = time.perf_counter()
                recorder.sample(state, info)
                recording_seconds += time.perf_counter() - started
            bar.update(1)
    wall = time.perf_counter() - run_started
    ordinary_step = stepping_seconds / (steps - 1) if steps > 1 else 0.0
    arrays = recorder.arrays()
    energy = arrays["energy_kinetic"] + arrays["energy_potential"] + arrays["energy_elastic"]
    summary = {
        "scene": scene_name, "method": method, "integrator": integrator, "dt": dt, "steps": steps,
        "options": asdict(options),
        "wall_seconds": wall,
        "first_step_seconds": first_step_seconds,
        "compile_seconds": (setup_compile_seconds + max(0.0, first_step_seconds - ordinary_step)
                            + later_compile_seconds),
        "recording_seconds": recording_seconds,
        "threads": chooser.summary(),
        "steps_per_second": ((steps - 1) / stepping_seconds if steps > 1 and stepping_seconds > 0
                             else 1.0 / max(first_step_seconds, 1e-9)),
        "bodies": model.body_count, "particles": model.particle_count, "max_contacts": max_contacts,
        "max_penetration": float(arrays["max_penetration"].max()),
        "final_penetration": float(arrays["max_penetration"][-1]),
        "energy": {"initial": float(energy[0]), "final": float(energy[-1]), "max": float(energy.max())},
        "solver": {"max_iterations": int(arrays["solver_iterations"].max()),
                   "mean_iterations": sweeps_made / steps,
                   "max_residual": float(arrays["solver_residual"].max())},
    }
    return Run(state, arrays, summary)


def _seconds(listener):
    """Seconds a Numba TimingListener has measured so far (0 before its first event)."""
    return listener.duration if listener.done else 0.0
