"""Saying so when kernels compile, and how many threads they may use.

contactlab's kernels are compiled by Numba on first use and kept in its on-disk cache
(``cache=True``, in the ``__pycache__`` folders beside the sources, or ``NUMBA_CACHE_DIR``).
A first run on an empty cache therefore spends seconds compiling before and during its first
steps, and a later run loads the same machine code in a fraction of a second. So that the
first run does not look hung, :func:`compile_notice` prints one line on stderr as soon as
anything starts compiling, and nothing at all when everything comes from the cache::

    with compile_notice():
        run_the_steps()          # "compiling contact kernels for first use…" if it compiles

A command says it once, however many runs compile (a comparison's methods, a sweep's cells):
the command line runs inside :func:`one_notice`. A job on a Dask worker does not print it where
the command's progress bar is drawn: inside :func:`notices_to` (``contactlab.cluster``'s jobs)
the line goes to the command that submitted the job, which says it (:func:`say`).

**A cache entry is as fresh as the whole package.** Numba stamps a function's entry with its
own source file alone, so an entry of a function that calls compiled code in other files
outlives an edit to them: the stepping loop ``run_steps`` (``methods/velocity_loop.py``) compiles in
the stages of a dozen modules. A ``pip install`` of a newer contactlab into the same
environment leaves the old ``.nbi``/``.nbc`` files beside the new sources (pip removes only the
files it installed), and a checkout of another commit leaves them in ``src/``: in both, the
loop ran the old stages. Every kernel of contactlab therefore takes :func:`njit` from this
module, whose cache entries are stamped with :func:`sources_digest` of the whole package
(:class:`PackageStampedLocator`): any change to any of contactlab's sources makes every entry
stale, and the next run compiles afresh (and says so).

The most threads the kernels may use is Numba's, fixed when it starts: :func:`available_threads`
(:mod:`contactlab.threads` chooses how many of them a run takes).

**Orchestration that runs either way.** A function that only calls kernels, and slices and
joins what they return (detection: broad phase, narrow phase, assembly), costs little to run
from Python, but compiled on its own it links every kernel it calls (Numba links the machine
code of every compiled function a function calls into its own and optimizes the whole again:
2 s for detection).
:func:`in_python` gives such a function, compiled code inlines, as Python that calls the same
compiled kernels: one source, the same numbers.
"""

from __future__ import annotations

import functools
import hashlib
import os
import shutil
import sys
import threading
import types as types_module
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TextIO

import numba
from numba import njit
from numba.core import caching, event
from numba.core.registry import CPUDispatcher as Dispatcher

fcntl: Any
try:
    import fcntl
except ImportError:  # no POSIX file locks (Windows): Numba's own saving, unlocked
    fcntl = None

__all__ = [
    "NOTICE",
    "FirstCompile",
    "expect",
    "notices_to",
    "one_notice",
    "say",
    "PackageStampedLocator",
    "available_threads",
    "kernel_cache_root",
    "compile_notice",
    "njit",
    "in_python",
    "inlined",
    "sources_digest",
]

NOTICE = "compiling contact kernels for first use…"  # how that line starts (simulate adds how long, once)

_sending = threading.local()
"""``send``: where the notice goes instead of standard error in this thread (:func:`notices_to`; a
worker's job compiles in its own thread, and a worker may run several jobs at once)"""
_commands: list[list] = []
"""one entry per :func:`one_notice` open, [whether the command has said the notice, the notice it
says in place of a run's (:func:`expect`) or None]"""


def say(message: str = NOTICE, write: Callable[[str], None] | None = None) -> None:
    """Give the compile notice ``message``: to the sender of :func:`notices_to` where one is set;
    else once at most within :func:`one_notice` (a command), with ``write`` (default: one line on
    ``sys.stderr``), as often as asked outside it."""
    send = getattr(_sending, "send", None)
    if send is not None:
        send(message)
        return
    if _commands:
        command = _commands[-1]
        if command[0]:
            return
        command[0] = True
        message = command[1] or message
    if write is None:
        print(message, file=sys.stderr, flush=True)
    else:
        write(message)


