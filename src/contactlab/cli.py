"""The command line: parses, calls the library, prints. See docs/cli.md.

contactlab                 run the default scene (same as ``contactlab demo``)
contactlab scenes          list the built-in scenes
contactlab run SCENE ...   run a built-in scene or a .toml file
contactlab compile [SCENE] every kind of run of these scenes (default: every built-in) compiled up front
contactlab compare SCENE   run it with every method; report.html, report.md, comparison.csv
contactlab render OUT_DIR  video.mp4, video.gif and still.png of a run's trajectory
contactlab export OUT_DIR  the run as USD, or as an OBJ or PLY sequence
contactlab view RUN_DIR... the runs in an interactive 3-D viewer in the web browser
contactlab sweep STUDY     every cell of a study on a Dask cluster; results.parquet, report.html
contactlab validate SCENE MEASURED.h5...  every method against measured motion; validation.csv, report.md
contactlab fit SCENE MEASURED.h5... --vary PATH=LO:HI  each method's settings fitted to it on Dask; fit.json
contactlab fclib bench DIR every FCLIB problem of a folder with every solver; a table, profiles
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import signal
import sys
import warnings
from collections.abc import Sequence

from . import interrupts
from .errors import InputError, SimulationDiverged, shorten
from .interrupts import EXIT_CODES, Interrupted, handled, tracking_written, written_paths

DEFAULT_SCENE = "bouncing_ball"


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, exit code 2, no usage dump; long values cut
        self.exit(2, f"error: {shorten(message)} (see '{self.prog} --help')\n")


def _parser():
    parser = _Parser(
        prog="contactlab",
        description="Contact resolution: penalty, projection, impulses, constraints on the same scenes.",
    )
    from . import __version__

    parser.add_argument("--version", action="version", version=f"contactlab {__version__}")
    commands = parser.add_subparsers(dest="command", parser_class=_Parser)
    commands.add_parser("demo", help="run the default scene and say where its outputs are")
    commands.add_parser("scenes", help="list the built-in scenes")
    compiling = commands.add_parser(
        "compile", help="compile every kind of run of these scenes up front, in parallel (default: every built-in)"
    )
    compiling.add_argument("scenes", nargs="*", metavar="SCENE", help="built-in scene names or .toml files")
    compiling.add_argument("--methods", help="comma-separated methods (default: all four)")
    compiling.add_argument("--workers", type=int, help="processes compiling at once (default: one a core)")
    run = commands.add_parser("run", help="run a built-in scene or a scene file")
    _scene_arguments(run)
    run.add_argument("--method", help="penalty | projection | impulse | constraints (default: the scene's)")
    run.add_argument("--integrator", help="symplectic_euler | explicit_euler | backward_euler (default: the scene's)")
    run.add_argument("--out", help="output folder (default: out/<scene>-<method>/)")
    run.add_argument("--record-every", type=int, default=1, metavar="K", help="record every K steps (default 1)")
    run.add_argument("--json", action="store_true", help="print the summary as one JSON object on stdout")
    run.add_argument("--video", action="store_true", help="also write video.mp4, video.gif and still.png")
    run.add_argument("--fps", type=int, default=30, help="frames per second of the video (default 30)")
    run.add_argument(
        "--export", default="", metavar="FORMATS", help="also export the run: a comma-separated list of usd, obj, ply"
    )
    run.add_argument("--no-plots", action="store_true", help="do not write plots/ (energy, penetration, ...)")
    run.add_argument(
        "--view",
        action="store_true",
        help="open the run in the interactive viewer afterwards (served on 127.0.0.1 until Ctrl-C)",
    )
    run.add_argument("--port", type=int, help="the viewer's port with --view (default: a free one)")
    run.add_argument(
        "--memory-limit",
        metavar="GB",
        help="the most memory the run may need by its estimate (default: half this machine's; 'none': no limit)",
    )
    run.add_argument(
        "--yes",
        action="store_true",
        help="run even a run of more than 500,000 steps (a duration or dt in the wrong unit?)",
    )
    run.add_argument(
        "--allow-divergence",
        action="store_true",
        help="go on when a health check fails (energy from nowhere, a speed beyond the scene's "
        "scale, a contact deep enough to pass through), noting it in the summary",
    )

    compare = commands.add_parser("compare", help="run a scene with several methods and write a side-by-side report")
    _scene_arguments(compare)
    compare.add_argument("--methods", help="comma-separated methods (default: every method that supports the scene)")
    compare.add_argument(
        "--peers",
        help="also run the scene in these engines, comma-separated: mujoco, pybullet (pip install 'contactlab[peers]')",
    )
    compare.add_argument("--out", help="output folder (default: out/<scene>-compare/)")
    compare.add_argument("--no-video", action="store_true", help="skip the videos (faster)")
    compare.add_argument("--fps", type=int, default=30, help="frames per second of the videos (default 30)")
    compare.add_argument("--allow-divergence", action="store_true", help="as for run: go on past failed health checks")
    _cluster_arguments(
        compare,
        "one per idle core when there are videos or long runs, else the runs one after another; 1: one after another",
    )

    render = commands.add_parser("render", help="draw a run's trajectory: video.mp4, video.gif, still.png")
    render.add_argument("directory", metavar="OUT_DIR", help="a run's output folder (holding trajectory.h5)")
    render.add_argument("--fps", type=int, default=30, help="frames per second (default 30)")
    render.add_argument("--width", type=int, default=640, help="picture width in pixels (default 640)")
    render.add_argument("--height", type=int, default=480, help="picture height in pixels (default 480)")
    render.add_argument("--elevation", type=float, default=25.0, help="camera elevation in degrees (default 25)")
    render.add_argument("--azimuth", type=float, default=-60.0, help="camera azimuth in degrees (default -60)")

    sweep = commands.add_parser("sweep", help="run every cell of a study file on a Dask cluster; a table and a report")
    sweep.add_argument("study", metavar="STUDY", help="a study file (.toml): scenes, methods, axes (docs/sweep.md)")
    sweep.add_argument("--out", help="output folder (default: out/<study>-sweep/)")
    _cluster_arguments(sweep)

    validate = commands.add_parser("validate", help="run every method from measured motion and say how far each drifts")
    _measured_arguments(validate)
    validate.add_argument(
        "--peers",
        help="also start these engines from each measurement, comma-separated: mujoco, pybullet "
        "(pip install 'contactlab[peers]')",
    )
    validate.add_argument("--out", help="output folder (default: out/<scene>-validate/)")
    validate.add_argument("--json", action="store_true", help="print the rows and medians as one JSON object")

    fit = commands.add_parser("fit", help="fit each method's settings to measured motion on a Dask cluster")
    _measured_arguments(fit)
    fit.add_argument(
        "--vary",
        action="append",
        default=[],
        metavar="PATH=LO:HI",
        help="a setting to fit within a range, by its --set path, e.g. materials.0.friction=0.05:0.6 (repeatable)",
    )
    fit.add_argument("--holdout", type=float, default=0.25, help="fraction of the files held out (default 0.25)")
    fit.add_argument(
        "--evaluations", type=int, help="points each method's fit evaluates at most (default 10 + 15 a setting)"
    )
    fit.add_argument("--out", help="output folder (default: out/<scene>-fit/)")
    _cluster_arguments(fit)

    fclib = commands.add_parser("fclib", help="FCLIB frictional-contact problems")
    fclib_commands = fclib.add_subparsers(dest="fclib_command", parser_class=_Parser, required=True)
    bench = fclib_commands.add_parser(
        "bench",
        help="solve every problem of a folder with every solver on a Dask cluster; a table and performance profiles",
    )
    bench.add_argument("directory", metavar="DIR", help="a folder of FCLIB .hdf5 / Siconos .dat problems")
    bench.add_argument("--solvers", help="comma-separated: nsgs, staggered, apgd, newton (default: all)")
    bench.add_argument("--out", help="output folder (default: out/fclib-bench/)")
    bench.add_argument("--tol", type=float, default=1e-8, help="tolerance on the natural-map error (default 1e-8)")
    bench.add_argument("--repeats", type=int, default=3, help="timed solves per problem and solver (default 3)")
    _cluster_arguments(bench)

    view = commands.add_parser("view", help="look around runs in an interactive 3-D viewer in the web browser")
    view.add_argument(
        "directories",
        nargs="+",
        metavar="RUN_DIR",
        help="a run's output folder, or a compare folder (all its methods side by side)",
    )
    view.add_argument("--port", type=int, help="port on 127.0.0.1 to serve on (default: a free one)")

    export = commands.add_parser("export", help="export a run for Blender, Houdini or usdview")
    export.add_argument("directory", metavar="OUT_DIR", help="a run's output folder (holding trajectory.h5)")
    export.add_argument("--format", default="usd", help="usd, obj or ply, or a comma-separated list (default usd)")
    export.add_argument("--every", type=int, default=1, metavar="K", help="export every K-th sample (default 1)")
    return parser


def _cluster_arguments(command, workers="one per idle core"):
    command.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="a running Dask scheduler, e.g. tcp://10.0.0.5:8786 (default: a local cluster)",
    )
    command.add_argument(
        "--workers", type=int, metavar="N", help=f"worker processes of the local cluster (default: {workers})"
    )


def _measured_arguments(command):
    """SCENE MEASURED.h5... --methods --set: what validate and fit share."""
    command.add_argument("scene", help="a built-in scene name or a path to a .toml file")
    command.add_argument("measured", nargs="+", metavar="MEASURED.h5", help="measured-motion files (docs/validate.md)")
    command.add_argument("--methods", help="comma-separated methods (default: all four)")
    _set_argument(command, "materials.0.friction=0.3")


def _set_argument(command, example):
    """--set KEY=VALUE, repeatable: a scene field overridden by its dotted path (``example``)."""
    command.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help=f"override any scene field by dotted path, e.g. {example}",
    )


def _scene_arguments(command):
    command.add_argument("scene", help="a built-in scene name (see 'contactlab scenes') or a path to a .toml file")
    command.add_argument("--dt", help="time step in seconds (default: the scene's)")
    command.add_argument("--duration", help="simulated time in seconds (default: the scene's)")
    _set_argument(command, "bodies.0.velocity=[3,0,0]")
    command.add_argument(
        "--threads",
        default="auto",
        metavar="N",
        help="threads of the compiled sweeps: a number, or auto (default: all cores, or one "
        "while that is faster on a busy machine); results are the same on any count",
    )


def _on_cluster(args):
    """The keywords of a batch the command line starts (compare, sweep, fit, fclib): the Dask
    scheduler and workers its options name, with a progress bar."""
    return dict(scheduler=args.scheduler, workers=args.workers, progress=True)


def _to_stderr(line):
    """A log line of a long command, on stderr (stdout keeps the results)."""
    print(line, file=sys.stderr)


def _scene_overrides(args):
    """The --set list plus the shorthands (--method, --dt, ...) as simulation.* overrides."""
    overrides = list(args.overrides)
    for option in ("method", "dt", "duration", "integrator"):
        if getattr(args, option, None) is not None:
            overrides.append(f"simulation.{option}={getattr(args, option)}")
    return overrides


EXPORT_FORMATS = ("usd", "obj", "ply")


def _list_option(text, option, allowed):
    """'a,b' → ['a', 'b'], each checked against ``allowed``."""
    names = [name.strip() for name in text.split(",") if name.strip()]
    for name in names:
        if name not in allowed:
            raise InputError(option, f"expected a comma-separated list of {', '.join(allowed)}, found {name!r}")
    return names


def _memory_limit(text):
    """--memory-limit GB as bytes (None: the default; "none": no limit)."""
    if text is None:
        return None
    if text.strip().lower() == "none":
        return float("inf")
    try:
        gigabytes = float(text)
    except ValueError:
        gigabytes = float("nan")
    if not gigabytes > 0 or gigabytes == float("inf"):
        raise InputError("--memory-limit", f"expected a number of GB > 0 or 'none', found {text!r}")
    return gigabytes * 2**30


def _run(args, restart=False):
    """``contactlab run`` with its parsed arguments ``args`` (``demo`` is ``run`` of the default
    scene with every default): the scene run, its files written, its summary printed; returns
    the Run. ``restart``: this is the program's own process, which may start again compiled or as
    Python (``first_run.settle``)."""
    from .closed_form import checks
    from .first_run import settle
    from .folder_lock import held
    from .plausibility import MANY_STEPS
    from .record import TRAJECTORY, make_folders, write_summary
    from .scene import load_scene
    from .validation import run_length, whole_number

    whole_number(args.record_every, "--record-every", 1)
    whole_number(args.fps, "--fps", 1)
    overrides = _scene_overrides(args)
    exports = _list_option(args.export, "--export", EXPORT_FORMATS)
    memory_limit = _memory_limit(args.memory_limit)
    if args.video:  # a bad --fps fails before the run, not after it
        from .render import check_settings

        check_settings(args.fps)
    if args.view:  # and so does a bad or busy --port
        from .viewer import check_port

        check_port(args.port)
    scene = load_scene(args.scene, overrides)
    steps = run_length(scene.dt, scene.duration)[2]
    if steps > MANY_STEPS and not args.yes:
        raise InputError(
            "--yes",
            f"the run would make {steps:,} steps (duration {scene.duration:g} s at dt = "
            f"{scene.dt:g} s): times are in seconds; add --yes to run it",
        )
    settle(scene, steps, restart)  # compiled, or as Python where compiling costs more than the run
    out = args.out or os.path.join("out", f"{scene.name}-{scene.method}")
    trajectory = os.path.join(out, TRAJECTORY)
    made = make_folders(out)
    with held(out, "--out", made):  # one run at a time writes a folder; one left empty is removed
        try:  # the samples stream into trajectory.h5 as the run goes
            result = scene.simulate(
                record_every=args.record_every,
                progress=True,
                allow_divergence=args.allow_divergence,
                memory_limit=memory_limit,
                trajectory=trajectory,
            )
        except (SimulationDiverged, KeyboardInterrupt) as error:  # the run up to then is kept, its summary marked
            if getattr(error, "run", None) is not None:
                error.run.summary.update(trajectory=trajectory, source=scene.origin(overrides))
                write_summary(out, error.run.summary)
                error.written = out
            raise
        result.summary["trajectory"] = trajectory
        found = checks(scene.name, scene.model, result.arrays)  # the scene's stated expectations
        result.summary["checks"] = [check.as_record() for check in found]
        result.summary["source"] = scene.origin(overrides)  # how to load the scene again (the viewer's contacts)
        write_summary(out, result.summary)
        written = _extras(
            result.arrays, out, f"{scene.name} — {scene.method}", not args.no_plots, args.video, args.fps, exports
        )
    if args.json:
        print(json.dumps(result.summary))
    else:
        print(_plain_summary(result.summary, scene, written, found))
    if args.view:  # with --json, standard output holds the JSON alone
        _view([out], args.port, sys.stderr if args.json else sys.stdout)
    return result


def _extras(arrays, out, title, plots=False, video=False, fps=30, exports=(), every=1):
    """Plots, video and exports of a run written into ``out``; returns the paths written."""
    written = []
    if plots:
        from .plots import write_plots

        written += list(write_plots(arrays, os.path.join(out, "plots"), title=title).values())
    if video:
        from .render import render

        written += list(render(arrays, out, fps=fps, title=title, progress=True).values())
    if "usd" in exports:
        from .export import write_usd

        written.append(write_usd(arrays, os.path.join(out, "run.usd"), every=every))
    for file_format in ("obj", "ply"):
        if file_format in exports:
            from .export import write_mesh_sequence

            frames = write_mesh_sequence(arrays, os.path.join(out, "frames"), file_format=file_format, every=every)
            written.append(os.path.join(out, "frames", f"frame_*.{file_format} ({len(frames)} files)"))
    return written


def _view(sources, port=None, stream=None):
    """Serve the viewer of ``sources`` (run or compare folders) until Ctrl-C, its address
    printed on ``stream`` (standard output unless given)."""
    from .viewer import view

    viewer = view(*sources, port=port)
    print(f"Viewer: {viewer.url} (open it in a web browser; Ctrl-C stops it)", file=stream or sys.stdout, flush=True)
    if viewer.wait() == signal.SIGTERM:  # Ctrl-C is how a viewer is closed (exit 0); SIGTERM is a stop (143)
        raise Interrupted(signal.SIGTERM)


def _compile(args):
    from .methods import method_names
    from .precompile import compile_kinds
    from .scene import builtin_scenes
    from .validation import whole_number

    if args.workers is not None:
        whole_number(args.workers, "--workers", 1)
    methods = method_names(args.methods)  # None: all four; "" names none: refused
    scenes = args.scenes or [name for name, _ in builtin_scenes()]
    done = compile_kinds(scenes, methods, args.workers, progress=True)
    print(
        f"Compiled {len(done.compiled)} kinds of run in {done.seconds:.0f} s; {len(done.already)} were compiled "
        f"already; {len(done.refused)} runs a method refuses (left out)."
    )


def _compare(args):
    from .compare import compare
    from .methods import method_names
    from .validation import whole_number

    methods = method_names(args.methods) if args.methods is not None else None  # "" names none: refused
    whole_number(args.fps, "--fps", 1)
    comparison = compare(
        args.scene,
        methods,
        args.out,
        overrides=_scene_overrides(args),
        video=not args.no_video,
        fps=args.fps,
        allow_divergence=args.allow_divergence,
        peers=args.peers,
        **_on_cluster(args),
    )
    print(comparison.summary_text)
    print(
        f"Report: {comparison.report_html} (also {os.path.basename(comparison.report_md)} and "
        f"{os.path.basename(comparison.csv)} beside it)"
    )


def _sweep(args):
    from . import sweep
    from .study import load_study

    study = load_study(args.study, log=_to_stderr)
    out = args.out or os.path.join("out", f"{study.name}-sweep")
    table = sweep.run(study, out, log=_to_stderr, **_on_cluster(args))
    counts = ", ".join(f"{count} {status}" for status, count in table["status"].value_counts().items())
    print(f"{study.name}: {len(table)} cells ({counts}).")
    print(
        f"Table: {os.path.join(out, 'results.parquet')} (and results.csv); report: {os.path.join(out, 'report.html')}"
    )


def _validate(args):
    from .prediction import validate
    from .prediction_report import table_text

    result = validate(args.scene, args.measured, args.methods, args.out, overrides=args.overrides, peers=args.peers)
    if args.json:
        print(json.dumps(result.as_json()))
    else:
        print(table_text(result.rows))
        medians = ", ".join(_median_text(method, values) for method, values in result.medians.items())
        print(f"Median position error: {medians}" + (f"; best: {result.best}." if result.best else "."))
        print(f"Table: {result.csv}; report: {result.report}")
    if result.best is None:  # a table of failures: no error measured (exit 3, as a run that went wrong)
        raise SimulationDiverged(f"no run of any method completed (each row of {result.csv} says why)")


def _median_text(method, values):
    """'impulse 3.2 %', or, where none of the method's runs completed, 'impulse none completed'."""
    median = values["position_error_pct"]
    return f"{method} {median:.3g} %" if median == median else f"{method} none completed"


