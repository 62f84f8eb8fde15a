"""Choosing and running the methods on one scene, and :func:`compare`, which runs them and
writes what contactlab.compare.measures measures of them and contactlab.compare.report says.

The scene is loaded for every method before anything is written, so a bad scene stops the
comparison with an InputError and no output. Each run streams its trajectory to disk as it goes
(contactlab.store), and its video is drawn from it; the runs go one after another, or, where it
pays, to a Dask cluster through contactlab.cluster, the path of contactlab.sweep
(:func:`run_method` is one job). A method that blows up (SimulationDiverged) is reported as
such, its trajectory up to then kept, and the others go on. Every file is written atomically,
and if the comparison fails (other than a method's own divergence) the files and folders it
created are removed again.
"""

from __future__ import annotations

import contextlib
import os
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from .. import cluster, compiling, interrupts, kernel_variants
from .. import peers as peers_package
from ..closed_form import Check
from ..errors import InputError, SimulationDiverged
from ..folder_lock import held
from ..methods import method_names
from ..plots import write_comparison_plots, write_plots
from ..record import (
    TRAJECTORY,
    atomic_path,
    make_folders,
    remove_empty,
    replaced,
    stamps,
    undo_written,
    write_summary,
)
from ..scene import Scene, load_scene
from ..simulation import Run
from ..store import open_trajectory
from . import report
from .measures import fill_rows

PARALLEL_WORK = 200_000  # steps × (bodies + particles) of all runs from which they go to a local cluster


@dataclass
class Comparison:
    """What :func:`compare` produced.

    rows: one dict per method, keys as the header of comparison.csv (units in the names, see
    docs/compare.md; None where a value is missing, "n/a" where it does not apply);
    out: the output folder; report_html, report_md, csv: paths of the three reports;
    summary_text: the plain-words paragraph of the report; skipped: methods left out because
    they do not support the scene (name → why); checks: method → its closed-form checks
    (contactlab.closed_form.Check); files: method → {name: path} of what it wrote.
    """

    rows: list[dict[str, Any]]
    out: str
    report_html: str
    report_md: str
    csv: str
    summary_text: str
    scene: str = ""
    skipped: dict[str, str] = field(default_factory=dict)
    checks: dict[str, list[Check]] = field(default_factory=dict)
    files: dict[str, dict[str, str]] = field(default_factory=dict)

    def _repr_html_(self):  # Jupyter (contactlab.notebook): the table and the report's link
        from ..notebook import comparison_html

        return comparison_html(self)


@dataclass
class Outcome:
    """One method's run: ``run`` (contactlab.simulation.Run) or ``failure`` (the divergence message),
    set here; measures.fill_rows gives it its ``row`` and ``checks``, and report reads it."""

    method: str
    scene: Scene
    run: Run | None = None
    failure: str | None = None
    failed_run: Run | None = None
    """the Run up to the blow-up (its trajectory streamed to disk)"""
    failed_at: float | None = None
    """s, simulated time of the blow-up when the message says it"""
    warnings: list = field(default_factory=list)
    media: dict = field(default_factory=dict)
    """the video, GIF and still drawn of it"""
    checks: list = field(default_factory=list)
    files: dict = field(default_factory=dict)
    row: dict = field(default_factory=dict)
    gap: str | None = None
    """a peer that was not run: the sentence saying what of the scene it cannot express and why"""
    notes: list = field(default_factory=list)
    """a peer's: its engine and settings, and how the scene's materials were mapped to it"""
    integrator: str | None = None
    """a peer's integrator (a method's is its scene's)"""


# ---- choosing and running the methods ----------------------------------------------------------


def _method_names(methods):
    """(names, named): the methods to compare, and whether the caller named them."""
    return method_names(methods), methods is not None


def supports(method: str, scene: Scene) -> bool:
    """Whether ``method`` is meant to run ``scene``: every method supports every scene today.
    The hook for a method that cannot (besides this, a method whose set-up rejects the scene
    with an InputError is left out when the methods were not named)."""
    return True


