"""Stepping a peer engine's world and recording it as contactlab records a method's run.

The engine's world (contactlab.peers.mujoco.World or contactlab.peers.pybullet.World) steps;
this module times its step calls alone (contactlab.simulation.Tally: the first step left out,
the rate over ~0.1 s windows), applies the scene's external forces at each step's start time,
reads the state back every ``record_every`` steps into contactlab's Recorder (positions,
energies by contactlab.diagnostics from the model's masses and inertias, a cloth's elastic
energy the engine's own cloth's (``world.cloth_energy``), the deepest overlap by
contactlab's own collision pass on the engine's positions, the engine's contact count and
solver iterations) and writes the summary :func:`contactlab.simulate` writes, with the
engine's settings as its ``options``.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from .. import budget
from ..errors import SimulationDiverged
from ..model import Model
from ..progress import bar as progress_bar
from ..record import Recorder, streaming_recorder
from ..simulation import Run, Tally, run_measures
from ..store import TrajectoryFile
from ..validation import run_length


@dataclass(frozen=True)
class _Counted:
    """The contacts of a step, as a method's Contacts shows their number."""

    count: int


class _Info(NamedTuple):
    """What the Recorder reads of a step besides the state (a method's StepInfo's fields)."""

    contacts: _Counted
    solver_iterations: int
    solver_residual: float = 0.0
    energy_elastic: float = 0.0
    cloth_energy: float | None = None  # J: the engine's own cloth's elastic energy (None: contactlab's springs')


def _info(world, model, state, count, sweeps):
    """The _Info of a sample of ``state``: ``count`` contacts, ``sweeps`` iterations, and the
    engine's own cloth energy where the scene has cloth."""
    cloth = world.cloth_energy(state) if model.cloth_count else None
    return _Info(_Counted(count), sweeps, cloth_energy=cloth)


def run_world(
    module: Any,
    model: Model,
    dt: float,
    duration: float,
    record_every: int,
    trajectory: str | os.PathLike[str] | None,
    scene_name: str,
    progress: bool,
) -> Run:
    """Build ``module.World(model, dt)``, step it ``duration`` / ``dt`` times and record it (see
    contactlab.peers.simulate, which checks the scene first)."""
    dt, duration, steps = run_length(dt, duration)
    samples = budget.require(model, steps, record_every, None, trajectory)["samples"]
    recorder = (
        Recorder(model, record_every, samples=samples)
        if trajectory is None
        else streaming_recorder(model, record_every, trajectory, samples)
    )
    try:
        world = module.World(model, dt)
        try:
            return _stepped(world, model, dt, steps, recorder, scene_name, progress)
        finally:
            world.close()
    except SimulationDiverged:
        raise
    except BaseException:
        if recorder.sink is not None:
            recorder.sink.discard()
        raise


def _stepped(world, model, dt, steps, recorder, scene_name, progress):
    started = time.perf_counter()
    state = model.state()
    recorder.sample(state, _info(world, model, state, 0, 0))
    tally, iterations, most = Tally(), [], 0
    loads = model.drive is not None and model.drive.has_loads
    failed = None
    with progress_bar(steps, f"{scene_name} ({world.name})", "step", progress) as bar:
        for step in range(1, steps + 1):
            force, torque = model.drive.loads((step - 1) * dt) if loads else (None, None)
            began = time.perf_counter()
            world.step(force, torque)
            tally.timed(step, time.perf_counter() - began, 0.0)
            count, sweeps = world.contacts(), world.iterations()
            tally.max_contacts = max(tally.max_contacts, count)
            if sweeps is not None:
                iterations.append(sweeps)
            if step % recorder.record_every == 0 or step == steps:
                began = time.perf_counter()
                state = world.state(step * dt)
                state.time = step * dt
                recorder.sample(state, _info(world, model, state, count, sweeps or 0))
                tally.recording_seconds += time.perf_counter() - began
                if not state.is_finite():
                    failed = step * dt
                    break
            if step == 1:
                bar.restart()
            bar.update(1)
    most = max(iterations, default=0)
    recorder.flush()
    status = "complete" if failed is None else "diverged"
    arrays = recorder.arrays() if recorder.sink is None else TrajectoryFile(recorder.sink.finish(status))
    totals = recorder.totals
    made = int(round(state.time / dt))
    summary = {
        "scene": scene_name,
        "method": world.name,
        "integrator": world.settings["integrator"],
        "dt": dt,
        "steps": steps,
        "options": world.settings,
        "engine_notes": list(world.notes),
        "wall_seconds": time.perf_counter() - started,
        "first_step_seconds": tally.first_step_seconds,
        "compile_seconds": 0.0,
        "recording_seconds": tally.recording_seconds,
        "compiled_loop": False,
        "stepping": world.name,
        **run_measures(model, tally, totals, made),
        "solver": {
            "max_iterations": most if iterations else None,
            "mean_iterations": float(np.mean(iterations)) if iterations else None,
            "max_residual": None,
        },
        "diverged": None,
        "interrupted": None,
    }
    run = Run(state, arrays, summary, model)
    if failed is not None:
        message = f"{world.name}'s state stopped being finite at t = {failed:.4g} s"
        summary["diverged"] = {"check": "finite", "time": failed, "message": message, "steps_made": made}
        raise SimulationDiverged(message, time=failed, run=run)
    return run
