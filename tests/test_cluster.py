"""Issue 59: where a command meets Dask (contactlab.cluster). A signal while the local cluster
starts stops the command in one line, its workers gone; a scheduler address where something
else listens is refused within seconds, before anything is written; a local cluster starts no
more workers than the machine runs at once."""

import http.server
import os
import signal
import socketserver
import subprocess
import sys
import threading
import time

import pytest
from conftest import alive_in_group, interruptible, messages

from contactlab import cluster
from contactlab.errors import InputError

STUDY = """
[study]
name = "ball"
[grid]
scenes = ["bouncing_ball"]
methods = ["impulse", "constraints"]
[grid.set]
"simulation.duration" = [0.5]
"""


def _command(*arguments, cwd, **options):
    return subprocess.Popen(
        [sys.executable, "-m", "contactlab", *map(str, arguments)],
        cwd=cwd,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        **options,
    )


def _starting_workers(group):
    """Whether a process of ``group`` is a worker process being spawned (multiprocessing's)."""
    for entry in os.listdir("/proc"):
        try:
            with open(f"/proc/{entry}/stat", encoding="ascii", errors="replace") as stream:
                fields = stream.read().rsplit(")", 1)[1].split()
            with open(f"/proc/{entry}/cmdline", "rb") as stream:
                line = stream.read()
        except (OSError, IndexError):
            continue
        if int(fields[2]) == group and b"spawn_main" in line:
            return True
    return False


# ---- a signal while the local cluster starts ----------------------------------------------------


@pytest.mark.parametrize(
    "arguments, signum, to_group",
    [
        (("sweep", "study.toml"), signal.SIGINT, True),  # a terminal's Ctrl-C: the command and its workers
        (("compare", "bouncing_ball", "--methods", "impulse,constraints", "--no-video"), signal.SIGINT, True),
        (("sweep", "study.toml"), signal.SIGTERM, False),  # kill PID: the command alone
        (("sweep", "study.toml"), signal.SIGTERM, True),  # a job runner's stop: the whole group
    ],
)
def test_a_signal_while_the_workers_start_stops_the_command_in_one_line(tmp_path, arguments, signum, to_group):
    # issue 59: "RuntimeError: Nanny failed to start", a traceback of 130 lines, exit 1 (a worker
    # process still importing died of the Ctrl-C, and Dask's start failed with it)
    (tmp_path / "study.toml").write_text(STUDY, encoding="utf-8")
    process = _command(
        *arguments,
        "--workers",
        "2",
        "--out",
        "out",
        cwd=tmp_path,
        preexec_fn=interruptible,
        start_new_session=True,
    )
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and process.poll() is None and not _starting_workers(process.pid):
        time.sleep(0.01)
    time.sleep(0.2)  # the workers' interpreters are up, importing
    (os.killpg if to_group else os.kill)(process.pid, signum)
    sent = time.monotonic()
    _, stderr = process.communicate(timeout=60)
    took = time.monotonic() - sent
    name = signal.Signals(signum).name
    assert process.returncode == 128 + signum and took < 2.0, (took, stderr)
    assert messages(stderr) == [f"interrupted ({name}); no output written"], stderr
    assert not alive_in_group(process.pid, 1.0)  # no worker outlived the command
    assert sorted(os.listdir(tmp_path)) == ["study.toml"]  # no out/ left behind


# ---- a scheduler address where no Dask scheduler listens --------------------------------------------


class _Quiet(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *arguments):
        pass


class _Greeting(socketserver.BaseRequestHandler):
    """A server that speaks first, not Dask: an SSH server's greeting, then nothing."""

    def handle(self):
        self.request.sendall(b"SSH-2.0-OpenSSH_9.2p1 Debian-2\r\n")
        time.sleep(10)


@pytest.fixture(params=["http", "greeting"])
def not_a_scheduler(request):
    """The address of a server on 127.0.0.1 that is no Dask scheduler: an HTTP server (such as
    the dashboard, on the port beside the scheduler's), or one that greets in its own protocol."""
    if request.param == "http":
        server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _Quiet)
    else:
        server = socketserver.ThreadingTCPServer(("127.0.0.1", 0), _Greeting)
    server.daemon_threads = True
    threading.Thread(target=server.serve_forever, daemon=True).start()
    yield f"tcp://127.0.0.1:{server.server_address[1]}"
    server.shutdown()
    server.server_close()


def test_an_address_where_no_scheduler_listens_is_refused_within_the_handshake_time(not_a_scheduler):
    # issue 59: an HTTP server made fit wait 12 min and sweep 5.5 min, deaf to Ctrl-C; a server
    # that speaks first, "Unable to allocate 3.07 EiB" and a traceback
    started = time.monotonic()
    with pytest.raises(InputError) as refused:
        cluster.check_cluster(not_a_scheduler)
    assert time.monotonic() - started < cluster.HANDSHAKE_TIMEOUT + 1.0
    assert refused.value.field == "--scheduler"
    assert refused.value.message.startswith(f"{not_a_scheduler} is not a Dask scheduler ("), refused.value
    assert "give the address that 'dask scheduler' prints" in refused.value.message


def test_sweep_with_an_http_server_for_scheduler_exits_2_in_one_line_writing_nothing(tmp_path):
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _Quiet)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    address = f"tcp://127.0.0.1:{server.server_address[1]}"
    (tmp_path / "study.toml").write_text(STUDY, encoding="utf-8")
    try:
        process = _command("sweep", "study.toml", "--scheduler", address, cwd=tmp_path)
        _, stderr = process.communicate(timeout=60)
    finally:
        server.shutdown()
        server.server_close()
    assert process.returncode == 2, stderr
    assert stderr.splitlines() == [
        f"error: study.toml: --scheduler: {address} is not a Dask scheduler (no answer in Dask's protocol "
        f"within {cluster.HANDSHAKE_TIMEOUT:g} s); give the address that 'dask scheduler' prints "
        "(tcp://HOST:8786 by default; its dashboard's port, 8787, serves web pages)"
    ]
    assert sorted(os.listdir(tmp_path)) == ["study.toml"]


def test_a_dask_scheduler_is_taken_and_a_dask_worker_is_not():
    with cluster.connect(workers=1) as client:
        cluster.check_cluster(client.scheduler.address)  # no error
        worker = next(iter(client.scheduler_info()["workers"]))
        with pytest.raises(InputError) as refused:
            cluster.check_cluster(worker)
    assert "(a Dask worker answers there, not a scheduler)" in refused.value.message, refused.value


# ---- how many workers ------------------------------------------------------------------------------


def test_more_workers_than_the_machine_runs_at_once_are_capped_with_one_warning():
    # issue 59: fit --workers 500 on 2 cores started about 500 processes (load 164-260, 20 GB)
    most = cluster.most_workers()
    assert 1 <= most <= cluster.cores()
    with pytest.warns(UserWarning) as warned:
        with cluster.connect(workers=most + 498) as client:
            assert len(client.scheduler_info()["workers"]) == most
    assert len(warned) == 1
    assert str(warned[0].message).startswith(f"--workers {most + 498} is more than this machine runs at once (")
    assert str(warned[0].message).endswith(f": using {most}")


def test_free_memory_caps_the_workers_too(monkeypatch):
    monkeypatch.setattr(cluster, "available_memory", lambda: 3 * cluster.WORKER_MEMORY // 2)
    assert cluster.most_workers() == 1
    monkeypatch.setattr(cluster, "available_memory", lambda: None)  # unknown: the cores alone
    assert cluster.most_workers() == cluster.cores()
