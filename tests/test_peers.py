"""Issue 39: MuJoCo and pybullet beside the methods (contactlab.peers): the translation of a Model
round-trips into each engine, a dropped box lands when the closed form says in every engine, the
peers' rows carry the scene's expectations, a scene a peer cannot express is reported, and a
missing extra is one line and exit 2."""

import csv
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from contactlab import ModelBuilder, peers, simulate
from contactlab.cli import main
from contactlab.closed_form import checks
from contactlab.compare import compare
from contactlab.record import DRAWN, load_run, read_trajectory
from contactlab.scene import load_scene
from contactlab.viewed_runs import run_folders

REASON = "the peers are the optional extra contactlab[peers] (pip install 'contactlab[peers]')"
TILTED = np.array([np.cos(0.3), np.sin(0.3) * 0.6, 0.0, np.sin(0.3) * 0.8])  # (w, x, y, z), unit


def _mixed_scene():
    """Every shape a body or an obstacle can have, posed off the axes and moving."""
    b = ModelBuilder()
    b.add_material("wood", friction=0.6, restitution=0.0)
    b.add_material("rubber", friction=0.9, restitution=0.5)
    b.add_body("sphere", radius=0.1, mass=2.0, position=(0, 0, 1), velocity=(1, 0, 0), material="rubber")
    b.add_body(
        "box",
        half_extents=(0.1, 0.2, 0.05),
        mass=3.0,
        position=(1, 0, 1),
        orientation=TILTED,
        angular_velocity=(0.5, -1.0, 2.0),
        material="wood",
    )
    b.add_body("capsule", radius=0.05, half_length=0.2, mass=1.5, position=(2, 0, 1), orientation=TILTED)
    corners = np.array([[0, 0, 0], [0.3, 0, 0], [0, 0.2, 0], [0, 0, 0.1], [0.3, 0.2, 0.1]], dtype=float)
    b.add_body("convex", points=corners, mass=1.0, position=(3, 0, 1), velocity=(0, 0, -1), angular_velocity=(1, 2, 3))
    b.add_obstacle("plane", normal=(0, 0, 1), offset=0.0, material="wood")
    b.add_obstacle("box", half_extents=(0.5, 0.5, 0.1), position=(0, 3, 0.1), orientation=TILTED)
    b.add_obstacle("sphere", radius=0.3, position=(2, 3, 0.3))
    b.add_obstacle("convex", points=corners, position=(4, 3, 0.0), orientation=TILTED)
    return b.finalize()


def _same_rotation(q, p):
    return min(np.abs(q - p).max(), np.abs(q + p).max())


def _assert_state(model, state):
    start = model.initial
    np.testing.assert_allclose(state.body_position, start.body_position, atol=1e-12)
    for q, p in zip(state.body_orientation, start.body_orientation):
        assert _same_rotation(q, p) < 1e-9
    np.testing.assert_allclose(state.body_velocity, start.body_velocity, atol=1e-12)
    np.testing.assert_allclose(state.body_angular_velocity, start.body_angular_velocity, atol=1e-9)


def test_the_translation_round_trips_into_mujoco():
    pytest.importorskip("mujoco", reason=REASON)
    import mujoco

    from contactlab.peers import mujoco as peer

    model = _mixed_scene()
    world = peer.World(model, 0.002)
    m, d = world.mj_model, world.data
    assert m.nbody == model.body_count + 1 and m.ngeom == model.body_count + model.obstacle_count
    np.testing.assert_allclose(m.body_mass[1:], model.body_mass)
    np.testing.assert_allclose(m.body_inertia[1:], model.body_inertia)
    np.testing.assert_allclose(m.body_ipos[1:], 0.0)
    np.testing.assert_allclose(m.opt.gravity, model.gravity)
    assert m.opt.timestep == 0.002
    _assert_state(model, world.state())
    # the shapes where contactlab has them: sizes, and the convex body's corners in the world
    kinds = [mujoco.mjtGeom(t).name for t in m.geom_type]
    assert kinds == ["mjGEOM_PLANE", "mjGEOM_BOX", "mjGEOM_SPHERE", "mjGEOM_MESH"] + [
        "mjGEOM_SPHERE",
        "mjGEOM_BOX",
        "mjGEOM_CAPSULE",
        "mjGEOM_MESH",
    ]
    np.testing.assert_allclose(m.geom_size[5], model.body_params[1, :3])
    np.testing.assert_allclose(m.geom_size[6, :2], model.body_params[2, :2])
    from contactlab.peers.translate import hull_vertices
    from contactlab.rotations import to_matrix

    convex = 7
    start = m.mesh_vertadr[m.geom_dataid[convex]]
    corners = m.mesh_vert[start : start + m.mesh_vertnum[m.geom_dataid[convex]]]
    in_world = d.geom_xpos[convex] + corners @ d.geom_xmat[convex].reshape(3, 3).T
    expected = (
        model.initial.body_position[3]
        + hull_vertices(model, int(model.body_params[3, 0])) @ to_matrix(model.initial.body_orientation[3]).T
    )
    assert max(np.min(np.linalg.norm(expected - point, axis=1)) for point in in_world) < 1e-6
    # friction: MuJoCo takes the larger of two geoms', and here the scene has two pairs it cannot both meet
    assert any("friction" in note for note in world.notes)


