"""Work spread over processes and machines, on Dask (``dask.distributed``).

Every study that runs many independent jobs — the cells of a sweep (``contactlab.sweep``), the
problems × solvers of an FCLIB benchmark (``contactlab.fclib_bench``) — goes through this one
path:

    with connect(scheduler=None) as client:          # a local cluster, or an existing one
        for key, result in run_tasks(client, function, jobs):   # as they finish
            ...

:func:`connect` starts a ``distributed.LocalCluster`` on 127.0.0.1 — one worker process per
idle core, one thread each, since a contact solve is single-threaded compiled code and processes
keep one job's memory and crashes away from the others — or connects to the scheduler at an
address (``tcp://HOST:PORT``: started with ``dask scheduler`` and ``dask worker`` on other
machines, or by dask-jobqueue on a batch system; docs/sweep.md). :func:`run_tasks` submits
one task per job and yields results as they complete. A job runs where Dask puts it: when a
worker dies, the scheduler hands its jobs to the others (up to ``distributed``'s
``allowed-failures``, 3 by default), and the result says nothing of where it ran except
``worker_address()``. A job's own failure is the job function's to report: it should return
a row saying so rather than raise; an exception that escapes (or a job whose workers keep
dying) comes back from :func:`run_tasks` as the exception, in place of a result.

Stopping (Ctrl-C, SIGTERM, the caller): :func:`run_tasks` cancels the jobs not finished, and a
job already running stops at its next step, frame or file (``interrupts.check``; the job sees
its task cancelled or its worker closing), as it would in this process — a run keeps its
trajectory up to then — so the workers are idle within a fraction of a second and a local
cluster closes at once, its worker processes ending normally. Those workers ignore Ctrl-C and
SIGTERM (a terminal sends Ctrl-C to every process of the command): the command stops them
itself, at any moment, their start included (:func:`_start_local`). While an
interrupted command closes its cluster, distributed's log (closed connections, cancelled
tasks) is silenced: the command's one line says what happened.
"""

from __future__ import annotations

import asyncio
import atexit
import concurrent.futures
import contextlib
import itertools
import logging
import math
import os
import signal
import socket
import sys
import threading
import time
import uuid
import warnings
from collections.abc import Callable, Iterable, Iterator
from typing import TYPE_CHECKING, Any

from . import compiling, interrupts
from .errors import InputError, first_line
from .progress import bar as progress_bar

if TYPE_CHECKING:
    from distributed import Client


CONNECT_TIMEOUT = 10.0  # s: how long Dask's handshake with a scheduler that answered may take
REACH_TIMEOUT = 3.0  # s: how long a scheduler's host may take to accept a connection at all
HANDSHAKE_TIMEOUT = 3.0  # s: how long what listens there may take to say it is a Dask scheduler
POLL_SECONDS = 0.1  # s: how often the wait for results looks for a signal
MIN_WINDOW = 32  # jobs in flight at least (run_tasks)
STOP_SECONDS = 1.0  # s: how long an interrupted command waits for a local worker to end its job and exit
LOCAL_CLUSTER_PAYS_FROM = 5.0  # s of cells in series from which a 2-core local cluster, its start counted, is faster
# (benchmarks/results/sweep_speedup.md: 0.70x at 2.8 s, 1.15x at 7.0 s); a sweep with less runs in its own process
IDLE_PROBE_SECONDS = 0.3  # s: how long default_workers watches the machine's load
WORKER_MEMORY = 2**29  # bytes of free memory a local worker process needs: about 240 MB at rest, and its runs


