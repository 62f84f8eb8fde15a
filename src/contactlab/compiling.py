"""Saying so when kernels compile.

contactlab's kernels are compiled by Numba on first use and kept in its on-disk cache
(``cache=True``, in the ``__pycache__`` folders beside the sources, or ``NUMBA_CACHE_DIR``).
A first run on an empty cache therefore spends seconds compiling before and during its first
steps, and a later run loads the same machine code in a fraction of a second. So that the
first run does not look hung, :func:`compile_notice` prints one line on stderr as soon as
anything starts compiling, and nothing at all when everything comes from the cache::

    with compile_notice():
        run_the_steps()          # "compiling contact kernels for first use…" if it compiles
"""

from __future__ import annotations

import sys
from collections.abc import Iterator
from contextlib import contextmanager
from typing import TextIO

from numba.core import event

NOTICE = "compiling contact kernels for first use… (once: later runs load them from Numba's cache)"


class FirstCompile(event.Listener):
    """A Numba event listener that prints ``message`` at the first compilation it sees.

    ``said`` tells whether it has printed. Numba sends "numba:compile" only for a real
    compilation (a function it has no cached machine code for), never for a cache load."""

    def __init__(self, message: str = NOTICE, stream: TextIO | None = None) -> None:
        self.message = message
        self.stream = stream
        self.said = False

    def on_start(self, event: event.Event) -> None:
        if not self.said:
            self.said = True
            stream = self.stream if self.stream is not None else sys.stderr
            print(self.message, file=stream, flush=True)

    def on_end(self, event: event.Event) -> None:
        pass


@contextmanager
def compile_notice(listener: FirstCompile | None = None) -> Iterator[FirstCompile]:
    """Within the block, the first Numba compilation prints ``NOTICE`` as one line on
    ``sys.stderr``; yields the FirstCompile listener. Hand the same ``listener`` to several
    blocks (one run's set-up and its steps) for one line at most over all of them."""
    listener = FirstCompile() if listener is None else listener
    with event.install_listener("numba:compile", listener):
        yield listener
