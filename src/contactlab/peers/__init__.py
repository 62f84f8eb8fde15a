"""The peers: a contactlab scene run in MuJoCo or pybullet, recorded as contactlab records its own runs.

    from contactlab import peers
    run = peers.simulate(scene.model, "mujoco", dt=scene.dt, duration=scene.duration, scene_name=scene.name)
    run.arrays["body_position"]      # (T, B, 3), the trajectory format of docs/trajectory.md
    run.summary["steps_per_second"]  # the engine's step calls alone

    peers.run_scene("bouncing_ball", "pybullet", duration=1.0)   # a scene by name or file, as loaded

:func:`simulate` translates a finalized Model (contactlab.peers.translate: shapes, masses and
inertias, poses and velocities, gravity, materials mapped to each engine's rule), steps it for
the duration at dt in the engine at its defaults, and records a sample every ``record_every``
steps through contactlab's own Recorder: the same arrays, energies, collision-pass penetration
and summary keys as :func:`contactlab.simulate`, in memory or streamed to a trajectory file, so
render, view, export, the plots, the comparison's measures and the closed-form checks treat it
as a method's run; a cloth's vertices are its particles, as in contactlab (MuJoCo's flex:
contactlab.peers.mujoco_cloth). A scene the engine cannot be given (cloth for pybullet,
particles, a kinematic path, a non-convex mesh for MuJoCo) raises :class:`Inexpressible`, whose
``reasons`` say what and why;
an engine that is not installed is an InputError that names the extra to install.

``contactlab compare SCENE --peers mujoco,pybullet`` and a study's ``peers = [...]`` run them
beside the methods (docs/peers.md, which holds the mapping per engine).
"""

from __future__ import annotations

import importlib
import os
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from ..errors import InputError
from .translate import PEERS, gaps

if TYPE_CHECKING:
    from ..model import Model
    from ..simulation import Run

INSTALL = "pip install 'contactlab[peers]'"  # what brings both engines

__all__ = ["INSTALL", "PEERS", "Inexpressible", "describe", "engine", "gaps", "peer_names", "run_scene", "simulate"]


class Inexpressible(Exception):
    """The scene holds something the peer engine cannot be given; ``reasons``: one sentence each."""

    def __init__(self, peer: str, reasons: Sequence[str]) -> None:
        self.peer, self.reasons = peer, list(reasons)
        super().__init__(self.sentence)

    @property
    def sentence(self) -> str:
        """What the peer cannot express and why, as one sentence."""
        return f"{self.peer} cannot express this scene: " + "; ".join(self.reasons)


def engine(peer: str, field: str = "peer") -> Any:
    """The module of ``peer`` (contactlab.peers.mujoco or contactlab.peers.pybullet), imported;
    InputError on ``field`` for a name that is no peer, or an engine that is not installed (one
    line: what to install)."""
    if peer not in PEERS:
        raise InputError(field, f"unknown peer {peer!r}; expected some of: {', '.join(PEERS)}")
    try:
        return importlib.import_module(f"{__name__}.{peer}")
    except ImportError as error:
        raise InputError(
            field, f"{peer} is not installed ({error}); install the peers with {INSTALL}, or leave {field} out"
        ) from None


def peer_names(peers: str | Sequence[str] | None, field: str = "--peers") -> list[str]:
    """The peers asked for (a list, or one comma-separated string; None: none), each checked
    and its engine imported (:func:`engine`), in order, without repeats."""
    if peers is None:
        return []
    if isinstance(peers, str):
        peers = peers.split(",")
    names = []
    for name in peers:
        name = str(name).strip()
        engine(name, field)
        if name not in names:
            names.append(name)
    return names


def simulate(
    model: Model,
    peer: str,
    dt: float,
    duration: float,
    *,
    record_every: int = 1,
    trajectory: str | os.PathLike[str] | None = None,
    scene_name: str = "custom",
    progress: bool = False,
) -> Run:
    """Run ``model`` in the engine ``peer`` ("mujoco" or "pybullet") for ``duration`` [s] at
    ``dt`` [s], sampling every ``record_every`` steps (the first and last state always), in
    memory or streamed to the HDF5 file ``trajectory``; returns a :class:`contactlab.simulation.Run`
    whose arrays and summary are those of :func:`contactlab.simulate` (the solver figures the
    engine does not report are None). Raises :class:`Inexpressible` for a scene the engine cannot
    be given, InputError for bad arguments or an engine not installed, SimulationDiverged (with
    the run up to then) when the engine's state stops being finite."""
    module = engine(peer, "peer")
    found = gaps(model, peer)
    if found:
        raise Inexpressible(peer, found)
    from .run import run_world  # the stepping loop: files and records (layer 4) and the run's measures

    return run_world(module, model, dt, duration, record_every, trajectory, scene_name, progress)


def run_scene(
    source: str | os.PathLike[str],
    peer: str,
    *,
    overrides: Sequence[str] = (),
    duration: float | None = None,
    record_every: int = 1,
    trajectory: str | os.PathLike[str] | None = None,
    progress: bool = False,
) -> Run:
    """Load the scene ``source`` (a built-in name or a .toml file, with ``overrides`` as
    ``--set`` strings) and run it in ``peer`` at the scene's dt for its duration (or
    ``duration`` [s]): :func:`simulate` of that scene. The summary's ``source`` says how to
    load it again."""
    from ..scene import load_scene

    overrides = [*overrides] + ([f"simulation.duration={duration}"] if duration is not None else [])
    scene = load_scene(source, overrides)
    run = simulate(
        scene.model,
        peer,
        scene.dt,
        scene.duration,
        record_every=record_every,
        trajectory=trajectory,
        scene_name=scene.name,
        progress=progress,
    )
    run.summary["source"] = scene.origin(overrides)
    return run


def describe(settings: dict[str, Any]) -> str:
    """One sentence of a peer run's engine and settings (its summary's ``options``)."""
    if settings.get("engine") == "mujoco":
        integrator = f"{settings['integrator']} integrator"
        if settings.get("cloth"):
            integrator += " (set for the cloth: MuJoCo integrates a flex's elasticity implicitly with no other)"
        return (
            f"MuJoCo {settings['version']} at its defaults: {settings['solver']} solver, at most "
            f"{settings['iterations']} iterations, {settings['cone']} friction cone, {integrator}, soft contacts "
            "(docs/peers.md has the mapping)."
        )
    return (
        f"pybullet {settings['version']} at its defaults: {settings['solver']} solver, {settings['iterations']} "
        f"iterations, {settings['coordinates']} coordinates, restitution below "
        f"{settings['restitution_velocity_threshold']:g} m/s ignored; no velocity damping and no sleeping, as the "
        "scene has neither (docs/peers.md has the mapping)."
    )