def cores() -> int:
    """The cores this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def idle_cores(seconds: float = IDLE_PROBE_SECONDS) -> int | None:
    """How many cores of the machine sat idle over the next ``seconds`` (from /proc/stat; None
    where it cannot be read)."""

    def times():
        with open("/proc/stat", encoding="ascii") as stream:
            values = [int(value) for value in stream.readline().split()[1:]]
        return sum(values), values[3] + values[4]  # all, idle + iowait (in clock ticks)

    try:
        total, idle = times()
        time.sleep(seconds)
        total_after, idle_after = times()
    except (OSError, ValueError, IndexError):
        return None
    elapsed = total_after - total
    return (os.cpu_count() or 1) * (idle_after - idle) / elapsed if elapsed > 0 else None


def available_memory() -> int | None:
    """Bytes of memory the machine can give new processes now (MemAvailable of /proc/meminfo;
    None where it cannot be read)."""
    try:
        with open("/proc/meminfo", encoding="ascii") as stream:
            for line in stream:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def most_workers() -> int:
    """The most worker processes a local cluster starts: one per core (a contact solve keeps
    its core busy, so more only take turns) and one per :data:`WORKER_MEMORY` of free memory;
    at least one."""
    memory = available_memory()
    by_memory = cores() if memory is None else memory // WORKER_MEMORY
    return max(1, min(cores(), by_memory))


def default_workers() -> int:
    """Worker processes of a local cluster: one per core that is idle now (at least one, at
    most :func:`most_workers`).

    On a machine another process keeps busy, a worker per core would make the workers take
    turns with it and each other: measured on 2 cores with one kept busy, two workers ran a
    16-cell study at 0.86× the speed of the cells in series, where on an idle machine they ran
    it 1.74× as fast (benchmarks/sweep_speedup.py). So the cores counted are those idle over
    :data:`IDLE_PROBE_SECONDS`."""
    idle = idle_cores()
    usable = cores() if idle is None else int(idle + 0.5)
    return max(1, min(most_workers(), usable))


def local_workers(workers: int | None) -> int:
    """The worker processes a local cluster asked for ``workers`` (None: :func:`default_workers`)
    starts: no more than :func:`most_workers`, with a warning (one line) saying so when fewer
    than asked. (500 workers on 2 cores made the machine unusable for minutes: issue 59.)"""
    if workers is None:
        return default_workers()
    most = most_workers()
    if workers > most:
        memory = available_memory()
        free = "" if memory is None else f" and {memory / 2**30:.1f} GB of free memory"
        warnings.warn(
            f"--workers {workers} is more than this machine runs at once ({cores()} cores{free}, "
            f"one worker per core and per {WORKER_MEMORY / 2**30:g} GB): using {most}",
            stacklevel=3,
        )
    return min(workers, most)


def check_cluster(scheduler: str | None, workers: int | None = None, field: str = "--scheduler") -> None:
    """Refuse, before anything starts or is written, what :func:`connect` could not use: a
    ``scheduler`` that is not ``tcp://HOST:PORT`` (PORT a whole number from 1 to 65535; an IPv6
    HOST in brackets), or where no Dask scheduler answers within a few seconds
    (:func:`_reach`, :func:`_identify`), ``workers`` that is not a whole number ≥ 1, or
    ``workers`` given with a ``scheduler``. InputError naming ``field`` (the address) or
    "--workers"."""
    if scheduler is None:
        if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
            raise InputError("--workers", f"expected a whole number of worker processes ≥ 1, found {workers!r}")
        return
    if workers is not None:
        raise InputError(
            "--workers",
            "sets the workers of a local cluster; an existing cluster (--scheduler) has "
            "the workers started for it ('dask worker ADDRESS')",
        )
    _reach(scheduler, field)
    _identify(scheduler, field)


def _host_and_port(scheduler: object, field: str) -> tuple[str, int]:
    """(HOST, PORT) of ``tcp://HOST:PORT``; InputError naming ``field`` for anything else."""
    example = "such as tcp://127.0.0.1:8786 (what 'dask scheduler' prints)"
    if not isinstance(scheduler, str) or not scheduler.startswith("tcp://"):
        raise InputError(field, f"expected a Dask scheduler's tcp://HOST:PORT address {example}, found {scheduler!r}")
    location = scheduler[len("tcp://") :]
    if location.startswith("["):  # an IPv6 host: tcp://[::1]:8786
        host, _, rest = location[1:].partition("]")
        port = rest[1:] if rest.startswith(":") else ""
    else:
        host, _, port = location.rpartition(":")
    if not host or "/" in host or not port:
        raise InputError(field, f"expected tcp://HOST:PORT {example}, found {scheduler!r}")
    if not (port.isascii() and port.isdigit() and 1 <= int(port) <= 65535):
        raise InputError(field, f"the port of {scheduler} must be a whole number from 1 to 65535, found {port!r}")
    return host, int(port)


