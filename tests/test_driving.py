"""Driving a scene: external forces and torques, kinematic bodies on a path (contactlab.driving),
checked against closed forms under every method."""

import numpy as np
import pytest
from numba.core import event

from contactlab import ModelBuilder, driving, simulate
from contactlab.closed_form import checks
from contactlab.errors import InputError, SimulationDiverged
from contactlab.methods import loop_stages, velocity_loop
from contactlab.scene import load_scene

METHODS = ("penalty", "projection", "impulse", "constraints")


def _ball(gravity=(0.0, 0.0, 0.0)):
    builder = ModelBuilder(gravity=gravity)
    builder.add_body("sphere", radius=0.1, mass=2.0, name="ball")
    return builder


# ---- forces and torques on a free body ------------------------------------------------------


@pytest.mark.parametrize("method", METHODS)
def test_constant_force_gives_half_a_t_squared(method):
    """F = 4 N on 2 kg from rest: v = (F/m) t exactly; symplectic Euler's x after n steps of h is
    ½ (F/m) t (t + h), the closed form ½ (F/m) t² plus its first-order term ½ (F/m) h t."""
    builder = _ball()
    builder.add_force("ball", force=(4.0, 0.0, 0.0))
    h, duration = 0.01, 1.0
    run = simulate(builder.finalize(), method=method, dt=h, duration=duration)
    t, x = run.arrays["time"], run.arrays["body_position"][:, 0, 0]
    a = 4.0 / 2.0
    assert np.allclose(run.arrays["body_velocity"][:, 0, 0], a * t, rtol=0, atol=1e-12)
    assert np.allclose(x, 0.5 * a * t * (t + h), rtol=0, atol=1e-12)
    assert abs(x[-1] - 0.5 * a * duration**2) <= 0.5 * a * h * duration + 1e-12
    assert run.summary["compiled_loop"] is True  # a constant force is a keyframed drive: the compiled loop


@pytest.mark.parametrize("method", METHODS)
def test_torque_gives_omega_tau_over_i_t(method):
    """τ = 0.3 N m about z on a sphere of I = 2/5 m r²: ω = τ/I t exactly (no gyroscopic term)."""
    builder = _ball()
    builder.add_force(0, torque=(0.0, 0.0, 0.3))
    run = simulate(builder.finalize(), method=method, dt=0.01, duration=0.5)
    inertia = 0.4 * 2.0 * 0.1**2
    omega = run.arrays["body_angular_velocity"][:, 0]
    assert np.allclose(omega[:, 2], 0.3 / inertia * run.arrays["time"], rtol=1e-12, atol=1e-12)
    assert np.allclose(omega[:, :2], 0.0) and np.allclose(run.arrays["body_position"], 0.0)


def test_piecewise_linear_force_interpolates_and_holds_its_ends():
    builder = _ball()
    builder.add_force("ball", force=[[0, 0, 0], [2, 0, 0], [2, -4, 0]], times=[0.5, 1.0, 2.0])
    drive = builder.finalize().drive
    for t, expected in ((0.0, [0, 0, 0]), (0.75, [1, 0, 0]), (1.0, [2, 0, 0]), (1.5, [2, -2, 0]), (9.0, [2, -4, 0])):
        force, torque = drive.loads(t)
        assert np.allclose(force[0], expected) and np.allclose(torque, 0.0), t


def test_forces_add_up_and_a_function_of_time_is_called_once_a_step():
    calls = []

    def push(t):
        calls.append(t)
        return (t, 0.0, 0.0), (0.0, 0.0, 0.0)

    builder = _ball()
    builder.add_force("ball", push)
    builder.add_force("ball", force=(0.0, 1.0, 0.0), torque=(0.0, 0.0, 0.5))
    model = builder.finalize()
    force, torque = model.drive.loads(0.25)
    assert np.allclose(force[0], [0.25, 1.0, 0.0]) and np.allclose(torque[0], [0, 0, 0.5])
    calls.clear()
    run = simulate(model, method="impulse", dt=0.1, duration=1.0)
    assert np.allclose(calls, np.arange(10) * 0.1)  # each step's start time, once
    # v_x = Σ h t_k / m over the steps' start times
    assert np.isclose(run.state.body_velocity[0, 0], 0.1 * np.sum(np.arange(10) * 0.1) / 2.0)


