"""From a validated scene dict (see :mod:`.schema`) to a :class:`~contactlab.model.Model`.

Everything goes through :class:`~contactlab.builder.ModelBuilder`, which checks the physical
values; its errors name the builder argument (``mass``), and are re-raised here with the scene
path in front (``bodies[2].mass``). ``array`` tables are expanded here: a body is copied on a
grid of ``count`` = [nx, ny, nz] positions ``spacing`` = [dx, dy, dz] apart, starting at its
``position`` (x varies fastest, then y, then z); the copies are named ``NAME_i``.
``[[cloth]]`` entries go to ``ModelBuilder.add_cloth`` key for key (``cloth[0].resolution``), a
body's ``path`` table to ``ModelBuilder.add_path`` (``bodies[1].path.times``) and ``[[forces]]``
entries to ``ModelBuilder.add_force`` (``forces[0].force``).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..builder import ModelBuilder
from ..errors import InputError
from ..validation import check_dynamic_count

if TYPE_CHECKING:
    from ..model import Model


def _call(prefix, function, **arguments):
    """``function(**arguments)`` (None arguments left out) with InputError fields prefixed."""
    try:
        return function(**{name: value for name, value in arguments.items() if value is not None})
    except InputError as error:
        field = f"{prefix}.{error.field}" if error.field else prefix
        raise InputError(field, error.message) from None


def grid_offsets(array: Mapping[str, Any] | None) -> np.ndarray:
    """Offsets (count, 3) [m] of the copies an ``array`` table makes; one zero row without one."""
    if array is None:
        return np.zeros((1, 3))
    (nx, ny, nz), spacing = array["count"], np.asarray(array["spacing"])
    check_dynamic_count(nx * ny * nz, "array.count", f"an array of {nx} x {ny} x {nz} copies")
    iz, iy, ix = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    return np.stack([ix.ravel(), iy.ravel(), iz.ravel()], axis=1) * spacing


def _resolve_files(entry, base):
    """The entry with a relative ``file`` made relative to the scene file's folder ``base``."""
    if entry.get("file") is None or base is None or Path(entry["file"]).is_absolute():
        return entry
    return dict(entry, file=str(Path(str(base)) / entry["file"]))


def build_model(scene: Mapping[str, Any], base: str | os.PathLike[str] | None = None) -> Model:
    """The Model of a validated scene dict; ``file`` keys are relative to the folder ``base``."""
    builder = _call("simulation", ModelBuilder, gravity=scene["simulation"]["gravity"])
    for i, material in enumerate(scene["materials"]):
        _call(f"materials[{i}]", builder.add_material, **material)
    for i, body in enumerate(scene["bodies"]):
        arguments = {key: value for key, value in _resolve_files(body, base).items() if key not in ("array", "path")}
        offsets = grid_offsets(body["array"])
        for copy, offset in enumerate(offsets):
            if body["array"] is not None:
                arguments["position"] = (np.asarray(body["position"]) + offset).tolist()
                arguments["name"] = f"{body['name']}_{copy}" if body["name"] is not None else None
            index = _call(f"bodies[{i}]", builder.add_body, **arguments)
            if body["path"] is not None:  # each copy moves along the path, shifted by its offset
                path = dict(body["path"], positions=(np.asarray(body["path"]["positions"]) + offset).tolist())
                _call(f"bodies[{i}].path", builder.add_path, body=index, **path)
    for i, particles in enumerate(scene["particles"]):
        offsets = grid_offsets(particles["array"])
        position = np.asarray(particles["position"])
        velocity = particles["velocity"]
        position = (position[None, :, :] + offsets[:, None, :]).reshape(-1, 3)
        if velocity is not None:
            if len(velocity) != len(particles["position"]):
                # checked here, before the array copies, so the counts match what the file says
                raise InputError(
                    f"particles[{i}].velocity",
                    f"expected {len(particles['position'])} velocities, one per position, found {len(velocity)}",
                )
            velocity = np.tile(np.asarray(velocity), (len(offsets), 1))
        _call(
            f"particles[{i}]",
            builder.add_particles,
            position=position,
            velocity=velocity,
            mass=particles["mass"],
            radius=particles["radius"],
            material=particles["material"],
        )
    for i, cloth in enumerate(scene.get("cloth", [])):
        _call(f"cloth[{i}]", builder.add_cloth, **_resolve_files(cloth, base))
    for i, obstacle in enumerate(scene["obstacles"]):
        _call(f"obstacles[{i}]", builder.add_obstacle, **_resolve_files(obstacle, base))
    for i, force in enumerate(scene.get("forces", [])):
        _call(f"forces[{i}]", builder.add_force, **force)
    return builder.finalize()
