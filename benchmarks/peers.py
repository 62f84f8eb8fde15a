"""contactlab against pybullet and MuJoCo on the scenes of issues 8 and 18 (a measurement, not a test).

    python benchmarks/peers.py            # full settings (tens of minutes on 2 cores)
    python benchmarks/peers.py --quick    # smoke run: the same scenes, short durations
    python benchmarks/peers.py --only pile1000 pyramid --report-only ...

Every engine steps the same scene in this one process, with dt = 1/240 s, each at its own
defaults (issue 18): contactlab's methods with their Options as shipped (``constraints``: up to
100 sweeps, stopping at their tolerance), and the peers as ``contactlab compare --peers`` runs
them: each scene is a contactlab Model, and every pybullet and MuJoCo world is built from it
by contactlab.peers (its translation of shapes, masses, inertias, poses, gravity, friction and
restitution; docs/peers.md), so the benchmark and the comparison measure the same world. The
peers' engines run at their defaults (pybullet: maximal coordinates, ``p.DIRECT``, 50
iterations; MuJoCo: Newton, at most 100 iterations, pyramidal cones). A peer that is not
installed is skipped (``pip install -e .[bench]`` installs both and matplotlib). The ``scenes``
item runs built-in scenes (box_pyramid, bouncing_ball, sliding_block, rolling_sphere) at their
own dt and duration, with the measures and closed-form verdicts of ``contactlab compare``.

Measured for each run:

* steps/s — the stepping loop only: contactlab after a separate 3-step run that compiles its
  kernels; every engine's ``summary["steps_per_second"]`` leaves out the run's first step and
  reading the state back for the measures below (a peer's clock runs around its step call
  only, contactlab.peers.run);
* max penetration [m] — spheres: measured the same way for every engine from the sampled
  positions (largest overlap of two spheres or of a sphere and a wall); boxes: the summary's
  ``max_penetration``, contactlab's own collision pass on each engine's sampled poses (the
  peers' rows included); cloth: largest overlap of a vertex (thickness 5 mm) with the sphere or
  the floor;
* drift [m] — the largest displacement of a body that should stay put: every box of the
  pyramid from its start, over the whole run; for the piles, every sphere over the last
  0.5 s (when the pile should be at rest).

Threads are pinned before NumPy loads: OPENBLAS/OMP/MKL/VECLIB/NUMEXPR_NUM_THREADS = 1 (the
peers are single-threaded), and NUMBA_NUM_THREADS = ``--numba-threads`` (default: 2, the cores
of the benchmark machine, which the issue's parallel Gauss-Seidel target is about).

Results go to ``benchmarks/results/results.json`` (merged run by run, so a partial run keeps
what it measured), ``benchmarks/results.md`` and the PNG plots in ``benchmarks/results/``.
"""

import argparse
import os
import sys

from pinning import pin_threads  # the script's own folder is on sys.path

pin_threads(sys.argv)

import contextlib  # noqa: E402  (after the thread pinning)
import json  # noqa: E402
import multiprocessing  # noqa: E402
import platform  # noqa: E402
import resource  # noqa: E402
import subprocess  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from datetime import date  # noqa: E402

import numpy as np  # noqa: E402
from scipy.spatial import cKDTree  # noqa: E402

import contactlab  # noqa: E402
from contactlab import ModelBuilder, simulate  # noqa: E402
from contactlab import peers as engines  # noqa: E402  (the peers' worlds: one translation, compare's)
from contactlab.closed_form import checks as closed_form_checks  # noqa: E402
from contactlab.compare.measures import expectation_verdict, metrics  # noqa: E402
from contactlab.errors import InputError  # noqa: E402
from contactlab.scene import load_scene  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
RESULTS_DIR = os.path.join(HERE, "results")
DT = 1.0 / 240.0
ITERATIONS = 50  # the LCP row's assembly: the constraints method's sweeps
RADIUS = 0.05
BALL_ROUNDS = 5  # interleaved rounds of the ball scene; each engine's best is its figure
PYRAMID_ROUNDS = 3  # interleaved rounds of the pyramid's constraints run and pybullet's (the target's pair)


def _installed(peer):
    try:
        engines.engine(peer)
    except InputError:  # the extra "bench" (or "peers") is not installed
        return False
    return True


PEERS = [peer for peer in ("pybullet", "mujoco") if _installed(peer)]  # run beside contactlab, in this order


# ---- scene descriptions (engine-neutral) ----------------------------------------------------


def pile_layout(count, grid=9, spacing=0.11, first_z=0.2):
    """Sphere centres of the pile: layers of grid × grid, 0.11 m apart, every other layer
    shifted by 5 mm (columns must not balance), the lowest 0.2 m up. A 9 × 9 grid fits the
    1 m box; more spheres make the column taller. Returns (count, 3) and the box half-width."""
    k = np.arange(count)
    layer, rest = np.divmod(k, grid * grid)
    i, j = np.divmod(rest, grid)
    start = -(grid - 1) * spacing / 2
    shift = 0.005 * (layer % 2)
    centres = np.stack([start + shift + spacing * i, start + shift + spacing * j, first_z + spacing * layer], axis=1)
    half_width = grid * spacing / 2 + 0.005  # 9 × 0.11 / 2 + 5 mm = 0.5 m for the 9 × 9 grid
    return centres, half_width