@contextmanager
def one_notice() -> Iterator[None]:
    """Within the block (a command), the compile notice is said once at most, however many runs
    compile in this process or on its cluster's workers (:func:`say`)."""
    _commands.append([False, None])
    try:
        yield
    finally:
        _commands.pop()


def expect(message: str) -> None:
    """Within :func:`one_notice` (a command), the notice said at the command's first compile, if
    one comes, in place of the compiling run's own: a command of several kinds of run says the
    wait of all of them. Outside a command, nothing."""
    if _commands:
        _commands[-1][1] = message


@contextmanager
def notices_to(send: Callable[[str], None]) -> Iterator[None]:
    """Within the block (in this thread), the compile notice is handed to ``send(message)`` instead
    of being printed: a job on a Dask worker sends it to the command that submitted the job
    (contactlab.cluster)."""
    previous = getattr(_sending, "send", None)
    _sending.send = send
    try:
        yield
    finally:
        _sending.send = previous


def available_threads() -> int:
    """The most threads the compiled kernels can use in this process (NUMBA_NUM_THREADS)."""
    return int(numba.config.NUMBA_NUM_THREADS)


class FirstCompile(event.Listener):
    """A Numba event listener that says ``message`` (a line, or a function giving it, called then;
    :func:`say`) at the first compilation it sees, on ``stream`` (default: ``sys.stderr`` as it is then).

    ``said`` tells whether it has said it. Numba sends "numba:compile" only for a real
    compilation (a function it has no cached machine code for), never for a cache load."""

    def __init__(self, message: str | Callable[[], str] = NOTICE, stream: TextIO | None = None) -> None:
        self.message = message
        self.stream = stream
        self.said = False

    def on_start(self, event: event.Event) -> None:
        if not self.said:
            self.said = True
            stream, message = self.stream, self.message if isinstance(self.message, str) else self.message()
            say(message, None if stream is None else lambda line: print(line, file=stream, flush=True))

    def on_end(self, event: event.Event) -> None:
        pass


@contextmanager
def compile_notice(listener: FirstCompile | None = None) -> Iterator[FirstCompile]:
    """Within the block, the first Numba compilation says ``NOTICE`` (:func:`say`: one line on
    ``sys.stderr``, or to the command a worker's job came from); yields the FirstCompile
    listener. Hand the same ``listener`` to several blocks (one run's set-up and its steps) for
    one line at most over all of them."""
    listener = FirstCompile() if listener is None else listener
    with event.install_listener("numba:compile", listener):
        yield listener


def sources_digest(root: str | os.PathLike[str]) -> str:
    """SHA-256 (hex) of every ``.py`` file under the folder ``root``: their paths relative to it
    and their bytes, in sorted order. contactlab's 1.3 MB of sources hash in a few ms."""
    base = Path(root)
    digest = hashlib.sha256()
    for path in sorted(base.rglob("*.py")):
        digest.update(path.relative_to(base).as_posix().encode() + b"\0")
        digest.update(path.read_bytes() + b"\0")
    return digest.hexdigest()


# Numba's cache machinery: ``CacheImpl`` in recent Numba, ``_CacheImpl`` in older releases
_CACHE_IMPL: Any = getattr(caching, "CacheImpl", None) or caching._CacheImpl


def kernel_cache_root() -> Path:
    """The folder under which contactlab's compiled kernels are kept, one subfolder a package
    content (:class:`PackageStampedLocator`): ``NUMBA_CACHE_DIR`` where it is set, else the user's
    cache (``$XDG_CACHE_HOME``, by default ``~/.cache``), ``contactlab/kernels``."""
    if numba.config.CACHE_DIR:
        return Path(numba.config.CACHE_DIR)
    home = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(home) / "contactlab" / "kernels"


