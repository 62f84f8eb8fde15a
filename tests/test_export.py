"""Exporters (contactlab.export): files read back with their own libraries (pxr, trimesh) hold the
trajectory's posed surfaces, cloth, particles and obstacles; failures leave nothing behind."""

import os

import numpy as np
import pytest
import trimesh
from pxr import Sdf, Usd, UsdGeom

from contactlab import InputError, ModelBuilder, export, rotations, simulate, store
from contactlab.export import frame_samples, write_mesh_sequence, write_usd
from contactlab.record import SERIES
from contactlab.scene import load_scene
from contactlab.surfaces import posed_body_vertices

FLOAT = 2e-6  # USD points and PLY vertices are 32-bit floats: ~1e-7 relative, coordinates ≲ 2 m


def _model():
    """A tumbling box, two bodies of one name, free particles between two cloths, a floor."""
    b = ModelBuilder()
    b.add_obstacle("plane", normal=(0, 0, 1), offset=0.0)
    b.add_body(
        "box",
        half_extents=(0.1, 0.2, 0.3),
        mass=1.0,
        position=(0, 0, 1.0),
        orientation=rotations.from_rotation_vector(np.array([[0.3, 0.2, 0.1]]))[0],
        angular_velocity=(4.0, -6.0, 8.0),
        name="box A",
    )
    b.add_particles([[0.5, 0.5, 0.5], [0.6, 0.5, 0.5]], radius=0.02, mass=0.1)
    b.add_body("sphere", radius=0.1, mass=1.0, position=(1.0, 0, 1.0), name="ball")
    b.add_cloth(size=(0.4, 0.4), resolution=(3, 4), position=(0, 1.0, 0.8), mass=0.1)
    b.add_body(
        "capsule",
        radius=0.05,
        half_length=0.2,
        mass=1.0,
        position=(-1.0, 0, 1.0),
        angular_velocity=(0, 5.0, 1.0),
        name="ball",
    )
    b.add_particles([[-0.5, 0.5, 0.5]], radius=0.03, mass=0.1)
    b.add_cloth(size=(0.3, 0.3), resolution=(2, 2), position=(0, -1.0, 0.8), mass=0.1)
    return b.finalize()


@pytest.fixture(scope="module")
def arrays():
    return simulate(_model(), "impulse", dt=0.01, duration=0.1).arrays  # 11 samples


def _builtin(name, duration=0.05):
    scene = load_scene(name)
    return simulate(
        scene.model, scene.method, scene.dt, duration, scene.method_options.get(scene.method, {}), scene.integrator
    ).arrays


def _expected_objects(arrays, sample):
    """{name: (world vertices, triangles or None)} in file order: bodies, cloths, obstacles, particles."""
    objects = {}
    posed = posed_body_vertices(arrays, sample)
    vs, ts = arrays["body_surface_vertex_start"], arrays["body_surface_triangle_start"]
    for b in range(len(vs) - 1):
        objects[f"body{b}"] = (posed[vs[b] : vs[b + 1]], arrays["body_surface_triangles"][ts[b] : ts[b + 1]] - vs[b])
    positions, cloth = arrays["particle_position"][sample], arrays["particle_cloth"]
    for c in range(cloth.max() + 1 if len(cloth) else 0):
        ids = np.flatnonzero(cloth == c)
        mine = arrays["triangles"][np.isin(arrays["triangles"][:, 0], ids)]
        objects[f"cloth{c}"] = (positions[ids], np.searchsorted(ids, mine))
    if len(arrays["obstacle_vertices"]):
        objects["obstacles"] = (arrays["obstacle_vertices"], arrays["obstacle_triangles"])
    if (cloth < 0).any():
        objects["particles"] = (positions[cloth < 0], None)
    return objects


def _concatenated(objects):
    vertices, faces, count = [], [], 0
    for v, t in objects.values():
        vertices.append(v)
        if t is not None:
            faces.append(t + count)
        count += len(v)
    return np.concatenate(vertices), np.concatenate(faces)


# ---------------------------------------------------------------------------------------------
# USD
# ---------------------------------------------------------------------------------------------