def run_method(job: Mapping[str, Any]) -> dict[str, Any]:
    """One method's run, here or on a Dask worker: load the scene for the method, simulate it
    streaming its trajectory to ``job["trajectory"]``, and (``job["video"]``: fps) render it
    beside that. A job with a ``peer`` runs the scene in that engine instead (contactlab.peers).
    Returns plain data: ``summary``, ``warnings`` [(category, message)], and
    ``failure``, ``failed_at`` [s] for a run a health check stopped, or ``media`` (name -> path)
    for a rendered one; ``input_error`` [field, message] for a scene the method refuses; ``gap``
    (one sentence) for a scene the peer cannot express."""
    from ..render import render

    result: dict[str, Any] = {"warnings": []}
    peer = job.get("peer")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            scene = load_scene(job["scene"], job["overrides"])
            if peer:
                run = peers_package.simulate(
                    scene.model,
                    peer,
                    scene.dt,
                    scene.duration,
                    trajectory=job["trajectory"],
                    scene_name=scene.name,
                    progress=job["progress"],
                )
            else:
                run = scene.simulate(
                    progress=job["progress"],
                    allow_divergence=job["allow_divergence"],
                    trajectory=job["trajectory"],
                )
            result["summary"] = run.summary
        except peers_package.Inexpressible as gap:
            return {"gap": gap.sentence, "warnings": []}
        except SimulationDiverged as error:
            result.update(summary=error.run.summary, failure=str(error), failed_at=error.time)  # type: ignore[union-attr]
        except InputError as error:
            return {"input_error": [error.field, error.message], "warnings": []}
    result["summary"]["source"] = scene.origin(job["overrides"])  # how to load the scene again (the viewer)
    result["warnings"] = [(warning.category, str(warning.message)) for warning in caught]
    if job["video"] is not None and "failure" not in result:
        result["media"] = render(
            open_trajectory(job["trajectory"]),
            os.path.dirname(job["trajectory"]),
            fps=job["video"],
            title=f"{scene.name} — {peer or scene.method}",
            progress=job["progress"],
        )
    return result


def _parallel(workers, scheduler, scenes, video) -> bool:
    """Whether the methods' runs go to a Dask cluster (contactlab.cluster): on an existing one
    (``scheduler``) always; on a local one when ``workers`` asks for more than one, or, left to
    choose (None), when the machine has an idle core for a second run and the work is worth
    starting a cluster — videos to draw, or at least PARALLEL_WORK steps × bodies and particles."""
    if scheduler is not None:
        return True
    if workers is not None:
        return workers > 1
    if len(scenes) < 2:
        return False
    work = sum(
        max(1, round(scene.duration / scene.dt)) * (scene.model.body_count + scene.model.particle_count)
        for scene in scenes.values()
    )
    return (video or work >= PARALLEL_WORK) and cluster.default_workers() > 1


