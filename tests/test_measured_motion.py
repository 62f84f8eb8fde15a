"""Measured motion (issue 40): the file checked, `validate` against measurements contactlab made
itself with known settings, `fit` recovering those settings, and the command line's refusals."""

import json
import os
import subprocess
import sys

import h5py
import numpy as np
import pytest

from contactlab.errors import InputError
from contactlab.fitting import fit, parse_vary, split
from contactlab.measured import read_measurement, write_measurement, write_synthetic
from contactlab.prediction import estimated_velocities, validate
from contactlab.rotations import from_rotation_vector, multiply
from contactlab.scene import load_scene

SCENE = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "data", "measured", "cube_toss.toml")
COARSE = ["simulation.dt=0.004"]  # the tests' runs: 100 steps of a 0.4 s toss


def _toss(path, settings=(), velocity=(1.0, 0.2, 0.6), spin=(4.0, -3.0, 6.0), duration=0.4, **noise):
    """A toss of the cube simulated by impulse with ``settings``, written as a measurement."""
    scene = load_scene(
        SCENE,
        [
            *COARSE,
            *settings,
            f"simulation.duration={duration}",
            f"bodies.0.velocity={list(velocity)}",
            f"bodies.0.angular_velocity={list(spin)}",
            "bodies.0.orientation=[0.9, 0.3, 0.2, 0.1]",
        ],
    )
    return write_synthetic(path, scene.simulate(compiled_loop=False).arrays, **noise)


def test_validate_finds_no_error_in_a_noise_free_measurement_of_its_own_method(tmp_path):
    measured = _toss(tmp_path / "own.h5", velocities=True)
    result = validate(SCENE, [measured], ["impulse", "penalty"], tmp_path / "out", overrides=COARSE)
    rows = {row["method"]: row for row in result.rows}
    assert rows["impulse"]["status"] == "ok" and rows["impulse"]["velocities"] == "file"
    for name in ("position_error_pct", "rotation_error_deg", "final_position_error_pct"):
        assert rows["impulse"][name] < 1e-6, rows["impulse"]
    assert rows["penalty"]["position_error_pct"] > 1.0  # another method drifts from it
    assert result.best == "impulse" and result.medians["impulse"]["failed"] == 0
    assert {p.name for p in (tmp_path / "out").iterdir()} == {"validation.csv", "report.md", "plots"}
    assert (tmp_path / "out" / "plots" / "own.png").stat().st_size > 0
    assert "Best predictor here: **impulse**" in (tmp_path / "out" / "report.md").read_text()


def test_the_starting_velocities_are_estimated_exactly_from_free_flight():
    # a parabola and a constant spin, sampled at 150 Hz: the estimate is exact, however fast
    t = np.arange(12) / 150.0 + 3.0
    g, v, w = np.array([0, 0, -9.81]), np.array([1.2, -0.4, 2.0]), np.array([3.0, -7.0, 5.0])
    start = np.array([0.96, 0.0, 0.28, 0.0])
    start /= np.linalg.norm(start)
    position = (np.array([0.1, 0.2, 0.3]) + np.outer(t - t[0], v) + 0.5 * np.outer((t - t[0]) ** 2, g))[:, None]
    orientation = multiply(from_rotation_vector(np.outer(t - t[0], w)), start[None])[:, None]
    measurement = _measurement(t, position, orientation)
    velocity, spin = estimated_velocities(measurement, g)
    assert velocity[0] == pytest.approx(v, abs=1e-9) and spin[0] == pytest.approx(w, abs=1e-9)


def _measurement(t, position, orientation):
    from contactlab.measured import Measurement

    return Measurement("m.h5", "m", t, ("cube",), position, orientation)


