"""contactlab.render: real-time MP4/GIF videos and PNG stills of a trajectory, drawn headless."""

import dataclasses
import os
import re
import subprocess
import sys

import imageio.v2
import imageio.v3
import numpy as np
import pytest
from PIL import Image

from contactlab import InputError, ModelBuilder, render, scenery, simulate, store
from contactlab.record import SERIES, Recorder
from contactlab.scene import load_scene

SMALL = dict(width=160, height=120)


def falling_box(duration=0.5, x=0.0):
    """A cube dropped from 0.3 m onto the floor z = 0, sampled every 0.01 s."""
    builder = ModelBuilder()
    builder.add_body("box", half_extents=(0.05, 0.05, 0.05), mass=1.0, position=(x, 0.0, 0.35))
    builder.add_obstacle("plane", normal=(0, 0, 1), offset=0.0)
    return simulate(builder.finalize(), "impulse", 0.01, duration).arrays


@pytest.fixture(scope="module")
def box_run():
    return falling_box()


@pytest.fixture(scope="module")
def drape():
    """cloth_drape for 0.6 s: the cloth has fallen onto the sphere and bends over it."""
    scene = load_scene("cloth_drape")
    return simulate(
        scene.model,
        scene.method,
        scene.dt,
        0.6,
        options=scene.method_options.get(scene.method),
        integrator=scene.integrator,
    ).arrays


def mp4_frames(path):
    """(frame count, (width, height)) of an MP4, decoded with imageio-ffmpeg."""
    with imageio.v2.get_reader(path, format="FFMPEG") as reader:
        return reader.count_frames(), tuple(reader.get_meta_data()["size"])


def coloured(image, threshold=20):
    """Mask (H, W) of saturated pixels: bodies and cloths; obstacles, axes and text are grey."""
    image = image.astype(int)
    return image.max(axis=2) - image.min(axis=2) > threshold


# -- files --------------------------------------------------------------------------------


def test_video_and_still_read_back_with_real_time_frame_counts(box_run, tmp_path):
    trajectory = store.write(tmp_path / "trajectory.h5", box_run, series=SERIES)
    arrays = store.open_trajectory(trajectory)  # a trajectory file works like the dict
    paths = render.render(arrays, tmp_path / "video", fps=20, title="falling box", **SMALL)
    assert set(paths) == {"mp4", "gif", "still"}
    assert sorted(os.listdir(tmp_path / "video")) == ["still.png", "video.gif", "video.mp4"]

    frames, size = mp4_frames(paths["mp4"])
    assert abs(frames - 0.5 * 20) <= 1 and size == (160, 120)
    gif = imageio.v3.imread(paths["gif"], index=None)
    delay = render._gif_delay(20)  # 1/100 s: 7 for any fps ≥ 15
    assert gif.shape[1:3] == (120, 160) and abs(len(gif) - 0.5 * 100 / delay) <= 1
    with Image.open(paths["gif"]) as image:
        assert image.info["loop"] == 0 and image.info["duration"] == 10 * delay
    assert imageio.v3.imread(paths["still"]).shape == (120, 160, 3)


def test_gif_only_is_scaled_down_and_mp4_sizes_are_made_even(box_run, tmp_path):
    paths = render.render(box_run, tmp_path, fps=10, formats="gif", width=401, height=601)
    assert set(paths) == {"gif", "still"} and not (tmp_path / "video.mp4").exists()
    gif = imageio.v3.imread(paths["gif"], index=None)
    assert gif.shape[1] == render.GIF_MAX_HEIGHT and abs(gif.shape[2] - 401 * 300 / 601) <= 1
    assert len(gif) == 5  # 0.5 s at 10 frames per second
    assert imageio.v3.imread(paths["still"]).shape == (601, 401, 3)

    paths = render.render(box_run, tmp_path / "odd", fps=10, formats=["mp4"], width=101, height=75)
    assert mp4_frames(paths["mp4"]) == (5, (102, 76))  # H.264 yuv420p needs even sizes


def test_frames_show_the_sample_nearest_to_their_time():
    time = np.array([0.0, 0.04, 0.1, 0.19, 0.3, 0.42])
    frames = render._frame_times(time, 10.0)
    assert np.allclose(frames, [0.0, 0.1, 0.2, 0.3])  # round(0.42 s × 10) frames
    assert render.nearest(time, frames).tolist() == [0, 2, 3, 4]
    assert render._frame_times(np.array([2.5]), 30.0).tolist() == [2.5]  # one sample: one frame
    assert render.nearest(np.array([2.5]), np.array([2.5])).tolist() == [0]


