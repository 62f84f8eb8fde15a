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
"""

from __future__ import annotations

import contextlib
import logging
import os
import socket
import time
import uuid
from collections.abc import Callable, Iterable, Iterator
from typing import TYPE_CHECKING, Any

from . import interrupts
from .errors import InputError, first_line
from .progress import bar as progress_bar

if TYPE_CHECKING:
    from distributed import Client


CONNECT_TIMEOUT = 10.0  # s: how long Dask's handshake with a scheduler that answered may take
REACH_TIMEOUT = 3.0  # s: how long a scheduler's host may take to accept a connection at all
POLL_SECONDS = 0.5  # s: how often the wait for results looks for a signal
IDLE_PROBE_SECONDS = 0.3  # s: how long default_workers watches the machine's load


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


def default_workers() -> int:
    """Worker processes of a local cluster: one per core that is idle now (at least one).

    On a machine another process keeps busy, a worker per core would make the workers take
    turns with it and each other: measured on 2 cores with one kept busy, two workers ran a
    16-cell study at 0.86× the speed of the cells in series, where on an idle machine they ran
    it 1.74× as fast (benchmarks/sweep_speedup.py). So the cores counted are those idle over
    :data:`IDLE_PROBE_SECONDS`."""
    idle = idle_cores()
    usable = cores() if idle is None else int(idle + 0.5)
    return max(1, min(cores(), usable))


def check_cluster(scheduler: str | None, workers: int | None = None, field: str = "--scheduler") -> None:
    """Refuse, before anything starts, what :func:`connect` could not use: a ``scheduler`` that
    is not ``tcp://HOST:PORT`` (PORT a whole number from 1 to 65535; an IPv6 HOST in brackets),
    ``workers`` that is not a whole number ≥ 1, or ``workers`` given with a ``scheduler``.
    InputError naming ``field`` (the address) or "--workers"."""
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
    _host_and_port(scheduler, field)


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


@contextlib.contextmanager
def connect(scheduler: str | None = None, workers: int | None = None, field: str = "--scheduler") -> Iterator[Client]:
    """Yield a ``distributed.Client``: to the scheduler at ``scheduler`` (``tcp://HOST:PORT``),
    or, when None, to a new local cluster of ``workers`` single-threaded worker processes
    (default :func:`default_workers`) listening on 127.0.0.1 only, closed on exit.
    InputError naming ``field`` when the address is malformed or the scheduler cannot be
    reached, "--workers" for a bad ``workers`` (:func:`check_cluster`)."""
    from distributed import Client, LocalCluster

    check_cluster(scheduler, workers, field)
    if scheduler is None:
        cluster = LocalCluster(
            n_workers=workers or default_workers(),
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address="127.0.0.1:0",
            silence_logs=logging.ERROR,
        )  # a cancelled task's warning is no news
        try:
            with Client(cluster) as client:
                yield client
        finally:
            cluster.close()
        return
    _reach(scheduler, field)
    try:
        client = Client(scheduler, timeout=CONNECT_TIMEOUT)
    except (OSError, TimeoutError, ValueError) as error:
        raise InputError(field, _unreachable(scheduler, first_line(error))) from None
    with client:
        yield client


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
    signal (contactlab.interrupts) takes effect within :data:`POLL_SECONDS`, and the jobs not
    finished are cancelled."""
    from distributed import wait

    token = uuid.uuid4().hex[:8]  # task keys of this call only, on a scheduler others may share
    futures = {}
    for key, job in jobs:
        future = client.submit(function, job, key=f"contactlab-{key}-{token}", pure=False)
        futures[future] = key
    bar = progress_bar(len(futures), description, "job", progress)
    try:
        while futures:
            interrupts.check()
            try:
                finished = wait(list(futures), timeout=POLL_SECONDS, return_when="FIRST_COMPLETED").done
            except TimeoutError:
                bar.tick()  # no job finished: a line where stderr is no terminal, every few seconds still
                continue
            for future in finished:
                key = futures.pop(future)
                try:
                    result = future.result()
                except Exception as error:  # escaped the job function, or its workers died
                    result = error
                future.release()
                bar.update(1)
                yield key, result
    finally:
        for future in futures:  # stopped early (a signal, the caller): cancel the rest
            future.cancel()
        bar.close()


def worker_address() -> str:
    """The address of the Dask worker running the caller, or "local" outside one."""
    try:
        from distributed import get_worker

        return get_worker().address
    except (ImportError, ValueError):
        return "local"
