"""Scene files: built-in scenes, schema errors with field paths, --set overrides, arrays."""

from pathlib import Path

import numpy as np
import pytest

from contactlab import rotations
from contactlab.errors import InputError
from contactlab.scene import Scene, builtin_scenes, load_scene, schema
from contactlab.simulation import simulate

BUILTIN = [
    "bouncing_ball",
    "box_pushed",
    "box_pyramid",
    "box_stack",
    "capsule_pile",
    "card_house",
    "cloth_drape",
    "cloth_fold",
    "cloth_table",
    "domino_chain",
    "incline",
    "mass_ratio_stack",
    "mesh_bowl",
    "newtons_cradle",
    "particles_bowl",
    "particles_box",
    "rod_impact",
    "rolling_sphere",
    "sliding_block",
    "sphere_pile",
]
CLOTH_AND_POURING = {
    "cloth_drape": "backward_euler",
    "cloth_fold": "backward_euler",
    "cloth_table": "backward_euler",
    "particles_bowl": "symplectic_euler",
}
DOCS = Path(__file__).resolve().parents[1] / "docs" / "scene-format.md"

# A small valid scene; the error cases below change one thing in it.
BASE = """\
description = "a test scene"
[simulation]
dt = 0.01
duration = 0.1
[[materials]]
name = "wood"
friction = 0.5
restitution = 0.2
[[bodies]]
name = "ball"
shape = "sphere"
radius = 0.1
mass = 1.0
position = [0.0, 0.0, 0.5]
material = "wood"
[[bodies]]
shape = "box"
half_extents = [0.1, 0.1, 0.1]
density = 1000.0
position = [1.0, 0.0, 0.5]
[[particles]]
position = [[0.0, 1.0, 1.0], [0.1, 1.0, 1.0]]
velocity = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]
mass = 0.01
radius = 0.01
[[obstacles]]
shape = "plane"
normal = [0.0, 0.0, 1.0]
offset = 0.0
material = "wood"
"""


def write(tmp_path, text, name="scene.toml"):
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def load_error(tmp_path, text=BASE, overrides=(), source=None):
    with pytest.raises(InputError) as info:
        load_scene(source if source is not None else write(tmp_path, text), overrides)
    error = info.value
    assert "\n" not in str(error), str(error)
    return error


# -- built-in scenes -----------------------------------------------------------------------------
def test_builtin_scenes_are_listed_sorted_with_one_line_descriptions():
    listed = builtin_scenes()
    assert [name for name, _ in listed] == BUILTIN
    for name, description in listed:
        assert description and "\n" not in description, name


@pytest.mark.parametrize("name", BUILTIN)
def test_builtin_scene_loads_and_runs(name):
    scene = load_scene(name)
    assert isinstance(scene, Scene)
    assert scene.name == name and scene.source == f"builtin:{name}"
    assert scene.description == dict(builtin_scenes())[name]
    if name in CLOTH_AND_POURING:  # the scenes of the projection method, cloth implicit
        assert scene.method == "projection" and scene.integrator == CLOTH_AND_POURING[name]
    else:
        assert scene.method == "impulse" and scene.integrator == "symplectic_euler"
    assert scene.dt > 0 and scene.duration > scene.dt
    run = simulate(
        scene.model, scene.method, scene.dt, 10 * scene.dt, scene.method_options.get(scene.method), scene.integrator
    )
    assert run.summary["steps"] == 10
    assert run.state.is_finite()


def test_builtin_scene_contents():
    ball = load_scene("bouncing_ball")
    assert ball.dt == 0.001 and ball.duration == 4.0
    assert ball.model.body_params[0, 0] == 0.1 and ball.model.body_mass[0] == 1.0
    assert ball.model.initial.body_position[0, 2] - 0.1 == pytest.approx(1.0)
    assert ball.model.material_restitution[ball.model.body_material[0]] == 0.8

    pile = load_scene("sphere_pile")
    assert pile.model.body_count == 324
    assert pile.dt == pytest.approx(1 / 240)
    position = pile.model.initial.body_position
    assert (np.abs(position[:, :2]) + 0.05 <= 0.5).all() and (position[:, 2] - 0.05 > 0).all()
    gaps = np.linalg.norm(position[:, None] - position[None], axis=-1) + np.eye(len(position))
    assert gaps.min() >= 0.1

    particles = load_scene("particles_box")
    assert particles.model.particle_count == 200
    assert (particles.model.particle_radius == 0.01).all()
    assert (np.abs(particles.model.initial.particle_position[:, :2]) < 0.49).all()

    cradle = load_scene("newtons_cradle")
    x = cradle.model.initial.body_position[:, 0]
    assert np.allclose(np.diff(x[1:]), 0.1)  # the four resting balls touch
    assert cradle.model.initial.body_velocity[0, 0] == 1.0
    assert (cradle.model.gravity == 0).all() and cradle.model.obstacle_count == 0


