"""The command line end to end: outputs, the JSON summary, and one clear line per mistake."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest
from conftest import messages

from contactlab import simulate
from contactlab.compiling import NOTICE
from contactlab.record import write_outputs
from contactlab.store import open_trajectory


def contactlab(*args, cwd):
    return subprocess.run(
        [sys.executable, "-m", "contactlab", *args], cwd=cwd, capture_output=True, text=True, timeout=600
    )


def test_run_bouncing_ball_json_and_trajectory(tmp_path):
    result = contactlab("run", "bouncing_ball", "--method", "impulse", "--json", "--duration", "3.5", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)  # stdout is exactly one JSON object
    for key in (
        "scene",
        "method",
        "dt",
        "steps",
        "wall_seconds",
        "steps_per_second",
        "compile_seconds",
        "recording_seconds",
        "first_step_seconds",
        "bodies",
        "particles",
        "max_contacts",
        "max_penetration",
        "energy",
        "trajectory",
    ):
        assert key in summary
    assert set(summary["energy"]) == {"initial", "final", "max"}
    assert summary["scene"] == "bouncing_ball" and summary["method"] == "impulse"
    out = tmp_path / "out" / "bouncing_ball-impulse"
    assert json.loads((out / "summary.json").read_text()) == summary
    run = open_trajectory(out / "trajectory.h5")
    T = len(run["time"])
    assert T == summary["steps"] + 1
    assert run["body_position"].shape == (T, 1, 3) and run["body_orientation"].shape == (T, 1, 4)
    assert run["particle_position"].shape == (T, 0, 3)  # empty, not missing
    for name in (
        "body_velocity",
        "body_angular_velocity",
        "particle_velocity",
        "energy_kinetic",
        "energy_potential",
        "energy_elastic",
        "max_penetration",
        "contact_count",
    ):
        assert name in run
    assert list(run["body_names"]) == ["ball"] or len(run["body_names"]) == 1
    # the rebound apexes follow h0 eps^(2n) (the scene: 1 m drop, eps = 0.8, r = 0.1)
    z = run["body_position"][:, 0, 2] - 0.1
    vz = run["body_velocity"][:, 0, 2]
    turning = np.nonzero((vz[:-1] > 0) & (vz[1:] <= 0))[0]
    apexes = np.array([z[i : i + 2].max() for i in turning])[:3]
    np.testing.assert_allclose(apexes, 0.8 ** (2 * np.arange(1, 4)), rtol=0.02)
    # the scene's stated expectation, checked: the first two apexes, each with its verdict
    checks = {check["quantity"]: check for check in summary["checks"]}
    assert set(checks) == {"rebound 1 apex", "rebound 2 apex"}
    assert checks["rebound 1 apex"]["measured"] == pytest.approx(apexes[0], abs=1e-3)
    assert all(check["passed"] for check in checks.values())


def test_run_prints_each_expectation_with_its_number_and_verdict(tmp_path):
    result = contactlab(
        "run", "bouncing_ball", "--method", "projection", "--duration", "1.0", "--no-plots", cwd=tmp_path
    )
    assert result.returncode == 0, result.stderr
    lines = [line for line in result.stdout.splitlines() if line.startswith("Expectation: ")]
    # projection is inelastic: the ball lands and stays, so no apex is ever reached
    assert lines == [
        "Expectation: rebound 1 apex: not reached (expected 0.64 ± 0.014): FAIL",
        "Expectation: rebound 2 apex: not reached (expected 0.4096 ± 0.0092): FAIL",
    ]


def test_record_every_and_out(tmp_path):
    result = contactlab(
        "run", "sliding_block", "--record-every", "10", "--duration", "0.2", "--out", "here", "--json", cwd=tmp_path
    )
    assert result.returncode == 0, result.stderr
    run = open_trajectory(tmp_path / "here" / "trajectory.h5")
    steps = json.loads(result.stdout)["steps"]
    assert len(run["time"]) == steps // 10 + 1


def test_set_overrides_a_field_by_path(tmp_path):
    result = contactlab(
        "run", "sliding_block", "--set", "bodies.0.velocity=[1,0,0]", "--duration", "0.01", "--json", cwd=tmp_path
    )
    assert result.returncode == 0, result.stderr
    run = open_trajectory(tmp_path / "out" / "sliding_block-impulse" / "trajectory.h5")
    assert run["body_velocity"][0, 0, 0] == 1.0


def test_demo_runs_the_default_scene_and_says_where(tmp_path):
    result = contactlab(cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert "out/bouncing_ball-impulse/trajectory.h5" in result.stdout
    assert (tmp_path / "out" / "bouncing_ball-impulse" / "trajectory.h5").exists()


def test_scenes_lists_one_line_each(tmp_path):
    result = contactlab("scenes", cwd=tmp_path)
    lines = result.stdout.strip().splitlines()
    assert result.returncode == 0 and any(line.startswith("bouncing_ball ") for line in lines)


BAD_SCENE = """
[simulation]
dt = 0.001
[[bodies]]
shape = "sphere"
radius = 0.1
mass = -1.0
"""


@pytest.mark.parametrize(
    "args, scene_text, expected",
    [
        (["run", "scene.toml"], BAD_SCENE, "bodies[0].mass"),
        (["run", "scene.toml"], BAD_SCENE.replace("radius", "raduis"), "did you mean 'radius'"),
        (["run", "scene.toml"], "[simulation\ndt = 1", "scene.toml"),
        (["run", "missing.toml"], None, "missing.toml"),
        (["run", "no_such_scene"], None, "no_such_scene"),
        (["run", "bouncing_ball", "--dt", "0"], None, "simulation.dt"),
        (["run", "bouncing_ball", "--dt", "nan"], None, "simulation.dt"),
        (["run", "bouncing_ball", "--method", "warp"], None, "method"),
        (["run", "bouncing_ball", "--set", "bodies.7.mass=1"], None, "bodies"),
        (["run", "bouncing_ball", "--set", "nonsense"], None, "nonsense"),
        (["run", "bouncing_ball", "--set", "materials.0.friction=-1"], None, "materials[0].friction"),
        (["run", "bouncing_ball", "--record-every", "0"], None, "--record-every"),
        (["run", "bouncing_ball", "--integrator", "rk4"], None, "integrator"),
        (["run", "bouncing_ball", "--set", "method.impulse.iteratons=3"], None, "did you mean 'iterations'"),
        (["run", "bouncing_ball", "--dt", "abc"], None, "simulation.dt"),
        (["frobnicate"], None, "invalid choice"),
    ],
)
def test_wrong_input_gives_one_line_exit_2_and_no_output(tmp_path, args, scene_text, expected):
    if scene_text is not None:
        (tmp_path / "scene.toml").write_text(scene_text)
    result = contactlab(*args, cwd=tmp_path)
    assert result.returncode == 2
    assert result.stdout == ""
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("error: ") and expected in lines[0]
    assert "Traceback" not in result.stderr
    assert not (tmp_path / "out").exists()


def test_a_failed_write_leaves_no_folder_and_no_partial_file(tmp_path):
    target = tmp_path / "run"

    class Unsaveable:
        def __array__(self, *args, **kwargs):
            raise OSError("disk full")

    with pytest.raises(OSError):
        write_outputs(str(target), {"time": np.zeros(3), "bad": Unsaveable()}, {})
    assert not target.exists()
    existing = tmp_path / "existing"
    existing.mkdir()
    with pytest.raises(OSError):
        write_outputs(str(existing), {"bad": Unsaveable()}, {})
    assert os.listdir(existing) == []


def test_penalty_stiffness_too_high_for_dt_stops_in_one_line_keeping_the_run(tmp_path):
    """Kept explicit, a spring that grows 105× a step: the health check stops the run (exit 3)
    with one line naming the check, the time and the fix, and the run up to then is written,
    its summary marked diverged."""
    result = contactlab(
        "run",
        "incline",
        "--method",
        "penalty",
        "--set",
        "method.penalty.stiffness=1e6",
        "--set",
        "method.penalty.implicit_springs=never",
        "--duration",
        "0.2",
        cwd=tmp_path,
    )
    assert result.returncode == 3, result.stderr
    lines = [line for line in messages(result.stderr.strip()) if not line.startswith(NOTICE)]  # NOTICE: on a cold cache
    assert len(lines) == 1 and lines[0].startswith("error: the run went wrong at t = ")
    assert "too long for penalty stiffness 1e+06 N/m" in lines[0] and "backward_euler" in lines[0]
    assert "Traceback" not in result.stderr and "out/incline-penalty" in lines[0]
    with open(tmp_path / "out" / "incline-penalty" / "summary.json", encoding="utf-8") as stream:
        summary = json.load(stream)
    assert summary["diverged"]["check"] in ("energy", "speed", "depth", "finite")
    trajectory = open_trajectory(tmp_path / "out" / "incline-penalty" / "trajectory.h5")
    assert trajectory["time"][-1] == pytest.approx(summary["diverged"]["time"])
    assert summary["options"]["stiffness"] == 1e6 and summary["implicit_spring_steps"] == 0
    allowed = contactlab(
        "run",
        "incline",
        "--method",
        "penalty",
        "--set",
        "method.penalty.stiffness=1e6",
        "--set",
        "method.penalty.implicit_springs=never",
        "--duration",
        "0.02",
        "--allow-divergence",
        "--json",
        "--no-plots",
        cwd=tmp_path,
    )
    assert allowed.returncode in (0, 3), allowed.stderr  # allowed: on until the state is not finite
    if allowed.returncode == 0:
        assert json.loads(allowed.stdout)["health"]["violations"]


def test_penalty_springs_too_stiff_for_dt_go_implicit_and_the_summary_says_so(tmp_path):
    result = contactlab(
        "run",
        "incline",
        "--method",
        "penalty",
        "--set",
        "method.penalty.stiffness=1e6",
        "--duration",
        "0.02",
        cwd=tmp_path,
    )
    assert result.returncode == 0, result.stderr
    assert [line for line in messages(result.stderr.strip()) if not line.startswith(NOTICE)] == []
    assert "too stiff for symplectic_euler at this dt in 5 steps: those stepped them by backward Euler" in result.stdout
    with open(tmp_path / "out" / "incline-penalty" / "summary.json", encoding="utf-8") as stream:
        assert json.load(stream)["implicit_spring_steps"] == 5


def test_penalty_with_backward_euler_from_the_command_line(tmp_path):
    result = contactlab(
        "run",
        "box_stack",
        "--method",
        "penalty",
        "--integrator",
        "backward_euler",
        "--duration",
        "0.2",
        "--json",
        cwd=tmp_path,
    )
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary["integrator"] == "backward_euler" and summary["solver"]["max_iterations"] >= 1
    assert summary["max_penetration"] < 0.005  # k = m g / 1 mm for the heaviest box, implicit


def test_cloth_drape_with_projection_comes_to_rest(tmp_path):
    result = contactlab("run", "cloth_drape", "--method", "projection", "--record-every", "10", "--json", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    run = open_trajectory(tmp_path / "out" / "cloth_drape-projection" / "trajectory.h5")
    kinetic = run["energy_kinetic"]
    assert kinetic.max() > 0.1 and kinetic[-1] < 1e-4 * kinetic.max()  # it fell, then stopped
    assert run["triangles"].shape == (2 * 24 * 24, 3) and (run["particle_cloth"] == 0).all()
    final = run["particle_position"][-1]
    assert final[:, 2].min() >= 0.005 - 1e-6  # on the floor, at its thickness
    to_sphere = np.linalg.norm(final - [0.0, 0.0, 0.3], axis=1)
    assert to_sphere.min() >= 0.25 + 0.005 - 1e-6  # and never inside the sphere


def test_run_with_video_export_and_plots_then_render_and_export_again(tmp_path):
    result = contactlab(
        "run",
        "box_pyramid",
        "--duration",
        "0.1",
        "--video",
        "--fps",
        "20",
        "--export",
        "usd,ply",
        "--out",
        "run",
        cwd=tmp_path,
    )
    assert result.returncode == 0, result.stderr
    out = tmp_path / "run"
    for name in (
        "video.mp4",
        "video.gif",
        "still.png",
        "run.usd",
        "plots/energy.png",
        "plots/penetration.png",
        "plots/contacts.png",
        "plots/residual.png",
        "frames/frame_00000.ply",
    ):
        assert (out / name).is_file(), name
        assert name.replace("00000", "*") in result.stdout  # the summary says where everything is
    run = open_trajectory(out / "trajectory.h5")
    assert len(list((out / "frames").iterdir())) == len(run["time"])
    assert not [p for p in out.rglob(".partial-*")]
    (out / "still.png").unlink()
    result = contactlab("render", "run", "--fps", "10", "--width", "320", "--height", "240", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    import imageio.v3 as iio

    assert iio.imread(out / "still.png").shape[:2] == (240, 320)
    result = contactlab("export", "run", "--format", "obj", "--every", "5", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    samples = len(run["time"])  # every 5th sample, and the last one
    assert len(list((out / "frames").glob("*.obj"))) == -(-(samples - 1) // 5) + 1


@pytest.mark.parametrize(
    "args, field",
    [
        (("run", "bouncing_ball", "--export", "fbx"), "--export"),
        (("run", "bouncing_ball", "--video", "--fps", "0"), "--fps"),
        (("render", "nowhere"), "OUT_DIR"),
        (("export", "nowhere"), "OUT_DIR"),
        (("compare", "bouncing_ball", "--methods", "impulse,magic"), "--methods"),
        (("compare", "no_such_scene"), ""),
    ],
)
def test_new_commands_reject_bad_input_in_one_line_and_write_nothing(tmp_path, args, field):
    result = contactlab(*args, cwd=tmp_path)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:") and field in lines[0]
    assert "Traceback" not in result.stderr
    assert list(tmp_path.iterdir()) == []


def test_compare_from_the_command_line(tmp_path):
    result = contactlab(
        "compare",
        "bouncing_ball",
        "--methods",
        "impulse,constraints",
        "--duration",
        "0.3",
        "--no-video",
        "--out",
        "cmp",
        cwd=tmp_path,
    )
    assert result.returncode == 0, result.stderr
    for name in ("report.html", "report.md", "comparison.csv", "impulse/trajectory.h5", "constraints/summary.json"):
        assert (tmp_path / "cmp" / name).is_file(), name
    assert "report.html" in result.stdout


def test_version_prints_the_installed_version(capsys):
    from contactlab import __version__, cli

    with pytest.raises(SystemExit) as done:
        cli.main(["--version"])
    assert done.value.code == 0 and capsys.readouterr().out == f"contactlab {__version__}\n"


def test_the_summary_line_says_where_the_time_went():
    """A first run's 20 s were compiling, not stepping at 190 steps/s (issue 22's "4000 steps in
    37.02 s (1137 steps/s)" hid that)."""
    from contactlab.cli import _where_time_went

    first = {"compile_seconds": 20.0, "recording_seconds": 0.4, "steps_per_second": 6003.2}
    assert _where_time_went(first) == "20.00 s compiling or loading kernels, 0.40 s recording, 6003 steps/s stepping"
    cached = {"compile_seconds": 0.02, "recording_seconds": 0.01, "steps_per_second": 6003.2}
    assert _where_time_went(cached) == "6003 steps/s stepping"