def _fit(args):
    from .fitting import fit

    result = fit(
        args.scene,
        args.measured,
        args.vary,
        args.methods,
        args.holdout,
        args.out,
        overrides=args.overrides,
        evaluations=args.evaluations,
        log=_to_stderr,
        **_on_cluster(args),
    )
    for method, entry in result.methods.items():
        values = ", ".join(f"{path} = {value:.4g}" for path, value in entry["values"].items())
        held = f", held out {entry['holdout_error']:.3g} %" if entry["holdout_error"] is not None else ""
        print(f"{method}: {values} (training error {entry['train_error']:.3g} %{held})")
    print(f"Fit: {result.json}; plots in {os.path.join(result.out, 'plots')}")


def _where_time_went(summary):
    """Where the run's wall time went: compiling kernels or loading them from the cache, and
    recording (each when it took a tenth of a second or more), and the stepping's speed."""
    parts = []
    if summary["compile_seconds"] >= 0.1:
        parts.append(f"{summary['compile_seconds']:.2f} s compiling or loading kernels")
    if summary["recording_seconds"] >= 0.1:
        parts.append(f"{summary['recording_seconds']:.2f} s recording")
    python = " as Python" if summary.get("kernels") == "python" else ""
    parts.append(f"{summary['steps_per_second']:.0f} steps/s stepping{python}")
    return ", ".join(parts)