def pyramid_layout(levels=20, size=0.1, gap=0.005, square=False):
    """Box centres of a 2D pyramid: level L (from 0) holds levels − L boxes, resting exactly on
    the level below (the gaps are sideways), each over the gap between two below; ``square``: a
    3-D pyramid, level L a square of (levels − L)² boxes, each over the corners of four."""
    centres = []
    for level in range(levels):
        n = levels - level
        along = [(i - (n - 1) / 2) * (size + gap) for i in range(n)]
        for x in along:
            for y in along if square else [0.0]:
                centres.append((x, y, size / 2 + size * level))
    return np.array(centres)


# issue 38's variants of the pyramid: its rows' boxes touching (no sideways gap), and a 3-D
# square pyramid of 10 levels (385 boxes)
PYRAMIDS = {
    "pyramid": dict(levels=20),
    "pyramid_touching": dict(levels=20, gap=0.0),
    "pyramid3d": dict(levels=10, square=True),
}


BALL = dict(radius=0.05, height=1.0, restitution=0.8)  # centre 1 m up: the first apex is r + ε² (1 − r)

CLOTH = dict(size=1.0, mass=0.3, height=0.85, sphere_radius=0.25, sphere_z=0.3, thickness=0.005, friction=0.4)


# ---- measures from positions -----------------------------------------------------------------


def sphere_penetration(positions, half_width, radius=RADIUS):
    """Largest overlap [m] of two spheres or of a sphere and the box (floor z = 0, walls at
    ±half_width) in one frame of centres (B, 3)."""
    worst = max(0.0, float(np.max(radius - positions[:, 2])))
    worst = max(worst, float(np.max(np.abs(positions[:, :2]) + radius - half_width)))
    pairs = cKDTree(positions).query_pairs(2 * radius, output_type="ndarray")
    if len(pairs):
        distance = np.linalg.norm(positions[pairs[:, 0]] - positions[pairs[:, 1]], axis=1)
        worst = max(worst, float(np.max(2 * radius - distance)))
    return worst


def cloth_penetration(vertices, thickness=CLOTH["thickness"]):
    centre = np.array([0.0, 0.0, CLOTH["sphere_z"]])
    to_sphere = np.linalg.norm(vertices - centre, axis=1) - CLOTH["sphere_radius"]
    return max(0.0, float(np.max(thickness - to_sphere)), float(np.max(thickness - vertices[:, 2])))


def pile_measures(frames, times, half_width):
    """(max penetration over the frames, drift over the last 0.5 s) of a pile trajectory."""
    penetration = max(sphere_penetration(f, half_width) for f in frames)
    late = [f for f, t in zip(frames, times) if t >= times[-1] - 0.5 - 1e-9]
    drift = float(np.max(np.linalg.norm(late[-1] - late[0], axis=1))) if len(late) > 1 else float("nan")
    return penetration, drift


def moved(frames):
    """Per body: the largest distance [m] from its first sampled position."""
    start = frames[0]
    return np.max([np.linalg.norm(f - start, axis=1) for f in frames], axis=0)


# ---- contactlab ----------------------------------------------------------------------------------


def contactlab_pile(count, grid=9):
    b = ModelBuilder()
    b.add_material("rubber", friction=0.5, restitution=0.0)
    centres, half_width = pile_layout(count, grid)
    for c in centres:
        b.add_body("sphere", radius=RADIUS, mass=1.0, position=c, material="rubber")
    b.add_obstacle("plane", normal=(0, 0, 1), offset=0.0, material="rubber")
    for normal in ((1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0)):
        b.add_obstacle("plane", normal=normal, offset=-half_width, material="rubber")
    return b.finalize(), half_width


def contactlab_pyramid(levels=20, **layout):
    b = ModelBuilder()
    b.add_material("wood", friction=0.6, restitution=0.0)
    for c in pyramid_layout(levels, **layout):
        b.add_body("box", half_extents=(0.05, 0.05, 0.05), mass=1.0, position=c, material="wood")
    b.add_obstacle("plane", normal=(0, 0, 1), offset=0.0, material="wood")
    return b.finalize()


def contactlab_ball():
    b = ModelBuilder()
    b.add_material("rubber", friction=0.5, restitution=BALL["restitution"])
    b.add_body("sphere", radius=BALL["radius"], mass=1.0, position=(0, 0, BALL["height"]), material="rubber")
    b.add_obstacle("plane", normal=(0, 0, 1), offset=0.0, material="rubber")
    return b.finalize()


def first_apex(heights):
    """The highest centre height [m] after the first bounce (the first rise) of a sampled series."""
    heights = np.asarray(heights)
    rising = np.nonzero(np.diff(heights) > 0)[0]
    return float(heights[rising[0] :].max()) if len(rising) else float("nan")


def contactlab_cloth(n):
    b = ModelBuilder()
    b.add_material("cotton", friction=CLOTH["friction"], restitution=0.0)
    b.add_cloth(
        size=(CLOTH["size"], CLOTH["size"]),
        resolution=(n, n),
        position=(0, 0, CLOTH["height"]),
        mass=CLOTH["mass"],
        stretch_stiffness=2000.0,
        shear_stiffness=200.0,
        bend_stiffness=2.0,
        damping=0.02,
        thickness=CLOTH["thickness"],
        material="cotton",
    )
    b.add_obstacle("sphere", radius=CLOTH["sphere_radius"], position=(0, 0, CLOTH["sphere_z"]), material="cotton")
    b.add_obstacle("plane", normal=(0, 0, 1), offset=0.0, material="cotton")
    return b.finalize()


