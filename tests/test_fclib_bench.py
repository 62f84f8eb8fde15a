"""contactlab.fclib_bench: the performance profile by hand, a real run on a local Dask cluster,
and the argument checks."""

import contextlib
import shutil

import numpy as np
import pandas as pd
import pytest
from conftest import FCLIB

from contactlab import fclib_bench
from contactlab.errors import InputError
from contactlab.fclib import read_problem
from contactlab.fclib_bench import COLUMNS, MAX_ITERATIONS, Job, bench, performance_profile, run_job
from contactlab.lcp import natural_map_error, solve_friction_contact

SOLVERS = ["nsgs", "newton"]
TOL = 1e-8
GARBAGE = "garbage.dat"
TINY = "3 1 0 3 3 3 3 1 0 0 0 1 0 0 0 1 -1 0 0 0.5\n"  # a Siconos dense problem: 1 contact


# ----------------------------------------------------------------------------- the profile


def test_profile_by_hand():
    # times [s] of solvers a, b on 4 problems; ratios to the best solver that solved each:
    #   p0: a 1 (best), b 2          p1: a 3, b 1 (best)
    #   p2: a 1 (b failed, though faster: ignored)     p3: nobody solved it: unsolved for all
    times = [[1.0, 2.0], [3.0, 1.0], [2.0, 0.5], [1.0, 1.0]]
    solved = [[True, True], [True, True], [True, False], [False, False]]
    taus, fractions = performance_profile(times, solved, ["a", "b"])
    assert taus.tolist() == [1.0, 2.0, 3.0]
    assert fractions["a"].tolist() == [2 / 4, 2 / 4, 3 / 4]  # p0, p2 at τ = 1; p1 joins at τ = 3
    assert fractions["b"].tolist() == [1 / 4, 2 / 4, 2 / 4]  # p1 at τ = 1; p0 joins at τ = 2


def test_profile_nothing_solved_and_default_names():
    taus, fractions = performance_profile([[1.0, np.nan]], [[False, False]])
    assert taus.tolist() == [1.0]
    assert list(fractions) == [0, 1]
    assert fractions[0].tolist() == [0.0] and fractions[1].tolist() == [0.0]


def test_profile_checks_its_input():
    with pytest.raises(InputError) as caught:
        performance_profile([[1.0, 2.0]], [[True]])
    assert caught.value.field == "times"
    with pytest.raises(InputError):
        performance_profile([[0.0]], [[True]])  # a solved pair needs a positive time


# ----------------------------------------------------------------------------- a real run


def smallest_problems(count=3):
    """The ``count`` smallest problem files of the repository's data/fclib (by bytes)."""
    files = [path for path in FCLIB.iterdir() if path.suffix in fclib_bench.PROBLEM_SUFFIXES]
    return sorted(files, key=lambda path: (path.stat().st_size, path.name))[:count]


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """bench on copies of the 3 smallest problems plus a garbage file, nsgs and newton, on a
    local cluster of 2 worker processes, one timed solve each."""
    folder = tmp_path_factory.mktemp("problems")
    for path in smallest_problems():
        shutil.copy(path, folder / path.name)
    (folder / GARBAGE).write_text("this is not a friction problem\n")
    (folder / "notes.txt").write_text("not a problem file: not listed\n")
    out = tmp_path_factory.mktemp("bench") / "out"
    return folder, bench(folder, SOLVERS, out, workers=2, tol=TOL, repeats=1)


def test_every_problem_and_solver_has_a_row(run):
    folder, result = run
    table = result.table
    assert list(table.columns) == list(COLUMNS)
    names = sorted(path.name for path in folder.iterdir() if path.suffix in fclib_bench.PROBLEM_SUFFIXES)
    assert len(names) == 4
    expected = [(name, solver) for name in names for solver in SOLVERS]
    assert list(zip(table["problem"], table["solver"])) == expected  # problems sorted, solvers as asked
    assert table["worker"].str.startswith("tcp://127.0.0.1:").all()  # ran on the cluster's workers


def test_errors_are_recomputed_and_match_a_serial_solve(run):
    folder, result = run
    good = result.table[result.table["status"] == "ok"]
    assert len(good) == 6 and good["converged"].all()  # the smallest problems: both solvers solve them
    for row in good.itertuples(index=False):
        assert row.error <= TOL
        problem = read_problem(folder / row.problem)
        assert row.contacts == problem.nc
        serial = solve_friction_contact(
            problem.W, problem.q, problem.mu, method=row.solver, tol=TOL, max_iterations=MAX_ITERATIONS[row.solver]
        )
        assert row.iterations == serial.iterations
        assert row.error == natural_map_error(problem.W, problem.q, problem.mu, serial.r)
        assert row.seconds > 0


def test_a_garbage_file_gives_error_rows(run):
    _, result = run
    bad = result.table[result.table["problem"] == GARBAGE]
    assert list(bad["solver"]) == SOLVERS
    assert bad["status"].str.startswith("error: InputError: ").all()
    assert not bad["converged"].any()
    assert bad["contacts"].isna().all() and bad["error"].isna().all() and bad["seconds"].isna().all()


