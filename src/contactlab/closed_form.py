"""Closed-form answers of the built-in scenes, and what a run measured of them.

    for check in checks("sliding_block", scene.model, run.arrays):
        print(check.quantity, check.expected, check.measured, check.error)

Every expected value is computed from the model itself (masses, radii, μ, ε, gravity, the
initial state), so a scene changed with ``--set`` is still checked against its own answer; a
scene changed so far that the formula no longer applies (another shape, a second body) gets no
check rather than a wrong one. Measurements read the recorded trajectory (docs/trajectory.md).
Friction and restitution combine as in contact generation: μ = √(μ_a μ_b), ε = max(ε_a, ε_b).
"""

from dataclasses import dataclass

import numpy as np

from . import rotations, shapes


@dataclass(frozen=True)
class Check:
    quantity: str        # what is compared, e.g. "first rebound apex"
    unit: str            # of expected and measured, e.g. "m"
    expected: float      # the closed-form value
    measured: float      # what the run gave (nan when the run never reached it)

    @property
    def error(self) -> float:
        """measured − expected, in ``unit``."""
        return self.measured - self.expected

    @property
    def relative_error(self):
        """|error| / |expected|; None when the expected value is 0 (compare ``error`` instead)."""
        return abs(self.error) / abs(self.expected) if self.expected != 0 else None


def checks(scene_name, model, arrays) -> list:
    """The closed-form checks of built-in scene ``scene_name`` on a run's ``arrays``; [] when the
    scene has none or no longer has the layout its formula needs."""
    check = _CHECKS.get(scene_name)
    return check(model, arrays) if check else []


# ---- what the formulas need of a scene ---------------------------------------------------------

def _gravity(model):
    """(|g| [m/s²], unit vector 'up' (3,)); up is None without gravity."""
    g = float(np.linalg.norm(model.gravity))
    return g, (-np.asarray(model.gravity) / g if g > 0 else None)


def _one_body_on_plane(model, kind):
    """(body shape params, plane params) when the scene is one body of ``kind`` and one plane."""
    if (model.body_count != 1 or model.particle_count or model.obstacle_count != 1
            or model.body_shape[0] != kind or model.obstacle_shape[0] != shapes.PLANE):
        return None
    return model.body_params[0], model.obstacle_params[0]


def _body_on_floor(model, kind):
    """(shape params (4,), |g|, up (3,), floor offset along up) when the scene is one body of
    ``kind`` on one horizontal plane under gravity; else None."""
    layout = _one_body_on_plane(model, kind)
    g, up = _gravity(model)
    floor = _horizontal_floor(model, up) if layout is not None else None
    return None if floor is None else (layout[0], g, up, floor)


def _materials(model):
    """(μ, ε) of the contact between body 0 and obstacle 0."""
    friction, restitution = model.pair_materials(model.body_material[0], model.obstacle_material[0])
    return float(friction), float(restitution)


def _horizontal_floor(model, up):
    """The floor's offset along ``up`` when obstacle 0 is a plane facing up, else None."""
    normal, offset = model.obstacle_params[0, :3], model.obstacle_params[0, 3]
    return float(offset) if up is not None and np.allclose(normal, up, atol=1e-9) else None


def _first_time(time, condition):
    """Time of the first sample where ``condition`` holds; nan if never."""
    index = np.flatnonzero(condition)
    return float(time[index[0]]) if len(index) else float("nan")


# ---- the scenes --------------------------------------------------------------------------------

def _bouncing_ball(model, arrays):
    """Dropped from rest at height h0: the n-th rebound peaks at ε^(2n) h0."""
    layout = _body_on_floor(model, shapes.SPHERE)
    if layout is None:
        return []
    params, g, up, floor = layout
    _, restitution = _materials(model)
    height = arrays["body_position"][:, 0] @ up - floor - params[0]
    rise = arrays["body_velocity"][:, 0] @ up
    h0 = float(height[0])
    if np.linalg.norm(arrays["body_velocity"][0, 0]) > 0:
        return []
    # apexes: where the upward speed turns from positive to non-positive
    turning = np.flatnonzero((rise[:-1] > 0) & (rise[1:] <= 0))
    apexes = [float(height[i:i + 2].max()) for i in turning]
    return [Check(f"rebound {n} apex", "m", restitution ** (2 * n) * h0,
                  apexes[n - 1] if len(apexes) >= n else float("nan")) for n in (1, 2)]