def _plain_summary(summary, scene, written=(), found=()):
    energy = summary["energy"]
    return (
        f"{summary['scene']} ({scene.model.describe()}) with {summary['method']}: "
        f"{summary['steps']} steps of {summary['dt']:g} s in {summary['wall_seconds']:.2f} s "
        f"({_where_time_went(summary)}); "
        f"at most {summary['max_contacts']} contact{'' if summary['max_contacts'] == 1 else 's'} at once, "
        f"deepest penetration {summary['max_penetration'] * 1000:.3g} mm; total energy "
        f"{energy['initial']:.4g} J at the start, {energy['final']:.4g} J at the end."
        + (
            f" The contact springs were too stiff for {summary['integrator']} at this dt in "
            f"{summary['implicit_spring_steps']} steps: those stepped them by backward Euler."
            if summary.get("implicit_spring_steps")
            else ""
        )
        + "\n"
        + "".join(f"Expectation: {check.verdict()}\n" for check in found)
        + f"Outputs: {summary['trajectory']} and {os.path.join(os.path.dirname(summary['trajectory']), 'summary.json')}"
        + "".join(f", {path}" for path in written)
    )


def _print_warning(message, category, filename, lineno, file=None, line=None):
    """Warnings (e.g. a penalty stiffness too high for the time step) as one line, no source."""
    print(f"warning: {message}", file=sys.stderr)