KEPT_FOLDERS = 8  # a package's kernel folders kept (the most recently used), one a content


def prune_kernel_folders(package: str, keep: int) -> None:
    """Remove ``package``'s kernel folders under ``kernel_cache_root()`` beyond the ``keep`` most
    recently modified (a folder is modified whenever a kernel is saved into it). Nothing is
    raised: a folder that cannot be removed stays."""
    try:
        folders = sorted(
            (folder for folder in kernel_cache_root().glob(f"{package}-*-numba*") if folder.is_dir()),
            key=lambda folder: folder.stat().st_mtime,
            reverse=True,
        )
    except OSError:
        return
    for folder in folders[keep:]:
        shutil.rmtree(folder, ignore_errors=True)


class PackageStampedLocator(caching._CacheLocator):
    """Where a compiled function of a package in ``ROOTS`` is kept, found by the package's
    content rather than by where it is installed: ``kernel_cache_root()/<package>-<digest>-numba<version>/``
    and the source file's folder within the package (a wheel installed in two virtual
    environments, a Dask worker's and a CI clone's copies of one commit share one cache), with the
    digest of the whole package (:func:`sources_digest`) also the source stamp that Numba checks
    before it loads an entry. Where that folder cannot be written, Numba's own location (beside the
    source, or its user-wide cache) with the same stamp. Functions of other files are left to
    Numba's locators (``from_function`` returns None for them)."""

    ROOTS: dict[str, str | None] = {}  # package folder → its digest, hashed at its first function

    def __init__(self, path: str, stamp: tuple[str, str], py_file: str, disambiguator: str) -> None:
        self._path = path
        self._stamp = stamp
        self._py_file = py_file  # Numba names it in its warning that a function cannot be cached
        self._disambiguator = disambiguator

    def get_cache_path(self) -> str:
        return self._path

    def get_source_stamp(self) -> tuple[str, str]:
        return self._stamp

    def get_disambiguator(self) -> str:
        return self._disambiguator

    @classmethod
    def stamp_package(cls, root: str | os.PathLike[str]) -> None:
        """Keep the cache entries of every function compiled from now on from a file under
        ``root`` by, and stamped with, the digest of all the sources under it."""
        cls.ROOTS.setdefault(os.path.abspath(root), None)
        if cls not in _CACHE_IMPL._locator_classes:
            _CACHE_IMPL._locator_classes.insert(0, cls)

    @classmethod
    def folder_of(cls, root: str) -> Path:
        """The cache folder of the package at ``root`` (stamped): one a content and Numba version.
        The first time it is asked for in a process, the package's folders beyond the KEPT_FOLDERS
        most recently used are removed (each edit of a source makes a new one: a developer's day
        would otherwise leave hundreds)."""
        if cls.ROOTS[root] is None:
            cls.ROOTS[root] = sources_digest(root)
            prune_kernel_folders(os.path.basename(root), keep=KEPT_FOLDERS)
        name = f"{os.path.basename(root)}-{str(cls.ROOTS[root])[:20]}-numba{numba.__version__}"
        return kernel_cache_root() / name

    @classmethod
    def from_function(cls, py_func: Any, py_file: str) -> PackageStampedLocator | None:
        path = os.path.abspath(py_file)
        root = next((r for r in cls.ROOTS if path.startswith(r + os.sep)), None)
        if root is None:
            return None
        folder = cls.folder_of(root)
        stamp = ("package sources", str(cls.ROOTS[root]))
        disambiguator = str(py_func.__code__.co_firstlineno)
        located = cls(str(folder / os.path.relpath(os.path.dirname(path), root)), stamp, py_file, disambiguator)
        try:
            located.ensure_cache_path()
            return located
        except OSError:  # not writable: wherever Numba's own locators put it
            pass
        for other in _CACHE_IMPL._locator_classes:
            inner = None if other is cls else other.from_function(py_func, py_file)
            if inner is not None:
                return cls(inner.get_cache_path(), stamp, py_file, inner.get_disambiguator())
        return None