def _check_usd(arrays, path, every):
    stage = Usd.Stage.Open(str(path))
    T = len(arrays["time"])
    samples = frame_samples(T, every)
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert stage.GetDefaultPrim().GetPath() == Sdf.Path("/World")
    assert stage.GetStartTimeCode() == 0 and stage.GetEndTimeCode() == T - 1
    assert stage.GetTimeCodesPerSecond() == pytest.approx(1.0 / np.median(np.diff(arrays["time"])), rel=1e-9)

    vs = arrays["body_surface_vertex_start"]
    bodies = stage.GetPrimAtPath("/World/Bodies").GetChildren() if len(vs) > 1 else []
    assert len(bodies) == len(vs) - 1
    cloth = arrays["particle_cloth"]
    for s in samples:
        code = Usd.TimeCode(float(s))
        expected = _expected_objects(arrays, s)
        for b, prim in enumerate(bodies):
            mesh = UsdGeom.Mesh(prim.GetChild("surface"))
            local = np.array(mesh.GetPointsAttr().Get(code), dtype=float)
            matrix = np.array(UsdGeom.Xformable(mesh).ComputeLocalToWorldTransform(code))
            world = local @ matrix[:3, :3] + matrix[3, :3]  # USD: row vectors, p' = p M
            np.testing.assert_allclose(world, expected[f"body{b}"][0], atol=FLOAT)
            np.testing.assert_array_equal(
                np.array(mesh.GetFaceVertexIndicesAttr().Get()).reshape(-1, 3), expected[f"body{b}"][1]
            )
            assert set(mesh.GetFaceVertexCountsAttr().Get()) == {3}
        for c in range(cloth.max() + 1 if len(cloth) else 0):
            mesh = UsdGeom.Mesh(stage.GetPrimAtPath(f"/World/Cloth/cloth{c}"))
            points = np.array(mesh.GetPointsAttr().Get(code), dtype=float)
            np.testing.assert_allclose(points, expected[f"cloth{c}"][0], atol=FLOAT)
            faces = np.array(mesh.GetFaceVertexIndicesAttr().Get()).reshape(-1, 3)
            # the same triangles as the trajectory's, as particle indices
            ids = np.flatnonzero(cloth == c)
            mine = arrays["triangles"][np.isin(arrays["triangles"][:, 0], ids)]
            np.testing.assert_array_equal(ids[faces], mine)
        if (cloth < 0).any():
            particles = UsdGeom.Points(stage.GetPrimAtPath("/World/Particles"))
            np.testing.assert_allclose(
                np.array(particles.GetPointsAttr().Get(code)), arrays["particle_position"][s][cloth < 0], atol=FLOAT
            )
            np.testing.assert_allclose(
                np.array(particles.GetWidthsAttr().Get()), 2 * arrays["particle_radius"][cloth < 0], rtol=1e-6
            )
        else:
            assert not stage.GetPrimAtPath("/World/Particles")
        assert stage.GetPrimAtPath("/World").GetAttribute("contactlab:time").Get(code) == arrays["time"][s]
    if len(arrays["obstacle_vertices"]):
        obstacles = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Obstacles"))
        np.testing.assert_allclose(np.array(obstacles.GetPointsAttr().Get()), arrays["obstacle_vertices"], atol=FLOAT)
        np.testing.assert_array_equal(
            np.array(obstacles.GetFaceVertexIndicesAttr().Get()).reshape(-1, 3), arrays["obstacle_triangles"]
        )
    return stage


def test_usd_holds_the_posed_bodies_cloth_particles_and_obstacles(arrays, tmp_path):
    path = tmp_path / "run.usda"
    assert write_usd(arrays, path, every=3) == str(path)
    stage = _check_usd(arrays, path, every=3)
    assert stage.GetTimeCodesPerSecond() == 100.0  # 1/Δt, rounded off 99.99999999999999
    # prim names: valid identifiers, unique; the original name kept as display name
    names = [p.GetName() for p in stage.GetPrimAtPath("/World/Bodies").GetChildren()]
    assert names == ["box_A", "ball", "ball_1"]
    assert stage.GetPrimAtPath("/World/Bodies/box_A").GetDisplayName() == "box A"
    # time samples at the exported samples (every 3rd, and the last), time code = sample index
    box = UsdGeom.Xformable(stage.GetPrimAtPath("/World/Bodies/box_A"))
    ops = box.GetOrderedXformOps()
    assert [op.GetOpType() for op in ops] == [UsdGeom.XformOp.TypeTranslate, UsdGeom.XformOp.TypeOrient]
    assert ops[0].GetTimeSamples() == [0, 3, 6, 9, 10]
    cloth = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Cloth/cloth0"))
    assert cloth.GetPointsAttr().GetTimeSamples() == [0, 3, 6, 9, 10]
    # the box tumbles: its orientation really changes, and stored quaternions stay in one hemisphere
    quats = np.array([[q.GetReal(), *q.GetImaginary()] for q in (ops[1].Get(t) for t in [0, 3, 6, 9, 10])])
    assert np.einsum("ij,ij->i", quats[1:], quats[:-1]).min() > 0
    angle = 2 * np.arccos(min(1.0, abs(np.dot(arrays["body_orientation"][0, 0], arrays["body_orientation"][-1, 0]))))
    assert angle > 0.5
    # between two time samples the body is interpolated, still rigid (distances kept)
    mid = Usd.TimeCode(1.5)
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Bodies/box_A/surface"))
    local = np.array(mesh.GetPointsAttr().Get(), dtype=float)
    matrix = np.array(box.ComputeLocalToWorldTransform(mid))
    world = local @ matrix[:3, :3] + matrix[3, :3]
    np.testing.assert_allclose(
        np.linalg.norm(world - world[0], axis=1), np.linalg.norm(local - local[0], axis=1), atol=1e-6
    )
    # box extent: the body's own frame
    np.testing.assert_allclose(np.array(mesh.GetExtentAttr().Get()), [[-0.1, -0.2, -0.3], [0.1, 0.2, 0.3]], atol=1e-7)