def test_incline_box_rests_on_the_tilted_plane():
    model = load_scene("incline").model
    theta = np.radians(20)
    normal = model.obstacle_params[0, :3]
    assert np.allclose(normal, [-np.sin(theta), 0, np.cos(theta)])
    R = rotations.to_matrix(model.initial.body_orientation)[0]
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * 0.05
    heights = (model.initial.body_position[0] + corners @ R.T) @ normal - model.obstacle_params[0, 3]
    assert np.allclose(np.sort(heights)[:4], 0.0, atol=1e-12)  # bottom face on the plane
    assert np.allclose(np.sort(heights)[4:], 0.1, atol=1e-12)
    assert np.tan(theta) < model.material_friction[model.body_material[0]]


def test_rod_impact_strikes_with_one_corner_half_a_metre_up():
    model = load_scene("rod_impact").model
    R = rotations.to_matrix(model.initial.body_orientation)[0]
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * [0.5, 0.025, 0.025]
    points = model.initial.body_position[0] + corners @ R.T
    lowest = np.argmin(points[:, 2])
    assert points[lowest, 2] == pytest.approx(0.5)
    assert np.sort(points[:, 2])[1] > 0.52  # one corner strikes first
    assert abs(points[lowest, 1]) < 1e-12  # in the x-z plane: a planar impact


# -- a scene from a file ----------------------------------------------------------------------------
def test_file_scene_defaults_and_values(tmp_path):
    scene = load_scene(write(tmp_path, BASE, "my_scene.toml"))
    assert scene.name == "my_scene" and scene.description == "a test scene"
    assert (scene.dt, scene.duration, scene.method, scene.integrator) == (0.01, 0.1, "impulse", "symplectic_euler")
    model = scene.model
    assert model.body_count == 2 and model.particle_count == 2 and model.obstacle_count == 1
    assert model.body_names[0] == "ball"
    assert model.body_mass[1] == pytest.approx(1000.0 * 0.2**3)
    assert model.material_names[model.body_material[1]] == "default"  # no material: the default one
    assert model.material_friction[model.body_material[0]] == 0.5
    assert np.allclose(model.gravity, [0, 0, -9.81])
    assert load_scene(str(write(tmp_path, BASE, "other.toml"))).name == "other"


def test_empty_file_gives_all_defaults(tmp_path):
    scene = load_scene(write(tmp_path, ""))
    assert (scene.dt, scene.duration, scene.method, scene.integrator) == (0.004, 2.0, "impulse", "symplectic_euler")
    assert scene.method_options == {} and scene.description == ""
    assert scene.model.body_count == 0


def test_method_tables_are_kept_and_validated(tmp_path):
    text = BASE + "[method.impulse]\niterations = 5\n[method.penalty]\nstiffness = 1e4\n"
    scene = load_scene(write(tmp_path, text))
    assert scene.method_options == {"impulse": {"iterations": 5}, "penalty": {"stiffness": 1e4}}
    run = simulate(scene.model, scene.method, scene.dt, 2 * scene.dt, scene.method_options.get(scene.method))
    assert run.summary["steps"] == 2


# -- errors: every one an InputError naming the field, on one line ------------------------------------
def replace(old, new):
    assert old in BASE, old
    return BASE.replace(old, new, 1)