def _run_all(
    scene_source, names, named, overrides, out, created, each, where, peer_names=()
) -> tuple[list[Outcome], dict[str, str], str]:
    """Load the scene for every method, then run it with each and in each of ``peer_names``
    (contactlab.peers), streaming each trajectory to out/<method>/trajectory.h5 and rendering it,
    one after another or on a Dask cluster (:func:`_parallel`) ``where`` = (workers, scheduler)
    says; folders and files noted in ``created``. ``each``: what every run's job carries,
    {"video": fps or None, "allow_divergence", "progress"}. Returns (outcomes, skipped {method:
    why}, out)."""
    workers, scheduler = where
    scenes = {name: load_scene(scene_source, [*overrides, f"simulation.method={name}"]) for name in names}
    if peer_names:  # the peers run the scene as its file has it: its method is not theirs
        as_written = load_scene(scene_source, overrides)
        scenes.update({peer: as_written for peer in peer_names})
    out = os.fspath(out) if out is not None else os.path.join("out", f"{next(iter(scenes.values())).name}-compare")
    created.lock(out)  # one compare at a time writes a folder: a second is refused, naming the first
    skipped, jobs = {}, []
    for name, scene in scenes.items():
        if name in peer_names:
            created.folder(os.path.join(out, name))
            peer_job = {
                **scene.origin(overrides),
                "peer": name,
                "trajectory": os.path.abspath(os.path.join(out, name, TRAJECTORY)),
                **each,
            }
            jobs.append((name, peer_job))
            continue
        if not supports(name, scene):
            if named:
                raise InputError("--methods", f"{name} does not support the scene {scene.name}")
            skipped[name] = "not supported"
            continue
        created.folder(os.path.join(out, name))
        jobs.append(
            (
                name,
                {
                    **scene.origin([*overrides, f"simulation.method={name}"]),
                    "trajectory": os.path.abspath(os.path.join(out, name, TRAJECTORY)),
                    **each,
                },
            )
        )
    # a compare of several kinds of run compiles each: its compile notice says their wait together
    pending = kernel_variants.uncompiled(scenes[name] for name, _ in jobs if name not in peer_names)
    if len(pending) > 1:
        compiling.expect(kernel_variants.compiling_notice(len(pending)))
    if _parallel(workers, scheduler, scenes, each["video"] is not None):
        before = stamps(_outputs(jobs))
        try:
            with cluster.connect(scheduler, workers) as client:
                for job in jobs:
                    job[1]["progress"] = False  # the bar is over the methods
                results = dict(cluster.run_tasks(client, run_method, jobs, each["progress"], "methods"))
        except BaseException:  # the workers have stopped: what they completed, as a run here notes it
            for path in replaced(before):
                interrupts.note_written(path)
            raise
    else:
        results = {name: run_method(job) for name, job in jobs}
    outcomes, first_error = [], None
    for name, _ in jobs:
        result = results[name]
        if isinstance(result, BaseException):
            raise result
        for category, message in result["warnings"]:
            warnings.warn(message, category, stacklevel=2)
        if "gap" in result:  # a peer that cannot express the scene: its row says why
            outcomes.append(Outcome(name, scenes[name], gap=result["gap"]))
            remove_empty([os.path.join(out, name)])
            continue
        if "input_error" in result:
            error = InputError(*result["input_error"])
            if named:
                raise error
            skipped[name] = str(error)
            first_error = first_error or error
            remove_empty([os.path.join(out, name)])  # its folder, empty: the method left nothing
            continue
        trajectory = os.path.join(out, name, TRAJECTORY)
        created.add(trajectory, *result.get("media", {}).values())
        run = Run(None, open_trajectory(trajectory), result["summary"])
        outcome = Outcome(
            name, scenes[name], warnings=[message for _, message in result["warnings"]], media=result.get("media", {})
        )
        if name in peer_names:
            outcome.integrator = result["summary"]["integrator"]
            outcome.notes = [peers_package.describe(result["summary"]["options"]), *result["summary"]["engine_notes"]]
        if "failure" in result:
            outcome.failure, outcome.failed_at, outcome.failed_run = result["failure"], result["failed_at"], run
        else:
            outcome.run = run
        outcomes.append(outcome)
    if not outcomes:
        raise first_error or InputError("--methods", "no method supports this scene")
    return outcomes, skipped, out


def _outputs(jobs):
    """The files the jobs write (:func:`run_method`): each trajectory, and the video, GIF and
    still drawn beside it."""
    from ..render import output_paths

    for _, job in jobs:
        yield job["trajectory"]
        if job["video"] is not None:
            yield from output_paths(os.path.dirname(job["trajectory"])).values()


# ---- writing ----------------------------------------------------------------------------------