def empty_trajectory(duration):
    """Two samples, 0 and ``duration`` s, of a scene with nothing in it (which simulate refuses:
    nothing to simulate), recorded as a run records them."""
    model = ModelBuilder().finalize()
    recorder = Recorder(model)
    start = model.state()
    recorder.sample(start)
    recorder.sample(dataclasses.replace(start, time=duration))
    return recorder.arrays()


def test_one_sample_and_an_empty_scene_still_make_videos(tmp_path):
    empty = empty_trajectory(0.2)
    paths = render.render(empty, tmp_path / "empty", fps=10, **SMALL)
    assert mp4_frames(paths["mp4"])[0] == 2
    assert not coloured(imageio.v3.imread(paths["still"])).any()

    single = dict(falling_box(0.05))
    for key in ("time", "body_position", "body_orientation", "particle_position"):
        single[key] = single[key][:1]
    paths = render.render(single, tmp_path / "single", **SMALL)
    assert mp4_frames(paths["mp4"])[0] == 1
    assert len(imageio.v3.imread(paths["gif"], index=None)) == 1


# -- what the pictures show --------------------------------------------------------------


def test_still_shows_the_box_where_it_is_and_shades_its_faces(box_run, tmp_path):
    moved = dict(box_run)  # sample 0: x = −0.3 m, last sample: x = +0.3 m
    moved["body_position"] = box_run["body_position"].copy()
    moved["body_position"][0, 0, 0] = -0.3
    moved["body_position"][-1, 0, 0] = 0.3
    columns = []
    for sample in (0, -1):
        path = render.still(moved, tmp_path / f"box{sample}.png", sample=sample)
        box = coloured(imageio.v3.imread(path))
        assert 500 < box.sum() < 0.2 * box.size
        columns.append(np.nonzero(box)[1].mean())
    assert columns[1] - columns[0] > 100  # x runs to the right at azimuth −60°

    image = imageio.v3.imread(path).astype(int)
    brightness = image[coloured(image)].sum(axis=1)
    low, high = np.percentile(brightness, [10, 90])
    assert high - low > 60  # lit top face, darker sides


def test_cloth_is_visible_and_shaded_by_its_folds(drape, tmp_path):
    spreads = []
    for sample in (0, -1):  # flat at first, draped over the sphere
        image = imageio.v3.imread(render.still(drape, tmp_path / f"cloth{sample}.png", sample=sample))
        cloth = coloured(image)
        assert cloth.sum() > 0.03 * cloth.size
        brightness = image[cloth].astype(int).sum(axis=1)
        low, high = np.percentile(brightness, [10, 90])
        spreads.append(high - low)
    assert spreads[0] < 15 and spreads[1] > 40


def test_floor_is_cut_to_the_scene_and_lies_beneath_it(box_run, tmp_path):
    picture = render._Picture(box_run, 160, 120, 25.0, -60.0, None)
    axes = picture.axes
    lower, upper = np.transpose([axes.get_xlim(), axes.get_ylim(), axes.get_zlim()])
    assert lower[2] == pytest.approx(0.0, abs=1e-3)  # the floor, not below it
    assert np.all(upper[:2] - lower[:2] < 1.0)  # cut from the trajectory's square
    assert upper[2] == pytest.approx(0.4, abs=1e-3)  # the box's top at the start


def test_walls_end_at_the_floor():
    floor = np.array([[[-1, -1, 0], [1, -1, 0], [1, 1, 0]], [[-1, -1, 0], [1, 1, 0], [-1, 1, 0]]], float)
    wall = np.array(
        [
            [[0.5, 1, 1], [0.5, 1, -1], [0.5, -1, -1]],  # x = 0.5, facing −x
            [[0.5, -1, 1], [0.5, 1, 1], [0.5, -1, -1]],
        ],
        float,
    )
    assert scenery.face_normals(floor)[0] == pytest.approx([0, 0, 1])
    assert np.allclose(scenery.face_normals(wall), [-1, 0, 0])
    polygons, normals = scenery.cut_flat([floor, wall], np.array([-0.2, -0.2, -0.2]), np.array([0.8, 0.2, 0.2]))
    floor_points = np.concatenate([p for p, n in zip(polygons, normals) if n[2] == 1])
    wall_points = np.concatenate([p for p, n in zip(polygons, normals) if n[0] == -1])
    assert wall_points[:, 2].min() == pytest.approx(0.0, abs=1e-6)  # the wall stops at the floor …
    assert floor_points[:, 0].max() == pytest.approx(0.5, abs=1e-6)  # … the floor at the wall
    assert floor_points[:, 1].max() == pytest.approx(0.2)  # both cut to the view box
    assert wall_points[:, 2].max() == pytest.approx(0.2)


