"""Issue 59: the output folder of every command that writes one. Something that is not a folder
is a usage error; a second command writing into a folder another one is writing is refused,
naming the first (contactlab.folder_lock, as ``run`` had it); a write that fails names its file."""

import errno
import os
import subprocess
import sys
import warnings

import pytest

from contactlab import cli, record
from contactlab.folder_lock import LOCK_NAME

STUDY = """
[study]
name = "ball"
[grid]
scenes = ["bouncing_ball"]
methods = ["impulse"]
[grid.set]
"simulation.duration" = [0.5]
"""
TINY_PROBLEM = "3 1 0 3 3 3 3 1 0 0 0 1 0 0 0 1 -1 0 0 0.5\n"  # one contact, Siconos' dense text
MEASURED = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "data", "measured")


def _inputs(folder):
    """The inputs the commands below read, written into ``folder``: study.toml (STUDY) and
    problems/tiny.dat (an FCLIB problem of one contact, Siconos' text format)."""
    (folder / "study.toml").write_text(STUDY, encoding="utf-8")
    (folder / "problems").mkdir()
    (folder / "problems" / "tiny.dat").write_text(TINY_PROBLEM, encoding="utf-8")


def _main(monkeypatch, capsys, *argv):
    """(exit code, stderr lines) of the command line run in this process."""
    monkeypatch.setattr(warnings, "showwarning", warnings.showwarning)  # main() replaces it
    code = cli.main([str(a) for a in argv])
    return code, capsys.readouterr().err.splitlines()


@pytest.mark.parametrize(
    "command",
    [
        ["run", "bouncing_ball"],
        ["compare", "bouncing_ball", "--no-video"],
        ["sweep", "study.toml"],
        ["validate", os.path.join(MEASURED, "cube_toss.toml"), os.path.join(MEASURED, "toss_01.h5")],
        ["fclib", "bench", "problems", "--workers", "1"],
    ],
)
@pytest.mark.parametrize("out", ["/dev/null", "a_file", "a_file/inside"])
def test_an_out_that_is_not_a_folder_is_a_usage_error(tmp_path, monkeypatch, capsys, command, out):
    # issue 59: run --out /dev/null (or an existing file) was exit 1, "File exists"
    monkeypatch.chdir(tmp_path)
    _inputs(tmp_path)
    (tmp_path / "a_file").write_text("mine\n", encoding="utf-8")
    code, err = _main(monkeypatch, capsys, *command, "--out", out)
    there = "/dev/null" if out == "/dev/null" else "a_file"
    assert code == 2 and len(err) == 1, err
    assert err[0].endswith(f": --out: {there} is there and is not a folder; give a new folder or an existing one")
    assert sorted(os.listdir(tmp_path)) == ["a_file", "problems", "study.toml"]
    assert (tmp_path / "a_file").read_text(encoding="utf-8") == "mine\n"


@pytest.fixture
def held_elsewhere(tmp_path):
    """A folder whose lock another process holds, as a command writing it would; that
    process's id."""
    folder = tmp_path / "out"
    folder.mkdir()
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys, time\nfrom contactlab.folder_lock import held\n"
            "with held(sys.argv[1]):\n    print('held', flush=True)\n    time.sleep(60)\n",
            str(folder),
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    assert holder.stdout.readline() == "held\n"
    yield folder, holder.pid
    holder.kill()
    holder.wait()


@pytest.mark.parametrize(
    "command",
    [
        ["compare", "bouncing_ball", "--no-video", "--workers", "1"],
        ["sweep", "study.toml", "--workers", "1"],
        ["validate", os.path.join(MEASURED, "cube_toss.toml"), os.path.join(MEASURED, "toss_01.h5")],
        [
            "fit",
            os.path.join(MEASURED, "cube_toss.toml"),
            *(os.path.join(MEASURED, f"toss_0{k}.h5") for k in (1, 2)),
            "--vary",
            "materials.0.friction=0.1:0.5",
            "--methods",
            "impulse",
            "--workers",
            "1",
        ],
        ["fclib", "bench", "problems", "--workers", "1"],
    ],
)
def test_a_second_writer_of_a_folder_is_refused_naming_the_first(
    tmp_path, monkeypatch, capsys, held_elsewhere, command
):
    # issue 59: two compares into one --out both exited 0 and mixed their reports; two sweeps
    # computed the same cells twice; fclib bench had no lock at all
    folder, holder = held_elsewhere
    monkeypatch.chdir(tmp_path)
    _inputs(tmp_path)
    code, err = _main(monkeypatch, capsys, *command, "--out", folder)
    assert code == 2 and len(err) == 1, err
    assert f"--out: {folder} is being written by another contactlab command (process {holder} on " in err[0]
    assert err[0].endswith("give another --out, or run again once that one has finished")
    assert os.listdir(folder) == [LOCK_NAME]  # nothing of the refused command's


def test_a_write_that_fails_names_its_file(tmp_path, monkeypatch, capsys):
    # issue 59: a full disk said "cannot write the outputs: … No space left on device (None)"
    path = str(tmp_path / "summary.json")

    def full_disk(args, restart=False):  # a write's ENOSPC names no file
        with record.atomic_path(path) as temporary:
            with open(temporary, "wb") as stream:
                stream.write(b"{")
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(cli, "_run", full_disk)
    code, err = _main(monkeypatch, capsys, "run", "bouncing_ball")
    assert code == 1
    assert err == [f"error: cannot write the outputs: {os.strerror(errno.ENOSPC)} ({path})"]
    assert os.listdir(tmp_path) == []  # the temporary file is gone


def test_a_comparison_owns_its_folder_an_earlier_ones_methods_go_and_the_users_files_stay(tmp_path):
    # issue 59: compare --methods impulse into the folder of an earlier 4-method comparison left
    # the 3 other method folders there, to be taken for this comparison's
    def compare(methods):
        return subprocess.run(
            [sys.executable, "-m", "contactlab", "compare", "bouncing_ball", "--no-video", "--methods", methods]
            + ["--duration", "0.2", "--workers", "1", "--out", "out"],
            cwd=tmp_path,
            capture_output=True,
            text=True,
            timeout=600,
        )

    out = tmp_path / "out"
    first = compare("projection,impulse,constraints")
    assert first.returncode == 0, first.stderr
    assert {"projection", "impulse", "constraints"} <= set(os.listdir(out))
    (out / "projection" / "notes.txt").write_text("mine\n", encoding="utf-8")  # a user's file in a method folder
    (out / "penalty").mkdir()  # a folder named after a method that holds no run: the user's
    (out / "penalty" / "plan.txt").write_text("mine\n", encoding="utf-8")
    (out / "mine").mkdir()
    second = compare("impulse")
    assert second.returncode == 0, second.stderr
    assert "constraints" not in os.listdir(out)  # the earlier comparison's, wholly
    assert os.listdir(out / "projection") == ["notes.txt"]  # its run gone, the user's file kept
    assert os.listdir(out / "penalty") == ["plan.txt"] and os.listdir(out / "mine") == []
    assert {"trajectory.h5", "summary.json", "plots"} <= set(os.listdir(out / "impulse"))
    with open(out / "comparison.csv", encoding="utf-8") as stream:
        assert [line.split(",")[0] for line in stream.read().splitlines()[1:]] == ["impulse"]
    assert LOCK_NAME not in os.listdir(out)
