"""What a run will need, estimated before it starts, against what the machine has.

``simulate`` refuses, with one sentence and before any work, a run whose estimate exceeds its
memory limit — by default ``MEMORY_SHARE`` of this machine's physical memory — instead of
running until the machine runs out (a million bodies, a 3000 × 3000 cloth, a long run recorded
every step). The estimate is the recorded trajectory (held in memory until the run ends, twice
while it is turned into arrays) plus a step's working arrays, about ``WORKING_BYTES`` per body,
particle or cloth vertex (contacts, their rows, the broad phase: about 11 KB measured on the
4000-sphere pile). ``simulate(..., memory_limit=…)`` (``--memory-limit`` on the command line)
sets another limit in bytes; ``math.inf`` none.
"""

import os

from .errors import InputError

MEMORY_SHARE = 0.5            # of the physical memory, for one run
WORKING_BYTES = 16 * 1024     # per body, particle or cloth vertex, a step's working arrays
FALLBACK_MEMORY = 8 * 2 ** 30  # where the machine does not say


def physical_memory() -> int:
    """This machine's physical memory [bytes] (FALLBACK_MEMORY where it cannot be read)."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return FALLBACK_MEMORY


def estimate(model, steps, record_every) -> dict:
    """Bytes a run of ``steps`` steps recorded every ``record_every`` will hold at most:
    ``trajectory`` (twice: the samples and their arrays), ``working`` and ``total``."""
    samples = steps // record_every + 2
    per_sample = 8 * (13 * model.body_count + 6 * model.particle_count + 8)
    trajectory = 2 * samples * per_sample
    working = WORKING_BYTES * (model.body_count + model.particle_count)
    return {"samples": samples, "trajectory": trajectory, "working": working, "total": trajectory + working}


def check(model, steps, record_every, memory_limit=None):
    """InputError, one sentence with the estimate and the limit, when the run cannot fit."""
    limit = MEMORY_SHARE * physical_memory() if memory_limit is None else memory_limit
    needed = estimate(model, steps, record_every)
    if needed["total"] <= limit:
        return needed
    dynamic = model.body_count + model.particle_count
    per_sample = needed["trajectory"] / needed["samples"]
    affordable = int((limit - needed["working"]) / per_sample) - 2        # samples that would fit
    if affordable >= 1:             # the trajectory is what does not fit: record less often
        fewer = max(record_every + 1, -(-steps // affordable))
        raise InputError("record_every", f"the run would hold {_size(needed['total'])}: {needed['samples']:,} samples "
                                         f"of {dynamic:,} bodies and particles, over its limit of {_size(limit)}; "
                                         f"record every {fewer:,} steps or more, run shorter, or raise memory_limit "
                                         f"(--memory-limit)")
    raise InputError("model", f"the run would need about {_size(needed['working'] + 3 * per_sample)} for "
                              f"{dynamic:,} bodies, particles and cloth vertices at the fewest samples, over its "
                              f"limit of {_size(limit)}; simulate fewer, or raise memory_limit (--memory-limit)")


def _size(count):
    return f"{count / 2 ** 30:.3g} GB" if count >= 2 ** 30 else f"{count / 2 ** 20:.3g} MB"