def _reach(scheduler: str, field: str) -> None:
    """Open and close one TCP connection to the scheduler's host and port, so that an address
    nobody listens on fails at once (Dask retries a refused connection until its timeout).
    InputError naming ``field`` when the host refuses, is unknown or takes over
    :data:`REACH_TIMEOUT` to answer. The scheduler logs the connection as closed before its
    handshake (an INFO line)."""
    host, port = _host_and_port(scheduler, field)
    try:
        with socket.create_connection((host, port), timeout=REACH_TIMEOUT):
            return
    except TimeoutError:
        reason = f"no answer within {REACH_TIMEOUT:g} s"
    except socket.gaierror as error:
        reason = f"unknown host {host!r}: {error.strerror or error}"
    except OSError as error:
        reason = (error.strerror or first_line(error)).lower()
    raise InputError(field, _unreachable(scheduler, reason))


def _unreachable(scheduler: str, reason: str) -> str:
    return (
        f"could not reach a Dask scheduler at {scheduler} ({reason}); "
        f"start one with 'dask scheduler' and workers with 'dask worker {scheduler}'"
    )


def _identify(scheduler: str, field: str) -> None:
    """Ask what listens at ``scheduler`` who it is, in Dask's protocol, and wait at most
    :data:`HANDSHAKE_TIMEOUT` for the answer (looking for a signal meanwhile): InputError naming
    ``field`` unless it is a Dask scheduler. Dask's own handshake waits for an answer without
    end — an HTTP server (the dashboard's port, say) waits for the rest of a request that never
    comes — and takes the first bytes another server sends for a message's length (exabytes)."""
    answer: concurrent.futures.Future = concurrent.futures.Future()

    def ask():  # in a thread of its own: the caller's thread may run an event loop (a notebook)
        try:
            answer.set_result(asyncio.run(asyncio.wait_for(_identity(scheduler), HANDSHAKE_TIMEOUT)))
        except BaseException as error:
            answer.set_exception(error)

    with _silenced():  # distributed logs the garbled message it read
        threading.Thread(target=ask, name="contactlab scheduler handshake", daemon=True).start()
        try:
            kind = _waited(answer)
        except TimeoutError:
            reason = f"no answer in Dask's protocol within {HANDSHAKE_TIMEOUT:g} s"
        except Exception:  # noqa: BLE001 — whatever it answered, it was not Dask's protocol
            reason = "it answers, but not in Dask's protocol"
        else:
            if kind == "Scheduler":
                return
            reason = f"a Dask {str(kind).lower()} answers there, not a scheduler"
    raise InputError(
        field,
        f"{scheduler} is not a Dask scheduler ({reason}); give the address that 'dask scheduler' "
        "prints (tcp://HOST:8786 by default; its dashboard's port, 8787, serves web pages)",
    )


async def _identity(scheduler: str) -> object:
    """The ``type`` a Dask server at ``scheduler`` gives in its identity ("Scheduler", "Worker")."""
    from distributed.comm import connect as open_comm

    comm = await open_comm(scheduler, timeout=HANDSHAKE_TIMEOUT)
    try:
        await comm.write({"op": "identity", "reply": True})
        identity = await comm.read()
    finally:
        comm.abort()
    return identity.get("type") if isinstance(identity, dict) else None


def _waited(future: concurrent.futures.Future) -> Any:
    """``future``'s result, looking for a signal (``interrupts.check``) every :data:`POLL_SECONDS`
    while it is not there: the wait is as short as the command's answer to Ctrl-C."""
    while not concurrent.futures.wait([future], timeout=POLL_SECONDS).done:
        interrupts.check()
    return future.result()