# ---- kinematic bodies -------------------------------------------------------------------------


def _paddle_and_ball(orientations=None):
    builder = ModelBuilder()
    builder.add_material("wood", friction=0.3)
    builder.add_body("sphere", radius=0.1, mass=1.0, position=(0.3, 0.0, 0.1), material="wood", name="ball")
    builder.add_body("box", half_extents=(0.05, 0.2, 0.05), mass=0.01, material="wood", name="paddle")
    builder.add_path(
        "paddle",
        positions=[[-0.2, 0, 0.12], [0.4, 0, 0.12], [0.4, 0, 0.4]],
        times=[0, 0.6, 1.0],
        orientations=orientations,
    )
    builder.add_obstacle("plane", normal=(0, 0, 1), material="wood")
    return builder.finalize()


def _slerp_reference(q0, q1, w):
    angle = np.arccos(np.clip(np.dot(q0, q1), -1, 1))
    return (np.sin((1 - w) * angle) * q0 + np.sin(w * angle) * q1) / np.sin(angle)


@pytest.mark.parametrize("method", METHODS)
def test_kinematic_body_keeps_its_path_whatever_it_hits(method):
    """A light paddle (0.01 kg given, infinite in fact) sweeps through a 1 kg ball and rises while
    turning: every sample it is exactly on its keyframes (slerp for the turn); the ball is pushed."""
    q_end = np.array([np.cos(0.4), 0.0, 0.0, np.sin(0.4)])
    model = _paddle_and_ball(orientations=[[1, 0, 0, 0], [1, 0, 0, 0], q_end.tolist()])
    run = simulate(model, method=method, dt=0.004, duration=1.2)
    t = run.arrays["time"]
    expected = np.stack([np.interp(t, [0, 0.6, 1.0], c) for c in ([-0.2, 0.4, 0.4], [0, 0, 0], [0.12, 0.12, 0.4])], 1)
    assert np.abs(run.arrays["body_position"][:, 1] - expected).max() < 1e-12
    q = run.arrays["body_orientation"][:, 1]
    turning = (t > 0.6) & (t < 1.0)
    reference = np.array([_slerp_reference(np.array([1.0, 0, 0, 0]), q_end, (s - 0.6) / 0.4) for s in t[turning]])
    assert np.abs(q[turning] - reference).max() < 1e-9
    assert np.abs(q[t >= 1.0] - q_end).max() < 1e-9
    assert run.arrays["body_position"][-1, 0, 0] > 0.4  # the ball was pushed ahead of the paddle


def test_path_function_and_fixed_pose():
    builder = _ball()
    builder.add_body("box", half_extents=(0.1, 0.1, 0.1), mass=1.0, name="lift")
    builder.add_body("box", half_extents=(0.1, 0.1, 0.1), mass=1.0, name="post")
    builder.add_path("lift", lambda t: ((0.0, 0.0, 1.0 + 0.5 * t), (1.0, 0.0, 0.0, 0.0)))
    builder.add_path("post", positions=(2.0, 0.0, 0.0))
    model = builder.finalize()
    assert np.allclose(model.initial.body_velocity[1], [0, 0, 0.5])
    run = simulate(model, method="impulse", dt=0.01, duration=0.5)
    assert np.allclose(run.state.body_position[1], [0, 0, 1.25]) and np.allclose(run.state.body_position[2], [2, 0, 0])
    assert np.all(model.body_inverse_mass[1:] == 0) and np.all(model.body_inverse_inertia[1:] == 0)