def test_fit_recovers_the_friction_and_restitution_behind_noisy_tosses(tmp_path):
    # three tosses at μ = 0.35, ε = 0.45 with 0.3 mm and 0.3° of tracking noise, velocities left
    # to be estimated; the fit starts from the scene's 0.18 and 0.125. The tolerance: the
    # noise moves the estimated start (about 5 mm/s, 0.1 rad/s), which a change of μ by 0.05
    # (0.5 m/s² less deceleration, 10 mm over the 0.2 s slide) or of ε by 0.1 (a rebound
    # 25 % higher) outweighs
    true = ["materials.0.friction=0.35", "materials.0.restitution=0.45"]
    files = [
        _toss(tmp_path / f"toss_{k}.h5", true, velocity, spin, position_noise=3e-4, angle_noise=np.radians(0.3), seed=k)
        for k, (velocity, spin) in enumerate(
            [((1.2, 0.0, 0.8), (0.0, 0.0, 2.0)), ((0.9, 0.4, 1.0), (1.0, 0.0, 0.0)), ((1.0, -0.3, 0.5), (0.0, 2, 0))]
        )
    ]
    out = tmp_path / "fit"
    lines = []
    settings = ["materials.0.friction=0.05:0.6", "materials.0.restitution=0:0.8"]
    result = fit(SCENE, files, settings, ["impulse"], 1 / 3, out, overrides=COARSE, workers=1, log=lines.append)
    fitted = result.methods["impulse"]
    assert fitted["values"]["materials.0.friction"] == pytest.approx(0.35, abs=0.05), fitted
    assert fitted["values"]["materials.0.restitution"] == pytest.approx(0.45, abs=0.1), fitted
    assert fitted["holdout_error"] is not None and fitted["holdout_error"] < 10.0, fitted
    saved = json.loads((out / "fit.json").read_text())
    assert saved["methods"]["impulse"]["values"] == fitted["values"] and result.holdout == ["toss_2"]
    assert {p.name for p in (out / "plots").iterdir()} == {
        "fit_materials.0.friction.png",
        "fit_materials.0.restitution.png",
    }
    # run again: every point is found in OUT/evaluations, nothing runs, the same answer
    kept = sorted(os.listdir(out / "evaluations"))
    again = fit(SCENE, files, settings, ["impulse"], 1 / 3, out, overrides=COARSE, workers=1)
    assert again.methods == result.methods and sorted(os.listdir(out / "evaluations")) == kept


def test_the_holdout_is_spread_over_the_files_and_leaves_some_to_fit_on():
    assert split(8, 0.25) == ([0, 1, 2, 4, 5, 6], [3, 7])
    assert split(3, 0.0) == ([0, 1, 2], [])
    with pytest.raises(InputError, match="leaves none to fit on"):
        split(1, 0.5)
    with pytest.raises(InputError, match="expected a fraction"):
        split(4, 1.0)
    assert parse_vary("materials.0.friction = 0.1:0.5").low == 0.1
    with pytest.raises(InputError, match="expected finite LO < HI"):
        parse_vary("materials.0.friction=0.5:0.1")


def _broken(path, **change):
    """A valid one-body measurement with some datasets replaced (None: left out)."""
    t = np.linspace(0.0, 0.2, 11)
    arrays = {
        "time": t,
        "body_position": np.tile([0.0, 0.0, 0.1], (11, 1, 1)),
        "body_orientation": np.tile([1.0, 0.0, 0.0, 0.0], (11, 1, 1)),
        "body_names": np.array(["cube"], dtype=h5py.string_dtype()),
    }
    arrays.update(change)
    with h5py.File(path, "w") as file:
        for name, value in arrays.items():
            if value is not None:
                file.create_dataset(name, data=value)
    return str(path)


@pytest.mark.parametrize(
    "change, field, words",
    [
        ({"time": None}, "time", "missing: a measurement needs time"),
        ({"time": np.array([0.0, 0.1, 0.1, *np.linspace(0.2, 1.0, 8)])}, "time", "expected strictly increasing times"),
        (
            {"body_orientation": np.tile([1.0, 0.1, 0.0, 0.0], (11, 1, 1))},
            "body_orientation",
            "expected unit quaternions",
        ),
        ({"body_position": np.full((11, 1, 3), np.nan)}, "body_position", "expected finite numbers"),
        ({"body_position": np.zeros((10, 1, 3))}, "body_position", "expected shape (11, B, 3)"),
        ({"body_position": np.tile([0.0, 0.0, 100.0e3], (11, 1, 1))}, "body_position", "positions are in metres"),
        ({"body_velocity": np.zeros((11, 1, 3))}, "body_velocity", "give body_velocity and body_angular_velocity"),
        ({"body_names": np.array(["a", "b"], dtype=h5py.string_dtype())}, "body_names", "expected 1 names"),
    ],
)
def test_a_bad_measurement_is_one_sentence_naming_the_file_and_dataset(tmp_path, change, field, words):
    with pytest.raises(InputError) as refused:
        read_measurement(_broken(tmp_path / "m.h5", **change))
    assert refused.value.field == f"m.h5:{field}" and words in refused.value.message, refused.value