ERROR_CASES = [
    # (id, scene text, expected field, words the message must contain)
    ("toml syntax", BASE + "oops = \n", f"line {BASE.count(chr(10)) + 1}, column 8", "not valid TOML"),
    ("toml syntax at end", BASE + "x = [1,\n", "end of file", "not valid TOML"),
    ("not a document of tables", "simulation = 3\n", "simulation", "expected a table"),
    ("unknown top key", "bodys = []\n" + BASE, "bodys", "did you mean 'bodies'"),
    ("unknown simulation key", replace("dt = 0.01", "dtt = 0.01"), "simulation.dtt", "did you mean 'dt'"),
    ("unknown body key", replace("mass = 1.0", "mas = 1.0"), "bodies[0].mas", "did you mean 'mass'"),
    (
        "unknown material key",
        replace("friction = 0.5", "frction = 0.5"),
        "materials[0].frction",
        "did you mean 'friction'",
    ),
    ("unknown particles key", replace("radius = 0.01", "radios = 0.01"), "particles[0].radios", "did you mean"),
    ("unknown obstacle key", replace("offset = 0.0", "ofset = 0.0"), "obstacles[0].ofset", "did you mean 'offset'"),
    ("unknown key without match", "zzz = 1\n" + BASE, "zzz", "expected one of"),
    ("string for number", replace("mass = 1.0", 'mass = "1"'), "bodies[0].mass", "expected a number (kg), found '1'"),
    ("bool for number", replace("dt = 0.01", "dt = true"), "simulation.dt", "found true"),
    ("list for number", replace("radius = 0.1", "radius = [0.1]"), "bodies[0].radius", "expected a number"),
    (
        "short list",
        replace("position = [0.0, 0.0, 0.5]", "position = [0.0, 0.5]"),
        "bodies[0].position",
        "expected a list of 3 numbers (m), found [0.0, 0.5]",
    ),
    (
        "string in list",
        replace("position = [0.0, 0.0, 0.5]", 'position = [0.0, "a", 0.5]'),
        "bodies[0].position",
        "expected a list of 3 numbers",
    ),
    ("nan", replace("mass = 1.0", "mass = nan"), "bodies[0].mass", "finite"),
    (
        "inf in vector",
        replace("position = [0.0, 0.0, 0.5]", "position = [inf, 0.0, 0.5]"),
        "bodies[0].position",
        "finite",
    ),
    ("negative mass", replace("mass = 1.0", "mass = -1"), "bodies[0].mass", "greater than 0"),
    ("zero radius", replace("radius = 0.1", "radius = 0.0"), "bodies[0].radius", "greater than 0"),
    (
        "negative half extents",
        replace("half_extents = [0.1, 0.1, 0.1]", "half_extents = [0.1, -0.1, 0.1]"),
        "bodies[1].half_extents",
        "positive",
    ),
    ("zero dt", replace("dt = 0.01", "dt = 0"), "simulation.dt", "greater than 0 (s), found 0"),
    ("negative duration", replace("duration = 0.1", "duration = -1.0"), "simulation.duration", "greater than 0"),
    ("mass and density", replace("mass = 1.0", "mass = 1.0\ndensity = 10.0"), "bodies[0].mass", "exactly one"),
    ("neither mass nor density", replace("mass = 1.0", ""), "bodies[0].mass", "exactly one"),
    ("negative friction", replace("friction = 0.5", "friction = -0.1"), "materials[0].friction", "at least 0"),
    ("restitution above 1", replace("restitution = 0.2", "restitution = 1.5"), "materials[0].restitution", "at most 1"),
    ("duplicate material", BASE + '[[materials]]\nname = "wood"\n', "materials[1].name", "twice"),
    ("unknown material", replace('material = "wood"', 'material = "wod"'), "bodies[0].material", "unknown material"),
    ("missing shape", replace('shape = "sphere"', ""), "bodies[0].shape", "missing required key"),
    ("unknown shape", replace('shape = "sphere"', 'shape = "spere"'), "bodies[0].shape", "did you mean 'sphere'"),
    ("planned body shape", replace('shape = "sphere"', 'shape = "mesh"'), "bodies[0].shape", "not supported"),
    (
        "key of another shape",
        replace("half_extents = [0.1, 0.1, 0.1]", "radius = 0.1"),
        "bodies[1].radius",
        "a box takes no radius",
    ),
    ("plane with position", BASE + "position = [0.0, 0.0, 0.0]\n", "obstacles[0].position", "a plane takes no"),
    (
        "unknown method",
        replace("duration = 0.1", 'duration = 0.1\nmethod = "impuls"'),
        "simulation.method",
        "did you mean 'impulse'",
    ),
    ("unknown method table", BASE + "[method.impuls]\niterations = 3\n", "method.impuls", "did you mean 'impulse'"),
    ("method table not a table", BASE + "[method]\nimpulse = 3\n", "method.impulse", "expected a table"),
    (
        "unknown method option",
        BASE + "[method.impulse]\niteratons = 3\n",
        "method.impulse.iteratons",
        "did you mean 'iterations'",
    ),
    ("bad method option", BASE + "[method.impulse]\niterations = 0\n", "method.impulse.iterations", "≥ 1"),
    (
        "unknown integrator",
        replace("duration = 0.1", 'duration = 0.1\nintegrator = "verlet"'),
        "simulation.integrator",
        "unknown integrator",
    ),
    (
        "zero quaternion",
        replace("mass = 1.0", "mass = 1.0\norientation = [0, 0, 0, 0]"),
        "bodies[0].orientation",
        "zero quaternion",
    ),
    (
        "quaternion of 3",
        replace("mass = 1.0", "mass = 1.0\norientation = [1, 0, 0]"),
        "bodies[0].orientation",
        "expected a list of 4 numbers",
    ),
    (
        "particle velocity count",
        replace("velocity = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]", "velocity = [[0.0, 0.0, 0.0]]"),
        "particles[0].velocity",
        "expected 2 velocities, one per position, found 1",
    ),
    (
        "particle point of 2",
        replace("[0.1, 1.0, 1.0]]", "[0.1, 1.0]]"),
        "particles[0].position[1]",
        "expected a list of 3 numbers",
    ),
    (
        "particle position empty",
        replace("position = [[0.0, 1.0, 1.0], [0.1, 1.0, 1.0]]", "position = []"),
        "particles[0].position",
        "non-empty list",
    ),
    ("particle negative mass", replace("mass = 0.01", "mass = -0.01"), "particles[0].mass", "greater than 0"),
    (
        "plane normal zero",
        replace("normal = [0.0, 0.0, 1.0]", "normal = [0.0, 0.0, 0.0]"),
        "obstacles[0].normal",
        "must not be zero",
    ),
    ("plane without normal", replace("normal = [0.0, 0.0, 1.0]", ""), "obstacles[0].normal", "needs a normal"),
    ("bodies a number", "bodies = 3\n", "bodies", "expected an array of tables written [[bodies]], found 3"),
    ("bodies a single table", '[bodies]\nshape = "sphere"\n', "bodies", "written [[bodies]], found a table"),
    (
        "multi-line description",
        replace('description = "a test scene"', 'description = """a\nb"""'),
        "description",
        "single line",
    ),
    (
        "gravity of 2",
        replace("duration = 0.1", "duration = 0.1\ngravity = [0, -9.81]"),
        "simulation.gravity",
        "expected a list of 3 numbers (m/s^2)",
    ),
    (
        "array count zero",
        replace("mass = 1.0", "mass = 1.0\narray = {count = [0, 1, 1], spacing = [1, 1, 1]}"),
        "bodies[0].array.count",
        "whole numbers ≥ 1",
    ),
    (
        "array count float",
        replace("mass = 1.0", "mass = 1.0\narray = {count = [2.0, 1, 1], spacing = [1, 1, 1]}"),
        "bodies[0].array.count",
        "whole numbers",
    ),
    (
        "array without spacing",
        replace("mass = 1.0", "mass = 1.0\narray = {count = [2, 1, 1]}"),
        "bodies[0].array.spacing",
        "missing required key",
    ),
    (
        "array zero spacing",
        replace("mass = 1.0", "mass = 1.0\narray = {count = [2, 1, 1], spacing = [0, 1, 1]}"),
        "bodies[0].array.spacing",
        "non-zero spacing along x",
    ),
    (
        "array unknown key",
        replace("mass = 1.0", "mass = 1.0\narray = {cout = [2, 1, 1], spacing = [1, 1, 1]}"),
        "bodies[0].array.cout",
        "did you mean 'count'",
    ),
    (
        "array too large",
        replace("mass = 1.0", "mass = 1.0\narray = {count = [1000, 1000, 1000], spacing = [1, 1, 1]}"),
        "bodies[0].array.count",
        "at most",
    ),
]