def test_keyframed_drives_step_in_the_compiled_loop_and_python_functions_outside_it():
    """Keyframes are evaluated by compiled code (driving.drive_velocities) in the loop and in the
    methods' steps alike (tests/test_velocity_loop.py holds the two equal on box_pushed); a force
    or a path given as a Python function can only be called from the methods' steps."""
    options = __import__("contactlab.methods.impulse", fromlist=["Options"]).Options()
    assert velocity_loop.applies(_paddle_and_ball(), "impulse", options, "symplectic_euler")
    for add in (
        lambda builder: builder.add_force("ball", lambda t: ((1.0, 0.0, 0.0), (0.0, 0.0, 0.0))),
        lambda builder: builder.add_path("ball", lambda t: ((t, 0.0, 0.1), (1.0, 0.0, 0.0, 0.0))),
    ):
        builder = _ball(gravity=(0.0, 0.0, -9.81))
        add(builder)
        assert not velocity_loop.applies(builder.finalize(), "impulse", options, "symplectic_euler")


def test_a_driven_scene_compiles_its_loop_and_none_of_the_stages_after_free_motion():
    """Only free motion reads the drive, an argument of the loop's own (``driving.table_of``:
    None where nothing drives the scene, so that none of its code is compiled there); every
    other stage takes the LoopModel, which holds no drive. So once the box has slid undriven, a
    constant force or a keyframed path on it compiles its loop (whose step it changes) and the
    drive's kernels, and nothing of detection, the rows, the sweeps or the samples again."""

    def box(drive):
        builder = ModelBuilder()
        builder.add_body("box", half_extents=(0.1, 0.1, 0.1), mass=1.0, position=(0.0, 0.0, 0.1), name="box")
        builder.add_obstacle("plane", normal=(0, 0, 1))
        drive(builder)
        return builder.finalize()

    undriven = box(lambda builder: None)
    assert driving.table_of(undriven.drive) is None and "drive" not in loop_stages.LoopModel._fields
    simulate(undriven, "impulse", dt=0.01, duration=0.05)
    for drive in (
        lambda builder: builder.add_force("box", force=(1.0, 0.0, 0.0)),
        lambda builder: builder.add_path("box", positions=[[0, 0, 0.1], [0.1, 0, 0.1]], times=[0.0, 1.0]),
    ):
        with event.install_recorder("numba:compile") as compiled:
            run = simulate(box(drive), "impulse", dt=0.01, duration=0.05)
        assert run.summary["compiled_loop"]
        names = {getattr(e.data.get("dispatcher"), "py_func", None) for _, e in compiled.buffer}
        modules = {f.__module__ for f in names if f is not None and f.__module__.startswith("contactlab")}
        assert modules <= {"contactlab.methods.velocity_loop", "contactlab.driving"}, modules


# ---- the pushed box: closed form under every method ---------------------------------------------


@pytest.mark.parametrize("method", METHODS)
def test_pushed_box_moves_with_the_pusher_against_mu_m_g(method):
    """box_pushed's checks (closed_form._box_pushed). Speed: the mean over the second half of the
    push, off by at most (the change of the paddle–box overlap) / window ≤ the deepest contact of
    the run / window. Force: m Δv/Δt after release is μ (m g + m Δv_z/Δt) exactly (the floor's
    normal impulse over the window), so it is off by at most μ m |Δv_z| / Δt."""
    scene = load_scene("box_pushed")
    run = simulate(scene.model, method, scene.dt, scene.duration)
    speed, force = checks("box_pushed", scene.model, run.arrays)
    a = run.arrays
    first = a["time"][np.argmax(a["body_velocity"][:, 0, 0] > 0.25)]
    window = 0.5 * (1.0 - first)
    assert abs(speed.error) <= run.summary["max_penetration"] / window + 1e-9, speed
    along, vertical, time = a["body_velocity"][:, 0, 0], a["body_velocity"][:, 0, 2], a["time"]
    sliding = np.flatnonzero((time > 1.0) & (along <= 0.45) & (along >= 0.1))
    i, j = sliding[0], sliding[-1]
    bound = 0.3 * 1.0 * abs(vertical[j] - vertical[i]) / (time[j] - time[i])
    assert abs(force.error) <= bound + 1e-9 * force.expected, (force, bound)
    assert np.isclose(force.expected, 0.3 * 9.81)


