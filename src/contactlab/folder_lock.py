"""One writer at a time for an output folder: every command's ``--out``.

Two runs into one folder at once would each write trajectory.h5, summary.json and the plots,
and the folder would hold the last finisher's files while both said they wrote them. So the
command holds a lock on the folder while it writes::

    with held("out/ball", "--out", made):
        ...                                   # write the run's files

The lock is ``LOCK_NAME`` in the folder, held with ``flock`` (POSIX): the second writer is
refused at once with an InputError naming the process that holds it. The kernel lets the lock
go when its process ends, however it ends, so a file left behind by a killed run (SIGKILL, a
crash) is stale and the next writer takes it over. The file is removed when the writer is done.
Where ``flock`` does not exist (Windows) nothing is locked.
"""

from __future__ import annotations

import contextlib
import os
import socket
import time
from collections.abc import Iterator, Sequence
from typing import IO

from .errors import InputError
from .record import remove_empty

LOCK_NAME = ".contactlab.lock"


@contextlib.contextmanager
def held(folder: str, field: str = "--out", made: Sequence[str] = ()) -> Iterator[None]:
    """Hold ``folder``'s lock (the folder exists) while the block runs; InputError naming
    ``field`` when another process holds it. On the way out (refused too) the lock file is
    removed, and then the folders of ``made`` (:func:`contactlab.record.make_folders`'s list)
    left empty."""
    try:
        import fcntl
    except ImportError:  # no flock here: nothing to hold
        fcntl = None
    path = os.path.join(folder, LOCK_NAME)
    try:
        stream = _take(path, folder, field, fcntl) if fcntl is not None else None
    except BaseException:  # refused: the folders made for this writer go again
        remove_empty(made)
        raise
    try:
        yield
    finally:
        if stream is not None:
            with contextlib.suppress(OSError):
                os.unlink(path)  # before the lock goes: a writer waiting finds a fresh file
            stream.close()
        remove_empty(made)


def _take(path: str, folder: str, field: str, fcntl) -> IO[str]:
    """The open lock file at ``path``, locked by this process."""
    for _ in range(5):
        stream = open(path, "a+", encoding="utf-8")  # held open as long as the lock
        try:
            fcntl.flock(stream, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            stream.seek(0)
            holder = stream.read().strip() or "another process"
            stream.close()
            raise InputError(
                field,
                f"{folder} is being written by another contactlab command ({holder}); "
                f"give another {field}, or run again once that one has finished",
            ) from None
        try:  # the holder may have removed the file between our open and our lock: then retry
            current = os.path.samestat(os.fstat(stream.fileno()), os.stat(path))
        except FileNotFoundError:
            current = False
        if current:
            stream.seek(0)
            stream.truncate()
            stream.write(f"process {os.getpid()} on {socket.gethostname()}, since {time.strftime('%H:%M:%S')}\n")
            stream.flush()
            return stream
        stream.close()
    raise InputError(field, f"{folder}: its lock file {LOCK_NAME} keeps being replaced; run again")
