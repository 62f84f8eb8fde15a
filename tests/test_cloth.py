"""Cloth: the mass-spring model, its forces and Jacobians, and their time integration."""

import numpy as np
import pytest

from contactlab import ModelBuilder, diagnostics, simulate
from contactlab.dynamics.cloth import spring_energy, spring_forces, spring_jacobians
from contactlab.dynamics.integrators import (
    conjugate_gradients,
    factor_symmetric,
    free_velocities,
    particle_system,
    solve_coupled,
    solve_particle_system,
)
from contactlab.dynamics.sparse_cholesky import ancestors, cholesky, cholesky_solve_within
from contactlab.errors import InputError, SimulationDiverged
from contactlab.scene import load_scene

UPRIGHT = (np.cos(np.pi / 4), np.sin(np.pi / 4), 0.0, 0.0)  # 90° about x: the grid's y axis points up


def sheet(n=6, k=1000.0, damping=0.0, pinned="top_corners", **extra):
    """A 0.5 m square cloth of 0.2 kg, horizontal at z = 1 m (n × n vertices)."""
    b = ModelBuilder()
    b.add_cloth(
        size=(0.5, 0.5),
        resolution=(n, n),
        mass=0.2,
        position=(0, 0, 1),
        stretch_stiffness=k,
        shear_stiffness=k / 10,
        bend_stiffness=k / 100,
        damping=damping,
        pinned=pinned,
        **extra,
    )
    return b.finalize()


def jiggled(model, rng, amount=0.03):
    state = model.state()
    return (
        state.particle_position + amount * rng.normal(size=state.particle_position.shape),
        rng.normal(size=state.particle_position.shape),
    )


# -- the model --------------------------------------------------------------------------------------
def test_grid_topology_masses_and_pins():
    b = ModelBuilder()
    b.add_particles([[0, 0, 5.0]], mass=2.0)
    vertices = b.add_cloth(
        size=(2.0, 1.0),
        resolution=(4, 3),
        density=0.5,
        position=(1, 2, 3),
        pinned=["top_edge", 1],
        thickness=0.01,
        name="flag",
    )
    model = b.finalize()
    assert vertices == range(1, 13)
    assert model.cloth_names == ("flag",) and model.cloth_count == 1
    assert model.particle_cloth.tolist() == [-1] + [0] * 12
    # uniform mass: 0.5 kg/m² × 2 m² over 12 vertices
    np.testing.assert_allclose(model.particle_mass[1:], 1.0 / 12)
    np.testing.assert_allclose(model.particle_radius[1:], 0.01)
    # vertex a + nx b at (-w/2 + a w/(nx-1), -h/2 + b h/(ny-1)) around the centre
    x = model.initial.particle_position
    np.testing.assert_allclose(x[1], [0.0, 1.5, 3.0])
    np.testing.assert_allclose(x[1 + 3 + 4 * 2], [2.0, 2.5, 3.0])
    pinned = np.nonzero(model.particle_pinned)[0]
    assert pinned.tolist() == [2, 9, 10, 11, 12]  # index 1 and the row b = 2
    assert (model.particle_inverse_mass[pinned] == 0).all() and model.particle_inverse_mass[0] == 0.5
    # 2 triangles per cell; stretch 3·3 + 4·2, shear 2·6, bend 2·3 + 4·1
    assert model.triangles.shape == (12, 3) and model.triangles.min() == 1
    assert model.spring_count == 17 + 12 + 10
    np.testing.assert_allclose(
        model.spring_rest_length,
        np.linalg.norm(x[model.spring_particles[:, 1]] - x[model.spring_particles[:, 0]], axis=1),
    )
    # triangles wound counter-clockwise seen from +z (the local front)
    t = model.triangles
    normals = np.cross(x[t[:, 1]] - x[t[:, 0]], x[t[:, 2]] - x[t[:, 0]])
    assert (normals[:, 2] > 0).all()
    assert "1 particle" in model.describe() and "1 cloth (12 vertices)" in model.describe()