def _forces_on_box(info, dt):
    """Per contact: (on the paddle?, force on the box (3,) [N], (F_n, F_t1, F_t2) [N], depth [m]),
    from a penalty step's contacts and impulses (the box is body 0, the paddle body 1)."""
    from contactlab.methods.penalty import contact_entities

    contacts = info.contacts
    a, b = contact_entities(contacts, 2)
    found = []
    for c in range(contacts.count):
        f_n, f_1, f_2 = info.impulses[c] / dt
        force = f_n * contacts.normal[c] + f_1 * contacts.tangent1[c] + f_2 * contacts.tangent2[c]
        found.append((1 in (a[c], b[c]), force if a[c] == 0 else -force, info.impulses[c] / dt, contacts.depth[c]))
    return found


@pytest.mark.parametrize("solver", ["cg", "direct"])  # the compiled matrix-free solve, and SciPy's
@pytest.mark.parametrize("friction", [0.3, 0.0])
def test_penalty_springs_push_the_box_with_what_it_needs_against_a_moving_paddle(friction, solver):
    """Issue 37: under penalty, box_pushed's box sat 7.9 mm inside the paddle (26 x the 0.3 mm
    its stiffness aims at), energy_elastic read 1.01 J, and each step reported 257 N of push
    while the box went on at 0.5 m/s: the backward Euler springs took the moving paddle for one
    at rest (penalty_implicit: both solves). Pushed at constant speed, the box
    balances: the forces a step reports are the ones that moved it (m Δv = h (Σ F + m g)); the
    paddle's push in x is the floor's sliding friction μ N, N = m g plus the paddle's vertical
    drag on the box, so μ m g where there is none; each spring holds ½ k δ² = F² / (2 k) of
    the k δ it pushes with; and a push below the box's weight per floor contact (the load
    "auto" stiffness is set for) sinks less than allowed_penetration. Without friction nothing
    needs pushing, and the paddle's springs hold nothing."""
    from contactlab.methods import penalty

    settings = [f"materials.0.friction={friction}", f"method.penalty.linear_solver={solver}"]
    scene = load_scene("box_pushed", ["simulation.method=penalty", *settings])
    model, dt, options = scene.model, scene.dt, scene.options["penalty"]
    mass, g, state = 1.0, 9.81, model.state()
    for _ in range(int(round(0.6 / dt))):  # the paddle meets the box at 0.26 s; the push settles
        state, info = penalty.step(model, state, dt, options, scene.integrator)
    for _ in range(int(round(0.3 / dt))):  # up to 0.9 s, still pushed (the path ends at 1 s)
        before = state.body_velocity[0].copy()
        state, info = penalty.step(model, state, dt, options, scene.integrator)
        found = _forces_on_box(info, dt)
        total = sum(force for _, force, _, _ in found)
        np.testing.assert_allclose(mass * (state.body_velocity[0] - before) / dt, total + [0, 0, -mass * g], atol=1e-6)
        paddle = [(force, f_n, depth) for on_paddle, force, f_n, depth in found if on_paddle]
        push = sum(force[0] for force, _, _ in paddle)
        drag = -sum(force[2] for force, _, _ in paddle)  # the paddle's pull down on the box [N]
        assert abs(push - friction * (mass * g + drag)) <= 1e-3 * mass * g, (push, drag)
        assert abs(drag) <= 0.1 * mass * g
        assert max((depth for _, _, depth in paddle), default=0.0) <= options.allowed_penetration
        if friction == 0.0:
            assert push == pytest.approx(0.0, abs=1e-6) and all(f[0] <= 1e-6 for _, f, _ in paddle)
    stiffness = mass * g / 4 / options.allowed_penetration  # "auto": the box's weight per floor contact
    np.testing.assert_allclose(penalty.contact_stiffness(model, state, info.contacts, options), stiffness)
    # k_t = k ("auto"): each spring, normal and anchor, holds F² / (2 k) of the force F it exerts
    # (steady: no spring moves, so no damping in F)
    energy = sum(f @ f / (2 * stiffness) for _, _, f, _ in _forces_on_box(info, dt))
    assert info.energy_elastic == pytest.approx(energy, rel=1e-6)
    if friction == 0.0:  # the floor's four springs alone, each holding m g / 4
        assert info.energy_elastic == pytest.approx(4 * (mass * g / 4) ** 2 / (2 * stiffness), rel=1e-6)