# -- failures -----------------------------------------------------------------------------


class Broken(RuntimeError):
    pass


def test_failed_encoding_leaves_no_file_behind(box_run, tmp_path, monkeypatch):
    class HalfWriter:
        def __init__(self, path, **options):
            self.path = path

        def append_data(self, image):
            with open(self.path, "ab") as stream:
                stream.write(b"half a frame")
            raise Broken("encoder died")

        def __enter__(self):
            return self

        def __exit__(self, *error):
            return False

    monkeypatch.setattr(imageio.v2, "get_writer", lambda path, **options: HalfWriter(path, **options))
    with pytest.raises(Broken):
        render.render(box_run, tmp_path / "new", **SMALL)
    assert not (tmp_path / "new").exists()  # the folder it created goes too

    (tmp_path / "old").mkdir()
    (tmp_path / "old" / "notes.txt").write_text("keep me")
    with pytest.raises(Broken):
        render.render(box_run, tmp_path / "old", **SMALL)
    assert os.listdir(tmp_path / "old") == ["notes.txt"]


def test_failed_png_leaves_no_file_behind(box_run, tmp_path, monkeypatch):
    def half_png(path, image, **options):
        open(path, "wb").write(b"\x89PNG half")
        raise Broken("disk full")

    monkeypatch.setattr(imageio.v3, "imwrite", half_png)
    with pytest.raises(Broken):
        render.still(box_run, tmp_path / "still.png", **SMALL)
    with pytest.raises(Broken):
        render.render(box_run, tmp_path, formats=(), **SMALL)
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize(
    "options, field",
    [
        (dict(fps=0), "fps"),
        (dict(fps=-5), "fps"),
        (dict(fps=float("nan")), "fps"),
        (dict(width=8), "width"),
        (dict(height=15), "height"),
        (dict(width=320.5), "width"),
        (dict(formats=("mp4", "avi")), "formats"),
        (dict(formats="webm"), "formats"),
        (dict(formats=None), "formats"),
        (dict(elevation=float("inf")), "elevation"),
    ],
)
def test_bad_arguments_name_the_argument(box_run, tmp_path, options, field):
    with pytest.raises(InputError) as error:
        render.render(box_run, tmp_path / "out", **options)
    assert error.value.field == field and field in str(error.value)
    assert not (tmp_path / "out").exists()


def test_bad_sample_or_trajectory(box_run, tmp_path):
    with pytest.raises(InputError, match="sample") as error:
        render.still(box_run, tmp_path / "x.png", sample=len(box_run["time"]))
    assert error.value.field == "sample"
    with pytest.raises(InputError, match="obstacle_vertices"):
        render.still({k: v for k, v in box_run.items() if k != "obstacle_vertices"}, tmp_path / "x.png")
    assert os.listdir(tmp_path) == []


# -- running ------------------------------------------------------------------------------


def test_progress_goes_to_stderr(box_run, tmp_path, capsys, monkeypatch):
    from contactlab import progress

    monkeypatch.setattr(progress, "PLAIN_SECONDS", 0.0)  # stderr is no terminal here: a line per frame
    render.render(box_run, tmp_path, fps=10, formats=("gif",), progress=True, **SMALL)
    captured = capsys.readouterr()
    assert re.search(r"^video: (\d+)/\1 frames \(100 %\) after \d+ s$", captured.err, re.M) and captured.out == ""


def test_drawing_never_touches_pyplot(tmp_path):
    code = (
        "import sys, matplotlib; from contactlab import ModelBuilder, simulate, render; "
        "b = ModelBuilder(); b.add_particles([[0, 0, 1]], radius=0.05, mass=1.0); "
        "run = simulate(b.finalize(), 'impulse', 0.01, 0.02); "
        f"render.still(run.arrays, {str(tmp_path / 'p.png')!r}, width=64, height=48); "
        "print('matplotlib.pyplot' in sys.modules)"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "False"
