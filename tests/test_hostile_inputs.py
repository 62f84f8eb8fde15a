"""Hostile input: whatever a user gives (a scene file, a trajectory, a command line, a Python
call), contactlab either runs it or refuses it with one InputError line (exit code 2 on the
command line, nothing written). Issue 20, deliverable 2.

The first part reproduces each class of failure a user reported (a traceback, a hang, a
megabyte-long line, NaN results) as a regression test; the second generates scenes, builder
calls and simulate() calls with Hypothesis and asserts that nothing but InputError (or
SimulationDiverged, a run that blew up) ever comes out.
"""

import contextlib
import io
import math
import os
import subprocess
import sys
import warnings
import zipfile

import h5py
import numpy as np
import pytest
from conftest import ball_on_plane
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from contactlab import cli, render, store
from contactlab.builder import ModelBuilder
from contactlab.errors import LONGEST_MESSAGE, InputError, SimulationDiverged
from contactlab.methods import AVAILABLE, penalty
from contactlab.plausibility import PlausibilityWarning
from contactlab.scene import load_scene, loader
from contactlab.scene.toml import MAX_NESTING
from contactlab.shape_arguments import BODY_SHAPE_ARGUMENTS, OBSTACLE_SHAPE_ARGUMENTS
from contactlab.shapes import BODY_SHAPES, OBSTACLE_SHAPES
from contactlab.simulation import simulate
from contactlab.validation import LENGTH, LIMITS, MASS


def fuzz(examples):
    """Hypothesis settings: ``examples`` examples, the same ones every run (no database written)."""
    return settings(
        max_examples=examples,
        deadline=None,
        database=None,
        derandomize=True,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much],
    )


BALL = """
[simulation]
dt = 0.01
duration = 0.03

[[bodies]]
shape = "sphere"
radius = 0.1
mass = 1.0
position = [0.0, 0.0, 0.5]

[[obstacles]]
shape = "plane"
normal = [0.0, 0.0, 1.0]
"""


def write(directory, text, name="scene.toml"):
    path = directory / name
    path.write_text(text, encoding="utf-8")
    return path


def refused(call, *args, **kwargs) -> InputError:
    """The InputError ``call`` raises; its text is one short line."""
    with pytest.raises(InputError) as caught:
        call(*args, **kwargs)
    text = str(caught.value)
    assert len(text.splitlines()) == 1 and len(text) <= 2 * LONGEST_MESSAGE, text[:200]
    return caught.value


def run_main(monkeypatch, capsys, *argv):
    """(exit code, stderr lines) of the command line run in this process."""
    monkeypatch.setattr(warnings, "showwarning", warnings.showwarning)  # main() replaces it
    code = cli.main([str(a) for a in argv])
    return code, capsys.readouterr().err.splitlines()


def contactlab(*args, cwd, timeout=120):
    return subprocess.run(
        [sys.executable, "-m", "contactlab", *map(str, args)], cwd=cwd, capture_output=True, text=True, timeout=timeout
    )


def assert_one_line_exit_2(result, cwd, contains=""):
    lines = result.stderr.splitlines()
    assert result.returncode == 2, result.stderr[-2000:]
    assert len(lines) == 1 and lines[0].startswith("error: ") and "Traceback" not in result.stderr, lines
    assert contains in lines[0]
    assert result.stdout == ""
    assert not (cwd / "out").exists()


# =============================================================================================
# 1. scene files: nesting, size, files that are not regular files
# =============================================================================================


@pytest.mark.parametrize(
    "text",
    [
        "a = " + "[" * 100_000 + "]" * 100_000 + "\n",  # arrays in arrays
        "a = " + "{b = " * 20_000 + "1" + "}" * 20_000 + "\n",  # inline tables
        "[" + ".".join(["t"] * (MAX_NESTING + 1)) + "]\n",  # dotted table headers
    ],
    ids=["arrays", "inline tables", "table headers"],
)
def test_a_scene_nested_too_deep_is_one_input_error(tmp_path, text):
    error = refused(load_scene, write(tmp_path, text))
    assert f"more than {MAX_NESTING} levels" in error.message


def test_a_set_value_nested_too_deep_is_one_input_error():
    error = refused(load_scene, "bouncing_ball", ["description=" + "[" * 50_000 + "]" * 50_000])
    assert error.field == "--set"


def test_integers_beyond_64_bits_are_refused_as_toml_says(tmp_path):
    refused(load_scene, write(tmp_path, BALL.replace("mass = 1.0", "mass = 1" + "0" * 400)))
    refused(load_scene, write(tmp_path, BALL.replace("mass = 1.0", "mass = 1" + "0" * 5000)))


def test_a_scene_file_over_the_size_limit_is_refused_unread(tmp_path, monkeypatch):
    assert loader.MAX_SCENE_BYTES == 16 * 2**20
    monkeypatch.setattr(loader, "MAX_SCENE_BYTES", 1000)
    error = refused(load_scene, write(tmp_path, BALL + "#" * 1000))
    assert "MiB" in error.message
    load_scene(write(tmp_path, BALL))


def test_directories_devices_and_fifos_are_refused_without_being_opened(tmp_path):
    assert "the directory" in refused(load_scene, str(tmp_path) + os.sep).message
    if os.path.exists("/dev/zero"):
        assert "character device" in refused(load_scene, "/dev/zero").message
    if hasattr(os, "mkfifo"):
        fifo = tmp_path / "pipe.toml"
        os.mkfifo(fifo)  # opening it for reading would block forever
        assert "FIFO" in refused(load_scene, fifo).message