PackageStampedLocator.stamp_package(Path(__file__).parent)

if numba.config.DISABLE_JIT:  # the kernels as Python: their integer hashes wrap, as compiled, unwarned
    warnings.filterwarnings("ignore", "overflow encountered in scalar", RuntimeWarning, r"contactlab\.")


@contextmanager
def _index_locked(index_path: str) -> Iterator[None]:
    """Hold an exclusive lock on ``index_path`` + ".lock" across processes (``fcntl``; where
    there is none, no lock)."""
    if fcntl is None:
        yield
        return
    with open(index_path + ".lock", "a") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


_UNLOCKED_SAVE = caching.IndexDataCacheFile.save


def _save_locked(self: Any, key: Any, data: Any) -> None:
    """Numba's ``IndexDataCacheFile.save`` under a lock of the function's index file.

    Numba reads a function's index, picks a data file name for a new signature (the first
    number the index has not used), writes the index, then the data, with no lock between
    processes. Two processes (the suite's two workers) that compile one function for two
    signatures at once can pick the same number: the index then names one signature and the
    data file holds the other's machine code, and the next process that loads it crashes (a
    segmentation fault seen in the suite, on ``loop_stages.solve``). Under the lock a process
    reads the index only after the last one wrote its index and data."""
    with _index_locked(self._index_path):
        _UNLOCKED_SAVE(self, key, data)


caching.IndexDataCacheFile.save = _save_locked


def inlined(kernel: Any) -> Any:
    """``kernel``'s Python function compiled anew with ``inline="always"``: inlined into each
    compiled caller, while ``kernel`` itself stays a callable kernel for every other caller. Under
    ``NUMBA_DISABLE_JIT=1`` (``njit`` gives back the Python function) the function itself."""
    return njit(inline="always")(getattr(kernel, "py_func", kernel))


def in_python(kernel: Any, **replacing: Any) -> Any:
    """``kernel`` (a compiled dispatcher, or a Python function that compiled code calls through an
    ``overload``) as a Python function of the same code, in which every function it inlines
    (``inline="always"``) or calls as Python runs as Python too, the same way down, and every
    other kernel it calls runs compiled: for orchestration that only calls kernels and slices
    what they return, whose compiled form would link all of them (2 s for detection).

    ``replacing``: names of ``kernel``'s own globals given other values in this twin (not in the
    functions it calls), a stage that only Python can run (``projection.step``'s detection, which
    sees meshes and cloth); a twin with replacements is made anew each call, not kept. Under
    ``NUMBA_DISABLE_JIT=1``, where every kernel is Python already, ``kernel`` itself, or its twin
    with the replacements alone."""
    interpreted = numba.config.DISABLE_JIT
    if not replacing and (interpreted or kernel in _IN_PYTHON):
        return kernel if interpreted else _IN_PYTHON[kernel]
    function = getattr(kernel, "py_func", kernel)
    names = dict(function.__globals__)
    twin = types_module.FunctionType(
        function.__code__, names, function.__name__, function.__defaults__, function.__closure__
    )
    functools.update_wrapper(twin, function)  # its name, docstring and module; __wrapped__ the original
    twin.__kwdefaults__ = function.__kwdefaults__
    if not replacing:
        _IN_PYTHON[kernel] = twin
    for name in () if interpreted else function.__code__.co_names:
        value = names.get(name)
        inlined = isinstance(value, Dispatcher) and value.targetoptions.get("inline") == "always"
        if name not in replacing and (
            inlined or (isinstance(value, types_module.FunctionType) and value.__module__.startswith(__package__))
        ):
            names[name] = in_python(value)
    names.update(replacing)
    return twin


_IN_PYTHON: dict[Any, Any] = {}
