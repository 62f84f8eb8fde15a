"""Exporters: a recorded run as a mesh sequence (OBJ or PLY, one file per sample) or as one
animated USD stage, for Blender, Houdini, usdview and friends (see ``docs/export.md``).

Both read only a trajectory: the dict ``simulate(...).arrays`` or a run's ``trajectory.h5``
(:func:`contactlab.store.open_trajectory`; the arrays of ``docs/trajectory.md``, surfaces from
:mod:`contactlab.surfaces`), and of it only the samples they export. What a
frame holds, in world coordinates [m], z up:

* every rigid body's surface, posed at the sample;
* every cloth's surface: its vertices (particles) at the sample and its triangles;
* the static obstacles' surfaces;
* the free particles (not cloth vertices) as points.

Files are written through :func:`contactlab.record.atomic_path`, so no file is ever left
half-written; a mesh sequence that fails part-way removes the frames it wrote.

    from contactlab.export import write_mesh_sequence, write_usd
    write_mesh_sequence(run.arrays, "out/frames", file_format="obj", every=2)
    write_usd(run.arrays, "out/run.usd")
"""

from __future__ import annotations

import os
import re
from collections.abc import Mapping
from typing import Any

import numpy as np

from . import interrupts, surfaces
from .errors import InputError
from .record import (
    DRAWN,
    atomic_path,
    checked_times,
    make_folders,
    read_trajectory,
    remove_empty,
    sample_count,
    undo_written,
)
from .trajectory import check_arrays

MESH_FORMATS = ("obj", "ply")
USD_SUFFIXES = (".usd", ".usda", ".usdc")
OBJ_DIGITS = 9  # decimals of the coordinates in OBJ text: 1 nm

_REQUIRED = (*DRAWN, "body_names")  # a picture's arrays, and the names the exported objects take


# ---------------------------------------------------------------------------------------------
# Arguments and the static decomposition of a trajectory into objects
# ---------------------------------------------------------------------------------------------


def _check_every(every):
    if isinstance(every, bool) or not isinstance(every, (int, np.integer)) or every < 1:
        raise InputError("every", f"expected a whole number ≥ 1, found {every!r}")
    return int(every)


def frame_samples(count: int, every: int = 1) -> np.ndarray:
    """Indices of the samples exported from a trajectory of ``count`` samples: every
    ``every``-th one, starting with the first and always including the last."""
    every = _check_every(every)
    samples = np.arange(0, count, min(every, max(count, 1)))  # beyond the count: the first and the last
    if count and samples[-1] != count - 1:
        samples = np.append(samples, count - 1)
    return samples


def _unique_names(names, taken=()):
    """``names`` made unique (``name``, ``name_1``, ``name_2``, …) and distinct from ``taken``."""
    used, out = set(taken), []
    for name in names:
        candidate, k = name, 0
        while candidate in used:
            k += 1
            candidate = f"{name}_{k}"
        used.add(candidate)
        out.append(candidate)
    return out


class _Parts:
    """Static layout of a trajectory's objects: which vertices and triangles each one owns."""

    def __init__(self, data):
        start = data["body_surface_vertex_start"].astype(np.int64)
        tri_start = data["body_surface_triangle_start"].astype(np.int64)
        triangles = data["body_surface_triangles"].astype(np.int64).reshape(-1, 3)
        self.body_count = len(start) - 1
        self.body_vertices = [(int(start[b]), int(start[b + 1])) for b in range(self.body_count)]
        # triangles of body b, as indices into its own vertices
        self.body_triangles = [triangles[tri_start[b] : tri_start[b + 1]] - start[b] for b in range(self.body_count)]
        self.body_local = data["body_surface_vertices"].astype(float).reshape(-1, 3)
        self.body_names = [str(name) for name in data["body_names"]]

        cloth = data["particle_cloth"].astype(np.int64)
        cloth_triangles = data["triangles"].astype(np.int64).reshape(-1, 3)
        owner = cloth[cloth_triangles[:, 0]] if len(cloth_triangles) else np.zeros(0, np.int64)
        lookup = np.full(len(cloth), -1, dtype=np.int64)
        self.cloths = []  # (cloth index, particle indices, local triangles)
        for c in range(int(cloth.max()) + 1 if len(cloth) else 0):
            ids = np.flatnonzero(cloth == c)
            if len(ids) == 0:
                continue
            lookup[ids] = np.arange(len(ids))
            self.cloths.append((c, ids, lookup[cloth_triangles[owner == c]]))
        self.free = np.flatnonzero(cloth < 0)
        self.free_radius = data["particle_radius"].astype(float)[self.free]

        self.obstacle_vertices = data["obstacle_vertices"].astype(float).reshape(-1, 3)
        self.obstacle_triangles = data["obstacle_triangles"].astype(np.int64).reshape(-1, 3)
        self.object_names = _obj_names(self)  # the bodies' names in mesh files


