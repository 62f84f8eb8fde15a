"""Shape surfaces for pictures and exports: closed, outward, the shape's size, posed like the body."""

import numpy as np
import pytest
import trimesh

from contactlab import ModelBuilder, rotations, shapes, surfaces
from contactlab.simulation import simulate


def _model():
    b = ModelBuilder()
    b.add_obstacle("plane", normal=(0, 0, 1), offset=0.0)
    b.add_body(
        "box",
        half_extents=[0.1, 0.2, 0.3],
        mass=1.0,
        position=[0, 0, 1.0],
        orientation=rotations.from_rotation_vector(np.array([[0.3, 0.2, 0.1]]))[0],
    )
    b.add_body("sphere", radius=0.1, mass=1.0, position=[1.0, 0, 1.0])
    b.add_body("capsule", radius=0.05, half_length=0.2, mass=1.0, position=[-1.0, 0, 1.0])
    b.add_particles([[0, 1.0, 0.5]], radius=0.02, mass=0.1)
    return b.finalize()


def test_every_body_surface_is_closed_outward_and_of_the_shape_size():
    model = _model()
    arrays = surfaces.surface_arrays(model)
    vs, ts = arrays["body_surface_vertex_start"], arrays["body_surface_triangle_start"]
    volumes = []
    for b in range(model.body_count):
        v = arrays["body_surface_vertices"][vs[b] : vs[b + 1]]
        t = arrays["body_surface_triangles"][ts[b] : ts[b + 1]] - vs[b]
        mesh = trimesh.Trimesh(v, t, process=False)
        assert mesh.is_watertight
        assert mesh.volume > 0  # positive: wound outward
        volumes.append(mesh.volume)
    exact = [shapes.volume(int(k), p) for k, p in zip(model.body_shape, model.body_params)]
    assert volumes[0] == pytest.approx(exact[0], rel=1e-12)  # a box is exact
    assert volumes[1] == pytest.approx(exact[1], rel=0.15)  # tessellated: inscribed, a bit smaller
    assert volumes[2] == pytest.approx(exact[2], rel=0.15)
    assert volumes[1] < exact[1] and volumes[2] < exact[2]
    np.testing.assert_array_equal(arrays["particle_radius"], [0.02])


def test_posed_vertices_follow_the_bodies_and_planes_lie_on_their_plane():
    model = _model()
    run = simulate(model, "impulse", dt=0.01, duration=0.2)
    arrays = run.arrays
    world = surfaces.posed_body_vertices(arrays, -1)
    start = arrays["body_surface_vertex_start"]
    R = rotations.to_matrix(arrays["body_orientation"][-1])
    for b in range(model.body_count):
        local = arrays["body_surface_vertices"][start[b] : start[b + 1]]
        expected = local @ R[b].T + arrays["body_position"][-1, b]
        np.testing.assert_allclose(world[start[b] : start[b + 1]], expected, atol=1e-14)
    box = world[start[0] : start[1]] - arrays["body_position"][-1, 0]
    np.testing.assert_allclose(np.sort(np.abs(box @ R[0]), axis=0)[-1], [0.1, 0.2, 0.3], atol=1e-12)
    floor = arrays["obstacle_vertices"]
    np.testing.assert_allclose(floor[:, 2], 0.0, atol=1e-15)
    assert np.ptp(floor[:, 0]) >= 2.0  # wide enough to hold the scene (x from −1 to 1)


def test_the_written_out_icosphere_is_trimeshs_bit_for_bit():
    """contactlab.icosphere spares every run with a sphere the import of trimesh."""
    from contactlab import icosphere
    from contactlab.surfaces import SPHERE_SUBDIVISIONS, _unit_sphere

    mesh = trimesh.creation.icosphere(subdivisions=SPHERE_SUBDIVISIONS, radius=1.0)
    vertices, triangles = _unit_sphere()
    assert vertices.tobytes() == np.asarray(mesh.vertices, dtype=float).tobytes()
    np.testing.assert_array_equal(triangles, mesh.faces)
    assert len(icosphere.VERTICES) == 42 and len(icosphere.TRIANGLES) == 80