def _sliding_block(model, arrays):
    """A block launched at v0 on a floor stops after v0²/(2 μ g), at t = v0/(μ g)."""
    layout = _body_on_floor(model, shapes.BOX)
    if layout is None:
        return []
    _, g, up, _ = layout
    friction, _ = _materials(model)
    v0 = np.linalg.norm(arrays["body_velocity"][0, 0] - (arrays["body_velocity"][0, 0] @ up) * up)
    if friction == 0 or v0 == 0:
        return []
    moved = arrays["body_position"][:, 0] - arrays["body_position"][0, 0]
    moved -= np.outer(moved @ up, up)
    speed = np.linalg.norm(arrays["body_velocity"][:, 0], axis=1)
    return [Check("stopping distance", "m", v0 ** 2 / (2 * friction * g), float(np.linalg.norm(moved[-1]))),
            Check("stopping time", "s", v0 / (friction * g), _first_time(arrays["time"], speed < 1e-3 * v0))]


def _rolling_sphere(model, arrays):
    """A ball launched at v0 without spin slides until t = 2 v0/(7 μ g), then rolls at 5/7 v0."""
    layout = _body_on_floor(model, shapes.SPHERE)
    if layout is None:
        return []
    params, g, up, _ = layout
    radius = params[0]
    friction, _ = _materials(model)
    v = arrays["body_velocity"][:, 0]
    w = arrays["body_angular_velocity"][:, 0]
    v0 = float(np.linalg.norm(v[0]))
    if friction == 0 or v0 == 0 or np.linalg.norm(w[0]) > 0:
        return []
    slip = np.linalg.norm(v + np.cross(w, -radius * up), axis=1)     # velocity of the touching point
    return [Check("rolling speed", "m/s", 5.0 / 7.0 * v0, float(np.linalg.norm(v[-1]))),
            Check("end of sliding", "s", 2.0 * v0 / (7.0 * friction * g),
                  _first_time(arrays["time"], slip < 0.01 * v0))]


def _incline(model, arrays):
    """A block at rest on a slope of angle θ: it sticks when μ ≥ tan θ, else slides ½ g (sinθ − μ cosθ) t²."""
    layout = _one_body_on_plane(model, shapes.BOX)
    g, up = _gravity(model)
    if layout is None or up is None or np.linalg.norm(arrays["body_velocity"][0, 0]) > 0:
        return []
    normal = model.obstacle_params[0, :3]
    cos_theta = float(normal @ up)
    downhill = -(up - cos_theta * normal)
    if np.linalg.norm(downhill) < 1e-12:
        return []
    downhill /= np.linalg.norm(downhill)
    sin_theta = float(np.sqrt(max(0.0, 1.0 - cos_theta ** 2)))
    friction, _ = _materials(model)
    acceleration = max(0.0, g * (sin_theta - friction * cos_theta))
    elapsed = float(arrays["time"][-1] - arrays["time"][0])
    moved = float((arrays["body_position"][-1, 0] - arrays["body_position"][0, 0]) @ downhill)
    return [Check("distance down the slope", "m", 0.5 * acceleration * elapsed ** 2, moved)]


def _newtons_cradle(model, arrays):
    """Equal balls, ε = 1, no gravity: the striker's velocity ends in the last ball, the others stop."""
    if (model.body_count < 2 or model.obstacle_count or model.particle_count or np.any(model.gravity != 0)
            or np.any(model.body_shape != shapes.SPHERE) or np.ptp(model.body_mass) > 0
            or np.any(model.material_restitution[model.body_material] != 1.0)):
        return []
    v = arrays["body_velocity"]
    v0 = v[0, 0]
    if np.linalg.norm(v0) == 0 or np.any(np.linalg.norm(v[0, 1:], axis=1) > 0):
        return []
    direction = v0 / np.linalg.norm(v0)
    return [Check("last ball velocity", "m/s", float(np.linalg.norm(v0)), float(v[-1, -1] @ direction)),
            Check("largest speed of the other balls", "m/s", 0.0,
                  float(np.linalg.norm(v[-1, :-1], axis=1).max()))]


