"""``contactlab compile``: every kind of run compiled up front, in parallel processes.

A run of a kind this machine has not compiled (:func:`contactlab.kernel_variants.variant_of`) either
steps as Python, where that is quicker than compiling, or waits for Numba first (30–60 s a kind on
2 cores). Compiling the kinds a user will run before they are needed — after an install, on each
machine of a Dask cluster, in a CI image — takes that wait out of every later command, and lets a
long first run step compiled from its first step. Each kind compiles in a worker process of its own
(a short run of two steps of a scene that needs it), one a core, and is recorded as compiled; a kind
compiled already is skipped. The cache is the package's (``contactlab.compiling``): one per content
of the package, shared by every environment on the machine that installs the same sources.
"""

from __future__ import annotations

import multiprocessing
import os
import sys
import time
from collections.abc import Sequence
from typing import Any, NamedTuple

from . import interrupts, kernel_variants
from .errors import InputError
from .first_run import CHOICE
from .progress import bar

WAIT_SECONDS = 0.25  # how often the parent looks for a signal while the workers compile


class KindToCompile(NamedTuple):
    """One kind of run to compile: a scene (a built-in name or a file) and a method."""

    scene: str
    method: str
    kind: str  # kernel_variants.variant_of, or "scene/method" where the Python-wired path steps it


class Compiled(NamedTuple):
    """What ``compile_kinds`` did: the kinds compiled now, those compiled already, the runs a method
    refuses (their scene and method, and why), and the wall time [s]."""

    compiled: list[KindToCompile]
    already: list[KindToCompile]
    refused: list[tuple[str, str, str]]
    seconds: float


def jobs_for(scenes: Sequence[str], methods: Sequence[str]) -> tuple[list[KindToCompile], list[tuple[str, str, str]]]:
    """The kinds of run of these scenes under these methods, one KindToCompile a kind (the first scene that
    needs it), and the (scene, method, why) a method refuses. Raises InputError for a scene that
    cannot be loaded."""
    from .methods import get, make_options
    from .scene import load_scene

    jobs: dict[str, KindToCompile] = {}
    refused = []
    for name in scenes:
        scene = load_scene(name)
        for method in methods:
            try:
                options = make_options(get(method), scene.method_options.get(method, {}), f"method.{method}")
            except InputError as error:
                refused.append((name, method, str(error)))
                continue
            kind = kernel_variants.variant_of(scene.model, method, options, scene.integrator) or f"{name}/{method}"
            jobs.setdefault(kind, KindToCompile(name, method, kind))
    return list(jobs.values()), refused


def _compile(job: KindToCompile) -> tuple[KindToCompile, str | None]:
    """In a worker process: two steps of the job's scene under its method, compiled, which records
    the kind (``simulation`` does, after a compiled run). (job, None), or (job, why) where the run
    was refused."""
    from .errors import SimulationDiverged
    from .scene import load_scene
    from .simulation import simulate

    scene = load_scene(job.scene)
    options = scene.method_options.get(job.method, {})  # the table, built into Options by simulate
    try:
        simulate(scene.model, job.method, scene.dt, 2 * scene.dt, options, scene.integrator)
    except (InputError, SimulationDiverged) as error:
        return job, str(error)
    return job, None


def compile_kinds(
    scenes: Sequence[str], methods: Sequence[str], workers: int | None = None, progress: bool = False
) -> Compiled:
    """Compile every kind of run of ``scenes`` under ``methods`` not yet compiled on this machine,
    ``workers`` processes at once (None, or more than ``cluster.most_workers()``: that many, one a
    core and a half-gigabyte of free memory), with ``progress`` on stderr. Ctrl-C or
    SIGTERM stops the workers at once (Interrupted); what they finished stays compiled."""
    from .cluster import most_workers

    if kernel_variants.interpreted():
        raise InputError("NUMBA_DISABLE_JIT", "is set: nothing compiles; unset it to compile the kernels")
    started = time.perf_counter()
    jobs, refused = jobs_for(scenes, methods)
    known = kernel_variants.compiled_variants()
    already = [job for job in jobs if job.kind in known]
    todo = [job for job in jobs if job.kind not in known]
    compiled: list[KindToCompile] = []
    if todo:
        count = min(workers or most_workers(), most_workers(), len(todo))  # more would only take turns
        if progress:
            estimate = kernel_variants.compile_estimate() * len(todo) / count
            print(
                f"compiling {len(todo)} kinds of run in {count} processes (about {estimate:.0f} s; "
                f"{len(already)} compiled already)",
                file=sys.stderr,
                flush=True,
            )
        compiled, more_refused = _in_workers(todo, count, progress)
        refused += more_refused
    return Compiled(compiled, already, refused, time.perf_counter() - started)


def _in_workers(
    todo: list[KindToCompile], count: int, progress: bool
) -> tuple[list[KindToCompile], list[tuple[str, str, str]]]:
    """Run ``_compile`` for each job on ``count`` fresh processes; none outlives the call."""
    os.environ[CHOICE] = "compiled"  # the workers compile (they inherit it)
    compiled, refused = [], []
    pool: Any = multiprocessing.get_context("spawn").Pool(count)
    try:
        results = pool.imap_unordered(_compile, todo)
        with bar(len(todo), "compiling", "kind", progress) as shown:
            while len(compiled) + len(refused) < len(todo):
                interrupts.check()  # a signal stops the workers within WAIT_SECONDS
                try:
                    job, why = results.next(timeout=WAIT_SECONDS)
                except multiprocessing.TimeoutError:
                    shown.tick()
                    continue
                if why is None:
                    compiled.append(job)
                else:
                    refused.append((job.scene, job.method, why))
                shown.update(1)
        pool.close()
    finally:
        pool.terminate()
        pool.join()
    return compiled, refused
