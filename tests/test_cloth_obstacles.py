"""Cloth against obstacles between its vertices (issue 57, item 4): the face contacts of
collision.cloth against closed-form placements, and a coarse sheet dropped across a rod
narrower than its vertex spacing, which every method at its defaults holds up."""

import numpy as np
import pytest

from contactlab import ModelBuilder, simulate
from contactlab.collision import DetectionSettings, collide, collide_keeping
from contactlab.collision.cloth import FACE, cloth_face_contacts
from contactlab.collision.contact_output import FEATURE_BITS
from contactlab.errors import InputError, SimulationDiverged
from contactlab.methods import get

THICKNESS = 0.005
ROD_TOP = 0.52  # m: a 40 mm rod along x, its axis at z = 0.5


def cloth(vertices_xy, height, rod=None, sphere=None, resolution=(2, 2), size=(0.1, 0.1)):
    """A cloth of ``resolution`` vertices over ``size`` [m] centred at (0, 0, height) over a rod
    (a box of half extents ``rod`` at the origin) or a sphere ((radius, centre z))."""
    b = ModelBuilder()
    b.add_material("cotton", friction=0.4, restitution=0.0)
    b.add_cloth(
        size=size, resolution=resolution, mass=0.01, position=(0.0, 0.0, height), thickness=THICKNESS, material="cotton"
    )
    if rod is not None:
        b.add_obstacle("box", half_extents=rod, position=(0.0, 0.0, 0.0), material="cotton")
    if sphere is not None:
        b.add_obstacle("sphere", radius=sphere[0], position=(0.0, 0.0, sphere[1]), material="cotton")
    return b.finalize()


def face_contacts(model):
    N = model.body_count + model.particle_count + model.obstacle_count
    return cloth_face_contacts(model, model.state(), 0.002, N * N)


def test_a_rod_under_the_middle_of_a_square_meets_one_triangle_at_its_diagonal_once():
    # a 0.1 m square (two triangles sharing a diagonal) 3 mm above a 10 mm rod along y under
    # x = 0: the vertices, 50 mm either side, see nothing; the triangles' points nearest the rod
    # lie over its top face
    model = cloth(None, 0.003 + 0.005, rod=(0.005, 0.2, 0.005))
    found = face_contacts(model)
    vertex_contacts = collide_keeping(model, model.state(), None, 0.0, DetectionSettings(0.002, cloth_faces=False))[0]
    assert vertex_contacts.count == 0  # the vertices are 45 mm from the rod
    assert found.count >= 1
    # each contact: its weights sum to 1 and reproduce a point on the cloth 3 mm over the rod's top
    positions = model.state().particle_position
    on_cloth = np.einsum("ck,ckd->cd", found.weights_a, positions[found.particles_a])
    np.testing.assert_allclose(found.weights_a.sum(axis=1), 1.0)
    np.testing.assert_allclose(on_cloth[:, 2], 0.008)
    np.testing.assert_allclose(np.abs(on_cloth[:, 0]), 0.0, atol=0.0051)  # over the rod's top face
    np.testing.assert_allclose(found.normal, np.tile([0.0, 0.0, 1.0], (found.count, 1)), atol=1e-12)
    # depth counts from the thickness: the gap is 3 mm, the thickness 5 mm
    np.testing.assert_allclose(found.depth, THICKNESS - 0.003)
    assert np.all(found.feature_id & ((1 << FEATURE_BITS) - 1) == FACE)
    # one contact per point: the two triangles share the diagonal, which the first one owns
    keys = {tuple(np.round(p, 9)) for p in on_cloth}
    assert len(keys) == found.count


def test_a_sphere_under_a_triangles_middle_meets_it_at_the_foot_of_its_centre():
    # a 0.2 m square 40 mm over a sphere of radius 38 mm: the closest point of the square to the
    # centre is straight above it, 2 mm from the sphere; the corners are 0.14 m away
    model = cloth(None, 0.04, sphere=(0.038, 0.0), size=(0.2, 0.2))
    found = face_contacts(model)
    assert found.count == 1
    point = found.weights_a[0] @ model.state().particle_position[found.particles_a[0]]
    np.testing.assert_allclose(point, [0.0, 0.0, 0.04], atol=1e-9)
    np.testing.assert_allclose(found.depth[0], THICKNESS - 0.002)
    np.testing.assert_allclose(found.normal[0], [0.0, 0.0, 1.0], atol=1e-12)


def test_a_triangle_whose_vertex_is_nearest_makes_no_face_contact():
    # a sphere under a corner of the square: the vertex's own contact sees it
    b = ModelBuilder()
    b.add_material("cotton")
    b.add_cloth(
        size=(0.1, 0.1), resolution=(2, 2), mass=0.01, position=(0.0, 0.0, 0.01), thickness=THICKNESS, material="cotton"
    )
    b.add_obstacle("sphere", radius=0.008, position=(0.05, 0.05, 0.0), material="cotton")
    model = b.finalize()
    assert face_contacts(model).count == 0
    assert collide(model, model.state(), margin=0.002).count >= 1  # the corner's particle contact


def test_cloth_faces_is_a_switch():
    with pytest.raises(InputError, match="cloth_faces"):
        get("impulse").Options(cloth_faces="yes")


def sheet_over_rod():
    """A 24 × 24 sheet (0.3 kg), its vertices 43 mm apart, level 8 cm over a 40 mm rod 0.5 m up,
    the floor below: the rod fits between two rows of vertices."""
    b = ModelBuilder()
    b.add_material("cotton", friction=0.4, restitution=0.0)
    size = 23 * 0.043
    b.add_cloth(
        size=(size, size),
        resolution=(24, 24),
        mass=0.3,
        position=(0.0, 0.0, 0.6),
        stretch_stiffness=2000.0,
        shear_stiffness=200.0,
        bend_stiffness=2.0,
        damping=0.02,
        thickness=THICKNESS,
        material="cotton",
    )
    b.add_obstacle("box", half_extents=(0.7, 0.02, 0.02), position=(0.0, 0.0, 0.5), material="cotton")
    b.add_obstacle("plane", normal=(0, 0, 1), offset=0.0, material="cotton")
    return b.finalize()


@pytest.mark.parametrize("method", ["projection", "impulse", "constraints", "penalty"])
def test_a_coarse_sheet_dropped_across_a_thin_rod_stays_draped_on_it(method):
    model = sheet_over_rod()
    run = simulate(model, method, 1 / 120, 0.6, None, "backward_euler", record_every=6)
    top = run.arrays["particle_position"][:, :, 2].max(axis=1)
    # it lands (the rod's top plus the thickness) and stays: no sample after the landing lower
    landed = np.nonzero(top < ROD_TOP + 2 * THICKNESS)[0][0]
    assert np.all(top[landed:] > ROD_TOP)
    assert np.all(top[landed:] < ROD_TOP + 2 * THICKNESS)
    # the rod never comes out on the far side of the cloth: a cloth is 2 thicknesses across
    assert run.summary["max_penetration"] < 2 * THICKNESS


def test_without_face_contacts_penalty_lets_the_sheet_through_the_rod():
    with pytest.raises(SimulationDiverged, match="went through"):  # through the rod, then the floor
        simulate(sheet_over_rod(), "penalty", 1 / 120, 0.6, {"cloth_faces": False}, "backward_euler", record_every=6)