@contextlib.contextmanager
def connect(scheduler: str | None = None, workers: int | None = None, field: str = "--scheduler") -> Iterator[Client]:
    """Yield a ``distributed.Client``: to the scheduler at ``scheduler`` (``tcp://HOST:PORT``),
    or, when None, to a new local cluster of :func:`local_workers` single-threaded worker
    processes listening on 127.0.0.1 only, closed on exit. InputError naming ``field`` when the
    address is malformed or no scheduler answers there, "--workers" for a bad ``workers``
    (:func:`check_cluster`). A signal while a local cluster starts stops it within
    :data:`STOP_SECONDS` or so (:func:`_start_local`)."""
    interrupts.check()  # a signal of the command's first moments: before a second of Dask's imports
    from distributed import Client

    check_cluster(scheduler, workers, field)
    if scheduler is None:
        cluster = _start_local(local_workers(workers))
        try:
            client = Client(cluster)
        except BaseException:
            _stop(cluster)
            raise
        with _closing(cluster, client) as client:
            yield client
        return
    try:
        client = Client(scheduler, timeout=CONNECT_TIMEOUT)
    except (OSError, TimeoutError, ValueError) as error:
        raise InputError(field, _unreachable(scheduler, first_line(error))) from None
    with _closing(None, client):
        yield client


def _start_local(workers: int):
    """A ``distributed.LocalCluster`` of ``workers`` worker processes, started while this thread
    looks for a signal every :data:`POLL_SECONDS`: one stops the start and closes what had
    started (a start takes seconds on a busy machine; Dask's own start, one call, ran to its
    end or failed with "Nanny failed to start" and a traceback of a hundred lines).

    Ctrl-C reaches the worker processes too (a terminal sends it to every process of the
    command; a job runner's SIGTERM often goes to the whole process group as well), and one
    still importing would die of it with a traceback: so the cluster's threads are made with
    SIGINT and SIGTERM blocked, and the processes they start inherit the block until
    :func:`dask_setup` ignores them there (a blocked signal waits; an ignored one is gone)."""
    from multiprocessing import resource_tracker

    from distributed import LocalCluster

    resource_tracker.ensure_running()  # started by the first worker, it would unblock them in Dask's thread
    blocked = _block_stops()
    cluster = None
    try:
        cluster = LocalCluster(
            n_workers=0,  # the scheduler only: the workers start below, a signal looked for meanwhile
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address="127.0.0.1:0",
            silence_logs=logging.ERROR,  # a cancelled task's warning is no news
            preload=[__name__],  # dask_setup: each worker ignores Ctrl-C
        )
        _unblock_stops(blocked)  # a signal of the last moments arrives here
        blocked = None
        cluster.scale(workers)
        _waited(asyncio.run_coroutine_threadsafe(_workers_started(cluster), cluster.loop.asyncio_loop))
        return cluster
    except BaseException:
        if cluster is not None:
            _stop(cluster, starting=True)
        raise
    finally:
        _unblock_stops(blocked)


async def _workers_started(cluster) -> None:
    """Wait for the workers ``cluster.scale`` asked for (distributed's own wait: its
    ``_correct_state``, which raises when a worker fails to start)."""
    await cluster._correct_state()


def _block_stops() -> object:
    """Block SIGINT and SIGTERM (interrupts.EXIT_CODES) in this thread and the threads it starts
    from now on; returns what to give :func:`_unblock_stops`. Nothing where threads have no
    signal masks (Windows)."""
    if not hasattr(signal, "pthread_sigmask"):
        return None
    return signal.pthread_sigmask(signal.SIG_BLOCK, set(interrupts.EXIT_CODES))


def _unblock_stops(blocked: object) -> None:
    """Undo :func:`_block_stops` (given its answer; None: nothing to undo)."""
    if blocked is not None:
        signal.pthread_sigmask(signal.SIG_UNBLOCK, set(interrupts.EXIT_CODES) - set(blocked))


def _stop(cluster, starting: bool = False) -> None:
    """Close a local ``cluster`` at once, Dask's log silenced: its worker processes end within
    :data:`STOP_SECONDS` (killed if they do not). ``starting``: the cluster was still starting
    its workers, which have nothing to keep: they are killed at once (Dask would wait for one
    still importing to finish its start before closing it: most of 2 s on a busy machine)."""
    with _silenced():
        if starting:
            for nanny in getattr(cluster, "_created", ()):  # Dask's: every worker started or starting
                pid = getattr(getattr(nanny, "process", None), "pid", None)
                if pid is not None:
                    with contextlib.suppress(ProcessLookupError):
                        os.kill(pid, signal.SIGKILL)
        cluster.sync(_close_workers, cluster, STOP_SECONDS)
        cluster.close()


