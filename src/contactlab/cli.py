"""The command line: parses, calls the library, prints. See docs/cli.md.

    contactlab                 run the default scene (same as ``contactlab demo``)
    contactlab scenes          list the built-in scenes
    contactlab run SCENE ...   run a built-in scene or a .toml file
"""

import argparse
import json
import os
import sys
import warnings

from .errors import InputError, SimulationDiverged

DEFAULT_SCENE = "bouncing_ball"


class _Parser(argparse.ArgumentParser):
    def error(self, message):           # one line, exit code 2, no usage dump
        self.exit(2, f"error: {message} (see '{self.prog} --help')\n")


def _parser():
    parser = _Parser(prog="contactlab", description="Contact resolution: penalty, projection, impulses, "
                                                    "constraints on the same scenes.")
    commands = parser.add_subparsers(dest="command", parser_class=_Parser)
    commands.add_parser("demo", help="run the default scene and say where its outputs are")
    commands.add_parser("scenes", help="list the built-in scenes")
    run = commands.add_parser("run", help="run a built-in scene or a scene file")
    run.add_argument("scene", help="a built-in scene name (see 'contactlab scenes') or a path to a .toml file")
    run.add_argument("--method", help="penalty | projection | impulse | constraints (default: the scene's)")
    run.add_argument("--dt", help="time step in seconds (default: the scene's)")
    run.add_argument("--duration", help="simulated time in seconds (default: the scene's)")
    run.add_argument("--integrator", help="symplectic_euler | explicit_euler | backward_euler (default: the scene's)")
    run.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                     help="override any scene field by dotted path, e.g. bodies.0.velocity=[3,0,0]")
    run.add_argument("--out", help="output folder (default: out/<scene>-<method>/)")
    run.add_argument("--record-every", type=int, default=1, metavar="K", help="record every K steps (default 1)")
    run.add_argument("--json", action="store_true", help="print the summary as one JSON object on stdout")
    return parser


def _run(scene_source, overrides=(), out=None, record_every=1, as_json=False):
    from .record import write_outputs
    from .scene import load_scene
    from .simulation import simulate

    scene = load_scene(scene_source, overrides)
    options = scene.method_options.get(scene.method, {})
    result = simulate(scene.model, scene.method, scene.dt, scene.duration, options, scene.integrator,
                      record_every, progress=sys.stderr.isatty(), scene_name=scene.name)
    out = out or os.path.join("out", f"{scene.name}-{scene.method}")
    result.summary["trajectory"] = os.path.join(out, "trajectory.npz")
    write_outputs(out, result.arrays, result.summary)
    if as_json:
        print(json.dumps(result.summary))
    else:
        print(_plain_summary(result.summary, scene))
    return result


def _plain_summary(summary, scene):
    energy = summary["energy"]
    return (f"{summary['scene']} ({scene.model.describe()}) with {summary['method']}: "
            f"{summary['steps']} steps of {summary['dt']:g} s in {summary['wall_seconds']:.2f} s "
            f"({summary['steps_per_second']:.0f} steps/s after a first step of {summary['first_step_seconds']:.2f} s); "
            f"at most {summary['max_contacts']} contact{'' if summary['max_contacts'] == 1 else 's'} at once, "
            f"deepest penetration {summary['max_penetration'] * 1000:.3g} mm; total energy "
            f"{energy['initial']:.4g} J at the start, {energy['final']:.4g} J at the end.\n"
            f"Outputs: {summary['trajectory']} and {os.path.join(os.path.dirname(summary['trajectory']), 'summary.json')}")


def _print_warning(message, category, filename, lineno, file=None, line=None):
    """Warnings (e.g. a penalty stiffness too high for the time step) as one line, no source."""
    print(f"warning: {message}", file=sys.stderr)


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    warnings.showwarning = _print_warning
    try:
        if args.command in (None, "demo"):
            _run(DEFAULT_SCENE)
        elif args.command == "scenes":
            from .scene import builtin_scenes
            for name, description in builtin_scenes():
                print(f"{name:20s} {description}")
        else:
            if args.record_every < 1:
                raise InputError("--record-every", f"expected a whole number ≥ 1, found {args.record_every}")
            overrides = list(args.overrides)
            for option, key in (("method", "method"), ("dt", "dt"), ("duration", "duration"),
                                ("integrator", "integrator")):
                if getattr(args, option) is not None:
                    overrides.append(f"simulation.{key}={getattr(args, option)}")
            _run(args.scene, overrides, args.out, args.record_every, args.json)
    except InputError as error:
        source = getattr(args, "scene", None) or DEFAULT_SCENE
        print(f"error: {source}: {error}", file=sys.stderr)
        return 2
    except SimulationDiverged as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    except OSError as error:
        print(f"error: cannot write the outputs: {error.strerror or error} ({error.filename})", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("interrupted; no output written", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