@pytest.mark.parametrize("suffix, magic", [(".usd", b"PXR-USDC"), (".usdc", b"PXR-USDC"), (".usda", b"#usda")])
def test_usd_format_follows_the_suffix_and_no_temporary_is_left(arrays, tmp_path, suffix, magic):
    path = tmp_path / f"run{suffix}"
    write_usd(arrays, path)
    assert path.read_bytes().startswith(magic)
    assert os.listdir(tmp_path) == [path.name]
    _check_usd(arrays, path, every=1)


@pytest.mark.parametrize("name", ["mesh_bowl", "cloth_drape"])
def test_builtin_scenes_export(name, tmp_path):
    arrays = _builtin(name)
    write_usd(arrays, tmp_path / "run.usd", every=2)
    _check_usd(arrays, tmp_path / "run.usd", every=2)
    paths = write_mesh_sequence(arrays, tmp_path / "frames", every=2)
    _check_obj(arrays, paths, every=2)


def test_usd_failure_keeps_the_old_file_and_leaves_no_temporary(arrays, tmp_path, monkeypatch):
    path = tmp_path / "run.usd"
    path.write_bytes(b"old")

    def broken(layer, temporary, *args, **kwargs):
        with open(temporary, "wb") as stream:
            stream.write(b"half")
        raise OSError("disk full")

    monkeypatch.setattr(Sdf.Layer, "Export", broken)
    with pytest.raises(OSError, match="disk full"):
        write_usd(arrays, path)
    assert path.read_bytes() == b"old"
    assert os.listdir(tmp_path) == ["run.usd"]


# ---------------------------------------------------------------------------------------------
# OBJ and PLY sequences
# ---------------------------------------------------------------------------------------------


def _check_obj(arrays, paths, every):
    samples = frame_samples(len(arrays["time"]), every)
    assert [os.path.basename(p) for p in paths] == [f"frame_{j:05d}.obj" for j in range(len(samples))]
    for path, s in zip(paths, samples):
        expected = _expected_objects(arrays, s)
        vertices, faces = _concatenated(expected)
        # every vertex in file order, the particles' loose vertices included
        mesh = trimesh.load(path, force="mesh", process=False, maintain_order=True)
        np.testing.assert_allclose(mesh.vertices, vertices, atol=1e-8)
        np.testing.assert_array_equal(mesh.faces, faces)
        # named objects keep apart (trimesh leaves out the point-only "particles")
        scene = trimesh.load_scene(path, process=False, split_objects=True, group_material=False)
        meshes = {k: v for k, v in expected.items() if v[1] is not None}
        assert len(scene.geometry) == len(meshes)
        with open(path) as stream:
            names = [line.split(None, 1)[1].strip() for line in stream if line.startswith("o ")]
        assert names[len(arrays["body_names"]) :] == [k for k in expected if not k.startswith("body")]


def test_obj_sequence_holds_every_object_of_every_exported_sample(arrays, tmp_path):
    paths = write_mesh_sequence(arrays, tmp_path / "frames", file_format="obj", every=3)
    assert len(paths) == 5  # samples 0, 3, 6, 9 and the last, 10
    _check_obj(arrays, paths, every=3)
    scene = trimesh.load_scene(paths[-1], process=False, split_objects=True, group_material=False)
    assert set(scene.geometry) == {"box_A", "ball", "ball_1", "cloth0", "cloth1", "obstacles"}
    expected = _expected_objects(arrays, 10)
    np.testing.assert_allclose(scene.geometry["box_A"].vertices, expected["body0"][0], atol=1e-8)
    np.testing.assert_allclose(scene.geometry["ball_1"].vertices, expected["body2"][0], atol=1e-8)
    with open(paths[-1]) as stream:
        text = stream.read()
    assert "o particles\nv 0." in text and "sample 10, t = 0.1 s" in text.splitlines()[0]


def test_ply_sequence_is_one_mesh_per_frame(arrays, tmp_path):
    paths = write_mesh_sequence(arrays, tmp_path / "frames", file_format="ply", every=4)
    samples = frame_samples(len(arrays["time"]), 4)
    assert list(samples) == [0, 4, 8, 10]
    assert [os.path.basename(p) for p in paths] == [f"frame_{j:05d}.ply" for j in range(4)]
    for path, s in zip(paths, samples):
        vertices, faces = _concatenated(_expected_objects(arrays, s))
        mesh = trimesh.load(path, process=False)
        np.testing.assert_allclose(mesh.vertices, vertices, atol=FLOAT)
        np.testing.assert_array_equal(mesh.faces, faces)