# ---------------------------------------------------------------------------------------------
# Mesh sequences: OBJ and PLY
# ---------------------------------------------------------------------------------------------


def _frame_objects(parts, data, sample):
    """[(name, world vertices (n,3), triangles (m,3) or None for points)] of one sample, in the
    order bodies, cloths, obstacles, particles; empty objects left out."""
    objects = []
    if parts.body_count:
        posed = surfaces.posed_body_vertices(data, sample)
        for name, (v0, v1), tri in zip(parts.object_names, parts.body_vertices, parts.body_triangles):
            objects.append((name, posed[v0:v1], tri))
    positions = data["particle_position"][sample]
    for c, ids, tri in parts.cloths:
        objects.append((f"cloth{c}", positions[ids], tri))
    if len(parts.obstacle_vertices):
        objects.append(("obstacles", parts.obstacle_vertices, parts.obstacle_triangles))
    if len(parts.free):
        objects.append(("particles", positions[parts.free], None))
    return objects


def _obj_names(parts):
    """OBJ object names: body names with white space and ``#`` replaced by ``_`` (an ``o`` line
    ends at the line's end, but some importers split at spaces; ``#`` starts a comment), unique
    and distinct from the fixed names; one per body."""
    fixed = [f"cloth{c}" for c, _, _ in parts.cloths] + ["obstacles", "particles"]
    bodies = [re.sub(r"[\s#]+", "_", name.strip()) or "body" for name in parts.body_names]
    return _unique_names(bodies, taken=fixed)


class _ObjWriter:
    """Writes OBJ frames of one static layout of objects (names, sizes, triangles).

    A tiny writer rather than ``trimesh.exchange.obj.export_obj``: that one takes a Scene, whose
    ``dump()`` copies every geometry at every frame, and formats the faces again each time;
    with 324 spheres (sphere_pile) it took 0.15 s a frame. Here the static part of the text
    (``o`` lines, faces) is formatted once into a template with a slot per coordinate, and a
    frame is one ``str.format`` call: 10× faster. The files read back with ``trimesh.load``.
    """

    def __init__(self, objects):
        pieces, count = [], 0
        for name, vertices, tri in objects:
            name = name.replace("{", "{{").replace("}", "}}")
            pieces.append(f"o {name}\n")
            pieces.append(f"v {{:.{OBJ_DIGITS}f}} {{:.{OBJ_DIGITS}f}} {{:.{OBJ_DIGITS}f}}\n" * len(vertices))
            if tri is not None:  # a point-only object (particles) is loose vertices
                pieces.append(("f {} {} {}\n" * len(tri)).format(*(tri + count + 1).ravel().tolist()))
            count += len(vertices)
        self.template = "".join(pieces)

    def write(self, path, objects, header):
        coordinates = [v for _, v, _ in objects]
        coordinates = np.concatenate(coordinates).ravel().tolist() if coordinates else []
        with open(path, "w", encoding="utf-8") as stream:
            stream.write(f"# {header}\n")
            stream.write(self.template.format(*coordinates))


def _write_ply(path, objects):
    import trimesh
    from trimesh.exchange.ply import export_ply

    # A PLY file holds one mesh: the objects are concatenated (their names are lost); the free
    # particles are vertices that no face uses.
    vertices, faces, count = [], [np.zeros((0, 3), np.int64)], 0
    for _, v, tri in objects:
        vertices.append(v)
        if tri is not None:
            faces.append(tri + count)
        count += len(v)
    vertices = np.concatenate(vertices) if vertices else np.zeros((0, 3))
    mesh = trimesh.Trimesh(vertices, np.concatenate(faces), process=False, validate=False)
    with open(path, "wb") as stream:
        stream.write(export_ply(mesh, encoding="binary", include_attributes=False))