CONTACTLAB_OPTIONS = {"constraints": {}, "impulse": {}, "projection": {}, "penalty": {}}  # as shipped


PILE_WARMUP = 0.25  # s: the lowest layer (0.2 m up) lands after 0.17 s


def run_contactlab(model, method, duration, record_every, integrator="symplectic_euler", options=None, warmup=3 * DT):
    """(summary, arrays) of a timed run, after an untimed run of ``warmup`` seconds that compiles
    the kernels (long enough to reach the first contacts: a pile starts in the air, and a
    3-step warm-up would leave the contact kernels to compile inside the timed run when the
    compiled-code cache is cold). The warm-up compiles the stepping loop of projection,
    impulse and constraints too, as a user's first long run does, so the timed run takes it at its default
    (``compiled_loop=None``: the loop once it is compiled)."""
    options = dict(CONTACTLAB_OPTIONS[method] if options is None else options)
    simulate(model, method, DT, max(warmup, 3 * DT), options, integrator, compiled_loop=True)  # warm-up: compile
    run = simulate(model, method, DT, duration, options, integrator, record_every=record_every)
    return run.summary, run.arrays


# ---- the peers: worlds built by contactlab.peers ------------------------------------------------


def run_peer(model, peer, duration, record_every, scene, dt=DT):
    """(summary, arrays) of ``model`` run in ``peer`` ("pybullet" or "mujoco") for ``duration``
    [s] at ``dt`` [s], sampled every ``record_every`` steps: contactlab.peers.simulate, the world
    and the stepping ``contactlab compare --peers`` uses. Raises contactlab.peers.Inexpressible
    for a scene the engine cannot be given."""
    run = engines.simulate(model, peer, dt, duration, record_every=record_every, scene_name=scene)
    return run.summary, run.arrays


def peer_label(summary):
    """The row's method cell of a peer's run: the engine's solver and iterations as it ran."""
    options = summary["options"]
    if options["engine"] == "mujoco":
        return f"defaults ({options['solver']} ≤ {options['iterations']})"
    return f"{options['coordinates']}, defaults (SI {options['iterations']})"


def peer_row(scene, peer, summary, duration, **measures):
    """A peer's row: its rate (steps/s as the summary has it) and threads (one), with ``measures``."""
    return dict(
        scene=scene,
        engine=peer,
        method=peer_label(summary),
        bodies=summary["bodies"],
        duration=duration,
        steps=summary["steps"],
        steps_per_second=summary["steps_per_second"],
        threads=1,
        **measures,
    )


def not_run_row(scene, peer, gap):
    """The row of a peer that cannot be given the scene: contactlab.peers' sentence why."""
    return dict(scene=scene, engine=peer, method="not run", error=gap.sentence)


# ---- the benchmark runs ------------------------------------------------------------------------------

SETTINGS = {  # durations [s] of the full run and of --quick
    "full": dict(
        ball=3.0,
        pile1000=3.0,
        pile4000=3.0,
        pyramid=5.0,
        cloth64=2.0,
        cloth128=0.5,
        scaling=0.75,
        scaling_sizes=(1000, 2000, 4000, 7000, 10000),
        sample_every=12,
    ),
    "quick": dict(
        ball=1.0,
        pile1000=0.5,
        pile4000=0.25,
        pyramid=0.5,
        cloth64=0.25,
        cloth128=0.1,
        scaling=0.1,
        scaling_sizes=(1000, 2000, 4000, 7000, 10000),
        sample_every=6,
    ),
}


def record(results, key, row, path):
    """Keep ``row`` under ``key``, with the 1-minute load average when it was taken (unless the
    row brings its own, as the ball's rounds do), and save the results at once."""
    row.setdefault("load", [round(os.getloadavg()[0], 2)])
    results.setdefault("runs", {})[key] = row
    print(
        f"  {key}: "
        + ", ".join(
            f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in row.items() if k not in ("scene",)
        ),
        flush=True,
    )
    save(results, path)


METHODS = ("constraints", "impulse", "projection", "penalty")  # contactlab's, on the pile and the pyramid
PILE_METHODS = {1000: METHODS, 4000: ("constraints",)}  # the 4000 pile's target is about constraints


def contactlab_rows(results, scene, model, methods, duration, sample_every, path, measures, warmup=3 * DT):
    """Run each of contactlab's ``methods`` on ``model`` and record its row under
    ``{scene}/contactlab-{method}``: the rate, sweeps a step and threads, with what
    ``measures(summary, arrays)`` returns (a dict of the scene's own measures). A method that
    fails gets a row with its error: a diverging method is a result too."""
    steps = int(round(duration / DT))
    for method in methods:
        key = f"{scene}/contactlab-{method}"
        try:
            summary, arrays = run_contactlab(model, method, duration, sample_every, warmup=warmup)
        except Exception as error:
            record(results, key, dict(scene=scene, engine="contactlab", method=method, error=repr(error)[:200]), path)
            continue
        row = dict(
            scene=scene,
            engine="contactlab",
            method=method,
            bodies=model.body_count,
            duration=duration,
            steps=steps,
            steps_per_second=summary["steps_per_second"],
            sweeps_per_step=summary["solver"]["mean_iterations"],
            threads=summary["threads"],
        )
        record(results, key, dict(row, **measures(summary, arrays)), path)


