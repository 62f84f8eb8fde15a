"""Issue 21: studies (contactlab.study) swept on a real Dask cluster (contactlab.sweep): the
table matches runs made directly, survives interruption and dead workers, and a rerun
recomputes nothing."""

import os
import signal
import socket
import subprocess
import sys
import time

import numpy as np
import pandas as pd
import pytest
from conftest import alive_in_group, interruptible, messages

from contactlab import InputError, closed_form, simulate
from contactlab.compiling import NOTICE
from contactlab.scene import load_scene
from contactlab.scene.loader import read_source
from contactlab.study import load_study, toml_value
from contactlab.sweep import TIMING_COLUMNS
from contactlab.sweep_report import convergence_words, observed_order, pareto_front, stalled_from

BALL_STUDY = """
[study]
name = "ball"
[grid]
scenes = ["bouncing_ball"]
methods = ["impulse", "constraints"]
[grid.set]
"simulation.dt" = [0.004, 0.002]
"simulation.duration" = [1.0]
"materials.0.restitution" = [0.8, 0.5]
"""


def write(folder, text, name="study.toml"):
    path = folder / name
    path.write_text(text, encoding="utf-8")
    return path


# ---- the study file ---------------------------------------------------------------------------------


def test_a_grid_expands_to_every_combination_and_explicit_cells_join_it(tmp_path):
    study = load_study(
        write(
            tmp_path,
            BALL_STUDY
            + """
[[cells]]
scene = "bouncing_ball"
method = "impulse"
set = { "simulation.dt" = 0.004, "simulation.duration" = 1.0, "materials.0.restitution" = 0.8 }
[[cells]]
scene = "box_pyramid"
method = "constraints"
set = { "method.constraints.iterations" = 20 }
""",
        )
    )
    assert len(study.cells) == 2 * 2 * 2 + 1  # the first listed cell is in the grid already
    assert study.axes == [
        "simulation.dt",
        "simulation.duration",
        "materials.0.restitution",
        "method.constraints.iterations",
    ]
    first = study.cells[0]
    assert (first.scene, first.method, dict(first.settings)) == (
        "bouncing_ball",
        "impulse",
        {"simulation.dt": 0.004, "simulation.duration": 1.0, "materials.0.restitution": 0.8},
    )
    assert first.overrides()[-1] == "simulation.method=impulse"
    assert len({cell.key for cell in study.cells}) == len(study.cells)
    assert load_study(write(tmp_path, BALL_STUDY)).cells[0].key == first.key  # the same cell, the same key


def test_a_cell_key_changes_with_the_scene_text(tmp_path):
    text = read_source("bouncing_ball")[1]
    write(tmp_path, text, "ball.toml")
    study = '[grid]\nscenes = ["ball.toml"]\nmethods = ["impulse"]\n'
    before = load_study(write(tmp_path, study)).cells[0].key
    write(tmp_path, text.replace("restitution = 0.8", "restitution = 0.7"), "ball.toml")
    assert load_study(write(tmp_path, study)).cells[0].key != before


@pytest.mark.parametrize(
    "text, field, words",
    [
        ('[grd]\nscenes = ["bouncing_ball"]', "grd", "did you mean 'grid'"),
        ('[grid]\nscenes = ["bouncing_bal"]', "grid.scenes", "did you mean 'bouncing_ball'"),
        ('[grid]\nscenes = ["bouncing_ball"]\nmethods = ["impulses"]', "grid.methods", "did you mean 'impulse'"),
        (
            '[grid]\nscenes = ["bouncing_ball"]\n[grid.set]\n"simulation.dtt" = [0.1]',
            'grid.set."simulation.dtt"',
            "did you mean 'dt'",
        ),
        (
            '[grid]\nscenes = ["bouncing_ball"]\n[grid.set]\n"simulation.dt" = [-0.1]',
            'grid.set."simulation.dt"',
            "expected a number greater than 0 (s), found -0.1",
        ),
        (
            '[grid]\nscenes = ["bouncing_ball"]\n[grid.set]\n"simulation.dt" = []',
            'grid.set."simulation.dt"',
            "at least one value",
        ),
        ('[[cells]]\nscene = "bouncing_ball"', "cells[0].method", "needs a method"),
        ('[study]\nrecord = "everything"', "study.record", "summary, trajectory"),
        ('[study]\nname = "x"', "", "no cells"),
    ],
)
def test_a_wrong_study_is_one_input_error_naming_the_field(tmp_path, text, field, words):
    with pytest.raises(InputError) as refused:
        load_study(write(tmp_path, text))
    assert refused.value.field == field and words in refused.value.message, refused.value