# ---- bad input ------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "call, field, words",
    [
        (lambda b: b.add_force("ball", force=(1.0, 2.0)), "force", "3 numbers"),
        (lambda b: b.add_force("ball", force=(np.nan, 0, 0)), "force", "finite"),
        (lambda b: b.add_force("bal", force=(1, 0, 0)), "body", "did you mean 'ball'"),
        (lambda b: b.add_force("ball", force=[[0, 0, 0], [1, 0, 0]], times=[1.0, 0.5]), "times", "increase"),
        (lambda b: b.add_force("ball", force=[[0, 0, 0]], times=[0.0, 1.0]), "force", "one per time"),
        (lambda b: b.add_path("ball", positions=[[0, 0, 0], [1, 0, 0]], times=[0.0, 0.0]), "times", "increase"),
        (lambda b: b.add_path("ball", positions=[[0, 0, 0], [1, 0, np.nan]], times=[0.0, 1.0]), "positions", "finite"),
        (
            lambda b: b.add_path("ball", positions=[[0, 0, 0]], times=[0.0], orientations=[[0, 0, 0, 0]]),
            "orientations",
            "zero quaternion",
        ),
    ],
)
def test_bad_input_names_the_field(call, field, words):
    with pytest.raises(InputError) as error:
        call(_ball())
    assert error.value.field == field and words in error.value.message


def test_a_bad_force_function_names_the_time():
    builder = _ball()
    builder.add_force("ball", lambda t: ((0.0, 0.0), (0.0, 0.0, 0.0)))
    with pytest.raises(InputError, match="at t = 0 s") as error:
        simulate(builder.finalize(), dt=0.01, duration=0.1)
    assert error.value.field == "force"


def test_explicit_euler_is_refused_for_a_kinematic_body():
    with pytest.raises(InputError) as error:
        simulate(_paddle_and_ball(), dt=0.01, duration=0.1, integrator="explicit_euler")
    assert error.value.field == "integrator"


def _scene_error(tmp_path, extra, body_extra=""):
    text = f"""
[[bodies]]
name = "box"
shape = "box"
half_extents = [0.1, 0.1, 0.1]
mass = 1.0
{body_extra}
{extra}
"""
    path = tmp_path / "scene.toml"
    path.write_text(text)
    with pytest.raises(InputError) as error:
        load_scene(path)
    return error.value


def test_scene_file_errors_give_the_field_path(tmp_path):
    error = _scene_error(tmp_path, '[[forces]]\nbody = "box"\nforce = [1.0, 2.0]')
    assert error.field == "forces[0].force" and "(N)" in error.message
    error = _scene_error(tmp_path, '[[forces]]\nbody = "bx"\nforce = [1.0, 2.0, 0.0]')
    assert error.field == "forces[0].body" and "did you mean 'box'" in error.message
    error = _scene_error(tmp_path, '[[forces]]\nbody = "box"\nforec = [1.0, 2.0, 0.0]')
    assert error.field == "forces[0].forec" and "did you mean 'force'" in error.message
    error = _scene_error(
        tmp_path, "", "path = { times = [0.0, 1.0, 0.5], positions = [[0, 0, 0], [1, 0, 0], [2, 0, 0]] }"
    )
    assert error.field == "bodies[0].path.times[2]" and "increase" in error.message
    error = _scene_error(tmp_path, "", "path = { times = [0.0, 1.0], positions = [[0, 0, 0]] }")
    assert error.field == "bodies[0].path.positions" and "one per time" in error.message
    error = _scene_error(tmp_path, '[[forces]]\nbody = "box"\ntimes = [0.0, 1.0]\nforce = [[0, 0, 0], [1, 0, nan]]')
    assert error.field == "forces[0].force[1]" and "finite" in error.message