def pile_runs(results, count, duration, sample_every, path):
    scene = f"pile{count}"
    model, half_width = contactlab_pile(count)

    def measures(summary, arrays):
        penetration, drift = pile_measures(list(arrays["body_position"]), list(arrays["time"]), half_width)
        return dict(
            max_penetration=penetration,
            drift=drift,
            engine_penetration=summary["max_penetration"],
            max_contacts=summary["max_contacts"],
        )

    contactlab_rows(
        results,
        scene,
        model,
        PILE_METHODS.get(count, ("constraints",)),
        duration,
        sample_every,
        path,
        measures,
        warmup=PILE_WARMUP,
    )
    for peer in PEERS:
        summary, arrays = run_peer(model, peer, duration, sample_every, scene)
        penetration, drift = pile_measures(list(arrays["body_position"]), list(arrays["time"]), half_width)
        record(
            results,
            f"{scene}/{peer}",
            peer_row(scene, peer, summary, duration, max_penetration=penetration, drift=drift),
            path,
        )


def _ball_round(duration):
    """One timed ball run of each engine, back to back: {row key: (steps/s, first apex, extra)}."""
    summary, arrays = run_contactlab(contactlab_ball(), "impulse", duration, 1)
    out = {
        "ball/contactlab-impulse": (
            summary["steps_per_second"],
            first_apex(arrays["body_position"][:, 0, 2]),
            dict(
                method="impulse",
                max_penetration=summary["max_penetration"],
                sweeps_per_step=summary["solver"]["mean_iterations"],
                threads=summary["threads"],
            ),
        )
    }
    steps = int(round(duration / DT))
    for peer in PEERS:  # timed sampling only the last step: a sample between two steps of 2 µs costs the next
        # its caches (57–195k steps/s against 470–530k here); the apex from a run sampled every step
        summary = run_peer(contactlab_ball(), peer, duration, steps, "ball")[0]
        apex = first_apex(run_peer(contactlab_ball(), peer, duration, 1, "ball")[1]["body_position"][:, 0, 2])
        out[f"ball/{peer}"] = (summary["steps_per_second"], apex, dict(method=peer_label(summary), threads=1))
    return out


def ball_runs(results, duration, path, rounds=BALL_ROUNDS):
    """The smallest scene: one ball bouncing (ε = 0.8) under ``impulse``: what a step costs when
    the scene costs nothing, i.e. the per-step overhead of each engine. Sampled every step for
    the first apex (closed form r + ε² (h − r)).

    A run is a few milliseconds, so one timed run says more about what else the machine did in
    those milliseconds than about the engine: the engines run in ``rounds`` interleaved rounds
    (contactlab, pybullet, MuJoCo, then again), and each row keeps its best rate (the least
    disturbed run) with every round's rate and the 1-minute load average before and after."""
    steps = int(round(duration / DT))
    expected = BALL["radius"] + BALL["restitution"] ** 2 * (BALL["height"] - BALL["radius"])
    load_before = os.getloadavg()[0]
    measured = [_ball_round(duration) for _ in range(rounds)]
    load_after = os.getloadavg()[0]
    for key, (_, apex, extra) in measured[0].items():
        rates = [one[key][0] for one in measured]
        record(
            results,
            key,
            dict(
                scene="ball",
                engine=key.split("/")[1].split("-")[0],
                bodies=1,
                duration=duration,
                steps=steps,
                steps_per_second=max(rates),
                round_rates=[round(r) for r in rates],
                load=[round(load_before, 2), round(load_after, 2)],
                first_apex=apex,
                expected_apex=expected,
                **extra,
            ),
            path,
        )


def _pyramid_rounds(model, scene, steps, sample_every, results, first_bullet_rate, path, rounds=PYRAMID_ROUNDS):
    """The pyramid's target compares ``constraints`` with pybullet, and on a host whose speed
    drifts (20 % within a quarter of an hour on the sixteenth round's) two runs a minute apart
    compare the host as much as the engines. So after the first runs of each, the two run
    again in turn, ``rounds`` in all: contactlab's row keeps its best rate and every round's
    (``round_rates``), and this returns pybullet's rates, the first run's first."""
    row = results["runs"].get(f"{scene}/contactlab-constraints", {})
    if "steps_per_second" not in row:  # it diverged: nothing to pair
        return [first_bullet_rate]
    ours, theirs = [row["steps_per_second"]], [first_bullet_rate]
    for _ in range(rounds - 1):
        ours.append(run_contactlab(model, "constraints", steps * DT, sample_every)[0]["steps_per_second"])
        theirs.append(run_peer(model, "pybullet", steps * DT, steps, scene)[0]["steps_per_second"])
    record(
        results,
        f"{scene}/contactlab-constraints",
        dict(row, steps_per_second=max(ours), round_rates=[round(r, 1) for r in ours]),
        path,
    )
    return theirs


def pyramid_runs(results, duration, sample_every, path, scene="pyramid"):
    """The pyramid ``scene`` (a key of PYRAMIDS): contactlab's methods (its variants:
    constraints and impulse), then each peer, pybullet in rounds with constraints."""
    steps = int(round(duration / DT))
    model = contactlab_pyramid(**PYRAMIDS[scene])

    def measures(summary, arrays):
        travel = moved(list(arrays["body_position"]))
        return dict(
            max_penetration=summary["max_penetration"],
            drift=float(travel.max()),
            moved_over_1mm=int((travel > 1e-3).sum()),
            moved_over_1cm=int((travel > 1e-2).sum()),
        )

    methods = METHODS if scene == "pyramid" else ("constraints", "impulse")
    contactlab_rows(results, scene, model, methods, duration, sample_every, path, measures)
    for peer in PEERS:
        summary, arrays = run_peer(model, peer, duration, sample_every, scene)
        row = peer_row(scene, peer, summary, duration, **measures(summary, arrays))
        if peer == "pybullet":  # the target's pair: best of interleaved rounds with constraints
            rounds = _pyramid_rounds(model, scene, steps, sample_every, results, row["steps_per_second"], path)
            row.update(steps_per_second=max(rounds), round_rates=[round(r, 1) for r in rounds])
        record(results, f"{scene}/{peer}", row, path)


