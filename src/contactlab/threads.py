"""How many threads the compiled kernels use, and choosing it while a run goes.

Only one kind of loop in contactlab runs on several threads: a Gauss-Seidel sweep over a
thousand contacts or more, split into slabs that share no body (``methods.sequential``;
``lcp.pgs.projected_sweeps`` likewise). The split is fixed by the contacts, not by the thread
count, so a run gives the same numbers, bit for bit, on one thread as on many: the thread count
is a matter of speed only, and can change at any step.

Whether the threads pay depends on the machine *now*. A sweep ends at a barrier, and a step
makes up to a hundred sweeps; on an idle 2-core machine two threads step the 1000-sphere pile
1.3× as fast as one, but with another process keeping one core busy the second thread is
descheduled at every barrier and two threads run 2–3× *slower* than one (measured 20–31 against
66–68 steps/s). So the default, ``threads="auto"``, measures: :class:`ThreadChooser` times a
few steps on all the threads and a few on one, keeps the faster, and checks again later
(sooner when the verdict changes), so a run follows the load of the machine it runs on.
A run of the compiled loop with no parallel sweep compiled in (a small scene) makes no trials:
:meth:`ThreadChooser.nothing_parallel`.

Set the count with ``simulate(..., threads=N)``, ``contactlab run --threads N``, or for every
run of the process with :func:`set_threads`. The most threads there can be is fixed when
Numba starts: ``NUMBA_NUM_THREADS`` (default: the number of cores).
"""

from __future__ import annotations

import os
from typing import Any

import numba

from .compiling import available_threads
from .errors import InputError

# OpenMP's workers (Numba's default threading layer where GNU OpenMP is found) spin for about
# 300 000 rounds, a millisecond, after each parallel loop before they sleep. A sweep ends at a
# barrier every ~0.1 ms, so on a busy machine the spinning worker and the main thread take
# turns on one core: a 1000-sphere pile step took 0.7–2.3 s on two threads instead of 30 ms on
# one. 3 000 rounds (~10 µs) keep the idle-machine gain (87 against 90 steps/s) and bound the
# loss on a busy one (28–31 instead of 1.4–4.4 steps/s), which ThreadChooser then avoids.
# Read by OpenMP when Numba first starts its threads; a value the user set is kept.
if "OMP_WAIT_POLICY" not in os.environ:
    os.environ.setdefault("GOMP_SPINCOUNT", "3000")

AUTO = "auto"
_default: int | str = AUTO  # what ``threads=None`` means: set_threads changes it


def check_threads(threads: int | str | None, field: str = "threads") -> int | str:
    """``threads`` as given to ``simulate`` or ``--threads``: "auto", or a whole number from 1 to
    ``available_threads()`` (None: the process default, see :func:`set_threads`). Returns
    "auto" or an int; raises InputError naming ``field`` otherwise."""
    if threads is None:
        return _default
    if isinstance(threads, str):
        text = threads.strip().lower()
        if text == AUTO:
            return AUTO
        if not text.isdigit():
            raise InputError(field, f"expected 'auto' or a whole number of threads ≥ 1, found {threads!r}")
        threads = int(text)
    if isinstance(threads, bool) or not isinstance(threads, int) or threads < 1:
        raise InputError(field, f"expected 'auto' or a whole number of threads ≥ 1, found {threads!r}")
    most = available_threads()
    if threads > most:
        raise InputError(
            field,
            f"{threads} threads asked for, but this process has at most {most}; "
            f"start it with NUMBA_NUM_THREADS={threads} to allow more",
        )
    return threads


def set_threads(threads: int | str | None, field: str = "threads") -> None:
    """Make ``threads`` ("auto" or a whole number, see :func:`check_threads`; None: "auto") the
    default of every later run in this process that does not name its own."""
    global _default
    _default = AUTO if threads is None else check_threads(threads, field)


