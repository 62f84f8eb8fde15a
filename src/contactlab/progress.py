"""Progress on standard error while long work goes on (a run's steps, a video's frames, a
cluster's jobs): a tqdm bar when stderr is a terminal, and where it is not (a log file, CI, a
notebook) a plain line every PLAIN_SECONDS, so a long run still shows that it is alive without
filling a log with carriage returns.

    with progress.bar(1200, "box_pyramid (impulse)", "step", show=True) as shown:
        shown.update(1)       # the first step (it compiled the kernels)
        shown.restart()       # count again from 0, the clock started anew
        shown.update(600)     # on a terminal the bar moves; elsewhere a line at most every 5 s:
        shown.tick()          #   "box_pyramid (impulse): 600/1200 steps (50 %) after 5 s"
        shown.write("a line") # printed clear of the bar

A terminal bar appears only for work longer than BAR_DELAY and is erased when it closes, so
the summary a command prints next starts on a clean line.
"""

from __future__ import annotations

import sys
import time
from typing import IO, Any

from tqdm import tqdm

PLAIN_SECONDS = 5.0  # s between two progress lines where stderr is no terminal
BAR_DELAY = 1.0  # s: a terminal bar shows only for work that lasts longer than this


class _Progress:
    """What every kind of progress answers: ``update(n)`` (n more units done), ``restart()``
    (count from 0 again), ``tick()`` (nothing done, time passed), ``write(line)`` (a line of
    news, clear of the progress) and ``close()``; a context manager."""

    def update(self, count: int = 1) -> None:
        pass

    def restart(self) -> None:
        pass

    def tick(self) -> None:
        pass

    def close(self) -> None:
        pass

    def write(self, line: str) -> None:
        """Print ``line`` on standard error, clear of the progress (a bar is drawn again below it)."""
        print(line, file=sys.stderr, flush=True)

    def __enter__(self) -> _Progress:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


class _Bar(_Progress):
    """A tqdm bar on a terminal, erased when closed."""

    def __init__(self, total: int, description: str, unit: str, stream: IO[str]):
        self._arguments = {"total": total, "desc": description, "unit": unit, "file": stream}
        self._bar = self._new()

    def _new(self):
        return tqdm(**self._arguments, delay=BAR_DELAY, leave=False)

    def update(self, count: int = 1) -> None:
        self._bar.update(count)

    def restart(self) -> None:
        """A fresh bar in place of this one (its rate and time left count from now). Not tqdm's
        reset(): that draws the bar at once, delay or not, and a bar drawn only then is not
        erased by close() (tqdm deems it never shown), so "0/1200" stayed on the terminal with
        the command's summary printed after it."""
        self._bar.close()
        self._bar = self._new()

    def close(self) -> None:
        self._bar.close()

    def write(self, line: str) -> None:
        tqdm.write(line, file=self._arguments["file"])


class _Lines(_Progress):
    """A plain line on ``stream`` at most every PLAIN_SECONDS, the first after PLAIN_SECONDS:
    "<description>: <done>/<total> <unit>s (<share> %) after <elapsed> s"."""

    def __init__(self, total: int, description: str, unit: str, stream: IO[str]):
        self._total, self._description, self._unit, self._stream = total, description, unit, stream
        self._done = 0
        self._started = self._printed = time.monotonic()

    def update(self, count: int = 1) -> None:
        self._done += count
        self.tick()

    def write(self, line: str) -> None:
        print(line, file=self._stream, flush=True)

    def restart(self) -> None:
        self._done = 0
        self._started = self._printed = time.monotonic()  # the clock anew: the next line comes a period on

    def tick(self) -> None:
        now = time.monotonic()
        if now - self._printed < PLAIN_SECONDS:
            return
        self._printed = now
        share = f" ({100 * self._done / self._total:.0f} %)" if self._total else ""
        done = f"{self._done:,}/{self._total:,} {self._unit}s{share}"
        print(f"{self._description}: {done} after {now - self._started:.0f} s", file=self._stream, flush=True)


def bar(total: int, description: str, unit: str, show: bool, stream: IO[str] | None = None) -> _Progress:
    """Progress over ``total`` units (``unit``: "step", "frame", "job") of the work named
    ``description``, on ``stream`` (default: sys.stderr as it is now): nothing unless ``show``;
    a tqdm bar when the stream is a terminal; otherwise a plain line every PLAIN_SECONDS."""
    if not show:
        return _Progress()
    stream = sys.stderr if stream is None else stream
    terminal = getattr(stream, "isatty", None)
    return (_Bar if terminal is not None and terminal() else _Lines)(total, description, unit, stream)