@contextlib.contextmanager
def _closing(cluster, client: Client) -> Iterator[Client]:
    """Yield ``client``; close it and ``cluster`` (a local one, or None) at the end, with
    distributed's log silenced when the end is an exception (a signal's, most often)."""
    try:
        yield client
    except BaseException:
        with _silenced():
            client.close()
        if cluster is not None:
            _stop(cluster)
        raise
    client.close()
    if cluster is not None:
        cluster.close()


async def _close_workers(cluster, seconds: float) -> None:
    """Close the worker processes of the local ``cluster``, those still starting too (Dask's
    ``_created``: a worker joins ``cluster.workers`` once all have started), killing those
    still there after ``seconds`` (one stuck in a compilation, which no signal interrupts)."""
    nannies = {*cluster.workers.values(), *getattr(cluster, "_created", ())}
    await asyncio.gather(*(nanny.close(timeout=seconds / 0.8) for nanny in nannies), return_exceptions=True)


@contextlib.contextmanager
def _silenced() -> Iterator[None]:
    """No log record of any level while this is open (distributed logs from several threads)."""
    previous = logging.root.manager.disable
    logging.disable(logging.CRITICAL)
    try:
        yield
    finally:
        logging.disable(previous)


def dask_setup(worker: Any) -> None:
    """Run by Dask in each worker process of a local cluster as it starts (the ``preload`` of
    :func:`connect`). Ctrl-C and SIGTERM are ignored there: a terminal sends Ctrl-C to every
    process of the command in front (and a job runner often SIGTERM), and a worker would die of
    it with a traceback — or, dead while the command fetched its result, have Dask log
    "Couldn't gather keys" — while the command stops its jobs and closes its workers itself
    (Dask closes a worker by message, then SIGKILL; never by SIGTERM). And tqdm (the bars of
    ``simulate`` and ``render``, off on a worker) locks with a thread lock, not its default
    multiprocessing one: a semaphore that a worker killed while stuck (in a compilation, say)
    would leave to multiprocessing's ``resource_tracker``, which warns of it when the command
    exits."""
    from tqdm import tqdm

    tqdm.set_lock(threading.RLock())
    with contextlib.suppress(ValueError):  # not the main thread (a worker started some other way)
        for stop in interrupts.EXIT_CODES:
            signal.signal(stop, signal.SIG_IGN)
        if hasattr(signal, "pthread_sigmask"):  # born with them blocked (_start_local): one held is dropped
            signal.pthread_sigmask(signal.SIG_UNBLOCK, set(interrupts.EXIT_CODES))


def dask_teardown(worker: Any) -> None:
    """Run by Dask as a local cluster's worker closes (its jobs ended). Its log has no news from
    here on (a heartbeat cut short by the closing connections is an ERROR to distributed), and
    once the interpreter starts to exit, multiprocessing's own clean-up done, the process ends
    without tearing down every module: most of a second with NumPy, Numba and pandas loaded,
    while the command waits for it."""
    logging.disable(logging.CRITICAL)
    atexit.register(_exit_now)


def _exit_now() -> None:
    """The last exit handler registered, so the first run: flush the log and end the process."""
    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    os._exit(0)


def dashboard(client: Client) -> str:
    """The address of the cluster's dashboard, or a sentence saying there is none."""
    link = getattr(client, "dashboard_link", None)
    import importlib.util

    if importlib.util.find_spec("bokeh") is None:  # the dashboard is served only with bokeh installed
        return "none (install bokeh to get one)"
    return link or "none"