@pytest.mark.parametrize(
    "settings, field, words",
    [
        (
            '"simulation.dt" = [1e-300]\n"simulation.duration" = [1e308]',
            'grid.set."simulation.dt"',
            "expected a time of at least 1e-09 s, found 1e-300 s",
        ),
        (
            '"simulation.dt" = [1e-9]\n"simulation.duration" = [1e9]',
            'grid.set."simulation.dt"',
            "duration / dt = 1e+18 steps, more than the 1e+09 a run may make",
        ),
        (
            '"simulation.dt" = [2.0]\n"simulation.duration" = [1.0]',
            'grid.set."simulation.dt"',
            "dt = 2 s is longer than duration = 1 s",
        ),
        ('"simulation.duration" = [0.001]', 'grid.set."simulation.duration"', "is longer than duration = 0.001 s"),
        (  # 9 × 10⁸ samples of the pyramid held in memory: terabytes
            '"simulation.dt" = [1e-6]\n"simulation.duration" = [900.0]',
            'grid.set."simulation.duration"',
            "over its limit of",
        ),
    ],
)
def test_a_cell_over_the_limits_of_a_run_is_refused_when_the_study_is_read(tmp_path, settings, field, words):
    # issue 37: these cells started a cluster and came back as errors, where `run` refuses them
    text = f'[grid]\nscenes = ["box_pyramid"]\nmethods = ["constraints"]\n[grid.set]\n{settings}\n'
    with pytest.raises(InputError) as refused:
        load_study(write(tmp_path, text))
    assert refused.value.field == field and words in refused.value.message, refused.value
    assert refused.value.message.startswith("box_pyramid with constraints (simulation.")


def test_a_cell_too_big_for_memory_is_advised_what_a_study_offers(tmp_path):
    text = '[grid]\nscenes = ["box_pyramid"]\nmethods = ["constraints"]\n[grid.set]\n'
    text += '"simulation.dt" = [1e-6]\n"simulation.duration" = [900.0]\n'
    with pytest.raises(InputError) as refused:
        load_study(write(tmp_path, text))
    message = refused.value.message
    assert "900,000,002 samples" in message
    assert "shorter simulation.duration or a longer simulation.dt" in message
    assert 'record = "trajectory" under [study]' in message  # what the study file offers, and
    assert "--memory-limit" not in message and "trajectory=" not in message  # not what sweep has not
    streamed = load_study(write(tmp_path, '[study]\nrecord = "trajectory"\n' + text))  # the advice taken
    assert len(streamed.cells) == 1


def test_the_largest_study_is_checked_a_setting_at_a_time_with_news_of_a_long_check(tmp_path, monkeypatch):
    """Issue 37: the documented maximum, 100,000 cells, took 70 s to check, one scene load per
    cell, in silence. Each method and each distinct setting is checked once now (8 + 51 loads
    here), each value still with its field named, and a long check says how far it got."""
    from contactlab import study as study_module
    from contactlab.scene import loader

    def values(count, low, high):
        return ", ".join(repr(round(low + (high - low) * i / count, 6)) for i in range(count))

    text = (
        '[grid]\nscenes = ["bouncing_ball"]\n[grid.set]\n'
        f'"simulation.duration" = [{values(10, 0.1, 0.5)}]\n'
        f'"materials.0.restitution" = [{values(25, 0.1, 0.9)}]\n'
        f'"materials.0.friction" = [{values(10, 0.1, 0.9)}]\n'
        f'"simulation.dt" = [{values(10, 0.001, 0.004)}]\n'
    )
    validated = []
    validate = loader.validate_scene
    monkeypatch.setattr(loader, "validate_scene", lambda raw: validated.append(1) or validate(raw))
    monkeypatch.setattr(study_module, "CHECK_NEWS_SECONDS", 0.0)
    news = []
    started = time.monotonic()
    study = load_study(write(tmp_path, text), log=news.append)
    assert len(study.cells) == study_module.MAX_CELLS and time.monotonic() - started < 30
    # each method once on a cell's settings and once as the file has it (the run limits' base), then each value
    assert len(validated) == 2 * 4 + (10 - 1) + (25 - 1) + (10 - 1) + (10 - 1)
    assert news and news[0].startswith("checking the study: ") and news[0].endswith(" s so far")
    bad = text[: text.rindex(", ")] + ", -0.5]\n"  # the last value of the last axis
    with pytest.raises(InputError) as refused:  # a bad value deep in an axis, named
        load_study(write(tmp_path, bad))
    assert refused.value.field == 'grid.set."simulation.dt"' and "found -0.5" in refused.value.message


