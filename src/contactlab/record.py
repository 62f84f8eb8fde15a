"""Recorder: samples states and diagnostics every K steps; writes the trajectory atomically.

The simulation never does I/O: it hands states to :meth:`Recorder.sample`; files are written
once, at the end, by :func:`write_outputs` (a temporary file, then a rename, so an interrupted
run leaves no half-written file). The arrays are documented in ``docs/trajectory.md``.
"""

import contextlib
import json
import os
import tempfile

import numpy as np

from . import diagnostics, interrupts, surfaces
from .collision import collide
from .errors import InputError

SERIES = ("time", "body_position", "body_orientation", "body_velocity", "body_angular_velocity",
          "particle_position", "particle_velocity", "energy_kinetic", "energy_potential",
          "energy_elastic", "max_penetration", "contact_count", "solver_iterations", "solver_residual")


class Recorder:
    """Collects samples (T of them) of a run of ``model``."""

    def __init__(self, model, record_every=1):
        self.model = model
        self.record_every = record_every
        self.samples = {name: [] for name in SERIES}

    def sample(self, state, info=None):
        """Record ``state``; penetration is measured on its own positions (collision pass), whose
        Contacts it returns."""
        model = self.model
        contacts = collide(model, state)
        values = dict(
            time=state.time,
            body_position=state.body_position, body_orientation=state.body_orientation,
            body_velocity=state.body_velocity, body_angular_velocity=state.body_angular_velocity,
            particle_position=state.particle_position, particle_velocity=state.particle_velocity,
            energy_kinetic=diagnostics.kinetic_energy(model, state),
            energy_potential=diagnostics.potential_energy(model, state),
            energy_elastic=info.energy_elastic if info else 0.0,
            max_penetration=diagnostics.max_penetration(contacts),
            contact_count=info.contacts.count if info else contacts.count,
            solver_iterations=info.solver_iterations if info else 0,
            solver_residual=info.solver_residual if info else 0.0,
        )
        for name, value in values.items():
            self.samples[name].append(np.array(value, copy=True))
        return contacts

    def latest(self, names=SERIES) -> dict:
        """The last sample of the series ``names``, as arrays of one row."""
        return {name: np.array(self.samples[name][-1:]) for name in names}

    def extend(self, samples):
        """Add samples recorded elsewhere (the compiled loop): ``samples`` maps each name of SERIES
        to an array with one row per sample."""
        for name in SERIES:
            self.samples[name].extend(np.array(samples[name], copy=True))

    def arrays(self) -> dict:
        """The trajectory as arrays: time (T,), body_position (T,B,3), …, body_names (B,), the
        static cloth topology triangles (F,3) and particle_cloth (P,), and the shapes' surfaces
        for drawing and export (contactlab.surfaces)."""
        model = self.model
        empty = {"body_position": (0, model.body_count, 3), "body_orientation": (0, model.body_count, 4),
                 "body_velocity": (0, model.body_count, 3), "body_angular_velocity": (0, model.body_count, 3),
                 "particle_position": (0, model.particle_count, 3),
                 "particle_velocity": (0, model.particle_count, 3)}
        out = {}
        for name, values in self.samples.items():
            out[name] = np.array(values) if values else np.zeros(empty.get(name, (0,)))
        out["contact_count"] = out["contact_count"].astype(np.int64)
        out["solver_iterations"] = out["solver_iterations"].astype(np.int64)
        out["body_names"] = np.array(model.body_names, dtype=str)
        out["triangles"] = np.array(model.triangles, dtype=np.int64).reshape(-1, 3)
        out["particle_cloth"] = np.array(model.particle_cloth, dtype=np.int64)
        out.update(surfaces.surface_arrays(model))
        return out


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path beside ``path`` (same suffix) to write to; on success it is
    renamed to ``path``, on any failure it is removed, so ``path`` is never half-written.

        with atomic_path("out/video.mp4") as temporary:
            imageio.mimwrite(temporary, frames)
    """
    directory = os.path.dirname(os.path.abspath(path))
    name = os.path.basename(path)
    temporary = None
    try:
        with interrupts.deferred():     # a signal waits until the temporary file is known, to be removed
            handle, temporary = tempfile.mkstemp(dir=directory, prefix=".partial-", suffix=name)
            os.close(handle)
            umask = os.umask(0)         # mkstemp makes the file private: give it the usual rights
            os.umask(umask)
            os.chmod(temporary, 0o666 & ~umask)
        yield temporary
        with interrupts.deferred():     # renamed and noted as written, or neither
            os.replace(temporary, path)
            interrupts.note_written(path)
    except BaseException:
        if temporary is not None and os.path.exists(temporary):
            os.unlink(temporary)
        raise


def undo_written(paths, directory, created):
    """After a failed or interrupted write of several files: remove ``paths`` (those this call
    completed), un-note them (``interrupts.note_written``), and remove ``directory`` if this
    call ``created`` it and it is empty again, so nothing of the call remains."""
    for path in paths:
        if os.path.exists(path):
            os.unlink(path)
        interrupts.note_written(path, removed=True)
    if created and os.path.isdir(directory) and not os.listdir(directory):
        os.rmdir(directory)


def read_trajectory(arrays, keys) -> dict:
    """The trajectory arrays named in ``keys`` as plain NumPy arrays (an ``np.load`` archive
    decompresses a key at every access), from ``simulate(...).arrays`` or an ``np.load`` of
    trajectory.npz. InputError("arrays", ...) when a key is missing (a trajectory written before
    contactlab recorded surfaces) or there is no sample."""
    missing = [key for key in keys if key not in arrays]
    if missing:
        raise InputError("arrays", f"not a trajectory with surfaces: missing {', '.join(missing)}; "
                                   f"record the run again with this version of contactlab")
    out = {key: np.asarray(arrays[key]) for key in keys}
    if "time" in out and len(out["time"]) == 0:
        raise InputError("arrays", "the trajectory has no samples")
    return out


def _atomic_write(path, write):
    with atomic_path(path) as temporary, open(temporary, "wb") as stream:
        write(stream)


def write_outputs(directory, arrays, summary):
    """Write ``trajectory.npz`` and ``summary.json`` into ``directory`` (created if needed).

    On failure nothing is left behind: no partial file, and no folder this call created.
    """
    created = not os.path.isdir(directory)
    os.makedirs(directory, exist_ok=True)
    try:
        _atomic_write(os.path.join(directory, "trajectory.npz"), lambda s: np.savez_compressed(s, **arrays))
        _atomic_write(os.path.join(directory, "summary.json"),
                      lambda s: s.write((json.dumps(summary, indent=2) + "\n").encode()))
    except BaseException:
        if created:
            undo_written([os.path.join(directory, name) for name in ("trajectory.npz", "summary.json")],
                         directory, created)
        raise