def test_a_short_run_steps_through_the_compiled_loop_and_its_line_says_where_the_time_went():
    # issue 37: the demo printed 8,314 steps/s where the README says ~353,000 for the ball, and
    # nothing said why: a short first run stepped the loop's body from Python. Since issue 36 every
    # run the loop serves takes it compiled, however short; one it does not serve (explicit Euler
    # here) steps through the method's step. Neither line has anything to excuse.
    from conftest import ball_on_plane

    from contactlab.cli import _where_time_went

    model = ball_on_plane()
    looped = simulate(model, "impulse", 1e-3, 0.01).summary
    unserved = simulate(model, "impulse", 1e-3, 0.01, integrator="explicit_euler").summary
    assert looped["stepping"] == "compiled loop" and unserved["stepping"] == "python"
    assert "loop" not in _where_time_went(looped) and "loop" not in _where_time_went(unserved)


@pytest.mark.parametrize("compiled_loop", [True, False])
def test_the_progress_bar_starts_its_clock_after_the_first_step(monkeypatch, compiled_loop):
    """The first step compiles (or loads) the kernels; the bar's rate and time left must be the
    stepping's, so it is restarted after that step and before any other progress (issue 22)."""
    from conftest import ball_on_plane

    from contactlab import simulation

    events = []

    class Bar:
        def __init__(self, total, description, unit, show):
            events.append(("total", total))

        def __enter__(self):
            return self

        def __exit__(self, *exception):
            return False

        def restart(self):
            events.append(("restart",))

        def update(self, count):
            events.append(("update", count))

    monkeypatch.setattr(simulation, "progress_bar", Bar)
    simulation.simulate(ball_on_plane(), "impulse", 0.01, 0.5, progress=True, compiled_loop=compiled_loop)
    assert events[:3] == [("total", 50), ("restart",), ("update", 1)]
    assert events.count(("restart",)) == 1 and sum(event[1] for event in events if event[0] == "update") == 50