def cloth_runs(results, n, duration, sample_every, path, methods=("projection", "constraints"), peers=True):
    steps = int(round(duration / DT))
    scene = f"cloth{n}"
    model = contactlab_cloth(n)
    for method in methods:
        try:
            summary, arrays = run_contactlab(model, method, duration, sample_every, integrator="backward_euler")
        except Exception as error:
            record(
                results,
                f"{scene}/contactlab-{method}",
                dict(scene=scene, engine="contactlab", method=method, error=repr(error)[:200]),
                path,
            )
            continue
        penetration = max(cloth_penetration(f) for f in arrays["particle_position"])
        record(
            results,
            f"{scene}/contactlab-{method}",
            dict(
                scene=scene,
                engine="contactlab",
                method=f"{method} (backward Euler)",
                vertices=n * n,
                duration=duration,
                steps=steps,
                steps_per_second=summary["steps_per_second"],
                max_penetration=penetration,
                engine_penetration=summary["max_penetration"],
                lowest_vertex=float(arrays["particle_position"][..., 2].min()),
            ),
            path,
        )
    for peer in PEERS if peers else ():
        try:  # contactlab.peers translates rigid bodies only: the row says so (the flex cloth MuJoCo was
            # given by hand until the twentieth round was another model than contactlab's springs)
            run_peer(model, peer, duration, sample_every, scene)
        except engines.Inexpressible as gap:
            record(results, f"{scene}/{peer}", not_run_row(scene, peer, gap), path)


def scaling_runs(results, sizes, duration, path):
    """Time per step of the contactlab pile, constraints, as N grows. The box widens with N
    (a square grid of side √(N/12.35), as the 1000-sphere pile's 12.35 layers), so every size
    is the same pile, only wider: the work per sphere stays alike."""
    for count in sizes:
        grid = max(9, int(np.ceil(np.sqrt(count / (1000 / 81)))))
        model, _ = contactlab_pile(count, grid)
        summary, _ = run_contactlab(model, "constraints", duration, 1000, warmup=PILE_WARMUP)
        record(
            results,
            f"scaling/{count}",
            dict(
                scene="scaling",
                engine="contactlab",
                method="constraints",
                bodies=count,
                grid=grid,
                duration=duration,
                steps=int(round(duration / DT)),
                steps_per_second=summary["steps_per_second"],
                ms_per_step=1e3 / summary["steps_per_second"],
                max_contacts=summary["max_contacts"],
            ),
            path,
        )


BUILTIN = ("box_pyramid", "bouncing_ball", "sliding_block", "rolling_sphere")  # issue 39's acceptance scenes


def scene_measures(name, model, summary, arrays):
    """What ``contactlab compare`` puts in a row (contactlab.compare.measures.metrics: penetration,
    energy and momentum drift, contacts, iterations) and its closed-form checks of scene ``name``
    (contactlab.closed_form), each as plain data."""
    found = metrics(model, arrays, summary)
    checks = closed_form_checks(name, model, arrays)
    return dict(
        max_penetration=summary["max_penetration"],
        energy_drift=found["energy_drift_J"],
        momentum_drift=found["momentum_drift_Ns"],
        max_contacts=found["max_contacts"],
        max_iterations=found["max_solver_iterations"],
        expectations=expectation_verdict(checks),
        checks=[check.as_record() for check in checks],
    )


def scene_runs(results, path, quick, names=BUILTIN):
    """The built-in scenes as ``contactlab compare SCENE --peers pybullet,mujoco`` runs them: at
    the scene's own dt and duration (``--quick``: at most 1 s), sampled every step; the scene's
    method at its defaults (after a 3-step run that compiles it) and each peer through
    contactlab.peers, with compare's measures and verdicts (:func:`scene_measures`), under
    ``builtin-{scene}/{engine}``."""
    for name in names:
        scene = load_scene(name)
        duration = min(scene.duration, 1.0) if quick else scene.duration
        key = f"builtin-{name}"
        options = scene.options[scene.method]
        simulate(scene.model, scene.method, scene.dt, 3 * scene.dt, options, scene.integrator)  # compiles
        run = simulate(scene.model, scene.method, scene.dt, duration, options, scene.integrator)
        record(
            results,
            f"{key}/contactlab-{scene.method}",
            dict(
                scene=key,
                engine="contactlab",
                method=scene.method,
                bodies=scene.model.body_count,
                dt=scene.dt,
                duration=duration,
                steps=run.summary["steps"],
                steps_per_second=run.summary["steps_per_second"],
                threads=run.summary["threads"],
                **scene_measures(name, scene.model, run.summary, run.arrays),
            ),
            path,
        )
        for peer in PEERS:
            summary, arrays = run_peer(scene.model, peer, duration, 1, name, dt=scene.dt)
            row = peer_row(key, peer, summary, duration, **scene_measures(name, scene.model, summary, arrays))
            record(results, f"{key}/{peer}", dict(row, dt=scene.dt, engine_notes=summary["engine_notes"]), path)


