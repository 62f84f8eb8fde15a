"""The interactive viewer: runs in a web browser, served from this machine by viser.

    viewer = view("out/box_pyramid-impulse")          # or a compare folder, several folders, a Run
    print(viewer.url)                                   # http://127.0.0.1:PORT, loopback only
    viewer.stop()

``contactlab view RUN_DIR…`` and ``contactlab run … --view`` serve it until Ctrl-C;
:func:`view` returns it, serving in the background (a notebook goes on).
viser (https://viser.studio) draws the scene with three.js in the page and gives the orbit
camera; its built web client ships in its wheel, so nothing is fetched from the network.

What it shows (docs/viewer.md):

* each run under its own node ``/runI`` (I = 0, 1, …), its runs side by side along x, a label
  above each: bodies ``/runI/bodies/B`` (their surfaces from the trajectory, posed at each sample),
  cloths ``/runI/cloth``, free particles ``/runI/particles``, the static obstacles
  ``/runI/obstacles`` (planes cut around the content, as :func:`contactlab.scenery.scenery` frames them);
* one clock for all runs (time-locked): each run shows its sample nearest to the clock's time;
  play, pause, scrub, playback speed;
* on request, for the shown samples: contact points ``/runI/contacts/points``, normals
  ``/runI/contacts/normals`` and force arrows ``/runI/contacts/forces``. Contacts are not stored
  in a trajectory: the points, normals and depths come from :func:`contactlab.collision.collide`
  on the recorded state, and the forces from a step of the run's method from that state
  (:attr:`contactlab.methods.StepInfo.impulses` over the step's dt), warm started by one step
  before it. Both need the run's Model, rebuilt from its summary's ``source`` (or its built-in
  scene's name); they are computed only while a toggle needs them, so scrubbing stays smooth;
* bodies coloured each its own colour, or by penetration (their deepest contact) or by speed.

The runs are opened by :mod:`contactlab.viewed_runs`; a sample's contacts are rebuilt by
:mod:`contactlab.sample_contacts`.
"""

from __future__ import annotations

import contextlib
import html
import io
import os
import signal
import socket
import threading
import time
from typing import TYPE_CHECKING

import numpy as np
from matplotlib import colormaps

from . import interrupts
from .errors import InputError
from .record import DRAWN, read_trajectory
from .render import OBSTACLE_RGBA, PARTICLE_RGB, nearest, spread_samples
from .sample_contacts import contacts_at, state_at
from .scenery import scenery
from .trajectory import check_arrays
from .viewed_runs import Shown, open_runs

if TYPE_CHECKING:
    from .simulation import Run


HOST = "127.0.0.1"  # the viewer listens on loopback only
FRAME_SECONDS = 1.0 / 30.0  # s: how often the clock moves while playing
GAP = 0.3  # runs side by side are this share of the widest (or tallest) apart
SPEEDS = ("0.1×", "0.25×", "0.5×", "1×", "2×", "4×")
COLOURINGS = ("each body its colour", "penetration", "speed")
FORCE_SHARE = 0.25  # the heaviest body's weight draws as an arrow of this share of the scene's size
POINT_RGB = (220, 30, 30)
NORMAL_RGB = (30, 90, 220)
FORCE_RGB = (255, 140, 0)
SPEED_MAP, PENETRATION_MAP = "viridis", "YlOrRd"
BODY_SEEN_THROUGH = 0.55  # bodies' opacity while contacts are shown (their arrows are inside them)


# -- lines and colours for viser --------------------------------------------------------------


def _segments(starts, vectors):
    """Line segments (N, 2, 3) from ``starts`` (N, 3) along ``vectors`` (N, 3)."""
    return np.stack([starts, starts + vectors], axis=1)


def _arrows(starts, vectors, head=0.25):
    """Arrows as line segments (3N, 2, 3): a shaft from each of ``starts`` (N, 3) along
    ``vectors`` (N, 3), and two barbs at its tip, ``head`` of its length long."""
    tips = starts + vectors
    across = np.cross(
        vectors,
        np.where(
            np.abs(vectors[:, 2:3]) < 0.9 * np.linalg.norm(vectors, axis=1, keepdims=True),
            [0.0, 0.0, 1.0],
            [1.0, 0.0, 0.0],
        ),
    )
    across *= (
        0.5
        * head
        * np.linalg.norm(vectors, axis=1, keepdims=True)
        / np.maximum(np.linalg.norm(across, axis=1, keepdims=True), 1e-300)
    )
    back = tips - head * vectors
    return np.concatenate(
        [_segments(starts, vectors), np.stack([tips, back + across], axis=1), np.stack([tips, back - across], axis=1)]
    )