class _Created:
    """Files and folders one compare() call wrote, so a failure can remove them again, and the
    lock on its output folder while it writes (contactlab.folder_lock: two compares into one
    folder mixed their reports)."""

    def __init__(self):
        self.files, self.folders = [], []
        self.locked = contextlib.ExitStack()

    def lock(self, out):
        """Create the folder ``out`` and hold its lock until :meth:`unlock` (InputError when
        another command holds it)."""
        self.folder(out)
        self.locked.enter_context(held(out, "--out"))

    def unlock(self):
        self.locked.close()

    def folder(self, path):
        self.folders += make_folders(path)

    def add(self, *paths):
        self.files += paths

    def text(self, path, text):
        with atomic_path(path) as temporary:
            with open(temporary, "w", encoding="utf-8", newline="") as stream:
                stream.write(text)
        self.add(path)
        return path

    def remove(self):
        self.unlock()
        undo_written(self.files)  # an interrupted compare says it wrote nothing
        for folder in self.folders:  # what a stopped worker was writing
            for name in os.listdir(folder) if os.path.isdir(folder) else ():
                if name.startswith(".partial-"):
                    os.unlink(os.path.join(folder, name))
        remove_empty(self.folders)


def _video_fps(video, fps):
    """``fps`` checked (contactlab.render: InputError) before any run when ``video``, else None."""
    if not video:
        return None
    from ..render import check_settings

    return check_settings(fps)[0]


def _write_method(outcome, out, created):
    """summary.json and plots of one run into out/<method>, beside the trajectory it streamed
    and the video drawn of it; a run that blew up gets its summary only."""
    directory = os.path.join(out, outcome.method)
    run = outcome.run or outcome.failed_run
    if run is None:
        return
    run.summary["trajectory"] = os.path.join(directory, TRAJECTORY)
    files = {"trajectory": run.summary["trajectory"], "summary": write_summary(directory, run.summary)}
    created.add(files["summary"])
    if outcome.run is not None:
        created.folder(os.path.join(directory, "plots"))
        title = f"{outcome.scene.name} — {outcome.method}"
        plots = write_plots(run.arrays, os.path.join(directory, "plots"), title=title)
        created.add(*plots.values())
        files.update({f"plot {name}": path for name, path in plots.items()})
        files = {**outcome.media, **files}
    outcome.files = files


def _method_files(directory: str) -> list[str]:
    """The files a comparison writes into a method's folder ``directory`` (:func:`_write_method`,
    :func:`run_method`): trajectory.h5 (trajectory.npz of an older contactlab), summary.json,
    the plots, the video, GIF and still."""
    from ..plots import PLOTS
    from ..render import FORMATS, output_paths

    return [
        os.path.join(directory, TRAJECTORY),
        os.path.join(directory, "trajectory.npz"),
        os.path.join(directory, "summary.json"),
        *(os.path.join(directory, "plots", f"{name}.png") for name in PLOTS),
        *output_paths(directory, FORMATS).values(),
    ]


def _remove_earlier_methods(out: str, kept: set[str]) -> list[str]:
    """Remove what an earlier comparison into ``out`` left of the methods (and peers) that this
    one did not run (``kept``: the names whose folders it wrote). A folder counts only where it
    is recognisably a method's run: named after a method or a peer
    (contactlab.methods.AVAILABLE, contactlab.peers.PEERS), holding a trajectory or a
    summary.json. From it go the files a comparison writes there (:func:`_method_files`) and
    those a stopped worker left half-written (``.partial-*``); the folder goes where nothing else
    is left in it, so a file of the user's, and its folder, stay. A file that cannot be removed
    is warned of in one line and left. Returns the folders removed."""
    from ..methods import AVAILABLE
    from ..peers import PEERS

    removed = []
    for name in (*AVAILABLE, *PEERS):
        directory = os.path.join(out, name)
        files = _method_files(directory)
        if name in kept or not any(os.path.isfile(path) for path in files[:3]):
            continue
        try:
            for folder in (directory, os.path.join(directory, "plots")):
                if os.path.isdir(folder):
                    half_written = [entry for entry in os.listdir(folder) if entry.startswith(".partial-")]
                    files += [os.path.join(folder, entry) for entry in half_written]
            for path in files:
                if os.path.isfile(path):
                    os.unlink(path)
        except OSError as error:
            warnings.warn(
                f"the earlier comparison's {directory} is left: cannot remove {error.filename} ({error.strerror})",
                stacklevel=2,
            )
            continue
        remove_empty([directory, os.path.join(directory, "plots")])
        if not os.path.exists(directory):
            removed.append(directory)
    return removed


