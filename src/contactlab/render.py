"""Headless pictures and videos of a trajectory: ``still.png``, ``video.mp4``, ``video.gif``.

Input is a trajectory (the ``arrays`` of :func:`contactlab.simulate`, or a run's
``trajectory.h5`` read back by :func:`contactlab.store.open_trajectory`; see
``docs/trajectory.md``). Only the samples a video draws are read (for a still, at most
:data:`STILL_SAMPLES` spread over the run frame the camera), so a long run is drawn without
holding it in memory. Everything is drawn with matplotlib's Agg
canvas (no pyplot, no display) on 3-D axes, z up:

* rigid bodies: their posed surfaces, flat-shaded, one colour per body (``tab10``, cycled);
* cloths: shaded triangle meshes, both sides lit, one colour per cloth (``Set2``);
* free particles: dots whose size follows their radius;
* static obstacles: light grey and semi-transparent; planes (finite squares in the
  trajectory) are cut to a rectangle around the moving content, and drawn beneath it
  (:mod:`contactlab.scenery` frames them).

The camera is fixed for the whole video: the axis limits enclose everything the drawn samples
reach, with equal scales on x, y and z. Frames play in real time: frame k of a video
at ``fps`` shows the sample nearest to ``time[0] + k / fps``. The GIF is smaller (at most
:data:`GIF_MAX_FPS` frames per second, at most :data:`GIF_MAX_HEIGHT` pixels high) because
GIFs get huge; the MP4 (H.264, yuv420p) uses the full ``fps`` and size. Every file is written
through :func:`contactlab.record.atomic_path`, so none is ever left half-written.
"""

from __future__ import annotations

import contextlib
import math
import os
from collections import Counter
from collections.abc import Mapping, Sequence
from typing import Any

import imageio.v2
import imageio.v3
import numpy as np
from matplotlib import colormaps
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator
from mpl_toolkits.mplot3d import proj3d
from mpl_toolkits.mplot3d.art3d import Poly3DCollection
from numpy.typing import ArrayLike
from PIL import Image

from . import interrupts, surfaces
from .errors import InputError
from .progress import bar as progress_bar
from .record import DRAWN, atomic_path, checked_times, make_folders, read_trajectory, remove_empty
from .scenery import axis_limits, face_normals, scenery
from .trajectory import check_arrays

FORMATS = ("mp4", "gif")
GIF_MAX_FPS = 15  # frames per second of the GIF at most (its delay is a whole 1/100 s)
GIF_MAX_HEIGHT = 300  # pixels; the GIF is the video scaled down to this height at most
MIN_SIZE = 16  # pixels, smallest width or height accepted
MAX_SIZE = 8192  # pixels, largest width or height accepted (8K video is 7680 x 4320)
MAX_FPS = 240  # frames per second at most (the video plays in real time)
DPI = 100
AMBIENT = 0.4  # share of a colour kept by a face turned away from the light
BACKGROUND = "white"
OBSTACLE_RGBA = (0.72, 0.72, 0.72, 0.3)
PARTICLE_RGB = (0.15, 0.3, 0.6)
STILL_SAMPLES = 600  # samples a still reads at most to frame its camera


# -- public API -------------------------------------------------------------------------


def render(
    arrays: Mapping[str, Any],
    directory: str,
    *,
    fps: float = 30,
    width: int = 640,
    height: int = 480,
    elevation: float = 25.0,
    azimuth: float = -60.0,
    formats: Sequence[str] = ("mp4", "gif"),
    title: str | None = None,
    progress: bool = False,
) -> dict[str, str]:
    """Write video.mp4, video.gif (whichever `formats` names) and still.png into `directory` (created if
    needed); return {"mp4": path, "gif": path, "still": path} for what was written.

    fps [1/s] in (0, MAX_FPS]: frames per second of the MP4 (the GIF uses at most ``GIF_MAX_FPS``);
    width, height [px] from MIN_SIZE to MAX_SIZE (the MP4's are rounded up to even numbers, the GIF is scaled down
    to at most ``GIF_MAX_HEIGHT`` px high); elevation, azimuth [degrees]: the camera, as in
    matplotlib's ``view_init``; title: a line above the picture (e.g. "box_pyramid — impulse");
    progress: progress over the frames on stderr (contactlab.progress: a bar on a terminal, else a
    line every few seconds). The still is the last sample.
    All files appear together or not at all: on failure nothing is left behind.
    """
    fps = check_settings(fps, width, height, elevation, azimuth)[0]
    formats = _formats(formats)
    time = checked_times(arrays)
    mp4_times, gif_times, _ = _video_times(time, fps, formats)
    drawn = {len(time) - 1} | {
        int(k) for times in (mp4_times, gif_times) if times is not None for k in nearest(time, times)
    }
    picture = _Picture(arrays, width, height, elevation, azimuth, title, np.array(sorted(drawn)))
    paths = output_paths(directory, formats)
    made = make_folders(os.fspath(directory))
    try:
        with contextlib.ExitStack() as stack:  # renames every file at the end, or removes them all
            temporary = {name: stack.enter_context(atomic_path(path)) for name, path in paths.items()}
            _write_videos(picture, temporary, fps, progress)
            imageio.v3.imwrite(temporary["still"], picture.draw(len(picture.time) - 1))
    except BaseException:
        remove_empty(made)
        raise
    return paths