def test_the_translation_round_trips_into_pybullet():
    pytest.importorskip("pybullet", reason=REASON)
    import pybullet

    from contactlab.peers import pybullet as peer

    model = _mixed_scene()
    world = peer.World(model, 0.002)
    try:
        c = world.client
        assert pybullet.getNumBodies(physicsClientId=c) == model.body_count + model.obstacle_count
        for b, body in enumerate(world.bodies):
            info = pybullet.getDynamicsInfo(body, -1, physicsClientId=c)
            assert info[0] == pytest.approx(model.body_mass[b])
            np.testing.assert_allclose(info[2], model.body_inertia[b], rtol=1e-12)
        _assert_state(model, world.state())
        # the capsule reaches half length + radius along its tilted axis, and its radius across it
        from contactlab.rotations import to_matrix

        centre, frame = model.initial.body_position[2], to_matrix(TILTED)
        for direction, reach in ((frame[:, 2], 0.25), (-frame[:, 2], 0.25), (frame[:, 0], 0.05)):
            hit = pybullet.rayTest(list(centre + direction), list(centre), physicsClientId=c)[0]
            assert hit[0] == world.bodies[2]
            assert np.linalg.norm(np.subtract(hit[3], centre)) == pytest.approx(reach, abs=1e-6)
        # friction √μ a shape: Bullet's product gives every pair contactlab's geometric mean
        sphere, box = (pybullet.getDynamicsInfo(world.bodies[k], -1, physicsClientId=c)[1] for k in (0, 1))
        assert sphere * box == pytest.approx(float(model.pair_materials(1, 0)[0]))
    finally:
        world.close()


@pytest.mark.parametrize("height", [0.5, 1.2])
def test_a_dropped_box_lands_when_the_closed_form_says_in_every_engine(height):
    """A box whose bottom starts ``height`` up lands at t = √(2 h / g): the first sample whose
    vertical velocity stops falling faster, within two steps, in contactlab and in each peer."""
    pytest.importorskip("mujoco", reason=REASON)
    pytest.importorskip("pybullet", reason=REASON)
    dt, g = 0.002, 9.81
    b = ModelBuilder()
    b.add_body("box", half_extents=(0.1, 0.1, 0.1), mass=1.0, position=(0, 0, height + 0.1))
    b.add_obstacle("plane", normal=(0, 0, 1), offset=0.0)
    model = b.finalize()
    landing = np.sqrt(2 * height / g)
    runs = {"impulse": simulate(model, "impulse", dt, landing + 0.1)}
    runs.update({peer: peers.simulate(model, peer, dt, landing + 0.1) for peer in peers.PEERS})
    for name, run in runs.items():
        vz = run.arrays["body_velocity"][:, 0, 2]
        landed = np.flatnonzero(np.diff(vz) > -0.5 * g * dt)
        assert landed.size, name
        assert abs(run.arrays["time"][landed[0] + 1] - landing) <= 2 * dt, name


def test_compare_with_peers_gives_their_rows_the_methods_columns_and_expectations(tmp_path, capsys):
    """The command line's compare --peers: each peer a row of comparison.csv with the same
    columns, the scene's closed-form checks evaluated on its trajectory, and its folder a run
    that the viewer, render and export read."""
    pytest.importorskip("mujoco", reason=REASON)
    pytest.importorskip("pybullet", reason=REASON)
    out = tmp_path / "rolling"
    code = main(
        [
            "compare",
            "rolling_sphere",
            "--methods",
            "impulse",
            "--peers",
            "mujoco,pybullet",
            "--no-video",
            "--out",
            str(out),
            "--set",
            "simulation.duration=0.6",
        ]
    )
    assert code == 0
    with open(out / "comparison.csv", newline="", encoding="utf-8") as stream:
        rows = {row["method"]: row for row in csv.DictReader(stream)}
    assert list(rows) == ["impulse", "mujoco", "pybullet"]
    scene = load_scene("rolling_sphere", ["simulation.duration=0.6"])
    for peer in peers.PEERS:
        row = rows[peer]
        assert row["status"] == "ok" and float(row["steps_per_second"]) > 0 and row["steps"] == "300"
        arrays, summary = load_run(str(out / peer))
        assert summary["method"] == peer and summary["options"]["engine"] == peer
        found = checks(scene.name, scene.model, arrays)
        assert len(found) == 2
        assert row["expectations"] == f"{'pass' if all(c.passed for c in found) else 'FAIL'} " + (
            f"({sum(c.passed for c in found)} of 2)"
        )
        for check in found:
            assert float(row[f"{check.quantity} error ({check.unit})"]) == pytest.approx(check.error)
        read_trajectory(arrays, DRAWN)  # what render, view and export read
    assert [os.path.basename(folder) for folder in run_folders(str(out))] == ["impulse", "mujoco", "pybullet"]
    report = (out / "report.md").read_text(encoding="utf-8")
    assert "MuJoCo " in report and "pybullet " in report and "docs/peers.md" in report