def compare(
    scene_source: str | os.PathLike[str],
    methods: str | Sequence[str] | None = None,
    out: str | os.PathLike[str] | None = None,
    *,
    overrides: Sequence[str] = (),
    duration: float | None = None,
    video: bool = True,
    progress: bool = False,
    fps: int = 30,
    allow_divergence: bool = False,
    workers: int | None = None,
    scheduler: str | None = None,
    peers: str | Sequence[str] | None = None,
) -> Comparison:
    """Run ``scene_source`` (a built-in name or a .toml path) with each of ``methods`` and write
    the comparison into ``out`` (default ``out/<scene>-compare/``).

    methods: names (a list, or one comma-separated string); None: every method of
    contactlab.methods.AVAILABLE that supports the scene. overrides: "dotted.key=value"
    strings as the command line's --set; duration [s]: overrides simulation.duration;
    video: render each run (contactlab.render) at ``fps`` frames per second; progress:
    progress on stderr (contactlab.progress); allow_divergence: each run's (see ``simulate``);
    workers, scheduler: where the runs go — one after another here, or on a Dask cluster, local
    (``workers`` processes) or at the address ``scheduler`` (contactlab.cluster); None: a local
    cluster when it pays (see docs/compare.md); peers: engines to run the scene in beside the
    methods, "mujoco" and "pybullet" (a list, or one comma-separated string; contactlab.peers,
    docs/peers.md), each with its row, trajectory and files as a method's, or a row saying what
    of the scene it cannot express. Raises InputError for a bad
    scene, an unknown method or bad options, before anything is written. A method that blows up
    (a failed health check) is reported, not raised.
    """
    names, named = _method_names(methods)
    peer_names = peers_package.peer_names(peers)  # a name that is no peer, or one not installed: before anything
    cluster.check_cluster(scheduler, workers)
    overrides = [*overrides] + ([f"simulation.duration={duration}"] if duration is not None else [])
    video = _video_fps(video, fps)  # a missing renderer or a bad fps fails before the runs
    created = _Created()
    try:
        each = {"video": video, "allow_divergence": allow_divergence, "progress": progress}
        outcomes, skipped, out = _run_all(
            scene_source, names, named, overrides, out, created, each, (workers, scheduler), peer_names
        )
        scene = outcomes[0].scene
        fill_rows(outcomes)
        summary_text = report.paragraph(scene, outcomes, skipped)
        for outcome in outcomes:
            _write_method(outcome, out, created)
        ran = {outcome.method: outcome.run.arrays for outcome in outcomes if outcome.run}
        plot_paths = {}
        if ran:
            created.folder(os.path.join(out, "plots"))
            plot_paths = write_comparison_plots(ran, os.path.join(out, "plots"), title=scene.name)
            created.add(*plot_paths.values())
        rows = [outcome.row for outcome in outcomes]
        markdown, html = report.report_texts(
            scene, outcomes, summary_text, report.table_cells(outcomes), plot_paths, out
        )
        comparison = Comparison(  # the three reports are written as the result names them
            rows=rows,
            out=out,
            report_html=created.text(os.path.join(out, "report.html"), html),
            report_md=created.text(os.path.join(out, "report.md"), markdown),
            csv=created.text(os.path.join(out, "comparison.csv"), report.csv_text(rows)),
            summary_text=summary_text,
            scene=scene.name,
            skipped=skipped,
            checks={outcome.method: outcome.checks for outcome in outcomes},
            files={outcome.method: outcome.files for outcome in outcomes},
        )
    except BaseException:
        created.remove()
        raise
    try:  # this comparison's reports are written: the folder is this comparison's alone
        _remove_earlier_methods(out, {outcome.method for outcome in outcomes if outcome.files})
    finally:
        created.unlock()
    return comparison
