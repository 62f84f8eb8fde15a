"""Which kinds of run this machine has compiled: the record that decides whether a command's run
compiles its kernels or steps them as Python (:mod:`contactlab.first_run`).

The compiled stepping loop is specialized per kind of run (:func:`variant_of`: the method, the
integrator, the scene's shape families and the options' flags, ``loop_stages.Specialization``), and
a run of a kind that this machine has never compiled waits for Numba first: 40–60 s on 2 cores,
where the run itself may take a second. The same kernels also run as Python, their own source
executed by the interpreter (``NUMBA_DISABLE_JIT=1``), with the same numbers, bit for bit (sorts
stable, sums in index order, no BLAS: see tests/test_reruns.py). So that a
first run never waits on a compile that costs more than the run it serves, ``contactlab run`` (and
``demo``) goes through :func:`contactlab.first_run.settle` before it writes anything:

1. the run's kind is in this machine's record of compiled kinds (:func:`compiled_variants`,
   ``variants.json`` in the package's kernel cache, written after every compiled run), or the run
   steps through the methods' Python-wired path (cloth, meshes: always compiled): it compiles or
   loads as before;
2. otherwise the command starts again as Python (the same process, ``os.execv``) and times a few
   steps of the scene (:func:`contactlab.first_run.probe`); where the whole run would take less
   than half of what a compile takes here (:func:`compile_estimate`), it
   steps the run as Python and says so in one line on stderr; else it starts once more, compiled,
   and the compile happens where it repays.

``NUMBA_DISABLE_JIT`` set by the user (0 or 1) is their choice and is left alone; ``contactlab
compile`` builds the kinds up front (:mod:`contactlab.precompile`). Library calls (``simulate``) run
however their process was started: only a command can choose before Numba is set up. This module
holds the record (written by ``simulate`` after each compiled run), the kind of a run and what a
compile costs here; :mod:`contactlab.first_run` the probe and the command's choice.
"""

from __future__ import annotations

import json
import os
import statistics
import tempfile
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numba

from .compiling import PackageStampedLocator

if TYPE_CHECKING:
    from .model import Model
    from .scene import Scene

VARIANTS_FILE = "variants.json"
DEFAULT_COMPILE_SECONDS = 45.0  # a first kind on 2 cores (the demo's loop: 51–64 s; another kind 30–40 s)


def interpreted() -> bool:
    """Whether this process runs contactlab's kernels as Python (``NUMBA_DISABLE_JIT=1``)."""
    return bool(numba.config.DISABLE_JIT)


def variant_of(model: Model, method: str, options: Any, integrator: str) -> str | None:
    """The kind of compiled loop that steps ``method`` on ``model`` with these Options and
    integrator, as a short text (the same text for runs that compile the same loop); None where
    the compiled loop does not step it (the methods' Python-wired path: cloth, meshes, Python drives)."""
    from .methods.loop_stages import specialization
    from .methods.velocity_loop import applies

    if not applies(model, method, options, integrator):
        return None
    spec = specialization(model, method, options)
    flags = "".join("-" if value is None else "1" for value in spec[1:])
    families = "".join("-" if family is None else "1" for family in spec.plan.families)
    hulls = "-" if spec.plan.hull_store is None else "h"
    large = "-" if spec.plan.large is None else "g"
    drive = "-" if model.drive is None else "d"
    loop = "velocity" if method in ("impulse", "constraints") else method  # the two share one loop
    return f"{loop}/{integrator}/{families}{hulls}{large}/{flags}{drive}"


_PACKAGE = os.path.dirname(os.path.abspath(__file__))  # contactlab's folder, as stamp_package keys it
_REMEMBERED: set[str] = set()  # the kinds this process has recorded or found recorded


def _record() -> Path:
    return PackageStampedLocator.folder_of(_PACKAGE) / VARIANTS_FILE


def compiled_variants() -> dict[str, float]:
    """The kinds of run this machine has compiled for this package's sources, each with the
    seconds its first run spent compiling (0 where it was loaded, not compiled, in this package's
    cache); empty where none is recorded or the record cannot be read."""
    try:
        record = json.loads(_record().read_text())
    except (OSError, ValueError):
        return {}
    return {str(key): float(value) for key, value in record.items()} if isinstance(record, dict) else {}


def remember(variant: str | None, compile_seconds: float) -> None:
    """Record that a compiled run of kind ``variant`` ran here (``compile_seconds`` [s]: what it
    spent compiling). Written whole to a new file and moved over the old one; a record that cannot
    be written is skipped (the next run of that kind probes again, nothing worse). Once a kind is
    recorded, later runs of it in this process read nothing (200 short runs: 200 reads of the file)."""
    if variant is None or interpreted() or variant in _REMEMBERED:
        return
    known = compiled_variants()
    if variant in known and (compile_seconds <= 0.0 or known[variant] > 0.0):
        _REMEMBERED.add(variant)
        return
    known[variant] = round(float(compile_seconds), 2)
    path = _record()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile("w", dir=path.parent, delete=False, suffix=".tmp") as handle:
            json.dump(known, handle, indent=1, sort_keys=True)
        os.replace(handle.name, path)
        _REMEMBERED.add(variant)
    except OSError:
        pass


def compile_estimate() -> float:
    """What compiling a kind of run not yet compiled costs on this machine [s]: the median of the
    compiles recorded here, DEFAULT_COMPILE_SECONDS where none is."""
    spent = [seconds for seconds in compiled_variants().values() if seconds > 1.0]
    return float(statistics.median(spent)) if spent else DEFAULT_COMPILE_SECONDS


def compiling_notice(kinds: int = 1) -> str:
    """The line a run (or a command of several runs) that compiles prints as it starts to: that
    it compiles, for about how long here (:func:`compile_estimate` for each of ``kinds`` kinds of
    run), and that it happens once."""
    many = f" for {kinds} kinds of run" if kinds > 1 else ""
    return (
        f"compiling contact kernels for first use… about {kinds * compile_estimate():.0f} s on this machine{many}, "
        "once (later runs load them from the cache; 'contactlab compile' builds every kind ahead)"
    )


def uncompiled(scenes: Iterable[Scene]) -> set[str]:
    """The kinds of run among ``scenes`` (each stepped by its own method, options and integrator)
    that this machine has no record of compiling: what a command of those runs will compile. Runs
    the compiled loop does not step (cloth, meshes) are left out, and everything is where the
    kernels run as Python."""
    if interpreted():
        return set()
    known = compiled_variants()
    kinds = {variant_of(scene.model, scene.method, scene.options[scene.method], scene.integrator) for scene in scenes}
    return {kind for kind in kinds if kind is not None and kind not in known}