def test_fifo_and_dev_zero_fail_at_once_on_the_command_line(tmp_path):
    os.mkfifo(tmp_path / "pipe.toml")
    for scene in ("pipe.toml", "/dev/zero"):
        assert_one_line_exit_2(contactlab("run", scene, cwd=tmp_path, timeout=60), tmp_path)


# =============================================================================================
# 2. an empty scene
# =============================================================================================


@pytest.mark.parametrize("method", AVAILABLE)
def test_an_empty_scene_is_nothing_to_simulate(tmp_path, method):
    scene = load_scene(write(tmp_path, '[[obstacles]]\nshape = "plane"\nnormal = [0, 0, 1]\n'))
    error = refused(simulate, scene.model, method, 0.01, 0.05)
    assert error.field == "model" and "nothing to simulate" in error.message


def test_compare_of_an_empty_scene_says_so_and_writes_nothing(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    write(tmp_path, "[simulation]\nduration = 0.02\n", "empty.toml")
    code, err = run_main(monkeypatch, capsys, "compare", "empty.toml", "--no-video")
    assert code == 2 and len(err) == 1 and "nothing to simulate" in err[0]
    code, err = run_main(monkeypatch, capsys, "run", "empty.toml", "--method", "penalty")
    assert code == 2 and len(err) == 1 and "nothing to simulate" in err[0]
    assert os.listdir(tmp_path) == ["empty.toml"]


# =============================================================================================
# 3. corrupt trajectories (render and export)
# =============================================================================================


@pytest.fixture(scope="module")
def ball_run(tmp_path_factory):
    """A short run's output folder (trajectory.h5, summary.json) and its arrays."""
    out = tmp_path_factory.mktemp("ball")
    code = cli.main(["run", str(write(out, BALL)), "--out", str(out / "run"), "--no-plots", "--json"])
    assert code == 0
    trajectory = store.open_trajectory(out / "run" / "trajectory.h5")
    return out / "run", {name: trajectory[name] for name in trajectory}


def damaged(arrays, **changes):
    result = dict(arrays)
    result.update(changes)
    return result


def content_damage(arrays):
    """name -> arrays whose values are wrong though the file holding them is sound."""
    return {
        "missing arrays": {"body_surface_vertices": arrays["body_surface_vertices"]},
        "wrong shape": damaged(arrays, body_position=arrays["body_position"][:2]),
        "strings for numbers": damaged(arrays, body_position=np.array(["a", "b"])),
        "nan positions": damaged(arrays, body_position=arrays["body_position"] * np.nan),
        "huge positions": damaged(arrays, body_position=arrays["body_position"] + 1e200),
        "indices out of range": damaged(arrays, body_surface_triangles=arrays["body_surface_triangles"] + 999),
        "time backwards": damaged(arrays, time=arrays["time"][::-1].copy()),
        "bad starts": damaged(arrays, body_surface_vertex_start=np.array([0, 5])),
    }


def byte_damage(data, flip):
    """name -> bytes of a file that is not sound: ``data`` (a good file) cut short, or with its
    byte ``flip`` (one the file's meaning depends on) changed."""
    middle = len(data) // 2
    return {
        "random bytes": np.random.default_rng(1).bytes(4000),
        "empty file": b"",
        "truncated": data[:middle],
        "a flipped byte": data[:flip] + bytes([data[flip] ^ 0xFF]) + data[flip + 1 :],
    }


def h5_bytes(tmp_path, arrays, **attributes):
    """The bytes of an HDF5 file holding ``arrays`` as datasets, with ``attributes`` (by default
    those of a contactlab trajectory)."""
    path = tmp_path / "made.h5"
    with h5py.File(path, "w") as file:
        file.attrs.update({"format": store.FORMAT, "version": store.VERSION, **attributes})
        for name, value in arrays.items():
            value = np.asarray(value)
            file.create_dataset(name, data=value.astype(h5py.string_dtype()) if value.dtype.kind == "U" else value)
    data = path.read_bytes()
    path.unlink()
    return data


def h5_corruptions(arrays, path, tmp_path):
    """name -> bytes of a damaged trajectory.h5 (``path``: a sound one); its flipped byte is
    one of the positions (a checksum catches it: the rest of the file is mostly padding)."""
    with h5py.File(path, "r") as file:
        flip = file["body_position"].id.get_chunk_info(0).byte_offset + 5
    with h5py.File(tmp_path / "ragged.h5", "w") as file:  # a type contactlab never writes
        file.attrs.update(format=store.FORMAT, version=store.VERSION)
        file.create_dataset("time", (2,), dtype=h5py.vlen_dtype(np.float64))
    ragged = (tmp_path / "ragged.h5").read_bytes()
    (tmp_path / "ragged.h5").unlink()
    return {
        **byte_damage(path.read_bytes(), flip),
        "another HDF5 file": h5_bytes(tmp_path, arrays, format="something else"),
        "a newer format": h5_bytes(tmp_path, arrays, version=store.VERSION + 1),
        "ragged arrays": ragged,
        **{name: h5_bytes(tmp_path, contents) for name, contents in content_damage(arrays).items()},
    }


def npz_corruptions(arrays, data):
    """name -> bytes of a damaged trajectory.npz (what an older contactlab wrote, still read);
    its flipped byte is one of the compressed positions (the zip's CRC catches it)."""
    with zipfile.ZipFile(io.BytesIO(data)) as archive:
        member = archive.getinfo("body_position.npy")
    flip = member.header_offset + 30 + len(member.filename.encode()) + len(member.extra) + member.compress_size // 2

    def npz(contents):
        stream = io.BytesIO()
        np.savez(stream, **contents)
        return stream.getvalue()

    objects = damaged(arrays, time=np.array([0.0, "a", None], dtype=object))
    bare = io.BytesIO()
    np.save(bare, arrays["time"])
    return {
        **byte_damage(data, flip),
        "object array": npz(objects),
        "a bare .npy": bare.getvalue(),
        **{name: npz(contents) for name, contents in content_damage(arrays).items()},
    }


@pytest.mark.parametrize("kind", ["trajectory.h5", "trajectory.npz"])
@pytest.mark.parametrize("command", ["render", "export"])
def test_a_corrupt_trajectory_is_one_line_and_nothing_written(ball_run, tmp_path, monkeypatch, capsys, command, kind):
    directory, arrays = ball_run
    if kind == "trajectory.h5":
        damages = h5_corruptions(arrays, directory / kind, tmp_path)
    else:
        stream = io.BytesIO()
        np.savez_compressed(stream, **arrays)
        damages = npz_corruptions(arrays, stream.getvalue())
    for name, content in damages.items():
        folder = tmp_path / f"{command}-{name.replace(' ', '_')}"
        folder.mkdir()
        (folder / kind).write_bytes(content)
        options = ("--width", 32) if command == "render" else ("--format", "obj")
        code, err = run_main(monkeypatch, capsys, command, folder, *options)
        assert code == 2 and len(err) == 1, (name, err)
        assert sorted(os.listdir(folder)) == [kind], name


def test_an_object_array_is_never_unpickled(tmp_path, ball_run):
    from contactlab.trajectory import load_npz

    unpickled = []

    class Spy:
        def __reduce__(self):
            return unpickled.append, ("unpickled",)

    np.savez(tmp_path / "trajectory.npz", time=np.array([Spy()], dtype=object))
    unpickled.clear()
    error = refused(load_npz, tmp_path / "trajectory.npz")
    assert unpickled == [] and "never unpickles" in error.message


def test_a_summary_that_is_not_an_object_or_a_fifo_is_ignored(ball_run, tmp_path, monkeypatch, capsys):
    directory, arrays = ball_run
    for summary in ("[1, 2]", '{"scene": "x"}', "[" * 100_000, "fifo"):
        folder = tmp_path / f"s{len(os.listdir(tmp_path))}"
        folder.mkdir()
        (folder / "trajectory.h5").write_bytes((directory / "trajectory.h5").read_bytes())
        if summary == "fifo":
            os.mkfifo(folder / "summary.json")
        else:
            (folder / "summary.json").write_text(summary)
        code, err = run_main(monkeypatch, capsys, "export", folder, "--format", "obj")
        assert code == 0, err


# =============================================================================================
# 4. absurd drawing and export settings
# =============================================================================================


@pytest.mark.parametrize(
    "option, value",
    [
        ("--width", 100_000),
        ("--height", 0),
        ("--width", -3),
        ("--fps", 0),
        ("--fps", 1_000_000),
        ("--fps", -1),
        ("--elevation", "nan"),
        ("--azimuth", "inf"),
    ],
)
def test_absurd_render_settings_are_refused(ball_run, monkeypatch, capsys, option, value):
    directory, _ = ball_run
    code, err = run_main(monkeypatch, capsys, "render", directory, option, value)
    assert code == 2 and len(err) == 1 and option.lstrip("-") in err[0]
    assert not (directory / "video.mp4").exists()


def test_render_limits_are_the_documented_ones():
    assert (render.MIN_SIZE, render.MAX_SIZE, render.MAX_FPS) == (16, 8192, 240)
    assert render.check_settings(240, 8192, 16) == (240.0, 8192, 16, 25.0, -60.0)
    for settings_ in ((240.5, 640, 480), (30, 8193, 480), (30, 640, 15), (30, 640.0, 480), (True, 640, 480)):
        refused(render.check_settings, *settings_)


def test_a_huge_every_exports_the_first_and_the_last_sample(ball_run, monkeypatch, capsys, tmp_path):
    from contactlab.export import frame_samples

    assert frame_samples(5, 10**30).tolist() == [0, 4]
    directory, _ = ball_run
    code, err = run_main(monkeypatch, capsys, "export", directory, "--format", "ply", "--every", 10**30)
    assert code == 0, err
    assert sorted(os.listdir(directory / "frames")) == ["frame_00000.ply", "frame_00001.ply"]


def test_a_bad_video_fps_fails_before_the_run(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    write(tmp_path, BALL)
    code, err = run_main(monkeypatch, capsys, "run", "scene.toml", "--video", "--fps", 100_000)
    assert code == 2 and len(err) == 1 and "fps" in err[0]
    code, err = run_main(monkeypatch, capsys, "compare", "scene.toml", "--fps", 100_000)
    assert code == 2 and len(err) == 1 and "fps" in err[0]
    assert os.listdir(tmp_path) == ["scene.toml"]


# =============================================================================================
# 5. drawing a run that went NaN
# =============================================================================================


def test_drawing_non_finite_positions_is_one_input_error(ball_run, tmp_path):
    _, arrays = ball_run
    blown = dict(arrays)
    blown["body_position"] = arrays["body_position"].copy()
    blown["body_position"][2:] = np.nan  # from the third sample on
    error = refused(render.render, blown, tmp_path / "video", fps=100, formats="mp4", width=32, height=32)
    assert f"at t = {arrays['time'][2]:.4g} s (the first sample used" in error.message  # 100 fps: every sample
    assert not (tmp_path / "video").exists()
    refused(render.still, blown, tmp_path / "still.png", width=32, height=32)


# =============================================================================================
# 6. the Python API: simulate's arguments, shape arguments of the builder
# =============================================================================================


@pytest.mark.parametrize(
    "arguments, field",
    [
        (dict(options=42), "options"),
        (dict(options="fast"), "options"),
        (dict(options={1: 2}), "options"),
        (dict(method="impulse", options=penalty.Options()), "options"),
        (dict(method=["impulse"]), "method"),
        (dict(method="nope"), "method"),
        (dict(integrator=["x"]), "integrator"),
        (dict(state=5), "state"),
        (dict(record_every=10**30), "record_every"),
        (dict(record_every=0), "record_every"),
        (dict(scene_name=3), "scene_name"),
        (dict(dt=float("nan")), "dt"),
        (dict(dt=1e-12), "dt"),
        (dict(dt=1e-9, duration=10.0), "dt"),
        (dict(duration=1e12), "duration"),
    ],
)
def test_bad_simulate_arguments_are_input_errors_naming_them(arguments, field):
    arguments = {"dt": 0.01, "duration": 0.02, **arguments}
    assert refused(simulate, ball_on_plane(height=0.4), **arguments).field == field


def test_simulate_a_non_model_or_a_state_of_another_model():
    assert refused(simulate, "x").field == "model"
    other = ModelBuilder()
    for x in (0.0, 1.0):
        other.add_body("sphere", radius=0.1, mass=1.0, position=(x, 0, 1))
    error = refused(simulate, ball_on_plane(height=0.4), dt=0.01, duration=0.02, state=other.finalize().state())
    assert error.field == "state" and "another model" in error.message
    state = ball_on_plane(height=0.4).state()
    state.body_velocity[0, 0] = np.inf
    assert refused(simulate, ball_on_plane(height=0.4), dt=0.01, duration=0.02, state=state).field == "state"
    state = ball_on_plane(height=0.4).state()
    simulate(ball_on_plane(height=0.4), dt=0.01, duration=0.02, state=state)  # its own state runs


@pytest.mark.parametrize(
    "call, field",
    [
        (lambda b: b.add_body("sphere", radius=0.1, half_extents=(1, 1, 1), mass=1.0), "half_extents"),
        (lambda b: b.add_body("box", half_extents=(1, 1, 1), radius=0.1, mass=1.0), "radius"),
        (lambda b: b.add_body("sphere", radius=0.1, scale=2.0, mass=1.0), "scale"),
        (lambda b: b.add_body("capsule", radius=0.1, half_length=0.1, points=[[0, 0, 0]], mass=1.0), "points"),
        (lambda b: b.add_obstacle("plane", normal=(0, 0, 1), position=(0, 0, 1)), "position"),
        (lambda b: b.add_obstacle("sphere", radius=0.1, orientation=(1, 0, 0, 0)), "orientation"),
        (lambda b: b.add_obstacle("sphere", radius=0.1, normal=(0, 0, 1)), "normal"),
        (lambda b: b.add_obstacle("box", half_extents=(1, 1, 1), offset=1.0), "offset"),
        (lambda b: b.add_body(["sphere"], radius=0.1, mass=1.0), "shape"),
        (lambda b: b.add_obstacle({"plane"}, normal=(0, 0, 1)), "shape"),
        (lambda b: b.add_body("sphere", radius=0.1, mass=1.0, material=[1]), "material"),
    ],
)
def test_a_shape_given_another_shapes_argument_is_an_input_error(call, field):
    error = refused(call, ModelBuilder())
    assert error.field == field


@pytest.mark.parametrize(
    "table, key, value",
    [
        ("bodies", "half_extents", "[1.0, 1.0, 1.0]"),
        ("bodies", "half_length", "0.5"),
        ("obstacles", "position", "[0.0, 0.0, 1.0]"),
        ("obstacles", "orientation", "[1.0, 0.0, 0.0, 0.0]"),
    ],
)
def test_scene_files_refuse_the_same_shape_arguments(tmp_path, table, key, value):
    section = (
        '[[bodies]]\nshape = "sphere"\nradius = 0.1\nmass = 1.0\n'
        if table == "bodies"
        else '[[obstacles]]\nshape = "plane"\nnormal = [0.0, 0.0, 1.0]\n'
    )
    error = refused(load_scene, write(tmp_path, f"{section}{key} = {value}\n"))
    assert error.field == f"{table}[0].{key}" and "takes no" in error.message


def test_the_scene_schema_and_the_builder_agree_on_shapes():
    assert set(BODY_SHAPE_ARGUMENTS) == set(BODY_SHAPES)
    assert set(OBSTACLE_SHAPE_ARGUMENTS) == set(OBSTACLE_SHAPES)


# =============================================================================================
# 7. a time step longer than the duration
# =============================================================================================


def test_a_dt_longer_than_the_duration_is_refused(tmp_path):
    error = refused(simulate, ball_on_plane(height=0.4), dt=1.0, duration=0.01)
    assert "dt = 1 s is longer than duration = 0.01 s" in error.message
    simulate(ball_on_plane(height=0.4), dt=0.01, duration=0.01)  # one step of exactly the duration


# =============================================================================================
# 8. long keys and values are cut in every message
# =============================================================================================


@pytest.mark.parametrize(
    "text",
    [
        "x" * 1_000_000 + " = 1\n",  # an unknown key
        BALL.replace('shape = "sphere"', 'shape = "' + "s" * 1_000_000 + '"'),  # an unknown shape
        BALL.replace("mass = 1.0", "mass = [" + "1.0, " * 200_000 + "]"),  # a long list where a number goes
        BALL.replace("[[bodies]]", '[[bodies]]\nmaterial = "' + "m" * 100_000 + '"'),  # builder: unknown material
        '"a\\nb\\u2028c" = 1\n',  # line breaks in a key
    ],
    ids=["unknown key", "unknown shape", "long list", "unknown material", "line breaks"],
)
def test_long_or_multi_line_keys_and_values_are_cut_to_one_short_line(tmp_path, text):
    error = refused(load_scene, write(tmp_path, text))
    assert len(str(error)) <= LONGEST_MESSAGE + 80 + 2


def test_argparse_errors_are_cut_too(tmp_path):
    result = contactlab("run", "bouncing_ball", "--fps", "9" * 100_000, cwd=tmp_path)
    assert_one_line_exit_2(result, tmp_path, "--fps")
    assert len(result.stderr) < 1000


# =============================================================================================
# 9. absurd magnitudes
# =============================================================================================


@pytest.mark.parametrize(
    "old, new, field",
    [
        ("radius = 0.1", "radius = 1e200", "bodies[0].radius"),
        ("radius = 0.1", "radius = 1e-9", "bodies[0].radius"),
        ("mass = 1.0", "mass = 1e20", "bodies[0].mass"),
        ("mass = 1.0", "mass = 1e-300", "bodies[0].mass"),
        ("mass = 1.0", "density = 1e9", "bodies[0].density"),
        ("mass = 1.0", "density = 1e-30", "bodies[0].density"),  # a mass of 4e-33 kg
        ("position = [0.0, 0.0, 0.5]", "position = [1e7, 0.0, 0.5]", "bodies[0].position"),
        ("position = [0.0, 0.0, 0.5]", "position = [0.0, 0.0, 0.5]\nvelocity = [1e9, 0, 0]", "bodies[0].velocity"),
        (
            "position = [0.0, 0.0, 0.5]",
            "position = [0.0, 0.0, 0.5]\nangular_velocity = [0, 1e300, 0]",
            "bodies[0].angular_velocity",
        ),
        (
            "position = [0.0, 0.0, 0.5]",
            "position = [0.0, 0.0, 0.5]\norientation = [1e300, 1e300, 0, 0]",
            "bodies[0].orientation",
        ),
        ("duration = 0.03", "duration = 0.03\ngravity = [0, 0, -1e10]", "simulation.gravity"),
        ("normal = [0.0, 0.0, 1.0]", "normal = [0.0, 0.0, 1.0]\noffset = 1e30", "obstacles[0].offset"),
        ("normal = [0.0, 0.0, 1.0]", "normal = [1e300, 1e300, 0.0]", "obstacles[0].normal"),
    ],
)
def test_absurd_magnitudes_are_refused(tmp_path, old, new, field):
    assert old in BALL
    error = refused(load_scene, write(tmp_path, BALL.replace(old, new)))
    assert error.field == field and "docs/scene-format.md" in error.message


def test_the_limits_are_generous(tmp_path):
    """Every limit is far from what a scene uses: a 1 km ball of 10^9 kg, a 1 mm grain of 10 mg
    thrown at 10 m/s and a particle of a microgram 100 km away, all load and run."""
    builder = ModelBuilder(gravity=(0, 0, -100.0))
    builder.add_body("sphere", radius=1000.0, mass=1e9, position=(0, 0, 2000.0))
    builder.add_body("sphere", radius=1e-3, mass=1e-5, position=(5000.0, 0, 1.0), velocity=(10.0, 0, 0))
    builder.add_particles([[1e5, 0, 1e5]], mass=1e-9, radius=0.0)
    builder.add_obstacle("plane", normal=(0, 0, 1))
    with pytest.warns(PlausibilityWarning, match="1e\\+06× the other body's 0.001 m"):  # valid, and it says so
        simulate(builder.finalize(), "impulse", 1e-4, 3e-4)
    assert LENGTH.largest == 1e6 and MASS.largest == 1e12 and all(q.largest > q.smallest for q in LIMITS)


def test_a_huge_ball_no_longer_reports_nan(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    write(tmp_path, BALL.replace("radius = 0.1", "radius = 1e200"))
    code, err = run_main(monkeypatch, capsys, "run", "scene.toml", "--video")
    assert code == 2 and err == [
        "error: scene.toml: bodies[0].radius: expected a length of at most 1e+06 m, found "
        "1e+200 m (see Limits in docs/scene-format.md)"
    ]
    assert os.listdir(tmp_path) == ["scene.toml"]


# =============================================================================================
# The command line, end to end: a few hostile inputs through a real process
# =============================================================================================


@pytest.mark.parametrize(
    "args, text",
    [
        (("run", "scene.toml"), "a = " + "[" * 100_000 + "]" * 100_000),
        (("run", "scene.toml", "--method", "penalty"), "[simulation]\nduration = 0.1\n"),
        (("run", "scene.toml"), BALL.replace("radius = 0.1", "radius = 1e200")),
        (("run", "scene.toml", "--dt", "1"), BALL),
        (("run", "scene.toml"), '"' + "k" * 1_000_000 + '" = 1\n'),
    ],
    ids=["nested", "empty", "huge ball", "dt", "long key"],
)
def test_the_command_line_says_one_line_and_writes_nothing(tmp_path, args, text):
    write(tmp_path, text)
    result = contactlab(*args, cwd=tmp_path)
    assert_one_line_exit_2(result, tmp_path)
    assert len(result.stderr) < 1000
    assert os.listdir(tmp_path) == ["scene.toml"]


@pytest.mark.parametrize("kind, start", [("trajectory.h5", b"\x89HDF\r\n\x1a\n"), ("trajectory.npz", b"PK\x03\x04")])
def test_rendering_random_bytes_from_the_command_line(tmp_path, kind, start):
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / kind).write_bytes(start + os.urandom(3000))
    result = contactlab("render", "run", cwd=tmp_path)
    assert_one_line_exit_2(result, tmp_path, "not a trajectory")
    assert os.listdir(tmp_path / "run") == [kind]


# =============================================================================================
# Property-based: generated scenes, builder calls and simulate() calls
# =============================================================================================


def toml_value(value) -> str:
    """``value`` (bool, int, float, str, list, dict) written as a TOML value (inline tables)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf") if math.isinf(value) else repr(value)
    if isinstance(value, str):
        return toml_string(value)
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(item) for item in value) + "]"
    return "{" + ", ".join(f"{toml_string(str(k))} = {toml_value(v)}" for k, v in value.items()) + "}"


def toml_string(text) -> str:
    """``text`` as a TOML basic string: quotes, backslashes and control characters escaped."""
    return '"' + "".join(f"\\u{ord(c):04x}" if c in '"\\' or ord(c) < 0x20 or ord(c) == 0x7F else c for c in text) + '"'


def toml_document(document) -> str:
    return "".join(f"{toml_string(str(key))} = {toml_value(value)}\n" for key, value in document.items())


HOSTILE_NUMBERS = st.sampled_from(
    [
        0,
        -1,
        1e200,
        -1e200,
        1e-300,
        1e7,
        2**70,
        -(2**70),
        10**18,
        float("nan"),
        float("inf"),
        -float("inf"),
        0.0,
        -0.0,
        1e-7,
    ]
)
NUMBERS = st.one_of(st.floats(0.01, 1.0), st.integers(-3, 5), HOSTILE_NUMBERS)
ANY = st.recursive(
    st.one_of(NUMBERS, st.booleans(), st.text(max_size=6)),
    lambda children: st.one_of(
        st.lists(children, max_size=4), st.dictionaries(st.text(max_size=5), children, max_size=3)
    ),
    max_leaves=8,
)


def one_in_ten(rare, common):
    """``rare`` about one time in ten, else ``common`` (st.one_of would take each half the time)."""
    return st.integers(0, 9).flatmap(lambda draw: rare if draw == 4 else common)


def sometimes(plausible):
    """Mostly ``plausible`` values, now and then anything at all."""
    return one_in_ten(ANY, plausible)


def now_and_then_a_stray_key(tables):
    """``tables`` (a strategy of dicts), one in ten of them with a key no table has."""
    stray = st.builds(
        lambda table, key, value: {**table, key: value}, tables, st.sampled_from(["bogus", "radiuss", "Mass", ""]), ANY
    )
    return one_in_ten(stray, tables)


def vector(size, low=-1.0, high=1.0):
    return st.lists(st.floats(low, high), min_size=size, max_size=size)


POSITIVE = st.floats(0.02, 0.5)
BODY_VALUES = {
    "radius": sometimes(POSITIVE),
    "half_extents": sometimes(vector(3, 0.02, 0.5)),
    "half_length": sometimes(POSITIVE),
    "mass": sometimes(st.floats(0.1, 10.0)),
    "density": sometimes(st.floats(10.0, 5000.0)),
    "points": sometimes(st.lists(vector(3), min_size=4, max_size=6)),
    "file": sometimes(st.text(max_size=8)),
    "scale": sometimes(POSITIVE),
    "position": sometimes(vector(3, -1.0, 2.0)),
    "orientation": sometimes(vector(4)),
    "velocity": sometimes(vector(3, -5.0, 5.0)),
    "angular_velocity": sometimes(vector(3, -5.0, 5.0)),
    "material": sometimes(st.sampled_from(["m", "x"])),
    "name": sometimes(st.text(max_size=5)),
    "array": sometimes(
        st.fixed_dictionaries(
            {"count": st.lists(st.integers(0, 2), min_size=3, max_size=3), "spacing": vector(3, 0.0, 0.5)}
        )
    ),
}
OBSTACLE_VALUES = {
    "normal": sometimes(vector(3)),
    "offset": sometimes(st.floats(-1.0, 1.0)),
    "radius": sometimes(POSITIVE),
    "half_extents": sometimes(vector(3, 0.02, 1.0)),
    "points": sometimes(st.lists(vector(3), min_size=4, max_size=6)),
    "position": sometimes(vector(3)),
    "orientation": sometimes(vector(4)),
    "scale": sometimes(POSITIVE),
    "material": sometimes(st.sampled_from(["m", "x"])),
    "file": sometimes(st.text(max_size=8)),
}
PARTICLE_VALUES = {
    "position": sometimes(st.lists(vector(3, -1.0, 2.0), min_size=1, max_size=3)),
    "velocity": sometimes(st.lists(vector(3), min_size=1, max_size=3)),
    "mass": sometimes(POSITIVE),
    "radius": sometimes(st.floats(0.0, 0.1)),
}
CLOTH_VALUES = {
    "size": sometimes(vector(2, 0.05, 1.0)),
    "resolution": sometimes(st.lists(st.integers(2, 4), min_size=2, max_size=2)),
    "mass": sometimes(POSITIVE),
    "position": sometimes(vector(3, 0.0, 1.0)),
    "pinned": sometimes(
        st.lists(st.one_of(st.integers(-1, 20), st.sampled_from(["corners", "top_edge", "x"])), max_size=3)
    ),
    "thickness": sometimes(st.floats(0.0, 0.02)),
    "stretch_stiffness": sometimes(st.floats(0.0, 1e4)),
    "self_collision": sometimes(st.booleans()),
}
# the keys each shape needs besides "shape" (a body needs a mass or a density too)
BODY_NEEDS = {
    "sphere": ("radius",),
    "box": ("half_extents",),
    "capsule": ("radius", "half_length"),
    "convex": ("points",),
}
OBSTACLE_NEEDS = {"plane": ("normal",), "sphere": ("radius",), "box": ("half_extents",), "convex": ("points",)}


def table(values, required=(), extra=None):
    """A table with all of the ``required`` keys of ``values`` and some of the others (each
    from its strategy), the ``extra`` entries (a dict of strategies) too."""
    return now_and_then_a_stray_key(
        st.fixed_dictionaries(
            {**{key: values[key] for key in required}, **(extra or {})},
            optional={key: strategy for key, strategy in values.items() if key not in required},
        )
    )


def shaped(values, needs, takes, weighed=False):
    """Tables of one shape each (mostly one of ``needs``), with the keys that shape needs (and,
    where ``weighed``, one of mass or density), and some of the others it ``takes`` (the
    builder's table of shape arguments) or every shape takes; foreign keys come from the
    stray keys and the hostile values."""
    specific = {key for names in takes.values() for key in names}

    def of_shape(shape_and_weight):
        shape, weight = shape_and_weight
        required = needs[shape] + ((weight,) if weighed else ())
        allowed = {
            key: strategy
            for key, strategy in values.items()
            if (key not in specific or key in takes[shape])
            and (not weighed or key not in ("mass", "density") or key == weight)
        }
        return table(allowed, required, {"shape": sometimes(st.just(shape))})

    return st.tuples(st.sampled_from(sorted(needs)), st.sampled_from(["mass", "density"])).flatmap(of_shape)


MOSTLY_OK = one_in_ten(
    ANY, st.one_of(st.integers(1, 30), st.floats(1e-6, 1.0), st.sampled_from(["auto", "vertex", "object", "never"]))
)
SCENES = now_and_then_a_stray_key(
    st.fixed_dictionaries(
        {
            "bodies": sometimes(
                st.lists(shaped(BODY_VALUES, BODY_NEEDS, BODY_SHAPE_ARGUMENTS, weighed=True), min_size=1, max_size=3)
            )
        },
        optional={
            "simulation": table(
                {
                    "dt": sometimes(st.floats(0.002, 0.01)),
                    "duration": sometimes(st.floats(0.01, 0.06)),
                    "method": sometimes(st.sampled_from(AVAILABLE)),
                    "gravity": sometimes(vector(3, -10, 10)),
                    "integrator": sometimes(st.sampled_from(["symplectic_euler", "explicit_euler", "backward_euler"])),
                }
            ),
            "materials": sometimes(
                st.lists(
                    table(
                        {
                            "name": sometimes(st.sampled_from(["m", "m", "n"])),
                            "friction": sometimes(st.floats(0.0, 1.0)),
                            "restitution": sometimes(st.floats(0.0, 1.0)),
                        },
                        ("name",),
                    ),
                    max_size=2,
                )
            ),
            "particles": sometimes(st.lists(table(PARTICLE_VALUES, ("position",)), max_size=2)),
            "cloth": sometimes(st.lists(table(CLOTH_VALUES, ("size", "resolution", "mass")), max_size=1)),
            "obstacles": sometimes(
                st.lists(shaped(OBSTACLE_VALUES, OBSTACLE_NEEDS, OBSTACLE_SHAPE_ARGUMENTS), max_size=2)
            ),
            "method": sometimes(
                st.dictionaries(
                    st.sampled_from(AVAILABLE),
                    st.dictionaries(
                        st.sampled_from(["iterations", "stiffness", "tolerance", "bogus", "granularity"]),
                        MOSTLY_OK,
                        max_size=2,
                    ),
                    max_size=2,
                )
            ),
        },
    )
)


def run_briefly(scene):
    """Simulate a loaded scene for at most 4 steps: a run, or InputError, or SimulationDiverged.
    Through the methods' ``step`` (``compiled_loop=False``; the checks and the stages are the
    loop's, the same numbers): the loop compiles for each mix of shapes, 15–20 s a mix, and the
    generated scenes make a dozen mixes the scene tests do not, which cost this one test 60–160 s
    of the suite (the loop's specializations are the scene and method tests' to compile)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        simulate(
            scene.model,
            scene.method,
            scene.dt,
            min(scene.duration, 4 * scene.dt),
            scene.method_options.get(scene.method),
            scene.integrator,
            compiled_loop=False,
        )


@pytest.fixture(scope="module")
def scratch(tmp_path_factory):
    return tmp_path_factory.mktemp("fuzz")


@fuzz(400)
@given(document=SCENES, mutation=st.one_of(st.none(), st.tuples(st.integers(0, 400), st.text(max_size=3))))
def test_generated_scene_files_run_or_fail_with_one_input_error(scratch, document, mutation):
    text = toml_document(document)
    if mutation is not None:  # a few characters typed anywhere: a syntax error, mostly
        where, typed = mutation
        text = text[:where] + typed + text[where:]
    path = scratch / "generated.toml"
    path.write_text(text, encoding="utf-8")
    with contextlib.suppress(InputError, SimulationDiverged):
        run_briefly(load_scene(path))


ARGUMENT_VALUES = {
    **OBSTACLE_VALUES,
    **BODY_VALUES,
    **PARTICLE_VALUES,
    **CLOTH_VALUES,
    "friction": sometimes(st.floats(0.0, 2.0)),
    "restitution": sometimes(st.floats(0.0, 1.0)),
    "material": sometimes(st.sampled_from(["m", "n", 0, 7])),
}
ARGUMENTS = st.lists(
    st.sampled_from(sorted(ARGUMENT_VALUES)).flatmap(
        lambda key: st.tuples(st.just(key), one_in_ten(st.one_of(st.integers(), st.floats()), ARGUMENT_VALUES[key]))
    ),
    max_size=6,
).map(dict)
SHAPE_NAMES = one_in_ten(ANY, st.sampled_from(sorted({*BODY_SHAPES, *OBSTACLE_SHAPES})))
TETRAHEDRON = [[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0], [0, 0, 0.1]]
VALID_SHAPE_ARGUMENTS = {
    "sphere": {"radius": 0.1},
    "box": {"half_extents": [0.1, 0.1, 0.1]},
    "capsule": {"radius": 0.05, "half_length": 0.1},
    "convex": {"points": TETRAHEDRON},
    "plane": {"normal": [0, 0, 1]},
}


def with_a_valid_start(name, shape, arguments):
    """``arguments`` over arguments that make a valid ``shape`` (a body also gets a mass), so
    that the random ones are checked one by one rather than all refused at the first."""
    start = dict(VALID_SHAPE_ARGUMENTS.get(shape, {}) if isinstance(shape, str) else {})
    if name == "add_body" and "density" not in arguments:
        start["mass"] = 1.0
    return {**start, **arguments}


@fuzz(300)
@given(
    calls=st.lists(
        st.tuples(
            st.sampled_from(["add_body", "add_obstacle", "add_particles", "add_material", "add_cloth"]),
            SHAPE_NAMES,
            ARGUMENTS,
        ),
        min_size=1,
        max_size=4,
    ),
    gravity=sometimes(vector(3, -10, 10)),
    method=st.sampled_from(AVAILABLE),
)
def test_builder_calls_with_any_arguments_run_or_fail_with_one_input_error(calls, gravity, method):
    with contextlib.suppress(InputError, SimulationDiverged):
        builder = ModelBuilder(gravity=gravity)
        for name, shape, arguments in calls:
            call = getattr(builder, name)
            arguments = keywords_of(call, arguments)
            with contextlib.suppress(InputError):
                if name in ("add_body", "add_obstacle"):
                    call(shape, **keywords_of(call, with_a_valid_start(name, shape, arguments)))
                elif name == "add_particles":
                    call(arguments.pop("position", [[0, 0, 1]]), **arguments)
                elif name == "add_material":
                    call(arguments.pop("name", "m"), **arguments)
                else:
                    call(**arguments)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            # the methods' own steps: they call the same compiled narrow phase and responses as
            # the loop, but compile no loop step for each new mix of shape families the examples
            # make (about 20 s each: on an empty cache these 300 examples took 422 s of CPU, 154 s so)
            simulate(builder.finalize(), method, 0.01, 0.03, compiled_loop=False)


def keywords_of(function, arguments):
    """The entries of ``arguments`` that ``function`` has parameters for (others would be
    Python's own TypeError, not contactlab's business)."""
    import inspect

    known = inspect.signature(function).parameters
    return {key: value for key, value in arguments.items() if key in known}


@fuzz(200)
@given(
    method=sometimes(st.sampled_from(AVAILABLE)),
    dt=sometimes(st.floats(0.005, 0.02)),
    duration=sometimes(st.floats(0.005, 0.05)),
    options=one_in_ten(
        ANY,
        st.one_of(
            st.none(),
            st.builds(penalty.Options),
            st.dictionaries(
                st.sampled_from(["iterations", "stiffness", "tolerance", "contact_margin", "granularity", "bogus"]),
                MOSTLY_OK,
                max_size=2,
            ),
        ),
    ),
    integrator=sometimes(st.sampled_from(["symplectic_euler", "explicit_euler", "backward_euler"])),
    record_every=sometimes(st.integers(1, 3)),
    state=st.sampled_from(["none", "own", "other", "junk"]),
    scene_name=sometimes(st.text(max_size=4)),
    threads=st.one_of(st.none(), st.sampled_from(["auto", 1, 0, "x"])),
)
def test_simulate_with_any_arguments_runs_or_fails_with_one_input_error(
    method, dt, duration, options, integrator, record_every, state, scene_name, threads
):
    model = ball_on_plane(height=0.4)
    other = ModelBuilder()
    other.add_particles([[0, 0, 1], [0, 0, 2]])
    given_state = {"none": None, "own": model.state(), "other": other.finalize().state(), "junk": [1, 2]}[state]
    with contextlib.suppress(InputError, SimulationDiverged), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        simulate(
            model,
            method,
            dt,
            duration,
            options,
            integrator,
            record_every,
            given_state,
            scene_name=scene_name,
            threads=threads,
        )