def test_a_measurement_round_trips_and_names_the_scene_bodies(tmp_path):
    path = write_measurement(
        tmp_path / "m.h5", [0.0, 0.1], ["cube"], np.zeros((2, 1, 3)), np.tile([1.0, 0, 0, 0], (2, 1, 1))
    )
    assert read_measurement(path).body_names == ("cube",) and read_measurement(path).duration == 0.1
    wrong = _broken(tmp_path / "other.h5", body_names=np.array(["ball"], dtype=h5py.string_dtype()))
    with pytest.raises(InputError) as refused:
        validate(SCENE, [wrong], ["impulse"], tmp_path / "out")
    assert refused.value.field == "other.h5:body_names" and "no body named 'ball'" in refused.value.message
    assert not (tmp_path / "out").exists()


def _command(*args, cwd):
    return subprocess.run(
        [sys.executable, "-m", "contactlab", *args], cwd=cwd, capture_output=True, text=True, timeout=300
    )


@pytest.mark.parametrize(
    "args, words",
    [
        (["validate", SCENE, "missing.h5"], "no such file"),
        (["validate", SCENE, "not_hdf5.h5"], "cannot read it as an HDF5 file"),
        (["validate", SCENE, "good.h5", "--methods", "magic"], "unknown method 'magic'"),
        (["fit", SCENE, "good.h5", "--vary", "materials.0.friction"], "expected PATH=LO:HI"),
        (["fit", SCENE, "good.h5", "--vary", "materials.0.friction=0.1:0.5"], "leaves none to fit on"),
        (["fit", SCENE, "good.h5", "--holdout", "0", "--vary", "materials.9.friction=0.1:0.5"], "--vary"),
        (["fit", SCENE, "good.h5", "--holdout", "0", "--vary", "materials.0.restitution=0.5:2"], "--vary"),
        (["fit", SCENE, "good.h5", "--vary", "materials.0.friction=0:1", "--scheduler", "nowhere"], "--scheduler"),
    ],
)
def test_the_commands_refuse_bad_input_with_exit_2_one_line_and_nothing_written(tmp_path, args, words):
    (tmp_path / "not_hdf5.h5").write_text("hello")
    _broken(tmp_path / "good.h5")
    result = _command(*args, "--out", "out", cwd=tmp_path)
    assert result.returncode == 2, result.stderr
    assert len(result.stderr.splitlines()) == 1 and words in result.stderr and "Traceback" not in result.stderr
    assert not (tmp_path / "out").exists()