@pytest.mark.parametrize(
    "text, field, words", [case[1:] for case in ERROR_CASES], ids=[case[0] for case in ERROR_CASES]
)
def test_scene_error(tmp_path, text, field, words):
    error = load_error(tmp_path, text)
    assert error.field == field, str(error)
    assert str(error).startswith(field + ": ")
    assert words in error.message, str(error)


def test_missing_file(tmp_path):
    error = load_error(tmp_path, source=tmp_path / "nowhere.toml")
    assert "no such file" in str(error) and "nowhere.toml" in str(error)


def test_directory_instead_of_file(tmp_path):
    (tmp_path / "dir.toml").mkdir()
    assert "directory" in str(load_error(tmp_path, source=tmp_path / "dir.toml"))


def test_not_utf8(tmp_path):
    path = tmp_path / "latin.toml"
    path.write_bytes(b'description = "caf\xe9"\n')
    assert "UTF-8" in str(load_error(tmp_path, source=path))


def test_unknown_builtin_name_suggests_close_ones():
    with pytest.raises(InputError) as info:
        load_scene("bouncing_bal")
    message = str(info.value)
    assert "'bouncing_ball'" in message and "contactlab scenes" in message and "\n" not in message


def test_unknown_builtin_without_close_match():
    with pytest.raises(InputError, match="contactlab scenes"):
        load_scene("zzzzzz")