def test_models_without_cloth_have_empty_cloth_arrays():
    b = ModelBuilder()
    b.add_particles([[0, 0, 1.0]])
    model = b.finalize()
    assert model.spring_count == 0 and model.triangles.shape == (0, 3)
    assert model.particle_cloth.tolist() == [-1] and model.particle_pinned.tolist() == [False]
    assert spring_forces(model, model.initial.particle_position).shape == (1, 3)
    assert spring_energy(model, model.initial.particle_position) == 0.0


def test_cloth_from_mesh_file(tmp_path):
    # two triangles sharing the diagonal (0, 2) of a unit square, plus a duplicate of vertex 0
    (tmp_path / "quad.obj").write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 0\nf 1 2 3\nf 5 3 4\n")
    b = ModelBuilder()
    b.add_cloth(
        file=str(tmp_path / "quad.obj"),
        scale=2.0,
        density=1.0,
        position=(0, 0, 1),
        pinned=[0],
        stretch_stiffness=50.0,
        bend_stiffness=5.0,
    )
    model = b.finalize()
    assert model.particle_count == 4  # the duplicate is merged
    np.testing.assert_allclose(model.initial.particle_position[3], [0, 2, 1])
    # mass by area: 4 m² × 1 kg/m²; the diagonal's ends are in both triangles
    np.testing.assert_allclose(model.particle_mass, [4 / 3, 2 / 3, 4 / 3, 2 / 3])
    # 5 edges (stretch) + 1 bend across the shared edge, between vertices 1 and 3
    assert model.spring_count == 6
    bend = model.spring_stiffness == 5.0
    assert sorted(model.spring_particles[bend][0].tolist()) == [1, 3]
    assert model.particle_pinned.tolist() == [True, False, False, False]


