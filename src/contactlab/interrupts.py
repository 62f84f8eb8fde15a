"""Ctrl-C and SIGTERM, between steps: a run stops cleanly, never inside compiled code.

Python's own Ctrl-C raises KeyboardInterrupt wherever the interpreter happens to be; inside a
call into Numba-compiled code that can surface as ``SystemError: CPUDispatcher(...) returned a
result with an exception set``, and SIGTERM kills the process without cleaning up at all. So
``simulate`` runs inside :func:`deferred`: a signal that arrives then is noted, and
:func:`check` raises :class:`Interrupted` at the next step or chunk boundary. The command line
installs :func:`handled` and runs the whole command deferred, so a signal also waits for the
end of the current picture, video or export frame, or file (the places that call ``check``),
and their temporary files are removed on the way out (``record.atomic_path``). Outside any
deferred block, with :func:`handled` installed, a signal raises at once.

A job running in another thread — on a Dask worker (contactlab.cluster) — has no signal of its
own to stop it: it runs inside :func:`stoppable`, and ``check`` in that thread raises
:class:`Interrupted` as soon as the job's ``asked`` function says it should stop (its task was
cancelled, its worker is closing), at the same step, frame and file boundaries.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Callable, Iterator

EXIT_CODES: dict[int, int] = {signal.SIGINT: 130, signal.SIGTERM: 143}  # 128 + the signal's number


class Interrupted(KeyboardInterrupt):
    """The run was stopped by a signal: ``signum`` (SIGINT or SIGTERM) and its ``name``;
    ``run``, set by ``simulate``, the run up to then (a contactlab.simulation.Run) or None."""

    def __init__(self, signum: int) -> None:
        self.signum = signum
        self.run = None
        self.name = signal.Signals(signum).name
        super().__init__(self.name)

    @property
    def exit_code(self) -> int:
        return EXIT_CODES.get(self.signum, 130)


_deferring = 0  # how many deferred() blocks are open (the main thread's)
_pending: int | None = None  # the signal noted while deferring


def _handler(signum, frame):
    global _pending
    if _deferring:
        _pending = signum
    else:
        raise Interrupted(signum)


def _main_thread():
    return threading.current_thread() is threading.main_thread()


@contextlib.contextmanager
def handled(restore: bool = True) -> Iterator[None]:
    """SIGINT and SIGTERM raise :class:`Interrupted` while this is open (main thread only; a
    signal the process was started ignoring, as a shell does for background jobs, stays
    ignored); the previous handlers come back at the end unless ``restore`` is False."""
    if not _main_thread():
        yield
        return
    previous = {s: signal.signal(s, _handler) for s in EXIT_CODES if signal.getsignal(s) is not signal.SIG_IGN}
    try:
        yield
    finally:
        if restore:
            for s, handler in previous.items():
                signal.signal(s, handler)


def ignore_signals() -> None:
    """Ignore SIGINT and SIGTERM from now on (a finished command, exiting)."""
    if _main_thread():
        for s in EXIT_CODES:
            signal.signal(s, signal.SIG_IGN)


@contextlib.contextmanager
def deferred() -> Iterator[None]:
    """Signals wait for :func:`check` (or the end of the block) while this is open. Installs the
    handler for SIGINT where Python's default one is in place (a library caller), and leaves a
    caller's own handlers alone."""
    global _deferring
    if not _main_thread():
        yield
        return
    installed = signal.getsignal(signal.SIGINT) is signal.default_int_handler
    if installed:
        signal.signal(signal.SIGINT, _handler)
    _deferring += 1
    try:
        yield
    finally:
        _deferring -= 1
        if installed:
            signal.signal(signal.SIGINT, signal.default_int_handler)
    if _deferring == 0:
        check()


def check() -> None:
    """Raise :class:`Interrupted` if a signal arrived while deferred (and forget it), or, in a
    thread inside :func:`stoppable`, if its job was asked to stop."""
    global _pending
    if _pending is not None:
        signum, _pending = _pending, None
        raise Interrupted(signum)
    if _job_asked_to_stop():
        raise Interrupted(signal.SIGTERM)


def pending() -> bool:
    """Whether :func:`check` would raise now, without raising: for a loop that ends its chunk of
    work early and leaves the raising to its caller's next ``check``."""
    return _pending is not None or _job_asked_to_stop()


def _job_asked_to_stop() -> bool:
    """Whether this thread runs inside :func:`stoppable` and its job was asked to stop."""
    asked = _stop_asked.get(threading.get_ident()) if _stop_asked else None
    return asked is not None and bool(asked())


_stop_asked: dict = {}  # thread ident -> a function saying whether the job in that thread should stop


@contextlib.contextmanager
def stoppable(asked: Callable[[], bool]) -> Iterator[None]:
    """While this is open, :func:`check` in this thread raises :class:`Interrupted` (as for
    SIGTERM) once ``asked()`` is true: how a job on a worker thread stops at its next step,
    frame or file when whoever started it no longer wants it (contactlab.cluster)."""
    ident = threading.get_ident()
    _stop_asked[ident] = asked
    try:
        yield
    finally:
        _stop_asked.pop(ident, None)


# ---- what an interrupted command wrote ------------------------------------------------------

_written: list[str] | None = None  # the files completed inside tracking_written(), or None


@contextlib.contextmanager
def tracking_written() -> Iterator[None]:
    """Note every file ``note_written`` reports while this is open (``written_paths``): what an
    interrupted command can truthfully say it wrote (``record.atomic_path`` reports each)."""
    global _written
    previous, _written = _written, []
    try:
        yield
    finally:
        _written = previous


def note_written(path: str, removed: bool = False) -> None:
    """``path`` was completed (or, ``removed``, taken away again), if tracking."""
    if _written is not None:
        if removed:
            if path in _written:
                _written.remove(path)
        else:
            _written.append(path)


def written_paths() -> list[str]:
    """The files completed so far inside ``tracking_written`` (empty outside it)."""
    return list(_written or ())