def test_a_scene_a_peer_cannot_express_gets_a_row_saying_why_and_the_comparison_goes_on(tmp_path):
    pytest.importorskip("mujoco", reason=REASON)
    result = compare(
        "particles_box",
        ["projection"],
        str(tmp_path / "particles"),
        duration=0.01,
        video=False,
        peers=["mujoco"],
    )
    rows = {row["method"]: row for row in result.rows}
    assert rows["projection"]["status"] == "ok"
    status = rows["mujoco"]["status"]
    assert status.startswith("not run: mujoco cannot express this scene: ") and "particles" in status
    assert "mujoco cannot express this scene" in result.summary_text
    assert not (tmp_path / "particles" / "mujoco").exists()
    assert "not run" in open(result.report_html, encoding="utf-8").read()


def test_a_non_convex_mesh_is_a_gap_for_mujoco_alone_and_holds_a_ball_in_pybullet():
    """The bowl of mesh_bowl: MuJoCo would collide its convex hull (a filled bowl), so it is not
    run there; pybullet is given the triangles, and a ball dropped into it stays inside."""
    bowl = os.path.join(os.path.dirname(peers.__file__), "..", "scene", "meshes", "bowl.obj")
    b = ModelBuilder()
    b.add_body("sphere", radius=0.05, mass=1.0, position=(0.2, 0.0, 0.6))
    b.add_obstacle("mesh", file=bowl)
    model = b.finalize()
    assert any("convex hull" in reason for reason in peers.gaps(model, "mujoco"))
    with pytest.raises(peers.Inexpressible, match="mujoco cannot express this scene"):
        peers.simulate(model, "mujoco", 0.004, 0.1)
    assert peers.gaps(model, "pybullet") == []
    pytest.importorskip("pybullet", reason=REASON)
    run = peers.simulate(model, "pybullet", 0.004, 1.5)
    lowest = float(np.min(model.meshes[0].vertices[:, 2]))
    assert run.arrays["body_position"][:, 0, 2].min() > lowest + 0.05  # resting on the inside, not through
    assert np.abs(run.arrays["body_velocity"][-1, 0]).max() < 1.0