def _rgb255(rgb):
    return np.clip(np.round(np.asarray(rgb, dtype=float)[..., :3] * 255.0), 0, 255).astype(np.uint8)


# -- the viewer ---------------------------------------------------------------------------


def _quiet():
    """viser prints a banner on starting and a line on stopping whatever its ``verbose``; the
    viewer prints its own address instead."""
    return contextlib.redirect_stdout(io.StringIO())


def check_port(port: int | None) -> int:
    """``port`` checked (None: any free one, 0 to the OS): a whole number from 1 to 65535 that
    nothing on 127.0.0.1 listens on, else InputError("--port", ...)."""
    if port is None:
        return 0
    if isinstance(port, bool) or not isinstance(port, (int, np.integer)) or not 1 <= port <= 65535:
        raise InputError("--port", f"expected a whole number from 1 to 65535, found {port!r}")
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        try:
            probe.bind((HOST, int(port)))
        except OSError:
            raise InputError(
                "--port",
                f"port {port} on {HOST} is in use (another viewer?); give another --port, or none for a free one",
            ) from None
    return int(port)


class Viewer:
    """The viewer of a list of :class:`~contactlab.viewed_runs.Shown` runs, serving on 127.0.0.1 from construction on.

    ``url``: its address; ``server``: the viser.ViserServer (``server.scene`` holds the nodes
    the module docstring names); :meth:`show_time` moves the clock, :meth:`stop` ends it.
    Toggles: ``gui["points"]``, ``gui["normals"]``, ``gui["forces"]`` (checkboxes),
    ``gui["colour"]`` (a dropdown of COLOURINGS), ``gui["force_scale"]`` [N per m of arrow],
    ``gui["time"]`` [s], ``gui["play"]``, ``gui["speed"]``.
    """

    def __init__(self, runs: list[Shown], port: int | None = None) -> None:
        import viser

        requested = check_port(port)
        self.runs = runs
        self.lock = threading.RLock()
        self.time = [np.asarray(read_trajectory(run.arrays, ("time",))["time"], dtype=float) for run in runs]
        self.start = min(float(t[0]) for t in self.time)
        self.end = max(float(t[-1]) for t in self.time)
        self.shown = [None] * len(runs)  # the sample each run shows
        self.contacts = [None] * len(runs)  # its ContactView while a toggle needs one
        self.playing = False
        self.speed = 1.0
        with _quiet():
            self.server = viser.ViserServer(host=HOST, port=requested, verbose=False)
        if requested and self.server.get_port() != requested:  # taken meanwhile: viser moved to the next
            self._stop_server()
            check_port(requested)
        self.port = self.server.get_port()
        self.url = f"http://{HOST}:{self.port}"
        try:
            self._build()
            self.show_time(self.start)
        except BaseException:
            self._stop_server()
            raise
        self._stopping = threading.Event()
        self._player = threading.Thread(target=self._play, name="contactlab-viewer-clock", daemon=True)
        self._player.start()

    # -- building the scene ----------------------------------------------------------------

    def _build(self):
        scene = self.server.scene
        scene.set_up_direction("+z")
        frames = [self._framing(run, len(times)) for run, times in zip(self.runs, self.time)]
        slot = (1.0 + GAP) * max(max(upper[0] - lower[0], upper[2] - lower[2]) for lower, upper, _ in frames)
        for index, (run, (lower, upper, obstacles)) in enumerate(zip(self.runs, frames)):
            run.offset = np.array([index * slot - 0.5 * (lower[0] + upper[0]), 0.0, 0.0])
            self._add_run(index, run, lower, upper, obstacles)
        lower = np.min([f[0] + r.offset for f, r in zip(frames, self.runs)], axis=0)
        upper = np.max([f[1] + r.offset for f, r in zip(frames, self.runs)], axis=0)
        self.size = float(max(np.max(upper - lower), 1e-3))
        centre = 0.5 * (lower + upper)
        self.server.initial_camera.look_at = tuple(centre)
        self.server.initial_camera.position = tuple(centre + self.size * np.array([0.3, -0.9, 0.5]))
        self._add_gui()

    @staticmethod
    def _framing(run, count):
        """(lower (3,), upper (3,)) [m] of a run's content over its ``count`` samples, and its
        obstacles as (vertices (W, 3) [m], triangles (M, 3)), planes cut around the content."""
        try:
            arrays = read_trajectory(run.arrays, DRAWN, spread_samples(count))
            check_arrays(arrays)
        except InputError as error:  # named by the run's folder (as render names its OUT_DIR)
            raise InputError(run.source, error.message) from None
        content, flat, _, solid = scenery(arrays)
        vertices = np.concatenate([solid.reshape(-1, 3), *flat])
        counts = np.array([len(polygon) for polygon in flat], dtype=np.int64)
        first = len(solid) * 3 + np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
        fans = [
            np.column_stack([np.full(n - 2, f), f + np.arange(1, n - 1), f + np.arange(2, n)])
            for f, n in zip(first, counts)
        ]  # each flat polygon (convex) as a fan of triangles
        triangles = np.concatenate([np.arange(3 * len(solid)).reshape(-1, 3), *fans]).astype(np.int64)
        points = [vertices] + ([np.stack(content)] if content is not None else [])
        points = np.concatenate(points)
        lower, upper = (points.min(axis=0), points.max(axis=0)) if len(points) else (-np.ones(3), np.ones(3))
        return lower, upper, (vertices, triangles)

    def _add_run(self, index, run, lower, upper, obstacles):
        scene, root = self.server.scene, f"/run{index}"
        arrays = read_trajectory(
            run.arrays,
            (
                "body_surface_vertices",
                "body_surface_vertex_start",
                "body_surface_triangles",
                "body_surface_triangle_start",
                "triangles",
                "particle_cloth",
                "particle_radius",
            ),
        )
        scene.add_frame(root, show_axes=False, position=run.offset)
        vertices, triangles = obstacles
        if len(triangles):
            scene.add_mesh_simple(
                f"{root}/obstacles",
                vertices,
                triangles,
                color=tuple(_rgb255(OBSTACLE_RGBA)),
                opacity=0.5,
                side="double",
                flat_shading=True,
            )
        starts, tri_starts = arrays["body_surface_vertex_start"], arrays["body_surface_triangle_start"]
        run.body_rgb = _rgb255(colormaps["tab10"](np.arange(len(starts) - 1) % 10))
        run.bodies = [
            scene.add_mesh_simple(
                f"{root}/bodies/{b}",
                arrays["body_surface_vertices"][starts[b] : starts[b + 1]],
                arrays["body_surface_triangles"][tri_starts[b] : tri_starts[b + 1]] - starts[b],
                color=tuple(run.body_rgb[b]),
                flat_shading=True,
            )
            for b in range(len(starts) - 1)
        ]
        run.cloth_triangles = arrays["triangles"]
        run.free = np.flatnonzero(arrays["particle_cloth"] < 0)
        run.point_size = float(2.0 * np.mean(arrays["particle_radius"][run.free])) if len(run.free) else 0.0
        centre = 0.5 * (lower + upper)
        above = upper[2] + 0.08 * (upper - lower).max()
        scene.add_label(f"{root}/label", run.label, position=(centre[0], centre[1], above), anchor="bottom-center")
        series = read_trajectory(
            run.arrays, ("body_velocity", "max_penetration"), spread_samples(len(self.time[index]))
        )
        speeds = np.linalg.norm(series["body_velocity"], axis=-1)
        run.speed_range = float(max(speeds.max(initial=0.0), 1e-6))
        run.depth_range = float(max(np.max(series["max_penetration"], initial=0.0), 1e-6))
        run.weight = (
            float(np.max(run.model.body_mass, initial=0.0) * np.linalg.norm(run.model.gravity))
            if run.model is not None
            else 0.0
        )

    def _add_gui(self):
        gui, self.gui = self.server.gui, {}
        step = min((float(np.min(np.diff(t))) for t in self.time if len(t) > 1), default=1.0)
        with gui.add_folder("Time"):
            self.gui["time"] = gui.add_slider(
                "time [s]", self.start, max(self.end, self.start + step), step, self.start
            )
            self.gui["play"] = gui.add_button("Play", icon=None)
            self.gui["speed"] = gui.add_dropdown("speed", SPEEDS, initial_value="1×")
        with gui.add_folder("Contacts"):
            have_model = any(run.model is not None for run in self.runs)
            self.gui["points"] = gui.add_checkbox("contact points", False, disabled=not have_model)
            self.gui["normals"] = gui.add_checkbox("normals", False, disabled=not have_model)
            self.gui["forces"] = gui.add_checkbox("force arrows", False, disabled=not have_model)
            weight = max(run.weight for run in self.runs)
            scale = weight / (FORCE_SHARE * self.size) if weight > 0 else 100.0
            self.gui["force_scale"] = gui.add_number("force scale [N per m]", float(f"{scale:.2g}"), min=1e-9)
            self.gui["legend"] = gui.add_markdown("")
        with gui.add_folder("Colours"):
            self.gui["colour"] = gui.add_dropdown("bodies", COLOURINGS, initial_value=COLOURINGS[0])
            self.gui["colour_legend"] = gui.add_markdown("")
        missing = [run.label for run in self.runs if run.model is None]
        if missing:
            gui.add_markdown(
                f"*No contacts for {', '.join(missing)}: they need the run's scene, which could not "
                f"be loaded again (a scene file moved or changed since the run).*"
            )
        self.gui["time"].on_update(lambda _: self.show_time(self.gui["time"].value, from_slider=True))
        self.gui["play"].on_click(lambda _: self.set_playing(not self.playing))
        self.gui["speed"].on_update(lambda _: setattr(self, "speed", float(self.gui["speed"].value.rstrip("×"))))
        for name in ("points", "normals", "forces", "force_scale", "colour"):
            self.gui[name].on_update(lambda _: self.redraw())
        self._legends()

    def _legends(self):
        scale = float(self.gui["force_scale"].value)
        self.gui["legend"].content = (
            f"Red dots: contact points; blue: normals (from B into A); orange arrows: "
            f"the force on a moving side (on A where both move). "
            f"**Arrow scale: 10 cm = {0.1 * scale:.3g} N.**"
        )
        colour = self.gui["colour"].value
        ranges = {
            "speed": ("speed", "m/s", "dark blue 0 → yellow"),
            "penetration": ("deepest contact", "mm", "pale yellow 0 → dark red"),
        }
        if colour in ranges:
            what, unit, words = ranges[colour]
            top = max(run.speed_range if colour == "speed" else 1000.0 * run.depth_range for run in self.runs)
            self.gui["colour_legend"].content = f"{what}: {words} {top:.3g} {unit} (the run's largest)"
        else:
            self.gui["colour_legend"].content = "each body its own colour"

    # -- the clock -------------------------------------------------------------------------

    def set_playing(self, playing: bool) -> None:
        """Start (True) or pause (False) the clock."""
        self.playing = bool(playing)
        self.gui["play"].label = "Pause" if self.playing else "Play"

    def _play(self):
        last = time.perf_counter()
        while not self._stopping.wait(FRAME_SECONDS):
            now = time.perf_counter()
            if self.playing:
                t = float(self.gui["time"].value) + self.speed * (now - last)
                self.show_time(self.start if t > self.end else t)
            last = now

    def show_time(self, t: float, from_slider: bool = False) -> None:
        """Show every run at its sample nearest to time ``t`` [s] (clamped to the runs' span)."""
        t = float(min(max(t, self.start), self.end))
        with self.lock:
            if not from_slider and abs(self.gui["time"].value - t) > 0.0:
                self.gui["time"].value = t
            samples = [int(nearest(times, np.array([t]))[0]) for times in self.time]
            if samples != self.shown:
                self.shown = samples
                self.redraw(moved=True)

    def redraw(self, moved: bool = False) -> None:
        """Draw the shown samples again (after a toggle, or ``moved``: new samples)."""
        with self.lock, self.server.atomic():
            self._legends()
            for index, run in enumerate(self.runs):
                self._draw(index, run, self.shown[index], moved)

    def _wants_contacts(self):
        return (
            self.gui["points"].value
            or self.gui["normals"].value
            or self.gui["forces"].value
            or self.gui["colour"].value == "penetration"
        )

    def _draw(self, index, run, sample, moved):
        scene, root = self.server.scene, f"/run{index}"
        row = read_trajectory(
            run.arrays, ("body_position", "body_orientation", "body_velocity", "particle_position"), [sample]
        )
        if moved:
            for body, handle in enumerate(run.bodies):
                handle.position = row["body_position"][0, body]
                handle.wxyz = row["body_orientation"][0, body]
            if len(run.cloth_triangles):
                scene.add_mesh_simple(
                    f"{root}/cloth",
                    row["particle_position"][0],
                    run.cloth_triangles,
                    color=tuple(_rgb255(colormaps["Set2"](0))),
                    side="double",
                    flat_shading=True,
                )
            if len(run.free):
                scene.add_point_cloud(
                    f"{root}/particles",
                    row["particle_position"][0, run.free],
                    colors=tuple(_rgb255(PARTICLE_RGB)),
                    point_size=run.point_size,
                    point_shape="circle",
                )
        wanted = self._wants_contacts() and run.model is not None
        if wanted and (moved or self.contacts[index] is None):
            self.contacts[index] = contacts_at(run.model, run.summary, state_at(run.arrays, sample))
        contacts = self.contacts[index] if wanted else None
        self._draw_contacts(root, contacts)
        self._colour(run, row["body_velocity"][0], contacts)

    def _draw_contacts(self, root, contacts):
        scene = self.server.scene
        thickness = 0.004 * self.size
        drawn = set()
        if contacts is not None and self.gui["points"].value and len(contacts.points):
            scene.add_point_cloud(
                f"{root}/contacts/points",
                contacts.points,
                colors=POINT_RGB,
                point_size=0.01 * self.size,
                point_shape="circle",
            )
            drawn.add("points")
        if contacts is not None and self.gui["normals"].value and len(contacts.points):
            scene.add_line_segments(
                f"{root}/contacts/normals",
                _segments(contacts.points, 0.06 * self.size * contacts.normals),
                colors=NORMAL_RGB,
                thickness=thickness,
            )
            drawn.add("normals")
        if contacts is not None and self.gui["forces"].value and len(contacts.forces):
            scale = float(self.gui["force_scale"].value)
            scene.add_line_segments(
                f"{root}/contacts/forces",
                _arrows(contacts.force_points, contacts.forces / max(scale, 1e-12)),
                colors=FORCE_RGB,
                thickness=1.5 * thickness,
            )
            drawn.add("forces")
        for name in {"points", "normals", "forces"} - drawn:
            scene.remove_by_name(f"{root}/contacts/{name}")

    def _colour(self, run, velocity, contacts):
        """Colour the run's bodies: their own colours, or by penetration or speed."""
        colour = self.gui["colour"].value
        if colour == "speed":
            rgb = _rgb255(colormaps[SPEED_MAP](np.linalg.norm(velocity, axis=1) / run.speed_range))
        elif colour == "penetration" and contacts is not None:
            rgb = _rgb255(colormaps[PENETRATION_MAP](contacts.body_depth / run.depth_range))
        else:
            rgb = run.body_rgb
        opacity = BODY_SEEN_THROUGH if contacts is not None else None  # arrows inside bodies show
        if getattr(run, "painted", None) == (rgb.tobytes(), opacity):  # unchanged: nothing to send
            return
        run.painted = (rgb.tobytes(), opacity)
        for handle, value in zip(run.bodies, rgb):
            handle.color = tuple(int(v) for v in value)
            handle.opacity = opacity

    def nodes(self) -> list[str]:
        """The names of the scene's nodes (``/run0/bodies/3``, …), sorted."""
        return sorted(self.server.scene._handle_from_node_name)

    # -- serving ---------------------------------------------------------------------------

    def stop(self) -> None:
        """Stop serving (the page shows the connection lost)."""
        if not self._stopping.is_set():
            self._stopping.set()
            self._player.join()  # a frame being drawn is finished first
            self._stop_server()

    def _stop_server(self):
        with _quiet():
            self.server.stop()

    def wait(self) -> int:
        """Serve until Ctrl-C (or SIGTERM), then stop; returns the signal's number
        (``signal.SIGINT`` or ``signal.SIGTERM``): the command line exits 0 after Ctrl-C, the
        way to close the viewer, and 143 after SIGTERM."""
        try:
            while True:
                interrupts.check()
                time.sleep(0.2)
        except KeyboardInterrupt as stopped:
            return getattr(stopped, "signum", signal.SIGINT)
        finally:
            self.stop()

    def _repr_html_(self):  # Jupyter: a link to open it
        address = html.escape(self.url)
        return (
            f"<div>contactlab viewer of {len(self.runs)} run{'s' if len(self.runs) != 1 else ''}: "
            f"<a href='{address}' target='_blank'>{address}</a> (<code>.stop()</code> ends it)</div>"
        )

    def __repr__(self):
        return f"Viewer({self.url}, {len(self.runs)} run{'s' if len(self.runs) != 1 else ''}; .stop() ends it)"


def view(*sources: str | os.PathLike[str] | Run, port: int | None = None, field: str = "RUN_DIR") -> Viewer:
    """Open the viewer on ``sources`` (run folders, compare folders, Runs); returns the
    :class:`Viewer`, serving in the background at ``viewer.url`` until ``viewer.stop()``.
    port: a free one when None; InputError when it is in use or a folder is not a run."""
    return Viewer(open_runs(sources, field), port)