def test_toml_value_reads_back_as_the_value():
    from contactlab.scene.overrides import parse_value

    for value in (0.1, 3, True, 'text with "quotes"', [10, 10, 4], [0.5, [1, 2]], 1e-300, float("inf")):
        assert parse_value(toml_value(value)) == value


# ---- the report's arithmetic ------------------------------------------------------------------------


def test_the_observed_order_of_a_power_law_is_its_exponent():
    dt = np.array([0.004, 0.002, 0.001, 0.0005])
    assert observed_order(dt, 3.0 * dt**2) == pytest.approx(2.0, abs=1e-12)
    assert observed_order(dt, 0.5 * dt) == pytest.approx(1.0, abs=1e-12)
    assert observed_order(dt[:1], dt[:1]) is None and observed_order(dt, np.zeros(4)) is None


def test_a_series_that_stalls_gets_no_order_but_the_dt_it_stalls_from():
    """Issue 37: errors 0.99 -> 0.044 -> 0.042 were fitted "order 2.27"; halving dt from 2 ms
    to 1 ms bought a local order of log(0.044/0.042)/log 2 = 0.07, below STALL_ORDER."""
    dt = np.array([0.001, 0.004, 0.002])  # any order: the series is read by decreasing dt
    error = np.array([0.042, 0.99, 0.044])
    assert stalled_from(dt, error) == 0.002
    assert observed_order(dt, error) is None
    assert convergence_words(dt, error) == "stalls from dt = 0.002 s"
    three = np.array([0.004, 0.002, 0.001])
    assert stalled_from(three, np.array([0.01, 0.02, 0.04])) == 0.004  # the error grows as dt falls
    plateau = np.array([6.6e-5, 4.7e-5, 1.8e-6])  # a plateau, then convergence again: no stall
    assert stalled_from(three, plateau) is None and observed_order(three, plateau) is not None
    power = np.array([0.004, 0.002, 0.001, 0.0005])
    assert stalled_from(power, 3.0 * power**2) is None
    assert convergence_words(power, 3.0 * power**2) == "order 2.00"
    assert convergence_words(power[:1], power[:1]) == ""


def test_a_cells_cost_leaves_its_compiling_out():
    # issue 59: the Pareto plot counted the first cell's compile time as that cell's cost
    from contactlab.sweep_report import cost

    rows = pd.DataFrame({"wall_seconds": [5.0, 0.2, 0.3], "compile_seconds": [4.8, 0.0, None]})
    assert cost(rows).tolist() == pytest.approx([0.2, 0.2, 0.3])
    assert cost(rows.drop(columns="compile_seconds")).tolist() == [5.0, 0.2, 0.3]  # an older table's rows


def test_the_pareto_front_holds_exactly_the_cells_nothing_beats():
    cost = np.array([1.0, 2.0, 3.0, 1.5, 4.0, np.nan])
    error = np.array([0.5, 0.1, 0.2, 0.6, 0.01, 0.0])
    assert pareto_front(cost, error) == [0, 1, 4]


# ---- a local cluster ------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def ball_sweep(tmp_path_factory):
    from contactlab import sweep

    folder = tmp_path_factory.mktemp("sweep")
    study = write(
        folder,
        BALL_STUDY
        + """
[[cells]]
scene = "bouncing_ball"
method = "penalty"
[cells.set]
"simulation.dt" = 0.01
"simulation.integrator" = "explicit_euler"
"method.penalty.stiffness" = 1e9
"method.penalty.implicit_springs" = "never"
""",
    )
    lines = []
    table = sweep.run(study, folder / "out", workers=2, log=lines.append)
    return folder, study, table, lines