def write_mesh_sequence(
    arrays: Mapping[str, Any], directory: str, *, file_format: str = "obj", every: int = 1
) -> list[str]:
    """One mesh file per sample (every ``every``-th sample, always including the last) into
    ``directory`` (created if needed), named frame_00000.obj (or .ply), … ; returns the paths
    in order.

    Frame j holds sample ``frame_samples(T, every)[j]`` in world coordinates [m], z up: OBJ
    files have one object per body (``o <body name>``), per cloth (``o cloth<i>``), the
    obstacles (``o obstacles``) and the free particles (``o particles``: vertices only); a PLY
    file (binary) holds the same vertices and faces concatenated into one mesh, so object
    names are lost there. Each file is written atomically; if a frame fails, the frames this
    call wrote are removed (and the folders this call created) and the error is
    raised. After success, older ``frame_NNNNN`` files of the same format beyond the new
    sequence are removed, so the directory holds one sequence.
    """
    if not isinstance(file_format, str) or file_format.lower().lstrip(".") not in MESH_FORMATS:
        raise InputError("file_format", f"expected one of {', '.join(MESH_FORMATS)}, found {file_format!r}")
    file_format = file_format.lower().lstrip(".")
    every = _check_every(every)
    samples = frame_samples(sample_count(arrays), every)
    data = read_trajectory(arrays, _REQUIRED, samples)  # only the samples exported are read
    check_arrays(data)
    parts = _Parts(data)
    writer = _ObjWriter(_frame_objects(parts, data, 0)) if file_format == "obj" else None

    directory = os.fspath(directory)
    made, written = make_folders(directory), []
    try:
        for j, sample in enumerate(samples):
            interrupts.check()  # Ctrl-C or SIGTERM: between frames
            path = os.path.join(directory, f"frame_{j:05d}.{file_format}")
            objects = _frame_objects(parts, data, j)
            with atomic_path(path) as temporary:
                if file_format == "obj":
                    header = f"contactlab frame {j}: sample {sample}, t = {float(data['time'][j]):.9g} s; metres, z up"
                    writer.write(temporary, objects, header)
                else:
                    _write_ply(temporary, objects)
            written.append(path)
    except BaseException:
        undo_written(written, made)
        raise
    pattern = re.compile(r"frame_(\d{5,})\." + file_format + "$")
    for name in os.listdir(directory):  # stale frames of a longer, earlier export
        match = pattern.match(name)
        if match and int(match.group(1)) >= len(samples):
            os.unlink(os.path.join(directory, name))
    return written


# ---------------------------------------------------------------------------------------------
# USD
# ---------------------------------------------------------------------------------------------


def _continuous(q):
    """Quaternions (S, B, 4) with signs flipped so that consecutive samples lie in one
    hemisphere (q and −q are one rotation; USD interpolates between samples the short way)."""
    if len(q) < 2:
        return q
    dots = np.einsum("sbk,sbk->sb", q[1:], q[:-1])
    flip = np.where(dots < 0.0, -1.0, 1.0)
    sign = np.concatenate([np.ones((1, q.shape[1])), np.cumprod(flip, axis=0)])
    return q * sign[:, :, None]


def _extent(points, pad=None):
    """[min, max] corners of ``points`` (n, 3), grown by ``pad`` (n,) per point if given."""
    from pxr import Vt

    if len(points) == 0:
        return Vt.Vec3fArray.FromNumpy(np.zeros((2, 3), np.float32))
    pad = np.zeros((len(points), 1)) if pad is None else np.asarray(pad)[:, None]
    corners = np.stack([(points - pad).min(axis=0), (points + pad).max(axis=0)])
    return Vt.Vec3fArray.FromNumpy(corners.astype(np.float32))


def _define_mesh(stage, path, points, triangles, double_sided=False):
    """A triangle Mesh at ``path`` with static topology; ``points`` static if given."""
    from pxr import UsdGeom, Vt

    mesh = UsdGeom.Mesh.Define(stage, path)
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(triangles), 3, np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(triangles.astype(np.int32).ravel()))
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)  # flat triangles, not a subdivision cage
    mesh.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)  # counter-clockwise seen from the front
    mesh.CreateDoubleSidedAttr(double_sided)
    if points is not None:
        mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(points.astype(np.float32)))
        mesh.CreateExtentAttr(_extent(points))
    return mesh