# -- --set overrides -------------------------------------------------------------------------------
def test_set_nested_values_indices_and_strings(tmp_path):
    path = write(tmp_path, BASE)
    scene = load_scene(
        path,
        [
            "simulation.dt=0.001",
            "bodies.0.velocity=[3, 0, 0]",
            "materials.0.friction=0.3",
            "bodies[1].position = [2.0, 0, 1]",
            "simulation.integrator=explicit_euler",
            'description="quoted text"',
            "particles.0.position.1=[5, 5, 5]",
        ],
    )
    assert scene.dt == 0.001 and scene.integrator == "explicit_euler" and scene.description == "quoted text"
    assert np.allclose(scene.model.initial.body_velocity[0], [3, 0, 0])
    assert np.allclose(scene.model.initial.body_position[1], [2, 0, 1])
    assert scene.model.material_friction[0] == 0.3
    assert np.allclose(scene.model.initial.particle_position[1], [5, 5, 5])


def test_set_creates_missing_keys_and_tables(tmp_path):
    scene = load_scene(
        write(tmp_path, ""),
        ["simulation.duration=5", "method.impulse.iterations=7", 'materials=[{name = "ice", friction = 0.0}]'],
    )
    assert scene.duration == 5.0
    assert scene.method_options == {"impulse": {"iterations": 7}}
    assert scene.model.material_names == ("ice",)
    with pytest.raises(InputError, match="exactly one"):  # a new key is validated with the rest
        load_scene("bouncing_ball", ["bodies.0.density=1000"])


def test_set_plain_string_that_is_not_toml_selects_a_method():
    for name in ("penalty", "projection", "impulse", "constraints"):
        assert load_scene("bouncing_ball", [f"simulation.method={name}"]).method == name
    with pytest.raises(InputError) as info:
        load_scene("bouncing_ball", ["simulation.method=penalties"])
    assert info.value.field == "simulation.method" and "did you mean 'penalty'" in info.value.message


def test_penalty_table_is_checked_when_loaded():
    with pytest.raises(InputError) as info:
        load_scene("bouncing_ball", ["method.penalty.stifness=1e4"])
    assert info.value.field == "method.penalty.stifness" and "did you mean 'stiffness'" in info.value.message


def test_set_new_key_is_validated():
    with pytest.raises(InputError) as info:
        load_scene("bouncing_ball", ["bodies.0.mas=2"])
    assert info.value.field == "bodies[0].mas" and "did you mean 'mass'" in info.value.message