def test_a_trajectory_file_exports_like_its_arrays(arrays, tmp_path):
    loaded = store.open_trajectory(store.write(tmp_path / "trajectory.h5", arrays, series=SERIES))
    paths = write_mesh_sequence(loaded, tmp_path / "frames", every=5)
    write_usd(loaded, tmp_path / "run.usd", every=5)
    _check_obj(arrays, paths, every=5)
    _check_usd(arrays, tmp_path / "run.usd", every=5)


def test_a_shorter_export_replaces_the_whole_sequence(arrays, tmp_path):
    directory = tmp_path / "frames"
    write_mesh_sequence(arrays, directory, every=1)
    (directory / "notes.txt").write_text("mine")
    write_mesh_sequence(arrays, directory, file_format="ply", every=1)
    paths = write_mesh_sequence(arrays, directory, every=5)
    names = sorted(os.listdir(directory))
    assert names == sorted(
        [os.path.basename(p) for p in paths] + [f"frame_{j:05d}.ply" for j in range(11)] + ["notes.txt"]
    )


@pytest.mark.parametrize("file_format", ["obj", "ply"])
@pytest.mark.parametrize("existing", [False, True])
def test_a_failing_frame_leaves_no_frames(arrays, tmp_path, monkeypatch, file_format, existing):
    directory = tmp_path / "frames" if existing else tmp_path / "new" / "frames"  # parents made go too
    if existing:
        directory.mkdir()
        (directory / "notes.txt").write_text("mine")
    calls = []

    def failing(write):
        def wrapped(*args):
            calls.append(1)
            path = args[1] if file_format == "obj" else args[0]  # (self, path, …) or (path, …)
            if len(calls) == 3:  # the third frame breaks half-way
                with open(path, "w") as stream:
                    stream.write("v 1 2")
                raise RuntimeError("broken writer")
            return write(*args)

        return wrapped

    if file_format == "obj":
        monkeypatch.setattr(export._ObjWriter, "write", failing(export._ObjWriter.write))
    else:
        monkeypatch.setattr(export, "_write_ply", failing(export._write_ply))
    with pytest.raises(RuntimeError, match="broken writer"):
        write_mesh_sequence(arrays, directory, file_format=file_format)
    assert len(calls) == 3
    if existing:
        assert os.listdir(directory) == ["notes.txt"]  # no frame, no .partial- file
    else:
        assert not directory.exists()  # the folders it created are gone
    assert os.listdir(tmp_path) == (["frames"] if existing else [])


# ---------------------------------------------------------------------------------------------
# Arguments
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "kwargs, field",
    [
        (dict(file_format="stl"), "file_format"),
        (dict(file_format=None), "file_format"),
        (dict(every=0), "every"),
        (dict(every=1.5), "every"),
        (dict(every=True), "every"),
    ],
)
def test_bad_mesh_arguments_name_the_field(arrays, tmp_path, kwargs, field):
    with pytest.raises(InputError) as error:
        write_mesh_sequence(arrays, tmp_path / "frames", **kwargs)
    assert error.value.field == field
    assert not (tmp_path / "frames").exists()


@pytest.mark.parametrize(
    "name, kwargs, field",
    [
        ("run.abc", {}, "path"),
        ("run", {}, "path"),
        ("run.usd", dict(every=0), "every"),
        ("run.usd", dict(every="2"), "every"),
    ],
)
def test_bad_usd_arguments_name_the_field(arrays, tmp_path, name, kwargs, field):
    with pytest.raises(InputError) as error:
        write_usd(arrays, tmp_path / name, **kwargs)
    assert error.value.field == field
    assert os.listdir(tmp_path) == []


def test_a_trajectory_without_surfaces_is_an_input_error(arrays, tmp_path):
    old = {k: v for k, v in arrays.items() if not k.startswith("body_surface")}
    for write, target in ((write_usd, tmp_path / "run.usd"), (write_mesh_sequence, tmp_path / "frames")):
        with pytest.raises(InputError) as error:
            write(old, target)
        assert error.value.field == "arrays" and "body_surface_vertices" in str(error.value)
    assert os.listdir(tmp_path) == []


def test_frame_samples_always_end_with_the_last():
    assert list(frame_samples(11, 1)) == list(range(11))
    assert list(frame_samples(11, 5)) == [0, 5, 10]
    assert list(frame_samples(12, 5)) == [0, 5, 10, 11]
    assert list(frame_samples(1, 7)) == [0]
    assert list(frame_samples(3, 100)) == [0, 2]