def output_paths(directory: str, formats: Sequence[str] = ("mp4", "gif")) -> dict[str, str]:
    """What :func:`render` writes into ``directory`` for ``formats``: {"mp4": path, "gif": path,
    "still": path} (whichever formats are named; the still always)."""
    paths = {name: os.path.join(directory, f"video.{name}") for name in _formats(formats)}
    paths["still"] = os.path.join(directory, "still.png")
    return paths


def still(
    arrays: Mapping[str, Any],
    path: str,
    *,
    sample: int = -1,
    width: int = 640,
    height: int = 480,
    elevation: float = 25.0,
    azimuth: float = -60.0,
    title: str | None = None,
) -> str:
    """Write one PNG picture of trajectory sample `sample` to `path`; return the path.

    sample: index into the trajectory's samples (negative counts from the end);
    width, height [px] from MIN_SIZE to MAX_SIZE; elevation, azimuth [degrees]; title: a line above the picture.
    """
    count = len(checked_times(arrays))
    if isinstance(sample, bool) or not isinstance(sample, (int, np.integer)) or not -count <= sample < count:
        raise InputError(
            "sample",
            f"expected a whole number from {-count} to {count - 1} "
            f"(the trajectory has {count} samples), found {sample!r}",
        )
    sample = int(sample) % count
    framing = np.union1d(spread_samples(count), [sample])
    picture = _Picture(arrays, width, height, elevation, azimuth, title, framing)
    image = picture.draw(int(np.searchsorted(framing, sample)))
    with atomic_path(path) as temporary:
        imageio.v3.imwrite(temporary, image, extension=".png")
    return os.fspath(path)


def _write_videos(picture, paths, fps, progress):
    """Draw the frames once and write them to ``paths["mp4"]`` and/or ``paths["gif"]``.

    The MP4 gets ``fps`` frames per second; the GIF a whole number of 1/100 s per frame (at
    most GIF_MAX_FPS frames per second), each one the MP4 frame nearest to its time when there
    is an MP4, and is scaled down to GIF_MAX_HEIGHT pixels high at most.
    """
    time = picture.time
    mp4_times, gif_times, gif_delay = _video_times(time, fps, paths)
    mp4_count = Counter(nearest(time, mp4_times).tolist() if "mp4" in paths else [])
    gif_count = Counter(nearest(time, gif_times).tolist() if "gif" in paths else [])
    gif_frames = []
    samples = sorted(mp4_count | gif_count)
    with (
        _mp4_writer(paths["mp4"], fps) if "mp4" in paths else contextlib.nullcontext() as mp4,
        progress_bar(len(samples), "video", "frame", progress) as shown,
    ):
        for sample in samples:
            interrupts.check()  # Ctrl-C or SIGTERM: between frames
            image = picture.draw(sample)
            for _ in range(mp4_count[sample]):
                mp4.append_data(_even(image))
            gif_frames += [_shrink(image, GIF_MAX_HEIGHT)] * gif_count[sample]
            shown.update(1)
    if gif_frames:
        imageio.v3.imwrite(paths["gif"], np.stack(gif_frames), plugin="pillow", duration=10 * gif_delay, loop=0)


# -- arguments ----------------------------------------------------------------------------