def test_without_the_extra_peers_is_one_line_naming_what_to_install_and_exit_2(tmp_path):
    code = textwrap.dedent(
        f"""
        import sys
        sys.modules["mujoco"] = None  # as if the extra were not installed
        from contactlab.cli import main
        out = {str(tmp_path / "out")!r}
        sys.exit(main(["compare", "bouncing_ball", "--peers", "mujoco", "--no-video", "--out", out]))
        """
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "pip install 'contactlab[peers]'" in lines[0] and "--peers" in lines[0]
    assert not (tmp_path / "out").exists()


def test_a_study_sweeps_the_peers_beside_the_methods(tmp_path):
    pytest.importorskip("mujoco", reason=REASON)
    from contactlab import sweep
    from contactlab.study import load_study

    study = tmp_path / "study.toml"
    study.write_text(
        textwrap.dedent(
            """
            [grid]
            scenes = ["bouncing_ball"]
            methods = ["impulse"]
            peers = ["mujoco"]
            [grid.set]
            "simulation.duration" = [0.5]
            [[cells]]
            scene = "particles_box"
            method = "mujoco"
            """
        ),
        encoding="utf-8",
    )
    cells = load_study(study).cells
    assert [cell.method for cell in cells] == ["impulse", "mujoco", "mujoco"]
    assert cells[1].overrides() == ["simulation.duration=0.5"]  # the scene's own method: a peer has none
    table = sweep.run(study, tmp_path / "out", workers=1)
    rows = {(row["scene"], row["method"]): row for row in table.to_dict("records")}
    ball = rows[("bouncing_ball", "mujoco")]
    assert ball["status"] == "ok" and ball["integrator"].startswith("MuJoCo") and ball["steps"] == 500
    assert ball["closed_form_checks"]  # the rebound apexes, measured on MuJoCo's trajectory
    gap = rows[("particles_box", "mujoco")]
    assert gap["status"] == "not run" and "particles" in gap["message"]


def _benchmark(monkeypatch):
    """benchmarks/peers.py as a module (it pins thread variables on import: put back after the test)."""
    import importlib.util

    folder = os.path.join(os.path.dirname(__file__), os.pardir, "benchmarks")
    for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "VECLIB_MAXIMUM_THREADS"):
        monkeypatch.setenv(name, os.environ.get(name, ""))
    monkeypatch.setenv("NUMEXPR_NUM_THREADS", os.environ.get("NUMEXPR_NUM_THREADS", ""))
    monkeypatch.setenv("NUMBA_NUM_THREADS", os.environ.get("NUMBA_NUM_THREADS", ""))
    monkeypatch.syspath_prepend(folder)
    spec = importlib.util.spec_from_file_location("benchmark_peers", os.path.join(folder, "peers.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _read_back(peer, world):
    """What the engine holds of a built world, read from the engine: per body its mass and
    friction, per obstacle its friction, and the time step; pybullet's restitution too."""
    if peer == "mujoco":
        m = world.mj_model
        bodies = [int(m.geom_bodyid[g]) for g in range(m.ngeom)]
        return {
            "masses": [float(x) for x in m.body_mass[1:]],
            "inertias": np.asarray(m.body_inertia[1:]).round(12).tolist(),
            "body friction": [float(m.geom_friction[g, 0]) for g in range(m.ngeom) if bodies[g] > 0],
            "obstacle friction": [float(m.geom_friction[g, 0]) for g in range(m.ngeom) if bodies[g] == 0],
            "solref": np.asarray(m.geom_solref).round(12).tolist(),
            "dt": float(m.opt.timestep),
        }
    import pybullet

    ids = [
        pybullet.getBodyUniqueId(k, physicsClientId=world.client) for k in range(pybullet.getNumBodies(world.client))
    ]
    info = {i: pybullet.getDynamicsInfo(i, -1, physicsClientId=world.client) for i in ids}
    static = [i for i in ids if i not in world.bodies]
    return {
        "masses": [info[i][0] for i in world.bodies],
        "inertias": [list(info[i][2]) for i in world.bodies],
        "body friction": [info[i][1] for i in world.bodies],
        "obstacle friction": [info[i][1] for i in static],
        "restitution": [info[i][5] for i in ids],
        "dt": pybullet.getPhysicsEngineParameters(physicsClientId=world.client)["fixedTimeStep"],
    }


@pytest.mark.parametrize("peer", ["pybullet", "mujoco"])
def test_the_benchmark_steps_the_world_the_comparison_steps(peer, monkeypatch, tmp_path):
    """benchmarks/peers.py and `contactlab compare --peers` give the engine the same world: the
    same bodies, masses, inertias, friction and time step as the engine reads them back, and on
    the benchmark's own pyramid every box meets the floor with the scene's μ (pybullet
    multiplies two bodies' friction: the benchmark once gave both 0.6, a contact 0.36)."""
    pytest.importorskip(peer, reason=REASON)
    from contactlab.compare.run import run_method

    bench = _benchmark(monkeypatch)
    World = peers.engine(peer).World
    built = []
    original = World.__init__

    def recording(self, *arguments, **keywords):
        original(self, *arguments, **keywords)
        built.append(_read_back(peer, self))

    monkeypatch.setattr(World, "__init__", recording)
    scene = load_scene("sliding_block", ["simulation.duration=0.02"])
    bench.run_peer(scene.model, peer, scene.duration, 1, scene.name, dt=scene.dt)
    job = {**scene.origin(["simulation.duration=0.02"]), "peer": peer, "video": None, "progress": False}
    result = run_method({**job, "trajectory": str(tmp_path / "run.h5"), "allow_divergence": False})
    assert "summary" in result and len(built) == 2
    assert built[0] == built[1]

    pyramid = bench.contactlab_pyramid(3)
    bench.run_peer(pyramid, peer, 2 * bench.DT, 1, "pyramid")
    world = built[-1]
    assert world["masses"] == pytest.approx(list(pyramid.body_mass)) and world["dt"] == pytest.approx(bench.DT)
    mu = pyramid.pair_materials(0, 0)[0]
    combine = (lambda a, b: a * b) if peer == "pybullet" else max
    for body in world["body friction"]:
        assert combine(body, world["obstacle friction"][0]) == pytest.approx(mu)  # a box on the floor
        for other in world["body friction"]:
            assert combine(body, other) == pytest.approx(mu)  # two boxes


@pytest.mark.parametrize("on_a_body", [False, True])
@pytest.mark.parametrize("degrees, slides", [(27.0, False), (35.0, True)])
def test_pybullet_slides_a_block_iff_the_slope_is_steeper_than_the_scenes_mu(degrees, slides, on_a_body):
    """A block of μ 0.4 on a surface of μ 0.9 (contactlab's contact μ = √(0.36) = 0.6, a slope of
    30.96°), the surface the floor or a 1000 kg box on it (a body: Bullet multiplies the two
    bodies' friction as it does a body's and the floor's): pybullet holds the block on a 27°
    slope, and on 35° it slides with the acceleration a = g (sin θ − μ cos θ) of μ within 3 % on
    the floor and 10 % on the box (the slope is gravity turned by θ; a product of the materials'
    own μ would be 0.36, and hold nothing steeper than 19.8°). The box's margin is pybullet's:
    the product of the two bodies' friction it reads back is 0.6 exactly (the test above), but its
    box-on-box contact holds the block as if μ were 0.61–0.66 (over bases of 1–1000 kg, 0.2–1 m
    thick), where its box-on-plane contact gives 0.588."""
    pytest.importorskip("pybullet", reason=REASON)
    theta, g, mu = np.radians(degrees), 9.81, 0.6
    b = ModelBuilder(gravity=(g * np.sin(theta), 0.0, -g * np.cos(theta)))
    b.add_material("block", friction=0.4, restitution=0.0)
    b.add_material("rough", friction=0.9, restitution=0.0)
    base = 0.0
    if on_a_body:  # μ 0.9 with the floor as well: it holds on 35° (tan 35° = 0.70)
        b.add_body("box", half_extents=(1.0, 1.0, 0.1), mass=1000.0, position=(0, 0, 0.1), material="rough")
        base = 0.2
    b.add_body("box", half_extents=(0.05, 0.05, 0.05), mass=1.0, position=(0, 0, base + 0.05), material="block")
    b.add_obstacle("plane", normal=(0, 0, 1), offset=0.0, material="rough")
    model = b.finalize()
    block = model.body_count - 1
    assert model.pair_materials(0, 1)[0] == pytest.approx(mu)
    run = peers.simulate(model, "pybullet", 1.0 / 240.0, 1.0, record_every=12)
    t, x = run.arrays["time"], run.arrays["body_position"][:, block, 0]
    if on_a_body:
        assert np.abs(run.arrays["body_position"][:, 0, 0]).max() < 1e-3  # the heavy box holds
    if slides:
        acceleration = 2.0 * np.polyfit(t, x, 2)[0]
        held = (g * np.sin(theta) - acceleration) / (g * np.cos(theta))
        assert held == pytest.approx(mu, rel=0.10 if on_a_body else 0.03)
    else:
        assert np.abs(x).max() < 1e-3


@pytest.mark.parametrize("dt", [0.001, 1.0 / 240.0])
def test_mujoco_bounces_the_ball_back_with_the_scenes_restitution(dt):
    """MuJoCo has no restitution coefficient: contactlab.peers gives it the damping ratio at
    which its own contact returns ε. The ball's first three bounces each return ε = 0.8 of the
    speed to within 12 % (MuJoCo's soft contact varies with the depth its first touching step
    reaches) and 4 % on average; the continuous spring-damper's ζ gave 0.85–0.87 at dt = 1 ms
    and flung the ball up eightfold at 1/240 s."""
    pytest.importorskip("mujoco", reason=REASON)
    scene = load_scene("bouncing_ball", [f"simulation.dt={dt!r}", "simulation.duration=2.5"])
    run = peers.simulate(scene.model, "mujoco", scene.dt, scene.duration)
    height = run.arrays["body_position"][:, 0, 2] - 0.1  # the ball's bottom
    apexes = [height[0]]
    rising = np.flatnonzero((height[1:-1] > height[:-2]) & (height[1:-1] >= height[2:])) + 1
    apexes += [height[k] for k in rising if height[k] > 0.05][:3]
    assert len(apexes) == 4
    ratios = np.sqrt(np.array(apexes[1:]) / np.array(apexes[:-1]))
    assert np.all(np.abs(ratios - 0.8) < 0.12 * 0.8), ratios
    assert abs(ratios.mean() - 0.8) < 0.04 * 0.8, ratios


@pytest.mark.parametrize("peer", ["pybullet", "mujoco"])
def test_a_wall_whose_normal_is_not_up_holds_a_ball_in_every_engine(peer):
    """Gravity along −x onto the plane x = 0 (normal +x), and along a tilted normal onto a tilted
    plane: the ball comes to rest on each, its centre one radius out along the normal (the
    translation once turned a wall's normal twice in pybullet, by its own normal and by the
    body's rotation taking z onto it: every sphere of the benchmark's boxed pile sat inside a
    wall and was thrown out, 0.74 m of overlap)."""
    pytest.importorskip(peer, reason=REASON)
    for normal in (np.array([1.0, 0.0, 0.0]), np.array([0.3, -0.4, np.sqrt(0.75)])):
        b = ModelBuilder(gravity=-9.81 * normal)
        b.add_body("sphere", radius=0.1, mass=1.0, position=0.3 * normal + np.array([0.0, 0.0, 0.05]))
        b.add_obstacle("plane", normal=normal, offset=0.0)
        model = b.finalize()
        run = peers.simulate(model, peer, 0.002, 1.0, record_every=50)
        height = run.arrays["body_position"][:, 0] @ normal
        assert height.min() > 0.09 and height[-1] == pytest.approx(0.1, abs=2e-3), (normal, height)


def test_the_benchmark_pyramids_rest_each_box_on_the_level_below(monkeypatch):
    """The benchmark's pyramids (issue 38's variants): every box of a level above the floor rests
    with its bottom face exactly on the top faces of the boxes below it — two in the 2-D
    pyramids, four in the 3-D one (over their shared corner) — and the touching variant's
    neighbours in a row touch side to side, where the plain pyramid keeps a 5 mm gap."""
    bench = _benchmark(monkeypatch)
    size = 0.1
    for name, layout in bench.PYRAMIDS.items():
        centres = bench.pyramid_layout(**layout, size=size)
        levels, square = layout["levels"], layout.get("square", False)
        assert len(centres) == sum((n * n if square else n) for n in range(1, levels + 1))
        gap = layout.get("gap", 0.005)
        for box in centres[centres[:, 2] > size]:
            below = centres[np.isclose(centres[:, 2], box[2] - size)]
            under = below[np.all(np.abs(below[:, :2] - box[:2]) < size, axis=1)]  # footprints overlapping
            assert len(under) == (4 if square else 2), name
            assert np.allclose(np.abs(under[:, :2] - box[:2])[:, 0], (size + gap) / 2)
        floor = centres[np.isclose(centres[:, 2], size / 2)]
        row = floor[np.isclose(floor[:, 1], floor[0, 1])]
        assert np.allclose(np.diff(np.sort(row[:, 0])), size + gap), name  # side by side: touching if gap 0


def test_pybullet_loads_without_its_build_banner():
    # issue 59: "pybullet build time: …" on standard error before every command's own line
    pytest.importorskip("pybullet", reason=REASON)
    loaded = subprocess.run(
        [sys.executable, "-c", "import contactlab.peers.pybullet"], capture_output=True, text=True, timeout=120
    )
    assert loaded.returncode == 0 and loaded.stderr == "" and loaded.stdout == "", loaded.stderr


def _pinned_sheet():
    """A 5 × 4 sheet (0.4 × 0.3 m, 40 g) tilted off the axes, its two top corners pinned, the rest
    moving, over a floor: a small cloth of every kind of vertex."""
    b = ModelBuilder()
    b.add_material("cotton", friction=0.4, restitution=0.0)
    b.add_cloth(
        size=(0.4, 0.3),
        resolution=(5, 4),
        position=(0.1, -0.2, 0.8),
        orientation=TILTED,
        velocity=(0.3, 0.0, -0.2),
        mass=0.04,
        stretch_stiffness=800.0,
        shear_stiffness=80.0,
        bend_stiffness=1.0,
        damping=0.01,
        thickness=0.004,
        pinned="top_corners",
        material="cotton",
    )
    b.add_obstacle("plane", normal=(0, 0, 1), offset=0.0, material="cotton")
    return b.finalize()


@pytest.mark.parametrize("scene", ["cloth_drape", "pinned"])
def test_a_cloth_is_a_mujoco_flex_vertex_for_vertex(scene):
    """Issue 57: each cloth vertex is a flex vertex in the model's particle order, with its mass,
    initial position and velocity; a pinned vertex is the world's; the flex's triangles are the
    cloth's and its radius the thickness; the state read back (vectorised from qpos) is what
    MuJoCo's own flexvert_xpos says after its kinematics."""
    pytest.importorskip("mujoco", reason=REASON)
    import mujoco

    from contactlab.peers import mujoco as peer

    model = load_scene("cloth_drape").model if scene == "cloth_drape" else _pinned_sheet()
    assert peers.gaps(model, "mujoco") == []
    world = peer.World(model, 1.0 / 120.0)
    m, d = world.mj_model, world.data
    assert (
        m.nflex == 1 and m.nflexvert == model.particle_count and m.opt.integrator == mujoco.mjtIntegrator.mjINT_DISCRETE
    )
    np.testing.assert_array_equal(m.flex_elem.reshape(-1, 3), model.triangles)
    assert m.flex_radius[0] == pytest.approx(float(model.particle_radius[0]))
    vertex_body = m.flex_vertbodyid
    pinned = np.asarray(model.particle_pinned)
    assert np.all((vertex_body == 0) == pinned)  # the pinned vertices (none on the drape) are the world's
    np.testing.assert_allclose(m.body_mass[vertex_body[~pinned]], model.particle_mass[~pinned], rtol=1e-12)
    assert m.body_mass[1:].sum() == pytest.approx(model.particle_mass[~pinned].sum())
    np.testing.assert_allclose(d.flexvert_xpos, model.initial.particle_position, atol=1e-12)
    start = world.state()
    np.testing.assert_allclose(start.particle_position, model.initial.particle_position, atol=1e-12)
    np.testing.assert_allclose(start.particle_velocity, model.initial.particle_velocity, atol=1e-12)
    for _ in range(5):
        world.step()
    after = world.state()
    mujoco.mj_kinematics(m, d)
    mujoco.mj_flex(m, d)
    np.testing.assert_allclose(after.particle_position, d.flexvert_xpos, atol=1e-12)
    assert np.abs(after.particle_position[pinned] - model.initial.particle_position[pinned]).max(initial=0.0) == 0.0
    assert not after.particle_velocity[pinned].any()
    assert np.abs(after.particle_position - model.initial.particle_position).max() > 1e-4  # it moved


def test_mujoco_s_membrane_stores_the_cloth_springs_energy_under_a_uniform_stretch():
    """The membrane given to MuJoCo (translate.membrane: the isotropic one closest to the springs)
    stores exactly the springs' energy Σ ½ k (l − L)² under a uniform dilation of the sheet by
    ε = 1e-4, as MuJoCo computes it: the work −½ f·u of its elastic forces f over the
    displacement u, to 1e-3 (the Green strain's quadratic part adds O(ε)). Off the dilation the
    lattice's anisotropy is averaged: a shear stores other energy than the springs do."""
    pytest.importorskip("mujoco", reason=REASON)
    import mujoco

    from contactlab.dynamics.cloth import spring_energy
    from contactlab.peers import mujoco as peer

    model = load_scene("cloth_drape").model
    world = peer.World(model, 1.0 / 120.0)
    m, d = world.mj_model, world.data
    start = model.initial.particle_position
    centre = start.mean(axis=0)
    epsilon = 1e-4
    for strain, same in (((epsilon, 0.0), True), ((0.0, epsilon), False)):  # dilation, then shear
        u = np.zeros_like(start)
        u[:, 0] = strain[0] * (start[:, 0] - centre[0]) + 2 * strain[1] * (start[:, 1] - centre[1])
        u[:, 1] = strain[0] * (start[:, 1] - centre[1])
        d.qpos[:] = u.ravel()
        mujoco.mj_forward(m, d)
        stored = -0.5 * float(d.qfrc_spring @ d.qpos)
        springs = spring_energy(model, start + u)
        if same:
            assert stored == pytest.approx(springs, rel=1e-3)
        else:
            assert abs(stored / springs - 1.0) > 0.5
        assert world.cloth_energy(world.state()) == pytest.approx(stored, rel=1e-3)
    # the energy the row records is the flex's: its change along any displacement δ is the work of
    # MuJoCo's elastic forces, −f·δ, at a state far from flat (central differences, to 1e-4)
    rng = np.random.default_rng(57)
    bent = 0.01 * rng.standard_normal(start.shape)
    bent[:, 2] += 0.3 * (start[:, 0] - centre[0]) ** 2  # a curved sheet, stretched and crumpled
    d.qpos[:] = bent.ravel()
    mujoco.mj_forward(m, d)
    force = np.array(d.qfrc_spring).reshape(-1, 3)
    delta, h = rng.standard_normal(start.shape), 1e-7
    energy = world.flexes.energy
    slope = (energy(start + bent + h * delta) - energy(start + bent - h * delta)) / (2 * h)
    assert slope == pytest.approx(-float(np.sum(force * delta)), rel=1e-4)


def test_mujoco_drops_the_sheet_in_free_fall_until_it_touches():
    """cloth_drape's sheet falls 0.3 m before it meets the sphere (at t = √(2 · 0.295 / g) =
    0.245 s): over the first 0.2 s every vertex of MuJoCo's flex falls as z0 − g t²/2. MuJoCo's
    discrete integrator steps v += h a then x += h v (semi-implicit Euler), which lags the
    closed form by exactly g h t / 2; a uniform fall strains nothing, so the membrane adds no
    force and the lag is the whole difference (to 1e-9 m). The velocity is −g t exactly."""
    pytest.importorskip("mujoco", reason=REASON)
    run = peers.run_scene("cloth_drape", "mujoco", duration=0.2)
    g, h = 9.81, load_scene("cloth_drape").dt
    t = np.asarray(run.arrays["time"])[:, None]
    z = np.asarray(run.arrays["particle_position"])[:, :, 2]
    z0 = run.model.initial.particle_position[:, 2]
    closed = z0 - 0.5 * g * t**2
    assert np.abs(z - closed).max() <= g * h * t.max() / 2 + 1e-9
    np.testing.assert_allclose(z - closed, np.broadcast_to(-g * h * t / 2, z.shape), atol=1e-9)
    np.testing.assert_allclose(
        np.asarray(run.arrays["particle_velocity"])[:, :, 2], np.broadcast_to(-g * t, z.shape), atol=1e-9
    )
    xy = np.asarray(run.arrays["particle_position"])[:, :, :2]
    np.testing.assert_allclose(xy, np.broadcast_to(run.model.initial.particle_position[:, :2], xy.shape), atol=1e-12)
    assert max(run.arrays["contact_count"]) == 0


def test_mujoco_drapes_the_sheet_over_the_sphere_and_it_rests_there():
    """cloth_drape for 3 s in MuJoCo: the sheet ends at rest (kinetic energy under 1 mJ, of the
    1.5 J its fall releases), its highest vertex on the sphere's top, one thickness above it,
    and no vertex deeper in the sphere than MuJoCo's soft contact lets a resting one sink: its
    default solimp (0.9 0.95 0.001) ramps the contact's impedance over the first 1 mm of
    overlap, and a vertex whose weight (and the sheet's pull) the contact holds sits within it.
    The impact is another matter: the sheet meets the sphere at 2.4 m/s, and MuJoCo's contact
    (time constant 0.02 s) lets it in by centimetres before pushing it out, which the scene's
    G1 check says (the row's verdict, not this test's)."""
    pytest.importorskip("mujoco", reason=REASON)
    scene = load_scene("cloth_drape")
    run = peers.simulate(scene.model, "mujoco", scene.dt, scene.duration, record_every=12, scene_name=scene.name)
    end = np.asarray(run.arrays["particle_position"][-1])
    radius, thickness, centre = 0.25, float(scene.model.particle_radius[0]), np.array([0.0, 0.0, 0.3])
    assert float(run.arrays["energy_kinetic"][-1]) < 1e-3
    overlap = radius + thickness - np.linalg.norm(end - centre, axis=1)
    assert overlap.max() < 1e-3
    assert end[:, 2].max() == pytest.approx(centre[2] + radius + thickness, abs=2e-3)
    assert np.abs(end[:, 2].min() - thickness) < 1e-3  # and its skirt on the floor


def test_pybullet_cannot_express_cloth_and_says_why():
    """The pybullet cloth line: not run, naming what its deformable cloth lacks; MuJoCo runs it."""
    for name in ("cloth_drape", "cloth_fold"):
        model = load_scene(name).model
        assert peers.gaps(model, "mujoco") == []
        (reason,) = peers.gaps(model, "pybullet")
        assert "cloth" in reason and "loadSoftBody" in reason and "one spring stiffness" in reason
    pytest.importorskip("pybullet", reason=REASON)
    with pytest.raises(peers.Inexpressible, match="pybullet cannot express this scene: .*loadSoftBody"):
        peers.simulate(model, "pybullet", 0.004, 0.01)


def test_compare_gives_mujoco_s_cloth_a_row_with_the_scene_s_verdicts(tmp_path):
    """compare cloth_fold --peers mujoco,pybullet: MuJoCo's row is a run (steps/s, its contacts and
    iterations) whose expectations are the scene's checks on its trajectory; pybullet's row is
    the honest not-run line."""
    pytest.importorskip("mujoco", reason=REASON)
    pytest.importorskip("pybullet", reason=REASON)
    overrides = ["simulation.duration=0.3"]
    result = compare(
        "cloth_fold",
        ["projection"],
        str(tmp_path / "fold"),
        overrides=overrides,
        video=False,
        peers=["mujoco", "pybullet"],
    )
    rows = {row["method"]: row for row in result.rows}
    row = rows["mujoco"]
    assert row["status"] == "ok" and float(row["steps_per_second"]) > 0 and int(row["steps"]) == 72
    arrays, summary = load_run(str(tmp_path / "fold" / "mujoco"))
    assert summary["options"]["integrator"] == "MuJoCo Discrete" and int(row["max_contacts"]) > 0
    found = checks("cloth_fold", load_scene("cloth_fold", overrides).model, arrays)
    passed = sum(c.passed for c in found)
    assert len(found) == 2 and row["expectations"] == f"{'pass' if passed == 2 else 'FAIL'} ({passed} of 2)"
    assert rows["pybullet"]["status"].startswith("not run: pybullet cannot express this scene: ")
    assert "loadSoftBody" in rows["pybullet"]["status"]