def test_a_second_run_into_a_folder_being_written_is_refused_and_a_stale_lock_is_not(tmp_path):
    # issue 37: two runs into one --out both exited 0 and both listed the same outputs, of which the
    # folder held the last finisher's; now the second is refused while the first writes
    import signal
    import time

    from conftest import interruptible

    from contactlab.folder_lock import LOCK_NAME

    out = tmp_path / "shared"
    first = subprocess.Popen(  # long enough to be still running when the second one starts
        [
            sys.executable,
            "-m",
            "contactlab",
            "run",
            "box_pyramid",
            "--duration",
            "120",
            "--no-plots",
            "--out",
            "shared",
        ],
        cwd=tmp_path,
        preexec_fn=interruptible,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 120
        while not (out / LOCK_NAME).exists() and time.monotonic() < deadline and first.poll() is None:
            time.sleep(0.05)
        second = contactlab("run", "bouncing_ball", "--duration", "0.1", "--no-plots", "--out", "shared", cwd=tmp_path)
        assert first.poll() is None, first.stderr.read()  # still writing while the second was refused
        first.send_signal(signal.SIGINT)
        _, stderr = first.communicate(timeout=120)
    finally:
        if first.poll() is None:
            first.kill()
    assert second.returncode == 2 and second.stdout == "" and "Traceback" not in second.stderr
    assert second.stderr.startswith(
        f"error: bouncing_ball: --out: shared is being written by another contactlab command (process {first.pid} on "
    ), second.stderr
    assert second.stderr.count("\n") == 1
    assert first.returncode == 130 and "written before it: shared" in stderr
    assert sorted(os.listdir(out)) == ["summary.json", "trajectory.h5"]  # the first run's, and no lock left
    # a lock file whose process is gone (a run killed with SIGKILL) does not hold the folder
    (out / LOCK_NAME).write_text("process 999999999 on nowhere, since 00:00:00\n")
    again = contactlab("run", "bouncing_ball", "--duration", "0.1", "--no-plots", "--out", "shared", cwd=tmp_path)
    assert again.returncode == 0, again.stderr
    assert not (out / LOCK_NAME).exists()


@pytest.mark.parametrize("command", [["compare", "bouncing_ball"], ["validate", "bouncing_ball", "m.h5"]])
def test_an_empty_methods_list_is_refused_by_compare_as_by_validate(tmp_path, monkeypatch, capsys, command):
    # issue 59: compare --methods '' ran all four methods where validate refused it
    from contactlab import cli

    monkeypatch.chdir(tmp_path)
    assert cli.main([*command, "--methods", ""]) == 2
    assert capsys.readouterr().err.splitlines() == [
        "error: bouncing_ball: --methods: expected at least one of: penalty, projection, impulse, constraints"
    ]
    assert os.listdir(tmp_path) == []