def test_every_cell_has_its_row_in_the_study_order_with_a_parquet_table_and_a_report(ball_sweep):
    folder, study, table, lines = ball_sweep
    cells = load_study(study).cells
    assert list(table["key"]) == [cell.key for cell in cells]
    assert lines[0] == "9 cells: 0 done already, 9 to run"
    assert list(table.columns[:11]) == [
        "key",
        "scene",
        "method",
        "simulation.dt",
        "simulation.duration",
        "materials.0.restitution",
        "simulation.integrator",
        "method.penalty.stiffness",
        "method.penalty.implicit_springs",
        "status",
        "message",
    ]
    on_disk = pd.read_parquet(folder / "out" / "results.parquet")
    pd.testing.assert_frame_equal(on_disk, table, check_dtype=False)
    assert all(worker.startswith("tcp://127.0.0.1:") for worker in table["worker"])
    report = (folder / "out" / "report.html").read_text(encoding="utf-8")
    assert "9 cells (8 ok, 1 diverged)" in report
    for name in ("bouncing_ball-pareto.png", "bouncing_ball-convergence.png"):
        assert (folder / "out" / "plots" / name).stat().st_size > 10_000
        assert f"plots/{name}" in report


def test_a_cell_gives_the_numbers_of_the_same_run_made_directly(ball_sweep):
    """The impulse cell at dt = 2 ms, e = 0.5: its row against simulate() and the closed form
    computed here, in this process."""
    _, _, table, _ = ball_sweep
    row = table[
        (table["method"] == "impulse") & (table["simulation.dt"] == 0.002) & (table["materials.0.restitution"] == 0.5)
    ].iloc[0]
    scene = load_scene(
        "bouncing_ball", ["simulation.dt=0.002", "simulation.duration=1.0", "materials.0.restitution=0.5"]
    )
    run = simulate(scene.model, "impulse", scene.dt, scene.duration, threads=1, scene_name=scene.name)
    assert row["status"] == "ok" and row["steps"] == run.summary["steps"] == 500
    assert row["max_penetration_mm"] == run.summary["max_penetration"] * 1000.0
    energy = run.arrays["energy_kinetic"] + run.arrays["energy_potential"] + run.arrays["energy_elastic"]
    assert row["energy_drift_J"] == float(energy[-1] - energy[0])
    checks = closed_form.checks("bouncing_ball", scene.model, run.arrays)
    reached = [check.relative_error for check in checks if np.isfinite(check.measured)]
    assert reached and row["closed_form_error"] == max(reached)
    assert row["closed_form_unreached"] == len(checks) - len(reached)
    assert row["closed_form_error"] < 1e-3  # the rebound apex e² h, within 0.1 %


def test_a_cell_that_diverges_is_recorded_and_the_sweep_goes_on(ball_sweep):
    _, _, table, _ = ball_sweep
    blown = table[table["method"] == "penalty"].iloc[0]
    assert blown["status"] == "diverged" and "went wrong at t = " in blown["message"]
    assert 0.3 < blown["diverged_at_s"] < 0.6
    assert (table[table["method"] != "penalty"]["status"] == "ok").all()


def test_a_rerun_recomputes_nothing(ball_sweep):
    from contactlab import sweep

    folder, study, table, _ = ball_sweep
    cells = folder / "out" / "cells"
    stamps = {path.name: path.stat().st_mtime_ns for path in cells.iterdir()}

    class NoCluster:  # any job submitted would fail the test
        def submit(self, *arguments, **keywords):
            raise AssertionError("a cell was run again")

    lines = []
    again = sweep.run(study, folder / "out", client=NoCluster(), log=lines.append)
    assert lines == ["9 cells: 9 done already, 0 to run"]
    pd.testing.assert_frame_equal(again, table)
    assert {path.name: path.stat().st_mtime_ns for path in cells.iterdir()} == stamps