def _rod_impact(model, arrays):
    """A frictionless box dropped from rest falls onto one corner at v_n = −√(2 g h); one impulse
    j n at the corner r then gives (R4) j = −(1 + ε) v_n / (1/m + n·((I⁻¹ (r × n)) × r)),
    v⁺ = v + j n/m and ω⁺ = I⁻¹ (r × j n).

    Measured when the corner has left the floor again (the first contact-free sample after the
    impact): the angular velocity as it is, the velocity along n less the gravity of the time
    since the closed-form instant of impact."""
    layout = _body_on_floor(model, shapes.BOX)
    if layout is None:
        return []
    params, g, up, floor = layout
    friction, restitution = _materials(model)
    if (friction != 0 or np.linalg.norm(arrays["body_velocity"][0, 0]) > 0
            or np.linalg.norm(arrays["body_angular_velocity"][0, 0]) > 0):
        return []
    R = rotations.to_matrix(arrays["body_orientation"][0, :1])[0]        # unchanged while falling
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * params[:3]
    r = min(corners @ R.T, key=lambda c: c @ up)            # the lowest corner, from the centre, world
    drop = float((arrays["body_position"][0, 0] + r) @ up - floor)
    impact_time = arrays["time"][0] + np.sqrt(2.0 * drop / g)
    v_normal = -np.sqrt(2.0 * g * drop)
    inverse_inertia = R @ np.diag(1.0 / model.body_inertia[0]) @ R.T
    effective = 1.0 / model.body_mass[0] + up @ np.cross(inverse_inertia @ np.cross(r, up), r)
    j = -(1.0 + restitution) * v_normal / effective
    v_after = v_normal + j / model.body_mass[0]
    w_after = inverse_inertia @ np.cross(r, j * up)
    axis = int(np.argmax(np.abs(w_after)))                 # the impact is planar: one axis spins
    touching = arrays["contact_count"] > 0
    first = np.argmax(touching) if touching.any() else len(touching)
    after = np.flatnonzero(~touching & (np.arange(len(touching)) > first))
    if len(after):
        k = after[0]
        measured_v = float(arrays["body_velocity"][k, 0] @ up + g * (arrays["time"][k] - impact_time))
        measured_w = float(arrays["body_angular_velocity"][k, 0, axis])
    else:
        measured_v = measured_w = float("nan")
    return [Check("vertical velocity after the impact", "m/s", float(v_after), measured_v),
            Check(f"angular velocity about {'xyz'[axis]} after the impact", "rad/s", float(w_after[axis]),
                  measured_w)]


def _box_pushed(model, arrays):
    """A box on the floor pushed by a kinematic paddle at constant velocity v_p until the path's
    last keyframe, then released.

    Pushed, the box moves with the paddle: its mean speed over the second half of the push,
    measured from its displacement, is |v_p| (the paddle–box overlap changes by less than the
    run's deepest contact over that window, which bounds the error by it over the window's
    length). The push then balances the floor's sliding friction μ m g; the paddle is infinitely
    heavy, so its push is not observed directly, but the friction it balances is: released, the
    box slides on the same contact, and m Δv / Δt over the samples from 0.9 |v_p| down to
    0.2 |v_p| equals μ (m g + m Δv_z / Δt) (the floor's normal impulse is m (g Δt + Δv_z)), so it
    differs from μ m g by μ m |Δv_z| / Δt at most, Δv_z the box's vertical velocity change."""
    drive = model.drive
    g, up = _gravity(model)
    if (drive is None or model.body_count != 2 or model.particle_count or model.obstacle_count != 1
            or up is None or _horizontal_floor(model, up) is None or model.body_shape[0] != shapes.BOX
            or list(np.flatnonzero(drive.kinematic)) != [1] or list(drive.path_body) != [1] or drive.has_loads
            or len(drive.path_times[0]) != 2):
        return []
    start, end = drive.path_times[0]
    velocity = (drive.path_positions[0, 1] - drive.path_positions[0, 0]) / (end - start)
    speed = float(np.linalg.norm(velocity))
    if speed == 0 or abs(velocity @ up) > 1e-12 * speed:
        return []
    direction = velocity / speed
    mass = float(model.body_mass[0])
    friction = float(model.pair_materials(model.body_material[0], model.obstacle_material[0])[0])
    time = arrays["time"]
    along = arrays["body_velocity"][:, 0] @ direction
    moved = (arrays["body_position"][:, 0] - arrays["body_position"][0, 0]) @ direction
    first = _first_time(time, along > 0.5 * speed)            # the first contact
    window = (time >= first + 0.5 * (end - first)) & (time <= end)
    mean_speed = float("nan")
    if np.isfinite(first) and window.sum() >= 2:
        a, b = np.flatnonzero(window)[[0, -1]]
        mean_speed = float((moved[b] - moved[a]) / (time[b] - time[a]))
    sliding = np.flatnonzero((time > end) & (along <= 0.9 * speed) & (along >= 0.2 * speed))
    force = float("nan")
    if len(sliding) >= 2:
        a, b = sliding[0], sliding[-1]
        force = float(mass * (along[a] - along[b]) / (time[b] - time[a]))
    return [Check("box speed while pushed", "m/s", speed, mean_speed),
            Check("push force: the sliding friction it balances", "N", friction * mass * g, force)]


def _standing(model, arrays):
    """A structure in static equilibrium must not move: the largest displacement is 0."""
    if model.body_count == 0:
        return []
    moved = np.linalg.norm(arrays["body_position"][-1] - arrays["body_position"][0], axis=1)
    return [Check("largest body displacement", "m", 0.0, float(moved.max()))]


_CHECKS = {
    "bouncing_ball": _bouncing_ball,
    "sliding_block": _sliding_block,
    "rolling_sphere": _rolling_sphere,
    "incline": _incline,
    "newtons_cradle": _newtons_cradle,
    "rod_impact": _rod_impact,
    "box_stack": _standing,
    "box_pyramid": _standing,
    "mass_ratio_stack": _standing,
    "card_house": _standing,
    "box_pushed": _box_pushed,
}