def test_the_validate_command_prints_one_json_object(tmp_path):
    measured = _toss(tmp_path / "own.h5", duration=0.2, velocities=True)
    result = _command("validate", SCENE, measured, "--methods", "impulse", "--set", COARSE[0], "--json", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    found = json.loads(result.stdout)
    assert found["rows"][0]["measurement"] == "own" and found["rows"][0]["position_error_pct"] < 1e-6
    assert found["medians"]["impulse"]["failed"] == 0 and found["best"] == "impulse"
    assert (tmp_path / "out" / "cube_toss-validate" / "validation.csv").is_file()


def test_validate_starts_the_peers_from_the_measurement_and_finds_no_error_in_their_own_toss(tmp_path):
    """A toss recorded by MuJoCo itself, from the same start: validate's MuJoCo row drifts from it
    by nothing (the peer is started from the measured state, not the scene's), and pybullet and
    a method, which model the contact otherwise, land elsewhere."""
    pytest.importorskip("mujoco", reason="MuJoCo not installed (pip install 'contactlab[peers]')")
    pytest.importorskip("pybullet", reason="pybullet not installed (pip install 'contactlab[peers]')")
    from dataclasses import replace

    from contactlab import peers

    scene = load_scene(SCENE, [*COARSE, "simulation.duration=0.4"])
    start = scene.model.state()
    start.body_position[0] += [0.05, -0.02, 0.1]  # not the scene's own start
    start.body_velocity[0] = [1.0, 0.2, 0.6]
    start.body_angular_velocity[0] = [4.0, -3.0, 6.0]
    own = peers.simulate(replace(scene.model, initial=start), "mujoco", scene.dt, scene.duration)
    measured = write_synthetic(tmp_path / "mujoco_toss.h5", own.arrays, velocities=True)
    result = validate(SCENE, [measured], ["impulse"], tmp_path / "out", overrides=COARSE, peers="mujoco,pybullet")
    rows = {row["method"]: row for row in result.rows}
    assert set(rows) == {"impulse", "mujoco", "pybullet"} and all(r["status"] == "ok" for r in rows.values())
    assert rows["mujoco"]["position_error_pct"] < 1e-6 and rows["mujoco"]["rotation_error_deg"] < 1e-4
    assert rows["pybullet"]["position_error_pct"] > 0.1 and rows["impulse"]["position_error_pct"] > 0.1
    assert result.best == "mujoco"


def test_validate_where_no_run_completed_says_so_and_exits_3(tmp_path, monkeypatch, capsys):
    # issue 59: every run diverged, and validate said "Median position error: impulse nan %", exit 0
    import time as clock

    from contactlab import cli, prediction

    def diverged(job):  # what predict returns for a run a health check stopped
        measurement = prediction.read_measurement(job["measurement"])
        row = {"measurement": measurement.name, "method": job["method"], "samples": len(measurement.time)}
        return prediction._failed(row, "diverged", "energy from nowhere at t = 0.1 s", clock.perf_counter())

    monkeypatch.setattr(prediction, "predict", diverged)
    out = tmp_path / "out"
    measured = [os.path.join(os.path.dirname(SCENE), f"toss_0{k}.h5") for k in (1, 2)]
    code = cli.main(["validate", SCENE, *measured, "--methods", "impulse,penalty", "--out", str(out)])
    captured = capsys.readouterr()
    assert code == 3
    assert "Median position error: impulse none completed, penalty none completed." in captured.out
    assert "nan" not in captured.out
    csv = out / "validation.csv"
    assert captured.err.splitlines() == [f"error: no run of any method completed (each row of {csv} says why)"]
    assert csv.is_file() and (out / "report.md").is_file()  # what went wrong, kept to be read


def test_a_whole_number_setting_is_fitted_in_whole_numbers():
    # issue 59: fit --vary method.impulse.iterations=1:100 was refused, "expected a whole number
    # ≥ 1, found 1.0", though any --set path may be fitted
    from contactlab.fitting import _checked

    count = _checked(parse_vary("method.impulse.iterations=1:100"), SCENE, COARSE, ["impulse"])
    assert (
        count.whole
        and count.value(0.3712) == 38
        and count.setting(count.value(0.3712)) == ("method.impulse.iterations=38")
    )
    friction = _checked(parse_vary("materials.0.friction=0:1"), SCENE, COARSE, ["impulse"])
    assert not friction.whole and friction.setting(friction.value(0.3712)) == "materials.0.friction=0.3712"
    with pytest.raises(InputError, match=r"^--vary: method.impulse.iterations=0.5: "):
        _checked(parse_vary("method.impulse.iterations=0.5:10"), SCENE, COARSE, ["impulse"])


def test_a_measurement_too_long_to_run_is_refused_with_advice_validate_can_follow(tmp_path):
    # issue 59: an 800,000 s measurement's refusal advised record every, trajectory= and
    # --memory-limit, none of which validate or fit takes
    times = np.concatenate([np.linspace(0.0, 0.04, 5), np.linspace(1.0, 8e5, 6)])
    with pytest.raises(InputError) as refused:
        validate(SCENE, [_broken(tmp_path / "long.h5", time=times)], "impulse", tmp_path / "out")
    assert refused.value.field == "long.h5"
    assert "cut the measurement into shorter files, or give a longer simulation.dt (--set)" in refused.value.message
    for advice in ("record every", "trajectory=", "memory_limit", "--memory-limit"):
        assert advice not in refused.value.message, refused.value
    assert not (tmp_path / "out").exists()


def test_positions_in_millimetres_are_warned_of(tmp_path):
    # issue 59: positions in millimetres (up to 600 m, within the 1 km refused) were taken as
    # metres without a word, and validate found 5.4e5 % errors
    import warnings

    t = np.linspace(0.0, 0.2, 11)
    millimetres = np.stack([2000.0 * t, 0.0 * t, 100.0 + 0.0 * t], axis=-1)[:, None]  # 2 m/s, in mm
    words = r"^m.h5:body_position: a body moves at 2e\+03 m/s between samples \d+ and \d+; "
    with pytest.warns(UserWarning, match=words):
        read_measurement(_broken(tmp_path / "m.h5", body_position=millimetres))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        read_measurement(_broken(tmp_path / "metres.h5", body_position=millimetres / 1000.0))