# -- forces, Jacobians, energy ----------------------------------------------------------------------
def test_single_spring_force_and_energy():
    b = ModelBuilder(gravity=(0, 0, 0))
    b.add_cloth(
        size=(1.0, 1.0),
        resolution=(2, 2),
        mass=1.0,
        stretch_stiffness=100.0,
        shear_stiffness=0.0,
        bend_stiffness=0.0,
        damping=2.0,
    )
    model = b.finalize()
    x = model.initial.particle_position.copy()
    x[1, 0] += 0.1  # stretch the bottom spring (0, 1) by 0.1 m
    v = np.zeros_like(x)
    v[1, 0] = 1.0  # separating at 1 m/s
    f = spring_forces(model, x, v)
    # spring (0,1): k·0.1 + c·1 = 12 N pulls 0 towards +x and 1 towards −x; spring (1,3) leans
    np.testing.assert_allclose(f[0], [12.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(f.sum(axis=0), 0.0, atol=1e-12)  # internal forces: no net force
    length13 = np.hypot(0.1, 1.0)
    assert spring_energy(model, x) == pytest.approx(0.5 * 100 * (0.01 + (length13 - 1.0) ** 2))


def central_differences(function, point, step=1e-6):
    """∂function/∂point by central differences: (outputs, 3P) for a function of a (P, 3) point
    returning an array (flattened) or a number (one row)."""
    columns = []
    for column in range(point.size):
        plus, minus = point.copy().ravel(), point.copy().ravel()
        plus[column] += step
        minus[column] -= step
        columns.append(np.ravel(function(plus.reshape(-1, 3)) - function(minus.reshape(-1, 3))) / (2 * step))
    return np.stack(columns, axis=1)


@pytest.mark.parametrize("clamp", [False, True])
def test_jacobians_match_finite_differences(rng, clamp):
    model = sheet(n=4, k=500.0, damping=0.0, pinned=())
    x, v = jiggled(model, rng)
    # compress some springs so the clamp matters
    x = x * np.array([0.8, 0.8, 1.0])
    K, _ = spring_jacobians(model, x, v, clamp_compressed=clamp)
    numeric = central_differences(lambda y: spring_forces(model, y, v), x)
    dense = K.toarray()
    np.testing.assert_allclose(dense, dense.T, atol=1e-9)
    if clamp:
        # negative semidefinite, and exact wherever no spring is compressed
        assert np.linalg.eigvalsh(dense).max() < 1e-8
        assert np.linalg.eigvalsh(numeric).max() > 1e-3  # the exact K is not
    else:
        np.testing.assert_allclose(dense, numeric, atol=1e-5 * np.abs(numeric).max())


def test_damping_jacobian_and_energy_gradient(rng):
    model = sheet(n=4, damping=3.0, pinned=())
    x, v = jiggled(model, rng)
    _, D = spring_jacobians(model, x, v)
    numeric = central_differences(lambda y: spring_forces(model, x, y), v)
    np.testing.assert_allclose(D.toarray(), numeric, atol=1e-6 * np.abs(numeric).max())
    # the elastic force is minus the gradient of the energy
    gradient = central_differences(lambda y: spring_energy(model, y), x)[0]
    np.testing.assert_allclose(spring_forces(model, x).ravel(), -gradient, atol=1e-5 * np.abs(gradient).max())


def test_backward_euler_system_pins_and_matches_its_definition(rng):
    model = sheet(n=4, damping=0.5)
    state = model.state()
    state.particle_position[:], state.particle_velocity[:] = jiggled(model, rng, 0.01)
    h = 0.01
    system = particle_system(model, state, h)
    delta = solve_particle_system(system, model, tolerance=1e-12)
    pinned = model.particle_pinned
    assert np.all(delta[pinned] == 0.0)
    # on the free particles: (M − h D − h² K) Δv = h (f + h K v)
    K, D = spring_jacobians(model, state.particle_position, state.particle_velocity, clamp_compressed=True)
    A = np.diag(np.repeat(model.particle_mass, 3)) - h * D.toarray() - h * h * K.toarray()
    f = (
        spring_forces(model, state.particle_position, state.particle_velocity)
        + model.particle_mass[:, None] * model.gravity
    ).ravel()
    free = np.repeat(~pinned, 3)
    residual = (A @ delta.ravel() - h * (f + h * K @ state.particle_velocity.ravel()))[free]
    assert np.abs(residual).max() < 1e-9 * np.abs(h * f).max()
    velocities = free_velocities(model, state, h, "backward_euler", linear_tolerance=1e-12)[2]
    np.testing.assert_allclose(velocities[~pinned], state.particle_velocity[~pinned] + delta[~pinned])
    assert np.all(velocities[pinned] == 0.0)


@pytest.fixture(scope="module")
def draped():
    """The built-in cloth_drape 0.6 s in (625 vertices over a sphere): (its Scene, the State),
    simulated once for the module (the tests only read it), as the scene runs by default, as the
    render, plot and command-line tests run it (so its kernels compile once for all of them)."""
    scene = load_scene("cloth_drape")
    options = scene.method_options.get(scene.method)
    return scene, simulate(scene.model, scene.method, scene.dt, 0.6, options, scene.integrator, record_every=72).state


@pytest.fixture(scope="module")
def draped_system(draped):
    """The backward Euler system of the draped cloth."""
    scene, state = draped
    return particle_system(scene.model, state, scene.dt)


def jacobi_iterations(matrix, rhs, tolerance):
    """Conjugate gradient iterations to |r| < tolerance |rhs| from rhs / diag with the point Jacobi
    preconditioner, written out (the reference the block one is held against)."""
    inverse = 1.0 / matrix.diagonal()
    x = rhs * inverse
    r = rhs - matrix @ x
    z = inverse * r
    p, current = z.copy(), r @ z
    for iterations in range(10 * len(rhs)):
        if np.linalg.norm(r) < tolerance * np.linalg.norm(rhs):
            return iterations
        q = matrix @ p
        alpha = current / (p @ q)
        x, r = x + alpha * p, r - alpha * q
        z = inverse * r
        previous, current = current, r @ z
        p = z + (current / previous) * p
    raise AssertionError("point Jacobi did not converge")


def test_block_jacobi_conjugate_gradients_converge_in_fewer_iterations_to_the_same_solution(draped_system):
    # a cloth's springs couple a vertex's x, y and z: inverting each vertex's 3 × 3 diagonal block
    # is a better preconditioner than its diagonal alone, for the same answer
    system = draped_system
    A, b = system.matrix.tocsr(), system.rhs
    everything = np.ones(len(b), dtype=bool)
    x, iterations, converged = conjugate_gradients(A, b, b / A.diagonal(), everything, 1e-10, 10 * len(b))
    assert converged
    assert iterations < 0.8 * jacobi_iterations(A, b, 1e-10)
    exact = np.linalg.solve(A.toarray(), b)
    assert np.abs(x - exact).max() < 1e-8 * np.abs(exact).max()


def test_the_spring_solve_started_from_the_last_steps_answer_reaches_the_same_answer_sooner(draped):
    """Issue 36: a draped cloth's Δv changes little from one step to the next. The state carries
    the last one (``Carry.springs``) and the next solve starts from it: at the steps' tolerance
    (1e-6, ``free_velocities``' default) as close to a dense solve as from the diagonal's guess,
    in at most 70 % of the iterations (136 → 83 when measured, 1.5 s in)."""
    scene, state = draped
    options = scene.method_options.get(scene.method)
    state = simulate(
        scene.model, scene.method, scene.dt, 0.9, options, scene.integrator, record_every=108, state=state
    ).state
    assert state.carried.springs is not None and state.carried.springs.shape == state.particle_velocity.shape
    system = particle_system(scene.model, state, scene.dt)
    A, b, coupled = system.matrix.tocsr(), system.rhs, np.repeat(system.coupled, 3)
    cold, cold_iterations = solve_coupled(A, b, coupled, 1e-6, "cg")
    warm, warm_iterations = solve_coupled(A, b, coupled, 1e-6, "cg", state.carried.springs)
    assert warm_iterations < 0.7 * cold_iterations
    exact = np.linalg.solve(A.toarray(), b)
    for x in (cold, warm):
        assert np.abs(x - exact).max() < 1e-4 * np.abs(exact).max()
        assert np.linalg.norm(A @ x - b) < 1.5e-6 * np.linalg.norm(b)  # it stops on the preconditioned residual


def test_conjugate_gradients_on_part_of_a_triple_solve_its_active_part_alone(rng):
    # an inactive DOF in a triple whose others are active: held at its guess, and the active ones
    # solve the system of the active rows and columns alone
    model = sheet(n=4, damping=0.5)
    state = model.state()
    state.particle_position[:], state.particle_velocity[:] = jiggled(model, rng, 0.01)
    system = particle_system(model, state, 0.01)
    A, b = system.matrix.tocsr(), system.rhs
    active = np.ones(len(b), dtype=bool)
    active[[4, 9, 10]] = False
    guess = rng.normal(size=len(b))
    x, _, converged = conjugate_gradients(A, b, guess, active, 1e-13, 1000)
    assert converged
    np.testing.assert_array_equal(x[~active], guess[~active])
    compact = A.toarray()[np.ix_(active, active)]
    np.testing.assert_allclose(x[active], np.linalg.solve(compact, b[active]), rtol=1e-9, atol=1e-12)


def test_block_cholesky_solves_the_draped_system_as_a_dense_solve(draped_system, rng):
    system = draped_system
    A = system.matrix.tocsr()
    factor = cholesky(A)
    assert factor is not None
    dense = A.toarray()
    rhs = rng.normal(size=(len(system.rhs), 3))
    np.testing.assert_allclose(factor.solve(rhs), np.linalg.solve(dense, rhs), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(factor.solve(system.rhs), np.linalg.solve(dense, system.rhs), rtol=1e-9, atol=1e-14)
    # the pattern is analysed once: the next matrix of that pattern reuses it
    assert cholesky(2.0 * A).analysis is factor.analysis


def test_block_cholesky_solve_within_the_ancestors_matches_the_full_solve_there(draped_system, rng):
    # a right-hand side on a few particles: the solve over their elimination-tree ancestors alone
    # gives the full solve's values on them (what W x = J A⁻¹ Jᵀ x reads), and skips the rest
    A = draped_system.matrix.tocsr()
    factor = cholesky(A)
    a = factor.analysis
    touched = np.sort(rng.choice(A.shape[0] // 3, size=6, replace=False)).astype(np.int64)
    reach = ancestors(a.order, a.column_start, a.column_rows, touched)
    position = np.argsort(a.order)
    assert set(position[touched]) <= set(reach) and len(reach) < len(a.order)
    for j in reach:  # closed under the elimination tree's parent (first row below the diagonal)
        rows = a.column_rows[a.column_start[j] + 1 : a.column_start[j + 1]]
        assert rows.size == 0 or rows[0] in reach
    rhs = np.zeros((A.shape[0], 2))
    dofs = (3 * touched[:, None] + np.arange(3)).ravel()
    rhs[dofs] = rng.normal(size=(len(dofs), 2))
    within = cholesky_solve_within(a.order, a.column_start, a.column_rows, factor.values, reach, rhs)
    np.testing.assert_array_equal(within[dofs], factor.solve(rhs)[dofs])
    np.testing.assert_allclose(within[dofs], np.linalg.solve(A.toarray(), rhs)[dofs], rtol=1e-9, atol=1e-12)


def test_block_cholesky_declines_what_it_cannot_factor():
    import scipy.sparse as sp

    indefinite = sp.csr_matrix(np.array([[1.0, 2.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, 1.0]]))
    assert cholesky(indefinite) is None
    assert cholesky(sp.identity(2, format="csr")) is None  # not 3 × 3 blocks
    # factor_symmetric then answers with the sparse LU
    np.testing.assert_allclose(factor_symmetric(sp.identity(2, format="csr") * 2.0).solve(np.ones(2)), 0.5)


@pytest.mark.parametrize("integrator", ["symplectic_euler", "explicit_euler", "backward_euler"])
def test_pinned_vertices_do_not_move_and_free_particles_fall_freely(integrator):
    b = ModelBuilder()
    b.add_particles([[3.0, 0, 1.0]])
    b.add_cloth(
        size=(0.5, 0.5),
        resolution=(4, 4),
        mass=0.1,
        position=(0, 0, 1),
        pinned="corners",
        velocity=(0, 0, 1.0),
        stretch_stiffness=20.0,
        shear_stiffness=2.0,
        bend_stiffness=0.2,
    )
    model = b.finalize()
    pinned = model.particle_pinned
    assert np.all(model.initial.particle_velocity[pinned] == 0)
    # soft springs: explicit Euler grows every oscillation, slowly enough at this step
    run = simulate(model, "impulse", dt=0.001, duration=0.3, integrator=integrator)
    positions = run.arrays["particle_position"]
    np.testing.assert_array_equal(
        positions[:, pinned], np.broadcast_to(positions[0, pinned], positions[:, pinned].shape)
    )
    assert positions[-1, ~pinned, 2].min() < positions[0, ~pinned, 2].min()  # the rest sags
    t = run.arrays["time"][-1]
    z = positions[-1, 0, 2]
    assert z == pytest.approx(1.0 - 0.5 * 9.81 * t**2, abs=9.81 * 0.001 * t)  # the free particle falls


# -- statics: a hanging chain -----------------------------------------------------------------------
def test_hanging_chain_extension_matches_mg_over_k():
    """A strip two vertices wide hung from its top edge: with no shear or bend springs the two
    columns are chains whose spring i from the bottom carries the weight of the i masses below
    it, so it stretches by i m g / k (the horizontal springs stay at rest length)."""
    rows, k, total_mass, length = 6, 200.0, 0.12, 0.5
    b = ModelBuilder()
    b.add_cloth(
        size=(0.1, length),
        resolution=(2, rows),
        mass=total_mass,
        orientation=UPRIGHT,
        position=(0, 0, 1),
        stretch_stiffness=k,
        shear_stiffness=0.0,
        bend_stiffness=0.0,
        damping=0.5,
        pinned="top_edge",
    )
    model = b.finalize()
    run = simulate(model, "impulse", dt=0.01, duration=3.0, integrator="backward_euler", record_every=300)
    x = run.state.particle_position
    assert np.abs(run.state.particle_velocity).max() < 1e-6  # at rest
    m, g = total_mass / (2 * rows), 9.81
    rest = length / (rows - 1)
    for column in range(2):
        z = x[column::2, 2]  # bottom to top
        extension = np.diff(z) - rest
        expected = np.arange(1, rows) * m * g / k
        np.testing.assert_allclose(extension, expected, rtol=0.01)
    # and backward Euler's rest state is the static equilibrium: the forces balance
    force = spring_forces(model, x) + model.particle_mass[:, None] * model.gravity
    assert np.abs(force[~model.particle_pinned]).max() < 1e-6


# -- dynamics: stability and energy -----------------------------------------------------------------
def test_backward_euler_runs_ten_times_the_step_symplectic_euler_can():
    """A stiff sheet pinned at two corners swinging down: symplectic Euler is stable at 1 ms but
    blows up at 2 ms; backward Euler runs at 20 ms (10× the step where symplectic Euler fails)."""
    model = sheet(n=8, k=1000.0)
    small = simulate(model, "impulse", dt=0.001, duration=0.5, record_every=100)
    assert small.state.is_finite()
    with pytest.raises(SimulationDiverged):
        simulate(model, "impulse", dt=0.002, duration=0.5)
    big = simulate(model, "impulse", dt=0.02, duration=1.0, integrator="backward_euler")
    energy = big.arrays["energy_kinetic"] + big.arrays["energy_potential"]
    assert big.state.is_finite() and energy.max() <= energy[0] + 1e-9  # backward Euler never gains energy here
    # it hangs below the pins, spread to about the cloth's size, not crumpled or exploded
    x = big.state.particle_position
    assert x[:, 2].max() <= 1.0 + 1e-9 and x[:, 2].min() > 1.0 - 0.5 * 1.2
    with pytest.raises(SimulationDiverged):
        simulate(model, "impulse", dt=0.02, duration=1.0)


def test_undamped_swinging_cloth_keeps_its_energy_under_symplectic_euler():
    model = sheet(n=6, k=300.0, pinned=[5])  # one corner: it swings and flaps
    run = simulate(model, "impulse", dt=0.001, duration=2.0, record_every=10)
    energy = run.arrays["energy_kinetic"] + run.arrays["energy_potential"]
    drop = 0.2 * 9.81 * 0.5  # the scale of the energy that moves around
    assert np.abs(energy - energy[0]).max() < 0.05 * drop
    assert run.arrays["energy_kinetic"].max() > 0.3 * drop  # and it really swings


# -- scene files and trajectory ---------------------------------------------------------------------
SCENE = """
[simulation]
dt = 0.005
duration = 0.05
integrator = "backward_euler"

[[particles]]
position = [[2.0, 0.0, 1.0]]

[[cloth]]
name = "sheet"
size = [0.4, 0.4]
resolution = [5, 5]
position = [0.0, 0.0, 1.0]
density = 0.2
pinned = ["top_corners", 0]
thickness = 0.01

[[obstacles]]
shape = "plane"
normal = [0.0, 0.0, 1.0]
"""


def write(tmp_path, text):
    path = tmp_path / "scene.toml"
    path.write_text(text)
    return str(path)


def test_scene_file_cloth_and_trajectory_arrays(tmp_path):
    scene = load_scene(write(tmp_path, SCENE))
    model = scene.model
    assert model.particle_count == 26 and model.cloth_names == ("sheet",)
    assert model.particle_pinned.sum() == 3 and model.particle_pinned[1]
    np.testing.assert_allclose(model.particle_mass[1:].sum(), 0.2 * 0.16)
    np.testing.assert_allclose(model.particle_radius[1:], 0.01)
    run = simulate(model, scene.method, scene.dt, scene.duration, integrator=scene.integrator)
    assert run.arrays["triangles"].shape == (32, 3) and run.arrays["triangles"].min() == 1
    assert run.arrays["particle_cloth"].tolist() == [-1] + [0] * 25
    assert run.arrays["particle_position"].shape == (11, 26, 3)
    # energy_potential includes the springs' elastic energy
    state = run.state
    gravity_only = -np.sum(model.particle_mass * (state.particle_position @ model.gravity))
    assert diagnostics.potential_energy(model, state) == pytest.approx(
        gravity_only + spring_energy(model, state.particle_position)
    )
    assert spring_energy(model, state.particle_position) > 0


CLOTH_ERRORS = [
    ("resolution = [5, 5]", "resolution = [1, 5]", "cloth[0].resolution", "at least 2"),
    ("density = 0.2", "density = 0.2\nmass = 1.0", "cloth[0].mass", "both"),
    ("density = 0.2", "", "cloth[0].mass", "neither"),
    ("thickness = 0.01", "stretch_stiffness = -1.0", "cloth[0].stretch_stiffness", "at least 0"),
    ("thickness = 0.01", "damping = -0.5", "cloth[0].damping", "at least 0"),
    ("thickness = 0.01", "thickness = -0.5", "cloth[0].thickness", "at least 0"),
    ("thickness = 0.01", 'bend_stiffness = "stiff"', "cloth[0].bend_stiffness", "expected a number"),
    ('pinned = ["top_corners", 0]', "pinned = [25]", "cloth[0].pinned", "outside"),
    ('pinned = ["top_corners", 0]', 'pinned = ["top"]', "cloth[0].pinned", "unknown vertex set"),
    ('pinned = ["top_corners", 0]', "pinned = [-1]", "cloth[0].pinned[0]", "vertex index"),
    ("size = [0.4, 0.4]", 'size = [0.4, 0.4]\nfile = "x.obj"', "cloth[0].size", "exactly one"),
    ("size = [0.4, 0.4]", "size = [0.0, 0.4]", "cloth[0].size", "greater than 0"),
    ("size = [0.4, 0.4]", "size = [0.4]", "cloth[0].size", "list of 2"),
    ("thickness = 0.01", "stifness = 5.0", "cloth[0].stifness", "unknown key"),
    ("thickness = 0.01", 'self_collision = "yes"', "cloth[0].self_collision", "expected true or false"),
    ("thickness = 0.01", "thickness = 0.05", "cloth[0].thickness", "shortest triangle height"),
    ("resolution = [5, 5]", 'resolution = [5, 5]\nfile = "x.obj"', "cloth[0].size", "exactly one"),
]


@pytest.mark.parametrize("old, new, field, words", CLOTH_ERRORS, ids=[e[2] + ":" + e[3] for e in CLOTH_ERRORS])
def test_scene_cloth_errors(tmp_path, old, new, field, words):
    assert old in SCENE
    with pytest.raises(InputError) as caught:
        load_scene(write(tmp_path, SCENE.replace(old, new)))
    assert caught.value.field == field, str(caught.value)
    assert words in caught.value.message, caught.value.message


@pytest.mark.parametrize("method, dt", [("impulse", 1 / 480), ("projection", 1 / 480), ("constraints", 1 / 240)])
def test_a_cloth_landing_on_a_sphere_creates_no_energy_at_a_small_enough_step(method, dt):
    """cloth_drape with backward Euler springs. At the scene's 1/120 s the landing creates
    energy with every method — the total rises from 2.50 J to 5.9 J (impulse), 5.3 J
    (projection), 2.67 J (constraints, which solves springs and contacts together, M4) — see
    docs/methods/impulse.md; at these steps it does not, and the landing loses energy."""
    scene = load_scene("cloth_drape", [f"simulation.method={method}", f"simulation.dt={dt}"])
    run = simulate(scene.model, method, scene.dt, 0.45, scene.method_options.get(method, {}), scene.integrator)
    energy = run.arrays["energy_kinetic"] + run.arrays["energy_potential"] + run.arrays["energy_elastic"]
    assert run.summary["max_contacts"] > 100  # it did land on the sphere
    assert energy.max() <= energy[0] * (1 + 1e-3)
    assert energy[-1] < 0.9 * energy[0]  # and the landing lost energy