def test_a_cell_file_cut_short_is_said_and_its_cell_runs_again(ball_sweep, tmp_path):
    # issue 37: a truncated cell file counted as done, then failed the table's reading for good
    import shutil

    from contactlab import sweep

    folder, study, table, _ = ball_sweep
    out = tmp_path / "out"
    shutil.copytree(folder / "out", out)
    cut = out / "cells" / f"{table['key'][3]}.parquet"
    cut.write_bytes(cut.read_bytes()[: cut.stat().st_size // 2])
    lines = []
    again = sweep.run(study, out, workers=1, log=lines.append)
    assert lines[0].startswith(f"{cut} could not be read (") and lines[0].endswith("); that cell runs again")
    assert lines[1] == "9 cells: 8 done already, 1 to run"
    pd.testing.assert_frame_equal(_numbers(again), _numbers(table))
    assert pd.read_parquet(cut)["key"].tolist() == [table["key"][3]]  # written again, whole


# ---- a separately started scheduler and workers ------------------------------------------------------


def _free_port():
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def _dask(*arguments):
    return subprocess.Popen(
        [sys.executable, "-m", "distributed.cli.dask_" + arguments[0], *arguments[1:]],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )


@pytest.fixture
def scheduler():
    """A real Dask scheduler and two single-threaded workers, separate processes on 127.0.0.1."""
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    processes = [_dask("scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard")]
    processes += [
        _dask("worker", address, "--nthreads", "1", "--nworkers", "1", "--no-dashboard", "--host", "127.0.0.1")
        for _ in range(2)
    ]
    from distributed import Client

    with Client(address, timeout=60) as client:
        client.wait_for_workers(2, timeout=120)
    yield address, processes
    for process in processes:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGTERM)
    for process in processes:
        try:
            process.wait(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)


def _sweep_command(*arguments, cwd):
    return subprocess.run(
        [sys.executable, "-m", "contactlab", "sweep", *map(str, arguments)],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=600,
    )


def _numbers(table):
    """The table without what differs run to run (timings, workers); missing values all None."""
    table = table.drop(columns=[c for c in (*TIMING_COLUMNS, "cell_seconds") if c in table]).reset_index(drop=True)
    return table.astype(object).where(table.notna(), None)


def test_the_cluster_gives_the_local_table_and_survives_a_worker_killed_mid_study(tmp_path, scheduler, ball_sweep):
    address, processes = scheduler
    study = write(
        tmp_path,
        BALL_STUDY.replace('"simulation.duration" = [1.0]', '"simulation.duration" = [1.0, 2.0]').replace(
            'name = "ball"', 'name = "ball2"'
        ),
    )
    out = tmp_path / "out"
    command = subprocess.Popen(
        [sys.executable, "-m", "contactlab", "sweep", str(study), "--out", str(out), "--scheduler", address],
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline, killed = time.monotonic() + 300, None
    while time.monotonic() < deadline and command.poll() is None:  # kill a worker once cells finish
        if (out / "cells").is_dir() and len(os.listdir(out / "cells")) >= 2:
            os.killpg(processes[1].pid, signal.SIGKILL)
            killed = len(os.listdir(out / "cells"))
            break
        time.sleep(0.05)
    stdout, stderr = command.communicate(timeout=600)
    assert killed is not None and killed < 16  # it died mid-study
    assert processes[1].wait(timeout=10) == -signal.SIGKILL
    assert command.returncode == 0, stderr
    assert "16 cells (16 ok)" in stdout
    table = pd.read_parquet(out / "results.parquet")
    assert (table["status"] == "ok").all() and len(table) == 16
    local = ball_sweep[2]
    local = local[local["method"] != "penalty"][table.columns]  # without the penalty cell's own axes
    shared = table[table["simulation.duration"] == 1.0]
    pd.testing.assert_frame_equal(
        _numbers(shared).drop(columns="key"), _numbers(local).drop(columns="key"), check_dtype=False
    )
    again = _sweep_command(study, "--out", out, "--scheduler", address, cwd=tmp_path)
    assert again.returncode == 0 and "16 cells: 16 done already, 0 to run" in again.stderr


def test_a_bad_study_on_the_command_line_is_one_line_exit_2_and_nothing_written(tmp_path):
    write(tmp_path, '[grid]\nscenes = ["bouncing_ball"]\nmethods = ["teleport"]\n')
    result = _sweep_command("study.toml", cwd=tmp_path)
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert result.stderr.strip().count("\n") == 0 and "grid.methods: unknown method 'teleport'" in result.stderr
    assert os.listdir(tmp_path) == ["study.toml"]
    result = _sweep_command(write(tmp_path, BALL_STUDY), "--scheduler", f"tcp://127.0.0.1:{_free_port()}", cwd=tmp_path)
    assert result.returncode == 2 and "could not reach a Dask scheduler" in result.stderr.splitlines()[-1]
    assert sorted(os.listdir(tmp_path)) == ["study.toml"]


@pytest.mark.parametrize(
    "address, words",
    [
        ("tcp://127.0.0.1:99999", "must be a whole number from 1 to 65535, found '99999'"),
        ("tcp://127.0.0.1:0", "from 1 to 65535, found '0'"),
        ("tcp://127.0.0.1:-5", "from 1 to 65535, found '-5'"),
        ("tcp://127.0.0.1:http", "from 1 to 65535, found 'http'"),
        ("tcp://127.0.0.1", "expected tcp://HOST:PORT"),
        ("tcp://:8786", "expected tcp://HOST:PORT"),
        ("http://127.0.0.1:8786", "expected a Dask scheduler's tcp://HOST:PORT address"),
        ("127.0.0.1:8786", "expected a Dask scheduler's tcp://HOST:PORT address"),
    ],
)
def test_a_malformed_scheduler_address_is_refused_before_anything_runs(tmp_path, address, words):
    # issue 37: these went to Dask, which waited out its timeout (or advised 'dask worker http://…')
    from contactlab import sweep

    lines = []
    started = time.monotonic()
    with pytest.raises(InputError) as refused:
        sweep.run(write(tmp_path, BALL_STUDY), tmp_path / "out", scheduler=address, log=lines.append)
    assert time.monotonic() - started < 1.0
    assert refused.value.field == "--scheduler" and words in refused.value.message, refused.value
    assert "dask worker" not in refused.value.message and lines == []
    assert os.listdir(tmp_path) == ["study.toml"]


def test_a_scheduler_nobody_listens_at_fails_at_once_in_one_line(tmp_path):
    # issue 37: a refused connection waited Dask's 10 s, after a "N cells: … to run" line
    write(tmp_path, BALL_STUDY)
    address = f"tcp://127.0.0.1:{_free_port()}"
    started = time.monotonic()
    result = _sweep_command("study.toml", "--scheduler", address, cwd=tmp_path)
    seconds = time.monotonic() - started
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert result.stderr.splitlines() == [
        f"error: study.toml: --scheduler: could not reach a Dask scheduler at {address} (connection refused); "
        f"start one with 'dask scheduler' and workers with 'dask worker {address}'"
    ]
    assert seconds < 8.0, seconds  # python and contactlab's imports, then one refused connection
    assert os.listdir(tmp_path) == ["study.toml"]


def test_a_study_over_the_limits_of_a_run_stops_in_one_line_before_a_cluster_starts(tmp_path):
    write(tmp_path, BALL_STUDY.replace('"simulation.duration" = [1.0]', '"simulation.duration" = [1.0, 0.003]'))
    result = _sweep_command("study.toml", cwd=tmp_path)
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert result.stderr.splitlines() == [
        'error: study.toml: grid.set."simulation.dt": bouncing_ball with impulse (simulation.dt = 0.004, '
        "simulation.duration = 0.003, materials.0.restitution = 0.8): dt = 0.004 s is longer than duration = "
        "0.003 s, so the run would make one whole step of 0.004 s; give a dt no longer than the duration"
    ]
    assert result.stdout == "" and os.listdir(tmp_path) == ["study.toml"]  # no out/ball-sweep, no dashboard line


def _spin(stop):
    while not stop.is_set():
        pass


def test_a_local_cluster_takes_one_worker_per_idle_core():
    """A process spinning on a core takes that core from the default worker count; with every
    core kept busy there is still one worker."""
    import multiprocessing

    from contactlab import cluster

    cores = cluster.cores()
    stop = multiprocessing.Event()
    spinners = [multiprocessing.Process(target=_spin, args=(stop,)) for _ in range(cores)]
    try:
        spinners[0].start()
        time.sleep(0.5)
        assert cluster.default_workers() <= max(1, cores - 1)
        for spinner in spinners[1:]:
            spinner.start()
        time.sleep(0.5)
        assert cluster.default_workers() == 1
    finally:
        stop.set()
        for spinner in spinners:
            if spinner.pid is not None:
                spinner.join()


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_ctrl_c_stops_a_sweep_in_one_line_keeping_its_finished_cells_for_the_rerun(tmp_path, signum):
    """Ctrl-C in a terminal reaches the command and its workers: within a second the command
    exits 130 with one line (no traceback, no Dask log, no resource_tracker warning), and no
    worker outlives it. Issue 37: it took 5 s and warned of leaked semaphores. The same for a
    SIGTERM to the whole process group, as a job runner sends it (issue 59: a worker died of it,
    and Dask logged "Couldn't gather keys"): exit 143."""
    # 20 s cells (5,000-10,000 steps each), not 1 s: the signal must find cells still to run,
    # and 1 s cells of a ball finish in milliseconds once compiled (the six left could all end
    # between the second cell's file and the signal, and the sweep exit 0)
    write(
        tmp_path,
        BALL_STUDY.replace('name = "ball"', 'name = "stopped"').replace(
            '"simulation.duration" = [1.0]', '"simulation.duration" = [20.0]'
        ),
    )
    process = subprocess.Popen(
        [sys.executable, "-m", "contactlab", "sweep", "study.toml", "--workers", "1"],
        cwd=tmp_path,
        preexec_fn=interruptible,
        start_new_session=True,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    cells = tmp_path / "out" / "stopped-sweep" / "cells"
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and not (cells.is_dir() and len(os.listdir(cells)) >= 2):
        time.sleep(0.05)
    os.killpg(process.pid, signum)
    sent = time.monotonic()
    _, stderr = process.communicate(timeout=300)
    took = time.monotonic() - sent
    kept = len(os.listdir(cells))
    assert process.returncode == 128 + signum and 2 <= kept < 8 and took < 2.0, (took, stderr)
    news = ("8 cells: 0 done already, 8 to run", "Dask dashboard: ", "compiling contact kernels")
    assert [line for line in messages(stderr) if not line.startswith(news)] == [
        f"interrupted ({signal.Signals(signum).name}); written before it: "
        f"{os.path.join('out', 'stopped-sweep', 'cells')}"
    ], stderr
    assert not any(name.startswith(".partial-") for name in os.listdir(cells))
    assert not alive_in_group(process.pid, 1.0)
    again = _sweep_command("study.toml", "--workers", "1", cwd=tmp_path)
    assert again.returncode == 0 and f"8 cells: {kept} done already, {8 - kept} to run" in again.stderr


def test_a_sweep_on_a_local_cluster_says_compiling_once_however_many_workers_compile(tmp_path):
    # issue 59: "compiling contact kernels for first use…" came once a worker, 3 times inside the
    # sweep's progress. Each cell here first compiles a kernel no cache holds (as a cell does on
    # an empty cache), on each of the 2 workers, then runs as a cell does.
    script = """
import sys, time
import numba
from contactlab import cli, sweep
from contactlab.compiling import compile_notice

def run_cell(job, cell=sweep.run_cell):
    with compile_notice():
        numba.njit(lambda x: x + 1.0)(1.0)  # a function of its own: compiled here, every time
    time.sleep(0.5)  # no worker takes every cell
    return cell(job)

sweep.run_cell = run_cell
sys.exit(cli.main(sys.argv[1:]))
"""
    study = BALL_STUDY.replace('["impulse", "constraints"]', '["impulse"]').replace("[1.0]", "[0.2]")
    write(tmp_path, study)
    done = subprocess.run(
        [sys.executable, "-c", script, "sweep", "study.toml", "--workers", "2", "--out", "out"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr
    assert done.stderr.count(NOTICE) == 1, done.stderr
    workers = pd.read_parquet(tmp_path / "out" / "results.parquet")["worker"]
    assert len(workers) == 4 and workers.nunique() == 2  # both compiled: each would have said it


def test_a_single_cell_runs_here_and_says_so(tmp_path):
    # issue 59: a study too small to repay a cluster started one all the same (seconds)
    from contactlab import sweep

    one = BALL_STUDY.replace('["impulse", "constraints"]', '["impulse"]').replace("[0.004, 0.002]", "[0.004]")
    study = write(tmp_path, one.replace("[0.8, 0.5]", "[0.8]"))
    lines = []
    table = sweep.run(study, tmp_path / "out", log=lines.append)
    assert lines == [
        "1 cells: 0 done already, 1 to run",
        "1 cell to run: it runs here (a local cluster would only add the seconds it takes to start)",
    ]
    assert table["status"].tolist() == ["ok"] and table["worker"].tolist() == ["local"]
    assert {"cells", "results.parquet", "report.html"} <= set(os.listdir(tmp_path / "out"))


class _NoClusterStarted(Exception):
    pass


def _refusing_connect(*arguments, **options):
    raise _NoClusterStarted


def test_a_study_too_small_to_repay_a_cluster_runs_here_and_says_so(tmp_path, monkeypatch):
    # issue 59: a local cluster takes seconds to start; a study of less work than that ran slower
    # on one (0.28x for 16 cells of 0.8 s in all, benchmarks/results/sweep_speedup.md)
    from contactlab import cluster, sweep

    monkeypatch.setattr(cluster, "connect", _refusing_connect)
    study = write(tmp_path, BALL_STUDY.replace("[1.0]", "[0.2]"))
    lines = []
    table = sweep.run(study, tmp_path / "out", log=lines.append)
    assert lines[0] == "8 cells: 0 done already, 8 to run"
    first = table["cell_seconds"][0] - table["compile_seconds"][0]
    assert lines[1] == (
        f"the first cell ran in {first:.2g} s: the 7 others (about {7 * first:.2g} s) run here too "
        "(a local cluster repays its start from about 5 s of cells)"
    )
    assert table["status"].tolist() == ["ok"] * 8 and set(table["worker"]) == {"local"}


def test_a_study_worth_a_cluster_spreads_the_cells_after_the_first(tmp_path, monkeypatch):
    from contactlab import cluster, sweep

    monkeypatch.setattr(cluster, "LOCAL_CLUSTER_PAYS_FROM", 0.0)  # any study repays it
    monkeypatch.setattr(cluster, "connect", _refusing_connect)
    study = write(tmp_path, BALL_STUDY.replace("[1.0]", "[0.2]"))
    with pytest.raises(_NoClusterStarted):
        sweep.run(study, tmp_path / "out")
    assert len(os.listdir(tmp_path / "out" / "cells")) == 1  # the first cell ran here, and stays done


def test_a_study_of_many_short_runs_steps_its_cells_through_the_compiled_loop():
    # issue 36: a study is thousands of short runs, each of which stepped the loop's body from
    # Python (about 30 ms a 720-step ball run against 3 ms through the compiled loop) unless the
    # cells of a scene and method together repaid compiling it; every cell now takes the loop
    from types import SimpleNamespace

    from contactlab.study import Cell
    from contactlab.sweep import _jobs, run_cell

    cells = [Cell("bouncing_ball", "impulse", (("simulation.duration", 0.05),), "summary", f"k{n}") for n in range(2)]
    jobs = _jobs(cells, SimpleNamespace(record="summary"), ".")
    rows = [run_cell(job) for _, job in jobs]
    assert all(row["status"] == "ok" and row["stepping"] == "compiled loop" for row in rows)


def test_a_cluster_holds_a_few_jobs_per_thread_not_the_whole_study():
    """Issue 37: a 100,000-cell study went to the scheduler at once (a 28 MB graph), and stopped,
    had 100,000 tasks to cancel, which timed out after 60 s. Jobs are submitted as others finish."""
    from contactlab import cluster

    held, kept = [], []
    with cluster.connect(workers=1) as client:
        jobs = ((str(index), f"/jobs/{index}") for index in range(300))
        for key, result in cluster.run_tasks(client, os.path.basename, jobs):
            assert result == key
            tasks = client.cluster.scheduler.tasks.values()
            held.append(sum(task.state not in ("memory", "released", "forgotten", "erred") for task in tasks))
            kept.append(len(tasks))
    # Jobs waiting or running on the scheduler: never more than the window. A finished job's
    # release reaches the scheduler asynchronously (CI once saw 33 tasks, one of them done and
    # its release in transit), so all it holds is bounded by the window twice, not by the 300.
    assert len(held) == 300 and max(held) <= cluster.MIN_WINDOW
    assert max(kept) <= 2 * cluster.MIN_WINDOW