def write_usd(arrays: Mapping[str, Any], path: str, *, every: int = 1) -> str:
    """One USD stage (.usd/.usda/.usdc by the path's suffix) with the whole animation; returns
    path.

    Time code s is trajectory sample s (every ``every``-th sample, always including the last,
    carries time samples); timeCodesPerSecond = 1/median(Δt) of the samples; upAxis Z,
    metersPerUnit 1. Prims: ``/World`` (default prim), ``/World/Bodies/<name>`` (Xform with
    time-sampled translate and orient, child ``surface``: a Mesh in the body's frame),
    ``/World/Cloth/cloth<i>`` (Mesh, time-sampled points), ``/World/Particles`` (Points of
    the free particles, widths = 2 radius), ``/World/Obstacles`` (static Mesh). Groups with
    nothing in them are left out. Written atomically.
    """
    suffix = os.path.splitext(os.fspath(path))[1].lower()
    if suffix not in USD_SUFFIXES:
        raise InputError("path", f"expected a file name ending in {', '.join(USD_SUFFIXES)}, found {os.fspath(path)!r}")
    every = _check_every(every)
    time = checked_times(arrays).astype(float)
    samples = frame_samples(len(time), every)
    data = read_trajectory(arrays, _REQUIRED, samples)  # only the samples exported are read
    check_arrays(data)
    from pxr import Gf, Sdf, Tf, Usd, UsdGeom, Vt

    parts = _Parts(data)
    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    steps = np.diff(time)
    steps = steps[steps > 0]
    if len(steps):
        rate = 1.0 / float(np.median(steps))
        if abs(rate - round(rate)) < 1e-9 * rate:  # 1/(1/240) is 240.00000000000085
            rate = float(round(rate))
        stage.SetTimeCodesPerSecond(rate)
        stage.SetFramesPerSecond(rate)
    stage.SetStartTimeCode(0.0)
    stage.SetEndTimeCode(float(len(time) - 1))

    world = UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(world.GetPrim())
    world.GetPrim().SetDocumentation("contactlab run: metres, seconds, z up; time code s = trajectory sample s")
    # the exact simulated time of each exported sample (the last interval may be shorter)
    clock = world.GetPrim().CreateAttribute("contactlab:time", Sdf.ValueTypeNames.Double, custom=True)
    for s in samples:
        clock.Set(float(time[s]), Usd.TimeCode(float(s)))

    if parts.body_count:
        UsdGeom.Xform.Define(stage, "/World/Bodies")
        names = _unique_names([Tf.MakeValidIdentifier(name) if name else "body" for name in parts.body_names])
        position = data["body_position"].astype(float)
        orientation = _continuous(data["body_orientation"].astype(float))
        for b, name in enumerate(names):
            body = UsdGeom.Xform.Define(stage, f"/World/Bodies/{name}")
            if name != parts.body_names[b] and hasattr(Usd.Prim, "SetDisplayName"):  # USD ≥ 23.11
                body.GetPrim().SetDisplayName(parts.body_names[b])
            translate = body.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble)
            orient = body.AddOrientOp(UsdGeom.XformOp.PrecisionDouble)
            for k, s in enumerate(samples):
                code = Usd.TimeCode(float(s))
                translate.Set(Gf.Vec3d(*position[k, b]), code)
                w, x, y, z = orientation[k, b]
                orient.Set(Gf.Quatd(w, x, y, z), code)
            v0, v1 = parts.body_vertices[b]
            _define_mesh(stage, f"/World/Bodies/{name}/surface", parts.body_local[v0:v1], parts.body_triangles[b])

    positions = data["particle_position"].astype(float)
    if parts.cloths:
        UsdGeom.Xform.Define(stage, "/World/Cloth")
        for c, ids, tri in parts.cloths:
            mesh = _define_mesh(stage, f"/World/Cloth/cloth{c}", None, tri, double_sided=True)
            points, extent = mesh.CreatePointsAttr(), mesh.CreateExtentAttr()
            for k, s in enumerate(samples):
                code = Usd.TimeCode(float(s))
                points.Set(Vt.Vec3fArray.FromNumpy(positions[k, ids].astype(np.float32)), code)
                extent.Set(_extent(positions[k, ids]), code)

    if len(parts.free):
        cloud = UsdGeom.Points.Define(stage, "/World/Particles")
        cloud.CreateWidthsAttr(Vt.FloatArray.FromNumpy((2.0 * parts.free_radius).astype(np.float32)))
        cloud.SetWidthsInterpolation(UsdGeom.Tokens.vertex)
        points, extent = cloud.CreatePointsAttr(), cloud.CreateExtentAttr()
        for k, s in enumerate(samples):
            code = Usd.TimeCode(float(s))
            points.Set(Vt.Vec3fArray.FromNumpy(positions[k, parts.free].astype(np.float32)), code)
            extent.Set(_extent(positions[k, parts.free], parts.free_radius), code)

    if len(parts.obstacle_vertices):
        _define_mesh(stage, "/World/Obstacles", parts.obstacle_vertices, parts.obstacle_triangles, double_sided=True)

    # pxr picks the file format (text or crate) from the suffix, which the temporary keeps
    path = os.fspath(path)
    made = make_folders(os.path.dirname(os.path.abspath(path)))
    try:
        with atomic_path(path) as temporary:
            if not stage.GetRootLayer().Export(temporary):
                raise OSError(f"USD could not write {temporary}")
    except BaseException:
        remove_empty(made)
        raise
    return path