COMPILE_NOTICE = "compiling contact kernels for first use"


def _timed_process(command, env, cwd):
    """(wall seconds, CPU seconds of the process, return code, standard error) of one run of
    ``command``: the wall clock follows whatever else the cores do, the CPU time hardly does."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    done = subprocess.run(command, env=env, cwd=cwd, capture_output=True, text=True)
    wall = time.perf_counter() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, done.returncode, done.stderr


def cold_start_runs(results, path, imports=5):
    """Issue 18's start-up targets as a user meets them, each in a process of its own:
    ``python -m contactlab demo`` on an empty compile cache (a new ``NUMBA_CACHE_DIR``, as a
    fresh install has), the same again on the cache the first run left, and ``import
    contactlab`` timed inside a bare interpreter (best of ``imports``). Each demo runs in an
    empty folder, where it writes its outputs."""
    probe = "import time; t = time.perf_counter(); import contactlab; print(time.perf_counter() - t)"
    with tempfile.TemporaryDirectory() as cache, tempfile.TemporaryDirectory() as folder:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        demo = [sys.executable, "-m", "contactlab", "demo"]
        load_before = os.getloadavg()[0]
        runs = [_timed_process(demo, env, folder) for _ in range(2)]
        import_seconds = []
        for _ in range(imports):
            out = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True, text=True, check=True)
            import_seconds.append(float(out.stdout.strip().splitlines()[-1]))
        load_after = os.getloadavg()[0]
    (first_wall, first_cpu, first_rc, first_err), (second_wall, second_cpu, second_rc, second_err) = runs
    record(
        results,
        "coldstart/contactlab",
        dict(
            scene="coldstart",
            engine="contactlab",
            method="demo",
            first_wall=first_wall,
            first_cpu=first_cpu,
            first_returncode=first_rc,
            first_says_compiling=COMPILE_NOTICE in first_err,
            second_wall=second_wall,
            second_cpu=second_cpu,
            second_returncode=second_rc,
            second_says_compiling=COMPILE_NOTICE in second_err,
            import_seconds=min(import_seconds),
            import_rounds=[round(t, 3) for t in import_seconds],
            load=[round(load_before, 2), round(load_after, 2)],
        ),
        path,
    )


SHORT_RUN = 3.0  # s of the ball at DT: 720 steps, issue 36's short run
MANY_RUNS = 200  # runs of it in one process (a study's cells)

_SHORT_CHILD = """
import json, sys, time
sys.path.insert(0, {here!r})
engine, runs, warm_loop = {engine!r}, {runs!r}, {warm_loop!r}
started = time.perf_counter()
import peers
steps = int(round({duration!r} / peers.DT))
if engine == "contactlab":
    from contactlab.simulation import simulate
    model = peers.contactlab_ball()
    if runs > 1:  # a study's runs: one that loads (or compiles) the kernels, then the timed ones
        simulate(model, "impulse", dt=peers.DT, duration={duration!r}, compiled_loop=warm_loop or None)
    run_started = time.perf_counter()
    for _ in range(runs):
        summary = simulate(model, "impulse", dt=peers.DT, duration={duration!r}).summary
    run_wall = time.perf_counter() - run_started
    out = dict(steps_per_second=summary["steps_per_second"], compiled_loop=summary["compiled_loop"],
               stepping=summary["stepping"], threads=summary["threads"])
else:
    import mujoco
    from contactlab.peers.mujoco import World
    world = World(peers.contactlab_ball(), peers.DT)  # the ball as contactlab.peers gives it to MuJoCo
    m, d = world.mj_model, world.data
    run_started = time.perf_counter()
    for _ in range(runs):
        mujoco.mj_resetData(m, d)
        for _ in range(steps):
            mujoco.mj_step(m, d)
    run_wall = time.perf_counter() - run_started
    out = dict(steps_per_second=runs * steps / run_wall)