def main(argv: Sequence[str] | None = None) -> int:
    """The command (``argv`` None: the program's own arguments, as the ``contactlab`` command and
    ``python -m contactlab`` call it; then a signal after the work is done, while the
    interpreter shuts down, is ignored: there is nothing left to stop)."""
    with handled(restore=argv is not None), tracking_written():
        try:  # signals take effect between steps, files and frames (interrupts.check), never inside a
            with interrupts.deferred():  # library call: Numba compiling, matplotlib drawing
                code = _main(argv)
                if argv is None:  # exiting: from here on a signal has nothing to stop
                    interrupts.ignore_signals()
        except Interrupted:  # it came after the last step, file and frame: the command had finished
            pass
        return code


def _main(argv):
    args = _parser().parse_args(argv)
    warnings.showwarning = _print_warning
    from .compiling import one_notice

    with one_notice():  # "compiling contact kernels…" once, however many runs and workers compile
        return _command(args, argv)


def _command(args, argv):
    """Run the command ``args`` (parsed from ``argv``); its exit code."""
    try:
        if hasattr(args, "threads"):
            from .threads import set_threads

            set_threads(args.threads, "--threads")
        if args.command in (None, "demo"):
            _run(_parser().parse_args(["run", DEFAULT_SCENE]), restart=argv is None)
        elif args.command == "scenes":
            from .scene import builtin_scenes

            for name, description in builtin_scenes():
                print(f"{name:20s} {description}")
        elif args.command == "run":
            _run(args, restart=argv is None)
        elif args.command == "compile":
            _compile(args)
        elif args.command == "compare":
            _compare(args)
        elif args.command == "sweep":
            _sweep(args)
        elif args.command == "validate":
            _validate(args)
        elif args.command == "fit":
            _fit(args)
        elif args.command == "fclib":
            from .fclib_bench import bench

            cluster = _on_cluster(args)
            result = bench(args.directory, args.solvers, args.out, tol=args.tol, repeats=args.repeats, **cluster)
            solved = result.table.groupby("solver", sort=False)["converged"].sum()
            problems = result.table["problem"].nunique()
            print(
                f"{problems} problems: "
                + ", ".join(f"{solver} solved {int(count)}" for solver, count in solved.items())
            )
            print(f"Table: {result.csv} (and {result.markdown.name}); performance profile: {result.profile_png}")
        elif args.command == "render":
            from .record import load_run

            arrays, summary = load_run(args.directory)
            from .render import render

            title = f"{summary['scene']} — {summary['method']}" if "scene" in summary else None
            paths = render(
                arrays,
                args.directory,
                fps=args.fps,
                width=args.width,
                height=args.height,
                elevation=args.elevation,
                azimuth=args.azimuth,
                title=title,
                progress=True,
            )
            print("Wrote " + ", ".join(paths.values()))
        elif args.command == "view":
            _view(args.directories, args.port)
        elif args.command == "export":
            formats = _list_option(args.format, "--format", EXPORT_FORMATS)
            from .validation import whole_number

            whole_number(args.every, "--every", 1)
            from .record import load_run

            arrays, _ = load_run(args.directory)
            print("Wrote " + ", ".join(_extras(arrays, args.directory, None, exports=formats, every=args.every)))
    except InputError as error:
        source = (
            getattr(args, "scene", None)
            or getattr(args, "directory", None)
            or getattr(args, "study", None)
            or DEFAULT_SCENE
        )
        if args.command == "view" or error.field == "--port":  # the message names the folder or port itself
            print(f"error: {error}", file=sys.stderr)
        else:
            print(f"error: {shorten(str(source))}: {error}", file=sys.stderr)
        return 2
    except SimulationDiverged as error:
        written = getattr(error, "written", None)
        kept = f" (the run up to then is in {written})" if written else ""
        print(f"error: {error}{kept}", file=sys.stderr)
        return 3
    except OSError as error:
        where = f" ({error.filename})" if error.filename else ""  # the file, where the error names it
        print(f"error: cannot write the outputs: {error.strerror or error}{where}", file=sys.stderr)
        return 1
    except KeyboardInterrupt as error:
        signum = error.signum if isinstance(error, Interrupted) else signal.SIGINT
        print(f"interrupted ({signal.Signals(signum).name}); {_written_text()}", file=sys.stderr)
        if argv is None:  # the process ends now: its objects (after a sweep, millions) are left out
            gc.freeze()  # of the interpreter's last collections, most of a second; every file is closed
        return EXIT_CODES.get(signum, 130)
    return 0


def _written_text():
    """What an interrupted command had written completely (interrupts.written_paths), as a clause."""
    paths = written_paths()
    return "written before it: " + ", ".join(paths) if paths else "no output written"


if __name__ == "__main__":
    sys.exit(main())