def run_tasks(
    client: Client,
    function: Callable[[Any], Any],
    jobs: Iterable[tuple[Any, Any]],
    progress: bool = False,
    description: str = "jobs",
) -> Iterator[tuple[Any, Any]]:
    """Run ``function(job)`` for every ``(key, job)`` of ``jobs`` on ``client``'s workers;
    yield ``(key, result)`` as each finishes — the exception in place of the result when one
    escaped the function or its workers kept dying. ``progress``: progress over the jobs on
    stderr (contactlab.progress: a bar on a terminal, else a line every few seconds). A
    signal (contactlab.interrupts) takes effect within :data:`POLL_SECONDS`; then, as when the
    caller stops early, the jobs in flight (a few per thread of the cluster, :class:`_Window`)
    are cancelled, and those running stop at their next ``interrupts.check`` (:func:`_run_job`).
    A job that compiles kernels sends the compile notice here rather than print it on its
    worker (into the bar, once a worker): it is said once (contactlab.compiling.say: once a
    command inside ``one_notice``, else once a call), clear of the bar."""
    from distributed import as_completed

    token = uuid.uuid4().hex[:8]  # task keys of this call only, on a scheduler others may share
    heard: list[str] = []  # compile notices the jobs sent (appended in the client's thread)
    topic = f"contactlab-compiling-{client.id}-{token}"
    client.subscribe_topic(topic, lambda event: heard.append(event[1]))
    jobs = list(jobs)
    waiting = iter(jobs)
    futures: dict = {}  # submitted, not finished -> its key
    finished = as_completed()
    window = _Window(client)

    def submit():  # up to the window's size in flight, in one message to the scheduler
        batch = list(itertools.islice(waiting, max(0, window.size() - len(futures))))
        if batch:
            submitted = client.map(
                _run_job,
                [function] * len(batch),
                [job for _, job in batch],
                [topic] * len(batch),
                key=[f"contactlab-{key}-{token}" for key, _ in batch],
                pure=False,
            )
            futures.update(zip(submitted, (key for key, _ in batch)))
            finished.update(submitted)

    bar = progress_bar(len(jobs), description, "job", progress)
    said = False

    def tell():  # the first compile notice a job sent, once
        nonlocal said
        if heard and not said:
            said = True
            compiling.say(heard[0], bar.write)

    try:
        submit()
        while futures:
            interrupts.check()
            tell()
            batch = finished.next_batch(block=False)
            if not batch:
                bar.tick()  # no job finished: a line where stderr is no terminal, every few seconds still
                time.sleep(POLL_SECONDS)
                continue
            for future in batch:
                key = futures.pop(future)
                try:
                    result = future.result()
                except Exception as error:  # escaped the job function, or its workers died
                    result = error
                future.release()
                bar.update(1)
                yield key, result
            submit()
        tell()
    finally:
        if futures:  # stopped early (a signal, the caller): cancel those in flight, in one message
            with _silenced():
                client.cancel(list(futures))
        with _silenced(), contextlib.suppress(Exception):  # a closed connection has no topic left to leave
            client.unsubscribe_topic(topic)
        bar.close()


class _Window:
    """How many jobs :func:`run_tasks` keeps submitted at once: twice the cluster's threads (at
    least :data:`MIN_WINDOW`), looked up again every few seconds as workers come and go. The
    scheduler then holds a few jobs per thread, not all of a 100,000-cell study (a graph of
    tens of MB to send, and as many tasks to cancel when it is stopped)."""

    def __init__(self, client):
        self.client, self.known, self.checked = client, MIN_WINDOW, -math.inf

    def size(self) -> int:
        if time.monotonic() - self.checked > 5.0:
            self.checked = time.monotonic()
            with contextlib.suppress(Exception):  # no answer: the last size
                self.known = max(MIN_WINDOW, 2 * sum(self.client.nthreads().values()))
        return self.known


def _run_job(function: Callable[[Any], Any], job: Any, topic: str) -> Any:
    """``function(job)`` on a Dask worker, stopped at its next ``interrupts.check`` once its task
    is cancelled or its worker is closing (then None: nobody waits for the result). A compile
    notice of the job goes to the command as an event of ``topic`` (:func:`run_tasks`)."""
    from distributed import get_worker
    from distributed.core import Status

    worker = get_worker()
    key = worker.get_current_task()

    def asked() -> bool:
        task = worker.state.tasks.get(key)
        return (
            worker.status in (Status.closing, Status.closed, Status.failed) or task is None or task.state == "cancelled"
        )

    with interrupts.stoppable(asked), compiling.notices_to(lambda message: worker.log_event(topic, message)):
        try:
            return function(job)
        except interrupts.Interrupted:
            return None


def worker_address() -> str:
    """The address of the Dask worker running the caller, or "local" outside one."""
    try:
        from distributed import get_worker

        return get_worker().address
    except (ImportError, ValueError):
        return "local"