@pytest.mark.parametrize(
    "assignment, field, words",
    [
        ("simulation.dt", "--set", "expected PATH=VALUE"),
        ("=3", "--set", "expected a path"),
        ("simulation..dt=3", "--set", "empty part"),
        ("bodies.5.mass=2", "bodies[5]", "out of range"),
        ("bodies.x.mass=2", "bodies", "is a list"),
        ("simulation.dt.value=2", "simulation.dt", "not a table"),
        ("particles.0.position=1", "particles", "there is no list particles"),
        ("bodies.0.mass=-3", "bodies[0].mass", "greater than 0"),
        ("bodies.0.position=[1, 2]", "bodies[0].position", "list of 3 numbers"),
        ("simulation.dt=fast", "simulation.dt", "found 'fast'"),
    ],
)
def test_set_errors(assignment, field, words):
    with pytest.raises(InputError) as info:
        load_scene("bouncing_ball", [assignment])
    assert info.value.field == field, str(info.value)
    assert words in info.value.message and "\n" not in str(info.value)


def test_set_index_past_end_of_points_list():
    with pytest.raises(InputError) as info:
        load_scene("particles_box", ["particles.0.position.3=[0, 0, 0]"])
    assert info.value.field == "particles[0].position[3]" and "out of range" in info.value.message


# -- array ---------------------------------------------------------------------------------------
def test_array_replicates_bodies_on_a_grid(tmp_path):
    text = replace("mass = 1.0", "mass = 1.0\narray = { count = [3, 2, 2], spacing = [0.5, 0.25, 1.0] }")
    model = load_scene(write(tmp_path, text)).model
    assert model.body_count == 12 + 1
    positions = model.initial.body_position[:12]
    expected = [[0.5 * ix, 0.25 * iy, 0.5 + 1.0 * iz] for iz in range(2) for iy in range(2) for ix in range(3)]
    assert np.allclose(positions, expected)  # x fastest, then y, then z
    assert model.body_names[:12] == tuple(f"ball_{i}" for i in range(12))
    assert (model.body_mass[:12] == 1.0).all() and (model.body_material[:12] == 0).all()
    assert model.body_names[12] == "body12"  # an unnamed body after them


def test_array_replicates_particles_with_their_velocities(tmp_path):
    text = replace("radius = 0.01", "radius = 0.01\narray = { count = [1, 1, 3], spacing = [0, 0, 0.5] }")
    text = text.replace(
        "velocity = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]", "velocity = [[1.0, 0.0, 0.0], [0.0, 2.0, 0.0]]"
    )
    model = load_scene(write(tmp_path, text)).model
    assert model.particle_count == 6
    assert np.allclose(model.initial.particle_position[:, 2], [1.0, 1.0, 1.5, 1.5, 2.0, 2.0])
    assert np.allclose(model.initial.particle_velocity[:, :2], [[1, 0], [0, 2]] * 3)


# -- the document ----------------------------------------------------------------------------------
def test_document_names_every_key_and_builtin_scene():
    text = DOCS.read_text(encoding="utf-8")
    for table, keys in schema.TABLES.items():
        for key in keys:
            assert f"`{key}`" in text, f"docs/scene-format.md does not document {table} key {key!r}"
    for name, description in builtin_scenes():
        assert f"`{name}`" in text and description in text, name
    for name in ("box_pyramid", "card_house", "domino_chain", "mass_ratio_stack", "cloth_drape", "cloth_table"):
        assert name in text


def test_document_example_loads(tmp_path):
    text = DOCS.read_text(encoding="utf-8")
    example = text.split("## A complete example", 1)[1].split("```toml\n", 1)[1].split("```", 1)[0]
    scene = load_scene(write(tmp_path, example))
    assert scene.model.body_count == 1 + 9 and scene.model.particle_count == 2
    assert scene.method_options == {"impulse": {"iterations": 20}}


def test_every_builtin_scene_is_documented():
    text = (Path(__file__).parent.parent / "docs" / "scene-format.md").read_text()
    for name, description in builtin_scenes():
        assert f"- `{name}` — {description}" in text