def check_settings(
    fps: float = 30, width: int = 640, height: int = 480, elevation: float = 25.0, azimuth: float = -60.0
) -> tuple[float, int, int, float, float]:
    """The drawing settings checked, an InputError naming the first bad one: fps [1/s] in
    (0, MAX_FPS], width and height [px] whole numbers from MIN_SIZE to MAX_SIZE, elevation and
    azimuth finite [degrees]. Returns them as (fps, width, height, elevation, azimuth). A
    caller that renders after a long run (``contactlab run --video``, compare) calls it first."""
    return (
        _fps(fps),
        _size(width, "width"),
        _size(height, "height"),
        _angle(elevation, "elevation"),
        _angle(azimuth, "azimuth"),
    )


def _number(value, name, check, expected):
    """``value`` as a float if it is a real number passing ``check``, else InputError."""
    if (
        isinstance(value, bool)
        or not isinstance(value, (int, float, np.integer, np.floating))
        or not math.isfinite(value)
        or not check(value)
    ):
        raise InputError(name, f"expected {expected}, found {value!r}")
    return float(value)


def _fps(value):
    return _number(
        value, "fps", lambda v: 0 < v <= MAX_FPS, f"a number of frames per second from above 0 to {MAX_FPS} (e.g. 30)"
    )


def _angle(value, name):
    return _number(value, name, lambda v: True, "a finite number of degrees")


def _size(value, name):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not MIN_SIZE <= value <= MAX_SIZE:
        raise InputError(
            name, f"expected a whole number of pixels from {MIN_SIZE} to {MAX_SIZE} (e.g. 640), found {value!r}"
        )
    return int(value)


def _formats(formats):
    """The video formats named in ``formats`` (one name or several), without repeats."""
    try:
        names = (formats,) if isinstance(formats, str) else tuple(formats)
    except TypeError:
        names = (formats,)
    for name in names:
        if name not in FORMATS:
            raise InputError("formats", f"expected names among {', '.join(FORMATS)}, found {name!r}")
    return tuple(dict.fromkeys(names))


# -- timing -------------------------------------------------------------------------------


def _video_times(time, fps, formats):
    """(MP4 frame times, GIF frame times, GIF delay [1/100 s]) of a trajectory sampled at
    ``time`` (T,) [s]: the MP4 at ``fps``, the GIF at a whole number of 1/100 s per frame (at
    most GIF_MAX_FPS), each GIF frame the MP4 frame nearest to its time when there is an MP4;
    None for a format not in ``formats``. They depend only on time[0] and time[-1]."""
    mp4_times = _frame_times(time, fps)
    gif_delay = _gif_delay(fps)
    gif_times = _frame_times(time, 100.0 / gif_delay)
    if "mp4" in formats:
        gif_times = mp4_times[nearest(mp4_times, gif_times)]
    return (mp4_times if "mp4" in formats else None, gif_times if "gif" in formats else None, gif_delay)


def _frame_times(time, rate):
    """Times (n,) [s] of the frames of a real-time video at ``rate`` frames per second of a
    trajectory sampled at ``time`` (T,) [s]: time[0] + k / rate for k < round(duration × rate),
    at least one frame."""
    count = max(1, int(round((time[-1] - time[0]) * rate)))
    return time[0] + np.arange(count) / rate


def spread_samples(count: int, most: int = STILL_SAMPLES) -> np.ndarray:
    """At most ``most`` sample indices (n,) spread evenly over ``count`` samples, first and last
    included: those that frame a camera without reading a whole long run."""
    return np.unique(np.linspace(0, count - 1, min(count, most)).astype(int))


def nearest(times: np.ndarray, wanted: ArrayLike) -> np.ndarray:
    """Index (n,) of the entry of the sorted ``times`` (T,) nearest to each of ``wanted`` (n,)."""
    after = np.clip(np.searchsorted(times, wanted), 1, max(len(times) - 1, 1))
    before = after - 1
    after = np.minimum(after, len(times) - 1)
    return np.where(wanted - times[before] <= times[after] - wanted, before, after)


def _gif_delay(fps):
    """GIF frame delay [1/100 s]: a whole number of hundredths (all GIF can store), fps ≤ GIF_MAX_FPS."""
    return math.ceil(100.0 / min(fps, GIF_MAX_FPS))


# -- images -------------------------------------------------------------------------------


def _fit(image, height, width):
    """``image`` (h, w, 3) cropped or edge-padded to exactly (height, width, 3)."""
    image = image[:height, :width]
    pad = ((0, height - image.shape[0]), (0, width - image.shape[1]), (0, 0))
    return np.pad(image, pad, mode="edge") if any(p[1] for p in pad) else image