def test_scene_file_keyframed_force(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text("""
[simulation]
gravity = [0.0, 0.0, 0.0]

[[bodies]]
name = "box"
shape = "box"
half_extents = [0.1, 0.1, 0.1]
mass = 2.0

[[forces]]
body = "box"
times = [0.0, 1.0]
force = [[0.0, 0.0, 0.0], [4.0, 0.0, 0.0]]
torque = [[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
""")
    drive = load_scene(path).model.drive
    force, torque = drive.loads(0.5)
    assert np.allclose(force[0], [2, 0, 0]) and np.allclose(torque[0], [0, 0, 0.5])


@pytest.mark.parametrize("method", METHODS)
def test_a_path_through_the_floor_is_kept_and_not_called_a_divergence(method):
    """Two immovable sides (a kinematic box, the static floor) overlap: no contact can act, the
    path is kept, and the depth check leaves them alone (neither side can move). Stepped through
    the methods' ``step``: the depth check is the same either way, and a driven box on a plane
    would compile four loops for this test alone (the loop keeps paths in
    ``test_kinematic_body_keeps_its_path_whatever_it_hits``)."""
    builder = ModelBuilder()
    builder.add_body("box", half_extents=(0.1, 0.1, 0.1), mass=1.0, name="ram")
    builder.add_path("ram", positions=[[0, 0, 0.3], [0, 0, -0.3]], times=[0.0, 0.2])
    builder.add_obstacle("plane", normal=(0, 0, 1))
    run = simulate(builder.finalize(), method=method, dt=0.01, duration=0.3, compiled_loop=False)
    assert np.allclose(run.state.body_position[0], [0, 0, -0.3], atol=1e-12)
    assert run.summary["health"]["violations"] == []


# ---- the advice when a driven run goes wrong -------------------------------------------------------


def _stopped(model, **keywords):
    """The message of the SimulationDiverged that stops ``simulate(model, **keywords)``."""
    with pytest.raises(SimulationDiverged) as stopped:
        simulate(model, **keywords)
    return str(stopped.value)


@pytest.mark.parametrize("method", METHODS)
def test_a_force_far_too_large_is_named_as_the_problem_not_the_dt(method):
    # issue 37: a 10¹² N push was answered "use a smaller dt". Through the methods' step: the
    # advice is simulate's whichever path stopped, and a driven ball on a plane would compile
    # four loops for this test alone
    builder = _ball(gravity=(0.0, 0.0, -9.81))
    builder.add_obstacle("plane", normal=(0, 0, 1), offset=-0.1)
    builder.add_force("ball", force=(1e12, 0.0, 0.0))
    message = _stopped(builder.finalize(), method=method, dt=0.004, duration=1.0, compiled_loop=False)
    assert "the force on 'ball', 1e+12 N on 2 kg, alone would speed it to 2e+09 m/s by then" in message, message
    assert message.endswith("the force is the likely problem (its values, units or times), not the time step")


def test_a_path_that_jumps_a_thousand_kilometres_in_a_nanosecond_is_named_not_the_dt():
    scene = load_scene("box_pushed", ["bodies.1.path={times=[0.0, 1e-9], positions=[[-0.2, 0, 0.06], [1e6, 0, 0.06]]}"])
    message = _stopped(scene.model, method="impulse", dt=scene.dt, duration=scene.duration)
    assert message.startswith("the run went wrong at t = 0.004 s: ")
    assert "the path of 'paddle' moves it at 2.5e+08 m/s then" in message, message
    assert message.endswith("the path is the likely problem (its values, units or times), not the time step")


def test_a_driven_run_that_goes_wrong_for_its_method_keeps_the_methods_advice():
    """A gentle push on a ball whose penalty springs are far too stiff for the step: the springs
    are the problem, and the advice says so (penalty's), not the push."""
    builder = _ball(gravity=(0.0, 0.0, -9.81))
    builder.add_obstacle("plane", normal=(0, 0, 1), offset=-0.2)
    builder.add_force("ball", force=(1.0, 0.0, 0.0))
    options = {"stiffness": 1e9, "implicit_springs": "never"}
    message = _stopped(builder.finalize(), method="penalty", dt=0.01, duration=2.0, options=options)
    assert "a stiffness below" in message and "the force" not in message and "not the time step" not in message, message