def test_convex_bodies_from_points_and_from_a_mesh_file(tmp_path):
    import trimesh

    trimesh.creation.box(extents=(0.2, 0.1, 0.1)).export(tmp_path / "brick.obj")
    (tmp_path / "scene.toml").write_text("""
[[bodies]]
shape = "convex"
file = "brick.obj"
scale = 2.0
density = 1000.0
position = [0.0, 0.0, 1.0]

[[bodies]]
shape = "convex"
points = [[0, 0, 0], [0.3, 0, 0], [0, 0.3, 0], [0, 0, 0.3]]
mass = 2.0
position = [1.0, 0.0, 0.0]

[[obstacles]]
shape = "convex"
points = [[-1, -1, -0.1], [1, -1, -0.1], [-1, 1, -0.1], [1, 1, -0.1], [-1, -1, 0], [1, -1, 0], [-1, 1, 0], [1, 1, 0]]
""")
    model = load_scene(str(tmp_path / "scene.toml")).model  # the file is found beside the scene
    assert model.body_mass[0] == pytest.approx(1000.0 * 0.4 * 0.2 * 0.2)
    # the hull's centre of mass is placed from the frame its points are given in
    np.testing.assert_allclose(model.state().body_position[1], [1.075, 0.075, 0.075])
    np.testing.assert_allclose(model.state().body_position[0], [0, 0, 1.0], atol=1e-12)


@pytest.mark.parametrize(
    "entry, field, words",
    [
        ("points = [[0, 0, 0], [1, 0, 0], [0, 1, 0]]", "bodies[0].points", "4"),
        ("points = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]]", "bodies[0].points", "flat"),
        ('file = "missing.obj"', "bodies[0].file", "missing.obj"),
        ('file = "broken.obj"', "bodies[0].file", "broken.obj"),
        ("points = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]\nscale = 0", "bodies[0].scale", "greater than 0"),
    ],
)
def test_convex_input_errors(tmp_path, entry, field, words):
    (tmp_path / "broken.obj").write_text("v 1 2\nf 1 2 9\ngarbage\n")
    (tmp_path / "scene.toml").write_text(f'[[bodies]]\nshape = "convex"\n{entry}\nmass = 1.0\n')
    with pytest.raises(InputError) as error:
        load_scene(str(tmp_path / "scene.toml"))
    assert error.value.field == field and words in error.value.message
    assert "\n" not in str(error.value)


@pytest.mark.parametrize("name", ["impulse", "penalty", "projection", "constraints"])
def test_every_method_option_is_documented(name):
    from dataclasses import fields

    from contactlab import methods

    text = DOCS.read_text(encoding="utf-8")
    section = text[text.index(f"### `[method.{name}]`") :]
    section = section[: section.index("\n## ")] if "\n## " in section else section
    for field in fields(methods.get(name).Options):
        assert f"| `{field.name}` |" in section, field.name


def test_scene_simulate_is_simulate_with_the_scene_s_own_arguments():
    scene = load_scene("bouncing_ball", ["simulation.duration=0.05", "simulation.method=projection"])
    by_scene = scene.simulate(record_every=2)
    by_hand = simulate(
        scene.model,
        "projection",
        scene.dt,
        0.05,
        scene.options["projection"],
        scene.integrator,
        record_every=2,
        scene_name="bouncing_ball",
    )
    assert by_scene.summary["scene"] == "bouncing_ball" and by_scene.summary["method"] == "projection"
    assert sorted(by_scene.arrays) == sorted(by_hand.arrays)
    for key in by_hand.arrays:
        np.testing.assert_array_equal(np.asarray(by_scene.arrays[key]), np.asarray(by_hand.arrays[key]))


def test_a_scene_file_with_a_byte_order_mark_reads_as_without_it(tmp_path):
    # issue 59: a scene saved with a UTF-8 byte-order mark (Notepad) was "line 1, column 1: this
    # is not valid TOML"; a byte that is not UTF-8 after the mark is still named at its offset
    text = (Path(__file__).parents[1] / "src" / "contactlab" / "scene" / "builtin" / "bouncing_ball.toml").read_bytes()
    marked = tmp_path / "marked.toml"
    marked.write_bytes(b"\xef\xbb\xbf" + text)
    plain = tmp_path / "plain.toml"
    plain.write_bytes(text)
    assert load_scene(marked).model.describe() == load_scene(plain).model.describe()
    broken = tmp_path / "broken.toml"
    broken.write_bytes(b"\xef\xbb\xbf# \xff\n")
    with pytest.raises(InputError, match="found a byte 0xff at offset 5 that is not"):
        load_scene(broken)
