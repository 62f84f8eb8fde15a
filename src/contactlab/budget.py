"""What a run will need, estimated before it starts, against what the machine has.

``simulate`` refuses, with one sentence and before any work, a run whose estimate exceeds its
memory limit — by default ``MEMORY_SHARE`` of this machine's physical memory — instead of
running until the machine runs out (a million bodies, a 3000 × 3000 cloth, a long run recorded
every step). The estimate is the recorded trajectory (held in memory until the run ends, twice
while it is turned into arrays — or, for a run that streams it to a file, two chunks of it,
``2 × store.CHUNK_BYTES``) plus a step's working arrays, about ``WORKING_BYTES`` per body,
particle or cloth vertex (contacts, their rows, the broad phase: about 11 KB measured on the
4000-sphere pile). ``simulate(..., memory_limit=…)`` (``--memory-limit`` on the command line)
sets another limit in bytes; ``math.inf`` none. A streamed trajectory must also fit on its
disk: a run whose file would outgrow the free space there is refused the same way. What the
refusal advises depends on what the caller offers (:class:`Remedies`): ``simulate``'s own
keywords and options by default, a study's settings for a sweep's cells.
"""

from __future__ import annotations

import os
import shutil
from typing import TYPE_CHECKING, NamedTuple

from . import record, store
from .errors import InputError

if TYPE_CHECKING:
    from .model import Model


MEMORY_SHARE = 0.5  # of the physical memory, for one run
WORKING_BYTES = 16 * 1024  # per body, particle or cloth vertex, a step's working arrays
FALLBACK_MEMORY = 8 * 2**30  # where the machine does not say


class Remedies(NamedTuple):
    """The advice closing a refusal, by what does not fit: ``disk`` (a streamed trajectory's file),
    ``memory`` (the samples held in memory) and ``model`` (a step's working arrays alone). In
    ``disk`` and ``memory``, ``{fewer}`` stands for the smallest record_every that would fit."""

    disk: str
    memory: str
    model: str


SIMULATE = Remedies(
    disk="record every {fewer:,} steps or more, or run shorter",
    memory="record every {fewer:,} steps or more, run shorter, stream the trajectory to a file (trajectory=…), "
    "or raise memory_limit (--memory-limit)",
    model="simulate fewer, or raise memory_limit (--memory-limit)",
)
"""What ``simulate`` (and ``contactlab run``) offer."""


def physical_memory() -> int:
    """This machine's physical memory [bytes] (FALLBACK_MEMORY where it cannot be read)."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return FALLBACK_MEMORY


def estimate(model: Model, steps: int, record_every: int, streamed: bool = False) -> dict[str, int]:
    """Bytes a run of ``steps`` steps recorded every ``record_every`` will hold at most:
    ``file`` (the trajectory's size), ``trajectory`` (in memory: twice the file, the samples and
    their arrays; two chunks when ``streamed``), ``working`` and ``total``."""
    samples = steps // record_every + 2
    per_sample = record.sample_bytes(model)
    file = samples * per_sample
    trajectory = min(2 * file, 2 * max(store.CHUNK_BYTES, per_sample)) if streamed else 2 * file
    working = WORKING_BYTES * (model.body_count + model.particle_count)
    return {
        "samples": samples,
        "per_sample": per_sample,
        "file": file,
        "trajectory": trajectory,
        "working": working,
        "total": trajectory + working,
    }


def require(
    model: Model,
    steps: int,
    record_every: int,
    memory_limit: float | None = None,
    trajectory: str | os.PathLike[str] | None = None,
    *,
    streamed: bool | None = None,
    remedies: Remedies = SIMULATE,
) -> dict[str, int]:
    """InputError, one sentence with the estimate, the limit and ``remedies``' advice, when the
    run cannot fit: in memory, and for a run streaming to the file ``trajectory``, on that
    file's disk. ``streamed``: whether the samples go to a file (default: when ``trajectory``
    is given); True without a ``trajectory`` checks the memory of a streamed run only."""
    streamed = trajectory is not None if streamed is None else streamed
    limit = MEMORY_SHARE * physical_memory() if memory_limit is None else memory_limit
    needed = estimate(model, steps, record_every, streamed=streamed)
    dynamic = model.body_count + model.particle_count
    per_sample = needed["per_sample"]
    if trajectory is not None:
        free = _free_disk(trajectory)
        if free is not None and needed["file"] > free:
            fewer = max(record_every + 1, -(-steps // max(1, free // per_sample - 2)))
            raise InputError(
                "record_every",
                f"the trajectory would take {_size(needed['file'])}: "
                f"{needed['samples']:,} samples of {dynamic:,} bodies and particles, "
                f"more than the {_size(free)} free on the disk of {trajectory}; " + remedies.disk.format(fewer=fewer),
            )
    if needed["total"] <= limit:
        return needed
    affordable = int((limit - needed["working"]) / (2 * per_sample)) - 2  # samples that would fit
    if not streamed and affordable >= 1:  # the trajectory is what does not fit: record less often
        fewer = max(record_every + 1, -(-steps // affordable))
        raise InputError(
            "record_every",
            f"the run would hold {_size(needed['total'])}: {needed['samples']:,} samples "
            f"of {dynamic:,} bodies and particles, over its limit of {_size(limit)}; "
            + remedies.memory.format(fewer=fewer),
        )
    raise InputError(
        "model",
        f"the run would need about {_size(needed['working'] + 6 * per_sample)} for "
        f"{dynamic:,} bodies, particles and cloth vertices at the fewest samples, over its "
        f"limit of {_size(limit)}; " + remedies.model,
    )


def _free_disk(path):
    """Bytes free on the disk that holds ``path``'s folder (None where it cannot be told)."""
    try:
        return shutil.disk_usage(os.path.dirname(os.path.abspath(path))).free
    except OSError:
        return None


def _size(count):
    return f"{count / 2**30:.3g} GB" if count >= 2**30 else f"{count / 2**20:.3g} MB"