def test_the_files(run):
    _, result = run
    assert result.out.is_dir()
    assert {path.name for path in result.out.iterdir()} == {"results.csv", "results.md", "profile.png"}
    back = pd.read_csv(result.csv)
    assert list(back.columns) == list(COLUMNS) and len(back) == len(result.table)
    assert back["error"].tolist() == pytest.approx(result.table["error"].tolist(), nan_ok=True, rel=1e-15)
    text = result.markdown.read_text()
    assert "| " + " | ".join(COLUMNS) + " |" in text
    assert text.count(f"| {GARBAGE} |") == 2
    assert "Machine: " in text and "cores" in text and "NUMBA_NUM_THREADS" in text and "before" in text
    assert result.profile_png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_run_job_reports_instead_of_raising(tmp_path):
    path = tmp_path / "empty.h5"
    path.write_bytes(b"")
    row = run_job(Job(str(path), "nsgs", TOL, 10, 1))
    assert set(row) == set(COLUMNS)
    assert row["status"].startswith("error: ") and row["converged"] is False and row["worker"] == "local"


def test_an_exception_from_run_tasks_gives_a_row(tmp_path, monkeypatch):
    # A job whose workers kept dying comes back from run_tasks as the exception: still a row.
    (tmp_path / "p.dat").write_text(TINY)

    class Client:
        def run(self, function, on_error="raise"):
            return {}

    @contextlib.contextmanager
    def connect(scheduler, workers):
        yield Client()

    def run_tasks(client, function, jobs, progress=False, description=""):
        for key, _ in jobs:
            yield key, RuntimeError("the worker died\nwhile solving")

    monkeypatch.setattr(fclib_bench.cluster, "connect", connect)
    monkeypatch.setattr(fclib_bench.cluster, "run_tasks", run_tasks)
    result = bench(tmp_path, ["apgd"], tmp_path / "out", repeats=1)
    assert result.table["status"].tolist() == ["error: RuntimeError: the worker died"]
    assert result.table["worker"].tolist() == [""] and not result.table["converged"].any()
    assert "Machine: unknown" in result.markdown.read_text() and result.profile_png.exists()


# ----------------------------------------------------------------------------- argument checks


def test_missing_folder(tmp_path):
    with pytest.raises(InputError) as caught:
        bench(tmp_path / "nowhere", out=tmp_path / "out")
    assert caught.value.field == "DIR"
    assert not (tmp_path / "out").exists()


def test_folder_without_problems(tmp_path):
    (tmp_path / "README.md").write_text("no problems here\n")
    with pytest.raises(InputError) as caught:
        bench(tmp_path, out=tmp_path / "out")
    assert caught.value.field == "DIR" and ".hdf5" in caught.value.message


def test_unknown_solver(tmp_path):
    (tmp_path / "p.dat").write_text(TINY)
    for solvers in (["nsgs", "lemke"], "nsgs,lemke"):
        with pytest.raises(InputError) as caught:
            bench(tmp_path, solvers, out=tmp_path / "out")
        assert caught.value.field == "--solvers"
        assert "'lemke'" in caught.value.message
        assert all(name in caught.value.message for name in fclib_bench.SOLVERS)  # the valid choices
    with pytest.raises(InputError) as caught:
        bench(tmp_path, [], out=tmp_path / "out")
    assert caught.value.field == "--solvers"


def test_other_settings(tmp_path):
    (tmp_path / "p.dat").write_text(TINY)
    (tmp_path / "file").write_text("")
    for keywords, field in (
        (dict(repeats=0), "--repeats"),
        (dict(tol=-1.0), "--tol"),
        (dict(max_iterations=0), "--max-iterations"),
        (dict(out=tmp_path / "file"), "--out"),
        (dict(scheduler="http://127.0.0.1:8786"), "--scheduler"),
        (dict(scheduler="tcp://127.0.0.1:65536"), "--scheduler"),
        (dict(workers=0), "--workers"),
    ):
        with pytest.raises(InputError) as caught:
            bench(tmp_path, **{"out": tmp_path / "out", **keywords})
        assert caught.value.field == field


# ----------------------------------------------------------------------------- the command line


def test_the_command_writes_the_table_and_profile_and_refuses_a_bad_solver_in_one_line(tmp_path):
    import subprocess
    import sys

    folder = tmp_path / "problems"
    folder.mkdir()
    for path in smallest_problems(2):
        shutil.copy(path, folder / path.name)
    command = [
        sys.executable,
        "-m",
        "contactlab",
        "fclib",
        "bench",
        str(folder),
        "--solvers",
        "newton",
        "--workers",
        "1",
        "--repeats",
        "1",
        "--out",
        str(tmp_path / "out"),
    ]
    done = subprocess.run(command, capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("2 problems: newton solved 2")
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["profile.png", "results.csv", "results.md"]
    refused = subprocess.run(
        [*command[:6], "--solvers", "lemke"], capture_output=True, text=True, timeout=120, cwd=tmp_path
    )
    assert refused.returncode == 2 and refused.stderr.count("\n") == 1 and "Traceback" not in refused.stderr
    assert "--solvers: expected solvers among nsgs, staggered, apgd, newton, found 'lemke'" in refused.stderr