def _even(image):
    """``image`` edge-padded to an even height and width (what H.264 in yuv420p needs)."""
    height, width = image.shape[:2]
    return _fit(image, height + height % 2, width + width % 2)


def _shrink(image, max_height):
    """``image`` scaled down (aspect kept) to at most ``max_height`` pixels high."""
    height, width = image.shape[:2]
    if height <= max_height:
        return image
    size = (max(1, round(width * max_height / height)), max_height)
    return np.asarray(Image.fromarray(image).resize(size, Image.Resampling.LANCZOS))


def _mp4_writer(path, fps):
    """An imageio writer of H.264 MP4 (yuv420p) at ``fps``; frames must have even sizes."""
    return imageio.v2.get_writer(
        path,
        format="FFMPEG",
        mode="I",
        fps=fps,
        codec="libx264",
        pixelformat="yuv420p",
        macro_block_size=1,
        quality=8,
        ffmpeg_log_level="error",
    )


# -- shading ------------------------------------------------------------------------------


def _shade(rgba, normals, light, two_sided):
    """Face colours (N, 4): ``rgba`` (N, 4) darkened by the angle between each face's unit
    normal (N, 3) and the unit vector ``light`` towards the light; ``two_sided`` lights both
    sides of a face alike."""
    cosine = normals @ light
    cosine = np.abs(cosine) if two_sided else np.maximum(cosine, 0.0)
    shaded = rgba.copy()
    shaded[:, :3] *= (AMBIENT + (1.0 - AMBIENT) * cosine)[:, None]
    return shaded


def _light_direction(elevation, azimuth):
    """Unit vector towards a light above the camera and a little to its left (degrees as view_init)."""
    elevation = np.radians(min(elevation + 30.0, 80.0))
    azimuth = np.radians(azimuth - 15.0)
    return np.array([np.cos(elevation) * np.cos(azimuth), np.cos(elevation) * np.sin(azimuth), np.sin(elevation)])


# -- the picture --------------------------------------------------------------------------