out.update(runs=runs, run_wall=run_wall, ms_per_run=1e3 * run_wall / runs, process_wall=time.perf_counter() - started)
print(json.dumps(out))
"""


def _short_child(engine, env, runs=1, warm_loop=False):
    """``runs`` 720-step ball runs in a fresh process of ``engine`` (after one untimed where
    ``runs`` > 1, through the compiled loop where ``warm_loop``): its JSON line as a dict."""
    code = _SHORT_CHILD.format(here=HERE, engine=engine, duration=SHORT_RUN, runs=runs, warm_loop=warm_loop)
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def short_runs(results, path, runs=MANY_RUNS):
    """Issue 36's short runs, as a user and a study meet them, each engine in processes of its own
    sharing one new compile cache.

    * ``shortrun``: the 720-step ball (``impulse``, dt 1/240) in a fresh process on the empty
      cache, then again in another on the cache the first left; MuJoCo's same ball in a fresh
      process. The second run's steps/s is the target: a user's every later run.
    * ``manyruns``: ``runs`` such runs through ``simulate()`` in one process after one untimed
      run, at the defaults (on the cache the short runs left) and again after one run through
      the compiled loop (``compiled_loop=True``, which caches it); MuJoCo resetting
      (``mj_resetData``) and stepping its ball as often: ms a run."""
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        load_before = os.getloadavg()[0]
        first, second = _short_child("contactlab", env), _short_child("contactlab", env)
        peer = _short_child("mujoco", env) if "mujoco" in PEERS else None
        load_between = os.getloadavg()[0]
        many = _short_child("contactlab", env, runs)
        many_loop = _short_child("contactlab", env, runs, warm_loop=True)
        many_peer = _short_child("mujoco", env, runs) if "mujoco" in PEERS else None
        load_after = os.getloadavg()[0]
    shared = dict(method="impulse", steps=int(round(SHORT_RUN / DT)))
    record(
        results,
        "shortrun/contactlab",
        dict(
            scene="shortrun",
            engine="contactlab",
            first=first,
            second=second,
            steps_per_second=second["steps_per_second"],
            load=[round(load_before, 2), round(load_between, 2)],
            **shared,
        ),
        path,
    )
    record(
        results,
        "manyruns/contactlab",
        dict(
            scene="manyruns",
            engine="contactlab",
            defaults=many,
            loop_compiled=many_loop,
            load=[round(load_between, 2), round(load_after, 2)],
            **shared,
        ),
        path,
    )
    if peer is not None:
        record(results, "shortrun/mujoco", dict(scene="shortrun", engine="mujoco", **peer), path)
        record(results, "manyruns/mujoco", dict(scene="manyruns", engine="mujoco", **many_peer), path)


def assembled_pile_lcp(count=4000, settle=0.5):
    """The frictionless LCP (B_nn, c_n) that the constraints method forms for the pile after
    ``settle`` seconds, assembled the way methods.constraints.step does (stages 1–4)."""
    from contactlab.collision import collide, swept_distances
    from contactlab.contacts import jacobian
    from contactlab.dynamics.generalized import inverse_mass_matrix, stack
    from contactlab.dynamics.integrators import free_velocities
    from contactlab.methods import constraints as cm
    from contactlab.methods.jacobian_rows import rows_of

    model, _ = contactlab_pile(count)
    options = cm.Options(iterations=ITERATIONS)
    state = simulate(model, "constraints", DT, settle, {"iterations": ITERATIONS}, record_every=10_000).state
    free = free_velocities(model, state, DT, "symplectic_euler")
    v_free = stack(*free)
    sweep = swept_distances(model, free[0], free[1], free[2], DT)
    contacts = collide(
        model,
        state,
        options.contact_margin,
        sweep,
        options.granularity,
        options.normal,
        options.samples,
        cloth_samples=options.cloth_samples,
    )
    J = jacobian(contacts, state.body_position, model.body_count, model.particle_count)
    rows = rows_of(model, contacts, state.body_position, state.body_orientation)
    target, _ = cm.normal_row_targets(model, state, contacts, rows, v_free, DT, options)
    targets = np.zeros((contacts.count, 3))
    targets[:, 0] = target
    inverse = cm.SystemInverse(inverse_mass=inverse_mass_matrix(model, state.body_orientation))
    B, q = cm.lcp_matrices(J, inverse, v_free, targets.ravel())
    rows = np.arange(0, 3 * contacts.count, 3)
    return B[rows][:, rows].tocsr(), -q[rows], f"sphere pile, {count}, assembled after {settle} s"


def random_spd_lcp(n=12000, per_row=8, seed=1):
    rng = np.random.default_rng(seed)
    import scipy.sparse as sp

    A = sp.random(n, n, density=per_row / n, random_state=rng, format="csr")
    B = (A @ A.T + sp.identity(n) * per_row).tocsr()
    return B, rng.normal(size=n), f"random sparse SPD, n = {n}"


def lcp_runs(results, path, quick):
    from contactlab.lcp import solve_lcp

    try:
        B, c, source = assembled_pile_lcp(4000, 0.25 if quick else 0.5)
    except Exception as error:  # internals moved: fall back, say so
        print(f"  (assembling the pile's LCP failed: {error!r}; using a random SPD LCP)")
        B, c, source = random_spd_lcp()
    timings = {}
    answers = {}
    for method in ("pgs", "redblack", "redblack_blocks"):
        solve_lcp(B, c, method=method, tol=1e-8, max_iterations=5)  # compile
        best = None
        for _ in range(3):
            t0 = time.perf_counter()
            result = solve_lcp(B, c, method=method, tol=1e-8, max_iterations=20000)
            elapsed = time.perf_counter() - t0
            best = elapsed if best is None else min(best, elapsed)
        timings[method] = (best, result)
        answers[method] = result.lam
    for method, (seconds, result) in timings.items():
        difference = float(
            np.linalg.norm(answers["pgs"] - answers[method]) / max(np.linalg.norm(answers["pgs"]), 1e-300)
        )
        record(
            results,
            f"lcp/{method}",
            dict(
                scene="lcp",
                engine="contactlab.lcp",
                method=method,
                rows=B.shape[0],
                nonzeros=int(B.nnz),
                source=source,
                seconds=seconds,
                sweeps=int(result.iterations),
                residual=float(result.residual),
                converged=bool(result.converged),
                colors=int(result.colors or 0),
                relative_difference=difference,
            ),
            path,
        )


# ---- machine, saving, report ---------------------------------------------------------------------------


def machine():
    cpu = "unknown"
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    import numba
    import scipy

    info = dict(
        cpu=cpu,
        cores=os.cpu_count(),
        python=platform.python_version(),
        platform=platform.platform(),
        numpy=np.__version__,
        scipy=scipy.__version__,
        numba=numba.__version__,
        contactlab=contactlab.__version__,
        numba_threads=os.environ["NUMBA_NUM_THREADS"],
        blas_threads=os.environ["OPENBLAS_NUM_THREADS"],
        date=date.today().isoformat(),
    )
    from importlib.metadata import version

    for peer in PEERS:
        info[peer] = version(peer)
    return info


def _spin():
    while True:
        pass


@contextlib.contextmanager
def busy_core(active=True):
    """While the block runs (and ``active``), a second process keeps one core at 100 %: the
    'another process keeps a core busy' of every benchmark that measures under load."""
    if not active:
        yield
        return
    spinner = multiprocessing.Process(target=_spin, daemon=True)
    spinner.start()
    time.sleep(0.5)  # running before anything is measured
    try:
        yield
    finally:
        spinner.terminate()
        spinner.join()


def write_lines(path, lines):
    """Write the Markdown ``lines`` to ``path`` (its folder made if needed) and say so."""
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with open(path, "w", encoding="utf-8") as stream:
        stream.write("\n".join(lines) + "\n")
    print(f"wrote {path}")


def save(results, path):
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w") as f:
        json.dump(results, f, indent=1, sort_keys=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="short durations: a smoke run")
    parser.add_argument(
        "--only",
        nargs="*",
        default=None,
        choices=[
            "ball",
            "shortruns",
            "pile1000",
            "pile4000",
            "pyramid",
            "pyramid_touching",
            "pyramid3d",
            "cloth64",
            "cloth128",
            "scaling",
            "lcp",
            "coldstart",
            "scenes",
        ],
        help="run only these (default: all)",
    )
    parser.add_argument("--scaling-sizes", type=int, nargs="*", default=None)
    parser.add_argument(
        "--cloth-methods", nargs="*", default=["projection", "constraints"], help="contactlab methods of the cloth runs"
    )
    parser.add_argument("--no-peers", action="store_true", help="cloth: contactlab only (keep the peers' rows)")
    parser.add_argument(
        "--duration", nargs="*", default=[], metavar="KEY=SECONDS", help="override a scene's duration, e.g. cloth64=0.5"
    )
    parser.add_argument("--numba-threads", default="2", help="NUMBA_NUM_THREADS (set before numba loads)")
    parser.add_argument(
        "--no-mujoco",
        action="store_true",
        help="leave MuJoCo out (at its default Newton solver a 1000-sphere pile takes it over ten "
        "minutes here); its rows of the scenes run are dropped, not kept from another setting",
    )
    parser.add_argument("--results", default=os.path.join(RESULTS_DIR, "results.json"))
    parser.add_argument("--fresh", action="store_true", help="start a new results.json instead of merging")
    parser.add_argument("--report-only", action="store_true", help="rewrite results.md and the plots only")
    args = parser.parse_args()
    settings = dict(SETTINGS["quick" if args.quick else "full"])
    for item in args.duration:
        key, seconds = item.split("=")
        settings[key] = float(seconds)
    results = {}
    if os.path.exists(args.results) and not args.fresh:
        with open(args.results) as f:
            results = json.load(f)
    if not args.report_only:
        results["machine"] = machine()
        results.setdefault("settings", {})["quick" if args.quick else "full"] = {
            k: list(v) if isinstance(v, tuple) else v for k, v in settings.items()
        }
        results["mode"] = "quick" if args.quick else "full"
        results["settings_mode"] = "each engine's defaults; the peers' worlds built by contactlab.peers"
        if args.no_mujoco and "mujoco" in PEERS:
            PEERS.remove("mujoco")
        todo = args.only or [
            "coldstart",
            "shortruns",
            "ball",
            "pile1000",
            "pyramid",
            "pyramid_touching",
            "pyramid3d",
            "cloth64",
            "lcp",
            "scaling",
            "pile4000",
            "cloth128",
            "scenes",
        ]
        every = settings["sample_every"]
        for item in todo:
            print(f"{item} ...", flush=True)
            if args.no_mujoco:
                results.get("runs", {}).pop(f"{item}/mujoco", None)
            started = time.perf_counter()
            if item == "ball":
                ball_runs(results, settings["ball"], args.results)
            elif item.startswith("pile"):
                pile_runs(results, int(item[4:]), settings[item], every, args.results)
            elif item in PYRAMIDS:
                pyramid_runs(results, settings["pyramid"], every, args.results, item)
            elif item.startswith("cloth"):
                cloth_runs(
                    results, int(item[5:]), settings[item], every, args.results, args.cloth_methods, not args.no_peers
                )
            elif item == "scaling":
                scaling_runs(
                    results, args.scaling_sizes or settings["scaling_sizes"], settings["scaling"], args.results
                )
            elif item == "lcp":
                lcp_runs(results, args.results, args.quick)
            elif item == "coldstart":
                cold_start_runs(results, args.results)
            elif item == "shortruns":
                short_runs(results, args.results)
            elif item == "scenes":
                scene_runs(results, args.results, args.quick)
            print(f"{item} done in {time.perf_counter() - started:.0f} s", flush=True)
    from report import write_report  # benchmarks/report.py

    out_dir = os.path.dirname(os.path.abspath(args.results))
    md_path = os.path.join(HERE, "results.md") if out_dir == RESULTS_DIR else os.path.join(out_dir, "results.md")
    write_report(results, md_path, out_dir)  # a --results elsewhere keeps the committed baseline


if __name__ == "__main__":
    sys.path.insert(0, HERE)
    main()