class ThreadChooser:
    """Sets the thread count step by step: fixed, or (``"auto"``) whichever steps faster now.

    Used as a context manager around the stepping loop, which puts the process's count back
    at the end. ``before_step()`` before each step sets the count for it; ``after_step(seconds)`` reports
    how long the step took (stepping only: no recording, no compiling). In "auto" mode a trial
    runs ``trial_steps`` steps on one thread, then as many on every thread; the count with the
    shorter median step wins and is kept for ``hold_steps`` steps. A step on every thread that
    takes ``give_up`` times the one-thread median or more ends the trial at once (one thread
    wins): on a busy machine such steps cost whole seconds. A verdict that stays the same
    doubles the hold (up to ``longest_hold``), one that changes sets it back. Where every
    trial step is shorter than ``too_short_to_matter`` [s] (a scene too small for any parallel
    loop) the hold is at its longest. A verdict holds only while the steps cost what they cost
    in its trial: a held step (or chunk of steps, per step) ``retry_at`` times as long as the
    winner's median, or that fraction of it, starts a new trial at once — a pile timed in the
    air, where both counts step alike, is timed again when it lands, instead of keeping a coin
    toss for the whole hold; the compiled loop reports held steps in chunks of at most
    ``held_chunk`` (``steps_at_this_count``), so the change is seen within that many steps.
    ``counts`` tallies the steps run at each count.
    """

    def __init__(
        self,
        threads: int | str | None = AUTO,
        trial_steps: int = 6,
        hold_steps: int = 200,
        longest_hold: int = 3200,
        give_up: float = 1.5,
        too_short_to_matter: float = 2e-4,
        retry_at: float = 2.0,
        held_chunk: int = 64,
    ) -> None:
        self.mode = check_threads(threads)
        self.most = available_threads()
        self.trial_steps = trial_steps
        self.shortest_hold = hold_steps
        self.hold = hold_steps
        self.longest_hold = longest_hold
        self.give_up = give_up
        self.too_short = too_short_to_matter
        self.retry_at = retry_at
        self.held_chunk = held_chunk
        self._step_seconds = 0.0  # the verdict's median step in its trial [s]
        self.counts: dict[int, int] = {}
        self._plan: list[int] = []  # thread counts of the steps to come (a trial), in order
        self._timed: dict[int, list[float]] = {}  # thread count -> step times of the running trial
        self._held = 0  # steps left at the current verdict
        self._current: int = self.most if self.mode == AUTO else self.mode  # type: ignore[assignment]  # an int
        self._verdict = None
        self._saved = numba.get_num_threads()
        self._auto = self.mode == AUTO and self.most > 1  # trials to run, verdicts to hold
        if self._auto:
            self._start_trial()

    def nothing_parallel(self) -> None:
        """Tell the chooser the run has no parallel loop (the compiled loop without one: see
        ``loop_stages.specialization``, its ``parallel``): in "auto" mode it then makes no trials,
        which would time the same code on both counts, and runs every step on one thread; a fixed
        count is kept."""
        if self.mode == AUTO:
            self._auto = False
            self._plan = []
            self._current = 1

    def _start_trial(self):
        self._plan = [1] * self.trial_steps + [self.most] * self.trial_steps
        self._timed = {self.most: [], 1: []}

    def before_step(self, count: int = 1) -> None:
        """Set the thread count for the next step (or the next ``count`` steps, at most
        ``steps_at_this_count()``)."""
        if self._plan:
            self._current = self._plan[0]
        numba.set_num_threads(self._current)
        self.counts[self._current] = self.counts.get(self._current, 0) + count

    def steps_at_this_count(self) -> int | None:
        """How many steps may run before the next report is due: 1 during a trial, the rest of
        the hold in "auto" mode (at most ``held_chunk``), else any number (None)."""
        if self._plan:
            return 1
        if self._auto:  # in chunks of at most held_chunk: a change of cost is seen within them
            return max(1, min(self._held, self.held_chunk))
        return None

    def after_steps(self, count: int, seconds: float) -> None:
        """Report ``count`` steps just made in ``seconds`` [s] of stepping (one during a trial)."""
        if self._plan or count == 1:
            self.after_step(seconds / count)
            return
        if self._auto:
            self._hold_for(count, seconds / count)

    def after_step(self, seconds: float) -> None:
        """Report the step just made: ``seconds`` [s] of stepping."""
        if self._plan:
            count = self._plan.pop(0)
            self._timed[count].append(seconds)
            if count == self.most and seconds >= self.give_up * _median(self._timed[1]):
                self._timed[count] = [seconds]  # hopeless: stop the trial here
                self._plan = []
            if not self._plan:
                self._decide()
        elif self._auto:
            self._hold_for(1, seconds)

    def _hold_for(self, count, step_seconds):
        """``count`` held steps made, ``step_seconds`` [s] each: a new trial once the hold is
        over, or at once where the steps no longer cost what they cost in the trial."""
        self._held -= count
        ratio = step_seconds / self._step_seconds if self._step_seconds > 0.0 else 1.0
        if self._held <= 0 or not 1.0 / self.retry_at < ratio < self.retry_at:
            self._start_trial()

    def _decide(self):
        many, one = _median(self._timed[self.most]), _median(self._timed[1])
        verdict = self.most if many < one else 1
        if max(many, one) < self.too_short:
            self.hold = self.longest_hold
        elif verdict == self._verdict:
            self.hold = min(self.longest_hold, 2 * self.hold)
        else:
            self.hold = self.shortest_hold
        self._verdict = self._current = verdict
        self._held = self.hold
        self._step_seconds = min(many, one)

    def __enter__(self):
        return self

    def __exit__(self, *exception):
        """Put back the thread count the process had before the run."""
        numba.set_num_threads(self._saved)

    def summary(self) -> dict[str, Any]:
        """What the run used: {"setting": "auto" or N, "available": N, "steps_at": {count: steps}}."""
        return {
            "setting": self.mode,
            "available": self.most,
            "steps_at": {str(count): steps for count, steps in sorted(self.counts.items())},
        }


def _median(values):
    """The middle of ``values`` (the upper one of the middle two for an even count)."""
    return sorted(values)[len(values) // 2]