class _Picture:
    """One matplotlib Figure that draws any sample of one trajectory.

    The static parts (axes, camera, obstacles, title) are built once; :meth:`draw` only moves
    the bodies', cloths' and particles' collections and the time text. still() and render()
    both draw through it.
    """

    def __init__(self, arrays, width, height, elevation, azimuth, title, samples=None):
        """``samples``: the samples (indices in increasing order) it may draw, the only ones read
        (None: all); draw(i) draws the i-th of them."""
        _, self.width, self.height, elevation, azimuth = check_settings(30, width, height, elevation, azimuth)
        self.arrays = arrays = read_trajectory(arrays, DRAWN, samples)
        check_arrays(arrays)
        self.time = arrays["time"]
        self.light = _light_direction(elevation, azimuth)

        start = arrays["body_surface_triangle_start"]
        body_of = np.repeat(np.arange(len(start) - 1), np.diff(start))
        self.body_triangles = arrays["body_surface_triangles"]
        self.body_rgba = colormaps["tab10"](body_of % 10)
        cloth_of = arrays["particle_cloth"][arrays["triangles"][:, 0]]
        self.cloth_triangles = arrays["triangles"]
        self.cloth_rgba = colormaps["Set2"](cloth_of % 8)
        self.free = np.flatnonzero(arrays["particle_cloth"] < 0)

        content, flat_polygons, flat_normals, solid = scenery(arrays)
        self.obstacle_faces = solid
        self.obstacle_rgba = _shade(np.tile(OBSTACLE_RGBA, (len(solid), 1)), face_normals(solid), self.light, True)

        self.figure = Figure(figsize=(self.width / DPI, self.height / DPI), dpi=DPI, facecolor=BACKGROUND)
        self.canvas = FigureCanvasAgg(self.figure)
        top = 1.0 - 28.0 / self.height if title else 1.0
        self.axes = self._axes(axis_limits(content, flat_polygons), elevation, azimuth, top)
        self._add_flat(flat_polygons, flat_normals)
        self.surfaces = None
        if len(self.body_triangles) + len(self.cloth_triangles) + len(solid):
            self.surfaces = self.axes.add_collection3d(Poly3DCollection(np.zeros((0, 3, 3)), linewidths=0.8, zorder=2))
        self.particles = None
        if len(self.free):
            self.particles = self.axes.scatter(
                *arrays["particle_position"][0, self.free].T, color=PARTICLE_RGB, edgecolors="none", zorder=3
            )
        if title:
            self.figure.text(0.5, 1.0 - 6.0 / self.height, str(title), ha="center", va="top", fontsize=11)
        self.clock = self.figure.text(0.015, 0.015, "", ha="left", va="bottom", fontsize=10, family="monospace")
        self.canvas.draw()  # lays out the axes: needed to size the particles
        if self.particles is not None:
            self.particles.set_sizes(self._particle_sizes(arrays["particle_radius"][self.free]))

    def _axes(self, limits, elevation, azimuth, top):
        """3-D axes filling the figure below ``top`` (a fraction of its height), z up, equal
        scales, fixed limits (lower (3,), upper (3,)) [m] and camera (degrees)."""
        axes = self.figure.add_axes((0.0, 0.0, 1.0, top), projection="3d", computed_zorder=False)
        lower, upper = limits
        axes.set_xlim(lower[0], upper[0])
        axes.set_ylim(lower[1], upper[1])
        axes.set_zlim(lower[2], upper[2])
        axes.set_box_aspect(upper - lower, zoom=0.9)
        axes.view_init(elev=elevation, azim=azimuth)
        for axis, name in zip((axes.xaxis, axes.yaxis, axes.zaxis), "xyz"):
            axis.set_major_locator(MaxNLocator(5))
            axis.set_label_text(f"{name} [m]", fontsize=8)
            axis.set_tick_params(labelsize=7, pad=0)
            axis.labelpad = -2
            axis.set_pane_color((1.0, 1.0, 1.0, 0.0))  # only obstacles are grey
        return axes

    def _add_flat(self, polygons, normals):
        """Flat obstacles (cut planes; polygons (k, 3) [m], unit normals (n, 3)), drawn first so
        that they never hide the scene."""
        if not polygons:
            return
        rgba = _shade(np.tile(OBSTACLE_RGBA, (len(polygons), 1)), normals, self.light, True)
        self.axes.add_collection3d(Poly3DCollection(polygons, facecolors=rgba, edgecolors="none", zorder=1))

    def _particle_sizes(self, radius):
        """Marker areas [pt²] of dots of ``radius`` (n,) [m] at the middle of the view."""
        axes = self.axes
        centre = np.array([np.mean(axes.get_xlim()), np.mean(axes.get_ylim()), np.mean(axes.get_zlim())])
        length = 0.1 * np.ptp(axes.get_xlim())
        azimuth = np.radians(axes.azim)
        ends = np.stack([centre, centre + length * np.array([-np.sin(azimuth), np.cos(azimuth), 0.0])])
        x, y, _ = proj3d.proj_transform(*ends.T, axes.get_proj())
        pixels = axes.transData.transform(np.column_stack([x, y]))
        points_per_metre = np.linalg.norm(pixels[1] - pixels[0]) / length * 72.0 / DPI
        return np.maximum(2.0 * radius * points_per_metre, 2.0) ** 2

    def _surface_faces(self, sample):
        """Faces (N, 3, 3) [m] and colours (N, 4) of bodies, cloths and solid obstacles at ``sample``."""
        arrays = self.arrays
        bodies = surfaces.posed_body_vertices(arrays, sample)[self.body_triangles]
        cloths = arrays["particle_position"][sample][self.cloth_triangles]
        faces = np.concatenate([bodies, cloths, self.obstacle_faces])
        rgba = np.concatenate(
            [
                _shade(self.body_rgba, face_normals(bodies), self.light, False),
                _shade(self.cloth_rgba, face_normals(cloths), self.light, True),
                self.obstacle_rgba,
            ]
        )
        return faces, rgba

    def draw(self, sample):
        """The picture (height, width, 3) uint8 of trajectory sample ``sample`` (an index ≥ 0)."""
        if self.surfaces is not None:
            faces, rgba = self._surface_faces(sample)
            self.surfaces.set_verts(faces)
            self.surfaces.set_facecolor(rgba)
            edges = rgba.copy()  # hide the seams between opaque faces only
            edges[rgba[:, 3] < 1.0, 3] = 0.0
            self.surfaces.set_edgecolor(edges)
        if self.particles is not None:
            position = self.arrays["particle_position"][sample, self.free]
            self.particles.set_offsets(position[:, :2])
            self.particles.set_3d_properties(position[:, 2], "z")
        self.clock.set_text(f"t = {self.time[sample]:.3f} s")
        self.canvas.draw()
        image = np.asarray(self.canvas.buffer_rgba())[:, :, :3]
        return _fit(image, self.height, self.width).copy()
